"""float64 oracles for the accumulations that grow without bound.

* a reservoir streaming 10⁵ candidates (``reservoir_update``'s float32 weight sum and confidence)
  against the float64 sum of the same weights — the bound a float32 running sum can keep, n·2⁻²⁴;
* the frame driver's ``--accumulate`` (float64 on the device) against the float64 mean of the
  same frames rendered one by one;
* the path tracer's progressive sums are float64 since a float32 sum drifted by −1.8e-4 at
  20,000 spp (``tests/render/test_hostile.py::test_pt_is_unbiased_beside_a_10e16_brighter_light``);
* Poisson residuals: ``tests/poisson`` checks them against a dense float64 solve.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from grisx.render import render
from grisx.theory.random import random_key, random_uniform
from grisx.theory.reservoir import Reservoir, reservoir_empty, reservoir_update


@wp.kernel
def _stream(weights: wp.array(dtype=float), out: wp.array(dtype=Reservoir)):
    r = reservoir_empty()
    key = random_key(3, 0)
    for i in range(weights.shape[0]):
        r = reservoir_update(r, weights[i], 1.0, 1.0, random_uniform(key, i))
    out[0] = r


def test_a_reservoir_streaming_1e5_candidates_keeps_its_weight_sum():
    rng = np.random.default_rng(0)
    w = (10.0 ** rng.uniform(-6, 6, 100_000)).astype(np.float32)  # twelve decades of weights
    out = wp.empty(1, dtype=Reservoir, device="cpu")
    wp.launch(_stream, dim=1, inputs=[wp.array(w, dtype=float, device="cpu")], outputs=[out], device="cpu")
    r = out.numpy()[0]
    exact = w.astype(np.float64).sum()
    assert abs(r["w_sum"] / exact - 1.0) < len(w) * 2.0**-24  # a float32 running sum's worst case
    assert r["confidence"] == len(w)  # integers up to 2²⁴ are exact in float32


def test_accumulated_frames_are_their_float64_mean():
    frames = []
    render("cornell-box", "pt", spp=1, frames=200, res=(8, 6), seed=4, camera="static",
           on_frame=lambda i, img, s: frames.append(np.asarray(img, dtype=np.float64)))
    acc = render("cornell-box", "pt", spp=1, frames=200, res=(8, 6), seed=4, accumulate=True).image
    mean = np.mean(frames, axis=0)
    np.testing.assert_allclose(acc, mean, rtol=2e-7, atol=1e-9)
    # sibling: a float32 running sum of the same frames is off by ~1e-6 and fails the same check
    running = np.zeros_like(frames[0], dtype=np.float32)
    for f in frames:
        running = (running + f.astype(np.float32)).astype(np.float32)
    assert not np.allclose(running / np.float32(len(frames)), mean, rtol=2e-7, atol=1e-9)
