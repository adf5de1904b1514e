"""Screen-space reuse plumbing shared by every ReSTIR renderer: who may reuse from whom.

The estimator math of reuse (resampling weights, MIS, Jacobians, reservoir
merging) lives in :mod:`grisx.theory`; this module answers the *geometric*
questions a renderer asks before it calls that math, once for all renderers:

* :func:`gbuffer_similar` — the similarity test that keeps reuse between
  pixels that see similar surfaces: shading normals within an angle
  (25° in seed 004, Sec. 5) and camera depths within a relative difference
  (0.05 "normalized depth", seed 004; Bitterli et al. 2020 use 10%).
  A *biased* ReSTIR relies on it to hide bias; an unbiased one only uses it
  to avoid wasting samples (MIS keeps it unbiased either way).
* :func:`temporal_neighbor` — the pixel of the previous frame that this
  pixel's surface came from (integer motion vector), checked against the
  film and the previous G-buffer (seed 004, Alg. 3).
* :func:`spatial_neighbor` — a random pixel within a radius (uniform on the
  disk, never the pixel itself), clamped to the film (seed 004, Alg. 4;
  Bitterli et al. 2020: 5 neighbours within 30 px).
* :func:`adaptive_radius` — seed 004's radius schedule: start at 10% of the
  image and halve after each rejected neighbour, down to 3 px.

:class:`DomainList` carries a pass's domains (the pixels it resampled from, and from
which buffer) to the next stage in global memory: a staged spatial pass draws and
shifts its candidates in one kernel and counts Z or MIS over the *same* domains in
the next (``DESIGN.md``, "GPU execution": each stage a small kernel).

:class:`DoubleBuffer` holds a renderer's per-pixel reservoirs for "this
frame" and "previous frame" (or "input"/"output" of a spatial pass), swapped
without copies, so a pass never reads what it is writing.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Generic, TypeVar

import warp as wp

from grisx.scene.gbuffer import GBufferData

wp.set_module_options({"enable_backward": False})

__all__ = [
    "NeighborPixel",
    "gbuffer_similar",
    "pixels_similar",
    "temporal_neighbor",
    "spatial_neighbor",
    "adaptive_radius",
    "DoubleBuffer",
    "DomainList",
    "DOMAIN_HISTORY",
    "DOMAIN_PREVIOUS",
    "domain_code",
    "domain_pixel",
    "domain_flags",
    "SIMILARITY_NORMAL_COS",
    "SIMILARITY_DEPTH",
]

#: cos 25°: seed 004's normal threshold
SIMILARITY_NORMAL_COS = math.cos(math.radians(25.0))
#: seed 004's normalized depth threshold
SIMILARITY_DEPTH = 0.05


@wp.struct
class NeighborPixel:
    x: int
    y: int
    valid: int


@wp.func
def gbuffer_similar(n_a: wp.vec3, depth_a: float, n_b: wp.vec3, depth_b: float, normal_cos: float, max_depth_ratio: float) -> bool:
    """Normals within acos(normal_cos) and |depth_a − depth_b| ≤ max_depth_ratio · depth_a (seed 004, Sec. 5)."""
    if depth_a <= 0.0 or depth_b <= 0.0:
        return False
    if wp.dot(n_a, n_b) < normal_cos:
        return False
    return wp.abs(depth_a - depth_b) <= max_depth_ratio * depth_a


@wp.func
def pixels_similar(ga: GBufferData, xa: int, ya: int, gb: GBufferData, xb: int, yb: int, normal_cos: float, max_depth_ratio: float) -> bool:
    """:func:`gbuffer_similar` between pixel (xa, ya) of ``ga`` and (xb, yb) of ``gb`` (both must be hits)."""
    if ga.hit[ya, xa] == 0 or gb.hit[yb, xb] == 0:
        return False
    return gbuffer_similar(ga.normal[ya, xa], ga.depth[ya, xa], gb.normal[yb, xb], gb.depth[yb, xb], normal_cos, max_depth_ratio)


@wp.func
def temporal_neighbor(g: GBufferData, g_prev: GBufferData, x: int, y: int, normal_cos: float, max_depth_ratio: float) -> NeighborPixel:
    """The previous frame's pixel for (x, y) through the integer motion vector, if on the film and similar."""
    out = NeighborPixel()
    mv = g.motion_int[y, x]
    out.x = x + mv[0]
    out.y = y + mv[1]
    out.valid = 0
    width = g.hit.shape[1]
    height = g.hit.shape[0]
    if out.x < 0 or out.y < 0 or out.x >= width or out.y >= height:
        return out
    if pixels_similar(g, x, y, g_prev, out.x, out.y, normal_cos, max_depth_ratio):
        out.valid = 1
    return out


@wp.func
def spatial_neighbor(x: int, y: int, width: int, height: int, radius: float, u: wp.vec2) -> NeighborPixel:
    """A pixel uniformly within ``radius`` of (x, y), clamped to the film; invalid if it lands on (x, y)."""
    r = radius * wp.sqrt(u[0])
    phi = 2.0 * wp.pi * u[1]
    nx = wp.clamp(x + int(wp.round(r * wp.cos(phi))), 0, width - 1)
    ny = wp.clamp(y + int(wp.round(r * wp.sin(phi))), 0, height - 1)
    out = NeighborPixel()
    out.x = nx
    out.y = ny
    out.valid = int(nx != x or ny != y)
    return out


@wp.func
def adaptive_radius(width: int, height: int, rejections: int, min_radius: float) -> float:
    """Seed 004, Sec. 5: 10% of the image size, halved after each rejected neighbour, at least ``min_radius``."""
    r = 0.1 * float(wp.max(width, height))
    for _ in range(rejections):
        r = r * 0.5
    return wp.max(r, min_radius)


T = TypeVar("T")


#: :func:`domain_code` flags: the domain's reservoir is in the *previous* frame's buffer
DOMAIN_PREVIOUS = wp.constant(1)
#: the domain is this pixel's own history (the reprojected previous-frame reservoir)
DOMAIN_HISTORY = wp.constant(2)


@wp.func
def domain_code(x: int, y: int, width: int, flags: int) -> wp.int32:
    """One int for a domain: its pixel and :data:`DOMAIN_PREVIOUS` / :data:`DOMAIN_HISTORY` flags."""
    return wp.int32((y * width + x) * 4 + flags)


@wp.func
def domain_pixel(code: wp.int32, width: int) -> NeighborPixel:
    """The pixel of a :func:`domain_code` (valid)."""
    nb = NeighborPixel()
    i = int(code) // 4
    nb.x = i % width
    nb.y = i // width
    nb.valid = 1
    return nb


@wp.func
def domain_flags(code: wp.int32) -> int:
    return int(code) % 4


class DomainList:
    """Per pixel, up to ``capacity`` domain codes (:func:`domain_code`) in drawing order, their draw indices
    (``slots``: the random numbers beyond a neighbour's position are keyed by it), and their count.

    A spatial pass reads its neighbours several times (confidences for pairwise MIS, the candidates,
    the Z or MIS terms), often in different kernels; every reading must see the very same
    neighbours. Drawing them once into this list — instead of re-drawing them from the same random
    keys — makes that true by construction. It lives in global memory: a per-thread array of 64
    neighbours (the NeighborSet this replaced) sat in local memory and cost ReSTIR DI's spatial
    pass 1.6 KB of stack and the 255-register cap on sm_90 (152 registers without it). ``count``
    < 0 marks a pixel the pass does not resample (nothing for later stages to do).
    """

    def __init__(self, height: int, width: int, capacity: int, device: wp.context.Device) -> None:
        self.capacity = max(1, int(capacity))
        self.codes = wp.zeros((height, width, self.capacity), dtype=wp.int32, device=device)
        self.slots = wp.zeros((height, width, self.capacity), dtype=wp.int32, device=device)  # each domain's draw index
        self.count = wp.zeros((height, width), dtype=wp.int32, device=device)


class DoubleBuffer(Generic[T]):
    """Two instances of a per-pixel buffer: ``current`` is written, ``previous`` read; ``swap`` flips them."""

    def __init__(self, make: Callable[[], T]) -> None:
        self.current: T = make()
        self.previous: T = make()

    def swap(self) -> None:
        self.current, self.previous = self.previous, self.current
