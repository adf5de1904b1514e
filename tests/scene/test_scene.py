"""Scene layer: cameras, BVH queries, motion vectors, textures, built-in scenes, CLI (CPU, small sizes)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import warp as wp

from grisx.cli import main
from grisx.errors import InvalidParameterError, InvalidValueError
from grisx.scene.builtin import BUILTIN_SCENES, build_builtin, cornell_box_moving
from grisx.scene.camera import Camera, CameraData, CameraPath, camera_project, camera_ray, lookat
from grisx.scene.gbuffer import GBuffer, make_gbuffer_kernel
from grisx.scene.lights import PointLight  # noqa: F401  (records used by the builder)
from grisx.scene.material import ALL_MATERIAL_KINDS, SCENE_MOVING_OBJECTS, Diffuse
from grisx.scene.scene import RigidMotion, Scene, SceneData, intersect
from grisx.scene.shapes import rectangle
from grisx.scene.texture import Bitmap, Checkerboard, TextureSet, pack_textures, texture_gradient, texture_lookup
from grisx.scene.transform import scale

# ---- cameras ---------------------------------------------------------------------------


@wp.kernel
def _rays(cam: CameraData, px: wp.array(dtype=wp.vec2), o: wp.array(dtype=wp.vec3), d: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    r = camera_ray(cam, px[i][0], px[i][1], wp.vec2(0.5, 0.5))
    o[i] = r.o
    d[i] = r.d


@wp.kernel
def _project(cam: CameraData, p: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.vec2)):
    i = wp.tid()
    out[i] = camera_project(cam, p[i]).pixel


def _cast(cam: CameraData, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    px = wp.array(pixels.astype(np.float32), dtype=wp.vec2, device="cpu")
    o = wp.zeros(len(pixels), dtype=wp.vec3, device="cpu")
    d = wp.zeros(len(pixels), dtype=wp.vec3, device="cpu")
    wp.launch(_rays, dim=len(pixels), inputs=[cam, px, o, d], device="cpu")
    return o.numpy(), d.numpy()


def test_lookat_matches_mitsuba_frame():
    m = lookat((1, 2, 3), (1, 2, 10), (0, 1, 0))
    # columns: left, up, dir, origin (Mitsuba: camera +x is the left of the image)
    np.testing.assert_allclose(m[:3, 0], (1, 0, 0), atol=1e-12)
    np.testing.assert_allclose(m[:3, 1], (0, 1, 0), atol=1e-12)
    np.testing.assert_allclose(m[:3, 2], (0, 0, 1), atol=1e-12)
    np.testing.assert_allclose(m[:3, 3], (1, 2, 3), atol=1e-12)


def test_camera_rays_against_hand_computed_rays():
    cam = Camera(to_world=lookat((0, 0, 0), (0, 0, 1), (0, 1, 0)), fov=90.0, fov_axis="x").data(4, 2)
    pixels = np.array([[0.5, 0.5], [2.0, 1.0], [4.0, 0.0]])
    o, d = _cast(cam, pixels)
    # tan(45°) = 1 across x; aspect 2 gives tan_y = 0.5. Film (sx, sy) → ((1-2sx)·1, (1-2sy)·0.5, 1)
    expected = np.array([[0.75, 0.25, 1.0], [0.0, 0.0, 1.0], [-1.0, 0.5, 1.0]])
    expected /= np.linalg.norm(expected, axis=1, keepdims=True)
    np.testing.assert_allclose(d, expected, atol=1e-6)
    np.testing.assert_allclose(o, 0.0, atol=1e-7)


@pytest.mark.parametrize("axis,width,height,tx,ty", [
    ("x", 200, 100, 1.0, 0.5),
    ("y", 200, 100, 2.0, 1.0),
    ("smaller", 200, 100, 2.0, 1.0),
    ("larger", 200, 100, 1.0, 0.5),
    ("diagonal", 300, 400, 0.6, 0.8),
])
def test_fov_axis_conventions(axis, width, height, tx, ty):
    cam = Camera(fov=90.0, fov_axis=axis)
    np.testing.assert_allclose(cam.tan_half_fov(width, height), (tx, ty), rtol=1e-12)


def test_orthographic_rays_against_hand_computed_rays():
    # Mitsuba's orthographic.cpp: film (sx, sy) → camera-space (1 − 2sx, (1 − 2sy)/aspect, near), along +z; to_world scales the film
    m = lookat((0, 0, 0), (0, 0, 1), (0, 1, 0)) @ scale((1.5, 1.5, 1.0))
    cam = Camera(to_world=m, near_clip=0.5, projection="orthographic").data(4, 2)
    o, d = _cast(cam, np.array([[0.5, 0.5], [2.0, 1.0], [4.0, 0.0]]))
    np.testing.assert_allclose(o, 1.5 * np.array([[0.75, 0.25, 0.0], [0.0, 0.0, 0.0], [-1.0, 0.5, 0.0]]) + [0, 0, 0.5], atol=1e-6)
    np.testing.assert_allclose(d, np.tile([0.0, 0.0, 1.0], (3, 1)), atol=1e-7)
    with pytest.raises(InvalidParameterError, match="projection"):
        Camera(projection="fisheye")
    with pytest.raises(InvalidParameterError, match="lens"):
        Camera(projection="orthographic", aperture_radius=0.1, focus_distance=1.0)


@pytest.mark.parametrize("projection", ["perspective", "orthographic"])
def test_project_inverts_camera_ray(projection):
    """Reprojection (motion vectors, temporal reuse) maps a camera ray's points back to its pixel, in either projection."""
    to_world = lookat((0.3, 1, 4), (0, 0, 0), (0, 1, 0)) @ (scale((1.5, 1.5, 1.0)) if projection == "orthographic" else np.eye(4))
    cam = Camera(to_world=to_world, fov=50, projection=projection).data(64, 48)
    rng = np.random.default_rng(1)
    pixels = rng.uniform([0, 0], [64, 48], size=(50, 2))
    o, d = _cast(cam, pixels)
    points = o + d * rng.uniform(1, 10, size=(50, 1))
    out = wp.zeros(50, dtype=wp.vec2, device="cpu")
    wp.launch(_project, dim=50, inputs=[cam, wp.array(points.astype(np.float32), dtype=wp.vec3, device="cpu"), out], device="cpu")
    np.testing.assert_allclose(out.numpy(), pixels, atol=2e-3)


def test_camera_path_loops_and_starts_at_first_key():
    keys = [((0, 0, 5), (0, 0, 0), (0, 1, 0)), ((5, 0, 0), (0, 0, 0), (0, 1, 0))]
    path = CameraPath(keys=keys, frames_per_key=10)
    np.testing.assert_allclose(path.to_world(0), lookat(*keys[0]), atol=1e-12)
    np.testing.assert_allclose(path.to_world(10), lookat(*keys[1]), atol=1e-12)
    np.testing.assert_allclose(path.to_world(20), lookat(*keys[0]), atol=1e-12)


def test_linear_camera_path_moves_at_constant_speed():
    # smoothstep starts at rest (a tenth of the way in: 2.8% of the distance); linear covers a tenth at once
    keys = [((0, 0, 5), (0, 0, 0), (0, 1, 0)), ((1, 0, 5), (1, 0, 0), (0, 1, 0))]
    origin = {e: [CameraPath(keys=keys, frames_per_key=10, easing=e).to_world(f)[0, 3] for f in range(11)] for e in ("linear", "smoothstep")}
    np.testing.assert_allclose(np.diff(origin["linear"]), 0.1, atol=1e-12)
    assert origin["smoothstep"][1] == pytest.approx(0.028)
    with pytest.raises(InvalidParameterError, match="easing"):
        CameraPath(keys=keys, easing="cubic")


# ---- BVH against brute force ----------------------------------------------------------


@wp.kernel
def _hits(scene: SceneData, o: wp.array(dtype=wp.vec3), d: wp.array(dtype=wp.vec3), t: wp.array(dtype=float), tri: wp.array(dtype=int)):
    i = wp.tid()
    si = intersect(scene, o[i], d[i], 1.0e30)
    if si.valid != 0:
        t[i] = si.t
        tri[i] = si.tri
    else:
        t[i] = -1.0
        tri[i] = -1


def _brute_force(v: np.ndarray, f: np.ndarray, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Möller–Trumbore against every triangle, float64 (the oracle)."""
    p0, p1, p2 = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    e1, e2 = p1 - p0, p2 - p0
    ts = np.full(len(o), -1.0)
    ids = np.full(len(o), -1)
    for i in range(len(o)):
        pv = np.cross(d[i], e2)
        det = np.einsum("ij,ij->i", e1, pv)
        ok = np.abs(det) > 1e-12
        inv = np.where(ok, 1 / np.where(ok, det, 1), 0)
        tv = o[i] - p0
        u = np.einsum("ij,ij->i", tv, pv) * inv
        qv = np.cross(tv, e1)
        w = (qv @ d[i]) * inv
        t = np.einsum("ij,ij->i", e2, qv) * inv
        hit = ok & (u >= 0) & (w >= 0) & (u + w <= 1) & (t > 0)
        if hit.any():
            j = np.argmin(np.where(hit, t, np.inf))
            ts[i], ids[i] = t[j], j
    return ts, ids


def test_bvh_hits_match_brute_force():
    built = build_builtin("cornell-box").build("cpu")
    v = built.positions.numpy().astype(np.float64)
    f = built.indices.numpy().reshape(-1, 3)
    rng = np.random.default_rng(3)
    o = rng.uniform(-0.95, 0.95, size=(400, 3))
    d = rng.normal(size=(400, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t = wp.zeros(400, dtype=float, device="cpu")
    tri = wp.zeros(400, dtype=int, device="cpu")
    wp.launch(_hits, dim=400, inputs=[built.data, wp.array(o.astype(np.float32), dtype=wp.vec3, device="cpu"),
                                       wp.array(d.astype(np.float32), dtype=wp.vec3, device="cpu"), t, tri], device="cpu")
    t_ref, tri_ref = _brute_force(v, f, o, d)
    assert (t_ref > 0).mean() > 0.5  # the box is open only at the front
    np.testing.assert_allclose(t.numpy(), t_ref, rtol=1e-4, atol=1e-5)
    # the same triangle, except where two triangles meet within float precision
    same = tri.numpy() == tri_ref
    assert same.mean() > 0.99


# ---- motion, refit and motion vectors ----------------------------------------------------


def _plane_scene(path: CameraPath | None, motion: RigidMotion | None = None, projection: str = "perspective") -> Scene:
    s = Scene("plane")
    white = s.add_material(Diffuse(0.5))
    mesh = rectangle()
    s.add_mesh(mesh.vertices, mesh.faces, material=white, normals=mesh.normals, uvs=mesh.uvs,
               to_world=np.diag([5.0, 5.0, 1.0, 1.0]), motion=motion, emission=(1, 1, 1))
    s.set_camera(Camera(to_world=lookat((0, 0, 4), (0, 0, 0), (0, 1, 0)), fov=40, projection=projection), path)
    return s


def _project_numpy(cam: Camera, width: int, height: int, p: np.ndarray) -> np.ndarray:
    q = (np.linalg.inv(cam.to_world) @ np.c_[p, np.ones(len(p))].T).T
    if cam.projection == "orthographic":  # Mitsuba's orthographic film: x ∈ [−1, 1], y ∈ [−1/aspect, 1/aspect]
        sx = 0.5 * (1 - q[:, 0])
        sy = 0.5 * (1 - q[:, 1] * width / height)
        return np.c_[sx * width, sy * height]
    tx, ty = cam.tan_half_fov(width, height)
    sx = 0.5 * (1 - q[:, 0] / (q[:, 2] * tx))
    sy = 0.5 * (1 - q[:, 1] / (q[:, 2] * ty))
    return np.c_[sx * width, sy * height]


@pytest.mark.parametrize("jitter, projection", [(False, "perspective"), (True, "perspective"), (True, "orthographic")])
def test_motion_vectors_match_analytic_reprojection_for_a_moving_camera(jitter, projection):
    """Motion vectors (what temporal reuse reprojects with) against the camera's projection in numpy, either projection."""
    path = CameraPath(keys=[((0, 0, 4), (0, 0, 0), (0, 1, 0)), ((1.0, 0.5, 3.5), (0.2, 0, 0), (0, 1, 0))], frames_per_key=8)
    built = _plane_scene(path, projection=projection).build("cpu")
    built.animate_camera = True
    w, h = 48, 32
    g = GBuffer(w, h, built.device)
    for frame in range(4):
        built.set_frame(float(frame))
        g.fill(built, float(frame), seed=5, jitter=jitter)
    fields = g.numpy()
    hit = fields["hit"] == 1
    assert hit.mean() > 0.9
    ys, xs = np.nonzero(hit)
    p = fields["position"][ys, xs].astype(np.float64)
    # where each stored point is on this frame's film: the pixel centre, or a point inside the pixel
    here = _project_numpy(built.camera_at(3.0), w, h, p)
    offset = here - np.c_[xs, ys]
    assert np.all((offset > -1e-3) & (offset < 1 + 1e-3))
    if jitter:
        assert offset.std() > 0.2  # spread over the pixel, not at its centre
    else:
        np.testing.assert_allclose(offset, 0.5, atol=2e-3)
    prev = _project_numpy(built.camera_at(2.0), w, h, p)
    expected = prev - here
    assert np.abs(expected).max() > 0.5  # the camera really moved by more than half a pixel
    np.testing.assert_allclose(fields["motion"][ys, xs], expected, atol=2e-3)
    # the previous frame's pixel holding the point (away from pixel borders, where float rounding may go either way)
    inner = np.all(np.abs(prev - np.round(prev)) > 1e-2, axis=1)
    np.testing.assert_array_equal(fields["motion_int"][ys, xs][inner], (np.floor(prev) - np.c_[xs, ys])[inner].astype(int))


def test_jittered_gbuffer_holds_its_visible_points_and_draws_them_afresh_each_frame():
    built = build_builtin("cornell-box").build("cpu")
    w, h = 24, 18
    g = GBuffer(w, h, built.device)
    g.fill(built, 3.0, seed=11, jitter=True)
    si, wo, pos = g.current.si.numpy(), g.current.wo.numpy(), g.current.position.numpy()
    hit = g.current.hit.numpy() == 1
    np.testing.assert_array_equal(si["p"][hit], pos[hit])  # the fields describe the visible point
    np.testing.assert_array_equal(si["valid"], g.current.hit.numpy())
    np.testing.assert_allclose(np.linalg.norm(wo, axis=-1), 1.0, rtol=1e-5)
    g.fill(built, 4.0, seed=11, jitter=True)  # a new frame: new points; the last one's are kept as previous
    assert np.abs(g.current.position.numpy() - pos).max() > 1e-3
    np.testing.assert_array_equal(g.previous.si.numpy()["p"], si["p"])
    g.fill(built, 3.0, seed=11, jitter=True)  # same seed and frame: the same points
    np.testing.assert_array_equal(g.current.si.numpy()["p"], si["p"])


def test_motion_vectors_follow_a_moving_object_and_refit_only_when_it_moves():
    built = _plane_scene(None, RigidMotion(velocity=(0.05, 0.0, 0.0))).build("cpu")
    w, h = 32, 32
    g = GBuffer(w, h, built.device)
    before = built.positions.numpy().copy()
    assert built.set_frame(1.0) is True
    assert built.set_frame(1.0) is False  # nothing moved: no refit
    np.testing.assert_allclose(built.positions.numpy() - before, np.tile([0.05, 0, 0], (len(before), 1)), atol=1e-6)
    g.fill(built, 1.0)
    fields = g.numpy()
    ys, xs = np.nonzero(fields["hit"] == 1)
    p_prev = fields["position"][ys, xs].astype(np.float64) - [0.05, 0, 0]
    expected = _project_numpy(built.camera, w, h, p_prev) - np.c_[xs + 0.5, ys + 0.5]
    np.testing.assert_allclose(fields["motion"][ys, xs], expected, atol=2e-3)
    static = _plane_scene(None).build("cpu")
    assert static.set_frame(5.0) is False


def _gbuffer_fields(built, kinds, frames: int = 3) -> dict:
    """Every G-buffer field after ``frames`` jittered frames, its kernel compiled for ``kinds``."""
    g = GBuffer(32, 24, built.device)
    g.kernel = lambda b: make_gbuffer_kernel(frozenset(kinds), True)
    for frame in range(frames):
        built.set_frame(float(frame))
        g.fill(built, float(frame), seed=7, jitter=True)
    return {**g.numpy(), "si": g.current.si.numpy(), "wo": g.current.wo.numpy()}


def test_a_still_scenes_gbuffer_skips_the_object_round_trip_bit_for_bit():
    """A scene without SCENE_MOVING_OBJECTS compiles its G-buffer without the per-pixel trip through its objects' frames
    (identity transforms): every field, motion under a moving camera included, is the all-kinds kernel's to the bit. The
    sibling: a scene whose objects move, compiled without the kind, loses their motion."""
    built = build_builtin("door-ajar").build("cpu")
    built.animate_camera = True
    kinds = built.features.material_kinds
    assert SCENE_MOVING_OBJECTS not in kinds
    lean, every = _gbuffer_fields(built, kinds), _gbuffer_fields(built, ALL_MATERIAL_KINDS)
    assert np.abs(lean["motion"]).max() > 0.05  # the camera moved (door-ajar's path: ~0.07 px a frame at this size)
    for name in every:
        np.testing.assert_array_equal(lean[name], every[name], err_msg=name)
    moving = _plane_scene(None, RigidMotion(velocity=(0.05, 0.0, 0.0))).build("cpu")
    kinds = moving.features.material_kinds
    assert SCENE_MOVING_OBJECTS in kinds
    right, wrong = _gbuffer_fields(moving, kinds), _gbuffer_fields(moving, kinds - {SCENE_MOVING_OBJECTS})
    assert np.abs(right["motion"]).max() > 0.5 and not np.array_equal(wrong["motion"], right["motion"])


# ---- textures --------------------------------------------------------------------------


@wp.kernel
def _lookup(ts: TextureSet, uv: wp.array(dtype=wp.vec2), out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    out[i] = texture_lookup(ts, 0, uv[i])


def test_texture_lookup_is_bilinear_with_wraparound():
    img = np.arange(4 * 3 * 3, dtype=np.float32).reshape(3, 4, 3)
    ts = pack_textures([img], "cpu")
    uv = np.array([[0.125, 1 / 6], [0.25, 1 / 3], [1.125, 1 / 6 + 2.0], [0.0, 1 / 6]], dtype=np.float32)
    out = wp.zeros(len(uv), dtype=wp.vec3, device="cpu")
    wp.launch(_lookup, dim=len(uv), inputs=[ts, wp.array(uv, dtype=wp.vec2, device="cpu"), out], device="cpu")
    res = out.numpy()
    np.testing.assert_allclose(res[0], img[0, 0], atol=1e-4)  # texel centre
    np.testing.assert_allclose(res[1], 0.25 * (img[0, 0] + img[0, 1] + img[1, 0] + img[1, 1]), atol=1e-4)
    np.testing.assert_allclose(res[2], img[0, 0], atol=1e-3)  # wraps in u and v
    np.testing.assert_allclose(res[3], 0.5 * (img[0, 0] + img[0, 3]), atol=1e-4)  # left edge blends with the last column


def _bitmap_oracle(img, u, v, wrap, nearest):
    """Mitsuba's bitmap eval in numpy (Dr.Jit's Texture.wrap); agrees with Mitsuba 3.9.1's scalar_rgb bitmap to 2e-7
    at every (mode, filter, uv) of the test below."""
    h, w, _ = img.shape

    def wr(i, n):
        if wrap == "clamp":
            return min(max(i, 0), n - 1)
        if wrap == "mirror":
            m = i % (2 * n)
            return 2 * n - 1 - m if m >= n else m
        return i % n

    if nearest:
        return img[wr(math.floor(v * h), h), wr(math.floor(u * w), w)]
    x, y = u * w - 0.5, v * h - 0.5
    x0, y0 = math.floor(x), math.floor(y)
    fx, fy = x - x0, y - y0
    t = lambda i, j: img[wr(j, h), wr(i, w)]  # noqa: E731
    return (t(x0, y0) * (1 - fx) + t(x0 + 1, y0) * fx) * (1 - fy) + (t(x0, y0 + 1) * (1 - fx) + t(x0 + 1, y0 + 1) * fx) * fy


@pytest.mark.parametrize("wrap", ["repeat", "mirror", "clamp"])
@pytest.mark.parametrize("filter_type", ["bilinear", "nearest"])
def test_bitmap_wrap_modes_and_filters_are_mitsubas(wrap, filter_type):
    img = np.arange(4 * 3 * 3, dtype=np.float32).reshape(3, 4, 3) / 40.0
    uv = [(0.125, 1 / 6), (-0.1, 0.3), (1.2, -0.4), (-1.3, 2.7), (0.99, 0.01), (2.6, -1.1), (-0.02, 1.01)]
    got = _lookup_all(Bitmap(img, wrap_mode=wrap, filter_type=filter_type), uv)
    expected = [_bitmap_oracle(img, u, v, wrap, filter_type == "nearest") for u, v in uv]
    np.testing.assert_allclose(got, expected, atol=2e-5)
    if (wrap, filter_type) == ("mirror", "nearest"):  # hand-checked: u = -0.1 → texel column 0 (mirrored -1), v = 0.3 → row 0
        np.testing.assert_allclose(got[1], img[0, 0], atol=0)
    if (wrap, filter_type) == ("clamp", "bilinear"):  # v = -0.4: the top row; u = 1.2: the last column
        np.testing.assert_allclose(got[2], img[0, 3], atol=1e-6)


def test_a_bitmap_refuses_unknown_wrap_modes():
    with pytest.raises(InvalidValueError, match="wrap_mode"):
        pack_textures([Bitmap(np.zeros((2, 2, 3)), wrap_mode="border")], "cpu")


def _lookup_all(tex, uv):
    ts = pack_textures([tex], "cpu")
    out = wp.zeros(len(uv), dtype=wp.vec3, device="cpu")
    wp.launch(_lookup, dim=len(uv), inputs=[ts, wp.array(np.asarray(uv, dtype=np.float32), dtype=wp.vec2, device="cpu"), out], device="cpu")
    return out.numpy()


def test_checkerboard_is_mitsubas_and_to_uv_is_affine():
    c0, c1 = (0.9, 0.8, 0.7), (0.1, 0.2, 0.3)
    # checkerboard.cpp: color0 where frac(u) > ½ and frac(v) > ½ agree
    uv = [[0.25, 0.25], [0.75, 0.75], [0.75, 0.25], [0.25, 0.75], [-0.25, 0.25], [1.75, -1.25]]
    res = _lookup_all(Checkerboard(c0, c1), uv)
    np.testing.assert_allclose(res, [c0, c0, c1, c1, c1, c0], atol=0)
    # to_uv scales by 2 in u and shifts v by ½: (0.3, 0.1) → (0.6, 0.6), color0; (0.2, 0.1) → (0.4, 0.6), color1
    res = _lookup_all(Checkerboard(c0, c1, to_uv=((2.0, 0.0, 0.0), (0.0, 1.0, 0.5))), [[0.3, 0.1], [0.2, 0.1]])
    np.testing.assert_allclose(res, [c0, c1], atol=0)
    img = np.arange(4 * 3 * 3, dtype=np.float32).reshape(3, 4, 3)
    res = _lookup_all(Bitmap(img, to_uv=((0.5, 0.0, 0.125), (0.0, 1.0, 0.0))), [[0.0, 1 / 6], [0.25, 1 / 6]])
    np.testing.assert_allclose(res, [img[0, 0], 0.5 * (img[0, 0] + img[0, 1])], atol=1e-4)


@wp.kernel
def _gradient(ts: TextureSet, uv: wp.array(dtype=wp.vec2), out: wp.array(dtype=wp.vec2)):
    i = wp.tid()
    out[i] = texture_gradient(ts, 0, uv[i])


def test_texture_gradient_is_the_uv_derivative_of_the_lookups_luminance():
    """A bump map's slope (Mitsuba's ``eval_1_grad``) against central differences of the bilinear lookup, through a
    scaling and shifting ``to_uv`` (Mitsuba's formula scales by the resolution after the transposed map, exact
    for such maps); a checkerboard has none."""
    rng = np.random.default_rng(5)
    img = rng.random((5, 7, 3)).astype(np.float32)
    tex = Bitmap(img, to_uv=((2.0, 0.0, 0.1), (0.0, -1.5, 0.2)))
    uv = rng.random((64, 2))
    ts = pack_textures([tex], "cpu")
    out = wp.zeros(len(uv), dtype=wp.vec2, device="cpu")
    wp.launch(_gradient, dim=len(uv), inputs=[ts, wp.array(uv.astype(np.float32), dtype=wp.vec2, device="cpu"), out], device="cpu")
    lum = np.array([0.212671, 0.715160, 0.072169])
    h = 1e-3
    fd = np.stack([(_lookup_all(tex, uv + d) - _lookup_all(tex, uv - d)) @ lum / (2 * h) for d in ([h, 0.0], [0.0, h])], axis=1)
    # central differences straddle a texel edge for a few points: compare where both sides lie in one bilinear patch
    np.testing.assert_allclose(np.median(np.abs(out.numpy() - fd)), 0.0, atol=1e-3)
    inside = np.abs(out.numpy() - fd).max(axis=1) < 0.05 * np.abs(fd).max()
    assert inside.mean() > 0.8
    ts = pack_textures([Checkerboard()], "cpu")
    wp.launch(_gradient, dim=len(uv), inputs=[ts, wp.array(uv.astype(np.float32), dtype=wp.vec2, device="cpu"), out], device="cpu")
    assert np.all(out.numpy() == 0)


# ---- built-in scenes ---------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(BUILTIN_SCENES))
def test_every_builtin_scene_builds_and_its_gbuffer_is_finite(name):
    scene = build_builtin(name)
    built = scene.build("cpu")
    assert built.num_triangles > 0
    g = GBuffer(24, 16, built.device)
    g.fill(built, 0.0)
    fields = g.numpy()
    assert fields["hit"].sum() > 0
    for key, a in fields.items():
        assert np.all(np.isfinite(a)), key


def test_scene_features_record_what_a_scene_uses():
    cb = build_builtin("cornell-box").features()
    assert cb.material_kinds == frozenset({0}) and not cb.has_delta and not cb.has_caustic_casters
    assert cb.has_area_lights and cb.environment == "none" and not cb.animated_objects
    caustic = build_builtin("caustic-slab-plane").features()
    assert caustic.has_dielectric and caustic.has_delta and caustic.has_bump and caustic.has_caustic_casters
    assert build_builtin("pool").features().environment == "envmap"
    assert build_builtin("checker-grid").features().has_textures
    assert cornell_box_moving().features().animated_objects


def test_scene_without_lights_or_shapes_is_rejected():
    from grisx.errors import InvalidParameterError

    s = Scene("dark")
    m = s.add_material(Diffuse(0.5))
    mesh = rectangle()
    s.add_mesh(mesh.vertices, mesh.faces, material=m)
    with pytest.raises(InvalidParameterError, match="no light source"):
        s.build("cpu")
    with pytest.raises(InvalidParameterError, match="no shapes"):
        Scene("empty").build("cpu")


@pytest.mark.parametrize("bad", [
    dict(faces=[[0, 1, 7]]),
    dict(vertices=[[0, 0, np.nan], [1, 0, 0], [0, 1, 0]]),
    dict(material=3),
])
def test_bad_meshes_are_named(bad):
    from grisx.errors import GrisxError

    s = Scene()
    m = s.add_material(Diffuse(0.5))
    args = dict(vertices=[[0, 0, 0], [1, 0, 0], [0, 1, 0]], faces=[[0, 1, 2]], material=m) | bad
    with pytest.raises(GrisxError, match="mesh"):
        s.add_mesh(args.pop("vertices"), args.pop("faces"), **args)


# ---- CLI ----------------------------------------------------------------------------------


def test_scenes_cli_lists_every_builtin(capsys):
    assert main(["scenes", "--json"]) == 0
    names = [s["name"] for s in json.loads(capsys.readouterr().out)["scenes"]]
    assert names == list(BUILTIN_SCENES)


def test_render_cli_writes_exr_png_and_sidecar(tmp_path, capsys):
    out = tmp_path / "cb.exr"
    assert main(["render", "cornell-box", "--method", "normal", "--res", "20x16", "--out", str(out), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert (info["width"], info["height"], info["method"], info["scene"]) == (20, 16, "normal", "cornell-box")
    for path in info["output"]:
        assert (tmp_path / path.split("/")[-1]).exists()
    sidecar = json.loads(out.with_suffix(".json").read_text())
    assert sidecar["device"] == "cpu" and "grisx_version" in sidecar and sidecar["seed"] == 0
    from grisx.imageio import read_exr

    n = read_exr(out)
    assert n.shape == (16, 20, 3)
    lengths = np.linalg.norm(n, axis=-1)
    np.testing.assert_allclose(lengths[lengths > 0], 1.0, atol=1e-4)


@pytest.mark.parametrize("argv,fragment", [
    (["render", "no-such-scene", "--method", "albedo"], "scene"),
    (["render", "cornell-box", "--method", "nope"], "render method"),
    (["render", "cornell-box", "--method", "albedo", "--res", "12"], "--res"),
    (["render", "missing.xml", "--method", "albedo"], "does not exist"),
])
def test_render_cli_bad_input_is_one_line(argv, fragment, capsys, tmp_path):
    assert main([*argv, "--out", str(tmp_path / "x.exr")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("grisx: error:") and "\n" not in err and fragment in err


def test_fov_is_positive():
    from grisx.errors import InvalidParameterError

    with pytest.raises(InvalidParameterError, match="fov"):
        Camera(fov=0.0)
    assert math.isclose(Camera().fov, 39.3077)


def test_mitsuba_xml_cornell_box_matches_the_builtin_one():
    from pathlib import Path

    from grisx.render.driver import render

    xml = Path(__file__).parent / "data" / "cornell_box.xml"
    views = [render(str(s), "gbuffer", res=(32, 32)).extra for s in (xml, "cornell-box")]
    for field in ("albedo", "normal", "depth", "material", "emission"):
        np.testing.assert_allclose(views[0][field], views[1][field], atol=1e-5, err_msg=field)


@wp.kernel
def _lens_rays(cam: CameraData, u: wp.array(dtype=wp.vec2), o: wp.array(dtype=wp.vec3), d: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    r = camera_ray(cam, 7.3, 4.1, u[i])
    o[i] = r.o
    d[i] = r.d


def test_thin_lens_rays_of_one_pixel_meet_on_the_focal_plane():
    cam = Camera(to_world=lookat((0, 0, 0), (0, 0, 1), (0, 1, 0)), fov=50, aperture_radius=0.2, focus_distance=3.0)
    data = cam.data(16, 8)
    u = np.random.default_rng(2).uniform(size=(64, 2)).astype(np.float32)
    o = wp.zeros(64, dtype=wp.vec3, device="cpu")
    d = wp.zeros(64, dtype=wp.vec3, device="cpu")
    wp.launch(_lens_rays, dim=64, inputs=[data, wp.array(u, dtype=wp.vec2, device="cpu"), o, d], device="cpu")
    o, d = o.numpy().astype(np.float64), d.numpy().astype(np.float64)
    assert np.ptp(o[:, 0]) > 0.1 and np.all(np.hypot(o[:, 0], o[:, 1]) <= 0.2 + 1e-6)  # origins spread over the lens
    hit = o + d * ((3.0 - o[:, 2]) / d[:, 2])[:, None]  # where each ray crosses z = focus distance
    np.testing.assert_allclose(hit, np.broadcast_to(hit.mean(axis=0), hit.shape), atol=1e-5)
