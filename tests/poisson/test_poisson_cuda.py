"""GPU-only checks of grisx.poisson (skipped without CUDA; the device fixture covers the rest).

On a GPU the block reductions run with 256 lanes (one lane on the CPU) and the
data never leaves the device; these tests use images larger than one block
per channel so that several blocks add into each CG scalar.
"""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp
from numpy.testing import assert_allclose

from grisx.device import cuda_available
from grisx.poisson import forward_gradient, reconstruct, screened_operator, screened_rhs, solve

pytestmark = [
    pytest.mark.cuda,
    pytest.mark.skipif(not cuda_available(), reason="needs CUDA: Warp found no CUDA device on this machine"),
]


def _frame(h: int, w: int, seed: int = 0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    truth = rng.random((h, w, 3))
    g = forward_gradient(truth)
    return [np.asarray(a + 0.05 * rng.standard_normal(a.shape), dtype=np.float32) for a in (truth, g.dx, g.dy)]


@pytest.mark.parametrize("tol", [1e-4, 1e-5])
def test_cuda_cg_agrees_with_cpu_dct_within_residual_bound(tol):
    primal, dx, dy = _frame(67, 93)  # 6231 pixels: 25 blocks of 256 lanes per channel
    direct = reconstruct(primal, dx, dy, solver="dct").astype(np.float64)
    res = solve(*(wp.array(a, device="cuda") for a in (primal, dx, dy)), solver="cg", tol=tol, initial="zero")
    assert res.device.startswith("cuda") and res.iterations > 0
    image = res.image.numpy().astype(np.float64)
    # Too large for the dense oracle: the residual from the float64 numpy operator instead.
    b = screened_rhs(primal, dx, dy, 0.2)
    r_norm = np.linalg.norm((b - screened_operator(image, 0.2)).ravel())
    assert r_norm <= 1.5 * tol * np.linalg.norm(b.ravel())  # the stopping rule, recomputed in float64
    assert np.linalg.norm((image - direct).ravel()) <= r_norm / 0.2**2 * (1 + 1e-6) + 1e-9


def test_cuda_result_stays_on_device_in_the_input_form():
    primal, dx, dy = _frame(40, 50)
    for dtype, arrays in ((wp.vec3, (primal, dx, dy)), (wp.float32, (primal, dx, dy))):
        wa = [wp.array(a, dtype=dtype, device="cuda") for a in arrays]
        for norm in ("L2", "L1"):
            out = reconstruct(*wa, norm=norm)
            assert isinstance(out, wp.array) and out.device.is_cuda
            assert out.dtype == dtype and out.shape == wa[0].shape


def test_cuda_l1_matches_cpu_l1():
    primal, dx, dy = _frame(48, 64, seed=3)
    cpu = reconstruct(primal, dx, dy, norm="L1", device="cpu", preset="fast")
    gpu = reconstruct(primal, dx, dy, norm="L1", device="cuda", preset="fast")
    # same schedule and float32 arithmetic; only the order of the block sums differs
    assert_allclose(gpu, cpu, rtol=0, atol=1e-3)
