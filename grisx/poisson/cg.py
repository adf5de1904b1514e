"""Jacobi-preconditioned conjugate gradients for the screened Poisson system, in Warp.

The host side of the iterative solvers: :class:`PlanarSystem` holds the device
buffers of one problem (planar ``(C, H*W)`` float32, one independent system per
channel), :func:`solve_cg` runs CG to a relative-residual tolerance, and
:func:`run_cg` runs a fixed number of iterations without any host round trip
(the inner solves of IRLS, :mod:`grisx.poisson.l1`). The kernels and the
algorithm are described in :mod:`grisx.poisson.operators`.

Stopping rule. For each channel ``c`` with right-hand side ``b_c``, CG stops
when the recurrence residual satisfies ``‖r_c‖₂ ≤ tol · ‖b_c‖₂`` for *every*
channel, checked every ``check_every`` iterations (one small device-to-host
read per check). The error this leaves is bounded by
``‖I - I*‖₂ ≤ ‖r‖₂ / λ_min = ‖r‖₂ / α²`` for the unweighted (L2) system,
whose smallest eigenvalue is ``α²``; the tests use exactly that bound.
In float32 the achievable relative residual is about ``1e-6``, so ``tol``
should not go below ~``1e-6``.

References
----------
[Saa03] Saad. Iterative Methods for Sparse Linear Systems, 2nd ed., SIAM 2003,
        Alg. 9.1 (PCG), Sec. 6.11 (convergence).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import warp as wp

from grisx.poisson import operators as ops

__all__ = ["PlanarSystem", "CGReport", "Measurement", "allocate_system", "assemble", "update_weights",
           "solve_cg", "start_cg", "run_cg", "capture", "measure_system"]

# Launch shape of the tiled kernels: lanes per block and pixels per lane. On a
# GPU, 256 × 16 measured fastest on an H200 at 1080p (one lane per pixel was
# 2× slower: index arithmetic and same-address atomics dominated). On the CPU
# a "block" is one lane; many pixels per lane amortise the per-task overhead.
_CUDA_BLOCK, _CUDA_PER = 256, 16
_CPU_PER = 64


@dataclass
class PlanarSystem:
    """Device buffers of one screened Poisson problem (all ``(C, H*W)`` float32)."""

    device: wp.Device
    height: int
    width: int
    channels: int
    alpha: float
    primal: wp.array
    gx: wp.array
    gy: wp.array
    x: wp.array  # the iterate; the solution when a solve returns
    b: wp.array
    dinv: wp.array  # Jacobi preconditioner diag(A)⁻¹
    r: wp.array
    p: wp.array
    ap: wp.array
    wpri: wp.array  # IRLS weights; (1, 1) placeholders when only L2 is solved
    wx: wp.array
    wy: wp.array
    scal: wp.array  # (operators.SCAL_ROWS, C) CG scalars, on the device
    block: int  # lanes per tile block (1 on the CPU)
    per: int  # pixels per lane

    @property
    def n(self) -> int:
        return self.height * self.width


@dataclass(frozen=True)
class CGReport:
    """How a CG solve ended: iterations run and the max per-channel relative residual."""

    iterations: int
    residual: float
    converged: bool


@dataclass(frozen=True)
class Measurement:
    """Per-result diagnostics computed on the device after a solve."""

    residual: float  # max over channels of ‖b - Ax‖/‖b‖ of the last system solved
    energy_l2: float  # α²‖I-P‖² + ‖∇I-G‖², summed over channels
    energy_l1: float  # α‖I-P‖₁ + ‖∇I-G‖₁, summed over channels


def allocate_system(primal: wp.array, gx: wp.array, gy: wp.array, x: wp.array,
                    height: int, width: int, alpha: float, weighted: bool) -> PlanarSystem:
    """Wrap planar inputs (and the initial guess ``x``, updated in place) with work buffers."""
    device = primal.device
    c, n = primal.shape
    shape = (c, n)
    wshape = shape if weighted else (1, 1)

    def empty(s: tuple[int, int]) -> wp.array:
        return wp.empty(s, dtype=wp.float32, device=device)

    return PlanarSystem(
        device=device, height=height, width=width, channels=c, alpha=float(alpha),
        primal=primal, gx=gx, gy=gy, x=x,
        b=empty(shape), dinv=empty(shape), r=empty(shape), p=empty(shape), ap=empty(shape),
        wpri=empty(wshape), wx=empty(wshape), wy=empty(wshape),
        scal=wp.zeros((ops.SCAL_ROWS, c), dtype=wp.float32, device=device),
        block=_CUDA_BLOCK if device.is_cuda else 1,
        per=_CUDA_PER if device.is_cuda else _CPU_PER,
    )


def _tiled(s: PlanarSystem, kernel, inputs: list) -> None:
    """Launch over (C, blocks); every kernel takes (n, block, per) before its outputs."""
    chunk = s.block * s.per
    blocks = (s.n + chunk - 1) // chunk
    wp.launch_tiled(kernel, dim=(s.channels, blocks), inputs=inputs, block_dim=s.block, device=s.device)


def assemble(s: PlanarSystem, weighted: bool) -> None:
    """Fill ``b`` and ``dinv`` for the current weights (all ones unless ``weighted``)."""
    _tiled(s, ops.build_system, [s.primal, s.gx, s.gy, s.wpri, s.wx, s.wy, int(weighted),
                                 s.alpha * s.alpha, s.height, s.width, s.n, s.block, s.per,
                                 s.b, s.dinv])


def update_weights(s: PlanarSystem, eps: float) -> None:
    """IRLS: weights 1/max(|ρ|, eps) from the current iterate."""
    _tiled(s, ops.irls_weights, [s.x, s.primal, s.gx, s.gy, s.alpha, float(eps), s.height, s.width,
                                 s.n, s.block, s.per, s.wpri, s.wx, s.wy])


def start_cg(s: PlanarSystem, weighted: bool) -> None:
    """r = b - A x, p = M⁻¹ r and the scalars of iteration 0."""
    s.scal.zero_()
    _tiled(s, ops.cg_init, [s.x, s.b, s.dinv, s.wpri, s.wx, s.wy, int(weighted),
                            s.alpha * s.alpha, s.height, s.width, s.n, s.block, s.per,
                            s.r, s.p, s.scal])


def _iterate(s: PlanarSystem, weighted: bool, k: int) -> None:
    a2 = s.alpha * s.alpha
    _tiled(s, ops.cg_matvec, [s.p, s.wpri, s.wx, s.wy, int(weighted), a2, s.height, s.width,
                              s.n, s.block, s.per, s.ap, s.scal, k])
    _tiled(s, ops.cg_update, [s.x, s.r, s.p, s.ap, s.dinv, s.n, s.block, s.per, s.scal, k])
    _tiled(s, ops.cg_direction, [s.r, s.dinv, s.n, s.block, s.per, s.p, s.scal, k])


def run_cg(s: PlanarSystem, weighted: bool, iterations: int) -> None:
    """Start CG from the current ``x`` and run exactly ``iterations`` steps (no host sync)."""
    start_cg(s, weighted)
    for k in range(iterations):
        _iterate(s, weighted, k)


def capture(s: PlanarSystem, record: Callable[[], None]) -> Callable[[], None]:
    """Return a function that replays the launches ``record`` makes.

    On a GPU the launches are captured once into a CUDA graph: replaying a
    graph costs one launch instead of three per CG iteration, and Python's
    launch overhead (tens of µs per kernel) would otherwise be comparable to
    the kernels themselves at 1080p. On the CPU, or if capture is not possible,
    ``record`` itself is returned.
    """
    if not s.device.is_cuda:
        return record
    try:
        with wp.ScopedCapture(device=s.device) as cap:
            record()
    except Exception:  # e.g. capture unsupported without a memory pool: plain launches
        return record
    graph = cap.graph
    return lambda: wp.capture_launch(graph)


def _relative_residual(scal: np.ndarray, k: int) -> np.ndarray:
    rr = scal[ops.SCAL_RR + k % 3].astype(np.float64)
    bb = scal[ops.SCAL_BB].astype(np.float64)
    # A channel with b = 0 has solution 0: judge it by its absolute residual.
    return np.sqrt(rr / np.where(bb > 0.0, bb, 1.0))


def solve_cg(s: PlanarSystem, weighted: bool, tol: float, max_iter: int,
             check_every: int = 9) -> CGReport:
    """Run CG from the current ``x`` until every channel's relative residual ≤ ``tol``.

    Iterations run in batches of ``check_every`` (a multiple of 3, so that a
    batch uses the scalar slots in the same order wherever it starts and one
    captured batch can be replayed), with one host read after each batch.
    """
    if check_every % 3:
        raise ValueError("check_every must be a multiple of 3")
    start_cg(s, weighted)
    k = 0
    rel = _relative_residual(s.scal.numpy(), 0)
    batch = None
    while rel.max() > tol and k < max_iter:
        if max_iter - k >= check_every:
            if batch is None:
                batch = capture(s, lambda: [_iterate(s, weighted, j) for j in range(check_every)])
            batch()
            k += check_every
        else:  # a last, partial batch
            while k < max_iter:
                _iterate(s, weighted, k)
                k += 1
        rel = _relative_residual(s.scal.numpy(), k)
    return CGReport(iterations=k, residual=float(rel.max()), converged=bool(rel.max() <= tol))


def measure_system(s: PlanarSystem, weighted: bool) -> Measurement:
    """True residual of the last system and the energies of ``x`` (one host read)."""
    out = wp.zeros((ops.MEASURE_ROWS, s.channels), dtype=wp.float32, device=s.device)
    _tiled(s, ops.measure, [s.x, s.b, s.primal, s.gx, s.gy, s.wpri, s.wx, s.wy, int(weighted),
                            s.alpha, s.height, s.width, s.n, s.block, s.per, out])
    m = out.numpy().astype(np.float64)
    rel = np.sqrt(m[0] / np.where(m[1] > 0.0, m[1], 1.0))
    return Measurement(residual=float(rel.max()), energy_l2=float(m[2].sum()),
                       energy_l1=float(m[3].sum()))
