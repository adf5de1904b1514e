"""Toy sample spaces and their sampling triples (``sample_x``, ``x_pdf``, ``invert_x``).

Domains are described on the host by small records (:class:`Interval`,
:class:`Rectangle`, :class:`Union` of tagged parts — the last is the
paired-pixel domain X = Ω_i×{0} ∪ Ω_j×{1} of seed 000, Eq. 14) and sampled in
kernels by the Warp functions below, which take the random number ``u``
explicitly.
"""

from __future__ import annotations

import dataclasses
import math

import warp as wp

__all__ = [
    "Interval",
    "Rectangle",
    "Union",
    "sample_interval",
    "interval_pdf",
    "invert_interval",
    "sample_angle_uniform",
    "angle_uniform_pdf",
    "sample_angle_cosine",
    "angle_cosine_pdf",
    "invert_angle_cosine",
]


@dataclasses.dataclass(frozen=True)
class Interval:
    """The closed interval [lo, hi]."""

    lo: float
    hi: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.lo) and math.isfinite(self.hi) and self.hi > self.lo):
            from grisx.errors import InvalidParameterError

            raise InvalidParameterError(f"interval needs finite lo < hi, got [{self.lo}, {self.hi}]")

    @property
    def measure(self) -> float:
        return self.hi - self.lo

    def contains(self, x: float) -> bool:
        return self.lo <= x <= self.hi


@dataclasses.dataclass(frozen=True)
class Rectangle:
    """The product [x.lo, x.hi] × [y.lo, y.hi]."""

    x: Interval
    y: Interval

    @property
    def measure(self) -> float:
        return self.x.measure * self.y.measure

    def contains(self, p: tuple[float, float]) -> bool:
        return self.x.contains(p[0]) and self.y.contains(p[1])


@dataclasses.dataclass(frozen=True)
class Union:
    """A disjoint union of parts tagged 0, 1, … (a point is a pair (part, x))."""

    parts: tuple[Interval | Rectangle, ...]

    @property
    def measure(self) -> float:
        return sum(p.measure for p in self.parts)

    def contains(self, point: tuple[int, object]) -> bool:
        tag, x = point
        return 0 <= tag < len(self.parts) and self.parts[tag].contains(x)  # type: ignore[arg-type]


@wp.func
def sample_interval(u: float, lo: float, hi: float) -> float:
    """x = lo + u (hi − lo), uniform on [lo, hi)."""
    return lo + u * (hi - lo)


@wp.func
def interval_pdf(lo: float, hi: float) -> float:
    """Density 1 / (hi − lo) of :func:`sample_interval`."""
    return 1.0 / (hi - lo)


@wp.func
def invert_interval(x: float, lo: float, hi: float) -> float:
    """The u that :func:`sample_interval` maps to x."""
    return (x - lo) / (hi - lo)


@wp.func
def sample_angle_uniform(u: float) -> float:
    """Flatland direction θ ∈ (−π/2, π/2) from the normal, uniform in angle."""
    return (u - 0.5) * wp.pi


@wp.func
def angle_uniform_pdf(theta: float) -> float:
    """Density 1/π of :func:`sample_angle_uniform` (0 below the horizon)."""
    if wp.abs(theta) < 0.5 * wp.pi:
        return 1.0 / wp.pi
    return 0.0


@wp.func
def sample_angle_cosine(u: float) -> float:
    """Flatland cosine-weighted direction: θ = asin(2u − 1), density cos θ / 2."""
    return wp.asin(wp.clamp(2.0 * u - 1.0, -1.0, 1.0))


@wp.func
def angle_cosine_pdf(theta: float) -> float:
    """Density cos θ / 2 of :func:`sample_angle_cosine` (0 below the horizon)."""
    if wp.abs(theta) < 0.5 * wp.pi:
        return 0.5 * wp.cos(theta)
    return 0.0


@wp.func
def invert_angle_cosine(theta: float) -> float:
    """The u that :func:`sample_angle_cosine` maps to θ."""
    return 0.5 * (wp.sin(theta) + 1.0)
