#!/usr/bin/env python
"""Where a Suffix ReSTIR frame goes: the time of each kernel (seed 001, issue 20).

The driver's pass timer (``ms_per_pass`` in ``suffix_restir.py``) times phases; the final gather
is one phase of 2N + 1 launches. This script times every launch, the device synchronised before
and after it, so that the gather's *prefix pass* (sample a prefix, its NEE walk, the k-NN query,
fill the row) and its *MIS pass* (the Eq. 22 terms) are told apart, for a few parameter sets::

    python benchmarks/suffix_restir_passes.py --device cuda                 # 1920x1080, closed-room, N = 8
    python benchmarks/suffix_restir_passes.py --device cpu --width 64 --height 36

The synchronisation costs a little; use the totals of ``suffix_restir.py`` for frame times.
Writes ``suffix_restir_passes.json``: per variant, milliseconds per frame of each kernel.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from grisx.device import resolve_device
from grisx.errors import GrisxError
from grisx.render.driver import render

from kernels import launch_seconds  # benchmarks/kernels.py

#: (label, params) of the timed variants: the default, the paper's one borrowed suffix, no k-NN query, pairwise MIS
VARIANTS: list[tuple[str, dict[str, Any]]] = [
    ("gather_k=4", {"gather_k": 4}),
    ("gather_k=1 (the paper's, default)", {"gather_k": 1}),
    ("gather_k=0 (no k-NN query, no reuse)", {"gather_k": 0}),
    ("gather_k=4 pairwise", {"gather_k": 4, "gather_mis": "pairwise"}),
]


def time_kernels(scene: str, params: dict[str, Any], args: argparse.Namespace) -> dict[str, float]:
    """Milliseconds per frame of each kernel Suffix ReSTIR launches for ``params``."""
    with launch_seconds(lambda kernel: kernel.key.split("__")[-1]) as seconds:
        render(scene, "suffix-restir", frames=args.frames, res=(args.width, args.height), device=args.device, seed=args.seed,
               params={"prefixes": args.prefixes, "max_depth": args.max_depth, **params}, camera="path")
    return {k: 1e3 * v / args.frames for k, v in sorted(seconds.items(), key=lambda kv: -kv[1])}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--scene", default="closed-room")
    ap.add_argument("--width", type=int, default=None, help="default 1920 on CUDA, 64 on CPU")
    ap.add_argument("--height", type=int, default=None, help="default 1080 on CUDA, 36 on CPU")
    ap.add_argument("--frames", type=int, default=3)
    ap.add_argument("--prefixes", type=int, default=8)
    ap.add_argument("--max-depth", type=int, default=12, help="the paper's max path length")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results"))
    args = ap.parse_args(argv)
    try:
        dev = resolve_device(args.device)
    except GrisxError as exc:
        print(f"suffix_restir_passes.py: error: {exc}", file=sys.stderr)
        return 2
    args.device = str(dev)
    cuda = dev.is_cuda
    args.width = args.width or (1920 if cuda else 64)
    args.height = args.height or (1080 if cuda else 36)
    result = {"benchmark": "suffix_restir_passes", "device": args.device, "device_name": dev.name,
              "scene": args.scene, "width": args.width, "height": args.height, "frames": args.frames, "prefixes": args.prefixes,
              "ms_per_frame": {}}
    for label, params in VARIANTS:
        ms = time_kernels(args.scene, params, args)
        result["ms_per_frame"][label] = ms
        print(f"{label:38s} " + "  ".join(f"{k} {v:.1f}" for k, v in list(ms.items())[:4]), file=sys.stderr, flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "suffix_restir_passes.json").write_text(json.dumps(result, indent=1))
    print(f"wrote {args.out / 'suffix_restir_passes.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
