"""``f1-f2``: the pixel difference of seed 000's Fig. 3, with a partial inner shift.

Two "pixels" integrate

    f₁(x) = 0.1 + 2 g(x; 0, 0.25) + 0.6 g(x; −1.2, 0.12)    on Ω₁ = [−2, 2]
    f₂(x) = 0.1 + 2 g(x; 0, 0.25) + 0.9 g(x;  1.1, 0.12)    on Ω₂ = [−2 + d, 2 + d]

(g(x; c, s) = exp(−((x − c)/s)²)): they agree near the origin, where both
have a tall peak, and differ in two small peaks of opposite sign elsewhere.
The answer is Δ = ∫_{Ω₁} f₁ − ∫_{Ω₂} f₂, exact through erf. The inner shift
is the identity x ↦ x (Jacobian 1) where it lands inside the other pixel;
with ``offset`` d > 0 the pixels' domains only overlap, the shift is a
*partial* bijection, and only the symmetric, MIS-weighted difference (Eq. 3–4)
is unbiased — the one-sided Eq. 2 (``gradient-pt`` with ``symmetric=false``)
misses ∫_{Ω₂∖Ω₁} f₂.

Methods (all from :mod:`grisx.theory.toys.gradient_restir`): ``mc-difference``,
``gradient-pt`` (Eq. 2–4), ``gradient-after-restir`` (Eq. 10–13),
``gradient-with-restir`` (Eq. 14–20, ``positivize``, ``cross_sign``). M
candidates (or samples) are drawn *per pixel*, uniform on its domain.

**Temporal reuse.** ``frames`` = F > 0 runs F earlier frames in which the
picture is zoomed: frame t shows f_k(x · a^{F−t}) (a = ``motion``), so the
last frame is the one above and its exact Δ does not change. The outer shift
from frame t to t+1 is τ(x) = a·x with |∂τ/∂x| = a (Eq. 21–22); it fails
when a·x leaves the pixel. ``jacobian=false`` drops that factor from Eq. 20:
biased whenever a ≠ 1.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import warp as wp

from grisx.errors import InvalidParameterError
from grisx.theory.shift import ShiftResult, shift_failed, shift_result
from grisx.theory.toys.base import BiasedVariant, Method, Param, ToyProblem, TrialBatch
from grisx.theory.toys.domains import interval_pdf, sample_interval
from grisx.theory.toys.ris_1d import _bump  # exp(−((x − c)/s)²)
from grisx.theory.toys.gradient_restir import GradientScratch, launch_gradient_method, make_gradient_kernels

# grisx never differentiates through its kernels: skip adjoint code (halves compile time)
wp.set_module_options({"enable_backward": False})

__all__ = ["F1F2", "F1F2Spec", "f1f2_exact", "f1f2_integrand_np", "BUMPS"]

#: (pixel, amplitude, centre, width) of every Gaussian bump; both pixels also have a floor of 0.1
BUMPS = ((0, 2.0, 0.0, 0.25), (0, 0.6, -1.2, 0.12), (1, 2.0, 0.0, 0.25), (1, 0.9, 1.1, 0.12))
FLOOR = 0.1
HALF_WIDTH = 2.0


@wp.struct
class F1F2Spec:
    offset: float
    motion: float
    frames: int


@wp.func
def _lo(spec: F1F2Spec, pixel: int) -> float:
    return -HALF_WIDTH + spec.offset * float(pixel)


@wp.func
def _inside(spec: F1F2Spec, pixel: int, x: float) -> wp.bool:
    lo = _lo(spec, pixel)
    return x >= lo and x <= lo + 2.0 * HALF_WIDTH


@wp.func
def f1f2_pair_pixel(spec: F1F2Spec, p: int, k: int) -> int:
    return k


@wp.func
def f1f2_sample(spec: F1F2Spec, frame: int, pixel: int, u: float) -> float:
    lo = _lo(spec, pixel)
    return sample_interval(u, lo, lo + 2.0 * HALF_WIDTH)


@wp.func
def f1f2_pdf(spec: F1F2Spec, frame: int, pixel: int, x: float) -> float:
    if not _inside(spec, pixel, x):
        return 0.0
    lo = _lo(spec, pixel)
    return interval_pdf(lo, lo + 2.0 * HALF_WIDTH)


@wp.func
def f1f2_integrand(spec: F1F2Spec, frame: int, pixel: int, x: float) -> float:
    if not _inside(spec, pixel, x):
        return 0.0
    z = x * wp.pow(spec.motion, float(spec.frames - frame))  # frame t shows f(x a^{F−t})
    if pixel == 0:
        return FLOOR + 2.0 * _bump(z, 0.0, 0.25) + 0.6 * _bump(z, -1.2, 0.12)
    return FLOOR + 2.0 * _bump(z, 0.0, 0.25) + 0.9 * _bump(z, 1.1, 0.12)


@wp.func
def f1f2_inner_shift(spec: F1F2Spec, frame: int, src: int, dst: int, x: float) -> ShiftResult:
    # the same x in the other pixel: a partial bijection when the domains are offset
    if _inside(spec, dst, x):
        return shift_result(x, 1.0)
    return shift_failed()


@wp.func
def f1f2_tau(spec: F1F2Spec, frame_src: int, pixel_src: int, frame_dst: int, pixel_dst: int, x: float) -> ShiftResult:
    # τ: frame t → t' is x ↦ x a^{t'−t} (the zoom); pixels map by the domain offset
    scale = wp.pow(spec.motion, float(frame_dst - frame_src))
    y = x * scale + spec.offset * float(pixel_dst - pixel_src)
    if _inside(spec, pixel_dst, y):
        return shift_result(y, scale)
    return shift_failed()


@wp.func
def f1f2_neighbor(spec: F1F2Spec, key: wp.uint32, p: int, n: int) -> int:
    return -1  # one pair: no spatial neighbours


def f1f2_integrand_np(pixel: int, x: np.ndarray) -> np.ndarray:
    """float64 twin of the integrand (frame F), without the domain cut — for oracles and plots."""
    x = np.asarray(x, dtype=np.float64)
    out = np.full_like(x, FLOOR)
    for pix, a, c, s in BUMPS:
        if pix == pixel:
            out = out + a * np.exp(-(((x - c) / s) ** 2))
    return out


def _integral(pixel: int, lo: float, hi: float) -> float:
    total = FLOOR * (hi - lo)
    for pix, a, c, s in BUMPS:
        if pix == pixel:
            total += a * s * math.sqrt(math.pi) / 2.0 * (math.erf((hi - c) / s) - math.erf((lo - c) / s))
    return total


def f1f2_exact(offset: float) -> float:
    """Δ = ∫_{−2}^{2} f₁ − ∫_{−2+d}^{2+d} f₂ (erf)."""
    return _integral(0, -HALF_WIDTH, HALF_WIDTH) - _integral(1, -HALF_WIDTH + offset, HALF_WIDTH + offset)


_COMMON = ("offset", "candidates")
_RESTIR = ("frames", "motion", "cap", "jacobian")


class F1F2(ToyProblem):
    name = "f1-f2"
    summary = "pixel difference ∫f1 − ∫f2 of seed 000's Fig. 3; offset d makes the inner shift partial"
    params = (
        Param("offset", 0.5, "offset d of pixel 2's domain [−2+d, 2+d] (d > 0: partial inner shift; 0: Fig. 3's bijection)", minimum=0.0, maximum=2.0),
        Param("candidates", 8, "candidates (or MC samples) M per pixel", kind="int", minimum=1, maximum=1024),
        Param("symmetric", True, "gradient-pt: both pixels' base paths with MIS (Eq. 3–4); false = one-sided Eq. 2", kind="bool"),
        Param("frames", 0, "earlier frames of temporal reuse F (the estimate is frame F's)", kind="int", minimum=0, maximum=16),
        Param("motion", 1.1, "zoom a per frame: the outer shift τ(x) = a x, |∂τ/∂x| = a", minimum=0.5, maximum=2.0),
        Param("cap", 20.0, "confidence cap after temporal reuse (0 = none)", minimum=0.0),
        Param("jacobian", True, "multiply temporal resampling weights by |∂τ/∂x| (Eq. 20, 22)", kind="bool"),
        Param("positivize", True, "pos/neg reservoirs over shared candidates (Eq. 23–26); false = one reservoir, p̂ = ω*|G|", kind="bool"),
        Param("cross_sign", False, "with positivize and frames > 0: reuse the previous frame's pos and neg in both", kind="bool"),
    )
    methods = (
        Method("mc-difference", "independent MC in each pixel: ⟨F1⟩ − ⟨F2⟩", _COMMON),
        Method("gradient-pt", "shift-mapped differences from both pixels, balance heuristic (Eq. 2–4)", _COMMON + ("symmetric",)),
        Method("gradient-after-restir", "primal RIS/ReSTIR per pixel, then ω̂ G W of the kept paths (Eq. 10–13)", _COMMON + _RESTIR),
        Method(
            "gradient-with-restir",
            "RIS/ReSTIR on the paired-pixel domain, p̂ = ω*|G| (Eq. 14–20), optional positivization (Eq. 23–26)",
            _COMMON + _RESTIR + ("positivize", "cross_sign"),
        ),
    )
    biased_variants = (
        BiasedVariant(
            "gradient-pt",
            {"symmetric": False},
            "one-sided Eq. 2 on a partial inner shift (offset > 0) misses ∫ f2 over Ω2 \\ T(Ω1)",
            applies=lambda p: float(p["offset"]) > 0.0,
        ),
        # any frames > 0 with motion ≠ 1 is biased without the Jacobian; these are the configurations tested
        BiasedVariant(
            "gradient-with-restir",
            {"jacobian": False, "frames": 2, "motion": 1.5},
            "temporal weights without |∂τ/∂x| = a (Eq. 20, 22)",
        ),
        BiasedVariant(
            "gradient-after-restir",
            {"jacobian": False, "frames": 2, "motion": 1.5},
            "temporal weights without |∂τ/∂x| = a (Eq. 9)",
        ),
    )

    def __init__(self) -> None:
        self._kernels: dict[str, Any] | None = None
        self._scratch = GradientScratch()

    def exact(self, params: Mapping[str, Any]) -> np.ndarray:
        return np.array([f1f2_exact(float(params["offset"]))])

    def check_params(self, method: str, params: dict[str, Any]) -> None:
        if params.get("cross_sign") and not params.get("positivize", True):
            raise InvalidParameterError(f"param 'cross_sign' of toy '{self.name}' needs positivize=true (one reservoir has no signs)")

    def _all_kernels(self) -> dict[str, Any]:
        if self._kernels is None:
            self._kernels = make_gradient_kernels(
                F1F2Spec, f1f2_pair_pixel, f1f2_sample, f1f2_pdf, f1f2_integrand, f1f2_inner_shift, f1f2_tau, f1f2_neighbor
            )
        return self._kernels

    def kernels(self) -> list[Any]:
        return list(self._all_kernels().values())

    def spec(self, params: Mapping[str, Any]) -> F1F2Spec:
        s = F1F2Spec()
        s.offset = float(params["offset"])
        s.motion = float(params.get("motion", 1.0))
        s.frames = int(params.get("frames", 0))
        return s

    def launch(self, method: str, params: Mapping[str, Any], seed: int, first_trial: int, batch: TrialBatch, device: Any) -> None:
        launch_gradient_method(
            self._all_kernels(), self._scratch, method, self.spec(params), dict(params), 2, seed, first_trial,
            batch.values, batch.samples, batch.counters, device,
        )
