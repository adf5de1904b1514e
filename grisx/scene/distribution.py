"""Discrete and piecewise-constant distributions: the tables that light sampling draws from.

Three samplers, each built once on the host in float64 (numpy) and stored as a
Warp struct of float32/int32 arrays that kernels sample from:

**Alias table** (Walker 1977; Vose 1991). A discrete distribution over n items
with weights w_i ≥ 0 is split into n equiprobable columns; column i keeps
item i with probability ``prob[i]`` and otherwise returns ``alias[i]``. One
uniform u picks the column i = ⌊u n⌋ and reuses its fraction u n − i for the
coin, so sampling costs O(1) whatever n is:

    P(i) = pmf_i = w_i / Σ w.

Items of zero weight are never returned. grisx selects among lights with it
(power-proportional selection).

**Piecewise-constant 1D** (pbrt-v4 ``PiecewiseConstant1D``, PBR 4th ed.
§A.4.1). A non-negative function f given by n values on [0, 1) has density
p(x) = f_i / ∫f on cell i = ⌊x n⌋, with CDF
``cdf[i] = Σ_{k<i} f_k / (n ∫f)``. Sampling inverts the CDF: find the last i
with cdf[i] ≤ u, then x = (i + (u − cdf[i]) / (cdf[i+1] − cdf[i])) / n.
``invert`` maps x back to u (the same CDF, forwards).

**Piecewise-constant 2D** (pbrt-v4 ``PiecewiseConstant2D``, §A.5.2). A function
f(u, v) given on an n_v × n_u grid over [0, 1)² is sampled as a marginal in v
(row integrals) and a conditional in u (the chosen row), so

    p(u, v) = p_v(v) · p(u | v) = f(u, v) / ∫∫ f.

``u[1]`` drives the marginal and ``u[0]`` the conditional, as in pbrt; the
result's first coordinate is u (column), the second v (row). Environment maps
sample this with f = luminance · sin θ, then turn the (u, v) density into a
solid-angle density with the Jacobian 1 / (2π² sin θ) (see
:mod:`grisx.scene.lights`).

If every weight is zero, sampling still returns a point (uniform, as pbrt) but
with pdf 0, so callers treat it as "no sample" without dividing by zero.

Sampling triples: ``sample_*(table, u)``, ``*_pdf(table, x)``, ``invert_*(table, x)``.

References: A. J. Walker, "An efficient method for generating discrete random
variables with general distributions", ACM TOMS 3 (1977); M. D. Vose, "A linear
algorithm for generating random numbers with a given distribution", IEEE TSE 17
(1991); M. Pharr, W. Jakob, G. Humphreys, *Physically Based Rendering*, 4th ed.
(2023), §A.1 (alias method), §A.4.1 and §A.5.2 (piecewise-constant).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from grisx.errors import InvalidParameterError, InvalidValueError

wp.set_module_options({"enable_backward": False})

__all__ = [
    "AliasTable",
    "PiecewiseConstant1D",
    "PiecewiseConstant1DSample",
    "PiecewiseConstant2D",
    "PiecewiseConstant2DSample",
    "alias_table_arrays",
    "build_alias_table",
    "sample_alias",
    "alias_pmf",
    "build_piecewise_constant_1d",
    "sample_piecewise_constant_1d",
    "piecewise_constant_1d_pdf",
    "invert_piecewise_constant_1d",
    "build_piecewise_constant_2d",
    "sample_piecewise_constant_2d",
    "piecewise_constant_2d_pdf",
    "invert_piecewise_constant_2d",
]

#: the largest float32 below 1: samples stay in [0, 1)
_ONE_MINUS_EPS = wp.constant(0.99999994)


def _check_weights(weights: np.ndarray, what: str, ndim: int) -> np.ndarray:
    w = np.asarray(weights, dtype=np.float64)
    if w.ndim != ndim:
        raise InvalidParameterError(f"{what} must be a {ndim}D array, got shape {w.shape}")
    if w.size == 0:
        raise InvalidParameterError(f"{what} must not be empty")
    if not np.all(np.isfinite(w)):
        raise InvalidValueError(f"{what} contains NaN or Inf")
    if np.any(w < 0):
        raise InvalidValueError(f"{what} must be non-negative (min {w.min():g})")
    return w


# ---- alias table --------------------------------------------------------------------


@wp.struct
class AliasTable:
    """Walker/Vose alias table over ``size`` items (``total`` = Σ w, 0 if nothing can be drawn)."""

    prob: wp.array(dtype=wp.float32)
    alias: wp.array(dtype=wp.int32)
    pmf: wp.array(dtype=wp.float32)
    size: int
    total: float


def alias_table_arrays(weights: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Vose's construction in float64: (prob, alias, pmf, total) for non-negative ``weights``."""
    w = _check_weights(weights, "alias table weights", 1)
    n = w.size
    total = float(w.sum())
    prob = np.zeros(n, dtype=np.float64)
    alias = np.arange(n, dtype=np.int64)
    if total <= 0.0:
        return prob, alias, np.zeros(n), 0.0
    pmf = w / total
    scaled = pmf * n
    small = [i for i in range(n) if scaled[i] < 1.0]
    large = [i for i in range(n) if scaled[i] >= 1.0]
    while small and large:
        s, g = small.pop(), large.pop()
        prob[s] = scaled[s]
        alias[s] = g
        scaled[g] = (scaled[g] + scaled[s]) - 1.0
        (small if scaled[g] < 1.0 else large).append(g)
    # leftovers are 1 up to round-off; an item of zero weight must still never be returned
    fallback = int(np.argmax(w))
    for i in large + small:
        if w[i] > 0:
            prob[i] = 1.0
        else:
            prob[i], alias[i] = 0.0, fallback
    return prob, alias, pmf, total


def build_alias_table(weights: np.ndarray, device: str | None = None) -> AliasTable:
    """Alias table for sampling index i with probability w_i / Σ w (weights ≥ 0, finite)."""
    prob, alias, pmf, total = alias_table_arrays(weights)
    t = AliasTable()
    t.prob = wp.array(prob.astype(np.float32), dtype=wp.float32, device=device)
    t.alias = wp.array(alias.astype(np.int32), dtype=wp.int32, device=device)
    t.pmf = wp.array(pmf.astype(np.float32), dtype=wp.float32, device=device)
    t.size = int(prob.size)
    t.total = float(total)
    return t


@wp.func
def sample_alias(table: AliasTable, u: float) -> int:
    """Index i drawn with probability pmf_i from one uniform u in [0, 1); −1 if the table is empty."""
    if table.size == 0 or table.total <= 0.0:
        return -1
    x = u * float(table.size)
    i = wp.min(int(x), table.size - 1)
    coin = x - float(i)  # the column's fraction of u: uniform in [0, 1) again
    if coin < table.prob[i]:
        return i
    return table.alias[i]


@wp.func
def alias_pmf(table: AliasTable, i: int) -> float:
    """Probability that :func:`sample_alias` returns ``i`` (0 outside the table)."""
    if i < 0 or i >= table.size:
        return 0.0
    return table.pmf[i]


# ---- piecewise-constant 1D ---------------------------------------------------------


@wp.struct
class PiecewiseConstant1D:
    """pbrt-v4's PiecewiseConstant1D on [0, 1): ``func`` (n), ``cdf`` (n + 1), ``integral`` = mean of func."""

    func: wp.array(dtype=wp.float32)
    cdf: wp.array(dtype=wp.float32)
    n: int
    integral: float


@wp.struct
class PiecewiseConstant1DSample:
    """A point x in [0, 1), its density, and the cell it fell in."""

    x: float
    pdf: float
    index: int


def _cdf_rows(f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per row of f (…, n): CDF (…, n + 1) in float64 and the mean of f (= ∫ over [0, 1))."""
    n = f.shape[-1]
    integral = f.mean(axis=-1)
    c = np.concatenate([np.zeros(f.shape[:-1] + (1,)), np.cumsum(f, axis=-1)], axis=-1)
    total = c[..., -1:]
    uniform = np.broadcast_to(np.arange(n + 1) / n, c.shape)
    with np.errstate(invalid="ignore", divide="ignore"):
        cdf = np.where(total > 0, c / np.where(total > 0, total, 1.0), uniform)
    # entries at or after the last positive weight are exactly 1, so no zero-width cell is ever sampled
    cdf = np.where((total > 0) & (c >= total), 1.0, cdf)
    cdf[..., 0] = 0.0
    return cdf, integral


def build_piecewise_constant_1d(func: np.ndarray, device: str | None = None) -> PiecewiseConstant1D:
    """Piecewise-constant density ∝ ``func`` (n non-negative values) on [0, 1)."""
    f = _check_weights(func, "piecewise-constant function", 1)
    cdf, integral = _cdf_rows(f)
    d = PiecewiseConstant1D()
    d.func = wp.array(f.astype(np.float32), dtype=wp.float32, device=device)
    d.cdf = wp.array(cdf.astype(np.float32), dtype=wp.float32, device=device)
    d.n = int(f.size)
    d.integral = float(integral)
    return d


@wp.func
def _cell(x: float, n: int) -> int:
    """The cell ⌊x n⌋ of x in [0, 1), clamped to [0, n − 1]."""
    return wp.clamp(int(x * float(n)), 0, n - 1)


@wp.func
def _sample_cdf(
    func: wp.array(dtype=wp.float32),
    cdf: wp.array(dtype=wp.float32),
    f_offset: int,
    c_offset: int,
    n: int,
    integral: float,
    u: float,
) -> PiecewiseConstant1DSample:
    """Invert one CDF stored at ``cdf[c_offset : c_offset + n + 1]`` (pbrt-v4 PiecewiseConstant1D::Sample)."""
    # largest o in [0, n - 1] with cdf[o] <= u (pbrt's FindInterval)
    lo = int(0)
    hi = n - 1
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if cdf[c_offset + mid] <= u:
            lo = mid
        else:
            hi = mid - 1
    o = lo
    c0 = cdf[c_offset + o]
    c1 = cdf[c_offset + o + 1]
    du = u - c0
    if c1 - c0 > 0.0:
        du = du / (c1 - c0)
    du = wp.clamp(du, 0.0, _ONE_MINUS_EPS)
    x = wp.min((float(o) + du) / float(n), _ONE_MINUS_EPS)
    # float32 rounding of (o + du) / n can carry x over a cell edge (likely once o ~ 1000): step it back
    # so that the pdf functions, which find the cell as ⌊x n⌋, agree with the cell sampled here
    for _step in range(4):
        c = _cell(x, n)
        if c > o:
            x = x - x * 1.2e-7
        elif c < o:
            x = x + x * 1.2e-7
    s = PiecewiseConstant1DSample()
    s.x = x
    s.index = o
    s.pdf = 0.0
    if integral > 0.0:
        s.pdf = func[f_offset + o] / integral
    return s


@wp.func
def sample_piecewise_constant_1d(d: PiecewiseConstant1D, u: float) -> PiecewiseConstant1DSample:
    """x ~ f / ∫f on [0, 1) by CDF inversion of u (pdf 0 when f ≡ 0)."""
    return _sample_cdf(d.func, d.cdf, 0, 0, d.n, d.integral, u)


@wp.func
def piecewise_constant_1d_pdf(d: PiecewiseConstant1D, x: float) -> float:
    """Density of :func:`sample_piecewise_constant_1d` at x (0 outside [0, 1))."""
    if x < 0.0 or x >= 1.0 or d.integral <= 0.0:
        return 0.0
    return d.func[_cell(x, d.n)] / d.integral


@wp.func
def _invert_cdf(cdf: wp.array(dtype=wp.float32), c_offset: int, n: int, x: float) -> float:
    o = _cell(x, n)
    c0 = cdf[c_offset + o]
    c1 = cdf[c_offset + o + 1]
    return c0 + (x * float(n) - float(o)) * (c1 - c0)


@wp.func
def invert_piecewise_constant_1d(d: PiecewiseConstant1D, x: float) -> float:
    """The u that :func:`sample_piecewise_constant_1d` maps to x (the CDF at x)."""
    return _invert_cdf(d.cdf, 0, d.n, wp.clamp(x, 0.0, _ONE_MINUS_EPS))


# ---- piecewise-constant 2D ---------------------------------------------------------


@wp.struct
class PiecewiseConstant2D:
    """pbrt-v4's PiecewiseConstant2D on [0, 1)²: conditionals in u per row (flattened) and the marginal in v."""

    cond_func: wp.array(dtype=wp.float32)  # nv * nu
    cond_cdf: wp.array(dtype=wp.float32)  # nv * (nu + 1)
    marginal: PiecewiseConstant1D  # func = row integrals (nv)
    nu: int
    nv: int


@wp.struct
class PiecewiseConstant2DSample:
    """A point (u, v) in [0, 1)², its density, and the grid cell (column, row)."""

    uv: wp.vec2
    pdf: float
    cell: wp.vec2i


def build_piecewise_constant_2d(func: np.ndarray, device: str | None = None) -> PiecewiseConstant2D:
    """Piecewise-constant density ∝ ``func`` (nv rows × nu columns, non-negative) on [0, 1)²; row index = v."""
    f = _check_weights(func, "piecewise-constant 2D function", 2)
    nv, nu = f.shape
    cond_cdf, row_integrals = _cdf_rows(f)
    d = PiecewiseConstant2D()
    d.cond_func = wp.array(f.astype(np.float32).ravel(), dtype=wp.float32, device=device)
    d.cond_cdf = wp.array(cond_cdf.astype(np.float32).ravel(), dtype=wp.float32, device=device)
    d.marginal = build_piecewise_constant_1d(row_integrals, device)
    d.nu = int(nu)
    d.nv = int(nv)
    return d


@wp.func
def sample_piecewise_constant_2d(d: PiecewiseConstant2D, u: wp.vec2) -> PiecewiseConstant2DSample:
    """(u, v) ~ f / ∫∫f: v from the marginal with u[1], then u from row v's conditional with u[0]."""
    mv = sample_piecewise_constant_1d(d.marginal, u[1])
    row = mv.index
    cu = _sample_cdf(d.cond_func, d.cond_cdf, row * d.nu, row * (d.nu + 1), d.nu, d.marginal.func[row], u[0])
    s = PiecewiseConstant2DSample()
    s.uv = wp.vec2(cu.x, mv.x)
    s.pdf = mv.pdf * cu.pdf  # = f(u, v) / ∫∫ f
    s.cell = wp.vec2i(cu.index, row)
    return s


@wp.func
def piecewise_constant_2d_pdf(d: PiecewiseConstant2D, uv: wp.vec2) -> float:
    """Density of :func:`sample_piecewise_constant_2d` at (u, v) (0 outside [0, 1)²)."""
    if uv[0] < 0.0 or uv[0] >= 1.0 or uv[1] < 0.0 or uv[1] >= 1.0 or d.marginal.integral <= 0.0:
        return 0.0
    return d.cond_func[_cell(uv[1], d.nv) * d.nu + _cell(uv[0], d.nu)] / d.marginal.integral


@wp.func
def invert_piecewise_constant_2d(d: PiecewiseConstant2D, uv: wp.vec2) -> wp.vec2:
    """The (u[0], u[1]) that :func:`sample_piecewise_constant_2d` maps to (u, v)."""
    x = wp.clamp(uv[0], 0.0, _ONE_MINUS_EPS)
    y = wp.clamp(uv[1], 0.0, _ONE_MINUS_EPS)
    row = _cell(y, d.nv)
    return wp.vec2(_invert_cdf(d.cond_cdf, row * (d.nu + 1), d.nu, x), invert_piecewise_constant_1d(d.marginal, y))
