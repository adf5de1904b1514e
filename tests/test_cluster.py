"""Beyond one process: executors, chunked references, distributed and resumable studies (issue 25).

The claims, each checked against the single-process run at the same seeds:

* a reference split into chunks is the same image (bit for bit) wherever its chunks run — in process,
  on two worker processes (the multi-device path, here two logical CPU workers), or as Ray tasks —
  because chunk k holds samples k·chunk_spp, … of the counter RNG's stream and chunks are merged in
  chunk order in float64; a reference of one chunk keeps its pre-chunking cache key;
* a study's JSON has the same numbers on every executor;
* a failed or killed task is retried and reported; one that keeps failing is an error naming it;
* an interrupted reference or study resumes without rendering anything already written.

The Ray tests start one local Ray instance (2 CPUs) for the module and skip, saying so, without Ray.
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from grisx.cli import main
from grisx.errors import GrisxError
from grisx.eval.runner import render_study
from grisx.executor import DeviceExecutor, InProcessExecutor, Task
from grisx.render import reference as R

SCENE, RES = "cornell-box", (16, 12)
STUDY = dict(frames=[1, 2], res=RES, reference_spp=8, final_metrics=(), warmup=False, seeds=[1, 2], progress=False)


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("GRISX_CACHE_DIR", str(tmp_path / "cache"))


def _stream_image(spp: int) -> tuple[np.ndarray, np.ndarray]:
    """The path tracer's image of one sample stream, as references were rendered before chunking."""
    from grisx.device import resolve_device
    from grisx.render.driver import load_scene
    from grisx.render.pt import PathTracer

    pt = PathTracer(load_scene(SCENE).build(resolve_device("cpu")), *RES, spp=spp, max_depth=16, seed=0)
    pt.add_samples(0, spp)
    return pt.mean().astype(np.float32), pt.variance_of_mean()


# ---- tasks for the executors (module level: worker processes import them) ----
def flaky(value: int, marker: str, how: str, device: str = "cpu") -> int:
    """Fails on its first attempt (raises, or kills its process), then returns ``value``."""
    if not os.path.exists(marker):
        Path(marker).write_text("failed once")
        if how == "kill":
            os._exit(3)
        raise RuntimeError("transient failure")
    return value


def always_fails(device: str = "cpu") -> None:
    raise RuntimeError("broken for good")


def bad_input(device: str = "cpu") -> None:
    raise GrisxError("unknown thing 'x'")


def unknown_name(device: str = "cpu") -> None:
    from grisx.errors import UnknownNameError

    raise UnknownNameError("render method", "nosuch", ["pt"])  # takes 3 arguments: does not unpickle as it is


def _numbers(study: dict) -> dict:
    """What a study measured, without the clocks (which differ between any two runs)."""
    clocks = {"seconds", "renderer_seconds", "seconds_per_frame", "efficiency", "pass_seconds", "renderer_device"}
    out = {}
    for scene, s in study["scenes"].items():
        out[scene] = {"noise": s.get("reference_noise"), "methods": {
            lab: {k: ([{f: v for f, v in r.items() if f not in clocks} for r in m["records"]] if k == "records" else v)
                  for k, v in m.items() if k not in clocks | {"renderer_settings"}}
            for lab, m in s["methods"].items()}}
    return out


# ---- chunked references ----
def test_one_chunk_reference_keeps_its_key_and_its_image():
    ref = R.reference(SCENE, res=RES, spp=4)
    from grisx import __version__

    settings = {"scene": SCENE, "width": RES[0], "height": RES[1], "spp": 4, "max_depth": 16, "seed": 0, "grisx_version": __version__}
    old_key = hashlib.sha256(json.dumps({**settings, "identity": R._scene_identity(SCENE)}, sort_keys=True).encode()).hexdigest()[:24]
    assert ref.path.stem == old_key  # references stored before chunking stay valid
    image, variance = _stream_image(4)
    assert np.array_equal(ref.image, image) and np.array_equal(ref.variance, variance)
    assert R._chunks(10, 4) == [(0, 4), (4, 4), (8, 2)]
    assert R.reference(SCENE, res=RES, spp=8, chunk_spp=4).path.stem != R.reference(SCENE, res=RES, spp=8, chunk_spp=8).path.stem


def test_chunked_reference_on_two_device_workers_equals_the_in_process_one():
    here = R.reference(SCENE, res=RES, spp=8, chunk_spp=2)
    with DeviceExecutor(["cpu", "cpu"]) as ex:
        there = R.reference(SCENE, res=RES, spp=8, chunk_spp=2, force=True, executor=ex)
    assert np.array_equal(here.image, there.image) and np.array_equal(here.variance, there.variance)
    assert set(there.settings["throughput"]) == {"cpu#0", "cpu#1"}  # both workers rendered, each reported
    assert sum(d["spp"] for d in there.settings["throughput"].values()) == 8
    # a chunked reference estimates the stream's image: equal up to float64 summation order
    assert np.allclose(here.image, _stream_image(8)[0], rtol=1e-6, atol=1e-7)


def test_overlapping_chunks_are_caught_by_the_same_comparison():
    """The sibling: chunks that all start at sample 0 (not disjoint) give another image."""
    ref = R.reference(SCENE, res=RES, spp=4, chunk_spp=2)
    same = [R.render_chunk(SCENE, *RES, 16, 0, 0, 2) for _ in range(2)]
    wrong = ((same[0]["total"] + same[1]["total"]) / 4).astype(np.float32)
    assert not np.array_equal(ref.image, wrong)


class _Interrupt(InProcessExecutor):
    """Stops (as Ctrl-C would) when it is asked for task number ``stop``; records the tasks it started.

    ``backwards``: takes the tasks last first, so chunks finish ahead of the merged prefix.
    """

    def __init__(self, stop: int | None = None, backwards: bool = False) -> None:
        super().__init__("cpu")
        self.stop, self.backwards, self.started = stop, backwards, []

    def run(self, tasks):
        tasks = list(tasks)
        return super().run(tasks[::-1] if self.backwards else tasks)

    def _start(self, task: Task, slot: int):
        if self.stop is not None and len(self.started) == self.stop:
            raise KeyboardInterrupt
        self.started.append(task.key)
        return super()._start(task, slot)


@pytest.mark.parametrize("backwards, left, rendered_after", [
    (False, ["prefix.npz"], [3, 4]),  # chunks 0-2 merged into the prefix
    (True, ["chunk-00003.npz", "chunk-00004.npz"], [0, 1, 2]),  # chunks 4, 3 kept until 0-2 arrive
])
def test_interrupted_reference_resumes_without_rendering_a_chunk_twice(backwards, left, rendered_after):
    whole = R.reference(SCENE, res=RES, spp=10, chunk_spp=2)
    whole.path.unlink()
    with pytest.raises(KeyboardInterrupt):
        R.reference(SCENE, res=RES, spp=10, chunk_spp=2, executor=_Interrupt(stop=len(left) if backwards else 3, backwards=backwards))
    chunk_dir = whole.path.parent / f"{whole.path.stem}.chunks"
    assert sorted(p.name for p in chunk_dir.iterdir()) == left
    rest = _Interrupt()
    resumed = R.reference(SCENE, res=RES, spp=10, chunk_spp=2, executor=rest)
    assert rest.started == [f"{SCENE} chunk {i}" for i in rendered_after] and resumed.settings["resumed_chunks"] == 5 - len(rendered_after)
    assert np.array_equal(resumed.image, whole.image) and np.array_equal(resumed.variance, whole.variance)
    assert not chunk_dir.exists()  # nothing left beside the finished reference


# ---- retries ----
def test_failed_and_killed_tasks_are_retried_and_reported(tmp_path):
    with InProcessExecutor("cpu", retries=1) as ex:
        got = list(ex.run([Task("t", flaky, dict(value=7, marker=str(tmp_path / "a"), how="raise"))]))
    assert got[0][1] == 7 and got[0][2].attempts == 2 and "transient failure" in got[0][2].errors[0]
    with DeviceExecutor(["cpu", "cpu"], retries=1) as ex:
        got = {t.key: (v, r) for t, v, r in ex.run([Task(f"k{i}", flaky, dict(value=i, marker=str(tmp_path / f"k{i}"), how="kill"))
                                                    for i in range(3)])}
        assert ex.retried and all(r["attempts"] == 2 for r in ex.retried)
        # bad input raised in a worker comes back as a one-line GrisxError, not a dead worker, and is not retried
        with pytest.raises(GrisxError, match=r"^unknown render method 'nosuch' \(known: pt\)$"):
            list(ex.run([Task("u", unknown_name)]))
        assert ex.reports[-1].attempts == 1
    assert {k: v for k, (v, _) in got.items()} == {"k0": 0, "k1": 1, "k2": 2}
    assert all("died" in r.errors[0] for _, r in got.values())


def test_a_task_that_keeps_failing_is_an_error_naming_it_and_bad_input_is_not_retried():
    ex = InProcessExecutor("cpu", retries=2)
    with pytest.raises(GrisxError, match=r"task doomed failed after 3 attempts: RuntimeError: broken for good"):
        list(ex.run([Task("doomed", always_fails)]))
    ex = InProcessExecutor("cpu", retries=2)
    with pytest.raises(GrisxError, match="unknown thing 'x'"):
        list(ex.run([Task("bad", bad_input)]))
    assert ex.reports[0].attempts == 1


@pytest.mark.parametrize("argv, message", [
    (["--devices", "cpu,,cpu"], "--devices expects a comma-separated list"),
    (["--devices", "gpu0"], "unknown device 'gpu0'"),
    (["--devices", "cpu", "--address", "h:1"], "--address names a Ray cluster"),
    (["--executor", "ray", "--address", "no port"], "--address must be host:port"),
    (["--executor", "ray", "--devices", "cpu,cpu"], "--devices picks local worker processes"),
])
def test_bad_executor_flags_are_one_line_errors(argv, message, capsys):
    assert main(["reference", SCENE, "--res", "8x8", "--spp", "1", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("grisx: error:") and message in err and "\n" not in err


# ---- studies ----
def test_study_on_two_device_workers_has_the_single_process_numbers(tmp_path):
    one = render_study([SCENE], ["pt", "pt:max_depth=2"], **STUDY)
    with DeviceExecutor(["cpu", "cpu"]) as ex:
        two = render_study([SCENE], ["pt", "pt:max_depth=2"], executor=ex, out=tmp_path, **STUDY)
    assert _numbers(one) == _numbers(two)
    assert two["seeds"] == [1, 2] and set(two["scenes"][SCENE]["methods"]["pt"]["seeds"]["final"]) == {"1", "2"}
    assert _numbers(json.loads((tmp_path / "render_study.json").read_text())) == json.loads(json.dumps(_numbers(two)))


def test_resumed_study_recomputes_nothing_already_written(tmp_path):
    sys.path.insert(0, str(Path(__file__).parent / "eval"))
    from fake_renderer import FakeRenderer

    fake = FakeRenderer()
    kw = dict(methods=["noisy", "noisy:sigma=0.2"], frames=[1, 3], res=RES, seeds=[1, 2], final_metrics=(), out=tmp_path,
              render=fake, reference=fake.reference, progress=False)
    first = render_study(["a"], **kw)
    assert len([c for c in fake.calls if "render" in c]) == 8  # 2 methods x 2 seeds, each with a warm-up render
    written = json.loads((tmp_path / "render_study.json").read_text())
    fake.calls.clear()
    again = render_study(["a"], **kw)
    assert not [c for c in fake.calls if "render" in c] and len(again["resumed_jobs"]) == 4
    rewritten = json.loads((tmp_path / "render_study.json").read_text())
    this_run = ("resumed_jobs", "tasks")  # what this run read back and what it ran
    assert {k: v for k, v in rewritten.items() if k not in this_run} == {k: v for k, v in written.items() if k not in this_run}
    # an interrupted study: one job was never written; only it is rendered
    next((tmp_path / "jobs" / "a").glob("noisy_sigma=0.2.seed2.json")).unlink()
    fake.calls.clear()
    third = render_study(["a"], **kw)
    assert [(c["method"], c["seed"]) for c in fake.calls if "render" in c and c["frames"] == 3] == [("noisy", 2)]
    assert _numbers(third) == _numbers(first)
    # other settings are another study: nothing is reused
    fake.calls.clear()
    render_study(["a"], **{**kw, "frames": [1, 2]})
    assert len([c for c in fake.calls if "render" in c and c["frames"] == 2]) == 4


def test_bench_render_cli_on_two_device_workers_then_resumed(tmp_path, capsys):
    argv = ["bench", "render", SCENE, "--method", "pt", "--frames", "1,2", "--res", "16x12", "--reference-spp", "4",
            "--final-metrics", "none", "--seeds", "1,2", "--out", str(tmp_path), "--devices", "cpu,cpu"]
    assert main([*argv, "--json"]) == 0
    study = json.loads(capsys.readouterr().out)
    assert study["executor"]["devices"] == ["cpu", "cpu"] and study["resumed_jobs"] == []
    assert {t["worker"] for t in study["tasks"] if "seed" in t["key"]} <= {"cpu#0", "cpu#1"} and len(study["tasks"]) == 3
    assert main(argv) == 0
    assert "resumed 2 job(s)" in capsys.readouterr().out


# ---- Ray (local, 2 CPUs) ----
@pytest.fixture(scope="module")
def ray_executor():
    pytest.importorskip("ray", reason="Ray is not installed (pip install 'grisx[cluster]'); CI installs it with .[test]")
    import ray

    from grisx.executor import RayExecutor

    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])  # the tasks below live in this test file
    ex = RayExecutor("cpu", retries=1, num_cpus=2)
    yield ex
    ex.close()


def test_ray_chunked_reference_equals_the_single_process_one(ray_executor):
    here = R.reference(SCENE, res=RES, spp=8, chunk_spp=2)
    there = R.reference(SCENE, res=RES, spp=8, chunk_spp=2, force=True, executor=ray_executor)
    assert np.array_equal(here.image, there.image) and np.array_equal(here.variance, there.variance)
    assert there.settings["executor"]["executor"] == "ray" and sum(d["chunks"] for d in there.settings["throughput"].values()) == 4


def test_ray_tiny_study_json_equals_the_single_process_one(ray_executor, tmp_path):
    one = render_study([SCENE], ["pt", "pt:max_depth=2"], out=tmp_path / "one", **STUDY)
    ray_executor.reports.clear()
    two = render_study([SCENE], ["pt", "pt:max_depth=2"], out=tmp_path / "ray", executor=ray_executor, **STUDY)
    assert len(ray_executor.reports) == 4 and two["executor"]["executor"] == "ray"
    a, b = (json.loads((tmp_path / d / "render_study.json").read_text()) for d in ("one", "ray"))
    assert _numbers(a) == _numbers(b)


def test_ray_killed_task_is_retried_and_reported(ray_executor, tmp_path):
    ray_executor.reports.clear()
    got = list(ray_executor.run([Task("k", flaky, dict(value=5, marker=str(tmp_path / "k"), how="kill"))]))
    assert got[0][1] == 5 and got[0][2].attempts == 2 and ray_executor.retried[0]["key"] == "k"


def test_toy_study_with_several_seeds_keeps_the_first_seeds_tables():
    from grisx.eval.runner import toy_study

    one = toy_study("ris-1d", ["mc", "ris"], trials=[1000, 4000], seed=3, progress=False)
    many = toy_study("ris-1d", ["mc", "ris"], trials=[1000, 4000], seeds=[3, 4], progress=False)
    assert many["seeds"] == [3, 4] and len(many["rows"]) == 2 * len(one["rows"])
    drop = {"seconds", "efficiency", "trials_per_second", "rmse_at_equal_time", "efficiency_ratio", "rmse_over_seeds"}
    assert [{k: v for k, v in r.items() if k not in drop} for r in one["equal_time"]] == \
           [{k: v for k, v in r.items() if k not in drop} for r in many["equal_time"]]
    rmse = [[r["rmse"] for r in many["rows"] if r["method"] == "ris" and r["trials"] == 4000 and r["seed"] == s][0] for s in (3, 4)]
    assert rmse[0] != rmse[1] and many["equal_time"][1]["rmse_over_seeds"] == pytest.approx(float(np.sqrt(np.mean(np.square(rmse)))))
