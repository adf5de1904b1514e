"""``gris-shift``: GRIS across K pixels whose domains are shifted, scaled, bent and cut.

Pixel k (map kind k mod 5, see :mod:`grisx.theory.toys.shifts`) integrates

    f_k(x) = a_k · h(φ_k⁻¹(x) + δ_k),   x ∈ Ω_k = φ_k(U_k),
    h(v) = 0.25 + exp(−((v − 0.35)/0.08)²) + 0.6 exp(−((v − 0.75)/0.12)²),

so neighbouring pixels see the same two bumps, moved (δ_k), rescaled (a_k)
and carried into differently shaped domains — what makes reuse through shift
maps worthwhile. Exact values: a_k ∫_{U_k} h(u + δ_k) φ_k'(u) du by scipy
quadrature (tolerance 1e-12). p̂_k = f_k, candidates are uniform on Ω_k.

Method ``gris`` is the shared pixel-reuse chain
(:mod:`grisx.theory.toys.pixel_reuse`). Known-biased variants:

* ``mis=naive``: c_j/Σc counts the partial pixel (kind 4) even for points
  its shift cannot reach (u > 0.6): the other pixels lose 1/K of ∫_{u>0.6} f;
* ``jacobian=false``: drops |∂T/∂x| from Eq. 9, biased on the scaled and
  non-linear pixels.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import scipy.integrate
import warp as wp

from grisx.theory.shift import ShiftResult
from grisx.theory.toys.base import BiasedVariant, Method
from grisx.theory.toys.domains import interval_pdf, sample_interval
from grisx.theory.toys.pixel_reuse import REUSE_PARAMS, PixelReuseProblem, make_pixel_reuse_kernel, pixel_array, reuses
from grisx.theory.toys.shifts import PARTIAL_U_MAX, phi, phi_inverse, phi_u_max, pixel_shift

__all__ = ["GRISShift", "GRISShiftSpec", "pixel_layout"]


@wp.struct
class GRISShiftSpec:
    kind: wp.array(dtype=int)
    amplitude: wp.array(dtype=float)
    offset: wp.array(dtype=float)


@wp.func
def _h(v: float) -> float:
    a = (v - 0.35) / 0.08
    b = (v - 0.75) / 0.12
    return 0.25 + wp.exp(-a * a) + 0.6 * wp.exp(-b * b)


@wp.func
def _lo(spec: GRISShiftSpec, k: int) -> float:
    return phi(spec.kind[k], 0.0)


@wp.func
def _hi(spec: GRISShiftSpec, k: int) -> float:
    return phi(spec.kind[k], phi_u_max(spec.kind[k]))


@wp.func
def gris_shift_integrand(spec: GRISShiftSpec, k: int, x: float) -> float:
    if x < _lo(spec, k) or x > _hi(spec, k):
        return 0.0
    return spec.amplitude[k] * _h(phi_inverse(spec.kind[k], x) + spec.offset[k])


@wp.func
def gris_shift_sample(spec: GRISShiftSpec, k: int, u: float) -> float:
    return sample_interval(u, _lo(spec, k), _hi(spec, k))


@wp.func
def gris_shift_pdf(spec: GRISShiftSpec, k: int, x: float) -> float:
    return interval_pdf(_lo(spec, k), _hi(spec, k))


@wp.func
def gris_shift_shift(spec: GRISShiftSpec, src: int, dst: int, x: float) -> ShiftResult:
    return pixel_shift(spec.kind[src], spec.kind[dst], x)


def pixel_layout(pixels: int) -> dict[str, np.ndarray]:
    """Map kind, amplitude a_k and offset δ_k of each pixel."""
    k = np.arange(pixels)
    return {"kind": k % 5, "amplitude": 1.0 + 0.15 * (k % 3), "offset": 0.03 * k}


# ---- exact values (float64 twins of the problem definition, for quadrature) ----

def _h_np(v: float) -> float:
    return 0.25 + np.exp(-(((v - 0.35) / 0.08) ** 2)) + 0.6 * np.exp(-(((v - 0.75) / 0.12) ** 2))


def _phi_derivative_np(kind: int, u: float) -> float:
    if kind == 2:
        return 2.0
    if kind == 3:
        return 2.0 * np.exp(2.0 * u) / np.expm1(2.0)
    return 1.0


class GRISShift(PixelReuseProblem):
    name = "gris-shift"
    summary = "GRIS over K pixels linked by translation, scaling, non-linear and partial shift maps"
    params = REUSE_PARAMS
    methods = (Method("gris", "initial RIS per pixel, then spatial GRIS passes across all pixels", tuple(p.name for p in REUSE_PARAMS)),)
    biased_variants = (
        BiasedVariant(
            "gris",
            {"mis": "naive"},
            "c_j/Σc counts the partial-bijection pixel (pixel 4, so K >= 5) where its shift is undefined",
            applies=lambda p: reuses(p) and int(p["pixels"]) >= 5,
        ),
        BiasedVariant("gris", {"jacobian": False}, "resampling weights without |∂T/∂x| (seed 000, Eq. 9)", applies=reuses),
    )

    def exact(self, params: Mapping[str, Any]) -> np.ndarray:
        layout = pixel_layout(int(params["pixels"]))
        out = []
        for kind, amp, off in zip(layout["kind"], layout["amplitude"], layout["offset"]):
            u_max = PARTIAL_U_MAX if kind == 4 else 1.0
            g = lambda u, kind=kind, off=off: _h_np(u + off) * _phi_derivative_np(kind, u)  # noqa: E731
            value, _ = scipy.integrate.quad(g, 0.0, float(u_max), epsabs=1e-13, epsrel=1e-12, limit=200)
            out.append(amp * value)
        return np.array(out)

    def build_kernel(self) -> Any:
        return make_pixel_reuse_kernel(GRISShiftSpec, gris_shift_sample, gris_shift_pdf, gris_shift_integrand, gris_shift_integrand, gris_shift_shift)

    def spec(self, params: Mapping[str, Any], device: Any) -> GRISShiftSpec:
        layout = pixel_layout(int(params["pixels"]))
        s = GRISShiftSpec()
        s.kind = pixel_array(layout["kind"].astype(np.int32), int, device)
        s.amplitude = pixel_array(layout["amplitude"].astype(np.float32), float, device)
        s.offset = pixel_array(layout["offset"].astype(np.float32), float, device)
        return s
