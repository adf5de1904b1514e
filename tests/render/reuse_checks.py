"""Unbiasedness of a screen-space reuse renderer, the way every one of them is tested.

:func:`check` renders independent runs of a registered render method (each its own seed,
history from scratch) and compares them with the path tracer at the depth the method
estimates, per image *and* per 8×8 block (:func:`grisx.testing.reuse_unbiasedness_test`):
under the static camera with ``frames`` frames averaged, or under the scene's camera path (or
with objects that move) with frame ``frames − 1`` alone against the path tracer at that frame's
camera and geometry. A renderer added later tests itself with one parametrize entry.

:data:`HARD_SCENES` are the cases a renderer's history can get wrong (issue 35): a camera and
an object that move more than a pixel a frame at :data:`RES` (:func:`screen_motion` measures
it), and glass beside a glossy floor.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from grisx.render.driver import METHODS, RenderContext, load_scene, method_params
from grisx.render.pt import PathTracer
from grisx.scene.builtin import build_builtin, cornell_box, glossy_room_glass
from grisx.scene.camera import CameraPath
from grisx.scene.gbuffer import GBuffer
from grisx.scene.scene import RigidMotion
from grisx.testing import DEFAULT_K, ReuseTestResult, reuse_unbiasedness_test
from session_cache import committed, shared

RES = (16, 16)
REFERENCE_SEED = 987654
_REFERENCES: dict[Any, tuple[np.ndarray, np.ndarray]] = {}


def _fast_camera() -> Any:
    """The Cornell box under a camera that trucks and turns right at constant speed, sweeping across the box:
    every visible point moves more than a pixel a frame at :data:`RES` (the built-in path's first frames move
    0.001–0.01 px)."""
    s = cornell_box()
    s.name = "cornell-box-fast-camera"
    keys = [((-0.2, -0.05, 3.9), (-0.65, -0.1, 0), (0, 1, 0)), ((0.2, 0.05, 3.9), (0.65, 0.1, 0), (0, 1, 0))]
    s.camera_path = CameraPath(keys=keys, frames_per_key=5, easing="linear")
    return s


def _fast_objects() -> Any:
    """The Cornell box with its two boxes sliding past each other, each more than a pixel a frame at :data:`RES`
    (``cornell_box_moving``'s box moves 0.1 px a frame): the small one left 0.25 a frame turning 10°, the large
    one right 0.25 a frame turning −8°; their shadows sweep the floor and the back wall."""
    s = cornell_box()
    s.name = "cornell-box-fast-objects"
    motions = {"smallbox": RigidMotion(velocity=(-0.25, 0, 0), angular_velocity=10.0, pivot=(0.335, -0.7, 0.38)),
               "largebox": RigidMotion(velocity=(0.25, 0, 0), angular_velocity=-8.0, pivot=(-0.33, -0.4, -0.28))}
    for o in s.objects:
        o.motion = motions.get(o.name)
    return s


def _fast_orthographic() -> Any:
    """:func:`_fast_camera` through an orthographic camera (Mitsuba's ``orthographic``): motion vectors and
    reprojection drop depth instead of dividing by it; every visible point moves about 2.4 px a frame."""
    s = _fast_camera()
    s.name = "cornell-box-fast-orthographic"
    s.camera = dataclasses.replace(s.camera, projection="orthographic")
    return s


#: the hard cases of every reuse method's bias test, by name (reference images are cached by it)
HARD_SCENES = {
    "cornell-box-fast-camera": _fast_camera,
    "glossy-room-glass": glossy_room_glass,  # a rough-conductor floor, a rough-glass ball, a smooth-glass box
    "cornell-box-fast-objects": _fast_objects,
    "cornell-box-fast-orthographic": _fast_orthographic,
}


def _depth(method: str, params: dict[str, Any], scene: Any) -> int:
    spec = METHODS[method]
    if spec.reference_max_depth is not None:
        return spec.reference_max_depth
    return int(params.get("max_depth", scene.defaults.get("max_depth", 16)))


def _load(scene: Any) -> Any:
    """A built-in scene, one of :data:`HARD_SCENES` or a file by name, or a :class:`~grisx.scene.scene.Scene` as it is."""
    if not isinstance(scene, str):
        return scene
    return HARD_SCENES[scene]() if scene in HARD_SCENES else load_scene(scene)


def screen_motion(scene: Any, camera: str, frames: int, res: tuple[int, int] = RES) -> list[np.ndarray]:
    """How far, in pixels, each moving visible point moved since the frame before, for frames 1 … ``frames`` − 1.

    The G-buffer's motion vectors at the jittered camera samples the renderers shade: every pixel that sees
    geometry under the moving camera, the pixels that see a moving object under the static one.
    """
    sc = _load(scene)
    moving = {i for i, o in enumerate(sc.objects) if o.motion is not None}
    built = sc.build("cpu")
    built.animate_camera = camera == "moving"
    gbuffer = GBuffer(*res, built.positions.device)
    first_vertex = built.indices.numpy()[::3]
    object_of_vertex = built.vertex_object.numpy()
    out = []
    for f in range(frames):
        built.set_frame(float(f))
        g = gbuffer.fill(built, float(f), seed=1, jitter=True)
        if f == 0:
            continue
        seen = g.hit.numpy() == 1
        if camera == "static":
            seen &= np.isin(object_of_vertex[first_vertex[np.maximum(g.tri.numpy(), 0)]], list(moving))
        out.append(np.linalg.norm(g.motion.numpy()[seen], axis=-1))
    return out


def reference(scene_name: Any, depth: int, camera: str, frame: int, spp: int = 4096, res: tuple[int, int] = RES) -> tuple[np.ndarray, np.ndarray]:
    """The path tracer's image (jittered, as the renderers) and its per-pixel variance of the mean."""

    def render() -> tuple[np.ndarray, np.ndarray]:
        built = _load(scene_name).build("cpu")
        built.animate_camera = camera == "moving"
        built.set_frame(float(frame))
        pt = PathTracer(built, *res, spp=spp, max_depth=depth, seed=REFERENCE_SEED)
        pt.add_samples(frame, spp)
        return pt.mean().astype(np.float64), pt.variance_of_mean().astype(np.float64)

    if isinstance(scene_name, str):  # named: committed, or rendered once per test session (whichever xdist worker asks first)
        return committed(("reuse_checks.reference", scene_name, depth, camera, frame, spp, tuple(res), REFERENCE_SEED), _load(scene_name), render)
    key = (id(scene_name), depth, camera, frame, spp, tuple(res))
    if key not in _REFERENCES:
        _REFERENCES[key] = render()
    return _REFERENCES[key]


def builtin_image_mean(built: Any, size: tuple[int, int], max_depth: int, spp: int, jitter: bool, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The path tracer's image mean over a built-in scene (``built.name`` says which) and its standard error.

    Committed for the CPU (:func:`session_cache.committed`); on CUDA rendered once per session.
    """

    def render() -> tuple[np.ndarray, np.ndarray]:
        pt = PathTracer(built, *size, spp=spp, max_depth=max_depth, seed=seed, jitter=jitter)
        pt.add_samples(0, spp)
        assert pt.nonfinite_samples == 0
        mean = pt.mean().astype(np.float64).reshape(-1, 3)
        var = pt.variance_of_mean().astype(np.float64).reshape(-1, 3)
        return mean.mean(axis=0), np.sqrt(var.sum(axis=0)) / len(mean)

    device = str(built.positions.device)
    key = ("builtin_image_mean", built.name, device, tuple(size), max_depth, spp, jitter, seed)
    return committed(key, build_builtin(built.name), render) if device == "cpu" else shared(key, render)


def check(method: str, params: dict[str, Any] | None = None, *, scene: Any = "cornell-box", camera: str = "static",
          frames: int = 4, runs: int = 64, k: float = DEFAULT_K, device: str = "cpu", res: tuple[int, int] = RES, reference_spp: int = 4096,
          reference_image: tuple[np.ndarray, np.ndarray] | None = None, block: int = 8, skew_corrected: bool = False) -> ReuseTestResult:
    params = dict(params or {})
    sc = _load(scene)
    depth = _depth(method, params, sc)
    if "max_depth" in {p.name for p in METHODS[method].params}:
        params.setdefault("max_depth", depth)
    resolved = {**method_params(method, params), "spp": 1}
    built = sc.build(device)
    built.animate_camera = camera == "moving"
    last_frame = camera == "moving" or built.features.animated_objects  # the image changes from frame to frame

    def run(seed: int) -> np.ndarray:
        renderer = METHODS[method].create(RenderContext(built, *res, dict(resolved), seed, None, method))
        total = np.zeros(tuple(res[::-1]) + (3,))
        for f in range(frames):
            built.set_frame(float(f))
            image = renderer.render_frame(f).numpy().astype(np.float64)
            total = image if last_frame else total + image
        assert renderer.nonfinite_samples == 0
        return total if last_frame else total / frames

    if reference_image is not None:  # another estimator's image and per-pixel variance of its mean (pixels independent)
        ref, var = reference_image
    else:
        ref, var = reference(scene, depth, camera, frames - 1 if last_frame else 0, res=res, spp=reference_spp)
    return reuse_unbiasedness_test(run, ref, var, runs, block=block, k=k, skew_corrected=skew_corrected)


def random_records(numpy_dtype: np.dtype, rng: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
    """An array of Warp records (a struct's ``numpy_dtype()``) with every word random and non-zero: floats normal,
    integers in [1, 2³¹ − 1), so that a round trip through a layout that loses or zeroes a field shows."""
    a = np.zeros(shape, dtype=numpy_dtype)
    for name in a.dtype.names:
        field = a[name]
        if np.issubdtype(field.dtype, np.floating):
            a[name] = rng.normal(size=field.shape).astype(field.dtype)
        else:
            a[name] = rng.integers(1, 2**31 - 1, size=field.shape).astype(field.dtype)
    return a
