"""SMS frame time at 1080p (1 spp a frame, 5 frames after a warm-up), per pass: a line of JSON per (scene, method)."""
import json, sys, statistics, warnings
warnings.simplefilter("ignore")
from grisx.render import render
label = sys.argv[1]
for scene in sys.argv[2].split(","):
    for m in sys.argv[3].split(","):
        render(scene, m, res=(1920, 1080), spp=None if m == "sms-restir" else 1, frames=1, device="cuda", seed=1)
        if len(sys.argv) > 4:
            continue  # warm-up only (compile)
        r = render(scene, m, res=(1920, 1080), spp=None if m == "sms-restir" else 1, frames=5, device="cuda", seed=2)
        print(json.dumps({"label": label, "scene": scene, "method": m, "frame_ms": round(1e3 * statistics.median(r.frame_seconds), 2),
                          "pass_ms": {k: round(1e3 * v / 5, 2) for k, v in r.pass_seconds.items()}}), flush=True)
