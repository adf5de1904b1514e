"""Every render method agrees with Mitsuba 3, not only the path tracer.

``test_conformance.py`` checks that grisx's ``pt`` renders each Mitsuba feature as Mitsuba
does. Users render with the reuse methods, and outside comparisons run them on Mitsuba
scene files too; these tests close the loop without a grisx-made reference in between:
each registered radiance method loads a conformance scene file and its independent runs
(own seeds, history from scratch, frames averaged under the file's fixed camera) are
z-tested per image and per 8×8 block against the image **Mitsuba 3 rendered**
(:func:`grisx.testing.reuse_unbiasedness_test`, the reference's own variance included).

A method estimating the full image renders the features its shifts and reservoirs treat
apart (``FULL_IMAGE_CASES``): depth limits (``max_depth_4_rr_1``: Russian roulette from the
first bounce; ``max_depth_1``: emitters only), every light type (``delta_lights``: a plain and a
textured spot, a projector, a directional light and a textured area light, each re-evaluated by
index where a sample is reused; point, environment map, sphere and area lights), a rough
conductor (glossy vertices the hybrid shift does not reconnect at), textures, two-sided BSDFs
and Mitsuba's gaussian pixel filter (2×2-pixel blocks there). A method estimating emitted +
direct light (``reference_max_depth == 2``) renders ``max_depth_2`` and ``delta_lights_direct``. A method registered later joins by
itself; the skip list says why a method is left out.

What these cases have caught: ReSTIR DI skipped a smooth plastic's delta coat, which its
candidates cannot weigh, and so every method that composes it lost the coat's reflection of
the light (``plastic`` at 128 runs: ReSTCV block z −11.6, ReSTIR PT with ``direct=restir-di``
−11.5, ReSTIR GI with it −9.7; ReSTIR GI's hemisphere samples missed the coat too, −4.7, and with
``exact_bsdf`` its sample points' records −11.4); ReSTIR PT's reconnection to a spot light reused the spot's
intensity toward the *original* path's vertex (z = −10.5 on ``spot``); ReSTIR GI and ReSTCV
added ReSTIR DI's direct light at ``max_depth=1`` (z ≈ 190 on ``max_depth_1``); the methods
that put the film sample inside their samples (area-restir, gpt, ...) ignored the gaussian
filter (z ≈ −4 on ``filter_gaussian_wide``).
"""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path

import numpy as np
import pytest

from grisx.imageio import read_exr
from grisx.render import render
from grisx.render.driver import METHODS
from grisx.render.base.registry import load_plugins
from grisx.scene.mitsuba import load_mitsuba
from grisx.scene.scene import Scene
from grisx.testing import BIASED_K, DEFAULT_K, reuse_unbiasedness_test

HERE = Path(__file__).resolve().parent
#: the cases a method renders, by the path tracer depth whose image it estimates (None: the file's)
FULL_IMAGE_CASES = ("max_depth_4_rr_1", "max_depth_1", "delta_lights", "point", "envmap", "sphere_light", "roughconductor", "texture_exr",
                    "twosided", "filter_gaussian_wide")
CASES_BY_DEPTH = {None: FULL_IMAGE_CASES, 2: ("max_depth_2", "delta_lights_direct")}
#: z-test block size per case (default 8): a pixel filter moves energy between neighbouring pixels, so small blocks
BLOCK = {"filter_gaussian_wide": 2}
RUNS = 64
FRAMES = 4

load_plugins()
#: methods left out, and why
SKIP = {
    "pt": "the path tracer has its own suite (test_conformance.py)",
}
RADIANCE = sorted(name for name, m in METHODS.items() if m.kind == "radiance" and name not in SKIP)


def cases(method: str) -> tuple[str, ...]:
    return CASES_BY_DEPTH.get(METHODS[method].reference_max_depth, ())


#: methods whose kernels are another method's, run in CI on the cases that exercise what is their own; the other cases
#: are in the slow tier (``pytest -m slow``). mmis-gather is suffix-restir's final gather with the pixel's own suffixes
#: and no reuse (the same prefix, suffix and light code, which suffix-restir's cases cover in CI); its cases cost
#: 45-90 s each on the 2-core CI machine (64 prefixes x 3 suffixes a pixel and frame), ten of them most of CI's time.
#: Its own code (the own-suffix pass, the rows of own suffixes) is in every case, and test_suffix_restir's
#: test_mmis_gather_is_unbiased checks it against pt in CI (door-ajar, 8 prefixes, 3 suffixes, 64 runs); CI runs the
#: emitters-only case here (the whole render() path against Mitsuba). delta_lights (18 s of CI's CPU time) and
#: max_depth_4_rr_1 (13.5 s, the most expensive case of the file: 64 prefixes x 3 suffixes) moved to the slow tier
#: (2026-11-27).
CI_CASES = {"mmis-gather": ("max_depth_1",)}
#: (method, case) pairs; a method whose depth no Mitsuba case renders is listed (and skipped) with case None
PAIRS = [pytest.param(m, c, id=f"{m}-{c}", marks=pytest.mark.slow) if c not in CI_CASES.get(m, (c,)) else pytest.param(m, c, id=f"{m}-{c}")
         for m in RADIANCE for c in (cases(m) or (None,))]


def agreement(method: str, case: str, params: dict | None = None, *, runs: int = RUNS, k: float = DEFAULT_K, device: str = "cpu", edit=None):
    """The method's runs on ``case``, through :func:`grisx.render.render` as a user calls it (the file's
    max_depth and rr_depth become the method's defaults there), against Mitsuba's image; ``edit(scene)``
    changes the loaded scene first (the biased siblings)."""
    scene = load_mitsuba(HERE / "scenes" / f"{case}.xml")
    if edit is not None:
        edit(scene)
    # the runs share one built scene (its BVH), as reuse_checks' runs do: render() would build it again for each run
    # (a fifth of a cheap method's time here); the images are bit-identical either way
    build = functools.cache(lambda device: Scene.build(scene, device))
    scene.build = lambda device="cpu": build(str(device))
    ref = read_exr(HERE / "refs" / f"{case}.exr").astype(np.float64)[..., :3]
    ref_var = read_exr(HERE / "refs" / f"{case}.var.exr").astype(np.float64)[..., :3]

    def run(seed: int) -> np.ndarray:
        frames = []
        result = render(scene, method, spp=1, frames=FRAMES, camera="static", seed=seed, device=device, params=params,
                        on_frame=lambda i, img, s: frames.append(np.asarray(img, dtype=np.float64)[..., :3]))
        assert result.settings.get("nonfinite_samples", 0) == 0, result.settings
        return np.mean(frames, axis=0)

    return reuse_unbiasedness_test(run, ref, ref_var, runs, block=BLOCK.get(case, 8), k=k)


@pytest.mark.parametrize(("method", "case"), PAIRS)
def test_method_agrees_with_mitsuba(method, case, device):
    if case is None:
        pytest.skip(f"no Mitsuba case renders pt's max_depth={METHODS[method].reference_max_depth}, the image {method} estimates")
    result = agreement(method, case, device=device)
    assert result.passed, f"{method} on {case}: {result}"


@pytest.mark.parametrize(("method", "params", "runs"), [("restcv", {}, RUNS), ("restir-pt", {"direct": "restir-di"}, RUNS),
                                                       ("restir-gi", {"direct": "restir-di"}, 2 * RUNS), ("restir-gi", {"exact_bsdf": True}, RUNS)],
                         ids=["restcv", "restir-pt-direct-restir-di", "restir-gi-direct-restir-di", "restir-gi-exact-bsdf"])
def test_delta_lobes_beside_smooth_ones_agree_with_mitsuba(method, params, runs):
    # a smooth plastic: a delta coat over a diffuse base (ReSTIR DI's candidates and ReSTIR GI's hemisphere
    # samples cannot weigh the coat; a BSDF ray takes it, and ReSTIR GI path traces such visible points). Runs:
    # where the code before the fix fails each case (ReSTIR GI with ReSTIR DI passes at 64 runs, not at 128)
    result = agreement(method, "plastic", params, runs=runs)
    assert result.passed, f"{method} {params} on plastic: {result}"


# plugins2 (issue 38): Mitsuba's pplastic, polarizer/retarder, a textured roughdielectric alpha and a blend with a delta
# BSDF beside density ones, under ReSTIR PT's shifts, and the blend's delta conductor under the methods that compose
# ReSTIR DI (which cannot weigh a delta lobe, as the smooth plastic's coat above)
@pytest.mark.parametrize(("method", "params", "case"), [("restir-pt", {}, "blendbsdf_general"), ("restir-pt", {}, "pplastic"),
                                                       ("restir-pt", {}, "polarizer"), ("restir-pt", {}, "roughdielectric_textured"),
                                                       ("restcv", {}, "blendbsdf_general"),
                                                       ("restir-gi", {"direct": "restir-di"}, "blendbsdf_general")],
                         ids=["restir-pt-blendbsdf", "restir-pt-pplastic", "restir-pt-polarizer", "restir-pt-roughdielectric-textured",
                              "restcv-blendbsdf", "restir-gi-direct-restir-di-blendbsdf"])
def test_plugins2_bsdfs_agree_with_mitsuba_under_reuse(method, params, case):
    result = agreement(method, case, params)
    assert result.passed, f"{method} {params} on {case}: {result}"


def test_a_biased_method_disagrees_with_mitsuba():
    # ReSTIR PT with its shift Jacobians taken as 1 (the ablation the papers warn about)
    result = agreement("restir-pt", "max_depth_4_rr_1", {"shift": "reconnection", "jacobian": False}, k=BIASED_K)
    assert not result.passed, result


def test_a_film_sample_under_a_box_filter_is_caught_where_mitsuba_filters_with_a_gaussian():
    # Area ReSTIR's film samples uniform over the pixel (a box), on a film whose filter is Mitsuba's wide gaussian
    def box(scene):
        scene.film = dataclasses.replace(scene.film, filter_stddev=0.0)

    result = agreement("area-restir", "filter_gaussian_wide", edit=box, k=BIASED_K)
    assert not result.passed, result
