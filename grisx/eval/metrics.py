"""Image error metrics: how far a rendered (or estimated) image is from its reference.

Every metric takes a *test* image and a *reference* image of the same shape,
``(H, W)`` or ``(H, W, C)``, as linear float values, and averages over pixels
**and** channels unless ``per_channel=True`` (then it returns one value per
channel, averaged over pixels). The reference is always the second argument.

Metrics
-------
``mse``      mean squared error, mean((test − ref)²).
``rmse``     √mse.
``relmse``   relative MSE, mean((test − ref)² / (ref² + ε)), with **ε = 10⁻²**
             (:data:`RELMSE_EPSILON`) and ``ref`` the *reference* image, per pixel
             and channel. ε keeps dark reference pixels from dominating the mean;
             10⁻² is the common choice in rendering and denoising evaluations (e.g.
             Bako et al. 2017), so numbers are comparable with theirs. The seed
             papers report relMSE without stating ε; pass ``epsilon=`` to change it.
``mape``     mean absolute percentage error, mean(|test − ref| / (|ref| + ε)), same ε
             and reference (seed 002 reports relMSE and MAPE "over the full image").
``chroma``   colour noise: relMSE of the chrominance C(x) = x − Y(x)·(1, 1, 1) (Y the
             Rec. 709 luminance), mean(|C(test) − C(ref)|² / (Y(ref)² + ε)) — the noise a
             luminance-driven estimator leaves in hue (seed 002, Sec. 4: a white plane
             under a red and a green light rendered red or green per pixel). Needs 3
             channels; a grey test of a grey reference has none, whatever its error.
``flip``     **HDR-FLIP** (Andersson et al. 2021) through NVIDIA's ``flip-evaluator``
             package: both images are taken as linear sRGB radiance (renders are
             HDR), FLIP chooses its exposure range from the reference and tonemaps
             with ACES, at its default 67 pixels per degree. This is the default FLIP
             because it needs no exposure choice from us and sees errors in highlights
             that an LDR clip would hide. Negative values (possible for
             control-variate or gradient-domain estimators) are clamped to 0, which is
             what the package assumes.
``flip_ldr`` **LDR-FLIP** on the sRGB-encoded images ``srgb(clip(2^ev · x, 0, 1))``
             (:func:`to_srgb`, exposure ``ev`` in stops, default 0): what a paper
             figure shows; use it to compare with papers that report LDR FLIP.

FLIP is computed on three colour channels: single-channel images are repeated
into grey RGB, and a fourth (alpha) channel is ignored. FLIP has no
per-channel variant.

Other tools
-----------
:func:`bias_estimate` estimates the bias of an estimator from K independent
runs (different seeds): mean_k(run_k) − ref, with a standard error from the
spread of the runs, so that |bias| / stderr is a z-score. The reference must
be much more accurate than one run (its own error is not included).

:func:`efficiency` is 1 / (error × seconds). With a squared error (MSE,
relMSE), an unbiased Monte Carlo estimator's error falls as 1/time, so the
efficiency does not depend on how long it ran and its ratio between two methods
is the equal-time error ratio.

Bad input (shapes that differ, NaN or Inf anywhere) raises
:class:`~grisx.errors.InvalidValueError` naming the image.

References
----------
Andersson, Nilsson, Akenine-Möller, Oskarsson, Åström, Fairchild. "FLIP: A
Difference Evaluator for Alternating Images", HPG 2020; Andersson et al.
"Visualizing Errors in Rendered High Dynamic Range Images", Eurographics 2021
(HDR-FLIP). Rousselle, Knaus, Zwicker, "Adaptive Sampling and Reconstruction
using Greedy Error Minimization", SIGGRAPH Asia 2011 (relMSE). Bako et al.,
"Kernel-Predicting Convolutional Networks for Denoising Monte Carlo
Renderings", SIGGRAPH 2017 (relMSE with ε = 0.01).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterable, Sequence
from typing import Any

import numpy as np

from grisx.errors import InvalidParameterError, InvalidValueError, UnknownNameError

__all__ = [
    "RELMSE_EPSILON",
    "METRICS",
    "mse",
    "rmse",
    "relmse",
    "mape",
    "flip",
    "flip_ldr",
    "squared_error_map",
    "relative_squared_error_map",
    "to_srgb",
    "check_image",
    "check_images",
    "parse_metrics",
    "compare",
    "BiasEstimate",
    "bias_estimate",
    "efficiency",
]

#: ε of relMSE and MAPE (denominators ref² + ε and |ref| + ε; ref = the reference image)
RELMSE_EPSILON = 1e-2


# ---- validation ---------------------------------------------------------------
def check_image(a: Any, name: str) -> np.ndarray:
    """One image as a float64 (H, W) or (H, W, C) array; raise naming it if it is malformed, NaN or Inf."""
    try:
        img = np.asarray(a, dtype=np.float64)
    except (TypeError, ValueError):
        raise InvalidValueError(f"{name} image is not an array of numbers") from None
    if img.ndim not in (2, 3) or img.size == 0:
        raise InvalidValueError(f"{name} image must have shape (H, W) or (H, W, C) and be non-empty, got shape {img.shape}")
    bad = ~np.isfinite(img)
    if bad.any():
        where = tuple(int(i) for i in np.argwhere(bad)[0][:2])
        raise InvalidValueError(f"{name} image has {int(bad.sum())} NaN/Inf values (first at pixel y,x = {where})")
    return img


def check_images(test: Any, ref: Any, test_name: str = "test", ref_name: str = "reference") -> tuple[np.ndarray, np.ndarray]:
    """Both images as float64 arrays of one shape; raise naming the image otherwise."""
    t = check_image(test, test_name)
    r = check_image(ref, ref_name)
    if t.shape != r.shape:
        raise InvalidValueError(f"{test_name} image has shape {t.shape} but {ref_name} image has shape {r.shape}")
    return t, r


def _reduce(values: np.ndarray, per_channel: bool) -> float | np.ndarray:
    if not per_channel:
        return float(values.mean())
    if values.ndim == 2:
        return np.array([values.mean()])
    return values.reshape(-1, values.shape[-1]).mean(axis=0)


def _epsilon(epsilon: float) -> float:
    if not (isinstance(epsilon, (int, float)) and math.isfinite(epsilon) and epsilon > 0):
        raise InvalidParameterError(f"epsilon must be a positive number, got {epsilon!r}")
    return float(epsilon)


# ---- pixel-wise metrics ---------------------------------------------------------
def squared_error_map(test: Any, ref: Any) -> np.ndarray:
    """(test − ref)² per pixel and channel."""
    t, r = check_images(test, ref)
    return (t - r) ** 2


def relative_squared_error_map(test: Any, ref: Any, epsilon: float = RELMSE_EPSILON) -> np.ndarray:
    """(test − ref)² / (ref² + ε) per pixel and channel; ``ref`` is the reference."""
    t, r = check_images(test, ref)
    return (t - r) ** 2 / (r**2 + _epsilon(epsilon))


def mse(test: Any, ref: Any, *, per_channel: bool = False) -> float | np.ndarray:
    """Mean squared error over pixels and channels (or per channel)."""
    return _reduce(squared_error_map(test, ref), per_channel)


def rmse(test: Any, ref: Any, *, per_channel: bool = False) -> float | np.ndarray:
    """Root of :func:`mse`."""
    return np.sqrt(mse(test, ref, per_channel=per_channel)) if per_channel else math.sqrt(mse(test, ref))


def relmse(test: Any, ref: Any, *, epsilon: float = RELMSE_EPSILON, per_channel: bool = False) -> float | np.ndarray:
    """Relative MSE, mean((test − ref)² / (ref² + ε)); ``ref`` is the reference, ε = 10⁻² by default."""
    return _reduce(relative_squared_error_map(test, ref, epsilon), per_channel)


def mape(test: Any, ref: Any, *, epsilon: float = RELMSE_EPSILON, per_channel: bool = False) -> float | np.ndarray:
    """Mean absolute percentage error, mean(|test − ref| / (|ref| + ε)), as a fraction (not ×100)."""
    t, r = check_images(test, ref)
    return _reduce(np.abs(t - r) / (np.abs(r) + _epsilon(epsilon)), per_channel)


#: Rec. 709 luminance weights: Y = 0.2126 R + 0.7152 G + 0.0722 B
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def chroma(test: Any, ref: Any, *, epsilon: float = RELMSE_EPSILON, per_channel: bool = False) -> float | np.ndarray:
    """Colour noise: relMSE of the chrominance C(x) = x − Y(x)·(1, 1, 1), mean(|C(test) − C(ref)|² / (Y(ref)² + ε)).

    Linear in the images (no division by a test pixel, so negative control-variate estimates are
    fine); a test image of the reference's hues at another brightness has only the brightness
    part of its error here, which ``relmse`` counts too."""
    t, r = check_images(test, ref)
    if t.ndim != 3 or t.shape[-1] < 3:
        raise InvalidParameterError(f"chroma needs (H, W, 3) images, got shape {t.shape}")
    t, r = t[..., :3], r[..., :3]
    y_t, y_r = (t @ LUMINANCE)[..., None], (r @ LUMINANCE)[..., None]
    d2 = ((t - y_t) - (r - y_r)) ** 2 / (y_r**2 + _epsilon(epsilon))
    return _reduce(d2, per_channel)


# ---- FLIP ---------------------------------------------------------------------------
def to_srgb(linear: Any, exposure: float = 0.0) -> np.ndarray:
    """Display encoding: clip(2^exposure · x, 0, 1) through the sRGB transfer function (IEC 61966-2-1)."""
    from grisx.imageio import srgb_encode

    return srgb_encode(np.asarray(linear, dtype=np.float64) * 2.0**exposure)


def _rgb(img: np.ndarray) -> np.ndarray:
    if img.ndim == 2:
        img = img[:, :, None]
    c = img.shape[2]
    if c == 1:
        img = np.repeat(img, 3, axis=2)
    elif c in (3, 4):
        img = img[:, :, :3]  # alpha is not colour
    else:
        raise InvalidValueError(f"FLIP needs 1, 3 or 4 channels, got {c}")
    return np.ascontiguousarray(img, dtype=np.float32)


def _flip_evaluator():
    try:
        import flip_evaluator
    except ImportError as exc:  # a declared dependency, but say so clearly
        raise InvalidParameterError(f"FLIP needs the flip-evaluator package (pip install flip-evaluator): {exc}") from None
    return flip_evaluator


def _flip(test: np.ndarray, ref: np.ndarray, mode: str, return_map: bool) -> float | tuple[float, np.ndarray]:
    fe = _flip_evaluator()
    error_map, mean, _ = fe.evaluate(_rgb(ref), _rgb(test), mode, applyMagma=False)
    value = float(mean)
    if return_map:
        return value, np.asarray(error_map, dtype=np.float32).reshape(test.shape[:2])
    return value


def flip(test: Any, ref: Any, *, return_map: bool = False) -> float | tuple[float, np.ndarray]:
    """HDR-FLIP of linear images (mean over pixels; with ``return_map`` also the (H, W) error map)."""
    t, r = check_images(test, ref)
    return _flip(np.maximum(t, 0.0), np.maximum(r, 0.0), "HDR", return_map)


def flip_ldr(test: Any, ref: Any, *, exposure: float = 0.0, return_map: bool = False) -> float | tuple[float, np.ndarray]:
    """LDR-FLIP of the sRGB-encoded images :func:`to_srgb` (x, exposure)."""
    t, r = check_images(test, ref)
    return _flip(to_srgb(t, exposure), to_srgb(r, exposure), "LDR", return_map)


#: metric name → function(test, ref, per_channel) used by :func:`compare`, the runner and ``grisx compare``
METRICS: dict[str, Callable[..., Any]] = {
    "mse": mse,
    "rmse": rmse,
    "relmse": relmse,
    "mape": mape,
    "chroma": chroma,
    "flip": flip,
    "flip_ldr": flip_ldr,
}
#: metrics with a per-channel variant
PER_CHANNEL = ("mse", "rmse", "relmse", "mape", "chroma")


def parse_metrics(names: str | Iterable[str]) -> list[str]:
    """``"mse,relmse,flip"`` (or a list) → checked, de-duplicated metric names in order."""
    items = names.split(",") if isinstance(names, str) else list(names)
    out: list[str] = []
    for raw in items:
        name = raw.strip().lower().replace("-", "_")
        if not name:
            continue
        if name not in METRICS:
            raise UnknownNameError("metric", raw.strip(), list(METRICS))
        if name not in out:
            out.append(name)
    if not out:
        raise InvalidParameterError("no metric named (known: " + ", ".join(METRICS) + ")")
    return out


def compare(
    test: Any,
    ref: Any,
    metrics: str | Sequence[str] = ("mse", "rmse", "relmse", "mape", "flip"),
    *,
    per_channel: bool = False,
    epsilon: float = RELMSE_EPSILON,
    exposure: float = 0.0,
    test_name: str = "test",
    ref_name: str = "reference",
) -> dict[str, Any]:
    """Every requested metric of ``test`` against the reference ``ref``, as ``{name: value}``.

    With ``per_channel`` the metrics that have a per-channel variant also give
    ``{name}_per_channel`` (a list, one value per channel).
    """
    names = parse_metrics(metrics)
    t, r = check_images(test, ref, test_name, ref_name)
    out: dict[str, Any] = {}
    for name in names:
        if name in ("relmse", "mape"):
            out[name] = METRICS[name](t, r, epsilon=epsilon)
        elif name == "flip_ldr":
            out[name] = flip_ldr(t, r, exposure=exposure)
        else:
            out[name] = METRICS[name](t, r)
        if per_channel and name in PER_CHANNEL:
            kw = {"epsilon": epsilon} if name in ("relmse", "mape") else {}
            out[f"{name}_per_channel"] = [float(v) for v in METRICS[name](t, r, per_channel=True, **kw)]
    return out


# ---- bias and efficiency -------------------------------------------------------------
@dataclasses.dataclass
class BiasEstimate:
    """Bias of an estimator from K independent runs: mean_k(run_k) − ref.

    ``bias`` and ``stderr`` are image means (signed) over pixels and channels;
    ``per_channel`` / ``per_channel_stderr`` the same per channel; ``bias_map``
    and ``stderr_map`` per pixel and channel. ``z`` = bias / stderr.
    """

    bias: float
    stderr: float
    per_channel: np.ndarray
    per_channel_stderr: np.ndarray
    bias_map: np.ndarray
    stderr_map: np.ndarray
    runs: int
    relative_bias: float  # bias / mean(ref), 0 where the reference is black

    @property
    def z(self) -> float:
        if self.stderr > 0:
            return self.bias / self.stderr
        return 0.0 if self.bias == 0 else math.copysign(math.inf, self.bias)

    def to_dict(self) -> dict[str, Any]:
        return {
            "bias": self.bias,
            "stderr": self.stderr,
            "z": self.z if math.isfinite(self.z) else None,
            "relative_bias": self.relative_bias,
            "per_channel": [float(v) for v in self.per_channel],
            "per_channel_stderr": [float(v) for v in self.per_channel_stderr],
            "runs": self.runs,
        }


def bias_estimate(runs: Sequence[Any] | np.ndarray, ref: Any) -> BiasEstimate:
    """Bias by accumulation over ``runs`` (K ≥ 2 independent images, i.e. different seeds).

    The image-mean bias is the mean over runs of each run's image-mean
    difference from ``ref``; its standard error is the sample standard deviation
    of those K differences over √K (pixels within a run may be correlated, as in
    ReSTIR, so runs — not pixels — are the independent samples).
    """
    if isinstance(runs, np.ndarray):
        images = [runs[k] for k in range(runs.shape[0])] if runs.ndim >= 3 else [runs]
    else:
        images = list(runs)
    k = len(images)
    if k < 2:
        raise InvalidParameterError(f"bias_estimate needs at least 2 independent runs, got {k}")
    r = check_image(ref, "reference")
    diffs = np.stack([check_images(img, r, f"run {i}")[0] - r for i, img in enumerate(images)])
    bias_map = diffs.mean(axis=0)
    stderr_map = diffs.std(axis=0, ddof=1) / math.sqrt(k)
    per_run = diffs.reshape(k, -1).mean(axis=1)
    channels = 1 if r.ndim == 2 else r.shape[2]
    per_run_channel = diffs.reshape(k, -1, channels).mean(axis=1)
    bias = float(per_run.mean())
    ref_mean = float(r.mean())
    return BiasEstimate(
        bias=bias,
        stderr=float(per_run.std(ddof=1) / math.sqrt(k)),
        per_channel=per_run_channel.mean(axis=0),
        per_channel_stderr=per_run_channel.std(axis=0, ddof=1) / math.sqrt(k),
        bias_map=bias_map,
        stderr_map=stderr_map,
        runs=k,
        relative_bias=bias / ref_mean if ref_mean != 0 else 0.0,
    )


def efficiency(error: float, seconds: float) -> float:
    """1 / (error × seconds); use a squared error (MSE, relMSE) so it is time-invariant for MC.

    A zero error gives ``inf`` (a perfect image); seconds must be positive.
    """
    if not (math.isfinite(seconds) and seconds > 0):
        raise InvalidValueError(f"efficiency needs a positive time, got {seconds!r} s")
    if not (math.isfinite(error) and error >= 0):
        raise InvalidValueError(f"efficiency needs a finite non-negative error, got {error!r}")
    return math.inf if error == 0 else 1.0 / (error * seconds)
