"""The user's surface (issue 39): bad input is found before the work and named in one line, dropped samples are
said, JSON is strict, long work shows progress, outputs are what was asked for. Tiny renders only (seconds)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from grisx.cli import main
from grisx.errors import GrisxError

RES = "8x6"


def run_cli(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def one_error_line(capsys, *argv) -> str:
    code, out, err = run_cli(capsys, *argv)
    lines = err.strip().splitlines()
    assert code == 2 and out == "" and len(lines) == 1 and lines[0].startswith("grisx: error:"), (code, out, err)
    return lines[0]


def strict_json(text: str) -> dict:
    def refuse(name: str) -> None:
        raise AssertionError(f"not strict JSON: {name}")

    return json.loads(text, parse_constant=refuse)


@pytest.fixture
def no_rendering(monkeypatch):
    """Kernels are loaded just before the first frame: reaching that means the check came too late."""
    import grisx.render.driver as driver

    def refuse(*args, **kwargs):
        raise AssertionError("rendering started: the bad input was not found before the work")

    monkeypatch.setattr(driver, "load_kernels", refuse)


# ---- 1. an unwritable output is found before the render -----------------------------------------


@pytest.mark.skipif(not __import__("os").path.isdir("/proc/self"), reason="needs Linux's /proc (a directory no file can be created in)")
def test_an_unwritable_out_is_refused_before_rendering(tmp_path, capsys, no_rendering):
    line = one_error_line(capsys, "render", "cornell-box", "--method", "pt", "--res", RES, "--out", "/proc/grisx-test.exr")
    assert "/proc" in line and "cannot write" in line


@pytest.mark.skipif(not __import__("os").path.isdir("/proc/self"), reason="needs Linux's /proc")
def test_an_unwritable_cache_dir_is_refused_before_the_reference_renders(tmp_path, capsys, monkeypatch):
    import grisx.render.reference as reference

    monkeypatch.setenv("GRISX_CACHE_DIR", "/proc/grisx-cache")
    monkeypatch.setattr(reference, "render_chunk", lambda **kw: (_ for _ in ()).throw(AssertionError("rendered")))
    line = one_error_line(capsys, "reference", "cornell-box", "--res", "4x4", "--spp", "2")
    assert "GRISX_CACHE_DIR" in line and "/proc/grisx-cache" in line


def test_an_out_that_is_a_directory_is_refused_before_rendering(tmp_path, capsys, no_rendering):
    (tmp_path / "x.png").mkdir()  # the PNG beside x.exr cannot be written
    line = one_error_line(capsys, "render", "cornell-box", "--method", "pt", "--res", RES, "--out", str(tmp_path / "x.exr"))
    assert "x.png" in line and "is a directory" in line
    line = one_error_line(capsys, "render", "cornell-box", "--method", "pt", "--res", RES, "--out", str(tmp_path))
    assert "is a directory" in line


# ---- 2. integers that would wrap at 32 bits are refused -----------------------------------------


@pytest.mark.parametrize("argv, fragment", [
    (["render", "cornell-box", "--method", "pt", "--param", "max_depth=4294967297"], "32-bit"),
    (["render", "cornell-box", "--method", "restir-pt", "--param", "candidates=4294967297"], "32-bit"),
    (["render", "cornell-box", "--method", "pt", "--spp", "1e12"], "2^31"),
    (["render", "cornell-box", "--method", "pt", "--spp", "65536", "--frames", "65536"], "2^31"),
])
def test_integers_that_would_wrap_are_refused(tmp_path, capsys, no_rendering, argv, fragment):
    line = one_error_line(capsys, *argv, "--res", RES, "--out", str(tmp_path / "x.exr"))
    assert fragment in line


def test_integers_that_would_wrap_are_refused_by_the_python_api(no_rendering):
    from grisx.render.driver import render

    with pytest.raises(GrisxError, match="32-bit"):
        render("cornell-box", "pt", res=(8, 6), spp=1, params={"max_depth": 2**32 + 1})
    with pytest.raises(GrisxError, match="2\\^31"):
        render("cornell-box", "pt", res=(8, 6), spp=2**31)


# ---- 3. render() checks res, scene and params ----------------------------------------------------


@pytest.mark.parametrize("kwargs, fragment", [
    ({"res": (0, 0)}, "width"),
    ({"res": (-4, 6)}, "width"),
    ({"res": (32.5, 24)}, "integer"),
    ({"res": (8, 6.0)}, "integer"),
    ({"res": (100_000, 100_000)}, "between 1 and 16384"),
    ({"res": "8x6"}, "(width, height)"),
    ({"res": (8,)}, "(width, height)"),
    ({"res": (True, 6)}, "integer"),
    ({"params": ["max_depth"]}, "params must be a mapping"),
    ({"scene": None}, "scene must be"),
    ({"scene": b"cornell-box"}, "scene must be"),
    ({"scene": 42}, "scene must be"),
])
def test_render_checks_res_scene_and_params(no_rendering, kwargs, fragment):
    from grisx.render.driver import render

    call = {"scene": "cornell-box", "res": (8, 6), **kwargs}
    with pytest.raises(GrisxError) as info:
        render(call.pop("scene"), "pt", spp=1, **call)
    assert fragment in str(info.value)


def test_a_film_larger_than_memory_is_refused_before_anything_is_allocated(tmp_path, capsys, monkeypatch, no_rendering):
    import grisx.device as device

    monkeypatch.setattr(device, "available_memory", lambda dev: 2**30, raising=False)  # 1 GiB free
    line = one_error_line(capsys, "render", "cornell-box", "--method", "pt", "--res", "4096x4096", "--out", str(tmp_path / "x.exr"))
    assert "4096x4096" in line and "GiB" in line


# ---- 4. dropped non-finite samples are said ------------------------------------------------------


def hot_cornell_box(tmp_path):
    """The Cornell box with its light at 3.4e38 (finite in float32): pt drops a few samples that overflow."""
    import re
    from pathlib import Path

    text = (Path(__file__).parent / "scene" / "data" / "cornell_box.xml").read_text()
    xml = tmp_path / "hot.xml"
    xml.write_text(re.sub(r'name="radiance" value="[^"]*"', 'name="radiance" value="3.4e38"', text))
    return xml


def test_dropped_non_finite_samples_print_one_warning_line(tmp_path, capsys):
    xml = hot_cornell_box(tmp_path)
    code, out, err = run_cli(capsys, "render", str(xml), "--method", "pt", "--res", RES, "--spp", "4", "--out", str(tmp_path / "h.exr"), "--json")
    assert code == 0
    dropped = strict_json(out)["nonfinite_samples"]
    assert dropped > 0
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("grisx: warning:") and f"dropped {dropped} non-finite" in lines[0], err


def test_the_python_api_warns_of_dropped_samples(tmp_path):
    from grisx.errors import GrisxWarning
    from grisx.render.driver import render

    with pytest.warns(GrisxWarning, match="non-finite"):
        render(str(hot_cornell_box(tmp_path)), "pt", res=(8, 6), spp=4)


# ---- 5. strict JSON ------------------------------------------------------------------------------


def test_one_trial_gives_null_not_infinity(capsys):
    code, out, _ = run_cli(capsys, "toy", "run", "ris-1d", "--method", "ris", "--trials", "1", "--json")
    assert code == 0
    d = strict_json(out)
    assert d["z"] is None and d["stderr"] is None and d["trials"] == 1 and isinstance(d["estimate"], float)
    code, out, _ = run_cli(capsys, "toy", "run", "ris-1d", "--method", "ris", "--trials", "1")
    assert code == 0 and "z = n/a" in out and "inf" not in out.lower()


def test_vector_problems_give_null_per_component(capsys):
    code, out, _ = run_cli(capsys, "toy", "run", "reconnection-flatland", "--method", "gris", "--param", "pixels=3", "--trials", "1", "--json")
    assert code == 0 and strict_json(out)["z"] == [None, None, None]


# ---- 6. progress, on a terminal and off it, for frames and for spp -----------------------------


@pytest.fixture
def lines_every_time(monkeypatch):
    import grisx.progress

    monkeypatch.setattr(grisx.progress, "LINE_SECONDS", 0.0)


def test_progress_off_a_terminal_is_a_plain_line_with_an_eta_for_spp(tmp_path, capsys, lines_every_time, monkeypatch):
    import time

    import grisx.render.driver as driver

    load = driver.load_kernels
    monkeypatch.setattr(driver, "load_kernels", lambda *a: (load(*a), time.sleep(1.1)))  # compiling is not rendering
    code, _, err = run_cli(capsys, "render", "cornell-box", "--method", "pt", "--res", RES, "--spp", "4", "--out", str(tmp_path / "p.exr"))
    assert code == 0
    lines = err.strip().splitlines()
    assert "\r" not in err and len(lines) >= 4, err
    assert all("cornell-box pt:" in ln and "ETA" in ln and " spp " in ln for ln in lines)
    assert "4/4 spp" in lines[-1] and "00:00 elapsed" in lines[-1]  # the clock starts after the kernels are loaded


def test_progress_counts_frames_for_methods_without_spp(tmp_path, capsys, lines_every_time):
    code, _, err = run_cli(capsys, "render", "cornell-box", "--method", "albedo", "--res", RES, "--frames", "3", "--out", str(tmp_path / "a.png"))
    assert code == 0 and "3/3 frame" in err and "ETA" in err


def test_progress_on_a_terminal_is_a_bar(tmp_path, capsys, monkeypatch):
    import sys

    import grisx.progress

    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    line = one_error_line(capsys, "render", "cornell-box", "--method", "nope", "--out", str(tmp_path / "p.exr"))
    assert "\r" not in line  # input refused at once draws no bar
    monkeypatch.setattr(grisx.progress, "BAR_DELAY_SECONDS", 0.0)
    code, _, err = run_cli(capsys, "render", "cornell-box", "--method", "pt", "--res", RES, "--spp", "3", "--frames", "2", "--out", str(tmp_path / "p.exr"))
    assert code == 0 and "\r" in err and "6/6 spp" in err and "eta" in err and "#" in err


def test_short_work_off_a_terminal_prints_nothing(tmp_path, capsys):
    code, _, err = run_cli(capsys, "render", "cornell-box", "--method", "pt", "--res", RES, "--spp", "2", "--out", str(tmp_path / "p.exr"))
    assert code == 0 and err == ""


def test_toy_runs_report_progress_off_a_terminal(capsys, lines_every_time, monkeypatch):
    import grisx.theory.toys.base as base

    monkeypatch.setattr(base.ToyProblem, "chunk_trials", 1000)
    code, _, err = run_cli(capsys, "toy", "run", "ris-1d", "--method", "mc", "--trials", "3000")
    assert code == 0 and "ris-1d mc: 3000/3000 trials (100%)" in err and "ETA" in err


def test_studies_report_progress_off_a_terminal(lines_every_time):
    import io

    from grisx.eval.runner import Progress

    stream = io.StringIO()
    bar = Progress(3, "toys ris-1d", unit="run", stream=stream)
    for _ in range(3):
        bar.update(1, "mc")
    bar.close()
    lines = stream.getvalue().splitlines()
    assert len(lines) == 3 and lines[-1].startswith("toys ris-1d: 3/3 run (100%)") and "ETA" in lines[0]


# ---- 7. outputs are what was asked for -----------------------------------------------------------


def test_out_is_written_under_exactly_its_name(tmp_path, capsys):
    code, out, _ = run_cli(capsys, "render", "cornell-box", "--method", "pt", "--res", RES, "--spp", "1", "--out", str(tmp_path / "X.EXR"), "--json")
    assert code == 0
    names = sorted(p.name for p in tmp_path.iterdir())
    assert "X.EXR" in names and "X.exr" not in names, names
    assert strict_json(out)["output"][0] == str(tmp_path / "X.EXR")


def test_an_empty_out_is_refused(tmp_path, capsys, monkeypatch, no_rendering):
    monkeypatch.chdir(tmp_path)
    line = one_error_line(capsys, "render", "cornell-box", "--method", "pt", "--res", RES, "--out", "")
    assert "--out must name a file" in line
    assert list(tmp_path.iterdir()) == []


def test_render_json_and_the_sidecar_are_one_record(tmp_path, capsys):
    code, out, _ = run_cli(capsys, "render", "cornell-box", "--method", "pt", "--res", RES, "--spp", "1", "--out", str(tmp_path / "r.exr"), "--json")
    assert code == 0
    printed = strict_json(out)
    assert printed == strict_json((tmp_path / "r.json").read_text())
    assert {"method", "scene", "width", "height", "frames", "spp", "seconds", "device", "output"} <= set(printed)
    assert printed["seconds"]["total"] > 0 and "pt" in printed["seconds"]
    assert printed["output"][-1] == str(tmp_path / "r.json")


def test_gbuffer_panels_are_labelled_and_its_exr_is_no_field_in_disguise(tmp_path, capsys):
    import OpenEXR
    from PIL import Image

    from grisx.imageio import read_exr
    from grisx.render.cli import SHEET_LABEL_HEIGHT, SHEET_PANEL_WIDTH

    out = tmp_path / "g.exr"
    code, _, _ = run_cli(capsys, "render", "cornell-box", "--method", "gbuffer", "--res", RES, "--out", str(out))
    assert code == 0
    panels = strict_json((tmp_path / "g.json").read_text())["panels"]
    assert {"albedo", "normal", "depth", "motion"} <= set(panels)
    with OpenEXR.File(str(out), separate_channels=True) as f:
        channels = set(f.channels())
    assert {"albedo.R", "normal.G", "depth.Y"} <= channels  # every field, each named
    with pytest.raises(GrisxError, match="unsupported channels"):
        read_exr(out)  # not silently the albedo
    np.testing.assert_array_equal(read_exr(tmp_path / "g.albedo.exr").shape, (6, 8, 3))
    sheet = np.asarray(Image.open(tmp_path / "g.png").convert("RGB"))
    k = -(-SHEET_PANEL_WIDTH // 8)
    rows = -(-len(panels) // 4)
    assert sheet.shape == (rows * (SHEET_LABEL_HEIGHT + 6 * k), 4 * 8 * k, 3)
    band = sheet[:SHEET_LABEL_HEIGHT, : 8 * k]
    assert band.max() > 200 and (band > 0).mean() < 0.5  # text drawn on the band above the first panel


# ---- 8. rough messages made clean ----------------------------------------------------------------


SCENE_XML = """<scene version="3.0.0">
  <shape type="rectangle">
    <emitter type="area"><rgb name="radiance" value="{radiance}"/></emitter>
  </shape>
  <sensor type="perspective"><transform name="to_world"><lookat origin="0,0,3" target="0,0,0" up="0,1,0"/></transform></sensor>
</scene>
"""


def test_a_radiance_beyond_float32_is_refused_with_file_and_line(tmp_path, capsys):
    xml = tmp_path / "bright.xml"
    xml.write_text(SCENE_XML.format(radiance="1e300"))
    line = one_error_line(capsys, "render", str(xml), "--method", "pt", "--res", RES, "--out", str(tmp_path / "b.exr"))
    assert f"{xml}:3:" in line and "1e300" in line and "float32" in line
    assert not any(p.name.startswith("b.") for p in tmp_path.iterdir())


def test_load_mitsuba_names_an_empty_path_and_a_directory(tmp_path):
    from grisx.scene.mitsuba import load_mitsuba

    with pytest.raises(GrisxError, match="path is empty"):
        load_mitsuba("")
    with pytest.raises(GrisxError, match="is a directory"):
        load_mitsuba(tmp_path)


def test_load_mitsuba_refuses_a_param_the_file_never_uses(tmp_path):
    from grisx.scene.mitsuba import load_mitsuba

    xml = tmp_path / "s.xml"
    xml.write_text(SCENE_XML.format(radiance="$power").replace("<scene version=\"3.0.0\">",
                                                              "<scene version=\"3.0.0\"><default name=\"power\" value=\"5\"/>"))
    assert load_mitsuba(xml, {"power": 2.0}) is not None
    with pytest.raises(GrisxError, match="powr"):
        load_mitsuba(xml, {"powr": 2.0})


@pytest.mark.parametrize("argv, fragment", [
    (["--res", "-5x5"], "--res must be between 1x1"),
    (["--res", "-5x-5"], "--res must be between 1x1"),
    (["--spp", "-3"], "--spp"),
])
def test_negative_values_reach_the_options_own_check(tmp_path, capsys, argv, fragment):
    line = one_error_line(capsys, "render", "cornell-box", "--method", "pt", *argv, "--out", str(tmp_path / "x.exr"))
    assert fragment in line and "expected one argument" not in line


def test_a_directory_as_scene_is_called_a_directory(tmp_path, capsys):
    line = one_error_line(capsys, "render", str(tmp_path), "--method", "pt", "--res", RES, "--out", str(tmp_path / "x.exr"))
    assert "is a directory" in line and "does not exist" not in line


def test_a_biased_by_design_variant_says_so_beside_its_z(capsys):
    code, out, _ = run_cli(capsys, "toy", "run", "gris-shift", "--method", "gris", "--param", "jacobian=false", "--trials", "2000")
    assert code == 0 and "z =" in out
    assert "biased by design" in out
    code, out, _ = run_cli(capsys, "toy", "run", "gris-shift", "--method", "gris", "--param", "jacobian=false", "--trials", "2000", "--json")
    assert code == 0 and strict_json(out)["biased_by_design"]
    code, out, _ = run_cli(capsys, "toy", "run", "gris-shift", "--method", "gris", "--trials", "2000", "--json")
    assert code == 0 and strict_json(out)["biased_by_design"] is None
    code, out, _ = run_cli(capsys, "toy", "run", "gris-shift", "--method", "gris", "--trials", "2000")
    assert "biased by design" not in out
