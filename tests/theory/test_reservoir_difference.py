"""reservoir_difference: ReSTCV's difference estimator from two reservoirs' samples (seed 002, Eq. 10 with Eq. 11's weights).

Ladder: hand-computed values against a float64 transcription of Eq. 10–11 for
each weight mode, failed shifts and empty reservoirs → properties: it matches
the oracle on random inputs, swapping the pixels (α = 1) negates it, and zero
confidences, UCWs or targets never give NaN. The chromatic-cv toy's
statistical tests cover its unbiasedness.
"""

import numpy as np
import warp as wp
from hypothesis import given, settings
from hypothesis import strategies as st

from grisx.theory.control_variate import DIFFERENCE_MIS, reservoir_difference
from grisx.theory.gris import LUMINANCE_WEIGHTS
from grisx.theory.reservoir import reservoir_empty

wp.set_module_options({"enable_backward": False})

LUM = np.asarray(LUMINANCE_WEIGHTS, dtype=np.float64)


@wp.kernel
def _difference_kernel(
    mode: int,
    s: wp.array2d(dtype=float),  # M_i, W_i, M_j, W_j, |J_{i→j}|, |J_{j→i}|
    c: wp.array2d(dtype=wp.vec3),  # f_i(y_i), f_j(T y_i), f_j(y_j), f_i(T y_j), α
    out: wp.array2d(dtype=wp.vec3),
):
    t = wp.tid()
    r_i = reservoir_empty()
    r_i.confidence = s[t, 0]
    r_i.ucw = s[t, 1]
    r_j = reservoir_empty()
    r_j.confidence = s[t, 2]
    r_j.ucw = s[t, 3]
    out[t, 0] = reservoir_difference(r_i, r_j, c[t, 0], c[t, 1], c[t, 2], c[t, 3], s[t, 4], s[t, 5], c[t, 4], mode)
    # the same two samples seen from pixel j: ⟨F_j − α F_i⟩ with the roles swapped
    out[t, 1] = reservoir_difference(r_j, r_i, c[t, 2], c[t, 3], c[t, 0], c[t, 1], s[t, 5], s[t, 4], c[t, 4], mode)


def _run(mode, scalars, colours):
    s = np.asarray(scalars, dtype=np.float32).reshape(-1, 6)
    c = np.asarray(colours, dtype=np.float32).reshape(-1, 5, 3)
    out = wp.zeros((len(s), 2), dtype=wp.vec3, device="cpu")
    wp.launch(_difference_kernel, dim=len(s), inputs=[DIFFERENCE_MIS[mode], wp.array(s, dtype=float, device="cpu"), wp.array(c, dtype=wp.vec3, device="cpu"), out], device="cpu")
    return out.numpy().astype(np.float64)


def _oracle(mode, scalars, colours):
    """Eq. 10 with Eq. 11's ω (confidence), unit M (balance, Eq. 5's form) or ω = 1 (none), in float64."""
    s = np.asarray(scalars, dtype=np.float32).astype(np.float64).reshape(-1, 6)
    c = np.asarray(colours, dtype=np.float32).astype(np.float64).reshape(-1, 5, 3)
    out = np.zeros((len(s), 3))
    for n, ((m_i, w_i, m_j, w_j, j_ij, j_ji), (f_i_yi, f_j_yi, f_j_yj, f_i_yj, alpha)) in enumerate(zip(s, c)):
        if mode == "balance":
            m_i = m_j = 1.0
        lum = [max(float(v @ LUM), 0.0) for v in (f_i_yi, f_j_yi, f_j_yj, f_i_yj)]
        a, b = m_i * lum[0], m_j * lum[1] * j_ij
        w_ij = a / (a + b) if a + b > 0 else 0.0
        a, b = m_j * lum[2], m_i * lum[3] * j_ji
        w_ji = a / (a + b) if a + b > 0 else 0.0
        if mode == "none":
            w_ij = w_ji = 1.0
        d_i = f_i_yi - alpha * f_j_yi * j_ij
        d_j = alpha * f_j_yj - f_i_yj * j_ji
        out[n] = max(w_ij * w_i, 0.0) * d_i - max(w_ji * w_j, 0.0) * d_j
    return out


# ---- exact values on hand-computed cases ---------------------------------------------------

GREY = [1.0, 1.0, 1.0]  # luminance 1 (the Rec. 709 weights sum to 1)


def test_hand_computed_confidence_weights():
    # M_i = 2, M_j = 1, grey values: p̂_i(y_i) = 3, p̂_j(T y_i) = 4, |J_ij| = 0.5 → ω_ij = 6 / (6 + 2) = 0.75;
    # p̂_j(y_j) = 1, p̂_i(T y_j) = 1, |J_ji| = 1 → ω_ji = 1 / (1 + 2) = 1/3
    s = [2.0, 0.5, 1.0, 3.0, 0.5, 1.0]
    c = [[3.0] * 3, [4.0] * 3, GREY, GREY, [1.0, 0.5, 2.0]]
    expected = 0.75 * 0.5 * (np.full(3, 3.0) - np.array([1.0, 0.5, 2.0]) * 4.0 * 0.5) - (1 / 3) * 3.0 * (np.array([1.0, 0.5, 2.0]) - 1.0)
    np.testing.assert_allclose(_run("confidence", [s], [c])[0, 0], expected, rtol=1e-6)
    np.testing.assert_allclose(_run("confidence", [s], [c])[0, 0], _oracle("confidence", [s], [c])[0], rtol=1e-6)
    # unit confidences: ω_ij = 3 / (3 + 2) = 0.6, ω_ji = 1/2
    exp_bal = 0.6 * 0.5 * (np.full(3, 3.0) - np.array([1.0, 0.5, 2.0]) * 2.0) - 0.5 * 3.0 * (np.array([1.0, 0.5, 2.0]) - 1.0)
    np.testing.assert_allclose(_run("balance", [s], [c])[0, 0], exp_bal, rtol=1e-6)
    # no MIS (the known-biased ablation): ω = 1 on both sides
    exp_none = 0.5 * (np.full(3, 3.0) - np.array([1.0, 0.5, 2.0]) * 2.0) - 3.0 * (np.array([1.0, 0.5, 2.0]) - 1.0)
    np.testing.assert_allclose(_run("none", [s], [c])[0, 0], exp_none, rtol=1e-6)


def test_failed_shifts_and_empty_reservoirs():
    # |J| = 0 (failed shift): the other pixel cannot produce the sample, ω = 1, and its shifted term vanishes
    s = [1.0, 2.0, 1.0, 0.0, 0.0, 0.0]
    c = [[2.0] * 3, [5.0] * 3, GREY, GREY, GREY]
    np.testing.assert_allclose(_run("confidence", [s], [c])[0, 0], [4.0, 4.0, 4.0], rtol=1e-6)  # 1 · 2 · f_i; W_j = 0 adds nothing
    # everything zero: 0, never NaN
    z = _run("confidence", [[0.0] * 6], [[[0.0] * 3] * 5])
    assert np.all(z == 0.0)


# ---- properties ----------------------------------------------------------------------------

colour = st.tuples(*[st.one_of(st.just(0.0), st.floats(1e-3, 1e2))] * 3)
scalars = st.tuples(st.floats(0.0, 20.0), st.floats(0.0, 10.0), st.floats(0.0, 20.0), st.floats(0.0, 10.0), st.floats(0.0, 5.0), st.floats(0.0, 5.0))


@settings(deadline=None, max_examples=60)
@given(st.lists(st.tuples(scalars, st.tuples(colour, colour, colour, colour)), min_size=1, max_size=8), st.sampled_from(sorted(DIFFERENCE_MIS)))
def test_matches_eq10_and_is_antisymmetric_with_unit_alpha(rows, mode):
    s = np.array([r[0] for r in rows])
    c = np.concatenate([np.array([r[1] for r in rows]), np.ones((len(rows), 1, 3))], axis=1)
    out = _run(mode, s, c)
    assert np.all(np.isfinite(out))
    scale = 1.0 + np.abs(_oracle(mode, s, c)).max()
    np.testing.assert_allclose(out[:, 0], _oracle(mode, s, c), rtol=1e-4, atol=1e-5 * scale)
    # ⟨F_j − F_i⟩ from the same two samples is −⟨F_i − F_j⟩
    np.testing.assert_allclose(out[:, 1], -out[:, 0], rtol=1e-5, atol=1e-6 * scale)
