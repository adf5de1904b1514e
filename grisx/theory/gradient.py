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

**MIS of a positivized merge** (seed 001, Eq. 15–16 over the inputs of seed
000, Sec. 4.4). A merge into the reservoir of sign s reads, from every source
l (the pair's own reservoir l = 0, its previous frame, neighbour pairs), the
reservoir of sign s and — reusing across signs — the one of sign −s. Input
(l, e) has the target p̂^{s_e} (s_0 = s, s_1 = −s) and the generalized balance
heuristic over all inputs is

    m_{l,e}(y) = c_{l,e} p̂^{s_e}_{←l}(y) / Σ_{l',e'} c_{l',e'} p̂^{s_e'}_{←l'}(y),
    p̂^{s}_{←l}(y) = p̂^{s}_l(T*⁻¹ y) · |∂T*⁻¹/∂y|                       (seed 001, Eq. 15–16)

Both signs of one source read the same shifted value ω*G(T*⁻¹ y); since
p̂₊ p̂₋ = 0, at most one of a source's two terms is non-zero. The pair's own
reservoir of sign −s is no input: at the identity shift its samples have
p̂^{s} = 0 and its term vanishes wherever p̂^{s}(y) > 0.
:func:`pair_source_inputs`, :func:`pair_input_sign` and :func:`pair_input_slot`
enumerate the inputs; :class:`PairBalance` accumulates the sum one source at a
time (:func:`pair_balance_add`) and :func:`pair_balance_mis` gives m.

Every function takes plain values (integrands, pdfs or targets, Jacobians,
validity), so the toys here and a path-space renderer call the same code. The
integrand values f and G are floats (the toys) or RGB ``wp.vec3`` (a renderer),
through float and vec3 overloads of one generic body; densities, targets and
weights are scalars.
Assumptions: pdfs/targets are ≥ 0, Jacobians are |det|, and a failed shift is
reported by ``valid = False`` (its other inputs are then ignored).

References: seed 000 (Wang et al., Gradient-domain ReSTIR Path Tracing),
Eq. 1–4, 10–26; M. Kettunen et al., "Gradient-domain path tracing", ACM TOG
34(4), 2015; W. Chang et al., "Parameter-space ReSTIR", SIGGRAPH 2023.
"""

from __future__ import annotations

from typing import Any

import warp as wp

from grisx.theory.gris import resampling_weight
from grisx.theory.mis import balance_mis, balance_term, target_from, two_domain_balance
from grisx.theory.reservoir import Reservoir, reservoir_update
from grisx.theory.shift import ShiftResult

__all__ = [
    "PAIR_BASE_I",
    "PAIR_BASE_J",
    "SIGN_ABS",
    "SIGN_POS",
    "SIGN_NEG",
    "PairShift",
    "PairBalance",
    "gradient_mis",
    "shifted_difference",
    "pair_contribution",
    "pair_value",
    "signed_target",
    "pair_estimate",
    "outer_shift",
    "outer_shift_of",
    "pair_outer_weight",
    "pair_update",
    "pair_slot_sign",
    "pair_source_inputs",
    "pair_input_sign",
    "pair_input_slot",
    "pair_target_from",
    "pair_balance_empty",
    "pair_balance_add",
    "pair_balance_mis",
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


@wp.struct
class PairBalance:
    """Running sums of the generalized balance heuristic over a positivized merge's inputs (seed 001, Eq. 15).

    ``term_sum`` = Σ_{l,e} c_{l,e} p̂^{s_e}_{←l}(y) over the inputs added so far; ``own`` =
    p̂^{s_e}_{←l}(y) of the input the candidate y came from.
    """

    term_sum: float
    own: float


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


# The integrand values f and G come as floats (toys) or RGB wp.vec3 (renderers): one generic body
# per formula, and a concrete float and vec3 overload of each public name. (Concrete overloads,
# not public Any parameters: Warp 1.19 resolves a generic call's argument types by name before
# code generation and mistakes a kernel's local variable for a same-named module global.)


@wp.func
def _shifted_difference(f_base: Any, f_offset: Any, jacobian: float, valid: wp.bool):
    if valid:
        return f_base - f_offset * wp.abs(jacobian)  # seed 000, Eq. 2
    return f_base


@wp.func
def _pair_contribution(k: int, f_base: Any, f_offset: Any, jacobian: float, valid: wp.bool):
    d = _shifted_difference(f_base, f_offset, jacobian, valid)
    if k == PAIR_BASE_J:
        return -d  # seed 000, Eq. 15, k = 1
    return d


@wp.func
def _pair_value(k: int, f_base: Any, f_offset: Any, pdf_base: float, pdf_offset: float, jacobian: float, valid: wp.bool):
    return gradient_mis(pdf_base, pdf_offset, jacobian, valid) * _pair_contribution(k, f_base, f_offset, jacobian, valid)  # Eq. 14–16


@wp.func
def shifted_difference(f_base: float, f_offset: float, jacobian: float, valid: wp.bool) -> float:
    """f_i(x) − f_j(T_ij x)|∂T_ij/∂x| (seed 000, Eq. 2): base minus shifted offset (0 offset if T failed)."""
    return _shifted_difference(f_base, f_offset, jacobian, valid)


@wp.func
def shifted_difference(f_base: wp.vec3, f_offset: wp.vec3, jacobian: float, valid: wp.bool) -> wp.vec3:  # noqa: F811 (a Warp overload)
    """Eq. 2 on RGB values, per channel."""
    return _shifted_difference(f_base, f_offset, jacobian, valid)


@wp.func
def pair_contribution(k: int, f_base: float, f_offset: float, jacobian: float, valid: wp.bool) -> float:
    """G_ij(x, k) (seed 000, Eq. 15): f_i − f_j∘T_ij·|J| for k = 0, f_i∘T_ji·|J| − f_j for k = 1.

    ``f_base`` is the integrand of the pixel x lives in (i for k = 0, j for
    k = 1), ``f_offset`` the other pixel's at the inner shift of x.
    """
    return _pair_contribution(k, f_base, f_offset, jacobian, valid)


@wp.func
def pair_contribution(k: int, f_base: wp.vec3, f_offset: wp.vec3, jacobian: float, valid: wp.bool) -> wp.vec3:  # noqa: F811 (a Warp overload)
    """Eq. 15 on RGB values, per channel."""
    return _pair_contribution(k, f_base, f_offset, jacobian, valid)


@wp.func
def pair_value(k: int, f_base: float, f_offset: float, pdf_base: float, pdf_offset: float, jacobian: float, valid: wp.bool) -> float:
    """ω*_ij(x, k) · G_ij(x, k) (seed 000, Eq. 14–16): the integrand of Δ_ij over the paired-pixel domain."""
    return _pair_value(k, f_base, f_offset, pdf_base, pdf_offset, jacobian, valid)


@wp.func
def pair_value(k: int, f_base: wp.vec3, f_offset: wp.vec3, pdf_base: float, pdf_offset: float, jacobian: float, valid: wp.bool) -> wp.vec3:  # noqa: F811 (a Warp overload)
    """Eq. 14–16 on RGB values: one scalar ω* (densities or targets are scalars) times G per channel."""
    return _pair_value(k, f_base, f_offset, pdf_base, pdf_offset, jacobian, valid)


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
def _pair_estimate(value: Any, ucw: float):
    return value * ucw  # seed 000, Eq. 17


@wp.func
def pair_estimate(value: float, ucw: float) -> float:
    """⟨Δ_ij⟩ = ω*G(y) · W_y (seed 000, Eq. 17); also Eq. 11 for Gradient after ReSTIR.

    With positivization the ``pos`` and ``neg`` reservoirs' estimates have
    fixed signs and Δ is their sum (Eq. 24).
    """
    return _pair_estimate(value, ucw)


@wp.func
def pair_estimate(value: wp.vec3, ucw: float) -> wp.vec3:  # noqa: F811 (a Warp overload)
    """Eq. 17 on an RGB ω*G."""
    return _pair_estimate(value, ucw)


@wp.func
def outer_shift_of(k: int, jacobian: float, valid: wp.bool) -> PairShift:
    """The indicator and Jacobian of T*(x, k) = (τ(x), k) (seed 000, Eq. 21–22), for a τ whose base path the caller keeps.

    A renderer's base path is a whole light path (τ: the film translation and the hybrid path shift,
    :mod:`grisx.render.restir_gpt`); ``jacobian`` and ``valid`` are τ's, γ(k) = k, and
    |∂T*/∂(x, k)| = |∂τ/∂x|. (``x`` is left 0: the toys' scalar base path goes through :func:`outer_shift`.)
    """
    s = PairShift()
    s.x = 0.0
    s.k = k
    s.jacobian = wp.abs(jacobian)
    s.valid = valid
    if not valid:
        s.jacobian = 0.0
    return s


@wp.func
def outer_shift(shifted: ShiftResult, k: int) -> PairShift:
    """T*(x, k) = (τ(x), k) (seed 000, Eq. 21) with |∂T*/∂(x, k)| = |∂τ/∂x| (Eq. 22).

    ``shifted`` is the base path's shift to the corresponding pixel of the
    target pair (pixel i' → i for k = 0, j' → j for k = 1); the indicator is
    carried by the identity γ(k) = k.
    """
    s = outer_shift_of(k, shifted.jacobian, shifted.valid)
    s.x = shifted.x
    s.jacobian = wp.abs(shifted.jacobian)  # as given, also where τ failed (the toys read valid)
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


# ---- MIS of a positivized merge, with reuse across signs (seed 000, Sec. 4.4; seed 001, Eq. 15–16) ----


@wp.func
def pair_slot_sign(positivize: int, slot: int) -> int:
    """The target sign of reservoir ``slot`` of a pair: slot 0 holds ``pos`` (or, unpositivized, the one |ω*G| reservoir), slot 1 ``neg``."""
    if positivize == 0:
        return SIGN_ABS
    if slot == 0:
        return SIGN_POS
    return SIGN_NEG


@wp.func
def pair_source_inputs(source: int, positivize: int, cross_sign: int) -> int:
    """How many of source ``source``'s reservoirs a merge into one sign reads: 1, or 2 reusing across signs.

    Reuse across signs (Chang et al. 2023; seed 000, Sec. 4.4) reads the reservoir of the other sign
    too (input e = 1), except from source 0, the pair's own reservoir: there p̂₊ p̂₋ = 0 at the
    identity shift, so it would add nothing. Needs ``positivize``.
    """
    if positivize != 0 and cross_sign != 0 and source != 0:
        return 2
    return 1


@wp.func
def pair_input_sign(sign: int, e: int) -> int:
    """s_e: the target sign of input e of a source in a merge of sign ``sign`` (e = 0 same sign, 1 the other)."""
    if e == 1:
        return -sign
    return sign


@wp.func
def pair_input_slot(slot: int, e: int) -> int:
    """The reservoir slot of input e of a source in a merge into ``slot`` (e = 1: the other sign's slot)."""
    if e == 1:
        return 1 - slot
    return slot


@wp.func
def pair_target_from(sign: int, value_from: float, jacobian: float, valid: wp.bool) -> float:
    """p̂^s_{←l}(y) = p̂^s_l(T*⁻¹ y) · |∂T*⁻¹/∂y| (seed 001, Eq. 16; p̂^s of seed 000, Eq. 19, 25–26).

    ``value_from`` is ω*G in source l's domain at T*⁻¹(y), ``jacobian`` = |∂T*⁻¹/∂y|; 0 where T*⁻¹ fails.
    """
    if not valid:
        return 0.0
    return target_from(signed_target(sign, value_from), jacobian)


@wp.func
def pair_balance_empty() -> PairBalance:
    """No input added yet."""
    b = PairBalance()
    b.term_sum = 0.0
    b.own = 0.0
    return b


@wp.func
def pair_balance_add(
    b: PairBalance,
    sign: int,
    inputs: int,
    confidence_same: float,
    confidence_other: float,
    value_from: float,
    jacobian: float,
    valid: wp.bool,
    own_input: int,
) -> PairBalance:
    """Add source l's ``inputs`` terms c_{l,e} p̂^{s_e}_{←l}(y) to the denominator of Eq. 15 (seed 001).

    ``confidence_same``/``confidence_other`` are c of l's reservoirs of sign s and −s (the latter read
    only if ``inputs`` = 2, see :func:`pair_source_inputs`); ``value_from``, ``jacobian``, ``valid``
    describe T*⁻¹(y) into l's domain (:func:`pair_target_from`). ``own_input`` = e if y came from
    input (l, e), else −1.
    """
    out = b
    t = pair_target_from(sign, value_from, jacobian, valid)
    out.term_sum = b.term_sum + balance_term(confidence_same, t)
    if own_input == 0:
        out.own = t
    if inputs > 1:
        t = pair_target_from(-sign, value_from, jacobian, valid)
        out.term_sum = out.term_sum + balance_term(confidence_other, t)
        if own_input == 1:
            out.own = t
    return out


@wp.func
def pair_balance_mis(b: PairBalance, confidence: float) -> float:
    """m_{l,e}(y) = c_{l,e} p̂^{s_e}_{←l}(y) / Σ_{l',e'} c_{l',e'} p̂^{s_e'}_{←l'}(y) (seed 001, Eq. 15); 0 when nothing covers y.

    ``confidence`` is c_{l,e} of the candidate's input, after every input was added to ``b``.
    """
    return balance_mis(confidence, b.own, b.term_sum)
