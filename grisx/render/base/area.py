"""Pixel-area samples: the primary sample point as part of the sample, moved between pixels by translation.

ReSTIR PT (:mod:`grisx.render.restir_pt`) integrates, per pixel and frame, over paths from one
fixed primary vertex x₁ — the G-buffer's jittered visible point — and the pixel filter is
averaged over frames outside the reservoirs. Area ReSTIR (Zhang et al. 2024) and gradient-domain
rendering (Kettunen et al. 2015; seed 000) instead put the *film sample* inside the sample: a
pixel's integral is

    I_i = ∫_{[0,1)²} ∫_{lens} [ L_e(x₁(i + u)) + ∫ f(x̄; x₁(i + u)) dx̄ ] du dl,

and a sample is (u, l, x̄): the offset u of the primary sample point inside the pixel, the lens
point l and the path x̄ from the primary vertex x₁ of the camera ray through i + u
(:class:`FilmSample`, ``area_domain`` of :func:`make_area_domain`). Moving a sample to pixel j keeps (u, l) and traces
the ray through j + u — a translation on the film, |∂u'/∂u| = 1 — then shifts x̄ from there with
:func:`~grisx.render.base.path_shift.make_path_shift`'s ``shift`` (``film_shift``), so the
Jacobian of the whole shift is the path shift's. Temporal reuse translates by a *fractional*
motion vector δ instead of a whole pixel: a previous-frame sample at film position s' = p + u' lands at
s = s' − δ, wrapped into the destination pixel where it leaves it (:func:`film_translate_wrapped`, a
translation on the torus of the pixel's support) — a bijection, again with |J| = 1.

Random streams: the film sample has its own stream per pixel and pass (:func:`film_sample`),
apart from the G-buffer's camera sample, so the G-buffer's similarity tests and motion vectors
(which decide who reuses from whom) are independent of the samples being reused.

**The pixel filter.** With a box filter u is uniform over the pixel's square and every sample
weighs 1. With Mitsuba's gaussian (σ, radius r = 4σ: f(t) = max(0, e^{−t²/2σ²} − e^{−r²/2σ²})
per axis, the default of a Mitsuba film) pixel i's value is ∫ w_i(t) L(c_i + t) dt with
w_i = f(t_x) f(t_y) / Z_i normalized over the part of the filter inside the film (what
Mitsuba's splatting film converges to). Then u is uniform over the filter's support
[½ − r, ½ + r)² and x₁'s :class:`~grisx.render.base.path_shift.Domain` carries the film weight
ω_i(u) = (2r)² w_i(u − ½), which :func:`~grisx.render.base.path_shift.make_path_shift`'s walks
and shifts multiply into f (0 where the ray leaves the film). Moving u to pixel j is the same
translation with |J| = 1; ω_j(u) is pixel j's own weight, so the integrand of every domain is
its pixel's filtered one and the reuse stays unbiased, borders included.

Across frames, previous domains are traced with the previous camera through the previous frame's
geometry (:meth:`~grisx.scene.scene.BuiltScene.across_frames`), as ReSTIR PT's temporal stages do.

References: S. Zhang et al., "Area ReSTIR: Resampling for Real-Time Defocus and Antialiasing",
ACM TOG 43(4), 2024; M. Kettunen et al., "Gradient-domain path tracing", 2015; seed 000, Sec. 3.1.
"""

from __future__ import annotations

import functools
from typing import Any

import warp as wp

from grisx.render.base.path_shift import Domain, vertex_from_hit
from grisx.scene.camera import CameraData, camera_ray, film_weight, filter_reach
from grisx.scene.lights import make_lights
from grisx.scene.scene import SceneData, make_surface
from grisx.theory.random import random_uniform

wp.set_module_options({"enable_backward": False})

__all__ = ["FilmSample", "AreaDomain", "film_sample", "make_area_domain", "film_translate", "film_translate_wrapped", "temporal_film_offset", "film_onto_itself", "FILM_STREAM"]

#: the film sample's random stream of a pixel (pixel_key_of), apart from ReSTIR PT's 1–10 and 64+
FILM_STREAM = 48


@wp.struct
class FilmSample:
    """Where pixel i's sample's camera ray goes: film offset u (from the pixel's corner; in the filter's support, [0,1)² for
    a box) and lens point l; ``valid`` = 0 after a failed translation."""

    offset: wp.vec2
    lens: wp.vec2
    valid: int


@wp.struct
class AreaDomain:
    """The primary vertex x₁ of the camera ray through i + u (a path :class:`Domain`) and L_e seen along that ray."""

    dom: Domain
    emission: wp.vec3  # emitted radiance toward the camera; the environment where the ray missed


@wp.func
def film_sample(key: wp.uint32, cam: CameraData) -> FilmSample:
    """A film sample uniform over the pixel filter's support and the lens, from counters 0–3 of ``key``."""
    reach = filter_reach(cam)
    s = FilmSample()
    s.offset = wp.vec2(0.5 - reach + 2.0 * reach * random_uniform(key, 0), 0.5 - reach + 2.0 * reach * random_uniform(key, 1))
    s.lens = wp.vec2(random_uniform(key, 2), random_uniform(key, 3))
    s.valid = 1
    return s


@functools.cache
def make_area_domain(kinds: frozenset[int]) -> Any:
    """``area_domain(scene, cam, x, y, s) -> AreaDomain`` with the ray queries of the kinds ``kinds``
    (:func:`~grisx.scene.scene.make_surface`: the analytic shapes only where the scene has them; cached)."""
    intersect = make_surface(kinds).intersect
    lights = make_lights(kinds)  # the lights of these kinds only
    emitter_radiance, environment_eval = lights.emitter_radiance, lights.environment_eval

    @wp.func
    def area_domain(scene: SceneData, cam: CameraData, x: int, y: int, s: FilmSample) -> AreaDomain:
        """Trace the camera ray of film sample ``s`` in pixel (x, y): its primary vertex and the emission it sees."""
        out = AreaDomain()
        out.emission = wp.vec3(0.0)
        if s.valid == 0:
            out.dom = Domain()
            out.dom.valid = 0
            return out
        weight = film_weight(cam, x, y, s.offset)
        if weight <= 0.0:
            out.dom = Domain()
            out.dom.valid = 0  # outside the film or the filter: contributes nothing
            return out
        ray = camera_ray(cam, float(x) + s.offset[0], float(y) + s.offset[1], s.lens)
        si = intersect(scene, ray.o, ray.d, cam.far_clip)
        out.dom = vertex_from_hit(si, -ray.d)  # valid = 0 where the ray missed
        out.dom.weight = weight
        if si.valid == 0:
            out.emission = environment_eval(scene.lights, ray.d) * weight
        else:
            out.emission = emitter_radiance(scene.lights, si.tri, si.p, si.ng, -ray.d) * weight
        return out

    return area_domain


@wp.func
def temporal_film_offset(x: int, y: int, prev_x: int, prev_y: int, motion: wp.vec2) -> wp.vec2:
    """The film translation u' = u + i + δ − p that carries a sample of pixel i = (``x``, ``y``) into its
    previous pixel p = (``prev_x``, ``prev_y``), δ = ``motion`` (the G-buffer's fractional motion vector: previous
    minus current film position); its negative carries a previous sample of p into i. The one convention of
    every temporal film shift (Area ReSTIR, ReSTIR G-PT's pixel pairs)."""
    return wp.vec2(float(x - prev_x), float(y - prev_y)) + motion


@wp.func
def film_onto_itself(still: int, x: int, y: int, prev_x: int, prev_y: int, translation: wp.vec2) -> bool:
    """Whether a temporal film translation (:func:`temporal_film_offset` or its negative) carries pixel (x, y) onto
    itself, the same pixel and a zero offset, where ``still`` says that the camera and the scene did not move: the
    two domains are then one, and the temporal shift between them is the identity (Area ReSTIR's
    ``film_shift_as_is``, ReSTIR G-PT's ``pair_as_is``)."""
    return still != 0 and prev_x == x and prev_y == y and translation[0] == 0.0 and translation[1] == 0.0


@wp.func
def film_translate_wrapped(s: FilmSample, shift: wp.vec2, cam: CameraData) -> FilmSample:
    """u + ``shift`` wrapped into the filter's support [½ − r, ½ + r)²: a translation on the torus of one pixel's support
    onto another's, again a bijection with |J| = 1, its inverse the wrapped translation by −``shift``.

    Area ReSTIR's temporal shift. The unwrapped translation (:func:`film_translate`) is undefined for a sample that
    the fractional motion δ carries out of the destination pixel; with a box filter that is a fraction |δx| + |δy| of
    the history lost every frame, and what survives feeds the next frame (door-ajar, 128×72, a camera moving 0.02–0.2
    px a frame: 65–94% of the history's translations defined, a kept sample in 28% of the pixels after temporal reuse
    against 74% under a static camera). Wrapped, such a sample re-enters on the other side of the pixel, within one
    pixel of where the motion puts it, and is shifted from there like a spatial neighbour's."""
    reach = filter_reach(cam)
    lo = 0.5 - reach
    out = s
    # where the plain translation stays in the support the offset is its own, to the bit (film_translate's)
    out.offset = wp.vec2(_wrap_into(s.offset[0] + shift[0], lo, 2.0 * reach), _wrap_into(s.offset[1] + shift[1], lo, 2.0 * reach))
    return out


@wp.func
def _wrap_into(u: float, lo: float, side: float) -> float:
    """u itself inside [lo, lo + side), else lo + (u − lo) mod side."""
    if u >= lo and u < lo + side:
        return u
    t = u - lo
    t = t - side * wp.floor(t / side)
    if t >= side:  # floor's rounding, for a tiny negative t: that point is the support's first
        t = t - side
    return lo + t


@wp.func
def film_translate(s: FilmSample, shift: wp.vec2, cam: CameraData) -> FilmSample:
    """u + ``shift``, valid only inside the filter's support [½ − r, ½ + r)² (a translation between two
    pixels' supports, |J| = 1; [0,1)² for a box filter). The temporal shifts use :func:`film_translate_wrapped`,
    which equals it wherever it is valid."""
    reach = filter_reach(cam)
    out = s
    u = s.offset + shift
    out.offset = u
    lo = 0.5 - reach
    hi = 0.5 + reach
    if s.valid == 0 or u[0] < lo or u[0] >= hi or u[1] < lo or u[1] >= hi:
        out.valid = 0
    return out
