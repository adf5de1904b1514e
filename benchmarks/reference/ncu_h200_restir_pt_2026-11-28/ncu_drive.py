"""One restir-pt render (3 frames) and one pt frame at 1080p, for ncu to profile."""
import os, sys
import warp as wp
wp.config.quiet = True
from grisx.render import render
scene = os.environ.get("SCENE", "glossy-room")
meth = os.environ.get("METH", "restir-pt")
render(scene, "pt", res=(1920, 1080), frames=1, spp=1, seed=1, device="cuda")
render(scene, meth, res=(1920, 1080), frames=3, seed=1, device="cuda")
wp.synchronize()
print("done")
