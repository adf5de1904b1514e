"""Analytic spheres, disks and cylinders (grisx.scene.analytic) against closed forms in float64 and
against their tessellated twins in grisx.scene.shapes (whose conventions test_shapes.py checks against
Mitsuba 3's definitions)."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from grisx.errors import InvalidParameterError, InvalidValueError
from grisx.scene import shapes
from grisx.scene.material import Diffuse
from grisx.scene.mitsuba import load_mitsuba
from grisx.scene.scene import Scene, SceneData, intersect, occluded
from grisx.scene.transform import compose, rotate, scale, translate


@wp.kernel
def _trace(scene: SceneData, o: wp.array(dtype=wp.vec3), d: wp.array(dtype=wp.vec3), t_out: wp.array(dtype=float),
           p_out: wp.array(dtype=wp.vec3), n_out: wp.array(dtype=wp.vec3), uv_out: wp.array(dtype=wp.vec2),
           prim_out: wp.array(dtype=wp.int32), obj_out: wp.array(dtype=wp.int32), blocked: wp.array(dtype=wp.int32)):
    i = wp.tid()
    si = intersect(scene, o[i], d[i], 1.0e30)
    t_out[i] = -1.0
    prim_out[i] = -1
    if si.valid != 0:
        t_out[i] = si.t
        p_out[i] = si.p
        n_out[i] = si.ng
        uv_out[i] = si.uv
        prim_out[i] = si.tri
        obj_out[i] = si.object
    blocked[i] = int(occluded(scene, o[i], d[i], 50.0))


def trace(built, o: np.ndarray, d: np.ndarray) -> dict[str, np.ndarray]:
    n = len(o)
    dev = built.device
    out = {k: wp.zeros(n, dtype=t, device=dev) for k, t in
           (("t", float), ("p", wp.vec3), ("n", wp.vec3), ("uv", wp.vec2), ("prim", wp.int32), ("obj", wp.int32), ("blocked", wp.int32))}
    wp.launch(_trace, dim=n, inputs=[built.data, wp.array(o.astype(np.float32), dtype=wp.vec3, device=dev),
                                     wp.array(d.astype(np.float32), dtype=wp.vec3, device=dev)],
              outputs=list(out.values()), device=dev)
    return {k: v.numpy() for k, v in out.items()}


def rays_at(rng: np.random.Generator, n: int, center: np.ndarray, spread: float, dist: float) -> tuple[np.ndarray, np.ndarray]:
    """Rays from a shell of radius ``dist`` around ``center`` toward points within ``spread`` of it."""
    o = rng.normal(size=(n, 3))
    o = center + dist * o / np.linalg.norm(o, axis=1, keepdims=True)
    target = center + spread * rng.uniform(-1, 1, size=(n, 3))
    d = target - o
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    # the kernels see float32 rays: the closed forms take the same ones
    return o.astype(np.float32).astype(np.float64), d.astype(np.float32).astype(np.float64)


def one_shape(kind: str, to_world: np.ndarray, flip: bool = False) -> Scene:
    s = Scene()
    s.add_shape(kind, material=s.add_material(Diffuse(0.5)), to_world=to_world, flip_normals=flip)
    s.add_point_light((0, 10, 0), 1.0)
    return s


# ---- closed forms (float64) -------------------------------------------------------------


def ellipsoid_hits(to_world: np.ndarray, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """t of the nearest positive root of |M⁻¹(o + t d)|² = 1 (inf: miss), and the outward normal there."""
    inv = np.linalg.inv(to_world)
    ol = o @ inv[:3, :3].T + inv[:3, 3]
    dl = d @ inv[:3, :3].T
    a = np.sum(dl * dl, 1)
    b = 2 * np.sum(ol * dl, 1)
    c = np.sum(ol * ol, 1) - 1
    disc = b * b - 4 * a * c
    sq = np.sqrt(np.maximum(disc, 0))
    t0, t1 = (-b - sq) / (2 * a), (-b + sq) / (2 * a)
    t = np.where(t0 > 0, t0, np.where(t1 > 0, t1, np.inf))
    t = np.where(disc >= 0, t, np.inf)
    q = ol + np.where(np.isfinite(t), t, 0.0)[:, None] * dl
    n = q @ inv[:3, :3]  # inverse transpose, row-vector form
    return t, n / np.linalg.norm(n, axis=1, keepdims=True)


def test_sphere_hits_points_and_normals_are_exact():
    rng = np.random.default_rng(1)
    m = compose(translate((0.3, -0.2, 1.0)), scale(0.7))
    built = one_shape("sphere", m).build()
    o, d = rays_at(rng, 4000, np.array([0.3, -0.2, 1.0]), 0.9, 6.0)
    r = trace(built, o, d)
    t_ref, n_ref = ellipsoid_hits(m, o, d)
    hit = np.isfinite(t_ref)
    assert 0.3 < hit.mean() < 0.9  # both hits and misses are exercised
    # a hit/miss disagreement can only be a ray grazing the sphere (float32 rounding of the origin)
    differ = hit != (r["t"] > 0)
    closest = np.linalg.norm(np.cross(np.array([0.3, -0.2, 1.0]) - o, d), axis=1)
    assert np.all(np.abs(closest[differ] - 0.7) < 1e-5)
    both = hit & (r["t"] > 0)
    np.testing.assert_allclose(r["t"][both], t_ref[both], rtol=2e-5, atol=2e-5)
    np.testing.assert_allclose(np.linalg.norm(r["p"][both] - [0.3, -0.2, 1.0], axis=1), 0.7, rtol=1e-6)  # on the sphere
    np.testing.assert_allclose(r["n"][both], n_ref[both], atol=1e-5)
    assert np.all(r["prim"][both] == built.num_triangles)  # after the (one placeholder) triangle
    # occlusion agrees with the closest hit (the segment is 50 long)
    assert np.array_equal(r["blocked"][both] == 1, r["t"][both] < 50.0)


def test_rays_from_inside_a_sphere_leave_it_through_the_far_root():
    rng = np.random.default_rng(2)
    built = one_shape("sphere", scale(2.0)).build()
    o = rng.uniform(-0.5, 0.5, size=(500, 3))
    d = rng.normal(size=(500, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = trace(built, o, d)
    t_ref, _ = ellipsoid_hits(scale(2.0), o, d)
    np.testing.assert_allclose(r["t"], t_ref, rtol=1e-5)
    assert np.all(np.sum(r["n"] * d, 1) > 0)  # the outward normal faces along the exiting ray


def test_an_ellipsoid_from_a_non_uniform_scale():
    rng = np.random.default_rng(3)
    m = compose(translate((0.0, 1.0, 0.0)), rotate((1, 1, 0), 30.0), scale((0.5, 1.5, 0.8)))
    built = one_shape("sphere", m).build()
    o, d = rays_at(rng, 3000, np.array([0.0, 1.0, 0.0]), 1.2, 8.0)
    r = trace(built, o, d)
    t_ref, n_ref = ellipsoid_hits(m, o, d)
    both = np.isfinite(t_ref) & (r["t"] > 0)
    assert both.mean() > 0.3
    np.testing.assert_allclose(r["t"][both], t_ref[both], rtol=5e-5, atol=5e-5)
    np.testing.assert_allclose(r["n"][both], n_ref[both], atol=2e-4)


def test_a_ray_from_far_away_keeps_its_digits():
    """The foot-of-perpendicular form (module docstring): a unit sphere seen from 10⁴ away is still hit within
    float32 rounding of the distance, where the naive discriminant B² − 4AC loses the sphere's edge."""
    built = one_shape("sphere", np.eye(4)).build()
    y = np.linspace(-0.999, 0.999, 101)
    o = np.stack([np.zeros_like(y), y, np.full_like(y, 1.0e4)], 1)
    d = np.tile([0.0, 0.0, -1.0], (len(y), 1))
    r = trace(built, o, d)
    np.testing.assert_allclose(r["t"], 1.0e4 - np.sqrt(1 - y**2), rtol=2e-7 * 4)
    np.testing.assert_allclose(np.linalg.norm(r["p"], axis=1), 1.0, atol=1e-6)  # re-projected onto the sphere


def test_disk_and_cylinder_hits():
    rng = np.random.default_rng(4)
    for kind, m in (("disk", compose(translate((0, 0.5, 0)), rotate((1, 0, 0), -60.0), scale(0.8))),
                    ("cylinder", compose(translate((0.2, 0, 0)), rotate((0, 1, 0), 20.0), scale((0.5, 0.5, 2.0))))):
        built = one_shape(kind, m).build()
        center = m[:3, 3] + (m[:3, 2] * 0.5 if kind == "cylinder" else 0)
        o, d = rays_at(rng, 3000, center, 1.2, 6.0)
        r = trace(built, o, d)
        inv = np.linalg.inv(m)
        hit = r["t"] > 0
        assert 0.1 < hit.mean() < 0.9
        q = r["p"][hit] @ inv[:3, :3].T + inv[:3, 3]  # object space
        if kind == "disk":
            np.testing.assert_allclose(q[:, 2], 0.0, atol=1e-6)
            assert np.all(np.hypot(q[:, 0], q[:, 1]) <= 1 + 1e-6)
            np.testing.assert_allclose(r["uv"][hit][:, 0], np.hypot(q[:, 0], q[:, 1]), atol=1e-5)
            n = np.array([0, 0, 1.0]) @ inv[:3, :3]
        else:
            np.testing.assert_allclose(np.hypot(q[:, 0], q[:, 1]), 1.0, atol=1e-5)
            assert np.all((q[:, 2] >= -1e-6) & (q[:, 2] <= 1 + 1e-6))
            np.testing.assert_allclose(r["uv"][hit][:, 1], q[:, 2], atol=1e-5)
            n = (q * [1, 1, 0]) @ inv[:3, :3]
        n = n / np.linalg.norm(n, axis=-1, keepdims=True)
        np.testing.assert_allclose(r["n"][hit], np.broadcast_to(n, r["n"][hit].shape), atol=1e-4)
        # the hit is on the ray, and nothing nearer was skipped: the same ray from just past the hit goes on
        np.testing.assert_allclose(o[hit] + d[hit] * r["t"][hit][:, None], r["p"][hit], atol=2e-5)


@pytest.mark.parametrize("kind, flip, negative", [("sphere", False, False), ("sphere", True, False), ("sphere", False, True),
                                                  ("disk", False, False), ("disk", True, False),
                                                  ("cylinder", False, False), ("cylinder", True, False)])
def test_analytic_shapes_agree_with_their_tessellated_twins(kind, flip, negative):
    """Same rays against the analytic shape and its mesh from grisx.scene.shapes: hit points, the side the
    geometric normal faces, and uv agree to the tessellation's error (Mitsuba's conventions on both)."""
    rng = np.random.default_rng(5)
    m = compose(translate((0.1, 0.2, -0.3)), rotate((0, 0, 1), 40.0), rotate((1, 0, 0), 25.0), scale(-0.9 if negative else 0.9))
    a = one_shape(kind, m, flip).build()
    mesh = getattr(shapes, kind)(flip_normals=flip)
    s = Scene()
    s.add_mesh(mesh.vertices, mesh.faces, material=s.add_material(Diffuse(0.5)), normals=mesh.normals, uvs=mesh.uvs, to_world=m)
    s.add_point_light((0, 10, 0), 1.0)
    b = s.build()
    o, d = rays_at(rng, 3000, m[:3, 3], 0.7, 5.0)
    ra, rb = trace(a, o, d), trace(b, o, d)
    both = (ra["t"] > 0) & (rb["t"] > 0)
    assert both.mean() > 0.2
    assert np.mean((ra["t"] > 0) != (rb["t"] > 0)) < 0.01  # silhouette pixels only
    dt = np.abs(ra["t"][both] - rb["t"][both])  # the inscribed polyhedron is ≤ 6e-4 inside; more along grazing rays
    assert np.quantile(dt, 0.99) < 1e-3 and dt.max() < 1e-2
    assert np.all(np.sum(ra["n"][both] * rb["n"][both], 1) > 0.99)  # same side: flip_normals and mirrors agree
    du = np.abs(ra["uv"][both] - rb["uv"][both])
    du = np.minimum(du, 1 - du)  # φ/2π wraps at the seam
    assert np.quantile(du, 0.99) < 1e-2


def test_analytic_only_scene_and_primitive_ids():
    s = Scene()
    red, blue = s.add_material(Diffuse((0.8, 0.1, 0.1))), s.add_material(Diffuse((0.1, 0.1, 0.8)))
    s.add_shape("sphere", material=red, to_world=translate((-2, 0, 0)))
    s.add_shape("disk", material=blue, to_world=translate((2, 0, 0)))
    s.add_point_light((0, 5, 5), 10.0)
    assert s.triangle_count == 0 and s.shape_count == 2
    built = s.build()
    o = np.array([[-2, 0, 5.0], [2, 0, 5.0], [0, 0, 5.0]])
    d = np.tile([0, 0, -1.0], (3, 1))
    r = trace(built, o, d)
    assert list(r["prim"]) == [built.num_triangles, built.num_triangles + 1, -1]
    assert list(r["obj"][:2]) == [0, 1]
    np.testing.assert_allclose(r["t"][:2], [4.0, 5.0], rtol=1e-6)
    mats = built.data.tri_material.numpy()
    assert mats[built.num_triangles] == red and mats[built.num_triangles + 1] == blue
    assert built.lights.tri_emitter.numpy().size == built.num_triangles + 2


def test_add_shape_refuses_bad_input():
    s = Scene()
    mid = s.add_material(Diffuse(0.5))
    with pytest.raises(InvalidParameterError, match="unknown analytic shape 'torus'"):
        s.add_shape("torus", material=mid)
    with pytest.raises(InvalidParameterError, match="unknown material"):
        s.add_shape("sphere", material=7)
    with pytest.raises(InvalidValueError, match="invertible"):
        s.add_shape("sphere", material=mid, to_world=np.diag([1.0, 0.0, 1.0, 1.0]))


def test_the_loader_keeps_spheres_analytic_and_emitters_tessellated():
    xml = """<scene version="3.0.0">
      <shape type="sphere"><float name="radius" value="0.5"/></shape>
      <shape type="cylinder"/><shape type="disk"/>
      <shape type="sphere"><point name="center" x="3" y="0" z="0"/><emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>
    </scene>"""
    sc = load_mitsuba(xml)
    assert sc.shape_count == 3
    assert sc.triangle_count == len(shapes.sphere().faces)
