"""Taylor-series integration of the derived equations (issue 28)."""

from .coefficients import taylor_coefficients as taylor_coefficients
from .integrate import RESULTS as RESULTS
from .integrate import TaylorSolution as TaylorSolution
from .integrate import taylor_integrate as taylor_integrate
from .solver import Taylor as Taylor
from .step import order_from_tolerance as order_from_tolerance
