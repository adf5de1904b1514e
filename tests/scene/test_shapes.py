"""Shape tessellation and mesh loading against Mitsuba 3's definitions (grisx.scene.shapes)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from grisx.errors import GrisxError, InvalidParameterError
from grisx.scene import shapes

DATA = Path(__file__).parent / "data"


def unit_face_normals(m: shapes.MeshData) -> np.ndarray:
    fn = shapes.face_normals_of(m.vertices, m.faces)
    return fn / np.linalg.norm(fn, axis=1, keepdims=True)


def assert_winding_matches_normals(m: shapes.MeshData) -> None:
    """Every corner's vertex normal lies on the front side (winding) of its triangle."""
    fn = unit_face_normals(m)
    for k in range(3):
        assert np.all(np.einsum("ij,ij->i", fn, m.normals[m.faces[:, k]]) > 0)


# ---- exact values -----------------------------------------------------------------


def test_rectangle_is_mitsubas():
    m = shapes.rectangle()
    assert m.vertices.shape == (4, 3) and m.faces.shape == (2, 3)
    assert np.all(m.vertices[:, 2] == 0)
    assert np.array_equal(np.abs(m.vertices[:, :2]), np.ones((4, 2)))  # corners of [-1, 1]²
    assert shapes.mesh_area(m.vertices, m.faces) == pytest.approx(4.0)
    np.testing.assert_allclose(unit_face_normals(m), [[0, 0, 1]] * 2)
    np.testing.assert_allclose(m.normals, [[0, 0, 1]] * 4)
    # rectangle.cpp: uv = (x·½ + ½, y·½ + ½)
    np.testing.assert_allclose(m.uvs, 0.5 * m.vertices[:, :2] + 0.5)


def test_cube_is_mitsubas():
    m = shapes.cube()
    assert m.vertices.shape == (24, 3) and m.faces.shape == (12, 3)
    assert np.all(np.abs(m.vertices) == 1)
    assert shapes.mesh_area(m.vertices, m.faces) == pytest.approx(24.0)
    fn = unit_face_normals(m)
    centroids = m.vertices[m.faces].mean(axis=1)
    # outward: each face normal is the axis its triangle sits on, pointing away from the centre
    np.testing.assert_allclose(fn, np.round(centroids), atol=0)  # centroids are (±1, ±⅓, ±⅓)-like: rounding gives the axis
    for face in range(6):  # 4 vertices per face share the face's normal and the face's plane
        n = m.normals[4 * face : 4 * face + 4]
        assert np.all(n == n[0])
        assert np.all(m.vertices[4 * face : 4 * face + 4] @ n[0] == 1)
    assert sorted(map(tuple, m.normals[::4].astype(int))) == sorted(
        [(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)]
    )
    assert_winding_matches_normals(m)
    assert set(map(tuple, m.uvs)) == {(0, 0), (0, 1), (1, 0), (1, 1)}  # every face maps onto [0, 1]²


def test_disk_is_mitsubas():
    m = shapes.disk(segments=64)
    assert np.all(m.vertices[:, 2] == 0)
    r = np.linalg.norm(m.vertices[:, :2], axis=1)
    assert np.all((np.abs(r) < 1e-12) | (np.abs(r - 1) < 1e-12))
    np.testing.assert_allclose(unit_face_normals(m), np.tile([0, 0, 1], (64, 1)), atol=1e-12)
    # inscribed 64-gon: area = ½·N·sin(2π/N)
    assert shapes.mesh_area(m.vertices, m.faces) == pytest.approx(0.5 * 64 * math.sin(2 * math.pi / 64), rel=1e-12)
    # disk.cpp: uv = (r, φ/2π)
    np.testing.assert_allclose(m.uvs[:, 0], r, atol=1e-12)
    rim = r > 0.5
    phi = np.mod(np.arctan2(m.vertices[rim, 1], m.vertices[rim, 0]), 2 * math.pi)
    v = m.uvs[rim, 1]
    np.testing.assert_allclose(np.where(v > 1 - 1e-9, 0.0, v), phi / (2 * math.pi), atol=1e-12)


def test_sphere_geometry_normals_and_uvs():
    m = shapes.sphere(segments=32, rings=16)
    np.testing.assert_allclose(np.linalg.norm(m.vertices, axis=1), 1.0, atol=1e-12)  # inscribed
    np.testing.assert_allclose(m.normals, m.vertices, atol=1e-12)  # smooth, outward, exact
    fn = unit_face_normals(m)
    centroids = m.vertices[m.faces].mean(axis=1)
    assert np.all(np.einsum("ij,ij->i", fn, centroids) > 0)  # winding faces outward
    assert_winding_matches_normals(m)
    # sphere.cpp: uv = (φ/2π, θ/π), θ = acos z, φ = atan2(y, x) in [0, 2π)
    theta = np.arccos(np.clip(m.vertices[:, 2], -1, 1))
    np.testing.assert_allclose(m.uvs[:, 1], theta / math.pi, atol=1e-12)
    off_pole = np.abs(m.vertices[:, 2]) < 1 - 1e-9
    phi = np.mod(np.arctan2(m.vertices[off_pole, 1], m.vertices[off_pole, 0]), 2 * math.pi)
    u = m.uvs[off_pole, 0]
    np.testing.assert_allclose(np.where(u > 1 - 1e-9, 0.0, u), np.where(phi > 2 * math.pi - 1e-9, 0.0, phi) / (2 * math.pi), atol=1e-12)


def test_cylinder_geometry_normals_and_uvs():
    m = shapes.cylinder(segments=32)
    np.testing.assert_allclose(np.linalg.norm(m.vertices[:, :2], axis=1), 1.0, atol=1e-12)  # inscribed
    assert set(np.unique(m.vertices[:, 2])) == {0.0, 1.0}  # open: no caps
    np.testing.assert_allclose(m.normals, m.vertices * [1, 1, 0], atol=1e-12)  # radial, outward
    fn = unit_face_normals(m)
    centroids = m.vertices[m.faces].mean(axis=1) * [1, 1, 0]
    assert np.all(np.einsum("ij,ij->i", fn, centroids) > 0)  # winding faces outward
    assert_winding_matches_normals(m)
    # cylinder.cpp: uv = (φ/2π, z), φ = atan2(y, x) in [0, 2π)
    np.testing.assert_allclose(m.uvs[:, 1], m.vertices[:, 2])
    phi = np.mod(np.arctan2(m.vertices[:, 1], m.vertices[:, 0]), 2 * math.pi)
    u = m.uvs[:, 0]
    np.testing.assert_allclose(np.where(u > 1 - 1e-9, 0.0, u), np.where(phi > 2 * math.pi - 1e-9, 0.0, phi) / (2 * math.pi), atol=1e-12)
    # inscribed 32-gon prism: area = N·sin(π/N)·2·1
    assert shapes.mesh_area(m.vertices, m.faces) == pytest.approx(32 * 2 * math.sin(math.pi / 32), rel=1e-12)


def test_sphere_center_radius():
    m = shapes.sphere(center=(1.0, -2.0, 0.5), radius=3.0, segments=16, rings=8)
    np.testing.assert_allclose(np.linalg.norm(m.vertices - [1.0, -2.0, 0.5], axis=1), 3.0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(m.normals, axis=1), 1.0)


@pytest.mark.parametrize("make", [shapes.rectangle, shapes.cube, shapes.disk, lambda **kw: shapes.sphere(segments=16, rings=8, **kw),
                                  lambda **kw: shapes.cylinder(segments=16, **kw)])
def test_flip_normals_turns_inside_out(make):
    a, b = make(), make(flip_normals=True)
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.uvs, b.uvs)
    np.testing.assert_allclose(b.normals, -a.normals)
    np.testing.assert_allclose(unit_face_normals(b), -unit_face_normals(a))
    assert_winding_matches_normals(b)


# ---- properties -----------------------------------------------------------------------


def test_sphere_area_converges_to_4_pi_r2():
    errors = []
    for n in (16, 32, 64, 128):
        m = shapes.sphere(radius=2.0, segments=n, rings=n // 2)
        errors.append(4 * math.pi * 4.0 - shapes.mesh_area(m.vertices, m.faces))
    assert all(e > 0 for e in errors)  # inscribed: always a little smaller
    for coarse, fine in zip(errors, errors[1:]):
        assert fine / coarse == pytest.approx(0.25, abs=0.03)  # O(1/N²)
    # relative error below π²/N² (the chords of the φ and θ steps, 2π/N each, lose O((2π/N)²))
    assert errors[-1] / (16 * math.pi) < math.pi**2 / 128**2


def test_default_sphere_silhouette_is_sub_pixel_at_1080p():
    m = shapes.sphere()
    # every point of the mesh lies between the unit sphere and the sphere of radius min_f |n̂_f·p_f|
    # (the closest face plane), so the silhouette is off by at most r·(1 − that) pixels for a sphere
    # of projected radius r; r = 540 px fills a 1080-pixel-high frame
    fn = unit_face_normals(m)
    deviation = 1 - np.abs(np.einsum("ij,ij->i", fn, m.vertices[m.faces[:, 0]])).min()
    assert 540 * deviation < 0.1


def test_vertex_normals_angle_weighted():
    # a vertex shared by one face in the xy plane (corner angle 90°) and one in the xz plane (45°)
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0], [1, 0, 1]], dtype=float)
    f = np.array([[0, 1, 2], [0, 4, 3]])
    n = shapes.vertex_normals(v, f)
    # face 0: normal +z, corner angle π/2 at vertex 0; face 1: normal (p4 − p0) × (p3 − p0), angle π/4
    n1 = np.cross(v[4] - v[0], v[3] - v[0])
    n1 /= np.linalg.norm(n1)
    expected = (math.pi / 2) * np.array([0, 0, 1.0]) + (math.pi / 4) * n1
    np.testing.assert_allclose(n[0], expected / np.linalg.norm(expected), atol=1e-12)


# ---- files --------------------------------------------------------------------------------


def test_obj_keeps_uv_seams_and_flips_v():
    m = shapes.load_mesh(DATA / "seam.obj")
    # 6 positions, but the shared edge carries two different uvs: Mitsuba's v/vt keys give 8 vertices
    assert m.vertices.shape == (8, 3) and m.faces.shape == (4, 3)
    assert shapes.mesh_area(m.vertices, m.faces) == pytest.approx(2.0)
    # positions at x = 1 appear twice, each with its own uv; v is flipped (v ← 1 − v) as Mitsuba's obj
    at_seam = np.where(m.vertices[:, 0] == 1)[0]
    assert len(at_seam) == 4
    uv_at_seam = {tuple(m.uvs[i]) for i in at_seam}
    assert uv_at_seam == {(1.0, 1.0), (1.0, 0.0), (0.0, 0.75), (0.0, 0.25)}
    # no normals in the file: Mitsuba's smooth normals, here all +z
    np.testing.assert_allclose(m.normals, np.tile([0, 0, 1.0], (8, 1)))
    np.testing.assert_allclose(unit_face_normals(m), np.tile([0, 0, 1.0], (4, 1)))


def test_obj_flip_tex_coords_off_and_face_normals():
    m = shapes.load_mesh(DATA / "seam.obj", flip_tex_coords=False, face_normals=True)
    assert m.normals is None
    assert (0.0, 0.0) in {tuple(uv) for uv in m.uvs[m.vertices[:, 0] == 0]}


def test_an_obj_read_again_is_the_file_as_it_is_now_and_each_reader_owns_its_copy(tmp_path):
    # load_obj keeps the meshes it read (a scene names one file many times): by content's stamp, never stale
    path = tmp_path / "tri.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    first = shapes.load_obj(path)
    first.vertices[:] = 7.0  # a caller editing its mesh edits its own copy
    np.testing.assert_array_equal(shapes.load_obj(path).vertices, [[0, 0, 0], [1, 0, 0], [0, 1, 0]])
    path.write_text("v 0 0 0\nv 2 0 0\nv 0 2 0\nv 2 2 0\nf 1 2 3\nf 2 4 3\n")  # rewritten: read again
    assert shapes.load_obj(path).faces.shape == (2, 3)


def test_obj_file_normals_and_negative_indices():
    m = shapes.load_mesh(DATA / "normals.obj")
    assert m.uvs is None
    np.testing.assert_allclose(m.vertices[:3], [[0, 0, 0], [1, 0, 0], [0, 1, 0]])
    np.testing.assert_allclose(m.normals[:3], [[0, 0, 1], [0, 0, 1], [0, 0.6, 0.8]])
    # vertex 1 reused with another normal: a new vertex (6 in all)
    assert len(m.vertices) == 6
    np.testing.assert_allclose(m.normals[3], [0, 0.6, 0.8])


def test_ply_keeps_vertices_normals_uvs():
    m = shapes.load_mesh(DATA / "quad.ply")
    np.testing.assert_allclose(m.vertices, [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1]])
    np.testing.assert_allclose(m.normals[4], [0, 0, -1])
    np.testing.assert_allclose(m.uvs, [[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0.5]])  # PLY uvs: not flipped by default
    np.testing.assert_allclose(shapes.load_mesh(DATA / "quad.ply", flip_tex_coords=True).uvs[:, 1], 1 - m.uvs[:, 1])
    assert m.faces.shape == (3, 3)  # the quad is fan-triangulated
    assert shapes.mesh_area(m.vertices, m.faces) == pytest.approx(1.0 + shapes.mesh_area(m.vertices, m.faces[[0]]))
    # winding of the quad's triangles is the file's (+z)
    quad_tris = [i for i, f in enumerate(m.faces) if 4 not in f]
    np.testing.assert_allclose(unit_face_normals(m)[quad_tris], [[0, 0, 1]] * 2)


def test_binary_ply_roundtrip(tmp_path):
    trimesh = pytest.importorskip("trimesh")
    src = shapes.sphere(segments=8, rings=4)
    tm = trimesh.Trimesh(src.vertices, src.faces, process=False)
    path = tmp_path / "s.ply"
    tm.export(path, encoding="binary")
    m = shapes.load_mesh(path)
    np.testing.assert_allclose(m.vertices, src.vertices, atol=1e-6)
    assert m.uvs is None
    assert shapes.mesh_area(m.vertices, m.faces) == pytest.approx(shapes.mesh_area(src.vertices, src.faces), rel=1e-6)


@pytest.mark.parametrize("binary", [False, True])
def test_ply_with_uvs_keeps_unused_vertices(tmp_path, binary):
    """trimesh drops vertices no face uses when a PLY has uvs; Mitsuba keeps them, and so must the face indices."""
    import struct

    verts = [(9, 9, 9, 0.9, 0.9), (0, 0, 0, 0, 0), (1, 0, 0, 1, 0), (7, 7, 7, 0.7, 0.7), (0, 1, 0, 0, 1)]  # 0 and 3 unused
    head = ["ply", f"format {'binary_little_endian' if binary else 'ascii'} 1.0", "element vertex 5",
            *[f"property float {c}" for c in "xyzuv"], "element face 1", "property list uchar int vertex_indices", "end_header"]
    path = tmp_path / "unused.ply"
    with open(path, "wb") as f:
        f.write(("\n".join(head) + "\n").encode())
        if binary:
            f.write(b"".join(struct.pack("<5f", *v) for v in verts) + struct.pack("<B3i", 3, 1, 2, 4))
        else:
            f.write(("\n".join(" ".join(map(str, v)) for v in verts) + "\n3 1 2 4\n").encode())
    m = shapes.load_mesh(path)
    np.testing.assert_allclose(m.vertices[m.faces[0]], [[0, 0, 0], [1, 0, 0], [0, 1, 0]])
    np.testing.assert_allclose(m.uvs[m.faces[0]], [[0, 0], [1, 0], [0, 1]])


@pytest.mark.parametrize(
    "text, message",
    [
        ("v 0 0 0\nv 1 0 0\nf 1 2 3\n", "out of range"),
        ("v 0 0\n", "could not parse"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", "at least 3"),
        ("v 0 0 0\n", "no faces"),
    ],
)
def test_bad_obj_files(tmp_path, text, message):
    p = tmp_path / "bad.obj"
    p.write_text(text)
    with pytest.raises(GrisxError, match=message):
        shapes.load_mesh(p)


def test_bad_mesh_arguments(tmp_path):
    with pytest.raises(GrisxError, match="no such file"):
        shapes.load_mesh(tmp_path / "missing.obj")
    (tmp_path / "x.stl").write_text("solid")
    with pytest.raises(GrisxError, match="unknown mesh format"):
        shapes.load_mesh(tmp_path / "x.stl")
    with pytest.raises(InvalidParameterError):
        shapes.sphere(segments=2)
    with pytest.raises(InvalidParameterError):
        shapes.sphere(radius=-1.0)
