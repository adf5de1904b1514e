"""Light sampling: Mitsuba's mappings, χ² of sampled directions against the pdfs, and irradiance against closed forms.

The ladder: exact values (envmap orientation, triangle/sphere maps, a point
light) → properties (hypothesis round trips) → statistics: χ² of the
directions ``sample_light`` draws against ``light_pdf_emitter`` +
``environment_pdf`` integrated per direction cell, ∫ pdf dω = 1, and Monte
Carlo irradiance within 4σ of the analytic value — with a sibling that drops
the cosine of the area → solid-angle Jacobian and is caught beyond 6σ.
"""

import math

import numpy as np
import pytest
import warp as wp
from hypothesis import given, settings
from hypothesis import strategies as st

from grisx.errors import InvalidParameterError, InvalidValueError
from grisx.scene import lights as L
from grisx.testing import BIASED_K, DEFAULT_K, chi2_test, z_test
from grisx.theory.random import random_key, random_uniform

wp.set_module_options({"enable_backward": False})

SEED = 20261121


# ---- kernels ---------------------------------------------------------------------------


@wp.kernel
def _sample_kernel(ls: L.LightSet, ref: wp.vec3, normal: wp.vec3, seed: int,
                   wi: wp.array(dtype=wp.vec3), pdf: wp.array(dtype=float), pdf_query: wp.array(dtype=float),
                   contrib: wp.array(dtype=wp.vec3), contrib_no_cos: wp.array(dtype=wp.vec3), light: wp.array(dtype=int),
                   radiance: wp.array(dtype=wp.vec3)):
    """One light sample per thread; the irradiance estimate L cos θ / p, and its biased twin."""
    i = wp.tid()
    k = random_key(seed, i)
    s = L.sample_light(ls, ref, random_uniform(k, 0), wp.vec2(random_uniform(k, 1), random_uniform(k, 2)))
    wi[i] = s.wi
    pdf[i] = s.pdf
    light[i] = s.light
    radiance[i] = s.radiance
    q = float(0.0)
    if s.is_env == 1:
        q = L.environment_pdf(ls, s.wi)
    elif s.tri >= 0:
        q = L.light_pdf_emitter(ls, s.tri, ref, s.p, s.n)
    pdf_query[i] = q
    if s.pdf > 0.0:
        cos_ref = wp.max(wp.dot(normal, s.wi), 0.0)
        contrib[i] = s.radiance * (cos_ref / s.pdf)
        biased_pdf = s.pdf
        if s.tri >= 0:
            biased_pdf = s.pdf_area * s.dist * s.dist  # BIASED: the |cos θ_y| of the Jacobian forgotten
        contrib_no_cos[i] = s.radiance * (cos_ref / biased_pdf)


@wp.kernel
def _direction_pdf_kernel(ls: L.LightSet, mesh: wp.uint64, ref: wp.vec3, dirs: wp.array(dtype=wp.vec3),
                          pdf: wp.array(dtype=float), radiance: wp.array(dtype=wp.vec3)):
    """Density of direction d under sample_light: the emitter the ray hits (if any) + the environment."""
    i = wp.tid()
    d = dirs[i]
    p = L.environment_pdf(ls, d)
    rad = L.environment_eval(ls, d)
    q = wp.mesh_query_ray(mesh, ref, d, 1.0e6)
    if q.result:
        p = p + L.light_pdf_emitter(ls, q.face, ref, ref + d * q.t, q.normal)
        rad = L.emitter_radiance(ls, q.face, ref + d * q.t, q.normal, -d)
    pdf[i] = p
    radiance[i] = rad


@wp.kernel
def _map_kernel(uv_in: wp.array(dtype=wp.vec2), d_out: wp.array(dtype=wp.vec3), uv_back: wp.array(dtype=wp.vec2),
                b_in: wp.array(dtype=wp.vec2), b_out: wp.array(dtype=wp.vec3), u_back: wp.array(dtype=wp.vec2),
                sphere: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    d = L.envmap_uv_to_direction(uv_in[i])
    d_out[i] = d
    uv_back[i] = L.envmap_direction_to_uv(d)
    b = L.sample_uniform_triangle(b_in[i])
    b_out[i] = b
    u_back[i] = L.invert_uniform_triangle(b)
    sphere[i] = L.sample_uniform_sphere(b_in[i])


@wp.kernel
def _eval_kernel(ls: L.LightSet, dirs: wp.array(dtype=wp.vec3), radiance: wp.array(dtype=wp.vec3), pdf: wp.array(dtype=float)):
    i = wp.tid()
    radiance[i] = L.environment_eval(ls, dirs[i])
    pdf[i] = L.environment_pdf(ls, dirs[i])


# ---- helpers ---------------------------------------------------------------------------


def _sample(ls, n, device, ref=(0.0, 0.0, 0.0), normal=(0.0, 0.0, 1.0), seed=SEED):
    outs = [wp.zeros(n, dtype=wp.vec3, device=device), wp.zeros(n, dtype=float, device=device),
            wp.zeros(n, dtype=float, device=device), wp.zeros(n, dtype=wp.vec3, device=device),
            wp.zeros(n, dtype=wp.vec3, device=device), wp.zeros(n, dtype=int, device=device),
            wp.zeros(n, dtype=wp.vec3, device=device)]
    wp.launch(_sample_kernel, n, inputs=[ls, wp.vec3(*ref), wp.vec3(*normal), seed, *outs], device=device)
    return dict(zip(("wi", "pdf", "pdf_query", "contrib", "contrib_no_cos", "light", "radiance"), (o.numpy() for o in outs)))


def _eval_env(ls, dirs, device):
    d = wp.array(np.asarray(dirs, np.float32), dtype=wp.vec3, device=device)
    rad = wp.zeros(len(dirs), dtype=wp.vec3, device=device)
    pdf = wp.zeros(len(dirs), dtype=float, device=device)
    wp.launch(_eval_kernel, len(dirs), inputs=[ls, d, rad, pdf], device=device)
    return rad.numpy(), pdf.numpy()


def _rot_y(deg):
    a = math.radians(deg)
    m = np.eye(4)
    m[:3, :3] = [[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]]
    return m


NZ, NPHI, SUB = 16, 32, 48  # direction cells (cos θ × φ, equal solid angle) and midpoint sub-samples per axis


def _cell_of(wi):
    z = np.clip(wi[:, 2], -1.0, 1.0)
    phi = np.mod(np.arctan2(wi[:, 1], wi[:, 0]), 2 * np.pi)
    iz = np.minimum(((z + 1.0) * 0.5 * NZ).astype(int), NZ - 1)
    ip = np.minimum((phi / (2 * np.pi) * NPHI).astype(int), NPHI - 1)
    return iz * NPHI + ip


def _cell_masses(ls, positions, indices, device, ref=(0.0, 0.0, 0.0)):
    """∫ pdf dω over each (cos θ, φ) cell by the midpoint rule (dω = dz dφ)."""
    fz = (np.arange(NZ * SUB) + 0.5) / (NZ * SUB) * 2.0 - 1.0
    fp = (np.arange(NPHI * SUB) + 0.5) / (NPHI * SUB) * 2 * np.pi
    z, phi = np.meshgrid(fz, fp, indexing="ij")
    r = np.sqrt(1 - z**2)
    dirs = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1).reshape(-1, 3)
    mesh = wp.Mesh(points=wp.array(np.asarray(positions, np.float32), dtype=wp.vec3, device=device),
                   indices=wp.array(np.asarray(indices, np.int32).ravel(), dtype=wp.int32, device=device))
    pdf = wp.zeros(len(dirs), dtype=float, device=device)
    rad = wp.zeros(len(dirs), dtype=wp.vec3, device=device)
    wp.launch(_direction_pdf_kernel, len(dirs), inputs=[ls, mesh.id, wp.vec3(*ref),
                                                         wp.array(dirs.astype(np.float32), dtype=wp.vec3, device=device), pdf, rad],
              device=device)
    d_omega = (2.0 / (NZ * SUB)) * (2 * np.pi / (NPHI * SUB))
    per_sub = pdf.numpy().astype(np.float64).reshape(NZ, SUB, NPHI, SUB) * d_omega
    return per_sub.sum(axis=(1, 3)).ravel()


def _step_pdf(masses):
    m = np.asarray(masses, float)
    return lambda x: m[np.clip(np.floor(x).astype(int), 0, m.size - 1)]


def _direction_chi2(wi, masses, seed=SEED):
    cells = _cell_of(wi) + np.random.default_rng(seed).random(len(wi))
    return chi2_test(cells, _step_pdf(masses / masses.sum()), 0.0, float(masses.size), bins=masses.size)


# ---- scenes ------------------------------------------------------------------------------

# three emissive triangles around the origin that never overlap as seen from it:
# one overhead facing down, one at x = 3 facing the origin, one at y = −2 facing away (back-facing: black, still sampled)
TRI_POSITIONS = np.array([
    [-1.0, -0.5, 2.0], [1.0, -0.5, 2.0], [0.0, 1.0, 2.0],
    [3.0, -1.0, -1.0], [3.0, 1.0, -1.0], [3.0, 0.0, 1.0],
    [-1.0, -2.0, -1.0], [1.0, -2.0, -1.0], [0.0, -2.0, 1.0],
])
TRI_INDICES = np.array([[0, 2, 1], [3, 5, 4], [6, 7, 8]])
TRI_RADIANCE = np.array([[4.0, 2.0, 1.0], [1.0, 1.0, 6.0], [2.0, 2.0, 2.0]])


def _envmap_image(h=6, w=10, seed=3):
    img = np.random.default_rng(seed).random((h, w, 3)) * 0.5
    img[1, 2] = (30.0, 20.0, 10.0)  # a bright spot
    img[4, 7] = (0.0, 0.0, 0.0)
    return img


# ---- exact: mappings and orientation -------------------------------------------------


def _maps(uv, b, device="cpu"):
    n = len(uv)
    ins = [wp.array(np.asarray(uv, np.float32), dtype=wp.vec2, device=device)]
    outs = [wp.zeros(n, dtype=wp.vec3, device=device), wp.zeros(n, dtype=wp.vec2, device=device)]
    ins2 = [wp.array(np.asarray(b, np.float32), dtype=wp.vec2, device=device)]
    outs2 = [wp.zeros(n, dtype=wp.vec3, device=device), wp.zeros(n, dtype=wp.vec2, device=device), wp.zeros(n, dtype=wp.vec3, device=device)]
    wp.launch(_map_kernel, n, inputs=[*ins, *outs, *ins2, *outs2], device=device)
    return [o.numpy() for o in outs + outs2]


def test_envmap_axes_follow_mitsuba():
    # Mitsuba: d = (sin φ sin θ, cos θ, −cos φ sin θ), φ = 2π u, θ = π v
    uv = np.array([[0.0, 0.0], [0.0, 0.5], [0.25, 0.5], [0.5, 0.5], [0.75, 0.5], [0.3, 1.0]])
    d = _maps(uv, np.zeros_like(uv))[0]
    np.testing.assert_allclose(d, [[0, 1, 0], [0, 0, -1], [1, 0, 0], [0, 0, 1], [-1, 0, 0], [0, -1, 0]], atol=1e-6)


@settings(deadline=None, max_examples=20)
@given(st.lists(st.tuples(st.floats(0.0, 0.999), st.floats(0.001, 0.999)), min_size=1, max_size=16))
def test_envmap_mapping_round_trip(pairs):
    uv = np.array(pairs)
    d, uv_back = _maps(uv, np.zeros_like(uv))[:2]
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-5)
    du = np.abs(uv_back[:, 0] - uv[:, 0])
    np.testing.assert_allclose(np.minimum(du, 1 - du), 0.0, atol=2e-5)  # u is periodic
    np.testing.assert_allclose(uv_back[:, 1], uv[:, 1], atol=2e-4)


@settings(deadline=None, max_examples=20)
@given(st.lists(st.tuples(st.floats(0.0, 0.999), st.floats(0.0, 0.999)), min_size=1, max_size=16))
def test_triangle_map_round_trip_and_sphere_is_unit(pairs):
    u = np.array(pairs)
    _, _, b, u_back, sphere = _maps(np.zeros_like(u), u)
    assert np.all(b >= -1e-6)
    np.testing.assert_allclose(b.sum(axis=1), 1.0, atol=1e-6)
    np.testing.assert_allclose(u_back, u, atol=2e-4)
    np.testing.assert_allclose(np.linalg.norm(sphere, axis=1), 1.0, atol=1e-5)


def test_bright_pixel_lands_where_mitsuba_puts_it(device):
    # W = 6, H = 5: column 1 is centred at u = 1.5/6 = 0.25 (φ = π/2), row 2 lies at v = 2/4 (equator) → local +X
    img = np.zeros((5, 6, 3))
    img[2, 1] = (3.0, 2.0, 1.0)
    for to_world, expected in ((None, [1, 0, 0]), (_rot_y(90), [0, 0, -1])):
        ls = L.build_light_set(device, np.zeros((3, 3)), np.array([[0, 1, 2]]), environment=L.EnvMap(img, scale=2.0, to_world=to_world))
        rad, pdf = _eval_env(ls, [expected, [-e for e in expected], [0, 1, 0]], device)
        np.testing.assert_allclose(rad[0], [6.0, 4.0, 2.0], rtol=1e-5)  # the pixel value × scale, exactly at its centre
        np.testing.assert_allclose(rad[1:], 0.0, atol=1e-6)
        assert pdf[0] > 0 and pdf[1] == 0
        s = _sample(ls, 2000, device)
        assert np.all(s["pdf"] > 0)
        mean = s["wi"].mean(axis=0)
        np.testing.assert_allclose(mean / np.linalg.norm(mean), expected, atol=0.05)  # every sample near the bright pixel
        # only the 2 × 2 cells around the pixel (φ within ±60°, θ within ±45° of it) have radiance: cos ≥ sin 45° sin 30°
        assert np.min(s["wi"] @ np.asarray(expected, float)) > math.sin(math.pi / 4) * 0.5 - 1e-5


def test_point_light_is_a_delta_with_inverse_square_radiance(device):
    ls = L.build_light_set(device, np.zeros((3, 3)), np.array([[0, 1, 2]]), point_lights=[L.PointLight((0.0, 0.0, 2.0), (4.0, 8.0, 12.0))])
    s = _sample(ls, 8, device)
    np.testing.assert_allclose(s["wi"], np.tile([0.0, 0.0, 1.0], (8, 1)), atol=1e-6)
    np.testing.assert_allclose(s["pdf"], 1.0)
    np.testing.assert_allclose(s["contrib"], np.tile([1.0, 2.0, 3.0], (8, 1)), rtol=1e-6)  # I cos / d², pdf 1


def test_emission_is_one_sided():
    ls = L.build_light_set("cpu", TRI_POSITIONS, TRI_INDICES, [0, 1, 2], TRI_RADIANCE)
    s = _sample(ls, 4000, "cpu")
    back = s["light"] == 2
    assert back.any() and np.all(s["radiance"][back] == 0) and np.all(s["pdf"][back] > 0)
    np.testing.assert_array_equal(s["radiance"][~back], TRI_RADIANCE[s["light"][~back]])


# ---- statistics: χ² of sampled directions, ∫ pdf dω = 1 ------------------------------


@pytest.mark.parametrize("lights", ["triangles", "envmap", "triangles+envmap", "textured triangles+envmap"])
def test_sampled_directions_follow_the_pdf(device, lights):
    """... and with two triangles of one light textured (their selection weighted by the image over each, the
    light's share split between them) beside a plain triangle and the environment."""
    tris = [0, 1, 2] if "triangles" in lights else []
    env = L.EnvMap(_envmap_image(), scale=0.5, to_world=_rot_y(30) @ np.diag([1.0, 1.0, 1.0, 1.0])) if "envmap" in lights else None
    textured = {"emitter_textures": [np.random.default_rng(8).random((4, 5, 3))], "emitter_texture": [0, 0, -1], "emitter_group": [0, 0, 1]} if "textured" in lights else {}
    ls = L.build_light_set(device, TRI_POSITIONS, TRI_INDICES, tris, TRI_RADIANCE[tris] if tris else (), environment=env, scene_radius=2.0, **textured)
    s = _sample(ls, 200_000, device)
    assert np.all(s["pdf"] > 0)
    np.testing.assert_allclose(s["pdf_query"], s["pdf"], rtol=2e-3)  # the pdf a BSDF-sampled hit would ask for
    masses = _cell_masses(ls, TRI_POSITIONS, TRI_INDICES, device)
    # ∫ pdf dω = 1 (midpoint rule; triangle edges cut cells, hence the looser bound with triangles)
    assert abs(masses.sum() - 1.0) < (5e-3 if tris else 1e-3), masses.sum()
    result = _direction_chi2(s["wi"], masses)
    assert result.passed, str(result)


def test_envmap_pdf_integrates_to_one_exactly(device):
    # a (θ, φ) grid whose cells nest in the map's sampling cells: p_ω sin θ is constant on each, so the sum is exact
    img, rot = _envmap_image(), _rot_y(30)[:3, :3]
    ls = L.build_light_set(device, np.zeros((3, 3)), np.array([[0, 1, 2]]), environment=L.EnvMap(img, to_world=_rot_y(30)))
    n_theta, n_phi = 250, 500
    t, p = np.meshgrid((np.arange(n_theta) + 0.5) / n_theta * np.pi, (np.arange(n_phi) + 0.5) / n_phi * 2 * np.pi, indexing="ij")
    local = np.stack([np.sin(p) * np.sin(t), np.cos(t), -np.cos(p) * np.sin(t)], axis=-1).reshape(-1, 3)
    _, pdf = _eval_env(ls, local @ rot.T, device)
    integral = np.sum(pdf.astype(np.float64) * np.sin(t).ravel()) * (np.pi / n_theta) * (2 * np.pi / n_phi)
    assert abs(integral - 1.0) < 1e-5, integral


def test_direction_chi2_catches_a_wrong_pdf(device):
    # the same samples against the pdf of uniform (not power-proportional) triangle selection: caught
    ls = L.build_light_set(device, TRI_POSITIONS, TRI_INDICES, [0, 1, 2], TRI_RADIANCE)
    s = _sample(ls, 200_000, device)
    p = TRI_POSITIONS[TRI_INDICES]
    areas = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    equal_power = L.build_light_set(device, TRI_POSITIONS, TRI_INDICES, [0, 1, 2], np.ones((3, 3)) / areas[:, None])
    wrong = _cell_masses(equal_power, TRI_POSITIONS, TRI_INDICES, device)
    assert _direction_chi2(s["wi"], _cell_masses(ls, TRI_POSITIONS, TRI_INDICES, device)).passed
    result = _direction_chi2(s["wi"], wrong)
    assert not result.passed and result.p_value < 1e-12, str(result)


# ---- statistics: irradiance against closed forms --------------------------------------


def _square_irradiance(a, h):
    """Irradiance at the centre below a square of side 2a at height h, radiance 1 (four corner rectangles)."""
    # form factor of an a×a corner rectangle: F = (1/π) A/√(1+A²) atan(A/√(1+A²)), A = a/h; E = π · 4F
    A = a / h
    return 4.0 * (A / math.sqrt(1 + A * A)) * math.atan(A / math.sqrt(1 + A * A))


SQUARE = np.array([[-1.0, -1.0, 1.0], [1.0, -1.0, 1.0], [1.0, 1.0, 1.0], [-1.0, 1.0, 1.0]])
SQUARE_FACES = np.array([[0, 2, 1], [0, 3, 2]])  # facing −z, toward the origin
L_SQUARE = np.array([2.0, 1.0, 0.5])
POINT_I = np.array([3.0, 0.0, 1.0])
POINT_P = np.array([1.0, 0.5, 2.0])
L_ENV = np.array([0.1, 0.3, 0.2])


def test_emitter_pdf_and_radiance_of_a_hand_case(device):
    # two triangles of area 2 and equal power: pmf 1/2 each; toward (0.5, −0.5, 1): d² = 1.5, |cos θ_y| = 1/√1.5
    ls = L.build_light_set(device, SQUARE, SQUARE_FACES, [0, 1], L_SQUARE)
    d = np.array([0.5, -0.5, 1.0]) / math.sqrt(1.5)
    mesh = wp.Mesh(points=wp.array(SQUARE.astype(np.float32), dtype=wp.vec3, device=device),
                   indices=wp.array(SQUARE_FACES.astype(np.int32).ravel(), dtype=wp.int32, device=device))
    pdf = wp.zeros(2, dtype=float, device=device)
    rad = wp.zeros(2, dtype=wp.vec3, device=device)
    dirs = wp.array(np.array([d, -d], np.float32), dtype=wp.vec3, device=device)
    wp.launch(_direction_pdf_kernel, 2, inputs=[ls, mesh.id, wp.vec3(0.0, 0.0, 0.0), dirs, pdf, rad], device=device)
    np.testing.assert_allclose(pdf.numpy(), [0.5 / 2.0 * 1.5 * math.sqrt(1.5), 0.0], rtol=1e-5)
    np.testing.assert_allclose(rad.numpy(), [L_SQUARE, [0.0, 0.0, 0.0]], rtol=1e-6)
    # from above, the same square shows its back: no radiance, same density
    wp.launch(_direction_pdf_kernel, 2, inputs=[ls, mesh.id, wp.vec3(0.0, 0.0, 2.0), wp.array(np.array([-d, d], np.float32), dtype=wp.vec3, device=device), pdf, rad], device=device)
    np.testing.assert_allclose(pdf.numpy(), [0.5 / 2.0 * 1.5 * math.sqrt(1.5), 0.0], rtol=1e-5)
    np.testing.assert_allclose(rad.numpy(), 0.0)


def _irradiance_case(device):
    ls = L.build_light_set(device, SQUARE, SQUARE_FACES, [0, 1], L_SQUARE,
                           point_lights=[L.PointLight(POINT_P, POINT_I)], environment=L.ConstantEnvironment(L_ENV), scene_radius=1.5)
    d = np.linalg.norm(POINT_P)
    exact = L_SQUARE * _square_irradiance(1.0, 1.0) + POINT_I * (POINT_P[2] / d) / d**2 + math.pi * L_ENV
    return ls, exact


def test_square_irradiance_closed_form_against_quadrature():
    import scipy.integrate

    val = scipy.integrate.dblquad(lambda y, x: 1.0 / (x * x + y * y + 1.0) ** 2, -1, 1, -1, 1)[0]  # cos² / r² with h = 1
    assert abs(_square_irradiance(1.0, 1.0) - val) < 1e-9


def test_irradiance_from_light_sampling_is_unbiased(device):
    ls, exact = _irradiance_case(device)
    s = _sample(ls, 400_000, device)
    c = s["contrib"].astype(np.float64)
    assert np.all(np.isfinite(c))
    result = z_test(c.mean(axis=0), c.std(axis=0, ddof=1) / math.sqrt(len(c)), exact, k=DEFAULT_K)
    assert result.passed, str(result)


def test_irradiance_without_the_light_cosine_is_caught(device):
    ls, exact = _irradiance_case(device)
    c = _sample(ls, 400_000, device)["contrib_no_cos"].astype(np.float64)
    result = z_test(c.mean(axis=0), c.std(axis=0, ddof=1) / math.sqrt(len(c)), exact)
    assert result.max_abs_z > BIASED_K, str(result)


def _envmap_irradiance_oracle(img, scale, rot, normal, n_theta=1200, n_phi=2400):
    """∫ L(ω) max(cos, 0) dω with Mitsuba's bilinear envmap written again in numpy (midpoint rule in θ, φ)."""
    h, w = img.shape[:2]
    theta = (np.arange(n_theta) + 0.5) / n_theta * np.pi
    phi = (np.arange(n_phi) + 0.5) / n_phi * 2 * np.pi
    t, p = np.meshgrid(theta, phi, indexing="ij")
    local = np.stack([np.sin(p) * np.sin(t), np.cos(t), -np.cos(p) * np.sin(t)], axis=-1)
    world = local @ rot.T
    u = np.mod(p / (2 * np.pi) - 0.5 / w, 1.0) * w
    v = t / np.pi * (h - 1)
    x0 = np.minimum(u.astype(int), w - 1)
    y0 = np.minimum(v.astype(int), h - 2)
    fx, fy = (u - x0)[..., None], (v - y0)[..., None]
    padded = np.concatenate([img, img[:, :1]], axis=1)
    rad = ((padded[y0, x0] * (1 - fx) + padded[y0, x0 + 1] * fx) * (1 - fy)
           + (padded[y0 + 1, x0] * (1 - fx) + padded[y0 + 1, x0 + 1] * fx) * fy) * scale
    cos = np.maximum(world @ np.asarray(normal, float), 0.0)[..., None]
    d_omega = (np.pi / n_theta) * (2 * np.pi / n_phi) * np.sin(t)[..., None]
    return (rad * cos * d_omega).sum(axis=(0, 1))


def test_envmap_irradiance_matches_numerical_integration(device):
    img, rot = _envmap_image(), _rot_y(30)
    normal = np.array([0.3, 0.8, -0.2])
    normal /= np.linalg.norm(normal)
    ls = L.build_light_set(device, np.zeros((3, 3)), np.array([[0, 1, 2]]), environment=L.EnvMap(img, scale=0.5, to_world=rot))
    s = _sample(ls, 200_000, device, normal=tuple(normal))
    c = s["contrib"].astype(np.float64)
    exact = _envmap_irradiance_oracle(img, 0.5, rot[:3, :3], normal)
    result = z_test(c.mean(axis=0), c.std(axis=0, ddof=1) / math.sqrt(len(c)), exact, k=DEFAULT_K)
    assert result.passed, str(result)


def test_constant_environment_gives_pi_l(device):
    ls = L.build_light_set(device, np.zeros((3, 3)), np.array([[0, 1, 2]]), environment=L.ConstantEnvironment(L_ENV), scene_radius=1.0)
    c = _sample(ls, 100_000, device)["contrib"].astype(np.float64)
    result = z_test(c.mean(axis=0), c.std(axis=0, ddof=1) / math.sqrt(len(c)), math.pi * L_ENV)
    assert result.passed, str(result)


# ---- selection and bad input ------------------------------------------------------------


def _selection_oracle(power, lights):
    """P(k) = ¼ Φ_k / ΣΦ + ¾ (1/G) Φ_k / Φ_light(k) (the module docstring's mixture), for parts k of lights ``lights``."""
    power = np.asarray(power, dtype=np.float64)
    light_power = {g: power[np.asarray(lights) == g].sum() for g in set(lights)}
    return np.array([0.25 * p / power.sum() + 0.75 / len(light_power) * p / light_power[g] for p, g in zip(power, lights)])


def test_selection_mixes_power_and_lights(device):
    """Two triangles of one square light, a point light and an environment: a quarter of the picks ∝ power, three
    quarters uniform over the three lights (the square's share split between its triangles ∝ power); a table ∝ power
    alone, which gives the dim point light 4% instead of 28%, is caught by the same χ²."""
    ls, _ = _irradiance_case(device)
    light = _sample(ls, 100_000, device)["light"]
    lum = np.array(L.LUMINANCE_WEIGHTS)
    power = np.array([math.pi * 2.0 * (L_SQUARE @ lum)] * 2 + [4 * math.pi * (POINT_I @ lum), math.pi * 1.5**2 * 4 * math.pi * (L_ENV @ lum)])
    assert ls.num_lights == 4 and ls.env_light == 3
    jitter = np.random.default_rng(0).random(light.size)
    result = chi2_test(light + jitter, _step_pdf(_selection_oracle(power, [0, 0, 1, 2])), 0.0, 4.0, bins=4)
    assert result.passed, str(result)
    result = chi2_test(light + jitter, _step_pdf(power / power.sum()), 0.0, 4.0, bins=4)  # BIASED: power alone
    assert not result.passed, str(result)


def test_no_lights_gives_invalid_samples(device):
    ls = L.build_light_set(device, np.zeros((3, 3)), np.array([[0, 1, 2]]))
    s = _sample(ls, 16, device)
    assert ls.num_lights == 0 and np.all(s["pdf"] == 0) and np.all(s["light"] == -1) and np.all(s["contrib"] == 0)


@pytest.mark.parametrize("kwargs, error, match", [
    ({"emitter_tris": [0], "emitter_radiance": [1.0, -1.0, 0.0]}, InvalidValueError, "emitter_radiance"),
    ({"emitter_tris": [0], "emitter_radiance": [1.0, np.nan, 0.0]}, InvalidValueError, "NaN"),
    ({"emitter_tris": [0], "emitter_radiance": np.ones((2, 3))}, InvalidParameterError, "emitter_radiance"),
    ({"emitter_tris": [5], "emitter_radiance": [1.0, 1.0, 1.0]}, InvalidParameterError, "emitter_tris"),
    ({"point_lights": [L.PointLight((0, 0, np.inf), 1.0)]}, InvalidValueError, "position"),
    ({"point_lights": [L.PointLight((0, 0, 1), -2.0)]}, InvalidValueError, "intensity"),
    ({"environment": L.ConstantEnvironment(-1.0)}, InvalidValueError, "radiance"),
    ({"environment": L.ConstantEnvironment(1.0), "scene_radius": 0.0}, InvalidParameterError, "scene_radius"),
    ({"environment": L.EnvMap(np.ones((2, 4, 3)))}, InvalidParameterError, "2x3"),
    ({"environment": L.EnvMap(np.full((4, 4, 3), np.nan))}, InvalidValueError, "NaN"),
    ({"environment": L.EnvMap(-np.ones((4, 4, 3)))}, InvalidValueError, "negative"),
    ({"environment": L.EnvMap(np.ones((4, 4, 3)), to_world=np.diag([2.0, 2.0, 2.0, 1.0]))}, InvalidParameterError, "rotation"),
    ({"environment": L.EnvMap("/nonexistent/sky.exr")}, InvalidParameterError, "no such file"),
])
def test_bad_input_is_named(kwargs, error, match):
    with pytest.raises(error, match=match):
        L.build_light_set("cpu", np.zeros((3, 3)), np.array([[0, 1, 2]]), **kwargs)


def test_envmap_reads_exr_files(tmp_path):
    from grisx.imageio import write_exr

    img = _envmap_image().astype(np.float32)
    write_exr(tmp_path / "sky.exr", img)
    np.testing.assert_allclose(L.load_envmap_image(tmp_path / "sky.exr"), img)


def test_envmap_reads_png_files_as_srgb(tmp_path):
    from PIL import Image

    Image.fromarray(np.full((4, 6, 3), 128, np.uint8)).save(tmp_path / "sky.png")
    np.testing.assert_allclose(L.load_envmap_image(tmp_path / "sky.png"), ((128 / 255 + 0.055) / 1.055) ** 2.4)


def test_lights_follow_geometry_moved_in_place(device):
    # the light set references the scene's position array: a rigid motion written into it moves the samples
    positions = wp.array(SQUARE.astype(np.float32), dtype=wp.vec3, device=device)
    ls = L.build_light_set(device, positions, SQUARE_FACES, [0, 1], L_SQUARE)
    positions.assign((SQUARE + [0.0, 0.0, 2.0]).astype(np.float32))
    s = _sample(ls, 1000, device)
    t = s["wi"][:, 2]
    assert np.all(t > 0)
    np.testing.assert_allclose(s["pdf_query"], s["pdf"], rtol=1e-5)
    # at height 3: p_ω = (pmf 1/2 / area 2) · d² / cos θ_y with d = 3 / cos θ_y, cos θ_y = wi_z
    np.testing.assert_allclose(s["pdf"], 0.25 * 9.0 / t**3, rtol=1e-4)


# ---- delta lights: directional, projector, textured spot ---------------------------------------------

#: a 3×2 image (sRGB 0/255 texels decode to 0/1); Mitsuba 3.9.1 read the same texels from a PNG
TEX3X2 = np.array([[[1, 0, 0], [0, 1, 0], [0, 0, 1]], [[1, 1, 0], [0, 1, 1], [1, 0, 1]]], dtype=np.float64)
#: Mitsuba's look_at(origin=(0.2, 0.1, 2), target=0, up=+y) for the projector and the spot
DELTA_FRAME_KEY = ((0.2, 0.1, 2.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0))
DELTA_REFS = np.array([(0.3, -0.2, 0.0), (-0.5, 0.4, 0.0), (0.1, 0.1, 0.5), (1.5, 0.2, 0.0), (0.0, -0.9, -0.5)])
#: a rectangle of side 6 at z = 0: Mitsuba's bounding sphere of radius √18 (a directional light's samples lie 2R away)
PLANE6 = np.array([[-3.0, -3.0, 0.0], [3.0, -3.0, 0.0], [3.0, 3.0, 0.0], [-3.0, 3.0, 0.0]])
PLANE6_FACES = np.array([[0, 1, 2], [0, 2, 3]])
#: Mitsuba 3.9.1 (scalar_rgb) emitter.sample_direction at DELTA_REFS: (direction, distance, weight = radiance / pdf, pdf)
MITSUBA_DELTA = {
    # projector: fov 60 (x), scale 2.5, irradiance TEX3X2
    "projector": [((-0.049386479, 0.14815943, 0.98772949), 2.0248458, (0.59648812, 1.2277664, 1.7184284), 1.0),
                  ((0.32708853, -0.14018081, 0.93453866), 2.1400933, (1.2488965, 0.73854893, 0.0082397452), 1.0),
                  ((0.066519015, 0.0, 0.99778515), 1.5033296, (0.11157265, 3.1929162, 1.4846897), 1.0),
                  ((-0.54451013, -0.041885395, 0.83770788), 2.3874671, (0.0, 0.0, 0.0), 0.0),
                  ((0.074074075, 0.37037036, 0.92592591), 2.7, (0.039342031, 1.2083477, 0.80244511), 1.0)],
    # spot: cutoff 40, beam 20, intensity (3, 2, 1), texture TEX3X2
    "spot": [((-0.049386479, 0.14815943, 0.98772949), 2.0248458, (0.19595613, 0.40676278, 0.067797825), 1.0),
             ((0.32708853, -0.14018081, 0.93453866), 2.1400933, (0.20953780, 0.24651334, 0.18562476), 1.0),
             ((0.066519015, 0.0, 0.99778515), 1.5033296, (0.078672037, 0.86184150, 0.23280744), 1.0),
             ((-0.54451013, -0.041885395, 0.83770788), 2.3874671, (0.020323535, 0.0056745214, 0.0035679378), 1.0),
             ((0.074074075, 0.37037036, 0.92592591), 2.7, (0.014329986, 0.26567504, 0.012194898), 1.0)],
    # directional: direction (0.3, −0.2, −1), irradiance (1, 2, 3)
    "directional": [((-0.28221628, 0.18814418, 0.94072086), 8.4860392, (1.0, 2.0, 3.0), 1.0)] * 5,
}


def _delta_light(kind):
    from grisx.scene.camera import lookat

    frame = lookat(*DELTA_FRAME_KEY)
    if kind == "projector":
        return L.Projector(to_world=frame, irradiance=TEX3X2, scale=2.5, fov=60.0)
    if kind == "spot":
        return L.PointLight(frame[:3, 3], (3.0, 2.0, 1.0), direction=frame[:3, 2], cutoff_angle=40.0, beam_width=20.0, texture=TEX3X2, to_world=frame)
    return L.DirectionalLight((0.3, -0.2, -1.0), (1.0, 2.0, 3.0))


@wp.kernel
def _delta_kernel(ls: L.LightSet, refs: wp.array(dtype=wp.vec3), wi: wp.array(dtype=wp.vec3), dist: wp.array(dtype=float),
                  radiance: wp.array(dtype=wp.vec3), pdf: wp.array(dtype=float), delta: wp.array(dtype=int), again: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    s = L.sample_light(ls, refs[i], 0.5, wp.vec2(0.3, 0.7))
    wi[i] = s.wi
    dist[i] = s.dist
    radiance[i] = s.radiance
    pdf[i] = s.pdf
    delta[i] = s.delta
    again[i] = L.delta_light_arrival(ls, 0, refs[i]).radiance  # what a renderer re-evaluates a stored sample with


@pytest.mark.parametrize("kind", ["projector", "spot", "directional"])
def test_delta_lights_match_mitsuba(device, kind):
    """Direction, distance, radiance and density of one sample at five points, against Mitsuba 3's sample_direction."""
    ls = L.build_light_set(device, PLANE6, PLANE6_FACES, point_lights=[_delta_light(kind)], scene_radius=math.sqrt(18.0), scene_center=(0, 0, 0))
    n = len(DELTA_REFS)
    out = [wp.zeros(n, dtype=t, device=device) for t in (wp.vec3, float, wp.vec3, float, int, wp.vec3)]
    wp.launch(_delta_kernel, n, inputs=[ls, wp.array(DELTA_REFS.astype(np.float32), dtype=wp.vec3, device=device), *out], device=device)
    wi, dist, radiance, pdf, delta, again = (o.numpy() for o in out)
    ref = MITSUBA_DELTA[kind]
    valid = np.array([r[3] > 0 for r in ref])
    np.testing.assert_allclose(wi[valid], [r[0] for r in ref if r[3] > 0], atol=2e-6)
    # a directional light's distance is 2R, R Mitsuba's bounding sphere (which pads the box by about 1e-4)
    np.testing.assert_allclose(dist[valid], [r[1] for r in ref if r[3] > 0], rtol=2e-4 if kind == "directional" else 2e-6)
    np.testing.assert_allclose(radiance, [r[2] for r in ref], rtol=2e-5, atol=1e-7)
    assert np.all(pdf == 1.0) and np.all(delta == 1)  # one light: chosen with probability 1, a delta
    np.testing.assert_allclose(again, radiance, rtol=1e-6)


@wp.kernel
def _intensity_kernel(ls: L.LightSet, k: int, center: wp.vec3, dirs: wp.array(dtype=wp.vec3), lum: wp.array(dtype=float)):
    i = wp.tid()
    a = L.delta_light_arrival(ls, k, center + dirs[i])  # at distance 1: the radiance is the intensity
    lum[i] = L.luminance(a.radiance)


def test_projector_power_is_the_integral_of_its_intensity(device):
    """The selection weight of a projector (π·scale·4 t_x t_y·mean lum) is ∫ lum I dω, by Monte Carlo over the sphere;
    a projector that forgot its 1/cos³θ (a point light of intensity π·scale·E) is caught by the same check."""
    light = _delta_light("projector")
    ls = L.build_light_set(device, PLANE6, PLANE6_FACES, point_lights=[light, L.PointLight((9.0, 9.0, 9.0), 1.0)], scene_radius=math.sqrt(18.0))
    n = 400_000
    rng = np.random.default_rng(SEED)
    z = rng.uniform(-1, 1, n)
    phi = rng.uniform(0, 2 * math.pi, n)
    dirs = np.stack([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z], axis=1)
    lum = wp.zeros(n, dtype=float, device=device)
    wp.launch(_intensity_kernel, n, inputs=[ls, 0, wp.vec3(*np.asarray(light.to_world)[:3, 3]), wp.array(dirs.astype(np.float32), dtype=wp.vec3, device=device), lum],
              device=device)
    f = lum.numpy().astype(np.float64) * 4 * math.pi
    tx = math.tan(math.radians(30.0))
    power = math.pi * 2.5 * 4 * tx * tx * 2 / 3 * float(np.mean(TEX3X2 @ np.array(L.LUMINANCE_WEIGHTS)))
    result = z_test(f.mean(), f.std(ddof=1) / math.sqrt(n), power, k=DEFAULT_K)
    assert result.passed, str(result)
    local = np.asarray(light.to_world)[:3, :3].T @ dirs.T
    cos3 = np.clip(local[2], 0, None) ** 3
    biased = f * cos3  # BIASED: I = π·scale·E(uv), no 1/cos³θ
    result = z_test(biased.mean(), biased.std(ddof=1) / math.sqrt(n), power, k=BIASED_K)
    assert not result.passed, str(result)


def test_delta_light_selection_follows_their_powers(device):
    """Directional (π R² lum E), projector (π·scale·4 t_x t_y·mean lum E) and textured spot (cone solid angle × lum I ×
    the texture's mean lum): their powers enter the selection mixture (χ² over the light index)."""
    lights = [_delta_light("directional"), _delta_light("projector"), _delta_light("spot")]
    ls = L.build_light_set(device, PLANE6, PLANE6_FACES, point_lights=lights, scene_radius=math.sqrt(18.0))
    lum = np.array(L.LUMINANCE_WEIGHTS)
    tex = float(np.mean(TEX3X2 @ lum))
    tx = math.tan(math.radians(30.0))
    power = np.array([math.pi * 18.0 * (np.array([1.0, 2.0, 3.0]) @ lum),
                      math.pi * 2.5 * 4 * tx * tx * 2 / 3 * tex,
                      2 * math.pi * (1 - math.cos(math.radians(40.0))) * (np.array([3.0, 2.0, 1.0]) @ lum) * tex])
    light = _sample(ls, 100_000, device)["light"]
    jitter = np.random.default_rng(0).random(light.size)
    result = chi2_test(light + jitter, _step_pdf(_selection_oracle(power, [0, 1, 2])), 0.0, 3.0, bins=3)
    assert result.passed, str(result)


def test_projector_irradiance_on_a_facing_plane_is_pi_scale_e_over_depth_squared(device):
    """Seen from a plane it faces at depth h, a projector gives E = π·scale·E_tex(uv) / h² (projector.cpp's 1/(z² cos θ)
    times the plane's cos θ): sampled among a point light and a directional light, the one-sample estimate of the
    irradiance at points across the frustum is within 4σ of the closed form."""
    from grisx.scene.camera import lookat

    h, scale = 2.0, 1.5
    proj = L.Projector(to_world=lookat((0.0, 0.0, h), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0)), irradiance=(0.8, 0.5, 0.2), scale=scale, fov=70.0)
    sun = L.DirectionalLight((0.0, 0.6, -0.8), (0.3, 0.2, 0.1))
    lamp = L.PointLight((0.5, 0.5, 1.0), (1.0, 2.0, 1.0))
    ls = L.build_light_set(device, PLANE6, PLANE6_FACES, point_lights=[proj, sun, lamp], scene_radius=math.sqrt(18.0))
    half = h * math.tan(math.radians(35.0))
    refs = np.array([(x, y, 0.0) for x in np.linspace(-0.9, 0.9, 4) * half for y in np.linspace(-0.9, 0.9, 4) * half])
    exact = []
    for r in refs:
        d = np.array([0.5, 0.5, 1.0]) - r
        exact.append(math.pi * scale * np.array([0.8, 0.5, 0.2]) / h**2 + 0.8 * np.array([0.3, 0.2, 0.1])
                     + np.array([1.0, 2.0, 1.0]) * d[2] / np.linalg.norm(d) ** 3)
    for r, e in zip(refs[::5], exact[::5]):
        c = _sample(ls, 20_000, device, ref=tuple(r))["contrib"].astype(np.float64)
        result = z_test(c.mean(axis=0), c.std(axis=0, ddof=1) / math.sqrt(len(c)), e, k=DEFAULT_K)
        assert result.passed, f"{r}: {result}"


# ---- textured area emitters (Mitsuba's area light with a bitmap radiance) ----------------------------------

TEX_ROW = np.array([[[1.0, 0.2, 0.1], [0.1, 0.5, 1.0]]])  # 1×2 texels: bilinear with wrap-around is a triangle wave in u
SQUARE_UV = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])  # u = (x + 1)/2, v = (y + 1)/2 on SQUARE


def _textured_square(device):
    return L.build_light_set(device, SQUARE, SQUARE_FACES, [0, 1], [1.0, 1.0, 1.0], emitter_textures=[TEX_ROW],
                             emitter_texture=[0, 0], emitter_uvs=SQUARE_UV[SQUARE_FACES])


def _tex_row(u):
    """Oracle: the 1×2 image bilinearly interpolated at u (texel centres at ¼ and ¾, wrapping)."""
    x = u * 2 - 0.5
    x0 = np.floor(x)
    f = (x - x0)[:, None]
    i0 = x0.astype(int) % 2
    return TEX_ROW[0][i0] * (1 - f) + TEX_ROW[0][(i0 + 1) % 2] * f


def _textured_square_irradiance(ref, mirror=False, n=1500):
    """Oracle: E = ∫ L(x, y) cos θ cos θ' / d² dA over SQUARE (z = 1) at ``ref`` with normal +z, by the midpoint rule."""
    t = (np.arange(n) + 0.5) / n * 2 - 1
    x, y = np.meshgrid(t, t, indexing="ij")
    h = 1.0 - ref[2]
    d2 = (x - ref[0]) ** 2 + (y - ref[1]) ** 2 + h * h
    w = (h * h / d2**2).ravel() * (2.0 / n) ** 2
    u = (x.ravel() + 1) / 2
    return (_tex_row(1 - u if mirror else u) * w[:, None]).sum(axis=0)


@wp.kernel
def _textured_sample_kernel(ls: L.LightSet, mesh: wp.uint64, ref: wp.vec3, seed: int, sampled: wp.array(dtype=wp.vec3), hit: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    k = random_key(seed, i)
    s = L.sample_light(ls, ref, random_uniform(k, 0), wp.vec2(random_uniform(k, 1), random_uniform(k, 2)))
    sampled[i] = s.radiance
    q = wp.mesh_query_ray(mesh, ref, s.wi, 1.0e6)
    if q.result:
        hit[i] = L.emitter_radiance(ls, q.face, ref + s.wi * q.t, q.normal, -s.wi)


def test_textured_emitter_radiance_is_its_image_at_the_uv(device):
    """The radiance a sample carries equals what a ray reaching the same point sees (barycentrics from the sample and
    from the hit point), and at texel centres it is the texel."""
    ls = _textured_square(device)
    mesh = wp.Mesh(points=wp.array(SQUARE.astype(np.float32), dtype=wp.vec3, device=device),
                   indices=wp.array(SQUARE_FACES.astype(np.int32).ravel(), dtype=wp.int32, device=device))
    n = 2000
    sampled, hit = wp.zeros(n, dtype=wp.vec3, device=device), wp.zeros(n, dtype=wp.vec3, device=device)
    wp.launch(_textured_sample_kernel, n, inputs=[ls, mesh.id, wp.vec3(0.3, -0.2, 0.0), SEED, sampled, hit], device=device)
    np.testing.assert_allclose(sampled.numpy(), hit.numpy(), rtol=1e-3, atol=1e-4)
    assert np.ptp(sampled.numpy()[:, 0]) > 0.5  # the image varies over the light
    # texel centres u = ¼, ¾ lie at x = −½, ½: straight above the reference points
    pdf, rad = wp.zeros(2, dtype=float, device=device), wp.zeros(2, dtype=wp.vec3, device=device)
    for x, texel in ((-0.5, TEX_ROW[0, 0]), (0.5, TEX_ROW[0, 1])):
        wp.launch(_direction_pdf_kernel, 1, inputs=[ls, mesh.id, wp.vec3(x, 0.3, 0.0), wp.array(np.array([[0, 0, 1]], np.float32), dtype=wp.vec3, device=device), pdf, rad],
                  device=device)
        np.testing.assert_allclose(rad.numpy()[0], texel, rtol=1e-5)


def test_textured_emitter_irradiance_matches_quadrature(device):
    """Light sampling of a textured square light: the irradiance estimate at an off-centre point is within 4σ of the
    midpoint-rule integral of the bilinear image; the same light with its image mirrored in u (an orientation bug)
    is beyond 6σ."""
    ls = _textured_square(device)
    ref = (0.6, 0.2, 0.0)
    c = _sample(ls, 100_000, device, ref=ref)["contrib"].astype(np.float64)
    mean, se = c.mean(axis=0), c.std(axis=0, ddof=1) / math.sqrt(len(c))
    result = z_test(mean, se, _textured_square_irradiance(ref), k=DEFAULT_K)
    assert result.passed, str(result)
    result = z_test(mean, se, _textured_square_irradiance(ref, mirror=True), k=BIASED_K)
    assert not result.passed, str(result)
