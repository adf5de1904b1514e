"""Shift maps: inverse round trips, Jacobians against finite differences, partial bijections, Eq. 11."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from grisx.theory.batch import reconnection_jacobians
from grisx.theory.toys.shifts import MAP_KINDS, PARTIAL_U_MAX, apply_pixel_shift

KINDS = range(len(MAP_KINDS))
FULL = [k for k in KINDS if MAP_KINDS[k] != "partial"]


def _domain_samples(kind: int, n: int = 2000) -> np.ndarray:
    u = np.linspace(0.001, (PARTIAL_U_MAX if MAP_KINDS[kind] == "partial" else 1.0) - 0.001, n)
    return apply_pixel_shift(0, kind, u)["x"]  # φ_kind(u) via the identity pixel


@pytest.mark.parametrize("src", KINDS)
@pytest.mark.parametrize("dst", KINDS)
def test_inverse_round_trip(src, dst):
    x = _domain_samples(src)
    fwd = apply_pixel_shift(src, dst, x)
    back = apply_pixel_shift(dst, src, fwd["x"][fwd["valid"]])
    assert np.all(back["valid"])
    np.testing.assert_allclose(back["x"], x[fwd["valid"]], atol=2e-5)
    np.testing.assert_allclose(back["jacobian"] * fwd["jacobian"][fwd["valid"]], 1.0, rtol=1e-4)


@pytest.mark.parametrize("src", KINDS)
@pytest.mark.parametrize("dst", KINDS)
def test_jacobian_matches_finite_differences(src, dst):
    x = _domain_samples(src, 400)[5:-5]
    h = 1e-3
    plus, minus, mid = (apply_pixel_shift(src, dst, x + d) for d in (h, -h, 0.0))
    ok = plus["valid"] & minus["valid"] & mid["valid"]
    fd = (plus["x"][ok].astype(np.float64) - minus["x"][ok]) / (2 * h)
    np.testing.assert_allclose(mid["jacobian"][ok], np.abs(fd), rtol=5e-3)


@pytest.mark.parametrize("src", FULL)
def test_partial_bijection_fails_exactly_where_undefined(src):
    u = np.linspace(0.0, 1.0, 1001)
    x = apply_pixel_shift(0, src, u)["x"]
    valid = apply_pixel_shift(src, MAP_KINDS.index("partial"), x)["valid"]
    assert np.array_equal(valid, u <= PARTIAL_U_MAX + 1e-6) or np.mean(valid != (u <= PARTIAL_U_MAX)) < 2e-3


def test_reconnection_jacobian_hand_computed_3d():
    # seed 004, Eq. 11: x2 = (0,0,1) facing down; source x1 straight below, destination at (1,0,0)
    j = reconnection_jacobians([[0, 0, 0]], [[1, 0, 0]], [[0, 0, 1]], [[0, 0, -1]])
    # cos φ^r = 1/√2, cos φ^q = 1, distances² 1 and 2 → (1/√2) · (1/2)
    np.testing.assert_allclose(j, [0.5 / np.sqrt(2)], rtol=1e-6)


def _cross2(a: np.ndarray, b: np.ndarray) -> float:
    return float(a[0] * b[1] - a[1] * b[0])


def _flatland_angle(x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    d = x2 - x1
    return np.arctan2(d[..., 0], d[..., 1])


@settings(max_examples=40, deadline=None)
@given(
    st.floats(-1.0, 1.0), st.floats(-1.0, 1.0), st.floats(-1.0, 1.0), st.floats(0.5, 2.0), st.floats(-0.6, 0.6)
)
def test_flatland_reconnection_jacobian_matches_finite_differences(xq, xr, s, height, tilt):
    """|dθ_r/dθ_q| for a sample point moving along a tilted line: Eq. 11 with n = 2."""
    x1q, x1r = np.array([xq, 0.0]), np.array([xr, 0.0])
    a = np.array([s, height])
    tangent = np.array([np.cos(tilt), np.sin(tilt)])
    normal = np.array([tangent[1], -tangent[0]])

    def point_along_ray(theta: float) -> np.ndarray:
        # the sample point where q's ray at angle θ meets the line through a
        d = np.array([np.sin(theta), np.cos(theta)])
        t = _cross2(a - x1q, tangent) / _cross2(d, tangent)
        return x1q + t * d

    theta = _flatland_angle(x1q, a)
    h = 1e-6
    fd = (_flatland_angle(x1r, point_along_ray(theta + h)) - _flatland_angle(x1r, point_along_ray(theta - h))) / (2 * h)
    j = reconnection_jacobians([x1q], [x1r], [a], [normal])[0]
    np.testing.assert_allclose(j, abs(fd), rtol=2e-3)
