"""Russian roulette: ending paths early without bias.

A path tracer that continues a path with probability q and divides what the
continuation gathers by q has the same expectation as one that always
continues (Arvo and Kirk 1990): E[1{u < q} · L / q] = L. The only condition
is q > 0 wherever L ≠ 0. The choice of q is about variance and time; grisx
uses Mitsuba 3's rule (``path.py``: from ``rr_depth`` on,

    q = min(max_c β_c · η², 0.95),

β the path throughput f/p so far and η the product of the relative indices
of refraction crossed, so a path that has lost most of its energy is likely
to end, and one that gained radiance by refraction into a denser medium is
not punished for it).

For path *reuse* the roulette is part of the path's sampling: the survival
probabilities multiply the path's density, p(x̄) = Π p(ω_l) · Π q_l. A
random-replay shift replays the roulette decisions with the same uniforms
and the destination's own q (the decision ``u < q'`` may fail there, and
then the shift is undefined), so its Jacobian Π p / Π p' includes the q's.
A reconnection keeps the suffix's vertices and needs no density for them:
no q enters its Jacobian.

References: J. Arvo, D. Kirk, "Particle transport and image synthesis",
SIGGRAPH 1990; Mitsuba 3, ``src/integrators/path.cpp``; D. Lin et al.,
"Generalized resampled importance sampling", SIGGRAPH 2022, Sec. 7.
"""

from __future__ import annotations

import warp as wp

__all__ = ["roulette_survival", "ROULETTE_MAX"]

#: the largest survival probability (Mitsuba's 0.95): every path ends eventually
ROULETTE_MAX = wp.constant(0.95)


@wp.func
def roulette_survival(throughput: wp.vec3, eta: float) -> float:
    """q = min(max_c β_c · η², 0.95): the probability of continuing a path of throughput β (Mitsuba's rule)."""
    return wp.min(wp.max(throughput) * eta * eta, ROULETTE_MAX)
