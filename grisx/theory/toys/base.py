"""The toy-problem framework: named problems with exact answers, run as Warp kernels.

A :class:`ToyProblem` owns its kernels and exact values. ``run`` launches N
independent trials (one Warp thread each, trial t drawing its random numbers
from ``random_key(seed, t)``), reduces the per-trial estimates on the host in
float64, and returns an :class:`Estimate`: mean, standard error, exact value,
trials and seconds — what ``grisx toy run --json`` prints.

Problems declare their methods and parameters (:class:`Param`), so the CLI
can list them and reject unknown names or malformed values with one clear
line, and declare which (method, params) combinations are *known to be
biased*, so tests and users can check that the z-test catches them.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
import warp as wp

from grisx.device import resolve_device, synchronize
from grisx.errors import InvalidParameterError, InvalidValueError, UnknownNameError
from grisx.params import Param

__all__ = ["Param", "Method", "BiasedVariant", "Estimate", "ToyProblem", "TrialBatch", "CHUNK_TRIALS"]

#: trials launched per kernel call; bounds host memory for per-trial results
CHUNK_TRIALS = 1 << 20

@dataclasses.dataclass(frozen=True)
class Method:
    """A named estimator of a toy problem and the parameters it reads."""

    name: str
    doc: str
    params: tuple[str, ...] = ()


@dataclasses.dataclass(frozen=True)
class BiasedVariant:
    """A configuration that is biased by construction, and why.

    It matches a run of ``method`` whose parameters equal ``params``, and,
    when ``applies`` is given, for which ``applies(all_params)`` is true (the
    bias may need more than the named switch, e.g. a reuse pass to happen).
    """

    method: str
    params: dict[str, Any]
    why: str
    applies: Callable[[Mapping[str, Any]], bool] | None = None

    def matches(self, method: str, params: Mapping[str, Any]) -> bool:
        if method != self.method or any(params.get(k) != v for k, v in self.params.items()):
            return False
        return self.applies is None or bool(self.applies(params))


@dataclasses.dataclass
class Estimate:
    """The result of a toy run: estimate ± stderr beside the exact value.

    Scalar problems hold floats; vector-valued problems (several pixels) hold
    1D arrays of equal length.
    """

    problem: str
    method: str
    params: dict[str, Any]
    estimate: np.ndarray | float
    stderr: np.ndarray | float
    exact: np.ndarray | float
    trials: int
    seed: int
    seconds: float
    device: str
    samples: np.ndarray | None = None
    #: every trial's own estimate (trials × components, or trials for scalar problems), when asked for
    values: np.ndarray | None = None
    #: problem-specific run statistics (e.g. Newton iterations per solution), or None
    stats: dict[str, Any] | None = None

    @property
    def z(self) -> np.ndarray | float:
        """(estimate − exact) / stderr per component; ±inf where stderr is 0 and they differ."""
        est, ex, se = (np.asarray(a, dtype=np.float64) for a in (self.estimate, self.exact, self.stderr))
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.where(se > 0, (est - ex) / np.where(se > 0, se, 1.0), np.where(est == ex, 0.0, np.inf))
        return float(z) if z.ndim == 0 else z

    @property
    def max_abs_z(self) -> float:
        return float(np.max(np.abs(self.z)))

    @property
    def rmse(self) -> float:
        """Root-mean-square error of *one trial*, √(stderr²·N + bias²), averaged over components."""
        se = np.asarray(self.stderr, dtype=np.float64)
        bias = np.asarray(self.estimate, dtype=np.float64) - np.asarray(self.exact, dtype=np.float64)
        return float(np.sqrt(np.mean(se**2 * self.trials + bias**2)))

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready record; ``None`` (JSON ``null``) for a value that is undefined: NaN/Inf, and
        ``stderr`` and ``z`` of a single trial (the sample variance of one value does not exist)."""

        def plain(a: Any, defined: bool = True) -> Any:
            a = np.asarray(a, dtype=np.float64)
            values = [float(v) if defined and np.isfinite(v) else None for v in a.ravel()]
            return values[0] if a.ndim == 0 else values

        z = self.z
        return {
            "problem": self.problem,
            "method": self.method,
            "params": dict(self.params),
            "estimate": plain(self.estimate),
            "stderr": plain(self.stderr, self.trials > 1),
            "exact": plain(self.exact),
            "z": plain(z, self.trials > 1),
            "trials": self.trials,
            "seed": self.seed,
            "seconds": self.seconds,
            "trials_per_second": self.trials / self.seconds if self.seconds > 0 else None,
            "device": self.device,
            **({"stats": dict(self.stats)} if self.stats is not None else {}),
        }


@dataclasses.dataclass
class TrialBatch:
    """What a problem's launcher fills for one chunk of trials."""

    values: wp.array  # (n, components) float32: one estimate per trial and component
    samples: wp.array | None  # (n, components) float32 selected samples, or None
    counters: wp.array | None = None  # (n, len(counter_names)) float32 per-trial tallies, or None


class ToyProblem:
    """Base class of named toy problems (subclasses set the class attributes and hooks)."""

    name: str = ""
    summary: str = ""
    methods: tuple[Method, ...] = ()
    params: tuple[Param, ...] = ()
    #: configurations that are biased by construction
    biased_variants: tuple[BiasedVariant, ...] = ()
    #: trials per kernel launch (smaller for problems with large per-trial scratch)
    chunk_trials: int = CHUNK_TRIALS

    # ---- hooks -----------------------------------------------------------------
    def components(self, params: Mapping[str, Any]) -> int:
        """Number of estimated values (1 for scalar problems, K for K pixels)."""
        return 1

    def exact(self, params: Mapping[str, Any]) -> np.ndarray:
        raise NotImplementedError

    def kernels(self) -> list[Any]:
        """Kernels to load before the clock starts (compilation is not run time)."""
        raise NotImplementedError

    def launch(
        self, method: str, params: Mapping[str, Any], seed: int, first_trial: int, batch: TrialBatch, device: Any
    ) -> None:
        raise NotImplementedError

    def counter_names(self, method: str, params: Mapping[str, Any]) -> tuple[str, ...]:
        """Names of per-trial tallies the launcher writes into ``batch.counters`` (none by default).

        ``run`` sums them over all trials in float64 and hands the totals to
        :meth:`stats`, whose dict becomes ``Estimate.stats``.
        """
        return ()

    def stats(self, method: str, params: Mapping[str, Any], totals: Mapping[str, float], trials: int) -> dict[str, Any]:
        """Run statistics from the summed tallies (override with counter_names)."""
        return {name: value / trials for name, value in totals.items()}

    # ---- public API ----------------------------------------------------------
    def method(self, name: str) -> Method:
        for m in self.methods:
            if m.name == name:
                return m
        raise UnknownNameError(f"method of toy '{self.name}'", name, [m.name for m in self.methods])

    def resolve_params(self, method: str, params: Mapping[str, Any] | None) -> dict[str, Any]:
        """Defaults merged with ``params``, each parsed and range-checked."""
        m = self.method(method)
        known = {p.name: p for p in self.params if p.name in m.params}
        out = {name: p.default for name, p in known.items()}
        for key, value in (params or {}).items():
            if key not in known:
                raise UnknownNameError(f"param of toy '{self.name}' method '{method}'", key, sorted(known))
            out[key] = known[key].parse(value, f"toy '{self.name}'")
        self.check_params(method, out)
        return out

    def check_params(self, method: str, params: dict[str, Any]) -> None:
        """Cross-parameter checks (override where needed)."""

    def is_biased(self, method: str, params: Mapping[str, Any]) -> bool:
        return any(b.matches(method, params) for b in self.biased_variants)

    def describe(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "summary": self.summary,
            "methods": [
                {"name": m.name, "doc": m.doc, "params": [p.describe() for p in self.params if p.name in m.params]}
                for m in self.methods
            ],
            "biased_variants": [{"method": b.method, "params": b.params, "why": b.why} for b in self.biased_variants],
        }

    def run(
        self,
        method: str,
        trials: int = 100_000,
        seed: int = 0,
        params: Mapping[str, Any] | None = None,
        device: str = "cpu",
        return_samples: bool = False,
        return_values: bool = False,
        progress: Callable[[int, int], None] | None = None,
    ) -> Estimate:
        """Run ``trials`` independent trials of ``method`` and compare with the exact value.

        ``return_samples``: the selected sample of every trial; ``return_values``: every trial's
        estimate (e.g. to draw the estimator's distribution, as seed 000's Fig. 3 does).
        ``progress(trials_done, trials)`` is called after each chunk of :attr:`chunk_trials`.
        """
        resolved = self.resolve_params(method, params)
        trials = _check_count("trials", trials)
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not (0 <= int(seed) < 2**31):
            raise InvalidParameterError(f"seed must be an integer in [0, 2^31), got {seed!r}")
        dev = resolve_device(device)
        k = self.components(resolved)
        exact = np.asarray(self.exact(resolved), dtype=np.float64).reshape(k)
        for kernel in self.kernels():
            wp.load_module(kernel.module, device=dev)

        chunk = min(trials, self.chunk_trials)
        values = wp.empty((chunk, k), dtype=float, device=dev)
        sample_buf = wp.empty((chunk, k), dtype=float, device=dev) if return_samples else None
        samples = np.empty((trials, k), dtype=np.float32) if return_samples else None
        trial_values = np.empty((trials, k), dtype=np.float32) if return_values else None
        counter_names = tuple(self.counter_names(method, resolved))
        counter_buf = wp.zeros((chunk, len(counter_names)), dtype=float, device=dev) if counter_names else None
        counter_totals = np.zeros(len(counter_names))
        total = np.zeros(k)
        mean = np.zeros(k)
        m2 = np.zeros(k)
        bad = 0
        synchronize(dev)
        start = time.perf_counter()
        done = 0
        while done < trials:
            n = min(chunk, trials - done)
            batch = TrialBatch(
                values=values[:n],
                samples=None if sample_buf is None else sample_buf[:n],
                counters=None if counter_buf is None else counter_buf[:n],
            )
            self.launch(method, resolved, int(seed), done, batch, dev)
            v = batch.values.numpy().astype(np.float64)
            bad += int(np.count_nonzero(~np.isfinite(v)))
            # Chan et al.'s parallel update of mean and M2 (float64) across chunks
            cm = v.mean(axis=0)
            cm2 = ((v - cm) ** 2).sum(axis=0)
            delta = cm - mean
            new_total = total + n
            mean = mean + delta * n / new_total
            m2 = m2 + cm2 + delta**2 * total * n / new_total
            total = new_total
            if samples is not None:
                samples[done : done + n] = batch.samples.numpy()
            if trial_values is not None:
                trial_values[done : done + n] = v
            if counter_buf is not None:
                counter_totals += batch.counters.numpy().astype(np.float64).sum(axis=0)
            done += n
            if progress is not None:
                progress(done, trials)
        synchronize(dev)
        seconds = time.perf_counter() - start
        if bad:
            raise InvalidValueError(f"toy '{self.name}' method '{method}' produced {bad} NaN/Inf trial estimates")
        stderr = np.sqrt(m2 / max(trials - 1, 1) / trials)
        scalar = k == 1
        return Estimate(
            problem=self.name,
            method=method,
            params=resolved,
            estimate=float(mean[0]) if scalar else mean,
            stderr=float(stderr[0]) if scalar else stderr,
            exact=float(exact[0]) if scalar else exact,
            trials=trials,
            seed=int(seed),
            seconds=seconds,
            device=str(dev),
            samples=None if samples is None else (samples[:, 0] if scalar else samples),
            values=None if trial_values is None else (trial_values[:, 0] if scalar else trial_values),
            stats=dict(self.stats(method, resolved, dict(zip(counter_names, counter_totals)), trials))
            if counter_names
            else None,
        )


def _check_count(name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise InvalidParameterError(f"{name} must be a positive integer, got {value!r}")
    if value <= 0:
        raise InvalidParameterError(f"{name} must be a positive integer, got {value}")
    if value > 2**31 - 1:
        raise InvalidParameterError(f"{name} must be below 2^31, got {value}")
    return int(value)

