"""reservoir_retarget and reservoir_drop: the two ways a renderer changes a reservoir's kept sample after the fact."""

from __future__ import annotations

import numpy as np
import warp as wp

from grisx.theory.reservoir import Reservoir, reservoir_drop, reservoir_empty, reservoir_finalize, reservoir_retarget, reservoir_update


@wp.kernel
def _ops(target: float, out: wp.array(dtype=Reservoir)):
    r = reservoir_empty()
    r = reservoir_update(r, 2.0, 4.0, 1.0, 0.5)  # w = 2, p̂ = 4, c = 1
    r = reservoir_update(r, 6.0, 3.0, 2.0, 0.0)  # kept (u = 0): w_sum = 8, p̂ = 3, c = 3
    out[0] = reservoir_finalize(r)
    out[1] = reservoir_finalize(reservoir_retarget(r, target))
    out[2] = reservoir_finalize(reservoir_drop(r))
    out[3] = reservoir_finalize(reservoir_retarget(r, 0.0))


def test_retarget_and_drop_by_hand():
    out = wp.zeros(4, dtype=Reservoir, device="cpu")
    wp.launch(_ops, dim=1, inputs=[2.0, out], device="cpu")
    r = out.numpy()
    np.testing.assert_allclose([r["ucw"][0], r["ucw"][1]], [8.0 / 3.0, 8.0 / 2.0])  # W = w_sum / p̂ with the new p̂
    assert r["confidence"][1] == 3.0 and r["w_sum"][1] == 8.0
    for dropped in (r[2], r[3]):  # no weight, no sample, the confidence kept
        assert dropped["ucw"] == 0.0 and dropped["w_sum"] == 0.0 and dropped["target"] == 0.0 and dropped["confidence"] == 3.0
