"""ReSTIR PT with decoupled shading (Wyman & Panteleev 2021): every reuse candidate shades the pixel.

A reuse pass streams candidates z_l with resampling weights w_l (seed 000, Eq. 9) and keeps one,
y, with W_y = Σ w / p̂(y); ReSTIR PT shades f(y) W_y. Its expectation over the selection, given
the candidates, is

    E[f(y) W_y | z_1 … z_L] = Σ_l (w_l / Σ w) f(z_l) Σ w / p̂(z_l) = Σ_l w_l f(z_l) / p̂(z_l),

so shading with every candidate (:func:`grisx.theory.control_variate.decoupled_contribution`)
is unbiased wherever f(y) W_y is, and removes the selection's share of the noise — colour noise
included, but only over the few candidates of one pass (seed 002, Sec. 4 and Fig. 2c, 7). Per frame,
with ReSTIR PT's passes (:class:`~grisx.render.restir_pt.PixelEstimateHooks`, the kernels shared):

``# ---- initial candidates ----``
    Σ w f/p̂ over the streamed candidates: the MC estimate the reservoir carries anyway.
``# ---- temporal reuse ----``
    the two candidates' Σ w f/p̂ (the canonical path and the shifted history path); no colour
    history is kept across frames (what seed 002's Fig. 7 contrasts with ReSTCV).
``# ---- spatial reuse ----``
    Σ w f/p̂ over the canonical path and the shifted neighbour paths, averaged with the input
    estimate by candidate counts (the input weighted as 2, the temporal pass's two candidates;
    any fixed weights keep it unbiased), as the ``chromatic-cv`` toy's ``decoupled`` does.
``# ---- shading ----``
    L_e(x₁) + the estimate.

The reservoirs, and so the resampling, are ReSTIR PT's unchanged. Seed 002 notes that decoupled
shading is ReSTCV with a zero neighbour integrand (tested on the toy).

References: C. Wyman, A. Panteleev, "Rearchitecting spatiotemporal resampling for production",
HPG 2021; Z. Shi et al., SIGGRAPH 2026 (seed 002), Sec. 4, 6.
"""

from __future__ import annotations

from typing import Any

import warp as wp

from grisx.render.base.path_shift import PathReservoir, PathSample, path_target
from grisx.render.base.registry import METHODS, RenderMethod, create_renderer, register
from grisx.render.base.screen import kernel_cache
from grisx.render.restir_pt import PixelEstimateHooks, ReSTIRPT, SpatialStep, TemporalStep, build_restir_pt_kernels, shade_estimate
from grisx.scene.gbuffer import GBufferData
from grisx.theory.control_variate import CVOptions, cv_composite_add, cv_composite_empty, cv_composite_value, decoupled_contribution
from grisx.theory.gris import resampling_weight

wp.set_module_options({"enable_backward": False})

__all__ = ["ReSTIRPTDecoupled", "create_restir_pt_decoupled", "make_decoupled_kernels", "DECOUPLED_HOOKS"]

#: the weight of a spatial pass's input estimate against its own candidates (the temporal pass's two)
_INPUT_WEIGHT = wp.constant(2.0)


@wp.func
def candidate_shading(mis: float, ucw: float, jacobian: float, z: PathSample) -> wp.vec3:
    """w f(z) / p̂(z) of one candidate z of this pixel (shifted here; w: seed 000, Eq. 9)."""
    t = path_target(z)  # 0 where the shift failed
    return decoupled_contribution(resampling_weight(mis, t, ucw, jacobian), t, z.f)


@wp.struct
class SpatialDecoupled:
    """A spatial pass's input estimate, and Σ w f/p̂ over its candidates so far with their count."""

    before: wp.vec3
    shaded: wp.vec3
    count: float


# ---- temporal reuse ----
@wp.func
def decoupled_temporal(o: CVOptions, g: GBufferData, g_prev: GBufferData, t: TemporalStep, res: PathReservoir) -> PathReservoir:
    """GRIS's temporal reservoir shaded by its two candidates: the canonical path and T_{j→i}(y_prev)."""
    out = res
    out.estimate = candidate_shading(t.m_c, t.can.res.ucw, 1.0, t.can.path) + candidate_shading(t.m_t, t.prev.res.ucw, t.s_t.jacobian, t.s_t.path)
    return out


# ---- spatial reuse ----
@wp.func
def decoupled_spatial_begin(o: CVOptions, can: PathReservoir) -> SpatialDecoupled:
    s = SpatialDecoupled()
    s.before = can.estimate
    s.shaded = wp.vec3(0.0)
    s.count = 0.0
    return s


@wp.func
def decoupled_spatial_add(o: CVOptions, s: SpatialDecoupled, g: GBufferData, st: SpatialStep) -> SpatialDecoupled:
    """Neighbour j's shifted path T_{q→i}(y_q) shades the pixel."""
    out = s
    out.shaded = s.shaded + candidate_shading(st.m_q, st.other.res.ucw, st.s_qi.jacobian, st.s_qi.path)
    out.count = s.count + 1.0
    return out


@wp.func
def decoupled_spatial_end(s: SpatialDecoupled, can: PathReservoir, m_c: float, res: PathReservoir) -> PathReservoir:
    """The canonical path's share, then the pass's Σ w f/p̂ averaged with the input estimate by candidate counts."""
    shaded = s.shaded + candidate_shading(m_c, can.res.ucw, 1.0, can.path)
    c = cv_composite_add(cv_composite_empty(), s.before, _INPUT_WEIGHT)
    c = cv_composite_add(c, shaded, s.count + 1.0)
    out = res
    out.estimate = cv_composite_value(c)
    return out


# ---- shading: L_e(x₁) + the estimate; the hooks into ReSTIR PT's passes ----
DECOUPLED_HOOKS = PixelEstimateHooks(
    owner=__name__,
    temporal=decoupled_temporal,
    spatial_begin=decoupled_spatial_begin,
    spatial_add=decoupled_spatial_add,
    spatial_end=decoupled_spatial_end,
    shade=shade_estimate,
    spatial_state=SpatialDecoupled,
)


@kernel_cache
def make_decoupled_kernels(kinds: frozenset[int]) -> dict[str, Any]:
    """ReSTIR PT's passes shading every reuse candidate, for the material kinds ``kinds`` (cached)."""
    return build_restir_pt_kernels(kinds, DECOUPLED_HOOKS)


class ReSTIRPTDecoupled(ReSTIRPT):
    """ReSTIR PT with decoupled shading (module docstring); the params and defaults are ReSTIR PT's."""

    def make_kernels(self, kinds: frozenset[int]) -> dict[str, Any]:
        return make_decoupled_kernels(kinds)


def create_restir_pt_decoupled(ctx: Any) -> ReSTIRPTDecoupled:
    return create_renderer(ReSTIRPTDecoupled, ctx)


# ---- registration (grisx.render.base.registry) ----

register(
    RenderMethod(
        "restir-pt-decoupled",
        "ReSTIR PT with decoupled shading (Wyman & Panteleev 2021): every reuse candidate shades the pixel",
        create_restir_pt_decoupled,
        params=METHODS["restir-pt"].params,
    )
)
