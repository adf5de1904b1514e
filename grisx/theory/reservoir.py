"""Weighted reservoir sampling: RIS and GRIS in one pass over the candidates.

A reservoir (Chao 1982; Bitterli et al. 2020) streams candidates with
resampling weights w_l and keeps one of them, each with probability
w_l / Σ w, in O(1) memory. grisx's :class:`Reservoir` holds the
bookkeeping of seed 004's Algorithm 1:

``w_sum``       Σ w_l of everything streamed so far;
``target``      p̂(y) of the kept sample y, in the reservoir's own domain;
``confidence``  c (seed 001's α, ReSTIR's M): how many candidates' worth of
                information the reservoir holds — the weight it gets in MIS;
``ucw``         the unbiased contribution weight W_y = w_sum / p̂(y)
                (seed 000, Eq. 8), set by :func:`reservoir_finalize`;
``selected``    whether the most recent update kept its incoming candidate.

The sample itself is *not* in the struct: its type depends on the problem
(a float on a toy, a path record in a renderer). After
``r = reservoir_update(r, ...)`` the caller copies the candidate's payload
when ``r.selected`` is true — pbrt-v4's ``WeightedReservoirSampler::Add``
returns the same answer as a bool. (A flag in the returned record rather than a
second return value: Warp's CPU back end compiles tuple returns ~1.4× slower.)

Weights must already contain the MIS weight m_l (seed 000, Eq. 6 and 9), so
finalizing never divides by M: with m_l = 1/M the result is the classic
W = (1/(M p̂(y))) Σ p̂/p of seed 004, Eq. 7.

Merging a reservoir r' into r (seed 004, Alg. 1 MERGE) is one more GRIS
candidate: its sample shifted into r's domain, weighted by Eq. 9 with W = r'.ucw,
carrying r'.confidence. :func:`reservoir_merge` does exactly that.

Random decisions take ``u`` in [0, 1) from the caller (see
:mod:`grisx.theory.random`); nothing here draws numbers of its own.
"""

from __future__ import annotations

import warp as wp

from grisx.theory.gris import resampling_weight

__all__ = [
    "Reservoir",
    "reservoir_empty",
    "reservoir_update",
    "reservoir_merge",
    "reservoir_finalize",
    "reservoir_finalize_mis",
    "confidence_capped",
    "reservoir_retarget",
    "reservoir_drop",
]


@wp.struct
class Reservoir:
    """Bookkeeping of one reservoir (seed 004, Alg. 1); the kept sample lives beside it."""

    w_sum: float
    target: float
    confidence: float
    ucw: float
    selected: wp.bool


@wp.func
def reservoir_empty() -> Reservoir:
    """A reservoir that has seen nothing: every field 0."""
    r = Reservoir()
    r.w_sum = 0.0
    r.target = 0.0
    r.confidence = 0.0
    r.ucw = 0.0
    r.selected = False
    return r


@wp.func
def reservoir_update(r: Reservoir, w: float, target: float, confidence: float, u: float) -> Reservoir:
    """Stream one candidate of weight ``w`` (seed 004, Alg. 1 UPDATE).

    ``target`` is p̂ of the candidate in this reservoir's domain and
    ``confidence`` what it adds to c. In the returned reservoir,
    ``selected`` is true when the candidate was kept: the caller stores it
    as the new sample then. Weights that are 0, negative or NaN add
    confidence but are never kept.
    """
    out = r
    out.confidence = r.confidence + confidence
    out.selected = False
    if w > 0.0:
        out.w_sum = r.w_sum + w
        # Keep with probability w / w_sum. The first positive candidate is
        # always kept, even where u·w_sum rounds up to w in float32.
        if r.w_sum <= 0.0 or u * out.w_sum < w:
            out.target = target
            out.selected = True
    return out


@wp.func
def reservoir_merge(
    r: Reservoir, other: Reservoir, mis: float, target_shifted: float, jacobian: float, u: float
) -> Reservoir:
    """Merge reservoir ``other`` into ``r`` as one GRIS candidate (seed 004, Alg. 1 MERGE).

    ``target_shifted`` is p̂ of other's sample after the shift into r's domain,
    ``jacobian`` the shift's |∂T/∂x| and ``mis`` its MIS weight; the resampling
    weight is seed 000's Eq. 9 with W = other.ucw. ``selected`` as in :func:`reservoir_update`.
    """
    w = resampling_weight(mis, target_shifted, other.ucw, jacobian)
    return reservoir_update(r, w, target_shifted, other.confidence, u)


@wp.func
def reservoir_finalize(r: Reservoir) -> Reservoir:
    """Set the UCW W = w_sum / p̂(y) (seed 000, Eq. 8); 0 for an empty reservoir."""
    out = r
    out.ucw = 0.0
    if r.target > 0.0 and r.w_sum > 0.0:
        out.ucw = r.w_sum / r.target
    return out


@wp.func
def reservoir_finalize_mis(r: Reservoir, mis: float) -> Reservoir:
    """W = m(y) · w_sum / p̂(y): the MIS weight of the *kept* sample applied after selection.

    This is the 1/Z form of Bitterli et al. 2020, Sec. 4.3: candidates are streamed
    with weights c_i · p̂(x_i) · W_i (``reservoir_merge`` with ``mis = c_i``) and
    the kept sample y gets m(y) = 1/Z(y), Z(y) the total confidence of the domains
    that can produce y — seed 004, Alg. 3 l. 6 (Z = M) and Alg. 4 l. 16–19
    (support counting, :func:`~grisx.theory.mis.support_mis`). Unbiased when
    Σ_i c_i m(y) [y ∈ supp_i] = 1. ``mis`` ≤ 0 gives W = 0.
    """
    out = reservoir_finalize(r)
    if mis > 0.0:
        out.ucw = out.ucw * mis
    else:
        out.ucw = 0.0
    return out


@wp.func
def confidence_capped(confidence: float, cap: float) -> float:
    """min(c, cap): the history cap of ReSTIR (e.g. 20 in seed 004); cap <= 0 means no cap."""
    if cap > 0.0:
        return wp.min(confidence, cap)
    return confidence


@wp.func
def reservoir_retarget(r: Reservoir, target: float) -> Reservoir:
    """The kept sample's p̂ re-evaluated in its own domain (e.g. as the shifts measure it): W then uses it.

    A kept sample whose new p̂ is 0 cannot be weighted: the reservoir drops it (:func:`reservoir_drop`).
    """
    if not (target > 0.0):
        return reservoir_drop(r)
    out = r
    out.target = target
    return out


@wp.func
def reservoir_drop(r: Reservoir) -> Reservoir:
    """Forget the kept sample (no weight, W = 0) but keep the confidence: the history of what was seen stays."""
    out = reservoir_empty()
    out.confidence = r.confidence
    return out
