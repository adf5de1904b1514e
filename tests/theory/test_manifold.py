"""Specular manifold sampling (seed 003): exact cases → properties → statistics.

The ladder: the toy's closed-form solutions and the core's closed forms
(P(C), W = K/P(C)) on hand-computed cases; hypothesis properties of the seed
pdf (Eq. 7) against numerical integration (Eq. 8, 9); the Bernoulli-trial
count E[K] = P(C)/P'(u*) against P' measured by brute force over a fine seed
grid; and every unbiased method against the exact per-pixel sum within 4σ
(Šidák over pixels), with the capped variant (max_trials = 2) caught beyond 6σ.
"""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from grisx.errors import InvalidParameterError
from grisx.testing import BIASED_K, DEFAULT_K, z_test
from grisx.theory.toys import PROBLEMS, get_problem, run_toy
from grisx.theory.toys.sms_toy import WARP_K, basin_map, bernoulli_samples, seed_space_values, solutions, view_layout

SEED = 20261121


def _g(theta, k):
    """float64 oracle of the toy's g(θ; k) = sin(2 atan(k tan(θ/2)))."""
    return np.sin(2.0 * np.arctan(k * np.tan(theta / 2.0)))


def _constraint(u, a, b):
    u = np.atleast_2d(u)
    return np.stack([_g(2 * np.pi * (u[:, 0] + u[:, 1]), WARP_K[0]) - a, _g(2 * np.pi * u[:, 1], WARP_K[1]) - b], axis=1)


# ---- exact cases ------------------------------------------------------------------------


def test_solutions_at_zero_offsets_are_the_half_grid():
    # a = b = 0: ψ ∈ {0, π} on both axes, θ = ψ, v ∈ {0, ½}, u = (v₀ − v₁, v₁) mod 1
    got = {tuple(np.round(s, 12) % 1.0) for s in solutions(0.0, 0.0)}
    assert got == {(0.0, 0.0), (0.5, 0.5), (0.5, 0.0), (0.0, 0.5)}


@pytest.mark.parametrize("view", [0, 3, 7])
def test_closed_form_solutions_solve_the_constraint_and_are_distinct(view):
    layout = view_layout(8)
    sols = solutions(layout["a"][view], layout["b"][view])
    np.testing.assert_allclose(_constraint(sols, layout["a"][view], layout["b"][view]), 0.0, atol=1e-12)
    d = np.abs(sols[:, None, :] - sols[None, :, :])
    d = np.minimum(d, 1 - d).max(axis=2) + np.eye(4)
    assert d.min() > 0.05


def test_conditional_probability_without_prior_is_m2_over_n2_and_w_is_k_over_pc():
    for tiles in (3, 4, 16, 32):
        v = seed_space_values(tiles, 0.0, np.array([], dtype=np.int32), centers=[0, tiles * tiles - 1], points=[[0.3, 0.7]])
        np.testing.assert_allclose(v["p_c"], 9.0 / tiles**2, rtol=1e-6)
        np.testing.assert_allclose(v["alpha_prime"], 0.0)
        np.testing.assert_allclose(v["pdf"], 1.0)
    # hand case: N = 4, I = {0, 5, 15}, α = 0.8, C around tile 0 holds tiles {15, 0, 5} ⊂ I (periodic)
    v = seed_space_values(4, 0.8, np.array([0, 5, 15]), centers=[0, 10], points=[[0.1, 0.1], [0.6, 0.1]])
    np.testing.assert_allclose(v["p_c"], [0.8 * 3 / 3 + 0.2 * 9 / 16, 0.8 * 2 / 3 + 0.2 * 9 / 16], rtol=1e-6)
    np.testing.assert_allclose(v["alpha_prime"], [0.8 / v["p_c"][0], 0.8 * 2 / 3 / v["p_c"][1]], rtol=1e-6)
    np.testing.assert_allclose(v["pdf"], [0.2 + 0.8 * 16 / 3, 0.2], rtol=1e-6)


def test_bernoulli_ucw_is_trials_over_conditional_probability():
    b = bernoulli_samples(view=0, solution=0, n=200, seed=1, tiles=8)
    np.testing.assert_allclose(b["ucw"], b["trials"] / (9.0 / 64.0), rtol=1e-6)
    assert np.all(b["trials"] >= 1)


def test_trust_regions_only_remove_seeds_from_basins_and_shorten_walks():
    free = basin_map(view=2, resolution=128, tiles=0)
    assert np.all(free["basin"] >= 0), "every seed of the toy converges without trust regions"
    part = basin_map(view=2, resolution=128, tiles=16)
    # a restricted walk is the free walk stopped early: it reaches the same solution or none
    kept = part["basin"] >= 0
    assert 0.02 < kept.mean() < 0.5
    assert np.array_equal(part["basin"][kept], free["basin"][kept])
    assert part["iterations"].mean() < free["iterations"].mean()


# ---- properties -------------------------------------------------------------------------


@settings(deadline=None, max_examples=25)
@given(
    tiles=st.integers(3, 12),
    alpha=st.floats(0.05, 0.95),
    data=st.data(),
)
def test_conditional_probability_equals_the_integral_of_the_mixture_pdf(tiles, alpha, data):
    """Eq. 8 = ∫_C p(u) du and Eq. 9's α' = α ∫_C p_I / P(C), by midpoint quadrature of the core's p(u) (Eq. 7)."""
    n2 = tiles * tiles
    prior = np.array(sorted(data.draw(st.sets(st.integers(0, n2 - 1), min_size=1, max_size=min(n2, 12)))), dtype=np.int32)
    centers = np.array(data.draw(st.lists(st.integers(0, n2 - 1), min_size=1, max_size=4)), dtype=np.int32)
    sub = 4  # midpoints per tile side: p is constant on tiles, so this quadrature is exact up to float32
    g = (np.arange(tiles * sub) + 0.5) / (tiles * sub)
    points = np.stack(np.meshgrid(g, g, indexing="xy"), axis=-1).reshape(-1, 2)
    v = seed_space_values(tiles, alpha, prior, centers, points)
    cell = 1.0 / (tiles * sub) ** 2
    np.testing.assert_allclose(v["pdf"].sum() * cell, 1.0, rtol=1e-5)  # p is a pdf on U
    tx = np.minimum((points[:, 0] * tiles).astype(int), tiles - 1)
    ty = np.minimum((points[:, 1] * tiles).astype(int), tiles - 1)
    in_prior = np.isin(ty * tiles + tx, prior)
    for c, p_c, a_prime in zip(centers, v["p_c"], v["alpha_prime"]):
        dx = np.abs(tx - c % tiles)
        dy = np.abs(ty - c // tiles)
        in_c = (np.minimum(dx, tiles - dx) <= 1) & (np.minimum(dy, tiles - dy) <= 1)
        integral = v["pdf"][in_c].sum() * cell
        np.testing.assert_allclose(p_c, integral, rtol=1e-5)
        prior_mass = (v["pdf"][in_c & in_prior] - (1 - alpha)).sum() * cell  # ∫_C α p_I
        np.testing.assert_allclose(a_prime, prior_mass / integral, rtol=1e-4, atol=1e-6)


# ---- statistics: Bernoulli trials against brute-force basin areas -------------------------------

GRID = 1024


@pytest.mark.parametrize("tiles", [0, 8])
def test_expected_trial_count_is_pc_over_basin_probability(tiles):
    """E[K] = P(C)/P'(u*) (Eq. 2, 5) with P' from a stratified 1024² seed grid; P(C) = 1 for plain SMS.

    Walks that start near a fold (g' ≈ 0) jump chaotically, so P' is measured on
    a jittered grid (a regular one aliases with that chaos by a few per cent)
    and its binomial standard error joins the test's.
    """
    view = 1
    grid = basin_map(view=view, resolution=GRID, tiles=tiles, jitter=SEED)["basin"]
    p_c = 1.0 if tiles == 0 else 9.0 / tiles**2
    n = 20_000
    for k in range(4):
        p_star = float(np.mean(grid == k))
        assert p_star > 0.005
        b = bernoulli_samples(view=view, solution=k, n=n, seed=SEED + k, tiles=tiles)
        trials = b["trials"].astype(np.float64)
        expected = p_c / p_star
        se_grid = expected * math.sqrt(p_star * (1 - p_star) / grid.size) / p_star  # delta method on P_c/P'
        se = math.hypot(trials.std(ddof=1) / math.sqrt(n), se_grid)
        result = z_test(trials.mean(), se, expected, k=DEFAULT_K)
        assert result.passed, f"solution {k}: E[K] = {trials.mean():.3f} vs P(C)/P' = {expected:.3f}: {result}"


def test_a_trial_cap_truncates_the_geometric_count():
    b = bernoulli_samples(view=1, solution=0, n=20_000, seed=SEED, max_trials=2)
    assert b["trials"].max() == 2
    p_star = float(np.mean(basin_map(view=1, resolution=GRID, jitter=SEED)["basin"] == 0))
    # E[min(K, 2)] = 1 + (1 − P): far below 1/P
    truncated = 1.0 + (1.0 - p_star)
    mean = b["trials"].mean()
    assert z_test(mean, b["trials"].std(ddof=1) / math.sqrt(20_000), truncated).passed
    assert mean < 0.1 / p_star


# ---- statistics: unbiasedness of the methods --------------------------------------------------

UNBIASED = [
    ("sms", {"max_trials": 0}, 200_000),
    ("sms-partitioned", {"max_trials": 0, "prior": False}, 200_000),
    ("sms-partitioned", {"max_trials": 0, "prior": True}, 100_000),
    ("sms-partitioned", {"max_trials": 0, "tiles": 4, "presamples": 8, "block": 2}, 100_000),
    ("sms-restir", {"max_trials": 0, "pixels": 4, "frames": 3}, 50_000),
    ("sms-restir", {"max_trials": 0, "pixels": 3, "frames": 2, "temporal": False, "prior": False}, 50_000),
]


def _label(case):
    method, params, _ = case
    return method + "-" + ",".join(f"{k}={v}" for k, v in params.items())


@pytest.mark.parametrize("case", UNBIASED, ids=_label)
def test_unbounded_methods_match_the_exact_sum_of_solutions(case):
    method, params, trials = case
    est = run_toy("sms-toy", method, trials=trials, seed=SEED, params=params)
    assert not PROBLEMS["sms-toy"].is_biased(method, est.params)
    result = z_test(est.estimate, est.stderr, est.exact, k=DEFAULT_K)
    assert result.passed, f"{method} {params}: {result}"


def test_two_bernoulli_trials_lose_energy_and_are_caught():
    est = run_toy("sms-toy", "sms", trials=20_000, seed=SEED, params={"max_trials": 2})
    assert PROBLEMS["sms-toy"].is_biased("sms", est.params)
    assert z_test(est.estimate, est.stderr, est.exact).max_abs_z > BIASED_K
    assert np.all(est.estimate < est.exact)  # energy loss, never gain
    assert est.stats["capped_per_solution"] > 0.1


# ---- the cost statistics of Table 1 ----------------------------------------------------------


def test_stats_carry_table1_columns_and_partitioning_lowers_newton_per_solution():
    sms = run_toy("sms-toy", "sms", trials=5000, seed=1, params={"max_trials": 0})
    part = run_toy("sms-toy", "sms-partitioned", trials=5000, seed=1, params={"max_trials": 0, "prior": True})
    for est in (sms, part):
        for key in ("success_rate", "newton_per_sample", "bernoulli_per_solution", "newton_per_solution"):
            assert key in est.stats and math.isfinite(est.stats[key])
        assert "stats" in est.to_dict()
    assert sms.stats["success_rate"] == 1.0  # every seed of the toy converges somewhere
    # Eq. 3 vs Eq. 6: 1 + K solutions walks vs fewer; Bernoulli trials per solution ≈ 4 = #solutions for SMS
    assert 3.5 < sms.stats["bernoulli_per_solution"] < 4.5
    assert part.stats["bernoulli_per_solution"] < 0.5 * sms.stats["bernoulli_per_solution"]
    assert part.stats["newton_per_solution"] < 0.5 * sms.stats["newton_per_solution"]


def test_restir_shifts_mostly_succeed_between_neighbouring_pixels():
    est = run_toy("sms-toy", "sms-restir", trials=2000, seed=1, params={"max_trials": 0, "pixels": 4, "frames": 2})
    assert est.stats["shift_success_rate"] > 0.9
    # 4 manifold walks per neighbour and pass: temporal (1 neighbour) + spatial (1–2 neighbours)
    assert 4.0 < est.stats["walks_shift_per_sample"] <= 12.0


def test_runs_are_deterministic_and_free_of_nan(device):
    a = run_toy("sms-toy", "sms-restir", trials=500, seed=3, params={"pixels": 3, "frames": 2}, device=device)
    b = run_toy("sms-toy", "sms-restir", trials=500, seed=3, params={"pixels": 3, "frames": 2}, device=device)
    assert np.array_equal(a.estimate, b.estimate) and a.stats == b.stats
    assert np.all(np.isfinite(a.estimate)) and np.all(np.asarray(a.stderr) > 0)


# ---- bad input ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "method, params, text",
    [
        ("sms-partitioned", {"tiles": 2}, "tiles"),
        ("sms-restir", {"frames": 0}, "frames"),
        ("sms", {"max_trials": -1}, "max_trials"),
        ("sms-restir", {"presamples": 0}, "presamples"),
    ],
)
def test_bad_parameters_raise_named_errors(method, params, text):
    with pytest.raises(InvalidParameterError, match=text):
        get_problem("sms-toy").run(method, trials=10, params=params)


def test_same_solution_measures_a_difference_in_c_not_in_u():
    # Walks stop anywhere |C| < NEWTON_THRESHOLD: their ends scatter along a near-null direction of ∂C/∂u
    # (a fold, where a caustic is bright) much further than a fixed distance in U would allow, and two
    # solutions of a stiff constraint can lie closer than that distance. The rule follows ∂C/∂u.
    import warp as wp

    from grisx.theory.manifold import NEWTON_THRESHOLD, SOLUTION_RADIUS, same_solution

    @wp.kernel
    def same(a: wp.array(dtype=wp.vec2), b: wp.array(dtype=wp.vec2), jac: wp.array(dtype=wp.mat22), out: wp.array(dtype=int)):
        i = wp.tid()
        out[i] = int(same_solution(a[i], b[i], jac[i]))

    fold = np.array([[100.0, 0.0], [0.0, 0.002]], dtype=np.float32)  # stiff along u₀, nearly singular along u₁
    stiff = np.array([[2000.0, 0.0], [0.0, 2000.0]], dtype=np.float32)
    a = np.array([[0.3, 0.4]] * 5 + [[0.999, 0.5]], dtype=np.float32)
    d = np.array(
        [
            [0.0, 3e-3],  # along the fold's null direction, |J d| = 6e-6: one solution (a fixed 1e-4 in U splits it)
            [5e-7, 0.0],  # along its stiff direction within Newton's own tolerance (|J d| = 5e-5): one solution
            [3e-5, 0.0],  # |J d| = 3e-3: two solutions
            [0.0, 2.0 * SOLUTION_RADIUS],  # beyond the radius: never one solution, however flat C is there
            [5e-5, 0.0],  # a stiff constraint: 5e-5 apart in U (inside a fixed 1e-4) but |J d| = 0.1: two solutions
            [2e-3, 0.0],  # across the torus' seam (0.999 → 0.001), flat along u₀ there: measured the short way
        ],
        dtype=np.float32,
    )
    jac = np.stack([fold, fold, fold, fold, stiff, fold[::-1, ::-1]])
    b = (a + d) % 1.0
    out = wp.zeros(len(a), dtype=int, device="cpu")
    wp.launch(same, dim=len(a), inputs=[wp.array(a, dtype=wp.vec2), wp.array(b, dtype=wp.vec2), wp.array(jac, dtype=wp.mat22)], outputs=[out], device="cpu")
    assert NEWTON_THRESHOLD < 1e-4
    assert out.numpy().tolist() == [1, 1, 0, 0, 0, 1]
