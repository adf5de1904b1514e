"""technique_mis: the NEE/BSDF power heuristic with its delta cases (one copy, for pt and path reuse)."""

from __future__ import annotations

import numpy as np
import warp as wp
from hypothesis import given
from hypothesis import strategies as st

from grisx.theory.mis import technique_mis


@wp.kernel
def _mis(args: wp.array(dtype=wp.vec4), light_delta: wp.array(dtype=int), out: wp.array(dtype=float)):
    i = wp.tid()
    a = args[i]  # end_nee, bsdf_delta, light_pdf, bsdf_pdf
    out[i] = technique_mis(int(a[0]), light_delta[i], int(a[1]), a[2], a[3])


def _eval(rows, light_delta) -> np.ndarray:
    args = wp.array(np.asarray(rows, dtype=np.float32), dtype=wp.vec4, device="cpu")
    ld = wp.array(np.asarray(light_delta, dtype=np.int32), dtype=int, device="cpu")
    out = wp.zeros(len(rows), dtype=float, device="cpu")
    wp.launch(_mis, dim=len(rows), inputs=[args, ld, out], device="cpu")
    return out.numpy()


def test_hand_computed():
    rows = [(1, 0, 2.0, 1.0), (0, 0, 2.0, 1.0), (1, 0, 3.0, 5.0), (1, 0, 2.0, 1.0), (0, 1, 2.0, 1.0)]
    got = _eval(rows, [0, 0, 0, 1, 0])
    np.testing.assert_allclose(got, [4 / 5, 1 / 5, 9 / 34, 1.0, 1.0], rtol=1e-6)  # power heuristic; deltas have no rival


@given(st.floats(1e-3, 1e3), st.floats(1e-3, 1e3))
def test_the_two_techniques_sum_to_one(light_pdf, bsdf_pdf):
    nee, bsdf = _eval([(1, 0, light_pdf, bsdf_pdf), (0, 0, light_pdf, bsdf_pdf)], [0, 0])
    assert abs(nee + bsdf - 1.0) < 1e-5
