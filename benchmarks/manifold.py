#!/usr/bin/env python
"""Specular manifold sampling on ``sms-toy``: RMSE against seconds and seed 003's Table 1 columns.

Methods (all with unbounded Bernoulli trials, ``max_trials=0``, so every one
is unbiased and the error is pure variance):

* ``sms`` — plain SMS (seed 003, Eq. 1–3), the baseline;
* ``sms-partitioned`` with N ∈ {4, 8, 16, 32} tiles, with and without the
  prior (Eq. 4–9);
* ``sms-restir`` (N = 16 with prior, 4 frames of temporal + spatial reuse with
  manifold shifts; its components are the last frame's pixels).

For each method a ladder of trial counts is run (one trial = all 8 pixels of
the row; for ReSTIR all 4 frames) and records ``seconds``
(:attr:`Estimate.seconds`: launches + host reduction, compilation excluded,
device synchronized before the clock is read; fastest of ``--repeats``),
``rmse`` (error of the mean, √ mean over pixels of (estimate − exact)²) and
``rmse_predicted`` (√ mean stderr²). From the largest run: the Table 1
statistics (success rate, Newton iterations per sample, Bernoulli trials per
solution, Newton iterations per solution), the variance of one trial, the
efficiency 1/(variance × seconds per trial) and its ratio to SMS (equal-time
comparison within this one run), and the ratio of Newton iterations per
solution SMS / method (seed 003 reports 67 → 8.7 on its slab scene and
1183 → 39 on its plane scene).

A second table measures the **energy loss** of the cap used in seed 003's
results (``max_trials=128``) and of smaller caps, for SMS and N = 16 tiles:
(estimate − exact)/exact with its standard error.

Usage::

    python benchmarks/manifold.py                  # CPU, ladder up to 1e5 trials
    python benchmarks/manifold.py --quick          # ladder up to 1e4
    python benchmarks/manifold.py --device cuda --max-trials 1e6

Writes ``manifold.json`` and ``manifold.png`` to ``--out`` (default
``benchmarks/results/``) and prints the tables.
"""

from __future__ import annotations

import json
import math
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import warp as wp

import grisx
from grisx.theory.toys import run_toy

sys.path.insert(0, str(Path(__file__).resolve().parent))
from toys import cpu_model, ladder, ladder_parser, ladder_setup  # noqa: E402  (benchmarks/toys.py: the shared trial ladder, its options and the CPU-model probe)

PROBLEM = "sms-toy"
BASELINE = "SMS"
METHODS: list[tuple[str, str, dict[str, Any]]] = [("SMS", "sms", {})]
for _n in (4, 8, 16, 32):
    METHODS.append((f"N={_n}", "sms-partitioned", {"tiles": _n, "prior": False}))
    METHODS.append((f"N={_n} + prior", "sms-partitioned", {"tiles": _n, "prior": True}))
METHODS.append(("N=16 + prior + ReSTIR", "sms-restir", {"tiles": 16, "prior": True}))
#: the reference partitioned configuration for the headline Newton ratio (seed 003 uses N = 16 or 32 with prior)
HEADLINE = "N=16 + prior"
CAPS = (2, 8, 32, 128)
LADDER = (1_000, 3_000, 10_000, 30_000, 100_000, 300_000, 1_000_000, 3_000_000)
TABLE1 = ("success_rate", "newton_per_sample", "bernoulli_per_solution", "newton_per_solution")



def run_method(label: str, method: str, params: dict[str, Any], trials: int, seed: int, device: str, repeats: int) -> dict[str, Any]:
    runs = [run_toy(PROBLEM, method, trials=trials, seed=seed, params=params, device=device) for _ in range(repeats)]
    e = runs[0]
    est, ex, se = (np.atleast_1d(np.asarray(a, dtype=np.float64)) for a in (e.estimate, e.exact, e.stderr))
    seconds = min(r.seconds for r in runs)
    return {
        "method": label,
        "toy_method": method,
        "params": dict(e.params),
        "trials": trials,
        "seconds": seconds,
        "seconds_all_repeats": [r.seconds for r in runs],
        "trials_per_second": trials / seconds,
        "rmse": float(np.sqrt(np.mean((est - ex) ** 2))),
        "rmse_predicted": float(np.sqrt(np.mean(se**2))),
        "variance_per_trial": float(np.mean(se**2) * trials),
        "max_abs_z": float(np.max(np.abs((est - ex) / se))),
        "stats": {k: float(v) for k, v in (e.stats or {}).items()},
        "estimate": est.tolist(),
        "stderr": se.tolist(),
        "exact": ex.tolist(),
    }


def summarize(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per method at its largest count: Table 1 columns, efficiency and Newton ratio against SMS."""
    largest: dict[str, dict[str, Any]] = {}
    for r in rows:
        if r["method"] not in largest or r["trials"] > largest[r["method"]]["trials"]:
            largest[r["method"]] = r
    base = largest[BASELINE]
    base_eff = 1.0 / (base["variance_per_trial"] * base["seconds"] / base["trials"])
    out = []
    for label, r in largest.items():
        spt = r["seconds"] / r["trials"]
        eff = 1.0 / (r["variance_per_trial"] * spt)
        nps = r["stats"]["newton_per_solution"]
        frames = int(r["params"].get("frames", 1)) if r["toy_method"] == "sms-restir" else 1
        out.append(
            {
                "method": label,
                "trials": r["trials"],
                **{k: r["stats"][k] for k in TABLE1},
                "newton_total_per_sample": r["stats"]["newton_total_per_sample"],
                "seconds_per_trial": spt,
                "variance_per_trial": r["variance_per_trial"],
                "efficiency_ratio": eff / base_eff,
                # ReSTIR's trial renders `frames` frames and scores the last: per displayed frame it costs 1/frames
                "frames_per_trial": frames,
                "efficiency_ratio_per_frame": eff * frames / base_eff,
                "rmse_at_baseline_time": math.sqrt(r["variance_per_trial"] * spt / base["seconds"]),
                "newton_per_solution_ratio": base["stats"]["newton_per_solution"] / nps if nps > 0 else None,
                "max_abs_z": r["max_abs_z"],
            }
        )
    return out


def energy_loss(trials: int, seed: int, device: str) -> list[dict[str, Any]]:
    out = []
    for label, method, extra in (("SMS", "sms", {}), ("N=16", "sms-partitioned", {"tiles": 16, "prior": False}), ("N=16 + prior", "sms-partitioned", {"tiles": 16, "prior": True})):
        for cap in CAPS:
            e = run_toy(PROBLEM, method, trials=trials, seed=seed, params={"max_trials": cap} | extra, device=device)
            est, ex, se = (np.asarray(a, dtype=np.float64) for a in (e.estimate, e.exact, e.stderr))
            rel = (est.sum() - ex.sum()) / ex.sum()  # over the whole row
            out.append({"method": label, "max_trials": cap, "relative_bias": float(rel), "relative_bias_stderr": float(math.sqrt(np.sum(se**2)) / ex.sum()), "capped_per_solution": float(e.stats["capped_per_solution"]), "bernoulli_per_solution": float(e.stats["bernoulli_per_solution"])})
    return out


def print_tables(summary: list[dict[str, Any]], loss: list[dict[str, Any]]) -> None:
    print("\nTable 1 columns (largest run of each method) and equal-time efficiency against SMS")
    print(f"{'method':<24}{'success':>9}{'Newton/':>9}{'Bern./':>8}{'Newton/':>9}{'Newton/sol':>11}{'all Newton/':>12}{'var/trial':>11}{'eff. ratio':>11}{'per frame':>10}{'max|z|':>8}")
    print(f"{'':<24}{'rate':>9}{'sample':>9}{'sol.':>8}{'sol.':>9}{'SMS ratio':>11}{'sample':>12}")
    for s in summary:
        ratio = s["newton_per_solution_ratio"]
        print(
            f"{s['method']:<24}{s['success_rate']:9.1%}{s['newton_per_sample']:9.2f}{s['bernoulli_per_solution']:8.2f}{s['newton_per_solution']:9.2f}"
            f"{(f'{ratio:.1f}x' if ratio else '-'):>11}{s['newton_total_per_sample']:12.2f}{s['variance_per_trial']:11.3g}{s['efficiency_ratio']:11.2f}{s['efficiency_ratio_per_frame']:10.2f}{s['max_abs_z']:8.2f}"
        )
    print("\nEnergy loss of capped Bernoulli trials: (estimate - exact)/exact over the row")
    print(f"{'method':<16}{'max_trials':>11}{'rel. bias':>12}{'± stderr':>10}{'capped/sol.':>12}")
    for r in loss:
        print(f"{r['method']:<16}{r['max_trials']:>11}{r['relative_bias']:12.4%}{r['relative_bias_stderr']:10.4%}{r['capped_per_solution']:12.4f}")


def plot(rows: list[dict[str, Any]], summary: list[dict[str, Any]], path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(13, 5))
    ax = axes[0]
    labels = [m[0] for m in METHODS]
    cmap = plt.get_cmap("tab20")
    for i, label in enumerate(labels):
        rs = sorted((r for r in rows if r["method"] == label), key=lambda r: r["trials"])
        style = "--" if "prior" not in label and label != BASELINE else "-"
        ax.loglog([r["seconds"] for r in rs], [r["rmse_predicted"] for r in rs], style, marker="o", ms=3, color="k" if label == BASELINE else cmap(i), label=label, lw=2 if label in (BASELINE, HEADLINE) or "ReSTIR" in label else 1)
    ax.set_xlabel("seconds")
    ax.set_ylabel("RMSE of the mean (from stderr)")
    ax.legend(fontsize=7, ncol=2)
    ax.grid(True, which="both", alpha=0.3)
    ax.set_title("RMSE against time (unbounded Bernoulli trials)")
    ax = axes[1]
    names = [s["method"] for s in summary]
    ax.barh(names, [s["newton_per_solution"] for s in summary], color=["k"] + [cmap(i) for i in range(1, len(names))])
    ax.invert_yaxis()
    ax.set_xlabel("Newton iterations per solution (Bernoulli trials)")
    ax.set_title("Cost of the inverse probability (Table 1)")
    fig.suptitle(title, fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = ladder_parser(__doc__.split("\n\n")[0], default_trials=100_000, quick_trials=10_000, repeats=1)
    args, device, out, max_trials = ladder_setup(parser, argv, min_trials=1000)
    counts = ladder(max_trials, LADDER)
    device_name = cpu_model() if device.is_cpu else device.name
    print(f"device {device} ({device_name}), warp {wp.config.version}, numpy {np.__version__}, seed {args.seed}")
    print(f"trial ladder {counts}, best of {args.repeats}")
    run_toy(PROBLEM, "sms", trials=16, seed=args.seed, device=args.device)  # load the kernel module before any clock

    rows = []
    for label, method, params in METHODS:
        for n in counts:
            r = run_method(label, method, {"max_trials": 0} | params, n, args.seed, args.device, args.repeats)
            rows.append(r)
            print(f"  {label:24s} N = {n:>9,d}  {r['seconds']:8.3f} s  RMSE {r['rmse']:.3e} (pred. {r['rmse_predicted']:.3e})  max|z| {r['max_abs_z']:.2f}", flush=True)
    summary = summarize(rows)
    loss = energy_loss(max_trials, args.seed, args.device)
    print_tables(summary, loss)
    head = next(s for s in summary if s["method"] == HEADLINE)
    best = max(summary, key=lambda s: s["newton_per_solution_ratio"] or 0.0)
    print(f"\nNewton iterations per solution: SMS {summary[0]['newton_per_solution']:.2f} -> {HEADLINE} {head['newton_per_solution']:.2f} "
          f"({head['newton_per_solution_ratio']:.1f}x fewer; best {best['method']} {best['newton_per_solution_ratio']:.1f}x). "
          "Seed 003: 67.4 -> 8.67 (7.8x, slab), 1182.7 -> 39.1 (30x, plane).")

    result = {
        "benchmark": "manifold",
        "device": str(device),
        "device_name": device_name,
        "cpu_model": cpu_model(),
        "cpu_threads_used_by_warp_kernels": 1 if device.is_cpu else None,
        "versions": {"grisx": getattr(grisx, "__version__", None), "warp": wp.config.version, "numpy": np.__version__, "python": platform.python_version()},
        "platform": platform.platform(),
        "seed": args.seed,
        "settings": {
            "problem": PROBLEM,
            "trial_ladder": counts,
            "max_trials": max_trials,
            "repeats": args.repeats,
            "quick": args.quick,
            "methods": [{"label": lab, "method": m, "params": {"max_trials": 0} | pa} for lab, m, pa in METHODS],
            "baseline": BASELINE,
            "energy_loss_caps": list(CAPS),
        },
        "rows": rows,
        "summary": summary,
        "newton_per_solution_ratio": {"sms": summary[0]["newton_per_solution"], HEADLINE: head["newton_per_solution"], "ratio": head["newton_per_solution_ratio"], "paper": {"slab": [67.42, 8.67], "plane": [1182.72, 39.05]}},
        "energy_loss": loss,
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    }
    (out / "manifold.json").write_text(json.dumps(result, indent=1))
    title = f"grisx sms-toy benchmark — {device_name} ({device}), warp {wp.config.version}, seed {args.seed}; Warp CPU kernels run on one thread"
    plot(rows, summary, out / "manifold.png", title)
    print(f"\nwrote {out / 'manifold.json'} and {out / 'manifold.png'}")
    return 0


if __name__ == "__main__":
    os.environ.setdefault("MPLBACKEND", "Agg")
    sys.exit(main())
