"""Mitsuba 3's ``sdfgrid`` shape: a signed distance field on a grid, read as a fine triangle mesh of its zero set.

Mitsuba's ``sdfgrid`` [Mitsuba3] samples a signed distance function f on an
``X × Y × Z`` grid over object space [0, 1]³ (grid point (i, j, k) at
(i/(X−1), j/(Y−1), k/(Z−1)); negative inside) and renders the zero set of its
**trilinear interpolant**, intersected voxel by voxel. Its geometric normal is
the gradient of that interpolant in the voxel, ∇f; its shading normal is the
same (``normals="analytic"``) or, by default (``"smooth"``), the blend of the
eight neighbouring voxels' finite-difference gradients of Hansson-Söderlund
et al. [HEA22] (``smooth_sh`` in ``sdfgrid.cpp``). It has no uv (uv = (0, 0)
everywhere) and cannot emit.

grisx intersects triangles, so :func:`sdfgrid_mesh` tessellates that surface:
every voxel the zero set crosses (its corners change sign) is subdivided into
``subdivisions``³ cells, f is evaluated exactly at the cells' corners (it is
trilinear inside the voxel), and marching tetrahedra (six per cell, split
along the main diagonal) extract the zero set of the piecewise-linear
interpolant of those samples, vertices shared between neighbouring cells.
Along the axis-aligned cell edges f is linear, so vertices there lie exactly on
Mitsuba's surface; on the diagonals they deviate by O((h/s)²) for voxel size h
and s subdivisions: with the default s = 4 the largest |f|/|∇f| at a vertex is
0.006 voxels on the tests' 24³ torus and on mitsuba-data's 40³ one
(``test_sdfgrid.py``; s = 1 is caught by the conformance case ``sdfgrid``).
Vertex normals are Mitsuba's shading normals evaluated at the vertices
(interpolated in between; :class:`SdfGrid` agrees with Mitsuba 3.9.1's to
float32 precision at its own hit points); triangles face along ∇f (outward).
What it costs: 102k triangles for the 24³ torus, 222k for the 40³ one (1.4 s
to build on one CPU core), where Mitsuba stores the grid.

Mitsuba 3.9.1's LLVM variant renders almost nothing of an ``sdfgrid`` whose
own ``to_world`` rotates it (inside an ``instance`` it renders as meant, which
is how mitsuba-data's files place theirs); grisx renders both as meant.

The grid file is Mitsuba's binary volume format (``VOL``, version 3, float32
data with x fastest, one channel), :func:`read_vol`.

References
----------
[Mitsuba3] W. Jakob et al., Mitsuba 3, ``src/shapes/sdfgrid.cpp`` and the "Grid-based volume data source"
           file format (``gridvolume``), https://mitsuba.readthedocs.io (2022).
[HEA22] H. Hansson-Söderlund, A. Evans, T. Akenine-Möller, "Ray Tracing of Signed Distance Function Grids",
        JCGT 11(3), 94-113 (2022).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from grisx.errors import GrisxError
from grisx.scene.shapes import MeshData

__all__ = ["read_vol", "SdfGrid", "sdfgrid_mesh"]


def read_vol(path: str | os.PathLike) -> np.ndarray:
    """A Mitsuba ``.vol`` grid as a float64 array indexed ``[z, y, x]`` (one channel: an SDF grid's)."""
    path = Path(path)
    if not path.is_file():
        raise GrisxError(f"cannot read SDF grid '{path}': no such file")
    raw = path.read_bytes()
    if len(raw) < 48 or raw[:3] != b"VOL" or raw[3] != 3:
        raise GrisxError(f"cannot read SDF grid '{path}': not a Mitsuba volume file (VOL, version 3)")
    encoding, xres, yres, zres, channels = np.frombuffer(raw[4:24], dtype="<i4")
    if encoding != 1:
        raise GrisxError(f"cannot read SDF grid '{path}': encoding {encoding} (only 1, float32, is supported)")
    if channels != 1:
        raise GrisxError(f"cannot read SDF grid '{path}': {channels} channels (an SDF grid has one)")
    if min(xres, yres, zres) < 2:
        raise GrisxError(f"cannot read SDF grid '{path}': resolution {xres}x{yres}x{zres} (at least 2 per axis)")
    count = int(xres) * int(yres) * int(zres)
    data = np.frombuffer(raw[48:], dtype="<f4")
    if data.size != count:
        raise GrisxError(f"cannot read SDF grid '{path}': {data.size} values for a {xres}x{yres}x{zres} grid")
    if not np.all(np.isfinite(data)):
        raise GrisxError(f"cannot read SDF grid '{path}': NaN or Inf values")
    return data.astype(np.float64).reshape(int(zres), int(yres), int(xres))


class SdfGrid:
    """The trilinear interpolant f of a grid ``values[z, y, x]`` over [0, 1]³ and Mitsuba's normals of its zero set."""

    def __init__(self, values: np.ndarray):
        self.values = np.asarray(values, dtype=np.float64)
        self.res = np.array(self.values.shape[::-1])  # (X, Y, Z)
        self.voxel = 1.0 / (self.res - 1)

    def eval(self, p: np.ndarray) -> np.ndarray:
        """f at object-space points ``p`` (..., 3): trilinear between grid points, clamped at the border (Mitsuba's
        grid texture, its texels at the grid points)."""
        g = np.clip(np.asarray(p, dtype=np.float64) * (self.res - 1), 0.0, self.res - 1)
        i0 = np.minimum(np.floor(g).astype(np.int64), self.res - 2)
        t = g - i0
        v = self.values
        out = 0.0
        for dz in (0, 1):
            for dy in (0, 1):
                for dx in (0, 1):
                    w = (t[..., 0] if dx else 1 - t[..., 0]) * (t[..., 1] if dy else 1 - t[..., 1]) * (t[..., 2] if dz else 1 - t[..., 2])
                    out = out + w * v[i0[..., 2] + dz, i0[..., 1] + dy, i0[..., 0] + dx]
        return out

    def voxel_grad(self, p: np.ndarray, voxel: np.ndarray) -> np.ndarray:
        """``voxel_grad``: f's finite differences across the faces of ``voxel`` (integer (x, y, z)) through ``p``'s
        other coordinates; inside that voxel, the exact gradient of the interpolant."""
        h = self.voxel
        lo = voxel * h
        out = np.empty(np.broadcast_shapes(p.shape, voxel.shape))
        for a in range(3):
            hi_p, lo_p = np.array(p, dtype=np.float64, copy=True), np.array(p, dtype=np.float64, copy=True)
            hi_p = np.broadcast_to(hi_p, out.shape).copy()
            lo_p = np.broadcast_to(lo_p, out.shape).copy()
            hi_p[..., a] = lo[..., a] + h[a]
            lo_p[..., a] = lo[..., a]
            out[..., a] = (self.eval(hi_p) - self.eval(lo_p)) / h[a]
        return out

    def grad(self, p: np.ndarray) -> np.ndarray:
        """``sdf_grad``: the interpolant's gradient in the voxel that holds ``p`` (Mitsuba's geometric normal)."""
        voxel = np.floor(np.asarray(p) * (self.res - 1)).astype(np.int64)
        return self.voxel_grad(p, voxel)

    def smooth_normal(self, p: np.ndarray) -> np.ndarray:
        """``smooth_sh``: the eight voxels around the grid point nearest ``p``, their unit gradients blended
        trilinearly (voxels with a negative index left out, their axis weight moved to the others) [HEA22]."""
        scaled = np.asarray(p, dtype=np.float64) * (self.res - 1)
        v111 = np.round(scaled).astype(np.int64)  # the nearest grid point; v000 = v111 − 1
        w = scaled - v111 + 0.5
        normals, valid = {}, {}
        for c in np.ndindex(2, 2, 2):
            v = v111 - 1 + np.array(c)
            ok = np.all(v >= 0, axis=-1)
            g = self.voxel_grad(scaled * self.voxel, v)
            n = g / np.maximum(np.linalg.norm(g, axis=-1, keepdims=True), 1e-300)
            normals[c], valid[c] = np.where(ok[..., None], n, 0.0), ok
        for a in range(3):  # an axis side whose four voxels are all invalid: the weight goes to the other side
            side = [lambda c, s=s: c[a] == s for s in (0, 1)]
            none0 = ~np.any([valid[c] for c in valid if side[0](c)], axis=0)
            none1 = ~np.any([valid[c] for c in valid if side[1](c)], axis=0)
            w[..., a] = np.where(none0, 1.0, np.where(none1, 0.0, w[..., a]))
        out = 0.0
        for c, n in normals.items():
            weight = np.prod([w[..., a] if c[a] else 1 - w[..., a] for a in range(3)], axis=0)
            out = out + weight[..., None] * n
        return out


# Kuhn's six tetrahedra of the unit cube (corner k = x + 2y + 4z), all sharing the diagonal 0 → 7
_TETS = np.array([[0, 1, 3, 7], [0, 3, 2, 7], [0, 2, 6, 7], [0, 6, 4, 7], [0, 4, 5, 7], [0, 5, 1, 7]])
_CORNERS = np.array([[k & 1, (k >> 1) & 1, (k >> 2) & 1] for k in range(8)])


def sdfgrid_mesh(values: np.ndarray, normals: str = "smooth", subdivisions: int = 4) -> MeshData:
    """The zero set of the grid's trilinear interpolant as an object-space triangle mesh (module docstring): faces
    wound along ∇f, Mitsuba's shading normals (``"smooth"`` or ``"analytic"``) at the vertices, uv = (0, 0)."""
    if normals not in ("smooth", "analytic"):
        raise GrisxError(f"sdfgrid normals must be 'smooth' or 'analytic', got {normals!r}")
    grid = SdfGrid(values)
    v = grid.values
    s = int(subdivisions)
    # voxels whose corners change sign (the interpolant lies between its corner values)
    corners = np.stack([v[cz:v.shape[0] - 1 + cz, cy:v.shape[1] - 1 + cy, cx:v.shape[2] - 1 + cx] for cx, cy, cz in _CORNERS], -1)
    active = np.argwhere((corners.min(-1) <= 0) & (corners.max(-1) > 0))[:, ::-1]  # (x, y, z) voxel indices
    if len(active) == 0:
        raise GrisxError("the SDF grid has no zero crossing: its surface is empty")
    # fine sample points of each active voxel: (S+1)^3 per voxel, f exact (trilinear) there
    ax = np.arange(s + 1)
    sub = np.stack(np.meshgrid(ax, ax, ax, indexing="ij"), -1).reshape(-1, 3)  # (a, b, c) along (x, y, z)
    fine = active[:, None, :] * s + sub[None, :, :]  # fine grid coordinates, (V, P, 3)
    dims = (grid.res - 1) * s + 1
    point_id = (fine[..., 2] * dims[1] + fine[..., 1]) * dims[0] + fine[..., 0]
    p_obj = fine / ((grid.res - 1) * s)
    f = grid.eval(p_obj)
    # cells of each voxel and their tetrahedra: point index within the voxel's (S+1)^3 block
    cell = np.stack(np.meshgrid(np.arange(s), np.arange(s), np.arange(s), indexing="ij"), -1).reshape(-1, 3)
    cell_corner = cell[:, None, :] + _CORNERS[None, :, :]  # (C, 8, 3)
    local = (cell_corner[..., 0] * (s + 1) + cell_corner[..., 1]) * (s + 1) + cell_corner[..., 2]  # index into sub
    tet_local = local[:, _TETS].reshape(-1, 4)  # (C*6, 4)
    ids = point_id[:, tet_local].reshape(-1, 4)
    vals = f[:, tet_local].reshape(-1, 4)
    pos = p_obj[:, tet_local].reshape(-1, 4, 3)
    inside = vals <= 0
    n_in = inside.sum(1)
    keep = (n_in > 0) & (n_in < 4)
    ids, vals, pos, inside, n_in = ids[keep], vals[keep], pos[keep], inside[keep], n_in[keep]

    edge_keys, edge_pos, tri_rows, tri_dirs = [], [], [], []
    n_fine = int(np.prod(dims))

    def crossing(t_idx: np.ndarray, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The zero crossing on edge (a, b) of tetrahedra ``t_idx``: a key per fine-grid edge, and its point."""
        ia, ib = ids[t_idx, a], ids[t_idx, b]
        fa, fb = vals[t_idx, a], vals[t_idx, b]
        u = (fa / (fa - fb))[:, None]
        point = pos[t_idx, a] * (1 - u) + pos[t_idx, b] * u
        return np.minimum(ia, ib) * n_fine + np.maximum(ia, ib), point

    order = np.argsort(~inside, axis=1, kind="stable")  # inside corners first
    count = 0
    for k in (1, 2, 3):
        t_idx = np.nonzero(n_in == k)[0]
        if len(t_idx) == 0:
            continue
        o = order[t_idx]
        ins, outs = o[:, :k], o[:, k:]
        if k == 2:  # a quad: the four edges from the two inside corners to the two outside ones, in cyclic order
            pts = [crossing(t_idx, a, b) for a, b in ((ins[:, 0], outs[:, 0]), (ins[:, 0], outs[:, 1]),
                                                      (ins[:, 1], outs[:, 1]), (ins[:, 1], outs[:, 0]))]
            polys = ([0, 1, 2], [0, 2, 3])
        else:  # a triangle: the three edges from the lone corner
            lone, others = (ins[:, 0], outs) if k == 1 else (outs[:, 0], ins)
            pts = [crossing(t_idx, lone, others[:, j]) for j in range(3)]
            polys = ([0, 1, 2],)
        m = len(t_idx)
        for key, point in pts:
            edge_keys.append(key)
            edge_pos.append(point)
        slot = count + m * np.arange(len(pts))  # where point j of tetrahedron 0 went
        # from the inside corners' centroid to the outside ones': the side a face must turn to
        w_in = inside[t_idx].astype(float)
        c_in = (pos[t_idx] * w_in[..., None]).sum(1) / w_in.sum(1, keepdims=True)
        c_out = (pos[t_idx] * (1 - w_in)[..., None]).sum(1) / (1 - w_in).sum(1, keepdims=True)
        for poly in polys:
            tri_rows.append(np.arange(m)[:, None] + slot[poly][None, :])
            tri_dirs.append(c_out - c_in)
        count += m * len(pts)
    keys = np.concatenate(edge_keys)
    points = np.concatenate(edge_pos)
    _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    vertices = points[first]
    faces = []
    for rows, direction in zip(tri_rows, tri_dirs):
        fi = inverse[rows]
        ng = np.cross(vertices[fi[:, 1]] - vertices[fi[:, 0]], vertices[fi[:, 2]] - vertices[fi[:, 0]])
        flip = np.einsum("ij,ij->i", ng, direction) < 0
        fi[flip] = fi[flip][:, [0, 2, 1]]
        faces.append(fi)
    faces = np.concatenate(faces)
    area2 = np.linalg.norm(np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]]), axis=1)
    faces = faces[area2 > 1e-14 * float(np.max(area2))]  # cells cut through a corner: zero-area slivers
    used = np.unique(faces)
    remap = np.full(len(vertices), -1)
    remap[used] = np.arange(len(used))
    vertices, faces = vertices[used], remap[faces]
    n = grid.smooth_normal(vertices) if normals == "smooth" else grid.grad(vertices)
    n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    return MeshData(vertices, faces.astype(np.int64), n, np.zeros((len(vertices), 2)))
