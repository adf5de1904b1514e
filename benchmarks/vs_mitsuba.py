#!/usr/bin/env python
"""grisx's path tracer against Mitsuba 3's on the same scene files, in one process.

For every scene file in ``benchmarks/scenes/`` (a Cornell box at max_depth 5,
two small lights without a BSDF, a room lit only indirectly, a glass and a gold
sphere under a small light: analytic spheres and long specular paths) both renderers
load the *same XML* at ``--res`` and render with the file's ``max_depth``:

* **frame time** at 1 and 16 spp: median of ``--frames`` frames after a
  warm-up (kernels compiled, device synchronized, no copy to the host).
  grisx: :class:`grisx.render.pt.PathTracer`; Mitsuba: ``mi.render`` on the
  ``cuda_ad_rgb`` variant (``llvm_ad_rgb`` on a CPU).
* **efficiency** at 16 spp: 1 / (MSE × time) against one shared reference
  that Mitsuba renders at ``--ref-spp`` (both estimate the same image: the
  files use a box pixel filter), reported as grisx's efficiency over
  Mitsuba's (> 1: grisx converges faster per second).

Ratios are grisx / Mitsuba for times (< 1: grisx faster). Device, versions and
settings are recorded with the results in ``vs_mitsuba.json``.

Usage (needs ``pip install mitsuba``; on a CPU its LLVM backend wants
``DRJIT_LIBLLVM_PATH`` pointing at LLVM >= 17)::

    python benchmarks/vs_mitsuba.py --device cuda            # 1920x1080
    python benchmarks/vs_mitsuba.py --quick                  # CPU smoke test, 96x54
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import warp as wp

import grisx
from grisx.device import FAST_MATH, resolve_device, synchronize
from grisx.render.driver import load_scene
from grisx.render.pt import PathTracer

HERE = Path(__file__).resolve().parent
SCENES = ("cornell_box", "two_lights", "indirect_room", "spheres")


def grisx_times(pt: PathTracer, device, spp: int, frames: int) -> tuple[float, np.ndarray]:
    """Median frame time of ``spp`` samples per pixel, and the last frame's image."""
    pt.spp = spp
    pt.render_frame(0)  # warm-up
    times = []
    for f in range(frames):
        synchronize(device)
        t0 = time.perf_counter()
        img = pt.render_frame(f + 1)
        synchronize(device)
        times.append(time.perf_counter() - t0)
    return statistics.median(times), img.numpy().astype(np.float64)


def mitsuba_times(mi, dr, scene, spp: int, frames: int) -> tuple[float, np.ndarray]:
    img = mi.render(scene, spp=spp, seed=0)  # warm-up: traces and compiles the kernels
    dr.eval(img)
    dr.sync_thread()
    times = []
    for f in range(frames):
        dr.sync_thread()
        t0 = time.perf_counter()
        img = mi.render(scene, spp=spp, seed=f + 1)
        dr.eval(img)
        dr.sync_thread()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), np.asarray(img, dtype=np.float64)[..., :3]


def mitsuba_reference(mi, dr, scene, spp: int, chunk: int) -> np.ndarray:
    total = None
    for i in range(max(1, spp // chunk)):
        img = np.asarray(mi.render(scene, spp=chunk, seed=10_000 + i), dtype=np.float64)[..., :3]
        total = img if total is None else total + img
    return total / max(1, spp // chunk)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--device", default="cuda")
    ap.add_argument("--res", default="1920x1080")
    ap.add_argument("--frames", type=int, default=5)
    ap.add_argument("--ref-spp", type=int, default=1024)
    ap.add_argument("--scenes", nargs="*", default=list(SCENES))
    ap.add_argument("--quick", action="store_true", help="CPU smoke test: 96x54, 2 frames, 64-spp reference")
    ap.add_argument("--out", default=str(HERE / "results"))
    args = ap.parse_args(argv)
    if args.quick:
        args.device, args.res, args.frames, args.ref_spp = "cpu", "96x54", 2, 64
    try:
        import drjit as dr
        import mitsuba as mi
    except ImportError as exc:
        print(f"vs_mitsuba.py: error: Mitsuba 3 is needed (pip install mitsuba): {exc}", file=sys.stderr)
        return 2
    device = resolve_device(args.device)
    mi.set_variant("cuda_ad_rgb" if device.is_cuda else "llvm_ad_rgb")
    w, h = (int(v) for v in args.res.split("x"))
    rows = []
    for name in args.scenes:
        xml = HERE / "scenes" / f"{name}.xml"
        sc = load_scene(str(xml))
        built = sc.build(device)
        pt = PathTracer(built, w, h, spp=1, max_depth=int(sc.defaults["max_depth"]), rr_depth=int(sc.defaults["rr_depth"]))
        wp.load_module(pt.kernel.module, device=device)
        ms = mi.load_file(str(xml), width=str(w), height=str(h))
        row = {"scene": name, "max_depth": int(sc.defaults["max_depth"]), "triangles": built.num_triangles}
        for spp in (1, 16):
            tg, img_g = grisx_times(pt, device, spp, args.frames)
            tm, img_m = mitsuba_times(mi, dr, ms, spp, args.frames)
            row[f"grisx_ms_{spp}spp"] = 1e3 * tg
            row[f"mitsuba_ms_{spp}spp"] = 1e3 * tm
            row[f"time_ratio_{spp}spp"] = tg / tm
        ref = mitsuba_reference(mi, dr, ms, args.ref_spp, chunk=min(64, args.ref_spp))
        mse_g = float(np.mean((img_g - ref) ** 2))
        mse_m = float(np.mean((img_m - ref) ** 2))
        row.update(grisx_mse_16spp=mse_g, mitsuba_mse_16spp=mse_m, mse_ratio_16spp=mse_g / mse_m,
                   efficiency_ratio=(mse_m * row["mitsuba_ms_16spp"]) / (mse_g * row["grisx_ms_16spp"]),
                   image_mean_ratio=float(img_g.mean() / ref.mean()))
        rows.append(row)
        print(f"{name:14s} 1 spp {row['grisx_ms_1spp']:7.2f} / {row['mitsuba_ms_1spp']:7.2f} ms ({row['time_ratio_1spp']:.2f}x)   "
              f"16 spp {row['grisx_ms_16spp']:7.2f} / {row['mitsuba_ms_16spp']:7.2f} ms ({row['time_ratio_16spp']:.2f}x)   "
              f"MSE ratio {row['mse_ratio_16spp']:.2f}  efficiency {row['efficiency_ratio']:.2f}", flush=True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    result = {
        "benchmark": "vs_mitsuba", "device": wp.get_device(str(device)).name if device.is_cuda else platform.processor() or "cpu",
        "grisx": grisx.__version__, "warp": wp.config.version, "mitsuba": mi.__version__, "variant": mi.variant(),
        "fast_math": FAST_MATH and device.is_cuda, "res": [w, h], "frames": args.frames, "ref_spp": args.ref_spp, "python": platform.python_version(),
        "goal": "time_ratio_16spp <= 1 and efficiency_ratio >= 1 on every scene", "rows": rows,
    }
    tag = ("cuda" if device.is_cuda else "cpu") + ("" if FAST_MATH or not device.is_cuda else "_no_fast_math")
    (out / f"vs_mitsuba_{tag}.json").write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {out / f'vs_mitsuba_{tag}.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
