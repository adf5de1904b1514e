"""Caustics by specular manifold sampling (SMS), with sample-space partitioning and per-frame priors (seed 003).

The image is the path tracer's, split by *who owns which path*:

* **SMS owns** every camera path whose first non-delta vertex is x₁, followed by
  1 … ``chain`` delta vertices, each left by its canonical lobe (refraction at a
  dielectric, reflection at a conductor), the first on a caster object O with the
  direction from x₁ inside O's seed square and meeting O at |cos| ≥ 0.1 (not grazing),
  then a point x_n on an emitter triangle
  (:func:`grisx.scene.caustics.caustic_owned`) or escaping to the environment. At x₁ it picks a
  caster (uniformly, P(O) = 1/#casters) and an emitter point or environment direction
  (``sample_light``, density p_A per area or per solid angle), runs
  a manifold walk from a seed u ~ p (Eq. 7) and, if it converges to a solution u*,
  estimates 1/P(u*) by Bernoulli trials (Eq. 1–3) and adds
  β(x₁) ⊙ f(x̂) · W / (p_A(x_n) P(O)), f of Eq. 13 (generalized geometry term included);
* **the path tracer owns the rest** (:func:`grisx.render.base.trace.make_trace_path`
  with ``caustic_chain``): the very same ``trace_path`` as ``pt``, whose emitter hits
  on SMS-owned paths add nothing. Nothing is counted twice, nothing dropped, so
  ``pt`` and every method here estimate the same image; caustics through a
  dielectric's reflection lobe, longer than ``chain``, starting outside a caster's
  seed square or grazing it stay (noisy) with the path tracer (point lights: nobody reaches them).

Methods:

``sms``              Zeltner et al. 2020: uniform seed in U, unrestricted walk, W = K Bernoulli trials;
``sms-partitioned``  N × N tiles (``tiles``, 16), walks stopped outside the 3 × 3 trust region R(u)
                     (periodic), W = K / P(C) with trials in C(u*) (Eq. 4–6); with ``prior`` a
                     per-frame prior from ``presamples`` unrestricted walks per ``block`` × ``block``
                     pixel block, each from a random pixel to a random light–object pair: the tiles
                     that held solutions per caster (Eq. 7–9, α = 0.8) and the pairs that did, from
                     which a pixel draws its pair w.p. α, else from the whole scene, P(pair) =
                     α [pair ∈ I]/#I + (1 − α) p_scene entering W (Sec. 4.2). The presamples run one
                     thread each (``prior_walks``), then one thread per block gathers the sets in
                     presample order (``prior_sets``);
``sms-restir``       one ``sms-partitioned`` sample per pixel and frame as a reservoir x̂ = (u*, O, x_n)
                     with p̂ = lum f(x̂) and W = K / (P(C) p_A P(O)); temporal reuse of the pixel's
                     reservoir of the last frame, found by reprojecting x₁ (confidence cap ``history_cap`` 20), and one spatial
                     neighbour uniform in a ``radius`` 30 px disc, both through the **manifold shift**
                     (a ≤ 5-step walk from the neighbour's u* in this pixel's problem with the same O and
                     x_n, checked by the walk back; Jacobian 1) and pairwise MIS (Eq. 10–11) —
                     :meth:`grisx.theory.manifold.ManifoldSampler.reuse`, the toy's very function, run as
                     its parts: the two shifts of a pixel in threads of their own (``reuse_carry``,
                     ``reuse_shift``: ``restir_shifts``), then ``reuse_merge`` (``restir_merge``). The
                     path tracer's part of the pixel is its own fresh sample each frame.

``max_trials`` caps the Bernoulli trials (0, the default: unbounded; the paper runs 128): any cap
loses the energy f (1 − P)^cap of each solution — about 0.1% of the solutions hit 128 on the
slab — so the default is the unbiased estimator and ``max_trials=128`` the paper's setting;
a small cap (``max_trials=2``) is the biased ablation of Fig. 7. Every formula (seed pdf, P(C), α', W, the walk) is :mod:`grisx.theory.manifold`'s,
shared with the ``sms-toy`` toy problem.

Statistics (seed 003, Table 1) come back in ``render --json`` under ``statistics``, over all frames
rendered: success rate, Newton iterations per sample, Bernoulli trials per solution, Newton
iterations per solution, capped solutions, the prior's walks and (``sms-restir``) the shifts'
success rate and cost; the stage times are ``seconds``' ``prior``, ``path_tracing`` (the path tracer's sample of the pixel, x₁ recorded),
``manifold_sampling`` (SMS at x₁, the trial stage included), ``temporal``, ``spatial`` and ``shade``.

On a GPU a solution runs ``inline_trials`` (1) Bernoulli trials in its sample pass and the rest in a stage
of their own (:class:`BernoulliStage`), many trials of one solution at once: a long series of trials no
longer holds its warp. The result is the serial loop's, bit for bit (H200, 1080p: caustic-slab-plane's
manifold sampling 165 → 34 ms, the spheres' ``sms`` 201 → 24 ms; ``benchmarks/sms_trials.py``).

Simplified against the paper (said plainly): one emitter point and caster per sample (p_scene: the
caster uniform, the light by power; a "light" is one emitter triangle, as the light set has it);
the tile prior is per block and caster, not per pair (linked lists in the paper); delta casters only (no
offset manifolds for glossy casters); the chain is shot from x₁, its Jacobian
carried by ray differentials (:mod:`grisx.scene.caustics`; differences only through normal maps); ``sms-restir``'s temporal neighbour is found by
reprojecting x₁ (not a G-buffer similarity test) and temporal reuse is off while objects move.
"""

from __future__ import annotations

import contextlib
from typing import Any

import numpy as np
import warp as wp

from grisx.device import launch, specialized_module
from grisx.errors import InvalidParameterError
from grisx.params import Param
from grisx.render.base.registry import RenderMethod, register, renderer_params
from grisx.render.base.trace import PathRadiance, make_trace_path, no_first_hit
from grisx.render.pt import PathTracer, image_from_sum, add_sample, pixel_ray, sample_key
from grisx.scene.bsdf import make_bsdf
from grisx.render.base.reuse import spatial_neighbor
from grisx.scene.camera import CameraData, camera_project, camera_ray
from grisx.scene.caustics import CHAIN_MAX, CausticSpec, make_caustic_spec, make_caustics, set_view
from grisx.scene.frame import frame_from_normal, to_local, to_world
from grisx.scene.distribution import alias_pmf, sample_alias
from grisx.scene.lights import make_lights
from grisx.scene.material import MATERIAL_CONDUCTOR, MATERIAL_DIELECTRIC, material_kind
from grisx.scene.scene import SceneData, SurfaceInteraction, make_surface, spawn_origin
from grisx.theory.gris import resampling_weight
from grisx.theory.manifold import (
    NEWTON_MAX_ITERATIONS,
    PRIOR_ALPHA,
    UNBOUNDED_TRIALS,
    ReuseNeighbor,
    ReuseShifts,
    SeedSpace,
    SMSSample,
    bernoulli_ucw,
    conditional_space,
    pair_pmf,
    prior_add_tile,
    prior_contains,
    reuse_neighbor,
    seed_space,
    tile_of,
    trial_cap,
)
from grisx.theory.reservoir import Reservoir, reservoir_empty, reservoir_finalize, reservoir_update
from grisx.theory.random import random_key, random_subkey, random_uniform

wp.set_module_options({"enable_backward": False})

__all__ = ["SMSRenderer", "SMSReSTIR", "CausticSample", "ShadingPoint", "caster_objects", "STAT_NAMES", "make_sms_kernels", "sms_statistics"]

#: per-frame tallies (summed over pixels and samples), the order of the ``stats`` array
STAT_NAMES = (
    "samples",  # SMS attempts (x₁ found, an emitter triangle sampled)
    "successes",  # walks that converged to a solution u*
    "newton_sample",  # Newton steps of the main walks
    "bernoulli",  # Bernoulli trials of all solutions
    "newton_bernoulli",  # their Newton steps
    "capped",  # solutions whose trials hit max_trials
    "prior_walks",
    "prior_successes",
    "newton_prior",
    "prior_tiles",
    "shift_walks",  # sms-restir: manifold walks of the shifts (2 per shift: there and back)
    "shifts_valid",
    "newton_shift",
)
_N_STATS = len(STAT_NAMES)


def caster_objects(scene: Any) -> list[int]:
    """Object ids of a scene's caustic casters: objects with a delta (smooth conductor or dielectric) material."""
    kinds = (int(MATERIAL_CONDUCTOR), int(MATERIAL_DIELECTRIC))
    return [i for i, o in enumerate(scene.objects) if material_kind(scene.materials[o.material]) in kinds]


@wp.struct
class CausticSample:
    """A kept SMS sample x̂ = (solution u*, caster O, emitter point x_n): what a reservoir holds (Sec. 5.2)."""

    u: wp.vec2
    caster: int
    xn: wp.vec3
    xn_n: wp.vec3
    light_tri: int


@wp.struct
class ShadingPoint:
    """A pixel's x₁ this frame: the surface, the direction back, the camera path's throughput, its depth."""

    si: SurfaceInteraction
    wo: wp.vec3
    beta: wp.vec3
    depth: int
    valid: int


@wp.struct
class PendingTrials:
    """A solution whose Bernoulli trials outlasted its sample pass's budget, waiting for the trial stage:
    its problem (``view``: the pixel's row of the spec, intact until the next sample pass), u* with ∂C/∂u
    there, where its seeds come from, the trials' key, cap and Newton steps so far, and what W then
    multiplies: β ⊙ f(u*) and p(x_n | light) P(light, O), the rest of the pixel's sample, p̂ (``sms-restir``)."""

    view: int
    x: int
    y: int
    u: wp.vec2
    jacobian: wp.mat22
    space: SeedSpace
    row: int
    key: wp.uint32
    cap: int
    newton: int
    beta_f: wp.vec3
    pdf: float
    radiance: wp.vec3
    p_hat: float


@wp.struct
class CausticCandidate:
    """What :func:`sms_candidate` found at x₁: the SMS sample (``s.found``: a solution u*), the light–object
    density p(x_n | light) P(light, O), the seed space and prior row it drew from, and ``pending``: its
    Bernoulli trials outlasted the pass's budget (``s.ucw`` is not W yet)."""

    s: SMSSample
    pdf: float
    space: SeedSpace
    row: int
    pending: int


@wp.struct
class SMSPass:
    """What every sample pass reads: camera, casters, seed and frame, depth, trial cap, seed space and the prior."""

    cam: CameraData
    casters: wp.array(dtype=int)
    seed: int
    frame: int
    max_depth: int
    rr_depth: int
    jitter: int
    max_trials: int
    inline_trials: int  # trials a solution runs in the pass; the rest go to ``pending`` (0: all of them here)
    pending: wp.array(dtype=PendingTrials)
    pending_count: wp.array(dtype=int)
    tiles: int
    alpha: float
    block: int
    blocks_x: int
    prior_tiles: wp.array2d(dtype=int)
    prior_count: wp.array(dtype=int)
    prior_pairs: wp.array2d(dtype=int)  # per block: light · #casters + caster of the pairs that held solutions
    prior_pair_count: wp.array(dtype=int)
    stats: wp.array2d(dtype=wp.float64)


#: Bernoulli trials a solution runs in its sample pass on a GPU before the rest go to the trial stage
INLINE_TRIALS = 1

#: rows of the tally array: a thread adds into row (its index mod this), so atomics on a GPU rarely collide
STAT_ROWS = 256


@wp.func
def _tally(stats: wp.array2d(dtype=wp.float64), thread: int, i: int, value: float):
    wp.atomic_add(stats, thread % stats.shape[0], i, wp.float64(value))


@wp.func
def _tally_trials(stats: wp.array2d(dtype=wp.float64), thread: int, trials: int, newton: int, capped: wp.bool):
    _tally(stats, thread, 3, float(trials))
    _tally(stats, thread, 4, float(newton))
    if capped:
        _tally(stats, thread, 5, 1.0)


@wp.func
def caustic_ucw(trials_ucw: float, pdf: float) -> float:
    """W of an SMS sample: the trials' K/P(C) over p(x_n | light) P(light, O) (seed 003, Eq. 1, 5)."""
    return trials_ucw / pdf


@wp.func
def candidate_ucw(c: CausticCandidate) -> float:
    """W of a candidate whose trials are done (:func:`caustic_ucw`)."""
    return caustic_ucw(c.s.ucw, c.pdf)


@wp.func
def neighbor_in_views(res_n: wp.array(dtype=Reservoir), samples_n: wp.array(dtype=CausticSample), nb: int, q: int, pixels: int) -> ReuseNeighbor:
    """Neighbour ``nb`` of pixel q as a :class:`ReuseNeighbor` in the reuse passes' view layout: q canonical,
    +pixels its sample shifted here, +2 pixels the canonical sample there, +3 pixels its own domain."""
    return reuse_neighbor(res_n[nb], samples_n[nb].u, 3 * pixels + q, pixels + q, 2 * pixels + q, 1)


@wp.func
def initial_reservoir(p_hat: float, ucw: float) -> Reservoir:
    """``sms-restir``'s initial reservoir: one SMS sample with target p̂ and UCW W (Eq. 10 with m = 1, T = id)."""
    rc = reservoir_empty()
    rc = reservoir_update(rc, resampling_weight(1.0, p_hat, ucw, 1.0), p_hat, 1.0, 0.0)
    return reservoir_finalize(rc)


@wp.func
def defer_trials(p: SMSPass, c: CausticCandidate, view: int, x: int, y: int, beta_f: wp.vec3, radiance: wp.vec3, p_hat: float) -> wp.bool:
    """Queue a pending candidate's remaining trials for the trial stage; False when the queue is full."""
    slot = wp.atomic_add(p.pending_count, 0, 1)
    if slot >= p.pending.shape[0]:
        return False
    d = PendingTrials()
    d.view = view
    d.x = x
    d.y = y
    d.u = c.s.u
    d.jacobian = c.s.jacobian
    d.space = c.space
    d.row = c.row
    d.key = c.s.trial_key
    d.cap = trial_cap(p.max_trials)
    d.newton = c.s.newton_bernoulli
    d.beta_f = beta_f
    d.pdf = c.pdf
    d.radiance = radiance
    d.p_hat = p_hat
    p.pending[slot] = d
    return True


_KERNELS: dict[Any, Any] = {}


def make_sms_kernels(kinds: frozenset[int], chain: int) -> dict[str, Any]:
    """The prior and sample-pass kernels for material kinds ``kinds`` and chains of ≤ ``chain`` vertices (cached)."""
    key = (frozenset(kinds), int(chain))
    if key in _KERNELS:
        return _KERNELS[key]
    kinds = frozenset(kinds)
    bsdf = make_bsdf(kinds)
    surface = make_surface(kinds)  # the wrappers and shapes of these kinds only
    lights = make_lights(kinds)  # the lights of these kinds only
    sample_given_light, sample_light = lights.sample_given_light, lights.sample_light
    surface_material, intersect = surface.surface_material, surface.intersect
    trace_path = make_trace_path(kinds, caustic_chain=chain)
    caustics = make_caustics(kinds)
    SMS = caustics.sms
    # three Warp modules, each compiled on first use: the prior (sms-partitioned, sms-restir), the sample pass
    # (sms, sms-partitioned) and the reuse passes (sms-restir); one module of all six doubled a method's first compile
    prior_module = specialized_module(f"{__name__}.chain{chain}.prior", kinds)
    module = specialized_module(f"{__name__}.chain{chain}", kinds)
    reuse_module = specialized_module(f"{__name__}.chain{chain}.reuse", kinds)
    trials_module = specialized_module(f"{__name__}.chain{chain}.trials", kinds)
    camera_module = specialized_module(f"{__name__}.chain{chain}.camera", kinds)

    @wp.func
    def first_non_delta(scene: SceneData, o: wp.vec3, d: wp.vec3, key: wp.uint32) -> SurfaceInteraction:
        """The first non-delta vertex along a camera ray (delta lobes sampled as the path tracer does)."""
        si = intersect(scene, o, d, 1.0e30)
        for k in range(8):
            if si.valid == 0:
                return si
            m = surface_material(scene, si)
            if bsdf.is_delta(m) == 0:
                return si
            frame = frame_from_normal(si.ns)
            bs = bsdf.sample(m, to_local(frame, -d), random_uniform(key, 3 * k), wp.vec2(0.5, 0.5))
            if bs.valid == 0:
                break
            d = wp.normalize(to_world(frame, bs.wi))
            o = spawn_origin(scene, si.p, si.ng, d)
            si = intersect(scene, o, d, 1.0e30)
        si.valid = 0
        return si

    @wp.func
    def sms_candidate(spec: CausticSpec, p: SMSPass, view: int, x1: ShadingPoint, x: int, y: int, skey: wp.uint32) -> CausticCandidate:
        """One SMS sample at x₁ into ``view`` (caster and x_n in the view), its Bernoulli trials run up to the
        pass's budget (``pending`` when they need more)."""
        casters = p.casters
        stats = p.stats
        out = CausticCandidate()
        out.s.found = False
        out.pending = 0
        n_casters = casters.shape[0]
        blk = (y // p.block) * p.blocks_x + x // p.block
        # ---- a light–object pair: from the block's prior pairs w.p. α, else caster uniform, light ∝ power (Sec. 4.2) ----
        n_pairs = p.prior_pair_count[blk]
        ci = wp.min(int(random_uniform(skey, 0) * float(n_casters)), n_casters - 1)
        light = sample_alias(spec.scene.lights.selection, random_uniform(skey, 1))
        if p.alpha > 0.0 and n_pairs > 0 and random_uniform(skey, 5) < p.alpha:
            pair = p.prior_pairs[blk, wp.min(int(random_uniform(skey, 6) * float(n_pairs)), n_pairs - 1)]
            light = pair // n_casters
            ci = pair % n_casters
        if light < 0:
            return out
        scene_pmf = alias_pmf(spec.scene.lights.selection, light) / float(n_casters)
        p_pair = pair_pmf(p.alpha, prior_contains(p.prior_pairs[blk], n_pairs, light * n_casters + ci), n_pairs, scene_pmf)
        ls = sample_given_light(spec.scene.lights, light, 1.0, x1.si.p, wp.vec2(random_uniform(skey, 2), random_uniform(skey, 3)))
        if ls.light < 0 or ls.delta != 0 or not (ls.pdf_area > 0.0) or not (p_pair > 0.0):
            return out  # point lights: no chain reaches a delta light (the path tracer's neither)
        set_view(spec, view, x1.si, x1.wo, x1.depth, casters[ci], ls.p, ls.n, ls.tri)
        row = blk * n_casters + ci
        space = seed_space(p.tiles, p.alpha, p.prior_count[row])  # Eq. 7 (p_U when no prior)
        cap = trial_cap(p.max_trials)
        budget = cap
        if p.inline_trials > 0:
            budget = wp.min(cap, p.inline_trials)
        s = SMS.sample(spec, view, space, p.prior_tiles[row], random_subkey(skey, 4), budget)
        _tally(stats, view, 0, 1.0)
        _tally(stats, view, 2, float(s.newton_sample))
        out.s = s
        out.pdf = ls.pdf_area * p_pair
        out.space = space
        out.row = row
        if s.found:
            _tally(stats, view, 1, 1.0)
            if s.capped and budget < cap:
                out.pending = 1  # the trial stage (or finish_trials) takes it from trial ``budget`` on
            else:
                _tally_trials(stats, view, s.trials, s.newton_bernoulli, s.capped)
        return out

    @wp.func
    def finish_trials(spec: CausticSpec, p: SMSPass, view: int, c: CausticCandidate) -> CausticCandidate:
        """A pending candidate's trials, all in this thread (the trial stage's queue was full): from trial 0
        again, so K and W are what the stage would have found."""
        b = SMS.bernoulli(spec, view, c.s.u, c.s.jacobian, c.space, p.prior_tiles[c.row], c.s.trial_key, p.max_trials)
        _tally_trials(p.stats, view, b.trials, b.newton, b.capped)
        out = c
        out.s.ucw = b.ucw
        out.pending = 0
        return out

    @wp.func
    def shading_point(r: PathRadiance, casters: wp.array(dtype=int)) -> ShadingPoint:
        sp = ShadingPoint()
        sp.si = r.x1
        sp.wo = r.x1_wo
        sp.beta = r.x1_beta
        sp.depth = r.x1_depth
        sp.valid = int(r.x1_valid != 0 and casters.shape[0] > 0)
        return sp

    @wp.func
    def camera_path(spec: CausticSpec, p: SMSPass, x: int, y: int, sample: int) -> PathRadiance:
        """The path tracer's sample of pixel (x, y), without the paths SMS owns (x₁ recorded)."""
        key = sample_key(p.seed, p.frame, y * p.cam.width + x, sample)
        ray = pixel_ray(p.cam, key, x, y, p.jitter)
        return trace_path(spec.scene, ray.o, ray.d, random_subkey(key, 1), p.max_depth, p.rr_depth, 0, -1, 0, no_first_hit())

    @wp.func
    def view_sample(spec: CausticSpec, view: int, u: wp.vec2) -> CausticSample:
        c = CausticSample()
        c.u = u
        c.caster = spec.caster[view]
        c.xn = spec.xn[view]
        c.xn_n = spec.xn_n[view]
        c.light_tri = spec.light_tri[view]
        return c

    @wp.func
    def set_sample_view(spec: CausticSpec, view: int, x1: ShadingPoint, y: CausticSample):
        set_view(spec, view, x1.si, x1.wo, x1.depth, y.caster, y.xn, y.xn_n, y.light_tri)

    @wp.kernel(module=prior_module)
    def prior_walks(
        spec: CausticSpec,
        cam: CameraData,
        casters: wp.array(dtype=int),
        seed: int,
        frame: int,
        block: int,
        tiles: int,
        blocks_x: int,
        view_base: int,
        hits: wp.array2d(dtype=wp.vec3i),
        stats: wp.array2d(dtype=wp.float64),
    ):
        # ---- per-frame prior, stage 1: presample j of pixel block (bx, by), one thread each: an unrestricted walk
        # from a random pixel of the B × B block to a random light–object pair (seed 003, Sec. 4.1–4.2); its
        # (tile, caster, pair) when it converged, else tile −1 ----
        by, bx, j = wp.tid()
        presamples = hits.shape[1]
        n_casters = casters.shape[0]
        blk = by * blocks_x + bx
        view = view_base + blk * presamples + j
        hits[blk, j] = wp.vec3i(-1, 0, 0)
        jkey = random_subkey(random_subkey(random_subkey(random_key(seed, frame), 1), blk), j)
        x = wp.min(bx * block + int(random_uniform(jkey, 0) * float(block)), cam.width - 1)
        y = wp.min(by * block + int(random_uniform(jkey, 1) * float(block)), cam.height - 1)
        ray = camera_ray(cam, float(x) + 0.5, float(y) + 0.5, wp.vec2(0.5, 0.5))
        si = first_non_delta(spec.scene, ray.o, ray.d, random_subkey(jkey, 1))
        if si.valid == 0:
            return
        ci = wp.min(int(random_uniform(jkey, 7) * float(n_casters)), n_casters - 1)
        ls = sample_light(spec.scene.lights, si.p, random_uniform(jkey, 2), wp.vec2(random_uniform(jkey, 3), random_uniform(jkey, 4)))
        if ls.light < 0 or ls.delta != 0:
            return
        set_view(spec, view, si, -ray.d, 0, casters[ci], ls.p, ls.n, ls.tri)
        w = SMS.walk(spec, view, wp.vec2(random_uniform(jkey, 5), random_uniform(jkey, 6)), 0, NEWTON_MAX_ITERATIONS)
        _tally(stats, blk, 6, 1.0)
        _tally(stats, blk, 8, float(w.iterations))
        if w.converged:
            _tally(stats, blk, 7, 1.0)
            hits[blk, j] = wp.vec3i(tile_of(w.u, tiles), ci, ls.light * n_casters + ci)

    @wp.kernel(module=prior_module)
    def prior_sets(
        n_casters: int,
        hits: wp.array2d(dtype=wp.vec3i),
        prior_tiles: wp.array2d(dtype=int),
        prior_count: wp.array(dtype=int),
        prior_pairs: wp.array2d(dtype=int),
        prior_pair_count: wp.array(dtype=int),
        stats: wp.array2d(dtype=wp.float64),
    ):
        # ---- stage 2, one thread per block: the sets I of tiles that held solutions (per caster) and of the pairs,
        # in presample order ----
        blk = wp.tid()
        for ci in range(n_casters):
            prior_count[blk * n_casters + ci] = 0
        pairs = int(0)
        for j in range(hits.shape[1]):
            h = hits[blk, j]
            if h[0] >= 0:
                row = blk * n_casters + h[1]
                prior_count[row] = prior_add_tile(prior_tiles[row], prior_count[row], h[0])
                pairs = prior_add_tile(prior_pairs[blk], pairs, h[2])
        prior_pair_count[blk] = pairs
        for ci in range(n_casters):
            _tally(stats, blk, 9, float(prior_count[blk * n_casters + ci]))

    @wp.kernel(module=camera_module)
    def camera_pass(spec: CausticSpec, p: SMSPass, sample: int, radiance: wp.array(dtype=wp.vec3), points: wp.array(dtype=ShadingPoint)):
        # ---- the path tracer's sample of the pixel, without the paths SMS owns; its x₁ for the SMS pass ----
        y, x = wp.tid()
        q = y * p.cam.width + x
        r = camera_path(spec, p, x, y, sample)
        radiance[q] = r.total
        points[q] = shading_point(r, p.casters)

    @wp.kernel(module=module)
    def sample_pass(
        spec: CausticSpec,
        p: SMSPass,
        sample: int,
        radiance: wp.array(dtype=wp.vec3),
        points: wp.array(dtype=ShadingPoint),
        total: wp.array2d(dtype=wp.vec3d),
        total_sq: wp.array2d(dtype=wp.vec3d),
        nonfinite: wp.array(dtype=wp.int32),
    ):
        y, x = wp.tid()
        pixel = y * p.cam.width + x
        L = radiance[pixel]
        sp = points[pixel]
        if sp.valid != 0:
            # ---- caustic next-event estimation at x₁ (seed 003, Eq. 1) ----
            c = sms_candidate(spec, p, pixel, sp, x, y, random_subkey(sample_key(p.seed, p.frame, pixel, sample), 2))
            if c.s.found:
                beta_f = wp.cw_mul(sp.beta, caustics.value(spec, pixel, c.s.u))
                if c.pending != 0:
                    if defer_trials(p, c, pixel, x, y, beta_f, L, 0.0):
                        return  # the trial stage adds this sample (trials_shade)
                    c = finish_trials(spec, p, pixel, c)
                L += beta_f * candidate_ucw(c)
        add_sample(total, total_sq, nonfinite, y, x, L)

    @wp.kernel(module=reuse_module)
    def restir_initial(
        spec: CausticSpec,
        p: SMSPass,
        points: wp.array(dtype=ShadingPoint),
        res: wp.array(dtype=Reservoir),
        samples: wp.array(dtype=CausticSample),
    ):
        y, x = wp.tid()
        q = y * p.cam.width + x
        sp = points[q]
        # ---- initial candidate: one SMS sample, a reservoir of one (Eq. 10 with m = 1, T = id) ----
        rc = reservoir_empty()
        smp = CausticSample()
        if sp.valid != 0:
            rc = reservoir_finalize(reservoir_update(rc, 0.0, 0.0, 1.0, 0.0))  # the domain exists: confidence 1, found or not
            c = sms_candidate(spec, p, q, sp, x, y, random_subkey(sample_key(p.seed, p.frame, q, 0), 2))
            if c.s.found:
                p_hat = caustics.target(spec, q, c.s.u)
                smp = view_sample(spec, q, c.s.u)
                if c.pending != 0:
                    samples[q] = smp
                    if defer_trials(p, c, q, x, y, wp.vec3(0.0), wp.vec3(0.0), p_hat):
                        return  # the trial stage writes this reservoir (trials_reservoir)
                    c = finish_trials(spec, p, q, c)
                rc = initial_reservoir(p_hat, candidate_ucw(c))
        res[q] = rc
        samples[q] = smp

    @wp.func
    def reuse_domain(
        cam_prev: CameraData, seed: int, frame: int, width: int, height: int, spatial: int, radius: float,
        points: wp.array(dtype=ShadingPoint), points_n: wp.array(dtype=ShadingPoint), q: int,
    ) -> int:
        """The neighbour pixel whose reservoir pixel q reuses: where x₁ was seen last frame (temporal) or one
        uniform in a disc (spatial); −1 when there is none or it saw no x₁."""
        x = q % width
        y = q // width
        key = random_subkey(sample_key(seed, frame, q, 0), 10 + spatial)
        nb = int(-1)
        if spatial != 0:
            n = spatial_neighbor(x, y, width, height, radius, wp.vec2(random_uniform(key, 8), random_uniform(key, 9)))
            if n.valid != 0:
                nb = n.y * width + n.x
        else:
            proj = camera_project(cam_prev, points[q].si.p)  # x₁ reprojected into the last frame's camera
            if proj.valid != 0 and proj.inside != 0:
                nb = wp.min(int(proj.pixel[1]), height - 1) * width + wp.min(int(proj.pixel[0]), width - 1)
        if nb >= 0 and points_n[nb].valid == 0:
            nb = -1
        return nb

    @wp.kernel(module=reuse_module)
    def restir_shifts(
        spec: CausticSpec,
        cam_prev: CameraData,
        seed: int,
        frame: int,
        width: int,
        height: int,
        spatial: int,
        radius: float,
        points: wp.array(dtype=ShadingPoint),
        points_n: wp.array(dtype=ShadingPoint),
        res: wp.array(dtype=Reservoir),
        samples: wp.array(dtype=CausticSample),
        res_n: wp.array(dtype=Reservoir),
        samples_n: wp.array(dtype=CausticSample),
        carried: wp.array(dtype=ReuseShifts),
        shifted: wp.array(dtype=ReuseShifts),
    ):
        # ---- temporal or spatial reuse (Sec. 5.2), stage 1: its two manifold shifts in threads of their own,
        # side 0 the canonical sample carried into the neighbour's domain (for m_c), side 1 the neighbour's
        # sample shifted here. Views: q canonical (x₁ here, y_c's caster and x_n), +pixels T(y_n) here,
        # +2 pixels y_c there, +3 pixels y_n in its own domain ----
        side, y, x = wp.tid()
        q = y * width + x
        pixels = width * height
        if points[q].valid == 0:
            return
        nb = reuse_domain(cam_prev, seed, frame, width, height, spatial, radius, points, points_n, q)
        if nb < 0:
            return
        pc = points[q]
        pn = points_n[nb]
        y_c = samples[q]
        y_n = samples_n[nb]
        n0 = neighbor_in_views(res_n, samples_n, nb, q, pixels)
        if side == 0:
            set_sample_view(spec, q, pc, y_c)
            set_sample_view(spec, 2 * pixels + q, pn, y_c)
            carried[q] = SMS.reuse_carry(spec, res[q], y_c.u, q, n0, 0, ReuseShifts())
        else:
            set_sample_view(spec, pixels + q, pc, y_n)
            set_sample_view(spec, 3 * pixels + q, pn, y_n)
            shifted[q] = SMS.reuse_shift(spec, n0, 0, ReuseShifts())

    @wp.kernel(module=reuse_module)
    def restir_merge(
        cam_prev: CameraData,
        seed: int,
        frame: int,
        width: int,
        height: int,
        spatial: int,
        radius: float,
        cap: float,
        points: wp.array(dtype=ShadingPoint),
        points_n: wp.array(dtype=ShadingPoint),
        res: wp.array(dtype=Reservoir),
        samples: wp.array(dtype=CausticSample),
        res_n: wp.array(dtype=Reservoir),
        samples_n: wp.array(dtype=CausticSample),
        carried: wp.array(dtype=ReuseShifts),
        shifted: wp.array(dtype=ReuseShifts),
        res_out: wp.array(dtype=Reservoir),
        samples_out: wp.array(dtype=CausticSample),
        stats: wp.array2d(dtype=wp.float64),
    ):
        # ---- stage 2: pairwise MIS and the merge over the shifts stage 1 traced (Eq. 10–11) ----
        y, x = wp.tid()
        q = y * width + x
        pixels = width * height
        # each output written once, at the end (the pixel's own reservoir where it has no point)
        r_kept = res[q]
        kept = samples[q]
        if points[q].valid != 0:
            key = random_subkey(sample_key(seed, frame, q, 0), 10 + spatial)
            nb = reuse_domain(cam_prev, seed, frame, width, height, spatial, radius, points, points_n, q)
            absent = reuse_neighbor(reservoir_empty(), wp.vec2(0.0, 0.0), 0, 0, 0, 0)
            n0 = absent
            sh = ReuseShifts()
            if nb >= 0:
                n0 = neighbor_in_views(res_n, samples_n, nb, q, pixels)
                sh = shifted[q]
                c = carried[q]
                sh.carried = c.carried
                sh.walks += c.walks
                sh.newton += c.newton
                sh.succeeded += c.succeeded
            out = SMS.reuse_merge(r_kept, kept.u, n0, absent, sh, cap, key)
            _tally(stats, q, 10, float(out.walks))
            _tally(stats, q, 11, float(out.valid))
            _tally(stats, q, 12, float(out.newton))
            if out.source == 0:
                kept = samples_n[nb]
            kept.u = out.y
            r_kept = out.r
        res_out[q] = r_kept
        samples_out[q] = kept

    @wp.kernel(module=reuse_module)
    def restir_shade(
        spec: CausticSpec,
        width: int,
        radiance: wp.array(dtype=wp.vec3),
        points: wp.array(dtype=ShadingPoint),
        res: wp.array(dtype=Reservoir),
        samples: wp.array(dtype=CausticSample),
        total: wp.array2d(dtype=wp.vec3d),
        total_sq: wp.array2d(dtype=wp.vec3d),
        nonfinite: wp.array(dtype=wp.int32),
    ):
        # ---- shading: the path tracer's part + β ⊙ f(y) W_y (Eq. 11) ----
        y, x = wp.tid()
        q = y * width + x
        L = radiance[q]
        pc = points[q]
        r = res[q]
        if pc.valid != 0 and r.ucw > 0.0:
            smp = samples[q]
            set_sample_view(spec, q, pc, smp)
            L += wp.cw_mul(pc.beta, caustics.value(spec, q, smp.u)) * r.ucw
        add_sample(total, total_sq, nonfinite, y, x, L)

    # ---- the trial stage: pending solutions' Bernoulli trials, many at once -----------------------------

    @wp.kernel(module=trials_module)
    def trials_round(
        spec: CausticSpec,
        pending: wp.array(dtype=PendingTrials),
        prior_tiles: wp.array2d(dtype=int),
        active: wp.array(dtype=int),
        lanes: int,
        done: int,
        hit: wp.array(dtype=int),
        newton: wp.array(dtype=int),
    ):
        # trial t = done + lane of pending solution active[i / lanes]. Trials are i.i.d. given their index
        # (trial t draws its seed from counters 4t … of the solution's key), so K = 1 + the first t that hits:
        # the very K of the serial loop, found by ``lanes`` threads at once
        i = wp.tid()
        e = active[i // lanes]
        t = done + i % lanes
        d = pending[e]
        if t >= d.cap or hit[e] < t:
            return  # past the cap, or an earlier trial already hit
        prior = prior_tiles[d.row]
        b = SMS.trial(spec, d.view, d.u, d.jacobian, d.space, prior, conditional_space(d.space, prior, d.u), d.key, t)
        newton[i] = b.newton
        if b.hit:
            wp.atomic_min(hit, e, t)

    @wp.kernel(module=trials_module)
    def trials_settle(
        pending: wp.array(dtype=PendingTrials),
        active: wp.array(dtype=int),
        lanes: int,
        done: int,
        hit: wp.array(dtype=int),
        newton: wp.array(dtype=int),
        newton_total: wp.array(dtype=int),
        next_active: wp.array(dtype=int),
        next_count: wp.array(dtype=int),
    ):
        # a round's Newton steps up to the first hit (what the serial loop walked), and the solutions still
        # unresolved compacted into the next round's list
        i = wp.tid()
        e = active[i]
        h = hit[e]
        cap = pending[e].cap
        n = int(0)
        for lane in range(lanes):
            t = done + lane
            if t > h or t >= cap:
                break
            n += newton[i * lanes + lane]
        newton_total[e] = newton_total[e] + n
        if h >= cap and done + lanes < cap:
            next_active[wp.atomic_add(next_count, 0, 1)] = e

    @wp.func
    def trials_result(p: PendingTrials, prior: wp.array(dtype=int), h: int, newton: int, stats: wp.array2d(dtype=wp.float64)) -> float:
        # K = 1 + the first hit (the cap when none hit); W = K/P(C) / (p(x_n | light) P(light, O)) (Eq. 1, 5)
        trials = wp.min(h + 1, p.cap)
        _tally_trials(stats, p.view, trials, p.newton + newton, h >= p.cap)
        return caustic_ucw(bernoulli_ucw(trials, conditional_space(p.space, prior, p.u).p_c), p.pdf)

    @wp.kernel(module=trials_module)
    def trials_shade(
        pending: wp.array(dtype=PendingTrials),
        prior_tiles: wp.array2d(dtype=int),
        hit: wp.array(dtype=int),
        newton_total: wp.array(dtype=int),
        stats: wp.array2d(dtype=wp.float64),
        total: wp.array2d(dtype=wp.vec3d),
        total_sq: wp.array2d(dtype=wp.vec3d),
        nonfinite: wp.array(dtype=wp.int32),
    ):
        # the sample pass's pixels whose trials ran here: their sample, β ⊙ f W added to the path tracer's part
        e = wp.tid()
        d = pending[e]
        ucw = trials_result(d, prior_tiles[d.row], hit[e], newton_total[e], stats)
        add_sample(total, total_sq, nonfinite, d.y, d.x, d.radiance + d.beta_f * ucw)

    @wp.kernel(module=trials_module)
    def trials_reservoir(
        pending: wp.array(dtype=PendingTrials),
        prior_tiles: wp.array2d(dtype=int),
        hit: wp.array(dtype=int),
        newton_total: wp.array(dtype=int),
        stats: wp.array2d(dtype=wp.float64),
        res: wp.array(dtype=Reservoir),
    ):
        # ``sms-restir``: the initial reservoir of a pixel whose trials ran here
        e = wp.tid()
        d = pending[e]
        res[d.view] = initial_reservoir(d.p_hat, trials_result(d, prior_tiles[d.row], hit[e], newton_total[e], stats))

    out = {"camera_pass": camera_pass, "trials_round": trials_round, "trials_settle": trials_settle, "trials_shade": trials_shade, "trials_reservoir": trials_reservoir,
           "prior_walks": prior_walks, "prior_sets": prior_sets, "sample_pass": sample_pass, "restir_initial": restir_initial, "restir_shifts": restir_shifts, "restir_merge": restir_merge, "restir_shade": restir_shade, "first_non_delta": first_non_delta, "caustics": caustics}
    _KERNELS[key] = out
    return out


class BernoulliStage:
    """The trial stage: Bernoulli trials that outlast a sample pass's budget, many at once (issue 37).

    A solution of small P'(u*) needs K ≈ 1/P' trials in series, and in a sample pass one such pixel holds
    its warp, and so the whole pass, for all of them: on caustic-slab-plane at 1080p single solutions take
    4000–5700 trials (9000 Newton steps), while the mean is 1.5. The sample pass therefore runs at most
    ``inline_trials`` trials a solution and queues the rest (:class:`PendingTrials`). Trials are i.i.d.
    given their index (trial t draws from counters 4t … of the solution's key), so K = 1 + the first t
    that hits, whatever order they run in: each round runs the next ``lanes`` trials of every queued
    solution at once, keeps the first hit (``atomic_min``), counts the Newton steps the serial loop would
    have walked, and compacts the unresolved solutions into the next round's list. K, W and the image are
    those of the serial loop, bit for bit. Lanes at most double the trials done so far, so the trials run
    past K are at most as many as those up to it. One host read of the queue's length a round; a queue
    that overflows leaves the solution's trials to its own thread (:func:`finish_trials`).
    """

    #: threads a round may launch
    THREADS = {"cuda": 1 << 20, "cpu": 1 << 12}
    #: trials of one solution a round runs at least (H200, 1080p: 4–64 within 5% of each other; 8 the best)
    MIN_LANES = 8

    def __init__(self, kernels: dict[str, Any], pixels: int, device: Any, max_trials: int, capacity: int | None = None) -> None:
        self.kernels = kernels
        self.device = device
        self.capacity = max(4096, pixels // 8) if capacity is None else int(capacity)
        self.threads = self.THREADS["cuda" if wp.get_device(device).is_cuda else "cpu"]
        self.cap = int(max_trials) if max_trials > 0 else int(UNBOUNDED_TRIALS)
        self.pending = wp.zeros(self.capacity, dtype=PendingTrials, device=device)
        self.count = wp.zeros(1, dtype=int, device=device)
        self.next_count = wp.zeros(1, dtype=int, device=device)
        self.hit = wp.zeros(self.capacity, dtype=int, device=device)
        self.newton_total = wp.zeros(self.capacity, dtype=int, device=device)
        self.order = wp.array(np.arange(self.capacity, dtype=np.int32), dtype=int, device=device)
        self.active = [wp.zeros(self.capacity, dtype=int, device=device) for _ in range(2)]
        self.newton = wp.zeros(max(self.threads, self.capacity), dtype=int, device=device)
        self.queued = 0  # solutions the last run took (for tests and benchmarks)
        self.rounds = 0

    def begin(self) -> None:
        """Empty the queue before a sample pass."""
        self.count.zero_()

    def run(self, spec: Any, prior_tiles: wp.array, stats: wp.array, first_trial: int, finish: str, outputs: list[Any]) -> None:
        """Run the queued solutions' trials from ``first_trial`` on, then ``finish`` (``trials_shade`` or
        ``trials_reservoir``) writes their samples into ``outputs``."""
        n = min(int(self.count.numpy()[0]), self.capacity)
        self.queued, self.rounds = n, 0
        if n == 0:
            return
        dev, k = self.device, self.kernels
        self.hit.fill_(int(UNBOUNDED_TRIALS))  # no hit yet (≥ any cap)
        self.newton_total.zero_()
        active, m, done, side = self.order, n, int(first_trial), 0
        while m > 0 and done < self.cap:
            lanes = max(1, min(self.threads // m, max(done, self.MIN_LANES), self.cap - done))
            launch(k["trials_round"], dim=m * lanes, inputs=[spec, self.pending, prior_tiles, active, lanes, done],
                      outputs=[self.hit, self.newton], device=dev)
            self.next_count.zero_()
            launch(k["trials_settle"], dim=m, inputs=[self.pending, active, lanes, done, self.hit, self.newton],
                      outputs=[self.newton_total, self.active[side], self.next_count], device=dev)
            active, side = self.active[side], 1 - side
            done += lanes
            self.rounds += 1
            m = int(self.next_count.numpy()[0])
        launch(k[finish], dim=n, inputs=[self.pending, prior_tiles, self.hit, self.newton_total], outputs=[stats, *outputs], device=dev)


class SMSRenderer(PathTracer):
    """The path tracer plus SMS caustic NEE at x₁: ``spp`` sample passes per frame (see the module docstring)."""

    def __init__(
        self,
        built: Any,
        width: int,
        height: int,
        *,
        spp: int = 1,
        max_depth: int = 16,
        rr_depth: int = 5,
        max_trials: int = 0,
        tiles: int = 0,
        prior: bool = True,
        presamples: int = 128,
        block: int = 16,
        chain: int = CHAIN_MAX,
        inline_trials: int = -1,
        jitter: bool = True,
        seed: int = 0,
        timer: Any = None,
    ) -> None:
        if tiles != 0 and tiles < 3:
            raise InvalidParameterError(f"param 'tiles' must be 0 (unpartitioned) or >= 3 (3 × 3 trust regions), got {tiles}")
        if not 1 <= int(chain) <= 4:
            raise InvalidParameterError(f"param 'chain' must be in [1, 4] specular vertices, got {chain}")
        super().__init__(built, width, height, spp=spp, max_depth=max_depth, rr_depth=rr_depth, seed=seed, timer=timer, jitter=jitter)
        self.max_trials = int(max_trials)
        self.tiles = int(tiles)
        self.prior = bool(prior) and self.tiles > 0
        self.presamples = int(presamples)
        self.block = int(block)
        self.chain = int(chain)
        dev = built.device
        self.casters_host = caster_objects(built.scene)
        # no casters: SMS adds nothing and the path tracer keeps every path (it owns them all)
        self.casters = wp.array(np.asarray(self.casters_host, dtype=np.int32), dtype=int, device=dev)
        self.kernels_ = make_sms_kernels(built.features.kernel_kinds, self.chain)
        self.blocks_x = -(-self.width // self.block)
        self.blocks_y = -(-self.height // self.block)
        n_rows = self.blocks_x * self.blocks_y * max(len(self.casters_host), 1)
        self.prior_tiles = wp.zeros((n_rows, max(self.presamples, 1)), dtype=int, device=dev)
        self.prior_count = wp.zeros(n_rows, dtype=int, device=dev)
        n_blocks = self.blocks_x * self.blocks_y
        self.prior_pairs = wp.zeros((n_blocks, max(self.presamples, 1)), dtype=int, device=dev)
        self.prior_pair_count = wp.zeros(n_blocks, dtype=int, device=dev)
        self.prior_hits = wp.zeros((n_blocks, max(self.presamples, 1)), dtype=wp.vec3i, device=dev)
        self.prior_rows = n_blocks * max(self.presamples, 1) if self.prior else 0  # a problem row per presample
        self.spec = make_caustic_spec(built, self.width * self.height + self.prior_rows, self.chain, self.max_depth)
        self.prior_view_base = self.width * self.height
        self.stats = wp.zeros((STAT_ROWS, _N_STATS), dtype=wp.float64, device=dev)
        self.frames = 0
        # trials past a solution's first few run in a stage of their own on a GPU, where one long series
        # holds a whole warp (BernoulliStage); a CPU thread has no warp to hold
        if int(inline_trials) < 0:
            inline_trials = INLINE_TRIALS if wp.get_device(dev).is_cuda else 0
        self.inline_trials = int(inline_trials)
        self.trial_stage = BernoulliStage(self.kernels_, self.width * self.height, dev, self.max_trials) if self.inline_trials > 0 else None
        self.no_pending = wp.zeros(1, dtype=PendingTrials, device=dev)
        self.no_count = wp.zeros(1, dtype=int, device=dev)
        n = self.width * self.height
        self.radiance = wp.zeros(n, dtype=wp.vec3, device=dev)  # the path tracer's part of the pixel's sample
        self.points = wp.zeros(n, dtype=ShadingPoint, device=dev)  # and its x₁

    def kernels(self) -> list[Any]:
        prior = [self.kernels_["prior_walks"], self.kernels_["prior_sets"]] if self.prior and self.casters_host else []
        return [*prior, self.kernels_["camera_pass"], self.kernels_["sample_pass"], *self._trial_kernels("trials_shade"), image_from_sum]

    def _trial_kernels(self, finish: str) -> list[Any]:
        return [self.kernels_[k] for k in ("trials_round", "trials_settle", finish)] if self.trial_stage is not None else []

    def _timed(self, name: str) -> Any:
        return self.timer(name) if self.timer is not None else contextlib.nullcontext()

    def build_prior(self, frame: int, cam: CameraData) -> None:
        """Seed 003, Sec. 4.1–4.2: the tiles I that held solutions, per pixel block and caster, and the pairs."""
        self.prior_count.zero_()
        self.prior_pair_count.zero_()
        if not self.prior or not self.casters_host:
            return
        dev = self.built.device
        launch(
            self.kernels_["prior_walks"],
            dim=(self.blocks_y, self.blocks_x, self.presamples),
            inputs=[self.spec, cam, self.casters, self.seed, int(frame), self.block, self.tiles, self.blocks_x, self.prior_view_base],
            outputs=[self.prior_hits, self.stats],
            device=dev,
        )
        launch(
            self.kernels_["prior_sets"],
            dim=self.blocks_x * self.blocks_y,
            inputs=[len(self.casters_host), self.prior_hits],
            outputs=[self.prior_tiles, self.prior_count, self.prior_pairs, self.prior_pair_count, self.stats],
            device=dev,
        )

    def pass_record(self, frame: int, cam: CameraData) -> SMSPass:
        p = SMSPass()
        p.cam = cam
        p.casters = self.casters
        p.seed, p.frame = self.seed, int(frame)
        p.max_depth, p.rr_depth, p.jitter, p.max_trials = self.max_depth, self.rr_depth, self.jitter, self.max_trials
        p.inline_trials = self.inline_trials
        stage = self.trial_stage
        p.pending = stage.pending if stage is not None else self.no_pending
        p.pending_count = stage.count if stage is not None else self.no_count
        p.tiles, p.alpha, p.block, p.blocks_x = self.tiles, PRIOR_ALPHA if self.prior else 0.0, self.block, self.blocks_x
        p.prior_tiles, p.prior_count, p.stats = self.prior_tiles, self.prior_count, self.stats
        p.prior_pairs, p.prior_pair_count = self.prior_pairs, self.prior_pair_count
        return p

    def add_samples(self, frame: int, count: int, first_sample: int | None = None) -> None:
        cam = self.built.camera_data(float(frame), self.width, self.height)
        with self._timed("prior"):
            self.build_prior(frame, cam)
        p = self.pass_record(frame, cam)
        dev = self.built.device
        for _ in range(count):
            self.camera_pass(p, self.samples)
            with self._timed("manifold_sampling"):
                if self.trial_stage is not None:
                    self.trial_stage.begin()
                launch(self.kernels_["sample_pass"], dim=(self.height, self.width), inputs=[self.spec, p, self.samples, self.radiance, self.points],
                          outputs=[self.total, self.total_sq, self.nonfinite], device=dev)
                if self.trial_stage is not None:  # before the next pass overwrites the views
                    self.trial_stage.run(self.spec, self.prior_tiles, self.stats, self.inline_trials, "trials_shade", [self.total, self.total_sq, self.nonfinite])
            self.samples += 1
            if self.on_sample is not None:
                self.on_sample()

    def camera_pass(self, p: SMSPass, sample: int) -> None:
        """The path tracer's sample ``sample`` of every pixel, without SMS's paths; x₁ into ``points``."""
        with self._timed("path_tracing"):
            launch(self.kernels_["camera_pass"], dim=(self.height, self.width), inputs=[self.spec, p, int(sample)],
                      outputs=[self.radiance, self.points], device=self.built.device)

    def render_frame(self, frame: int) -> wp.array:
        self.reset()
        self.add_samples(frame, self.spp)
        self.frames += 1
        launch(image_from_sum, dim=self.total.shape, inputs=[self.total, wp.float64(1.0 / max(self.samples, 1))], outputs=[self.image], device=self.built.device)
        return self.image

    def statistics(self) -> dict[str, float]:
        """Seed 003's Table 1 columns over everything rendered so far (per frame where it says so)."""
        return sms_statistics(dict(zip(STAT_NAMES, self.stats.numpy().sum(axis=0).tolist())), max(self.frames, 1))


class SMSReSTIR(SMSRenderer):
    """``sms-restir``: sms-partitioned samples, then temporal and spatial GRIS through manifold shifts (Sec. 5).

    Per frame: the path tracer (without SMS's paths) and one SMS candidate per pixel; temporal reuse of
    the reservoir of the pixel where x₁ was seen in the last frame (x₁ reprojected into its camera; that
    pixel's x₁ then is the neighbour's domain; skipped while objects move, whose last frame's geometry is
    gone); one spatial neighbour uniform in a ``radius``-pixel disc (clamped to the film); pairwise MIS
    and the confidence cap ``history_cap`` (seed 003: 20) through :meth:`ManifoldSampler.reuse`.
    """

    def __init__(self, built: Any, width: int, height: int, *, temporal: bool = True, spatial: bool = True, radius: float = 30.0,
                 history_cap: float = 20.0, tiles: int = 16, **kw: Any) -> None:
        super().__init__(built, width, height, tiles=tiles, **kw)
        self.temporal, self.spatial = bool(temporal), bool(spatial)
        self.radius, self.history_cap = float(radius), float(history_cap)
        n = self.width * self.height
        dev = built.device
        # views: 4 per pixel (canonical, a neighbour's sample here, ours there, the neighbour's own) + prior rows
        self.spec = make_caustic_spec(built, 4 * n + self.prior_rows, self.chain, self.max_depth)
        self.prior_view_base = 4 * n
        self.carried = wp.zeros(n, dtype=ReuseShifts, device=dev)  # the reuse shifts: y_c carried there,
        self.shifted = wp.zeros(n, dtype=ReuseShifts, device=dev)  # and the neighbour's sample shifted here
        self.points_prev = wp.zeros(n, dtype=ShadingPoint, device=dev)
        self.res = [wp.zeros(n, dtype=Reservoir, device=dev) for _ in range(4)]  # initial, temporal, final, last frame's
        self.smp = [wp.zeros(n, dtype=CausticSample, device=dev) for _ in range(4)]
        self.history = False

    def kernels(self) -> list[Any]:
        k = self.kernels_
        prior = [k["prior_walks"], k["prior_sets"]] if self.prior and self.casters_host else []
        return [*prior, k["camera_pass"], k["restir_initial"], *self._trial_kernels("trials_reservoir"), k["restir_shifts"], k["restir_merge"], k["restir_shade"], image_from_sum]

    def _reuse(self, frame: int, spatial: int, points_n: wp.array, src: int, nb: int, dst: int) -> None:
        cam_prev = self.built.camera_data(float(frame - 1), self.width, self.height)
        dev = self.built.device
        domain = [cam_prev, self.seed, int(frame), self.width, self.height, spatial, self.radius]
        buffers = [self.points, points_n, self.res[src], self.smp[src], self.res[nb], self.smp[nb]]
        # the two shifts of every pixel in threads of their own, then the merge (seed 003, Sec. 5.2)
        launch(self.kernels_["restir_shifts"], dim=(2, self.height, self.width), inputs=[self.spec, *domain, *buffers],
                  outputs=[self.carried, self.shifted], device=dev)
        launch(self.kernels_["restir_merge"], dim=(self.height, self.width), inputs=[*domain, self.history_cap, *buffers, self.carried, self.shifted],
                  outputs=[self.res[dst], self.smp[dst], self.stats], device=dev)

    def render_frame(self, frame: int) -> wp.array:
        self.reset()
        dev = self.built.device
        cam = self.built.camera_data(float(frame), self.width, self.height)
        with self._timed("prior"):
            self.build_prior(frame, cam)
        p = self.pass_record(frame, cam)
        self.camera_pass(p, 0)
        with self._timed("manifold_sampling"):
            if self.trial_stage is not None:
                self.trial_stage.begin()
            launch(self.kernels_["restir_initial"], dim=(self.height, self.width), inputs=[self.spec, p, self.points],
                      outputs=[self.res[0], self.smp[0]], device=dev)
            if self.trial_stage is not None:
                self.trial_stage.run(self.spec, self.prior_tiles, self.stats, self.inline_trials, "trials_reservoir", [self.res[0]])
        cur = 0
        # ---- temporal reuse (static geometry: the last frame's x₁ still lies on it) ----
        if self.temporal and self.history and not self.built.features.animated_objects:
            with self._timed("temporal"):
                self._reuse(frame, 0, self.points_prev, 0, 3, 1)
            cur = 1
        # ---- spatial reuse ----
        if self.spatial:
            with self._timed("spatial"):
                self._reuse(frame, 1, self.points, cur, cur, 2)
            cur = 2
        with self._timed("shade"):
            launch(self.kernels_["restir_shade"], dim=(self.height, self.width),
                      inputs=[self.spec, self.width, self.radiance, self.points, self.res[cur], self.smp[cur]],
                      outputs=[self.total, self.total_sq, self.nonfinite], device=dev)
            wp.copy(self.res[3], self.res[cur])
            wp.copy(self.smp[3], self.smp[cur])
            wp.copy(self.points_prev, self.points)
        self.history = True
        self.samples = 1
        self.frames += 1
        launch(image_from_sum, dim=self.total.shape, inputs=[self.total, wp.float64(1.0)], outputs=[self.image], device=dev)
        return self.image


def sms_statistics(t: dict[str, float], frames: int) -> dict[str, float]:
    """Table 1's columns from the tallies ``t`` (:data:`STAT_NAMES`, plus any shift tallies)."""

    def ratio(a: float, b: float) -> float:
        return float(a / b) if b > 0 else 0.0

    found = t["successes"]
    out = {
        "success_rate": ratio(found, t["samples"]),
        "newton_per_sample": ratio(t["newton_sample"], t["samples"]),
        "bernoulli_per_solution": ratio(t["bernoulli"], found),
        "newton_per_solution": ratio(t["newton_bernoulli"], found),
        "capped_per_solution": ratio(t["capped"], found),
        "samples_per_frame": t["samples"] / frames,
        "prior_walks_per_frame": t["prior_walks"] / frames,
        "prior_success_rate": ratio(t["prior_successes"], t["prior_walks"]),
        "prior_tiles_per_frame": t["prior_tiles"] / frames,
    }
    if t.get("shift_walks", 0.0) > 0.0:  # sms-restir: the manifold shifts (2 walks each)
        out["shift_success_rate"] = ratio(t["shifts_valid"], t["shift_walks"] / 2.0)
        out["shift_walks_per_sample"] = ratio(t["shift_walks"], t["samples"])
        out["newton_shift_per_sample"] = ratio(t["newton_shift"], t["samples"])
    return out


def _create(tiles_default: int, cls: type = SMSRenderer):
    def create(ctx: Any) -> SMSRenderer:
        p = dict(ctx.params)
        names = {q.name for q in (*_PARAMS_ALL, *_PARAMS_RESTIR)}
        kw = {k: v for k, v in p.items() if k in names}
        kw.setdefault("tiles", tiles_default)
        return cls(ctx.built, ctx.width, ctx.height, spp=p["spp"], seed=ctx.seed, timer=ctx.timer, **kw)

    return create


# ---- registration (grisx.render.base.registry) ----

_COMMON = (
    Param("max_depth", ..., "longest path in segments, Mitsuba's meaning (the path tracer's); default: the scene's", kind="int", minimum=-1),
    Param("rr_depth", ..., "depth from which Russian roulette may end paths", kind="int", minimum=1),
    Param("max_trials", ..., "cap on Bernoulli trials per solution (0 = unbounded, unbiased; seed 003 runs 128, which loses ~0.1% of solutions; a small cap is the biased ablation)", kind="int", minimum=0, maximum=1 << 22),
    Param("chain", ..., "most specular vertices of a caustic chain (2: a slab's two refractions)", kind="int", minimum=1, maximum=4),
    Param("inline_trials", ..., "Bernoulli trials a solution runs in its sample pass; the rest run in a stage of their own, many at once, with the same result (-1: 1 on a GPU, 0 on a CPU; 0: all in the sample pass)", kind="int", minimum=-1, maximum=1 << 22),
    Param("jitter", ..., "a new camera sample per pixel and frame (the box filter pt estimates); false: pixel centres", kind="bool"),
)
_PARTITION = (
    Param("tiles", 16, "N: U is cut into N × N tiles, trust regions are 3 × 3 tiles (seed 003, Sec. 3.3)", kind="int", minimum=3, maximum=256),
    Param("prior", ..., "seed pdf α p_I + (1 − α) p_U from presampled tiles I per pixel block (Eq. 7), α = 0.8", kind="bool"),
    Param("presamples", ..., "unrestricted walks per pixel block, caster and frame that build the prior (seed 003: 128, 256 hard cases)", kind="int", minimum=1, maximum=1024),
    Param("block", ..., "B: prior blocks are B × B pixels", kind="int", minimum=1, maximum=256),
)
_PARAMS_ALL = renderer_params(SMSRenderer, *_COMMON, *_PARTITION)
_PARAMS_RESTIR = renderer_params(
    SMSReSTIR,
    Param("temporal", ..., "reuse the previous frame's reservoir of the pixel (manifold shift)", kind="bool"),
    Param("spatial", ..., "reuse one neighbour's reservoir per frame (manifold shift)", kind="bool"),
    Param("radius", ..., "spatial reuse radius in pixels (seed 003: 30)", kind="float", minimum=1.0, maximum=1024.0),
    Param("history_cap", ..., "cap on the confidence M a reservoir carries (seed 003: 20)", kind="float", minimum=0.0),
)

register(
    RenderMethod(
        "sms",
        "the path tracer + caustic NEE by specular manifold sampling: uniform seeds, Bernoulli-trial UCWs (seed 003, Eq. 1-3)",
        _create(0),
        params=_PARAMS_ALL[: len(_COMMON)],
        uses_spp=True,
    )
)
register(
    RenderMethod(
        "sms-partitioned",
        "SMS with N x N tiles, 3 x 3 trust regions, W = K / P(C) and per-frame priors per pixel block (seed 003, Eq. 4-9)",
        _create(16),
        params=_PARAMS_ALL,
        uses_spp=True,
    )
)
register(
    RenderMethod(
        "sms-restir",
        "sms-partitioned samples reused by temporal + spatial GRIS through manifold shifts, pairwise MIS (seed 003, Eq. 10-13)",
        _create(16, SMSReSTIR),
        params=(*_PARAMS_ALL, *_PARAMS_RESTIR),
    )
)
