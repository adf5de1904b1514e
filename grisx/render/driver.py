"""Rendering: named methods over named or loaded scenes, frame by frame.

:func:`render` is the one driver behind ``grisx render`` and the benchmark
runner. It resolves the scene (a built-in name from :mod:`grisx.scene.builtin`
or a Mitsuba XML file), uploads it, and runs a *method* — a renderer object
with ``render_frame(frame) -> wp.array2d(vec3)`` — for ``frames`` frames,
moving the scene and camera along their paths, optionally averaging all
frames (``accumulate``: how a reuse method converges under a static camera).
Per-pass timings come from a :class:`PassTimer` that synchronizes the device
before reading the clock, so GPU times are real. ``RenderResult.frame_seconds``
is each frame's time on the same clock: from a synchronized device to the
frame's last pass finished, the copy of the image to the host excluded — the
one way every method, ``pt`` included, is timed by the benchmark protocol.

Each renderer module registers its methods and options (``--param k=v``)
itself, in :mod:`grisx.render.base.registry`'s :data:`METHODS`; importing this
module loads them all. The debug views
(``gbuffer``, ``albedo``, ``normal``, ``depth``, ``motion``) show the
G-buffer every renderer reads.
"""

from __future__ import annotations

import contextlib
import dataclasses
import time
import warnings
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import warp as wp

from grisx.device import launch, load_kernels, resolve_device, synchronize
from grisx.errors import INT32_MAX, GrisxWarning, InvalidParameterError, InvalidValueError, UnknownNameError
from grisx.render.base.registry import METHODS, RenderContext, RenderMethod, load_plugins, method_params
from grisx.scene.material import MATERIAL_KIND_NAMES

__all__ = ["METHODS", "RenderMethod", "RenderContext", "RenderResult", "PassTimer", "render", "load_scene", "parse_res", "check_res",
           "method_params"]


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


#: the largest film side ``res`` may ask for
MAX_RES = 16384
#: a floor on the memory one pixel takes while rendering (image, sums, host copies, output encoding): a
#: ``res`` that needs more than the memory available is refused before anything is allocated
PIXEL_BYTES = 256


def parse_res(text: str) -> tuple[int, int]:
    """'WxH' → (W, H)."""
    try:
        w, h = (int(v) for v in str(text).lower().split("x"))
    except ValueError:
        raise InvalidParameterError(f"--res expects WxH (e.g. 640x480), got '{text}'") from None
    if not (1 <= w <= MAX_RES and 1 <= h <= MAX_RES):
        raise InvalidParameterError(f"--res must be between 1x1 and {MAX_RES}x{MAX_RES}, got '{text}'")
    return w, h


def check_res(res: Any) -> tuple[int, int]:
    """``res`` as (width, height) of whole numbers in [1, MAX_RES]; anything else is one clear error."""
    if isinstance(res, (str, bytes)) or not hasattr(res, "__len__") or len(res) != 2:
        raise InvalidParameterError(f"res must be (width, height), got {res!r}")
    out = []
    for name, v in zip(("width", "height"), res):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
            raise InvalidParameterError(f"res: {name} must be an integer, got {v!r}")
        if not 1 <= v <= MAX_RES:
            raise InvalidParameterError(f"res: {name} must be between 1 and {MAX_RES}, got {v}")
        out.append(int(v))
    return out[0], out[1]


def check_memory(width: int, height: int, dev: Any, what: str) -> None:
    """Refuse a film that cannot fit: at least :data:`PIXEL_BYTES` a pixel against the memory available."""
    from grisx.device import available_memory

    need = width * height * PIXEL_BYTES
    free = available_memory(dev)
    if free is not None and need > free:
        raise InvalidParameterError(f"{what} at {width}x{height} needs at least {need / 2**30:.1f} GiB "
                                    f"({PIXEL_BYTES} bytes a pixel); {dev} has {free / 2**30:.1f} GiB available")


def load_scene(scene: str, params: Mapping[str, Any] | None = None) -> Any:
    """A :class:`~grisx.scene.scene.Scene` from a built-in name or a Mitsuba XML path."""
    from grisx.scene.builtin import BUILTIN_SCENES, build_builtin

    if scene in BUILTIN_SCENES:
        return build_builtin(scene)
    path = Path(scene)
    if path.suffix.lower() == ".xml" or path.exists():
        if path.is_dir():
            raise InvalidParameterError(f"scene '{scene}' is a directory, not a Mitsuba XML file")
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
    frame_seconds: list[float]  # each frame's device time (synchronized before and after; no host copy)
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
    on_sample: Callable[[int, int], None] | None = None,
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
    ``progress(frames_done, frames)`` is called before the first frame (0 done)
    and after each frame and, for the
    methods that take ``spp``, ``on_sample(samples_done, spp)`` after each
    sample pass within a frame. Non-finite samples that a renderer dropped are
    reported as a :class:`~grisx.errors.GrisxWarning`.
    """
    from grisx.scene.scene import Scene

    if not isinstance(method, str) or method not in METHODS:
        raise UnknownNameError("render method", str(method), sorted(METHODS))
    if not isinstance(scene, (str, Path, Scene)):
        raise InvalidParameterError(f"scene must be a built-in name, a Mitsuba XML path or a Scene, got {type(scene).__name__}")
    if params is not None and not isinstance(params, Mapping):
        raise InvalidParameterError(f"params must be a mapping of param name to value, got {type(params).__name__}")
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
    if int(spp) * int(frames) > INT32_MAX:  # the counter RNG numbers samples (frame * spp + s) in int32
        raise InvalidParameterError(f"spp x frames must be at most 2^31 - 1, got {spp} x {frames}")
    width, height = check_res(res if res is not None else (sc.film.width, sc.film.height))
    dev = resolve_device(device)
    check_memory(width, height, dev, f"render '{method}'")
    if camera not in ("auto", "static", "path"):
        raise InvalidParameterError(f"camera must be auto, static or path, got {camera!r}")
    built = sc.build(dev)
    built.animate_camera = camera == "path" or (camera == "auto" and frames > 1 and not accumulate)
    timer = PassTimer(dev)
    with _out_of_memory(width, height, dev, method):
        return _run(spec, method, sc, built, dev, timer, resolved, width, height, int(spp), int(frames), bool(accumulate),
                    int(seed), on_frame, progress, on_sample)


@contextlib.contextmanager
def _out_of_memory(width: int, height: int, dev: Any, method: str) -> Iterator[None]:
    """An allocation that fails (Warp's RuntimeError, numpy's MemoryError) as one clear error."""
    try:
        yield
    except (MemoryError, RuntimeError) as exc:
        if isinstance(exc, RuntimeError) and "allocate" not in str(exc):
            raise
        raise InvalidParameterError(f"not enough memory to render '{method}' at {width}x{height} on {dev}: "
                                    f"{str(exc) or type(exc).__name__}") from None


def _run(spec: RenderMethod, method: str, sc: Any, built: Any, dev: Any, timer: PassTimer, resolved: dict[str, Any],
         width: int, height: int, spp: int, frames: int, accumulate: bool, seed: int,
         on_frame: Any, progress: Any, on_sample: Any) -> RenderResult:
    renderer = spec.create(RenderContext(built, width, height, {**resolved, "spp": int(spp)}, int(seed), timer, method))
    if on_sample is not None and spec.uses_spp:
        renderer.on_sample = _SampleTicks(on_sample, spp, dev)
    # compiling is not rendering: keep it off the clock, and say so when it takes a while
    kinds = ", ".join(MATERIAL_KIND_NAMES[k] for k in sorted(built.features.material_kinds))
    load_kernels([*(renderer.kernels() if hasattr(renderer, "kernels") else ()), _accumulate, _average], dev, f"{method} ({kinds})")
    acc = None  # running sum: on the device (float64) for device frames, on the host otherwise
    average = None
    image = None
    frame_seconds: list[float] = []
    synchronize(dev)
    if progress is not None:
        progress(0, frames)  # the kernels are loaded: the work (and its clock) starts now
    start = time.perf_counter()
    for f in range(frames):
        synchronize(dev)
        frame_start = time.perf_counter()
        with timer("scene_update"):
            built.set_frame(float(f))
        frame_img = renderer.render_frame(f)
        if isinstance(frame_img, wp.array) and accumulate:
            if acc is None:
                acc = wp.zeros(frame_img.shape, dtype=wp.vec3d, device=dev)
                average = wp.empty(frame_img.shape, dtype=wp.vec3, device=dev)
            launch(_accumulate, dim=frame_img.shape, inputs=[acc, frame_img], device=dev)
        synchronize(dev)
        frame_seconds.append(time.perf_counter() - frame_start)
        need_host = on_frame is not None or f == frames - 1  # data stays on the device otherwise
        if isinstance(frame_img, wp.array):
            if accumulate:
                if need_host:
                    launch(_average, dim=frame_img.shape, inputs=[acc, wp.float64(1.0 / (f + 1))], outputs=[average], device=dev)
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
    if hasattr(renderer, "statistics"):
        settings["statistics"] = renderer.statistics()  # a method's own tallies (e.g. seed 003's Table 1)
    if hasattr(renderer, "nonfinite_samples"):
        settings["nonfinite_samples"] = renderer.nonfinite_samples  # dropped NaN/Inf samples; 0 expected
        if settings["nonfinite_samples"]:
            warnings.warn(f"{method} dropped {settings['nonfinite_samples']} non-finite (NaN/Inf) samples of scene "
                          f"'{sc.name}': values beyond float32's range (an emitter too bright?)", GrisxWarning, stacklevel=3)
    return RenderResult(
        image=image,
        frames=int(frames),
        spp=int(spp),
        seconds=seconds,
        pass_seconds=dict(timer.seconds),
        frame_seconds=frame_seconds,
        device=str(dev),
        settings=settings,
        extra=extra,
    )


class _SampleTicks:
    """A renderer's ``on_sample()`` hook: counts sample passes within a frame and reports them to ``report(done, spp)``.

    On an asynchronous device it synchronizes at most twice a second, so that the count (and an ETA made
    from it) follows the work done rather than the work queued.
    """

    def __init__(self, report: Callable[[int, int], None], spp: int, dev: Any) -> None:
        self.report, self.spp, self.dev = report, spp, dev
        self.done, self.synced = 0, time.perf_counter()

    def __call__(self) -> None:
        self.done = self.done % self.spp + 1
        now = time.perf_counter()
        if now - self.synced > 0.5:
            synchronize(self.dev)
            self.synced = now
        self.report(self.done, self.spp)


load_plugins()  # every renderer module registers itself (grisx.render.base.registry.PLUGINS)
