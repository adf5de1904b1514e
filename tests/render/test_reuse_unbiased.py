"""Every screen-space reuse renderer, unbiased per 8×8 block, under a static and a moving camera.

The shared check (:mod:`reuse_checks`) renders independent runs and z-tests the image mean and
each block mean against the path tracer (Šidák across blocks and channels): biases of opposite
sign in different regions cancel in the image mean but not in the blocks. The moving-camera
case takes frame 5 of the camera path alone (history reprojected along the way) against the path
tracer at that frame's camera. A renderer added later joins by one entry in ``METHODS``.
"""

from __future__ import annotations

import numpy as np
import pytest
from reuse_checks import check

from grisx.testing import BIASED_K, DEFAULT_K

METHODS = [
    ("restir-di", {}),
    ("restir-gi", {}),
    ("restir-pt", {"shift": "hybrid"}),
    ("restir-pt", {"shift": "reconnection"}),
    ("restir-pt", {"shift": "replay"}),
]
IDS = ["restir-di", "restir-gi", "restir-pt-hybrid", "restir-pt-reconnection", "restir-pt-replay"]


@pytest.mark.parametrize("method,params", METHODS, ids=IDS)
def test_unbiased_per_block_static_camera(method, params):
    result = check(method, params, camera="static", frames=4, runs=64)
    assert result.passed, result


@pytest.mark.parametrize("method,params", METHODS, ids=IDS)
def test_unbiased_per_block_moving_camera(method, params):
    result = check(method, params, camera="moving", frames=6, runs=64)
    assert result.passed, result


def test_per_block_test_catches_what_the_image_mean_misses():
    # ReSTIR DI without visibility in its neighbours' targets (unbiased=false, Bitterli 2020's biased
    # variant) darkens some regions and brightens others: the image mean stays within 1σ, the blocks do not
    result = check("restir-di", {"unbiased": False}, camera="static", frames=4, runs=512, k=BIASED_K)
    assert np.all(np.abs(result.image.z) < DEFAULT_K), result.image
    assert not result.blocks.passed, result.blocks
