#!/usr/bin/env python
"""Run time against error for the gradient-domain estimators of seed 000 (``f1-f2``, ``gradient-row``).

For every method this script runs a ladder of trial counts and records
``seconds`` (``Estimate.seconds``: launches plus the host reduction, kernels
compiled before the clock starts, device synchronized before it is read; best
of ``--repeats``), the error of the mean ``rmse`` and what the run's stderr
predicts for it. From each method's largest run it derives the variance of one
trial, the efficiency 1 / (variance × seconds per trial), and the equal-time
**efficiency ratio** to a baseline measured in the same run.

``f1-f2`` (Fig. 3; ``--offset`` d, default 0.5: a partial inner shift), all
with M = 8 candidates or samples per pixel: ``mc-difference``, ``gradient-pt``,
``gradient-after-restir``, ``gradient-with-restir`` with and without
positivization, and both ReSTIR methods with two frames of temporal reuse.
The headline is gradient-with over gradient-after (the paper's claim that
resampling *in* the paired-pixel domain beats resampling the pixels).

``gradient-row`` (16 pixels, stripes of 4, M = 2, 3 earlier frames):
``gradient-pt``, ``gradient-after-restir`` and ``gradient-with-restir``
with spatial reuse ``none`` / ``dense`` / ``adaptive``; the baseline is
``gradient-with-restir spatial=none``. Components are the 15 gradients. The
same three spatial modes run again with ``light_drift=0`` (the outer shift then
maps neighbouring pairs' integrands onto each other), against their own
``spatial=none`` baseline.

Usage::

    python benchmarks/gradient.py                 # CPU (a few minutes)
    python benchmarks/gradient.py --quick         # small ladders
    python benchmarks/gradient.py --device cuda --max-trials 1e7

Writes ``gradient.json`` and ``gradient.png`` to ``--out`` (default
``benchmarks/results/``) and prints the tables.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import platform
import sys
from pathlib import Path
from typing import Any

import numpy as np
import warp as wp

import grisx
from grisx.device import resolve_device
from grisx.errors import GrisxError

# the trial ladder, one timed run and the CPU name are benchmarks/toys.py's
_spec = importlib.util.spec_from_file_location("_grisx_bench_toys", Path(__file__).with_name("toys.py"))
_toys = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_toys)  # type: ignore[union-attr]
ladder, run_method, cpu_model = _toys.ladder, _toys.run_method, _toys.cpu_model


def f1f2_methods(offset: float) -> list[tuple[str, str, str, dict[str, Any]]]:
    base = {"offset": offset, "candidates": 8}
    return [
        ("f1-f2", "mc-difference", "mc-difference", base),
        ("f1-f2", "gradient-pt", "gradient-pt", base),
        ("f1-f2", "gradient-after", "gradient-after-restir", base),
        ("f1-f2", "gradient-with", "gradient-with-restir", base),
        ("f1-f2", "gradient-with positivize=false", "gradient-with-restir", dict(base, positivize=False)),
        ("f1-f2", "gradient-after frames=2", "gradient-after-restir", dict(base, frames=2)),
        ("f1-f2", "gradient-with frames=2", "gradient-with-restir", dict(base, frames=2)),
        ("f1-f2", "gradient-with frames=2 cross_sign", "gradient-with-restir", dict(base, frames=2, cross_sign=True)),
    ]


ROW_METHODS: list[tuple[str, str, str, dict[str, Any]]] = [
    ("gradient-row", "gradient-pt", "gradient-pt", {}),
    ("gradient-row", "gradient-after", "gradient-after-restir", {}),
    ("gradient-row", "gradient-with spatial=none", "gradient-with-restir", {"spatial": "none"}),
    ("gradient-row", "gradient-with spatial=dense", "gradient-with-restir", {"spatial": "dense"}),
    ("gradient-row", "gradient-with spatial=adaptive", "gradient-with-restir", {"spatial": "adaptive"}),
    ("gradient-row", "gradient-with spatial=dense frames=0", "gradient-with-restir", {"spatial": "dense", "frames": 0}),
    ("gradient-row", "gradient-with spatial=adaptive frames=0", "gradient-with-restir", {"spatial": "adaptive", "frames": 0}),
    ("gradient-row", "gradient-with spatial=none frames=0", "gradient-with-restir", {"spatial": "none", "frames": 0}),
]
#: the same row with light_drift = 0, where the outer shift maps neighbouring pairs' integrands onto each other
ROW0 = "gradient-row light_drift=0"
ROW0_METHODS: list[tuple[str, str, str, dict[str, Any]]] = [
    ("gradient-row", label, "gradient-with-restir", {"spatial": sp, "light_drift": 0.0})
    for label, sp in (("gradient-with spatial=none", "none"), ("gradient-with spatial=dense", "dense"), ("gradient-with spatial=adaptive", "adaptive"))
]
BASELINES = {"f1-f2": "gradient-after", "gradient-row": "gradient-with spatial=none", ROW0: "gradient-with spatial=none"}


def summarize(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """benchmarks/toys.py's equal-time summary against this script's baselines, plus variance and time ratios."""
    out = _toys.equal_time(rows, BASELINES)
    by_key = {(s["problem"], s["method"]): s for s in out}
    for s in out:
        base = by_key[(s["problem"], s["baseline"])]
        s["variance_ratio"] = base["variance_per_trial"] / s["variance_per_trial"]
        s["time_ratio"] = s["seconds_per_trial"] / base["seconds_per_trial"]
        s["stats"] = next((r.get("stats") for r in rows if (r["problem"], r["method"], r["trials"]) == (s["problem"], s["method"], s["trials"])), None)
    return out


def print_table(summary: list[dict[str, Any]]) -> None:
    for problem in BASELINES:
        print(f"\n{problem} (baseline: {BASELINES[problem]})")
        print(f"{'method':42s} {'trials':>9s} {'us/trial':>9s} {'var/trial':>10s} {'var gain':>9s} {'time x':>7s} {'eff. ratio':>10s} {'max|z|':>7s}")
        for s in summary:
            if s["problem"] == problem:
                print(f"{s['method']:42s} {s['trials']:9d} {1e6 * s['seconds_per_trial']:9.3f} {s['variance_per_trial']:10.4g} "
                      f"{s['variance_ratio']:9.2f} {s['time_ratio']:7.2f} {s['efficiency_ratio']:10.2f} {s['max_abs_z']:7.2f}")


def plot(rows: list[dict[str, Any]], path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(BASELINES), figsize=(6.5 * len(BASELINES), 4.8))
    for ax, problem in zip(axes, BASELINES):
        labels = list(dict.fromkeys(r["method"] for r in rows if r["problem"] == problem))
        for label in labels:
            pts = sorted((r for r in rows if r["problem"] == problem and r["method"] == label), key=lambda r: r["trials"])
            ax.loglog([r["seconds"] for r in pts], [r["rmse_predicted"] for r in pts], "o-", ms=3, label=label)
        ax.set_xlabel("seconds")
        ax.set_ylabel("RMSE of the mean (predicted by stderr)")
        ax.set_title(problem)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parent / "results")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--max-trials", type=float, default=None, help="largest f1-f2 trial count (default 1e6, 1e5 with --quick)")
    ap.add_argument("--row-trials", type=float, default=None, help="largest gradient-row trial count (default 3e4, 3e3 with --quick)")
    ap.add_argument("--offset", type=float, default=0.5, help="f1-f2 offset d (partial inner shift for d > 0)")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    try:
        device = resolve_device(args.device)
    except GrisxError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    max_trials = int(args.max_trials or (100_000 if args.quick else 1_000_000))
    row_trials = int(args.row_trials or (3_000 if args.quick else 30_000))
    repeats = 1 if args.quick else args.repeats
    print(f"device {device} ({cpu_model() if device.is_cpu else device.name}), warp {wp.config.version}, numpy {np.__version__}, seed {args.seed}")

    rows = []
    plan = [(m, ladder(max_trials)) for m in f1f2_methods(args.offset)] + [(m, [n for n in (1_000, 3_000, 10_000, 30_000, 100_000) if n < row_trials] + [row_trials]) for m in ROW_METHODS + ROW0_METHODS]
    for (problem, label, method, params), counts in plan:
        for n in counts:
            r = run_method(problem, label, method, params, n, args.seed, str(device), repeats)
            if problem == "gradient-row" and method == "gradient-with-restir":
                from grisx.theory.toys import run_toy

                r["stats"] = run_toy(problem, method, trials=min(n, 2000), seed=args.seed, params=params, device=str(device)).stats
            if "light_drift" in params:
                r["problem"] = ROW0  # its own instance: compared with its own baseline
            rows.append(r)
            print(f"  {problem:13s} {label:42s} {n:>9d} trials  {r['seconds']:8.3f} s  rmse {r['rmse']:.3g} (pred. {r['rmse_predicted']:.3g})  max|z| {r['max_abs_z']:.2f}")
    summary = summarize(rows)
    print_table(summary)
    ratio = next(s["efficiency_ratio"] for s in summary if s["problem"] == "f1-f2" and s["method"] == "gradient-with")
    print(f"\nequal-time efficiency ratio, gradient-with / gradient-after on f1-f2 (offset {args.offset}): {ratio:.2f}")

    args.out.mkdir(parents=True, exist_ok=True)
    result = {
        "benchmark": "gradient",
        "device": str(device),
        "device_name": cpu_model() if device.is_cpu else device.name,
        "cpu_model": cpu_model(),
        "versions": {"grisx": getattr(grisx, "__version__", None), "warp": wp.config.version, "numpy": np.__version__, "python": platform.python_version()},
        "platform": platform.platform(),
        "seed": args.seed,
        "settings": {
            "f1f2_ladder": ladder(max_trials), "row_max_trials": row_trials, "repeats": repeats, "offset": args.offset, "quick": args.quick,
            "methods": [{"problem": p, "label": label, "method": m, "params": prm} for p, label, m, prm in f1f2_methods(args.offset) + ROW_METHODS + ROW0_METHODS],
            "baselines": BASELINES,
        },
        "rows": rows,
        "summary": summary,
        "f1f2_gradient_with_over_after_efficiency_ratio": ratio,
    }
    (args.out / "gradient.json").write_text(json.dumps(result, indent=1))
    plot(rows, args.out / "gradient.png", f"seed 000 gradient estimators, {result['device_name']}")
    print(f"wrote {args.out / 'gradient.json'} and {args.out / 'gradient.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
