"""The reference path tracer: unidirectional path tracing with next-event estimation and MIS.

Every renderer in the seeds is judged against this estimator, so it is the
plain, well-known one (Veach 1997, Ch. 9; pbrt-v4's ``PathIntegrator``;
Mitsuba 3's ``path``), written to agree with Mitsuba 3 picture for picture:

* at each vertex x_k, **next-event estimation** samples a light
  (:func:`~grisx.scene.lights.sample_light`) and **BSDF sampling** picks the
  next direction; an emitter reached either way is weighted by the **power
  heuristic** (:func:`~grisx.theory.mis.power_heuristic`, Veach Eq. 9.13)
  between the two densities in solid angle. Delta lobes and delta lights
  have no competitor and get weight 1;
* ``max_depth`` has **Mitsuba's meaning**: the longest path has
  ``max_depth`` segments, so 1 shows only directly visible emitters, 2 adds
  direct light, and −1 is unbounded;
* **Russian roulette** from depth ``rr_depth`` (Mitsuba's default 5)
  continues with probability q = min(max(throughput)·η², 0.95) and divides by q;
* ``strategy=nee|bsdf`` keeps one technique only (weight 1) — the two are
  unbiased on their own, which the tests use to check the MIS combination.

Each sample pass is one launch over the image; passes accumulate a running
sum and sum of squares per pixel, so the mean and the per-pixel variance of
the mean (what ``grisx reference`` stores) come from the same passes.
Random numbers are counter-based: stream (seed, frame) → pixel → sample,
counter = 8·depth + dimension, so results are the same on every run.

Kernels are specialized to the scene: :func:`make_path_tracer_kernel`
compiles only the BSDF kinds the scene uses (``make_bsdf``), so a scene
without dielectrics compiles no dielectric code.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import warp as wp

from grisx.device import specialized_module
from grisx.scene.bsdf import make_bsdf
from grisx.scene.camera import CameraData, camera_ray, sample_camera
from grisx.scene.frame import frame_from_normal, to_local, to_world
from grisx.scene.lights import emitter_radiance, environment_eval, environment_pdf, light_pdf_emitter, sample_light
from grisx.scene.scene import SceneData, finite_or_dropped, intersect, light_occluded, spawn_origin, surface_material
from grisx.theory.mis import power_heuristic
from grisx.theory.random import random_key, random_subkey, random_uniform

wp.set_module_options({"enable_backward": False})

__all__ = ["PathTracer", "PathRadiance", "make_path_tracer_kernel", "make_trace_path", "STRATEGIES", "create_path_tracer"]

#: sampling strategies: both techniques with MIS, or one alone
STRATEGIES = {"mis": 0, "nee": 1, "bsdf": 2}

_KERNELS: dict[frozenset[int], Any] = {}


_TRACE_PATHS: dict[frozenset[int], Any] = {}


@wp.struct
class PathRadiance:
    """One traced path's estimate: all of it, and the part of its first ``prefix_depth`` segments."""

    total: wp.vec3
    prefix: wp.vec3  # = what the same path (same random numbers) gives with max_depth = prefix_depth


def make_trace_path(kinds: frozenset[int]) -> Any:
    """``trace_path(scene, o, d, key, max_depth, rr_depth, strategy, prefix_depth) -> PathRadiance``
    for the material kinds ``kinds`` (cached): the radiance arriving at o from direction d, emission at
    the first hit included. Renderers that need the path tracer's estimate at a point (ReSTIR GI's
    outgoing radiance at a sample point) call this very function.

    ``prefix`` is the estimate truncated to ``prefix_depth`` segments (Mitsuba's max_depth), from the
    same path: a renderer that needs both (direct light and the rest; one bounce and all of them)
    traces once. ``prefix_depth`` < 0: ``prefix`` = ``total``."""
    kinds = frozenset(kinds)
    if kinds in _TRACE_PATHS:
        return _TRACE_PATHS[kinds]
    bsdf = make_bsdf(kinds)

    @wp.func
    def trace_path(
        scene: SceneData, o: wp.vec3, d: wp.vec3, key: wp.uint32, max_depth: int, rr_depth: int, strategy: int, prefix_depth: int
    ) -> PathRadiance:
        out = PathRadiance()
        have_prefix = int(0)
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
            si = intersect(scene, o, d, 1.0e30)
            c = 8 * depth
            # ---- emission reached by the previous BSDF sample (or the camera ray) ----
            if si.valid == 0:
                le = environment_eval(scene.lights, d)
                if wp.length_sq(le) > 0.0:
                    w = float(1.0)
                    if prev_delta == 0:
                        if not use_bsdf_emission:
                            w = 0.0
                        elif use_nee:
                            w = power_heuristic(prev_pdf, environment_pdf(scene.lights, d))
                    L += wp.cw_mul(beta, le) * w
                break
            le = emitter_radiance(scene.lights, si.tri, si.ng, -d)
            if wp.length_sq(le) > 0.0:
                w = float(1.0)
                if prev_delta == 0:
                    if not use_bsdf_emission:
                        w = 0.0
                    elif use_nee:
                        w = power_heuristic(prev_pdf, light_pdf_emitter(scene.lights, si.tri, prev_p, si.p, si.ng))
                L += wp.cw_mul(beta, le) * w
            if depth + 1 == prefix_depth:
                out.prefix = L  # a path of max_depth = prefix_depth would stop here
                have_prefix = 1
            if max_depth >= 0 and depth + 1 >= max_depth:
                break
            m = surface_material(scene, si)
            frame = frame_from_normal(si.ns)
            wo = to_local(frame, -d)
            # ---- next-event estimation ----
            if use_nee and bsdf.is_delta(m) == 0:
                ls = sample_light(
                    scene.lights, si.p, random_uniform(key, c + 0), wp.vec2(random_uniform(key, c + 1), random_uniform(key, c + 2))
                )
                if ls.pdf > 0.0 and wp.length_sq(ls.radiance) > 0.0:
                    wi = to_local(frame, ls.wi)
                    f = bsdf.eval(m, wo, wi)
                    if wp.length_sq(f) > 0.0:
                        if not light_occluded(scene, si.p, si.ng, ls):
                            w = float(1.0)
                            if ls.delta == 0 and use_bsdf_emission:
                                w = power_heuristic(ls.pdf, bsdf.pdf(m, wo, wi))
                            L += wp.cw_mul(beta, wp.cw_mul(f, ls.radiance)) * (w / ls.pdf)
            # ---- BSDF sampling ----
            bs = bsdf.sample(m, wo, random_uniform(key, c + 3), wp.vec2(random_uniform(key, c + 4), random_uniform(key, c + 5)))
            if bs.valid == 0:
                break
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
                q = wp.min(wp.max(beta) * eta * eta, 0.95)
                if random_uniform(key, c + 6) >= q:
                    break
                beta = beta / q
        out.total = L
        if have_prefix == 0:
            out.prefix = L  # the path ended before prefix_depth segments (or prefix_depth < 0)
        return out

    _TRACE_PATHS[kinds] = trace_path
    return trace_path


def make_path_tracer_kernel(kinds: frozenset[int]) -> Any:
    """The sample-pass kernel compiled for the material kinds ``kinds`` (cached)."""
    if kinds in _KERNELS:
        return _KERNELS[kinds]
    trace_path = make_trace_path(kinds)

    module = specialized_module(__name__, kinds)

    @wp.kernel(module=module)
    def sample_pass(
        scene: SceneData,
        cam: CameraData,
        seed: int,
        frame: int,
        sample: int,
        max_depth: int,
        rr_depth: int,
        strategy: int,
        jitter: int,
        total: wp.array2d(dtype=wp.vec3),
        total_sq: wp.array2d(dtype=wp.vec3),
        nonfinite: wp.array(dtype=wp.int32),
    ):
        y, x = wp.tid()
        pixel = y * cam.width + x
        key = random_subkey(random_subkey(random_key(seed, frame), pixel), sample)
        # counters 0–3 of the key are the camera's (box filter over the pixel and the lens; jitter = 0: the
        # pixel centre through the lens centre, as an unjittered G-buffer sees it); paths use subkey 1
        cs = sample_camera(key, x, y, jitter)
        ray = camera_ray(cam, cs.pixel[0], cs.pixel[1], cs.lens)
        L = trace_path(scene, ray.o, ray.d, random_subkey(key, 1), max_depth, rr_depth, strategy, -1).total
        L = finite_or_dropped(L, nonfinite)
        total[y, x] = total[y, x] + L
        total_sq[y, x] = total_sq[y, x] + wp.cw_mul(L, L)

    _KERNELS[kinds] = sample_pass
    return sample_pass


@wp.kernel
def _scale(total: wp.array2d(dtype=wp.vec3), s: float, out: wp.array2d(dtype=wp.vec3)):
    y, x = wp.tid()
    out[y, x] = total[y, x] * s


class PathTracer:
    """Progressive path tracing of a built scene: ``spp`` sample passes per frame."""

    def __init__(
        self,
        built: Any,
        width: int,
        height: int,
        *,
        spp: int = 1,
        max_depth: int = 16,
        rr_depth: int = 5,
        strategy: str = "mis",
        seed: int = 0,
        timer: Any = None,
        kinds: frozenset[int] | None = None,
        jitter: bool = True,
    ) -> None:
        self.built = built
        self.width, self.height = int(width), int(height)
        self.spp = int(spp)
        self.max_depth = int(max_depth)
        self.rr_depth = int(rr_depth)
        self.strategy = STRATEGIES[strategy]
        self.seed = int(seed)
        self.timer = timer
        self.jitter = int(bool(jitter))
        # compile only the scene's material kinds (``kinds`` overrides, e.g. to measure the gain)
        self.kernel = make_path_tracer_kernel(frozenset(built.features.material_kinds if kinds is None else kinds))
        dev = built.device
        self.total = wp.zeros((self.height, self.width), dtype=wp.vec3, device=dev)
        self.total_sq = wp.zeros((self.height, self.width), dtype=wp.vec3, device=dev)
        self.nonfinite = wp.zeros(1, dtype=wp.int32, device=dev)
        self.image = wp.zeros((self.height, self.width), dtype=wp.vec3, device=dev)
        self.samples = 0

    def kernels(self) -> list[Any]:
        return [self.kernel, _scale]

    def reset(self) -> None:
        self.total.zero_()
        self.total_sq.zero_()
        self.samples = 0

    def add_samples(self, frame: int, count: int) -> None:
        """Trace ``count`` more samples per pixel of frame ``frame`` into the running sums."""
        cam = self.built.camera_data(float(frame), self.width, self.height)
        for _ in range(count):
            wp.launch(
                self.kernel,
                dim=(self.height, self.width),
                inputs=[self.built.data, cam, self.seed, int(frame), self.samples, self.max_depth, self.rr_depth, self.strategy, self.jitter],
                outputs=[self.total, self.total_sq, self.nonfinite],
                device=self.built.device,
            )
            self.samples += 1

    def render_frame(self, frame: int) -> wp.array:
        """A fresh ``spp``-sample estimate of frame ``frame`` (linear RGB, H×W, on the device)."""
        self.reset()
        if self.timer is not None:
            with self.timer("pt"):
                self.add_samples(frame, self.spp)
        else:
            self.add_samples(frame, self.spp)
        wp.launch(_scale, dim=self.total.shape, inputs=[self.total, 1.0 / max(self.samples, 1)], outputs=[self.image], device=self.built.device)
        return self.image

    def mean(self) -> np.ndarray:
        return self.total.numpy() / max(self.samples, 1)

    @property
    def nonfinite_samples(self) -> int:
        """Samples dropped because they were NaN or Inf (over the renderer's lifetime)."""
        return int(self.nonfinite.numpy()[0])

    def variance_of_mean(self) -> np.ndarray:
        """Per-pixel sample variance divided by the sample count (the squared standard error)."""
        n = max(self.samples, 1)
        mean = self.total.numpy().astype(np.float64) / n
        var = np.maximum(self.total_sq.numpy().astype(np.float64) / n - mean**2, 0.0) * n / max(n - 1, 1)
        return (var / n).astype(np.float32)


def create_path_tracer(ctx: Any) -> PathTracer:
    p = ctx.params
    return PathTracer(
        ctx.built,
        ctx.width,
        ctx.height,
        spp=p["spp"],
        max_depth=p["max_depth"],
        rr_depth=p["rr_depth"],
        strategy=p["strategy"],
        seed=ctx.seed,
        timer=ctx.timer,
    )
