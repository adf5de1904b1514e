"""Mitsuba's ``linearcurve`` (grisx.scene.curves): the file format, Mitsuba's frame, the surface (a frustum
between each pair of control-point spheres, normals p − c), radii left alone by to_world, the loader."""

from __future__ import annotations

import numpy as np
import pytest

from grisx.errors import GrisxError, SceneFileError
from grisx.scene.curves import linear_curve_mesh, local_frame, read_curves
from grisx.scene.mitsuba import load_mitsuba


def test_curve_files_and_their_errors(tmp_path):
    path = tmp_path / "c.txt"
    path.write_text("0 0 0 0.1\n1 0 0 0.2\n\n\n  0 1 0 0.1\n0 2 0 0.1\n0 3 0 0.3\n")
    curves = read_curves(path)
    assert [c.shape for c in curves] == [(2, 4), (3, 4)]
    for text, message in (("0 0 0 0.1\n", "at least two control points"), ("0 0 0\n1 1 1\n", "expected 'x y z radius'"), ("\n\n", "no control points")):
        path.write_text(text)
        with pytest.raises(GrisxError, match=message):
            read_curves(path)


def test_local_frame_is_mitsubas():
    """u_rot: +z made orthogonal to d (+y where d = ±z); u_rad = u_rot × d."""
    rot, rad = local_frame(np.array([1.0, 0.0, 0.0]))
    np.testing.assert_allclose([rot, rad], [[0, 0, 1], [0, 1, 0]])
    rot, rad = local_frame(np.array([0.0, 0.0, -1.0]))
    np.testing.assert_allclose([rot, rad], [[0, 1, 0], [-1, 0, 0]])


def test_the_surface_is_the_spheres_envelope_with_mitsubas_normals_and_uv():
    curve = np.array([[0.0, 0.0, 0.0, 0.3], [2.0, 0.0, 0.0, 0.1], [2.0, 1.0, 0.5, 0.2]])
    to_world = np.diag([2.0, 1.0, 1.0, 1.0])  # stretches the positions, not the radii
    mesh = linear_curve_mesh([curve], to_world, around=32, rings=16)
    p = curve[:, :3] * [2, 1, 1]
    # every vertex lies on the sphere of its centre c(v) (v from its uv) and its normal is (p − c)/r there
    v = mesh.uvs[:, 1] * 2  # segment index + v_local
    seg = np.minimum(np.floor(v).astype(int), 1)
    t = v - seg
    c = p[seg] * (1 - t)[:, None] + p[seg + 1] * t[:, None]
    r = curve[seg, 3] * (1 - t) + curve[seg + 1, 3] * t
    np.testing.assert_allclose(np.linalg.norm(mesh.vertices - c, axis=1), r, atol=1e-12)
    np.testing.assert_allclose(mesh.normals, (mesh.vertices - c) / r[:, None], atol=1e-12)
    # u is the angle of the normal in the segment's local_frame, as linearcurve.cpp computes it (at a joint, v = 1
    # of the segment before it equals v = 0 of the one after: either frame; at a sphere's poles any u)
    ok = np.zeros(len(v), dtype=bool)
    for s_ in (seg, np.maximum(seg - 1, 0)):
        d = (p[s_ + 1] - p[s_]) / np.linalg.norm(p[s_ + 1] - p[s_], axis=1, keepdims=True)
        frames = [local_frame(x) for x in d]
        u = np.arctan2([n @ f[0] for n, f in zip(mesh.normals, frames)], [n @ f[1] for n, f in zip(mesh.normals, frames)]) / (2 * np.pi) % 1.0
        err = np.abs(u - mesh.uvs[:, 0])
        ok |= (np.minimum(err, 1 - err) < 1e-9) | (np.linalg.norm(np.cross(mesh.normals, d), axis=1) < 1e-9)
    assert np.all(ok)
    # faces turn outward
    ng = np.cross(mesh.vertices[mesh.faces[:, 1]] - mesh.vertices[mesh.faces[:, 0]], mesh.vertices[mesh.faces[:, 2]] - mesh.vertices[mesh.faces[:, 0]])
    ok = np.linalg.norm(ng, axis=1) > 1e-12
    assert np.all(np.einsum("ij,ij->i", ng, mesh.normals[mesh.faces].sum(axis=1))[ok] > 0)


def test_the_loader_reads_a_linearcurve_and_refuses_the_rest(tmp_path):
    path = tmp_path / "c.txt"
    path.write_text("0 0 0 0.1\n1 0 0 0.1\n")
    shape = f'<shape type="linearcurve"><string name="filename" value="{path}"/>{{}}</shape>'
    scaled = shape.format('<transform name="to_world"><scale value="3"/></transform>')
    scene = load_mitsuba(f'<scene version="3.0.0"><emitter type="constant"/>{scaled}</scene>')
    (o,) = scene.objects
    radial = np.linalg.norm(o.vertices[:, 1:], axis=1)
    assert radial.max() == pytest.approx(0.1)  # the tube keeps its radius under scale 3
    for extra, message in (('<boolean name="flip_normals" value="true"/>', "takes no flip_normals"),
                           ('<emitter type="area"><rgb name="radiance" value="1"/></emitter>', "cannot be an area emitter")):
        with pytest.raises(SceneFileError, match=message):
            load_mitsuba(f'<scene version="3.0.0"><emitter type="constant"/>{shape.format(extra)}</scene>')
    bspline = f'<shape type="bsplinecurve"><string name="filename" value="{path}"/></shape>'
    with pytest.raises(SceneFileError, match="a B-spline curve needs at least 4 control points"):
        load_mitsuba(f'<scene version="3.0.0"><emitter type="constant"/>{bspline}</scene>')


def test_bspline_tubes_are_mitsubas_circles_normal_to_the_curve():
    """Mitsuba 3.9.1's B-spline hits satisfy |p − c(v)| = r(v) and (p − c(v))·c'(v) = 0 at the v it reports
    (measured on 193 hits: residuals 1e-7 and 8e-7); its normal is (|c'|² − (p − c)·c'')(p − c) − r r' c'."""
    from grisx.scene.curves import _bspline, bspline_curve_mesh

    curve = np.array([[-1.0, 0.0, 0.0, 0.1], [-0.5, 0.4, 0.2, 0.2], [0.0, 0.0, -0.2, 0.08], [0.5, 0.5, 0.1, 0.15], [1.0, 0.1, 0.0, 0.1]])
    v = 0.3  # bsplinecurve.cpp's cubic_interpolation, written out
    b = np.array([-v**3 + 3 * v**2 - 3 * v + 1, 3 * v**3 - 6 * v**2 + 4, -3 * v**3 + 3 * v**2 + 3 * v + 1, v**3]) / 6
    db = np.array([-3 * v**2 + 6 * v - 3, 9 * v**2 - 12 * v, -9 * v**2 + 6 * v + 3, 3 * v**2]) / 6
    ddb = np.array([1 - v, 3 * v - 2, 1 - 3 * v, v])
    for order, w in enumerate((b, db, ddb)):
        np.testing.assert_allclose(_bspline(curve[:4], np.array([v]), order)[0], w @ curve[:4], atol=1e-12)
    mesh = bspline_curve_mesh([curve], around=16, steps=8)
    seg = np.minimum(np.floor(mesh.uvs[:, 1] * 2).astype(int), 1)
    t = mesh.uvs[:, 1] * 2 - seg
    c = np.array([_bspline(curve[s:s + 4, :3], np.array([x]))[0] for s, x in zip(seg, t)])
    r = np.array([_bspline(curve[s:s + 4, 3:], np.array([x]))[0, 0] for s, x in zip(seg, t)])
    dc = np.array([_bspline(curve[s:s + 4, :3], np.array([x]), 1)[0] for s, x in zip(seg, t)])
    np.testing.assert_allclose(np.linalg.norm(mesh.vertices - c, axis=1), r, atol=1e-12)
    np.testing.assert_allclose(np.einsum("ij,ij->i", mesh.vertices - c, dc), 0.0, atol=1e-12)
    assert np.all(np.einsum("ij,ij->i", mesh.normals, mesh.vertices - c) > 0)  # outward
    with pytest.raises(GrisxError, match="at least 4 control points"):
        bspline_curve_mesh(read_curves(_three_points(), min_points=4))


def _three_points():
    import tempfile
    from pathlib import Path

    path = Path(tempfile.mkdtemp()) / "three.txt"
    path.write_text("0 0 0 0.1\n1 0 0 0.1\n2 0 0 0.1\n")
    return path
