#!/usr/bin/env python
"""Suffix ReSTIR (seed 001, issue 20) against ReSTIR PT and the MMIS gather: frame time, error, correlation.

The paper's comparison (seed 001, Sec. 8): 1920×1080, a moving camera, paths of at most
12 segments, Suffix ReSTIR's final gather with 8 / 32 / 128 integration prefixes per pixel
against ReSTIR PT at equal time and MMIS (West et al. 2022) with 64 prefixes × 3 suffixes.
Per scene (``--scenes``) and method this script measures, on one device:

* **frame time**: the median seconds per frame after the first (compilation and the empty
  history off the clock), the renderer's own pass times beside it;
* **per-frame relMSE** (ε = 1e-2) of the last two frames of a run under the
  scene's **camera path**, each against a path-traced reference at that frame's camera
  (``benchmarks/protocol.py``'s helpers; the references' own noise subtracted), and
  **HDR-FLIP** of the last frame; the **gain over pt** at equal time,
  (relMSE · seconds)_pt / (relMSE · seconds)_method;
* **correlation**: under the static camera, the relMSE of the ``--frames``-frame temporal
  average, and the *correlation factor* F · relMSE(average) / mean relMSE(frame) — 1 for
  independent frames, larger where reuse correlates frames (the paper's motivation for
  reusing suffixes only).

The slow rows (more than 8 prefixes, MMIS) run ``--heavy-frames`` (8) frames instead (both
cameras), evaluated at their own last two frames of the camera path.

Methods: ``pt`` (1 spp), ``restir-pt`` (1 candidate), ``restir-pt`` with more candidates at the
time of ``suffix-restir`` with 8 prefixes (the paper's equal-time setting; the candidate count
from a line through ReSTIR PT's frame time at 1 candidate and at a probe count), ``suffix-restir`` with 8, 32 and 128 prefixes
(``--prefixes``), the first of them again with the O(k) pairwise gather MIS (``gather_mis=pairwise``),
and ``mmis-gather`` (64 × 3). The paper's RTX 4090 frame times are recorded
beside ours (``paper_ms``): 8 prefixes 74 ms, ReSTIR PT 76 ms, 32 prefixes 207 ms, 128 prefixes 736 ms.

Usage::

    python benchmarks/suffix_restir.py --device cuda --out benchmarks/results        # 1920x1080, 32 frames
    python benchmarks/suffix_restir.py --device cpu --width 32 --height 18 --frames 4 --reference-spp 64   # CPU check
    python benchmarks/suffix_restir.py --device cuda --rows "suffix-restir N=128,mmis-gather 64x3" --heavy-frames 2   # some rows (pt always)

Writes ``suffix_restir.json`` (device, versions, settings, every record; rewritten after every row with
``complete: false`` until the end, so a run cut short keeps its rows) and
``suffix_restir.png`` (each method's last moving-camera frame beside the reference, with its
time, relMSE and FLIP) to ``--out``, and prints the table.
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

sys.path.insert(0, str(Path(__file__).resolve().parent))
from protocol import frame_relmse, reference_at, reference_relmse, render_frames  # noqa: E402

import grisx  # noqa: E402
from grisx.device import resolve_device  # noqa: E402
from grisx.errors import GrisxError  # noqa: E402

MAX_DEPTH = 12  # the paper's max path length (segments from the camera)
#: seed 001, Sec. 8 (RTX 4090, 1920x1080): ms per frame
PAPER_MS = {"restir-pt": 76.0, "suffix-restir N=8": 74.0, "suffix-restir N=32": 207.0, "suffix-restir N=128": 736.0}


def methods(prefixes: list[int], gather_k: int | None = None) -> list[tuple[str, str, dict[str, Any]]]:
    """(label, method, params) of the compared renderers (the equal-time ReSTIR PT is added once timed).

    ``gather_k``: borrowed suffixes per integration prefix of the suffix-restir rows (None: the renderer's default).
    """
    k = {} if gather_k is None else {"gather_k": gather_k}
    rows = [("pt", "pt", {}), ("restir-pt", "restir-pt", {})]
    rows += [(f"suffix-restir N={n}", "suffix-restir", {"prefixes": n, **k}) for n in prefixes]
    rows.append((f"suffix-restir N={prefixes[0]} pairwise", "suffix-restir", {"prefixes": prefixes[0], "gather_mis": "pairwise", **k}))
    rows.append(("mmis-gather 64x3", "mmis-gather", {"prefixes": 64, "suffixes": 3}))
    return [(label, m, {"max_depth": MAX_DEPTH, **p}) for label, m, p in rows]


def equal_time_candidates(scene: str, target: float, t_one: float, args: argparse.Namespace) -> int:
    """ReSTIR PT's candidate count whose frame time is ``target``: a line through 1 candidate (``t_one``) and a probe run."""
    c = max(1, int(round(target / t_one)))
    if c == 1:
        return 1
    probe = argparse.Namespace(frames=4, res=(args.width, args.height), device=args.device, seed=args.seed + 5)
    _, timing, _ = render_frames(scene, "restir-pt", {"max_depth": MAX_DEPTH, "candidates": c}, None, "moving", probe, [])
    t_c = timing["median"]
    per_candidate = (t_c - t_one) / (c - 1)
    return max(1, int(round(1 + (target - t_one) / per_candidate))) if per_candidate > 0 else c


def last_frames(frames: int) -> list[int]:
    """The evaluated frames of a run of ``frames`` frames: its last two (history warmed up)."""
    return sorted(set(range(frames // 2, frames)))[-2:]


def heavy_row(label: str) -> bool:
    """Whether a row is one of the slow ones (more than 8 prefixes, or MMIS) that run ``--heavy-frames`` frames."""
    if label.startswith("mmis"):
        return True
    if label.startswith("suffix-restir N="):
        return int(label.split("=")[1].split()[0]) > 8
    return False


def static_correlation(scene: str, method: str, params: dict[str, Any], ref: np.ndarray, ref_var: np.ndarray, args: argparse.Namespace,
                       frames: int) -> dict[str, float]:
    """relMSE of the temporal average of ``frames`` static frames, and the correlation factor."""
    from grisx.eval.metrics import RELMSE_EPSILON, relmse
    from grisx.render.driver import METHODS, render

    per_frame: list[float] = []
    total: list[np.ndarray] = []

    def on_frame(i: int, image: np.ndarray, seconds: float) -> None:
        per_frame.append(relmse(image, ref))
        total.append(image.astype(np.float64) if not total else total.pop() + image)

    spp = 1 if METHODS[method].uses_spp else None
    render(scene, method, spp=spp, frames=frames, res=(args.width, args.height), device=args.device, seed=args.seed + 11,
           params=params, camera="static", on_frame=on_frame)
    noise = reference_relmse(ref, ref_var, RELMSE_EPSILON)
    average = total[0] / frames
    avg = relmse(average, ref) - noise
    frame = float(np.mean(per_frame)) - noise
    return {"static_frame_relmse": frame, "average_relmse": avg, "average_frames": frames, "correlation_factor": frames * avg / frame if frame > 0 else None}


def run_scene(scene: str, args: argparse.Namespace, on_row: Any = None) -> list[dict[str, Any]]:
    from grisx.eval.metrics import flip
    from grisx.render.driver import METHODS as REGISTRY
    from grisx.render.driver import load_scene

    sc = load_scene(scene)
    built = sc.build(args.device)
    built.animate_camera = True
    refs: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def ref_for(frame: int, depth: int) -> tuple[np.ndarray, np.ndarray]:
        if frame not in refs:
            refs[frame] = reference_at(built, args.width, args.height, frame, depth, args.reference_spp, args.seed + 7919)
        return refs[frame]

    static = sc.build(args.device)
    static.animate_camera = False
    static_ref = reference_at(static, args.width, args.height, 0, MAX_DEPTH, args.reference_spp, args.seed + 7920)
    specs = [s for s in methods(args.prefixes, args.gather_k) if args.rows is None or s[0] == "pt" or s[0] in args.rows]
    records: list[dict[str, Any]] = []
    seconds_of: dict[str, float] = {}
    i = 0
    while i < len(specs):
        label, method, params = specs[i]
        i += 1
        spp = 1 if REGISTRY[method].uses_spp else None
        # the slow rows (more than 8 prefixes, MMIS) run --heavy-frames frames, evaluated at their own last frames
        frames = min(args.frames, args.heavy_frames) if heavy_row(label) else args.frames
        ev = last_frames(frames)
        run = argparse.Namespace(frames=frames, res=(args.width, args.height), device=args.device, seed=args.seed)
        kept, timing, r = render_frames(scene, method, params, spp, "moving", run, ev)
        seconds = timing["median"]  # device time per frame, protocol v2 (the first frame not counted)
        seconds_of[label] = seconds
        last = ev[-1]
        rec = {"scene": scene, "method": label, "renderer": method, "params": params, "width": args.width, "height": args.height,
               "frames": frames, "eval_frames": ev, "ms_per_frame": 1e3 * seconds,
               "ms_per_pass": {k: 1e3 * v / frames for k, v in r.pass_seconds.items() if k != "scene_update"},
               "frame_relmse": frame_relmse(kept, ref_for, MAX_DEPTH), "frame_flip": float(flip(kept[last], ref_for(last, MAX_DEPTH)[0])),
               "nonfinite_samples": r.settings.get("nonfinite_samples", 0), "stats": r.settings.get("statistics", {}), "paper_ms": PAPER_MS.get(label),
               "last_frame": kept[last]}
        rec.update(static_correlation(scene, method, params, *static_ref, args, rec["frames"]))
        records.append(rec)
        if label == f"suffix-restir N={args.prefixes[0]}" and "restir-pt" in seconds_of:
            c = equal_time_candidates(scene, seconds, seconds_of["restir-pt"], args)
            specs.insert(i, (f"restir-pt equal-time (candidates={c})", "restir-pt", {"max_depth": MAX_DEPTH, "candidates": c}))
        if on_row is not None:
            on_row(records)
        print(f"[{scene}] {label:34s} {1e3 * seconds:9.2f} ms  relMSE {rec['frame_relmse']:.4g}  FLIP {rec['frame_flip']:.4f}  "
              f"corr. x{rec['correlation_factor'] or 0:.2f}", file=sys.stderr, flush=True)
    base = next(r for r in records if r["method"] == "pt")
    for rec in records:
        rec["gain_vs_pt"] = base["frame_relmse"] * base["ms_per_frame"] / (rec["frame_relmse"] * rec["ms_per_frame"]) if rec["frame_relmse"] > 0 else None
    records.append({"scene": scene, "method": "reference", "last_frame": ref_for(last_frames(args.frames)[-1], MAX_DEPTH)[0]})
    return records


def plot(records: list[dict[str, Any]], path: Path, title: str) -> None:
    """Each method's last moving-camera frame beside the reference, one row per scene."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = list(dict.fromkeys(r["scene"] for r in records))
    cols = max(sum(1 for r in records if r["scene"] == s) for s in scenes)
    fig, axes = plt.subplots(len(scenes), cols, figsize=(2.6 * cols, 1.9 * len(scenes) + 0.6), squeeze=False)
    for row, scene in zip(axes, scenes):
        recs = [r for r in records if r["scene"] == scene]
        ref = next(r for r in recs if r["method"] == "reference")["last_frame"]
        scale = max(float(np.percentile(ref.mean(axis=-1), 99)), 1e-6)
        for ax, r in zip(row, recs):
            ax.imshow(np.clip(r["last_frame"] / scale, 0.0, 1.0) ** (1 / 2.2), interpolation="nearest")
            t = r["method"] if r["method"] == "reference" else f"{r['method']}\n{r['ms_per_frame']:.1f} ms  relMSE {r['frame_relmse']:.3g}  FLIP {r['frame_flip']:.3f}"
            ax.set_title(t, fontsize=6)
            ax.axis("off")
        for ax in row[len(recs):]:
            ax.axis("off")
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--device", default="cuda")
    ap.add_argument("--width", type=int, default=None, help="default 1920 on CUDA, 64 on CPU")
    ap.add_argument("--height", type=int, default=None, help="default 1080 on CUDA, 36 on CPU")
    ap.add_argument("--frames", type=int, default=32, help="frames per run (the temporal average's length)")
    ap.add_argument("--heavy-frames", type=int, default=8, help="frames of the slow rows (more than 8 prefixes, MMIS)")
    ap.add_argument("--scenes", default="closed-room,cornell-box", help="comma-separated built-in scenes")
    ap.add_argument("--prefixes", default="8,32,128", help="integration prefixes per pixel of the suffix-restir rows")
    ap.add_argument("--gather-k", type=int, default=None, help="borrowed suffixes per integration prefix of the suffix-restir rows (default: the renderer's)")
    ap.add_argument("--rows", default=None,
                    help="comma-separated row labels to run (e.g. 'suffix-restir N=128,mmis-gather 64x3'; pt, the gain's baseline, always runs)")
    ap.add_argument("--reference-spp", type=int, default=None, help="reference samples per pixel (default 1024 on CUDA, 256 on CPU; their noise is subtracted)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parent / "results")
    args = ap.parse_args(argv)
    try:
        dev = resolve_device(args.device)
    except GrisxError as exc:
        print(f"suffix_restir.py: error: {exc}", file=sys.stderr)
        return 2
    cuda = dev.is_cuda
    args.width = args.width or (1920 if cuda else 64)
    args.height = args.height or (1080 if cuda else 36)
    args.reference_spp = args.reference_spp or (1024 if cuda else 256)
    args.prefixes = [int(n) for n in args.prefixes.split(",") if n]
    args.rows = None if args.rows is None else {r.strip() for r in args.rows.split(",") if r.strip()}
    known = {label for label, _, _ in methods(args.prefixes, args.gather_k)}
    if args.rows is not None and not args.rows <= known:
        print(f"suffix_restir.py: error: unknown rows {', '.join(sorted(args.rows - known))} (rows: {', '.join(sorted(known))})", file=sys.stderr)
        return 2
    if args.frames < 2 or args.heavy_frames < 2 or args.width < 1 or args.height < 1 or not args.prefixes:
        print("suffix_restir.py: error: need --frames >= 2, a positive size and at least one prefix count", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()

    def write(records: list[dict[str, Any]], complete: bool) -> dict[str, Any]:
        """The JSON, rewritten after every row (``complete`` false until the end): a run cut short keeps what it measured."""
        result = {
            "benchmark": "suffix_restir",
            "complete": complete,
            "device": str(dev),
            "device_name": dev.name if cuda else platform.processor() or platform.machine(),
            "versions": {"grisx": grisx.__version__, "warp": wp.config.version, "numpy": np.__version__, "python": platform.python_version()},
            "settings": {"scenes": args.scenes.split(","), "width": args.width, "height": args.height, "frames": args.frames,
                         "heavy_frames": args.heavy_frames, "max_depth": MAX_DEPTH, "rows": sorted(args.rows) if args.rows else "all",
                         "prefixes": args.prefixes, "reference_spp": args.reference_spp, "seed": args.seed, "relmse_epsilon": 1e-2,
                         "reference": "pt at each evaluated frame's camera (moving), at frame 0 (static), max_depth 12"},
            "paper_ms_rtx4090": PAPER_MS,
            "records": [{k: v for k, v in r.items() if k != "last_frame"} for r in records if r["method"] != "reference"],
            "seconds_total": time.perf_counter() - start,
        }
        (args.out / "suffix_restir.json").write_text(json.dumps(result, indent=2, default=float))
        return result

    records: list[dict[str, Any]] = []
    for scene in args.scenes.split(","):
        records += run_scene(scene, args, on_row=lambda rows: write(records + rows, False))
    result = write(records, True)
    plot(records, args.out / "suffix_restir.png", f"Suffix ReSTIR vs ReSTIR PT and MMIS, {args.width}x{args.height}, {dev}, camera path, max depth {MAX_DEPTH}")
    print(f"{args.width}x{args.height}, {dev}, {args.frames} frames, max_depth {MAX_DEPTH}; relMSE eps 1e-2 against pt ({args.reference_spp} spp)")
    print(f"{'scene':14s} {'method':36s} {'ms':>9s} {'paper ms':>9s} {'relMSE':>9s} {'FLIP':>7s} {'gain':>6s} {'avg relMSE':>11s} {'corr.':>6s} {'B/px':>6s}")
    for r in result["records"]:
        paper = f"{r['paper_ms']:9.0f}" if r.get("paper_ms") else "        -"
        print(f"{r['scene']:14s} {r['method']:36s} {r['ms_per_frame']:9.2f} {paper} {r['frame_relmse']:9.4g} {r['frame_flip']:7.4f} "
              f"{r['gain_vs_pt'] or 0:6.2f} {r['average_relmse']:11.4g} {r['correlation_factor'] or 0:6.2f} {r['stats'].get('reservoir_bytes_per_pixel', '-'):>6}")
    print(f"wrote {args.out / 'suffix_restir.json'} and {args.out / 'suffix_restir.png'} in {result['seconds_total']:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
