"""Benchmark: screened Poisson reconstruction, time against residual, L2 and each L1 preset.

Runs :func:`grisx.poisson.solve` on a synthetic gradient-domain frame (default
1920×1080 RGB) and records, per solver, the wall time (median over repeats,
device synchronised before the clock stops; input checks and layout
conversion included, the post-hoc diagnostics excluded), CG iterations, the
final relative residual of the last linear system, the energy, the RMS error
against the ground truth and, for L2, the max difference from the exact
CPU DCT solution.

The frame: a ground-truth image of smooth shading, hard-edged rectangles and
fine texture; primal = truth + Gaussian noise (σ = 0.1); gradients = ∇truth +
Gaussian noise (σ = 0.02) + sparse outliers (0.1 % of entries, ±2), the mix a
gradient-domain renderer produces (noisy primal, cleaner gradients, a few
shift-mapping failures). On CUDA the inputs are Warp arrays already on the
device, as a renderer would pass its buffers; on the CPU they are numpy arrays.

Then what a renderer pays per frame (``per_frame`` in the JSON): a
:class:`grisx.poisson.ScreenedPoisson` bound to three device buffers, each call
on a new frame (four noise seeds in turn, copied into the buffers outside the
clock), for L2 with each CG preconditioner (and multigrid at ``FRAME_TOL``, where the
renderers' :class:`~grisx.poisson.FrameReconstruction` stops) and every L1 preset: median ms,
CG iterations, and the true residual and energy of the last call.

Anchors: seed 000 (Wang et al., G-PT, Sec. 5) reports 11 ms (L2) and 300 ms (L1)
at 1080p on an RTX 5090.

Usage::

    python benchmarks/poisson.py --device cuda --out benchmarks/results/poisson
    python benchmarks/poisson.py --device cpu --size 480x270 --out /tmp/pb
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

try:
    import grisx
except ImportError:  # run from a checkout without installing
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    import grisx

import scipy
import warp as wp

from grisx.device import resolve_device, synchronize
from grisx.poisson import DEFAULT_TOL, FRAME_TOL, L1_PRESETS, ScreenedPoisson, forward_gradient, solve

PAPER_ANCHORS = {"gpu": "NVIDIA RTX 5090", "L2_ms": 11.0, "L1_ms": 300.0, "source": "seed 000, Sec. 5"}


@dataclass(frozen=True)
class Frame:
    truth: np.ndarray
    primal: np.ndarray
    dx: np.ndarray
    dy: np.ndarray


@dataclass(frozen=True)
class Row:
    solver: str
    norm: str
    preset: str | None
    seconds: float  # median over repeats
    seconds_all: list[float]
    iterations: int
    outer_iterations: int
    residual: float
    energy: float
    rmse_truth: float
    max_diff_exact_l2: float | None


def make_frame(width: int, height: int, channels: int, seed: int) -> Frame:
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float64)
    u, v = xx / max(width - 1, 1), yy / max(height - 1, 1)
    truth = np.empty((height, width, channels))
    for c in range(channels):
        img = 0.4 + 0.25 * np.sin(2 * np.pi * (u * (1.5 + c) + 0.3 * v)) * np.cos(2 * np.pi * v)
        for _ in range(12):  # hard edges
            x0, y0 = rng.integers(0, width), rng.integers(0, height)
            x1, y1 = x0 + rng.integers(width // 20 + 1, width // 4 + 2), y0 + rng.integers(height // 20 + 1, height // 4 + 2)
            img[y0:y1, x0:x1] += rng.uniform(-0.3, 0.6)
        img += 0.03 * np.sin(0.9 * xx + 0.4 * c) * np.sin(0.7 * yy)  # fine texture
        truth[:, :, c] = img
    g = forward_gradient(truth)
    primal = truth + 0.1 * rng.standard_normal(truth.shape)
    dx = g.dx + 0.02 * rng.standard_normal(truth.shape)
    dy = g.dy + 0.02 * rng.standard_normal(truth.shape)
    for d in (dx, dy):  # sparse outliers: failed shift maps
        mask = rng.random(truth.shape) < 1e-3
        d[mask] += rng.choice([-2.0, 2.0], size=int(mask.sum()))
    f32 = lambda a: np.ascontiguousarray(a, dtype=np.float32)  # noqa: E731
    return Frame(truth=f32(truth), primal=f32(primal), dx=f32(dx), dy=f32(dy))


def _configs(device: str) -> list[dict]:
    l2 = [dict(norm="L2", solver="dct"), dict(norm="L2", solver="cg")] if device == "cpu" else [dict(norm="L2", solver="cg")]
    return l2 + [dict(norm="L1", solver="irls", preset=name) for name in L1_PRESETS]


def run(args: argparse.Namespace) -> dict:
    width, height = (int(s) for s in args.size.lower().split("x"))
    dev = resolve_device(args.device)
    frame = make_frame(width, height, args.channels, args.seed)
    exact = solve(frame.primal, frame.dx, frame.dy, alpha=args.alpha, solver="dct", device="cpu").image
    if dev.is_cuda:
        inputs = [wp.array(a, dtype=wp.float32, device=dev) for a in (frame.primal, frame.dx, frame.dy)]
    else:
        inputs = [frame.primal, frame.dx, frame.dy]
    # Compile the kernels outside the clocks (a tiny solve per configuration).
    tiny = make_frame(8, 8, args.channels, 0)
    for cfg in _configs(args.device):
        solve(tiny.primal, tiny.dx, tiny.dy, device=str(dev), outer_iterations=1, inner_iterations=1, **cfg)

    rows: list[Row] = []
    for cfg in _configs(args.device):
        times, result = [], None
        for rep in range(args.warmup + args.repeats):
            synchronize(dev)
            result = solve(*inputs, alpha=args.alpha, device=str(dev), tol=args.tol, **cfg)
            if rep >= args.warmup:
                times.append(result.seconds)
        image = result.image.numpy() if isinstance(result.image, wp.array) else result.image
        rmse = float(np.sqrt(np.mean((image.astype(np.float64) - frame.truth) ** 2)))
        diff = float(np.abs(image - exact).max()) if cfg["norm"] == "L2" else None
        rows.append(Row(solver=cfg["solver"], norm=cfg["norm"], preset=cfg.get("preset"),
                        seconds=statistics.median(times), seconds_all=times, iterations=result.iterations,
                        outer_iterations=result.outer_iterations, residual=result.residual,
                        energy=result.energy, rmse_truth=rmse, max_diff_exact_l2=diff))
        print(f"  done {cfg}", file=sys.stderr, flush=True)

    per_frame = run_per_frame(args, dev, width, height)
    return {
        "benchmark": "poisson",
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "device": {"name": args.device, "warp_device": str(dev), "description": dev.name,
                   "host": platform.node(), "cpu": platform.processor() or platform.machine()},
        "versions": {"python": platform.python_version(), "numpy": np.__version__, "scipy": scipy.__version__,
                     "warp": wp.config.version, "grisx": grisx.__version__},
        "size": {"width": width, "height": height, "channels": args.channels},
        "settings": {"alpha": args.alpha, "tol": args.tol, "seed": args.seed, "repeats": args.repeats,
                     "warmup": args.warmup, "check_finite": True,
                     "input": "wp.array on device" if dev.is_cuda else "numpy",
                     "frame": "smooth+edges+texture; primal σ=0.1, gradient σ=0.02, 0.1% outliers ±2"},
        "paper_anchors": PAPER_ANCHORS,
        "results": [asdict(r) for r in rows],
        "per_frame": per_frame,
    }


def run_per_frame(args: argparse.Namespace, dev: wp.Device, width: int, height: int) -> list[dict]:
    """The persistent system a renderer keeps, a new frame each call (module docstring)."""
    frames = [make_frame(width, height, args.channels, args.seed + k) for k in range(4)]
    dtype = wp.vec3 if args.channels == 3 else wp.float32
    shape = (height, width) if args.channels == 3 else (height, width, args.channels)
    staged = [[wp.array(a.reshape(shape + ((3,) if args.channels == 3 else ())), dtype=dtype, device=dev) for a in (f.primal, f.dx, f.dy)]
              for f in frames]
    buffers = [wp.zeros(shape, dtype=dtype, device=dev) for _ in range(3)]
    rows = []
    configs = [dict(norm="L2", preconditioner="jacobi"), dict(norm="L2", preconditioner="multigrid")]
    configs += [dict(norm="L2", preconditioner="multigrid", tol=FRAME_TOL)]  # what FrameReconstruction stops at
    configs += [dict(norm="L1", preset=name) for name in L1_PRESETS]
    for cfg in configs:
        system = ScreenedPoisson(*buffers, alpha=args.alpha, **{"tol": args.tol, **cfg})
        times = []
        for k in range(args.warmup + max(args.repeats, 4)):
            for dst, src in zip(buffers, staged[k % 4]):
                wp.copy(dst, src)
            synchronize(dev)
            t0 = time.perf_counter()
            system.solve()
            synchronize(dev)
            if k >= args.warmup:
                times.append(time.perf_counter() - t0)
        m = system.measure()
        rows.append(dict(cfg, seconds=statistics.median(times), seconds_all=times, iterations=system.iterations,
                         residual=m.residual, energy=m.energy_l1 if cfg["norm"] == "L1" else m.energy_l2))
        print(f"  done per-frame {cfg}", file=sys.stderr, flush=True)
    return rows


def print_table(report: dict) -> None:
    s = report["size"]
    print(f"\nscreened Poisson, {s['width']}x{s['height']}x{s['channels']} on {report['device']['description']} "
          f"(warp {report['versions']['warp']}, median of {report['settings']['repeats']})")
    head = f"{'norm':4} {'solver':6} {'preset':8} {'ms':>10} {'CG it':>6} {'residual':>9} {'energy':>12} {'RMSE':>8} {'max|Δ| L2':>10}"
    print(head)
    print("-" * len(head))
    for r in report["results"]:
        diff = "" if r["max_diff_exact_l2"] is None else f"{r['max_diff_exact_l2']:.2e}"
        print(f"{r['norm']:4} {r['solver']:6} {r['preset'] or '-':8} {r['seconds'] * 1e3:10.2f} {r['iterations']:6d} "
              f"{r['residual']:9.2e} {r['energy']:12.5g} {r['rmse_truth']:8.4f} {diff:>10}")
    print("\nper frame (a ScreenedPoisson bound to the buffers, a new frame each call):")
    for r in report["per_frame"]:
        what = r["norm"] + " " + (r.get("preconditioner") or f"preset {r.get('preset')}") + (f" tol {r['tol']:g}" if "tol" in r else "")
        print(f"  {what:26} {r['seconds'] * 1e3:9.2f} ms  {r['iterations']:5d} CG it  residual {r['residual']:.2e}  energy {r['energy']:.6g}")
    a = report["paper_anchors"]
    print(f"anchors ({a['source']}, {a['gpu']}): L2 {a['L2_ms']} ms, L1 {a['L1_ms']} ms at 1920x1080")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--device", default="cpu", help="cpu, cuda or cuda:N")
    p.add_argument("--size", default="1920x1080", help="WIDTHxHEIGHT (default 1920x1080)")
    p.add_argument("--channels", type=int, default=3)
    p.add_argument("--alpha", type=float, default=0.2)
    p.add_argument("--tol", type=float, default=DEFAULT_TOL, help="relative residual of iterative L2")
    p.add_argument("--repeats", type=int, default=None, help="timed runs per solver (default 5 on CUDA, 1 on CPU)")
    p.add_argument("--warmup", type=int, default=None, help="untimed full-size runs first (default 1 on CUDA, 0 on CPU)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="benchmarks/results/poisson", help="directory for the JSON result")
    args = p.parse_args(argv)
    cuda = args.device.startswith("cuda")
    args.repeats = args.repeats if args.repeats is not None else (5 if cuda else 1)
    args.warmup = args.warmup if args.warmup is not None else (1 if cuda else 0)
    report = run(args)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    s = report["size"]
    path = out / f"poisson_{args.device.replace(':', '')}_{s['width']}x{s['height']}.json"
    path.write_text(json.dumps(report, indent=2))
    print_table(report)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
