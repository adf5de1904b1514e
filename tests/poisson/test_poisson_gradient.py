"""Conventions of grisx.poisson.gradient: forward differences, adjoint, Laplacian, energy.

Ladder: hand-computed values → the dense oracle (conftest) → properties
(adjointness on random shapes, DCT eigenvectors).
"""

from __future__ import annotations

import numpy as np
import scipy.fft
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from grisx.poisson import forward_gradient, gradient_adjoint, screened_energy, screened_operator
from grisx.poisson.gradient import laplacian_eigenvalues

shapes = st.tuples(st.integers(1, 7), st.integers(1, 7), st.sampled_from([None, 1, 3]))


def _image(shape: tuple[int, int, int | None], seed: int) -> np.ndarray:
    h, w, c = shape
    rng = np.random.default_rng(seed)
    return rng.standard_normal((h, w) if c is None else (h, w, c))


def test_forward_gradient_by_hand():
    img = np.array([[1.0, 2.0, 4.0], [0.0, 5.0, 5.0]])
    g = forward_gradient(img)
    # dx[y, x] = I[y, x+1] - I[y, x]; the last column has no pair and is 0
    assert_allclose(g.dx, [[1.0, 2.0, 0.0], [5.0, 0.0, 0.0]], rtol=0, atol=0)
    # dy[y, x] = I[y+1, x] - I[y, x]; the last row has no pair and is 0
    assert_allclose(g.dy, [[-1.0, 3.0, 1.0], [0.0, 0.0, 0.0]], rtol=0, atol=0)


def test_adjoint_by_hand_ignores_last_column_and_row():
    dx = np.array([[1.0, 2.0, 99.0]])  # 99 sits in the ignored last column
    dy = np.array([[np.nan, np.inf, -np.inf]])  # a 1-row image has no vertical edge at all
    # ∇ᵀg[x] = g[x-1] - g[x]: [-1, 1-2, 2]
    assert_allclose(gradient_adjoint(dx, dy), [[-1.0, -1.0, 2.0]], rtol=0, atol=0)


def test_operator_matches_dense_matrix(dense):
    h, w, alpha = 3, 4, 0.3
    img = _image((h, w, None), 1)
    d, _ = dense.gradient_matrix(h, w)
    expected = (alpha**2 * np.eye(h * w) + d.T @ d) @ img.ravel()
    # float64 sums of a few O(1) terms: agreement to 1e-12 is rounding only
    assert_allclose(screened_operator(img, alpha).ravel(), expected, rtol=0, atol=1e-12)


@settings(max_examples=40, deadline=None)
@given(shape=shapes, seed=st.integers(0, 2**31 - 1))
def test_adjoint_property(shape, seed):
    """<∇I, G> over existing edges equals <I, ∇ᵀG>, whatever the ignored entries hold."""
    img = _image(shape, seed)
    gx, gy = _image(shape, seed + 1), _image(shape, seed + 2)
    g = forward_gradient(img)
    lhs = (g.dx[:, :-1] * gx[:, :-1]).sum() + (g.dy[:-1] * gy[:-1]).sum()
    rhs = (img * gradient_adjoint(gx, gy)).sum()
    # O(50) products of O(1) numbers in float64: 1e-10 absolute is generous rounding slack
    assert_allclose(lhs, rhs, rtol=0, atol=1e-10)


@settings(max_examples=10, deadline=None)
@given(n=st.integers(1, 9), k=st.integers(0, 8))
def test_dct_basis_diagonalises_neumann_laplacian(n, k):
    k = k % n
    v = scipy.fft.idct(np.eye(n)[k], type=2, norm="ortho")  # k-th DCT-II basis vector
    lv = screened_operator(v[None, :], alpha=1.0)[0] - v  # L v = (1 + L) v - v
    assert_allclose(lv, laplacian_eigenvalues(n)[k] * v, rtol=0, atol=1e-12)


def test_energy_by_hand():
    # 1×2 image I = [1, 3], P = [0, 0], dx = [1, ·]: L2 = α²(1 + 9) + (2 - 1)², L1 = α(1 + 3) + 1
    img, primal = np.array([[1.0, 3.0]]), np.zeros((1, 2))
    dx, dy = np.array([[1.0, 7.0]]), np.zeros((1, 2))
    assert_allclose(screened_energy(img, primal, dx, dy, 0.5, "L2"), 0.25 * 10 + 1, rtol=1e-15)
    assert_allclose(screened_energy(img, primal, dx, dy, 0.5, "L1"), 0.5 * 4 + 1, rtol=1e-15)
