"""`grisx compare` and `grisx bench` through grisx.cli.main: output format, one-line errors, exit 2."""

from __future__ import annotations

import json
import subprocess
import sys

import flip_evaluator
import numpy as np
import pytest
from fake_renderer import FakeRenderer

from grisx.cli import main
from grisx.eval import metrics as M
from grisx.eval import runner
from grisx.imageio import write_exr


def run_cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture
def images(tmp_path):
    rng = np.random.default_rng(11)
    ref = (0.1 + 2.0 * rng.random((10, 14, 3))).astype(np.float32)
    test = (ref * (1 + 0.2 * rng.standard_normal(ref.shape))).clip(0, None).astype(np.float32)
    paths = {"test": tmp_path / "test.exr", "ref": tmp_path / "ref.exr"}
    write_exr(paths["test"], test)
    write_exr(paths["ref"], ref)
    return test, ref, paths


def test_compare_json_keys_are_the_metric_names(capsys, images):
    test, ref, p = images
    code, out, err = run_cli(capsys, "compare", p["test"], p["ref"], "--metrics", "mse,relmse,flip", "--json")
    assert code == 0 and err == ""
    values = json.loads(out)
    assert list(values) == ["mse", "relmse", "flip"]
    t, r = test.astype(np.float64), ref.astype(np.float64)
    assert values["mse"] == pytest.approx(np.mean((t - r) ** 2))
    assert values["relmse"] == pytest.approx(np.mean((t - r) ** 2 / (r**2 + 0.01)))
    assert values["flip"] == pytest.approx(float(flip_evaluator.evaluate(ref, test, "HDR")[1]), rel=1e-6)


def test_compare_text_prints_one_line_per_metric(capsys, images):
    test, ref, p = images
    code, out, _ = run_cli(capsys, "compare", p["test"], p["ref"], "--metrics", "rmse,mape,flip_ldr",
                           "--epsilon", "0.5", "--exposure", "-1")
    assert code == 0
    lines = out.splitlines()
    assert [ln.split()[0] for ln in lines] == ["rmse", "mape", "flip_ldr"]
    assert float(lines[1].split()[1]) == pytest.approx(M.mape(test, ref, epsilon=0.5), rel=1e-5)
    assert float(lines[2].split()[1]) == pytest.approx(M.flip_ldr(test, ref, exposure=-1.0), rel=1e-5)


def test_compare_per_channel(capsys, images):
    test, ref, p = images
    code, out, _ = run_cli(capsys, "compare", p["test"], p["ref"], "--metrics", "mse", "--per-channel", "--json")
    values = json.loads(out)
    assert code == 0 and values["mse_per_channel"] == pytest.approx(list(M.mse(test, ref, per_channel=True)))


def _bad(capsys, *argv) -> str:
    code, out, err = run_cli(capsys, *argv)
    assert code == 2 and out == ""
    assert len(err.splitlines()) == 1 and err.startswith("grisx: error: ")
    return err


def test_compare_bad_input_is_one_line_and_exit_2(capsys, images, tmp_path):
    test, ref, p = images
    assert "no such file" in _bad(capsys, "compare", tmp_path / "missing.exr", p["ref"])
    assert "unknown metric 'psnr'" in _bad(capsys, "compare", p["test"], p["ref"], "--metrics", "mse,psnr")
    small = tmp_path / "small.exr"
    write_exr(small, ref[:5])
    err = _bad(capsys, "compare", small, p["ref"])
    assert "small.exr" in err and "shape (5, 14, 3)" in err
    broken = ref.copy()
    broken[3, 4, 0] = np.inf
    nan_path = tmp_path / "broken.exr"
    write_exr(nan_path, broken)
    err = _bad(capsys, "compare", p["test"], nan_path, "--metrics", "mse")
    assert "reference" in err and "broken.exr" in err and "NaN/Inf" in err
    assert "positive number" in _bad(capsys, "compare", p["test"], p["ref"], "--epsilon", "0")


def test_compare_as_a_process_exits_2():
    proc = subprocess.run([sys.executable, "-m", "grisx", "compare", "nope.exr", "nope.exr"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.count("\n") == 1 and "no such file" in proc.stderr


def test_bench_help_documents_both_studies(capsys):
    for sub, words in (("toys", ("--method", "--budget", "--trials", "--out", "baseline")),
                       ("render", ("--method", "--budget", "--frames", "--out", "--reference-spp", "xt.png"))):
        with pytest.raises(SystemExit) as exc:
            main(["bench", sub, "--help"])
        assert exc.value.code == 0
        text = capsys.readouterr().out
        assert all(w in text for w in words), (sub, text)


def test_bench_toys_json(capsys, tmp_path):
    code, out, err = run_cli(capsys, "bench", "toys", "ris-1d", "--method", "mc", "--method", "ris:candidates=4",
                             "--trials", "1e3,4e3", "--out", tmp_path / "t", "--json")
    assert code == 0 and err == ""
    study = json.loads(out)
    assert [r["trials"] for r in study["rows"]] == [1000, 4000, 1000, 4000]
    assert study["rows"][2]["params"]["candidates"] == 4
    assert (tmp_path / "t" / "toy_study.json").is_file() and (tmp_path / "t" / "toy_error_vs_time.png").is_file()


def test_bench_toys_text_and_errors(capsys, tmp_path):
    code, out, _ = run_cli(capsys, "bench", "toys", "ris-1d", "--method", "mc", "--trials", "1000", "--out", tmp_path)
    assert code == 0 and "eff. ratio" in out and "mc" in out
    assert "unknown toy problem 'nope'" in _bad(capsys, "bench", "toys", "nope", "--method", "mc", "--trials", "10", "--out", tmp_path)
    assert "expected k=v" in _bad(capsys, "bench", "toys", "ris-1d", "--method", "ris:target", "--out", tmp_path)
    assert "not allowed with" in _bad(capsys, "bench", "toys", "ris-1d", "--method", "mc", "--budget", "1", "--trials", "10")


def test_bench_render_through_the_cli(capsys, tmp_path, monkeypatch):
    fake = FakeRenderer()
    monkeypatch.setattr(runner, "_default_render", lambda: (fake, fake.reference))
    code, out, err = run_cli(capsys, "bench", "render", "box", "--method", "noisy", "--method", "noisy:rho=0.5",
                             "--frames", "1,8", "--final-metrics", "flip", "--out", tmp_path)
    assert code == 0 and err == ""
    assert "box (16x12)" in out and "noisy:rho=0.5" in out and "flip" in out
    study = json.loads((tmp_path / "render_study.json").read_text())
    assert study["scenes"]["box"]["methods"]["noisy"]["frames"] == 8
    assert (tmp_path / "box" / "xt.png").is_file()
    assert "invalid WxH value" in _bad(capsys, "bench", "render", "box", "--method", "noisy", "--res", "64")
