"""The plots' exposure uses theory's one luminance (Rec. 709 weights of grisx.theory.gris), not a second copy."""

import numpy as np
import pytest

from grisx.eval.plots import display_exposure


def test_display_exposure_uses_the_rec709_weights_by_hand():
    # a pure-red image has luminance 0.212671 (Mitsuba's Rec. 709 weight): exposure −log2 of it
    red = np.zeros((4, 4, 3))
    red[..., 0] = 1.0
    assert display_exposure(red) == pytest.approx(-np.log2(0.212671), rel=1e-12)
    # mixed colour: 0.212671·2 + 0.715160·0.5 + 0.072169·4
    img = np.broadcast_to(np.array([2.0, 0.5, 4.0]), (3, 3, 3))
    assert display_exposure(img) == pytest.approx(-np.log2(0.212671 * 2 + 0.715160 * 0.5 + 0.072169 * 4), rel=1e-12)
    # single channel: the values themselves; black: no brightening
    assert display_exposure(np.full((2, 2), 0.25)) == pytest.approx(2.0)
    assert display_exposure(np.zeros((2, 2, 3))) == 0.0
