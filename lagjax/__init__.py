"""lagjax: classical mechanics in JAX.

Write a Lagrangian L(q, q̇) or a Hamiltonian H(q, p) as a plain JAX function; lagjax
derives the equations of motion, Legendre transforms, Poisson brackets and normal
modes by automatic differentiation.
"""

# ruff: noqa: E402  (the XLA default below must run before the other imports)
from importlib import metadata as _metadata

# Before anything computes: XLA's CPU loop threshold (see lagjax/xla_defaults.py).
from .xla_defaults import apply_cpu_loop_default as _apply_cpu_loop_default

_apply_cpu_loop_default()

from . import diagnostics as diagnostics
from . import phase_space as phase_space
from . import rigid as rigid
from . import scenes as scenes
from .hamilton_principle import action as action
from .hamilton_principle import action_of_path as action_of_path
from .hamilton_principle import principal_function as principal_function
from .mechanics import particles as particles
from .mechanics.brackets import poisson_bracket as poisson_bracket
from .mechanics.canonical import GeneratingFunction as GeneratingFunction
from .mechanics.canonical import is_canonical as is_canonical
from .mechanics.canonical import symplectic_defect as symplectic_defect
from .mechanics.canonical import symplectic_form as symplectic_form
from .mechanics.constraints import Constraints as Constraints
from .mechanics.euler_lagrange import (
    euler_lagrange_acceleration as euler_lagrange_acceleration,
)
from .mechanics.hamiltonian import AbstractHamiltonian as AbstractHamiltonian
from .mechanics.hamiltonian import Hamiltonian as Hamiltonian
from .mechanics.hamiltonian import LegendreHamiltonian as LegendreHamiltonian
from .mechanics.hamiltonian import SeparableHamiltonian as SeparableHamiltonian
from .mechanics.lagrangian import Lagrangian as Lagrangian
from .mechanics.linearize import LinearizedSystem as LinearizedSystem
from .mechanics.linearize import linearize as linearize
from .mechanics.modes import NormalModes as NormalModes
from .mechanics.modes import equilibrium as equilibrium
from .mechanics.modes import gyroscopic_matrix as gyroscopic_matrix
from .mechanics.modes import normal_modes as normal_modes
from .mechanics.modes import stiffness_matrices as stiffness_matrices
from .mechanics.particles import newtonian_gravity as newtonian_gravity
from .mechanics.particles import particle_hamiltonian as particle_hamiltonian
from .mechanics.particles import particle_lagrangian as particle_lagrangian
from .mechanics.relative_equilibria import (
    relative_equilibrium as relative_equilibrium,
)
from .phase_space import LyapunovSpectrum as LyapunovSpectrum
from .phase_space import PoincareSection as PoincareSection
from .phase_space import chaos_indicators as chaos_indicators
from .phase_space import fast_lyapunov_indicator as fast_lyapunov_indicator
from .phase_space import fundamental_frequencies as fundamental_frequencies
from .phase_space import lyapunov_spectrum as lyapunov_spectrum
from .phase_space import megno as megno
from .phase_space import poincare_section as poincare_section
from .phase_space import states_on_energy_shell as states_on_energy_shell
from .rigid.body import RigidBody as RigidBody
from .shooting import action_between as action_between
from .shooting import trajectory_between as trajectory_between
from .simulate import simulate as simulate
from .solvers.implicit import GaussLegendre as GaussLegendre
from .solvers.implicit import ImplicitMidpoint as ImplicitMidpoint
from .solvers.lie_poisson import QuaternionProjection as QuaternionProjection
from .solvers.lie_poisson import RigidBodyVerlet as RigidBodyVerlet
from .solvers.lie_poisson import RigidBodyYoshida4 as RigidBodyYoshida4
from .solvers.projection import ConstraintProjection as ConstraintProjection
from .solvers.rattle import Rattle as Rattle
from .solvers.splitting import BlanesMoan4 as BlanesMoan4
from .solvers.splitting import BlanesMoan6 as BlanesMoan6
from .solvers.splitting import BlanesMoanNystrom6 as BlanesMoanNystrom6
from .solvers.splitting import KahanLi8 as KahanLi8
from .solvers.splitting import SofSpa10 as SofSpa10
from .solvers.splitting import StormerVerlet as StormerVerlet
from .solvers.splitting import Yoshida4 as Yoshida4
from .solvers.splitting import Yoshida6 as Yoshida6
from .solvers.variational import VariationalMidpoint as VariationalMidpoint
from .sweep import sweep as sweep
from .system import AbstractSystem as AbstractSystem
from .terms import ConstrainedLagrangianTerm as ConstrainedLagrangianTerm
from .terms import LagrangianTerm as LagrangianTerm
from .terms import RattleTerm as RattleTerm
from .terms import RigidBodyTerm as RigidBodyTerm
from .trajectory import Trajectory as Trajectory

try:  # one source for the version: pyproject.toml, through the installed metadata
    __version__ = _metadata.version("lagjax")
except _metadata.PackageNotFoundError:  # a source tree that was never installed
    __version__ = "0+unknown"
del _metadata
