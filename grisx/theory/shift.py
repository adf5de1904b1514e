"""Shift maps: moving a sample from one domain to another, with its Jacobian.

A shift map T: Ω_j → Ω_i carries a sample x of pixel j to a sample T(x) of
pixel i so that GRIS can reuse it (seed 000, Eq. 9). The resampling weight
needs |∂T/∂x|, and MIS needs the inverse direction (seed 001, Eq. 16). In
practice T is a *partial* bijection: defined on Ω_j' ⊂ Ω_j only (seed 000,
Sec. 3.1), so every shift reports whether it succeeded.

:class:`ShiftResult` is that record — shifted sample, Jacobian, validity —
for one-dimensional sample spaces (the toys); renderers define path records
with the same three fields.

**Reconnection** (seed 004, Eq. 11). A path x₁^q → x₂^q sampled at pixel q in
solid angle at x₁^q is reused at pixel r by connecting r's visible point x₁^r
to the same x₂^q. The map between the two direction spaces has

    |J_{q→r}| = |cos φ₂^r| / |cos φ₂^q| · (‖x₁^q − x₂^q‖ / ‖x₁^r − x₂^q‖)^(n−1)

where φ₂ are the angles between the connecting segments and the normal at
x₂^q, and n is the dimension of the scene: n = 3 gives seed 004's squared
distances, n = 2 (flatland, where solid angle is plane angle and dω = cos φ
dA / r) gives the plain ratio. :func:`reconnection_jacobian` is that
formula; ``reconnection_jacobian_2d`` / ``_3d`` compute its inputs from points.

**Bounded Jacobians.** A shift whose |J| is huge multiplies one sample's
weight by it: a firefly. Declaring such shifts *undefined* keeps GRIS
unbiased as long as the MIS weights see the same partial bijection
(seed 000, Sec. 3.1): :func:`jacobian_bounded` is that rule, one-sided
(|J| ≤ τ, with every domain counted in Z by the same test: ReSTIR GI) or
symmetric (|J| ∈ [1/τ, τ], so T and T⁻¹ are rejected together: path shifts).

**Random replay** (Lin et al. 2022, Sec. 7). A path regenerated at pixel r
from pixel q's random numbers u has, in path space (solid-angle product
measure), the Jacobian of ω ↦ u ↦ ω' — the ratio of the sampling densities
of the replayed directions,

    |J_{q→r}| = Π_l p_q(ω_l) / Π_l p_r(ω'_l),

(:func:`replay_jacobian`); the hybrid shift multiplies it with Eq. 11 at its
reconnection vertex.
"""

from __future__ import annotations

from typing import Any

import warp as wp

__all__ = [
    "ShiftResult",
    "shift_result",
    "shift_failed",
    "reconnection_jacobian",
    "reconnection_jacobian_2d",
    "reconnection_jacobian_3d",
    "replay_jacobian",
    "jacobian_bounded",
    "JACOBIAN_BOUND_ONE_SIDED",
    "JACOBIAN_BOUND_SYMMETRIC",
]

#: reject shifts with |J| > τ (ReSTIR GI's reconnections: Z counts each domain by the same test)
JACOBIAN_BOUND_ONE_SIDED = wp.constant(0)
#: reject shifts with |J| ∉ [1/τ, τ] (symmetric in J ↔ 1/J: T restricted to the accepted set stays a bijection)
JACOBIAN_BOUND_SYMMETRIC = wp.constant(1)


@wp.struct
class ShiftResult:
    """Result of shifting a 1D sample: the shifted sample, |∂T/∂x|, and whether T was defined."""

    x: float
    jacobian: float
    valid: wp.bool


@wp.func
def shift_result(x: float, jacobian: float) -> ShiftResult:
    """A successful shift to ``x`` with Jacobian determinant ``jacobian``."""
    s = ShiftResult()
    s.x = x
    s.jacobian = wp.abs(jacobian)
    s.valid = True
    return s


@wp.func
def shift_failed() -> ShiftResult:
    """A shift that is undefined for this sample (outside the partial bijection's domain)."""
    s = ShiftResult()
    s.x = 0.0
    s.jacobian = 0.0
    s.valid = False
    return s


@wp.func
def reconnection_jacobian(cos_src: float, cos_dst: float, dist_src: float, dist_dst: float, dims: int) -> float:
    """|J_{q→r}| = |cos φ₂^r|/|cos φ₂^q| · (d_q/d_r)^(n−1) (seed 004, Eq. 11; n = ``dims``).

    ``cos_src``/``dist_src`` belong to the original connection x₁^q–x₂^q,
    ``cos_dst``/``dist_dst`` to the new one x₁^r–x₂^q. Degenerate
    configurations (grazing source, zero distance) return 0: the shift fails.
    """
    if wp.abs(cos_src) <= 0.0 or dist_dst <= 0.0:
        return 0.0
    ratio = dist_src / dist_dst
    scale = ratio
    if dims == 3:
        scale = ratio * ratio
    return wp.abs(cos_dst) / wp.abs(cos_src) * scale


@wp.func
def _reconnection_jacobian_points(x1_src: Any, x1_dst: Any, x2: Any, n2: Any, dims: int) -> float:
    d_src = x1_src - x2
    d_dst = x1_dst - x2
    l_src = wp.length(d_src)
    l_dst = wp.length(d_dst)
    if l_src <= 0.0 or l_dst <= 0.0:
        return 0.0
    return reconnection_jacobian(wp.dot(n2, d_src) / l_src, wp.dot(n2, d_dst) / l_dst, l_src, l_dst, dims)


@wp.func
def reconnection_jacobian_2d(x1_src: wp.vec2, x1_dst: wp.vec2, x2: wp.vec2, n2: wp.vec2) -> float:
    """Eq. 11 in flatland: reuse sample point ``x2`` (normal ``n2``) at ``x1_dst`` instead of ``x1_src``."""
    return _reconnection_jacobian_points(x1_src, x1_dst, x2, n2, 2)


@wp.func
def reconnection_jacobian_3d(x1_src: wp.vec3, x1_dst: wp.vec3, x2: wp.vec3, n2: wp.vec3) -> float:
    """Eq. 11 in 3D: reuse sample point ``x2`` (normal ``n2``) at ``x1_dst`` instead of ``x1_src``."""
    return _reconnection_jacobian_points(x1_src, x1_dst, x2, n2, 3)


@wp.func
def replay_jacobian(pdf_src: float, pdf_dst: float) -> float:
    """|J| = Π p_src(ω_l) / Π p_dst(ω'_l) of random replay (Lin et al. 2022, Sec. 7); 0 where p_dst = 0 (the shift fails).

    ``pdf_src`` and ``pdf_dst`` are the products of the replayed directions' sampling
    densities in the source and destination domains.
    """
    if pdf_dst > 0.0 and pdf_src > 0.0:
        return pdf_src / pdf_dst
    return 0.0


@wp.func
def jacobian_bounded(jacobian: float, bound: float, symmetric: int) -> bool:
    """Whether a shift with Jacobian ``jacobian`` is kept under the bound τ = ``bound`` (τ <= 0: no bound).

    ``symmetric`` (:data:`JACOBIAN_BOUND_SYMMETRIC`): |J| ∈ [1/τ, τ], and a non-positive or non-finite J
    is rejected outright; otherwise (:data:`JACOBIAN_BOUND_ONE_SIDED`): |J| ≤ τ.
    """
    if symmetric != 0:
        if not (jacobian > 0.0) or not wp.isfinite(jacobian):
            return False
        if bound > 0.0:
            return jacobian <= bound and jacobian * bound >= 1.0
        return True
    return bound <= 0.0 or jacobian <= bound
