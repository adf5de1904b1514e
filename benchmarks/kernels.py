#!/usr/bin/env python
"""Registers, spills and time of every CUDA kernel of every render method, and their compile time.

A Warp ``wp.func`` is inlined at every call site, so a kernel that calls a path walk, a shift and
a BSDF stack from several places grows into a megakernel (``/work/shared/DESIGN.md``, "GPU
execution: lean stages, not megakernels"; issue 35). Three numbers of the sm_90 code say whether
a kernel has: **registers** per thread (255 is the hardware cap; more live values than that go to
local memory), the **stack frame** (bytes of local memory per thread: spilled registers and
arrays indexed at run time), the **spill stores/loads** (bytes per thread the register
allocator moved out and back in) and the **SASS bytes** (the kernel's machine code, which the
instruction cache must hold). They come from ``ptxas -v -arch=sm_90`` on the PTX that Warp's
NVRTC generates for each module: no GPU is needed, only ``ptxas``. Warp 1.19 ships NVRTC 13.4,
whose PTX says ``.version 9.4``; an older ``ptxas`` (CUDA 13.0 reads 9.0) is given the same text
with the version it reads (recorded under ``ptx_version``). Checked against the cubin NVRTC itself
builds for the GPU (registers and frame of its ``.nv.info``): equal for pt and every ReSTIR PT kernel.

A method's kernels are found by rendering a tiny frame (two frames, so the temporal passes run)
with Warp's module loader wrapped: every module the render loads is compiled to PTX before it is
loaded. Modules are specialised to the scene's material kinds (``render.restcv.kinds_0_1``), so
the numbers belong to ``--scene`` (default ``glossy-room``: diffuse and rough conductor).

With ``--device cuda`` each method is also timed at ``--res`` (default 1920x1080), static camera
(``--camera path``: the scene's moving camera, under which no temporal shift is the identity):
a warm-up render, then ``--frames`` frames after a first one that is not counted (no history yet).
*Kernel* milliseconds come from ``wp.launch`` wrapped with a device synchronisation on each side
(a few microseconds per launch added); *phase* milliseconds from the driver's pass timer
(``RenderResult.pass_seconds``), as (phases of 1 + N frames − phases of 1 frame) / N; the frame's
from ``RenderResult.frame_seconds`` (median, host copy excluded).

Register budgets come from ``grisx.device`` (``PATH_REGISTERS``, ``SHIFT_REGISTERS``); a sweep sets
``GRISX_PATH_REGISTERS`` / ``GRISX_SHIFT_REGISTERS`` for the process, with a kernel cache of its own
(``WARP_CACHE_PATH``), and the JSON records the budgets it ran under.

``--compile`` measures first-use compilation instead: per method, a fresh process renders one
tiny frame with an empty kernel cache (``WARP_CACHE_PATH``, a temporary folder), then a second
fresh process with that cache filled (the warm start). On CUDA that is Warp's real compile; on
the CPU the process compiles the CPU kernels and, through ``aot_cuda.py``'s hook, the sm_90
cubins with NVRTC, timed apart (``cuda_compile_s``).

Usage::

    python benchmarks/kernels.py                                  # CPU: resources of every method
    python benchmarks/kernels.py --device cuda --methods pt,restir-gi        # + ms per kernel at 1080p
    python benchmarks/kernels.py --device cuda --compile --methods restir-gi # cold and warm start
    python benchmarks/kernels.py --report benchmarks/reference/kernels_before/kernels_cpu.json
    python benchmarks/kernels.py --device cuda --ptxas ''    # a GPU machine without ptxas: times only, then
    python benchmarks/kernels.py --report results/kernels/kernels_cpu.json results/kernels/kernels_cuda.json  # joined

Writes ``kernels_<cpu|cuda>.json`` (``kernels_cuda_path.json`` with ``--camera path``; or
``compile_<cpu|cuda>.json``) to ``--out`` after every method, keeping the other methods of an earlier file of the same scene (a run split across
calls fills one file), and prints a markdown table: one row per kernel, the heaviest first, the
ones at the register cap marked.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import platform
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from restir_every_scene import RESTIR_PT_SHIFTS

#: (label, method, params): the ReSTIR family of issue 35, pt as the yardstick, the later methods at the end
VARIANTS: list[tuple[str, str, dict[str, Any]]] = [
    ("pt", "pt", {}),
    ("restir-di", "restir-di", {}),
    ("restir-gi", "restir-gi", {}),
    *((f"restir-pt {s}", "restir-pt", {"shift": s}) for s in RESTIR_PT_SHIFTS),
    *((m, m, {}) for m in ("restcv", "restcv-di", "stcv", "icv", "restir-pt-decoupled", "area-restir",
                           "suffix-restir", "restir-gpt", "gradient-after-restir", "gpt", "sms", "sms-partitioned", "sms-restir")),
]
#: settings timed on request only (``--methods``), beside the defaults: the paper's variants of a default
EXTRA_VARIANTS: list[tuple[str, str, dict[str, Any]]] = [
    ("restir-gpt unpositivized", "restir-gpt", {"positivize": False}),  # seed 000, Fig. 9: 29.9 ms, 39.8 positivized
    ("suffix-restir rouletted", "suffix-restir", {"roulette": True}),  # seed 001, Eq. 23 with R = 1
]
ALL_VARIANTS = VARIANTS + EXTRA_VARIANTS
REGISTER_CAP = 255


# ---------------------------------------------------------------- resources: PTX -> ptxas -v

def ptxas_version(ptxas: str) -> str:
    out = subprocess.run([ptxas, "--version"], capture_output=True, text=True).stdout
    return (re.findall(r"release [^\n]*", out) or ["?"])[0]


def sass_sizes(cubin: Path) -> dict[str, int]:
    """Bytes of SASS per entry function: the sizes of the cubin's ``.text.<entry>`` sections (``readelf``).

    The instruction cache is what a megakernel overflows: Nsight Compute put ~40% of the shift
    stages' stalls on instruction fetch (benchmarks/README.md), so the code's size is a resource
    like the registers.
    """
    readelf = shutil.which("readelf")
    if readelf is None:
        return {}
    out = subprocess.run([readelf, "-S", "-W", str(cubin)], capture_output=True, text=True).stdout
    sizes = {}
    for m in re.finditer(r"\]\s+\.text\.(\S+)\s+PROGBITS\s+\S+\s+\S+\s+([0-9a-f]+)", out):
        sizes[m[1]] = int(m[2], 16)
    return sizes


def run_ptxas(ptx: str, ptxas: str, arch: int) -> tuple[dict[str, dict[str, float]], str]:
    """Per entry function: registers, stack frame, spill store/load bytes, SASS bytes and ptxas ms; and the PTX version fed."""
    version = re.search(r"^\.version (\S+)", ptx, re.M).group(1)
    fed = version
    with tempfile.TemporaryDirectory() as tmp:
        path, cubin = Path(tmp, "m.ptx"), Path(tmp, "m.cubin")
        while True:
            path.write_text(ptx.replace(f".version {version}\n", f".version {fed}\n", 1))
            proc = subprocess.run([ptxas, "-v", f"-arch=sm_{arch}", str(path), "-o", str(cubin)], capture_output=True, text=True)
            older = re.search(r"Unsupported \.version \S+; current version is '(\S+)'", proc.stderr)
            if not older or fed != version:
                break
            fed = older.group(1)  # the newest PTX ISA this ptxas reads
        sass = sass_sizes(cubin) if proc.returncode == 0 else {}
    if proc.returncode != 0:
        raise RuntimeError(f"ptxas failed: {proc.stderr.strip()[-500:]}")
    kernels: dict[str, dict[str, float]] = {}
    entry = None
    for line in proc.stderr.splitlines():
        if m := re.search(r"Compiling entry function '(\S+)'", line):
            entry = kernels.setdefault(re.sub(r"_cuda_kernel_forward$", "", m.group(1)), {})
        elif entry is None:
            continue
        elif m := re.search(r"(\d+) bytes stack frame, (\d+) bytes spill stores, (\d+) bytes spill loads", line):
            if "stack" not in entry:  # the entry's own line comes first; callees' lines follow
                entry.update(stack=int(m[1]), spill_st=int(m[2]), spill_ld=int(m[3]))
        elif m := re.search(r"Used (\d+) registers", line):
            entry["regs"] = int(m[1])
        elif m := re.search(r"Compile time = ([\d.]+) ms", line):
            entry["ptxas_ms"] = float(m[1])
            entry = None
    for name, size in sass.items():
        kernels.get(re.sub(r"_cuda_kernel_forward$", "", name), {})["sass_bytes"] = size
    return kernels, fed if fed == version else f"{version} fed as {fed}"


def module_resources(module: Any, ptxas: str, arch: int) -> dict[str, Any]:
    """Compile ``module`` to sm_``arch`` PTX with Warp's NVRTC (a scratch folder, no cache) and read ptxas -v."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp, "module")
        t0 = time.perf_counter()
        module._compile(None, out, "m.ptx", output_arch=arch, use_ptx=True)
        seconds = time.perf_counter() - t0
        ptx = (out / "m.ptx").read_bytes().rstrip(b"\0").decode()
    kernels, version = run_ptxas(ptx, ptxas, arch)
    return {"module": module.name, "hash": module.get_module_hash(None).hex()[:7], "nvrtc_ptx_s": round(seconds, 2),
            "ptx_version": version, "kernels": kernels}


def watch_loads(on_first_load: Callable[[Any], None]) -> Callable[[], None]:
    """Wrap ``warp.Module.load``: call ``on_first_load(module)`` before a module's first load in this process.

    Before, not after: a CPU build changes what Warp 1.19 hashes afterwards (see ``aot_cuda.py``).
    Returns a function that undoes the wrap.
    """
    from warp._src import context

    original = context.Module.load
    seen: set[str] = set()

    def load(self: Any, *args: Any, **kwargs: Any) -> Any:
        key = f"{self.name} {self.get_module_hash(None).hex()}"
        if key not in seen:
            seen.add(key)
            on_first_load(self)
        return original(self, *args, **kwargs)

    context.Module.load = load
    return lambda: setattr(context.Module, "load", original)


# ---------------------------------------------------------------- time per kernel and per phase

def render_kwargs(method: str, params: dict[str, Any], args: argparse.Namespace, **kw: Any) -> dict[str, Any]:
    from grisx.render.driver import METHODS

    return {"scene": args.scene, "method": method, "params": params, "device": args.device, "seed": 1,
            "camera": args.camera, "spp": 1 if METHODS[method].uses_spp else None, **kw}


@contextlib.contextmanager
def launch_seconds(name: Callable[[Any], str]) -> Iterator[dict[str, float]]:
    """While open, every ``wp.launch`` is timed with the device synchronised on each side; yields seconds per ``name(kernel)``.

    Renderers call ``wp.launch`` through the ``warp`` module, so replacing the module's attribute reaches them all.
    """
    import warp as wp

    seconds: dict[str, float] = defaultdict(float)
    launch = wp.launch

    def timed_launch(kernel: Any, *a: Any, **k: Any) -> Any:
        wp.synchronize()
        t0 = time.perf_counter()
        out = launch(kernel, *a, **k)
        wp.synchronize()
        seconds[name(kernel)] += time.perf_counter() - t0
        return out

    wp.launch = timed_launch
    try:
        yield seconds
    finally:
        wp.launch = launch


def time_method(method: str, params: dict[str, Any], args: argparse.Namespace) -> dict[str, Any]:
    """ms per frame of each phase (pass timer) and of each kernel (synchronised launches) over ``args.frames`` frames after
    the first ``args.warmup`` (1: the first frame, which has no history; more for a reuse method's steady state)."""
    from grisx.render.driver import render

    res = tuple(args.res)
    n, w = args.frames, max(1, args.warmup)
    one = render(**render_kwargs(method, params, args, res=res, frames=w))
    many = render(**render_kwargs(method, params, args, res=res, frames=w + n))
    phases = {k: 1e3 * (v - one.pass_seconds.get(k, 0.0)) / n for k, v in many.pass_seconds.items()}

    with launch_seconds(lambda kernel: f"{kernel.module.name} {unhashed(kernel.get_mangled_name())}") as seconds:  # the warm-up dropped
        render(**render_kwargs(method, params, args, res=res, frames=w + n, progress=lambda i, _: i == w and seconds.clear()))
    return {"frame_ms": 1e3 * statistics.median(many.frame_seconds[w:]), "phase_ms": phases,
            "kernel_ms": {k: 1e3 * v / n for k, v in seconds.items()}}


# ---------------------------------------------------------------- cold and warm compile

def compile_child(label: str, args: argparse.Namespace) -> int:
    """In a fresh process: render one tiny frame of ``label``, timing every Warp module compile; print JSON."""
    from warp._src import context

    from grisx.render.driver import render

    compiles: list[dict[str, Any]] = []
    original = context.Module._compile

    def timed(self: Any, device: Any = None, output_dir: Any = None, output_name: Any = None, output_arch: Any = None, *a: Any, **k: Any) -> Any:
        t0 = time.perf_counter()
        built = original(self, device, output_dir, output_name, output_arch, *a, **k)
        if built:
            compiles.append({"module": self.name, "target": "cpu" if output_arch is None else f"sm_{output_arch}",
                             "seconds": round(time.perf_counter() - t0, 2)})
        return built

    context.Module._compile = timed
    if args.device == "cpu":
        import aot_cuda

        aot_cuda.install_hook(args.arch)  # the CPU process also builds what a GPU would: sm_ARCH cubins
    _, method, params = next(v for v in ALL_VARIANTS if v[0] == label)
    t0 = time.perf_counter()
    render(**render_kwargs(method, params, args, res=(8, 8), frames=1))
    print(json.dumps({"render_s": time.perf_counter() - t0, "compiles": compiles}))
    return 0


def compile_times(label: str, args: argparse.Namespace) -> dict[str, Any]:
    """Cold (empty kernel cache) and warm start of ``label``, each a fresh process."""
    cmd = [sys.executable, __file__, "--compile-child", label, "--device", args.device, "--scene", args.scene, "--arch", str(args.arch)]
    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as cache:
        for run in ("cold", "warm"):
            t0 = time.perf_counter()
            proc = subprocess.run(cmd, capture_output=True, text=True, env=dict(os.environ, WARP_CACHE_PATH=cache))
            wall = time.perf_counter() - t0
            if proc.returncode != 0:
                return {**out, "error": f"{run}: {proc.stderr.strip()[-800:]}"}
            child = json.loads(proc.stdout.strip().splitlines()[-1])
            by_target: dict[str, float] = defaultdict(float)
            for c in child["compiles"]:
                by_target[c["target"]] += c["seconds"]
            cuda = [c for c in child["compiles"] if c["target"] != "cpu"]  # the CUDA build is the one asked about
            slowest = max(cuda or child["compiles"], key=lambda c: c["seconds"], default=None)
            out[run] = {"process_s": round(wall, 2), "render_s": round(child["render_s"], 2),
                        **{f"{'cpu' if t == 'cpu' else 'cuda'}_compile_s": round(s, 2) for t, s in by_target.items()},
                        "slowest": slowest, "compiles": child["compiles"]}
    return out


# ---------------------------------------------------------------- output

def environment(args: argparse.Namespace, dev: Any) -> dict[str, Any]:
    import warp as wp
    from warp._src.context import runtime

    import grisx
    from grisx.device import LAUNCH_BLOCK_DIM, PATH_REGISTERS, SHIFT_REGISTERS, WALK_REGISTERS

    def git(*a: str) -> str:
        return subprocess.run(["git", *a], capture_output=True, text=True, cwd=Path(grisx.__file__).parent).stdout.strip()

    commit = git("rev-parse", "--short", "HEAD") + ("+dirty" if git("status", "--porcelain", "--", ".") else "")
    return {"device": str(dev), "device_name": dev.name if dev.is_cuda else platform.processor() or platform.machine(),
            "commit": commit if not commit.startswith("+") else None, "date": time.strftime("%Y-%m-%d"), "scene": args.scene, "arch": args.arch,
            "block_dim": LAUNCH_BLOCK_DIM, "path_registers": PATH_REGISTERS, "shift_registers": SHIFT_REGISTERS, "walk_registers": WALK_REGISTERS,
            "versions": {"grisx": grisx.__version__, "warp": wp.config.version, "nvrtc": ".".join(map(str, runtime.toolkit_version or ())),
                         "ptxas": ptxas_version(args.ptxas) if args.ptxas else None, "python": platform.python_version()}}


def merge(results: list[dict[str, Any]]) -> dict[str, Any]:
    """Runs of the same code as one: each method's resources from a run that has them (the CPU's), times from one that has them (a GPU's)."""
    out = {**results[0], "methods": {}}
    for result in results:
        for label, rec in result["methods"].items():
            out["methods"].setdefault(label, {}).update({k: v for k, v in rec.items() if v or k not in out["methods"].get(label, {})})
    return out


def unhashed(name: str) -> str:
    """A kernel's mangled name without Warp's hash (which a CPU build of its module can change)."""
    return re.sub(r"_[0-9a-f]{8}$", "", name)


def kernel_rows(result: dict[str, Any]) -> list[dict[str, Any]]:
    """One row per kernel (a module shared by methods counted once), the heaviest first; kernels timed without resources last."""
    rows: dict[str, dict[str, Any]] = {}
    for label, rec in result["methods"].items():
        times = rec.get("kernel_ms", {})  # "module kernel" -> ms
        found = {f"{mod['module']} {unhashed(name)}": k for mod in rec.get("modules", []) for name, k in mod["kernels"].items()}
        found.update({key: {} for key in times if key not in found})
        for key, k in found.items():
            module, name = key.split(" ")
            row = rows.setdefault(key, {"module": module.removeprefix("grisx."), "kernel": re.sub(r"^.*__locals__", "", name), **k, "methods": [], "ms": []})
            row["methods"].append(label)
            if key in times:
                row["ms"].append(times[key])
    return sorted(rows.values(), key=lambda r: (-r.get("regs", 0), -r.get("stack", 0), -max(r["ms"], default=0), r["kernel"]))


def method_list(labels: list[str], every: list[str]) -> str:
    """``restir-pt hybrid, restir-pt replay`` -> ``restir-pt hybrid/replay``; every method of the run -> ``all``."""
    if labels == every and len(every) > 2:
        return "all"
    grouped: dict[str, list[str]] = {}
    for label in labels:
        head, _, variant = label.partition(" ")
        grouped.setdefault(head, []).append(variant)
    return ", ".join(head + (" " + "/".join(v) if any(v) else "") for head, v in grouped.items())


def markdown(result: dict[str, Any]) -> str:
    if result.get("benchmark") == "compile":
        lines = ["| method | cold: process s | CUDA compile s | CPU compile s | slowest module (s) | warm: process s | render s |", "|---" * 7 + "|"]
        for label, r in result["methods"].items():
            cold, warm = r.get("cold", {}), r.get("warm", {})
            slow = cold.get("slowest") or {}
            lines.append(f"| {label} | {cold.get('process_s', '–')} | {cold.get('cuda_compile_s', '–')} | {cold.get('cpu_compile_s', '–')} | "
                         f"{slow.get('module', '–')} {slow.get('target', '')} ({slow.get('seconds', '–')}) | {warm.get('process_s', '–')} | {warm.get('render_s', '–')} |"
                         + (f" error: {r['error'][:80]}" if "error" in r else ""))
        return "\n".join(lines)
    every = list(result["methods"])
    lines = ["| kernel | module | regs | stack B | spill st/ld B | SASS KB | ptxas ms | methods | ms/frame |", "|---" * 9 + "|"]
    for r in kernel_rows(result):
        regs = f"**{r['regs']}** (cap)" if r.get("regs", 0) >= REGISTER_CAP else r.get("regs", "?")
        ms = "–" if not r["ms"] else f"{min(r['ms']):.2f}" + (f"–{max(r['ms']):.2f}" if len(r["ms"]) > 1 else "")  # a range over the methods timed
        lines.append(f"| {r['kernel']} | {r['module']} | {regs} | {r.get('stack', '?')} | {r.get('spill_st', '?')}/{r.get('spill_ld', '?')} | "
                     f"{round(r['sass_bytes'] / 1024) if 'sass_bytes' in r else '?'} | {round(r['ptxas_ms']) if 'ptxas_ms' in r else '?'} | {method_list(r['methods'], every)} | {ms} |")
    timed = {label: r for label, r in result["methods"].items() if "frame_ms" in r}
    if timed:
        lines += ["", "| method | ms/frame | ms/frame of each phase |", "|---|---|---|"]
        lines += [f"| {label} | {r['frame_ms']:.2f} | " + ", ".join(f"{k} {v:.2f}" for k, v in sorted(r["phase_ms"].items(), key=lambda kv: -kv[1]) if v >= 0.005) + " |"
                  for label, r in timed.items()]
    errors = [f"{label}: {r['error']}" for label, r in result["methods"].items() if "error" in r]
    return "\n".join(lines + [""] * bool(errors) + errors)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--scene", default="glossy-room", help="modules are specialised to its material kinds")
    ap.add_argument("--methods", default=None, help="comma-separated labels (default: all of " + ", ".join(v[0] for v in VARIANTS) + "; on request: " + ", ".join(v[0] for v in EXTRA_VARIANTS) + ")")
    ap.add_argument("--res", type=int, nargs=2, default=(1920, 1080), metavar=("W", "H"), help="timing resolution (CUDA)")
    ap.add_argument("--frames", type=int, default=None, help="timed frames after the first (default 32 on CUDA, 0 = no timing on CPU)")
    ap.add_argument("--warmup", type=int, default=1, help="frames rendered before the timed ones (default 1; ReSTIR GI's frame grows "
                    "for some 64 frames: benchmarks/README.md, \"ReSTIR GI's frame grows as its reservoirs fill\")")
    ap.add_argument("--camera", default="static", choices=("static", "path"),
                    help="timing camera: still, or the scene's moving path (the temporal shifts of a still camera can be the identity)")
    ap.add_argument("--arch", type=int, default=90, help="CUDA compute capability of the resource numbers (90: H100/H200)")
    ap.add_argument("--ptxas", default=shutil.which("ptxas"), help="ptxas binary (default: on PATH; without it no resources)")
    ap.add_argument("--compile", action="store_true", help="cold and warm first-use compile time instead of resources")
    ap.add_argument("--compile-child", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--report", type=Path, nargs="+", default=None,
                    help="print the table of written JSONs and exit (several runs of one commit merged: resources from one, times from another)")
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/kernels"))
    args = ap.parse_args(argv)
    if args.report:
        print(markdown(merge([json.loads(p.read_text()) for p in args.report])))
        return 0
    from grisx.device import resolve_device
    from grisx.errors import GrisxError

    try:
        dev = resolve_device(args.device)
    except GrisxError as exc:
        print(f"kernels.py: error: {exc}", file=sys.stderr)
        return 2
    if args.compile_child:
        return compile_child(args.compile_child, args)
    labels = [v[0] for v in VARIANTS] if args.methods is None else args.methods.split(",")
    unknown = set(labels) - {v[0] for v in ALL_VARIANTS}
    if unknown:
        ap.error(f"unknown methods {sorted(unknown)}")
    if args.frames is None:
        args.frames = 32 if dev.is_cuda else 0
    kind = "compile" if args.compile else "kernels"
    camera = "" if args.camera == "static" else f"_{args.camera}"  # a moving camera's times in a file of their own
    path = args.out / f"{kind}_{'cuda' if dev.is_cuda else 'cpu'}{camera}.json"
    result = {"benchmark": kind, **environment(args, dev), "methods": {}}
    if kind == "kernels":
        result.update(res=list(args.res), frames=args.frames, warmup=args.warmup, camera=args.camera)
    if path.exists():  # a run split over several calls fills one file
        earlier = json.loads(path.read_text())
        if earlier.get("scene") == args.scene:
            result["methods"] = {k: v for k, v in earlier["methods"].items() if k not in labels}
    done: dict[str, dict[str, Any]] = {}  # module name + hash -> resources (shared modules compiled once)
    loaded: list[dict[str, Any]] = []  # the current method's modules

    def on_first_load(module: Any) -> None:
        key = f"{module.name} {module.get_module_hash(None).hex()}"
        if key not in done:
            t0 = time.perf_counter()
            done[key] = module_resources(module, args.ptxas, args.arch)
            print(f"  {module.name}: {len(done[key]['kernels'])} kernels, {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
        loaded.append(done[key])

    from grisx.render.driver import render

    for label in labels:
        _, method, params = next(v for v in ALL_VARIANTS if v[0] == label)
        print(f"{label} ...", file=sys.stderr, flush=True)
        t0 = time.perf_counter()
        try:
            if args.compile:
                rec = compile_times(label, args)
            else:
                loaded: list[dict[str, Any]] = []
                undo = watch_loads(on_first_load) if args.ptxas else (lambda: None)
                try:  # a tiny render finds the modules; on CUDA it is also the warm-up
                    render(**render_kwargs(method, params, args, res=tuple(args.res) if dev.is_cuda else (16, 16), frames=2))
                finally:
                    undo()
                rec = {"method": method, "params": params, "modules": loaded}
                if args.frames:
                    rec.update(time_method(method, params, args))
        except Exception as exc:  # one method failing leaves the others' rows
            rec = {"method": method, "params": params, "error": f"{type(exc).__name__}: {exc}"}
        rec["seconds"] = round(time.perf_counter() - t0, 1)
        result["methods"][label] = rec
        args.out.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(result, indent=1))
        print(f"{label}: {rec.get('error', 'done')} ({rec['seconds']} s)", file=sys.stderr, flush=True)
    print(markdown(result))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
