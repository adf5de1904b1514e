#!/usr/bin/env python
"""Every built-in scene with every ReSTIR renderer: does each one render, finite, on this device?

Every renderer issue asks that its methods render every built-in scene on CPU
and on CUDA: every registered radiance method but ``pt`` (ReSTIR PT with each
of its three shifts), a method registered later included. This script
renders ``--frames`` frames of each (scene, method) along the scene's camera
path (``camera="auto"``: the path where the scene has one) and records for
each: the count of NaN/Inf samples the renderer dropped (0 expected), whether
the last frame is finite, its mean, and the wall time (on CUDA mostly kernel
compilation, which the first scene with a given set of material kinds pays).

Compilation dominates on CUDA (minutes per material-kind set for ReSTIR GI),
so ``--jobs N`` renders N scenes at once in separate processes; Warp's kernel
cache is shared between them. A worker that dies (a CUDA fault poisons its context) is
relaunched for the methods after the one it died on; that one is reported under ``failed``,
and the exit status is 1.

Usage::

    python benchmarks/restir_every_scene.py --device cuda --jobs 9
    python benchmarks/restir_every_scene.py --scenes cornell-box,pool      # CPU

Writes ``restir_every_scene.json`` and a contact sheet ``restir_every_scene.png``
(one row per scene, one column per method; the last frame, exposure by the
scene's 99th percentile) to ``--out``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

#: ReSTIR PT once per shift; every other radiance method of the registry once with its defaults (added later: joins by itself)
RESTIR_PT_SHIFTS = ("hybrid", "reconnection", "replay")


def every_method() -> tuple[tuple[str, str, dict[str, Any]], ...]:
    """(label, method, params) of every reuse renderer registered (the path tracer is the reference: left out)."""
    from grisx.render.base.registry import METHODS, load_plugins

    load_plugins()
    rows = []
    for name in sorted(n for n, m in METHODS.items() if m.kind == "radiance" and n != "pt"):
        if name == "restir-pt":
            rows += [(f"restir-pt {shift}", name, {"shift": shift}) for shift in RESTIR_PT_SHIFTS]
        else:
            rows.append((name, name, {}))
    return tuple(rows)


METHODS = every_method()


def render_scene(scene: str, device: str, res: tuple[int, int], frames: int, out: Path,
                 methods: tuple[tuple[str, str, dict[str, Any]], ...] = METHODS) -> dict[str, Any]:
    """Render ``scene`` with every method; save each last frame as .npy for the contact sheet.

    The rows so far are rewritten to ``out/SCENE.json`` after every render, so a run that is cut
    short (a device call's time limit) keeps what it measured.
    """
    from grisx.render.driver import render

    rows_file = out / f"{scene}.json"
    rows = json.loads(rows_file.read_text()) if rows_file.exists() else {}  # a relaunch after a crash appends
    for label, method, params in methods:
        t0 = time.perf_counter()
        r = render(scene, method, frames=frames, res=res, device=device, seed=1, params=params, camera="auto")
        img = np.asarray(r.image, dtype=np.float32)
        np.save(out / f"{scene}__{label.replace(' ', '_')}.npy", img)
        rows[f"{scene} {label}"] = {
            "nonfinite_samples": int(r.settings.get("nonfinite_samples", 0)),
            "finite": bool(np.isfinite(img).all()),
            "mean": float(img.mean()),
            "wall_s": round(time.perf_counter() - t0, 1),
            "frames": frames,
            "camera": r.settings["camera"],
        }
        print(f"{scene:20s} {label:24s} nonfinite {rows[f'{scene} {label}']['nonfinite_samples']}  mean {img.mean():.4f}"
              f"  {rows[f'{scene} {label}']['wall_s']:.1f} s", flush=True)
        rows_file.write_text(json.dumps(rows, indent=1))
    return rows


def contact_sheet(scenes: list[str], methods, out: Path, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from grisx.imageio import srgb_encode

    fig, axes = plt.subplots(len(scenes), len(methods), figsize=(2.6 * len(methods), 2.1 * len(scenes)), squeeze=False)
    for i, scene in enumerate(scenes):
        files = [out / f"{scene}__{label.replace(' ', '_')}.npy" for label, _, _ in methods]
        imgs = [np.load(f) if f.exists() else None for f in files]  # None: a render that did not finish
        done = [im.ravel() for im in imgs if im is not None]
        scale = 1.0 / max(float(np.percentile(np.concatenate(done), 99)), 1e-6)
        for j, ((label, _, _), img) in enumerate(zip(methods, imgs)):
            ax = axes[i, j]
            if img is not None:
                ax.imshow(np.clip(srgb_encode(np.clip(img * scale, 0.0, 1.0)), 0.0, 1.0))
            ax.set_xticks([])
            ax.set_yticks([])
            if i == 0:
                ax.set_title(label, fontsize=9)
            if j == 0:
                ax.set_ylabel(scene, fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=60)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--scenes", default=None, help="comma-separated built-in scenes (default: all)")
    ap.add_argument("--res", default=None, help="WxH (default 320x240 on CUDA, 48x36 on CPU)")
    ap.add_argument("--methods", default=None, help="comma-separated labels (default: all, e.g. 'restir-pt hybrid,restcv')")
    ap.add_argument("--frames", type=int, default=4)
    ap.add_argument("--jobs", type=int, default=1, help="scenes rendered at once, in separate processes")
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parent / "results")
    ap.add_argument("--one", action="store_true", help=argparse.SUPPRESS)  # worker mode: one scene, JSON on stdout
    args = ap.parse_args(argv)
    from grisx.device import resolve_device
    from grisx.errors import GrisxError
    from grisx.scene.builtin import BUILTIN_SCENES
    from grisx.render.driver import parse_res

    try:
        dev = resolve_device(args.device)
        res = parse_res(args.res or ("320x240" if dev.is_cuda else "48x36"))
    except GrisxError as exc:
        print(f"restir_every_scene.py: error: {exc}", file=sys.stderr)
        return 2
    scenes = args.scenes.split(",") if args.scenes else list(BUILTIN_SCENES)
    methods = METHODS
    if args.methods:
        wanted = args.methods.split(",")
        unknown = sorted(set(wanted) - {label for label, _, _ in METHODS})
        if unknown:
            print(f"restir_every_scene.py: error: unknown method label(s) {', '.join(unknown)}; "
                  f"known: {', '.join(label for label, _, _ in METHODS)}", file=sys.stderr)
            return 2
        methods = tuple(m for m in METHODS if m[0] in wanted)
    frames_dir = args.out / "restir_every_scene_frames"
    frames_dir.mkdir(parents=True, exist_ok=True)
    if args.one:
        render_scene(scenes[0], args.device, res, args.frames, frames_dir, methods)
        return 0
    rows: dict[str, Any] = {}
    failed: dict[str, str] = {}
    start = time.perf_counter()
    labels = [label for label, _, _ in methods]
    # (scene, the labels still to render): a worker that dies (a CUDA fault poisons its context) is
    # relaunched for the labels after the one it died on, which is recorded as failed
    pending = [(scene, labels) for scene in scenes]
    for scene in scenes:
        (frames_dir / f"{scene}.json").unlink(missing_ok=True)
    running: list[subprocess.Popen] = []
    while pending or running:
        while pending and len(running) < max(1, args.jobs):
            scene, todo = pending.pop(0)
            cmd = [sys.executable, __file__, "--one", "--device", args.device, "--scenes", scene, "--res", f"{res[0]}x{res[1]}",
                   "--frames", str(args.frames), "--out", str(args.out), "--methods", ",".join(todo)]
            running.append(subprocess.Popen(cmd))  # its lines go straight to our stdout, as they come
            running[-1].job = (scene, todo)
        done = [p for p in running if p.poll() is not None]
        for p in done:
            running.remove(p)
            scene, todo = p.job
            rows_file = frames_dir / f"{scene}.json"
            scene_rows = json.loads(rows_file.read_text()) if rows_file.exists() else {}
            rows.update(scene_rows)
            left = [label for label in todo if f"{scene} {label}" not in scene_rows]
            if p.returncode != 0 and left:
                failed[f"{scene} {left[0]}"] = f"the worker exited with code {p.returncode} during this render"
                print(f"restir_every_scene.py: {scene} {left[0]} failed (exit code {p.returncode}); "
                      f"{len(left) - 1} method(s) left, relaunched", file=sys.stderr, flush=True)
                if left[1:]:
                    pending.append((scene, left[1:]))
        time.sleep(0.5)
    report = {
        "benchmark": "restir_every_scene",
        "device": str(dev),
        "res": list(res),
        "frames": args.frames,
        "wall_s": round(time.perf_counter() - start, 1),
        "all_finite": all(r["finite"] and r["nonfinite_samples"] == 0 for r in rows.values()) and len(rows) == len(scenes) * len(methods),
        "failed": failed,
        "methods": [label for label, _, _ in methods],
        "renders": rows,
    }
    (args.out / "restir_every_scene.json").write_text(json.dumps(report, indent=2))
    contact_sheet([s for s in scenes if any(k.startswith(s + " ") for k in rows)], methods, frames_dir, args.out / "restir_every_scene.png")
    print(f"{len(rows)} renders, all finite: {report['all_finite']}; wrote {args.out / 'restir_every_scene.json'} and .png")
    return 0 if report["all_finite"] else 1


if __name__ == "__main__":
    sys.exit(main())
