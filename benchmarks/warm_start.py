#!/usr/bin/env python
"""A warm start, phase by phase: what a fresh process spends before its first frame when the kernel cache is filled.

Issue 35 asks a warm start under 2 s. ``kernels.py --compile`` gives the whole process; this splits it: numpy's and
Warp's imports, grisx's (its ``wp.func``s and ``wp.struct``s are declared at import), Warp's start, the device's
context, the first tiny render (the renderer's kernels built and hashed, the cached modules loaded, the scene built)
and a second one (what is left once everything is loaded). Run it twice: the first run fills the cache.

    python benchmarks/warm_start.py glossy-room pt --device cuda      # prints one JSON line
    python -X importtime benchmarks/warm_start.py glossy-room pt 2> importtime.txt
"""

import time

# each import below is timed on its own, so they follow code (hence the E402 waivers)
t0 = time.perf_counter()
import argparse  # noqa: E402
import json  # noqa: E402

import numpy  # noqa: E402, F401

t_numpy = time.perf_counter()
import warp as wp  # noqa: E402

t_warp = time.perf_counter()
from grisx.device import init  # noqa: E402
from grisx.render.driver import render  # noqa: E402

t_grisx = time.perf_counter()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scene")
    ap.add_argument("method")
    ap.add_argument("--device", default="cuda")
    a = ap.parse_args()
    t1 = time.perf_counter()
    init()
    t_init = time.perf_counter()
    wp.get_device(a.device)
    wp.synchronize()
    t_ctx = time.perf_counter()
    kw = dict(scene=a.scene, method=a.method, device=a.device, res=(8, 8), frames=1, spp=1 if a.method == "pt" else None)
    render(seed=1, **kw)
    t_first = time.perf_counter()
    render(seed=2, **kw)
    t_second = time.perf_counter()
    print(json.dumps({"scene": a.scene, "method": a.method, "device": a.device, "numpy_s": t_numpy - t0, "warp_import_s": t_warp - t_numpy,
                      "grisx_import_s": t_grisx - t_warp, "wp_init_s": t_init - t1, "context_s": t_ctx - t_init,
                      "first_render_s": t_first - t_ctx, "second_render_s": t_second - t_first, "total_s": t_second - t0}))


if __name__ == "__main__":
    main()
