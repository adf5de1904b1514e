"""``gradient-row``: ReSTIR over the pixel pairs of a 1D image, with adaptive spatial reuse.

A row of N pixels (seed 000's Fig. 6 in one dimension: a dark/white stripe
pattern). Pixel i integrates, over its own domain Ω_i = [o_i, o_i + w_i]
(o_i = 0.01 i, w_i = 1 + 0.03 i), in its own coordinate u = (x − o_i)/w_i,

    f_i(x) = A_i · (0.2 + 1.5 g(u; 0.35 + δ i, 0.07) + 0.8 g(u; 0.85, 0.1)),

g(u; c, s) = exp(−((u − c)/s)²), with albedo A_i alternating 0.3 / 0.9 in
stripes of ``stripe`` pixels: the gradients are large at the stripes' edges
and small inside them (the light drifts by δ = ``light_drift`` per pixel,
default 0.004). The outer shift keeps u fixed, so it does *not* follow the
light: pairs 8 pixels apart see it 0.032 apart (its width is 0.07), and a
neighbour's samples fit worse than the pair's own — with ``light_drift=0``
similar pairs match in u up to the domains' widths. The pairs are (i+1, i), so
the components are the forward differences Δ_p = F_{p+1} − F_p (the ``dx`` of
:mod:`grisx.poisson`); exact through erf.

Shifts. Both the *inner* shift between the two pixels of a pair and the
*outer* shift τ between pixel a of one pair and pixel b of another map the
domains affinely (the same u), x ↦ o_b + (x − o_a) w_b / w_a, with
|∂τ/∂x| = w_b / w_a ≠ 1 — bijections here (``f1-f2`` has the partial one).
Over frames (the picture is static) τ is the identity. T* = (τ, k) (seed 000,
Eq. 21–22).

``gradient-with-restir`` runs ``frames`` + 1 frames of: initial candidates
per pair, temporal reuse of the pair's previous reservoirs, then
``spatial_passes`` passes of spatial reuse whose neighbours come from
``spatial``:

``none``      no spatial reuse;
``dense``     every pair merges ``neighbors`` random pairs within ``radius``;
``adaptive``  only *edge pairs* reuse — |A_{p+1} − A_p| > ``edge_threshold``
              (the G-buffer test of Sec. 4.3.2, albedo only) — and only from
              pairs that pass the same test and whose pixels' albedos match
              within ``similarity``, found among ``tries`` random pairs within
              ``radius`` (the edge-aligned search; the paper uses N = 256).

``output=pixels`` turns the gradients into pixels: the primal row is
estimated by plain MC (M uniform samples per pixel) and the pair is handed to
the 1D screened Poisson solve (α² I + DᵀD) I = α² P + Dᵀ Δ (L2: linear, so
unbiased) done per trial by :func:`poisson_1d` (the Thomas algorithm, with
grisx.poisson's conventions: forward differences, Neumann ends).

Every spatial merge's cost is counted: ``stats.spatial_merges`` is the mean
number of neighbour reservoirs merged per pair and frame.
"""

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import warp as wp

from grisx.errors import InvalidParameterError
from grisx.theory.gris import ucw_from_source_pdf
from grisx.theory.random import random_key, random_subkey, random_uniform
from grisx.theory.shift import ShiftResult, shift_failed, shift_result
from grisx.theory.toys.base import BiasedVariant, Method, Param, ToyProblem, TrialBatch
from grisx.theory.toys.domains import interval_pdf, sample_interval
from grisx.theory.toys.ris_1d import _bump  # exp(−((x − c)/s)²)
from grisx.theory.toys.gradient_restir import GradientScratch, launch_gradient_method, make_gradient_kernels

# grisx never differentiates through its kernels: skip adjoint code (halves compile time)
wp.set_module_options({"enable_backward": False})

__all__ = ["GradientRow", "GradientRowSpec", "row_layout", "row_exact_pixels", "poisson_1d"]

SPATIAL_MODES = ("none", "dense", "adaptive")
OUTPUTS = ("gradients", "pixels")
DRIFT = 0.01
WIDEN = 0.03
LIGHT_DRIFT = 0.004  # default of the ``light_drift`` param


@wp.struct
class GradientRowSpec:
    albedo: wp.array(dtype=float)
    spatial: int
    radius: int
    tries: int
    edge_threshold: float
    similarity: float
    light_drift: float


@wp.func
def _lo(pixel: int) -> float:
    return DRIFT * float(pixel)


@wp.func
def _width(pixel: int) -> float:
    return 1.0 + WIDEN * float(pixel)


@wp.func
def _inside(pixel: int, x: float) -> wp.bool:
    return x >= _lo(pixel) and x <= _lo(pixel) + _width(pixel)


@wp.func
def row_pair_pixel(spec: GradientRowSpec, p: int, k: int) -> int:
    # pair p = (i, j) = (p + 1, p): Δ_p = F_{p+1} − F_p, a forward difference
    return p + 1 - k


@wp.func
def row_sample(spec: GradientRowSpec, frame: int, pixel: int, u: float) -> float:
    return sample_interval(u, _lo(pixel), _lo(pixel) + _width(pixel))


@wp.func
def row_pdf(spec: GradientRowSpec, frame: int, pixel: int, x: float) -> float:
    if not _inside(pixel, x):
        return 0.0
    return interval_pdf(_lo(pixel), _lo(pixel) + _width(pixel))


@wp.func
def row_integrand(spec: GradientRowSpec, frame: int, pixel: int, x: float) -> float:
    if not _inside(pixel, x):
        return 0.0
    u = (x - _lo(pixel)) / _width(pixel)  # the pixel's own coordinate: what τ keeps fixed
    return spec.albedo[pixel] * (0.2 + 1.5 * _bump(u, 0.35 + spec.light_drift * float(pixel), 0.07) + 0.8 * _bump(u, 0.85, 0.1))


@wp.func
def _pixel_map(pixel_src: int, pixel_dst: int, x: float) -> ShiftResult:
    # the affine map of the pixels' domains: the same u in both, |∂/∂x| = w_dst / w_src
    scale = _width(pixel_dst) / _width(pixel_src)
    y = _lo(pixel_dst) + (x - _lo(pixel_src)) * scale
    if _inside(pixel_dst, y):
        return shift_result(y, scale)
    return shift_failed()


@wp.func
def row_inner_shift(spec: GradientRowSpec, frame: int, src: int, dst: int, x: float) -> ShiftResult:
    return _pixel_map(src, dst, x)


@wp.func
def row_tau(spec: GradientRowSpec, frame_src: int, pixel_src: int, frame_dst: int, pixel_dst: int, x: float) -> ShiftResult:
    # static picture: frames map by the identity; pixels by their domains' affine map
    return _pixel_map(pixel_src, pixel_dst, x)


@wp.func
def _is_edge(spec: GradientRowSpec, p: int) -> wp.bool:
    return wp.abs(spec.albedo[p + 1] - spec.albedo[p]) > spec.edge_threshold


@wp.func
def _similar(spec: GradientRowSpec, p: int, q: int) -> wp.bool:
    return (
        _is_edge(spec, q)
        and wp.abs(spec.albedo[q + 1] - spec.albedo[p + 1]) <= spec.similarity
        and wp.abs(spec.albedo[q] - spec.albedo[p]) <= spec.similarity
    )


@wp.func
def _random_pair(spec: GradientRowSpec, key: wp.uint32, counter: int, p: int) -> int:
    # p + δ, δ uniform in [−R, R] \ {0}; −1 if it leaves the row
    r = spec.radius
    d = int(random_uniform(key, counter) * float(2 * r))
    d = d - r
    if d >= 0:
        d = d + 1
    q = p + d
    pairs = spec.albedo.shape[0] - 1
    if q < 0 or q >= pairs:
        return -1
    return q


@wp.func
def row_neighbor(spec: GradientRowSpec, key: wp.uint32, p: int, n: int) -> int:
    """The n-th spatial neighbour pair of p (−1: none) — drawn from random numbers, never from samples."""
    if spec.spatial == 1:
        return _random_pair(spec, key, n, p)
    if spec.spatial == 2:
        if not _is_edge(spec, p):
            return -1  # interior pair: no spatial reuse at all (Sec. 4.3.2)
        found = int(0)
        for j in range(spec.tries):
            q = _random_pair(spec, key, j, p)
            if q >= 0 and _similar(spec, p, q):
                if found == n:
                    return q
                found += 1
    return -1


@wp.func
def poisson_1d(
    alpha: float, primal: wp.array(dtype=float), gradient: wp.array(dtype=float), c: wp.array(dtype=float), out: wp.array(dtype=float)
):
    """L2 screened Poisson in 1D: (α² I + DᵀD) I = α² P + Dᵀ g (forward differences, Neumann ends).

    Tridiagonal: diagonal α² + (1 or 2), off-diagonals −1; solved by the
    Thomas algorithm with scratch ``c``. ``gradient[p]`` ≈ I[p+1] − I[p].
    """
    n = primal.shape[0]
    a2 = alpha * alpha
    prev_d = float(0.0)
    for i in range(n):
        diag = a2
        if i > 0:
            diag += 1.0
        if i < n - 1:
            diag += 1.0
        rhs = a2 * primal[i]
        if i > 0:
            rhs += gradient[i - 1]
        if i < n - 1:
            rhs -= gradient[i]
        upper = float(0.0)
        if i < n - 1:
            upper = -1.0
        if i > 0:
            denom = diag + c[i - 1]  # lower = −1: diag − lower·c'
            c[i] = upper / denom
            prev_d = (rhs + prev_d) / denom
        else:
            c[i] = upper / diag
            prev_d = rhs / diag
        out[i] = prev_d
    for r in range(n - 1):
        i = n - 2 - r
        out[i] = out[i] - c[i] * out[i + 1]


@wp.kernel
def row_reconstruct_kernel(
    spec: GradientRowSpec,
    candidates: int,
    alpha: float,
    seed: int,
    first_trial: int,
    gradients: wp.array2d(dtype=float),
    primal: wp.array2d(dtype=float),
    scratch: wp.array2d(dtype=float),
    values: wp.array2d(dtype=float),
):
    t = wp.tid()
    # the primal row: plain MC, from a stream the gradient kernels never use
    key = random_subkey(random_key(seed, first_trial + t), 1 << 20)
    n = primal.shape[1]
    inv_m = 1.0 / float(candidates)
    for i in range(n):
        est = float(0.0)
        for c in range(candidates):
            x = row_sample(spec, 0, i, random_uniform(key, i * candidates + c))
            est += inv_m * row_integrand(spec, 0, i, x) * ucw_from_source_pdf(row_pdf(spec, 0, i, x))
        primal[t, i] = est
    poisson_1d(alpha, primal[t], gradients[t], scratch[t], values[t])


@wp.kernel
def _poisson_kernel(alpha: float, primal: wp.array2d(dtype=float), gradients: wp.array2d(dtype=float), scratch: wp.array2d(dtype=float), out: wp.array2d(dtype=float)):
    t = wp.tid()
    poisson_1d(alpha, primal[t], gradients[t], scratch[t], out[t])


def solve_poisson_1d(primal: np.ndarray, gradients: np.ndarray, alpha: float = 0.2, device: str = "cpu") -> np.ndarray:
    """Host front-end of :func:`poisson_1d` for rows (n, N) of primal and (n, N−1) of gradients."""
    p = np.atleast_2d(np.asarray(primal, dtype=np.float32))
    g = np.atleast_2d(np.asarray(gradients, dtype=np.float32))
    if g.shape != (p.shape[0], p.shape[1] - 1):
        raise InvalidParameterError(f"gradients must have shape {(p.shape[0], p.shape[1] - 1)}, got {g.shape}")
    if alpha <= 0:
        raise InvalidParameterError(f"alpha must be > 0, got {alpha}")
    arrays = [wp.array(a, dtype=float, device=device) for a in (p, g)]
    scratch = wp.zeros(p.shape, dtype=float, device=device)
    out = wp.zeros(p.shape, dtype=float, device=device)
    wp.launch(_poisson_kernel, dim=p.shape[0], inputs=[float(alpha), *arrays, scratch, out], device=device)
    return out.numpy()


def row_layout(pixels: int, stripe: int) -> np.ndarray:
    """Albedo A_i of every pixel: 0.3 / 0.9 alternating in stripes of ``stripe`` pixels."""
    return np.where((np.arange(pixels) // stripe) % 2 == 0, 0.3, 0.9)


def row_exact_pixels(pixels: int, stripe: int, light_drift: float = LIGHT_DRIFT) -> np.ndarray:
    """F_i = ∫_{Ω_i} f_i (erf), float64."""
    albedo = row_layout(pixels, stripe)
    out = []
    for i in range(pixels):
        # ∫_{Ω_i} f_i dx = w_i ∫_0^1 (…)(u) du
        total = 0.2
        for a, c, s in ((1.5, 0.35 + light_drift * i, 0.07), (0.8, 0.85, 0.1)):
            total += a * s * math.sqrt(math.pi) / 2.0 * (math.erf((1.0 - c) / s) - math.erf((0.0 - c) / s))
        out.append(albedo[i] * (1.0 + WIDEN * i) * total)
    return np.array(out)


_BASE = ("pixels", "stripe", "light_drift", "candidates", "output", "alpha")
_RESTIR = ("frames", "cap", "jacobian")
_SPATIAL = ("spatial", "spatial_passes", "neighbors", "radius", "tries", "edge_threshold", "similarity", "positivize", "cross_sign")


class GradientRow(ToyProblem):
    name = "gradient-row"
    summary = "a 1D row of stripes: gradient-domain ReSTIR over pixel pairs with temporal and adaptive spatial reuse"
    chunk_trials = 1 << 16
    params = (
        Param("pixels", 16, "pixels N of the row (N − 1 pairs)", kind="int", minimum=3, maximum=64),
        Param("stripe", 4, "stripe width in pixels (albedo 0.3 / 0.9)", kind="int", minimum=1, maximum=64),
        Param("light_drift", LIGHT_DRIFT, "how far the light moves per pixel (in u): what the outer shift does not follow", minimum=0.0, maximum=0.05),
        Param("candidates", 2, "candidates (or MC samples) M per pixel", kind="int", minimum=1, maximum=256),
        Param("output", "gradients", "components: the N − 1 gradients, or the N pixels of the L2 screened Poisson solve", kind="choice", choices=OUTPUTS),
        Param("alpha", 0.2, "screened Poisson weight α of the primal (output=pixels)", minimum=1e-3, maximum=100.0),
        Param("frames", 3, "earlier frames of temporal reuse (static picture)", kind="int", minimum=0, maximum=16),
        Param("cap", 20.0, "confidence cap after every reuse pass (0 = none)", minimum=0.0),
        Param("jacobian", True, "multiply reuse weights by |∂T*/∂(x,k)| = |∂τ/∂x| (Eq. 20, 22)", kind="bool"),
        Param("spatial", "adaptive", "spatial neighbours: none, dense (random) or adaptive (edge pairs, similar neighbours)", kind="choice", choices=SPATIAL_MODES),
        Param("spatial_passes", 1, "spatial reuse passes per frame", kind="int", minimum=0, maximum=4),
        Param("neighbors", 2, "spatial neighbours per pair and pass", kind="int", minimum=0, maximum=6),
        Param("radius", 8, "neighbour pairs are drawn from p ± radius", kind="int", minimum=1, maximum=64),
        Param("tries", 16, "adaptive: random pairs examined per pass for similar neighbours", kind="int", minimum=1, maximum=256),
        Param("edge_threshold", 0.1, "adaptive: a pair is an edge pair if |A_{p+1} − A_p| exceeds this", minimum=0.0),
        Param("similarity", 0.1, "adaptive: neighbour pixels' albedos must match within this", minimum=0.0),
        Param("positivize", True, "pos/neg reservoirs over shared candidates (Eq. 23–26)", kind="bool"),
        Param("cross_sign", False, "reuse neighbours' pos and neg reservoirs in both (Chang et al. 2023)", kind="bool"),
    )
    methods = (
        Method("mc-difference", "independent MC in both pixels of every pair", _BASE),
        Method("gradient-pt", "shift-mapped differences from both pixels, balance heuristic (Eq. 2–4)", _BASE),
        Method("gradient-after-restir", "primal RIS + temporal reuse per pixel, then ω̂ G W (Eq. 10–13)", _BASE + _RESTIR),
        Method("gradient-with-restir", "paired-pixel ReSTIR: temporal + spatial reuse through T* (Eq. 14–22)", _BASE + _RESTIR + _SPATIAL),
    )
    biased_variants = (
        # any spatial merge without the Jacobian is biased; dense reuse with 4 neighbours makes it large enough to test
        BiasedVariant(
            "gradient-with-restir",
            {"jacobian": False, "spatial": "dense", "neighbors": 4, "frames": 0},
            "spatial weights without |∂τ/∂x| = w_b/w_a ≠ 1 (Eq. 20, 22)",
        ),
    )

    def __init__(self) -> None:
        self._kernels: dict[str, Any] | None = None
        self._scratch = GradientScratch()
        self._recon: tuple[Any, ...] | None = None

    def components(self, params: Mapping[str, Any]) -> int:
        n = int(params["pixels"])
        return n if params["output"] == "pixels" else n - 1

    def exact(self, params: Mapping[str, Any]) -> np.ndarray:
        f = row_exact_pixels(int(params["pixels"]), int(params["stripe"]), float(params["light_drift"]))
        return f if params["output"] == "pixels" else np.diff(f)

    def check_params(self, method: str, params: dict[str, Any]) -> None:
        if params.get("cross_sign") and not params.get("positivize", True):
            raise InvalidParameterError(f"param 'cross_sign' of toy '{self.name}' needs positivize=true (one reservoir has no signs)")

    def counter_names(self, method: str, params: Mapping[str, Any]) -> tuple[str, ...]:
        return ("spatial_merges",) if method == "gradient-with-restir" else ()

    def stats(self, method: str, params: Mapping[str, Any], totals: Mapping[str, float], trials: int) -> dict[str, Any]:
        per = trials * (int(params["pixels"]) - 1) * (int(params["frames"]) + 1)
        return {"spatial_merges": float(totals["spatial_merges"] / per)}

    def _all_kernels(self) -> dict[str, Any]:
        if self._kernels is None:
            self._kernels = make_gradient_kernels(
                GradientRowSpec, row_pair_pixel, row_sample, row_pdf, row_integrand, row_inner_shift, row_tau, row_neighbor
            )
        return self._kernels

    def kernels(self) -> list[Any]:
        return [*self._all_kernels().values(), row_reconstruct_kernel]

    def spec(self, params: Mapping[str, Any], device: Any) -> GradientRowSpec:
        s = GradientRowSpec()
        s.albedo = wp.array(row_layout(int(params["pixels"]), int(params["stripe"])).astype(np.float32), dtype=float, device=device)
        s.spatial = SPATIAL_MODES.index(params.get("spatial", "none"))
        s.radius = int(params.get("radius", 8))
        s.tries = int(params.get("tries", 16))
        s.edge_threshold = float(params.get("edge_threshold", 0.1))
        s.similarity = float(params.get("similarity", 0.1))
        s.light_drift = float(params.get("light_drift", LIGHT_DRIFT))
        return s

    def launch(self, method: str, params: Mapping[str, Any], seed: int, first_trial: int, batch: TrialBatch, device: Any) -> None:
        n = batch.values.shape[0]
        pixels = int(params["pixels"])
        spec = self.spec(params, device)
        if params["output"] == "gradients":
            launch_gradient_method(self._all_kernels(), self._scratch, method, spec, dict(params), pixels, seed, first_trial,
                                   batch.values, batch.samples, batch.counters, device)
            return
        key = (n, pixels, str(device))
        if self._recon is None or self._recon[0] != key:
            self._recon = (key, wp.empty((n, pixels - 1), dtype=float, device=device), wp.empty((n, pixels), dtype=float, device=device),
                           wp.empty((n, pixels), dtype=float, device=device))
        _, grads, primal, scratch = self._recon
        launch_gradient_method(self._all_kernels(), self._scratch, method, spec, dict(params), pixels, seed, first_trial,
                               grads, None, batch.counters, device)
        wp.launch(row_reconstruct_kernel, dim=n, inputs=[spec, int(params["candidates"]), float(params["alpha"]), seed, first_trial,
                                                          grads, primal, scratch, batch.values], device=device)
        if batch.samples is not None:
            batch.samples.fill_(0.0)
