"""Gradient-domain estimators: shift-mapped pixel differences, paired-pixel resampling, positivization.

Gradient-domain rendering (Lehtinen et al. 2013; Kettunen et al. 2015)
estimates, besides pixel values, the *difference* of two pixels i and j,

    Δ_ij = ∫_{Ω_i} f_i(x) dx − ∫_{Ω_j} f_j(x) dx                  (seed 000, Eq. 1)

with correlated samples: a *base path* x of pixel i is carried to pixel j by an
*inner shift* T_ij (a partial bijection Ω_i' → Ω_j') and the two contributions
are subtracted. Because T_ij is only partial, both pixels sample base paths
and their one-sided differences are combined by MIS,

    Δ_ij = ∫_{Ω_i} ω_ij (f_i(x) − f_j(T_ij x)|∂T_ij/∂x|) dx
         − ∫_{Ω_j} ω_ji (f_j(x) − f_i(T_ji x)|∂T_ji/∂x|) dx         (Eq. 3)

    ω_ij(x) = p_i(x) / (p_i(x) + p_j(T_ij x)|∂T_ij/∂x|)              (Eq. 4)

— the balance heuristic of the two pixels' techniques, with the offset term
dropped where T_ij is undefined (ω_ij = 1 there). After ReSTIR the pdfs are
unknown and the targets take their place (Eq. 13, the generalized balance
heuristic of :mod:`grisx.theory.mis`); :func:`gradient_mis` is both.

**The paired-pixel domain** (seed 000, Sec. 4.2). Eq. 3 is one integral over
``pair_domain`` X = Ω_i×{0} ∪ Ω_j×{1} (Eq. 14): a sample is (x, k) with k the
pixel the base path lives in, its contribution

    G_ij(x, 0) = f_i(x) − f_j(T_ij x)|∂T_ij/∂x|
    G_ij(x, 1) = f_i(T_ji x)|∂T_ji/∂x| − f_j(x)                      (Eq. 15)

and ω*_ij(x, k) = ω_ij(x) or ω_ji(x) (Eq. 16), so Δ_ij = ∫_X ω* G. Note
G_ji(x, 1−k) = −G_ij(x, k): swapping the pixels flips the sign, and for a
shiftable x the weights ω_ij(x) and ω_ji(T_ij x) sum to one — each path's
contribution is split, never lost or doubled.

*Gradient after ReSTIR* (Sec. 4.1) resamples each pixel in the primal domain
and evaluates ω̂ G at the kept path (Eq. 10–13): the sum of the two pixels'
:func:`pair_estimate`\\ s with k = 0 and k = 1. *Gradient with ReSTIR*
(Sec. 4.2) resamples *in* X with the target

    p̂(x, k) = ω*(x, k) |G_ij(x, k)|                                   (Eq. 19)

and estimates ⟨Δ_ij⟩ = ω* G(y) · W_y (Eq. 17–18), the resampling weights
being the GRIS weights of :func:`grisx.theory.gris.resampling_weight` (Eq. 20).
Candidates from another pair (i', j') arrive through the *outer shift*
T*(x, k) = (τ(x), k) (Eq. 21): τ moves the base path to the corresponding pixel
of the target pair, k is kept, and |∂T*/∂(x, k)| = |∂τ/∂x| (Eq. 22).

**Positivization** (Sec. 4.4). ω* G changes sign, so one target |ω* G| mixes
signs in one reservoir ("sign noise"). Splitting

    p̂₊ = max(ω* G, 0),   p̂₋ = max(−ω* G, 0),   Δ_ij = ∫ p̂₊ − ∫ p̂₋     (Eq. 23–26)

gives two reservoirs ``pos`` and ``neg`` fed the *same* candidates; each one's
estimate ω* G(y) W_y has a fixed sign and Δ is their sum. Reuse *across signs*
(Chang et al. 2023) merges a neighbour's ``neg`` into one's ``pos`` too: after
an outer shift a sample may change sign. :func:`signed_target` is Eq. 19
(``sign`` = 0) and Eq. 25–26 (``sign`` = ±1) in one place.

Every function takes plain values (integrands, pdfs or targets, Jacobians,
validity), so the toys here and a path-space renderer call the same code.
Assumptions: pdfs/targets are ≥ 0, Jacobians are |det|, and a failed shift is
reported by ``valid = False`` (its other inputs are then ignored).

References: seed 000 (Wang et al., Gradient-domain ReSTIR Path Tracing),
Eq. 1–4, 10–26; M. Kettunen et al., "Gradient-domain path tracing", ACM TOG
34(4), 2015; W. Chang et al., "Parameter-space ReSTIR", SIGGRAPH 2023.
"""

from __future__ import annotations

import warp as wp

from grisx.theory.gris import resampling_weight
from grisx.theory.mis import target_from, two_domain_balance
from grisx.theory.reservoir import Reservoir, reservoir_update
from grisx.theory.shift import ShiftResult

__all__ = [
    "PAIR_BASE_I",
    "PAIR_BASE_J",
    "SIGN_ABS",
    "SIGN_POS",
    "SIGN_NEG",
    "PairShift",
    "gradient_mis",
    "shifted_difference",
    "pair_contribution",
    "pair_value",
    "signed_target",
    "pair_estimate",
    "outer_shift",
    "pair_outer_weight",
    "pair_update",
]

#: k of a paired-pixel sample whose base path lives in pixel i / pixel j (Eq. 14)
PAIR_BASE_I = wp.constant(0)
PAIR_BASE_J = wp.constant(1)
#: which target a reservoir resamples: |ω*G| (Eq. 19), its positive or negative part (Eq. 25–26)
SIGN_ABS = wp.constant(0)
SIGN_POS = wp.constant(1)
SIGN_NEG = wp.constant(-1)


@wp.struct
class PairShift:
    """A paired-pixel sample (x, k) after the outer shift T* (Eq. 21), with |∂T*/∂(x, k)| (Eq. 22)."""

    x: float
    k: int
    jacobian: float
    valid: wp.bool


@wp.func
def gradient_mis(density_base: float, density_offset: float, jacobian: float, valid: wp.bool) -> float:
    """ω_ij(x) = p_i(x) / (p_i(x) + p_j(T_ij x)|∂T_ij/∂x|) (seed 000, Eq. 4; Eq. 13 with targets).

    ``density_base`` is the base pixel's pdf (Eq. 4) or target (Eq. 13) at x,
    ``density_offset`` the other pixel's at T_ij(x). Where the shift failed the
    offset pixel cannot produce x: its term is dropped (ω = 1 if p_i(x) > 0).
    """
    offset = float(0.0)
    if valid:
        offset = target_from(density_offset, jacobian)
    return two_domain_balance(1.0, density_base, 1.0, offset)


@wp.func
def shifted_difference(f_base: float, f_offset: float, jacobian: float, valid: wp.bool) -> float:
    """f_i(x) − f_j(T_ij x)|∂T_ij/∂x| (seed 000, Eq. 2): base minus shifted offset (0 offset if T failed)."""
    if valid:
        return f_base - f_offset * wp.abs(jacobian)
    return f_base


@wp.func
def pair_contribution(k: int, f_base: float, f_offset: float, jacobian: float, valid: wp.bool) -> float:
    """G_ij(x, k) (seed 000, Eq. 15): f_i − f_j∘T_ij·|J| for k = 0, f_i∘T_ji·|J| − f_j for k = 1.

    ``f_base`` is the integrand of the pixel x lives in (i for k = 0, j for
    k = 1), ``f_offset`` the other pixel's at the inner shift of x.
    """
    d = shifted_difference(f_base, f_offset, jacobian, valid)
    if k == PAIR_BASE_J:
        return -d
    return d


@wp.func
def pair_value(k: int, f_base: float, f_offset: float, pdf_base: float, pdf_offset: float, jacobian: float, valid: wp.bool) -> float:
    """ω*_ij(x, k) · G_ij(x, k) (seed 000, Eq. 14–16): the integrand of Δ_ij over the paired-pixel domain."""
    return gradient_mis(pdf_base, pdf_offset, jacobian, valid) * pair_contribution(k, f_base, f_offset, jacobian, valid)


@wp.func
def signed_target(sign: int, value: float) -> float:
    """Target of a reservoir over X at a sample with ω*G = ``value``.

    ``SIGN_ABS``: p̂ = |ω*G| (seed 000, Eq. 19); ``SIGN_POS``: max(ω*G, 0)
    (Eq. 25); ``SIGN_NEG``: max(−ω*G, 0) (Eq. 26).
    """
    if sign == SIGN_POS:
        return wp.max(value, 0.0)
    if sign == SIGN_NEG:
        return wp.max(-value, 0.0)
    return wp.abs(value)


@wp.func
def pair_estimate(value: float, ucw: float) -> float:
    """⟨Δ_ij⟩ = ω*G(y) · W_y (seed 000, Eq. 17); also Eq. 11 for Gradient after ReSTIR.

    With positivization the ``pos`` and ``neg`` reservoirs' estimates have
    fixed signs and Δ is their sum (Eq. 24).
    """
    return value * ucw


@wp.func
def outer_shift(tau: ShiftResult, k: int) -> PairShift:
    """T*(x, k) = (τ(x), k) (seed 000, Eq. 21) with |∂T*/∂(x, k)| = |∂τ/∂x| (Eq. 22).

    ``tau`` is the base path's shift to the corresponding pixel of the
    target pair (pixel i' → i for k = 0, j' → j for k = 1); the indicator is
    carried by the identity γ(k) = k.
    """
    s = PairShift()
    s.x = tau.x
    s.k = k
    s.jacobian = wp.abs(tau.jacobian)
    s.valid = tau.valid
    return s


@wp.func
def pair_outer_weight(mis: float, target_shifted: float, ucw: float, shift: PairShift) -> float:
    """w = m · p̂(T*(x, k)) · W_(x,k) · |∂T*/∂(x, k)| (seed 000, Eq. 20); 0 if T* failed."""
    if not shift.valid:
        return 0.0
    return resampling_weight(mis, target_shifted, ucw, shift.jacobian)


@wp.func
def pair_update(r: Reservoir, sign: int, value: float, mis: float, ucw: float, jacobian: float, confidence: float, u: float) -> Reservoir:
    """Stream a paired-pixel candidate with ω*G = ``value`` into the reservoir of target ``sign``.

    The weight is Eq. 20 with the target of :func:`signed_target`; positivized
    runs call it twice with the same candidate, once for ``pos`` and once for
    ``neg`` (shared candidates, seed 000, Sec. 4.4).
    """
    target = signed_target(sign, value)
    return reservoir_update(r, resampling_weight(mis, target, ucw, jacobian), target, confidence, u)
