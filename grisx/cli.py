"""The ``grisx`` command line: the stable surface that scripts and checks use.

    grisx demo [--out PATH] [--trials N]
    grisx toy list [--json]
    grisx toy run NAME --method M [--trials N] [--seed S] [--param k=v ...] [--device cpu|cuda] [--json]
    grisx poisson --primal P.exr --dx DX.exr --dy DY.exr --out I.exr [--norm L1|L2] [--json]
    grisx scenes [--json]
    grisx render SCENE_OR_FILE --method M [--spp N] [--frames F [--accumulate]] [--res WxH]
                 [--device cpu|cuda] [--seed S] [--param k=v ...] [--out PATH.exr] [--json]
    grisx reference SCENE_OR_FILE [--spp N] [--res WxH] [--device cpu|cuda] [--out PATH.exr] [--json]
                    [--devices cuda:0,cuda:1 | --executor ray [--address HOST:PORT]] [--retries N] [--chunk-spp N]
    grisx compare TEST.exr REF.exr [--metrics mse,relmse,flip] [--json]
    grisx bench toys|render ...       (see grisx bench --help)

Bad input prints one line ``grisx: error: …`` on stderr and exits with 2; something the user should know
that did not stop the work (e.g. non-finite samples dropped) prints one line ``grisx: warning: …``.
Every ``--json`` prints strict JSON: ``null`` where a number is undefined (NaN, Inf).
"""

from __future__ import annotations

import argparse
import re
import sys
import warnings
from collections.abc import Sequence
from typing import Any, NoReturn

from grisx.errors import GrisxError, GrisxWarning, InvalidParameterError

__all__ = ["main", "build_parser"]

EXIT_BAD_INPUT = 2


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (the CLI contract)."""

    def error(self, message: str) -> NoReturn:
        # subcommands name themselves ("grisx render: ..."); the top level is already "grisx: error:"
        raise GrisxError(message if self.prog == "grisx" else f"{self.prog}: {message}")


def _count(text: str) -> int:
    """Parse a positive count, accepting 1e6-style notation for whole numbers."""
    try:
        value = float(text)
    except ValueError:
        raise InvalidParameterError(f"expected a positive integer, got '{text}'") from None
    if not value.is_integer() or value <= 0:
        raise InvalidParameterError(f"expected a positive integer, got '{text}'")
    return int(value)


_count.__name__ = "positive integer"  # argparse names the type in its one-line error


def _seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise InvalidParameterError(f"seed must be an integer, got '{text}'") from None
    return value


_seed.__name__ = "integer seed"


def _key_value(text: str) -> tuple[str, str]:
    if "=" not in text:
        raise InvalidParameterError(f"--param expects key=value, got '{text}'")
    key, value = text.split("=", 1)
    if not key:
        raise InvalidParameterError(f"--param expects key=value, got '{text}'")
    return key.strip(), value.strip()


_key_value.__name__ = "key=value"


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="grisx", description="Resampled importance sampling (RIS, GRIS, ReSTIR) with exact answers.")
    from grisx import __version__

    parser.add_argument("--version", action="version", version=f"grisx {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True

    demo = sub.add_parser("demo", help="run every toy problem, print estimates beside exact values, write a figure")
    demo.add_argument("--out", default="grisx-demo.png", help="figure path (PNG); a JSON summary is written beside it")
    demo.add_argument("--trials", type=_count, default=100_000, help="trials per toy run (default 100000; heavy toys take a share)")
    demo.add_argument("--seed", type=_seed, default=0)
    demo.add_argument("--device", default="cpu", help="cpu or cuda")
    demo.set_defaults(handler=_demo)

    toy = sub.add_parser("toy", help="toy problems with exact answers")
    toy_sub = toy.add_subparsers(dest="toy_command", metavar="SUBCOMMAND", parser_class=_Parser)
    toy_sub.required = True
    listing = toy_sub.add_parser("list", help="named toy problems, their methods and params")
    listing.add_argument("--json", action="store_true", help="print one JSON object")
    listing.set_defaults(handler=_toy_list)
    run = toy_sub.add_parser("run", help="run one toy problem with one method")
    run.add_argument("name", help="problem name (see 'grisx toy list')")
    run.add_argument("--method", required=True, help="method name")
    run.add_argument("--trials", type=_count, default=100_000, help="independent trials (default 100000)")
    run.add_argument("--seed", type=_seed, default=0, help="seed (default 0)")
    run.add_argument("--param", type=_key_value, action="append", default=[], metavar="K=V", help="method option (repeatable)")
    run.add_argument("--device", default="cpu", help="cpu (default) or cuda")
    run.add_argument("--json", action="store_true", help="print one JSON object")
    run.set_defaults(handler=_toy_run)

    from grisx.eval.cli import add_parser as add_eval_parser
    from grisx.poisson.cli import add_parser as add_poisson_parser
    from grisx.render.cli import add_parsers as add_scene_parsers

    add_poisson_parser(sub)
    add_scene_parsers(sub, _key_value, _count, _seed)
    add_eval_parser(sub)
    return parser


def _toy_list(args: argparse.Namespace) -> int:
    from grisx.theory.toys import PROBLEMS

    problems = [p.describe() for p in PROBLEMS.values()]
    if args.json:
        from grisx.eval.files import json_line

        print(json_line({"problems": problems}))
        return 0
    for p in problems:
        print(f"{p['name']}: {p['summary']}")
        for m in p["methods"]:
            print(f"  --method {m['name']}: {m['doc']}")
            for prm in m["params"]:
                choices = f" [{'|'.join(prm['choices'])}]" if "choices" in prm else ""
                print(f"      --param {prm['name']}={prm['default']}{choices}  {prm['doc']}")
        for b in p["biased_variants"]:
            kv = " ".join(f"{k}={v}" for k, v in b["params"].items())
            print(f"  biased by design: --method {b['method']} {kv}  ({b['why']})")
    return 0


def _toy_run(args: argparse.Namespace) -> int:
    from grisx.eval.files import json_line
    from grisx.theory.toys import PROBLEMS, run_toy

    params: dict[str, Any] = {}
    for key, value in args.param:
        if key in params:
            raise InvalidParameterError(f"--param '{key}' given twice")
        params[key] = value
    from grisx.progress import Progress

    with Progress(args.trials, f"{args.name} {args.method}", unit="trials") as bar:
        est = run_toy(args.name, args.method, trials=args.trials, seed=args.seed, params=params, device=args.device, progress=bar)
    why = biased_by_design(PROBLEMS[est.problem], est.method, est.params)
    if args.json:
        print(json_line({**est.to_dict(), "biased_by_design": why}))
        return 0
    print(format_estimate(est))
    if why is not None:
        print(f"  note: biased by design ({why}): a large |z| is what this variant is expected to show")
    return 0


def biased_by_design(problem: Any, method: str, params: dict[str, Any]) -> str | None:
    """Why ``method`` with ``params`` is biased by construction (a declared biased variant), or None."""
    return next((b.why for b in problem.biased_variants if b.matches(method, params)), None)


def format_estimate(est: Any) -> str:
    """Human-readable estimate ± stderr beside the exact value and z (n/a where one trial gives no stderr)."""
    import numpy as np

    head = f"{est.problem} / {est.method}  ({est.trials:,} trials, {est.seconds:.3f} s, {est.device})"
    ests, ses, exs, zs = (np.atleast_1d(np.asarray(a, dtype=float)) for a in (est.estimate, est.stderr, est.exact, est.z))
    known = est.trials > 1
    rows = [f"  [{i}] {e: .6f} ± {f'{s:.6f}' if known else 'n/a'}   exact {x: .6f}   z = {f'{z:+.2f}' if known and np.isfinite(z) else 'n/a'}"
            for i, (e, s, x, z) in enumerate(zip(ests, ses, exs, zs))]
    if not known:
        rows.append("  (one trial has no standard error: run at least 2)")
    return "\n".join([head, *rows])


def _demo(args: argparse.Namespace) -> int:
    from grisx.demo import run_demo

    run_demo(out=args.out, trials=args.trials, seed=args.seed, device=args.device)
    return 0


def _values_that_look_like_options(argv: list[str]) -> list[str]:
    """``--res -5x5`` → ``--res=-5x5``: a value starting with '-' and a digit is the option's value (argparse would
    take it for an option and say "expected one argument"), so the option's own check names the problem."""
    out: list[str] = []
    for tok in argv:
        if out and out[-1].startswith("--") and "=" not in out[-1] and re.match(r"^-[0-9.]", tok):
            out[-1] = f"{out[-1]}={tok}"
        else:
            out.append(tok)
    return out


def _show_warning(message: Any, category: type, filename: str, lineno: int, file: Any = None, line: Any = None) -> None:
    """grisx's own warnings as one line ``grisx: warning: ...``; others as Python prints them."""
    if issubclass(category, GrisxWarning):
        print(f"grisx: warning: {str(message).splitlines()[0]}", file=sys.stderr)
    else:
        _python_showwarning(message, category, filename, lineno, file, line)


_python_showwarning = warnings.showwarning


def main(argv: Sequence[str] | None = None) -> int:
    argv = _values_that_look_like_options(list(sys.argv[1:] if argv is None else argv))
    try:
        parser = build_parser()  # imports the layers: a bad GRISX_* setting fails here, as bad input
        with warnings.catch_warnings():
            warnings.simplefilter("always", GrisxWarning)
            warnings.showwarning = _show_warning
            return _run(parser, argv)
    except GrisxError as exc:
        message = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        print(f"grisx: error: {message}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("grisx: interrupted", file=sys.stderr)
        return 130


def _run(parser: argparse.ArgumentParser, argv: list[str]) -> int:
    if argv[:1] == ["render"] and ("-h" in argv or "--help" in argv) and "--method" in argv[:-1]:
        from grisx.render.cli import method_help  # 'render --method M --help': that method's params

        print(method_help(argv[argv.index("--method") + 1]))
        return 0
    args = parser.parse_args(argv)
    return int(args.handler(args))


if __name__ == "__main__":
    sys.exit(main())
