"""Warp kernels for the screened Poisson operator, preconditioned CG and IRLS.

Every iterative solve in :mod:`grisx.poisson` (L2 on a GPU, the inner solves
of L1) is a linear system of one form, the *weighted* screened Poisson
equation

.. math::

    \\big(α² W_p + ∇ᵀ W_g ∇\\big) I = α² W_p P + ∇ᵀ W_g G,

with non-negative diagonal weights ``W_p`` (one per pixel) and ``W_g`` (one per
edge, i.e. per entry of ``dx``/``dy`` that exists). L2 has all weights 1
(``weighted = 0`` skips reading them); IRLS for L1 sets them from the current
residual (:mod:`grisx.poisson.l1`). The matrix is a 5-point stencil, symmetric
positive definite for ``α > 0``, and never stored: ``_apply`` evaluates it
matrix-free from the gradient convention of :mod:`grisx.poisson.gradient`.

Layout and reductions
---------------------
Images live *planar*, as ``(C, H*W)`` float32 arrays, pixel ``i = y*W + x``;
each colour channel is an independent system with its own CG scalars. CG needs
two dot products per iteration; they are fused into the kernels that produce
their operands (``p·Ap`` into the mat-vec, ``r·z`` and ``r·r`` into the update)
and reduced per block with Warp tiles, one atomic add per block and channel.
A block covers a tile of ``rows`` image rows by ``lanes × strips`` columns:
lane ``l`` of strip ``s`` takes column ``(bx·strips + s)·lanes + l`` in every
row of the tile, so consecutive lanes read consecutive pixels (coalesced), a
pixel's row neighbours were just read by its neighbour lanes, and no index is
divided by the width (see :mod:`grisx.poisson.cg` for the launch shape). The
unweighted (L2) system never stores its diagonal: it is ``α²`` plus the
pixel's number of neighbours.
The scalars stay on the device: a kernel reads ``ρ_k = r_k·z_k`` and
``p_k·Ap_k`` from a small array, so an iteration needs no host round trip. The
scalars rotate through three slots (iteration ``k`` uses slot ``k % 3``) so that
each kernel zeroes the accumulators of the *next* iteration without racing
with the reads of the current one.

CG is the textbook preconditioned conjugate gradient [Saa03, Alg. 9.1], with
the Jacobi preconditioner ``M = diag(A)`` computed in the kernels (``jacobi``)
or ``z = M⁻¹ r`` made by the multigrid V-cycle of :mod:`grisx.poisson.multigrid`::

    r = b - A x;  z = M⁻¹ r;  p = z
    repeat:  a = (r·z)/(p·Ap);  x += a p;  r -= a Ap
             z = M⁻¹ r;  β = (r·z)_new/(r·z)_old;  p = z + β p

Keep the number of kernels small: they are compiled once per device, and
runtime parameters (``weighted``, ``a2``, the iteration ``k``) select
behaviour instead of specialised copies.

References
----------
[Saa03] Saad. Iterative Methods for Sparse Linear Systems, 2nd ed., SIAM 2003,
        Algorithm 9.1 (preconditioned CG).
[KMA*15] Kettunen et al. Gradient-Domain Path Tracing. ACM TOG 34(4), 2015.
"""

from __future__ import annotations

import warp as wp

# Reconstruction needs no adjoints; skipping them halves compile time.
wp.set_module_options({"enable_backward": False})

__all__ = [
    "SCAL_RZ",
    "SCAL_PAP",
    "SCAL_RR",
    "SCAL_BB",
    "SCAL_ROWS",
    "MEASURE_ROWS",
]

# Rows of the (SCAL_ROWS, C) scalar array a CG solve keeps on the device.
SCAL_RZ = wp.constant(0)  # rows 0..2: r·z for the three rotating slots
SCAL_PAP = wp.constant(3)  # rows 3..5: p·Ap
SCAL_RR = wp.constant(6)  # rows 6..8: r·r (the unpreconditioned residual, for stopping)
SCAL_BB = wp.constant(9)  # row 9: b·b
SCAL_ROWS = 10
# Rows of the (MEASURE_ROWS, C) array ``measure`` fills: ‖b-Ax‖², ‖b‖², L2 and L1 energy.
MEASURE_ROWS = 4


# ---- the weighted screened Poisson operator (matrix-free) ----


@wp.func
def _weight(w: wp.array2d(dtype=wp.float32), c: int, i: int, weighted: int) -> float:
    # Unweighted (L2) systems never touch the weight arrays.
    if weighted != 0:
        return w[c, i]
    return 1.0


@wp.func
def _stencil(xi: float, around: wp.vec4, wpri: wp.array2d(dtype=wp.float32), wx: wp.array2d(dtype=wp.float32),
             wy: wp.array2d(dtype=wp.float32), weighted: int, a2: float, c: int, i: int, y: int, xx: int,
             h: int, w: int) -> float:
    """(α² W_p + ∇ᵀ W_g ∇) x at pixel i = (y, xx) from x there and at its neighbours ``around`` = (right, left,
    down, up): a Neumann 5-point stencil (an edge enters only if both of its pixels exist)."""
    acc = a2 * _weight(wpri, c, i, weighted) * xi
    if xx + 1 < w:
        acc += _weight(wx, c, i, weighted) * (xi - around[0])
    if xx > 0:
        acc += _weight(wx, c, i - 1, weighted) * (xi - around[1])
    if y + 1 < h:
        acc += _weight(wy, c, i, weighted) * (xi - around[2])
    if y > 0:
        acc += _weight(wy, c, i - w, weighted) * (xi - around[3])
    return acc


@wp.func
def _around(x: wp.array2d(dtype=wp.float32), c: int, i: int, y: int, xx: int, h: int, w: int) -> wp.vec4:
    """x at the neighbours (right, left, down, up) of pixel i that exist (0 elsewhere: never weighed)."""
    v = wp.vec4(0.0)
    if xx + 1 < w:
        v[0] = x[c, i + 1]
    if xx > 0:
        v[1] = x[c, i - 1]
    if y + 1 < h:
        v[2] = x[c, i + w]
    if y > 0:
        v[3] = x[c, i - w]
    return v


@wp.func
def _apply(x: wp.array2d(dtype=wp.float32), wpri: wp.array2d(dtype=wp.float32),
           wx: wp.array2d(dtype=wp.float32), wy: wp.array2d(dtype=wp.float32),
           weighted: int, a2: float, c: int, i: int, y: int, xx: int, h: int, w: int) -> float:
    """(α² W_p + ∇ᵀ W_g ∇) x at pixel i = (y, xx)."""
    return _stencil(x[c, i], _around(x, c, i, y, xx, h, w), wpri, wx, wy, weighted, a2, c, i, y, xx, h, w)


@wp.func
def _diagonal(wpri: wp.array2d(dtype=wp.float32), wx: wp.array2d(dtype=wp.float32),
              wy: wp.array2d(dtype=wp.float32), weighted: int, a2: float,
              c: int, i: int, y: int, xx: int, h: int, w: int) -> float:
    d = a2 * _weight(wpri, c, i, weighted)
    if xx + 1 < w:
        d += _weight(wx, c, i, weighted)
    if xx > 0:
        d += _weight(wx, c, i - 1, weighted)
    if y + 1 < h:
        d += _weight(wy, c, i, weighted)
    if y > 0:
        d += _weight(wy, c, i - w, weighted)
    return d


@wp.func
def _inv_diagonal(dinv: wp.array2d(dtype=wp.float32), weighted: int, a2: float,
                  c: int, i: int, y: int, xx: int, h: int, w: int) -> float:
    """The Jacobi preconditioner diag(A)⁻¹ at pixel i: stored for a weighted system, else α² + neighbours."""
    if weighted != 0:
        return dinv[c, i]
    d = a2
    if xx + 1 < w:
        d += 1.0
    if xx > 0:
        d += 1.0
    if y + 1 < h:
        d += 1.0
    if y > 0:
        d += 1.0
    return 1.0 / d


@wp.func
def _rhs(primal: wp.array2d(dtype=wp.float32), gx: wp.array2d(dtype=wp.float32),
         gy: wp.array2d(dtype=wp.float32), wpri: wp.array2d(dtype=wp.float32),
         wx: wp.array2d(dtype=wp.float32), wy: wp.array2d(dtype=wp.float32),
         weighted: int, a2: float, c: int, i: int, y: int, xx: int, h: int, w: int) -> float:
    """α² W_p P + ∇ᵀ W_g G at pixel i = (y, xx); the ignored last column/row of G is never read."""
    acc = a2 * _weight(wpri, c, i, weighted) * primal[c, i]
    if xx + 1 < w:
        acc -= _weight(wx, c, i, weighted) * gx[c, i]
    if xx > 0:
        acc += _weight(wx, c, i - 1, weighted) * gx[c, i - 1]
    if y + 1 < h:
        acc -= _weight(wy, c, i, weighted) * gy[c, i]
    if y > 0:
        acc += _weight(wy, c, i - w, weighted) * gy[c, i - w]
    return acc


# ---- layout and input checks ----


@wp.kernel
def count_nonfinite(a: wp.array3d(dtype=wp.float32), nx: int, ny: int,
                    counts: wp.array(dtype=wp.int32), slot: int):
    """Count pixels (y < ny, x < nx) with a NaN/Inf channel into counts[slot]."""
    y, x = wp.tid()
    if x < nx and y < ny:
        bad = int(0)
        for c in range(a.shape[2]):
            if not wp.isfinite(a[y, x, c]):
                bad = 1
        if bad != 0:
            wp.atomic_add(counts, slot, 1)


@wp.kernel
def hwc_to_planar(src: wp.array3d(dtype=wp.float32), dst: wp.array2d(dtype=wp.float32), w: int):
    y, x, c = wp.tid()
    dst[c, y * w + x] = src[y, x, c]


@wp.kernel
def planar_to_hwc(src: wp.array2d(dtype=wp.float32), dst: wp.array3d(dtype=wp.float32), w: int):
    y, x, c = wp.tid()
    dst[y, x, c] = src[c, y * w + x]


# ---- system assembly ----


@wp.kernel
def build_system(primal: wp.array2d(dtype=wp.float32), gx: wp.array2d(dtype=wp.float32),
                 gy: wp.array2d(dtype=wp.float32), wpri: wp.array2d(dtype=wp.float32),
                 wx: wp.array2d(dtype=wp.float32), wy: wp.array2d(dtype=wp.float32),
                 weighted: int, a2: float, h: int, w: int, rows: int, strips: int, lanes: int,
                 b: wp.array2d(dtype=wp.float32), dinv: wp.array2d(dtype=wp.float32)):
    """Right-hand side b and the Jacobi preconditioner diag(A)⁻¹."""
    c, by, bx, lane = wp.tid()
    for j in range(rows):
        y = by * rows + j
        for strip in range(strips):
            xx = (bx * strips + strip) * lanes + lane
            if y < h and xx < w:
                i = y * w + xx
                b[c, i] = _rhs(primal, gx, gy, wpri, wx, wy, weighted, a2, c, i, y, xx, h, w)
                if weighted != 0:  # the unweighted diagonal is never stored
                    dinv[c, i] = 1.0 / _diagonal(wpri, wx, wy, weighted, a2, c, i, y, xx, h, w)


@wp.func
def _irls_weight(x: wp.array2d(dtype=wp.float32), primal: wp.array2d(dtype=wp.float32),
                 gx: wp.array2d(dtype=wp.float32), gy: wp.array2d(dtype=wp.float32),
                 alpha: float, eps: float, h: int, w: int,
                 wpri: wp.array2d(dtype=wp.float32), wx: wp.array2d(dtype=wp.float32),
                 wy: wp.array2d(dtype=wp.float32), c: int, i: int, y: int, xx: int):
    xi = x[c, i]
    wpri[c, i] = 1.0 / wp.max(alpha * wp.abs(xi - primal[c, i]), eps)
    # Absent edges get weight 0 so a NaN in the ignored column can never leak in.
    wxi = float(0.0)
    if xx + 1 < w:
        wxi = 1.0 / wp.max(wp.abs(x[c, i + 1] - xi - gx[c, i]), eps)
    wx[c, i] = wxi
    wyi = float(0.0)
    if y + 1 < h:
        wyi = 1.0 / wp.max(wp.abs(x[c, i + w] - xi - gy[c, i]), eps)
    wy[c, i] = wyi


@wp.kernel
def irls_weights(x: wp.array2d(dtype=wp.float32), primal: wp.array2d(dtype=wp.float32),
                 gx: wp.array2d(dtype=wp.float32), gy: wp.array2d(dtype=wp.float32),
                 alpha: float, eps: float, h: int, w: int, rows: int, strips: int, lanes: int,
                 wpri: wp.array2d(dtype=wp.float32), wx: wp.array2d(dtype=wp.float32),
                 wy: wp.array2d(dtype=wp.float32)):
    """IRLS weights 1/max(|ρ_j|, ε) for the residuals ρ = (α(x-P), ∇x-G)."""
    c, by, bx, lane = wp.tid()
    for j in range(rows):
        y = by * rows + j
        for strip in range(strips):
            xx = (bx * strips + strip) * lanes + lane
            if y < h and xx < w:
                i = y * w + xx
                _irls_weight(x, primal, gx, gy, alpha, eps, h, w, wpri, wx, wy, c, i, y, xx)


# ---- preconditioned CG ----
# Tiled kernels on a grid (C, row tiles, column tiles) (module docstring): a block reduces its
# tile with one atomic add per scalar, which keeps the contention on the scalar slots low.


@wp.kernel
def cg_init(x: wp.array2d(dtype=wp.float32), b: wp.array2d(dtype=wp.float32),
            dinv: wp.array2d(dtype=wp.float32), wpri: wp.array2d(dtype=wp.float32),
            wx: wp.array2d(dtype=wp.float32), wy: wp.array2d(dtype=wp.float32),
            weighted: int, a2: float, h: int, w: int, rows: int, strips: int, lanes: int, jacobi: int,
            r: wp.array2d(dtype=wp.float32), p: wp.array2d(dtype=wp.float32),
            scal: wp.array2d(dtype=wp.float32)):
    """r = b - Ax; r·r, b·b into slot 0 (scal zeroed before); with ``jacobi``, also p = z = D⁻¹r and r·z
    (another preconditioner makes z and r·z itself)."""
    c, by, bx, lane = wp.tid()
    rz = float(0.0)
    rr = float(0.0)
    bb = float(0.0)
    for j in range(rows):
        y = by * rows + j
        for strip in range(strips):
            xx = (bx * strips + strip) * lanes + lane
            if y < h and xx < w:
                i = y * w + xx
                bi = b[c, i]
                ri = bi - _apply(x, wpri, wx, wy, weighted, a2, c, i, y, xx, h, w)
                r[c, i] = ri
                if jacobi != 0:
                    zi = _inv_diagonal(dinv, weighted, a2, c, i, y, xx, h, w) * ri
                    p[c, i] = zi
                    rz += ri * zi
                rr += ri * ri
                bb += bi * bi
    if jacobi != 0:
        wp.tile_atomic_add(scal[SCAL_RZ], wp.tile_sum(wp.tile(rz)), offset=c)
    wp.tile_atomic_add(scal[SCAL_RR], wp.tile_sum(wp.tile(rr)), offset=c)
    wp.tile_atomic_add(scal[SCAL_BB], wp.tile_sum(wp.tile(bb)), offset=c)


@wp.kernel
def cg_matvec(p: wp.array2d(dtype=wp.float32), wpri: wp.array2d(dtype=wp.float32),
              wx: wp.array2d(dtype=wp.float32), wy: wp.array2d(dtype=wp.float32),
              weighted: int, a2: float, h: int, w: int, rows: int, strips: int, lanes: int,
              ap: wp.array2d(dtype=wp.float32), scal: wp.array2d(dtype=wp.float32), k: int):
    """Ap = A p and p·Ap into slot k % 3."""
    c, by, bx, lane = wp.tid()
    pap = float(0.0)
    for j in range(rows):
        y = by * rows + j
        for strip in range(strips):
            xx = (bx * strips + strip) * lanes + lane
            if y < h and xx < w:
                i = y * w + xx
                api = _apply(p, wpri, wx, wy, weighted, a2, c, i, y, xx, h, w)
                ap[c, i] = api
                pap += p[c, i] * api
    wp.tile_atomic_add(scal[SCAL_PAP + k % 3], wp.tile_sum(wp.tile(pap)), offset=c)


@wp.kernel
def cg_update(x: wp.array2d(dtype=wp.float32), r: wp.array2d(dtype=wp.float32),
              p: wp.array2d(dtype=wp.float32), ap: wp.array2d(dtype=wp.float32),
              dinv: wp.array2d(dtype=wp.float32), weighted: int, a2: float,
              h: int, w: int, rows: int, strips: int, lanes: int, jacobi: int,
              scal: wp.array2d(dtype=wp.float32), k: int):
    """x += a p, r -= a Ap with a = (r·z)/(p·Ap); new r·r (and, with ``jacobi``, r·z) into slot (k+1) % 3."""
    c, by, bx, lane = wp.tid()
    s = k % 3
    s1 = (k + 1) % 3
    pap = scal[SCAL_PAP + s, c]
    # A converged (or all-zero) channel has p·Ap = 0: take no step instead of 0/0.
    a = float(0.0)
    if pap > 0.0:
        a = scal[SCAL_RZ + s, c] / pap
    rz = float(0.0)
    rr = float(0.0)
    for j in range(rows):
        y = by * rows + j
        for strip in range(strips):
            xx = (bx * strips + strip) * lanes + lane
            if y < h and xx < w:
                i = y * w + xx
                x[c, i] = x[c, i] + a * p[c, i]
                ri = r[c, i] - a * ap[c, i]
                r[c, i] = ri
                if jacobi != 0:
                    rz += ri * ri * _inv_diagonal(dinv, weighted, a2, c, i, y, xx, h, w)
                rr += ri * ri
    if jacobi != 0:
        wp.tile_atomic_add(scal[SCAL_RZ + s1], wp.tile_sum(wp.tile(rz)), offset=c)
    wp.tile_atomic_add(scal[SCAL_RR + s1], wp.tile_sum(wp.tile(rr)), offset=c)


@wp.kernel
def cg_direction(r: wp.array2d(dtype=wp.float32), z: wp.array2d(dtype=wp.float32), dinv: wp.array2d(dtype=wp.float32),
                 weighted: int, a2: float, h: int, w: int, rows: int, strips: int, lanes: int, jacobi: int,
                 p: wp.array2d(dtype=wp.float32), scal: wp.array2d(dtype=wp.float32), k: int):
    """p = z + β p, z = M⁻¹r (D⁻¹r with ``jacobi``, else the preconditioner's ``z``); zero the accumulators
    iteration k+1 will add into."""
    c, by, bx, lane = wp.tid()
    s = k % 3
    s1 = (k + 1) % 3
    s2 = (k + 2) % 3
    rz_old = scal[SCAL_RZ + s, c]
    beta = float(0.0)
    if rz_old > 0.0:
        beta = scal[SCAL_RZ + s1, c] / rz_old
    for j in range(rows):
        y = by * rows + j
        for strip in range(strips):
            xx = (bx * strips + strip) * lanes + lane
            if y < h and xx < w:
                i = y * w + xx
                zi = float(0.0)
                if jacobi != 0:
                    zi = _inv_diagonal(dinv, weighted, a2, c, i, y, xx, h, w) * r[c, i]
                else:
                    zi = z[c, i]
                p[c, i] = zi + beta * p[c, i]
    # Nobody reads these slots in this kernel, so one lane may clear them.
    if by == 0 and bx == 0 and lane == 0:
        scal[SCAL_PAP + s1, c] = 0.0
        scal[SCAL_RZ + s2, c] = 0.0
        scal[SCAL_RR + s2, c] = 0.0


@wp.kernel
def cg_continue(scal: wp.array2d(dtype=wp.float32), tol2: float, step: int, limit: int,
                iterations: wp.array(dtype=wp.int32), keep_going: wp.array(dtype=wp.int32)):
    """The stopping rule of a CG loop, on the device (one thread): count ``step`` more iterations
    (0 right after ``cg_init``) and go on while fewer than ``limit`` ran and some channel still has
    r·r > tol² b·b (r·r of iteration k is in slot k % 3)."""
    k = iterations[0] + step
    iterations[0] = k
    go = int(0)
    if k < limit:
        for c in range(scal.shape[1]):
            if scal[SCAL_RR + k % 3, c] > tol2 * scal[SCAL_BB, c]:
                go = 1
    keep_going[0] = go


@wp.kernel
def cold_start(x: wp.array2d(dtype=wp.float32), primal: wp.array2d(dtype=wp.float32),
               cold: wp.array(dtype=wp.int32)):
    """x = P where ``cold[0]`` is set (a first frame, or no warm start); else x is kept (warm start)."""
    c, i = wp.tid()
    if cold[0] != 0:
        x[c, i] = primal[c, i]


# ---- measurement ----


@wp.kernel
def measure(x: wp.array2d(dtype=wp.float32), b: wp.array2d(dtype=wp.float32),
            primal: wp.array2d(dtype=wp.float32), gx: wp.array2d(dtype=wp.float32),
            gy: wp.array2d(dtype=wp.float32), wpri: wp.array2d(dtype=wp.float32),
            wx: wp.array2d(dtype=wp.float32), wy: wp.array2d(dtype=wp.float32),
            weighted: int, alpha: float, h: int, w: int, rows: int, strips: int, lanes: int,
            out: wp.array2d(dtype=wp.float32)):
    """‖b - Ax‖², ‖b‖² of the last system and the L2/L1 energies of x, per channel."""
    c, by, bx, lane = wp.tid()
    rr = float(0.0)
    bb = float(0.0)
    e2 = float(0.0)
    e1 = float(0.0)
    for j in range(rows):
        y = by * rows + j
        for strip in range(strips):
            xx = (bx * strips + strip) * lanes + lane
            if y < h and xx < w:
                i = y * w + xx
                y = i / w
                xx = i - y * w
                bi = b[c, i]
                ri = bi - _apply(x, wpri, wx, wy, weighted, alpha * alpha, c, i, y, xx, h, w)
                rr += ri * ri
                bb += bi * bi
                xi = x[c, i]
                rp = alpha * (xi - primal[c, i])
                e2 += rp * rp
                e1 += wp.abs(rp)
                if xx + 1 < w:
                    rx = x[c, i + 1] - xi - gx[c, i]
                    e2 += rx * rx
                    e1 += wp.abs(rx)
                if y + 1 < h:
                    ry = x[c, i + w] - xi - gy[c, i]
                    e2 += ry * ry
                    e1 += wp.abs(ry)
    wp.tile_atomic_add(out[0], wp.tile_sum(wp.tile(rr)), offset=c)
    wp.tile_atomic_add(out[1], wp.tile_sum(wp.tile(bb)), offset=c)
    wp.tile_atomic_add(out[2], wp.tile_sum(wp.tile(e2)), offset=c)
    wp.tile_atomic_add(out[3], wp.tile_sum(wp.tile(e1)), offset=c)
