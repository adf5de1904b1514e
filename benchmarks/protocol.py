#!/usr/bin/env python
"""The one benchmark protocol every renderer reports on (see benchmarks/README.md, "The protocol").

What users of a real-time renderer see is a **single frame**, jittered (a
new camera sample per pixel and frame), under a static or a moving camera.
So the protocol measures, per scene, camera and method:

* **frame time** (protocol v2): the median and quartiles, over the frames whose
  error is measured (the second half of the run; 32 frames by default), of
  each frame's device time, as
  :func:`grisx.render.driver.render` reports it in ``frame_seconds``: the
  device synchronized before the frame and after its last pass, the host copy
  of the image off the clock, for every method, ``pt`` included (protocol v1
  timed ``pt`` with each frame's copy to the host: its gains were inflated);
  ``pt_spp`` is the method's frame time over pt's at 1 spp. The frames timed
  are the frames evaluated because a reuse method's frame is not steady while
  its reservoirs fill: ReSTIR GI's grows by a quarter between its first 16
  frames and frames 64–79 of door-ajar (benchmarks/README.md, "ReSTIR GI's frame
  grows as its reservoirs fill"); until the nineteenth session the protocol timed every frame after
  the first (``frame_seconds_all`` keeps that median);
* **per-frame relMSE** (ε = 1e-2, :func:`grisx.eval.metrics.relmse`) of the
  frames in the second half of the run (history warmed up), each against a
  path-traced reference *at that frame's camera* with the method's own
  ``max_depth`` (``restir-di`` estimates pt's ``max_depth`` 2), the
  reference's own expected contribution (its variance of the mean, averaged
  as relMSE does) subtracted;
* **the equal-time relMSE gain over pt**: (relMSE · seconds)_pt /
  (relMSE · seconds)_method, pt at 1 spp per frame and the method's depth.
  A path tracer's single-frame relMSE falls as 1/spp, so this is the ratio
  of relMSEs when pt is given the method's frame time;
* **MAPE and colour noise** of the same frames (``frame_mape``, ``frame_chroma``:
  :func:`grisx.eval.metrics.mape`, :func:`grisx.eval.metrics.chroma`; seed 002
  reports MAPE over the full image and argues about colour noise), not
  corrected for the reference's noise;
* **FLIP at equal time**: HDR-FLIP of the method's last evaluated frame and
  of a pt frame rendered with spp = round(t_method / t_pt) at the same camera,
  both against the reference.

Scenes: ``cornell-box``, ``door-ajar``, ``glossy-room``, ``closed-room``,
``many-lights`` (``--scenes``); cameras: the static camera and the scene's
camera path; methods: ``pt``, ``restir-di``, ``restir-gi`` (with ``direct=nee`` and
``direct=restir-di``), ``restir-pt``, ``restcv`` and ``area-restir``
(``--methods``, ``label=method:k=v:k=v`` to add a configuration; every
renderer added later joins with one entry). Depth: each scene's own
``max_depth`` (the built-in scenes: 16; ``closed-room``: −1).

Kernels compile first, every scene in its own process at once (``--jobs``:
one tiny render of every method and camera fills Warp's kernel cache); the
measurements then run one scene at a time, so that no two renderers share the
device while they are timed.

Usage::

    python benchmarks/protocol.py --device cuda --out benchmarks/results/protocol      # the protocol: 1920x1080
    python benchmarks/protocol.py --quick                                              # CPU smoke run (64x36, 2 scenes)

Writes ``protocol.json`` (settings, device, versions, references' spp, every
record) and ``protocol.png`` (gain per scene and method, static and moving),
and prints the table.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

SCENES = ("cornell-box", "door-ajar", "glossy-room", "closed-room", "many-lights")
METHODS = ("pt", "restir-di", "restir-gi", "restir-gi-di=restir-gi:direct=restir-di", "restir-pt", "restcv", "area-restir")
CAMERAS = ("static", "moving")


def parse_methods(text: str) -> list[tuple[str, str, dict[str, str]]]:
    """``label=method:k=v:...`` or ``method`` entries, comma-separated → (label, method, params)."""
    out = []
    for item in filter(None, (s.strip() for s in text.split(","))):
        label, _, spec = item.partition("=") if "=" in item.split(":")[0] else (item.split(":")[0], "", item)
        method, *kvs = spec.split(":")
        out.append((label, method, dict(kv.split("=", 1) for kv in kvs)))
    return out


def reference_at(built: Any, width: int, height: int, frame: int, max_depth: int, spp: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The path tracer's image at ``frame``'s camera (and object positions) and its variance of the mean."""
    from grisx.render.pt import PathTracer

    built.set_frame(float(frame))
    pt = PathTracer(built, width, height, spp=spp, max_depth=max_depth, seed=seed)
    pt.add_samples(frame, spp)
    return pt.mean().astype(np.float64), pt.variance_of_mean().astype(np.float64)


def cached_reference(cache: Path | None, scene: str, camera: str, frame: int, depth: int, width: int, height: int, spp: int, seed: int,
                     compute: Any) -> tuple[np.ndarray, np.ndarray]:
    """``compute()``'s reference, kept in ``cache`` (a directory; None: no cache) under everything that selects it.

    The key does not know the code: a cache is valid for one tree. Use a fresh directory when the path tracer
    or a scene changes. On a GPU lease it saves each repeated call the references it already rendered.
    """
    if cache is None:
        return compute()
    tag = hashlib.sha1(scene.encode()).hexdigest()[:8]
    path = Path(cache) / f"{Path(scene).stem}-{tag}_{camera}_f{frame}_d{depth}_{width}x{height}_spp{spp}_s{seed}.npz"
    if path.exists():
        with np.load(path) as z:
            return z["ref"], z["var"]
    ref, var = compute()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npz")  # written whole, then renamed: an interrupted run leaves no half file
    np.savez(tmp, ref=ref, var=var)
    tmp.replace(path)
    return ref, var


def reference_relmse(ref: np.ndarray, var: np.ndarray, eps: float) -> float:
    """What the reference's own noise adds, in expectation, to a relMSE against it."""
    return float(np.mean(var / (ref**2 + eps)))


def render_frames(scene: str, method: str, params: dict[str, Any], spp: int | None, camera: str, args: argparse.Namespace,
                  eval_frames: list[int]) -> tuple[dict[int, np.ndarray], dict[str, float], Any]:
    """Render ``args.frames`` frames; keep the ``eval_frames`` images; frame time statistics over the frames from the first
    evaluated one on (and ``median_all``: every frame after the first).

    Time is :attr:`~grisx.render.driver.RenderResult.frame_seconds`: each frame's device time
    (synchronized before and after, the host copy of the image excluded), the same clock for
    every method, ``pt`` included (protocol v2).
    """
    from grisx.render.driver import render

    kept: dict[int, np.ndarray] = {}

    def on_frame(i: int, image: np.ndarray, seconds: float) -> None:
        if i in eval_frames:
            kept[i] = image.copy()

    r = render(scene, method, spp=spp, frames=args.frames, res=args.res, device=args.device, seed=args.seed, params=params,
               camera="path" if camera == "moving" else "static", on_frame=on_frame)
    return kept, frame_time(r.frame_seconds, min(eval_frames)), r


def frame_time(frame_seconds: list[float], first: int = 1) -> dict[str, float]:
    """Median and quartiles of frames ``first``, ``first`` + 1, … (never frame 0: its history is empty), and the median of
    every frame after the first (``median_all``, the window of earlier runs)."""
    s = np.asarray(frame_seconds, dtype=np.float64)
    t = s[max(1, min(first, s.size - 1)):] if s.size > 1 else s
    q25, q50, q75 = np.percentile(t, [25, 50, 75])
    return {"median": float(q50), "q25": float(q25), "q75": float(q75), "frames_timed": int(t.size),
            "median_all": float(np.median(s[1:] if s.size > 1 else s))}


def frame_relmse(kept: dict[int, np.ndarray], ref_for: Any, depth: int) -> float:
    """Mean relMSE of the kept frames against their references, less what the references' noise adds."""
    from grisx.eval.metrics import RELMSE_EPSILON, relmse

    return float(np.mean([relmse(img, ref_for(f, depth)[0]) - reference_relmse(*ref_for(f, depth), RELMSE_EPSILON) for f, img in kept.items()]))


def frame_metric(name: str, kept: dict[int, np.ndarray], ref_for: Any, depth: int) -> float:
    """Mean of metric ``name`` (:data:`grisx.eval.metrics.METRICS`) over the kept frames against their references."""
    from grisx.eval.metrics import METRICS

    return float(np.mean([METRICS[name](img, ref_for(f, depth)[0]) for f, img in kept.items()]))


def run_scene(scene: str, args: argparse.Namespace) -> list[dict[str, Any]]:
    from grisx.eval.metrics import flip
    from grisx.render.driver import METHODS as REGISTRY
    from grisx.render.driver import load_scene

    width, height = args.res
    sc = load_scene(scene)
    scene_depth = int(sc.defaults.get("max_depth", 16))
    frames = args.frames
    eval_frames = sorted(set(range(frames // 2, frames, max(1, frames // 4))) | {frames - 1})
    records: list[dict[str, Any]] = []
    for camera in CAMERAS:
        built = sc.build(args.device)
        built.animate_camera = camera == "moving"
        ref_frames = eval_frames if camera == "moving" else [eval_frames[0]]
        refs: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}

        def ref_for(frame: int, depth: int) -> tuple[np.ndarray, np.ndarray]:
            f = frame if camera == "moving" else ref_frames[0]
            if (f, depth) not in refs:
                refs[f, depth] = cached_reference(args.reference_cache, scene, camera, f, depth, width, height, args.reference_spp, args.seed + 7919,
                                                  lambda: reference_at(built, width, height, f, depth, args.reference_spp, args.seed + 7919))
            return refs[f, depth]

        baseline: dict[int, dict[str, float]] = {}  # depth → pt's per-frame relMSE and seconds
        for label, method, params in args.methods:
            spec = REGISTRY[method]
            depth = spec.reference_max_depth or int(params.get("max_depth", scene_depth))
            p = dict(params)
            if "max_depth" in {q.name for q in spec.params} and "max_depth" not in p:
                p["max_depth"] = depth
            kept, timing, r = render_frames(scene, method, p, 1 if spec.uses_spp else None, camera, args, eval_frames)
            seconds = timing["median"]
            rec = {"scene": scene, "camera": camera, "method": label, "renderer": method, "params": {k: str(v) for k, v in p.items()},
                   "max_depth": depth, "width": width, "height": height, "frames": frames, "eval_frames": sorted(kept),
                   "frame_seconds": seconds, "frame_seconds_q25": timing["q25"], "frame_seconds_q75": timing["q75"],
                   "frames_timed": timing["frames_timed"], "frame_seconds_all": timing["median_all"],
                   "frame_relmse": frame_relmse(kept, ref_for, depth),
                   "frame_mape": frame_metric("mape", kept, ref_for, depth), "frame_chroma": frame_metric("chroma", kept, ref_for, depth),
                   "nonfinite_samples": r.settings.get("nonfinite_samples", 0)}
            if method == "pt" and depth not in baseline:
                baseline[depth] = rec
            last = eval_frames[-1]
            ref, _ = ref_for(last, depth)
            rec["frame_flip"] = float(flip(kept[last], ref))
            records.append(rec)
            # pt at this depth if the protocol's pt row ran at another one (restir-di: depth 2)
            if depth not in baseline:
                b = _pt_row(scene, camera, depth, args, eval_frames, ref_for)
                baseline[depth] = b
                records.append(b)
            base = baseline[depth]
            rec["pt_frame_relmse"] = base["frame_relmse"]
            rec["pt_frame_seconds"] = base["frame_seconds"]
            rec["gain"] = base["frame_relmse"] * base["frame_seconds"] / (rec["frame_relmse"] * seconds) if rec["frame_relmse"] > 0 else None
            rec["pt_spp"] = seconds / base["frame_seconds"]  # the method's frame in path-traced samples (protocol v2)
            rec["pt_equal_time_spp"] = max(1, int(round(seconds / base["frame_seconds"])))
            if method != "pt":
                pt_eq = _pt_frame(scene, camera, depth, rec["pt_equal_time_spp"], last, args)
                rec["pt_equal_time_flip"] = float(flip(pt_eq, ref))
            print(f"[{scene}] {camera:6s} {label:24s} {1e3 * seconds:8.2f} ms  relMSE {rec['frame_relmse']:.4g}  gain {rec['gain'] or 0:.2f}", file=sys.stderr, flush=True)
    return records


def _pt_frame(scene: str, camera: str, depth: int, spp: int, frame: int, args: argparse.Namespace) -> np.ndarray:
    """pt's image of ``frame`` alone with ``spp`` samples (equal time)."""
    from grisx.render.driver import load_scene
    from grisx.render.pt import PathTracer

    built = load_scene(scene).build(args.device)
    built.animate_camera = camera == "moving"
    built.set_frame(float(frame))
    pt = PathTracer(built, args.res[0], args.res[1], spp=spp, max_depth=depth, seed=args.seed + 104729)
    pt.add_samples(frame, spp)
    return pt.mean()


def _pt_row(scene: str, camera: str, depth: int, args: argparse.Namespace, eval_frames: list[int], ref_for: Any) -> dict[str, Any]:
    """The baseline at another depth than the protocol's pt row (restir-di: pt at max_depth 2)."""
    kept, timing, _ = render_frames(scene, "pt", {"max_depth": depth}, 1, camera, args, eval_frames)
    sec = timing["median"]
    return {"scene": scene, "camera": camera, "method": f"pt (max_depth {depth})", "renderer": "pt", "params": {"max_depth": str(depth)},
            "max_depth": depth, "width": args.res[0], "height": args.res[1], "frames": args.frames, "eval_frames": sorted(kept),
            "frame_seconds": sec, "frame_seconds_q25": timing["q25"], "frame_seconds_q75": timing["q75"], "frames_timed": timing["frames_timed"],
            "frame_seconds_all": timing["median_all"],
            "frame_relmse": frame_relmse(kept, ref_for, depth), "gain": 1.0, "pt_spp": 1.0}


def plot(records: list[dict[str, Any]], path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = list(dict.fromkeys(r["scene"] for r in records))
    labels = [m for m in dict.fromkeys(r["method"] for r in records) if not m.startswith("pt")]
    fig, axes = plt.subplots(1, 2, figsize=(max(10.0, 2.2 * len(scenes)), 4.5), sharey=True)
    width = 0.8 / max(1, len(labels))
    x = np.arange(len(scenes))
    for ax, camera in zip(axes, CAMERAS):
        for j, lab in enumerate(labels):
            vals = [next((r.get("gain") or 0.0 for r in records if r["scene"] == s and r["method"] == lab and r["camera"] == camera), 0.0) for s in scenes]
            ax.bar(x + (j - (len(labels) - 1) / 2) * width, vals, width, label=lab)
        ax.axhline(1.0, color="k", lw=0.8)
        ax.set_yscale("log")
        ax.set_title(f"{camera} camera")
        ax.set_xticks(x, scenes, rotation=25, ha="right")
        ax.grid(True, axis="y", which="both", alpha=0.3)
    axes[0].set_ylabel("per-frame relMSE gain over pt at equal time")
    axes[0].legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--scenes", default=None, help=f"comma-separated scenes (default: {','.join(SCENES)})")
    ap.add_argument("--methods", default=",".join(METHODS), help="comma-separated label=method:k=v entries (pt first: the baseline)")
    ap.add_argument("--res", default=None, help="WxH (default 1920x1080 on CUDA, 64x36 on CPU)")
    ap.add_argument("--frames", type=int, default=32, help="frames per run (the second half is evaluated and timed)")
    ap.add_argument("--reference-spp", type=int, default=None, help="spp of each reference (default 1024 on CUDA, 256 on CPU)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--reference-cache", type=Path, default=None,
                    help="directory keeping the references between runs (valid for one tree: use a fresh one when pt or a scene changes)")
    ap.add_argument("--jobs", type=int, default=1, help="compile processes at once, one per (scene, method); the measurements run one scene at a time")
    ap.add_argument("--quick", action="store_true", help="2 scenes, 8 frames, 64x36")
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parent / "results" / "protocol")
    ap.add_argument("--scene-worker", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--warmup-worker", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    from grisx.device import resolve_device
    from grisx.render.driver import parse_res

    dev = resolve_device(args.device)
    cuda = dev.is_cuda
    args.res = parse_res(args.res or ("1920x1080" if cuda else "64x36"))
    args.reference_spp = args.reference_spp or (1024 if cuda else 256)
    if args.quick:
        args.frames = min(args.frames, 8)
    methods_text = args.methods
    args.methods = parse_methods(args.methods)
    if args.scene_worker:  # one scene in this process; records as JSON on stdout
        print(json.dumps(run_scene(args.scene_worker, args)))
        return 0
    if args.warmup_worker:  # compile every kernel the scene's measurement will use (Warp caches them on disk)
        args.res, args.frames, args.reference_spp, args.reference_cache = (16, 16), 2, 1, None
        run_scene(args.warmup_worker, args)
        return 0
    scenes = args.scenes.split(",") if args.scenes else (["cornell-box", "closed-room"] if args.quick else list(SCENES))
    start = time.perf_counter()
    records: list[dict[str, Any]] = []
    worker_args = ["--device", args.device, "--res", f"{args.res[0]}x{args.res[1]}", "--frames", str(args.frames),
                   "--reference-spp", str(args.reference_spp), "--seed", str(args.seed),
                   *(["--reference-cache", str(args.reference_cache)] if args.reference_cache else []), "--methods", methods_text]
    warm = []
    entries = [e.strip() for e in methods_text.split(",") if e.strip()]
    for scene in scenes:  # compile in parallel: one process per (scene, method), each module compiles on its own core
        for entry in entries:
            cmd = [sys.executable, __file__, *worker_args[:-2], "--methods", entry, "--warmup-worker", scene]
            warm.append(subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=os.environ))
            while sum(p.poll() is None for p in warm) >= args.jobs:
                time.sleep(0.5)
    for p in warm:
        p.wait()
    procs = []
    with tempfile.TemporaryDirectory() as tmp:
        for i, scene in enumerate(scenes):  # measure one scene at a time
            out = open(Path(tmp) / f"{i}.json", "w")
            cmd = [sys.executable, __file__, *worker_args, "--scene-worker", scene]
            procs.append((scene, subprocess.Popen(cmd, stdout=out, env=os.environ), out))
            procs[-1][1].wait()
            out.flush()
            args.out.mkdir(parents=True, exist_ok=True)  # what is measured so far survives an interrupted run
            (args.out / f"partial_{Path(scene).stem}.json").write_text((Path(tmp) / f"{i}.json").read_text())
        failed = []
        for i, (scene, p, out) in enumerate(procs):
            p.wait()
            out.close()
            if p.returncode != 0:
                failed.append(scene)
                continue
            records += json.loads((Path(tmp) / f"{i}.json").read_text())
    import warp as wp

    import grisx

    result = {
        "benchmark": "protocol",
        "device": str(dev),
        "device_name": dev.name if cuda else platform.processor() or platform.machine(),
        "versions": {"grisx": grisx.__version__, "warp": wp.config.version, "numpy": np.__version__, "python": platform.python_version()},
        "settings": {"scenes": scenes, "res": list(args.res), "frames": args.frames, "reference": f"pt, {args.reference_spp} spp at each evaluated frame's camera, the method's max_depth",
                     "reference_spp": args.reference_spp, "relmse_epsilon": 1e-2, "jitter": True, "seed": args.seed,
                     "methods": [{"label": lab, "method": m, "params": p} for lab, m, p in args.methods]},
        "failed_scenes": failed,
        "records": records,
        "seconds_total": time.perf_counter() - start,
    }
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "protocol.json").write_text(json.dumps(result, indent=2))
    plot(records, args.out / "protocol.png", f"protocol: {args.res[0]}x{args.res[1]}, {result['device_name']}")
    print(f"{'scene':12s} {'camera':7s} {'method':24s} {'ms/frame':>9s} {'(q25-q75)':>15s} {'pt-spp':>7s} {'relMSE':>9s} {'gain':>7s} {'FLIP':>6s} {'pt FLIP@t':>9s}")
    for r in records:
        g = f"{r['gain']:7.2f}" if r.get("gain") else "      -"
        fl = f"{r['frame_flip']:6.3f}" if "frame_flip" in r else "     -"
        pf = f"{r['pt_equal_time_flip']:9.3f}" if "pt_equal_time_flip" in r else "        -"
        spread = f"{1e3 * r['frame_seconds_q25']:6.2f}-{1e3 * r['frame_seconds_q75']:<6.2f}"
        print(f"{r['scene']:12s} {r['camera']:7s} {r['method']:24s} {1e3 * r['frame_seconds']:9.2f} {spread:>15s} {r.get('pt_spp', 0):7.2f} "
              f"{r['frame_relmse']:9.4g} {g} {fl} {pf}")
    if failed:
        print(f"protocol.py: scenes failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
