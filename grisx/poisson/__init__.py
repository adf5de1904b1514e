"""Screened Poisson reconstruction from primal and gradient images (L2 and L1).

Gradient-domain rendering [LKL*13, KMA*15; seed 000] estimates, besides the
usual *primal* image ``P``, the differences between adjacent pixels, the
*gradient images* ``dx[y, x] ≈ I[y, x+1] - I[y, x]`` and
``dy[y, x] ≈ I[y+1, x] - I[y, x]`` (seed 000, Eq. 1). Gradients are cheap to
estimate with low variance (the two pixels' paths are correlated by a shift
map), but they only fix the image up to a constant and their errors would
accumulate if simply integrated. The final image is therefore the *screened
Poisson* reconstruction: the image whose values and differences best match
both estimates,

.. math::

    I^* = \\arg\\min_I \\; \\lVert α (I - P) \\rVert_p^p + \\lVert ∇I - G \\rVert_p^p,
    \\qquad p \\in \\{1, 2\\},

with ``α`` (default 0.2 [KMA*15]) trading the noisy-but-unbiased primal
against the low-variance gradients.

* **L2** (``p = 2``) is a linear problem, ``(α² + L) I = α² P + ∇ᵀG`` with the
  Neumann grid Laplacian ``L = ∇ᵀ∇``; the result is unbiased if ``P`` and ``G``
  are [KMA*15]. On the CPU it is solved *exactly* by the DCT
  (:mod:`grisx.poisson.dct`), on a GPU by CG in Warp, preconditioned by a
  multigrid V-cycle (:mod:`grisx.poisson.multigrid`; about 10 iterations), to
  a relative residual ``tol`` (default ``1e-5``; :mod:`grisx.poisson.cg`).
* **L1** (``p = 1``) is robust to outlier gradients (shift-mapping failures):
  it is slightly biased but usually looks better [LKL*13]. It is solved by
  iteratively reweighted least squares with warm-started inner CG solves, on
  any device (:mod:`grisx.poisson.l1`), with presets ``fast`` (5 × 4),
  ``default`` (20 × 5) and ``high`` (50 × 8) of multigrid-preconditioned CG,
  and ``classic`` (20 × 50 Jacobi-preconditioned CG, the classic schedule).

Conventions (forward differences, the ignored last column of ``dx`` and last
row of ``dy``, Neumann boundaries, the energy and its normal equations) are
stated once, in :mod:`grisx.poisson.gradient`, and every solver uses them, so
exact gradients ``G = ∇P`` give back ``P`` for both norms. ``alpha <= 0`` is
rejected: with ``α = 0`` the image mean is undetermined.

Example
-------
>>> import numpy as np
>>> from grisx.poisson import forward_gradient, reconstruct
>>> truth = np.random.default_rng(0).random((4, 5, 3))
>>> g = forward_gradient(truth)
>>> image = reconstruct(truth, g.dx, g.dy, alpha=0.2, norm="L2")
>>> bool(np.allclose(image, truth, atol=1e-6))
True

Renderers pass Warp arrays straight in (``(H, W)``/``(H, W, C)`` float32 or
``(H, W)`` of ``wp.vec3``); on CUDA nothing is copied to the host and the
result is a Warp array on the same device. :func:`solve` also returns the
residual, iteration counts, energy and time as a :class:`PoissonResult`.
A renderer that reconstructs every frame from the same buffers binds a
:class:`ScreenedPoisson` to them instead: buffers and CUDA graph made once,
the stopping rule on the device, the previous frame's image as the start
(:mod:`grisx.poisson.system`).

References
----------
[KMA*15] Kettunen, Manzi, Aittala, Lehtinen, Durand, Zwicker. Gradient-Domain
         Path Tracing. ACM TOG 34(4), 2015, Sec. 3 and 5.
[LKL*13] Lehtinen, Karras, Laine, Aittala, Durand, Aila. Gradient-Domain
         Metropolis Light Transport. ACM TOG 32(4), 2013, Sec. 5.
seed 000 Wang et al. Gradient-domain ReSTIR Path Tracing (text in
         ``seeds/000_*.txt``), Sec. 3.1 and 5: L1 and L2 reconstruction,
         300 ms and 11 ms at 1080p on an RTX 5090.
"""

from grisx.poisson.gradient import (
    ImageGradients,
    forward_gradient,
    gradient_adjoint,
    screened_energy,
    screened_operator,
    screened_rhs,
)
from grisx.poisson.l1 import DEFAULT_EPS, L1_PRESETS, IRLSPreset
from grisx.poisson.reconstruct import DEFAULT_TOL, NORMS, SOLVERS, PoissonResult, reconstruct, solve
from grisx.poisson.system import FRAME_TOL, FrameReconstruction, ScreenedPoisson, frame_tol

__all__ = [
    "reconstruct",
    "solve",
    "ScreenedPoisson",
    "FrameReconstruction",
    "PoissonResult",
    "ImageGradients",
    "forward_gradient",
    "gradient_adjoint",
    "screened_operator",
    "screened_rhs",
    "screened_energy",
    "IRLSPreset",
    "L1_PRESETS",
    "DEFAULT_EPS",
    "DEFAULT_TOL",
    "FRAME_TOL",
    "frame_tol",
    "NORMS",
    "SOLVERS",
]
