"""The Disney principled BSDF and its thin-surface sibling, as Mitsuba 3 implements them.

Mitsuba 3's ``principled`` (Burley 2012, 2015) mixes per texel a diffuse base with Burley's
retro-reflection (and Hanrahan–Krueger's "fake subsurface" by ``flatness``), a sheen lobe, a GGX
specular lobe whose Fresnel term blends a metal's Schlick term (``metallic``), a tinted
dielectric's (``spec_tint``) and the true dielectric one, a GGX transmission lobe (``spec_trans``,
the rough dielectric's with a √base_color tint) and a GTR1 clearcoat lobe. With
brdf = (1 − metallic)(1 − spec_trans), bsdf = (1 − metallic) spec_trans, V = wo (toward the viewer;
Mitsuba's ``si.wi``), L = wi, h the (generalized) half vector turned up, F = F_dielectric(V·h; η):

    f cos θ_L =  F_p D G2 / (4 |cos θ_V|)                                  (specular reflection)
              + √c · bsdf · |η_V⁻² (1 − F) D G2 η² (V·h)(L·h) / (cos θ_V (V·h + η L·h)²)|  (transmission)
              + ¼ clearcoat · F_schlick(0.04) D_GTR1 G_cc |cos θ_L|        (clearcoat, Mitsuba's form)
              + brdf |cos θ_L| c/π · lerp(f_diff + f_retro, f_ss, flatness) (diffuse, retro, fake SSS)
              + sheen (1 − metallic) F_Schlick-weight(L·h) c_sheen |cos θ_L|     (sheen)

(principled.cpp ``eval``; the clearcoat term is Mitsuba's as written, without a 1/(4 cos θ_V cos θ_L)
— rendered as Mitsuba renders it). Sampling picks the diffuse lobe (cosine), the clearcoat (GTR1
normals), the transmission or the specular reflection (GGX visible normals of V, shared by both)
with Mitsuba's probabilities brdf : ¼ clearcoat : bsdf (1 − F) : 1 − bsdf (1 − F) on the front side,
(1 − F) : F inside; the pdf is the mixture and the weight eval/pdf, as Mitsuba's ``sample``.

``principledthin`` (principledthin.cpp) is a two-sided sheet: seen from either side it is mirrored
to the front, its specular lobes (GGX reflection, and GGX "transmission" through a roughness scaled
by 0.65 η − 0.35, Burley 2015 Fig. 15, that reflects and flips to the other side without bending)
weigh spec_trans, its diffuse reflection (1 − spec_trans)(1 − diff_trans/2), a Lambertian
transmission (1 − spec_trans) diff_trans/2; lobes chosen ½ spec_trans : ½ spec_trans : … by the same
weights.

**Fields.** Both kinds read their parameters from ``Material`` fields that no other lobe of theirs
uses (``grisx.scene.material`` packs them, ``_principled_params`` names them here):
``reflectance`` = base_color (``texture``: its texture), ``alpha`` = roughness, ``alpha_v`` =
anisotropic (textures in ``alpha_u_texture`` / ``alpha_v_texture``, resolved by the scene as a rough
conductor's α), ``anisotropic`` = Mitsuba's ``m_has_anisotropic`` (the lobe is turned to the shading
tangent), ``eta[0]`` = η, ``k`` = (metallic, spec_trans, spec_tint), ``transmittance`` = (sheen,
sheen_tint, flatness), ``specular_reflectance`` = (clearcoat, clearcoat_gloss, diff_trans),
``nonlinear`` = Mitsuba's ``m_has_spec_trans`` (it changes the pdf seen from inside), and
``lobe_textures``: up to four of those nine lobe weights given as textures (texture id · 16 + slot).

References: B. Burley, "Physically-based shading at Disney", SIGGRAPH 2012 course notes; B. Burley,
"Extending the Disney BRDF to a BSDF with integrated subsurface scattering", SIGGRAPH 2015 course
notes; W. Jakob et al., Mitsuba 3 ``src/bsdfs/{principled,principledthin}.cpp``, ``principledhelpers.h``.
"""

from __future__ import annotations

import math

import warp as wp

from grisx.scene.bsdf import BsdfSample, _no_sample, _weighted_sample, cosine_hemisphere_pdf, sample_cosine_hemisphere
from grisx.scene.material import MATERIAL_PRINCIPLED_THIN, Material
from grisx.scene.microfacet import (
    MICROFACET_GGX,
    fresnel_dielectric,
    half_vector,
    ggx_g1,
    microfacet_d,
    microfacet_g2,
    microfacet_pdf,
    reflect,
    refract,
    sample_microfacet,
)
from grisx.theory.gris import luminance

wp.set_module_options({"enable_backward": False})

__all__ = [
    "PRINCIPLED_SLOTS",
    "principled_eval",
    "principled_pdf",
    "principled_sample",
    "principled_thin_eval",
    "principled_thin_pdf",
    "principled_thin_sample",
    "principled_set_slot",
    "principled_albedo",
    "principled_roughness",
]

#: the nine lobe weights in ``Material`` slot order (k, transmittance, specular_reflectance), for ``lobe_textures``
PRINCIPLED_SLOTS = ("metallic", "spec_trans", "spec_tint", "sheen", "sheen_tint", "flatness", "clearcoat", "clearcoat_gloss",
                    "diff_trans")

_INV_PI = wp.constant(1.0 / math.pi)
_PI = wp.constant(math.pi)
_VISIBLE = wp.constant(1)  # Mitsuba's MicrofacetDistribution default: visible normals


@wp.func
def principled_set_slot(m: wp.ref[Material], slot: int, value: float):
    """Set ``m``'s lobe weight ``slot`` (an index into ``PRINCIPLED_SLOTS``) to ``value`` (a texture's at the hit), in place.

    In place rather than returning the Material: ``m = set_slot(m, ...)`` in the resolving loop made every
    all-kinds kernel keep its material in memory (CPU: Suffix ReSTIR's gather MIS 22% slower with it compiled in)."""
    j = slot % 3
    if slot < 3:
        v = m.k
        v[j] = value
        m.k = v
    elif slot < 6:
        v = m.transmittance
        v[j] = value
        m.transmittance = v
    else:
        v = m.specular_reflectance
        v[j] = value
        m.specular_reflectance = v


# ---- principledhelpers.h ----


@wp.func
def _schlick_weight(cos_i: float) -> float:
    # principledhelpers.h schlick_weight: clip(1 − cos, 0, 1)⁵
    x = wp.clamp(1.0 - cos_i, 0.0, 1.0)
    return x * x * x * x * x


@wp.func
def _calc_schlick(r0: wp.vec3, cos_i: float, eta: float) -> wp.vec3:
    # principledhelpers.h calc_schlick: R0 + (1 − R0) w, w of |cos θ_i| when η_it > 1, else of cos θ_t
    eta_it = eta
    eta_ti = 1.0 / eta
    if cos_i < 0.0:
        eta_it = 1.0 / eta
        eta_ti = eta
    cos_t = wp.sqrt(wp.max(0.0, 1.0 - (1.0 - cos_i * cos_i) * eta_ti * eta_ti))
    w = _schlick_weight(cos_t)
    if eta_it > 1.0:
        w = _schlick_weight(wp.abs(cos_i))
    one = wp.vec3(1.0, 1.0, 1.0)
    return w * (one - r0) + r0


@wp.func
def _schlick_r0(eta: float) -> float:
    # principledhelpers.h schlick_R0_eta
    x = (eta - 1.0) / (eta + 1.0)
    return x * x


@wp.func
def _tint(c: wp.vec3) -> wp.vec3:
    # c / lum(c), or white when lum(c) ≤ 0 (Mitsuba's c_tint)
    lum = luminance(c)
    if lum > 0.0:
        return c / lum
    return wp.vec3(1.0, 1.0, 1.0)


@wp.func
def _dist_alpha(anisotropic: float, roughness: float) -> wp.vec2:
    # principledhelpers.h calc_dist_params (Burley 2012): α = max(0.001, r² / aspect), max(0.001, r² aspect),
    # aspect = √(1 − 0.9 anisotropic); anisotropic 0 (or Mitsuba's has_anisotropic false) gives α_u = α_v = r²
    r2 = roughness * roughness
    aspect = wp.sqrt(1.0 - 0.9 * anisotropic)
    return wp.vec2(wp.max(0.001, r2 / aspect), wp.max(0.001, r2 * aspect))


@wp.func
def _mac_mic(h: wp.vec3, v: wp.vec3, l: wp.vec3, cos_v: float, reflection: int) -> bool:
    # principledhelpers.h mac_mic_compatibility: both directions on the facet's proper sides
    hs = h * wp.sign(cos_v)
    if reflection != 0:
        return wp.dot(v, hs) > 0.0 and wp.dot(l, hs) > 0.0
    return wp.dot(v, hs) > 0.0 and wp.dot(l, -hs) > 0.0


@wp.func
def _gtr1_d(h: wp.vec3, alpha: float) -> float:
    # principledhelpers.h GTR1Isotropic::eval (Burley 2012, Eq. 4 with γ = 1)
    c2 = h[2] * h[2]
    a2 = alpha * alpha
    d = (a2 - 1.0) / (_PI * wp.log(a2) * (1.0 + (a2 - 1.0) * c2))
    if d * h[2] > 1.0e-20:
        return d
    return 0.0


@wp.func
def _gtr1_pdf(h: wp.vec3, alpha: float) -> float:
    # GTR1Isotropic::pdf: D cos θ_h
    if h[2] < 0.0:
        return 0.0
    return h[2] * _gtr1_d(h, alpha)


@wp.func
def _gtr1_sample(u: wp.vec2, alpha: float) -> wp.vec3:
    # GTR1Isotropic::sample: φ = 2π u₁, cos²θ = (1 − α^{2(1 − u₂)}) / (1 − α²)
    phi = 2.0 * _PI * u[0]
    a2 = alpha * alpha
    c2 = (1.0 - wp.pow(a2, 1.0 - u[1])) / (1.0 - a2)
    s = wp.sqrt(wp.max(0.0, 1.0 - c2))
    return wp.vec3(wp.cos(phi) * s, wp.sin(phi) * s, wp.sqrt(wp.max(0.0, c2)))


@wp.func
def _clearcoat_alpha(m: Material) -> float:
    # principled.cpp: the clearcoat's roughness lerp(0.1, 0.001, clearcoat_gloss)
    g = m.specular_reflectance[1]
    return 0.1 * (1.0 - g) + 0.001 * g


@wp.func
def _diffuse_retro(m: Material, roughness: float, cos_v: float, cos_l: float, cos_d: float) -> float:
    # principled.cpp / principledthin.cpp: Burley's diffuse with retro-reflection, lerped to the fake subsurface
    fo = _schlick_weight(wp.abs(cos_l))
    fi = _schlick_weight(wp.abs(cos_v))
    f_diff = (1.0 - 0.5 * fi) * (1.0 - 0.5 * fo)
    rr = 2.0 * roughness * cos_d * cos_d
    f_retro = rr * (fo + fi + fo * fi * (rr - 1.0))
    fss90 = 0.5 * rr
    fss = (1.0 + (fss90 - 1.0) * fo) * (1.0 + (fss90 - 1.0) * fi)
    f_ss = 1.25 * (fss * (1.0 / (wp.abs(cos_l) + wp.abs(cos_v)) - 0.5) + 0.5)
    flatness = m.transmittance[2]
    return (f_diff + f_retro) * (1.0 - flatness) + f_ss * flatness


@wp.func
def _sheen(m: Material, cos_d: float) -> wp.vec3:
    # principled.cpp: sheen · Fd · lerp(1, c_tint, sheen_tint) (without the lobe weight and |cos θ_L|)
    one = wp.vec3(1.0, 1.0, 1.0)
    c_sheen = one + (_tint(m.reflectance) - one) * m.transmittance[1]
    return c_sheen * (m.transmittance[0] * _schlick_weight(wp.abs(cos_d)))


# ---- principled.cpp ----


@wp.struct
class _Probs:
    diffuse: float
    clearcoat: float
    spec_trans: float
    spec_reflect: float


@wp.func
def _principled_probs(m: Material, front: bool, f: float) -> _Probs:
    # principled.cpp sample()/pdf(): the lobe probabilities (sampling rates 1), normalized
    metallic = m.k[0]
    spec_trans = m.k[1]
    brdf = (1.0 - metallic) * (1.0 - spec_trans)
    bsdf = (1.0 - metallic) * spec_trans
    p = _Probs()
    p.diffuse = 0.0
    p.clearcoat = 0.0
    p.spec_trans = 0.0
    if front:
        p.spec_reflect = 1.0 - bsdf * (1.0 - f)
        p.spec_trans = bsdf * (1.0 - f)
        p.clearcoat = 0.25 * m.specular_reflectance[0]
        p.diffuse = brdf
    else:
        p.spec_reflect = f
        if (m.nonlinear & 1) != 0:  # Mitsuba's m_has_spec_trans
            p.spec_trans = 1.0 - f
    total = p.diffuse + p.clearcoat + p.spec_trans + p.spec_reflect
    if total > 0.0:
        r = 1.0 / total
        p.diffuse *= r
        p.clearcoat *= r
        p.spec_trans *= r
        p.spec_reflect *= r
    return p


@wp.func
def principled_eval(m: Material, wo: wp.vec3, wi: wp.vec3) -> wp.vec3:
    """f(wo, wi) |cos θ_i| of Mitsuba 3's ``principled`` (principled.cpp ``eval``; V = wo, L = wi)."""
    zero = wp.vec3(0.0, 0.0, 0.0)
    cos_v = wo[2]
    if cos_v == 0.0:
        return zero
    roughness = m.alpha
    metallic = m.k[0]
    spec_trans = m.k[1]
    spec_tint = m.k[2]
    clearcoat = m.specular_reflectance[0]
    base = m.reflectance
    brdf = (1.0 - metallic) * (1.0 - spec_trans)
    bsdf = (1.0 - metallic) * spec_trans
    cos_l = wi[2]
    is_reflect = cos_v * cos_l > 0.0
    is_refract = cos_v * cos_l < 0.0
    front = cos_v > 0.0
    eta = m.eta[0]
    eta_path = eta
    if not front:
        eta_path = 1.0 / eta
    alpha = _dist_alpha(m.alpha_v, roughness)
    h = half_vector(wo, wi, eta_path)
    dot_v = wp.dot(wo, h)
    dot_l = wp.dot(wi, h)
    f = fresnel_dielectric(dot_v, eta).f
    d = microfacet_d(h, alpha, MICROFACET_GGX)
    g = microfacet_g2(wo, wi, h, alpha, MICROFACET_GGX)
    value = zero
    if is_reflect and _mac_mic(h, wo, wi, cos_v, 1):
        if f > 0.0:
            # principled_fresnel: metal and tinted-dielectric Schlick terms beside the dielectric F (front side only)
            fp = wp.vec3(f, f, f) * bsdf
            if front:
                eta_it = eta
                if dot_v < 0.0:
                    eta_it = 1.0 / eta
                f_schlick = _calc_schlick(base, dot_v, eta) * metallic
                f_schlick += _calc_schlick(_tint(base) * _schlick_r0(eta_it), dot_v, eta) * ((1.0 - metallic) * spec_tint)
                fp = wp.vec3(f, f, f) * ((1.0 - metallic) * (1.0 - spec_tint)) + f_schlick
            value += fp * (d * g / (4.0 * wp.abs(cos_v)))
        if front and clearcoat > 0.0:
            # Mitsuba's clearcoat: ¼ cc · Schlick(0.04) · D_GTR1 · G(α = 0.25) · |cos θ_L|
            fcc = _calc_schlick(wp.vec3(0.04, 0.04, 0.04), dot_v, eta)[0]
            gcc = ggx_g1(wo, h, wp.vec2(0.25, 0.25)) * ggx_g1(wi, h, wp.vec2(0.25, 0.25))
            value += wp.vec3(1.0, 1.0, 1.0) * (0.25 * clearcoat * fcc * _gtr1_d(h, _clearcoat_alpha(m)) * gcc * wp.abs(cos_l))
    if is_refract and bsdf > 0.0 and f < 1.0 and _mac_mic(h, wo, wi, cos_v, 0):
        # the rough dielectric's transmission (Walter et al. 2007, Eq. 21) with the radiance scale 1/η_path², tinted √c
        denom = dot_v + eta_path * dot_l
        t = (1.0 - f) * d * g * dot_v * dot_l / (eta_path * eta_path * cos_v * denom * denom) * (eta_path * eta_path)
        value += wp.vec3(wp.sqrt(base[0]), wp.sqrt(base[1]), wp.sqrt(base[2])) * (bsdf * wp.abs(t))
    if is_reflect and front:
        cos_d = wp.dot(h, wi)
        if brdf > 0.0:
            value += base * (brdf * wp.abs(cos_l) * _INV_PI * _diffuse_retro(m, roughness, cos_v, cos_l, cos_d))
        # the llvm/cuda variants (what Mitsuba renders with) add the sheen under its own mask, brdf > 0 or not
        if m.transmittance[0] > 0.0 and 1.0 - metallic > 0.0:
            value += _sheen(m, cos_d) * ((1.0 - metallic) * wp.abs(cos_l))
    return value


@wp.func
def principled_pdf(m: Material, wo: wp.vec3, wi: wp.vec3) -> float:
    """The density of :func:`principled_sample` (principled.cpp ``pdf``)."""
    cos_v = wo[2]
    if cos_v == 0.0:
        return 0.0
    front = cos_v > 0.0
    eta = m.eta[0]
    eta_path = eta
    if not front:
        eta_path = 1.0 / eta
    cos_l = wi[2]
    is_reflect = cos_v * cos_l > 0.0
    is_refract = cos_v * cos_l < 0.0
    h = half_vector(wo, wi, eta_path)
    alpha = _dist_alpha(m.alpha_v, m.alpha)
    dot_v = wp.dot(wo, h)
    dot_l = wp.dot(wi, h)
    p = _principled_probs(m, front, fresnel_dielectric(dot_v, eta).f)
    # |dh/dL|: 1/(4 L·h) for reflection, η² L·h / (V·h + η L·h)² for transmission (Walter et al. 2007, Eqs. 14, 17)
    dh = wp.abs(1.0 / (4.0 * dot_l))
    if is_refract and (m.nonlinear & 1) != 0:
        denom = dot_v + eta_path * dot_l
        dh = wp.abs(eta_path * eta_path * dot_l / (denom * denom))
    pdf = float(0.0)
    v_up = wo * wp.sign(cos_v)
    if is_reflect:
        if _mac_mic(h, wo, wi, cos_v, 1):
            pdf += (p.spec_reflect * microfacet_pdf(v_up, h, alpha, MICROFACET_GGX, _VISIBLE) + p.clearcoat * _gtr1_pdf(h, _clearcoat_alpha(m))) * dh
        pdf += p.diffuse * cos_l * _INV_PI
    if is_refract and _mac_mic(h, wo, wi, cos_v, 0):
        pdf += p.spec_trans * microfacet_pdf(v_up, h, alpha, MICROFACET_GGX, _VISIBLE) * dh
    return pdf


@wp.func
def principled_sample(m: Material, wo: wp.vec3, u_lobe: float, u: wp.vec2) -> BsdfSample:
    """principled.cpp ``sample``: diffuse, clearcoat, transmission or specular reflection by Mitsuba's lobe
    probabilities (the specular pair split by F at the sampled GGX normal); weight = eval/pdf of the mixture."""
    cos_v = wo[2]
    if cos_v == 0.0:
        return _no_sample()
    front = cos_v > 0.0
    bsdf = (1.0 - m.k[0]) * m.k[1]
    if not front and bsdf <= 0.0:
        return _no_sample()
    alpha = _dist_alpha(m.alpha_v, m.alpha)
    h = sample_microfacet(wo * wp.sign(cos_v), alpha, MICROFACET_GGX, _VISIBLE, u)
    fr = fresnel_dielectric(wp.dot(wo, h), m.eta[0])
    p = _principled_probs(m, front, fr.f)
    wi = wp.vec3(0.0, 0.0, 1.0)
    eta = float(1.0)
    ok = bool(False)
    if u_lobe < p.diffuse:
        wi = sample_cosine_hemisphere(u)
        ok = cos_v * wi[2] > 0.0
    elif u_lobe < p.diffuse + p.clearcoat:
        hc = _gtr1_sample(u, _clearcoat_alpha(m))
        wi = reflect(wo, hc)
        ok = cos_v * wi[2] > 0.0 and _mac_mic(hc, wo, wi, cos_v, 1)
    elif u_lobe < p.diffuse + p.clearcoat + p.spec_trans:
        wi = refract(wo, h, fr.cos_t, fr.eta_ti)
        eta = fr.eta_it
        ok = cos_v * wi[2] < 0.0 and _mac_mic(h, wo, wi, cos_v, 0)
    else:
        wi = reflect(wo, h)
        ok = cos_v * wi[2] > 0.0 and _mac_mic(h, wo, wi, cos_v, 1)
    if not ok:
        return _no_sample()
    s = _weighted_sample(wi, principled_pdf(m, wo, wi), principled_eval(m, wo, wi))
    s.eta = eta
    return s


# ---- principledthin.cpp ----


@wp.func
def _thin_probs(m: Material) -> wp.vec4:
    # principledthin.cpp: (spec. reflection, spec. transmission, diffuse reflection, diffuse transmission), normalized
    spec_trans = m.k[1]
    diff_trans = 0.5 * m.specular_reflectance[2]  # Mitsuba's diff_trans ∈ [0, 2], halved
    p = wp.vec4(0.5 * spec_trans, 0.5 * spec_trans, (1.0 - spec_trans) * (1.0 - diff_trans), (1.0 - spec_trans) * diff_trans)
    total = p[0] + p[1] + p[2] + p[3]
    if total > 0.0:
        p = p / total
    return p


@wp.func
def _thin_trans_alpha(m: Material) -> wp.vec2:
    # principledthin.cpp: the transmission lobe's roughness scaled by 0.65 η − 0.35 (Burley 2015, Fig. 15)
    return _dist_alpha(m.alpha_v, (0.65 * m.eta[0] - 0.35) * m.alpha)


@wp.func
def principled_thin_eval(m: Material, wo: wp.vec3, wi: wp.vec3) -> wp.vec3:
    """f(wo, wi) |cos θ_i| of Mitsuba 3's ``principledthin`` (principledthin.cpp ``eval``), mirrored to the front."""
    zero = wp.vec3(0.0, 0.0, 0.0)
    if wo[2] == 0.0:
        return zero
    side = wp.sign(wo[2])
    v = wo * side
    l = wi * side
    cos_v = v[2]
    cos_l = l[2]
    spec_trans = m.k[1]
    diff_trans = 0.5 * m.specular_reflectance[2]
    base = m.reflectance
    eta = m.eta[0]
    h = wp.normalize(v + wp.vec3(l[0], l[1], wp.abs(l[2])))
    value = zero
    if spec_trans > 0.0:
        f = fresnel_dielectric(wp.dot(v, h), eta).f
        if cos_l > 0.0 and _mac_mic(h, v, l, cos_v, 1):
            # thin_fresnel: lerp(F, Schlick of the tinted R0, spec_tint)
            spec_tint = m.k[2]
            fs = _calc_schlick(_tint(base) * _schlick_r0(eta), wp.dot(v, h), eta)
            ft = wp.vec3(f, f, f) * (1.0 - spec_tint) + fs * spec_tint
            alpha = _dist_alpha(m.alpha_v, m.alpha)
            dg = microfacet_d(h, alpha, MICROFACET_GGX) * microfacet_g2(v, l, h, alpha, MICROFACET_GGX)
            value += ft * (spec_trans * dg / (4.0 * cos_v))
        if cos_l < 0.0 and _mac_mic(h, v, l, cos_v, 0):
            alpha_t = _thin_trans_alpha(m)
            dg = microfacet_d(h, alpha_t, MICROFACET_GGX) * microfacet_g2(v, l, h, alpha_t, MICROFACET_GGX)
            value += base * (spec_trans * (1.0 - f) * dg / (4.0 * cos_v))
    if spec_trans < 1.0:
        if cos_l > 0.0 and diff_trans < 1.0:
            cos_d = wp.dot(h, l)
            lobe = (1.0 - spec_trans) * (1.0 - diff_trans) * cos_l
            value += base * (lobe * _INV_PI * _diffuse_retro(m, m.alpha, cos_v, cos_l, cos_d)) + _sheen(m, cos_d) * lobe
        if cos_l < 0.0 and diff_trans > 0.0:
            value += base * ((1.0 - spec_trans) * diff_trans * _INV_PI * wp.abs(cos_l))
    return value


@wp.func
def principled_thin_pdf(m: Material, wo: wp.vec3, wi: wp.vec3) -> float:
    """The density of :func:`principled_thin_sample` (principledthin.cpp ``pdf``)."""
    if wo[2] == 0.0:
        return 0.0
    side = wp.sign(wo[2])
    v = wo * side
    l = wi * side
    p = _thin_probs(m)
    pdf = float(0.0)
    if m.k[1] > 0.0:
        lr = wp.vec3(l[0], l[1], wp.abs(l[2]))
        h = wp.normalize(v + lr)
        dh = wp.abs(1.0 / (4.0 * wp.dot(lr, h)))
        if l[2] > 0.0 and _mac_mic(h, v, l, v[2], 1):
            pdf += p[0] * microfacet_pdf(v, h, _dist_alpha(m.alpha_v, m.alpha), MICROFACET_GGX, _VISIBLE) * dh
        if l[2] < 0.0 and _mac_mic(h, v, l, v[2], 0):
            pdf += p[1] * microfacet_pdf(v, h, _thin_trans_alpha(m), MICROFACET_GGX, _VISIBLE) * dh
    if l[2] > 0.0:
        pdf += p[2] * cosine_hemisphere_pdf(l)
    if l[2] < 0.0:
        pdf += p[3] * cosine_hemisphere_pdf(-l)
    return pdf


@wp.func
def principled_thin_sample(m: Material, wo: wp.vec3, u_lobe: float, u: wp.vec2) -> BsdfSample:
    """principledthin.cpp ``sample``: GGX reflection, GGX "transmission" (reflected, then flipped through the
    sheet), cosine reflection or cosine transmission; weight = eval/pdf of the mixture; no bending (η = 1)."""
    if wo[2] == 0.0:
        return _no_sample()
    side = wp.sign(wo[2])
    v = wo * side
    p = _thin_probs(m)
    l = wp.vec3(0.0, 0.0, 1.0)
    ok = bool(True)
    if u_lobe < p[0]:
        h = sample_microfacet(v, _dist_alpha(m.alpha_v, m.alpha), MICROFACET_GGX, _VISIBLE, u)
        l = reflect(v, h)
        ok = l[2] > 0.0 and _mac_mic(h, v, l, v[2], 1)
    elif u_lobe < p[0] + p[1]:
        h = sample_microfacet(v, _thin_trans_alpha(m), MICROFACET_GGX, _VISIBLE, u)
        l = reflect(v, h)
        l = wp.vec3(l[0], l[1], -l[2])
        ok = l[2] < 0.0 and _mac_mic(h, v, l, v[2], 0)
    elif u_lobe < p[0] + p[1] + p[2]:
        l = sample_cosine_hemisphere(u)
    else:
        l = -sample_cosine_hemisphere(u)
        ok = p[3] > 0.0
    if not ok:
        return _no_sample()
    wi = l * side
    return _weighted_sample(wi, principled_thin_pdf(m, wo, wi), principled_thin_eval(m, wo, wi))


# ---- what the renderers ask of every kind: a guiding albedo and a roughness ----


@wp.func
def principled_albedo(m: Material) -> wp.vec3:
    """A guide (seed 002's albedo; not estimated): base_color, the colour of the diffuse, metal and tinted lobes."""
    return m.reflectance


@wp.func
def principled_roughness(m: Material) -> float:
    """The smoothest lobe's α: the GGX lobes' (``principledthin``'s transmission included where spec_trans > 0),
    the clearcoat's where clearcoat > 0; a thin sheet without spec_trans is diffuse (1)."""
    a = _dist_alpha(m.alpha_v, m.alpha)
    r = wp.min(a[0], a[1])
    if m.kind == MATERIAL_PRINCIPLED_THIN:
        if m.k[1] <= 0.0:
            return 1.0
        t = _thin_trans_alpha(m)
        return wp.min(r, wp.min(t[0], t[1]))
    if m.specular_reflectance[0] > 0.0:
        r = wp.min(r, _clearcoat_alpha(m))
    return r
