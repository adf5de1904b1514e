"""Soak: every screen-space reuse renderer for 1,000 frames (CPU, 8×8; the CUDA version runs 10,000 frames).

Reservoirs carry float32 weight sums and confidences across frames; a renderer that drifts, or that
produces a NaN/Inf after frame 500, is caught here: no sample may be dropped as non-finite, and under
the static camera the image mean of 10 batches of 100 frames must agree with the path tracer
(t-test of the batch means: frames inside a batch are correlated, batches of 100 nearly not). Under the
camera path only finiteness is checked (the reference moves).
"""

from __future__ import annotations

import numpy as np
import pytest

from grisx.render.driver import METHODS, RenderContext, load_scene, method_params
from grisx.render.pt import PathTracer
from grisx.testing import DEFAULT_K, z_test
from session_cache import committed

#: methods that keep nothing from frame to frame: their soak is 1,000 independent frames, nothing to drift (slow tier)
STATELESS = {"mmis-gather": "each frame traces its own prefixes and suffixes; no reservoir outlives a frame"}
REUSE = [pytest.param(n, marks=pytest.mark.slow) if n in STATELESS else n
         for n in sorted(n for n, m in METHODS.items() if m.kind == "radiance" and not m.uses_spp)]
RES = (8, 8)
FRAMES, BATCH = 1000, 100


def _renderer(method: str, built, seed: int):
    params = {**method_params(method, {}), "spp": 1}
    if "max_depth" in params:
        params["max_depth"] = 16
    return METHODS[method].create(RenderContext(built, *RES, params, seed, None, method))


def _reference(depth: int) -> tuple[np.ndarray, np.ndarray]:
    """The path tracer's image mean on the soak's cornell-box and its standard error (4096 spp; once per session and depth)."""

    def render() -> tuple[np.ndarray, np.ndarray]:
        pt = PathTracer(load_scene("cornell-box").build("cpu"), *RES, spp=4096, max_depth=depth, seed=1)
        pt.add_samples(0, 4096)
        return pt.mean().reshape(-1, 3).mean(axis=0), np.sqrt(pt.variance_of_mean().reshape(-1, 3).sum(axis=0)) / (RES[0] * RES[1])

    return committed(("test_soak.reference", "cornell-box", depth, RES, 4096, 1), load_scene("cornell-box"), render)


@pytest.mark.parametrize("method", REUSE)
def test_a_thousand_static_frames_stay_finite_and_unbiased(method):
    built = load_scene("cornell-box").build("cpu")
    r = _renderer(method, built, seed=77)
    means = np.empty((FRAMES // BATCH, 3))
    acc = np.zeros(3)
    for f in range(FRAMES):
        built.set_frame(float(f))
        acc += r.render_frame(f).numpy().reshape(-1, 3).mean(axis=0)
        if (f + 1) % BATCH == 0:
            means[f // BATCH] = acc / BATCH
            acc[:] = 0.0
    assert r.nonfinite_samples == 0
    ref, ref_se = _reference(METHODS[method].reference_max_depth or 16)
    se = means.std(axis=0, ddof=1) / np.sqrt(len(means))
    result = z_test(means.mean(axis=0) - ref, np.sqrt(se**2 + ref_se**2), 0.0, k=DEFAULT_K)
    assert result.passed, result


@pytest.mark.parametrize("method", REUSE)
def test_a_thousand_frames_along_the_camera_path_stay_finite(method):
    built = load_scene("glossy-room").build("cpu")
    built.animate_camera = True
    r = _renderer(method, built, seed=78)
    for f in range(FRAMES):
        built.set_frame(float(f))
        image = r.render_frame(f)
    assert r.nonfinite_samples == 0
    assert np.all(np.isfinite(image.numpy()))
