#!/usr/bin/env python
"""Run time against error for conditional RIS and the final gather (seed 001), with the work each uses.

Variants (all on the ``final-gather`` toy unless named otherwise; see
:mod:`grisx.theory.toys.conditional_paths`):

* ``mmis K=1`` / ``mmis K=3`` — the marginal-MIS baseline: 4 integration
  prefixes, 1 or 3 independent suffixes each (seed 001, Fig. 3 a/c);
* ``gather N=4 k=1`` — ReSTIR suffixes, roulette (Fig. 3 e);
* ``gather N=4 k=3``;
* ``gather N=5 roulette`` / ``gather N=5 all canonical`` — the roulette
  ablation at N = 5, where roulette saves 80% of canonical suffixes (Fig. 4);
* ``gather N=16 roulette`` — more integration prefixes;
* ``joint-ucw independent`` — the two-RIS joint UCW (Thm. 4.1), for scale;
* biased references, run once at the largest count: ``gather canonical=false``
  and ``joint-ucw dependent``.

For every variant a ladder of trial counts is run and each point records
``seconds`` (:attr:`Estimate.seconds`: kernel launches + host reduction, the
device synchronized before the clock is read, compilation excluded; best of
``--repeats``), ``rmse`` (|estimate − exact| of the mean), ``rmse_predicted``
(the run's stderr) and the work counters of :meth:`Estimate.stats` per trial:
canonical suffixes traced, borrowed suffixes, shift evaluations, and the
ray-equivalents ``gather_rays`` (N prefixes + 4 rays per canonical suffix +
1 per shift) and ``support_rays`` (building the supporting reservoirs,
amortized over pixels and frames in a renderer). The equal-time table gives
each variant's efficiency 1/(variance per trial × seconds per trial) relative
to ``mmis K=1`` measured in the same run, and its RMSE at the baseline's
time budget.

Usage::

    python benchmarks/conditional.py                 # CPU, ladder up to 3e5 trials
    python benchmarks/conditional.py --quick         # up to 3e4 trials
    python benchmarks/conditional.py --device cuda --max-trials 1e7

Writes ``conditional.json`` and ``conditional.png`` to ``--out`` (default
``benchmarks/results/``) and prints a table.
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

#: (label, problem, method, params) of every benchmarked variant; the first is the baseline
VARIANTS: tuple[tuple[str, str, str, dict[str, Any]], ...] = (
    ("mmis K=1", "final-gather", "mmis", {"prefixes": 4, "suffixes": 1}),
    ("mmis K=3", "final-gather", "mmis", {"prefixes": 4, "suffixes": 3}),
    ("gather N=4 k=1", "final-gather", "gather", {"prefixes": 4, "k": 1}),
    ("gather N=4 k=3", "final-gather", "gather", {"prefixes": 4, "k": 3}),
    ("gather N=5 roulette", "final-gather", "gather", {"prefixes": 5, "roulette": True}),
    ("gather N=5 all canonical", "final-gather", "gather", {"prefixes": 5, "roulette": False}),
    ("gather N=16 roulette", "final-gather", "gather", {"prefixes": 16}),
    ("joint-ucw independent", "joint-ucw", "independent", {}),
)
BIASED: tuple[tuple[str, str, str, dict[str, Any]], ...] = (
    ("gather canonical=false (biased)", "final-gather", "gather", {"prefixes": 4, "canonical": False}),
    ("joint-ucw dependent (biased)", "joint-ucw", "dependent", {}),
)
BASELINE = "mmis K=1"
LADDER = (10_000, 30_000, 100_000, 300_000, 1_000_000, 3_000_000, 10_000_000)
WORK_KEYS = ("canonical_suffixes", "borrowed_suffixes", "shifts", "gather_rays", "support_rays", "rays")


def run_variant(label: str, problem: str, method: str, params: dict[str, Any], trials: int, seed: int, device: str, repeats: int) -> dict[str, Any]:
    runs = [run_toy(problem, method, trials=trials, seed=seed, params=params, device=device) for _ in range(repeats)]
    best = min(runs, key=lambda e: e.seconds)
    exact = float(best.exact)
    return {
        "label": label,
        "problem": problem,
        "method": method,
        "params": best.params,
        "trials": trials,
        "seconds": best.seconds,
        "seconds_all_repeats": [e.seconds for e in runs],
        "trials_per_second": trials / best.seconds if best.seconds > 0 else None,
        "estimate": float(best.estimate),
        "stderr": float(best.stderr),
        "exact": exact,
        "rmse": abs(float(best.estimate) - exact),
        "rmse_predicted": float(best.stderr),
        "relative_rmse_per_trial": best.rmse / exact,
        "variance_per_trial": float(best.stderr) ** 2 * trials,
        "z": float(best.z),
        "work_per_trial": {k: v for k, v in (best.stats or {}).items()},
    }


def equal_time(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    largest = {}
    for r in rows:
        if r["label"] not in largest or r["trials"] > largest[r["label"]]["trials"]:
            largest[r["label"]] = r
    base = largest[BASELINE]
    budget = base["seconds"]
    base_eff = 1.0 / (base["variance_per_trial"] * base["seconds"] / base["trials"])
    out = []
    for label, r in largest.items():
        seconds_per_trial = r["seconds"] / r["trials"]
        eff = 1.0 / (r["variance_per_trial"] * seconds_per_trial)
        work = r["work_per_trial"]
        out.append(
            {
                "label": label,
                "trials": r["trials"],
                "seconds": r["seconds"],
                "trials_per_second": r["trials_per_second"],
                "variance_per_trial": r["variance_per_trial"],
                "budget_seconds": budget,
                "rmse_at_budget": math.sqrt(r["variance_per_trial"] * seconds_per_trial / budget),
                "efficiency_ratio": eff / base_eff if r["problem"] == base["problem"] else None,
                "z": r["z"],
                **{k: work.get(k) for k in WORK_KEYS},
            }
        )
    return out


def fmt(v: Any, spec: str) -> str:
    return "—" if v is None else format(v, spec)


def print_table(summary: list[dict[str, Any]], biased: list[dict[str, Any]], device: str) -> None:
    print()
    print(f"Equal-time comparison ({device}; budget = {BASELINE}'s time for its largest run; efficiency relative to {BASELINE})")
    print(f"{'variant':26s} {'trials':>9s} {'trials/s':>10s} {'var/trial':>10s} {'RMSE@budget':>11s} {'eff. ratio':>10s} {'z':>6s} "
          f"{'canon.':>6s} {'borrow':>6s} {'shifts':>7s} {'gath.rays':>9s} {'supp.rays':>9s}")
    for s in summary:
        print(f"{s['label']:26s} {s['trials']:9,d} {s['trials_per_second']:10.3g} {s['variance_per_trial']:10.4f} {s['rmse_at_budget']:11.3e} "
              f"{fmt(s['efficiency_ratio'], '10.2f'):>10s} {s['z']:6.2f} {fmt(s['canonical_suffixes'], '6.2f'):>6s} {fmt(s['borrowed_suffixes'], '6.2f'):>6s} "
              f"{fmt(s['shifts'], '7.1f'):>7s} {fmt(s['gather_rays'], '9.1f'):>9s} {fmt(s['support_rays'], '9.1f'):>9s}")
    print("\nBiased references (largest count):")
    for b in biased:
        print(f"  {b['label']:32s} estimate {b['estimate']:.5f} ± {b['stderr']:.5f}  exact {b['exact']:.5f}  z = {b['z']:.1f}")
    by = {s["label"]: s for s in summary}
    a, b = by.get("gather N=5 roulette"), by.get("gather N=5 all canonical")
    if a and b:
        print(f"\nroulette at N = 5: canonical suffixes {a['canonical_suffixes']:.2f} vs {b['canonical_suffixes']:.2f} per trial "
              f"({100 * (1 - a['canonical_suffixes'] / b['canonical_suffixes']):.0f}% saved), gather rays {a['gather_rays']:.1f} vs {b['gather_rays']:.1f}, "
              f"variance per trial {a['variance_per_trial']:.4f} vs {b['variance_per_trial']:.4f}")


def plot(rows: list[dict[str, Any]], summary: list[dict[str, Any]], path: Path, title: str) -> None:
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(14, 5.2))
    ax = axes[0]
    labels = [s["label"] for s in summary if s["label"] != "joint-ucw independent"]
    for label in labels:
        pts = sorted((r["seconds"], r["rmse"], r["rmse_predicted"]) for r in rows if r["label"] == label)
        sec = np.array([p[0] for p in pts])
        line = ax.loglog(sec, [p[2] for p in pts], "o-", label=label)[0]
        ax.loglog(sec, [max(p[1], 1e-12) for p in pts], "x", color=line.get_color(), alpha=0.6)
    ax.set(xlabel="seconds", ylabel="RMSE of the mean (line: stderr; x: |estimate − exact|)", title="final gather: RMSE against seconds")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    ax = axes[1]
    gather = [s for s in summary if s["label"] in labels]
    x = np.arange(len(gather))
    ax.bar(x - 0.2, [s["gather_rays"] for s in gather], 0.4, label="gather rays / trial")
    ax.bar(x + 0.2, [4 * s["canonical_suffixes"] for s in gather], 0.4, label="of which canonical suffixes (4 rays each)")
    ax.set_xticks(x, [s["label"] for s in gather], rotation=30, ha="right", fontsize=8)
    ax.set(ylabel="ray equivalents per trial", title="work of the gather (supporting reservoirs excluded)")
    ax.legend(fontsize=8)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = ladder_parser(__doc__.split("\n\n")[0], default_trials=300_000, quick_trials=30_000)
    args, device, out, max_trials = ladder_setup(parser, argv, min_trials=1)
    counts = ladder(max_trials, LADDER)
    print(f"device {device} ({cpu_model() if device.is_cpu else device.name}), warp {wp.config.version}, numpy {np.__version__}, seed {args.seed}")
    print(f"trial ladder {counts}, best of {args.repeats}")

    rows = []
    for label, problem, method, params in VARIANTS:
        for n in counts:
            r = run_variant(label, problem, method, params, n, args.seed, args.device, args.repeats)
            rows.append(r)
            print(f"  {label:26s} N = {n:>9,d}  {r['seconds']:8.3f} s  RMSE {r['rmse']:.3e} (pred. {r['rmse_predicted']:.3e})  z {r['z']:+.2f}", flush=True)
    biased = [run_variant(label, problem, method, params, counts[-1], args.seed, args.device, 1) for label, problem, method, params in BIASED]
    summary = equal_time(rows)
    print_table(summary, biased, str(device))

    result = {
        "benchmark": "conditional",
        "device": str(device),
        "device_name": cpu_model() if device.is_cpu else device.name,
        "cpu_model": cpu_model(),
        "cpu_threads_used_by_warp_kernels": 1 if device.is_cpu else None,
        "versions": {"grisx": getattr(grisx, "__version__", None), "warp": wp.config.version, "numpy": np.__version__, "python": platform.python_version()},
        "platform": platform.platform(),
        "seed": args.seed,
        "settings": {
            "trial_ladder": counts,
            "max_trials": max_trials,
            "repeats": args.repeats,
            "quick": args.quick,
            "variants": [{"label": lab, "problem": p, "method": m, "params": pa} for lab, p, m, pa in VARIANTS],
            "biased": [{"label": lab, "problem": p, "method": m, "params": pa} for lab, p, m, pa in BIASED],
            "baseline": BASELINE,
            "suffix_rays": 4,
        },
        "rows": rows,
        "equal_time": summary,
        "biased": biased,
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    }
    (out / "conditional.json").write_text(json.dumps(result, indent=1))
    title = f"grisx conditional-RIS benchmark — {result['device_name']} ({device}), warp {wp.config.version}, seed {args.seed}, best of {args.repeats}"
    plot(rows, summary, out / "conditional.png", title)
    print(f"\nwrote {out / 'conditional.json'} and {out / 'conditional.png'}")
    return 0


if __name__ == "__main__":
    os.environ.setdefault("MPLBACKEND", "Agg")
    sys.exit(main())
