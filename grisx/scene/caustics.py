"""Caustic chains on real geometry: the specular constraint that seed 003's manifold walks solve in a scene.

A *caustic chain* joins a shading point x₁ (the first non-delta vertex of a
camera path) to a point x_n on an area emitter (or a direction of the
environment) through k = 1 … ``chain_max``
delta vertices x₂ … x_{k+1} (seed 003, Sec. 3.1). It is fixed by a 2D seed
u ∈ U = [0, 1)² (the paper's primary sample space of x₂, here a *direction*
from x₁, as footnote 2 recommends, so the map is continuous):

* **seed space** of a caster object O seen from x₁: the square of half-size
  s on the plane through O's bounding-sphere centre c, perpendicular to the
  axis a = (c − x₁)/D, D = |c − x₁|, that covers the sphere's silhouette
  (s = r D / √(D² − r²)), but never wider than s = 2r, reached at D = 2r/√3: near
  and inside the sphere the square covers only part of O. The bound keeps s
  continuous in x₁ — as D → r the silhouette's square grows without bound, every
  solution's basin shrinks with it, and SMS's image showed a dark ring on the
  floor where O's bounding sphere meets it. The seed is the direction ω₁(u) from x₁ to the square's
  point c + s(2u₀ − 1) t + s(2u₁ − 1) b (a gnomonic map), whose density is
  |∂ω₁/∂u| = (2s)² D / ρ³, ρ the distance to that point. :func:`seed_direction`,
  :func:`invert_seed_direction` are the sampling pair;
* **shooting** (:func:`make_caustics`' ``shoot``): a ray from x₁ along ω₁(u)
  must hit O on a delta surface; from there the chain follows the *canonical
  lobe* of every delta vertex — refraction at a dielectric, reflection at a
  conductor (the BSDF's own ``sample`` with u_lobe = 1, so the throughput
  Π weight·pdf = Π (1 − F) η² T or Π R F_c is the path tracer's expected one)
  — re-projected onto the mesh by a ray cast each time, until a non-delta
  surface, an escaping ray or k = ``chain_max``; the last direction meets the
  plane of the emitter triangle of x_n at q(u);
* **the constraint** C(u) = q(u) − x_n in an orthonormal frame of that plane
  (world units): C = 0 exactly when the chain is admissible (every vertex obeys
  the law of reflection/refraction with the bumped shading normal and the last
  segment reaches x_n). For the **environment** x_n is a sampled direction ω_n
  and C(u) is the last direction's tangential part about ω_n (its antipode is
  refused), so |det ∂C/∂u| is per solid angle at ω_n. A vertex with total
  internal reflection has no canonical lobe: no chain;
* **∂C/∂u from the same shot** (ray differentials, Igehy 1999): the shot
  carries ∂/∂u₀ and ∂/∂u₁ of its point and direction — from the seed map,
  onto each vertex's tangent plane (:func:`transfer_differential`), turned by
  the law of reflection or refraction with the normal's own derivative
  (:func:`scatter_differential`; the normal's derivative is the analytic
  shape's Weingarten map, the interpolated mesh normal's through its
  barycentrics, and the procedural bump's through its height field's Hessian:
  :func:`~grisx.scene.scene.shading_normal_derivative`) — to the emitter
  plane. A Newton step is then *one* shot, and the geometry term below is
  exact. Where a normal is perturbed by something whose derivative is unknown
  (a normal map), ∂C/∂u falls back to central differences of four more shots
  (step 1e-3 in U; one-sided within a step of O's outline or of a chain-length
  change, so that no solution there is lost). The walks are
  :func:`grisx.theory.manifold.make_manifold_sampler`'s, given ``linearize``;
* **generalized geometry term** (Jakob & Marschner 2012): a change of variables
  from ω₁ to the area of x_n, |∂ω₁/∂A(x_n)| = |∂ω₁/∂u| / |det ∂C/∂u| — for one
  flat mirror exactly cos θ_n / (ℓ₁ + ℓ₂)² of the mirrored light — so a solution
  u* carries (Eq. 1, 13)

      f(x̂) = f_s(x₁, ω_o, ω₁) ⊙ Tr(chain) ⊙ L_e(x_n → x_{k+1}) · |∂ω₁/∂A(x_n)| · V(x_{k+1} ↔ x_n),

  and f(x̂) W / p_A(x_n) estimates the emitter integral of Eq. 12 over solutions
  (p per solid angle and |∂ω₁/∂ω_n| for the environment).

**Which paths a chain owns** (:func:`caustic_owned`): a camera path whose first
non-delta vertex is x₁, followed by 1 … ``chain_max`` delta vertices, each left
by its canonical lobe, the first on object O with ω₁ inside O's seed space from
x₁ and meeting O at |cos θ| ≥ ``GRAZING_COS`` (0.1), then a hit on an emitter
triangle or the escape to the environment. The grazing bound keeps what SMS claims
reachable: near O's silhouette ∂C/∂u is ill-conditioned, Newton steps leave O,
and a solution's basin has almost no measure (on a glass sphere's caustic one such
solution carried half the pixel and no walk of 65k seeds reached it), while the
ends of walks that do reach it scatter far in U. The
path tracer built with ``make_trace_path(kinds, caustic_chain=K)`` drops exactly
those emissions and SMS adds them, so the two together estimate the path
tracer's image. Non-canonical lobes (a dielectric's reflection), longer chains
and directions outside the seed square stay with the path tracer; point lights
are reached by neither through a delta chain.

Simplifications (stated, not hidden): delta casters only (no offset manifolds
for glossy casters, Sec. 5.3); the chain is shot from x₁ (a 2D Newton over
the seed, not a Newton over all vertices at once), which is the paper's 2D
sample-space view but converges less widely than a full manifold walk.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Iterable
from typing import Any

import numpy as np
import warp as wp

from grisx.device import launch
from grisx.scene.bsdf import make_bsdf
from grisx.scene.frame import frame_from_normal, to_local, to_world
from grisx.scene.material import MATERIAL_BUMPMAP, MATERIAL_DIELECTRIC, MATERIAL_NORMALMAP, Material
from grisx.scene.lights import make_lights
from grisx.scene.scene import (
    SceneData,
    SurfaceInteraction,
    make_surface,
    shadow_ray_along,
    shadow_ray_between,
    spawn_origin,
)
from grisx.theory.gris import luminance
from grisx.theory.manifold import ManifoldLinearization, ManifoldSampler, make_manifold_sampler, seed_space
from grisx.theory.random import random_key

wp.set_module_options({"enable_backward": False})

__all__ = [
    "CHAIN_MAX",
    "GRAZING_COS",
    "grazing",
    "JACOBIAN_STEP",
    "CausticSpec",
    "CausticChain",
    "SeedFrame",
    "SeedDirection",
    "seed_frame",
    "seed_direction",
    "invert_seed_direction",
    "caustic_owned",
    "canonical_lobe",
    "CausticFuncs",
    "make_caustics",
    "make_caustic_spec",
    "set_view",
    "solve_chains",
    "sms_estimates",
    "transfer_differential",
    "scatter_differential",
]

#: the longest chain a walk solves (2: a slab's two refractions)
CHAIN_MAX = 2
#: SMS owns a chain only where its ray from x₁ meets O at |cos θ| ≥ this (module docstring, "Which paths a chain owns")
GRAZING_COS = wp.constant(0.1)
#: central-difference step of ∂C/∂u in U
JACOBIAN_STEP = wp.constant(1.0e-3)
#: C(u) of a seed whose chain is not admissible at all (misses O, escapes, runs parallel to the light)
_INVALID = wp.constant(1.0e10)


# ---- records -------------------------------------------------------------------------


@wp.struct
class CausticSpec:
    """What the constraint reads: the scene, the chain length bound and, per *view*, x₁, O and x_n.

    A view is one (shading point, caster, emitter point) problem; renderers write its row before
    walking (a pixel's own problem, or a neighbour's sample moved to this pixel for a shift).
    """

    scene: SceneData
    chain_max: int
    max_depth: int  # the path tracer's: x₁'s depth + k + 2 segments at most (−1 unbounded)
    x1: wp.array(dtype=wp.vec3)  # shading point x₁
    x1_ng: wp.array(dtype=wp.vec3)  # its geometric normal (ray offsets)
    caster: wp.array(dtype=int)  # object O whose seed space U parametrizes x₂
    xn: wp.array(dtype=wp.vec3)  # the emitter point x_n (the direction ω_n for the environment)
    xn_n: wp.array(dtype=wp.vec3)  # the emitter triangle's normal at x_n
    # what f (Eq. 13) needs beyond the constraint
    x1_si: wp.array(dtype=SurfaceInteraction)  # x₁ (its material and shading frame)
    x1_wo: wp.array(dtype=wp.vec3)  # unit, x₁ → the previous path vertex
    x1_depth: wp.array(dtype=int)  # segments before the one that reached x₁
    light_tri: wp.array(dtype=int)  # the emitter triangle of x_n; −1: the environment, x_n a direction


@wp.struct
class SeedFrame:
    """The seed square of object O seen from x₁: centre c, axis a, tangents t, b, distance D, half-size s."""

    c: wp.vec3
    a: wp.vec3
    t: wp.vec3
    b: wp.vec3
    dist: float
    half: float
    valid: int


@wp.struct
class SeedDirection:
    """ω₁(u) and its density |∂ω₁/∂u| (solid angle per unit of U)."""

    d: wp.vec3
    jacobian: float
    dist: float  # ρ = |P(u) − x₁|, the distance to the square's point (∂ω₁/∂u = (I − ω₁ω₁ᵀ) ∂P/∂u / ρ)


@wp.struct
class CausticChain:
    """One shot chain: its k vertices' ends, directions, throughput and where it meets the emitter plane."""

    valid: int
    length: int  # k: delta vertices
    first: wp.vec3  # x₂
    last: wp.vec3  # x_{k+1}
    last_ng: wp.vec3
    d1: wp.vec3  # ω₁: x₁ → x₂
    d_out: wp.vec3  # leaving x_{k+1}
    throughput: wp.vec3  # Π weight · pdf of the canonical lobes
    seed_jacobian: float  # |∂ω₁/∂u|
    c: wp.vec2  # C(u) = q(u) − x_n in the emitter plane's frame
    dc: wp.mat22  # ∂C/∂u carried along the shot (ray differentials), when ``exact``
    exact: int  # 1: every vertex's normal has a known derivative (no bump), so ``dc`` is exact


@wp.func
def set_view(
    spec: CausticSpec, view: int, x1: SurfaceInteraction, wo: wp.vec3, x1_depth: int, caster: int, xn: wp.vec3, xn_n: wp.vec3, light_tri: int
):
    """Write problem row ``view``: shading point ``x1`` (seen from ``wo``, at depth ``x1_depth``), caster
    object, emitter point, its normal and triangle."""
    spec.x1[view] = x1.p
    spec.x1_ng[view] = x1.ng
    spec.x1_si[view] = x1
    spec.x1_wo[view] = wo
    spec.x1_depth[view] = x1_depth
    spec.caster[view] = caster
    spec.xn[view] = xn
    spec.xn_n[view] = xn_n
    spec.light_tri[view] = light_tri


# ---- the seed space U of a caster --------------------------------------------------------


@wp.func
def seed_frame(scene: SceneData, caster: int, x1: wp.vec3) -> SeedFrame:
    """The seed square of object ``caster`` seen from ``x1`` (module docstring)."""
    f = SeedFrame()
    f.valid = 0
    c = scene.object_center[caster]
    r = scene.object_radius[caster]
    v = c - x1
    dist = wp.length(v)
    if dist <= 1.0e-6 * (r + 1.0):
        return f
    f.c = c
    f.a = v / dist
    fr = frame_from_normal(f.a)
    f.t = fr.s
    f.b = fr.t
    f.dist = dist
    f.half = 2.0 * r  # x₁ inside or near the sphere: part of O only (the rest stays with the path tracer)
    if dist * dist > r * r * (4.0 / 3.0):
        f.half = r * dist / wp.sqrt(dist * dist - r * r)  # the silhouette, where that is < 2r
    f.valid = 1
    return f


@wp.func
def seed_direction(f: SeedFrame, x1: wp.vec3, u: wp.vec2) -> SeedDirection:
    """ω₁(u) = normalize(c + s(2u₀ − 1) t + s(2u₁ − 1) b − x₁), |∂ω₁/∂u| = (2s)² D / ρ³."""
    out = SeedDirection()
    p = f.c + f.t * (f.half * (2.0 * u[0] - 1.0)) + f.b * (f.half * (2.0 * u[1] - 1.0))
    v = p - x1
    rho = wp.length(v)
    out.d = v / rho
    out.dist = rho
    out.jacobian = 4.0 * f.half * f.half * f.dist / (rho * rho * rho)
    return out


@wp.func
def invert_seed_direction(f: SeedFrame, x1: wp.vec3, d: wp.vec3) -> wp.vec3:
    """u with ω₁(u) = d, as (u₀, u₁, inside): inside = 1 when d lies in the seed square (u ∈ [0, 1)²)."""
    cos_a = wp.dot(d, f.a)
    if f.valid == 0 or cos_a <= 0.0:
        return wp.vec3(0.0, 0.0, 0.0)
    p = x1 + d * (f.dist / cos_a) - f.c
    u0 = 0.5 * (wp.dot(p, f.t) / f.half + 1.0)
    u1 = 0.5 * (wp.dot(p, f.b) / f.half + 1.0)
    inside = float(0.0)
    if u0 >= 0.0 and u0 < 1.0 and u1 >= 0.0 and u1 < 1.0:
        inside = 1.0
    return wp.vec3(u0, u1, inside)


@wp.func
def grazing(d: wp.vec3, ng: wp.vec3) -> wp.bool:
    """Does a ray along ``d`` meet a surface of geometric normal ``ng`` below ``GRAZING_COS``? Such a chain is not SMS's."""
    return wp.abs(wp.dot(d, ng)) < GRAZING_COS


@wp.func
def caustic_owned(scene: SceneData, x1: wp.vec3, d1: wp.vec3, caster: int) -> int:
    """Does SMS own the chain that leaves x₁ along ``d1`` and first meets object ``caster``? (ω₁ in its seed square)"""
    return int(invert_seed_direction(seed_frame(scene, caster, x1), x1, d1)[2] > 0.0)


@wp.func
def canonical_lobe(m: Material, wo: wp.vec3, wi: wp.vec3) -> int:
    """Is ``wi`` a delta vertex's canonical lobe — refraction at a dielectric, reflection at a conductor?"""
    if m.kind == MATERIAL_DIELECTRIC:
        return int(wo[2] * wi[2] < 0.0)
    return 1


# ---- ray differentials through a chain (∂/∂u of every vertex and direction) -------------------


@wp.func
def transfer_differential(dp: wp.vec3, dd: wp.vec3, d: wp.vec3, t: float, n: wp.vec3) -> wp.vec3:
    """∂ of the point where the ray p + t·d meets the plane of normal ``n``, for the ray's differential
    (∂p, ∂d): ∂t = −(∂p + t ∂d)·n / (d·n), ∂x = ∂p + t ∂d + ∂t d (Igehy 1999, Eq. 10)."""
    a = dp + dd * t
    return a - d * (wp.dot(a, n) / wp.dot(d, n))


@wp.func
def scatter_differential(d: wp.vec3, dd: wp.vec3, n: wp.vec3, dn: wp.vec3, d_out: wp.vec3, eta: float) -> wp.vec3:
    """∂ω' of a delta vertex's outgoing direction ``d_out`` for incoming ``d`` (toward the vertex) and unit
    normal ``n`` with differentials ∂d, ∂n. Reflection (``d_out`` on ``d``'s side): ω' = d − 2(d·n) n. Refraction
    with η = ``eta`` (n_t / n_i, :class:`~grisx.scene.bsdf.BsdfSample`'s): ω' = d/η + μ n with μ = D' − D/η,
    D = d·n, D' = ω'·n, D'² = 1 − (1 − D²)/η², so ∂D' = D ∂D / (η² D') (Igehy 1999, Eq. 14–16)."""
    dot_d = wp.dot(d, n)
    ddot = wp.dot(dd, n) + wp.dot(d, dn)
    dot_out = wp.dot(d_out, n)
    if dot_d * dot_out < 0.0:  # reflection: ω' leaves on the side the ray came from (d travels toward it)
        return dd - (n * ddot + dn * dot_d) * 2.0
    inv = 1.0 / eta
    mu = dot_out - dot_d * inv
    ddot_out = dot_d * ddot * inv * inv / dot_out
    return dd * inv + n * (ddot_out - ddot * inv) + dn * mu


# ---- the constraint over a scene's material kinds ---------------------------------------


@dataclasses.dataclass(frozen=True)
class CausticFuncs:
    """The Warp functions of caustic chains for one set of material kinds (see :func:`make_caustics`).

    ``shoot(spec, view, u) -> CausticChain`` (with C and its ray-differential ∂C/∂u);
    ``constraint(spec, view, u) -> vec2`` (C); ``jacobian(spec, view, u) -> mat22`` (∂C/∂u);
    ``geometry(spec, view, u) -> float``
    (|∂ω₁/∂A(x_n)|, 0 if singular); ``value(spec, view, u) -> vec3`` (f of Eq. 13) and
    ``target`` (p̂ = lum f); ``sms``: the :class:`~grisx.theory.manifold.ManifoldSampler`
    built over them (with ``reuse``: manifold-shift GRIS).
    """

    shoot: Any
    constraint: Any
    jacobian: Any
    geometry: Any
    value: Any
    target: Any
    sms: ManifoldSampler
    probe: Any  # kernel of :func:`solve_chains`
    estimate: Any  # kernel of :func:`sms_estimates`


@functools.cache
def _make_caustics(kinds: frozenset[int]) -> CausticFuncs:
    bsdf = make_bsdf(kinds)
    surface = make_surface(kinds)  # the wrappers and shapes of these kinds only
    lights = make_lights(kinds)  # the lights of these kinds only
    emitter_radiance, environment_eval = lights.emitter_radiance, lights.environment_eval
    surface_material = surface.surface_material
    intersect = surface.intersect
    blocked = surface.blocked
    shading_normal_derivative = surface.shading_normal_derivative
    # only a normal or bump map turns a normal whose derivative the shot does not carry: without one, ∂C/∂u is
    # always the differentials', and the four extra shots of the differences are not compiled in at all
    differences = bool(kinds & {MATERIAL_NORMALMAP, MATERIAL_BUMPMAP})

    @wp.func
    def shoot(spec: CausticSpec, view: int, u: wp.vec2) -> CausticChain:
        out = CausticChain()
        out.valid = 0
        out.length = 0
        out.c = wp.vec2(_INVALID, _INVALID)
        scene = spec.scene
        x1 = spec.x1[view]
        caster = spec.caster[view]
        sf = seed_frame(scene, caster, x1)
        if sf.valid == 0:
            return out
        sd = seed_direction(sf, x1, u)
        out.d1 = sd.d
        out.seed_jacobian = sd.jacobian
        d = sd.d
        o = spawn_origin(scene, x1, spec.x1_ng[view], d)
        # ∂/∂u₀, ∂/∂u₁ of the ray (Igehy's ray differentials): x₁ is fixed; ω₁ = normalize(P(u) − x₁) with
        # ∂P/∂u = 2s (t, b), so ∂ω₁ = (I − ω₁ω₁ᵀ) ∂P / ρ
        rho = sd.dist
        dp0 = wp.vec3(0.0, 0.0, 0.0)
        dp1 = wp.vec3(0.0, 0.0, 0.0)
        dd0 = (sf.t - d * wp.dot(d, sf.t)) * (2.0 * sf.half / rho)
        dd1 = (sf.b - d * wp.dot(d, sf.b)) * (2.0 * sf.half / rho)
        out.exact = 1
        beta = wp.vec3(1.0, 1.0, 1.0)
        for k in range(spec.chain_max):
            si = intersect(scene, o, d, 1.0e30)
            if si.valid == 0:
                break
            m = surface_material(scene, si)
            if bsdf.is_delta(m) == 0:
                break
            if k == 0 and (si.object != caster or grazing(d, si.ng)):
                return out  # x₂ must lie on O (another object in front: not this chain), met at |cos| ≥ GRAZING_COS
            frame = frame_from_normal(si.ns)
            wo = to_local(frame, -d)
            bs = bsdf.sample(m, wo, 1.0, wp.vec2(0.5, 0.5))  # u_lobe = 1: the canonical lobe
            if bs.valid == 0 or bs.pdf <= 0.0:
                return out  # no canonical lobe here (total internal reflection: refraction has probability 0)
            beta = wp.cw_mul(beta, bs.weight * bs.pdf)
            d_out = wp.normalize(to_world(frame, bs.wi))
            # ---- the differentials through this vertex: onto its tangent plane, then the lobe's turn ----
            dp0 = transfer_differential(dp0, dd0, d, si.t, si.ng)
            dp1 = transfer_differential(dp1, dd1, d, si.t, si.ng)
            dn0 = shading_normal_derivative(scene, si, dp0)
            dn1 = shading_normal_derivative(scene, si, dp1)
            out.exact = out.exact * int(dn0[3]) * int(dn1[3])
            dd0 = scatter_differential(d, dd0, si.ns, wp.vec3(dn0[0], dn0[1], dn0[2]), d_out, bs.eta)
            dd1 = scatter_differential(d, dd1, si.ns, wp.vec3(dn1[0], dn1[1], dn1[2]), d_out, bs.eta)
            d = d_out
            o = spawn_origin(scene, si.p, si.ng, d)
            if k == 0:
                out.first = si.p
            out.last = si.p
            out.last_ng = si.ng
            out.length = k + 1
        if out.length == 0:
            return out
        xn = spec.xn[view]
        nn = spec.xn_n[view]
        if spec.light_tri[view] < 0:
            # ---- the environment: x_n is a direction ω_n, C = d_out's tangential part about ω_n ----
            if wp.dot(d, xn) <= 0.0:
                return out  # the antipode also has a zero tangential part: not a solution
            ef = frame_from_normal(xn)
            out.c = wp.vec2(wp.dot(d, ef.s), wp.dot(d, ef.t))
            out.dc = wp.mat22(wp.dot(dd0, ef.s), wp.dot(dd1, ef.s), wp.dot(dd0, ef.t), wp.dot(dd1, ef.t))
            out.d_out = d
            out.throughput = beta
            out.valid = 1
            return out
        # ---- where the last segment meets the emitter's plane ----
        denom = wp.dot(d, nn)
        if wp.abs(denom) < 1.0e-8:
            return out
        t = wp.dot(xn - out.last, nn) / denom
        if t <= 0.0:
            return out
        lf = frame_from_normal(nn)
        e = out.last + d * t - xn
        out.c = wp.vec2(wp.dot(e, lf.s), wp.dot(e, lf.t))
        de0 = transfer_differential(dp0, dd0, d, t, nn)
        de1 = transfer_differential(dp1, dd1, d, t, nn)
        out.dc = wp.mat22(wp.dot(de0, lf.s), wp.dot(de1, lf.s), wp.dot(de0, lf.t), wp.dot(de1, lf.t))
        out.d_out = d
        out.throughput = beta
        out.valid = 1
        return out

    @wp.func
    def constraint(spec: CausticSpec, view: int, u: wp.vec2) -> wp.vec2:
        return shoot(spec, view, u).c

    @wp.func
    def _difference(center: CausticChain, plus: CausticChain, minus: CausticChain, h: float) -> wp.vec3:
        """∂C along one axis: central where both neighbours are shots of the same chain as the centre,
        one-sided where only one is (at O's outline or a slab edge), else none: (∂C₀, ∂C₁, ok)."""
        ok_p = plus.valid != 0 and plus.length == center.length
        ok_m = minus.valid != 0 and minus.length == center.length
        if ok_p and ok_m:
            d = (plus.c - minus.c) / (2.0 * h)
            return wp.vec3(d[0], d[1], 1.0)
        if ok_p:
            d = (plus.c - center.c) / h
            return wp.vec3(d[0], d[1], 1.0)
        if ok_m:
            d = (center.c - minus.c) / h
            return wp.vec3(d[0], d[1], 1.0)
        return wp.vec3(0.0, 0.0, 0.0)

    @wp.func
    def jacobian_of(spec: CausticSpec, view: int, u: wp.vec2, center: CausticChain) -> wp.mat22:
        """∂C/∂u at ``u`` whose shot is ``center``: its ray differentials, or (where a bump perturbs a normal)
        central differences of four more shots."""
        if center.valid == 0:
            return wp.mat22(0.0, 0.0, 0.0, 0.0)  # singular: the walk stops
        if center.exact != 0:
            if not (wp.isfinite(center.dc[0, 0]) and wp.isfinite(center.dc[0, 1]) and wp.isfinite(center.dc[1, 0]) and wp.isfinite(center.dc[1, 1])):
                return wp.mat22(0.0, 0.0, 0.0, 0.0)  # a grazing vertex: singular, the walk stops
            return center.dc
        if wp.static(not differences):
            return wp.mat22(0.0, 0.0, 0.0, 0.0)  # unreachable: every normal's derivative is known
        h = JACOBIAN_STEP
        d0 = _difference(center, shoot(spec, view, wp.vec2(u[0] + h, u[1])), shoot(spec, view, wp.vec2(u[0] - h, u[1])), h)
        d1 = _difference(center, shoot(spec, view, wp.vec2(u[0], u[1] + h)), shoot(spec, view, wp.vec2(u[0], u[1] - h)), h)
        if d0[2] == 0.0 or d1[2] == 0.0:
            return wp.mat22(0.0, 0.0, 0.0, 0.0)
        return wp.mat22(d0[0], d1[0], d0[1], d1[1])

    @wp.func
    def jacobian(spec: CausticSpec, view: int, u: wp.vec2) -> wp.mat22:
        return jacobian_of(spec, view, u, shoot(spec, view, u))

    @wp.func
    def linearize(spec: CausticSpec, view: int, u: wp.vec2) -> ManifoldLinearization:
        """C(u) and ∂C/∂u from one shot (its differentials), or from differences where a normal map turns it."""
        ch = shoot(spec, view, u)
        out = ManifoldLinearization()
        out.c = ch.c
        out.jacobian = jacobian_of(spec, view, u, ch)
        return out

    @wp.func
    def geometry_of(spec: CausticSpec, view: int, u: wp.vec2, ch: CausticChain) -> float:
        det = wp.abs(wp.determinant(jacobian_of(spec, view, u, ch)))
        if ch.valid == 0 or not (det > 0.0):
            return 0.0
        return ch.seed_jacobian / det  # |∂ω₁/∂A(x_n)| = |∂ω₁/∂u| / |∂x_n/∂u|

    @wp.func
    def geometry(spec: CausticSpec, view: int, u: wp.vec2) -> float:
        return geometry_of(spec, view, u, shoot(spec, view, u))

    @wp.func
    def value(spec: CausticSpec, view: int, u: wp.vec2) -> wp.vec3:
        """f(x̂) of seed 003's Eq. 13 for solution u of ``view``: f_s ⊙ Tr ⊙ L_e · |∂ω₁/∂A(x_n)| · V."""
        zero = wp.vec3(0.0, 0.0, 0.0)
        ch = shoot(spec, view, u)
        if ch.valid == 0:
            return zero
        if spec.max_depth >= 0 and spec.x1_depth[view] + ch.length + 2 > spec.max_depth:
            return zero  # the path tracer's max_depth: x₁'s depth, k delta vertices, the emitter
        xn = spec.xn[view]
        nn = spec.xn_n[view]
        le = wp.vec3(0.0, 0.0, 0.0)
        if spec.light_tri[view] < 0:
            le = environment_eval(spec.scene.lights, xn)  # x_n = ω_n: visible if the ray escapes
            if wp.length_sq(le) <= 0.0:
                return zero
            shadow = shadow_ray_along(spec.scene, spawn_origin(spec.scene, ch.last, ch.last_ng, xn), xn, 1.0e30)
        else:
            le = emitter_radiance(spec.scene.lights, spec.light_tri[view], xn, nn, -ch.d_out)
            if wp.length_sq(le) <= 0.0:
                return zero
            shadow = shadow_ray_between(spec.scene, ch.last, ch.last_ng, xn, nn)
        if blocked(spec.scene, shadow):  # one inlined traversal for either segment (ShadowRay)
            return zero
        x1 = spec.x1_si[view]
        m = surface_material(spec.scene, x1)
        frame = frame_from_normal(x1.ns)
        f = bsdf.eval(m, to_local(frame, spec.x1_wo[view]), to_local(frame, ch.d1))
        return wp.cw_mul(f, wp.cw_mul(ch.throughput, le)) * geometry_of(spec, view, u, ch)

    @wp.func
    def target(spec: CausticSpec, view: int, u: wp.vec2) -> float:
        """p̂ = lum f(x̂) (seed 003, Sec. 5.2)."""
        return luminance(value(spec, view, u))

    sms = make_manifold_sampler(CausticSpec, constraint, jacobian, target, linearize)

    @wp.kernel
    def probe(
        spec: CausticSpec,
        seeds: wp.array(dtype=wp.vec2),
        max_iterations: int,
        u_out: wp.array(dtype=wp.vec2),
        converged: wp.array(dtype=int),
        vertices: wp.array2d(dtype=wp.vec3),
        c_out: wp.array(dtype=wp.vec2),
        jac_out: wp.array(dtype=wp.mat22),
        g_out: wp.array(dtype=float),
    ):
        i = wp.tid()
        w = sms.walk(spec, i, seeds[i], 0, max_iterations)
        u_out[i] = w.u
        converged[i] = int(w.converged)
        ch = shoot(spec, i, w.u)
        c_out[i] = ch.c
        jac_out[i] = jacobian(spec, i, w.u)
        g_out[i] = geometry(spec, i, w.u)
        # x₂, its shading and geometric normals; x_{k+1}, its normals (re-found by ray casts); the length k
        si = intersect(spec.scene, spawn_origin(spec.scene, spec.x1[i], spec.x1_ng[i], ch.d1), ch.d1, 1.0e30)
        vertices[i, 0] = ch.first
        vertices[i, 1] = si.ns
        vertices[i, 2] = si.ng
        vertices[i, 3] = ch.last
        if ch.length > 1:
            d = wp.normalize(ch.last - ch.first)
            sl = intersect(spec.scene, spawn_origin(spec.scene, ch.first, si.ng, d), d, 1.0e30)
            vertices[i, 4] = sl.ns
            vertices[i, 5] = sl.ng
        else:
            vertices[i, 4] = si.ns
            vertices[i, 5] = si.ng
        vertices[i, 6] = wp.vec3(float(ch.length), float(ch.valid), float(ch.exact))

    @wp.kernel
    def estimate(spec: CausticSpec, tiles: int, max_trials: int, seed: int, prior: wp.array(dtype=int), g_out: wp.array(dtype=float)):
        # one SMS sample of problem 0 per thread: |∂ω₁/∂A(x_n)| W, whose mean is Σ over solutions of |∂ω₁/∂A|
        i = wp.tid()
        s = sms.sample(spec, 0, seed_space(tiles, 0.0, 0), prior, random_key(seed, i), max_trials)
        g_out[i] = float(0.0)
        if s.found:
            g_out[i] = geometry(spec, 0, s.u) * s.ucw

    return CausticFuncs(shoot, constraint, jacobian, geometry, value, target, sms, probe, estimate)


def make_caustics(kinds: Iterable[int]) -> CausticFuncs:
    """The caustic-chain functions compiled for the material kinds ``kinds`` (cached per set)."""
    return _make_caustics(frozenset(int(k) for k in kinds))


def make_caustic_spec(built: Any, views: int, chain_max: int = CHAIN_MAX, max_depth: int = -1) -> CausticSpec:
    """A :class:`CausticSpec` over ``built`` with ``views`` rows (zeroed) on its device."""
    dev = built.device
    s = CausticSpec()
    s.scene = built.data
    s.chain_max = int(chain_max)
    s.max_depth = int(max_depth)
    n = max(int(views), 1)
    s.x1_si = wp.zeros(n, dtype=SurfaceInteraction, device=dev)
    s.x1_wo = wp.zeros(n, dtype=wp.vec3, device=dev)
    s.x1_depth = wp.zeros(n, dtype=int, device=dev)
    s.light_tri = wp.zeros(n, dtype=int, device=dev)
    s.x1 = wp.zeros(n, dtype=wp.vec3, device=dev)
    s.x1_ng = wp.zeros(n, dtype=wp.vec3, device=dev)
    s.caster = wp.zeros(n, dtype=int, device=dev)
    s.xn = wp.zeros(n, dtype=wp.vec3, device=dev)
    s.xn_n = wp.zeros(n, dtype=wp.vec3, device=dev)
    return s


def solve_chains(
    built: Any, x1: Any, x1_ng: Any, caster: int, xn: Any, xn_n: Any, seeds: Any, *, chain_max: int = CHAIN_MAX, max_iterations: int = 20,
    light_tri: int = 0,
) -> dict[str, np.ndarray]:
    """Manifold walks from ``seeds`` (n, 2) for n problems (x₁, its normal, x_n, its normal: (n, 3) each) on ``caster``.

    Returns the end ``u``, ``converged``, C(u), ∂C/∂u, |∂ω₁/∂A(x_n)| (``geometry``), and per walk
    ``vertices`` (n, 7, 3): x₂, its shading and geometric normals, x_{k+1}, its normals, (k, valid, exact):
    exact = 1 where ∂C/∂u came from the shot's ray differentials, 0 where from differences.
    ``light_tri`` < 0 makes x_n a direction of the environment. For tests and the tutorial (the
    renderers call the same functions in their kernels).
    """
    seeds = np.asarray(seeds, dtype=np.float32).reshape(-1, 2)
    n = len(seeds)
    dev = built.device
    spec = make_caustic_spec(built, n, chain_max)

    def rows(a: Any) -> np.ndarray:
        return np.broadcast_to(np.asarray(a, dtype=np.float32), (n, 3)).copy()

    spec.x1.assign(rows(x1))
    spec.x1_ng.assign(rows(x1_ng))
    spec.caster.assign(np.full(n, int(caster), dtype=np.int32))
    spec.xn.assign(rows(xn))
    spec.xn_n.assign(rows(xn_n))
    spec.light_tri.assign(np.full(n, int(light_tri), dtype=np.int32))
    funcs = make_caustics(built.features.kernel_kinds)
    out = {
        "u": wp.zeros(n, dtype=wp.vec2, device=dev),
        "converged": wp.zeros(n, dtype=int, device=dev),
        "vertices": wp.zeros((n, 7), dtype=wp.vec3, device=dev),
        "c": wp.zeros(n, dtype=wp.vec2, device=dev),
        "jacobian": wp.zeros(n, dtype=wp.mat22, device=dev),
        "geometry": wp.zeros(n, dtype=float, device=dev),
    }
    launch(funcs.probe, dim=n, inputs=[spec, wp.array(seeds, dtype=wp.vec2, device=dev), int(max_iterations)],
              outputs=[out["u"], out["converged"], out["vertices"], out["c"], out["jacobian"], out["geometry"]], device=dev)
    return {k: v.numpy() for k, v in out.items()}


def sms_estimates(
    built: Any, x1: Any, x1_ng: Any, caster: int, xn: Any, xn_n: Any, n: int, *, seed: int = 0, tiles: int = 0, max_trials: int = 0,
    chain_max: int = CHAIN_MAX, light_tri: int = 0,
) -> np.ndarray:
    """``n`` independent SMS samples of one problem (x₁, its normal, caster, x_n, its normal): |∂ω₁/∂A(x_n)| · W each.

    Their mean estimates Σ over the problem's solutions of |∂ω₁/∂A(x_n)| (W the Bernoulli-trial UCW:
    K for ``tiles`` = 0, K / P(C) with trust regions; no prior). For tests: the renderers draw the same
    ``sample`` in their kernels.
    """
    dev = built.device
    spec = make_caustic_spec(built, 1, chain_max)
    spec.x1.assign(np.asarray(x1, dtype=np.float32).reshape(1, 3))
    spec.x1_ng.assign(np.asarray(x1_ng, dtype=np.float32).reshape(1, 3))
    spec.caster.assign(np.array([int(caster)], dtype=np.int32))
    spec.xn.assign(np.asarray(xn, dtype=np.float32).reshape(1, 3))
    spec.xn_n.assign(np.asarray(xn_n, dtype=np.float32).reshape(1, 3))
    spec.light_tri.assign(np.array([int(light_tri)], dtype=np.int32))
    funcs = make_caustics(built.features.kernel_kinds)
    out = wp.zeros(int(n), dtype=float, device=dev)
    prior = wp.zeros(1, dtype=int, device=dev)
    launch(funcs.estimate, dim=int(n), inputs=[spec, int(tiles), int(max_trials), int(seed), prior], outputs=[out], device=dev)
    return out.numpy()
