"""Microbenchmark: the screened Poisson mat-vec at 1080p RGB, current tiled kernel against simpler shapes."""
import os, statistics, sys, time
import numpy as np
import warp as wp
sys.path.insert(0, os.getcwd())
wp.config.quiet = True
from grisx.poisson import operators as ops
dev = os.environ.get("DEV", "cuda:0")
W, H, C = int(os.environ.get("W", 1920)), int(os.environ.get("H", 1080)), 3
n = W * H
p = wp.array(np.random.default_rng(0).random((C, n)).astype(np.float32), device=dev)
ap = wp.zeros((C, n), dtype=wp.float32, device=dev)
one = wp.zeros((1, 1), dtype=wp.float32, device=dev)
scal = wp.zeros((10, C), dtype=wp.float32, device=dev)
ROWS = wp.constant(16)

@wp.kernel
def plain_stencil(p: wp.array2d(dtype=wp.float32), a2: float, h: int, w: int, ap: wp.array2d(dtype=wp.float32)):
    c, y, x = wp.tid()
    i = y * w + x
    xi = p[c, i]
    acc = a2 * xi
    if x + 1 < w:
        acc += xi - p[c, i + 1]
    if x > 0:
        acc += xi - p[c, i - 1]
    if y + 1 < h:
        acc += xi - p[c, i + w]
    if y > 0:
        acc += xi - p[c, i - w]
    ap[c, i] = acc

@wp.kernel
def plain_apply(p: wp.array2d(dtype=wp.float32), wpri: wp.array2d(dtype=wp.float32), a2: float, h: int, w: int, ap: wp.array2d(dtype=wp.float32)):
    c, y, x = wp.tid()
    i = y * w + x
    ap[c, i] = ops._apply(p, wpri, wpri, wpri, 0, a2, c, i, y, x, h, w)

@wp.kernel
def tiled_const_rows(p: wp.array2d(dtype=wp.float32), wpri: wp.array2d(dtype=wp.float32), a2: float, h: int, w: int, lanes: int,
                     ap: wp.array2d(dtype=wp.float32), scal: wp.array2d(dtype=wp.float32)):
    c, by, bx, lane = wp.tid()
    pap = float(0.0)
    for j in range(ROWS):
        y = by * ROWS + j
        xx = bx * lanes + lane
        if y < h and xx < w:
            i = y * w + xx
            api = ops._apply(p, wpri, wpri, wpri, 0, a2, c, i, y, xx, h, w)
            ap[c, i] = api
            pap += p[c, i] * api
    wp.tile_atomic_add(scal[3], wp.tile_sum(wp.tile(pap)), offset=c)

@wp.kernel
def tiled_const_rows_plain(p: wp.array2d(dtype=wp.float32), a2: float, h: int, w: int, lanes: int,
                           ap: wp.array2d(dtype=wp.float32), scal: wp.array2d(dtype=wp.float32)):
    c, by, bx, lane = wp.tid()
    pap = float(0.0)
    for j in range(ROWS):
        y = by * ROWS + j
        x = bx * lanes + lane
        if y < h and x < w:
            i = y * w + x
            xi = p[c, i]
            acc = a2 * xi
            if x + 1 < w:
                acc += xi - p[c, i + 1]
            if x > 0:
                acc += xi - p[c, i - 1]
            if y + 1 < h:
                acc += xi - p[c, i + w]
            if y > 0:
                acc += xi - p[c, i - w]
            ap[c, i] = acc
            pap += xi * acc
    wp.tile_atomic_add(scal[3], wp.tile_sum(wp.tile(pap)), offset=c)

def timeit(fn, reps=50):
    fn(); wp.synchronize_device(dev)
    g = None
    with wp.ScopedCapture(device=dev, force_module_load=False) as cap:
        for _ in range(reps):
            fn()
    wp.capture_launch(cap.graph); wp.synchronize_device(dev)
    ts = []
    for _ in range(5):
        t0 = time.perf_counter(); wp.capture_launch(cap.graph); wp.synchronize_device(dev); ts.append(time.perf_counter() - t0)
    return 1e6 * statistics.median(ts) / reps

wp.load_module(ops, device=dev)
wp.load_module(device=dev)
for lanes, rows in ((128, 16), (256, 16), (128, 4)):
    dim = (C, (H + rows - 1) // rows, (W + lanes - 1) // lanes)
    print("current cg_matvec lanes", lanes, "rows", rows, "%.1f us" % timeit(lambda: wp.launch_tiled(ops.cg_matvec, dim=dim, inputs=[p, one, one, one, 0, 0.04, H, W, rows, 1, lanes, ap, scal, 0], block_dim=lanes, device=dev)), flush=True)
print("plain stencil, one thread a pixel   %.1f us" % timeit(lambda: wp.launch(plain_stencil, dim=(C, H, W), inputs=[p, 0.04, H, W, ap], device=dev)), flush=True)
print("plain _apply, one thread a pixel    %.1f us" % timeit(lambda: wp.launch(plain_apply, dim=(C, H, W), inputs=[p, one, 0.04, H, W, ap], device=dev)), flush=True)
for lanes in (128, 256):
    dim = (C, (H + 15) // 16, (W + lanes - 1) // lanes)
    print("tiled, constant rows, _apply, lanes", lanes, "%.1f us" % timeit(lambda: wp.launch_tiled(tiled_const_rows, dim=dim, inputs=[p, one, 0.04, H, W, lanes, ap, scal], block_dim=lanes, device=dev)), flush=True)
    print("tiled, constant rows, plain,  lanes", lanes, "%.1f us" % timeit(lambda: wp.launch_tiled(tiled_const_rows_plain, dim=dim, inputs=[p, 0.04, H, W, lanes, ap, scal], block_dim=lanes, device=dev)), flush=True)
