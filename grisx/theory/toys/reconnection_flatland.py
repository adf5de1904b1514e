"""``reconnection-flatland``: ReSTIR GI's reconnection shift (seed 004) in 2D.

Visible points x₁ᵏ = (x_k, 0) with normal (0, 1) look up at a tilted emitter
segment A→B whose radiance varies along it, L(s) = 1 + 0.8 sin(3π s) for
s ∈ [0, 1]; a small occluder segment hangs between them. Pixel k integrates
its reflected radiance over the plane angle θ ∈ (−π/2, π/2) of directions
ω = (sin θ, cos θ):

    I_k = ∫ (ρ_k / 2) cos θ · L(s(θ)) · V(x₁ᵏ, s(θ)) dθ,

(ρ/2 is flatland's Lambertian BRDF: ∫ cos θ dθ = 2). The sample of a pixel
is a direction θ; its *sample point* x₂ = x₁ + t ω lies on the emitter. Exact
values integrate over the emitter with dθ = cos φ / r ds (scipy quadrature
with the occluder's shadow edges as break points).

Reuse at pixel i of pixel j's sample keeps the sample point and reconnects:
θ' = angle of x₂ − x₁ⁱ. The map θ ↦ θ' has seed 004's Eq. 11 Jacobian with
the flatland exponent n − 1 = 1 (:func:`grisx.theory.shift.reconnection_jacobian_2d`).
Known-biased variants: ``jacobian=false`` (seed 004, Fig. 7) and
``mis=naive``, which counts pixels from which the sample point is occluded
(seed 004's biased 1/M against Alg. 4's 1/Z).

``source`` selects the candidates' pdf: ``uniform`` angle (1/π) or ``cosine``
(cos θ / 2), as seed 004, Alg. 2 allows.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import scipy.integrate
import warp as wp

from grisx.theory.shift import ShiftResult, reconnection_jacobian_2d, shift_failed, shift_result
from grisx.theory.toys.base import BiasedVariant, Method, Param
from grisx.theory.toys.domains import (
    angle_cosine_pdf,
    angle_uniform_pdf,
    sample_angle_cosine,
    sample_angle_uniform,
)
from grisx.theory.toys.pixel_reuse import PixelReuseProblem, make_pixel_reuse_kernel, pixel_array, reuse_params, reuses

__all__ = ["ReconnectionFlatland", "FlatlandSpec", "flatland_scene"]

SOURCES = ("uniform", "cosine")


def flatland_scene(pixels: int) -> dict[str, Any]:
    """Geometry of the problem: visible points, albedos, emitter and occluder segments."""
    xs = np.linspace(-0.8, 0.8, pixels) if pixels > 1 else np.zeros(1)
    return {
        "visible": np.stack([xs, np.zeros_like(xs)], axis=1),
        "albedo": 0.5 + 0.1 * (np.arange(pixels) % 4),
        "emitter": (np.array([-1.2, 1.0]), np.array([1.0, 0.7])),
        "occluder": (np.array([-0.15, 0.45]), np.array([0.25, 0.45])),
    }


@wp.struct
class FlatlandSpec:
    visible: wp.array(dtype=wp.vec2)
    albedo: wp.array(dtype=float)
    emitter_a: wp.vec2
    emitter_b: wp.vec2
    emitter_normal: wp.vec2
    occluder_a: wp.vec2
    occluder_b: wp.vec2
    occluder: int
    source: int


@wp.func
def _segment_hit(o: wp.vec2, d: wp.vec2, a: wp.vec2, b: wp.vec2) -> wp.vec3:
    """Ray o + t d against segment a→b: (t, s, hit) with a + s (b − a) the hit point."""
    e = b - a
    denom = d[0] * e[1] - d[1] * e[0]
    if wp.abs(denom) < 1.0e-12:
        return wp.vec3(0.0, 0.0, 0.0)
    ao = a - o
    t = (ao[0] * e[1] - ao[1] * e[0]) / denom
    s = (ao[0] * d[1] - ao[1] * d[0]) / denom
    if t > 1.0e-6 and s >= 0.0 and s <= 1.0:
        return wp.vec3(t, s, 1.0)
    return wp.vec3(t, s, 0.0)


@wp.func
def _radiance(s: float) -> float:
    return 1.0 + 0.8 * wp.sin(3.0 * wp.pi * s)


@wp.func
def _direction(theta: float) -> wp.vec2:
    return wp.vec2(wp.sin(theta), wp.cos(theta))


@wp.func
def _emitter_hit(spec: FlatlandSpec, k: int, theta: float) -> wp.vec3:
    """(t, s, hit) of pixel k's ray at angle θ against the emitter, occlusion included."""
    if wp.abs(theta) >= 0.5 * wp.pi:
        return wp.vec3(0.0, 0.0, 0.0)
    o = spec.visible[k]
    d = _direction(theta)
    h = _segment_hit(o, d, spec.emitter_a, spec.emitter_b)
    if h[2] > 0.0 and wp.dot(d, spec.emitter_normal) < 0.0:
        if spec.occluder != 0:
            g = _segment_hit(o, d, spec.occluder_a, spec.occluder_b)
            if g[2] > 0.0 and g[0] < h[0]:
                return wp.vec3(h[0], h[1], 0.0)
        return h
    return wp.vec3(h[0], h[1], 0.0)


@wp.func
def flatland_integrand(spec: FlatlandSpec, k: int, theta: float) -> float:
    """f_k(θ) = (ρ_k/2) cos θ L(s(θ)) V — also the target p̂ (seed 004, Eq. 10's analogue)."""
    h = _emitter_hit(spec, k, theta)
    if h[2] <= 0.0:
        return 0.0
    return 0.5 * spec.albedo[k] * wp.cos(theta) * _radiance(h[1])


@wp.func
def flatland_sample(spec: FlatlandSpec, k: int, u: float) -> float:
    if spec.source == 1:
        return sample_angle_cosine(u)
    return sample_angle_uniform(u)


@wp.func
def flatland_pdf(spec: FlatlandSpec, k: int, theta: float) -> float:
    if spec.source == 1:
        return angle_cosine_pdf(theta)
    return angle_uniform_pdf(theta)


@wp.func
def flatland_shift(spec: FlatlandSpec, src: int, dst: int, theta: float) -> ShiftResult:
    """Reconnection: keep the sample point x₂ on the emitter, re-aim from pixel ``dst`` (seed 004, Eq. 11)."""
    if src == dst:
        return shift_result(theta, 1.0)
    o = spec.visible[src]
    h = _segment_hit(o, _direction(theta), spec.emitter_a, spec.emitter_b)
    if h[2] <= 0.0:
        return shift_failed()
    x2 = o + h[0] * _direction(theta)
    d = x2 - spec.visible[dst]
    if d[1] <= 0.0 or wp.dot(d, spec.emitter_normal) >= 0.0:
        return shift_failed()
    jacobian = reconnection_jacobian_2d(o, spec.visible[dst], x2, spec.emitter_normal)
    return shift_result(wp.atan2(d[0], d[1]), jacobian)


class ReconnectionFlatland(PixelReuseProblem):
    name = "reconnection-flatland"
    summary = "ReSTIR GI reconnection shift (seed 004, Eq. 11) between visible points in 2D flatland"
    params = reuse_params(mis_default="uniform") + (  # seed 004 uses 1/Z weights
        Param("source", "uniform", "source pdf of initial directions", kind="choice", choices=SOURCES),
        Param("occluder", True, "hang an occluder between the visible points and the emitter", kind="bool"),
    )
    methods = (Method("gris", "initial RIS per pixel, then spatial reuse by reconnection", tuple(p.name for p in reuse_params()) + ("source", "occluder")),)
    biased_variants = (
        BiasedVariant("gris", {"jacobian": False}, "reconnection without the Jacobian of seed 004, Eq. 11 (its Fig. 7)", applies=reuses),
        BiasedVariant(
            "gris", {"mis": "naive", "occluder": True}, "1/M counts pixels that cannot see the sample point (seed 004, Sec. 4.3)", applies=reuses
        ),
    )

    def exact(self, params: Mapping[str, Any]) -> np.ndarray:
        scene = flatland_scene(int(params["pixels"]))
        a, b = scene["emitter"]
        e = b - a
        normal = np.array([e[1], -e[0]]) / np.linalg.norm(e)  # faces down, toward the visible points
        occ = scene["occluder"] if params.get("occluder", True) else None
        out = []
        for x1, rho in zip(scene["visible"], scene["albedo"]):
            def integrand(s: float, x1: np.ndarray = x1, rho: float = rho) -> float:
                x2 = a + s * e
                d = x2 - x1
                r = float(np.hypot(*d))
                if occ is not None and _blocked(x1, x2, *occ):
                    return 0.0
                cos_theta = d[1] / r
                cos_phi = max(0.0, float(-(normal @ d)) / r)
                return 0.5 * rho * cos_theta * (1.0 + 0.8 * np.sin(3.0 * np.pi * s)) * cos_phi / r * np.linalg.norm(e)

            breaks = [] if occ is None else [s for s in (_shadow_edge(x1, p, a, e) for p in occ) if 0.0 < s < 1.0]
            value, _ = scipy.integrate.quad(integrand, 0.0, 1.0, points=breaks or None, epsabs=1e-13, epsrel=1e-12, limit=400)
            out.append(value)
        return np.array(out)

    def build_kernel(self) -> Any:
        return make_pixel_reuse_kernel(FlatlandSpec, flatland_sample, flatland_pdf, flatland_integrand, flatland_integrand, flatland_shift)

    def spec(self, params: Mapping[str, Any], device: Any) -> FlatlandSpec:
        scene = flatland_scene(int(params["pixels"]))
        a, b = scene["emitter"]
        e = b - a
        s = FlatlandSpec()
        s.visible = pixel_array(scene["visible"].astype(np.float32), wp.vec2, device)
        s.albedo = pixel_array(scene["albedo"].astype(np.float32), float, device)
        s.emitter_a, s.emitter_b = wp.vec2(*a), wp.vec2(*b)
        s.emitter_normal = wp.vec2(*(np.array([e[1], -e[0]]) / np.linalg.norm(e)))
        s.occluder_a, s.occluder_b = (wp.vec2(*p) for p in scene["occluder"])
        s.occluder = int(bool(params["occluder"]))
        s.source = SOURCES.index(params["source"])
        return s


def _cross(u: np.ndarray, v: np.ndarray) -> float:
    return float(u[0] * v[1] - u[1] * v[0])


def _blocked(x1: np.ndarray, x2: np.ndarray, p: np.ndarray, q: np.ndarray) -> bool:
    """Does segment p–q cross the open segment x1–x2?"""
    d, e = x2 - x1, q - p
    denom = _cross(d, e)
    if abs(denom) < 1e-15:
        return False
    t = _cross(p - x1, e) / denom
    s = _cross(p - x1, d) / denom
    return 0.0 < t < 1.0 and 0.0 <= s <= 1.0


def _shadow_edge(x1: np.ndarray, p: np.ndarray, a: np.ndarray, e: np.ndarray) -> float:
    """Emitter parameter s where the line from x1 through occluder end p meets the emitter."""
    d = p - x1
    denom = _cross(d, e)
    return _cross(a - x1, d) / denom if abs(denom) > 1e-15 else -1.0
