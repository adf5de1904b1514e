"""The bounded-Jacobian rule (grisx.theory.shift.jacobian_bounded): hand-computed cases and its symmetry."""

from __future__ import annotations

import numpy as np
import warp as wp
from hypothesis import given
from hypothesis import strategies as st

from grisx.theory.shift import JACOBIAN_BOUND_ONE_SIDED, JACOBIAN_BOUND_SYMMETRIC, jacobian_bounded


@wp.kernel
def _bounded(j: wp.array(dtype=float), bound: float, symmetric: int, out: wp.array(dtype=int)):
    i = wp.tid()
    out[i] = int(jacobian_bounded(j[i], bound, symmetric))


def _eval(js, bound: float, symmetric: int) -> np.ndarray:
    j = wp.array(np.asarray(js, dtype=np.float32), dtype=float, device="cpu")
    out = wp.zeros(len(js), dtype=int, device="cpu")
    wp.launch(_bounded, dim=len(js), inputs=[j, bound, symmetric, out], device="cpu")
    return out.numpy()


def test_hand_computed_cases():
    js = [0.05, 0.1, 0.5, 1.0, 10.0, 10.5, 0.0, np.inf, np.nan]
    np.testing.assert_array_equal(_eval(js, 10.0, int(JACOBIAN_BOUND_SYMMETRIC)), [0, 1, 1, 1, 1, 0, 0, 0, 0])
    np.testing.assert_array_equal(_eval(js, 10.0, int(JACOBIAN_BOUND_ONE_SIDED)), [1, 1, 1, 1, 1, 0, 1, 0, 0])
    # no bound: the symmetric form still refuses a J that is no Jacobian, the one-sided form keeps everything
    np.testing.assert_array_equal(_eval(js, 0.0, int(JACOBIAN_BOUND_SYMMETRIC)), [1, 1, 1, 1, 1, 1, 0, 0, 0])
    np.testing.assert_array_equal(_eval(js, 0.0, int(JACOBIAN_BOUND_ONE_SIDED)), [1] * 9)


@given(st.floats(1e-3, 1e3), st.floats(1.0, 100.0))
def test_symmetric_bound_accepts_j_exactly_when_it_accepts_its_inverse(j, bound):
    # T restricted to the accepted set is a bijection only if T and T⁻¹ (|J⁻¹| = 1/|J|) are kept together
    a, b = _eval([j, 1.0 / j], bound, int(JACOBIAN_BOUND_SYMMETRIC))
    if abs(j - bound) > 1e-4 * bound and abs(1.0 / j - bound) > 1e-4 * bound:  # away from float32 rounding at the edge
        assert a == b
