"""What every screen-space renderer shares: the frame record, one random-key scheme, pixel writes.

A screen-space ReSTIR renderer runs a few passes per frame over the pixels; each reads the
frame's G-buffers (:class:`ScreenFrame`), draws its random numbers from one key per
(seed, frame, pixel, pass) (:func:`pixel_key`, :func:`pixel_key_of`: the same scheme in every
renderer, so runs are reproducible and passes independent), and stores its pixel through
:func:`write_pixel`, which drops and counts a NaN/Inf estimate instead of writing it.
:class:`ScreenSpaceRenderer` holds the host side they share (timed phases, history reset,
the NaN/Inf count) and :func:`kernel_cache` the per-material-set kernel cache.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterable
from typing import Any

import warp as wp

from grisx.scene.gbuffer import GBuffer, GBufferData
from grisx.scene.scene import SurfaceInteraction, finite_or_dropped
from grisx.theory.random import random_key, random_subkey

wp.set_module_options({"enable_backward": False})

__all__ = ["ScreenFrame", "screen_frame", "frame_key", "frame_key_of", "pixel_key", "pixel_key_of", "write_pixel", "visible_normal", "ScreenSpaceRenderer", "kernel_cache", "arg_types"]


@wp.struct
class ScreenFrame:
    """What every pass of a frame reads: the G-buffers of this and the last frame (``si``/``wo``: their visible
    points, for short), seed, frame."""

    g: GBufferData
    g_prev: GBufferData
    si: wp.array2d(dtype=SurfaceInteraction)
    wo: wp.array2d(dtype=wp.vec3)  # unit, visible point → camera
    si_prev: wp.array2d(dtype=SurfaceInteraction)
    wo_prev: wp.array2d(dtype=wp.vec3)
    seed: int
    frame: int


@wp.func
def frame_key_of(seed: int, frame: int, stream: int) -> wp.uint32:
    """Random key of stream ``stream`` of frame ``frame`` of run ``seed`` (stream 0: pixels; others: e.g. tiles)."""
    return random_subkey(random_key(seed, frame), stream)


@wp.func
def frame_key(sf: ScreenFrame, stream: int) -> wp.uint32:
    """Random key of stream ``stream`` of this frame (:func:`frame_key_of`)."""
    return frame_key_of(sf.seed, sf.frame, stream)


@wp.func
def pixel_key_of(seed: int, frame: int, x: int, y: int, width: int, stream: int) -> wp.uint32:
    """Random key of pass (or use) ``stream`` of pixel (x, y) in frame ``frame`` of run ``seed``: the one scheme."""
    return random_subkey(random_subkey(frame_key_of(seed, frame, 0), y * width + x), stream)


@wp.func
def pixel_key(sf: ScreenFrame, x: int, y: int, stream: int) -> wp.uint32:
    """Random key of pass (or use) ``stream`` of pixel (x, y) in this frame (:func:`pixel_key_of`)."""
    return pixel_key_of(sf.seed, sf.frame, x, y, sf.si.shape[1], stream)


@wp.func
def write_pixel(image: wp.array2d(dtype=wp.vec3), nonfinite: wp.array(dtype=wp.int32), y: int, x: int, L: wp.vec3):
    """Store a pixel estimate; a NaN/Inf one is dropped (black) and counted (the tests require 0)."""
    image[y, x] = finite_or_dropped(L, nonfinite)


@wp.func
def visible_normal(si: SurfaceInteraction, wo: wp.vec3) -> wp.vec3:
    """The shading normal turned to the viewer's side (two-sided surfaces are seen from either)."""
    if wp.dot(si.ng, wo) < 0.0:
        return -si.ns
    return si.ns


def screen_frame(gbuffer: GBuffer, seed: int, frame: int) -> ScreenFrame:
    """The :class:`ScreenFrame` of the G-buffers as they are now (after ``fill`` for ``frame``)."""
    sf = ScreenFrame()
    sf.g, sf.g_prev = gbuffer.current, gbuffer.previous
    sf.si, sf.wo, sf.si_prev, sf.wo_prev = gbuffer.current.si, gbuffer.current.wo, gbuffer.previous.si, gbuffer.previous.wo
    sf.seed, sf.frame = int(seed), int(frame)
    return sf


class ScreenSpaceRenderer:
    """What the screen-space ReSTIR renderers share: timed phases, history reset, the NaN/Inf count."""

    seed: int
    frames_rendered: int
    timer: Any
    nonfinite: wp.array
    #: whether the renderer's passes read the G-buffer's albedo and roughness (ReSTCV's α, ReSTIR G-PT's edge pairs):
    #: the others get a G-buffer without them (:class:`~grisx.scene.gbuffer.GBuffer`, ``material``)
    GBUFFER_MATERIAL = False

    def _phase(self, name: str) -> Any:
        return contextlib.nullcontext() if self.timer is None else self.timer(name)

    def reset(self, seed: int | None = None) -> None:
        """Forget all history (the next frame starts fresh), optionally with a new seed: an independent run."""
        if seed is not None:
            self.seed = int(seed)
        self.frames_rendered = 0

    @property
    def nonfinite_samples(self) -> int:
        """Pixels whose estimate was NaN/Inf and was dropped (over the renderer's lifetime; 0 expected)."""
        return int(self.nonfinite.numpy()[0])


def kernel_cache(make: Callable[..., Any]) -> Callable[..., Any]:
    """``make(kinds, *options)`` memoized per set of material kinds and options (each specialization compiles once)."""
    cache: dict[tuple, Any] = {}

    def cached(kinds: Iterable[int], *options: Any) -> Any:
        key = (frozenset(int(k) for k in kinds), *options)
        if key not in cache:
            cache[key] = make(*key)
        return cache[key]

    cached.__doc__ = make.__doc__
    cached.__name__ = make.__name__
    return cached


def arg_types(**types: Any) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Give a kernel's arguments types that a kernel builder chose (``wp.array2d(dtype=T)`` for its ``T``).

    String annotations (``from __future__ import annotations``) cannot name the builder's local
    variables; apply this under ``@wp.kernel``.
    """

    def annotate(func: Callable[..., Any]) -> Callable[..., Any]:
        func.__annotations__.update(types)
        return func

    return annotate
