"""Suffix ReSTIR: conditional RIS over path suffixes and a final gather (seed 001, Sec. 6–7, Alg. 1).

ReSTIR PT (:mod:`~grisx.render.restir_pt`) reuses whole paths at the primary vertex x₁, so a
pixel's neighbours hand it their secondary bounces too: the image is smooth but correlated.
Suffix ReSTIR cuts each path x₁ → x₂ → … into a **prefix** x^p = (x₁ → … → x_k) and a
**suffix** x^s = (x_k → x_{k+1} → …), reuses only suffixes, and integrates by tracing fresh
prefixes that *borrow* them. The prefix ends at x_k, the second vertex of the first pair of
consecutive rough vertices farther apart than the near field — the hybrid shift's
reconnection rule (``prefix=hybrid``; in a diffuse scene k = 2, and ``prefix=bounce`` always
cuts at x₂). A suffix is sampled after its prefix, so its weight is a conditional UCW
W_{X^s|Z} (seed 001, Def. 4.1) given the **supporting prefixes** Z that carry it; every formula
of that theory is :mod:`grisx.theory.conditional`'s, built here by
:func:`~grisx.theory.conditional.make_conditional_ris` with this file's prefix record and
:class:`~grisx.render.base.path_shift.PathSample` as the suffix.

A suffix is a path of the *domain* at its prefix's end vertex x_k (ω_o toward x_{k−1}): the path
tracer of :func:`~grisx.render.base.path_shift.make_path_shift` traces it (``stream_candidates``,
its NEE and BSDF-hit candidates, one kept by RIS), and the suffix shift T(x^s | Z_j → z) is that
module's hybrid shift into the other prefix's x_k' — reconnect x_k' → x_{k+1} where both are
rough (seed 004, Eq. 11), replay first where they are not — undefined where the suffix is longer
than the other prefix leaves (``max_depth`` counts the whole path). Per frame:

``# ---- primary vertices ----``
    x₁ from the jittered G-buffer; emission seen directly is added outside the estimator.
``# ---- supporting prefixes ----`` (Alg. 1 lines 4–6)
    a new prefix by BSDF sampling from x₁, GRIS-merged with the previous frame's supporting
    prefix at the reprojected pixel, shifted here by random replay (|J| = p_src / p_dst; a
    one-bounce prefix reconnects x₁' → x₂ instead, |J| of Eq. 11), with target p̂(x^p) = f_p(x^p)
    (Eq. 19) and the generalized balance heuristic (Eq. 15), the old one favoured by its
    confidence (capped at ``history_cap``). Prefix selection never looks at a suffix (Sec. 6.2);
    ``suffix_in_prefix_target=true`` multiplies the target by the old suffix's p̂ — the
    self-conditioned alternative of Sec. S.1.1, biased, for teaching.
``# ---- temporal suffix reuse ----`` (Alg. 1 lines 8–9)
    a canonical suffix after the supporting prefix, then conditional RIS
    (:func:`conditional_ris`, Eq. 13) between it and the previous suffix shifted to this prefix,
    target p̂_i(x^s) = f_ps f_s (Eq. 20: the suffix path's own m_t f in the domain x_k), MIS the
    conditional generalized balance heuristic (Eq. 15–16) with the supporting prefixes as Z and
    the old suffix's confidence as its domain weight.
``# ---- spatial suffix reuse ----`` (Alg. 1 line 10)
    conditional RIS over the pixel's own suffix (canonical) and ``neighbors`` similar pixels'
    within ``radius``.
``# ---- k-NN grid ----``
    the supporting prefixes' end points x_k go into a uniform spatial hash (``wp.HashGrid``)
    built each frame; the paper searched a BVH. A hash grid is what Warp offers on CPU and CUDA
    alike, is rebuilt in one pass per frame, and a fixed-radius query with the k nearest kept
    is what the gather needs. The radius (``gather_radius`` × scene radius; 0: automatic,
    2 R √(k / pixels), the spacing of k prefixes if the pixels' x_k covered a disc of radius R)
    bounds the search: fewer than k neighbours within it are fewer domains, not bias. The grid
    has :func:`hash_grid_dims` buckets per axis (256 at 1080p) and cells two radii wide: Warp
    folds cells modulo the grid, and an aliased grid made the query most of the gather's time.
``# ---- final gather ----`` (Eq. 22–23, Alg. 1 lines 12–22)
    ``prefixes`` = N new prefixes per pixel. Each one's own walk (the same uniforms) adds the
    light of the paths that end within it — NEE at x₁ … x_{k−1} and emitters hit at x₂ … x_k,
    MIS'd as in ``pt`` (all of the walk's light where no suffix follows) — so that one prefix
    and its suffix are one path-tracer path. Then it borrows the suffixes of its ``gather_k``
    nearest supporting prefixes, shifted to it, each term m_i(Y_i|Z) f(X^p, Y_i) W_{X^p}
    W_{X_i|Z} |T_i'| (:func:`gather_sample`: joint UCW, Thm. 4.1; ``gather_mis=pairwise``:
    :func:`gather_weight_pairwise`, O(k) shifts instead of O(k²)). Every domain has weight
    α = 1 in the gather's MIS (Eq. 15): a borrowed suffix's reservoir confidence (up to
    ``history_cap``) describes its quality *at its own prefix*, not at the integration prefix,
    and weighting by it was measured worse (closed room, 24×18, frame 6: relMSE 0.175 against
    0.068 with α = 1). ``gather_alpha=confidence`` is the prototype's choice (α_j = the borrowed
    reservoir's confidence, capped at ``history_cap``; the canonical domain keeps 1). Which is better
    depends on the scene (this CPU, 96×54, depth 12, mean relMSE of frames 8–15, one seed): on door-ajar
    with the canonical suffix rouletted it lowers relMSE from 0.82 to 0.61. On closed-room it raises it,
    0.125 → 0.170 rouletted and 0.028 → 0.062 traced per prefix.

    **Why the canonical term dominates** (measured on door-ajar, same setting, R = N, frames 8–15). Canonical
    suffixes carry 85% of the gathered suffix light, and 93% of their second moment comes from terms with
    m_c ≥ 0.9, i.e. from paths no borrowed suffix covers. 70% of that share comes from integration prefixes that
    found *no* supporting prefix within the k-NN radius. Supporting prefixes are resampled by f_p and cluster
    where the prefix throughput is high; the integration prefixes are BSDF-sampled and land elsewhere too. The
    rare prefix that slips through the door gap ends next to the light, where its canonical NEE is bright and
    nothing is borrowed. That is the prefix-sampling noise the paper names as future work (Sec. 8, "improving
    importance sampling of integration prefixes"), and roulette multiplies it by N / R. ``gather_widen`` = w
    widens the radius ×4 up to w times for a prefix that found nothing. On this CPU, at w = 2, relMSE × ms
    moved from 75.2 to 74.9 (door-ajar, rouletted) and from 12.1 to 10.3 (closed-room, rouletted: relMSE
    0.125 → 0.083, the frame +28%). Traced per prefix it moved from 31.0 to 30.4 and from 6.6 to 6.3. Off by
    default until measured on a GPU, where a few wide queries hold their warp.

    ``gather_k`` = 1 by default: one borrowed ReSTIR suffix per prefix, the paper's setting (Fig. 3–4
    and 7). The MIS weights include the prefix's own canonical suffix domain. By
    default every prefix traces its canonical suffix (``roulette=false``, the right column of the
    paper's Fig. 4); ``roulette=true`` is Eq. 23 generalized: R = ``canonical_suffixes`` of the N
    prefixes (the paper's R = 1) trace theirs, a cyclic window after one random index per frame for
    every pixel (:func:`roulette_pick`, :func:`roulette_window_holds`; the prefixes are i.i.d., and on
    a GPU the suffixes are then whole passes' coherent work), each weighted N/R
    (:func:`roulette_window_weight`). The default departs from the paper's because the rouletted term's
    variance grows as N/R and dominated our images: relMSE × ms per static frame (H100, 1920×1080,
    k = 1, N = 8) for R = 1, 2, 4, 8 was 196, 108, 65, 44 on door-ajar and 31, 19, 13, 11 on
    closed-room, and 16 prefixes at R = 1 did little better than 8 (one suffix weighted N stays one
    suffix; benchmarks/README, "Suffix ReSTIR's canonical suffixes"). ``canonical=false`` drops the canonical domain: the borrowed
    suffixes no longer cover the suffix space (Eq. 17) — biased, and the tests show it.
    Each prefix j is three launches, a prefix pass (sample it, its walk, fill the pixel's row of
    domains), a suffix pass (its canonical suffix's walk, where traced) and a MIS pass (its Eq. 22
    terms), summed into a running image: no kernel loops over the N prefixes (the one-kernel gather
    faulted on CUDA: benchmarks/README, "The metal-rack fault"), and no walk runs in a kernel that
    holds another stage's state (the support pass is three stages for the same reason; on the GPU
    each split cut the frame by 5–8%, benchmarks/README).

**MMIS baseline** (``mmis-gather``, West et al. 2022 as in seed 001 Fig. 7): no reuse across
pixels or frames; each pixel traces ``prefixes`` prefixes and ``suffixes`` suffixes (after its
first ``suffixes`` prefixes), and every prefix connects to all of them, weighted by the same
conditional balance heuristic, its own canonical domain included (rouletted among the prefixes
that traced none).

**Simplifications** (stated, not hidden):

* prefixes are never rouletted; a suffix's roulette starts at its own x_k (from ``rr_depth`` − 1
  within the suffix, on the suffix's own throughput), pt's on the whole path's: other survival
  probabilities, the same mean;
* the MMIS baseline weighs by targets (the generalized balance heuristic, Eq. 15) rather than
  by source pdfs: a path-tracer suffix kept by RIS over its candidates has no tracked pdf;
* direct light by NEE along the prefix (``direct=nee``) or, as the paper, by ReSTIR DI
  (``direct=restir-di``: :mod:`~grisx.render.restir_di` on the same G-buffer owns the paths
  x₁ → light, as in ReSTIR PT's option; the prefix's NEE walk then starts at two segments).

Temporal reuse evaluates the previous frame's prefixes and suffixes with this frame's geometry
(exact for static scenes, as in ReSTIR PT). The reservoir of a pixel holds a prefix (its x_k
record, f_p, its reservoir) and a suffix path reservoir: ``stats()["reservoir_bytes_per_pixel"]``
reports its size beside ReSTIR PT's.

References: M. Kettunen, D. Lin, R. Ramamoorthi, T. Bashford-Rogers, C. Wyman, "Conditional
Resampled Importance Sampling and ReSTIR", SIGGRAPH Asia 2023 (seed 001), Eq. 13–23, Alg. 1;
D. Lin et al., "Generalized resampled importance sampling", SIGGRAPH 2022; R. West et al.,
"Marginal Multiple Importance Sampling", SIGGRAPH Asia 2022.
"""

from __future__ import annotations

import ctypes
import dataclasses
import math
from typing import Any

import numpy as np
import warp as wp

from grisx.device import SHIFT_REGISTERS, launch, specialized_module
from grisx.errors import InvalidParameterError
from grisx.params import Param
from grisx.render.base.path_shift import (
    CUT_FIRST_BOUNCE,
    CUT_HYBRID,
    DIM_BSDF,
    density_in_range,
    Domain,
    PathReservoir,
    PathSample,
    PathSlots,
    PrefixCut,
    ShiftParams,
    make_path_shift,
    path_dim,
    path_sample_empty,
    path_slot_load,
    path_slot_store,
    path_slots,
    path_target,
    prefix_cut_empty,
    prefix_cut_here,
    segment_measure,
    shift_params,
    vertex_from_hit,
)
from grisx.render.base.registry import RenderMethod, create_renderer, register, renderer_params
from grisx.render.base.reuse import SIMILARITY_DEPTH, SIMILARITY_NORMAL_COS, pixels_similar, spatial_neighbor, temporal_neighbor
from grisx.render.base.screen import ScreenSpaceRenderer, frame_key_of, kernel_cache, pixel_key_of
from grisx.scene.bsdf import make_bsdf
from grisx.scene.frame import frame_from_normal, to_local, to_world
from grisx.scene.gbuffer import GBuffer, GBufferData
from grisx.scene.lights import luminance
from grisx.scene.scene import SceneData, finite_or_dropped, make_surface, spawn_origin
from grisx.theory.conditional import PAIRWISE_TARGET, PROXY_TARGET, make_conditional_ris, roulette_pick, roulette_window_holds, roulette_window_weight
from grisx.theory.gris import resampling_weight, ucw_from_source_pdf
from grisx.theory.mis import target_from, two_domain_balance
from grisx.theory.random import random_subkey, random_uniform
from grisx.theory.reservoir import Reservoir, confidence_capped, reservoir_empty, reservoir_finalize, reservoir_merge, reservoir_update
from grisx.theory.shift import reconnection_jacobian, replay_jacobian

wp.set_module_options({"enable_backward": False})

__all__ = ["Prefix", "SupportReservoir", "SuffixReSTIR", "make_suffix_restir_kernels"]

#: the gather's MIS (Eq. 22): the generalized balance heuristic over all domains (O(k²) shifts per prefix,
#: the paper's), or pairs of each borrowed domain with the canonical one (O(k); grisx.theory.conditional)
GATHER_MIS = {"balance": int(PROXY_TARGET), "pairwise": int(PAIRWISE_TARGET)}
#: a borrowed suffix's domain weight α_j in the gather's MIS (Eq. 15): 1, or its reservoir's confidence (capped)
GATHER_ALPHA = ("one", "confidence")
#: where a prefix ends: the hybrid shift's reconnection rule (the paper's), or always after one bounce (x₂)
PREFIX_RULES = ("hybrid", "bounce")
#: where direct light comes from: NEE at the prefix vertex x₁, or ReSTIR DI on the same G-buffer (restir_pt's choice)
DIRECT_CHOICES = ("nee", "restir-di")
# random streams of a pixel (pixel_key_of)
_STREAM_PREFIX = wp.constant(1)
_STREAM_TEMPORAL = wp.constant(2)
_STREAM_SPATIAL = wp.constant(3)
_STREAM_SUPPORT_SUFFIX = wp.constant(4)  # the supporting canonical suffix's seed (replayed by shifts)
_STREAM_GATHER = wp.constant(5)
_FRAME_STREAM_ROULETTE = wp.constant(2)  # frame_key_of stream: which prefix traces the canonical suffix (every pixel's)
_STREAM_GATHER_PREFIX = wp.constant(1024)  # + j: integration prefix j (and its NEE)
_STREAM_GATHER_SUFFIX = wp.constant(4096)  # + j: integration prefix j's canonical suffix
_STREAM_CHOICES = wp.constant(8192)  # + j: reservoir decisions of prefix j's paths


@wp.struct
class Prefix:
    """A prefix x₁ → … → x_k: its end x_k as the suffix's domain (ω_o toward x_{k−1}; ``valid`` 0: no
    suffix follows), f_p (Π BSDF·|cos|, π-scaled measure as in path_shift), the directions' density,
    the reconnection data of x_k (cos at x_k of the last segment, its length; ``delta``: that segment
    sampled from a delta lobe), its seed ``key`` (replay), ``length`` = k − 1 segments and the
    suffix's budget ``bounces`` (segments after x_k; −1: unbounded)."""

    dom: Domain
    f: wp.vec3
    pdf: float
    cos: float
    dist: float
    delta: int
    key: wp.uint32
    length: int
    bounces: int


@wp.struct
class SupportReservoir:
    """A pixel's reservoir: the supporting prefix and its reservoir (W_{X^p}), the suffix and W_{X^s|Z}."""

    prefix: Prefix
    prefix_res: Reservoir
    suffix: PathReservoir


@wp.struct
class SuffixSpec:
    """What the conditional-RIS hooks read: the scene, the suffix shift's params, and the prefix rule."""

    scene: SceneData
    sp: ShiftParams
    max_bounces: int  # segments after x₁ (−1: unbounded): a prefix of length k − 1 leaves its suffix the rest
    prefix_cut: int  # where a prefix ends: CUT_HYBRID, the first rough pair (sp's thresholds); CUT_FIRST_BOUNCE, at x₂


@wp.struct
class SuffixShift:
    """T(x^s | Z_j → z): the suffix in z's domain, |T'| and whether T was defined (the hooks' record)."""

    x: PathSample
    jacobian: float
    valid: wp.bool


@wp.struct
class PrefixShift:
    """A prefix reconnected to another pixel's x₁: the prefix there, |J| (Eq. 11) and validity."""

    z: Prefix
    jacobian: float
    valid: wp.bool


@wp.struct
class Rows:
    """Per-thread domain rows of conditional RIS (row t: Z_l, X_l, W_{X_l|Z_l}, α_l, p̂_{←l} scratch), one row per pixel."""

    z: wp.array2d(dtype=Prefix)
    x: wp.array2d(dtype=PathSample)
    res: wp.array2d(dtype=Reservoir)
    conf: wp.array2d(dtype=float)
    targets: wp.array2d(dtype=float)


@wp.func
def row_set(rows: Rows, t: int, l: int, z: Prefix, x: PathSample, r: Reservoir, confidence: float):
    """Entry l of row t: domain Z_l with suffix X_l, its reservoir and its domain weight α_l (Eq. 15)."""
    rows.z[t, l] = z
    rows.x[t, l] = x
    rows.res[t, l] = r
    rows.conf[t, l] = confidence


@wp.func
def prefix_empty() -> Prefix:
    p = Prefix()
    p.dom.valid = 0
    p.f = wp.vec3(0.0)
    p.pdf = 0.0
    p.length = 0
    p.bounces = 0
    return p


@wp.func
def prefix_of_cut(c: PrefixCut, key: wp.uint32, max_bounces: int) -> Prefix:
    """The prefix a walk with seed ``key`` cut at ``c`` (none where ``c.end`` is invalid); its suffix may take the segments
    that ``max_bounces`` (after x₁; −1: unbounded) leaves."""
    p = prefix_empty()
    p.key = key
    if c.end.valid == 0:
        return p
    p.dom = c.end
    p.f = c.f
    p.pdf = c.pdf
    p.dist = c.dist
    p.cos = c.cos
    p.delta = c.delta
    p.length = c.length
    p.bounces = -1
    if max_bounces >= 0:
        p.bounces = max_bounces - c.length
    return p


@wp.func
def prefix_target(z: Prefix) -> float:
    """p̂(x^p) = f_p(x^p) (seed 001, Eq. 19; luminance), 0 for no prefix."""
    if z.dom.valid == 0:
        return 0.0
    t = luminance(z.f)
    if t > 0.0:
        return t
    return 0.0


@wp.func
def suffix_target(spec: SuffixSpec, z: Prefix, x: PathSample) -> float:
    """p̂_i(x^s) = f_ps(X_i^p, x^s) f_s(x^s) (seed 001, Eq. 20): the suffix path's m_t f in z's domain x_k."""
    return path_target(x)


@wp.func
def suffix_integrand(spec: SuffixSpec, z: Prefix, x: PathSample) -> float:
    """f(x^p, x^s) = f_p f_ps f_s (Eq. 18), luminance (the gather itself shades RGB: f_p ⊙ x.f)."""
    return luminance(wp.cw_mul(z.f, x.f))


@wp.func
def same_domain(a: Domain, b: Domain) -> wp.bool:
    """Whether two suffix domains are one: the same vertex x_k, seen from the same ω_o (valid)."""
    return (
        a.valid != 0 and b.valid != 0
        and a.p[0] == b.p[0] and a.p[1] == b.p[1] and a.p[2] == b.p[2]
        and a.wo[0] == b.wo[0] and a.wo[1] == b.wo[1] and a.wo[2] == b.wo[2]
    )


@wp.func
def suffix_none() -> PathSample:
    return path_sample_empty()


@kernel_cache
def make_suffix_restir_kernels(kinds: frozenset[int]) -> dict[str, Any]:
    """The passes of Suffix ReSTIR and the MMIS gather for the material kinds ``kinds`` (cached)."""
    shifts = make_path_shift(kinds)
    bsdf = make_bsdf(kinds)
    surface = make_surface(kinds)  # the shapes of these kinds only
    intersect, segment_occluded = surface.intersect, surface.segment_occluded
    path_shift = shifts.shift
    stream_kept = shifts.stream_candidates_kept_bare  # the suffix walk keeps its candidate in memory, not across its rays; no colour estimate (nothing reads it)
    stream_prefix = shifts.stream_prefix  # the gather's walk: its prefix and the light within it, no reservoir
    vertex_material = shifts.vertex_material
    settle = shifts.settle

    @wp.func
    def suffix_shift(spec: SuffixSpec, z_src: Prefix, z_dst: Prefix, x: PathSample) -> SuffixShift:
        """The conditioned shift T(x^s | z_src → z_dst): path_shift's hybrid shift into z_dst's x_k (the source data is in x).

        Undefined where the suffix is longer than z_dst leaves it (max_depth counts the whole path). Into its own domain
        (the same x_k and ω_o: a row's canonical entry, the gather's own canonical suffix) T is the identity, |T'| = 1,
        and no ray is traced.
        """
        out = SuffixShift()
        out.x = x
        out.jacobian = 1.0
        defined = True
        if not same_domain(z_src.dom, z_dst.dom):
            s = path_shift(spec.scene, z_dst.dom, x, spec.sp)
            out.x = s.path
            out.jacobian = s.jacobian
            defined = s.valid
        out.valid = defined and (z_dst.bounces < 0 or x.length <= z_dst.bounces)
        return out

    CRIS = make_conditional_ris(
        SuffixSpec, suffix_target, None, None, suffix_shift, suffix_integrand, prefix_type=Prefix, suffix_type=PathSample, suffix_empty=suffix_none
    )
    module = specialized_module(__name__, kinds)

    @wp.func
    def reconnect_prefix(scene: SceneData, x1: Domain, z: Prefix) -> PrefixShift:
        """The prefix x₁ → x₂ as x₁' → x₂ (|J| of seed 004, Eq. 11); undefined at delta x₁, x₁' or blocked segments."""
        out = PrefixShift()
        out.z = z
        out.jacobian = 0.0
        out.valid = False
        if x1.valid == 0 or z.dom.valid == 0 or z.delta != 0:
            return out
        m = vertex_material(scene, x1.material, x1.uv, x1.tri, x1.p, x1.ns, x1.ng)
        if bsdf.is_delta(m) != 0:
            return out
        dd = z.dom.p - x1.p
        dist = wp.length(dd)
        if dist <= 0.0:
            return out
        d = dd / dist
        frame = frame_from_normal(x1.ns)
        wo_l = to_local(frame, x1.wo)
        wi_l = to_local(frame, d)
        fo = bsdf.eval(m, wo_l, wi_l)
        pdf = bsdf.pdf(m, wo_l, wi_l)
        if wp.length_sq(fo) <= 0.0 or not (pdf > 0.0):
            return out
        if segment_occluded(scene, x1.p, x1.ng, z.dom.p, z.dom.ng):
            return out
        cos_dst = wp.dot(z.dom.ng, -d)
        out.jacobian = reconnection_jacobian(z.cos, cos_dst, z.dist, dist, 3)
        out.z.dom.wo = -d
        out.z.f = fo * segment_measure(0)
        out.z.pdf = pdf * segment_measure(0)
        out.z.cos = cos_dst
        out.z.dist = dist
        out.valid = out.jacobian > 0.0
        return out

    @wp.func
    def sample_prefix(spec: SuffixSpec, x1: Domain, key: wp.uint32) -> Prefix:
        """A prefix from x₁ by BSDF sampling with the path tracer's uniforms (its NEE shares ``key``), no roulette.

        It ends at x_k where :func:`prefix_cut_here` first holds (``spec.prefix_cut``: the second vertex of the first
        pair rougher than the threshold and farther apart than the near field, the hybrid shift's rule, or x₂).
        Invalid (no suffix) where it escapes, fails, or finds no pair within ``max_bounces``: then the NEE walk of
        the gather owns all of that path's light. The gather's own prefixes come from ``stream_prefix``, the same
        walk with that light streamed on the way.
        """
        c = prefix_cut_empty()
        if x1.valid == 0:
            return prefix_of_cut(c, key, spec.max_bounces)
        v = x1
        f = wp.vec3(1.0, 1.0, 1.0)
        pdf = float(1.0)
        i = int(1)
        while spec.max_bounces < 0 or i <= spec.max_bounces:
            m = vertex_material(spec.scene, v.material, v.uv, v.tri, v.p, v.ns, v.ng)
            frame = frame_from_normal(v.ns)
            c_dim = path_dim(i, DIM_BSDF)
            bs = bsdf.sample(m, to_local(frame, v.wo), random_uniform(key, c_dim), wp.vec2(random_uniform(key, c_dim + 1), random_uniform(key, c_dim + 2)))
            if bs.valid == 0 or not (bs.pdf > 0.0):
                break
            s = segment_measure(bs.delta)
            f = wp.cw_mul(f, bs.weight * (bs.pdf * s))
            pdf = pdf * bs.pdf * s
            if not density_in_range(pdf):
                break
            d = wp.normalize(to_world(frame, bs.wi))
            si = intersect(spec.scene, spawn_origin(spec.scene, v.p, v.ng, d), d, 1.0e30)
            if si.valid == 0:
                break  # escaped: its light is the NEE walk's
            dist = wp.length(si.p - v.p)
            if prefix_cut_here(spec.sp, spec.prefix_cut, bsdf.roughness(m), shifts.roughness(spec.scene, si.material), dist):
                c.end = vertex_from_hit(si, -d)
                c.f = f
                c.pdf = pdf
                c.dist = dist
                c.cos = wp.dot(si.ng, v.p - si.p) / dist
                c.delta = bs.delta
                c.length = i
                break
            v = vertex_from_hit(si, -d)
            i += 1
        return prefix_of_cut(c, key, spec.max_bounces)

    @wp.func
    def replay_prefix(spec: SuffixSpec, x1: Domain, z: Prefix) -> PrefixShift:
        """The prefix z replayed from another x₁ (its seed; |J| = p_src / p_dst, Lin et al. 2022 Sec. 7.1); undefined where the
        replayed prefix has another length (T stays a bijection)."""
        out = PrefixShift()
        out.z = sample_prefix(spec, x1, z.key)
        out.jacobian = 0.0
        out.valid = False
        if z.dom.valid != 0 and out.z.dom.valid != 0 and out.z.length == z.length:
            out.jacobian = replay_jacobian(z.pdf, out.z.pdf)
            out.valid = out.jacobian > 0.0
        return out

    @wp.func
    def shift_prefix(spec: SuffixSpec, x1: Domain, z: Prefix) -> PrefixShift:
        """The supporting prefix's shift into another pixel: reconnection x₁' → x₂ for one-bounce prefixes, replay for the hybrid rule's."""
        if spec.prefix_cut == CUT_HYBRID:
            return replay_prefix(spec, x1, z)
        return reconnect_prefix(spec.scene, x1, z)

    @wp.func
    def trace_suffix(
        spec: SuffixSpec, z: Prefix, key: wp.uint32, ukey: wp.uint32, kept: PathSlots, ky: int, kx: int
    ) -> PathReservoir:
        """A canonical suffix after z (Alg. 1 line 8): one path-tracer path from x_k, one candidate kept by RIS, confidence 1.

        The walk writes the candidate it keeps into the pixel's slot (ky, kx) of ``kept`` as ReSTIR PT's initial pass
        does, instead of carrying a 32-word path across its rays (where it spilled)."""
        pr = PathReservoir()
        pr.res = reservoir_empty()
        pr.path = path_sample_empty()
        pr.estimate = wp.vec3(0.0)
        if z.dom.valid == 0 or z.bounces == 0:
            return pr
        path_slot_store(kept, ky, kx, path_sample_empty())  # what the walk leaves there where it keeps nothing
        pr = stream_kept(spec.scene, z.dom, key, z.bounces, 1.0, spec.sp, pr, ukey, kept, ky, kx)
        pr.path = path_slot_load(kept, ky, kx)
        pr = settle(spec.scene, z.dom, pr, spec.sp)
        pr.res.confidence = 1.0
        return pr

    @wp.func
    def with_target_of_suffix(spec: SuffixSpec, t: float, z: Prefix, old: SupportReservoir) -> float:
        """The self-conditioned prefix target f_p · p̂(old suffix | z) (seed 001, Sec. S.1.1; biased)."""
        s = suffix_shift(spec, old.prefix, z, old.suffix.path)
        if not s.valid:
            return 0.0
        return t * path_target(s.x)

    # ---- primary vertices ----
    @wp.kernel(module=module)
    def primary_pass(g: GBufferData, domains: wp.array2d(dtype=Domain), direct: wp.array2d(dtype=wp.vec3)):
        y, x = wp.tid()
        domains[y, x] = vertex_from_hit(g.si[y, x], g.wo[y, x])
        direct[y, x] = g.emission[y, x]

    # ---- supporting prefixes, then temporal suffix reuse ----
    # Three stages, each its own kernel so that none holds another's state across a walk (where it spilled): the
    # supporting prefix and its temporal GRIS; the canonical suffix's walk; the temporal conditional RIS of suffixes.
    # ``temporal_src`` carries the one fact the last stage needs from the first: the history pixel whose suffix it
    # reuses (−1: none).
    def make_support_prefix_pass(suffix_in_prefix_target: bool) -> Any:
        # the biased ablation's prefix target (four suffix shifts) in a module of its own: compiled only when asked for,
        # and absent from the default kernel
        prefix_module = specialized_module(__name__ + ".prefix_target", kinds) if suffix_in_prefix_target else module

        @wp.kernel(module=prefix_module, cuda_max_registers=SHIFT_REGISTERS)
        def support_prefix_pass(
            spec: SuffixSpec,
            seed: int,
            frame: int,
            history_valid: int,
            history_cap: float,
            temporal_suffix: int,
            g: GBufferData,
            g_prev: GBufferData,
            domains: wp.array2d(dtype=Domain),
            domains_prev: wp.array2d(dtype=Domain),
            history: wp.array2d(dtype=SupportReservoir),
            out: wp.array2d(dtype=SupportReservoir),
            temporal_src: wp.array2d(dtype=int),
        ):
            y, x = wp.tid()
            width = domains.shape[1]
            dom_i = domains[y, x]
            ukey = pixel_key_of(seed, frame, x, y, width, _STREAM_TEMPORAL)
            # the canonical prefix x₁ → … → x_k (Alg. 1 line 4), W = 1/p
            z_can = sample_prefix(spec, dom_i, pixel_key_of(seed, frame, x, y, width, _STREAM_PREFIX))
            r = reservoir_empty()
            z = z_can
            have_prev = int(0)
            nb = temporal_neighbor(g, g_prev, x, y, SIMILARITY_NORMAL_COS, SIMILARITY_DEPTH)
            if history_valid != 0 and dom_i.valid != 0:
                if nb.valid != 0:
                    if domains_prev[nb.y, nb.x].valid != 0 and history[nb.y, nb.x].prefix_res.confidence > 0.0 and history[nb.y, nb.x].prefix.dom.valid != 0:
                        have_prev = 1
            t_c = prefix_target(z_can)
            if have_prev != 0:
                # ---- temporal prefix reuse: GRIS, target f_p (Eq. 19), generalized balance MIS (Eq. 15) ----
                # the old reservoir is read from memory where it is used: a 73-word record held across the two prefix
                # shifts spilled (sm_90, 128 registers)
                dom_j = domains_prev[nb.y, nb.x]
                c_j = confidence_capped(history[nb.y, nb.x].prefix_res.confidence, history_cap)
                t_old = prefix_target(history[nb.y, nb.x].prefix)
                s_cj = shift_prefix(spec, dom_j, z_can)  # the canonical prefix in the old pixel
                s_t = shift_prefix(spec, dom_i, history[nb.y, nb.x].prefix)  # the old prefix in this pixel
                t_cj = float(0.0)
                t_ti = float(0.0)
                t_tj = float(0.0)
                if s_cj.valid:
                    t_cj = target_from(prefix_target(s_cj.z), s_cj.jacobian)  # seed 001, Eq. 16
                if s_t.valid:
                    t_ti = prefix_target(s_t.z)
                    t_tj = target_from(t_old, 1.0 / s_t.jacobian)
                if wp.static(suffix_in_prefix_target):
                    # the biased alternative: the prefixes' targets read the old suffix (Sec. S.1.1)
                    t_c = with_target_of_suffix(spec, t_c, z_can, history[nb.y, nb.x])
                    t_ti = with_target_of_suffix(spec, t_ti, s_t.z, history[nb.y, nb.x])
                    t_cj = with_target_of_suffix(spec, t_cj, s_cj.z, history[nb.y, nb.x])
                    t_tj = with_target_of_suffix(spec, t_tj, history[nb.y, nb.x].prefix, history[nb.y, nb.x])
                m_c = two_domain_balance(1.0, t_c, c_j, t_cj)
                m_t = two_domain_balance(c_j, t_tj, 1.0, t_ti)
                r = reservoir_update(r, resampling_weight(m_c, t_c, ucw_from_source_pdf(z_can.pdf), 1.0), t_c, 1.0, random_uniform(ukey, 0))
                other = history[nb.y, nb.x].prefix_res
                other.confidence = c_j
                r = reservoir_merge(r, other, m_t, t_ti, s_t.jacobian, random_uniform(ukey, 1))  # seed 000, Eq. 9
                if r.selected:
                    z = s_t.z
                r = reservoir_finalize(r)
                if r.ucw <= 0.0:
                    z = z_can  # nothing kept: the supporting prefix is still the new one (its UCW is 0)
            else:
                r.ucw = ucw_from_source_pdf(z_can.pdf)
                r.confidence = 1.0
                r.target = t_c
            out[y, x].prefix = z
            out[y, x].prefix_res = r
            src = int(-1)
            if have_prev != 0 and temporal_suffix != 0 and z.dom.valid != 0:
                src = nb.y * width + nb.x
            temporal_src[y, x] = src

        return support_prefix_pass

    @wp.kernel(module=module, cuda_max_registers=SHIFT_REGISTERS)
    def support_suffix_pass(
        spec: SuffixSpec, seed: int, frame: int, kept: PathSlots, out: wp.array2d(dtype=SupportReservoir)
    ):
        """The canonical suffix after the supporting prefix (Alg. 1 line 8)."""
        y, x = wp.tid()
        skey = pixel_key_of(seed, frame, x, y, out.shape[1], _STREAM_SUPPORT_SUFFIX)
        out[y, x].suffix = trace_suffix(spec, out[y, x].prefix, skey, random_subkey(skey, 1), kept, y, x)

    @wp.kernel(module=module, cuda_max_registers=SHIFT_REGISTERS)
    def support_temporal_pass(
        spec: SuffixSpec,
        seed: int,
        frame: int,
        history_cap: float,
        history: wp.array2d(dtype=SupportReservoir),
        temporal_src: wp.array2d(dtype=int),
        rows: Rows,
        out: wp.array2d(dtype=SupportReservoir),
    ):
        """Temporal suffix reuse: conditional RIS between the canonical and the old suffix (Alg. 1 lines 8–9)."""
        y, x = wp.tid()
        src = temporal_src[y, x]
        if src < 0:
            return
        width = out.shape[1]
        t = y * width + x
        ukey = pixel_key_of(seed, frame, x, y, width, _STREAM_TEMPORAL)
        cur = out[y, x]
        old = history[src // width, src % width]
        row_set(rows, t, 0, cur.prefix, cur.suffix.path, cur.suffix.res, 1.0)
        # old suffixes weigh more: their confidence (capped) is their domain weight
        row_set(rows, t, 1, old.prefix, old.suffix.path, old.suffix.res, confidence_capped(old.suffix.res.confidence, history_cap))
        # the two reservoirs are read back where they are needed, not held across the row's shifts (73 words each)
        cr = CRIS.conditional_ris(spec, out[y, x].prefix, 0, rows.z[t], rows.x[t], rows.res[t], rows.conf[t], rows.targets[t], ukey, 2)
        res = cr.reservoir
        res.confidence = confidence_capped(cr.reservoir.confidence, history_cap)
        out[y, x].suffix.res = res
        out[y, x].suffix.path = cr.y

    # ---- spatial suffix reuse ----
    @wp.kernel(module=module, cuda_max_registers=SHIFT_REGISTERS)
    def spatial_pass(
        spec: SuffixSpec,
        seed: int,
        frame: int,
        neighbors: int,
        radius: float,
        history_cap: float,
        g: GBufferData,
        domains: wp.array2d(dtype=Domain),
        inp: wp.array2d(dtype=SupportReservoir),
        rows: Rows,
        out: wp.array2d(dtype=SupportReservoir),
    ):
        y, x = wp.tid()
        width = domains.shape[1]
        t = y * width + x
        own = inp[y, x]
        if domains[y, x].valid == 0 or own.prefix.dom.valid == 0:
            out[y, x] = own
            return
        ukey = pixel_key_of(seed, frame, x, y, width, _STREAM_SPATIAL)
        row_set(rows, t, 0, own.prefix, own.suffix.path, own.suffix.res, own.suffix.res.confidence)
        found = int(0)
        for q in range(neighbors):
            nb = spatial_neighbor(x, y, width, domains.shape[0], radius, wp.vec2(random_uniform(ukey, 2 * q), random_uniform(ukey, 2 * q + 1)))
            l = q + 1
            # an empty domain (no prefix, confidence 0) where no similar neighbour was drawn: it weighs nothing (each
            # entry written once, as in the gather)
            drawn = bool(False)
            if nb.valid != 0:
                if domains[nb.y, nb.x].valid != 0 and inp[nb.y, nb.x].prefix.dom.valid != 0 and pixels_similar(g, x, y, g, nb.x, nb.y, SIMILARITY_NORMAL_COS, SIMILARITY_DEPTH):
                    drawn = True
            if drawn:
                other = inp[nb.y, nb.x]
                row_set(rows, t, l, other.prefix, other.suffix.path, other.suffix.res, other.suffix.res.confidence)
                found += 1
            else:
                row_set(rows, t, l, prefix_empty(), path_sample_empty(), reservoir_empty(), 0.0)
        if found == 0:
            out[y, x] = inp[y, x]
            return
        # only the suffix changes; nothing of the pixel's reservoir is held across the row's shifts (73 words): the rest
        # is read again after them, and each word of out written once
        cr = CRIS.conditional_ris(spec, inp[y, x].prefix, 0, rows.z[t], rows.x[t], rows.res[t], rows.conf[t], rows.targets[t], ukey, 2 * neighbors)
        res = cr.reservoir
        res.confidence = confidence_capped(cr.reservoir.confidence, history_cap)
        out[y, x].prefix = inp[y, x].prefix
        out[y, x].prefix_res = inp[y, x].prefix_res
        out[y, x].suffix.estimate = inp[y, x].suffix.estimate
        out[y, x].suffix.res = res
        out[y, x].suffix.path = cr.y

    # ---- k-NN grid ----
    @wp.kernel(module=module)
    def points_pass(support: wp.array2d(dtype=SupportReservoir), points: wp.array(dtype=wp.vec3)):
        y, x = wp.tid()
        z = support[y, x].prefix
        p = wp.vec3(1.0e20, 1.0e20, 1.0e20)  # no prefix: far from every query (and checked again there)
        if z.dom.valid != 0:
            p = z.dom.p
        points[y * support.shape[1] + x] = p

    @wp.func
    def knn(
        grid: wp.uint64,
        p: wp.vec3,
        radius: float,
        k: int,
        points: wp.array(dtype=wp.vec3),
        idx: wp.array(dtype=int),
        dist: wp.array(dtype=float),
    ) -> int:
        """The ≤ k supporting prefixes whose x_k are nearest to ``p`` within ``radius`` (FindSpatialKNN), sorted, in ``idx``.

        Reads the grid's own point array (12 bytes a candidate; a pixel without a prefix sits at 1e20, out of every
        radius), not the support records.
        """
        count = int(0)
        query = wp.hash_grid_query(grid, p, radius)
        j = int(0)
        while wp.hash_grid_query_next(query, j):
            d = wp.length(points[j] - p)
            if d <= radius and (count < k or d < dist[k - 1]):
                # insertion into the sorted list (ties keep the earlier index: deterministic)
                pos = wp.min(count, k - 1)
                while pos > 0 and dist[pos - 1] > d:
                    if pos < k:
                        dist[pos] = dist[pos - 1]
                        idx[pos] = idx[pos - 1]
                    pos -= 1
                dist[pos] = d
                idx[pos] = j
                if count < k:
                    count += 1
        return count

    # ---- final gather ----
    # Three launches per integration prefix j (the passes of Eq. 22 over j = 0 … N−1): the
    # prefix pass samples prefix j, adds its walk's light and fills the pixel's row; the suffix
    # pass traces its canonical suffix; the MIS pass adds its Eq. 22 terms. Splitting the loop over j out of the kernel keeps each kernel
    # small. The single-kernel gather (255 registers, 3.3 kB of stack) faulted on H100 and H200
    # (metal-rack, mmis-gather): a row store's address was built from uniform registers that
    # held kernel int params written by diverged lanes — a code-generation fault, measured with
    # cuda-gdb; see benchmarks/README "The metal-rack fault".
    @wp.func
    def gather_chosen(seed: int, frame: int, prefixes: int, own_suffixes: int) -> int:
        """The first prefix that traces its canonical suffix (Eq. 23; the window of ``kept`` prefixes starts there), one
        index for every pixel of the frame; with own suffixes (MMIS) the first ones always do.

        A pixel's N prefixes are i.i.d., so which index traces does not change the estimator's law, nor the joint
        law of the pixels: a per-pixel index is as unbiased and no better. One index per frame makes the suffix
        trace one pass's work for every pixel, where a per-pixel index had almost every 32-pixel warp of a GPU
        trace a suffix in every pass (1 − (7/8)³² ≈ 99% at N = 8; Alg. 1 traces it with the first prefix).
        """
        return own_suffixes + roulette_pick(random_uniform(frame_key_of(seed, frame, _FRAME_STREAM_ROULETTE), 0), wp.max(prefixes - own_suffixes, 1))

    @wp.func
    def gather_traced(j: int, chosen: int, prefixes: int, own_suffixes: int, kept: int, canonical: int) -> wp.bool:
        """Whether prefix j has its canonical suffix domain (α = 0 without it: canonical=false, biased): one of the ``kept``
        after ``chosen`` (cyclic over the prefixes after the own suffixes)."""
        if canonical == 0:
            return False
        if j < own_suffixes:
            return True
        return roulette_window_holds(j - own_suffixes, chosen - own_suffixes, kept, wp.max(prefixes - own_suffixes, 1))

    @wp.kernel(module=module, cuda_max_registers=SHIFT_REGISTERS)
    def gather_prefix_pass(
        spec: SuffixSpec,
        full_sp: ShiftParams,
        seed: int,
        frame: int,
        j: int,
        prefixes: int,
        gather_k: int,
        own_suffixes: int,
        kept: int,
        canonical: int,
        alpha_cap: float,
        max_bounces: int,
        grid: wp.uint64,
        grid_radius: float,
        widen: int,
        domains: wp.array2d(dtype=Domain),
        direct: wp.array2d(dtype=wp.vec3),
        support: wp.array2d(dtype=SupportReservoir),
        points: wp.array(dtype=wp.vec3),
        own_z: wp.array2d(dtype=Prefix),
        own_x: wp.array2d(dtype=PathSample),
        own_res: wp.array2d(dtype=Reservoir),
        knn_idx: wp.array2d(dtype=int),
        knn_dist: wp.array2d(dtype=float),
        rows: Rows,
        accum: wp.array2d(dtype=wp.vec3),
    ):
        y, x = wp.tid()
        width = domains.shape[1]
        t = y * width + x
        dom = domains[y, x]
        L = accum[y, x]
        if j == 0:
            L = direct[y, x]
        # entry 0 holds the integration prefix for the MIS pass; none (invalid) makes it skip the pixel. Each entry is
        # written once: a field-by-field store of a row's records (some 70 words at a row's stride) costs a GPU a memory
        # transaction per field and lane
        if dom.valid == 0:
            row_set(rows, t, 0, prefix_empty(), path_sample_empty(), reservoir_empty(), 0.0)
            accum[y, x] = L
            return
        gkey = pixel_key_of(seed, frame, x, y, width, _STREAM_GATHER)
        pkey = random_subkey(gkey, _STREAM_GATHER_PREFIX + j)
        # ---- the prefix, and the light of the paths that end within it: NEE at x₁ … x_{k−1}, emitters hit at x₂ … x_k ----
        # (MIS'd as pt; one walk, sample_prefix's directions: without a suffix, the whole path is the walk's)
        d = PathReservoir()
        d.res = reservoir_empty()
        d.path = path_sample_empty()
        d.estimate = wp.vec3(0.0)
        walk = stream_prefix(spec.scene, dom, pkey, max_bounces, 1.0, full_sp, d, random_subkey(gkey, _STREAM_CHOICES + j), spec.sp, spec.prefix_cut)
        z = prefix_of_cut(walk.cut, pkey, spec.max_bounces)
        L += walk.pr.estimate * (1.0 / float(prefixes))  # Σ f/p over its candidates
        accum[y, x] = L
        if z.dom.valid == 0 or z.bounces == 0:
            row_set(rows, t, 0, prefix_empty(), path_sample_empty(), reservoir_empty(), 0.0)
            return
        # entry 0: the prefix's own (canonical) suffix domain, α = 0 without it (canonical=false, biased). A traced
        # canonical suffix is gather_suffix_pass's walk, after this pass, which writes the rest of the entry; MMIS's own
        # ones are here already
        if j < own_suffixes and canonical != 0:
            row_set(rows, t, 0, z, own_x[t, j], own_res[t, j], 1.0)
        elif j >= own_suffixes and gather_traced(j, gather_chosen(seed, frame, prefixes, own_suffixes), prefixes, own_suffixes, kept, canonical):
            rows.z[t, 0] = z
        else:
            row_set(rows, t, 0, z, path_sample_empty(), reservoir_empty(), float(canonical))
        # entries 1 … k: the suffixes of the k nearest supporting prefixes (Alg. 1 lines 14–15)
        found = int(0)
        if gather_k > 0:
            found = knn(grid, z.dom.p, grid_radius, gather_k, points, knn_idx[t], knn_dist[t])
            r_wide = grid_radius
            for _w in range(widen):
                if found == 0:
                    r_wide = r_wide * 4.0
                    found = knn(grid, z.dom.p, r_wide, gather_k, points, knn_idx[t], knn_dist[t])
        for l in range(gather_k):
            if l < found:
                q = knn_idx[t, l]
                s = support[q // width, q % width]
                alpha = float(1.0)  # α = 1, or the reservoir's confidence (capped): see the module docstring
                if alpha_cap > 0.0:
                    alpha = confidence_capped(s.suffix.res.confidence, alpha_cap)
                row_set(rows, t, 1 + l, s.prefix, s.suffix.path, s.suffix.res, alpha)
            else:
                row_set(rows, t, 1 + l, prefix_empty(), path_sample_empty(), reservoir_empty(), 0.0)
        # entries after: the pixel's own suffixes (MMIS), the prefix's own one left empty (it is entry 0)
        for l in range(own_suffixes):
            e = 1 + gather_k + l
            if l != j:
                row_set(rows, t, e, own_z[t, l], own_x[t, l], own_res[t, l], 1.0)
            else:
                row_set(rows, t, e, prefix_empty(), path_sample_empty(), reservoir_empty(), 0.0)

    @wp.kernel(module=module, cuda_max_registers=SHIFT_REGISTERS)
    def gather_suffix_pass(
        spec: SuffixSpec, seed: int, frame: int, j: int, prefixes: int, own_suffixes: int, kept: int, canonical: int, width: int, rows: Rows,
        kept_path: PathSlots,
    ):
        """Prefix j's canonical suffix (Eq. 22's canonical input), traced where the window of Eq. 23 holds j: a kernel
        of its own, so that the walk does not hold the prefix pass's state (the row, the k-NN lists) where it spilled."""
        y, x = wp.tid()
        if j < own_suffixes or not gather_traced(j, gather_chosen(seed, frame, prefixes, own_suffixes), prefixes, own_suffixes, kept, canonical):
            return
        t = y * width + x
        z = rows.z[t, 0]
        if z.dom.valid == 0 or z.bounces == 0:
            return
        skey = random_subkey(pixel_key_of(seed, frame, x, y, width, _STREAM_GATHER), _STREAM_GATHER_SUFFIX + j)
        c = trace_suffix(spec, z, skey, random_subkey(skey, 1), kept_path, y, x)
        rows.x[t, 0] = c.path
        rows.res[t, 0] = c.res
        rows.conf[t, 0] = 1.0

    @wp.kernel(module=module, cuda_max_registers=SHIFT_REGISTERS)
    def gather_mis_pass(
        spec: SuffixSpec,
        seed: int,
        frame: int,
        j: int,
        prefixes: int,
        own_suffixes: int,
        kept: int,
        canonical: int,
        mis_mode: int,
        rows: Rows,
        accum: wp.array2d(dtype=wp.vec3),
    ):
        y, x = wp.tid()
        width = accum.shape[1]
        t = y * width + x
        z = rows.z[t, 0]
        if z.dom.valid == 0 or z.bounces == 0:
            return
        chosen = gather_chosen(seed, frame, prefixes, own_suffixes)
        traced = gather_traced(j, chosen, prefixes, own_suffixes, kept, canonical)
        inv_n = 1.0 / float(prefixes)
        w_prefix = ucw_from_source_pdf(z.pdf)
        L = accum[y, x]
        # ---- Eq. 22 for this prefix: borrowed suffixes l = 1 … k, then the (rouletted) canonical one, l = 0 ----
        # one loop, so that gather_sample (shifts and the MIS sums over the domains) is inlined once, not twice
        domains = rows.conf.shape[1]
        for step in range(1, domains + 1):
            l = step % domains  # the canonical domain last
            rw = float(1.0)  # the canonical term's roulette weight
            due = rows.conf[t, l] > 0.0
            if l == 0:
                due = traced
                if j >= own_suffixes:
                    rw = roulette_window_weight(True, kept, prefixes - own_suffixes)  # N/R (Eq. 23: N)
            if due:
                gw = CRIS.gather_sample(spec, mis_mode, z, w_prefix, l, 0, rows.z[t], rows.x[t], rows.res[t], rows.conf[t], rows.targets[t])
                if gw.weight > 0.0:
                    L += wp.cw_mul(z.f, gw.y.f) * (gw.weight * rw * inv_n)  # f(X^p, Y_l) m_l W_{X^p,Y_l} / N (× N/R)
        accum[y, x] = L

    @wp.kernel(module=module)
    def gather_finish_pass(accum: wp.array2d(dtype=wp.vec3), image: wp.array2d(dtype=wp.vec3), nonfinite: wp.array(dtype=wp.int32)):
        y, x = wp.tid()
        image[y, x] = finite_or_dropped(accum[y, x], nonfinite)

    # ---- MMIS: the pixel's own prefixes and suffixes ----
    @wp.kernel(module=module, cuda_max_registers=SHIFT_REGISTERS)
    def own_suffix_pass(
        spec: SuffixSpec,
        seed: int,
        frame: int,
        domains: wp.array2d(dtype=Domain),
        kept: PathSlots,
        own_z: wp.array2d(dtype=Prefix),
        own_x: wp.array2d(dtype=PathSample),
        own_res: wp.array2d(dtype=Reservoir),
    ):
        y, x = wp.tid()
        width = domains.shape[1]
        t = y * width + x
        gkey = pixel_key_of(seed, frame, x, y, width, _STREAM_GATHER)
        for j in range(own_z.shape[1]):
            # prefix j is the gather's prefix j (same key): its suffix is traced once, here
            z = sample_prefix(spec, domains[y, x], random_subkey(gkey, _STREAM_GATHER_PREFIX + j))
            own_z[t, j] = z  # stored before the suffix's walk: what the walk does not read is not held across it
            skey = random_subkey(gkey, _STREAM_GATHER_SUFFIX + j)
            c = trace_suffix(spec, z, skey, random_subkey(skey, 1), kept, y, x)
            own_x[t, j] = c.path
            own_res[t, j] = c.res

    return {
        "primary": primary_pass,
        "support_prefix": make_support_prefix_pass(False),
        "support_prefix_suffix_target": make_support_prefix_pass(True),
        "support_suffix": support_suffix_pass,
        "support_temporal": support_temporal_pass,
        "spatial": spatial_pass,
        "points": points_pass,
        "gather_prefix": gather_prefix_pass,
        "gather_suffix": gather_suffix_pass,
        "gather_mis": gather_mis_pass,
        "gather_finish": gather_finish_pass,
        "own": own_suffix_pass,
    }


def hash_grid_dims(points: int) -> int:
    """Buckets per axis of the k-NN hash grid for ``points`` supporting prefixes: ∛(8 · points) as a power of two in [32, 256].

    Warp's hash grid folds cell coordinates modulo its size, so a grid smaller than the scene in
    cells makes every query scan the points of aliased cells. Measured at 1920×1080 (H200,
    closed-room, N = 8, k = 4): the gather's prefix pass takes 2066 ms with 64³ buckets, 781 ms
    with 128³ and 453 ms with 256³ (the same image); 256³ costs 134 MB, the cap. Cells two query
    radii wide fold less and are scanned 2³ at a time instead of 3³: 380 ms at 256³ (3 radii: 434).
    """
    return int(min(256, max(32, 2 ** math.ceil(math.log2(max(8 * points, 1)) / 3))))


def _rows(n: int, width: int, device: Any) -> Rows:
    """``n`` rows of ``width`` domains (one per pixel), zeroed: empty domains of confidence 0."""
    rows = Rows()
    rows.z = wp.zeros((n, width), dtype=Prefix, device=device)
    rows.x = wp.zeros((n, width), dtype=PathSample, device=device)
    rows.res = wp.zeros((n, width), dtype=Reservoir, device=device)
    rows.conf = wp.zeros((n, width), dtype=float, device=device)
    rows.targets = wp.zeros((n, width), dtype=float, device=device)
    return rows


def _struct_bytes(struct: Any) -> int:
    return int(ctypes.sizeof(struct.ctype))


class SuffixReSTIR(ScreenSpaceRenderer):
    """Suffix ReSTIR (and, with ``suffixes`` > 0 and no reuse, the MMIS gather) over a built scene (see the module docstring)."""

    def __init__(
        self,
        built: Any,
        width: int,
        height: int,
        *,
        prefixes: int = 8,
        gather_k: int = 1,
        gather_radius: float = 0.0,
        gather_widen: int = 0,
        roulette: bool = False,
        canonical_suffixes: int = 1,
        canonical: bool = True,
        gather_mis: str = "balance",
        gather_alpha: str = "one",
        prefix: str = "hybrid",
        temporal: bool = True,
        spatial: bool = True,
        suffix_in_prefix_target: bool = False,
        suffixes: int = 0,
        shift: str = "hybrid",
        max_depth: int = 16,
        rr_depth: int = 5,
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
        if prefix not in PREFIX_RULES:
            raise InvalidParameterError(f"prefix must be one of {', '.join(PREFIX_RULES)}, not '{prefix}'")
        if gather_mis not in GATHER_MIS:
            raise InvalidParameterError(f"gather_mis must be one of {', '.join(GATHER_MIS)}, not '{gather_mis}'")
        if gather_alpha not in GATHER_ALPHA:
            raise InvalidParameterError(f"gather_alpha must be one of {', '.join(GATHER_ALPHA)}, not '{gather_alpha}'")
        if prefixes < 1 or gather_k < 0 or gather_radius < 0.0 or suffixes < 0 or suffixes > prefixes:
            raise InvalidParameterError("suffix-restir needs prefixes >= 1, gather_k >= 0, gather_radius >= 0 and 0 <= suffixes <= prefixes")
        if max_depth == 0 or max_depth < -1 or rr_depth < 1 or neighbors < 0 or radius <= 0.0:
            raise InvalidParameterError("suffix-restir needs max_depth -1 or >= 1, rr_depth >= 1, neighbors >= 0, radius > 0")
        self.built = built
        self.width, self.height = int(width), int(height)
        self.prefixes, self.gather_k, self.suffixes = int(prefixes), int(gather_k), int(suffixes)
        self.roulette, self.canonical = bool(roulette), bool(canonical)
        if canonical_suffixes < 1:
            raise InvalidParameterError(f"canonical_suffixes must be >= 1, not {canonical_suffixes}")
        # R of the N − (own suffixes) prefixes trace their canonical suffix, each weighted N/R; no roulette: all of them
        self.kept = max(self.prefixes - self.suffixes, 1)
        if self.roulette:
            self.kept = min(int(canonical_suffixes), self.kept)
        self.mis_mode = GATHER_MIS[gather_mis]
        # a borrowed suffix's α: 1 (alpha_cap 0), or its confidence capped at the history cap
        self.alpha_cap = 0.0 if gather_alpha == "one" else (float(history_cap) if history_cap > 0.0 else 1.0e30)
        self.temporal, self.spatial = bool(temporal), bool(spatial)
        self.suffix_in_prefix_target = bool(suffix_in_prefix_target)
        # the biased prefix target is a kernel of its own (make_suffix_restir_kernels)
        self._support_prefix = "support_prefix_suffix_target" if self.suffix_in_prefix_target else "support_prefix"
        self.neighbors, self.radius, self.history_cap = int(neighbors), float(radius), float(history_cap)
        self.jitter = bool(jitter)
        self.seed = int(seed)
        self.timer = timer
        # segments after x₁ (-1 unbounded); a suffix gets what its prefix leaves (Prefix.bounces)
        self.max_bounces = -1 if max_depth < 0 else int(max_depth) - 1
        near = float(near_field) * float(built.data.scene_radius)
        common = dict(rough_threshold=rough_threshold, near_distance=near, jacobian_max=max_jacobian, jacobian=jacobian)
        # the prefix's NEE walk (pt's); with ReSTIR DI it starts at two segments (DI owns x₁ → light)
        self.full_sp = shift_params(shift, rr_depth=rr_depth, min_bounces=2 if direct == "restir-di" else 1, **common)
        self.spec = SuffixSpec()
        self.spec.scene = built.data
        self.spec.sp = shift_params(shift, rr_depth=max(int(rr_depth) - 1, 1), **common)  # roulette counted from the suffix's own x_k
        self.spec.max_bounces = self.max_bounces
        self.spec.prefix_cut = CUT_HYBRID if prefix == "hybrid" else CUT_FIRST_BOUNCE
        n = self.width * self.height
        self.gather_widen = int(gather_widen)
        self.grid_radius = float(gather_radius) * float(built.data.scene_radius)
        if self.grid_radius <= 0.0:
            self.grid_radius = 2.0 * float(built.data.scene_radius) * math.sqrt(max(self.gather_k, 1) / n)
        self.k = make_suffix_restir_kernels(built.features.kernel_kinds)
        dev = built.device
        shape = (self.height, self.width)
        self.di = None
        if direct == "restir-di":
            # ReSTIR DI owns the paths x₁ → light (as in restir_pt): the same G-buffer, its own random streams
            from grisx.render.base.registry import METHODS, RenderContext

            self.di = METHODS["restir-di"].create(RenderContext(built, width, height, {"jitter": jitter}, self.seed + 7919, timer, "restir-di"))
            self.gbuffer = self.di.gbuffer
        else:
            self.gbuffer = GBuffer(self.width, self.height, dev, material=self.GBUFFER_MATERIAL)
        self.domains = [wp.zeros(shape, dtype=Domain, device=dev) for _ in range(2)]  # current, previous
        self.buffers = [wp.zeros(shape, dtype=SupportReservoir, device=dev) for _ in range(3)]  # 0: history, 1–2: scratch
        # one row width per pass: conditional RIS and the MIS read every entry of a row
        self.rows = {name: _rows(n, width, dev) for name, width in (("temporal", 2), ("spatial", 1 + self.neighbors), ("gather", 1 + self.gather_k + self.suffixes))}
        own = max(self.suffixes, 1)
        self.own_z = wp.zeros((n, own), dtype=Prefix, device=dev)
        self.own_x = wp.zeros((n, own), dtype=PathSample, device=dev)
        self.own_res = wp.zeros((n, own), dtype=Reservoir, device=dev)
        self.suffix_kept = path_slots(self.height, self.width, dev)  # each suffix walk's kept candidate (scratch)
        self.knn_idx = wp.zeros((n, max(self.gather_k, 1)), dtype=int, device=dev)
        self.knn_dist = wp.zeros((n, max(self.gather_k, 1)), dtype=float, device=dev)
        self.points = wp.zeros(n, dtype=wp.vec3, device=dev)
        self.temporal_src = wp.zeros(shape, dtype=int, device=dev)  # the history pixel whose suffix a pixel reuses (−1: none)
        self.grid = wp.HashGrid(*(hash_grid_dims(n),) * 3, device=dev)
        self.direct = wp.zeros(shape, dtype=wp.vec3, device=dev)
        self.accum = wp.zeros(shape, dtype=wp.vec3, device=dev)  # the gather's running sum over its prefixes
        self.image = wp.zeros(shape, dtype=wp.vec3, device=dev)
        self.nonfinite = wp.zeros(1, dtype=wp.int32, device=dev)
        self.frames_rendered = 0

    @property
    def reuses(self) -> bool:
        """Whether supporting reservoirs are built (no: the MMIS gather, which borrows only its own suffixes)."""
        return self.gather_k > 0

    def kernels(self) -> list[Any]:
        unused = "support_prefix" if self.suffix_in_prefix_target else "support_prefix_suffix_target"
        return [kern for name, kern in self.k.items() if name != unused]

    def statistics(self) -> dict[str, Any]:
        """Render statistics (the driver's ``settings["statistics"]``): bytes of a pixel's reservoir (prefix + suffix) against ReSTIR PT's path reservoir."""
        return {
            "reservoir_bytes_per_pixel": _struct_bytes(SupportReservoir) if self.reuses else 0,
            "restir_pt_reservoir_bytes_per_pixel": _struct_bytes(PathReservoir),
            "prefixes": self.prefixes,
            "gather_k": self.gather_k,
            "gather_radius_world": self.grid_radius,
        }

    def render_frame(self, frame: int) -> wp.array:
        b = self.built
        dev = b.device
        dim = (self.height, self.width)
        k = self.k
        with self._phase("gbuffer"):
            self.gbuffer.fill(b, float(frame), self.seed, jitter=self.jitter)
        self.domains.reverse()
        dom, dom_prev = self.domains
        with self._phase("primary"):
            launch(k["primary"], dim=dim, inputs=[self.gbuffer.current], outputs=[dom, self.direct], device=dev)
        history, cur, other = self.buffers
        if self.reuses:
            with self._phase("support"):
                history_valid = self.temporal and self.frames_rendered > 0
                launch(
                    k[self._support_prefix],
                    dim=dim,
                    inputs=[
                        self.spec, self.seed, int(frame), int(history_valid), self.history_cap,
                        int(self.temporal), self.gbuffer.current, self.gbuffer.previous, dom, dom_prev, history,
                    ],
                    outputs=[cur, self.temporal_src],
                    device=dev,
                )
                launch(k["support_suffix"], dim=dim, inputs=[self.spec, self.seed, int(frame), self.suffix_kept], outputs=[cur], device=dev)
                if history_valid:
                    launch(
                        k["support_temporal"],
                        dim=dim,
                        inputs=[self.spec, self.seed, int(frame), self.history_cap, history, self.temporal_src, self.rows["temporal"]],
                        outputs=[cur],
                        device=dev,
                    )
            if self.spatial and self.neighbors > 0:
                with self._phase("spatial"):
                    launch(
                        k["spatial"],
                        dim=dim,
                        inputs=[self.spec, self.seed, int(frame), self.neighbors, self.radius, self.history_cap, self.gbuffer.current, dom, cur, self.rows["spatial"]],
                        outputs=[other],
                        device=dev,
                    )
                cur, other = other, cur
            with self._phase("grid"):
                launch(k["points"], dim=dim, inputs=[cur], outputs=[self.points], device=dev)
                self.grid.build(self.points, 2.0 * self.grid_radius)  # cells of 2 radii: see hash_grid_dims
        if self.suffixes > 0:
            with self._phase("own_suffixes"):
                launch(k["own"], dim=dim, inputs=[self.spec, self.seed, int(frame), dom, self.suffix_kept], outputs=[self.own_z, self.own_x, self.own_res], device=dev)
        direct = self.direct  # emission seen at x₁; with ReSTIR DI, emission and direct light
        if self.di is not None:
            direct = self.di.direct_light(frame)
        with self._phase("gather"):
            for j in range(self.prefixes):
                launch(
                    k["gather_prefix"],
                    dim=dim,
                    inputs=[
                        self.spec, self.full_sp, self.seed, int(frame), j, self.prefixes, self.gather_k, self.suffixes, self.kept, int(self.canonical),
                        self.alpha_cap, self.max_bounces, self.grid.id, self.grid_radius, self.gather_widen, dom, direct, cur, self.points,
                        self.own_z, self.own_x, self.own_res, self.knn_idx, self.knn_dist, self.rows["gather"],
                    ],
                    outputs=[self.accum],
                    device=dev,
                )
                launch(
                    k["gather_suffix"],
                    dim=dim,
                    inputs=[self.spec, self.seed, int(frame), j, self.prefixes, self.suffixes, self.kept, int(self.canonical), self.width, self.rows["gather"],
                            self.suffix_kept],
                    device=dev,
                )
                launch(
                    k["gather_mis"],
                    dim=dim,
                    inputs=[self.spec, self.seed, int(frame), j, self.prefixes, self.suffixes, self.kept, int(self.canonical), self.mis_mode, self.rows["gather"]],
                    outputs=[self.accum],
                    device=dev,
                )
            launch(k["gather_finish"], dim=dim, inputs=[self.accum], outputs=[self.image, self.nonfinite], device=dev)
        self.buffers = [cur, history, other]
        self.frames_rendered += 1
        return self.image

    def reservoirs(self) -> np.ndarray:
        """The last frame's supporting reservoirs (structured NumPy array), for tests and debugging."""
        return self.buffers[0].numpy()


def create_suffix_restir(ctx: Any) -> SuffixReSTIR:
    return create_renderer(SuffixReSTIR, ctx)


def create_mmis_gather(ctx: Any) -> SuffixReSTIR:
    return create_renderer(SuffixReSTIR, ctx)


# ---- registration (grisx.render.base.registry) ----

def _restir_pt_params(*names: str) -> tuple[Param, ...]:
    """ReSTIR PT's params of these names (the same meaning here), their defaults this constructor's."""
    from grisx.render import restir_pt  # noqa: F401  (registers restir-pt)
    from grisx.render.base.registry import METHODS

    pt = {p.name: p for p in METHODS["restir-pt"].params}
    return tuple(dataclasses.replace(pt[n], default=...) for n in names)


_SHARED = (
    Param("roulette", ..., "Russian-roulette canonical suffix (seed 001, Eq. 23): canonical_suffixes of the N prefixes trace theirs, weighted N/R; false: every prefix traces one", kind="bool"),
    Param("canonical_suffixes", ..., "R: prefixes per pixel and frame that trace their canonical suffix under roulette, each weighted N/R (1: Eq. 23)", kind="int", minimum=1, maximum=1024),
    Param("canonical", ..., "include the canonical suffix domain (false: the borrowed suffixes alone, biased: Eq. 17's coverage lost)", kind="bool"),
    Param("shift", ..., "suffix shift: hybrid (reconnect x_k' -> x_k+1 where both are rough, replay before), reconnection or replay", kind="choice", choices=("hybrid", "reconnection", "replay")),
    *_restir_pt_params("max_depth", "rr_depth", "rough_threshold", "near_field", "jacobian", "max_jacobian", "jitter"),
    *_restir_pt_params("direct"),
)

register(
    RenderMethod(
        "suffix-restir",
        "Suffix ReSTIR (seed 001): suffixes reused by conditional RIS, final gather over N prefixes with k-NN borrowed suffixes and their canonical ones (all, or R of N rouletted)",
        create_suffix_restir,
        params=renderer_params(
            SuffixReSTIR,
            Param("prefixes", ..., "integration prefixes per pixel and frame (N of Eq. 23; the paper's equal-time setting: 8)", kind="int", minimum=1, maximum=1024),
            Param("gather_k", ..., "supporting prefixes (nearest in world space) whose suffixes each integration prefix borrows", kind="int", minimum=0, maximum=32),
            Param("gather_widen", ..., "times the k-NN radius is widened 4x for a prefix that found no supporting prefix within it", kind="int", minimum=0, maximum=4),
            Param("gather_radius", ..., "k-NN search radius as a fraction of the scene radius (0: automatic, 2 sqrt(k / pixels))", minimum=0.0),
            Param("temporal", ..., "temporal reuse of prefixes (GRIS) and suffixes (conditional RIS)", kind="bool"),
            Param("spatial", ..., "spatial suffix reuse (conditional RIS over neighbouring pixels)", kind="bool"),
            Param("neighbors", ..., "spatial neighbours per pixel", kind="int", minimum=0, maximum=16),
            Param("radius", ..., "spatial reuse radius in pixels", minimum=1.0),
            Param("history_cap", ..., "temporal confidence cap of prefixes and suffixes"),
            Param("prefix", ..., "where a prefix ends: hybrid (at the first pair of rough vertices, the paper's split) or bounce (always at x2)", kind="choice", choices=PREFIX_RULES),
            Param("gather_alpha", ..., "a borrowed suffix's domain weight in the gather's MIS: one, or its reservoir's confidence capped at history_cap (the prototype's)", kind="choice", choices=GATHER_ALPHA),
            Param("gather_mis", ..., "gather MIS: balance (Eq. 15 over the k + 1 domains, O(k^2) shifts) or pairwise (each borrowed domain against the canonical, O(k))", kind="choice", choices=tuple(GATHER_MIS)),
            Param("suffix_in_prefix_target", ..., "prefix target f_p times the old suffix's target (seed 001, Sec. S.1.1): biased, for teaching", kind="bool"),
            *_SHARED,
        ),
    )
)

register(
    RenderMethod(
        "mmis-gather",
        "MMIS baseline (West et al. 2022, seed 001 Fig. 7): each pixel's prefixes all connect to its few independent suffixes, balance-heuristic weights",
        create_mmis_gather,
        params=(
            Param("prefixes", 64, "prefixes per pixel and frame", kind="int", minimum=1, maximum=1024),
            Param("suffixes", 3, "suffixes per pixel and frame (traced after the first prefixes), each connected to every prefix", kind="int", minimum=1, maximum=32),
            Param("gather_k", 0, "no borrowed supporting suffixes: the baseline reuses nothing across pixels", kind="int", minimum=0, maximum=0),
            # its own canonical domain is rouletted among the prefixes without a suffix of their own: the baseline's
            # few suffixes per pixel are its point (seed 001, Fig. 3)
            Param("roulette", True, "Russian-roulette canonical suffix among the prefixes that traced none (seed 001, Eq. 23); false: each traces one", kind="bool"),
            *renderer_params(SuffixReSTIR, *(p for p in _SHARED if p.name != "roulette")),
        ),
    )
)
