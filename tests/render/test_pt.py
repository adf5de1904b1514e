"""The reference path tracer against exact answers (CPU, small images, fixed seeds).

Pixels use independent random streams, so a pixel-averaged estimate has a
standard error from the per-pixel variances; each check is a z-test
(``grisx.testing.z_test``, k = 4, Šidák over channels) with a sibling showing
that a known-biased configuration fails the same check.
"""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from pathlib import Path

from grisx.scene.builtin import BUILTIN_SCENES, build_builtin
from grisx.scene.camera import Camera, CameraData, camera_ray, lookat
from grisx.scene.lights import ConstantEnvironment
from grisx.scene.material import (
    MATERIAL_PROCEDURAL_BUMP,
    MATERIAL_REFLECTANCE_TEXTURE,
    MATERIAL_SCALAR_TEXTURES,
    SCENE_ANALYTIC_SHAPES,
    SCENE_DELTA_LIGHTS,
    SCENE_EMITTER_TEXTURES,
    SCENE_ENVMAP,
    Diffuse,
)
from grisx.scene.mitsuba import load_mitsuba
from grisx.render.base.trace import STRATEGIES, make_trace_path, no_first_hit
from grisx.render.pt import PathTracer
from grisx.scene.scene import Scene, SceneData
from grisx.scene.shapes import cube, rectangle
from grisx.testing import BIASED_K, DEFAULT_K, z_test
from grisx.theory.random import random_key, random_subkey

CONFORMANCE = Path(__file__).resolve().parents[1] / "conformance" / "scenes"


def _estimate(scene: Scene, width: int, height: int, spp: int, seed: int = 1, mask: np.ndarray | None = None, **kw):
    """Pixel-averaged estimate and its standard error per channel."""
    built = scene.build("cpu")
    pt = PathTracer(built, width, height, spp=spp, seed=seed, **kw)
    pt.add_samples(0, spp)
    assert pt.nonfinite_samples == 0
    mean, var = pt.mean().astype(np.float64), pt.variance_of_mean().astype(np.float64)
    if mask is not None:
        mean, var = mean[mask], var[mask]
    mean, var = mean.reshape(-1, 3), var.reshape(-1, 3)
    n = len(mean)
    est = mean.mean(axis=0)
    # floor at float32 rounding: BSDF sampling of a diffuse plane under a constant sky has zero variance
    return est, np.maximum(np.sqrt(var.sum(axis=0)) / n, 1e-6 * np.abs(est))


# ---- white furnace: a closed diffuse box of albedo ρ whose walls all emit Le: L = Le / (1 − ρ) ----

RHO, LE = 0.7, 0.6


def _furnace() -> Scene:
    s = Scene("furnace")
    m = s.add_material(Diffuse(RHO))
    box = cube(flip_normals=True)  # normals inward
    s.add_mesh(box.vertices, box.faces, normals=box.normals, material=m, emission=(LE, LE, LE))
    s.set_camera(Camera(to_world=lookat((0.1, -0.2, 0.3), (1, 0.3, -0.5), (0, 1, 0)), fov=80))
    return s


def test_white_furnace_converges_to_le_over_one_minus_rho():
    est, se = _estimate(_furnace(), 16, 16, 16, max_depth=-1)
    exact = LE / (1 - RHO)
    result = z_test(est, se, np.full(3, exact), k=DEFAULT_K)
    assert result.passed, result


def test_white_furnace_catches_a_truncated_path():
    # max_depth = 4 keeps Le (1 + ρ + ρ²) of the geometric series: biased
    est, se = _estimate(_furnace(), 16, 16, 16, max_depth=4)
    result = z_test(est, se, np.full(3, LE / (1 - RHO)), k=BIASED_K)
    assert not result.passed, result


# ---- a diffuse plane under a constant environment: L = ρ · L_env -------------------------------


def _env_plane() -> Scene:
    s = Scene("env-plane")
    m = s.add_material(Diffuse(0.5))
    r = rectangle()
    s.add_mesh(r.vertices, r.faces, normals=r.normals, material=m, to_world=np.diag([50.0, 50.0, 1.0, 1.0]))
    s.set_environment(ConstantEnvironment((0.8, 1.0, 1.2)))
    s.set_camera(Camera(to_world=lookat((0, 0, 3), (0, 0, 0), (0, 1, 0)), fov=30))
    return s


@pytest.mark.parametrize("strategy", ["mis", "nee", "bsdf"])
def test_diffuse_plane_under_constant_environment(strategy):
    est, se = _estimate(_env_plane(), 12, 12, 8, strategy=strategy)
    result = z_test(est, se, 0.5 * np.array([0.8, 1.0, 1.2]), k=DEFAULT_K)
    assert result.passed, result


def test_diffuse_plane_catches_missing_direct_light():
    est, se = _estimate(_env_plane(), 12, 12, 8, max_depth=1)  # only emitters seen directly: black
    assert not z_test(est, se, 0.5 * np.array([0.8, 1.0, 1.2]), k=BIASED_K).passed


# ---- the two techniques agree with their MIS combination on the Cornell box ----------------------


def _cornell(strategy: str, seed: int, max_depth: int = 6):
    # the lower half of the image: the light itself (radiance ~18 next to ~0.2) would dominate the error bars
    mask = np.zeros((32, 32), dtype=bool)
    mask[16:] = True
    return _estimate(build_builtin("cornell-box"), 32, 32, 32, seed=seed, mask=mask, strategy=strategy, max_depth=max_depth)


def test_nee_only_bsdf_only_and_mis_agree_on_the_cornell_box():
    mis = _cornell("mis", 11)
    for seed, strategy in ((12, "nee"), (13, "bsdf")):
        other = _cornell(strategy, seed)
        diff = other[0] - mis[0]
        se = np.sqrt(other[1] ** 2 + mis[1] ** 2)
        result = z_test(diff, se, np.zeros(3), k=DEFAULT_K)
        assert result.passed, (strategy, result)
    # MIS has lower variance than either technique alone on this scene
    assert np.all(mis[1] < _cornell("bsdf", 14)[1])


def test_cornell_box_agreement_check_catches_a_shorter_path():
    mis = _cornell("mis", 11)
    short = _cornell("nee", 12, max_depth=2)  # direct light only: misses the indirect light
    assert not z_test(short[0] - mis[0], np.sqrt(short[1] ** 2 + mis[1] ** 2), np.zeros(3), k=BIASED_K).passed


# ---- determinism and finiteness ------------------------------------------------------------------


def test_same_seed_same_image_other_seed_other_image():
    built = build_builtin("cornell-box").build("cpu")
    images = []
    for seed in (5, 5, 6):
        pt = PathTracer(built, 12, 12, spp=2, seed=seed)
        images.append(pt.render_frame(0).numpy())
    np.testing.assert_array_equal(images[0], images[1])
    assert not np.array_equal(images[0], images[2])


def test_kernels_specialised_on_the_scene_kinds_give_the_same_image(monkeypatch):
    """The suite compiles every renderer for all kinds (conftest: ``GRISX_KERNEL_KINDS=all``); users' kernels are
    specialised on their scene's kinds. The specialisation must only leave out absent kinds' code: same image, bit
    for bit. Its sibling leaves out a kind the scene uses (the rough conductor), and the image changes."""
    built = build_builtin("glossy-room").build("cpu")
    assert built.features.material_kinds == {0, 2}  # diffuse, rough conductor

    def image(**kinds) -> np.ndarray:
        return PathTracer(built, 16, 12, spp=2, seed=3, max_depth=6, **kinds).render_frame(0).numpy()

    monkeypatch.setenv("GRISX_KERNEL_KINDS", "all")
    every = image()
    monkeypatch.setenv("GRISX_KERNEL_KINDS", "scene")
    np.testing.assert_array_equal(image(), every)
    assert not np.array_equal(image(kinds=frozenset({0})), every)


#: conformance scenes whose materials resolve something at the hit, by what: a textured mask opacity, a textured α, a
#: diffuse blend, a principled BSDF's textured lobes, a normal map (a bump map shares its code), an anisotropic rough conductor,
#: textured reflectances (a checkerboard and a bitmap), a procedural bump (caustic-slab),
#: and the scene pseudo-kinds: analytic spheres and a disk (the ray queries' shapes), an environment map, delta lights, a
#: textured area emitter (light sampling)
WRAPPER_SCENES = ("mask_checkerboard", "roughdielectric_textured", "blendbsdf", "principled", "normalmap", "roughconductor_anisotropic",
                  "checkerboard", "sphere_mirror", "envmap", "delta_lights", "area_texture", "caustic-slab")


def _scene(case: str):
    """A conformance scene file by name, or a built-in scene (``caustic-slab``: seed 003's bumped glass)."""
    return build_builtin(case) if case in BUILTIN_SCENES else load_mitsuba(CONFORMANCE / f"{case}.xml")


@pytest.mark.parametrize("case", WRAPPER_SCENES)
def test_surfaces_specialised_on_the_scene_kinds_give_the_same_image(case, monkeypatch):
    """``surface_material`` compiles each wrapper (normal and bump maps, the tangent, the scalar textures), the ray
    queries their analytic shapes and light sampling each kind of light only where the scene's kinds name them
    (``make_surface``, ``make_lights``); the suite's all-kinds kernels cannot see a pseudo-kind the loader forgot, so
    each such scene is rendered both ways here."""
    built = _scene(case).build("cpu")
    monkeypatch.setenv("GRISX_KERNEL_KINDS", "all")
    every = PathTracer(built, 16, 12, spp=2, seed=3, max_depth=4).render_frame(0).numpy()
    monkeypatch.setenv("GRISX_KERNEL_KINDS", "scene")
    np.testing.assert_array_equal(PathTracer(built, 16, 12, spp=2, seed=3, max_depth=4).render_frame(0).numpy(), every)


@pytest.mark.parametrize("case,kind", [("mask_checkerboard", MATERIAL_SCALAR_TEXTURES), ("checkerboard", MATERIAL_REFLECTANCE_TEXTURE),
                                       ("caustic-slab", MATERIAL_PROCEDURAL_BUMP)],
                         ids=["scalar-textures", "reflectance-texture", "procedural-bump"])
def test_surfaces_without_their_material_feature_kind_are_caught(case, kind):
    # the siblings: the textured mask's scene compiled without MATERIAL_SCALAR_TEXTURES, the checkerboards' without
    # MATERIAL_REFLECTANCE_TEXTURE, the bumped glass slab's without MATERIAL_PROCEDURAL_BUMP, render another image
    built = _scene(case).build("cpu")
    kinds = built.features.material_kinds
    assert kind in kinds

    def image(kinds: frozenset[int]) -> np.ndarray:
        return PathTracer(built, 16, 12, spp=2, seed=3, max_depth=4, kinds=kinds).render_frame(0).numpy()

    assert not np.array_equal(image(kinds - {kind}), image(kinds))


@pytest.mark.parametrize("case,kind", [("sphere_mirror", SCENE_ANALYTIC_SHAPES), ("envmap", SCENE_ENVMAP), ("delta_lights", SCENE_DELTA_LIGHTS),
                                       ("area_texture", SCENE_EMITTER_TEXTURES)],
                         ids=["analytic-shapes", "envmap", "delta-lights", "emitter-textures"])
def test_a_scene_compiled_without_its_scene_kind_is_caught(case, kind):
    # the siblings of the scene pseudo-kinds: compiled without it, the scene loses its spheres, its environment map, its
    # point and spot lights or its emitter's image
    built = load_mitsuba(CONFORMANCE / f"{case}.xml").build("cpu")
    kinds = built.features.material_kinds
    assert kind in kinds

    def image(kinds: frozenset[int]) -> np.ndarray:
        return PathTracer(built, 16, 12, spp=2, seed=3, max_depth=4, kinds=kinds).render_frame(0).numpy()

    assert not np.array_equal(image(kinds - {kind}), image(kinds))


@pytest.mark.parametrize("name", sorted(BUILTIN_SCENES))
def test_no_nan_or_inf_on_any_builtin_scene(name):
    built = build_builtin(name).build("cpu")
    pt = PathTracer(built, 12, 8, spp=2, seed=0)
    img = pt.render_frame(0).numpy()
    assert pt.nonfinite_samples == 0
    assert np.all(np.isfinite(img)) and np.all(img >= 0)
    assert img.max() > 0  # every built-in scene shows some light


@pytest.mark.parametrize("prefix_depth", [1, 2, 3])
def test_trace_path_prefix_is_the_same_path_truncated(prefix_depth):
    # one traced path gives both sums: its first prefix_depth segments must be exactly what the path
    # tracer gives with max_depth = prefix_depth and the same random numbers (ReSTIR GI relies on it)
    built = build_builtin("cornell-box").build("cpu")
    trace_path = make_trace_path(built.features.kernel_kinds)
    cam = built.camera_data(0.0, 16, 16)
    mis = STRATEGIES["mis"]

    @wp.kernel(module="unique")
    def paths(scene: SceneData, cam: CameraData, prefix_depth: int, out: wp.array2d(dtype=wp.vec3)):
        i = wp.tid()
        ray = camera_ray(cam, float(i % 16) + 0.5, float(i // 16) + 0.5, wp.vec2(0.5, 0.5))
        key = random_subkey(random_key(3, 0), i)
        both = trace_path(scene, ray.o, ray.d, key, -1, 5, mis, prefix_depth, 0, no_first_hit())
        out[i, 0] = both.total
        out[i, 1] = both.prefix
        out[i, 2] = trace_path(scene, ray.o, ray.d, key, prefix_depth, 5, mis, -1, 0, no_first_hit()).total
        out[i, 3] = trace_path(scene, ray.o, ray.d, key, -1, 5, mis, -1, 0, no_first_hit()).total

    out = wp.zeros((256, 4), dtype=wp.vec3, device="cpu")
    wp.launch(paths, dim=256, inputs=[built.data, cam, prefix_depth], outputs=[out], device="cpu")
    o = out.numpy()
    np.testing.assert_array_equal(o[:, 1], o[:, 2])  # the prefix is the truncated path
    np.testing.assert_array_equal(o[:, 0], o[:, 3])  # and asking for it changes nothing else
    assert np.any(o[:, 0] != o[:, 1])  # the rest of the path is not empty


# ---- the closed room: the built-in scene where long paths matter ----


def test_closed_room_long_paths_carry_more_than_five_percent():
    # what makes closed-room a depth test: paths of more than 10 segments carry >= 5% of the image
    scene = build_builtin("closed-room")
    full, full_se = _estimate(scene, 16, 12, 256, max_depth=-1)
    short, short_se = _estimate(scene, 16, 12, 256, max_depth=10)
    share = 1.0 - short / full
    assert np.all(share - 4 * np.hypot(full_se / full, short_se / short) > 0.05), share
