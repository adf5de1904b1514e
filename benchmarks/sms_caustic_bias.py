#!/usr/bin/env python
"""The caustic under a glass sphere, SMS against the path tracer over independent runs (issue 37).

``scenes/sphere_caustic_crop.xml`` is the conformance scene ``sphere_glass`` (an analytic glass sphere,
IOR 1.5, on a floor under a small light) with the camera narrowed onto the sphere's caustic: every one
of its 16 × 6 pixels is caustic. Each method renders ``--runs`` independent images (seeds 1000, 1001,
…) at ``--spp``; ``pt`` renders ``--pt-runs`` at ``--pt-spp``. Per method: the mean over runs of the
image mean, its standard error, z against pt (both errors), the skewness of the per-run means and the
five largest (SMS's weights are heavy-tailed: a few runs can carry many times the mean).

Usage::

    python benchmarks/sms_caustic_bias.py --runs 1600 --spp 256 --methods sms,sms-partitioned   # CPU, ~5 min
    python benchmarks/sms_caustic_bias.py --device cuda --runs 16000

Writes ``sms_caustic_bias.json`` to ``--out`` after every method.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

import grisx
from grisx.render.driver import render

SCENE = Path(__file__).parent / "scenes" / "sphere_caustic_crop.xml"


def run_means(method: str, runs: int, spp: int, device: str) -> tuple[np.ndarray, float]:
    t0 = time.perf_counter()
    means = np.array([float(render(str(SCENE), method, spp=spp, seed=1000 + i, device=device).image.mean()) for i in range(runs)])
    return means, time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--methods", default="sms,sms-partitioned")
    ap.add_argument("--runs", type=int, default=1600)
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--pt-runs", type=int, default=64)
    ap.add_argument("--pt-spp", type=int, default=4096)
    ap.add_argument("--out", default="benchmarks/results")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    ref, seconds = run_means("pt", args.pt_runs, args.pt_spp, args.device)
    result = {"benchmark": "sms_caustic_bias", "grisx": grisx.__version__, "device": args.device, "scene": SCENE.name,
              "pt": {"runs": args.pt_runs, "spp": args.pt_spp, "mean": ref.mean(), "se": ref.std(ddof=1) / np.sqrt(len(ref)), "seconds": seconds},
              "methods": {}}
    print(f"pt {ref.mean():.5f} ± {result['pt']['se']:.5f} ({seconds:.0f} s)", flush=True)
    for method in args.methods.split(","):
        m, seconds = run_means(method, args.runs, args.spp, args.device)
        se = m.std(ddof=1) / np.sqrt(len(m))
        z = (m.mean() - ref.mean()) / np.hypot(se, result["pt"]["se"])
        row = {"runs": args.runs, "spp": args.spp, "mean": m.mean(), "se": se, "relative": m.mean() / ref.mean() - 1.0, "z": z,
               "skew": float(((m - m.mean()) ** 3).mean() / m.std() ** 3), "median": float(np.median(m)), "largest": np.sort(m)[-5:].tolist(),
               "seconds": seconds}
        result["methods"][method] = row
        print(f"{method}: {row['mean']:.5f} ± {se:.5f} ({100 * row['relative']:+.2f}%, z {z:+.2f}), skew {row['skew']:.1f}, "
              f"largest run {row['largest'][-1]:.2f} ({seconds:.0f} s)", flush=True)
        (out / "sms_caustic_bias.json").write_text(json.dumps(result, indent=2, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
