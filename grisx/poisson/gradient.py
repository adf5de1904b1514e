"""Discrete image gradients, their adjoint, and the screened Poisson operator.

This module fixes the *conventions* every other part of :mod:`grisx.poisson`
follows, and implements them plainly in numpy (float64) so that tests and
users have an oracle to check the fast solvers against.

Forward differences
-------------------
A gradient-domain renderer [KMA*15] estimates, next to the primal image
``I``, the differences between horizontally and vertically adjacent pixels:

.. math::

    dx[y, x] = I[y, x+1] - I[y, x],  \\qquad  0 \\le x < W-1,

    dy[y, x] = I[y+1, x] - I[y, x],  \\qquad  0 \\le y < H-1.

Arrays are indexed ``[y, x]`` (row, column) or ``[y, x, c]`` for colour, and
``dx``/``dy`` have the *same shape as the primal image* so a renderer can
pass its full-size buffers straight in. The last column of ``dx`` and the last
row of ``dy`` have no pixel pair: they are ignored (they may hold anything,
NaN included), which is the same as treating them as absent edges. That is the
Neumann (zero-flux) boundary: nothing flows across the image border.

Adjoint and Laplacian
---------------------
Write ``∇`` for the map ``I ↦ (dx, dy)`` above. Its adjoint ``∇ᵀ`` (the
negative divergence, ``div = -∇ᵀ``) is

.. math::

    (∇ᵀ G)[y, x] = G_x[y, x-1] - G_x[y, x] + G_y[y-1, x] - G_y[y, x],

with terms whose edge does not exist dropped. ``L = ∇ᵀ∇`` is the graph
Laplacian of the pixel grid (4-neighbour, Neumann); ``L`` is positive
semi-definite and its null space is the constant image. In 1D the path-graph
Laplacian is diagonalised by the DCT-II, with eigenvalues
``λ_k = 2 - 2 cos(π k / N)`` for ``k = 0..N-1``, and in 2D the eigenvalues add,
``λ_{ky,kx} = λ_ky + λ_kx`` [Str99]; this is what makes the exact solver in
:mod:`grisx.poisson.dct` exact.

Screened Poisson energy
-----------------------
Reconstruction minimises, over the image ``I``, a norm of the residual vector

.. math::

    ρ(I) = \\big( α (I - P),\\; ∇I - G \\big),

where ``P`` is the primal image and ``G = (dx, dy)`` the gradient images
[LKL*13, KMA*15]. ``L2`` minimises ``‖ρ‖₂² = α²‖I-P‖² + ‖∇I-G‖²``, whose
normal equations are the screened Poisson equation

.. math::

    (α² + L)\\, I = α² P + ∇ᵀ G.

``L1`` minimises ``‖ρ‖₁ = α‖I-P‖₁ + ‖∇I-G‖₁``. For ``α > 0`` the L2 system is
symmetric positive definite (eigenvalues in ``[α², α² + 8]``); ``α = 0``
leaves the mean of ``I`` undetermined, so grisx rejects ``alpha <= 0``.

References
----------
[KMA*15] Kettunen, Manzi, Aittala, Lehtinen, Durand, Zwicker. Gradient-Domain
         Path Tracing. ACM TOG 34(4), 2015. Sec. 3 (screened Poisson, L1/L2).
[LKL*13] Lehtinen, Karras, Laine, Aittala, Durand, Aila. Gradient-Domain
         Metropolis Light Transport. ACM TOG 32(4), 2013. Sec. 5.
[Str99]  Strang. The Discrete Cosine Transform. SIAM Review 41(1), 1999.
seed 000: Wang et al. Gradient-domain ReSTIR Path Tracing, Sec. 3.1, Eq. 1
         (gradients are differences of adjacent pixel values).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "ImageGradients",
    "forward_gradient",
    "gradient_adjoint",
    "laplacian_eigenvalues",
    "screened_operator",
    "screened_rhs",
    "screened_energy",
]


@dataclass(frozen=True)
class ImageGradients:
    """Horizontal and vertical forward differences, each with the image's shape."""

    dx: np.ndarray
    dy: np.ndarray


def _hwc(a: np.ndarray) -> np.ndarray:
    """View (H, W) as (H, W, 1) so one code path serves grey and colour."""
    return a[:, :, None] if a.ndim == 2 else a


def forward_gradient(image: np.ndarray) -> ImageGradients:
    """Return ``dx``, ``dy`` of ``image`` in grisx's convention (zeros where no edge)."""
    image = np.asarray(image, dtype=np.float64)
    dx = np.zeros_like(image)
    dy = np.zeros_like(image)
    dx[:, :-1] = image[:, 1:] - image[:, :-1]
    dy[:-1, :] = image[1:, :] - image[:-1, :]
    return ImageGradients(dx=dx, dy=dy)


def gradient_adjoint(dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
    """Return ``∇ᵀ(dx, dy)`` (= ``-div``); the ignored last column/row never enter."""
    grey = np.ndim(dx) == 2
    dx = _hwc(np.asarray(dx, dtype=np.float64))
    dy = _hwc(np.asarray(dy, dtype=np.float64))
    out = np.zeros(dx.shape, dtype=np.float64)
    gx = dx[:, :-1]  # the edges that exist
    gy = dy[:-1, :]
    out[:, :-1] -= gx
    out[:, 1:] += gx
    out[:-1, :] -= gy
    out[1:, :] += gy
    return out[:, :, 0] if grey else out


def laplacian_eigenvalues(n: int) -> np.ndarray:
    """Eigenvalues ``2 - 2cos(πk/n)`` of the 1D Neumann path Laplacian, in DCT-II order."""
    return 2.0 - 2.0 * np.cos(np.pi * np.arange(n) / n)


def screened_operator(image: np.ndarray, alpha: float) -> np.ndarray:
    """Apply ``α² + L`` to ``image`` (float64), the L2 normal-equation matrix."""
    image = np.asarray(image, dtype=np.float64)
    g = forward_gradient(image)
    return alpha * alpha * image + gradient_adjoint(g.dx, g.dy)


def screened_rhs(primal: np.ndarray, dx: np.ndarray, dy: np.ndarray, alpha: float) -> np.ndarray:
    """Return ``α² P + ∇ᵀ G`` (float64), the L2 normal-equation right-hand side."""
    primal = np.asarray(primal, dtype=np.float64)
    return alpha * alpha * primal + gradient_adjoint(dx, dy)


def screened_energy(image: np.ndarray, primal: np.ndarray, dx: np.ndarray, dy: np.ndarray,
                    alpha: float, norm: str = "L2") -> float:
    """Return ``‖ρ(I)‖₂²`` (``norm="L2"``) or ``‖ρ(I)‖₁`` (``norm="L1"``), summed over channels."""
    image = np.asarray(image, dtype=np.float64)
    primal = np.asarray(primal, dtype=np.float64)
    g = forward_gradient(image)
    rx = (g.dx - np.asarray(dx, dtype=np.float64))[:, :-1]
    ry = (g.dy - np.asarray(dy, dtype=np.float64))[:-1, :]
    rp = alpha * (image - primal)
    if norm.upper() == "L1":
        return float(np.abs(rp).sum() + np.abs(rx).sum() + np.abs(ry).sum())
    return float((rp * rp).sum() + (rx * rx).sum() + (ry * ry).sum())
