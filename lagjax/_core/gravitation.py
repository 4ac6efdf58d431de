r"""`Gravitation`: what a gravitating system declares about itself.

A separable Hamiltonian $H = T(p) + V(q)$ whose potential is attractive and
vanishes at infinity ($V < 0$: Newtonian gravity, an attractive Coulomb force) can be
integrated in fictitious time with the logarithmic Hamiltonian
(`lagjax.solvers.time_transformed`), whose step shrinks in proportion to the
separation. Whether that beats an adaptive Runge–Kutta method depends on how many
bodies there are (two: the orbit is kept exactly, only its timing errs; more: the
encounters set the error) and on the time scale that makes the fictitious step
dimensionless. A system says both through `AbstractSystem.gravitation`;
`lagjax._integrate.geometric_choice` decides.

References: Mikkola & Tanikawa, Celest. Mech. Dyn. Astron. 74, 287 (1999);
Preto & Tremaine, Astron. J. 118, 2532 (1999); Aarseth, *Gravitational N-Body
Simulations*, CUP (2003), §1.4 (the crossing time).
"""

from __future__ import annotations

from typing import Any, NamedTuple


class Gravitation(NamedTuple):
    r"""A gravitating separable system's declaration.

    - `bodies`: how many bodies attract each other (2: a Kepler problem, in
      relative or inertial coordinates).
    - `dynamical_time`: $\tau$, one radian of its typical orbit: $\sqrt{a^3/\mu}$
      for a Kepler orbit, the crossing time $G M^{5/2} / (2|E|)^{3/2}$ for a
      self-gravitating cluster. The fictitious step is measured in units of
      $2|E|\,\tau$ (an action: $ds = dt\,(-V)$, and $\langle -V\rangle = 2|E|$ by
      the virial theorem), so $2|E|\tau/ds$ is the number of steps per $\tau$.
    """

    bodies: int
    dynamical_time: Any
