"""Built-in scenes: procedural, nothing downloaded, one per situation the seeds study.

Each scene has a static default camera and an animated camera path
(``grisx render NAME --frames F`` follows the path; the static camera is the
path's first key). ``grisx scenes`` lists them:

=====================  ==========================================================================
``cornell-box``        Mitsuba's Cornell box (same geometry, colours, light and camera as ``mi.cornell_box()``)
``door-ajar``          a room lit only through a barely open door: indirect light dominates (seed 004)
``red-green-lights``   a white diffuse plane under one red and one green light (seed 002, Fig. 2)
``checker-grid``       a black/white grid with sharp edges under an area light (seed 000, Fig. 6)
``metal-rack``         glossy metal bars lit by two lights (seed 000, Fig. 9)
``caustic-slab-plane`` a bumpy two-sided glass slab and a wavy metal plane, two small coloured lights (seed 003, Fig. 1)
``caustic-slab``       a bumpy double-refractive glass slab over a plane, one small light (seed 003)
``reflective-plane``   a bumpy metal plane throwing a caustic on a floor and wall, one small light (seed 003)
``pool``               a wavy water surface over a tiled floor under a sky with a small, bright sun (seed 003)
``swimming-pool``      ``pool`` with a distant area-light sun under a sunless sky
``glossy-room``        a room with a glossy floor (seed 004, Fig. 9)
``many-lights``        hundreds of small coloured emitters over a floor
``closed-room``        a closed room of bright walls (albedo 0.85) and one small light: long paths matter
=====================  ==========================================================================

All use Mitsuba's conventions (y up, radiance units, one-sided emitters).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from grisx.errors import UnknownNameError
from grisx.scene.camera import Camera, CameraPath, lookat
from grisx.scene.lights import ConstantEnvironment, EnvMap
from grisx.scene.material import Conductor, Dielectric, Diffuse, RoughConductor, RoughDielectric, TextureRef, conductor_material
from grisx.scene.scene import Film, RigidMotion, Scene
from grisx.scene.shapes import MeshData, cube, rectangle, sphere
from grisx.scene.transform import compose, rotate, scale, translate

__all__ = ["BUILTIN_SCENES", "build_builtin", "scene_summaries"]


def _add(scene: Scene, mesh: MeshData, material: int, to_world: np.ndarray | None = None, **kw) -> int:
    return scene.add_mesh(mesh.vertices, mesh.faces, normals=mesh.normals, uvs=mesh.uvs, material=material, to_world=to_world, **kw)


def _camera(scene: Scene, fov: float, keys: list[tuple], frames_per_key: float = 40.0, fov_axis: str = "x") -> None:
    """Static camera at the first key; the path visits every key and loops."""
    camera = Camera(to_world=lookat(*keys[0]), fov=fov, fov_axis=fov_axis)
    scene.set_camera(camera, CameraPath(keys=keys, frames_per_key=frames_per_key))


def _room(scene: Scene, lo: tuple, hi: tuple, materials: dict[str, int], skip: tuple[str, ...] = ()) -> None:
    """Inward-facing axis-aligned box walls from rectangles (names: floor, ceiling, back, front, left, right)."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    cx, cy, cz = (x0 + x1) / 2, (y0 + y1) / 2, (z0 + z1) / 2
    sx, sy, sz = (x1 - x0) / 2, (y1 - y0) / 2, (z1 - z0) / 2
    walls = {
        "floor": compose(translate((cx, y0, cz)), rotate((1, 0, 0), -90), scale((sx, sz, 1))),
        "ceiling": compose(translate((cx, y1, cz)), rotate((1, 0, 0), 90), scale((sx, sz, 1))),
        "back": compose(translate((cx, cy, z0)), scale((sx, sy, 1))),
        "front": compose(translate((cx, cy, z1)), rotate((0, 1, 0), 180), scale((sx, sy, 1))),
        "left": compose(translate((x0, cy, cz)), rotate((0, 1, 0), 90), scale((sz, sy, 1))),
        "right": compose(translate((x1, cy, cz)), rotate((0, 1, 0), -90), scale((sz, sy, 1))),
    }
    for name, m in walls.items():
        if name not in skip:
            _add(scene, rectangle(), materials.get(name, materials["default"]), m, name=name)


def _panel(scene: Scene, center: tuple, half: tuple[float, float], normal_rot: np.ndarray, material: int, **kw) -> int:
    return _add(scene, rectangle(), material, compose(translate(center), normal_rot, scale((*half, 1))), **kw)


# ---- the scenes ----------------------------------------------------------------------


def cornell_box() -> Scene:
    s = Scene("cornell-box")
    s.description = "Mitsuba's Cornell box: diffuse walls, two boxes, one area light"
    white = s.add_material(Diffuse((0.885809, 0.698859, 0.666422)), "white")
    green = s.add_material(Diffuse((0.105421, 0.37798, 0.076425)), "green")
    red = s.add_material(Diffuse((0.570068, 0.0430135, 0.0443706)), "red")
    _add(s, rectangle(), white, compose(translate((0, 0.99, 0.01)), rotate((1, 0, 0), 90), scale((0.23, 0.19, 0.19))),
         emission=(18.387, 13.9873, 6.75357), name="light")
    _add(s, rectangle(), white, compose(translate((0, -1, 0)), rotate((1, 0, 0), -90)), name="floor")
    _add(s, rectangle(), white, compose(translate((0, 1, 0)), rotate((1, 0, 0), 90)), name="ceiling")
    _add(s, rectangle(), white, translate((0, 0, -1)), name="back")
    _add(s, rectangle(), green, compose(translate((1, 0, 0)), rotate((0, 1, 0), -90)), name="greenwall")
    _add(s, rectangle(), red, compose(translate((-1, 0, 0)), rotate((0, 1, 0), 90)), name="redwall")
    _add(s, cube(), white, compose(translate((0.335, -0.7, 0.38)), rotate((0, 1, 0), -17), scale(0.3)), name="smallbox")
    _add(s, cube(), white, compose(translate((-0.33, -0.4, -0.28)), rotate((0, 1, 0), 18.25), scale((0.3, 0.61, 0.3))), name="largebox")
    _camera(s, 39.3077, [((0, 0, 3.9), (0, 0, 0), (0, 1, 0)), ((0.5, 0.15, 3.8), (0, 0, 0), (0, 1, 0)), ((-0.5, -0.1, 3.8), (0, 0, 0), (0, 1, 0))], fov_axis="smaller")
    s.film = Film(256, 256)
    s.defaults = {"spp": 64, "max_depth": 16}
    return s


def door_ajar() -> Scene:
    s = Scene("door-ajar")
    s.description = "a room lit only through a barely open door (indirect-dominated)"
    wall = s.add_material(Diffuse((0.7, 0.68, 0.62), two_sided=True), "wall")
    floor = s.add_material(Diffuse(0.45), "floor")
    door = s.add_material(Diffuse((0.55, 0.4, 0.25)), "door")
    lit = s.add_material(Diffuse(0.8), "lit-room")
    # the camera's room: x ∈ [-2, 2], y ∈ [0, 2.5], z ∈ [-2, 2]; its back wall (z = -2) has a doorway x ∈ [0.4, 1.2], y < 2
    _room(s, (-2, 0, -2), (2, 2.5, 2), {"default": wall, "floor": floor}, skip=("back",))
    back = compose(translate((0, 0, -2)), scale(1.0))
    for name, (x0, x1, y0, y1) in {"back-left": (-2, 0.4, 0, 2.5), "back-right": (1.2, 2, 0, 2.5), "lintel": (0.4, 1.2, 2.0, 2.5)}.items():
        _add(s, rectangle(), wall, compose(back, translate(((x0 + x1) / 2, (y0 + y1) / 2, 0)), scale(((x1 - x0) / 2, (y1 - y0) / 2, 1))), name=name)
    # the door: hinged at x = 0.4, opened 8° into the far room, a thin box
    _add(s, cube(), door, compose(translate((0.4, 1.0, -2.04)), rotate((0, 1, 0), 8), translate((0.4, 0, 0)), scale((0.395, 0.995, 0.03))), name="door")
    # the lit room behind: z ∈ [-5, -2], with a bright ceiling light
    _room(s, (-2, 0, -5), (2, 2.5, -2.001), {"default": lit}, skip=("front",))
    _panel(s, (0.5, 2.49, -3.5), (0.6, 0.6), rotate((1, 0, 0), 90), lit, emission=(40.0, 36.0, 30.0), name="light")
    # something in the camera's room to catch the light
    _add(s, cube(), wall, compose(translate((-0.8, 0.4, -0.5)), rotate((0, 1, 0), 25), scale(0.4)), name="box")
    _add(s, sphere(), s.add_material(Diffuse((0.6, 0.3, 0.2))), compose(translate((0.6, 0.35, 0.3)), scale(0.35)), name="ball")
    _camera(s, 70, [((-1.6, 1.5, 1.8), (0.6, 0.8, -2.0), (0, 1, 0)), ((0.0, 1.4, 1.9), (0.8, 0.8, -2.0), (0, 1, 0))])
    s.film = Film(320, 240)
    s.defaults = {"spp": 256, "max_depth": 16}
    return s


def red_green_lights() -> Scene:
    s = Scene("red-green-lights")
    s.description = "a white diffuse plane lit by one red and one green light (seed 002, Fig. 2)"
    white = s.add_material(Diffuse(0.8), "white")
    _add(s, rectangle(), white, compose(rotate((1, 0, 0), -90), scale(3.0)), name="plane")
    _panel(s, (-0.9, 1.2, 0.0), (0.15, 0.15), rotate((1, 0, 0), 90), white, emission=(30.0, 0.5, 0.5), name="red-light")
    _panel(s, (0.9, 1.2, 0.0), (0.15, 0.15), rotate((1, 0, 0), 90), white, emission=(0.5, 30.0, 0.5), name="green-light")
    _camera(s, 50, [((0, 1.0, 3.2), (0, 0.2, 0), (0, 1, 0)), ((1.2, 0.9, 2.9), (0, 0.2, 0), (0, 1, 0))])
    s.film = Film(256, 256)
    s.defaults = {"spp": 64, "max_depth": 2}
    return s


def _checker(n: int, res: int) -> np.ndarray:
    i = (np.arange(res) * n // res)
    board = ((i[:, None] + i[None, :]) % 2).astype(np.float32)
    img = 0.02 + 0.78 * board  # black 0.02, white 0.8
    return np.repeat(img[:, :, None], 3, axis=2)


def checker_grid() -> Scene:
    s = Scene("checker-grid")
    s.description = "a black/white grid with sharp edges (seed 000, Fig. 6)"
    tex = s.add_texture(_checker(12, 768), "checker")
    board = s.add_material(Diffuse(TextureRef(tex)), "checker")
    white = s.add_material(Diffuse(0.8), "white")
    _add(s, rectangle(), board, compose(rotate((1, 0, 0), -90), scale(2.0)), name="grid")
    _add(s, cube(), white, compose(translate((0.3, 0.25, 0.2)), rotate((0, 1, 0), 30), scale(0.25)), name="block")
    _panel(s, (-0.8, 2.0, 0.6), (0.5, 0.5), rotate((1, 0, 0), 90), white, emission=(8.0, 8.0, 8.0), name="light")
    s.set_environment(ConstantEnvironment((0.05, 0.06, 0.08)))
    _camera(s, 50, [((0, 2.2, 2.8), (0, 0, 0), (0, 1, 0)), ((-1.2, 1.8, 2.6), (0, 0, 0), (0, 1, 0))])
    s.film = Film(256, 256)
    s.defaults = {"spp": 64, "max_depth": 16}
    return s


def metal_rack() -> Scene:
    s = Scene("metal-rack")
    s.description = "glossy metal bars lit by two lights (seed 000, Fig. 9)"
    floor = s.add_material(Diffuse(0.5), "floor")
    wall = s.add_material(Diffuse(0.6), "wall")
    al_eta, al_k = conductor_material("Al")
    cu_eta, cu_k = conductor_material("Cu")
    alu = s.add_material(RoughConductor(alpha=0.12, eta=al_eta, k=al_k), "aluminium")
    cop = s.add_material(RoughConductor(alpha=0.25, eta=cu_eta, k=cu_k), "copper")
    _add(s, rectangle(), floor, compose(rotate((1, 0, 0), -90), scale(4.0)), name="floor")
    _add(s, rectangle(), wall, compose(translate((0, 2, -1.5)), scale((4, 2, 1))), name="wall")
    for i in range(7):
        x = -1.2 + 0.4 * i
        _add(s, cube(), alu if i % 2 == 0 else cop, compose(translate((x, 0.9, 0)), scale((0.05, 0.9, 0.05))), name=f"post{i}")
    for j, y in enumerate((0.5, 1.1, 1.7)):
        _add(s, cube(), alu, compose(translate((0, y, 0)), rotate((1, 0, 0), 45), scale((1.4, 0.035, 0.035))), name=f"bar{j}")
    white = s.add_material(Diffuse(0.8))
    _panel(s, (-1.8, 2.5, 1.5), (0.3, 0.3), compose(rotate((0, 1, 0), 135), rotate((1, 0, 0), 55)), white, emission=(25, 22, 18), name="light-warm")
    _panel(s, (1.8, 1.5, 1.2), (0.2, 0.2), compose(rotate((0, 1, 0), -120), rotate((1, 0, 0), 20)), white, emission=(12, 16, 30), name="light-cool")
    _camera(s, 45, [((0.3, 1.3, 3.6), (0, 1.0, 0), (0, 1, 0)), ((-1.0, 1.6, 3.2), (0, 1.0, 0), (0, 1, 0))])
    s.film = Film(320, 240)
    s.defaults = {"spp": 128, "max_depth": 16}
    return s


def caustic_slab_plane() -> Scene:
    s = Scene("caustic-slab-plane")
    s.description = "a bumpy two-sided glass slab and a wavy metal plane lit by two small coloured lights (seed 003, Fig. 1)"
    ground = s.add_material(Diffuse(0.7), "ground")
    wall = s.add_material(Diffuse(0.6), "wall")
    glass = s.add_material(Dielectric(int_ior=1.5, bump_amplitude=0.004, bump_frequency=18.0), "slab")
    metal = s.add_material(Conductor(specular_reflectance=(0.95, 0.93, 0.88), two_sided=True, bump_amplitude=0.003, bump_frequency=14.0), "metal")
    white = s.add_material(Diffuse(0.8))
    _add(s, rectangle(), ground, compose(rotate((1, 0, 0), -90), scale(3.0)), name="ground")
    _add(s, rectangle(), wall, compose(translate((0, 1.5, -2.0)), scale((3, 1.5, 1))), name="wall")
    _add(s, cube(), glass, compose(translate((-0.6, 0.7, 0.0)), rotate((0, 0, 1), 10), scale((0.5, 0.04, 0.4))), name="slab")
    _add(s, rectangle(), metal, compose(translate((0.9, 0.5, -0.6)), rotate((0, 1, 0), -35), scale((0.5, 0.5, 1))), name="metal-plane")
    _panel(s, (-0.7, 2.2, 0.3), (0.04, 0.04), rotate((1, 0, 0), 90), white, emission=(900, 600, 250), name="light-warm")
    _panel(s, (0.4, 1.6, 1.4), (0.04, 0.04), compose(rotate((0, 1, 0), 160), rotate((1, 0, 0), 60)), white, emission=(200, 350, 900), name="light-cool")
    _camera(s, 45, [((0, 2.2, 3.4), (0, 0.3, 0), (0, 1, 0)), ((-1.2, 2.0, 3.0), (0, 0.3, 0), (0, 1, 0))])
    s.film = Film(320, 240)
    s.defaults = {"spp": 256, "max_depth": 16}
    return s


def caustic_slab() -> Scene:
    s = Scene("caustic-slab")
    s.description = "a bumpy double-refractive glass slab over a diffuse plane under one small light (seed 003, after Zeltner et al. 2020)"
    ground = s.add_material(Diffuse(0.7), "ground")
    glass = s.add_material(Dielectric(int_ior=1.5, bump_amplitude=0.004, bump_frequency=12.0), "slab")
    white = s.add_material(Diffuse(0.8))
    _add(s, rectangle(), ground, compose(rotate((1, 0, 0), -90), scale(1.5)), name="ground")
    _add(s, cube(), glass, compose(translate((0.0, 0.45, 0.0)), rotate((0, 0, 1), 8), scale((0.45, 0.04, 0.45))), name="slab")
    _panel(s, (0.1, 1.6, 0.05), (0.04, 0.04), rotate((1, 0, 0), 90), white, emission=(600, 560, 500), name="light")
    _camera(s, 40, [((0, 2.6, 1.9), (0, 0.0, -0.05), (0, 1, 0)), ((0.8, 2.4, 1.8), (0, 0.0, 0), (0, 1, 0))])
    s.film = Film(256, 192)
    s.defaults = {"spp": 256, "max_depth": 8}
    return s


def reflective_plane() -> Scene:
    s = Scene("reflective-plane")
    s.description = "a bumpy metal plane throwing a caustic onto a diffuse floor and wall under one small light (seed 003)"
    ground = s.add_material(Diffuse(0.7), "ground")
    wall = s.add_material(Diffuse(0.6), "wall")
    metal = s.add_material(Conductor(specular_reflectance=(0.95, 0.93, 0.88), bump_amplitude=0.003, bump_frequency=10.0), "metal")
    white = s.add_material(Diffuse(0.8))
    _add(s, rectangle(), ground, compose(rotate((1, 0, 0), -90), scale(2.0)), name="ground")
    _add(s, rectangle(), wall, compose(translate((0, 1.0, -1.2)), scale((2, 1, 1))), name="wall")
    # the plane stands at the back tilted 23.6° down, so the light in front is reflected onto the floor
    _add(s, rectangle(), metal, compose(translate((0.3, 0.6, -0.6)), rotate((1, 0, 0), 23.6), scale((0.4, 0.4, 1))), name="metal-plane")
    _panel(s, (-0.4, 1.4, 0.8), (0.04, 0.04), compose(rotate((0, 1, 0), 153.4), rotate((1, 0, 0), 26.7)), white, emission=(500, 480, 440), name="light")
    _camera(s, 45, [((0, 1.6, 2.8), (0, 0.5, -0.4), (0, 1, 0)), ((-0.8, 1.5, 2.6), (0, 0.5, -0.4), (0, 1, 0))])
    s.film = Film(256, 192)
    s.defaults = {"spp": 256, "max_depth": 8}
    return s


def _sky(width: int = 512, height: int = 256, sun_dir: tuple = (0.4, 0.75, -0.5), sun_radius_deg: float = 1.5) -> np.ndarray:
    """An equirectangular sky (Mitsuba's envmap mapping, +y up) with a small, very bright sun."""
    u = (np.arange(width) + 0.5) / width
    v = (np.arange(height) + 0.5) / height
    uu, vv = np.meshgrid(u, v)
    theta, phi = vv * np.pi, (uu * 2 - 1) * np.pi
    # Mitsuba envmap: d = (sin θ sin φ, cos θ, −sin θ cos φ)
    d = np.stack([np.sin(theta) * np.sin(phi), np.cos(theta), -np.sin(theta) * np.cos(phi)], axis=-1)
    up = np.clip(d[..., 1], 0, 1)
    sky = (0.25 + 0.75 * up)[..., None] * np.array([0.35, 0.55, 1.0]) * 0.8
    ground = np.array([0.18, 0.16, 0.14])
    img = np.where((d[..., 1] > 0)[..., None], sky, ground)
    sd = np.asarray(sun_dir, dtype=np.float64)
    sd /= np.linalg.norm(sd)
    cos_sun = d @ sd
    img = img + (cos_sun > np.cos(np.radians(sun_radius_deg)))[..., None] * np.array([5000.0, 4500.0, 3800.0])
    return img.astype(np.float32)


def _pool_basin(s: Scene) -> None:
    """The pool's tiled floor, walls and wavy water (shared by ``pool`` and ``swimming-pool``)."""
    tiles = np.ones((256, 256, 3), np.float32) * np.array([0.55, 0.75, 0.8], np.float32)
    grout = (np.arange(256) % 32) < 2
    tiles[grout, :] = 0.9
    tiles[:, grout] = 0.9
    floor = s.add_material(Diffuse(TextureRef(s.add_texture(tiles, "tiles"))), "tiles")
    wall = s.add_material(Diffuse((0.8, 0.8, 0.75)), "wall")
    water = s.add_material(Dielectric(int_ior=1.33, bump_amplitude=0.01, bump_frequency=6.0), "water")
    _add(s, rectangle(), floor, compose(translate((0, -1, 0)), rotate((1, 0, 0), -90), scale(2.0)), name="floor")
    for name, m in {
        "wall-n": compose(translate((0, -0.5, -2)), scale((2, 0.5, 1))),
        "wall-s": compose(translate((0, -0.5, 2)), rotate((0, 1, 0), 180), scale((2, 0.5, 1))),
        "wall-w": compose(translate((-2, -0.5, 0)), rotate((0, 1, 0), 90), scale((2, 0.5, 1))),
        "wall-e": compose(translate((2, -0.5, 0)), rotate((0, 1, 0), -90), scale((2, 0.5, 1))),
    }.items():
        _add(s, rectangle(), wall, m, name=name)
    _add(s, rectangle(), water, compose(translate((0, -0.15, 0)), rotate((1, 0, 0), -90), scale(2.0)), name="water")


def pool() -> Scene:
    s = Scene("pool")
    s.description = "a wavy water surface over a tiled floor under a sky with a small, bright sun (seed 003)"
    _pool_basin(s)
    s.set_environment(EnvMap(image=_sky(), scale=1.0))
    _pool_camera(s)
    return s


def swimming_pool() -> Scene:
    """``pool`` with its sun as a small, distant area light (1° across) and the sky without it: the same
    caustics from an area emitter instead of the environment (SMS handles both)."""
    s = Scene("swimming-pool")
    s.description = "the wavy pool lit by a distant area-light sun under a sunless sky (seed 003, area-light variant)"
    _pool_basin(s)
    s.set_environment(EnvMap(image=_sky(sun_radius_deg=0.0), scale=1.0))
    sun = np.array([0.4, 0.75, -0.5]) / np.linalg.norm([0.4, 0.75, -0.5])
    white = s.add_material(Diffuse(0.8))
    # a quad 20 units away along the sun direction, facing the pool: half-size 0.175 ≈ 1° across
    yaw = np.degrees(np.arctan2(-sun[0], -sun[2]))
    pitch = np.degrees(np.arcsin(sun[1]))
    _panel(s, tuple(20.0 * sun), (0.175, 0.175), compose(rotate((0, 1, 0), yaw), rotate((1, 0, 0), pitch)), white, emission=(34000, 30600, 25800), name="sun")
    _pool_camera(s)
    return s


def _pool_camera(s: Scene) -> None:
    _camera(s, 55, [((0, 1.8, 3.4), (0, -0.8, 0), (0, 1, 0)), ((1.5, 1.6, 3.0), (0, -0.8, 0), (0, 1, 0))])
    s.film = Film(320, 240)
    s.defaults = {"spp": 256, "max_depth": 16}


def glossy_room() -> Scene:
    s = Scene("glossy-room")
    s.description = "a room with a glossy floor (seed 004, Fig. 9)"
    wall = s.add_material(Diffuse((0.75, 0.72, 0.68)), "wall")
    accent = s.add_material(Diffuse((0.2, 0.35, 0.6)), "accent")
    floor = s.add_material(RoughConductor(alpha=0.08, specular_reflectance=(0.6, 0.55, 0.5)), "glossy-floor")
    _room(s, (-3, 0, -3), (3, 3, 3), {"default": wall, "floor": floor, "left": accent})
    _add(s, cube(), wall, compose(translate((-1.0, 0.5, -1.0)), rotate((0, 1, 0), 20), scale(0.5)), name="box")
    _add(s, sphere(), s.add_material(Diffuse((0.7, 0.2, 0.15))), compose(translate((1.0, 0.6, -0.2)), scale(0.6)), name="ball")
    _panel(s, (0, 2.99, 0), (0.6, 0.6), rotate((1, 0, 0), 90), wall, emission=(15, 14, 12), name="light")
    _camera(s, 60, [((0, 1.6, 2.8), (0, 0.8, -1), (0, 1, 0)), ((-1.5, 1.4, 2.6), (0.3, 0.8, -1), (0, 1, 0))])
    s.film = Film(320, 240)
    s.defaults = {"spp": 256, "max_depth": 16}
    return s


def many_lights() -> Scene:
    s = Scene("many-lights")
    s.description = "hundreds of small coloured emitters over a floor with blocks"
    floor = s.add_material(Diffuse(0.6), "floor")
    block = s.add_material(Diffuse((0.7, 0.7, 0.65)), "block")
    _add(s, rectangle(), floor, compose(rotate((1, 0, 0), -90), scale(4.0)), name="floor")
    rng = np.random.default_rng(2025)
    for i in range(12):
        x, z = rng.uniform(-3, 3, 2)
        h = rng.uniform(0.2, 1.0)
        _add(s, cube(), block, compose(translate((x, h, z)), rotate((0, 1, 0), rng.uniform(0, 90)), scale((0.25, h, 0.25))), name=f"block{i}")
    light_mat = s.add_material(Diffuse(0.5))
    n = 0
    for gx in np.linspace(-3.5, 3.5, 20):
        for gz in np.linspace(-3.5, 3.5, 20):
            color = rng.uniform(0.1, 1.0, 3)
            color = color / color.max() * rng.uniform(20, 60)
            y = rng.uniform(1.8, 2.6)
            _panel(s, (gx, y, gz), (0.04, 0.04), rotate((1, 0, 0), 90), light_mat, emission=tuple(color), name=f"light{n}")
            n += 1
    _camera(s, 60, [((0, 1.1, 5.0), (0, 1.3, 0), (0, 1, 0)), ((3.0, 1.0, 4.0), (0, 1.3, 0), (0, 1, 0))])
    s.film = Film(320, 240)
    s.defaults = {"spp": 64, "max_depth": 16}
    return s


def closed_room() -> Scene:
    """Depth matters here: every wall reflects 85%, nothing escapes, the light is small.

    Paths of more than 10 segments carry about a fifth of the image (``tests`` measure it), so a
    renderer that truncates, underflows or mis-weights long paths is visibly wrong here.
    """
    s = Scene("closed-room")
    s.description = "a closed room of bright walls (albedo 0.85) and one small light: long paths matter"
    wall = s.add_material(Diffuse((0.85, 0.85, 0.85)), "wall")
    warm = s.add_material(Diffuse((0.9, 0.8, 0.7)), "warm")
    blue = s.add_material(Diffuse((0.6, 0.7, 0.9)), "blue")
    _room(s, (-2, 0, -2), (2, 2.5, 2), {"default": wall, "left": warm, "right": blue})
    _add(s, cube(), wall, compose(translate((-0.7, 0.45, -0.6)), rotate((0, 1, 0), 25), scale(0.45)), name="box")
    _add(s, sphere(), warm, compose(translate((0.8, 0.4, 0.2)), scale(0.4)), name="ball")
    # a small light facing down; its back is the room's (black) side of the panel, so it reflects like the ceiling
    _panel(s, (0.0, 2.49, 0.0), (0.2, 0.2), rotate((1, 0, 0), 90), wall, emission=(60.0, 55.0, 48.0), name="light")
    _camera(s, 70, [((-1.2, 1.4, 1.9), (0.3, 0.9, -1.5), (0, 1, 0)), ((1.2, 1.3, 1.9), (-0.3, 0.9, -1.5), (0, 1, 0))])
    s.film = Film(320, 240)
    s.defaults = {"spp": 256, "max_depth": -1}
    return s


BUILTIN_SCENES: dict[str, Callable[[], Scene]] = {
    "cornell-box": cornell_box,
    "door-ajar": door_ajar,
    "red-green-lights": red_green_lights,
    "checker-grid": checker_grid,
    "metal-rack": metal_rack,
    "caustic-slab-plane": caustic_slab_plane,
    "pool": pool,
    "swimming-pool": swimming_pool,
    "caustic-slab": caustic_slab,
    "reflective-plane": reflective_plane,
    "glossy-room": glossy_room,
    "many-lights": many_lights,
    "closed-room": closed_room,
}


def build_builtin(name: str) -> Scene:
    """The built-in scene ``name`` (a fresh :class:`Scene` each call)."""
    try:
        return BUILTIN_SCENES[name]()
    except KeyError:
        raise UnknownNameError("scene", name, sorted(BUILTIN_SCENES)) from None


def scene_summaries() -> dict[str, str]:
    """name → one-line description."""
    return {name: build_builtin(name).description for name in BUILTIN_SCENES}


# A moving object for the temporal tests: the Cornell box's small box slides back and forth.
def cornell_box_moving() -> Scene:
    s = cornell_box()
    s.name = "cornell-box-moving"
    obj = next(i for i, o in enumerate(s.objects) if o.name == "smallbox")
    s.objects[obj].motion = RigidMotion(velocity=(0.01, 0, 0), angular_velocity=1.0, axis=(0, 1, 0), pivot=(0.335, -0.7, 0.38), period=60)
    return s


# Glass for the reuse tests: glossy-room's ball of rough glass and its box of smooth glass, beside the glossy floor.
def glossy_room_glass() -> Scene:
    s = glossy_room()
    s.name = "glossy-room-glass"
    s.description = "glossy-room with a ball of rough glass and a box of smooth glass"
    materials = {"ball": s.add_material(RoughDielectric(alpha=0.15, int_ior=1.5), "rough-glass"),
                 "box": s.add_material(Dielectric(int_ior=1.5), "glass")}
    for o in s.objects:
        o.material = materials.get(o.name, o.material)
    return s
