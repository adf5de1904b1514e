#!/usr/bin/env python
"""ReSTIR PT (issue 11) against the path tracer and ReSTIR GI: MSE at equal time, and frame time.

For each built-in scene (``--scenes``) this script runs one
:func:`grisx.eval.runner.render_study` with a time budget per method
(``--budget`` seconds of rendering after a warm-up frame; images accumulate
under the static camera) and reads every method's MSE against the cached
path-traced reference at the same time (log-log interpolation): the
**equal-time MSE ratio** = MSE(pt) / MSE(method) (> 1: better than the path
tracer at equal time). Methods, all with paths of at most 10 segments from the
camera (``max_depth`` 10 for every method),
so that the reference (``max_depth`` 10 too) is the limit of every method:

* ``pt`` — 1 sample per pixel per frame (the baseline);
* ``restir-pt`` with ``shift=hybrid``, ``reconnection`` and ``replay``
  (1 initial candidate, temporal reuse, one spatial round of 3 neighbours in
  20 px: the real-time setting);
* ``restir-gi`` (issue 10), when ``grisx.render.restir_gi`` is present.

Because ReSTIR is built for frames that are good *on their own* (its frames
are correlated, so averaging them converges more slowly than averaging
independent path-traced frames), the study's single-frame errors are
summarized too: the mean relMSE of a frame in the second half of each run,
its ratio to pt's, and the **per-frame efficiency ratio**
(relMSE × seconds per frame)_pt / (relMSE × seconds per frame)_method.

A second pass measures **frame time**: ``--timed-frames`` frames of each
method at the study resolution (CPU) or 1920×1080 (CUDA; ``--frame-res``),
per-pass seconds from the renderer's :class:`~grisx.render.driver.PassTimer`
(device synchronized around every pass), the first frame (compilation,
empty history) excluded.

Usage::

    python benchmarks/restir_pt.py                     # CPU: every scene, 96x96, 4 s per method
    python benchmarks/restir_pt.py --quick             # CPU smoke run: 2 scenes, 48x48, 1 s
    python benchmarks/restir_pt.py --device cuda       # GPU: 1920x1080 frame times, 640x360 study

Writes ``restir_pt.json`` and ``restir_pt.png`` (equal-time ratios per scene)
to ``--out`` (default ``benchmarks/results/``), the study's per-scene images
and error curves under ``--out/restir_pt_study/``, and prints the tables.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import warp as wp

import grisx
from grisx.device import resolve_device
from grisx.errors import GrisxError

MAX_DEPTH = 10  # segments from the camera, every method (Mitsuba's meaning)
QUICK_SCENES = ("cornell-box", "glossy-room")


def methods(with_gi: bool) -> list[tuple[str, str, dict[str, Any]]]:
    """(label, method, params) of every compared renderer; the first is the baseline."""
    rows = [
        ("pt", "pt", {"max_depth": MAX_DEPTH}),
        ("restir-pt hybrid", "restir-pt", {"shift": "hybrid", "max_depth": MAX_DEPTH}),
        ("restir-pt reconnection", "restir-pt", {"shift": "reconnection", "max_depth": MAX_DEPTH}),
        ("restir-pt replay", "restir-pt", {"shift": "replay", "max_depth": MAX_DEPTH}),
    ]
    if with_gi:
        rows.append(("restir-gi", "restir-gi", {"max_depth": MAX_DEPTH}))
    return rows


def has_restir_gi() -> bool:
    import importlib.util

    from grisx.render.driver import METHODS

    return "restir-gi" in METHODS and importlib.util.find_spec("grisx.render.restir_gi") is not None


def frame_times(scene: str, specs: list[tuple[str, str, dict[str, Any]]], res: tuple[int, int], device: str, frames: int, seed: int) -> list[dict[str, Any]]:
    """Seconds per frame and per pass (the first frame excluded) of each method."""
    from grisx.render.driver import render

    out = []
    for label, method, params in specs:
        first: dict[str, float] = {}

        def on_frame(i: int, image: np.ndarray, seconds: float, first: dict[str, float] = first) -> None:
            if i == 0:
                first["seconds"] = seconds

        r = render(scene, method, spp=1, frames=frames + 1, res=res, device=device, seed=seed, params=params, camera="static", on_frame=on_frame)
        per_frame = (r.seconds - first["seconds"]) / frames
        out.append({
            "scene": scene, "method": label, "width": res[0], "height": res[1], "frames": frames,
            "ms_per_frame": 1e3 * per_frame,
            # pass timings include the first frame: reported per frame over all frames
            "ms_per_pass": {k: 1e3 * v / (frames + 1) for k, v in r.pass_seconds.items()},
        })
    return out


def per_frame_errors(methods_out: dict[str, Any]) -> dict[str, dict[str, float]]:
    """The real-time view: each frame on its own (second half of the run, history warmed up).

    ``frame_relmse`` is the mean relMSE of single frames, ``frame_seconds`` the mean time per
    frame over the same frames, ``frame_relmse_ratio`` the first method's (pt's) over this
    one's, and ``frame_efficiency_ratio`` = (relMSE × seconds)_pt / (relMSE × seconds)_method.
    """
    out: dict[str, dict[str, float]] = {}
    base = None
    for label, m in methods_out.items():
        rec = m["records"]
        h = len(rec) // 2
        rel = float(np.mean([r["frame_relmse"] for r in rec[h:]]))
        sec = (rec[-1]["seconds"] - rec[h - 1]["seconds"]) / (len(rec) - h) if h > 0 else rec[-1]["seconds"] / len(rec)
        if base is None:
            base = (rel, sec)
        out[label] = {"frame_relmse": rel, "frame_seconds": sec, "frame_relmse_ratio": base[0] / rel if rel > 0 else None,
                      "frame_efficiency_ratio": base[0] * base[1] / (rel * sec) if rel > 0 and sec > 0 else None}
    return out


def plot(summary: list[dict[str, Any]], path: Path, title: str) -> None:
    """Two bar charts per scene: accumulated MSE ratio at equal time, and per-frame efficiency ratio (log scale)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = list(dict.fromkeys(s["scene"] for s in summary))
    labels = [lab for lab in dict.fromkeys(s["method"] for s in summary) if lab != "pt"]
    fig, axes = plt.subplots(2, 1, figsize=(max(8.0, 1.1 * len(scenes)), 7.5), sharex=True)
    width = 0.8 / max(1, len(labels))
    x = np.arange(len(scenes))
    for ax, key, ylabel in (
        (axes[0], "mse_ratio", "MSE(pt) / MSE(method)\naccumulated, equal time"),
        (axes[1], "frame_efficiency_ratio", "per-frame efficiency vs pt\n(relMSE x s)_pt / (relMSE x s)"),
    ):
        for j, lab in enumerate(labels):
            vals = [next((s[key] for s in summary if s["scene"] == sc and s["method"] == lab), None) for sc in scenes]
            ax.bar(x + (j - (len(labels) - 1) / 2) * width, [v if v else 0.0 for v in vals], width, label=lab)
        ax.axhline(1.0, color="k", lw=0.8)
        ax.set_yscale("log")
        ax.set_ylabel(ylabel)
        ax.grid(True, axis="y", which="both", alpha=0.3)
    axes[0].legend(fontsize=8, ncol=len(labels))
    axes[0].set_title(title)
    axes[1].set_xticks(x, scenes, rotation=30, ha="right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--scenes", default=None, help="comma-separated built-in scenes (default: all; --quick: cornell-box,glossy-room)")
    ap.add_argument("--res", default=None, help="study resolution WxH (default 96x96 on CPU, 48x48 with --quick, 640x360 on CUDA)")
    ap.add_argument("--frame-res", default=None, help="frame-time resolution (default: the study's on CPU, 1920x1080 on CUDA)")
    ap.add_argument("--budget", type=float, default=None, help="seconds per method and scene (default 4; 1 with --quick; 5 on CUDA)")
    ap.add_argument("--reference-spp", type=int, default=None, help="reference samples per pixel (default 2048; 512 with --quick; 8192 on CUDA)")
    ap.add_argument("--timed-frames", type=int, default=None, help="frames timed per method (default 4 on CPU, 20 on CUDA)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--no-gi", action="store_true", help="leave ReSTIR GI out")
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parent / "results")
    args = ap.parse_args(argv)
    try:
        dev = resolve_device(args.device)
    except GrisxError as exc:
        print(f"restir_pt.py: error: {exc}", file=sys.stderr)
        return 2
    cuda = dev.is_cuda
    from grisx.eval.runner import MethodSpec, render_study
    from grisx.scene.builtin import BUILTIN_SCENES
    from grisx.render.reference import reference
    from grisx.render.driver import parse_res, render

    scenes = args.scenes.split(",") if args.scenes else (list(QUICK_SCENES) if args.quick else list(BUILTIN_SCENES))
    res = parse_res(args.res or ("640x360" if cuda else ("48x48" if args.quick else "96x96")))
    frame_res = parse_res(args.frame_res) if args.frame_res else ((1920, 1080) if cuda else res)
    budget = args.budget or (5.0 if cuda else (1.0 if args.quick else 4.0))
    ref_spp = args.reference_spp or (8192 if cuda else (512 if args.quick else 2048))
    timed = args.timed_frames or (20 if cuda else (2 if args.quick else 4))
    with_gi = has_restir_gi() and not args.no_gi
    specs = methods(with_gi)

    def reference_10(scene: str, *, res: Any = None, spp: int = 1024, device: str = "cpu", seed: int = 0) -> Any:
        # the limit of every compared method: paths of at most MAX_DEPTH segments
        return reference(scene, res=res, spp=spp, max_depth=MAX_DEPTH, device=device, seed=seed)

    args.out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    study = render_study(
        scenes,
        [MethodSpec(m, p, label) for label, m, p in specs],
        budget=budget,
        res=res,
        device=args.device,
        seed=args.seed + 1,
        reference_spp=ref_spp,
        metrics=("mse", "relmse"),
        final_metrics=(),
        out=args.out / "restir_pt_study",
        progress=False,
        render=render,
        reference=reference_10,
    )
    summary = []
    for scene in scenes:
        eq = study["scenes"][scene]["equal_time"]
        per_frame = per_frame_errors(study["scenes"][scene]["methods"])
        for row in eq["rows"]:
            summary.append({"scene": scene, "method": row["method"], "seconds": eq["seconds"], "mse": row["mse"], "mse_ratio": row["ratio"],
                            "frames": len(study["scenes"][scene]["methods"][row["method"]]["records"]), **per_frame[row["method"]]})
    times = [t for scene in scenes for t in frame_times(scene, specs, frame_res, args.device, timed, args.seed + 2)]
    result = {
        "benchmark": "restir_pt",
        "device": str(dev),
        "device_name": dev.name if cuda else platform.processor() or platform.machine(),
        "versions": {"grisx": grisx.__version__, "warp": wp.config.version, "numpy": np.__version__, "python": platform.python_version()},
        "settings": {"scenes": scenes, "res": list(res), "frame_res": list(frame_res), "budget_seconds": budget, "reference_spp": ref_spp,
                     "max_depth": MAX_DEPTH, "timed_frames": timed, "seed": args.seed, "quick": args.quick,
                     "methods": [{"label": lab, "method": m, "params": p} for lab, m, p in specs]},
        "equal_time": summary,
        "frame_time": times,
        "seconds_total": time.perf_counter() - start,
        "study_json": str(args.out / "restir_pt_study" / "render_study.json"),
    }
    (args.out / "restir_pt.json").write_text(json.dumps(result, indent=2, default=float))
    plot(summary, args.out / "restir_pt.png", f"ReSTIR PT vs pt at {budget:g} s, {res[0]}x{res[1]}, {dev}")
    print(f"equal time ({budget:g} s per method, {res[0]}x{res[1]}, {dev}): MSE and MSE(pt) / MSE(method)")
    print(f"{'scene':20s} {'method':24s} {'frames':>7s} {'MSE':>11s} {'ratio':>7s}")
    for s in summary:
        ratio = f"{s['mse_ratio']:7.2f}" if s["mse_ratio"] else "      -"
        mse = f"{s['mse']:11.4g}" if s["mse"] is not None else "          -"
        print(f"{s['scene']:20s} {s['method']:24s} {s['frames']:7d} {mse} {ratio}")
    print("\nsingle frames (second half of each run): relMSE of a frame, pt's / the method's, and per-frame efficiency vs pt")
    print(f"{'scene':20s} {'method':24s} {'relMSE':>10s} {'ratio':>7s} {'ms':>8s} {'eff.':>6s}")
    for s in summary:
        print(f"{s['scene']:20s} {s['method']:24s} {s['frame_relmse']:10.4g} {s['frame_relmse_ratio']:7.2f} {1e3 * s['frame_seconds']:8.2f} {s['frame_efficiency_ratio']:6.2f}")
    print(f"\nframe time ({frame_res[0]}x{frame_res[1]}, {dev}, mean of {timed} frames after the first)")
    for t in times:
        passes = ", ".join(f"{k} {v:.2f}" for k, v in t["ms_per_pass"].items() if k != "scene_update")
        print(f"{t['scene']:20s} {t['method']:24s} {t['ms_per_frame']:10.2f} ms   ({passes})")
    print(f"\nwrote {args.out / 'restir_pt.json'} and {args.out / 'restir_pt.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
