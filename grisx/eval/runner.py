"""Studies of error against run time: toy problems and renderers through one harness.

Toy study
---------
:func:`toy_study` runs every method of one toy problem (each with its own
params) over a ladder of trial counts through
:func:`grisx.theory.toys.run_toy` and records, per run, the seconds
(``Estimate.seconds``: launches and host reduction with the device
synchronized, compilation excluded) and the error of the mean against the
exact value: ``rmse`` = √(mean over components (estimate − exact)²), measured,
and ``rmse_predicted`` = √(mean stderr²), what the run's own standard error
predicts (the measured one is a single realization). The ladder is either
given (``trials=``) or climbs 1e3, 3e3, 1e4, … until one run takes at least
``budget`` seconds. From each method's largest run: ``efficiency`` =
1 / (MSE × seconds) with the predicted MSE (time-invariant for an unbiased
estimator), its ratio to the first method (the baseline), and the RMSE that
each method reaches in the baseline's time.

Render study
------------
:func:`render_study` renders each scene with each method through the renderer
interface of :mod:`grisx.render.driver` (injectable, for tests and other
renderers)::

    render(scene, method, *, spp, frames, accumulate, res, device, seed, params, on_frame) -> RenderResult
    reference(scene, *, res, spp, device, seed) -> (H, W, 3) float32, or a record with
        .image and .variance (the variance of the reference's mean, per pixel)

By default these are :func:`grisx.render.driver.render` and
:func:`grisx.render.reference.reference` (the cached high-spp path tracer).
With a variance, the study records ``reference_noise``: the MSE and relMSE
that the reference's own noise adds, in expectation, to every measured error
(an error curve flattening near it has reached the reference's accuracy).

For each (scene, method) it first renders one warm-up frame (so that kernel
compilation is not run time), then renders with ``accumulate=True`` (the
renderer averages the frames under a static camera: how a method converges
against one reference) and reads every running average in ``on_frame``. Each
frame on its own is recovered from two consecutive averages,
``n·A_n − (n−1)·A_{n−1}``, for the per-frame errors and the (x, t) plot.
``on_frame`` is called by the renderer with the device synchronized and the
renderer's seconds since its first frame began; the study subtracts the time
spent inside its own earlier callbacks, so ``seconds`` is rendering time
(including the renderer's copy of each frame to the host and its averaging,
the same for every method). It records per frame the seconds, the renderer's
raw ``seconds_elapsed``, and the metrics of both the running average and the
frame against the reference (rendered once per scene with ``reference_seed``,
which must differ from ``seed``, and cached on disk by the renderer). It stops
after the last frame count of ``frames``, or once ``budget`` seconds have
passed (then the render is interrupted from ``on_frame`` and the renderer's
pass timings are not available).

Outputs in ``out`` (each written atomically):

* ``render_study.json`` — settings, device, versions, per-frame records,
  final metrics (FLIP added there), the equal-time table;
* ``render_study.csv`` — one row per (scene, method, frame);
* ``<scene>/reference.exr``, ``<scene>/<method>.exr`` — final images;
* ``<scene>/error_vs_time.png`` (log-log), ``<scene>/grid.png`` (images,
  zoomed insets, and HDR-FLIP error maps when FLIP is among the metrics, else
  relative-squared-error maps), ``<scene>/xt.png`` ((x, t) plot of one
  scanline over frames — seed 001, Fig. 1);

* ``jobs/<scene>/<method>.seed<S>.json`` and ``.npz`` — each finished
  (scene, method, seed) job, written as soon as it is done; a later run of the
  same study (same settings) reads them back instead of rendering again;

and for a toy study ``toy_study.json``, ``toy_study.csv`` and
``toy_error_vs_time.png``.

Beyond one process. Each (scene, method, seed) of a render study is one job,
:func:`study_job`, a task of :mod:`grisx.executor`: in process by default,
one job per device at a time with ``--devices cuda:0,cuda:1``, or one Ray task
each (``num_gpus=1``) with ``--executor ray``; the references' sample chunks
run there too. Jobs depend only on their arguments, so the study's numbers do
not depend on where they ran (their seconds do: on CPU, jobs running side by
side share the cores).

Equal time. Every method of a render study has an error curve of its running
average against seconds; the equal-time table reads each curve at one time T
(the budget, or the shortest total time among the methods when frame counts
are given) by log-log interpolation between the frames around T, and divides
the baseline's (first method's) error by each method's: a ratio > 1 means
better at equal time.

Long work reports on stderr through :class:`grisx.progress.Progress`: a bar
when stderr is a terminal, a plain line with the ETA every ~10 s otherwise.
"""

from __future__ import annotations

import dataclasses
import hashlib
import inspect
import math
import os
import platform
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from grisx.errors import GrisxError, InvalidParameterError, InvalidValueError
from grisx.eval import metrics as M
from grisx.eval.files import plain, write_csv, write_json
from grisx.progress import Progress

__all__ = [
    "MethodSpec",
    "Progress",
    "toy_study",
    "render_study",
    "REFERENCE_SEED",
    "TOY_LADDER",
]

_MAX_TRIALS = 2**31 - 1
#: trial counts a toy study climbs when given a time budget (1e3, 3e3, 1e4, … up to run_toy's limit)
TOY_LADDER = tuple(n for n in (m * 10**e for e in range(3, 10) for m in (1, 3)) if n <= _MAX_TRIALS)
#: seed of reference renders (test renders must use another seed to be independent of it)
REFERENCE_SEED = 999_983


# ---- method specs --------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class MethodSpec:
    """A method and its params, labelled for tables and plots (``METHOD[:k=v,k=v]``)."""

    method: str
    params: dict[str, Any] = dataclasses.field(default_factory=dict)
    label: str = ""

    def __post_init__(self) -> None:
        if not self.label:
            kv = ",".join(f"{k}={v}" for k, v in self.params.items())
            object.__setattr__(self, "label", self.method + (f":{kv}" if kv else ""))

    @classmethod
    def parse(cls, text: str) -> MethodSpec:
        """``"ris:target=approx,candidates=8"`` → MethodSpec('ris', {...})."""
        text = text.strip()
        name, _, rest = text.partition(":")
        if not name.strip():
            raise InvalidParameterError(f"method spec '{text}' has no method name (use METHOD[:k=v,k=v])")
        params: dict[str, Any] = {}
        for item in filter(None, (s.strip() for s in rest.split(","))):
            key, eq, value = item.partition("=")
            if not eq or not key.strip():
                raise InvalidParameterError(f"method spec '{text}': expected k=v, got '{item}'")
            if key.strip() in params:
                raise InvalidParameterError(f"method spec '{text}': param '{key.strip()}' given twice")
            params[key.strip()] = value.strip()
        return cls(name.strip(), params, text)

    @classmethod
    def coerce(cls, spec: MethodSpec | str | tuple[str, Mapping[str, Any]]) -> MethodSpec:
        if isinstance(spec, MethodSpec):
            return spec
        if isinstance(spec, str):
            return cls.parse(spec)
        name, params = spec
        return cls(name, dict(params))


def _specs(methods: Sequence[Any]) -> list[MethodSpec]:
    specs = [MethodSpec.coerce(m) for m in methods]
    if not specs:
        raise InvalidParameterError("a study needs at least one method")
    labels = [s.label for s in specs]
    dup = {x for x in labels if labels.count(x) > 1}
    if dup:
        raise InvalidParameterError(f"method '{sorted(dup)[0]}' is listed twice")
    return specs


# ---- writing ------------------------------------------------------------------------------
def _out_dir(out: str | os.PathLike | None) -> Path | None:
    if out is None:
        return None
    path = Path(out)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InvalidParameterError(f"cannot create output directory '{path}': {exc.strerror}") from None
    return path


def environment(device: str) -> dict[str, Any]:
    """Device and versions recorded beside every study."""
    import warp as wp

    import grisx
    from grisx.device import resolve_device

    dev = resolve_device(device)
    cpu_model = None
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            cpu_model = next((ln.split(":", 1)[1].strip() for ln in f if ln.startswith("model name")), None)
    except OSError:
        pass
    return {
        "device": str(dev),
        "device_name": getattr(dev, "name", str(dev)),
        "cpu_model": cpu_model,
        "platform": platform.platform(),
        "versions": {"grisx": grisx.__version__, "warp": wp.config.version, "numpy": np.__version__,
                     "python": platform.python_version()},
    }


def _seed_list(seed: int, seeds: Sequence[int] | None) -> list[int]:
    """The seeds of a study: ``seeds``, or ``[seed]``; distinct, at least one."""
    out = [int(seed)] if seeds is None else [int(x) for x in seeds]
    if not out or len(set(out)) != len(out):
        raise InvalidParameterError(f"seeds must be distinct and at least one, got {list(out)}")
    return out


# ---- toy study -----------------------------------------------------------------------------
def toy_study(
    problem: str,
    methods: Sequence[MethodSpec | str | tuple[str, Mapping[str, Any]]],
    *,
    trials: Sequence[int] | None = None,
    budget: float | None = None,
    seed: int = 0,
    device: str = "cpu",
    out: str | os.PathLike | None = None,
    repeats: int = 1,
    progress: bool | None = None,
    run: Callable[..., Any] | None = None,
    seeds: Sequence[int] | None = None,
) -> dict[str, Any]:
    """Error (RMSE of the mean vs the exact value) against seconds for each method of toy ``problem``.

    ``seeds``: run every ladder once per seed (default ``[seed]``); the tables and the plot are the first
    seed's, ``rows`` holds every seed's runs and the table each method's RMSE over the seeds.

    Give ``trials`` (a ladder of counts) or ``budget`` (seconds: climb
    :data:`TOY_LADDER` until a run takes that long; default 1 s). Each count
    is run ``repeats`` times with the same seed (same estimate) and the fastest
    kept, after one untimed warm-up run per method. All counts share the seed,
    so a smaller run's trials are a prefix of a larger one's. The efficiency
    uses the MSE predicted by the standard error, which assumes an unbiased
    method (``max_abs_z`` flags one that is not). Returns the study as a dict
    (also written to ``out`` with a CSV and a PNG).
    """
    if isinstance(repeats, bool) or not isinstance(repeats, int) or repeats < 1:
        raise InvalidParameterError(f"repeats must be a positive integer, got {repeats!r}")
    if run is None:
        from grisx.theory.toys import run_toy as run
    specs = _specs(methods)
    seeds = _seed_list(seed, seeds)
    if trials is not None and budget is not None:
        raise InvalidParameterError("give a trial ladder or a time budget, not both")
    if trials is not None:
        ladder = sorted({int(n) for n in trials})
        if not ladder or ladder[0] <= 0 or ladder[-1] > _MAX_TRIALS:
            raise InvalidParameterError(f"trial counts must be in [1, 2^31), got {list(trials)}")
    else:
        budget = 1.0 if budget is None else float(budget)
        if not (math.isfinite(budget) and budget > 0):
            raise InvalidParameterError(f"time budget must be a positive number of seconds, got {budget}")
        ladder = list(TOY_LADDER)
    outdir = _out_dir(out)
    env = environment(device)

    rows: list[dict[str, Any]] = []
    bar = Progress(len(specs) * (len(ladder) if trials is not None else 1), f"toys {problem}", unit="run", enabled=progress)
    for spec in specs:
        # warm-up: compiles/loads the kernels and touches the allocator, so the first timed run is not an outlier
        run(problem, spec.method, trials=min(ladder[0], 1000), seed=seeds[0], params=spec.params, device=device)
        for s_ in seeds:
            for n in ladder:
                est = min((run(problem, spec.method, trials=n, seed=s_, params=spec.params, device=device)
                           for _ in range(repeats)), key=lambda e: e.seconds)
                estimate, exact, stderr = (np.atleast_1d(np.asarray(a, dtype=np.float64)) for a in (est.estimate, est.exact, est.stderr))
                mse_pred = float(np.mean(stderr**2))
                rows.append({
                    "problem": problem, "method": spec.label, "seed": s_, "trials": n, "seconds": est.seconds,
                    "rmse": float(np.sqrt(np.mean((estimate - exact) ** 2))),
                    "rmse_predicted": math.sqrt(mse_pred),
                    "variance_per_trial": mse_pred * n,
                    "efficiency": M.efficiency(mse_pred, est.seconds) if est.seconds > 0 else None,
                    "max_abs_z": est.max_abs_z if math.isfinite(est.max_abs_z) else None,
                    "params": dict(est.params),
                    "estimate": estimate, "stderr": stderr, "exact": exact,
                })
                if trials is not None:
                    bar.update(1, spec.label)
                elif est.seconds >= budget:
                    break
        if trials is None:
            bar.update(1, spec.label)
    bar.close()
    first_rows = [r for r in rows if r["seed"] == seeds[0]]  # the tables and the plot: the first seed's runs

    # equal time, from each method's largest run (the baseline is the first method)
    final = {spec.label: [r for r in first_rows if r["method"] == spec.label][-1] for spec in specs}
    base = final[specs[0].label]
    t_eq = base["seconds"]
    table = []
    for spec in specs:
        r = final[spec.label]
        sec_per_trial = r["seconds"] / r["trials"]
        table.append({
            "method": spec.label, "trials": r["trials"], "seconds": r["seconds"],
            "trials_per_second": r["trials"] / r["seconds"] if r["seconds"] > 0 else None,
            "variance_per_trial": r["variance_per_trial"],
            "rmse_at_equal_time": math.sqrt(r["variance_per_trial"] * sec_per_trial / t_eq) if t_eq > 0 else None,
            "efficiency": r["efficiency"],
            "efficiency_ratio": (r["efficiency"] / base["efficiency"]) if r["efficiency"] and base["efficiency"] else None,
            "max_abs_z": r["max_abs_z"],
        })
        if len(seeds) > 1:  # the measured RMSE at the largest count, root-mean-squared over the seeds
            last = [[x for x in rows if x["method"] == spec.label and x["seed"] == s_][-1]["rmse"] for s_ in seeds]
            table[-1]["rmse_over_seeds"] = math.sqrt(float(np.mean(np.square(last))))
    study = {
        "kind": "toy",
        "problem": problem,
        **env,
        "seed": seeds[0],
        "seeds": seeds,
        "settings": {"methods": [{"label": s.label, "method": s.method, "params": s.params} for s in specs],
                     "ladder": ladder if trials is not None else None, "budget": budget, "repeats": repeats,
                     "baseline": specs[0].label,
                     "equal_time_seconds": t_eq},
        "rows": rows,
        "equal_time": table,
    }
    if outdir is not None:
        from grisx.eval.plots import plot_error_vs_time

        files = {
            "json": outdir / "toy_study.json",
            "csv": outdir / "toy_study.csv",
            "plot": outdir / "toy_error_vs_time.png",
        }
        study["output"] = {k: str(v) for k, v in files.items()}
        curves = {s.label: ([r["seconds"] for r in first_rows if r["method"] == s.label],
                            [r["rmse_predicted"] for r in first_rows if r["method"] == s.label]) for s in specs}
        plot_error_vs_time(curves, files["plot"], metric="RMSE of the mean (predicted from stderr)",
                           title=f"{problem} on {env['device']}")
        write_csv(files["csv"], rows, ["problem", "method", *(["seed"] if len(seeds) > 1 else []), "trials", "seconds", "rmse", "rmse_predicted",
                                       "variance_per_trial", "efficiency", "max_abs_z"])
        write_json(files["json"], study)
    return study


# ---- render study ---------------------------------------------------------------------------
class _BudgetSpent(Exception):
    """Raised from on_frame to stop a render once the time budget is spent."""


def _default_render() -> tuple[Callable[..., Any], Callable[..., Any]]:
    """grisx's renderer and its cached path-traced reference (with per-pixel variance where available)."""
    try:
        from grisx.render.driver import render
    except ImportError as exc:
        raise GrisxError(f"no renderer available (grisx.render.driver: {exc})") from None
    try:
        from grisx.render.reference import reference  # returns the image and the variance of its mean
    except ImportError:
        try:
            from grisx.render.driver import reference_image as reference
        except ImportError as exc:
            raise GrisxError(f"no reference renderer available: {exc}") from None
    return render, reference


def _interp_loglog(t: float, secs: Sequence[float], errs: Sequence[float]) -> float | None:
    """Error at time t on a curve, interpolated linearly in log-log between the frames around t."""
    s, e = np.asarray(secs, dtype=float), np.asarray(errs, dtype=float)
    if len(s) == 0 or t < s[0] or t > s[-1]:
        return None
    i = int(np.searchsorted(s, t))
    if i < len(s) and s[i] == t or i == 0:
        return float(e[i])
    s0, s1, e0, e1 = s[i - 1], s[i], e[i - 1], e[i]
    if min(s0, s1, e0, e1) <= 0 or s1 == s0:
        return float(e1)
    a = (math.log(t) - math.log(s0)) / (math.log(s1) - math.log(s0))
    return float(math.exp(math.log(e0) + a * (math.log(e1) - math.log(e0))))


def _safe_name(text: str) -> str:
    return "".join(c if c.isalnum() or c in "-_.=" else "_" for c in text)


def _method_spec(method: str) -> Any:
    """The registered :class:`~grisx.render.driver.RenderMethod` (None for unknown or fake renderers)."""
    try:
        from grisx.render.driver import METHODS
    except ImportError:  # no scene layer: fake renderers in tests
        return None
    return METHODS.get(method)


def _reference_max_depth(method: str) -> int | None:
    """The path-tracer depth a method's images estimate (None: the scene's full depth)."""
    spec = _method_spec(method)
    return None if spec is None else spec.reference_max_depth


def _frame_spp(method: str, spp: int) -> int | None:
    """The study's samples per pixel per frame for ``method``; None for methods that take one sample a frame."""
    spec = _method_spec(method)
    return None if spec is not None and not spec.uses_spp else spp


def study_job(
    *,
    scene: str,
    method: str,
    params: dict[str, Any],
    label: str,
    seed: int,
    reference: np.ndarray,
    reference_seed: int,
    spp: int,
    res: tuple[int, int] | None,
    names: Sequence[str],
    finals: Sequence[str],
    checkpoints: Sequence[int],
    total_frames: int,
    budget: float | None,
    warmup: bool,
    scanline: int,
    progress: bool | None,
    render: Callable[..., Any],
    device: str = "cpu",
) -> dict[str, Any]:
    """One (scene, method, seed) of a render study: its per-frame records, final image and (x, t) rows.

    A task of :mod:`grisx.executor` (``device``: where it runs); it depends on nothing but its arguments,
    so it gives the same numbers wherever it runs.
    """
    from grisx.device import resolve_device, synchronize

    dev = resolve_device(device)
    spec_ref = reference
    y_line = scanline
    # accumulate=True: the renderer averages the frames (and keeps a static camera, which is what
    # convergence against one reference needs); per-frame images are recovered from the averages
    kw = dict(spp=_frame_spp(method, spp), accumulate=True, res=res, device=device, params=dict(params))
    if warmup:  # compiles kernels; another seed so that nothing it draws is reused
        render(scene, method, frames=1, seed=seed + 1 if seed + 1 != reference_seed else seed + 2, **kw)
    records: list[dict[str, Any]] = []
    lines: list[np.ndarray] = []
    kept: dict[int, np.ndarray] = {}
    state: dict[str, Any] = {"callback": 0.0, "average": np.zeros_like(spec_ref)}
    bar = Progress(total_frames if budget is None else 100, f"{scene} {label}", unit="frame" if budget is None else "% of budget",
                   enabled=progress)

    def on_frame(index: int, image: np.ndarray, seconds_elapsed: float) -> None:
        entered = time.perf_counter()
        # the renderer's clock runs from before its first frame, device synchronized; take out the
        # time spent in this study's earlier callbacks (metrics are not rendering)
        seconds = float(seconds_elapsed) - state["callback"]
        n = len(records) + 1  # frames count from 1
        what = f"scene '{scene}' method '{label}' frame {n}"
        average, _ = M.check_images(image, spec_ref, what, f"reference of scene '{scene}'")
        frame = n * average - (n - 1) * state["average"]  # this frame alone, from two running averages
        state["average"] = average
        rec: dict[str, Any] = {"frame": n, "seconds": seconds, "renderer_seconds": float(seconds_elapsed)}
        for name in names:
            rec[name] = float(M.METRICS[name](average, spec_ref))
            rec[f"frame_{name}"] = float(M.METRICS[name](frame, spec_ref))
        if n in checkpoints:
            kept[n] = average  # final metrics (FLIP) after the run: keep callbacks light
        lines.append(frame[y_line].astype(np.float32))
        records.append(rec)
        if budget is not None:  # the bar counts percent of the budget
            bar.done = min(int(100 * seconds / budget), 100)
        bar.update(1 if budget is None else 0, f"{names[0]} {rec[names[0]]:.3g}")
        state["callback"] += time.perf_counter() - entered
        if budget is not None and seconds >= budget:
            raise _BudgetSpent

    result = None
    try:
        result = render(scene, method, frames=total_frames, seed=seed, on_frame=on_frame, **kw)
    except _BudgetSpent:
        pass
    synchronize(dev)
    bar.close()
    if not records:
        raise InvalidValueError(f"renderer called on_frame no time for scene '{scene}' method '{label}'")
    last = records[-1]
    final_image = state["average"]
    kept[len(records)] = final_image
    for n, image in kept.items():
        for name in finals:
            records[n - 1][name] = float(M.METRICS[name](image, spec_ref))
    primary = last[names[0]]
    record = {
        "method": method,
        "params": dict(params),
        "frames": len(records),
        "seconds": last["seconds"],
        "seconds_per_frame": last["seconds"] / len(records),
        "final": {k: last[k] for k in (*names, *finals) if k in last},
        "efficiency": M.efficiency(primary, last["seconds"]) if last["seconds"] > 0 else None,
        "pass_seconds": dict(getattr(result, "pass_seconds", {}) or {}),
        "renderer_settings": plain(dict(getattr(result, "settings", {}) or {})),
        "renderer_device": getattr(result, "device", None),
        "stopped_by_budget": result is None,
        "records": records,
    }
    return {"record": record, "image": final_image, "xt": np.stack(lines)}


def _job_path(outdir: Path, scene: str, label: str, seed: int) -> Path:
    return outdir / "jobs" / _safe_name(scene) / f"{_safe_name(label)}.seed{seed}"


def _load_job(path: Path, fingerprint: str) -> dict[str, Any] | None:
    """A job that an earlier run of the same study wrote (None: not written, or with other settings)."""
    import json

    meta, arrays = path.with_suffix(path.suffix + ".json"), path.with_suffix(path.suffix + ".npz")
    if not (meta.is_file() and arrays.is_file()):
        return None
    got = json.loads(meta.read_text())
    if got.get("fingerprint") != fingerprint:
        return None
    with np.load(arrays) as z:
        return {"record": got["record"], "image": z["image"], "xt": z["xt"]}


def _save_job(path: Path, fingerprint: str, job: dict[str, Any]) -> None:
    """A finished job on disk (arrays first, then the JSON that marks it done; each written atomically)."""
    import io

    from grisx.eval.files import write_atomic

    path.parent.mkdir(parents=True, exist_ok=True)
    buf = io.BytesIO()
    np.savez(buf, image=job["image"], xt=job["xt"])
    write_atomic(path.with_suffix(path.suffix + ".npz"), buf.getvalue())
    write_json(path.with_suffix(path.suffix + ".json"), {"fingerprint": fingerprint, "record": job["record"]})


def _fingerprint(**settings: Any) -> str:
    import hashlib
    import json

    return hashlib.sha256(json.dumps(plain(settings), sort_keys=True, default=str).encode()).hexdigest()


def render_study(
    scenes: Sequence[str],
    methods: Sequence[MethodSpec | str | tuple[str, Mapping[str, Any]]],
    *,
    frames: Sequence[int] | None = None,
    budget: float | None = None,
    spp: int = 1,
    res: tuple[int, int] | None = None,
    device: str = "cpu",
    seed: int = 0,
    reference_spp: int = 4096,
    reference_seed: int = REFERENCE_SEED,
    metrics: Sequence[str] = ("relmse", "mse", "mape"),
    final_metrics: Sequence[str] = ("flip",),
    scanline: int | None = None,
    warmup: bool = True,
    max_frames: int = 100_000,
    out: str | os.PathLike | None = None,
    progress: bool | None = None,
    render: Callable[..., Any] | None = None,
    reference: Callable[..., Any] | None = None,
    seeds: Sequence[int] | None = None,
    executor: Any = None,
    resume: bool = True,
) -> dict[str, Any]:
    """Render each scene with each method, recording per-frame seconds and errors; see the module doc.

    ``seeds``: run every (scene, method) once per seed (default: ``[seed]``); the per-method table and
    the equal-time table are the first seed's, ``seeds`` gives every seed's final errors and their mean.
    ``executor`` (:mod:`grisx.executor`): where the (scene, method, seed) jobs and the reference chunks
    run (default: here, on ``device``). With ``out``, each finished job is written to ``out/jobs/``
    at once, and with ``resume`` a job written there by an earlier run with the same settings is read
    back instead of rendered again (an interrupted study resumes where it stopped).

    Give ``frames`` (frame counts at which images are kept and FLIP is
    computed; the run goes to the largest) or ``budget`` (seconds per method;
    up to ``max_frames`` frames). ``metrics`` are computed at every frame (the
    first is the one plotted and used for efficiency and equal time);
    ``final_metrics`` only at the kept frames.
    """
    if (render is None) != (reference is None):
        raise InvalidParameterError("inject both render and reference functions, or neither")
    if render is None:
        render, reference = _default_render()
    specs = _specs(methods)
    scenes = list(scenes)
    if not scenes:
        raise InvalidParameterError("a render study needs at least one scene")
    names = M.parse_metrics(metrics)
    finals = [m for m in M.parse_metrics(final_metrics) if m not in names] if final_metrics else []
    if frames is not None and budget is not None:
        raise InvalidParameterError("give frame counts or a time budget, not both")
    if frames is not None:
        checkpoints = sorted({int(f) for f in frames})
        if not checkpoints or checkpoints[0] <= 0:
            raise InvalidParameterError(f"frame counts must be positive, got {list(frames)}")
        total_frames = checkpoints[-1]
    else:
        budget = 1.0 if budget is None else float(budget)
        if not (math.isfinite(budget) and budget > 0):
            raise InvalidParameterError(f"time budget must be a positive number of seconds, got {budget}")
        checkpoints, total_frames = [], int(max_frames)
    if spp <= 0 or reference_spp <= 0:
        raise InvalidParameterError(f"spp and reference spp must be positive, got {spp} and {reference_spp}")
    seeds = _seed_list(seed, seeds)
    if reference_seed in seeds:
        raise InvalidParameterError(f"seed {reference_seed} equals the reference seed: test renders must be independent of the reference")
    seed = seeds[0]
    outdir = _out_dir(out)
    env = environment(device)
    from grisx.executor import InProcessExecutor, Task

    if executor is None:
        executor = InProcessExecutor(device)
    ref_kw: dict[str, Any] = {}
    if "executor" in inspect.signature(reference).parameters:
        ref_kw["executor"] = executor  # grisx's reference: its chunks run where the jobs run

    # ---- references (cached on disk by the reference renderer) ----
    results: dict[str, Any] = {}
    refs: dict[str, dict[str, np.ndarray]] = {}
    for scene in scenes:
        got = reference(scene, res=res, spp=reference_spp, device=device, seed=reference_seed, **ref_kw)
        ref = M.check_image(getattr(got, "image", got), f"reference of scene '{scene}'")
        height, width = ref.shape[:2]
        scene_out: dict[str, Any] = {"width": width, "height": height}
        variance = getattr(got, "variance", None)
        if variance is not None:
            # the reference's own noise: what it adds, in expectation, to a measured MSE / relMSE
            var, _ = M.check_images(variance, ref, f"variance of the reference of scene '{scene}'", f"reference of scene '{scene}'")
            scene_out["reference_noise"] = {"mse": float(var.mean()),
                                            "relmse": float((var / (ref**2 + M.RELMSE_EPSILON)).mean())}
        y_line = height // 2 if scanline is None else int(scanline)
        if not 0 <= y_line < height:
            raise InvalidParameterError(f"scanline {y_line} is outside the image (height {height})")
        scene_out.update(scanline=y_line, methods={})
        results[scene] = scene_out
        refs[scene] = {"": ref}
        for spec in specs:
            # a method that estimates less than the full image (restir-di: emitted + direct light) is judged
            # against the path tracer at the depth it renders
            depth = _reference_max_depth(spec.method)
            if depth is None:
                refs[scene][spec.label] = ref
            else:
                got_d = reference(scene, res=res, spp=reference_spp, device=device, seed=reference_seed, max_depth=depth, **ref_kw)
                refs[scene][spec.label] = M.check_image(getattr(got_d, "image", got_d), f"max_depth={depth} reference of scene '{scene}'")

    # ---- the jobs: one per (scene, method, seed); those an earlier run wrote are read back ----
    jobs: dict[tuple[str, str, int], dict[str, Any]] = {}
    tasks, where = [], {}
    for scene in scenes:
        for spec in specs:
            for s_ in seeds:
                kwargs = dict(scene=scene, method=spec.method, params=dict(spec.params), label=spec.label, seed=s_,
                              reference=refs[scene][spec.label], reference_seed=reference_seed, spp=spp, res=res,
                              names=list(names), finals=list(finals), checkpoints=list(checkpoints),
                              total_frames=total_frames, budget=budget, warmup=warmup,
                              scanline=results[scene]["scanline"], progress=progress, render=render)
                fingerprint = _fingerprint(device=device, reference_sha=hashlib.sha256(kwargs["reference"].tobytes()).hexdigest(),
                                           **{k: v for k, v in kwargs.items() if k not in ("reference", "render", "progress")})
                path = _job_path(outdir, scene, spec.label, s_) if outdir is not None else None
                done = _load_job(path, fingerprint) if path is not None and resume else None
                if done is not None:
                    jobs[(scene, spec.label, s_)] = {**done, "resumed": True}
                    continue
                task = Task(f"{scene} | {spec.label} | seed {s_}", study_job, kwargs)
                tasks.append(task)
                where[task.key] = ((scene, spec.label, s_), path, fingerprint)
    for task, job, _report in executor.run(tasks):
        key, path, fingerprint = where[task.key]
        if path is not None:
            _save_job(path, fingerprint, job)
        jobs[key] = {**job, "resumed": False}

    csv_rows: list[dict[str, Any]] = []
    for scene in scenes:
        scene_out = results[scene]
        height, width = scene_out["height"], scene_out["width"]
        ref = refs[scene][""]
        method_refs = {spec.label: refs[scene][spec.label] for spec in specs}
        kept_images: dict[str, np.ndarray] = {}
        xt_rows: dict[str, np.ndarray] = {}
        for spec in specs:
            job = jobs[(scene, spec.label, seed)]
            depth = _reference_max_depth(spec.method)
            record = dict(job["record"])
            scene_out["methods"][spec.label] = {"method": record.pop("method"), "params": record.pop("params"),
                                                "reference_max_depth": depth, **record}
            for s_ in seeds:
                for rec in jobs[(scene, spec.label, s_)]["record"]["records"]:
                    csv_rows.append({"scene": scene, "method": spec.label, "seed": s_, **rec})
            kept_images[spec.label] = job["image"]
            xt_rows[spec.label] = job["xt"]
            if len(seeds) > 1:
                finals_by_seed = {str(s_): jobs[(scene, spec.label, s_)]["record"]["final"] for s_ in seeds}
                over = {}
                for k in finals_by_seed[str(seed)]:
                    v = np.array([f[k] for f in finals_by_seed.values()], dtype=np.float64)
                    over[k] = {"mean": float(v.mean()), "stderr": float(v.std(ddof=1) / math.sqrt(len(v)))}
                scene_out["methods"][spec.label]["seeds"] = {"final": finals_by_seed, "final_over_seeds": over}

        # equal time: each curve read at one time T
        curves = {lab: ([r["seconds"] for r in m["records"]], [r[names[0]] for r in m["records"]])
                  for lab, m in scene_out["methods"].items()}
        t_eq = budget if budget is not None else min(m["seconds"] for m in scene_out["methods"].values())
        at = {lab: _interp_loglog(t_eq, *c) for lab, c in curves.items()}
        base = at[specs[0].label]
        scene_out["equal_time"] = {
            "seconds": t_eq, "metric": names[0], "baseline": specs[0].label,
            "rows": [{"method": lab, names[0]: v, "ratio": (base / v) if (base is not None and v) else None}
                     for lab, v in at.items()],
        }
        if outdir is not None:
            from grisx.eval.plots import display_exposure, plot_error_vs_time, plot_image_grid, plot_xt
            from grisx.imageio import write_exr

            sdir = outdir / _safe_name(scene)
            sdir.mkdir(parents=True, exist_ok=True)
            files: dict[str, Any] = {"reference": write_exr(sdir / "reference.exr", ref)}
            files["images"] = {lab: write_exr(sdir / f"{_safe_name(lab)}.exr", img) for lab, img in kept_images.items()}
            files["error_vs_time"] = plot_error_vs_time(curves, sdir / "error_vs_time.png", metric=names[0],
                                                        title=f"{scene} on {env['device']}", budget=budget)
            exposure = display_exposure(ref)
            if "flip" in (*names, *finals):  # FLIP maps share a fixed [0, 1] scale across methods and studies
                maps = {lab: M.flip(img, method_refs[lab], return_map=True)[1] for lab, img in kept_images.items()}
                map_label, map_range = "HDR-FLIP error map", (0.0, 1.0)
            else:
                maps = {lab: M.relative_squared_error_map(img, method_refs[lab]).reshape(height, width, -1).mean(axis=-1)
                        for lab, img in kept_images.items()}
                map_label, map_range = f"relative squared error (eps={M.RELMSE_EPSILON:g})", None
            captions = {lab: f"{names[0]} {m['final'][names[0]]:.3g}, {m['seconds']:.2f} s, {m['frames']} fr"
                        for lab, m in scene_out["methods"].items()}
            files["grid"] = plot_image_grid(ref, kept_images, sdir / "grid.png", error_maps=maps,
                                            error_label=map_label, error_range=map_range,
                                            exposure=exposure, captions=captions, title=scene)
            files["xt"] = plot_xt(xt_rows, sdir / "xt.png", scanline=y_line, exposure=exposure, title=scene)
            scene_out["output"] = plain(files)
        results[scene] = scene_out

    study = {
        "kind": "render",
        **env,
        "seed": seed,
        "seeds": seeds,
        "executor": executor.describe(),
        "retried": executor.retried,
        "tasks": [r.to_dict() for r in executor.reports],  # where each job and reference chunk ran, and how long
        "resumed_jobs": sorted(" | ".join(map(str, k)) for k, j in jobs.items() if j["resumed"]),
        "settings": {
            "scenes": scenes,
            "methods": [{"label": s.label, "method": s.method, "params": s.params} for s in specs],
            "frames": checkpoints or None, "budget": budget, "spp": spp, "res": list(res) if res else None,
            "reference_spp": reference_spp, "reference_seed": reference_seed, "metrics": names,
            "final_metrics": finals, "relmse_epsilon": M.RELMSE_EPSILON, "relmse_reference": "the reference render",
            "warmup": warmup, "baseline": specs[0].label,
            "timing": "the renderer's seconds from before its first frame to each on_frame call (device "
                      "synchronized), minus the time spent inside the study's earlier callbacks; warm-up render excluded",
        },
        "scenes": results,
    }
    if outdir is not None:
        cols = ["scene", "method", *(["seed"] if len(seeds) > 1 else []), "frame", "seconds", "renderer_seconds", *names,
                *[f"frame_{n}" for n in names], *finals]
        study["output"] = {"json": str(outdir / "render_study.json"), "csv": str(outdir / "render_study.csv")}
        write_csv(outdir / "render_study.csv", csv_rows, cols)
        write_json(outdir / "render_study.json", study)
    return study
