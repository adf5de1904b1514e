"""``grisx demo``: every toy problem, every method, estimates beside exact values, one figure.

Until the scene layer lands this is the main job a newcomer runs: it shows
that the estimator core is unbiased where theory says so (|z| small) and that
the known-biased variants are caught (|z| large), and draws where RIS puts
its samples.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from grisx.cli import format_estimate
from grisx.testing import BIASED_K, DEFAULT_K, z_test
from grisx.theory.toys import PROBLEMS, run_toy

__all__ = ["run_demo", "DEMO_RUNS"]

#: (problem, method, params) of every run the demo makes
DEMO_RUNS: tuple[tuple[str, str, dict[str, Any]], ...] = (
    ("ris-1d", "mc", {}),
    ("ris-1d", "ris", {}),
    ("ris-1d", "ris", {"target": "approx"}),
    ("ris-1d", "ris", {"target": "narrow"}),
    ("gris-shift", "gris", {"passes": 0}),
    ("gris-shift", "gris", {"mis": "balance"}),
    ("gris-shift", "gris", {"mis": "pairwise"}),
    ("gris-shift", "gris", {"mis": "uniform"}),
    ("gris-shift", "gris", {"mis": "naive"}),
    ("gris-shift", "gris", {"jacobian": False}),
    ("reconnection-flatland", "gris", {"passes": 0}),
    ("reconnection-flatland", "gris", {"mis": "uniform"}),
    ("reconnection-flatland", "gris", {"mis": "balance"}),
    ("reconnection-flatland", "gris", {"mis": "naive"}),
    ("reconnection-flatland", "gris", {"jacobian": False}),
)


def run_demo(out: str | os.PathLike = "grisx-demo.png", trials: int = 200_000, seed: int = 0, device: str = "cpu") -> dict[str, Any]:
    """Run :data:`DEMO_RUNS`, print each result, write the figure and a JSON summary beside it."""
    out = Path(out)
    if out.suffix.lower() != ".png":
        from grisx.errors import InvalidParameterError

        raise InvalidParameterError(f"--out must name a .png file, got '{out}'")
    results = []
    for name, method, params in DEMO_RUNS:
        est = run_toy(name, method, trials=trials, seed=seed, params=params, device=device)
        biased = PROBLEMS[name].is_biased(method, est.params)
        check = z_test(est.estimate, est.stderr, est.exact, k=DEFAULT_K)
        verdict = ("caught: biased by design" if check.max_abs_z > BIASED_K else "NOT caught") if biased else ("unbiased: ok" if check.passed else "UNEXPECTED: fails the z-test")
        label = " ".join(f"{k}={v}" for k, v in params.items()) or "defaults"
        print(f"{format_estimate(est)}\n  params: {label} -> {verdict}\n")
        results.append({"label": f"{name} {method} {label}", "biased": biased, "verdict": verdict, **est.to_dict()})
    samples = {m: run_toy("ris-1d", "ris", trials=trials, seed=seed, params={"candidates": m}, device=device, return_samples=True).samples for m in (1, 4, 32)}
    _figure(out, results, samples)
    summary = {"trials": trials, "seed": seed, "device": device, "figure": str(out), "runs": results}
    out.with_suffix(".json").write_text(json.dumps(summary, indent=1, ensure_ascii=False))
    print(f"wrote {out} and {out.with_suffix('.json')}")
    return summary


def _figure(out: Path, results: list[dict[str, Any]], samples: dict[int, np.ndarray]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from grisx.theory.toys.ris_1d import RIS1D

    fig, axes = plt.subplots(1, 2, figsize=(13, 5.2), gridspec_kw={"width_ratios": [1, 1.25]})
    ax = axes[0]
    xs = np.linspace(0, 1, 400)
    f = 0.2 + np.exp(-(((xs - 0.3) / 0.06) ** 2)) + 0.5 * np.exp(-(((xs - 0.72) / 0.1) ** 2))
    exact = float(RIS1D().exact({})[0])
    for m, s in samples.items():
        ax.hist(s, bins=80, range=(0, 1), density=True, histtype="step", lw=1.4, label=f"RIS samples, M = {m}")
    ax.plot(xs, f / exact, "k--", lw=1.2, label="f / ∫f (the M → ∞ limit)")
    ax.set(title="ris-1d: where RIS puts its samples", xlabel="x", ylabel="density")
    ax.legend(fontsize=8)

    ax = axes[1]
    labels = [r["label"].replace("reconnection-flatland", "flatland") for r in results]
    zmax = [max(abs(z) for z in np.atleast_1d(r["z"])) for r in results]
    colors = ["tab:red" if r["biased"] else "tab:blue" for r in results]
    y = np.arange(len(results))[::-1]
    ax.barh(y, zmax, color=colors)
    ax.axvline(DEFAULT_K, color="k", ls="--", lw=1)
    ax.axvline(BIASED_K, color="tab:red", ls=":", lw=1)
    ax.set_xscale("symlog", linthresh=10)
    ax.set_yticks(y, labels, fontsize=7)
    ax.set(title="max |z| over components (blue: unbiased, red: biased by design)", xlabel="|estimate − exact| / stderr")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
