"""L2 screened Poisson reconstruction: exact DCT solver and Warp PCG.

Ladder: 1×2 and 1×3 images solved by hand → the dense float64 oracle
(conftest) → exact recovery from exact gradients (hypothesis) → PCG against
the DCT within its residual bound, on every device.

Tolerance for the iterative solver. CG stops at a relative residual, so
``r = b - A I`` is known but the error is not; since ``A = α² + L`` has smallest
eigenvalue ``α²``, ``‖I - I*‖₂ ≤ ‖r‖₂ / α²``. The tests recompute ``r`` in
float64 from the returned image (not trusting the solver's own number) and
assert exactly this bound.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import warp as wp
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from grisx.poisson import forward_gradient, reconstruct, solve

ODD_SHAPES = [(1, 1), (1, 7), (7, 1), (2, 2), (5, 8, 3), (9, 6, 3), (4, 3, 1)]


def _problem(shape: tuple[int, ...], seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random float32 primal and gradients (not consistent with each other)."""
    rng = np.random.default_rng(seed)
    return tuple(rng.standard_normal(shape).astype(np.float32) for _ in range(3))


# ---- hand-computed cases ----


@pytest.mark.parametrize("solver", ["dct", "cg"])
def test_1x3_pure_gradient_by_hand(solver, device):
    """α = 1, P = 0, dx = [1, 1]: (1 + L)I = ∇ᵀg = [-1, 0, 1], so I = [-1/2, 0, 1/2]."""
    if solver == "dct" and device != "cpu":
        pytest.skip("the DCT solver runs on the CPU only")
    primal = np.zeros((1, 3))
    dx = np.array([[1.0, 1.0, 123.0]])  # last column ignored
    dy = np.zeros((1, 3))
    out = reconstruct(primal, dx, dy, alpha=1.0, device=device, solver=solver, tol=1e-6)
    # DCT: float64 rounding; CG: float32, 3 unknowns converge in ≤ 3 steps, rounding ~1e-7
    assert_allclose(out, [[-0.5, 0.0, 0.5]], rtol=0, atol=1e-6)


@pytest.mark.parametrize("solver", ["dct", "cg"])
def test_1x2_pure_primal_by_hand(solver, device):
    """α = 1, P = [1, 3], dx = [0]: [[2, -1], [-1, 2]] I = [1, 3], so I = [5/3, 7/3]."""
    if solver == "dct" and device != "cpu":
        pytest.skip("the DCT solver runs on the CPU only")
    out = reconstruct(np.array([[1.0, 3.0]]), np.zeros((1, 2)), np.zeros((1, 2)), alpha=1.0,
                      device=device, solver=solver, tol=1e-6)
    assert_allclose(out, [[5 / 3, 7 / 3]], rtol=0, atol=1e-6)


# ---- the exact solver against the dense oracle ----


@pytest.mark.parametrize("shape", ODD_SHAPES)
def test_dct_matches_dense_solve(shape, dense):
    primal, dx, dy = (a.astype(np.float64) for a in _problem(shape, 3))
    got = reconstruct(primal, dx, dy, alpha=0.2, solver="dct")
    want = dense.solve_l2(primal, dx, dy, 0.2)
    assert got.dtype == np.float64 and got.shape == primal.shape
    # cond(A) ≤ (α²+8)/α² = 201; both solves are float64 backward stable, so ~1e-13 relative
    assert_allclose(got, want, rtol=0, atol=1e-11 * max(1.0, np.abs(want).max()))


@settings(max_examples=30, deadline=None)
@given(h=st.integers(1, 12), w=st.integers(1, 12), c=st.sampled_from([None, 1, 3]),
       alpha=st.floats(0.01, 10.0), seed=st.integers(0, 2**31 - 1))
def test_dct_exact_recovery(h, w, c, alpha, seed):
    """G = ∇P ⇒ I = P: P is the exact minimiser (energy 0)."""
    shape = (h, w) if c is None else (h, w, c)
    truth = np.random.default_rng(seed).standard_normal(shape)
    g = forward_gradient(truth)
    got = reconstruct(truth, g.dx, g.dy, alpha=alpha, solver="dct")
    # float64 transforms: error ~ cond · 1e-16 ≤ (1 + 8/α²) · 1e-16 ≤ 1e-11 for α ≥ 0.01
    assert_allclose(got, truth, rtol=0, atol=1e-10)


def test_dct_keeps_float32_for_float32_input():
    primal, dx, dy = _problem((4, 5, 3), 0)
    res = solve(primal, dx, dy, solver="dct")
    assert res.image.dtype == np.float32
    assert res.solver == "dct" and res.iterations == 0 and res.device == "cpu"
    # residual of the float32-rounded result: ~ unit roundoff of float32 times cond
    assert res.residual < 1e-5
    assert res.seconds > 0.0


# ---- the iterative solver (Warp PCG) ----


@pytest.mark.parametrize("shape", ODD_SHAPES)
def test_cg_exact_recovery_from_zero(shape, device, dense):
    truth = np.random.default_rng(7).standard_normal(shape).astype(np.float32)
    g = forward_gradient(truth)
    dx, dy = g.dx.astype(np.float32), g.dy.astype(np.float32)
    res = solve(truth, dx, dy, alpha=0.2, device=device, solver="cg", initial="zero", tol=1e-6)
    assert res.image.dtype == np.float32 and res.image.shape == truth.shape
    bound = dense.residual_norm(res.image, truth, dx, dy, 0.2) / 0.2**2
    err = np.linalg.norm((res.image.astype(np.float64) - truth).ravel())
    assert err <= bound * (1 + 1e-6) + 1e-12
    # and the bound itself is small: the solve converged to ~float32 precision
    assert err <= 1e-3 * np.linalg.norm(truth.ravel())


@pytest.mark.parametrize("shape", [(1, 9), (9, 1), (6, 7), (11, 10, 3)])
@pytest.mark.parametrize("tol", [1e-3, 1e-5])
def test_cg_agrees_with_dct_to_its_tolerance(shape, tol, device, dense):
    """The iterative L2 on `device` against the CPU direct solver, within ‖r‖/α²."""
    primal, dx, dy = _problem(shape, 11)
    direct = reconstruct(primal, dx, dy, alpha=0.2, device="cpu", solver="dct").astype(np.float64)
    res = solve(primal, dx, dy, alpha=0.2, device=device, solver="cg", initial="zero", tol=tol)
    b_norm = dense.residual_norm(np.zeros(primal.shape), primal, dx, dy, 0.2)  # ‖b - A·0‖ = ‖b‖
    r_norm = dense.residual_norm(res.image, primal, dx, dy, 0.2)
    # the stopping rule holds for the true residual too (float32 drift of the recurrence ≪ tol)
    assert r_norm <= 1.5 * tol * b_norm
    err = np.linalg.norm((res.image - direct).ravel())
    assert err <= r_norm / 0.2**2 * (1 + 1e-6) + 1e-9


@settings(max_examples=15, deadline=None)
@given(h=st.integers(1, 10), w=st.integers(1, 10), c=st.sampled_from([None, 3]),
       tol=st.sampled_from([1e-2, 1e-4, 1e-5]), seed=st.integers(0, 2**31 - 1))
def test_cg_residual_below_tolerance(h, w, c, tol, seed):
    shape = (h, w) if c is None else (h, w, c)
    primal, dx, dy = _problem(shape, seed)
    res = solve(primal, dx, dy, solver="cg", device="cpu", tol=tol, initial="zero")
    # the reported residual is recomputed from the image in float32: allow float32 drift
    assert res.residual <= tol + 1e-6


def test_cg_warns_when_max_iter_is_reached():
    primal, dx, dy = _problem((16, 16), 5)
    with pytest.warns(RuntimeWarning, match="CG stopped after 3 iterations"):
        res = solve(primal, dx, dy, solver="cg", device="cpu", max_iter=3, tol=1e-6, initial="zero")
    assert res.iterations == 3 and res.residual > 1e-6


def test_cg_exact_initial_guess_needs_no_iteration():
    truth = np.random.default_rng(2).random((5, 6, 3)).astype(np.float32)
    g = forward_gradient(truth)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = solve(truth, g.dx, g.dy, solver="cg", device="cpu")  # initial="primal"
    assert res.iterations == 0
    # the exact gradients were rounded to float32 once: the primal is exact to ~1e-7
    assert_allclose(res.image, truth, rtol=0, atol=1e-6)


def test_zero_channel_gives_zero_and_no_nan(device):
    """b = 0 in one channel: CG must not divide 0/0 (p·Ap = 0)."""
    primal, dx, dy = _problem((5, 4, 3), 9)
    primal[..., 1] = dx[..., 1] = dy[..., 1] = 0.0
    out = reconstruct(primal, dx, dy, device=device, solver="cg", initial="zero")
    assert np.isfinite(out).all()
    assert_allclose(out[..., 1], 0.0, rtol=0, atol=0)


# ---- Warp arrays in, Warp arrays out ----


@pytest.mark.parametrize("form", ["hw", "hwc", "vec3"])
@pytest.mark.parametrize("solver", ["dct", "cg"])
def test_warp_arrays_round_trip(form, solver, device):
    if solver == "dct" and device != "cpu":
        pytest.skip("the DCT solver runs on the CPU only")
    shape = (5, 7) if form == "hw" else (5, 7, 3)
    arrays = _problem(shape, 4)
    want = reconstruct(*arrays, solver="dct")
    dtype = wp.vec3 if form == "vec3" else wp.float32
    wa = [wp.array(a, dtype=dtype, device=device) for a in arrays]
    got = reconstruct(*wa, solver=solver, tol=1e-6)
    assert isinstance(got, wp.array)
    assert got.dtype == dtype and got.shape == wa[0].shape and str(got.device) == str(wa[0].device)
    # float32 CG at tol 1e-6: error ≤ ‖r‖/α² ≈ 25·1e-6·‖b‖, well inside 1e-4
    assert_allclose(got.numpy().reshape(want.shape), want, rtol=0, atol=1e-4)
