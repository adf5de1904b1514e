import sys, json, time, numpy as np
sys.path.insert(0, '/work/main/benchmarks')
import warp as wp
from grisx.render.driver import load_scene
from grisx.render.driver import METHODS as REGISTRY, RenderContext, method_params
from grisx.poisson import ScreenedPoisson, reconstruct
from grisx.eval.metrics import relmse
from protocol import reference_at
scene, W, H, F = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
sc = load_scene(scene); built = sc.build('cpu'); built.animate_camera = True
params = {**method_params('restir-gpt', {'max_depth': 8}), 'spp': 1}
r = REGISTRY['restir-gpt'].create(RenderContext(built, W, H, dict(params), 0, None, 'restir-gpt'))
r.reconstruct_frames = False
out = []
for f in range(F):
    built.set_frame(float(f)); r.render_frame(f)
    if f < F - 2: continue
    g = r.gradient
    arrs = [wp.array(a.numpy(), dtype=wp.vec3, device='cpu') for a in (g.primal, g.dx, g.dy)]
    exact = np.asarray(reconstruct(*arrs, alpha=0.2, norm='L2', check_finite=False, measure=False).numpy())
    rb = sc.build('cpu'); rb.animate_camera = True
    ref, var = reference_at(rb, W, H, f, 8, 256, seed=424242 + f)
    rec = {'frame': f, 'mc_relmse_exact': float(relmse(exact, ref))}
    for tol in (1e-5, 1e-4, 1e-3, 3e-3):
        s = ScreenedPoisson(*arrs, alpha=0.2, norm='L2', tol=tol, preconditioner='multigrid') if True else None
        img = s.solve().numpy()
        rel = np.abs(img - exact) / (np.abs(exact) + 1e-2)
        rec[f'tol{tol:g}'] = {'it': s.iterations, 'relmse_vs_exact': float(relmse(img, exact)), 'relmse_vs_ref': float(relmse(img, ref)), 'p999_rel': float(np.quantile(rel, 0.999)), 'max_rel': float(rel.max())}
    print(json.dumps(rec), flush=True); out.append(rec)
