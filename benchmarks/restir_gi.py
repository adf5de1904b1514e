#!/usr/bin/env python
"""ReSTIR GI against the path tracer at equal time: per-pass frame times and MSE (seed 004, Sec. 6).

For ``cornell-box``, ``door-ajar`` and ``glossy-room`` (static camera, the
scene's ``max_depth``) this script

1. renders a **reference**: the path tracer at the pixel centres
   (``jitter=False``) with ``--ref-spp`` samples. Every image of the study is
   at the pixel centres (ReSTIR GI too): a frame's error is then light
   transport alone, not the pixel filter's variance (on the Cornell box the
   light's jittered edges alone give a per-frame MSE 20× the path tracer's
   1-spp transport noise, and hide what resampling changes);
2. runs **ReSTIR GI** (unbiased, and ``unbiased=false``) for ``--frames``
   frames and records the time of each pass (device synchronized around every
   pass; kernels compiled and warmed before the clock starts), the frame time,
   the per-frame MSE averaged over the second half of the frames (the paper's
   comparison is one frame after 32 frames of temporal reuse; one frame's MSE
   is a single heavy-tailed draw, so the mean over frames 17–32 is reported)
   and the MSE of the *accumulated* frames;
3. measures the path tracer's time per sample per pixel and renders, from an
   independent seeds, the path tracer **at equal time**: as many spp as fit in
   one ReSTIR GI frame (at least 1; as many independent frames as ReSTIR GI
   frames averaged), and as many as fit in all ``--frames`` ReSTIR GI frames;
4. reports the MSE ratios PT / ReSTIR GI (> 1: ReSTIR GI is better at equal time).

The paper reports 9.3×–166× lower MSE than path tracing at equal time for the
unbiased variant (14.6×–141× biased) and 8–18 ms per 1080p frame on an RTX
3090; the JSON keeps those figures beside ours. MSE is over all pixels and
channels, against the reference; ``ref_noise`` is the reference's own mean
per-pixel variance (the floor under any MSE measured against it).

Usage::

    python benchmarks/restir_gi.py --quick              # CPU smoke test, 32×24
    python benchmarks/restir_gi.py                      # CPU, 64×48
    python benchmarks/restir_gi.py --device cuda        # GPU, 1920×1080

Writes ``restir_gi.json`` and ``restir_gi.png`` to ``--out`` (default ``benchmarks/results/``).
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
from grisx.device import resolve_device, synchronize
from grisx.errors import GrisxError
from grisx.scene.builtin import build_builtin
from grisx.render.pt import PathTracer
from grisx.render.driver import PassTimer
from grisx.render.restir_gi import ReSTIRGI

SCENES = ("cornell-box", "door-ajar", "glossy-room")
#: the unbiased (reconnections with |J| > 10 rejected, the default) and biased variants, and the paper's unbiased one (no rejection)
VARIANTS = (("unbiased", {}), ("biased", {"unbiased": False}), ("unbiased_paper", {"max_jacobian": 0.0}))
PAPER = {"mse_ratio_unbiased": [9.3, 166.0], "mse_ratio_biased": [14.6, 141.0], "frame_ms_1080p_rtx3090": [8.0, 18.0]}


def mse(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))


def reference(built: Any, w: int, h: int, max_depth: int, spp: int, seed: int) -> tuple[np.ndarray, float]:
    pt = PathTracer(built, w, h, max_depth=max_depth, seed=seed + 9973, jitter=False)
    batch = 64
    done = 0
    while done < spp:
        n = min(batch, spp - done)
        pt.add_samples(0, n)
        done += n
    return pt.mean(), float(np.mean(pt.variance_of_mean()))


def pt_seconds_per_spp(built: Any, w: int, h: int, max_depth: int, device: Any, seed: int, repeats: int) -> float:
    pt = PathTracer(built, w, h, max_depth=max_depth, seed=seed, jitter=False)
    wp.load_module(pt.kernel.module, device=device)
    pt.add_samples(0, 1)  # warm-up
    best = float("inf")
    for r in range(repeats):
        synchronize(device)
        t0 = time.perf_counter()
        pt.add_samples(r + 1, 1)
        synchronize(device)
        best = min(best, time.perf_counter() - t0)
    return best


def pt_image(built: Any, w: int, h: int, max_depth: int, spp: int, seed: int) -> np.ndarray:
    pt = PathTracer(built, w, h, max_depth=max_depth, seed=seed, jitter=False)
    pt.add_samples(0, spp)
    return pt.mean()


def pt_curve(built: Any, w: int, h: int, max_depth: int, spp_max: int, seed: int, ref: np.ndarray, spp_s: float) -> list[dict]:
    """The path tracer's accumulated MSE after 1, 2, 4, … spp (up to ``spp_max``), at the time they take (spp × ``spp_s``)."""
    pt = PathTracer(built, w, h, max_depth=max_depth, seed=seed, jitter=False)
    curve = []
    n = 1
    while True:
        pt.add_samples(0, n - pt.samples)
        curve.append({"spp": n, "seconds": n * spp_s, "mse_accumulated": mse(pt.mean(), ref)})
        if n >= spp_max:
            return curve
        n = min(2 * n, spp_max)


def run_restir(built: Any, w: int, h: int, max_depth: int, frames: int, device: Any, seed: int, ref: np.ndarray, **params: Any) -> dict:
    timer = PassTimer(device)
    gi = ReSTIRGI(built, w, h, seed=seed, max_depth=max_depth, jitter=False, timer=timer, **params)
    for k in gi.kernels():
        wp.load_module(k.module, device=device)
    gi.render_frame(0)  # warm-up (also allocates), then start afresh
    gi.reset(seed)
    timer.seconds.clear()
    acc = np.zeros((h, w, 3))
    frame_s = []
    curve = []
    last = None
    for f in range(frames):
        synchronize(device)
        t0 = time.perf_counter()
        img = gi.render_frame(f)
        synchronize(device)
        frame_s.append(time.perf_counter() - t0)
        last = img.numpy()
        acc += last
        curve.append({"frame": f + 1, "seconds": float(sum(frame_s)), "mse_accumulated": mse(acc / (f + 1), ref), "mse_frame": mse(last, ref)})
    return {
        "params": params,
        "frame_ms_mean": 1e3 * float(np.mean(frame_s)),
        "frame_ms_median": 1e3 * float(np.median(frame_s)),
        "pass_ms_per_frame": {k: 1e3 * v / frames for k, v in timer.seconds.items()},
        "total_s": float(sum(frame_s)),
        "mse_last_frame": mse(last, ref),
        # per-frame MSE averaged over the second half of the frames (temporal history built up): one frame's
        # MSE is a single, heavy-tailed draw, the mean over frames is the stable figure
        "mse_frame_tail": float(np.mean([p["mse_frame"] for p in curve[frames // 2 :]])),
        "tail_frames": frames - frames // 2,
        "mse_accumulated": mse(acc / frames, ref),
        "nonfinite_samples": gi.nonfinite_samples,
        "curve": curve,
        "last_frame": last,
        "accumulated": acc / frames,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--device", default="cpu", help="cpu, cuda or cuda:N")
    ap.add_argument("--quick", action="store_true", help="tiny films and few samples (a smoke test)")
    ap.add_argument("--size", default=None, help="WIDTHxHEIGHT (default 1920x1080 on CUDA, 64x48 on CPU, 32x24 with --quick)")
    ap.add_argument("--frames", type=int, default=32, help="ReSTIR GI frames (the paper compares frame 32)")
    ap.add_argument("--ref-spp", type=int, default=None, help="reference spp (default 1024; 128 with --quick)")
    ap.add_argument("--repeats", type=int, default=5, help="timed path-tracer frames (best kept)")
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument(
        "--mb-fraction", type=float, default=None,
        help="share of 64x32 tiles with multi-bounce paths (default 0.25 on CUDA as in the paper; 1.0 on CPU, whose tiny films hold one tile)",
    )
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="benchmarks/results")
    args = ap.parse_args(argv)
    try:
        device = resolve_device(args.device)
    except GrisxError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    cuda = str(device).startswith("cuda")
    size = args.size or ("1920x1080" if cuda else ("32x24" if args.quick else "64x48"))
    w, h = (int(v) for v in size.lower().split("x"))
    frames = 8 if args.quick and args.frames == 32 else args.frames
    ref_spp = args.ref_spp or (128 if args.quick else 1024)
    mb_fraction = args.mb_fraction if args.mb_fraction is not None else (0.25 if cuda else 1.0)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    report: dict[str, Any] = {
        "benchmark": "restir_gi",
        "device": str(device),
        "device_name": wp.get_device(device).name if hasattr(wp.get_device(device), "name") else str(device),
        "grisx": grisx.__version__,
        "warp": wp.__version__,
        "python": platform.python_version(),
        "platform": platform.platform(),
        "seed": args.seed,
        "settings": {"width": w, "height": h, "frames": frames, "ref_spp": ref_spp, "repeats": args.repeats, "quick": bool(args.quick), "mb_fraction": mb_fraction},
        "paper": PAPER,
        "scenes": {},
    }
    images = {}
    for name in args.scenes.split(","):
        scene = build_builtin(name)
        max_depth = int(scene.defaults.get("max_depth", 16))
        built = scene.build(device)
        t0 = time.perf_counter()
        ref, ref_noise = reference(built, w, h, max_depth, ref_spp, args.seed)
        ref_s = time.perf_counter() - t0
        spp_s = pt_seconds_per_spp(built, w, h, max_depth, device, args.seed + 17, args.repeats)
        entry: dict[str, Any] = {"max_depth": max_depth, "ref_seconds": ref_s, "ref_noise": ref_noise, "pt_ms_per_spp": 1e3 * spp_s, "variants": {}}
        for label, params in VARIANTS:
            r = run_restir(built, w, h, max_depth, frames, device, args.seed + 1, ref, mb_fraction=mb_fraction, **params)
            # ---- the path tracer at equal time: one ReSTIR GI frame, and all of them ----
            spp_frame = max(1, int(round(r["frame_ms_median"] / 1e3 / spp_s)))
            spp_total = max(1, int(round(r["total_s"] / spp_s)))
            pt_mses = []
            for k in range(r["tail_frames"]):  # as many independent equal-time PT frames as ReSTIR GI frames averaged
                pt_frame = pt_image(built, w, h, max_depth, spp_frame, args.seed + 1000 * (k + 1) + 31)
                pt_mses.append(mse(pt_frame, ref))
            pt_total = pt_image(built, w, h, max_depth, spp_total, args.seed + 37)
            r["pt_equal_time_frame"] = {"spp": spp_frame, "mse": float(np.mean(pt_mses)), "frames": len(pt_mses)}
            r["pt_equal_time_total"] = {"spp": spp_total, "mse": mse(pt_total, ref)}
            r["mse_ratio_frame"] = r["pt_equal_time_frame"]["mse"] / max(r["mse_frame_tail"], 1e-30)
            r["mse_ratio_total"] = r["pt_equal_time_total"]["mse"] / max(r["mse_accumulated"], 1e-30)
            images[(name, label)] = (r.pop("last_frame"), r.pop("accumulated"), pt_frame, ref)
            entry["variants"][label] = r
            print(
                f"{name:12s} {label:9s} frame {r['frame_ms_median']:9.2f} ms  "
                + " ".join(f"{k}={v:.2f}" for k, v in r["pass_ms_per_frame"].items())
                + f"\n{'':22s} MSE/frame {r['mse_frame_tail']:.3e} vs PT@{spp_frame}spp {r['pt_equal_time_frame']['mse']:.3e}"
                f" (x{r['mse_ratio_frame']:.1f});  accumulated {r['mse_accumulated']:.3e} vs PT@{spp_total}spp"
                f" {r['pt_equal_time_total']['mse']:.3e} (x{r['mse_ratio_total']:.1f});  ref noise {ref_noise:.1e}",
                flush=True,
            )
        spp_max = max(v["pt_equal_time_total"]["spp"] for v in entry["variants"].values())
        entry["pt_curve"] = pt_curve(built, w, h, max_depth, spp_max, args.seed + 41, ref, spp_s)
        report["scenes"][name] = entry
    (out / "restir_gi.json").write_text(json.dumps(report, indent=2))
    _plot(report, images, out / "restir_gi.png")
    print(f"wrote {out / 'restir_gi.json'} and {out / 'restir_gi.png'}")
    return 0


def _plot(report: dict, images: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    from grisx.imageio import srgb_encode

    names = list(report["scenes"])
    fig, axes = plt.subplots(len(names), 5, figsize=(17, 3.2 * len(names)), squeeze=False)
    for i, name in enumerate(names):
        last, _acc, pt_frame, ref = images[(name, "unbiased")]
        v = report["scenes"][name]["variants"]["unbiased"]
        scale = 1.0 / max(float(np.percentile(ref, 99)), 1e-6)
        for j, (img, title) in enumerate(
            (
                (pt_frame, f"PT {v['pt_equal_time_frame']['spp']} spp (equal time)\nmean MSE/frame {v['pt_equal_time_frame']['mse']:.2e}"),
                (last, f"ReSTIR GI frame {report['settings']['frames']}\nMSE {v['mse_last_frame']:.2e} (mean/frame {v['mse_frame_tail']:.2e})"),
                (ref, f"reference ({report['settings']['ref_spp']} spp)"),
            )
        ):
            axes[i, j].imshow(np.clip(srgb_encode(np.clip(img * scale, 0, 1)), 0, 1))
            axes[i, j].set_title(f"{name}: {title}", fontsize=8)
            axes[i, j].axis("off")
        ax = axes[i, 3]
        for label, _ in VARIANTS:
            c = report["scenes"][name]["variants"][label]["curve"]
            ax.loglog([p["seconds"] for p in c], [p["mse_accumulated"] for p in c], label=f"ReSTIR GI {label} (accumulated)")
        c = report["scenes"][name]["pt_curve"]
        ax.loglog([p["seconds"] for p in c], [p["mse_accumulated"] for p in c], "k--", label="path tracer (accumulated spp)")
        ax.axhline(report["scenes"][name]["ref_noise"], color="gray", ls=":", label="reference noise")
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_xlabel("seconds")
        ax.set_ylabel("MSE")
        ax.legend(fontsize=6)
        ax = axes[i, 4]
        ms = report["scenes"][name]["variants"]["unbiased"]["pass_ms_per_frame"]
        ax.barh(list(ms), list(ms.values()))
        ax.set_xlabel("ms per frame")
        ax.tick_params(labelsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
