import numpy as np, warp as wp
from grisx.render.driver import load_scene, PassTimer, method_params
from grisx.render.base.registry import METHODS, RenderContext
from grisx.device import resolve_device
sc = load_scene("door-ajar"); built = sc.build(resolve_device("cpu"))
t=PassTimer(built.device)
r = METHODS["restir-gi"].create(RenderContext(built, 160, 120, method_params("restir-gi", None), 1, t, "restir-gi"))
for f in range(96):
    built.set_frame(float(f)); r.render_frame(f)
    if f % 16 == 15:
        def lum(core): 
            lo=core["lo"]; v=core["valid"]==1; return ((lo.sum(-1)>0)&v).mean(), v.mean()
        ini=lum(r.initial[1].core.numpy()); tem=lum(r.temporal_buf.current[1].core.numpy()); spa=lum(r.spatial_buf.current[1].core.numpy())
        print(f, "L_o>0 & valid: initial %.3f temporal %.3f spatial %.3f" % (ini[0], tem[0], spa[0]), "valid initial %.3f" % ini[1])
