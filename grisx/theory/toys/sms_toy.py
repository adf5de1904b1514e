"""``sms-toy``: specular manifold sampling on a 2D toy "specular chain" with known solutions.

Every *view* v (pixel q of frame t: v = t·pixels + q) has the constraint on
the periodic primary sample space U = [0, 1)²

    C(u; v) = ( g(2π(u₀ + u₁); k₀) − a_v,  g(2π u₁; k₁) − b_v ),
    g(θ; k) = sin ψ_k(θ),  ψ_k(θ) = 2 atan(k tan(θ/2))
            = k sin θ / (cos²(θ/2) + k² sin²(θ/2)),

a sheared (u₀ + u₁: the torus automorphism [[1, 1], [0, 1]]), warped
(ψ_k, a circle diffeomorphism that stretches θ ≈ 0 by k) pair of sines.
sin ψ = a has two roots ψ ∈ {asin a, π − asin a} per axis, so C has four
solutions in closed form, θ = 2 atan2(sin(ψ/2), k cos(ψ/2)), which move
continuously with (a_v, b_v). Newton's method uses the analytic Jacobian
∂C/∂u = 2π [[g'₀, g'₀], [0, g'₁]]. Its basins are uneven — the roots near
ψ = 0 sit where ψ_k stretches θ, so only a thin band of seeds reaches them
(k = (2.5, 2): basin areas ≈ 0.036, 0.13, 0.18, 0.65 in pixel 0) — and
fractal near the folds where g' = 0, where walks jump across the torus:
exactly the regime where SMS needs many Bernoulli trials (seed 003, Fig. 2).
Every seed converges to *some* solution, so plain SMS succeeds always; trust
regions lower that rate, and priors raise it again (Table 1).

A found solution carries the toy "throughput" (Eq. 13, one point light)

    f(u*; v) = L_v (1 + 0.5 cos 2π u*₀ + 0.3 sin 2π u*₁),

and the exact per-pixel value is Σ_k f(u*_k; v) (Eq. 12 with the light
integral trivial). Components are the pixels of the last frame; returned
samples are u*₀ of each pixel's kept solution.

Methods (all built on :mod:`grisx.theory.manifold`):

``sms``              uniform seed, unrestricted walk, W = K Bernoulli trials (Eq. 1–2);
``sms-partitioned``  N × N tiles with 3 × 3 trust regions, W = K / P(C) (Eq. 4–6, 8),
                     optional prior from presampled walks per pixel block (Eq. 7, 9);
``sms-restir``       ``sms-partitioned`` samples, then per frame temporal and spatial
                     GRIS with the manifold shift and pairwise MIS (Sec. 5.2–5.3).

``max_trials`` caps the Bernoulli trials (0 = unbounded); any cap loses the
energy f (1 − P)^cap of each solution, so only unbounded runs are exactly
unbiased — ``max_trials=2`` is the declared biased variant. The default 128
(seed 003's setting) loses Σ f (1 − P)^128 / Σ f ≈ 0.3 % with ``sms`` (the
thin basins) and nothing measurable with tiles (``benchmarks/manifold.py``).

Priors (default: one block of 8 pixels, 64 presampled walks per frame) keep
every solution reachable through the (1 − α) p_U share, but a solution that
the presamples miss gets P' = (1 − α) P'_U: rare, large weights (seed 003's
Fig. 10 failure case), visible as a skewed z at small trial counts.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import warp as wp

from grisx.theory.manifold import (
    NEWTON_MAX_ITERATIONS,
    ManifoldReuse,
    ReuseNeighbor,
    reuse_neighbor,
    PRIOR_ALPHA,
    conditional_alpha,
    conditional_probability,
    make_manifold_sampler,
    prior_add_tile,
    same_solution,
    seed_pdf,
    seed_space,
    tile_of,
    wrap_unit,
)
from grisx.theory.random import random_key, random_subkey, random_uniform
from grisx.theory.reservoir import (
    Reservoir,
    confidence_capped,
    reservoir_empty,
    reservoir_finalize,
    reservoir_update,
)
from grisx.theory.gris import resampling_weight
from grisx.theory.toys.base import BiasedVariant, Method, Param, ToyProblem, TrialBatch

# grisx never differentiates through its kernels: skip adjoint code (halves compile time)
wp.set_module_options({"enable_backward": False})

__all__ = ["SMSToy", "SMSToySpec", "SMS", "view_layout", "solutions", "COUNTERS"]

#: warp strengths k₀ (sheared axis) and k₁
WARP_K = (2.5, 2.0)
_K0 = wp.constant(WARP_K[0])
_K1 = wp.constant(WARP_K[1])
_TWO_PI = wp.constant(2.0 * math.pi)

#: per-trial tallies written by the kernel (summed over pixels and frames)
COUNTERS = (
    "samples",
    "successes",
    "newton_sample",
    "bernoulli",
    "newton_bernoulli",
    "capped",
    "prior_walks",
    "prior_successes",
    "newton_prior",
    "prior_tiles",
    "shift_walks",
    "newton_shift",
    "shifts_valid",
)


@wp.struct
class SMSToySpec:
    """Per view v: constraint offsets a_v, b_v and light L_v; ``pixels`` per frame."""

    a: wp.array(dtype=float)
    b: wp.array(dtype=float)
    light: wp.array(dtype=float)
    pixels: int


# ---- the specular chain ----------------------------------------------------------------


@wp.func
def _g(theta: float, k: float) -> float:
    """sin ψ_k(θ) = k sin θ / D, D = cos²(θ/2) + k² sin²(θ/2) > 0."""
    c = wp.cos(theta)
    d = 0.5 * (1.0 + c) + k * k * 0.5 * (1.0 - c)
    return k * wp.sin(theta) / d


@wp.func
def _g_prime(theta: float, k: float) -> float:
    """d sin ψ_k/dθ = cos ψ · ψ' = k (cos²(θ/2) − k² sin²(θ/2)) / D²."""
    c = wp.cos(theta)
    d = 0.5 * (1.0 + c) + k * k * 0.5 * (1.0 - c)
    return k * (0.5 * (1.0 + c) - k * k * 0.5 * (1.0 - c)) / (d * d)


@wp.func
def sms_toy_constraint(spec: SMSToySpec, view: int, u: wp.vec2) -> wp.vec2:
    """C(u; v) = (g(2π(u₀+u₁); k₀) − a_v, g(2π u₁; k₁) − b_v)."""
    return wp.vec2(_g(_TWO_PI * (u[0] + u[1]), _K0) - spec.a[view], _g(_TWO_PI * u[1], _K1) - spec.b[view])


@wp.func
def sms_toy_jacobian(spec: SMSToySpec, view: int, u: wp.vec2) -> wp.mat22:
    """∂C/∂u = 2π [[g'₀, g'₀], [0, g'₁]] (analytic)."""
    d0 = _TWO_PI * _g_prime(_TWO_PI * (u[0] + u[1]), _K0)
    d1 = _TWO_PI * _g_prime(_TWO_PI * u[1], _K1)
    return wp.mat22(d0, d0, 0.0, d1)


@wp.func
def sms_toy_throughput(spec: SMSToySpec, view: int, u: wp.vec2) -> float:
    """f(u*; v) = L_v (1 + 0.5 cos 2π u₀ + 0.3 sin 2π u₁) (toy Eq. 13); p̂ = f."""
    return spec.light[view] * (1.0 + 0.5 * wp.cos(_TWO_PI * u[0]) + 0.3 * wp.sin(_TWO_PI * u[1]))


#: the SMS functions of the core, built over this constraint
SMS = make_manifold_sampler(SMSToySpec, sms_toy_constraint, sms_toy_jacobian, sms_toy_throughput)


# ---- views and their closed-form solutions ---------------------------------------------


def view_layout(pixels: int, frames: int = 1) -> dict[str, np.ndarray]:
    """a_v, b_v, L_v for v = t·pixels + q (q < pixels, t < frames): solutions drift with q and t."""
    q = np.tile(np.arange(pixels), frames)
    t = np.repeat(np.arange(frames), pixels)
    return {
        "a": -0.25 + 0.015 * q + 0.02 * t,
        "b": 0.2 - 0.012 * q + 0.015 * t,
        "light": 1.0 + 0.1 * (q % 3),
    }


def _theta_roots(value: float, k: float) -> np.ndarray:
    psi = np.array([math.asin(value), math.pi - math.asin(value)])
    return 2.0 * np.arctan2(np.sin(psi / 2.0), k * np.cos(psi / 2.0))


def solutions(a: float, b: float) -> np.ndarray:
    """The four solutions u*_k of C(u) = 0 (float64, closed form), shape (4, 2)."""
    v0 = _theta_roots(a, WARP_K[0]) / (2.0 * math.pi)
    v1 = _theta_roots(b, WARP_K[1]) / (2.0 * math.pi)
    out = [((x - y) % 1.0, y % 1.0) for x in v0 for y in v1]
    return np.array(out)


def throughput(u: np.ndarray, light: float) -> np.ndarray:
    """float64 twin of :func:`sms_toy_throughput` for the exact values."""
    u = np.atleast_2d(u)
    return light * (1.0 + 0.5 * np.cos(2 * np.pi * u[:, 0]) + 0.3 * np.sin(2 * np.pi * u[:, 1]))


# ---- one kernel for all methods ---------------------------------------------------------


@wp.func
def _counter_add(counters: wp.array2d(dtype=float), t: int, c: int, value: float):
    counters[t, c] = counters[t, c] + value


@wp.func
def _toy_neighbor(res_row: wp.array(dtype=Reservoir), y_row: wp.array(dtype=wp.vec2), nb: int, view_base: int, view_c: int) -> ReuseNeighbor:
    """Pixel ``nb`` of a row as a reuse neighbour (−1: none); a toy view is a pixel, so y_i lands in view_c."""
    if nb < 0:
        return reuse_neighbor(reservoir_empty(), wp.vec2(0.0, 0.0), 0, 0, 0, 0)
    return reuse_neighbor(res_row[nb], y_row[nb], view_base + nb, view_c, view_base + nb, 1)


@wp.func
def _pairwise_reuse(
    spec: SMSToySpec,
    r_c: Reservoir,
    y_c: wp.vec2,
    view_c: int,
    res_row: wp.array(dtype=Reservoir),
    y_row: wp.array(dtype=wp.vec2),
    nb0: int,
    nb1: int,
    view_base: int,
    cap: float,
    key: wp.uint32,
) -> ManifoldReuse:
    """GRIS of the canonical reservoir with ≤ 2 neighbours (pixels ``nb0``, ``nb1`` of ``res_row``; −1 = none)."""
    n0 = _toy_neighbor(res_row, y_row, nb0, view_base, view_c)
    n1 = _toy_neighbor(res_row, y_row, nb1, view_base, view_c)
    return SMS.reuse(spec, r_c, y_c, view_c, n0, n1, cap, key)


@wp.func
def _count_reuse(counters: wp.array2d(dtype=float), t: int, out: ManifoldReuse):
    _counter_add(counters, t, 10, float(out.walks))
    _counter_add(counters, t, 11, float(out.newton))
    _counter_add(counters, t, 12, float(out.valid))


@wp.kernel
def sms_toy_kernel(
    spec: SMSToySpec,
    frames: int,
    tiles: int,
    use_prior: int,
    alpha: float,
    presamples: int,
    block: int,
    max_trials: int,
    temporal: int,
    spatial: int,
    cap: float,
    seed: int,
    first_trial: int,
    prior_tiles: wp.array2d(dtype=int),
    prior_count: wp.array2d(dtype=int),
    res_a: wp.array2d(dtype=Reservoir),
    y_a: wp.array2d(dtype=wp.vec2),
    res_b: wp.array2d(dtype=Reservoir),
    y_b: wp.array2d(dtype=wp.vec2),
    values: wp.array2d(dtype=float),
    counters: wp.array2d(dtype=float),
    samples: wp.array2d(dtype=float),
    keep_samples: int,
):
    t = wp.tid()
    pixels = spec.pixels
    blocks = (pixels + block - 1) // block
    key = random_key(seed, first_trial + t)
    for c in range(counters.shape[1]):
        counters[t, c] = 0.0
    for fr in range(frames):
        fkey = random_subkey(key, fr)
        view0 = fr * pixels

        # ---- prior construction: presampled unrestricted walks per pixel block (Sec. 4.1) ----
        for blk in range(blocks):
            count = int(0)
            if use_prior != 0:
                bkey = random_subkey(fkey, 1000 + blk)
                first = blk * block
                size = wp.min(block, pixels - first)
                for j in range(presamples):
                    q = first + wp.min(int(random_uniform(bkey, 3 * j) * float(size)), size - 1)
                    u = wp.vec2(random_uniform(bkey, 3 * j + 1), random_uniform(bkey, 3 * j + 2))
                    w = SMS.walk(spec, view0 + q, u, 0, NEWTON_MAX_ITERATIONS)
                    _counter_add(counters, t, 6, 1.0)
                    _counter_add(counters, t, 8, float(w.iterations))
                    if w.converged:
                        _counter_add(counters, t, 7, 1.0)
                        count = prior_add_tile(prior_tiles[t * blocks + blk], count, tile_of(w.u, tiles))
                _counter_add(counters, t, 9, float(count))
            prior_count[t, blk] = count

        # ---- initial samples: one SMS sample per pixel, a reservoir of one candidate ----
        for q in range(pixels):
            blk = q // block
            space = seed_space(tiles, alpha, prior_count[t, blk])
            s = SMS.sample(spec, view0 + q, space, prior_tiles[t * blocks + blk], random_subkey(fkey, q), max_trials)
            _counter_add(counters, t, 0, 1.0)
            _counter_add(counters, t, 2, float(s.newton_sample))
            r = reservoir_empty()
            if s.found:
                _counter_add(counters, t, 1, 1.0)
                _counter_add(counters, t, 3, float(s.trials))
                _counter_add(counters, t, 4, float(s.newton_bernoulli))
                if s.capped:
                    _counter_add(counters, t, 5, 1.0)
            p_hat = sms_toy_throughput(spec, view0 + q, s.u)
            w0 = float(0.0)
            if s.found:
                w0 = resampling_weight(1.0, p_hat, s.ucw, 1.0)  # seed 003, Eq. 10 with m = 1, T = id
            r = reservoir_finalize(reservoir_update(r, w0, p_hat, 1.0, 0.0))
            # ---- temporal reuse: the previous frame's reservoir of this pixel ----
            if temporal != 0 and fr > 0:
                out = _pairwise_reuse(spec, r, s.u, view0 + q, res_b[t], y_b[t], q, -1, view0 - pixels, cap, random_subkey(fkey, 2000 + q))
                _count_reuse(counters, t, out)
                res_a[t, q] = out.r
                y_a[t, q] = out.y
            else:
                res_a[t, q] = r
                y_a[t, q] = s.u

        # ---- spatial reuse: left and right neighbours after the temporal pass ----
        for q in range(pixels):
            if spatial != 0 and pixels > 1:
                left = q - 1
                right = q + 1
                if right >= pixels:
                    right = -1
                out = _pairwise_reuse(spec, res_a[t, q], y_a[t, q], view0 + q, res_a[t], y_a[t], left, right, view0, cap, random_subkey(fkey, 3000 + q))
                _count_reuse(counters, t, out)
                res_b[t, q] = out.r
                y_b[t, q] = out.y
            else:
                r = res_a[t, q]
                r.confidence = confidence_capped(r.confidence, cap)
                res_b[t, q] = r
                y_b[t, q] = y_a[t, q]

    # ---- shading: f(y) W in every pixel of the last frame ----
    last = (frames - 1) * pixels
    for q in range(pixels):
        values[t, q] = sms_toy_throughput(spec, last + q, y_b[t, q]) * res_b[t, q].ucw
        if keep_samples != 0:
            samples[t, q] = y_b[t, q][0]  # u₀ of the kept solution (for histograms)


# ---- host helpers for tests and the tutorial ----------------------------------------------


@wp.kernel
def _basin_kernel(
    spec: SMSToySpec, view: int, tiles: int, res: int, jitter: int, sols: wp.array(dtype=wp.vec2), out: wp.array2d(dtype=int), iters: wp.array2d(dtype=int)
):
    i, j = wp.tid()
    dx = float(0.5)
    dy = float(0.5)
    if jitter >= 0:  # stratified: one uniform seed per cell
        cell = random_key(jitter, i * res + j)
        dx = random_uniform(cell, 0)
        dy = random_uniform(cell, 1)
    u = wrap_unit(wp.vec2((float(j) + dx) / float(res), (float(i) + dy) / float(res)))
    w = SMS.walk(spec, view, u, tiles, NEWTON_MAX_ITERATIONS)
    iters[i, j] = w.iterations
    out[i, j] = -1
    if w.converged:
        for k in range(sols.shape[0]):
            if same_solution(w.u, sols[k], w.jacobian):
                out[i, j] = k


@wp.kernel
def _bernoulli_kernel(
    spec: SMSToySpec,
    view: int,
    u_star: wp.vec2,
    tiles: int,
    alpha: float,
    prior: wp.array(dtype=int),
    prior_count: int,
    max_trials: int,
    seed: int,
    trials: wp.array(dtype=int),
    ucw: wp.array(dtype=float),
):
    t = wp.tid()
    space = seed_space(tiles, alpha, prior_count)
    b = SMS.bernoulli(spec, view, u_star, sms_toy_jacobian(spec, view, u_star), space, prior, random_key(seed, t), max_trials)
    trials[t] = b.trials
    ucw[t] = b.ucw


@wp.kernel
def _seed_space_kernel(
    tiles: int,
    alpha: float,
    prior: wp.array(dtype=int),
    prior_count: int,
    centers: wp.array(dtype=int),
    points: wp.array(dtype=wp.vec2),
    p_c: wp.array(dtype=float),
    alpha_prime: wp.array(dtype=float),
    pdf: wp.array(dtype=float),
):
    i = wp.tid()
    space = seed_space(tiles, alpha, prior_count)
    if i < centers.shape[0]:
        p_c[i] = conditional_probability(space, prior, centers[i])
        alpha_prime[i] = conditional_alpha(space, prior, centers[i], p_c[i])
    if i < points.shape[0]:
        pdf[i] = seed_pdf(space, prior, points[i])


def make_spec(pixels: int, frames: int, device: Any) -> SMSToySpec:
    """The problem's spec struct for ``pixels`` × ``frames`` views on ``device``."""
    layout = view_layout(pixels, frames)
    s = SMSToySpec()
    s.a = wp.array(layout["a"].astype(np.float32), dtype=float, device=device)
    s.b = wp.array(layout["b"].astype(np.float32), dtype=float, device=device)
    s.light = wp.array(layout["light"].astype(np.float32), dtype=float, device=device)
    s.pixels = int(pixels)
    return s


def view_solutions(view: int, pixels: int = 8, frames: int = 1) -> np.ndarray:
    """Closed-form solutions (4, 2) of view ``view`` of the layout with ``pixels`` × ``frames`` views."""
    layout = view_layout(pixels, frames)
    return solutions(float(layout["a"][view]), float(layout["b"][view]))


def basin_map(
    view: int = 0, resolution: int = 256, tiles: int = 0, pixels: int = 8, jitter: int | None = None, device: str = "cpu"
) -> dict[str, np.ndarray]:
    """Which solution the walk from each seed of a ``resolution``² grid reaches.

    ``basin[i, j]`` is the index k of :func:`view_solutions` reached from seed
    u = ((j + ½)/res, (i + ½)/res), or −1 (no convergence, or the walk left its
    trust region when ``tiles`` > 0); ``iterations`` the Newton steps it took.
    With ``jitter`` (a seed) every cell's seed is uniform in the cell instead
    (stratified sampling): near the folds where g' = 0 the walks are chaotic,
    and a regular grid aliases with them.
    """
    sols = view_solutions(view, pixels)
    spec = make_spec(pixels, 1, device)
    out = wp.empty((resolution, resolution), dtype=int, device=device)
    iters = wp.empty((resolution, resolution), dtype=int, device=device)
    wp.launch(_basin_kernel, dim=(resolution, resolution), inputs=[spec, int(view), int(tiles), int(resolution), -1 if jitter is None else int(jitter), wp.array(sols.astype(np.float32), dtype=wp.vec2, device=device), out, iters], device=device)
    return {"basin": out.numpy(), "iterations": iters.numpy(), "solutions": sols}


def bernoulli_samples(
    view: int,
    solution: int,
    n: int,
    seed: int = 0,
    tiles: int = 0,
    alpha: float = 0.0,
    prior: np.ndarray | None = None,
    max_trials: int = 0,
    pixels: int = 8,
    device: str = "cpu",
) -> dict[str, np.ndarray]:
    """``n`` independent Bernoulli-trial runs of the core for solution ``solution`` of ``view``: K and W."""
    sols = view_solutions(view, pixels)
    prior_tiles = np.asarray(prior if prior is not None and len(prior) else [0], dtype=np.int32)
    count = 0 if prior is None else len(prior)
    trials = wp.empty(n, dtype=int, device=device)
    ucw = wp.empty(n, dtype=float, device=device)
    wp.launch(
        _bernoulli_kernel,
        dim=n,
        inputs=[make_spec(pixels, 1, device), int(view), wp.vec2(*sols[solution].astype(np.float32)), int(tiles), float(alpha), wp.array(prior_tiles, dtype=int, device=device), int(count), int(max_trials), int(seed), trials, ucw],
        device=device,
    )
    return {"trials": trials.numpy(), "ucw": ucw.numpy()}


def seed_space_values(tiles: int, alpha: float, prior: np.ndarray, centers: np.ndarray, points: np.ndarray, device: str = "cpu") -> dict[str, np.ndarray]:
    """The core's P(C) (Eq. 8) and α' (Eq. 9) at tile ``centers`` and p(u) (Eq. 7) at ``points``."""
    prior = np.asarray(prior, dtype=np.int32)
    centers = np.asarray(centers, dtype=np.int32).ravel()
    points = np.asarray(points, dtype=np.float32).reshape(-1, 2)
    n = max(len(centers), len(points))
    p_c = wp.zeros(max(len(centers), 1), dtype=float, device=device)
    alpha_prime = wp.zeros(max(len(centers), 1), dtype=float, device=device)
    pdf = wp.zeros(max(len(points), 1), dtype=float, device=device)
    wp.launch(
        _seed_space_kernel,
        dim=n,
        inputs=[int(tiles), float(alpha), wp.array(prior if len(prior) else np.zeros(1, np.int32), dtype=int, device=device), len(prior), wp.array(centers, dtype=int, device=device), wp.array(points, dtype=wp.vec2, device=device), p_c, alpha_prime, pdf],
        device=device,
    )
    return {"p_c": p_c.numpy()[: len(centers)], "alpha_prime": alpha_prime.numpy()[: len(centers)], "pdf": pdf.numpy()[: len(points)]}


# ---- the problem -----------------------------------------------------------------------

_PARTITION = ("tiles", "prior", "presamples", "block")


class SMSToy(ToyProblem):
    name = "sms-toy"
    summary = "specular manifold sampling on a 2D toy chain with 4 known solutions per pixel: Bernoulli UCWs, trust regions, priors, manifold-shift ReSTIR"
    params = (
        Param("pixels", 8, "pixels of the row (the components)", kind="int", minimum=1, maximum=16),
        Param("max_trials", 128, "cap on Bernoulli trials per solution (0 = unbounded; any cap loses energy)", kind="int", minimum=0, maximum=1 << 20),
        Param("tiles", 16, "N: the sample space is cut into N × N tiles, trust regions are 3 × 3 tiles", kind="int", minimum=3, maximum=64),
        Param("prior", True, "seed pdf α p_I + (1 − α) p_U from presampled tiles I (Eq. 7), α = 0.8", kind="bool"),
        Param("presamples", 64, "unrestricted walks per pixel block and frame that build the prior", kind="int", minimum=1, maximum=256),
        Param("block", 8, "pixels per prior block (at most all pixels)", kind="int", minimum=1, maximum=16),
        Param("frames", 4, "frames simulated (components are the last frame's pixels)", kind="int", minimum=1, maximum=16),
        Param("temporal", True, "temporal reuse of the previous frame's reservoir", kind="bool"),
        Param("spatial", True, "spatial reuse of the left and right neighbours", kind="bool"),
        Param("cap", 20.0, "confidence cap M after each reuse pass (0 = none)", kind="float", minimum=0.0),
    )
    methods = (
        Method("sms", "SMS: uniform seed, unrestricted Newton walk, W = K Bernoulli trials (seed 003, Eq. 1–2)", ("pixels", "max_trials")),
        Method(
            "sms-partitioned",
            "tiles with 3 × 3 trust regions, W = K / P(C) (Eq. 4–6, 8); prior from presampled walks (Eq. 7, 9)",
            ("pixels", "max_trials") + _PARTITION,
        ),
        Method(
            "sms-restir",
            "sms-partitioned samples, temporal + spatial GRIS with manifold shifts and pairwise MIS (Sec. 5.2–5.3)",
            ("pixels", "max_trials") + _PARTITION + ("frames", "temporal", "spatial", "cap"),
        ),
    )
    biased_variants = (
        BiasedVariant(
            "sms",
            {"max_trials": 2},
            "Bernoulli trials capped at 2: E[min(K, 2)] = (1 − (1 − P)²)/P < 1/P loses energy on every hard solution",
        ),
    )
    chunk_trials = 1 << 16

    def __init__(self) -> None:
        self._scratch_key: tuple[Any, ...] | None = None
        self._scratch: list[wp.array] = []

    def components(self, params: Mapping[str, Any]) -> int:
        return int(params["pixels"])

    @staticmethod
    def _block(params: Mapping[str, Any]) -> int:
        return min(int(params.get("block", 1)), int(params["pixels"]))

    @staticmethod
    def _frames(params: Mapping[str, Any]) -> int:
        return int(params.get("frames", 1))

    def exact(self, params: Mapping[str, Any]) -> np.ndarray:
        pixels, frames = int(params["pixels"]), self._frames(params)
        layout = view_layout(pixels, frames)
        last = (frames - 1) * pixels
        return np.array([float(np.sum(throughput(solutions(layout["a"][v], layout["b"][v]), layout["light"][v]))) for v in range(last, last + pixels)])

    def kernels(self) -> list[Any]:
        return [sms_toy_kernel]

    def counter_names(self, method: str, params: Mapping[str, Any]) -> tuple[str, ...]:
        return COUNTERS

    def stats(self, method: str, params: Mapping[str, Any], totals: Mapping[str, float], trials: int) -> dict[str, Any]:
        def ratio(a: float, b: float) -> float:
            return float(a / b) if b > 0 else 0.0

        s = totals["samples"]
        found = totals["successes"]
        newton_all = totals["newton_sample"] + totals["newton_bernoulli"] + totals["newton_prior"] + totals["newton_shift"]
        out = {
            # the columns of seed 003's Table 1 (manifold sampling stage)
            "success_rate": ratio(found, s),
            "newton_per_sample": ratio(totals["newton_sample"], s),
            "bernoulli_per_solution": ratio(totals["bernoulli"], found),
            "newton_per_solution": ratio(totals["newton_bernoulli"], found),
            # more of the cost
            "capped_per_solution": ratio(totals["capped"], found),
            "newton_total_per_sample": ratio(newton_all, s),
            "newton_total_per_solution": ratio(newton_all, found),
            "samples_per_trial": s / trials,
        }
        if method != "sms" and params.get("prior"):
            out.update(
                prior_success_rate=ratio(totals["prior_successes"], totals["prior_walks"]),
                prior_newton_per_walk=ratio(totals["newton_prior"], totals["prior_walks"]),
                prior_tiles_per_block=ratio(totals["prior_tiles"], s) * float(self._block(params)),
            )
        if method == "sms-restir":
            out.update(
                shift_success_rate=ratio(totals["shifts_valid"], totals["shift_walks"] / 2.0),
                newton_shift_per_sample=ratio(totals["newton_shift"], s),
                walks_shift_per_sample=ratio(totals["shift_walks"], s),
            )
        return out

    def _buffers(self, n: int, params: Mapping[str, Any], device: Any) -> list[wp.array]:
        pixels, block = int(params["pixels"]), self._block(params)
        blocks = -(-pixels // block)
        presamples = int(params.get("presamples", 1))
        key = (n, pixels, blocks, presamples, str(device))
        if key != self._scratch_key:
            self._scratch = [
                wp.zeros((n * blocks, presamples), dtype=int, device=device),
                wp.zeros((n, blocks), dtype=int, device=device),
                wp.empty((n, pixels), dtype=Reservoir, device=device),
                wp.empty((n, pixels), dtype=wp.vec2, device=device),
                wp.empty((n, pixels), dtype=Reservoir, device=device),
                wp.empty((n, pixels), dtype=wp.vec2, device=device),
            ]
            self._scratch_key = key
        return self._scratch

    def launch(self, method: str, params: Mapping[str, Any], seed: int, first_trial: int, batch: TrialBatch, device: Any) -> None:
        n, pixels = batch.values.shape
        partitioned = method != "sms"
        restir = method == "sms-restir"
        frames = self._frames(params)
        wp.launch(
            sms_toy_kernel,
            dim=n,
            inputs=[
                make_spec(pixels, frames, device),
                frames,
                int(params["tiles"]) if partitioned else 0,
                int(partitioned and bool(params["prior"])),
                PRIOR_ALPHA,
                int(params.get("presamples", 1)),
                self._block(params),
                int(params["max_trials"]),
                int(restir and bool(params["temporal"])),
                int(restir and bool(params["spatial"])),
                float(params["cap"]) if restir else 0.0,
                seed,
                first_trial,
                *self._buffers(n, params, device),
                batch.values,
                batch.counters,
                batch.samples if batch.samples is not None else batch.values,
                int(batch.samples is not None),
            ],
            device=device,
        )
