#!/usr/bin/env python
"""The stress suite at full length: soak every reuse renderer, and check the invariances of every method.

For each registered radiance method (a renderer added later joins without edits):

* **soak, static camera** — ``--frames`` frames (10,000 on CUDA) of ``--scenes`` under the static
  camera; the image means of batches of ``--batch`` frames are t-tested against the path tracer
  (``t``: the worst channel), and the worst single-frame relative deviation of the image mean from
  the reference is reported;
* **soak, camera path** — the same number of frames along the scene's camera path: NaN/Inf samples
  dropped (must be 0);
* **reservoir bounds** (renderers with ``reservoirs()``: ReSTIR PT and the methods on its passes) —
  20 times per soak: every confidence, weight sum and UCW finite, the largest confidence (bounded by
  the history cap and the spatial merges) and weight sum, and the frame of the largest confidence;
* **radiance linearity / unit invariance** — the fraction of pixel values that change by more than
  1e-3 (relative) when every emitter is ×10⁶ / ×10⁻⁶, or the scene and camera ×10⁻³ / ×10³
  (``tests/render/test_invariance.py`` at larger size).

Usage::

    python benchmarks/stress.py --device cuda --frames 10000 --res 320x240     # the full table
    python benchmarks/stress.py --quick                                        # CPU, 200 frames, 16x16

Writes ``stress.json`` (device, versions, settings, one row per method × scene × stress) to ``--out``
and prints the table.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "render"))


def soak(method: str, scene: str, camera: str, args: argparse.Namespace) -> dict[str, Any]:
    from grisx.render.driver import METHODS, RenderContext, load_scene, method_params
    from grisx.render.pt import PathTracer

    built = load_scene(scene).build(args.device)
    built.animate_camera = camera == "moving"
    spec = METHODS[method]
    params = {**method_params(method, {}), "spp": 1}
    depth = spec.reference_max_depth or int(load_scene(scene).defaults.get("max_depth", 16))
    if "max_depth" in params:
        params["max_depth"] = depth
    r = spec.create(RenderContext(built, *args.res, params, args.seed, None, method))
    frame_means = np.empty((args.frames, 3))
    start = time.perf_counter()
    bounds = {"max_confidence": 0.0, "max_w_sum": 0.0, "reservoirs_finite": True, "worst_confidence_frame": -1}
    for f in range(args.frames):
        built.set_frame(float(f))
        frame_means[f] = r.render_frame(f).numpy().reshape(-1, 3).mean(axis=0)
        if hasattr(r, "reservoirs") and (f + 1) % max(1, args.frames // 20) == 0:  # 20 looks at the reservoirs
            res = r.reservoirs()["res"]
            conf, w_sum = res["confidence"].astype(np.float64), res["w_sum"].astype(np.float64)
            bounds["reservoirs_finite"] &= bool(np.all(np.isfinite(conf)) and np.all(np.isfinite(w_sum)) and np.all(np.isfinite(res["ucw"])))
            if conf.max() > bounds["max_confidence"]:
                bounds.update(max_confidence=float(conf.max()), worst_confidence_frame=f)
            bounds["max_w_sum"] = max(bounds["max_w_sum"], float(w_sum.max()))
    seconds = time.perf_counter() - start
    row = {"method": method, "scene": scene, "stress": f"soak-{camera}", "frames": args.frames, "seconds": seconds,
           "nonfinite_samples": int(r.nonfinite_samples), "finite": bool(np.all(np.isfinite(frame_means)))}
    if hasattr(r, "reservoirs"):
        row.update(bounds)
    if camera == "static":
        pt = PathTracer(built, *args.res, spp=args.reference_spp, max_depth=depth, seed=args.seed + 1)
        pt.add_samples(0, args.reference_spp)
        ref = pt.mean().reshape(-1, 3).mean(axis=0).astype(np.float64)
        ref_se = np.sqrt(pt.variance_of_mean().reshape(-1, 3).astype(np.float64).sum(axis=0)) / (args.res[0] * args.res[1])
        batches = frame_means[: args.frames // args.batch * args.batch].reshape(-1, args.batch, 3).mean(axis=1)
        se = batches.std(axis=0, ddof=1) / np.sqrt(len(batches))
        t = (batches.mean(axis=0) - ref) / np.sqrt(se**2 + ref_se**2)
        row.update({"t": float(np.max(np.abs(t))), "t_per_channel": t.tolist(),
                    "worst_frame_relative_deviation": float(np.max(np.abs(frame_means / ref - 1.0))),
                    "passed": bool(row["nonfinite_samples"] == 0 and np.max(np.abs(t)) <= 4.0)})
    else:
        row["passed"] = bool(row["nonfinite_samples"] == 0 and row["finite"])
    return row


def invariance(method: str, scene: str, stress: str, args: argparse.Namespace) -> dict[str, Any]:
    from test_invariance import scaled_emission, scaled_units

    from grisx.render.driver import METHODS, render
    from grisx.scene.builtin import build_builtin

    spp = 2 if METHODS[method].uses_spp else None

    def image(sc: Any) -> np.ndarray:
        return render(sc, method, res=args.res, frames=3, seed=args.seed, spp=spp, device=args.device).image.astype(np.float64)

    base = image(build_builtin(scene))
    worst = 0.0
    for k in ((1e6, 1e-6) if stress == "linearity" else (1e-3, 1e3)):
        sc = scaled_emission(build_builtin(scene), k) if stress == "linearity" else scaled_units(build_builtin(scene), k)
        img = image(sc) / (k if stress == "linearity" else 1.0)
        worst = max(worst, float(np.mean(np.abs(img - base) / (np.abs(base) + 1e-3) > 1e-3)))
    return {"method": method, "scene": scene, "stress": stress, "changed_fraction": worst, "passed": worst <= 0.01}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--scenes", default="cornell-box,closed-room,glossy-room")
    ap.add_argument("--methods", default=None, help="comma-separated radiance methods (default: every registered one; named ones are soaked even when they take spp)")
    ap.add_argument("--res", default=None, help="WxH (default 320x240 on CUDA, 16x16 on CPU)")
    ap.add_argument("--frames", type=int, default=None, help="soak frames (default 10000 on CUDA, 1000 on CPU)")
    ap.add_argument("--batch", type=int, default=100)
    ap.add_argument("--reference-spp", type=int, default=4096)
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parent / "results")
    args = ap.parse_args(argv)
    import warp as wp

    import grisx
    from grisx.device import resolve_device
    from grisx.render.driver import METHODS, parse_res

    dev = resolve_device(args.device)
    args.res = parse_res(args.res or ("320x240" if dev.is_cuda else "16x16"))
    args.frames = args.frames or (10000 if dev.is_cuda else (200 if args.quick else 1000))
    scenes = args.scenes.split(",")[:1] if args.quick else args.scenes.split(",")
    rows = []
    methods = args.methods.split(",") if args.methods else sorted(n for n, m in METHODS.items() if m.kind == "radiance")
    for method in methods:
        for scene in scenes:
            # spp methods keep nothing between frames, except where asked by name (gpt: the Poisson solve's warm start)
            if not METHODS[method].uses_spp or args.methods:
                for camera in ("static", "moving"):
                    rows.append(soak(method, scene, camera, args))
                    print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
        rows.append(invariance(method, "cornell-box", "linearity", args))
        rows.append(invariance(method, "cornell-box", "units", args))
    result = {"benchmark": "stress", "device": str(dev), "device_name": dev.name if dev.is_cuda else platform.machine(),
              "versions": {"grisx": grisx.__version__, "warp": wp.config.version, "numpy": np.__version__},
              "settings": {"scenes": scenes, "res": list(args.res), "frames": args.frames, "batch": args.batch,
                           "reference_spp": args.reference_spp, "seed": args.seed},
              "rows": rows}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "stress.json").write_text(json.dumps(result, indent=2))
    print(f"{'method':10s} {'scene':12s} {'stress':12s} {'pass':5s} {'NaN/Inf':>8s} {'|t|':>6s} {'worst frame':>11s} {'changed':>8s}")
    for r in rows:
        t = f"{r['t']:6.2f}" if "t" in r else "     -"
        w = f"{r['worst_frame_relative_deviation']:11.3g}" if "worst_frame_relative_deviation" in r else "          -"
        c = f"{r['changed_fraction']:8.2%}" if "changed_fraction" in r else "       -"
        n = f"{r['nonfinite_samples']:8d}" if "nonfinite_samples" in r else "       -"
        print(f"{r['method']:10s} {r['scene']:12s} {r['stress']:12s} {str(r['passed']):5s} {n} {t} {w} {c}")
    return 0 if all(r["passed"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
