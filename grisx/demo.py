"""``grisx demo``: the whole toolkit in one run — every toy problem, the five seeds, one scene.

What a newcomer sees, on CPU in about two minutes:

1. **Every toy problem** (``grisx toy list``), each method once with its
   defaults and the known-biased ablations: one line each with the estimate,
   the exact value and z = (estimate − exact) / stderr. Unbiased estimators
   stay within |z| ≤ 4; the biased ones are *caught* (|z| > 6).
2. **The five seeds' signature results**, drawn in one figure:
   RIS's sample histograms approaching f/∫f (the estimator core);
   seed 000 — the distribution of a pixel-difference estimate with gradient
   *after* ReSTIR and gradient *with* ReSTIR (its Fig. 3);
   seed 001 — the final gather against marginal MIS at equal suffixes;
   seed 002 — ReSTCV against ReSTIR, relative error per colour channel;
   seed 003 — Newton iterations per manifold solution, with and without
   sample-space partitioning (its Table 1; the prior's presampling walks are
   printed beside it, since on this toy they cost more than they save);
   seed 004 — a scene: ``pt`` and ``restir-gi`` at equal time, with relMSE
   against a high-spp reference.
3. The z-values of every toy run.

The figure is ``--out`` (PNG) and a JSON summary lies beside it. ``--device
cuda`` runs the same at full size.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from grisx.testing import BIASED_K, DEFAULT_K, z_test
from grisx.theory.toys import PROBLEMS, run_toy

__all__ = ["run_demo", "DEMO_RUNS"]

#: (problem, method, params, share of --trials) of every toy run: every problem and method, and the
#: known-biased ablations (a share below 1 where one trial is a whole image or a Newton walk per pixel)
DEMO_RUNS: tuple[tuple[str, str, dict[str, Any], float], ...] = (
    ("ris-1d", "mc", {}, 1),
    ("ris-1d", "ris", {}, 1),
    ("ris-1d", "ris", {"target": "narrow"}, 1),
    ("gris-shift", "gris", {"mis": "balance"}, 1),
    ("gris-shift", "gris", {"mis": "pairwise"}, 1),
    ("gris-shift", "gris", {"mis": "naive"}, 1),
    ("gris-shift", "gris", {"jacobian": False}, 1),
    ("reconnection-flatland", "gris", {"mis": "balance"}, 1),
    ("reconnection-flatland", "gris", {"jacobian": False}, 1),
    ("joint-ucw", "independent", {}, 1),
    ("joint-ucw", "dependent", {}, 1),
    ("suffix-reuse", "cris", {}, 1),
    ("suffix-reuse", "cris", {"jacobian": False}, 1),
    ("final-gather", "gather", {}, 1),
    ("final-gather", "mmis", {}, 1),
    ("final-gather", "gather", {"canonical": False}, 1),
    ("f1-f2", "mc-difference", {}, 1),
    ("f1-f2", "gradient-pt", {}, 1),
    ("f1-f2", "gradient-after-restir", {}, 1),
    ("f1-f2", "gradient-with-restir", {}, 1),
    ("f1-f2", "gradient-with-restir", {"positivize": True}, 1),
    ("gradient-row", "gradient-pt", {}, 0.25),
    ("gradient-row", "gradient-with-restir", {}, 0.25),
    ("chromatic-cv", "restir", {}, 0.01),
    ("chromatic-cv", "restcv", {}, 0.01),
    ("sms-toy", "sms", {}, 0.05),
    ("sms-toy", "sms-partitioned", {}, 0.05),
    ("sms-toy", "sms", {"max_trials": 2}, 0.05),
)


def run_demo(out: str | os.PathLike = "grisx-demo.png", trials: int = 100_000, seed: int = 0, device: str = "cpu",
             scene: bool = True) -> dict[str, Any]:
    """Run :data:`DEMO_RUNS` and the scene comparison, print each result, write the figure and a JSON summary."""
    from grisx.errors import InvalidParameterError
    from grisx.imageio import check_writable_dir

    out = Path(out)
    if out.suffix.lower() != ".png":
        raise InvalidParameterError(f"--out must name a .png file, got '{out}'")

    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InvalidParameterError(f"--out '{out}': cannot create directory '{out.parent}': {exc.strerror or exc}") from None
    check_writable_dir(out.parent, f"--out '{out}'")  # before the work, not after it
    start = time.perf_counter()
    results, runs = [], {}
    print("# every toy problem: estimate beside its exact value\n")
    for name, method, params, share in DEMO_RUNS:
        n = max(1000, int(trials * share))
        want_values = name == "f1-f2" and method in ("gradient-after-restir", "gradient-with-restir") and not params
        est = run_toy(name, method, trials=n, seed=seed, params=params, device=device, return_values=want_values)
        biased = PROBLEMS[name].is_biased(method, est.params)
        check = z_test(est.estimate, est.stderr, est.exact, k=DEFAULT_K)
        verdict = ("caught: biased by design" if check.max_abs_z > BIASED_K else "NOT caught") if biased else ("unbiased: ok" if check.passed else "UNEXPECTED: fails the z-test")
        label = " ".join(f"{k}={v}" for k, v in params.items()) or "defaults"
        print(_one_line(est, label, verdict), flush=True)
        results.append({"label": f"{name} {method} {label}", "biased": biased, "verdict": verdict, **est.to_dict()})
        runs[(name, method, label)] = est
    ris = {m: run_toy("ris-1d", "ris", trials=trials, seed=seed, params={"candidates": m}, device=device, return_samples=True).samples for m in (1, 4, 32)}
    scene_result = _scene_comparison(device, seed) if scene else None
    _figure(out, results, runs, ris, scene_result)
    seconds = time.perf_counter() - start
    summary = {"trials": trials, "seed": seed, "device": device, "figure": str(out), "seconds": round(seconds, 1), "runs": results,
               "scene": None if scene_result is None else {k: v for k, v in scene_result.items() if k != "images"}}
    from grisx.eval.files import write_json

    write_json(out.with_suffix(".json"), summary)
    print(f"wrote {out} and {out.with_suffix('.json')} ({seconds:.0f} s)")
    return summary


def _one_line(est: Any, label: str, verdict: str) -> str:
    """problem / method params: estimate vs exact (the component farthest from it), max |z|, verdict."""
    z = np.atleast_1d(est.z)
    i = int(np.argmax(np.abs(z)))
    e, x = np.atleast_1d(est.estimate)[i], np.atleast_1d(est.exact)[i]
    where = f"[{i}] " if z.size > 1 else ""
    return (f"{est.problem + ' / ' + est.method:36s} {label:18s} {where}{e:10.5f} vs exact {x:10.5f}  "
            f"max|z| {np.max(np.abs(z)):7.2f} of {z.size:4d}  {est.trials:7d} trials  -> {verdict}")


def _scene_comparison(device: str, seed: int) -> dict[str, Any]:
    """seed 004 on a scene: ``restir-gi`` after a few frames of reuse against ``pt`` given the same frame time."""
    from grisx.eval.metrics import relmse
    from grisx.render import render

    cuda = device.startswith("cuda")
    res = (480, 360) if cuda else (96, 72)
    name, frames = "cornell-box", 8
    print(f"# seed 004 on a scene: {name} {res[0]}x{res[1]}, restir-gi after {frames} frames vs pt at equal time\n")
    times: list[float] = []
    gi = render(name, "restir-gi", frames=frames, res=res, device=device, seed=seed, camera="static",
                on_frame=lambda i, img, s: times.append(s))
    frame_seconds = float(np.median(np.diff([0.0, *times])[1:]))
    one = render(name, "pt", spp=1, frames=3, res=res, device=device, seed=seed + 1, camera="static")
    pt_spp = max(1, int(round(frame_seconds / (one.seconds / 3))))
    pt = render(name, "pt", spp=pt_spp, res=res, device=device, seed=seed + 2)
    ref = render(name, "pt", spp=256 if not cuda else 4096, res=res, device=device, seed=seed + 3)
    row = {
        "scene": name, "res": list(res), "frame_seconds": frame_seconds, "pt_spp": pt_spp, "pt_seconds": pt.seconds,
        "reference_spp": ref.spp, "relmse_pt": float(relmse(pt.image, ref.image)), "relmse_restir_gi": float(relmse(gi.image, ref.image)),
        "images": {"reference": ref.image, "pt": pt.image, "restir-gi": gi.image},
    }
    print(f"frame time {1e3 * frame_seconds:.0f} ms: pt {pt_spp} spp relMSE {row['relmse_pt']:.4f}, "
          f"restir-gi relMSE {row['relmse_restir_gi']:.4f} (reference pt {ref.spp} spp)\n")
    return row


def _tonemap(img: np.ndarray) -> np.ndarray:
    x = np.clip(np.asarray(img, dtype=np.float64), 0.0, None)
    return np.clip(np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055), 0.0, 1.0)


def plot_ris_histograms(ax: Any, samples: dict[int, np.ndarray]) -> None:
    """Histograms of RIS's kept samples on ``ris-1d`` for several candidate counts M, beside f / ∫f."""
    from grisx.theory.toys.ris_1d import RIS1D

    xs = np.linspace(0, 1, 400)
    f = 0.2 + np.exp(-(((xs - 0.3) / 0.06) ** 2)) + 0.5 * np.exp(-(((xs - 0.72) / 0.1) ** 2))
    exact = float(RIS1D().exact({})[0])
    for m, s in samples.items():
        ax.hist(s, bins=80, range=(0, 1), density=True, histtype="step", lw=1.4, label=f"M = {m}")
    ax.plot(xs, f / exact, "k--", lw=1.2, label="f / ∫f")
    ax.set(title="RIS: where the kept sample lands (ris-1d)", xlabel="x", ylabel="density")
    ax.legend(fontsize=8)


def plot_gradient_histograms(ax: Any, after: Any, with_: Any) -> None:
    """Seed 000's Fig. 3: the distribution of one trial's pixel difference, gradient after vs with ReSTIR."""
    lo, hi = np.percentile(np.concatenate([after.values, with_.values]), [0.5, 99.5])
    for est, label in ((after, "gradient after ReSTIR"), (with_, "gradient with ReSTIR")):
        ax.hist(est.values, bins=80, range=(lo, hi), density=True, histtype="step", lw=1.4,
                label=f"{label}: σ = {np.std(est.values):.3f}")
    ax.axvline(float(after.exact), color="k", ls="--", lw=1, label="exact F₁ − F₂")
    ax.set(title="seed 000: one trial's pixel difference (f1-f2, Fig. 3)", xlabel="estimate", ylabel="density")
    ax.legend(fontsize=8)


def _figure(out: Path, results: list[dict[str, Any]], runs: dict[tuple[str, str, str], Any], ris: dict[int, np.ndarray],
            scene: dict[str, Any] | None) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(17, 14))
    grid = fig.add_gridspec(3, 4, height_ratios=[1, 1, 1.05])

    # ---- the estimator core: RIS ----
    plot_ris_histograms(fig.add_subplot(grid[0, 0]), ris)

    # ---- seed 000: gradient after vs with ReSTIR ----
    plot_gradient_histograms(fig.add_subplot(grid[0, 1]), runs[("f1-f2", "gradient-after-restir", "defaults")],
                             runs[("f1-f2", "gradient-with-restir", "defaults")])

    # ---- seed 001: final gather vs marginal MIS ----
    ax = fig.add_subplot(grid[0, 2])
    variants = [("final-gather", "mmis", "defaults"), ("final-gather", "gather", "defaults")]
    sig = [float(np.sqrt(np.mean(np.square(runs[v].stderr)) * runs[v].trials)) for v in variants]
    ax.bar(["marginal MIS\n(independent suffixes)", "final gather\n(ReSTIR suffixes, Eq. 23)"], sig, color=["tab:gray", "tab:green"])
    ax.set(title="seed 001: error of one trial (final-gather)", ylabel="RMSE per trial")

    # ---- seed 002: ReSTCV vs ReSTIR per channel ----
    ax = fig.add_subplot(grid[0, 3])
    width = 0.38
    for k, (method, color) in enumerate((("restir", "tab:gray"), ("restcv", "tab:purple"))):
        est = runs[("chromatic-cv", method, "defaults")]
        se = np.asarray(est.stderr).reshape(-1, 3)
        ex = np.asarray(est.exact).reshape(-1, 3)
        rel = np.sqrt(np.mean(se**2 * est.trials / (ex**2 + 1e-3), axis=0))
        ax.bar(np.arange(3) + (k - 0.5) * width, rel, width, color=color, label=method)
    ax.set_xticks(range(3), ["R", "G", "B"])
    ax.set(title="seed 002: error per channel (chromatic-cv)", ylabel="relative RMSE of one frame")
    ax.legend(fontsize=8)

    # ---- seed 003: Newton iterations per solution ----
    ax = fig.add_subplot(grid[1, 0])
    sms, part = runs[("sms-toy", "sms", "defaults")].stats, runs[("sms-toy", "sms-partitioned", "defaults")].stats
    vals = [sms["newton_per_solution"], part["newton_per_solution"]]
    ax.bar(["SMS", "SMS + sample-space\npartitioning + prior"], vals, color=["tab:gray", "tab:orange"])
    for i, v in enumerate(vals):
        ax.text(i, v, f"{v:.1f}", ha="center", va="bottom")
    ax.set(title="seed 003: Newton iterations per solution (Table 1)", ylabel="iterations in Bernoulli trials")
    ax.text(0.98, 0.95, f"all walks incl. prior presampling:\n{sms['newton_total_per_solution']:.1f} vs {part['newton_total_per_solution']:.1f}",
            transform=ax.transAxes, ha="right", va="top", fontsize=8)

    # ---- z of every toy run ----
    ax = fig.add_subplot(grid[1, 1:])
    labels = [r["label"].replace("reconnection-flatland", "flatland") for r in results]
    zmax = [max(abs(z) for z in np.atleast_1d(r["z"])) for r in results]
    colors = ["tab:red" if r["biased"] else "tab:blue" for r in results]
    x = np.arange(len(results))
    ax.bar(x, zmax, color=colors)
    ax.axhline(DEFAULT_K, color="k", ls="--", lw=1)
    ax.axhline(BIASED_K, color="tab:red", ls=":", lw=1)
    ax.set_yscale("symlog", linthresh=10)
    ax.set_xticks(x, labels, rotation=75, ha="right", fontsize=7)
    ax.set(title="every toy problem: max |z| (blue: unbiased, must stay under 4; red: biased by design, must exceed 6)", ylabel="|estimate − exact| / stderr")

    # ---- seed 004: a scene at equal time ----
    if scene is not None:
        panels = [("reference", f"reference: pt {scene['reference_spp']} spp"),
                  ("pt", f"pt {scene['pt_spp']} spp — relMSE {scene['relmse_pt']:.4f}"),
                  ("restir-gi", f"restir-gi (8th frame) — relMSE {scene['relmse_restir_gi']:.4f}")]
        for k, (key, title) in enumerate(panels):
            ax = fig.add_subplot(grid[2, k])
            ax.imshow(_tonemap(scene["images"][key]), interpolation="nearest")
            ax.set_title(title, fontsize=10)
            ax.axis("off")
        ax = fig.add_subplot(grid[2, 3])
        ax.axis("off")
        ax.text(0, 0.5, f"seed 004 (ReSTIR GI) on {scene['scene']}\n{scene['res'][0]}×{scene['res'][1]}, "
                        f"equal time: {1e3 * scene['frame_seconds']:.0f} ms a frame\n\n"
                        "the same estimator core as the toys:\nreservoirs, UCWs, MIS weights and\nshift Jacobians of grisx.theory",
                fontsize=10, va="center")
    fig.suptitle("grisx demo — every toy problem against its exact value, and the five seeds", fontsize=14)
    fig.tight_layout()
    fig.savefig(out, dpi=90)
    plt.close(fig)
