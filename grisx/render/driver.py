"""Rendering: named methods over named or loaded scenes, frame by frame.

:func:`render` is the one driver behind ``grisx render`` and the benchmark
runner. It resolves the scene (a built-in name from :mod:`grisx.scene.builtin`
or a Mitsuba XML file), uploads it, and runs a *method* — a renderer object
with ``render_frame(frame) -> wp.array2d(vec3)`` — for ``frames`` frames,
moving the scene and camera along their paths, optionally averaging all
frames (``accumulate``: how a reuse method converges under a static camera).
Per-pass timings come from a :class:`PassTimer` that synchronizes the device
before reading the clock, so GPU times are real.

Methods register in :data:`METHODS` with their options (``--param k=v``,
parsed by :class:`~grisx.theory.toys.base.Param`). The debug views
(``gbuffer``, ``albedo``, ``normal``, ``depth``, ``motion``) show the
G-buffer every renderer reads.
"""

from __future__ import annotations

import dataclasses
import importlib
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import warp as wp

from grisx.device import resolve_device, synchronize
from grisx.errors import InvalidParameterError, InvalidValueError, UnknownNameError
from grisx.theory.toys.base import Param

__all__ = ["METHODS", "RenderMethod", "RenderContext", "RenderResult", "PassTimer", "render", "load_scene", "parse_res", "method_params"]


wp.set_module_options({"enable_backward": False})


@wp.kernel
def _accumulate(acc: wp.array2d(dtype=wp.vec3d), img: wp.array2d(dtype=wp.vec3)):
    y, x = wp.tid()
    v = img[y, x]
    acc[y, x] = acc[y, x] + wp.vec3d(wp.float64(v[0]), wp.float64(v[1]), wp.float64(v[2]))


@wp.kernel
def _average(acc: wp.array2d(dtype=wp.vec3d), inv_n: wp.float64, out: wp.array2d(dtype=wp.vec3)):
    y, x = wp.tid()
    a = acc[y, x] * inv_n
    out[y, x] = wp.vec3(wp.float32(a[0]), wp.float32(a[1]), wp.float32(a[2]))


class PassTimer:
    """Wall-clock seconds per named pass, measured between device synchronizations."""

    def __init__(self, device: wp.context.Device) -> None:
        self.device = device
        self.seconds: dict[str, float] = {}

    def __call__(self, name: str) -> _PassScope:
        return _PassScope(self, name)


class _PassScope:
    def __init__(self, timer: PassTimer, name: str) -> None:
        self.timer, self.name = timer, name

    def __enter__(self) -> None:
        synchronize(self.timer.device)
        self.start = time.perf_counter()

    def __exit__(self, *exc: Any) -> None:
        synchronize(self.timer.device)
        self.timer.seconds[self.name] = self.timer.seconds.get(self.name, 0.0) + time.perf_counter() - self.start


@dataclasses.dataclass
class RenderContext:
    """What a renderer is created with."""

    built: Any  # BuiltScene
    width: int
    height: int
    params: dict[str, Any]  # the method's params, resolved, plus "spp"
    seed: int
    timer: PassTimer
    method: str


@dataclasses.dataclass(frozen=True)
class RenderMethod:
    """A named renderer: ``module.factory(ctx: RenderContext)`` → object with ``render_frame(frame)``."""

    name: str
    summary: str
    module: str  # imported lazily: compiling a renderer's kernels costs only when it is used
    factory: str
    params: tuple[Param, ...] = ()
    kind: str = "radiance"  # "radiance" (linear RGB) or "debug" (a G-buffer view)
    #: the path tracer's max_depth whose image this method estimates (None: the scene's own)
    reference_max_depth: int | None = None
    #: whether ``spp`` (samples per pixel per frame) means anything to it; the others take one sample a frame
    uses_spp: bool = False

    def create(self, ctx: RenderContext) -> Any:
        return getattr(importlib.import_module(self.module), self.factory)(ctx)


METHODS: dict[str, RenderMethod] = {}


def register(method: RenderMethod) -> RenderMethod:
    METHODS[method.name] = method
    return method


for _view, _doc in (
    ("gbuffer", "every G-buffer field (one EXR per field) and a contact sheet PNG"),
    ("albedo", "albedo at the primary hit"),
    ("normal", "shading normal at the primary hit (n/2 + 1/2 in the PNG)"),
    ("depth", "camera-space depth of the primary hit"),
    ("motion", "motion vector into the previous frame, in pixels (EXR: dx, dy, 0)"),
):
    register(RenderMethod(_view, _doc, "grisx.render.views", "create_view", kind="debug"))


register(
    RenderMethod(
        "pt",
        "reference path tracer: BSDF sampling + next-event estimation, power-heuristic MIS, Russian roulette",
        "grisx.render.pt",
        "create_path_tracer",
        params=(
            Param("max_depth", 16, "longest path in segments, Mitsuba's meaning (1: emitters only, 2: + direct light, -1: unbounded); default: the scene's", kind="int", minimum=-1),
            Param("rr_depth", 5, "depth from which Russian roulette may end paths", kind="int", minimum=1),
            Param("strategy", "mis", "mis: NEE and BSDF sampling with the power heuristic; nee or bsdf: one technique alone", kind="choice", choices=("mis", "nee", "bsdf")),
        ),
        uses_spp=True,
    )
)


# ---- restir-di / restir-gi (issue 10): registered here by grisx.render.restir_di / restir_gi ----

register(
    RenderMethod(
        "restir-di",
        "ReSTIR DI (Bitterli et al. 2020): 32 light + 1 BSDF candidates, visibility before reuse, temporal and spatial reuse with pairwise MIS; emitted + direct light (pt's max_depth=2)",
        "grisx.render.restir_di",
        "create_restir_di",
        reference_max_depth=2,
        params=(
            Param("light_candidates", 32, "initial light-sampled candidates per pixel", kind="int", minimum=0, maximum=1024),
            Param("bsdf_candidates", 1, "initial BSDF-sampled candidates per pixel", kind="int", minimum=0, maximum=64),
            Param("temporal", True, "reuse the previous frame's reservoir (reprojected)", kind="bool"),
            Param("spatial", True, "reuse neighbouring pixels' reservoirs", kind="bool"),
            Param("neighbors", 5, "spatial neighbours per pixel", kind="int", minimum=0, maximum=64),
            Param("radius", 30.0, "spatial reuse radius in pixels", minimum=1.0),
            Param("history_cap", 20.0, "cap on a reused reservoir's confidence M (the history cap)", minimum=0.0),
            Param("unbiased", True, "true: targets at other pixels include their visibility (shadow rays), unbiased; false: unshadowed, cheaper, biased", kind="bool"),
            Param("jitter", True, "visible point uniform over the pixel each frame (box filter: what pt estimates); false: pixel centres", kind="bool"),
        ),
    )
)

register(
    RenderMethod(
        "restir-gi",
        "ReSTIR GI (seed 004): sample points resampled in temporal and spatial reservoir buffers with the reconnection Jacobian (Eq. 11); full global illumination",
        "grisx.render.restir_gi",
        "create_restir_gi",
        params=(
            Param("source", "uniform", "initial direction pdf (Alg. 2)", kind="choice", choices=("uniform", "cosine", "bsdf")),
            Param("target", "full", "full: Eq. 9 (L_o f cos); radiance: Eq. 10 (L_o)", kind="choice", choices=("full", "radiance")),
            Param("jacobian", True, "reconnection Jacobian of Eq. 11 (false reproduces Fig. 7's bias)", kind="bool"),
            Param("unbiased", True, "true: Z counts only domains that can produce the sample (visibility rays, Alg. 4 l. 16-19); false: Z = sum of M", kind="bool"),
            Param("temporal", True, "temporal resampling (Alg. 3)", kind="bool"),
            Param("spatial", True, "spatial resampling (Alg. 4)", kind="bool"),
            Param("temporal_cap", 30.0, "M cap of temporal reservoirs", minimum=0.0),
            Param("spatial_cap", 500.0, "M cap of spatial reservoirs", minimum=0.0),
            Param("iterations_low", 9, "maxIterations while the spatial reservoir's M < spatial_cap/2", kind="int", minimum=0, maximum=64),
            Param("iterations_high", 3, "maxIterations otherwise", kind="int", minimum=0, maximum=64),
            Param("adaptive_radius", True, "radius 10% of the image, halved per rejected neighbour down to min_radius; false: fixed radius", kind="bool"),
            Param("radius", 30.0, "fixed spatial radius in pixels (adaptive_radius=false)", minimum=1.0),
            Param("min_radius", 3.0, "smallest adaptive radius in pixels", minimum=1.0),
            Param("low_m", 10.0, "a pixel whose spatial reservoir has M below this reuses neighbours' spatial reservoirs (Fig. 10); 0: never", minimum=0.0),
            Param("max_depth", 16, "longest path in segments from the camera, Mitsuba's meaning (as pt); default: the scene's", kind="int", minimum=-1),
            Param("rr_depth", 5, "depth from which Russian roulette may end the paths at sample points", kind="int", minimum=1),
            Param("mb_fraction", 0.25, "probability that a 64x32 tile follows multi-bounce paths (tile Russian roulette)", minimum=1e-3, maximum=1.0),
            Param("validation_interval", 6, "replay and validate reservoir samples every N frames; 0: never", kind="int", minimum=0),
            Param("validation_tolerance", 0.2, "relative change of L_o that invalidates a sample", minimum=0.0),
            Param("direct", "auto", "direct light: nee (path-traced, NEE + BSDF with MIS), restir-di, or auto (restir-di above 16 lights: where it is better, measured)", kind="choice", choices=("auto", "nee", "restir-di")),
            Param("exact_bsdf", False, "re-evaluate the sample point's BSDF toward each visible point reusing it; false: its radiance reused as if Lambertian (the paper)", kind="bool"),
            Param("max_jacobian", 10.0, "reject reconnections with |J| above this (counted the same way in Z: still unbiased); 0: never (the paper)", minimum=0.0),
            Param("jitter", True, "visible point uniform over the pixel each frame (box filter: what pt estimates); false: pixel centres", kind="bool"),
        ),
    )
)

# ---- restir-pt (issue 11): registered here by grisx.render.restir_pt ----

register(
    RenderMethod(
        "restir-pt",
        "ReSTIR PT (Lin et al. 2022): path reservoirs with temporal and spatial GRIS reuse through replay, reconnection or hybrid shifts",
        "grisx.render.restir_pt",
        "create_restir_pt",
        params=(
            Param("shift", "hybrid", "path shift: hybrid (replay until two rough vertices, then reconnect), reconnection (at x2) or replay", kind="choice", choices=("hybrid", "reconnection", "replay")),
            Param("candidates", 1, "initial path-tracer candidates per pixel and frame (1 real-time, 32 offline)", kind="int", minimum=1),
            Param("max_depth", 16, "longest path in segments from the camera, Mitsuba's meaning (as pt; -1: unbounded); default: the scene's", kind="int", minimum=-1),
            Param("rr_depth", 5, "depth from which Russian roulette may end paths (as pt)", kind="int", minimum=1),
            Param("temporal", True, "temporal reuse (generalized balance MIS)", kind="bool"),
            Param("spatial_rounds", 1, "rounds of spatial reuse (pairwise MIS)", kind="int", minimum=0, maximum=8),
            Param("neighbors", 3, "spatial neighbours per round", kind="int", minimum=0, maximum=16),
            Param("radius", 20.0, "spatial reuse radius in pixels", minimum=1.0),
            Param("history_cap", 20.0, "temporal confidence cap (<= 0: none)"),
            Param("rough_threshold", 0.2, "hybrid shift: vertices rougher than this may be reconnected", minimum=0.0),
            Param("near_field", 0.01, "hybrid shift: reconnection segments must be longer than this fraction of the scene radius", minimum=0.0),
            Param("jacobian", True, "use shift Jacobians (false: |J| = 1, the biased ablation)", kind="bool"),
            Param("jacobian_max", 0.0, "reject shifts with |J| outside [1/J_max, J_max] (0: no threshold)", minimum=0.0),
        ),
    )
)


def method_params(method: str, params: Mapping[str, Any] | None) -> dict[str, Any]:
    """Defaults of ``method`` merged with ``params``, parsed and range-checked."""
    if method not in METHODS:
        raise UnknownNameError("render method", method, sorted(METHODS))
    m = METHODS[method]
    known = {p.name: p for p in m.params}
    out = {name: p.default for name, p in known.items()}
    for key, value in (params or {}).items():
        if key not in known:
            raise UnknownNameError(f"param of render method '{method}'", key, sorted(known))
        out[key] = known[key].parse(value, method)
    return out


def parse_res(text: str) -> tuple[int, int]:
    """'WxH' → (W, H)."""
    try:
        w, h = (int(v) for v in str(text).lower().split("x"))
    except ValueError:
        raise InvalidParameterError(f"--res expects WxH (e.g. 640x480), got '{text}'") from None
    if not (1 <= w <= 16384 and 1 <= h <= 16384):
        raise InvalidParameterError(f"--res must be between 1x1 and 16384x16384, got '{text}'")
    return w, h


def load_scene(scene: str, params: Mapping[str, Any] | None = None) -> Any:
    """A :class:`~grisx.scene.scene.Scene` from a built-in name or a Mitsuba XML path."""
    from grisx.scene.builtin import BUILTIN_SCENES, build_builtin

    if scene in BUILTIN_SCENES:
        return build_builtin(scene)
    path = Path(scene)
    if path.suffix.lower() == ".xml" or path.exists():
        if not path.is_file():
            raise InvalidParameterError(f"scene file '{scene}' does not exist")
        from grisx.scene.mitsuba import load_mitsuba

        return load_mitsuba(path, params)
    raise UnknownNameError("scene", scene, sorted(BUILTIN_SCENES) + ["<file.xml>"])


@dataclasses.dataclass
class RenderResult:
    """What :func:`render` returns."""

    image: np.ndarray  # (H, W, 3) float32 linear (or the view's channels for debug methods)
    frames: int
    spp: int
    seconds: float
    pass_seconds: dict[str, float]
    device: str
    settings: dict[str, Any]
    extra: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)  # e.g. every G-buffer field


def render(
    scene: str | Any,
    method: str,
    *,
    spp: int | None = None,
    frames: int = 1,
    accumulate: bool = False,
    res: tuple[int, int] | None = None,
    device: str = "cpu",
    seed: int = 0,
    params: Mapping[str, Any] | None = None,
    on_frame: Callable[[int, np.ndarray, float], None] | None = None,
    progress: Callable[[int, int], None] | None = None,
    camera: str = "auto",
) -> RenderResult:
    """Render ``scene`` with ``method`` for ``frames`` frames; see the module docstring.

    ``scene`` is a built-in name, a path to a Mitsuba XML file, or a
    :class:`~grisx.scene.scene.Scene`. ``spp`` defaults to the scene's
    (a file's ``sampler`` ``sample_count``). ``on_frame(i, image, seconds)``
    is called after each frame with the device synchronized (the image is the
    running average when ``accumulate``). ``camera``: ``"static"`` (the
    scene's default camera), ``"path"`` (its camera path, frame by frame) or
    ``"auto"``: the path when several frames are rendered without
    ``accumulate`` (averaging frames only converges under a static camera).
    """
    from grisx.scene.scene import Scene

    if method not in METHODS:
        raise UnknownNameError("render method", method, sorted(METHODS))
    spec = METHODS[method]
    resolved = method_params(method, params)
    if isinstance(frames, bool) or not isinstance(frames, (int, np.integer)) or frames < 1:
        raise InvalidParameterError(f"frames must be a positive integer, got {frames!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not (0 <= seed < 2**31):
        raise InvalidParameterError(f"seed must be an integer in [0, 2^31), got {seed!r}")
    sc = scene if isinstance(scene, Scene) else load_scene(str(scene))
    # a scene file's integrator settings (max_depth, rr_depth) are the defaults of the method's params
    for key in ("max_depth", "rr_depth"):
        if key in resolved and key not in (params or {}) and key in sc.defaults:
            resolved[key] = int(sc.defaults[key])
    if "max_depth" in resolved:
        if resolved["max_depth"] == 0:
            raise InvalidParameterError("param 'max_depth' must be -1 (unbounded) or >= 1, got 0")
    if isinstance(spp, bool) or (spp is not None and (not isinstance(spp, (int, np.integer)) or spp < 1)):
        raise InvalidParameterError(f"spp must be a positive integer, got {spp!r}")
    if not spec.uses_spp:
        if spp is not None and spp != 1:
            raise InvalidParameterError(f"method '{method}' takes one sample per pixel per frame: spp does not apply (use --frames)")
        spp = 1
    spp = int(sc.defaults.get("spp", 16)) if spp is None else spp
    width, height = res if res is not None else (sc.film.width, sc.film.height)
    dev = resolve_device(device)
    if camera not in ("auto", "static", "path"):
        raise InvalidParameterError(f"camera must be auto, static or path, got {camera!r}")
    built = sc.build(dev)
    built.animate_camera = camera == "path" or (camera == "auto" and frames > 1 and not accumulate)
    timer = PassTimer(dev)
    renderer = spec.create(RenderContext(built, width, height, {**resolved, "spp": int(spp)}, int(seed), timer, method))
    for kernel in renderer.kernels() if hasattr(renderer, "kernels") else ():
        wp.load_module(kernel.module, device=dev)  # compiling is not rendering: keep it off the clock
    for kernel in (_accumulate, _average):
        wp.load_module(kernel.module, device=dev)
    acc = None  # running sum: on the device (float64) for device frames, on the host otherwise
    average = None
    image = None
    synchronize(dev)
    start = time.perf_counter()
    for f in range(frames):
        with timer("scene_update"):
            built.set_frame(float(f))
        frame_img = renderer.render_frame(f)
        need_host = on_frame is not None or f == frames - 1  # data stays on the device otherwise
        if isinstance(frame_img, wp.array):
            if accumulate:
                if acc is None:
                    acc = wp.zeros(frame_img.shape, dtype=wp.vec3d, device=dev)
                    average = wp.empty(frame_img.shape, dtype=wp.vec3, device=dev)
                wp.launch(_accumulate, dim=frame_img.shape, inputs=[acc, frame_img], device=dev)
                if need_host:
                    wp.launch(_average, dim=frame_img.shape, inputs=[acc, wp.float64(1.0 / (f + 1))], outputs=[average], device=dev)
                    image = average.numpy()
            elif need_host:
                image = frame_img.numpy()
        else:
            host = np.asarray(frame_img)
            if accumulate:
                acc = host.astype(np.float64) if acc is None else acc + host
                image = (acc / (f + 1)).astype(np.float32)
            else:
                image = host.astype(np.float32)
        synchronize(dev)
        if on_frame is not None:
            on_frame(f, image, time.perf_counter() - start)
        if progress is not None:
            progress(f + 1, frames)
    seconds = time.perf_counter() - start
    bad = int(np.count_nonzero(~np.isfinite(image)))
    if bad:
        raise InvalidValueError(f"render '{method}' of '{sc.name}' produced {bad} NaN/Inf values")
    extra = renderer.extra() if hasattr(renderer, "extra") else {}
    settings = {
        "scene": sc.name,
        "method": method,
        "params": {**resolved, **getattr(renderer, "resolved_params", {})},  # "auto" params as the renderer resolved them
        "width": width,
        "height": height,
        "spp": int(spp),
        "frames": int(frames),
        "accumulate": bool(accumulate),
        "camera": "path" if built.animate_camera else "static",
        "seed": int(seed),
        "features": built.features.to_dict(),
        "triangles": built.num_triangles,
    }
    if hasattr(renderer, "nonfinite_samples"):
        settings["nonfinite_samples"] = renderer.nonfinite_samples  # dropped NaN/Inf samples; 0 expected
    return RenderResult(
        image=image,
        frames=int(frames),
        spp=int(spp),
        seconds=seconds,
        pass_seconds=dict(timer.seconds),
        device=str(dev),
        settings=settings,
        extra=extra,
    )
