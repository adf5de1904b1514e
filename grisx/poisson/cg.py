"""Preconditioned conjugate gradients for the screened Poisson system, in Warp.

The host side of the iterative solvers: :class:`PlanarSystem` holds the device
buffers of one problem (planar ``(C, H*W)`` float32, one independent system per
channel), :func:`solve_cg` runs CG to a relative-residual tolerance, and
:func:`run_cg` runs a fixed number of iterations without any host round trip
(the inner solves of IRLS, :mod:`grisx.poisson.l1`). The kernels and the
algorithm are described in :mod:`grisx.poisson.operators`.

Stopping rule. For each channel ``c`` with right-hand side ``b_c``, CG stops
when the recurrence residual satisfies ``‖r_c‖₂ ≤ tol · ‖b_c‖₂`` for *every*
channel, checked on the device after every iteration (:func:`cg_loop`: no
host read inside the loop). The preconditioner is Jacobi's diag(A) or one
multigrid V-cycle (:mod:`grisx.poisson.multigrid`), chosen when the system is
allocated. The error this leaves is bounded by
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
from typing import Any

import numpy as np
import warp as wp

from grisx.errors import UnknownNameError
from grisx.poisson import operators as ops

#: CG's preconditioners: diag(A), or one multigrid V-cycle (grisx.poisson.multigrid)
PRECONDITIONERS = ("jacobi", "multigrid")

__all__ = ["PlanarSystem", "CGReport", "Measurement", "allocate_system", "assemble", "update_weights",
           "solve_cg", "start_cg", "run_cg", "cg_loop", "cg_report", "LoopState", "capture", "measure_system"]

# Launch shape of the tiled kernels (operators: a block is a tile of ``rows`` image rows by
# ``lanes × strips`` columns). On a GPU 128 lanes, one strip, 16 rows: consecutive pixels in each
# row, 3.1k blocks at 1080p RGB (few same-address atomics); on an H200 at 1080p 128 lanes were 4–8%
# faster than 256, and 8 rows the same as 16 (benchmarks/reference/poisson_system_h200_2026-11-27).
# On the CPU a "block" is one lane, and long strips amortise the per-task overhead.
_CUDA_LANES, _CUDA_STRIPS, _CUDA_ROWS = 128, 1, 16
_CPU_LANES, _CPU_STRIPS, _CPU_ROWS = 1, 64, 4


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
    dinv: wp.array  # Jacobi preconditioner diag(A)⁻¹ of a weighted system; (1, 1) for L2 (computed, not stored)
    r: wp.array
    p: wp.array
    ap: wp.array
    wpri: wp.array  # IRLS weights; (1, 1) placeholders when only L2 is solved
    wx: wp.array
    wy: wp.array
    scal: wp.array  # (operators.SCAL_ROWS, C) CG scalars, on the device
    z: wp.array  # the preconditioned residual M⁻¹r (multigrid); (1, 1) with Jacobi (computed in place)
    multigrid: Any  # grisx.poisson.multigrid.Multigrid, or None: Jacobi
    lanes: int  # lanes per block (1 on the CPU)
    strips: int  # columns per lane in a row of the tile
    rows: int  # rows of the tile

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
                    height: int, width: int, alpha: float, weighted: bool,
                    preconditioner: str = "jacobi") -> PlanarSystem:
    """Wrap planar inputs (and the initial guess ``x``, updated in place) with work buffers;
    ``preconditioner``: ``"jacobi"`` (diag(A)) or ``"multigrid"`` (a V-cycle, :mod:`grisx.poisson.multigrid`)."""
    if preconditioner not in PRECONDITIONERS:
        raise UnknownNameError("CG preconditioner", str(preconditioner), PRECONDITIONERS)
    device = primal.device
    c, n = primal.shape
    shape = (c, n)
    wshape = shape if weighted else (1, 1)

    def empty(s: tuple[int, int]) -> wp.array:
        return wp.empty(s, dtype=wp.float32, device=device)

    system = PlanarSystem(
        device=device, height=height, width=width, channels=c, alpha=float(alpha),
        primal=primal, gx=gx, gy=gy, x=x,
        b=empty(shape), dinv=empty(wshape), r=empty(shape), p=empty(shape), ap=empty(shape),
        wpri=empty(wshape), wx=empty(wshape), wy=empty(wshape),
        scal=wp.zeros((ops.SCAL_ROWS, c), dtype=wp.float32, device=device),
        lanes=_CUDA_LANES if device.is_cuda else _CPU_LANES,
        strips=_CUDA_STRIPS if device.is_cuda else _CPU_STRIPS,
        rows=_CUDA_ROWS if device.is_cuda else _CPU_ROWS,
        z=empty(shape if preconditioner == "multigrid" else (1, 1)), multigrid=None,
    )
    if preconditioner == "multigrid":
        from grisx.poisson.multigrid import Multigrid

        system.multigrid = Multigrid(system)
    return system


def _tiled(s: PlanarSystem, kernel, inputs: list) -> None:
    """Launch over (C, row tiles, column tiles); every kernel takes (h, w, rows, strips, lanes) before its outputs."""
    columns = s.lanes * s.strips
    dim = (s.channels, (s.height + s.rows - 1) // s.rows, (s.width + columns - 1) // columns)
    wp.launch_tiled(kernel, dim=dim, inputs=inputs, block_dim=s.lanes, device=s.device)


def assemble(s: PlanarSystem, weighted: bool) -> None:
    """Fill ``b`` and ``dinv`` (and the coarse levels) for the current weights (all ones unless ``weighted``)."""
    _tiled(s, ops.build_system, [s.primal, s.gx, s.gy, s.wpri, s.wx, s.wy, int(weighted),
                                 s.alpha * s.alpha, s.height, s.width, s.rows, s.strips, s.lanes,
                                 s.b, s.dinv])
    if s.multigrid is not None:
        s.multigrid.assemble(weighted)


def update_weights(s: PlanarSystem, eps: float) -> None:
    """IRLS: weights 1/max(|ρ|, eps) from the current iterate."""
    _tiled(s, ops.irls_weights, [s.x, s.primal, s.gx, s.gy, s.alpha, float(eps), s.height, s.width,
                                 s.rows, s.strips, s.lanes, s.wpri, s.wx, s.wy])


def start_cg(s: PlanarSystem, weighted: bool) -> None:
    """r = b - A x, p = M⁻¹ r and the scalars of iteration 0."""
    s.scal.zero_()
    jacobi = int(s.multigrid is None)
    _tiled(s, ops.cg_init, [s.x, s.b, s.dinv, s.wpri, s.wx, s.wy, int(weighted),
                            s.alpha * s.alpha, s.height, s.width, s.rows, s.strips, s.lanes, jacobi,
                            s.r, s.p, s.scal])
    if not jacobi:
        s.multigrid.precondition(weighted, s.z, 0)
        wp.copy(s.p, s.z)


def _iterate(s: PlanarSystem, weighted: bool, k: int) -> None:
    a2 = s.alpha * s.alpha
    _tiled(s, ops.cg_matvec, [s.p, s.wpri, s.wx, s.wy, int(weighted), a2, s.height, s.width,
                              s.rows, s.strips, s.lanes, s.ap, s.scal, k])
    jacobi = int(s.multigrid is None)
    _tiled(s, ops.cg_update, [s.x, s.r, s.p, s.ap, s.dinv, int(weighted), a2, s.height, s.width, s.rows, s.strips, s.lanes, jacobi, s.scal, k])
    if not jacobi:
        s.multigrid.precondition(weighted, s.z, (k + 1) % 3)
    _tiled(s, ops.cg_direction, [s.r, s.z, s.dinv, int(weighted), a2, s.height, s.width, s.rows, s.strips, s.lanes, jacobi, s.p, s.scal, k])


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
    # load this package's kernels, and only these: a capture loads every module in the process by default
    from grisx.poisson import multigrid

    for module in (ops, multigrid):
        wp.load_module(module, device=s.device)
    try:
        with wp.ScopedCapture(device=s.device, force_module_load=False) as cap:
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


@dataclass
class LoopState:
    """The device words a CG loop keeps: iterations run, and whether to go on."""

    iterations: wp.array  # (1,) int32
    keep_going: wp.array  # (1,) int32

    @staticmethod
    def allocate(device: wp.Device) -> LoopState:
        return LoopState(wp.zeros(1, dtype=wp.int32, device=device), wp.zeros(1, dtype=wp.int32, device=device))


def cg_loop(s: PlanarSystem, weighted: bool, tol: float, max_iter: int, state: LoopState) -> None:
    """Launch CG from the current ``x`` to ``‖r_c‖ ≤ tol ‖b_c‖`` for every channel, or ``max_iter``.

    Nothing is read back: the stopping rule runs on the device (``operators.cg_continue``) after
    every iteration and guards the next one, a :func:`warp.capture_while` loop over turns of three
    iterations (the CG scalars rotate through three slots, so one body serves every turn) with a
    :func:`warp.capture_if` around the second and third: conditional nodes when captured in a
    CUDA graph.
    """
    tol2 = float(tol) * float(tol)
    state.iterations.zero_()
    start_cg(s, weighted)

    def check(step: int) -> None:
        wp.launch(ops.cg_continue, dim=1, inputs=[s.scal, tol2, step, max_iter, state.iterations, state.keep_going], device=s.device)

    def iteration(j: int) -> None:
        _iterate(s, weighted, j)
        check(1)
        if j < 2:
            wp.capture_if(state.keep_going, iteration, j=j + 1)

    check(0)
    wp.capture_while(state.keep_going, iteration, j=0)


def cg_report(s: PlanarSystem, tol: float, state: LoopState) -> CGReport:
    """How the last :func:`cg_loop` ended (two small host reads)."""
    k = int(state.iterations.numpy()[0])
    rel = _relative_residual(s.scal.numpy(), k)
    return CGReport(iterations=k, residual=float(rel.max()), converged=bool(rel.max() <= tol))


def solve_cg(s: PlanarSystem, weighted: bool, tol: float, max_iter: int) -> CGReport:
    """Run CG from the current ``x`` until every channel's relative residual ≤ ``tol`` (or ``max_iter``).

    The loop of :func:`cg_loop`, captured once into a CUDA graph on a GPU (plain launches on
    the CPU, where the loop reads its condition each turn); one host read at the end.
    """
    state = LoopState.allocate(s.device)
    capture(s, lambda: cg_loop(s, weighted, tol, max_iter, state))()
    return cg_report(s, tol, state)


def measure_system(s: PlanarSystem, weighted: bool) -> Measurement:
    """True residual of the last system and the energies of ``x`` (one host read)."""
    out = wp.zeros((ops.MEASURE_ROWS, s.channels), dtype=wp.float32, device=s.device)
    _tiled(s, ops.measure, [s.x, s.b, s.primal, s.gx, s.gy, s.wpri, s.wx, s.wy, int(weighted),
                            s.alpha, s.height, s.width, s.rows, s.strips, s.lanes, out])
    m = out.numpy().astype(np.float64)
    rel = np.sqrt(m[0] / np.where(m[1] > 0.0, m[1], 1.0))
    return Measurement(residual=float(rel.max()), energy_l2=float(m[2].sum()),
                       energy_l1=float(m[3].sum()))
