"""MIS weights: hand-computed values and the sum-to-one property that unbiasedness rests on."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from grisx.errors import UnknownNameError
from grisx.theory.batch import mis_weights


def test_balance_hand_computed():
    # m_i = c_i p̂_{←i} / Σ c_j p̂_{←j} (seed 001, Eq. 15): c = (1, 2, 1), p̂ = (1, 1, 2) → (1, 2, 2)/5
    np.testing.assert_allclose(mis_weights("balance", [[1, 2, 1]], [[1, 1, 2]]), [[0.2, 0.4, 0.4]], rtol=1e-6)


def test_pairwise_unit_confidence_is_bitterlis_form():
    # k neighbours, unit confidences: m_i = (1/k) p̂_i / (p̂_i + p̂_c / k)
    t = np.array([[2.0, 1.0, 3.0, 0.5]])  # canonical is domain 0
    m = mis_weights("pairwise", np.ones_like(t), t, canonical=0)
    k = 3
    expected_neighbours = (1 / k) * t[0, 1:] / (t[0, 1:] + t[0, 0] / k)
    np.testing.assert_allclose(m[0, 1:], expected_neighbours, rtol=1e-6)
    np.testing.assert_allclose(m.sum(), 1.0, rtol=1e-6)


def test_support_counting_hand_computed():
    # seed 004, Alg. 4: Z counts only domains with p̂_{←j}(y) > 0; c = (2, 1, 1)
    m = mis_weights("uniform", [[2, 1, 1]], [[0.3, 0.0, 5.0]])
    np.testing.assert_allclose(m, [[2 / 3, 0.0, 1 / 3]], rtol=1e-6)
    naive = mis_weights("naive", [[2, 1, 1]], [[0.3, 0.0, 5.0]])
    np.testing.assert_allclose(naive, [[0.5, 0.25, 0.25]], rtol=1e-6)


positive_rows = st.integers(1, 8).flatmap(
    lambda k: st.tuples(
        arrays(np.float64, (16, k), elements=st.floats(0.1, 40.0)),
        arrays(np.float64, (16, k), elements=st.one_of(st.just(0.0), st.floats(1e-6, 1e6))),
    )
)


@settings(max_examples=60, deadline=None)
@given(positive_rows, st.sampled_from(["balance", "pairwise", "uniform"]))
def test_weights_of_covering_domains_sum_to_one(rows, mode):
    confidence, target_from = rows
    canonical = 0
    target_from[:, canonical] = np.maximum(target_from[:, canonical], 1e-3)  # the canonical domain covers y
    m = mis_weights(mode, confidence, target_from, canonical=canonical)
    assert np.all(np.isfinite(m)) and np.all(m >= 0)
    covering = target_from > 0
    np.testing.assert_allclose((m * covering).sum(axis=1), 1.0, rtol=2e-5)
    assert np.all(m[~covering] < 1e-7) or mode == "naive"


@settings(max_examples=30, deadline=None)
@given(positive_rows)
def test_naive_weights_miss_one_wherever_a_domain_cannot_reach_y(rows):
    # the sibling of the property above: naive c_j/Σc leaves out the share of non-covering domains
    confidence, target_from = rows
    target_from[:, 0] = np.maximum(target_from[:, 0], 1e-3)
    m = mis_weights("naive", confidence, target_from)
    covering = target_from > 0
    missing = (confidence * ~covering).sum(axis=1) / confidence.sum(axis=1)
    np.testing.assert_allclose((m * covering).sum(axis=1), 1.0 - missing, rtol=2e-5, atol=1e-6)


def test_pairwise_with_no_neighbours_gives_the_canonical_sample_everything():
    np.testing.assert_allclose(mis_weights("pairwise", [[3.0]], [[0.7]]), [[1.0]])


def test_unknown_mode_is_named():
    with pytest.raises(UnknownNameError, match="MIS mode 'heuristic'"):
        mis_weights("heuristic", [[1.0]], [[1.0]])
