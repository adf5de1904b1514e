"""Work that a test session does once, whichever pytest-xdist worker asks first.

Deterministic references (a path tracer's image at a fixed seed, say) are wanted by tests that
xdist sends to different workers; each worker kept its own per-process cache, so each rendered
the same reference. :func:`shared` keeps them in one folder per session (``GRISX_TEST_SHARED``,
made by ``conftest.py`` before the workers start and removed after): the first worker to ask
computes and writes, a worker asking meanwhile waits on a file lock and reads what was written.
The key must name everything that defines the result (scene, depth, camera, frame, spp, seed,
resolution, ...); the code does not change within a session, so it need not be part of it.

:func:`compile_once` does the same for Warp's kernel cache: a module being compiled by one
worker is not compiled again by the other at the same time (Warp checks its cache first, so the
waiting worker loads the binary the first one wrote). Each compilation's wall time is logged in the
shared folder, and :func:`compile_report` sums them at the end of the session: on a cold kernel cache
compilation is most of the suite's time, and the report says which modules cost it.
"""

from __future__ import annotations

import hashlib
import os
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from filelock import FileLock

__all__ = ["ENV", "shared", "compile_once", "compile_report"]

#: the environment variable naming the session's shared folder
ENV = "GRISX_TEST_SHARED"

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
