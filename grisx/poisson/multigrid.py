"""A multigrid V-cycle that preconditions CG on the screened Poisson system.

Jacobi-preconditioned CG needs about 60 iterations to a relative residual of 1e-5 on a
rendered frame, at any resolution: the system's condition number is bounded by
(α² + 8)/α² ≈ 200 for α = 0.2, and CG pays about √κ iterations per decade. The slow modes are
smooth ones, which a coarser grid represents with a quarter of the pixels. One V-cycle of the
hierarchy below as the preconditioner M brings the count to about 10 (measured on ReSTIR G-PT
frames and on the benchmark's synthetic frame), each iteration costing a few more passes over
the image.

**The hierarchy (aggregation, Galerkin).** Level ℓ+1 merges 2×2 pixels of level ℓ (one or two
at an odd edge) into one. The prolongation P copies a coarse value to the pixels it merged; the
restriction is Pᵀ (the sum over them); the coarse operator is Pᵀ A P. For the weighted screened
Poisson operator of :mod:`grisx.poisson.operators`, A = α² W_p + ∇ᵀ W_g ∇, that product is again
of the same form, with

* W_p of a coarse pixel = the sum of its fine pixels' W_p;
* W_g of a coarse edge = the sum of the fine edges that cross it (edges inside one coarse pixel
  vanish: P x is constant there);

so every level runs the same matrix-free stencil, for L2 (all fine weights 1) and for IRLS's
reweighted systems alike. Coarsening goes down to one pixel (:data:`COARSEST_SIDE`); long
before that the α² W_p term (4^ℓ α² against 2^ℓ per edge) makes the operator nearly diagonal.

**The cycle.** Damped Jacobi (ω = 0.8, below 2/λ_max(D⁻¹A) = 1 for a 5-point stencil) once before and
once after the coarse correction, from a zero guess; :data:`COARSEST_SWEEPS` Jacobi sweeps on the
coarsest level. Every step is linear in the residual, and the smoothing is symmetric about the
coarse correction, so M is a fixed symmetric positive definite operator, which is what CG
requires of a preconditioner [Saa03, Sec. 9.2; TOS01, Sec. 2.5 and 9.1].

References
----------
[Saa03] Saad. Iterative Methods for Sparse Linear Systems, 2nd ed., SIAM 2003, Sec. 9.2 and 13.
[TOS01] Trottenberg, Oosterlee, Schüller. Multigrid. Academic Press 2001.
"""

from __future__ import annotations

from dataclasses import dataclass

import warp as wp

from grisx.poisson.operators import SCAL_RZ, _around, _inv_diagonal, _stencil, _weight

wp.set_module_options({"enable_backward": False})

__all__ = ["MultigridLevel", "Multigrid", "COARSEST_SIDE", "COARSEST_SWEEPS", "OMEGA"]

#: coarsen until both sides have at most this many pixels (1080p: 1920×1080 → … → 1×1, 12 levels; any image
#: gets a hierarchy, the smallest ones too)
COARSEST_SIDE = 1
#: damped Jacobi sweeps on the coarsest level (nearly diagonal there)
COARSEST_SWEEPS = 2
#: the Jacobi damping
OMEGA = 0.8


# ---- kernels: one thread per (channel, pixel) of a level; the finest level's weights may be implicit ----


@wp.kernel
def coarsen(wpri: wp.array2d(dtype=wp.float32), wx: wp.array2d(dtype=wp.float32), wy: wp.array2d(dtype=wp.float32),
            weighted: int, a2: float, hf: int, wf: int, wc: int,
            cpri: wp.array2d(dtype=wp.float32), cx: wp.array2d(dtype=wp.float32), cy: wp.array2d(dtype=wp.float32),
            cdinv: wp.array2d(dtype=wp.float32)):
    """Galerkin weights of coarse pixel (Y, X): Pᵀ A P summed from the fine weights (module docstring)."""
    c, yc, xc = wp.tid()
    i = yc * wc + xc
    p = float(0.0)
    ex = float(0.0)  # the coarse edge to (Y, X + 1): fine edges (y, 2X + 1) → (y, 2X + 2)
    ey = float(0.0)  # the coarse edge to (Y + 1, X): fine edges (2Y + 1, x) → (2Y + 2, x)
    for dy in range(2):
        y = 2 * yc + dy
        for dx in range(2):
            x = 2 * xc + dx
            if y < hf and x < wf:
                f = y * wf + x
                p += _weight(wpri, c, f, weighted)
                if dx == 1 and x + 1 < wf:
                    ex += _weight(wx, c, f, weighted)
                if dy == 1 and y + 1 < hf:
                    ey += _weight(wy, c, f, weighted)
    cpri[c, i] = p
    cx[c, i] = ex
    cy[c, i] = ey
    # the diagonal needs the edges to the left and above too: their sums, recomputed here
    left = float(0.0)
    up = float(0.0)
    for d in range(2):
        y = 2 * yc + d
        if xc > 0 and y < hf:
            left += _weight(wx, c, y * wf + 2 * xc - 1, weighted)
        x = 2 * xc + d
        if yc > 0 and x < wf:
            up += _weight(wy, c, (2 * yc - 1) * wf + x, weighted)
    cdinv[c, i] = 1.0 / (a2 * p + ex + ey + left + up)


@wp.func
def _swept(xi: float, around: wp.vec4, r: wp.array2d(dtype=wp.float32), wpri: wp.array2d(dtype=wp.float32),
           wx: wp.array2d(dtype=wp.float32), wy: wp.array2d(dtype=wp.float32), dinv: wp.array2d(dtype=wp.float32),
           weighted: int, a2: float, omega: float, c: int, i: int, y: int, xx: int, h: int, w: int) -> float:
    """One damped Jacobi sweep at pixel i, x + ω D⁻¹ (r − A x), from x there (``xi``) and at its neighbours."""
    res = r[c, i] - _stencil(xi, around, wpri, wx, wy, weighted, a2, c, i, y, xx, h, w)
    return xi + omega * _inv_diagonal(dinv, weighted, a2, c, i, y, xx, h, w) * res


@wp.kernel
def smooth_from_zero(r: wp.array2d(dtype=wp.float32), dinv: wp.array2d(dtype=wp.float32), weighted: int, a2: float,
                     h: int, w: int, omega: float, x: wp.array2d(dtype=wp.float32)):
    """x = ω D⁻¹ r: one Jacobi sweep from x = 0."""
    c, y, xx = wp.tid()
    i = y * w + xx
    x[c, i] = _presmoothed(r, dinv, r, 0, weighted, a2, omega, c, i, y, xx, h, w, 1)


@wp.kernel
def smooth(x: wp.array2d(dtype=wp.float32), r: wp.array2d(dtype=wp.float32), wpri: wp.array2d(dtype=wp.float32),
           wx: wp.array2d(dtype=wp.float32), wy: wp.array2d(dtype=wp.float32), dinv: wp.array2d(dtype=wp.float32),
           weighted: int, a2: float, h: int, w: int, omega: float, out: wp.array2d(dtype=wp.float32)):
    """out = x + ω D⁻¹ (r − A x): one Jacobi sweep (out is another buffer than x)."""
    c, y, xx = wp.tid()
    i = y * w + xx
    out[c, i] = _swept(x[c, i], _around(x, c, i, y, xx, h, w), r, wpri, wx, wy, dinv, weighted, a2, omega, c, i, y, xx, h, w)


# A level's pre-smoothed guess ω D⁻¹ r and its corrected guess ω D⁻¹ r + P e are never stored: the
# kernels that need them at a pixel and its four neighbours evaluate them there (one pass fewer each,
# and a V-cycle is two kernels a level).


@wp.func
def _presmoothed(r: wp.array2d(dtype=wp.float32), dinv: wp.array2d(dtype=wp.float32), e: wp.array2d(dtype=wp.float32),
                 corrected: int, weighted: int, a2: float, omega: float, c: int, i: int, y: int, xx: int,
                 h: int, w: int, wc: int) -> float:
    """ω D⁻¹ r at pixel i = (y, xx) (one Jacobi sweep from 0), plus the coarse correction P e if ``corrected``."""
    v = omega * _inv_diagonal(dinv, weighted, a2, c, i, y, xx, h, w) * r[c, i]
    if corrected != 0:
        v += e[c, (y / 2) * wc + xx / 2]
    return v


@wp.func
def _presmoothed_around(r: wp.array2d(dtype=wp.float32), dinv: wp.array2d(dtype=wp.float32), e: wp.array2d(dtype=wp.float32),
                        corrected: int, weighted: int, a2: float, omega: float, c: int, i: int, y: int, xx: int,
                        h: int, w: int, wc: int) -> wp.vec4:
    """:func:`_presmoothed` at the neighbours (right, left, down, up) that exist."""
    v = wp.vec4(0.0)
    if xx + 1 < w:
        v[0] = _presmoothed(r, dinv, e, corrected, weighted, a2, omega, c, i + 1, y, xx + 1, h, w, wc)
    if xx > 0:
        v[1] = _presmoothed(r, dinv, e, corrected, weighted, a2, omega, c, i - 1, y, xx - 1, h, w, wc)
    if y + 1 < h:
        v[2] = _presmoothed(r, dinv, e, corrected, weighted, a2, omega, c, i + w, y + 1, xx, h, w, wc)
    if y > 0:
        v[3] = _presmoothed(r, dinv, e, corrected, weighted, a2, omega, c, i - w, y - 1, xx, h, w, wc)
    return v


@wp.func
def _post_smoothed(r: wp.array2d(dtype=wp.float32), wpri: wp.array2d(dtype=wp.float32), wx: wp.array2d(dtype=wp.float32),
                   wy: wp.array2d(dtype=wp.float32), dinv: wp.array2d(dtype=wp.float32), e: wp.array2d(dtype=wp.float32),
                   corrected: int, weighted: int, a2: float, omega: float, c: int, i: int, y: int, xx: int,
                   h: int, w: int, wc: int) -> float:
    """The last sweep of a level, x + ω D⁻¹ (r − A x), at x = the corrected guess."""
    xi = _presmoothed(r, dinv, e, corrected, weighted, a2, omega, c, i, y, xx, h, w, wc)
    around = _presmoothed_around(r, dinv, e, corrected, weighted, a2, omega, c, i, y, xx, h, w, wc)
    return _swept(xi, around, r, wpri, wx, wy, dinv, weighted, a2, omega, c, i, y, xx, h, w)


@wp.kernel
def restrict_residual(r: wp.array2d(dtype=wp.float32), wpri: wp.array2d(dtype=wp.float32), wx: wp.array2d(dtype=wp.float32),
                      wy: wp.array2d(dtype=wp.float32), dinv: wp.array2d(dtype=wp.float32), weighted: int, a2: float,
                      omega: float, hf: int, wf: int, wc: int, rc: wp.array2d(dtype=wp.float32)):
    """rc = Pᵀ (r − A x) at x = ω D⁻¹ r (the pre-smoothed guess): the fine residual summed over each coarse pixel."""
    c, yc, xc = wp.tid()
    acc = float(0.0)
    for dy in range(2):
        y = 2 * yc + dy
        for dx in range(2):
            xx = 2 * xc + dx
            if y < hf and xx < wf:
                i = y * wf + xx
                xi = _presmoothed(r, dinv, rc, 0, weighted, a2, omega, c, i, y, xx, hf, wf, 1)
                around = _presmoothed_around(r, dinv, rc, 0, weighted, a2, omega, c, i, y, xx, hf, wf, 1)
                acc += r[c, i] - _stencil(xi, around, wpri, wx, wy, weighted, a2, c, i, y, xx, hf, wf)
    rc[c, yc * wc + xc] = acc


@wp.kernel
def post_smooth(r: wp.array2d(dtype=wp.float32), wpri: wp.array2d(dtype=wp.float32), wx: wp.array2d(dtype=wp.float32),
                wy: wp.array2d(dtype=wp.float32), dinv: wp.array2d(dtype=wp.float32), ec: wp.array2d(dtype=wp.float32),
                weighted: int, a2: float, omega: float, h: int, w: int, wc: int, e: wp.array2d(dtype=wp.float32)):
    """e = the level's correction: the pre-smoothed guess, corrected by the level below, swept once more."""
    c, y, xx = wp.tid()
    i = y * w + xx
    e[c, i] = _post_smoothed(r, wpri, wx, wy, dinv, ec, 1, weighted, a2, omega, c, i, y, xx, h, w, wc)


@wp.kernel
def post_smooth_dot(r: wp.array2d(dtype=wp.float32), wpri: wp.array2d(dtype=wp.float32), wx: wp.array2d(dtype=wp.float32),
                    wy: wp.array2d(dtype=wp.float32), dinv: wp.array2d(dtype=wp.float32), ec: wp.array2d(dtype=wp.float32),
                    corrected: int, weighted: int, a2: float, omega: float, h: int, w: int, wc: int,
                    rows: int, strips: int, lanes: int, z: wp.array2d(dtype=wp.float32), scal: wp.array2d(dtype=wp.float32),
                    slot: int):
    """:func:`post_smooth` on the finest level, z = M r, with r·z into CG's ``slot`` (a tiled kernel: the launch
    shape of :mod:`grisx.poisson.operators`)."""
    c, by, bx, lane = wp.tid()
    rz = float(0.0)
    for j in range(rows):
        y = by * rows + j
        for strip in range(strips):
            xx = (bx * strips + strip) * lanes + lane
            if y < h and xx < w:
                i = y * w + xx
                zi = _post_smoothed(r, wpri, wx, wy, dinv, ec, corrected, weighted, a2, omega, c, i, y, xx, h, w, wc)
                z[c, i] = zi
                rz += r[c, i] * zi
    wp.tile_atomic_add(scal[SCAL_RZ + slot], wp.tile_sum(wp.tile(rz)), offset=c)


# ---- the hierarchy ----


@dataclass
class MultigridLevel:
    """One coarse level: its size, Galerkin weights and diagonal, and the vectors of a V-cycle."""

    height: int
    width: int
    wpri: wp.array
    wx: wp.array
    wy: wp.array
    dinv: wp.array
    r: wp.array  # the restricted residual (this level's right-hand side)
    e: wp.array  # the correction this level hands up
    t: wp.array  # the other buffer of the coarsest level's sweeps


class Multigrid:
    """The coarse levels below a :class:`~grisx.poisson.cg.PlanarSystem` and its V-cycle (launches only)."""

    def __init__(self, system) -> None:
        self.system = system
        self.levels: list[MultigridLevel] = []
        h, w = system.height, system.width
        while max(h, w) > COARSEST_SIDE:
            h, w = (h + 1) // 2, (w + 1) // 2

            def empty() -> wp.array:
                return wp.empty((system.channels, h * w), dtype=wp.float32, device=system.device)

            self.levels.append(MultigridLevel(h, w, empty(), empty(), empty(), empty(), empty(), empty(), empty()))
        self._none = wp.zeros((system.channels, 1), dtype=wp.float32, device=system.device)  # a 1×1 image has no level below

    def assemble(self, weighted: bool) -> None:
        """The coarse weights from the finest level's (ones for L2, IRLS's weights when ``weighted``)."""
        s = self.system
        a2 = s.alpha * s.alpha
        fine = (s.wpri, s.wx, s.wy, int(weighted), s.height, s.width)
        for lv in self.levels:
            wpri, wx, wy, wtd, hf, wf = fine
            wp.launch(coarsen, dim=(s.channels, lv.height, lv.width), inputs=[wpri, wx, wy, wtd, a2, hf, wf, lv.width],
                      outputs=[lv.wpri, lv.wx, lv.wy, lv.dinv], device=s.device)
            fine = (lv.wpri, lv.wx, lv.wy, 1, lv.height, lv.width)

    def precondition(self, weighted: bool, z: wp.array, slot: int) -> None:
        """z = M r for CG's residual r (one V-cycle), with r·z added into CG's scalar ``slot``."""
        s = self.system
        a2 = s.alpha * s.alpha
        fine = [s.r, s.wpri, s.wx, s.wy, s.dinv, int(weighted), a2]
        ec, wc = self._none, 1
        if self.levels:
            first = self.levels[0]
            wp.launch(restrict_residual, dim=(s.channels, first.height, first.width),
                      inputs=[*fine, OMEGA, s.height, s.width, first.width], outputs=[first.r], device=s.device)
            self._cycle(0)
            ec, wc = first.e, first.width
        columns = s.lanes * s.strips
        wp.launch_tiled(post_smooth_dot, dim=(s.channels, (s.height + s.rows - 1) // s.rows, (s.width + columns - 1) // columns),
                        inputs=[s.r, s.wpri, s.wx, s.wy, s.dinv, ec, int(bool(self.levels)), int(weighted), a2, OMEGA,
                                s.height, s.width, wc, s.rows, s.strips, s.lanes],
                        outputs=[z, s.scal, slot], block_dim=s.lanes, device=s.device)

    def _cycle(self, k: int) -> None:
        """Level k's correction into ``levels[k].e`` from its right-hand side ``levels[k].r``."""
        s, lv = self.system, self.levels[k]
        a2 = s.alpha * s.alpha
        dim = (s.channels, lv.height, lv.width)
        if k + 1 < len(self.levels):
            below = self.levels[k + 1]
            level = [lv.r, lv.wpri, lv.wx, lv.wy, lv.dinv, 1, a2]
            wp.launch(restrict_residual, dim=(s.channels, below.height, below.width),
                      inputs=[*level, OMEGA, lv.height, lv.width, below.width], outputs=[below.r], device=s.device)
            self._cycle(k + 1)
            wp.launch(post_smooth, dim=dim, inputs=[*level[:5], below.e, 1, a2, OMEGA, lv.height, lv.width, below.width],
                      outputs=[lv.e], device=s.device)
            return
        # the coarsest level: Jacobi sweeps alternating between two buffers, the last one into e
        bufs = (lv.t, lv.e) if (COARSEST_SWEEPS - 1) % 2 == 1 else (lv.e, lv.t)
        weights = [lv.wpri, lv.wx, lv.wy, lv.dinv, 1, a2, lv.height, lv.width, OMEGA]
        wp.launch(smooth_from_zero, dim=dim, inputs=[lv.r, lv.dinv, 1, a2, lv.height, lv.width, OMEGA], outputs=[bufs[0]], device=s.device)
        for j in range(COARSEST_SWEEPS - 1):
            wp.launch(smooth, dim=dim, inputs=[bufs[j % 2], lv.r, *weights], outputs=[bufs[(j + 1) % 2]], device=s.device)
