"""The G-buffer: what every ReSTIR pass reads about each pixel's primary hit.

One camera ray per pixel — through the pixel centre, or through the frame's
jittered camera sample (:func:`~grisx.scene.camera.sample_camera`) — fills
structure-of-arrays buffers with the primary hit's full surface interaction
and direction to the camera (the *visible point* the screen-space ReSTIR
renderers shade and reuse), its position, geometric and shading normals, albedo (the BSDF's
average reflectance, which ReSTCV's α heuristic needs — seed 002, Eq. 9),
roughness (which the hybrid shift tests against 0.2), material id, linear
(camera-space) depth, triangle and barycentrics, emitted radiance, and the
**motion vector into the previous frame**: the hit point is carried back
through its object's rigid motion and projected with the previous camera,
minus its projection with this frame's (exactly 0 where nothing moved),
giving a fractional pixel offset (seed 000's pixel pairs are reprojected
with subpixel motion vectors) and its rounded integer version (seed 004's
temporal reuse looks up one pixel).

:class:`GBuffer` keeps the previous frame's buffers beside the current ones
(``swap`` at the start of each frame) for temporal reuse and for the
similarity tests (normals within 25°, normalized depth within 0.05;
seed 004, Sec. 5).
"""

from __future__ import annotations

import functools
from typing import Any

import warp as wp

from grisx.device import launch, specialized_module
from grisx.scene.bsdf import make_bsdf
from grisx.scene.camera import CameraData, camera_project, camera_ray, camera_sample_key, sample_camera
from grisx.scene.lights import make_lights
from grisx.scene.material import SCENE_MOVING_OBJECTS
from grisx.scene.scene import BuiltScene, SceneData, SurfaceInteraction, make_surface

wp.set_module_options({"enable_backward": False})

__all__ = ["GBufferData", "GBuffer", "GBUFFER_FIELDS", "make_gbuffer_kernel"]

#: field name → (Warp dtype, channels in an image dump); ``si`` and ``wo`` (the visible point) are not images
GBUFFER_FIELDS = {
    "position": (wp.vec3, 3),
    "normal_geo": (wp.vec3, 3),
    "normal": (wp.vec3, 3),
    "albedo": (wp.vec3, 3),
    "roughness": (float, 1),
    "material": (wp.int32, 1),
    "depth": (float, 1),
    "tri": (wp.int32, 1),
    "bary": (wp.vec2, 2),
    "motion": (wp.vec2, 2),
    "motion_int": (wp.vec2i, 2),
    "emission": (wp.vec3, 3),
    "hit": (wp.int32, 1),
}


@wp.struct
class GBufferData:
    position: wp.array2d(dtype=wp.vec3)
    normal_geo: wp.array2d(dtype=wp.vec3)
    normal: wp.array2d(dtype=wp.vec3)  # shading normal
    albedo: wp.array2d(dtype=wp.vec3)
    roughness: wp.array2d(dtype=float)
    material: wp.array2d(dtype=wp.int32)  # −1: no hit
    depth: wp.array2d(dtype=float)  # camera-space z; 0 where nothing was hit
    tri: wp.array2d(dtype=wp.int32)
    bary: wp.array2d(dtype=wp.vec2)
    motion: wp.array2d(dtype=wp.vec2)  # previous-frame pixel position minus this pixel's, fractional (may leave the film)
    motion_int: wp.array2d(dtype=wp.vec2i)  # the same, rounded to whole pixels
    emission: wp.array2d(dtype=wp.vec3)  # radiance emitted toward the camera (environment where nothing was hit)
    hit: wp.array2d(dtype=wp.int32)
    si: wp.array2d(dtype=SurfaceInteraction)  # the visible point (valid = 0 where nothing was hit)
    wo: wp.array2d(dtype=wp.vec3)  # unit direction from it to the camera (−ray direction)


@functools.cache
def make_gbuffer_kernel(kinds: frozenset[int], material: bool = True) -> Any:
    """The G-buffer kernel for the material kinds ``kinds`` (cached): its albedo and roughness are the BSDF's, whose
    dispatch is compiled for the scene's kinds as the renderers' are (the all-kinds one cost a 1080p frame up to
    1 ms more on an H200 once principled, pplastic and blends joined it). Without ``material`` the kernel leaves
    albedo and roughness at 0 and resolves no material: on a glossy or textured scene that is a third of its work
    (glossy-room 160×120, one CPU core: 9.5 → 6.3 ms)."""
    bsdf = make_bsdf(kinds)
    surface = make_surface(kinds)  # the wrappers and shapes of these kinds only
    lights = make_lights(kinds)  # the lights of these kinds only
    emitter_radiance, environment_eval = lights.emitter_radiance, lights.environment_eval
    surface_material, intersect = surface.surface_material, surface.intersect

    @wp.kernel(module=specialized_module(__name__ + ("" if material else ".geometry"), kinds))
    def gbuffer_kernel(
        scene: SceneData,
        cam: CameraData,
        cam_prev: CameraData,
        transforms: wp.array(dtype=wp.mat44),
        transforms_prev: wp.array(dtype=wp.mat44),
        seed: int,
        frame: int,
        jitter: int,
        g: GBufferData,
    ):
        y, x = wp.tid()
        cs = sample_camera(cam, camera_sample_key(seed, frame, y * cam.width + x), x, y, jitter)
        ray = camera_ray(cam, cs.pixel[0], cs.pixel[1], cs.lens)
        si = intersect(scene, ray.o, ray.d, cam.far_clip)
        g.si[y, x] = si
        g.wo[y, x] = -ray.d
        zero3 = wp.vec3(0.0, 0.0, 0.0)
        if si.valid == 0:
            g.position[y, x] = zero3
            g.normal_geo[y, x] = zero3
            g.normal[y, x] = zero3
            if wp.static(material):
                g.albedo[y, x] = zero3
                g.roughness[y, x] = 0.0
            g.material[y, x] = -1
            g.depth[y, x] = 0.0
            g.tri[y, x] = -1
            g.bary[y, x] = wp.vec2(0.0, 0.0)
            g.motion[y, x] = wp.vec2(0.0, 0.0)
            g.motion_int[y, x] = wp.vec2i(0, 0)
            g.emission[y, x] = environment_eval(scene.lights, ray.d)
            g.hit[y, x] = 0
            return
        g.position[y, x] = si.p
        g.normal_geo[y, x] = si.ng
        g.normal[y, x] = si.ns
        if wp.static(material):
            m = surface_material(scene, si)
            g.albedo[y, x] = bsdf.albedo(m)
            g.roughness[y, x] = bsdf.roughness(m)
        g.material[y, x] = si.material
        g.depth[y, x] = wp.transform_point(cam.to_camera, si.p)[2]
        g.tri[y, x] = si.tri
        g.bary[y, x] = si.bary
        g.emission[y, x] = emitter_radiance(scene.lights, si.tri, si.p, si.ng, -ray.d)
        g.hit[y, x] = 1
        # ---- motion vector: back through the object's motion, then the previous camera ----
        # The point is projected with both cameras after the same round trip through its object's frame, so what
        # did not move has no motion, to the bit: measured against the camera sample, the round trip's rounding
        # alone (≈ 5e-6 px here, more on a GPU with a scene in large units) read as motion and sent a static
        # camera's temporal film shifts off their identity (ReSTIR G-PT's unit invariance on the H200).
        # A scene whose objects never move (no SCENE_MOVING_OBJECTS kind) has identity transforms: no round trip, and no
        # 4×4 inverse a pixel (8% of this kernel on a CPU core, door-ajar 160×120).
        p_base = si.p
        p_prev = si.p
        p_here = si.p
        if wp.static(SCENE_MOVING_OBJECTS in kinds):
            p_base = wp.transform_point(wp.inverse(transforms[si.object]), si.p)
            p_prev = wp.transform_point(transforms_prev[si.object], p_base)
            p_here = wp.transform_point(transforms[si.object], p_base)
        proj = camera_project(cam_prev, p_prev)
        here = camera_project(cam, p_here)
        mv = wp.vec2(0.0, 0.0)
        if proj.valid != 0 and here.valid != 0:
            mv = proj.pixel - here.pixel
        g.motion[y, x] = mv
        # the previous frame's pixel that holds the point, relative to this one (round(mv) at the pixel centre)
        q = cs.pixel + mv
        g.motion_int[y, x] = wp.vec2i(int(wp.floor(q[0])) - x, int(wp.floor(q[1])) - y)

    return gbuffer_kernel


def _alloc(width: int, height: int, device: wp.context.Device) -> GBufferData:
    g = GBufferData()
    for name, (dtype, _) in GBUFFER_FIELDS.items():
        setattr(g, name, wp.zeros((height, width), dtype=dtype, device=device))
    g.si = wp.zeros((height, width), dtype=SurfaceInteraction, device=device)
    g.wo = wp.zeros((height, width), dtype=wp.vec3, device=device)
    return g


class GBuffer:
    """Current and previous G-buffers of a film, filled per frame from a built scene."""

    def __init__(self, width: int, height: int, device: wp.context.Device, material: bool = True) -> None:
        self.width = int(width)
        self.height = int(height)
        self.device = device
        self.material = bool(material)  # false: albedo and roughness stay 0 (see make_gbuffer_kernel)
        self.current = _alloc(self.width, self.height, device)
        self.previous = _alloc(self.width, self.height, device)

    def kernel(self, built: BuiltScene) -> Any:
        """The G-buffer kernel for ``built``'s material kinds (what :meth:`fill` launches)."""
        return make_gbuffer_kernel(built.features.kernel_kinds, self.material)

    def swap(self) -> None:
        self.current, self.previous = self.previous, self.current

    def fill(self, built: BuiltScene, frame: float, seed: int = 0, jitter: bool = False) -> GBufferData:
        """Swap, then trace this frame's primary hits (the scene must already be at ``frame``).

        At the pixel centres, or with ``jitter`` at the camera samples of ``seed`` and ``frame``
        (:func:`~grisx.scene.camera.camera_sample_key`): the points a jittered renderer shades.
        """
        self.swap()
        kernel = self.kernel(built)
        cam = built.camera_data(frame, self.width, self.height)
        cam_prev = built.camera_data(frame - 1.0, self.width, self.height)
        launch(
            kernel,
            dim=(self.height, self.width),
            inputs=[
                built.data, cam, cam_prev, built.object_transforms, built.object_transforms_prev,
                int(seed), int(frame), int(bool(jitter)),
            ],
            outputs=[self.current],
            device=self.device,
        )
        return self.current

    def numpy(self, which: str = "current") -> dict[str, object]:
        g = getattr(self, which)
        return {name: getattr(g, name).numpy() for name in GBUFFER_FIELDS}
