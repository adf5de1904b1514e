"""Spatio-temporal control variates with ReSTIR difference estimation (ReSTCV).

A *control variate* (CV) estimates an integral F_i through a correlated
function h_i whose integral H_i is known (or well estimated)::

    ⟨F_i⟩ = α_i H_i + ⟨F_i − α_i H_i⟩                               (seed 002, Eq. 2)

and only the *difference* is sampled — cheap in variance when f_i ≈ α_i h_i.
**Image-space control variates** (Rousselle et al. 2016) take the
neighbouring pixels' estimates as the control variates, and composite the
"from-j" estimators of the neighbourhood N̄_i (pixel i included)::

    ⟨F_i⟩ = Σ_j q_j ⟨F_i⟩_{←j} / Σ_j q_j,
    ⟨F_i⟩_{←j} = α_ij ⟨F_j⟩ + ⟨F_i − α_ij F_j⟩                        (Eq. 3, 7)

**STCV** (Sec. 5.1) does the same across time (the reprojected pixel of the
previous frame, with the fresh estimate weighted q_init; Eq. 6) and space
(random neighbours; Eq. 8). It is unbiased whenever each ⟨F_j⟩ and each
difference estimate is unbiased and the weights q, α do not depend on the
samples: the composite is then a fixed affine combination of unbiased
estimates (correlations between them change the variance only).

* **Coefficient** α_ij = min(ρ_i / ρ_j, 2) per colour channel (Eq. 9), ρ the
  albedo at the pixels' primary hits: the optimal coefficient when two pixels
  see the same incident light through different albedos, clamped against bad
  shifts (:func:`cv_alpha`, or α = 1).
* **Compositing weights** q_j = M_j, the reservoir's confidence, capped at 20,
  and q_init = 1 for the initial estimate (Sec. 5.3; :func:`compositing_weight`,
  :data:`Q_INIT`); :class:`CVComposite` accumulates Σ q ⟨F⟩_{←j} and Σ q.

**Difference estimators.** With a shift T_{i→j} and samples X_i, X_j::

    ⟨F_i − α F_j⟩ = ω_ij(X_i) W_i (f_i(X_i) − α f_j(T_{i→j} X_i)|J_{i→j}|)
                  − ω_ji(X_j) W_j (α f_j(X_j) − f_i(T_{j→i} X_j)|J_{j→i}|)  (Eq. 4, 10)

Direct MC (Eq. 4) uses fresh samples with W = 1/p and the balance heuristic
on the pdfs (Eq. 5); ReSTCV (Eq. 10) reuses the reservoir samples Y_i, Y_j
with their UCWs and the confidence-weighted targets::

    ω̂_ij(x) = M_i p̂_i(x) / (M_i p̂_i(x) + M_j p̂_j(T_{i→j} x) |∂T_{i→j}/∂x|)   (Eq. 11)

Both are unbiased because ω_ij(x) + ω_ji(T_{i→j} x) = 1 wherever either
target is positive (the Jacobian of the reverse shift cancels). The paper's
Eq. 10 keeps |J| inside f_j(T(·)); here it is an explicit factor (1 for
identity shifts). :func:`grisx.theory.mis.two_domain_balance` is Eq. 5/11 (written with the
generalized balance heuristic of :mod:`grisx.theory.mis`), :class:`DifferenceSample`
one side's record and :func:`difference_estimate` Eq. 4/10.

**Listing 1** stores the colour estimate F in the reservoir: every reuse pass
forms ⟨F_i⟩_{←j} = α_ij F_j + diff for each input reservoir j and composites
them with q_j = M_j, while the GRIS resampling of the pass proceeds unchanged;
final shading returns F instead of f(Y) W_Y. :func:`cv_estimate` is Eq. 7,
and the initial F is the plain MC estimate (:func:`mc_contribution`).

**Decoupled shading** (Wyman & Panteleev 2021) shades with every candidate
z_l seen in a reuse pass, Σ_l w_l f(z_l)/p̂(z_l) = Σ_l m_l f(z_l) W_l |J_l| —
the expectation of f(Y)W_Y given the candidates (:func:`decoupled_contribution`).
The paper's §6 notes it equals ReSTCV with a zero neighbour integrand.

ReSTIR's scalar target for a colour integrand is its luminance
(:func:`luminance`); the single sample kept then carries the colour
f(Y)/p̂(Y), which is the colour noise that the control variates remove (Sec. 4).

References: Z. Shi, C. Wu, L. Wu, K. Xu, "Spatio-Temporal Control Variates
with ReSTIR for Real-Time Rendering", SIGGRAPH 2026 (seed 002), Eq. 2–11 and
Listing 1; F. Rousselle, W. Jarosz, J. Novák, "Image-space control variates
for rendering", SIGGRAPH Asia 2016; C. Wyman, A. Panteleev, "Rearchitecting
spatiotemporal resampling for production", HPG 2021.
"""

from __future__ import annotations

import warp as wp

from grisx.theory.gris import luminance, ucw_from_source_pdf
from grisx.theory.mis import target_from, two_domain_balance
from grisx.theory.reservoir import Reservoir, confidence_capped

# grisx never differentiates through its kernels: skip adjoint code (halves compile time)
wp.set_module_options({"enable_backward": False})

__all__ = [
    "ALPHA_MODES",
    "ALPHA_HEURISTIC",
    "ALPHA_ONE",
    "ALPHA_CAP",
    "Q_INIT",
    "Q_CAP",
    "CVComposite",
    "CVOptions",
    "cv_options",
    "DifferenceSample",
    "luminance",
    "cv_alpha",
    "cv_alpha_or_sample",
    "ALPHA_SAMPLE",
    "cv_estimate",
    "cv_from_pixel",
    "cv_composite_empty",
    "cv_composite_add",
    "cv_composite_value",
    "compositing_weight",
    "difference_sample",
    "difference_estimate",
    "reservoir_difference",
    "DIFFERENCE_MIS",
    "mc_contribution",
    "decoupled_contribution",
]

#: Eq. 10's weights: Eq. 11 with the reservoirs' confidences M, with unit confidences (Eq. 5), or none (ω = 1: biased)
DIFFERENCE_MIS = {"confidence": 0, "balance": 1, "none": 2}
DMIS_CONFIDENCE = wp.constant(0)
DMIS_BALANCE = wp.constant(1)

ALPHA_HEURISTIC = wp.constant(0)
ALPHA_ONE = wp.constant(1)
#: user-facing names of the α choices, in the order of their constants
ALPHA_MODES = {"heuristic": 0, "one": 1}
#: a renderer's known-biased ablation: Eq. 9's ρ taken from the samples (:func:`cv_alpha_or_sample`)
ALPHA_SAMPLE = wp.constant(2)
#: the clamp of Eq. 9's reflectance ratio
ALPHA_CAP = wp.constant(2.0)
#: weight of the initial estimate in Eq. 6 (Sec. 5.3)
Q_INIT = wp.constant(1.0)
#: cap of the compositing weights q_j = M_j (Sec. 5.3, following GRIS)
Q_CAP = wp.constant(20.0)



@wp.struct
class CVComposite:
    """Running sums of Eq. 3/6/8: Σ_j q_j ⟨F_i⟩_{←j} and Σ_j q_j."""

    total: wp.vec3
    weight: float


@wp.struct
class CVOptions:
    """A renderer's runtime choices: ``alpha`` (:data:`ALPHA_MODES`), Eq. 10's weights ``difference_mis``
    (:data:`DIFFERENCE_MIS`), and whether the temporal (Eq. 6) and spatial (Eq. 8) composites run (1) or
    the pass keeps its input estimate (0)."""

    alpha: int
    difference_mis: int
    temporal: int
    spatial: int


def cv_options(alpha: int = 0, difference_mis: int = 0, temporal: bool = True, spatial: bool = True) -> CVOptions:
    """A :class:`CVOptions` record from the integer codes of :data:`ALPHA_MODES` and :data:`DIFFERENCE_MIS`."""
    o = CVOptions()
    o.alpha = int(alpha)
    o.difference_mis = int(difference_mis)
    o.temporal = int(bool(temporal))
    o.spatial = int(bool(spatial))
    return o


@wp.struct
class DifferenceSample:
    """One side of Eq. 4/10: a sample of pixel ``a`` used to estimate F_a − α F_b.

    ``mis`` is ω_ab at the sample, ``ucw`` its W (1/p for a fresh sample),
    ``f_own`` = f_a at the sample, ``f_shifted`` = f_b at T_{a→b}(sample) and
    ``jacobian`` = |∂T_{a→b}/∂x| (0 where the shift fails).
    """

    mis: float
    ucw: float
    f_own: wp.vec3
    f_shifted: wp.vec3
    jacobian: float


@wp.func
def _ratio_clamped(rho_i: float, rho_j: float) -> float:
    if rho_j > 0.0:
        return wp.min(rho_i / rho_j, ALPHA_CAP)
    if rho_i > 0.0:
        return ALPHA_CAP  # the limit ρ_j → 0⁺ of Eq. 9
    return 1.0  # both black: F_i = F_j = 0 in this channel, any α is exact


@wp.func
def cv_alpha(mode: int, rho_i: wp.vec3, rho_j: wp.vec3) -> wp.vec3:
    """α_ij = min(ρ_i / ρ_j, 2) per channel (seed 002, Eq. 9), or 1 with ``ALPHA_ONE``.

    ρ are the albedos at the primary hits of pixels i and j; α must not depend
    on the light samples, or the CV estimate loses its unbiasedness.
    """
    if mode == ALPHA_ONE:
        return wp.vec3(1.0, 1.0, 1.0)
    return wp.vec3(_ratio_clamped(rho_i[0], rho_j[0]), _ratio_clamped(rho_i[1], rho_j[1]), _ratio_clamped(rho_i[2], rho_j[2]))


@wp.func
def cv_estimate(estimate_j: wp.vec3, alpha: wp.vec3, difference: wp.vec3) -> wp.vec3:
    """⟨F_i⟩_{←j} = α_ij ⊙ ⟨F_j⟩ + ⟨F_i − α_ij F_j⟩ (seed 002, Eq. 2, 3, 7)."""
    return wp.cw_mul(alpha, estimate_j) + difference


@wp.func
def cv_alpha_or_sample(mode: int, rho_i: wp.vec3, rho_j: wp.vec3, sample_i: wp.vec3, estimate_j: wp.vec3) -> wp.vec3:
    """:func:`cv_alpha` for ``mode`` in :data:`ALPHA_MODES`; with :data:`ALPHA_SAMPLE` the known-biased
    ablation that takes ρ_i from pixel i's current one-sample estimate and ρ_j = ⟨F_j⟩, so α
    correlates with the difference it multiplies (what the renderers' tests must catch)."""
    if mode == ALPHA_SAMPLE:
        return cv_alpha(ALPHA_HEURISTIC, sample_i, estimate_j)
    return cv_alpha(mode, rho_i, rho_j)


@wp.func
def cv_composite_empty() -> CVComposite:
    """An empty composite: no estimator added yet."""
    c = CVComposite()
    c.total = wp.vec3(0.0, 0.0, 0.0)
    c.weight = 0.0
    return c


@wp.func
def cv_composite_add(c: CVComposite, estimate: wp.vec3, q: float) -> CVComposite:
    """Add q · ⟨F_i⟩_{←j} to the composite of Eq. 3/6/8 (non-positive q adds nothing)."""
    out = c
    if q > 0.0:
        out.total = c.total + q * estimate
        out.weight = c.weight + q
    return out


@wp.func
def cv_composite_value(c: CVComposite) -> wp.vec3:
    """⟨F_i⟩ = Σ q ⟨F_i⟩_{←j} / Σ q (seed 002, Eq. 3, 6, 8; Listing 1 line 29); 0 when empty."""
    if c.weight > 0.0:
        return c.total / c.weight
    return wp.vec3(0.0, 0.0, 0.0)


@wp.func
def compositing_weight(confidence: float) -> float:
    """q_j = M_j capped at 20 (seed 002, Sec. 5.3 "Compositing weights"); q_init is :data:`Q_INIT`."""
    return confidence_capped(confidence, Q_CAP)


@wp.func
def difference_sample(mis: float, ucw: float, f_own: wp.vec3, f_shifted: wp.vec3, jacobian: float) -> DifferenceSample:
    """The record of one side of Eq. 4/10 (see :class:`DifferenceSample`)."""
    s = DifferenceSample()
    s.mis = mis
    s.ucw = ucw
    s.f_own = f_own
    s.f_shifted = f_shifted
    s.jacobian = wp.abs(jacobian)
    return s


@wp.func
def difference_estimate(s_i: DifferenceSample, s_j: DifferenceSample, alpha: wp.vec3) -> wp.vec3:
    """⟨F_i − α F_j⟩ from a sample of pixel i and one of pixel j (seed 002, Eq. 4 and 10).

    ``s_i`` holds f_i at X_i and f_j at T_{i→j}(X_i); ``s_j`` holds f_j at
    X_j and f_i at T_{j→i}(X_j). Each side is weighted ω W; zero weights give
    zero, never NaN.
    """
    d_i = s_i.f_own - wp.cw_mul(alpha, s_i.f_shifted) * s_i.jacobian
    d_j = wp.cw_mul(alpha, s_j.f_own) - s_j.f_shifted * s_j.jacobian
    out = wp.vec3(0.0, 0.0, 0.0)
    k_i = s_i.mis * s_i.ucw
    k_j = s_j.mis * s_j.ucw
    if k_i > 0.0:
        out = out + k_i * d_i
    if k_j > 0.0:
        out = out - k_j * d_j
    return out


@wp.func
def mc_contribution(f: wp.vec3, source_pdf: float, samples: int) -> wp.vec3:
    """f(x) / (N p(x)): one of N terms of the MC estimate, ReSTCV's initial F (Listing 1 line 36)."""
    return f * (ucw_from_source_pdf(source_pdf) / float(samples))


@wp.func
def decoupled_contribution(w: float, target: float, f: wp.vec3) -> wp.vec3:
    """w · f(z) / p̂(z) = m f(z) W |J|: one candidate's share of decoupled shading (Wyman & Panteleev 2021)."""
    if w > 0.0 and target > 0.0:
        return f * (w / target)
    return wp.vec3(0.0, 0.0, 0.0)


@wp.func
def reservoir_difference(
    r_i: Reservoir,
    r_j: Reservoir,
    f_i_yi: wp.vec3,
    f_j_yi: wp.vec3,
    f_j_yj: wp.vec3,
    f_i_yj: wp.vec3,
    jacobian_ij: float,
    jacobian_ji: float,
    alpha: wp.vec3,
    mis_mode: int,
) -> wp.vec3:
    """⟨F_i − α F_j⟩ from the two reservoirs' kept samples y_i, y_j (seed 002, Eq. 10 with Eq. 11's weights).

    ``f_a_yb`` is f_a at pixel b's sample carried into a's domain (f_j_yi = f_j(T_{i→j} y_i), with
    ``jacobian_ij`` = |∂T_{i→j}/∂y_i|, 0 where the shift fails); the targets are the luminances of
    these four values, which Eq. 10 needs anyway. ``mis_mode``: :data:`DIFFERENCE_MIS`.
    """
    m_i = r_i.confidence
    m_j = r_j.confidence
    if mis_mode == DMIS_BALANCE:
        m_i = 1.0
        m_j = 1.0
    w_ij = float(1.0)
    w_ji = float(1.0)
    if mis_mode == DMIS_CONFIDENCE or mis_mode == DMIS_BALANCE:
        w_ij = two_domain_balance(m_i, luminance(f_i_yi), m_j, target_from(luminance(f_j_yi), jacobian_ij))  # Eq. 11
        w_ji = two_domain_balance(m_j, luminance(f_j_yj), m_i, target_from(luminance(f_i_yj), jacobian_ji))
    s_i = difference_sample(w_ij, r_i.ucw, f_i_yi, f_j_yi, jacobian_ij)
    s_j = difference_sample(w_ji, r_j.ucw, f_j_yj, f_i_yj, jacobian_ji)
    return difference_estimate(s_i, s_j, alpha)


@wp.func
def cv_from_pixel(
    r_i: Reservoir,
    r_j: Reservoir,
    estimate_j: wp.vec3,
    f_i_yi: wp.vec3,
    f_j_yi: wp.vec3,
    f_j_yj: wp.vec3,
    f_i_yj: wp.vec3,
    jacobian_ij: float,
    jacobian_ji: float,
    alpha: wp.vec3,
    mis_mode: int,
) -> wp.vec3:
    """⟨F_i⟩_{←j} = α ⟨F_j⟩ + ⟨F_i − α F_j⟩ (seed 002, Eq. 7), the difference from the two reservoirs'
    samples and their shifts (Eq. 10–11, :func:`reservoir_difference`; ``r_j`` with the confidence
    the pass gives it)."""
    diff = reservoir_difference(r_i, r_j, f_i_yi, f_j_yi, f_j_yj, f_i_yj, jacobian_ij, jacobian_ji, alpha, mis_mode)
    return cv_estimate(estimate_j, alpha, diff)
