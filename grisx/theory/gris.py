"""Resampling weights of RIS and generalized RIS (GRIS).

Resampled importance sampling (Talbot et al. 2005) draws candidates
x₁ … x_M with pdfs p_l, weights each by

    w_l = m_l(x_l) · p̂(x_l) / p_l(x_l)                         (seed 000, Eq. 6)

and keeps one, y, with probability w_l / Σ w. The pair (y, W_y) with the
*unbiased contribution weight* (UCW)

    W_y = (1 / p̂(y)) · Σ_l w_l                                 (seed 000, Eq. 8)

estimates ∫ f by ``f(y) · W_y`` (Eq. 7) for any MIS weights m_l that sum to
one wherever f ≠ 0 — with m_l = 1/M this is the classic RIS estimator
(seed 004, Eq. 7).

Generalized RIS (Lin et al. 2022) takes candidates from *other* domains: a
sample x_l of domain Ω_l with its own UCW W_{x_l} is moved into the target
domain by a shift map T_l and weighted by

    w_l = m_l(T_l(x_l)) · p̂(T_l(x_l)) · W_{x_l} · |∂T_l/∂x_l|    (seed 000, Eq. 9; seed 003, Eq. 10)

Eq. 6 is the special case T = identity, W = 1/p. Because W replaces the
unknown pdf, GRIS can be applied again to its own output: that chain is ReSTIR.

Every renderer and toy computes its weights through :func:`resampling_weight`;
there is no other copy of Eq. 9 in grisx.

A colour integrand needs a scalar target: grisx uses its :func:`luminance`
(Rec. 709 weights as Mitsuba gives them), p̂ = lum(f), everywhere — in the
toys, the ReSTIR renderers and the light-selection powers alike.
"""

from __future__ import annotations

import warp as wp

__all__ = ["resampling_weight", "ris_weight", "ucw_from_source_pdf", "luminance", "LUMINANCE_WEIGHTS"]

#: Rec. 709 luminance weights of linear RGB, as Mitsuba 3 gives them
LUMINANCE_WEIGHTS = (0.212671, 0.715160, 0.072169)
_LUMINANCE = wp.constant(wp.vec3(*LUMINANCE_WEIGHTS))


@wp.func
def luminance(c: wp.vec3) -> float:
    """lum(c): the scalar resampling target p̂ of a colour integrand value c."""
    return wp.dot(c, _LUMINANCE)


@wp.func
def ucw_from_source_pdf(source_pdf: float) -> float:
    """W = 1/p for a sample drawn directly from ``source_pdf`` (0 where p = 0: it cannot occur)."""
    if source_pdf > 0.0:
        return 1.0 / source_pdf
    return 0.0


@wp.func
def resampling_weight(mis: float, target: float, ucw: float, jacobian: float) -> float:
    """GRIS weight w = m · p̂(T(x)) · W_x · |∂T/∂x| (seed 000, Eq. 9).

    ``target`` is p̂ evaluated at the *shifted* sample, ``ucw`` the sample's UCW
    in its source domain and ``jacobian`` |∂T/∂x| of the shift. Non-positive or
    NaN factors give weight 0, never NaN.
    """
    w = mis * target * ucw * wp.abs(jacobian)
    if w > 0.0:  # false for NaN too
        return w
    return 0.0


@wp.func
def ris_weight(mis: float, target: float, source_pdf: float) -> float:
    """RIS weight w = m · p̂(x) / p(x) (seed 000, Eq. 6): Eq. 9 with T = id, W = 1/p."""
    return resampling_weight(mis, target, ucw_from_source_pdf(source_pdf), 1.0)
