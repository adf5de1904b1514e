"""ReSTCV: spatio-temporal control variates inside ReSTIR PT (Shi et al. 2026, seed 002).

ReSTIR PT shades a pixel with one kept path, f(y) W_y: its UCW fits the *luminance* of the pixel,
but its colour is the colour of that one path — the colour noise of seed 002, Sec. 4 (a white
plane under a red and a green light is red or green per pixel, never yellow). ReSTCV keeps ReSTIR
PT's resampling as it is and carries, with every reservoir, an accumulated colour estimate ⟨F⟩
(``PathReservoir.estimate``, Listing 1 line 6). Per frame, with ReSTIR PT's passes
(:mod:`grisx.render.restir_pt`, whose kernels this renderer shares through
:class:`~grisx.render.restir_pt.PixelEstimateHooks`):

``# ---- initial candidates ----``
    ⟨F_i⟩_init is the MC estimate of the traced candidate paths, Σ_l f(x̄_l) / (N p(x̄_l))
    (Listing 1 line 36), streamed by ``stream_candidates`` next to the reservoir.
``# ---- temporal reuse ----``
    with j the reprojected pixel of the previous frame (Eq. 6, q_init = 1)::

        ⟨F_i⟩ = (q_init ⟨F_i⟩_init + q_j ⟨F_i⟩_{←j}) / (q_init + q_j),
        ⟨F_i⟩_{←j} = α_ij ⟨F_j⟩ + ⟨F_i − α_ij F_j⟩                           (Eq. 7)

``# ---- spatial reuse ----``
    over N̄_i, the pixel and its accepted neighbours (Eq. 8)::

        ⟨F_i⟩ = Σ_{j ∈ N̄_i} q_j ⟨F_i⟩_{←j} / Σ q_j,   ⟨F_i⟩_{←i} = ⟨F_i⟩.

``# ---- shading ----``
    L_e(x₁) + ⟨F_i⟩ instead of L_e(x₁) + f(y) W_y (Listing 1 lines 44–45).

**The difference** ⟨F_i − α F_j⟩ comes from the two input reservoirs' kept paths y_i, y_j and
the two shifts that ReSTIR PT evaluates for its MIS anyway, T_{i→j}(y_i) and T_{j→i}(y_j)::

    ⟨F_i − α F_j⟩ = ω_ij(y_i) W_i (f_i(y_i) − α f_j(T_{i→j} y_i) |J_{i→j}|)
                  − ω_ji(y_j) W_j (α f_j(y_j) − f_i(T_{j→i} y_j) |J_{j→i}|)        (Eq. 10)

with ω_ij(x) = M_i p̂_i(x) / (M_i p̂_i(x) + M_j p̂_j(T x) |J|) (Eq. 11), f the labelled
integrand m_t f of :mod:`~grisx.render.base.path_shift` and p̂ its luminance. It is unbiased
because ω_ij(x) + ω_ji(T_{i→j} x) = 1 wherever either target is positive, the shift being a
bijection where it succeeds (a failed shift gives ω = 1 and f = 0 on the other side).

**Coefficient and weights.** α_ij = min(ρ_i/ρ_j, 2) per channel from the albedos of the two
primary hits (Eq. 9; ``alpha=one``: α = 1, Fig. 3's ablation); q_j = M_j capped at 20 and
q_init = 1 (Sec. 5.3). Neither depends on the light paths sampled (only on the G-buffers), so
every composite is a fixed affine combination of unbiased estimates and ⟨F_i⟩ stays unbiased,
frame after frame, by induction.

**Known-biased ablations** (the tests show the check catches them): ``alpha=sample`` takes
Eq. 9's ρ from the samples themselves — ρ_i = f(y_i) W_i, the current reservoir's own
one-sample estimate, and ρ_j = ⟨F_j⟩ — so α correlates with the difference it multiplies;
``difference_mis=none`` drops Eq. 11 (ω = 1 on both sides: each pair's difference counted twice).
``difference_mis=balance`` is Eq. 11 with M = 1 (still unbiased); ``temporal_cv=false`` /
``spatial_cv=false`` switch one composite off while ReSTIR PT's reuse runs on (still unbiased).

**STCV** (``stcv``, Sec. 5.1, the baseline without ReSTIR): the same passes and composites, but every
pixel keeps its own frame's sample — the canonical reservoir's path y_i, drawn by RIS among the
traced path's candidates, whose UCW W_i stands in for Eq. 4's 1/p — so each difference comes from
fresh random samples of the two pixels (the history's sample for a temporal j), and its weights are
Eq. 5's balance heuristic written on the targets (``difference_mis=balance``: Eq. 11 with M = 1;
the paper's Eq. 5 weighs by the source pdfs, and any ω with ω_ij(x) + ω_ji(T x) = 1 is unbiased).
The confidences still count the history (q of the next composite). STCV's passes evaluate GRIS's
resampling weights and then drop them: cheap next to the shifts they share.

**Direct light** is handled apart, as the paper does after Lin et al. 2022 (``direct=restir-di``, the
default; ``direct=nee`` keeps it in the path reservoirs): the path candidates start at two segments
after x₁, and :class:`ReSTCVDI` (``restcv-di``, ReSTIR DI with its 8 light candidates and 3 neighbours)
estimates the **intermediate auxiliary** Ḋ_i — the direct light in colour with the glossy part of the
BSDF omitted — by the same control variates, then adds the **second-level CV** ⟨D_i − Ḋ_i⟩ =
(f − ḟ)(y) W_y from its final light sample (Sec. 5.3): ⟨D_i⟩ = ⟨Ḋ_i⟩ + ⟨D_i − Ḋ_i⟩. STCV and ICV,
which have no ReSTIR, keep direct light in their paths. Every formula — ``cv_alpha``,
``cv_estimate``, ``reservoir_difference``, ``compositing_weight``, ``cv_composite_*``,
``decoupled_contribution`` — is :mod:`grisx.theory.control_variate`'s, the functions the
``chromatic-cv`` toy is verified with.

References: Z. Shi, C. Wu, L. Wu, K. Xu, "Spatio-Temporal Control Variates with ReSTIR for
Real-Time Rendering", SIGGRAPH 2026 (seed 002), Sec. 4–5, Eq. 6–11, Listing 1; D. Lin et al.,
"Generalized resampled importance sampling", SIGGRAPH 2022.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import warp as wp

from grisx.errors import InvalidParameterError
from grisx.params import Param
from grisx.render.base.path_shift import PathReservoir
from grisx.render.base.registry import METHODS, RenderMethod, create_renderer, register, renderer_params
from grisx.render.base.screen import kernel_cache
from grisx.render.restir_di import ReSTIRDI, build_restir_di_kernels
from grisx.render.restir_pt import PixelEstimateHooks, ReSTIRPT, SpatialStep, TemporalStep, build_restir_pt_kernels, shade_estimate
from grisx.scene.gbuffer import GBufferData
from grisx.theory.control_variate import (
    ALPHA_MODES,
    ALPHA_SAMPLE,
    DIFFERENCE_MIS,
    Q_INIT,
    CVComposite,
    CVOptions,
    compositing_weight,
    cv_alpha_or_sample,
    cv_composite_add,
    cv_composite_empty,
    cv_composite_value,
    cv_from_pixel,
    cv_options,
)

wp.set_module_options({"enable_backward": False})

__all__ = ["ReSTCV", "ReSTCVDI", "STCV", "create_restcv", "create_stcv", "make_restcv_kernels", "make_stcv_kernels", "ALPHA_CHOICES", "RESTCV_HOOKS", "STCV_HOOKS"]

#: α choices of the renderer: theory's (Eq. 9's heuristic, 1) and the biased ablation ``sample``
ALPHA_CHOICES = {**ALPHA_MODES, "sample": int(ALPHA_SAMPLE)}


@wp.struct
class SpatialCV:
    """A spatial pass's Eq. 8 sums (each neighbour's f_q(T_{i→q} y_i) and |∂T_{i→q}/∂y_i|, Eq. 10's first side, come with
    its :class:`~grisx.render.restir_pt.SpatialStep`)."""

    composite: CVComposite


@wp.func
def pair_alpha(o: CVOptions, rho_i: wp.vec3, rho_j: wp.vec3, can: PathReservoir, estimate_j: wp.vec3) -> wp.vec3:
    """α_ij from the primary hits' albedos (seed 002, Eq. 9; or 1); ``sample``: ρ from the samples (biased)."""
    return cv_alpha_or_sample(o.alpha, rho_i, rho_j, can.path.f * can.res.ucw, estimate_j)


@wp.func
def from_pixel(
    o: CVOptions, alpha: wp.vec3, can: PathReservoir, other: PathReservoir, confidence_j: float,
    f_j_yi: wp.vec3, jacobian_ij: float, f_i_yj: wp.vec3, jacobian_ji: float,
) -> wp.vec3:
    """⟨F_i⟩_{←j} = α ⟨F_j⟩ + ⟨F_i − α F_j⟩ (seed 002, Eq. 7), the difference from y_i, y_j and their shifts (Eq. 10–11)."""
    r_j = other.res
    r_j.confidence = confidence_j
    return cv_from_pixel(can.res, r_j, other.estimate, can.path.f, f_j_yi, other.path.f, f_i_yj, jacobian_ij, jacobian_ji, alpha, o.difference_mis)


@wp.func
def canonical_with(can: PathReservoir, estimate: wp.vec3, confidence: float) -> PathReservoir:
    """STCV's record: the frame's own sample and UCW (no resampling) with the estimate and the confidence
    (the q of the next composite) that the pass accumulated."""
    out = can
    out.estimate = estimate
    out.res.confidence = confidence
    return out


# ---- temporal reuse ----
@wp.func
def temporal_estimate(o: CVOptions, g: GBufferData, g_prev: GBufferData, t: TemporalStep) -> wp.vec3:
    """Eq. 6: ⟨F_i⟩_init (q_init = 1) with the previous frame's ⟨F_i⟩_{←j} (q_j = M_j ≤ 20); ⟨F_i⟩_init alone without temporal CV."""
    if o.temporal == 0:
        return t.can.estimate
    alpha = pair_alpha(o, g.albedo[t.y, t.x], g_prev.albedo[t.nb.y, t.nb.x], t.can, t.prev.estimate)
    c = cv_composite_add(cv_composite_empty(), t.can.estimate, Q_INIT)
    from_j = from_pixel(o, alpha, t.can, t.prev, t.c_j, t.f_cj, t.jacobian_cj, t.s_t.path.f, t.s_t.jacobian)
    c = cv_composite_add(c, from_j, compositing_weight(t.c_j))  # seed 002, Eq. 6
    return cv_composite_value(c)


@wp.func
def restcv_temporal(o: CVOptions, g: GBufferData, g_prev: GBufferData, t: TemporalStep, res: PathReservoir) -> PathReservoir:
    """ReSTCV: GRIS's temporal reservoir carrying Eq. 6's estimate (Listing 1 lines 21–22)."""
    out = res
    out.estimate = temporal_estimate(o, g, g_prev, t)
    return out


@wp.func
def stcv_temporal(o: CVOptions, g: GBufferData, g_prev: GBufferData, t: TemporalStep, res: PathReservoir) -> PathReservoir:
    """STCV: the canonical sample carrying Eq. 6's estimate."""
    return canonical_with(t.can, temporal_estimate(o, g, g_prev, t), res.res.confidence)


# ---- spatial reuse ----
@wp.func
def spatial_begin(o: CVOptions, can: PathReservoir) -> SpatialCV:
    """Eq. 8's sums with the pixel's own term, ⟨F_i⟩_{←i} = ⟨F_i⟩ with q_i = M_i ≤ 20."""
    s = SpatialCV()
    s.composite = cv_composite_add(cv_composite_empty(), can.estimate, compositing_weight(can.res.confidence))
    return s


@wp.func
def spatial_add(o: CVOptions, s: SpatialCV, g: GBufferData, st: SpatialStep) -> SpatialCV:
    """Add q_j ⟨F_i⟩_{←j} of neighbour ``j`` (seed 002, Eq. 7–8) with T_{q→i}(y_q) from the merge loop."""
    out = s
    if o.spatial != 0:
        alpha = pair_alpha(o, g.albedo[st.y, st.x], g.albedo[st.nb.y, st.nb.x], st.can, st.other.estimate)
        conf_j = st.other.res.confidence
        from_j = from_pixel(o, alpha, st.can, st.other, conf_j, st.f_cq, st.jacobian_cq, st.s_qi.path.f, st.s_qi.jacobian)
        out.composite = cv_composite_add(s.composite, from_j, compositing_weight(conf_j))
    return out


@wp.func
def restcv_spatial_end(s: SpatialCV, can: PathReservoir, m_c: float, res: PathReservoir) -> PathReservoir:
    """ReSTCV: GRIS's spatial reservoir carrying ⟨F_i⟩ = Σ q ⟨F_i⟩_{←j} / Σ q (seed 002, Eq. 8; Listing 1 line 29)."""
    out = res
    out.estimate = cv_composite_value(s.composite)
    return out


@wp.func
def stcv_spatial_end(s: SpatialCV, can: PathReservoir, m_c: float, res: PathReservoir) -> PathReservoir:
    """STCV: the canonical sample carrying Eq. 8's estimate."""
    return canonical_with(can, cv_composite_value(s.composite), res.res.confidence)


# ---- shading: L_e(x₁) + ⟨F_i⟩; the hooks into ReSTIR PT's passes ----
RESTCV_HOOKS = PixelEstimateHooks(
    owner=__name__,
    temporal=restcv_temporal,
    spatial_begin=spatial_begin,
    spatial_add=spatial_add,
    spatial_end=restcv_spatial_end,
    shade=shade_estimate,  # L_e(x₁) + ⟨F_i⟩ (seed 002, Listing 1 line 44)
    spatial_state=SpatialCV,
)
STCV_HOOKS = dataclasses.replace(RESTCV_HOOKS, owner=__name__ + ".stcv", temporal=stcv_temporal, spatial_end=stcv_spatial_end)


@kernel_cache
def make_restcv_kernels(kinds: frozenset[int]) -> dict[str, Any]:
    """ReSTIR PT's passes with ReSTCV's estimate compiled in, for the material kinds ``kinds`` (cached)."""
    return build_restir_pt_kernels(kinds, RESTCV_HOOKS)


@kernel_cache
def make_stcv_kernels(kinds: frozenset[int]) -> dict[str, Any]:
    """ReSTIR PT's passes with STCV's estimate compiled in (canonical samples kept), for ``kinds`` (cached)."""
    return build_restir_pt_kernels(kinds, STCV_HOOKS)


def _checked_cv_options(alpha: str, difference_mis: str, temporal_cv: bool, spatial_cv: bool) -> CVOptions:
    if alpha not in ALPHA_CHOICES or difference_mis not in DIFFERENCE_MIS:
        raise InvalidParameterError(f"alpha must be one of {sorted(ALPHA_CHOICES)}, difference_mis one of {sorted(DIFFERENCE_MIS)}")
    return cv_options(ALPHA_CHOICES[alpha], DIFFERENCE_MIS[difference_mis], temporal_cv, spatial_cv)


class ReSTCV(ReSTIRPT):
    """ReSTCV over a built scene: ReSTIR PT's passes carrying the control-variate estimate (module docstring);
    direct light through :class:`ReSTCVDI` (``direct=restir-di``, the paper's) or the path reservoirs (``nee``)."""

    DIRECT_METHOD = "restcv-di"
    GBUFFER_MATERIAL = True  # α_ij from the primary hits' albedos (Eq. 9)

    def __init__(
        self, built: Any, width: int, height: int, *, alpha: str = "heuristic", difference_mis: str = "confidence",
        temporal_cv: bool = True, spatial_cv: bool = True, direct: str = "restir-di", **restir_pt: Any,
    ) -> None:
        options = _checked_cv_options(alpha, difference_mis, temporal_cv, spatial_cv)
        self.alpha = alpha
        self.difference_mis = difference_mis
        self.cv_choices = {"alpha": alpha, "difference_mis": difference_mis, "temporal_cv": temporal_cv, "spatial_cv": spatial_cv}
        super().__init__(built, width, height, direct=direct, **restir_pt)
        self.cv_options = options

    def direct_params(self) -> dict[str, Any]:
        return dict(self.cv_choices)  # the same control variates on direct light

    def make_kernels(self, kinds: frozenset[int]) -> dict[str, Any]:
        return make_restcv_kernels(kinds)


class STCV(ReSTCV):
    """The STCV baseline: the same control variates, differences from each frame's own samples (module docstring);
    no ReSTIR, so direct light stays in its path estimate."""

    def __init__(
        self, built: Any, width: int, height: int, *, alpha: str = "heuristic", difference_mis: str = "balance",
        temporal_cv: bool = True, spatial_cv: bool = True, **restir_pt: Any,
    ) -> None:
        if restir_pt.pop("direct", "nee") != "nee":
            raise InvalidParameterError(f"{type(self).__name__.lower()} has no ReSTIR: direct light stays in its path estimate (direct=nee)")
        super().__init__(
            built, width, height, alpha=alpha, difference_mis=difference_mis, temporal_cv=temporal_cv, spatial_cv=spatial_cv, direct="nee", **restir_pt
        )

    def make_kernels(self, kinds: frozenset[int]) -> dict[str, Any]:
        return make_stcv_kernels(kinds)


class ICV(STCV):
    """Image-space control variates (Rousselle et al. 2016), the offline reference point of seed 002:
    STCV's spatial composite (Eq. 8) within each frame alone — no history, no temporal composite."""

    def __init__(self, built: Any, width: int, height: int, *, alpha: str = "heuristic", difference_mis: str = "balance",
                 spatial_cv: bool = True, **restir_pt: Any) -> None:
        if restir_pt.pop("temporal", False) or restir_pt.pop("temporal_cv", False):
            raise InvalidParameterError("icv works within one frame: temporal reuse does not apply (use stcv or restcv)")
        super().__init__(built, width, height, alpha=alpha, difference_mis=difference_mis, temporal_cv=False,
                         spatial_cv=spatial_cv, temporal=False, **restir_pt)


# ---- direct light: ReSTIR DI carrying ⟨Ḋ_i⟩ (seed 002, Sec. 5.3) ----
@kernel_cache
def make_restcv_di_kernels(kinds: frozenset[int]) -> Any:
    """ReSTIR DI's passes with ReSTCV's auxiliary estimate compiled in, for ``kinds`` (cached)."""
    return build_restir_di_kernels(kinds, cv=True)


class ReSTCVDI(ReSTIRDI):
    """ReSTCV on direct light (seed 002, Sec. 5.3): ReSTIR DI's resampling unchanged, and with it

    * the **intermediate auxiliary** Ḋ_i: the direct light with its glossy part omitted — ḟ(y) =
      f_diffuse L_e G V, in colour (ReSTIR DI's proxy target p̂ is its luminance); grisx's diffuse
      BSDF is all diffuse lobe and its conductors and dielectrics all glossy, so ḟ = f or 0;
    * ⟨Ḋ_i⟩ by the control variates of the path version: ⟨Ḋ_i⟩_init = ḟ(y_i) W_i of the visibility-tested
      canonical sample, Eq. 6–8 with differences (Eq. 10–11) from the light samples and the targets
      the pairwise MIS evaluates anyway (light samples move by the identity, |J| = 1), q and α as for paths;
    * the **second-level control variate** ⟨D_i⟩ = ⟨Ḋ_i⟩ + ⟨D_i − Ḋ_i⟩, the difference from the final
      reservoir's sample: (f − ḟ)(y) W_y — zero on diffuse surfaces, f(y) W_y (ReSTIR DI's own estimate)
      on glossy ones, whose high-frequency lobe the identity shift would reuse badly.

    ``unbiased=false`` drops visibility from the targets at other pixels, and so from the differences: biased.
    """

    GBUFFER_MATERIAL = True  # α_ij from the primary hits' albedos (Eq. 9)

    def __init__(
        self, built: Any, width: int, height: int, *, alpha: str = "heuristic", difference_mis: str = "confidence",
        temporal_cv: bool = True, spatial_cv: bool = True, **restir_di: Any,
    ) -> None:
        options = _checked_cv_options(alpha, difference_mis, temporal_cv, spatial_cv)
        super().__init__(built, width, height, **restir_di)
        self.cv_options = options

    def make_kernels(self, kinds: frozenset[int]) -> Any:
        return make_restcv_di_kernels(kinds)


def create_restcv_di(ctx: Any) -> ReSTCVDI:
    return create_renderer(ReSTCVDI, ctx)


def create_restcv(ctx: Any) -> ReSTCV:
    return create_renderer(ReSTCV, ctx)


def create_stcv(ctx: Any) -> STCV:
    return create_renderer(STCV, ctx)


def create_icv(ctx: Any) -> ICV:
    return create_renderer(ICV, ctx)


def _cv_params(cls: type, temporal: bool = True, base_method: str = "restir-pt") -> tuple[Param, ...]:
    """``base_method``'s params and defaults (the same shifts, reuse and depth), plus the control variates' own
    (without the temporal ones for a method that works within one frame); ``direct`` with ``cls``'s default,
    for ReSTCV only (STCV and ICV have no ReSTIR for direct light)."""
    own = [
        Param("alpha", ..., "CV coefficient: heuristic (Eq. 9's min(rho_i/rho_j, 2) per channel), one, or sample (biased: rho from the samples)", kind="choice", choices=tuple(ALPHA_CHOICES)),
        Param("difference_mis", ..., "weights of Eq. 10: confidence (Eq. 11), balance (Eq. 11 with M = 1) or none (biased: omega = 1)", kind="choice", choices=tuple(DIFFERENCE_MIS)),
        Param("temporal_cv", ..., "temporal control variates (Eq. 6); false: the temporal pass keeps the frame's own estimate", kind="bool"),
        Param("spatial_cv", ..., "spatial control variates (Eq. 8); false: the spatial pass keeps its input estimate", kind="bool"),
    ]
    base = tuple(p for p in METHODS[base_method].params if p.name != "direct")
    if cls is ReSTCV:
        own.append(Param("direct", ..., "direct light: restir-di (ReSTIR DI with the control variates of Sec. 5.3, the paper's) or nee (inside the path reservoirs)", kind="choice", choices=("restir-di", "nee")))
    if not temporal:
        own = [p for p in own if p.name != "temporal_cv"]
        base = tuple(p for p in base if p.name not in ("temporal", "history_cap"))
    return base + renderer_params(cls, *own)


# ---- registration (grisx.render.base.registry) ----

register(
    RenderMethod(
        "restcv",
        "ReSTCV (Shi et al. 2026): ReSTIR PT shading an accumulated colour estimate with spatio-temporal control variates",
        create_restcv,
        params=_cv_params(ReSTCV),
    )
)
register(
    RenderMethod(
        "restcv-di",
        "ReSTCV on direct light (Shi et al. 2026, Sec. 5.3): ReSTIR DI carrying the auxiliary estimate and a second-level control variate; emitted + direct light",
        create_restcv_di,
        reference_max_depth=2,
        params=_cv_params(ReSTCVDI, base_method="restir-di"),
    )
)
register(
    RenderMethod(
        "stcv",
        "STCV (Shi et al. 2026, Sec. 5.1): spatio-temporal control variates with differences from each frame's own samples, no resampling",
        create_stcv,
        params=_cv_params(STCV),
    )
)
register(
    RenderMethod(
        "icv",
        "image-space control variates (Rousselle et al. 2016; seed 002's offline reference point): STCV's spatial composite within each frame, no history",
        create_icv,
        params=_cv_params(ICV, temporal=False),
    )
)
