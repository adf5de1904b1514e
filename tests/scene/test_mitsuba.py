"""Mitsuba XML loading (grisx.scene.mitsuba): the Cornell box, every supported element, and every error path."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from grisx.errors import SceneFileError
from grisx.scene import shapes
from grisx.scene.lights import ConstantEnvironment, DirectionalLight, EnvMap, Projector
from grisx.scene.material import (
    CONDUCTOR_PRESETS,
    BlendBSDF,
    BumpMap,
    Conductor,
    Mask,
    NormalMap,
    Null,
    Dielectric,
    Diffuse,
    Plastic,
    Principled,
    PrincipledThin,
    RoughPlastic,
    RoughConductor,
    RoughDielectric,
    TextureRef,
    MATERIAL_ANISOTROPIC,
    MATERIAL_SCALAR_TEXTURES,
    MATERIAL_ROUGH_CONDUCTOR,
    MATERIAL_ROUGH_DIELECTRIC,
    PolarizedPlastic,
    Polarizer,
    Retarder,
    material_kinds,
    pack_materials,
)
from grisx.scene.analytic import SHAPE_KIND_NAMES
from grisx.scene.mitsuba import NAMED_IORS, load_mitsuba

DATA = Path(__file__).parent / "data"
CBOX = DATA / "cornell_box.xml"


def doc(body: str) -> str:
    """A scene document whose ``body`` starts on line 2."""
    return '<scene version="3.0.0">\n' + body + "\n</scene>\n"


def objects(scene):
    return {o.name: o for o in scene.objects}


def tessellated(o) -> shapes.MeshData:
    """An analytic shape's record as its tessellated twin in world space (the same unit shape, ``to_world``
    applied as for a mesh), so one set of checks reads both."""
    kind = {v: k for k, v in SHAPE_KIND_NAMES.items()}[o.shape.kind]
    m = getattr(shapes, kind)(flip_normals=o.shape.flip_normals)
    to_world = o.shape.to_world
    n = m.normals @ np.linalg.inv(to_world[:3, :3])
    return shapes.MeshData(m.vertices @ to_world[:3, :3].T + to_world[:3, 3], m.faces, n / np.linalg.norm(n, axis=1, keepdims=True), m.uvs)


def unit_face_normals(o) -> np.ndarray:
    fn = shapes.face_normals_of(o.vertices, o.faces)
    return fn / np.linalg.norm(fn, axis=1, keepdims=True)


def rot_y(deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


# ---- the Cornell box ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def cbox():
    return load_mitsuba(CBOX)


def test_cornell_box_counts(cbox):
    assert cbox.name == "cornell_box"
    assert len(cbox.objects) == 8  # light, 5 walls, 2 boxes
    assert cbox.triangle_count == 6 * 2 + 2 * 12
    assert len(cbox.materials) == 3  # white, green, red: shared by reference, registered once
    assert sum(o.emission is not None for o in cbox.objects) == 1
    assert cbox.point_lights == [] and cbox.environment is None and cbox.textures == []


def test_cornell_box_colours(cbox):
    obj = objects(cbox)
    white, green, red = (cbox.materials[obj[n].material] for n in ("back", "green-wall", "red-wall"))
    assert white == Diffuse(reflectance=(0.885809, 0.698859, 0.666422))
    assert green == Diffuse(reflectance=(0.105421, 0.37798, 0.076425))
    assert red == Diffuse(reflectance=(0.570068, 0.0430135, 0.0443706))
    for name in ("light", "floor", "ceiling", "back", "small-box", "large-box"):
        assert obj[name].material == obj["back"].material
    np.testing.assert_allclose(obj["light"].emission, [18.387, 13.9873, 6.75357])


def test_cornell_box_transforms(cbox):
    obj = objects(cbox)
    # light: scale(0.23, 0.19, 0.19), then rotate 90° about x ((x, y, z) → (x, −z, y)), then translate
    # (0, 0.99, 0.01): the corner (sx, sy, 0) of [-1, 1]² lands at (0.23 sx, 0.99, 0.01 + 0.19 sy)
    corners = [(-1, -1), (1, -1), (1, 1), (-1, 1)]  # rectangle vertex order
    expected = [(0.23 * sx, 0.99, 0.01 + 0.19 * sy) for sx, sy in corners]
    np.testing.assert_allclose(obj["light"].vertices, expected, atol=1e-12)
    np.testing.assert_allclose(unit_face_normals(obj["light"]), [[0, -1, 0]] * 2, atol=1e-12)  # emits downwards
    # walls face the inside of the box (towards the origin)
    for name, n in [("floor", (0, 1, 0)), ("ceiling", (0, -1, 0)), ("back", (0, 0, 1)),
                    ("green-wall", (-1, 0, 0)), ("red-wall", (1, 0, 0))]:
        np.testing.assert_allclose(unit_face_normals(obj[name]), [n] * 2, atol=1e-12)
        np.testing.assert_allclose(obj[name].normals, [n] * 4, atol=1e-12)
        assert np.allclose(np.abs(obj[name].vertices) @ np.abs(n), 1.0)  # the plane at distance 1
    # small box: cube vertex (1, −1, −1) → scale 0.3 → rotate −17° about y → translate (0.335, −0.7, 0.38)
    p = rot_y(-17) @ (0.3 * np.array([1.0, -1.0, -1.0])) + [0.335, -0.7, 0.38]
    np.testing.assert_allclose(obj["small-box"].vertices[0], p, atol=1e-12)
    # large box: non-uniform scale (0.3, 0.61, 0.3), rotate 18.25° about y, translate (−0.33, −0.4, −0.28)
    cube = shapes.cube()
    p = (rot_y(18.25) @ (np.array([0.3, 0.61, 0.3])[:, None] * cube.vertices.T)).T + [-0.33, -0.4, -0.28]
    np.testing.assert_allclose(obj["large-box"].vertices, p, atol=1e-12)
    assert obj["large-box"].vertices[:, 1].min() == pytest.approx(-1.01)  # its base sits just below the floor
    # boxes: outward normals (away from each box's centre)
    for name in ("small-box", "large-box"):
        o = obj[name]
        centre = o.vertices.mean(axis=0)
        c = o.vertices[o.faces].mean(axis=1) - centre
        assert np.all(np.einsum("ij,ij->i", unit_face_normals(o), c) > 0)


def test_cornell_box_camera_film_defaults(cbox):
    cam = cbox.camera
    assert cam.fov == pytest.approx(39.3077) and cam.fov_axis == "smaller"
    assert cam.near_clip == pytest.approx(0.001) and cam.far_clip == pytest.approx(100.0)
    assert cam.aperture_radius == 0
    # lookat(origin (0, 0, 3.9), target 0, up +y): columns left = up × dir, up' = dir × left, dir, origin
    np.testing.assert_allclose(cam.to_world, [[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, -1, 3.9], [0, 0, 0, 1]], atol=1e-12)
    assert (cbox.film.width, cbox.film.height) == (256, 256)
    assert cbox.defaults["spp"] == 64 and cbox.defaults["max_depth"] == 8


def test_cornell_box_params_override_defaults():
    s = load_mitsuba(CBOX, params={"spp": 4, "max_depth": 3})
    assert s.defaults["spp"] == 4 and s.defaults["max_depth"] == 3


def test_cornell_box_builds(cbox):
    built = cbox.build("cpu")
    assert built.num_triangles == 36
    assert built.features.has_area_lights and built.features.environment == "none"


def test_xml_string_is_accepted_and_params_substitute_anywhere():
    s = load_mitsuba(
        doc('<default name="r" value="0.25"/>\n'
            '<shape type="rectangle"><bsdf type="diffuse"><rgb name="reflectance" value="$r, $g, 0.5"/></bsdf>'
            '<emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>'),
        params={"g": 0.75},
    )
    assert s.materials[0] == Diffuse(reflectance=(0.25, 0.75, 0.5))
    np.testing.assert_allclose(s.objects[0].emission, [1, 1, 1])


# ---- transforms ---------------------------------------------------------------------------


def rect_with(transform: str):
    s = load_mitsuba(doc(f'<shape type="rectangle"><transform name="to_world">{transform}</transform></shape>'))
    return s.objects[0].vertices


def test_transforms_compose_in_document_order():
    v = rect_with('<translate x="1"/><scale value="2"/>')  # scale after translate: (x + 1)·2
    np.testing.assert_allclose(v[2], [4, 2, 0])
    v = rect_with('<scale value="2"/><translate x="1"/>')  # 2x + 1
    np.testing.assert_allclose(v[2], [3, 2, 0])


def test_transform_ops():
    np.testing.assert_allclose(rect_with('<scale x="2" z="5"/>')[2], [2, 1, 0])
    np.testing.assert_allclose(rect_with('<scale value="1 2 3"/>')[2], [1, 2, 0])
    np.testing.assert_allclose(rect_with('<translate value="1,2 3"/>')[2], [2, 3, 3])
    np.testing.assert_allclose(rect_with('<rotate z="1" angle="90"/>')[1], [1, 1, 0], atol=1e-12)  # (1,−1) → (1, 1)
    # Mitsuba 3 does not normalize the axis: (0, 0, 2) rotates and scales xy by |a| = 2 (its own answer: [2, 2, 0])
    np.testing.assert_allclose(rect_with('<rotate value="0, 0, 2" angle="90"/>')[1], [2, 2, 0], atol=1e-12)
    np.testing.assert_allclose(rect_with('<matrix value="1 0 0 5  0 1 0 6  0 0 1 7  0 0 0 1"/>')[0], [4, 5, 7])
    np.testing.assert_allclose(rect_with('<matrix value="0 -1 0  1 0 0  0 0 1"/>')[1], [1, 1, 0])
    # lookat without 'up' picks Mitsuba's coordinate_system(dir) tangent
    v = rect_with('<lookat origin="0 0 0" target="0 0 5"/>')
    assert np.allclose(v[:, 2], 0) and np.allclose(np.abs(v[:, :2]), 1)


# ---- shapes -----------------------------------------------------------------------------------


def test_sphere_center_radius_and_to_world():
    s = load_mitsuba(doc('<shape type="sphere"><point name="center" x="1" y="2" z="3"/><float name="radius" value="0.5"/>'
                         '<transform name="to_world"><translate z="10"/></transform></shape>'))
    assert s.shape_count == 1 and s.triangle_count == 0  # analytic (grisx.scene.analytic)
    o = tessellated(s.objects[0])
    v = o.vertices
    np.testing.assert_allclose(np.linalg.norm(v - [1, 2, 13], axis=1), 0.5, atol=1e-12)
    np.testing.assert_allclose(o.normals, (v - [1, 2, 13]) / 0.5, atol=1e-9)  # outward
    assert s.objects[0].shape.orientation == 1.0
    s = load_mitsuba(doc('<shape type="sphere"><boolean name="flip_normals" value="true"/></shape>'))
    assert s.objects[0].shape.orientation == -1.0
    o = tessellated(s.objects[0])
    assert np.all(np.einsum("ij,ij->i", o.normals, o.vertices) < 0)


def test_cylinder_p0_p1_radius_and_mitsubas_frame():
    s = load_mitsuba(doc('<shape type="cylinder"><point name="p0" x="1" y="2" z="3"/><point name="p1" x="1" y="5" z="3"/>'
                         '<float name="radius" value="0.5"/></shape>'))
    o = tessellated(s.objects[0])
    v = o.vertices
    np.testing.assert_allclose(np.hypot(v[:, 0] - 1, v[:, 2] - 3), 0.5, atol=1e-12)  # axis along +y through (1, ·, 3)
    assert set(np.round(np.unique(v[:, 1]), 12)) == {2.0, 5.0}
    np.testing.assert_allclose(o.normals, (v - [1, v[0, 1], 3]) * [2, 0, 2], atol=1e-9)  # outward, unit
    # Mitsuba's coordinate_system for n = +y: s = (1, 0, 0)·… → φ = 0 (u = 0) lies along s = (1, 0, −0) and t = (0, 0, −1)
    at_u0 = v[(o.uvs[:, 0] == 0.0)]
    np.testing.assert_allclose(at_u0[:, [0, 2]], [[1.5, 3.0]] * len(at_u0), atol=1e-12)
    quarter = np.isclose(o.uvs[:, 0], 0.25)
    np.testing.assert_allclose(v[quarter][:, [0, 2]], [[1.0, 2.5]] * quarter.sum(), atol=1e-12)


def test_disk_and_flipped_rectangle():
    s = load_mitsuba(doc('<shape type="disk"><transform name="to_world"><scale value="2"/></transform></shape>\n'
                         '<shape type="rectangle"><boolean name="flip_normals" value="true"/></shape>'))
    d, r = tessellated(s.objects[0]), s.objects[1]
    assert shapes.mesh_area(d.vertices, d.faces) == pytest.approx(4 * math.pi, rel=1e-3)
    np.testing.assert_allclose(unit_face_normals(d), np.tile([0, 0, 1], (len(d.faces), 1)), atol=1e-12)
    np.testing.assert_allclose(unit_face_normals(r), [[0, 0, -1]] * 2)
    np.testing.assert_allclose(r.normals, [[0, 0, -1]] * 4)


def test_obj_and_ply_shapes(tmp_path):
    xml = tmp_path / "meshes.xml"
    xml.write_text(doc(
        f'<shape type="obj"><string name="filename" value="{DATA / "seam.obj"}"/></shape>\n'
        f'<shape type="obj"><string name="filename" value="{DATA / "seam.obj"}"/><boolean name="face_normals" value="true"/>'
        f'<boolean name="flip_tex_coords" value="false"/></shape>\n'
        f'<shape type="ply"><string name="filename" value="{DATA / "quad.ply"}"/>'
        f'<transform name="to_world"><translate z="1"/></transform></shape>'))
    s = load_mitsuba(xml)
    a, b, c = s.objects
    assert len(a.vertices) == 8 and a.uvs is not None and a.normals is not None
    assert b.normals is None and not np.allclose(a.uvs, b.uvs)
    np.testing.assert_allclose(b.uvs[:, 1], 1 - a.uvs[:, 1])
    np.testing.assert_allclose(c.vertices[:, 2], [1, 1, 1, 1, 2])


def test_relative_paths_are_relative_to_the_file(tmp_path):
    (tmp_path / "m").mkdir()
    (tmp_path / "m" / "q.ply").write_bytes((DATA / "quad.ply").read_bytes())
    (tmp_path / "s.xml").write_text(doc('<shape type="ply"><string name="filename" value="m/q.ply"/></shape>'))
    assert len(load_mitsuba(tmp_path / "s.xml").objects[0].vertices) == 5


def test_cube_face_normals_and_ply_flip_tex_coords():
    s = load_mitsuba(doc(f'<shape type="cube"><boolean name="face_normals" value="true"/></shape>\n'
                         f'<shape type="ply"><string name="filename" value="{DATA / "quad.ply"}"/>'
                         f'<boolean name="flip_tex_coords" value="true"/></shape>'))
    cube, quad = s.objects
    # Mitsuba 3.9.1's cube sets its per-face vertex normals whatever face_normals says (they decide its front
    # side under a mirroring to_world: conformance case mirrored_meshes)
    np.testing.assert_allclose(cube.normals, shapes.cube().normals)
    np.testing.assert_allclose(quad.uvs[:, 1], [1, 1, 0, 0, 0.5])


def test_shape_without_bsdf_gets_mitsubas_default():
    s = load_mitsuba(doc('<shape type="cube"/><shape type="rectangle"/>'))
    assert s.materials == [Diffuse(reflectance=(0.5, 0.5, 0.5))]


def test_emitter_without_bsdf_is_black():
    """Mitsuba 3 gives an emitting shape without a BSDF a black diffuse: it reflects nothing (conformance case emitter_no_bsdf)."""
    s = load_mitsuba(doc('<shape type="rectangle"><emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>'
                         '<shape type="cube"/><shape type="disk"><emitter type="area"><rgb name="radiance" value="2"/></emitter></shape>'))
    assert [s.materials[o.material] for o in s.objects] == [Diffuse(reflectance=(0.0,) * 3), Diffuse(reflectance=(0.5,) * 3), Diffuse(reflectance=(0.0,) * 3)]


# ---- BSDFs ------------------------------------------------------------------------------------------


def bsdf(xml: str):
    s = load_mitsuba(doc(f'<shape type="rectangle">{xml}</shape>'))
    return s.materials[s.objects[0].material]


def test_bsdfs():
    assert bsdf('<bsdf type="diffuse"/>') == Diffuse()
    assert bsdf('<bsdf type="diffuse"><spectrum name="reflectance" value="0.3"/></bsdf>') == Diffuse(reflectance=(0.3,) * 3)
    assert bsdf('<bsdf type="diffuse"><float name="reflectance" value="0.2"/></bsdf>') == Diffuse(reflectance=(0.2,) * 3)
    assert bsdf('<bsdf type="conductor"/>') == Conductor(eta=(0.0,) * 3, k=(1.0,) * 3)
    au_eta, au_k = CONDUCTOR_PRESETS["Au"]
    assert bsdf('<bsdf type="conductor"><string name="material" value="Au"/></bsdf>') == Conductor(eta=au_eta, k=au_k)
    rc = bsdf('<bsdf type="roughconductor"><string name="distribution" value="ggx"/><float name="alpha" value="0.3"/>'
              '<rgb name="eta" value="0.2 0.3 0.4"/><rgb name="k" value="3"/>'
              '<rgb name="specular_reflectance" value="0.9"/></bsdf>')
    assert rc == RoughConductor(alpha=0.3, eta=(0.2, 0.3, 0.4), k=(3.0,) * 3, specular_reflectance=(0.9,) * 3)
    assert bsdf('<bsdf type="dielectric"/>') == Dielectric(int_ior=NAMED_IORS["bk7"], ext_ior=NAMED_IORS["air"])
    assert NAMED_IORS["bk7"] == 1.5046 and NAMED_IORS["air"] == 1.000277
    d = bsdf('<bsdf type="dielectric"><string name="int_ior" value="water"/><float name="ext_ior" value="1.1"/></bsdf>')
    assert (d.int_ior, d.ext_ior) == (1.333, 1.1)
    rd = bsdf('<bsdf type="roughdielectric"><string name="distribution" value="ggx"/><float name="alpha" value="0.05"/>'
              '<string name="int_ior" value="diamond"/></bsdf>')
    assert rd == RoughDielectric(alpha=0.05, int_ior=2.419, ext_ior=1.000277)
    ts = bsdf('<bsdf type="twosided"><bsdf type="roughconductor"><string name="distribution" value="ggx"/></bsdf></bsdf>')
    # Mitsuba's default distribution is Beckmann
    assert bsdf('<bsdf type="roughconductor"/>').distribution == "beckmann"
    assert bsdf('<bsdf type="roughdielectric"><float name="alpha" value="0.2"/></bsdf>') == RoughDielectric(alpha=0.2, distribution="beckmann")
    assert ts == RoughConductor(two_sided=True)


def test_anisotropic_roughconductor():
    """roughconductor's alpha_u / alpha_v (numbers or textures) as Mitsuba's microfacet.h reads them."""
    rc = bsdf('<bsdf type="roughconductor"><string name="distribution" value="ggx"/><float name="alpha_u" value="0.25"/>'
              '<float name="alpha_v" value="0.05"/></bsdf>')
    assert rc == RoughConductor(distribution="ggx", alpha_u=0.25, alpha_v=0.05, eta=(0.0,) * 3, k=(1.0,) * 3)
    assert material_kinds([rc]) == {MATERIAL_ROUGH_CONDUCTOR, MATERIAL_ANISOTROPIC}
    packed = pack_materials([rc], "cpu").numpy()[0]
    assert (packed["alpha"], packed["anisotropic"]) == (pytest.approx(0.25), 1) and packed["alpha_v"] == pytest.approx(0.05)
    # equal alphas: isotropic, nothing of the tangent compiled in
    iso = bsdf('<bsdf type="roughconductor"><float name="alpha_u" value="0.2"/><float name="alpha_v" value="0.2"/></bsdf>')
    assert material_kinds([iso]) == {MATERIAL_ROUGH_CONDUCTOR} and material_kinds([RoughConductor()]) == {MATERIAL_ROUGH_CONDUCTOR}
    # textures (the render test's carbon fibre: two inverted checkerboards)
    tex = bsdf('<bsdf type="roughconductor"><texture type="checkerboard" name="alpha_u"><float name="color0" value="0.05"/>'
               '<float name="color1" value="0.3"/></texture><texture type="checkerboard" name="alpha_v">'
               '<float name="color0" value="0.3"/><float name="color1" value="0.05"/></texture></bsdf>')
    assert (tex.alpha_u.texture_id, tex.alpha_v.texture_id, tex.distribution) == (0, 1, "beckmann")
    packed = pack_materials([tex], "cpu").numpy()[0]
    assert (packed["alpha_u_texture"], packed["alpha_v_texture"], packed["anisotropic"]) == (0, 1, 1)
    # one texture as alpha: isotropic, its value at the hit in both
    one = bsdf('<bsdf type="roughconductor"><texture type="checkerboard" name="alpha"/></bsdf>')
    assert one.alpha == TextureRef(0) and one.alpha_u is None and material_kinds([one]) == {MATERIAL_ROUGH_CONDUCTOR, MATERIAL_SCALAR_TEXTURES}  # α resolved at the hit
    packed = pack_materials([one], "cpu").numpy()[0]
    assert (packed["alpha_u_texture"], packed["alpha_v_texture"], packed["anisotropic"]) == (0, 0, 0)
    with pytest.raises(SceneFileError, match=r"<float name=\"alpha_u\"> both 'alpha_u' and 'alpha_v' must be specified"):
        bsdf('<bsdf type="roughconductor"><float name="alpha_u" value="0.1"/></bsdf>')
    with pytest.raises(SceneFileError, match="give either 'alpha' or 'alpha_u'/'alpha_v', not both"):
        bsdf('<bsdf type="roughconductor"><float name="alpha" value="0.1"/><float name="alpha_u" value="0.1"/>'
             '<float name="alpha_v" value="0.3"/></bsdf>')
    with pytest.raises(SceneFileError, match="alpha_v must be a finite positive number"):
        bsdf('<bsdf type="roughconductor"><float name="alpha_u" value="0.1"/><float name="alpha_v" value="-0.3"/></bsdf>')
    with pytest.raises(SceneFileError, match="unsupported parameter 'alpha_u'"):  # as in Mitsuba 3: roughdielectric is refused here
        bsdf('<bsdf type="roughdielectric"><float name="alpha_u" value="0.1"/><float name="alpha_v" value="0.3"/></bsdf>')
    with pytest.raises(SceneFileError, match="an anisotropic roughconductor .* on an analytic sphere is not supported"):
        load_mitsuba(doc('<shape type="sphere"><bsdf type="roughconductor"><float name="alpha_u" value="0.1"/>'
                         '<float name="alpha_v" value="0.3"/></bsdf></shape>'))
    # rawconstant textures, and a bitmap's storage format (the normal-map render tests)
    nm = bsdf('<bsdf type="normalmap"><texture type="rawconstant" name="normalmap"><vector name="value" value="0.5, 0.5, 1.0"/>'
              '</texture><bsdf type="diffuse"/></bsdf>')
    assert isinstance(nm, NormalMap)


def test_plastics():
    # Mitsuba's defaults: polypropylene in air, diffuse 0.5, specular 1, linear, Beckmann α 0.1
    assert bsdf('<bsdf type="plastic"/>') == Plastic(int_ior=1.49, ext_ior=1.000277)
    assert bsdf('<bsdf type="roughplastic"/>') == RoughPlastic(alpha=0.1, distribution="beckmann")
    p = bsdf('<bsdf type="plastic"><rgb name="diffuse_reflectance" value="0.1 0.2 0.3"/><string name="int_ior" value="bk7"/>'
             '<string name="ext_ior" value="water"/><boolean name="nonlinear" value="true"/>'
             '<rgb name="specular_reflectance" value="0.9"/></bsdf>')
    assert p == Plastic(diffuse_reflectance=(0.1, 0.2, 0.3), specular_reflectance=(0.9,) * 3, int_ior=1.5046, ext_ior=1.333, nonlinear=True)
    rp = bsdf('<bsdf type="twosided"><bsdf type="roughplastic"><string name="distribution" value="ggx"/><float name="alpha" value="0.25"/>'
              '<boolean name="sample_visible" value="false"/><texture type="checkerboard" name="diffuse_reflectance"/></bsdf></bsdf>')
    assert rp.alpha == 0.25 and rp.distribution == "ggx" and rp.two_sided and rp.diffuse_reflectance.texture_id == 0
    assert rp.diffuse_mean == pytest.approx(0.3)  # the checkerboard's mean, as Mitsuba's texture.mean() sets the lobe weights
    with pytest.raises(SceneFileError, match=r"<float name=\"alpha_u\"> roughplastic does not support anisotropic roughness"):
        bsdf('<bsdf type="roughplastic"><float name="alpha_u" value="0.1"/><float name="alpha_v" value="0.3"/></bsdf>')
    with pytest.raises(SceneFileError, match="specular_reflectance': textures are supported only as"):
        bsdf('<bsdf type="plastic"><texture type="checkerboard" name="specular_reflectance"/></bsdf>')
    with pytest.raises(SceneFileError, match="int_ior and ext_ior must differ"):
        bsdf('<bsdf type="plastic"><float name="int_ior" value="1.2"/><float name="ext_ior" value="1.2"/></bsdf>')


def test_pplastic_polarizer_retarder_and_textured_roughdielectric_alpha():
    """plugins2 (issue 38): Mitsuba's polarization plugins as its RGB variants read them, and roughdielectric's textured alpha."""
    # pplastic's defaults: polypropylene in air, diffuse 0.5, specular 1, Beckmann α 0.1 (pplastic.cpp)
    assert bsdf('<bsdf type="pplastic"/>') == PolarizedPlastic(int_ior=1.49, ext_ior=1.000277, alpha=0.1, distribution="beckmann")
    pp = bsdf('<bsdf type="pplastic"><rgb name="diffuse_reflectance" value="0.05, 0.03, 0.1"/><float name="alpha" value="0.06"/>'
              '<rgb name="specular_reflectance" value="0"/><float name="eta" value="1.6"/></bsdf>')
    assert pp == PolarizedPlastic(diffuse_reflectance=(0.05, 0.03, 0.1), alpha=0.06, specular_reflectance=(0.0,) * 3,
                                  int_ior=1.6, ext_ior=1.0)
    tex = bsdf('<bsdf type="pplastic"><string name="distribution" value="ggx"/><texture type="checkerboard" name="alpha"/>'
               '<texture type="checkerboard" name="diffuse_reflectance"/></bsdf>')
    assert tex.alpha == TextureRef(1) and tex.diffuse_reflectance == TextureRef(0) and tex.diffuse_mean == pytest.approx(0.3)
    an = bsdf('<bsdf type="pplastic"><float name="alpha_u" value="0.1"/><float name="alpha_v" value="0.3"/></bsdf>')
    assert (an.alpha_u, an.alpha_v) == (0.1, 0.3) and MATERIAL_ANISOTROPIC in material_kinds([an])
    with pytest.raises(SceneFileError, match="an anisotropic pplastic .* on an analytic sphere is not supported"):
        load_mitsuba(doc('<shape type="sphere"><bsdf type="pplastic"><float name="alpha_u" value="0.1"/>'
                         '<float name="alpha_v" value="0.3"/></bsdf></shape>'))
    # polarizer and retarder: null lobes of weight ½ T and T; their angles do not act on unpolarized light
    assert bsdf('<bsdf type="polarizer"><spectrum name="theta" value="90"/></bsdf>') == Polarizer()
    assert bsdf('<bsdf type="polarizer"><rgb name="transmittance" value="0.5, 0.6, 0.7"/><boolean name="polarizing" '
                'value="false"/></bsdf>') == Polarizer(transmittance=(0.5, 0.6, 0.7))
    assert bsdf('<bsdf type="retarder"><float name="theta" value="30"/><float name="delta" value="45"/></bsdf>') == Retarder()
    # roughdielectric: a texture as alpha (mitsuba-data's bsdf_roughdielectric_textured.xml), isotropic
    rd = bsdf('<bsdf type="roughdielectric"><texture type="checkerboard" name="alpha"><float name="color0" value="0.0"/>'
              '<float name="color1" value="0.4"/></texture></bsdf>')
    assert rd.alpha == TextureRef(0) and rd.distribution == "beckmann" and material_kinds([rd]) == {MATERIAL_ROUGH_DIELECTRIC, MATERIAL_SCALAR_TEXTURES}


def test_twosided_and_shared_references():
    s = load_mitsuba(doc(
        '<bsdf type="diffuse" id="d"><rgb name="reflectance" value="0.1 0.2 0.3"/></bsdf>\n'
        '<bsdf type="twosided" id="t"><ref id="d"/></bsdf>\n'
        '<shape type="rectangle"><ref id="t"/></shape><shape type="cube"><ref id="t"/></shape>'
        '<shape type="disk"><ref id="d"/></shape>'))
    a, b, c = s.objects
    assert a.material == b.material != c.material
    assert s.materials[a.material] == Diffuse(reflectance=(0.1, 0.2, 0.3), two_sided=True)
    assert s.materials[c.material] == Diffuse(reflectance=(0.1, 0.2, 0.3))


def test_null_mask_normalmap_bumpmap():
    assert bsdf('<bsdf type="null"/>') == Null()
    # mask: Mitsuba's default opacity 0.5; a twosided around it goes to the nested BSDF (a mask is the same from both sides)
    assert bsdf('<bsdf type="mask"><bsdf type="diffuse"/></bsdf>') == Mask(Diffuse(), 0.5)
    assert bsdf('<bsdf type="twosided"><bsdf type="mask"><float name="opacity" value="0.3"/><bsdf type="roughconductor"/></bsdf></bsdf>') \
        == Mask(RoughConductor(distribution="beckmann", two_sided=True), 0.3)
    m = bsdf('<bsdf type="mask"><texture type="checkerboard" name="opacity"/><bsdf type="twosided"><bsdf type="diffuse"/></bsdf></bsdf>')
    assert m == Mask(Diffuse(two_sided=True), TextureRef(0))
    nm = bsdf('<bsdf type="normalmap"><texture type="checkerboard" name="normalmap"/>'
              '<boolean name="flip_invalid_normals" value="false"/><bsdf type="plastic"/></bsdf>')
    assert nm == NormalMap(Plastic(int_ior=1.49, ext_ior=1.000277), TextureRef(0), flip_invalid_normals=False)
    # bumpmap: its one nested texture, whatever its name (bumpmap.cpp), and scale [1]
    bm = bsdf('<bsdf type="mask"><float name="opacity" value="0.9"/><bsdf type="bumpmap"><float name="scale" value="0.02"/>'
              '<texture type="checkerboard" name="floor_tiles_bumpmap"/><bsdf type="diffuse"/></bsdf></bsdf>')
    assert bm == Mask(BumpMap(Diffuse(), TextureRef(0), scale=0.02), 0.9)
    assert bsdf('<bsdf type="bumpmap"><texture type="checkerboard" name="h"/><bsdf type="diffuse"/></bsdf>').scale == 1.0
    # blendbsdf: the first nested BSDF weighs 1 − weight, the second weight (blendbsdf.cpp)
    bl = bsdf('<bsdf type="blendbsdf"><float name="weight" value="0.25"/><bsdf type="diffuse"/>'
              '<bsdf type="diffuse"><rgb name="reflectance" value="0.1 0.2 0.3"/></bsdf></bsdf>')
    assert bl == BlendBSDF(Diffuse(), Diffuse((0.1, 0.2, 0.3)), 0.25)
    assert bsdf('<bsdf type="blendbsdf"><texture type="checkerboard" name="weight"/><bsdf type="diffuse"/><bsdf type="diffuse"/></bsdf>').weight \
        == TextureRef(0)
    # any two plain BSDFs (plugins2): the second one untextured and isotropic
    gb = bsdf('<bsdf type="blendbsdf"><float name="weight" value="0.4"/><bsdf type="plastic"/><bsdf type="conductor"/></bsdf>')
    assert gb == BlendBSDF(Plastic(int_ior=1.49, ext_ior=1.000277), Conductor(eta=(0.0,) * 3, k=(1.0,) * 3), 0.4)
    tb = bsdf('<bsdf type="twosided"><bsdf type="blendbsdf"><float name="weight" value="0.4"/><bsdf type="diffuse"/>'
              '<bsdf type="conductor"/></bsdf></bsdf>')  # twosided around a blend: both BSDFs two-sided
    assert tb.bsdf0.two_sided and tb.bsdf1.two_sided and tb.two_sided
    for xml, message in [
        ('<bsdf type="mask"/>', "mask needs exactly one nested BSDF, got 0"),
        ('<bsdf type="normalmap"><bsdf type="diffuse"/></bsdf>', "normalmap needs a texture named 'normalmap'"),
        ('<bsdf type="bumpmap"><bsdf type="diffuse"/></bsdf>', "bumpmap needs exactly one nested texture, got 0"),
        ('<bsdf type="twosided"><bsdf type="normalmap"><texture type="checkerboard" name="normalmap"/><bsdf type="diffuse"/></bsdf></bsdf>',
         "twosided around a normalmap or bumpmap is not supported"),
        ('<bsdf type="normalmap"><texture type="checkerboard" name="normalmap"/><bsdf type="mask"><bsdf type="diffuse"/></bsdf></bsdf>',
         "a mask inside a normalmap or bumpmap is not supported"),
        ('<bsdf type="twosided"><bsdf type="mask"><bsdf type="dielectric"/></bsdf></bsdf>', "twosided cannot wrap a transmissive BSDF"),
        ('<bsdf type="blendbsdf"><float name="weight" value="0.5"/><bsdf type="diffuse"/><bsdf type="mask"><bsdf type="plastic"/>'
         '</bsdf></bsdf>', "a blendbsdf of Mask is not supported"),
        ('<bsdf type="blendbsdf"><float name="weight" value="0.5"/><bsdf type="diffuse"/><bsdf type="roughdielectric">'
         '<texture type="checkerboard" name="alpha"/></bsdf></bsdf>', "second BSDF of a blendbsdf must be untextured"),
        ('<bsdf type="blendbsdf"><bsdf type="diffuse"/><bsdf type="diffuse"/></bsdf>', "missing required parameter 'weight'"),
    ]:
        with pytest.raises(SceneFileError, match=message):
            bsdf(xml)
    with pytest.raises(SceneFileError, match="a normalmap or bumpmap on an analytic sphere is not supported"):
        load_mitsuba(doc('<shape type="sphere"><bsdf type="normalmap"><texture type="checkerboard" name="normalmap"/>'
                         '<bsdf type="diffuse"/></bsdf></shape>'))


def test_principled_bsdfs():
    """principled.cpp / principledthin.cpp parameters: numbers or textures, Mitsuba's defaults; the corners refused."""
    assert bsdf('<bsdf type="principled"/>') == Principled()
    p = bsdf('<bsdf type="principled"><rgb name="base_color" value="0.2 0.8 0.1"/><float name="metallic" value="0.7"/>'
             '<float name="specular" value="0.6"/><texture type="checkerboard" name="clearcoat"/><float name="spec_trans" value="0.4"/>'
             '<float name="main_specular_sampling_rate" value="1"/></bsdf>')
    assert p == Principled(base_color=(0.2, 0.8, 0.1), metallic=0.7, specular=0.6, clearcoat=TextureRef(0), spec_trans=0.4)
    t = bsdf('<bsdf type="principledthin"><float name="eta" value="1.33"/><float name="diff_trans" value="1.4"/>'
             '<texture type="checkerboard" name="base_color"/></bsdf>')
    assert t == PrincipledThin(eta=1.33, diff_trans=1.4, base_color=TextureRef(0))
    assert bsdf('<bsdf type="twosided"><bsdf type="principled"><float name="spec_trans" value="0"/></bsdf></bsdf>').two_sided
    for xml, message in [
        ('<bsdf type="principled"><float name="eta" value="1.5"/><float name="specular" value="0.5"/></bsdf>',
         "give either 'eta' or 'specular', not both"),
        ('<bsdf type="principled"><float name="clearcoat_sampling_rate" value="0"/></bsdf>',
         "parameter 'clearcoat_sampling_rate' of principled: sampling rates other than 1 are not supported"),
        ('<bsdf type="principledthin"><texture type="checkerboard" name="eta"/></bsdf>', "a textured eta is not supported"),
        ('<bsdf type="twosided"><bsdf type="principled"><float name="spec_trans" value="0.1"/></bsdf></bsdf>',
         "twosided cannot wrap a transmissive BSDF"),
        ('<bsdf type="twosided"><bsdf type="principledthin"/></bsdf>', "twosided cannot wrap a transmissive BSDF"),
        ('<bsdf type="principled">' + "".join(f'<texture type="checkerboard" name="{n}"/>' for n in
                                              ("metallic", "sheen", "clearcoat", "spec_tint", "flatness")) + '</bsdf>',
         "at most four of metallic, .* may be textures"),
        ('<bsdf type="principled"><float name="subsurface" value="0.5"/></bsdf>', "unsupported parameter 'subsurface'"),
    ]:
        with pytest.raises(SceneFileError, match=message):
            bsdf(xml)
    with pytest.raises(SceneFileError, match="a principled BSDF with 'anisotropic' on an analytic sphere is not supported"):
        load_mitsuba(doc('<shape type="sphere"><bsdf type="principled"><float name="anisotropic" value="0.5"/></bsdf></shape>'))


# ---- textures and emitters ---------------------------------------------------------------------------


def test_bitmap_textures(tmp_path):
    from PIL import Image

    from grisx.imageio import write_exr

    px = np.array([[[0, 128, 255], [10, 20, 30]]], dtype=np.uint8)  # 1×2 RGB
    Image.fromarray(px).save(tmp_path / "t.png")
    write_exr(tmp_path / "t.exr", np.full((2, 3, 3), 0.25, dtype=np.float32))
    (tmp_path / "s.xml").write_text(doc(
        '<texture type="bitmap" id="tex"><string name="filename" value="t.png"/></texture>\n'
        '<shape type="rectangle"><bsdf type="diffuse"><ref name="reflectance" id="tex"/></bsdf></shape>\n'
        '<shape type="rectangle"><bsdf type="diffuse"><texture type="bitmap" name="reflectance">'
        '<string name="filename" value="t.png"/><boolean name="raw" value="true"/></texture></bsdf></shape>\n'
        '<shape type="cube"><bsdf type="diffuse"><texture type="bitmap" name="reflectance">'
        '<string name="filename" value="t.exr"/><string name="filter_type" value="bilinear"/></texture></bsdf></shape>'))
    s = load_mitsuba(tmp_path / "s.xml")
    refs = [s.materials[o.material].reflectance for o in s.objects]
    assert refs == [TextureRef(0), TextureRef(1), TextureRef(2)]
    c = px / 255.0  # Mitsuba decodes 8-bit sRGB with the exact curve
    srgb = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    np.testing.assert_allclose(s.textures[0], srgb, rtol=1e-6)
    np.testing.assert_allclose(s.textures[1], c, rtol=1e-6)
    np.testing.assert_allclose(s.textures[2], 0.25)


def test_bitmap_wrap_mode_and_filter_type(tmp_path):
    from grisx.imageio import write_exr

    write_exr(tmp_path / "t.exr", np.full((2, 3, 3), 0.25, dtype=np.float32))

    def texture(params: str):
        (tmp_path / "s.xml").write_text(doc('<shape type="rectangle"><bsdf type="diffuse"><texture type="bitmap" name="reflectance">'
                                            f'<string name="filename" value="t.exr"/>{params}</texture></bsdf></shape>'))
        return load_mitsuba(tmp_path / "s.xml").textures[0]

    assert isinstance(texture(""), np.ndarray)  # Mitsuba's defaults: repeat, bilinear
    for wrap in ("repeat", "mirror", "clamp"):
        for filt in ("bilinear", "nearest"):
            t = texture(f'<string name="wrap_mode" value="{wrap}"/><string name="filter_type" value="{filt}"/>')
            assert isinstance(t, np.ndarray) if (wrap, filt) == ("repeat", "bilinear") else (t.wrap_mode, t.filter_type) == (wrap, filt)
    with pytest.raises(SceneFileError, match=r"s\.xml:2: <string name=\"wrap_mode\"> parameter 'wrap_mode' = 'border' is not supported \(supported: repeat, mirror, clamp\)"):
        texture('<string name="wrap_mode" value="border"/>')


def test_emitters(tmp_path):
    from grisx.imageio import write_exr

    write_exr(tmp_path / "sky.exr", np.full((4, 8, 3), 2.0, dtype=np.float32))
    (tmp_path / "s.xml").write_text(doc(
        '<shape type="rectangle"/>\n'
        '<emitter type="point"><point name="position" x="1" y="2" z="3"/><rgb name="intensity" value="5 6 7"/></emitter>\n'
        '<emitter type="point"><transform name="to_world"><translate x="-1"/></transform></emitter>\n'
        '<emitter type="envmap"><string name="filename" value="sky.exr"/><float name="scale" value="0.5"/>'
        '<transform name="to_world"><rotate y="1" angle="90"/></transform></emitter>'))
    s = load_mitsuba(tmp_path / "s.xml")
    p0, p1 = s.point_lights
    np.testing.assert_allclose(p0.position, [1, 2, 3])
    np.testing.assert_allclose(p0.intensity, [5, 6, 7])
    np.testing.assert_allclose(p1.position, [-1, 0, 0])
    np.testing.assert_allclose(p1.intensity, [1, 1, 1])
    assert p0.direction is None and p1.direction is None
    env = s.environment
    assert isinstance(env, EnvMap) and env.scale == 0.5
    np.testing.assert_allclose(env.image, 2.0)
    np.testing.assert_allclose(np.asarray(env.to_world)[:3, :3], rot_y(90), atol=1e-12)
    s = load_mitsuba(doc('<shape type="cube"/><emitter type="constant"><rgb name="radiance" value="0.5"/></emitter>'))
    assert isinstance(s.environment, ConstantEnvironment)
    np.testing.assert_allclose(s.environment.radiance, [0.5] * 3)


def test_sensor_variants():
    s = load_mitsuba(doc('<shape type="cube"/><sensor type="perspective"/>'))
    # Mitsuba: no fov → a 50 mm lens on 36×24 mm film, measured along the diagonal
    assert s.camera.fov_axis == "diagonal"
    assert s.camera.fov == pytest.approx(math.degrees(2 * math.atan(math.hypot(36, 24) / 100)))
    s = load_mitsuba(doc('<shape type="cube"/><sensor type="thinlens"><float name="fov" value="30"/>'
                         '<string name="fov_axis" value="y"/><float name="aperture_radius" value="0.1"/>'
                         '<float name="focus_distance" value="4"/><film type="hdrfilm"/>'
                         '<sampler type="stratified"><integer name="sample_count" value="9"/></sampler></sensor>'
                         '<integrator type="path"/>'))
    assert (s.camera.fov, s.camera.fov_axis, s.camera.aperture_radius, s.camera.focus_distance) == (30, "y", 0.1, 4)
    assert (s.film.width, s.film.height) == (768, 576)  # Mitsuba's hdrfilm defaults
    assert s.defaults["spp"] == 9 and s.defaults["max_depth"] == -1  # Mitsuba: unbounded


def test_gaussian_rfilter_is_accepted_as_box():
    s = load_mitsuba(doc('<shape type="cube"/><sensor type="perspective"><film type="hdrfilm">'
                         '<rfilter type="gaussian"><float name="stddev" value="0.5"/></rfilter></film></sensor>'))
    assert s.film.width == 768


def test_tent_rfilter():
    def film(rfilter: str):
        return load_mitsuba(doc(f'<shape type="cube"/><sensor type="perspective"><film type="hdrfilm">{rfilter}</film></sensor>')).film

    f = film('<rfilter type="tent"/>')
    assert (f.filter_tent, f.filter_stddev) == (1.0, 0.0)  # Mitsuba's default radius
    assert film('<rfilter type="tent"><float name="radius" value="1.25"/></rfilter>').filter_tent == 1.25
    assert (film("").filter_stddev, film("").filter_tent) == (0.5, 0.0)  # no filter: Mitsuba's gaussian
    assert film('<boolean name="banner" value="false"/>').width == 768  # accepted, ignored, as by Mitsuba 3


def test_mitsuba_0x_names_are_upgraded():
    s = load_mitsuba('<scene version="0.6.0"><shape type="rectangle"><boolean name="flipNormals" value="true"/>'
                     '<transform name="toWorld"><translate x="1"/></transform>'
                     '<bsdf type="dielectric"><float name="intIOR" value="1.7"/></bsdf></shape></scene>')
    assert s.materials[0].int_ior == 1.7
    np.testing.assert_allclose(s.objects[0].vertices[:, 0].min(), 0.0)


# ---- errors --------------------------------------------------------------------------------------------

ERRORS = [
    # (document, line, element contains, attribute, message contains)
    ('<scene version="3.0.0">\n<shape type="cube">\n</scene>', 3, None, None, "malformed XML"),
    ("<scene version='3.0.0'>\n<shape type=\"cube\"/>\n<shape", 3, None, None, "malformed XML"),
    ("<scene>\n</scene>", 1, "scene", "version", "version"),
    ('<scenes version="3.0.0"/>', 1, "scenes", None, "root element"),
    (doc('<medium type="homogeneous"/>'), 2, "medium", None, "unsupported element <medium>: participating media"),
    (doc('<include filename="x.xml"/>'), 2, "include", "filename", "included file 'x.xml' not found"),
    (doc('<path value="no/such/folder"/>'), 2, "path", "value", "folder 'no/such/folder' not found"),
    (doc('<shape type="cube">\n<path value="."/></shape>'), 3, "path", None, "only allowed directly inside <scene>"),
    (doc('<shape type="nurbs"/>'), 2, "shape", "type", "unsupported shape type 'nurbs'"),
    (doc('<shape type="cube">\n<bsdf type="hair"/>\n</shape>'), 3, "bsdf", "type", "hair BSDF is not implemented"),
    (doc('<shape type="cube">\n<bsdf type="measured_polarized"/>\n</shape>'), 3, "bsdf", "type", "refuse it too unless one 'wavelength'"),
    (doc('<shape type="cube"><bsdf type="pplastic">\n<float name="eta" value="1.5"/><float name="int_ior" value="1.5"/></bsdf></shape>'),
     3, "float", "eta", "either 'eta' or 'int_ior'/'ext_ior'"),
    (doc('<shape type="cube">\n<bsdf type="roughplastic"><texture type="checkerboard" name="alpha"/></bsdf></shape>'),
     3, "bsdf", None, "roughplastic's alpha must be a number"),
    (doc('<shape type="cube">\n<bsdf type="diffuse">\n<float name="foo" value="1"/></bsdf></shape>'), 4, "float", "foo", "unsupported parameter 'foo'"),
    (doc('<shape type="cube">\n<float name="radius" value="1"/></shape>'), 3, "float", "radius", "unsupported parameter"),
    (doc('<shape type="cube"><bsdf type="roughconductor">\n<float name="alpha" value="0.1" foo="2"/>'
         '<string name="distribution" value="ggx"/></bsdf></shape>'), 3, "float", "foo", "unsupported attribute 'foo'"),
    (doc('<shape type="cube"><bsdf type="roughconductor">\n<string name="distribution" value="phong"/></bsdf></shape>'),
     3, "string", "distribution", "phong"),
    (doc('<shape type="cube">\n<bsdf type="diffuse"><rgb name="reflectance" value="$albedo"/></bsdf></shape>'),
     3, "rgb", "value", "unknown parameter '$albedo'"),
    (doc('<shape type="cube">\n<ref id="nowhere"/></shape>'), 3, "ref", "id", "unknown id 'nowhere'"),
    (doc('<sensor type="perspective" id="cam"/>\n<shape type="cube">\n<ref id="cam"/></shape>'), 4, "ref", None, "unexpected"),
    (doc('<shape type="cube"><bsdf type="diffuse">\n<spectrum name="reflectance" value="400:0.1, 700"/></bsdf></shape>'),
     3, "spectrum", "value", "wavelength:value pairs"),
    (doc('<shape type="cube"><bsdf type="diffuse">\n<spectrum name="reflectance" value="700:0.1, 400:0.5"/></bsdf></shape>'),
     3, "spectrum", "value", "must increase"),
    (doc('<shape type="cube"><bsdf type="diffuse">\n<spectrum name="reflectance" filename="none.spd"/></bsdf></shape>'),
     3, "spectrum", "filename", "no such file"),
    (doc('<shape type="cube"><bsdf type="diffuse">\n<spectrum type="blackbody" name="reflectance">'
         '<float name="temperature" value="3000"/></spectrum></bsdf></shape>'), 3, "spectrum", "type", "emission spectrum"),
    (doc('<shape type="cube"><emitter type="area">\n<spectrum type="blackbody" name="radiance">'
         '<float name="temperature" value="-3"/></spectrum></emitter></shape>'), 3, "spectrum", None, "positive temperature"),
    (doc('<sensor type="perspective"><film type="hdrfilm">\n<rfilter type="lanczos"/></film></sensor>'), 3, "rfilter", "type", "lanczos"),
    (doc('<sensor type="perspective"><film type="hdrfilm"><rfilter type="tent">\n<float name="radius" value="0"/></rfilter></film></sensor>'),
     3, "float", "radius", "radius must be in (0, 64]"),
    (doc('<integrator type="stokes"><integrator type="path"/></integrator>'), 2, "integrator", "type", "RGB variants refuse it too"),
    (doc('<integrator type="moment"/>'), 2, "integrator", None, "exactly one nested integrator"),
    (doc('<sensor type="radiancemeter"/>'), 2, "sensor", "type", "radiancemeter"),
    (doc('<emitter type="directional">\n<vector name="direction" value="0, 0, 1"/><transform name="to_world"/></emitter>'),
     2, "emitter", "direction", "either 'direction' or 'to_world'"),
    (doc('<emitter type="directional">\n<texture type="bitmap" name="irradiance"><string name="filename" value="t.png"/></texture></emitter>'),
     3, "texture", "irradiance", "cannot be a texture"),
    (doc('<emitter type="spot">\n<texture type="checkerboard" name="texture"/></emitter>'), 3, "texture", "texture", "must be a bitmap"),
    (doc('<shape type="cube"><emitter type="area">\n<texture type="checkerboard" name="radiance"/></emitter></shape>'), 3, "texture", "radiance", "must be a bitmap"),
    (doc('<emitter type="projector"><float name="fov" value="30"/>\n<string name="focal_length" value="50mm"/></emitter>'),
     2, "emitter", "focal_length", "either 'fov' or 'focal_length'"),
    (doc('<emitter type="projector"><transform name="to_world">\n<scale value="2"/></transform></emitter>'), 2, "emitter", None, "rigid frame"),
    (doc('<emitter type="area"><rgb name="radiance" value="1"/></emitter>'), 2, "emitter", "type", "nested inside a <shape>"),
    (doc('<emitter type="constant"/>\n<emitter type="constant"/>'), 3, "emitter", None, "only one environment"),
    (doc('<sensor type="perspective"/>\n<sensor type="perspective"/>'), 3, "sensor", None, "only one sensor"),
    (doc('<shape type="cube"><bsdf type="roughconductor">\n<float name="alpha">0.1</float></bsdf></shape>'), 3, "float", None, "unexpected text"),
    (doc('<bsdf type="diffuse" id="a"/>\n<bsdf type="diffuse" id="a"/>'), 3, "bsdf", "id", "duplicate id"),
    (doc('<shape type="obj"/>'), 2, "shape", "filename", "missing required parameter 'filename'"),
    (doc('<shape type="obj">\n<string name="filename" value="missing.obj"/></shape>'), 2, "shape", None, "no such file"),
    (doc('<shape type="obj">\n<string name="filename" value="mesh.ply"/></shape>'), 3, "string", "filename", ".obj file"),
    (doc('<shape type="cube"><bsdf type="conductor">\n<texture type="bitmap" name="specular_reflectance">'
         '<string name="filename" value="t.png"/></texture></bsdf></shape>'), 3, "texture", "specular_reflectance", "textures are supported only"),
    (doc('<shape type="cube"><bsdf type="diffuse">\n<texture type="noise" name="reflectance"/></bsdf></shape>'),
     3, "texture", "type", "unsupported texture type 'noise'"),
    (doc('<shape type="cube"><bsdf type="diffuse"><texture type="checkerboard" name="reflectance">\n<texture type="bitmap" name="color0">'
         '<string name="filename" value="t.png"/></texture></texture></bsdf></shape>'), 3, "texture", "color0", "textures are supported only"),
    (doc('<shape type="cube"><bsdf type="diffuse">\n<float name="reflectance" value="abc"/></bsdf></shape>'), 3, "float", "value", "cannot parse"),
    (doc('<shape type="cube">\n<default name="x" value="1"/></shape>'), 3, "default", None, "only allowed directly inside"),
    (doc('<integrator type="path">\n<boolean name="hide_emitters" value="true"/></integrator>'), 3, "boolean", "hide_emitters", "not supported"),
    (doc('<shape type="cube"><bsdf type="roughconductor"><string name="distribution" value="ggx"/>\n'
         '<rgb name="alpha" value="0.1"/></bsdf></shape>'), 3, "rgb", "alpha", "must be given as <float>"),
    (doc('<shape type="cube">\n<bsdf type="conductor"><string name="material" value="Au"/><rgb name="eta" value="1"/></bsdf></shape>'),
     3, "bsdf", "material", "either 'material' or 'eta'"),
    (doc('<shape type="cube"><bsdf type="dielectric">\n<string name="int_ior" value="unobtainium"/></bsdf></shape>'),
     3, "string", "int_ior", "unknown named IOR"),
    (doc('<shape type="cube"><bsdf type="conductor">\n<string name="material" value="Xx"/></bsdf></shape>'),
     3, "string", "material", "conductor material"),
    (doc('<sensor type="perspective">\n<float name="fov" value="30"/><string name="focal_length" value="50mm"/></sensor>'),
     2, "sensor", "focal_length", "either 'fov' or 'focal_length'"),
    (doc('<sensor type="perspective">\n<string name="fov_axis" value="z"/><float name="fov" value="30"/></sensor>'),
     3, "string", "fov_axis", "fov_axis"),
    (doc('<shape type="cube"><transform name="to_world">\n<shear value="1"/></transform></shape>'), 3, "shear", None, "unsupported element"),
    (doc('<shape type="cube"><transform name="to_world">\n<rotate x="1"/></transform></shape>'), 3, "rotate", "angle", "angle"),
    (doc('<shape type="cube"><transform name="to_world">\n<matrix value="1 2 3"/></transform></shape>'), 3, "matrix", "value", "9 or 16"),
    (doc('<shape type="cube"><bsdf type="twosided">\n<bsdf type="dielectric"/></bsdf></shape>'), 2, "bsdf", None, "transmissive"),
    (doc('<shape type="cube">\n<emitter type="area"/></shape>'), 3, "emitter", "radiance", "missing required parameter 'radiance'"),
    (doc('<shape type="cube"><bsdf type="diffuse">\n<rgb value="1"/></bsdf></shape>'), 3, "rgb", "name", "missing attribute 'name'"),
    (doc('<shape type="cube"><bsdf type="diffuse">\n<rgb name="reflectance" value="1"/>\n<rgb name="reflectance" value="1"/></bsdf></shape>'),
     4, "rgb", "name", "given twice"),
    (doc('<sensor type="perspective"><sampler type="sobol"/></sensor>'), 2, "sampler", "type", "sobol"),
    (doc('<shape type="cube">\n<bsdf type="roughconductor"><string name="distribution" value="ggx"/>'
         '<float name="alpha" value="-0.1"/></bsdf></shape>'), 3, "bsdf", None, "alpha must be a finite positive"),
    (doc('<shape type="cube">\n<bsdf type="dielectric"><float name="int_ior" value="1"/><float name="ext_ior" value="1"/></bsdf></shape>'),
     3, "bsdf", None, "must differ"),
    (doc('<shape type="cube"><emitter type="area">\n<rgb name="radiance" value="-1"/></emitter></shape>'), 2, "shape", None, "non-negative"),
    (doc('<emitter type="spot">\n<float name="cutoff_angle" value="120"/></emitter>'), 2, "emitter", "cutoff_angle", "cutoff_angle <= 90"),
    (doc('<shape type="cylinder"><point name="p1" x="0" y="0" z="0"/></shape>'), 2, "shape", None, "p0 != p1"),
    (doc('<shape type="cylinder"><float name="radius" value="-1"/></shape>'), 2, "shape", None, "positive radius"),
    (doc('<emitter type="point">\n<point name="position" x="0" y="0" z="0"/><transform name="to_world"><translate x="1"/></transform></emitter>'),
     2, "emitter", "position", "either 'position' or 'to_world'"),
]


@pytest.mark.parametrize("text, line, element, attribute, message", ERRORS, ids=[f"case{i}" for i in range(len(ERRORS))])
def test_errors_name_element_attribute_and_line(text, line, element, attribute, message):
    with pytest.raises(SceneFileError) as info:
        load_mitsuba(text)
    err = info.value
    assert message in str(err)
    assert err.line == line and f":{line}:" in str(err)
    if element is not None:
        assert err.element is not None and err.element.startswith(element) and f"<{err.element}>" in str(err)
    if attribute is not None:
        assert err.attribute == attribute and attribute in str(err)


def test_missing_file_and_missing_image(tmp_path):
    with pytest.raises(SceneFileError, match="no such scene file"):
        load_mitsuba(tmp_path / "nope.xml")
    (tmp_path / "s.xml").write_text(doc('<shape type="cube"><bsdf type="diffuse">\n<texture type="bitmap" name="reflectance">'
                                        '<string name="filename" value="none.png"/></texture></bsdf></shape>'))
    with pytest.raises(SceneFileError, match=r"s\.xml:3: <texture type=\"bitmap\" name=\"reflectance\">.*none\.png"):
        load_mitsuba(tmp_path / "s.xml")


def test_spot_lights_point_along_local_z_with_mitsubas_cone_defaults():
    s = load_mitsuba(doc('<emitter type="spot"><transform name="to_world"><lookat origin="0, 2, 0" target="0, 0, 0" up="0, 0, 1"/></transform>'
                         '<rgb name="intensity" value="3"/></emitter>'
                         '<emitter type="spot"><float name="cutoff_angle" value="40"/><float name="beam_width" value="5"/></emitter>'))
    a, b = s.point_lights
    np.testing.assert_allclose(a.position, [0, 2, 0])
    np.testing.assert_allclose(a.direction, [0, -1, 0], atol=1e-12)
    assert a.cutoff_angle == 20.0 and a.beam_width == 15.0  # Mitsuba: cutoff 20°, beam ¾ of it
    np.testing.assert_allclose(b.direction, [0, 0, 1])
    assert (b.cutoff_angle, b.beam_width) == (40.0, 5.0)


def test_directional_projector_textured_spot_and_orthographic_sensor(tmp_path):
    from PIL import Image

    Image.fromarray(np.array([[[255, 0, 0], [0, 255, 0], [0, 0, 255]]] * 2, dtype=np.uint8)).save(tmp_path / "t.png")
    (tmp_path / "s.xml").write_text(doc(
        '<shape type="rectangle"/>\n'
        '<emitter type="directional"><vector name="direction" value="0, 0, -2"/><rgb name="irradiance" value="1 2 3"/></emitter>\n'
        '<emitter type="directional"><transform name="to_world"><lookat origin="0, 0, 0" target="1, 0, 0"/></transform></emitter>\n'
        '<emitter type="projector"><float name="fov" value="30"/><float name="scale" value="2"/>'
        '<transform name="to_world"><lookat origin="0, 0, 3" target="0, 0, 0" up="0, 1, 0"/></transform>'
        '<texture type="bitmap" name="irradiance"><string name="filename" value="t.png"/></texture></emitter>\n'
        '<emitter type="projector"/>\n'
        '<emitter type="spot"><texture type="bitmap" name="texture"><string name="filename" value="t.png"/></texture>'
        '<transform name="to_world"><lookat origin="0, 2, 0" target="0, 0, 0" up="0, 0, 1"/></transform></emitter>\n'
        '<sensor type="orthographic"><float name="near_clip" value="0.5"/>'
        '<transform name="to_world"><scale x="2" y="2"/><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform></sensor>\n'
        '<shape type="rectangle" id="glow"><emitter type="area"><texture type="bitmap" name="radiance">'
        '<string name="filename" value="t.png"/></texture></emitter></shape>'))
    s = load_mitsuba(tmp_path / "s.xml")
    d0, d1, p0, p1, spot = s.point_lights
    assert isinstance(d0, DirectionalLight) and isinstance(d1, DirectionalLight)
    np.testing.assert_allclose(d0.direction, [0, 0, -2])
    np.testing.assert_allclose(d0.irradiance, [1, 2, 3])
    np.testing.assert_allclose(d1.direction, [1, 0, 0], atol=1e-12)  # to_world's +z (Mitsuba's directional)
    np.testing.assert_allclose(d1.irradiance, [1, 1, 1])
    assert isinstance(p0, Projector) and (p0.fov, p0.fov_axis, p0.scale) == (30.0, "x", 2.0)
    assert np.asarray(p0.irradiance).shape == (2, 3, 3)
    np.testing.assert_allclose(np.asarray(p0.irradiance)[0, 0], [1, 0, 0])  # sRGB-decoded texels
    np.testing.assert_allclose(np.asarray(p0.to_world)[:3, 3], [0, 0, 3])
    # no fov: Mitsuba's 50 mm focal length along the diagonal; irradiance 1
    assert p1.fov_axis == "diagonal" and p1.fov == pytest.approx(46.7930, abs=1e-3)
    np.testing.assert_allclose(p1.irradiance, [1, 1, 1])
    assert np.asarray(spot.texture).shape == (2, 3, 3)
    np.testing.assert_allclose(np.asarray(spot.to_world)[:3, 2], [0, -1, 0], atol=1e-12)
    cam = s.camera
    assert cam.projection == "orthographic" and cam.near_clip == 0.5
    np.testing.assert_allclose(cam.to_world[:3, 0], [-2, 0, 0], atol=1e-12)  # the film scaled by 2
    glow = objects(s)["glow"]
    assert np.asarray(glow.emission).shape == (2, 3, 3) and glow.uvs is not None  # a radiance image, looked up at the uv
    s.build("cpu")


# ---- <path>, <include>, <default> and params across files ----------------------------------------------


def _write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


@pytest.fixture
def tree(tmp_path):
    """A scene in scenes/ that finds a mesh through <path> and includes a file that holds the default it uses."""
    root = tmp_path / "data"
    (root / "common" / "meshes").mkdir(parents=True)
    (root / "common" / "meshes" / "quad.ply").write_bytes((DATA / "quad.ply").read_bytes())
    _write(root / "scenes" / "include" / "parts.xml", '<scene version="3.0.0">\n'
           '    <path value="../../common"/>\n'
           '    <default name="spp" value="12"/>\n'
           '    <shape type="ply"><string name="filename" value="meshes/quad.ply"/><ref id="mat"/></shape>\n'
           '</scene>\n')
    _write(root / "scenes" / "include" / "bsdf.xml", '<bsdf version="3.0.0" type="diffuse" id="mat">\n'
           '    <rgb name="reflectance" value="$albedo"/>\n</bsdf>\n')
    main = _write(root / "scenes" / "main.xml", '<scene version="3.0.0">\n'
                  '    <path value="../common"/>\n'
                  '    <default name="albedo" value="0.25"/>\n'
                  '    <sensor type="perspective"><sampler type="independent">\n'
                  '        <integer name="sample_count" value="$spp"/></sampler></sensor>\n'
                  '    <include filename="include/bsdf.xml"/>\n'
                  '    <include filename="include/parts.xml"/>\n'
                  '</scene>\n')
    return main


def test_path_and_include_splice_files_in_document_order(tree):
    s = load_mitsuba(tree)
    assert s.defaults["spp"] == 12  # a default from an included file, after its use
    assert [type(m) for m in s.materials] == [Diffuse] and s.materials[0].reflectance == (0.25, 0.25, 0.25)
    assert s.triangle_count == len(shapes.load_mesh(DATA / "quad.ply").faces)  # found through the included file's <path>


def test_params_override_defaults_of_included_files(tree):
    s = load_mitsuba(tree, params={"spp": 3, "albedo": "0.5"})
    assert s.defaults["spp"] == 3 and s.materials[0].reflectance == (0.5, 0.5, 0.5)


def test_unknown_param_names_are_refused(tree):
    with pytest.raises(SceneFileError, match=r"unknown scene parameter\(s\) 'sp'.*its parameters: albedo, spp"):
        load_mitsuba(tree, params={"sp": 3})


def test_errors_in_included_files_name_that_file_and_line(tree):
    inc = tree.parent / "include" / "parts.xml"
    inc.write_text(inc.read_text().replace('<ref id="mat"/>', '<bsdf type="glossy"/>'))
    with pytest.raises(SceneFileError) as info:
        load_mitsuba(tree)
    assert info.value.path == str(inc) and info.value.line == 4 and f"{inc}:4:" in str(info.value)


def test_an_include_cycle_is_refused(tmp_path):
    f = _write(tmp_path / "a.xml", '<scene version="3.0.0">\n<include filename="a.xml"/>\n</scene>\n')
    with pytest.raises(SceneFileError, match="nested deeper"):
        load_mitsuba(f)


def test_a_referenced_top_level_sampler_and_film():
    s = load_mitsuba(doc('<sampler type="independent" id="smp"><integer name="sample_count" value="7"/></sampler>\n'
                         '<film type="hdrfilm" id="flm"><integer name="width" value="32"/></film>\n'
                         '<sensor type="perspective"><ref id="smp"/><ref id="flm"/></sensor>'))
    assert s.defaults["spp"] == 7 and s.film.width == 32


# ---- integrators read as what they estimate --------------------------------------------------------


@pytest.mark.parametrize("xml, max_depth, rr_depth", [
    ('<integrator type="moment"><integrator type="path"><integer name="max_depth" value="3"/></integrator></integrator>', 3, 5),
    ('<integrator type="aov"><string name="aovs" value="nn:sh_normal"/><integrator type="volpath" name="image">'
     '<integer name="rr_depth" value="2"/></integrator></integrator>', -1, 2),
    ('<integrator type="direct"><integer name="emitter_samples" value="0"/><integer name="bsdf_samples" value="4"/></integrator>', 2, 5),
    ('<integrator type="ptracer"><integer name="max_depth" value="7"/><integer name="samples_per_pass" value="9"/></integrator>', 7, 5),
])
def test_integrators_read_as_path_tracing_at_their_depth(xml, max_depth, rr_depth):
    s = load_mitsuba(doc(xml))
    assert (s.defaults["max_depth"], s.defaults["rr_depth"]) == (max_depth, rr_depth)


def test_other_unbiased_integrators_read_as_pt_with_a_notice():
    from grisx.errors import GrisxWarning

    with pytest.warns(GrisxWarning, match=r'<string>:2: <integrator type="bdpt"> read as path tracing \(pt\) at max_depth 6'):
        s = load_mitsuba(doc('<integrator type="bdpt"><integer name="max_depth" value="6"/>\n'
                             '<boolean name="light_image" value="true"/></integrator>'))
    assert s.defaults["max_depth"] == 6


def test_mitsuba_0x_files_srgb_colours_and_lookAt():
    from grisx.imageio import srgb_decode

    s = load_mitsuba('<scene version="0.5.0">\n<sensor type="perspective"><transform name="toWorld">\n'
                     '<lookAt origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform></sensor>\n'
                     '<shape type="sphere"><bsdf type="diffuse"><srgb name="diffuseReflectance" value="#336699"/></bsdf></shape>\n'
                     '<shape type="sphere"><bsdf type="diffuse"><srgb name="reflectance" value="0.5"/></bsdf></shape>\n</scene>')
    np.testing.assert_allclose(s.materials[0].reflectance, srgb_decode(np.array([0x33, 0x66, 0x99]) / 255.0))
    np.testing.assert_allclose(s.materials[1].reflectance, [float(srgb_decode(np.array(0.5)))] * 3)
    np.testing.assert_allclose(s.camera.to_world[:3, 3], [0, 0, 5])


def test_reconstruction_filters_without_a_film_hook_are_refused_with_the_reason():
    with pytest.raises(SceneFileError, match=r"<string>:3: <rfilter type=\"mitchell\"> unsupported rfilter type 'mitchell': "
                                             r"grisx films filter with box, gaussian or tent only \(a filter with negative lobes"):
        load_mitsuba(doc('<sensor type="perspective"><film type="hdrfilm">\n<rfilter type="mitchell"/></film></sensor>'))
