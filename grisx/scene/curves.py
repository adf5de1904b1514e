"""Mitsuba 3's ``linearcurve`` and ``bsplinecurve`` shapes, read as fine triangle meshes.

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

**B-spline curves** (``bsplinecurve``, at least four control points per curve):
each segment i (control points i … i + 3, v ∈ [0, 1]) follows the uniform cubic
B-spline c(v) with the radius r(v) interpolated alike. Mitsuba 3.9.1's hits on
it lie on the circle of radius r(v) about c(v) in the plane normal to c'(v), at
the v it reports (measured: |p − c| − r and (p − c)·c' vanish to 10⁻⁶), so
grisx tessellates that tube (``steps`` rings per segment): uv as for linear
curves, normals as ``bsplinecurve.cpp`` computes them, n ∝ (|c'|² − (p − c)·c'')
(p − c) − r r' c'. Its ends are open (no caps), and Mitsuba culls its inner
side, which grisx does not: looking into an open end shows the inside here
(what the conformance case ``bsplinecurve`` keeps out of its frame).

References
----------
[Mitsuba3] W. Jakob et al., Mitsuba 3, ``src/shapes/{linear,bspline}curve.cpp`` and the plugin reference
           "Linear curve", https://mitsuba.readthedocs.io (2022); Embree's ``RTC_GEOMETRY_TYPE_ROUND_LINEAR_CURVE``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from grisx.errors import GrisxError
from grisx.scene.shapes import MeshData, sphere

__all__ = ["read_curves", "local_frame", "linear_curve_mesh", "bspline_curve_mesh"]


def read_curves(path: str | os.PathLike, min_points: int = 2) -> list[np.ndarray]:
    """Mitsuba's curve file: a list of (n, 4) arrays (x, y, z, radius), one per curve of at least ``min_points``
    points (a linear curve needs two, a B-spline curve four)."""
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
    if any(len(c) < min_points for c in curves):
        kind = "a linear curve needs at least two" if min_points == 2 else f"a B-spline curve needs at least {min_points}"
        raise GrisxError(f"cannot read curves '{path}': {kind} control points")
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


def _outward(verts: list, norms: list, uvs: list, faces: list) -> MeshData:
    """The pieces as one mesh, every triangle wound to face along its vertices' normals (outward)."""
    vertices, normals = np.concatenate(verts), np.concatenate(norms)
    f = np.concatenate(faces).astype(np.int64)
    ng = np.cross(vertices[f[:, 1]] - vertices[f[:, 0]], vertices[f[:, 2]] - vertices[f[:, 0]])
    flip = np.einsum("ij,ij->i", ng, normals[f].sum(axis=1)) < 0
    f[flip] = f[flip][:, [0, 2, 1]]
    return MeshData(vertices, f, normals, np.concatenate(uvs))


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
    return _outward(verts, norms, uvs, faces)


#: the uniform cubic B-spline basis (rows: the weights of p₀..p₃ as polynomials in v, constant term first) ×6
_BSPLINE = np.array([[1, -3, 3, -1], [4, 0, -6, 3], [1, 3, 3, -3], [0, 0, 0, 1]], dtype=np.float64) / 6.0


def _bspline(points: np.ndarray, v: np.ndarray, order: int = 0) -> np.ndarray:
    """The cubic B-spline of the four ``points`` (4, k) at ``v`` (m,), or its ``order``-th derivative, as
    ``bsplinecurve.cpp``'s ``cubic_interpolation``."""
    coeff = _BSPLINE
    for _ in range(order):
        coeff = coeff[:, 1:] * np.arange(1, coeff.shape[1])
    powers = np.stack([v**k for k in range(coeff.shape[1])], axis=1)
    return (powers @ coeff.T) @ points


def bspline_curve_mesh(curves: list[np.ndarray], to_world: np.ndarray | None = None, around: int = 64, steps: int = 32) -> MeshData:
    """Mitsuba's ``bsplinecurve`` as a world-space mesh: each cubic segment (control points i … i + 3, v ∈ [0, 1])
    is the tube of circles of radius r(v) about c(v) in the planes normal to c'(v) — where Mitsuba 3.9.1's hits
    lie, |p − c(v)| = r(v) and (p − c(v))·c'(v) = 0 at the v it reports — open at the curve's ends (no caps).
    uv = (φ/2π, (v + i)/N) with φ the angle in ``local_frame(c'(v))``; normals as ``bsplinecurve.cpp``:
    n ∝ (|c'|² − (p − c)·c'')(p − c) − r r' c'. Mitsuba culls the tubes' inner sides, grisx does not: looking
    into an open end shows the inside here."""
    m = np.eye(4) if to_world is None else np.asarray(to_world, dtype=np.float64)
    n_segments = sum(len(c) - 3 for c in curves)
    phi = np.linspace(0.0, 2.0 * np.pi, around + 1)
    v = np.linspace(0.0, 1.0, steps + 1)
    verts, norms, uvs, faces = [], [], [], []
    count, seg = 0, 0
    for curve in curves:
        p = np.column_stack([curve[:, :3] @ m[:3, :3].T + m[:3, 3], curve[:, 3]])  # radii as they are
        for i in range(len(curve) - 3):
            cp = p[i:i + 4]
            c, r = _bspline(cp[:, :3], v), _bspline(cp[:, 3:], v)[:, 0]
            dc, dr = _bspline(cp[:, :3], v, 1), _bspline(cp[:, 3:], v, 1)[:, 0]
            ddc = _bspline(cp[:, :3], v, 2)
            if np.any(np.linalg.norm(dc, axis=1) == 0):
                raise GrisxError("a B-spline curve's tangent vanishes (repeated control points)")
            frames = [local_frame(t / np.linalg.norm(t)) for t in dc]
            rot = np.array([f[0] for f in frames])[:, None, :]
            rad = np.array([f[1] for f in frames])[:, None, :]
            e = np.cos(phi)[None, :, None] * rad + np.sin(phi)[None, :, None] * rot  # (steps+1, around+1, 3)
            radial = r[:, None, None] * e
            pos = c[:, None, :] + radial
            correction = np.einsum("vak,vk->va", radial, ddc)
            normal = (np.einsum("vk,vk->v", dc, dc)[:, None] - correction)[..., None] * radial - (dr * r)[:, None, None] * dc[:, None, :]
            normal /= np.maximum(np.linalg.norm(normal, axis=2, keepdims=True), 1e-300)
            uv = np.stack(np.broadcast_arrays(phi[None, :] / (2 * np.pi), ((v + seg) / n_segments)[:, None]), axis=-1)
            a = (np.arange(steps)[:, None] * (around + 1) + np.arange(around)[None, :]).reshape(-1)
            b, a1, b1 = a + around + 1, a + 1, a + around + 2  # the next ring, the next column
            verts.append(pos.reshape(-1, 3))
            norms.append(normal.reshape(-1, 3))
            uvs.append(uv.reshape(-1, 2))
            faces.append(np.concatenate([np.stack([a, a1, b1], -1), np.stack([a, b1, b], -1)]) + count)
            count += pos.shape[0] * pos.shape[1]
            seg += 1
    return _outward(verts, norms, uvs, faces)
