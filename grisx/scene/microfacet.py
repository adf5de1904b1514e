"""Microfacet theory: the GGX and Beckmann distributions, Smith masking, visible-normal sampling, Fresnel.

A rough surface is modelled as a field of tiny perfect mirrors whose normals
m follow a distribution D(m) (per unit projected area, ∫ D(m) cos θ_m dm = 1).
All formulas are in the local shading frame (z = macro normal, x along the
tangent s) with roughness α = (α_u, α_v) along s and the bitangent t
(α_u = α_v: isotropic). Anisotropy stretches the microsurface: every formula
below holds with m_x/α, m_y/α → m_x/α_u, m_y/α_v, α² → α_u α_v in D's
normalization, and α² tan²θ_v → (α_u² v_x² + α_v² v_y²)/v_z² in Smith's
masking (Heitz 2014, Eqs. 80, 82, 85).

**GGX / Trowbridge–Reitz** (Walter et al. 2007, Eq. 33):

    D(m) = 1 / (π α_u α_v (m_x²/α_u² + m_y²/α_v² + m_z²)²)      for m_z > 0.

**Smith masking** for a direction v (Walter et al. 2007, Eq. 34; Heitz 2014,
Eq. 43 with Λ of GGX), with the orientation test that the back of a facet is
never seen:

    G1(v, m) = 2 / (1 + sqrt(1 + α² tan²θ_v))     if (v·m)(v·n) > 0, else 0,

and the separable two-direction form G2(wo, wi, m) = G1(wo, m) G1(wi, m)
(Mitsuba's ``G``).

**Visible normals** (Heitz 2018): the normals seen from wo have density

    D_wo(m) = G1(wo, m) max(0, wo·m) D(m) / cos θ_o               (Heitz 2018, Eq. 1)

and are sampled exactly by stretching wo to the α = 1 configuration, sampling
a point on the projected hemisphere (a disk whose lower half is squashed by
½(1 + cos θ)) and unstretching (Heitz 2018, Listing 1). Sampling D_wo instead
of D cos θ_m keeps the weight of a reflected sample to F·G1(wi, m) ≤ 1.

**Beckmann** (Walter et al. 2007, Eqs. 25–27; Mitsuba's default distribution):

    D(m) = exp(−tan²θ_m / α²) / (π α² cos⁴θ_m),
    G1(v, m) = (3.535a + 2.181a²) / (1 + 2.276a + 2.577a²) for a = 1/(α tan θ_v) < 1.6, else 1

(the rational fit of Smith's G1 that Mitsuba 3 evaluates).

**Sampling** (``sample_microfacet`` / ``microfacet_pdf``, a sampling pair, and
Mitsuba's ``sample_visible``). Visible normals (the default): GGX by Heitz 2018
as above, Beckmann by Heitz & d'Eon 2014 (stretch, the α = 1 slopes by
Mitsuba's numerical inversion of their CDF, rotate, unstretch). They are
distributed as D_wo with Smith's *exact* Beckmann masking
1/(1 + Λ), Λ(a) = (erf a − 1)/2 + e^{−a²}/(2a√π) (``beckmann_g1_exact``), so
that is the pdf; the fit's ratio G1/G1_exact (within 0.32% of 1) goes into the
sample's weight (``microfacet_visible_weight``), which stays eval/pdf exactly.
All normals (``sample_visible`` false): m ∝ D(m) cos θ_m, the azimuth first
(φ = 2π u₂, or anisotropic tan φ = (α_v/α_u) tan 2πu₂ in u₂'s quadrant), then
tan²θ_m = −α(φ)² ln(1 − u₁) (Beckmann) or α(φ)² u₁/(1 − u₁) (GGX), with
1/α(φ)² = cos²φ/α_u² + sin²φ/α_v²; the weight then carries
G1(wo, m)|wo·m|/(|cos θ_o| cos θ_m). ``microfacet_*`` dispatch on
``MICROFACET_GGX`` / ``MICROFACET_BECKMANN``.

**Fresnel.** A conductor with complex index η + i k (per RGB channel) reflects
the unpolarized fraction F_c(cos θ) of K. D. Möller's closed form (Mitsuba 3's
``fresnel_conductor``); η = 0, k = 1 reflects everything (a perfect mirror).
A dielectric with relative index η = η_int/η_ext (the normal points to the
exterior) reflects

    F = ½ (r_s² + r_p²),   r_s = (cos θ_i − η_it cos θ_t)/(cos θ_i + η_it cos θ_t),
                           r_p = (cos θ_t − η_it cos θ_i)/(cos θ_t + η_it cos θ_i),

with η_it = η seen from outside (cos θ_i ≥ 0) and 1/η from inside, and F = 1
under total internal reflection (``fresnel_dielectric`` returns F with the
signed cos θ_t and η_it, η_ti = 1/η_it as a ``FresnelDielectric`` record,
Mitsuba 3's ``fresnel``).

**A rough interface's albedos** (for ``roughplastic``, as Mitsuba 3's
``eval_transmittance`` / ``eval_reflectance``): light arriving from wi is
transmitted through a rough dielectric interface with probability

    T(wi) = ∫ D_wi(m) (1 − F(wi·m)) G1(wt, m) dm,     wt = refract(wi, m),

and reflected with R(wi) = ∫ D_wi(m) F(wi·m) G1(wr, m) dm (single scattering).
``rough_interface_table`` integrates both over the square of sample numbers
that ``sample_microfacet`` maps to m, with Gauss–Legendre nodes (32² for η > 1,
128² otherwise, as Mitsuba), weighting non-visible samples by
``microfacet_visible_weight``; it tabulates T at Mitsuba's 64 cosines
(``rough_table_lookup`` interpolates them linearly, as its ``lerp_gather``)
and returns the internal reflectance 2·mean(R(μ; 1/η) μ) over the same
cosines — Mitsuba's Riemann sum, kept so as to render what it renders.

References: B. Walter, S. Marschner, H. Li, K. Torrance, "Microfacet models
for refraction through rough surfaces", EGSR 2007; E. Heitz, "Understanding
the masking-shadowing function in microfacet-based BRDFs", JCGT 3(2), 2014;
E. Heitz, "Sampling the GGX distribution of visible normals", JCGT 7(4), 2018;
E. Heitz, E. d'Eon, "Importance sampling microfacet-based BSDFs using the
distribution of visible normals", EGSR 2014;
K. D. Möller, "Optics", 1988; W. Jakob et al., Mitsuba 3
``include/mitsuba/render/{microfacet,fresnel}.h``, ``src/bsdfs/roughplastic.cpp``.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import warp as wp

wp.set_module_options({"enable_backward": False})

__all__ = [
    "half_vector",
    "ALPHA_MIN",
    "FresnelDielectric",
    "ggx_d",
    "ggx_g1",
    "ggx_g2",
    "sample_ggx_vndf",
    "ggx_vndf_pdf",
    "MICROFACET_GGX",
    "MICROFACET_BECKMANN",
    "beckmann_d",
    "beckmann_g1",
    "beckmann_g1_exact",
    "sample_beckmann_vndf",
    "microfacet_d",
    "microfacet_g1",
    "microfacet_g2",
    "sample_microfacet",
    "microfacet_pdf",
    "microfacet_visible_weight",
    "fresnel_conductor",
    "fresnel_dielectric",
    "reflect",
    "refract",
    "ROUGH_TABLE_SIZE",
    "rough_interface_table",
    "rough_table_lookup",
]

#: smallest roughness used in kernels (Mitsuba clamps α to 1e-4 as well)
ALPHA_MIN = wp.constant(1.0e-4)
_PI = wp.constant(math.pi)
_INV_PI = wp.constant(1.0 / math.pi)
_SQRT_PI = wp.constant(math.sqrt(math.pi))
_INV_SQRT_PI = wp.constant(1.0 / math.sqrt(math.pi))


@wp.func
def _clamped(alpha: wp.vec2) -> wp.vec2:
    return wp.vec2(wp.max(alpha[0], ALPHA_MIN), wp.max(alpha[1], ALPHA_MIN))


@wp.func
def _projected_alpha2_tan2(v: wp.vec3, a: wp.vec2) -> float:
    # α(φ_v)² tan²θ_v = (α_u² v_x² + α_v² v_y²) / v_z²: the roughness seen along v's azimuth (Heitz 2014, Eq. 80)
    return (a[0] * a[0] * v[0] * v[0] + a[1] * a[1] * v[1] * v[1]) / (v[2] * v[2])


@wp.func
def ggx_d(m: wp.vec3, alpha: wp.vec2) -> float:
    """GGX normal distribution D(m) (Walter et al. 2007, Eq. 33; anisotropic: Heitz 2014, Eq. 85); 0 below the surface."""
    a = _clamped(alpha)
    x = m[0] / a[0]
    y = m[1] / a[1]
    s = x * x + y * y + m[2] * m[2]
    d = _INV_PI / (a[0] * a[1] * s * s)
    # Mitsuba's guard: drop denormal-sized values and the lower hemisphere
    if d * m[2] > 1.0e-20:
        return d
    return 0.0


@wp.func
def ggx_g1(v: wp.vec3, m: wp.vec3, alpha: wp.vec2) -> float:
    """Smith masking G1(v, m) of GGX (Walter et al. 2007, Eq. 34), 0 when v sees the back of m."""
    if wp.dot(v, m) * v[2] <= 0.0:
        return 0.0
    a = _clamped(alpha)
    if v[0] * v[0] + v[1] * v[1] == 0.0:
        return 1.0  # normal incidence: no masking
    tan2 = _projected_alpha2_tan2(v, a)  # α² tan²θ_v
    return 2.0 / (1.0 + wp.sqrt(1.0 + tan2))


@wp.func
def ggx_g2(wo: wp.vec3, wi: wp.vec3, m: wp.vec3, alpha: wp.vec2) -> float:
    """Separable shadowing-masking G1(wo, m) G1(wi, m) (Mitsuba's ``G``)."""
    return ggx_g1(wo, m, alpha) * ggx_g1(wi, m, alpha)


@wp.func
def sample_ggx_vndf(wo: wp.vec3, alpha: wp.vec2, u: wp.vec2) -> wp.vec3:
    """Microfacet normal m ~ D_wo (Heitz 2018, Listing 1); ``wo`` must lie in the upper hemisphere."""
    a = _clamped(alpha)
    # stretch to the hemisphere configuration (α = 1)
    vh = wp.normalize(wp.vec3(a[0] * wo[0], a[1] * wo[1], wo[2]))
    # orthonormal basis around vh (T1 = (1, 0, 0) when vh is the pole)
    lensq = vh[0] * vh[0] + vh[1] * vh[1]
    t1 = wp.vec3(1.0, 0.0, 0.0)
    if lensq > 0.0:
        t1 = wp.vec3(-vh[1], vh[0], 0.0) / wp.sqrt(lensq)
    t2 = wp.cross(vh, t1)
    # uniform point on the unit disk, lower half squashed to the projected hemisphere
    r = wp.sqrt(u[0])
    phi = 2.0 * _PI * u[1]
    p1 = r * wp.cos(phi)
    p2 = r * wp.sin(phi)
    s = 0.5 * (1.0 + vh[2])
    p2 = (1.0 - s) * wp.sqrt(wp.max(0.0, 1.0 - p1 * p1)) + s * p2
    # reproject onto the hemisphere and unstretch
    nh = p1 * t1 + p2 * t2 + wp.sqrt(wp.max(0.0, 1.0 - p1 * p1 - p2 * p2)) * vh
    return wp.normalize(wp.vec3(a[0] * nh[0], a[1] * nh[1], wp.max(0.0, nh[2])))


@wp.func
def ggx_vndf_pdf(wo: wp.vec3, m: wp.vec3, alpha: wp.vec2) -> float:
    """Density D_wo(m) = G1(wo, m) max(0, wo·m) D(m) / cos θ_o of ``sample_ggx_vndf`` (Heitz 2018, Eq. 1)."""
    if wo[2] <= 0.0:
        return 0.0
    return ggx_g1(wo, m, alpha) * wp.max(0.0, wp.dot(wo, m)) * ggx_d(m, alpha) / wo[2]


MICROFACET_GGX = wp.constant(0)
MICROFACET_BECKMANN = wp.constant(1)


@wp.func
def beckmann_d(m: wp.vec3, alpha: wp.vec2) -> float:
    """Beckmann normal distribution D(m) (Walter et al. 2007, Eq. 25; anisotropic: Heitz 2014, Eq. 82); 0 below the surface."""
    if m[2] <= 0.0:
        return 0.0
    a = _clamped(alpha)
    c2 = m[2] * m[2]
    x = m[0] / a[0]
    y = m[1] / a[1]
    d = wp.exp(-(x * x + y * y) / c2) / (_PI * a[0] * a[1] * c2 * c2)
    if d * m[2] > 1.0e-20:  # Mitsuba's guard, as for GGX
        return d
    return 0.0


@wp.func
def beckmann_g1(v: wp.vec3, m: wp.vec3, alpha: wp.vec2) -> float:
    """Smith masking of Beckmann by Walter et al.'s rational fit (Eq. 27, as Mitsuba 3), 0 when v sees the back of m."""
    if wp.dot(v, m) * v[2] <= 0.0:
        return 0.0
    a = _clamped(alpha)
    if v[0] * v[0] + v[1] * v[1] == 0.0:
        return 1.0
    b = 1.0 / wp.sqrt(_projected_alpha2_tan2(v, a))  # 1 / (α tan θ_v)
    if b >= 1.6:
        return 1.0
    return (3.535 * b + 2.181 * b * b) / (1.0 + 2.276 * b + 2.577 * b * b)


@wp.func
def microfacet_d(m: wp.vec3, alpha: wp.vec2, distribution: int) -> float:
    if distribution == MICROFACET_BECKMANN:
        return beckmann_d(m, alpha)
    return ggx_d(m, alpha)


@wp.func
def microfacet_g1(v: wp.vec3, m: wp.vec3, alpha: wp.vec2, distribution: int) -> float:
    if distribution == MICROFACET_BECKMANN:
        return beckmann_g1(v, m, alpha)
    return ggx_g1(v, m, alpha)


@wp.func
def microfacet_g2(wo: wp.vec3, wi: wp.vec3, m: wp.vec3, alpha: wp.vec2, distribution: int) -> float:
    """Separable shadowing-masking G1(wo, m) G1(wi, m) (Mitsuba's ``G``)."""
    return microfacet_g1(wo, m, alpha, distribution) * microfacet_g1(wi, m, alpha, distribution)


@wp.func
def beckmann_g1_exact(v: wp.vec3, m: wp.vec3, alpha: wp.vec2) -> float:
    """Smith's exact masking of Beckmann, 1/(1 + Λ(a)), Λ(a) = (erf(a) − 1)/2 + e^{−a²}/(2a√π), a = 1/(α tan θ_v)
    (Walter et al. 2007, Eq. 27 before its fit): the G1 of the visible normals that :func:`sample_microfacet` draws."""
    if wp.dot(v, m) * v[2] <= 0.0:
        return 0.0
    if v[0] * v[0] + v[1] * v[1] == 0.0:
        return 1.0
    a = 1.0 / wp.sqrt(_projected_alpha2_tan2(v, _clamped(alpha)))
    lam = 0.5 * (wp.erf(a) - 1.0) + wp.exp(-a * a) / (2.0 * a * _SQRT_PI)
    return 1.0 / (1.0 + lam)


@wp.func
def _beckmann_visible_slopes(cos_theta_i: float, u: wp.vec2) -> wp.vec2:
    # slopes of the α = 1 visible normals seen at cos θ_i: Heitz and d'Eon 2014, by Mitsuba 3's numerical inversion
    # of the slope CDF (an initial guess exact at grazing incidence, three Newton steps; microfacet.h sample_visible_11)
    tan_i = wp.sqrt(wp.max(0.0, 1.0 - cos_theta_i * cos_theta_i)) / cos_theta_i
    cot_i = 1.0e30
    if tan_i > 0.0:
        cot_i = 1.0 / tan_i
    maxval = wp.erf(cot_i)
    ux = wp.clamp(u[0], 1.0e-6, 1.0 - 1.0e-6)
    uy = wp.clamp(u[1], 1.0e-6, 1.0 - 1.0e-6)
    x = maxval - (maxval + 1.0) * wp.erf(wp.sqrt(-wp.log(ux)))
    ux = ux * (1.0 + maxval + _INV_SQRT_PI * tan_i * wp.exp(-cot_i * cot_i))
    for _k in range(3):
        slope = wp.erfinv(x)
        value = 1.0 + x + _INV_SQRT_PI * tan_i * wp.exp(-slope * slope) - ux
        x = x - value / (1.0 - slope * tan_i)
    return wp.vec2(wp.erfinv(x), wp.erfinv(2.0 * uy - 1.0))


@wp.func
def sample_beckmann_vndf(wo: wp.vec3, alpha: wp.vec2, u: wp.vec2) -> wp.vec3:
    """Microfacet normal m ~ D_wo of Beckmann (Heitz and d'Eon 2014: stretch, sample the α = 1 slopes, rotate, unstretch)."""
    a = _clamped(alpha)
    wh = wp.normalize(wp.vec3(a[0] * wo[0], a[1] * wo[1], wo[2]))
    sin_t = wp.sqrt(wh[0] * wh[0] + wh[1] * wh[1])
    cos_p = float(1.0)
    sin_p = float(0.0)
    if sin_t > 0.0:
        cos_p = wh[0] / sin_t
        sin_p = wh[1] / sin_t
    sl = _beckmann_visible_slopes(wh[2], u)
    sx = (cos_p * sl[0] - sin_p * sl[1]) * a[0]
    sy = (sin_p * sl[0] + cos_p * sl[1]) * a[1]
    return wp.normalize(wp.vec3(-sx, -sy, 1.0))


@wp.func
def sample_microfacet(wo: wp.vec3, alpha: wp.vec2, distribution: int, visible: int, u: wp.vec2) -> wp.vec3:
    """A microfacet normal: with ``visible`` (Mitsuba's ``sample_visible``, its default) the normals seen from ``wo``
    (upper hemisphere) of either distribution, else all normals ∝ D(m) cos θ_m (azimuth, then elevation)."""
    if visible != 0:
        if distribution == MICROFACET_BECKMANN:
            return sample_beckmann_vndf(wo, alpha, u)
        return sample_ggx_vndf(wo, alpha, u)
    a = _clamped(alpha)
    cos_p = float(0.0)
    sin_p = float(0.0)
    alpha2 = a[0] * a[0]
    if a[0] == a[1]:
        phi = 2.0 * _PI * u[1]
        cos_p = wp.cos(phi)
        sin_p = wp.sin(phi)
    else:
        # the azimuth's marginal of D cos θ_m: tan φ = (α_v/α_u) tan 2πu₂, in u₂'s quadrant (Mitsuba's microfacet.h)
        tmp = a[1] / a[0] * wp.tan(2.0 * _PI * u[1])
        cos_p = 1.0 / wp.sqrt(tmp * tmp + 1.0)
        if wp.abs(u[1] - 0.5) - 0.25 < 0.0:
            cos_p = -cos_p
        sin_p = cos_p * tmp
        alpha2 = 1.0 / ((cos_p / a[0]) * (cos_p / a[0]) + (sin_p / a[1]) * (sin_p / a[1]))
    tan2 = float(0.0)
    if distribution == MICROFACET_BECKMANN:
        tan2 = -alpha2 * wp.log(wp.max(1.0 - u[0], 1.0e-30))
    else:
        tan2 = alpha2 * u[0] / wp.max(1.0 - u[0], 1.0e-30)
    cos_t = 1.0 / wp.sqrt(1.0 + tan2)
    sin_t = wp.sqrt(wp.max(0.0, 1.0 - cos_t * cos_t))
    return wp.vec3(sin_t * cos_p, sin_t * sin_p, cos_t)


@wp.func
def microfacet_pdf(wo: wp.vec3, m: wp.vec3, alpha: wp.vec2, distribution: int, visible: int) -> float:
    """Density of :func:`sample_microfacet` (solid angle of m): D_wo(m) = G1(wo, m) max(0, wo·m) D(m) / cos θ_o with
    the exact G1 of the sampled distribution, or D(m) cos θ_m."""
    if visible != 0:
        if distribution == MICROFACET_BECKMANN:
            if wo[2] <= 0.0:
                return 0.0
            return beckmann_g1_exact(wo, m, alpha) * wp.max(0.0, wp.dot(wo, m)) * beckmann_d(m, alpha) / wo[2]
        return ggx_vndf_pdf(wo, m, alpha)
    return microfacet_d(m, alpha, distribution) * wp.max(0.0, m[2])


@wp.func
def microfacet_visible_weight(wo: wp.vec3, m: wp.vec3, alpha: wp.vec2, distribution: int, visible: int) -> float:
    """What a sample's weight G1(wi, m)·F owes to how m was drawn: G1(wo, m)|wo·m| / (|cos θ_o| cos θ_m) for all
    normals; for Beckmann's visible normals G1(wo, m) / G1_exact(wo, m) (the masking evaluated is Walter's fit, the
    one sampled Smith's exact); 1 for GGX's."""
    if visible == 0:
        return microfacet_g1(wo, m, alpha, distribution) * wp.abs(wp.dot(wo, m)) / (wp.abs(wo[2]) * m[2])
    if distribution == MICROFACET_BECKMANN:
        g = beckmann_g1_exact(wo, m, alpha)
        if g > 0.0:
            return beckmann_g1(wo, m, alpha) / g
        return 0.0
    return 1.0


@wp.func
def _fresnel_conductor_1(cos_i: float, eta_r: float, eta_i: float) -> float:
    # K. D. Möller, "Optics" (1988), as Mitsuba 3's fresnel_conductor; cos_i ≥ 0
    c2 = cos_i * cos_i
    s2 = 1.0 - c2
    s4 = s2 * s2
    temp1 = eta_r * eta_r - eta_i * eta_i - s2
    a2pb2 = wp.sqrt(wp.max(0.0, temp1 * temp1 + 4.0 * eta_i * eta_i * eta_r * eta_r))
    a = wp.sqrt(wp.max(0.0, 0.5 * (a2pb2 + temp1)))
    term1 = a2pb2 + c2
    term2 = 2.0 * cos_i * a
    r_s = (term1 - term2) / (term1 + term2)
    term3 = a2pb2 * c2 + s4
    term4 = term2 * s2
    r_p = r_s * (term3 - term4) / (term3 + term4)
    return 0.5 * (r_s + r_p)


@wp.func
def fresnel_conductor(cos_i: float, eta: wp.vec3, k: wp.vec3) -> wp.vec3:
    """Unpolarized reflectance of a conductor with complex index η + i k, per RGB channel (cos_i ≥ 0)."""
    c = wp.clamp(cos_i, 0.0, 1.0)
    return wp.vec3(
        _fresnel_conductor_1(c, eta[0], k[0]),
        _fresnel_conductor_1(c, eta[1], k[1]),
        _fresnel_conductor_1(c, eta[2], k[2]),
    )


@wp.struct
class FresnelDielectric:
    """Result of ``fresnel_dielectric``: reflectance ``f``, signed ``cos_t`` (opposite side to cos_i), ``eta_it``, ``eta_ti``."""

    f: float
    cos_t: float
    eta_it: float
    eta_ti: float


@wp.func
def fresnel_dielectric(cos_i: float, eta: float) -> FresnelDielectric:
    """Unpolarized dielectric Fresnel term for relative index η = η_int/η_ext (Mitsuba 3's ``fresnel``)."""
    r = FresnelDielectric()
    eta_it = eta
    eta_ti = 1.0 / eta
    if cos_i < 0.0:
        eta_it = 1.0 / eta
        eta_ti = eta
    # Snell's law: squared cosine of the transmitted ray (negative under total internal reflection)
    cos_t_sqr = 1.0 - (1.0 - cos_i * cos_i) * eta_ti * eta_ti
    ci = wp.abs(cos_i)
    ct = wp.sqrt(wp.max(0.0, cos_t_sqr))
    a_s = (ci - eta_it * ct) / (ci + eta_it * ct)
    a_p = (ct - eta_it * ci) / (ct + eta_it * ci)
    f = 0.5 * (a_s * a_s + a_p * a_p)
    if eta == 1.0:
        f = 0.0  # index-matched: no interface
    elif ci == 0.0 or cos_t_sqr <= 0.0:
        f = 1.0  # grazing, or total internal reflection (else 0/0 when ci underflows with ct = 0)
    r.f = f
    r.cos_t = ct
    if cos_i >= 0.0:
        r.cos_t = -ct
    r.eta_it = eta_it
    r.eta_ti = eta_ti
    return r


@wp.func
def half_vector(wo: wp.vec3, wi: wp.vec3, eta: float) -> wp.vec3:
    """The generalized half vector m ∝ wo + η wi (Walter et al. 2007, Eq. 16; η = 1 where wo and wi lie on one side),
    turned to the macro normal's side. ``eta``: the relative index seen from wo's side."""
    scale = eta
    if wo[2] * wi[2] > 0.0:
        scale = 1.0
    h = wp.normalize(wo + wi * scale)
    return h * wp.sign(h[2])


@wp.func
def reflect(v: wp.vec3, m: wp.vec3) -> wp.vec3:
    """Mirror ``v`` about the (micro)normal ``m``: 2 (v·m) m − v."""
    return 2.0 * wp.dot(v, m) * m - v


@wp.func
def refract(v: wp.vec3, m: wp.vec3, cos_t: float, eta_ti: float) -> wp.vec3:
    """Refract ``v`` through ``m`` given ``cos_t`` and ``eta_ti`` from ``fresnel_dielectric`` (Mitsuba's ``refract``)."""
    return m * (wp.dot(v, m) * eta_ti + cos_t) - v * eta_ti


# ---- a rough interface's transmittance and reflectance (roughplastic) ----

#: cosines at which the rough interface's transmittance is tabulated (Mitsuba's MI_ROUGH_TRANSMITTANCE_RES)
ROUGH_TABLE_SIZE = wp.constant(64)


@wp.kernel
def _rough_interface_kernel(
    mu: wp.array(dtype=float),
    eta: float,
    alpha: float,
    distribution: int,
    transmit: int,
    nodes: wp.array(dtype=float),
    weights: wp.array(dtype=float),
    out: wp.array(dtype=float),
):
    i = wp.tid()
    c = mu[i]
    wi = wp.vec3(wp.sqrt(wp.max(0.0, 1.0 - c * c)), 0.0, c)
    n = nodes.shape[0]
    ab = wp.vec2(alpha, alpha)  # roughplastic is isotropic
    visible = int(distribution == MICROFACET_GGX)  # the quadrature's map from the square to m (its integral is the same)
    acc = float(0.0)
    for a in range(n):
        for b in range(n):
            m = sample_microfacet(wi, ab, distribution, visible, wp.vec2(0.5 * nodes[a] + 0.5, 0.5 * nodes[b] + 0.5))
            w = microfacet_visible_weight(wi, m, ab, distribution, visible) * weights[a] * weights[b]
            fr = fresnel_dielectric(wp.dot(wi, m), eta)
            if transmit != 0:
                wt = refract(wi, m, fr.cos_t, fr.eta_ti)
                if wt[2] * wi[2] < 0.0:
                    acc += w * microfacet_g1(wt, m, ab, distribution) * (1.0 - fr.f)
            else:
                wr = reflect(wi, m)
                if wr[2] > 0.0 and wi[2] > 0.0:
                    acc += w * microfacet_g1(wr, m, ab, distribution) * fr.f
    out[i] = acc * 0.25  # the square [0, 1]² is a quarter of Gauss–Legendre's [−1, 1]²


def _rough_interface(mu: np.ndarray, eta: float, alpha: float, distribution: int, transmit: bool) -> np.ndarray:
    nodes, weights = np.polynomial.legendre.leggauss(32 if eta > 1.0 else 128)
    out = wp.zeros(len(mu), dtype=float, device="cpu")
    wp.launch(
        _rough_interface_kernel,
        len(mu),
        inputs=[
            wp.array(mu.astype(np.float32), dtype=float, device="cpu"),
            float(eta),
            float(alpha),
            int(distribution),
            int(transmit),
            wp.array(nodes.astype(np.float32), dtype=float, device="cpu"),
            wp.array(weights.astype(np.float32), dtype=float, device="cpu"),
        ],
        outputs=[out],
        device="cpu",
    )
    return out.numpy().astype(np.float64)


@functools.lru_cache(maxsize=64)
def rough_interface_table(eta: float, alpha: float, distribution: int) -> tuple[np.ndarray, float]:
    """(T at ``ROUGH_TABLE_SIZE`` cosines linspace(0, 1) (the first raised to 1e-6), internal reflectance
    2·mean(R(μ; 1/η) μ)) of a rough interface of relative index ``eta`` — Mitsuba 3's ``roughplastic``
    ``parameters_changed`` (computed on the CPU, cached per argument triple)."""
    mu = np.maximum(1.0e-6, np.linspace(0.0, 1.0, ROUGH_TABLE_SIZE))
    table = _rough_interface(mu, eta, alpha, distribution, True)
    internal = 2.0 * float(np.mean(_rough_interface(mu, 1.0 / eta, alpha, distribution, False) * mu))
    return table, internal


@wp.func
def rough_table_lookup(table: wp.array(dtype=float), cos_theta: float) -> float:
    """The table of ``rough_interface_table`` interpolated linearly at ``cos_theta`` ∈ [0, 1] (Mitsuba's ``lerp_gather``)."""
    x = wp.clamp(cos_theta, 0.0, 1.0) * float(ROUGH_TABLE_SIZE - 1)
    index = wp.min(int(x), ROUGH_TABLE_SIZE - 2)
    v0 = table[index]
    return v0 + (table[index + 1] - v0) * (x - float(index))
