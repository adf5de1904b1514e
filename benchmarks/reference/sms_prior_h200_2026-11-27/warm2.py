"""Cold compile of one method on one scene in a fresh Warp cache: seconds, and Warp's own load lines (compiled/cached)."""
import sys, time, json, warnings, io, contextlib
warnings.simplefilter("ignore")
import warp as wp
wp.config.quiet = False
from grisx.render import render
scene, m = sys.argv[1], sys.argv[2]
kw = {} if m == "sms-restir" else {"spp": 1}
buf = io.StringIO()
t0 = time.time()
with contextlib.redirect_stdout(buf):
    render(scene, m, res=(64, 36), frames=2 if m == "sms-restir" else 1, device="cuda", seed=1, **kw)
dt = time.time() - t0
loads = [l.strip() for l in buf.getvalue().splitlines() if "took" in l]
print(json.dumps({"scene": scene, "method": m, "first_use_s": round(dt, 1), "loads": loads}), flush=True)
