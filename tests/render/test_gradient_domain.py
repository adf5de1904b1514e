"""Gradient-domain renderers (seed 000) against the reference path tracer (CPU, 12×10 images, independent runs).

Every method's *primal* image and the *gradient* images dx, dy of ``gpt`` (B.2) and
``gradient-after-restir`` (B.1) are tested over independent runs (each its own seed and history)
with :func:`grisx.testing.reuse_unbiasedness_test`, per image and per 8×8 block, k = 4: the primal
against ``pt``'s image, dx and dy against the forward differences of ``pt``'s image. The reference's
standard errors for the differences are taken as if dx[x] = I[x+1] − I[x] were independent across x,
an upper bound (a block mean of differences telescopes: each pixel enters with coefficients that
sum to at most one in magnitude), so the check errs on the side of passing. Scenes: the Cornell box
and the closed bright room at max_depth 8 with Russian roulette from depth 5. A known-biased
sibling — the inner shift without its Jacobian (``jacobian=false``) — fails the same check.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from grisx.render.driver import METHODS, RenderContext, load_scene, method_params, render
from grisx.render.pt import PathTracer
from grisx.scene.builtin import BUILTIN_SCENES
from grisx.testing import BIASED_K, DEFAULT_K, reuse_unbiasedness_test

RES = (12, 10)
GRADIENT_METHODS = ("gpt", "gradient-after-restir")
_REFERENCES: dict[Any, tuple[np.ndarray, np.ndarray]] = {}
_RUNS: dict[Any, list[dict[str, np.ndarray]]] = {}


def _reference(scene: str, depth: int, spp: int = 4096) -> tuple[np.ndarray, np.ndarray]:
    key = (scene, depth, spp)
    if key not in _REFERENCES:
        built = load_scene(scene).build("cpu")
        pt = PathTracer(built, *RES, spp=spp, max_depth=depth, seed=987654)
        pt.add_samples(0, spp)
        _REFERENCES[key] = pt.mean().astype(np.float64), pt.variance_of_mean().astype(np.float64)
    return _REFERENCES[key]


def _differences(ref: np.ndarray, var: np.ndarray) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """dx, dy of the reference (forward differences, the last column / row left out) and an upper bound of their variance."""
    return {
        "dx": (ref[:, 1:] - ref[:, :-1], var[:, 1:] + var[:, :-1]),
        "dy": (ref[1:] - ref[:-1], var[1:] + var[:-1]),
    }


def _runs(method: str, params: dict[str, Any], scene: str, frames: int, runs: int, spp: int = 1) -> list[dict[str, np.ndarray]]:
    """``runs`` independent runs: the frame-averaged primal, dx, dy and final image of each (static camera)."""
    key = (method, tuple(sorted(params.items())), scene, frames, runs, spp)
    if key in _RUNS:
        return _RUNS[key]
    built = load_scene(scene).build("cpu")
    resolved = {**method_params(method, params), "spp": spp}
    out = []
    for r in range(runs):
        renderer = METHODS[method].create(RenderContext(built, *RES, dict(resolved), 1000 + r, None, method))
        sums: dict[str, np.ndarray] = {}
        for f in range(frames):
            built.set_frame(float(f))
            image = renderer.render_frame(f).numpy().astype(np.float64)
            parts = {"image": image, **{k: v.astype(np.float64) for k, v in (renderer.extra() if hasattr(renderer, "extra") else {}).items()}}
            for k, v in parts.items():
                sums[k] = sums.get(k, 0.0) + v / frames
        assert renderer.nonfinite_samples == 0
        sums["dx"] = sums["dx"][:, :-1] if "dx" in sums else None
        sums["dy"] = sums["dy"][:-1] if "dy" in sums else None
        out.append(sums)
    _RUNS[key] = out
    return out


def _check(method: str, params: dict[str, Any], scene: str, which: str, *, frames: int, runs: int, spp: int = 1, k: float = DEFAULT_K):
    depth = int(params.get("max_depth", 16))
    ref, var = _reference(scene, depth)
    refs = {"image": (ref, var), "primal": (ref, var), **_differences(ref, var)}
    data = _runs(method, {"max_depth": depth, **params}, scene, frames, runs, spp)
    expected, expected_var = refs[which]
    return reuse_unbiasedness_test(lambda seed: data[seed - 1000][which], expected, expected_var, runs, block=8, k=k, seed0=1000)


CASES = [("cornell-box", {"max_depth": 16}), ("closed-room", {"max_depth": 8, "rr_depth": 5})]
CASE_IDS = ["cornell", "closed-room-depth8-rr"]


@pytest.mark.parametrize("scene,params", CASES, ids=CASE_IDS)
@pytest.mark.parametrize("method", ["gpt", "gradient-after-restir", "area-restir"])
def test_primal_is_unbiased(method, scene, params):
    which = "image" if method == "area-restir" else "primal"
    result = _check(method, params, scene, which, frames=4, runs=24)
    print(method, scene, which, "image z", result.image.z, "blocks max |z|", np.max(np.abs(result.blocks.z)))
    assert result.passed, result


@pytest.mark.parametrize("scene,params", CASES, ids=CASE_IDS)
@pytest.mark.parametrize("method", GRADIENT_METHODS)
@pytest.mark.parametrize("which", ["dx", "dy"])
def test_gradients_are_unbiased(method, scene, params, which):
    result = _check(method, params, scene, which, frames=4, runs=24)
    print(method, scene, which, "image z", result.image.z, "blocks max |z|", np.max(np.abs(result.blocks.z)))
    assert result.passed, result


@pytest.mark.parametrize("method", GRADIENT_METHODS)
def test_inner_shift_without_jacobian_is_caught(method):
    params = {"max_depth": 16, "jacobian": False}
    z = []
    for which in ("dx", "dy"):
        result = _check(method, params, "cornell-box", which, frames=4, runs=24, k=BIASED_K)
        z.append(float(np.max(np.abs(result.blocks.z))))
        print(method, which, "no jacobian: image z", result.image.z, "blocks max |z|", z[-1])
    assert max(z) > BIASED_K


@pytest.mark.parametrize("method", ["gpt", "gradient-after-restir", "area-restir"])
def test_every_builtin_scene_renders_finite(method):
    for scene in sorted(BUILTIN_SCENES):
        result = render(scene, method, res=(8, 6), frames=2, params={"max_depth": 6})
        assert np.all(np.isfinite(result.image)), scene
        assert result.settings["nonfinite_samples"] == 0, scene
        for name, img in result.extra.items():
            assert np.all(np.isfinite(img)), (scene, name)
