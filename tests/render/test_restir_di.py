"""ReSTIR DI against the path tracer's direct light (CPU, tiny films, fixed seeds).

Reuse correlates pixels, so nothing here is tested per pixel: each check runs
R *independent* renders (different seeds, history reset), accumulates F frames
of a static camera in each, and compares the mean over runs of the image mean
with ``pt`` at ``max_depth=2`` (emitted + direct light) at the pixel centres
(``jitter=False``, what the G-buffer sees), the reference's own standard error
included: a z-test (``grisx.testing.z_test``, k = 4, Šidák over channels).
Every unbiased configuration has a sibling that is known to be biased
(``unbiased=false``: unshadowed targets at neighbours) and must fail the same
check beyond 6σ.
"""

from __future__ import annotations

import numpy as np
import pytest

from reuse_checks import builtin_image_mean

from grisx.errors import InvalidParameterError, UnknownNameError
from grisx.scene.builtin import BUILTIN_SCENES, build_builtin
from grisx.render.pt import PathTracer
from grisx.render.driver import render
from grisx.render.restir_di import ReSTIRDI
from grisx.testing import BIASED_K, DEFAULT_K, independent_runs, z_test

# a non-square film: the Cornell box's concave edges do not run through pixel centres
W, H = 12, 9


@pytest.fixture
def cornell(device):
    return build_builtin("cornell-box").build(device)


def _reference(built, max_depth: int = 2, spp: int = 4096, jitter: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Image mean of the path tracer (pixel centres, or box-filtered with ``jitter``) and its standard error."""
    return builtin_image_mean(built, (W, H), max_depth, spp, jitter, seed=99)


def _runs(renderer, runs: int, frames: int) -> tuple[np.ndarray, np.ndarray]:
    """Mean over independent runs (history reset, new seed) of the F-frame accumulated image's mean."""

    def one_run(seed: int) -> np.ndarray:
        renderer.reset(seed=seed)
        return np.mean([renderer.render_frame(f).numpy().reshape(-1, 3).mean(axis=0) for f in range(frames)], axis=0)

    est = independent_runs(one_run, runs)
    assert renderer.nonfinite_samples == 0
    return est


def _z(built, runs: int, frames: int, k: float, jitter: bool = False, **params):
    ref, ref_se = _reference(built, jitter=jitter)
    est, se = _runs(ReSTIRDI(built, W, H, jitter=jitter, **params), runs, frames)
    return z_test(est, np.sqrt(se**2 + ref_se**2), ref, k=k)


# ---- convergence of the unbiased variants ------------------------------------------------


@pytest.mark.parametrize(
    "params",
    [
        {},
        {"temporal": False},
        {"spatial": False},
        {"light_candidates": 4, "bsdf_candidates": 2},
        {"light_candidates": 0, "bsdf_candidates": 1},  # BSDF sampling alone
        {"jitter": True},  # box-filtered pixels (the renderer's default) against the jittered path tracer
    ],
    ids=["default", "spatial-only", "temporal-only", "4+2-candidates", "bsdf-only", "jittered"],
)
def test_unbiased_restir_di_converges_to_direct_light(cornell, params):
    result = _z(cornell, 64, 6, DEFAULT_K, **params)
    assert result.passed, result


def test_many_lights_converge(device):
    built = build_builtin("many-lights").build(device)
    result = _z(built, 48, 6, DEFAULT_K)
    assert result.passed, result


def test_biased_mode_is_caught(cornell):
    # unshadowed targets at the neighbours claim MIS weight for samples they cannot see: darker near shadows
    result = _z(cornell, 64, 6, BIASED_K, unbiased=False)
    assert not result.passed, result


# ---- robustness, determinism, CLI -----------------------------------------------------------


@pytest.mark.parametrize("scene", sorted(BUILTIN_SCENES))
def test_no_nan_over_a_moving_camera(scene, device):
    r = render(scene, "restir-di", frames=50, res=(12, 9), camera="path", device=device, seed=5)
    assert r.settings["nonfinite_samples"] == 0
    assert np.all(np.isfinite(r.image)) and np.all(r.image >= 0)


def test_same_seed_same_image(cornell):
    a = ReSTIRDI(cornell, W, H, seed=3)
    b = ReSTIRDI(cornell, W, H, seed=3)
    c = ReSTIRDI(cornell, W, H, seed=4)
    for f in range(3):
        ia, ib, ic = (x.render_frame(f).numpy() for x in (a, b, c))
    np.testing.assert_array_equal(ia, ib)
    assert not np.array_equal(ia, ic)


def test_no_candidates_leaves_emission_only(cornell):
    r = ReSTIRDI(cornell, W, H, light_candidates=0, bsdf_candidates=0)
    img = r.render_frame(0).numpy()
    pt = PathTracer(cornell, W, H, max_depth=1, jitter=False)
    pt.add_samples(0, 1)
    np.testing.assert_allclose(img, pt.mean(), rtol=1e-6, atol=1e-7)


def test_cli_params_are_checked():
    with pytest.raises(UnknownNameError):
        render("cornell-box", "restir-di", res=(4, 4), params={"candidates": 3})
    with pytest.raises(InvalidParameterError):
        render("cornell-box", "restir-di", res=(4, 4), params={"light_candidates": -1})
    r = render("cornell-box", "restir-di", res=(8, 6), frames=2, accumulate=True, params={"unbiased": "false"})
    assert {"di_initial", "di_temporal", "di_spatial", "di_shade"} <= set(r.pass_seconds)
