"""ReSTIR DI: direct lighting by spatiotemporal reservoir resampling (Bitterli et al. 2020).

For the visible point x of a pixel (the G-buffer's pixel-centre hit) the
direct light is

    L_d(x → ω_o) = ∫_{lights} f(x, ω_o, ω(y)) L_e(y → x) G(x, y) V(x, y) dA(y),

an integral over points y on the lights. ReSTIR DI estimates it with a
*light sample* y and an unbiased contribution weight W (seed 000, Eq. 7–8):
``L ≈ f L_e G V (y) · W``. Each frame runs the passes of Bitterli et al.
(their Alg. 5), as renderer phases:

1. **Initial candidates.** 8 light samples (power-proportional light choice,
   uniform area on triangles: :func:`~grisx.scene.lights.sample_light`),
   streamed through a reservoir with the RIS weights w = m · p̂ / p of seed
   000, Eq. 6. ``bsdf_candidates`` adds BSDF samples (the ray's first hit, if
   it is an emitter); the MIS weights m are then the balance heuristic between
   the two techniques with their candidate counts as confidences (seed 001,
   Eq. 15). The
   target p̂ is the luminance of the **unshadowed** contribution
   f L_e G (no shadow ray per candidate: that is the point of RIS).
2. **Visibility before reuse.** One shadow ray for the kept sample; an
   occluded sample gets W = 0 (Bitterli et al., Sec. 6.1). From then on the
   reservoir's target is p̂·V.
3. **Temporal reuse.** The previous frame's final reservoir at the
   reprojected pixel (integer motion vector, G-buffer similarity test of
   :mod:`grisx.render.base.reuse`) is merged with the new one; its confidence is
   capped at 20 (the history cap).
4. **Spatial reuse.** 3 neighbours uniformly within 30 px that pass the
   similarity test are merged into the temporal result.
5. **Shading.** f L_e G V (y) · W, plus the emission seen at x.

**Defaults that differ from the paper.** Bitterli et al. use 32 candidates and 5 neighbours; the
defaults here are 8 and 3. On the benchmark protocol (one H200, 1920×1080, five scenes, static and
moving camera; ``benchmarks/README.md``, "ReSTIR DI's candidates and neighbours") a frame costs
21–32% less. Per-frame relMSE rises by 1–18%, and the gain over ``pt`` at equal time is higher in
all ten cells, e.g. glossy-room 10.9 → 15.5 and cornell-box 1.16 → 1.50. Temporal and spatial
reuse already supply most of what the extra candidates and neighbours would add. Their candidates
are light samples alone, as here: a BSDF candidate (``bsdf_candidates=1``, the default until
2026-11-28) costs a ray and changed per-frame relMSE by less than 0.5% in all ten cells of the same
protocol, while frames were up to 24% shorter without it (README, "ReSTIR DI without its BSDF
candidate").

Both reuse passes weigh domains with **pairwise MIS** (Bitterli 2022, Ch. 9;
:func:`~grisx.theory.mis.pairwise_mis_neighbor` /
:func:`~grisx.theory.mis.pairwise_mis_canonical_term`) — the current pixel's
fresh (temporal pass) or temporally reused (spatial pass) reservoir is the
canonical domain. With ``unbiased=true`` every target evaluated at *another*
pixel includes that pixel's visibility (one shadow ray per evaluation, 2 per
neighbour), so each domain's target is zero exactly where it can not produce
a sample and the weights sum to one over the domains that can: unbiased.
``unbiased=false`` evaluates the unshadowed target there (no extra rays) —
cheaper, and biased dark near shadow boundaries, as in Bitterli et al.

**Measure.** A light sample is a *point on a light* (its position, normal,
and what radiates: a scene triangle or a point light), or, for the
environment, a direction. Targets are expressed in the sample's own measure:
area on emissive triangles (p̂ = lum(f L_e |cos θ_y| / ‖x − y‖²)), solid angle
for the environment, counting measure for point lights (p̂ = lum(f I / d²)).
None of these measures depend on the shading point, so moving a sample from
pixel q to pixel r is the identity map in a fixed measure: its Jacobian is 1,
and reuse re-evaluates p̂ at r with r's geometry and BSDF. (Had the target been
written in the solid angle at q, the shift would need the area ↔ solid-angle
Jacobian |cos θ_r| d_q² / (|cos θ_q| d_r²) — seed 004, Eq. 11 with the light
as the second vertex — which cancels against the change of measure.) The
source pdfs of the initial candidates are converted to the same measure (BSDF
pdf × |cos θ_y| / d² on triangles), so the RIS weights are ratios in one
measure. The radiance of a stored sample is re-evaluated from its source
(triangle emission, point intensity, environment lookup), so a neighbour sees
the emitter from its own side. Across frames (temporal reuse) the history's
target is evaluated in the previous frame's scene
(:meth:`~grisx.scene.scene.BuiltScene.across_frames`), and a point on an
emitter that moved between the frames has no counterpart in the other frame:
its shift fails both ways.

**What the image shows.** Emission seen at the visible point plus direct
light — what :mod:`grisx.render.pt` shows with ``max_depth=2``. The visible
point is a fresh uniform point of its pixel each frame (``jitter=true``, the
default: the box-filtered pixel ``pt`` estimates), or the pixel centre
(``jitter=false``, reference ``PathTracer(..., jitter=False, max_depth=2)``). Visible points on delta BSDFs
(mirror, glass) cannot be reached by light sampling; there the pixel gets one
BSDF-sampled ray's emission (what the path tracer does) and no reservoir.

References: B. Bitterli, C. Wyman, M. Pharr, P. Shirley, A. Lefohn, W. Jarosz,
"Spatiotemporal reservoir resampling for real-time ray tracing with dynamic
direct lighting", ACM TOG 39(4), 2020 (Alg. 3–5, Sec. 4.3, 6.1);
B. Bitterli, *Correlations and reuse for fast and accurate physically based
light transport*, PhD thesis, Dartmouth 2022, Ch. 9 (pairwise MIS);
seed 000, Eq. 6–9 (RIS/GRIS weights); seed 004, Alg. 1 (reservoirs).
"""

from __future__ import annotations

import types
from typing import Any

import warp as wp

from grisx.device import launch, specialized_module
from grisx.render.base.screen import ScreenFrame, ScreenSpaceRenderer, kernel_cache, pixel_key, screen_frame, write_pixel
from grisx.params import Param
from grisx.render.base.registry import RenderMethod, create_renderer, register, renderer_params
from grisx.scene.bsdf import make_bsdf
from grisx.scene.frame import Frame, frame_from_normal, to_local, to_world
from grisx.scene.gbuffer import GBuffer
from grisx.scene.lights import LightSample, light_pdf_emitter, luminance, make_lights
from grisx.render.base.reuse import (
    DomainList,
    domain_code,
    domain_pixel,
    SIMILARITY_DEPTH,
    SIMILARITY_NORMAL_COS,
    DoubleBuffer,
    NeighborPixel,
    pixels_similar,
    spatial_neighbor,
    temporal_neighbor,
)
from grisx.scene.scene import SceneData, SurfaceInteraction, make_surface, motion_touches, shadow_ray_along, shadow_ray_between, spawn_origin
from grisx.scene.bsdf import MATERIAL_DIFFUSE
from grisx.scene.material import Material
from grisx.theory.control_variate import (
    Q_INIT,
    CVOptions,
    compositing_weight,
    cv_alpha_or_sample,
    cv_composite_add,
    cv_composite_empty,
    cv_composite_value,
    cv_from_pixel,
    cv_options,
)
from grisx.theory.gris import ris_weight
from grisx.theory.mis import balance_mis, balance_term, pairwise_mis_canonical_term, pairwise_mis_neighbor
from grisx.theory.random import random_uniform
from grisx.theory.reservoir import (
    Reservoir,
    confidence_capped,
    reservoir_drop,
    reservoir_empty,
    reservoir_finalize,
    reservoir_merge,
    reservoir_update,
)

wp.set_module_options({"enable_backward": False})

__all__ = [
    "LightPoint",
    "LIGHT_NONE",
    "LIGHT_TRIANGLE",
    "LIGHT_POINT",
    "LIGHT_ENV",
    "make_restir_di_kernels",
    "ReSTIRDI",
    "create_restir_di",
]

LIGHT_NONE = wp.constant(0)
LIGHT_TRIANGLE = wp.constant(1)
LIGHT_POINT = wp.constant(2)
LIGHT_ENV = wp.constant(3)

#: random-number passes inside a pixel's stream
_PASS_INITIAL = wp.constant(10)
_PASS_TEMPORAL = wp.constant(11)
_PASS_SPATIAL = wp.constant(12)


@wp.struct
class LightPoint:
    """A light sample in its own measure: a point on a light, or an environment direction."""

    p: wp.vec3  # point on the triangle / point light position; the direction (scene → sky) for the environment
    n: wp.vec3  # the triangle's geometric normal (winding order)
    kind: int  # LIGHT_NONE, LIGHT_TRIANGLE, LIGHT_POINT, LIGHT_ENV
    index: int  # scene triangle (LIGHT_TRIANGLE) or point light (LIGHT_POINT)


@wp.struct
class LightEval:
    """A light sample seen from a shading point: f L_e G (RGB), its luminance p̂, and the shadow ray."""

    rgb: wp.vec3
    aux: wp.vec3  # ReSTCV's auxiliary ḟ: f L_e G with the BSDF's glossy part omitted (seed 002, Sec. 5.3)
    target: float
    wi: wp.vec3  # unit, shading point → light
    dist: float
    cos_light: float  # |cos θ_y| on triangles (area ↔ solid angle), 1 otherwise


@wp.struct
class PairwiseStep:
    """One neighbour merged with pairwise MIS: the reservoir after it, and its pair's canonical-weight share."""

    res: Reservoir
    canonical: float
    aux_c_of_n: wp.vec3  # ḟ_c(y_n): the neighbour's sample at the canonical point (visibility as the targets)
    aux_n_of_c: wp.vec3  # ḟ_n(y_c): the canonical sample at the neighbour's point


@wp.func
def light_point_none() -> LightPoint:
    lp = LightPoint()
    lp.kind = LIGHT_NONE
    lp.index = -1
    return lp


@wp.func
def light_point_from_sample(ls: LightSample, num_emitters: int) -> LightPoint:
    """The stored form of a :func:`sample_light` result."""
    lp = light_point_none()
    if ls.light < 0:
        return lp
    lp.p = ls.p
    lp.n = ls.n
    if ls.is_env != 0:
        lp.kind = LIGHT_ENV
    elif ls.delta != 0:
        lp.kind = LIGHT_POINT
        lp.index = ls.light - num_emitters
    else:
        lp.kind = LIGHT_TRIANGLE
        lp.index = ls.tri
    return lp




@kernel_cache
def make_restir_di_kernels(kinds: frozenset[int]) -> Any:
    """ReSTIR DI's functions and kernels compiled for the material kinds ``kinds`` (cached)."""
    return build_restir_di_kernels(kinds, cv=False)


def build_restir_di_kernels(kinds: frozenset[int], cv: bool) -> Any:
    """ReSTIR DI's functions and kernels for ``kinds``; with ``cv``, each pass also carries ReSTCV's
    estimate ⟨Ḋ_i⟩ of the auxiliary direct light (seed 002, Sec. 5.3; :mod:`grisx.render.restcv`)."""
    bsdf = make_bsdf(kinds)
    surface = make_surface(kinds)  # the wrappers and shapes of these kinds only
    lights = make_lights(kinds)  # the lights of these kinds only
    emitter_radiance = lights.emitter_radiance
    environment_eval = lights.environment_eval
    environment_pdf = lights.environment_pdf
    sample_light = lights.sample_light
    delta_light_arrival = lights.delta_light_arrival
    surface_material = surface.surface_material
    intersect = surface.intersect
    blocked = surface.blocked

    @wp.func
    def light_eval_at(scene: SceneData, si: SurfaceInteraction, m: Material, frame: Frame, wo: wp.vec3, lp: LightPoint) -> LightEval:
        """f L_e G of light sample ``lp`` at visible point ``si``, whose material ``m`` and shading ``frame`` the caller
        resolved once (the initial pass weighs 33 candidates at one point; resolving textures and normal maps for each
        was most of its time)."""
        ev = LightEval()
        ev.rgb = wp.vec3(0.0, 0.0, 0.0)
        ev.aux = wp.vec3(0.0, 0.0, 0.0)
        ev.target = 0.0
        ev.wi = wp.vec3(0.0, 0.0, 1.0)
        ev.dist = 0.0
        ev.cos_light = 1.0
        if lp.kind == LIGHT_NONE or si.valid == 0:
            return ev
        le = wp.vec3(0.0, 0.0, 0.0)
        g = float(1.0)
        wi = lp.p
        dist = float(1.0e30)
        if lp.kind == LIGHT_ENV:
            le = environment_eval(scene.lights, wi)
        elif lp.kind == LIGHT_POINT:
            a = delta_light_arrival(scene.lights, lp.index, si.p)  # I(−wi) / d², or a directional light's E
            if a.dist <= 0.0:
                return ev
            wi = a.wi
            dist = a.dist
            le = a.radiance
        else:
            d = lp.p - si.p
            dist_sq = wp.dot(d, d)
            if dist_sq <= 0.0:
                return ev
            dist = wp.sqrt(dist_sq)
            wi = d / dist
            cos_light = -wp.dot(lp.n, wi)
            if cos_light <= 0.0:
                return ev
            le = emitter_radiance(scene.lights, lp.index, lp.p, lp.n, -wi)
            ev.cos_light = cos_light
            g = cos_light / dist_sq  # area measure: dω = |cos θ_y| dA / d²
        f = bsdf.eval(m, to_local(frame, wo), to_local(frame, wi))
        ev.rgb = wp.cw_mul(f, le) * g
        ev.target = luminance(ev.rgb)
        if not (ev.target > 0.0):  # also NaN
            ev.target = 0.0
            ev.rgb = wp.vec3(0.0, 0.0, 0.0)
        elif m.kind == MATERIAL_DIFFUSE:
            ev.aux = ev.rgb  # the diffuse lobe; grisx's other BSDFs are all glossy lobe (ḟ = 0 there)
        ev.wi = wi
        ev.dist = dist
        return ev

    @wp.func
    def light_eval(scene: SceneData, si: SurfaceInteraction, wo: wp.vec3, lp: LightPoint) -> LightEval:
        """f L_e G of light sample ``lp`` at visible point ``si`` (area measure on triangles; see the module docstring)."""
        return light_eval_at(scene, si, surface_material(scene, si), frame_from_normal(si.ns), wo, lp)

    @wp.func
    def light_visible(scene: SceneData, si: SurfaceInteraction, ev: LightEval, lp: LightPoint) -> bool:
        # the segment built first and traced at one place: one inlined traversal (ShadowRay)
        shadow = shadow_ray_along(scene, spawn_origin(scene, si.p, si.ng, ev.wi), ev.wi, ev.dist)
        if lp.kind == LIGHT_TRIANGLE:
            shadow = shadow_ray_between(scene, si.p, si.ng, lp.p, lp.n)
        return not blocked(scene, shadow)

    @wp.func
    def eval_at(scene: SceneData, si: SurfaceInteraction, m: Material, frame: Frame, wo: wp.vec3, lp: LightPoint, visibility: int) -> LightEval:
        """``lp`` seen from a visible point (its material ``m`` and shading ``frame`` resolved by the caller): unshadowed,
        or zero where occluded when ``visibility`` is set; zero across frames where its emitter moved (no such point in
        the other frame)."""
        ev = light_eval_at(scene, si, m, frame, wo, lp)
        if lp.kind == LIGHT_TRIANGLE and motion_touches(scene, lp.p, lp.p):
            ev.target = 0.0
            ev.rgb = wp.vec3(0.0, 0.0, 0.0)
            ev.aux = wp.vec3(0.0, 0.0, 0.0)
            return ev
        if ev.target > 0.0 and visibility != 0:
            if not light_visible(scene, si, ev, lp):
                ev.target = 0.0
                ev.rgb = wp.vec3(0.0, 0.0, 0.0)
                ev.aux = wp.vec3(0.0, 0.0, 0.0)
        return ev

    @wp.func
    def target_at(scene: SceneData, si: SurfaceInteraction, wo: wp.vec3, lp: LightPoint, visibility: int) -> float:
        """p̂ of ``lp`` at a visible point: unshadowed, or times its visibility when ``visibility`` is set."""
        return eval_at(scene, si, surface_material(scene, si), frame_from_normal(si.ns), wo, lp, visibility).target

    @wp.func
    def pairwise_step(
        scene: SceneData,
        scene_n: SceneData,
        out: Reservoir,
        si: SurfaceInteraction,
        mat_c: Material,
        frame_c: Frame,
        wo: wp.vec3,
        r_c: Reservoir,
        y_c: LightPoint,
        si_n: SurfaceInteraction,
        wo_n: wp.vec3,
        r_n: Reservoir,
        y_n: LightPoint,
        k: int,
        total: float,
        unbiased: int,
        u: float,
    ) -> PairwiseStep:
        """Merge neighbour n's reservoir into ``out`` with its pairwise MIS weight (identity shift, J = 1),
        and return its pair's share of the canonical sample's weight (Bitterli 2022, Ch. 9). Each side is
        evaluated in its own frame's scene: ``scene_n`` is the previous frame's for the history. The canonical
        point's material and frame come from the caller, which resolves them once for all its neighbours."""
        e_c_of_n = eval_at(scene, si, mat_c, frame_c, wo, y_n, unbiased)
        e_n_of_c = eval_at(scene_n, si_n, surface_material(scene_n, si_n), frame_from_normal(si_n.ns), wo_n, y_c, unbiased)
        t_c_of_n = e_c_of_n.target  # p̂_c(y_n)
        t_n_of_c = e_n_of_c.target  # p̂_n(y_c)
        step = PairwiseStep()
        step.aux_c_of_n = e_c_of_n.aux
        step.aux_n_of_c = e_n_of_c.aux
        step.res = reservoir_merge(
            out, r_n, pairwise_mis_neighbor(r_n.confidence, r_n.target, r_c.confidence, t_c_of_n, k, total), t_c_of_n, 1.0, u
        )
        step.canonical = pairwise_mis_canonical_term(r_n.confidence, t_n_of_c, r_c.confidence, r_c.target, k, total)
        return step

    @wp.func
    def own_aux(scene: SceneData, si: SurfaceInteraction, wo: wp.vec3, r: Reservoir, lp: LightPoint) -> wp.vec3:
        """ḟ_i(y_i) of a pixel's own reservoir sample: visible from it by construction (visibility before
        reuse, targets with visibility in the merges, occluded samples dropped when shaded)."""
        if r.ucw > 0.0:
            return light_eval(scene, si, wo, lp).aux
        return wp.vec3(0.0, 0.0, 0.0)

    module = specialized_module(__name__ + (".cv" if cv else ""), kinds)

    @wp.kernel(module=module)
    def initial_pass(
        scene: SceneData,
        sf: ScreenFrame,
        n_light: int,
        n_bsdf: int,
        res_out: wp.array2d(dtype=Reservoir),
        lp_out: wp.array2d(dtype=LightPoint),
        est_out: wp.array2d(dtype=wp.vec3),
        base: wp.array2d(dtype=wp.vec3),
    ):
        y, x = wp.tid()
        key = pixel_key(sf, x, y, _PASS_INITIAL)
        est_out[y, x] = wp.vec3(0.0, 0.0, 0.0)
        si = sf.si[y, x]
        wo = sf.wo[y, x]
        ls = scene.lights
        r = reservoir_empty()
        sel = light_point_none()
        if si.valid == 0:
            base[y, x] = environment_eval(ls, -wo)
            res_out[y, x] = r
            lp_out[y, x] = sel
            return
        b = emitter_radiance(ls, si.tri, si.p, si.ng, wo)  # emission seen at x
        m = surface_material(scene, si)
        frame_x = frame_from_normal(si.ns)
        wo_l = to_local(frame_x, wo)
        if bsdf.has_delta_lobe(m) != 0:
            # ---- delta lobes: no light sample can reach them (nor a candidate's density weigh them); one BSDF
            # ray, as the path tracer does, counted where it took a delta lobe (all of a mirror; a plastic's coat) ----
            bs = bsdf.sample(m, wo_l, random_uniform(key, 0), wp.vec2(random_uniform(key, 1), random_uniform(key, 2)))
            if bs.valid != 0 and bs.delta != 0:
                d = wp.normalize(to_world(frame_x, bs.wi))
                hit = intersect(scene, spawn_origin(scene, si.p, si.ng, d), d, 1.0e30)
                le = environment_eval(ls, d)
                if hit.valid != 0:
                    le = emitter_radiance(ls, hit.tri, hit.p, hit.ng, -d)
                b += wp.cw_mul(bs.weight, le)
            if bsdf.is_delta(m) != 0:
                base[y, x] = b
                res_out[y, x] = r
                lp_out[y, x] = sel
                return
        base[y, x] = b
        # ---- initial candidates: light samples and BSDF samples, balance heuristic over the two ----
        c_light = float(n_light)
        c_bsdf = float(n_bsdf)
        for i in range(n_light):
            c = 4 * i + 8
            s = sample_light(ls, si.p, random_uniform(key, c), wp.vec2(random_uniform(key, c + 1), random_uniform(key, c + 2)))
            if s.pdf <= 0.0:
                continue
            lp = light_point_from_sample(s, ls.num_emitters)
            ev = light_eval_at(scene, si, m, frame_x, wo, lp)
            if ev.target <= 0.0:
                continue
            p_light = s.pdf_area  # area density on triangles, solid angle on the environment, pmf for point lights
            p_bsdf = float(0.0)  # the competing technique's density: none without BSDF candidates (the default)
            if n_bsdf > 0:
                if lp.kind == LIGHT_TRIANGLE:
                    p_bsdf = bsdf.pdf(m, wo_l, to_local(frame_x, ev.wi)) * ev.cos_light / (ev.dist * ev.dist)
                elif lp.kind == LIGHT_ENV:
                    p_bsdf = bsdf.pdf(m, wo_l, to_local(frame_x, ev.wi))
            total = balance_term(c_light, p_light) + balance_term(c_bsdf, p_bsdf)
            w = ris_weight(balance_mis(1.0, p_light, total), ev.target, p_light)  # seed 000, Eq. 6; seed 001, Eq. 15
            r = reservoir_update(r, w, ev.target, 0.0, random_uniform(key, c + 3))
            if r.selected:
                sel = lp
        for j in range(n_bsdf):
            c = 4 * (n_light + j) + 8
            bs = bsdf.sample(m, wo_l, random_uniform(key, c), wp.vec2(random_uniform(key, c + 1), random_uniform(key, c + 2)))
            if bs.valid == 0 or bs.delta != 0:
                continue
            d = wp.normalize(to_world(frame_x, bs.wi))
            hit = intersect(scene, spawn_origin(scene, si.p, si.ng, d), d, 1.0e30)
            lp = light_point_none()
            if hit.valid != 0:
                if ls.tri_emitter[hit.tri] >= 0:
                    lp.kind = LIGHT_TRIANGLE
                    lp.p = hit.p
                    lp.n = hit.ng
                    lp.index = hit.tri
            elif ls.env_light >= 0:
                lp.kind = LIGHT_ENV
                lp.p = d
            if lp.kind == LIGHT_NONE:
                continue
            ev = light_eval_at(scene, si, m, frame_x, wo, lp)
            if ev.target <= 0.0:
                continue
            p_bsdf = bs.pdf
            p_light = environment_pdf(ls, d)
            if lp.kind == LIGHT_TRIANGLE:
                to_area = ev.cos_light / (ev.dist * ev.dist)
                p_bsdf = bs.pdf * to_area
                p_light = light_pdf_emitter(ls, hit.tri, si.p, hit.p, hit.ng) * to_area
            total = balance_term(c_light, p_light) + balance_term(c_bsdf, p_bsdf)
            w = ris_weight(balance_mis(1.0, p_bsdf, total), ev.target, p_bsdf)
            r = reservoir_update(r, w, ev.target, 0.0, random_uniform(key, c + 3))
            if r.selected:
                sel = lp
        r = reservoir_finalize(r)
        # ---- visibility before reuse: an occluded sample contributes nothing here (Bitterli et al., Sec. 6.1) ----
        if r.ucw > 0.0:
            if not light_visible(scene, si, light_eval_at(scene, si, m, frame_x, wo, sel), sel):
                r = reservoir_empty()
                sel = light_point_none()
        r.confidence = 1.0  # one initial RIS counts as one unit of confidence (M = 1)
        res_out[y, x] = r
        lp_out[y, x] = sel
        if wp.static(cv):
            est_out[y, x] = own_aux(scene, si, wo, r, sel) * r.ucw  # ⟨Ḋ_i⟩_init = ḟ(y) W (seed 002, Listing 1 line 36)

    @wp.kernel(module=module)
    def temporal_pass(
        scene: SceneData,
        scene_prev: SceneData,
        sf: ScreenFrame,
        history_cap: float,
        unbiased: int,
        normal_cos: float,
        depth_tol: float,
        o: CVOptions,
        res_in: wp.array2d(dtype=Reservoir),
        lp_in: wp.array2d(dtype=LightPoint),
        est_in: wp.array2d(dtype=wp.vec3),
        res_prev: wp.array2d(dtype=Reservoir),
        lp_prev: wp.array2d(dtype=LightPoint),
        est_prev: wp.array2d(dtype=wp.vec3),
        res_out: wp.array2d(dtype=Reservoir),
        lp_out: wp.array2d(dtype=LightPoint),
        est_out: wp.array2d(dtype=wp.vec3),
    ):
        y, x = wp.tid()
        key = pixel_key(sf, x, y, _PASS_TEMPORAL)
        r_c = res_in[y, x]
        y_c = lp_in[y, x]
        si = sf.si[y, x]
        # each output written once, at the end (the fresh reservoir where there is no history); the estimate only by
        # ReSTCV's variant, the one that reads it
        r_out = r_c
        lp_sel = y_c
        est = wp.vec3(0.0, 0.0, 0.0)
        if wp.static(cv):
            est = est_in[y, x]
        tn = NeighborPixel()
        tn.valid = 0
        if si.valid != 0:
            tn = temporal_neighbor(sf.g, sf.g_prev, x, y, normal_cos, depth_tol)
        if tn.valid != 0:
            wo = sf.wo[y, x]
            si_p = sf.si_prev[tn.y, tn.x]
            wo_p = sf.wo_prev[tn.y, tn.x]
            r_p = res_prev[tn.y, tn.x]
            y_p = lp_prev[tn.y, tn.x]
            r_p.confidence = confidence_capped(r_p.confidence, history_cap)
            # ---- pairwise MIS between the fresh (canonical) reservoir and the history ----
            step = pairwise_step(
                scene, scene_prev, reservoir_empty(), si, surface_material(scene, si), frame_from_normal(si.ns), wo, r_c, y_c, si_p, wo_p, r_p,
                y_p, 1, r_c.confidence + r_p.confidence, unbiased,
                random_uniform(key, 1)
            )
            sel = light_point_none()
            if step.res.selected:
                sel = y_p
            out = reservoir_merge(step.res, r_c, step.canonical, r_c.target, 1.0, random_uniform(key, 0))
            if out.selected:
                sel = y_c
            r_out = reservoir_finalize(out)
            lp_sel = sel
            if wp.static(cv):
                if o.temporal != 0:
                    # ---- ReSTCV: ⟨Ḋ_i⟩ = (q_init ⟨Ḋ_i⟩_init + q_j ⟨Ḋ_i⟩_{←j}) / (q_init + q_j) (seed 002, Eq. 6–7) ----
                    aux_c = own_aux(scene, si, wo, r_c, y_c)
                    est_j = est_prev[tn.y, tn.x]
                    alpha = cv_alpha_or_sample(o.alpha, sf.g.albedo[y, x], sf.g_prev.albedo[tn.y, tn.x], aux_c * r_c.ucw, est_j)
                    from_j = cv_from_pixel(  # light samples move by the identity: |J| = 1 (module docstring, "Measure")
                        r_c, r_p, est_j, aux_c, step.aux_n_of_c, own_aux(scene_prev, si_p, wo_p, r_p, y_p), step.aux_c_of_n, 1.0, 1.0, alpha, o.difference_mis
                    )
                    c = cv_composite_add(cv_composite_empty(), est, Q_INIT)
                    est = cv_composite_value(cv_composite_add(c, from_j, compositing_weight(r_p.confidence)))
        res_out[y, x] = r_out
        lp_out[y, x] = lp_sel
        if wp.static(cv):
            est_out[y, x] = est

    @wp.kernel(module=module)
    def spatial_pass(
        scene: SceneData,
        sf: ScreenFrame,
        neighbors: int,
        radius: float,
        history_cap: float,
        unbiased: int,
        normal_cos: float,
        depth_tol: float,
        o: CVOptions,
        res_in: wp.array2d(dtype=Reservoir),
        lp_in: wp.array2d(dtype=LightPoint),
        est_in: wp.array2d(dtype=wp.vec3),
        codes: wp.array3d(dtype=wp.int32),
        slots: wp.array3d(dtype=wp.int32),
        res_out: wp.array2d(dtype=Reservoir),
        lp_out: wp.array2d(dtype=LightPoint),
        est_out: wp.array2d(dtype=wp.vec3),
    ):
        y, x = wp.tid()
        width = sf.si.shape[1]
        height = sf.si.shape[0]
        key = pixel_key(sf, x, y, _PASS_SPATIAL)
        r_c = res_in[y, x]
        y_c = lp_in[y, x]
        si = sf.si[y, x]
        # each output written once, at the end (the input reservoir where nothing is resampled); the estimate only by
        # ReSTCV's variant, the one that reads it
        r_out = r_c
        lp_sel = y_c
        est = wp.vec3(0.0, 0.0, 0.0)
        if wp.static(cv):
            est = est_in[y, x]
        # ---- choose the neighbours (similar G-buffer only), drawn once into a DomainList (global memory,
        # not a per-thread array); k counts the accepted ones ----
        total = r_c.confidence
        k = int(0)
        if si.valid != 0:
            for i in range(wp.min(neighbors, codes.shape[2])):
                nb = spatial_neighbor(x, y, width, height, radius, wp.vec2(random_uniform(key, 4 * i), random_uniform(key, 4 * i + 1)))
                if nb.valid != 0 and pixels_similar(sf.g, x, y, sf.g, nb.x, nb.y, normal_cos, depth_tol):
                    codes[y, x, k] = domain_code(nb.x, nb.y, width, 0)
                    slots[y, x, k] = i
                    k += 1
                    total += confidence_capped(res_in[nb.y, nb.x].confidence, history_cap)
        if k > 0:
            wo = sf.wo[y, x]
            # ---- merge each neighbour with its pairwise MIS weight; collect the canonical weight ----
            out = reservoir_empty()
            sel = light_point_none()
            m_c = float(0.0)
            # ReSTCV: Eq. 8's composite starts with ⟨Ḋ_i⟩_{←i} = ⟨Ḋ_i⟩, q_i = M_i ≤ 20 (seed 002)
            composite = cv_composite_add(cv_composite_empty(), est, compositing_weight(r_c.confidence))
            aux_c = wp.vec3(0.0, 0.0, 0.0)
            if wp.static(cv):
                aux_c = own_aux(scene, si, wo, r_c, y_c)
            m_si = surface_material(scene, si)  # the canonical point's, once for its k neighbours
            frame_si = frame_from_normal(si.ns)
            for j in range(k):
                nb = domain_pixel(codes[y, x, j], width)
                r_n = res_in[nb.y, nb.x]
                y_n = lp_in[nb.y, nb.x]
                r_n.confidence = confidence_capped(r_n.confidence, history_cap)
                si_n = sf.si[nb.y, nb.x]
                wo_n = sf.wo[nb.y, nb.x]
                step = pairwise_step(scene, scene, out, si, m_si, frame_si, wo, r_c, y_c, si_n, wo_n, r_n, y_n, k, total, unbiased,
                                     random_uniform(key, 4 * slots[y, x, j] + 2))
                out = step.res
                m_c += step.canonical
                if out.selected:
                    sel = y_n
                if wp.static(cv):
                    if o.spatial != 0:
                        # ---- ReSTCV: + q_n ⟨Ḋ_i⟩_{←n} from the targets the pairwise MIS just evaluated (Eq. 7–8, 10–11) ----
                        est_n = est_in[nb.y, nb.x]
                        alpha = cv_alpha_or_sample(o.alpha, sf.g.albedo[y, x], sf.g.albedo[nb.y, nb.x], aux_c * r_c.ucw, est_n)
                        from_n = cv_from_pixel(
                            r_c, r_n, est_n, aux_c, step.aux_n_of_c, own_aux(scene, si_n, wo_n, r_n, y_n), step.aux_c_of_n, 1.0, 1.0, alpha,
                            o.difference_mis
                        )
                        composite = cv_composite_add(composite, from_n, compositing_weight(r_n.confidence))
            out = reservoir_merge(out, r_c, m_c, r_c.target, 1.0, random_uniform(key, 4 * neighbors))
            if out.selected:
                sel = y_c
            r_out = reservoir_finalize(out)
            lp_sel = sel
            if wp.static(cv):
                est = cv_composite_value(composite)
        res_out[y, x] = r_out
        lp_out[y, x] = lp_sel
        if wp.static(cv):
            est_out[y, x] = est

    @wp.kernel(module=module)
    def shade_pass(
        scene: SceneData,
        sf: ScreenFrame,
        unbiased: int,
        base: wp.array2d(dtype=wp.vec3),
        res: wp.array2d(dtype=Reservoir),
        lps: wp.array2d(dtype=LightPoint),
        est: wp.array2d(dtype=wp.vec3),
        image: wp.array2d(dtype=wp.vec3),
        nonfinite: wp.array(dtype=wp.int32),
    ):
        y, x = wp.tid()
        L = base[y, x]
        r = res[y, x]
        if wp.static(cv):
            L += est[y, x]  # ⟨Ḋ_i⟩, ReSTCV's estimate of the auxiliary (seed 002, Sec. 5.3)
        if r.ucw > 0.0:
            si = sf.si[y, x]
            ev = light_eval(scene, si, sf.wo[y, x], lps[y, x])
            # unbiased, the kept sample is visible from here by construction (visibility before reuse, and every
            # merge's target at this pixel includes it): no shadow ray; else it is tested here
            if ev.target > 0.0 and (unbiased != 0 or light_visible(scene, si, ev, lps[y, x])):
                if wp.static(cv):
                    L += (ev.rgb - ev.aux) * r.ucw  # the second-level CV: ⟨D_i − Ḋ_i⟩ = (f − ḟ)(y) · W
                else:
                    L += ev.rgb * r.ucw  # seed 004, Eq. 8: f(y) · W
            else:
                # an occluded sample (possible when unbiased=false) is not handed to the next frame
                res[y, x] = reservoir_drop(r)
                lps[y, x] = light_point_none()
        write_pixel(image, nonfinite, y, x, L)

    return types.SimpleNamespace(
        light_eval=light_eval, target_at=target_at, initial_pass=initial_pass, temporal_pass=temporal_pass, spatial_pass=spatial_pass, shade_pass=shade_pass
    )


class ReSTIRDI(ScreenSpaceRenderer):
    """ReSTIR DI over a built scene; ``render_frame(frame)`` returns emitted + direct light (H×W×3)."""

    def __init__(
        self,
        built: Any,
        width: int,
        height: int,
        *,
        seed: int = 0,
        light_candidates: int = 8,
        bsdf_candidates: int = 0,
        temporal: bool = True,
        spatial: bool = True,
        neighbors: int = 3,
        radius: float = 30.0,
        history_cap: float = 20.0,
        unbiased: bool = True,
        jitter: bool = True,
        timer: Any = None,
    ) -> None:
        self.built = built
        self.width, self.height = int(width), int(height)
        self.seed = int(seed)
        self.light_candidates = int(light_candidates)
        self.bsdf_candidates = int(bsdf_candidates)
        self.temporal = bool(temporal)
        self.spatial = bool(spatial)
        self.neighbors = int(neighbors)
        self.radius = float(radius)
        self.history_cap = float(history_cap)
        self.unbiased = int(bool(unbiased))
        self.jitter = bool(jitter)
        self.timer = timer
        self.k = self.make_kernels(built.features.kernel_kinds)
        self.cv_options = cv_options()  # the passes' CV options: unused by ReSTIR DI itself (ReSTCV's, restcv-di)
        dev = self.device = built.device
        shape = (self.height, self.width)
        self.gbuffer = GBuffer(self.width, self.height, dev, material=self.GBUFFER_MATERIAL)
        # a pixel's reservoir, its light sample, and the estimate a ReSTCV variant carries with them
        triple = lambda: (  # noqa: E731
            wp.zeros(shape, dtype=Reservoir, device=dev), wp.zeros(shape, dtype=LightPoint, device=dev), wp.zeros(shape, dtype=wp.vec3, device=dev)
        )
        self.initial = triple()
        self.temporal_out = triple()
        self.final = DoubleBuffer(triple)  # this frame's / last frame's final reservoirs
        self.spatial_domains = DomainList(self.height, self.width, self.neighbors, dev)  # the spatial pass's neighbours
        self.base = wp.zeros(shape, dtype=wp.vec3, device=dev)
        self.image = wp.zeros(shape, dtype=wp.vec3, device=dev)
        self.nonfinite = wp.zeros(1, dtype=wp.int32, device=dev)
        self.frames_rendered = 0

    def make_kernels(self, kinds: frozenset[int]) -> Any:
        """The passes compiled for ``kinds`` (ReSTCV's variant compiles its estimate in)."""
        return make_restir_di_kernels(kinds)

    def kernels(self) -> list[Any]:
        return [self.gbuffer.kernel(self.built), self.k.initial_pass, self.k.temporal_pass, self.k.spatial_pass, self.k.shade_pass]

    def prepare(self, frame: int) -> None:
        """The G-buffer (with the visible points) of ``frame`` (the scene must already be at ``frame``)."""
        with self._phase("gbuffer"):
            self.gbuffer.fill(self.built, float(frame), self.seed, self.jitter)

    def resample(self, frame: int) -> None:
        """Initial candidates, temporal and spatial reuse into ``self.final.current``."""
        dim = (self.height, self.width)
        data = self.built.data
        dev = self.device
        self.final.swap()
        sf = screen_frame(self.gbuffer, self.seed, frame)
        with self._phase("di_initial"):
            launch(
                self.k.initial_pass,
                dim=dim,
                inputs=[data, sf, self.light_candidates, self.bsdf_candidates],
                outputs=[self.initial[0], self.initial[1], self.initial[2], self.base],
                device=dev,
            )
        src = self.initial
        if self.temporal and self.frames_rendered > 0:
            with self._phase("di_temporal"):
                launch(
                    self.k.temporal_pass,
                    dim=dim,
                    inputs=[
                        *self.built.across_frames(), sf, self.history_cap, self.unbiased, SIMILARITY_NORMAL_COS, SIMILARITY_DEPTH, self.cv_options,
                        src[0], src[1], src[2], self.final.previous[0], self.final.previous[1], self.final.previous[2],
                    ],
                    outputs=[self.temporal_out[0], self.temporal_out[1], self.temporal_out[2]],
                    device=dev,
                )
            src = self.temporal_out
        dst = self.final.current
        if self.spatial and self.neighbors > 0:
            with self._phase("di_spatial"):
                launch(
                    self.k.spatial_pass,
                    dim=dim,
                    inputs=[
                        data, sf, self.neighbors, self.radius, self.history_cap, self.unbiased, SIMILARITY_NORMAL_COS, SIMILARITY_DEPTH,
                        self.cv_options, src[0], src[1], src[2], self.spatial_domains.codes, self.spatial_domains.slots,
                    ],
                    outputs=[dst[0], dst[1], dst[2]],
                    device=dev,
                )
        else:
            for a, b in zip(dst, src):
                wp.copy(a, b)

    def shade(self) -> wp.array:
        with self._phase("di_shade"):
            launch(
                self.k.shade_pass,
                dim=(self.height, self.width),
                inputs=[self.built.data, screen_frame(self.gbuffer, self.seed, 0), self.unbiased, self.base, *self.final.current],
                outputs=[self.image, self.nonfinite],
                device=self.device,
            )
        return self.image

    def direct_light(self, frame: int) -> wp.array:
        """Resample and shade ``frame`` on the prepared G-buffer (what ReSTIR GI's ``direct=restir-di`` calls)."""
        self.resample(frame)
        out = self.shade()
        self.frames_rendered += 1
        return out

    def render_frame(self, frame: int) -> wp.array:
        self.prepare(frame)
        return self.direct_light(frame)


def create_restir_di(ctx: Any) -> ReSTIRDI:
    return create_renderer(ReSTIRDI, ctx)


# ---- registration (grisx.render.base.registry): the method, its params (defaults: the constructor's) ----

register(
    RenderMethod(
        "restir-di",
        "ReSTIR DI (Bitterli et al. 2020): 8 light candidates, 3 spatial neighbours, visibility before reuse, temporal and spatial reuse with pairwise MIS; emitted + direct light (pt's max_depth=2)",
        create_restir_di,
        reference_max_depth=2,
        params=renderer_params(
            ReSTIRDI,
            Param("light_candidates", ..., "initial light-sampled candidates per pixel", kind="int", minimum=0, maximum=1024),
            Param("bsdf_candidates", ..., "initial BSDF-sampled candidates per pixel", kind="int", minimum=0, maximum=64),
            Param("temporal", ..., "reuse the previous frame's reservoir (reprojected)", kind="bool"),
            Param("spatial", ..., "reuse neighbouring pixels' reservoirs", kind="bool"),
            Param("neighbors", ..., "spatial neighbours per pixel", kind="int", minimum=0, maximum=64),
            Param("radius", ..., "spatial reuse radius in pixels", minimum=1.0),
            Param("history_cap", ..., "cap on a reused reservoir's confidence M (the history cap)", minimum=0.0),
            Param("unbiased", ..., "true: targets at other pixels include their visibility (shadow rays), unbiased; false: unshadowed, cheaper, biased", kind="bool"),
            Param("jitter", ..., "visible point uniform over the pixel each frame (box filter: what pt estimates); false: pixel centres", kind="bool"),
        ),
    )
)
