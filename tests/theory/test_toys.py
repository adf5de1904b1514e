"""Statistical tests of every toy estimator against its exact value.

Unbiased configurations must land within 4σ (Šidák-corrected over pixels);
every configuration a problem declares biased must land beyond 6σ at the same
trial counts — the proof that the check can fail.
"""

import numpy as np
import pytest
import scipy.integrate

from grisx.errors import DeviceError, InvalidParameterError, InvalidValueError, UnknownNameError
from grisx.testing import BIASED_K, DEFAULT_K, z_test
from grisx.theory.toys import PROBLEMS, get_problem, run_toy
from grisx.theory.toys.reconnection_flatland import flatland_scene

TRIALS = {"ris-1d": 1_000_000, "gris-shift": 200_000, "reconnection-flatland": 200_000, "joint-ucw": 200_000, "suffix-reuse": 60_000, "final-gather": 60_000, "sms-toy": 20_000, "f1-f2": 200_000, "gradient-row": 80_000, "chromatic-cv": 2_000}

UNBIASED = [
    ("ris-1d", "mc", {}),
    ("ris-1d", "ris", {}),
    ("ris-1d", "ris", {"target": "approx"}),
    ("ris-1d", "ris", {"candidates": 1}),
    ("ris-1d", "ris", {"candidates": 64, "target": "approx"}),
    ("gris-shift", "gris", {"passes": 0}),
    ("gris-shift", "gris", {"mis": "balance"}),
    ("gris-shift", "gris", {"mis": "pairwise"}),
    ("gris-shift", "gris", {"mis": "uniform"}),
    ("gris-shift", "gris", {"mis": "balance", "passes": 3}),
    ("gris-shift", "gris", {"mis": "pairwise", "passes": 2, "cap": 2}),
    ("gris-shift", "gris", {"mis": "uniform", "candidates": 1, "pixels": 7}),
    ("gris-shift", "gris", {"mis": "naive", "pixels": 4}),  # no partial pixel: naive is unbiased here
    ("reconnection-flatland", "gris", {"passes": 0}),
    ("reconnection-flatland", "gris", {"mis": "uniform"}),
    ("reconnection-flatland", "gris", {"mis": "balance"}),
    ("reconnection-flatland", "gris", {"mis": "pairwise", "source": "cosine"}),
    ("reconnection-flatland", "gris", {"mis": "naive", "occluder": False}),
    ("reconnection-flatland", "gris", {"mis": "uniform", "passes": 2, "pixels": 3}),
]

BIASED = [(name, b.method, dict(b.params)) for name, p in PROBLEMS.items() for b in p.biased_variants]


def _label(case):
    name, method, params = case
    return f"{name}-{method}-" + ",".join(f"{k}={v}" for k, v in params.items())


@pytest.mark.parametrize("case", UNBIASED, ids=_label)
def test_unbiased_methods_match_the_exact_value(case):
    name, method, params = case
    est = run_toy(name, method, trials=TRIALS[name], seed=20261121, params=params)
    assert not PROBLEMS[name].is_biased(method, est.params)
    result = z_test(est.estimate, est.stderr, est.exact, k=DEFAULT_K)
    assert result.passed, f"{name} {method} {params}: {result}"


@pytest.mark.parametrize("case", BIASED, ids=_label)
def test_known_biased_variants_are_caught(case):
    name, method, params = case
    est = run_toy(name, method, trials=TRIALS[name], seed=20261121, params=params)
    assert PROBLEMS[name].is_biased(method, est.params)
    assert z_test(est.estimate, est.stderr, est.exact).max_abs_z > BIASED_K


def test_every_problem_declares_a_biased_variant_that_is_tested():
    assert {b[0] for b in BIASED} == set(PROBLEMS)


@pytest.mark.parametrize("seed", [0, 7, 123456])
def test_ris_unbiased_at_1e6_trials_for_several_seeds(seed):
    est = run_toy("ris-1d", "ris", trials=1_000_000, seed=seed, params={"target": "approx"})
    assert z_test(est.estimate, est.stderr, est.exact).passed


# ---- the records and their contract -----------------------------------------------


def test_estimate_fields_and_determinism(device):
    a = run_toy("gris-shift", "gris", trials=5000, seed=3, device=device)
    b = run_toy("gris-shift", "gris", trials=5000, seed=3, device=device)
    c = run_toy("gris-shift", "gris", trials=5000, seed=4, device=device)
    assert np.array_equal(a.estimate, b.estimate) and not np.array_equal(a.estimate, c.estimate)
    d = a.to_dict()
    for key in ("estimate", "stderr", "exact", "trials", "seconds", "method", "problem", "z", "params"):
        assert key in d
    assert len(d["estimate"]) == len(d["exact"]) == 5 and d["trials"] == 5000 and d["seconds"] > 0


def test_trials_split_into_chunks_give_the_same_answer_as_one_launch(monkeypatch):
    # trial t always uses stream t: chunking must not change any number
    problem = get_problem("ris-1d")
    whole = problem.run("ris", trials=10_000, seed=5)
    monkeypatch.setattr(type(problem), "chunk_trials", 3000)
    parts = problem.run("ris", trials=10_000, seed=5)
    np.testing.assert_allclose(parts.estimate, whole.estimate, rtol=1e-12)
    np.testing.assert_allclose(parts.stderr, whole.stderr, rtol=1e-9)


def test_samples_are_returned_for_histograms():
    est = run_toy("ris-1d", "ris", trials=20_000, seed=1, return_samples=True)
    assert est.samples.shape == (20_000,)
    assert np.all((est.samples >= 0) & (est.samples < 1))
    # p̂ = f puts 38% of its mass on [0.2, 0.4] (uniform: 20%); RIS with M = 8 is already close
    assert np.mean(np.abs(est.samples - 0.3) < 0.1) > 0.3
    vec = run_toy("gris-shift", "gris", trials=1000, seed=1, return_samples=True)
    assert vec.samples.shape == (1000, 5)


# ---- exact values against independent oracles ---------------------------------------


@pytest.mark.parametrize("occluder", [True, False])
def test_flatland_exact_values_match_an_angle_space_quadrature(occluder):
    """Independent oracle: integrate over θ with numpy ray casting instead of over the emitter."""
    problem = get_problem("reconnection-flatland")
    params = problem.resolve_params("gris", {"occluder": occluder})
    exact = problem.exact(params)
    scene = flatland_scene(params["pixels"])
    a, b = scene["emitter"]
    p, q = scene["occluder"]
    theta = np.linspace(-np.pi / 2, np.pi / 2, 2_000_001)[1:-1]
    d = np.stack([np.sin(theta), np.cos(theta)], axis=1)

    def hits(o, a, b):
        e = b - a
        denom = d[:, 0] * e[1] - d[:, 1] * e[0]
        ao = a - o
        t = (ao[0] * e[1] - ao[1] * e[0]) / denom
        s = (ao[0] * d[:, 1] - ao[1] * d[:, 0]) / denom
        return t, s, (t > 0) & (s >= 0) & (s <= 1)

    for k, (x1, rho) in enumerate(zip(scene["visible"], scene["albedo"])):
        t, s, hit = hits(x1, a, b)
        if occluder:
            to, _, hit_o = hits(x1, p, q)
            hit &= ~(hit_o & (to < t))
        f = np.where(hit, 0.5 * rho * np.cos(theta) * (1 + 0.8 * np.sin(3 * np.pi * s)), 0.0)
        oracle = scipy.integrate.trapezoid(f, theta)
        np.testing.assert_allclose(exact[k], oracle, rtol=2e-5)


def test_ris1d_exact_matches_quadrature():
    f = lambda x: 0.2 + np.exp(-(((x - 0.3) / 0.06) ** 2)) + 0.5 * np.exp(-(((x - 0.72) / 0.1) ** 2))  # noqa: E731
    oracle, _ = scipy.integrate.quad(f, 0, 1, epsabs=1e-13)
    np.testing.assert_allclose(get_problem("ris-1d").exact({})[0], oracle, rtol=1e-10)


# ---- bad input -------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kwargs, error, text",
    [
        ({"name": "ris-2d", "method": "ris"}, UnknownNameError, "toy problem 'ris-2d'"),
        ({"name": "ris-1d", "method": "restir"}, UnknownNameError, "method of toy 'ris-1d'"),
        ({"name": "ris-1d", "method": "ris", "params": {"alpha": 1}}, UnknownNameError, "param of toy"),
        ({"name": "ris-1d", "method": "ris", "params": {"candidates": 0}}, InvalidParameterError, "candidates"),
        ({"name": "ris-1d", "method": "ris", "params": {"candidates": "many"}}, InvalidParameterError, "candidates"),
        ({"name": "ris-1d", "method": "ris", "params": {"target": "exact"}}, InvalidParameterError, "target"),
        ({"name": "gris-shift", "method": "gris", "params": {"cap": "nan"}}, InvalidParameterError, "cap"),
        ({"name": "gris-shift", "method": "gris", "params": {"jacobian": "maybe"}}, InvalidParameterError, "jacobian"),
        ({"name": "gris-shift", "method": "gris", "params": {"pixels": 1}}, InvalidParameterError, "pixels >= 2"),
        ({"name": "ris-1d", "method": "ris", "trials": 0}, InvalidParameterError, "trials"),
        ({"name": "ris-1d", "method": "ris", "trials": -5}, InvalidParameterError, "trials"),
        ({"name": "ris-1d", "method": "ris", "seed": -1}, InvalidParameterError, "seed"),
    ],
)
def test_bad_input_raises_a_named_grisx_error(kwargs, error, text):
    with pytest.raises(error, match=text):
        run_toy(**kwargs)


def test_cuda_on_a_machine_without_one_is_a_device_error():
    from grisx.device import cuda_available

    if cuda_available():
        pytest.skip("this machine has CUDA: the error path cannot be exercised")
    with pytest.raises(DeviceError, match="cuda"):
        run_toy("ris-1d", "ris", trials=10, device="cuda")


def test_nan_trial_estimates_are_an_error_not_a_result(monkeypatch):
    problem = get_problem("ris-1d")
    original = problem.launch

    def poisoned(*args, **kwargs):
        original(*args, **kwargs)
        batch = args[4]
        values = batch.values.numpy()
        values[0, 0] = np.nan
        batch.values.assign(values)

    monkeypatch.setattr(problem, "launch", poisoned)
    with pytest.raises(InvalidValueError, match="NaN"):
        problem.run("ris", trials=100)
