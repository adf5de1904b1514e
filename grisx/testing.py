"""Statistical checks for Monte Carlo estimators — the ones grisx's own tests use.

An unbiased estimator is verified by running many independent trials and
comparing the sample mean with the exact value in units of its standard
error,

    z = (mean − exact) / stderr,

which is ≈ N(0, 1) by the central limit theorem. A test *passes* when
|z| ≤ k (k = 4 by default: a false alarm once in ~16 000 runs) and a
known-biased variant is *caught* when |z| > 6 at the same trial count — so
every check is shown to be able to fail.

When one verdict rests on many z-values (pixels × channels), the per-value
threshold is raised by the Šidák correction so that the family-wise false
alarm rate stays at that of a single 4σ test:

    α_each = 1 − (1 − α)^(1/n).

A sampler (``sample_x`` / ``x_pdf`` pair) is verified by a χ² goodness-of-fit
test: samples are binned and the counts compared with the pdf integrated over
each bin (bins with expectation below 5 are pooled, as in Mitsuba's
``ChiSquareTest``).

Correlated estimators (ReSTIR reuse across pixels) must be tested over
independent runs or batch means, never per correlated pixel.

**Heavy right tails** (caustics by specular manifold sampling: Bernoulli-trial
counts, a prior's rare large weights) break the z-test in one direction. The
runs that would raise the mean are rare, so most sets of runs miss them: their
mean is low *and* their spread is small, and z = (mean − exact)/stderr lands
far below −k much more often than the normal tail says (lognormal runs of
skewness 13: 40× too often at k = 4 and 1024 runs). :func:`skew_corrected_z`
removes the leading term of that skew (Hall 1992's monotone transform of the
studentized mean, with the runs' own third cumulant): ``reuse_unbiasedness_test(...,
skew_corrected=True)``. It does not make a test of too few runs decisive — a
tail that no run has sampled cannot be seen — so tests of such estimators still
need enough runs, and a known-biased sibling that the same check catches.
:func:`reuse_unbiasedness_test` does that for a renderer: it compares the
mean over independent runs of the image mean *and* of every block mean
(e.g. 8×8 pixels; Šidák across blocks and channels) with a reference, so
that biases of opposite sign in different parts of the image — which cancel
in the image mean — are still seen.

Two renderers that should agree — grisx's path tracer and Mitsuba 3's on the
same scene file — are compared by :func:`image_agreement_test`: both give
per-pixel means and variances (pixels independent, as a path tracer's are),
and the image mean and block means are z-tested, Šidák-corrected over a whole
suite of scenes (``tests/conformance``).

Mitsuba 3's own render-test suite (``src/render/tests/test_renders.py``, scenes and
references in mitsuba-data ``tests/scenes``) has its own verdict, kept here as
:func:`mitsuba_render_test` so that grisx is judged by exactly Mitsuba's rule: a
budget of 2·10⁶ samples spread over the pixels, every pixel and XYZ channel
z-tested against the 32k-spp reference and its variance image (floored at
1e-4) at a Šidák-corrected 1% level, and the scene passes when at least
99.75% of the pixels' channels pass.

References: P. Hall, "On the removal of skewness by transformation", JRSS B 54
(1992); N. J. Johnson, "Modified t tests and confidence intervals for asymmetrical
populations", JASA 73 (1978); Z. Šidák, "Rectangular confidence regions for the means of
multivariate normal distributions", JASA 62 (1967); W. Jakob et al., Mitsuba 3
``mitsuba.chi2``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence

import numpy as np
import scipy.integrate
import scipy.stats

from grisx.errors import InvalidParameterError, InvalidValueError

__all__ = [
    "independent_runs",
    "skew_corrected_z",
    "block_means",
    "ReuseTestResult",
    "reuse_unbiasedness_test",
    "ZTestResult",
    "Chi2Result",
    "z_test",
    "sidak_alpha",
    "sidak_threshold",
    "chi2_test",
    "image_agreement_test",
    "MitsubaRenderTestResult",
    "mitsuba_render_test",
    "mitsuba_render_test_spp",
    "DEFAULT_K",
    "BIASED_K",
]

#: |z| allowed for an unbiased estimator
DEFAULT_K = 4.0
#: |z| that a known-biased variant must exceed to count as caught
BIASED_K = 6.0


@dataclasses.dataclass(frozen=True)
class ZTestResult:
    """Outcome of :func:`z_test`: per-component z-values and the verdict."""

    z: np.ndarray
    threshold: float
    passed: bool

    @property
    def max_abs_z(self) -> float:
        return float(np.max(np.abs(self.z)))

    def __str__(self) -> str:
        verdict = "pass" if self.passed else "FAIL"
        return f"{verdict}: max |z| = {self.max_abs_z:.2f} (threshold {self.threshold:.2f}, {self.z.size} values)"


@dataclasses.dataclass(frozen=True)
class Chi2Result:
    """Outcome of :func:`chi2_test`."""

    statistic: float
    dof: int
    p_value: float
    alpha: float
    passed: bool

    def __str__(self) -> str:
        verdict = "pass" if self.passed else "FAIL"
        return f"{verdict}: chi2 = {self.statistic:.1f}, dof = {self.dof}, p = {self.p_value:.3g} (alpha {self.alpha:g})"


def sidak_alpha(alpha: float, tests: int) -> float:
    """Per-test level 1 − (1 − α)^(1/n) keeping the family-wise level at α."""
    if not 0.0 < alpha < 1.0:
        raise InvalidParameterError(f"alpha must be in (0, 1), got {alpha}")
    if tests < 1:
        raise InvalidParameterError(f"tests must be >= 1, got {tests}")
    return -math.expm1(math.log1p(-alpha) / tests)


def sidak_threshold(k: float, tests: int) -> float:
    """The |z| threshold for ``tests`` values with the family-wise level of one two-sided k-σ test."""
    alpha = 2.0 * scipy.stats.norm.sf(k)
    return float(scipy.stats.norm.isf(sidak_alpha(alpha, tests) / 2.0))


def z_test(
    estimate: float | Sequence[float] | np.ndarray,
    stderr: float | Sequence[float] | np.ndarray,
    exact: float | Sequence[float] | np.ndarray,
    k: float = DEFAULT_K,
    sidak: bool = True,
) -> ZTestResult:
    """Is ``estimate`` within k standard errors of ``exact`` (per component)?

    With ``sidak`` and n > 1 components the threshold is
    :func:`sidak_threshold`\\ (k, n). A zero standard error passes only on an
    exact match. NaN anywhere is an error, never a pass.
    """
    est, se, ex = (np.atleast_1d(np.asarray(a, dtype=np.float64)) for a in (estimate, stderr, exact))
    try:
        est, se, ex = np.broadcast_arrays(est, se, ex)
    except ValueError:
        raise InvalidParameterError(f"estimate, stderr and exact have incompatible shapes {est.shape}, {se.shape}, {ex.shape}") from None
    for name, a in (("estimate", est), ("stderr", se), ("exact", ex)):
        if not np.all(np.isfinite(a)):
            raise InvalidValueError(f"{name} contains NaN or Inf")
    if np.any(se < 0):
        raise InvalidValueError("stderr must be non-negative")
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(se > 0, (est - ex) / np.where(se > 0, se, 1.0), np.where(est == ex, 0.0, np.inf))
    threshold = sidak_threshold(k, z.size) if sidak and z.size > 1 else float(k)
    return ZTestResult(z=z, threshold=threshold, passed=bool(np.all(np.abs(z) <= threshold)))


def chi2_test(
    samples: np.ndarray,
    pdf: Callable[[np.ndarray], np.ndarray],
    lo: float,
    hi: float,
    bins: int = 64,
    alpha: float = 1e-4,
    tests: int = 1,
    min_expected: float = 5.0,
) -> Chi2Result:
    """χ² test that 1D ``samples`` on [lo, hi] follow the density ``pdf``.

    Expected bin counts come from integrating ``pdf`` (vectorised) over each
    bin with adaptive quadrature; bins expecting fewer than ``min_expected``
    samples are pooled. ``tests`` applies a Šidák correction to ``alpha``.
    Samples outside [lo, hi] go to an overflow bin whose expectation is the
    pdf mass outside (normally 0: any such sample fails the test).
    """
    x = np.asarray(samples, dtype=np.float64).ravel()
    if x.size == 0:
        raise InvalidParameterError("chi2_test needs at least one sample")
    if not np.all(np.isfinite(x)):
        raise InvalidValueError("samples contain NaN or Inf")
    edges = np.linspace(lo, hi, bins + 1)
    observed = np.histogram(x, bins=edges)[0].astype(np.float64)
    outside = float(np.count_nonzero((x < lo) | (x > hi)))
    scalar_pdf = lambda t: float(np.asarray(pdf(np.array([t])))[0])  # noqa: E731
    mass = np.array([scipy.integrate.quad(scalar_pdf, a, b, limit=100)[0] for a, b in zip(edges[:-1], edges[1:])])
    expected = mass * x.size
    outside_expected = max(0.0, 1.0 - mass.sum()) * x.size
    if outside > 0 and outside_expected < 1e-9 * x.size:
        # samples where the pdf says none can be: certain failure, whatever the bins say
        return Chi2Result(statistic=math.inf, dof=bins - 1, p_value=0.0, alpha=alpha, passed=False)
    observed = np.append(observed, outside)
    expected = np.append(expected, outside_expected)
    # pool small bins (in order) until every pooled bin expects >= min_expected
    obs_pooled, exp_pooled = [], []
    acc_o = acc_e = 0.0
    for o, e in zip(observed, expected):
        acc_o += o
        acc_e += e
        if acc_e >= min_expected:
            obs_pooled.append(acc_o)
            exp_pooled.append(acc_e)
            acc_o = acc_e = 0.0
    if acc_o > 0 and acc_e < min_expected and exp_pooled:
        obs_pooled[-1] += acc_o
        exp_pooled[-1] += acc_e
    elif acc_o > 0 or acc_e > 0:
        obs_pooled.append(acc_o)
        exp_pooled.append(acc_e)
    o = np.array(obs_pooled)
    e = np.array(exp_pooled)
    if np.any((e <= 0) & (o > 0)):
        # samples where the pdf says none can be: certain failure
        return Chi2Result(statistic=math.inf, dof=max(len(o) - 1, 1), p_value=0.0, alpha=alpha, passed=False)
    keep = e > 0
    stat = float(np.sum((o[keep] - e[keep]) ** 2 / e[keep]))
    dof = max(int(keep.sum()) - 1, 1)
    p = float(scipy.stats.chi2.sf(stat, dof))
    level = sidak_alpha(alpha, tests) if tests > 1 else alpha
    return Chi2Result(statistic=stat, dof=dof, p_value=p, alpha=level, passed=p >= level)


def independent_runs(run: Callable[[int], np.ndarray], runs: int, seed0: int = 1000) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard error over ``runs`` independent runs of a correlated estimator.

    ``run(seed)`` returns one run's estimate (e.g. a reuse renderer's image mean
    after F frames, all history started afresh with that seed). The runs are
    independent, so their spread gives an honest standard error even though
    the pixels inside one run are correlated.
    """
    if runs < 2:
        raise InvalidParameterError(f"independent_runs needs at least 2 runs, got {runs}")
    values = np.asarray([np.asarray(run(seed0 + r), dtype=np.float64) for r in range(runs)])
    return values.mean(axis=0), values.std(axis=0, ddof=1) / math.sqrt(runs)


def skew_corrected_z(runs: np.ndarray, exact: np.ndarray | float, exact_stderr: np.ndarray | float = 0.0) -> np.ndarray:
    """z of the mean of independent ``runs`` (axis 0) against ``exact``, corrected for the mean's skewness.

    With D = mean − exact, V = s²/n + ``exact_stderr``² its variance, T = D/√V and γ = κ₃/V^{3/2}
    the standardized skewness of D (κ₃ = the runs' unbiased third cumulant / n²; the exact value's
    taken as symmetric), Hall's (1992) transform

        z = T + γ/6 + γ T²/3 + γ² T³/27

    is monotone in T and N(0, 1) to a smaller error than T (Johnson 1978's modified t plus the
    cubic term that makes it monotone). For right-skewed runs (γ > 0) it pulls the too-frequent
    large negative T towards 0 and keeps the positive side's power. With γ = 0 it is T.
    """
    x = np.asarray(runs, dtype=np.float64)
    n = x.shape[0]
    if n < 3:
        raise InvalidParameterError(f"skew_corrected_z needs at least 3 runs, got {n}")
    if not np.all(np.isfinite(x)):
        raise InvalidValueError("runs contain NaN or Inf")
    mean = x.mean(axis=0)
    d = x - mean
    var_mean = (d**2).sum(axis=0) / (n - 1) / n
    k3_mean = (d**3).sum(axis=0) * n / ((n - 1) * (n - 2)) / n**2
    v = var_mean + np.asarray(exact_stderr, dtype=np.float64) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(v > 0, (mean - exact) / np.sqrt(np.where(v > 0, v, 1.0)), np.where(mean == exact, 0.0, np.inf))
        g = np.where(v > 0, k3_mean / np.where(v > 0, v, 1.0) ** 1.5, 0.0)
    return t + g / 6.0 + g * t**2 / 3.0 + g**2 * t**3 / 27.0


def _z_result(z: np.ndarray, k: float) -> ZTestResult:
    """A :class:`ZTestResult` for ready z-values, thresholds as :func:`z_test`'s (Šidák over the components)."""
    z = np.atleast_1d(np.asarray(z, dtype=np.float64))
    threshold = sidak_threshold(k, z.size) if z.size > 1 else float(k)
    return ZTestResult(z=z, threshold=threshold, passed=bool(np.all(np.abs(z) <= threshold)))


def block_means(image: np.ndarray, block: int = 8) -> np.ndarray:
    """Means of ``block``×``block`` tiles of an (H, W, C) image → (⌈H/b⌉, ⌈W/b⌉, C); edge tiles may be smaller."""
    a = np.asarray(image, dtype=np.float64)
    if a.ndim != 3 or block < 1:
        raise InvalidParameterError(f"block_means needs an (H, W, C) image and block >= 1, got shape {a.shape}, block {block}")
    h, w, c = a.shape
    rows, cols = -(-h // block), -(-w // block)
    out = np.empty((rows, cols, c))
    for i in range(rows):
        for j in range(cols):
            out[i, j] = a[i * block:(i + 1) * block, j * block:(j + 1) * block].reshape(-1, c).mean(axis=0)
    return out


@dataclasses.dataclass(frozen=True)
class ReuseTestResult:
    """The image-mean z-test and the per-block z-test of :func:`reuse_unbiasedness_test` or :func:`image_agreement_test`.

    ``runs``: the independent runs behind the standard errors (0 when they came from per-pixel variances).
    """

    image: ZTestResult
    blocks: ZTestResult
    runs: int

    @property
    def passed(self) -> bool:
        return self.image.passed and self.blocks.passed


def reuse_unbiasedness_test(
    run: Callable[[int], np.ndarray],
    reference: np.ndarray,
    reference_variance: np.ndarray,
    runs: int,
    *,
    block: int = 8,
    k: float = DEFAULT_K,
    seed0: int = 1000,
    skew_corrected: bool = False,
) -> ReuseTestResult:
    """Is a reuse renderer's image unbiased against ``reference``, over ``runs`` independent runs?

    ``run(seed)`` renders one independent run (history started afresh with that seed) and
    returns its (H, W, C) image; ``reference`` is an independent estimate of the same image
    (e.g. the path tracer at many spp) and ``reference_variance`` the per-pixel variance of
    its mean (pixels independent). Both the image mean and every ``block``×``block`` block
    mean are z-tested per channel, the standard error combining the runs' spread with the
    reference's own (floored at float32 rounding, :func:`_rounding_floor`); the block test is
    Šidák-corrected across blocks and channels. ``skew_corrected``: the z-values are
    :func:`skew_corrected_z`'s (heavy-tailed runs; the rounding floor still applies).
    """
    ref = np.asarray(reference, dtype=np.float64)
    var = np.asarray(reference_variance, dtype=np.float64)
    images = np.asarray([np.asarray(run(seed0 + r), dtype=np.float64) for r in range(runs)])
    if runs < 2 or images.shape[1:] != ref.shape:
        raise InvalidParameterError(f"need >= 2 runs of images shaped like the reference {ref.shape}, got {images.shape}")
    c = ref.shape[-1]
    ref_block_se, ref_se = _independent_pixel_errors(var, block)
    run_blocks = np.asarray([block_means(im, block) for im in images])
    mean_blocks, ref_blocks = run_blocks.mean(axis=0), block_means(ref, block)
    block_se = _rounding_floor(np.sqrt(run_blocks.var(axis=0, ddof=1) / runs + ref_block_se**2), mean_blocks, ref_blocks)
    run_means = images.reshape(runs, -1, c).mean(axis=1)
    mean, ref_mean = run_means.mean(axis=0), ref.reshape(-1, c).mean(axis=0)
    image_se = _rounding_floor(np.sqrt(run_means.var(axis=0, ddof=1) / runs + ref_se**2), mean, ref_mean)
    if not skew_corrected:
        blocks = z_test(mean_blocks - ref_blocks, block_se, 0.0, k=k)
        image = z_test(mean - ref_mean, image_se, 0.0, k=k)
    else:  # the floored standard error enters as the reference's share, so that V is at least its square
        def floored(se: np.ndarray, run_var_of_mean: np.ndarray) -> np.ndarray:
            return np.sqrt(np.maximum(se**2 - run_var_of_mean, 0.0))

        blocks = _z_result(skew_corrected_z(run_blocks, ref_blocks, floored(block_se, run_blocks.var(axis=0, ddof=1) / runs)), k)
        image = _z_result(skew_corrected_z(run_means, ref_mean, floored(image_se, run_means.var(axis=0, ddof=1) / runs)), k)
    return ReuseTestResult(image=image, blocks=blocks, runs=runs)


def _rounding_floor(se: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """A standard error no smaller than float32 rounding of the two values being compared.

    Where both estimates are noiseless (e.g. a constant environment seen directly), rounding is
    the only difference (a renderer summing n equal float32 samples is off by up to ~n·2⁻²⁴ of
    the value; Mitsuba's film at 2048 spp by ~1e-5): differences below 1e-4 of the value are
    below the resolution of these tests, and a zero standard error must not make them infinite z.
    """
    return np.maximum(se, 1e-4 * np.maximum(np.abs(x), np.abs(y)))


def _independent_pixel_errors(variance: np.ndarray, block: int) -> tuple[np.ndarray, np.ndarray]:
    """Standard errors of every block mean and of the image mean of an image whose pixels are independent.

    ``variance`` is the per-pixel variance of the pixel estimates; a mean over n pixels has
    variance Σ var / n² = mean(var) / n.
    """
    h, w, c = variance.shape
    rows, cols = -(-h // block), -(-w // block)
    n_block = np.asarray([[min(block, h - i * block) * min(block, w - j * block) for j in range(cols)]
                          for i in range(rows)], dtype=np.float64)[..., None]  # pixels per block
    return np.sqrt(block_means(variance, block) / n_block), np.sqrt(variance.reshape(-1, c).sum(axis=0)) / (h * w)


def image_agreement_test(
    image: np.ndarray,
    variance: np.ndarray,
    reference: np.ndarray,
    reference_variance: np.ndarray,
    *,
    block: int = 8,
    k: float = DEFAULT_K,
    family: int | None = None,
) -> ReuseTestResult:
    """Do two independent estimates of one image agree — e.g. grisx's path tracer and Mitsuba 3's?

    Both images must have *independent pixels* (a path tracer's, not a reuse renderer's);
    ``variance`` and ``reference_variance`` are the per-pixel variances of the two estimates
    (e.g. the spread over independent runs divided by their number). The image mean and every
    ``block``×``block`` block mean are z-tested per channel. ``family`` is the number of z-values
    sharing one verdict (a whole suite of scenes: every case's blocks + 1, times channels);
    the threshold is ``sidak_threshold(k, family)``, by default over this image's own count.
    The standard error has a floor of 1e-4 of the value (:func:`_rounding_floor`).
    """
    a, va, b, vb = (np.asarray(x, dtype=np.float64) for x in (image, variance, reference, reference_variance))
    if a.ndim != 3 or not (a.shape == va.shape == b.shape == vb.shape):
        raise InvalidParameterError(f"image_agreement_test needs four (H, W, C) arrays of one shape, got {a.shape}, {va.shape}, {b.shape}, {vb.shape}")
    c = a.shape[-1]
    (se_a_blocks, se_a), (se_b_blocks, se_b) = _independent_pixel_errors(va, block), _independent_pixel_errors(vb, block)
    n_values = se_a_blocks.size + c
    threshold = sidak_threshold(k, family if family is not None else n_values)

    def check(x: np.ndarray, y: np.ndarray, se_x: np.ndarray, se_y: np.ndarray) -> ZTestResult:
        return z_test(x - y, _rounding_floor(np.hypot(se_x, se_y), x, y), 0.0, k=threshold, sidak=False)

    blocks = check(block_means(a, block), block_means(b, block), se_a_blocks, se_b_blocks)
    mean = check(a.reshape(-1, c).mean(axis=0), b.reshape(-1, c).mean(axis=0), se_a, se_b)
    return ReuseTestResult(image=mean, blocks=blocks, runs=0)


# ---- Mitsuba 3's render-test criterion --------------------------------------------------------

#: Mitsuba's render tests: samples per scene, spread evenly over the pixels
MITSUBA_SAMPLE_BUDGET = 2_000_000
#: Mitsuba's render tests: family-wise significance level of one scene's pixel tests
MITSUBA_SIGNIFICANCE = 0.01
#: Mitsuba's render tests: the floor under the reference's per-pixel variance
MITSUBA_VARIANCE_FLOOR = 1e-4
#: Mitsuba's render tests: the fraction of pixels (channels counted, divided by 3) that must pass
MITSUBA_PASS_FRACTION = 0.9975


def mitsuba_render_test_spp(width: int, height: int) -> int:
    """Samples per pixel of Mitsuba's render tests for a ``width``×``height`` film: ⌊2·10⁶ / pixels⌋."""
    if width < 1 or height < 1:
        raise InvalidParameterError(f"film size must be positive, got {width}x{height}")
    return MITSUBA_SAMPLE_BUDGET // (width * height)


@dataclasses.dataclass(frozen=True)
class MitsubaRenderTestResult:
    """Outcome of :func:`mitsuba_render_test`: per-value p-values (XYZ), the Šidák level, the pass fraction."""

    p_value: np.ndarray
    alpha: float
    pass_fraction: float
    passed: bool

    @property
    def min_p_value(self) -> float:
        return float(np.min(self.p_value))

    def __str__(self) -> str:
        verdict = "pass" if self.passed else "FAIL"
        return (f"{verdict}: {100.0 * self.pass_fraction:.2f}% of pixels pass (need {100.0 * MITSUBA_PASS_FRACTION:.2f}%), "
                f"min p = {self.min_p_value:.3g}, level {self.alpha:.3g}")


def mitsuba_render_test(
    image: np.ndarray,
    spp: int,
    reference: np.ndarray,
    reference_variance: np.ndarray,
) -> MitsubaRenderTestResult:
    """Mitsuba 3's render-test verdict on an ``image`` rendered at ``spp`` samples per pixel.

    ``image``, ``reference`` and ``reference_variance`` are (H, W, 3) linear sRGB, as
    mitsuba-data stores its ``*_ref_rgb.exr`` and ``*_ref_rgb_var.exr`` (the variance is the
    per-pixel variance of *one sample*, so the image's variance is it divided by ``spp``).
    As Mitsuba's ``test_render`` does, all three are converted to CIE XYZ with Mitsuba's
    ``srgb_to_xyz`` matrix (the variance image too, linearly, as its Bitmap conversion does),
    the variance is floored at 1e-4, and per pixel and channel

        z = |image − reference| · √(spp / variance),   p = 2 (1 − Φ(z)),

    is compared with the Šidák level α = 1 − (1 − 0.01)^(1/pixels); the scene passes when
    (number of values with p > α) / 3 ≥ 0.9975 · pixels. ``spp`` is the image's sample count
    (Mitsuba renders :func:`mitsuba_render_test_spp` samples). p-values are computed in float64
    (Mitsuba computes them in float32, which rounds p below ~6e-8 to 0: the verdict can
    differ only for a value within a hair of the level).
    """
    from grisx.scene.spectrum import SRGB_TO_XYZ

    img, ref, var = (np.asarray(a, dtype=np.float64) for a in (image, reference, reference_variance))
    if img.ndim != 3 or img.shape[-1] != 3 or not (img.shape == ref.shape == var.shape):
        raise InvalidParameterError(f"mitsuba_render_test needs three (H, W, 3) RGB arrays of one shape, got {img.shape}, {ref.shape}, {var.shape}")
    if spp < 1:
        raise InvalidParameterError(f"spp must be >= 1, got {spp}")
    for name, a in (("image", img), ("reference", ref), ("reference_variance", var)):
        if not np.all(np.isfinite(a)):
            raise InvalidValueError(f"{name} contains NaN or Inf")
    img, ref, var = (a @ SRGB_TO_XYZ.T for a in (img, ref, var))
    z = np.abs(img - ref) * np.sqrt(spp / np.maximum(var, MITSUBA_VARIANCE_FLOOR))
    p_value = 2.0 * scipy.stats.norm.sf(z)
    pixels = img.shape[0] * img.shape[1]
    alpha = sidak_alpha(MITSUBA_SIGNIFICANCE, pixels)
    fraction = np.count_nonzero(p_value > alpha) / 3 / pixels
    return MitsubaRenderTestResult(p_value=p_value, alpha=alpha, pass_fraction=float(fraction),
                                   passed=bool(fraction >= MITSUBA_PASS_FRACTION))
