"""4×4 affine transforms with Mitsuba's conventions (column vectors, angles in degrees).

``translate(v) @ rotate(axis, angle) @ scale(s)`` applies the scale first,
as Mitsuba's ``to_world`` chains do. ``lookat`` lives in
:mod:`grisx.scene.camera` (the sensor frame is a camera concept).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from grisx.errors import InvalidParameterError

__all__ = ["translate", "rotate", "scale", "compose", "to_frame"]


def translate(v: Sequence[float]) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = np.asarray(v, dtype=np.float64).reshape(3)
    return m


def rotate(axis: Sequence[float], angle: float) -> np.ndarray:
    """Counter-clockwise rotation by ``angle`` degrees about ``axis``, exactly as Mitsuba 3's ``rotate``.

    The matrix is cos θ·I + sin θ·[a]ₓ + (1 − cos θ)·a aᵀ with the axis ``a`` *as given*:
    Mitsuba does not normalize it, so a non-unit axis (``x="1" y="1"``) also scales and
    shears, and a scene file that relies on that must render the same here.
    """
    a = np.asarray(axis, dtype=np.float64).reshape(3)
    n = np.linalg.norm(a)
    if not np.isfinite(n) or n == 0:
        raise InvalidParameterError(f"rotate: axis must be a non-zero vector, got {a.tolist()}")
    t = math.radians(angle)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    m = np.eye(4)
    m[:3, :3] = math.cos(t) * np.eye(3) + math.sin(t) * k + (1 - math.cos(t)) * np.outer(a, a)
    return m


def scale(s: float | Sequence[float]) -> np.ndarray:
    v = np.broadcast_to(np.asarray(s, dtype=np.float64), (3,))
    return np.diag([*v, 1.0])


def compose(*ms: np.ndarray) -> np.ndarray:
    """m₁ @ m₂ @ … (the rightmost applies first)."""
    out = np.eye(4)
    for m in ms:
        out = out @ m
    return out


def to_frame(n: Sequence[float]) -> np.ndarray:
    """Mitsuba 3's ``Transform4f.to_frame(Frame3f(n))``: local (x, y, z) → s x + t y + n z for the unit
    ``n`` and the tangents s, t of Mitsuba's ``coordinate_system`` (Duff et al. 2017, "Building an
    Orthonormal Basis, Revisited"), so that a shape's local φ = 0 lies where Mitsuba's does."""
    n = np.asarray(n, dtype=np.float64).reshape(3)
    sign = 1.0 if n[2] >= 0.0 else -1.0
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    s_ = np.array([n[0] * n[0] * a * sign + 1.0, b * sign, -n[0] * sign])
    t_ = np.array([b, sign + n[1] * n[1] * a, -n[1]])
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2] = s_, t_, n
    return m
