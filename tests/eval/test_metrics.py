"""Image metrics: hand-computed values, FLIP against the flip-evaluator package, bias and efficiency, bad input."""

from __future__ import annotations

import math

import flip_evaluator
import numpy as np
import pytest
from numpy.testing import assert_allclose

from grisx.errors import InvalidParameterError, InvalidValueError, UnknownNameError
from grisx.eval import metrics as M

EPS = 1e-2


# ---- exact values on hand-computed images ------------------------------------------------------
def test_constants_state_epsilon():
    assert M.RELMSE_EPSILON == EPS


def test_mse_rmse_relmse_mape_on_a_2x2_image():
    test = np.array([[1.0, 2.0], [3.0, 4.0]])
    ref = np.ones((2, 2))
    # differences 0, 1, 2, 3; ref² + ε = 1.01 everywhere
    assert M.mse(test, ref) == pytest.approx(14 / 4)
    assert M.rmse(test, ref) == pytest.approx(math.sqrt(14 / 4))
    assert M.relmse(test, ref) == pytest.approx(14 / 4 / 1.01)
    assert M.mape(test, ref) == pytest.approx(6 / 4 / 1.01)


def test_reference_is_the_denominator_and_epsilon_guards_black_pixels():
    test = np.array([[0.1, 2.0]])
    ref = np.array([[0.0, 2.0]])
    assert M.relmse(test, ref) == pytest.approx((0.01 / (0 + EPS) + 0) / 2)  # = 0.5
    assert M.mape(test, ref) == pytest.approx((0.1 / (0 + EPS) + 0) / 2)  # = 5
    # swapping test and reference changes relMSE: the reference is the second argument
    assert M.relmse(ref, test) == pytest.approx((0.01 / (0.01 + EPS)) / 2)
    assert M.relmse(test, ref, epsilon=1.0) == pytest.approx(0.01 / 2)


def test_per_channel_variants():
    ref = np.array([[[1.0, 2.0, 0.0], [1.0, 2.0, 0.0]]])  # 1x2 RGB
    test = np.array([[[2.0, 2.0, 0.0], [1.0, 0.0, 0.5]]])
    assert_allclose(M.mse(test, ref, per_channel=True), [0.5, 2.0, 0.125])
    assert_allclose(M.rmse(test, ref, per_channel=True), np.sqrt([0.5, 2.0, 0.125]))
    assert_allclose(M.relmse(test, ref, per_channel=True), [1 / 1.01 / 2, 4 / 4.01 / 2, 0.25 / 0.01 / 2])
    assert_allclose(M.mape(test, ref, per_channel=True), [1 / 1.01 / 2, 2 / 2.01 / 2, 0.5 / 0.01 / 2])
    # the all-channel value is the mean of the per-channel ones (equal pixel counts)
    assert M.mse(test, ref) == pytest.approx(np.mean([0.5, 2.0, 0.125]))


def test_chroma_is_colour_noise_alone():
    # seed 002, Fig. 2: a yellow plane seen as red or green pixels has colour noise; a grey one of any error has none
    yellow = np.full((2, 2, 3), [0.5, 0.5, 0.0])
    red_green = np.array([[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]])
    y = yellow @ M.LUMINANCE
    c_ref = yellow - y[..., None]
    c_test = red_green - (red_green @ M.LUMINANCE)[..., None]
    assert M.chroma(red_green, yellow) == pytest.approx(float(np.mean((c_test - c_ref) ** 2 / (y[..., None] ** 2 + EPS))))
    assert M.chroma(red_green, yellow) > 1.0
    assert M.chroma(np.full((2, 2, 3), 3.0), np.ones((2, 2, 3))) == 0.0  # brightness error only
    assert M.relmse(np.full((2, 2, 3), 3.0), np.ones((2, 2, 3))) > 1.0
    with pytest.raises(InvalidParameterError, match="chroma needs"):
        M.chroma(np.ones((2, 2)), np.ones((2, 2)))


def test_identical_images_have_zero_error():
    img = np.random.default_rng(1).random((9, 7, 3))
    for name in M.METRICS:
        assert M.compare(img, img, [name])[name] == pytest.approx(0.0, abs=1e-7), name


def test_to_srgb_matches_the_standard_curve():
    x = np.array([0.0, 0.0031308, 0.5, 1.0, 2.0, -1.0])
    assert_allclose(M.to_srgb(x), [0.0, 0.04045, 1.055 * 0.5 ** (1 / 2.4) - 0.055, 1.0, 1.0, 0.0], atol=2e-6)
    assert_allclose(M.to_srgb(np.array([0.25]), exposure=1.0), M.to_srgb(np.array([0.5])))


# ---- FLIP: the package is the oracle -----------------------------------------------------------
@pytest.fixture
def pair():
    rng = np.random.default_rng(7)
    ref = (rng.random((24, 32, 3)) * 3.0).astype(np.float32)  # HDR values up to 3
    test = np.clip(ref + 0.3 * rng.standard_normal(ref.shape), 0, None).astype(np.float32)
    return test, ref


def test_hdr_flip_equals_the_package_value(pair):
    test, ref = pair
    _, oracle, _ = flip_evaluator.evaluate(ref, test, "HDR")
    value, error_map = M.flip(test, ref, return_map=True)
    assert value == pytest.approx(float(oracle), rel=1e-6)
    assert error_map.shape == ref.shape[:2]
    assert error_map.mean() == pytest.approx(value, rel=1e-4)
    assert 0.0 < value < 1.0


def test_ldr_flip_equals_the_package_value_on_srgb_images(pair):
    test, ref = pair

    def srgb(x):  # independent sRGB encoding for the oracle
        x = np.clip(x.astype(np.float64) * 0.5, 0, 1)  # exposure −1 stop
        return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055).astype(np.float32)

    _, oracle, _ = flip_evaluator.evaluate(srgb(ref), srgb(test), "LDR")
    assert M.flip_ldr(test, ref, exposure=-1.0) == pytest.approx(float(oracle), rel=1e-6)


def test_flip_on_grey_images_repeats_the_channel(pair):
    test, ref = pair
    g_test, g_ref = test[..., 0], ref[..., 0]
    rgb = lambda a: np.repeat(a[..., None], 3, axis=2)  # noqa: E731
    _, oracle, _ = flip_evaluator.evaluate(rgb(g_ref), rgb(g_test), "HDR")
    assert M.flip(g_test, g_ref) == pytest.approx(float(oracle), rel=1e-6)


# ---- compare() and names -------------------------------------------------------------------------
def test_compare_returns_keys_named_after_the_metrics(pair):
    test, ref = pair
    out = M.compare(test, ref, "mse, RelMSE,flip-ldr", per_channel=True)
    assert list(out) == ["mse", "mse_per_channel", "relmse", "relmse_per_channel", "flip_ldr"]
    assert out["mse"] == pytest.approx(M.mse(test, ref))
    assert out["relmse_per_channel"] == pytest.approx(list(M.relmse(test, ref, per_channel=True)))


def test_unknown_metric_is_named():
    with pytest.raises(UnknownNameError, match="metric 'psnr'"):
        M.parse_metrics("mse,psnr")
    with pytest.raises(InvalidParameterError, match="no metric"):
        M.parse_metrics(" , ")


# ---- bad input -------------------------------------------------------------------------------------
def test_shape_mismatch_names_both_images():
    with pytest.raises(InvalidValueError, match=r"test image has shape \(2, 3\) but reference image has shape \(3, 2\)"):
        M.mse(np.zeros((2, 3)), np.zeros((3, 2)))


@pytest.mark.parametrize("which", ["test", "reference"])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nan_and_inf_are_rejected_naming_the_image(which, bad):
    good = np.ones((4, 5, 3))
    broken = good.copy()
    broken[2, 3, 1] = bad
    args = (broken, good) if which == "test" else (good, broken)
    for fn in (M.mse, M.relmse, M.mape, M.flip):
        with pytest.raises(InvalidValueError, match=rf"^{which} image has 1 NaN/Inf values \(first at pixel y,x = \(2, 3\)\)"):
            fn(*args)


def test_compare_uses_the_given_names():
    with pytest.raises(InvalidValueError, match="render.exr"):
        M.compare(np.full((2, 2), np.nan), np.ones((2, 2)), ["mse"], test_name="render.exr")


@pytest.mark.parametrize("shape", [(5,), (0, 3), (2, 2, 2, 2)])
def test_bad_shapes(shape):
    with pytest.raises(InvalidValueError, match="shape"):
        M.mse(np.zeros(shape), np.zeros(shape))


def test_bad_epsilon():
    with pytest.raises(InvalidParameterError, match="epsilon"):
        M.relmse(np.ones((2, 2)), np.ones((2, 2)), epsilon=0.0)


# ---- bias by accumulation ------------------------------------------------------------------------
def test_bias_estimate_by_hand():
    ref = np.ones((2, 3))
    est = M.bias_estimate([ref + 1.0, ref + 3.0], ref)
    assert est.bias == pytest.approx(2.0)
    assert est.stderr == pytest.approx(1.0)  # std([1, 3], ddof=1) / √2
    assert est.z == pytest.approx(2.0)
    assert est.relative_bias == pytest.approx(2.0)
    assert_allclose(est.bias_map, 2.0)
    assert est.to_dict()["runs"] == 2


def test_bias_estimate_separates_unbiased_from_biased_runs():
    rng = np.random.default_rng(20261121)
    ref = 0.2 + rng.random((8, 8, 3))
    noisy = lambda offset: np.stack([ref + offset + 0.3 * rng.standard_normal(ref.shape) for _ in range(64)])  # noqa: E731
    unbiased = M.bias_estimate(noisy(0.0), ref)
    # offset 0.04 is 0.13 σ of one pixel, but ≈ 15 stderr of the image mean (0.3 / √192 / √64 ≈ 0.0027)
    biased = M.bias_estimate(noisy(0.04), ref)
    assert abs(unbiased.z) < 4
    assert biased.z > 6
    assert np.all(np.abs(unbiased.per_channel / unbiased.per_channel_stderr) < 4)


def test_bias_estimate_needs_two_runs():
    with pytest.raises(InvalidParameterError, match="at least 2"):
        M.bias_estimate([np.ones((2, 2))], np.ones((2, 2)))
    with pytest.raises(InvalidValueError, match="run 1 image has shape"):
        M.bias_estimate([np.ones((2, 2)), np.ones((3, 2))], np.ones((2, 2)))


# ---- efficiency ----------------------------------------------------------------------------------------
def test_efficiency():
    assert M.efficiency(0.5, 2.0) == pytest.approx(1.0)
    assert M.efficiency(0.0, 1.0) == math.inf
    with pytest.raises(InvalidValueError, match="positive time"):
        M.efficiency(0.1, 0.0)
    with pytest.raises(InvalidValueError, match="non-negative error"):
        M.efficiency(float("nan"), 1.0)
