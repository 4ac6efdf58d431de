"""Phase-space tools: Lyapunov spectra, Poincaré sections, chaos indicators, frequencies.

All act on an autonomous system's flow, built from `lj.simulate` and differentiated
exactly with `jax.jvp`; the per-orbit tools vmap over a batch of initial states.
"""

from .energy_shell import states_on_energy_shell as states_on_energy_shell
from .frequency import Frequencies as Frequencies
from .frequency import fundamental_frequencies as fundamental_frequencies
from .henon_heiles import henon_heiles as henon_heiles
from .henon_heiles import henon_heiles_section_states as henon_heiles_section_states
from .henon_heiles import section_plane as section_plane
from .indicators import ChaosIndicators as ChaosIndicators
from .indicators import chaos_indicators as chaos_indicators
from .indicators import fast_lyapunov_indicator as fast_lyapunov_indicator
from .indicators import megno as megno
from .lyapunov import LyapunovSpectrum as LyapunovSpectrum
from .lyapunov import lyapunov_spectrum as lyapunov_spectrum
from .plotting import draw_section as draw_section
from .plotting import plot_poincare_section as plot_poincare_section
from .sections import PoincareSection as PoincareSection
from .sections import poincare_section as poincare_section
