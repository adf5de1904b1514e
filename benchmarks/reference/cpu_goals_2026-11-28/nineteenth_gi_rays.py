import time, sys, numpy as np, warp as wp
from grisx.render.driver import load_scene, PassTimer
from grisx.render.base.registry import METHODS, RenderContext
from grisx.render.driver import method_params
from grisx.device import resolve_device
sc = load_scene("door-ajar"); built = sc.build(resolve_device("cpu"))
class T(PassTimer):
    def __call__(self, name):
        outer=self
        class S:
            def __enter__(s):
                wp.synchronize(); built.dbg.zero_(); s.t=time.perf_counter()
            def __exit__(s,*a):
                wp.synchronize(); c=built.dbg.numpy(); outer.seconds[name]=(round((time.perf_counter()-s.t)*1e3,1), int(c[0]), round(1-c[1]/max(c[0],1),3))
        return S()
t=T(built.device)
r = METHODS["restir-gi"].create(RenderContext(built, 160, 120, method_params("restir-gi", None), 1, t, "restir-gi"))
for f in range(int(sys.argv[1])):
    built.set_frame(float(f)); t.seconds={}
    r.render_frame(f)
    if f % 8 == 7: print(f, {k: v for k,v in t.seconds.items() if k in ("gi_temporal","gi_spatial","gi_initial")})
