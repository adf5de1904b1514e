"""The path tracer's inner loop, shared: ``trace_path`` gives the radiance arriving along a ray.

The reference path tracer (:mod:`grisx.render.pt`) and every renderer that needs the path
tracer's estimate somewhere (ReSTIR GI's outgoing radiance at a sample point) call the very
same function, so they estimate the same integrals: NEE and BSDF sampling with the power
heuristic, Mitsuba's ``max_depth``, Russian roulette from ``rr_depth``
(:func:`grisx.theory.roulette.roulette_survival`).
"""

from __future__ import annotations

import functools
from typing import Any

import warp as wp

from grisx.scene.bsdf import cosine_hemisphere_pdf, make_bsdf, sample_cosine_hemisphere
from grisx.scene.frame import frame_from_normal, to_local, to_world
from grisx.scene.lights import light_pdf_emitter, make_lights
from grisx.scene.material import MATERIAL_PRINCIPLED, MATERIAL_PRINCIPLED_THIN, MATERIAL_ROUGH_DIELECTRIC, PERTURB_NONE
from grisx.scene.caustics import canonical_lobe, caustic_owned, grazing
from grisx.scene.scene import SceneData, SurfaceInteraction, make_surface, spawn_origin
from grisx.theory.mis import technique_mis
from grisx.theory.roulette import roulette_survival
from grisx.theory.random import random_uniform

wp.set_module_options({"enable_backward": False})

__all__ = ["PathRadiance", "make_trace_path", "no_first_hit", "STRATEGIES"]

#: sampling strategies: both techniques with MIS, or one alone
STRATEGIES = {"mis": 0, "nee": 1, "bsdf": 2}
_FAR = wp.constant(1.0e30)



@wp.struct
class PathRadiance:
    """One traced path's estimate: all of it, and the part of its first ``prefix_depth`` segments.

    With ``record``, also the two techniques at the first hit x, split from its BSDF so that the
    radiance x reflects can be re-evaluated toward another direction ω' (ReSTIR GI's ``exact_bsdf``):
    L(x → ω') = f(ω', nee_wi) ⊙ nee_li + f(ω', bs_wi) ⊙ bs_li (f with the cosine, as ``bsdf.eval``).
    For that to be one function of the path whatever direction it was traced from, nothing at x may
    depend on the outgoing direction: there the continuation is drawn cosine-weighted on the
    outgoing side (not from the BSDF) and both MIS weights use that density. ``recorded`` = 0 where
    this cannot be done (a delta or transmitting BSDF at x, or no hit): the path is then the usual one.
    """

    total: wp.vec3
    prefix: wp.vec3  # = what the same path (same random numbers) gives with max_depth = prefix_depth
    nee_wi: wp.vec3  # light direction of next-event estimation at the first hit (world)
    nee_li: wp.vec3  # its radiance × MIS weight / pdf (0 when occluded or not sampled)
    bs_wi: wp.vec3  # BSDF-sampled direction at the first hit (world)
    bs_li: wp.vec3  # everything the path gathers after it, divided by that sample's pdf (not by f)
    bs_li_prefix: wp.vec3  # the part of bs_li within the first prefix_depth segments
    recorded: int  # 1: the records above describe the path
    # with ``bounds``: the box of every point the path's value depends on after o, its hits and its light samples
    # (unbounded once a ray leaves for the environment); else empty. ReSTIR GI reuses L_o across frames only where
    # nothing in it moved
    box_lo: wp.vec3
    box_hi: wp.vec3
    # caustic_chain > 0 (grisx.render.sms): the first non-delta vertex x₁, where SMS adds its caustic NEE
    x1_valid: int
    x1: SurfaceInteraction
    x1_wo: wp.vec3  # unit, x₁ → the previous vertex
    x1_beta: wp.vec3  # path throughput at x₁ (its BSDF not included)
    x1_depth: int  # segments before the one that reached x₁ (the loop's depth there)


@wp.func
def no_first_hit() -> SurfaceInteraction:
    """``trace_path``'s ``first`` when the caller has not traced the ray: ``t`` = 0, so the function traces it."""
    si = SurfaceInteraction()
    si.valid = 0
    si.t = 0.0
    return si


def make_trace_path(kinds: frozenset[int], caustic_chain: int = 0, bounds: bool = False) -> Any:
    """``trace_path(scene, o, d, key, max_depth, rr_depth, strategy, prefix_depth, record, first) -> PathRadiance``
    for the material kinds ``kinds`` (cached): the radiance arriving at o from direction d, emission at
    the first hit included. Renderers that need the path tracer's estimate at a point (ReSTIR GI's
    outgoing radiance at a sample point) call this very function.

    ``prefix`` is the estimate truncated to ``prefix_depth`` segments (Mitsuba's max_depth), from the
    same path: a renderer that needs both (direct light and the rest; one bounce and all of them)
    traces once. ``prefix_depth`` < 0: ``prefix`` = ``total``. ``record`` = 1 fills the first hit's
    technique records of :class:`PathRadiance` (the path itself is the same). ``first``: the ray's first hit
    where the caller already traced it (a G-buffer's visible point, or a miss with ``t`` > 0), else
    :func:`no_first_hit` (``t`` = 0): the function traces it.

    ``caustic_chain`` = K > 0 (specular manifold sampling, :mod:`grisx.render.sms`): the paths that SMS
    owns (:func:`grisx.scene.caustics.caustic_owned`: x₁ the first non-delta vertex, then 1 … K delta
    vertices left by their canonical lobes, the first on a caster whose seed square holds the direction
    from x₁, met at |cos| ≥ ``GRAZING_COS``, then an emitter triangle) add no emission here, and x₁ is recorded for SMS's own estimate.

    ``bounds``: fill :class:`PathRadiance`'s box (compiled in only where asked: scenes with moving objects)."""
    return _make_trace_path(frozenset(int(k) for k in kinds), int(caustic_chain), bool(bounds))


@functools.cache
def _make_trace_path(kinds: frozenset[int], caustic_chain: int, bounds: bool) -> Any:
    bsdf = make_bsdf(kinds)
    surface = make_surface(kinds)  # the wrappers and shapes of these kinds only
    lights = make_lights(kinds)  # the lights of these kinds only
    emitter_radiance = lights.emitter_radiance
    environment_eval = lights.environment_eval
    environment_pdf = lights.environment_pdf
    sample_light = lights.sample_light
    surface_material, intersect, light_occluded = surface.surface_material, surface.intersect, surface.light_occluded
    chain_max = caustic_chain

    @wp.func
    def trace_path(
        scene: SceneData, o: wp.vec3, d: wp.vec3, key: wp.uint32, max_depth: int, rr_depth: int, strategy: int, prefix_depth: int, record: int,
        first: SurfaceInteraction,
    ) -> PathRadiance:
        out = PathRadiance()
        zero = wp.vec3(0.0, 0.0, 0.0)
        out.nee_wi = zero
        out.nee_li = zero
        out.bs_wi = zero
        out.bs_li = zero
        out.bs_li_prefix = zero
        out.recorded = 0
        out.x1_valid = 0
        out.x1_depth = -1
        out.box_lo = wp.vec3(_FAR)
        out.box_hi = wp.vec3(-_FAR)
        # SMS ownership (caustic_chain > 0): 0 before x₁, 1 while the chain after x₁ may still be SMS's, 2 never
        chain_state = int(0)
        chain_len = int(0)
        chain_obj = int(-1)
        x1_p = wp.vec3(0.0, 0.0, 0.0)
        d1 = wp.vec3(0.0, 0.0, 0.0)
        have_prefix = int(0)
        gamma = wp.vec3(0.0, 0.0, 0.0)  # record: the throughput after the first hit's BSDF sample, over its pdf
        use_nee = strategy != 2
        use_bsdf_emission = strategy != 1
        L = wp.vec3(0.0, 0.0, 0.0)
        beta = wp.vec3(1.0, 1.0, 1.0)  # path throughput
        eta = float(1.0)
        prev_pdf = float(1.0)  # solid-angle pdf of the BSDF sample that led here
        prev_delta = int(1)  # camera rays count emission fully
        prev_p = o
        depth = int(0)
        while max_depth < 0 or depth < max_depth:
            si = first  # the ray's first hit, where the caller has it (a G-buffer's): not traced again
            if depth > 0 or first.t <= 0.0:
                si = intersect(scene, o, d, 1.0e30)
            c = 8 * depth
            # ---- emission reached by the previous BSDF sample (or the camera ray) ----
            le = wp.vec3(0.0, 0.0, 0.0)
            if si.valid == 0:
                le = environment_eval(scene.lights, d)
            else:
                le = emitter_radiance(scene.lights, si.tri, si.p, si.ng, -d)
            if wp.length_sq(le) > 0.0:
                w = float(1.0)
                if prev_delta == 0:
                    if not use_bsdf_emission:
                        w = 0.0
                    elif use_nee:
                        light_pdf = float(0.0)  # the density NEE would have picked this emitter point with
                        if si.valid == 0:
                            light_pdf = environment_pdf(scene.lights, d)
                        else:
                            light_pdf = light_pdf_emitter(scene.lights, si.tri, prev_p, si.p, si.ng)
                        w = technique_mis(0, 0, prev_delta, light_pdf, prev_pdf)
                if chain_max > 0:
                    if chain_state == 1 and chain_len >= 1:  # an emitter triangle or the environment
                        if caustic_owned(scene, x1_p, d1, chain_obj) != 0:
                            w = 0.0  # SMS's caustic next-event estimate owns this path
                L += wp.cw_mul(beta, le) * w
                if record != 0:
                    out.bs_li += wp.cw_mul(gamma, le) * w
            if si.valid == 0:
                if wp.static(bounds):
                    if depth > 0:
                        out.box_lo = wp.vec3(-_FAR)  # a ray to infinity
                        out.box_hi = wp.vec3(_FAR)
                break
            if wp.static(bounds):
                out.box_lo = wp.min(out.box_lo, si.p)
                out.box_hi = wp.max(out.box_hi, si.p)
            if depth + 1 == prefix_depth:
                out.prefix = L  # a path of max_depth = prefix_depth would stop here
                out.bs_li_prefix = out.bs_li
                have_prefix = 1
            if max_depth >= 0 and depth + 1 >= max_depth:
                break
            m = surface_material(scene, si)
            frame = frame_from_normal(si.ns)
            wo = to_local(frame, -d)
            if chain_max > 0:
                if chain_state == 0:
                    if bsdf.is_delta(m) == 0:  # x₁: the first non-delta vertex
                        chain_state = 1
                        x1_p = si.p
                        out.x1_valid = 1
                        out.x1 = si
                        out.x1_wo = -d
                        out.x1_beta = beta
                        out.x1_depth = depth
                elif chain_state == 1:
                    if bsdf.is_delta(m) == 0:
                        chain_state = 2
                    else:
                        chain_len += 1
                        if chain_len == 1:
                            chain_obj = si.object
                            if grazing(d, si.ng):
                                chain_state = 2  # met at a grazing angle: the path tracer's (caustic_owned)
                        if chain_len > chain_max:
                            chain_state = 2
            # record: a view-independent first vertex (cosine-weighted continuation), where the BSDF allows
            view_free = int(0)
            # (not about a normal or bump map's normal: re-evaluating it needs the hit's triangle, which the records do not keep)
            # (nor through a rough transmission lobe: rough dielectrics, and the principled kinds whose spec_trans / diff_trans may cross)
            crosses = m.kind == MATERIAL_ROUGH_DIELECTRIC or m.kind == MATERIAL_PRINCIPLED or m.kind == MATERIAL_PRINCIPLED_THIN
            if record != 0 and depth == 0 and bsdf.has_delta_lobe(m) == 0 and not crosses and m.perturb == PERTURB_NONE and wo[2] != 0.0:
                view_free = 1
                out.recorded = 1
            # ---- next-event estimation ----
            if use_nee and bsdf.is_delta(m) == 0:
                ls = sample_light(
                    scene.lights, si.p, random_uniform(key, c + 0), wp.vec2(random_uniform(key, c + 1), random_uniform(key, c + 2))
                )
                if wp.static(bounds):
                    if ls.is_env != 0:
                        out.box_lo = wp.vec3(-_FAR)
                        out.box_hi = wp.vec3(_FAR)
                    elif ls.pdf > 0.0:
                        out.box_lo = wp.min(out.box_lo, ls.p)
                        out.box_hi = wp.max(out.box_hi, ls.p)
                if ls.pdf > 0.0 and wp.length_sq(ls.radiance) > 0.0:
                    wi = to_local(frame, ls.wi)
                    f = bsdf.eval(m, wo, wi)
                    if wp.length_sq(f) > 0.0:
                        if not light_occluded(scene, si.p, si.ng, ls):
                            w = float(1.0)
                            if ls.delta == 0 and use_bsdf_emission:
                                bsdf_pdf = float(0.0)
                                if view_free != 0:
                                    bsdf_pdf = cosine_hemisphere_pdf(wi * wp.sign(wo[2]))
                                else:
                                    bsdf_pdf = bsdf.pdf(m, wo, wi)
                                w = technique_mis(1, ls.delta, 0, ls.pdf, bsdf_pdf)
                            li = ls.radiance * (w / ls.pdf)
                            L += wp.cw_mul(beta, wp.cw_mul(f, li))
                            if record != 0:
                                if depth == 0:
                                    out.nee_wi = ls.wi
                                    out.nee_li = li
                                else:
                                    out.bs_li += wp.cw_mul(gamma, wp.cw_mul(f, li))
            # ---- BSDF sampling ----
            bs = bsdf.sample(m, wo, random_uniform(key, c + 3), wp.vec2(random_uniform(key, c + 4), random_uniform(key, c + 5)))
            if view_free != 0:
                side = wp.sign(wo[2])  # the outgoing side: a reflection, cosine-weighted about the normal there
                wl = sample_cosine_hemisphere(wp.vec2(random_uniform(key, c + 4), random_uniform(key, c + 5)))
                bs.wi = wp.vec3(wl[0], wl[1], wl[2] * side)
                bs.pdf = cosine_hemisphere_pdf(wl)
                bs.valid = int(bs.pdf > 0.0)
                bs.delta = 0
                bs.eta = 1.0
                if bs.valid != 0:
                    bs.weight = bsdf.eval(m, wo, bs.wi) / bs.pdf
            if bs.valid == 0:
                break
            if record != 0:
                if depth == 0:
                    out.bs_wi = wp.normalize(to_world(frame, bs.wi))
                    if bs.pdf > 0.0:
                        gamma = wp.vec3(1.0 / bs.pdf, 1.0 / bs.pdf, 1.0 / bs.pdf)
                else:
                    gamma = wp.cw_mul(gamma, bs.weight)
            if chain_max > 0:
                if chain_state == 1:
                    if chain_len == 0:
                        d1 = wp.normalize(to_world(frame, bs.wi))
                    elif canonical_lobe(m, wo, bs.wi) == 0:
                        chain_state = 2
            beta = wp.cw_mul(beta, bs.weight)
            if wp.max(beta) <= 0.0:
                break
            eta = eta * bs.eta
            prev_pdf = bs.pdf
            prev_delta = bs.delta
            prev_p = si.p
            d = wp.normalize(to_world(frame, bs.wi))
            o = spawn_origin(scene, si.p, si.ng, d)
            depth += 1
            # ---- Russian roulette ----
            if depth >= rr_depth:
                q = roulette_survival(beta, eta)
                if random_uniform(key, c + 6) >= q:
                    break
                beta = beta / q
                gamma = gamma / q
        out.total = L
        if have_prefix == 0:
            out.prefix = L  # the path ended before prefix_depth segments (or prefix_depth < 0)
            out.bs_li_prefix = out.bs_li
        return out

    return trace_path


