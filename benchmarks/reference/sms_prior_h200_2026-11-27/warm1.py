"""Cold compile: render one 64x36 frame of each method (so every kernel of the scene's SMS module loads); print seconds."""
import sys, time, json, warnings
warnings.simplefilter("ignore")
from grisx.render import render
scene, methods = sys.argv[1], sys.argv[2].split(",")
t0 = time.time()
for m in methods:
    kw = {} if m == "sms-restir" else {"spp": 1}
    render(scene, m, res=(64, 36), frames=2 if m == "sms-restir" else 1, device="cuda", seed=1, **kw)
print(json.dumps({"scene": scene, "methods": methods, "cold_s": round(time.time() - t0, 1)}), flush=True)
