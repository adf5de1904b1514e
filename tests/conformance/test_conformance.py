"""Conformance with Mitsuba 3: each feature the loader accepts renders as Mitsuba renders it.

Every case is a tiny Mitsuba scene file in ``scenes/`` (32×24 or 24×32) that
exercises one feature — a shape type, a BSDF, a texture, an emitter, a camera
model, a transform chain, an integrator setting — and a reference that
Mitsuba 3 itself rendered (``refs/``, written by ``make_references.py``; its
version is in ``refs/meta.json``). grisx's ``pt`` renders the same file in
``frames`` independent frames of ``spp`` samples; the per-pixel means and
variances of the two renderers give z-values for the image mean and for every
block mean (8×8 pixels, 2×2 where a case needs it) per channel (:func:`grisx.testing.image_agreement_test`),
Šidák-corrected over the whole suite so that the suite as one verdict has the
false-alarm rate of a single 4σ test.

Adding a case: write ``scenes/NAME.xml``, run ``python
tests/conformance/make_references.py NAME``, add one line to ``CASES``.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest

from grisx.imageio import read_exr
from grisx.render import render
from grisx.scene.material import BlendBSDF, BumpMap, Diffuse, Mask, NormalMap, Null, PolarizedPlastic, Polarizer, Principled, PrincipledThin, RoughDielectric, RoughPlastic
from grisx.scene.mitsuba import load_mitsuba
from grisx.scene.texture import Bitmap, Checkerboard
from grisx.scene.transform import rotate
from grisx.testing import block_means, image_agreement_test

HERE = Path(__file__).resolve().parent
SCENES = HERE / "scenes"
REFS = HERE / "refs"


class Case(NamedTuple):
    """grisx's run for one scene file: ``frames`` independent frames of ``spp`` samples, z-tests per ``block``×``block`` pixels."""

    spp: int
    frames: int
    block: int = 8


#: case → grisx's run; the scene file says what the case checks
CASES: dict[str, Case] = {
    "emitter_no_bsdf": Case(32, 16),
    "emitter_with_bsdf": Case(32, 16),
    "rectangle": Case(32, 16),
    "disk": Case(32, 16),
    "cube": Case(32, 16),
    "sphere": Case(32, 16),
    "cylinder": Case(32, 16),
    "sphere_glass": Case(32, 16),
    "sphere_mirror": Case(32, 16),
    "sphere_light": Case(32, 16),
    "obj_normals_uv": Case(32, 16),
    "obj_plain": Case(32, 16),
    "ply_normals_uv": Case(32, 16),
    "ply_plain": Case(32, 16),
    "twosided": Case(32, 16),
    "flip_normals": Case(32, 16),
    "conductor_none": Case(32, 16),
    "conductor_named": Case(32, 16),
    "conductor_eta_k": Case(32, 16),
    "roughconductor": Case(32, 16),
    "roughconductor_all_normals": Case(32, 16),
    "roughconductor_beckmann": Case(32, 16),
    "roughconductor_anisotropic": Case(32, 16),
    "twosided_conductor": Case(32, 16),
    "dielectric": Case(32, 16),
    "dielectric_named": Case(32, 16),
    "roughdielectric": Case(32, 16),
    "roughdielectric_beckmann": Case(32, 16),
    "thindielectric": Case(32, 16),
    "plastic": Case(32, 16),
    "roughplastic": Case(32, 16),
    "mask": Case(32, 16),
    "mask_checkerboard": Case(32, 16),
    "null": Case(32, 16),
    "normalmap": Case(32, 16),
    "bumpmap": Case(32, 16),
    "blendbsdf": Case(32, 16),
    "principled": Case(32, 16),
    "principledthin": Case(32, 16),
    "texture_srgb": Case(32, 16),
    "texture_raw": Case(32, 16),
    "texture_exr": Case(32, 16),
    "checkerboard": Case(32, 16),
    "envmap": Case(32, 16),
    "constant": Case(32, 16),
    "point": Case(32, 16),
    "spot": Case(32, 16),
    "spot_texture": Case(32, 16),
    "projector": Case(32, 16),
    "directional": Case(32, 16),
    "area_texture": Case(32, 16),
    "delta_lights": Case(32, 16),
    "delta_lights_direct": Case(32, 16),
    "thinlens": Case(32, 16),
    "orthographic": Case(32, 16),
    "fov_axis_x": Case(16, 16),
    "fov_axis_y": Case(16, 16),
    "fov_axis_diagonal": Case(16, 16),
    "fov_axis_smaller": Case(16, 16),
    "fov_axis_larger": Case(16, 16),
    "focal_length": Case(16, 16),
    "nested_transforms": Case(32, 16),
    "instancing": Case(32, 16),
    "mirrored_meshes": Case(32, 16, block=4),
    "sdfgrid": Case(32, 16, block=4),
    "linearcurve": Case(32, 16, block=4),
    "bsplinecurve": Case(32, 16, block=4),
    "mesh_attribute": Case(32, 16, block=4),  # faces of a few pixels: blocks small enough to see a face's colour
    "max_depth_1": Case(16, 16),
    "max_depth_2": Case(16, 16),
    "max_depth_4_rr_1": Case(32, 16),
    "filter_gaussian_default": Case(32, 16, block=2),  # a filter moves energy between neighbouring pixels: small blocks
    "filter_gaussian_wide": Case(32, 16, block=2),
    "filter_tent": Case(32, 16, block=2),
    # plugins2 (issue 38): Mitsuba's polarization plugins as its RGB variants evaluate them; textured roughdielectric alpha
    "pplastic": Case(32, 16),
    "polarizer": Case(32, 16),
    "roughdielectric_textured": Case(32, 16),
    "blendbsdf_general": Case(32, 16),
}


def _reference(case: str) -> tuple[np.ndarray, np.ndarray]:
    return read_exr(REFS / f"{case}.exr"), read_exr(REFS / f"{case}.var.exr")


def _values_per_case(case: str) -> int:
    ref, _ = _reference(case)
    return block_means(ref, CASES[case].block).size + ref.shape[-1]


#: z-values sharing the suite's one verdict: every case's blocks and image mean, per channel
FAMILY = sum(_values_per_case(c) for c in CASES)


def render_runs(scene, spp: int, frames: int, seed: int = 7, device: str = "cpu") -> tuple[np.ndarray, np.ndarray]:
    """grisx ``pt``: the mean of ``frames`` independent frames and the per-pixel variance of that mean."""
    images = []
    render(scene, "pt", spp=spp, frames=frames, camera="static", seed=seed, device=device,
           on_frame=lambda i, img, s: images.append(np.asarray(img, dtype=np.float64)))
    stack = np.stack(images)
    return stack.mean(axis=0), stack.var(axis=0, ddof=1) / frames


def agreement(scene, case: str, device: str = "cpu"):
    c = CASES[case]
    mean, variance = render_runs(scene, c.spp, c.frames, device=device)
    ref, ref_var = _reference(case)
    return image_agreement_test(mean, variance, ref, ref_var, block=c.block, family=FAMILY)


def test_every_scene_file_has_a_case_and_a_reference():
    files = {p.stem for p in SCENES.glob("*.xml")}
    assert files == set(CASES), f"scene files without a case: {sorted(files - set(CASES))}; cases without a file: {sorted(set(CASES) - files)}"
    meta = json.loads((REFS / "meta.json").read_text())
    assert meta["renderer"].startswith("Mitsuba 3"), meta["renderer"]
    assert set(meta["cases"]) >= set(CASES)


@pytest.mark.parametrize("case", sorted(CASES))
def test_conformance(case, device):
    """On CPU always; on CUDA too where there is a GPU (its kernels compile with fast math)."""
    result = agreement(str(SCENES / f"{case}.xml"), case, device)
    assert result.passed, f"{case}: image mean {result.image}; blocks {result.blocks}; z (image mean) = {np.round(result.image.z, 2)}"


# ---- the suite can fail ----------------------------------------------------------------------


def test_a_reflecting_emitter_is_caught():
    """Before the fix grisx gave an emitter without a BSDF Mitsuba's default diffuse 0.5 (Mitsuba: black)."""
    scene = load_mitsuba(SCENES / "emitter_no_bsdf.xml")
    scene.materials[scene.material_names["default_emitter"]] = Diffuse()
    result = agreement(scene, "emitter_no_bsdf")
    assert not result.passed, f"a 0.5 reflectance on the emitters went unnoticed: {result}"


def test_a_two_percent_dimmer_light_is_caught():
    scene = load_mitsuba(SCENES / "max_depth_2.xml")
    scene.objects[:] = [o if o.emission is None else dataclasses.replace(o, emission=0.98 * o.emission) for o in scene.objects]
    result = agreement(scene, "max_depth_2")
    assert not result.passed, f"a 2% dimmer light went unnoticed: {result}"


def test_a_box_filter_is_caught_where_mitsuba_uses_its_default_gaussian():
    scene = load_mitsuba(SCENES / "filter_gaussian_default.xml")
    scene.film = dataclasses.replace(scene.film, filter_stddev=0.0)
    result = agreement(scene, "filter_gaussian_default")
    assert not result.passed, f"a box filter instead of Mitsuba's gaussian went unnoticed: {result}"


def test_a_box_filter_is_caught_where_mitsuba_uses_a_tent():
    scene = load_mitsuba(SCENES / "filter_tent.xml")
    scene.film = dataclasses.replace(scene.film, filter_tent=0.0)
    result = agreement(scene, "filter_tent")
    assert not result.passed, f"a box filter instead of the file's tent went unnoticed: {result}"


def test_ggx_is_caught_where_mitsuba_defaults_to_beckmann():
    scene = load_mitsuba(SCENES / "roughconductor_beckmann.xml")
    scene.materials[:] = [dataclasses.replace(m, distribution="ggx") if hasattr(m, "distribution") else m for m in scene.materials]
    result = agreement(scene, "roughconductor_beckmann")
    assert not result.passed, f"GGX instead of Mitsuba's default Beckmann went unnoticed: {result}"


def test_an_anisotropic_roughness_turned_by_90_degrees_is_caught():
    scene = load_mitsuba(SCENES / "roughconductor_anisotropic.xml")
    scene.materials[:] = [dataclasses.replace(m, alpha_u=m.alpha_v, alpha_v=m.alpha_u) if getattr(m, "alpha_u", None) else m
                          for m in scene.materials]
    result = agreement(scene, "roughconductor_anisotropic")
    assert not result.passed, f"alpha_u and alpha_v swapped (the lobe turned by 90 degrees) went unnoticed: {result}"


def test_a_checkerboard_opacity_and_weight_read_as_its_colour_are_caught():
    # Mitsuba's scalar eval_1 picks a checkerboard's colours the other way round from its eval: swapped here
    scene = load_mitsuba(SCENES / "mask_checkerboard.xml")
    scene.textures[:] = [dataclasses.replace(t, color0=t.color1, color1=t.color0) if isinstance(t, Checkerboard) else t
                         for t in scene.textures]
    result = agreement(scene, "mask_checkerboard")
    assert not result.passed, f"a checkerboard's opacity and blend weight read as its eval went unnoticed: {result}"


def test_a_spot_without_its_falloff_is_caught():
    scene = load_mitsuba(SCENES / "spot.xml")
    scene.point_lights[:] = [dataclasses.replace(p, beam_width=p.cutoff_angle) for p in scene.point_lights]  # hard-edged cones
    result = agreement(scene, "spot")
    assert not result.passed, f"spot lights without Mitsuba's falloff went unnoticed: {result}"


def test_a_thin_pane_reflecting_at_one_interface_only_is_caught():
    """A pane that reflects F, as a single interface does, instead of 2F/(1 + F) (the internal bounces
    summed): its reflection about halved, as by specular_reflectance (1 + F)/2 ≈ 0.5."""
    scene = load_mitsuba(SCENES / "thindielectric.xml")
    scene.materials[:] = [dataclasses.replace(m, specular_reflectance=0.5) if type(m).__name__ == "ThinDielectric" else m for m in scene.materials]
    result = agreement(scene, "thindielectric")
    assert not result.passed, f"a pane reflecting at one interface only went unnoticed: {result}"


def test_a_cylinder_framed_otherwise_than_mitsuba_is_caught():
    """The tube's uv seam where Mitsuba's ``to_frame`` puts φ = 0, not a quarter turn away (a gradient texture in u)."""
    scene = load_mitsuba(SCENES / "cylinder.xml")
    tube = scene.objects[3]  # the textured tube (analytic: grisx.scene.analytic)
    turned = tube.shape.to_world @ rotate((0, 0, 1), 90.0)  # the same tube, φ = 0 a quarter turn away
    scene.objects[3] = dataclasses.replace(tube, shape=dataclasses.replace(tube.shape, to_world=turned))
    result = agreement(scene, "cylinder")
    assert not result.passed, f"a cylinder's uv a quarter turn off went unnoticed: {result}"


def test_a_cylinder_with_its_normals_unflipped_is_caught():
    scene = load_mitsuba(SCENES / "cylinder.xml")
    tube = scene.objects[5]  # flip_normals: seen from outside it shows its black back
    assert tube.shape.flip_normals
    scene.objects[5] = dataclasses.replace(tube, shape=dataclasses.replace(tube.shape, flip_normals=False))
    result = agreement(scene, "cylinder")
    assert not result.passed, f"a cylinder's flip_normals ignored went unnoticed: {result}"


def test_an_inside_out_sphere_read_right_side_out_is_caught():
    """A negative radius turns a sphere inside out in Mitsuba (``sphere.cpp``): its diffuse front faces inward."""
    scene = load_mitsuba(SCENES / "sphere_mirror.xml")
    inside_out = next(i for i, o in enumerate(scene.objects) if o.shape is not None and o.shape.orientation < 0)
    o = scene.objects[inside_out]
    scene.objects[inside_out] = dataclasses.replace(o, shape=dataclasses.replace(o.shape, flip_normals=True))
    result = agreement(scene, "sphere_mirror")
    assert not result.passed, f"an inside-out sphere rendered right side out went unnoticed: {result}"


def test_a_checkerboard_with_its_colours_swapped_is_caught():
    """color0 where the fractional parts of u and v fall on the same side of ½ (Mitsuba), not color1."""
    scene = load_mitsuba(SCENES / "checkerboard.xml")
    scene.textures[:] = [dataclasses.replace(t, color0=t.color1, color1=t.color0) if isinstance(t, Checkerboard) else t for t in scene.textures]
    result = agreement(scene, "checkerboard")
    assert not result.passed, f"a checkerboard with swapped colours went unnoticed: {result}"


def test_a_bitmap_without_its_to_uv_is_caught():
    scene = load_mitsuba(SCENES / "checkerboard.xml")
    scene.textures[:] = [t.image if isinstance(t, Bitmap) else t for t in scene.textures]
    result = agreement(scene, "checkerboard")
    assert not result.passed, f"a bitmap's to_uv ignored went unnoticed: {result}"


def test_a_mirrored_mesh_shown_from_its_winding_side_is_caught():
    """Under a mirroring to_world Mitsuba's front side is where a mesh's normals point, not where the winding
    of its mirrored vertices does (the obj and the cube with face_normals shown from behind: black)."""
    scene = load_mitsuba(SCENES / "mirrored_meshes.xml")
    for i in (4, 5):  # cube5 (face_normals), obj6 (blob_nuv.obj)
        o = scene.objects[i]
        scene.objects[i] = dataclasses.replace(o, faces=o.faces[:, [0, 2, 1]].copy())
    result = agreement(scene, "mirrored_meshes")
    assert not result.passed, f"mirrored meshes seen from their winding's side went unnoticed: {result}"


def test_a_projector_image_upside_down_is_caught():
    """A projector whose film rows run bottom to top (v flipped: the orientation bug a camera run backwards invites)."""
    scene = load_mitsuba(SCENES / "projector.xml")
    scene.point_lights[:] = [dataclasses.replace(p, irradiance=np.asarray(p.irradiance)[::-1]) if hasattr(p, "fov") else p for p in scene.point_lights]
    result = agreement(scene, "projector")
    assert not result.passed, f"a projector image upside down went unnoticed: {result}"


def test_a_spot_texture_mirrored_is_caught():
    """A spot texture laid out with u running the other way across the cone (its columns mirrored)."""
    scene = load_mitsuba(SCENES / "spot_texture.xml")
    scene.point_lights[:] = [p if p.texture is None else dataclasses.replace(p, texture=np.asarray(p.texture)[:, ::-1]) for p in scene.point_lights]
    result = agreement(scene, "spot_texture")
    assert not result.passed, f"a mirrored spot texture went unnoticed: {result}"


def test_an_area_light_image_mirrored_is_caught():
    """A textured area light whose image is looked up with u mirrored."""
    scene = load_mitsuba(SCENES / "area_texture.xml")
    scene.objects[:] = [o if o.emission is None or np.ndim(getattr(o.emission, "image", o.emission)) < 2
                        else dataclasses.replace(o, emission=dataclasses.replace(o.emission, image=np.asarray(o.emission.image)[:, ::-1]))
                        for o in scene.objects]
    result = agreement(scene, "area_texture")
    assert not result.passed, f"a mirrored emission image went unnoticed: {result}"


def test_an_orthographic_film_of_the_wrong_height_is_caught():
    """An orthographic film spanning [−1, 1]² (aspect ignored) instead of Mitsuba's [−1, 1] × [−1/aspect, 1/aspect]: stretched vertically."""
    scene = load_mitsuba(SCENES / "orthographic.xml")
    scene.camera = dataclasses.replace(scene.camera, to_world=scene.camera.to_world @ np.diag([1.0, 32 / 24, 1.0, 1.0]))
    result = agreement(scene, "orthographic")
    assert not result.passed, f"an orthographic film of the wrong height went unnoticed: {result}"


def test_a_mask_with_a_constant_opacity_is_caught():
    """The checker's opacity replaced by its mean-ish 0.5: the see-through squares must show."""
    scene = load_mitsuba(SCENES / "mask.xml")
    scene.materials[:] = [dataclasses.replace(m, opacity=0.5) if isinstance(m, Mask) else m for m in scene.materials]
    result = agreement(scene, "mask")
    assert not result.passed, f"a mask without its opacity texture went unnoticed: {result}"


def test_null_surfaces_that_are_no_path_vertex_are_caught():
    """Without the null rectangles (as if passing one were no bounce): at max_depth 4 what is seen through them
    gets a bounce more than in Mitsuba."""
    scene = load_mitsuba(SCENES / "null.xml")
    scene.objects[:] = [o for o in scene.objects if not isinstance(scene.materials[o.material], Null)]
    result = agreement(scene, "null")
    assert not result.passed, f"null surfaces that do not count toward max_depth went unnoticed: {result}"


def test_a_normal_map_without_its_shadowing_term_is_caught():
    scene = load_mitsuba(SCENES / "normalmap.xml")
    scene.materials[:] = [dataclasses.replace(m, use_shadowing_function=False) if isinstance(m, NormalMap) else m for m in scene.materials]
    result = agreement(scene, "normalmap")
    assert not result.passed, f"a normal map without Estevez et al.'s shadowing went unnoticed: {result}"


def test_a_bump_map_of_half_the_scale_is_caught():
    scene = load_mitsuba(SCENES / "bumpmap.xml")
    scene.materials[:] = [dataclasses.replace(m, scale=0.5 * m.scale) if isinstance(m, BumpMap) else m for m in scene.materials]
    result = agreement(scene, "bumpmap")
    assert not result.passed, f"a bump map at half its scale went unnoticed: {result}"


def test_a_blend_with_its_weight_inverted_is_caught():
    """The first BSDF weighted w and the second 1 − w (blendbsdf.cpp gives the first 1 − w)."""
    scene = load_mitsuba(SCENES / "blendbsdf.xml")
    scene.materials[:] = [dataclasses.replace(m, bsdf0=m.bsdf1, bsdf1=m.bsdf0) if isinstance(m, BlendBSDF) and m.bsdf1.reflectance != m.bsdf0.reflectance
                          and not hasattr(m.bsdf0.reflectance, "texture_id") else m for m in scene.materials]
    result = agreement(scene, "blendbsdf")
    assert not result.passed, f"a blend with its weight inverted went unnoticed: {result}"


def test_a_principled_roughness_read_as_alpha_is_caught():
    """α = roughness instead of Burley's α = roughness² (calc_dist_params): every principled lobe rougher."""
    scene = load_mitsuba(SCENES / "principled.xml")
    scene.materials[:] = [dataclasses.replace(m, roughness=m.roughness**0.5) if isinstance(m, Principled) else m for m in scene.materials]
    result = agreement(scene, "principled")
    assert not result.passed, f"a principled roughness read as alpha went unnoticed: {result}"


def test_a_thin_sheet_with_its_diff_trans_not_halved_is_caught():
    """principledthin's diff_trans runs over [0, 2] and is halved (principledthin.cpp): read as a [0, 1] weight here."""
    scene = load_mitsuba(SCENES / "principledthin.xml")
    scene.materials[:] = [dataclasses.replace(m, diff_trans=2.0 * m.diff_trans) if isinstance(m, PrincipledThin) and not hasattr(m.diff_trans, "texture_id")
                          else m for m in scene.materials]
    result = agreement(scene, "principledthin")
    assert not result.passed, f"a thin sheet's diff_trans read unhalved went unnoticed: {result}"
# ---- plugins2 (issue 38): the suite catches pplastic read as a coated plastic, a polarizer read as a null, a constant alpha ----


def test_pplastic_read_as_the_coated_roughplastic_is_caught():
    """pplastic is not roughplastic: the same parameters in the coated model (light trapped under the coat, 1/η², a
    rough interface's transmittance) give another picture."""
    scene = load_mitsuba(SCENES / "pplastic.xml")
    scene.materials[:] = [RoughPlastic(alpha=m.alpha if isinstance(m.alpha, float) else 0.2, distribution=m.distribution,
                                       int_ior=m.int_ior, ext_ior=m.ext_ior, diffuse_reflectance=m.diffuse_reflectance,
                                       specular_reflectance=m.specular_reflectance)
                          if isinstance(m, PolarizedPlastic) else m for m in scene.materials]
    result = agreement(scene, "pplastic")
    assert not result.passed, f"pplastic read as roughplastic went unnoticed: {result}"


def test_a_polarizer_passing_all_light_is_caught():
    """A polarizer read as a null (weight 1, as if polarization were ignored altogether) instead of ½ transmittance."""
    scene = load_mitsuba(SCENES / "polarizer.xml")
    scene.materials[:] = [Null() if type(m) is Polarizer else m for m in scene.materials]
    result = agreement(scene, "polarizer")
    assert not result.passed, f"polarizers passing all light went unnoticed: {result}"


def test_a_roughdielectric_with_a_constant_alpha_is_caught():
    """The checkerboard's alpha replaced by the constant 0.1 that packing leaves where the texture is not looked up."""
    scene = load_mitsuba(SCENES / "roughdielectric_textured.xml")
    scene.materials[:] = [dataclasses.replace(m, alpha=0.1) if isinstance(m, RoughDielectric) else m for m in scene.materials]
    result = agreement(scene, "roughdielectric_textured")
    assert not result.passed, f"a roughdielectric's alpha texture ignored went unnoticed: {result}"


def test_a_general_blend_with_its_bsdfs_swapped_is_caught():
    """blendbsdf's first BSDF weighs 1 − w and its second w (blendbsdf.cpp), not the other way round."""
    scene = load_mitsuba(SCENES / "blendbsdf_general.xml")
    scene.materials[:] = [dataclasses.replace(m, bsdf0=m.bsdf1, bsdf1=m.bsdf0) if isinstance(m, BlendBSDF) else m for m in scene.materials]
    result = agreement(scene, "blendbsdf_general")
    assert not result.passed, f"a blendbsdf with its two BSDFs swapped went unnoticed: {result}"
