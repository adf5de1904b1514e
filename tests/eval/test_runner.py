"""Studies end to end: a toy study through run_toy, a render study through a fake renderer.

The fake renderer (fake_renderer.py) returns ref · (1 + σ n_f) per frame, so the expected relMSE of
the running average after n frames is known in closed form:
E[relMSE_n] = mean_i(ref_i² σ² / (ref_i² + ε)) · s_n / n², with s_n = Σ_{j,k<n} ρ^|j−k| (AR(1) noise),
and over P pixel-channels relMSE_n is a weighted mean of χ²₁ variables whose standard deviation is
√(2 · mean(w²) / P) / mean(w) relative to its mean; the checks allow 4 of those.
"""

from __future__ import annotations

import csv
import io
import json
import math

import numpy as np
import pytest
from fake_renderer import FakeRenderer, known_image
from PIL import Image

from grisx.errors import InvalidParameterError, InvalidValueError
from grisx.eval import runner
from grisx.eval.metrics import RELMSE_EPSILON
from grisx.eval.runner import REFERENCE_SEED, MethodSpec, Progress, render_study, toy_study
from grisx.imageio import read_exr

SIGMA = 0.5


def _expected_relmse(n: int, rho: float) -> tuple[float, float]:
    """Mean and standard deviation of relMSE of the average of n fake frames."""
    ref = known_image().astype(np.float64)
    w = (ref**2 * SIGMA**2 / (ref**2 + RELMSE_EPSILON)).ravel()
    s = n + 2 * sum((n - k) * rho**k for k in range(1, n))
    mean = float(w.mean()) * s / n**2
    return mean, mean * math.sqrt(2 * float((w**2).mean()) / w.size) / float(w.mean())


def _png(path) -> tuple[int, int]:
    with Image.open(path) as im:
        im.verify()
    with Image.open(path) as im:
        return im.size


# ---- small pieces ------------------------------------------------------------------------------------
def test_method_spec_parsing():
    s = MethodSpec.parse("gris:passes=1,mis=pairwise")
    assert (s.method, s.params, s.label) == ("gris", {"passes": "1", "mis": "pairwise"}, "gris:passes=1,mis=pairwise")
    assert MethodSpec.parse("pt") == MethodSpec("pt", {}, "pt")
    assert MethodSpec("ris", {"target": "approx"}).label == "ris:target=approx"
    for bad, why in [(":a=1", "no method name"), ("ris:target", "expected k=v"), ("ris:a=1,a=2", "twice")]:
        with pytest.raises(InvalidParameterError, match=why):
            MethodSpec.parse(bad)


def test_log_log_interpolation():
    assert runner._interp_loglog(2.0, [1.0, 4.0], [1.0, 0.25]) == pytest.approx(0.5)
    assert runner._interp_loglog(4.0, [1.0, 4.0], [1.0, 0.25]) == pytest.approx(0.25)
    assert runner._interp_loglog(0.5, [1.0, 4.0], [1.0, 0.25]) is None


def test_progress_is_quiet_off_a_terminal_and_draws_on_one():
    quiet = io.StringIO()
    bar = Progress(3, "x", stream=quiet)
    for _ in range(3):
        bar.update()
    bar.close()
    assert quiet.getvalue() == ""
    loud = io.StringIO()
    bar = Progress(2, "x", stream=loud, enabled=True)
    bar.update(2, "done")
    bar.close()
    assert "\rx [" in loud.getvalue() and "2/2" in loud.getvalue() and loud.getvalue().endswith("\n")


# ---- toy study ---------------------------------------------------------------------------------------
def test_toy_study_end_to_end(tmp_path):
    study = toy_study("ris-1d", ["mc", "ris:target=approx"], trials=[2_000, 32_000], seed=3, out=tmp_path)
    rows = study["rows"]
    assert [(r["method"], r["trials"]) for r in rows] == [("mc", 2_000), ("mc", 32_000),
                                                          ("ris:target=approx", 2_000), ("ris:target=approx", 32_000)]
    for small, large in ((rows[0], rows[1]), (rows[2], rows[3])):
        # 16x the trials: the predicted RMSE falls by 4 (up to the noise of the stderr estimate)
        assert small["rmse_predicted"] / large["rmse_predicted"] == pytest.approx(4.0, rel=0.15)
        assert large["seconds"] > 0 and large["max_abs_z"] < 5
        # the measured error of the mean is one realization of what stderr predicts
        assert large["rmse"] < 5 * large["rmse_predicted"]
        assert large["efficiency"] == pytest.approx(1 / (large["rmse_predicted"] ** 2 * large["seconds"]))
    table = {r["method"]: r for r in study["equal_time"]}
    assert table["mc"]["efficiency_ratio"] == pytest.approx(1.0)
    assert table["mc"]["rmse_at_equal_time"] == pytest.approx(rows[1]["rmse_predicted"])
    assert study["device"] == "cpu" and study["versions"]["warp"]

    saved = json.loads((tmp_path / "toy_study.json").read_text())
    assert saved["rows"][1]["trials"] == 32_000 and saved["equal_time"][1]["method"] == "ris:target=approx"
    with open(tmp_path / "toy_study.csv", newline="") as f:
        csv_rows = list(csv.DictReader(f))
    assert len(csv_rows) == 4 and float(csv_rows[3]["rmse_predicted"]) == pytest.approx(rows[3]["rmse_predicted"])
    w, h = _png(tmp_path / "toy_error_vs_time.png")
    assert w > 300 and h > 200


def test_toy_study_with_a_budget_climbs_until_a_run_takes_that_long():
    calls = []

    class Est:  # a stand-in for run_toy whose cost is 1 µs per trial
        def __init__(self, trials):
            self.trials, self.seconds = trials, trials * 1e-6
            self.estimate, self.exact, self.stderr = 1.0, 1.0, 1.0 / math.sqrt(trials)
            self.max_abs_z, self.params = 0.0, {}

    def fake_run(problem, method, *, trials, seed, params, device):
        calls.append(trials)
        return Est(trials)

    study = toy_study("any", ["a"], budget=0.05, run=fake_run)
    timed = [r["trials"] for r in study["rows"]]
    assert timed == [1_000, 3_000, 10_000, 30_000, 100_000]  # 0.1 s ≥ 0.05 s: stops there
    assert calls[0] == 1_000 and calls[1:] == timed  # one warm-up run first


def test_toy_study_bad_input():
    with pytest.raises(InvalidParameterError, match="not both"):
        toy_study("ris-1d", ["mc"], trials=[10], budget=1.0)
    with pytest.raises(InvalidParameterError, match="listed twice"):
        toy_study("ris-1d", ["mc", "mc"], trials=[10])
    with pytest.raises(InvalidParameterError, match="trial counts"):
        toy_study("ris-1d", ["mc"], trials=[0])


# ---- render study on the fake renderer -------------------------------------------------------------------
def test_render_study_frames_end_to_end(tmp_path):
    fake = FakeRenderer()
    methods = ["noisy:cost=0.01", "noisy:rho=0.9,cost=0.01"]
    study = render_study(["box"], methods, frames=[1, 4, 64], seed=5, out=tmp_path, render=fake,
                         reference=fake.reference, final_metrics=("flip", "flip_ldr"))
    scene = study["scenes"]["box"]
    assert (scene["width"], scene["height"]) == (16, 12) and scene["scanline"] == 6

    # the reference: rendered once, with the reference seed; warm-up renders use yet another seed
    assert [c for c in fake.calls if "reference" in c] == [{"reference": "box", "seed": REFERENCE_SEED, "spp": 4096}]
    renders = [c for c in fake.calls if "render" in c]
    assert [(c["frames"], c["seed"] != 5) for c in renders] == [(1, True), (64, False)] * 2
    assert all(c["accumulate"] for c in renders)

    for label, rho in (("noisy:cost=0.01", 0.0), ("noisy:rho=0.9,cost=0.01", 0.9)):
        m = scene["methods"][label]
        assert m["frames"] == 64 and not m["stopped_by_budget"] and m["pass_seconds"]
        recs = m["records"]
        assert [r["frame"] for r in recs] == list(range(1, 65))
        # the renderer's clock less the study's own callback time: 0.01 s per frame, up to call overheads
        assert [r["seconds"] for r in recs] == pytest.approx([0.01 * n for n in range(1, 65)], abs=2e-4)
        assert recs[-1]["renderer_seconds"] >= recs[-1]["seconds"]
        for n in (1, 64):
            mean, sd = _expected_relmse(n, rho)
            assert abs(recs[n - 1]["relmse"] - mean) < 4 * sd, (label, n, recs[n - 1]["relmse"], mean, sd)
        # FLIP only at kept frames, and it falls as frames accumulate
        assert [r["frame"] for r in recs if "flip" in r] == [1, 4, 64]
        assert recs[63]["flip"] < recs[0]["flip"] and recs[63]["flip_ldr"] < recs[0]["flip_ldr"]
        assert m["final"]["relmse"] == recs[63]["relmse"]
        assert m["efficiency"] == pytest.approx(1 / (recs[63]["relmse"] * recs[63]["seconds"]))
        # frame 64 alone, recovered from two running averages, has one frame's error (noise variance 1)
        mean, sd = _expected_relmse(1, 0.0)
        assert abs(recs[63]["frame_relmse"] - mean) < 4 * sd and recs[0]["frame_relmse"] == recs[0]["relmse"]

    eq = scene["equal_time"]
    assert eq["baseline"] == "noisy:cost=0.01" and eq["rows"][0]["ratio"] == pytest.approx(1.0)
    assert eq["seconds"] == pytest.approx(0.64, abs=2e-4)
    assert eq["rows"][1]["ratio"] < 0.5  # correlated frames converge slower at equal cost

    # files
    saved = json.loads((tmp_path / "render_study.json").read_text())
    assert saved["settings"]["relmse_epsilon"] == RELMSE_EPSILON and saved["settings"]["frames"] == [1, 4, 64]
    assert saved["scenes"]["box"]["methods"]["noisy:cost=0.01"]["records"][3]["frame"] == 4
    with open(tmp_path / "render_study.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 128 and {"scene", "method", "frame", "seconds", "relmse", "frame_relmse", "flip"} <= set(rows[0])
    assert rows[0]["flip"] != "" and rows[1]["flip"] == ""
    assert float(rows[-1]["relmse"]) == pytest.approx(scene["methods"]["noisy:rho=0.9,cost=0.01"]["final"]["relmse"])
    sdir = tmp_path / "box"
    np.testing.assert_array_equal(read_exr(sdir / "reference.exr"), known_image())
    final = read_exr(sdir / "noisy_cost=0.01.exr")
    assert final.shape == (12, 16, 3)
    from grisx.eval.metrics import relmse

    assert relmse(final, known_image()) == pytest.approx(scene["methods"]["noisy:cost=0.01"]["final"]["relmse"], rel=1e-5)
    for png in ("error_vs_time.png", "grid.png", "xt.png"):
        w, h = _png(sdir / png)
        assert w > 300 and h > 200, png


def test_render_study_stops_when_the_budget_is_spent(tmp_path):
    fake = FakeRenderer()
    study = render_study(["box"], ["noisy:cost=0.004"], budget=0.05, render=fake, reference=fake.reference,
                         final_metrics=(), out=tmp_path)
    m = study["scenes"]["box"]["methods"]["noisy:cost=0.004"]
    secs = [r["seconds"] for r in m["records"]]
    assert m["stopped_by_budget"] and m["frames"] == 13 and secs[-1] >= 0.05 > secs[-2]  # 13 · 0.004 s ≥ 0.05 s
    assert study["scenes"]["box"]["equal_time"]["seconds"] == 0.05
    assert _png(tmp_path / "box" / "grid.png")[0] > 300  # relative-error maps (no FLIP asked for)
    assert json.loads((tmp_path / "render_study.json").read_text())["settings"]["budget"] == 0.05


def test_render_study_records_the_reference_noise():
    fake = FakeRenderer(reference_variance=0.002)
    study = render_study(["box"], ["noisy:cost=0.01"], frames=[2], render=fake, reference=fake.reference, final_metrics=())
    ref = known_image().astype(np.float64)
    noise = study["scenes"]["box"]["reference_noise"]
    assert noise["mse"] == pytest.approx(0.002)
    assert noise["relmse"] == pytest.approx(np.mean(0.002 / (ref**2 + RELMSE_EPSILON)), rel=1e-6)
    assert "reference_noise" not in render_study(["box"], ["noisy"], frames=[1], render=FakeRenderer(),
                                                 reference=FakeRenderer().reference, final_metrics=())["scenes"]["box"]


def test_render_study_bad_input():
    fake = FakeRenderer()
    kw = dict(render=fake, reference=fake.reference, final_metrics=())
    with pytest.raises(InvalidValueError, match=r"scene 'box' method 'noisy:nan_frame=2' frame 3 image has 1 NaN"):
        render_study(["box"], ["noisy:nan_frame=2"], frames=[4], **kw)
    with pytest.raises(InvalidValueError, match=r"frame 1 image has shape \(6, 8, 3\) but reference"):
        render_study(["box"], ["noisy:half=1"], frames=[2], **kw)
    with pytest.raises(InvalidParameterError, match="reference seed"):
        render_study(["box"], ["noisy"], frames=[2], seed=REFERENCE_SEED, **kw)
    with pytest.raises(InvalidParameterError, match="scanline 12"):
        render_study(["box"], ["noisy"], frames=[2], scanline=12, **kw)
    with pytest.raises(InvalidParameterError, match="both"):
        render_study(["box"], ["noisy"], frames=[2], render=fake)
    with pytest.raises(InvalidParameterError, match="not both"):
        render_study(["box"], ["noisy"], frames=[2], budget=1.0, **kw)
