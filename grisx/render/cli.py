"""``grisx scenes`` and ``grisx render``.

::

    grisx scenes [--json]
    grisx render SCENE_OR_FILE --method M [--spp N] [--frames F [--accumulate]] [--res WxH]
                 [--device cpu|cuda] [--seed S] [--param k=v ...] [--out PATH.exr|.png|.npy [--exr]] [--json]
    grisx reference SCENE_OR_FILE [--spp N] [--res WxH] [--max-depth D] [--device cpu|cuda] [--force] [--out PATH.exr] [--json]
                    [--devices cuda:0,cuda:1 | --executor ray [--address HOST:PORT]] [--retries N] [--chunk-spp N]

``render`` writes ``--out`` under exactly its name (linear EXR, PNG or NPY), a
tonemapped sRGB PNG beside an EXR, and a JSON sidecar (settings, grisx
version, device, seed, timings, the paths written). ``--method gbuffer``
writes every G-buffer field as a named layer of the EXR (``albedo.R``,
``depth.Y``, ...), one EXR per field beside it (``PATH.<field>.exr``) and a
contact-sheet PNG whose panels are labelled. ``--json`` prints the sidecar's
record on stdout (one schema): ``method``, ``scene``, ``width``, ``height``,
``frames``, ``spp``, ``seconds`` (total and per pass), ``device``, ``output``
(the paths written) and the rest of the settings.

What can be checked before rendering is: the output's folder must take a new
file, no output may be a directory, integers must fit the kernels' 32 bits,
and the film must fit in memory. Long renders show progress on stderr
(:mod:`grisx.progress`), per frame and per sample pass.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from grisx.errors import InvalidParameterError
from grisx.eval.files import json_line

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
    r.add_argument("--json", action="store_true", help="print one JSON object: the sidecar's record (the files are written as usual)")
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
        print(json_line({"scenes": [{"name": k, "summary": v} for k, v in summaries.items()]}))
        return 0
    width = max(len(k) for k in summaries)
    for name, text in summaries.items():
        print(f"{name:<{width}}  {text}")
    return 0


class _RenderProgress:
    """Frames and, for the methods that take ``spp``, samples per pixel within each frame, as one :class:`Progress`."""

    def __init__(self, label: str, frames: int) -> None:
        from grisx.progress import Progress

        self.bar = Progress(frames, label, unit="frame")
        self.frames, self.frames_done, self.spp = frames, 0, 1

    def frame(self, done: int, frames: int) -> None:
        self.frames_done = done
        self.bar(done * self.spp, frames * self.spp)

    def sample(self, done: int, spp: int) -> None:
        self.spp = spp
        self.bar(self.frames_done * spp + done, self.frames * spp, unit="spp")


#: what ``--out`` may name
OUTPUT_FORMATS = (".exr", ".png", ".npy")


def check_output(out: str | Path, flag: str = "--out", formats: tuple[str, ...] = OUTPUT_FORMATS) -> Path:
    """``out`` as a Path, or a one-line error before any rendering if it cannot be written as asked."""
    from grisx.imageio import check_writable_dir

    text = str(out)
    if not text.strip():
        raise InvalidParameterError(f"{flag} must name a file, got '{text}'")
    out = Path(text)
    if out.is_dir():
        raise InvalidParameterError(f"{flag} '{out}' is a directory; name a file (e.g. '{out / ('image' + formats[0])}')")
    if out.suffix.lower() not in formats:
        raise InvalidParameterError(f"{flag} must end in {', '.join(formats)}, got '{out}'")
    if not out.parent.is_dir():
        raise InvalidParameterError(f"{flag}: directory '{out.parent}' does not exist")
    check_writable_dir(out.parent, f"{flag} '{out}'")
    return out


def planned_outputs(out: Path, method: str, exr: bool = False, fields: tuple[str, ...] = ()) -> list[Path]:
    """Every path ``write_outputs`` writes for ``out`` (``out`` itself first, the JSON sidecar last)."""
    from grisx.render.driver import METHODS

    suffix = out.suffix.lower()
    kind = METHODS[method].kind if method in METHODS else "radiance"  # an unknown name is render()'s error
    paths = [out]
    if exr and suffix != ".exr":
        paths.append(out.with_suffix(".exr"))
    if suffix != ".npy":
        if suffix != ".png":
            paths.append(out.with_suffix(".png"))
        if kind != "debug" or (method == "gbuffer" and (suffix == ".exr" or exr)):
            paths += [out.with_suffix(f".{name}.exr") for name in fields]
    paths.append(out.with_suffix(".json"))
    return paths


def check_planned(paths: list[Path]) -> None:
    """No path to be written is a directory (found before rendering, not after)."""
    for p in paths:
        if p.is_dir():
            raise InvalidParameterError(f"cannot write '{p}': it is a directory")


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


#: the labels of the G-buffer contact sheet's panels: at least this many pixels wide, a band this tall above each
SHEET_PANEL_WIDTH, SHEET_LABEL_HEIGHT = 96, 14


def contact_sheet(panels: dict[str, np.ndarray], cols: int = 4) -> np.ndarray:
    """Display-referred panels ((H, W, 3) in [0, 1]) on a grid, each enlarged to at least
    :data:`SHEET_PANEL_WIDTH` pixels and labelled with its name in a band above it; returns (H', W', 3) in [0, 1]."""
    from PIL import Image, ImageDraw, ImageFont

    h, w = next(iter(panels.values())).shape[:2]
    k = max(1, -(-SHEET_PANEL_WIDTH // w))  # whole-pixel enlargement: every pixel stays visible as it is
    ph, pw = SHEET_LABEL_HEIGHT + h * k, w * k
    rows = -(-len(panels) // cols)
    sheet = np.zeros((rows * ph, cols * pw, 3), dtype=np.uint8)
    for i, tile in enumerate(panels.values()):
        r, c = divmod(i, cols)
        big = np.repeat(np.repeat(np.clip(tile[:, :, :3], 0, 1), k, axis=0), k, axis=1)
        sheet[r * ph + SHEET_LABEL_HEIGHT : (r + 1) * ph, c * pw : (c + 1) * pw] = np.round(big * 255).astype(np.uint8)
    img = Image.fromarray(sheet)
    draw, font = ImageDraw.Draw(img), ImageFont.load_default()
    for i, name in enumerate(panels):
        r, c = divmod(i, cols)
        draw.text((c * pw + 2, r * ph + 1), name, fill=(255, 255, 255), font=font)
    return np.asarray(img, dtype=np.float64) / 255.0


def _gbuffer_panels(extra: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    from grisx.imageio import srgb_encode
    from grisx.render.views import display_image

    panels = {}
    for name, img in extra.items():
        view = {"normal_geo": "normal", "tri": "tri", "material": "material", "hit": "material"}.get(name, name)
        disp, encode = display_image(view, img if img.ndim == 3 else np.repeat(img[:, :, None], 3, axis=2))
        panels[name] = srgb_encode(disp) if encode else np.clip(disp, 0, 1)
    return panels


def write_outputs(result: Any, out: Path, method: str, exr: bool = False) -> list[str]:
    """Write the image as ``out`` asks (.exr + PNG, .png, .npy; ``exr``: the EXR too) and the JSON sidecar; returns the paths.

    ``out`` itself is written under exactly its name; the files beside it share its stem. ``gbuffer`` writes
    every field as a named layer of ``out`` (.exr), one EXR per field beside it, and a labelled contact sheet.
    """
    from grisx.imageio import write_exr, write_exr_layers, write_png
    from grisx.render.driver import METHODS
    from grisx.render.views import display_image

    out = check_output(out)
    fields = tuple(result.extra)
    paths = planned_outputs(out, method, exr, fields)
    check_planned(paths)
    suffix = out.suffix.lower()
    exr_path = out if suffix == ".exr" else out.with_suffix(".exr") if exr else None
    png = out if suffix == ".png" else out.with_suffix(".png")
    written = []
    if suffix == ".npy":
        written.append(str(_write_npy(out, result.image)))
    if exr_path is not None:
        if method == "gbuffer":  # every field a named layer: the file is not any one field in disguise
            written.append(str(write_exr_layers(exr_path, result.extra)))
        else:
            written.append(str(write_exr(exr_path, result.image)))
    extras: dict[str, Any] = {}
    if suffix == ".npy":
        pass  # data only (and the EXR if asked)
    elif METHODS[method].kind == "debug":
        if method == "gbuffer":
            if exr_path is not None:
                written += [str(write_exr(out.with_suffix(f".{name}.exr"), img)) for name, img in result.extra.items()]
            written.append(str(write_png(png, contact_sheet(_gbuffer_panels(result.extra)), encode=False)))
            extras["panels"] = list(fields)  # the contact sheet's panels, row by row, four to a row
        else:
            disp, encode = display_image(method, result.image)
            written.append(str(write_png(png, disp, encode=encode)))
    else:
        written.append(str(write_png(png, result.image)))
        for name, img in result.extra.items():  # gradient-domain methods: primal, dx, dy beside the reconstruction
            written.append(str(write_exr(out.with_suffix(f".{name}.exr"), img)))
    sidecar = out.with_suffix(".json")
    written.append(str(sidecar))
    from grisx.eval.files import write_json

    write_json(sidecar, render_record(result, written, **extras))
    return written


def render_record(result: Any, written: list[str], **extras: Any) -> dict[str, Any]:
    """What ``render --json`` prints and the JSON sidecar holds: one schema (the CLI contract's keys first)."""
    from grisx import __version__

    s = result.settings
    return {
        "method": s["method"],
        "scene": s["scene"],
        "width": s["width"],
        "height": s["height"],
        "frames": result.frames,
        "spp": result.spp,
        "seconds": {"total": result.seconds, **result.pass_seconds},
        "device": result.device,
        "output": list(written),
        "seed": s["seed"],
        "params": s["params"],
        "nonfinite_samples": s.get("nonfinite_samples", 0),
        **({"statistics": s["statistics"]} if "statistics" in s else {}),
        "accumulate": s["accumulate"],
        "camera": s["camera"],
        "features": s["features"],
        "triangles": s["triangles"],
        "grisx_version": __version__,
        **extras,
    }


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
            print(json_line({"method": m.name, "summary": m.summary, "kind": m.kind, "uses_spp": m.uses_spp,
                             "reference_max_depth": m.reference_max_depth, "params": [p.describe() for p in m.params]}))
        else:
            print(method_help(args.method))
        return 0
    if args.json:
        print(json_line({name: {"summary": m.summary, "kind": m.kind, "params": [p.name for p in m.params]} for name, m in METHODS.items()}))
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

    from grisx.progress import Progress

    out = check_output(args.out, formats=(".exr",)) if args.out is not None else None
    if out is not None:
        check_planned([out, out.with_suffix(".variance.exr"), out.with_suffix(".png")])
    with executor_from_args(args) as executor, Progress(args.spp, f"reference {args.scene}", unit="spp") as bar:
        ref = reference(
            args.scene,
            res=parse_res(args.res) if args.res else None,
            spp=args.spp,
            max_depth=args.max_depth,
            device=args.device,
            seed=args.seed,
            force=args.force,
            progress=bar,
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
        print(json_line({**ref.settings, "cached": ref.cached, "output": written}))
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


def _render(args: argparse.Namespace) -> int:

    from grisx.render.driver import parse_res, render

    params: dict[str, Any] = {}
    for key, value in args.param:
        if key in params:
            raise InvalidParameterError(f"--param '{key}' given twice")
        params[key] = value
    res = parse_res(args.res) if args.res else None
    stem = Path(args.scene).stem if args.scene.lower().endswith(".xml") else args.scene
    out = check_output(args.out if args.out is not None else f"{stem}-{args.method}.exr")
    check_planned(planned_outputs(out, args.method, args.exr))
    progress = _RenderProgress(f"{stem} {args.method}", args.frames)
    try:
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
            progress=progress.frame,
            on_sample=progress.sample,
        )
    finally:
        progress.bar.close()
    written = write_outputs(result, out, args.method, exr=args.exr)
    if args.json:
        print(json_line(json.loads(Path(written[-1]).read_text())))  # the sidecar, as written
    else:
        print(f"{result.settings['scene']}: {args.method}, {result.settings['width']}x{result.settings['height']}, "
              f"{result.frames} frame(s) x {result.spp} spp in {result.seconds:.3f} s on {result.device} -> {written[0]}")
    return 0
