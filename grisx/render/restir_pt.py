"""ReSTIR PT: spatiotemporal reuse of whole paths with generalized RIS (Lin et al. 2022).

Each pixel's integral is the radiance leaving its primary vertex x₁ toward the
camera, an integral over paths x₁ → … → x_n of f(x̄) (see
:mod:`grisx.render.base.path_shift` for the measure and the shifts). Per frame:

``# ---- primary vertices ----``
    the G-buffer's visible point — a jittered camera ray per pixel — is x₁
    (the pixel's *domain*; the reference path tracer jitters its rays too, so
    both estimate the same pixel integral), and the G-buffer's similarity
    tests and motion vectors are those of the x₁ being reused; emission seen
    directly is added outside the reservoir.
``# ---- initial candidates ----``
    ``candidates`` path-tracer samples from x₁ with next-event estimation at
    every vertex and Russian roulette from ``rr_depth`` on, paths of at most
    ``max_depth`` segments counted from the camera (Mitsuba's meaning, as
    ``pt``: −1 unbounded, 2 direct light only; both default to the scene
    file's ``<integrator>``), so that ``restir-pt`` and ``pt`` estimate the same
    image (``stream_candidates`` of :func:`~grisx.render.base.path_shift.make_path_shift`).
    Every light connection and every emitter hit is one candidate path x̄_l
    labelled with its technique t, target p̂ = luminance(m_t f) (m_t the power
    heuristic between the two techniques, see ``path_shift``) and RIS weight
    w_l = p̂(x̄_l) / (N p(x̄_l)) over N samples (seed 000, Eq. 6), so
    ``reservoir_update`` keeps one path with UCW W = Σ w / p̂(y) (Eq. 8). The
    canonical reservoir has confidence 1 (one frame: the unit of the history cap).
``# ---- temporal reuse ----``
    merge the previous frame's reservoir at the motion-reprojected pixel, its
    confidence capped at ``history_cap`` (20), with the *generalized balance
    heuristic* over the two domains (seed 001, Eqs. 15–16), each p̂_{←j}
    evaluated through the shift (seed 000, Eq. 9).
``# ---- spatial reuse ----``
    ``spatial_rounds`` rounds, each merging ``neighbors`` (3) random pixels
    within ``radius`` (20 px) that pass the G-buffer similarity test, with
    *pairwise MIS* against the canonical reservoir (Bitterli 2022; Lin et al.
    2022) — one shift of each neighbour's path into this pixel and one of
    this pixel's path into each neighbour.
``# ---- shading ----``
    the pixel value L_e(x₁) + (m_t f)(y) · W_y; the reservoir becomes next
    frame's history.

All estimator math (``reservoir_update``/``merge``/``finalize``,
``ris_weight``, ``resampling_weight``, ``balance_mis``, pairwise MIS,
``confidence_capped``, ``target_from``, ``power_heuristic``, the Jacobians
``reconnection_jacobian`` and ``replay_jacobian``) is grisx.theory's; the
shifts and the candidate sampler are
:func:`grisx.render.base.path_shift.make_path_shift`'s. The wrong-Jacobian ablation
(``jacobian=false``: |J| = 1 in every weight) is biased and the tests show it.

**Direct light.** By default the path reservoirs hold direct light too (``direct=nee``: NEE and BSDF
sampling at x₁ with MIS, like every other vertex). ``direct=restir-di`` hands the paths x₁ → light to
:mod:`~grisx.render.restir_di` on the same G-buffer, as Lin et al. 2022 do; the candidates then start
at two segments after x₁ (``ShiftParams.min_bounces``), the walk itself unchanged, so the two
estimators own disjoint sets of paths and their sum estimates ``pt``'s image.

**Variants.** The passes can carry a per-pixel estimate of their own besides the reservoir
(``PathReservoir.estimate``), formed at each reuse step from the shifts the pass evaluates anyway:
:class:`PixelEstimateHooks` compiles a variant's Warp funcs into the same kernels
(:func:`build_restir_pt_kernels`; ReSTCV, :mod:`grisx.render.restcv`, is one). Without hooks the
kernels are ReSTIR PT's alone.

**Stages** (``DESIGN.md``, "GPU execution"). Each phase runs as kernels with at most one
inlined shift or walk: ``initial_pass`` (the candidate walk, its kept candidate in
:class:`~grisx.render.base.path_shift.PathSlots`) then ``settle_pass`` (the kept path's own shift);
``temporal_canonical_pass`` (T_{i→j}(y_c)) then ``temporal_merge_pass``; per spatial round
``spatial_canonical_pass`` (draws the neighbours into a :class:`~grisx.render.base.reuse.DomainList`,
m_c) then ``spatial_merge_pass``. What one stage hands the next (the neighbours, m_c, p̂_{←j}(y_c), a
variant's state) goes through per-pixel buffers; the images are bit-identical to the one-kernel
passes. On CUDA the walk runs under :data:`~grisx.device.WALK_REGISTERS` and the shift stages under
:data:`~grisx.device.SHIFT_REGISTERS`, and each stage writes
a reservoir's words once where it can: a lane's store of one field at a record's stride is a memory
transaction of its own, so a record copied and then rewritten cost the temporal stages a third of their
time (benchmarks/README, "ReSTIR PT's merges write the kept path once").

**Moving objects.** Temporal reuse evaluates every domain in its own frame's
scene (:meth:`~grisx.scene.scene.BuiltScene.across_frames`): this frame's
path shifted into the previous frame's domain traces the previous frame's
geometry, and a reconnection reuses its suffix x_k … x_n across frames only
where none of its segments meets the box of something that moved (the
temporal stages replay the suffix to test it: ``shift_across``, nothing
stored per path). Lin et al. 2022 evaluate the previous domains with the current
geometry and reuse suffixes regardless, which is biased around moving
objects; here the temporal shift fails there instead, and the image stays
unbiased (``tests/render/test_reuse_unbiased.py``, fast-objects).

References: D. Lin et al., "Generalized resampled importance sampling:
foundations of ReSTIR", SIGGRAPH 2022; B. Bitterli, PhD thesis (2022), Ch. 9.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import warp as wp

from grisx.device import SHIFT_REGISTERS, WALK_REGISTERS, launch, specialized_module
from grisx.params import Param
from grisx.render.base.registry import RenderMethod, composed_direct, create_renderer, register, renderer_params
from grisx.errors import InvalidParameterError
from grisx.scene.gbuffer import GBuffer, GBufferData
from grisx.render.base.path_shift import (
    Domain,
    PathReservoir,
    PathSample,
    PathShiftResult,
    PathSlots,
    ShiftParams,
    make_path_shift,
    path_sample_empty,
    path_slot_load,
    path_slot_store,
    path_slots,
    path_target,
    shift_params,
    target_back_from,
    target_to,
    vertex_from_hit,
)
from grisx.render.base.screen import ScreenSpaceRenderer, kernel_cache, pixel_key_of
from grisx.render.base.reuse import (
    SIMILARITY_DEPTH,
    SIMILARITY_NORMAL_COS,
    DomainList,
    NeighborPixel,
    domain_code,
    domain_pixel,
    pixels_similar,
    spatial_neighbor,
    temporal_neighbor,
)
from grisx.scene.scene import SceneData, finite_or_dropped
from grisx.theory.control_variate import CVOptions, cv_options
from grisx.theory.gris import resampling_weight
from grisx.theory.mis import pairwise_mis_canonical_term, pairwise_mis_neighbor, two_domain_balance
from grisx.theory.random import random_subkey, random_uniform
from grisx.theory.reservoir import Reservoir, confidence_capped, reservoir_empty, reservoir_finalize, reservoir_merge, reservoir_update

wp.set_module_options({"enable_backward": False})

__all__ = ["PathReservoir", "path_reservoir", "confidence_total", "ReSTIRPT", "create_restir_pt", "make_restir_pt_kernels", "build_restir_pt_kernels", "PixelEstimateHooks", "TemporalStep", "SpatialStep", "shade_estimate"]

#: where direct light comes from: the path reservoirs' own NEE, or ReSTIR DI (Lin et al. 2022 handle it apart)
DIRECT_CHOICES = ("nee", "restir-di")
# random streams of a pixel (pixel_key_of: the base's one key scheme; the camera sample has its own key)
_STREAM_RESAMPLE = wp.constant(1)
_STREAM_TEMPORAL = wp.constant(2)
_STREAM_SPATIAL = wp.constant(3)  # + round
_STREAM_PATHS = wp.constant(64)  # + candidate: the path's own seed (replayed by shifts)


@wp.func
def path_reservoir(r: Reservoir, path: PathSample) -> PathReservoir:
    """The finalized reservoir (UCW W = w_sum / p̂(y), seed 000, Eq. 8) with its kept path."""
    pr = PathReservoir()
    pr.res = reservoir_finalize(r)
    pr.path = path
    return pr


@wp.func
def finalize_kept(out: wp.array2d(dtype=PathReservoir), y: int, x: int, r: Reservoir):
    """:func:`path_reservoir` for a pass that wrote the kept path into ``out[y, x].path`` as it kept it (a path carried
    in registers across the shifts of a merge spilled): the finalized reservoir beside it, and no estimate."""
    out[y, x].res = reservoir_finalize(r)
    out[y, x].estimate = wp.vec3(0.0)


@wp.func
def confidence_total(inp: wp.array2d(dtype=PathReservoir), codes: wp.array3d(dtype=wp.int32), y: int, x: int, k: int, c_c: float) -> float:
    """Pairwise MIS's total confidence C = c_c + Σ of the k domains drawn into ``codes`` (in drawing order,
    as the canonical stage summed it)."""
    total = c_c
    for j in range(k):
        nb = domain_pixel(codes[y, x, j], inp.shape[1])
        total += inp[nb.y, nb.x].res.confidence
    return total


@wp.func
def _spatial_candidate(
    g: GBufferData, domains: wp.array2d(dtype=Domain), inp: wp.array2d(dtype=PathReservoir), x: int, y: int, radius: float, u: wp.vec2
) -> NeighborPixel:
    """A random pixel within ``radius`` that may take part in spatial reuse: a hit, similar, with a reservoir."""
    nb = spatial_neighbor(x, y, domains.shape[1], domains.shape[0], radius, u)
    if nb.valid != 0:
        if domains[nb.y, nb.x].valid == 0 or inp[nb.y, nb.x].res.confidence <= 0.0:
            nb.valid = 0
        elif not pixels_similar(g, x, y, g, nb.x, nb.y, SIMILARITY_NORMAL_COS, SIMILARITY_DEPTH):
            nb.valid = 0
    return nb


@wp.struct
class TemporalStep:
    """What the temporal pass evaluated for pixel (x, y) and its history pixel ``nb``: the canonical
    reservoir, the history ``prev`` (its confidence c_j after the cap), of T_{i→j}(y_c) (the canonical stage's
    shift into the history's domain) its f and |∂T/∂y| (0 and 0 where it failed), T_{j→i}(y_prev) = ``s_t`` and
    the two candidates' MIS weights."""

    x: int
    y: int
    nb: NeighborPixel
    can: PathReservoir
    prev: PathReservoir
    c_j: float
    f_cj: wp.vec3
    jacobian_cj: float
    s_t: PathShiftResult
    m_c: float
    m_t: float


@wp.struct
class SpatialStep:
    """What the spatial pass evaluated for pixel (x, y) and its ``j``-th neighbour ``nb``: the canonical
    reservoir, the neighbour's ``other``, T_{q→i}(y_q) = ``s_qi`` and its MIS weight, and of T_{i→q}(y_c) (the canonical
    stage's shift into the neighbour) its f and |∂T/∂y| (0 and 0 where it failed)."""

    x: int
    y: int
    nb: NeighborPixel
    j: int
    can: PathReservoir
    other: PathReservoir
    s_qi: PathShiftResult
    m_q: float
    f_cq: wp.vec3
    jacobian_cq: float


@dataclasses.dataclass(frozen=True)
class PixelEstimateHooks:
    """Warp funcs with which a variant of ReSTIR PT's passes carries its own pixel estimate.

    The estimate lives in ``PathReservoir.estimate`` and is formed, at every reuse step, from the
    shifts the pass evaluates for GRIS anyway (ReSTCV, :mod:`grisx.render.restcv`: seed 002, Listing 1).
    The passes call, with ``o`` the run's :class:`~grisx.theory.control_variate.CVOptions`:

    * ``temporal(o, g, g_prev, t: TemporalStep, res) -> PathReservoir``: what the temporal pass
      stores, given what it evaluated and GRIS's result ``res``;
    * ``spatial_begin(o, can) -> state``, ``spatial_add(o, state, g, st: SpatialStep) -> state`` (each
      neighbour, from the merge loop, with what both stages evaluated for it) and
      ``spatial_end(state, can, m_c, res) -> PathReservoir``: what the spatial pass stores;
    * ``shade(direct, pr) -> vec3``: the pixel value.

    The spatial pass runs as two kernels (the canonical MIS loop, then the merge loop); the state lives in the
    merge loop alone, and what the canonical loop evaluated reaches it through per-neighbour buffers (a per-pixel
    state kept between the kernels held the canonical shifts of up to 16 neighbours: 256 B a pixel, live beside
    every shift of the merge). ``spatial_state`` is the Warp struct type of ``state``.

    ``owner`` names the Warp modules of the variant's kernels.
    """

    owner: str
    temporal: Any
    spatial_begin: Any
    spatial_add: Any
    spatial_end: Any
    shade: Any
    spatial_state: Any


@wp.func
def shade_estimate(direct: wp.vec3, pr: PathReservoir) -> wp.vec3:
    """A variant's pixel value: L_e(x₁) + the estimate its reservoir carries (a ``shade`` hook)."""
    return direct + pr.estimate


class PassKernels(dict):
    """A renderer's kernels by pass name, and ``spatial_state``: the struct its spatial stages hand over."""

    spatial_state: Any = None


@wp.struct
class _NoSpatialState:
    unused: int


@kernel_cache
def make_restir_pt_kernels(kinds: frozenset[int]) -> dict[str, Any]:
    """The passes of ReSTIR PT compiled for the material kinds ``kinds`` (cached)."""
    return build_restir_pt_kernels(kinds)


def build_restir_pt_kernels(kinds: frozenset[int], hooks: PixelEstimateHooks | None = None) -> dict[str, Any]:
    """The passes of ReSTIR PT for the material kinds ``kinds``, with a variant's ``hooks`` compiled in (uncached)."""
    shifts = make_path_shift(kinds)
    shift = shifts.shift
    shift_across = shifts.shift_across  # between frames: fails where the reused suffix met something that moved
    # ReSTIR PT shades f(y) W_y: only a variant (its hooks) reads the walk's colour estimate
    sample_paths = shifts.stream_candidates_kept if hooks is not None else shifts.stream_candidates_kept_bare
    settle = shifts.settle
    est = hooks  # the variant's code is compiled in only where it is not None (wp.static)
    est_temporal = None if hooks is None else hooks.temporal
    est_spatial_begin = None if hooks is None else hooks.spatial_begin
    est_spatial_add = None if hooks is None else hooks.spatial_add
    est_spatial_end = None if hooks is None else hooks.spatial_end
    est_shade = None if hooks is None else hooks.shade

    # what a variant's spatial pass carries from the canonical stage to the merge stage
    state_t = _NoSpatialState if hooks is None else hooks.spatial_state

    # ---- primary vertices ----
    module = specialized_module(__name__ if hooks is None else hooks.owner, kinds)

    @wp.kernel(module=module)
    def primary_pass(g: GBufferData, domains: wp.array2d(dtype=Domain), direct: wp.array2d(dtype=wp.vec3)):
        y, x = wp.tid()
        # x₁ is the G-buffer's visible point (its jittered camera sample), so the similarity tests describe it
        domains[y, x] = vertex_from_hit(g.si[y, x], g.wo[y, x])  # valid = 0 where the ray missed
        direct[y, x] = g.emission[y, x]  # emission seen directly (the environment where nothing was hit)

    # ---- initial candidates ----
    @wp.kernel(module=module, cuda_max_registers=WALK_REGISTERS)
    def initial_pass(
        scene: SceneData,
        seed: int,
        frame: int,
        candidates: int,
        max_bounces: int,
        sp: ShiftParams,
        missed_confidence: float,
        domains: wp.array2d(dtype=Domain),
        kept: PathSlots,
        out: wp.array2d(dtype=PathReservoir),
    ):
        """N paths per pixel streamed into its reservoir; confidence 1, or ``missed_confidence`` where the
        primary ray missed (Area ReSTIR: 1, those film samples are part of the pixel's domain). The kept path is left in
        the pixel's slot of ``kept``, the bookkeeping in ``out``: :func:`settle_pass` joins them."""
        y, x = wp.tid()
        width = domains.shape[1]
        ukey = pixel_key_of(seed, frame, x, y, width, _STREAM_RESAMPLE)
        dom = domains[y, x]
        pr = PathReservoir()
        pr.res = reservoir_empty()
        pr.path = path_sample_empty()
        pr.estimate = wp.vec3(0.0)
        inv_n = 1.0 / float(candidates)
        path_slot_store(kept, y, x, pr.path)  # what the slot holds where no candidate is kept
        if dom.valid != 0:
            for cand in range(candidates):
                key = pixel_key_of(seed, frame, x, y, width, _STREAM_PATHS + cand)  # the path's seed: shifts replay it
                # the kept candidate goes to the slot as it is kept (not carried across the walk's rays)
                pr = sample_paths(scene, dom, key, max_bounces, inv_n, sp, pr, random_subkey(ukey, cand), kept, y, x)
            pr.res.confidence = 1.0  # one frame's canonical sample: the unit of the history cap
        else:
            pr.res.confidence = missed_confidence
        out[y, x].res = pr.res  # finalized by settle_pass: the path walk and the shift are two kernels, not one
        out[y, x].estimate = pr.estimate

    @wp.kernel(module=module, cuda_max_registers=SHIFT_REGISTERS)
    def settle_pass(scene: SceneData, sp: ShiftParams, domains: wp.array2d(dtype=Domain), kept: PathSlots, out: wp.array2d(dtype=PathReservoir)):
        """The kept candidate (from its slot) re-evaluated as the shifts see it, and the UCW (``settle``): the whole
        reservoir written once."""
        y, x = wp.tid()
        pr = PathReservoir()
        pr.res = out[y, x].res
        pr.path = path_slot_load(kept, y, x)
        pr.estimate = out[y, x].estimate
        out[y, x] = settle(scene, domains[y, x], pr, sp)

    # ---- temporal reuse, in two stages (one shift each): the canonical path into the history's domain, then the merge ----
    @wp.kernel(module=module, cuda_max_registers=SHIFT_REGISTERS)
    def temporal_canonical_pass(
        scene: SceneData,
        sp: ShiftParams,
        g: GBufferData,
        g_prev: GBufferData,
        domains: wp.array2d(dtype=Domain),
        domains_prev: wp.array2d(dtype=Domain),
        canonical: wp.array2d(dtype=PathReservoir),
        history: wp.array2d(dtype=PathReservoir),
        out: wp.array2d(dtype=PathReservoir),
        history_pixel: wp.array2d(dtype=wp.int32),
        target_cj: wp.array2d(dtype=float),
        f_cj: wp.array2d(dtype=wp.vec3),
        jacobian_cj: wp.array2d(dtype=float),
    ):
        y, x = wp.tid()
        history_pixel[y, x] = -1
        code = int(-1)
        if domains[y, x].valid != 0:
            nb = temporal_neighbor(g, g_prev, x, y, SIMILARITY_NORMAL_COS, SIMILARITY_DEPTH)
            if nb.valid != 0:
                if domains_prev[nb.y, nb.x].valid != 0 and history[nb.y, nb.x].res.confidence > 0.0:
                    code = domain_code(nb.x, nb.y, domains.shape[1], 0)
        if code < 0:
            out[y, x] = canonical[y, x]  # no history: the canonical reservoir passes through (the merge stage skips it)
            return
        # (where there is a history the merge stage writes the whole reservoir, once)
        hp = domain_pixel(code, domains.shape[1])
        # canonical path y_c: p̂_{←j}(y_c) through T_{i→j} (seed 001, Eq. 16)
        s_cj = shift_across(scene, domains_prev[hp.y, hp.x], canonical[y, x].path, sp)
        target_cj[y, x] = target_to(s_cj)
        if wp.static(est is not None):
            # a variant's estimate needs T_{i→j}(y_c)'s f and |J|: two small arrays, not the whole 136-byte result
            # (storing that record per lane made this stage 6× ReSTIR PT's, H200 1080p)
            f_cj[y, x] = s_cj.path.f
            jacobian_cj[y, x] = s_cj.jacobian
        history_pixel[y, x] = code

    @wp.kernel(module=module, cuda_max_registers=SHIFT_REGISTERS)
    def temporal_merge_pass(
        scene: SceneData,
        seed: int,
        frame: int,
        sp: ShiftParams,
        history_cap: float,
        cvo: CVOptions,
        g: GBufferData,
        g_prev: GBufferData,
        domains: wp.array2d(dtype=Domain),
        canonical: wp.array2d(dtype=PathReservoir),
        history: wp.array2d(dtype=PathReservoir),
        history_pixel: wp.array2d(dtype=wp.int32),
        target_cj: wp.array2d(dtype=float),
        f_cj: wp.array2d(dtype=wp.vec3),
        jacobian_cj: wp.array2d(dtype=float),
        out: wp.array2d(dtype=PathReservoir),
    ):
        y, x = wp.tid()
        code = history_pixel[y, x]
        if code < 0:
            return  # no history: the canonical stage passed the canonical reservoir through
        nb = domain_pixel(code, domains.shape[1])
        can = canonical[y, x]
        prev = history[nb.y, nb.x]
        dom_i = domains[y, x]
        ukey = pixel_key_of(seed, frame, x, y, domains.shape[1], _STREAM_TEMPORAL)
        c_i = can.res.confidence
        c_j = confidence_capped(prev.res.confidence, history_cap)
        t_c = path_target(can.path)
        t_cj = target_cj[y, x]
        m_c = two_domain_balance(c_i, t_c, c_j, t_cj)  # seed 001, Eq. 15
        # history path y_t shifted into this pixel: p̂_i(T(y_t)) and p̂_{←j}(T(y_t)) = p̂_j(y_t) / |J|
        t_j = path_target(prev.path)  # p̂_j(y_t), before the shift
        s_t = shift_across(scene, dom_i, prev.path, sp)
        t_ti = path_target(s_t.path)  # 0 where the shift failed
        t_tj = target_back_from(t_j, s_t)
        m_t = two_domain_balance(c_j, t_tj, c_i, t_ti)
        r = reservoir_empty()
        r = reservoir_update(r, resampling_weight(m_c, t_c, can.res.ucw, 1.0), t_c, c_i, random_uniform(ukey, 0))
        canonical_kept = r.selected
        other = prev.res
        other.confidence = c_j
        r = reservoir_merge(r, other, m_t, t_ti, s_t.jacobian, random_uniform(ukey, 1))  # seed 000, Eq. 9
        # the kept path, chosen after the merge (no shift follows it: nothing is held across one) and written once: in
        # place (each branch its own store: 0.15 ms a frame less than a path chosen in registers, H200 1080p), or inside
        # the variant's reservoir
        if wp.static(est is None):
            if r.selected:
                out[y, x].path = s_t.path
            elif canonical_kept:
                out[y, x].path = canonical[y, x].path  # read again: not held across the shift
            else:
                out[y, x].path = path_sample_empty()
            finalize_kept(out, y, x, r)
        else:
            kept = path_sample_empty()
            if r.selected:
                kept = s_t.path
            elif canonical_kept:
                kept = canonical[y, x].path
            # the two reservoirs read again after the shift, not held across it (the variant's spills)
            step = TemporalStep(x=x, y=y, nb=nb, can=canonical[y, x], prev=history[nb.y, nb.x], c_j=c_j, f_cj=f_cj[y, x], jacobian_cj=jacobian_cj[y, x],
                                s_t=s_t, m_c=m_c, m_t=m_t)
            out[y, x] = est_temporal(cvo, g, g_prev, step, path_reservoir(r, kept))

    # ---- spatial reuse, in two stages (one shift each): the canonical path's pairwise weight, then the merge ----
    @wp.kernel(module=module, cuda_max_registers=SHIFT_REGISTERS)
    def spatial_canonical_pass(
        scene: SceneData,
        seed: int,
        frame: int,
        round_index: int,
        neighbors: int,
        radius: float,
        sp: ShiftParams,
        cvo: CVOptions,
        g: GBufferData,
        domains: wp.array2d(dtype=Domain),
        inp: wp.array2d(dtype=PathReservoir),
        out: wp.array2d(dtype=PathReservoir),
        codes: wp.array3d(dtype=wp.int32),
        slots: wp.array3d(dtype=wp.int32),
        count: wp.array2d(dtype=wp.int32),
        m_canonical: wp.array2d(dtype=float),
        f_cq: wp.array3d(dtype=wp.vec3),
        jacobian_cq: wp.array3d(dtype=float),
    ):
        y, x = wp.tid()
        width = domains.shape[1]
        can = inp[y, x]
        count[y, x] = -1  # not resampled: the merge stage leaves the pixel as it is
        dom_i = domains[y, x]
        if dom_i.valid == 0:
            out[y, x] = can
            return
        ukey = pixel_key_of(seed, frame, x, y, width, _STREAM_SPATIAL + round_index)
        # ---- the neighbours, drawn once into the DomainList: both stages read them (k and C of pairwise MIS) ----
        c_c = can.res.confidence
        total = c_c
        k = int(0)
        for q in range(wp.min(neighbors, codes.shape[2])):
            nb = _spatial_candidate(g, domains, inp, x, y, radius, wp.vec2(random_uniform(ukey, 2 * q), random_uniform(ukey, 2 * q + 1)))
            if nb.valid != 0:
                codes[y, x, k] = domain_code(nb.x, nb.y, width, 0)
                slots[y, x, k] = q
                k += 1
                total += inp[nb.y, nb.x].res.confidence
        if k == 0:
            out[y, x] = can
            return
        # the canonical path's pairwise weight m_c = Σ_q (pair q's canonical share)
        t_c = path_target(can.path)
        m_c = float(0.0)
        for j in range(k):
            nb = domain_pixel(codes[y, x, j], width)
            s_cq = shift(scene, domains[nb.y, nb.x], can.path, sp)
            t_cq = target_to(s_cq)  # p̂_{←q}(y_c), seed 001, Eq. 16
            if wp.static(est is not None):
                f_cq[j, y, x] = s_cq.path.f  # T_{i→q}(y_c) for a variant's estimate (0 where it failed)
                jacobian_cq[j, y, x] = s_cq.jacobian
            m_c += pairwise_mis_canonical_term(inp[nb.y, nb.x].res.confidence, t_cq, c_c, t_c, k, total)
        m_canonical[y, x] = m_c
        count[y, x] = k

    @wp.kernel(module=module, cuda_max_registers=SHIFT_REGISTERS)
    def spatial_merge_pass(
        scene: SceneData,
        seed: int,
        frame: int,
        round_index: int,
        sp: ShiftParams,
        cvo: CVOptions,
        g: GBufferData,
        domains: wp.array2d(dtype=Domain),
        inp: wp.array2d(dtype=PathReservoir),
        codes: wp.array3d(dtype=wp.int32),
        slots: wp.array3d(dtype=wp.int32),
        count: wp.array2d(dtype=wp.int32),
        m_canonical: wp.array2d(dtype=float),
        f_cq: wp.array3d(dtype=wp.vec3),
        jacobian_cq: wp.array3d(dtype=float),
        out: wp.array2d(dtype=PathReservoir),
    ):
        y, x = wp.tid()
        k = int(count[y, x])
        if k < 0:
            return
        width = domains.shape[1]
        can = inp[y, x]
        ukey = pixel_key_of(seed, frame, x, y, width, _STREAM_SPATIAL + round_index)
        c_c = can.res.confidence
        total = confidence_total(inp, codes, y, x, k, c_c)
        t_c = path_target(can.path)
        m_c = m_canonical[y, x]
        if wp.static(est is not None):
            state = est_spatial_begin(cvo, can)
        r = reservoir_empty()
        r = reservoir_update(r, resampling_weight(m_c, t_c, can.res.ucw, 1.0), t_c, c_c, random_uniform(ukey, 100))
        # a neighbour's kept path goes to out[y, x].path as it is kept, not carried across the other neighbours' shifts;
        # the canonical one (or none) is written at the end, only where no neighbour's replaced it
        own_kept = r.selected
        neighbor_kept = bool(False)
        # each neighbour's path shifted here, weighted against the canonical domain
        for j in range(k):
            nb = domain_pixel(codes[y, x, j], width)
            t_q = path_target(inp[nb.y, nb.x].path)  # p̂_q of the neighbour's path, before its shift
            s = shift(scene, domains[y, x], inp[nb.y, nb.x].path, sp)  # x₁ read again for each shift, not held across them
            other = inp[nb.y, nb.x]  # read after the shift: not held across it
            t_qi = path_target(s.path)  # 0 where the shift failed
            t_qq = target_back_from(t_q, s)
            m_q = pairwise_mis_neighbor(other.res.confidence, t_qq, c_c, t_qi, k, total)
            if wp.static(est is not None):
                # the canonical reservoir read again for each neighbour, not held across the shifts (the variant's spills)
                step = SpatialStep(x=x, y=y, nb=nb, j=j, can=inp[y, x], other=other, s_qi=s, m_q=m_q, f_cq=f_cq[j, y, x], jacobian_cq=jacobian_cq[j, y, x])
                state = est_spatial_add(cvo, state, g, step)
            r = reservoir_merge(r, other.res, m_q, t_qi, s.jacobian, random_uniform(ukey, 101 + slots[y, x, j]))  # seed 000, Eq. 9
            if r.selected:
                out[y, x].path = s.path
                neighbor_kept = True
        if not neighbor_kept:
            if own_kept:
                out[y, x].path = inp[y, x].path  # read again here: not held across the shifts
            else:
                out[y, x].path = path_sample_empty()
        if wp.static(est is None):
            finalize_kept(out, y, x, r)
        else:
            out[y, x] = est_spatial_end(state, inp[y, x], m_c, path_reservoir(r, out[y, x].path))  # the kept path read back

    # ---- shading ----
    @wp.kernel(module=module)
    def shade_pass(
        direct: wp.array2d(dtype=wp.vec3),
        reservoirs: wp.array2d(dtype=PathReservoir),
        image: wp.array2d(dtype=wp.vec3),
        nonfinite: wp.array(dtype=wp.int32),
    ):
        y, x = wp.tid()
        pr = reservoirs[y, x]
        L = direct[y, x]
        if wp.static(est is not None):
            L = est_shade(L, pr)
        elif pr.res.ucw > 0.0 and pr.path.length > 0:
            L = L + pr.path.f * pr.res.ucw  # f(y) · W_y (seed 000, Eq. 7)
        image[y, x] = finite_or_dropped(L, nonfinite)

    kernels = PassKernels(primary=primary_pass, initial=initial_pass, settle=settle_pass, temporal_canonical=temporal_canonical_pass,
                          temporal_merge=temporal_merge_pass,
                          spatial_canonical=spatial_canonical_pass, spatial_merge=spatial_merge_pass, shade=shade_pass)
    kernels.spatial_state = state_t
    return kernels


class ReSTIRPT(ScreenSpaceRenderer):
    """ReSTIR PT over a built scene; ``render_frame(frame)`` runs one frame's passes (see the module docstring)."""

    def __init__(
        self,
        built: Any,
        width: int,
        height: int,
        *,
        shift: str = "hybrid",
        candidates: int = 1,
        max_depth: int = 16,
        rr_depth: int = 5,
        temporal: bool = True,
        spatial_rounds: int = 1,
        neighbors: int = 3,
        radius: float = 20.0,
        history_cap: float = 20.0,
        rough_threshold: float = 0.2,
        near_field: float = 0.01,
        jacobian: bool = True,
        max_jacobian: float = 0.0,
        jitter: bool = True,
        direct: str = "nee",
        seed: int = 0,
        timer: Any = None,
    ) -> None:
        if direct not in DIRECT_CHOICES:
            raise InvalidParameterError(f"direct must be one of {', '.join(DIRECT_CHOICES)}, not '{direct}'")
        if candidates < 1 or max_depth == 0 or max_depth < -1 or rr_depth < 1 or spatial_rounds < 0 or neighbors < 0 or radius <= 0.0:
            raise InvalidParameterError(
                "restir-pt needs candidates >= 1, max_depth -1 or >= 1, rr_depth >= 1, spatial_rounds >= 0, neighbors >= 0, radius > 0"
            )
        direct = composed_direct(direct, int(max_depth))
        self.resolved_params = {"direct": direct}  # for render --json
        self.built = built
        self.width, self.height = int(width), int(height)
        self.candidates = int(candidates)
        self.max_depth = int(max_depth)
        self.rr_depth = int(rr_depth)
        # segments after x₁: the camera segment is the first of max_depth (−1: unbounded; 0: emitters seen directly only)
        self.max_bounces = -1 if self.max_depth < 0 else self.max_depth - 1
        self.temporal = bool(temporal)
        self.spatial_rounds = int(spatial_rounds)
        self.neighbors = int(neighbors)
        self.radius = float(radius)
        self.history_cap = float(history_cap)
        self.jitter = bool(jitter)
        self.seed = int(seed)
        self.timer = timer
        # the near field is a fraction of the scene's radius, so one default fits every scene's scale
        self.shift_params = shift_params(
            shift,
            rough_threshold=rough_threshold,
            near_distance=float(near_field) * float(built.data.scene_radius),
            jacobian_max=max_jacobian,
            jacobian=jacobian,
            rr_depth=rr_depth,
            min_bounces=2 if direct == "restir-di" else 1,  # ReSTIR DI owns the paths x₁ → light
        )
        self.k = self.make_kernels(built.features.kernel_kinds)
        self.cv_options = cv_options()  # the passes' CV options: unused by ReSTIR PT itself (see PixelEstimateHooks)
        dev = built.device
        shape = (self.height, self.width)
        self.direct_name = direct
        self.di = None
        if direct == "restir-di":
            # composed through the registry, as ReSTIR GI does: the same G-buffer, its own random streams
            from grisx.render.base.registry import METHODS, RenderContext

            ctx = RenderContext(built, width, height, {"jitter": jitter, **self.direct_params()}, self.seed + 7919, timer, self.DIRECT_METHOD)
            self.di = METHODS[self.DIRECT_METHOD].create(ctx)
            self.gbuffer = self.di.gbuffer
        else:
            self.gbuffer = GBuffer(self.width, self.height, dev, material=self.GBUFFER_MATERIAL)
        self.domains = [wp.zeros(shape, dtype=Domain, device=dev) for _ in range(2)]  # current, previous
        self.buffers = [wp.zeros(shape, dtype=PathReservoir, device=dev) for _ in range(3)]  # 0: history, 1–2: scratch
        self.kept_paths = path_slots(self.height, self.width, dev)  # the initial walk's kept candidate (settle_pass reads it)
        # the spatial pass's two stages share the neighbours drawn, m_c, and (for a variant) the canonical path's shifts
        self.spatial_domains = DomainList(self.height, self.width, self.neighbors, dev)
        self.m_canonical = wp.zeros(shape, dtype=float, device=dev)
        state_t = getattr(self.k, "spatial_state", None) or _NoSpatialState  # a subclass with passes of its own has none
        # the temporal pass's two stages share the history pixel, p̂_{←j}(y_c) and (for a variant) T_{i→j}(y_c)'s f and |J|
        self.history_pixel = wp.zeros(shape, dtype=wp.int32, device=dev)
        self.target_cj = wp.zeros(shape, dtype=float, device=dev)
        variant_shape = shape if state_t is not _NoSpatialState else (1, 1)
        self.f_cj = wp.zeros(variant_shape, dtype=wp.vec3, device=dev)
        self.jacobian_cj = wp.zeros(variant_shape, dtype=float, device=dev)
        # T_{i→q}(y_c)'s f and |J| per neighbour slot, from the canonical stage to a variant's merge
        slots_shape = (self.spatial_domains.capacity, self.height, self.width) if state_t is not _NoSpatialState else (1, 1, 1)
        self.f_cq = wp.zeros(slots_shape, dtype=wp.vec3, device=dev)
        self.jacobian_cq = wp.zeros(slots_shape, dtype=float, device=dev)
        self.direct = wp.zeros(shape, dtype=wp.vec3, device=dev)
        self.image = wp.zeros(shape, dtype=wp.vec3, device=dev)
        self.nonfinite = wp.zeros(1, dtype=wp.int32, device=dev)
        self.frames_rendered = 0

    #: the render method that shades direct light with ``direct=restir-di`` (ReSTCV's has the control variates)
    DIRECT_METHOD = "restir-di"

    def direct_params(self) -> dict[str, Any]:
        """Params of :attr:`DIRECT_METHOD` beyond the shared ``jitter``."""
        return {}

    def make_kernels(self, kinds: frozenset[int]) -> dict[str, Any]:
        """The passes compiled for ``kinds`` (a variant overrides this with its :class:`PixelEstimateHooks`)."""
        return make_restir_pt_kernels(kinds)

    def kernels(self) -> list[Any]:
        return list(self.k.values())

    def render_frame(self, frame: int) -> wp.array:
        """One frame: primary vertices, initial candidates, temporal and spatial reuse, shading."""
        b = self.built
        dev = b.device
        dim = (self.height, self.width)
        k = self.k
        with self._phase("gbuffer"):
            self.gbuffer.fill(b, float(frame), self.seed, jitter=self.jitter)
        self.domains.reverse()  # the previous frame's domains become "previous"
        dom, dom_prev = self.domains
        with self._phase("primary"):
            launch(k["primary"], dim=dim, inputs=[self.gbuffer.current], outputs=[dom, self.direct], device=dev)
        history, cur, other = self.buffers
        with self._phase("initial"):
            launch(
                k["initial"],
                dim=dim,
                inputs=[b.data, self.seed, int(frame), self.candidates, self.max_bounces, self.shift_params, 0.0, dom, self.kept_paths],
                outputs=[cur],
                device=dev,
            )
            launch(k["settle"], dim=dim, inputs=[b.data, self.shift_params, dom, self.kept_paths], outputs=[cur], device=dev)
        if self.temporal and self.frames_rendered > 0:
            with self._phase("temporal"):
                g, g_prev = self.gbuffer.current, self.gbuffer.previous
                scene_from_prev, scene_prev = b.across_frames()  # each domain in its own frame's scene
                launch(
                    k["temporal_canonical"],
                    dim=dim,
                    inputs=[scene_prev, self.shift_params, g, g_prev, dom, dom_prev, cur, history],
                    outputs=[other, self.history_pixel, self.target_cj, self.f_cj, self.jacobian_cj],
                    device=dev,
                )
                launch(
                    k["temporal_merge"],
                    dim=dim,
                    inputs=[scene_from_prev, self.seed, int(frame), self.shift_params, self.history_cap, self.cv_options, g, g_prev, dom, cur, history,
                            self.history_pixel, self.target_cj, self.f_cj, self.jacobian_cj],
                    outputs=[other],
                    device=dev,
                )
            cur, other = other, cur
        for rnd in range(self.spatial_rounds):
            with self._phase("spatial"):
                nbs = self.spatial_domains
                launch(
                    k["spatial_canonical"],
                    dim=dim,
                    inputs=[b.data, self.seed, int(frame), rnd, self.neighbors, self.radius, self.shift_params, self.cv_options, self.gbuffer.current, dom, cur],
                    outputs=[other, nbs.codes, nbs.slots, nbs.count, self.m_canonical, self.f_cq, self.jacobian_cq],
                    device=dev,
                )
                launch(
                    k["spatial_merge"],
                    dim=dim,
                    inputs=[b.data, self.seed, int(frame), rnd, self.shift_params, self.cv_options, self.gbuffer.current, dom, cur,
                            nbs.codes, nbs.slots, nbs.count, self.m_canonical, self.f_cq, self.jacobian_cq],
                    outputs=[other],
                    device=dev,
                )
            cur, other = other, cur
        direct = self.direct  # emission seen at x₁; with ReSTIR DI, emission and direct light
        if self.di is not None:
            direct = self.di.direct_light(frame)
        with self._phase("shade"):
            launch(k["shade"], dim=dim, inputs=[direct, cur], outputs=[self.image, self.nonfinite], device=dev)
        self.buffers = [cur, history, other]  # this frame's reservoirs are the next frame's history
        self.frames_rendered += 1
        return self.image

    def reservoirs_array(self) -> wp.array:
        """The last frame's path reservoirs on the device (H×W ``PathReservoir``)."""
        return self.buffers[0]

    def reservoirs(self) -> np.ndarray:
        """The last frame's path reservoirs (structured NumPy array), for tests and debugging."""
        return self.buffers[0].numpy()


def create_restir_pt(ctx: Any) -> ReSTIRPT:
    return create_renderer(ReSTIRPT, ctx)


# ---- registration (grisx.render.base.registry): the method, its params (defaults: the constructor's) ----

register(
    RenderMethod(
        "restir-pt",
        "ReSTIR PT (Lin et al. 2022): path reservoirs with temporal and spatial GRIS reuse through replay, reconnection or hybrid shifts",
        create_restir_pt,
        params=renderer_params(
            ReSTIRPT,
            Param("shift", ..., "path shift: hybrid (replay until two rough vertices, then reconnect), reconnection (at x2) or replay", kind="choice", choices=("hybrid", "reconnection", "replay")),
            Param("candidates", ..., "initial path-tracer candidates per pixel and frame (1 real-time, 32 offline)", kind="int", minimum=1),
            Param("max_depth", ..., "longest path in segments from the camera, Mitsuba's meaning (as pt; -1: unbounded); default: the scene's", kind="int", minimum=-1),
            Param("rr_depth", ..., "depth from which Russian roulette may end paths (as pt)", kind="int", minimum=1),
            Param("temporal", ..., "temporal reuse (generalized balance MIS)", kind="bool"),
            Param("spatial_rounds", ..., "rounds of spatial reuse (pairwise MIS)", kind="int", minimum=0, maximum=8),
            Param("neighbors", ..., "spatial neighbours per round", kind="int", minimum=0, maximum=16),
            Param("radius", ..., "spatial reuse radius in pixels", minimum=1.0),
            Param("history_cap", ..., "temporal confidence cap (<= 0: none)"),
            Param("rough_threshold", ..., "hybrid shift: vertices rougher than this may be reconnected", minimum=0.0),
            Param("near_field", ..., "hybrid shift: reconnection segments must be longer than this fraction of the scene radius", minimum=0.0),
            Param("jacobian", ..., "use shift Jacobians (false: |J| = 1, the biased ablation)", kind="bool"),
            Param("max_jacobian", ..., "reject shifts with |J| outside [1/τ, τ] (still unbiased: T stays a bijection); 0: never", minimum=0.0),
            Param("jitter", ..., "visible point uniform over the pixel each frame (box filter: what pt estimates); false: pixel centres", kind="bool"),
            Param("direct", ..., "direct light: nee (inside the path reservoirs) or restir-di (ReSTIR DI on the same G-buffer; the paths then start at two bounces)", kind="choice", choices=DIRECT_CHOICES),
        ),
    )
)
