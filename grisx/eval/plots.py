"""Figures of the evaluation layer: error against time, image grids with insets, (x, t) plots.

All figures are drawn with matplotlib's object-oriented API on an Agg canvas
(no pyplot, so no global backend state is touched) and written as PNG
atomically (a temporary file renamed into place).

* :func:`plot_error_vs_time` — log-log error of each method against seconds.
* :func:`plot_image_grid` — reference and each method's image (sRGB), a
  highlighted inset window zoomed below each, and a per-pixel error map.
* :func:`plot_xt` — one scanline of every frame stacked top to bottom: rows
  are consecutive frames, so temporal correlation shows as vertical streaks
  and spatial correlation as horizontal ones (seed 001, Fig. 1).
"""

from __future__ import annotations

import io
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from grisx.eval.files import write_atomic
from grisx.eval.metrics import to_srgb
from grisx.theory.gris import LUMINANCE_WEIGHTS

__all__ = ["display_exposure", "plot_error_vs_time", "plot_image_grid", "plot_xt", "choose_inset"]


def _figure(width: float, height: float):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=110)
    FigureCanvasAgg(fig)
    return fig


def _save(fig, path: str | os.PathLike) -> Path:
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return write_atomic(path, buf.getvalue())


def _luminance(img: np.ndarray) -> np.ndarray:
    if img.ndim == 2:
        return img
    if img.shape[2] >= 3:
        return img[..., :3] @ np.asarray(LUMINANCE_WEIGHTS)  # the one luminance (Rec. 709, Mitsuba's weights)
    return img[..., 0]


def display_exposure(reference: np.ndarray) -> float:
    """Exposure (stops) that maps the reference's 99th-percentile luminance to 1 (never brightens above ×1 for black)."""
    p = float(np.percentile(_luminance(np.asarray(reference, dtype=np.float64)), 99))
    return float(-np.log2(p)) if p > 0 else 0.0


def _show(img: np.ndarray, exposure: float) -> np.ndarray:
    rgb = to_srgb(img, exposure)
    if rgb.ndim == 3 and rgb.shape[2] == 1:
        rgb = rgb[..., 0]
    if rgb.ndim == 3 and rgb.shape[2] > 3:
        rgb = rgb[..., :3]
    return rgb


def plot_error_vs_time(
    curves: Mapping[str, tuple[Sequence[float], Sequence[float]]],
    path: str | os.PathLike,
    *,
    metric: str = "relmse",
    title: str = "",
    budget: float | None = None,
) -> Path:
    """Log-log plot of ``metric`` against seconds, one line per method (label → (seconds, errors))."""
    fig = _figure(6.0, 4.2)
    ax = fig.add_subplot()
    for label, (secs, errs) in curves.items():
        s, e = np.asarray(secs, dtype=float), np.asarray(errs, dtype=float)
        keep = (s > 0) & (e > 0) & np.isfinite(s) & np.isfinite(e)
        if keep.any():
            ax.plot(s[keep], e[keep], marker="o", markersize=3, label=label)
    ax.set_xscale("log")
    ax.set_yscale("log")
    from matplotlib.ticker import NullFormatter

    ax.xaxis.set_minor_formatter(NullFormatter())  # labelled minor ticks collide on short ranges
    if budget is not None:
        ax.axvline(budget, color="0.5", linestyle=":", linewidth=1, label="time budget")
    ax.set_xlabel("seconds")
    ax.set_ylabel(metric)
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    if curves:
        ax.legend(fontsize=8)
    fig.tight_layout()
    return _save(fig, path)


def choose_inset(reference: np.ndarray, images: Sequence[np.ndarray], size: int | None = None) -> tuple[int, int, int, int]:
    """(y, x, h, w) of the square window where the methods' summed squared error is largest."""
    h, w = reference.shape[:2]
    size = size or max(4, min(h, w) // 4)
    size = min(size, h, w)
    err = np.zeros((h, w))
    for img in images:
        d = (np.asarray(img, dtype=np.float64) - reference) ** 2
        err += d if d.ndim == 2 else d.sum(axis=2)
    # box sums through a summed-area table
    sat = np.pad(err.cumsum(0).cumsum(1), ((1, 0), (1, 0)))
    box = sat[size:, size:] - sat[:-size, size:] - sat[size:, :-size] + sat[:-size, :-size]
    y, x = np.unravel_index(int(np.argmax(box)), box.shape)
    return int(y), int(x), size, size


def plot_image_grid(
    reference: np.ndarray,
    images: Mapping[str, np.ndarray],
    path: str | os.PathLike,
    *,
    error_maps: Mapping[str, np.ndarray] | None = None,
    error_label: str = "relative squared error",
    error_range: tuple[float, float] | None = None,
    inset: tuple[int, int, int, int] | None = None,
    exposure: float | None = None,
    captions: Mapping[str, str] | None = None,
    title: str = "",
) -> Path:
    """Reference + methods (sRGB) with a marked inset, the zoomed insets, and error maps below."""
    from matplotlib.patches import Rectangle

    ref = np.asarray(reference, dtype=np.float64)
    exposure = display_exposure(ref) if exposure is None else exposure
    labels = ["reference", *images]
    pics = [ref, *[np.asarray(images[k], dtype=np.float64) for k in images]]
    y0, x0, ih, iw = inset or choose_inset(ref, pics[1:])
    rows = 3 if error_maps else 2
    n = len(labels)
    aspect = ref.shape[0] / ref.shape[1]
    fig = _figure(2.6 * n, 2.6 * aspect + 2.6 + (2.6 * aspect if error_maps else 0) + 0.6)
    axes = fig.subplots(rows, n, squeeze=False)
    # one colour scale for every method: the given range (FLIP: [0, 1]) or the 99th percentile of all maps
    vmin, vmax = error_range if error_range else (0.0, None)
    if error_maps and error_range is None:
        stacked = np.concatenate([np.ravel(m) for m in error_maps.values()])
        vmax = float(np.percentile(stacked, 99)) or None
    for j, (label, img) in enumerate(zip(labels, pics)):
        shown = _show(img, exposure)
        ax = axes[0, j]
        ax.imshow(shown, interpolation="nearest")
        ax.add_patch(Rectangle((x0 - 0.5, y0 - 0.5), iw, ih, fill=False, edgecolor="#ff3030", linewidth=1.2))
        caption = (captions or {}).get(label, "")
        ax.set_title(label + (f"\n{caption}" if caption else ""), fontsize=8)
        axes[1, j].imshow(shown[y0 : y0 + ih, x0 : x0 + iw], interpolation="nearest")
        if error_maps:
            if label in error_maps:
                im = axes[2, j].imshow(error_maps[label], cmap="magma", vmin=vmin, vmax=vmax, interpolation="nearest")
            else:
                axes[2, j].text(0.5, 0.5, error_label, ha="center", va="center", fontsize=8, wrap=True,
                                transform=axes[2, j].transAxes)
        for r in range(rows):
            axes[r, j].set_xticks([])
            axes[r, j].set_yticks([])
    if error_maps and len(error_maps):
        fig.colorbar(im, ax=axes[2, :].tolist(), shrink=0.8, fraction=0.03)
    fig.suptitle(f"{title}   (exposure {exposure:+.2f} EV, inset y={y0} x={x0} {iw}x{ih})", fontsize=9)
    return _save(fig, path)


def plot_xt(
    rows: Mapping[str, np.ndarray],
    path: str | os.PathLike,
    *,
    scanline: int,
    exposure: float = 0.0,
    title: str = "",
) -> Path:
    """(x, t) plots: label → (frames, W[, C]) array of one scanline per frame, frame 0 at the top."""
    n = max(1, len(rows))
    fig = _figure(3.2 * n, 3.6)
    axes = fig.subplots(1, n, squeeze=False)[0]
    for ax, (label, xt) in zip(axes, rows.items()):
        ax.imshow(_show(np.asarray(xt, dtype=np.float64), exposure), aspect="auto", interpolation="nearest")
        ax.set_title(label, fontsize=8)
        ax.set_xlabel("x")
        ax.set_ylabel("frame t")
    fig.suptitle(f"{title}   scanline y = {scanline}, one row per frame (vertical streaks = temporal correlation)", fontsize=9)
    fig.tight_layout()
    return _save(fig, path)
