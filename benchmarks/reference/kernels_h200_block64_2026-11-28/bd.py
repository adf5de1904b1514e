"""Run benchmarks/kernels.py with wp.launch's block_dim forced for kernels whose name matches $BD_MATCH."""
import os, re, runpy, sys
import warp as wp
bd = int(os.environ.get("BD", "0")); pat = re.compile(os.environ.get("BD_MATCH", "."))
_launch = wp.launch
def launch(kernel, *a, **k):
    if bd and pat.search(getattr(kernel, "key", "")):
        k["block_dim"] = bd
    return _launch(kernel, *a, **k)
wp.launch = launch
sys.argv = ["benchmarks/kernels.py"] + sys.argv[1:]
sys.path.insert(0, "benchmarks")
runpy.run_path("benchmarks/kernels.py", run_name="__main__")
