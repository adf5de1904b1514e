import numpy as np
from grisx.render import render
from grisx.eval.metrics import flip, METRICS
from grisx.render.driver import load_scene
from grisx.render.pt import PathTracer
W,H=160,90
sc=load_scene("door-ajar"); b=sc.build("cpu")
pt=PathTracer(b,W,H,spp=256,max_depth=2,seed=7); pt.add_samples(0,256); ref=pt.mean().astype(np.float64)[...,:3]
for m in ("restir-di","restcv-di"):
    imgs=[]
    r=render(sc,m,res=(W,H),frames=16,camera="static",seed=1,on_frame=lambda i,img,s: imgs.append(np.asarray(img,np.float64)[...,:3]))
    im=imgs[-1]
    print(m, "relmse", METRICS["relmse"](im,ref), "flip", flip(im,ref), "min", im.min(), "mean", im.mean(), "neg frac", (im<0).mean(), "nan", np.isnan(im).sum())
    np.save(f"/tmp/{m}.npy", im)
np.save("/tmp/ref.npy", ref)
