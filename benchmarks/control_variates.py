#!/usr/bin/env python
"""relMSE against run time for the control-variate estimators of seed 002 on ``chromatic-cv``.

Every method of the ``chromatic-cv`` toy (``mc``, ``restir``, ``decoupled``,
``icv``, ``stcv``, ``restcv``, and ``restcv`` with α = 1 as the Eq. 9
ablation) renders the same static scene (``--size`` × ``--size`` pixels,
``--frames`` frames, 2 light samples per pixel and frame, light width 0.1)
for a ladder of trial counts. One trial renders all frames of the image; its
estimate is the last frame. For each run the script records

* ``seconds``: :attr:`grisx.theory.toys.Estimate.seconds` — kernel launches
  and the host-side float64 reduction, *not* compilation (the module is loaded
  before the clock starts; the device is synchronized before the clock is
  read); best of ``--repeats`` identical runs, interleaved across methods so
  that all see the same machine load;
* ``relmse``: relMSE of the mean image, mean over pixels and channels of
  (estimate − exact)² / (exact² + ε), ε = 1e-3 (pixel values lie in
  0.003 … 0.43); the reference is the closed-form exact image;
* ``relvar_per_trial``: relative variance of one trial (one rendered frame),
  mean over components of stderr² · N / (exact² + ε), also per channel.

From the largest run of each method it derives the equal-time comparison
against **ReSTIR**: efficiency 1 / (relvar per trial × seconds per trial),
its ratio to ReSTIR's (= ReSTIR's relMSE / the method's relMSE at equal
time), and the relMSE each method reaches within ReSTIR's time for its
largest run. All numbers come from this one run. On CPU, Warp runs each
kernel on one thread, so CPU numbers are single-core numbers.

Usage::

    python benchmarks/control_variates.py                 # CPU, ladder 100 … 3000 trials
    python benchmarks/control_variates.py --quick         # ladder 100, 300
    python benchmarks/control_variates.py --device cuda --max-trials 100000

Writes ``control_variates.json`` and ``control_variates.png`` to ``--out``
(default ``benchmarks/results/``) and prints a table.
"""

from __future__ import annotations

import json
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import warp as wp

import grisx
from grisx.errors import GrisxError
from grisx.theory.toys import run_toy

sys.path.insert(0, str(Path(__file__).resolve().parent))
from toys import cpu_model, ladder, ladder_parser, ladder_setup  # noqa: E402  (benchmarks/toys.py: the shared trial ladder, its options and the CPU-model probe)

PROBLEM = "chromatic-cv"
#: (label, method, params) of every benchmarked estimator
METHODS: tuple[tuple[str, str, dict[str, Any]], ...] = (
    ("mc", "mc", {}),
    ("restir", "restir", {}),
    ("decoupled", "decoupled", {}),
    ("icv", "icv", {}),
    ("stcv", "stcv", {}),
    ("restcv", "restcv", {}),
    ("restcv alpha=one", "restcv", {"alpha": "one"}),
)
BASELINE = "restir"
LADDER = (100, 300, 1000, 3000, 10_000, 30_000, 100_000, 300_000, 1_000_000)
EPSILON = 1e-3



def summarize(label: str, runs: list[Any]) -> dict[str, Any]:
    """One row of the table from ``runs``: identical runs (same seed, so the same estimate), fastest kept."""
    e = runs[0]
    est, ex, se = (np.asarray(a, dtype=np.float64) for a in (e.estimate, e.exact, e.stderr))
    seconds = min(r.seconds for r in runs)
    trials = e.trials
    scale = ex**2 + EPSILON
    relvar = (se**2 * trials / scale).reshape(-1, 3)
    return {
        "method": label,
        "toy_method": e.method,
        "params": dict(e.params),
        "trials": trials,
        "seconds": seconds,
        "seconds_all_repeats": [r.seconds for r in runs],
        "trials_per_second": trials / seconds,
        "relmse": float(np.mean((est - ex) ** 2 / scale)),
        "relmse_predicted": float(np.mean(se**2 / scale)),
        "relvar_per_trial": float(relvar.mean()),
        "relvar_per_trial_rgb": relvar.mean(axis=0).tolist(),
        "max_abs_z": float(np.max(np.abs((est - ex) / np.where(se > 0, se, 1.0)))),
    }


def equal_time(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per method at its largest count: efficiency, its ratio to ReSTIR's, relMSE within ReSTIR's time."""
    largest: dict[str, dict[str, Any]] = {}
    for r in rows:
        if r["method"] not in largest or r["trials"] > largest[r["method"]]["trials"]:
            largest[r["method"]] = r
    base = largest[BASELINE]
    budget = base["seconds"]
    base_eff = 1.0 / (base["relvar_per_trial"] * base["seconds"] / base["trials"])
    out = []
    for label, r in largest.items():
        spt = r["seconds"] / r["trials"]
        eff = 1.0 / (r["relvar_per_trial"] * spt)
        out.append(
            {
                "method": label,
                "trials": r["trials"],
                "seconds_per_trial": spt,
                "relvar_per_trial": r["relvar_per_trial"],
                "relvar_per_trial_rgb": r["relvar_per_trial_rgb"],
                "efficiency": eff,
                "budget_seconds": budget,
                "relmse_at_budget": r["relvar_per_trial"] * spt / budget,
                "efficiency_ratio_to_restir": eff / base_eff,
                "max_abs_z": r["max_abs_z"],
            }
        )
    return out


def print_table(summary: list[dict[str, Any]], device: str) -> None:
    print()
    print(f"Equal-time comparison ({device}; budget = ReSTIR's time for its largest run; relMSE ε = {EPSILON:g})")
    header = f"{'method':18s} {'trials':>8s} {'ms/trial':>9s} {'relvar/trial':>12s} {'R / G / B':>26s} {'relMSE@budget':>13s} {'vs ReSTIR':>10s} {'max|z|':>7s}"
    print(header)
    print("-" * len(header))
    for s in summary:
        rgb = " / ".join(f"{v:.2e}" for v in s["relvar_per_trial_rgb"])
        print(
            f"{s['method']:18s} {s['trials']:>8,d} {1e3 * s['seconds_per_trial']:>9.3f} {s['relvar_per_trial']:>12.3e} {rgb:>26s} "
            f"{s['relmse_at_budget']:>13.3e} {s['efficiency_ratio_to_restir']:>9.2f}x {s['max_abs_z']:>7.2f}"
        )
    restcv = next(s for s in summary if s["method"] == "restcv")
    restir = next(s for s in summary if s["method"] == BASELINE)
    print(
        f"\nequal-time relMSE ratio ReSTIR / ReSTCV = {restcv['efficiency_ratio_to_restir']:.2f}"
        f"  (variance per frame ×{restir['relvar_per_trial'] / restcv['relvar_per_trial']:.2f} lower,"
        f" time per frame ×{restcv['seconds_per_trial'] / restir['seconds_per_trial']:.2f})"
    )


def plot(rows: list[dict[str, Any]], summary: list[dict[str, Any]], path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(13, 5.6), gridspec_kw={"width_ratios": [1.4, 1.0]})
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for color, (label, _m, _p) in zip(colors, METHODS):
        rs = sorted((r for r in rows if r["method"] == label), key=lambda r: r["trials"])
        eff = next(s["efficiency_ratio_to_restir"] for s in summary if s["method"] == label)
        sec = [r["seconds"] for r in rs]
        ax.loglog(sec, [r["relmse_predicted"] for r in rs], "-", color=color, lw=1.6, label=f"{label}  (×{eff:.2f} ReSTIR's efficiency)")
        ax.loglog(sec, [r["relmse"] for r in rs], "o", color=color, ms=5, mfc="none", mew=1.3)
    ax.plot([], [], "k-", lw=1.6, label="line: relMSE predicted from stderr")
    ax.plot([], [], "ko", ms=5, mfc="none", label="circles: measured relMSE of the mean")
    ax.set(xlabel="seconds (kernel + host reduction, no compilation)", ylabel=f"relMSE of the mean image (ε = {EPSILON:g})", title="relMSE against run time")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7.5)
    labels = [s["method"] for s in summary]
    x = np.arange(len(labels))
    for c, colour in enumerate(("tab:red", "tab:green", "tab:blue")):
        bx.bar(x + (c - 1) * 0.27, [s["relvar_per_trial_rgb"][c] for s in summary], width=0.27, color=colour, label="RGB"[c])
    bx.set_yscale("log")
    bx.set_xticks(x, labels, rotation=30, ha="right", fontsize=8)
    bx.set(ylabel="relative variance of one frame", title="per-channel variance (largest run)")
    bx.legend(title="channel", fontsize=8)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = ladder_parser(__doc__.split("\n\n")[0], default_trials=3000, quick_trials=300, quick_help="small ladder (100, 300 trials) for a smoke test")
    parser.add_argument("--size", type=int, default=16, help="image width = height (default 16)")
    parser.add_argument("--frames", type=int, default=8, help="static frames per trial (default 8)")
    args, device, out, max_trials = ladder_setup(parser, argv, min_trials=100)
    scene = {"size": args.size, "frames": args.frames}
    counts = ladder(max_trials, LADDER)
    print(f"device {device} ({cpu_model() if device.is_cpu else device.name}), warp {wp.config.version}, numpy {np.__version__}, seed {args.seed}")
    print(f"{PROBLEM} {scene}, trial ladder {counts}, best of {args.repeats}")

    # repeats are interleaved across methods, so that every method sees the same machine load
    runs: dict[tuple[str, int], list[Any]] = {(label, n): [] for label, _m, _p in METHODS for n in counts}
    try:
        for n in counts:
            for _ in range(args.repeats):
                for label, method, params in METHODS:
                    runs[(label, n)].append(run_toy(PROBLEM, method, trials=n, seed=args.seed, params={**scene, **params}, device=args.device))
            for label, _m, _p in METHODS:
                r = summarize(label, runs[(label, n)])
                print(f"  {label:18s} N = {n:>8,d}  {r['seconds']:8.3f} s  relMSE {r['relmse']:.3e} (pred. {r['relmse_predicted']:.3e})  max|z| {r['max_abs_z']:.2f}", flush=True)
    except GrisxError as exc:
        print(f"control_variates.py: error: {exc}", file=sys.stderr)
        return 2
    rows = [summarize(label, runs[(label, n)]) for label, _m, _p in METHODS for n in counts]
    summary = equal_time(rows)
    print_table(summary, str(device))

    restcv = next(s for s in summary if s["method"] == "restcv")
    result = {
        "benchmark": "control_variates",
        "device": str(device),
        "device_name": cpu_model() if device.is_cpu else device.name,
        "cpu_model": cpu_model(),
        "cpu_threads_used_by_warp_kernels": 1 if device.is_cpu else None,
        "versions": {"grisx": getattr(grisx, "__version__", None), "warp": wp.config.version, "numpy": np.__version__, "python": platform.python_version()},
        "platform": platform.platform(),
        "seed": args.seed,
        "settings": {
            "problem": PROBLEM,
            "scene": scene,
            "trial_ladder": counts,
            "repeats": args.repeats,
            "quick": args.quick,
            "relmse_epsilon": EPSILON,
            "reference": "closed-form exact image (chromatic_exact)",
            "methods": [{"label": lab, "method": m, "params": p} for lab, m, p in METHODS],
            "baseline": BASELINE,
        },
        "rows": rows,
        "equal_time": summary,
        "equal_time_relmse_ratio_restir_over_restcv": restcv["efficiency_ratio_to_restir"],
        "variance_ratio_restir_over_restcv": next(s["relvar_per_trial"] for s in summary if s["method"] == BASELINE) / restcv["relvar_per_trial"],
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    }
    (out / "control_variates.json").write_text(json.dumps(result, indent=1))
    title = f"grisx control-variates benchmark — {PROBLEM} {args.size}×{args.size}, {args.frames} frames — {result['device_name']} ({device}), warp {wp.config.version}, seed {args.seed}, best of {args.repeats}; Warp CPU kernels run on one thread"
    plot(rows, summary, out / "control_variates.png", title)
    print(f"\nwrote {out / 'control_variates.json'} and {out / 'control_variates.png'}")
    return 0


if __name__ == "__main__":
    os.environ.setdefault("MPLBACKEND", "Agg")
    sys.exit(main())
