"""Alias tables and piecewise-constant distributions: exact tables, round trips, χ² against their pmf/pdf."""

import numpy as np
import pytest
import warp as wp
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from grisx.errors import InvalidParameterError, InvalidValueError
from grisx.scene import distribution as D
from grisx.testing import chi2_test
from grisx.theory.random import random_key, random_uniform

wp.set_module_options({"enable_backward": False})

SEED = 20261121


@wp.kernel
def _alias_kernel(t: D.AliasTable, seed: int, index: wp.array(dtype=int), pmf: wp.array(dtype=float)):
    i = wp.tid()
    k = random_key(seed, i)
    j = D.sample_alias(t, random_uniform(k, 0))
    index[i] = j
    pmf[i] = D.alias_pmf(t, j)


@wp.kernel
def _dist1d_kernel(d: D.PiecewiseConstant1D, seed: int, x: wp.array(dtype=float), pdf: wp.array(dtype=float),
                   pdf_eval: wp.array(dtype=float), u_back: wp.array(dtype=float), u_in: wp.array(dtype=float)):
    i = wp.tid()
    u = random_uniform(random_key(seed, i), 0)
    s = D.sample_piecewise_constant_1d(d, u)
    u_in[i] = u
    x[i] = s.x
    pdf[i] = s.pdf
    pdf_eval[i] = D.piecewise_constant_1d_pdf(d, s.x)
    u_back[i] = D.invert_piecewise_constant_1d(d, s.x)


@wp.kernel
def _dist2d_kernel(d: D.PiecewiseConstant2D, us: wp.array(dtype=wp.vec2), uv: wp.array(dtype=wp.vec2), pdf: wp.array(dtype=float),
                   pdf_eval: wp.array(dtype=float), u_back: wp.array(dtype=wp.vec2)):
    i = wp.tid()
    s = D.sample_piecewise_constant_2d(d, us[i])
    uv[i] = s.uv
    pdf[i] = s.pdf
    pdf_eval[i] = D.piecewise_constant_2d_pdf(d, s.uv)
    u_back[i] = D.invert_piecewise_constant_2d(d, s.uv)


def _alias_samples(weights, n, device, seed=SEED):
    t = D.build_alias_table(np.asarray(weights, float), device)
    index = wp.zeros(n, dtype=int, device=device)
    pmf = wp.zeros(n, dtype=float, device=device)
    wp.launch(_alias_kernel, n, inputs=[t, seed, index, pmf], device=device)
    return index.numpy(), pmf.numpy()


def _step_pdf(masses):
    """Density on [0, n) that puts ``masses[i]`` uniformly on [i, i + 1): χ² of discrete draws via chi2_test."""
    m = np.asarray(masses, float)
    return lambda x: m[np.clip(np.floor(x).astype(int), 0, m.size - 1)]


def _discrete_chi2(indices, masses, seed=SEED):
    jitter = np.random.default_rng(seed).random(indices.size)  # spread each index over its unit bin
    return chi2_test(indices + jitter, _step_pdf(masses), 0.0, float(len(masses)), bins=len(masses))


# ---- exact tables --------------------------------------------------------------------


def _alias_implied_pmf(prob, alias):
    n = prob.size
    p = prob / n
    np.add.at(p, alias, (1.0 - prob) / n)
    return p


def test_alias_table_of_a_hand_case():
    prob, alias, pmf, total = D.alias_table_arrays(np.array([1.0, 0.0, 3.0, 4.0]))
    assert total == 8.0
    np.testing.assert_allclose(pmf, [0.125, 0.0, 0.375, 0.5])
    np.testing.assert_allclose(_alias_implied_pmf(prob, alias), pmf, atol=1e-15)
    assert prob[1] == 0.0 and alias[1] != 1  # a zero weight keeps no probability of its own


@settings(deadline=None, max_examples=60)
@given(arrays(np.float64, st.integers(1, 40), elements=st.one_of(st.just(0.0), st.floats(1e-6, 1e6))))
def test_alias_table_reproduces_every_pmf(weights):
    prob, alias, pmf, total = D.alias_table_arrays(weights)
    if weights.sum() == 0:
        assert total == 0.0 and np.all(pmf == 0)
        return
    np.testing.assert_allclose(_alias_implied_pmf(prob, alias), weights / weights.sum(), atol=1e-12)
    zero = weights == 0
    assert np.all(prob[zero] == 0) and not np.any(np.isin(np.flatnonzero(zero), alias[prob < 1]))


# ---- alias sampling statistics ------------------------------------------------------


WEIGHTS = np.array([5.0, 0.0, 1.0, 0.25, 3.0, 0.0, 8.0, 2.0, 0.5, 1.5])


def test_alias_frequencies_match_the_pmf(device):
    index, pmf = _alias_samples(WEIGHTS, 200_000, device)
    assert np.all(index >= 0) and not np.any(np.isin(index, np.flatnonzero(WEIGHTS == 0)))
    np.testing.assert_allclose(pmf, (WEIGHTS / WEIGHTS.sum())[index], rtol=1e-6)
    result = _discrete_chi2(index, WEIGHTS / WEIGHTS.sum())
    assert result.passed, str(result)


def test_alias_frequencies_against_a_wrong_pmf_are_caught(device):
    index, _ = _alias_samples(WEIGHTS, 200_000, device)
    wrong = WEIGHTS.copy()
    wrong[[2, 3]] = wrong[[3, 2]]  # two entries swapped: a plausible indexing bug
    result = _discrete_chi2(index, wrong / wrong.sum())
    assert not result.passed and result.p_value < 1e-12, str(result)


def test_alias_table_of_zero_weights_returns_no_sample(device):
    index, pmf = _alias_samples([0.0, 0.0, 0.0], 16, device)
    assert np.all(index == -1) and np.all(pmf == 0)


@pytest.mark.parametrize("bad, error", [([1.0, -1.0], InvalidValueError), ([1.0, np.nan], InvalidValueError),
                                        ([[1.0, 2.0]], InvalidParameterError), ([], InvalidParameterError)])
def test_alias_table_rejects_bad_weights(bad, error):
    with pytest.raises(error, match="weights"):
        D.build_alias_table(np.asarray(bad, float), "cpu")


# ---- piecewise-constant 1D ----------------------------------------------------------


FUNC_1D = np.array([0.0, 2.0, 2.0, 0.0, 0.0, 5.0, 1.0, 0.5, 0.0])


def _run_1d(func, n, device):
    d = D.build_piecewise_constant_1d(func, device)
    outs = [wp.zeros(n, dtype=float, device=device) for _ in range(5)]
    wp.launch(_dist1d_kernel, n, inputs=[d, SEED, *outs], device=device)
    return [o.numpy() for o in outs]


def test_piecewise_1d_samples_follow_the_pdf(device):
    x, pdf, pdf_eval, u_back, u_in = _run_1d(FUNC_1D, 100_000, device)
    density = FUNC_1D / FUNC_1D.mean()
    np.testing.assert_allclose(pdf, density[(x * FUNC_1D.size).astype(int)], rtol=1e-6)
    np.testing.assert_allclose(pdf_eval, pdf, rtol=1e-6)
    np.testing.assert_allclose(u_back, u_in, atol=2e-6)
    assert np.all(pdf > 0)  # never a sample in a zero cell
    result = chi2_test(x, lambda t: density[np.clip((t * FUNC_1D.size).astype(int), 0, FUNC_1D.size - 1)], 0.0, 1.0, bins=90)
    assert result.passed, str(result)


def test_piecewise_1d_of_zeros_has_zero_pdf(device):
    x, pdf, pdf_eval, _, _ = _run_1d(np.zeros(4), 64, device)
    assert np.all((x >= 0) & (x < 1)) and np.all(pdf == 0) and np.all(pdf_eval == 0)


# ---- piecewise-constant 2D ----------------------------------------------------------


def _run_2d(func, us, device):
    d = D.build_piecewise_constant_2d(func, device)
    n = len(us)
    u_in = wp.array(np.asarray(us, np.float32), dtype=wp.vec2, device=device)
    uv, pdf, pdf_eval, u_back = (wp.zeros(n, dtype=wp.vec2, device=device), wp.zeros(n, dtype=float, device=device),
                                 wp.zeros(n, dtype=float, device=device), wp.zeros(n, dtype=wp.vec2, device=device))
    wp.launch(_dist2d_kernel, n, inputs=[d, u_in, uv, pdf, pdf_eval, u_back], device=device)
    return uv.numpy(), pdf.numpy(), pdf_eval.numpy(), u_back.numpy()


@settings(deadline=None, max_examples=25)
@given(func=arrays(np.float64, st.tuples(st.integers(1, 6), st.integers(1, 7)),
                   elements=st.one_of(st.just(0.0), st.floats(1e-3, 1e3))).filter(lambda f: f.sum() > 0),
       us=arrays(np.float64, (32, 2), elements=st.floats(0.0, 0.999)))
def test_piecewise_2d_sample_pdf_invert_round_trip(func, us):
    uv, pdf, pdf_eval, u_back = _run_2d(func, us, "cpu")
    nv, nu = func.shape
    cell = func[np.minimum((uv[:, 1] * nv).astype(int), nv - 1), np.minimum((uv[:, 0] * nu).astype(int), nu - 1)]
    assert np.all((uv >= 0) & (uv < 1))
    assert np.all(cell > 0)  # samples land only where f > 0
    np.testing.assert_allclose(pdf, cell / func.mean(), rtol=1e-4)
    np.testing.assert_allclose(pdf_eval, pdf, rtol=1e-5)
    np.testing.assert_allclose(u_back, us, atol=1e-4)


def test_piecewise_2d_cell_frequencies_match(device):
    rng = np.random.default_rng(1)
    func = rng.random((6, 9)) ** 3
    func[2] = 0.0
    func[:, 4] = 0.0
    uv, _, _, _ = _run_2d(func, rng.random((200_000, 2)), device)
    cells = np.minimum((uv[:, 1] * 6).astype(int), 5) * 9 + np.minimum((uv[:, 0] * 9).astype(int), 8)
    result = _discrete_chi2(cells, (func / func.sum()).ravel())
    assert result.passed, str(result)


def test_piecewise_2d_rejects_bad_input():
    with pytest.raises(InvalidParameterError, match="2D"):
        D.build_piecewise_constant_2d(np.ones(4), "cpu")
    with pytest.raises(InvalidValueError, match="NaN"):
        D.build_piecewise_constant_2d(np.array([[1.0, np.inf]]), "cpu")
