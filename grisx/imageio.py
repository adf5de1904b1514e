"""Linear float images on disk: OpenEXR read and write.

grisx keeps data images (renders, primal and gradient buffers, references) as
linear float32 OpenEXR files, read and written with the ``OpenEXR`` package
[OpenEXR]. Arrays are indexed ``[y, x]`` or ``[y, x, c]`` with row 0 at the top
of the image, as in the file's data window.

Channel layout
--------------
* ``(H, W)`` or ``(H, W, 1)`` ↔ one channel named ``Y`` (on reading, any single
  channel is accepted, whatever its name);
* ``(H, W, 3)`` ↔ ``R``, ``G``, ``B``; ``(H, W, 4)`` ↔ ``R``, ``G``, ``B``, ``A``.

:func:`write_exr_layers` writes several images into one file as named layers
(``albedo.R``, ``albedo.G``, ``albedo.B``, ``depth.Y``, ...), as Mitsuba's AOV
files do; :func:`read_exr` reads single images only.

Half and uint channels are converted to float32 on reading. Other layouts
(several unnamed channels, layers) raise :class:`~grisx.errors.GrisxError`
naming the channels found. Writing goes to a temporary file in the target
directory that is renamed into place, so a failed write leaves nothing
half-written behind.

References
----------
[OpenEXR] Academy Software Foundation, OpenEXR file format and Python
          bindings, https://openexr.com (``OpenEXR.File``).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from grisx.errors import GrisxError

__all__ = ["read_exr", "write_exr", "write_exr_layers", "write_png", "check_writable_dir", "srgb_encode", "srgb_decode"]


def _openexr():
    try:
        import OpenEXR
    except ImportError as exc:  # a declared dependency, but say so clearly
        raise GrisxError(f"reading/writing EXR needs the OpenEXR package (pip install OpenEXR): {exc}") from None
    return OpenEXR


def read_exr(path: str | os.PathLike) -> np.ndarray:
    """Read an EXR file into a float32 array of shape (H, W) or (H, W, C)."""
    OpenEXR = _openexr()
    path = Path(path)
    if not path.is_file():
        raise GrisxError(f"cannot read EXR '{path}': no such file")
    try:
        with OpenEXR.File(str(path), separate_channels=True) as f:
            channels = {name: np.asarray(ch.pixels) for name, ch in f.channels().items()}
    except Exception as exc:  # OpenEXR raises RuntimeError/ValueError with its own text
        raise GrisxError(f"cannot read EXR '{path}': {exc}") from None
    names = set(channels)
    if len(names) == 1:
        return np.ascontiguousarray(next(iter(channels.values())), dtype=np.float32)
    for layout in (("R", "G", "B", "A"), ("R", "G", "B")):
        if names == set(layout):
            return np.ascontiguousarray(np.stack([channels[n] for n in layout], axis=-1), dtype=np.float32)
    raise GrisxError(f"cannot read EXR '{path}': unsupported channels {sorted(names)} "
                     f"(expected one channel, R,G,B or R,G,B,A)")


def _exr_planes(path: Path, array: np.ndarray, layer: str = "") -> dict[str, np.ndarray]:
    """``array``'s channels by EXR name (``Y``; ``R``, ``G``, ``B`` [, ``A``]), each prefixed ``layer.`` if given."""
    a = np.asarray(array)
    if a.dtype.kind not in "fiub":
        raise GrisxError(f"cannot write EXR '{path}': array must hold real numbers, got dtype {a.dtype}")
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[:, :, 0]
    if a.ndim == 2:
        names: tuple[str, ...] = ("Y",)
        planes = [a]
    elif a.ndim == 3 and a.shape[2] in (3, 4):
        names = ("R", "G", "B", "A")[: a.shape[2]]
        planes = [a[:, :, i] for i in range(a.shape[2])]
    else:
        raise GrisxError(f"cannot write EXR '{path}': shape {a.shape} is not (H, W) or (H, W, 1|3|4)")
    if a.shape[0] == 0 or a.shape[1] == 0:
        raise GrisxError(f"cannot write EXR '{path}': image is empty (shape {a.shape})")
    prefix = f"{layer}." if layer else ""
    return {prefix + n: np.ascontiguousarray(p, dtype=np.float32) for n, p in zip(names, planes)}


def write_exr(path: str | os.PathLike, array: np.ndarray) -> Path:
    """Write ``array`` ((H, W) or (H, W, 1|3|4)) as a float32 ZIP-compressed EXR; return the path."""
    path = Path(path)
    return _write_channels(path, _exr_planes(path, array))


def write_exr_layers(path: str | os.PathLike, layers: dict[str, np.ndarray]) -> Path:
    """Write several same-sized images into one EXR, each a named layer (``albedo.R``, ``depth.Y``, ...).

    :func:`read_exr` reads single images only; OpenEXR tools (and Mitsuba's AOV files) show the layers.
    """
    path = Path(path)
    channels: dict[str, np.ndarray] = {}
    for name, array in layers.items():
        channels.update(_exr_planes(path, array, name))
    if len({c.shape for c in channels.values()}) > 1:
        raise GrisxError(f"cannot write EXR '{path}': layers of different sizes")
    return _write_channels(path, channels)


def _write_channels(path: Path, channels: dict[str, np.ndarray]) -> Path:
    OpenEXR = _openexr()
    if not path.parent.is_dir():
        raise GrisxError(f"cannot write EXR '{path}': directory '{path.parent}' does not exist")
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp.exr", dir=path.parent)
    os.close(fd)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the file the usual permissions
    try:
        with OpenEXR.File(header, channels) as f:
            f.write(tmp)
        os.replace(tmp, path)
    except Exception as exc:
        Path(tmp).unlink(missing_ok=True)
        raise GrisxError(f"cannot write EXR '{path}': {exc}") from None
    return path


def check_writable_dir(folder: str | os.PathLike, what: str) -> None:
    """Raise a one-line :class:`~grisx.errors.GrisxError` unless a file can be created in ``folder``.

    It creates and removes a temporary file there: permission bits do not tell (root, read-only mounts,
    immutable directories, ``/proc``), so this is how an output is checked before the work that makes it.
    """
    try:
        fd, tmp = tempfile.mkstemp(prefix=".grisx-write-check.", dir=folder)
    except OSError as exc:
        raise GrisxError(f"{what}: cannot write in '{folder}': {exc.strerror or exc}") from None
    os.close(fd)
    os.unlink(tmp)


def srgb_decode(encoded: np.ndarray) -> np.ndarray:
    """sRGB-encoded values in [0, 1] → linear (IEC 61966-2-1), as Mitsuba linearises 8-bit bitmaps."""
    c = np.asarray(encoded, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    """The sRGB transfer curve (IEC 61966-2-1) of linear values clipped to [0, 1]."""
    x = np.clip(np.nan_to_num(np.asarray(linear, dtype=np.float64), nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def write_png(path: str | os.PathLike, linear: np.ndarray, exposure: float = 0.0, encode: bool = True) -> Path:
    """Write a linear image as an 8-bit sRGB PNG (clip after scaling by 2^exposure).

    ``encode=False`` writes values in [0, 1] as they are (for false-colour
    views that are already display-referred). Written to a temporary file and
    renamed into place.
    """
    from PIL import Image

    path = Path(path)
    a = np.asarray(linear, dtype=np.float64)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[:, :, 0]
    if not (a.ndim == 2 or (a.ndim == 3 and a.shape[2] in (3, 4))):
        raise GrisxError(f"cannot write PNG '{path}': shape {a.shape} is not (H, W) or (H, W, 3|4)")
    if a.ndim == 3 and a.shape[2] == 4:
        a = a[:, :, :3]
    a = a * (2.0**exposure)
    out = srgb_encode(a) if encode else np.clip(np.nan_to_num(a), 0.0, 1.0)
    img = Image.fromarray(np.round(out * 255).astype(np.uint8))
    if not path.parent.is_dir():
        raise GrisxError(f"cannot write PNG '{path}': directory '{path.parent}' does not exist")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp.png", dir=path.parent)
    os.close(fd)
    try:
        img.save(tmp, format="PNG")
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except Exception as exc:
        Path(tmp).unlink(missing_ok=True)
        raise GrisxError(f"cannot write PNG '{path}': {exc}") from None
    return path
