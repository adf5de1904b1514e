"""The CLI contract: `grisx toy list|run`, `grisx demo`, and one-line errors with a non-zero exit."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from grisx.cli import main

CONTRACT_KEYS = {"estimate", "stderr", "exact", "trials", "seconds", "method", "problem"}


def run_cli(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_toy_list_json_names_every_problem_method_and_param(capsys):
    code, out, _ = run_cli(capsys, "toy", "list", "--json")
    assert code == 0
    problems = {p["name"]: p for p in json.loads(out)["problems"]}
    assert {"ris-1d", "gris-shift", "reconnection-flatland"} <= set(problems)
    gris = problems["gris-shift"]["methods"][0]
    assert {p["name"] for p in gris["params"]} >= {"mis", "passes", "jacobian", "cap"}
    assert problems["gris-shift"]["biased_variants"]


def test_toy_list_text(capsys):
    code, out, _ = run_cli(capsys, "toy", "list")
    assert code == 0 and "--param mis=balance" in out and "biased by design" in out


@pytest.mark.parametrize(
    "argv, n",
    [
        (["ris-1d", "--method", "ris", "--param", "target=approx"], 1),
        (["gris-shift", "--method", "gris", "--param", "mis=pairwise", "--param", "passes=2"], 5),
        (["reconnection-flatland", "--method", "gris", "--param", "pixels=3"], 3),
    ],
)
def test_toy_run_json_has_the_contract_fields(capsys, argv, n):
    code, out, _ = run_cli(capsys, "toy", "run", *argv, "--trials", "2e4", "--seed", "5", "--json")
    assert code == 0
    d = json.loads(out)
    assert CONTRACT_KEYS <= set(d)
    assert d["trials"] == 20000 and d["seconds"] > 0
    if n > 1:
        assert len(d["estimate"]) == len(d["stderr"]) == len(d["exact"]) == n
    else:
        assert isinstance(d["estimate"], float)


def test_toy_run_text(capsys):
    code, out, _ = run_cli(capsys, "toy", "run", "ris-1d", "--method", "mc", "--trials", "1000")
    assert code == 0 and "exact" in out and "z =" in out


@pytest.mark.parametrize(
    "argv, text",
    [
        (["toy", "run", "nope", "--method", "ris"], "unknown toy problem 'nope'"),
        (["toy", "run", "ris-1d", "--method", "nope"], "unknown method"),
        (["toy", "run", "ris-1d", "--method", "ris", "--param", "alpha=2"], "unknown param"),
        (["toy", "run", "ris-1d", "--method", "ris", "--param", "candidates=-3"], "candidates"),
        (["toy", "run", "ris-1d", "--method", "ris", "--param", "noequals"], "key=value"),
        (["toy", "run", "gris-shift", "--method", "gris", "--param", "cap=nan"], "finite"),
        (["toy", "run", "ris-1d", "--method", "ris", "--trials", "0"], "--trials"),
        (["toy", "run", "ris-1d", "--method", "ris", "--trials", "-5"], "--trials"),
        (["toy", "run", "ris-1d", "--method", "ris", "--trials", "abc"], "--trials"),
        (["toy", "run", "ris-1d", "--method", "ris", "--device", "tpu"], "unknown device 'tpu'"),
        (["toy", "run", "ris-1d"], "--method"),
        (["toy", "frobnicate"], "invalid choice"),
        (["demo", "--out", "figure.jpg"], ".png"),
    ],
)
def test_bad_input_prints_one_line_and_exits_non_zero(capsys, argv, text):
    code, out, err = run_cli(capsys, *argv)
    assert code == 2
    assert out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("grisx: error:") and text in lines[0], err


def test_console_entry_point_runs_as_a_module():
    proc = subprocess.run(
        [sys.executable, "-m", "grisx", "toy", "run", "ris-1d", "--method", "ris", "--trials", "1000", "--json"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    assert CONTRACT_KEYS <= set(json.loads(proc.stdout))
    bad = subprocess.run([sys.executable, "-m", "grisx", "toy", "run", "x", "--method", "y"], capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and "Traceback" not in bad.stderr and len(bad.stderr.strip().splitlines()) == 1


def test_a_bad_register_budget_in_the_environment_is_one_line_of_bad_input():
    # read when grisx.device is first imported, i.e. while the CLI builds its parser
    env = dict(os.environ, GRISX_PATH_REGISTERS="abc")
    bad = subprocess.run([sys.executable, "-m", "grisx", "scenes"], capture_output=True, text=True, timeout=300, env=env)
    assert bad.returncode == 2 and "Traceback" not in bad.stderr, bad.stderr
    assert bad.stderr.strip().splitlines() == ["grisx: error: GRISX_PATH_REGISTERS='abc': a register budget is an integer from 32 to 255"]


def test_demo_writes_a_figure_and_a_summary(capsys, tmp_path):
    out = tmp_path / "demo.png"
    code, stdout, _ = run_cli(capsys, "demo", "--trials", "20000", "--out", str(out))
    assert code == 0
    assert out.stat().st_size > 10_000
    summary = json.loads(out.with_suffix(".json").read_text())
    assert all("UNEXPECTED" not in r["verdict"] and "NOT caught" not in r["verdict"] for r in summary["runs"])
    assert "caught: biased by design" in stdout
    # every toy problem is shown, and the scene comparison (seed 004) gives both errors
    from grisx.theory.toys import PROBLEMS

    assert {r["problem"] for r in summary["runs"]} == set(PROBLEMS)
    assert summary["scene"]["relmse_pt"] > 0 and summary["scene"]["relmse_restir_gi"] > 0


def test_a_bad_render_param_names_the_render_method():
    from grisx.errors import InvalidParameterError, UnknownNameError
    from grisx.render.driver import render

    with pytest.raises(InvalidParameterError, match="of render method 'restir-gi'"):
        render("cornell-box", "restir-gi", res=(8, 8), params={"mb_fraction": 5})
    with pytest.raises(UnknownNameError, match="render method 'restir-pt'"):
        render("cornell-box", "restir-pt", res=(8, 8), params={"max_bounces": 9})


def test_every_registered_default_is_the_constructors():
    # params are declared once: the registry reads each default from the renderer's constructor
    import inspect

    from grisx.render import pt, restir_di, restir_gi, restir_pt
    from grisx.render.driver import METHODS

    for name, cls in (("pt", pt.PathTracer), ("restir-di", restir_di.ReSTIRDI), ("restir-gi", restir_gi.ReSTIRGI), ("restir-pt", restir_pt.ReSTIRPT)):
        signature = inspect.signature(cls.__init__).parameters
        assert all(p.default == signature[p.name].default for p in METHODS[name].params), name


def test_render_writes_the_format_asked_for(capsys, tmp_path):
    code, _, _ = run_cli(capsys, "render", "cornell-box", "--method", "albedo", "--res", "8x6", "--out", str(tmp_path / "a.png"))
    assert code == 0 and sorted(p.name for p in tmp_path.iterdir()) == ["a.json", "a.png"]
    code, _, _ = run_cli(capsys, "render", "cornell-box", "--method", "pt", "--spp", "1", "--res", "8x6", "--out", str(tmp_path / "b.npy"), "--exr")
    assert code == 0 and np.load(tmp_path / "b.npy").shape == (6, 8, 3) and (tmp_path / "b.exr").is_file()
    code, _, err = run_cli(capsys, "render", "cornell-box", "--method", "pt", "--res", "8x6", "--out", str(tmp_path / "c.jpg"))
    assert code == 2 and err.count("\n") == 1 and ".exr, .png, .npy" in err
    assert not any(p.name.startswith("c.") for p in tmp_path.iterdir())  # nothing half-written


def test_methods_explain_themselves(capsys):
    code, out, _ = run_cli(capsys, "methods")
    assert code == 0 and all(name in out for name in ("pt", "restir-di", "restir-gi", "restir-pt"))
    code, out, _ = run_cli(capsys, "render", "--method", "restir-pt", "--help")
    assert code == 0 and "--param max_depth=" in out and "--param shift=hybrid" in out
    code, _, err = run_cli(capsys, "methods", "nope")
    assert code == 2 and "unknown render method 'nope'" in err


def test_kernel_loads_that_take_a_while_are_announced_on_a_terminal_only(monkeypatch, capsys):
    import sys as _sys

    import grisx.device as device
    from grisx.render.pt import image_from_sum

    monkeypatch.setattr(device, "COMPILE_NOTICE_SECONDS", 0.0)  # every load counts as slow
    monkeypatch.setattr(_sys.stderr, "isatty", lambda: True)
    device.load_kernels([image_from_sum, image_from_sum], "cpu", "pt (diffuse)")
    err = capsys.readouterr().err
    assert err.count("compiling kernels for pt (diffuse)") == 1
    monkeypatch.setattr(_sys.stderr, "isatty", lambda: False)
    device.load_kernels([image_from_sum], "cpu", "pt (diffuse)")
    assert capsys.readouterr().err == ""
