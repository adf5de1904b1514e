"""Mitsuba 3's render-test suite on a chosen device: one pass/fail line per scene, the pass fraction, JSON.

The same scenes, sample budget and criterion as ``tests/conformance/test_mitsuba_render_suite.py``
(mitsuba-data's 29 surface scenes in ``tests/conformance/mitsuba_render_tests``, grisx's ``pt``
at Mitsuba's 2·10⁶ samples per scene, seed 0, :func:`grisx.testing.mitsuba_render_test`), so the
suite can be run where the tests do not: on a GPU.

    python benchmarks/mitsuba_render_tests.py --device cuda --out benchmarks/results/mitsuba_render_tests_cuda.json
    python benchmarks/mitsuba_render_tests.py --match bsdf_spheres     # some scenes, on the CPU

Each line: ``pass``/``FAIL`` (Mitsuba's verdict), ``load`` or ``render`` (a grisx error, its first
line), the percentage of pixels passing, the smallest p-value, seconds. The JSON records the device,
versions, seed and settings next to the rows.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SUITE = ROOT / "tests" / "conformance" / "mitsuba_render_tests" / "tests" / "scenes"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--device", default="cpu", help="Warp device: cpu, cuda, cuda:1 ...")
    ap.add_argument("--match", default="", help="only scenes whose folder/name contains this")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=None, help="JSON rows (default: print only)")
    args = ap.parse_args(argv)

    import warp as wp

    import grisx
    from grisx.errors import GrisxError
    from grisx.imageio import read_exr
    from grisx.render import render
    from grisx.scene.mitsuba import load_mitsuba
    from grisx.testing import mitsuba_render_test, mitsuba_render_test_spp

    scenes = sorted(str(p.relative_to(SUITE).with_suffix("")) for p in SUITE.glob("*/*.xml"))
    scenes = [s for s in scenes if args.match in s]
    rows = []
    for name in scenes:
        path = SUITE / f"{name}.xml"
        stem = path.name.rsplit("_", 1)[0]
        ref = read_exr(path.parent / "refs" / f"{stem}_ref_rgb.exr")
        var = read_exr(path.parent / "refs" / f"{stem}_ref_rgb_var.exr")
        spp = mitsuba_render_test_spp(ref.shape[1], ref.shape[0])
        row = {"scene": name, "width": ref.shape[1], "height": ref.shape[0], "spp": spp}
        start = time.perf_counter()
        try:
            scene = load_mitsuba(path)
        except GrisxError as exc:
            row.update(status="load", reason=str(exc).splitlines()[0])
        else:
            try:
                result = render(scene, "pt", spp=spp, seed=args.seed, device=args.device)
            except GrisxError as exc:
                row.update(status="render", reason=str(exc).splitlines()[0])
            else:
                verdict = mitsuba_render_test(result.image, spp, ref, var)
                row.update(status="pass" if verdict.passed else "FAIL", pass_fraction=verdict.pass_fraction,
                           min_p_value=verdict.min_p_value, alpha=verdict.alpha)
        row["seconds"] = round(time.perf_counter() - start, 2)
        rows.append(row)
        detail = (f"{100 * row['pass_fraction']:6.2f}% of pixels, min p {row['min_p_value']:.2g}" if "pass_fraction" in row
                  else row.get("reason", ""))
        print(f"{row['status']:6s} {name}: {detail} ({row['seconds']} s)", flush=True)
    passed = sum(r["status"] == "pass" for r in rows)
    print(f"\n{passed} of {len(rows)} scenes pass Mitsuba's criterion on {args.device} ({100.0 * passed / max(len(rows), 1):.0f}%)")
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        device = wp.get_device(args.device)
        args.out.write_text(json.dumps({
            "device": args.device, "device_name": getattr(device, "name", str(device)), "seed": args.seed,
            "passed": passed, "scenes": len(rows), "grisx": getattr(grisx, "__version__", ""), "warp": wp.config.version,
            "python": platform.python_version(), "rows": rows,
        }, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
