"""Fixtures for the Poisson tests: the device fixture and a dense float64 oracle.

The oracle builds the forward-difference matrix ``D`` (one row per existing
edge) straight from the convention ``dx[y, x] = I[y, x+1] - I[y, x]``, so it
shares no code with :mod:`grisx.poisson`; dense solves with it are the
independent reference for small images.
"""

from __future__ import annotations

import numpy as np
import pytest

from grisx.device import cuda_available

NO_CUDA = "needs CUDA: Warp found no CUDA device on this machine"


@pytest.fixture(params=["cpu", pytest.param("cuda", marks=pytest.mark.cuda)])
def device(request) -> str:
    """Every device: ``cpu`` always, ``cuda`` when Warp finds a GPU."""
    if request.param == "cuda" and not cuda_available():
        pytest.skip(NO_CUDA)
    return request.param


class DenseOracle:
    """Dense float64 matrices of the screened Poisson problem for one (H, W) grid."""

    @staticmethod
    def gradient_matrix(h: int, w: int) -> tuple[np.ndarray, list[tuple[str, int, int]]]:
        """D with D @ I.ravel() = the existing entries of (dx, dy); also the (name, y, x) of each row."""
        rows: list[np.ndarray] = []
        where: list[tuple[str, int, int]] = []
        for y in range(h):
            for x in range(w - 1):
                r = np.zeros(h * w)
                r[y * w + x + 1], r[y * w + x] = 1.0, -1.0
                rows.append(r)
                where.append(("dx", y, x))
        for y in range(h - 1):
            for x in range(w):
                r = np.zeros(h * w)
                r[(y + 1) * w + x], r[y * w + x] = 1.0, -1.0
                rows.append(r)
                where.append(("dy", y, x))
        d = np.array(rows) if rows else np.zeros((0, h * w))
        return d, where

    @classmethod
    def solve_l2(cls, primal: np.ndarray, dx: np.ndarray, dy: np.ndarray, alpha: float) -> np.ndarray:
        """argmin α²‖I-P‖² + ‖DI-g‖² by a dense solve, per channel (float64)."""
        primal = np.asarray(primal, np.float64)
        grey = primal.ndim == 2
        p3 = primal[:, :, None] if grey else primal
        dx3 = np.asarray(dx, np.float64).reshape(p3.shape)
        dy3 = np.asarray(dy, np.float64).reshape(p3.shape)
        h, w, c = p3.shape
        d, where = cls.gradient_matrix(h, w)
        a = alpha * alpha * np.eye(h * w) + d.T @ d
        out = np.empty_like(p3)
        for ch in range(c):
            g = np.array([(dx3 if n == "dx" else dy3)[y, x, ch] for n, y, x in where])
            b = alpha * alpha * p3[:, :, ch].ravel() + (d.T @ g if len(g) else 0.0)
            out[:, :, ch] = np.linalg.solve(a, b).reshape(h, w)
        return out[:, :, 0] if grey else out

    @classmethod
    def residual_norm(cls, image: np.ndarray, primal: np.ndarray, dx: np.ndarray, dy: np.ndarray,
                      alpha: float) -> float:
        """‖b - A I‖₂ of the L2 normal equations over all channels (float64)."""
        image = np.asarray(image, np.float64)
        ref_shape = image.shape
        i3 = image.reshape(ref_shape[0], ref_shape[1], -1)
        p3 = np.asarray(primal, np.float64).reshape(i3.shape)
        dx3 = np.asarray(dx, np.float64).reshape(i3.shape)
        dy3 = np.asarray(dy, np.float64).reshape(i3.shape)
        h, w, c = i3.shape
        d, where = cls.gradient_matrix(h, w)
        a = alpha * alpha * np.eye(h * w) + d.T @ d
        total = 0.0
        for ch in range(c):
            g = np.array([(dx3 if n == "dx" else dy3)[y, x, ch] for n, y, x in where])
            b = alpha * alpha * p3[:, :, ch].ravel() + (d.T @ g if len(g) else 0.0)
            r = b - a @ i3[:, :, ch].ravel()
            total += float(r @ r)
        return float(np.sqrt(total))


@pytest.fixture
def dense() -> type[DenseOracle]:
    return DenseOracle
