#!/usr/bin/env python
"""BVH build, refit, primary-ray and G-buffer times of the scene layer.

For each scene — ``cornell-box`` (36 triangles) and a synthetic scene of
``--triangles`` random triangles (default 1 M; small random triangles in a
unit box, as in Warp's own ray-casting benchmarks) — this script measures on
one device:

* ``bvh_build_ms``: ``Scene.build`` of the mesh alone (``wp.Mesh`` construction,
  device synchronized), best of ``--repeats``;
* ``refit_ms``: ``wp.Mesh.refit`` after moving the vertices (rigid motion);
* ``primary_rays_per_s``: one closest-hit query per pixel through
  :func:`grisx.scene.scene.intersect` at the film size, best of ``--repeats``
  launches (module loaded and warmed first, device synchronized);
* ``gbuffer_ms``: a full :meth:`GBuffer.fill` (primary hit + material, albedo,
  roughness, emission and motion vectors) at the film size.

Anchors measured on these machines (issue 3): Warp's BVH on an H200 casts
about 12 G primary rays/s on a 12-triangle box and 0.3–1 G rays/s on 1 M
random triangles; one CPU core about 0.7 M rays/s.

Usage::

    python benchmarks/scene.py                       # CPU, 1920×1080 (about a minute)
    python benchmarks/scene.py --quick               # CPU, 320×180, 100 k triangles
    python benchmarks/scene.py --device cuda         # GPU

Writes ``scene.json`` and ``scene.png`` to ``--out`` (default ``benchmarks/results/``).
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
from grisx.scene.camera import Camera, CameraData, camera_ray, lookat
from grisx.scene.gbuffer import GBuffer, make_gbuffer_kernel
from grisx.scene.material import Diffuse
from grisx.scene.scene import Film, Scene, SceneData, intersect

wp.set_module_options({"enable_backward": False})


@wp.kernel
def primary_rays(scene: SceneData, cam: CameraData, t_out: wp.array2d(dtype=float)):
    y, x = wp.tid()
    ray = camera_ray(cam, float(x) + 0.5, float(y) + 0.5, wp.vec2(0.5, 0.5))
    si = intersect(scene, ray.o, ray.d, 1.0e30)
    t_out[y, x] = wp.where(si.valid != 0, si.t, -1.0)


def random_triangles(n: int, seed: int = 0) -> Scene:
    """``n`` small random triangles in the unit box, lit by a constant sky, seen from outside."""
    from grisx.scene.lights import ConstantEnvironment

    rng = np.random.default_rng(seed)
    centres = rng.uniform(-1, 1, size=(n, 1, 3))
    size = 2.0 / n ** (1 / 3)  # triangles about the spacing of their centres
    verts = (centres + rng.normal(scale=size, size=(n, 3, 3))).reshape(-1, 3)
    s = Scene(f"random-{n}")
    m = s.add_material(Diffuse(0.6))
    s.add_mesh(verts, np.arange(3 * n).reshape(n, 3), material=m)
    s.set_environment(ConstantEnvironment(1.0))
    s.set_camera(Camera(to_world=lookat((0, 0, 3.5), (0, 0, 0), (0, 1, 0)), fov=45))
    s.film = Film(640, 360)
    return s


def best_of(repeats: int, device: Any, fn: Any) -> float:
    times = []
    for _ in range(repeats):
        synchronize(device)
        t0 = time.perf_counter()
        fn()
        synchronize(device)
        times.append(time.perf_counter() - t0)
    return min(times)


def measure(scene: Scene, width: int, height: int, device: Any, repeats: int) -> dict[str, Any]:
    built = scene.build(device)
    tris = built.num_triangles
    # BVH build alone: a fresh wp.Mesh over the uploaded points
    build_s = best_of(repeats, device, lambda: wp.Mesh(points=built.positions, indices=built.indices))
    refit_s = best_of(repeats, device, built.mesh.refit)
    cam = built.camera_data(0.0, width, height)
    t_out = wp.zeros((height, width), dtype=float, device=device)
    for kernel in (primary_rays, make_gbuffer_kernel(built.features.kernel_kinds)):
        wp.load_module(kernel.module, device=device)
    wp.launch(primary_rays, dim=(height, width), inputs=[built.data, cam, t_out], device=device)  # warm-up
    cast_s = best_of(repeats, device, lambda: wp.launch(primary_rays, dim=(height, width), inputs=[built.data, cam, t_out], device=device))
    hits = float((t_out.numpy() > 0).mean())
    g = GBuffer(width, height, device)
    g.fill(built, 0.0)
    gbuf_s = best_of(repeats, device, lambda: g.fill(built, 0.0))
    return {
        "scene": scene.name,
        "triangles": tris,
        "width": width,
        "height": height,
        "hit_fraction": hits,
        "bvh_build_ms": build_s * 1e3,
        "refit_ms": refit_s * 1e3,
        "primary_ms": cast_s * 1e3,
        "primary_rays_per_s": width * height / cast_s,
        "gbuffer_ms": gbuf_s * 1e3,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--res", default=None, help="WxH (default 1920x1080, 320x180 with --quick)")
    ap.add_argument("--triangles", type=float, default=None, help="random-triangle count (default 1e6, 1e5 with --quick)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results"))
    args = ap.parse_args(argv)
    try:
        device = resolve_device(args.device)
    except GrisxError as exc:
        print(f"scene.py: error: {exc}", file=sys.stderr)
        return 2
    w, h = (int(v) for v in (args.res or ("320x180" if args.quick else "1920x1080")).split("x"))
    n = int(args.triangles or (1e5 if args.quick else 1e6))
    rows = [measure(build_builtin("cornell-box"), w, h, device, args.repeats), measure(random_triangles(n), w, h, device, args.repeats)]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    meta = {
        "device": str(device),
        "device_name": device.name if hasattr(device, "name") else str(device),
        "grisx": grisx.__version__,
        "warp": wp.__version__,
        "python": platform.python_version(),
        "machine": platform.machine(),
        "repeats": args.repeats,
    }
    (out / "scene.json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=2))
    print(f"device {meta['device_name']}  film {w}x{h}")
    print(f"{'scene':<16}{'triangles':>10}{'build ms':>10}{'refit ms':>10}{'rays/s':>12}{'primary ms':>12}{'gbuffer ms':>12}")
    for r in rows:
        print(f"{r['scene']:<16}{r['triangles']:>10}{r['bvh_build_ms']:>10.2f}{r['refit_ms']:>10.2f}{r['primary_rays_per_s']:>12.3g}"
              f"{r['primary_ms']:>12.3f}{r['gbuffer_ms']:>12.3f}")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(9, 3.4))
    names = [f"{r['scene']}\n{r['triangles']:,} tris" for r in rows]
    ax[0].bar(names, [r["primary_rays_per_s"] for r in rows], color="#4878a8")
    ax[0].set_yscale("log")
    ax[0].set_ylabel("primary rays / s")
    ax[1].bar(names, [r["gbuffer_ms"] for r in rows], color="#a86448")
    ax[1].set_ylabel(f"G-buffer ms at {w}x{h}")
    fig.suptitle(f"grisx scene layer on {meta['device_name']}")
    fig.tight_layout()
    fig.savefig(out / "scene.png", dpi=120)
    return 0


if __name__ == "__main__":
    sys.exit(main())
