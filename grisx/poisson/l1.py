"""L1 screened Poisson reconstruction by iteratively reweighted least squares.

L1 reconstruction minimises the same residual as L2 in the 1-norm,

.. math::

    E_1(I) = α \\lVert I - P \\rVert_1 + \\lVert ∇I - G \\rVert_1,

which is far less sensitive to a few wrong gradients (shift-mapping failures,
fireflies) than L2: an outlier gradient costs in proportion to its size, not
its square, so the reconstruction does not smear it into its neighbourhood
[LKL*13, KMA*15].

IRLS [Bjö96] replaces each ``|ρ_j|`` by the quadratic majoriser
``ρ_j² / |ρ̃_j|`` around the previous iterate's residual ``ρ̃``. Each
outer iteration therefore solves a *weighted* screened Poisson system

.. math::

    (α² W_p + ∇ᵀ W_g ∇) I = α² W_p P + ∇ᵀ W_g G,
    \\qquad  w_j = 1 / \\max(|ρ̃_j|, ε),

with ``ε`` keeping the weights finite where a residual vanishes (this is
also what makes IRLS minimise a smoothed (Huber-like) L1 near zero). The first outer
iteration uses unit weights, i.e. it *is* an L2 solve, and every inner CG
solve is warm-started from the previous iterate. The inner solves are run
for a fixed number of CG iterations (no host synchronisation). The classic
gradient-domain reconstruction code runs 20 IRLS × 50 Jacobi-preconditioned
CG iterations (preset ``classic``); with the multigrid preconditioner
(:mod:`grisx.poisson.multigrid`) 5 inner iterations reach the same energy
(``default``; measured on the benchmark's 480×270 frame: energy 15224.166
against 15224.186, RMSE to the truth equal to 5 digits), and so do the other
presets against their Jacobi schedules (``fast`` 5 × 4 against 5 × 20:
15444.2 against 15445.1; ``high`` 50 × 8 against 50 × 100: 15205.510 both).
:data:`L1_PRESETS` name the trade-offs.

``ε`` is in image units (default ``1e-3``); a smaller ``ε`` is a closer L1
but a stiffer inner system.

References
----------
[Bjö96] Björck. Numerical Methods for Least Squares Problems, SIAM 1996,
        Sec. 4.5.2 (IRLS for l_p approximation).
[LKL*13] Lehtinen et al. Gradient-Domain Metropolis Light Transport. ACM TOG
         32(4), 2013 (L1 reconstruction).
[KMA*15] Kettunen et al. Gradient-Domain Path Tracing. ACM TOG 34(4), 2015.
seed 000: Wang et al. Gradient-domain ReSTIR Path Tracing, Sec. 5 (L1/L2
          reconstruction, 300 ms / 11 ms at 1080p).
"""

from __future__ import annotations

from dataclasses import dataclass

from grisx.errors import UnknownNameError
from grisx.poisson.cg import PlanarSystem, assemble, capture, run_cg, update_weights

__all__ = ["IRLSPreset", "L1_PRESETS", "DEFAULT_EPS", "get_preset", "irls"]

DEFAULT_EPS = 1e-3


@dataclass(frozen=True)
class IRLSPreset:
    """A named IRLS schedule: ``outer`` reweightings × ``inner`` CG iterations each, CG preconditioned by ``preconditioner``."""

    name: str
    outer: int
    inner: int
    preconditioner: str = "multigrid"


L1_PRESETS: dict[str, IRLSPreset] = {
    p.name: p
    for p in (
        IRLSPreset("fast", outer=5, inner=4),
        IRLSPreset("default", outer=20, inner=5),
        IRLSPreset("high", outer=50, inner=8),
        IRLSPreset("classic", outer=20, inner=50, preconditioner="jacobi"),  # the classic 20 × 50
    )
}


def get_preset(name: str) -> IRLSPreset:
    """Look up an L1 preset by name (``UnknownNameError`` if there is none)."""
    try:
        return L1_PRESETS[name]
    except KeyError:
        raise UnknownNameError("L1 preset", name, list(L1_PRESETS)) from None


def irls(s: PlanarSystem, outer: int, inner: int, eps: float, graph_steps: bool = True) -> bool:
    """Run IRLS on ``s`` from its current ``x``; return whether the last system was weighted.

    Launches only: nothing is read back, so on a GPU the whole schedule is
    queued without a host round trip. ``graph_steps``: capture one reweighted
    solve as a CUDA graph and replay it (a caller that captures the whole
    schedule itself passes False).
    """
    # ---- outer iteration 0: unit weights, i.e. an L2 solve ----
    assemble(s, False)
    run_cg(s, False, inner)

    # ---- outer iterations 1..: reweight from the iterate, re-solve warm-started ----
    def reweighted_solve() -> None:
        update_weights(s, eps)
        assemble(s, True)
        run_cg(s, True, inner)

    if outer > 1:
        step = capture(s, reweighted_solve) if graph_steps else reweighted_solve  # one CUDA graph, replayed (GPU)
        for _ in range(outer - 1):
            step()
    return outer > 1
