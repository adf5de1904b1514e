"""two_domain_balance: the one two-domain balance weight (gradients, control-variate differences, temporal reuse)."""

from __future__ import annotations

import numpy as np
import warp as wp
from hypothesis import given
from hypothesis import strategies as st

from grisx.theory.mis import two_domain_balance


@wp.kernel
def _weights(rows: wp.array2d(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = two_domain_balance(rows[i, 0], rows[i, 1], rows[i, 2], rows[i, 3])


def _eval(rows) -> np.ndarray:
    out = wp.zeros(len(rows), dtype=float, device="cpu")
    wp.launch(_weights, dim=len(rows), inputs=[wp.array(np.asarray(rows, dtype=np.float32), dtype=float, device="cpu"), out], device="cpu")
    return out.numpy()


def test_hand_computed():
    # 2·3 / (2·3 + 1·2); b cannot produce the sample: 1; a has no target: 0; negative targets count as 0; all zero: 0
    np.testing.assert_allclose(_eval([[2, 3, 1, 2], [1, 5, 4, 0], [1, 0, 1, 3], [1, 2, 1, -4], [0, 0, 0, 0]]), [0.75, 1.0, 0.0, 1.0, 0.0], rtol=1e-6)


@given(st.floats(0.1, 10), st.floats(1e-3, 1e3), st.floats(0.1, 10), st.floats(1e-3, 1e3))
def test_the_two_weights_of_a_sample_sum_to_one(c_a, t_a, c_b, t_b):
    m_a, m_b = _eval([[c_a, t_a, c_b, t_b], [c_b, t_b, c_a, t_a]])
    assert abs(m_a + m_b - 1.0) < 1e-5 and np.isfinite(m_a)
