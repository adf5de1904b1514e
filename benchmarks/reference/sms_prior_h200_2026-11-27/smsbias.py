"""Issue 37's open scene (benchmarks/scenes/spheres.xml, 48x36): sms / sms-partitioned / sms-restir vs pt over independent runs.
Image mean and the caustic's 5x5 block (brightest block of the pt mean), z over runs. JSON after every method."""
import json, os, sys, time, warnings
import numpy as np
warnings.simplefilter("ignore")
from grisx.render import render
from grisx.scene.mitsuba import load_mitsuba
dev = sys.argv[1]; methods = sys.argv[2].split(","); budget = float(sys.argv[3]); spp = int(sys.argv[4]) if len(sys.argv) > 4 else 256
out_dir = os.environ.get("OUT", "."); label = os.environ.get("LABEL", "after")
sc = load_mitsuba("benchmarks/scenes/spheres.xml", params={"width": 48, "height": 36})
res = {}
def runs_of(m, spp, budget, max_runs, seed0):
    means, t0 = [], time.time()
    for s in range(max_runs):
        if m == "sms-restir":
            r = render(sc, m, frames=spp, accumulate=True, seed=seed0 + s, device=dev)
        else:
            r = render(sc, m, spp=spp, seed=seed0 + s, device=dev)
        means.append(np.asarray(r.image, dtype=np.float64).mean(-1))
        if time.time() - t0 > budget:
            break
    return np.stack(means), time.time() - t0
ref, tref = runs_of("pt", 16384, budget, 64, 9000)
m = ref.mean(0)
k = np.ones((5, 5)); bs = np.array([[m[y:y+5, x:x+5].sum() for x in range(48 - 4)] for y in range(36 - 4)])
by, bx = np.unravel_index(np.argmax(bs), bs.shape)
def stats(st):
    img = st.mean((1, 2)); blk = st[:, by:by+5, bx:bx+5].mean((1, 2))
    return img, blk
ri, rb = stats(ref)
res["pt"] = {"runs": len(ref), "seconds": round(tref, 1), "spp": 16384, "block": [int(by), int(bx)], "image": ri.mean(), "block_mean": rb.mean(),
             "image_se": ri.std(ddof=1) / np.sqrt(len(ri)), "block_se": rb.std(ddof=1) / np.sqrt(len(rb))}
print(json.dumps(res["pt"]), flush=True)
for mth in methods:
    st, t = runs_of(mth, spp, budget, 100000, 20000)
    i, b = stats(st)
    row = {"runs": len(st), "seconds": round(t, 1), "spp": spp}
    for name, v, r in (("image", i, ri), ("block", b, rb)):
        se = np.sqrt(v.var(ddof=1) / len(v) + r.var(ddof=1) / len(r))
        row[name + "_rel"] = v.mean() / r.mean() - 1.0
        row[name + "_z"] = (v.mean() - r.mean()) / se
        row[name + "_rel_se"] = se / r.mean()
        row[name + "_skew"] = float(((v - v.mean()) ** 3).mean() / v.std() ** 3)
    res[mth] = row
    print(mth, json.dumps({k: (round(v, 4) if isinstance(v, float) else v) for k, v in row.items()}), flush=True)
    json.dump({"label": label, "device": dev, **{k: {kk: (float(vv) if isinstance(vv, (np.floating, float)) else vv) for kk, vv in v.items()} for k, v in res.items()}},
              open(f"{out_dir}/smsbias_{label}.json", "w"), indent=1)
