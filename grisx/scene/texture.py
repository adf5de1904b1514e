"""Albedo textures: one flat RGB atlas on the device, bilinear lookups with wrap-around.

Every texture registered on a :class:`~grisx.scene.scene.Scene` is packed
into one ``wp.array(dtype=wp.vec3)`` with a :class:`TextureInfo` record
(offset, width, height) per texture, so kernels carry a single struct
whatever the number of textures. Texels are linear RGB, row 0 at the top of
the image; ``uv = (0, 0)`` is the top-left corner of texel (0, 0), as in
Mitsuba's ``bitmap`` (bilinear filter, ``repeat`` wrap mode).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from grisx.errors import InvalidValueError

wp.set_module_options({"enable_backward": False})

__all__ = ["TextureInfo", "TextureSet", "texture_lookup", "pack_textures"]


@wp.struct
class TextureInfo:
    offset: int
    width: int
    height: int


@wp.struct
class TextureSet:
    texels: wp.array(dtype=wp.vec3)
    info: wp.array(dtype=TextureInfo)
    count: int


@wp.func
def _texel(ts: TextureSet, info: TextureInfo, x: int, y: int) -> wp.vec3:
    xm = ((x % info.width) + info.width) % info.width
    ym = ((y % info.height) + info.height) % info.height
    return ts.texels[info.offset + ym * info.width + xm]


@wp.func
def texture_lookup(ts: TextureSet, texture: int, uv: wp.vec2) -> wp.vec3:
    """Bilinear, wrap-around lookup of texture ``texture`` at ``uv``."""
    info = ts.info[texture]
    x = uv[0] * float(info.width) - 0.5
    y = uv[1] * float(info.height) - 0.5
    x0 = wp.floor(x)
    y0 = wp.floor(y)
    fx = x - x0
    fy = y - y0
    ix = int(x0)
    iy = int(y0)
    a = _texel(ts, info, ix, iy) * (1.0 - fx) + _texel(ts, info, ix + 1, iy) * fx
    b = _texel(ts, info, ix, iy + 1) * (1.0 - fx) + _texel(ts, info, ix + 1, iy + 1) * fx
    return a * (1.0 - fy) + b * fy


def pack_textures(images: list[np.ndarray], device: wp.context.Device) -> TextureSet:
    """Pack linear RGB images (H, W, 3) into one device atlas."""
    infos = []
    chunks = []
    offset = 0
    for i, img in enumerate(images):
        a = np.asarray(img, dtype=np.float32)
        if a.ndim == 2:
            a = np.repeat(a[:, :, None], 3, axis=2)
        if a.ndim != 3 or a.shape[2] not in (3, 4) or a.shape[0] < 1 or a.shape[1] < 1:
            raise InvalidValueError(f"texture {i}: expected an (H, W, 3) image, got shape {a.shape}")
        a = a[:, :, :3]
        if not np.all(np.isfinite(a)) or np.any(a < 0):
            raise InvalidValueError(f"texture {i}: texels must be finite and non-negative")
        infos.append((offset, a.shape[1], a.shape[0]))
        chunks.append(a.reshape(-1, 3))
        offset += a.shape[0] * a.shape[1]
    ts = TextureSet()
    data = np.concatenate(chunks) if chunks else np.zeros((1, 3), dtype=np.float32)
    ts.texels = wp.array(data, dtype=wp.vec3, device=device)
    info_np = np.array(infos if infos else [(0, 1, 1)], dtype=TextureInfo.numpy_dtype())
    ts.info = wp.array(info_np, dtype=TextureInfo, device=device)
    ts.count = len(images)
    return ts
