"""ReSTIR G-PT: gradient-domain ReSTIR path tracing with paired-pixel reservoirs (Wang et al., seed 000).

Gradient after ReSTIR (``gradient-after-restir``, :mod:`grisx.render.gpt`) picks its paths by the
*primal* target of one pixel and only then shifts them to the neighbours, so it samples pixel
differences poorly. *Gradient with ReSTIR* (seed 000, Sec. 4.2) resamples in the difference's own
domain: every horizontal and vertical pixel pair (i, j) — j = i + x̂ or i + ŷ — keeps a reservoir
of **paired-pixel samples** (y, k) over X = Ω_i×{0} ∪ Ω_j×{1} (Eq. 14), k telling which pixel the
base path y lives in, with target

    p̂(y, k) = |ω*_ij(y, k) G_ij(y, k)|                                          (seed 000, Eq. 19)

where G is the difference of the base path's contribution and that of its *inner shift* to the
other pixel (Eq. 15; the film translation and hybrid path shift of :mod:`grisx.render.base.area`)
and ω* the balance heuristic on the two pixels' targets (Eq. 13, 16) —
:func:`~grisx.theory.gradient.pair_value`, the function the ``f1-f2`` toy is verified with. The
pair's difference is ⟨Δ_ij⟩ = ω*G(y, k) · W (Eq. 17), dx[i] = −Δ_ij. Per frame:

``# ---- primal pass ----``
    Area ReSTIR (:mod:`grisx.render.area_restir`: 1 candidate, temporal reuse with fractional
    motion vectors, 2 spatial neighbours) gives the primal image, as in the paper.
``# ---- initial paired-pixel candidates ----``
    each pair streams two candidates, pixel i's canonical sample (y_i, 0) and pixel j's (y_j, 1),
    with their UCWs from the primal pass's initial candidates (before any reuse), resampling weight
    w = p̂(y, k) W (Eq. 20 with m = 1: each candidate alone covers its half of X). With
    ``positivize`` the reservoirs r₊ and r₋ of targets max(±ω*G, 0) (Eq. 25–26) are fed the *same*
    candidates (Sec. 4.4); ⟨Δ⟩ is then the sum of their fixed-sign estimates (Eq. 24). The camera
    ray into the other pixel that the inner shift starts from also gives the emission's differences
    (below), so no camera ray is traced twice.
``# ---- temporal reuse ----``
    with **pixel-pair motion vectors** (Sec. 4.3.1): the pair (i, j) is carried to (i + δ, j + δ)
    of the previous frame by pixel i's fractional motion vector δ; the previous pair's samples come
    back through the **outer shift** T*(y, k) = (τ(y), k) (Eq. 21): the base path moves to the
    corresponding pixel of this pair (the film offset translated by δ, the path shifted from the new
    primary vertex), k is kept and |∂T*/∂(y, k)| = |∂τ/∂y| (Eq. 22, ``outer_shift_of``). Where the pair is carried
    onto itself (δ = 0 under a still camera, in a scene where nothing moves) the two domains are one and
    T* is the identity (:func:`pair_as_is`): no shift either way. The merge runs in stages of one hybrid
    shift each (the outer shift is two in series: the base path into the pair, then the inner shift that
    evaluates ω*G there): the source pair; T*⁻¹ of the pair's own samples, base then inner (their MIS
    weights); T* of the source's samples, base then inner; the merge. The shift stages run over a work
    queue (:class:`~grisx.render.base.queue.WorkQueue`) of the reservoirs that hold a sample, in pairs that
    have a source pair to shift from. The merge writes the pairs' reservoirs in place: each pair reads only
    its own, and its sources are the history's.
``# ---- spatial reuse ----``
    one neighbour pair (the paper's setting) of the same orientation: ``pair_reuse=dense`` a random
    pair within ``radius`` whose pixel i passes the G-buffer similarity test; ``adaptive`` (Sec. 4.3.2,
    Fig. 6, 10) reuses only for *edge pairs* — |albedo(i) − albedo(j)| > 0.1, normals apart by more
    than cos⁻¹ 0.9 (the paper prints "Dot > 0.9", which would make almost every pair an edge pair:
    read as a typo; measured, the literal test reuses for 47–95% of the pairs at 1.8–2.4× the frame and
    lowers no error, benchmarks/README.md) or depths by more than 10% — and picks, among up to ``pair_search`` random pairs
    within ``radius``, the first that is an edge pair whose two pixels match this pair's (edge-aligned
    reuse; the search runs over a work queue of the edge pairs, a few percent of all); ``off`` none. Here the
    sources are other pairs of the same frame, so the merged pairs are written to scratch and copied back after
    the merge (``pair_commit_pass``).
``# ---- gradients and reconstruction ----``
    dx, dy from the pairs' reservoirs plus the emission seen directly (as B.1 does, ω* = ½; written by
    the initial pair pass), then the screened Poisson image (``reconstruction=l2|l1``: a
    :class:`~grisx.poisson.ScreenedPoisson` kept across frames, CG preconditioned by multigrid and stopped at
    :data:`~grisx.poisson.FRAME_TOL`), which is the frame.

**MIS.** Every merge (temporal and spatial) is the generalized balance heuristic over its inputs
(seed 001, Eq. 15–16) — the pair's own reservoir and the source pair's reservoir of the same sign,
and with ``cross_sign`` (Chang et al. 2023) the source's reservoir of the other sign too — each
input's target carried through the outer shift: :func:`~grisx.theory.gradient.pair_balance_add`,
:func:`~grisx.theory.gradient.pair_balance_mis`, :func:`~grisx.theory.gradient.pair_update`,
:func:`~grisx.theory.gradient.pair_slot_sign` and :func:`~grisx.theory.gradient.pair_source_inputs`
are the toys' functions. Targets are the luminance of the RGB ω*G (signed; lum is linear), the
estimate is the RGB ω*G(y) W.

Neighbour pairs are chosen from the G-buffer alone (its own camera samples), never from the
reservoirs' samples. ``jacobian=false`` drops every shift's Jacobian, ``outer_jacobian=false`` the
outer shift's alone, and ``symmetric=false`` resamples the one-sided Eq. 2 on pixel i's half of X
alone (the pair target without the other pixel's MIS-weighted term, Eq. 12–13): all three are
known-biased siblings the tests catch. Previous-frame domains are traced through the previous
frame's geometry, and a temporal shift fails where the suffix it reuses met something that moved
(:func:`pair_scenes`); evaluating them in this frame's geometry is a fourth sibling, caught under
moving objects. Differences from the paper: one spatial round of one neighbour pair, ``pair_search``
tries (the paper: 256), and the initial candidates are the primal pass's (not separately traced paths).

References: seed 000 (Wang et al., Gradient-domain ReSTIR Path Tracing), Sec. 4.2–4.4, Eq. 14–26;
seed 001, Eq. 15–16; W. Chang et al., "Parameter-space ReSTIR", SIGGRAPH 2023; S. Zhang et al.,
"Area ReSTIR", 2024.
"""

from __future__ import annotations

from typing import Any

import warp as wp

from grisx.device import SHIFT_REGISTERS, launch, specialized_module
from grisx.errors import InvalidParameterError
from grisx.params import Param
from grisx.render.base.area import FilmSample, film_onto_itself, film_translate_wrapped, make_area_domain, temporal_film_offset
from grisx.render.base.gradient import DIFFERENCES_NONE
from grisx.render.base.path_shift import Domain, PathReservoir, PathSample, ShiftParams, make_path_shift, path_sample_empty, path_target
from grisx.render.base.queue import WorkQueue, enqueue
from grisx.render.base.registry import RenderMethod, create_renderer, register, renderer_params
from grisx.render.base.reuse import SIMILARITY_DEPTH, SIMILARITY_NORMAL_COS, pixels_similar, spatial_neighbor, temporal_neighbor
from grisx.render.base.screen import kernel_cache, pixel_key_of
from grisx.render.gpt import GradientFromPrimal, gradient_params
from grisx.scene.camera import CameraData, camera_data_equal
from grisx.scene.material import SCENE_MOVING_OBJECTS
from grisx.scene.gbuffer import GBufferData
from grisx.scene.scene import SceneData, finite_or_dropped
from grisx.theory.gradient import (
    PAIR_BASE_I,
    PairBalance,
    outer_shift_of,
    pair_balance_add,
    pair_balance_empty,
    pair_balance_mis,
    pair_estimate,
    pair_input_slot,
    pair_slot_sign,
    pair_source_inputs,
    pair_update,
    pair_value,
    shifted_difference,
)
from grisx.theory.gris import luminance
from grisx.theory.random import random_uniform
from grisx.theory.reservoir import Reservoir, confidence_capped, reservoir_empty, reservoir_finalize

wp.set_module_options({"enable_backward": False})

__all__ = ["ReSTIRGPT", "PairReservoir", "create_restir_gpt", "make_restir_gpt_kernels", "PAIR_REUSE"]

#: spatial reuse of pairs: none, a random similar pair, or edge pairs only from edge-aligned pairs (Sec. 4.3.2)
PAIR_REUSE = {"off": 0, "dense": 1, "adaptive": 2}
_REUSE_ADAPTIVE = wp.constant(2)
#: Sec. 4.3.2's edge-pair thresholds: albedo difference, normal cosine, relative depth
_EDGE_ALBEDO = wp.constant(0.1)
_EDGE_NORMAL_COS = wp.constant(0.9)
_EDGE_DEPTH = wp.constant(0.1)
_STREAM_PAIR_INITIAL = wp.constant(40)  # + orientation
_STREAM_PAIR_TEMPORAL = wp.constant(42)  # + orientation
_STREAM_PAIR_SPATIAL = wp.constant(44)  # + orientation


@wp.struct
class PairReservoir:
    """A paired-pixel reservoir: bookkeeping, the kept base path y (in the base pixel's domain at film
    sample ``film``), its indicator k and ω*G_ij(y, k) in RGB (Eq. 14–16) at this pair."""

    res: Reservoir
    path: PathSample
    film: FilmSample
    k: int
    value: wp.vec3


@wp.struct
class PairCandidate:
    """A paired-pixel sample after the outer shift into a pair: base path, film sample, k, ω*G there, |∂T*| and validity."""

    path: PathSample
    film: FilmSample
    k: int
    value: wp.vec3
    jacobian: float
    valid: wp.bool


@wp.func
def _axis(orient: int) -> wp.vec2i:
    if orient == 0:
        return wp.vec2i(1, 0)
    return wp.vec2i(0, 1)


@wp.func
def _queued_pair(i: int, height: int, width: int) -> wp.vec3i:
    """(orientation, y, x) of the flat index ``i`` of a (2, height, width) array (a :class:`WorkQueue` item)."""
    plane = height * width
    r = i % plane
    return wp.vec3i(i // plane, r // width, r % width)


@wp.func
def _queued_reservoir(i: int, height: int, width: int) -> wp.vec4i:
    """(slot, orientation, y, x) of the flat index ``i`` of a (2, 2, height, width) array (a :class:`WorkQueue` item)."""
    p = _queued_pair(i % (2 * height * width), height, width)
    return wp.vec4i(i // (2 * height * width), p[0], p[1], p[2])


@wp.func
def _pair_on_film(x: int, y: int, orient: int, width: int, height: int) -> bool:
    e = _axis(orient)
    return x >= 0 and y >= 0 and x + e[0] < width and y + e[1] < height


@wp.func
def _edge_pair(g: GBufferData, x: int, y: int, jx: int, jy: int) -> bool:
    """Sec. 4.3.2: a pair whose two G-buffer pixels differ in albedo, normal or depth (a miss counts as an edge)."""
    if g.hit[y, x] == 0 or g.hit[jy, jx] == 0:
        return g.hit[y, x] != g.hit[jy, jx]
    da = g.albedo[y, x] - g.albedo[jy, jx]
    if wp.max(wp.abs(da[0]), wp.max(wp.abs(da[1]), wp.abs(da[2]))) > _EDGE_ALBEDO:
        return True
    if wp.dot(g.normal[y, x], g.normal[jy, jx]) < _EDGE_NORMAL_COS:
        return True
    return wp.abs(g.depth[y, x] - g.depth[jy, jx]) > _EDGE_DEPTH * g.depth[y, x]


@wp.func
def _pairs_alike(g: GBufferData, x: int, y: int, nx: int, ny: int, e: wp.vec2i) -> bool:
    """Edge-aligned reuse: pixel i of each pair like the other's i, and j like j (normals, depths, albedos)."""
    if not pixels_similar(g, x, y, g, nx, ny, SIMILARITY_NORMAL_COS, SIMILARITY_DEPTH):
        return False
    if not pixels_similar(g, x + e[0], y + e[1], g, nx + e[0], ny + e[1], SIMILARITY_NORMAL_COS, SIMILARITY_DEPTH):
        return False
    da = g.albedo[y, x] - g.albedo[ny, nx]
    db = g.albedo[y + e[1], x + e[0]] - g.albedo[ny + e[1], nx + e[0]]
    return wp.length(da) <= _EDGE_ALBEDO and wp.length(db) <= _EDGE_ALBEDO


@wp.func
def pair_carries(film: FilmSample, path: PathSample) -> bool:
    """Whether a pair reservoir's kept sample is one the outer shift can carry: a film sample and a path of at least
    one segment (:func:`pair_as_is`, ``outer_base``; the shift stages' queues hold only such samples)."""
    return film.valid != 0 and path.length >= 1


@wp.func
def pair_as_is(r: PairReservoir) -> PairCandidate:
    """T*(y, k) when the source pair's domain *is* the destination's (the same pair, film translation 0, a still
    camera, a scene where nothing moves): the identity, |∂T*| = 1, ω*G unchanged.

    Every shift map may be chosen per pair of domains as long as T and T⁻¹ agree; between a domain and itself the
    identity is the natural one, and the hybrid shift would replay the path to the same result at the cost of two
    path traces (the base and the inner shift). Invalid where :func:`outer` fails before shifting (no film sample,
    an empty path)."""
    c = PairCandidate()
    c.path = r.path
    c.film = r.film
    c.k = r.k
    c.value = wp.vec3(0.0)
    c.jacobian = 0.0
    c.valid = False
    if pair_carries(r.film, r.path):
        c.value = r.value
        c.jacobian = 1.0
        c.valid = True
    return c


@wp.func
def _spatial_source(g: GBufferData, x: int, y: int, orient: int, width: int, height: int, reuse: int, tries: int, radius: float,
                    ukey: wp.uint32) -> wp.vec2i:
    """A spatial source pair for pair (orient, y, x), or (−1, −1): the first of ``tries`` random pairs within ``radius``
    that is similar (dense reuse) or an edge pair whose pixels match this pair's (adaptive reuse, Sec. 4.3.2)."""
    e = _axis(orient)
    nx = int(-1)
    ny = int(-1)
    for t in range(tries):
        if nx < 0:
            nb = spatial_neighbor(x, y, width, height, radius, wp.vec2(random_uniform(ukey, 2 * t + 8), random_uniform(ukey, 2 * t + 9)))
            if nb.valid != 0 and _pair_on_film(nb.x, nb.y, orient, width, height):
                ok = bool(False)
                if reuse == _REUSE_ADAPTIVE:
                    ok = _edge_pair(g, nb.x, nb.y, nb.x + e[0], nb.y + e[1]) and _pairs_alike(g, x, y, nb.x, nb.y, e)
                else:
                    ok = pixels_similar(g, x, y, g, nb.x, nb.y, SIMILARITY_NORMAL_COS, SIMILARITY_DEPTH)
                if ok:
                    nx = nb.x
                    ny = nb.y
    return wp.vec2i(nx, ny)


@wp.func
def _record_source(
    still: int, positivize: int, orient: int, y: int, x: int, nx: int, ny: int, to_dst: wp.vec2,
    own: wp.array4d(dtype=PairReservoir), src: wp.array4d(dtype=PairReservoir),
    source: wp.array3d(dtype=wp.vec2i), to_source: wp.array3d(dtype=wp.vec2), as_is: wp.array3d(dtype=wp.int32),
    due_back: wp.array4d(dtype=wp.int32), due_here: wp.array4d(dtype=wp.int32),
):
    """Pair (orient, y, x) takes pair (nx, ny) as its source: the film translation, ``as_is``, and the reservoirs whose
    samples the shift stages carry (``due_back``, ``due_here``: :func:`pair_carries`)."""
    source[orient, y, x] = wp.vec2i(nx, ny)
    to_source[orient, y, x] = to_dst
    if film_onto_itself(still, x, y, nx, ny, to_dst):
        as_is[orient, y, x] = 1
        return
    for s in range(2):
        if s == 0 or positivize != 0:
            if pair_carries(own[s, orient, y, x].film, own[s, orient, y, x].path):
                due_back[s, orient, y, x] = 1
            if pair_carries(src[s, orient, ny, nx].film, src[s, orient, ny, nx].path):
                due_here[s, orient, y, x] = 1


@kernel_cache
def make_restir_gpt_kernels(kinds: frozenset[int]) -> dict[str, Any]:
    """The paired-pixel passes of ReSTIR G-PT compiled for the material kinds ``kinds`` (cached)."""
    shifts = make_path_shift(kinds)
    shift = shifts.shift
    suffix_moved = shifts.suffix_moved
    area_domain = make_area_domain(kinds)
    module = specialized_module(__name__, kinds)

    @wp.func
    def pair_other_pixel(x: int, y: int, orient: int, k: int) -> wp.vec2i:
        """The pixel a base path of side ``k`` of pair (i = (x, y), j = i + axis) is shifted into: j for k = 0, i for k = 1."""
        e = _axis(orient)
        if k != PAIR_BASE_I:
            return wp.vec2i(x, y)
        return wp.vec2i(x + e[0], y + e[1])

    @wp.func
    def pair_value_in(scene: SceneData, dom: Domain, k: int, path: PathSample, sp: ShiftParams, symmetric: int) -> wp.vec3:
        """ω*_ij G_ij(y, k) (Eq. 14–16) for base path ``path`` of side ``k``, ``dom`` the other pixel's domain at its film
        sample; ``symmetric`` = 0: the one-sided Eq. 2 on pixel i's half alone (the biased ablation)."""
        inner = shift(scene, dom, path, sp)  # the inner shift T_ij or T_ji
        if symmetric == 0:
            if k != PAIR_BASE_I:
                return wp.vec3(0.0)
            return shifted_difference(path.f, inner.path.f, inner.jacobian, inner.valid)  # Eq. 2 without Eq. 3's other half
        return pair_value(k, path.f, inner.path.f, path_target(path), path_target(inner.path), inner.jacobian, inner.valid)

    @wp.func
    def pair_value_at(scene: SceneData, cam: CameraData, x: int, y: int, orient: int, fs: FilmSample, k: int, path: PathSample, sp: ShiftParams, symmetric: int) -> wp.vec3:
        """:func:`pair_value_in` with the other pixel's domain at film sample ``fs`` (a camera ray)."""
        o = pair_other_pixel(x, y, orient, k)
        return pair_value_in(scene, area_domain(scene, cam, o[0], o[1], fs).dom, k, path, sp, symmetric)

    @wp.func
    def outer_base(
        scene: SceneData, cam: CameraData, x: int, y: int, orient: int, fs_src: FilmSample, to_dst: wp.vec2, k: int,
        path: PathSample, sp: ShiftParams, use_jacobian: int, across: int,
    ) -> PairCandidate:
        """T*(y, k) = (τ(y), k) into pair (x, y, orient) (Eq. 21–22): τ translates the film offset by ``to_dst`` (wrapped into
        the pixel's support, :func:`~grisx.render.base.area.film_translate_wrapped`) and shifts the path from the primary
        vertex of the corresponding pixel. ω*G there (the inner shift) is left to :func:`pair_value_at` (its own stage).
        ``across`` = 1 between frames (``scene`` the destination frame's, :meth:`~grisx.scene.scene.BuiltScene.across_frames`):
        undefined where the suffix that a reconnection reuses met something that moved (``shift_across``)."""
        c = PairCandidate()
        c.k = k
        # wrapped into the pixel's support (a temporal to_dst that carries the film sample out of the pixel would
        # otherwise leave the shift undefined, losing history under motion, as Area ReSTIR's did); to_dst = 0 (spatial)
        # and every translation that stays inside are film_translate's, to the bit
        c.film = film_translate_wrapped(fs_src, to_dst, cam)
        c.path = path_sample_empty()
        c.value = wp.vec3(0.0)
        c.jacobian = 0.0
        c.valid = False
        if not pair_carries(c.film, path):
            return c
        if across != 0:
            if suffix_moved(scene, path):
                return c
        e = _axis(orient)
        bx = x
        by = y
        if k != PAIR_BASE_I:
            bx = x + e[0]
            by = y + e[1]
        shifted = shift(scene, area_domain(scene, cam, bx, by, c.film).dom, path, sp)
        jac = shifted.jacobian
        if use_jacobian == 0:
            jac = 1.0
        t = outer_shift_of(k, jac, shifted.valid)  # seed 000, Eq. 21–22
        if not t.valid:
            return c
        c.path = shifted.path
        c.jacobian = t.jacobian
        c.valid = True
        return c

    @wp.func
    def keep_in(out: wp.array4d(dtype=PairReservoir), slot: int, orient: int, y: int, x: int, c: PairCandidate):
        """Write candidate ``c`` as the kept sample of ``out[slot, orient, y, x]`` (its bookkeeping is written apart)."""
        out[slot, orient, y, x].path = c.path
        out[slot, orient, y, x].film = c.film
        out[slot, orient, y, x].k = c.k
        out[slot, orient, y, x].value = c.value

    @wp.func
    def carried_here(
        as_is: int, shifted: int, src: wp.array4d(dtype=PairReservoir), carried: wp.array4d(dtype=PairCandidate),
        s: int, orient: int, y: int, x: int, nx: int, ny: int,
    ) -> PairCandidate:
        """The outer shift of reservoir ``s`` of pair (nx, ny), as the merge reads it at pair (x, y): the shift stages'
        result where they ran (``shifted``), else the identity, which for a sample the shift could not carry
        (:func:`pair_carries`) is the invalid candidate the shift would have returned. T* of the source's reservoirs
        here (the merge); T*⁻¹ of the pair's own, (nx, ny) = (x, y) (the back pass)."""
        if as_is != 0 or shifted == 0:
            return pair_as_is(src[s, orient, ny, nx])
        return carried[s, orient, y, x]

    @wp.func
    def pair_initial_reservoir(
        canonical: wp.array2d(dtype=PathReservoir), film: wp.array2d(dtype=FilmSample), x: int, y: int, orient: int,
        r: Reservoir, k: int, value: wp.vec3,
    ) -> PairReservoir:
        """An initial pair reservoir, finalized: bookkeeping ``r`` and, where it kept side ``k`` ≥ 0, that pixel's canonical
        path and film sample (read here, once, not carried across the shifts) with ω*G = ``value``."""
        p = PairReservoir()
        p.res = reservoir_finalize(r)
        p.path = path_sample_empty()
        p.value = wp.vec3(0.0)
        if k >= 0:
            e = _axis(orient)
            px = x + k * e[0]
            py = y + k * e[1]
            p.path = canonical[py, px].path
            p.film = film[py, px]
            p.k = k
            p.value = value
        return p

    # ---- initial paired-pixel candidates ----
    @wp.kernel(module=module, cuda_max_registers=SHIFT_REGISTERS)
    def pair_initial_pass(
        scene: SceneData, cam: CameraData, seed: int, frame: int, sp: ShiftParams, positivize: int, symmetric: int,
        film: wp.array2d(dtype=FilmSample), canonical: wp.array2d(dtype=PathReservoir), direct: wp.array2d(dtype=wp.vec3),
        out: wp.array4d(dtype=PairReservoir), halves: wp.array3d(dtype=wp.vec3), nonfinite: wp.array(dtype=wp.int32),
    ):
        """The pair's initial candidates, and the emission's differences of its two pixels (``halves``: the camera ray
        into the other pixel is the one the inner shift starts from, so the gradient pass does not trace it again)."""
        orient, y, x = wp.tid()
        h = film.shape[0]
        w = film.shape[1]
        # the two reservoirs' bookkeeping, the side k of the kept candidate (−1: none) and its ω*G stay in registers;
        # each reservoir is written once, at the end: a field-by-field read-modify-write of a 60-word record at a
        # 240-byte stride in every update is what this pass paid for on a GPU
        r0 = reservoir_empty()
        r1 = reservoir_empty()
        k0 = int(-1)
        k1 = int(-1)
        v0 = wp.vec3(0.0)
        v1 = wp.vec3(0.0)
        if _pair_on_film(x, y, orient, w, h):
            e = _axis(orient)
            ukey = pixel_key_of(seed, frame, x, y, w, _STREAM_PAIR_INITIAL + orient)
            # (y_i, 0) and (y_j, 1): each pixel's canonical sample with its UCW, alone on its half of X (m = 1)
            sides = int(2)  # a dynamic bound: Warp unrolls a constant range, and this body inlines a shift (pair_value_in)
            for k in range(sides):
                px = x + k * e[0]
                py = y + k * e[1]
                o = pair_other_pixel(x, y, orient, k)
                ad = area_domain(scene, cam, o[0], o[1], film[py, px])  # u kept in the other pixel: a film translation, |J| = 1
                # ---- the emission at x₁ (a path of length 0) of pixel (px, py) toward the other: ω* = ½ (Eq. 4), its half
                # of the pair's difference (the gradient pass's slot: right/down for side i, left/up for side j) ----
                halves[2 * orient + k, py, px] = finite_or_dropped(pair_value(k, direct[py, px], ad.emission, 1.0, 1.0, 1.0, True), nonfinite)
                ucw = canonical[py, px].res.ucw
                value = wp.vec3(0.0)
                if ucw > 0.0 and canonical[py, px].path.length > 0:
                    value = pair_value_in(scene, ad.dom, k, canonical[py, px].path, sp, symmetric)
                # the shared candidates of r+ and r- (Sec. 4.4); Eq. 20 with m = 1, |J| = 1
                r0 = pair_update(r0, pair_slot_sign(positivize, 0), luminance(value), 1.0, ucw, 1.0, 0.5, random_uniform(ukey, 2 * k))
                if r0.selected:
                    k0 = k
                    v0 = value
                if positivize != 0:
                    r1 = pair_update(r1, pair_slot_sign(positivize, 1), luminance(value), 1.0, ucw, 1.0, 0.5, random_uniform(ukey, 2 * k + 1))
                    if r1.selected:
                        k1 = k
                        v1 = value
        out[0, orient, y, x] = pair_initial_reservoir(canonical, film, x, y, orient, r0, k0, v0)  # W = Σ w / p̂(y, k), Eq. 18
        out[1, orient, y, x] = pair_initial_reservoir(canonical, film, x, y, orient, r1, k1, v1)

    # ---- temporal reuse / spatial reuse: one merge of a source pair into each of this pair's reservoirs, in stages ----
    # The outer shift is two hybrid shifts in series (the base path into the pair, then the inner shift that gives ω*G);
    # the merge needs it twice a reservoir (the pair's own sample back to the source pair, the source's samples here).
    # Each runs in a stage of its own, one inlined shift a kernel: the source pair; the base shifts of the own samples;
    # their inner shifts (their p̂ at the source pair); the same two for the source's samples; then the merge, which
    # shifts nothing. One kernel running all four shifts sat at the register cap and spilled (sm_90: 255 registers,
    # 1 KB stack); two stages of two shifts each still did. A source pair that is this pair's own domain (``as_is``)
    # is left to the light stages (back and merge): the identity is a copy, and a copy in a shift stage's 200-odd
    # registers a thread ran at a quarter of the light stages' occupancy (H200, still camera: 40 ms a merge).
    # The shift stages run under SHIFT_REGISTERS: two blocks an SM with spills beat one without (grisx.device), and
    # over work queues of the reservoirs that hold a sample (most pairs see ω*G = 0 and keep none; shift_stages).
    @wp.kernel(module=module)
    def pair_source_pass(
        seed: int, frame: int, temporal: int, still: int, positivize: int, reuse: int, radius: float, g: GBufferData, g_src: GBufferData,
        own: wp.array4d(dtype=PairReservoir), src: wp.array4d(dtype=PairReservoir),
        source: wp.array3d(dtype=wp.vec2i), to_source: wp.array3d(dtype=wp.vec2), as_is: wp.array3d(dtype=wp.int32),
        due_back: wp.array4d(dtype=wp.int32), due_here: wp.array4d(dtype=wp.int32), edge: wp.array3d(dtype=wp.int32),
    ):
        """The source pair of each pair, from the G-buffers alone, the film translation u_dst = u_src + to_dst, and
        whether the source pair is this pair's own domain (``as_is``: T* and T*⁻¹ the identity, :func:`pair_as_is`).
        Elsewhere the reservoirs whose samples the shift stages carry are flagged: ``due_back[s]``, the pair's own
        sample of slot s toward the source pair (T*⁻¹); ``due_here[s]``, the source's toward this pair (T*); each only
        where the reservoir holds a sample (:func:`pair_carries`). Adaptive spatial reuse only flags the edge pairs
        (``edge``): their search of up to ``pair_search`` pairs runs over a queue of them (:func:`pair_search_pass`)."""
        orient, y, x = wp.tid()
        h = own.shape[2]
        w = own.shape[3]
        source[orient, y, x] = wp.vec2i(-1, -1)
        as_is[orient, y, x] = 0
        edge[orient, y, x] = 0
        for s in range(2):
            due_back[s, orient, y, x] = 0
            due_here[s, orient, y, x] = 0
        if not _pair_on_film(x, y, orient, w, h):
            return
        e = _axis(orient)
        nx = int(-1)
        ny = int(-1)
        to_dst = wp.vec2(0.0, 0.0)
        if temporal != 0:
            nb = temporal_neighbor(g, g_src, x, y, SIMILARITY_NORMAL_COS, SIMILARITY_DEPTH)  # pixel-pair motion (Sec. 4.3.1)
            if nb.valid != 0 and _pair_on_film(nb.x, nb.y, orient, w, h):
                nx = nb.x
                ny = nb.y
                to_dst = -temporal_film_offset(x, y, nb.x, nb.y, g.motion[y, x])
        elif reuse == _REUSE_ADAPTIVE:
            if _edge_pair(g, x, y, x + e[0], y + e[1]):
                edge[orient, y, x] = 1  # searched by pair_search_pass; an interior pair has no spatial reuse (Sec. 4.3.2)
            return
        else:
            ukey = pixel_key_of(seed, frame, x, y, w, _STREAM_PAIR_TEMPORAL + orient + 2)
            nxy = _spatial_source(g, x, y, orient, w, h, reuse, 1, radius, ukey)
            nx = nxy[0]
            ny = nxy[1]
        if nx >= 0:
            _record_source(still, positivize, orient, y, x, nx, ny, to_dst, own, src, source, to_source, as_is, due_back, due_here)

    @wp.kernel(module=module)
    def pair_search_pass(
        seed: int, frame: int, positivize: int, search: int, radius: float, g: GBufferData, queue: wp.array(dtype=wp.int32),
        own: wp.array4d(dtype=PairReservoir), source: wp.array3d(dtype=wp.vec2i), to_source: wp.array3d(dtype=wp.vec2),
        as_is: wp.array3d(dtype=wp.int32), due_back: wp.array4d(dtype=wp.int32), due_here: wp.array4d(dtype=wp.int32),
    ):
        """Adaptive spatial reuse's edge-aligned search (Sec. 4.3.2) for the edge pairs of ``queue`` (flat indices of
        (orientation, y, x)): a few percent of the pairs, each trying up to ``search`` random pairs, run in full warps
        instead of holding every warp that has one of them."""
        h = own.shape[2]
        w = own.shape[3]
        p = _queued_pair(queue[wp.tid()], h, w)
        orient = p[0]
        y = p[1]
        x = p[2]
        ukey = pixel_key_of(seed, frame, x, y, w, _STREAM_PAIR_TEMPORAL + orient + 2)
        nxy = _spatial_source(g, x, y, orient, w, h, _REUSE_ADAPTIVE, search, radius, ukey)
        if nxy[0] >= 0:  # a spatial source is never the pair itself: still = 0
            _record_source(0, positivize, orient, y, x, nxy[0], nxy[1], wp.vec2(0.0, 0.0), own, own, source, to_source, as_is, due_back, due_here)

    @wp.kernel(module=module, cuda_max_registers=SHIFT_REGISTERS)
    def pair_base_pass(
        scene: SceneData, cam_dst: CameraData, sp: ShiftParams, toward_source: int, use_outer_jacobian: int, across: int,
        own: wp.array4d(dtype=PairReservoir), src: wp.array4d(dtype=PairReservoir),
        source: wp.array3d(dtype=wp.vec2i), to_source: wp.array3d(dtype=wp.vec2), queue: wp.array(dtype=wp.int32),
        carried: wp.array4d(dtype=PairCandidate), inner_due: wp.array(dtype=wp.int32),
    ):
        """The base path of one reservoir carried by the outer shift: ``toward_source`` = 1, the pair's own sample of slot
        ``s`` into the source pair (T*⁻¹, on the source's camera); 0, the source pair's sample of slot ``s`` into this pair
        (T*). ``scene`` and ``cam_dst`` are the destination frame's; ``across`` = 1 for a temporal merge. Runs over
        ``queue`` (the reservoirs flagged ``due_back`` or ``due_here``); ``inner_due[q]`` = 1 where the inner shift (ω*G
        there) is still to be evaluated."""
        q = wp.tid()
        p = _queued_reservoir(queue[q], source.shape[1], source.shape[2])
        s = p[0]
        orient = p[1]
        y = p[2]
        x = p[3]
        nxy = source[orient, y, x]
        nx = nxy[0]
        ny = nxy[1]
        to_dst = to_source[orient, y, x]
        # the reservoir and its destination chosen first, shifted at one place (one inlined shift); only the fields the
        # shift reads are loaded, from the one array the record lives in (a select between two records loaded both)
        rs = src
        ry = ny
        rx = nx
        px = x
        py = y
        t = to_dst
        if toward_source != 0:
            rs = own
            ry = y
            rx = x
            px = nx
            py = ny
            t = -to_dst
        c = outer_base(scene, cam_dst, px, py, orient, rs[s, orient, ry, rx].film, t, rs[s, orient, ry, rx].k, rs[s, orient, ry, rx].path, sp,
                       use_outer_jacobian, across)
        carried[s, orient, y, x] = c
        inner_due[q] = int(c.valid)

    @wp.kernel(module=module, cuda_max_registers=SHIFT_REGISTERS)
    def pair_inner_pass(
        scene: SceneData, cam_dst: CameraData, sp: ShiftParams, toward_source: int, symmetric: int,
        source: wp.array3d(dtype=wp.vec2i), queue: wp.array(dtype=wp.int32), inner_queue: wp.array(dtype=wp.int32),
        carried: wp.array4d(dtype=PairCandidate),
    ):
        """ω*G of each carried base path at its destination pair (the inner shift, Eq. 14–16), in place; over
        ``inner_queue``, the positions in the base stage's ``queue`` whose base path was carried."""
        p = _queued_reservoir(queue[inner_queue[wp.tid()]], source.shape[1], source.shape[2])
        s = p[0]
        orient = p[1]
        y = p[2]
        x = p[3]
        px = x
        py = y
        if toward_source != 0:
            nxy = source[orient, y, x]
            px = nxy[0]
            py = nxy[1]
        carried[s, orient, y, x].value = pair_value_at(scene, cam_dst, px, py, orient, carried[s, orient, y, x].film, carried[s, orient, y, x].k,
                                                       carried[s, orient, y, x].path, sp, symmetric)

    @wp.kernel(module=module)
    def pair_back_pass(
        own: wp.array4d(dtype=PairReservoir), source: wp.array3d(dtype=wp.vec2i), as_is: wp.array3d(dtype=wp.int32),
        due_back: wp.array4d(dtype=wp.int32), carried: wp.array4d(dtype=PairCandidate), back: wp.array4d(dtype=wp.vec3),
    ):
        """What the merge keeps of the own samples carried to the source pair: (luminance of ω*G there, |∂T*⁻¹|, valid)."""
        s, orient, y, x = wp.tid()
        if source[orient, y, x][0] < 0:
            return
        # T*⁻¹ onto itself is the identity, ω*G included; a reservoir with no sample to carry gives the invalid candidate
        # (as the shift would); the others were carried by the shift stages
        c = carried_here(as_is[orient, y, x], due_back[s, orient, y, x], own, carried, s, orient, y, x, x, y)
        back[s, orient, y, x] = wp.vec3(luminance(c.value), c.jacobian, float(c.valid))

    @wp.kernel(module=module)
    def pair_merge_pass(
        seed: int, frame: int, positivize: int, cross_sign: int, temporal: int, history_cap: float,
        own: wp.array4d(dtype=PairReservoir), src: wp.array4d(dtype=PairReservoir),
        source: wp.array3d(dtype=wp.vec2i), as_is: wp.array3d(dtype=wp.int32), due_here: wp.array4d(dtype=wp.int32), back: wp.array4d(dtype=wp.vec3),
        carried: wp.array4d(dtype=PairCandidate), out: wp.array4d(dtype=PairReservoir),
    ):
        """The generalized balance heuristic over the pair's own reservoir and the source pair's (seed 001, Eq. 15–16),
        every shift done by the stages before, written to ``out`` for the pairs that have a source pair. A temporal merge
        writes in place (``out`` is ``own``: its sources are the history's, and each pair reads only its own reservoirs
        of ``own``, each before writing it); a spatial merge's sources are other pairs of ``own``, so ``out`` is scratch
        that :func:`pair_commit_pass` copies back."""
        orient, y, x = wp.tid()
        nxy = source[orient, y, x]
        if nxy[0] < 0:
            return
        nx = nxy[0]
        ny = nxy[1]
        ukey = pixel_key_of(seed, frame, x, y, own.shape[3], _STREAM_PAIR_TEMPORAL + orient + 2 * (1 - temporal))
        for slot in range(2):
            if slot == 0 or positivize != 0:
                sign = pair_slot_sign(positivize, slot)
                c_own = own[slot, orient, y, x].res.confidence
                t_own = luminance(own[slot, orient, y, x].value)
                n_src = pair_source_inputs(1, positivize, cross_sign)
                c_same = src[slot, orient, ny, nx].res.confidence
                c_other = src[1 - slot, orient, ny, nx].res.confidence
                if temporal != 0:
                    c_same = confidence_capped(c_same, history_cap)
                    c_other = confidence_capped(c_other, history_cap)
                # the pair's own sample: its p̂ here, and at the source pair (pair_back_pass)
                bk = back[slot, orient, y, x]
                b = pair_balance_empty()
                b = pair_balance_add(b, sign, 1, c_own, 0.0, t_own, 1.0, True, 0)
                b = pair_balance_add(b, sign, n_src, c_same, c_other, bk[0], bk[1], bk[2] != 0.0, -1)
                r = reservoir_empty()
                r = pair_update(r, sign, t_own, pair_balance_mis(b, c_own), own[slot, orient, y, x].res.ucw, 1.0, c_own, random_uniform(ukey, 0))
                kept_e = int(-1)  # the input kept: −1 the pair's own sample, else the source's input e (written once, below)
                # the source pair's reservoirs of this sign (and of the other, across signs), carried here by T*
                for input_e in range(n_src):  # 1 or 2 (pair_source_inputs)
                    theirs = pair_input_slot(slot, input_e)
                    c_e = c_same
                    if input_e == 1:
                        c_e = c_other
                    cand = carried_here(as_is[orient, y, x], due_here[theirs, orient, y, x], src, carried, theirs, orient, y, x, nx, ny)
                    t_cand = luminance(cand.value)
                    valid = cand.valid
                    jac = cand.jacobian
                    inv_j = float(0.0)
                    if valid:
                        inv_j = 1.0 / jac
                    b = pair_balance_empty()
                    b = pair_balance_add(b, sign, 1, c_own, 0.0, t_cand, 1.0, valid, -1)
                    b = pair_balance_add(b, sign, n_src, c_same, c_other, luminance(src[theirs, orient, ny, nx].value), inv_j, valid, input_e)
                    mis = pair_balance_mis(b, c_e)
                    r = pair_update(r, sign, t_cand, mis, src[theirs, orient, ny, nx].res.ucw, jac, c_e,
                                    random_uniform(ukey, 1 + input_e))  # Eq. 20
                    if r.selected:
                        kept_e = input_e
                if kept_e >= 0:
                    theirs = pair_input_slot(slot, kept_e)
                    keep_in(out, slot, orient, y, x, carried_here(as_is[orient, y, x], due_here[theirs, orient, y, x], src, carried, theirs, orient, y, x, nx, ny))
                elif temporal == 0:
                    out[slot, orient, y, x] = own[slot, orient, y, x]  # the own sample kept: into the scratch record
                out[slot, orient, y, x].res = reservoir_finalize(r)
            elif temporal == 0:
                out[slot, orient, y, x] = own[slot, orient, y, x]  # an unused slot (unpositivized), as it was

    @wp.kernel(module=module)
    def pair_commit_pass(source: wp.array3d(dtype=wp.vec2i), merged: wp.array4d(dtype=PairReservoir), own: wp.array4d(dtype=PairReservoir)):
        """A spatial merge's results into the pairs' reservoirs, where there was a merge (the others are as they were)."""
        orient, y, x = wp.tid()
        if source[orient, y, x][0] >= 0:
            own[0, orient, y, x] = merged[0, orient, y, x]
            own[1, orient, y, x] = merged[1, orient, y, x]

    # ---- gradients and reconstruction ----
    @wp.kernel(module=module)
    def pair_gradient_pass(
        pairs: wp.array4d(dtype=PairReservoir), dx: wp.array2d(dtype=wp.vec3), dy: wp.array2d(dtype=wp.vec3), nonfinite: wp.array(dtype=wp.int32),
    ):
        """dx[i] −= Σ_slots ω*G(y) W (Eq. 17, 24; dx[i] = −Δ_ij), dy likewise."""
        orient, y, x = wp.tid()
        d = wp.vec3(0.0)
        for slot in range(2):
            p = pairs[slot, orient, y, x]
            if p.res.ucw > 0.0:
                d = d + pair_estimate(p.value, p.res.ucw)
        d = finite_or_dropped(d, nonfinite)
        if orient == 0:
            dx[y, x] = dx[y, x] - d
        else:
            dy[y, x] = dy[y, x] - d

    return {"initial": pair_initial_pass, "source": pair_source_pass, "search": pair_search_pass, "base": pair_base_pass, "inner": pair_inner_pass, "back": pair_back_pass,
            "merge": pair_merge_pass, "commit": pair_commit_pass, "gradient": pair_gradient_pass}


def pair_scenes(built: Any, temporal: bool) -> tuple[Any, Any]:
    """The scenes of a merge's two ends, (this pair's, the source pair's): each domain in its own frame's geometry, a
    temporal source in the previous frame's, and each knowing what moved in between
    (:meth:`~grisx.scene.scene.BuiltScene.across_frames`), so that a temporal shift fails where the suffix it reuses
    met something that moved. (Evaluating the previous frame's domains in this frame's scene, as the paper does, is
    the known-biased sibling of ``tests/render/test_gradient_domain.py``.)"""
    return built.across_frames() if temporal else (built.data, built.data)


class ReSTIRGPT(GradientFromPrimal):
    """ReSTIR G-PT over a built scene: Area ReSTIR's primal pass and paired-pixel reservoirs for dx, dy (module docstring)."""

    GBUFFER_MATERIAL = True  # edge pairs differ in albedo (Sec. 4.3.2)

    def __init__(
        self, built: Any, width: int, height: int, *, positivize: bool = True, cross_sign: bool = False, pair_reuse: str = "adaptive",
        pair_temporal: bool = True, pair_search: int = 64, outer_jacobian: bool = True, **options: Any,
    ) -> None:
        if pair_reuse not in PAIR_REUSE:
            raise InvalidParameterError(f"pair_reuse must be one of {', '.join(PAIR_REUSE)}, not '{pair_reuse}'")
        if cross_sign and not positivize:
            raise InvalidParameterError("cross_sign reuses across the r+ and r- reservoirs: it needs positivize=true")
        if pair_search < 1:
            raise InvalidParameterError(f"pair_search must be >= 1, got {pair_search}")
        super().__init__(built, width, height, **options)
        self.positivize = bool(positivize)
        self.cross_sign = bool(cross_sign)
        self.pair_reuse = PAIR_REUSE[pair_reuse]
        self.pair_temporal = bool(pair_temporal)
        self.pair_search = int(pair_search)
        self.outer_jacobian = bool(outer_jacobian)
        self.pk = make_restir_gpt_kernels(built.features.kernel_kinds)
        shape = (2, 2, self.height, self.width)  # (slot: r+ or |.|, r-), (orientation: x, y), H, W
        self.pairs = [wp.zeros(shape, dtype=PairReservoir, device=built.device) for _ in range(3)]  # 0: history, 1–2: scratch
        self.canonical_kept = wp.zeros((self.height, self.width), dtype=PathReservoir, device=built.device)
        # between the merge's stages: each pair's source pair and film translation, the own samples' p̂ there
        self.pair_source = wp.zeros((2, self.height, self.width), dtype=wp.vec2i, device=built.device)
        self.pair_to_source = wp.zeros((2, self.height, self.width), dtype=wp.vec2, device=built.device)
        self.pair_as_is = wp.zeros((2, self.height, self.width), dtype=wp.int32, device=built.device)  # the source pair is this pair's domain
        self.pair_edge = wp.zeros((2, self.height, self.width), dtype=wp.int32, device=built.device)  # edge pairs (adaptive spatial reuse)
        # reservoirs whose samples the shift stages carry, toward the source pair and here (pair_source_pass)
        self.pair_due_back = wp.zeros(shape, dtype=wp.int32, device=built.device)
        self.pair_due_here = wp.zeros(shape, dtype=wp.int32, device=built.device)
        self.pair_queue = WorkQueue(2 * 2 * self.height * self.width, built.device)
        self.inner_queue = WorkQueue(2 * 2 * self.height * self.width, built.device)
        self.pair_back = wp.zeros(shape, dtype=wp.vec3, device=built.device)
        self.pair_carried = wp.zeros(shape, dtype=PairCandidate, device=built.device)  # one outer shift's results, stage to stage
        self.pair_inner_due = wp.zeros(2 * 2 * self.height * self.width, dtype=wp.int32, device=built.device)  # by position in pair_queue
        self.pair_frames = 0

    def kernels(self) -> list[Any]:
        return [*super().kernels(), *self.pk.values(), enqueue]

    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        self.pair_frames = 0

    def after_canonical(self, reservoirs: wp.array) -> None:
        wp.copy(self.canonical_kept, reservoirs)  # the gradient pass's initial candidates (before any reuse)

    def merge_pairs(self, frame: int, cam: Any, cam_src: Any, g: Any, g_src: Any, own: wp.array, src: wp.array, scratch: wp.array, *, temporal: bool) -> None:
        """One temporal or spatial merge of a source pair into every pair's reservoirs ``own``, in place, stage by stage
        (the kernels'). A spatial merge writes its results to ``scratch`` first: its sources are pairs of ``own``."""
        b = self.built
        dev = b.device
        pairs = (2, self.height, self.width)
        each = (2, 2, self.height, self.width)  # (slot, orientation, H, W)
        scene_here, scene_src = pair_scenes(b, temporal)
        # a temporal source pair onto itself (zero motion), under a still camera in a scene where nothing moves, is this
        # pair's own domain: T* and T*⁻¹ are the identity there (pair_as_is)
        still = int(temporal and camera_data_equal(cam, cam_src) and SCENE_MOVING_OBJECTS not in b.features.kernel_kinds)
        launch(self.pk["source"], dim=pairs, inputs=[self.seed, int(frame), int(temporal), still, int(self.positivize), self.pair_reuse,
                                                       self.radius, g, g_src, own, src],
                  outputs=[self.pair_source, self.pair_to_source, self.pair_as_is, self.pair_due_back, self.pair_due_here, self.pair_edge], device=dev)
        if not temporal and self.pair_reuse == PAIR_REUSE["adaptive"]:
            n = self.pair_queue.build(self.pair_edge)  # the edge pairs (the queue is free until the shift stages)
            if n > 0:
                launch(self.pk["search"], dim=n, inputs=[self.seed, int(frame), int(self.positivize), self.pair_search, self.radius, g,
                                                            self.pair_queue.items, own],
                          outputs=[self.pair_source, self.pair_to_source, self.pair_as_is, self.pair_due_back, self.pair_due_here], device=dev)
        # the pair's own samples to the source pair (T*⁻¹): base, inner, what the merge keeps of them
        self.shift_stages(scene_src, cam_src, 1, temporal, own, src, self.pair_due_back)
        launch(self.pk["back"], dim=each, inputs=[own, self.pair_source, self.pair_as_is, self.pair_due_back, self.pair_carried], outputs=[self.pair_back], device=dev)
        # the source's samples here (T*), then the merge
        self.shift_stages(scene_here, cam, 0, temporal, own, src, self.pair_due_here)
        out = own if temporal else scratch
        launch(self.pk["merge"], dim=pairs, inputs=[self.seed, int(frame), int(self.positivize), int(self.cross_sign), int(temporal), self.history_cap,
                                                      own, src, self.pair_source, self.pair_as_is, self.pair_due_here, self.pair_back,
                                                      self.pair_carried], outputs=[out], device=dev)
        if not temporal:
            launch(self.pk["commit"], dim=pairs, inputs=[self.pair_source, scratch], outputs=[own], device=dev)

    def shift_stages(self, scene: Any, cam: Any, toward_source: int, temporal: bool, own: wp.array, src: wp.array, due: wp.array) -> None:
        """The outer shift of the reservoirs flagged in ``due`` (slot, orientation, pixel), over work queues: the base
        paths, then the inner shift of those that were carried. Only a reservoir that holds a sample, of a pair with a
        source pair to shift from, is queued: in a temporal merge under a moving camera about 4% of this frame's
        reservoirs (most pairs see ω*G = 0 and keep nothing) and 19% of the history's (door-ajar, 160×120)."""
        dev = self.built.device
        n = self.pair_queue.build(due)
        if n == 0:
            return
        launch(self.pk["base"], dim=n, inputs=[scene, cam, self.shift_params, toward_source, int(self.outer_jacobian), int(temporal), own, src,
                                                  self.pair_source, self.pair_to_source, self.pair_queue.items], outputs=[self.pair_carried, self.pair_inner_due], device=dev)
        m = self.inner_queue.build(self.pair_inner_due, n)
        if m == 0:
            return
        launch(self.pk["inner"], dim=m, inputs=[scene, cam, self.shift_params, toward_source, int(self.symmetric), self.pair_source, self.pair_queue.items,
                                                   self.inner_queue.items], outputs=[self.pair_carried], device=dev)

    def render_frame(self, frame: int) -> wp.array:
        """Primal pass, paired-pixel candidates, temporal and spatial pair reuse, gradients, reconstruction."""
        b = self.built
        dev = b.device
        # ---- primal pass ----
        cur, film = self.resample(frame)
        self.gradient.begin()
        self.add_gradients(frame, cur, film, 1.0, differences=DIFFERENCES_NONE)  # the primal image (the emission's differences: pair_initial)
        cam, cam_prev = self.cameras(frame)
        dim = (2, self.height, self.width)
        history, pairs, other = self.pairs
        # ---- initial paired-pixel candidates ----
        with self._phase("pair_initial"):
            launch(self.pk["initial"], dim=dim, inputs=[b.data, cam, self.seed, int(frame), self.shift_params, int(self.positivize), int(self.symmetric), self.films[3], self.canonical_kept, self.direct],
                      outputs=[pairs, self.gradient.halves, self.nonfinite], device=dev)
        g, g_prev = self.gbuffer.current, self.gbuffer.previous
        # ---- temporal reuse ----
        if self.pair_temporal and self.pair_frames > 0:
            with self._phase("pair_temporal"):
                self.merge_pairs(frame, cam, cam_prev, g, g_prev, pairs, history, other, temporal=True)
        # ---- spatial reuse ----
        if self.pair_reuse != 0:
            with self._phase("pair_spatial"):
                self.merge_pairs(frame, cam, cam, g, g, pairs, pairs, other, temporal=False)
        self.pairs = [pairs, history, other]
        self.pair_frames += 1
        # ---- gradients and reconstruction ----
        with self._phase("gradients"):
            self.gradient.gradients(self.gk)
            launch(self.pk["gradient"], dim=dim, inputs=[pairs], outputs=[self.gradient.dx, self.gradient.dy, self.nonfinite], device=dev)
        return self.reconstructed()


def create_restir_gpt(ctx: Any) -> ReSTIRGPT:
    return create_renderer(ReSTIRGPT, ctx)


# ---- registration (grisx.render.base.registry) ----

register(
    RenderMethod(
        "restir-gpt",
        "ReSTIR G-PT (Wang et al., seed 000): paired-pixel reservoirs with the pair target, inner and outer shifts, pixel-pair temporal and adaptive spatial reuse, positivization; Area ReSTIR primal, screened Poisson reconstruction",
        create_restir_gpt,
        params=gradient_params() + renderer_params(
            ReSTIRGPT,
            Param("positivize", ..., "r+ and r- reservoirs of max(+-omega*G, 0) sharing their candidates (Eq. 23-26); false: one reservoir of |omega*G| (Eq. 19)", kind="bool"),
            Param("cross_sign", ..., "reuse across signs (Chang et al. 2023): merge the source pair's reservoir of the other sign too (needs positivize)", kind="bool"),
            Param("pair_reuse", ..., "spatial reuse of pairs: off, dense (a random similar pair) or adaptive (edge pairs only, edge-aligned neighbours; Sec. 4.3.2)", kind="choice", choices=tuple(PAIR_REUSE)),
            Param("pair_temporal", ..., "temporal reuse of pairs with pixel-pair motion vectors (Sec. 4.3.1)", kind="bool"),
            Param("pair_search", ..., "adaptive reuse: random pairs tried for an edge-aligned neighbour (the paper: 256)", kind="int", minimum=1, maximum=1024),
            Param("outer_jacobian", ..., "use the outer shift's Jacobian (Eq. 22); false: |J| = 1 there, the biased ablation", kind="bool"),
        ),
    )
)
