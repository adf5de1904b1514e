"""Unbiasedness of a screen-space reuse renderer, the way every one of them is tested.

:func:`check` renders independent runs of a registered render method (each its own seed,
history from scratch) and compares them with the path tracer at the depth the method
estimates, per image *and* per 8×8 block (:func:`grisx.testing.reuse_unbiasedness_test`):
under the static camera with ``frames`` frames averaged, or under the scene's camera path
with frame ``frames − 1`` alone against the path tracer at that frame's camera. A renderer
added later tests itself with one parametrize entry.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from grisx.render.driver import METHODS, RenderContext, load_scene, method_params
from grisx.render.pt import PathTracer
from grisx.testing import DEFAULT_K, ReuseTestResult, reuse_unbiasedness_test

RES = (16, 16)
_REFERENCES: dict[Any, tuple[np.ndarray, np.ndarray]] = {}


def _depth(method: str, params: dict[str, Any], scene: Any) -> int:
    spec = METHODS[method]
    if spec.reference_max_depth is not None:
        return spec.reference_max_depth
    return int(params.get("max_depth", scene.defaults.get("max_depth", 16)))


def _load(scene: Any) -> Any:
    """A built-in scene or file by name, or a :class:`~grisx.scene.scene.Scene` as it is."""
    return load_scene(scene) if isinstance(scene, str) else scene


def reference(scene_name: Any, depth: int, camera: str, frame: int, spp: int = 4096, res: tuple[int, int] = RES) -> tuple[np.ndarray, np.ndarray]:
    """The path tracer's image (jittered, as the renderers) and its per-pixel variance of the mean."""
    key = (scene_name if isinstance(scene_name, str) else id(scene_name), depth, camera, frame, spp, tuple(res))
    if key not in _REFERENCES:
        built = _load(scene_name).build("cpu")
        built.animate_camera = camera == "moving"
        built.set_frame(float(frame))
        pt = PathTracer(built, *res, spp=spp, max_depth=depth, seed=987654)
        pt.add_samples(frame, spp)
        _REFERENCES[key] = pt.mean().astype(np.float64), pt.variance_of_mean().astype(np.float64)
    return _REFERENCES[key]


def check(method: str, params: dict[str, Any] | None = None, *, scene: Any = "cornell-box", camera: str = "static",
          frames: int = 4, runs: int = 64, k: float = DEFAULT_K, device: str = "cpu", res: tuple[int, int] = RES, reference_spp: int = 4096,
          reference_image: tuple[np.ndarray, np.ndarray] | None = None) -> ReuseTestResult:
    params = dict(params or {})
    sc = _load(scene)
    depth = _depth(method, params, sc)
    if "max_depth" in {p.name for p in METHODS[method].params}:
        params.setdefault("max_depth", depth)
    resolved = {**method_params(method, params), "spp": 1}
    built = sc.build(device)
    built.animate_camera = camera == "moving"

    def run(seed: int) -> np.ndarray:
        renderer = METHODS[method].create(RenderContext(built, *res, dict(resolved), seed, None, method))
        total = np.zeros(tuple(res[::-1]) + (3,))
        for f in range(frames):
            built.set_frame(float(f))
            image = renderer.render_frame(f).numpy().astype(np.float64)
            total = total + image if camera == "static" else image
        assert renderer.nonfinite_samples == 0
        return total / frames if camera == "static" else total

    if reference_image is not None:  # another estimator's image and per-pixel variance of its mean (pixels independent)
        ref, var = reference_image
    else:
        ref, var = reference(scene, depth, camera, frames - 1 if camera == "moving" else 0, res=res, spp=reference_spp)
    return reuse_unbiasedness_test(run, ref, var, runs, block=8, k=k)
