"""Triangle meshes for Mitsuba 3's shapes, and OBJ/PLY loading.

Mitsuba's shapes as triangle meshes, with **Mitsuba 3's object-space
conventions** [Mitsuba3], so that a scene file frames and lights the same in
both renderers. Spheres, disks and cylinders are intersected exactly
(:mod:`grisx.scene.analytic`, same conventions); their tessellations here
serve emitters (next-event estimation samples triangles), moving objects and
the built-in scenes:

=============  ==================================================================
``rectangle``  [-1, 1]² in the z = 0 plane, normal +z, uv = (x+1, y+1)/2
               (two triangles; ``rectangle.cpp``)
``cube``       [-1, 1]³, 24 vertices with per-face outward normals, every face
               mapped onto [0, 1]² in uv (Mitsuba's own vertex, normal, uv and
               triangle tables; ``cube.cpp``)
``sphere``     unit sphere (``center``/``radius`` become part of ``to_world``,
               ``to_world · translate(center) · scale(radius)`` as in
               ``sphere.cpp``), smooth outward vertex normals, uv = (φ/2π, θ/π)
               with θ = acos z, φ = atan2(y, x) ∈ [0, 2π)
``disk``       unit disk in the z = 0 plane, normal +z, uv = (r, φ/2π)
               (``disk.cpp``)
``cylinder``   open tube of radius 1 from z = 0 to z = 1 (no caps; ``p0``,
               ``p1`` and ``radius`` become part of ``to_world`` as in
               ``cylinder.cpp``), smooth outward normals, uv = (φ/2π, z)
=============  ==================================================================

**Orientation.** A triangle's front side is the one its counter-clockwise
winding faces, ``ng = (p1 − p0) × (p2 − p0)``: grisx derives geometric
normals (and the emitting side of one-sided area lights) from winding, so
every mesh here has winding and vertex normals that agree. ``flip_normals``
reverses the winding *and* negates vertex normals, which is what Mitsuba's
``flip_normals`` does for every shape (analytic shapes flip their frame,
meshes negate ``n`` and the shading normal).

**Tessellation.** Spheres, cylinders and disks are inscribed polygons. A disk of ``N``
segments deviates from the circle by ``r (1 − cos(π/N)) ≈ r π²/(2N²)``; a UV
sphere's faces (quads split along a diagonal) come closer to the centre, by at
most ``≈ r π²/N²`` with ``rings = N/2``. The defaults (``segments=256``,
``rings=128``) keep the silhouette error of a sphere filling a 1080p frame
(projected radius 540 px) at 0.08 px, and below half a pixel up to a
projected radius of ≈ 3300 px. The area converges to 4πr² as O(1/N²).

**Meshes.** :func:`load_mesh` reads OBJ with a small parser that follows
Mitsuba's ``obj.cpp`` exactly (vertices are unique ``v/vt/vn`` index triples,
so UV and normal seams are kept; polygons are fan-triangulated; texture ``v``
is flipped, ``v ← 1 − v``, Mitsuba's default ``flip_tex_coords=true``), and
PLY with ``trimesh`` (``process=False``: no merging or reordering), taking
vertex normals (``nx, ny, nz``) and texture coordinates (``u, v``, else
``texture_u, texture_v``, else ``s, t``: Mitsuba's order; ``texture_s, texture_t``
are not uvs to Mitsuba) from the file as they are (Mitsuba's ``ply`` has ``flip_tex_coords`` too, default false). When a file has no normals, smooth normals are computed with Mitsuba's
weighting (face normals weighted by the corner angle; Thürmer & Wüthrich
1998), unless ``face_normals=True``, which drops normals altogether (faceted
shading, Mitsuba's ``face_normals``). A PLY file's other vertex and face properties become Mitsuba's
**mesh attributes** (``MeshData.attributes``), grouped and named as its ``ply`` plugin does
(:func:`ply_attributes`: ``r, g, b`` → ``vertex_color``, ``weight_0`` → ``face_weight``, ...), for
``mesh_attribute`` textures (:mod:`grisx.scene.texture`).

Every function returns a :class:`MeshData` record in object space.

References
----------
[Mitsuba3] W. Jakob et al., Mitsuba 3 renderer, plugin reference "Shapes"
           and ``src/shapes/{rectangle,cube,sphere,disk,cylinder,obj,ply}.cpp``,
           https://mitsuba.readthedocs.io (2022).
"""

from __future__ import annotations

import dataclasses
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from grisx.errors import GrisxError, InvalidParameterError

__all__ = [
    "MeshData",
    "rectangle",
    "cube",
    "sphere",
    "disk",
    "load_mesh",
    "load_obj",
    "load_ply",
    "flip_mesh",
    "vertex_normals",
    "mesh_area",
    "face_normals_of",
    "finish_mesh",
    "ply_attributes",
]


@dataclasses.dataclass(frozen=True)
class MeshData:
    """A triangle mesh in object space.

    ``vertices`` (n, 3) float64, ``faces`` (m, 3) int64 (counter-clockwise =
    front), ``normals`` (n, 3) unit vertex normals or ``None`` (face normals),
    ``uvs`` (n, 2) or ``None``.
    """

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray | None = None
    uvs: np.ndarray | None = None
    #: Mitsuba's mesh attributes: name → (rows, dim) float values, one row per vertex (``vertex_*``) or per
    #: face (``face_*``), as a PLY file's extra properties are grouped (:func:`ply_attributes`)
    attributes: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)

    def __iter__(self):  # allows ``vertices, faces, normals, uvs = load_mesh(...)``
        return iter((self.vertices, self.faces, self.normals, self.uvs))


def flip_mesh(mesh: MeshData) -> MeshData:
    """Turn the mesh inside out: reverse the winding and negate the vertex normals (Mitsuba's ``flip_normals``)."""
    return dataclasses.replace(mesh, faces=mesh.faces[:, [0, 2, 1]].copy(), normals=None if mesh.normals is None else -mesh.normals)


def _finish(mesh: MeshData, flip_normals: bool) -> MeshData:
    return flip_mesh(mesh) if flip_normals else mesh


def face_normals_of(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unnormalized face normals (p1 − p0) × (p2 − p0); their length is twice the triangle area."""
    v = np.asarray(vertices, dtype=np.float64)
    p0, p1, p2 = v[faces[:, 0]], v[faces[:, 1]], v[faces[:, 2]]
    return np.cross(p1 - p0, p2 - p0)


def mesh_area(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Total surface area of a triangle mesh."""
    return float(0.5 * np.linalg.norm(face_normals_of(vertices, faces), axis=1).sum())


# ---- analytic shapes -------------------------------------------------------------


def rectangle(flip_normals: bool = False) -> MeshData:
    """Mitsuba's ``rectangle``: [-1, 1]² at z = 0, normal +z, uv = (x+1, y+1)/2."""
    v = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], dtype=np.float64)
    f = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int64)
    n = np.tile([0.0, 0.0, 1.0], (4, 1))
    uv = 0.5 * (v[:, :2] + 1.0)
    return _finish(MeshData(v, f, n, uv), flip_normals)


# Mitsuba 3's cube tables (src/shapes/cube.cpp): 6 faces × 4 vertices.
_CUBE_VERTICES = [
    (1, -1, -1), (1, -1, 1), (-1, -1, 1), (-1, -1, -1),
    (1, 1, -1), (-1, 1, -1), (-1, 1, 1), (1, 1, 1),
    (1, -1, -1), (1, 1, -1), (1, 1, 1), (1, -1, 1),
    (1, -1, 1), (1, 1, 1), (-1, 1, 1), (-1, -1, 1),
    (-1, -1, 1), (-1, 1, 1), (-1, 1, -1), (-1, -1, -1),
    (1, 1, -1), (1, -1, -1), (-1, -1, -1), (-1, 1, -1),
]
_CUBE_FACE_NORMALS = [(0, -1, 0), (0, 1, 0), (1, 0, 0), (0, 0, 1), (-1, 0, 0), (0, 0, -1)]
_CUBE_UVS = [(0, 1), (1, 1), (1, 0), (0, 0)] * 6
_CUBE_TRIANGLES = [
    (0, 1, 2), (3, 0, 2), (4, 5, 6), (7, 4, 6), (8, 9, 10), (11, 8, 10),
    (12, 13, 14), (15, 12, 14), (16, 17, 18), (19, 16, 18), (20, 21, 22), (23, 20, 22),
]


def cube(flip_normals: bool = False) -> MeshData:
    """Mitsuba's ``cube``: [-1, 1]³, 24 vertices, 12 triangles, outward per-face normals."""
    v = np.array(_CUBE_VERTICES, dtype=np.float64)
    n = np.repeat(np.array(_CUBE_FACE_NORMALS, dtype=np.float64), 4, axis=0)
    uv = np.array(_CUBE_UVS, dtype=np.float64)
    f = np.array(_CUBE_TRIANGLES, dtype=np.int64)
    return _finish(MeshData(v, f, n, uv), flip_normals)


def _check_count(name: str, value: int, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise InvalidParameterError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def sphere(
    center: tuple[float, float, float] | None = None,
    radius: float = 1.0,
    flip_normals: bool = False,
    segments: int = 256,
    rings: int = 128,
) -> MeshData:
    """Mitsuba's ``sphere`` as a UV-sphere: ``segments`` around z, ``rings`` from pole to pole.

    Vertices lie on the sphere (inscribed); normals are the exact sphere
    normals; uv = (φ/2π, θ/π) as Mitsuba's ``sphere`` (seam and pole vertices
    are duplicated so uv is continuous within every triangle). ``center`` and
    ``radius`` are applied here; the loader instead puts them into
    ``to_world`` exactly as Mitsuba does and calls ``sphere()``.
    """
    segments = _check_count("sphere segments", segments, 3)
    rings = _check_count("sphere rings", rings, 2)
    if not (math.isfinite(radius) and radius > 0):
        raise InvalidParameterError(f"sphere radius must be positive and finite, got {radius!r}")
    theta = np.linspace(0.0, math.pi, rings + 1)  # ring i, theta_0 = 0 is the +z pole
    phi = np.linspace(0.0, 2 * math.pi, segments + 1)  # column j; j = segments duplicates j = 0 (uv seam)
    # interior rings: (rings - 1) × (segments + 1) vertices
    th, ph = np.meshgrid(theta[1:-1], phi, indexing="ij")
    ring_p = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], axis=-1).reshape(-1, 3)
    ring_uv = np.stack([ph / (2 * math.pi), th / math.pi], axis=-1).reshape(-1, 2)
    # pole vertices, one per segment, at u = centre of the segment
    u_mid = (np.arange(segments) + 0.5) / segments
    north = np.tile([0.0, 0.0, 1.0], (segments, 1))
    south = np.tile([0.0, 0.0, -1.0], (segments, 1))
    verts = np.concatenate([north, ring_p, south])
    uvs = np.concatenate([np.stack([u_mid, np.zeros(segments)], -1), ring_uv, np.stack([u_mid, np.ones(segments)], -1)])
    # exact values at the seam: sin(2π) is not 0 in floating point
    verts[np.abs(verts) < 1e-15] = 0.0

    def ring_index(i: int, j: np.ndarray) -> np.ndarray:  # ring i in 1..rings-1
        return segments + (i - 1) * (segments + 1) + j

    j = np.arange(segments)
    faces = [np.stack([j, ring_index(1, j), ring_index(1, j + 1)], -1)]  # north cap: pole, ring1[j], ring1[j+1]
    for i in range(1, rings - 1):
        a, b = ring_index(i, j), ring_index(i + 1, j)
        c, d = ring_index(i + 1, j + 1), ring_index(i, j + 1)
        # (a, b, c) and (a, c, d): south × east = outward (a→b goes south, a→d goes east)
        faces.append(np.stack([a, b, c], -1))
        faces.append(np.stack([a, c, d], -1))
    south_base = segments + (rings - 1) * (segments + 1)
    faces.append(np.stack([ring_index(rings - 1, j), south_base + j, ring_index(rings - 1, j + 1)], -1))
    f = np.concatenate(faces).astype(np.int64)
    normals = verts.copy()
    c = np.zeros(3) if center is None else np.asarray(center, dtype=np.float64)
    return _finish(MeshData(verts * radius + c, f, normals, uvs), flip_normals)


def disk(flip_normals: bool = False, segments: int = 256) -> MeshData:
    """Mitsuba's ``disk``: unit disk at z = 0, normal +z, uv = (r, φ/2π) (a fan of ``segments`` triangles)."""
    segments = _check_count("disk segments", segments, 3)
    phi = np.linspace(0.0, 2 * math.pi, segments + 1)
    rim = np.stack([np.cos(phi), np.sin(phi), np.zeros_like(phi)], -1)
    rim[np.abs(rim) < 1e-15] = 0.0
    centre = np.zeros((segments, 3))  # one centre vertex per segment: uv's v = φ/2π differs per wedge
    v = np.concatenate([centre, rim])
    u_mid = (np.arange(segments) + 0.5) / segments
    uv = np.concatenate([np.stack([np.zeros(segments), u_mid], -1), np.stack([np.ones(segments + 1), phi / (2 * math.pi)], -1)])
    j = np.arange(segments)
    f = np.stack([j, segments + j, segments + j + 1], -1).astype(np.int64)
    n = np.tile([0.0, 0.0, 1.0], (len(v), 1))
    return _finish(MeshData(v, f, n, uv), flip_normals)


def cylinder(flip_normals: bool = False, segments: int = 256) -> MeshData:
    """Mitsuba's ``cylinder``: the open tube x² + y² = 1, 0 ≤ z ≤ 1, normals outward, uv = (φ/2π, z)
    (``segments`` quads around z, each split along a diagonal; the seam column is duplicated for uv)."""
    segments = _check_count("cylinder segments", segments, 3)
    phi = np.linspace(0.0, 2 * math.pi, segments + 1)
    ring = np.stack([np.cos(phi), np.sin(phi), np.zeros_like(phi)], -1)
    ring[np.abs(ring) < 1e-15] = 0.0
    top = ring + [0.0, 0.0, 1.0]
    v = np.concatenate([ring, top])  # bottom j, top segments + 1 + j
    n = np.concatenate([ring, ring])
    u = phi / (2 * math.pi)
    uv = np.concatenate([np.stack([u, np.zeros_like(u)], -1), np.stack([u, np.ones_like(u)], -1)])
    j = np.arange(segments)
    a, b, c, d = j, segments + 1 + j, j + 1, segments + 2 + j  # bottom j, top j, bottom j+1, top j+1
    # (a, c, b) and (b, c, d): (c − a) × (b − a) points away from the axis
    f = np.concatenate([np.stack([a, c, b], -1), np.stack([b, c, d], -1)]).astype(np.int64)
    return _finish(MeshData(v, f, n, uv), flip_normals)


# ---- meshes from files -----------------------------------------------------------


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Smooth vertex normals as Mitsuba's ``Mesh::recompute_vertex_normals``.

    Each face adds its unit normal weighted by its interior angle at the
    vertex (Thürmer & Wüthrich 1998); degenerate faces add nothing. A vertex
    that only touches degenerate faces gets an arbitrary +z (it is never hit).
    """
    v = np.asarray(vertices, dtype=np.float64)
    fn = face_normals_of(v, faces)
    length = np.linalg.norm(fn, axis=1)
    ok = length > 0
    fn = np.where(ok[:, None], fn / np.where(ok, length, 1.0)[:, None], 0.0)
    out = np.zeros_like(v)
    for k in range(3):
        i0, i1, i2 = faces[:, k], faces[:, (k + 1) % 3], faces[:, (k + 2) % 3]
        e1 = v[i1] - v[i0]
        e2 = v[i2] - v[i0]
        n1 = np.linalg.norm(e1, axis=1)
        n2 = np.linalg.norm(e2, axis=1)
        cosang = np.einsum("ij,ij->i", e1, e2) / np.maximum(n1 * n2, 1e-300)
        angle = np.arccos(np.clip(cosang, -1.0, 1.0))
        np.add.at(out, i0, fn * angle[:, None])
    length = np.linalg.norm(out, axis=1)
    good = length > 0
    out[good] /= length[good, None]
    out[~good] = (0.0, 0.0, 1.0)
    return out


def _mesh_error(path: Path, what: str) -> GrisxError:
    return GrisxError(f"cannot load mesh '{path}': {what}")


def _obj_index(token: str, count: int, kind: str, path: Path, line: int) -> int:
    try:
        i = int(token)
    except ValueError:
        raise _mesh_error(path, f"line {line}: bad {kind} index '{token}'") from None
    j = i - 1 if i > 0 else count + i  # OBJ indices are 1-based; negative ones count from the end
    if not (0 <= j < count) or i == 0:
        raise _mesh_error(path, f"line {line}: {kind} index {i} out of range (have {count})")
    return j


#: meshes read from OBJ files, by (file, modification time, size, flip_tex_coords): a scene names one file many
#: times (Mitsuba's bsdf_spheres scenes place sphere.obj, 81,671 lines, twelve times) and a session reads it in many
#: scenes; each caller gets its own copy
_OBJ_CACHE: dict[tuple[str, int, int, bool], MeshData] = {}
_OBJ_CACHE_SIZE = 16


def _mesh_copy(m: MeshData) -> MeshData:
    return MeshData(m.vertices.copy(), m.faces.copy(), None if m.normals is None else m.normals.copy(),
                    None if m.uvs is None else m.uvs.copy(), {k: v.copy() for k, v in m.attributes.items()})


def load_obj(path: str | os.PathLike, flip_tex_coords: bool = True) -> MeshData:
    """Read a Wavefront OBJ file as Mitsuba's ``obj`` plugin does (see module docstring).

    Returns the file's normals (or ``None`` when it has none) and uvs (or ``None``).
    """
    path = Path(path)
    if not path.is_file():
        raise _mesh_error(path, "no such file")
    st = path.stat()
    key = (str(path.resolve()), st.st_mtime_ns, st.st_size, bool(flip_tex_coords))
    mesh = _OBJ_CACHE.get(key)
    if mesh is None:
        mesh = _read_obj(path, flip_tex_coords)
        if len(_OBJ_CACHE) >= _OBJ_CACHE_SIZE:
            _OBJ_CACHE.pop(next(iter(_OBJ_CACHE)))
        _OBJ_CACHE[key] = mesh
    return _mesh_copy(mesh)


def _read_obj(path: Path, flip_tex_coords: bool) -> MeshData:
    pos: list[tuple[float, float, float]] = []
    tex: list[tuple[float, float]] = []
    nrm: list[tuple[float, float, float]] = []
    key_to_vertex: dict[tuple[int, int, int], int] = {}
    keys: list[tuple[int, int, int]] = []
    tris: list[tuple[int, int, int]] = []
    token_to_vertex: dict[str, int] = {}  # face tokens without relative (negative) indices name one vertex for good
    with open(path, encoding="utf-8", errors="replace") as fh:
        for lineno, raw in enumerate(fh, start=1):
            parts = raw.split()
            if not parts:
                continue
            tag = parts[0]
            try:
                if tag == "v":
                    pos.append((float(parts[1]), float(parts[2]), float(parts[3])))
                elif tag == "vt":
                    u = float(parts[1])
                    w = float(parts[2]) if len(parts) > 2 else 0.0
                    tex.append((u, 1.0 - w if flip_tex_coords else w))
                elif tag == "vn":
                    nrm.append((float(parts[1]), float(parts[2]), float(parts[3])))
            except (IndexError, ValueError):
                raise _mesh_error(path, f"line {lineno}: could not parse '{raw.strip()}'") from None
            if tag != "f":
                continue  # o, g, s, usemtl, mtllib, l, p: geometry groups are merged, as Mitsuba does
            corner_ids = []
            for tok in parts[1:]:
                vid = token_to_vertex.get(tok)
                if vid is not None:
                    corner_ids.append(vid)
                    continue
                fields = tok.split("/")
                if len(fields) > 3 or not fields[0]:
                    raise _mesh_error(path, f"line {lineno}: bad face vertex '{tok}'")
                vi = _obj_index(fields[0], len(pos), "vertex", path, lineno)
                ti = _obj_index(fields[1], len(tex), "texture coordinate", path, lineno) if len(fields) > 1 and fields[1] else -1
                ni = _obj_index(fields[2], len(nrm), "normal", path, lineno) if len(fields) > 2 and fields[2] else -1
                key = (vi, ti, ni)
                vid = key_to_vertex.get(key)
                if vid is None:
                    vid = key_to_vertex[key] = len(keys)
                    keys.append(key)
                if "-" not in tok:
                    token_to_vertex[tok] = vid
                corner_ids.append(vid)
            if len(corner_ids) < 3:
                raise _mesh_error(path, f"line {lineno}: a face needs at least 3 vertices")
            for k in range(1, len(corner_ids) - 1):  # fan, as obj.cpp
                tris.append((corner_ids[0], corner_ids[k], corner_ids[k + 1]))
    if not tris:
        raise _mesh_error(path, "no faces")
    k = np.asarray(keys, dtype=np.int64)
    vertices = np.asarray(pos, dtype=np.float64)[k[:, 0]]
    uvs = None
    if tex and np.all(k[:, 1] >= 0):
        uvs = np.asarray(tex, dtype=np.float64)[k[:, 1]]
    elif tex and np.any(k[:, 1] >= 0):
        raise _mesh_error(path, "some face vertices have texture coordinates and others do not")
    normals = None
    if nrm and np.all(k[:, 2] >= 0):
        normals = np.asarray(nrm, dtype=np.float64)[k[:, 2]]
        ln = np.linalg.norm(normals, axis=1, keepdims=True)
        if np.any(ln == 0) or not np.all(np.isfinite(normals)):
            raise _mesh_error(path, "zero-length or invalid vertex normal")
        normals = normals / ln
    elif nrm and np.any(k[:, 2] >= 0):
        raise _mesh_error(path, "some face vertices have normals and others do not")
    if not np.all(np.isfinite(vertices)):
        raise _mesh_error(path, "invalid vertex position data")
    return MeshData(vertices, np.asarray(tris, dtype=np.int64), normals, uvs)


_PLY_UV_NAMES = (("u", "v"), ("texture_u", "texture_v"), ("s", "t"))  # ply.cpp's order


def _ply_used_vertices(face_data: Any) -> np.ndarray | None:
    """Sorted indices of the vertices a PLY file's faces use, from trimesh's raw face element (ASCII or binary)."""
    if face_data is None:
        return None
    lists = face_data["vertex_indices"]
    if isinstance(lists, np.ndarray) and lists.dtype.names:  # binary: (count, indices) records
        lists = lists[lists.dtype.names[-1]]
    flat = [np.asarray(f, dtype=np.int64).reshape(-1) for f in lists] if lists.dtype == object else [np.asarray(lists, dtype=np.int64).reshape(-1)]
    return np.unique(np.concatenate(flat)) if flat else None


#: postfix categories of a multi-field PLY attribute (Mitsuba's ``ply.h``): {x,y,z,w}, {r,g,b,a}, {0,1,2,3}, {1,2,3,4}
_PLY_POSTFIXES = ("xr01", "yg12", "zb23", "wa34")


def ply_attributes(kind: str, names: list[str], reserved: set[str]) -> list[tuple[str, list[str]]]:
    """Mitsuba's grouping of a PLY element's extra properties into mesh attributes (``find_other_fields``).

    ``kind`` is ``"vertex_"`` or ``"face_"``, ``names`` the element's properties in file order, ``reserved``
    those read otherwise (positions, normals, uvs; vertex indices). Returns ``(attribute name, property names)``:

    * ``r, g, b[, a]`` (or ``red, green, blue[, alpha]``) → ``{kind}color``;
    * consecutive ``{prefix}_{x|y|z}``, ``{prefix}_{r|g|b}`` (→ ``{kind}{prefix}_color``), ``{prefix}_{0|1|2}``
      or ``{prefix}_{1|2|3}`` → ``{kind}{prefix}``, of 1 or 3 fields (others, and properties without a
      one-letter postfix, are ignored, as Mitsuba ignores them with a warning).
    """
    out: list[tuple[str, list[str]]] = []
    present = set(names)
    rename = {}
    if not {"r", "g", "b"} <= present and {"red", "green", "blue"} <= present:
        rename = {"red": "r", "green": "g", "blue": "b", "alpha": "a"}
    named = [rename.get(n, n) for n in names]
    if {"r", "g", "b"} <= set(named):
        fields = ["r", "g", "b"] + (["a"] if "a" in named else [])
        out.append((kind + "color", [names[named.index(f)] for f in fields]))
    reserved = set(reserved) | {"r", "g", "b", "a"}
    encountered: set[str] = set()
    prefix, category, fields = "", 0, []

    def flush() -> None:
        if len(fields) in (1, 3):
            out.append((kind + prefix + ("_color" if category == 1 else ""), list(fields)))
            encountered.add(prefix)

    for name, mapped in zip(names, named):
        if mapped in reserved:
            continue
        head, sep, postfix = mapped.rpartition("_")
        if not sep or len(postfix) != 1:  # no one-letter postfix: ignored
            flush()
            prefix, fields = "", []
            continue
        if fields and head != prefix:
            flush()
            prefix, fields = "", []
        if not fields:
            if head in encountered or postfix not in _PLY_POSTFIXES[0]:
                continue
            prefix, category = head, _PLY_POSTFIXES[0].index(postfix)
        elif len(fields) >= 4 or postfix != _PLY_POSTFIXES[len(fields)][category]:
            prefix, fields = "", []  # a broken sequence: the attribute is ignored
            encountered.add(head)
            continue
        fields.append(name)
    flush()
    return out


def _ply_columns(element: dict) -> dict[str, np.ndarray]:
    """A trimesh ``_ply_raw`` element's properties by name, in file order (ASCII: a dict; binary: a record array)."""
    data = element.get("data", {})
    names = (data.dtype.names or ()) if isinstance(data, np.ndarray) else tuple(data)
    return {name: data[name] for name in names}


def load_ply(path: str | os.PathLike, flip_tex_coords: bool = False) -> MeshData:
    """Read a PLY file (ASCII or binary) with trimesh, keeping its vertex order, normals and uvs.

    Faces may come back grouped by polygon size (trimesh triangulates
    triangles and larger polygons separately); winding is the file's.
    """
    path = Path(path)
    if not path.is_file():
        raise _mesh_error(path, "no such file")
    import trimesh  # a declared dependency; imported lazily (it is slow to import)

    try:
        m = trimesh.load(str(path), file_type="ply", process=False, force="mesh")
    except Exception as exc:  # trimesh raises many kinds of errors on bad files
        raise _mesh_error(path, f"{type(exc).__name__}: {exc}") from None
    if not isinstance(m, trimesh.Trimesh) or len(m.faces) == 0:
        raise _mesh_error(path, "no triangle faces (point clouds are not supported)")
    vertices = np.asarray(m.vertices, dtype=np.float64)
    faces = np.asarray(m.faces, dtype=np.int64)
    ply_raw = (m.metadata or {}).get("_ply_raw", {})
    raw = _ply_columns(ply_raw.get("vertex", {}))
    if "x" in raw:  # trimesh keeps the file's vertex order with process=False; check it
        xyz = np.column_stack([np.asarray(raw[c], dtype=np.float64).reshape(-1) for c in ("x", "y", "z")])
        if xyz.shape != vertices.shape:
            # with uvs trimesh drops vertices no face uses (keeping the order of the rest); Mitsuba keeps
            # them, and the per-vertex columns below are the file's: index the file's vertices instead
            used = _ply_used_vertices((m.metadata or {}).get("_ply_raw", {}).get("face", {}).get("data"))
            if used is None or used.size != len(vertices) or used[-1] >= len(xyz) or not np.allclose(xyz[used], vertices):
                raise _mesh_error(path, "internal: trimesh reordered the vertices")
            faces = used[faces]
            vertices = xyz
        elif not np.allclose(xyz, vertices):
            raise _mesh_error(path, "internal: trimesh reordered the vertices")

    def column(name: str) -> np.ndarray:
        return np.asarray(raw[name], dtype=np.float64).reshape(-1)

    normals = None
    if all(c in raw for c in ("nx", "ny", "nz")):
        normals = np.column_stack([column(c) for c in ("nx", "ny", "nz")])
        ln = np.linalg.norm(normals, axis=1, keepdims=True)
        if np.any(ln == 0) or not np.all(np.isfinite(normals)):
            raise _mesh_error(path, "zero-length or invalid vertex normal")
        normals = normals / ln
    uvs = None
    for a, b in _PLY_UV_NAMES:
        if a in raw and b in raw:
            uvs = np.column_stack([column(a), column(b)])
            if flip_tex_coords:
                uvs[:, 1] = 1.0 - uvs[:, 1]
            break
    if not np.all(np.isfinite(vertices)):
        raise _mesh_error(path, "invalid vertex position data")
    return MeshData(vertices, faces, normals, uvs, _ply_mesh_attributes(path, ply_raw, raw, len(faces)))


def _ply_mesh_attributes(path: Path, ply_raw: dict, vertex_columns: dict, face_count: int) -> dict[str, np.ndarray]:
    """A PLY file's vertex and face attributes, grouped as Mitsuba groups them (:func:`ply_attributes`)."""
    vertex_names = list(vertex_columns)
    reserved = {"x", "y", "z", "nx", "ny", "nz", "u", "v"}
    if {"texture_u", "texture_v"} <= set(vertex_names):  # Mitsuba reads these as u, v
        reserved |= {"texture_u", "texture_v"}
    elif {"s", "t"} <= set(vertex_names):
        reserved |= {"s", "t"}
    face_columns = _ply_columns(ply_raw.get("face", {}))
    out = {}
    for kind, columns, skip in (("vertex_", vertex_columns, reserved), ("face_", face_columns, {"vertex_indices", "vertex_index"})):
        for name, fields in ply_attributes(kind, list(columns), skip):
            out[name] = np.column_stack([np.asarray(columns[f], dtype=np.float64).reshape(-1) for f in fields])
    if any(k.startswith("face_") for k in out):
        lists = face_columns.get("vertex_indices", face_columns.get("vertex_index"))
        counts = lists["f0"] if isinstance(lists, np.ndarray) and lists.dtype.names else [len(f) for f in lists]
        if len(counts) != face_count or np.any(np.asarray(counts) != 3):
            raise _mesh_error(path, "face attributes on polygons that are not triangles (Mitsuba reads triangle PLYs only)")
    return out


def load_mesh(
    path: str | os.PathLike,
    face_normals: bool = False,
    flip_normals: bool = False,
    flip_tex_coords: bool | None = None,
    to_world: np.ndarray | None = None,
) -> MeshData:
    """Load an ``.obj`` or ``.ply`` mesh in object space (see module docstring).

    ``normals`` is the file's vertex normals, or Mitsuba's angle-weighted
    smooth normals when the file has none, or ``None`` with ``face_normals``.
    ``flip_tex_coords`` (v ← 1 − v) defaults to Mitsuba's per-format
    default: ``True`` for OBJ, ``False`` for PLY. ``to_world``: the transform the
    mesh will be placed with, where it mirrors (:func:`finish_mesh`).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".obj":
        mesh = load_obj(path, flip_tex_coords=True if flip_tex_coords is None else flip_tex_coords)
    elif suffix == ".ply":
        mesh = load_ply(path, flip_tex_coords=bool(flip_tex_coords))
    else:
        raise _mesh_error(path, f"unknown mesh format '{suffix}' (expected .obj or .ply)")
    return finish_mesh(mesh, face_normals, flip_normals, to_world)


def finish_mesh(mesh: MeshData, face_normals: bool = False, flip_normals: bool = False, to_world: np.ndarray | None = None) -> MeshData:
    """A file's mesh as Mitsuba renders it: face normals if asked, else the file's vertex normals or
    Mitsuba's smooth ones where it has none; turned inside out with ``flip_normals``.

    ``to_world``, where it mirrors (det < 0), decides the front side of a mesh that brings its own normals:
    Mitsuba shades in the frame of the normals, mapped by ``to_world``'s inverse transpose, and its BSDFs
    take the side they point to as the front, while the winding of the mapped vertices turns the other way
    (Mitsuba ≥ 3.10 reverses the winding of such meshes explicitly, ``Mesh::flip_winding``); grisx's front
    side is the winding's, so the winding is reversed here. A mesh without normals (or with
    ``face_normals``) keeps the winding of its mapped vertices, whose normals Mitsuba computes from them."""
    if to_world is not None and not face_normals and mesh.normals is not None and np.linalg.det(np.asarray(to_world)[:3, :3]) < 0:
        mesh = dataclasses.replace(mesh, faces=mesh.faces[:, [0, 2, 1]].copy())
    if face_normals:
        mesh = dataclasses.replace(mesh, normals=None)
    elif mesh.normals is None:
        mesh = dataclasses.replace(mesh, normals=vertex_normals(mesh.vertices, mesh.faces))
    return _finish(mesh, flip_normals)
