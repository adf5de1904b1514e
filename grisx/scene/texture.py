"""Albedo textures: one flat RGB atlas on the device, bilinear or nearest lookups, Mitsuba's wrap modes.

Every texture registered on a :class:`~grisx.scene.scene.Scene` is packed
into one ``wp.array(dtype=wp.vec3)`` with a :class:`TextureInfo` record
(kind, offset, width, height, uv transform, colours) per texture, so kernels
carry a single struct whatever the number of textures. Two kinds, with
Mitsuba 3's meaning:

* **bitmap** (a linear RGB image, :class:`Bitmap` or a bare array): texels
  row 0 at the top of the image; ``uv = (0, 0)`` is the top-left corner of
  texel (0, 0). ``filter_type``: ``bilinear`` (default; between the four texel
  centres around ``uv · size − ½``) or ``nearest`` (the texel ``⌊uv · size⌋``);
  ``wrap_mode`` maps a texel index outside the image back into it, as Dr.Jit's
  ``Texture.wrap`` does for Mitsuba: ``repeat`` (default; index mod size),
  ``mirror`` (period 2·size, every other copy flipped: …, 1, 0, 0, 1, …,
  size−1, size−1, …) or ``clamp`` (the edge texel);
* **checkerboard** (:class:`Checkerboard`): ``color0`` where the fractional
  parts of u and v are both above ½ or both at most ½, ``color1`` elsewhere
  (``checkerboard.cpp``).

Both look up at ``to_uv · (u, v, 1)``, a 2×3 affine map (Mitsuba's ``to_uv``).

A third kind reads no uv: **mesh_attribute** (:class:`MeshAttribute`, Mitsuba's ``mesh_attribute``
texture) evaluates a named attribute of the mesh that was hit (a PLY file's extra vertex or face
properties, :func:`grisx.scene.shapes.ply_attributes`), times ``scale``, as Mitsuba's
``Mesh::interpolate_attribute`` does in its RGB variants:

* ``vertex_*``: the barycentric blend ``b₀ a[i₀] + b₁ a[i₁] + b₂ a[i₂]`` of the triangle's three vertices;
* ``face_*``: the triangle's own value, constant over it;

a 1-channel attribute is grey (its value in all three channels), a 3-channel one is RGB.
:meth:`~grisx.scene.scene.Scene.build` gathers each such texture's values over the whole scene
(one row per scene vertex or triangle: :class:`AttributeTexels`) so that :func:`attribute_lookup`
indexes them by the hit's triangle and vertices.

Scalar uses (a mask's opacity, a bump map's height) read the luminance of the
RGB value, as Mitsuba's ``eval_1`` of a 3-channel bitmap; ``texture_gradient``
is the exact uv gradient of that luminance under the bilinear filter (Mitsuba's
``eval_1_grad``; 0 for a checkerboard or a nearest lookup, constant almost everywhere).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import warp as wp

from grisx.errors import InvalidValueError
from grisx.theory.gris import luminance

wp.set_module_options({"enable_backward": False})

__all__ = ["Bitmap", "Checkerboard", "MeshAttribute", "AttributeTexels", "TextureInfo", "TextureSet", "texture_lookup", "texture_lookup_1", "texture_gradient",
           "attribute_lookup", "pack_textures", "TEXTURE_BITMAP", "TEXTURE_CHECKERBOARD", "TEXTURE_MESH_ATTRIBUTE",
           "WRAP_MODES", "FILTER_TYPES"]

TEXTURE_BITMAP = wp.constant(0)
TEXTURE_CHECKERBOARD = wp.constant(1)
TEXTURE_MESH_ATTRIBUTE = wp.constant(2)
#: Mitsuba's bitmap ``wrap_mode`` names → TextureInfo.wrap
WRAP_MODES = {"repeat": 0, "mirror": 1, "clamp": 2}
WRAP_MIRROR = wp.constant(1)
WRAP_CLAMP = wp.constant(2)
#: Mitsuba's bitmap ``filter_type`` names → TextureInfo.nearest
FILTER_TYPES = {"bilinear": 0, "nearest": 1}
#: the identity 2×3 uv map
IDENTITY_UV = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0))


@dataclasses.dataclass(frozen=True)
class Bitmap:
    """A linear RGB image (H, W, 3), looked up at ``to_uv · (u, v, 1)`` (2×3, rows); Mitsuba's ``wrap_mode`` and ``filter_type``."""

    image: np.ndarray
    to_uv: tuple[tuple[float, float, float], tuple[float, float, float]] = IDENTITY_UV
    wrap_mode: str = "repeat"
    filter_type: str = "bilinear"


@dataclasses.dataclass(frozen=True)
class Checkerboard:
    """Mitsuba's ``checkerboard``: ``color0`` (default 0.4) and ``color1`` (0.2) in squares of ½ in uv."""

    color0: tuple[float, float, float] = (0.4, 0.4, 0.4)
    color1: tuple[float, float, float] = (0.2, 0.2, 0.2)
    to_uv: tuple[tuple[float, float, float], tuple[float, float, float]] = IDENTITY_UV


@dataclasses.dataclass(frozen=True)
class MeshAttribute:
    """Mitsuba's ``mesh_attribute``: the hit mesh's attribute ``name`` (``vertex_*`` or ``face_*``) times ``scale``."""

    name: str
    scale: float = 1.0

    def __post_init__(self) -> None:
        if not (self.name.startswith("vertex_") or self.name.startswith("face_")):
            raise InvalidValueError(f"mesh attribute name must start with 'vertex_' or 'face_', got {self.name!r}")


@dataclasses.dataclass(frozen=True)
class AttributeTexels:
    """A :class:`MeshAttribute` resolved over a built scene: RGB ``values`` (N, 3), one row per scene vertex
    (``per_face`` false) or per scene triangle (true); rows of meshes without the attribute are unused."""

    values: np.ndarray
    per_face: bool


@wp.struct
class TextureInfo:
    kind: int  # TEXTURE_*
    offset: int
    width: int  # mesh attributes: 1 per face, 0 per vertex
    height: int
    uv_row0: wp.vec3  # to_uv: u' = row0 · (u, v, 1)
    uv_row1: wp.vec3  # v' = row1 · (u, v, 1)
    color0: wp.vec3  # checkerboard colours
    color1: wp.vec3
    wrap: int  # WRAP_MODES
    nearest: int  # FILTER_TYPES


@wp.struct
class TextureSet:
    texels: wp.array(dtype=wp.vec3)
    info: wp.array(dtype=TextureInfo)
    count: int


@wp.func
def _wrap(i: int, size: int, mode: int) -> int:
    """A texel index in [0, size): Dr.Jit's ``Texture.wrap`` (repeat, mirror, clamp)."""
    if mode == WRAP_CLAMP:
        return wp.clamp(i, 0, size - 1)
    if mode == WRAP_MIRROR:
        m = ((i % (2 * size)) + 2 * size) % (2 * size)
        if m >= size:
            m = 2 * size - 1 - m
        return m
    return ((i % size) + size) % size


@wp.func
def _texel(ts: TextureSet, info: TextureInfo, x: int, y: int) -> wp.vec3:
    xm = _wrap(x, info.width, info.wrap)
    ym = _wrap(y, info.height, info.wrap)
    return ts.texels[info.offset + ym * info.width + xm]


@wp.struct
class _Patch:
    """The bilinear filter's texel (ix, iy) below and left of a point and the point's fractions (fx, fy) past it."""

    ix: int
    iy: int
    fx: float
    fy: float


@wp.func
def _patch(info: TextureInfo, uv: wp.vec2) -> _Patch:
    x = uv[0] * float(info.width) - 0.5
    y = uv[1] * float(info.height) - 0.5
    q = _Patch()
    q.ix = int(wp.floor(x))
    q.iy = int(wp.floor(y))
    q.fx = x - wp.floor(x)
    q.fy = y - wp.floor(y)
    return q


@wp.func
def texture_lookup(ts: TextureSet, texture: int, uv_in: wp.vec2) -> wp.vec3:
    """Texture ``texture`` at ``to_uv · uv``: a checkerboard's colour, or a bitmap's bilinear (or nearest), wrapped value."""
    info = ts.info[texture]
    h = wp.vec3(uv_in[0], uv_in[1], 1.0)
    uv = wp.vec2(wp.dot(info.uv_row0, h), wp.dot(info.uv_row1, h))
    if info.kind == TEXTURE_CHECKERBOARD:
        if _checker_even(uv):
            return info.color0
        return info.color1
    if info.nearest != 0:
        return _texel(ts, info, int(wp.floor(uv[0] * float(info.width))), int(wp.floor(uv[1] * float(info.height))))
    q = _patch(info, uv)
    a = _texel(ts, info, q.ix, q.iy) * (1.0 - q.fx) + _texel(ts, info, q.ix + 1, q.iy) * q.fx
    b = _texel(ts, info, q.ix, q.iy + 1) * (1.0 - q.fx) + _texel(ts, info, q.ix + 1, q.iy + 1) * q.fx
    return a * (1.0 - q.fy) + b * q.fy


@wp.func
def _checker_even(uv: wp.vec2) -> bool:
    # whether the fractional parts of u and v are both above ½ or both at most ½ (checkerboard.cpp)
    return (uv[0] - wp.floor(uv[0]) > 0.5) == (uv[1] - wp.floor(uv[1]) > 0.5)


@wp.func
def texture_lookup_1(ts: TextureSet, texture: int, uv_in: wp.vec2) -> float:
    """A scalar texture value at ``uv_in`` as Mitsuba's ``eval_1`` gives it: the luminance of :func:`texture_lookup`,
    except that a checkerboard's ``eval_1`` picks its colours the other way round from its ``eval`` (``color0``
    where exactly one of u, v has its fractional part above ½; ``checkerboard.cpp``), which grisx keeps so as to
    render what Mitsuba renders (a mask's opacity, a blend's weight, a roughconductor's textured α)."""
    info = ts.info[texture]
    if info.kind == TEXTURE_CHECKERBOARD:
        h = wp.vec3(uv_in[0], uv_in[1], 1.0)
        if _checker_even(wp.vec2(wp.dot(info.uv_row0, h), wp.dot(info.uv_row1, h))):
            return luminance(info.color1)
        return luminance(info.color0)
    return luminance(texture_lookup(ts, texture, uv_in))


@wp.func
def texture_gradient(ts: TextureSet, texture: int, uv_in: wp.vec2) -> wp.vec2:
    """(∂/∂u, ∂/∂v) of the luminance of ``texture_lookup(ts, texture, uv)``: the bilinear patch's slopes in
    texels through the transpose of ``to_uv``'s linear part, times the resolution (Mitsuba's ``eval_1_grad``,
    formula for formula: exact for a ``to_uv`` that scales and shifts, as Mitsuba's is)."""
    info = ts.info[texture]
    if info.kind != TEXTURE_BITMAP or info.nearest != 0:
        return wp.vec2(0.0, 0.0)  # piecewise constant (a checkerboard, a nearest lookup) or not over uv
    h = wp.vec3(uv_in[0], uv_in[1], 1.0)
    q = _patch(info, wp.vec2(wp.dot(info.uv_row0, h), wp.dot(info.uv_row1, h)))
    f00 = luminance(_texel(ts, info, q.ix, q.iy))
    f10 = luminance(_texel(ts, info, q.ix + 1, q.iy))
    f01 = luminance(_texel(ts, info, q.ix, q.iy + 1))
    f11 = luminance(_texel(ts, info, q.ix + 1, q.iy + 1))
    dx = (1.0 - q.fy) * (f10 - f00) + q.fy * (f11 - f01)
    dy = (1.0 - q.fx) * (f01 - f00) + q.fx * (f11 - f10)
    return wp.vec2((info.uv_row0[0] * dx + info.uv_row1[0] * dy) * float(info.width),
                   (info.uv_row0[1] * dx + info.uv_row1[1] * dy) * float(info.height))


@wp.func
def attribute_lookup(ts: TextureSet, texture: int, tri: int, corners: wp.vec3i, b: wp.vec3) -> wp.vec3:
    """Mesh-attribute texture ``texture`` at barycentrics ``b`` of triangle ``tri`` (scene vertices ``corners``):
    a face attribute's row ``tri``, or the blend of a vertex attribute's rows (Mitsuba's ``interpolate_attribute``)."""
    info = ts.info[texture]
    if info.width == 1:
        return ts.texels[info.offset + tri]
    a0 = ts.texels[info.offset + corners[0]]
    a1 = ts.texels[info.offset + corners[1]]
    a2 = ts.texels[info.offset + corners[2]]
    return a0 * b[0] + a1 * b[1] + a2 * b[2]


def _to_uv(m: object, i: int) -> np.ndarray:
    a = np.asarray(m, dtype=np.float64)
    if a.shape != (2, 3) or not np.all(np.isfinite(a)):
        raise InvalidValueError(f"texture {i}: to_uv must be a finite 2x3 affine map, got {m!r}")
    return a


def pack_textures(textures: list, device: wp.context.Device) -> TextureSet:
    """Pack textures — linear RGB images (H, W, 3), :class:`Bitmap`, :class:`Checkerboard` or
    :class:`AttributeTexels` records — into one device atlas."""
    infos = []
    chunks = []
    offset = 0
    for i, tex in enumerate(textures):
        if isinstance(tex, MeshAttribute):
            raise InvalidValueError(f"texture {i}: a mesh attribute ('{tex.name}') is resolved by Scene.build, not packed by itself")
        if isinstance(tex, AttributeTexels):
            a = np.asarray(tex.values, dtype=np.float32).reshape(-1, 3)
            if not np.all(np.isfinite(a)) or np.any(a < 0):
                raise InvalidValueError(f"texture {i}: mesh attribute values must be finite and non-negative")
            infos.append((int(TEXTURE_MESH_ATTRIBUTE), offset, int(bool(tex.per_face)), len(a), np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3), 0, 0))
            chunks.append(a)
            offset += len(a)
            continue
        if isinstance(tex, Checkerboard):
            colours = np.asarray([tex.color0, tex.color1], dtype=np.float64)
            if colours.shape != (2, 3) or not np.all(np.isfinite(colours)) or np.any(colours < 0):
                raise InvalidValueError(f"texture {i}: checkerboard colours must be finite, non-negative RGB, got {tex.color0}, {tex.color1}")
            uv = _to_uv(tex.to_uv, i)
            infos.append((int(TEXTURE_CHECKERBOARD), 0, 1, 1, uv[0], uv[1], colours[0], colours[1], 0, 0))
            continue
        img, uv = (tex.image, _to_uv(tex.to_uv, i)) if isinstance(tex, Bitmap) else (tex, np.asarray(IDENTITY_UV))
        wrap, filt = (tex.wrap_mode, tex.filter_type) if isinstance(tex, Bitmap) else ("repeat", "bilinear")
        if wrap not in WRAP_MODES or filt not in FILTER_TYPES:
            raise InvalidValueError(f"texture {i}: wrap_mode must be one of {sorted(WRAP_MODES)} and filter_type one of "
                                    f"{sorted(FILTER_TYPES)}, got {wrap!r}, {filt!r}")
        a = np.asarray(img, dtype=np.float32)
        if a.ndim == 2:
            a = np.repeat(a[:, :, None], 3, axis=2)
        if a.ndim != 3 or a.shape[2] not in (3, 4) or a.shape[0] < 1 or a.shape[1] < 1:
            raise InvalidValueError(f"texture {i}: expected an (H, W, 3) image, got shape {a.shape}")
        a = a[:, :, :3]
        if not np.all(np.isfinite(a)) or np.any(a < 0):
            raise InvalidValueError(f"texture {i}: texels must be finite and non-negative")
        infos.append((int(TEXTURE_BITMAP), offset, a.shape[1], a.shape[0], uv[0], uv[1], np.zeros(3), np.zeros(3),
                      WRAP_MODES[wrap], FILTER_TYPES[filt]))
        chunks.append(a.reshape(-1, 3))
        offset += a.shape[0] * a.shape[1]
    ts = TextureSet()
    data = np.concatenate(chunks) if chunks else np.zeros((1, 3), dtype=np.float32)
    ts.texels = wp.array(data, dtype=wp.vec3, device=device)
    records = []
    for kind, off, w, hgt, row0, row1, c0, c1, wrap_id, nearest in infos or [(int(TEXTURE_BITMAP), 0, 1, 1, (1, 0, 0), (0, 1, 0), (0, 0, 0), (0, 0, 0), 0, 0)]:
        t = TextureInfo()
        t.kind, t.offset, t.width, t.height = kind, off, w, hgt
        t.uv_row0, t.uv_row1 = wp.vec3(*map(float, row0)), wp.vec3(*map(float, row1))
        t.color0, t.color1 = wp.vec3(*map(float, c0)), wp.vec3(*map(float, c1))
        t.wrap, t.nearest = wrap_id, nearest
        records.append(t)
    ts.info = wp.array(records, dtype=TextureInfo, device=device)
    ts.count = len(textures)
    return ts
