"""grisx.imageio: EXR round trips, channel layouts, and errors that leave nothing behind."""

from __future__ import annotations

import numpy as np
import OpenEXR
import pytest
from numpy.testing import assert_array_equal

from grisx.errors import GrisxError
from grisx.imageio import read_exr, write_exr


@pytest.mark.parametrize("shape,names", [((5, 7), ["Y"]), ((5, 7, 1), ["Y"]), ((4, 3, 3), ["B", "G", "R"]),
                                         ((2, 6, 4), ["A", "B", "G", "R"]), ((1, 1, 3), ["B", "G", "R"])])
def test_round_trip_is_bit_exact_for_float32(tmp_path, shape, names):
    a = np.random.default_rng(0).standard_normal(shape).astype(np.float32)
    a.flat[0] = np.nan  # data images may carry NaN/Inf; EXR stores them
    a.flat[-1] = np.inf
    path = write_exr(tmp_path / "a.exr", a)
    with OpenEXR.File(str(path)) as f:
        assert sorted(f.channels()) == names or sorted(f.channels()) == ["RGB" if len(names) == 3 else "RGBA"] \
            or sorted(f.header()["channels"][i].name for i in range(len(names))) == names
    b = read_exr(path)
    assert b.dtype == np.float32
    assert b.shape == (shape if len(shape) == 2 or shape[2] != 1 else shape[:2])
    assert_array_equal(b, a.reshape(b.shape))  # float32 in, float32 out: bit-exact (NaN == NaN here)
    assert list(tmp_path.iterdir()) == [path]  # no temporary file left behind


def test_float64_and_int_are_written_as_float32(tmp_path):
    a = np.arange(12, dtype=np.int64).reshape(3, 4)
    assert_array_equal(read_exr(write_exr(tmp_path / "i.exr", a)), a.astype(np.float32))
    b = np.array([[1.0 / 3.0]])
    assert read_exr(write_exr(tmp_path / "d.exr", b))[0, 0] == np.float32(1.0 / 3.0)


def test_half_channel_is_read_as_float32(tmp_path):
    half = np.array([[0.5, 2.0], [-1.0, 65504.0]], dtype=np.float16)
    path = str(tmp_path / "h.exr")
    header = {"compression": OpenEXR.NO_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {"Z": half}) as f:
        f.write(path)
    b = read_exr(path)
    assert b.dtype == np.float32
    assert_array_equal(b, half.astype(np.float32))


def test_unsupported_channel_layout(tmp_path):
    path = str(tmp_path / "xy.exr")
    header = {"compression": OpenEXR.NO_COMPRESSION, "type": OpenEXR.scanlineimage}
    chans = {"U": np.zeros((2, 2), np.float32), "V": np.zeros((2, 2), np.float32)}
    with OpenEXR.File(header, chans) as f:
        f.write(path)
    with pytest.raises(GrisxError, match=r"unsupported channels \['U', 'V'\]"):
        read_exr(path)


def test_missing_and_malformed_files(tmp_path):
    with pytest.raises(GrisxError, match="no such file"):
        read_exr(tmp_path / "missing.exr")
    junk = tmp_path / "junk.exr"
    junk.write_bytes(b"not an exr at all")
    with pytest.raises(GrisxError, match="cannot read EXR"):
        read_exr(junk)
    truncated = tmp_path / "trunc.exr"
    data = write_exr(tmp_path / "ok.exr", np.ones((64, 64, 3), np.float32)).read_bytes()
    truncated.write_bytes(data[: len(data) // 2])
    with pytest.raises(GrisxError, match="cannot read EXR"):
        read_exr(truncated)


@pytest.mark.parametrize("bad,msg", [
    (np.zeros((2, 2, 2)), r"shape \(2, 2, 2\)"),
    (np.zeros(4), r"shape \(4,\)"),
    (np.zeros((0, 3)), "empty"),
    (np.zeros((2, 2), dtype=complex), "real numbers"),
])
def test_write_rejects_bad_arrays(tmp_path, bad, msg):
    with pytest.raises(GrisxError, match=msg):
        write_exr(tmp_path / "bad.exr", bad)
    assert list(tmp_path.iterdir()) == []


def test_write_into_missing_directory(tmp_path):
    with pytest.raises(GrisxError, match="does not exist"):
        write_exr(tmp_path / "no" / "dir.exr", np.zeros((2, 2)))
