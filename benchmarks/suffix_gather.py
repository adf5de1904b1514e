#!/usr/bin/env python
"""Suffix ReSTIR's final gather, row by row: frame time, pass times and relMSE per static frame (issue 36).

Each row is a method and its params (``"suffix-restir gather_k=1 canonical_suffixes=8"``); every row
renders the same scene under its static camera for ``--frames`` frames, and the relMSE (ε = 1e-2) of
each frame of the second half against one path-traced reference (its own noise subtracted) is
averaged. ``relMSE × ms`` is the figure of merit: lower is better at equal time. Rows are appended
to ``--out`` (JSON lines) as they finish::

    python benchmarks/suffix_gather.py door-ajar "restir-pt" "suffix-restir canonical_suffixes=1 roulette=true" "suffix-restir" --device cuda
    python benchmarks/suffix_gather.py closed-room "suffix-restir" --device cpu --res 96 54 --ref-spp 512 --frames 12
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from protocol import reference_at, reference_relmse  # noqa: E402


def parse_row(row: str) -> tuple[str, dict]:
    """``"method k=v k=v"`` → (method, params), values as int, float or bool where they read as one."""
    method, *kv = row.split()
    params: dict = {}
    for x in kv:
        k, v = x.split("=", 1)
        params[k] = {"true": True, "false": False}.get(v, v)
        for cast in (int, float):
            try:
                params[k] = cast(v)
                break
            except ValueError:
                pass
    return method, params


def main(argv: list[str] | None = None) -> int:
    from grisx.eval.metrics import RELMSE_EPSILON, relmse
    from grisx.render.driver import load_scene, render

    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("scene")
    p.add_argument("rows", nargs="+", help='"method k=v ..." (max_depth 12 unless given)')
    p.add_argument("--device", default="cuda")
    p.add_argument("--res", nargs=2, type=int, default=[1920, 1080])
    p.add_argument("--frames", type=int, default=12)
    p.add_argument("--ref-spp", type=int, default=256)
    p.add_argument("--out", type=Path, default=Path("benchmarks/results/suffix_gather.jsonl"))
    a = p.parse_args(argv)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    w, h = a.res
    built = load_scene(a.scene).build(a.device)
    built.animate_camera = False
    ref, var = reference_at(built, w, h, 0, 12, a.ref_spp, 7)
    noise = reference_relmse(ref, var, RELMSE_EPSILON)
    for row in a.rows:
        method, params = parse_row(row)
        params.setdefault("max_depth", 12)
        errors: list[float] = []
        r = render(a.scene, method, params=params, device=a.device, res=(w, h), frames=a.frames, seed=3, camera="static",
                   on_frame=lambda i, image, s: errors.append(relmse(image, ref)) if i >= a.frames // 2 else None)
        ms = 1e3 * float(np.median(r.frame_seconds[1:]))
        e = float(np.mean(errors)) - noise
        rec = {"scene": a.scene, "row": row, "device": str(r.device), "res": [w, h], "frames": a.frames, "ms": ms, "relmse": e,
               "relmse_x_ms": e * ms, "pass_ms": {k: 1e3 * v / a.frames for k, v in r.pass_seconds.items()}, "stats": r.settings.get("statistics", {})}
        with a.out.open("a") as f:
            f.write(json.dumps(rec) + "\n")
        print(f"{a.scene:12s} {row:60s} {ms:8.1f} ms  relMSE {e:.4f}  relMSE x ms {e * ms:8.2f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
