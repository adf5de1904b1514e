"""Specular manifold sampling (SMS): Newton walks, Bernoulli-trial UCWs, trust regions, priors, manifold shifts.

A specular chain between a shading point and a light vertex is fixed by a
2D seed ``u`` in the periodic primary sample space U = [0, 1)² (seed 003,
Sec. 3.1): a *manifold walk* — Newton's method on a constraint C(u) = 0 —
carries the seed to an admissible solution u*. Solutions are discrete, so a
sample's "pdf" is the probability P(u*) that a random seed converges to it,
the area of its *convergence basin* (Eq. 2)::

    P(u*) = ∫_U p(u) P(u* | u) du,        P(u* | u) ∈ {0, 1}.

P is unknown, but its reciprocal has an unbiased estimate by **Bernoulli
trials** (Booth 2007; Zeltner et al. 2020): draw fresh seeds until one walks
to the same u*; the number K of seeds drawn is geometric with E[K] = 1/P(u*),
so ``W = K`` is an unbiased contribution weight (UCW) and ``f(u*) · W`` an
unbiased estimate of Σ_k f(u*_k) (Eq. 1). One sample costs 1 + Σ_k P_k/P_k
= 1 + K_solutions walks on average (Eq. 3). Capping K at ``max_trials``
loses energy: E[min(K, cap)] = (1 − (1 − P)^cap)/P < 1/P.

**Trust regions** (Sec. 3.3). U is cut into N × N tiles; a walk seeded at u
may only move inside R(u), the 3 × 3 tiles around u's tile (periodic), and
stops (fails) when it steps out. A seed can then reach u* only from the
*conditional sample space* C(u*) = R(u*), and (Eq. 4–5)::

    P'(u*) = ∫_{C(u*)} p(u) P_C(u* | u) du
           = P(C) ∫_{C} p(u)/P(C) · P_C(u* | u) du,   P(C) = ∫_C p(u) du.

P(C) is known in closed form, and Bernoulli trials drawn *inside* C from
p/P(C) estimate only the remaining reciprocal: ``W = K / P(C)``, with
E[K] = P(C)/P'(u*) trials — fewer than SMS's 1/P (Eq. 6).

**Priors** (Sec. 4.1). Presampled unrestricted walks of nearby pixels mark
the tiles I that held solutions; seeds are then drawn from the mixture
(Eq. 7)::

    p(u) = α p_I(u) + (1 − α) p_U(u),   p_I uniform on the tiles of I,

whose mass in C is (Eq. 8, M = 3 tiles per side of C)::

    P(C) = α #(I ∩ C)/#(I) + (1 − α) M²/N²,

and Bernoulli seeds in C come from I ∩ C with probability (Eq. 9)::

    α' = α #(I ∩ C)/#(I) / P(C),   else uniformly from C.

The (1 − α) p_U term keeps every solution reachable: the estimator stays
unbiased for any I. With I empty the mixture is p_U (α is set to 0).

**Manifold shift** (Sec. 5.2–5.3). ReSTIR reuses a neighbour's solution x
by a walk in the current pixel seeded at x (at most 5 Newton iterations, no
trust region); the shift is defined only if the walk converges to y *and*
the walk back from y in the neighbour returns x (a partial bijection between
the two discrete solution sets). Solutions are points of a counting measure,
so the Jacobian is 1 (delta BSDFs, Sec. 5.2); the resampling weight is
seed 003's Eq. 10 with |∂T/∂x| = 1 and W_Y follows Eq. 11.

**Using it.** The functions that need the constraint are built by
:func:`make_manifold_sampler` from two Warp functions
``constraint(spec, view, u) -> vec2`` and ``constraint_jacobian(spec, view, u)
-> mat22`` (``view`` names the pixel/frame whose specular chain is solved);
everything else (tiles, Eq. 5–9 and the UCW) is plain ``@wp.func``. The toy
``sms-toy`` and a scene-layer caustics renderer call the same record.

=======================  ==============================================
Newton solver            ≤ 20 iterations, |C| < 1e-5 converged (SMS)
same solution            |∂C/∂u (b − a)| < 1e-4 and |b − a| < 1e-2 (Newton's
                         own uncertainty, not a fixed distance in U)
manifold shift           ≤ 5 iterations each way, Jacobian 1
=======================  ==============================================

References: P. Hong et al., "Sample Space Partitioning and Spatiotemporal
Resampling for Specular Manifold Sampling", SIGGRAPH Asia 2025 (seed 003);
T. Zeltner, I. Georgiev, W. Jakob, "Specular Manifold Sampling", SIGGRAPH
2020; W. Jakob, S. Marschner, "Manifold Exploration", SIGGRAPH 2012;
T. E. Booth, "Unbiased Monte Carlo estimation of the reciprocal of an
integral", NSE 156 (2007).
"""

import dataclasses
from typing import Any

import warp as wp

from grisx.theory.mis import pairwise_mis_canonical_term, pairwise_mis_neighbor, target_from
from grisx.theory.random import random_subkey, random_uniform
from grisx.theory.reservoir import Reservoir, confidence_capped, reservoir_empty, reservoir_finalize, reservoir_merge, reservoir_update

# grisx never differentiates through its kernels: skip adjoint code (halves compile time)
wp.set_module_options({"enable_backward": False})

__all__ = [
    "NEWTON_MAX_ITERATIONS",
    "NEWTON_THRESHOLD",
    "SOLUTION_THRESHOLD",
    "SOLUTION_RADIUS",
    "SHIFT_MAX_ITERATIONS",
    "TRUST_REGION_TILES",
    "UNBOUNDED_TRIALS",
    "PRIOR_ALPHA",
    "ManifoldWalk",
    "BernoulliTrials",
    "BernoulliTrial",
    "ConditionalSpace",
    "conditional_space",
    "SMSSample",
    "ManifoldShift",
    "ManifoldReuse",
    "ReuseShifts",
    "ReuseNeighbor",
    "reuse_neighbor",
    "SeedSpace",
    "ManifoldSampler",
    "make_manifold_sampler",
    "ManifoldLinearization",
    "wrap_unit",
    "periodic_distance",
    "periodic_delta",
    "same_solution",
    "tile_of",
    "tile_offset",
    "in_region",
    "seed_space",
    "seed_pdf",
    "sample_seed",
    "prior_add_tile",
    "prior_count_in_region",
    "prior_contains",
    "pair_pmf",
    "conditional_probability",
    "conditional_alpha",
    "sample_conditional_seed",
    "bernoulli_ucw",
    "trial_cap",
]

NEWTON_MAX_ITERATIONS = wp.constant(20)
NEWTON_THRESHOLD = wp.constant(1.0e-5)
#: two converged walks name one solution when ∂C/∂u maps their difference below this (C's units, 10× Newton's)
SOLUTION_THRESHOLD = wp.constant(1.0e-4)
#: ... and they lie this close in U (a guard along a near-null direction of ∂C/∂u)
SOLUTION_RADIUS = wp.constant(1.0e-2)
SHIFT_MAX_ITERATIONS = wp.constant(5)
#: M: a trust region / conditional sample space is M × M tiles (seed 003 uses 3 × 3)
TRUST_REGION_TILES = wp.constant(3)
#: the safety bound of "unbounded" Bernoulli trials: (1 − P)^(2^22) is negligible for P > 1e-5
UNBOUNDED_TRIALS = wp.constant(1 << 22)
#: α of Eq. 7 used in seed 003's results
PRIOR_ALPHA = 0.8
_SINGULAR = wp.constant(1.0e-12)


# ---- records -------------------------------------------------------------------------


@wp.struct
class ManifoldLinearization:
    """C(u) and ∂C/∂u: what one walk step reads (the Jacobian also names a converged solution)."""

    c: wp.vec2
    jacobian: wp.mat22


@wp.struct
class ManifoldWalk:
    """Result of one Newton walk: where it ended, whether |C| < threshold there, steps taken, ∂C/∂u there
    (when converged: what :func:`same_solution` measures a difference with)."""

    u: wp.vec2
    converged: wp.bool
    iterations: int
    jacobian: wp.mat22


@wp.struct
class BernoulliTrials:
    """Bernoulli trials for one solution: trial count K, their Newton steps, whether K hit the cap, W."""

    trials: int
    newton: int
    capped: wp.bool
    ucw: float


@wp.struct
class BernoulliTrial:
    """Bernoulli trial t of one solution: did its fresh seed walk to u*, and that walk's Newton steps."""

    hit: wp.bool
    newton: int


@wp.struct
class ConditionalSpace:
    """Where a solution's Bernoulli seeds come from: the centre tile of C(u*), P(C) (Eq. 8) and α' (Eq. 9)."""

    center: int
    p_c: float
    alpha_prime: float


@wp.struct
class SMSSample:
    """One SMS sample: solution u*, its UCW W (0 when no solution was found) and its cost; ``trial_key`` is
    the key its Bernoulli trials draw seeds from (trial t from counters 4t … 4t + 3), so trials past a cap
    can go on elsewhere (:meth:`ManifoldSampler.trial`)."""

    u: wp.vec2
    found: wp.bool
    ucw: float
    newton_sample: int
    trials: int
    newton_bernoulli: int
    capped: wp.bool
    jacobian: wp.mat22
    trial_key: wp.uint32


@wp.struct
class ManifoldShift:
    """A manifold shift: shifted solution, Jacobian (1: counting measure), validity, Newton steps spent."""

    u: wp.vec2
    jacobian: float
    valid: wp.bool
    iterations: int


@wp.struct
class ReuseNeighbor:
    """A neighbour's reservoir for manifold-shift GRIS: its sample y solves problem ``view``; ``to_here``
    is the view of y's problem at the canonical pixel (where T_i takes y), ``from_here`` the view of the
    canonical sample's problem in the neighbour's domain (for m_c); ``present`` = 0: no neighbour."""

    r: Reservoir
    y: wp.vec2
    view: int
    to_here: int
    from_here: int
    present: int


@wp.struct
class ManifoldReuse:
    """Result of one reuse pass: the merged reservoir, its sample and the shifts' cost."""

    r: Reservoir
    y: wp.vec2
    source: int  # where y came from: −1 the canonical sample, 0 or 1 that neighbour
    walks: int
    newton: int
    valid: int


@wp.struct
class ReuseShifts:
    """A reuse pass's manifold shifts, traced apart from its merge (slot n = 0, 1 of :class:`ReuseNeighbor`):
    ``carried`` p̂_{←n}(y_c), the canonical sample carried into neighbour n's domain (0 where the shift
    fails), and neighbour n's sample shifted here: ``u``, ``valid``, its target ``p_hat`` and Jacobian; the
    walks, their Newton steps and the shifts that succeeded."""

    carried: wp.vec2
    u0: wp.vec2
    u1: wp.vec2
    valid: wp.vec2i
    p_hat: wp.vec2
    jacobian: wp.vec2
    walks: int
    newton: int
    succeeded: int


@wp.struct
class SeedSpace:
    """How seeds are drawn: N × N tiles (0: unpartitioned SMS), prior weight α and #(I)."""

    tiles: int
    alpha: float
    prior_count: int


# ---- the periodic sample space and its tiles ---------------------------------------------


@wp.func
def wrap_unit(u: wp.vec2) -> wp.vec2:
    """u mod 1 per coordinate, in [0, 1) even where float32 rounds u − floor(u) up to 1."""
    x = u[0] - wp.floor(u[0])
    y = u[1] - wp.floor(u[1])
    if x >= 1.0:
        x = 0.0
    if y >= 1.0:
        y = 0.0
    return wp.vec2(x, y)


@wp.func
def periodic_delta(a: wp.vec2, b: wp.vec2) -> wp.vec2:
    """The shortest b − a on the unit torus (each coordinate in [−½, ½])."""
    d = b - a
    return d - wp.vec2(wp.round(d[0]), wp.round(d[1]))


@wp.func
def periodic_distance(a: wp.vec2, b: wp.vec2) -> float:
    """Euclidean distance on the unit torus."""
    return wp.length(periodic_delta(a, b))


@wp.func
def same_solution(a: wp.vec2, b: wp.vec2, jacobian: wp.mat22) -> wp.bool:
    """Do two converged walks name the same solution? ``jacobian`` is ∂C/∂u at ``a``.

    A walk stops anywhere |C| < NEWTON_THRESHOLD, so the ends of walks to one solution scatter
    over an ellipse of U whose size is Newton's, |∂C/∂u δu| ≲ threshold: tiny where the chain is
    well conditioned, ~10⁻³ of U near a fold, where caustics are brightest. A fixed distance in U
    splits one solution there (K counts trials that did reach it: W too large) or merges two.
    The difference is therefore measured where Newton measures it, in C: |∂C/∂u (b − a)| below
    SOLUTION_THRESHOLD (10× the walk's own tolerance), and within SOLUTION_RADIUS in U."""
    d = periodic_delta(a, b)
    if wp.length(d) >= SOLUTION_RADIUS:
        return False
    return wp.length(jacobian @ d) < SOLUTION_THRESHOLD


@wp.func
def tile_of(u: wp.vec2, tiles: int) -> int:
    """Index ty·N + tx of the tile holding u (N = ``tiles`` >= 1)."""
    tx = wp.min(int(u[0] * float(tiles)), tiles - 1)
    ty = wp.min(int(u[1] * float(tiles)), tiles - 1)
    return ty * tiles + tx


@wp.func
def _axis_offset(a: int, b: int, tiles: int) -> int:
    """Periodic tile distance along one axis."""
    d = wp.abs(a - b)
    return wp.min(d, tiles - d)


@wp.func
def tile_offset(tile: int, center: int, tiles: int) -> int:
    """Chebyshev distance between two tiles on the periodic N × N grid."""
    return wp.max(_axis_offset(tile % tiles, center % tiles, tiles), _axis_offset(tile // tiles, center // tiles, tiles))


@wp.func
def in_region(tile: int, center: int, tiles: int) -> wp.bool:
    """Is ``tile`` in the 3 × 3 region R = C around tile ``center`` (Sec. 3.3)? Always true for N = 0."""
    if tiles <= 0:
        return True
    return tile_offset(tile, center, tiles) <= TRUST_REGION_TILES // 2


@wp.func
def _uniform_in_tile(tile: int, tiles: int, r0: float, r1: float) -> wp.vec2:
    inv = 1.0 / float(tiles)
    return wrap_unit(wp.vec2((float(tile % tiles) + r0) * inv, (float(tile // tiles) + r1) * inv))


@wp.func
def _region_tile(center: int, j: int, tiles: int) -> int:
    """The j-th (0 … M²−1) tile of the region around ``center``."""
    half = TRUST_REGION_TILES // 2
    dx = j % TRUST_REGION_TILES - half
    dy = j // TRUST_REGION_TILES - half
    tx = (center % tiles + dx + tiles) % tiles
    ty = (center // tiles + dy + tiles) % tiles
    return ty * tiles + tx


@wp.func
def _pick(count: int, r: float) -> int:
    return wp.min(int(r * float(count)), count - 1)


# ---- the seed pdf (Eq. 7) and its prior tiles I --------------------------------------------


@wp.func
def seed_space(tiles: int, alpha: float, prior_count: int) -> SeedSpace:
    """Seed distribution of Eq. 7; without prior tiles (#I = 0) or tiles the mixture is p_U (α = 0)."""
    s = SeedSpace()
    s.tiles = tiles
    s.prior_count = prior_count
    s.alpha = alpha
    if prior_count <= 0 or tiles <= 0:
        s.alpha = 0.0
        s.prior_count = 0
    return s


@wp.func
def prior_add_tile(prior: wp.array(dtype=int), count: int, tile: int) -> int:
    """Add ``tile`` to the set I held in ``prior[0:count]`` (no duplicates, room permitting); new #(I)."""
    for j in range(count):
        if prior[j] == tile:
            return count
    if count < prior.shape[0]:
        prior[count] = tile
        return count + 1
    return count


@wp.func
def prior_contains(prior: wp.array(dtype=int), count: int, tile: int) -> wp.bool:
    """Is ``tile`` in the set I held in ``prior[0:count]``?"""
    for j in range(count):
        if prior[j] == tile:
            return True
    return False


@wp.func
def prior_count_in_region(space: SeedSpace, prior: wp.array(dtype=int), center: int) -> int:
    """#(I ∩ C(center))."""
    n = int(0)
    for j in range(space.prior_count):
        if in_region(prior[j], center, space.tiles):
            n += 1
    return n


@wp.func
def seed_pdf(space: SeedSpace, prior: wp.array(dtype=int), u: wp.vec2) -> float:
    """p(u) = α p_I(u) + (1 − α) p_U(u) (seed 003, Eq. 7), p_I = N²/#(I) on the tiles of I."""
    p = 1.0 - space.alpha
    if space.alpha > 0.0 and prior_contains(prior, space.prior_count, tile_of(u, space.tiles)):
        p += space.alpha * float(space.tiles * space.tiles) / float(space.prior_count)
    return p


@wp.func
def sample_seed(space: SeedSpace, prior: wp.array(dtype=int), key: wp.uint32, counter: int) -> wp.vec2:
    """Draw u ~ p (Eq. 7) from uniforms ``counter`` … ``counter + 3`` of ``key``."""
    r0 = random_uniform(key, counter + 1)
    r1 = random_uniform(key, counter + 2)
    if space.alpha > 0.0 and random_uniform(key, counter) < space.alpha:
        tile = prior[_pick(space.prior_count, random_uniform(key, counter + 3))]
        return _uniform_in_tile(tile, space.tiles, r0, r1)
    return wrap_unit(wp.vec2(r0, r1))


@wp.func
def pair_pmf(alpha: float, in_prior: wp.bool, prior_count: int, scene_pmf: float) -> float:
    """P(pair) = α [pair ∈ I]/#(I) + (1 − α) p_scene(pair) (seed 003, Sec. 4.2): a light–object pair drawn from
    the block's prior pairs with probability α, else from the whole scene; α = 0 when I is empty."""
    p = scene_pmf
    if alpha > 0.0 and prior_count > 0:
        p = (1.0 - alpha) * scene_pmf
        if in_prior:
            p += alpha / float(prior_count)
    return p


# ---- the conditional sample space C(u*) (Eq. 4–6, 8, 9) ------------------------------------


@wp.func
def conditional_probability(space: SeedSpace, prior: wp.array(dtype=int), center: int) -> float:
    """P(C) = α #(I∩C)/#(I) + (1 − α) M²/N² (seed 003, Eq. 8); 1 when unpartitioned (C = U)."""
    if space.tiles <= 0:
        return 1.0
    m2 = float(TRUST_REGION_TILES * TRUST_REGION_TILES)
    p = (1.0 - space.alpha) * m2 / float(space.tiles * space.tiles)
    if space.alpha > 0.0:
        p += space.alpha * float(prior_count_in_region(space, prior, center)) / float(space.prior_count)
    return p


@wp.func
def conditional_alpha(space: SeedSpace, prior: wp.array(dtype=int), center: int, p_c: float) -> float:
    """α' = α #(I∩C)/#(I) / P(C) (seed 003, Eq. 9): the chance a Bernoulli seed comes from I ∩ C."""
    if space.alpha <= 0.0 or space.tiles <= 0 or p_c <= 0.0:
        return 0.0
    return space.alpha * float(prior_count_in_region(space, prior, center)) / float(space.prior_count) / p_c


@wp.func
def conditional_space(space: SeedSpace, prior: wp.array(dtype=int), u_star: wp.vec2) -> ConditionalSpace:
    """C(u*) for solution u*: its centre tile, P(C) (Eq. 8) and α' (Eq. 9)."""
    c = ConditionalSpace()
    c.center = int(0)
    if space.tiles > 0:
        c.center = tile_of(u_star, space.tiles)
    c.p_c = conditional_probability(space, prior, c.center)
    c.alpha_prime = conditional_alpha(space, prior, c.center, c.p_c)
    return c


@wp.func
def sample_conditional_seed(
    space: SeedSpace, prior: wp.array(dtype=int), center: int, alpha_prime: float, key: wp.uint32, counter: int
) -> wp.vec2:
    """Draw u ~ p/P(C) restricted to C(center): uniform in I ∩ C w.p. α', else uniform in C (Eq. 9)."""
    if space.tiles <= 0:
        return sample_seed(space, prior, key, counter)
    r0 = random_uniform(key, counter + 1)
    r1 = random_uniform(key, counter + 2)
    r2 = random_uniform(key, counter + 3)
    if alpha_prime > 0.0 and random_uniform(key, counter) < alpha_prime:
        pick = _pick(prior_count_in_region(space, prior, center), r2)
        for j in range(space.prior_count):
            if in_region(prior[j], center, space.tiles):
                if pick == 0:
                    return _uniform_in_tile(prior[j], space.tiles, r0, r1)
                pick -= 1
    m2 = TRUST_REGION_TILES * TRUST_REGION_TILES
    return _uniform_in_tile(_region_tile(center, _pick(m2, r2), space.tiles), space.tiles, r0, r1)


@wp.func
def bernoulli_ucw(trials: int, p_c: float) -> float:
    """W = K / P(C) (seed 003, Eq. 1–2 and 5): E[K] = P(C)/P'(u*), so E[W] = 1/P'(u*)."""
    if p_c > 0.0:
        return float(trials) / p_c
    return 0.0


@wp.func
def trial_cap(max_trials: int) -> int:
    """The Bernoulli-trial budget: ``max_trials``, or the safety bound for 0 (= unbounded)."""
    if max_trials > 0:
        return max_trials
    return UNBOUNDED_TRIALS


# ---- functions built over a problem's constraint ----------------------------------------


@wp.func
def reuse_neighbor(r: Reservoir, y: wp.vec2, view: int, to_here: int, from_here: int, present: int) -> ReuseNeighbor:
    """A :class:`ReuseNeighbor` record (``present`` = 0 for an absent neighbour; its other fields are then unread)."""
    n = ReuseNeighbor()
    n.r = r
    n.y = y
    n.view = view
    n.to_here = to_here
    n.from_here = from_here
    n.present = present
    return n


@dataclasses.dataclass(frozen=True)
class ManifoldSampler:
    """SMS over one constraint: the Warp functions :func:`make_manifold_sampler` builds.

    ``walk(spec, view, u0, tiles, max_iterations) -> ManifoldWalk``
        Newton's method on C(u) = 0 from seed u0; with ``tiles`` > 0 the walk
        stops (unconverged) when it leaves R(u0) (Sec. 3.3).
    ``bernoulli(spec, view, u_star, jacobian_star, space, prior, key, max_trials) -> BernoulliTrials``
        fresh seeds from p/P(C(u*)) until one walks to u* (∂C/∂u there: :func:`same_solution`):
        W = K / P(C) (Eq. 5).
    ``trial(spec, view, u_star, jacobian_star, space, prior, cond, key, t) -> BernoulliTrial``
        Bernoulli trial number t alone (what ``bernoulli`` runs in turn): trials are independent, so
        K = 1 + the first t that hits can be found by running many t at once.
    ``sample(spec, view, space, prior, key, max_trials) -> SMSSample``
        seed u ~ p (Eq. 7), walk with trust region, Bernoulli UCW if it converged.
    ``shift(spec, src_view, dst_view, x) -> ManifoldShift``
        manifold shift of solution x of ``src_view`` into ``dst_view`` with the
        back-walk invertibility check, ≤ 5 iterations each (Sec. 5.2–5.3).
    ``reuse(spec, r_c, y_c, view_c, n0, n1, cap, key) -> ManifoldReuse``
        (with a ``target``) GRIS of the canonical reservoir with ≤ 2 :class:`ReuseNeighbor`
        records through manifold shifts and pairwise MIS (Eq. 10–11); confidence capped.
        It is ``reuse_merge(r_c, y_c, n0, n1, shifts, cap, key)`` over the shifts that
        ``reuse_carry(spec, r_c, y_c, view_c, nb, n, shifts)`` (y_c into neighbour n's domain) and
        ``reuse_shift(spec, nb, n, shifts)`` (neighbour n's sample here) record in a
        :class:`ReuseShifts`, so a renderer can trace the shifts in passes of their own.
    """

    walk: Any
    bernoulli: Any
    sample: Any
    shift: Any
    trial: Any
    reuse: Any = None
    reuse_carry: Any = None
    reuse_shift: Any = None
    reuse_merge: Any = None


def make_manifold_sampler(
    spec_type: Any, constraint: Any, constraint_jacobian: Any, target: Any = None, linearize: Any = None
) -> ManifoldSampler:
    """Build the SMS functions for ``constraint(spec, view, u) -> vec2`` and its ∂C/∂u ``-> mat22``;
    with ``target(spec, view, u) -> float`` (p̂ of solution u of a view, Eq. 13) also ``reuse``.
    ``linearize(spec, view, u) -> ManifoldLinearization`` gives both at once where a problem can (a chain
    shot with its ray differentials: one shot per Newton step); by default the two functions in turn."""

    if linearize is None:

        @wp.func
        def linearize(spec: spec_type, view: int, u: wp.vec2) -> ManifoldLinearization:
            out = ManifoldLinearization()
            out.c = constraint(spec, view, u)
            out.jacobian = constraint_jacobian(spec, view, u)
            return out

    @wp.func
    def walk(spec: spec_type, view: int, u0: wp.vec2, tiles: int, max_iterations: int) -> ManifoldWalk:
        out = ManifoldWalk()
        out.u = u0
        out.converged = False
        out.iterations = 0
        center = int(0)
        if tiles > 0:
            center = tile_of(u0, tiles)
        u = u0
        for it in range(max_iterations + 1):
            lin = linearize(spec, view, u)
            c = lin.c
            if wp.length(c) < NEWTON_THRESHOLD:
                out.u = u
                out.converged = True
                out.jacobian = lin.jacobian  # names the solution (same_solution)
                return out
            if it == max_iterations:
                break
            jac = lin.jacobian
            if wp.abs(wp.determinant(jac)) < _SINGULAR:
                break
            u = wrap_unit(u - wp.inverse(jac) @ c)  # Newton step on the torus
            out.iterations = out.iterations + 1
            if tiles > 0 and not in_region(tile_of(u, tiles), center, tiles):
                break  # the walk left its trust region R(u0): stop (Sec. 3.3)
        out.u = u
        return out

    @wp.func
    def trial(
        spec: spec_type,
        view: int,
        u_star: wp.vec2,
        jacobian_star: wp.mat22,
        space: SeedSpace,
        prior: wp.array(dtype=int),
        cond: ConditionalSpace,
        key: wp.uint32,
        t: int,
    ) -> BernoulliTrial:
        # trial t: a fresh seed from p/P(C) (uniforms 4t … 4t + 3 of key), walked inside C (Eq. 5, 9)
        out = BernoulliTrial()
        u = sample_conditional_seed(space, prior, cond.center, cond.alpha_prime, key, 4 * t)
        w = walk(spec, view, u, space.tiles, NEWTON_MAX_ITERATIONS)
        out.newton = w.iterations
        out.hit = w.converged and same_solution(u_star, w.u, jacobian_star)
        return out

    @wp.func
    def bernoulli(
        spec: spec_type,
        view: int,
        u_star: wp.vec2,
        jacobian_star: wp.mat22,
        space: SeedSpace,
        prior: wp.array(dtype=int),
        key: wp.uint32,
        max_trials: int,
    ) -> BernoulliTrials:
        out = BernoulliTrials()
        out.trials = 0
        out.newton = 0
        out.capped = True
        cond = conditional_space(space, prior, u_star)  # Eq. 8, 9
        cap = trial_cap(max_trials)
        while out.trials < cap:
            b = trial(spec, view, u_star, jacobian_star, space, prior, cond, key, out.trials)
            out.trials = out.trials + 1
            out.newton = out.newton + b.newton
            if b.hit:
                out.capped = False
                break
        out.ucw = bernoulli_ucw(out.trials, cond.p_c)  # Eq. 5: E[W] = 1/P'(u*)
        return out

    @wp.func
    def sample(
        spec: spec_type, view: int, space: SeedSpace, prior: wp.array(dtype=int), key: wp.uint32, max_trials: int
    ) -> SMSSample:
        out = SMSSample()
        out.found = False
        out.ucw = 0.0
        out.trials = 0
        out.newton_bernoulli = 0
        out.capped = False
        # ---- main sampling phase: one seed, one walk (Sec. 3.2) ----
        w = walk(spec, view, sample_seed(space, prior, key, 0), space.tiles, NEWTON_MAX_ITERATIONS)
        out.u = w.u
        out.newton_sample = w.iterations
        out.jacobian = w.jacobian
        out.trial_key = random_subkey(key, 1)
        if w.converged:
            # ---- inverse probability by Bernoulli trials (Eq. 2, 5) ----
            b = bernoulli(spec, view, w.u, w.jacobian, space, prior, out.trial_key, max_trials)
            out.found = True
            out.ucw = b.ucw
            out.trials = b.trials
            out.newton_bernoulli = b.newton
            out.capped = b.capped
        return out

    @wp.func
    def shift(spec: spec_type, src_view: int, dst_view: int, x: wp.vec2) -> ManifoldShift:
        out = ManifoldShift()
        out.u = x
        out.jacobian = 0.0
        out.valid = False
        out.iterations = 0
        # leg 0: T(x), a walk seeded at x in the new view; leg 1: T⁻¹(T(x)) must give x back. One walk in a loop
        # Warp does not unroll (each walk inlines the constraint's whole chain shot)
        legs = int(2)
        there = wp.vec2(0.0, 0.0)
        for leg in range(legs):
            view = dst_view
            seed = x
            if leg == 1:
                view = src_view
                seed = there
            w = walk(spec, view, seed, 0, SHIFT_MAX_ITERATIONS)
            out.iterations = out.iterations + w.iterations
            if not w.converged:
                return out
            if leg == 0:
                there = w.u
            elif same_solution(w.u, x, w.jacobian):
                out.u = there
                out.jacobian = 1.0  # discrete solutions: no density change (Sec. 5.2)
                out.valid = True
        return out

    if target is None:
        return ManifoldSampler(walk=walk, bernoulli=bernoulli, sample=sample, shift=shift, trial=trial)

    @wp.func
    def _pick_neighbor(n: int, n0: ReuseNeighbor, n1: ReuseNeighbor) -> ReuseNeighbor:
        if n == 0:
            return n0
        return n1

    @wp.func
    def reuse_carry(spec: spec_type, r_c: Reservoir, y_c: wp.vec2, view_c: int, nb: ReuseNeighbor, n: int, shifts: ReuseShifts) -> ReuseShifts:
        # p̂_{←n}(y_c): the canonical sample shifted into neighbour n's domain, for m_c (0 where the shift fails)
        out = shifts
        carried = float(0.0)
        if nb.present != 0 and r_c.ucw > 0.0:
            s = shift(spec, view_c, nb.from_here, y_c)
            out.walks += 2
            out.newton += s.iterations
            if s.valid:
                out.succeeded += 1
                carried = target_from(target(spec, nb.from_here, s.u), s.jacobian)
        out.carried[n] = carried
        return out

    @wp.func
    def reuse_shift(spec: spec_type, nb: ReuseNeighbor, n: int, shifts: ReuseShifts) -> ReuseShifts:
        # T_n(y_n): neighbour n's sample shifted here (seed 003, Sec. 5.2), its target and Jacobian
        out = shifts
        out.valid[n] = 0
        if nb.present != 0 and nb.r.ucw > 0.0:
            s = shift(spec, nb.view, nb.to_here, nb.y)
            out.walks += 2
            out.newton += s.iterations
            if s.valid:
                out.succeeded += 1
                out.valid[n] = 1
                out.p_hat[n] = target(spec, nb.to_here, s.u)
                out.jacobian[n] = s.jacobian
                if n == 0:
                    out.u0 = s.u
                else:
                    out.u1 = s.u
        return out

    @wp.func
    def _shifted(shifts: ReuseShifts, n: int) -> wp.vec2:
        if n == 0:
            return shifts.u0
        return shifts.u1

    @wp.func
    def reuse_merge(
        r_c: Reservoir, y_c: wp.vec2, n0: ReuseNeighbor, n1: ReuseNeighbor, shifts: ReuseShifts, cap: float, key: wp.uint32
    ) -> ManifoldReuse:
        # Pairwise MIS (seed 003, Sec. 5.2) over the shifts already traced
        out = ManifoldReuse()
        out.walks = shifts.walks
        out.newton = shifts.newton
        out.valid = shifts.succeeded
        slots = int(2)
        k = int(0)
        total = r_c.confidence
        for n in range(slots):
            nb = _pick_neighbor(n, n0, n1)
            if nb.present != 0:
                k += 1
                total += nb.r.confidence
        # canonical MIS weight m_c(y_c) = Σ_i pair terms (with p̂_{←i}(y_c): y_c shifted into domain i)
        m_c = float(0.0)
        if k == 0:
            m_c = 1.0
        for n in range(slots):
            nb = _pick_neighbor(n, n0, n1)
            if nb.present != 0:
                m_c += pairwise_mis_canonical_term(nb.r.confidence, shifts.carried[n], r_c.confidence, r_c.target, k, total)
        r = reservoir_merge(reservoir_empty(), r_c, m_c, r_c.target, 1.0, random_uniform(key, 0))
        y = y_c
        out.source = -1
        for n in range(slots):
            nb = _pick_neighbor(n, n0, n1)
            if nb.present != 0:
                if shifts.valid[n] != 0:
                    p_hat = shifts.p_hat[n]
                    jacobian = shifts.jacobian[n]
                    # p̂_{←i}(T(x)) = p̂_i(x) |∂T⁻¹/∂y| with Jacobian 1
                    m = pairwise_mis_neighbor(nb.r.confidence, target_from(nb.r.target, jacobian), r_c.confidence, p_hat, k, total)
                    r = reservoir_merge(r, nb.r, m, p_hat, jacobian, random_uniform(key, 1 + n))  # Eq. 10
                    if r.selected:
                        y = _shifted(shifts, n)
                        out.source = n
                else:
                    r = reservoir_update(r, 0.0, 0.0, nb.r.confidence, 0.0)  # confidence stays deterministic
        r = reservoir_finalize(r)  # Eq. 11
        r.confidence = confidence_capped(r.confidence, cap)
        out.r = r
        out.y = y
        return out

    @wp.func
    def reuse(
        spec: spec_type, r_c: Reservoir, y_c: wp.vec2, view_c: int, n0: ReuseNeighbor, n1: ReuseNeighbor, cap: float, key: wp.uint32
    ) -> ManifoldReuse:
        # each neighbour costs up to 4 manifold walks: the canonical sample shifted there and back, its sample
        # shifted here and back. A loop bound Warp cannot unroll: each shift (two walks, each a chain shot per
        # Newton step) is compiled once per loop, not once per neighbour
        shifts = ReuseShifts()
        slots = int(2)
        for n in range(slots):
            shifts = reuse_carry(spec, r_c, y_c, view_c, _pick_neighbor(n, n0, n1), n, shifts)
        for n in range(slots):
            shifts = reuse_shift(spec, _pick_neighbor(n, n0, n1), n, shifts)
        return reuse_merge(r_c, y_c, n0, n1, shifts, cap, key)

    return ManifoldSampler(walk=walk, bernoulli=bernoulli, sample=sample, shift=shift, trial=trial, reuse=reuse,
                           reuse_carry=reuse_carry, reuse_shift=reuse_shift, reuse_merge=reuse_merge)
