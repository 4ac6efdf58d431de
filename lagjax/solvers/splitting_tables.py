r"""Coefficient tables of the splitting and composition methods in `splitting.py`.

A symmetric composition of Störmer–Verlet steps with weights $\gamma_1..\gamma_m$
becomes the kick–drift table $a = \gamma$, $b = (\gamma_1/2, (\gamma_1 +
\gamma_2)/2, \ldots, \gamma_m/2)$ (`merged_kicks`); a partitioned Runge–Kutta
splitting (Blanes & Moan) is given directly by its kick and drift coefficients.
Every table is palindromic (the methods are time-reversible) and is printed here
with the digits of its published source; the free middle coefficient follows from
consistency (the coefficients of each flow sum to one).

Which to use: on Kepler e = 0.6 over 1000 periods (`benchmarks/kepler_saved.py`)
an energy error below 1e-10 at every saved state took about 950 force evaluations
per period with Blanes–Moan's optimised sixth-order S10, 1300 with Kahan–Li's
eighth-order s17odr8a, 1400 with Yoshida's sixth order and 1750 with
Sofroniou–Spaletta's tenth-order s35odr10.

References:

- Yoshida, Phys. Lett. A 150, 262 (1990).
- Kahan & Li, Math. Comp. 66, 1089 (1997).
- Blanes & Moan, J. Comput. Appl. Math. 142, 313 (2002), Tables 2 and 3.
- Sofroniou & Spaletta, Optim. Methods Softw. 20, 597 (2005).
- Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed., Springer
  (2006), §V.3.2 (the composition tables to 26 digits).
"""

import itertools
from collections.abc import Sequence


def merged_kicks(weights: Sequence[float]) -> tuple[float, ...]:
    """Kick coefficients of a composition of kick–drift–kick Verlet steps."""
    inner = [(left + right) / 2 for left, right in itertools.pairwise(weights)]
    return (weights[0] / 2, *inner, weights[-1] / 2)


def palindrome(outer_half: Sequence[float], middle: float) -> tuple[float, ...]:
    """`(w1, …, wk, middle, wk, …, w1)` from the outer half and the middle weight."""
    return (*outer_half, middle, *reversed(outer_half))


# --- Coefficient tables --------------------------------------------------------
# Störmer–Verlet (velocity Verlet, kick–drift–kick); Hairer, Lubich & Wanner,
# Acta Numerica 12, 399 (2003).
VERLET_WEIGHTS = (1.0,)

# Yoshida (1990), Phys. Lett. A 150, 262: the fourth-order triple jump.
_CBRT2 = 2.0 ** (1.0 / 3.0)
YOSHIDA4_WEIGHTS = (1 / (2 - _CBRT2), -_CBRT2 / (2 - _CBRT2), 1 / (2 - _CBRT2))

# Yoshida (1990), Table 1, solution A (order 6, 7 stages); listed w3, w2, w1, and
# the middle w0 = 1 − 2(w1 + w2 + w3) follows from consistency.
_YOSHIDA6_OUTER = (0.784513610477560, 0.235573213359357, -1.17767998417887)
YOSHIDA6_WEIGHTS = palindrome(_YOSHIDA6_OUTER, 1 - 2 * sum(_YOSHIDA6_OUTER))

# Kahan & Li (1997), Math. Comp. 66, 1089, method s17odr8a (order 8, 17 stages);
# also tabulated in Hairer, Lubich & Wanner, Geometric Numerical Integration
# (2006), §V.3.2.
KAHAN_LI8_WEIGHTS = palindrome(
    (
        0.13020248308889008087881763,
        0.56116298177510838456196441,
        -0.38947496264484728640807860,
        0.15884190655515560089621075,
        -0.39590389413323757733623154,
        0.18453964097831570709183254,
        0.25837438768632204729397911,
        0.29501172360931029887096624,
    ),
    -0.60550853383003451169892108,
)

# Sofroniou & Spaletta (2005), Optim. Methods Softw. 20, 597, method s35odr10
# (order 10, 35 stages); also Hairer, Lubich & Wanner (2006), §V.3.2.
SOFSPA10_WEIGHTS = palindrome(
    (
        0.07879572252168641926390768,
        0.31309610341510852776481247,
        0.02791838323507806610952027,
        -0.22959284159390709415121340,
        0.13096206107716486317465686,
        -0.26973340565451071434460973,
        0.07497334315589143566613711,
        0.11199342399981020488957508,
        0.36613344954622675119314812,
        -0.39910563013603589787862981,
        0.10308739852747107731580277,
        0.41143087395589023782070412,
        -0.00486636058313526176219566,
        -0.39203335370863990644808194,
        0.05194250296244964703718290,
        0.05066509075992449633587434,
        0.04967437063972987905456880,
    ),
    0.04931773575959453791768001,
)

# Blanes & Moan (2002), J. Comput. Appl. Math. 142, 313, PRK method S6
# (order 4, 6 stages): the 7 outer-flow coefficients a_i act on the kick (so the
# step costs 6 force evaluations with first-same-as-last), the 6 inner b_i on
# the drift; a4 = 1 − 2(a1 + a2 + a3) and b3 = 1/2 − (b1 + b2).
_BM4_A = (0.0792036964311957, 0.353172906049774, -0.0420650803577195)
_BM4_B = (0.209515106613362, -0.143851773179818)
BLANES_MOAN4_KICKS = palindrome(_BM4_A, 1 - 2 * sum(_BM4_A))
BLANES_MOAN4_DRIFTS = (*_BM4_B, 0.5 - sum(_BM4_B), 0.5 - sum(_BM4_B), *reversed(_BM4_B))

# Blanes & Moan (2002), Table 2, PRK method S10 (order 6, 10 stages): 11 kick
# coefficients a_i with a6 = 1 − 2(a1 + … + a5), 10 drift coefficients b_i with
# b5 = 1/2 − (b1 + … + b4); 10 force evaluations per step with first-same-as-last.
_BM6_A = (
    0.0502627644003922,
    0.413514300428344,
    0.0450798897943977,
    -0.188054853819569,
    0.541960678450780,
)
_BM6_B = (0.148816447901042, -0.132385865767784, 0.067307604692185, 0.432666402578175)
BLANES_MOAN6_KICKS = palindrome(_BM6_A, 1 - 2 * sum(_BM6_A))
BLANES_MOAN6_DRIFTS = (*_BM6_B, 0.5 - sum(_BM6_B), 0.5 - sum(_BM6_B), *reversed(_BM6_B))

# Blanes & Moan (2002), Table 3, RKN method SRKN_11^b (order 6 when T is quadratic
# in p, so that [V, [V, [V, T]]] = 0): 12 kick coefficients b_1..b_6, b_6..b_1 with
# b6 = 1/2 − (b1 + … + b5), 11 drift coefficients a_1..a_6..a_1 with
# a6 = 1 − 2(a1 + … + a5); 11 force evaluations per step with first-same-as-last.
_BMN6_KICK = (
    0.0414649985182624,
    0.198128671918067,
    -0.0400061921041533,
    0.0752539843015807,
    -0.0115113874206879,
)
_BMN6_DRIFT = (
    0.123229775946271,
    0.290553797799558,
    -0.127049212625417,
    -0.246331761062075,
    0.357208872795928,
)
BLANES_MOAN_NYSTROM6_KICKS = (
    *_BMN6_KICK,
    0.5 - sum(_BMN6_KICK),
    0.5 - sum(_BMN6_KICK),
    *reversed(_BMN6_KICK),
)
BLANES_MOAN_NYSTROM6_DRIFTS = palindrome(_BMN6_DRIFT, 1 - 2 * sum(_BMN6_DRIFT))
