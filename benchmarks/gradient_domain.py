#!/usr/bin/env python
"""Gradient-domain ReSTIR PT (seed 000) against its three baselines at equal time, moving camera.

The paper's comparison (seed 000, Sec. 5, Fig. 1, 7, 8): at 1920×1080 on the GPU, each method
gets the frame time of ours at one sample per pixel — 29.9 ms (39.8 ms with positivization) on
an RTX 5090, reconstruction included (L2 11 ms, L1 300 ms there) — and the reconstructed frames
are compared with a reference by relMSE and FLIP. Methods (``--methods``):

* ``ours`` — ``restir-gpt`` (Area ReSTIR primal, paired-pixel reservoirs, positivization, adaptive
  pair reuse), one sample per pixel;
* ``B.1`` — ``gradient-after-restir``, n independent instances whose primal and gradients are
  averaged before the reconstruction (as the paper does);
* ``B.2`` — ``gpt`` at n spp;
* ``B.3`` — ``area-restir``, n independent instances averaged (no reconstruction).

n is chosen per method from a calibration run (``--calibration-frames`` frames of one instance /
1 spp): n = max(1, round((t_ours − l2) / r)), t_ours ours' median frame time with its L2
reconstruction, r and l2 the method's render and L2 times of one instance. n instances render n
times and reconstruct once (B.3: never), so each method's frame is about t_ours.
Then every method renders ``--frames`` frames of the scene's camera path (``--camera path``; or
``static``); frame times (device synchronized; render, L2 and L1 reconstruction apart) are medians
over the frames after the first, the reconstructions being the renderers' own
(:class:`grisx.poisson.FrameReconstruction`: on a GPU a system bound to the buffers, made once); errors are measured on the last ``--eval-frames`` frames against
``pt`` at ``--ref-spp`` spp at that frame's camera: relMSE (ε = 1e-2, the reference's own
expected contribution subtracted) and HDR-FLIP of the L2 and the L1 reconstructions (B.3: of its
image) and of the primal. The ranking the paper reports: ours < B.1 < B.3 < B.2 in error.

Usage::

    python benchmarks/gradient_domain.py --device cuda --out benchmarks/results/gradient_domain    # 1920x1080, 32 frames
    python benchmarks/gradient_domain.py --device cpu --width 48 --height 27 --frames 4 --ref-spp 64   # smoke run

Writes ``gradient_domain.json`` (settings, device, versions, seeds, every record) and
``gradient_domain.png`` (relMSE and FLIP per method, L2 and L1, and the last frame's crops) to
``--out``, and prints the table.
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

sys.path.insert(0, str(Path(__file__).resolve().parent))

SCENES = ("cornell-box", "glossy-room", "metal-rack")
#: label → (render method, extra params, how n instances combine: "spp", "average-gradients" or "average-images")
METHODS = {
    "ours": ("restir-gpt", {}, "one"),
    "ours-no-positivization": ("restir-gpt", {"positivize": False}, "one"),
    "ours-no-pair-spatial": ("restir-gpt", {"pair_reuse": "off"}, "one"),  # ablations: what each pair reuse buys
    "ours-no-pair-temporal": ("restir-gpt", {"pair_temporal": False}, "one"),
    "B.1": ("gradient-after-restir", {}, "average-gradients"),
    "B.2": ("gpt", {}, "spp"),
    "B.3": ("area-restir", {}, "average-images"),
}
PAPER = {"frame_ms": 29.9, "frame_ms_positivized": 39.8, "l2_ms": 11.0, "l1_ms": 300.0, "gpu": "RTX 5090",
         "ranking": "ours < B.1 < B.3 < B.2 (error)"}


class Instances:
    """n instances of one method, rendered in lockstep; their primal/gradients (or images) averaged on the device."""

    def __init__(self, built: Any, label: str, n: int, args: argparse.Namespace) -> None:
        import warp as wp

        from grisx.render.driver import METHODS as REGISTRY
        from grisx.render.driver import RenderContext, method_params

        self.label = label
        method, extra, self.combine = METHODS[label]
        self.n = int(n)
        params = {"max_depth": args.max_depth, **extra}
        spp = self.n if self.combine == "spp" else 1
        count = 1 if self.combine in ("spp", "one") else self.n
        resolved = {**method_params(method, params), "spp": spp}
        self.renderers = [REGISTRY[method].create(RenderContext(built, args.width, args.height, dict(resolved), args.seed + 7919 * i, None, method))
                          for i in range(count)]
        for r in self.renderers:
            if hasattr(r, "reconstruct_frames"):
                r.reconstruct_frames = False  # averaged first, reconstructed once below
        self.gradient = hasattr(self.renderers[0], "gradient")
        self.wp = wp
        shape = (args.height, args.width)
        self.sum = {k: wp.zeros(shape, dtype=wp.vec3, device=built.device) for k in ("primal", "dx", "dy")}

    def frame(self, f: int) -> dict[str, Any]:
        """Render frame ``f`` with every instance; return the averaged primal, dx, dy (Warp arrays)."""
        wp = self.wp
        if len(self.renderers) == 1:
            img = self.renderers[0].render_frame(f)
            if not self.gradient:
                return {"primal": img}
            g = self.renderers[0].gradient
            return {"primal": g.primal, "dx": g.dx, "dy": g.dy}
        for a in self.sum.values():
            a.zero_()
        for r in self.renderers:
            img = r.render_frame(f)
            parts = {"primal": r.gradient.primal, "dx": r.gradient.dx, "dy": r.gradient.dy} if self.gradient else {"primal": img}
            for k, a in parts.items():
                wp.launch(_axpy, dim=a.shape, inputs=[a, 1.0 / len(self.renderers)], outputs=[self.sum[k]], device=a.device)
        return {k: self.sum[k] for k in (("primal", "dx", "dy") if self.gradient else ("primal",))}


def _make_axpy():
    import warp as wp

    @wp.kernel
    def axpy(x: wp.array2d(dtype=wp.vec3), a: float, y: wp.array2d(dtype=wp.vec3)):
        i, j = wp.tid()
        y[i, j] = y[i, j] + x[i, j] * a

    return axpy


_axpy = None


def run_method(built: Any, label: str, n: int, frames: int, eval_frames: list[int], args: argparse.Namespace) -> dict[str, Any]:
    """Render ``frames`` frames of ``n`` instances of ``label``; frame times and the evaluated frames' images."""
    from grisx.device import synchronize
    from grisx.poisson import FrameReconstruction, frame_tol

    inst = Instances(built, label, n, args)
    solvers: dict[str, Any] = {}  # per norm, bound to the instances' output buffers (the same arrays every frame)
    dev = built.device
    t_render, t_l2, t_l1 = [], [], []
    kept: dict[int, dict[str, np.ndarray]] = {}
    for f in range(frames):
        built.set_frame(float(f))
        synchronize(dev)
        t0 = time.perf_counter()
        parts = inst.frame(f)
        synchronize(dev)
        t1 = time.perf_counter()
        images = {"primal": parts["primal"]}
        if inst.gradient:
            if not solvers:  # the renderers' own reconstruction (grisx.poisson.FrameReconstruction), made once
                # as accurate as n averaged instances (or spp) need: their noise is 1/√n of one's (poisson.frame_tol)
                solvers = {norm: FrameReconstruction(parts["primal"], parts["dx"], parts["dy"], alpha=0.2, norm=norm, tol=frame_tol(n))
                           for norm in ("L2", "L1")}
            images["L2"] = solvers["L2"].solve()
            synchronize(dev)
            t2 = time.perf_counter()
            if f in eval_frames or f == 0 or not args.l1_eval_only:
                images["L1"] = solvers["L1"].solve()
                synchronize(dev)
                t_l1.append(time.perf_counter() - t2)
            t_l2.append(t2 - t1)
        t_render.append(t1 - t0)
        if f in eval_frames:
            kept[f] = {k: (v.numpy() if hasattr(v, "numpy") else np.asarray(v)).astype(np.float32) for k, v in images.items()}
    med = lambda xs: float(np.median(xs[1:] if len(xs) > 1 else xs))  # noqa: E731 (the first frame compiles)
    rec = {"label": label, "method": METHODS[label][0], "params": METHODS[label][1], "combine": METHODS[label][2], "n": n,
           "render_ms": 1e3 * med(t_render), "l2_ms": 1e3 * med(t_l2) if t_l2 else 0.0, "l1_ms": 1e3 * med(t_l1) if t_l1 else 0.0}
    rec["frame_ms_l2"] = rec["render_ms"] + rec["l2_ms"]
    rec["frame_ms_l1"] = rec["render_ms"] + rec["l1_ms"]
    rec["nonfinite_samples"] = int(sum(r.nonfinite_samples for r in inst.renderers))
    return {"record": rec, "kept": kept}


def evaluate(kept: dict[int, dict[str, np.ndarray]], ref_for: Any) -> dict[str, float]:
    """Mean relMSE (less the reference's own share) and HDR-FLIP of every kept image kind."""
    from grisx.eval.metrics import RELMSE_EPSILON, flip, relmse
    from protocol import reference_relmse

    out: dict[str, float] = {}
    kinds = sorted({k for imgs in kept.values() for k in imgs})
    for kind in kinds:
        rel, fl = [], []
        for f, imgs in kept.items():
            ref, var = ref_for(f)
            rel.append(relmse(imgs[kind], ref) - reference_relmse(ref, var, RELMSE_EPSILON))
            fl.append(flip(imgs[kind], ref))
        out[f"relmse_{kind}"] = float(np.mean(rel))
        out[f"flip_{kind}"] = float(np.mean(fl))
    return out


def run_scene(scene: str, args: argparse.Namespace) -> list[dict[str, Any]]:
    from grisx.render.driver import load_scene
    from protocol import reference_at

    sc = load_scene(scene)
    built = sc.build(args.device)
    built.animate_camera = args.camera == "path"
    eval_frames = list(range(max(1, args.frames - args.eval_frames), args.frames))
    # ---- calibration: one instance / 1 spp of each method ----
    cal = {}
    for label in args.methods:
        start = time.perf_counter()
        cal[label] = run_method(built, label, 1, args.calibration_frames, [], args)["record"]
        print(f"{scene:12s} {label:24s} calibration {cal[label]['frame_ms_l2']:8.2f} ms/frame (render {cal[label]['render_ms']:.2f}, L2 {cal[label]['l2_ms']:.2f}; "
              f"{time.perf_counter() - start:.0f} s, compilation included)", flush=True)
    target = cal[args.methods[0]]["frame_ms_l2"]
    refs: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def ref_for(f: int) -> tuple[np.ndarray, np.ndarray]:
        if f not in refs:
            ref_built = sc.build(args.device)
            ref_built.animate_camera = args.camera == "path"
            refs[f] = reference_at(ref_built, args.width, args.height, f, args.max_depth, args.ref_spp, seed=424242 + f)
        return refs[f]

    records = []
    for label in args.methods:
        # n instances (or spp) render n times and reconstruct once: the time left after one reconstruction, in renders
        c = cal[label]
        n = 1 if METHODS[label][2] == "one" else max(1, int(round((target - c["l2_ms"]) / c["render_ms"])))
        out = run_method(built, label, n, args.frames, eval_frames, args)
        rec = {"scene": scene, "camera": args.camera, "calibration_ms": c["frame_ms_l2"], "target_ms": target, **out["record"], **evaluate(out["kept"], ref_for)}
        rec["last_frame"] = out["kept"][eval_frames[-1]]
        records.append(rec)
        print(f"{scene:12s} {label:24s} n={n:<3d} frame {rec['frame_ms_l2']:8.2f} ms (L2 {rec['l2_ms']:6.2f}, L1 {rec['l1_ms']:7.2f})  "
              + "  ".join(f"{k} {v:.4f}" for k, v in rec.items() if k.startswith(("relmse_", "flip_"))), flush=True)
    records[0]["reference"] = ref_for(eval_frames[-1])[0]
    return records


def plot(records: list[dict[str, Any]], path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from grisx.eval.metrics import to_srgb

    scenes = sorted({r["scene"] for r in records}, key=[r["scene"] for r in records].index)
    fig, axes = plt.subplots(len(scenes), 3, figsize=(15, 3.6 * len(scenes)), squeeze=False)
    for row, scene in enumerate(scenes):
        rs = [r for r in records if r["scene"] == scene]
        labels = [r["label"] for r in rs]
        x = np.arange(len(rs))
        for col, metric in enumerate(("relmse", "flip")):
            ax = axes[row, col]
            for k, (kind, off) in enumerate((("L2", -0.25), ("L1", 0.0), ("primal", 0.25))):
                vals = [r.get(f"{metric}_{kind}", r.get(f"{metric}_primal") if kind != "primal" else np.nan) for r in rs]
                ax.bar(x + off, vals, width=0.25, label=kind if kind != "L2" else "L2 (B.3: its image)")
            ax.set_xticks(x, labels, rotation=20, fontsize=7)
            ax.set_title(f"{scene}: {metric} at equal time ({rs[0]['target_ms']:.1f} ms)", fontsize=9)
            ax.legend(fontsize=7)
        ax = axes[row, 2]
        crops = [to_srgb(r["last_frame"].get("L1", r["last_frame"]["primal"])) for r in rs] + [to_srgb(rs[0]["reference"])]
        ax.imshow(np.concatenate(crops, axis=1))
        ax.set_title(" | ".join(labels + ["reference"]) + " (L1)", fontsize=7)
        ax.axis("off")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--device", default="cpu")
    p.add_argument("--width", type=int, default=None, help="default: 1920 on CUDA, 64 on the CPU")
    p.add_argument("--height", type=int, default=None, help="default: 1080 on CUDA, 36 on the CPU")
    p.add_argument("--frames", type=int, default=32)
    p.add_argument("--eval-frames", type=int, default=2, help="the last frames evaluated")
    p.add_argument("--calibration-frames", type=int, default=4)
    p.add_argument("--scenes", nargs="+", default=list(SCENES))
    p.add_argument("--methods", nargs="+", default=[m for m in METHODS if not m.startswith("ours-no-pair")], choices=list(METHODS),
                   help="the first sets the equal time (default: all but the pair-reuse ablations)")
    p.add_argument("--camera", choices=("path", "static"), default="path")
    p.add_argument("--max-depth", type=int, default=8)
    p.add_argument("--ref-spp", type=int, default=1024)
    p.add_argument("--l1-every-frame", dest="l1_eval_only", action="store_false",
                   help="run (and time) the L1 reconstruction on every frame; default: on the evaluated frames only (300 ms each in the paper)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, default=Path("benchmarks/results"))
    args = p.parse_args(argv)
    import warp as wp

    import grisx
    from grisx.device import resolve_device
    from grisx.errors import GrisxError

    global _axpy
    wp.config.quiet = True
    _axpy = _make_axpy()
    cuda = args.device.startswith("cuda")
    args.width = args.width or (1920 if cuda else 64)
    args.height = args.height or (1080 if cuda else 36)
    if args.frames < 2 or args.eval_frames < 1 or args.eval_frames >= args.frames:
        p.error("need --frames >= 2 and 1 <= --eval-frames < --frames")
    try:
        dev = resolve_device(args.device)
    except GrisxError as e:
        print(f"gradient_domain.py: {e}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    records: list[dict[str, Any]] = []
    settings = {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()}

    def write_json(complete: bool) -> dict[str, Any]:
        """The JSON so far: rewritten after every scene, so a run cut short keeps the scenes it finished."""
        payload = {
            "benchmark": "gradient_domain", "settings": settings, "device": str(dev), "complete": complete,
            "device_name": wp.get_device(dev).name if cuda else platform.processor() or platform.machine(),
            "versions": {"grisx": grisx.__version__, "warp": wp.__version__, "python": platform.python_version(), "numpy": np.__version__},
            "paper": PAPER, "relmse_epsilon": 1e-2, "reference": f"pt at {args.ref_spp} spp, max_depth {args.max_depth}, at each evaluated frame's camera",
            "seconds": time.perf_counter() - t0,
            "records": [{k: v for k, v in r.items() if k not in ("last_frame", "reference")} for r in records],
        }
        tmp = args.out / "gradient_domain.json.tmp"
        tmp.write_text(json.dumps(payload, indent=2))
        tmp.replace(args.out / "gradient_domain.json")
        return payload

    for scene in args.scenes:
        records += run_scene(scene, args)
        write_json(complete=False)
    payload = write_json(complete=True)
    plot(records, args.out / "gradient_domain.png", f"gradient-domain ReSTIR PT vs B.1-B.3, equal time, {args.width}x{args.height}, {args.camera} camera, {payload['device_name']}")
    print(f"wrote {args.out / 'gradient_domain.json'} and {args.out / 'gradient_domain.png'} ({payload['seconds']:.1f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
