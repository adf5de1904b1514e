"""Tests of the gradient-domain core (seed 000) and its toys ``f1-f2`` and ``gradient-row``.

Ladder: hand-computed values of the core functions → properties (the ω
weights of the two pixels partition every shiftable path's contribution, G is
antisymmetric under swapping the pixels, pos − neg = ω*G) → a quadrature
check that ∫_X ω*G is Δ on a partial bijection → statistics: every method
within 4σ with and without ``offset``, and the known-biased variants beyond 6σ.
"""

import numpy as np
import pytest
import warp as wp
from hypothesis import given, settings
from hypothesis import strategies as st

from grisx.errors import InvalidParameterError, UnknownNameError
from grisx.testing import BIASED_K, DEFAULT_K, z_test
from grisx.theory.gradient import (
    SIGN_ABS,
    SIGN_NEG,
    SIGN_POS,
    gradient_mis,
    outer_shift,
    pair_contribution,
    pair_estimate,
    pair_value,
    signed_target,
)
from grisx.theory.shift import shift_failed, shift_result
from grisx.theory.toys import PROBLEMS, get_problem, run_toy
from grisx.theory.toys.f1_f2 import F1F2Spec, f1f2_exact, f1f2_inner_shift, f1f2_integrand, f1f2_integrand_np, f1f2_pdf
from grisx.theory.toys.gradient_row import row_exact_pixels, solve_poisson_1d

wp.set_module_options({"enable_backward": False})

SEED = 20261121


# ---- a harness kernel: the core functions over arrays ----------------------------------


@wp.kernel
def _core_kernel(
    d_base: wp.array(dtype=float),
    d_off: wp.array(dtype=float),
    f_base: wp.array(dtype=float),
    f_off: wp.array(dtype=float),
    jac: wp.array(dtype=float),
    valid: wp.array(dtype=int),
    out: wp.array2d(dtype=float),
):
    n = wp.tid()
    v = valid[n] != 0
    out[n, 0] = gradient_mis(d_base[n], d_off[n], jac[n], v)
    # the same path seen from the other pixel: base and offset swapped, inverse Jacobian
    inv = float(0.0)
    if jac[n] > 0.0:
        inv = 1.0 / jac[n]
    out[n, 1] = gradient_mis(d_off[n], d_base[n], inv, v)
    out[n, 2] = pair_contribution(0, f_base[n], f_off[n], jac[n], v)
    out[n, 3] = pair_contribution(1, f_base[n], f_off[n], jac[n], v)
    value = pair_value(0, f_base[n], f_off[n], d_base[n], d_off[n], jac[n], v)
    out[n, 4] = value
    out[n, 5] = signed_target(SIGN_POS, value)
    out[n, 6] = signed_target(SIGN_NEG, value)
    out[n, 7] = signed_target(SIGN_ABS, value)
    out[n, 8] = pair_estimate(value, 2.0)
    tau = shift_result(f_off[n], -jac[n])
    if not v:
        tau = shift_failed()
    s = outer_shift(tau, 1)
    out[n, 9] = s.jacobian
    out[n, 10] = float(s.k)
    out[n, 11] = float(int(s.valid))


def core(d_base, d_off, f_base, f_off, jac, valid):
    arrays = [np.atleast_1d(np.asarray(a, dtype=np.float32)) for a in (d_base, d_off, f_base, f_off, jac)]
    n = arrays[0].size
    val = np.broadcast_to(np.asarray(valid, dtype=np.int32), (n,)).copy()
    out = wp.zeros((n, 12), dtype=float, device="cpu")
    wp.launch(_core_kernel, dim=n, inputs=[*[wp.array(a, dtype=float, device="cpu") for a in arrays], wp.array(val, dtype=int, device="cpu"), out], device="cpu")
    return out.numpy().astype(np.float64)


# ---- exact values ---------------------------------------------------------------------------


def test_core_values_by_hand():
    # p_i = 1, p_j(T x) = 3, |J| = 1/3: ω_ij = 1 / (1 + 1) = 1/2
    r = core(1.0, 3.0, 5.0, 2.0, 1.0 / 3.0, 1)[0]
    assert r[0] == pytest.approx(0.5)
    assert r[2] == pytest.approx(5.0 - 2.0 / 3.0) and r[3] == pytest.approx(-(5.0 - 2.0 / 3.0))  # Eq. 15
    assert r[4] == pytest.approx(0.5 * (5.0 - 2.0 / 3.0))  # ω*G, Eq. 14
    assert r[5] == pytest.approx(r[4]) and r[6] == 0.0 and r[7] == pytest.approx(r[4])  # Eq. 19, 25, 26
    assert r[8] == pytest.approx(2.0 * r[4])  # Eq. 17
    assert r[9] == pytest.approx(1.0 / 3.0) and r[10] == 1.0 and r[11] == 1.0  # Eq. 21–22: |∂τ/∂x|, k kept


def test_failed_inner_shift_gives_the_base_pixel_everything():
    r = core(0.25, 7.0, 2.0, 9.0, 4.0, 0)[0]
    assert r[0] == 1.0  # the offset technique cannot produce x: ω = 1 (Eq. 4, term dropped)
    assert r[2] == 2.0 and r[3] == -2.0  # no offset contribution (Eq. 15)
    assert r[11] == 0.0 and r[9] == 0.0  # T* fails with τ


def test_zero_densities_and_negative_values_never_give_nan():
    r = core([0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [0.0, 1.0, 1.0], [3.0, 1.0, 4.0], [0.0, 1.0, 1.0], 1)
    assert np.all(np.isfinite(r))
    assert r[0, 0] == 0.0 and r[1, 0] == 0.0 and r[2, 0] == 1.0
    assert r[2, 5] == 0.0 and r[2, 6] == pytest.approx(3.0) and r[2, 7] == pytest.approx(3.0)


# ---- properties ------------------------------------------------------------------------------

positive = st.floats(1e-3, 1e3, allow_nan=False, allow_infinity=False)
value = st.floats(0.0, 1e3, allow_nan=False, allow_infinity=False)


@settings(deadline=None, max_examples=60)
@given(st.lists(st.tuples(positive, positive, value, value, positive), min_size=1, max_size=16))
def test_omega_weights_of_the_two_pixels_partition_a_shiftable_path(rows):
    """ω_ij(x) + ω_ji(T_ij x) = 1: a path reachable from both pixels is counted exactly once (Eq. 3–4)."""
    d_b, d_o, f_b, f_o, j = map(np.array, zip(*rows))
    r = core(d_b, d_o, f_b, f_o, j, 1)
    np.testing.assert_allclose(r[:, 0] + r[:, 1], 1.0, rtol=1e-5)
    assert np.all((r[:, :2] >= 0) & (r[:, :2] <= 1))


@settings(deadline=None, max_examples=60)
@given(st.lists(st.tuples(positive, positive, value, value, positive), min_size=1, max_size=16), st.booleans())
def test_g_is_antisymmetric_under_swapping_the_pixels(rows, valid):
    """G_ji(x, 1−k) = −G_ij(x, k), and pos − neg = ω*G (Eq. 15, 24–26)."""
    d_b, d_o, f_b, f_o, j = map(np.array, zip(*rows))
    r = core(d_b, d_o, f_b, f_o, j, int(valid))
    np.testing.assert_allclose(r[:, 2], -r[:, 3], rtol=0, atol=1e-6 * (1 + np.max(np.abs(r[:, 2]))))
    np.testing.assert_allclose(r[:, 5] - r[:, 6], r[:, 4], rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(r[:, 7], np.abs(r[:, 4]), rtol=1e-6)


@wp.kernel
def _pair_integrand_kernel(spec: F1F2Spec, xs: wp.array(dtype=float), k: int, symmetric: int, out: wp.array(dtype=float)):
    n = wp.tid()
    x = xs[n]
    other = 1 - k
    s = f1f2_inner_shift(spec, 0, k, other, x)
    f_o = float(0.0)
    d_o = float(0.0)
    if s.valid:
        f_o = f1f2_integrand(spec, 0, other, s.x)
        d_o = f1f2_pdf(spec, 0, other, s.x)
    if symmetric != 0:
        out[n] = pair_value(k, f1f2_integrand(spec, 0, k, x), f_o, f1f2_pdf(spec, 0, k, x), d_o, s.jacobian, s.valid)
    else:
        out[n] = pair_contribution(k, f1f2_integrand(spec, 0, k, x), f_o, s.jacobian, s.valid)


@pytest.mark.parametrize("offset", [0.0, 0.3, 1.0])
def test_pair_domain_integral_is_the_difference_on_a_partial_bijection(offset):
    """∫_X ω*G = Δ (Eq. 14) by quadrature; the one-sided Eq. 2 misses ∫_{Ω2∖Ω1} f2 when d > 0."""
    spec = F1F2Spec()
    spec.offset, spec.motion, spec.frames = offset, 1.0, 0
    total, one_sided = 0.0, 0.0
    for k in (0, 1):
        lo = -2.0 + offset * k
        x = np.linspace(lo, lo + 4.0, 400_001)
        out = wp.zeros(x.size, dtype=float, device="cpu")
        xs = wp.array(x.astype(np.float32), dtype=float, device="cpu")
        wp.launch(_pair_integrand_kernel, dim=x.size, inputs=[spec, xs, k, 1, out], device="cpu")
        total += np.trapezoid(out.numpy().astype(np.float64), x)
        if k == 0:
            wp.launch(_pair_integrand_kernel, dim=x.size, inputs=[spec, xs, 0, 0, out], device="cpu")
            one_sided = np.trapezoid(out.numpy().astype(np.float64), x)
    exact = f1f2_exact(offset)
    assert total == pytest.approx(exact, abs=2e-5)
    missed = 0.1 * offset  # the floor of f2 over [2, 2 + d], where no path of pixel 1 lands
    assert one_sided - exact == pytest.approx(missed, abs=2e-4)


def test_f1f2_exact_matches_quadrature():
    for d in (0.0, 0.7):
        x1 = np.linspace(-2, 2, 400_001)
        x2 = np.linspace(-2 + d, 2 + d, 400_001)
        oracle = np.trapezoid(f1f2_integrand_np(0, x1), x1) - np.trapezoid(f1f2_integrand_np(1, x2), x2)
        assert f1f2_exact(d) == pytest.approx(oracle, abs=1e-9)


def test_row_exact_matches_quadrature():
    from grisx.theory.toys.gradient_row import DRIFT, WIDEN, row_layout

    f = row_exact_pixels(10, 3, light_drift=0.01)
    albedo = row_layout(10, 3)
    for i in range(10):
        x = np.linspace(DRIFT * i, DRIFT * i + 1 + WIDEN * i, 200_001)
        u = (x - DRIFT * i) / (1 + WIDEN * i)
        g = 0.2 + 1.5 * np.exp(-(((u - 0.35 - 0.01 * i) / 0.07) ** 2)) + 0.8 * np.exp(-(((u - 0.85) / 0.1) ** 2))
        assert f[i] == pytest.approx(albedo[i] * np.trapezoid(g, x), rel=1e-9)


def test_poisson_1d_matches_grisx_poisson_on_a_one_row_image():
    from grisx.poisson import reconstruct

    rng = np.random.default_rng(3)
    primal = rng.random((4, 9))
    grads = rng.normal(size=(4, 8))
    ours = solve_poisson_1d(primal, grads, alpha=0.3)
    for r in range(4):
        dx = np.append(grads[r], 0.0)[None, :]
        oracle = reconstruct(primal[r][None, :], dx, np.zeros((1, 9)), alpha=0.3, norm="L2")
        np.testing.assert_allclose(ours[r], np.asarray(oracle)[0], atol=2e-5)
    # exact gradients of the primal give the primal back
    np.testing.assert_allclose(solve_poisson_1d(primal, np.diff(primal, axis=1)), primal, atol=2e-5)


# ---- statistics: f1-f2 -------------------------------------------------------------------------

F1F2_TRIALS = 200_000

F1F2_UNBIASED = [
    ("mc-difference", {}),
    ("gradient-pt", {}),
    ("gradient-pt", {"symmetric": False}),  # offset 0: the inner shift is a bijection, Eq. 2 suffices
    ("gradient-after-restir", {}),
    ("gradient-with-restir", {}),
    ("gradient-with-restir", {"positivize": False}),
    ("gradient-after-restir", {"frames": 1, "motion": 1.5}),
    ("gradient-with-restir", {"frames": 1, "motion": 1.5}),
    ("gradient-with-restir", {"frames": 1, "motion": 0.8, "cross_sign": True, "candidates": 2}),
    ("gradient-with-restir", {"frames": 2, "positivize": False, "cap": 4}),
]


@pytest.mark.parametrize("offset", [0.0, 0.6])
@pytest.mark.parametrize("method, params", F1F2_UNBIASED, ids=lambda c: str(c))
def test_f1f2_methods_are_unbiased(method, params, offset):
    params = dict(params, offset=offset)
    problem = get_problem("f1-f2")
    if problem.is_biased(method, problem.resolve_params(method, params)):
        pytest.skip("biased here by construction (tested below)")
    trials = F1F2_TRIALS if "frames" not in params else F1F2_TRIALS // 4
    est = run_toy("f1-f2", method, trials=trials, seed=SEED, params=params)
    result = z_test(est.estimate, est.stderr, est.exact, k=DEFAULT_K)
    assert result.passed, f"{method} {params}: {result}"


F1F2_BIASED = [
    ("gradient-pt", {"symmetric": False, "offset": 0.6}),
    ("gradient-with-restir", {"jacobian": False, "frames": 2, "motion": 1.5, "offset": 0.6}),
    ("gradient-after-restir", {"jacobian": False, "frames": 2, "motion": 1.5}),
]


@pytest.mark.parametrize("method, params", F1F2_BIASED, ids=lambda c: str(c))
def test_f1f2_biased_variants_are_caught(method, params):
    problem = get_problem("f1-f2")
    assert problem.is_biased(method, problem.resolve_params(method, params))
    trials = F1F2_TRIALS if "frames" not in params else F1F2_TRIALS // 4
    est = run_toy("f1-f2", method, trials=trials, seed=SEED, params=params)
    assert z_test(est.estimate, est.stderr, est.exact).max_abs_z > BIASED_K


def test_gradient_with_selects_where_f1_and_f2_differ():
    """Fig. 3: gradient-after piles its samples on the shared peak, gradient-with on the two differing peaks."""
    after = run_toy("f1-f2", "gradient-after-restir", trials=20_000, seed=1, params={"candidates": 32, "offset": 0.0}, return_samples=True)
    with_ = run_toy("f1-f2", "gradient-with-restir", trials=20_000, seed=1, params={"candidates": 32, "positivize": False, "offset": 0.0}, return_samples=True)
    near_origin = lambda s: np.mean(np.abs(s) < 0.4)  # noqa: E731
    near_peaks = lambda s: np.mean((np.abs(s + 1.2) < 0.3) | (np.abs(s - 1.1) < 0.3))  # noqa: E731
    assert near_origin(after.samples) > 0.4 and near_origin(with_.samples) < 0.05
    assert near_peaks(with_.samples) > 0.8 and near_peaks(after.samples) < 0.3


# ---- statistics: gradient-row ---------------------------------------------------------------------

ROW_TRIALS = 10_000
ROW_UNBIASED = [
    ("mc-difference", {}),
    ("gradient-pt", {}),
    ("gradient-after-restir", {"frames": 2}),
    ("gradient-with-restir", {"spatial": "none", "frames": 1}),
    ("gradient-with-restir", {"spatial": "dense", "frames": 1}),
    ("gradient-with-restir", {"spatial": "adaptive", "frames": 1, "cross_sign": True}),
    ("gradient-with-restir", {"spatial": "dense", "frames": 0, "positivize": False, "spatial_passes": 2}),
    ("gradient-with-restir", {"spatial": "adaptive", "frames": 1, "output": "pixels"}),
    ("gradient-with-restir", {"spatial": "adaptive", "frames": 2, "light_drift": 0.0}),
]


@pytest.mark.parametrize("method, params", ROW_UNBIASED, ids=lambda c: str(c))
def test_gradient_row_methods_are_unbiased(method, params):
    params = dict(params, pixels=12, stripe=3)
    est = run_toy("gradient-row", method, trials=ROW_TRIALS, seed=SEED, params=params)
    assert not get_problem("gradient-row").is_biased(method, est.params)
    result = z_test(est.estimate, est.stderr, est.exact, k=DEFAULT_K)  # Šidák over the row
    assert result.passed, f"{method} {params}: {result}"


def test_gradient_row_without_the_outer_jacobian_is_caught():
    params = {"pixels": 12, "stripe": 3, "spatial": "dense", "frames": 0, "neighbors": 4, "jacobian": False}
    assert get_problem("gradient-row").is_biased("gradient-with-restir", params)
    # |∂τ/∂x| = w_b/w_a is within 5% of 1 here: the bias is small, so more trials
    est = run_toy("gradient-row", "gradient-with-restir", trials=8 * ROW_TRIALS, seed=SEED, params=params)
    assert get_problem("gradient-row").is_biased("gradient-with-restir", est.params)
    assert z_test(est.estimate, est.stderr, est.exact).max_abs_z > BIASED_K


def test_adaptive_reuse_merges_only_at_edge_pairs():
    base = {"pixels": 12, "stripe": 3, "frames": 0}
    dense = run_toy("gradient-row", "gradient-with-restir", trials=200, seed=1, params=dict(base, spatial="dense"))
    adaptive = run_toy("gradient-row", "gradient-with-restir", trials=200, seed=1, params=dict(base, spatial="adaptive"))
    none = run_toy("gradient-row", "gradient-with-restir", trials=200, seed=1, params=dict(base, spatial="none"))
    assert none.stats["spatial_merges"] == 0.0
    edge_pairs = 3 / 11  # stripes of 3 in 12 pixels: edges at pairs 2, 5, 8
    assert 0 < adaptive.stats["spatial_merges"] <= 2 * edge_pairs < dense.stats["spatial_merges"]


# ---- contract and bad input ---------------------------------------------------------------------------


def test_problems_are_registered_with_biased_variants():
    for name in ("f1-f2", "gradient-row"):
        assert name in PROBLEMS and PROBLEMS[name].biased_variants


def test_determinism_and_json_contract(device):
    a = run_toy("f1-f2", "gradient-with-restir", trials=3000, seed=4, params={"frames": 1}, device=device)
    b = run_toy("f1-f2", "gradient-with-restir", trials=3000, seed=4, params={"frames": 1}, device=device)
    assert a.estimate == b.estimate
    d = run_toy("gradient-row", "gradient-with-restir", trials=300, seed=4, device=device).to_dict()
    assert len(d["estimate"]) == len(d["exact"]) == 15 and "spatial_merges" in d["stats"]


@pytest.mark.parametrize(
    "name, method, params, error, text",
    [
        ("f1-f2", "gradient-with-restir", {"positivize": False, "cross_sign": True}, InvalidParameterError, "cross_sign"),
        ("f1-f2", "gradient-pt", {"offset": 3.0}, InvalidParameterError, "offset"),
        ("f1-f2", "mc-difference", {"frames": 2}, UnknownNameError, "param of toy"),
        ("gradient-row", "gradient-with-restir", {"spatial": "sparse"}, InvalidParameterError, "spatial"),
        ("gradient-row", "gradient-pt", {"pixels": 2}, InvalidParameterError, "pixels"),
    ],
)
def test_bad_input_is_a_named_error(name, method, params, error, text):
    with pytest.raises(error, match=text):
        run_toy(name, method, trials=10, params=params)
