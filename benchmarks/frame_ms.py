#!/usr/bin/env python
"""One method's first frame (compile included, on a cold kernel cache) and its median frame time.

The A/B loop behind the "staged passes" rows run47–run49 (`benchmarks/README.md`): run it once per
tree (``PYTHONPATH``) and kernel cache (``WARP_CACHE_PATH``), cold caches side by side to time the
compile, then warm runs one at a time (before, after, before) to time the frames. Each run appends
one JSON row: ``first_frame_s`` (import excluded; with an empty cache this is the cold compile),
and with ``--frames`` > 1 the median and quartiles of ``frame_seconds`` over frames 1… and each
pass's mean milliseconds (``pass_seconds``).

    WARP_CACHE_PATH=~/wc python benchmarks/frame_ms.py glossy-room restir-pt --frames 33 --out rows.jsonl --tag after
    python benchmarks/frame_ms.py glossy-room restir-pt --opt-level 2 ...   # Warp's optimization_level (CUDA: NVRTC --Ofast-compile)
"""

from __future__ import annotations

import argparse
import json
import time

t_start = time.perf_counter()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scene")
    ap.add_argument("method")
    ap.add_argument("--frames", type=int, default=1, help="> 1: also time this many frames (the first not counted)")
    ap.add_argument("--res", default="1920x1080")
    ap.add_argument("--device", default="cuda")
    ap.add_argument("--opt-level", type=int, default=None, help="warp.config.optimization_level (default: Warp's, -O3 on CUDA)")
    ap.add_argument("--camera", default="static", help="static, or path (the scene's camera path; moving)")
    ap.add_argument("--param", action="append", default=[], help="KEY=VALUE, repeatable")
    ap.add_argument("--tag", default="", help="a label written into the row (the tree, say)")
    ap.add_argument("--out", required=True, help="JSON-lines file to append the row to")
    a = ap.parse_args()

    import numpy as np
    import warp as wp

    if a.opt_level is not None:
        wp.config.optimization_level = a.opt_level
    from grisx.render import render

    params = dict(p.split("=", 1) for p in a.param) or None
    res = tuple(int(v) for v in a.res.split("x"))
    spp = 1 if a.method == "pt" else None
    t_import = time.perf_counter()
    render(a.scene, a.method, res=res, frames=1, spp=spp, seed=1, device=a.device, params=params, camera=a.camera)
    wp.synchronize()
    row = {"tag": a.tag, "opt_level": a.opt_level, "scene": a.scene, "method": a.method, "params": params, "res": a.res, "camera": a.camera,
           "import_s": t_import - t_start, "first_frame_s": time.perf_counter() - t_import,
           "device": wp.get_device(a.device).name}
    if a.frames > 1:
        r = render(a.scene, a.method, res=res, frames=a.frames, spp=spp, seed=1, device=a.device, params=params, camera=a.camera)
        ms = np.asarray(r.frame_seconds[1:]) * 1e3
        row.update(frame_ms=float(np.median(ms)), q25=float(np.percentile(ms, 25)), q75=float(np.percentile(ms, 75)),
                   passes={k: float(v) * 1e3 / a.frames for k, v in (r.pass_seconds or {}).items()})
    with open(a.out, "a") as f:
        f.write(json.dumps(row) + "\n")
    print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
