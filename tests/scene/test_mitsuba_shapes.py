"""Mitsuba's shape-level constructs (grisx.scene.mitsuba, grisx.scene.shapes): ``shapegroup`` + ``instance``
(flattened into world-space meshes), PLY mesh attributes read by ``mesh_attribute`` textures, and the shapes
grisx refuses (with the reason, in one line naming the element)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import warp as wp

from grisx.errors import SceneFileError
from grisx.scene import shapes
from grisx.scene.material import Diffuse, TextureRef
from grisx.scene.mitsuba import load_mitsuba
from grisx.scene.scene import Scene, SceneData, intersect, surface_material, surface_material_at
from grisx.scene.texture import MeshAttribute

CONFORMANCE = Path(__file__).resolve().parents[1] / "conformance" / "scenes"
BLOB = CONFORMANCE / "blob_nuv.obj"  # an obj with normals and uvs
ATTRIBUTES = CONFORMANCE / "attributes.ply"  # vertex_color (3), face_color_color (3), face_weight (1)


def doc(body: str) -> str:
    """A scene document whose ``body`` starts on line 2."""
    return '<scene version="3.0.0">\n' + body + "\n</scene>\n"


LIGHT = '<emitter type="constant"/>'

#: a group of three members, each with a to_world of its own: (xml of the member's shape, its transform ops)
MEMBERS = [
    (f'<shape type="obj"><string name="filename" value="{BLOB}"/>{{t}}<bsdf type="diffuse"><rgb name="reflectance" value="0.7, 0.5, 0.3"/></bsdf></shape>',
     '<scale value="0.3"/><rotate x="1" y="2" z="0.5" angle="33"/><translate y="0.4"/>'),
    ('<shape type="rectangle">{t}<bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.6, 0.3"/></bsdf></shape>',
     '<scale x="0.5" y="0.2"/><rotate x="1" angle="-40"/><translate z="0.3"/>'),
    ('<shape type="cube">{t}<boolean name="face_normals" value="true"/></shape>', '<scale value="0.1"/><translate x="0.5"/>'),
]
INSTANCES = [
    "",  # no to_world: the group where it was defined
    '<rotate y="1" angle="45"/><scale value="1.5"/><translate z="2"/>',
    '<rotate y="1" angle="-45"/><rotate x="1" angle="-25"/><scale value="1.5"/><translate x="-1" z="-2"/>',
]
MIRROR = '<scale x="-1"/><rotate y="1" angle="20"/><translate x="0.7"/>'


def _transform(ops: str) -> str:
    return f'<transform name="to_world">{ops}</transform>' if ops else ""


def _group() -> str:
    return '<shape type="shapegroup" id="group">' + "".join(m.format(t=_transform(ops)) for m, ops in MEMBERS) + "</shape>"


def _instances(transforms) -> str:
    return "".join(f'<shape type="instance"><ref id="group"/>{_transform(ops)}</shape>' for ops in transforms)


def _written_out(transforms) -> str:
    """The same shapes written out one by one: the member's transform ops, then the instance's (``to_world`` of
    the instance · ``to_world`` of the member, as ops compose in document order)."""
    return "".join(m.format(t=_transform(ops + inst)) for inst in transforms for m, ops in MEMBERS)


def _same_mesh(a, b, scene_a, scene_b) -> None:
    np.testing.assert_array_equal(a.faces, b.faces)
    np.testing.assert_allclose(a.vertices, b.vertices, rtol=0, atol=1e-12)
    for x, y in ((a.normals, b.normals), (a.uvs, b.uvs)):
        assert (x is None) == (y is None)
        if x is not None:
            np.testing.assert_allclose(x, y, rtol=0, atol=1e-12)
    assert scene_a.materials[a.material] == scene_b.materials[b.material]


# ---- shapegroup + instance ---------------------------------------------------------------------


def test_instances_are_their_group_written_out_with_the_composed_transform():
    instanced = load_mitsuba(doc(LIGHT + _group() + _instances(INSTANCES)))
    explicit = load_mitsuba(doc(LIGHT + _written_out(INSTANCES)))
    assert len(instanced.objects) == len(explicit.objects) == len(MEMBERS) * len(INSTANCES)
    for a, b in zip(instanced.objects, explicit.objects):
        _same_mesh(a, b, instanced, explicit)
    # the members' BSDFs are registered once, whatever the number of instances (Mitsuba shares them too)
    assert len({o.material for o in instanced.objects}) == len(MEMBERS)


def test_a_group_without_instances_adds_no_geometry_and_an_instance_may_come_first():
    scene = load_mitsuba(doc(LIGHT + _group() + '<shape type="rectangle"/>'))
    assert [o.name for o in scene.objects] == ["rectangle4"]
    first = load_mitsuba(doc(LIGHT + _instances(INSTANCES[1:2]) + _group()))
    explicit = load_mitsuba(doc(LIGHT + _written_out(INSTANCES[1:2])))
    for a, b in zip(first.objects, explicit.objects):
        _same_mesh(a, b, first, explicit)


def test_a_mirroring_instance_keeps_the_members_front_sides():
    """Mitsuba's ``instance.cpp`` maps a member's normals by M⁻ᵀ, so under a mirror (det M < 0) the front side
    stays where the normals point; flattened vertices would turn it by winding, so the winding is reversed
    (as for these members written out with the mirror: each has normals, whose side is the front)."""
    instanced = load_mitsuba(doc(LIGHT + _group() + _instances([MIRROR])))
    explicit = load_mitsuba(doc(LIGHT + _written_out([MIRROR])))
    plain = load_mitsuba(doc(LIGHT + _group() + _instances([""])))
    for a, b, c in zip(instanced.objects, explicit.objects, plain.objects):
        _same_mesh(a, b, instanced, explicit)
        np.testing.assert_array_equal(a.faces, c.faces[:, [0, 2, 1]])
    rect = instanced.objects[1]  # the member rectangle: its winding's normal agrees with its (mirrored) normals again
    ng = shapes.face_normals_of(rect.vertices, rect.faces)
    assert np.all(np.einsum("ij,ij->i", ng, rect.normals[rect.faces[:, 0]]) > 0)


ANALYTIC = [
    ('<shape type="sphere"><point name="center" value="0.2, 0.1, 0"/><float name="radius" value="0.3"/>{t}</shape>', ""),
    ('<shape type="cylinder">{t}</shape>', '<scale value="0.2"/><rotate x="1" angle="30"/>'),
    ('<shape type="disk">{t}</shape>', '<scale value="0.4"/><rotate y="1" angle="60"/><translate x="1"/>'),
]


@pytest.mark.parametrize("mirror", [False, True], ids=["plain", "mirrored"])
def test_instanced_spheres_disks_and_tubes_stay_analytic_with_mitsubas_orientation(mirror):
    """A member sphere, tube or disk is an analytic shape with ``to_world(instance) · to_world(member)``; under a
    mirroring instance it keeps the member's outward normal (Mitsuba maps it by M⁻ᵀ), where a sphere or tube
    written out with that mirror is inside out (``sphere.cpp``, ``cylinder.cpp``)."""
    inst = MIRROR if mirror else INSTANCES[1]
    group = '<shape type="shapegroup" id="group">' + "".join(m.format(t=_transform(ops)) for m, ops in ANALYTIC) + "</shape>"
    instanced = load_mitsuba(doc(LIGHT + group + _instances([inst])))
    explicit = load_mitsuba(doc(LIGHT + "".join(m.format(t=_transform(ops + inst)) for m, ops in ANALYTIC)))
    for a, b in zip(instanced.objects, explicit.objects):
        assert a.shape is not None and a.shape.kind == b.shape.kind
        np.testing.assert_allclose(a.shape.to_world, b.shape.to_world, rtol=0, atol=1e-12)
        assert a.shape.orientation == 1.0  # outward, as the member
    turned = [b.shape.orientation for b in explicit.objects]
    assert turned == ([-1.0, -1.0, 1.0] if mirror else [1.0, 1.0, 1.0])


@pytest.mark.parametrize(
    ("body", "line", "element", "message"),
    [
        ('<shape type="shapegroup" id="g">\n<shape type="rectangle"><emitter type="area"><rgb name="radiance" value="1"/></emitter></shape></shape>',
         3, 'shape type="rectangle"', "cannot emit"),
        ('<shape type="shapegroup" id="g">\n<shape type="shapegroup" id="h"><shape type="cube"/></shape></shape>',
         3, 'shape type="shapegroup" id="h"', "no nesting"),
        ('<shape type="shapegroup" id="g">\n<shape type="instance"><ref id="g"/></shape></shape>', 3, 'shape type="instance"', "no nesting"),
        ('<shape type="shapegroup" id="g"/>', 2, 'shape type="shapegroup" id="g"', "empty shapegroup"),
        ('<shape type="cube" id="c"/>\n<shape type="instance"/>', 3, 'shape type="instance"', "exactly one <ref> to a shapegroup"),
        ('<shape type="cube" id="c"/>\n<shape type="instance"><ref id="c"/></shape>', 3, 'ref id="c"', "takes a shapegroup, not a shape of type 'cube'"),
        ('<shape type="shapegroup" id="g">\n<shape type="hair"><string name="filename" value="curve.txt"/></shape></shape>',
         3, 'shape type="hair"', "unsupported shape type 'hair'"),
    ],
)
def test_shape_errors_name_the_element_and_line(body, line, element, message):
    with pytest.raises(SceneFileError) as info:
        load_mitsuba(doc(body + "\n" + LIGHT))
    err = info.value
    assert err.line == line and err.element == element, str(err)
    assert message in str(err) and "\n" not in str(err)


# ---- mirroring transforms ----------------------------------------------------------------------


@pytest.mark.parametrize("face_normals", [False, True], ids=["own-normals", "face-normals"])
def test_a_mirroring_to_world_keeps_a_meshs_front_where_its_normals_point(face_normals):
    """Mitsuba shades a mesh in the frame of its normals (mapped by M⁻ᵀ): under a mirror (det M < 0) the winding
    of the mapped vertices turns away from them, so grisx reverses it; a mesh without normals keeps its winding."""
    fn = '<boolean name="face_normals" value="true"/>' if face_normals else ""
    mirror, plain = '<scale x="-0.5" y="0.5" z="0.5"/>', '<scale x="0.5" y="0.5" z="0.5"/>'
    body = "".join(f'<shape type="obj"><string name="filename" value="{BLOB}"/>{fn}{_transform(t)}</shape>' for t in (plain, mirror))
    straight, mirrored = load_mitsuba(doc(LIGHT + body)).objects
    reversed_ = not face_normals
    np.testing.assert_array_equal(mirrored.faces, straight.faces[:, [0, 2, 1]] if reversed_ else straight.faces)
    if not face_normals:  # the winding's normals agree with the mapped vertex normals again
        ng = shapes.face_normals_of(mirrored.vertices, mirrored.faces)
        assert np.mean(np.einsum("ij,ij->i", ng, mirrored.normals[mirrored.faces].mean(axis=1)) > 0) > 0.99


# ---- mesh attributes ---------------------------------------------------------------------------

#: a PLY header's vertex properties and how Mitsuba 3.9.1's ``ply`` groups them (its ``mesh attributes`` listing
#: for a file with exactly these properties): colours by name, {prefix}_{x,y,z | r,g,b | 0,1,2 | 1,2,3} groups of
#: 1 or 3 fields, an r,g,b group named {prefix}_color; no postfix, 2 fields or a bad first postfix: ignored
VERTEX_PROPS = ["x", "y", "z", "nx", "ny", "nz", "u", "v", "red", "green", "blue", "alpha", "temp_0", "n_x", "n_y", "n_z",
                "q_r", "q_g", "q_b", "bad", "two_x", "two_y", "w_1", "w_2", "w_3", "k_y"]
FACE_PROPS = ["vertex_indices", "f_0", "f_1", "f_2", "g_x", "h_r"]
MITSUBA_GROUPS = {"vertex_color": 4, "vertex_n": 3, "vertex_w": 3, "vertex_q_color": 3, "vertex_temp": 1,
                  "face_f": 3, "face_g": 1, "face_h_color": 1}


def test_ply_attribute_grouping_is_mitsubas():
    groups = shapes.ply_attributes("vertex_", VERTEX_PROPS, {"x", "y", "z", "nx", "ny", "nz", "u", "v"})
    groups += shapes.ply_attributes("face_", FACE_PROPS, {"vertex_indices"})
    assert {name: len(fields) for name, fields in groups} == MITSUBA_GROUPS
    assert dict(groups)["vertex_color"] == ["red", "green", "blue", "alpha"]
    assert dict(groups)["vertex_w"] == ["w_1", "w_2", "w_3"]


def _write_ply(path: Path, binary: bool) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    rng = np.random.default_rng(5)
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=np.float32)
    f = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int32)
    vcol = rng.uniform(0, 1, (4, 3)).astype(np.float32)
    fval = rng.uniform(0, 1, (2, 1)).astype(np.float32)
    header = ["ply", f"format {'binary_little_endian' if binary else 'ascii'} 1.0", "element vertex 4",
              *(f"property float {p}" for p in ("x", "y", "z", "r", "g", "b")), "element face 2",
              "property list uchar int vertex_indices", "property float value_0", "end_header"]
    if binary:
        body = b"".join(np.concatenate([v[k], vcol[k]]).astype("<f4").tobytes() for k in range(4))
        body += b"".join(np.uint8(3).tobytes() + f[k].astype("<i4").tobytes() + fval[k].astype("<f4").tobytes() for k in range(2))
        path.write_bytes(("\n".join(header) + "\n").encode() + body)
    else:
        rows = [" ".join(f"{x:.9g}" for x in np.concatenate([v[k], vcol[k]])) for k in range(4)]
        rows += [f"3 {' '.join(map(str, f[k]))} {fval[k, 0]:.9g}" for k in range(2)]
        path.write_text("\n".join(header + rows) + "\n")
    return v, f, {"vertex_color": vcol.astype(np.float64), "face_value": fval.astype(np.float64)}


@pytest.mark.parametrize("binary", [False, True], ids=["ascii", "binary"])
def test_ply_files_bring_their_attributes(tmp_path, binary):
    v, f, attrs = _write_ply(tmp_path / "a.ply", binary)
    mesh = shapes.load_mesh(tmp_path / "a.ply", flip_normals=True)  # attributes survive flipping and smooth normals
    np.testing.assert_allclose(mesh.vertices, v)
    assert set(mesh.attributes) == set(attrs)
    for name, values in attrs.items():
        np.testing.assert_allclose(mesh.attributes[name], values, rtol=1e-6)


def test_ply_uvs_are_read_under_mitsubas_names_only(tmp_path):
    """u, v, else texture_u, texture_v, else s, t (ply.cpp); Mitsuba 3.9.1 reads texture_s, texture_t as no uvs."""
    def ply(names: str) -> Path:
        path = tmp_path / f"{names.replace(' ', '_')}.ply"
        header = ["ply", "format ascii 1.0", "element vertex 3", *(f"property float {p}" for p in ["x", "y", "z", *names.split()]),
                  "element face 1", "property list uchar int vertex_indices", "end_header"]
        cols = len(names.split())
        rows = [" ".join(["0 0 0", *(f"0.{k}{c}" for c in range(cols))]) for k in range(1, 4)]
        rows = [r.replace("0 0 0", p, 1) for r, p in zip(rows, ("0 0 0", "1 0 0", "0 1 0"))]
        path.write_text("\n".join(header + rows + ["3 0 1 2"]) + "\n")
        return path

    assert shapes.load_ply(ply("texture_s texture_t")).uvs is None
    np.testing.assert_allclose(shapes.load_ply(ply("s t texture_u texture_v")).uvs[:, 0], [0.12, 0.22, 0.32])
    np.testing.assert_allclose(shapes.load_ply(ply("s t")).uvs[:, 1], [0.11, 0.21, 0.31])


def _attribute_doc(name: str, filename: Path = ATTRIBUTES, extra: str = "", bsdf: str = "diffuse", param: str = "reflectance") -> str:
    return doc(f'{LIGHT}<shape type="ply"><string name="filename" value="{filename}"/><bsdf type="{bsdf}">\n'
               f'<texture type="mesh_attribute" name="{param}"><string name="name" value="{name}"/>{extra}</texture></bsdf></shape>')


def test_mesh_attribute_textures_load_with_their_mesh():
    scene = load_mitsuba(_attribute_doc("face_weight", extra='<float name="scale" value="0.5"/>'))
    assert scene.textures == [MeshAttribute("face_weight", 0.5)]
    (o,) = scene.objects
    assert scene.materials[o.material] == Diffuse(reflectance=TextureRef(0))
    assert set(o.attributes) == {"vertex_color", "face_color_color", "face_weight"}
    assert o.attributes["face_weight"].shape == (len(o.faces), 1)


@pytest.mark.parametrize(
    ("xml", "line", "element", "message"),
    [
        (_attribute_doc("color"), 3, 'string name="name"', "must start with 'vertex_' or 'face_'"),
        (_attribute_doc("vertex_weight"), 2, 'shape type="ply"', "reads mesh attribute 'vertex_weight', which it does not have "
                                                                 "(its attributes: face_color_color, face_weight, vertex_color)"),
        (doc(f'{LIGHT}<shape type="obj"><string name="filename" value="{BLOB}"/><bsdf type="diffuse">\n<texture type="mesh_attribute" '
             f'name="reflectance"><string name="name" value="vertex_color"/></texture></bsdf></shape>'),
         2, 'shape type="obj"', "which it does not have (its attributes: none)"),
        (doc(f'{LIGHT}<shape type="sphere"><bsdf type="diffuse">\n<texture type="mesh_attribute" name="reflectance"><string name="name" '
             f'value="face_weight"/></texture></bsdf></shape>'), 2, 'shape type="sphere"', "shape 'sphere1': its material reads mesh attribute"),
        (_attribute_doc("vertex_color", bsdf="plastic", param="diffuse_reflectance"), 3, 'texture type="mesh_attribute" name="diffuse_reflectance"',
         "needs its texture's mean"),
    ],
)
def test_mesh_attribute_errors(xml, line, element, message):
    with pytest.raises(SceneFileError) as info:
        load_mitsuba(xml)
    err = info.value
    assert err.line == line and err.element == element, str(err)
    assert message in str(err)


def test_a_four_channel_attribute_is_refused_where_a_texture_reads_it(tmp_path):
    ply = tmp_path / "rgba.ply"
    header = ["ply", "format ascii 1.0", "element vertex 3", *(f"property float {p}" for p in "xyzrgba"),
              "element face 1", "property list uchar int vertex_indices", "end_header"]
    ply.write_text("\n".join(header + ["0 0 0 1 0 0 1", "1 0 0 0 1 0 1", "0 1 0 0 0 1 1", "3 0 1 2"]) + "\n")
    with pytest.raises(SceneFileError, match="attribute 'vertex_color' has 4 channels; a mesh_attribute texture reads 1"):
        load_mitsuba(_attribute_doc("vertex_color", filename=ply))


# ---- attribute textures at surface points, against Mitsuba's interpolate_attribute ----------------


@wp.kernel
def _materials_at_hits(scene: SceneData, o: wp.array(dtype=wp.vec3), d: wp.array(dtype=wp.vec3), p: wp.array(dtype=wp.vec3),
                       tri: wp.array(dtype=wp.int32), at_hit: wp.array(dtype=wp.vec3), at_point: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    si = intersect(scene, o[i], d[i], 1.0e30)
    tri[i] = -1
    if si.valid != 0:
        p[i] = si.p
        tri[i] = si.tri
        at_hit[i] = surface_material(scene, si).reflectance
        at_point[i] = surface_material_at(scene, si.material, si.uv, si.tri, si.p, si.ns, si.ng).reflectance


@pytest.mark.parametrize("name", ["vertex_color", "face_color_color", "face_weight"])
def test_attribute_textures_are_mitsubas_barycentric_blend_or_face_value(name):
    """At random hits on the PLY: ``vertex_*`` = Σ bₖ a[iₖ] with the barycentrics of the hit point, ``face_*`` = the
    hit face's value (1 channel: grey) times ``scale``, both at the hit (``surface_material``) and recomputed from
    a stored point (``surface_material_at``, what the reuse renderers call for their path vertices)."""
    mesh = shapes.load_mesh(ATTRIBUTES)
    scene = Scene("attributes")
    tid = scene.add_texture(MeshAttribute(name, scale=0.75))
    scene.add_mesh(mesh.vertices, mesh.faces, material=scene.add_material(Diffuse(reflectance=TextureRef(tid))),
                   attributes=mesh.attributes, normals=mesh.normals)
    scene.add_point_light((0, 0, 3), 1.0)
    built = scene.build("cpu")
    rng = np.random.default_rng(1)
    n = 256
    origins = np.column_stack([rng.uniform(-0.95, 0.95, (n, 2)), np.full(n, 2.0)])
    dirs = np.tile([0.0, 0.0, -1.0], (n, 1))
    out = {k: wp.zeros(n, dtype=wp.vec3) for k in ("p", "at_hit", "at_point")}
    tri = wp.zeros(n, dtype=wp.int32)
    wp.launch(_materials_at_hits, dim=n, inputs=[built.data, wp.array(origins, dtype=wp.vec3), wp.array(dirs, dtype=wp.vec3)],
              outputs=[out["p"], tri, out["at_hit"], out["at_point"]])
    tri = tri.numpy()
    assert np.all(tri >= 0)
    p = out["p"].numpy().astype(np.float64)
    values = mesh.attributes[name]
    if name.startswith("face_"):
        expected = np.broadcast_to(values[tri], (n, 3)) * 0.75
    else:  # the hit point's barycentrics on its triangle (least squares on the two edges), Mitsuba's blend
        corners = mesh.vertices[mesh.faces[tri]]
        e = np.stack([corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]], axis=2)
        b12 = np.stack([np.linalg.lstsq(e[k], p[k] - corners[k, 0], rcond=None)[0] for k in range(n)])
        b = np.column_stack([1 - b12.sum(axis=1), b12])
        assert np.all(b > -1e-4)
        expected = np.einsum("nk,nkc->nc", b, values[mesh.faces[tri]]) * 0.75
    np.testing.assert_allclose(out["at_hit"].numpy(), expected, rtol=0, atol=2e-5)
    np.testing.assert_allclose(out["at_point"].numpy(), expected, rtol=0, atol=2e-5)
