"""Work that a test session does once, whichever pytest-xdist worker asks first.

Deterministic references (a path tracer's image at a fixed seed, say) are wanted by tests that
xdist sends to different workers; each worker kept its own per-process cache, so each rendered
the same reference. :func:`shared` keeps them in one folder per session (``GRISX_TEST_SHARED``,
made by ``conftest.py`` before the workers start and removed after): the first worker to ask
computes and writes, a worker asking meanwhile waits on a file lock and reads what was written.
The key must name everything that defines the result (scene, depth, camera, frame, spp, seed,
resolution, ...); the code does not change within a session, so it need not be part of it.

:func:`committed` keeps path-tracer references across sessions: in ``tests/references/``, committed
with the tests, under a key that names the scene by its content (:func:`scene_fingerprint`: every
material, mesh, light and camera value of the scene builder), so a reference of a scene that
changed is never read; it is rendered again. CI (a fresh clone, ~85 worker-seconds of references)
reads them instead of rendering them. ``GRISX_TEST_WRITE_REFERENCES=1`` renders and writes them
(``python3 -m pytest tests/render`` with it set regenerates the folder). A reference is the same
estimate whichever version of the path tracer rendered it, and the path tracer itself is tested
against Mitsuba 3's images (``tests/conformance``), so a renderer test that compares with a committed
reference compares with an independent, checked image.

:func:`compile_once` does the same for Warp's kernel cache: a module being compiled by one
worker is not compiled again by the other at the same time (Warp checks its cache first, so the
waiting worker loads the binary the first one wrote). Each compilation's wall time is logged in the
shared folder, and :func:`compile_report` sums them at the end of the session: on a cold kernel cache
compilation is most of the suite's time, and the report says which modules cost it.
"""

from __future__ import annotations

import dataclasses
import enum
import hashlib
import inspect
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from filelock import FileLock

__all__ = ["ENV", "shared", "committed", "scene_fingerprint", "compile_once", "compile_report"]

#: the environment variable naming the session's shared folder
ENV = "GRISX_TEST_SHARED"
#: set to 1: :func:`committed` renders every reference and writes it into :data:`REFERENCES`
WRITE_ENV = "GRISX_TEST_WRITE_REFERENCES"
#: the committed references
REFERENCES = Path(__file__).resolve().parent / "references"
#: part of every committed key: raise it when the path tracer's image changes meaning (its filter, say)
REFERENCE_EPOCH = 1

_MEMO: dict[str, tuple[np.ndarray, ...]] = {}


def _folder() -> Path | None:
    root = os.environ.get(ENV)
    return Path(root) if root else None


def shared(key: tuple, compute: Callable[[], tuple[np.ndarray, ...]]) -> tuple[np.ndarray, ...]:
    """``compute()`` (a tuple of arrays) once per session for ``key`` (a tuple of str/int/float/bool/None/tuples)."""
    name = hashlib.sha256(repr(key).encode()).hexdigest()[:32]
    if name in _MEMO:
        return _MEMO[name]
    folder = _folder()
    if folder is None:  # not under pytest's conftest (a test module run as a script): this process only
        _MEMO[name] = tuple(compute())
        return _MEMO[name]
    path = folder / f"{name}.npz"
    with FileLock(str(path) + ".lock"):
        if path.exists():
            with np.load(path) as data:
                value = tuple(data[f"a{i}"] for i in range(len(data.files)))
        else:
            value = tuple(compute())
            partial = path.with_suffix(f".{os.getpid()}.tmp.npz")
            np.savez(partial, **{f"a{i}": a for i, a in enumerate(value)})
            os.replace(partial, path)
    _MEMO[name] = value
    return value


def _feed(h: Any, obj: Any, seen: set[int]) -> None:
    """Feed ``obj``'s content (not its identity) to ``h``: the same scene gives the same bytes in every process."""
    if obj is None or isinstance(obj, (bool, int, float, str, bytes, complex)):
        h.update(f"{type(obj).__name__}:{obj!r};".encode())
        return
    if isinstance(obj, np.generic):
        h.update(f"{obj.dtype}:{obj.item()!r};".encode())
        return
    if isinstance(obj, np.ndarray):
        a = np.ascontiguousarray(obj)
        h.update(f"nd:{a.dtype}:{a.shape};".encode())
        h.update(a.tobytes())
        return
    if isinstance(obj, enum.Enum):
        h.update(f"enum:{obj!r};".encode())
        return
    if inspect.isroutine(obj) or inspect.isclass(obj):  # code: its name would not say what it computes
        raise TypeError(f"scene_fingerprint: cannot fingerprint {obj!r} (code, not data)")
    if id(obj) in seen:
        h.update(b"cycle;")
        return
    seen.add(id(obj))
    if isinstance(obj, dict):
        h.update(f"dict:{len(obj)}{{".encode())
        for k in sorted(obj, key=repr):
            _feed(h, k, seen)
            _feed(h, obj[k], seen)
        h.update(b"}")
    elif isinstance(obj, (list, tuple, set, frozenset)):
        items = sorted(obj, key=repr) if isinstance(obj, (set, frozenset)) else obj
        h.update(f"{type(obj).__name__}:{len(items)}[".encode())
        for item in items:
            _feed(h, item, seen)
        h.update(b"]")
    elif dataclasses.is_dataclass(obj):
        h.update(f"dc:{type(obj).__qualname__}(".encode())
        for f in dataclasses.fields(obj):
            h.update(f.name.encode())
            _feed(h, getattr(obj, f.name), seen)
        h.update(b")")
    elif hasattr(obj, "__dict__"):
        h.update(f"obj:{type(obj).__qualname__}(".encode())
        _feed(h, vars(obj), seen)
        h.update(b")")
    elif hasattr(obj, "__len__") and hasattr(obj, "__getitem__"):  # Warp vectors and matrices
        h.update(f"seq:{type(obj).__name__}:".encode())
        _feed(h, [obj[i] for i in range(len(obj))], seen)
    else:
        raise TypeError(f"scene_fingerprint: cannot fingerprint a {type(obj).__qualname__}")


def scene_fingerprint(scene: Any) -> str:
    """SHA-256 of a scene builder's content (:class:`~grisx.scene.scene.Scene`): materials, textures, meshes, lights, camera, film."""
    h = hashlib.sha256()
    _feed(h, scene, set())
    return h.hexdigest()


def committed(key: tuple, scene: Any, compute: Callable[[], tuple[np.ndarray, ...]]) -> tuple[np.ndarray, ...]:
    """A reference committed under :data:`REFERENCES` for ``key`` and ``scene``'s content, else :func:`shared`'s.

    ``key`` names everything but the scene (depth, camera, frame, spp, seed, resolution, ...); ``scene`` is
    the builder whose content the reference is an image of. With :data:`WRITE_ENV` set the reference is
    rendered and written here (one ``.npz`` each, its key inside for whoever reads the folder).
    """
    full = (*key, scene_fingerprint(scene), REFERENCE_EPOCH)
    name = hashlib.sha256(repr(full).encode()).hexdigest()[:32]
    path = REFERENCES / f"{name}.npz"
    write = os.environ.get(WRITE_ENV) == "1"
    if not write and path.exists():
        if name not in _MEMO:
            with np.load(path) as data:
                _MEMO[name] = tuple(data[f"a{i}"] for i in range(len(data.files) - 1))
        return _MEMO[name]
    value = shared(full, compute)
    if write:
        REFERENCES.mkdir(exist_ok=True)
        partial = path.with_suffix(f".{os.getpid()}.tmp.npz")
        np.savez_compressed(partial, key=np.array(repr(key)), **{f"a{i}": np.asarray(a) for i, a in enumerate(value)})
        os.replace(partial, path)
    return value


def compile_once() -> None:
    """Serialize Warp's compilation of each module across the session's processes (no-op outside a session).

    Wraps ``Module._compile`` (Warp ≥ 1.10; left alone where Warp has no such method): the lock is named by
    the module's cache folder, which holds its content hash, so only compilations of the same binary wait.
    """
    folder = _folder()
    try:
        from warp._src.context import Module
    except ImportError:
        return
    original = getattr(Module, "_compile", None)
    if folder is None or original is None or getattr(original, "_grisx_once", False):
        return

    def _compile(self, device, output_dir, *args, **kwargs):
        lock = folder / ("compile-" + hashlib.sha256(f"{output_dir}|{device}".encode()).hexdigest()[:32] + ".lock")
        with FileLock(str(lock)):
            start = time.perf_counter()
            result = original(self, device, output_dir, *args, **kwargs)
            seconds = time.perf_counter() - start
        if seconds < 0.05:  # the binary was already there (the other worker wrote it while this one waited)
            return result
        with open(folder / _COMPILE_LOG, "a") as log:  # one short line per append: safe across processes
            log.write(f"{seconds:.3f}\t{device}\t{self.name}\n")
        return result

    _compile._grisx_once = True
    Module._compile = _compile


_COMPILE_LOG = "compile-times.tsv"


def compile_report(folder: Path, top: int = 12) -> list[str]:
    """Lines summing the session's Warp compilations (logged by :func:`compile_once`), slowest modules first."""
    try:
        rows = [line.split("\t") for line in (folder / _COMPILE_LOG).read_text().splitlines() if line]
    except OSError:
        return []
    rows = sorted(((float(s), d, n) for s, d, n in rows), reverse=True)
    total = sum(s for s, _, _ in rows)
    lines = [f"Warp compiled {len(rows)} modules in {total:.0f} s (summed over workers); the slowest:"]
    lines += [f"  {s:7.1f} s  {n} ({d})" for s, d, n in rows[:top]]
    return lines
