#!/usr/bin/env python
"""ReSTIR DI with and without its BSDF candidate where light sampling alone should be weakest.

A near-mirror floor (GGX α = 0.02) under a large ceiling light (4 × 4 in a 6 × 6 room): a light
sample rarely falls in the floor's lobe, which is the case a BSDF-sampled candidate defends
(issue 35's lead, `benchmarks/README.md`, "ReSTIR DI's candidates and neighbours"). Per-frame
relMSE (ε = 1e-2, the reference's noise subtracted) of frames 8–15 of independent runs, against pt
at ``max_depth`` 2 and ``--ref-spp``, and the median frame time::

    python benchmarks/di_bsdf_candidate.py --device cpu --out benchmarks/results/di_bsdf_candidate.json
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np


def sharp_room():
    from grisx.scene import builtin as B

    s = B.Scene("sharp-room")
    s.description = "a near-mirror floor (GGX alpha 0.02) under a 4 x 4 ceiling light"
    wall = s.add_material(B.Diffuse((0.75, 0.72, 0.68)), "wall")
    floor = s.add_material(B.RoughConductor(alpha=0.02, specular_reflectance=(0.9, 0.9, 0.9)), "mirror-floor")
    B._room(s, (-3, 0, -3), (3, 3, 3), {"default": wall, "floor": floor})
    B._add(s, B.sphere(), s.add_material(B.Diffuse((0.7, 0.2, 0.15))), B.compose(B.translate((1.0, 0.6, -0.2)), B.scale(0.6)), name="ball")
    B._panel(s, (0, 2.99, 0), (2.0, 2.0), B.rotate((1, 0, 0), 90), wall, emission=(3, 3, 3), name="light")
    B._camera(s, 60, [((0, 1.6, 2.8), (0, 0.8, -1), (0, 1, 0)), ((-1.5, 1.4, 2.6), (0.3, 0.8, -1), (0, 1, 0))])
    s.film = B.Film(96, 72)
    s.defaults = {"spp": 64, "max_depth": 2}
    return s


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--res", nargs=2, type=int, default=[96, 72])
    ap.add_argument("--runs", type=int, default=4)
    ap.add_argument("--frames", type=int, default=16)
    ap.add_argument("--ref-spp", type=int, default=4096)
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/di_bsdf_candidate.json"))
    a = ap.parse_args(argv)
    from grisx.eval.metrics import RELMSE_EPSILON, relmse
    from grisx.render.driver import METHODS, RenderContext, method_params
    from grisx.render.pt import PathTracer

    built = sharp_room().build(a.device)
    built.animate_camera = False
    w, h = a.res
    pt = PathTracer(built, w, h, spp=a.ref_spp, max_depth=2, seed=99)
    pt.add_samples(0, a.ref_spp)
    ref, var = pt.mean().astype(np.float64), pt.variance_of_mean().astype(np.float64)
    noise = float(np.mean(var / (ref**2 + RELMSE_EPSILON)))
    rows = []
    for label, params in [("restir-di", {}), ("restir-di bsdf_candidates=0", {"bsdf_candidates": 0})]:
        errors, seconds = [], []
        for seed in range(a.runs):
            r = METHODS["restir-di"].create(RenderContext(built, w, h, {**method_params("restir-di", params), "spp": 1}, seed, None, "restir-di"))
            for f in range(a.frames):
                t = time.perf_counter()
                image = r.render_frame(f).numpy()
                seconds.append(time.perf_counter() - t)
                if f >= a.frames // 2:
                    errors.append(relmse(image, ref) - noise)
        rows.append({"row": label, "params": params, "relmse": float(np.mean(errors)), "relmse_sd_frames": float(np.std(errors)),
                     "frame_ms": 1e3 * float(np.median(seconds[1:]))})
        print(f"{label:30s} relMSE {rows[-1]['relmse']:.5f}  frame {rows[-1]['frame_ms']:.1f} ms", flush=True)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps({"benchmark": "di_bsdf_candidate", "device": a.device, "res": [w, h], "runs": a.runs, "frames": a.frames,
                                 "ref_spp": a.ref_spp, "rows": rows}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
