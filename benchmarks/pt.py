#!/usr/bin/env python
"""Frame time and path throughput of the reference path tracer, and what specialization saves.

For ``cornell-box`` and ``door-ajar`` at 1 spp and ``max_depth`` 5 (Mitsuba's
meaning: paths of up to 5 segments) this script renders ``--frames`` frames
at the film size and records the best frame time (device synchronized, the
kernel compiled and warmed before the clock starts) and the throughput in
million camera paths per second. Each scene is rendered twice: with the
kernel specialized to the scene's material kinds (what ``grisx render``
does) and with the all-kinds kernel (diffuse, conductors, dielectrics), so
the gain of compiling only what a scene uses is measured in one run.

Anchor (issue 4, measured here): Mitsuba 3's CUDA path tracer renders its
Cornell box at 1920×1080, 1 spp, max_depth 5 in about 6 ms on an H200.

Usage::

    python benchmarks/pt.py                     # CPU, 320×180
    python benchmarks/pt.py --device cuda       # GPU, 1920×1080

Writes ``pt.json`` and ``pt.png`` to ``--out`` (default ``benchmarks/results/``).
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import warp as wp

import grisx
from grisx.device import resolve_device, synchronize
from grisx.errors import GrisxError
from grisx.scene.builtin import build_builtin
from grisx.scene.material import MATERIAL_KINDS
from grisx.render.pt import PathTracer

SCENES = ("cornell-box", "door-ajar")


def frame_time(pt: PathTracer, device, frames: int) -> float:
    wp.load_module(pt.kernel.module, device=device)
    pt.add_samples(0, 1)  # warm-up
    best = float("inf")
    for f in range(frames):
        synchronize(device)
        t0 = time.perf_counter()
        pt.add_samples(f, 1)
        synchronize(device)
        best = min(best, time.perf_counter() - t0)
    return best


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--res", default=None, help="WxH (default 1920x1080 on CUDA, 320x180 on CPU)")
    ap.add_argument("--frames", type=int, default=None, help="timed frames, best kept (default 20 on CUDA, 3 on CPU)")
    ap.add_argument("--max-depth", type=int, default=5)
    ap.add_argument("--quick", action="store_true", help="CPU smoke test: 160x90, 2 frames")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results"))
    args = ap.parse_args(argv)
    try:
        device = resolve_device(args.device)
    except GrisxError as exc:
        print(f"pt.py: error: {exc}", file=sys.stderr)
        return 2
    cuda = device.is_cuda
    res = args.res or ("1920x1080" if cuda else ("160x90" if args.quick else "320x180"))
    w, h = (int(v) for v in res.split("x"))
    frames = args.frames or (20 if cuda else (2 if args.quick else 3))
    rows = []
    for name in SCENES:
        built = build_builtin(name).build(device)
        for label, kinds in (("specialized", None), ("all kinds", frozenset(MATERIAL_KINDS))):
            pt = PathTracer(built, w, h, spp=1, max_depth=args.max_depth, kinds=kinds)
            t = frame_time(pt, device, frames)
            rows.append({
                "scene": name,
                "kernel": label,
                "material_kinds": sorted(pt_kinds) if (pt_kinds := (kinds or built.features.material_kinds)) else [],
                "width": w,
                "height": h,
                "max_depth": args.max_depth,
                "frame_ms": t * 1e3,
                "mpaths_per_s": w * h / t / 1e6,
            })
    meta = {"device": str(device), "device_name": getattr(device, "name", str(device)), "grisx": grisx.__version__,
            "warp": wp.__version__, "python": platform.python_version(), "frames": frames,
            "anchor": "Mitsuba 3 CUDA path tracer, Cornell box 1920x1080, 1 spp, max_depth 5: about 6 ms on an H200"}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "pt.json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=2))
    print(f"device {meta['device_name']}  {w}x{h}  1 spp  max_depth {args.max_depth}  best of {frames} frames")
    print(f"{'scene':<14}{'kernel':<13}{'frame ms':>10}{'Mpaths/s':>10}")
    for r in rows:
        print(f"{r['scene']:<14}{r['kernel']:<13}{r['frame_ms']:>10.2f}{r['mpaths_per_s']:>10.2f}")
    for name in SCENES:
        spec, full = (next(r for r in rows if r["scene"] == name and r["kernel"] == k) for k in ("specialized", "all kinds"))
        print(f"{name}: specialization speed-up {full['frame_ms'] / spec['frame_ms']:.2f}x")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 3.2))
    labels = [f"{r['scene']}\n{r['kernel']}" for r in rows]
    ax.bar(labels, [r["frame_ms"] for r in rows], color=["#4878a8", "#a8a8a8"] * len(SCENES))
    if cuda:
        ax.axhline(6.0, color="k", ls="--", lw=1, label="Mitsuba 3 anchor (Cornell box, H200)")
        ax.legend(fontsize=8)
    ax.set_ylabel(f"frame ms ({w}x{h}, 1 spp)")
    ax.set_title(f"grisx pt on {meta['device_name']}", fontsize=10)
    fig.tight_layout()
    fig.savefig(out / "pt.png", dpi=120)
    return 0


if __name__ == "__main__":
    sys.exit(main())
