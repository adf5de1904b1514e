"""grisx.testing: the checks themselves, on cases with known answers."""

import numpy as np
import pytest
import scipy.stats

from grisx.errors import InvalidValueError
from grisx.scene.spectrum import SRGB_TO_XYZ
from grisx.testing import BIASED_K, chi2_test, image_agreement_test, mitsuba_render_test, mitsuba_render_test_spp, sidak_alpha, sidak_threshold, skew_corrected_z, z_test


def test_z_test_hand_computed():
    r = z_test(1.3, 0.1, 1.0)
    np.testing.assert_allclose(r.z, [3.0])
    assert r.passed and r.threshold == 4.0
    assert not z_test(1.5, 0.1, 1.0).passed


def test_zero_stderr_passes_only_exact_matches():
    assert z_test(2.0, 0.0, 2.0).passed
    assert not z_test(2.0, 0.0, 2.1).passed


def test_sidak_numbers():
    # 1 − (1 − 0.05)^(1/10) = 0.0051162...
    np.testing.assert_allclose(sidak_alpha(0.05, 10), 0.00511619, rtol=1e-5)
    assert sidak_threshold(4.0, 1) == pytest.approx(4.0)
    assert 4.0 < sidak_threshold(4.0, 100) < 5.5
    r = z_test(np.zeros(100) + 4.2, np.ones(100), np.zeros(100))
    assert r.passed and r.threshold > 4.2  # 4.2σ is no surprise among 100 values


def test_z_test_rejects_nan():
    with pytest.raises(InvalidValueError, match="estimate"):
        z_test(np.nan, 1.0, 0.0)


def test_z_test_false_alarm_rate_is_as_designed():
    # 20 000 draws of a correct estimator: 4σ false alarms ≈ 20000 · 6.3e-5 ≈ 1.3
    rng = np.random.default_rng(0)
    z = rng.standard_normal(20_000)
    alarms = sum(not z_test(v, 1.0, 0.0).passed for v in z[:20_000])
    assert alarms <= 6


def test_chi2_accepts_the_right_pdf_and_rejects_a_wrong_one():
    rng = np.random.default_rng(1)
    x = rng.beta(2.0, 5.0, 100_000)
    right = chi2_test(x, lambda t: scipy.stats.beta.pdf(t, 2.0, 5.0), 0.0, 1.0)
    wrong = chi2_test(x, lambda t: scipy.stats.beta.pdf(t, 2.1, 5.0), 0.0, 1.0)
    assert right.passed, right
    assert not wrong.passed, wrong


def test_chi2_fails_on_samples_where_the_pdf_is_zero():
    x = np.concatenate([np.full(10, 1.5), np.random.default_rng(2).uniform(0, 1, 1000)])
    assert not chi2_test(x, lambda t: np.ones_like(t), 0.0, 1.0).passed


def test_reuse_test_catches_opposite_biases_that_cancel_in_the_image_mean():
    from grisx.testing import block_means, reuse_unbiasedness_test

    ref, var = np.ones((16, 20, 3)), np.full((16, 20, 3), 1e-4)

    def noisy(seed: int, bias: float = 0.0) -> np.ndarray:
        im = ref + np.random.default_rng(seed).normal(0.0, 0.1, ref.shape)
        im[:, :10] += bias  # left half too bright, right half too dark: the image mean is exact
        im[:, 10:] -= bias
        return im

    fair = reuse_unbiasedness_test(noisy, ref, var, 50)
    assert fair.passed and fair.blocks.z.shape == (2, 3, 3)
    biased = reuse_unbiasedness_test(lambda s: noisy(s, 0.02), ref, var, 50)
    assert biased.image.passed and not biased.blocks.passed
    np.testing.assert_allclose(block_means(np.arange(12.0).reshape(2, 6, 1), 4)[..., 0], [[4.5, 7.5]])


def test_image_agreement_test_passes_equal_means_and_catches_a_shift():
    rng = np.random.default_rng(3)
    truth = rng.uniform(0.1, 1.0, (24, 32, 3))
    var = np.full_like(truth, 1e-4)
    a = truth + rng.normal(0, 1e-2, truth.shape)
    b = truth + rng.normal(0, 1e-2, truth.shape)
    assert image_agreement_test(a, var, b, var).passed
    shifted = image_agreement_test(a * 1.01, var, b, var)  # 1% too bright: z ≈ 0.01·0.55·√768/0.014 ≈ 11
    assert not shifted.passed and shifted.image.max_abs_z > 6
    # noiseless and equal up to float32 rounding: passes; a real difference: fails
    flat = np.full((8, 8, 3), 0.6)
    zero = np.zeros_like(flat)
    assert image_agreement_test(flat, zero, flat * (1 + 1e-6), zero).passed
    assert not image_agreement_test(flat, zero, flat * 1.001, zero).passed
    # a larger family raises the threshold (Šidák)
    assert image_agreement_test(a, var, b, var, family=10_000).image.threshold > image_agreement_test(a, var, b, var).image.threshold


def test_mitsuba_render_test_is_mitsubas_criterion():
    """test_renders.py: spp = ⌊2e6 / pixels⌋, XYZ, variance floored at 1e-4, Šidák at 1%, ≥ 99.75% of pixels pass."""
    assert mitsuba_render_test_spp(48, 48) == 868 and mitsuba_render_test_spp(200, 120) == 83
    rng = np.random.default_rng(5)
    h, w, spp = 48, 48, 868
    ref = rng.uniform(0.1, 1.0, (h, w, 3))
    var = rng.uniform(0.01, 0.5, (h, w, 3))  # per-sample variance, as mitsuba-data stores it
    xyz_sd = np.sqrt(var @ SRGB_TO_XYZ.T / spp)  # Mitsuba converts the variance image linearly, as a colour

    def image(noise_sd):
        return ref + (rng.standard_normal(ref.shape) * noise_sd) @ np.linalg.inv(SRGB_TO_XYZ).T  # noise in XYZ

    ok = mitsuba_render_test(image(xyz_sd), spp, ref, var)
    assert ok.passed and ok.pass_fraction > 0.999, ok
    assert ok.alpha == pytest.approx(1 - 0.99 ** (1 / (h * w)), rel=1e-9)
    # the line: 0.25% of 2304 pixels = 5.76 pixels' worth of failing values (each counts 1/3): 17 values pass, 18 fail
    img = image(xyz_sd * 0)
    assert mitsuba_render_test(img, spp, ref, var).pass_fraction == 1.0
    for n, passes in ((17, True), (18, False)):
        offset = np.zeros((h * w, 3))
        offset[:n, 1] = 10.0  # Y of n pixels, far off
        result = mitsuba_render_test(img + (offset @ np.linalg.inv(SRGB_TO_XYZ).T).reshape(h, w, 3), spp, ref, var)
        assert result.passed is passes and result.pass_fraction == pytest.approx(1 - n / 3 / (h * w)), (n, result)
    # noise twice the reference's: many pixels beyond the Šidák level
    assert not mitsuba_render_test(image(2 * xyz_sd), spp, ref, var).passed
    # a zero variance image is floored at 1e-4: a difference of 1e-4 passes at 868 spp (z ≈ 2.9)
    assert mitsuba_render_test(ref + 1e-4, spp, ref, np.zeros_like(ref)).passed


# ---- heavy-tailed runs: the skewness-corrected z --------------------------------------------------


def _lognormal_z(sigma: float, runs: int, reps: int, scale: float = 1.0, seed: int = 12345) -> tuple[np.ndarray, np.ndarray]:
    """Plain and skewness-corrected z of ``reps`` sets of ``runs`` lognormal runs (times ``scale``) against the exact mean."""
    rng = np.random.default_rng(seed)
    mu = np.exp(sigma**2 / 2)
    plain, corrected = [], []
    for _ in range(max(reps // 2000, 1)):
        x = scale * rng.lognormal(0.0, sigma, size=(runs, min(reps, 2000)))
        plain.append((x.mean(axis=0) - mu) / (x.std(axis=0, ddof=1) / np.sqrt(runs)))
        corrected.append(skew_corrected_z(x, mu))
    return np.concatenate(plain), np.concatenate(corrected)


def test_skew_corrected_z_is_the_plain_z_for_symmetric_runs():
    x = np.random.default_rng(3).normal(1.0, 0.1, size=(4096, 64))
    plain = (x.mean(axis=0) - 1.0) / (x.std(axis=0, ddof=1) / 64)
    np.testing.assert_allclose(skew_corrected_z(x, 1.0), plain, atol=0.02)


def test_skew_corrected_z_cuts_the_false_alarms_of_heavy_tailed_runs():
    # lognormal runs of skewness 13 (SMS's per-run image means: 5-20), 1024 runs, 8000 sets, |z| > 3 (nominal 0.27%):
    # the plain z fires 0.95% of the time, all below -3 (sets that missed the tail); the corrected 0.55%
    plain, corrected = _lognormal_z(1.25, 1024, 8000)
    assert np.mean(plain < -3) > 0.008 and np.mean(plain > 3) < 0.001  # the defect: one-sided false alarms
    assert np.mean(np.abs(corrected) > 3) < 0.007
    assert np.mean(np.abs(corrected) > 3) < 0.65 * np.mean(np.abs(plain) > 3)


def test_skew_corrected_z_still_catches_a_biased_sibling():
    # the same kind of runs 20% low, 4096 runs: caught (|z| > 6) in 97% of 200 sets
    _, corrected = _lognormal_z(1.0, 4096, 200, scale=0.8, seed=7)
    assert np.mean(np.abs(corrected) > BIASED_K) > 0.9
