"""Spatio-temporal control variates (seed 002): the core funcs by hand, their properties, and the ``chromatic-cv`` toy.

Ladder: hand-computed values of Eq. 5/9/10/11 and the compositing of
Eq. 3/6/8 → properties (Eq. 11's two weights sum to one; decoupled shading
is ReSTCV with a zero neighbour integrand, as the paper's §6 says) →
statistics: every method of ``chromatic-cv`` unbiased per pixel and channel
within 4σ (Šidák over pixels × channels), the known-biased variant beyond 6σ.
"""

import numpy as np
import pytest
import scipy.integrate
import warp as wp
from hypothesis import given, settings
from hypothesis import strategies as st

from grisx.errors import InvalidParameterError, UnknownNameError
from grisx.testing import BIASED_K, DEFAULT_K, z_test
from grisx.theory.control_variate import (
    ALPHA_MODES,
    compositing_weight,
    cv_alpha,
    cv_composite_add,
    cv_composite_empty,
    cv_composite_value,
    cv_estimate,
    decoupled_contribution,
    difference_estimate,
    difference_sample,
    luminance,
    mc_contribution,
)
from grisx.theory.gris import resampling_weight
from grisx.theory.mis import MIS_BALANCE, mis_weight, target_from, two_domain_balance
from grisx.theory.toys import PROBLEMS, get_problem, run_toy
from grisx.theory.toys.chromatic_cv import (
    LIGHT_GREEN,
    LIGHT_RED,
    chromatic_exact,
    chromatic_layout,
)

wp.set_module_options({"enable_backward": False})

NAME = "chromatic-cv"
SMALL = {"size": 8, "frames": 3}
TRIALS = 4000
SEED = 20261121


# ---- thin kernels around the core funcs (test-only front-ends) ---------------------------


@wp.kernel
def _alpha_kernel(mode: int, rho_i: wp.array(dtype=wp.vec3), rho_j: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.vec3)):
    t = wp.tid()
    out[t] = cv_alpha(mode, rho_i[t], rho_j[t])


@wp.kernel
def _difference_mis_kernel(m: wp.array2d(dtype=float), out: wp.array(dtype=float)):
    # columns: M_a, p̂_a(x), M_b, p̂_b(T x), |J|
    t = wp.tid()
    out[t] = two_domain_balance(m[t, 0], m[t, 1], m[t, 2], target_from(m[t, 3], m[t, 4]))


@wp.kernel
def _difference_kernel(
    scalars: wp.array2d(dtype=float),  # mis_i, ucw_i, jac_i, mis_j, ucw_j, jac_j
    colours: wp.array2d(dtype=wp.vec3),  # f_i(X_i), f_j(T X_i), f_j(X_j), f_i(T X_j), α
    out: wp.array(dtype=wp.vec3),
):
    t = wp.tid()
    s_i = difference_sample(scalars[t, 0], scalars[t, 1], colours[t, 0], colours[t, 1], scalars[t, 2])
    s_j = difference_sample(scalars[t, 3], scalars[t, 4], colours[t, 2], colours[t, 3], scalars[t, 5])
    out[t] = difference_estimate(s_i, s_j, colours[t, 4])


@wp.kernel
def _composite_kernel(estimates: wp.array2d(dtype=wp.vec3), q: wp.array2d(dtype=float), out: wp.array(dtype=wp.vec3)):
    t = wp.tid()
    c = cv_composite_empty()
    for l in range(q.shape[1]):
        c = cv_composite_add(c, estimates[t, l], q[t, l])
    out[t] = cv_composite_value(c)


@wp.kernel
def _scalar_funcs_kernel(x: wp.array(dtype=float), out: wp.array2d(dtype=float)):
    t = wp.tid()
    out[t, 0] = compositing_weight(x[t])
    out[t, 1] = luminance(wp.vec3(x[t], 2.0 * x[t], 3.0 * x[t]))
    out[t, 2] = mc_contribution(wp.vec3(x[t], 1.0, 0.0), 0.5, 4)[0]
    out[t, 3] = decoupled_contribution(2.0, x[t], wp.vec3(1.0, 1.0, 1.0))[0]
    out[t, 4] = cv_estimate(wp.vec3(x[t], 0.0, 0.0), wp.vec3(2.0, 1.0, 1.0), wp.vec3(1.0, 0.0, 0.0))[0]


@wp.kernel
def _decoupled_vs_restcv_kernel(
    m: wp.array2d(dtype=float),  # M_i, M_j, W_i, W_j, p̂_i(Y_i), p̂_j(Y_i), p̂_i(Y_j), p̂_j(Y_j)
    colours: wp.array2d(dtype=wp.vec3),  # f_i(Y_i), f_i(Y_j), α
    conf: wp.array2d(dtype=float),
    tf: wp.array2d(dtype=float),
    out: wp.array2d(dtype=wp.vec3),
):
    t = wp.tid()
    zero = wp.vec3(0.0, 0.0, 0.0)
    # ReSTCV's from-j estimator with a zero neighbour (⟨F_j⟩ = 0, f_j = 0), Eq. 7 and 10–11
    w_ij = two_domain_balance(m[t, 0], m[t, 4], m[t, 1], m[t, 5])
    w_ji = two_domain_balance(m[t, 1], m[t, 7], m[t, 0], m[t, 6])
    s_i = difference_sample(w_ij, m[t, 2], colours[t, 0], zero, 1.0)
    s_j = difference_sample(w_ji, m[t, 3], zero, colours[t, 1], 1.0)
    out[t, 0] = cv_estimate(zero, colours[t, 2], difference_estimate(s_i, s_j, colours[t, 2]))
    # decoupled shading of the two-domain GRIS pass over Y_i, Y_j with balance MIS (identity shift)
    conf[t, 0] = m[t, 0]
    conf[t, 1] = m[t, 1]
    d = wp.vec3(0.0, 0.0, 0.0)
    tf[t, 0] = m[t, 4]
    tf[t, 1] = m[t, 5]
    w = resampling_weight(mis_weight(MIS_BALANCE, 0, 0, conf[t], tf[t]), m[t, 4], m[t, 2], 1.0)
    d = d + decoupled_contribution(w, m[t, 4], colours[t, 0])
    tf[t, 0] = m[t, 6]
    tf[t, 1] = m[t, 7]
    w = resampling_weight(mis_weight(MIS_BALANCE, 1, 0, conf[t], tf[t]), m[t, 6], m[t, 3], 1.0)
    d = d + decoupled_contribution(w, m[t, 6], colours[t, 1])
    out[t, 1] = d


def _v3(a):
    return wp.array(np.asarray(a, dtype=np.float32).reshape(-1, 3), dtype=wp.vec3, device="cpu")


def _alpha(mode, rho_i, rho_j):
    out = wp.empty(len(rho_i), dtype=wp.vec3, device="cpu")
    wp.launch(_alpha_kernel, dim=len(rho_i), inputs=[ALPHA_MODES[mode], _v3(rho_i), _v3(rho_j), out], device="cpu")
    return out.numpy()


def _difference_mis(rows):
    rows = np.asarray(rows, dtype=np.float32).reshape(-1, 5)
    out = wp.empty(len(rows), dtype=float, device="cpu")
    wp.launch(_difference_mis_kernel, dim=len(rows), inputs=[wp.array(rows, dtype=float, device="cpu"), out], device="cpu")
    return out.numpy()


# ---- exact values on hand-computed cases -------------------------------------------------


def test_alpha_is_the_clamped_reflectance_ratio_per_channel():
    # Eq. 9: min(ρ_i/ρ_j, 2) per channel; ρ_j = 0 → the clamp (limit ρ_j → 0⁺); both 0 → 1
    rho_i = [[0.8, 0.4, 0.2], [0.3, 0.0, 0.5]]
    rho_j = [[0.4, 0.8, 0.05], [0.0, 0.0, 0.5]]
    np.testing.assert_allclose(_alpha("heuristic", rho_i, rho_j), [[2.0, 0.5, 2.0], [2.0, 1.0, 1.0]], rtol=1e-6)
    np.testing.assert_array_equal(_alpha("one", rho_i, rho_j), np.ones((2, 3)))


def test_difference_mis_hand_computed():
    # Eq. 11: M_a p̂_a / (M_a p̂_a + M_b p̂_b(T x) |J|): 2·3 / (2·3 + 1·4·0.5) = 0.75
    # a failed shift (p̂_b = 0) gives 1; nothing covers x → 0, never NaN
    np.testing.assert_allclose(_difference_mis([[2, 3, 1, 4, 0.5], [1, 2, 5, 0, 1], [1, 0, 1, 0, 1]]), [0.75, 1.0, 0.0], rtol=1e-6)


def test_difference_estimate_hand_computed():
    # Eq. 10: ω_i W_i (f_i − α f_j∘T |J_i|) − ω_j W_j (α f_j − f_i∘T |J_j|)
    scalars = np.array([[0.25, 2.0, 1.5, 0.5, 4.0, 2.0]], dtype=np.float32)
    colours = np.array([[[1, 2, 3], [0.5, 1, 0], [2, 0, 1], [1, 1, 1], [2, 1, 0.5]]], dtype=np.float32)
    f_i, f_j_t, f_j, f_i_t, alpha = colours[0]
    expected = 0.25 * 2.0 * (f_i - alpha * f_j_t * 1.5) - 0.5 * 4.0 * (alpha * f_j - f_i_t * 2.0)
    out = wp.empty(1, dtype=wp.vec3, device="cpu")
    wp.launch(_difference_kernel, dim=1, inputs=[wp.array(scalars, dtype=float), wp.array(colours, dtype=wp.vec3), out], device="cpu")
    np.testing.assert_allclose(out.numpy()[0], expected, rtol=1e-6)


def test_composite_weights_and_empty_composite():
    # Eq. 3/6/8: Σ q F / Σ q; q = 0 adds nothing; an empty composite is 0, not NaN
    est = np.array([[[1, 2, 3], [3, 2, 1], [100, 100, 100]], [[5, 5, 5], [1, 1, 1], [2, 2, 2]]], dtype=np.float32)
    q = np.array([[1.0, 3.0, 0.0], [0.0, 0.0, 0.0]], dtype=np.float32)
    out = wp.empty(2, dtype=wp.vec3, device="cpu")
    wp.launch(_composite_kernel, dim=2, inputs=[wp.array(est, dtype=wp.vec3), wp.array(q, dtype=float), out], device="cpu")
    np.testing.assert_allclose(out.numpy(), [[2.5, 2.0, 1.5], [0.0, 0.0, 0.0]], rtol=1e-6)


def test_scalar_helpers_hand_computed():
    x = np.array([3.0, 25.0, 0.0], dtype=np.float32)
    out = wp.empty((3, 5), dtype=float, device="cpu")
    wp.launch(_scalar_funcs_kernel, dim=3, inputs=[wp.array(x, dtype=float), out], device="cpu")
    o = out.numpy()
    np.testing.assert_allclose(o[:, 0], [3.0, 20.0, 0.0])  # q_j = min(M_j, 20)
    np.testing.assert_allclose(o[:, 1], x * (0.212671 + 2 * 0.715160 + 3 * 0.072169), rtol=1e-6)  # Rec. 709 luminance (Mitsuba)
    np.testing.assert_allclose(o[:, 2], x / (4 * 0.5), rtol=1e-6)  # f / (N p)
    np.testing.assert_allclose(o[:, 3], [2 / 3.0, 2 / 25.0, 0.0], rtol=1e-6)  # w f / p̂, 0 where p̂ = 0
    np.testing.assert_allclose(o[:, 4], 2 * x + 1, rtol=1e-6)  # α F_j + diff


def test_exact_values_match_quadrature_of_the_integrand():
    """Independent oracle: integrate the numpy twin of f_i per channel with scipy."""
    size, w = 6, 0.1
    lay = chromatic_layout(size)
    exact = chromatic_exact(size, w)
    for i in (0, 7, 20, 35):
        a, h, rho = lay["position"][i], lay["height"][i], lay["albedo"][i]
        for ch in range(3):
            def f(x, c=ch):
                light = LIGHT_RED[c] if abs(x - 0.25) < w / 2 else (LIGHT_GREEN[c] if abs(x - 0.75) < w / 2 else 0.0)
                return rho[c] * light * h * h / ((x - a) ** 2 + h * h)

            oracle = scipy.integrate.quad(f, 0, 1, points=[0.2, 0.3, 0.7, 0.8], epsabs=1e-13, limit=200)[0]
            np.testing.assert_allclose(exact[i, ch], oracle, rtol=1e-9)


def test_the_albedo_has_edges_and_the_middle_is_yellow():
    lay = chromatic_layout(16)
    assert len(np.unique(lay["albedo"], axis=0)) >= 3
    exact = chromatic_exact(16, 0.1)
    middle = exact.reshape(16, 16, 3)[:, 7:9]
    assert np.all(middle[..., 0] > 0.3 * middle[..., 1]) and np.all(middle[..., 1] > 0.3 * middle[..., 0])


# ---- properties ----------------------------------------------------------------------------

positive = st.floats(1e-4, 1e4)
nonneg = st.one_of(st.just(0.0), positive)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.floats(0.5, 40.0), positive, st.floats(0.5, 40.0), nonneg, st.floats(0.05, 20.0)), min_size=1, max_size=16))
def test_the_two_mis_weights_of_eq11_sum_to_one(rows):
    # ω̂_ij(x) + ω̂_ji(T_{i→j} x) = 1 wherever p̂_i(x) > 0: with y = T x, p̂_j(y) and |J_{j→i}(y)| = 1/|J_{i→j}(x)|
    rows = np.array(rows, dtype=np.float64)
    m_i, t_i, m_j, t_j, jac = rows.T
    w_ij = _difference_mis(np.stack([m_i, t_i, m_j, t_j, jac], axis=1))
    w_ji = _difference_mis(np.stack([m_j, t_j, m_i, t_i, 1.0 / jac], axis=1))
    assert np.all((w_ij >= 0) & (w_ij <= 1) & (w_ji >= 0) & (w_ji <= 1))
    np.testing.assert_allclose(w_ij + w_ji, 1.0, rtol=1e-5)


@settings(max_examples=30, deadline=None)
@given(
    st.lists(
        st.tuples(st.floats(1.0, 20.0), st.floats(1.0, 20.0), st.floats(0.01, 10.0), st.floats(0.01, 10.0), positive, positive, positive, positive),
        min_size=1,
        max_size=8,
    ),
    st.floats(0.0, 2.0),
)
def test_decoupled_shading_is_restcv_with_a_zero_neighbour(rows, alpha):
    # seed 002, §6: decoupled shading "is equivalent to our method using a zero-valued neighbouring
    # integrand (both ⟨F_j⟩ and f_j(x) are 0)": Eq. 7 + 10 + 11 against Σ w f/p̂ of a two-domain GRIS pass
    m = np.array(rows, dtype=np.float32)
    n = len(m)
    rng = np.random.default_rng(len(rows))
    colours = np.concatenate([rng.uniform(0, 1, (n, 2, 3)), np.full((n, 1, 3), alpha)], axis=1).astype(np.float32)
    out = wp.empty((n, 2), dtype=wp.vec3, device="cpu")
    scratch = [wp.zeros((n, 2), dtype=float, device="cpu") for _ in range(2)]
    wp.launch(_decoupled_vs_restcv_kernel, dim=n, inputs=[wp.array(m, dtype=float), wp.array(colours, dtype=wp.vec3), *scratch, out], device="cpu")
    o = out.numpy()
    np.testing.assert_allclose(o[:, 0], o[:, 1], rtol=2e-4, atol=1e-6)


# ---- statistics: every method unbiased per pixel and channel ---------------------------------

UNBIASED = [
    ("mc", {}),
    ("restir", {}),
    ("restir", {"frames": 6, "neighbors": 5, "radius": 1}),
    ("decoupled", {}),
    ("icv", {}),
    ("icv", {"alpha": "one"}),
    ("stcv", {}),
    ("stcv", {"alpha": "one", "light_width": 0.5}),
    ("restcv", {}),
    ("restcv", {"alpha": "one"}),
    ("restcv", {"difference_mis": "balance"}),
    ("restcv", {"frames": 1}),
    ("restcv", {"frames": 6, "candidates": 1, "neighbors": 5, "radius": 1}),
    ("restcv", {"light_width": 0.5, "size": 5}),
]


def _label(case):
    method, params = case
    return method + "-" + ",".join(f"{k}={v}" for k, v in params.items())


@pytest.mark.parametrize("case", UNBIASED, ids=_label)
def test_every_method_is_unbiased_per_pixel_and_channel(case):
    method, params = case
    est = run_toy(NAME, method, trials=TRIALS, seed=SEED, params={**SMALL, **params})
    assert not PROBLEMS[NAME].is_biased(method, est.params)
    result = z_test(est.estimate, est.stderr, est.exact, k=DEFAULT_K)  # Šidák over pixels × 3 channels
    assert result.passed, f"{method} {params}: {result}"
    assert est.estimate.size == est.params["size"] ** 2 * 3


@pytest.mark.parametrize("seed", [0, 7, 123456])
@pytest.mark.parametrize("method", ["stcv", "restcv"])
def test_control_variates_are_unbiased_at_several_seeds(method, seed):
    est = run_toy(NAME, method, trials=TRIALS, seed=seed, params=SMALL)
    assert z_test(est.estimate, est.stderr, est.exact).passed


def test_every_method_is_tested():
    assert {m for m, _ in UNBIASED} == {m.name for m in get_problem(NAME).methods}


@pytest.mark.parametrize("variant", get_problem(NAME).biased_variants, ids=lambda b: f"{b.method}-{b.params}")
def test_known_biased_variant_is_caught(variant):
    est = run_toy(NAME, variant.method, trials=TRIALS, seed=SEED, params={**SMALL, **variant.params})
    assert PROBLEMS[NAME].is_biased(variant.method, est.params)
    assert z_test(est.estimate, est.stderr, est.exact).max_abs_z > BIASED_K


def test_restcv_removes_most_of_restirs_colour_variance():
    # the paper's claim as a variance statement (timings live in benchmarks/control_variates.py)
    var = {}
    for method in ("restir", "restcv"):
        est = run_toy(NAME, method, trials=TRIALS, seed=SEED, params={**SMALL, "frames": 6})
        var[method] = (np.asarray(est.stderr) ** 2 * est.trials).reshape(-1, 3).mean(axis=0)
    # summed over channels, and in red (the light a luminance target under-samples); the faint
    # blue channel gains least (albedo edges clamp α at 2 there)
    assert var["restcv"].sum() < 0.5 * var["restir"].sum() and var["restcv"][0] < 0.5 * var["restir"][0], var


def test_stats_count_difference_samples_and_how_many_lie_on_a_light():
    # per pixel and frame, F frames, k neighbours, C samples: the spatial pass pairs i with k
    # neighbours every frame, the temporal pass with its past in F − 1 frames; each pair uses
    # 2C samples (Eq. 4) or the 2 reservoir samples (Eq. 10)
    f, k, c = 4, 3, 2
    params = {"size": 6, "frames": f, "neighbors": k, "candidates": c}
    icv, stcv, restcv = (run_toy(NAME, m, trials=200, seed=1, params=params).stats for m in ("icv", "stcv", "restcv"))
    assert icv["difference_samples_per_pixel_frame"] == pytest.approx(2 * k * c)
    assert stcv["difference_samples_per_pixel_frame"] == pytest.approx((f * 2 * k * c + (f - 1) * 2 * c) / f)
    assert restcv["difference_samples_per_pixel_frame"] == pytest.approx((f * 2 * k + (f - 1) * 2) / f)
    # uniform samples hit the two lights (width 0.1 each) 20 % of the time; reservoir samples mostly do
    assert stcv["difference_samples_on_light_fraction"] == pytest.approx(0.2, abs=0.01)
    assert restcv["difference_samples_on_light_fraction"] > 0.6
    full = run_toy(NAME, "stcv", trials=20, seed=1, params={**params, "light_width": 0.5}).stats
    assert full["difference_samples_on_light_fraction"] == 1.0
    assert run_toy(NAME, "restir", trials=20, seed=1, params=params).stats is None


# ---- the records and their contract ---------------------------------------------------------


def test_images_are_the_trials_of_run(device):
    problem = get_problem(NAME)
    imgs = problem.images("restcv", trials=3, seed=5, params={"size": 4, "frames": 2}, device=device)
    assert imgs.shape == (3, 4, 4, 3) and np.all(np.isfinite(imgs))
    run = problem.run("restcv", trials=3, seed=5, params={"size": 4, "frames": 2}, device=device)
    np.testing.assert_allclose(imgs.reshape(3, -1).mean(axis=0), run.estimate, rtol=1e-5, atol=1e-7)
    again = run_toy(NAME, "restcv", trials=3, seed=5, params={"size": 4, "frames": 2}, device=device)
    np.testing.assert_array_equal(again.estimate, run.estimate)
    d = again.to_dict()
    assert len(d["estimate"]) == len(d["stderr"]) == len(d["exact"]) == 48


@pytest.mark.parametrize(
    "method, params, error, text",
    [
        ("restcv", {"radius": 4, "size": 4}, InvalidParameterError, "radius"),
        ("restcv", {"alpha": "optimal"}, InvalidParameterError, "alpha"),
        ("restcv", {"difference_mis": "pairwise"}, InvalidParameterError, "difference_mis"),
        ("mc", {"alpha": "one"}, UnknownNameError, "param of toy"),
        ("restir", {"difference_mis": "none"}, UnknownNameError, "param of toy"),
        ("stcv", {"light_width": 0.0}, InvalidParameterError, "light_width"),
        ("stcv", {"frames": 0}, InvalidParameterError, "frames"),
    ],
)
def test_bad_input_raises_a_named_grisx_error(method, params, error, text):
    with pytest.raises(error, match=text):
        run_toy(NAME, method, trials=10, params=params)
