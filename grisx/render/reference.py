"""Reference images: high-sample path-traced images with per-pixel variance, cached on disk.

Every convergence test and benchmark compares a renderer with a
:func:`reference`: the path tracer (:mod:`grisx.render.pt`) at many samples per
pixel, together with the per-pixel variance of its mean (so a comparison can
tell the reference's own noise from a renderer's error). References are
cached under ``$GRISX_CACHE_DIR/references`` (default
``~/.cache/grisx/references``) by a SHA-256 of what determines the image:

* the scene — a built-in scene's name and the source of
  :mod:`grisx.scene.builtin`, or a scene file's bytes;
* the film size, sample count, maximum depth, seed and grisx's version.

The device is not part of the key: CPU and CUDA estimate the same image.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from grisx.errors import InvalidParameterError

__all__ = ["Reference", "reference", "reference_image", "cache_dir"]


def cache_dir() -> Path:
    root = os.environ.get("GRISX_CACHE_DIR")
    base = Path(root) if root else Path.home() / ".cache" / "grisx"
    return base / "references"


@dataclasses.dataclass
class Reference:
    image: np.ndarray  # (H, W, 3) linear mean
    variance: np.ndarray  # (H, W, 3) variance of the mean
    path: Path  # the cached EXR
    cached: bool  # found in the cache (not rendered now)
    settings: dict[str, Any]


def _scene_identity(scene: str) -> str:
    from grisx.scene import builtin

    if scene in builtin.BUILTIN_SCENES:
        return "builtin:" + scene + ":" + hashlib.sha256(Path(builtin.__file__).read_bytes()).hexdigest()
    path = Path(scene)
    if not path.is_file():
        raise InvalidParameterError(f"scene file '{scene}' does not exist")
    return "file:" + hashlib.sha256(path.read_bytes()).hexdigest()


def reference(
    scene: str,
    *,
    res: tuple[int, int] | None = None,
    spp: int = 1024,
    max_depth: int | None = None,
    device: str = "cpu",
    seed: int = 0,
    force: bool = False,
    progress: Callable[[int, int], None] | None = None,
) -> Reference:
    """The cached reference of ``scene`` (rendered now if missing or ``force``)."""
    from grisx import __version__
    from grisx.device import resolve_device
    from grisx.imageio import read_exr, write_exr
    from grisx.render.pt import PathTracer
    from grisx.render.driver import load_scene

    if isinstance(spp, bool) or not isinstance(spp, (int, np.integer)) or spp < 1:
        raise InvalidParameterError(f"spp must be a positive integer, got {spp!r}")
    sc = load_scene(scene)
    width, height = res if res is not None else (sc.film.width, sc.film.height)
    depth = int(sc.defaults.get("max_depth", 16)) if max_depth is None else int(max_depth)
    if depth == 0:
        raise InvalidParameterError("max_depth must be -1 (unbounded) or >= 1, got 0")
    settings = {"scene": str(scene), "width": int(width), "height": int(height), "spp": int(spp),
                "max_depth": depth, "seed": int(seed), "grisx_version": __version__}
    key = hashlib.sha256(json.dumps({**settings, "identity": _scene_identity(str(scene))}, sort_keys=True).encode()).hexdigest()[:24]
    folder = cache_dir()
    path = folder / f"{key}.exr"
    var_path = folder / f"{key}.variance.exr"
    if path.is_file() and var_path.is_file() and not force:
        return Reference(read_exr(path), read_exr(var_path), path, True, json.loads(path.with_suffix(".json").read_text()))
    dev = resolve_device(device)
    built = sc.build(dev)
    pt = PathTracer(built, width, height, spp=spp, max_depth=depth, seed=seed)
    start = time.perf_counter()
    done = 0
    while done < spp:
        n = min(16, spp - done)
        pt.add_samples(0, n)
        done += n
        if progress is not None:
            progress(done, spp)
    image, variance = pt.mean().astype(np.float32), pt.variance_of_mean()
    seconds = time.perf_counter() - start
    folder.mkdir(parents=True, exist_ok=True)
    write_exr(path, image)
    write_exr(var_path, variance)
    meta = {**settings, "device": str(dev), "seconds": seconds, "nonfinite_samples": pt.nonfinite_samples, "key": key}
    path.with_suffix(".json").write_text(json.dumps(meta, indent=2))
    return Reference(image, variance, path, False, meta)


def reference_image(scene: str, *, res: tuple[int, int] | None = None, spp: int = 1024, device: str = "cpu", seed: int = 0) -> np.ndarray:
    """The reference image alone (see :func:`reference`)."""
    return reference(scene, res=res, spp=spp, device=device, seed=seed).image
