"""Warp initialisation and device selection, shared by every layer.

grisx runs its kernels on ``"cpu"`` by default and on ``"cuda"`` (or
``"cuda:N"``) when Warp finds a GPU. Asking for a device that is not there is a
:class:`~grisx.errors.DeviceError`, never a silent fall-back.
"""

from __future__ import annotations

import functools
import os
import sys
import tempfile
from collections.abc import Iterable
from typing import Any

import warp as wp

from grisx.errors import DeviceError, InvalidValueError

__all__ = ["init", "resolve_device", "cuda_available", "available_memory", "synchronize", "specialized_module", "load_kernels", "launch", "LAUNCH_BLOCK_DIM", "PATH_REGISTERS", "SHIFT_REGISTERS", "WALK_REGISTERS", "register_budget"]


#: a line Warp's native library prints on every machine without a GPU; on such
#: a machine it is expected, and grisx reports CUDA's absence itself when asked
_EXPECTED_NATIVE_NOISE = ("Could not find or load the NVIDIA CUDA driver",)


@functools.cache
def init() -> None:
    """Initialise Warp once, quietly.

    Warp's info messages (greeting, kernel loads) are hidden unless the
    environment sets ``GRISX_VERBOSE=1``; the native "no CUDA driver" notice
    is dropped (``cuda_available()`` answers that question) and anything else
    Warp writes to stderr while starting is passed on.
    """
    verbose = os.environ.get("GRISX_VERBOSE", "") not in ("", "0")
    if not verbose:
        wp.config.log_level = max(wp.config.log_level, wp.LOG_WARNING)
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile(mode="w+b") as capture:
        os.dup2(capture.fileno(), 2)
        try:
            wp.init()
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        capture.seek(0)
        text = capture.read().decode(errors="replace")
    kept = [line for line in text.splitlines() if verbose or not any(n in line for n in _EXPECTED_NATIVE_NOISE)]
    if kept:
        print("\n".join(kept), file=sys.stderr)


def cuda_available() -> bool:
    init()
    return wp.get_cuda_device_count() > 0


def resolve_device(device: str | None = "cpu") -> wp.context.Device:
    """Return the Warp device for a user-facing name (``cpu``, ``cuda``, ``cuda:N``)."""
    init()
    name = "cpu" if device is None else str(device)
    if name == "cpu":
        return wp.get_device("cpu")
    if name == "cuda" or name.startswith("cuda:"):
        if not cuda_available():
            raise DeviceError(f"device '{name}' requested but Warp found no CUDA device on this machine")
        try:
            return wp.get_device(name)
        except (RuntimeError, ValueError) as exc:
            raise DeviceError(f"device '{name}' is not available: {exc}") from None
    raise DeviceError(f"unknown device '{name}' (use cpu, cuda or cuda:N)")


def available_memory(device: wp.context.Device) -> int | None:
    """Bytes free for new allocations on ``device`` (host: MemAvailable), or None where it cannot be told."""
    if getattr(device, "is_cuda", False):
        free = getattr(device, "free_memory", None)
        return int(free) if free else None
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def synchronize(device: wp.context.Device) -> None:
    """Wait for all work on ``device``; call before reading a clock."""
    wp.synchronize_device(device)


#: Render kernels on CUDA compile with fast math (nvcc ``--use_fast_math``: single-precision
#: division, square root and transcendentals by their fast approximations, denormals flushed
#: to zero). It halves the path tracer's frame time at 1080p (``benchmarks/vs_mitsuba.py``);
#: the approximations (a few ulp) are far below Monte Carlo noise and NaN/Inf checks still
#: work (nvcc does not assume finite math). Warp ignores the option on the CPU, so CPU
#: results do not change. ``GRISX_FAST_MATH=0`` in the environment turns it off.
FAST_MATH = os.environ.get("GRISX_FAST_MATH", "1") != "0"


def specialized_module(owner: str, kinds: Iterable[int]) -> wp.context.Module:
    """The Warp module for ``owner``'s kernels specialized to the material kinds ``kinds``.

    Warp compiles a module as one unit, and a kernel defined inside a factory lands in
    its Python module's Warp module by default. Every new specialization would then
    recompile all earlier ones with it (a process rendering k scenes compiles
    1 + 2 + … + k kernel sets; on CUDA that is minutes per set). One module per
    (owner, kinds) compiles each set once and caches it on its own.
    """
    name = f"{owner}.kinds_" + "_".join(str(int(k)) for k in sorted(kinds))
    module = wp.get_module(name)
    module.options["enable_backward"] = False
    module.options["fast_math"] = FAST_MATH
    return module


#: Threads per block of every render pass on CUDA (Warp launches 256 unless told). Lanes end their paths,
#: shifts and shadow rays at different times, and a block keeps its registers until its last warp ends:
#: a 256-thread block of a path tracer holds eight warps' worth of the SM for its longest path. In blocks
#: of 64 an SM refills in finer steps, and kernels above 128 registers fit more warps (149 registers:
#: one 256-thread block an SM, 8 warps; six 64-thread blocks, 12). Measured on an H200 at 1080p
#: (``benchmarks/README.md``, "Blocks of 64 threads"): door-ajar pt 9.90 -> 9.40 ms, restir-gi
#: 14.63 -> 12.84, restir-pt 26.45 -> 24.53. The CPU runs one thread a block whatever is asked.
LAUNCH_BLOCK_DIM = 64


def launch(kernel: Any, dim: Any, inputs: Any = (), outputs: Any = (), device: Any = None, **kw: Any) -> None:
    """``wp.launch`` in blocks of :data:`LAUNCH_BLOCK_DIM` threads: how grisx launches its render passes.

    ``wp.launch`` is looked up at each call, so a tool that wraps it (``benchmarks/kernels.py``'s per-kernel
    timer) sees every pass.
    """
    kw.setdefault("block_dim", LAUNCH_BLOCK_DIM)
    wp.launch(kernel, dim=dim, inputs=list(inputs), outputs=list(outputs), device=device, **kw)


def register_budget(variable: str, default: int) -> int:
    """A ``cuda_max_registers`` budget: ``default``, or the environment's ``variable`` where it is set.

    The override is for register-budget sweeps on a GPU (``benchmarks/register_sweep.sh``): one tree, one process
    per budget, each with its own kernel cache. A budget outside 32–255 (CUDA's range) or not an integer is an
    :class:`~grisx.errors.InvalidValueError` that names the variable.
    """
    text = os.environ.get(variable, "").strip()
    if not text:
        return default
    try:
        value = int(text)
    except ValueError:
        value = 0
    if not 32 <= value <= 255:
        raise InvalidValueError(f"{variable}={text!r}: a register budget is an integer from 32 to 255")
    return value


#: ``cuda_max_registers`` of the kernels that trace paths or shadow rays (the path tracer's sample
#: pass, ReSTIR GI's stages). Software BVH traversal is latency-bound, and more warps in flight pay for
#: the spills. In 64-thread blocks an SM holds 65536 / (64 r) blocks: 24 warps at 80 registers, 32 at 64.
#: Measured on an H200 at 1080p (``benchmarks/README.md``, "Register budgets in blocks of 64"): 80 -> 64
#: takes pt's 1-spp frame 9.38 -> 8.72 ms (door-ajar), 10.11 -> 9.60 (glossy-room), 3.3 -> 3.3
#: (cornell-box); ReSTIR GI 13.4 -> 12.4 and 18.5 -> 17.4 ms (cornell-box: 7.1 -> 7.4); 56 and 48 lose again. (Earlier, in blocks
#: of 256: 80 beat no cap, pt 12.7 -> 10.2 ms on door-ajar.) Kernels that lost at a cap keep none
#: (ReSTIR DI's spatial pass: 7.1 -> 14.9 ms at 128). Ignored on the CPU.
PATH_REGISTERS = register_budget("GRISX_PATH_REGISTERS", 64)
#: the same for the kernels that run ReSTIR PT's hybrid shift (its candidate walk: ``WALK_REGISTERS``), whose live
#: state (path samples) spills heavily below 128: at 128 ReSTIR PT's frame on door-ajar 44.0 -> 34.6 ms
#: (H100, 1080p), at 80 40.7. Area ReSTIR's own stages run under it too, chosen
#: per stage (its spatial stages on an H200: door-ajar 11.4 -> 8.2 ms, glossy-room the same); capping
#: all its passes at once had lost on glossy-room (115 -> 135 ms). ReSTIR G-PT's shift stages (base, inner) and
#: its initial pair pass, uncapped at 200-223 registers without spills, run faster at 128 with spills (H200,
#: 1080p, moving camera: glossy-room 237.5 -> 217.0 ms, door-ajar 133.4 -> 125.2).
SHIFT_REGISTERS = register_budget("GRISX_SHIFT_REGISTERS", 128)
#: the same for ReSTIR PT's candidate walk (``initial_pass``, shared by ReSTCV and its variants, Area ReSTIR, G-PT):
#: a path tracer that also keeps its candidate path, so it gains from more warps in flight like ``PATH_REGISTERS``'s
#: kernels, where the shift stages do not. H200, 1080p, 64-thread blocks ("Register budgets in blocks of 64"):
#: door-ajar's walk 13.5 -> 11.7 ms at 80 (12.5 at 96), ReSTIR PT's frame 24.5 -> 22.7; the shift stages at 96
#: or 80 lose on cornell-box (spatial 3.2 -> 3.5 / 3.8 ms), so they keep 128.
WALK_REGISTERS = register_budget("GRISX_WALK_REGISTERS", 80)


#: seconds a kernel load may take before the user is told that Warp is compiling (cached loads take milliseconds)
COMPILE_NOTICE_SECONDS = 1.0


def load_kernels(kernels: Iterable[Any], device: Any, what: str) -> None:
    """Load (compile on first use) the Warp modules of ``kernels`` on ``device``, saying so when it takes a while.

    Warp compiles a module the first time it is loaded on a device and caches the binary
    (``~/.cache/warp``); a first CUDA render can then be silent for half a minute. When the
    load has not finished after :data:`COMPILE_NOTICE_SECONDS` and stderr is a terminal,
    one line says what is being compiled.
    """
    import threading

    done = threading.Event()

    def notice() -> None:
        if not done.wait(COMPILE_NOTICE_SECONDS):
            print(f"grisx: compiling kernels for {what} on {device} (first run only; cached afterwards) ...", file=sys.stderr, flush=True)

    watcher = threading.Thread(target=notice, daemon=True) if sys.stderr.isatty() else None
    if watcher is not None:
        watcher.start()
    try:
        seen = set()
        for kernel in kernels:
            if id(kernel.module) not in seen:
                seen.add(id(kernel.module))
                wp.load_module(kernel.module, device=device)
    finally:
        done.set()
        if watcher is not None:
            watcher.join()
