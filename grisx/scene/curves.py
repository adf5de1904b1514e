"""Mitsuba 3's ``linearcurve`` shape: round linear curves, read as a fine triangle mesh.

Mitsuba's ``linearcurve`` [Mitsuba3] reads curves from a text file, one control
point per line (``x y z radius``), an empty line between curves; ``to_world``
maps the positions and leaves the radii as they are. Each segment between two
control points p₀, p₁ (radii r₀, r₁) is the envelope of the spheres centred on
the segment with linearly interpolated radii — a cone frustum tangent to the
spheres at its ends — and every control point carries its sphere, so segments
join smoothly and curves end in round caps (Embree's round linear curves).

**Parametrization and normals, as ``linearcurve.cpp``.** A hit's normal is
p − c, c = (1 − v)p₀ + v p₁ the centre of the sphere it lies on (v ∈ [0, 1]
along the segment); on the envelope n = sin β d + cos β e(φ) with d the unit
segment direction, sin β = (r₀ − r₁)/|p₁ − p₀| and e(φ) = cos φ u_rad + sin φ
u_rot in Mitsuba's ``local_frame(d)`` (u_rot: the unit part of +z orthogonal
to d, or +y where d = ±z; u_rad = u_rot × d). uv = (φ/2π, (v + i)/N) for
segment i of N.

grisx tessellates that surface. The frustum is ruled (position, normal and uv
are linear along it), so two rings of ``around`` vertices each are exact up to
the polygon around the axis (distance ≤ r (1 − cos(π/around)), 1.2·10⁻³ r at the
default 64); each control point's sphere is a UV sphere in its segment's frame
(a joint takes the frame and v = 1 of the segment that ends there, the first
point of a curve v = 0 of the one that starts there), uv as on the frustum.
Where one sphere holds the other (|r₀ − r₁| ≥ |p₁ − p₀|) the segment is its
spheres alone.

References
----------
[Mitsuba3] W. Jakob et al., Mitsuba 3, ``src/shapes/linearcurve.cpp`` and the plugin reference
           "Linear curve", https://mitsuba.readthedocs.io (2022); Embree's ``RTC_GEOMETRY_TYPE_ROUND_LINEAR_CURVE``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from grisx.errors import GrisxError
from grisx.scene.shapes import MeshData, sphere

__all__ = ["read_curves", "local_frame", "linear_curve_mesh"]


def read_curves(path: str | os.PathLike) -> list[np.ndarray]:
    """Mitsuba's curve file: a list of (n, 4) arrays (x, y, z, radius), one per curve of at least two points."""
    path = Path(path)
    if not path.is_file():
        raise GrisxError(f"cannot read curves '{path}': no such file")
    curves: list[list[list[float]]] = [[]]
    for lineno, line in enumerate(path.read_text(errors="replace").splitlines(), start=1):
        parts = line.split()
        if not parts:
            if curves[-1]:
                curves.append([])
            continue
        try:
            values = [float(x) for x in parts[:4]]
        except ValueError:
            values = []
        if len(values) != 4 or not np.all(np.isfinite(values)):
            raise GrisxError(f"cannot read curves '{path}': line {lineno}: expected 'x y z radius', got '{line.strip()}'")
        curves[-1].append(values)
    curves = [c for c in curves if c]
    if not curves:
        raise GrisxError(f"cannot read curves '{path}': no control points")
    if any(len(c) < 2 for c in curves):
        raise GrisxError(f"cannot read curves '{path}': a linear curve needs at least two control points")
    return [np.asarray(c, dtype=np.float64) for c in curves]


def local_frame(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mitsuba's ``local_frame`` of a unit direction ``d``: (u_rot, u_rad)."""
    guide = np.array([0.0, 0.0, 1.0])
    if abs(float(d @ guide)) == 1.0:
        rot = np.array([0.0, 1.0, 0.0])
    else:
        rot = guide - d * float(d @ guide)
        rot /= np.linalg.norm(rot)
    return rot, np.cross(rot, d)


def linear_curve_mesh(curves: list[np.ndarray], to_world: np.ndarray | None = None, around: int = 64, rings: int = 32) -> MeshData:
    """The curves' surface (module docstring) as a world-space mesh: ``to_world`` maps the control points only."""
    m = np.eye(4) if to_world is None else np.asarray(to_world, dtype=np.float64)
    n_segments = sum(len(c) - 1 for c in curves)
    unit = sphere(segments=around, rings=rings)  # unit sphere, poles on ±z, uv.x = φ/2π with φ = atan2(y, x)
    verts, norms, uvs, faces = [], [], [], []
    count = 0

    def add(v: np.ndarray, n: np.ndarray, uv: np.ndarray, f: np.ndarray) -> None:
        nonlocal count
        verts.append(v)
        norms.append(n)
        uvs.append(uv)
        faces.append(f + count)
        count += len(v)

    phi = np.linspace(0.0, 2.0 * np.pi, around + 1)
    k = np.arange(around)
    seg = 0
    for c in curves:
        p = c[:, :3] @ m[:3, :3].T + m[:3, 3]
        r = c[:, 3]
        for j in range(len(c) - 1):
            d = p[j + 1] - p[j]
            length = float(np.linalg.norm(d))
            if not length > 0.0:
                raise GrisxError("a linear curve has two equal consecutive control points")
            d /= length
            rot, rad = local_frame(d)
            frame = np.stack([rad, rot, d], axis=1)  # local (x, y, z) = (u_rad, u_rot, d)
            # the control points' spheres: the first point of the curve at v = 0, every end at v = 1
            ends = [(j + 1, 1.0)] if j > 0 else [(j, 0.0), (j + 1, 1.0)]
            for i, v in ends:
                add(p[i] + abs(r[i]) * (unit.vertices @ frame.T), unit.vertices @ frame.T,
                    np.column_stack([unit.uvs[:, 0], np.full(len(unit.uvs), (v + seg) / n_segments)]), unit.faces)
            sin_b = (r[j] - r[j + 1]) / length
            if abs(sin_b) < 1.0:  # the frustum tangent to both spheres
                cos_b = np.sqrt(1.0 - sin_b**2)
                e = np.cos(phi)[:, None] * rad + np.sin(phi)[:, None] * rot
                n = sin_b * d + cos_b * e
                v = np.concatenate([p[j] + r[j] * n, p[j + 1] + r[j + 1] * n])
                uv = np.concatenate([np.column_stack([phi / (2 * np.pi), np.full(around + 1, seg / n_segments)]),
                                     np.column_stack([phi / (2 * np.pi), np.full(around + 1, (seg + 1) / n_segments)])])
                a, b = k, around + 1 + k  # ring 0 and ring 1, column k
                f = np.concatenate([np.stack([a, a + 1, b + 1], -1), np.stack([a, b + 1, b], -1)])
                add(v, np.concatenate([n, n]), uv, f)
            seg += 1
    vertices, normals = np.concatenate(verts), np.concatenate(norms)
    faces = np.concatenate(faces).astype(np.int64)
    # every triangle faces along its vertices' normals (outward)
    ng = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]])
    flip = np.einsum("ij,ij->i", ng, normals[faces].sum(axis=1)) < 0
    faces[flip] = faces[flip][:, [0, 2, 1]]
    return MeshData(vertices, faces, normals, np.concatenate(uvs))
