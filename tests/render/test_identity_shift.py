"""The temporal shift onto itself is the identity, and taking it as such changes no image.

Under a still camera the renderers whose samples carry their film sample (Area ReSTIR, ReSTIR G-PT's
pairs and their Area ReSTIR primal pass) carry a pixel with zero motion onto itself: the history's domain
and this frame's are one, and the temporal shift is the identity (``film_shift_as_is``, ``pair_as_is``)
instead of a replay of the path to the same result. This file renders each case twice at one seed, once
as shipped and once with the shortcut turned off (the renderers' ``camera_data_equal`` made to answer
"moved"), and requires the images to agree to float rounding. The shortcut applies only where nothing in the
scene moves: a temporal shift sees the previous frame's geometry at one end. The sibling drops that condition
(the two boxes of ``reuse_checks``' ``cornell-box-fast-objects`` slide under a still camera): the history's stale
paths are then reused as they were, and the same comparison fails.
"""

from __future__ import annotations

import numpy as np
import pytest

from reuse_checks import HARD_SCENES

from grisx.render import area_restir, restir_gpt
from grisx.render.driver import render

RES = (24, 18)
MOVING_OBJECTS = "cornell-box-fast-objects"
CASES = [("area-restir", "cornell-box"), ("area-restir", "glossy-room"), ("restir-gpt", "cornell-box"), ("restir-gpt", "door-ajar"),
         ("area-restir", MOVING_OBJECTS), ("restir-gpt", MOVING_OBJECTS)]


def _images(method: str, scene: str, camera: str) -> dict[str, np.ndarray]:
    scene_or_name = HARD_SCENES[scene]() if scene in HARD_SCENES else scene
    r = render(scene_or_name, method, res=RES, frames=5, seed=11, device="cpu", camera=camera)
    return {"image": np.asarray(r.image, np.float64), **{k: np.asarray(v, np.float64) for k, v in (r.extra or {}).items()}}


def _with_stillness(monkeypatch: pytest.MonkeyPatch, answer: bool) -> None:
    """Make both renderers see every pair of cameras as still (True) or moved (False)."""
    for module in (area_restir, restir_gpt):
        monkeypatch.setattr(module, "camera_data_equal", lambda a, b: answer)


def _largest_difference(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> float:
    """The largest |a − b| over every image, relative to that image's largest value."""
    assert a.keys() == b.keys()
    return max(float(np.max(np.abs(a[k] - b[k]))) / max(float(np.max(np.abs(a[k]))), 1e-30) for k in a)


@pytest.mark.parametrize("method,scene", CASES)
def test_the_identity_onto_itself_changes_no_image(monkeypatch, method, scene):
    shipped = _images(method, scene, "static")
    _with_stillness(monkeypatch, False)
    shifted = _images(method, scene, "static")
    diff = _largest_difference(shipped, shifted)
    print(method, scene, "largest relative difference", diff)
    assert diff <= 1e-5  # float rounding (measured: 0 in three cases, 2.4e-7 absolute on glossy-room)


@pytest.mark.parametrize("method", ["area-restir", "restir-gpt"])
def test_the_identity_where_objects_moved_is_caught(monkeypatch, method):
    """The sibling: the history taken as it is although objects moved (the moving-objects condition dropped)."""
    shipped = _images(method, MOVING_OBJECTS, "static")
    for module in (area_restir, restir_gpt):
        monkeypatch.setattr(module, "SCENE_MOVING_OBJECTS", -1)  # a kind no scene has: "nothing moves"
    wrong = _images(method, MOVING_OBJECTS, "static")
    diff = _largest_difference(shipped, wrong)
    print(method, MOVING_OBJECTS, "largest relative difference", diff)
    assert diff > 1e-2
