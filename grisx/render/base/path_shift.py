"""Shift mappings of whole light paths: random replay, reconnection and their hybrid.

GRIS reuses a path x̄ sampled at pixel j in pixel i by a *shift map* T_{j→i}
that turns it into a path of pixel i, weighting it by (seed 000, Eq. 9;
seed 003, Sec. 5.1)

    w = m_j(T(x̄)) · p̂_i(T(x̄)) · W_x̄ · |∂T/∂x̄|.

This module holds the three shifts of ReSTIR PT (Lin et al. 2022, Sec. 7), as
one specialized Warp function that every path-reuse renderer calls (ReSTIR PT,
and later G-PT's inner/outer shifts, Suffix ReSTIR's suffix shifts and
ReSTCV's T_{i→j}). Paths live in **path space with the solid-angle product
measure**: a path x₁ → x₂ → … → x_n starts at the pixel's primary vertex x₁
(the *domain*: :class:`Domain`), and its integrand is

    f(x̄) = Π_{i<n} f_s(x_i) |cos θ_i| · L_e(x_n → x_{n−1})

(BSDF evals carry the cosine, grisx's Mitsuba convention; a delta lobe
counts as weight × lobe probability).

**Measure.** Each sampled direction is measured in π · solid angle rather
than solid angle (a delta direction by counting): f and every path density
carry a factor π per non-delta segment (:func:`segment_measure`). That is a
change of measure by a constant per path length, so it changes no ratio
that an estimate is made of — RIS weights p̂/p, UCWs, MIS weights, shift
Jacobians (both sides of a shift have the same segments) and f · W are all
the same — but it keeps f and p near 1 per diffuse bounce (a cosine-sampled
density is cos θ instead of cos θ / π). In plain solid angle a path of 60
diffuse bounces has f and p near 10⁻⁴⁵, below float32's range: ReSTIR PT
then produced 0/0 weights and lost 72% of a closed room's light.

**Russian roulette.** From ``rr_depth`` on, a path continues after the BSDF
sample at x_i with probability q (:func:`grisx.theory.roulette.roulette_survival`,
decided by uniform ``8 i + 6`` of the path's key); q is part of the path's
density, so replay re-decides it with the destination's own q (failing where
it would have ended there) and its Jacobian carries both q's. Reconnected
suffixes keep their vertices: no q enters Eq. 11. A path also carries the *technique*
t that made its last segment — next-event estimation or BSDF sampling — and
the integrand of the labelled path is m_t(x̄) f(x̄), m_t the power heuristic
between the two techniques in the path's current domain (Σ_t m_t = 1, so the
labelled integrals sum to the pixel's). Shifts keep the label, and because
replay regenerates the last segment *with its technique*, m_t must be part of
f in every domain: a label-dependent shift applied to an unlabelled integrand
is biased (the tests catch it). The target of resampling is
p̂(x̄) = luminance(m_t f)(x̄) (:func:`path_target`).

**Random replay.** A path is identified by its random seed ``key``: the
uniforms of vertex i are ``random_uniform(key, 8 i + d)`` (d = 0–2: next-event
estimation, 3–5: BSDF sampling), so re-running the path tracer at pixel i with
j's key gives T(x̄). In path space its Jacobian is the ratio of the sampling
densities of the replayed directions (Lin et al. 2022, Sec. 7.1)

    |∂T/∂x̄| = Π_l p_j(ω_l) / p_i(ω'_l).

**Reconnection.** Connect x₁' of pixel i to x₂ of the source path and keep
everything after it. The solid angle at x₁ maps to the one at x₁' through the
area at x₂, so |∂T/∂x̄| is seed 004's Eq. 11,

    |J| = |cos φ₂'| / |cos φ₂| · ‖x₁ − x₂‖² / ‖x₁' − x₂‖²,

(:func:`grisx.theory.shift.reconnection_jacobian`, ``dims = 3``). Defined only
where x₁, x₁' and x₂ are not delta surfaces.

**Hybrid.** Replay up to the *reconnection vertex* x_k, the second vertex of the
first pair (x_{k−1}, x_k) of consecutive rough vertices (roughness > 0.2;
emitter end points count as rough) more than a near-field distance apart,
then reconnect x_{k−1}' → x_k and keep the suffix. Its Jacobian is the product
of the two above: the replayed prefix's density ratio times Eq. 11 at x_k.

**Partial bijections.** Each shift is defined on part of path space only
(seed 000, Sec. 3.1): it fails on a blocked or missed replay, a delta vertex
where it must reconnect, an occluded reconnection segment, and — for the
hybrid shift to be its own inverse — when the shifted prefix would have
picked a *different* reconnection vertex (an earlier qualifying pair, or a
near/smooth x_{k−1}'). A **Jacobian rejection threshold** (|J| outside
[1/J_max, J_max]) discards shifts whose weight would explode; it is symmetric
in J ↔ 1/J, so T restricted to the accepted set is still a bijection and MIS
stays unbiased.

Invertibility: T_{i→j}(T_{j→i}(x̄)) = x̄ with |J_{i→j}| · |J_{j→i}| = 1, and
:func:`make_path_shift`'s ``shift`` is both directions (call it with the
other domain). The :class:`PathSample` record stores what every shift needs:
the seed, the length and how the last vertex was reached (next-event estimation
or BSDF sampling), the reconnection vertex (index, position, normals,
material, outgoing direction ``rc_wi``, the cached suffix f beyond its BSDF),
the replayed directions' density product and the path's f in its own domain.

**Sampling into a path reservoir.** ``stream_candidates`` traces one path
from a domain (next-event estimation at every non-delta vertex, BSDF
sampling, Russian roulette) and streams every light connection and emitter
hit into a :class:`PathReservoir` with its reconnection data chosen by the same
rule the shift checks; ``settle`` re-evaluates the kept path as the shift
measures it (geometric segments instead of the offset rays that sampled them,
so T⁻¹(T(x̄)) = x̄ holds to rounding) and finalizes the UCW. Renderers that reuse
paths start from these two. ``stream_prefix`` walks a path for its estimate alone and **cuts** it
where a prefix x₁ … x_k ends (:func:`prefix_cut_here`: the first rough pair beyond the near field, or
x₂): Suffix ReSTIR's gather samples its prefix and gathers the light that ends within it in one walk.

References: D. Lin, M. Kettunen, B. Bitterli, J. Pantaleoni, C. Yuksel,
C. Wyman, "Generalized resampled importance sampling", SIGGRAPH 2022
(restated in seed 000 Sec. 3.2.2 and seed 003 Sec. 5.1); seed 004 Eq. 11.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from typing import Any

import warp as wp

from grisx.render.base.screen import kernel_cache
from grisx.errors import InvalidParameterError
from grisx.scene.bsdf import make_bsdf
from grisx.scene.frame import frame_from_normal, to_local, to_world
from grisx.scene.material import SCENE_MOVING_OBJECTS, Material
from grisx.scene.lights import DeltaArrival, light_pdf_emitter, luminance, make_lights
from grisx.scene.scene import (
    SceneData,
    shadow_ray_along,
    shadow_ray_between,
    SurfaceInteraction,
    motion_on_segment,
    spawn_origin,
    make_surface,
    surface_material_at,
)
from grisx.theory.control_variate import decoupled_contribution
from grisx.theory.mis import target_from, technique_mis
from grisx.theory.gris import ris_weight
from grisx.theory.random import random_uniform
from grisx.theory.roulette import roulette_survival
from grisx.theory.reservoir import Reservoir, reservoir_drop, reservoir_finalize, reservoir_retarget, reservoir_update
from grisx.theory.shift import JACOBIAN_BOUND_SYMMETRIC, jacobian_bounded, reconnection_jacobian, replay_jacobian

wp.set_module_options({"enable_backward": False})

__all__ = [
    "Domain",
    "PathSample",
    "PathReservoir",
    "PathSlots",
    "path_slots",
    "path_slot_store",
    "path_slot_load",
    "ShiftParams",
    "PathShiftResult",
    "PathShiftFuncs",
    "make_path_shift",
    "shift_params",
    "path_dim",
    "rc_pair_ok",
    "path_target",
    "path_sample_empty",
    "vertex_material",
    "vertex_from_hit",
    "target_to",
    "target_back_from",
    "jacobian_accepted",
    "EmitterHit",
    "SHIFT_MODES",
    "SHIFT_REPLAY",
    "SHIFT_RECONNECTION",
    "SHIFT_HYBRID",
    "VERTEX_SURFACE",
    "VERTEX_AREA_LIGHT",
    "VERTEX_POINT_LIGHT",
    "VERTEX_ENV",
    "DIM_NEE",
    "DIM_BSDF",
    "PrefixCut",
    "StreamedPath",
    "prefix_cut_here",
    "CUT_NONE",
    "CUT_HYBRID",
    "CUT_FIRST_BOUNCE",
]

SHIFT_REPLAY = wp.constant(0)
SHIFT_RECONNECTION = wp.constant(1)
SHIFT_HYBRID = wp.constant(2)
#: user-facing names of the shifts, in the order of their constants
SHIFT_MODES = {"replay": 0, "reconnection": 1, "hybrid": 2}

VERTEX_SURFACE = wp.constant(0)  # a surface vertex with a BSDF (followed by more of the path)
VERTEX_AREA_LIGHT = wp.constant(1)  # end point on an emissive triangle
VERTEX_POINT_LIGHT = wp.constant(2)  # end point on a point light (a delta in direction)
VERTEX_ENV = wp.constant(3)  # end point on the environment: ``rc_p`` holds the direction

DIM_NEE = wp.constant(0)  # counters 8i + 0..2: light selection, point on the light
DIM_BSDF = wp.constant(3)  # counters 8i + 3..5: lobe, direction
DIM_RR = wp.constant(6)  # counter 8i + 6: the Russian-roulette decision after BSDF sampling at x_i
#: each non-delta direction is measured in π · solid angle (see "Measure" in the module docstring)
MEASURE_SCALE = wp.constant(wp.pi)
#: where :func:`prefix_cut_here` cuts a walk into a prefix and a suffix: nowhere, at the first rough pair beyond the
#: near field (the hybrid shift's reconnection rule), or always at x₂
CUT_NONE = wp.constant(0)
CUT_HYBRID = wp.constant(1)
CUT_FIRST_BOUNCE = wp.constant(2)
#: a path whose density leaves this range (float32) ends there: far beyond any path's real density
_PDF_RANGE = wp.constant(1.0e30)
_FAR = wp.constant(1.0e30)


@wp.struct
class Domain:
    """A pixel's integration domain: its primary vertex x₁ (surface record) and ω_o toward the camera."""

    p: wp.vec3
    ng: wp.vec3
    ns: wp.vec3
    uv: wp.vec2
    material: int
    tri: int
    wo: wp.vec3
    valid: int  # 0: the camera ray missed (no path space to reuse into)
    weight: float  # the domain's film weight (a pixel filter evaluated where its camera ray went, :mod:`~grisx.render.base.area`); 1 for a path vertex


@wp.struct
class PathSample:
    """A path x₁ → … → x_n of some domain, stored as what its shifts need (see the module docstring)."""

    key: wp.uint32  # the random seed: replaying it regenerates every sampled direction
    length: int  # n − 1 segments after x₁ (1 … max bounces); 0: no path
    end_nee: int  # 1: x_n was reached by next-event estimation, 0: by BSDF sampling
    rc_index: int  # k ≥ 2: the reconnection vertex x_k; 0: none (replayed whole)
    pdf_replay: float  # Π density of the replayed directions (x₁ … x_{k−2}, or all) in this domain
    rc_p: wp.vec3  # x_k (a direction for VERTEX_ENV)
    rc_ng: wp.vec3
    rc_ns: wp.vec3
    rc_uv: wp.vec2
    rc_material: int
    rc_tri: int  # the triangle of x_k (surface, area light) or the point light's index (VERTEX_POINT_LIGHT)
    rc_kind: int  # VERTEX_*
    rc_wi: wp.vec3  # direction x_k → x_{k+1} (surface x_k only)
    rc_cos: float  # cos at x_k of the segment to x_{k−1} (geometric normal; Eq. 11's φ₂)
    rc_dist: float  # ‖x_{k−1} − x_k‖
    suffix: wp.vec3  # f beyond x_k's BSDF (Π f_s|cos| · L_e · m_t); a point light's intensity when x_k is one
    end_light_pdf: float  # k = n − 1: light-sampling density of the last segment (for m_t at x_k)
    end_delta: int  # k = n − 1: the last segment ends on a delta light (m_t = 1)
    f: wp.vec3  # m_t · f(x̄) in this domain (RGB); the target is its luminance


@wp.struct
class PathReservoir:
    """A path reservoir: the bookkeeping (w_sum, target, confidence, UCW), the kept path and a colour estimate.

    ``estimate`` is the pixel's colour estimate carried with the reservoir (seed 002, Listing 1
    line 6): :func:`stream_candidates` leaves there the MC estimate of the paths it traced,
    Σ_l f(x̄_l) / (N p(x̄_l)) (Listing 1 line 36); ReSTCV's reuse passes replace it by their control-variate
    composites; ReSTIR PT shades f(y) W_y and ignores it.
    """

    res: Reservoir
    path: PathSample
    estimate: wp.vec3


@wp.struct
class PrefixCut:
    """Where a walk was cut into a prefix x₁ … x_k and a suffix (seed 001, Sec. 6): x_k and the prefix's factors.

    ``end`` is x_k as a domain (ω_o toward x_{k−1}; ``end.valid`` 0: not cut, no suffix follows); ``f`` is
    Π f_s|cos| of the prefix's directions (π-scaled measure, without the film weight) and ``pdf`` their density
    (no roulette); ``cos`` and ``dist`` describe the segment x_{k−1} → x_k, ``delta`` whether it was sampled
    from a delta lobe, and ``length`` = k − 1 its segments.
    """

    end: Domain
    f: wp.vec3
    pdf: float
    cos: float
    dist: float
    delta: int
    length: int


@wp.struct
class StreamedPath:
    """What a walk of ``make_path_shift``'s streams returns: the path reservoir and, for ``stream_prefix``, its cut."""

    pr: PathReservoir
    cut: PrefixCut


@wp.struct
class ShiftParams:
    """Which shift and its thresholds (runtime: one compiled kernel serves all three shifts)."""

    mode: int  # SHIFT_REPLAY, SHIFT_RECONNECTION, SHIFT_HYBRID
    rough_threshold: float  # hybrid: vertices rougher than this may be reconnected (0.2, Lin et al. 2022)
    near_distance: float  # hybrid: the pair must be farther apart than this (world units)
    jacobian_max: float  # reject shifts with |J| ∉ [1/J_max, J_max]; <= 0: no threshold
    use_jacobian: int  # 0: pretend |J| = 1 (the wrong-Jacobian ablation; biased)
    rr_depth: int  # Russian roulette after BSDF sampling at x_i for i >= rr_depth (Mitsuba's depth; part of the path's sampling)
    min_bounces: int  # candidates have at least this many segments after x₁ (2: indirect light only, direct light left to ReSTIR DI)


@wp.struct
class PathShiftResult:
    """T(x̄) as a :class:`PathSample` of the destination domain, |∂T/∂x̄|, and whether T was defined."""

    path: PathSample
    jacobian: float
    valid: wp.bool


@wp.func
def path_dim(vertex: int, dim: int) -> int:
    """Counter of random dimension ``dim`` at path vertex x_``vertex`` (8 per vertex, as the path tracer)."""
    return 8 * vertex + dim


@wp.func
def segment_measure(delta: int) -> float:
    """The factor of one segment's measure: π for a direction sampled from a density, 1 for a delta (a count)."""
    if delta != 0:
        return 1.0
    return MEASURE_SCALE


@wp.func
def density_in_range(pdf: float) -> bool:
    """Whether a path density is a normal float32 far from under- and overflow (false for 0 and NaN)."""
    return pdf > 1.0 / _PDF_RANGE and pdf < _PDF_RANGE


@wp.func
def target_of(f: wp.vec3) -> float:
    """p̂ = luminance(m_t f) of a path (one segment or more) whose m_t f is ``f``: :func:`path_target`'s value."""
    t = luminance(f)
    if t > 0.0:  # false for NaN
        return t
    return 0.0


@wp.func
def path_target(x: PathSample) -> float:
    """p̂(x̄) = luminance(m_t f)(x̄): the resampling target of a path in its domain (0 for no path)."""
    if x.length < 1:
        return 0.0
    return target_of(x.f)


@wp.func
def path_sample_empty() -> PathSample:
    """No path (length 0, f = 0)."""
    x = PathSample()
    x.length = 0
    x.f = wp.vec3(0.0)
    x.rc_index = 0
    x.pdf_replay = 0.0
    return x


# ---- a path walk's kept candidate, one slot a pixel, in structure-of-arrays form ----
# A path walk writes the candidate it keeps into memory as it keeps it (a 32-word PathSample carried across the walk's
# rays spilled). In an array of PathSample a warp's store of one field is 32 lanes at a 128-byte stride: a memory
# transaction per lane, for each of the 32 fields. Word w of slot (y, x) at [w, y, x] makes the same store one
# coalesced transaction of the warp (on a CPU the same indices address slot-major memory). PATH_SLOT_FLOATS/INTS name
# the words in order; path_slot_store and path_slot_load are their one reading (tests/render/test_path_shift.py checks
# that they cover every field of PathSample).
PATH_SLOT_FLOATS = ("pdf_replay", "rc_p", "rc_ng", "rc_ns", "rc_uv", "rc_wi", "rc_cos", "rc_dist", "suffix", "end_light_pdf", "f")
PATH_SLOT_INTS = ("length", "end_nee", "rc_index", "rc_material", "rc_tri", "rc_kind", "end_delta")
PATH_SLOT_KEYS = ("key",)
_PATH_SLOT_FLOAT_WORDS = 24  # the float fields' words (vec3 three, vec2 two)


@wp.struct
class PathSlots:
    """Kept paths, one slot a pixel, in structure-of-arrays form (``path_slots`` allocates them): the float words of slot
    (y, x) at ``words[w, y, x]``, its integers at ``ints[w, y, x]``, its seed at ``key[y, x]``."""

    words: wp.array3d(dtype=float)
    ints: wp.array3d(dtype=wp.int32)
    key: wp.array2d(dtype=wp.uint32)


def _slot_words(words: int, height: int, width: int, dtype: Any, device: Any) -> wp.array:
    """A (words, height, width) array of zeros: word-major on a GPU (a warp's store of one word is coalesced); on a CPU
    the same indices over slot-major memory (strides), so that one thread's slot is a few cache lines, not ``words``."""
    if not wp.get_device(device).is_cpu:
        return wp.zeros((words, height, width), dtype=dtype, device=device)
    base = wp.zeros((height, width, words), dtype=dtype, device=device)
    item = wp.types.type_size_in_bytes(dtype)
    view = wp.array(ptr=base.ptr, dtype=dtype, shape=(words, height, width), strides=(item, width * words * item, words * item), device=device)
    view._slot_memory = base  # the view does not own its memory: keep it alive with the view
    return view


def path_slots(height: int, width: int, device: Any) -> PathSlots:
    """Path slots for a height × width image on ``device``, every slot the empty path (all words 0)."""
    s = PathSlots()
    s.words = _slot_words(_PATH_SLOT_FLOAT_WORDS, height, width, float, device)
    s.ints = _slot_words(len(PATH_SLOT_INTS), height, width, wp.int32, device)
    s.key = wp.zeros((height, width), dtype=wp.uint32, device=device)
    return s


@wp.func
def _slot_vec3(s: PathSlots, w: int, y: int, x: int, v: wp.vec3):
    s.words[w, y, x] = v[0]
    s.words[w + 1, y, x] = v[1]
    s.words[w + 2, y, x] = v[2]


@wp.func
def _slot_vec3_at(s: PathSlots, w: int, y: int, x: int) -> wp.vec3:
    return wp.vec3(s.words[w, y, x], s.words[w + 1, y, x], s.words[w + 2, y, x])


@wp.func
def path_slot_store(s: PathSlots, y: int, x: int, p: PathSample):
    """Write path ``p`` into slot (y, x) (the words in PATH_SLOT_FLOATS, PATH_SLOT_INTS, PATH_SLOT_KEYS order)."""
    s.words[0, y, x] = p.pdf_replay
    _slot_vec3(s, 1, y, x, p.rc_p)
    _slot_vec3(s, 4, y, x, p.rc_ng)
    _slot_vec3(s, 7, y, x, p.rc_ns)
    s.words[10, y, x] = p.rc_uv[0]
    s.words[11, y, x] = p.rc_uv[1]
    _slot_vec3(s, 12, y, x, p.rc_wi)
    s.words[15, y, x] = p.rc_cos
    s.words[16, y, x] = p.rc_dist
    _slot_vec3(s, 17, y, x, p.suffix)
    s.words[20, y, x] = p.end_light_pdf
    _slot_vec3(s, 21, y, x, p.f)
    s.ints[0, y, x] = p.length
    s.ints[1, y, x] = p.end_nee
    s.ints[2, y, x] = p.rc_index
    s.ints[3, y, x] = p.rc_material
    s.ints[4, y, x] = p.rc_tri
    s.ints[5, y, x] = p.rc_kind
    s.ints[6, y, x] = p.end_delta
    s.key[y, x] = p.key


@wp.func
def path_slot_load(s: PathSlots, y: int, x: int) -> PathSample:
    """The path in slot (y, x), as :func:`path_slot_store` wrote it."""
    p = PathSample()
    p.pdf_replay = s.words[0, y, x]
    p.rc_p = _slot_vec3_at(s, 1, y, x)
    p.rc_ng = _slot_vec3_at(s, 4, y, x)
    p.rc_ns = _slot_vec3_at(s, 7, y, x)
    p.rc_uv = wp.vec2(s.words[10, y, x], s.words[11, y, x])
    p.rc_wi = _slot_vec3_at(s, 12, y, x)
    p.rc_cos = s.words[15, y, x]
    p.rc_dist = s.words[16, y, x]
    p.suffix = _slot_vec3_at(s, 17, y, x)
    p.end_light_pdf = s.words[20, y, x]
    p.f = _slot_vec3_at(s, 21, y, x)
    p.length = s.ints[0, y, x]
    p.end_nee = s.ints[1, y, x]
    p.rc_index = s.ints[2, y, x]
    p.rc_material = s.ints[3, y, x]
    p.rc_tri = s.ints[4, y, x]
    p.rc_kind = s.ints[5, y, x]
    p.end_delta = s.ints[6, y, x]
    p.key = s.key[y, x]
    return p


@wp.func
def rc_pair_ok(sp: ShiftParams, rough_prev: float, rough_cur: float, dist: float, index: int) -> bool:
    """Whether (x_{index−1}, x_index) may be the reconnection pair: the hybrid's rule, or x₂ for pure reconnection.

    Emitter end points pass roughness 1. Replay never reconnects.
    """
    if sp.mode == SHIFT_HYBRID:
        return rough_prev > sp.rough_threshold and rough_cur > sp.rough_threshold and dist > sp.near_distance
    if sp.mode == SHIFT_RECONNECTION:
        return index == 2 and rough_prev > 0.0 and rough_cur > 0.0
    return False


@wp.func
def prefix_cut_here(sp: ShiftParams, rule: int, rough_prev: float, rough_cur: float, dist: float) -> bool:
    """Whether a prefix ends at x_k after the segment x_{k−1} → x_k (``dist`` long) under ``rule``: ``CUT_HYBRID``, both
    rougher than ``sp``'s threshold and farther apart than its near field (the hybrid shift's rule, whatever ``sp.mode``);
    ``CUT_FIRST_BOUNCE``, always (k = 2)."""
    if rule == CUT_FIRST_BOUNCE:
        return True
    if rule == CUT_HYBRID:
        return rough_prev > sp.rough_threshold and rough_cur > sp.rough_threshold and dist > sp.near_distance
    return False


@wp.func
def prefix_cut_empty() -> PrefixCut:
    c = PrefixCut()
    c.end.valid = 0
    c.f = wp.vec3(0.0)
    c.pdf = 0.0
    c.length = 0
    return c


@wp.struct
class EmitterHit:
    """What a BSDF-sampled ray from p along d finds: emitted radiance, NEE's density for it, distance."""

    radiance: wp.vec3
    light_pdf: float  # solid angle, incl. selection: the competitor in m_t
    dist: float  # ‖hit − p‖ (1e30 for the environment)


@wp.func
def jacobian_accepted(jacobian: float, sp: ShiftParams) -> bool:
    """The symmetric bound |J| ∈ [1/J_max, J_max] of :func:`grisx.theory.shift.jacobian_bounded` (T stays a bijection)."""
    return jacobian_bounded(jacobian, sp.jacobian_max, JACOBIAN_BOUND_SYMMETRIC)


@wp.func
def vertex_from_hit(si: SurfaceInteraction, wo: wp.vec3) -> Domain:
    """A path vertex (or a pixel's domain) at hit ``si`` seen from direction ``wo`` (unit, away from the surface)."""
    v = Domain()
    v.p = si.p
    v.ng = si.ng
    v.ns = si.ns
    v.uv = si.uv
    v.material = si.material
    v.tri = si.tri
    v.wo = wo
    v.valid = si.valid
    v.weight = 1.0
    return v


@wp.func
def target_to(s: PathShiftResult) -> float:
    """p̂_{←src}(y) seen from the destination of ``s`` = T(y): p̂_dst(T(y)) · |∂T/∂y| (seed 001, Eq. 16); 0 if T failed."""
    if s.valid:
        return target_from(path_target(s.path), s.jacobian)
    return 0.0


@wp.func
def target_back_from(target_at_source: float, s: PathShiftResult) -> float:
    """p̂_{←src}(T(x)) = p̂_src(x) / |∂T/∂x| for ``s`` = T(x), from ``target_at_source`` = p̂_src(x): the source
    domain's target carried over (seed 001, Eq. 16). A pass that reads p̂_src(x) before the shift need not hold x
    across it."""
    if s.valid:
        return target_from(target_at_source, 1.0 / s.jacobian)
    return 0.0


@wp.func
def _shift_failed(x: PathSample) -> PathShiftResult:
    r = PathShiftResult()
    r.path = x
    r.path.f = wp.vec3(0.0)
    r.jacobian = 0.0
    r.valid = False
    return r


@wp.func
def vertex_material(scene: SceneData, material: int, uv: wp.vec2, tri: int, p: wp.vec3, ns: wp.vec3, ng: wp.vec3) -> Material:
    """The material of a stored vertex (material id, uv, triangle, position, normals) with its textures resolved, as at
    the hit."""
    return surface_material_at(scene, material, uv, tri, p, ns, ng)


@dataclasses.dataclass(frozen=True)
class PathShiftFuncs:
    """Warp funcs of the path shifts compiled for a set of material kinds.

    ``shift(scene, dst: Domain, x: PathSample, sp: ShiftParams) -> PathShiftResult``
    is T into ``dst`` (and T⁻¹: call it with the source domain);
    ``roughness(scene, material) -> float`` is the hybrid rule's roughness of a material id;
    ``stream_candidates(scene, dom, key, max_bounces, weight_scale, sp, pr, ukey) -> PathReservoir``
    traces one path and streams its candidates (with their reconnection data) into a path
    reservoir, and ``settle(scene, dom, pr, sp) -> PathReservoir`` finalizes it; ``stream_candidates_kept`` (the same
    arguments, then ``kept, ky, kx``) writes the path it keeps into slot (ky, kx) of the :class:`PathSlots` ``kept`` instead of returning it,
    and ``stream_candidates_kept_bare`` does so without the colour estimate (``pr.estimate`` left as given: for a
    renderer that shades f(y) W_y and never reads it); ``stream_prefix`` (the same arguments,
    then ``cut_sp, cut_rule``; returns :class:`StreamedPath`) walks a path for ``estimate`` alone (Σ f/(N p) of its
    candidates; the reservoir is left as given) up to where :func:`prefix_cut_here` ends its prefix.
    ``shift_across`` is ``shift`` between the frames of :meth:`~grisx.scene.scene.BuiltScene.across_frames`,
    failing where ``suffix_moved(scene, x) -> bool`` finds the reused suffix in a box of what moved.
    ``vertex_material(scene, material, uv, tri, p, ns, ng) -> Material`` resolves a stored vertex's material with
    the wrappers of these kinds (:func:`~grisx.scene.scene.make_surface`).
    """

    kinds: frozenset[int]
    shift: Any
    roughness: Any
    stream_candidates: Any
    stream_candidates_kept: Any
    stream_candidates_kept_bare: Any
    stream_prefix: Any
    settle: Any
    suffix_moved: Any
    shift_across: Any
    vertex_material: Any


@wp.func
def _endpoint_light(x: PathSample, index: int, kind: int, p: wp.vec3, n: wp.vec3, tri: int, cos_rc: float, dist: float, suffix: wp.vec3, pdf_replay: float) -> PathSample:
    """``x`` with its reconnection vertex set to the end point x_index on a light."""
    out = x
    out.rc_index = index
    out.rc_kind = kind
    out.rc_p = p
    out.rc_ng = n
    out.rc_ns = n
    out.rc_tri = tri
    out.rc_material = -1
    out.rc_cos = cos_rc
    out.rc_dist = dist
    out.suffix = suffix
    out.pdf_replay = pdf_replay
    return out




@kernel_cache
def make_path_shift(kinds: Iterable[int]) -> PathShiftFuncs:
    """The path shifts specialized to the scene's material kinds ``kinds`` (cached)."""
    key = frozenset(kinds)
    bsdf = make_bsdf(key)
    surface = make_surface(key)  # the wrappers and shapes of these kinds only (shadow the all-kinds ones)
    lights = make_lights(key)  # the lights of these kinds only
    emitter_radiance = lights.emitter_radiance
    environment_eval = lights.environment_eval
    environment_pdf = lights.environment_pdf
    sample_light = lights.sample_light
    delta_light_arrival = lights.delta_light_arrival
    vertex_material = surface.surface_material_at
    intersect = surface.intersect
    light_occluded = surface.light_occluded
    blocked = surface.blocked

    @wp.func
    def emitter_hit(scene: SceneData, p: wp.vec3, d: wp.vec3, si: SurfaceInteraction) -> EmitterHit:
        """Emission reached from ``p`` along ``d`` (the environment if ``si`` missed)."""
        # (not named ``e``: Warp 1.19 resolves ``e.dist`` as its constant ``wp.e`` while hashing a module before
        # code generation, and not after, so a process that had built another module hashed this one differently
        # and compiled it a second time)
        hit = EmitterHit()
        hit.dist = _FAR
        if si.valid == 0:
            hit.radiance = environment_eval(scene.lights, d)
            hit.light_pdf = environment_pdf(scene.lights, d)
        else:
            hit.radiance = emitter_radiance(scene.lights, si.tri, si.p, si.ng, -d)
            hit.light_pdf = light_pdf_emitter(scene.lights, si.tri, p, si.p, si.ng)
            hit.dist = wp.length(si.p - p)
        return hit

    @wp.func
    def roughness(scene: SceneData, material: int) -> float:
        return bsdf.roughness(scene.materials[material])

    @wp.func
    def rc_roughness(scene: SceneData, x: PathSample) -> float:
        if x.rc_kind == VERTEX_SURFACE:
            return bsdf.roughness(scene.materials[x.rc_material])
        return 1.0  # emitter end points

    @wp.func
    def shift(scene: SceneData, dst: Domain, x: PathSample, sp: ShiftParams) -> PathShiftResult:
        res = _shift_failed(x)
        if dst.valid == 0 or x.length < 1:
            return res
        k = x.rc_index
        if sp.mode == SHIFT_RECONNECTION and k != 2:
            return res  # pure reconnection does not fall back to replay
        if sp.mode == SHIFT_REPLAY and k != 0:
            return res
        n = x.length + 1  # index of the end vertex x_n
        key = x.key
        v = dst  # the current vertex x_i'
        f = wp.vec3(dst.weight, dst.weight, dst.weight)  # the film weight of x₁' (1 unless the film sample is part of the path)
        pdf = float(1.0)
        eta = float(1.0)
        jac_rc = float(1.0)
        cos_dst = float(0.0)
        dist_dst = float(0.0)
        done = bool(False)
        i = int(1)
        while i < n and not done:
            m = vertex_material(scene, v.material, v.uv, v.tri, v.p, v.ns, v.ng)
            frame = frame_from_normal(v.ns)
            wo_l = to_local(frame, v.wo)
            rough = bsdf.roughness(m)
            if k != 0 and i == k - 1:
                # ---- reconnection x'_{k−1} → x_k (seed 004, Eq. 11) ----
                if bsdf.is_delta(m) != 0:
                    return res
                d = x.rc_p
                dist = float(_FAR)
                rc_p = x.rc_p
                arrival = DeltaArrival()
                if x.rc_kind == VERTEX_POINT_LIGHT:
                    arrival = delta_light_arrival(scene.lights, x.rc_tri, v.p)  # from the new x'_{k−1}
                    if arrival.dist <= 0.0:
                        return res
                    rc_p = arrival.p
                    dist = arrival.dist
                    d = arrival.wi
                elif x.rc_kind != VERTEX_ENV:
                    dd = x.rc_p - v.p
                    dist = wp.length(dd)
                    if dist <= 0.0:
                        return res
                    d = dd / dist
                if not rc_pair_ok(sp, rough, rc_roughness(scene, x), dist, k):
                    return res  # x'_{k−1} would not pick x_k: T⁻¹ would differ
                fo = bsdf.eval(m, wo_l, to_local(frame, d))
                if wp.length_sq(fo) <= 0.0:
                    return res
                pdf_bsdf = bsdf.pdf(m, wo_l, to_local(frame, d))  # for m_t when x_k is the end vertex (before the shadow ray: m dies here)
                # the segment x'_{k−1} → x_k built first, traced at one place: one inlined traversal (ShadowRay)
                if x.rc_kind == VERTEX_ENV:
                    shadow = shadow_ray_along(scene, spawn_origin(scene, v.p, v.ng, d), d, dist)
                else:
                    n_k = x.rc_ng  # both ends lifted off their surfaces; a point light is no surface
                    if x.rc_kind == VERTEX_POINT_LIGHT:
                        n_k = wp.vec3(0.0, 0.0, 0.0)
                    shadow = shadow_ray_between(scene, v.p, v.ng, rc_p, n_k)
                if blocked(scene, shadow):
                    return res
                if x.rc_kind != VERTEX_POINT_LIGHT:
                    fo = fo * MEASURE_SCALE  # the segment x'_{k−1} → x_k is a direction (a point light's is a delta)
                f = wp.cw_mul(f, fo)
                if x.rc_kind == VERTEX_SURFACE:
                    mk = vertex_material(scene, x.rc_material, x.rc_uv, x.rc_tri, x.rc_p, x.rc_ns, x.rc_ng)
                    frame_k = frame_from_normal(x.rc_ns)
                    wo_k = to_local(frame_k, -d)
                    wi_k = to_local(frame_k, x.rc_wi)
                    fk = bsdf.eval(mk, wo_k, wi_k)
                    if not (k == n - 1 and x.end_nee != 0 and x.end_delta != 0):
                        fk = fk * MEASURE_SCALE  # x_k → x_{k+1} is a direction unless NEE to a point light
                    f = wp.cw_mul(f, wp.cw_mul(fk, x.suffix))
                    if k == n - 1:
                        # x_k's new incoming direction changes its BSDF density: the technique weight m_t
                        f = f * technique_mis(x.end_nee, x.end_delta, 0, x.end_light_pdf, bsdf.pdf(mk, wo_k, wi_k))
                    cos_dst = wp.dot(x.rc_ng, -d)
                    jac_rc = reconnection_jacobian(x.rc_cos, cos_dst, x.rc_dist, dist, 3)
                elif x.rc_kind == VERTEX_AREA_LIGHT:
                    f = wp.cw_mul(f, emitter_radiance(scene.lights, x.rc_tri, x.rc_p, x.rc_ng, -d))
                    f = f * technique_mis(x.end_nee, 0, 0, light_pdf_emitter(scene.lights, x.rc_tri, v.p, x.rc_p, x.rc_ng), pdf_bsdf)
                    cos_dst = wp.dot(x.rc_ng, -d)
                    jac_rc = reconnection_jacobian(x.rc_cos, cos_dst, x.rc_dist, dist, 3)
                elif x.rc_kind == VERTEX_POINT_LIGHT:
                    # I(−d) / d² toward the *new* x'_{k−1} (a spot's falloff, a projector's image), or a directional
                    # light's E along its one direction; a delta position or direction: |J| = 1, m_t = 1
                    f = wp.cw_mul(f, arrival.radiance)
                    cos_dst = 1.0
                else:
                    f = wp.cw_mul(f, environment_eval(scene.lights, d))  # same direction: |J| = 1
                    f = f * technique_mis(x.end_nee, 0, 0, environment_pdf(scene.lights, d), pdf_bsdf)
                    cos_dst = 1.0
                dist_dst = dist
                done = True
            elif i == n - 1 and x.end_nee != 0:
                # ---- the last segment: next-event estimation, replayed ----
                if bsdf.is_delta(m) != 0:
                    return res
                c = path_dim(i, DIM_NEE)
                ls = sample_light(scene.lights, v.p, random_uniform(key, c), wp.vec2(random_uniform(key, c + 1), random_uniform(key, c + 2)))
                if ls.pdf <= 0.0 or wp.length_sq(ls.radiance) <= 0.0:
                    return res
                fo = bsdf.eval(m, wo_l, to_local(frame, ls.wi))
                if wp.length_sq(fo) <= 0.0:
                    return res
                pdf_bsdf = bsdf.pdf(m, wo_l, to_local(frame, ls.wi))  # before the shadow ray, as above
                if rc_pair_ok(sp, rough, 1.0, ls.dist, n):
                    return res  # the shifted path would reconnect here; the source did not
                if light_occluded(scene, v.p, v.ng, ls):
                    return res
                s = segment_measure(ls.delta)
                f = wp.cw_mul(f, wp.cw_mul(fo, ls.radiance)) * (s * technique_mis(1, ls.delta, 0, ls.pdf, pdf_bsdf))
                pdf = pdf * ls.pdf * s
                done = True
            else:
                # ---- BSDF sampling, replayed ----
                c = path_dim(i, DIM_BSDF)
                bs = bsdf.sample(m, wo_l, random_uniform(key, c), wp.vec2(random_uniform(key, c + 1), random_uniform(key, c + 2)))
                if bs.valid == 0 or not (bs.pdf > 0.0):
                    return res
                s = segment_measure(bs.delta)
                f = wp.cw_mul(f, bs.weight * (bs.pdf * s))  # f_s|cos θ| (a delta lobe: weight × lobe probability)
                pdf = pdf * bs.pdf * s
                eta = eta * bs.eta
                if i >= sp.rr_depth:
                    # ---- Russian roulette, replayed with this domain's survival probability ----
                    q = roulette_survival(f / pdf, eta)
                    if random_uniform(key, path_dim(i, DIM_RR)) >= q:
                        return res  # the destination's path would have ended here
                    pdf = pdf * q
                if not density_in_range(pdf):
                    return res
                d = wp.normalize(to_world(frame, bs.wi))
                si = intersect(scene, spawn_origin(scene, v.p, v.ng, d), d, 1.0e30)
                if i == n - 1:
                    # the end vertex, reached by BSDF sampling
                    eh = emitter_hit(scene, v.p, d, si)
                    if rc_pair_ok(sp, rough, 1.0, eh.dist, n):
                        return res
                    f = wp.cw_mul(f, eh.radiance) * technique_mis(0, 0, bs.delta, eh.light_pdf, bs.pdf)
                    done = True
                else:
                    if si.valid == 0:
                        return res
                    # the replayed prefix may not offer an earlier reconnection pair than the source's
                    if rc_pair_ok(sp, rough, bsdf.roughness(scene.materials[si.material]), wp.length(si.p - v.p), i + 1):
                        return res
                    v = vertex_from_hit(si, -d)
                    i += 1
        if not done or not (pdf > 0.0):
            return res
        jac = replay_jacobian(x.pdf_replay, pdf) * jac_rc  # Lin et al. 2022, Sec. 7: replay density ratio × Eq. 11
        if not jacobian_accepted(jac, sp):
            return res
        if sp.use_jacobian == 0:
            jac = 1.0
        out = PathShiftResult()
        out.path = x
        out.path.pdf_replay = pdf
        out.path.rc_cos = cos_dst
        out.path.rc_dist = dist_dst
        out.path.f = f
        out.jacobian = jac
        out.valid = True
        return out

    # ---- shifts across frames: the reused suffix must be the same path in both ----
    @wp.func
    def suffix_replay_moved(scene: SceneData, x: PathSample) -> bool:
        """Across frames (``scene.moved_count`` > 0): whether x's suffix x_k … x_n, which a reconnection reuses
        as it is, runs through a box of what moved in between (:func:`~grisx.scene.scene.motion_on_segment`).

        The suffix is replayed — its directions are x's random numbers, drawn as the walk drew them — and
        each segment tested, shadow rays and escapes included. Everything outside the boxes is the same in
        both frames, so up to the first segment that meets one, the replay is the same in either frame's
        scene: both ends of a temporal shift reach the same verdict (T and T⁻¹ fail together). A path that
        reconnects nowhere (replayed whole) reuses nothing.
        """
        if scene.moved_count == 0 or x.length < 1 or x.rc_index == 0:
            return False
        k = x.rc_index
        n = x.length + 1
        if x.rc_kind == VERTEX_AREA_LIGHT:
            return motion_on_segment(scene, x.rc_p, x.rc_ng, 0.0)  # x_k = x_n on an emitter, which may move
        if x.rc_kind != VERTEX_SURFACE:
            return False  # a direction to the environment or a point light: nothing after x_k is reused
        key = x.key
        v = Domain()
        v.p = x.rc_p
        v.ng = x.rc_ng
        d = x.rc_wi  # x_k → x_{k+1} as sampled (the light's direction where x_k's NEE ends the path)
        i = k
        while i < n:
            if i == n - 1 and x.end_nee != 0:
                c = path_dim(i, DIM_NEE)
                ls = sample_light(scene.lights, v.p, random_uniform(key, c), wp.vec2(random_uniform(key, c + 1), random_uniform(key, c + 2)))
                return motion_on_segment(scene, v.p, ls.wi, ls.dist)
            if i > k:
                m = vertex_material(scene, v.material, v.uv, v.tri, v.p, v.ns, v.ng)
                frame = frame_from_normal(v.ns)
                c = path_dim(i, DIM_BSDF)
                bs = bsdf.sample(m, to_local(frame, v.wo), random_uniform(key, c), wp.vec2(random_uniform(key, c + 1), random_uniform(key, c + 2)))
                if bs.valid == 0:
                    return True  # not x's suffix in this scene
                d = wp.normalize(to_world(frame, bs.wi))
            si = intersect(scene, spawn_origin(scene, v.p, v.ng, d), d, 1.0e30)
            if si.valid == 0:
                return motion_on_segment(scene, v.p, d, 1.0e30)  # an escape (x_n on the environment)
            if motion_on_segment(scene, v.p, d, si.t):
                return True
            v = vertex_from_hit(si, -d)
            i += 1
        return False

    @wp.func
    def nothing_moves(scene: SceneData, x: PathSample) -> bool:
        """``suffix_moved`` of a scene whose objects never move: no suffix meets what moved."""
        return False

    # the replay is a whole path walk inlined into every temporal stage: only for scenes with moving objects
    suffix_moved = suffix_replay_moved if SCENE_MOVING_OBJECTS in key else nothing_moves

    @wp.func
    def shift_across(scene: SceneData, dst: Domain, x: PathSample, sp: ShiftParams) -> PathShiftResult:
        """:func:`shift` between frames: undefined where the suffix it would reuse may differ between them."""
        if suffix_moved(scene, x):
            return _shift_failed(x)
        return shift(scene, dst, x, sp)

    # ---- sampling paths into a path reservoir (what every path-reuse renderer starts from) ----
    # ``estimate_only``: the same walk and the same Σ f/(N p), without the reservoir or the candidates' reconnection
    # data (Suffix ReSTIR's gather walks a prefix for its light alone: two thirds of its prefix pass was that bookkeeping).
    # ``cut``: the walk also ends its prefix where ``prefix_cut_here`` says (the gather sampled the prefix in a walk of its
    # own before, the same directions traced twice)
    # ``with_estimate``: the walk sums Σ f/(N p) into ``pr.estimate`` (ReSTCV's ⟨F⟩_init, Suffix ReSTIR's gather); without
    # it that vec3 and its sum are not live across the walk's rays (ReSTIR PT's walk at 80 registers on door-ajar, sm_90:
    # 1264 -> 1200 B of stack, spill stores 1816 -> 1660 B)
    # ``kept_in_memory``: the walk writes the candidate it keeps into slot (ky, kx) of ``kept`` (PathSlots) when it keeps it, instead of
    # carrying it across every ray of the walk: a third 32-word PathSample live beside the walk's reconnection data and
    # the candidate being composed, it spilled (sm_90, glossy-room: initial_pass 2160 -> 1104 B of stack at 128
    # registers). ``pr.path`` is then left as given
    def make_stream(estimate_only: bool, cut: bool, kept_in_memory: bool, with_estimate: bool = True) -> Any:
        @wp.func
        def stream_path(
            scene: SceneData,
            dom: Domain,
            key: wp.uint32,
            max_bounces: int,
            weight_scale: float,
            sp: ShiftParams,
            pr: PathReservoir,
            ukey: wp.uint32,
            cut_sp: ShiftParams,
            cut_rule: int,
            kept: Any,
            ky: int,
            kx: int,
        ) -> StreamedPath:
            """Trace one path from ``dom`` with seed ``key`` and stream every light connection and emitter hit into ``pr``.

            Next-event estimation at every non-delta vertex, BSDF sampling, Russian roulette from
            ``sp.rr_depth`` on (Mitsuba's rule, :func:`~grisx.theory.roulette.roulette_survival`), at
            most ``max_bounces`` segments after x₁ (< 0: unbounded), candidates of at least
            ``sp.min_bounces`` (2: indirect light alone, the walk itself unchanged). Each candidate x̄_l gets the
            RIS weight w_l = ``weight_scale`` · p̂(x̄_l) / p(x̄_l) (seed 000, Eq. 6; m_t is inside p̂,
            so with ``weight_scale`` = 1/N over N traced paths the MIS weights sum to one) and its
            reconnection data under ``sp``'s rule. Reservoir decisions use ``random_uniform(ukey, j)``,
            j = 0, 1, … (one key per traced path). Call :func:`settle` once after the last path.

            With ``cut``, the walk is also a prefix sampler: it ends after the segment x_{k−1} → x_k where
            :func:`prefix_cut_here` (``cut_sp``, ``cut_rule``) first holds and returns x_k in ``cut``, having
            streamed the light that ends within the prefix (NEE at x₁ … x_{k−1}, emitters hit at x₂ … x_k). Where
            roulette ends the light's walk first, the prefix walks on (a prefix is never rouletted); where the
            prefix fails (escape, an invalid sample, no pair within ``max_bounces``), the walk is the whole path's.
            """
            r = pr.res
            sel = path_sample_empty()
            if wp.static(not kept_in_memory):
                sel = pr.path
            estimate = pr.estimate  # Σ f/(N p) over the candidates (seed 002, Listing 1 line 36)
            ucount = int(0)
            out = StreamedPath()
            out.pr = pr
            out.cut = prefix_cut_empty()
            if dom.valid == 0:
                return out
            v = dom  # the current vertex x_i
            fthru = wp.vec3(dom.weight, dom.weight, dom.weight)  # f of x₁ … x_i: x₁'s film weight, the BSDF factors so far
            pdf = float(1.0)  # density of the directions sampled so far (π-scaled measure, roulette included)
            eta = float(1.0)  # relative index of refraction crossed so far (for the roulette)
            cur = path_sample_empty()  # the walk's reconnection data (k = 0 until a pair qualifies)
            cur.key = key
            suffix_thru = wp.vec3(1.0, 1.0, 1.0)  # f factors after x_k's BSDF
            lit = bool(True)  # the light's walk goes on (false once roulette or the density range ended it)
            seeking = bool(wp.static(cut))  # the prefix's end is still to be found
            cut_f = wp.vec3(1.0, 1.0, 1.0)  # the prefix's f and density (no film weight, no roulette)
            cut_pdf = float(1.0)
            i = int(1)
            while max_bounces < 0 or i <= max_bounces:
                m = vertex_material(scene, v.material, v.uv, v.tri, v.p, v.ns, v.ng)
                frame_l = frame_from_normal(v.ns)
                wo_l = to_local(frame_l, v.wo)
                rough = bsdf.roughness(m)
                # x_i's BSDF sample is drawn before NEE's shadow ray (its own random dimensions, so the order changes no
                # number): the material is then dead across that ray, and across every later one
                c = path_dim(i, DIM_BSDF)
                bs = bsdf.sample(m, wo_l, random_uniform(key, c), wp.vec2(random_uniform(key, c + 1), random_uniform(key, c + 2)))
                # -- next-event estimation: candidate x₁ … x_i → light --
                if lit and bsdf.is_delta(m) == 0 and i >= sp.min_bounces:
                    c = path_dim(i, DIM_NEE)
                    ls = sample_light(scene.lights, v.p, random_uniform(key, c), wp.vec2(random_uniform(key, c + 1), random_uniform(key, c + 2)))
                    if ls.pdf > 0.0 and wp.length_sq(ls.radiance) > 0.0:
                        wi_l = to_local(frame_l, ls.wi)
                        fo = bsdf.eval(m, wo_l, wi_l)
                        pdf_bsdf = bsdf.pdf(m, wo_l, wi_l)  # before the shadow ray, as the BSDF sample
                        if wp.length_sq(fo) > 0.0:
                            if not light_occluded(scene, v.p, v.ng, ls):
                                mis = technique_mis(1, ls.delta, 0, ls.pdf, pdf_bsdf)  # Veach Eq. 9.13
                                s_nee = segment_measure(ls.delta)
                                fo = fo * s_nee
                                f_cand = wp.cw_mul(fthru, wp.cw_mul(fo, ls.radiance)) * mis  # m_t · f
                                t = target_of(f_cand)
                                w = ris_weight(weight_scale, t, pdf * ls.pdf * s_nee)  # seed 000, Eq. 6 (m_t is inside t)
                                if wp.static(with_estimate):
                                    estimate += decoupled_contribution(w, t, f_cand)  # w f/p̂ = m_t f/(N p)
                                if wp.static(not estimate_only):
                                    r = reservoir_update(r, w, t, 0.0, random_uniform(ukey, ucount))
                                    ucount += 1
                                    if r.selected:
                                        # the candidate's record, built only where it is kept
                                        cand_x = cur
                                        cand_x.length = i
                                        cand_x.end_nee = 1
                                        cand_x.f = f_cand
                                        if cur.rc_index == i:
                                            cand_x.rc_wi = ls.wi
                                            cand_x.suffix = ls.radiance  # m_t is re-evaluated at x_k by the shift
                                            cand_x.end_light_pdf = ls.pdf
                                            cand_x.end_delta = ls.delta
                                        elif cur.rc_index != 0:
                                            cand_x.suffix = wp.cw_mul(suffix_thru, wp.cw_mul(fo, ls.radiance)) * mis
                                        elif rc_pair_ok(sp, rough, 1.0, ls.dist, i + 1):
                                            kind = VERTEX_AREA_LIGHT
                                            lp = ls.p
                                            light_id = ls.tri
                                            sfx = wp.vec3(1.0, 1.0, 1.0)
                                            if ls.is_env != 0:
                                                kind = VERTEX_ENV
                                                lp = ls.wi
                                            elif ls.delta != 0:
                                                # a spot's intensity depends on the direction it is left in: keep which light, not its value
                                                kind = VERTEX_POINT_LIGHT
                                                light_id = ls.light - scene.lights.num_emitters
                                            cand_x = _endpoint_light(cand_x, i + 1, kind, lp, ls.n, light_id, wp.dot(ls.n, -ls.wi), ls.dist, sfx, pdf)
                                        else:
                                            cand_x.pdf_replay = pdf * ls.pdf * s_nee
                                        if wp.static(kept_in_memory):
                                            path_slot_store(kept, ky, kx, cand_x)
                                        else:
                                            sel = cand_x
                # -- BSDF sampling (drawn above) --
                if bs.valid == 0 or not (bs.pdf > 0.0):
                    break
                s_bsdf = segment_measure(bs.delta)
                fac = bs.weight * (bs.pdf * s_bsdf)
                fthru = wp.cw_mul(fthru, fac)
                pdf_before = pdf
                pdf = pdf * bs.pdf * s_bsdf
                eta = eta * bs.eta
                if wp.static(cut):
                    cut_f = wp.cw_mul(cut_f, fac)
                    cut_pdf = cut_pdf * bs.pdf * s_bsdf
                    if seeking and not density_in_range(cut_pdf):
                        seeking = False  # the prefix fails; the light's walk goes on alone
                # -- Russian roulette (Mitsuba's rule); its decision is part of the path's random sequence --
                if lit and i >= sp.rr_depth:
                    q = roulette_survival(fthru / pdf, eta)
                    if random_uniform(key, path_dim(i, DIM_RR)) >= q:
                        lit = False
                    pdf = pdf * q
                if lit and not density_in_range(pdf):
                    lit = False  # beyond float32: ends the path (see _PDF_RANGE)
                if not lit and not seeking:
                    break
                d = wp.normalize(to_world(frame_l, bs.wi))
                if wp.static(not estimate_only):
                    if cur.rc_index == i:
                        cur.rc_wi = d
                    elif cur.rc_index != 0:
                        suffix_thru = wp.cw_mul(suffix_thru, fac)
                si = intersect(scene, spawn_origin(scene, v.p, v.ng, d), d, 1.0e30)
                eh = emitter_hit(scene, v.p, d, si)
                le = eh.radiance
                lpdf = eh.light_pdf
                dist = eh.dist
                # -- emitter reached by BSDF sampling: candidate x₁ … x_{i+1} --
                if lit and wp.length_sq(le) > 0.0 and i >= sp.min_bounces:
                    mis = technique_mis(0, 0, bs.delta, lpdf, bs.pdf)
                    f_cand = wp.cw_mul(fthru, le) * mis  # m_t · f
                    t = target_of(f_cand)
                    w = ris_weight(weight_scale, t, pdf)
                    if wp.static(with_estimate):
                        estimate += decoupled_contribution(w, t, f_cand)
                    if wp.static(not estimate_only):
                        r = reservoir_update(r, w, t, 0.0, random_uniform(ukey, ucount))
                        ucount += 1
                        if r.selected:
                            # the candidate's record, built only where it is kept
                            cand_x = cur
                            cand_x.length = i
                            cand_x.end_nee = 0
                            cand_x.f = f_cand
                            if cur.rc_index == i:
                                cand_x.suffix = le  # m_t is re-evaluated at x_k by the shift
                                cand_x.end_light_pdf = lpdf
                                cand_x.end_delta = 0
                            elif cur.rc_index != 0:
                                cand_x.suffix = wp.cw_mul(suffix_thru, le) * mis
                            elif rc_pair_ok(sp, rough, 1.0, dist, i + 1):
                                if si.valid == 0:
                                    cand_x = _endpoint_light(cand_x, i + 1, VERTEX_ENV, d, -d, -1, 1.0, dist, wp.vec3(1.0, 1.0, 1.0), pdf_before)
                                else:
                                    cand_x = _endpoint_light(cand_x, i + 1, VERTEX_AREA_LIGHT, si.p, si.ng, si.tri, wp.dot(si.ng, v.p - si.p) / dist, dist, wp.vec3(1.0, 1.0, 1.0), pdf_before)
                            else:
                                cand_x.pdf_replay = pdf
                            if wp.static(kept_in_memory):
                                path_slot_store(kept, ky, kx, cand_x)
                            else:
                                sel = cand_x
                if wp.static(cut):
                    # -- does the prefix end at x_{i+1}? (the light beyond it is its suffix's) --
                    if seeking and si.valid != 0:
                        cut_dist = wp.length(si.p - v.p)
                        if prefix_cut_here(cut_sp, cut_rule, rough, roughness(scene, si.material), cut_dist):
                            out.cut.end = vertex_from_hit(si, -d)
                            out.cut.f = cut_f
                            out.cut.pdf = cut_pdf
                            out.cut.dist = cut_dist
                            out.cut.cos = wp.dot(si.ng, v.p - si.p) / cut_dist
                            out.cut.delta = bs.delta
                            out.cut.length = i
                            break
                if si.valid == 0 or (max_bounces >= 0 and i >= max_bounces):
                    break
                # -- advance to x_{i+1}; is (x_i, x_{i+1}) the reconnection pair? --
                if wp.static(not estimate_only):
                    if cur.rc_index == 0 and rc_pair_ok(sp, rough, roughness(scene, si.material), dist, i + 1):
                        cur.rc_index = i + 1
                        cur.rc_kind = VERTEX_SURFACE
                        cur.rc_p = si.p
                        cur.rc_ng = si.ng
                        cur.rc_ns = si.ns
                        cur.rc_uv = si.uv
                        cur.rc_material = si.material
                        cur.rc_tri = si.tri
                        cur.rc_cos = wp.dot(si.ng, v.p - si.p) / dist  # the geometric segment, as the shift measures it
                        cur.rc_dist = dist
                        cur.pdf_replay = pdf_before
                        suffix_thru = wp.vec3(1.0, 1.0, 1.0)
                v = vertex_from_hit(si, -d)
                i += 1
            out.pr.res = r
            if wp.static(not kept_in_memory):
                out.pr.path = sel
            out.pr.estimate = estimate
            return out

        return stream_path

    stream_path = make_stream(False, False, False)
    stream_path_kept = make_stream(False, False, True)
    stream_path_kept_bare = make_stream(False, False, True, with_estimate=False)
    stream_path_prefix_walk = make_stream(True, True, False)

    @wp.func
    def stream_path_prefix(
        scene: SceneData, dom: Domain, key: wp.uint32, max_bounces: int, weight_scale: float, sp: ShiftParams, pr: PathReservoir,
        ukey: wp.uint32, cut_sp: ShiftParams, cut_rule: int,
    ) -> StreamedPath:
        """:func:`stream_path` for ``estimate`` alone, cut where :func:`prefix_cut_here` ends the prefix."""
        return stream_path_prefix_walk(scene, dom, key, max_bounces, weight_scale, sp, pr, ukey, cut_sp, cut_rule, int(0), 0, 0)

    @wp.func
    def stream_path_candidates(
        scene: SceneData, dom: Domain, key: wp.uint32, max_bounces: int, weight_scale: float, sp: ShiftParams, pr: PathReservoir, ukey: wp.uint32
    ) -> PathReservoir:
        """:func:`stream_path` without a cut: one path's candidates streamed into ``pr``."""
        return stream_path(scene, dom, key, max_bounces, weight_scale, sp, pr, ukey, sp, CUT_NONE, int(0), 0, 0).pr

    @wp.func
    def stream_path_candidates_kept(
        scene: SceneData, dom: Domain, key: wp.uint32, max_bounces: int, weight_scale: float, sp: ShiftParams, pr: PathReservoir,
        ukey: wp.uint32, kept: PathSlots, ky: int, kx: int,
    ) -> PathReservoir:
        """:func:`stream_path_candidates` that writes the candidate it keeps into slot (ky, kx) of ``kept`` when it keeps it
        (``pr.path`` is left as given: the kept path is the one in memory, :func:`path_slot_load`)."""
        return stream_path_kept(scene, dom, key, max_bounces, weight_scale, sp, pr, ukey, sp, CUT_NONE, kept, ky, kx).pr

    @wp.func
    def stream_path_candidates_kept_bare(
        scene: SceneData, dom: Domain, key: wp.uint32, max_bounces: int, weight_scale: float, sp: ShiftParams, pr: PathReservoir,
        ukey: wp.uint32, kept: PathSlots, ky: int, kx: int,
    ) -> PathReservoir:
        """:func:`stream_path_candidates_kept` without the colour estimate (``pr.estimate`` is left as given)."""
        return stream_path_kept_bare(scene, dom, key, max_bounces, weight_scale, sp, pr, ukey, sp, CUT_NONE, kept, ky, kx).pr

    @wp.func
    def settle(scene: SceneData, dom: Domain, pr: PathReservoir, sp: ShiftParams) -> PathReservoir:
        """Re-evaluate a kept path that reconnects as the shifts see it, and finalize (UCW, seed 000 Eq. 8).

        Sampling traces offset rays; the shifts measure geometric segments. Storing the
        shift's own evaluation makes T⁻¹(T(y)) = y hold to rounding (a replayed path is
        already computed exactly as its replay). A path the shift cannot reproduce is dropped.
        """
        r = pr.res
        sel = pr.path
        if sel.length > 0 and sel.rc_index != 0:
            own = shift(scene, dom, sel, sp)
            if own.valid and path_target(own.path) > 0.0:
                sel = own.path
                r = reservoir_retarget(r, path_target(sel))
            else:
                r = reservoir_drop(r)
                sel = path_sample_empty()
        out = PathReservoir()
        out.res = reservoir_finalize(r)
        out.path = sel
        out.estimate = pr.estimate
        return out

    funcs = PathShiftFuncs(kinds=key, shift=shift, roughness=roughness, stream_candidates=stream_path_candidates,
                           stream_candidates_kept=stream_path_candidates_kept, stream_candidates_kept_bare=stream_path_candidates_kept_bare,
                           stream_prefix=stream_path_prefix, settle=settle,
                           suffix_moved=suffix_moved, shift_across=shift_across, vertex_material=vertex_material)
    return funcs


def shift_params(
    name: str,
    *,
    rough_threshold: float = 0.2,
    near_distance: float = 0.0,
    jacobian_max: float = 0.0,
    jacobian: bool = True,
    rr_depth: int = 5,
    min_bounces: int = 1,
) -> ShiftParams:
    """A :class:`ShiftParams` record for the shift ``name`` (replay, reconnection or hybrid)."""
    if name not in SHIFT_MODES:
        raise InvalidParameterError(f"unknown shift '{name}' (known: {', '.join(SHIFT_MODES)})")
    if not rough_threshold >= 0.0 or not near_distance >= 0.0 or not jacobian_max >= 0.0:
        raise InvalidParameterError("shift thresholds must be >= 0")
    sp = ShiftParams()
    sp.mode = SHIFT_MODES[name]
    sp.rough_threshold = float(rough_threshold)
    sp.near_distance = float(near_distance)
    sp.jacobian_max = float(jacobian_max)
    sp.use_jacobian = int(bool(jacobian))
    sp.rr_depth = int(rr_depth)
    sp.min_bounces = int(min_bounces)
    return sp
