"""``ris-1d``: resampled importance sampling of one bumpy function on [0, 1].

The integrand is a floor with two Gaussian bumps,

    f(x) = 0.2 + exp(−((x − 0.3)/0.06)²) + 0.5 exp(−((x − 0.72)/0.1)²),

whose integral over [0, 1] is exact through erf. Candidates are uniform
(p = 1). Methods:

``mc``   (1/M) Σ f(x_i)/p(x_i) over M uniform samples — the baseline;
``ris``  M candidates, one kept by a reservoir with weights w = p̂/(M p)
         (seed 000, Eq. 6) and estimated by f(y) W_y (Eq. 7–8).

``target`` picks p̂: ``integrand`` (p̂ = f: zero-variance in the limit
M → ∞), ``approx`` (one wide bump: a cheaper, imperfect p̂, still positive
wherever f is) or ``narrow`` (p̂ = f on [0, 0.5] and 0 beyond). RIS only
covers supp p̂, so ``narrow`` loses ∫_{0.5}^{1} f: the classic support
violation, kept as a known-biased variant.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import warp as wp

from grisx.theory.gris import ris_weight
from grisx.theory.random import random_key, random_uniform
from grisx.theory.reservoir import reservoir_empty, reservoir_finalize, reservoir_update
from grisx.theory.toys.base import BiasedVariant, Method, Param, ToyProblem, TrialBatch
from grisx.theory.toys.domains import interval_pdf, sample_interval

# grisx never differentiates through its kernels: skip adjoint code (halves compile time)
wp.set_module_options({"enable_backward": False})

__all__ = ["RIS1D", "ris1d_integrand", "ris1d_target"]

TARGETS = ("integrand", "approx", "narrow")


@wp.func
def _bump(x: float, center: float, width: float) -> float:
    d = (x - center) / width
    return wp.exp(-d * d)


@wp.func
def ris1d_integrand(x: float) -> float:
    """f(x) = 0.2 + bump(0.3, 0.06) + 0.5 bump(0.72, 0.1) on [0, 1]."""
    return 0.2 + _bump(x, 0.3, 0.06) + 0.5 * _bump(x, 0.72, 0.1)


@wp.func
def ris1d_target(kind: int, x: float) -> float:
    """p̂ of the ``target`` param: 0 integrand, 1 approx, 2 narrow (zero on (0.5, 1])."""
    if kind == 1:
        return 0.3 + _bump(x, 0.45, 0.25)
    if kind == 2 and x > 0.5:
        return 0.0
    return ris1d_integrand(x)


@wp.kernel
def ris1d_kernel(
    use_ris: int,
    target_kind: int,
    candidates: int,
    seed: int,
    first_trial: int,
    values: wp.array2d(dtype=float),
    samples: wp.array2d(dtype=float),
    keep_samples: int,
):
    t = wp.tid()
    key = random_key(seed, first_trial + t)
    pdf = interval_pdf(0.0, 1.0)
    inv_m = 1.0 / float(candidates)
    y = float(0.0)
    value = float(0.0)
    if use_ris == 0:
        # ---- plain Monte Carlo: (1/M) Σ f(x)/p(x) ----
        for i in range(candidates):
            y = sample_interval(random_uniform(key, i), 0.0, 1.0)
            value += inv_m * ris1d_integrand(y) / pdf
    else:
        # ---- RIS: stream M candidates through one reservoir (seed 004, Alg. 1) ----
        r = reservoir_empty()
        for i in range(candidates):
            x = sample_interval(random_uniform(key, 2 * i), 0.0, 1.0)
            target = ris1d_target(target_kind, x)
            w = ris_weight(inv_m, target, pdf)  # seed 000, Eq. 6 with m = 1/M
            r = reservoir_update(r, w, target, 1.0, random_uniform(key, 2 * i + 1))
            if r.selected:
                y = x
        r = reservoir_finalize(r)  # W_y, seed 000 Eq. 8
        value = ris1d_integrand(y) * r.ucw  # seed 000, Eq. 7
    values[t, 0] = value
    if keep_samples != 0:
        samples[t, 0] = y


def _bump_integral(center: float, width: float, lo: float = 0.0, hi: float = 1.0) -> float:
    return width * math.sqrt(math.pi) / 2.0 * (math.erf((hi - center) / width) - math.erf((lo - center) / width))


class RIS1D(ToyProblem):
    name = "ris-1d"
    summary = "RIS of a two-bump function on [0,1] from uniform candidates; exact integral via erf"
    params = (
        Param("candidates", 8, "candidates M per trial (mc: samples averaged)", kind="int", minimum=1, maximum=4096),
        Param("target", "integrand", "target function p̂", kind="choice", choices=TARGETS),
    )
    methods = (
        Method("mc", "plain Monte Carlo with M uniform samples", ("candidates",)),
        Method("ris", "resampled importance sampling: M candidates, one kept", ("candidates", "target")),
    )
    biased_variants = (
        BiasedVariant("ris", {"target": "narrow"}, "p̂ = 0 on (0.5, 1] where f > 0: RIS never selects there"),
    )

    def exact(self, params: Mapping[str, Any]) -> np.ndarray:
        return np.array([0.2 + _bump_integral(0.3, 0.06) + 0.5 * _bump_integral(0.72, 0.1)])

    def kernels(self) -> list[Any]:
        return [ris1d_kernel]

    def launch(self, method: str, params: Mapping[str, Any], seed: int, first_trial: int, batch: TrialBatch, device: Any) -> None:
        samples = batch.samples if batch.samples is not None else batch.values
        wp.launch(
            ris1d_kernel,
            dim=batch.values.shape[0],
            inputs=[
                int(method == "ris"),
                TARGETS.index(params.get("target", "integrand")),
                int(params["candidates"]),
                seed,
                first_trial,
                batch.values,
                samples,
                int(batch.samples is not None),
            ],
            device=device,
        )
