#!/usr/bin/env python
"""Speed-up of a reference rendered on several GPUs over one (``grisx reference --devices``).

Renders the same path-traced reference twice, each into a fresh cache under
``--out`` (``force``: nothing is read from an earlier run):

1. on the first device of ``--devices`` alone, in this process (what
   ``grisx reference --device cuda:0`` does), at ``--baseline-spp`` samples
   per pixel (default: ``--spp``);
2. on every device of ``--devices``, one worker process each, chunks of
   ``--chunk-spp`` handed to whichever worker is free, at ``--spp``.

The speed-up is the ratio of the two throughputs (spp per second of wall
time, worker start-up included in the second). Each run's per-device
throughput (chunk seconds only) is recorded too. At equal spp the two images
must be bit-for-bit equal (checked and recorded): chunks are disjoint parts
of one counter-RNG stream, merged in chunk order in float64.

Kernels are compiled before any clock starts (one tiny render per device;
the workers load them from Warp's kernel cache). Writes
``multi_gpu_reference.json`` (settings, devices, versions, seconds,
throughputs, speed-up) to ``--out`` and prints a summary.

Usage::

    python benchmarks/multi_gpu_reference.py --devices cuda:0,cuda:1 --out benchmarks/results/multi_gpu   # 1080p, 64k spp
    python benchmarks/multi_gpu_reference.py --devices cuda:0,cuda:1 --spp 4096 --out DIR              # fits a 10-minute call
    python benchmarks/multi_gpu_reference.py --devices cpu,cpu --res 64x36 --spp 8 --chunk-spp 2 --out /tmp/mg   # CPU smoke run
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # this checkout's grisx


def _one_run(scene: str, res: tuple[int, int], spp: int, chunk_spp: int, executor, cache: Path) -> tuple[float, object]:
    from grisx.render.reference import reference

    os.environ["GRISX_CACHE_DIR"] = str(cache)
    start = time.perf_counter()
    ref = reference(scene, res=res, spp=spp, seed=0, force=True, executor=executor, chunk_spp=chunk_spp)
    return time.perf_counter() - start, ref


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--devices", required=True, help="comma-separated devices, e.g. cuda:0,cuda:1 (cpu,cpu for a smoke run)")
    ap.add_argument("--out", required=True, help="output directory")
    ap.add_argument("--scene", default="door-ajar")
    ap.add_argument("--res", default="1920x1080", help="WxH (default 1920x1080)")
    ap.add_argument("--spp", type=int, default=65536, help="samples per pixel of the multi-device run (default 65536)")
    ap.add_argument("--baseline-spp", type=int, default=None, help="spp of the one-device run (default: --spp)")
    ap.add_argument("--chunk-spp", type=int, default=1024, help="samples per pixel of one chunk (default 1024)")
    args = ap.parse_args()

    import warp as wp

    import grisx
    from grisx.device import resolve_device
    from grisx.errors import GrisxError
    from grisx.executor import DeviceExecutor, InProcessExecutor, parse_devices
    from grisx.render.driver import parse_res
    from grisx.render.reference import render_chunk

    try:
        devices = parse_devices(args.devices)
        res = parse_res(args.res)
    except GrisxError as exc:
        print(f"multi_gpu_reference: error: {exc}", file=sys.stderr)
        return 2
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    base_spp = args.baseline_spp or args.spp
    for d in dict.fromkeys(devices):  # compile the kernels off the clock
        render_chunk(args.scene, 8, 8, 16, 0, 0, 1, device=d)

    t1, one = _one_run(args.scene, res, base_spp, args.chunk_spp, InProcessExecutor(devices[0]), out / "cache-one")
    with DeviceExecutor(devices) as ex:
        tn, many = _one_run(args.scene, res, args.spp, args.chunk_spp, ex, out / "cache-many")
    rate1, raten = base_spp / t1, args.spp / tn
    equal = bool(np.array_equal(one.image, many.image) and np.array_equal(one.variance, many.variance)) if base_spp == args.spp else None
    dev0 = resolve_device(devices[0])
    result = {
        "scene": args.scene, "width": res[0], "height": res[1], "spp": args.spp, "baseline_spp": base_spp,
        "chunk_spp": args.chunk_spp, "devices": devices, "device_name": getattr(dev0, "name", str(dev0)),
        "one_device": {"device": devices[0], "seconds": t1, "spp_per_second": rate1, "throughput": one.settings["throughput"]},
        "all_devices": {"seconds": tn, "spp_per_second": raten, "throughput": many.settings["throughput"]},
        "speedup": raten / rate1, "images_equal": equal,
        "timing": "wall seconds of grisx.render.reference (force, fresh cache), kernels compiled before; the multi-device "
                  "run includes starting its worker processes",
        "versions": {"grisx": grisx.__version__, "warp": wp.config.version, "numpy": np.__version__,
                     "python": platform.python_version()}, "platform": platform.platform(),
    }
    (out / "multi_gpu_reference.json").write_text(json.dumps(result, indent=1, default=str) + "\n")
    print(f"{args.scene} {res[0]}x{res[1]} on {devices[0]} ({result['device_name']}): {base_spp} spp in {t1:.1f} s "
          f"({rate1:.3g} spp/s)")
    print(f"on {','.join(devices)}: {args.spp} spp in {tn:.1f} s ({raten:.3g} spp/s) -> speed-up {raten / rate1:.2f}x"
          + ("" if equal is None else f", images {'bit-for-bit equal' if equal else 'DIFFER'}"))
    for worker, d in many.settings["throughput"].items():
        print(f"  {worker}: {d['chunks']} chunks, {d['spp']} spp, {d['spp_per_second']:.3g} spp/s")
    print(f"wrote {out / 'multi_gpu_reference.json'}")
    return 0 if equal is not False else 1


if __name__ == "__main__":
    sys.exit(main())
