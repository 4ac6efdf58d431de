"""Taylor-series integration of the derived equations: one trajectory
(`taylor_integrate`), a batch (`taylor_integrate_batch`), or `lj.Taylor` in
`simulate` and `lj.sweep`."""

from .batch import taylor_integrate_batch as taylor_integrate_batch
from .coefficients import taylor_coefficients as taylor_coefficients
from .integrate import RESULTS as RESULTS
from .integrate import TaylorSolution as TaylorSolution
from .integrate import taylor_integrate as taylor_integrate
from .solver import Taylor as Taylor
from .step import order_from_tolerance as order_from_tolerance
