"""Per-instance quality of G-PT's gradients against B.1's (one instance each), CPU, small frames."""
import sys, json, time, numpy as np
sys.path.insert(0, '/work/main/benchmarks')
import warp as wp
from grisx.render.driver import load_scene, METHODS as REG, RenderContext, method_params
from grisx.poisson import forward_gradient, reconstruct
from grisx.eval.metrics import relmse
from protocol import reference_at
scene, W, H, F, camera = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), sys.argv[5]
variants = json.loads(sys.argv[6])
seeds = [int(s) for s in sys.argv[7].split(',')]
ev = list(range(F - 2, F))
sc = load_scene(scene)
refs = {}
for f in ev:
    rb = sc.build('cpu'); rb.animate_camera = camera == 'path'
    refs[f] = reference_at(rb, W, H, f, 8, int(sys.argv[8]) if len(sys.argv) > 8 else 1024, seed=424242 + f)
for label, (method, params) in variants.items():
    for seed in seeds:
        built = sc.build('cpu'); built.animate_camera = camera == 'path'
        p = {**method_params(method, {'max_depth': 8, **params}), 'spp': 1}
        r = REG[method].create(RenderContext(built, W, H, dict(p), seed, None, method))
        if hasattr(r, 'reconstruct_frames'): r.reconstruct_frames = False
        res = {'dx': [], 'dy': [], 'L1': [], 'primal': [], 'ms': []}
        for f in range(F):
            built.set_frame(float(f)); t0 = time.perf_counter(); r.render_frame(f); t = time.perf_counter() - t0
            if f > 0: res['ms'].append(t * 1e3)
            if f in ev:
                g = r.gradient; ref, var = refs[f]; rg = forward_gradient(ref); vg = forward_gradient(var)
                pr, dx, dy = (a.numpy().astype(np.float64) for a in (g.primal, g.dx, g.dy))
                norm = np.mean(ref ** 2)
                vx = np.zeros_like(var); vx[:, :-1] = var[:, :-1] + var[:, 1:]; vy = np.zeros_like(var); vy[:-1] = var[:-1] + var[1:]
                res['dx'].append((np.mean((dx - rg.dx) ** 2) - np.mean(vx)) / norm); res['dy'].append((np.mean((dy - rg.dy) ** 2) - np.mean(vy)) / norm)
                res.setdefault('refshare_dx', []).append(np.mean(vx) / np.mean((dx - rg.dx) ** 2))
                lx = np.zeros_like(ref); lx[:, :-1] = 0.5 * (ref[:, :-1] + ref[:, 1:]); ly = np.zeros_like(ref); ly[:-1] = 0.5 * (ref[:-1] + ref[1:])
                res.setdefault('rel_dx', []).append(np.mean(((dx - rg.dx) ** 2 - vx) / (lx ** 2 + 1e-2)))
                res.setdefault('rel_dy', []).append(np.mean(((dy - rg.dy) ** 2 - vy) / (ly ** 2 + 1e-2)))
                l1 = reconstruct(*[wp.array(a.astype(np.float32), dtype=wp.vec3, device='cpu') for a in (pr, dx, dy)], alpha=0.2, norm='L1', check_finite=False, measure=False).numpy()
                res['L1'].append(relmse(l1, ref)); res['primal'].append(relmse(pr, ref))
                L1 = lambda p_, x_, y_: reconstruct(*[wp.array(np.asarray(a, dtype=np.float32), dtype=wp.vec3, device='cpu') for a in (p_, x_, y_)], alpha=0.2, norm='L1', check_finite=False, measure=False).numpy()
                res.setdefault('L1_exact_gradients', []).append(relmse(L1(pr, rg.dx, rg.dy), ref))
                res.setdefault('L1_exact_primal', []).append(relmse(L1(ref, dx, dy), ref))
        out = {'scene': scene, 'label': label, 'seed': seed, **{k: float(np.mean(v)) for k, v in res.items()}, 'ms': float(np.median(res['ms']))}
        print(json.dumps(out), flush=True)
