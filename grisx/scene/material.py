"""Materials: Python records with Mitsuba 3's names and defaults, packed into one Warp struct per material.

A scene describes its surfaces with frozen records that mirror Mitsuba 3's
BSDF plugins parameter by parameter, so that the XML loader is a plain
mapping and a scene renders the same picture in both systems:

=====================  ==========================  =========================================
record                 Mitsuba plugin              lobes (see ``grisx.scene.bsdf``)
=====================  ==========================  =========================================
``Diffuse``            ``diffuse``                 Lambertian reflection
``Conductor``          ``conductor``               delta reflection, complex Fresnel
``RoughConductor``     ``roughconductor`` (GGX)    microfacet reflection
``Dielectric``         ``dielectric``              delta reflection + refraction
``RoughDielectric``    ``roughdielectric`` (GGX)   microfacet reflection + refraction
``Plastic``            ``plastic``                 delta coating reflection + diffuse base
``RoughPlastic``       ``roughplastic``            microfacet coating reflection + diffuse base
``Null``               ``null``                    none: the ray passes through (a delta lobe)
``Principled``         ``principled``              Disney's principled BSDF (Burley 2012, 2015)
``PrincipledThin``     ``principledthin``          its thin-sheet sibling (no bending)
``PolarizedPlastic``   ``pplastic`` (RGB variant)  microfacet reflection + Fresnel-weighted Lambertian base
``Polarizer``          ``polarizer`` (RGB)         the null lobe, weight ½ transmittance
``Retarder``           ``retarder`` (RGB)          the null lobe, weight transmittance
=====================  ==========================  =========================================

Mitsuba's polarization plugins are read as its RGB (unpolarized) variants evaluate them, which is
exact for unpolarized transport: ``pplastic``'s non-polarized branch, a polarizer that passes half
the light whatever its angle, a retarder that passes all of it (``pplastic.cpp``, ``polarizer.cpp``,
``retarder.cpp``). They add no field to ``Material``: ``pplastic`` fills the plastic fields, and the
null kind's sample weight is ``transmittance`` (1 for ``null``).

Three **wrappers** hold one of those records, as Mitsuba's plugins nest one BSDF:

* ``Mask(bsdf, opacity)`` (``mask``): the nested BSDF with probability
  ``opacity`` (a number or a texture's luminance), otherwise the ray passes
  straight through (Mitsuba's *null* lobe: wi = −wo, weight 1, pdf 1 − opacity);
  eval and pdf are the nested ones times the opacity. A null transmission is a
  path vertex as in Mitsuba's ``path`` integrator (it counts toward
  ``max_depth``, and shadow rays stop at the surface: light behind it arrives
  through BSDF sampling only).
* ``NormalMap(bsdf, normalmap)`` (``normalmap``) and ``BumpMap(bsdf, texture,
  scale)`` (``bumpmap``): the nested BSDF in a shading frame perturbed by a
  texture (a tangent-space normal 2·rgb − 1, or the gradient of a height field),
  resolved at each hit into the struct's ``perturbed_n``; see
  :mod:`grisx.scene.bsdf` for the wrapper's lobes.

A wrapper may hold another wrapper of a different type (``Mask(NormalMap(...))``);
``material_kinds`` reports each wrapper present as a pseudo-kind
(``MATERIAL_MASK``, ``MATERIAL_NORMALMAP``, ``MATERIAL_BUMPMAP``) beside the
nested kinds, so a dispatch compiles the wrapper code only for scenes that use it;
likewise ``MATERIAL_ANISOTROPIC`` where some rough conductor has α_u ≠ α_v,
``MATERIAL_REFLECTANCE_TEXTURE`` where some reflectance is a texture
(:func:`has_reflectance_texture`), ``MATERIAL_PROCEDURAL_BUMP`` where some
material has a procedural bump (:func:`has_procedural_bump`), and
``MATERIAL_SCALAR_TEXTURES`` where some material resolves scalars at the hit
(:func:`resolves_scalars`: a textured mask opacity or α, a blend, a principled
BSDF's textured lobes). The ``SCENE_*`` pseudo-kinds are the scene's, not a
material's (:class:`~grisx.scene.scene.SceneFeatures` adds them): analytic shapes
(the ray queries compile the shapes in), delta lights, an environment map and
textured emitters (light sampling compiles their code in), and objects that move
(shifts across frames compile their suffix replay in).

Every record carries ``two_sided`` (set by the loader for Mitsuba's
``twosided`` wrapper): a one-sided reflecting BSDF is black seen from the back,
a two-sided one mirrors the frame. Dielectrics are two-sided by nature (their
back side is the interior, with η inverted) and ignore the flag, as Mitsuba
refuses to wrap them.

Rough records take ``distribution`` ``"ggx"`` or ``"beckmann"`` (Mitsuba's
default) with an isotropic ``alpha`` (``RoughConductor`` also Mitsuba's
anisotropic ``alpha_u`` / ``alpha_v``, numbers or textures) and
``sample_visible`` (Mitsuba's default true: m drawn from the normals visible
from wo, else from D(m) cos θ_m; :mod:`grisx.scene.microfacet`), which changes
the variance, not the image.

Conductor indices come from ``conductor_material(name)``: RGB η and k for
Mitsuba's measured presets (the spectral ``data/ior/<name>.{eta,k}.spd`` tables
integrated to linear sRGB, as tabulated by Tungsten's ``ComplexIorData`` and
pbrt-v3), and ``"none"`` = η 0, k 1, a perfect mirror (Mitsuba 3's default).

``pack_materials`` turns a list of records into ``wp.array(dtype=Material)``
indexed by material id; ``material_kinds`` gives the set of kinds present,
which ``grisx.scene.bsdf.make_bsdf`` uses to compile only the needed lobes.

``Material`` has exactly the contract's fields; how the records fill them:
``eta`` of a dielectric holds the relative index int_ior/ext_ior in all three
channels, ``reflectance`` of conductors and dielectrics holds
``specular_reflectance`` and ``transmittance`` holds ``specular_transmittance``.
The records add ``bump_amplitude`` / ``bump_frequency`` (copied to the struct)
so a scene can attach normal perturbation to a material.

Plastics (a dielectric coating of relative index η over a diffuse base, with
the light trapped under the coating summed in closed form) fill ``reflectance``
with ``diffuse_reflectance`` (so a texture resolves there as for ``diffuse``),
``eta`` with int_ior/ext_ior, and four fields of their own, precomputed at
packing as Mitsuba 3 precomputes them in ``parameters_changed``:
``specular_reflectance`` (the coating's tint), ``specular_weight`` (Mitsuba's
``specular_sampling_weight`` = s̄/(d̄ + s̄) of the two reflectances' means),
``internal_reflectance`` (the fraction of diffuse light the coating reflects
back down: Fdr(1/η) of d'Eon and Irving's fit for ``plastic``, the rough
interface's hemispherical average for ``roughplastic``), ``nonlinear``, and
for ``roughplastic`` the table ``external_transmittance`` of the rough
interface's transmittance at 64 cosines (:func:`grisx.scene.microfacet.rough_interface_table`).

References: W. Jakob et al., Mitsuba 3 plugin documentation (``diffuse``,
``conductor``, ``roughconductor``, ``dielectric``, ``roughdielectric``,
``twosided``, ``plastic``, ``roughplastic``, ``principled``, ``principledthin``); W. Jakob, Tungsten renderer ``ComplexIorData.hpp``;
E. d'Eon, G. Irving, "A quantized-diffusion model for rendering translucent materials",
SIGGRAPH 2011 (the Fdr fit); J. Egan, T. Hilgeman, "Optical properties of inhomogeneous
materials", 1979 (Fdr for η < 1).
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np
import warp as wp

from grisx.errors import InvalidParameterError, InvalidValueError, UnknownNameError
from grisx.scene.microfacet import ROUGH_TABLE_SIZE, rough_interface_table

wp.set_module_options({"enable_backward": False})

__all__ = [
    "ALL_MATERIAL_KINDS",
    "kernel_kinds",
    "MATERIAL_DIFFUSE",
    "MATERIAL_CONDUCTOR",
    "MATERIAL_ROUGH_CONDUCTOR",
    "MATERIAL_DIELECTRIC",
    "MATERIAL_ROUGH_DIELECTRIC",
    "MATERIAL_THIN_DIELECTRIC",
    "MATERIAL_PLASTIC",
    "MATERIAL_ROUGH_PLASTIC",
    "MATERIAL_NULL",
    "MATERIAL_MASK",
    "MATERIAL_NORMALMAP",
    "MATERIAL_BUMPMAP",
    "MATERIAL_ANISOTROPIC",
    "MATERIAL_SCALAR_TEXTURES",
    "MATERIAL_REFLECTANCE_TEXTURE",
    "MATERIAL_PROCEDURAL_BUMP",
    "SCENE_ANALYTIC_SHAPES",
    "SCENE_DELTA_LIGHTS",
    "SCENE_ENVMAP",
    "SCENE_EMITTER_TEXTURES",
    "SCENE_MOVING_OBJECTS",
    "SCENE_KINDS",
    "MATERIAL_PPLASTIC",
    "MATERIAL_BLEND",
    "MATERIAL_WRAPPERS",
    "MATERIAL_PRINCIPLED",
    "MATERIAL_PRINCIPLED_THIN",
    "PERTURB_NONE",
    "PERTURB_NORMALMAP",
    "PERTURB_BUMPMAP",
    "MATERIAL_KINDS",
    "MATERIAL_KIND_NAMES",
    "TextureRef",
    "Diffuse",
    "Conductor",
    "RoughConductor",
    "Dielectric",
    "RoughDielectric",
    "ThinDielectric",
    "Plastic",
    "RoughPlastic",
    "Null",
    "PolarizedPlastic",
    "Polarizer",
    "Retarder",
    "BlendBSDF",
    "Principled",
    "PrincipledThin",
    "BlendPartner",
    "is_general_blend",
    "Mask",
    "NormalMap",
    "BumpMap",
    "unwrap",
    "MaterialDesc",
    "CONDUCTOR_PRESETS",
    "conductor_material",
    "fresnel_diffuse_reflectance",
    "Material",
    "material_kind",
    "material_kinds",
    "is_anisotropic",
    "resolves_scalars",
    "pack_materials",
    "principled_has",
]

MATERIAL_DIFFUSE = wp.constant(0)
MATERIAL_CONDUCTOR = wp.constant(1)
MATERIAL_ROUGH_CONDUCTOR = wp.constant(2)
MATERIAL_DIELECTRIC = wp.constant(3)
MATERIAL_ROUGH_DIELECTRIC = wp.constant(4)
MATERIAL_THIN_DIELECTRIC = wp.constant(5)
MATERIAL_PLASTIC = wp.constant(6)
MATERIAL_ROUGH_PLASTIC = wp.constant(7)
MATERIAL_NULL = wp.constant(8)
# wrappers: pseudo-kinds in a kinds set (a material's ``kind`` is its nested BSDF's)
MATERIAL_MASK = wp.constant(9)
MATERIAL_NORMALMAP = wp.constant(10)
MATERIAL_BUMPMAP = wp.constant(11)
#: a feature pseudo-kind: some rough material is anisotropic (α_u ≠ α_v), so the BSDF needs the shading frame's tangent
MATERIAL_ANISOTROPIC = wp.constant(12)
#: a feature pseudo-kind: some material resolves scalars at the hit (a mask's opacity, a textured α, a blend's
#: weight, a principled BSDF's textured lobes): ``surface_material`` compiles that loop in only then
MATERIAL_SCALAR_TEXTURES = wp.constant(13)
#: a feature pseudo-kind: some material's reflectance is a texture (a diffuse reflectance, a plastic's diffuse
#: reflectance, a principled base colour): ``surface_material`` compiles the texture lookup in only then
MATERIAL_REFLECTANCE_TEXTURE = wp.constant(14)
#: a feature pseudo-kind: some material has a procedural bump (``bump_amplitude`` > 0: seed 003's caustic casters):
#: ``intersect`` perturbs the shading normal, and the caustics differentiate it, only then
MATERIAL_PROCEDURAL_BUMP = wp.constant(15)
# ---- principled (grisx.scene.principled); ids 16, 17 leave room for kinds added beside them
#: Mitsuba 3's ``principled`` and ``principledthin`` (Disney's principled BSDF, Burley 2012, 2015)
MATERIAL_PRINCIPLED = wp.constant(16)
MATERIAL_PRINCIPLED_THIN = wp.constant(17)
# ---- plugins2 (issue 38): kinds of Mitsuba's polarization-family plugins read as their RGB variants do ----
#: Mitsuba's ``pplastic`` in an unpolarized variant: a microfacet coat reflection beside a smooth-Fresnel-weighted Lambertian base
MATERIAL_PPLASTIC = wp.constant(20)
#: a wrapper pseudo-kind: some material is a ``blendbsdf`` of two BSDFs other than two Lambertian ones (its second BSDF
#: rides in ``Material.blend_partner``; the dispatch mixes the two)
MATERIAL_BLEND = wp.constant(21)
# ---- end plugins2 ----
# ---- scene pseudo-kinds: what the scene has besides its materials (``SceneFeatures.material_kinds`` holds them beside
# the materials' kinds), so that code every kernel inlines is compiled only for scenes that use it
#: analytic shapes (grisx.scene.analytic): the ray queries compile their BVH and quadrics in (``make_surface``)
SCENE_ANALYTIC_SHAPES = wp.constant(24)
#: delta lights (point, spot, projector, directional): light sampling compiles their branch in (``make_lights``)
SCENE_DELTA_LIGHTS = wp.constant(25)
#: an environment map: light sampling and environment lookups compile its image and distribution in (``make_lights``)
SCENE_ENVMAP = wp.constant(26)
#: an area emitter with a radiance image: emission compiles its texture lookup in (``make_lights``)
SCENE_EMITTER_TEXTURES = wp.constant(27)
#: objects that move between frames: shifts across frames compile the suffix replay that tests what moved in
#: (``make_path_shift``'s ``suffix_moved``)
SCENE_MOVING_OBJECTS = wp.constant(28)
#: the scene pseudo-kinds
SCENE_KINDS: tuple[int, ...] = (SCENE_ANALYTIC_SHAPES, SCENE_DELTA_LIGHTS, SCENE_ENVMAP, SCENE_EMITTER_TEXTURES, SCENE_MOVING_OBJECTS)
#: the wrapper pseudo-kinds
MATERIAL_WRAPPERS: tuple[int, ...] = (MATERIAL_MASK, MATERIAL_NORMALMAP, MATERIAL_BUMPMAP)
#: Material.perturb values: no perturbation, a normal map, a bump map
PERTURB_NONE = wp.constant(0)
PERTURB_NORMALMAP = wp.constant(1)
PERTURB_BUMPMAP = wp.constant(2)

#: every kind, in id order
MATERIAL_KINDS: tuple[int, ...] = (
    MATERIAL_DIFFUSE,
    MATERIAL_CONDUCTOR,
    MATERIAL_ROUGH_CONDUCTOR,
    MATERIAL_DIELECTRIC,
    MATERIAL_ROUGH_DIELECTRIC,
    MATERIAL_THIN_DIELECTRIC,
    MATERIAL_PLASTIC,
    MATERIAL_ROUGH_PLASTIC,
    MATERIAL_NULL,
    MATERIAL_MASK,
    MATERIAL_NORMALMAP,
    MATERIAL_BUMPMAP,
    MATERIAL_ANISOTROPIC,
    MATERIAL_SCALAR_TEXTURES,
    MATERIAL_REFLECTANCE_TEXTURE,
    MATERIAL_PROCEDURAL_BUMP,
    MATERIAL_PRINCIPLED,
    MATERIAL_PRINCIPLED_THIN,
    MATERIAL_PPLASTIC,
    MATERIAL_BLEND,
    *SCENE_KINDS,
)
#: Mitsuba plugin name of each kind
#: microfacet distributions of the rough records → grisx.scene.microfacet's MICROFACET_* ids
MICROFACET_DISTRIBUTIONS: dict[str, int] = {"ggx": 0, "beckmann": 1}

MATERIAL_KIND_NAMES: dict[int, str] = {
    MATERIAL_DIFFUSE: "diffuse",
    MATERIAL_CONDUCTOR: "conductor",
    MATERIAL_ROUGH_CONDUCTOR: "roughconductor",
    MATERIAL_DIELECTRIC: "dielectric",
    MATERIAL_ROUGH_DIELECTRIC: "roughdielectric",
    MATERIAL_THIN_DIELECTRIC: "thindielectric",
    MATERIAL_PLASTIC: "plastic",
    MATERIAL_ROUGH_PLASTIC: "roughplastic",
    MATERIAL_NULL: "null",
    MATERIAL_MASK: "mask",
    MATERIAL_NORMALMAP: "normalmap",
    MATERIAL_BUMPMAP: "bumpmap",
    MATERIAL_ANISOTROPIC: "anisotropic",
    MATERIAL_SCALAR_TEXTURES: "scalar textures",
    MATERIAL_REFLECTANCE_TEXTURE: "reflectance texture",
    MATERIAL_PROCEDURAL_BUMP: "procedural bump",
    MATERIAL_PRINCIPLED: "principled",
    MATERIAL_PRINCIPLED_THIN: "principledthin",
    MATERIAL_PPLASTIC: "pplastic",
    MATERIAL_BLEND: "blendbsdf",
    SCENE_ANALYTIC_SHAPES: "analytic shapes",
    SCENE_DELTA_LIGHTS: "delta lights",
    SCENE_ENVMAP: "envmap",
    SCENE_EMITTER_TEXTURES: "emitter textures",
    SCENE_MOVING_OBJECTS: "moving objects",
}

#: every kind a kernel can be compiled for
ALL_MATERIAL_KINDS: frozenset[int] = frozenset(int(k) for k in MATERIAL_KIND_NAMES)

#: ``GRISX_KERNEL_KINDS``: which kinds renderers compile their kernels for, ``scene`` (the default: the kinds the
#: scene uses, the leanest kernels) or ``all`` (one kernel set per renderer serves every scene)
KERNEL_KINDS_ENV = "GRISX_KERNEL_KINDS"


def kernel_kinds(kinds: Iterable[int]) -> frozenset[int]:
    """The material kinds to compile kernels for, given the kinds a scene uses.

    Kernels are specialised on the scene's kinds (``make_bsdf``): each set of kinds is its own
    compilation, seconds on the CPU and more on CUDA. A process that renders many scenes of
    different kinds — the test suite renders ~100 — pays one compilation per renderer and set;
    with ``GRISX_KERNEL_KINDS=all`` it pays one per renderer. The images are the same (the
    specialisation only leaves out the code of absent kinds; ``tests/scene/test_bsdf.py`` checks it).
    """
    policy = os.environ.get(KERNEL_KINDS_ENV, "scene")
    if policy == "all":
        return ALL_MATERIAL_KINDS
    if policy != "scene":
        raise InvalidParameterError(f"{KERNEL_KINDS_ENV}={policy!r}: expected 'scene' or 'all'")
    return frozenset(int(k) for k in kinds)


RGB = tuple[float, float, float]

# RGB (linear sRGB) complex IOR of Mitsuba's measured conductor presets: eta, k. Every material of
# Mitsuba 3's ``data/ior`` (mitsuba-data ``ior/NAME.eta.spd``, ``NAME.k.spd``) as its rgb variants read
# ``material="NAME"`` (``ior_from_file``): each spectrum reduced by ``spectrum_list_to_srgb`` without
# D65 and unbounded, negative components clamped to 0 (as its ``srgb`` texture does, with a warning).
# Values: Mitsuba 3.9.1 ``scalar_rgb`` (float32), ``mi.traverse(conductor)['eta.value']``, ``['k.value']``;
# grisx's :func:`grisx.scene.spectrum.spectrum_list_to_srgb` gives them to 1e-6 (tests/scene/test_spectrum.py).
# ``none``: a perfect mirror (Mitsuba's default).
CONDUCTOR_PRESETS: dict[str, tuple[RGB, RGB]] = {
    "none": ((0.0, 0.0, 0.0), (1.0, 1.0, 1.0)),
    "a-C": ((2.94404578, 2.22713637, 1.9681617), (0.887464881, 0.799298525, 0.815289974)),
    "Ag": ((0.155276194, 0.116727956, 0.138387635), (4.82835436, 3.12222242, 2.14690113)),
    "Al": ((1.65750086, 0.880404711, 0.521244466), (9.22381115, 6.26950216, 4.83700418)),
    "AlAs": ((3.6052959, 3.23293781, 2.21631861), (0.000679437304, 0, 0.00751270913)),
    "AlAs_palik": ((3.6052959, 3.23293781, 2.21631861), (0.000679437304, 0, 0.00751270913)),
    "AlSb": ((0, 4.13937473, 4.6692543), (0, 0.094009079, 1.30057001)),
    "AlSb_palik": ((0, 4.13937473, 4.6692543), (0, 0.094009079, 1.30057001)),
    "Au": ((0.143035978, 0.375307083, 1.44204533), (3.98299694, 2.38555646, 1.60335922)),
    "Be": ((4.18501234, 3.18502927, 2.78406119), (3.83546591, 3.0101223, 2.868994)),
    "Be_palik": ((4.18501234, 3.18502927, 2.78406119), (3.83546591, 3.0101223, 2.868994)),
    "Cr": ((4.36966753, 2.91650534, 1.6549046), (5.20654678, 4.23130608, 3.75469875)),
    "CsI": ((2.14489961, 1.70231891, 1.66242719), (0, 0, 0)),
    "CsI_palik": ((2.14489961, 1.70231891, 1.66242719), (0, 0, 0)),
    "Cu": ((0.201005474, 0.923749506, 1.10221541), (3.91326213, 2.45304513, 2.14208984)),
    "Cu2O": ((3.55177259, 2.94986963, 2.7518754), (0.114207022, 0.19389686, 0.606133878)),
    "Cu2O_palik": ((3.55177259, 2.94986963, 2.7518754), (0.114207022, 0.19389686, 0.606133878)),
    "Cu_palik": ((0.213228509, 0.919715405, 1.10241079), (3.92187333, 2.45733166, 2.13658404)),
    "CuO": ((3.24754095, 2.44780517, 2.21021962), (0.521089554, 0.570030749, 0.722178936)),
    "CuO_palik": ((3.24754095, 2.44780517, 2.21021962), (0.521089554, 0.570030749, 0.722178936)),
    "d-C": ((2.70871973, 2.31882572, 2.22889757), (0, 0, 0)),
    "d-C_palik": ((2.70871973, 2.31882572, 2.22889757), (0, 0, 0)),
    "Hg": ((2.39893866, 1.44002795, 0.909570396), (6.32758713, 4.37192488, 3.42176366)),
    "Hg_palik": ((2.39893866, 1.44002795, 0.909570396), (6.32758713, 4.37192488, 3.42176366)),
    "HgTe": ((4.77903986, 3.23119617, 2.65990114), (1.63161266, 1.58081043, 1.72928739)),
    "HgTe_palik": ((4.77903986, 3.23119617, 2.65990114), (1.63161266, 1.58081043, 1.72928739)),
    "Ir": ((3.0862999, 2.08219051, 1.61791456), (5.59215307, 4.06708813, 3.26731205)),
    "Ir_palik": ((3.0862999, 2.08219051, 1.61791456), (5.59215307, 4.06708813, 3.26731205)),
    "K": ((0.0640431866, 0.0464097671, 0.0381849147), (2.10419965, 1.34894001, 0.913125873)),
    "K_palik": ((0.0640431866, 0.0464097671, 0.0381849147), (2.10419965, 1.34894001, 0.913125873)),
    "Li": ((0.265790939, 0.195618317, 0.220948622), (3.54015493, 2.31112337, 1.66860723)),
    "Li_palik": ((0.265790939, 0.195618317, 0.220948622), (3.54015493, 2.31112337, 1.66860723)),
    "MgO": ((2.08958387, 1.65072346, 1.59487903), (4.33269523e-12, 0, 2.49864573e-11)),
    "MgO_palik": ((2.08958387, 1.65072346, 1.59487903), (4.33269523e-12, 0, 2.49864573e-11)),
    "Mo": ((4.48397398, 3.52513075, 2.77631044), (4.11143732, 3.42082691, 3.15060735)),
    "Mo_palik": ((4.48397398, 3.52513075, 2.77631044), (4.11143732, 3.42082691, 3.15060735)),
    "Na_palik": ((0.0602693558, 0.0561409481, 0.061988432), (3.17927337, 2.11249042, 1.57904112)),
    "Nb": ((3.42007399, 2.79009318, 2.39562941), (3.44139457, 2.73766613, 2.57974577)),
    "Nb_palik": ((3.42007399, 2.79009318, 2.39562941), (3.44139457, 2.73766613, 2.57974577)),
    "Ni_palik": ((2.36730456, 1.66337311, 1.46707809), (4.49881172, 3.05015302, 2.3454392)),
    "Rh": ((2.5857935, 1.86021638, 1.55426335), (6.78226042, 4.70298719, 3.97607303)),
    "Rh_palik": ((2.5857935, 1.86021638, 1.55426335), (6.78226042, 4.70298719, 3.97607303)),
    "Se": ((4.05831146, 2.84293509, 2.82085347), (0.75404954, 0.63844353, 0.521807551)),
    "Se-e": ((5.72284889, 4.1657362, 4.08133841), (0.871136308, 1.10515749, 1.56532025)),
    "Se-e_palik": ((5.72284889, 4.1657362, 4.08133841), (0.871136308, 1.10515749, 1.56532025)),
    "Se_palik": ((4.05831146, 2.84293509, 2.82085347), (0.75404954, 0.63844353, 0.521807551)),
    "SiC": ((3.17234159, 2.52597165, 2.47937059), (7.53766358e-07, 0, 1.01925307e-05)),
    "SiC_palik": ((3.17234159, 2.52597165, 2.47937059), (7.53766358e-07, 0, 1.01925307e-05)),
    "SnTe": ((4.52424955, 1.98164499, 1.2815913), (0, 0, 0)),
    "SnTe_palik": ((4.52424955, 1.98164499, 1.2815913), (0, 0, 0)),
    "Ta": ((2.06272101, 2.39293885, 2.62792873), (2.40835977, 1.74148643, 1.9470278)),
    "Ta_palik": ((2.06272101, 2.39293885, 2.62792873), (2.40835977, 1.74148643, 1.9470278)),
    "Te": ((7.39023352, 4.48210478, 2.63710594), (3.25602221, 3.52705884, 3.29205418)),
    "Te-e": ((7.50890684, 4.29642868, 2.36998773), (5.58392859, 4.94720507, 3.99759221)),
    "Te-e_palik": ((7.50890684, 4.29642868, 2.36998773), (5.58392859, 4.94720507, 3.99759221)),
    "Te_palik": ((7.39023352, 4.48210478, 2.63710594), (3.25602221, 3.52705884, 3.29205418)),
    "ThF4": ((1.83071363, 1.44222856, 1.38764763), (0, 0, 0)),
    "ThF4_palik": ((1.83071363, 1.44222856, 1.38764763), (0, 0, 0)),
    "TiC": ((3.70052838, 2.83742213, 2.58228707), (3.26563501, 2.3515892, 2.17279053)),
    "TiC_palik": ((3.70052838, 2.83742213, 2.58228707), (3.26563501, 2.3515892, 2.17279053)),
    "TiN": ((1.64844966, 1.15051603, 1.37982345), (3.36832809, 1.94349813, 1.10206771)),
    "TiN_palik": ((1.64844966, 1.15051603, 1.37982345), (3.36832809, 1.94349813, 1.10206771)),
    "TiO2": ((3.45660996, 2.80173588, 2.90517497), (0.000105264837, 0, 0.00065288652)),
    "TiO2-e": ((3.10656452, 2.51316833, 2.58244443), (2.97516053e-05, 0, 0.000182698088)),
    "TiO2-e_palik": ((3.10656452, 2.51316833, 2.58244443), (2.97516053e-05, 0, 0.000182698088)),
    "TiO2_palik": ((3.45660996, 2.80173588, 2.90517497), (0.000105264837, 0, 0.00065288652)),
    "V_palik": ((4.27758217, 3.51294875, 2.76107144), (3.49130082, 2.88945484, 3.11152196)),
    "VC": ((3.65756607, 2.75273609, 2.53267193), (3.06830072, 2.19868731, 1.9631927)),
    "VC_palik": ((3.65756607, 2.75273609, 2.53267193), (3.06830072, 2.19868731, 1.9631927)),
    "VN": ((2.86560225, 2.11918902, 1.94009113), (3.03224254, 2.05611563, 1.6163063)),
    "VN_palik": ((2.86560225, 2.11918902, 1.94009113), (3.03224254, 2.05611563, 1.6163063)),
    "W": ((4.37081671, 3.30024648, 2.99840736), (3.50064063, 2.6048739, 2.27323318)),
}


def conductor_material(name: str) -> tuple[RGB, RGB]:
    """RGB ``(eta, k)`` of Mitsuba's conductor preset ``name`` (``Au``, ``a-C``, ``Cu_palik``, ... or ``none`` = perfect mirror)."""
    if name not in CONDUCTOR_PRESETS:
        raise UnknownNameError("conductor material", name, list(CONDUCTOR_PRESETS))
    eta, k = CONDUCTOR_PRESETS[name]
    # A channel whose eta and k both clamp to 0 (AlSb's red) is a mirror in Mitsuba: its conductor Fresnel
    # term is 1 for eta = 0 whatever k (0/0 at exact normal incidence); k = 1 there, as in ``none``.
    k = tuple(1.0 if e == 0.0 and kk == 0.0 else kk for e, kk in zip(eta, k))
    return eta, k


@dataclasses.dataclass(frozen=True)
class TextureRef:
    """A texture registered on the Scene (``Scene.add_texture`` returns the id)."""

    texture_id: int


_NONE_ETA, _NONE_K = CONDUCTOR_PRESETS["none"]


@dataclasses.dataclass(frozen=True)
class Diffuse:
    """Mitsuba ``diffuse``: Lambertian reflection of ``reflectance`` (RGB or a texture)."""

    reflectance: RGB | float | TextureRef = (0.5, 0.5, 0.5)
    two_sided: bool = False
    bump_amplitude: float = 0.0
    bump_frequency: float = 0.0


@dataclasses.dataclass(frozen=True)
class Conductor:
    """Mitsuba ``conductor``: a smooth metal (delta reflection); default material ``none`` = perfect mirror."""

    eta: RGB | float = _NONE_ETA
    k: RGB | float = _NONE_K
    specular_reflectance: RGB | float = (1.0, 1.0, 1.0)
    two_sided: bool = False
    bump_amplitude: float = 0.0
    bump_frequency: float = 0.0


@dataclasses.dataclass(frozen=True)
class RoughConductor:
    """Mitsuba ``roughconductor``: microfacet metal of roughness ``alpha`` (``distribution`` ggx or beckmann).

    Anisotropic: ``alpha_u`` and ``alpha_v`` (both, numbers or :class:`TextureRef`, whose luminance at the hit is
    used) replace ``alpha``: the roughness along the shading frame's tangent s (along ∂p/∂u) and bitangent t = n × s.
    A surface without a parametrization (analytic shapes, meshes without uv) takes Mitsuba's s of its ∂p/∂u."""

    alpha: float = 0.1
    distribution: str = "ggx"
    eta: RGB | float = _NONE_ETA
    k: RGB | float = _NONE_K
    specular_reflectance: RGB | float = (1.0, 1.0, 1.0)
    two_sided: bool = False
    bump_amplitude: float = 0.0
    bump_frequency: float = 0.0
    alpha_u: float | TextureRef | None = None
    alpha_v: float | TextureRef | None = None
    sample_visible: bool = True


@dataclasses.dataclass(frozen=True)
class Dielectric:
    """Mitsuba ``dielectric``: smooth glass (delta reflection + refraction); BK7 in air by default."""

    int_ior: float = 1.5046
    ext_ior: float = 1.000277
    specular_reflectance: RGB | float = (1.0, 1.0, 1.0)
    specular_transmittance: RGB | float = (1.0, 1.0, 1.0)
    two_sided: bool = False  # ignored: dielectrics have two sides by nature
    bump_amplitude: float = 0.0
    bump_frequency: float = 0.0


@dataclasses.dataclass(frozen=True)
class RoughDielectric:
    """Mitsuba ``roughdielectric``: microfacet reflection + refraction (Walter et al. 2007), ggx or beckmann.
    ``alpha``: a number, or a :class:`TextureRef` whose luminance at the hit is the roughness (clamped to 1e-4 as Mitsuba)."""

    alpha: float | TextureRef = 0.1
    distribution: str = "ggx"
    int_ior: float = 1.5046
    ext_ior: float = 1.000277
    specular_reflectance: RGB | float = (1.0, 1.0, 1.0)
    specular_transmittance: RGB | float = (1.0, 1.0, 1.0)
    two_sided: bool = False  # ignored: dielectrics have two sides by nature
    bump_amplitude: float = 0.0
    bump_frequency: float = 0.0
    sample_visible: bool = True


@dataclasses.dataclass(frozen=True)
class ThinDielectric:
    """Mitsuba ``thindielectric``: a thin pane of glass (delta reflection + straight transmission).

    The light inside the pane is summed in closed form: with F the Fresnel reflectance at the
    first interface, R = F + (1 − F)² F / (1 − F²) = 2F / (1 + F) is reflected and T = 1 − R
    passes through undeflected (Mitsuba's ``thindielectric``)."""

    int_ior: float = 1.5046
    ext_ior: float = 1.000277
    specular_reflectance: RGB | float = (1.0, 1.0, 1.0)
    specular_transmittance: RGB | float = (1.0, 1.0, 1.0)
    two_sided: bool = False  # ignored: a pane has two sides by nature
    bump_amplitude: float = 0.0
    bump_frequency: float = 0.0


@dataclasses.dataclass(frozen=True)
class Plastic:
    """Mitsuba ``plastic``: a smooth dielectric coating (delta reflection) over a diffuse base.

    Light refracted into the coating scatters off the base of ``diffuse_reflectance`` ρ and
    bounces between base and coating; summed, the diffuse lobe is
    ρ/(1 − Fdr) · (1 − F(cos θ_o))(1 − F(cos θ_i)) cos θ_i / (π η²) with Fdr the coating's
    internal diffuse reflectance (``nonlinear``: ρ/(1 − ρ Fdr), the darker, more saturated
    colour of real varnished surfaces). Polypropylene (1.49) in air by default, as Mitsuba.
    ``diffuse_mean``: the mean of a texture given as ``diffuse_reflectance`` (Mitsuba's
    ``texture.mean()``, which sets the lobe sampling weights; 0.5 if not given)."""

    diffuse_reflectance: RGB | float | TextureRef = (0.5, 0.5, 0.5)
    specular_reflectance: RGB | float = (1.0, 1.0, 1.0)
    int_ior: float = 1.49
    ext_ior: float = 1.000277
    nonlinear: bool = False
    diffuse_mean: float | None = None
    two_sided: bool = False
    bump_amplitude: float = 0.0
    bump_frequency: float = 0.0


@dataclasses.dataclass(frozen=True)
class RoughPlastic(Plastic):
    """Mitsuba ``roughplastic``: a rough dielectric coating (microfacet reflection, ggx or beckmann) over a diffuse base.

    As :class:`Plastic` (its fields, then ``alpha`` and ``distribution``), with the smooth
    interface's Fresnel transmittances replaced by the rough interface's (tabulated at 64
    cosines) and Fdr by the rough interface's internal hemispherical reflectance, both
    integrated as Mitsuba 3's ``roughplastic`` does."""

    alpha: float = 0.1
    distribution: str = "ggx"
    sample_visible: bool = True


@dataclasses.dataclass(frozen=True)
class Null:
    """Mitsuba ``null``: no interaction — the ray goes on unchanged (a delta lobe wi = −wo of weight 1).

    Used for surfaces that only bound something (a medium, an emitter's shape); as in Mitsuba's
    ``path`` integrator, passing one is a path vertex (it counts toward ``max_depth``) and
    shadow rays stop at it."""

    two_sided: bool = False  # ignored: nothing to mirror
    bump_amplitude: float = 0.0
    bump_frequency: float = 0.0


# ---- plugins2 (issue 38): pplastic and polarizer, as Mitsuba 3's unpolarized (RGB) variants evaluate them ----


@dataclasses.dataclass(frozen=True)
class PolarizedPlastic:
    """Mitsuba ``pplastic`` as its unpolarized variants evaluate it (``pplastic.cpp``, the non-polarized branch).

    Not a coated model (no light trapped under a coating, no 1/η²): the sum of a microfacet reflection and a
    Lambertian base attenuated by two smooth refractions,
    f cos θ_i = spec · F(wo·h) D G2 / (4 cos θ_o) + ρ (1 − F(cos θ_o)) (1 − F(cos θ_i)) cos θ_i / π,
    with F the dielectric Fresnel term of η = int_ior/ext_ior. The glossy lobe is sampled with the constant
    probability s̄/(d̄ + s̄) of the two reflectances' means (``diffuse_mean`` for a texture, as
    :class:`Plastic`), the base by cosine. ``alpha`` (a number or a texture), or ``alpha_u``/``alpha_v``
    (anisotropic, numbers or textures, as :class:`RoughConductor`); ``distribution`` defaults to Beckmann, as
    Mitsuba's. Packed into the plastic fields (``reflectance`` = ρ, ``specular_reflectance``, ``specular_weight``,
    ``eta``); no field of its own."""

    diffuse_reflectance: RGB | float | TextureRef = (0.5, 0.5, 0.5)
    specular_reflectance: RGB | float = (1.0, 1.0, 1.0)
    int_ior: float = 1.49
    ext_ior: float = 1.000277
    alpha: float | TextureRef = 0.1
    distribution: str = "beckmann"
    sample_visible: bool = True
    alpha_u: float | TextureRef | None = None
    alpha_v: float | TextureRef | None = None
    diffuse_mean: float | None = None
    two_sided: bool = False
    bump_amplitude: float = 0.0
    bump_frequency: float = 0.0


@dataclasses.dataclass(frozen=True)
class Polarizer:
    """Mitsuba ``polarizer`` as its unpolarized variants evaluate it (``polarizer.cpp``): a null interaction
    (wi = −wo, a delta lobe of probability 1) that passes ½ · ``transmittance`` of the light, whatever the
    polarizer's angle ``theta`` (ignored: unpolarized light loses half its power to any linear polarizer; two
    crossed polarizers pass ¼, not 0, as in Mitsuba's RGB variants). Packed as a ``null`` material whose
    ``transmittance`` field holds the ½ · transmittance (``null`` itself: 1)."""

    transmittance: RGB | float = (1.0, 1.0, 1.0)
    two_sided: bool = False  # ignored: a null interaction looks the same from both sides
    bump_amplitude: float = 0.0
    bump_frequency: float = 0.0


@dataclasses.dataclass(frozen=True)
class Retarder(Polarizer):
    """Mitsuba ``retarder`` as its unpolarized variants evaluate it (``retarder.cpp``): a null interaction that passes
    ``transmittance`` (a wave plate changes only the polarization state; its ``theta`` and ``delta`` are ignored)."""


# ---- end plugins2 ----


@dataclasses.dataclass(frozen=True)
class Mask:
    """Mitsuba ``mask``: ``bsdf`` where the surface is opaque, a null interaction elsewhere.

    ``opacity`` (a number in [0, 1] or a :class:`TextureRef`, whose luminance is used, clamped to
    [0, 1]; Mitsuba's default 0.5): the nested BSDF is chosen with that probability and its eval and
    pdf scaled by it; otherwise the ray passes straight through (weight 1, pdf 1 − opacity)."""

    bsdf: Any
    opacity: float | TextureRef = 0.5


@dataclasses.dataclass(frozen=True)
class NormalMap:
    """Mitsuba ``normalmap``: ``bsdf`` in the shading frame whose normal is 2·``normalmap`` − 1 in the
    unperturbed shading frame (s along ∂p/∂u, t = n × s, n); ``flip_invalid_normals`` mirrors a normal
    the outgoing direction cannot see, ``use_shadowing_function`` applies Estevez et al.'s shadowing
    term (both Mitsuba's defaults: true). The texture should be read ``raw``."""

    bsdf: Any
    normalmap: TextureRef
    flip_invalid_normals: bool = True
    use_shadowing_function: bool = True


@dataclasses.dataclass(frozen=True)
class BumpMap:
    """Mitsuba ``bumpmap``: ``bsdf`` in the shading frame of the height field ``scale`` · ``texture``
    (its luminance) over the surface: ∂p/∂u += n (scale ∂h/∂u − n·∂p/∂u), likewise for v, and the
    normal (∂p/∂u × ∂p/∂v) turned to the geometric normal's side; flags as :class:`NormalMap`."""

    bsdf: Any
    texture: TextureRef
    scale: float = 1.0
    flip_invalid_normals: bool = True
    use_shadowing_function: bool = True


@dataclasses.dataclass(frozen=True)
class BlendBSDF:
    """Mitsuba ``blendbsdf``: (1 − w) f₀ + w f₁ with w = ``weight`` (a number, or a texture's luminance, clamped to
    [0, 1]).

    Two diffuse BSDFs (one- or two-sided alike, ``bsdf1``'s reflectance a colour) blend into one Lambertian lobe of
    reflectance (1 − w) ρ₀ + w ρ₁, sampled and evaluated exactly as Mitsuba's mixture (the lobes share their
    density), so that is how they are packed. Any other pair (plugins2) is packed as ``bsdf0`` with ``bsdf1`` in
    :class:`BlendPartner` (``Material.blend_partner``), mixed by the dispatch (``MATERIAL_BLEND``): sampled by
    choosing f₁ with probability w, eval and pdf the weighted mixtures. ``bsdf0`` may carry textures; ``bsdf1``
    must be untextured and isotropic, and neither may be a wrapper or another blend (put a ``mask``, ``normalmap``
    or ``bumpmap`` around the blend)."""

    bsdf0: Any
    bsdf1: Any
    weight: float | TextureRef = 0.5

    @property
    def two_sided(self) -> bool:
        return self.bsdf0.two_sided

    bump_amplitude = 0.0
    bump_frequency = 0.0


# ---- principled (Mitsuba 3's principled.cpp, principledthin.cpp) ----

#: a lobe weight of the principled records: a number or a texture (its ``eval_1`` at the hit)
Weight = float | TextureRef


@dataclasses.dataclass(frozen=True)
class _PrincipledLobes:
    """The parameters ``principled`` and ``principledthin`` share (Mitsuba's names and defaults)."""

    base_color: RGB | float | TextureRef = (0.5, 0.5, 0.5)
    roughness: Weight = 0.5
    anisotropic: Weight = 0.0
    spec_trans: Weight = 0.0
    spec_tint: Weight = 0.0
    sheen: Weight = 0.0
    sheen_tint: Weight = 0.0
    flatness: Weight = 0.0
    has_anisotropic: bool | None = None  # None: given when anisotropic is not the number 0 (Mitsuba's get_flag)
    two_sided: bool = False
    bump_amplitude: float = 0.0
    bump_frequency: float = 0.0


@dataclasses.dataclass(frozen=True)
class Principled(_PrincipledLobes):
    """Mitsuba ``principled``: the Disney principled BSDF (Burley 2012, 2015) as Mitsuba 3 implements it
    (:mod:`grisx.scene.principled`). Parameters and defaults are Mitsuba's; ``base_color`` an RGB or a texture,
    every other weight a number or a :class:`TextureRef` (at most four textured besides base_color, roughness and
    anisotropic). ``eta`` (interior/exterior index) or ``specular`` (η = 2/(1 − √(0.08 specular)) − 1) — not both;
    ``has_*``: whether Mitsuba was given the parameter (its ``get_flag``); None derives it from the value as Mitsuba
    does (a texture, or a number other than 0). Only ``has_spec_trans`` changes a value (the pdf seen from inside,
    and η = 1 or specular = 0 nudged to 1.001 or 1e-3); ``has_anisotropic`` turns the lobe to the shading tangent."""

    metallic: Weight = 0.0
    eta: float | None = None
    specular: float | None = None
    clearcoat: Weight = 0.0
    clearcoat_gloss: Weight = 0.0
    has_spec_trans: bool | None = None  # None: given when spec_trans is not the number 0 (Mitsuba's get_flag)

    diff_trans = 0.0  # principledthin only


@dataclasses.dataclass(frozen=True)
class PrincipledThin(_PrincipledLobes):
    """Mitsuba ``principledthin``: the thin-sheet principled BSDF (Burley 2015), two-sided (``two_sided`` ignored), no
    bending: GGX reflection, a GGX transmission through a roughness scaled by 0.65 η − 0.35, a diffuse reflection and a
    Lambertian transmission ``diff_trans`` ∈ [0, 2] (Mitsuba's range). ``eta`` a number (Mitsuba's may be a texture)."""

    eta: float = 1.5
    diff_trans: Weight = 0.0

    metallic = 0.0  # principled only
    clearcoat = 0.0
    clearcoat_gloss = 0.0


_WRAPPER_KIND: dict[type, int] = {Mask: MATERIAL_MASK, NormalMap: MATERIAL_NORMALMAP, BumpMap: MATERIAL_BUMPMAP}

MaterialDesc = (Diffuse | Conductor | RoughConductor | Dielectric | RoughDielectric | ThinDielectric | Plastic | RoughPlastic | Null
                | BlendBSDF | Mask | NormalMap | BumpMap | Principled | PrincipledThin | PolarizedPlastic | Polarizer | Retarder)


def unwrap(desc: Any) -> tuple[Any, list[Any]]:
    """The BSDF record inside ``desc``'s wrappers, and the wrappers from the outermost in."""
    wrappers = []
    while type(desc) in _WRAPPER_KIND:
        wrappers.append(desc)
        desc = desc.bsdf
    return desc, wrappers

_KIND_OF: dict[type, int] = {
    Diffuse: MATERIAL_DIFFUSE,
    Conductor: MATERIAL_CONDUCTOR,
    RoughConductor: MATERIAL_ROUGH_CONDUCTOR,
    Dielectric: MATERIAL_DIELECTRIC,
    RoughDielectric: MATERIAL_ROUGH_DIELECTRIC,
    ThinDielectric: MATERIAL_THIN_DIELECTRIC,
    Plastic: MATERIAL_PLASTIC,
    RoughPlastic: MATERIAL_ROUGH_PLASTIC,
    Null: MATERIAL_NULL,
    BlendBSDF: MATERIAL_DIFFUSE,
    Principled: MATERIAL_PRINCIPLED,
    PrincipledThin: MATERIAL_PRINCIPLED_THIN,
    PolarizedPlastic: MATERIAL_PPLASTIC,  # plugins2
    Polarizer: MATERIAL_NULL,  # plugins2: a null lobe of weight ½ transmittance
    Retarder: MATERIAL_NULL,  # plugins2: a null lobe of weight transmittance
}


# ---- plugins2 (issue 38): the second BSDF of a general blendbsdf ----


@wp.struct
class BlendPartner:
    """The second BSDF of a general ``blendbsdf``: the fields of :class:`Material` that its BSDF reads (untextured,
    isotropic; :func:`grisx.scene.bsdf.make_bsdf` rebuilds a Material of them with the hit's own frame fields)."""

    kind: int
    reflectance: wp.vec3
    alpha: float
    distribution: int
    sample_visible: int
    eta: wp.vec3
    k: wp.vec3
    transmittance: wp.vec3
    two_sided: int
    specular_reflectance: wp.vec3
    specular_weight: float
    internal_reflectance: float
    nonlinear: int
    external_transmittance: wp.array(dtype=float)


# ---- end plugins2 ----


@wp.struct
class Material:
    """One material as kernels see it (index = material id).

    ``kind``: a MATERIAL_* constant. ``reflectance``: diffuse reflectance, or
    ``specular_reflectance`` of conductors/dielectrics (for a textured diffuse
    material the caller replaces it with the texture's value before calling a
    BSDF). ``texture``: texture id or −1. ``alpha``: microfacet roughness (0 for smooth
    kinds; α_u along the shading frame's tangent), ``alpha_v`` (α_v along its bitangent; = ``alpha``
    when isotropic), ``anisotropic`` (1 when α_u ≠ α_v may hold: the BSDF then turns its frame to
    ``tangent``, the shading frame's s = normalize(∂p/∂u − n (n·∂p/∂u)) in the local frame of the
    renderer (resolved at the hit by ``grisx.scene.scene.surface_material``), ``alpha_u_texture`` /
    ``alpha_v_texture`` (texture ids whose luminance at the hit replaces α_u / α_v, or −1), ``distribution``: MICROFACET_GGX or MICROFACET_BECKMANN. ``eta``, ``k``: conductor complex index per channel; for
    dielectrics ``eta`` = int_ior/ext_ior in every channel and ``k`` = 0.
    ``transmittance``: ``specular_transmittance`` of dielectrics; the null lobe's weight of the null kind (1 for
    ``null``, ½ T for ``polarizer``, T for ``retarder``). ``two_sided``:
    1 if the frame is mirrored on the back side. ``bump_amplitude``,
    ``bump_frequency``: procedural normal perturbation (0 = none), applied by
    the scene to the shading normal before any BSDF call. Plastics only:
    ``specular_reflectance``, ``specular_weight``, ``internal_reflectance``,
    ``nonlinear`` and (rough) ``external_transmittance``, a table of
    ``ROUGH_TABLE_SIZE`` values (an empty array for every other kind).
    Wrappers: ``opacity`` (1 unless masked) and ``opacity_texture`` (texture id or −1; the
    hit's value replaces ``opacity``); ``perturb`` (PERTURB_*), ``perturb_texture``,
    ``bump_scale``, ``perturb_flags`` (bit 0: flip invalid normals, bit 1: shadowing
    function) and ``perturbed_n``, the perturbed normal in the local frame of the hit's
    shading normal (resolved at the hit by ``grisx.scene.scene.surface_material``). A blend of
    two diffuse BSDFs whose weight or first reflectance is a texture: ``blend_weight`` (or
    ``blend_texture``, its texture id or −1) and ``blend_reflectance`` (ρ₁); the hit's
    reflectance is (1 − w) ρ₀ + w ρ₁ (a constant blend is packed as a diffuse of that reflectance). A general
    blend (plugins2): the first BSDF's fields, ``blend_weight`` (resolved at the hit from ``blend_texture``) and
    ``blend_partner``, one :class:`BlendPartner` (an empty array for every other material: one array field, no
    per-kind cost). The principled kinds reuse fields whose meaning is otherwise unused for them (``_pack_principled``
    lists them) and add one: ``lobe_textures``, up to four textured lobe weights (texture id · 16 + slot, −1 unused),
    resolved at the hit into their slots (``grisx.scene.principled.principled_set_slot``).
    """

    kind: int
    reflectance: wp.vec3
    texture: int
    alpha: float
    alpha_v: float
    anisotropic: int
    alpha_u_texture: int
    alpha_v_texture: int
    tangent: wp.vec3
    distribution: int
    sample_visible: int
    eta: wp.vec3
    k: wp.vec3
    transmittance: wp.vec3
    two_sided: int
    bump_amplitude: float
    bump_frequency: float
    specular_reflectance: wp.vec3
    specular_weight: float
    internal_reflectance: float
    nonlinear: int
    external_transmittance: wp.array(dtype=float)
    opacity: float
    opacity_texture: int
    perturb: int
    perturb_texture: int
    bump_scale: float
    perturb_flags: int
    perturbed_n: wp.vec3
    blend_weight: float
    blend_texture: int
    blend_reflectance: wp.vec3
    lobe_textures: wp.vec4i
    blend_partner: wp.array(dtype=BlendPartner)


def is_general_blend(desc: Any) -> bool:
    """Whether ``desc`` is a :class:`BlendBSDF` that is not one Lambertian lobe (plugins2: two BSDFs, mixed by the dispatch)."""
    return isinstance(desc, BlendBSDF) and not (
        isinstance(desc.bsdf0, Diffuse) and isinstance(desc.bsdf1, Diffuse) and desc.bsdf0.two_sided == desc.bsdf1.two_sided
        and not isinstance(desc.bsdf1.reflectance, TextureRef))


def material_kind(desc: MaterialDesc) -> int:
    """MATERIAL_* kind of one record (of the BSDF inside a wrapper; a general blend's first BSDF's)."""
    inner, _ = unwrap(desc)
    if is_general_blend(inner):
        return material_kind(inner.bsdf0)
    kind = _KIND_OF.get(type(inner))
    if kind is None:
        names = ', '.join(t.__name__ for t in [*_KIND_OF, *_WRAPPER_KIND])
        raise InvalidParameterError(f"not a material record: {inner!r} (expected one of {names})")
    return kind


def material_kinds(descs: Iterable[MaterialDesc]) -> set[int]:
    """The set of MATERIAL_* kinds used by ``descs``, with a wrapper pseudo-kind for each wrapper
    present (for ``make_bsdf`` specialization)."""
    kinds = set()
    for d in descs:
        kinds.add(material_kind(d))
        kinds.update(_WRAPPER_KIND[type(w)] for w in unwrap(d)[1])
        if is_anisotropic(d):
            kinds.add(MATERIAL_ANISOTROPIC)
        if resolves_scalars(d):
            kinds.add(MATERIAL_SCALAR_TEXTURES)
        if has_reflectance_texture(d):
            kinds.add(MATERIAL_REFLECTANCE_TEXTURE)
        if has_procedural_bump(d):
            kinds.add(MATERIAL_PROCEDURAL_BUMP)
        if is_general_blend(unwrap(d)[0]):  # plugins2: the second BSDF's kind compiled in too
            kinds.update((MATERIAL_BLEND, material_kind(unwrap(d)[0].bsdf1)))
    return kinds


def resolves_scalars(desc: MaterialDesc) -> bool:
    """Whether ``desc`` has scalars that ``surface_material`` resolves at the hit: a mask (its opacity), a blend (its
    weight, or the mixed reflectance of a diffuse blend), a principled BSDF (textured lobes or roughness), or a
    textured α / α_u / α_v."""
    inner, wrappers = unwrap(desc)
    if any(isinstance(w, Mask) and isinstance(w.opacity, TextureRef) for w in wrappers) or isinstance(inner, BlendBSDF):
        return True
    if isinstance(inner, (Principled, PrincipledThin)):  # base_color is the material's texture, resolved apart
        return any(isinstance(getattr(inner, f.name), TextureRef) for f in dataclasses.fields(inner) if f.name != "base_color")
    return any(isinstance(getattr(inner, name, None), TextureRef) for name in ("alpha", "alpha_u", "alpha_v"))


def has_reflectance_texture(desc: MaterialDesc) -> bool:
    """Whether ``desc``'s packed reflectance is a texture (``Material.texture``): a diffuse ``reflectance``, a plastic's
    ``diffuse_reflectance`` or a principled ``base_color`` given as a texture (a blend's: its first BSDF's)."""
    inner, _ = unwrap(desc)
    if isinstance(inner, BlendBSDF):
        inner = inner.bsdf0
    return any(isinstance(getattr(inner, name, None), TextureRef) for name in ("reflectance", "diffuse_reflectance", "base_color"))


def has_procedural_bump(desc: MaterialDesc) -> bool:
    """Whether ``desc``'s packed record has a procedural bump (``bump_amplitude`` > 0; a blend's: its first BSDF's)."""
    inner, _ = unwrap(desc)
    if isinstance(inner, BlendBSDF):
        inner = inner.bsdf0
    return getattr(inner, "bump_amplitude", 0.0) > 0.0


def is_anisotropic(desc: MaterialDesc) -> bool:
    """Whether ``desc`` (inside its wrappers) may have α_u ≠ α_v: a rough conductor or a pplastic given different
    alpha_u and alpha_v (numbers or textures); such a BSDF turns to the shading frame's tangent."""
    inner, _ = unwrap(desc)
    if isinstance(inner, (Principled, PrincipledThin)):
        return principled_has(inner, "anisotropic")
    if is_general_blend(inner):
        inner = inner.bsdf0  # the second BSDF must be isotropic
    return isinstance(inner, (RoughConductor, PolarizedPlastic)) and inner.alpha_u is not None and inner.alpha_u != inner.alpha_v


def _rgb(value: RGB | float, what: str, *, nonneg: bool = True) -> RGB:
    a = np.broadcast_to(np.asarray(value, dtype=np.float64), (3,)) if np.ndim(value) == 0 else np.asarray(value, dtype=np.float64)
    if a.shape != (3,):
        raise InvalidParameterError(f"{what} must be a scalar or 3 values (RGB), got {value!r}")
    if not np.all(np.isfinite(a)):
        raise InvalidValueError(f"{what} contains NaN or Inf: {value!r}")
    if nonneg and np.any(a < 0):
        raise InvalidValueError(f"{what} must be non-negative, got {value!r}")
    return (float(a[0]), float(a[1]), float(a[2]))


def _positive(value: float, what: str) -> float:
    v = float(value)
    if not math.isfinite(v) or v <= 0.0:
        raise InvalidParameterError(f"{what} must be a finite positive number, got {value!r}")
    return v


def fresnel_diffuse_reflectance(eta: float) -> float:
    """Fdr: the fraction of diffuse (cosine-distributed) light an interface of relative index ``eta``
    reflects — Egan and Hilgeman's fit for η < 1, d'Eon and Irving's for η ≥ 1, as Mitsuba 3's
    ``fresnel_diffuse_reflectance``."""
    if eta < 1.0:
        return 0.0636 / eta + eta * (eta * -1.4399 + 0.7099) + 0.6681
    x = 1.0 / eta
    return 0.919317 + x * (-3.4793 + x * (6.75335 + x * (-7.80989 + x * (4.98554 + x * -1.36881))))


def _relative_ior(desc: MaterialDesc, where: str) -> float:
    """int_ior / ext_ior, both validated."""
    int_ior = _positive(desc.int_ior, f"{where}: int_ior")
    ext_ior = _positive(desc.ext_ior, f"{where}: ext_ior")
    if int_ior == ext_ior:
        raise InvalidParameterError(f"{where}: int_ior and ext_ior must differ (got {int_ior} for both)")
    return int_ior / ext_ior


def _texture_id(value: TextureRef, where: str, name: str) -> int:
    if int(value.texture_id) < 0:
        raise InvalidParameterError(f"{where}: {name} texture id must be >= 0, got {value.texture_id}")
    return int(value.texture_id)


def _unit_or_texture(value: float | TextureRef, where: str, what: str) -> tuple[float | None, int]:
    """A mask's opacity or a blend's weight: ``(value clamped to [0, 1], -1)`` for a number (Mitsuba's ``eval_opacity`` /
    ``eval_weight`` clamp too), ``(None, texture id)`` for a texture looked up at the hit."""
    if isinstance(value, TextureRef):
        return None, _texture_id(value, where, what)
    v = float(value)
    if not math.isfinite(v):
        raise InvalidParameterError(f"{where}: {what} must be finite, got {value!r}")
    return min(max(v, 0.0), 1.0), -1


def _pack_plastic(desc: Plastic | PolarizedPlastic, m: Material, where: str, device: str | wp.context.Device | None) -> None:
    # plastic.cpp / roughplastic.cpp / pplastic.cpp, parameters_changed(): 1/η², Fdr, the lobe sampling weight
    if isinstance(desc.diffuse_reflectance, TextureRef):
        m.texture = _texture_id(desc.diffuse_reflectance, where, "diffuse_reflectance")
        m.reflectance = wp.vec3(1.0, 1.0, 1.0)  # replaced by the texture's value at the hit
        d_mean = 0.5 if desc.diffuse_mean is None else float(desc.diffuse_mean)
        if not math.isfinite(d_mean) or d_mean < 0.0:
            raise InvalidParameterError(f"{where}: diffuse_mean must be finite and >= 0, got {desc.diffuse_mean!r}")
    else:
        rho = _rgb(desc.diffuse_reflectance, f"{where}: diffuse_reflectance")
        m.reflectance = wp.vec3(*rho)
        d_mean = sum(rho) / 3.0
    spec = _rgb(desc.specular_reflectance, f"{where}: specular_reflectance")
    m.specular_reflectance = wp.vec3(*spec)
    s_mean = sum(spec) / 3.0
    if d_mean + s_mean <= 0.0:
        raise InvalidParameterError(f"{where}: diffuse_reflectance and specular_reflectance are both black")
    m.specular_weight = s_mean / (d_mean + s_mean)
    m.nonlinear = 1 if getattr(desc, "nonlinear", False) else 0
    eta = _relative_ior(desc, where)
    m.eta = wp.vec3(eta, eta, eta)
    if isinstance(desc, PolarizedPlastic):
        return  # pplastic.cpp: no light trapped under a coating, so no internal reflectance
    if not isinstance(desc, RoughPlastic):
        m.internal_reflectance = fresnel_diffuse_reflectance(1.0 / eta)
        return
    table, internal = rough_interface_table(eta, max(m.alpha, 1.0e-4), m.distribution)
    m.internal_reflectance = internal
    m.external_transmittance = wp.array(table.astype(np.float32), dtype=float, device=device)


def _pack_wrappers(wrappers: list[Any], m: Material, where: str) -> None:
    # mask.cpp, normalmap.cpp, bumpmap.cpp: the wrappers' parameters beside the nested BSDF's
    seen: set[type] = set()
    for i, w in enumerate(wrappers):
        name = MATERIAL_KIND_NAMES[_WRAPPER_KIND[type(w)]]
        if type(w) in seen or (type(w) is not Mask and {NormalMap, BumpMap} & seen):
            raise InvalidParameterError(f"{where}: a {name} inside another {name if type(w) in seen else 'normalmap or bumpmap'} "
                                        f"is not supported (one mask and one normalmap or bumpmap per material)")
        if isinstance(w, Mask) and i > 0:
            raise InvalidParameterError(f"{where}: a mask inside a normalmap or bumpmap is not supported (put the mask outside)")
        seen.add(type(w))
        if isinstance(w, Mask):
            v, m.opacity_texture = _unit_or_texture(w.opacity, where, "mask opacity")
            if v is not None:
                m.opacity = v
            continue
        if not isinstance(w.normalmap if isinstance(w, NormalMap) else w.texture, TextureRef):
            raise InvalidParameterError(f"{where}: {name} needs a texture, got {w!r}")
        m.perturb = PERTURB_NORMALMAP if isinstance(w, NormalMap) else PERTURB_BUMPMAP
        m.perturb_texture = _texture_id(w.normalmap if isinstance(w, NormalMap) else w.texture, where, "texture")
        if isinstance(w, BumpMap):
            m.bump_scale = float(w.scale)
            if not math.isfinite(m.bump_scale):
                raise InvalidParameterError(f"{where}: bumpmap scale must be finite, got {w.scale!r}")
        m.perturb_flags = (1 if w.flip_invalid_normals else 0) | (2 if w.use_shadowing_function else 0)


def _pack_blend(blend: BlendBSDF, m: Material, where: str) -> None:
    # blendbsdf.cpp of two Lambertian lobes: one lobe of the blended reflectance, folded now where nothing varies
    rho1 = wp.vec3(*_rgb(blend.bsdf1.reflectance, f"{where}: the second BSDF's reflectance"))
    w, m.blend_texture = _unit_or_texture(blend.weight, where, "blendbsdf weight")
    if w is None:
        m.blend_reflectance = rho1
        return
    if m.texture >= 0:
        m.blend_weight = w
        m.blend_reflectance = rho1
    else:
        m.reflectance = wp.vec3(*((1.0 - w) * np.asarray(m.reflectance, dtype=np.float64) + w * np.asarray(rho1, dtype=np.float64)))


def _pack_alpha(desc: Any, m: Material, where: str) -> None:
    # microfacet.h via roughconductor.cpp, roughdielectric.cpp, pplastic.cpp: alpha a number or a texture (its
    # luminance at the hit, into both α_u and α_v); roughplastic.cpp reads a number only (its tables depend on it)
    if isinstance(desc.alpha, TextureRef):
        if isinstance(desc, RoughPlastic):
            raise InvalidParameterError(f"{where}: roughplastic's alpha must be a number (as in Mitsuba 3: its "
                                        f"interface tables are integrated for one roughness)")
        m.alpha_u_texture = _texture_id(desc.alpha, where, "alpha")
        m.alpha_v_texture = m.alpha_u_texture
        m.alpha = 0.1  # the texture's value replaces it at the hit
    else:
        m.alpha = _positive(desc.alpha, f"{where}: alpha")
    m.alpha_v = m.alpha
    if isinstance(desc, (RoughConductor, PolarizedPlastic)):
        _pack_anisotropy(desc, m, where)


def _pack_anisotropy(desc: RoughConductor | PolarizedPlastic, m: Material, where: str) -> None:
    # roughconductor.cpp, pplastic.cpp: alpha_u / alpha_v (numbers or textures) in place of alpha; anisotropic where they may differ
    if desc.alpha_u is None and desc.alpha_v is None:
        return
    if desc.alpha_u is None or desc.alpha_v is None:
        raise InvalidParameterError(f"{where}: give both alpha_u and alpha_v (or neither), got alpha_u={desc.alpha_u!r}, "
                                    f"alpha_v={desc.alpha_v!r}")
    values = []
    for name in ("alpha_u", "alpha_v"):
        v = getattr(desc, name)
        if isinstance(v, TextureRef):
            setattr(m, f"{name}_texture", _texture_id(v, where, name))
            values.append(("texture", v.texture_id))
            continue
        values.append(("value", _positive(v, f"{where}: {name}")))
    m.alpha = values[0][1] if values[0][0] == "value" else 0.1  # a texture's value replaces it at the hit
    m.alpha_v = values[1][1] if values[1][0] == "value" else 0.1
    m.anisotropic = 1 if values[0] != values[1] else 0
    if m.anisotropic == 0 and m.alpha_u_texture >= 0:  # one texture for both: isotropic, resolved into both
        m.alpha_v_texture = m.alpha_u_texture


def principled_has(desc: Principled | PrincipledThin, name: str) -> bool:
    """Mitsuba's ``get_flag(name)``: the parameter was given and is not the number 0 (an explicit ``has_*`` wins)."""
    flag = getattr(desc, f"has_{name}", None)
    if flag is not None:
        return bool(flag)
    v = getattr(desc, name)
    return isinstance(v, TextureRef) or float(v) != 0.0


def _pack_principled(desc: Principled | PrincipledThin, m: Material, where: str) -> None:
    # principled.cpp / principledthin.cpp constructors. Field reuse (none of these fields has another meaning for
    # the principled kinds; grisx.scene.principled reads them): reflectance = base_color, alpha = roughness,
    # alpha_v = anisotropic, eta[0] = η, k = (metallic, spec_trans, spec_tint), transmittance = (sheen, sheen_tint,
    # flatness), specular_reflectance = (clearcoat, clearcoat_gloss, diff_trans), nonlinear = has_spec_trans;
    # textured lobe weights: alpha_u_texture / alpha_v_texture (roughness / anisotropic) and lobe_textures.
    from grisx.scene.principled import PRINCIPLED_SLOTS  # noqa: PLC0415 (principled imports this module)

    thin = isinstance(desc, PrincipledThin)
    if isinstance(desc.base_color, TextureRef):
        m.texture = _texture_id(desc.base_color, where, "base_color")
        m.reflectance = wp.vec3(1.0, 1.0, 1.0)  # replaced by the texture's value at the hit
    else:
        m.reflectance = wp.vec3(*_rgb(desc.base_color, f"{where}: base_color"))
    m.sample_visible = 1  # GGX (distribution 0), visible normals: Mitsuba's MicrofacetDistribution defaults
    m.anisotropic = 1 if principled_has(desc, "anisotropic") else 0
    values = {}
    for name in ("roughness", "anisotropic", *PRINCIPLED_SLOTS):
        v = getattr(desc, name)
        if isinstance(v, TextureRef):
            values[name] = v
            continue
        x = float(v)
        if not math.isfinite(x):
            raise InvalidParameterError(f"{where}: {name} must be finite, got {v!r}")
        values[name] = x
    for name, field in (("roughness", "alpha_u_texture"), ("anisotropic", "alpha_v_texture")):
        if isinstance(values[name], TextureRef):
            setattr(m, field, _texture_id(values[name], where, name))
            values[name] = 0.0
    m.alpha = values["roughness"]
    m.alpha_v = values["anisotropic"] if m.anisotropic else 0.0
    textured = [(i, values[n]) for i, n in enumerate(PRINCIPLED_SLOTS) if isinstance(values[n], TextureRef)]
    if len(textured) > 4:
        raise InvalidParameterError(f"{where}: at most four of {', '.join(PRINCIPLED_SLOTS)} may be textures, got "
                                    f"{', '.join(PRINCIPLED_SLOTS[i] for i, _ in textured)}")
    slots = [-1, -1, -1, -1]
    for j, (i, ref) in enumerate(textured):
        slots[j] = _texture_id(ref, where, PRINCIPLED_SLOTS[i]) * 16 + i
        values[PRINCIPLED_SLOTS[i]] = 0.0
    m.lobe_textures = wp.vec4i(*slots)
    w = [values[n] for n in PRINCIPLED_SLOTS]
    m.k = wp.vec3(w[0], w[1], w[2])
    m.transmittance = wp.vec3(w[3], w[4], w[5])
    m.specular_reflectance = wp.vec3(w[6], w[7], w[8])
    has_spec_trans = principled_has(desc, "spec_trans")
    m.nonlinear = 1 if has_spec_trans and not thin else 0
    if thin:
        if isinstance(desc.eta, TextureRef):
            raise InvalidParameterError(f"{where}: a textured eta is not supported (give a number), got {desc.eta!r}")
        eta = _positive(desc.eta, f"{where}: eta")
    elif desc.eta is not None and desc.specular is not None:
        raise InvalidParameterError(f"{where}: give either eta or specular, not both (as in Mitsuba 3)")
    elif desc.eta is not None:
        eta = _positive(desc.eta, f"{where}: eta")
        if has_spec_trans and eta == 1.0:
            eta = 1.001  # principled.cpp: η = 1 is not plausible for transmission
    else:
        specular = 0.5 if desc.specular is None else float(desc.specular)
        if not (math.isfinite(specular) and 0.0 <= specular < 12.5):
            raise InvalidParameterError(f"{where}: specular must be in [0, 12.5), got {desc.specular!r}")
        if has_spec_trans and specular == 0.0:
            specular = 1.0e-3  # principled.cpp: zero specular is not plausible for transmission
        eta = float(np.float32(2.0) / (np.float32(1.0) - np.sqrt(np.float32(0.08) * np.float32(specular))) - np.float32(1.0))
    m.eta = wp.vec3(eta, eta, eta)
def _pack_general_blend(blend: BlendBSDF, wrappers: list[Any], index: int, device: str | wp.context.Device | None) -> Material:
    # blendbsdf.cpp of any two BSDFs (plugins2): the first packed with the blend's wrappers, the second beside it
    where = f"material {index} (blendbsdf)"
    for b in (blend.bsdf0, blend.bsdf1):
        if type(b) in _WRAPPER_KIND or isinstance(b, BlendBSDF) or type(b) not in _KIND_OF:
            raise InvalidParameterError(f"{where}: a blendbsdf of {type(b).__name__} is not supported (blend two plain "
                                        f"BSDFs; put a mask, normalmap or bumpmap around the blendbsdf)")
    first = blend.bsdf0
    for w in reversed(wrappers):
        first = dataclasses.replace(w, bsdf=first)
    m = _pack_one(first, index, device)
    p = _pack_one(blend.bsdf1, index, device)
    if p.texture >= 0 or p.alpha_u_texture >= 0 or p.alpha_v_texture >= 0 or p.anisotropic != 0:
        raise InvalidParameterError(f"{where}: the second BSDF of a blendbsdf must be untextured and isotropic (got a "
                                    f"{MATERIAL_KIND_NAMES[p.kind]} with a texture or alpha_u != alpha_v); swap the two "
                                    f"and the weight w for 1 - w if the first one is not")
    bp = BlendPartner()
    for name in BlendPartner.vars:
        setattr(bp, name, getattr(p, name))
    m.blend_partner = wp.array([bp], dtype=BlendPartner, device=device)
    m.blend_partner.partner_tables = [bp.external_transmittance]  # the struct holds a pointer only
    w, m.blend_texture = _unit_or_texture(blend.weight, where, "blendbsdf weight")
    m.blend_weight = 0.0 if w is None else w  # a texture's value replaces it at the hit
    return m


def _pack_one(desc: MaterialDesc, index: int, device: str | wp.context.Device | None = None) -> Material:
    kind = material_kind(desc)
    where = f"material {index} ({MATERIAL_KIND_NAMES[kind]})"
    desc, wrappers = unwrap(desc)
    if is_general_blend(desc):  # plugins2
        return _pack_general_blend(desc, wrappers, index, device)
    blend = None
    if isinstance(desc, BlendBSDF):
        blend, desc = desc, desc.bsdf0  # two Lambertian lobes (is_general_blend is false): one lobe
    m = Material()
    m.blend_weight = 0.0
    m.blend_texture = -1
    m.blend_reflectance = wp.vec3(0.0, 0.0, 0.0)
    m.lobe_textures = wp.vec4i(-1, -1, -1, -1)
    m.opacity = 1.0
    m.opacity_texture = -1
    m.perturb = PERTURB_NONE
    m.perturb_texture = -1
    m.bump_scale = 0.0
    m.perturb_flags = 0
    m.perturbed_n = wp.vec3(0.0, 0.0, 1.0)
    _pack_wrappers(wrappers, m, where)
    m.kind = kind
    m.texture = -1
    m.alpha = 0.0
    m.alpha_v = 0.0
    m.anisotropic = 0
    m.alpha_u_texture = -1
    m.alpha_v_texture = -1
    m.tangent = wp.vec3(1.0, 0.0, 0.0)
    m.distribution = 0
    m.sample_visible = 1
    m.eta = wp.vec3(1.0, 1.0, 1.0)
    m.k = wp.vec3(0.0, 0.0, 0.0)
    m.transmittance = wp.vec3(0.0, 0.0, 0.0)
    m.two_sided = 1 if desc.two_sided else 0
    m.specular_reflectance = wp.vec3(0.0, 0.0, 0.0)
    m.specular_weight = 0.0
    m.internal_reflectance = 0.0
    m.nonlinear = 0
    for name in ("bump_amplitude", "bump_frequency"):
        v = float(getattr(desc, name))
        if not math.isfinite(v) or v < 0.0:
            raise InvalidParameterError(f"{where}: {name} must be finite and >= 0, got {v!r}")
        setattr(m, name, v)
    if isinstance(desc, (RoughConductor, RoughDielectric, RoughPlastic, PolarizedPlastic)):
        _pack_alpha(desc, m, where)
        if desc.distribution not in MICROFACET_DISTRIBUTIONS:
            raise InvalidParameterError(f"{where}: distribution must be one of {', '.join(MICROFACET_DISTRIBUTIONS)}, got {desc.distribution!r}")
        m.distribution = MICROFACET_DISTRIBUTIONS[desc.distribution]
        m.sample_visible = 1 if desc.sample_visible else 0
    if isinstance(desc, Diffuse):
        if isinstance(desc.reflectance, TextureRef):
            m.texture = _texture_id(desc.reflectance, where, "reflectance")
            m.reflectance = wp.vec3(1.0, 1.0, 1.0)  # replaced by the texture's value at the hit
        else:
            m.reflectance = wp.vec3(*_rgb(desc.reflectance, f"{where}: reflectance"))
        if blend is not None:
            _pack_blend(blend, m, where)
        return m
    if isinstance(desc, (Plastic, PolarizedPlastic)):  # and RoughPlastic
        _pack_plastic(desc, m, where, device)
        return m
    if isinstance(desc, (Principled, PrincipledThin)):
        _pack_principled(desc, m, where)
        return m
    if isinstance(desc, Null):
        m.transmittance = wp.vec3(1.0, 1.0, 1.0)  # the null lobe's weight
        return m
    if isinstance(desc, Polarizer):  # polarizer.cpp (retarder.cpp), unpolarized: the null lobe of weight ½ (1) × transmittance
        share = 1.0 if isinstance(desc, Retarder) else 0.5
        m.transmittance = wp.vec3(*(share * v for v in _rgb(desc.transmittance, f"{where}: transmittance")))
        return m
    m.reflectance = wp.vec3(*_rgb(desc.specular_reflectance, f"{where}: specular_reflectance"))
    if isinstance(desc, (Conductor, RoughConductor)):
        m.eta = wp.vec3(*_rgb(desc.eta, f"{where}: eta"))
        m.k = wp.vec3(*_rgb(desc.k, f"{where}: k"))
        if any(e == 0.0 and kk == 0.0 for e, kk in zip(m.eta, m.k)):
            raise InvalidParameterError(f"{where}: eta and k must not both be 0 in a channel")
    else:
        eta = _relative_ior(desc, where)
        m.eta = wp.vec3(eta, eta, eta)
        m.transmittance = wp.vec3(*_rgb(desc.specular_transmittance, f"{where}: specular_transmittance"))
    return m


def pack_materials(descs: Sequence[MaterialDesc], device: str | wp.context.Device | None = None) -> wp.array:
    """``wp.array(dtype=Material)`` of ``descs`` in order (material id = list index), validated."""
    if len(descs) == 0:
        raise InvalidParameterError("pack_materials needs at least one material")
    packed = [_pack_one(d, i, device) for i, d in enumerate(descs)]
    out = wp.array(packed, dtype=Material, device=device)
    # the struct holds only a pointer to each roughplastic's table: the array keeps the tables alive
    out.material_tables = [m.external_transmittance for m in packed if m.kind == MATERIAL_ROUGH_PLASTIC]
    out.material_tables += [m.blend_partner for m in packed if m.blend_partner is not None]  # plugins2
    return out
