"""``grisx scenes`` and ``grisx render``.

::

    grisx scenes [--json]
    grisx render SCENE_OR_FILE --method M [--spp N] [--frames F [--accumulate]] [--res WxH]
                 [--device cpu|cuda] [--seed S] [--param k=v ...] [--out PATH.exr|.png|.npy [--exr]] [--json]
    grisx reference SCENE_OR_FILE [--spp N] [--res WxH] [--max-depth D] [--device cpu|cuda] [--force] [--out PATH.exr] [--json]
                    [--devices cuda:0,cuda:1 | --executor ray [--address HOST:PORT]] [--retries N] [--chunk-spp N]

``render`` writes the linear EXR, a tonemapped sRGB PNG beside it and a JSON
sidecar (settings, grisx version, device, seed, timings). ``--method
gbuffer`` writes one EXR per G-buffer field (``PATH.<field>.exr``) and a
contact-sheet PNG. ``--json`` prints one object with ``method``, ``scene``,
``width``, ``height``, ``frames``, ``spp``, ``seconds`` (total and per pass),
``device`` and ``output`` (the paths written).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from grisx.errors import InvalidParameterError

__all__ = ["add_parsers", "write_outputs"]


def add_parsers(sub: Any, key_value: Any, count: Any, seed: Any) -> None:
    """Register ``scenes`` and ``render`` on the top-level subparsers."""
    from grisx.render.driver import METHODS

    scenes = sub.add_parser("scenes", help="list the built-in scenes")
    scenes.add_argument("--json", action="store_true", help="print one JSON object")
    scenes.set_defaults(handler=_scenes)

    m = sub.add_parser("methods", help="the render methods (a table), or one method's params")
    m.add_argument("method", nargs="?", default=None, help="a render method: its params with defaults, ranges and help")
    m.add_argument("--json", action="store_true", help="print one JSON object")
    m.add_argument("--markdown", action="store_true", help="print the table as Markdown (the README's methods table)")
    m.set_defaults(handler=_methods)

    r = sub.add_parser(
        "render",
        help="render a built-in scene or a Mitsuba XML file",
        description="Render a scene. 'grisx methods' lists the methods; 'grisx render --method M --help' (or "
        "'grisx methods M') gives one method's params.",
    )
    r.add_argument("scene", help="built-in scene name (see 'grisx scenes') or a Mitsuba XML file")
    r.add_argument("--method", required=True, help="render method: " + ", ".join(METHODS))
    r.add_argument("--spp", type=count, default=None, help="samples per pixel per frame (default: the scene's)")
    r.add_argument("--frames", type=count, default=1, help="frames to render along the scene's camera path (default 1)")
    r.add_argument("--accumulate", action="store_true", help="average all frames into the output")
    r.add_argument("--res", default=None, help="WxH, overrides the scene's film size")
    r.add_argument("--device", default="cpu", help="cpu (default) or cuda")
    r.add_argument("--seed", type=seed, default=0, help="seed (default 0)")
    r.add_argument("--param", type=key_value, action="append", default=[], metavar="K=V", help="method option (repeatable)")
    r.add_argument("--out", default=None, help="output path: .exr (linear, with a tonemapped PNG beside it), .png (tonemapped) or .npy "
                   "(linear float32); a JSON sidecar always (default SCENE-METHOD.exr)")
    r.add_argument("--exr", action="store_true", help="with a .png or .npy --out: also write the linear EXR beside it")
    r.add_argument("--json", action="store_true", help="print one JSON object")
    r.set_defaults(handler=_render)

    ref = sub.add_parser(
        "reference",
        help="render (or fetch from the cache) a high-spp path-traced reference with its per-pixel variance",
        description="Reference images are cached under $GRISX_CACHE_DIR/references (default ~/.cache/grisx/references) "
                    "by a hash of the scene and the settings.",
    )
    ref.add_argument("scene", help="built-in scene name or a Mitsuba XML file")
    ref.add_argument("--spp", type=count, default=1024, help="samples per pixel (default 1024)")
    ref.add_argument("--res", default=None, help="WxH, overrides the scene's film size")
    ref.add_argument("--max-depth", type=int, default=None, help="Mitsuba's max_depth (default: the scene's)")
    ref.add_argument("--device", default="cpu", help="cpu (default) or cuda")
    ref.add_argument("--seed", type=seed, default=0, help="seed (default 0)")
    ref.add_argument("--force", action="store_true", help="render even if cached")
    ref.add_argument("--out", default=None, help="also copy the image (and PATH.variance.exr, PATH.png) here")
    ref.add_argument("--json", action="store_true", help="print one JSON object")
    ref.add_argument("--chunk-spp", type=count, default=1024, help="samples per pixel of one chunk (one task; default 1024)")
    from grisx.executor import add_executor_arguments

    add_executor_arguments(ref)
    ref.set_defaults(handler=_reference)


def _scenes(args: argparse.Namespace) -> int:
    from grisx.scene.builtin import scene_summaries

    summaries = scene_summaries()
    if args.json:
        print(json.dumps({"scenes": [{"name": k, "summary": v} for k, v in summaries.items()]}))
        return 0
    width = max(len(k) for k in summaries)
    for name, text in summaries.items():
        print(f"{name:<{width}}  {text}")
    return 0


class _Progress:
    """A one-line progress bar on stderr, only when it is a terminal."""

    def __init__(self, label: str) -> None:
        self.label = label
        self.active = sys.stderr.isatty()

    def __call__(self, done: int, total: int) -> None:
        if not self.active or total <= 1:
            return
        bar = "#" * int(30 * done / total)
        sys.stderr.write(f"\r{self.label} [{bar:<30}] {done}/{total}")
        if done == total:
            sys.stderr.write("\n")
        sys.stderr.flush()


#: what ``--out`` may name
OUTPUT_FORMATS = (".exr", ".png", ".npy")


def check_output(out: Path) -> None:
    """A one-line error before any rendering if ``out`` cannot be written as asked."""
    if out.suffix.lower() not in OUTPUT_FORMATS:
        raise InvalidParameterError(f"--out must end in {', '.join(OUTPUT_FORMATS)}, got '{out}'")
    if not out.parent.is_dir():
        raise InvalidParameterError(f"--out: directory '{out.parent}' does not exist")


def _write_npy(path: Path, array: np.ndarray) -> Path:
    """np.save through a temporary file in the same folder, so a failure leaves nothing half-written."""
    import os
    import tempfile

    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp.npy", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            np.save(f, np.asarray(array, dtype=np.float32))
        os.replace(tmp, path)
    finally:
        Path(tmp).unlink(missing_ok=True)
    return path


def write_outputs(result: Any, out: Path, method: str, exr: bool = False) -> list[str]:
    """Write the image as ``out`` asks (.exr + PNG, .png, .npy; ``exr``: the EXR too) and the JSON sidecar; returns the paths."""
    from grisx import __version__
    from grisx.imageio import write_exr, write_png
    from grisx.render.driver import METHODS
    from grisx.render.views import display_image

    check_output(out)
    suffix = out.suffix.lower()
    linear = suffix == ".exr" or exr
    written = []
    if suffix == ".npy":
        written.append(str(_write_npy(out, result.image)))
    if linear:
        written.append(str(write_exr(out.with_suffix(".exr"), result.image)))
    png = out.with_suffix(".png")
    if suffix == ".npy":
        pass  # data only (and the EXR if asked)
    elif METHODS[method].kind == "debug":
        if method == "gbuffer":
            tiles = []
            for name, img in result.extra.items():
                if linear:
                    written.append(str(write_exr(out.with_suffix(f".{name}.exr"), img)))
                view = {"normal_geo": "normal", "tri": "tri", "material": "material", "hit": "material"}.get(name, name)
                disp, encode = display_image(view, img if img.ndim == 3 else np.repeat(img[:, :, None], 3, axis=2))
                from grisx.imageio import srgb_encode

                tiles.append(srgb_encode(disp) if encode else np.clip(disp, 0, 1))
            cols = 4
            rows = -(-len(tiles) // cols)
            h, w = tiles[0].shape[:2]
            sheet = np.zeros((rows * h, cols * w, 3))
            for i, t in enumerate(tiles):
                r, c = divmod(i, cols)
                sheet[r * h : (r + 1) * h, c * w : (c + 1) * w] = t[:, :, :3]
            written.append(str(write_png(png, sheet, encode=False)))
        else:
            disp, encode = display_image(method, result.image)
            written.append(str(write_png(png, disp, encode=encode)))
    else:
        written.append(str(write_png(png, result.image)))
        for name, img in result.extra.items():  # gradient-domain methods: primal, dx, dy beside the reconstruction
            written.append(str(write_exr(out.with_suffix(f".{name}.exr"), img)))
    sidecar = out.with_suffix(".json")
    meta = {
        "grisx_version": __version__,
        "device": result.device,
        "seconds": result.seconds,
        "pass_seconds": result.pass_seconds,
        **result.settings,
    }
    sidecar.write_text(json.dumps(meta, indent=2, default=_plain))
    written.append(str(sidecar))
    return written


def method_help(name: str) -> str:
    """One method's summary and params: name, type, default, range, help (``grisx methods M``)."""
    from grisx.errors import UnknownNameError
    from grisx.render.driver import METHODS

    if name not in METHODS:
        raise UnknownNameError("render method", name, sorted(METHODS))
    m = METHODS[name]
    lines = [f"{m.name}: {m.summary}", ""]
    if m.reference_max_depth is not None:
        lines.append(f"estimates pt's image at max_depth {m.reference_max_depth}")
    lines.append("spp: samples per pixel per frame" if m.uses_spp else "one sample per pixel per frame (--frames for more)")
    if not m.params:
        lines.append("no params")
    for p in m.params:
        rng = ""
        if p.choices:
            rng = " {" + "|".join(p.choices) + "}"
        elif p.minimum is not None or p.maximum is not None:
            rng = f" [{'' if p.minimum is None else f'{p.minimum:g}'}, {'' if p.maximum is None else f'{p.maximum:g}'}]"
        lines.append(f"  --param {p.name}={p.default}  ({p.kind}{rng})  {p.doc}")
    return "\n".join(lines)


def methods_markdown() -> str:
    """The registered methods as a Markdown table (the README's, checked by a test)."""
    from grisx.render.driver import METHODS

    rows = ["| method | kind | what it renders | params |", "| --- | --- | --- | --- |"]
    for name, m in METHODS.items():
        params = ", ".join(f"`{p.name}`" for p in m.params) or "—"
        summary = m.summary.replace("|", "\\|")
        rows.append(f"| `{name}` | {m.kind} | {summary} | {params} |")
    return "\n".join(rows)


def _methods(args: argparse.Namespace) -> int:
    from grisx.render.driver import METHODS

    if args.method is not None:
        if args.json:
            m = METHODS.get(args.method)
            method_help(args.method)  # the one-line error for an unknown name
            print(json.dumps({"method": m.name, "summary": m.summary, "kind": m.kind, "uses_spp": m.uses_spp,
                              "reference_max_depth": m.reference_max_depth, "params": [p.describe() for p in m.params]}, default=_plain))
        else:
            print(method_help(args.method))
        return 0
    if args.json:
        print(json.dumps({name: {"summary": m.summary, "kind": m.kind, "params": [p.name for p in m.params]} for name, m in METHODS.items()}))
        return 0
    if args.markdown:
        print(methods_markdown())
        return 0
    width = max(len(n) for n in METHODS)
    for name, m in METHODS.items():
        print(f"{name:{width}s}  {m.kind:8s}  {m.summary}")
    return 0


def _reference(args: argparse.Namespace) -> int:
    import shutil


    from grisx.imageio import write_png
    from grisx.render.reference import reference
    from grisx.render.driver import parse_res

    from grisx.executor import executor_from_args

    out = Path(args.out) if args.out else None
    if out is not None and (out.suffix.lower() != ".exr" or not out.parent.is_dir()):
        raise InvalidParameterError(f"--out must name an .exr file in an existing directory, got '{out}'")
    with executor_from_args(args) as executor:
        ref = reference(
            args.scene,
            res=parse_res(args.res) if args.res else None,
            spp=args.spp,
            max_depth=args.max_depth,
            device=args.device,
            seed=args.seed,
            force=args.force,
            progress=_Progress(f"reference {args.scene}"),
            executor=executor,
            chunk_spp=args.chunk_spp,
        )
    written = [str(ref.path), str(ref.path.with_name(ref.path.stem + ".variance.exr"))]
    if out is not None:
        shutil.copyfile(ref.path, out)
        shutil.copyfile(written[1], out.with_suffix(".variance.exr"))
        write_png(out.with_suffix(".png"), ref.image)
        written += [str(out), str(out.with_suffix(".variance.exr")), str(out.with_suffix(".png"))]
    if args.json:
        print(json.dumps({**ref.settings, "cached": ref.cached, "output": written}, default=_plain))
    else:
        state = "cached" if ref.cached else f"rendered in {ref.settings.get('seconds', 0):.1f} s"
        for worker, d in ({} if ref.cached else ref.settings.get("throughput", {})).items():
            rate = d.get("spp_per_second")
            print(f"  {worker}: {d['chunks']} chunk(s), {d['spp']} spp in {d['seconds']:.2f} s"
                  + (f" ({rate:.3g} spp/s, {d['samples_per_second'] / 1e6:.3g} Msamples/s)" if rate else ""))
        for r in [] if ref.cached else ref.settings.get("retried", []):
            print(f"  retried {r['key']}: {r['attempts']} attempts ({'; '.join(r['errors'])})")
        print(f"{args.scene}: reference {ref.settings['width']}x{ref.settings['height']}, {ref.settings['spp']} spp ({state}) -> {ref.path}")
    return 0


def _plain(v: Any) -> Any:
    if isinstance(v, (np.integer, np.floating)):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    return str(v)


def _render(args: argparse.Namespace) -> int:

    from grisx.render.driver import parse_res, render

    params: dict[str, Any] = {}
    for key, value in args.param:
        if key in params:
            raise InvalidParameterError(f"--param '{key}' given twice")
        params[key] = value
    res = parse_res(args.res) if args.res else None
    stem = Path(args.scene).stem if args.scene.lower().endswith(".xml") else args.scene
    out = Path(args.out) if args.out else Path(f"{stem}-{args.method}.exr")
    check_output(out)
    result = render(
        args.scene,
        args.method,
        spp=args.spp,
        frames=args.frames,
        accumulate=args.accumulate,
        res=res,
        device=args.device,
        seed=args.seed,
        params=params,
        progress=_Progress(f"{stem} {args.method}"),
    )
    written = write_outputs(result, out, args.method, exr=args.exr)
    if args.json:
        s = result.settings
        print(json.dumps({
            "method": args.method,
            "scene": s["scene"],
            "width": s["width"],
            "height": s["height"],
            "frames": result.frames,
            "spp": result.spp,
            "seconds": {"total": result.seconds, **result.pass_seconds},
            "device": result.device,
            "seed": args.seed,
            "params": s["params"],
            "nonfinite_samples": s.get("nonfinite_samples", 0),
            **({"statistics": s["statistics"]} if "statistics" in s else {}),
            "output": written,
        }, default=_plain))
    else:
        print(f"{result.settings['scene']}: {args.method}, {result.settings['width']}x{result.settings['height']}, "
              f"{result.frames} frame(s) x {result.spp} spp in {result.seconds:.3f} s on {result.device} -> {written[0]}")
    return 0
