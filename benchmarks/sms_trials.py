#!/usr/bin/env python
"""SMS's Bernoulli trials in the sample pass or in a stage of their own (issue 37, seed 003 Table 1).

A solution of small conditional probability P'(u*) needs K ≈ 1/P' Bernoulli trials in series. In a
sample pass that runs them all, one such pixel holds its warp, and so the whole pass, until its last
trial: on ``caustic-slab-plane`` at 1080p single solutions take 4000–5700 trials (9000 Newton steps)
where the mean is 1.5 (CPU tally, 3 seeds). ``inline_trials`` = k runs at most k trials a solution in
the pass and the rest in :class:`grisx.render.sms.BernoulliStage`, many trials at once; k = 0 runs
them all in the pass (the CPU's default). The images are the same bit for bit (the script checks
that, per scene and method, against k = 0).

For each scene and method row, a 1-frame warm-up (compilation), then ``--frames`` frames at
``--width`` × ``--height`` under the static camera, per k in ``--inline``: the frame's device time
(median and spread over frames, protocol v2: the renderers' pass timers), the stage times per frame
(``manifold_sampling``: SMS at x₁ with its trial stage; the path tracer's own sample is ``path_tracing``),
Table 1's tallies,
and max |Δ| of the image against k = 0. The paper's manifold-sampling milliseconds (RTX 4090, with
its cap of 128 trials) stand beside them.

Usage::

    python benchmarks/sms_trials.py --width 64 --height 48 --frames 2            # CPU check
    python benchmarks/sms_trials.py --device cuda --width 1920 --height 1080      # the paper's size

Writes ``sms_trials.jsonl`` (a row at a time) and ``sms_trials.png`` to ``--out``.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
from pathlib import Path
from typing import Any

import numpy as np
import warp as wp

from grisx.device import resolve_device
from grisx.render.driver import render

SCENES = ("caustic-slab", "reflective-plane", "caustic-slab-plane", "benchmarks/scenes/spheres.xml")
#: seed 003, Table 1, manifold sampling ("ours", RTX 4090, 1920×1080, 128 trials at most)
PAPER_MS = {"caustic-slab": 12.4, "reflective-plane": 26.0, "caustic-slab-plane": 41.7}
#: (label, method, params): grisx's default (uncapped, unbiased) and the paper's cap
ROWS = (
    ("sms-partitioned", "sms-partitioned", {}),
    ("sms-partitioned, 128 trials", "sms-partitioned", {"max_trials": 128}),
    ("sms", "sms", {}),
    ("sms-restir", "sms-restir", {}),
)
_ONE_FRAME = {"sms-restir"}


def _render(scene: str, method: str, params: dict[str, Any], args: argparse.Namespace, frames: int) -> Any:
    kw = {"frames": frames} if method in _ONE_FRAME else {"spp": 1, "frames": frames}
    return render(scene, method, res=(args.width, args.height), device=args.device, seed=args.seed, params=params, camera="static", **kw)


def measure(scene: str, label: str, method: str, params: dict[str, Any], k: int, args: argparse.Namespace) -> tuple[dict[str, Any], np.ndarray]:
    prm = {**params, "inline_trials": int(k)}
    _render(scene, method, prm, args, 1)  # warm-up: compilation and caches
    r = _render(scene, method, prm, args, args.frames)
    ms = np.asarray(r.frame_seconds) * 1e3
    row = {
        "scene": scene,
        "row": label,
        "method": method,
        "params": prm,
        "frame_ms_median": float(np.median(ms)),
        "frame_ms_min": float(ms.min()),
        "frame_ms_max": float(ms.max()),
        "stage_ms": {name: 1e3 * s / args.frames for name, s in r.pass_seconds.items()},
        "statistics": r.settings.get("statistics", {}),
        "image_mean": float(r.image.mean()),
    }
    return row, r.image


def plot(rows: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = [lab for lab, _, _ in ROWS]
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    fig, axes = plt.subplots(1, len(scenes), figsize=(4.2 * len(scenes), 3.6), squeeze=False)
    for ax, scene in zip(axes[0], scenes):
        ks = sorted({r["params"]["inline_trials"] for r in rows if r["scene"] == scene})
        width = 0.8 / max(len(ks), 1)
        for j, k in enumerate(ks):
            vals = [next((r["stage_ms"].get("manifold_sampling", np.nan) for r in rows if r["scene"] == scene and r["row"] == lab
                          and r["params"]["inline_trials"] == k), np.nan) for lab in labels]
            ax.bar(np.arange(len(labels)) + j * width, vals, width, label=f"inline_trials={k}")
        if Path(scene).stem in PAPER_MS or scene in PAPER_MS:
            ax.axhline(PAPER_MS.get(scene, np.nan), color="k", ls="--", lw=1, label="paper (RTX 4090)")
        ax.set_xticks(np.arange(len(labels)) + 0.4 - width / 2, labels, rotation=30, ha="right", fontsize=7)
        ax.set_yscale("log")
        ax.set_title(Path(scene).stem, fontsize=9)
        ax.set_ylabel("manifold sampling, ms / frame")
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--width", type=int, default=160)
    ap.add_argument("--height", type=int, default=120)
    ap.add_argument("--frames", type=int, default=6)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--inline", type=int, nargs="+", default=[0, 8], help="inline_trials values; the first is the images' baseline")
    ap.add_argument("--scenes", nargs="*", default=list(SCENES))
    ap.add_argument("--rows", nargs="*", default=[lab for lab, _, _ in ROWS])
    ap.add_argument("--out", default="benchmarks/results")
    args = ap.parse_args(argv)
    args.device = str(resolve_device(args.device))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    dev = wp.get_device(args.device)
    header = {"device": dev.name if dev.is_cuda else platform.processor() or "cpu", "warp": wp.config.version, "res": [args.width, args.height],
              "frames": args.frames, "seed": args.seed}
    rows: list[dict[str, Any]] = []
    with open(out / "sms_trials.jsonl", "w") as f:
        f.write(json.dumps({"header": header}) + "\n")
        for scene in args.scenes:
            for label, method, params in ROWS:
                if label not in args.rows:
                    continue
                base = None
                for k in args.inline:
                    row, image = measure(scene, label, method, params, k, args)
                    base = image if base is None else base
                    row["max_abs_diff_vs_first"] = float(np.abs(image - base).max())
                    row["paper_manifold_sampling_ms"] = PAPER_MS.get(scene)
                    rows.append(row)
                    f.write(json.dumps(row) + "\n")
                    f.flush()
                    print(f"{Path(scene).stem:20s} {label:28s} k={k:<3d} frame {row['frame_ms_median']:8.2f} ms  "
                          f"manifold {row['stage_ms'].get('manifold_sampling', 0):8.2f} ms  |Δ| {row['max_abs_diff_vs_first']:.3g}", flush=True)
    plot(rows, out / "sms_trials.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
