"""The test session's caches: a committed reference is read only for the scene it is an image of."""

import dataclasses

import numpy as np
import pytest

import session_cache
from grisx.scene.builtin import build_builtin
from session_cache import committed, scene_fingerprint


def _renders(value):
    calls = []

    def compute():
        calls.append(1)
        return (np.full((2, 2, 3), value),)

    return compute, calls


def test_a_scene_has_one_fingerprint_and_every_change_makes_another():
    base = scene_fingerprint(build_builtin("cornell-box"))
    assert base == scene_fingerprint(build_builtin("cornell-box"))
    assert base != scene_fingerprint(build_builtin("closed-room"))

    brighter = build_builtin("cornell-box")
    i = next(i for i, m in enumerate(brighter.materials) if hasattr(m, "reflectance") and isinstance(m.reflectance, tuple))
    r = brighter.materials[i].reflectance
    brighter.materials[i] = dataclasses.replace(brighter.materials[i], reflectance=(r[0] * 1.001, r[1], r[2]))
    assert scene_fingerprint(brighter) != base

    moved = build_builtin("cornell-box")
    moved.camera.to_world = moved.camera.to_world.copy()
    moved.camera.to_world[0, 3] += 1e-6
    assert scene_fingerprint(moved) != base


def test_a_committed_reference_is_read_for_its_scene_and_rendered_again_for_a_changed_one(tmp_path, monkeypatch):
    monkeypatch.setattr(session_cache, "REFERENCES", tmp_path)
    monkeypatch.setattr(session_cache, "_MEMO", {})
    scene = build_builtin("cornell-box")
    key = ("test_session_cache", 16, 4096)

    monkeypatch.setenv(session_cache.WRITE_ENV, "1")
    compute, calls = _renders(1.0)
    committed(key, scene, compute)
    assert calls == [1] and len(list(tmp_path.glob("*.npz"))) == 1

    monkeypatch.delenv(session_cache.WRITE_ENV)
    monkeypatch.setattr(session_cache, "_MEMO", {})
    compute, calls = _renders(2.0)
    (image,) = committed(key, scene, compute)
    assert calls == [] and np.all(image == 1.0)  # read, not rendered

    changed = build_builtin("cornell-box")
    changed.film = dataclasses.replace(changed.film, width=changed.film.width + 1)
    (image,) = committed(key, changed, compute)
    assert calls == [1] and np.all(image == 2.0)  # another scene: rendered, not read
    assert len(list(tmp_path.glob("*.npz"))) == 1  # and not written outside write mode


def test_what_cannot_be_fingerprinted_is_refused():
    class Opaque:
        __slots__ = ()

    with pytest.raises(TypeError, match="Opaque"):
        scene_fingerprint({"x": Opaque()})
    with pytest.raises(TypeError, match="code, not data"):
        scene_fingerprint({"x": lambda t: t})
