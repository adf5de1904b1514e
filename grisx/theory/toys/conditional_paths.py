"""Conditional RIS on two-vertex toy paths: ``joint-ucw``, ``suffix-reuse``, ``final-gather`` (seed 001).

A toy path is a 1D **prefix** z ∈ [0, 1] and a 1D **suffix** θ ∈ [0, 1]. The
suffix is a direction-like coordinate *relative to its prefix*: it reaches the
"reconnection point"

    s(z, θ) = A z + θ ℓ(z),   A = 0.6,   ℓ(z) = 0.5 + 0.5 z,

so the set of points a suffix can reach — its conditional support — moves and
stretches with the prefix: [0, 0.5] after z = 0, [0.6, 1.6] after z = 1. The
path contribution factors as in seed 001, Eq. 18,

    f(z, θ) = f_p(z) · f_ps(z, s) · f_s(s),
    f_p(z)     = 0.1 + (1 − (z − c)²)⁴              prefix throughput (bump at c),
    f_ps(z, s) = 1.2 − 0.4 (s − A z)               the reconnection term,
    f_s(s)     = 0.05 + 4 (s (1.6 − s) / 0.64)⁴     emission: a "light" peaked at s = 0.8,

and ∫₀¹∫₀¹ f dθ dz is a polynomial integral, evaluated exactly (to rounding)
by a 24 × 24-point Gauss–Legendre rule.

**Suffix target and shift.** The suffix target given prefix z is
p̂(θ|z) = f_ps f_s (seed 001, Eq. 20: f_p cancels). Reusing a suffix of prefix
z_j after prefix z is the reconnection shift: keep the point s, re-express it
from z,

    T(θ | z_j → z) = (s(z_j, θ) − A z) / ℓ(z),   |T'| = ℓ(z_j) / ℓ(z),

defined only when the result lies in [0, 1] — a partial bijection, so
suffixes borrowed from other prefixes do not cover the suffix domain of z,
and a canonical suffix is needed for coverage (Sec. 5, Eq. 17).

Problems (every estimator formula is in :mod:`grisx.theory.conditional`,
:mod:`~grisx.theory.reservoir`, :mod:`~grisx.theory.gris`, :mod:`~grisx.theory.mis`):

``joint-ucw``
    ``independent``: prefix X₁ by RIS (M uniform candidates, p̂ = f_p), suffix
    X₂ | X₁ by RIS (M uniform candidates, p̂(θ|X₁)) from *its own* random
    numbers; f(X₁, X₂) W_{X₁} W_{X₂|X₁} is unbiased (Thm. 4.1).
    ``dependent`` (biased): the suffix candidates reuse the prefix's random
    numbers — candidate θ_c is the very uniform that drew prefix candidate z_c,
    and the suffix reservoir's selection uniforms are the prefix reservoir's.
    Each θ_c is still marginally uniform, so W_{X₂|X₁} *looks* like a valid
    RIS weight; but W_{X₁} and W_{X₂|X₁} are now functions of the same pool
    u₁ … u_M. Given X₁ the pool is tilted towards f_p (it produced the winner),
    so the suffix candidates are not uniform given X₁ and W_{X₁}; W_{X₁} cannot
    leave the inner expectation of Eq. 8 and the product is not a joint UCW.
``suffix-reuse``
    ``cris``: K pixels, pixel k with prefix throughput centred at
    c_k = (k + ½)/K. Each frame (``passes`` frames; seed 001, Alg. 1 lines 4–10):
    a new prefix candidate by RIS, temporally GRIS-combined with the pixel's
    previous supporting prefix (target f_p only: prefixes never look at
    suffixes); a new canonical suffix after the current prefix by conditional
    RIS; temporal conditional RIS between the previous suffix (shifted from
    the previous prefix) and the canonical one; then spatial conditional RIS
    over all K pixels' suffixes, each shifted to continue this pixel's prefix.
    Pixel k's estimate is f(z_k, θ_k) W_{z_k} W_{θ_k|Z} (Thm. 4.1: the suffix
    chain's randomness is independent of the prefix chain's, and its UCWs are
    conditional on *all* prefixes). ``jacobian=false`` (biased) drops |T'|.
``final-gather``
    ``gather`` (Eq. 22–23): S supporting prefixes (RIS with p̂ = f_p) carry
    suffixes from conditional RIS plus ``passes`` spatial conditional-RIS
    passes among themselves. N integration prefixes are drawn uniformly; each
    borrows the suffixes of its ``k`` nearest supporting prefixes, MIS-weighted
    by the generalized balance heuristic with the supporting reservoirs'
    confidences as α (Eq. 15–16) against its own canonical domain. The
    canonical suffix is traced for one random prefix and multiplied by N
    (``roulette=true``), or for every prefix (``roulette=false``).
    ``canonical=false`` (biased) drops the canonical domain altogether: the k
    borrowed suffixes never cover the whole suffix domain (T is partial), so
    the uncovered part of ∫ f is lost.
    ``mmis``: the marginal-MIS baseline (West et al. 2022): the supporting
    prefixes carry one *independent* suffix each (no conditional RIS), and
    each integration prefix connects to ``suffixes`` of them, weighted by the
    balance heuristic of their known conditional pdfs.

Work counters (``Estimate.stats``, per trial): prefix and suffix traces and
shift evaluations (each a reconnection with a visibility ray in a renderer);
for ``final-gather`` split into the supporting reservoirs (``support_*``,
amortized over pixels and frames in a renderer) and the gather itself
(``prefixes``, ``canonical_suffixes``, ``borrowed_suffixes``, ``shifts``).
``rays`` (``support_rays`` + ``gather_rays``) is a ray-equivalent total: 1
per prefix, :data:`SUFFIX_RAYS` per suffix, 1 per shift.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import warp as wp

from grisx.errors import InvalidParameterError
from grisx.theory.conditional import (
    PAIRWISE_TARGET,
    PROXY_SOURCE_PDF,
    PROXY_TARGET,
    canonical_roulette_weight,
    joint_ucw,
    make_conditional_ris,
    roulette_pick,
)
from grisx.theory.gris import resampling_weight, ris_weight, ucw_from_source_pdf
from grisx.theory.mis import confidence_share
from grisx.theory.random import random_key, random_subkey, random_uniform
from grisx.theory.reservoir import Reservoir, confidence_capped, reservoir_empty, reservoir_finalize, reservoir_update
from grisx.theory.shift import ShiftResult, shift_failed, shift_result
from grisx.theory.toys.base import BiasedVariant, Method, Param, ToyProblem, TrialBatch
from grisx.theory.toys.domains import interval_pdf, sample_interval

wp.set_module_options({"enable_backward": False})

__all__ = [
    "JointUCW",
    "SuffixReuse",
    "FinalGather",
    "PathsSpec",
    "CRIS",
    "path_integral_exact",
    "SUFFIX_RAYS",
    "RECONNECT_A",
]

#: ray-equivalent cost of tracing one suffix (a multi-bounce subpath in a renderer)
SUFFIX_RAYS = 4
#: s(z, θ) = A z + θ ℓ(z), ℓ(z) = L0 + L1 z
RECONNECT_A = 0.6
SUFFIX_L0 = 0.5
SUFFIX_L1 = 0.5
#: prefix-throughput centre of the single-pixel problems (joint-ucw, final-gather)
GATHER_CENTER = 0.4
_A = wp.constant(RECONNECT_A)
_L0 = wp.constant(SUFFIX_L0)
_L1 = wp.constant(SUFFIX_L1)


@wp.struct
class PathsSpec:
    """What the hooks read: the prefix-throughput centre, and the Jacobian ablation switch."""

    center: float
    use_jacobian: int


# ---- the toy path -----------------------------------------------------------------


@wp.func
def suffix_length(z: float) -> float:
    """ℓ(z): how far a suffix after prefix z reaches."""
    return _L0 + _L1 * z


@wp.func
def reconnection_point(z: float, theta: float) -> float:
    """s(z, θ) = A z + θ ℓ(z)."""
    return _A * z + theta * suffix_length(z)


@wp.func
def prefix_throughput(center: float, z: float) -> float:
    """f_p(z) = 0.1 + (1 − (z − c)²)⁴ on [0, 1] (0 outside)."""
    if z < 0.0 or z > 1.0:
        return 0.0
    d = z - center
    b = 1.0 - d * d
    b2 = b * b
    return 0.1 + b2 * b2


@wp.func
def suffix_target(spec: PathsSpec, z: float, theta: float) -> float:
    """p̂(θ|z) = f_ps(z, s) f_s(s) (seed 001, Eq. 20), 0 outside θ ∈ [0, 1]."""
    if theta < 0.0 or theta > 1.0:
        return 0.0
    s = reconnection_point(z, theta)
    f_ps = 1.2 - 0.4 * (s - _A * z)
    b = s * (1.6 - s) / 0.64
    b2 = b * b
    return f_ps * (0.05 + 4.0 * b2 * b2)


@wp.func
def path_integrand(spec: PathsSpec, z: float, theta: float) -> float:
    """f(z, θ) = f_p(z) f_ps f_s (seed 001, Eq. 18)."""
    return prefix_throughput(spec.center, z) * suffix_target(spec, z, theta)


@wp.func
def suffix_sample(spec: PathsSpec, z: float, u: float) -> float:
    """A fresh suffix after z: uniform θ."""
    return sample_interval(u, 0.0, 1.0)


@wp.func
def suffix_pdf(spec: PathsSpec, z: float, theta: float) -> float:
    """p(θ|z) = 1 on [0, 1]."""
    if theta < 0.0 or theta > 1.0:
        return 0.0
    return interval_pdf(0.0, 1.0)


@wp.func
def suffix_shift(spec: PathsSpec, z_src: float, z_dst: float, theta: float) -> ShiftResult:
    """Reconnection T(θ | z_src → z_dst): keep s, re-express from z_dst; |T'| = ℓ(z_src)/ℓ(z_dst)."""
    if z_src == z_dst:
        return shift_result(theta, 1.0)  # exact identity: no rounding at the domain's edges
    t = (reconnection_point(z_src, theta) - _A * z_dst) / suffix_length(z_dst)
    if t < 0.0 or t > 1.0:
        return shift_failed()
    jacobian = suffix_length(z_src) / suffix_length(z_dst)
    if spec.use_jacobian == 0:
        jacobian = 1.0  # the ablation: biased, |T'| ≠ 1 here
    return shift_result(t, jacobian)


#: the conditional-RIS functions of this toy (seed 001, Sec. 5; built once from the hooks)
CRIS = make_conditional_ris(PathsSpec, suffix_target, suffix_sample, suffix_pdf, suffix_shift, path_integrand)


@wp.struct
class PrefixSample:
    """A prefix z with its reservoir (W_z in ``ucw``)."""

    reservoir: Reservoir
    z: float


@wp.func
def prefix_ris(center: float, candidates: int, key: wp.uint32, counter: int) -> PrefixSample:
    """Prefix z by RIS: M uniform candidates, p̂ = f_p (seed 001, Eq. 19), confidence M."""
    out = PrefixSample()
    r = reservoir_empty()
    z = float(0.0)
    inv_m = 1.0 / float(candidates)
    for c in range(candidates):
        x = sample_interval(random_uniform(key, counter + 2 * c), 0.0, 1.0)
        p_hat = prefix_throughput(center, x)
        r = reservoir_update(r, ris_weight(inv_m, p_hat, interval_pdf(0.0, 1.0)), p_hat, 1.0, random_uniform(key, counter + 2 * c + 1))
        if r.selected:
            z = x
    out.reservoir = reservoir_finalize(r)
    out.z = z
    return out


# ---- joint-ucw ----------------------------------------------------------------------


@wp.kernel
def joint_ucw_kernel(
    spec: PathsSpec,
    dependent: int,
    candidates: int,
    seed: int,
    first_trial: int,
    values: wp.array2d(dtype=float),
    samples: wp.array2d(dtype=float),
    keep_samples: int,
):
    t = wp.tid()
    key = random_key(seed, first_trial + t)
    # ---- X₁: the prefix by RIS (uniforms 0 … 2M−1 of the trial's key) ----
    prefix = prefix_ris(spec.center, candidates, key, 0)
    # ---- X₂ | X₁: the suffix by conditional RIS ----
    suffix_key = random_subkey(key, 1)  # its own numbers: independent of W_{X₁} given X₁
    if dependent != 0:
        suffix_key = key  # the bug: the prefix's candidate and selection uniforms again
    suffix = CRIS.canonical_suffix(spec, prefix.z, candidates, suffix_key, 0)
    w = joint_ucw(prefix.reservoir.ucw, suffix.reservoir.ucw)  # seed 001, Thm. 4.1
    values[t, 0] = path_integrand(spec, prefix.z, suffix.y) * w
    if keep_samples != 0:
        samples[t, 0] = suffix.y


# ---- suffix-reuse --------------------------------------------------------------------


@wp.kernel
def suffix_reuse_kernel(
    spec: PathsSpec,
    centers: wp.array(dtype=float),
    candidates: int,
    frames: int,
    spatial: int,
    cap: float,
    seed: int,
    first_trial: int,
    prefix_z: wp.array2d(dtype=float),
    prefix_res: wp.array2d(dtype=Reservoir),
    suffix_x: wp.array2d(dtype=float),
    suffix_res: wp.array2d(dtype=Reservoir),
    next_x: wp.array2d(dtype=float),
    next_res: wp.array2d(dtype=Reservoir),
    confidence: wp.array2d(dtype=float),
    targets: wp.array2d(dtype=float),
    pair_z: wp.array2d(dtype=float),
    pair_x: wp.array2d(dtype=float),
    pair_res: wp.array2d(dtype=Reservoir),
    pair_conf: wp.array2d(dtype=float),
    pair_targets: wp.array2d(dtype=float),
    values: wp.array2d(dtype=float),
    samples: wp.array2d(dtype=float),
    keep_samples: int,
    counters: wp.array2d(dtype=float),
):
    t = wp.tid()
    pixels = values.shape[1]
    key = random_key(seed, first_trial + t)
    traced_prefixes = float(0.0)
    traced_suffixes = float(0.0)
    shifts = float(0.0)
    for f in range(frames):
        prefix_key = random_subkey(key, 3 * f + 1)  # prefix and suffix randomness never mix
        suffix_key = random_subkey(key, 3 * f + 2)
        spatial_key = random_subkey(key, 3 * f + 3)
        for i in range(pixels):
            # ---- temporal prefix reuse with GRIS (Alg. 1 lines 4–5; target f_p only) ----
            fresh = prefix_ris(centers[i], candidates, prefix_key, 2 * candidates * i)
            traced_prefixes += float(candidates)
            z_old = prefix_z[t, i]
            z = fresh.z
            pr = fresh.reservoir
            if f > 0:
                old = prefix_res[t, i]
                c_old = confidence_capped(old.confidence, cap)
                c_all = c_old + fresh.reservoir.confidence
                # one pixel, identity shift, one target: the balance heuristic is c_l / Σ c
                p_old = prefix_throughput(centers[i], z_old)
                p_new = prefix_throughput(centers[i], fresh.z)
                u = random_uniform(prefix_key, 2 * candidates * pixels + i)
                pr = reservoir_empty()
                pr = reservoir_update(pr, resampling_weight(confidence_share(c_old, c_all), p_old, old.ucw, 1.0), p_old, c_old, 0.0)
                z = z_old
                pr = reservoir_update(
                    pr,
                    resampling_weight(confidence_share(fresh.reservoir.confidence, c_all), p_new, fresh.reservoir.ucw, 1.0),
                    p_new,
                    fresh.reservoir.confidence,
                    u,
                )
                if pr.selected:
                    z = fresh.z
                pr = reservoir_finalize(pr)
                pr.confidence = confidence_capped(pr.confidence, cap)
            prefix_z[t, i] = z
            prefix_res[t, i] = pr
            # ---- a new canonical suffix after the current prefix (Alg. 1 line 8) ----
            canon = CRIS.canonical_suffix(spec, z, candidates, suffix_key, 2 * candidates * i)
            traced_suffixes += float(candidates)
            if f == 0:
                suffix_x[t, i] = canon.y
                suffix_res[t, i] = canon.reservoir
            else:
                # ---- temporal conditional RIS: previous suffix (from z_old) vs canonical (Alg. 1 line 9) ----
                pair_z[t, 0] = z_old
                pair_x[t, 0] = suffix_x[t, i]
                pair_res[t, 0] = suffix_res[t, i]
                pair_conf[t, 0] = confidence_capped(suffix_res[t, i].confidence, cap)
                pair_z[t, 1] = z
                pair_x[t, 1] = canon.y
                pair_res[t, 1] = canon.reservoir
                pair_conf[t, 1] = canon.reservoir.confidence
                res = CRIS.conditional_ris(spec, z, 1, pair_z[t], pair_x[t], pair_res[t], pair_conf[t], pair_targets[t], suffix_key, 2 * candidates * pixels + 2 * i)
                shifts += float(res.shifts)
                r = res.reservoir
                r.confidence = confidence_capped(r.confidence, cap)
                suffix_x[t, i] = res.y
                suffix_res[t, i] = r
        # ---- spatial conditional RIS over all pixels (Alg. 1 line 10) ----
        if spatial != 0 and pixels > 1:
            shifts += float(
                CRIS.spatial_conditional_ris(spec, prefix_z[t], suffix_x[t], suffix_res[t], next_x[t], next_res[t], confidence[t], targets[t], cap, spatial_key)
            )
    # ---- shading: f(z, θ) W_z W_{θ|Z} (seed 001, Thm. 4.1) ----
    for i in range(pixels):
        z = prefix_z[t, i]
        values[t, i] = prefix_throughput(centers[i], z) * suffix_target(spec, z, suffix_x[t, i]) * joint_ucw(
            prefix_res[t, i].ucw, suffix_res[t, i].ucw
        )
        if keep_samples != 0:
            samples[t, i] = suffix_x[t, i]
    counters[t, 0] = traced_prefixes
    counters[t, 1] = traced_suffixes
    counters[t, 2] = shifts


# ---- final-gather ----------------------------------------------------------------------


@wp.func
def nearest_after(z: float, prefixes: wp.array(dtype=float), d_prev: float, j_prev: int) -> int:
    """The supporting prefix nearest to z after (d_prev, j_prev) in (distance, index) order: a k-NN step."""
    best = int(-1)
    best_d = float(0.0)
    for j in range(prefixes.shape[0]):
        d = wp.abs(prefixes[j] - z)
        after = d > d_prev or (d == d_prev and j > j_prev)
        if after and (best < 0 or d < best_d):
            best = j
            best_d = d
    return best


@wp.kernel
def final_gather_kernel(
    spec: PathsSpec,
    mmis: int,
    pairwise: int,
    prefixes: int,
    neighbors: int,
    roulette: int,
    canonical: int,
    candidates: int,
    passes: int,
    cap: float,
    seed: int,
    first_trial: int,
    support_z: wp.array2d(dtype=float),
    support_x: wp.array2d(dtype=float),
    support_res: wp.array2d(dtype=Reservoir),
    next_x: wp.array2d(dtype=float),
    next_res: wp.array2d(dtype=Reservoir),
    confidence: wp.array2d(dtype=float),
    targets: wp.array2d(dtype=float),
    row_z: wp.array2d(dtype=float),
    row_x: wp.array2d(dtype=float),
    row_res: wp.array2d(dtype=Reservoir),
    row_conf: wp.array2d(dtype=float),
    row_targets: wp.array2d(dtype=float),
    values: wp.array2d(dtype=float),
    counters: wp.array2d(dtype=float),
):
    t = wp.tid()
    support = support_z.shape[1]
    key = random_key(seed, first_trial + t)
    prefix_key = random_subkey(key, 1)
    suffix_key = random_subkey(key, 2)
    gather_key = random_subkey(key, 3)
    support_prefixes = float(0.0)
    support_suffixes = float(0.0)
    support_shifts = float(0.0)
    suffix_candidates = candidates
    mode = PROXY_TARGET
    if mmis != 0:
        suffix_candidates = 1  # independent suffixes with known pdfs: no conditional RIS
        mode = PROXY_SOURCE_PDF
    elif pairwise != 0:
        mode = PAIRWISE_TARGET  # each borrowed domain against the canonical one: O(k) shifts
    # ---- supporting prefixes and their suffixes (Alg. 1 lines 4–10) ----
    for j in range(support):
        p = prefix_ris(spec.center, candidates, prefix_key, 2 * candidates * j)
        support_z[t, j] = p.z
        s = CRIS.canonical_suffix(spec, p.z, suffix_candidates, suffix_key, 2 * candidates * j)
        support_x[t, j] = s.y
        support_res[t, j] = s.reservoir
        support_prefixes += float(candidates)
        support_suffixes += float(suffix_candidates)
    if mmis == 0:
        for q in range(passes):
            support_shifts += float(
                CRIS.spatial_conditional_ris(
                    spec, support_z[t], support_x[t], support_res[t], next_x[t], next_res[t], confidence[t], targets[t], cap, random_subkey(suffix_key, q + 1)
                )
            )
    # ---- final gather over N integration prefixes (Eq. 23; Alg. 1 lines 12–22) ----
    chosen = roulette_pick(random_uniform(gather_key, 0), prefixes)
    value = float(0.0)
    traced_prefixes = float(0.0)
    canonicals = float(0.0)
    borrowed = float(0.0)
    shifts = float(0.0)
    row = neighbors + 1
    for i in range(prefixes):
        z = sample_interval(random_uniform(gather_key, 1 + 2 * i), 0.0, 1.0)
        w_prefix = ucw_from_source_pdf(interval_pdf(0.0, 1.0))
        traced_prefixes += 1.0
        # entry 0: the prefix's own (canonical) suffix domain; α = 0 removes it (canonical=false)
        traced = canonical != 0 and (roulette == 0 or i == chosen)
        row_z[t, 0] = z
        row_conf[t, 0] = float(canonical)
        r0 = reservoir_empty()
        x0 = float(0.0)
        if traced:
            c = CRIS.canonical_suffix(spec, z, 1, gather_key, 2 + 2 * prefixes + 2 * i)
            r0 = c.reservoir
            x0 = c.y
            canonicals += 1.0
        row_x[t, 0] = x0
        row_res[t, 0] = r0
        # entries 1 … k: the suffixes of the k nearest supporting prefixes (FindSpatialKNN)
        d_prev = float(-1.0)
        j_prev = int(-1)
        for l in range(1, row):
            j = nearest_after(z, support_z[t], d_prev, j_prev)
            d_prev = wp.abs(support_z[t, j] - z)
            j_prev = j
            row_z[t, l] = support_z[t, j]
            row_x[t, l] = support_x[t, j]
            row_res[t, l] = support_res[t, j]
            row_conf[t, l] = 1.0
            if mmis == 0:
                row_conf[t, l] = support_res[t, j].confidence
        # ---- Eq. 22 for this prefix: borrowed suffixes, then the (rouletted) canonical one ----
        contribution = float(0.0)
        for l in range(1, row):
            term = CRIS.gather_term(spec, mode, z, w_prefix, l, 0, row_z[t], row_x[t], row_res[t], row_conf[t], row_targets[t])
            if mode == PAIRWISE_TARGET:
                shifts += 1.0  # its own shift; the pair's targets need no other
            else:
                shifts += float(row)
            if term > 0.0:
                borrowed += 1.0
            contribution += term
        if traced:
            term = CRIS.gather_term(spec, mode, z, w_prefix, 0, 0, row_z[t], row_x[t], row_res[t], row_conf[t], row_targets[t])
            shifts += float(row - 1)
            contribution += canonical_roulette_weight(roulette, i == chosen, prefixes) * term
        value += contribution / float(prefixes)
    values[t, 0] = value
    counters[t, 0] = support_prefixes
    counters[t, 1] = support_suffixes
    counters[t, 2] = support_shifts
    counters[t, 3] = traced_prefixes
    counters[t, 4] = canonicals
    counters[t, 5] = borrowed
    counters[t, 6] = shifts


# ---- exact values ----------------------------------------------------------------------------


def _prefix_throughput_np(center: float, z: np.ndarray) -> np.ndarray:
    return 0.1 + (1.0 - (z - center) ** 2) ** 4


def _suffix_target_np(z: np.ndarray, theta: np.ndarray) -> np.ndarray:
    s = RECONNECT_A * z + theta * (SUFFIX_L0 + SUFFIX_L1 * z)
    return (1.2 - 0.4 * (s - RECONNECT_A * z)) * (0.05 + 4.0 * (s * (1.6 - s) / 0.64) ** 4)


def path_integral_exact(center: float, nodes: int = 24) -> float:
    """∫₀¹∫₀¹ f_p(z) p̂(θ|z) dθ dz: f is a polynomial of degree 17 in z and 9 in θ, so
    Gauss–Legendre with ``nodes`` ≥ 9 points per axis is exact up to rounding."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    x = 0.5 * (x + 1.0)
    w = 0.5 * w
    z, th = np.meshgrid(x, x, indexing="ij")
    f = _prefix_throughput_np(center, z) * _suffix_target_np(z, th)
    return float(np.einsum("i,j,ij->", w, w, f))


def _spec(center: float, jacobian: bool = True) -> PathsSpec:
    s = PathsSpec()
    s.center = float(center)
    s.use_jacobian = int(bool(jacobian))
    return s


def _pixel_centers(pixels: int) -> np.ndarray:
    return (np.arange(pixels) + 0.5) / pixels


class _Scratch:
    """Per-trial scratch arrays keyed by shape and device, reused across chunks."""

    def __init__(self) -> None:
        self._key: Any = None
        self.arrays: list[wp.array] = []

    def get(self, shapes: list[tuple[tuple[int, int], Any]], device: Any) -> list[wp.array]:
        key = (tuple(s for s, _ in shapes), str(device))
        if key != self._key:
            self.arrays = [wp.zeros(shape, dtype=dtype, device=device) for shape, dtype in shapes]
            self._key = key
        return self.arrays


def _rays(totals: Mapping[str, float], trials: int) -> dict[str, float]:
    out = {name: value / trials for name, value in totals.items()}
    out["rays"] = out["prefixes"] + SUFFIX_RAYS * out["suffixes"] + out["shifts"]
    return out


CANDIDATES = Param("candidates", 4, "RIS candidates M for prefixes and suffixes", kind="int", minimum=1, maximum=256)


class JointUCW(ToyProblem):
    name = "joint-ucw"
    summary = "prefix by RIS, suffix | prefix by RIS; W_{X1} W_{X2|X1} is a joint UCW only under conditional independence"
    params = (CANDIDATES,)
    methods = (
        Method("independent", "X2 | X1 by RIS from its own random numbers: joint UCW by Thm. 4.1", ("candidates",)),
        Method("dependent", "X2's candidates reuse X1's candidate uniforms: biased (shared randomness beyond X1)", ("candidates",)),
    )
    biased_variants = (
        BiasedVariant(
            "dependent",
            {},
            "the suffix candidates are the prefix candidates' uniforms, so W_{X1} and W_{X2|X1} depend on the same pool beyond X1 (Thm. 4.1 fails)",
        ),
    )

    def exact(self, params: Mapping[str, Any]) -> np.ndarray:
        return np.array([path_integral_exact(GATHER_CENTER)])

    def kernels(self) -> list[Any]:
        return [joint_ucw_kernel]

    def launch(self, method: str, params: Mapping[str, Any], seed: int, first_trial: int, batch: TrialBatch, device: Any) -> None:
        samples = batch.samples if batch.samples is not None else batch.values
        wp.launch(
            joint_ucw_kernel,
            dim=batch.values.shape[0],
            inputs=[_spec(GATHER_CENTER), int(method == "dependent"), int(params["candidates"]), seed, first_trial, batch.values, samples, int(batch.samples is not None)],
            device=device,
        )


class SuffixReuse(ToyProblem):
    name = "suffix-reuse"
    summary = "K pixels: temporal prefix GRIS, temporal and spatial conditional RIS of suffixes (seed 001, Alg. 1 l. 4-10)"
    params = (
        Param("pixels", 4, "number of pixels K (prefix-throughput centres (k+1/2)/K)", kind="int", minimum=1, maximum=16),
        Param("candidates", 2, "RIS candidates M for new prefixes and new canonical suffixes", kind="int", minimum=1, maximum=256),
        Param("passes", 3, "frames, each with temporal and spatial conditional RIS", kind="int", minimum=1, maximum=64),
        Param("spatial", True, "spatial conditional RIS over all pixels each frame", kind="bool"),
        Param("cap", 20.0, "confidence cap of prefix and suffix reservoirs (0 = none)", kind="float", minimum=0.0),
        Param("jacobian", True, "multiply by the suffix shift's Jacobian |T'|", kind="bool"),
    )
    methods = (Method("cris", "Suffix ReSTIR: conditional RIS of suffixes over frames and pixels", tuple(p.name for p in params)),)
    biased_variants = (
        BiasedVariant(
            "cris",
            {"jacobian": False},
            "suffix shifts without |T'| = l(z_src)/l(z_dst) (seed 001, Eq. 14/16)",
            applies=lambda p: int(p["passes"]) > 1 or (bool(p["spatial"]) and int(p["pixels"]) > 1),
        ),
    )
    chunk_trials = 1 << 16

    def __init__(self) -> None:
        self._scratch = _Scratch()

    def components(self, params: Mapping[str, Any]) -> int:
        return int(params["pixels"])

    def exact(self, params: Mapping[str, Any]) -> np.ndarray:
        return np.array([path_integral_exact(c) for c in _pixel_centers(int(params["pixels"]))])

    def kernels(self) -> list[Any]:
        return [suffix_reuse_kernel]

    def counter_names(self, method: str, params: Mapping[str, Any]) -> tuple[str, ...]:
        return ("prefixes", "suffixes", "shifts")

    def stats(self, method: str, params: Mapping[str, Any], totals: Mapping[str, float], trials: int) -> dict[str, Any]:
        return _rays(totals, trials)

    def launch(self, method: str, params: Mapping[str, Any], seed: int, first_trial: int, batch: TrialBatch, device: Any) -> None:
        n, k = batch.values.shape
        f, r = float, Reservoir
        scratch = self._scratch.get([((n, k), f), ((n, k), r), ((n, k), f), ((n, k), r), ((n, k), f), ((n, k), r), ((n, k), f), ((n, k), f),
                                     ((n, 2), f), ((n, 2), f), ((n, 2), r), ((n, 2), f), ((n, 2), f)], device)
        samples = batch.samples if batch.samples is not None else batch.values
        wp.launch(
            suffix_reuse_kernel,
            dim=n,
            inputs=[
                _spec(0.0, params["jacobian"]),
                wp.array(_pixel_centers(k).astype(np.float32), dtype=float, device=device),
                int(params["candidates"]),
                int(params["passes"]),
                int(bool(params["spatial"])),
                float(params["cap"]),
                seed,
                first_trial,
                *scratch,
                batch.values,
                samples,
                int(batch.samples is not None),
                batch.counters,
            ],
            device=device,
        )


class FinalGather(ToyProblem):
    name = "final-gather"
    summary = "final gather (seed 001, Eq. 22-23): N prefixes borrow k ReSTIR suffixes + a rouletted canonical suffix; MMIS baseline"
    params = (
        Param("prefixes", 4, "integration prefixes N", kind="int", minimum=1, maximum=256),
        Param("k", 1, "suffixes borrowed per prefix from the nearest supporting prefixes", kind="int", minimum=1, maximum=32),
        Param("suffixes", 1, "mmis: independent suffixes borrowed per prefix", kind="int", minimum=1, maximum=32),
        Param("roulette", True, "trace the canonical suffix for one random prefix (x N) instead of all", kind="bool"),
        Param("canonical", True, "include the canonical suffix domain (false: biased, borrowed supports do not cover)", kind="bool"),
        Param("mis", "balance", "gather MIS: balance (Eq. 15 over all domains, O(k^2) shifts) or pairwise (each against the canonical, O(k))", kind="choice", choices=("balance", "pairwise")),
        Param("support", 8, "supporting prefixes S (reservoirs with suffixes)", kind="int", minimum=1, maximum=64),
        Param("candidates", 4, "RIS candidates M of supporting prefixes and (gather) suffixes; mmis suffixes are single samples", kind="int", minimum=1, maximum=256),
        Param("passes", 1, "spatial conditional-RIS passes among the supporting suffixes", kind="int", minimum=0, maximum=8),
        Param("cap", 20.0, "confidence cap of the supporting suffix reservoirs (0 = none)", kind="float", minimum=0.0),
    )
    methods = (
        Method("gather", "ReSTIR suffixes borrowed by N prefixes, generalized balance MIS (Eq. 23)", ("prefixes", "k", "roulette", "canonical", "mis", "support", "candidates", "passes", "cap")),
        Method("mmis", "independent suffixes, balance heuristic of their pdfs (marginal MIS)", ("prefixes", "suffixes", "roulette", "canonical", "support", "candidates")),
    )
    biased_variants = (
        BiasedVariant("gather", {"canonical": False}, "no canonical suffix: borrowed suffixes (a partial shift) do not cover the suffix domain (Eq. 17)"),
        BiasedVariant("mmis", {"canonical": False}, "no canonical suffix: borrowed suffixes (a partial shift) do not cover the suffix domain (Eq. 17)"),
    )
    chunk_trials = 1 << 16

    def __init__(self) -> None:
        self._scratch = _Scratch()

    def neighbors(self, method: str, params: Mapping[str, Any]) -> int:
        return int(params["suffixes"] if method == "mmis" else params["k"])

    def check_params(self, method: str, params: dict[str, Any]) -> None:
        name = "suffixes" if method == "mmis" else "k"
        if int(params[name]) > int(params["support"]):
            raise InvalidParameterError(f"param '{name}' of toy '{self.name}' must be <= support ({params['support']}), got {params[name]}")

    def exact(self, params: Mapping[str, Any]) -> np.ndarray:
        return np.array([path_integral_exact(GATHER_CENTER)])

    def kernels(self) -> list[Any]:
        return [final_gather_kernel]

    def counter_names(self, method: str, params: Mapping[str, Any]) -> tuple[str, ...]:
        return ("support_prefixes", "support_suffixes", "support_shifts", "prefixes", "canonical_suffixes", "borrowed_suffixes", "shifts")

    def stats(self, method: str, params: Mapping[str, Any], totals: Mapping[str, float], trials: int) -> dict[str, Any]:
        out = {name: value / trials for name, value in totals.items()}
        # ray equivalents: the supporting reservoirs (amortized over pixels and frames in a
        # renderer) apart from the gather itself (N prefixes, canonical suffixes, shifts)
        out["support_rays"] = out["support_prefixes"] + SUFFIX_RAYS * out["support_suffixes"] + out["support_shifts"]
        out["gather_rays"] = out["prefixes"] + SUFFIX_RAYS * out["canonical_suffixes"] + out["shifts"]
        out["rays"] = out["support_rays"] + out["gather_rays"]
        return out

    def launch(self, method: str, params: Mapping[str, Any], seed: int, first_trial: int, batch: TrialBatch, device: Any) -> None:
        n = batch.values.shape[0]
        s = int(params["support"])
        row = self.neighbors(method, params) + 1
        f, r = float, Reservoir
        scratch = self._scratch.get([((n, s), f), ((n, s), f), ((n, s), r), ((n, s), f), ((n, s), r), ((n, s), f), ((n, s), f),
                                     ((n, row), f), ((n, row), f), ((n, row), r), ((n, row), f), ((n, row), f)], device)
        wp.launch(
            final_gather_kernel,
            dim=n,
            inputs=[
                _spec(GATHER_CENTER),
                int(method == "mmis"),
                int(params.get("mis", "balance") == "pairwise"),
                int(params["prefixes"]),
                row - 1,
                int(bool(params["roulette"])),
                int(bool(params["canonical"])),
                int(params["candidates"]),
                int(params.get("passes", 0)),
                float(params.get("cap", 20.0)),
                seed,
                first_trial,
                *scratch,
                batch.values,
                batch.counters,
            ],
            device=device,
        )
