"""BSDFs: the sampling triple (sample, eval, pdf) of every material kind, with Mitsuba 3's conventions.

Every function works in the **local shading frame** (z = shading normal, see
``grisx.scene.frame``). ``wo`` points away from the surface toward the viewer
(the previous path vertex), ``wi`` toward the next vertex or a light. As in
Mitsuba 3 (whose ``si.wi`` is our ``wo``):

* ``bsdf_eval(m, wo, wi)`` returns f(wo, wi)·|cos θ_i| — the cosine is folded
  in, so a path throughput is a product of evals over pdfs;
* ``bsdf_pdf(m, wo, wi)`` is the solid-angle density of ``bsdf_sample``;
* ``bsdf_sample(m, wo, u_lobe, u)`` returns a ``BsdfSample`` record whose
  ``weight`` = eval/pdf for non-delta lobes. Delta lobes (smooth conductor and
  dielectric) have ``delta = 1``, eval = pdf = 0 for every given direction,
  ``pdf`` = the probability of the chosen lobe (1, F or 1 − F, as Mitsuba)
  and ``weight`` = their throughput factor;
* transport is of **radiance**: a refracted sample's weight and a
  transmission eval carry Mitsuba's 1/η_it² (= η_ti²) factor for the solid
  angle compression across the interface (Veach 1997, §5.2), so transmission
  is not symmetric — see the reciprocity note below.

Lobes (equations in ``grisx.scene.microfacet``):

* **Lambertian** (``diffuse``): f = ρ/π; cosine-weighted sampling, pdf = cos θ_i/π,
  weight = ρ. Concentric-disk (Shirley–Chiu) mapping, invertible
  (``invert_cosine_hemisphere``) for random-replay shifts.
* **Smooth conductor** (``conductor``): wi = (−wo_x, −wo_y, wo_z), weight =
  specular_reflectance · F_c(cos θ_o; η, k) per channel.
* **Rough conductor** (``roughconductor``, GGX or Beckmann): m ~ D_wo (visible normals; ``sample_visible``
  false: m ∝ D cos θ_m, the weight times ``microfacet_visible_weight``),
  wi = reflect(wo, m); f·cos θ_i = F D G2 / (4 cos θ_o) (Walter et al. 2007,
  Eq. 20), pdf = D_wo(m)/(4 |wi·m|) = D G1(wo) /(4 cos θ_o), weight = F G1(wi, m).
  **Anisotropic** (α_u ≠ α_v, Mitsuba's ``alpha_u``/``alpha_v``): the same formulas with
  α_u along the shading frame's tangent s = normalize(∂p/∂u − n(n·∂p/∂u)). The local frame
  of a renderer (``frame_from_normal``) has its own tangent, so the material carries s as
  an azimuth (``Material.tangent``, resolved at the hit) and the dispatch turns wo, wi by
  it about the normal before the lobe and a sampled wi back after it
  (``rotate_to_tangent``); inside a normal or bump map, s is projected on the perturbed
  frame's plane first (Mitsuba's ``normalmap`` frame). Compiled in only for scenes with
  ``MATERIAL_ANISOTROPIC`` and run only for materials with ``anisotropic = 1``.
* **Smooth dielectric** (``dielectric``): reflect with probability F,
  otherwise refract (Snell); weight = specular_reflectance, or
  specular_transmittance · η_ti² (radiance).
* **Thin dielectric** (``thindielectric``): a pane whose internal bounces are
  summed, R = 2F/(1 + F) with F = F(|cos θ_o|); reflect with probability R,
  else pass straight through (wi = −wo); weight = specular_reflectance or
  specular_transmittance; two-sided, no refraction, no η scaling.
* **Rough dielectric** (``roughdielectric``, GGX; Walter et al. 2007, Eqs. 16–21 with
  Mitsuba's radiance scaling): the half vector m ∝ wo + η wi (η = η_i/η_o of
  the two sides), f_r·|cos θ_i| = F D G2/(4|cos θ_o|),
  f_t·|cos θ_i| = η_ti² (1 − F) D G2 η² |(wo·m)(wi·m)| / (|cos θ_o| (wo·m + η wi·m)²),
  sampled by D_wo then reflection with probability F; pdf = D_wo(m) ·
  {F, 1 − F} · |∂ω_m/∂ω_i| with the Jacobians 1/(4 |wi·m|) and
  η² |wi·m| / (wo·m + η wi·m)² (Walter et al. 2007, Eqs. 14 and 17).

* **Plastic** (``plastic``; Mitsuba 3's ``SmoothPlastic``): a smooth coating of
  relative index η over a diffuse base ρ. The coating reflects F_i = F(cos θ_o)
  as a delta lobe (weight specular_reflectance · F_i / P_s); what enters
  scatters between base and coating, summed to
  f cos θ_i = ρ/(1 − Fdr) · (1 − F_i)(1 − F(cos θ_i)) cos θ_i / (π η²)
  (``nonlinear``: ρ/(1 − ρ Fdr)). The specular lobe is chosen with
  P_s = F_i w / (F_i w + (1 − F_i)(1 − w)), w = ``specular_weight``;
  pdf = (1 − P_s) cos θ_i / π (eval and pdf see the diffuse lobe only).
* **Rough plastic** (``roughplastic``): the coating is a microfacet interface,
  f cos θ_i = spec · F(wo·h) D G2 / (4 cos θ_o) + ρ/(1 − R_int) · T(cos θ_o) T(cos θ_i)
  cos θ_i / (π η²), with T the rough interface's tabulated transmittance and
  R_int its internal reflectance (``grisx.scene.microfacet.rough_interface_table``);
  the glossy lobe is chosen with P_s as above with F_i → 1 − T(cos θ_o), sampled
  as the rough conductor's, the diffuse lobe by cosine; pdf is the mixture and
  weight = eval/pdf (Mitsuba 3's ``RoughPlastic``).

* **Polarized plastic** (``pplastic``, Mitsuba 3's unpolarized branch): no coating model, the sum
  f cos θ_i = spec · F(wo·h) D G2 / (4 cos θ_o) + ρ (1 − F(cos θ_o))(1 − F(cos θ_i)) cos θ_i / π;
  the glossy lobe chosen with the constant probability ``specular_weight``, the base by cosine;
  pdf the mixture, weight = eval/pdf. It shares the rough plastic's coat term and lobe mixture and
  the smooth plastic's two Fresnel crossings.

* **Null** (``null``): the ray goes on, wi = −wo, weight ``transmittance`` (1; a ``polarizer`` of an
  unpolarized variant ½ T, a ``retarder`` T) (delta, pdf 1).

* **Principled** (``principled``, ``principledthin``): Mitsuba 3's Disney principled BSDFs, in their own
  module (:mod:`grisx.scene.principled`), dispatched beside the reflective kinds (their back side is their
  own: black, the inside of the transmission, or the sheet's other face, unless ``twosided`` mirrors it).

**Wrappers** (applied outside in: mask, then the perturbed frame, then two-sided):

* **Mask** (``mask``, opacity α at the hit): the nested BSDF with probability α
  (its pdf times α, its weight unchanged), else the null lobe with pdf 1 − α;
  eval and pdf are α times the nested ones (Mitsuba 3's ``MaskBSDF``).
* **Normal and bump maps** (``normalmap``, ``bumpmap``): the nested BSDF in the
  frame of the perturbed normal n' (``Material.perturbed_n``, local), mirrored
  to (−n'_x, −n'_y, n'_z) where wo cannot see it (cos θ_o · wo·n' ≤ 0,
  ``flip_invalid_normals``); a direction on different sides of the two frames
  is black; eval and the sample weight carry the shadowing term
  G = 2/(1 + √(1 + α_n² tan² θ_i)), α_n² = min(tan² θ_n'/8, 1) (Estevez et al.
  2019, Mitsuba's ``eval_shadow_terminator``), the pdf does not. The tangent of
  the perturbed frame is arbitrary: the nested BSDFs are isotropic.

**Blend** (``blendbsdf`` of two BSDFs other than two Lambertian ones; ``Material.blend_partner``
holds the second): eval and pdf are (1 − w) f₀ + w f₁ and (1 − w) p₀ + w p₁; sampling picks f₁
with probability w (else f₀), samples it, and weighs the direction by the mixture,
weight = (P f_c + (1 − P) f_o)/(P p_c + (1 − P) p_o) with P the choice's probability (one-sample
MIS, Mitsuba 3's ``blendbsdf.cpp``). A delta sample takes the same formula (f_c/p_c its lobe's
weight, p_c its probability), as Mitsuba 3.9.1 does: that makes the delta lobe weigh
P(P r + (1 − P) f_o)/(P + (1 − P) p_o) rather than P r, and grisx follows Mitsuba (with the
textbook P r, ``tests/conformance``'s blendbsdf_general case reads max block |z| 9.05 against
Mitsuba's render); its pdf is P p_c. The blend sits inside the perturbed frame and outside the
tangent turn; it costs one array field in ``Material`` and compiles only for ``MATERIAL_BLEND``.

**Two-sided.** Reflection-only kinds are one-sided, as Mitsuba's: seen from
the back (cos θ_o ≤ 0) they are black and sample nothing. With
``two_sided = 1`` (Mitsuba's ``twosided`` wrapper) the frame is mirrored —
wo_z and wi_z are negated, the front BSDF evaluated, and a sampled wi_z negated
back. Dielectrics are always two-sided: the back side is the interior and η
is inverted.

**Reciprocity.** Reflection lobes satisfy f(wo, wi) = f(wi, wo). With the
radiance scaling, transmission satisfies f(wi, wo) = η² f(wo, wi) where
η = η(wi's side)/η(wo's side) (Veach 1997, Eq. 5.23).

**Specialization.** ``make_bsdf(kinds)`` builds a ``BsdfFuncs`` record whose
dispatch compiles only the listed kinds (branches are pruned with
``wp.static`` at code generation); the module-level ``bsdf_*`` functions are
the all-kinds dispatch. Scenes pass ``material_kinds(descs)`` so that a scene
without glass compiles no dielectric code.

**Albedo and roughness** (for seed 002, Eq. 9 and the hybrid shift):
``bsdf_albedo(m)`` is the bi-hemispherical average reflectance (cosine-weighted
over both directions) of the single-scattering model: ρ for diffuse,
specular_reflectance · F̄ for conductors (F̄ = 2∫F(μ)μ dμ, the average Fresnel
term), F̄ specular_reflectance + (1 − F̄) specular_transmittance for
dielectrics (from outside), F̄ specular_reflectance + (1 − F̄) ρ for plastics;
``bsdf_roughness(m)`` is 0 for smooth kinds (``plastic`` included: a path
through its delta lobe cannot be reconnected), α for rough kinds and 1 for diffuse.

References: W. Jakob et al., Mitsuba 3 ``src/bsdfs/{diffuse,conductor,
roughconductor,dielectric,roughdielectric,twosided,plastic,roughplastic,null,mask,normalmap,bumpmap,
pplastic,polarizer,retarder,blendbsdf}.cpp``;
A. Estevez, P. Lecocq, C. Hellmuth, "A microfacet-based shadowing function to solve the bump
terminator problem", Ray Tracing Gems (2019), ch. 12; B. Walter et al.,
"Microfacet models for refraction through rough surfaces", EGSR 2007;
E. Heitz, "Sampling the GGX distribution of visible normals", JCGT 7(4) 2018;
E. Veach, PhD thesis (1997), §5.2; P. Shirley, K. Chiu, "A low distortion map
between disk and square", JGT 2(3) 1997.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable

import warp as wp

from grisx.errors import InvalidParameterError
from grisx.scene.material import (
    MATERIAL_CONDUCTOR,
    MATERIAL_DIELECTRIC,
    MATERIAL_DIFFUSE,
    MATERIAL_KIND_NAMES,
    MATERIAL_ANISOTROPIC,
    MATERIAL_BUMPMAP,
    MATERIAL_KINDS,
    MATERIAL_MASK,
    MATERIAL_NORMALMAP,
    MATERIAL_NULL,
    MATERIAL_PLASTIC,
    MATERIAL_PRINCIPLED,
    MATERIAL_PRINCIPLED_THIN,
    MATERIAL_PPLASTIC,
    MATERIAL_BLEND,
    MATERIAL_ROUGH_CONDUCTOR,
    MATERIAL_ROUGH_PLASTIC,
    MATERIAL_ROUGH_DIELECTRIC,
    MATERIAL_THIN_DIELECTRIC,
    PERTURB_NONE,
    Material,
)
from grisx.scene.frame import Frame, frame_from_normal, to_local, to_world
from grisx.scene.microfacet import (
    fresnel_conductor,
    fresnel_dielectric,
    half_vector,
    MICROFACET_BECKMANN,
    ggx_d,
    ggx_g1,
    rough_table_lookup,
    microfacet_d,
    microfacet_g1,
    microfacet_g2,
    microfacet_pdf,
    microfacet_visible_weight,
    reflect,
    refract,
    sample_microfacet,
)

wp.set_module_options({"enable_backward": False})

__all__ = [
    "BsdfSample",
    "BsdfFuncs",
    "make_bsdf",
    "bsdf_sample",
    "bsdf_eval",
    "bsdf_pdf",
    "bsdf_albedo",
    "bsdf_roughness",
    "bsdf_is_delta",
    "sample_cosine_hemisphere",
    "cosine_hemisphere_pdf",
    "invert_cosine_hemisphere",
    "average_fresnel_conductor",
    "average_fresnel_dielectric",
    "diffuse_sample",
    "diffuse_eval",
    "diffuse_pdf",
    "conductor_sample",
    "rough_conductor_sample",
    "rough_conductor_eval",
    "rough_conductor_pdf",
    "dielectric_sample",
    "rough_dielectric_sample",
    "rough_dielectric_eval",
    "rough_dielectric_pdf",
    "thin_dielectric_sample",
    "plastic_sample",
    "plastic_eval",
    "plastic_pdf",
    "rough_plastic_sample",
    "rough_plastic_eval",
    "rough_plastic_pdf",
    "pplastic_sample",
    "pplastic_eval",
    "pplastic_pdf",
    "null_sample",
    "shadow_terminator",
    "tangent_azimuth",
    "rotate_to_tangent",
    "rotate_from_tangent",
]

_INV_PI = wp.constant(1.0 / math.pi)
_PI_OVER_4 = wp.constant(math.pi / 4.0)
_PI_OVER_2 = wp.constant(math.pi / 2.0)
_FOUR_OVER_PI = wp.constant(4.0 / math.pi)
#: quadrature nodes of the average-Fresnel integral 2∫F(μ)μ dμ (midpoint rule in μ)
_ALBEDO_NODES = wp.constant(32)


@wp.struct
class BsdfSample:
    """A sampled direction: ``wi`` (local), ``weight`` (eval/pdf, or the delta throughput),
    ``pdf`` (solid angle; the lobe probability for delta lobes), ``delta`` (1 for a delta lobe),
    ``eta`` (relative IOR η_it crossed; 1 when reflected), ``valid`` (0: nothing sampled, weight 0)."""

    wi: wp.vec3
    weight: wp.vec3
    pdf: float
    delta: int
    eta: float
    valid: int


@wp.func
def _no_sample() -> BsdfSample:
    s = BsdfSample()
    s.wi = wp.vec3(0.0, 0.0, 1.0)
    s.weight = wp.vec3(0.0, 0.0, 0.0)
    s.pdf = 0.0
    s.delta = 0
    s.eta = 1.0
    s.valid = 0
    return s


# ---- cosine-weighted hemisphere (concentric disk) ----


@wp.func
def sample_cosine_hemisphere(u: wp.vec2) -> wp.vec3:
    """Cosine-weighted direction: Shirley–Chiu concentric disk lifted to the hemisphere (Malley's method)."""
    r1 = 2.0 * u[0] - 1.0
    r2 = 2.0 * u[1] - 1.0
    r = float(0.0)
    phi = float(0.0)
    if r1 * r1 > r2 * r2:
        r = r1
        phi = _PI_OVER_4 * (r2 / r1)
    elif r2 != 0.0:
        r = r2
        phi = _PI_OVER_2 - _PI_OVER_4 * (r1 / r2)
    x = r * wp.cos(phi)
    y = r * wp.sin(phi)
    return wp.vec3(x, y, wp.sqrt(wp.max(0.0, 1.0 - x * x - y * y)))


@wp.func
def cosine_hemisphere_pdf(w: wp.vec3) -> float:
    """Density cos θ/π of ``sample_cosine_hemisphere`` (0 below the horizon)."""
    return wp.max(w[2], 0.0) * _INV_PI


@wp.func
def invert_cosine_hemisphere(w: wp.vec3) -> wp.vec2:
    """u with ``sample_cosine_hemisphere(u) = w`` (inverse concentric map of (w_x, w_y))."""
    x = w[0]
    y = w[1]
    quadrant = wp.abs(x) < wp.abs(y)
    r_sign = x
    if quadrant:
        r_sign = y
    r = wp.sqrt(x * x + y * y)
    sgn = wp.sign(r_sign)
    r = r * sgn
    t = _FOUR_OVER_PI * wp.atan2(y * sgn, x * sgn)
    a = r
    b = r * t
    if quadrant:
        t = 2.0 - t
        a = r * t
        b = r
    return wp.vec2(0.5 * (a + 1.0), 0.5 * (b + 1.0))


# ---- Lambertian ----


@wp.func
def diffuse_eval(m: Material, wo: wp.vec3, wi: wp.vec3) -> wp.vec3:
    """ρ cos θ_i / π for wo, wi both above the surface (one-sided)."""
    if wo[2] <= 0.0 or wi[2] <= 0.0:
        return wp.vec3(0.0, 0.0, 0.0)
    return m.reflectance * (wi[2] * _INV_PI)


@wp.func
def diffuse_pdf(m: Material, wo: wp.vec3, wi: wp.vec3) -> float:
    """cos θ_i / π (one-sided)."""
    if wo[2] <= 0.0 or wi[2] <= 0.0:
        return 0.0
    return wi[2] * _INV_PI


@wp.func
def diffuse_sample(m: Material, wo: wp.vec3, u_lobe: float, u: wp.vec2) -> BsdfSample:
    """Cosine-weighted wi; weight = ρ."""
    s = _no_sample()
    if wo[2] <= 0.0:
        return s
    wi = sample_cosine_hemisphere(u)
    pdf = cosine_hemisphere_pdf(wi)
    if pdf <= 0.0:
        return s
    s.wi = wi
    s.pdf = pdf
    s.weight = m.reflectance
    s.valid = 1
    return s


# ---- conductors ----


@wp.func
def conductor_sample(m: Material, wo: wp.vec3, u_lobe: float, u: wp.vec2) -> BsdfSample:
    """Mirror direction; weight = specular_reflectance · F_c(cos θ_o) per channel (delta)."""
    s = _no_sample()
    if wo[2] <= 0.0:
        return s
    s.wi = wp.vec3(-wo[0], -wo[1], wo[2])
    s.weight = wp.cw_mul(m.reflectance, fresnel_conductor(wo[2], m.eta, m.k))
    s.pdf = 1.0
    s.delta = 1
    s.valid = 1
    return s


@wp.func
def _alpha(m: Material) -> wp.vec2:
    """(α_u, α_v) of a rough kind: roughness along the frame's tangent s and bitangent t (α_u = α_v: isotropic)."""
    return wp.vec2(m.alpha, m.alpha_v)


@wp.func
def _glossy_dg(m: Material, wo: wp.vec3, wi: wp.vec3, h: wp.vec3) -> float:
    # D G2 / (4 cos θ_o): a microfacet reflection lobe without its Fresnel factor (Walter et al. 2007, Eq. 20)
    return microfacet_d(h, _alpha(m), m.distribution) * microfacet_g2(wo, wi, h, _alpha(m), m.distribution) / (4.0 * wo[2])


@wp.func
def _glossy_pdf(m: Material, wo: wp.vec3, wi: wp.vec3) -> float:
    # density of reflect(wo, sample_microfacet(wo)) for wo, wi above the surface
    h = wp.normalize(wo + wi)
    return microfacet_pdf(wo, h, _alpha(m), m.distribution, m.sample_visible) / (4.0 * wp.dot(wi, h))


@wp.func
def rough_conductor_eval(m: Material, wo: wp.vec3, wi: wp.vec3) -> wp.vec3:
    """F D G2 / (4 cos θ_o) (= f cos θ_i, Walter et al. 2007, Eq. 20)."""
    if wo[2] <= 0.0 or wi[2] <= 0.0:
        return wp.vec3(0.0, 0.0, 0.0)
    h = wp.normalize(wo + wi)
    f = fresnel_conductor(wp.dot(wo, h), m.eta, m.k)
    return wp.cw_mul(m.reflectance, f) * _glossy_dg(m, wo, wi, h)


@wp.func
def rough_conductor_pdf(m: Material, wo: wp.vec3, wi: wp.vec3) -> float:
    """GGX: D_wo(h) / (4 wi·h) = D(h) G1(wo, h) / (4 cos θ_o); Beckmann: D(h) cos θ_h / (4 wi·h)."""
    if wo[2] <= 0.0 or wi[2] <= 0.0:
        return 0.0
    return _glossy_pdf(m, wo, wi)


@wp.func
def rough_conductor_sample(m: Material, wo: wp.vec3, u_lobe: float, u: wp.vec2) -> BsdfSample:
    """A microfacet normal m (``sample_microfacet``) reflected; weight = F(wo·m) G1(wi, m) · specular_reflectance
    (× ``microfacet_visible_weight`` where m is not a visible-normal sample)."""
    s = _no_sample()
    if wo[2] <= 0.0:
        return s
    mn = sample_microfacet(wo, _alpha(m), m.distribution, m.sample_visible, u)
    wi = reflect(wo, mn)
    dot_i = wp.dot(wi, mn)
    if wi[2] <= 0.0 or dot_i <= 0.0:
        return s
    pdf = microfacet_pdf(wo, mn, _alpha(m), m.distribution, m.sample_visible) / (4.0 * dot_i)
    g1 = microfacet_g1(wi, mn, _alpha(m), m.distribution) * microfacet_visible_weight(wo, mn, _alpha(m), m.distribution, m.sample_visible)
    if not (pdf > 0.0) or g1 <= 0.0:
        return s
    s.wi = wi
    s.pdf = pdf
    s.weight = wp.cw_mul(m.reflectance, fresnel_conductor(wp.dot(wo, mn), m.eta, m.k)) * g1
    s.valid = 1
    return s


# ---- dielectrics ----


@wp.func
def dielectric_sample(m: Material, wo: wp.vec3, u_lobe: float, u: wp.vec2) -> BsdfSample:
    """Reflect with probability F, else refract (delta); radiance weight of refraction η_ti²."""
    s = _no_sample()
    cos_o = wo[2]
    if cos_o == 0.0:
        return s
    fr = fresnel_dielectric(cos_o, m.eta[0])
    s.delta = 1
    s.valid = 1
    if u_lobe < fr.f:
        s.wi = wp.vec3(-wo[0], -wo[1], cos_o)
        s.pdf = fr.f
        s.weight = m.reflectance
    else:
        s.wi = wp.vec3(-fr.eta_ti * wo[0], -fr.eta_ti * wo[1], fr.cos_t)
        s.pdf = 1.0 - fr.f
        s.weight = m.transmittance * (fr.eta_ti * fr.eta_ti)
        s.eta = fr.eta_it
    return s


@wp.func
def thin_dielectric_sample(m: Material, wo: wp.vec3, u_lobe: float, u: wp.vec2) -> BsdfSample:
    """A thin pane: reflect with probability R = 2F/(1 + F) (every internal bounce summed), else pass
    straight through (−wo); both delta, from either side (Mitsuba's ``thindielectric``)."""
    s = _no_sample()
    if wo[2] == 0.0:
        return s
    f = fresnel_dielectric(wp.abs(wo[2]), m.eta[0]).f
    r = 2.0 * f / (1.0 + f)
    s.delta = 1
    s.valid = 1
    if u_lobe < r:
        s.wi = wp.vec3(-wo[0], -wo[1], wo[2])
        s.pdf = r
        s.weight = m.reflectance
    else:
        s.wi = -wo
        s.pdf = 1.0 - r
        s.weight = m.transmittance
    return s


@wp.func
def _half_vector(m: Material, wo: wp.vec3, wi: wp.vec3) -> wp.vec3:
    # generalized half vector m ∝ wo + η wi (Walter et al. 2007, Eq. 16), oriented to the macro normal
    eta = m.eta[0]
    if wo[2] < 0.0:
        eta = 1.0 / eta
    return half_vector(wo, wi, eta)


@wp.func
def rough_dielectric_eval(m: Material, wo: wp.vec3, wi: wp.vec3) -> wp.vec3:
    """GGX reflection + transmission (Walter et al. 2007, Eqs. 20–21) times |cos θ_i|, radiance-scaled."""
    cos_o = wo[2]
    cos_i = wi[2]
    if cos_o == 0.0:
        return wp.vec3(0.0, 0.0, 0.0)
    eta = m.eta[0]
    if cos_o < 0.0:
        eta = 1.0 / eta
    h = _half_vector(m, wo, wi)
    dot_o = wp.dot(wo, h)
    dot_i = wp.dot(wi, h)
    d = microfacet_d(h, _alpha(m), m.distribution)
    g = microfacet_g2(wo, wi, h, _alpha(m), m.distribution)
    f = fresnel_dielectric(dot_o, m.eta[0]).f
    if cos_o * cos_i > 0.0:
        return m.reflectance * (f * d * g / (4.0 * wp.abs(cos_o)))
    denom = dot_o + eta * dot_i
    if denom == 0.0:
        return wp.vec3(0.0, 0.0, 0.0)
    # (1/η²) · η²: Mitsuba's radiance scaling times Walter's Eq. 21; kept apart to mirror both sources
    value = (1.0 / (eta * eta)) * (1.0 - f) * d * g * eta * eta * dot_o * dot_i / (cos_o * denom * denom)
    return m.transmittance * wp.abs(value)


@wp.func
def rough_dielectric_pdf(m: Material, wo: wp.vec3, wi: wp.vec3) -> float:
    """D_wo(m) · {F, 1 − F} · |∂ω_m/∂ω_i| (Walter et al. 2007, Eqs. 14, 17; Heitz 2018, Eq. 1)."""
    cos_o = wo[2]
    cos_i = wi[2]
    if cos_o == 0.0:
        return 0.0
    eta = m.eta[0]
    if cos_o < 0.0:
        eta = 1.0 / eta
    h = _half_vector(m, wo, wi)
    dot_o = wp.dot(wo, h)
    dot_i = wp.dot(wi, h)
    # the micro and macro surface must agree on each direction's side (as G1 demands)
    if dot_o * cos_o <= 0.0 or dot_i * cos_i <= 0.0:
        return 0.0
    f = fresnel_dielectric(dot_o, m.eta[0]).f
    pm = microfacet_pdf(wo * wp.sign(cos_o), h, _alpha(m), m.distribution, m.sample_visible)
    if cos_o * cos_i > 0.0:
        return pm * f / (4.0 * wp.abs(dot_i))
    denom = dot_o + eta * dot_i
    if denom == 0.0:
        return 0.0
    return pm * (1.0 - f) * wp.abs(eta * eta * dot_i / (denom * denom))


@wp.func
def rough_dielectric_sample(m: Material, wo: wp.vec3, u_lobe: float, u: wp.vec2) -> BsdfSample:
    """m ~ D_wo, reflect with probability F(wo·m) else refract; weight = G1(wi, m) (× η_ti² if refracted)."""
    s = _no_sample()
    cos_o = wo[2]
    if cos_o == 0.0:
        return s
    side = wp.sign(cos_o)
    mn = sample_microfacet(wo * side, _alpha(m), m.distribution, m.sample_visible, u)
    pm = microfacet_pdf(wo * side, mn, _alpha(m), m.distribution, m.sample_visible)
    dot_o = wp.dot(wo, mn)
    if dot_o * cos_o <= 0.0:  # a facet wo cannot see (only non-visible-normal sampling draws one)
        return s
    fr = fresnel_dielectric(dot_o, m.eta[0])
    wi = wp.vec3(0.0, 0.0, 1.0)
    pdf = float(0.0)
    weight = wp.vec3(0.0, 0.0, 0.0)
    if u_lobe < fr.f:
        wi = reflect(wo, mn)
        if wi[2] * cos_o <= 0.0:
            return s
        pdf = pm * fr.f / (4.0 * wp.abs(wp.dot(wi, mn)))
        weight = m.reflectance
    else:
        wi = refract(wo, mn, fr.cos_t, fr.eta_ti)
        if wi[2] * cos_o >= 0.0:
            return s
        dot_i = wp.dot(wi, mn)
        denom = dot_o + fr.eta_it * dot_i
        pdf = pm * (1.0 - fr.f) * wp.abs(fr.eta_it * fr.eta_it * dot_i / (denom * denom))
        weight = m.transmittance * (fr.eta_ti * fr.eta_ti)
        s.eta = fr.eta_it
    g1 = microfacet_g1(wi, mn, _alpha(m), m.distribution) * microfacet_visible_weight(wo, mn, _alpha(m), m.distribution, m.sample_visible)
    if not (pdf > 0.0) or g1 <= 0.0:
        return _no_sample()
    s.wi = wi
    s.pdf = pdf
    s.weight = weight * g1
    s.valid = 1
    return s


# ---- plastics (plastic.cpp, roughplastic.cpp) ----


@wp.func
def _plastic_base(m: Material) -> wp.vec3:
    """ρ/(1 − Fdr) (or ρ/(1 − ρ Fdr) if nonlinear) / η²: the diffuse base seen through its coating, every
    internal bounce summed, without the two crossings' transmittances."""
    inv_eta2 = 1.0 / (m.eta[0] * m.eta[0])
    if m.nonlinear != 0:
        one = wp.vec3(1.0, 1.0, 1.0)
        return wp.cw_div(m.reflectance, one - m.reflectance * m.internal_reflectance) * inv_eta2
    return m.reflectance * (inv_eta2 / (1.0 - m.internal_reflectance))


@wp.func
def _plastic_specular_prob(m: Material, reflected: float) -> float:
    """Probability of the coating's lobe when it reflects the fraction ``reflected`` (Mitsuba's prob_specular)."""
    ps = reflected * m.specular_weight
    pd = (1.0 - reflected) * (1.0 - m.specular_weight)
    if ps + pd <= 0.0:
        return 0.0
    return ps / (ps + pd)


@wp.func
def _weighted_sample(wi: wp.vec3, pdf: float, value: wp.vec3) -> BsdfSample:
    """``wi`` sampled with density ``pdf``, weight value/pdf (nothing where pdf is 0)."""
    s = _no_sample()
    if pdf > 0.0:
        s.wi = wi
        s.pdf = pdf
        s.weight = value / pdf
        s.valid = 1
    return s


@wp.func
def _smooth_crossings(m: Material, wo: wp.vec3, wi: wp.vec3) -> float:
    """(1 − F(cos θ_o))(1 − F(cos θ_i)) cos θ_i / π: a Lambertian lobe seen through a smooth interface, in and out."""
    f_o = fresnel_dielectric(wo[2], m.eta[0]).f
    f_i = fresnel_dielectric(wi[2], m.eta[0]).f
    return (1.0 - f_o) * (1.0 - f_i) * wi[2] * _INV_PI


@wp.func
def plastic_eval(m: Material, wo: wp.vec3, wi: wp.vec3) -> wp.vec3:
    """The diffuse lobe ρ'(1 − F(cos θ_o))(1 − F(cos θ_i)) cos θ_i / π (the coating's mirror is a delta)."""
    if wo[2] <= 0.0 or wi[2] <= 0.0:
        return wp.vec3(0.0, 0.0, 0.0)
    return _plastic_base(m) * _smooth_crossings(m, wo, wi)


@wp.func
def plastic_pdf(m: Material, wo: wp.vec3, wi: wp.vec3) -> float:
    """(1 − P_s) cos θ_i / π."""
    if wo[2] <= 0.0 or wi[2] <= 0.0:
        return 0.0
    ps = _plastic_specular_prob(m, fresnel_dielectric(wo[2], m.eta[0]).f)
    return (1.0 - ps) * cosine_hemisphere_pdf(wi)


@wp.func
def plastic_sample(m: Material, wo: wp.vec3, u_lobe: float, u: wp.vec2) -> BsdfSample:
    """The coating's mirror with probability P_s (delta, weight spec · F / P_s), else a cosine-weighted
    direction (weight eval/pdf)."""
    s = _no_sample()
    if wo[2] <= 0.0:
        return s
    f_o = fresnel_dielectric(wo[2], m.eta[0]).f
    ps = _plastic_specular_prob(m, f_o)
    if u_lobe < ps:
        s.wi = wp.vec3(-wo[0], -wo[1], wo[2])
        s.pdf = ps
        s.weight = m.specular_reflectance * (f_o / ps)
        s.delta = 1
        s.valid = 1
        return s
    wi = sample_cosine_hemisphere(u)
    return _weighted_sample(wi, (1.0 - ps) * cosine_hemisphere_pdf(wi), plastic_eval(m, wo, wi))


@wp.func
def _coat_glossy(m: Material, wo: wp.vec3, wi: wp.vec3) -> wp.vec3:
    """spec · F(wo·h) D G2 / (4 cos θ_o): the microfacet reflection of a dielectric coat (roughplastic, pplastic)."""
    h = wp.normalize(wo + wi)
    return m.specular_reflectance * (fresnel_dielectric(wp.dot(wo, h), m.eta[0]).f * _glossy_dg(m, wo, wi, h))


@wp.func
def _glossy_diffuse_pdf(m: Material, wo: wp.vec3, wi: wp.vec3, ps: float) -> float:
    """ps · (the microfacet reflection's pdf) + (1 − ps) cos θ_i / π, wo and wi above the surface."""
    return ps * _glossy_pdf(m, wo, wi) + (1.0 - ps) * cosine_hemisphere_pdf(wi)


@wp.func
def _glossy_diffuse_direction(m: Material, wo: wp.vec3, u_lobe: float, u: wp.vec2, ps: float) -> wp.vec3:
    """A microfacet reflection with probability ps, else a cosine-weighted direction (the density: ``_glossy_diffuse_pdf``)."""
    if u_lobe < ps:
        return reflect(wo, sample_microfacet(wo, _alpha(m), m.distribution, m.sample_visible, u))
    return sample_cosine_hemisphere(u)


@wp.func
def _rough_plastic_prob(m: Material, wo: wp.vec3) -> float:
    # P_s of the rough coat: its reflected fraction 1 − T(cos θ_o)
    return _plastic_specular_prob(m, 1.0 - rough_table_lookup(m.external_transmittance, wo[2]))


@wp.func
def rough_plastic_eval(m: Material, wo: wp.vec3, wi: wp.vec3) -> wp.vec3:
    """spec · F(wo·h) D G2 / (4 cos θ_o) + ρ' T(cos θ_o) T(cos θ_i) cos θ_i / π."""
    if wo[2] <= 0.0 or wi[2] <= 0.0:
        return wp.vec3(0.0, 0.0, 0.0)
    t_o = rough_table_lookup(m.external_transmittance, wo[2])
    t_i = rough_table_lookup(m.external_transmittance, wi[2])
    return _coat_glossy(m, wo, wi) + _plastic_base(m) * (t_o * t_i * wi[2] * _INV_PI)


@wp.func
def rough_plastic_pdf(m: Material, wo: wp.vec3, wi: wp.vec3) -> float:
    """P_s · (the rough conductor's pdf) + (1 − P_s) cos θ_i / π, P_s of the reflected fraction 1 − T(cos θ_o)."""
    if wo[2] <= 0.0 or wi[2] <= 0.0:
        return 0.0
    return _glossy_diffuse_pdf(m, wo, wi, _rough_plastic_prob(m, wo))


@wp.func
def rough_plastic_sample(m: Material, wo: wp.vec3, u_lobe: float, u: wp.vec2) -> BsdfSample:
    """A microfacet reflection with probability P_s, else a cosine-weighted direction; weight = eval/pdf of the mixture."""
    if wo[2] <= 0.0:
        return _no_sample()
    wi = _glossy_diffuse_direction(m, wo, u_lobe, u, _rough_plastic_prob(m, wo))
    return _weighted_sample(wi, rough_plastic_pdf(m, wo, wi), rough_plastic_eval(m, wo, wi))


# ---- plugins2 (issue 38): pplastic, as Mitsuba 3's unpolarized variants evaluate it (pplastic.cpp) ----


@wp.func
def pplastic_eval(m: Material, wo: wp.vec3, wi: wp.vec3) -> wp.vec3:
    """spec · F(wo·h) D G2 / (4 cos θ_o) + ρ (1 − F(cos θ_o))(1 − F(cos θ_i)) cos θ_i / π (no coating: no 1/η², no
    internal reflection)."""
    if wo[2] <= 0.0 or wi[2] <= 0.0:
        return wp.vec3(0.0, 0.0, 0.0)
    return _coat_glossy(m, wo, wi) + m.reflectance * _smooth_crossings(m, wo, wi)


@wp.func
def pplastic_pdf(m: Material, wo: wp.vec3, wi: wp.vec3) -> float:
    """w · (the microfacet reflection's pdf) + (1 − w) cos θ_i / π with the constant w = ``specular_weight``."""
    if wo[2] <= 0.0 or wi[2] <= 0.0:
        return 0.0
    return _glossy_diffuse_pdf(m, wo, wi, m.specular_weight)


@wp.func
def pplastic_sample(m: Material, wo: wp.vec3, u_lobe: float, u: wp.vec2) -> BsdfSample:
    """A microfacet reflection with probability ``specular_weight``, else a cosine-weighted direction; weight = eval/pdf."""
    if wo[2] <= 0.0:
        return _no_sample()
    wi = _glossy_diffuse_direction(m, wo, u_lobe, u, m.specular_weight)
    return _weighted_sample(wi, pplastic_pdf(m, wo, wi), pplastic_eval(m, wo, wi))


# ---- end plugins2 ----


# ---- null, and the wrappers' pieces (null.cpp, mask.cpp, normalmap.cpp, bumpmap.cpp) ----


@wp.func
def null_sample(wo: wp.vec3, pdf: float) -> BsdfSample:
    """The null lobe: the ray goes on (wi = −wo) with weight 1; ``pdf``: the lobe's probability (delta)."""
    s = _no_sample()
    s.wi = -wo
    s.weight = wp.vec3(1.0, 1.0, 1.0)
    s.pdf = pdf
    s.delta = 1
    s.valid = 1
    return s


@wp.func
def _tan2(w: wp.vec3) -> float:
    z2 = w[2] * w[2]
    if z2 <= 0.0:
        return 1.0e30
    return wp.max(1.0 - z2, 0.0) / z2


@wp.func
def shadow_terminator(n: wp.vec3, w: wp.vec3) -> float:
    """Estevez et al.'s shadowing of a perturbed normal ``n`` toward ``w`` (both local to the unperturbed frame):
    2/(1 + √(1 + α² tan² θ_w)), α² = min(tan² θ_n / 8, 1)."""
    alpha2 = wp.min(0.125 * _tan2(n), 1.0)
    return 2.0 / (1.0 + wp.sqrt(1.0 + alpha2 * _tan2(w)))


@wp.func
def _masked(m: Material) -> bool:
    """Whether a mask may pass light here: a property of the material, whether or not its opacity texture was
    resolved at a hit (so that every renderer, at a hit or at a stored vertex, sees the same lobes)."""
    return m.opacity < 1.0 or m.opacity_texture >= 0


@wp.func
def _perturbed_normal(m: Material, wo: wp.vec3) -> wp.vec3:
    """The hit's perturbed normal, mirrored about the normal's axis where ``wo`` cannot see it (flip_invalid_normals)."""
    n = m.perturbed_n
    if (m.perturb_flags & 1) != 0:
        if wo[2] * wp.dot(wo, n) <= 0.0:
            n = wp.vec3(-n[0], -n[1], n[2])
    return n


# ---- the tangent of an anisotropic lobe ----


@wp.func
def tangent_azimuth(tangent: wp.vec3) -> wp.vec2:
    """(cos φ, sin φ) of ``tangent`` projected on the local frame's plane: the azimuth of the shading frame's s
    (Mitsuba's normalize(∂p/∂u − n (n·∂p/∂u))); the frame's own s where the projection vanishes."""
    l2 = tangent[0] * tangent[0] + tangent[1] * tangent[1]
    if l2 <= 0.0:
        return wp.vec2(1.0, 0.0)
    r = 1.0 / wp.sqrt(l2)
    return wp.vec2(tangent[0] * r, tangent[1] * r)


@wp.func
def rotate_to_tangent(v: wp.vec3, cs: wp.vec2) -> wp.vec3:
    """Local coordinates of ``v`` → those of the frame turned about z by the azimuth (cos φ, sin φ) = ``cs``."""
    return wp.vec3(cs[0] * v[0] + cs[1] * v[1], cs[0] * v[1] - cs[1] * v[0], v[2])


@wp.func
def rotate_from_tangent(v: wp.vec3, cs: wp.vec2) -> wp.vec3:
    """Inverse of :func:`rotate_to_tangent`."""
    return wp.vec3(cs[0] * v[0] - cs[1] * v[1], cs[1] * v[0] + cs[0] * v[1], v[2])


# ---- albedo (average reflectance) ----


@wp.func
def average_fresnel_conductor(eta: wp.vec3, k: wp.vec3) -> wp.vec3:
    """F̄ = 2∫₀¹ F_c(μ) μ dμ per channel (midpoint rule, 32 nodes)."""
    acc = wp.vec3(0.0, 0.0, 0.0)
    h = 1.0 / float(_ALBEDO_NODES)
    for j in range(_ALBEDO_NODES):
        mu = (float(j) + 0.5) * h
        acc += fresnel_conductor(mu, eta, k) * (2.0 * mu * h)
    return acc


@wp.func
def average_fresnel_dielectric(eta: float) -> float:
    """F̄ = 2∫₀¹ F(μ) μ dμ seen from outside (midpoint rule, 32 nodes)."""
    acc = float(0.0)
    h = 1.0 / float(_ALBEDO_NODES)
    for j in range(_ALBEDO_NODES):
        mu = (float(j) + 0.5) * h
        acc += fresnel_dielectric(mu, eta).f * (2.0 * mu * h)
    return acc


# ---- dispatch (specialized per set of kinds) ----


@dataclasses.dataclass(frozen=True)
class BsdfFuncs:
    """Warp funcs of one specialized dispatch: ``sample(m, wo, u_lobe, u)``, ``eval(m, wo, wi)``,
    ``pdf(m, wo, wi)``, ``albedo(m)``, ``roughness(m)``, ``is_delta(m)``, ``has_delta_lobe(m)``; ``kinds`` compiled in.
    A material of a kind not compiled in is black: invalid samples, zero eval/pdf/albedo."""

    kinds: frozenset[int]
    sample: wp.Function
    eval: wp.Function
    pdf: wp.Function
    albedo: wp.Function
    roughness: wp.Function
    is_delta: wp.Function
    has_delta_lobe: wp.Function


_DISPATCH_CACHE: dict[frozenset[int], BsdfFuncs] = {}


def make_bsdf(kinds: Iterable[int]) -> BsdfFuncs:
    """The BSDF dispatch compiled for exactly ``kinds`` (MATERIAL_* constants; cached per set)."""
    key = frozenset(int(k) for k in kinds)
    unknown = sorted(key - set(MATERIAL_KINDS))
    if unknown:
        raise InvalidParameterError(f"unknown material kind(s) {unknown} (known: {dict(MATERIAL_KIND_NAMES)})")
    if key in _DISPATCH_CACHE:
        return _DISPATCH_CACHE[key]

    has_diffuse = MATERIAL_DIFFUSE in key
    has_conductor = MATERIAL_CONDUCTOR in key
    has_rough_conductor = MATERIAL_ROUGH_CONDUCTOR in key
    has_dielectric = MATERIAL_DIELECTRIC in key
    has_rough_dielectric = MATERIAL_ROUGH_DIELECTRIC in key
    has_thin_dielectric = MATERIAL_THIN_DIELECTRIC in key
    has_plastic = MATERIAL_PLASTIC in key
    has_rough_plastic = MATERIAL_ROUGH_PLASTIC in key
    has_null = MATERIAL_NULL in key
    has_mask = MATERIAL_MASK in key
    has_perturb = MATERIAL_NORMALMAP in key or MATERIAL_BUMPMAP in key
    has_anisotropic = MATERIAL_ANISOTROPIC in key
    # ---- principled (grisx.scene.principled): in the reflective blocks below, as its back side is its own
    # (black, or the inside of its transmission) unless a twosided wrapper mirrors it
    has_principled = MATERIAL_PRINCIPLED in key
    has_principled_thin = MATERIAL_PRINCIPLED_THIN in key
    if has_principled or has_principled_thin:
        from grisx.scene import principled as pr  # noqa: PLC0415 (it imports this module's records)
    else:
        pr = None
    has_pplastic = MATERIAL_PPLASTIC in key  # plugins2
    has_blend = MATERIAL_BLEND in key  # plugins2
    has_reflective = (has_diffuse or has_conductor or has_rough_conductor or has_plastic or has_rough_plastic or has_pplastic
                      or has_principled or has_principled_thin)
    has_evaluable = (has_diffuse or has_rough_conductor or has_plastic or has_rough_plastic or has_pplastic or has_principled
                     or has_principled_thin)

    @wp.func
    def kind_sample(m: Material, wo: wp.vec3, u_lobe: float, u: wp.vec2) -> BsdfSample:
        if wp.static(has_null):
            if m.kind == MATERIAL_NULL:
                s0 = null_sample(wo, 1.0)
                s0.weight = m.transmittance  # null: 1; polarizer (unpolarized): ½ transmittance
                return s0
        if wp.static(has_dielectric):
            if m.kind == MATERIAL_DIELECTRIC:
                return dielectric_sample(m, wo, u_lobe, u)
        if wp.static(has_rough_dielectric):
            if m.kind == MATERIAL_ROUGH_DIELECTRIC:
                return rough_dielectric_sample(m, wo, u_lobe, u)
        if wp.static(has_thin_dielectric):
            if m.kind == MATERIAL_THIN_DIELECTRIC:
                return thin_dielectric_sample(m, wo, u_lobe, u)
        s = _no_sample()
        if wp.static(has_reflective):
            # Mitsuba twosided: mirror the frame when seen from the back
            flip = m.two_sided != 0 and wo[2] < 0.0
            w = wo
            if flip:
                w = wp.vec3(wo[0], wo[1], -wo[2])
            if wp.static(has_diffuse):
                if m.kind == MATERIAL_DIFFUSE:
                    s = diffuse_sample(m, w, u_lobe, u)
            if wp.static(has_conductor):
                if m.kind == MATERIAL_CONDUCTOR:
                    s = conductor_sample(m, w, u_lobe, u)
            if wp.static(has_rough_conductor):
                if m.kind == MATERIAL_ROUGH_CONDUCTOR:
                    s = rough_conductor_sample(m, w, u_lobe, u)
            if wp.static(has_plastic):
                if m.kind == MATERIAL_PLASTIC:
                    s = plastic_sample(m, w, u_lobe, u)
            if wp.static(has_rough_plastic):
                if m.kind == MATERIAL_ROUGH_PLASTIC:
                    s = rough_plastic_sample(m, w, u_lobe, u)
            if wp.static(has_principled):
                if m.kind == MATERIAL_PRINCIPLED:
                    s = pr.principled_sample(m, w, u_lobe, u)
            if wp.static(has_principled_thin):
                if m.kind == MATERIAL_PRINCIPLED_THIN:
                    s = pr.principled_thin_sample(m, w, u_lobe, u)
            if wp.static(has_pplastic):
                if m.kind == MATERIAL_PPLASTIC:
                    s = pplastic_sample(m, w, u_lobe, u)
            if flip:
                s.wi = wp.vec3(s.wi[0], s.wi[1], -s.wi[2])
        return s

    @wp.func
    def kind_eval(m: Material, wo: wp.vec3, wi: wp.vec3) -> wp.vec3:
        if wp.static(has_rough_dielectric):
            if m.kind == MATERIAL_ROUGH_DIELECTRIC:
                return rough_dielectric_eval(m, wo, wi)
        r = wp.vec3(0.0, 0.0, 0.0)
        if wp.static(has_evaluable):
            a = wo
            b = wi
            if m.two_sided != 0 and wo[2] < 0.0:
                a = wp.vec3(wo[0], wo[1], -wo[2])
                b = wp.vec3(wi[0], wi[1], -wi[2])
            if wp.static(has_diffuse):
                if m.kind == MATERIAL_DIFFUSE:
                    r = diffuse_eval(m, a, b)
            if wp.static(has_rough_conductor):
                if m.kind == MATERIAL_ROUGH_CONDUCTOR:
                    r = rough_conductor_eval(m, a, b)
            if wp.static(has_plastic):
                if m.kind == MATERIAL_PLASTIC:
                    r = plastic_eval(m, a, b)
            if wp.static(has_rough_plastic):
                if m.kind == MATERIAL_ROUGH_PLASTIC:
                    r = rough_plastic_eval(m, a, b)
            if wp.static(has_principled):
                if m.kind == MATERIAL_PRINCIPLED:
                    r = pr.principled_eval(m, a, b)
            if wp.static(has_principled_thin):
                if m.kind == MATERIAL_PRINCIPLED_THIN:
                    r = pr.principled_thin_eval(m, a, b)
            if wp.static(has_pplastic):
                if m.kind == MATERIAL_PPLASTIC:
                    r = pplastic_eval(m, a, b)
        return r  # delta kinds: 0

    @wp.func
    def kind_pdf(m: Material, wo: wp.vec3, wi: wp.vec3) -> float:
        if wp.static(has_rough_dielectric):
            if m.kind == MATERIAL_ROUGH_DIELECTRIC:
                return rough_dielectric_pdf(m, wo, wi)
        p = float(0.0)
        if wp.static(has_evaluable):
            a = wo
            b = wi
            if m.two_sided != 0 and wo[2] < 0.0:
                a = wp.vec3(wo[0], wo[1], -wo[2])
                b = wp.vec3(wi[0], wi[1], -wi[2])
            if wp.static(has_diffuse):
                if m.kind == MATERIAL_DIFFUSE:
                    p = diffuse_pdf(m, a, b)
            if wp.static(has_rough_conductor):
                if m.kind == MATERIAL_ROUGH_CONDUCTOR:
                    p = rough_conductor_pdf(m, a, b)
            if wp.static(has_plastic):
                if m.kind == MATERIAL_PLASTIC:
                    p = plastic_pdf(m, a, b)
            if wp.static(has_rough_plastic):
                if m.kind == MATERIAL_ROUGH_PLASTIC:
                    p = rough_plastic_pdf(m, a, b)
            if wp.static(has_principled):
                if m.kind == MATERIAL_PRINCIPLED:
                    p = pr.principled_pdf(m, a, b)
            if wp.static(has_principled_thin):
                if m.kind == MATERIAL_PRINCIPLED_THIN:
                    p = pr.principled_thin_pdf(m, a, b)
            if wp.static(has_pplastic):
                if m.kind == MATERIAL_PPLASTIC:
                    p = pplastic_pdf(m, a, b)
        return p  # delta kinds: 0

    # ---- the tangent: an anisotropic lobe turned about the normal to the shading frame's s ----

    @wp.func
    def oriented_sample(m: Material, wo: wp.vec3, u_lobe: float, u: wp.vec2) -> BsdfSample:
        if wp.static(has_anisotropic):
            if m.anisotropic != 0:
                cs = tangent_azimuth(m.tangent)
                s = kind_sample(m, rotate_to_tangent(wo, cs), u_lobe, u)
                s.wi = rotate_from_tangent(s.wi, cs)
                return s
        return kind_sample(m, wo, u_lobe, u)

    @wp.func
    def oriented_eval(m: Material, wo: wp.vec3, wi: wp.vec3) -> wp.vec3:
        if wp.static(has_anisotropic):
            if m.anisotropic != 0:
                cs = tangent_azimuth(m.tangent)
                return kind_eval(m, rotate_to_tangent(wo, cs), rotate_to_tangent(wi, cs))
        return kind_eval(m, wo, wi)

    @wp.func
    def oriented_pdf(m: Material, wo: wp.vec3, wi: wp.vec3) -> float:
        if wp.static(has_anisotropic):
            if m.anisotropic != 0:
                cs = tangent_azimuth(m.tangent)
                return kind_pdf(m, rotate_to_tangent(wo, cs), rotate_to_tangent(wi, cs))
        return kind_pdf(m, wo, wi)

    @wp.func
    def perturbed_tangent(m: Material, f: Frame) -> Material:
        # the perturbed frame's s is the unperturbed s projected on its plane (Mitsuba's normalmap frame())
        if wp.static(has_anisotropic):
            m.tangent = to_local(f, m.tangent)
        return m

    # ---- plugins2: a general blendbsdf, (1 − w) f₀ + w f₁ (blendbsdf.cpp), inside the perturbed frame ----

    @wp.func
    def blended(m: Material) -> bool:
        return m.blend_partner.shape[0] > 0

    @wp.func
    def partner(m: Material) -> Material:
        # the second BSDF as a Material: its own BSDF fields, the hit's frame fields (tangent, perturbation) of m
        p = m.blend_partner[0]
        r = m
        r.kind = p.kind
        r.reflectance = p.reflectance
        r.texture = -1
        r.alpha = p.alpha
        r.alpha_v = p.alpha
        r.anisotropic = 0
        r.distribution = p.distribution
        r.sample_visible = p.sample_visible
        r.eta = p.eta
        r.k = p.k
        r.transmittance = p.transmittance
        r.two_sided = p.two_sided
        r.specular_reflectance = p.specular_reflectance
        r.specular_weight = p.specular_weight
        r.internal_reflectance = p.internal_reflectance
        r.nonlinear = p.nonlinear
        r.external_transmittance = p.external_transmittance
        return r

    @wp.func
    def blend_sample(m: Material, wo: wp.vec3, u_lobe: float, u: wp.vec2) -> BsdfSample:
        if wp.static(has_blend):
            # f₁ when u_lobe <= w, else f₀, the lobe number rescaled (blendbsdf.cpp); the sample's weight is then
            # (P f_c/p_c·p_c + (1 − P) f_o)/(P p_c + (1 − P) p_o) for the chosen BSDF's probability P = w or 1 − w
            # (one-sample MIS over the two), its pdf the mixture P p_c + (1 − P) p_o. A delta sample (p_c its lobe's
            # probability, f_o, p_o the other BSDF's at its direction) takes the same weight, as in Mitsuba 3.9.1,
            # and the probability P p_c as its pdf. One call site per lobe function: the chosen BSDF is a variable.
            c = m
            o = m
            prob = float(1.0)
            ul = u_lobe
            if blended(m):
                w = m.blend_weight
                if u_lobe > w or w <= 0.0:
                    prob = 1.0 - w
                    ul = wp.min((u_lobe - w) / prob, 0.99999994)
                    o = partner(m)
                else:
                    prob = w
                    ul = wp.min(u_lobe / w, 0.99999994)
                    c = partner(m)
            s = oriented_sample(c, wo, ul, u)
            if prob < 1.0 and s.valid != 0:  # the other BSDF weighs 1 − P > 0
                p_o = oriented_pdf(o, wo, s.wi)
                pdf = prob * s.pdf + (1.0 - prob) * p_o
                if not (pdf > 0.0):
                    return _no_sample()
                chosen = prob * s.pdf
                s.weight = (s.weight * chosen + oriented_eval(o, wo, s.wi) * (1.0 - prob)) / pdf
                s.pdf = pdf
                if s.delta != 0:
                    s.pdf = chosen
            return s
        return oriented_sample(m, wo, u_lobe, u)

    @wp.func
    def blend_passes(m: Material) -> int:
        # (1 − w) f₀ + w f₁ is summed in a loop of one pass (no blend) or two: one call site of the lobes
        if blended(m):
            return 2
        return 1

    @wp.func
    def blend_pass(m: Material, j: int) -> Material:
        if j == 1:
            return partner(m)
        return m

    @wp.func
    def blend_share(m: Material, j: int) -> float:
        if not blended(m):
            return 1.0
        if j == 1:
            return m.blend_weight
        return 1.0 - m.blend_weight

    @wp.func
    def blend_eval(m: Material, wo: wp.vec3, wi: wp.vec3) -> wp.vec3:
        if wp.static(has_blend):
            r = wp.vec3(0.0, 0.0, 0.0)
            for j in range(blend_passes(m)):
                r += oriented_eval(blend_pass(m, j), wo, wi) * blend_share(m, j)
            return r
        return oriented_eval(m, wo, wi)

    @wp.func
    def blend_pdf(m: Material, wo: wp.vec3, wi: wp.vec3) -> float:
        if wp.static(has_blend):
            p = float(0.0)
            for j in range(blend_passes(m)):
                p += oriented_pdf(blend_pass(m, j), wo, wi) * blend_share(m, j)
            return p
        return oriented_pdf(m, wo, wi)

    # ---- wrappers: the perturbed frame (normalmap, bumpmap), then the mask ----

    @wp.func
    def frame_sample(m: Material, wo: wp.vec3, u_lobe: float, u: wp.vec2) -> BsdfSample:
        if wp.static(has_perturb):
            if m.perturb != PERTURB_NONE:
                n = _perturbed_normal(m, wo)
                f = frame_from_normal(n)
                s = blend_sample(perturbed_tangent(m, f), to_local(f, wo), u_lobe, u)
                wi = to_world(f, s.wi)
                if s.valid == 0 or s.wi[2] * wi[2] <= 0.0:
                    return _no_sample()
                s.wi = wi
                if (m.perturb_flags & 2) != 0:
                    s.weight = s.weight * shadow_terminator(n, wi)
                return s
        return blend_sample(m, wo, u_lobe, u)

    @wp.func
    def frame_eval(m: Material, wo: wp.vec3, wi: wp.vec3) -> wp.vec3:
        if wp.static(has_perturb):
            if m.perturb != PERTURB_NONE:
                f = frame_from_normal(_perturbed_normal(m, wo))
                if wi[2] * wp.dot(wi, f.n) <= 0.0:
                    return wp.vec3(0.0, 0.0, 0.0)
                v = blend_eval(perturbed_tangent(m, f), to_local(f, wo), to_local(f, wi))
                if (m.perturb_flags & 2) != 0:
                    v = v * shadow_terminator(f.n, wi)
                return v
        return blend_eval(m, wo, wi)

    @wp.func
    def frame_pdf(m: Material, wo: wp.vec3, wi: wp.vec3) -> float:
        if wp.static(has_perturb):
            if m.perturb != PERTURB_NONE:
                f = frame_from_normal(_perturbed_normal(m, wo))
                if wi[2] * wp.dot(wi, f.n) <= 0.0:
                    return 0.0
                return blend_pdf(perturbed_tangent(m, f), to_local(f, wo), to_local(f, wi))
        return blend_pdf(m, wo, wi)

    # A plain diffuse material (no mask, perturbed frame, blend, two sides) skips the wrappers and the kind
    # dispatch: where they are compiled in, LLVM leaves them out of line (the all-kinds kind_sample alone is
    # 78 kB of x86), and the all-kinds path tracer ran the Cornell box 27% slower than its own kernels (CPU);
    # with this, 10%. The same values, bit for bit (the scene-kinds tests compare the two).
    plain_fast_path = has_diffuse and (has_mask or has_perturb or has_blend or has_anisotropic)

    @wp.func
    def plain_diffuse(m: Material) -> bool:
        plain = m.kind == MATERIAL_DIFFUSE and m.two_sided == 0
        if wp.static(has_mask):
            plain = plain and m.opacity >= 1.0
        if wp.static(has_perturb):
            plain = plain and m.perturb == PERTURB_NONE
        if wp.static(has_blend):
            plain = plain and not blended(m)
        return plain

    @wp.func
    def sample(m: Material, wo: wp.vec3, u_lobe: float, u: wp.vec2) -> BsdfSample:
        if wp.static(plain_fast_path):
            if plain_diffuse(m):
                return diffuse_sample(m, wo, u_lobe, u)
        if wp.static(has_mask):
            if m.opacity < 1.0:
                if u_lobe >= m.opacity:
                    return null_sample(wo, 1.0 - m.opacity)
                s = frame_sample(m, wo, u_lobe / m.opacity, u)
                s.pdf = s.pdf * m.opacity
                return s
        return frame_sample(m, wo, u_lobe, u)

    @wp.func
    def eval(m: Material, wo: wp.vec3, wi: wp.vec3) -> wp.vec3:
        if wp.static(plain_fast_path):
            if plain_diffuse(m):
                return diffuse_eval(m, wo, wi)
        if wp.static(has_mask):
            return frame_eval(m, wo, wi) * m.opacity
        return frame_eval(m, wo, wi)

    @wp.func
    def pdf(m: Material, wo: wp.vec3, wi: wp.vec3) -> float:
        if wp.static(plain_fast_path):
            if plain_diffuse(m):
                return diffuse_pdf(m, wo, wi)
        if wp.static(has_mask):
            return frame_pdf(m, wo, wi) * m.opacity
        return frame_pdf(m, wo, wi)

    @wp.func
    def kind_albedo(m: Material) -> wp.vec3:
        if wp.static(has_diffuse):
            if m.kind == MATERIAL_DIFFUSE:
                return m.reflectance
        if wp.static(has_conductor or has_rough_conductor):
            if m.kind == MATERIAL_CONDUCTOR or m.kind == MATERIAL_ROUGH_CONDUCTOR:
                return wp.cw_mul(m.reflectance, average_fresnel_conductor(m.eta, m.k))
        if wp.static(has_dielectric or has_rough_dielectric):
            if m.kind == MATERIAL_DIELECTRIC or m.kind == MATERIAL_ROUGH_DIELECTRIC:
                f = average_fresnel_dielectric(m.eta[0])
                return m.reflectance * f + m.transmittance * (1.0 - f)
        if wp.static(has_plastic or has_rough_plastic or has_pplastic):
            if m.kind == MATERIAL_PLASTIC or m.kind == MATERIAL_ROUGH_PLASTIC or m.kind == MATERIAL_PPLASTIC:
                f = average_fresnel_dielectric(m.eta[0])  # the coating's F̄ over the base's ρ (it guides, it is not estimated)
                return m.specular_reflectance * f + m.reflectance * (1.0 - f)
        if wp.static(has_thin_dielectric):
            if m.kind == MATERIAL_THIN_DIELECTRIC:
                f = average_fresnel_dielectric(m.eta[0])
                r = 2.0 * f / (1.0 + f)  # the pane's R of an average F (an approximation: the albedo guides, it is not estimated)
                return m.reflectance * r + m.transmittance * (1.0 - r)
        if wp.static(has_principled or has_principled_thin):
            if m.kind == MATERIAL_PRINCIPLED or m.kind == MATERIAL_PRINCIPLED_THIN:
                return pr.principled_albedo(m)
        return wp.vec3(0.0, 0.0, 0.0)

    @wp.func
    def blend_albedo(m: Material) -> wp.vec3:
        if wp.static(has_blend):
            a = wp.vec3(0.0, 0.0, 0.0)
            for j in range(blend_passes(m)):
                a += kind_albedo(blend_pass(m, j)) * blend_share(m, j)
            return a
        return kind_albedo(m)

    @wp.func
    def albedo(m: Material) -> wp.vec3:
        if wp.static(has_mask):
            return blend_albedo(m) * m.opacity  # what passes through is not reflected
        return blend_albedo(m)

    @wp.func
    def kind_roughness(m: Material) -> float:
        if m.kind == MATERIAL_DIFFUSE:
            return 1.0
        if m.kind == MATERIAL_ROUGH_CONDUCTOR or m.kind == MATERIAL_ROUGH_DIELECTRIC or m.kind == MATERIAL_ROUGH_PLASTIC or m.kind == MATERIAL_PPLASTIC:
            return wp.min(m.alpha, m.alpha_v)  # anisotropic: as smooth as its smoothest direction
        if wp.static(has_principled or has_principled_thin):
            if m.kind == MATERIAL_PRINCIPLED or m.kind == MATERIAL_PRINCIPLED_THIN:
                return pr.principled_roughness(m)
        return 0.0  # smooth kinds, and plastic: its coating's delta lobe makes a path through it unreconnectable

    @wp.func
    def roughness(m: Material) -> float:
        if wp.static(has_mask):
            if _masked(m):
                return 0.0  # the null lobe beside the nested ones: as a plastic's coat, unreconnectable
        if wp.static(has_blend):
            if blended(m):
                return wp.min(kind_roughness(m), kind_roughness(partner(m)))  # as smooth as its smoother BSDF
        return kind_roughness(m)

    @wp.func
    def kind_is_delta(m: Material) -> int:
        if m.kind == MATERIAL_CONDUCTOR or m.kind == MATERIAL_DIELECTRIC or m.kind == MATERIAL_THIN_DIELECTRIC or m.kind == MATERIAL_NULL:
            return 1
        return 0

    @wp.func
    def is_delta(m: Material) -> int:
        if wp.static(has_blend):
            if blended(m):
                return kind_is_delta(m) * kind_is_delta(partner(m))  # all lobes delta only if both BSDFs are
        return kind_is_delta(m)

    @wp.func
    def has_delta_lobe(m: Material) -> int:
        """1 where some lobe is a delta (all-delta kinds, a smooth plastic's coat beside its diffuse base, a mask's
        null lobe, a delta BSDF in a blend): eval and pdf miss that lobe, so only BSDF sampling reaches what it reflects."""
        if kind_is_delta(m) != 0 or m.kind == MATERIAL_PLASTIC:
            return 1
        if wp.static(has_mask):
            if _masked(m):
                return 1
        if wp.static(has_blend):
            if blended(m):
                p = partner(m)
                if kind_is_delta(p) != 0 or p.kind == MATERIAL_PLASTIC:
                    return 1
        return 0

    funcs = BsdfFuncs(kinds=key, sample=sample, eval=eval, pdf=pdf, albedo=albedo, roughness=roughness, is_delta=is_delta,
                      has_delta_lobe=has_delta_lobe)
    _DISPATCH_CACHE[key] = funcs
    return funcs


_ALL_KINDS = make_bsdf(MATERIAL_KINDS)

#: all-kinds dispatch: ``bsdf_sample(m, wo, u_lobe, u) -> BsdfSample``
bsdf_sample = _ALL_KINDS.sample
#: all-kinds dispatch: ``bsdf_eval(m, wo, wi) -> vec3`` = f(wo, wi)|cos θ_i| (0 for delta kinds)
bsdf_eval = _ALL_KINDS.eval
#: all-kinds dispatch: ``bsdf_pdf(m, wo, wi) -> float`` (solid angle; 0 for delta kinds)
bsdf_pdf = _ALL_KINDS.pdf
#: all-kinds dispatch: ``bsdf_albedo(m) -> vec3`` (bi-hemispherical average reflectance)
bsdf_albedo = _ALL_KINDS.albedo
#: all-kinds dispatch: ``bsdf_roughness(m) -> float`` (0 smooth, α GGX, 1 diffuse)
bsdf_roughness = _ALL_KINDS.roughness
#: all-kinds dispatch: ``bsdf_is_delta(m) -> int``
bsdf_is_delta = _ALL_KINDS.is_delta
