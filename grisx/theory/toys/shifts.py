"""Toy shift maps between pixel domains, all built on one reference space U = [0, 1].

Pixel k's domain is the image of a map φ_k: U_k → Ω_k, and the shift from
pixel j to pixel i is T_{j→i} = φ_i ∘ φ_j⁻¹ with Jacobian
|∂T/∂x| = φ_i'(u) / φ_j'(u), u = φ_j⁻¹(x). The maps cover the cases GRIS
must handle:

=====  ==============  ===========================  ======================
kind   name            φ(u)                         Ω
=====  ==============  ===========================  ======================
0      identity        u                            [0, 1]
1      translation     u + 0.5                      [0.5, 1.5]
2      scaling         2u − 1                       [−1, 1]
3      non-linear      (e^{2u} − 1)/(e² − 1)        [0, 1]
4      partial         u on U = [0, 0.6] only       [0, 0.6]
=====  ==============  ===========================  ======================

Kind 4 makes every shift *into* that pixel a partial bijection: samples with
u > 0.6 have no image (seed 000, Sec. 3.1), so MIS must not count that pixel
there.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from grisx.theory.shift import ShiftResult, shift_failed, shift_result

# grisx never differentiates through its kernels: skip adjoint code (halves compile time)
wp.set_module_options({"enable_backward": False})

__all__ = [
    "MAP_KINDS",
    "phi",
    "phi_derivative",
    "phi_inverse",
    "phi_u_max",
    "pixel_shift",
    "apply_pixel_shift",
]

MAP_KINDS = ("identity", "translation", "scaling", "non-linear", "partial")
PARTIAL_U_MAX = wp.constant(0.6)
_E2M1 = wp.constant(float(np.expm1(2.0)))  # e² − 1


@wp.func
def phi(kind: int, u: float) -> float:
    """φ_kind(u): reference coordinate → pixel domain."""
    if kind == 1:
        return u + 0.5
    if kind == 2:
        return 2.0 * u - 1.0
    if kind == 3:
        return (wp.exp(2.0 * u) - 1.0) / _E2M1
    return u


@wp.func
def phi_derivative(kind: int, u: float) -> float:
    """φ'_kind(u) > 0."""
    if kind == 2:
        return 2.0
    if kind == 3:
        return 2.0 * wp.exp(2.0 * u) / _E2M1
    return 1.0


@wp.func
def phi_inverse(kind: int, x: float) -> float:
    """φ⁻¹_kind(x): pixel domain → reference coordinate."""
    if kind == 1:
        return x - 0.5
    if kind == 2:
        return 0.5 * (x + 1.0)
    if kind == 3:
        return 0.5 * wp.log(1.0 + x * _E2M1)
    return x


@wp.func
def phi_u_max(kind: int) -> float:
    """Upper end of U_kind (1, or 0.6 for the partial map)."""
    if kind == 4:
        return PARTIAL_U_MAX
    return 1.0


@wp.func
def pixel_shift(kind_src: int, kind_dst: int, x: float) -> ShiftResult:
    """T_{src→dst}(x) = φ_dst(φ_src⁻¹(x)), Jacobian φ'_dst(u)/φ'_src(u); fails outside U_dst."""
    u = phi_inverse(kind_src, x)
    if u < 0.0 or u > phi_u_max(kind_dst) or u > phi_u_max(kind_src):
        return shift_failed()
    return shift_result(phi(kind_dst, u), phi_derivative(kind_dst, u) / phi_derivative(kind_src, u))


@wp.kernel
def _pixel_shift_kernel(
    kind_src: int,
    kind_dst: int,
    xs: wp.array(dtype=float),
    out_x: wp.array(dtype=float),
    out_jacobian: wp.array(dtype=float),
    out_valid: wp.array(dtype=int),
):
    t = wp.tid()
    s = pixel_shift(kind_src, kind_dst, xs[t])
    out_x[t] = s.x
    out_jacobian[t] = s.jacobian
    out_valid[t] = int(s.valid)


def apply_pixel_shift(kind_src: int, kind_dst: int, xs: np.ndarray) -> dict[str, np.ndarray]:
    """Host helper: shift an array of samples; returns ``x``, ``jacobian`` and ``valid`` arrays."""
    xs = wp.array(np.asarray(xs, dtype=np.float32), dtype=float, device="cpu")
    n = xs.shape[0]
    out = {"x": wp.empty(n, dtype=float, device="cpu"), "jacobian": wp.empty(n, dtype=float, device="cpu"), "valid": wp.empty(n, dtype=int, device="cpu")}
    wp.launch(_pixel_shift_kernel, dim=n, inputs=[kind_src, kind_dst, xs, out["x"], out["jacobian"], out["valid"]], device="cpu")
    return {k: v.numpy() for k, v in out.items()} | {"valid": out["valid"].numpy().astype(bool)}
