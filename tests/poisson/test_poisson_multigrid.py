"""The multigrid preconditioner of CG (grisx.poisson.multigrid), against dense float64 matrices.

CG needs M to be a fixed symmetric positive definite operator; the V-cycle is one only if its
coarse operators are Pᵀ A P and its smoothing is symmetric about the coarse correction. The
tests build M column by column on small odd-sized grids (L2 and IRLS-weighted) and check
exactly that, each with a sibling that breaks one ingredient and is caught.
"""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from grisx.poisson import cg as cgm
from grisx.poisson import multigrid as mg
from grisx.poisson import reconstruct
from grisx.poisson.reconstruct import _to_planar, as_warp_input

ALPHA = 0.2


def _system(h: int, w: int, weighted: bool, seed: int = 0) -> cgm.PlanarSystem:
    rng = np.random.default_rng(seed)
    planar = [wp.array(rng.random((1, h * w)).astype(np.float32), device="cpu") for _ in range(4)]
    s = cgm.allocate_system(*planar, h, w, ALPHA, weighted, preconditioner="multigrid")
    if weighted:  # IRLS-like weights over three decades
        for a in (s.wpri, s.wx, s.wy):
            a.assign(10.0 ** rng.uniform(-1.0, 2.0, size=(1, h * w)).astype(np.float32))
    cgm.assemble(s, weighted)
    return s


def _operator(h: int, w: int, wpri: np.ndarray, wx: np.ndarray, wy: np.ndarray) -> np.ndarray:
    """Dense α² W_p + ∇ᵀ W_g ∇ on an h × w grid (wx[y, x]: edge to x + 1; wy[y, x]: edge to y + 1)."""
    n = h * w
    a = np.diag(ALPHA**2 * wpri.ravel().astype(np.float64))
    for y in range(h):
        for x in range(w):
            i = y * w + x
            for j, wt in ((i + 1, wx[y, x] if x + 1 < w else 0.0), (i + w, wy[y, x] if y + 1 < h else 0.0)):
                if wt:
                    a[i, i] += wt
                    a[j, j] += wt
                    a[i, j] -= wt
                    a[j, i] -= wt
    return a


def _aggregation(h: int, w: int) -> np.ndarray:
    hc, wc = (h + 1) // 2, (w + 1) // 2
    p = np.zeros((h * w, hc * wc))
    for y in range(h):
        for x in range(w):
            p[y * w + x, (y // 2) * wc + x // 2] = 1.0
    return p


def _fine_weights(s: cgm.PlanarSystem, weighted: bool) -> tuple[np.ndarray, ...]:
    shape = (s.height, s.width)
    if not weighted:
        return np.ones(shape), np.ones(shape), np.ones(shape)
    return tuple(a.numpy()[0].reshape(shape) for a in (s.wpri, s.wx, s.wy))


def _preconditioner_matrix(s: cgm.PlanarSystem, weighted: bool) -> np.ndarray:
    """M column by column: z = M e_i from one V-cycle."""
    n = s.height * s.width
    cols = []
    for i in range(n):
        e = np.zeros((1, n), dtype=np.float32)
        e[0, i] = 1.0
        s.r.assign(e)
        s.scal.zero_()
        s.multigrid.precondition(weighted, s.z, 0)
        cols.append(s.z.numpy()[0].astype(np.float64))
    return np.stack(cols, axis=1)


@pytest.mark.parametrize("weighted", [False, True])
@pytest.mark.parametrize("shape", [(7, 9), (6, 11), (13, 5)])
def test_coarse_levels_are_the_galerkin_products(shape, weighted):
    """Every level's stencil is Pᵀ A P of the level above, exactly (to float32), at odd sizes and with weights."""
    h, w = shape
    s = _system(h, w, weighted)
    fine = _operator(h, w, *_fine_weights(s, weighted))
    for lv in s.multigrid.levels:
        p = _aggregation(h, w)
        galerkin = p.T @ fine @ p
        got = _operator(lv.height, lv.width, *(a.numpy()[0].reshape(lv.height, lv.width) for a in (lv.wpri, lv.wx, lv.wy)))
        np.testing.assert_allclose(got, galerkin, rtol=1e-5, atol=1e-5 * np.abs(galerkin).max())
        np.testing.assert_allclose(lv.dinv.numpy()[0], 1.0 / np.diag(galerkin), rtol=1e-5)
        fine, h, w = galerkin, lv.height, lv.width
    assert (h, w) == (1, 1)


def test_coarse_weights_averaged_instead_of_summed_are_caught():
    """The sibling: a restriction that averages (Pᵀ/4) makes another coarse operator than Pᵀ A P."""
    h, w = 7, 9
    s = _system(h, w, False)
    lv = s.multigrid.levels[0]
    p = _aggregation(h, w)
    galerkin = p.T @ _operator(h, w, *_fine_weights(s, False)) @ p
    averaged = _operator(lv.height, lv.width, *(a.numpy()[0].reshape(lv.height, lv.width) / 4.0 for a in (lv.wpri, lv.wx, lv.wy)))
    assert np.abs(averaged - galerkin).max() > 0.1 * np.abs(galerkin).max()


@pytest.mark.parametrize("weighted", [False, True])
def test_the_v_cycle_is_symmetric_positive_definite_and_clusters_the_spectrum(weighted):
    h, w = 9, 13
    s = _system(h, w, weighted)
    m = _preconditioner_matrix(s, weighted)
    a = _operator(h, w, *_fine_weights(s, weighted))
    assert np.abs(m - m.T).max() <= 1e-5 * np.abs(m).max()
    assert np.linalg.eigvalsh(0.5 * (m + m.T)).min() > 0.0
    # M A's spectrum against Jacobi's D⁻¹ A: the condition number CG's rate depends on
    kappa_mg = np.linalg.cond(np.linalg.cholesky(0.5 * (m + m.T)).T @ a @ np.linalg.cholesky(0.5 * (m + m.T)))
    d = np.diag(1.0 / np.sqrt(np.diag(a)))
    kappa_jacobi = np.linalg.cond(d @ a @ d)
    assert kappa_mg < 0.25 * kappa_jacobi


def test_a_cycle_without_its_post_smoothing_is_not_symmetric(monkeypatch):
    """The sibling: drop the finest level's last sweep (z = the corrected guess) and M is no longer symmetric."""
    h, w = 9, 13
    s = _system(h, w, False)
    m_ok = _preconditioner_matrix(s, False)
    assert np.abs(m_ok - m_ok.T).max() <= 1e-5 * np.abs(m_ok).max()
    monkeypatch.setattr(mg, "post_smooth_dot", _corrected_guess)
    m_bad = _preconditioner_matrix(s, False)
    assert np.abs(m_bad - m_bad.T).max() > 1e-2 * np.abs(m_bad).max()


@wp.kernel
def _corrected_guess(r: wp.array2d(dtype=wp.float32), wpri: wp.array2d(dtype=wp.float32), wx: wp.array2d(dtype=wp.float32),
                     wy: wp.array2d(dtype=wp.float32), dinv: wp.array2d(dtype=wp.float32), ec: wp.array2d(dtype=wp.float32),
                     corrected: int, weighted: int, a2: float, omega: float, h: int, w: int, wc: int,
                     rows: int, strips: int, lanes: int, z: wp.array2d(dtype=wp.float32), scal: wp.array2d(dtype=wp.float32),
                     slot: int):
    """post_smooth_dot's signature, z = the corrected guess: the finest level's last sweep left out."""
    c, by, bx, lane = wp.tid()
    for j in range(rows):
        y = by * rows + j
        for strip in range(strips):
            xx = (bx * strips + strip) * lanes + lane
            if y < h and xx < w:
                z[c, y * w + xx] = mg._presmoothed(r, dinv, ec, corrected, weighted, a2, omega, c, y * w + xx, y, xx, h, w, wc)


def test_multigrid_cg_needs_a_sixth_of_jacobis_iterations_on_a_rendered_like_frame():
    """Same stopping rule, same answer (the exact DCT solve within CG's bound), far fewer iterations."""
    rng = np.random.default_rng(1)
    h, w = 54, 96
    yy, xx = np.mgrid[0:h, 0:w] / 96.0
    truth = np.stack([np.sin(5 * xx + c) * np.cos(3 * yy) + (xx > 0.4) + 1.0 for c in range(3)], axis=2)
    from grisx.poisson import forward_gradient

    g = forward_gradient(truth)
    frame = [np.asarray(a + s * rng.standard_normal(a.shape), dtype=np.float32) for a, s in ((truth, 0.3), (g.dx, 0.05), (g.dy, 0.05))]
    exact = reconstruct(*[a.astype(np.float64) for a in frame], alpha=ALPHA, solver="dct")
    iterations = {}
    for pre in ("jacobi", "multigrid"):
        planar = [_to_planar(as_warp_input(n, wp.array(a, dtype=wp.vec3, device="cpu")), wp.get_device("cpu"))
                  for n, a in zip(("primal", "dx", "dy"), frame)]
        s = cgm.allocate_system(*planar, wp.clone(planar[0]), h, w, ALPHA, False, preconditioner=pre)
        cgm.assemble(s, False)
        report = cgm.solve_cg(s, False, 1e-5, 500)
        assert report.converged
        image = np.moveaxis(s.x.numpy().reshape(3, h, w), 0, 2)
        b = np.linalg.norm(s.b.numpy().ravel().astype(np.float64))
        assert np.linalg.norm((image - exact).ravel()) <= 1.5e-5 * b / ALPHA**2
        iterations[pre] = report.iterations
    assert iterations["multigrid"] * 6 <= iterations["jacobi"], iterations
