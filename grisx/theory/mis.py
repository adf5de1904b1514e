"""MIS weights for resampling: which share of a sample each source domain gets.

GRIS is unbiased when, at every point y where the integrand is non-zero, the
MIS weights of the domains that *could* have produced y sum to one
(Lin et al. 2022, Sec. 5). Three families are used by the seeds:

**Generalized balance heuristic** (seed 001, Eq. 15–16)::

    m_i(y) = c_i p̂_{←i}(y) / Σ_j c_j p̂_{←j}(y),
    p̂_{←j}(y) = p̂_j(T_j⁻¹(y)) · |∂T_j⁻¹/∂y|,

with confidence (domain) weights c_i. ``p̂_{←j}`` is domain j's target
carried into the current domain through the inverse shift; it is 0 where the
shift is undefined, which is what makes the weights correct for *partial*
bijections. Cost O(M) target evaluations per sample, O(M²) per reservoir.

**Pairwise MIS** (Bitterli 2022, Ch. 9; Lin et al. 2022), with one canonical
domain c and k neighbours: each neighbour i is weighed only against the
canonical domain, in a pair that gets the share P_i = (c_i + c_c/k) / C of
the total confidence C = c_c + Σ_i c_i::

    m_i(y) = P_i · c_i p̂_{←i}(y) / (c_i p̂_{←i}(y) + (c_c/k) p̂_c(y))
    m_c(y) = Σ_i P_i · (c_c/k) p̂_c(y) / (c_i p̂_{←i}(y) + (c_c/k) p̂_c(y))

For unit confidences P_i = 1/k and m_i = (1/k) p̂_{←i}/(p̂_{←i} + p̂_c/k),
Bitterli's form. Cost O(M). It needs the canonical domain's support to cover
every point with f ≠ 0 — the canonical sample's job.

**Support-counting uniform weights** (seed 004, Alg. 4 lines 16–19)::

    m_i(y) = c_i [p̂_{←i}(y) > 0] / Z(y),   Z(y) = Σ_{j : p̂_{←j}(y) > 0} c_j

Only domains whose support holds y are counted. Counting *every* domain
(the naive 1/M of biased ReSTIR) is the same formula with the wrong Z, and is
biased exactly where a shift is a partial bijection.

**Power heuristic** (Veach 1997, Eq. 9.13, β = 2) for the two sampling
techniques of a path tracer (BSDF sampling and next-event estimation)::

    m_a(x) = p_a(x)² / (p_a(x)² + p_b(x)²)
"""

from __future__ import annotations

import warp as wp

__all__ = [
    "target_from",
    "balance_term",
    "balance_mis",
    "two_domain_balance",
    "pairwise_pair_share",
    "pairwise_mis_neighbor",
    "pairwise_mis_canonical_term",
    "support_count",
    "support_count_term",
    "support_mis",
    "confidence_share",
    "power_heuristic",
    "technique_mis",
    "mis_weight",
    "MIS_MODES",
]


@wp.func
def target_from(target_at_preimage: float, inverse_jacobian: float) -> float:
    """p̂_{←j}(y) = p̂_j(T_j⁻¹(y)) · |∂T_j⁻¹/∂y| (seed 001, Eq. 16).

    ``target_at_preimage`` is domain j's target at the inverse shift of y and
    ``inverse_jacobian`` that inverse shift's Jacobian; call it only where
    the inverse shift is defined (elsewhere p̂_{←j}(y) = 0).
    """
    t = target_at_preimage * wp.abs(inverse_jacobian)
    if t > 0.0:
        return t
    return 0.0


@wp.func
def balance_term(confidence: float, target_from: float) -> float:
    """c_j · p̂_{←j}(y): one term of the generalized balance heuristic's sums (seed 001, Eq. 15)."""
    t = confidence * target_from
    if t > 0.0:
        return t
    return 0.0


@wp.func
def balance_mis(confidence: float, target_from: float, term_sum: float) -> float:
    """m_i(y) = c_i p̂_{←i}(y) / Σ_j c_j p̂_{←j}(y) (seed 001, Eq. 15).

    ``term_sum`` is Σ_j :func:`balance_term` over all domains, this one included.
    """
    if term_sum > 0.0:
        return balance_term(confidence, target_from) / term_sum
    return 0.0


@wp.func
def two_domain_balance(confidence_a: float, target_a: float, confidence_b: float, target_b_from: float) -> float:
    """m_a = c_a p̂_a / (c_a p̂_a + c_b p̂_{←b}): the generalized balance heuristic over two domains (seed 001, Eq. 15).

    The one copy of the weight that gradient-domain ReSTIR (seed 000, Eq. 4 and 13: unit confidences,
    pdfs or targets), the ReSTIR difference estimator (seed 002, Eq. 5 and 11) and temporal reuse
    (ReSTIR PT) use. ``target_b_from`` is domain b's target carried to a's sample,
    p̂_b(T x)·|∂T/∂x| (:func:`target_from`; 0 where b cannot produce the sample, giving m_a = 1 when
    p̂_a > 0). m_a(x) + m_b(T x) = 1 wherever either term is positive.
    """
    a = balance_term(confidence_a, target_a)
    return balance_mis(confidence_a, target_a, a + balance_term(confidence_b, target_b_from))


@wp.func
def pairwise_pair_share(
    confidence_i: float, target_from_i: float, confidence_c: float, target_c: float, neighbors: int
) -> float:
    """Neighbour i's share of its pair with the canonical domain (c_c split over k pairs)."""
    a = balance_term(confidence_i, target_from_i)
    b = balance_term(confidence_c / float(neighbors), target_c)
    if a + b > 0.0:
        return a / (a + b)
    return 0.0


@wp.func
def _pairwise_pair_weight(confidence_i: float, confidence_c: float, neighbors: int, confidence_total: float) -> float:
    """P_i = (c_i + c_c/k) / C: the share of all confidence that pair (i, c) distributes."""
    return (confidence_i + confidence_c / float(neighbors)) / confidence_total


@wp.func
def pairwise_mis_neighbor(
    confidence_i: float,
    target_from_i: float,
    confidence_c: float,
    target_c: float,
    neighbors: int,
    confidence_total: float,
) -> float:
    """Pairwise MIS weight m_i(y) of a sample from neighbour i (k = ``neighbors`` >= 1).

    ``target_from_i`` = p̂_{←i}(y), ``target_c`` = p̂_c(y), ``confidence_total`` = C.
    """
    if neighbors < 1 or confidence_total <= 0.0:
        return 0.0
    return _pairwise_pair_weight(confidence_i, confidence_c, neighbors, confidence_total) * pairwise_pair_share(
        confidence_i, target_from_i, confidence_c, target_c, neighbors
    )


@wp.func
def pairwise_mis_canonical_term(
    confidence_i: float,
    target_from_i: float,
    confidence_c: float,
    target_c: float,
    neighbors: int,
    confidence_total: float,
) -> float:
    """Pair i's contribution to the canonical sample's weight m_c(y); sum it over the k neighbours.

    With no neighbours the canonical weight is 1: call with ``neighbors = 0``
    once and it returns 1.
    """
    if neighbors < 1:
        return 1.0
    if confidence_total <= 0.0:
        return 0.0
    share_c = 1.0 - pairwise_pair_share(confidence_i, target_from_i, confidence_c, target_c, neighbors)
    if balance_term(confidence_i, target_from_i) + balance_term(confidence_c, target_c) <= 0.0:
        share_c = 1.0  # neither domain reaches y: the pair gives its share to the canonical sample
    return _pairwise_pair_weight(confidence_i, confidence_c, neighbors, confidence_total) * share_c


@wp.func
def support_count(z: float, confidence: float, in_support: bool) -> float:
    """Z + c_j if domain j can produce y, else Z: Z(y) = Σ_j c_j [y ∈ supp_j] counted one domain at a time (seed 004, Alg. 4 l. 16–19).

    Renderers decide ``in_support`` (a shifted target > 0, a visibility ray, a Jacobian bound) and add every
    domain through this function, the canonical one included (:func:`support_count_term`).
    """
    if in_support:
        return z + confidence
    return z


@wp.func
def support_count_term(confidence: float, target_from: float) -> float:
    """c_j if domain j's support holds y (p̂_{←j}(y) > 0), else 0: one term of Z(y) (seed 004, Alg. 4)."""
    return support_count(0.0, confidence, target_from > 0.0)


@wp.func
def support_mis(confidence: float, target_from: float, z: float) -> float:
    """m_i = c_i [p̂_{←i}(y) > 0] / Z, Z the confidence of the domains that can produce y (seed 004, Alg. 4 l. 16–19)."""
    if z > 0.0:
        return support_count_term(confidence, target_from) / z
    return 0.0


@wp.func
def confidence_share(confidence: float, total: float) -> float:
    """c_i / Σ_j c_j over *all* domains: the naive weight, unbiased only where every domain covers y."""
    if total > 0.0:
        return confidence / total
    return 0.0


@wp.func
def power_heuristic(pdf_a: float, pdf_b: float) -> float:
    """m_a = p_a² / (p_a² + p_b²) (Veach 1997, Eq. 9.13); 0 when both densities are 0.

    Evaluated through the ratio of the smaller to the larger density, so huge
    densities (near-delta lobes) cannot overflow float32.
    """
    if pdf_a <= 0.0:
        return 0.0
    if pdf_a >= pdf_b:
        r = pdf_b / pdf_a
        return 1.0 / (1.0 + r * r)
    r = pdf_a / pdf_b
    return r * r / (1.0 + r * r)


# ---- one entry point for reuse passes --------------------------------------
# A pass that merges M domains into domain ``canonical`` evaluates, for each
# candidate y, every domain's carried-over target p̂_{←l}(y) into a row and
# asks for the weight of the domain the candidate came from.

MIS_BALANCE = wp.constant(0)
MIS_PAIRWISE = wp.constant(1)
MIS_SUPPORT = wp.constant(2)
MIS_NAIVE = wp.constant(3)

#: user-facing names of the MIS modes, in the order of their constants
MIS_MODES = {"balance": 0, "pairwise": 1, "uniform": 2, "naive": 3}


@wp.func
def mis_weight(
    mode: int,
    source: int,
    canonical: int,
    confidence: wp.array(dtype=float),
    target_from: wp.array(dtype=float),
) -> float:
    """MIS weight m_source(y) of a candidate y from domain ``source`` merged into ``canonical``.

    ``confidence[l]`` is c_l and ``target_from[l]`` is p̂_{←l}(y) for every
    domain l (``target_from[canonical]`` = p̂(y) itself). Modes: balance
    (seed 001, Eq. 15), pairwise (Bitterli 2022), uniform support counting
    (seed 004, Alg. 4) and naive c_j / Σ c (biased on partial bijections).
    """
    n = confidence.shape[0]
    if mode == MIS_BALANCE:
        term_sum = float(0.0)
        for l in range(n):
            term_sum += balance_term(confidence[l], target_from[l])
        return balance_mis(confidence[source], target_from[source], term_sum)
    if mode == MIS_PAIRWISE:
        total = float(0.0)
        for l in range(n):
            total += confidence[l]
        k = n - 1
        c_c = confidence[canonical]
        t_c = target_from[canonical]
        if source != canonical:
            return pairwise_mis_neighbor(confidence[source], target_from[source], c_c, t_c, k, total)
        if k == 0:
            return 1.0
        m = float(0.0)
        for l in range(n):
            if l != canonical:
                m += pairwise_mis_canonical_term(confidence[l], target_from[l], c_c, t_c, k, total)
        return m
    z = float(0.0)
    if mode == MIS_SUPPORT:
        for l in range(n):
            z += support_count_term(confidence[l], target_from[l])
        return support_mis(confidence[source], target_from[source], z)
    for l in range(n):
        z += confidence[l]
    return confidence_share(confidence[source], z)


@wp.func
def technique_mis(end_nee: int, light_delta: int, bsdf_delta: int, light_pdf: float, bsdf_pdf: float) -> float:
    """m_t: the power-heuristic weight of the technique that made a path's last segment (Veach 1997, Eq. 9.13).

    ``end_nee`` = 1: the segment came from next-event estimation (light sampling, density
    ``light_pdf``), 0: from BSDF sampling (``bsdf_pdf``); both densities in solid angle at the
    vertex. A delta light or a delta lobe has no competing technique: weight 1. The path tracer
    weights its two estimates with this, and path reuse keeps m_t inside a path's integrand (a
    shift keeps the label, so p̂ = luminance(m_t f) in every domain).
    """
    if end_nee != 0:
        if light_delta != 0:
            return 1.0
        return power_heuristic(light_pdf, bsdf_pdf)
    if bsdf_delta != 0:
        return 1.0
    return power_heuristic(bsdf_pdf, light_pdf)
