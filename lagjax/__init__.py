"""lagjax: classical mechanics in JAX.

Write a Lagrangian L(q, q̇) or a Hamiltonian H(q, p) as a plain JAX function; lagjax
derives the equations of motion, Legendre transforms, Poisson brackets and normal
modes by automatic differentiation.
"""

from importlib import metadata as _metadata

from lagjax import diagnostics as diagnostics
from lagjax import phase_space as phase_space
from lagjax import rigid as rigid
from lagjax import scenes as scenes
from lagjax._core.cpu_loops import enable_fast_cpu_loops as enable_fast_cpu_loops
from lagjax._core.system import AbstractSystem as AbstractSystem
from lagjax._core.terms import ConstrainedLagrangianTerm as ConstrainedLagrangianTerm
from lagjax._core.terms import LagrangianTerm as LagrangianTerm
from lagjax._core.terms import RattleTerm as RattleTerm
from lagjax._core.terms import RigidBodyTerm as RigidBodyTerm
from lagjax._integrate.checks.late_failure import SimulationError as SimulationError
from lagjax._integrate.reversible_adjoint import ReversibleAdjoint as ReversibleAdjoint
from lagjax._integrate.simulate import simulate as simulate
from lagjax._sweep.progress import SweepProgress as SweepProgress
from lagjax._sweep.reader import SweepStore as SweepStore
from lagjax._sweep.reader import open_sweep as open_sweep
from lagjax._sweep.to_disk import sweep_to_disk as sweep_to_disk
from lagjax.action_principle import action as action
from lagjax.action_principle import action_between as action_between
from lagjax.action_principle import action_of_path as action_of_path
from lagjax.action_principle import principal_function as principal_function
from lagjax.action_principle import trajectory_between as trajectory_between
from lagjax.mechanics import particles as particles
from lagjax.mechanics.brackets import poisson_bracket as poisson_bracket
from lagjax.mechanics.canonical import GeneratingFunction as GeneratingFunction
from lagjax.mechanics.canonical import is_canonical as is_canonical
from lagjax.mechanics.canonical import symplectic_defect as symplectic_defect
from lagjax.mechanics.canonical import symplectic_form as symplectic_form
from lagjax.mechanics.captured_globals import (
    CapturedNumberWarning as CapturedNumberWarning,
)
from lagjax.mechanics.constraints import Constraints as Constraints
from lagjax.mechanics.euler_lagrange import (
    euler_lagrange_acceleration as euler_lagrange_acceleration,
)
from lagjax.mechanics.hamiltonian import AbstractHamiltonian as AbstractHamiltonian
from lagjax.mechanics.hamiltonian import Hamiltonian as Hamiltonian
from lagjax.mechanics.hamiltonian import LegendreHamiltonian as LegendreHamiltonian
from lagjax.mechanics.hamiltonian import SeparableHamiltonian as SeparableHamiltonian
from lagjax.mechanics.lagrangian import Lagrangian as Lagrangian
from lagjax.mechanics.linearize import LinearizedSystem as LinearizedSystem
from lagjax.mechanics.linearize import linearize as linearize
from lagjax.mechanics.modes import NormalModes as NormalModes
from lagjax.mechanics.modes import equilibrium as equilibrium
from lagjax.mechanics.modes import gyroscopic_matrix as gyroscopic_matrix
from lagjax.mechanics.modes import normal_modes as normal_modes
from lagjax.mechanics.modes import stiffness_matrices as stiffness_matrices
from lagjax.mechanics.particles import newtonian_gravity as newtonian_gravity
from lagjax.mechanics.particles import particle_hamiltonian as particle_hamiltonian
from lagjax.mechanics.particles import particle_lagrangian as particle_lagrangian
from lagjax.mechanics.relative_equilibria import (
    relative_equilibrium as relative_equilibrium,
)
from lagjax.phase_space import LyapunovSpectrum as LyapunovSpectrum
from lagjax.phase_space import PoincareSection as PoincareSection
from lagjax.phase_space import chaos_indicators as chaos_indicators
from lagjax.phase_space import fast_lyapunov_indicator as fast_lyapunov_indicator
from lagjax.phase_space import fundamental_frequencies as fundamental_frequencies
from lagjax.phase_space import lyapunov_spectrum as lyapunov_spectrum
from lagjax.phase_space import megno as megno
from lagjax.phase_space import poincare_section as poincare_section
from lagjax.phase_space import states_on_energy_shell as states_on_energy_shell
from lagjax.rigid.body import RigidBody as RigidBody
from lagjax.solvers.bit_reversible import BitReversible as BitReversible
from lagjax.solvers.chain import ChainRegularization as ChainRegularization
from lagjax.solvers.extrapolation import GraggBulirschStoer as GraggBulirschStoer
from lagjax.solvers.implicit import GaussLegendre as GaussLegendre
from lagjax.solvers.implicit import ImplicitMidpoint as ImplicitMidpoint
from lagjax.solvers.lie_poisson import QuaternionProjection as QuaternionProjection
from lagjax.solvers.lie_poisson import RigidBodyVerlet as RigidBodyVerlet
from lagjax.solvers.lie_poisson import RigidBodyYoshida4 as RigidBodyYoshida4
from lagjax.solvers.projection import ConstraintProjection as ConstraintProjection
from lagjax.solvers.rattle import Rattle as Rattle
from lagjax.solvers.splitting import BlanesMoan4 as BlanesMoan4
from lagjax.solvers.splitting import BlanesMoan6 as BlanesMoan6
from lagjax.solvers.splitting import BlanesMoanNystrom6 as BlanesMoanNystrom6
from lagjax.solvers.splitting import KahanLi8 as KahanLi8
from lagjax.solvers.splitting import SofSpa10 as SofSpa10
from lagjax.solvers.splitting import StormerVerlet as StormerVerlet
from lagjax.solvers.splitting import Yoshida4 as Yoshida4
from lagjax.solvers.splitting import Yoshida6 as Yoshida6
from lagjax.solvers.time_transformed import TimeTransformed as TimeTransformed
from lagjax.solvers.variational import VariationalMidpoint as VariationalMidpoint
from lagjax.solvers.wisdom_holman import WisdomHolman as WisdomHolman
from lagjax.sweep import sweep as sweep
from lagjax.taylor.solver import Taylor as Taylor
from lagjax.trajectory import Trajectory as Trajectory

try:  # one source for the version: pyproject.toml, through the installed metadata
    __version__ = _metadata.version("lagjax")
except _metadata.PackageNotFoundError:  # a source tree that was never installed
    __version__ = "0+unknown"
del _metadata
