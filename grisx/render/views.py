"""Debug views of the G-buffer: ``grisx render SCENE --method albedo|normal|depth|motion|gbuffer``."""

from __future__ import annotations

from typing import Any

import numpy as np

from grisx.render.base.registry import RenderMethod, register
from grisx.scene.gbuffer import GBuffer
from grisx.scene.scene import BuiltScene

__all__ = ["GBufferView", "create_view", "display_image"]


class GBufferView:
    """Fills the G-buffer each frame and returns one field as an image."""

    def __init__(self, built: BuiltScene, width: int, height: int, view: str, timer: Any) -> None:
        self.built = built
        self.view = view
        self.timer = timer
        self.gbuffer = GBuffer(width, height, built.device)

    def kernels(self) -> list[Any]:
        return [self.gbuffer.kernel(self.built)]

    def render_frame(self, frame: int) -> np.ndarray:
        with self.timer("gbuffer"):
            self.gbuffer.fill(self.built, float(frame))
        if self.view == "gbuffer":  # every field is written out: read them all back
            self._fields = self.gbuffer.numpy()
            return _as_rgb(self._fields["albedo"])
        return _as_rgb(getattr(self.gbuffer.current, self.view).numpy())  # only the field shown

    def extra(self) -> dict[str, np.ndarray]:
        if self.view != "gbuffer":
            return {}
        return {name: _as_rgb(a) if a.ndim == 3 else a.astype(np.float32) for name, a in self._fields.items()}


def _as_rgb(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, dtype=np.float32)
    if a.ndim == 2:
        return np.repeat(a[:, :, None], 3, axis=2)
    if a.shape[2] == 2:
        return np.concatenate([a, np.zeros_like(a[:, :, :1])], axis=2)
    return a


def create_view(ctx: Any) -> GBufferView:
    return GBufferView(ctx.built, ctx.width, ctx.height, ctx.method, ctx.timer)


def display_image(view: str, image: np.ndarray) -> tuple[np.ndarray, bool]:
    """A display-referred version of a view for the PNG, and whether it still needs sRGB encoding."""
    a = np.asarray(image, dtype=np.float64)
    if view == "normal":
        return np.where(np.any(a != 0, axis=-1, keepdims=True), a * 0.5 + 0.5, 0.0), False
    if view == "depth":
        d = a[..., 0]
        valid = d > 0
        out = np.zeros_like(d)
        if valid.any():
            lo, hi = d[valid].min(), d[valid].max()
            out[valid] = 1.0 - 0.85 * (d[valid] - lo) / max(hi - lo, 1e-12)
        return np.repeat(out[..., None], 3, axis=2), False
    if view == "motion":
        # hue = direction, brightness = length relative to the largest motion
        dx, dy = a[..., 0], a[..., 1]
        mag = np.hypot(dx, dy)
        scale = max(float(mag.max()), 1.0)  # sub-pixel motions stay dark
        ang = np.arctan2(dy, dx)
        rgb = np.stack([0.5 + 0.5 * np.cos(ang), 0.5 + 0.5 * np.cos(ang - 2.094), 0.5 + 0.5 * np.cos(ang + 2.094)], axis=-1)
        v = (mag / scale)[..., None]
        return rgb * v, False
    if view in ("material", "tri", "hit"):
        ids = a[..., 0].astype(np.int64)
        rng = np.random.default_rng(7)
        palette = rng.uniform(0.15, 1.0, size=(int(ids.max(initial=0)) + 2, 3))
        return np.where((ids >= 0)[..., None], palette[np.maximum(ids, 0)], 0.0), False
    return a, True


# ---- registration (grisx.render.base.registry): the method, its params (defaults: the constructor's) ----

for _view, _doc in (
    ("gbuffer", "every G-buffer field (one EXR per field) and a contact sheet PNG"),
    ("albedo", "albedo at the primary hit"),
    ("normal", "shading normal at the primary hit (n/2 + 1/2 in the PNG)"),
    ("depth", "camera-space depth of the primary hit"),
    ("motion", "motion vector into the previous frame, in pixels (EXR: dx, dy, 0)"),
):
    register(RenderMethod(_view, _doc, create_view, kind="debug"))
