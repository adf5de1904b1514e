#!/usr/bin/env python
"""Run time against error for the toy estimators, and what the estimator core costs.

For each method on ``ris-1d`` (mc, RIS with target = integrand / approx, all
with M = 8) and ``gris-shift`` (plain per-pixel RIS = ``passes=0``, and one
spatial GRIS pass with MIS = balance / pairwise / uniform) this script runs a
ladder of trial counts and records

* ``seconds``: :attr:`grisx.theory.toys.Estimate.seconds` — kernel launches
  plus the host-side float64 reduction, *excluding* kernel compilation (the
  module is loaded before the clock starts); best of ``--repeats`` identical
  runs (same seed, so the same estimate);
* ``rmse``: the error of the *mean*, √(mean over pixels of (estimate − exact)²);
* ``rmse_predicted``: √(mean over pixels of stderr²), what the run's own
  standard error predicts for that error.

From the largest count of each method it derives the throughput (trials/s),
the variance of one trial (mean over pixels of stderr²·N) and the efficiency
1 / (variance per trial × seconds per trial). The equal-time comparison gives,
for every method, the RMSE reachable in the time budget the baseline
(``mc`` / ``passes=0``) took for its largest run, and the efficiency ratio to
that baseline — all measured in this one run.

**Anchor.** A minimal hand-written Warp RIS kernel for the same ``ris-1d``
integrand (inline weighted reservoir over M = 8 candidates with plain
``wp.rand_init``/``wp.randf``, writing f(y)·W per trial) is timed the same way
(module loaded first, a warm-up launch, ``wp.synchronize`` before reading the
clock, best of 3) next to a bare launch of the core-based
``grisx.theory.toys.ris_1d.ris1d_kernel`` with the arguments
``RIS1D.launch`` uses. On CPU, Warp runs a kernel on one thread, so both are
single-core numbers.

Usage::

    python benchmarks/toys.py                     # CPU, up to 1e6 trials
    python benchmarks/toys.py --quick             # up to 1e5 trials
    python benchmarks/toys.py --device cuda --max-trials 10000000

Writes ``toys.json`` and ``toys.png`` to ``--out`` (default
``benchmarks/results/``) and prints a table.
"""

from __future__ import annotations

import argparse
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
from grisx.device import resolve_device, synchronize
from grisx.errors import GrisxError
from grisx.theory.random import random_key, random_uniform
from grisx.theory.toys import get_problem, run_toy
from grisx.theory.toys.ris_1d import TARGETS, ris1d_kernel

#: (problem, label, method, params) of every benchmarked estimator; the first of a problem is its baseline
METHODS: tuple[tuple[str, str, str, dict[str, Any]], ...] = (
    ("ris-1d", "mc", "mc", {"candidates": 8}),
    ("ris-1d", "ris target=integrand", "ris", {"candidates": 8, "target": "integrand"}),
    ("ris-1d", "ris target=approx", "ris", {"candidates": 8, "target": "approx"}),
    ("gris-shift", "passes=0", "gris", {"passes": 0}),
    ("gris-shift", "passes=1 mis=balance", "gris", {"passes": 1, "mis": "balance"}),
    ("gris-shift", "passes=1 mis=pairwise", "gris", {"passes": 1, "mis": "pairwise"}),
    ("gris-shift", "passes=1 mis=uniform", "gris", {"passes": 1, "mis": "uniform"}),
)
BASELINES = {"ris-1d": "mc", "gris-shift": "passes=0"}
LADDER = (10_000, 30_000, 100_000, 300_000, 1_000_000, 3_000_000, 10_000_000, 30_000_000, 100_000_000)
ANCHOR_CANDIDATES = 8


# ---- the anchor: a minimal hand-written RIS kernel, no grisx core -----------------
@wp.func
def _handwritten_f(x: float) -> float:
    a = (x - 0.3) / 0.06
    b = (x - 0.72) / 0.1
    return 0.2 + wp.exp(-a * a) + 0.5 * wp.exp(-b * b)


@wp.kernel
def handwritten_ris_kernel(seed: int, candidates: int, values: wp.array(dtype=float)):
    t = wp.tid()
    state = wp.rand_init(seed, t)
    inv_m = 1.0 / float(candidates)
    w_sum = float(0.0)
    y = float(0.0)
    target_y = float(0.0)
    for _i in range(candidates):
        x = wp.randf(state)  # uniform candidate, p(x) = 1
        target = _handwritten_f(x)  # p̂ = f
        w = inv_m * target  # w = p̂ / (M p)
        w_sum += w
        if wp.randf(state) * w_sum < w:
            y = x
            target_y = target
    value = float(0.0)
    if target_y > 0.0:
        value = _handwritten_f(y) * (w_sum / target_y)  # f(y) · W_y
    values[t] = value


@wp.kernel
def handwritten_ris_counter_rng_kernel(seed: int, candidates: int, values: wp.array(dtype=float)):
    # the same hand-written kernel, but drawing its numbers from grisx's counter-based
    # hash (random_key / random_uniform, as the core kernel does): isolates the RNG's cost
    t = wp.tid()
    key = random_key(seed, t)
    inv_m = 1.0 / float(candidates)
    w_sum = float(0.0)
    y = float(0.0)
    target_y = float(0.0)
    for i in range(candidates):
        x = random_uniform(key, 2 * i)
        target = _handwritten_f(x)
        w = inv_m * target
        w_sum += w
        if random_uniform(key, 2 * i + 1) * w_sum < w:
            y = x
            target_y = target
    value = float(0.0)
    if target_y > 0.0:
        value = _handwritten_f(y) * (w_sum / target_y)
    values[t] = value


def time_launch(kernel: Any, dim: int, inputs: list[Any], device: Any, repeats: int = 3) -> float:
    """Best-of-``repeats`` seconds of one launch (module loaded and warmed up first)."""
    wp.load_module(kernel.module, device=device)
    wp.launch(kernel, dim=dim, inputs=inputs, device=device)
    synchronize(device)
    best = math.inf
    for _ in range(repeats):
        synchronize(device)
        start = time.perf_counter()
        wp.launch(kernel, dim=dim, inputs=inputs, device=device)
        synchronize(device)
        best = min(best, time.perf_counter() - start)
    return best


def anchor(device: Any, trials: int, seed: int, repeats: int) -> dict[str, Any]:
    """Hand-written RIS kernel vs the core-based ris-1d kernel vs end-to-end run_toy."""
    exact = float(get_problem("ris-1d").exact({})[0])
    flat = wp.zeros(trials, dtype=float, device=device)
    t_hand = time_launch(handwritten_ris_kernel, trials, [seed, ANCHOR_CANDIDATES, flat], device, repeats)
    v = flat.numpy().astype(np.float64)
    hand_mean, hand_se = float(v.mean()), float(v.std(ddof=1) / math.sqrt(trials))

    t_hand_counter = time_launch(handwritten_ris_counter_rng_kernel, trials, [seed, ANCHOR_CANDIDATES, flat], device, repeats)
    v = flat.numpy().astype(np.float64)
    counter_mean, counter_se = float(v.mean()), float(v.std(ddof=1) / math.sqrt(trials))

    values = wp.zeros((trials, 1), dtype=float, device=device)
    # the arguments RIS1D.launch passes: use_ris, target kind, M, seed, first trial, values, samples, keep_samples
    core_inputs = [1, TARGETS.index("integrand"), ANCHOR_CANDIDATES, seed, 0, values, values, 0]
    t_core = time_launch(ris1d_kernel, trials, core_inputs, device, repeats)
    v = values.numpy()[:, 0].astype(np.float64)
    core_mean, core_se = float(v.mean()), float(v.std(ddof=1) / math.sqrt(trials))

    params = {"candidates": ANCHOR_CANDIDATES, "target": "integrand"}
    runs = [run_toy("ris-1d", "ris", trials=trials, seed=seed, params=params, device=str(device)) for _ in range(repeats)]
    t_e2e = min(e.seconds for e in runs)

    def entry(seconds: float, mean: float | None = None, se: float | None = None) -> dict[str, Any]:
        out: dict[str, Any] = {"seconds": seconds, "trials_per_second": trials / seconds}
        if mean is not None:
            out.update(estimate=mean, stderr=se, z=(mean - exact) / se if se else None)
        return out

    return {
        "trials": trials,
        "candidates": ANCHOR_CANDIDATES,
        "repeats": repeats,
        "exact": exact,
        "handwritten_kernel": entry(t_hand, hand_mean, hand_se),
        "handwritten_kernel_counter_rng": entry(t_hand_counter, counter_mean, counter_se),
        "core_kernel": entry(t_core, core_mean, core_se),
        "run_toy_end_to_end": entry(t_e2e, float(runs[0].estimate), float(runs[0].stderr)),
        "core_kernel_vs_handwritten": t_hand / t_core,
        "claimed_handwritten_trials_per_second": 4.8e6,
    }


# ---- run time against error ---------------------------------------------------
def ladder(max_trials: int, steps: tuple[int, ...] = LADDER) -> list[int]:
    """The trial counts of ``steps`` up to ``max_trials``, ending at ``max_trials`` (shared by the toy benchmarks)."""
    counts = [n for n in steps if n <= max_trials]
    if not counts or counts[-1] != max_trials:
        counts.append(max_trials)
    return counts


def ladder_parser(description: str, *, default_trials: int, quick_trials: int, repeats: int = 3, quick_help: str = "small ladder for a smoke test") -> argparse.ArgumentParser:
    """The options every trial-ladder benchmark shares: --out, --device, --max-trials, --quick, --repeats, --seed."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"), help="output directory (default benchmarks/results/)")
    parser.add_argument("--device", default="cpu", help="cpu, cuda or cuda:N (default cpu)")
    parser.add_argument(
        "--max-trials", type=float, default=None, help=f"largest trial count of the ladder (default {default_trials:g}; {quick_trials:g} with --quick)"
    )
    parser.add_argument("--quick", action="store_true", help=quick_help)
    parser.add_argument("--repeats", type=int, default=repeats, help=f"runs per point; the fastest is kept (default {repeats})")
    parser.add_argument("--seed", type=int, default=0)
    parser.set_defaults(trials=(default_trials, quick_trials))
    return parser


def ladder_setup(parser: argparse.ArgumentParser, argv: list[str] | None, *, min_trials: int) -> tuple[argparse.Namespace, Any, Path, int]:
    """Parse ``argv``; check the ladder's size, resolve the device, create --out. Bad input: one line, exit 2."""
    args = parser.parse_args(argv)
    default_trials, quick_trials = args.trials
    max_trials = int(args.max_trials) if args.max_trials is not None else (quick_trials if args.quick else default_trials)
    if max_trials < min_trials or args.repeats < 1:
        parser.exit(2, f"{parser.prog}: error: --max-trials must be >= {min_trials} and --repeats >= 1\n")
    try:
        device = resolve_device(args.device)
    except GrisxError as exc:
        parser.exit(2, f"{parser.prog}: error: {exc}\n")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    return args, device, out, max_trials


def run_method(problem: str, label: str, method: str, params: dict[str, Any], trials: int, seed: int, device: str, repeats: int) -> dict[str, Any]:
    runs = [run_toy(problem, method, trials=trials, seed=seed, params=params, device=device) for _ in range(repeats)]
    e = runs[0]
    est, ex, se = (np.atleast_1d(np.asarray(a, dtype=np.float64)) for a in (e.estimate, e.exact, e.stderr))
    seconds = min(r.seconds for r in runs)
    return {
        "problem": problem,
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
        "estimate": est.tolist(),
        "stderr": se.tolist(),
        "exact": ex.tolist(),
    }


def equal_time(rows: list[dict[str, Any]], baselines: dict[str, str] = BASELINES) -> list[dict[str, Any]]:
    """Per method at its largest count: throughput, efficiency, RMSE within the baseline's time."""
    largest: dict[tuple[str, str], dict[str, Any]] = {}
    for r in rows:
        key = (r["problem"], r["method"])
        if key not in largest or r["trials"] > largest[key]["trials"]:
            largest[key] = r
    out = []
    for problem, base_label in baselines.items():
        base = largest[(problem, base_label)]
        budget = base["seconds"]
        base_eff = 1.0 / (base["variance_per_trial"] * base["seconds"] / base["trials"])
        for (p, label), r in largest.items():
            if p != problem:
                continue
            spt = r["seconds"] / r["trials"]
            eff = 1.0 / (r["variance_per_trial"] * spt)
            out.append(
                {
                    "problem": problem,
                    "method": label,
                    "baseline": base_label,
                    "trials": r["trials"],
                    "trials_per_second": r["trials_per_second"],
                    "seconds_per_trial": spt,
                    "variance_per_trial": r["variance_per_trial"],
                    "efficiency": eff,
                    "budget_seconds": budget,
                    "rmse_at_budget": math.sqrt(r["variance_per_trial"] * spt / budget),
                    "efficiency_ratio": eff / base_eff,
                    "max_abs_z": r["max_abs_z"],
                }
            )
    return out


# ---- reporting ----------------------------------------------------------------
def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def print_table(summary: list[dict[str, Any]], anchor_result: dict[str, Any], device: str) -> None:
    print()
    print(f"Equal-time comparison ({device}; budget = the baseline's time for its largest run)")
    header = f"{'problem':11s} {'method':22s} {'trials':>9s} {'trials/s':>10s} {'var/trial':>10s} {'budget s':>8s} {'RMSE@budget':>11s} {'eff. ratio':>10s} {'max|z|':>7s}"
    print(header)
    print("-" * len(header))
    for s in summary:
        print(
            f"{s['problem']:11s} {s['method']:22s} {s['trials']:>9,d} {s['trials_per_second']:>10.3g} {s['variance_per_trial']:>10.3g} "
            f"{s['budget_seconds']:>8.3f} {s['rmse_at_budget']:>11.3e} {s['efficiency_ratio']:>10.3f} {s['max_abs_z']:>7.2f}"
        )
    a = anchor_result
    print()
    print(f"Anchor: ris-1d RIS, M = {a['candidates']}, {a['trials']:,} trials, best of {a['repeats']} ({device}, one thread on CPU)")
    for name, key in (
        ("hand-written Warp kernel", "handwritten_kernel"),
        ("hand-written, grisx counter RNG", "handwritten_kernel_counter_rng"),
        ("core ris1d_kernel (launch only)", "core_kernel"),
        ("run_toy end to end", "run_toy_end_to_end"),
    ):
        e = a[key]
        z = f"   z = {e['z']:+.2f}" if e.get("z") is not None else ""
        print(f"  {name:33s} {e['trials_per_second'] / 1e6:8.2f} M trials/s   ({e['seconds'] * 1e3:8.2f} ms){z}")
    print(f"  core kernel / hand-written throughput: {1.0 / a['core_kernel_vs_handwritten']:.2f}x the time, i.e. {a['core_kernel_vs_handwritten']:.2f} of the speed")
    print(f"  (claim to check: the hand-written kernel runs ≈ {a['claimed_handwritten_trials_per_second'] / 1e6:.1f} M trials/s on one core)")


def plot(rows: list[dict[str, Any]], summary: list[dict[str, Any]], anchor_result: dict[str, Any], path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    problems = list(BASELINES)
    fig, axes = plt.subplots(1, len(problems) + 1, figsize=(6.0 * len(problems) + 5.0, 6.3), gridspec_kw={"width_ratios": [1.2] * len(problems) + [1.0]})
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, problem in zip(axes, problems):
        labels = [label for p, label, _m, _pa in METHODS if p == problem]
        for color, label in zip(colors, labels):
            rs = sorted((r for r in rows if r["problem"] == problem and r["method"] == label), key=lambda r: r["trials"])
            sec = [r["seconds"] for r in rs]
            eff = next(s["efficiency_ratio"] for s in summary if s["problem"] == problem and s["method"] == label)
            ax.loglog(sec, [r["rmse_predicted"] for r in rs], "-", color=color, lw=1.6, label=f"{label}  (efficiency ×{eff:.2f})")
            ax.loglog(sec, [r["rmse"] for r in rs], "o", color=color, ms=5, mfc="none", mew=1.3)
        ax.plot([], [], "k-", lw=1.6, label="line: RMSE predicted from stderr")
        ax.plot([], [], "ko", ms=5, mfc="none", label="circles: measured |estimate − exact| (RMS over pixels)")
        ax.set(xlabel="seconds (kernel + host reduction, no compilation)", ylabel="RMSE of the mean", title=f"{problem}: error against run time")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7.5, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=1)
    ax = axes[-1]
    a = anchor_result
    names = ["hand-written\n(wp.randf)", "hand-written\n(grisx RNG)", "core\nris1d_kernel", "run_toy\nend to end"]
    tps = [a[k]["trials_per_second"] / 1e6 for k in ("handwritten_kernel", "handwritten_kernel_counter_rng", "core_kernel", "run_toy_end_to_end")]
    bars = ax.bar(names, tps, color=["0.55", "0.75", "tab:blue", "tab:cyan"])
    for b, v in zip(bars, tps):
        ax.annotate(f"{v:.2f}", (b.get_x() + b.get_width() / 2, v), xytext=(0, 3), textcoords="offset points", ha="center", fontsize=9)
    ax.axhline(a["claimed_handwritten_trials_per_second"] / 1e6, color="tab:red", ls=":", lw=1.2, label="claimed 4.8 M/s (hand-written)")
    ax.set(ylabel="million trials / s", title=f"Anchor: ris-1d RIS kernels, M = {a['candidates']}\n{a['trials']:,} trials, best of {a['repeats']}")
    ax.tick_params(axis="x", labelsize=8)
    ax.set_ylim(0, max(tps + [a["claimed_handwritten_trials_per_second"] / 1e6]) * 1.18)
    ax.legend(fontsize=8, loc="upper right")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = ladder_parser(__doc__.split("\n\n")[0], default_trials=1_000_000, quick_trials=100_000)
    args, device, out, max_trials = ladder_setup(parser, argv, min_trials=1000)
    counts = ladder(max_trials)
    print(f"device {device} ({cpu_model() if device.is_cpu else device.name}), warp {wp.config.version}, numpy {np.__version__}, seed {args.seed}")
    print(f"trial ladder {counts}, best of {args.repeats}")

    rows = []
    for problem, label, method, params in METHODS:
        for n in counts:
            r = run_method(problem, label, method, params, n, args.seed, args.device, args.repeats)
            rows.append(r)
            print(f"  {problem:11s} {label:22s} N = {n:>10,d}  {r['seconds']:8.3f} s  {r['trials_per_second']:10.3g} trials/s  RMSE {r['rmse']:.3e} (pred. {r['rmse_predicted']:.3e})  max|z| {r['max_abs_z']:.2f}", flush=True)
    summary = equal_time(rows)
    anchor_result = anchor(device, max_trials, args.seed, args.repeats)
    print_table(summary, anchor_result, str(device))

    result = {
        "benchmark": "toys",
        "device": str(device),
        "device_name": cpu_model() if device.is_cpu else device.name,
        "cpu_model": cpu_model(),
        "cpu_threads_used_by_warp_kernels": 1 if device.is_cpu else None,
        "versions": {"grisx": getattr(grisx, "__version__", None), "warp": wp.config.version, "numpy": np.__version__, "python": platform.python_version()},
        "platform": platform.platform(),
        "seed": args.seed,
        "settings": {"trial_ladder": counts, "max_trials": max_trials, "repeats": args.repeats, "quick": args.quick, "methods": [{"problem": p, "label": lab, "method": m, "params": pa} for p, lab, m, pa in METHODS], "baselines": BASELINES},
        "rows": rows,
        "equal_time": summary,
        "anchor": anchor_result,
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    }
    (out / "toys.json").write_text(json.dumps(result, indent=1))
    title = f"grisx toys benchmark — {result['device_name']} ({device}), warp {wp.config.version}, seed {args.seed}, best of {args.repeats}; Warp CPU kernels run on one thread"
    plot(rows, summary, anchor_result, out / "toys.png", title)
    print(f"\nwrote {out / 'toys.json'} and {out / 'toys.png'}")
    return 0


if __name__ == "__main__":
    os.environ.setdefault("MPLBACKEND", "Agg")
    sys.exit(main())
