"""The MIS of a positivized pair merge with reuse across signs, and the pair functions on RGB values.

Ladder: hand-computed inputs, targets and weights (seed 000, Sec. 4.4; seed 001,
Eq. 15–16) → properties: the weights of all inputs at one sample sum to one and
match a float64 numpy oracle of Eq. 15; the generic pair functions give on
``wp.vec3`` what they give per channel on floats. The toys' statistical tests
(``test_gradient.py``) cover the merges that use these weights.
"""

import numpy as np
import pytest
import warp as wp
from hypothesis import given, settings
from hypothesis import strategies as st

from grisx.theory.gradient import (
    SIGN_ABS,
    SIGN_NEG,
    SIGN_POS,
    pair_balance_add,
    pair_balance_empty,
    pair_balance_mis,
    pair_contribution,
    pair_estimate,
    pair_input_sign,
    pair_input_slot,
    pair_slot_sign,
    pair_source_inputs,
    pair_target_from,
    pair_value,
)

wp.set_module_options({"enable_backward": False})


@wp.kernel
def _enumeration_kernel(rows: wp.array2d(dtype=int), out: wp.array2d(dtype=int)):
    i = wp.tid()
    a = rows[i, 0]
    b = rows[i, 1]
    c = rows[i, 2]
    out[i, 0] = pair_source_inputs(a, b, c)
    out[i, 1] = pair_input_sign(a, b)
    out[i, 2] = pair_input_slot(b, c)
    out[i, 3] = pair_slot_sign(b, c)


@wp.kernel
def _target_kernel(sign: wp.array(dtype=int), rows: wp.array2d(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = pair_target_from(sign[i], rows[i, 0], rows[i, 1], rows[i, 2] != 0.0)


@wp.kernel
def _weights_kernel(
    sign: int,
    positivize: int,
    cross_sign: int,
    src: wp.array2d(dtype=float),  # per source l: c_same, c_other, ω*G at T*⁻¹(y) in l, |∂T*⁻¹/∂y|, valid
    out: wp.array2d(dtype=float),  # m_{l,e}(y) of every input (l, e); −1 where (l, e) is no input
):
    l, e = wp.tid()
    sources = src.shape[0]
    out[l, e] = -1.0
    if e < pair_source_inputs(l, positivize, cross_sign):
        b = pair_balance_empty()
        for l2 in range(sources):
            own = int(-1)
            if l2 == l:
                own = e
            b = pair_balance_add(
                b, sign, pair_source_inputs(l2, positivize, cross_sign), src[l2, 0], src[l2, 1], src[l2, 2], src[l2, 3], src[l2, 4] != 0.0, own
            )
        out[l, e] = pair_balance_mis(b, src[l, e])


def _ints(rows):
    rows = np.asarray(rows, dtype=np.int32)
    out = wp.zeros((len(rows), 4), dtype=int, device="cpu")
    wp.launch(_enumeration_kernel, dim=len(rows), inputs=[wp.array(rows, dtype=int, device="cpu"), out], device="cpu")
    return out.numpy()


def _targets(signs, rows):
    out = wp.zeros(len(rows), dtype=float, device="cpu")
    wp.launch(
        _target_kernel,
        dim=len(rows),
        inputs=[wp.array(np.asarray(signs, dtype=np.int32), dtype=int, device="cpu"), wp.array(np.asarray(rows, dtype=np.float32), dtype=float, device="cpu"), out],
        device="cpu",
    )
    return out.numpy()


def _weights(sign, src, positivize=1, cross_sign=1):
    src = np.asarray(src, dtype=np.float32).reshape(-1, 5)
    out = wp.zeros((len(src), 2), dtype=float, device="cpu")
    wp.launch(_weights_kernel, dim=(len(src), 2), inputs=[sign, positivize, cross_sign, wp.array(src, dtype=float, device="cpu"), out], device="cpu")
    return out.numpy()


def _oracle(sign, src, positivize=1, cross_sign=1):
    """Eq. 15 over the inputs (l, e), in float64: target of input (l, e) is max(s_e v_l, 0)·J_l (seed 000, Eq. 25–26)."""
    src = np.asarray(src, dtype=np.float32).astype(np.float64).reshape(-1, 5)
    terms = np.full((len(src), 2), np.nan)
    for l, (c_same, c_other, v, jac, valid) in enumerate(src):
        inputs = 2 if positivize and cross_sign and l != 0 else 1
        for e in range(inputs):
            s = sign if e == 0 else -sign
            target = (max(s * v, 0.0) if s != 0 else abs(v)) * abs(jac) if valid else 0.0
            terms[l, e] = (c_same, c_other)[e] * target
    total = np.nansum(terms)
    return np.where(np.isnan(terms), -1.0, terms / total if total > 0 else 0.0)


# ---- exact values on hand-computed cases ---------------------------------------------------


def test_inputs_signs_and_slots_by_hand():
    r = _ints([[0, 1, 1], [1, 1, 1], [2, 0, 1], [3, 1, 0]])
    assert list(r[:, 0]) == [1, 2, 1, 1]  # the own source (0) and runs without cross-sign or positivization read one reservoir
    r = _ints([[1, 0, 0], [1, 1, 0], [-1, 1, 1], [0, 1, 1]])
    assert list(r[:, 1]) == [1, -1, 1, 0]  # s_0 = s, s_1 = −s; |ω*G| (sign 0) has no other sign
    assert list(r[:, 2]) == [0, 1, 0, 0]  # input 1 reads the other slot
    # (positivize, slot) → sign: unpositivized one |ω*G| reservoir; slot 0 pos, slot 1 neg
    assert list(r[:, 3]) == [SIGN_ABS, SIGN_POS, SIGN_NEG, SIGN_NEG]


def test_carried_targets_by_hand():
    # p̂^s_{←l}(y) = max(s·ω*G, 0)·|J| (Eq. 16, 25–26); |ω*G|·|J| for sign 0; 0 where T*⁻¹ fails
    t = _targets([SIGN_POS, SIGN_NEG, SIGN_NEG, SIGN_ABS, SIGN_POS, SIGN_POS], [[2, 0.5, 1], [2, 0.5, 1], [-2, 3, 1], [-2, 3, 1], [5, 2, 0], [2, -0.5, 1]])
    np.testing.assert_allclose(t, [1.0, 0.0, 6.0, 6.0, 0.0, 1.0], rtol=1e-6)


def test_cross_sign_weights_by_hand():
    # merge into pos (s = +1): source 0 (own, one input): c = 2, ω*G = 3, J = 1 → term 6;
    # source 1 (two inputs): c₊ = 1, c₋ = 4, ω*G = −0.5, J = 2 → p̂₊ term 0, p̂₋ term 4·0.5·2 = 4; Σ = 10
    src = [[2, 9, 3, 1, 1], [1, 4, -0.5, 2, 1]]
    m = _weights(SIGN_POS, src)
    np.testing.assert_allclose(m, [[0.6, -1.0], [0.0, 0.4]], rtol=1e-6)
    # without reuse across signs source 1 reads only its pos reservoir, whose target is 0 at y
    np.testing.assert_allclose(_weights(SIGN_POS, src, cross_sign=0), [[1.0, -1.0], [0.0, -1.0]], rtol=1e-6)
    # a failed inverse shift drops the source; nothing covering y gives 0, never NaN
    np.testing.assert_allclose(_weights(SIGN_NEG, [[2, 9, -3, 1, 1], [1, 4, -0.5, 2, 0]]), [[1.0, -1.0], [0.0, 0.0]], rtol=1e-6)
    z = _weights(SIGN_POS, [[0, 0, 0, 0, 1], [0, 0, 0, 0, 1], [1, 1, 0, 1, 0]])
    assert np.all(np.isfinite(z)) and np.all(z[z >= 0] == 0.0)


# ---- properties ----------------------------------------------------------------------------

source = st.tuples(
    st.floats(0.0, 20.0),  # c_same
    st.floats(0.0, 20.0),  # c_other
    st.one_of(st.just(0.0), st.floats(-1e3, 1e3)),  # ω*G at T*⁻¹(y)
    st.floats(0.0, 50.0),  # |J|
    st.sampled_from([0.0, 1.0]),  # valid
)


@settings(deadline=None, max_examples=80)
@given(st.lists(source, min_size=1, max_size=6), st.sampled_from([SIGN_POS, SIGN_NEG]), st.booleans())
def test_weights_of_all_inputs_sum_to_one_and_match_eq15(src, sign, cross_sign):
    m = _weights(sign, src, cross_sign=int(cross_sign))
    expected = _oracle(sign, src, cross_sign=int(cross_sign))
    assert np.all(np.isfinite(m))
    np.testing.assert_allclose(m, expected, rtol=1e-5, atol=1e-6)
    used = m[expected >= 0]
    assert np.all((used >= 0) & (used <= 1 + 1e-6))
    total = used.sum()
    assert total == pytest.approx(1.0, abs=1e-5) or total == 0.0


# ---- the pair functions on RGB values ------------------------------------------------------


@wp.kernel
def _rgb_kernel(
    k: int,
    f: wp.array2d(dtype=wp.vec3),  # f_base, f_offset
    s: wp.array2d(dtype=float),  # pdf_base, pdf_offset, |J|, valid, W
    out3: wp.array2d(dtype=wp.vec3),
    out1: wp.array3d(dtype=float),
):
    i = wp.tid()
    v = s[i, 3] != 0.0
    out3[i, 0] = pair_contribution(k, f[i, 0], f[i, 1], s[i, 2], v)
    out3[i, 1] = pair_value(k, f[i, 0], f[i, 1], s[i, 0], s[i, 1], s[i, 2], v)
    out3[i, 2] = pair_estimate(out3[i, 1], s[i, 4])
    for c in range(3):
        out1[i, c, 0] = pair_contribution(k, f[i, 0][c], f[i, 1][c], s[i, 2], v)
        out1[i, c, 1] = pair_value(k, f[i, 0][c], f[i, 1][c], s[i, 0], s[i, 1], s[i, 2], v)
        out1[i, c, 2] = pair_estimate(out1[i, c, 1], s[i, 4])


def _rgb(k, f, s):
    f = np.asarray(f, dtype=np.float32).reshape(-1, 2, 3)
    s = np.asarray(s, dtype=np.float32).reshape(-1, 5)
    out3 = wp.zeros((len(f), 3), dtype=wp.vec3, device="cpu")
    out1 = wp.zeros((len(f), 3, 3), dtype=float, device="cpu")
    wp.launch(_rgb_kernel, dim=len(f), inputs=[k, wp.array(f, dtype=wp.vec3, device="cpu"), wp.array(s, dtype=float, device="cpu"), out3, out1], device="cpu")
    return out3.numpy(), out1.numpy().transpose(0, 2, 1)  # both (n, function, channel)


def test_rgb_pair_value_by_hand():
    # ω = 1/(1 + 3·(1/3)) = 1/2, G = f_i − f_j∘T·|J| per channel (seed 000, Eq. 4, 15), ⟨Δ⟩ = ω G W (Eq. 17)
    rgb, _ = _rgb(0, [[[3, 0, 6], [3, 3, 0]]], [[1, 3, 1 / 3, 1, 2]])
    np.testing.assert_allclose(rgb[0, 0], [2, -1, 6], rtol=1e-6)
    np.testing.assert_allclose(rgb[0, 1], [1, -0.5, 3], rtol=1e-6)
    np.testing.assert_allclose(rgb[0, 2], [2, -1, 6], rtol=1e-6)
    rgb, _ = _rgb(1, [[[3, 0, 6], [3, 3, 0]]], [[1, 3, 1 / 3, 0, 2]])
    np.testing.assert_allclose(rgb[0, 0], [-3, 0, -6], rtol=1e-6)  # k = 1, failed shift: −f_base, ω = 1


@settings(deadline=None, max_examples=40)
@given(
    st.lists(st.tuples(*[st.floats(0.0, 1e3)] * 6, st.floats(0.0, 1e3), st.floats(0.0, 1e3), st.floats(0.0, 10.0), st.sampled_from([0.0, 1.0]), st.floats(0.0, 10.0)), min_size=1, max_size=8),
    st.sampled_from([0, 1]),
)
def test_rgb_is_the_scalar_functions_per_channel(rows, k):
    rows = np.asarray(rows, dtype=np.float32)
    rgb, per_channel = _rgb(k, rows[:, :6], rows[:, 6:])
    np.testing.assert_array_equal(rgb, per_channel)
