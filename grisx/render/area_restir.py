"""Area ReSTIR: ReSTIR PT whose samples carry their primary sample point over the pixel's area (Zhang et al. 2024).

ReSTIR PT (:mod:`grisx.render.restir_pt`) resamples paths from one primary vertex per pixel and
frame; the pixel's footprint is averaged only across frames. Area ReSTIR makes the film sample
part of what is resampled: a sample is (u, l, x̄) — the offset u ∈ [0,1)² of the primary sample
point inside the pixel, the lens point l and the path x̄ from the primary vertex of the ray through
i + u (:mod:`grisx.render.base.area`) — so reuse moves whole pixel-area samples and one reservoir
integrates the pixel's footprint (antialiasing and defocus). Per frame:

``# ---- primary vertices ----``
    each pixel draws a film sample (u, l) uniformly (its own random stream, independent of the
    G-buffer's), traces its camera ray and keeps the primary vertex x₁ and the emission seen
    there (added outside the reservoir, as ReSTIR PT does).
``# ---- initial candidates ----``
    ``candidates`` (1, the paper's setting) path-tracer samples from x₁, streamed into a path
    reservoir by ``stream_candidates`` exactly as ReSTIR PT; the joint density of (u, l, x̄) is the
    path's, the film density being 1. The canonical reservoir always has confidence 1 (also where
    its ray missed: the pixel's domain includes those u).
``# ---- temporal reuse ----``
    with *fractional* motion vectors: the G-buffer's motion δ of the pixel (previous minus current
    film position) and the previous pixel p that holds i + δ define the translation
    u ↦ u + i + δ − p, wrapped into the pixel's support (:func:`~grisx.render.base.area.film_translate_wrapped`:
    a translation on its torus, |J| = 1); the history sample (u', l, x̄) is shifted to (u' + p − i − δ wrapped, l,
    T(x̄)), T the hybrid path shift from the new primary vertex. (Unwrapped, the shift is undefined where the offset
    leaves pixel i, and under sub-pixel motion a box filter loses |δx| + |δy| of the history a frame: that compounds.) MIS is the generalized
    balance heuristic over the two domains (seed 001, Eq. 15–16), the canonical sample's
    p̂_{←p} evaluated through the inverse translation on the previous frame's camera; history
    confidence capped at ``history_cap``. Under a still camera in a scene where nothing moves, a pixel with
    δ = 0 is carried onto itself: its two domains are one, and T is the identity (:func:`film_shift_as_is`)
    instead of a replay to the same path.
``# ---- spatial reuse ----``
    ``spatial_rounds`` rounds of ``neighbors`` (2, the paper's) random pixels within ``radius`` that
    pass the G-buffer similarity test, pairwise MIS against the canonical reservoir. A neighbour's
    sample (u_q, l_q, x̄_q) moves to pixel i by the whole-pixel translation: the ray through
    i + u_q, then the hybrid shift of x̄_q from its primary vertex (|J| of the path shift alone).
``# ---- shading ----``
    L_e(x₁) + f(y) W_y, with the kept sample's film offset stored beside the reservoir.

**What is and isn't Zhang et al. 2024.** Kept: the sample space (film offset and lens point inside
the sample), the whole-pixel and fractional translations as shifts of that coordinate (|J| = 1),
one initial candidate and two spatial neighbours, temporal reuse through fractional motion vectors.
Not kept: their *primary-hit* reservoirs of direct light alone and their raster G-buffer reuse —
here every sample is a full ReSTIR PT path (the primal pass that seed 000 runs its gradients on);
the scene's pixel filter (box, or Mitsuba's gaussian) enters as a film weight with uniform film
samples over its support (:mod:`~grisx.render.base.area`) rather than by filter importance
sampling; previous domains are traced with the
previous camera through the previous frame's geometry, and a suffix is reused across frames
only where nothing moved along it (as ReSTIR PT's temporal stages: ``across_frames``,
``suffix_moved``). Neighbours are chosen from the G-buffer alone, never from the reservoirs' samples, so the
choice is independent of what is reused.

All estimator math is :mod:`grisx.theory`'s (``reservoir_update``/``merge``/``finalize``,
``resampling_weight``, ``two_domain_balance``, pairwise MIS, ``confidence_capped``); shifts and
candidates are :func:`~grisx.render.base.path_shift.make_path_shift`'s. ``jacobian=false`` is the
biased ablation, as for ReSTIR PT.

References: S. Zhang, D. Lin, M. Kettunen, C. Yuksel, C. Wyman, "Area ReSTIR: Resampling for
Real-Time Defocus and Antialiasing", ACM TOG 43(4), 2024; D. Lin et al., "Generalized resampled
importance sampling", SIGGRAPH 2022; seed 000, Sec. 5 (Area ReSTIR as the primal pass).
"""

from __future__ import annotations

import dataclasses
import inspect
from typing import Any

import warp as wp

from grisx.device import SHIFT_REGISTERS, launch, specialized_module
from grisx.errors import InvalidParameterError
from grisx.params import Param
from grisx.render.base.area import FILM_STREAM, FilmSample, film_onto_itself, film_sample, film_translate_wrapped, make_area_domain, temporal_film_offset
from grisx.render.base.path_shift import (
    Domain,
    PathReservoir,
    PathShiftResult,
    ShiftParams,
    make_path_shift,
    path_sample_empty,
    path_target,
    target_back_from,
    target_to,
)
from grisx.render.base.registry import METHODS, RenderMethod, create_renderer, register
from grisx.render.base.reuse import (
    SIMILARITY_DEPTH,
    SIMILARITY_NORMAL_COS,
    domain_code,
    domain_pixel,
    pixels_similar,
    spatial_neighbor,
    temporal_neighbor,
)
from grisx.render.base.screen import kernel_cache, pixel_key_of
from grisx.render.restir_pt import ReSTIRPT, confidence_total, finalize_kept, make_restir_pt_kernels
from grisx.scene.camera import CameraData, camera_data_equal
from grisx.scene.material import SCENE_MOVING_OBJECTS
from grisx.scene.gbuffer import GBufferData
from grisx.scene.scene import SceneData
from grisx.theory.gris import resampling_weight
from grisx.theory.mis import pairwise_mis_canonical_term, pairwise_mis_neighbor, two_domain_balance
from grisx.theory.random import random_uniform
from grisx.theory.reservoir import confidence_capped, reservoir_empty, reservoir_merge, reservoir_update

wp.set_module_options({"enable_backward": False})

__all__ = ["AreaReSTIR", "create_area_restir", "make_area_restir_kernels", "area_params"]

# random streams of a pixel (pixel_key_of), as ReSTIR PT's (whose candidate walk serves as the initial pass)
_STREAM_TEMPORAL = wp.constant(2)
_STREAM_SPATIAL = wp.constant(3)  # + round


@wp.func
def _shift_none() -> PathShiftResult:
    s = PathShiftResult()
    s.path = path_sample_empty()
    s.jacobian = 0.0
    s.valid = False
    return s


@wp.func
def film_shift_as_is(fs: FilmSample, pr: PathReservoir) -> PathShiftResult:
    """T between a domain and itself (a pixel carried onto itself by a zero motion vector, under a still camera, in a
    scene where nothing moves): the identity, |∂T/∂y| = 1. A shift map may be chosen per pair of domains as long as
    T and T⁻¹ agree, and here the hybrid shift would replay the path to the same result at the cost of a path trace.
    Undefined where :func:`film_shift` is before it shifts (no film sample, an empty path)."""
    if fs.valid == 0 or pr.path.length < 1:
        return _shift_none()
    s = PathShiftResult()
    s.path = pr.path
    s.jacobian = 1.0
    s.valid = True
    return s


@kernel_cache
def make_area_restir_kernels(kinds: frozenset[int]) -> dict[str, Any]:
    """The passes of Area ReSTIR compiled for the material kinds ``kinds`` (cached)."""
    shifts = make_path_shift(kinds)
    area_domain = make_area_domain(kinds)
    shift = shifts.shift
    suffix_moved = shifts.suffix_moved
    module = specialized_module(__name__, kinds)

    @wp.func
    def film_shift(scene: SceneData, cam: CameraData, x: int, y: int, fs: FilmSample, pr: PathReservoir, sp: ShiftParams) -> PathShiftResult:
        """T(u, l, x̄) into pixel (x, y): the ray through (x, y) + u, then the path shift from its primary vertex."""
        if fs.valid == 0:
            return _shift_none()
        return shift(scene, area_domain(scene, cam, x, y, fs).dom, pr.path, sp)

    @wp.func
    def film_shift_across(scene: SceneData, cam: CameraData, x: int, y: int, fs: FilmSample, pr: PathReservoir, sp: ShiftParams) -> PathShiftResult:
        """:func:`film_shift` between frames: undefined where the reused suffix met something that moved."""
        if suffix_moved(scene, pr.path):
            return _shift_none()
        return film_shift(scene, cam, x, y, fs, pr, sp)

    # ---- primary vertices ----
    @wp.kernel(module=module)
    def primary_pass(
        scene: SceneData, cam: CameraData, seed: int, frame: int,
        film: wp.array2d(dtype=FilmSample), domains: wp.array2d(dtype=Domain), direct: wp.array2d(dtype=wp.vec3),
    ):
        y, x = wp.tid()
        fs = film_sample(pixel_key_of(seed, frame, x, y, film.shape[1], FILM_STREAM), cam)
        ad = area_domain(scene, cam, x, y, fs)
        film[y, x] = fs
        domains[y, x] = ad.dom
        direct[y, x] = ad.emission

    # ---- temporal reuse, in two stages (one film shift each): the canonical sample into the history's pixel, then the merge ----
    @wp.kernel(module=module, cuda_max_registers=SHIFT_REGISTERS)
    def temporal_canonical_pass(
        scene_prev: SceneData, cam: CameraData, cam_prev: CameraData, sp: ShiftParams, still: int,
        g: GBufferData, g_prev: GBufferData,
        canonical: wp.array2d(dtype=PathReservoir), film_can: wp.array2d(dtype=FilmSample), history: wp.array2d(dtype=PathReservoir),
        out: wp.array2d(dtype=PathReservoir), film_out: wp.array2d(dtype=FilmSample),
        history_pixel: wp.array2d(dtype=wp.int32), target_cj: wp.array2d(dtype=float),
    ):
        y, x = wp.tid()
        fs_c = film_can[y, x]
        film_out[y, x] = fs_c  # the merge stage overwrites it where it keeps the history's sample
        history_pixel[y, x] = -1
        # the previous pixel p and the fractional motion δ come from the G-buffer alone (independent of the samples)
        nb = temporal_neighbor(g, g_prev, x, y, SIMILARITY_NORMAL_COS, SIMILARITY_DEPTH)
        found = bool(False)
        if nb.valid != 0:
            found = history[nb.y, nb.x].res.confidence > 0.0
        if not found:
            out[y, x] = canonical[y, x]  # no history: the canonical reservoir passes through (the merge stage skips it)
            return
        # (where there is a history the merge stage writes the whole reservoir, once)
        can = canonical[y, x]
        # canonical sample: p̂_{←p}(y_c) through the inverse translation, on the previous camera and in the
        # previous frame's scene (each domain in its own frame)
        to_prev = temporal_film_offset(x, y, nb.x, nb.y, g.motion[y, x])
        s_cj = film_shift_as_is(fs_c, can)  # onto itself: the identity
        if not film_onto_itself(still, x, y, nb.x, nb.y, to_prev):
            s_cj = film_shift_across(scene_prev, cam_prev, nb.x, nb.y, film_translate_wrapped(fs_c, to_prev, cam), can, sp)
        t_cj = target_to(s_cj)
        target_cj[y, x] = t_cj
        history_pixel[y, x] = domain_code(nb.x, nb.y, g.hit.shape[1], 0)

    @wp.kernel(module=module, cuda_max_registers=SHIFT_REGISTERS)
    def temporal_merge_pass(
        scene: SceneData, cam: CameraData, seed: int, frame: int, sp: ShiftParams, history_cap: float, still: int,
        g: GBufferData,
        canonical: wp.array2d(dtype=PathReservoir), film_can: wp.array2d(dtype=FilmSample),
        history: wp.array2d(dtype=PathReservoir), film_hist: wp.array2d(dtype=FilmSample),
        history_pixel: wp.array2d(dtype=wp.int32), target_cj: wp.array2d(dtype=float),
        out: wp.array2d(dtype=PathReservoir), film_out: wp.array2d(dtype=FilmSample),
    ):
        y, x = wp.tid()
        code = history_pixel[y, x]
        if code < 0:
            return  # no history: the canonical stage passed the canonical sample through
        nb = domain_pixel(code, g.hit.shape[1])
        can = canonical[y, x]  # its film sample (film_can) is in film_out already, passed through by the canonical stage
        prev = history[nb.y, nb.x]
        ukey = pixel_key_of(seed, frame, x, y, g.hit.shape[1], _STREAM_TEMPORAL)
        c_i = can.res.confidence
        c_j = confidence_capped(prev.res.confidence, history_cap)
        t_c = path_target(can.path)
        m_c = two_domain_balance(c_i, t_c, c_j, target_cj[y, x])  # seed 001, Eq. 15
        # history sample translated into pixel i (fractional motion vector), its path shifted from the new x₁
        to_here = -temporal_film_offset(x, y, nb.x, nb.y, g.motion[y, x])
        fs_t = film_translate_wrapped(film_hist[nb.y, nb.x], to_here, cam)
        t_j = path_target(prev.path)  # p̂_j(y_t), before the shift
        s_t = film_shift_as_is(fs_t, prev)  # onto itself: the identity
        if not film_onto_itself(still, x, y, nb.x, nb.y, to_here):
            s_t = film_shift_across(scene, cam, x, y, fs_t, prev, sp)
        t_ti = path_target(s_t.path)
        t_tj = target_back_from(t_j, s_t)
        m_t = two_domain_balance(c_j, t_tj, c_i, t_ti)
        r = reservoir_empty()
        r = reservoir_update(r, resampling_weight(m_c, t_c, can.res.ucw, 1.0), t_c, c_i, random_uniform(ukey, 0))
        other = prev.res
        other.confidence = c_j
        r = reservoir_merge(r, other, m_t, t_ti, s_t.jacobian, random_uniform(ukey, 1))  # seed 000, Eq. 9
        # the kept sample written once, after the merge; the canonical stage left the canonical film sample in film_out
        if r.selected:
            out[y, x].path = s_t.path
            film_out[y, x] = fs_t
        else:
            out[y, x].path = canonical[y, x].path  # read again: not held across the shift
        finalize_kept(out, y, x, r)

    # ---- spatial reuse, in two stages (one film shift each): the canonical sample's pairwise weight, then the merge ----
    @wp.kernel(module=module, cuda_max_registers=SHIFT_REGISTERS)
    def spatial_canonical_pass(
        scene: SceneData, cam: CameraData, seed: int, frame: int, round_index: int, neighbors: int, radius: float, sp: ShiftParams,
        g: GBufferData,
        inp: wp.array2d(dtype=PathReservoir), film_in: wp.array2d(dtype=FilmSample),
        out: wp.array2d(dtype=PathReservoir), film_out: wp.array2d(dtype=FilmSample),
        codes: wp.array3d(dtype=wp.int32), slots: wp.array3d(dtype=wp.int32), count: wp.array2d(dtype=wp.int32),
        m_canonical: wp.array2d(dtype=float),
    ):
        y, x = wp.tid()
        width = inp.shape[1]
        height = inp.shape[0]
        can = inp[y, x]
        fs_c = film_in[y, x]
        count[y, x] = -1  # not resampled: the merge stage leaves the pixel as it is
        ukey = pixel_key_of(seed, frame, x, y, width, _STREAM_SPATIAL + round_index)
        # ---- the neighbours, drawn once from the G-buffer alone into the DomainList ----
        c_c = can.res.confidence
        total = c_c
        k = int(0)
        for q in range(wp.min(neighbors, codes.shape[2])):
            nb = spatial_neighbor(x, y, width, height, radius, wp.vec2(random_uniform(ukey, 2 * q), random_uniform(ukey, 2 * q + 1)))
            if nb.valid != 0 and pixels_similar(g, x, y, g, nb.x, nb.y, SIMILARITY_NORMAL_COS, SIMILARITY_DEPTH):
                codes[y, x, k] = domain_code(nb.x, nb.y, width, 0)
                slots[y, x, k] = q
                k += 1
                total += inp[nb.y, nb.x].res.confidence
        if k == 0:
            out[y, x] = can
            film_out[y, x] = fs_c
            return
        # the canonical sample's pairwise weight: (u_c, l_c, y_c) moved to each neighbour
        t_c = path_target(can.path)
        m_c = float(0.0)
        for j in range(k):
            nb = domain_pixel(codes[y, x, j], width)
            t_cq = target_to(film_shift(scene, cam, nb.x, nb.y, fs_c, can, sp))  # p̂_{←q}(y_c), seed 001, Eq. 16
            m_c += pairwise_mis_canonical_term(inp[nb.y, nb.x].res.confidence, t_cq, c_c, t_c, k, total)
        m_canonical[y, x] = m_c
        count[y, x] = k

    @wp.kernel(module=module, cuda_max_registers=SHIFT_REGISTERS)
    def spatial_merge_pass(
        scene: SceneData, cam: CameraData, seed: int, frame: int, round_index: int, sp: ShiftParams,
        inp: wp.array2d(dtype=PathReservoir), film_in: wp.array2d(dtype=FilmSample),
        codes: wp.array3d(dtype=wp.int32), slots: wp.array3d(dtype=wp.int32), count: wp.array2d(dtype=wp.int32),
        m_canonical: wp.array2d(dtype=float),
        out: wp.array2d(dtype=PathReservoir), film_out: wp.array2d(dtype=FilmSample),
    ):
        y, x = wp.tid()
        k = int(count[y, x])
        if k < 0:
            return
        width = inp.shape[1]
        can = inp[y, x]
        ukey = pixel_key_of(seed, frame, x, y, width, _STREAM_SPATIAL + round_index)
        c_c = can.res.confidence
        total = confidence_total(inp, codes, y, x, k, c_c)
        t_c = path_target(can.path)
        m_c = m_canonical[y, x]
        r = reservoir_empty()
        r = reservoir_update(r, resampling_weight(m_c, t_c, can.res.ucw, 1.0), t_c, c_c, random_uniform(ukey, 100))
        # a neighbour's kept sample goes to out as it is kept, not carried across the other neighbours' shifts; the
        # canonical one is written at the end, only where no neighbour's replaced it
        neighbor_kept = bool(False)
        # each neighbour's sample moved here by the whole-pixel translation, weighted against the canonical
        for j in range(k):
            nb = domain_pixel(codes[y, x, j], width)
            t_q = path_target(inp[nb.y, nb.x].path)  # p̂_q of the neighbour's path, before its shift
            fs_q = film_in[nb.y, nb.x]
            s = film_shift(scene, cam, x, y, fs_q, inp[nb.y, nb.x], sp)
            other = inp[nb.y, nb.x]  # read after the shift: not held across it
            t_qi = path_target(s.path)
            t_qq = target_back_from(t_q, s)
            m_q = pairwise_mis_neighbor(other.res.confidence, t_qq, c_c, t_qi, k, total)
            r = reservoir_merge(r, other.res, m_q, t_qi, s.jacobian, random_uniform(ukey, 101 + slots[y, x, j]))  # seed 000, Eq. 9
            if r.selected:
                out[y, x].path = s.path
                film_out[y, x] = fs_q
                neighbor_kept = True
        if not neighbor_kept:
            out[y, x].path = inp[y, x].path  # read again here: not held across the shifts
            film_out[y, x] = film_in[y, x]
        finalize_kept(out, y, x, r)

    pt = make_restir_pt_kernels(kinds)  # ReSTIR PT's candidate walk, settle and shade passes serve as they are
    return {"primary": primary_pass, "initial": pt["initial"], "settle": pt["settle"], "temporal_canonical": temporal_canonical_pass, "temporal_merge": temporal_merge_pass,
            "spatial_canonical": spatial_canonical_pass, "spatial_merge": spatial_merge_pass, "shade": pt["shade"]}


class AreaReSTIR(ReSTIRPT):
    """Area ReSTIR over a built scene; ``render_frame(frame)`` runs one frame's passes (see the module docstring).

    ReSTIR PT's settings and buffers (``jitter`` and ``direct`` do not apply: the film sample is always
    in the sample, direct light in the paths) with its own kernels and two spatial neighbours.
    """

    def __init__(self, built: Any, width: int, height: int, *, neighbors: int = 2, **restir_pt: Any) -> None:
        if restir_pt.pop("jitter", True) is not True or restir_pt.pop("direct", "nee") != "nee":
            raise InvalidParameterError(f"{type(self).__name__}: the film sample is always part of the sample (jitter) and direct light is in the paths (direct=nee)")
        super().__init__(built, width, height, neighbors=neighbors, **restir_pt)
        shape = (self.height, self.width)
        # the G-buffer serves the similarity tests and motion vectors only; the primary vertices are the film samples'
        self.films = [wp.zeros(shape, dtype=FilmSample, device=built.device) for _ in range(4)]  # 0: history, 1–2: scratch, 3: canonical

    def make_kernels(self, kinds: frozenset[int]) -> dict[str, Any]:
        return make_area_restir_kernels(kinds)

    def cameras(self, frame: int) -> tuple[Any, Any]:
        """This frame's and the previous frame's camera records."""
        b = self.built
        return b.camera_data(float(frame), self.width, self.height), b.camera_data(float(frame) - 1.0, self.width, self.height)

    def canonical(self, frame: int, stream_frame: int | None = None) -> tuple[wp.array, wp.array]:
        """Primary vertices and initial candidates of ``frame`` (random streams of ``stream_frame``): reservoirs, film samples."""
        b = self.built
        dev = b.device
        dim = (self.height, self.width)
        k = self.k
        sf = int(frame if stream_frame is None else stream_frame)
        cam, _ = self.cameras(frame)
        film = self.films[3]
        with self._phase("primary"):
            launch(k["primary"], dim=dim, inputs=[b.data, cam, self.seed, sf], outputs=[film, self.domains[0], self.direct], device=dev)
        cur = self.buffers[1]
        with self._phase("initial"):
            launch(k["initial"], dim=dim, inputs=[b.data, self.seed, sf, self.candidates, self.max_bounces, self.shift_params, 1.0, self.domains[0],
                                                    self.kept_paths], outputs=[cur], device=dev)
            launch(k["settle"], dim=dim, inputs=[b.data, self.shift_params, self.domains[0], self.kept_paths], outputs=[cur], device=dev)
        return cur, film

    def after_canonical(self, reservoirs: wp.array) -> None:
        """Called with the canonical reservoirs before any reuse (a variant may keep them)."""

    def resample(self, frame: int) -> tuple[wp.array, wp.array]:
        """One frame's passes up to the final reservoirs (canonical, temporal, spatial); returns them and their film samples."""
        b = self.built
        dev = b.device
        dim = (self.height, self.width)
        k = self.k
        with self._phase("gbuffer"):
            self.gbuffer.fill(b, float(frame), self.seed + 104729, jitter=True)
        cam, cam_prev = self.cameras(frame)
        cur, film_cur = self.canonical(frame)
        self.after_canonical(cur)
        history, _, other = self.buffers
        film_hist, film_a, film_b, _ = self.films
        g, g_prev = self.gbuffer.current, self.gbuffer.previous
        if self.temporal and self.frames_rendered > 0:
            with self._phase("temporal"):
                scene_from_prev, scene_prev = b.across_frames()  # each domain in its own frame's scene
                # a pixel carried onto itself under a still camera in a still scene: its two domains are one (film_shift_as_is)
                still = int(camera_data_equal(cam, cam_prev) and SCENE_MOVING_OBJECTS not in b.features.kernel_kinds)
                launch(
                    k["temporal_canonical"], dim=dim,
                    inputs=[scene_prev, cam, cam_prev, self.shift_params, still, g, g_prev, cur, film_cur, history],
                    outputs=[other, film_a, self.history_pixel, self.target_cj], device=dev,
                )
                launch(
                    k["temporal_merge"], dim=dim,
                    inputs=[scene_from_prev, cam, self.seed, int(frame), self.shift_params, self.history_cap, still, g, cur, film_cur, history, film_hist,
                            self.history_pixel, self.target_cj],
                    outputs=[other, film_a], device=dev,
                )
            cur, other = other, cur
            film_cur = film_a
        for rnd in range(self.spatial_rounds):
            film_out = film_b if film_cur is not film_b else film_a
            with self._phase("spatial"):
                nbs = self.spatial_domains
                launch(
                    k["spatial_canonical"], dim=dim,
                    inputs=[b.data, cam, self.seed, int(frame), rnd, self.neighbors, self.radius, self.shift_params, g, cur, film_cur],
                    outputs=[other, film_out, nbs.codes, nbs.slots, nbs.count, self.m_canonical], device=dev,
                )
                launch(
                    k["spatial_merge"], dim=dim,
                    inputs=[b.data, cam, self.seed, int(frame), rnd, self.shift_params, cur, film_cur, nbs.codes, nbs.slots, nbs.count, self.m_canonical],
                    outputs=[other, film_out], device=dev,
                )
            cur, other = other, cur
            film_cur = film_out
        # this frame's reservoirs and film samples are the next frame's history
        wp.copy(film_hist, film_cur)
        self.buffers = [cur, history, other]
        self.frames_rendered += 1
        return cur, film_hist

    def render_frame(self, frame: int) -> wp.array:
        """One frame: primary vertices, initial candidates, temporal and spatial reuse, shading."""
        cur, _ = self.resample(frame)
        with self._phase("shade"):
            launch(self.k["shade"], dim=(self.height, self.width), inputs=[self.direct, cur], outputs=[self.image, self.nonfinite], device=self.built.device)
        return self.image



def create_area_restir(ctx: Any) -> AreaReSTIR:
    return create_renderer(AreaReSTIR, ctx)


#: ReSTIR PT's params that Area ReSTIR takes (jitter and direct do not apply: the film sample is always in the sample)
AREA_KEYS = ("shift", "candidates", "max_depth", "rr_depth", "temporal", "spatial_rounds", "neighbors", "radius", "history_cap",
             "rough_threshold", "near_field", "jacobian", "max_jacobian")


def area_params(keep: tuple[str, ...] = AREA_KEYS) -> tuple[Param, ...]:
    """ReSTIR PT's params named in ``keep`` (the same names mean the same things), with Area ReSTIR's defaults."""
    own = {name: p.default for name, p in inspect.signature(AreaReSTIR.__init__).parameters.items() if p.default is not inspect.Parameter.empty}
    return tuple(dataclasses.replace(p, default=own.get(p.name, p.default)) for p in METHODS["restir-pt"].params if p.name in keep)

# ---- registration (grisx.render.base.registry) ----

register(
    RenderMethod(
        "area-restir",
        "Area ReSTIR (Zhang et al. 2024) on ReSTIR PT paths: the film sample inside the resampled sample, reused by pixel and fractional-motion translations (wrapped into the pixel)",
        create_area_restir,
        params=area_params(),
    )
)
