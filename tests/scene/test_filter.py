"""Mitsuba's gaussian and tent reconstruction filters as camera-sample distributions (grisx.scene.camera).

A pixel of Mitsuba's splatting film converges to ∫ f·L / ∫ f over the film, f the
filter around the pixel centre; grisx draws camera rays from f restricted to the film.
χ² tests of the sampled offsets against f, inside the film and at its border; the
sibling shows that the plain (unshifted) gaussian is told apart from Mitsuba's.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import warp as wp

from grisx.scene.camera import CameraData, film_weight, gaussian_filter_sample, tent_filter_sample
from grisx.testing import chi2_test
from grisx.theory.random import random_key


@wp.kernel
def _offsets(x: int, y: int, width: int, height: int, size: float, tent: int, out: wp.array(dtype=wp.vec2)):
    i = wp.tid()
    if tent != 0:
        p = tent_filter_sample(random_key(13, i), x, y, width, height, size)
    else:
        p = gaussian_filter_sample(random_key(11, i), x, y, width, height, size)
    out[i] = wp.vec2(p[0] - (float(x) + 0.5), p[1] - (float(y) + 0.5))


def offsets(x: int, y: int, stddev: float, n: int = 200_000, size: int = 16, tent: bool = False) -> np.ndarray:
    """Film offsets of pixel (x, y) drawn from the gaussian of ``stddev`` (or, with ``tent``, the tent of that radius)."""
    out = wp.empty(n, dtype=wp.vec2, device="cpu")
    wp.launch(_offsets, dim=n, inputs=[x, y, size, size, stddev, int(tent)], outputs=[out], device="cpu")
    return out.numpy()


def tent_offsets(x: int, y: int, radius: float) -> np.ndarray:
    return offsets(x, y, radius, tent=True)


def mitsuba_filter(stddev: float, lo: float, hi: float, bias: bool = True):
    """Mitsuba's gaussian f(t) = max(0, exp(−t²/2σ²) − exp(−r²/2σ²)), r = 4σ, normalized on [lo, hi]."""
    r = 4 * stddev
    b = math.exp(-r * r / (2 * stddev**2)) if bias else 0.0
    return _normalized(lambda t: np.maximum(np.exp(-np.asarray(t) ** 2 / (2 * stddev**2)) - b, 0.0), lo, hi)


def mitsuba_tent(radius: float, lo: float, hi: float):
    """Mitsuba's tent f(t) = max(0, 1 − |t|/r), normalized on [lo, hi]."""
    return _normalized(lambda t: np.maximum(1.0 - np.abs(np.asarray(t)) / radius, 0.0), lo, hi)


def _normalized(f, lo: float, hi: float):
    """The density f / ∫ f on [lo, hi] (numerically), 0 outside."""
    ts = np.linspace(lo, hi, 20001)
    norm = float(np.sum(f(ts)) * (ts[1] - ts[0]))
    return lambda t: np.where((np.asarray(t) >= lo) & (np.asarray(t) <= hi), f(t) / norm, 0.0)


@pytest.mark.parametrize("stddev", [0.5, 1.0])
def test_interior_pixel_offsets_follow_the_filter(stddev):
    t = offsets(8, 8, stddev)
    r = 4 * stddev
    assert np.all(np.abs(t) <= r + 1e-5)
    for axis in range(2):
        result = chi2_test(t[:, axis], mitsuba_filter(stddev, -r, r), -r, r, bins=48, tests=4)
        assert result.passed, f"axis {axis}: {result}"


def test_border_pixel_offsets_stay_on_the_film():
    t = offsets(0, 15, 1.0)  # left column, bottom row: the film ends 0.5 px away
    assert t[:, 0].min() >= -0.5 - 1e-6 and t[:, 1].max() <= 0.5 + 1e-6
    assert chi2_test(t[:, 0], mitsuba_filter(1.0, -0.5, 4.0), -0.5, 4.0, bins=48, tests=2).passed
    assert chi2_test(t[:, 1], mitsuba_filter(1.0, -4.0, 0.5), -4.0, 0.5, bins=48, tests=2).passed


def test_a_filter_not_cut_at_the_film_border_is_told_apart():
    """Mitsuba's border pixels see only samples from inside the film; the whole filter is a different distribution."""
    t = offsets(0, 8, 1.0)
    assert not chi2_test(t[:, 0], mitsuba_filter(1.0, -4.0, 4.0), -4.0, 4.0, bins=48).passed


@wp.kernel
def _film_weights(cam: CameraData, x: int, y: int, offsets: wp.array(dtype=wp.vec2), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = film_weight(cam, x, y, offsets[i])


@pytest.mark.parametrize(("x", "y", "stddev", "tent"), [(8, 8, 0.5, 0.0), (0, 15, 1.0, 0.0), (8, 8, 0.0, 0.0),
                                                        (8, 8, 0.0, 1.0), (0, 15, 0.0, 1.5)])
def test_film_weight_is_the_filter_normalized_on_the_film(x, y, stddev, tent):
    """ω(u) = |support| · w(u − ½): Mitsuba's filter (gaussian or tent) normalized over its part inside the film (the
    numpy oracles above), so uniform film samples over the support average to the filtered pixel; a box weighs 1
    inside the pixel."""
    size = 16
    cam = CameraData()
    cam.width, cam.height, cam.filter_stddev, cam.filter_tent = size, size, stddev, tent
    r = 4 * stddev if stddev > 0 else (tent if tent > 0 else 0.5)
    g = np.linspace(0.5 - r, 0.5 + r, 41)[:-1] + r / 40  # cell centres of the support
    u = np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2).astype(np.float32)
    out = wp.empty(len(u), dtype=float, device="cpu")
    wp.launch(_film_weights, dim=len(u), inputs=[cam, x, y, wp.array(u, dtype=wp.vec2, device="cpu")], outputs=[out], device="cpu")
    w = out.numpy()
    inside = (x + u[:, 0] >= 0) & (x + u[:, 0] < size) & (y + u[:, 1] >= 0) & (y + u[:, 1] < size)
    assert np.all(w[~inside] == 0.0)
    if stddev == 0 and tent == 0:
        np.testing.assert_array_equal(w, 1.0)
        return
    t = u - 0.5
    density = (lambda lo, hi: mitsuba_filter(stddev, lo, hi)) if stddev > 0 else (lambda lo, hi: mitsuba_tent(tent, lo, hi))
    fx = density(max(-r, -(x + 0.5)), min(r, size - (x + 0.5)))(t[:, 0])
    fy = density(max(-r, -(y + 0.5)), min(r, size - (y + 0.5)))(t[:, 1])
    np.testing.assert_allclose(w[inside], (4 * r * r * fx * fy)[inside], rtol=2e-3, atol=1e-5)


# ---- tent ------------------------------------------------------------------------------------


@pytest.mark.parametrize("radius", [1.0, 1.5])
def test_tent_offsets_follow_the_filter_inside_and_at_the_border(radius):
    t = tent_offsets(8, 8, radius)
    assert np.all(np.abs(t) <= radius + 1e-5)
    for axis in range(2):
        assert chi2_test(t[:, axis], mitsuba_tent(radius, -radius, radius), -radius, radius, bins=48, tests=6).passed
    b = tent_offsets(0, 15, radius)  # left column, bottom row: the film ends 0.5 px away
    assert b[:, 0].min() >= -0.5 - 1e-6 and b[:, 1].max() <= 0.5 + 1e-6
    assert chi2_test(b[:, 0], mitsuba_tent(radius, -0.5, radius), -0.5, radius, bins=48, tests=6).passed
    assert chi2_test(b[:, 1], mitsuba_tent(radius, -radius, 0.5), -radius, 0.5, bins=48, tests=6).passed


def test_a_box_or_a_wider_tent_is_told_apart_from_the_tent():
    t = tent_offsets(8, 8, 1.0)[:, 0]
    assert not chi2_test(t, lambda s: np.where(np.abs(s) <= 0.5, 1.0, 0.0), -0.5, 0.5, bins=48).passed  # the box
    assert not chi2_test(t, mitsuba_tent(1.25, -1.25, 1.25), -1.25, 1.25, bins=48).passed


def test_a_film_has_one_filter():
    from grisx.errors import InvalidParameterError
    from grisx.scene.scene import Film

    with pytest.raises(InvalidParameterError, match="one reconstruction filter"):
        Film(8, 8, filter_stddev=0.5, filter_tent=1.0)
    with pytest.raises(InvalidParameterError, match="filter_tent"):
        Film(8, 8, filter_tent=-1.0)
