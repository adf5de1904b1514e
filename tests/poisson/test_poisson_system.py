"""The persistent screened Poisson system (grisx.poisson.ScreenedPoisson) a renderer solves every frame.

A sequence of frames is written into the same bound buffers, as a renderer does; each frame's image is
checked against the exact (DCT, float64) solution of *that* frame with CG's own error bound,
‖I − I*‖ ≤ ‖b − A I‖ / α² (the smallest eigenvalue of the L2 system is α²), and its residual, recomputed
in float64, against the stopping rule. Warm starts must not loosen either: the sibling that warm-starts
without the stopping rule (max_iter = 0, so the previous frame's image comes back) fails the same check.
"""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp
from numpy.testing import assert_array_equal

from grisx.errors import InvalidParameterError, UnknownNameError
from grisx.poisson import FRAME_TOL, FrameReconstruction, ScreenedPoisson, frame_tol, forward_gradient, reconstruct, screened_operator, screened_rhs

ALPHA = 0.2
TOL = 1e-5


def _truth(h: int, w: int) -> np.ndarray:
    """The scene's image: smooth shading with an edge."""
    yy, xx = np.mgrid[0:h, 0:w] / max(h, w)
    return np.stack([np.sin(3 * xx + c) * np.cos(2 * yy) + 1.5 + (xx > 0.5) for c in range(3)], axis=2)


def _frames(h: int, w: int, count: int, seed: int = 0) -> list[list[np.ndarray]]:
    """Frames of one scene: a fixed truth, fresh noise in the primal and the gradients each frame."""
    rng = np.random.default_rng(seed)
    truth = _truth(h, w)
    g = forward_gradient(truth)
    return [[np.asarray(a + s * rng.standard_normal(a.shape), dtype=np.float32) for a, s in ((truth, 0.1), (g.dx, 0.02), (g.dy, 0.02))]
            for _ in range(count)]


def _bound(arrays: list[wp.array], frame: list[np.ndarray]) -> None:
    for dst, src in zip(arrays, frame):
        dst.assign(wp.array(src, dtype=wp.vec3, device=dst.device))


def _check_l2(image: np.ndarray, frame: list[np.ndarray]) -> tuple[float, float]:
    """The relative residual of ``image`` for this frame's system (float64), and its distance to the exact
    solution over what the stopping rule allows, 1.5 tol ‖b‖ / α² (the float32 recurrence's slack: 1.5)."""
    exact = reconstruct(*[a.astype(np.float64) for a in frame], alpha=ALPHA, solver="dct")
    b = np.linalg.norm(screened_rhs(*frame, ALPHA).ravel())
    r = np.linalg.norm((screened_rhs(*frame, ALPHA) - screened_operator(image.astype(np.float64), ALPHA)).ravel())
    return r / b, np.linalg.norm((image - exact).ravel()) / (1.5 * TOL * b / ALPHA**2)


def _system(device: str, h: int, w: int, **options) -> tuple[ScreenedPoisson, list[wp.array]]:
    arrays = [wp.zeros((h, w), dtype=wp.vec3, device=device) for _ in range(3)]
    return ScreenedPoisson(*arrays, alpha=ALPHA, **options), arrays


def test_every_frame_meets_the_stopping_rule_and_the_error_bound(device):
    frames = _frames(37, 53, 4)
    system, arrays = _system(device, 37, 53, norm="L2", tol=TOL, warm_start=True)
    iterations = []
    for frame in frames:
        _bound(arrays, frame)
        image = system.solve().numpy()
        rel, ratio = _check_l2(image, frame)
        assert rel <= 1.5 * TOL  # float32 recurrence against the float64 residual
        assert ratio <= 1.0
        iterations.append(system.iterations)
    assert all(0 < k < 200 for k in iterations)
    # the same frame again: the warm start is the answer (to float32 rounding of the true residual)
    system.solve()
    assert system.iterations <= 3 < iterations[0]
    assert system.report().converged


def test_warm_start_without_the_stopping_rule_is_caught():
    """The sibling: a warm start that skips CG hands back the previous frame's image; the same check fails.
    (On the CPU every solve re-runs the launches, so changing ``max_iter`` takes effect.)"""
    frames = _frames(37, 53, 2)
    system, arrays = _system("cpu", 37, 53, norm="L2", tol=TOL)
    _bound(arrays, frames[0])
    assert _check_l2(system.solve().numpy(), frames[0])[1] <= 1.0
    system.max_iter = 0
    _bound(arrays, frames[1])
    rel, ratio = _check_l2(system.solve().numpy(), frames[1])
    assert system.iterations == 0
    assert rel > 100 * TOL and ratio > 1.0


def _algebraic_over_noise(tol: float, seed: int, samples: int = 1) -> float:
    """A frame's L2 image stopped at ``tol``: its squared distance to the exact solve over the exact solve's own
    squared error against the truth (the frame's noise, here ~4% a pixel, milder than a 1-spp frame's; with
    ``samples``, the noise of that many such frames averaged)."""
    h, w = 64, 96
    truth = _truth(h, w)
    g = forward_gradient(truth)
    frame = [np.asarray(t + (a - t) / np.sqrt(samples), dtype=np.float32) for a, t in zip(_frames(h, w, 1, seed)[0], (truth, g.dx, g.dy))]
    exact = reconstruct(*[a.astype(np.float64) for a in frame], alpha=ALPHA, solver="dct")
    system, arrays = _system("cpu", h, w, norm="L2", tol=tol)
    _bound(arrays, frame)
    image = system.solve().numpy()
    return float(np.mean((image - exact) ** 2) / np.mean((exact - _truth(h, w)) ** 2))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_frame_tolerance_leaves_an_error_far_below_the_frames_noise(seed):
    """FrameReconstruction stops L2's CG at FRAME_TOL, not the one-off solve's 1e-5: the algebraic error must stay
    10⁴× under the frame's Monte Carlo error (measured: 2.5–2.6e-6 of it, 7 iterations)."""
    assert _algebraic_over_noise(FRAME_TOL, seed) < 1e-4


def test_a_tolerance_that_shows_in_the_image_is_caught():
    """The sibling: stopped at 1e-2 (4 iterations), the algebraic error is 2.6–2.8e-3 of the noise; the check fails."""
    assert _algebraic_over_noise(1e-2, 0) > 1e-4


def test_averaged_samples_tighten_the_frame_tolerance():
    """1000 frames' worth of samples have 1/√1000 of one frame's noise: frame_tol(1000) (the one-off solve's 1e-5)
    keeps the algebraic error under 1e-4 of it (measured 2.7e-6, as one frame at FRAME_TOL); FRAME_TOL there (the
    sibling) lets it reach 3.2e-4 and fails."""
    assert frame_tol(1) == FRAME_TOL and frame_tol(4) == FRAME_TOL / 2 and frame_tol(100) == frame_tol(10_000) == 1e-5
    assert _algebraic_over_noise(frame_tol(1000), 0, samples=1000) < 1e-4
    assert _algebraic_over_noise(FRAME_TOL, 0, samples=1000) > 1e-4
    with pytest.raises(InvalidParameterError, match="samples >= 1"):
        frame_tol(0)


def test_frame_reconstruction_passes_its_tolerance():
    """Off the CPU's exact L2 (here: L1, which builds the system), the bound system carries FrameReconstruction's tol."""
    arrays = [wp.zeros((8, 12), dtype=wp.vec3, device="cpu") for _ in range(3)]
    assert FrameReconstruction(*arrays, norm="L1").system.tol == FRAME_TOL
    assert FrameReconstruction(*arrays, norm="L1", tol=3e-5).system.tol == 3e-5
    assert FrameReconstruction(*arrays, norm="L2").system is None  # the CPU solves L2 exactly (DCT)


def test_reset_gives_a_cold_start_bit_for_bit(device):
    frames = _frames(24, 40, 3, seed=2)
    for norm, options in (("L2", {}), ("L1", {"preset": "fast"})):
        system, arrays = _system(device, 24, 40, norm=norm, **options)
        fresh, fresh_arrays = _system(device, 24, 40, norm=norm, **options)
        for frame in frames:
            _bound(arrays, frame)
            system.solve()
        system.reset()
        _bound(arrays, frames[0])
        _bound(fresh_arrays, frames[0])
        assert_array_equal(system.solve().numpy(), fresh.solve().numpy())


def test_a_cold_l1_frame_is_the_one_off_solve(device):
    """Without warm starts, L1 runs reconstruct()'s schedule on the same arithmetic: the same image."""
    frames = _frames(24, 40, 2, seed=3)
    system, arrays = _system(device, 24, 40, norm="L1", preset="fast", warm_start=False)
    for frame in frames:
        _bound(arrays, frame)
        got = system.solve().numpy()
        want = reconstruct(*[wp.array(a, dtype=wp.vec3, device=device) for a in frame], alpha=ALPHA, norm="L1", preset="fast").numpy()
        assert_array_equal(got, want)


def test_warm_l1_stays_at_the_l1_minimum():
    """Warm-started IRLS (the previous frame's L1 image) reaches an energy no higher than a cold start's."""
    from grisx.poisson import screened_energy

    frames = _frames(24, 40, 3, seed=4)
    warm, arrays = _system("cpu", 24, 40, norm="L1", preset="fast")
    for frame in frames:
        _bound(arrays, frame)
        image = warm.solve().numpy().astype(np.float64)
    cold = reconstruct(*frames[-1], alpha=ALPHA, norm="L1", preset="fast").astype(np.float64)
    e_warm = screened_energy(image, *frames[-1], ALPHA, "L1")
    e_cold = screened_energy(cold, *frames[-1], ALPHA, "L1")
    assert e_warm <= e_cold * (1 + 1e-3)


def test_inputs_of_different_shapes_are_refused():
    a = wp.zeros((4, 5), dtype=wp.vec3, device="cpu")
    b = wp.zeros((4, 6), dtype=wp.vec3, device="cpu")
    with pytest.raises(InvalidParameterError, match="dx has shape"):
        ScreenedPoisson(a, b, a)
    with pytest.raises(UnknownNameError, match="norm"):
        ScreenedPoisson(a, a, a, norm="L3")
    with pytest.raises(InvalidParameterError, match="alpha"):
        ScreenedPoisson(a, a, a, alpha=0.0)
