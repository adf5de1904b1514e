"""How many of mitsuba-data's scene files grisx loads and renders (issue 38).

mitsuba-data (https://github.com/mitsuba-renderer/mitsuba-data) holds the
scenes of Mitsuba 3's documentation and test suite. This script walks a
checkout of it, takes every *top-level* scene file (an ``.xml`` whose root
element is ``<scene>``, outside ``include/`` and ``fragments/`` folders, which
hold pieces that other files include), and for each one

1. loads it with :func:`grisx.scene.mitsuba.load_mitsuba` (its ``<default>``
   parameters as published), and
2. renders a tiny image with ``--method pt`` (16x12, 1 spp by default) and
   checks that every pixel is finite.

It prints one line per file (``ok``, ``load: <reason>`` or ``render:
<reason>``), a summary, and writes the rows as JSON. Files that use
participating media (a ``<medium>`` element, in the file or in what it
includes) are counted apart, since grisx renders surfaces only.

    git clone https://github.com/mitsuba-renderer/mitsuba-data /tmp/mitsuba-data
    python benchmarks/mitsuba_data.py /tmp/mitsuba-data --out benchmarks/results/mitsuba_data.json
    python benchmarks/mitsuba_data.py /tmp/mitsuba-data --no-render      # loading only (fast)
"""

from __future__ import annotations

import argparse
import json
import platform
import re
import sys
import time
from pathlib import Path

import numpy as np

_INCLUDE_RE = re.compile(r"<include\s+filename=\"([^\"]+)\"")


def scene_files(root: Path) -> list[Path]:
    """Top-level scene XMLs under ``root``: root element <scene>, not in include/ or fragments/ folders."""
    out = []
    for p in sorted(root.rglob("*.xml")):
        rel = p.relative_to(root).parts
        if "include" in rel[:-1] or "fragments" in rel[:-1] or any(s.startswith(".") for s in rel):
            continue
        head = p.read_text(errors="replace")[:4000]
        if re.search(r"<scene[\s>]", head):
            out.append(p)
    return out


def uses_media(path: Path, depth: int = 0) -> bool:
    """Whether the file (or anything it includes, literally named) has a <medium> element."""
    try:
        text = path.read_text(errors="replace")
    except OSError:
        return False
    if "<medium" in text:
        return True
    if depth > 4:
        return False
    return any(uses_media(path.parent / name, depth + 1) for name in _INCLUDE_RE.findall(text) if "$" not in name)


def check(path: Path, render: bool, method: str, res: tuple[int, int], spp: int) -> tuple[str, str, float]:
    """(status, reason, seconds) for one file: status 'ok', 'load' or 'render'."""
    from grisx.errors import GrisxError
    from grisx.scene.mitsuba import load_mitsuba

    start = time.perf_counter()
    try:
        scene = load_mitsuba(path)
    except GrisxError as exc:
        return "load", str(exc).splitlines()[0], time.perf_counter() - start
    if not render:
        return "ok", "", time.perf_counter() - start
    from grisx.render.driver import render as render_scene

    try:
        result = render_scene(scene, method, spp=spp, res=res, device="cpu", seed=0)
    except GrisxError as exc:
        return "render", str(exc).splitlines()[0], time.perf_counter() - start
    if not np.all(np.isfinite(result.image)):
        return "render", "non-finite pixels", time.perf_counter() - start
    return "ok", "", time.perf_counter() - start


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("root", type=Path, help="a checkout of mitsuba-data")
    ap.add_argument("--no-render", action="store_true", help="load only")
    ap.add_argument("--method", default="pt")
    ap.add_argument("--res", default="16x12")
    ap.add_argument("--spp", type=int, default=1)
    ap.add_argument("--match", default="", help="only files whose path contains this")
    ap.add_argument("--out", type=Path, default=None, help="JSON rows (default: print only)")
    args = ap.parse_args(argv)
    w, h = (int(v) for v in args.res.lower().split("x"))
    files = [p for p in scene_files(args.root) if args.match in str(p)]
    rows = []
    for p in files:
        rel = str(p.relative_to(args.root))
        media = uses_media(p)
        status, reason, secs = check(p, not args.no_render, args.method, (w, h), args.spp)
        rows.append({"file": rel, "status": status, "reason": reason, "media": media, "seconds": round(secs, 3)})
        print(f"{status:6s} {rel}{' [media]' if media else ''}{': ' + reason if reason else ''}", flush=True)
    ok = sum(r["status"] == "ok" for r in rows)
    surf = [r for r in rows if not r["media"]]
    ok_surf = sum(r["status"] == "ok" for r in surf)
    stage = "load" if args.no_render else f"load and render ({args.method}, {w}x{h}, {args.spp} spp)"
    print(f"\n{stage}: {ok} of {len(rows)} files; without participating media {ok_surf} of {len(surf)}"
          f" ({100.0 * ok_surf / max(len(surf), 1):.0f}%)")
    if args.out is not None:
        import grisx

        args.out.parent.mkdir(parents=True, exist_ok=True)
        commit = ""
        head = args.root / ".git" / "HEAD"
        if head.is_file():
            commit = head.read_text().strip()
        args.out.write_text(json.dumps({
            "root": str(args.root), "commit": commit, "stage": stage, "ok": ok, "files": len(rows),
            "ok_without_media": ok_surf, "files_without_media": len(surf),
            "grisx": getattr(grisx, "__version__", ""), "python": platform.python_version(), "rows": rows,
        }, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
