"""`grisx poisson` through its argparse registration (grisx.poisson.cli)."""

from __future__ import annotations

import argparse
import json

import numpy as np
import pytest
import warp as wp
from numpy.testing import assert_allclose

from grisx.device import init
from grisx.errors import GrisxError
from grisx.imageio import read_exr, write_exr
from grisx.poisson import forward_gradient, operators
from grisx.poisson.cli import add_parser, run


@pytest.fixture(autouse=True, scope="module")
def _warp_initialised():
    # Initialise Warp and load the kernels before capturing stdout, so that these tests check
    # the command's own output even if Warp's start-up or module-load lines were not silenced.
    init()
    wp.load_module(operators, device="cpu")


def _parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="grisx")
    add_parser(parser.add_subparsers(dest="command", required=True))
    return parser.parse_args(argv)


@pytest.fixture
def buffers(tmp_path):
    truth = np.random.default_rng(0).random((6, 9, 3)).astype(np.float32)
    g = forward_gradient(truth)
    paths = {n: tmp_path / f"{n}.exr" for n in ("primal", "dx", "dy")}
    write_exr(paths["primal"], truth)
    write_exr(paths["dx"], g.dx)
    write_exr(paths["dy"], g.dy)
    return truth, paths


def _argv(paths, out, *extra: str) -> list[str]:
    return ["poisson", "--primal", str(paths["primal"]), "--dx", str(paths["dx"]),
            "--dy", str(paths["dy"]), "--out", str(out), *extra]


@pytest.mark.parametrize("extra", [(), ("--norm", "L1", "--preset", "fast"), ("--norm", "l2", "--solver", "cg")])
def test_cli_reconstructs_and_reports_json(buffers, tmp_path, capsys, extra):
    truth, paths = buffers
    out = tmp_path / "I.exr"
    args = _parse(_argv(paths, out, "--json", "--alpha", "0.3", *extra))
    assert args.handler is run
    assert args.handler(args) == 0
    report = json.loads(capsys.readouterr().out)
    for key in ("output", "norm", "alpha", "solver", "device", "width", "height", "channels",
                "seconds", "residual", "iterations", "outer_iterations", "energy"):
        assert key in report
    assert report["output"] == str(out) and report["alpha"] == 0.3
    assert (report["width"], report["height"], report["channels"]) == (9, 6, 3)
    assert report["norm"] == ("L1" if "L1" in extra else "L2")
    # exact gradients: the reconstruction is the primal to float32 precision
    assert_allclose(read_exr(out), truth, rtol=0, atol=1e-5)


def test_cli_plain_output_is_one_line(buffers, tmp_path, capsys):
    _, paths = buffers
    args = _parse(_argv(paths, tmp_path / "I.exr"))
    assert run(args) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("wrote ")


def test_cli_missing_input_is_a_grisx_error_and_writes_nothing(buffers, tmp_path):
    _, paths = buffers
    paths = dict(paths, dx=tmp_path / "nope.exr")
    out = tmp_path / "I.exr"
    with pytest.raises(GrisxError, match="nope.exr"):
        run(_parse(_argv(paths, out)))
    assert not out.exists()


def test_cli_mismatched_sizes_write_nothing(buffers, tmp_path):
    _, paths = buffers
    write_exr(paths["dy"], np.zeros((6, 8, 3), dtype=np.float32))
    out = tmp_path / "I.exr"
    with pytest.raises(GrisxError, match="^dy has shape"):
        run(_parse(_argv(paths, out)))
    assert not out.exists()
    assert list(tmp_path.glob("*.tmp.exr")) == []


def test_cli_rejects_unknown_norm_at_parse_time(buffers, tmp_path):
    _, paths = buffers
    with pytest.raises(SystemExit):
        _parse(_argv(paths, tmp_path / "I.exr", "--norm", "L3"))
