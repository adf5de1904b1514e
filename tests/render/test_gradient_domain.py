"""Gradient-domain renderers (seed 000) against the reference path tracer (CPU, 12×10 images, independent runs).

Every method's *primal* image and the *gradient* images dx, dy of ``gpt`` (B.2),
``gradient-after-restir`` (B.1) and ``restir-gpt`` are tested over independent runs (each its own
seed and history) with :func:`grisx.testing.reuse_unbiasedness_test`, per image and per 8×8 block,
k = 4: the primal against ``pt``'s image, dx and dy against the forward differences of ``pt``'s
image. Under the static camera the runs average their frames; under the camera path the last
frame alone is compared with ``pt`` at that frame's camera (temporal reuse through fractional
motion vectors). The reference's standard errors for the differences are taken as if
dx[x] = I[x+1] − I[x] were independent across x, an upper bound (a block mean of differences
telescopes: each pixel enters with coefficients summing to at most one in magnitude), so the check
errs on the side of passing; on the Cornell runs every pixel of dx and dy is also z-tested alone (block 1), and a
gradient written one pixel off is caught there. Scenes: the Cornell box and the closed bright room at max_depth 32 with
Russian roulette from depth 5.

Known-biased siblings fail the same check beyond 6σ: every shift without its Jacobian
(``jacobian=false``) in B.1, B.2 and ReSTIR G-PT, the one-sided difference of Eq. 2 without the
MIS-weighted term from the other pixel (``symmetric=false``, Eq. 3 and 12–13) in all three, and ReSTIR G-PT's outer shift without its Jacobian
(``outer_jacobian=false``, Eq. 22) on the lit wall of ``test_path_shift``, whose shifts between
nearby pixels have Jacobians far from one. Positivization (Eq. 23–26) lowers the gradients'
variance on the two-light metal rack (seed 000, Fig. 9).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from reuse_checks import HARD_SCENES
from session_cache import committed
from test_path_shift import lit_wall  # the scene whose Jacobians are far from 1

from grisx.errors import InvalidParameterError
from grisx.render import restir_gpt
from grisx.render.driver import METHODS, RenderContext, load_scene, method_params, render
from grisx.render.pt import PathTracer
from grisx.scene.builtin import BUILTIN_SCENES
from grisx.testing import BIASED_K, DEFAULT_K, reuse_unbiasedness_test

RES = (12, 10)
GRADIENT_METHODS = ("gpt", "gradient-after-restir", "restir-gpt")
ALL_METHODS = ("area-restir", *GRADIENT_METHODS)
_SCENES: dict[str, Any] = {}
_RUNS: dict[Any, list[dict[str, np.ndarray]]] = {}


def _scene(name: str) -> Any:
    if name not in _SCENES:
        _SCENES[name] = lit_wall() if name == "lit-wall" else load_scene(name)
    return _SCENES[name]


def _reference(scene: str, depth: int, camera: str, frame: int, spp: int = 4096) -> tuple[np.ndarray, np.ndarray]:

    def render() -> tuple[np.ndarray, np.ndarray]:
        built = _scene(scene).build("cpu")
        built.animate_camera = camera == "moving"
        built.set_frame(float(frame))
        pt = PathTracer(built, *RES, spp=spp, max_depth=depth, seed=987654)
        pt.add_samples(frame, spp)
        return pt.mean().astype(np.float64), pt.variance_of_mean().astype(np.float64)

    return committed(("test_gradient_domain.reference", scene, depth, camera, frame, spp, RES, 987654), _scene(scene), render)


def _runs(method: str, params: dict[str, Any], scene: str, camera: str, frames: int, runs: int) -> list[dict[str, np.ndarray]]:
    """``runs`` independent runs: primal, dx, dy and the final image of each (frame-averaged, or the last frame when moving)."""
    key = (method, tuple(sorted(params.items())), scene, camera, frames, runs)
    if key in _RUNS:
        return _RUNS[key]
    built = _scene(scene).build("cpu")
    built.animate_camera = camera == "moving"
    resolved = {**method_params(method, params), "spp": 1}
    out = []
    for r in range(runs):
        renderer = METHODS[method].create(RenderContext(built, *RES, dict(resolved), 1000 + r, None, method))
        sums: dict[str, np.ndarray] = {}
        for f in range(frames):
            built.set_frame(float(f))
            parts = {"image": renderer.render_frame(f).numpy(), **(renderer.extra() if hasattr(renderer, "extra") else {})}
            for k, v in parts.items():
                v = v.astype(np.float64)
                sums[k] = sums.get(k, 0.0) + v / frames if camera == "static" else v
        assert renderer.nonfinite_samples == 0
        if "dx" in sums:
            sums["dx"], sums["dy"] = sums["dx"][:, :-1], sums["dy"][:-1]
        out.append(sums)
    _RUNS[key] = out
    return out


def _check(method: str, params: dict[str, Any], scene: str, which: str, *, camera: str = "static", frames: int = 4,
           runs: int = 64, k: float = DEFAULT_K, block: int = 8, edit: Any = None):
    """``which`` of the method's runs against the reference, per image and per ``block``×``block`` block (1: per
    pixel); ``edit(image)`` changes each run's image first (a sibling's known error)."""
    depth = int(params["max_depth"])
    ref, var = _reference(scene, depth, camera, frames - 1 if camera == "moving" else 0)
    refs = {"image": (ref, var), "primal": (ref, var),
            "dx": (ref[:, 1:] - ref[:, :-1], var[:, 1:] + var[:, :-1]), "dy": (ref[1:] - ref[:-1], var[1:] + var[:-1])}
    data = _runs(method, params, scene, camera, frames, runs)
    expected, expected_var = refs[which]
    result = reuse_unbiasedness_test(lambda seed: (edit or (lambda im: im))(data[seed - 1000][which]), expected, expected_var, runs,
                                     block=block, k=k, seed0=1000)
    print(method, scene, camera, params, which, "image z", np.round(result.image.z, 2), "blocks max |z|", round(float(np.max(np.abs(result.blocks.z))), 2))
    return result


CLOSED_ROOM = {"max_depth": 32, "rr_depth": 5}
#: glossy-room: rough conductors, where the hybrid shift replays through glossy vertices instead of reconnecting
CASES = [("cornell-box", "static", {"max_depth": 16}), ("closed-room", "static", CLOSED_ROOM), ("closed-room", "moving", CLOSED_ROOM),
         ("glossy-room", "static", {"max_depth": 16}), ("glossy-room", "moving", {"max_depth": 16})]
CASE_IDS = ["cornell", "closed-room-depth32-rr", "closed-room-depth32-rr-moving", "glossy", "glossy-moving"]


def _frames(camera: str) -> int:
    return 4 if camera == "static" else 6


# ---- unbiased against the path tracer ----------------------------------------------------------------


@pytest.mark.parametrize("scene,camera,params", CASES, ids=CASE_IDS)
@pytest.mark.parametrize("method", ALL_METHODS)
def test_primal_is_unbiased(method, scene, camera, params):
    which = "image" if method == "area-restir" else "primal"
    assert _check(method, params, scene, which, camera=camera, frames=_frames(camera)).passed


@pytest.mark.parametrize("scene,camera,params", CASES, ids=CASE_IDS)
@pytest.mark.parametrize("method", GRADIENT_METHODS)
@pytest.mark.parametrize("which", ["dx", "dy"])
def test_gradients_are_unbiased(method, scene, camera, params, which):
    assert _check(method, params, scene, which, camera=camera, frames=_frames(camera)).passed


def test_gradients_are_unbiased_pixel_by_pixel():
    """Per pixel (block 1, Šidák-corrected over pixels and channels), on the runs of the cornell case above.

    A block mean of dx telescopes (the sum of a row's differences is its end pixels' difference), so an 8×8 block
    sees an error in dx mostly through the block's edges; here every difference is tested. The sibling: a gradient
    written one pixel off is caught (max |z| 52 for dx, 39 for dy on these runs; the 8×8 check sees it at 19 and 17).
    """
    for method in GRADIENT_METHODS:
        for which in ("dx", "dy"):
            result = _check(method, {"max_depth": 16}, "cornell-box", which, block=1)
            assert result.passed, (method, which, result)


def _one_pixel_off(which: str):
    """The gradient image as a renderer that wrote pixel x's difference into pixel x + 1 would (edge pixel kept)."""
    axis = 1 if which == "dx" else 0
    return lambda im: np.concatenate([np.take(im, [0], axis=axis), np.take(im, range(im.shape[axis] - 1), axis=axis)], axis=axis)


def test_a_gradient_written_one_pixel_off_is_caught_pixel_by_pixel():
    for which in ("dx", "dy"):
        assert not _check("gpt", {"max_depth": 16}, "cornell-box", which, block=1, k=BIASED_K, edit=_one_pixel_off(which)).passed, which


@pytest.mark.parametrize(
    "params",
    [{"positivize": False}, {"cross_sign": True}, {"pair_reuse": "dense", "radius": 4.0}, {"pair_reuse": "off", "pair_temporal": False},
     {"pair_reuse": "adaptive", "radius": 4.0, "pair_search": 16}],
    ids=["one-reservoir", "cross-sign", "dense-reuse", "no-pair-reuse", "adaptive-reuse-near"],
)
def test_restir_gpt_ablations_stay_unbiased(params):
    for which in ("dx", "dy"):
        assert _check("restir-gpt", {**CLOSED_ROOM, **params}, "closed-room", which).passed


# ---- moving objects: the history's pairs shifted through the previous frame's geometry -------------------------

MOVING_OBJECTS = "cornell-box-fast-objects"  # two boxes sliding past each other, > 1 px a frame (reuse_checks)
MOVING_RUNS = 2048  # the sibling's worst 4×4 block of dx reads |z| 6.4 at 1536 runs (not caught there), 1.7 for the method


def _moving_objects_check(k: float) -> list[Any]:
    """ReSTIR G-PT's dx and dy (a result each, from the same runs) at the last of 4 frames of the sliding boxes, static
    camera, against pt at that frame (8192 spp), per 4×4 block: what a moving edge leaves wrong is a few pixels wide."""
    depth = 16
    scene = HARD_SCENES[MOVING_OBJECTS]()
    frames = 4

    def reference() -> tuple[np.ndarray, np.ndarray]:
        built = scene.build("cpu")
        built.set_frame(float(frames - 1))
        pt = PathTracer(built, *RES, spp=8192, max_depth=depth, seed=987654)
        pt.add_samples(frames - 1, 8192)
        return pt.mean().astype(np.float64), pt.variance_of_mean().astype(np.float64)

    ref, var = committed(("test_gradient_domain.moving_objects", MOVING_OBJECTS, depth, frames, 8192, RES, 987654), scene, reference)
    expected = {"dx": (ref[:, 1:] - ref[:, :-1], var[:, 1:] + var[:, :-1]), "dy": (ref[1:] - ref[:-1], var[1:] + var[:-1])}
    resolved = {**method_params("restir-gpt", {"max_depth": depth}), "spp": 1}

    gradients: dict[int, dict[str, np.ndarray]] = {}  # dx and dy of one render: each run is rendered once for both
    built = scene.build("cpu")  # the runs share one built scene (its BVH), as reuse_checks' do: each starts at frame 0

    def run(seed: int) -> dict[str, np.ndarray]:
        if seed in gradients:
            return gradients[seed]
        renderer = METHODS["restir-gpt"].create(RenderContext(built, *RES, dict(resolved), seed, None, "restir-gpt"))
        for f in range(frames):
            built.set_frame(float(f))
            renderer.render_frame(f)
        assert renderer.nonfinite_samples == 0
        extra = renderer.extra()
        gradients[seed] = {"dx": np.asarray(extra["dx"], np.float64)[:, :-1], "dy": np.asarray(extra["dy"], np.float64)[:-1]}
        return gradients[seed]

    results = []
    for which in ("dx", "dy"):
        result = reuse_unbiasedness_test(lambda seed, w=which: run(seed)[w], *expected[which], MOVING_RUNS, block=4, k=k, seed0=1000)
        print(which, "image z", np.round(result.image.z, 2), "blocks max |z|", round(float(np.max(np.abs(result.blocks.z))), 2))
        results.append(result)
    return results


def test_gradients_are_unbiased_where_objects_move():
    assert all(r.passed for r in _moving_objects_check(DEFAULT_K))


def test_history_shifted_through_this_frames_geometry_is_caught(monkeypatch):
    """The sibling: the source pair's domains of a temporal merge in this frame's scene, no shift failing where what
    it reuses moved (the previous frame's pairs read as if nothing had moved)."""
    monkeypatch.setattr(restir_gpt, "pair_scenes", lambda built, temporal: (built.data, built.data))
    assert not all(r.passed for r in _moving_objects_check(BIASED_K))


def test_the_l2_reconstruction_is_unbiased():
    """The frame itself: L2 is linear in unbiased primal and gradients (Kettunen et al. 2015)."""
    assert _check("restir-gpt", {"max_depth": 16}, "cornell-box", "image").passed


# ---- the biased siblings are caught by the same check -------------------------------------------------


@pytest.mark.parametrize("scene", ["cornell-box", "glossy-room"])
@pytest.mark.parametrize("method", GRADIENT_METHODS)
def test_inner_shift_without_jacobian_is_caught(method, scene):
    results = [_check(method, {"max_depth": 16, "jacobian": False}, scene, which, k=BIASED_K) for which in ("dx", "dy")]
    assert not all(r.passed for r in results)


@pytest.mark.parametrize("method", GRADIENT_METHODS)
def test_one_sided_difference_is_caught(method):
    """Eq. 2 alone (pixel i's base paths, omega = 1; ReSTIR G-PT: the pair target on pixel i's half of X alone):
    the paths of pixel j that T_ij cannot reach are lost (Eq. 3, 12–13)."""
    results = [_check(method, {"max_depth": 16, "symmetric": False}, "cornell-box", which, k=BIASED_K) for which in ("dx", "dy")]
    assert not all(r.passed for r in results)


def test_outer_shift_without_jacobian_is_caught():
    """Eq. 22 on the lit wall, dense reuse of pairs 4 px apart: the sibling drops |∂τ/∂y| of the outer shift alone."""
    params = {"max_depth": 10, "pair_reuse": "dense", "radius": 4.0}
    for jacobian in (True, False):
        results = [_check("restir-gpt", {**params, "outer_jacobian": jacobian}, "lit-wall", which, frames=6, runs=512,
                          k=DEFAULT_K if jacobian else BIASED_K) for which in ("dx", "dy")]
        assert all(r.passed for r in results) == jacobian


# ---- positivization (Sec. 4.4, Fig. 9) ------------------------------------------------------------------


def test_positivization_lowers_gradient_variance():
    """metal-rack (two lights, gradients of both signs): r+ and r- against one reservoir of |omega*G|."""
    variance = {}
    for positivize in (True, False):
        data = _runs("restir-gpt", {"max_depth": 6, "positivize": positivize}, "metal-rack", "static", 4, 32)
        variance[positivize] = float(np.mean([np.var([d[w] for d in data], axis=0, ddof=1).mean() for w in ("dx", "dy")]))
    print("metal-rack gradient variance: positivized", variance[True], "one reservoir", variance[False])
    assert variance[True] < variance[False]


# ---- every scene, the CLI's files, bad params ------------------------------------------------------------


@pytest.mark.parametrize("method", ALL_METHODS)
def test_every_builtin_scene_renders_finite(method):
    for scene in sorted(BUILTIN_SCENES):
        result = render(scene, method, res=(8, 6), frames=2, spp=1 if METHODS[method].uses_spp else None, params={"max_depth": 4})
        assert np.all(np.isfinite(result.image)), scene
        assert result.settings["nonfinite_samples"] == 0, scene
        for name, img in result.extra.items():
            assert np.all(np.isfinite(img)), (scene, name)


def test_cli_writes_primal_and_gradients(tmp_path):
    from grisx.cli import main

    out = tmp_path / "frame.exr"
    assert main(["render", "cornell-box", "--method", "restir-gpt", "--res", "8x6", "--param", "reconstruction=l1", "--out", str(out)]) == 0
    for name in ("frame.exr", "frame.png", "frame.primal.exr", "frame.dx.exr", "frame.dy.exr", "frame.json"):
        assert (tmp_path / name).exists(), name


@pytest.mark.parametrize(
    "params,match",
    [({"cross_sign": True, "positivize": False}, "positivize"), ({"pair_reuse": "sparse"}, "pair_reuse"), ({"reconstruction": "l3"}, "reconstruction")],
)
def test_bad_params_raise(params, match):
    with pytest.raises(InvalidParameterError, match=match):
        render("cornell-box", "restir-gpt", res=(8, 6), params=params)


def test_adaptive_reuse_merges_only_edge_pairs():
    """Sec. 4.3.2 on the black/white grid: interior pairs keep their own reservoir, edge pairs (a numpy oracle of the
    G-buffer test: albedo apart by > 0.1, normals by cos < 0.9, depths by > 10%, or one pixel a miss) take a neighbour's."""
    built = _scene("checker-grid").build("cpu")
    params = {**method_params("restir-gpt", {"pair_temporal": False, "pair_reuse": "adaptive", "radius": 4.0, "max_depth": 4}), "spp": 1}
    r = METHODS["restir-gpt"].create(RenderContext(built, 24, 18, params, 5, None, "restir-gpt"))
    r.render_frame(0)
    g = r.gbuffer.numpy()
    conf = r.pairs[0].numpy()["res"]["confidence"][0]  # slot r+, (orientation, y, x)
    hit, alb, nrm, dep = g["hit"], g["albedo"], g["normal"], g["depth"]
    merged = edges = 0
    for o, (ex, ey) in enumerate(((1, 0), (0, 1))):
        for y in range(18 - ey):
            for x in range(24 - ex):
                j = (y + ey, x + ex)
                if hit[y, x] == 0 or hit[j] == 0:
                    edge = hit[y, x] != hit[j]
                else:
                    edge = (np.abs(alb[y, x] - alb[j]).max() > 0.1 or np.dot(nrm[y, x], nrm[j]) < 0.9
                            or abs(dep[y, x] - dep[j]) > 0.1 * dep[y, x])
                edges += edge
                if not edge:
                    assert conf[o, y, x] == pytest.approx(1.0), (o, y, x)  # the canonical pair alone
                merged += conf[o, y, x] > 1.0
    print("edge pairs", edges, "merged", merged)
    assert 0 < merged <= edges
