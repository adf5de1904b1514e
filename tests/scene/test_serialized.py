"""Mitsuba .serialized meshes (grisx.scene.serialized): files written here by an independent writer, and
mitsuba-data's own test files (tests/scene/data/mitsuba_data)."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np
import pytest

from grisx.errors import GrisxError, SceneFileError
from grisx.scene.mitsuba import load_mitsuba
from grisx.scene.serialized import load_serialized, serialized_count

MD = Path(__file__).parent / "data" / "mitsuba_data" / "serialized"


def write_serialized(path: Path, meshes: list[dict], version: int = 4, double: bool = False) -> Path:
    """The format as Mitsuba's documentation describes it (an oracle independent of the reader)."""
    out, offsets = b"", []
    for m in meshes:
        flags = (0x2000 if double else 0x1000) | (0x1 if "n" in m else 0) | (0x2 if "uv" in m else 0) | (0x8 if "c" in m else 0)
        body = struct.pack("<I", flags) + (m.get("name", "mesh").encode() + b"\0" if version == 4 else b"")
        body += struct.pack("<QQ", len(m["v"]), len(m["f"]))
        for key in ("v", "n", "uv", "c"):
            if key in m:
                body += np.asarray(m[key], dtype="<f8" if double else "<f4").tobytes()
        body += np.asarray(m["f"], dtype="<u4").tobytes()
        offsets.append(len(out))
        out += struct.pack("<HH", 0x041C, version) + zlib.compress(body)
    out += b"".join(struct.pack("<Q" if version == 4 else "<I", o) for o in offsets) + struct.pack("<I", len(meshes))
    path.write_bytes(out)
    return path


TRI = {"v": [[0, 0, 0], [1, 0, 0], [0, 1, 0]], "f": [[0, 1, 2]]}
QUAD = {"v": [[0, 0, 1], [2, 0, 1], [2, 2, 1], [0, 2, 1]], "f": [[0, 1, 2], [0, 2, 3]],
        "n": [[0, 0, 2]] * 4, "uv": [[0, 0], [1, 0], [1, 1], [0, 1]], "c": [[1, 0, 0]] * 4}


@pytest.mark.parametrize("version, double", [(3, False), (4, False), (4, True)])
def test_every_mesh_of_a_file_reads_back(tmp_path, version, double):
    f = write_serialized(tmp_path / "m.serialized", [TRI, QUAD], version=version, double=double)
    assert serialized_count(f) == 2
    a, b = load_serialized(f, 0), load_serialized(f, 1)
    np.testing.assert_array_equal(a.vertices, TRI["v"])
    np.testing.assert_array_equal(a.faces, TRI["f"])
    assert a.normals is None and a.uvs is None
    np.testing.assert_array_equal(b.vertices, QUAD["v"])
    np.testing.assert_array_equal(b.faces, QUAD["f"])
    np.testing.assert_array_equal(b.normals, [[0, 0, 1]] * 4)  # unit length; colours skipped
    np.testing.assert_array_equal(b.uvs, QUAD["uv"])


def test_mitsuba_datas_rectangles():
    # the same rectangle three ways (tests/serialized of mitsuba-data, format version 4)
    full = load_serialized(MD / "rectangle_normals_uv.serialized")
    for name, normals, uvs in (("rectangle_normals_uv", True, True), ("rectangle_uv", False, True)):
        m = load_serialized(MD / f"{name}.serialized")
        assert (m.normals is not None, m.uvs is not None) == (normals, uvs)
        np.testing.assert_array_equal(m.vertices, full.vertices)
        np.testing.assert_array_equal(m.faces, full.faces)
    assert len(full.vertices) == 4 and len(full.faces) == 2
    np.testing.assert_allclose(full.normals, [[0, 1, 0]] * 4)  # a y = 0 rectangle


@pytest.mark.parametrize("mutate, message", [
    (lambda b: b"\x00\x00" + b[2:], "not a Mitsuba .serialized mesh"),
    (lambda b: b[:2] + b"\x05\x00" + b[4:], "version 5 is not supported"),
    (lambda b: b[:4] + b"\x00" * 8 + b[12:], "corrupt zlib stream"),
    (lambda b: b[:-4] + struct.pack("<I", 0), "out of range"),
])
def test_bad_files_are_refused(tmp_path, mutate, message):
    f = write_serialized(tmp_path / "m.serialized", [TRI])
    f.write_bytes(mutate(f.read_bytes()))
    with pytest.raises(GrisxError, match=message):
        load_serialized(f)


def test_the_loader_reads_shape_index_and_names_the_line(tmp_path):
    write_serialized(tmp_path / "m.serialized", [TRI, QUAD])
    xml = ('<scene version="3.0.0">\n<shape type="serialized"><string name="filename" value="m.serialized"/>\n'
           '<integer name="shape_index" value="{}"/>{}</shape>\n</scene>\n')
    (tmp_path / "a.xml").write_text(xml.format(1, '<boolean name="face_normals" value="true"/>'))
    s = load_mitsuba(tmp_path / "a.xml")
    assert s.triangle_count == 2 and s.objects[0].normals is None
    (tmp_path / "b.xml").write_text(xml.format(0, ""))
    s = load_mitsuba(tmp_path / "b.xml")
    assert s.triangle_count == 1 and s.objects[0].normals is not None  # Mitsuba's smooth normals where the file has none
    (tmp_path / "c.xml").write_text(xml.format(2, ""))
    with pytest.raises(SceneFileError, match=r"c\.xml:2: <shape type=\"serialized\"> .*shape_index 2 is out of range"):
        load_mitsuba(tmp_path / "c.xml")
