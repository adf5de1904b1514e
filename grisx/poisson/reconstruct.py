"""The public entry points :func:`reconstruct` and :func:`solve`.

This module checks inputs at the boundary, moves them into the planar device
layout the Warp solvers use (or hands numpy arrays to the DCT solver), picks a
solver, and returns the image in the form it was given. The mathematics lives
in :mod:`grisx.poisson.gradient` (conventions), :mod:`grisx.poisson.dct`
(exact L2), :mod:`grisx.poisson.cg` (iterative L2) and
:mod:`grisx.poisson.l1` (IRLS).

Input and output forms
----------------------
``primal``, ``dx``, ``dy`` are each one of

* a numpy array (or anything :func:`numpy.asarray` accepts) of real numbers,
  shape ``(H, W)`` or ``(H, W, C)``;
* a ``wp.array`` of float32, shape ``(H, W)`` or ``(H, W, C)``, or of float32
  vectors (``wp.vec3`` …) with shape ``(H, W)``; strided views are fine.

All three must have the same ``(H, W, C)``. The result has the form of
``primal``: a numpy array (float64 if ``primal`` is float64, else float32) for
numpy input, a ``wp.array`` of the same shape and dtype on the same device for
Warp input. Warp arrays are never copied to the host (only the NaN/Inf count
and the small CG scalars are read back) and never moved between devices: a Warp
array on another device than ``device`` is an error.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
import warp as wp

from grisx.device import resolve_device, synchronize
from grisx.errors import InvalidParameterError, InvalidValueError, UnknownNameError
from grisx.poisson import operators as ops
from grisx.poisson.cg import PRECONDITIONERS, allocate_system, assemble, measure_system, solve_cg
from grisx.poisson.dct import solve_l2_dct
from grisx.poisson.gradient import screened_energy, screened_operator, screened_rhs
from grisx.poisson.l1 import DEFAULT_EPS, get_preset, irls

__all__ = ["PoissonResult", "reconstruct", "solve", "NORMS", "SOLVERS", "DEFAULT_TOL"]

NORMS = ("L2", "L1")
SOLVERS = ("auto", "dct", "cg", "irls")
DEFAULT_TOL = 1e-5  # relative residual of iterative L2 (float32 floor is ~1e-6)
DEFAULT_MAX_ITER = 2000


@dataclass(frozen=True)
class PoissonResult:
    """A reconstruction and how it was obtained.

    ``residual`` is the max over channels of ``‖b - A I‖₂ / ‖b‖₂`` for the last
    linear system solved (the L2 normal equations, or the last reweighted
    system of IRLS), recomputed from the returned image; ``energy`` is the
    objective of ``norm`` at ``image`` (summed over channels). ``seconds`` is
    wall time of the solve with the device synchronised, input checks and
    layout conversion included, the diagnostics excluded. With
    ``measure=False`` ``residual`` falls back to CG's own estimate (NaN for
    L1) and ``energy`` is NaN.
    """

    image: Any  # np.ndarray or wp.array, in the form of the primal input
    norm: str
    solver: str
    alpha: float
    device: str
    residual: float
    iterations: int  # CG iterations in total (0 for the DCT)
    outer_iterations: int  # IRLS reweightings (0 for L2)
    energy: float
    seconds: float


@dataclass
class _Input:
    """One image argument, normalised to an (H, W, C) view."""

    name: str
    kind: str  # "numpy" or "warp"
    hwc: Any  # np.ndarray (H, W, C) or wp.array3d float32 view
    source: Any  # the object the caller passed (keeps Warp views alive)
    grey: bool  # given as (H, W) with scalar dtype

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(self.hwc.shape)


def _as_input(name: str, a: Any) -> _Input:
    if isinstance(a, wp.array):
        return as_warp_input(name, a)
    try:
        arr = np.asarray(a)
    except Exception as exc:  # e.g. ragged nested lists
        raise InvalidParameterError(f"{name} is not an array: {exc}") from None
    if arr.dtype.kind not in "fiub":
        raise InvalidParameterError(f"{name} must hold real numbers, got dtype {arr.dtype}")
    if arr.ndim not in (2, 3):
        raise InvalidParameterError(f"{name} must have shape (H, W) or (H, W, C), got {arr.shape}")
    if arr.size == 0:
        raise InvalidParameterError(f"{name} is empty (shape {arr.shape})")
    if arr.dtype.kind != "f":
        arr = arr.astype(np.float64)
    hwc = arr[:, :, None] if arr.ndim == 2 else arr
    return _Input(name=name, kind="numpy", hwc=hwc, source=arr, grey=arr.ndim == 2)


def as_warp_input(name: str, a: wp.array) -> _Input:
    dtype = a.dtype
    vector = wp.types.type_is_vector(dtype)
    scalar = dtype._wp_scalar_type_ if vector else dtype
    if scalar != wp.float32 or not (a.ndim in (2, 3) and not vector or a.ndim == 2 and vector):
        raise InvalidParameterError(
            f"{name} must be a float32 Warp array of shape (H, W) or (H, W, C), or float32 vectors "
            f"of shape (H, W); got dtype {wp.types.type_repr(dtype)} with shape {a.shape}")
    if a.size == 0:
        raise InvalidParameterError(f"{name} is empty (shape {a.shape})")
    if a.ndim == 3:
        hwc = a
    else:
        # A (H, W) scalar or vector array is viewed as (H, W, C) without copying.
        channels = wp.types.type_size(dtype) if vector else 1
        hwc = wp.array(ptr=a.ptr, dtype=wp.float32, shape=(a.shape[0], a.shape[1], channels),
                       strides=(a.strides[0], a.strides[1], 4), device=a.device)
    return _Input(name=name, kind="warp", hwc=hwc, source=a, grey=a.ndim == 2 and not vector)


def _check_shapes(primal: _Input, others: list[_Input]) -> None:
    for inp in others:
        if inp.shape != primal.shape:
            raise InvalidParameterError(
                f"{inp.name} has shape {tuple(inp.source.shape)} ({inp.shape[2]} channel(s)) but primal has "
                f"shape {tuple(primal.source.shape)} ({primal.shape[2]} channel(s)); dx and dy must match "
                f"the primal image (their last column / row is ignored)")


def _pick_device(device: str | None, inputs: list[_Input]) -> wp.Device:
    on_warp = [inp for inp in inputs if inp.kind == "warp"]
    if device is None:
        names = sorted({str(inp.source.device) for inp in on_warp})
        if len(names) > 1:
            raise InvalidParameterError(f"primal, dx and dy live on different devices ({', '.join(names)})")
        device = names[0] if names else "cpu"
    dev = resolve_device(device)
    for inp in on_warp:
        if inp.source.device != dev:
            raise InvalidParameterError(
                f"{inp.name} lives on device '{inp.source.device}' but device='{dev}'; grisx does not "
                f"move Warp arrays between devices")
    return dev


def _check_finite(inputs: list[_Input], dev: wp.Device) -> None:
    """Count pixels with NaN/Inf in the entries the energy uses (not dx's last column, dy's last row)."""
    h, w, _ = inputs[0].shape
    # (rows, columns) of each argument that enter the energy
    extent = {"primal": (h, w), "dx": (h, w - 1), "dy": (h - 1, w)}
    counts: dict[str, int] = {}
    on_warp = [inp for inp in inputs if inp.kind == "warp"]
    if on_warp:
        buf = wp.zeros(len(on_warp), dtype=wp.int32, device=dev)
        for slot, inp in enumerate(on_warp):
            ny, nx = extent[inp.name]
            wp.launch(ops.count_nonfinite, dim=(h, w), inputs=[inp.hwc, nx, ny, buf, slot], device=dev)
        counts.update(zip((inp.name for inp in on_warp), (int(v) for v in buf.numpy())))
    for inp in inputs:
        if inp.kind == "numpy":
            ny, nx = extent[inp.name]
            counts[inp.name] = int(np.count_nonzero(~np.isfinite(inp.hwc[:ny, :nx]).all(axis=2)))
    for inp in inputs:
        if counts[inp.name]:
            n = counts[inp.name]
            raise InvalidValueError(f"{inp.name} contains NaN/Inf at {n} pixel{'s' if n != 1 else ''}")


def _to_planar(inp: _Input, dev: wp.Device) -> wp.array:
    h, w, c = inp.shape
    if inp.kind == "numpy":
        planar = np.ascontiguousarray(np.moveaxis(inp.hwc, 2, 0).reshape(c, h * w), dtype=np.float32)
        return wp.array(planar, dtype=wp.float32, device=dev)
    out = wp.empty((c, h * w), dtype=wp.float32, device=dev)
    wp.launch(ops.hwc_to_planar, dim=(h, w, c), inputs=[inp.hwc, out, w], device=dev)
    return out


def _from_planar(x: wp.array, primal: _Input, dev: wp.Device) -> Any:
    h, w, c = primal.shape
    if primal.kind == "numpy":
        img = np.moveaxis(x.numpy().reshape(c, h, w), 0, 2)
        img = img[:, :, 0] if primal.grey else img
        dtype = np.float64 if primal.hwc.dtype == np.float64 else np.float32
        return np.ascontiguousarray(img, dtype=dtype)
    out = wp.empty(primal.source.shape, dtype=primal.source.dtype, device=dev)
    view = as_warp_input("out", out).hwc
    wp.launch(ops.planar_to_hwc, dim=(h, w, c), inputs=[x, view, w], device=dev)
    return out


def _as_float(name: str, v: Any) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        raise InvalidParameterError(f"{name} must be a number, got {v!r}") from None


def _check_options(norm: str, alpha: Any, solver: str, dev: wp.Device,
                   tol: Any, max_iter: Any, eps: Any) -> tuple[str, str]:
    norm_u = str(norm).upper()
    if norm_u not in NORMS:
        raise UnknownNameError("norm", str(norm), NORMS)
    alpha_f = _as_float("alpha", alpha)
    tol, eps = _as_float("tol", tol), _as_float("eps", eps)
    if not math.isfinite(alpha_f) or alpha_f <= 0.0:
        # α = 0 leaves the image mean undetermined (Neumann Laplacian is singular).
        raise InvalidParameterError(f"alpha must be finite and > 0 (alpha = 0 leaves the mean undetermined), got {alpha}")
    if solver not in SOLVERS:
        raise UnknownNameError("Poisson solver", str(solver), SOLVERS)
    if solver == "auto":
        solver = "irls" if norm_u == "L1" else ("cg" if dev.is_cuda else "dct")
    allowed = {"L2": ("dct", "cg"), "L1": ("irls",)}[norm_u]
    if solver not in allowed:
        raise InvalidParameterError(f"solver '{solver}' does not solve norm {norm_u} (use {' or '.join(allowed)})")
    if solver == "dct" and not dev.is_cpu:
        raise InvalidParameterError("solver 'dct' runs on the CPU only; use solver='cg' on a GPU")
    if not (math.isfinite(tol) and tol > 0.0):
        raise InvalidParameterError(f"tol must be finite and > 0, got {tol}")
    if not isinstance(max_iter, (int, np.integer)) or max_iter < 0:
        raise InvalidParameterError(f"max_iter must be an integer >= 0, got {max_iter!r}")
    if not (math.isfinite(eps) and eps > 0.0):
        raise InvalidParameterError(f"eps must be finite and > 0, got {eps}")
    return norm_u, solver


def solve(primal: Any, dx: Any, dy: Any, alpha: float = 0.2, norm: str = "L2",
          device: str | None = None, *, solver: str = "auto", preset: str = "default",
          outer_iterations: int | None = None, inner_iterations: int | None = None,
          tol: float = DEFAULT_TOL, max_iter: int = DEFAULT_MAX_ITER, eps: float = DEFAULT_EPS,
          initial: str = "primal", check_finite: bool = True, measure: bool = True,
          preconditioner: str | None = None) -> PoissonResult:
    """Reconstruct an image from ``primal``, ``dx``, ``dy``; return a :class:`PoissonResult`.

    Parameters
    ----------
    primal, dx, dy
        The primal image and its forward-difference gradients (see
        :mod:`grisx.poisson.gradient` for the convention and
        :mod:`grisx.poisson.reconstruct` for accepted array forms).
    alpha
        Weight of the primal term, ``> 0`` (0.2 as in [KMA*15]).
    norm
        ``"L2"`` or ``"L1"``.
    device
        ``"cpu"``, ``"cuda"`` or ``"cuda:N"``; default: the device of Warp
        inputs, else ``"cpu"``.
    solver
        ``"auto"`` (DCT on CPU, CG on CUDA for L2; IRLS for L1), ``"dct"``
        (exact, CPU), ``"cg"`` (Warp PCG, any device), ``"irls"`` (L1).
    preset, outer_iterations, inner_iterations
        L1 schedule: a name from :data:`grisx.poisson.L1_PRESETS`, optionally
        overriding its IRLS and CG iteration counts.
    tol, max_iter
        CG stops when every channel has ``‖b - AI‖ ≤ tol ‖b‖`` (L2 only).
    eps
        IRLS weight floor, in image units (L1 only).
    initial
        Initial iterate of the Warp solvers: ``"primal"`` or ``"zero"``.
    preconditioner
        CG's preconditioner, ``"multigrid"`` (one V-cycle, :mod:`grisx.poisson.multigrid`) or
        ``"jacobi"``; default: multigrid for L2, the preset's for L1.
    check_finite
        Reject NaN/Inf (one small host read for Warp inputs).
    measure
        Recompute the true residual and the energy after the solve.
    """
    t0 = time.perf_counter()
    inputs = [_as_input("primal", primal), _as_input("dx", dx), _as_input("dy", dy)]
    _check_shapes(inputs[0], inputs[1:])
    dev = _pick_device(device, inputs)
    norm_u, solver = _check_options(norm, alpha, solver, dev, tol, max_iter, eps)
    if initial not in ("primal", "zero"):
        raise UnknownNameError("initial guess", str(initial), ("primal", "zero"))
    if preconditioner is not None and preconditioner not in PRECONDITIONERS:
        raise UnknownNameError("CG preconditioner", str(preconditioner), PRECONDITIONERS)
    alpha = float(alpha)
    outer = inner = 0
    chosen = preconditioner or "multigrid"
    if norm_u == "L1":
        p = get_preset(preset)
        chosen = preconditioner or p.preconditioner
        outer = p.outer if outer_iterations is None else int(outer_iterations)
        inner = p.inner if inner_iterations is None else int(inner_iterations)
        if outer < 1 or inner < 0:
            raise InvalidParameterError(f"IRLS needs outer_iterations >= 1 and inner_iterations >= 0, got {outer} × {inner}")
    if check_finite:
        _check_finite(inputs, dev)

    if solver == "dct":
        return _solve_dct(inputs, alpha, dev, t0, measure)

    # ---- Warp iterative solvers: planar device buffers ----
    h, w, c = inputs[0].shape
    planar = [_to_planar(inp, dev) for inp in inputs]
    x = wp.clone(planar[0]) if initial == "primal" else wp.zeros_like(planar[0])
    system = allocate_system(planar[0], planar[1], planar[2], x, h, w, alpha, weighted=norm_u == "L1", preconditioner=chosen)
    if norm_u == "L2":
        assemble(system, weighted=False)
        report = solve_cg(system, weighted=False, tol=float(tol), max_iter=int(max_iter))
        iterations, weighted, residual = report.iterations, False, report.residual
        if not report.converged:
            warnings.warn(f"CG stopped after {report.iterations} iterations at relative residual "
                          f"{report.residual:.3g} > tol {tol:.3g}", RuntimeWarning, stacklevel=2)
    else:
        weighted = irls(system, outer, inner, float(eps))
        iterations, residual = outer * inner, math.nan
    image = _from_planar(system.x, inputs[0], dev)
    synchronize(dev)
    seconds = time.perf_counter() - t0

    energy = math.nan
    if measure:
        m = measure_system(system, weighted)
        residual = m.residual
        energy = m.energy_l1 if norm_u == "L1" else m.energy_l2
    return PoissonResult(image=image, norm=norm_u, solver=solver, alpha=alpha, device=str(dev),
                         residual=residual, iterations=iterations, outer_iterations=outer,
                         energy=energy, seconds=seconds)


def _solve_dct(inputs: list[_Input], alpha: float, dev: wp.Device, t0: float,
               measure: bool) -> PoissonResult:
    arrays = [inp.hwc if inp.kind == "numpy" else inp.hwc.numpy() for inp in inputs]
    img = solve_l2_dct(*arrays, alpha=alpha, workers=-1)
    primal = inputs[0]
    if primal.kind == "numpy":
        dtype = np.float64 if primal.hwc.dtype == np.float64 else np.float32
        out: Any = (img[:, :, 0] if primal.grey else img).astype(dtype)
        returned = out
    else:
        returned = img.astype(np.float32)
        data = returned[:, :, 0] if primal.grey else returned
        out = wp.array(np.ascontiguousarray(data), dtype=primal.source.dtype, device=dev)
    seconds = time.perf_counter() - t0
    residual = energy = math.nan
    if measure:
        # Residual of the image actually returned (float32 rounding included), in float64.
        got = np.asarray(returned, dtype=np.float64).reshape(img.shape)
        b = screened_rhs(arrays[0], arrays[1], arrays[2], alpha)
        r = b - screened_operator(got, alpha)
        rr = (r * r).sum(axis=(0, 1))
        bb = (b * b).sum(axis=(0, 1))
        residual = float(np.sqrt(rr / np.where(bb > 0.0, bb, 1.0)).max())
        energy = screened_energy(got, arrays[0], arrays[1], arrays[2], alpha, "L2")
    return PoissonResult(image=out, norm="L2", solver="dct", alpha=alpha, device=str(dev),
                         residual=residual, iterations=0, outer_iterations=0, energy=energy,
                         seconds=seconds)


def reconstruct(primal: Any, dx: Any, dy: Any, alpha: float = 0.2, norm: str = "L2",
                device: str | None = None, **options: Any) -> Any:
    """Return the screened Poisson reconstruction of ``primal``, ``dx``, ``dy``.

    The image has the form of ``primal`` (numpy in → numpy out, Warp in → Warp
    out on the same device). ``options`` are those of :func:`solve`, which
    also reports residual, iterations and time.
    """
    return solve(primal, dx, dy, alpha=alpha, norm=norm, device=device, **options).image
