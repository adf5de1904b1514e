"""Mitsuba's ``.serialized`` triangle meshes (file format versions 3 and 4).

A ``.serialized`` file holds one or more meshes, each a little-endian header
(``uint16`` magic ``0x041C``, ``uint16`` version) followed by a zlib stream:

=========================  ==================================================
``uint32`` flags           ``0x0001`` vertex normals, ``0x0002`` uvs,
                           ``0x0008`` vertex colours, ``0x1000`` single /
                           ``0x2000`` double precision
name                       version 4 only: a NUL-terminated UTF-8 string
``uint64`` V, ``uint64`` F vertex and triangle counts
positions                  3V floats (or doubles), then 3V normals, 2V uvs,
                           3V colours where the flags say so
faces                      3F ``uint32`` vertex indices
=========================  ==================================================

The file ends with a dictionary: the byte offset of each mesh (``uint64`` in
version 4, ``uint32`` in version 3) and the ``uint32`` mesh count, so mesh
``shape_index`` is found without inflating the ones before it. Vertex
colours are read past (grisx has no use for them, as Mitsuba's loader).
Version 5 (Mitsuba's packed vertex records) is refused with a clear error.

Reference: Mitsuba 3 plugin documentation, ``serialized`` shape ("Format
description", "End-of-file dictionary").
"""

from __future__ import annotations

import os
import struct
import zlib
from pathlib import Path

import numpy as np

from grisx.errors import GrisxError
from grisx.scene.shapes import MeshData

__all__ = ["load_serialized", "serialized_count"]

MAGIC = 0x041C
_NORMALS, _UVS, _COLORS, _SINGLE, _DOUBLE = 0x0001, 0x0002, 0x0008, 0x1000, 0x2000


def _error(path: Path, what: str) -> GrisxError:
    return GrisxError(f"cannot load mesh '{path}': {what}")


def _header(path: Path, data: bytes, offset: int) -> int:
    if offset + 4 > len(data):
        raise _error(path, f"truncated file (no mesh header at byte {offset})")
    magic, version = struct.unpack_from("<HH", data, offset)
    if magic != MAGIC:
        raise _error(path, f"not a Mitsuba .serialized mesh (magic 0x{magic:04X} at byte {offset}, expected 0x041C)")
    if version not in (3, 4):
        raise _error(path, f"serialized format version {version} is not supported (versions 3 and 4 are; "
                           f"re-export it as PLY)")
    return version


def serialized_count(path: str | os.PathLike) -> int:
    """How many meshes the file holds (its end-of-file dictionary)."""
    path = Path(path)
    data = _read(path)
    _header(path, data, 0)
    return struct.unpack_from("<I", data, len(data) - 4)[0]


def _read(path: Path) -> bytes:
    if not path.is_file():
        raise _error(path, "no such file")
    return path.read_bytes()


def load_serialized(path: str | os.PathLike, shape_index: int = 0) -> MeshData:
    """Mesh ``shape_index`` of a ``.serialized`` file in object space: positions, the file's unit vertex normals
    (``None`` if it has none) and uvs (``None`` if it has none)."""
    path = Path(path)
    data = _read(path)
    version = _header(path, data, 0)
    if len(data) < 8:
        raise _error(path, "truncated file")
    count = struct.unpack_from("<I", data, len(data) - 4)[0]
    if not 0 <= shape_index < count:
        raise _error(path, f"shape_index {shape_index} is out of range (the file holds {count} mesh(es): 0..{count - 1})")
    size = 8 if version == 4 else 4
    table = len(data) - 4 - size * count
    if table < 4:
        raise _error(path, "truncated end-of-file dictionary")
    offset = struct.unpack_from("<Q" if size == 8 else "<I", data, table + size * shape_index)[0]
    if _header(path, data, offset) != version:
        raise _error(path, f"mesh {shape_index} has another format version than the file")
    try:
        stream = zlib.decompressobj().decompress(data[offset + 4:table])
    except zlib.error as exc:
        raise _error(path, f"mesh {shape_index}: corrupt zlib stream ({exc})") from None
    return _parse(path, shape_index, stream, version)


def _parse(path: Path, index: int, s: bytes, version: int) -> MeshData:
    pos = 0

    def take(n: int) -> bytes:
        nonlocal pos
        if pos + n > len(s):
            raise _error(path, f"mesh {index}: truncated data")
        out = s[pos:pos + n]
        pos += n
        return out

    flags = struct.unpack("<I", take(4))[0]
    if version == 4:
        end = s.find(b"\0", pos)
        if end < 0:
            raise _error(path, f"mesh {index}: unterminated name")
        pos = end + 1
    nv, nf = struct.unpack("<QQ", take(16))
    dtype = np.dtype("<f8") if flags & _DOUBLE else np.dtype("<f4")

    def floats(dim: int) -> np.ndarray:
        return np.frombuffer(take(nv * dim * dtype.itemsize), dtype=dtype).reshape(nv, dim).astype(np.float64)

    vertices = floats(3)
    normals = floats(3) if flags & _NORMALS else None
    uvs = floats(2) if flags & _UVS else None
    if flags & _COLORS:
        floats(3)
    faces = np.frombuffer(take(nf * 12), dtype="<u4").reshape(nf, 3).astype(np.int64)
    if nf == 0:
        raise _error(path, f"mesh {index}: no triangles")
    if faces.max() >= nv:
        raise _error(path, f"mesh {index}: a face index ({int(faces.max())}) is out of range (V = {nv})")
    if not np.all(np.isfinite(vertices)):
        raise _error(path, f"mesh {index}: invalid vertex position data")
    if normals is not None:
        length = np.linalg.norm(normals, axis=1, keepdims=True)
        if np.any(length == 0) or not np.all(np.isfinite(normals)):
            raise _error(path, f"mesh {index}: zero-length or invalid vertex normal")
        normals = normals / length
    return MeshData(vertices, faces, normals, uvs)
