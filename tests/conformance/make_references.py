"""Render the conformance references with Mitsuba 3 itself.

Every ``scenes/<case>.xml`` is rendered by Mitsuba 3 (``llvm_ad_rgb``, the
``path`` integrator of the file) in ``--runs`` independent runs of ``--spp``
samples per pixel, seeds 0, 1, ... Per pixel the runs give the mean and its
variance (sample variance / runs); they are written as

    refs/<case>.exr       the mean image (linear RGB)
    refs/<case>.var.exr   the variance of that mean, per pixel and channel
    refs/meta.json        Mitsuba's version, variant, runs, spp and seconds per case

``test_conformance.py`` compares grisx's ``pt`` with them; it needs only the
committed files, not Mitsuba. Re-run this script after adding a case (``python
tests/conformance/make_references.py CASE``) or when a newer Mitsuba changes
its answer.

Setup (Mitsuba's CPU backend needs LLVM >= 17; Debian 12's default LLVM
crashes Dr.Jit)::

    apt-get update && apt-get install -y libllvm19
    pip install mitsuba
    export DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM-19.so   # found automatically if unset
"""

from __future__ import annotations

import argparse
import datetime
import glob
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SCENES = HERE / "scenes"
REFS = HERE / "refs"


def _find_llvm() -> None:
    if "DRJIT_LIBLLVM_PATH" in os.environ:
        return
    for pattern in ("/usr/lib/x86_64-linux-gnu/libLLVM-1[7-9]*.so*", "/usr/lib/llvm-1[7-9]/lib/libLLVM*.so*"):
        found = sorted(glob.glob(pattern))
        if found:
            os.environ["DRJIT_LIBLLVM_PATH"] = found[-1]
            return


def render_reference(mi, xml: Path, runs: int, spp: int) -> tuple[np.ndarray, np.ndarray, float]:
    """Mean image and per-pixel variance of the mean over ``runs`` Mitsuba runs (float64 sums)."""
    scene = mi.load_file(str(xml))
    start = time.perf_counter()
    total = sq = None
    for seed in range(runs):
        img = np.asarray(mi.render(scene, spp=spp, seed=seed), dtype=np.float64)[..., :3]
        total = img if total is None else total + img
        sq = img**2 if sq is None else sq + img**2
    mean = total / runs
    variance = np.maximum(sq / runs - mean**2, 0.0) * runs / (runs - 1) / runs  # sample variance / runs
    return mean, variance, time.perf_counter() - start


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cases", nargs="*", help="case names (default: every scenes/*.xml)")
    ap.add_argument("--runs", type=int, default=16)
    ap.add_argument("--spp", type=int, default=4096, help="samples per pixel of each run")
    args = ap.parse_args(argv)
    _find_llvm()
    import mitsuba as mi

    from grisx.imageio import write_exr

    mi.set_variant("llvm_ad_rgb")
    cases = args.cases or sorted(p.stem for p in SCENES.glob("*.xml"))
    REFS.mkdir(exist_ok=True)
    meta_path = REFS / "meta.json"
    meta = json.loads(meta_path.read_text()) if meta_path.exists() else {"cases": {}}
    for case in cases:
        xml = SCENES / f"{case}.xml"
        if not xml.is_file():
            print(f"make_references: no scene file {xml}", file=sys.stderr)
            return 1
        mean, variance, seconds = render_reference(mi, xml, args.runs, args.spp)
        write_exr(REFS / f"{case}.exr", mean.astype(np.float32))
        write_exr(REFS / f"{case}.var.exr", variance.astype(np.float32))
        meta["cases"][case] = {"runs": args.runs, "spp": args.spp, "seconds": round(seconds, 2),
                               "mean": [round(float(v), 6) for v in mean.reshape(-1, 3).mean(axis=0)]}
        print(f"{case:28s} mean {mean.mean():.5f}  {seconds:6.1f} s", flush=True)
    meta.update({"renderer": f"Mitsuba {mi.__version__}", "variant": mi.variant(), "integrator": "the file's <integrator>",
                 "date": datetime.date.today().isoformat()})
    meta["cases"] = dict(sorted(meta["cases"].items()))
    meta_path.write_text(json.dumps(meta, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
