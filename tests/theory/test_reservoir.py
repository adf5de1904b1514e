"""The reservoir: hand-computed cases, properties, and selection statistics."""

import numpy as np
import pytest
import scipy.stats
from hypothesis import given, settings
from hypothesis import strategies as st

from grisx.errors import InvalidValueError
from grisx.theory.batch import merge, resample, resampling_weights


# ---- hand-computed cases ------------------------------------------------------


def test_single_candidate_is_always_kept(device):
    r = resample(np.full((1000, 1), 2.5), targets=np.full((1000, 1), 5.0), device=device)
    assert np.all(r.index == 0)
    np.testing.assert_allclose(r.w_sum, 2.5)
    np.testing.assert_allclose(r.ucw, 0.5)  # W = w_sum / p̂(y) = 2.5 / 5 (seed 000, Eq. 8)
    np.testing.assert_allclose(r.confidence, 1.0)


def test_empty_and_all_zero_reservoirs_finalize_to_zero(device):
    r = resample(np.zeros((4, 3)), device=device)
    assert np.all(r.index == -1)
    assert np.all(r.ucw == 0.0) and np.all(r.w_sum == 0.0)
    np.testing.assert_allclose(r.confidence, 3.0)  # zero-weight candidates still count


def test_ucw_formula_hand_computed():
    # weights (1, 3), targets (2, 6): W = (1 + 3) / p̂(y) for whichever y is kept
    r = resample(np.tile([[1.0, 3.0]], (500, 1)), targets=np.tile([[2.0, 6.0]], (500, 1)), seed=1)
    expected = np.where(r.index == 0, 4.0 / 2.0, 4.0 / 6.0)
    np.testing.assert_allclose(r.ucw, expected, rtol=1e-6)


def test_resampling_weight_hand_computed():
    # w = m p̂ W |J| (seed 000, Eq. 9); negative Jacobian sign is dropped, zeros give 0
    w = resampling_weights([0.5, 0.25, 1.0, 0.0], [2.0, 4.0, 3.0, 1.0], [3.0, 1.0, 0.0, 2.0], [1.0, -2.0, 1.0, 1.0])
    np.testing.assert_allclose(w, [3.0, 2.0, 0.0, 0.0])


def test_merge_hand_computed():
    # merging (W=1, c=1) and (W=2, c=3) with m = 1/2 and shifted targets 2, 4
    r = merge([[1.0, 2.0]] * 200, [[1.0, 3.0]] * 200, [[0.5, 0.5]] * 200, [[2.0, 4.0]] * 200, seed=2)
    np.testing.assert_allclose(r.w_sum, 0.5 * 2 * 1 + 0.5 * 4 * 2)
    np.testing.assert_allclose(r.confidence, 4.0)
    np.testing.assert_allclose(r.ucw, np.where(r.index == 0, 5.0 / 2.0, 5.0 / 4.0), rtol=1e-6)


# ---- bad input at the boundary ---------------------------------------------------


@pytest.mark.parametrize("bad", [np.nan, np.inf, -1.0])
def test_bad_weights_are_rejected_with_a_named_error(bad):
    w = np.ones((2, 3))
    w[1, 2] = bad
    with pytest.raises(InvalidValueError, match="weights"):
        resample(w)
    with pytest.raises(InvalidValueError, match="targets"):
        resample(np.ones((2, 3)), targets=w)


# ---- properties --------------------------------------------------------------------


@settings(max_examples=60, deadline=None)
@given(st.lists(st.one_of(st.just(0.0), st.floats(1e-30, 1e30)), min_size=1, max_size=12), st.integers(0, 2**31 - 1))
def test_extreme_and_zero_weights_never_give_nan_or_inf(weights, seed):
    w = np.array([weights])
    r = resample(w, seed=seed)
    for a in (r.w_sum, r.ucw, r.target):
        assert np.all(np.isfinite(a))
    if w.max() > 0:
        assert r.index[0] >= 0 and w[0, r.index[0]] > 0  # only positive weights are ever kept
        np.testing.assert_allclose(r.ucw[0], w.sum() / w[0, r.index[0]], rtol=1e-5)
    else:
        assert r.index[0] == -1 and r.ucw[0] == 0.0


@settings(max_examples=25, deadline=None)
@given(st.lists(st.floats(0.01, 100.0), min_size=2, max_size=8), st.floats(1e-20, 1e20))
def test_estimate_is_invariant_to_scaling_the_target(weights, scale):
    # p̂ → s·p̂ scales every w = m p̂/p and p̂(y) by s, so the kept sample and
    # W = Σw / p̂(y) — hence the estimate f(y) W — do not change
    w = np.tile(weights, (64, 1))
    a = resample(w, seed=9)
    b = resample(w * scale, targets=w * scale, seed=9)
    assert np.array_equal(a.index, b.index)
    np.testing.assert_allclose(b.ucw, a.ucw, rtol=1e-4)


def test_selection_frequency_is_proportional_to_weight():
    w = np.array([0.5, 2.0, 0.0, 1.0, 4.5, 1e-3])
    n = 200_000
    r = resample(np.tile(w, (n, 1)), seed=123)
    counts = np.bincount(r.index, minlength=w.size)
    expected = n * w / w.sum()
    keep = expected > 0
    assert counts[~keep].sum() == 0
    p = scipy.stats.chisquare(counts[keep], expected[keep]).pvalue
    assert p > 1e-4, (counts, expected)


def test_selection_frequency_check_catches_a_biased_selector():
    # sibling: the same χ² check rejects selection by (unnormalised) w² instead of w
    w = np.array([0.5, 2.0, 1.0, 4.5])
    n = 200_000
    r = resample(np.tile(w**2, (n, 1)), seed=123)
    counts = np.bincount(r.index, minlength=w.size)
    assert scipy.stats.chisquare(counts, n * w / w.sum()).pvalue < 1e-10


def test_merge_order_does_not_change_the_distribution():
    # merging inputs (a, b, c) or (c, a, b): the kept input's frequencies agree (two-sample χ²)
    n = 100_000
    ucw = np.array([1.0, 0.5, 2.0])
    conf = np.array([1.0, 2.0, 4.0])
    tgt = np.array([3.0, 1.0, 0.5])
    m = conf / conf.sum()
    a = merge(np.tile(ucw, (n, 1)), np.tile(conf, (n, 1)), np.tile(m, (n, 1)), np.tile(tgt, (n, 1)), seed=1)
    perm = [2, 0, 1]
    b = merge(np.tile(ucw[perm], (n, 1)), np.tile(conf[perm], (n, 1)), np.tile(m[perm], (n, 1)), np.tile(tgt[perm], (n, 1)), seed=2)
    counts_a = np.bincount(a.index, minlength=3)
    counts_b = np.bincount(np.array(perm)[b.index], minlength=3)
    _, p, _, _ = scipy.stats.chi2_contingency(np.stack([counts_a, counts_b]))
    assert p > 1e-4, (counts_a, counts_b)
    np.testing.assert_allclose(a.w_sum, b.w_sum, rtol=1e-6)
    np.testing.assert_allclose(a.confidence, 7.0)
