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
from grisx.params import Param
from grisx.render.registry import RenderMethod, create_renderer, register, renderer_params
from grisx.scene.bsdf import cosine_hemisphere_pdf, make_bsdf, sample_cosine_hemisphere
from grisx.scene.camera import CameraData, camera_ray, sample_camera
from grisx.scene.frame import frame_from_normal, to_local, to_world
from grisx.scene.lights import emitter_radiance, environment_eval, environment_pdf, light_pdf_emitter, sample_light
from grisx.scene.material import MATERIAL_ROUGH_DIELECTRIC
from grisx.scene.scene import SceneData, finite_or_dropped, intersect, light_occluded, spawn_origin, surface_material
from grisx.theory.mis import power_heuristic
from grisx.theory.roulette import roulette_survival
from grisx.theory.random import random_key, random_subkey, random_uniform

wp.set_module_options({"enable_backward": False})

__all__ = ["PathTracer", "PathRadiance", "make_path_tracer_kernel", "make_trace_path", "STRATEGIES", "create_path_tracer"]

#: sampling strategies: both techniques with MIS, or one alone
STRATEGIES = {"mis": 0, "nee": 1, "bsdf": 2}

_KERNELS: dict[frozenset[int], Any] = {}


_TRACE_PATHS: dict[frozenset[int], Any] = {}


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


def make_trace_path(kinds: frozenset[int]) -> Any:
    """``trace_path(scene, o, d, key, max_depth, rr_depth, strategy, prefix_depth, record) -> PathRadiance``
    for the material kinds ``kinds`` (cached): the radiance arriving at o from direction d, emission at
    the first hit included. Renderers that need the path tracer's estimate at a point (ReSTIR GI's
    outgoing radiance at a sample point) call this very function.

    ``prefix`` is the estimate truncated to ``prefix_depth`` segments (Mitsuba's max_depth), from the
    same path: a renderer that needs both (direct light and the rest; one bounce and all of them)
    traces once. ``prefix_depth`` < 0: ``prefix`` = ``total``. ``record`` = 1 fills the first hit's
    technique records of :class:`PathRadiance` (the path itself is the same)."""
    kinds = frozenset(kinds)
    if kinds in _TRACE_PATHS:
        return _TRACE_PATHS[kinds]
    bsdf = make_bsdf(kinds)

    @wp.func
    def trace_path(
        scene: SceneData, o: wp.vec3, d: wp.vec3, key: wp.uint32, max_depth: int, rr_depth: int, strategy: int, prefix_depth: int, record: int
    ) -> PathRadiance:
        out = PathRadiance()
        zero = wp.vec3(0.0, 0.0, 0.0)
        out.nee_wi = zero
        out.nee_li = zero
        out.bs_wi = zero
        out.bs_li = zero
        out.bs_li_prefix = zero
        out.recorded = 0
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
            si = intersect(scene, o, d, 1.0e30)
            c = 8 * depth
            # ---- emission reached by the previous BSDF sample (or the camera ray) ----
            le = wp.vec3(0.0, 0.0, 0.0)
            if si.valid == 0:
                le = environment_eval(scene.lights, d)
            else:
                le = emitter_radiance(scene.lights, si.tri, si.ng, -d)
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
                        w = power_heuristic(prev_pdf, light_pdf)
                L += wp.cw_mul(beta, le) * w
                if record != 0:
                    out.bs_li += wp.cw_mul(gamma, le) * w
            if si.valid == 0:
                break
            if depth + 1 == prefix_depth:
                out.prefix = L  # a path of max_depth = prefix_depth would stop here
                out.bs_li_prefix = out.bs_li
                have_prefix = 1
            if max_depth >= 0 and depth + 1 >= max_depth:
                break
            m = surface_material(scene, si)
            frame = frame_from_normal(si.ns)
            wo = to_local(frame, -d)
            # record: a view-independent first vertex (cosine-weighted continuation), where the BSDF allows
            view_free = int(0)
            if record != 0 and depth == 0 and bsdf.is_delta(m) == 0 and m.kind != MATERIAL_ROUGH_DIELECTRIC and wo[2] != 0.0:
                view_free = 1
                out.recorded = 1
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
                                if view_free != 0:
                                    w = power_heuristic(ls.pdf, cosine_hemisphere_pdf(wi * wp.sign(wo[2])))
                                else:
                                    w = power_heuristic(ls.pdf, bsdf.pdf(m, wo, wi))
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
        L = trace_path(scene, ray.o, ray.d, random_subkey(key, 1), max_depth, rr_depth, strategy, -1, 0).total
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

# ---- registration (grisx.render.registry): the method, its params (defaults: the constructor's) ----

register(
    RenderMethod(
        "pt",
        "reference path tracer: BSDF sampling + next-event estimation, power-heuristic MIS, Russian roulette",
        create_path_tracer,
        params=renderer_params(
            PathTracer,
            Param("max_depth", ..., "longest path in segments, Mitsuba's meaning (1: emitters only, 2: + direct light, -1: unbounded); default: the scene's", kind="int", minimum=-1),
            Param("rr_depth", ..., "depth from which Russian roulette may end paths", kind="int", minimum=1),
            Param("strategy", ..., "mis: NEE and BSDF sampling with the power heuristic; nee or bsdf: one technique alone", kind="choice", choices=("mis", "nee", "bsdf")),
        ),
        uses_spp=True,
    )
)
