"""ReSTIR PT against the reference path tracer (CPU, 16×16 images, fixed seeds).

Reuse correlates pixels, so unbiasedness is tested over *independent runs*:
each run (its own seed) renders a few accumulated frames of a static camera
and contributes one image mean per channel; the runs' mean is compared with
the path tracer's image mean at the same ``max_depth`` by a z-test
whose standard error combines the runs' spread and the reference's own
standard error (k = 4, Šidák over channels). The sibling checks show the
wrong-Jacobian ablation (``jacobian=false``) fails the same check beyond 6σ.

Depth is tested where it matters: ``closed-room`` (walls of albedo 0.85, paths of
more than 10 segments carry ~17% of its image) at ``max_depth`` −1 (Russian
roulette) and 64, for every shift; truncating the paths at 10 segments fails
the same check.
"""

from __future__ import annotations

import numpy as np
import pytest
from session_cache import committed
from test_path_shift import lit_wall  # the scene whose Jacobians are far from 1

from grisx.errors import InvalidParameterError, UnknownNameError
from grisx.scene.builtin import BUILTIN_SCENES, build_builtin
from grisx.render.pt import PathTracer
from grisx.render.driver import render
from grisx.render.restir_pt import ReSTIRPT
from grisx.testing import BIASED_K, DEFAULT_K, z_test

RES = 16
MAX_DEPTH = 10
SHIFTS = ("hybrid", "reconnection", "replay")
_BUILT: dict = {}


def _built(name: str, device: str = "cpu"):
    if (name, device) not in _BUILT:
        _BUILT[name, device] = (lit_wall() if name == "lit-wall" else build_builtin(name)).build(device)
    return _BUILT[name, device]


def _reference(name: str, spp: int = 1024, max_depth: int = MAX_DEPTH) -> tuple[np.ndarray, np.ndarray]:
    """The path tracer's image mean and its standard error (independent pixels; CPU: the device is not part of it)."""

    def render() -> tuple[np.ndarray, np.ndarray]:
        pt = PathTracer(_built(name), RES, RES, spp=spp, max_depth=max_depth, seed=4321)
        pt.add_samples(0, spp)
        mean = pt.mean().reshape(-1, 3).astype(np.float64)
        var = pt.variance_of_mean().reshape(-1, 3).astype(np.float64)
        return mean.mean(axis=0), np.sqrt(var.sum(axis=0)) / len(mean)

    scene = lit_wall() if name == "lit-wall" else build_builtin(name)
    return committed(("test_restir_pt.reference", name, spp, max_depth, RES, 4321), scene, render)


def _runs(name: str, runs: int, frames: int, device: str = "cpu", **kw) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard error over independent runs of the image mean of ``frames`` accumulated frames."""
    built = _built(name, device)
    means = np.empty((runs, 3))
    for s in range(runs):
        r = ReSTIRPT(built, RES, RES, seed=1000 + s, **{"max_depth": MAX_DEPTH, **kw})
        acc = np.zeros((RES, RES, 3))
        for f in range(frames):
            acc += r.render_frame(f).numpy()
        assert r.nonfinite_samples == 0
        means[s] = (acc / frames).reshape(-1, 3).mean(axis=0)
    return means.mean(axis=0), means.std(axis=0, ddof=1) / np.sqrt(runs)


def _check(name: str, runs: int, frames: int, k: float, reference_depth: int = MAX_DEPTH, **kw):
    ref, ref_se = _reference(name, max_depth=reference_depth)
    est, se = _runs(name, runs, frames, **kw)
    return z_test(est - ref, np.sqrt(se**2 + ref_se**2), np.zeros(3), k=k)


# ---- unbiased against the path tracer ---------------------------------------------------------------


@pytest.mark.parametrize("shift", SHIFTS)
def test_converges_to_the_path_tracer(shift):
    result = _check("lit-wall", 200, 6, DEFAULT_K, shift=shift, radius=6.0)
    assert result.passed, result


@pytest.mark.parametrize(
    "options",
    [
        {"candidates": 4, "spatial_rounds": 2},  # the offline setting in small
        {"temporal": False},  # spatial reuse alone
        {"spatial_rounds": 0},  # temporal reuse alone
        {"max_jacobian": 2.0},  # the rejection threshold keeps T a bijection: still unbiased
    ],
    ids=["offline", "spatial-only", "temporal-only", "jacobian-threshold"],
)
def test_configurations_converge_to_the_path_tracer(options):
    result = _check("lit-wall", 100, 4, DEFAULT_K, shift="hybrid", radius=6.0, **options)
    assert result.passed, result


@pytest.mark.parametrize("shift", SHIFTS)
def test_converges_on_a_glossy_scene(shift):
    # glossy-room: rough conductors, so the hybrid shift replays past glossy vertices before it reconnects
    result = _check("glossy-room", 120, 6, DEFAULT_K, shift=shift, radius=4.0)
    assert result.passed, result


# ---- at the depth users render at -------------------------------------------------------------------


@pytest.mark.parametrize("max_depth", [-1, 64], ids=["unbounded", "depth64"])
@pytest.mark.parametrize("shift", SHIFTS)
def test_converges_in_a_closed_room_at_realistic_depth(shift, max_depth, device):
    # Russian roulette from depth 5 (replayed with each domain's own survival probability); at depth 64
    # without roulette the path densities span dozens of orders of magnitude (the π-scaled measure keeps
    # them in float32)
    rr_depth = 5 if max_depth < 0 else 1000
    result = _check("closed-room", 24, 6, DEFAULT_K, reference_depth=max_depth, device=device, shift=shift, radius=6.0, max_depth=max_depth, rr_depth=rr_depth)
    assert result.passed, result


@pytest.mark.parametrize("shift", SHIFTS)
def test_truncated_paths_are_caught_in_the_closed_room(shift):
    # the sibling: paths cut at 10 segments lose the closed room's long-path light (~17%)
    result = _check("closed-room", 48, 6, BIASED_K, reference_depth=-1, shift=shift, radius=6.0, max_depth=10)
    assert not result.passed, result


def test_depth_follows_the_scene_and_is_reported():
    # closed-room's integrator: max_depth -1; an explicit param wins
    r = render("closed-room", "restir-pt", res=(8, 8), seed=1)
    assert r.settings["params"]["max_depth"] == -1 and r.settings["params"]["rr_depth"] == 5
    r = render("closed-room", "restir-pt", res=(8, 8), seed=1, params={"max_depth": 7})
    assert r.settings["params"]["max_depth"] == 7
    with pytest.raises(InvalidParameterError, match="max_depth"):
        render("closed-room", "restir-pt", res=(8, 8), params={"max_depth": 0})


@pytest.mark.parametrize("shift", SHIFTS)
def test_wrong_jacobian_is_caught(shift):
    result = _check("lit-wall", 400 if shift == "replay" else 200, 6, BIASED_K, shift=shift, radius=6.0, jacobian=False)
    assert not result.passed, result


# ---- robustness -------------------------------------------------------------------------------------


@pytest.mark.parametrize("shift", SHIFTS)
def test_every_builtin_scene_renders_finite(shift):
    for name in BUILTIN_SCENES:
        r = render(name, "restir-pt", frames=3, accumulate=True, res=(RES, RES), seed=2, params={"shift": shift, "radius": 4})
        assert np.all(np.isfinite(r.image)), name
        assert r.settings["nonfinite_samples"] == 0, name
        assert r.image.mean() > 0.0, name


def test_same_seed_same_image_other_seed_other_image():
    def run(seed: int) -> np.ndarray:
        return render("cornell-box", "restir-pt", frames=3, res=(RES, RES), seed=seed, camera="static").image

    a, b, c = run(5), run(5), run(6)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_params_are_checked():
    with pytest.raises(InvalidParameterError, match="shift"):
        render("cornell-box", "restir-pt", res=(8, 8), params={"shift": "teleport"})
    with pytest.raises(InvalidParameterError, match="candidates"):
        render("cornell-box", "restir-pt", res=(8, 8), params={"candidates": 0})
    with pytest.raises(UnknownNameError):
        render("cornell-box", "restir-pt", res=(8, 8), params={"bounces": 3})


@pytest.mark.parametrize("method", ["restir-pt", "restir-gi"])
def test_the_motion_tests_are_compiled_only_for_scenes_whose_objects_move(method, monkeypatch):
    """Shifts across frames test what they reuse against what moved: ReSTIR PT replays a reused suffix
    (``suffix_moved``, a path walk in every temporal stage), ReSTIR GI keeps the box of the path behind each L_o. Both
    are compiled only where the scene's kinds hold SCENE_MOVING_OBJECTS. A static scene renders the same with its kinds
    as with every kind; the scene whose boxes slide, compiled without the pseudo-kind (the sibling), reuses what moved
    and renders another image."""
    from reuse_checks import HARD_SCENES

    from grisx.scene.material import SCENE_MOVING_OBJECTS, kernel_kinds
    from grisx.scene.scene import SceneFeatures

    moving = HARD_SCENES["cornell-box-fast-objects"]()
    assert SCENE_MOVING_OBJECTS in moving.features().material_kinds
    assert SCENE_MOVING_OBJECTS not in build_builtin("cornell-box").features().material_kinds

    def image(scene, kinds: str, drop: frozenset[int] = frozenset()) -> np.ndarray:
        monkeypatch.setenv("GRISX_KERNEL_KINDS", kinds)
        monkeypatch.setattr(SceneFeatures, "kernel_kinds", property(lambda f: kernel_kinds(f.material_kinds) - drop))
        return render(scene, method, frames=4, seed=3, res=(16, 12)).image

    np.testing.assert_array_equal(image("cornell-box", "scene"), image("cornell-box", "all"))
    assert not np.array_equal(image(moving, "scene", frozenset({SCENE_MOVING_OBJECTS})), image(moving, "all"))
