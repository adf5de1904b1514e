"""Shared fixtures: every test that takes ``device`` runs on cpu, and on cuda when Warp finds one."""

import os

import pytest
from hypothesis import settings

from grisx.device import cuda_available, init

init()

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
