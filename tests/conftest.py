"""Shared fixtures: every test that takes ``device`` runs on cpu, and on cuda when Warp finds one; the
session's shared folder for work done once across xdist workers (:mod:`session_cache`)."""

import os
import shutil
import tempfile
from pathlib import Path

import pytest
import session_cache
import warp as wp
from hypothesis import settings

# One kernel set per renderer for every scene (``grisx.scene.material.kernel_kinds``): the suite renders ~100 scenes
# whose material kinds differ, and each combination was its own compilation of each renderer (on a cold kernel cache,
# most of CI's time). Specialising on a scene's kinds leaves images bit-identical; test_pt checks that it does.
os.environ.setdefault("GRISX_KERNEL_KINDS", "all")

from grisx.device import cuda_available, init  # noqa: E402

init()
# No test differentiates a kernel: the kernels that tests define compile their forward code only (grisx's own modules
# already do). test_path_shift's round-trip harness, which inlines a whole path shift, compiled 46 s with its adjoint.
wp.config.enable_backward = False


def pytest_configure(config: pytest.Config) -> None:
    # one folder per session for the work its xdist workers share (session_cache): made by the process that
    # starts the workers, before it starts them, so they inherit its name; removed by that process at the end
    if not hasattr(config, "workerinput") and session_cache.ENV not in os.environ:
        config._grisx_shared = tempfile.mkdtemp(prefix="grisx-tests-")
        os.environ[session_cache.ENV] = config._grisx_shared
    session_cache.compile_once()


def pytest_terminal_summary(terminalreporter, config: pytest.Config) -> None:
    folder = getattr(config, "_grisx_shared", None)
    for line in session_cache.compile_report(Path(folder)) if folder else []:
        terminalreporter.write_line(line)


def pytest_unconfigure(config: pytest.Config) -> None:
    folder = getattr(config, "_grisx_shared", None)
    if folder is not None:
        shutil.rmtree(folder, ignore_errors=True)
        os.environ.pop(session_cache.ENV, None)

# Property tests draw their examples from a fixed seed, like every other test here: a failure is
# reproducible and CI cannot pass or fail by luck. GRISX_HYPOTHESIS=explore searches afresh each run.
settings.register_profile("ci", derandomize=True, print_blob=True)
settings.register_profile("explore", derandomize=False, print_blob=True)
settings.load_profile(os.environ.get("GRISX_HYPOTHESIS", "ci"))

DEVICES = ["cpu", pytest.param("cuda", marks=pytest.mark.cuda)]


@pytest.fixture(params=DEVICES)
def device(request: pytest.FixtureRequest) -> str:
    if request.param == "cuda" and not cuda_available():
        pytest.skip("no CUDA device: Warp found none on this machine (CI is CPU-only)")
    return request.param
