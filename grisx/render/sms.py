"""Caustics by specular manifold sampling (SMS), with sample-space partitioning and per-frame priors (seed 003).

The image is the path tracer's, split by *who owns which path*:

* **SMS owns** every camera path whose first non-delta vertex is x₁, followed by
  1 … ``chain`` delta vertices, each left by its canonical lobe (refraction at a
  dielectric, reflection at a conductor), the first on a caster object O with the
  direction from x₁ inside O's seed square, then a point x_n on an emitter triangle
  (:func:`grisx.scene.caustics.caustic_owned`). At x₁ it picks a caster (uniformly,
  P(O) = 1/#casters) and an emitter point (``sample_light``, area density p_A), runs
  a manifold walk from a seed u ~ p (Eq. 7) and, if it converges to a solution u*,
  estimates 1/P(u*) by Bernoulli trials (Eq. 1–3) and adds
  β(x₁) ⊙ f(x̂) · W / (p_A(x_n) P(O)), f of Eq. 13 (generalized geometry term included);
* **the path tracer owns the rest** (:func:`grisx.render.base.trace.make_trace_path`
  with ``caustic_chain``): the very same ``trace_path`` as ``pt``, whose emitter hits
  on SMS-owned paths add nothing. Nothing is counted twice, nothing dropped, so
  ``pt`` and every method here estimate the same image; caustics from the
  environment or point lights, through a dielectric's reflection lobe, or longer
  than ``chain``, stay (noisy) with the path tracer.

Methods:

``sms``              Zeltner et al. 2020: uniform seed in U, unrestricted walk, W = K Bernoulli trials;
``sms-partitioned``  N × N tiles (``tiles``, 16), walks stopped outside the 3 × 3 trust region R(u)
                     (periodic), W = K / P(C) with trials in C(u*) (Eq. 4–6); with ``prior`` a
                     per-frame prior over tiles from ``presamples`` unrestricted walks per
                     ``block`` × ``block`` pixel block and caster (Eq. 7–9, α = 0.8).

``max_trials`` caps the Bernoulli trials (128 as the paper; 0 = unbounded): any cap loses the
energy f (1 − P)^cap of each solution, so a small cap (``max_trials=2``) is the biased ablation
of Fig. 7. Every formula (seed pdf, P(C), α', W, the walk) is :mod:`grisx.theory.manifold`'s,
shared with the ``sms-toy`` toy problem.

Per-frame statistics (seed 003, Table 1) come back in ``render --json`` under ``statistics``:
success rate, Newton iterations per sample, Bernoulli trials per solution, Newton iterations per
solution, the prior's walks, and the stage times (``prior``, ``manifold_sampling``).

Simplified against the paper (said plainly): one emitter point and caster per sample, drawn
without the α mix over light–object pairs of Sec. 4.2 (the prior is per block *and* caster, built
with light points drawn per presample); delta casters only; area lights only (the pool's sun in
an environment map stays with the path tracer); the chain is shot from x₁ with a numerical
Jacobian (:mod:`grisx.scene.caustics`).
"""

from __future__ import annotations

import contextlib
from typing import Any

import numpy as np
import warp as wp

from grisx.device import specialized_module
from grisx.errors import InvalidParameterError
from grisx.params import Param
from grisx.render.base.registry import RenderMethod, register, renderer_params
from grisx.render.base.trace import make_trace_path
from grisx.render.pt import PathTracer, _scale, add_sample, pixel_ray, sample_key
from grisx.scene.bsdf import make_bsdf
from grisx.scene.camera import CameraData, camera_ray
from grisx.scene.caustics import CHAIN_MAX, CausticSpec, make_caustic_spec, make_caustics, set_view
from grisx.scene.frame import frame_from_normal, to_local, to_world
from grisx.scene.lights import emitter_radiance, sample_light
from grisx.scene.material import MATERIAL_CONDUCTOR, MATERIAL_DIELECTRIC, material_kind
from grisx.scene.scene import SceneData, SurfaceInteraction, intersect, segment_occluded, spawn_origin, surface_material
from grisx.theory.manifold import NEWTON_MAX_ITERATIONS, PRIOR_ALPHA, prior_add_tile, seed_space, tile_of
from grisx.theory.random import random_key, random_subkey, random_uniform

wp.set_module_options({"enable_backward": False})

__all__ = ["SMSRenderer", "caster_objects", "STAT_NAMES", "make_sms_kernels"]

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
)
_N_STATS = len(STAT_NAMES)


def caster_objects(scene: Any) -> list[int]:
    """Object ids of a scene's caustic casters: objects with a delta (smooth conductor or dielectric) material."""
    kinds = (int(MATERIAL_CONDUCTOR), int(MATERIAL_DIELECTRIC))
    return [i for i, o in enumerate(scene.objects) if material_kind(scene.materials[o.material]) in kinds]


@wp.func
def _tally(stats: wp.array(dtype=wp.float64), i: int, value: float):
    wp.atomic_add(stats, i, wp.float64(value))


_KERNELS: dict[Any, Any] = {}


def make_sms_kernels(kinds: frozenset[int], chain: int) -> dict[str, Any]:
    """The prior and sample-pass kernels for material kinds ``kinds`` and chains of ≤ ``chain`` vertices (cached)."""
    key = (frozenset(kinds), int(chain))
    if key in _KERNELS:
        return _KERNELS[key]
    kinds = frozenset(kinds)
    bsdf = make_bsdf(kinds)
    trace_path = make_trace_path(kinds, caustic_chain=chain)
    caustics = make_caustics(kinds)
    SMS = caustics.sms
    module = specialized_module(f"{__name__}.chain{chain}", kinds)

    @wp.func
    def caustic_value(spec: CausticSpec, view: int, u: wp.vec2, x1: SurfaceInteraction, wo: wp.vec3, light_tri: int, x1_depth: int, max_depth: int) -> wp.vec3:
        """f(x̂) of seed 003's Eq. 13 for solution u of ``view``: f_s ⊙ Tr ⊙ L_e · |∂ω₁/∂A(x_n)| · V."""
        zero = wp.vec3(0.0, 0.0, 0.0)
        ch = caustics.shoot(spec, view, u)
        if ch.valid == 0:
            return zero
        if max_depth >= 0 and x1_depth + ch.length + 2 > max_depth:
            return zero  # the path tracer's max_depth: x₁'s depth, k delta vertices, the emitter
        xn = spec.xn[view]
        nn = spec.xn_n[view]
        le = emitter_radiance(spec.scene.lights, light_tri, nn, -ch.d_out)
        if wp.length_sq(le) <= 0.0:
            return zero
        if segment_occluded(spec.scene, ch.last, ch.last_ng, xn, nn):
            return zero
        m = surface_material(spec.scene, x1)
        frame = frame_from_normal(x1.ns)
        f = bsdf.eval(m, to_local(frame, wo), to_local(frame, ch.d1))
        g = caustics.geometry(spec, view, u)
        return wp.cw_mul(f, wp.cw_mul(ch.throughput, le)) * g

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

    @wp.kernel(module=module)
    def prior_pass(
        spec: CausticSpec,
        cam: CameraData,
        casters: wp.array(dtype=int),
        seed: int,
        frame: int,
        block: int,
        tiles: int,
        presamples: int,
        blocks_x: int,
        view_base: int,
        prior_tiles: wp.array2d(dtype=int),
        prior_count: wp.array(dtype=int),
        stats: wp.array(dtype=wp.float64),
    ):
        # ---- per-frame prior: unrestricted walks from random pixels of a B × B block (seed 003, Sec. 4.1) ----
        by, bx, ci = wp.tid()
        n_casters = casters.shape[0]
        row = (by * blocks_x + bx) * n_casters + ci
        view = view_base + row
        key = random_subkey(random_subkey(random_key(seed, frame), 1), row)
        count = int(0)
        for j in range(presamples):
            jkey = random_subkey(key, j)
            x = wp.min(bx * block + int(random_uniform(jkey, 0) * float(block)), cam.width - 1)
            y = wp.min(by * block + int(random_uniform(jkey, 1) * float(block)), cam.height - 1)
            ray = camera_ray(cam, float(x) + 0.5, float(y) + 0.5, wp.vec2(0.5, 0.5))
            si = first_non_delta(spec.scene, ray.o, ray.d, random_subkey(jkey, 1))
            if si.valid == 0:
                continue
            ls = sample_light(spec.scene.lights, si.p, random_uniform(jkey, 2), wp.vec2(random_uniform(jkey, 3), random_uniform(jkey, 4)))
            if ls.tri < 0:
                continue
            set_view(spec, view, si, casters[ci], ls.p, ls.n)
            w = SMS.walk(spec, view, wp.vec2(random_uniform(jkey, 5), random_uniform(jkey, 6)), 0, NEWTON_MAX_ITERATIONS)
            _tally(stats, 6, 1.0)
            _tally(stats, 8, float(w.iterations))
            if w.converged:
                _tally(stats, 7, 1.0)
                count = prior_add_tile(prior_tiles[row], count, tile_of(w.u, tiles))
        prior_count[row] = count
        _tally(stats, 9, float(count))

    @wp.kernel(module=module)
    def sample_pass(
        spec: CausticSpec,
        cam: CameraData,
        casters: wp.array(dtype=int),
        seed: int,
        frame: int,
        sample: int,
        max_depth: int,
        rr_depth: int,
        jitter: int,
        max_trials: int,
        tiles: int,
        alpha: float,
        block: int,
        blocks_x: int,
        prior_tiles: wp.array2d(dtype=int),
        prior_count: wp.array(dtype=int),
        total: wp.array2d(dtype=wp.vec3d),
        total_sq: wp.array2d(dtype=wp.vec3d),
        nonfinite: wp.array(dtype=wp.int32),
        stats: wp.array(dtype=wp.float64),
    ):
        y, x = wp.tid()
        pixel = y * cam.width + x
        key = sample_key(seed, frame, pixel, sample)
        ray = pixel_ray(cam, key, x, y, jitter)
        # ---- the path tracer, without the paths SMS owns ----
        r = trace_path(spec.scene, ray.o, ray.d, random_subkey(key, 1), max_depth, rr_depth, 0, -1, 0)
        L = r.total
        n_casters = casters.shape[0]
        if r.x1_valid != 0 and n_casters > 0:
            # ---- caustic next-event estimation at x₁ (seed 003, Eq. 1) ----
            skey = random_subkey(key, 2)
            x1 = r.x1
            ci = wp.min(int(random_uniform(skey, 0) * float(n_casters)), n_casters - 1)
            ls = sample_light(spec.scene.lights, x1.p, random_uniform(skey, 1), wp.vec2(random_uniform(skey, 2), random_uniform(skey, 3)))
            if ls.tri >= 0 and ls.pdf_area > 0.0:
                view = pixel
                set_view(spec, view, x1, casters[ci], ls.p, ls.n)
                row = ((y // block) * blocks_x + x // block) * n_casters + ci
                space = seed_space(tiles, alpha, prior_count[row])  # Eq. 7 (p_U when no prior)
                s = SMS.sample(spec, view, space, prior_tiles[row], random_subkey(skey, 4), max_trials)
                _tally(stats, 0, 1.0)
                _tally(stats, 2, float(s.newton_sample))
                if s.found:
                    _tally(stats, 1, 1.0)
                    _tally(stats, 3, float(s.trials))
                    _tally(stats, 4, float(s.newton_bernoulli))
                    if s.capped:
                        _tally(stats, 5, 1.0)
                    f = caustic_value(spec, view, s.u, x1, r.x1_wo, ls.tri, r.x1_depth, max_depth)
                    # f W / (p_A(x_n) P(O)), W = K / P(C) (Eq. 1, 5)
                    L += wp.cw_mul(r.x1_beta, f) * (s.ucw * float(n_casters) / ls.pdf_area)
        add_sample(total, total_sq, nonfinite, y, x, L)

    out = {"prior_pass": prior_pass, "sample_pass": sample_pass, "caustic_value": caustic_value, "first_non_delta": first_non_delta, "caustics": caustics}
    _KERNELS[key] = out
    return out


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
        max_trials: int = 128,
        tiles: int = 0,
        prior: bool = True,
        presamples: int = 128,
        block: int = 16,
        chain: int = CHAIN_MAX,
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
        self.kernels_ = make_sms_kernels(frozenset(built.features.material_kinds), self.chain)
        self.blocks_x = -(-self.width // self.block)
        self.blocks_y = -(-self.height // self.block)
        n_rows = self.blocks_x * self.blocks_y * max(len(self.casters_host), 1)
        self.prior_tiles = wp.zeros((n_rows, max(self.presamples, 1)), dtype=int, device=dev)
        self.prior_count = wp.zeros(n_rows, dtype=int, device=dev)
        self.spec = make_caustic_spec(built, self.width * self.height + n_rows, self.chain)
        self.stats = wp.zeros(_N_STATS, dtype=wp.float64, device=dev)
        self.frames = 0

    def kernels(self) -> list[Any]:
        return [self.kernels_["prior_pass"], self.kernels_["sample_pass"], _scale]

    def _timed(self, name: str) -> Any:
        return self.timer(name) if self.timer is not None else contextlib.nullcontext()

    def build_prior(self, frame: int, cam: CameraData) -> None:
        """Seed 003, Sec. 4.1: the tiles I that held solutions, per pixel block and caster."""
        self.prior_count.zero_()
        if not self.prior or not self.casters_host:
            return
        wp.launch(
            self.kernels_["prior_pass"],
            dim=(self.blocks_y, self.blocks_x, len(self.casters_host)),
            inputs=[self.spec, cam, self.casters, self.seed, int(frame), self.block, self.tiles, self.presamples, self.blocks_x, self.width * self.height],
            outputs=[self.prior_tiles, self.prior_count, self.stats],
            device=self.built.device,
        )

    def add_samples(self, frame: int, count: int, first_sample: int | None = None) -> None:
        cam = self.built.camera_data(float(frame), self.width, self.height)
        with self._timed("prior"):
            self.build_prior(frame, cam)
        with self._timed("manifold_sampling"):
            for _ in range(count):
                wp.launch(
                    self.kernels_["sample_pass"],
                    dim=(self.height, self.width),
                    inputs=[self.spec, cam, self.casters, self.seed, int(frame), self.samples, self.max_depth, self.rr_depth, self.jitter, self.max_trials,
                            self.tiles, PRIOR_ALPHA if self.prior else 0.0, self.block, self.blocks_x, self.prior_tiles, self.prior_count],
                    outputs=[self.total, self.total_sq, self.nonfinite, self.stats],
                    device=self.built.device,
                )
                self.samples += 1

    def render_frame(self, frame: int) -> wp.array:
        self.reset()
        self.add_samples(frame, self.spp)
        self.frames += 1
        wp.launch(_scale, dim=self.total.shape, inputs=[self.total, wp.float64(1.0 / max(self.samples, 1))], outputs=[self.image], device=self.built.device)
        return self.image

    def statistics(self) -> dict[str, float]:
        """Seed 003's Table 1 columns over everything rendered so far (per frame where it says so)."""
        return sms_statistics(dict(zip(STAT_NAMES, self.stats.numpy().tolist())), max(self.frames, 1))


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
    for k in ("shift_walks", "shifts_valid", "newton_shift"):
        if k in t:
            out[k + "_per_frame"] = t[k] / frames
    return out


def _create(tiles_default: int):
    def create(ctx: Any) -> SMSRenderer:
        p = dict(ctx.params)
        names = {q.name for q in _PARAMS_ALL}
        kw = {k: v for k, v in p.items() if k in names}
        kw.setdefault("tiles", tiles_default)
        return SMSRenderer(ctx.built, ctx.width, ctx.height, spp=p["spp"], seed=ctx.seed, timer=ctx.timer, **kw)

    return create


# ---- registration (grisx.render.base.registry) ----

_COMMON = (
    Param("max_depth", ..., "longest path in segments, Mitsuba's meaning (the path tracer's); default: the scene's", kind="int", minimum=-1),
    Param("rr_depth", ..., "depth from which Russian roulette may end paths", kind="int", minimum=1),
    Param("max_trials", ..., "cap on Bernoulli trials per solution (128 as seed 003; 0 = unbounded; a small cap is the biased ablation)", kind="int", minimum=0, maximum=1 << 22),
    Param("chain", ..., "most specular vertices of a caustic chain (2: a slab's two refractions)", kind="int", minimum=1, maximum=4),
    Param("jitter", ..., "a new camera sample per pixel and frame (the box filter pt estimates); false: pixel centres", kind="bool"),
)
_PARTITION = (
    Param("tiles", 16, "N: U is cut into N × N tiles, trust regions are 3 × 3 tiles (seed 003, Sec. 3.3)", kind="int", minimum=3, maximum=256),
    Param("prior", ..., "seed pdf α p_I + (1 − α) p_U from presampled tiles I per pixel block (Eq. 7), α = 0.8", kind="bool"),
    Param("presamples", ..., "unrestricted walks per pixel block, caster and frame that build the prior (seed 003: 128, 256 hard cases)", kind="int", minimum=1, maximum=1024),
    Param("block", ..., "B: prior blocks are B × B pixels", kind="int", minimum=1, maximum=256),
)
_PARAMS_ALL = renderer_params(SMSRenderer, *_COMMON, *_PARTITION)

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
