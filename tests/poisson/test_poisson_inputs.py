"""Bad input at the boundary of grisx.poisson: each raises a grisx error naming the argument."""

from __future__ import annotations

import re

import numpy as np
import pytest
import warp as wp
from numpy.testing import assert_allclose

from grisx.device import cuda_available
from grisx.errors import DeviceError, GrisxError, InvalidParameterError, InvalidValueError, UnknownNameError
from grisx.poisson import reconstruct


def _arrays(shape=(4, 5, 3), seed=0):
    rng = np.random.default_rng(seed)
    return [rng.random(shape).astype(np.float32) for _ in range(3)]


@pytest.mark.parametrize("which", [0, 1, 2])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize("kind", ["numpy", "warp"])
@pytest.mark.parametrize("solver", ["dct", "cg", "irls"])
def test_nonfinite_input_names_argument_and_count(which, bad, kind, solver):
    arrays = _arrays()
    arrays[which][0, 0, 1] = bad
    arrays[which][1, 2, 0] = bad
    arrays[which][1, 2, 2] = bad  # same pixel as the previous line: 2 pixels in all
    if kind == "warp":
        arrays = [wp.array(a, dtype=wp.float32, device="cpu") for a in arrays]
    name = ("primal", "dx", "dy")[which]
    norm = "L1" if solver == "irls" else "L2"
    with pytest.raises(InvalidValueError, match=rf"^{name} contains NaN/Inf at 2 pixels$"):
        reconstruct(*arrays, norm=norm, solver=solver)


@pytest.mark.parametrize("kind", ["numpy", "warp"])
@pytest.mark.parametrize("solver", ["dct", "cg", "irls"])
def test_ignored_last_column_and_row_may_hold_anything(kind, solver):
    primal, dx, dy = _arrays()
    norm = "L1" if solver == "irls" else "L2"
    want = reconstruct(primal, dx, dy, norm=norm, solver=solver)
    dx[:, -1] = np.nan
    dy[-1, :] = np.inf
    if kind == "warp":
        primal, dx, dy = (wp.array(a, dtype=wp.float32, device="cpu") for a in (primal, dx, dy))
    got = reconstruct(primal, dx, dy, norm=norm, solver=solver)
    got = got.numpy() if kind == "warp" else got
    assert_allclose(got, want, rtol=0, atol=0)  # the ignored entries are never read


def test_check_finite_can_be_turned_off():
    primal, dx, dy = _arrays()
    primal[0, 0, 0] = np.nan
    out = reconstruct(primal, dx, dy, check_finite=False)
    assert np.isnan(out).any()  # garbage in, garbage out, but no exception


@pytest.mark.parametrize("which,shape", [(1, (4, 4, 3)), (2, (4, 5)), (1, (5, 5, 3)), (2, (4, 5, 4))])
def test_mismatched_shapes_name_the_argument(which, shape):
    arrays = _arrays()
    arrays[which] = np.zeros(shape, dtype=np.float32)
    name = ("primal", "dx", "dy")[which]
    with pytest.raises(InvalidParameterError, match="^" + re.escape(f"{name} has shape {shape}")):
        reconstruct(*arrays)


@pytest.mark.parametrize("bad,msg", [
    (np.zeros((0, 4)), "primal is empty"),
    (np.zeros(5), r"primal must have shape \(H, W\) or \(H, W, C\)"),
    (np.zeros((2, 2, 2, 2)), r"primal must have shape"),
    (np.zeros((3, 3), dtype=complex), "primal must hold real numbers"),
    (np.array([["a", "b"]]), "primal must hold real numbers"),
])
def test_malformed_primal(bad, msg):
    with pytest.raises(InvalidParameterError, match=msg):
        reconstruct(bad, np.zeros((3, 3)), np.zeros((3, 3)))


def test_malformed_warp_arrays():
    good = np.zeros((3, 3), dtype=np.float32)
    with pytest.raises(InvalidParameterError, match="dx must be a float32 Warp array"):
        reconstruct(good, wp.zeros((3, 3), dtype=wp.float64, device="cpu"), good)
    with pytest.raises(InvalidParameterError, match="dy must be a float32 Warp array"):
        reconstruct(good, good, wp.zeros(9, dtype=wp.float32, device="cpu"))


@pytest.mark.parametrize("alpha", [0.0, -0.2, np.nan, np.inf, "x"])
def test_alpha_must_be_positive(alpha):
    with pytest.raises(InvalidParameterError, match="alpha"):
        reconstruct(*_arrays(), alpha=alpha)


def test_unknown_names():
    arrays = _arrays()
    with pytest.raises(UnknownNameError, match="unknown norm 'L3'"):
        reconstruct(*arrays, norm="L3")
    with pytest.raises(UnknownNameError, match="unknown Poisson solver 'fft'"):
        reconstruct(*arrays, solver="fft")
    with pytest.raises(InvalidParameterError, match="solver 'dct' does not solve norm L1"):
        reconstruct(*arrays, norm="L1", solver="dct")
    with pytest.raises(InvalidParameterError, match="solver 'irls' does not solve norm L2"):
        reconstruct(*arrays, norm="L2", solver="irls")
    with pytest.raises(DeviceError, match="unknown device 'tpu'"):
        reconstruct(*arrays, device="tpu")
    with pytest.raises(UnknownNameError, match="initial guess"):
        reconstruct(*arrays, solver="cg", initial="noise")
    with pytest.raises(InvalidParameterError, match="tol"):
        reconstruct(*arrays, solver="cg", tol=-1.0)
    with pytest.raises(InvalidParameterError, match="tol must be a number"):
        reconstruct(*arrays, solver="cg", tol="small")
    with pytest.raises(InvalidParameterError, match="max_iter"):
        reconstruct(*arrays, solver="cg", max_iter=2.5)


def test_lowercase_norm_is_accepted():
    arrays = _arrays()
    assert_allclose(reconstruct(*arrays, norm="l2"), reconstruct(*arrays, norm="L2"), rtol=0, atol=0)


@pytest.mark.skipif(cuda_available(), reason="checks the error on a machine without CUDA")
def test_cuda_without_gpu_is_a_device_error():
    with pytest.raises(DeviceError, match="cuda"):
        reconstruct(*_arrays(), device="cuda")


@pytest.mark.cuda
def test_warp_array_on_other_device_is_refused():
    if not cuda_available():
        pytest.skip("needs CUDA: Warp found no CUDA device on this machine")
    arrays = [wp.array(a, device="cuda") for a in _arrays()]
    with pytest.raises(InvalidParameterError, match="primal lives on device 'cuda:0' but device='cpu'"):
        reconstruct(*arrays, device="cpu")
    with pytest.raises(InvalidParameterError, match="dct.*CPU only"):
        reconstruct(*arrays, solver="dct")


def test_all_errors_are_grisx_errors():
    # the CLI relies on catching GrisxError only
    for cls in (InvalidParameterError, InvalidValueError, UnknownNameError, DeviceError):
        assert issubclass(cls, GrisxError)
