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

A reference is rendered in chunks of :data:`CHUNK_SPP` samples per pixel
(:func:`render_chunk`: chunk k holds samples k·1024, … of the counter RNG's
sample stream, so chunks are disjoint wherever they run), each a task of a
:mod:`grisx.executor` executor — here, on several devices (``--devices``) or on
a Ray cluster — and their float64 sums and sums of squares are merged in chunk
order: the same image, bit for bit, on every executor for the same total spp.
A reference of several chunks has ``chunk_spp`` in its key (its float64 sums
are added in another order than one stream's); one of a single chunk keeps the
key it had before chunking.
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

from grisx.errors import INT32_MAX, InvalidParameterError

__all__ = ["Reference", "reference", "reference_image", "cache_dir", "render_chunk", "CHUNK_SPP"]


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


#: samples per pixel of one chunk: a reference of more is the float64 sum of chunks merged in chunk order
CHUNK_SPP = 1024


def render_chunk(scene: str, width: int, height: int, max_depth: int, seed: int, first: int, count: int,
                 device: str = "cpu") -> dict[str, Any]:
    """Samples ``first`` … ``first + count − 1`` of a reference: their float64 sums and sums of squares.

    A task of :mod:`grisx.executor`: it runs wherever it is sent (``device``) and depends on nothing else,
    so a chunk is the same image on every worker of one kind of device.
    """
    from grisx.device import resolve_device, synchronize
    from grisx.render.driver import load_scene
    from grisx.render.pt import PathTracer

    dev = resolve_device(device)
    built = load_scene(scene).build(dev)
    pt = PathTracer(built, width, height, spp=count, max_depth=max_depth, seed=seed)
    start = time.perf_counter()
    done = 0
    while done < count:
        n = min(16, count - done)
        pt.add_samples(0, n, first_sample=first + done)
        done += n
    synchronize(dev)
    seconds = time.perf_counter() - start
    return {"first": int(first), "count": int(count), "total": pt.total.numpy().astype(np.float64),
            "total_sq": pt.total_sq.numpy().astype(np.float64), "nonfinite": pt.nonfinite_samples,
            "seconds": seconds, "device": str(dev)}


def _chunks(spp: int, chunk_spp: int) -> list[tuple[int, int]]:
    """(first sample, count) of each chunk, in order."""
    return [(first, min(chunk_spp, spp - first)) for first in range(0, spp, chunk_spp)]


def _save_npz(path: Path, **arrays: Any) -> None:
    """Arrays on disk, written atomically (a file is whole or absent)."""
    import io

    from grisx.eval.files import write_atomic

    buf = io.BytesIO()
    np.savez(buf, **{k: np.asarray(v) for k, v in arrays.items()})
    write_atomic(path, buf.getvalue())


class _ChunkMerge:
    """The float64 sums of chunks 0 … k−1 (the prefix), folded in chunk order while chunks finish in any order.

    On disk in ``folder``: ``prefix.npz`` (the folded chunks' sums and a log of them) and one
    ``chunk-NNNNN.npz`` per chunk finished ahead of the prefix, each written atomically, the prefix
    before the chunk files it folds are deleted. An interrupted reference reloads both, so no chunk is
    rendered twice, and the disk holds about one image of sums per worker, not one per chunk.
    """

    def __init__(self, folder: Path, plan: list[tuple[int, int]], shape: tuple[int, int, int]) -> None:
        self.folder, self.plan = folder, plan
        self.folded = 0
        self.total, self.total_sq = np.zeros(shape), np.zeros(shape)
        self.log: list[dict[str, Any]] = []  # one entry per folded chunk
        self.pending: dict[int, dict[str, Any]] = {}
        prefix = folder / "prefix.npz"
        if prefix.is_file():
            with np.load(prefix) as z:
                if np.array_equal(z["plan"], np.array(plan).reshape(-1, 2)) and z["total"].shape == shape:
                    self.folded, self.total, self.total_sq = int(z["folded"]), z["total"], z["total_sq"]
                    self.log = [{**e, "resumed": True} for e in json.loads(str(z["log"]))]
        for index in range(self.folded, len(plan)):
            path = folder / f"chunk-{index:05d}.npz"
            if path.is_file():
                with np.load(path) as z:
                    chunk = {k: z[k].item() if z[k].ndim == 0 else z[k] for k in z.files}
                if (chunk["first"], chunk["count"]) == plan[index] and chunk["total"].shape == shape:
                    self.pending[index] = {**chunk, "resumed": True}
        self.resumed = len(self.log) + len(self.pending)
        self._fold()

    def missing(self) -> list[int]:
        return [i for i in range(self.folded, len(self.plan)) if i not in self.pending]

    def spp_done(self) -> int:
        return sum(e["count"] for e in self.log) + sum(int(c["count"]) for c in self.pending.values())

    def add(self, index: int, chunk: dict[str, Any]) -> None:
        _save_npz(self.folder / f"chunk-{index:05d}.npz", **chunk)
        self.pending[index] = chunk
        self._fold()

    def _fold(self) -> None:
        start = self.folded
        while self.folded in self.pending:  # seed order: ((0 + c0) + c1) + … whatever finished first
            c = self.pending.pop(self.folded)
            self.total += c["total"]
            self.total_sq += c["total_sq"]
            self.log.append({"chunk": self.folded, "count": int(c["count"]), "seconds": float(c["seconds"]),
                             "nonfinite": int(c["nonfinite"]), "worker": str(c["device"]), "resumed": bool(c.get("resumed"))})
            self.folded += 1
        if self.folded == start:
            return
        _save_npz(self.folder / "prefix.npz", folded=self.folded, plan=np.array(self.plan), total=self.total,
                  total_sq=self.total_sq, log=json.dumps(self.log))
        for index in range(start, self.folded):
            (self.folder / f"chunk-{index:05d}.npz").unlink(missing_ok=True)

    def remove(self) -> None:
        for path in self.folder.glob("*.npz"):
            path.unlink()
        self.folder.rmdir()


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
    executor: Any = None,
    chunk_spp: int = CHUNK_SPP,
) -> Reference:
    """The cached reference of ``scene`` (rendered now if missing or ``force``).

    The samples are rendered in chunks of ``chunk_spp`` (the last one shorter), each a task of ``executor``
    (a :class:`grisx.executor.Executor`; default: here, on ``device``). Chunk k holds samples
    k·chunk_spp, … of the counter RNG's stream, so chunks are disjoint wherever they run; their float64
    sums and sums of squares are merged in chunk order, which makes the image the same on every executor
    for the same total spp. Finished chunks are kept beside the cache entry until the image is written, so
    an interrupted reference resumes without rendering any chunk twice. A reference of one chunk has the
    key it had before chunking; one of several chunks has ``chunk_spp`` in its key.
    """
    from grisx import __version__
    from grisx.device import resolve_device
    from grisx.executor import InProcessExecutor, Task
    from grisx.imageio import check_writable_dir, read_exr, write_exr
    from grisx.render.driver import check_memory, check_res, load_scene
    from grisx.render.pt import variance_of_mean

    for name, value in (("spp", spp), ("chunk_spp", chunk_spp)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise InvalidParameterError(f"{name} must be a positive integer, got {value!r}")
    if int(spp) > INT32_MAX:  # the counter RNG numbers samples in int32
        raise InvalidParameterError(f"spp must be at most 2^31 - 1, got {spp}")
    sc = load_scene(scene)
    width, height = check_res(res if res is not None else (sc.film.width, sc.film.height))
    check_memory(width, height, resolve_device("cpu"), "reference")  # the float64 sums are merged here, on the host
    depth = int(sc.defaults.get("max_depth", 16)) if max_depth is None else int(max_depth)
    if depth == 0:
        raise InvalidParameterError("max_depth must be -1 (unbounded) or >= 1, got 0")
    settings: dict[str, Any] = {"scene": str(scene), "width": int(width), "height": int(height), "spp": int(spp),
                                "max_depth": depth, "seed": int(seed), "grisx_version": __version__}
    if spp > chunk_spp:  # one chunk: the sums of one stream, as before chunking (the stored references stay valid)
        settings["chunk_spp"] = int(chunk_spp)
    key = hashlib.sha256(json.dumps({**settings, "identity": _scene_identity(str(scene))}, sort_keys=True).encode()).hexdigest()[:24]
    folder = cache_dir()
    path = folder / f"{key}.exr"
    var_path = folder / f"{key}.variance.exr"
    if path.is_file() and var_path.is_file() and not force:
        return Reference(read_exr(path), read_exr(var_path), path, True, json.loads(path.with_suffix(".json").read_text()))
    if executor is None:
        executor = InProcessExecutor(device)
    chunk_dir = folder / f"{key}.chunks"
    try:  # the cache must take the result: find out now, not after the render
        chunk_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InvalidParameterError(f"cannot create the reference cache '{folder}' (GRISX_CACHE_DIR): {exc.strerror or exc}") from None
    check_writable_dir(chunk_dir, "the reference cache (GRISX_CACHE_DIR)")
    if force and chunk_dir.is_dir():
        for old in chunk_dir.glob("*.npz"):
            old.unlink()
    chunk_dir.mkdir(parents=True, exist_ok=True)
    plan = _chunks(int(spp), int(chunk_spp))
    start = time.perf_counter()
    merge = _ChunkMerge(chunk_dir, plan, (int(height), int(width), 3))
    if progress is not None and merge.spp_done():
        progress(merge.spp_done(), spp)
    tasks = {f"{scene} chunk {i}": i for i in merge.missing()}
    for task, chunk, report in executor.run(
            Task(k, render_chunk, dict(scene=str(scene), width=int(width), height=int(height), max_depth=depth,
                                       seed=int(seed), first=plan[i][0], count=plan[i][1])) for k, i in tasks.items()):
        chunk["device"] = report.worker
        merge.add(tasks[task.key], chunk)
        if progress is not None:
            progress(merge.spp_done(), spp)
    # ---- the merged sums: float64, in chunk order (the same image whatever ran each chunk) ----
    total, total_sq = merge.total, merge.total_sq
    image, variance = (total / spp).astype(np.float32), variance_of_mean(total, total_sq, spp)
    seconds = time.perf_counter() - start
    throughput: dict[str, dict[str, float]] = {}
    for e in merge.log:
        d = throughput.setdefault("resumed" if e["resumed"] else e["worker"], {"chunks": 0, "spp": 0, "seconds": 0.0})
        d["chunks"] += 1
        d["spp"] += e["count"]
        d["seconds"] += e["seconds"]
    for d in throughput.values():
        d["spp_per_second"] = d["spp"] / d["seconds"] if d["seconds"] > 0 else None
        d["samples_per_second"] = d["spp"] * width * height / d["seconds"] if d["seconds"] > 0 else None
    write_exr(var_path, variance)
    meta = {**settings, "device": ",".join(sorted(throughput)), "seconds": seconds,
            "nonfinite_samples": sum(e["nonfinite"] for e in merge.log), "key": key, "chunks": len(plan),
            "chunk_spp": int(chunk_spp), "resumed_chunks": merge.resumed, "executor": executor.describe(),
            "throughput": throughput, "retried": executor.retried}
    from grisx.eval.files import write_json

    write_json(path.with_suffix(".json"), meta)
    write_exr(path, image)  # last: the image marks the cache entry complete
    merge.remove()
    return Reference(image, variance, path, False, meta)


def reference_image(scene: str, *, res: tuple[int, int] | None = None, spp: int = 1024, device: str = "cpu", seed: int = 0) -> np.ndarray:
    """The reference image alone (see :func:`reference`)."""
    return reference(scene, res=res, spp=spp, device=device, seed=seed).image
