"""``grisx compare`` and ``grisx bench``: image errors and run-time-against-error studies.

::

    grisx compare TEST.exr REF.exr [--metrics mse,relmse,flip] [--per-channel]
                  [--epsilon 0.01] [--exposure EV] [--json]
    grisx bench toys PROBLEM --method SPEC [--method SPEC ...] [--budget S | --trials N,N,...]
                  [--seed S | --seeds S,S,...] [--device cpu|cuda] [--out DIR] [--json]
    grisx bench render SCENE [SCENE ...] --method SPEC [--method SPEC ...]
                  [--budget S | --frames N,N,...] [--spp N] [--res WxH] [--reference-spp N]
                  [--metrics relmse,mse,mape] [--final-metrics flip] [--scanline Y]
                  [--device cpu|cuda] [--seed S | --seeds S,S,...] [--out DIR] [--json] [--no-resume]
                  [--devices cuda:0,cuda:1 | --executor ray [--address HOST:PORT]] [--retries N]

A method SPEC is ``METHOD`` or ``METHOD:k=v,k=v`` (the method's params, as
``--param`` of ``toy run`` / ``render``); the first one is the baseline of the
equal-time table. ``compare --json`` prints one object whose keys are the
metric names; text mode prints one ``name value`` line per metric. Errors are
:class:`~grisx.errors.GrisxError` (``grisx`` prints one line and exits 2).
"""

from __future__ import annotations

import argparse
import math
from typing import Any

from grisx.errors import InvalidParameterError
from grisx.eval import metrics as M
from grisx.eval.files import json_line

__all__ = ["add_parser", "compare_command", "bench_toys_command", "bench_render_command"]


def _positive_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise InvalidParameterError(f"expected a positive number, got '{text}'") from None
    if not (math.isfinite(v) and v > 0):
        raise InvalidParameterError(f"expected a positive number, got '{text}'")
    return v


_positive_float.__name__ = "positive number"


def _float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise InvalidParameterError(f"expected a number, got '{text}'") from None
    if not math.isfinite(v):
        raise InvalidParameterError(f"expected a finite number, got '{text}'")
    return v


_float.__name__ = "number"


def _int(text: str, what: str = "integer", minimum: int | None = 1) -> int:
    try:
        v = float(text)  # accepts 1e6
    except ValueError:
        raise InvalidParameterError(f"expected {what}, got '{text}'") from None
    if not v.is_integer() or (minimum is not None and v < minimum):
        raise InvalidParameterError(f"expected {what}, got '{text}'")
    return int(v)


def _counts(text: str) -> list[int]:
    return [_int(t.strip(), "a comma-separated list of positive integers") for t in text.split(",") if t.strip()]


_counts.__name__ = "N,N,..."


def _pos_int(text: str) -> int:
    return _int(text, "a positive integer")


_pos_int.__name__ = "positive integer"


def _seed(text: str) -> int:
    return _int(text, "a non-negative integer seed", minimum=0)


_seed.__name__ = "seed"


def _seeds(text: str) -> list[int]:
    return [_seed(t.strip()) for t in text.split(",") if t.strip()] or [_seed(text)]


_seeds.__name__ = "S,S,..."


def _res(text: str) -> tuple[int, int]:
    w, sep, h = text.lower().partition("x")
    if not sep:
        raise InvalidParameterError(f"--res expects WxH, got '{text}'")
    return _int(w, "WxH with positive sizes"), _int(h, "WxH with positive sizes")


_res.__name__ = "WxH"


def add_parser(subparsers: Any) -> None:
    """Register ``compare`` and ``bench`` on an argparse ``subparsers`` object."""
    c = subparsers.add_parser(
        "compare",
        help="errors of a test image against a reference image (EXR)",
        description="Errors of TEST against the reference REF, both linear EXR of one shape. "
                    f"relmse = mean((test-ref)^2/(ref^2+eps)) and mape = mean(|test-ref|/(|ref|+eps)) over pixels "
                    f"and channels with eps = {M.RELMSE_EPSILON:g} by default; flip = HDR-FLIP of the linear images "
                    "(flip-evaluator package); flip_ldr = LDR-FLIP of the sRGB-encoded images at --exposure.",
    )
    c.add_argument("test", help="test image (EXR)")
    c.add_argument("reference", help="reference image (EXR)")
    c.add_argument("--metrics", default="mse,rmse,relmse,mape,flip",
                   help=f"comma-separated, from {','.join(M.METRICS)} (default mse,rmse,relmse,mape,flip)")
    c.add_argument("--per-channel", action="store_true", help="also give NAME_per_channel lists (mse, rmse, relmse, mape)")
    c.add_argument("--epsilon", type=_positive_float, default=M.RELMSE_EPSILON,
                   help=f"epsilon of relmse and mape (default {M.RELMSE_EPSILON:g})")
    c.add_argument("--exposure", type=_float, default=0.0, help="exposure in stops before sRGB encoding, for flip_ldr (default 0)")
    c.add_argument("--json", action="store_true", help="print one JSON object keyed by metric name")
    c.set_defaults(handler=compare_command)

    b = subparsers.add_parser(
        "bench",
        help="run-time-against-error studies of toy estimators and renderers",
        description="Equal-time / run-time-against-error studies. Writes JSON, CSV and PNG plots to --out "
                    "and prints a table.",
    )
    # type(b): the caller's parser class (grisx's one-line-error parser), for the sub-subcommands too
    bsub = b.add_subparsers(dest="bench_command", metavar="SUBCOMMAND", parser_class=type(b))
    bsub.required = True

    t = bsub.add_parser(
        "toys",
        help="RMSE against seconds for methods of one toy problem",
        description="Run each --method of toy PROBLEM (via 'grisx toy run' machinery) over a trial ladder and record "
                    "RMSE of the mean against the exact value vs seconds. The first method is the baseline: the table "
                    "gives each method's efficiency 1/(MSE x seconds) relative to it and its RMSE at the baseline's time. "
                    "Writes toy_study.json, toy_study.csv and toy_error_vs_time.png to --out.",
        epilog="example: grisx bench toys ris-1d --method mc --method ris:target=approx --budget 2",
    )
    t.add_argument("problem", help="toy problem (see 'grisx toy list')")
    _study_arguments(t, "seconds: climb 1e3,3e3,1e4,... trials until a run takes this long (default 1)",
                     "--trials", "explicit trial ladder, e.g. 1e4,1e5,1e6", "seed of every run (default 0)")
    t.add_argument("--repeats", type=_pos_int, default=1, help="identical runs per count, fastest kept (default 1)")
    t.add_argument("--seeds", type=_seeds, default=None,
                   help="several seeds, e.g. 1,2,3: every ladder once per seed (the tables are the first seed's)")
    t.set_defaults(handler=bench_toys_command)

    r = bsub.add_parser(
        "render",
        help="error against seconds of renderers on scenes, with image grids and (x,t) plots",
        description="Render each SCENE with each --method, frame by frame (warm-up frame first; device synchronized "
                    "before every clock read), and record per-frame seconds and the errors of the running average of "
                    "the frames against a reference render (--reference-spp, cached by the renderer). relmse uses "
                    f"eps = {M.RELMSE_EPSILON:g} with the reference in the denominator. Writes render_study.json, "
                    "render_study.csv, and per scene error_vs_time.png (log-log), grid.png (images, zoomed insets, "
                    "error maps), xt.png (one scanline over frames: temporal correlation) and EXRs to --out.",
        epilog="example: grisx bench render cornell-box --method pt --method restir-di --budget 10 --res 256x256",
    )
    r.add_argument("scenes", nargs="+", metavar="SCENE", help="built-in scene name or scene file")
    _study_arguments(r, "seconds per method: render frames until spent (default 1)",
                     "--frames", "frame counts to keep, e.g. 1,4,16,64 (runs to the largest)",
                     "seed of the test renders (default 0)")
    r.add_argument("--spp", type=_pos_int, default=1, help="samples per pixel per frame of pt (default 1; the ReSTIR renderers take one a frame)")
    r.add_argument("--res", type=_res, default=None, help="resolution WxH (default: the scene's)")
    r.add_argument("--reference-spp", type=_pos_int, default=4096, help="samples per pixel of the reference (default 4096)")
    r.add_argument("--metrics", default="relmse,mse,mape", help="per-frame metrics; the first is plotted (default relmse,mse,mape)")
    r.add_argument("--final-metrics", default="flip", help="metrics of the kept frames only (default flip; 'none' for none)")
    r.add_argument("--scanline", type=lambda s: _int(s, "a row index", minimum=0), default=None,
                   help="row of the (x,t) plot (default: the middle row)")
    r.add_argument("--seeds", type=_seeds, default=None,
                   help="several seeds, e.g. 1,2,3: every (scene, method) once per seed (the tables are the first seed's)")
    r.add_argument("--no-resume", action="store_true",
                   help="render every job again, even those an earlier run of the same study wrote to --out/jobs")
    from grisx.executor import add_executor_arguments

    add_executor_arguments(r)
    r.set_defaults(handler=bench_render_command)


def _study_arguments(p: argparse.ArgumentParser, budget_help: str, counts_flag: str, counts_help: str, seed_help: str) -> None:
    """Options every study takes: methods, budget or counts, seed, device, output."""
    p.add_argument("--method", action="append", required=True, metavar="SPEC",
                   help="METHOD or METHOD:k=v,k=v (repeatable; the first is the baseline)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--budget", type=_positive_float, help=budget_help)
    g.add_argument(counts_flag, type=_counts, help=counts_help)
    p.add_argument("--seed", type=_seed, default=0, help=seed_help)
    p.add_argument("--device", default="cpu", help="cpu (default), cuda or cuda:N")
    p.add_argument("--out", default="grisx-bench", help="output directory (default ./grisx-bench)")
    p.add_argument("--json", action="store_true", help="print the study as one JSON object")


# ---- handlers ------------------------------------------------------------------------------------
def _fmt(v: Any) -> str:
    if isinstance(v, list):
        return " ".join(_fmt(x) for x in v)
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v)


def compare_command(args: argparse.Namespace) -> int:
    from grisx.imageio import read_exr

    names = M.parse_metrics(args.metrics)  # check names before reading files
    test = read_exr(args.test)
    ref = read_exr(args.reference)
    values = M.compare(test, ref, names, per_channel=args.per_channel, epsilon=args.epsilon, exposure=args.exposure,
                       test_name=f"test '{args.test}'", ref_name=f"reference '{args.reference}'")
    if args.json:
        print(json_line(values))
    else:
        for name, value in values.items():
            print(f"{name} {_fmt(value)}")
    return 0


def _print_json(study: dict[str, Any]) -> None:
    print(json_line(study))


def bench_toys_command(args: argparse.Namespace) -> int:
    from grisx.eval.runner import MethodSpec, toy_study

    study = toy_study(args.problem, [MethodSpec.parse(s) for s in args.method], trials=args.trials, budget=args.budget,
                      repeats=args.repeats, seed=args.seed, device=args.device, out=args.out, seeds=args.seeds)
    if args.json:
        _print_json(study)
        return 0
    print(f"{args.problem} on {study['device']} — equal time {study['settings']['equal_time_seconds']:.3g} s "
          f"(baseline {study['settings']['baseline']})")
    print(f"  {'method':<36} {'trials':>11} {'seconds':>9} {'RMSE@eq.time':>13} {'eff. ratio':>10} {'max|z|':>7}")
    for row in study["equal_time"]:
        ratio = row["efficiency_ratio"]
        z = row["max_abs_z"]
        print(f"  {row['method']:<36} {row['trials']:>11,} {row['seconds']:>9.3g} {row['rmse_at_equal_time']:>13.4g} "
              f"{(f'{ratio:.3g}' if ratio else '-'):>10} {(f'{z:.2f}' if z is not None else '-'):>7}")
    print(f"wrote {', '.join(study['output'].values())}")
    return 0


def bench_render_command(args: argparse.Namespace) -> int:
    from grisx.eval.runner import MethodSpec, render_study

    from grisx.executor import executor_from_args

    finals = [] if args.final_metrics.strip().lower() in ("", "none") else M.parse_metrics(args.final_metrics)
    with executor_from_args(args) as executor:
        study = render_study(args.scenes, [MethodSpec.parse(s) for s in args.method], frames=args.frames,
                             budget=args.budget, spp=args.spp, res=args.res, device=executor.devices[0], seed=args.seed,
                             reference_spp=args.reference_spp, metrics=M.parse_metrics(args.metrics),
                             final_metrics=finals, scanline=args.scanline, out=args.out, seeds=args.seeds,
                             executor=executor, resume=not args.no_resume)
    if args.json:
        _print_json(study)
        return 0
    for scene, s in study["scenes"].items():
        eq = s["equal_time"]
        metric = eq["metric"]
        print(f"{scene} ({s['width']}x{s['height']}) on {study['device']} — equal time {eq['seconds']:.3g} s, "
              f"baseline {eq['baseline']}")
        if "reference_noise" in s and metric in s["reference_noise"]:
            print(f"  (the reference's own noise adds about {s['reference_noise'][metric]:.3g} to every {metric})")
        print(f"  {'method':<32} {'frames':>7} {'seconds':>9} {metric + ' final':>14} {metric + '@eq.t':>13} {'ratio':>7}"
              + "".join(f" {m:>9}" for m in study["settings"]["final_metrics"]))
        for row in eq["rows"]:
            m = s["methods"][row["method"]]
            at, ratio = row[metric], row["ratio"]
            print(f"  {row['method']:<32} {m['frames']:>7} {m['seconds']:>9.3g} {m['final'][metric]:>14.4g} "
                  f"{(f'{at:.4g}' if at is not None else '-'):>13} {(f'{ratio:.3g}' if ratio else '-'):>7}"
                  + "".join(f" {m['final'].get(f, float('nan')):>9.4g}" for f in study["settings"]["final_metrics"]))
    for r in study["retried"]:
        print(f"retried {r['key']}: {r['attempts']} attempts ({'; '.join(r['errors'])})")
    if study["resumed_jobs"]:
        print(f"resumed {len(study['resumed_jobs'])} job(s) from {args.out}/jobs (not rendered again)")
    print(f"wrote {study['output']['json']}, {study['output']['csv']} and per-scene plots")
    return 0
