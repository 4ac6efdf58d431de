"""Phase-space tools: Lyapunov spectra, Poincaré sections, chaos indicators, frequencies.

All act on an autonomous system's flow, built from `lj.simulate` and differentiated
exactly with `jax.jvp`; the per-orbit tools vmap over a batch of initial states.
"""

from lagjax.phase_space.energy_shell import (
    states_on_energy_shell as states_on_energy_shell,
)
from lagjax.phase_space.frequency import Frequencies as Frequencies
from lagjax.phase_space.frequency import (
    fundamental_frequencies as fundamental_frequencies,
)
from lagjax.phase_space.henon_heiles import henon_heiles as henon_heiles
from lagjax.phase_space.henon_heiles import (
    henon_heiles_section_states as henon_heiles_section_states,
)
from lagjax.phase_space.henon_heiles import section_plane as section_plane
from lagjax.phase_space.indicators import ChaosIndicators as ChaosIndicators
from lagjax.phase_space.indicators import chaos_indicators as chaos_indicators
from lagjax.phase_space.indicators import (
    fast_lyapunov_indicator as fast_lyapunov_indicator,
)
from lagjax.phase_space.indicators import megno as megno
from lagjax.phase_space.lyapunov import LyapunovSpectrum as LyapunovSpectrum
from lagjax.phase_space.lyapunov import lyapunov_spectrum as lyapunov_spectrum
from lagjax.phase_space.plotting import draw_section as draw_section
from lagjax.phase_space.plotting import plot_poincare_section as plot_poincare_section
from lagjax.phase_space.sections import PoincareSection as PoincareSection
from lagjax.phase_space.sections import poincare_section as poincare_section
