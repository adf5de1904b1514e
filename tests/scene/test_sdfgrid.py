"""Mitsuba's ``sdfgrid`` (grisx.scene.sdfgrid): its trilinear surface and normals against Mitsuba 3.9.1's
intersections, the tessellation's distance to that surface, the loader, and the refusals."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from grisx.errors import GrisxError, SceneFileError
from grisx.scene import shapes
from grisx.scene.mitsuba import load_mitsuba
from grisx.scene.sdfgrid import SdfGrid, read_vol, sdfgrid_mesh

TORUS = Path(__file__).resolve().parents[1] / "conformance" / "scenes" / "torus.vol"  # a 24^3 torus SDF

#: hit points of rays on torus.vol (identity to_world) and the shading normals there, as Mitsuba 3.9.1
#: (llvm_ad_rgb: ``scene.ray_intersect``; si.p, si.sh_frame.n with normals="smooth" and "analytic")
MITSUBA_HITS = np.array([[0.280593, 0.61838, 0.489526], [0.38382, 0.612027, 0.329869], [0.692427, 0.621471, 0.617289],
                         [0.621164, 0.622416, 0.306836], [0.259415, 0.627681, 0.445614]])
MITSUBA_SMOOTH = np.array([[0.386996, 0.92192, 0.017274], [0.269953, 0.872554, 0.407155], [-0.280251, 0.944486, -0.171481],
                           [-0.166133, 0.951249, 0.259856], [0.160322, 0.986435, 0.035258]])
MITSUBA_ANALYTIC = np.array([[0.394048, 0.91909, 0.0], [0.263211, 0.883924, 0.386521], [-0.357096, 0.920152, -0.160629],
                             [-0.157034, 0.926926, 0.340806], [0.022563, 0.999128, 0.035128]])


@pytest.fixture(scope="module")
def grid():
    return SdfGrid(read_vol(TORUS))


def test_the_surface_and_normals_are_mitsubas(grid):
    """Mitsuba's hit points lie on the trilinear interpolant's zero set; its smooth (Hansson-Söderlund) and
    analytic normals there are SdfGrid's (Mitsuba's float32 values printed to 6 digits)."""
    np.testing.assert_allclose(grid.eval(MITSUBA_HITS), 0.0, atol=2e-6)
    unit = lambda n: n / np.linalg.norm(n, axis=1, keepdims=True)  # noqa: E731
    np.testing.assert_allclose(unit(grid.smooth_normal(MITSUBA_HITS)), MITSUBA_SMOOTH, atol=1e-5)  # hit points rounded to 6 digits
    np.testing.assert_allclose(unit(grid.grad(MITSUBA_HITS)), MITSUBA_ANALYTIC, atol=1e-5)
    assert np.abs(unit(grid.smooth_normal(MITSUBA_HITS)) - MITSUBA_ANALYTIC).max() > 0.05  # the two modes differ


@pytest.mark.parametrize("normals", ["smooth", "analytic"])
def test_the_mesh_lies_on_the_surface_and_faces_out(grid, normals):
    mesh = sdfgrid_mesh(grid.values, normals)
    g = grid.grad(mesh.vertices)
    distance = np.abs(grid.eval(mesh.vertices)) / np.linalg.norm(g, axis=1)  # first-order distance to the zero set
    assert distance.max() < 0.01 * grid.voxel[0], distance.max() / grid.voxel[0]
    fn = shapes.face_normals_of(mesh.vertices, mesh.faces)
    centroid_grad = grid.grad(mesh.vertices[mesh.faces].mean(axis=1))
    assert np.all(np.einsum("ij,ij->i", fn, centroid_grad) > 0)  # wound along ∇f: outward
    np.testing.assert_allclose(np.linalg.norm(mesh.normals, axis=1), 1.0, atol=1e-9)
    assert np.all(mesh.uvs == 0.0)  # Mitsuba's sdfgrid has no uv
    # the torus' area, 4π²Rr for R = 0.27, r = 0.13 (the grid's own surface differs by its sampling)
    assert shapes.mesh_area(mesh.vertices, mesh.faces) == pytest.approx(4 * np.pi**2 * 0.27 * 0.13, rel=0.01)


def test_the_loader_reads_an_sdfgrid_and_refuses_what_mitsuba_refuses(tmp_path):
    scene = load_mitsuba('<scene version="3.0.0"><emitter type="constant"/>\n'
                         f'<shape type="sdfgrid"><string name="filename" value="{TORUS}"/><string name="normals" value="analytic"/></shape></scene>')
    (o,) = scene.objects
    assert len(o.faces) > 1000 and np.all(o.uvs == 0.0)
    cases = [
        ('<boolean name="flip_normals" value="true"/>', "takes no flip_normals"),
        ('<string name="normals" value="flat"/>', "'normals' = 'flat' is not supported"),
        ('<emitter type="area"><rgb name="radiance" value="1"/></emitter>', "cannot be an area emitter"),
    ]
    for extra, message in cases:
        with pytest.raises(SceneFileError, match=message):
            load_mitsuba(f'<scene version="3.0.0"><emitter type="constant"/>\n<shape type="sdfgrid"><string name="filename" value="{TORUS}"/>{extra}</shape></scene>')
    bad = tmp_path / "bad.vol"
    bad.write_bytes(TORUS.read_bytes()[:100])
    with pytest.raises(GrisxError, match="values for a 24x24x24 grid"):
        read_vol(bad)
    with pytest.raises(SceneFileError, match=r"<string>:2: <shape type=\"sdfgrid\"> cannot read SDF grid"):
        load_mitsuba(f'<scene version="3.0.0"><emitter type="constant"/>\n<shape type="sdfgrid"><string name="filename" value="{bad}"/></shape></scene>')
