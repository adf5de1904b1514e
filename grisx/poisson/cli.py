"""``grisx poisson``: screened Poisson reconstruction of EXR buffers.

::

    grisx poisson --primal P.exr --dx DX.exr --dy DY.exr [--norm L1|L2] [--alpha 0.2]
                  [--preset fast|default|high|classic] [--solver auto|dct|cg|irls]
                  [--device cpu|cuda] --out I.exr [--json]

The three inputs follow the conventions of :mod:`grisx.poisson.gradient`
(``dx[y, x] = I[y, x+1] - I[y, x]``, same size as the primal, last column of
``dx`` / last row of ``dy`` ignored). ``--json`` prints one JSON object with
``output``, ``norm``, ``alpha``, ``solver``, ``preset`` (L1), ``device``,
``width``, ``height``, ``channels``, ``seconds``, ``residual``,
``iterations``, ``outer_iterations`` and ``energy``. Errors are
:class:`~grisx.errors.GrisxError` and propagate to the caller (``grisx``'s
``main`` prints them on one line); the output file is written only after a
successful solve.
"""

from __future__ import annotations

import argparse
import math
from typing import Any

from grisx.imageio import read_exr, write_exr
from grisx.poisson.l1 import L1_PRESETS
from grisx.poisson.reconstruct import NORMS, SOLVERS, solve

__all__ = ["add_parser", "run"]


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Register the ``poisson`` subcommand on an argparse ``subparsers`` object."""
    p = subparsers.add_parser(
        "poisson",
        help="screened Poisson reconstruction (L2/L1) from primal and gradient EXRs",
        description="Reconstruct an image from a primal image and its forward-difference "
                    "gradients dx[y,x] = I[y,x+1] - I[y,x], dy[y,x] = I[y+1,x] - I[y,x] "
                    "(screened Poisson, Neumann boundaries).",
    )
    p.add_argument("--primal", required=True, help="primal image (EXR)")
    p.add_argument("--dx", required=True, help="horizontal gradient image (EXR, same size)")
    p.add_argument("--dy", required=True, help="vertical gradient image (EXR, same size)")
    p.add_argument("--out", required=True, help="output image (EXR)")
    p.add_argument("--norm", default="L2", type=str.upper, choices=NORMS, help="reconstruction norm (default L2)")
    p.add_argument("--alpha", default=0.2, type=float, help="weight of the primal term, > 0 (default 0.2)")
    p.add_argument("--preset", default="default", choices=tuple(L1_PRESETS),
                   help="L1 IRLS schedule (reweightings x CG iterations): fast (5x4), default (20x5), high (50x8) with multigrid CG; classic (20x50) with Jacobi CG")
    p.add_argument("--solver", default="auto", choices=SOLVERS,
                   help="auto: DCT on CPU / CG on CUDA for L2, IRLS for L1")
    p.add_argument("--device", default="cpu", help="cpu, cuda or cuda:N (default cpu)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(handler=run)
    return p


def _number(v: float) -> float | None:
    # JSON has no NaN; report an unmeasured quantity as null.
    return None if not math.isfinite(v) else v


def run(args: argparse.Namespace) -> int:
    """Read the EXRs, reconstruct, write ``--out``; return the exit code (0)."""
    primal = read_exr(args.primal)
    dx = read_exr(args.dx)
    dy = read_exr(args.dy)
    result = solve(primal, dx, dy, alpha=args.alpha, norm=args.norm, device=args.device,
                   solver=args.solver, preset=args.preset)
    out = write_exr(args.out, result.image)
    h, w = primal.shape[:2]
    report = {
        "output": str(out),
        "norm": result.norm,
        "alpha": result.alpha,
        "solver": result.solver,
        "preset": args.preset if result.norm == "L1" else None,
        "device": result.device,
        "width": w,
        "height": h,
        "channels": 1 if primal.ndim == 2 else primal.shape[2],
        "seconds": result.seconds,
        "residual": _number(result.residual),
        "iterations": result.iterations,
        "outer_iterations": result.outer_iterations,
        "energy": _number(result.energy),
    }
    if args.json:
        from grisx.eval.files import json_line

        print(json_line(report))
    else:
        print(f"wrote {out} ({w}x{h}, {result.norm} {result.solver} on {result.device}, "
              f"{result.seconds * 1e3:.1f} ms, relative residual {result.residual:.2e})")
    return 0
