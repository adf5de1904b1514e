"""Array front-ends to the estimator core, for users' experiments and for tests.

The core is Warp functions called inside kernels. These wrappers run those
same functions over numpy arrays — one row per independent reservoir — and
validate input at the boundary: NaN/Inf or negative weights and targets raise
:class:`~grisx.errors.InvalidValueError` naming the array and how many entries
are bad, instead of flowing silently into an estimate.

>>> import numpy as np
>>> from grisx.theory.batch import resample
>>> r = resample(weights=np.array([[1.0, 3.0]]), targets=np.array([[1.0, 3.0]]), seed=7)
>>> r.index.shape, float(r.w_sum[0])
((1,), 4.0)
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import warp as wp

from grisx.device import resolve_device
from grisx.errors import InvalidParameterError, InvalidValueError
from grisx.theory.gris import resampling_weight
from grisx.theory.mis import MIS_MODES, mis_weight
from grisx.theory.random import random_key, random_uniform
from grisx.theory.reservoir import Reservoir, reservoir_empty, reservoir_finalize, reservoir_merge, reservoir_update
from grisx.theory.shift import reconnection_jacobian_2d, reconnection_jacobian_3d

# grisx never differentiates through its kernels: skip adjoint code (halves compile time)
wp.set_module_options({"enable_backward": False})

__all__ = [
    "ResampleResult",
    "resample",
    "merge",
    "resampling_weights",
    "mis_weights",
    "uniforms",
    "reconnection_jacobians",
]


@dataclasses.dataclass(frozen=True)
class ResampleResult:
    """Per row: index of the kept candidate (−1 if none), Σw, p̂ of the kept one, W, confidence."""

    index: np.ndarray
    w_sum: np.ndarray
    target: np.ndarray
    ucw: np.ndarray
    confidence: np.ndarray


# ---- kernels: thin loops around the core functions ---------------------------


@wp.kernel
def _resample_kernel(
    weights: wp.array2d(dtype=float),
    targets: wp.array2d(dtype=float),
    confidences: wp.array2d(dtype=float),
    seed: int,
    out_index: wp.array(dtype=int),
    out: wp.array(dtype=Reservoir),
):
    row = wp.tid()
    key = random_key(seed, row)
    r = reservoir_empty()
    index = int(-1)
    for i in range(weights.shape[1]):
        r = reservoir_update(r, weights[row, i], targets[row, i], confidences[row, i], random_uniform(key, i))
        if r.selected:
            index = i
    out_index[row] = index
    out[row] = reservoir_finalize(r)


@wp.kernel
def _merge_kernel(
    inputs: wp.array2d(dtype=Reservoir),
    mis: wp.array2d(dtype=float),
    targets_shifted: wp.array2d(dtype=float),
    jacobians: wp.array2d(dtype=float),
    seed: int,
    out_index: wp.array(dtype=int),
    out: wp.array(dtype=Reservoir),
):
    row = wp.tid()
    key = random_key(seed, row)
    r = reservoir_empty()
    index = int(-1)
    for i in range(inputs.shape[1]):
        r = reservoir_merge(r, inputs[row, i], mis[row, i], targets_shifted[row, i], jacobians[row, i], random_uniform(key, i))
        if r.selected:
            index = i
    out_index[row] = index
    out[row] = reservoir_finalize(r)


@wp.kernel
def _weights_kernel(
    mis: wp.array(dtype=float),
    targets: wp.array(dtype=float),
    ucws: wp.array(dtype=float),
    jacobians: wp.array(dtype=float),
    out: wp.array(dtype=float),
):
    i = wp.tid()
    out[i] = resampling_weight(mis[i], targets[i], ucws[i], jacobians[i])


@wp.kernel
def _mis_kernel(
    mode: int,
    canonical: int,
    confidence: wp.array2d(dtype=float),
    target_from: wp.array2d(dtype=float),
    out: wp.array2d(dtype=float),
):
    row, source = wp.tid()
    out[row, source] = mis_weight(mode, source, canonical, confidence[row], target_from[row])


@wp.kernel
def _uniform_kernel(seed: int, streams: wp.array(dtype=int), counters: wp.array(dtype=int), out: wp.array2d(dtype=float)):
    i, j = wp.tid()
    out[i, j] = random_uniform(random_key(seed, streams[i]), counters[j])


@wp.kernel
def _reconnection_kernel(
    dims: int,
    x1_src: wp.array(dtype=wp.vec3),
    x1_dst: wp.array(dtype=wp.vec3),
    x2: wp.array(dtype=wp.vec3),
    n2: wp.array(dtype=wp.vec3),
    out: wp.array(dtype=float),
):
    i = wp.tid()
    if dims == 2:
        a = x1_src[i]
        b = x1_dst[i]
        c = x2[i]
        n = n2[i]
        out[i] = reconnection_jacobian_2d(wp.vec2(a[0], a[1]), wp.vec2(b[0], b[1]), wp.vec2(c[0], c[1]), wp.vec2(n[0], n[1]))
    else:
        out[i] = reconnection_jacobian_3d(x1_src[i], x1_dst[i], x2[i], n2[i])


# ---- validation ------------------------------------------------------------------


def _array(name: str, value: Any, ndim: int, nonnegative: bool = True, shape: tuple[int, ...] | None = None) -> np.ndarray:
    a = np.asarray(value, dtype=np.float64)
    if a.ndim == ndim - 1:
        a = a[None]
    if a.ndim != ndim:
        raise InvalidParameterError(f"{name} must be a {ndim}D array, got shape {a.shape}")
    if shape is not None and a.shape != shape:
        raise InvalidParameterError(f"{name} has shape {a.shape}, expected {shape}")
    bad = int(np.count_nonzero(~np.isfinite(a)))
    if bad:
        raise InvalidValueError(f"{name} contains {bad} NaN/Inf value(s)")
    if nonnegative and np.any(a < 0):
        raise InvalidValueError(f"{name} contains {int(np.count_nonzero(a < 0))} negative value(s)")
    if np.any(np.abs(a) > np.finfo(np.float32).max):
        # kernels run in float32; values that would overflow to Inf are rejected (underflow to 0 is harmless)
        raise InvalidValueError(f"{name} has values beyond float32's range (|x| > 3.4e38)")
    return a


def _wp(a: np.ndarray, device: Any, dtype: Any = float) -> wp.array:
    return wp.array(np.ascontiguousarray(a, dtype=np.float32), dtype=dtype, device=device)


# ---- public functions --------------------------------------------------------------


def resample(
    weights: Any,
    targets: Any | None = None,
    confidences: Any | None = None,
    seed: int = 0,
    device: str = "cpu",
) -> ResampleResult:
    """Stream each row of candidates through a reservoir and finalize it (seed 004, Alg. 1; seed 000, Eq. 8).

    ``weights[r, i]`` is candidate i's resampling weight in row r, ``targets``
    its p̂ (defaults to the weights), ``confidences`` what it adds to c
    (default 1). Row r draws its uniforms from ``random_key(seed, r)``.
    """
    w = _array("weights", weights, 2)
    t = w if targets is None else _array("targets", targets, 2, shape=w.shape)
    c = np.ones_like(w) if confidences is None else _array("confidences", confidences, 2, shape=w.shape)
    dev = resolve_device(device)
    n = w.shape[0]
    index = wp.empty(n, dtype=int, device=dev)
    out = wp.empty(n, dtype=Reservoir, device=dev)
    wp.launch(_resample_kernel, dim=n, inputs=[_wp(w, dev), _wp(t, dev), _wp(c, dev), int(seed), index, out], device=dev)
    return _result(index, out)


def merge(
    ucws: Any,
    confidences: Any,
    mis: Any,
    targets_shifted: Any,
    jacobians: Any | None = None,
    seed: int = 0,
    device: str = "cpu",
) -> ResampleResult:
    """Merge reservoirs (row r, input i: W, c) as GRIS candidates (seed 004, Alg. 1 MERGE; seed 000, Eq. 9)."""
    u = _array("ucws", ucws, 2)
    c = _array("confidences", confidences, 2, shape=u.shape)
    m = _array("mis", mis, 2, shape=u.shape)
    t = _array("targets_shifted", targets_shifted, 2, shape=u.shape)
    j = np.ones_like(u) if jacobians is None else _array("jacobians", jacobians, 2, shape=u.shape)
    dev = resolve_device(device)
    n, k = u.shape
    records = np.zeros((n, k), dtype=Reservoir.numpy_dtype())
    records["ucw"], records["confidence"] = u, c
    res = wp.array(records, dtype=Reservoir, device=dev)
    index = wp.empty(n, dtype=int, device=dev)
    out = wp.empty(n, dtype=Reservoir, device=dev)
    wp.launch(_merge_kernel, dim=n, inputs=[res, _wp(m, dev), _wp(t, dev), _wp(j, dev), int(seed), index, out], device=dev)
    return _result(index, out)


def resampling_weights(mis: Any, targets: Any, ucws: Any, jacobians: Any | None = None, device: str = "cpu") -> np.ndarray:
    """w = m · p̂(T(x)) · W · |J| elementwise (seed 000, Eq. 9)."""
    m = _array("mis", mis, 1)
    t = _array("targets", targets, 1, shape=m.shape)
    u = _array("ucws", ucws, 1, shape=m.shape)
    j = np.ones_like(m) if jacobians is None else _array("jacobians", jacobians, 1, nonnegative=False, shape=m.shape)
    dev = resolve_device(device)
    out = wp.empty(m.shape[0], dtype=float, device=dev)
    wp.launch(_weights_kernel, dim=m.shape[0], inputs=[_wp(m, dev), _wp(t, dev), _wp(u, dev), _wp(j, dev), out], device=dev)
    return out.numpy()


def mis_weights(mode: str, confidence: Any, target_from: Any, canonical: int = 0, device: str = "cpu") -> np.ndarray:
    """MIS weight of every source domain, per row: ``out[r, j]`` = m_j(y_r) for y_r in domain ``canonical``.

    ``target_from[r, l]`` = p̂_{←l}(y_r); ``confidence[r, l]`` = c_l. Modes
    are those of :data:`grisx.theory.mis.MIS_MODES`.
    """
    if mode not in MIS_MODES:
        from grisx.errors import UnknownNameError

        raise UnknownNameError("MIS mode", mode, list(MIS_MODES))
    c = _array("confidence", confidence, 2)
    t = _array("target_from", target_from, 2, shape=c.shape)
    if not 0 <= canonical < c.shape[1]:
        raise InvalidParameterError(f"canonical must index one of {c.shape[1]} domains, got {canonical}")
    dev = resolve_device(device)
    out = wp.empty(c.shape, dtype=float, device=dev)
    wp.launch(_mis_kernel, dim=c.shape, inputs=[MIS_MODES[mode], int(canonical), _wp(c, dev), _wp(t, dev), out], device=dev)
    return out.numpy()


def uniforms(seed: int, streams: Any, counters: Any, device: str = "cpu") -> np.ndarray:
    """``out[i, j]`` = random_uniform(random_key(seed, streams[i]), counters[j])."""
    s = np.asarray(streams, dtype=np.int64).ravel()
    c = np.asarray(counters, dtype=np.int64).ravel()
    dev = resolve_device(device)
    out = wp.empty((s.size, c.size), dtype=float, device=dev)
    wp.launch(
        _uniform_kernel,
        dim=(s.size, c.size),
        inputs=[int(seed), wp.array(s.astype(np.int32), dtype=int, device=dev), wp.array(c.astype(np.int32), dtype=int, device=dev), out],
        device=dev,
    )
    return out.numpy()


def reconnection_jacobians(x1_src: Any, x1_dst: Any, x2: Any, n2: Any, device: str = "cpu") -> np.ndarray:
    """Seed 004's Eq. 11 for arrays of 2D or 3D points (shape (n, 2) or (n, 3))."""
    arrays = [_array(name, v, 2, nonnegative=False) for name, v in (("x1_src", x1_src), ("x1_dst", x1_dst), ("x2", x2), ("n2", n2))]
    dims = arrays[0].shape[1]
    if dims not in (2, 3) or any(a.shape != arrays[0].shape for a in arrays):
        raise InvalidParameterError(f"points must all have shape (n, 2) or (n, 3), got {[a.shape for a in arrays]}")
    pad = [np.pad(a, ((0, 0), (0, 3 - dims))) for a in arrays]
    dev = resolve_device(device)
    out = wp.empty(pad[0].shape[0], dtype=float, device=dev)
    wp.launch(_reconnection_kernel, dim=pad[0].shape[0], inputs=[dims, *(_wp(a, dev, wp.vec3) for a in pad), out], device=dev)
    return out.numpy()


def _result(index: wp.array, out: wp.array) -> ResampleResult:
    rec = out.numpy()
    return ResampleResult(
        index=index.numpy(),
        w_sum=rec["w_sum"].astype(np.float64),
        target=rec["target"].astype(np.float64),
        ucw=rec["ucw"].astype(np.float64),
        confidence=rec["confidence"].astype(np.float64),
    )
