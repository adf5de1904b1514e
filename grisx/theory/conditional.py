"""Conditional and joint unbiased contribution weights, and conditional RIS (seed 001).

A path x = (x^p, x^s) splits into a *prefix* x^p and a *suffix* x^s whose
sampling depends on the prefix. Reusing only the suffix of another pixel's
path (Suffix ReSTIR, seed 001, Sec. 6) means resampling in a probability
space *conditioned* on prefixes Z — the supporting prefixes that produced the
reused suffixes and the prefix they are reused for.

**Conditional UCW** (seed 001, Def. 4.1). W_{X|Z} is a conditional unbiased
contribution weight for X given Z when, for every integrable f (which may
depend on Z),

    E[f(X) W_{X|Z} | Z] = ∫_{supp(X|Z)} f(x) dx.                   (Eq. 5)

A sample from a conditional pdf has W = 1/p(x|z) (:func:`~grisx.theory.gris.ucw_from_source_pdf`);
a shift Y = T(X|Z) carries the weight as W_{Y|Z} = W_{X|Z} |T'(X|Z)|
(:func:`shifted_conditional_ucw`, Sec. 6.3).

**Joint UCW** (Thm. 4.1). If X₂ and W_{X₂|X₁} are conditionally independent
of W_{X₁} given X₁, then

    W_{X₁,X₂} = W_{X₁} · W_{X₂|X₁}                                  (Eq. 9)

is a joint UCW for (X₁, X₂) (:func:`joint_ucw`). The condition is not a
formality: E[f W_{X₁} W_{X₂|X₁}] = E[E[f W_{X₁} W_{X₂|X₁} | X₁]] (Eq. 8) only
equals the iterated integral (Eq. 7) when W_{X₁} can leave the inner
expectation. When X₂ shares random numbers with W_{X₁} beyond X₁ (the same
candidate pool, the same uniforms), W_{X₂|X₁} must be a UCW *conditional on
those shared numbers too* — treating them as constants — or the product is
biased (the ``joint-ucw`` toy's ``dependent`` method shows this).

**Conditional RIS** (Sec. 5.1). Inputs X_i ∈ Ω_i with W_{X_i|Z}, possibly
in domains that depend on Z, are shifted into the destination domain by
conditioned shifts Y_i = T_i(X_i|Z), and one is kept with probability ∝

    w_i = m_i(Y_i|Z) p̂(Y_i|Z) W_{X_i|Z} |T_i'(X_i|Z)|,

giving W_{Y|Z} = Σ w_i / p̂(Y|Z) (Eq. 13) — GRIS read in the conditional
space, so the weights are :func:`~grisx.theory.gris.resampling_weight` and
the reservoir of :mod:`grisx.theory.reservoir`. The MIS weights are the
generalized balance heuristic with domain weights α_i,

    m_i(y|Z) = α_i p̂_{←i}(y|Z) / Σ_j α_j p̂_{←j}(y|Z),               (Eq. 15)
    p̂_{←j}(y|Z) = p̂_j(T_j⁻¹(y|Z) | Z_j) |T_j'⁻¹(y|Z)|,              (Eq. 16)

where p̂_j is domain j's target *given its own supporting prefix* Z_j
(:func:`~grisx.theory.mis.target_from`, :func:`~grisx.theory.mis.mis_weight`).
The domains a reservoir holds need not cover supp(f(·|Z)); the result only
integrates over the union of their supports (Eq. 17), so a **canonical**
input — a fresh sample of the destination's own conditional domain — is
combined in for coverage.

**Integration** (Eq. 14, 22). Summing instead of selecting,

    ⟨I⟩ = Σ_i m_i(Y_i|Z) f(X^p, Y_i) W_{X^p} W_{X_i^s|Z} |T_i'|,     (Eq. 22)

is unbiased for ∫∫ f when the canonical suffix is among the inputs
(:func:`gather_term` for one i, after a prefix X^p with W_{X^p}).

**Final gather with roulette** (Eq. 23). N integration prefixes each borrow
suffixes; all N canonical suffixes stay in every MIS weight, but only one
random prefix traces its canonical suffix, whose contribution is multiplied by
N (selection probability 1/N): :func:`roulette_pick`,
:func:`canonical_roulette_weight`. The mean is that of N canonical suffixes;
the work drops from N canonical suffixes to one. Keeping R of the N (a cyclic
window after a uniform first index, :func:`roulette_window_holds`, each kept
one weighted N/R, :func:`roulette_window_weight`) is as unbiased and trades
the canonical term's variance, which grows as N/R, against R suffix traces.

Problem-specific hooks (the conditional target, the conditioned shift, the
source pdf, the full-path integrand) enter through
:func:`make_conditional_ris`, which builds the conditional-RIS step, the
conditional MIS weight and the Eq. 22 term for one sample type — the toys'
1D suffixes here and, with path records, the scene-layer Suffix ReSTIR.

Assumptions: supports of the domains are the supports of their targets (each
domain carried a canonical sample when it was built); confidences α_i do not
depend on the samples being weighted; all prefix randomness is independent of
suffix randomness, and prefix selection never looks at suffixes (seed 001,
Sec. 6.2: otherwise suffixes end up conditioned on themselves).

References: M. Kettunen, D. Lin, R. Ramamoorthi, T. Bashford-Rogers, C.
Wyman, "Conditional Resampled Importance Sampling and ReSTIR", SIGGRAPH Asia
2023 (seed 001), Def. 4.1, Thm. 4.1, Eq. 5–23, Alg. 1; D. Lin et al.,
"Generalized Resampled Importance Sampling", SIGGRAPH 2022; R. West et al.,
"Marginal Multiple Importance Sampling", SIGGRAPH Asia 2022 (the MMIS
baseline: the same balance heuristic read with source pdfs).
"""

from typing import Any

import warp as wp

from grisx.theory.mis import MIS_BALANCE, mis_weight, pairwise_mis_canonical_term, pairwise_mis_neighbor, target_from
from grisx.theory.random import random_uniform
from grisx.theory.gris import resampling_weight, ris_weight
from grisx.theory.reservoir import Reservoir, confidence_capped, reservoir_empty, reservoir_finalize, reservoir_update

__all__ = [
    "joint_ucw",
    "shifted_conditional_ucw",
    "roulette_pick",
    "canonical_roulette_weight",
    "roulette_window_holds",
    "roulette_window_weight",
    "PROXY_TARGET",
    "PROXY_SOURCE_PDF",
    "PAIRWISE_TARGET",
    "make_conditional_ris",
]

#: MIS proxies: read each domain's conditional target p̂_j (resampled inputs,
#: seed 001 Eq. 16) or its conditional source pdf p_j (independently sampled
#: inputs: the balance heuristic of MMIS, West et al. 2022)
PROXY_TARGET = wp.constant(0)
PROXY_SOURCE_PDF = wp.constant(1)
#: the gather's MIS as pairs (each borrowed domain against the canonical one) over targets: O(k) shifts
PAIRWISE_TARGET = wp.constant(2)


@wp.func
def joint_ucw(ucw_first: float, ucw_second_given_first: float) -> float:
    """W_{X₁,X₂} = W_{X₁} · W_{X₂|X₁} (seed 001, Thm. 4.1, Eq. 9).

    Valid only when X₂ and W_{X₂|X₁} are conditionally independent of W_{X₁}
    given X₁ (or W_{X₂|X₁} is conditional on everything they share). 0 when
    either factor is non-positive or NaN.
    """
    w = ucw_first * ucw_second_given_first
    if w > 0.0:
        return w
    return 0.0


@wp.func
def shifted_conditional_ucw(ucw_given_z: float, jacobian: float) -> float:
    """W_{Y|Z} = W_{X|Z} |T'(X|Z)| for Y = T(X|Z) (seed 001, Sec. 6.3 after Eq. 22); 0 for non-positive or NaN.

    The W·|T'| factor of the GRIS weight (seed 000, Eq. 9) with m = p̂ = 1.
    """
    return resampling_weight(1.0, 1.0, ucw_given_z, jacobian)


@wp.func
def roulette_pick(u: float, count: int) -> int:
    """The prefix that traces the canonical suffix: uniform over 0 … count−1 (seed 001, Sec. 7)."""
    i = int(u * float(count))
    return wp.clamp(i, 0, count - 1)


@wp.func
def roulette_window_holds(j: int, first: int, kept: int, count: int) -> wp.bool:
    """Whether prefix ``j`` of ``count`` is among the ``kept`` that trace their canonical suffix: the cyclic window
    first, first + 1, … (mod count) of ``kept`` prefixes after a uniform ``first`` (:func:`roulette_pick`), so each
    prefix is in it with probability kept / count."""
    return (j - first + count) % count < kept


@wp.func
def roulette_window_weight(traced: wp.bool, kept: int, count: int) -> float:
    """Weight of one prefix's canonical-suffix term when ``kept`` of ``count`` prefixes trace theirs (seed 001, Eq. 23
    with ``kept`` = 1): count / kept if it was traced, else 0. E[weight] = 1, so the gather's mean does not change;
    the canonical term's variance grows as count / kept."""
    if traced:
        return float(count) / float(kept)
    return 0.0


@wp.func
def canonical_roulette_weight(roulette: int, chosen: wp.bool, count: int) -> float:
    """Weight of one prefix's canonical-suffix term in the final gather (seed 001, Eq. 23).

    With roulette, the canonical suffix is kept for one of ``count`` prefixes
    (probability 1/count) and divided by that probability: ``count`` if
    ``chosen``, else 0. Without roulette every prefix traces its own: 1.
    Either way E[weight] = 1, so the gather's mean does not change.
    """
    if roulette == 0:
        return roulette_window_weight(True, count, count)
    return roulette_window_weight(chosen, 1, count)


def make_conditional_ris(
    spec_type: Any,
    target: Any,
    sample: Any,
    source_pdf: Any,
    shift: Any,
    integrand: Any,
    *,
    prefix_type: Any = float,
    suffix_type: Any = float,
    suffix_empty: Any = None,
) -> Any:
    """Build the conditional-RIS functions for one problem (a namespace of ``wp.func``).

    ``prefix_type`` and ``suffix_type`` are the Warp types of a prefix z and a suffix x (floats
    for the 1D toys; :mod:`grisx.render.suffix_restir` passes its prefix record and
    :class:`~grisx.render.base.path_shift.PathSample`), ``suffix_empty() -> suffix_type`` the
    "no suffix" value (0.0 by default). ``sample`` and ``source_pdf`` may be None where suffixes
    come from elsewhere (the renderer traces them with the path tracer); then
    ``canonical_suffix`` is not built and only the target proxy (``PROXY_TARGET``) exists.

    Hooks (Warp functions of the problem's ``spec`` struct):

    ``target(spec, z, x) -> float``
        p̂(x | z): the conditional target of suffix x after prefix z (seed 001, Eq. 20);
    ``sample(spec, z, u) -> x`` and ``source_pdf(spec, z, x) -> float``
        a fresh (canonical) suffix after prefix z from one uniform u, and its pdf p(x | z);
    ``shift(spec, z_src, z_dst, x) -> ShiftResult``
        the conditioned shift T(x | z_src → z_dst) with |∂T/∂x| and validity;
    ``integrand(spec, z, x) -> float``
        the full path contribution f(z, x) = f_p f_ps f_s (seed 001, Eq. 18) (any type that a
        float scales: the renderer's is RGB).

    A *domain row* of n inputs is three arrays of length n: ``prefixes[l]`` (the
    supporting prefix Z_l), ``suffixes[l]`` (X_l) and ``reservoirs[l]`` (its
    W_{X_l|Z_l} as ``ucw``), plus ``confidences[l]`` (α_l, Eq. 15) and a
    scratch row ``targets`` (p̂_{←l}, Eq. 16). Entry ``canonical`` is the
    destination's own domain (its prefix is the destination prefix z).

    Returns an object with the ``wp.func`` attributes ``canonical_suffix``,
    ``carried_target``, ``source_carried_target``, ``conditional_mis``, ``conditional_ris``,
    ``spatial_conditional_ris``, ``gather_sample``, ``gather_weight_pairwise`` and ``gather_term`` and the structs
    ``ConditionalReservoir`` and ``GatherSample``.
    """
    if suffix_empty is None:

        @wp.func
        def suffix_empty() -> float:
            return 0.0

    @wp.struct
    class ConditionalReservoir:
        """One conditional-RIS result: reservoir (W_{Y|Z} in ``ucw``), its sample y, and the shifts it cost."""

        reservoir: Reservoir
        y: suffix_type
        shifts: int

    @wp.struct
    class GatherSample:
        """One input of Eq. 22 shifted to the integration prefix: Y_i and m_i(Y_i|Z) W_{X^p,Y_i} (0: no term)."""

        y: suffix_type
        weight: float

    def canonical_suffix(spec: spec_type, z: prefix_type, candidates: int, key: wp.uint32, counter: int) -> ConditionalReservoir:
        """A fresh suffix after prefix z by RIS of M candidates from p(·|z) (seed 001, Sec. 5.1; Alg. 1 line 8).

        w = p̂(x|z) / (M p(x|z)) (seed 000, Eq. 6 given z), W_{X|z} = Σ w / p̂(X|z)
        (Eq. 13), confidence 1: its support is all of supp p̂(·|z), which makes
        it the canonical input. M = 1 is a plain conditional sample, W = 1/p(x|z).
        Uses uniforms ``counter`` … ``counter + 2M − 1`` of ``key``.
        """
        out = ConditionalReservoir()
        r = reservoir_empty()
        y = suffix_empty()
        inv_m = 1.0 / float(candidates)
        for c in range(candidates):
            x = sample(spec, z, random_uniform(key, counter + 2 * c))
            p_hat = target(spec, z, x)
            w = ris_weight(inv_m, p_hat, source_pdf(spec, z, x))
            r = reservoir_update(r, w, p_hat, 0.0, random_uniform(key, counter + 2 * c + 1))
            if r.selected:
                y = x
        r.confidence = 1.0
        out.reservoir = reservoir_finalize(r)
        out.y = y
        out.shifts = 0
        return out

    if sample is not None:
        canonical_suffix = wp.func(canonical_suffix)
    else:
        canonical_suffix = None

    if source_pdf is not None:

        @wp.func
        def proxy(spec: spec_type, mode: int, z: prefix_type, x: suffix_type) -> float:
            if mode == PROXY_SOURCE_PDF:
                return source_pdf(spec, z, x)
            return target(spec, z, x)

    else:

        @wp.func
        def proxy(spec: spec_type, mode: int, z: prefix_type, x: suffix_type) -> float:
            return target(spec, z, x)  # PROXY_TARGET only

    @wp.func
    def carried_target(spec: spec_type, mode: int, z_from: prefix_type, z: prefix_type, y: suffix_type) -> float:
        """p̂_{←j}(y|Z) (seed 001, Eq. 16): the proxy of the domain with prefix ``z_from`` at T⁻¹(y), times |T'⁻¹|."""
        s = shift(spec, z, z_from, y)  # the inverse shift: destination prefix z back to domain j's
        if not s.valid:
            return 0.0
        return target_from(proxy(spec, mode, z_from, s.x), s.jacobian)

    @wp.func
    def conditional_mis(
        spec: spec_type,
        mode: int,
        z: prefix_type,
        y: suffix_type,
        source: int,
        canonical: int,
        prefixes: wp.array(dtype=prefix_type),
        confidences: wp.array(dtype=float),
        targets: wp.array(dtype=float),
        source_proxy: float,
    ) -> float:
        """m_source(y|Z): generalized balance heuristic over the row's domains (seed 001, Eq. 15–16).

        ``y`` is a sample of the destination domain (prefix ``z``); fills
        ``targets`` with p̂_{←l}(y|Z) for every domain l (the canonical one
        reads p̂(y|z) directly) and weighs them with ``confidences``.
        ``source_proxy`` ≥ 0 is p̂_{←source}(y) as the caller knows it when y is
        the shift of the source's own suffix, y = T(x_source): the inverse shift
        gives back x_source, so p̂_{←source}(y) = p̂_source(x_source) / |T'|
        (:func:`source_carried_target`) and costs no shift. Negative: that domain
        is shifted too, like every other.
        """
        n = prefixes.shape[0]
        for l in range(n):
            if l == canonical:
                targets[l] = proxy(spec, mode, z, y)
            elif l == source and source_proxy >= 0.0:
                targets[l] = source_proxy
            else:
                targets[l] = carried_target(spec, mode, prefixes[l], z, y)
        return mis_weight(MIS_BALANCE, source, canonical, confidences, targets)

    @wp.func
    def source_carried_target(spec: spec_type, mode: int, z_source: prefix_type, x_source: suffix_type, jacobian: float) -> float:
        """p̂_{←source}(T(x_source)) = p̂_source(x_source) / |T'| (Eq. 16 at the forward shift's own image, T bijective)."""
        if jacobian <= 0.0:
            return 0.0
        return target_from(proxy(spec, mode, z_source, x_source), 1.0 / jacobian)

    @wp.func
    def conditional_ris(
        spec: spec_type,
        z: prefix_type,
        canonical: int,
        prefixes: wp.array(dtype=prefix_type),
        suffixes: wp.array(dtype=suffix_type),
        reservoirs: wp.array(dtype=Reservoir),
        confidences: wp.array(dtype=float),
        targets: wp.array(dtype=float),
        key: wp.uint32,
        counter: int,
    ) -> ConditionalReservoir:
        """One conditional-RIS step (seed 001, Sec. 5.1; Alg. 1 lines 6–10): resample the row into prefix z.

        Every input X_l is shifted to Y_l = T(X_l | Z_l → z), weighted by
        w_l = m_l(Y_l|Z) p̂(Y_l|z) W_{X_l|Z} |T'| and streamed through a
        reservoir (uniform ``random_uniform(key, counter + l)``); the result's
        ``ucw`` is W_{Y|Z} (Eq. 13) and its confidence Σ α_l. ``confidences``
        must hold the α_l (e.g. the reservoirs' capped confidences) on entry.
        """
        n = prefixes.shape[0]
        out = ConditionalReservoir()
        r = reservoir_empty()
        y = suffix_empty()
        shifts = int(0)
        for l in range(n):
            s = shift(spec, prefixes[l], z, suffixes[l])
            shifts += 1
            w = float(0.0)
            p_hat = float(0.0)
            if s.valid and reservoirs[l].ucw > 0.0:
                own = float(-1.0)  # the canonical input's own domain is read directly
                if l != canonical:
                    own = source_carried_target(spec, PROXY_TARGET, prefixes[l], suffixes[l], s.jacobian)
                m = conditional_mis(spec, PROXY_TARGET, z, s.x, l, canonical, prefixes, confidences, targets, own)
                shifts += n - 1  # the inverse shifts of Eq. 16 (one of them, the source's own, read from x_l)
                if l != canonical:
                    shifts -= 1
                p_hat = target(spec, z, s.x)
                w = resampling_weight(m, p_hat, reservoirs[l].ucw, s.jacobian)  # GRIS weight read given Z
            # a failed shift still adds its domain's confidence α_l (sample-independent)
            r = reservoir_update(r, w, p_hat, confidences[l], random_uniform(key, counter + l))
            if r.selected:
                y = s.x
        out.reservoir = reservoir_finalize(r)  # W_{Y|Z} = Σ w / p̂(Y|z), Eq. 13
        out.y = y
        out.shifts = shifts
        return out

    @wp.func
    def spatial_conditional_ris(
        spec: spec_type,
        prefixes: wp.array(dtype=prefix_type),
        suffixes: wp.array(dtype=suffix_type),
        reservoirs: wp.array(dtype=Reservoir),
        next_suffixes: wp.array(dtype=suffix_type),
        next_reservoirs: wp.array(dtype=Reservoir),
        confidences: wp.array(dtype=float),
        targets: wp.array(dtype=float),
        cap: float,
        key: wp.uint32,
    ) -> int:
        """Spatial suffix reuse (seed 001, Alg. 1 line 10) over a row of n supporting prefixes.

        Every entry i resamples all n suffixes, shifted to continue its own
        prefix, by :func:`conditional_ris` with itself canonical and α_l the
        capped confidences; the results (confidence capped at ``cap``) replace
        the row once all are done (``next_*`` is the second buffer). Returns
        the number of shift evaluations.
        """
        n = prefixes.shape[0]
        for l in range(n):
            confidences[l] = confidence_capped(reservoirs[l].confidence, cap)
        shifts = int(0)
        for i in range(n):
            res = conditional_ris(spec, prefixes[i], i, prefixes, suffixes, reservoirs, confidences, targets, key, i * n)
            shifts += res.shifts
            r = res.reservoir
            r.confidence = confidence_capped(r.confidence, cap)
            next_suffixes[i] = res.y
            next_reservoirs[i] = r
        for i in range(n):
            suffixes[i] = next_suffixes[i]
            reservoirs[i] = next_reservoirs[i]
        return shifts

    @wp.func
    def gather_weight_pairwise(
        spec: spec_type,
        z: prefix_type,
        prefix_ucw: float,
        source: int,
        canonical: int,
        prefixes: wp.array(dtype=prefix_type),
        suffixes: wp.array(dtype=suffix_type),
        reservoirs: wp.array(dtype=Reservoir),
        confidences: wp.array(dtype=float),
    ) -> GatherSample:
        """:func:`gather_sample` with *pairwise* conditional MIS instead of the balance heuristic over all domains.

        Each borrowed domain l pairs with the canonical one (Bitterli 2022's pairwise MIS read given
        Z, :func:`~grisx.theory.mis.pairwise_mis_neighbor`): a borrowed sample's weight needs only
        p̂(Y_l|z) and p̂_{←l}(Y_l) = p̂_l(X_l|Z_l) / |T_l'| — no further shift — and the canonical
        sample's needs one inverse shift per borrowed domain, so a row of k + 1 costs O(k) shifts,
        not O(k²). The weights still sum to one over the domains that reach y (the pair
        weights sum to one; a pair whose borrowed domain misses y gives its share to the
        canonical domain), which is all Eq. 22 asks. Domains of confidence 0 are left out.
        """
        out = GatherSample()
        out.weight = 0.0
        src = reservoirs[source]
        s = shift(spec, prefixes[source], z, suffixes[source])
        out.y = s.x
        if not s.valid or src.ucw <= 0.0:
            return out
        n = prefixes.shape[0]
        c_c = confidences[canonical]
        total = c_c
        k = int(0)
        for l in range(n):
            if l != canonical and confidences[l] > 0.0:
                total += confidences[l]
                k += 1
        t_c = target(spec, z, s.x)  # p̂(y|z)
        m = float(0.0)
        if source == canonical:
            if k == 0:
                m = pairwise_mis_canonical_term(0.0, 0.0, c_c, t_c, 0, total)  # no neighbours: 1
            for l in range(n):
                if l != canonical and confidences[l] > 0.0:
                    t_l = carried_target(spec, PROXY_TARGET, prefixes[l], z, s.x)  # p̂_{←l}(y), Eq. 16
                    m += pairwise_mis_canonical_term(confidences[l], t_l, c_c, t_c, k, total)
        else:
            t_l = source_carried_target(spec, PROXY_TARGET, prefixes[source], suffixes[source], s.jacobian)  # p̂_l(x)/|T'|, Eq. 16
            m = pairwise_mis_neighbor(confidences[source], t_l, c_c, t_c, k, total)
        out.weight = m * joint_ucw(prefix_ucw, shifted_conditional_ucw(src.ucw, s.jacobian))
        return out

    @wp.func
    def gather_sample(
        spec: spec_type,
        mode: int,
        z: prefix_type,
        prefix_ucw: float,
        source: int,
        canonical: int,
        prefixes: wp.array(dtype=prefix_type),
        suffixes: wp.array(dtype=suffix_type),
        reservoirs: wp.array(dtype=Reservoir),
        confidences: wp.array(dtype=float),
        targets: wp.array(dtype=float),
    ) -> GatherSample:
        """Y_i = T_i(X_i|Z) and m_i(Y_i|Z) W_{X^p, Y_i}: input ``source``'s term of Eq. 22 for prefix z, less f (seed 001).

        W_{X^p,Y_i} = W_{X^p} · W_{X_i|Z} |T_i'| (Thm. 4.1 with the shifted
        conditional UCW). m_i is :func:`conditional_mis` over the row with ``mode``'s proxy, or,
        for ``PAIRWISE_TARGET``, :func:`gather_weight_pairwise`'s. Weight 0 where the shift is
        undefined or W = 0.
        """
        if mode == PAIRWISE_TARGET:
            return gather_weight_pairwise(spec, z, prefix_ucw, source, canonical, prefixes, suffixes, reservoirs, confidences)
        out = GatherSample()
        out.weight = 0.0
        src = reservoirs[source]
        s = shift(spec, prefixes[source], z, suffixes[source])
        out.y = s.x
        if not s.valid or src.ucw <= 0.0:
            return out
        own = float(-1.0)
        if source != canonical:
            own = source_carried_target(spec, mode, prefixes[source], suffixes[source], s.jacobian)
        m = conditional_mis(spec, mode, z, s.x, source, canonical, prefixes, confidences, targets, own)
        out.weight = m * joint_ucw(prefix_ucw, shifted_conditional_ucw(src.ucw, s.jacobian))
        return out

    @wp.func
    def gather_term(
        spec: spec_type,
        mode: int,
        z: prefix_type,
        prefix_ucw: float,
        source: int,
        canonical: int,
        prefixes: wp.array(dtype=prefix_type),
        suffixes: wp.array(dtype=suffix_type),
        reservoirs: wp.array(dtype=Reservoir),
        confidences: wp.array(dtype=float),
        targets: wp.array(dtype=float),
    ) -> float:
        """m_i(Y_i|Z) f(X^p, Y_i) W_{X^p, Y_i}: input ``source``'s term of Eq. 22 for prefix z (seed 001), scalar f.

        :func:`gather_sample`'s weight times the integrand; 0 where the shift is undefined or W = 0.
        """
        g = gather_sample(spec, mode, z, prefix_ucw, source, canonical, prefixes, suffixes, reservoirs, confidences, targets)
        if g.weight <= 0.0:
            return 0.0
        return g.weight * integrand(spec, z, g.y)

    class ConditionalRIS:
        pass

    ns = ConditionalRIS()
    ns.ConditionalReservoir = ConditionalReservoir
    ns.GatherSample = GatherSample
    ns.gather_weight_pairwise = gather_weight_pairwise
    ns.gather_sample = gather_sample
    ns.canonical_suffix = canonical_suffix
    ns.carried_target = carried_target
    ns.conditional_mis = conditional_mis
    ns.source_carried_target = source_carried_target
    ns.conditional_ris = conditional_ris
    ns.spatial_conditional_ris = spatial_conditional_ris
    ns.gather_term = gather_term
    return ns
