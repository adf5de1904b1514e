"""One ReSTIR-style algorithm over K toy "pixels": initial RIS, then spatial GRIS passes.

Pixel k has a domain Ω_k, a source pdf, a target p̂_k and an integrand f_k;
pixels are linked by shift maps T_{j→i}. Each trial runs

1. **initial candidates** — in every pixel, M candidates from the source pdf
   stream into a reservoir with w = p̂/(M p) (seed 000, Eq. 6); confidence M;
2. **spatial reuse**, ``passes`` times — every pixel i merges the reservoirs
   of all K pixels (its own is the canonical one): sample y_j shifted to
   T_{j→i}(y_j), weighted by w = m_j · p̂_i(T(y_j)) · W_j · |∂T/∂y_j|
   (seed 000, Eq. 9) with the MIS weight m_j chosen by ``mis`` (seed 001,
   Eq. 15–16; pairwise; seed 004 Alg. 4's 1/Z; or the naive c_j/Σc), then
   finalized to W = w_sum / p̂_i(y) (Eq. 8) and its confidence capped;
3. **shading** — f_i(y_i) W_i for every pixel.

Confidences depend only on M, K and the pass, never on the samples, so the MIS
weights sum to one at every point covered by a canonical sample and the chain
stays unbiased even though later passes reuse correlated inputs.

:func:`make_pixel_reuse_kernel` builds the kernel from a problem's hooks
(Warp functions taking the problem's spec struct), so every problem shares
this one copy of the algorithm and of the core calls in it.
"""


from collections.abc import Mapping
from typing import Any

import numpy as np
import warp as wp

from grisx.errors import InvalidParameterError
from grisx.theory.gris import ris_weight
from grisx.theory.mis import MIS_MODES, MIS_PAIRWISE, mis_weight, target_from
from grisx.theory.random import random_key, random_subkey, random_uniform
from grisx.theory.reservoir import (
    Reservoir,
    confidence_capped,
    reservoir_empty,
    reservoir_finalize,
    reservoir_merge,
    reservoir_update,
)
from grisx.theory.toys.base import Param, ToyProblem, TrialBatch

__all__ = ["make_pixel_reuse_kernel", "PixelReuseScratch", "PixelReuseProblem", "REUSE_PARAMS", "reuse_params", "reuses", "pixel_array"]


def make_pixel_reuse_kernel(spec_type: Any, sample_candidate: Any, candidate_pdf: Any, target: Any, integrand: Any, shift: Any) -> Any:
    """Build the pixel-reuse kernel for one problem.

    Hooks (Warp functions): ``sample_candidate(spec, pixel, u) -> x``,
    ``candidate_pdf(spec, pixel, x) -> p``, ``target(spec, pixel, x) -> p̂``,
    ``integrand(spec, pixel, x) -> f`` and ``shift(spec, src, dst, x) -> ShiftResult``.
    """

    @wp.func
    def carried_target(spec: spec_type, l: int, i: int, x: float) -> float:
        # p̂_{←l}(x) for x in pixel i's domain (seed 001, Eq. 16): l's target
        # at the preimage T_{i→l}(x), times that shift's Jacobian.
        if l == i:
            return target(spec, i, x)
        s = shift(spec, i, l, x)
        if not s.valid:
            return 0.0
        return target_from(target(spec, l, s.x), s.jacobian)

    @wp.kernel(module="unique", enable_backward=False)
    def pixel_reuse(
        spec: spec_type,
        candidates: int,
        passes: int,
        mis_mode: int,
        use_jacobian: int,
        confidence_cap: float,
        seed: int,
        first_trial: int,
        res_a: wp.array2d(dtype=Reservoir),
        y_a: wp.array2d(dtype=float),
        res_b: wp.array2d(dtype=Reservoir),
        y_b: wp.array2d(dtype=float),
        confidence: wp.array2d(dtype=float),
        targets_from: wp.array2d(dtype=float),
        values: wp.array2d(dtype=float),
        samples: wp.array2d(dtype=float),
        keep_samples: int,
    ):
        t = wp.tid()
        pixels = values.shape[1]
        key = random_key(seed, first_trial + t)
        inv_m = 1.0 / float(candidates)

        # ---- initial candidates: RIS in every pixel (seed 000, Eq. 6–8) ----
        for j in range(pixels):
            r = reservoir_empty()
            y = float(0.0)
            for c in range(candidates):
                counter = 2 * (j * candidates + c)
                x = sample_candidate(spec, j, random_uniform(key, counter))
                p_hat = target(spec, j, x)
                w = ris_weight(inv_m, p_hat, candidate_pdf(spec, j, x))
                r = reservoir_update(r, w, p_hat, 1.0, random_uniform(key, counter + 1))
                if r.selected:
                    y = x
            res_a[t, j] = reservoir_finalize(r)
            y_a[t, j] = y

        # ---- spatial reuse: GRIS over all pixels (seed 000, Eq. 9) ----
        for p in range(passes):
            pass_key = random_subkey(key, p + 1)
            for l in range(pixels):
                confidence[t, l] = res_a[t, l].confidence
            for i in range(pixels):
                r = reservoir_empty()
                y = float(0.0)
                for j in range(pixels):
                    src = res_a[t, j]
                    s = shift(spec, j, i, y_a[t, j])
                    if s.valid and src.ucw > 0.0:
                        for l in range(pixels):
                            # pairwise MIS reads only p̂_{←j} and p̂_i for a neighbour's sample: O(1), not O(K)
                            if mis_mode != MIS_PAIRWISE or j == i or l == i or l == j:
                                targets_from[t, l] = carried_target(spec, l, i, s.x)
                        m = mis_weight(mis_mode, j, i, confidence[t], targets_from[t])
                        jacobian = s.jacobian
                        if use_jacobian == 0:
                            jacobian = 1.0  # the ablation: biased wherever |∂T/∂x| ≠ 1
                        r = reservoir_merge(r, src, m, target(spec, i, s.x), jacobian, random_uniform(pass_key, i * pixels + j))
                    else:
                        # a failed shift still counts toward the confidence, which stays deterministic
                        r = reservoir_update(r, 0.0, 0.0, src.confidence, 0.0)
                    if r.selected:
                        y = s.x
                r = reservoir_finalize(r)
                r.confidence = confidence_capped(r.confidence, confidence_cap)
                res_b[t, i] = r
                y_b[t, i] = y
            for i in range(pixels):
                res_a[t, i] = res_b[t, i]
                y_a[t, i] = y_b[t, i]

        # ---- shading: f_i(y_i) W_i (seed 000, Eq. 7) ----
        for i in range(pixels):
            values[t, i] = integrand(spec, i, y_a[t, i]) * res_a[t, i].ucw
            if keep_samples != 0:
                samples[t, i] = y_a[t, i]

    return pixel_reuse


class PixelReuseScratch:
    """Per-trial scratch buffers of the pixel-reuse kernel, reused across chunks."""

    def __init__(self) -> None:
        self._key: tuple[int, int, str] | None = None
        self.buffers: list[wp.array] = []

    def get(self, trials: int, pixels: int, device: Any) -> list[wp.array]:
        key = (trials, pixels, str(device))
        if key != self._key:
            shape = (trials, pixels)
            self.buffers = [
                wp.empty(shape, dtype=Reservoir, device=device),
                wp.empty(shape, dtype=float, device=device),
                wp.empty(shape, dtype=Reservoir, device=device),
                wp.empty(shape, dtype=float, device=device),
                wp.empty(shape, dtype=float, device=device),
                wp.empty(shape, dtype=float, device=device),
            ]
            self._key = key
        return self.buffers


# ---- the problem class both pixel-reuse toys derive from --------------------

def reuse_params(mis_default: str = "balance") -> tuple[Param, ...]:
    """The parameters every pixel-reuse problem takes (``mis_default`` differs per paper)."""
    return (
        Param("pixels", 5, "number of pixels K", kind="int", minimum=1, maximum=16),
        Param("candidates", 4, "initial candidates M per pixel", kind="int", minimum=1, maximum=1024),
        Param("passes", 1, "spatial GRIS passes (0 = plain RIS per pixel)", kind="int", minimum=0, maximum=16),
        Param("mis", mis_default, "MIS weights of the spatial passes", kind="choice", choices=tuple(MIS_MODES)),
        Param("jacobian", True, "multiply resampling weights by the shift Jacobian", kind="bool"),
        Param("cap", 20.0, "confidence cap after each pass (0 = none)", kind="float", minimum=0.0),
    )


REUSE_PARAMS = reuse_params()


def reuses(params: Mapping[str, Any]) -> bool:
    """Does the run make at least one spatial pass? Every reuse bias needs one."""
    return int(params.get("passes", 1)) > 0


class PixelReuseProblem(ToyProblem):
    """A toy whose method ``gris`` is :func:`make_pixel_reuse_kernel` over the problem's hooks."""

    chunk_trials = 1 << 18

    def __init__(self) -> None:
        self._scratch = PixelReuseScratch()
        self._kernel: Any = None

    # hooks of subclasses
    def build_kernel(self) -> Any:
        raise NotImplementedError

    def spec(self, params: Mapping[str, Any], device: Any) -> Any:
        raise NotImplementedError

    def components(self, params: Mapping[str, Any]) -> int:
        return int(params["pixels"])

    def check_params(self, method: str, params: dict[str, Any]) -> None:
        if params["passes"] > 0 and params["pixels"] < 2:
            raise InvalidParameterError(f"param 'passes' of toy '{self.name}' needs pixels >= 2 to reuse anything")

    def kernels(self) -> list[Any]:
        if self._kernel is None:
            self._kernel = self.build_kernel()
        return [self._kernel]

    def launch(self, method: str, params: Mapping[str, Any], seed: int, first_trial: int, batch: TrialBatch, device: Any) -> None:
        n, k = batch.values.shape
        res_a, y_a, res_b, y_b, conf, tfrom = self._scratch.get(n, k, device)
        samples = batch.samples if batch.samples is not None else batch.values
        wp.launch(
            self.kernels()[0],
            dim=n,
            inputs=[
                self.spec(params, device),
                int(params["candidates"]),
                int(params["passes"]),
                MIS_MODES[params["mis"]],
                int(bool(params["jacobian"])),
                float(params["cap"]),
                seed,
                first_trial,
                res_a,
                y_a,
                res_b,
                y_b,
                conf,
                tfrom,
                batch.values,
                samples,
                int(batch.samples is not None),
            ],
            device=device,
        )


def pixel_array(values: Any, dtype: Any, device: Any) -> wp.array:
    """A small per-pixel parameter array on ``device``."""
    return wp.array(np.asarray(values), dtype=dtype, device=device)
