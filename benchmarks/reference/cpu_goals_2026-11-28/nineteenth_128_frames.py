import sys, json, numpy as np
from grisx.render import render
out = {}
for m in sys.argv[2].split(","):
    r = render(sys.argv[1], m, res=(160,120), frames=128, spp=1 if m=="pt" else None, seed=1, device="cpu", camera="static")
    ms = np.asarray(r.frame_seconds)*1e3
    out[m] = {"frames_1_31": float(np.median(ms[1:32])), "frames_32_63": float(np.median(ms[32:64])), "frames_64_127": float(np.median(ms[64:])), "all_ms": [round(float(v),2) for v in ms]}
    print(m, {k: round(v,1) for k,v in out[m].items() if k!="all_ms"}, flush=True)
json.dump(out, open(sys.argv[3],"w"))
