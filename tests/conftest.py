"""Shared fixtures: every test that takes ``device`` runs on cpu, and on cuda when Warp finds one."""

import pytest

from grisx.device import cuda_available, init

init()

DEVICES = ["cpu", pytest.param("cuda", marks=pytest.mark.cuda)]


@pytest.fixture(params=DEVICES)
def device(request: pytest.FixtureRequest) -> str:
    if request.param == "cuda" and not cuda_available():
        pytest.skip("no CUDA device: Warp found none on this machine (CI is CPU-only)")
    return request.param
