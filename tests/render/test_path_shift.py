"""Path shifts (random replay, reconnection, hybrid): invertibility and Jacobians on random paths.

Paths come from ReSTIR PT's initial-candidate pass (one frame, no reuse) on
small images; pairs of pixels are drawn at random (hypothesis picks the
seeds). For each shift T_{j→i}:

* **invertibility** — y = T(x), z = T⁻¹(y): T(z) = y exactly (the shift is
  an involution on its image), |J_T(x)| · |J_{T⁻¹}(y)| = 1, and z agrees
  with x (exactly for replay; for shifts that reconnect, up to the ray
  offset that separates a sampled direction from the geometric one);
* **Jacobian against finite differences** — for every path whose shift maps
  the first direction ω at x₁ through a fixed planar vertex x₂ (reconnection
  to a surface or light point; replayed next-event estimation to the same
  light point), |∂ω'/∂ω| is measured by central differences of
  ω ↦ x₂(ω) ↦ ω' in numpy and compared with the Jacobian the shift returns
  (seed 004, Eq. 11; Lin et al. 2022, Sec. 7).
"""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp
from hypothesis import given, settings
from hypothesis import strategies as st

from reuse_checks import random_records
from grisx.errors import InvalidParameterError
from grisx.scene.builtin import build_builtin
from grisx.scene.camera import Camera, lookat
from grisx.scene.lights import sample_light
from grisx.scene.material import Diffuse
from grisx.render.base.path_shift import (
    DIM_NEE,
    PATH_SLOT_FLOATS,
    PATH_SLOT_INTS,
    PATH_SLOT_KEYS,
    Domain,
    PathSample,
    PathSlots,
    ShiftParams,
    make_path_shift,
    path_dim,
    path_slot_load,
    path_slot_store,
    path_slots,
    path_target,
    shift_params,
)
from grisx.render.restir_pt import PathReservoir, ReSTIRPT
from grisx.scene.scene import Scene, SceneData
from grisx.scene.shapes import rectangle
from grisx.theory.random import random_uniform
from grisx.theory.shift import replay_jacobian

SHIFTS = ("replay", "reconnection", "hybrid")
RES = 20


def lit_wall() -> Scene:
    """A diffuse wall facing the camera, a diffuse floor, and a strip light close to the wall."""
    s = Scene("lit-wall")
    white = s.add_material(Diffuse(0.7))
    r = rectangle()
    s.add_mesh(r.vertices, r.faces, normals=r.normals, material=white, to_world=np.diag([1.5, 1.5, 1.0, 1.0]))
    floor = np.array([[1.5, 0, 0, 0], [0, 0, 1.0, -1.0], [0, -1.0, 0, 1.0], [0, 0, 0, 1.0]])  # y = −1, facing +y
    s.add_mesh(r.vertices, r.faces, normals=r.normals, material=white, to_world=floor)
    # a strip light above the field of view, facing down along the wall: the wall's irradiance falls
    # off steeply with height, so reconnection distances (and Jacobians) differ strongly between pixels
    light = np.array([[1.0, 0, 0, 0], [0, 0, -1.0, 1.5], [0, 0.3, 0, 0.35], [0, 0, 0, 1.0]])
    s.add_mesh(r.vertices, r.faces, normals=r.normals, material=white, to_world=light, emission=(12.0, 11.0, 9.0))
    s.set_camera(Camera(to_world=lookat((0, 0, 3), (0, 0, 0), (0, 1, 0)), fov=50))
    return s


_HARNESS: dict = {}


def _harness(kinds: frozenset[int]):
    """A kernel that shifts path x of pixel a into pixel b and back, and records both records."""
    if kinds in _HARNESS:
        return _HARNESS[kinds]
    shift = make_path_shift(kinds).shift

    @wp.kernel
    def roundtrip(
        scene: SceneData,
        sp: ShiftParams,
        doms: wp.array2d(dtype=Domain),
        res: wp.array2d(dtype=PathReservoir),
        src: wp.array(dtype=wp.vec2i),
        dst: wp.array(dtype=wp.vec2i),
        steps: int,
        scalars: wp.array2d(dtype=float),
        points: wp.array2d(dtype=wp.vec3),
    ):
        t = wp.tid()
        a = src[t]
        b = dst[t]
        x = res[a[1], a[0]].path
        da = doms[a[1], a[0]]
        db = doms[b[1], b[0]]
        scalars[t, 0] = float(x.length)
        scalars[t, 1] = path_target(x)
        scalars[t, 8] = float(x.rc_index)
        scalars[t, 9] = float(x.rc_kind)
        scalars[t, 10] = float(x.end_nee)
        points[t, 0] = da.p
        points[t, 1] = db.p
        points[t, 2] = x.rc_p
        points[t, 3] = x.rc_ng
        points[t, 4] = da.ng
        if x.length == 1 and x.end_nee == 1:
            # the light point of a direct path (independent of the reference point: area sampling)
            c = path_dim(1, DIM_NEE)
            ls = sample_light(scene.lights, da.p, random_uniform(x.key, c), wp.vec2(random_uniform(x.key, c + 1), random_uniform(x.key, c + 2)))
            points[t, 5] = ls.p
            points[t, 6] = ls.n
        # T into b, T⁻¹ back into a, T into b again: one shift in a loop (``steps`` = 3, a launch argument so that
        # Warp does not unroll it), not three inlined copies (a third of the compile time)
        cur = x
        going = bool(True)
        for step in range(steps):
            if going:
                into = db
                if step == 1:
                    into = da
                s = shift(scene, into, cur, sp)
                if step == 0:
                    scalars[t, 2] = float(s.valid)
                    scalars[t, 3] = s.jacobian
                    if s.valid:
                        scalars[t, 7] = path_target(s.path)
                elif step == 1:
                    scalars[t, 4] = float(s.valid)
                    scalars[t, 5] = s.jacobian
                    scalars[t, 6] = path_target(s.path)
                else:
                    scalars[t, 11] = float(s.valid)
                    scalars[t, 12] = path_target(s.path)
                    scalars[t, 13] = s.jacobian
                going = s.valid
                cur = s.path

    _HARNESS[kinds] = roundtrip
    return roundtrip


_BUILT: dict = {}


def _scene(name: str):
    if name not in _BUILT:
        _BUILT[name] = (lit_wall() if name == "lit-wall" else build_builtin(name)).build("cpu")
    return _BUILT[name]


def _roundtrips(scene: str, shift: str, seed: int, n: int = 600, reach: int = 6, **kw) -> tuple[np.ndarray, np.ndarray]:
    built = _scene(scene)
    r = ReSTIRPT(built, RES, RES, shift=shift, temporal=False, spatial_rounds=0, seed=seed, **kw)
    r.render_frame(0)
    rng = np.random.default_rng(seed)
    src = rng.integers(0, RES, size=(n, 2))
    dst = np.clip(src + rng.integers(-reach, reach + 1, size=(n, 2)), 0, RES - 1)
    scalars = wp.zeros((n, 14), dtype=float, device="cpu")
    points = wp.zeros((n, 7), dtype=wp.vec3, device="cpu")
    wp.launch(
        _harness(built.features.kernel_kinds),
        dim=n,
        inputs=[built.data, r.shift_params, r.domains[0], r.reservoirs_array(), wp.array(src.astype(np.int32), dtype=wp.vec2i), wp.array(dst.astype(np.int32), dtype=wp.vec2i), 3],
        outputs=[scalars, points],
        device="cpu",
    )
    return scalars.numpy().astype(np.float64), points.numpy().astype(np.float64)


# ---- exact values -----------------------------------------------------------------------------------


@wp.kernel
def _replay_jacobian_kernel(src: wp.array(dtype=float), dst: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = replay_jacobian(src[i], dst[i])


def test_replay_jacobian_exact_values():
    src = wp.array([2.0, 0.25, 3.0, 0.0], dtype=float, device="cpu")
    dst = wp.array([4.0, 0.125, 0.0, 1.0], dtype=float, device="cpu")
    out = wp.zeros(4, dtype=float, device="cpu")
    wp.launch(_replay_jacobian_kernel, dim=4, inputs=[src, dst, out], device="cpu")
    np.testing.assert_allclose(out.numpy(), [0.5, 2.0, 0.0, 0.0])  # p_dst = 0 or p_src = 0: the shift fails (0)


# ---- invertibility ------------------------------------------------------------------------------


@pytest.mark.parametrize("shift", SHIFTS)
@settings(deadline=None, max_examples=4)
@given(seed=st.integers(0, 2**16))
def test_shift_is_invertible(shift, seed):
    s, _ = _roundtrips("cornell-box", shift, seed)
    has = s[:, 1] > 0
    fwd = has & (s[:, 2] > 0) & (s[:, 7] > 0)
    assert fwd.sum() > 50, "too few successful shifts to test"
    # T⁻¹ is defined wherever T was (the bijection's image maps back)
    assert np.all(s[fwd, 4] > 0)
    # T(T⁻¹(y)) = y: bit-for-bit the same construction, so to float32 rounding
    assert np.all(s[fwd, 11] > 0)
    np.testing.assert_allclose(s[fwd, 12], s[fwd, 7], rtol=1e-4)
    # |J_T(x)| · |J_T⁻¹(T(x))| = 1
    np.testing.assert_allclose(s[fwd, 3] * s[fwd, 5], 1.0, rtol=2e-3 if shift == "replay" else 5e-2)
    np.testing.assert_allclose(s[fwd, 5] * s[fwd, 13], 1.0, rtol=1e-4)
    # T⁻¹(T(x)) = x: exact for replay; reconnection differs from the sampled path by the ray offset only
    rel = np.abs(s[fwd, 6] - s[fwd, 1]) / s[fwd, 1]
    if shift == "replay":
        assert rel.max() < 1e-5
    else:
        assert np.median(rel) < 1e-4 and rel.max() < 5e-2


def test_pure_reconnection_never_replays_and_replay_never_reconnects():
    s, _ = _roundtrips("cornell-box", "reconnection", 7)
    k = s[s[:, 1] > 0, 8]
    assert set(np.unique(k)) <= {0.0, 2.0}
    s, _ = _roundtrips("cornell-box", "replay", 7)
    assert np.all(s[s[:, 1] > 0, 8] == 0)


def test_hybrid_reconnects_later_past_a_mirror():
    # metal-rack has smooth conductors: the hybrid shift picks later reconnection vertices there
    s, _ = _roundtrips("metal-rack", "hybrid", 3)
    k = s[s[:, 1] > 0, 8]
    assert np.any(k > 2) and np.any(k == 2)


# ---- Jacobians against finite differences -----------------------------------------------------


def _tangent_basis(w: np.ndarray) -> np.ndarray:
    a = np.array([1.0, 0, 0]) if abs(w[0]) < 0.9 else np.array([0, 1.0, 0])
    s = np.cross(w, a)
    s /= np.linalg.norm(s)
    return np.stack([s, np.cross(w, s)])


def _fd_jacobian(x1: np.ndarray, x1_dst: np.ndarray, x2: np.ndarray, n2: np.ndarray, h: float = 1e-4) -> float:
    """|dω'/dω| of ω ↦ x₂(ω) (the plane through x₂ with normal n₂) ↦ ω' = (x₂ − x₁')/‖·‖, by central differences."""
    w0 = (x2 - x1) / np.linalg.norm(x2 - x1)
    basis = _tangent_basis(w0)
    w_dst = (x2 - x1_dst) / np.linalg.norm(x2 - x1_dst)
    basis_dst = _tangent_basis(w_dst)

    def image(a: float, b: float) -> np.ndarray:
        w = w0 + a * basis[0] + b * basis[1]
        w /= np.linalg.norm(w)
        t = np.dot(x2 - x1, n2) / np.dot(w, n2)
        p = x1 + t * w
        v = p - x1_dst
        return v / np.linalg.norm(v)

    cols = []
    for e in ((1, 0), (0, 1)):
        d = (image(h * e[0], h * e[1]) - image(-h * e[0], -h * e[1])) / (2 * h)
        cols.append(basis_dst @ d)
    # ω(a, b) has unit Jacobian at (0, 0) in the tangent plane: the ratio is det of the image's
    return abs(np.linalg.det(np.array(cols).T))


@pytest.mark.parametrize("shift", ("reconnection", "hybrid"))
@settings(deadline=None, max_examples=3)
@given(seed=st.integers(0, 2**16))
def test_reconnection_jacobian_matches_finite_differences(shift, seed):
    s, pts = _roundtrips("lit-wall", shift, seed)
    # paths reconnected at x₂ (k = 2) to a planar surface or light point (not the environment)
    ok = (s[:, 1] > 0) & (s[:, 2] > 0) & (s[:, 8] == 2) & (s[:, 9] <= 1)
    ok &= np.linalg.norm(pts[:, 0] - pts[:, 1], axis=1) > 1e-3  # a real move
    assert ok.sum() > 20
    fd = np.array([_fd_jacobian(pts[t, 0], pts[t, 1], pts[t, 2], pts[t, 3]) for t in np.flatnonzero(ok)])
    np.testing.assert_allclose(s[ok, 3], fd, rtol=2e-2)


@settings(deadline=None, max_examples=3)
@given(seed=st.integers(0, 2**16))
def test_replay_jacobian_matches_finite_differences(seed):
    # direct paths x₁ → light by next-event estimation: replay keeps the light point, so
    # the map of solid angles at x₁ is ω ↦ y ↦ ω' and the density ratio must equal its |∂ω'/∂ω|
    s, pts = _roundtrips("lit-wall", "replay", seed)
    ok = (s[:, 1] > 0) & (s[:, 2] > 0) & (s[:, 0] == 1) & (s[:, 10] == 1)
    ok &= np.linalg.norm(pts[:, 0] - pts[:, 1], axis=1) > 1e-3
    assert ok.sum() > 20
    fd = np.array([_fd_jacobian(pts[t, 0], pts[t, 1], pts[t, 5], pts[t, 6]) for t in np.flatnonzero(ok)])
    np.testing.assert_allclose(s[ok, 3], fd, rtol=2e-2)


def test_wrong_jacobian_ablation_returns_one():
    true, _ = _roundtrips("lit-wall", "hybrid", 1)
    assert np.any(np.abs(true[true[:, 2] > 0, 3] - 1.0) > 0.1)  # the true Jacobians are far from 1 here
    wrong, _ = _roundtrips("lit-wall", "hybrid", 1, jacobian=False)
    assert np.all(wrong[wrong[:, 2] > 0, 3] == 1.0)


def test_jacobian_threshold_rejects_symmetrically():
    base, _ = _roundtrips("lit-wall", "hybrid", 5)
    j = base[base[:, 2] > 0, 3]
    assert np.any((j > 1.5) | (j < 1 / 1.5)), "the test needs Jacobians beyond the threshold"
    s, _ = _roundtrips("lit-wall", "hybrid", 5, max_jacobian=1.5)
    fwd = s[:, 2] > 0
    assert 0 < fwd.sum() < (base[:, 2] > 0).sum()
    assert np.all((s[fwd, 3] <= 1.5) & (s[fwd, 3] >= 1 / 1.5))
    assert np.all(s[fwd, 4] > 0)  # the inverse of an accepted shift is accepted: T stays a bijection


def test_unknown_shift_is_an_error():
    with pytest.raises(InvalidParameterError, match="unknown shift"):
        shift_params("teleport")


# ---- path slots: a kept path in structure-of-arrays form ----

@wp.kernel
def _slot_roundtrip(src: wp.array2d(dtype=PathSample), slots: PathSlots, out: wp.array2d(dtype=PathSample)):
    y, x = wp.tid()
    path_slot_store(slots, y, x, src[y, x])
    out[y, x] = path_slot_load(slots, y, x)


def _random_paths(rng: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
    a = random_records(PathSample.numpy_dtype(), rng, shape)
    a["key"] = rng.integers(2**31, 2**32, size=shape, dtype=np.uint64).astype(np.uint32)  # the high bit survives
    return a


def test_path_slots_hold_every_field_of_a_path():
    """path_slot_store then path_slot_load gives back every word of a PathSample, and the named layout covers every
    field: a field added to PathSample and not to the slots would come back as 0 here and fail."""
    assert set(PATH_SLOT_FLOATS + PATH_SLOT_INTS + PATH_SLOT_KEYS) == set(PathSample.vars)
    shape = (5, 7)
    a = _random_paths(np.random.default_rng(3), shape)
    src = wp.array(a, dtype=PathSample, device="cpu")
    out = wp.zeros(shape, dtype=PathSample, device="cpu")
    wp.launch(_slot_roundtrip, dim=shape, inputs=[src, path_slots(*shape, "cpu")], outputs=[out], device="cpu")
    b = out.numpy()
    for name in a.dtype.names:
        assert np.array_equal(a[name], b[name]), name


def test_path_slots_sibling_a_store_that_drops_a_field_is_caught():
    """The check above fails when one word is left out: the same round trip through a store that skips rc_cos."""

    @wp.kernel
    def lossy(src: wp.array2d(dtype=PathSample), slots: PathSlots, out: wp.array2d(dtype=PathSample)):
        y, x = wp.tid()
        p = src[y, x]
        p.rc_cos = 0.0
        path_slot_store(slots, y, x, p)
        out[y, x] = path_slot_load(slots, y, x)

    shape = (3, 4)
    a = _random_paths(np.random.default_rng(4), shape)
    out = wp.zeros(shape, dtype=PathSample, device="cpu")
    wp.launch(lossy, dim=shape, inputs=[wp.array(a, dtype=PathSample, device="cpu"), path_slots(*shape, "cpu")], outputs=[out], device="cpu")
    b = out.numpy()
    assert not np.array_equal(a["rc_cos"], b["rc_cos"])
