"""Counter-based uniforms: range, determinism, uniformity and independence."""

import numpy as np
import scipy.stats

from grisx.testing import chi2_test
from grisx.theory.batch import uniforms


def test_range_and_determinism(device):
    a = uniforms(3, np.arange(2000), np.arange(50), device=device)
    b = uniforms(3, np.arange(2000), np.arange(50), device=device)
    assert np.array_equal(a, b)
    assert a.min() >= 0.0 and a.max() < 1.0
    assert not np.array_equal(a, uniforms(4, np.arange(2000), np.arange(50), device=device))


def test_uniform_chi2():
    u = uniforms(11, np.arange(20_000), np.arange(20)).ravel()
    result = chi2_test(u, lambda x: np.ones_like(x), 0.0, 1.0, bins=100)
    assert result.passed, result


def test_chi2_catches_a_skewed_generator():
    # sibling: u² is not uniform, the same check must reject it
    u = uniforms(11, np.arange(20_000), np.arange(20)).ravel() ** 1.05
    assert not chi2_test(u, lambda x: np.ones_like(x), 0.0, 1.0, bins=100).passed


def test_neighbouring_streams_and_counters_are_uncorrelated():
    u = uniforms(5, np.arange(100_000), np.arange(2))
    # adjacent counters within a stream, and adjacent streams for one counter
    for a, b in ((u[:, 0], u[:, 1]), (u[:-1, 0], u[1:, 0])):
        r, _ = scipy.stats.pearsonr(a, b)
        assert abs(r) < 4.0 / np.sqrt(a.size), r  # 4 sigma under independence


def test_seeds_differing_by_one_are_unrelated():
    a = uniforms(0, np.arange(1, 50_001), [0]).ravel()
    b = uniforms(1, np.arange(0, 50_000), [0]).ravel()
    assert np.count_nonzero(a == b) < 5  # equal 24-bit values only by coincidence
