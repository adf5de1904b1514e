"""Conditional and joint UCWs, conditional RIS and the final gather (seed 001) — the test ladder.

Exact values of the core functions on hand-computed cases → properties (the
conditional MIS weights of the domains that contain a sample sum to one; the
suffix shift's inverse and Jacobian) → statistics: every unbiased method of
``joint-ucw``, ``suffix-reuse`` and ``final-gather`` within 4σ (Šidák over
pixels), every declared biased variant beyond 6σ, roulette with the mean of
all-canonical.
"""

import math

import numpy as np
import pytest
import scipy.integrate
import warp as wp
from hypothesis import given, settings
from hypothesis import strategies as st

from grisx.errors import InvalidParameterError
from grisx.testing import BIASED_K, DEFAULT_K, z_test
from grisx.theory.conditional import (
    PROXY_SOURCE_PDF,
    PROXY_TARGET,
    canonical_roulette_weight,
    joint_ucw,
    roulette_pick,
    roulette_window_holds,
    roulette_window_weight,
    shifted_conditional_ucw,
)
from grisx.theory.toys import PROBLEMS, get_problem, run_toy
from grisx.theory.toys.conditional_paths import CRIS, PathsSpec, path_integral_exact, suffix_shift

wp.set_module_options({"enable_backward": False})

SEED = 20261121
TRIALS = {"joint-ucw": 200_000, "suffix-reuse": 60_000, "final-gather": 60_000}
NAMES = tuple(TRIALS)

UNBIASED = [
    ("joint-ucw", "independent", {}),
    ("joint-ucw", "independent", {"candidates": 1}),
    ("suffix-reuse", "cris", {}),
    ("suffix-reuse", "cris", {"passes": 1, "pixels": 1}),
    ("suffix-reuse", "cris", {"spatial": False, "passes": 4}),
    ("suffix-reuse", "cris", {"pixels": 6, "candidates": 1, "cap": 0}),
    ("final-gather", "gather", {}),
    ("final-gather", "gather", {"roulette": False}),
    ("final-gather", "gather", {"prefixes": 8, "k": 3, "passes": 2}),
    ("final-gather", "gather", {"prefixes": 1, "support": 1, "passes": 0}),
    ("final-gather", "gather", {"mis": "pairwise"}),
    ("final-gather", "gather", {"mis": "pairwise", "prefixes": 8, "k": 3, "passes": 2, "roulette": False}),
    ("final-gather", "mmis", {}),
    ("final-gather", "mmis", {"suffixes": 3, "roulette": False}),
]

BIASED = [(name, b.method, dict(b.params)) for name in NAMES for b in PROBLEMS[name].biased_variants]


def _label(case):
    name, method, params = case
    return f"{name}-{method}-" + ",".join(f"{k}={v}" for k, v in params.items())


# ---- exact values of the core functions --------------------------------------------------


@wp.kernel
def _core_values_kernel(inputs: wp.array(dtype=wp.vec2), out: wp.array(dtype=float)):
    i = wp.tid()
    a = inputs[i][0]
    b = inputs[i][1]
    out[4 * i + 0] = joint_ucw(a, b)
    out[4 * i + 1] = shifted_conditional_ucw(a, b)
    out[4 * i + 2] = float(roulette_pick(a, 5))
    out[4 * i + 3] = canonical_roulette_weight(1, b > 0.0, 5) + 10.0 * canonical_roulette_weight(0, b > 0.0, 5)


@wp.kernel
def _window_kernel(kept: int, count: int, out: wp.array2d(dtype=float)):
    first, j = wp.tid()
    out[first, j] = roulette_window_weight(roulette_window_holds(j, first, kept, count), kept, count)


@pytest.mark.parametrize("kept,count", [(1, 8), (3, 8), (2, 5), (5, 5), (4, 7)])
def test_a_roulette_window_weights_each_prefix_one_on_average(kept, count):
    """Over the uniform first index, each prefix is traced kept/count of the time and weighted count/kept: E[w] = 1
    exactly, and every first index traces exactly ``kept`` prefixes."""
    out = wp.zeros((count, count), dtype=float)
    wp.launch(_window_kernel, dim=(count, count), inputs=[kept, count, out])
    w = out.numpy()
    np.testing.assert_allclose(w.mean(axis=0), 1.0, rtol=1e-6)  # each prefix j
    assert np.all((w > 0).sum(axis=1) == kept)  # each frame
    np.testing.assert_allclose(w[w > 0], count / kept, rtol=1e-6)


def test_core_functions_on_hand_computed_cases():
    cases = np.array([[2.0, 3.0], [0.5, -2.0], [-1.0, 2.0], [0.0, 4.0], [0.99999, 0.0], [np.nan, 1.0]], dtype=np.float32)
    out = wp.zeros(4 * len(cases), dtype=float)
    wp.launch(_core_values_kernel, dim=len(cases), inputs=[wp.array(cases, dtype=wp.vec2), out])
    got = out.numpy().reshape(-1, 4)
    # joint UCW W1·W2 (Thm. 4.1): 0 for non-positive or NaN products, never NaN
    np.testing.assert_array_equal(got[:, 0], [6.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    # W_{Y|Z} = W_{X|Z}|T'| (Sec. 6.3)
    np.testing.assert_array_equal(got[:, 1], [6.0, 1.0, 0.0, 0.0, 0.0, 0.0])
    # roulette pick: floor(u·N) clamped to 0 … N−1
    assert got[0, 2] == 4 and got[1, 2] == 2 and got[2, 2] == 0 and got[4, 2] == 4
    # roulette weight N for the chosen prefix, 0 otherwise; 1 without roulette
    np.testing.assert_array_equal(got[:, 3], [15.0, 10.0, 15.0, 15.0, 10.0, 15.0])
    assert np.all(np.isfinite(got))


def test_exact_value_matches_a_quadrature_oracle():
    def f(theta, z, c):
        s = 0.6 * z + theta * (0.5 + 0.5 * z)
        return (0.1 + (1 - (z - c) ** 2) ** 4) * (1.2 - 0.4 * theta * (0.5 + 0.5 * z)) * (0.05 + 4 * (s * (1.6 - s) / 0.64) ** 4)

    for c in (0.125, 0.4, 0.875):
        oracle, _ = scipy.integrate.dblquad(f, 0.0, 1.0, 0.0, 1.0, args=(c,), epsabs=1e-12, epsrel=1e-12)
        np.testing.assert_allclose(path_integral_exact(c), oracle, rtol=1e-11)


# ---- properties ----------------------------------------------------------------------------


@wp.kernel
def _mis_row_kernel(
    spec: PathsSpec,
    mode: int,
    z: float,
    y: float,
    canonical: int,
    prefixes: wp.array(dtype=float),
    confidences: wp.array(dtype=float),
    targets: wp.array(dtype=float),
    weights: wp.array(dtype=float),
    carried: wp.array(dtype=float),
):
    for j in range(prefixes.shape[0]):
        weights[j] = CRIS.conditional_mis(spec, mode, z, y, j, canonical, prefixes, confidences, targets, -1.0)
    for j in range(prefixes.shape[0]):
        carried[j] = targets[j]


def _spec() -> PathsSpec:
    s = PathsSpec()
    s.center = 0.4
    s.use_jacobian = 1
    return s


@settings(deadline=None, max_examples=40)
@given(
    z=st.floats(0.0, 1.0),
    y=st.floats(0.0, 0.999),
    others=st.lists(st.floats(0.0, 1.0), min_size=1, max_size=6),
    alphas=st.lists(st.floats(0.05, 20.0), min_size=7, max_size=7),
    canonical_alpha=st.sampled_from([0.0, 1.0, 3.0]),
    mode=st.sampled_from([0, 1]),
)
def test_conditional_mis_weights_of_the_domains_containing_y_sum_to_one(z, y, others, alphas, canonical_alpha, mode):
    prefixes = np.array([z, *others], dtype=np.float32)  # entry 0: the destination's own domain
    conf = np.array(alphas[: len(prefixes)], dtype=np.float32)
    conf[0] = canonical_alpha
    n = len(prefixes)
    weights, carried, scratch = (wp.zeros(n, dtype=float) for _ in range(3))
    wp.launch(
        _mis_row_kernel,
        dim=1,
        inputs=[_spec(), PROXY_SOURCE_PDF if mode else PROXY_TARGET, float(z), float(y), 0, wp.array(prefixes, dtype=float), wp.array(conf, dtype=float), scratch, weights, carried],
    )
    m, t = weights.numpy(), carried.numpy()
    contains = (t > 0) & (conf > 0)  # the domains whose support holds y (and that take part)
    assert np.all(m >= 0) and np.all(np.isfinite(m))
    assert np.all(m[~contains] == 0.0)
    if contains.any():
        assert math.isclose(float(m.sum()), 1.0, rel_tol=1e-5)
    else:
        assert m.sum() == 0.0
    # domain j holds y exactly when y's preimage A z + y ℓ(z) − A z_j lies in [0, ℓ(z_j)]
    s = 0.6 * z + y * (0.5 + 0.5 * z)
    pre = (s - 0.6 * prefixes.astype(np.float64)) / (0.5 + 0.5 * prefixes.astype(np.float64))
    inside = (pre >= 1e-5) & (pre <= 1 - 1e-5)
    assert np.all(t[1:][inside[1:]] > 0) and np.all(t[1:][(pre[1:] < -1e-5) | (pre[1:] > 1 + 1e-5)] == 0)


@wp.kernel
def _source_shortcut_kernel(
    spec: PathsSpec,
    mode: int,
    z: float,
    theta: float,
    prefixes: wp.array(dtype=float),
    confidences: wp.array(dtype=float),
    targets: wp.array(dtype=float),
    out: wp.array2d(dtype=float),
):
    # source j's own suffix θ shifted to z: its weight with every domain shifted, with its own domain read from θ, and
    # with the Jacobian not inverted (the sibling that must differ)
    for j in range(1, prefixes.shape[0]):
        s = suffix_shift(spec, prefixes[j], z, theta)
        out[j, 0] = float(s.valid)
        if s.valid:
            out[j, 1] = CRIS.conditional_mis(spec, mode, z, s.x, j, 0, prefixes, confidences, targets, -1.0)
            out[j, 2] = CRIS.conditional_mis(spec, mode, z, s.x, j, 0, prefixes, confidences, targets, CRIS.source_carried_target(spec, mode, prefixes[j], theta, s.jacobian))
            out[j, 3] = CRIS.conditional_mis(spec, mode, z, s.x, j, 0, prefixes, confidences, targets, CRIS.source_carried_target(spec, mode, prefixes[j], theta, 1.0 / s.jacobian))
            out[j, 4] = s.jacobian


@settings(deadline=None, max_examples=40)
@given(
    z=st.floats(0.0, 1.0),
    theta=st.floats(0.05, 0.9),
    others=st.lists(st.floats(0.0, 1.0), min_size=1, max_size=6),
    alphas=st.lists(st.floats(0.05, 20.0), min_size=7, max_size=7),
    mode=st.sampled_from([0, 1]),
)
def test_the_sources_own_domain_read_from_its_suffix_equals_its_inverse_shift(z, theta, others, alphas, mode):
    """conditional_mis with p̂_{←j}(T(x_j)) = p̂_j(x_j)/|T'| (no shift) gives the weight of the inverse shift; with |T'| in
    place of its inverse it does not (where |T'| ≠ 1)."""
    prefixes = np.array([z, *others], dtype=np.float32)
    conf = np.array(alphas[: len(prefixes)], dtype=np.float32)
    n = len(prefixes)
    out = wp.zeros((n, 5), dtype=float)
    wp.launch(
        _source_shortcut_kernel,
        dim=1,
        inputs=[_spec(), PROXY_SOURCE_PDF if mode else PROXY_TARGET, float(z), float(theta), wp.array(prefixes, dtype=float), wp.array(conf, dtype=float), wp.zeros(n, dtype=float), out],
    )
    for valid, full, short, wrong, jac in out.numpy()[1:]:
        if valid:
            assert short == pytest.approx(full, rel=1e-4, abs=1e-6)
            if abs(jac - 1.0) > 0.05 and 0.02 < full < 0.98:
                assert wrong != pytest.approx(full, rel=1e-3)


@wp.kernel
def _shift_kernel(spec: PathsSpec, z_src: float, z_dst: float, theta: float, h: float, out: wp.array(dtype=float)):
    s = suffix_shift(spec, z_src, z_dst, theta)
    back = suffix_shift(spec, z_dst, z_src, s.x)
    plus = suffix_shift(spec, z_src, z_dst, theta + h)
    out[0] = float(s.valid)
    out[1] = s.x
    out[2] = s.jacobian
    out[3] = back.x
    out[4] = back.jacobian
    out[5] = (plus.x - s.x) / h
    out[6] = float(plus.valid)


@settings(deadline=None, max_examples=40)
@given(z_src=st.floats(0.0, 1.0), z_dst=st.floats(0.0, 1.0), theta=st.floats(0.05, 0.9))
def test_suffix_shift_inverse_and_jacobian(z_src, z_dst, theta):
    out = wp.zeros(7, dtype=float)
    wp.launch(_shift_kernel, dim=1, inputs=[_spec(), float(z_src), float(z_dst), float(theta), 1e-2, out])
    valid, x, jac, back, back_jac, fd, plus_valid = out.numpy()
    if valid and 0.01 < x < 0.99:
        assert back == pytest.approx(theta, abs=1e-5)  # T⁻¹(T(θ)) = θ
        assert jac * back_jac == pytest.approx(1.0, rel=1e-5)  # |T'| |T'⁻¹| = 1
        if plus_valid:
            assert jac == pytest.approx(fd, rel=1e-3)  # affine in θ: finite differences are exact up to rounding


# ---- statistics ------------------------------------------------------------------------------


@pytest.mark.parametrize("case", UNBIASED, ids=_label)
def test_unbiased_methods_match_the_exact_value(case):
    name, method, params = case
    est = run_toy(name, method, trials=TRIALS[name], seed=SEED, params=params)
    assert not PROBLEMS[name].is_biased(method, est.params)
    result = z_test(est.estimate, est.stderr, est.exact, k=DEFAULT_K)
    assert result.passed, f"{name} {method} {params}: {result}"


@pytest.mark.parametrize("case", BIASED, ids=_label)
def test_known_biased_variants_are_caught(case):
    name, method, params = case
    est = run_toy(name, method, trials=TRIALS[name], seed=SEED, params=params)
    assert PROBLEMS[name].is_biased(method, est.params)
    assert z_test(est.estimate, est.stderr, est.exact).max_abs_z > BIASED_K, est.z


def test_every_conditional_problem_declares_a_biased_variant():
    assert {b[0] for b in BIASED} == set(NAMES)
    assert ("joint-ucw", "dependent", {}) in BIASED
    assert ("final-gather", "gather", {"canonical": False}) in BIASED


@pytest.mark.parametrize("prefixes", [3, 6])
def test_roulette_has_the_mean_of_all_canonical(prefixes):
    # independent seeds: the two estimators' difference is N(0, se1² + se2²) if their means agree
    a = run_toy("final-gather", "gather", trials=60_000, seed=SEED + 1, params={"prefixes": prefixes, "roulette": True})
    b = run_toy("final-gather", "gather", trials=60_000, seed=SEED + 2, params={"prefixes": prefixes, "roulette": False})
    z = (a.estimate - b.estimate) / math.hypot(a.stderr, b.stderr)
    assert abs(z) <= DEFAULT_K, z
    # ... at 1/N of the canonical suffixes, and with more variance (the price of roulette)
    assert a.stats["canonical_suffixes"] == 1.0 and b.stats["canonical_suffixes"] == prefixes
    assert a.stderr > b.stderr


def test_work_counters_follow_the_configuration():
    g = run_toy("final-gather", "gather", trials=2000, seed=1, params={"prefixes": 5, "k": 2, "support": 6, "candidates": 3, "passes": 0})
    assert g.stats["canonical_suffixes"] == 1.0
    assert g.stats["support_prefixes"] == 6 * 3 and g.stats["support_suffixes"] == 6 * 3 and g.stats["prefixes"] == 5
    assert g.stats["support_shifts"] == 0 and g.stats["gather_rays"] < g.stats["rays"]
    assert 0 < g.stats["borrowed_suffixes"] <= 5 * 2
    all_canon = run_toy("final-gather", "gather", trials=2000, seed=1, params={"prefixes": 5, "roulette": False})
    assert all_canon.stats["canonical_suffixes"] == 5.0  # roulette saves 80% of canonical suffixes at N = 5
    none = run_toy("final-gather", "mmis", trials=2000, seed=1, params={"canonical": False})
    assert none.stats["canonical_suffixes"] == 0.0
    m3 = run_toy("final-gather", "mmis", trials=2000, seed=1, params={"suffixes": 3})
    m1 = run_toy("final-gather", "mmis", trials=2000, seed=1, params={"suffixes": 1})
    assert m3.stats["shifts"] > 3 * m1.stats["shifts"]  # the balance heuristic's quadratic cost
    r = run_toy("suffix-reuse", "cris", trials=2000, seed=1, params={"pixels": 3, "passes": 2, "candidates": 2})
    assert r.stats["prefixes"] == 3 * 2 * 2 and r.stats["suffixes"] == 3 * 2 * 2
    assert r.stats["rays"] > r.stats["shifts"]


def test_samples_and_determinism(device):
    a = run_toy("suffix-reuse", "cris", trials=3000, seed=3, device=device, return_samples=True)
    b = run_toy("suffix-reuse", "cris", trials=3000, seed=3, device=device)
    assert np.array_equal(a.estimate, b.estimate)
    assert a.samples.shape == (3000, 4) and np.all((a.samples >= 0) & (a.samples <= 1))
    j = run_toy("joint-ucw", "independent", trials=3000, seed=3, device=device, return_samples=True)
    assert j.samples.shape == (3000,)


@pytest.mark.parametrize(
    "name, method, params, text",
    [
        ("final-gather", "gather", {"k": 9}, "k"),
        ("final-gather", "mmis", {"suffixes": 4, "support": 3}, "suffixes"),
        ("final-gather", "gather", {"prefixes": 0}, "prefixes"),
        ("suffix-reuse", "cris", {"passes": 0}, "passes"),
        ("joint-ucw", "independent", {"candidates": "x"}, "candidates"),
    ],
)
def test_bad_input_raises_a_named_error(name, method, params, text):
    with pytest.raises(InvalidParameterError, match=text):
        get_problem(name).resolve_params(method, params)
