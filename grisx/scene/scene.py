"""Scenes: a builder on the host and a :class:`SceneData` record on the device.

A grisx scene is everything a renderer in the seeds needs at a surface point:

* **geometry** — all triangles of all objects in *one* world-space
  ``wp.Mesh`` (one BVH), with per-triangle material id, object id and flags,
  per-vertex shading normals and UVs. Rigid motion (:class:`RigidMotion`)
  moves an object's vertices each frame; the BVH is then *refit* (topology
  does not change under rigid motion, so a rebuild is never needed), and
  nothing is done at all on frames where no object moved;
* **materials** (:mod:`grisx.scene.material`) with optional albedo textures
  (:mod:`grisx.scene.texture`) and procedural normal perturbation (bumpy
  and wavy surfaces: seed 003's caustic casters);
* **lights** (:mod:`grisx.scene.lights`): emissive triangles, point lights
  and an environment;
* a **camera** (:mod:`grisx.scene.camera`), static or on a keyframed path,
  and a film size; ``defaults`` carries a scene file's sample count and
  maximum depth.

:class:`Scene` is the builder the Mitsuba loader and the built-in scenes
use; :meth:`Scene.build` uploads it and returns a :class:`BuiltScene` whose
``data`` is the :class:`SceneData` struct kernels take. Surface queries
(:func:`intersect`, :func:`occluded`, :func:`surface_material`) live here so
every renderer reads surfaces the same way.

:class:`SceneFeatures` records what a scene uses (material kinds, delta
BSDFs, textures, bump, light types, motion) so that renderers compile only
the code a scene needs (DESIGN.md, "Skip what a scene doesn't need").
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Iterable, Sequence
from typing import Any, NamedTuple

import numpy as np
import warp as wp

from grisx.device import launch, resolve_device
from grisx.errors import InvalidParameterError, InvalidValueError
from grisx.scene.analytic import (
    SHAPE_KIND_NAMES,
    AnalyticShape,
    ShapeSet,
    build_shape_set,
    intersect_shapes,
    shape_bounds,
    shape_normal_derivative,
    shape_surface,
    shapes_occluded,
)
from grisx.scene.camera import Camera, CameraData, CameraPath
from grisx.scene.lights import ConstantEnvironment, DirectionalLight, EnvMap, LightSample, LightSet, PointLight, Projector, build_light_set
from grisx.scene.frame import frame_from_normal, to_local, to_world
from grisx.scene.material import (
    ALL_MATERIAL_KINDS,
    MATERIAL_ANISOTROPIC,
    MATERIAL_BUMPMAP,
    MATERIAL_NORMALMAP,
    MATERIAL_PROCEDURAL_BUMP,
    MATERIAL_REFLECTANCE_TEXTURE,
    MATERIAL_SCALAR_TEXTURES,
    SCENE_ANALYTIC_SHAPES,
    SCENE_DELTA_LIGHTS,
    SCENE_EMITTER_TEXTURES,
    SCENE_ENVMAP,
    SCENE_MOVING_OBJECTS,
    MATERIAL_CONDUCTOR,
    MATERIAL_DIELECTRIC,
    MATERIAL_MASK,
    MATERIAL_NULL,
    PERTURB_NONE,
    PERTURB_NORMALMAP,
    MATERIAL_ROUGH_DIELECTRIC,
    MATERIAL_THIN_DIELECTRIC,
    Material,
    kernel_kinds,
    material_kinds,
    pack_materials,
    unwrap,
)
from grisx.scene.principled import principled_set_slot
from grisx.scene.texture import (
    TEXTURE_MESH_ATTRIBUTE,
    AttributeTexels,
    Bitmap,
    Checkerboard,
    MeshAttribute,
    TextureSet,
    attribute_lookup,
    pack_textures,
    texture_gradient,
    texture_lookup,
    texture_lookup_1,
)
from grisx.theory.gris import luminance
from grisx.scene.transform import rotate, translate

wp.set_module_options({"enable_backward": False})

__all__ = [
    "Scene",
    "BuiltScene",
    "SceneData",
    "SceneFeatures",
    "SurfaceInteraction",
    "RigidMotion",
    "Film",
    "intersect",
    "occluded",
    "segment_occluded",
    "light_occluded",
    "ShadowRay",
    "shadow_ray_along",
    "shadow_ray_between",
    "shadow_ray_to_light",
    "finite_or_dropped",
    "surface_material",
    "surface_material_at",
    "make_surface",
    "SurfaceFuncs",
    "surface_texture",
    "surface_texture_1",
    "stored_surface",
    "triangle_barycentrics",
    "spawn_origin",
    "shading_normal_derivative",
    "TRI_HAS_NORMALS",
    "TRI_HAS_UVS",
]

TRI_HAS_NORMALS = wp.constant(1)
TRI_HAS_UVS = wp.constant(2)


# ---- host-side records ---------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Film:
    """Mitsuba's ``hdrfilm``: the output size and the reconstruction filter."""

    width: int = 256
    height: int = 256
    filter_stddev: float = 0.0  # reconstruction filter: 0 = box (the pixel's area), else Mitsuba's gaussian (pixels)
    filter_tent: float = 0.0  # or, when > 0, Mitsuba's tent filter of this radius (pixels)

    def __post_init__(self) -> None:
        for name in ("width", "height"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not (1 <= v <= 16384):
                raise InvalidParameterError(f"film {name} must be an integer in [1, 16384], got {v!r}")
        sd = self.filter_stddev
        if isinstance(sd, bool) or not isinstance(sd, (int, float, np.floating, np.integer)) or not (math.isfinite(sd) and 0 <= sd <= 64):
            raise InvalidParameterError(f"film filter_stddev must be 0 (box) or a gaussian's standard deviation in (0, 64] pixels, got {sd!r}")
        r = self.filter_tent
        if isinstance(r, bool) or not isinstance(r, (int, float, np.floating, np.integer)) or not (math.isfinite(r) and 0 <= r <= 64):
            raise InvalidParameterError(f"film filter_tent must be 0 (none) or a tent filter's radius in (0, 64] pixels, got {r!r}")
        if sd > 0 and r > 0:
            raise InvalidParameterError(f"a film has one reconstruction filter: filter_stddev {sd} (gaussian) and filter_tent {r} both set")


@dataclasses.dataclass(frozen=True)
class RigidMotion:
    """Rigid per-frame motion of an object on top of its ``to_world``.

    M(t) = T(pivot + velocity·s(t)) · R(axis, angular_velocity·s(t)) · T(−pivot),
    with s(t) = t, or ``period/(2π)·sin(2π t/period)`` when ``period`` is set
    (a back-and-forth motion that returns to the start).
    """

    velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    angular_velocity: float = 0.0  # degrees per frame
    axis: tuple[float, float, float] = (0.0, 1.0, 0.0)
    pivot: tuple[float, float, float] = (0.0, 0.0, 0.0)
    period: float | None = None

    def transform(self, frame: float) -> np.ndarray:
        s = frame if not self.period else self.period / (2 * math.pi) * math.sin(2 * math.pi * frame / self.period)
        pivot = np.asarray(self.pivot, dtype=np.float64)
        moved = translate(pivot + np.asarray(self.velocity, dtype=np.float64) * s)
        return moved @ rotate(self.axis, self.angular_velocity * s) @ translate(-pivot)


@dataclasses.dataclass
class _Object:
    name: str
    vertices: np.ndarray  # world space at frame 0 (to_world applied)
    faces: np.ndarray
    normals: np.ndarray | None
    uvs: np.ndarray | None
    material: int
    emission: np.ndarray | None
    motion: RigidMotion | None
    # an analytic shape (then ``vertices`` are the corners of its box, ``faces`` empty)
    shape: AnalyticShape | None = None
    attributes: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)  # Mitsuba's mesh attributes


def _textured_emission(emission: Any) -> bool:
    """Whether an object's ``emission`` is a radiance image (Mitsuba's area emitter with a bitmap), not a colour."""
    return emission is not None and (isinstance(emission, Bitmap) or np.ndim(emission) >= 2)


@dataclasses.dataclass(frozen=True)
class SceneFeatures:
    """What a scene uses; renderers specialize their kernels on it."""

    material_kinds: frozenset[int]  # with the pseudo-kinds (grisx.scene.material), the SCENE_* ones among them
    has_textures: bool
    has_bump: bool
    has_area_lights: bool
    has_point_lights: bool
    environment: str  # "none", "constant" or "envmap"
    has_delta: bool
    has_dielectric: bool
    has_caustic_casters: bool  # delta or near-specular surfaces that can focus light (seed 003)
    animated_camera: bool
    animated_objects: bool

    @property
    def kernel_kinds(self) -> frozenset[int]:
        """The kinds renderers compile their kernels for: the scene's (``GRISX_KERNEL_KINDS``, :func:`kernel_kinds`)."""
        return kernel_kinds(self.material_kinds)

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["material_kinds"] = sorted(self.material_kinds)
        return d


# ---- device-side records -------------------------------------------------------


@wp.struct
class SceneData:
    mesh: wp.uint64
    positions: wp.array(dtype=wp.vec3)  # world space, this frame
    indices: wp.array(dtype=wp.int32)  # 3 per triangle
    normals: wp.array(dtype=wp.vec3)  # world-space vertex normals (unused where the flag is clear)
    uvs: wp.array(dtype=wp.vec2)
    tri_material: wp.array(dtype=wp.int32)
    tri_object: wp.array(dtype=wp.int32)
    tri_flags: wp.array(dtype=wp.int32)
    materials: wp.array(dtype=Material)
    textures: TextureSet
    lights: LightSet
    ray_epsilon: float  # scaled to the scene's size
    scene_radius: float
    object_center: wp.array(dtype=wp.vec3)  # per object: centre of its bounding sphere, this frame (caustics' seed space)
    object_radius: wp.array(dtype=float)  # per object: radius of that sphere
    # what moved between the frames of a shift across frames (:meth:`BuiltScene.across_frames`): the boxes that
    # bound each object that moved, at both frames; none (``moved_count`` 0) within a frame
    moved_lo: wp.array(dtype=wp.vec3)
    moved_hi: wp.array(dtype=wp.vec3)
    moved_count: int
    shapes: ShapeSet  # analytic spheres, disks, cylinders (grisx.scene.analytic); primitive ids after the triangles


@wp.struct
class SurfaceInteraction:
    valid: int
    t: float
    p: wp.vec3
    ng: wp.vec3  # geometric normal (winding order)
    ns: wp.vec3  # shading normal (interpolated, perturbed), same side as ng
    uv: wp.vec2
    bary: wp.vec2  # Warp's (u, v): p = u·p0 + v·p1 + (1−u−v)·p2; uv on an analytic shape
    tri: int  # primitive id: a triangle, or an analytic shape (ShapeSet.prim_base + its index)
    material: int
    object: int
    front: int  # 1 when the ray arrived on the side ng points to


@wp.struct
class ShadowRay:
    """A segment to test for blockers: ``o + t·d`` (d unit), 0 < t < ``t_max``; ``valid`` = 0 for an empty segment.

    Visibility tests build this record first and trace it at one place (``blocked``): the traversal is inlined at
    every call site, so a kernel that picks among several kinds of segment and then traces one holds one copy of
    the BVH code instead of one per kind (sm_90: ~7 KB of SASS each, benchmarks/README, "kernels.py").
    """

    o: wp.vec3
    d: wp.vec3
    t_max: float
    valid: int


@wp.func
def motion_touches(scene: SceneData, lo: wp.vec3, hi: wp.vec3) -> bool:
    """Whether the box [``lo``, ``hi``] meets anything that moved between the frames ``scene`` was taken across.

    A sample that reuses a part of itself across frames may do so only where that part is the same in
    both frames: ReSTIR GI's L_o (the box of the path that estimated it: its segments lie in it) and
    ReSTIR DI's light point are tested so; a reconnection suffix, segment by segment
    (:func:`motion_on_segment`). Within one frame nothing moved (0 boxes).
    """
    for i in range(scene.moved_count):
        a = scene.moved_lo[i]
        b = scene.moved_hi[i]
        if lo[0] <= b[0] and hi[0] >= a[0] and lo[1] <= b[1] and hi[1] >= a[1] and lo[2] <= b[2] and hi[2] >= a[2]:
            return True
    return False


@wp.func
def motion_on_segment(scene: SceneData, a: wp.vec3, d: wp.vec3, t_max: float) -> bool:
    """Whether the segment a + t·d, t ∈ [0, ``t_max``] (``d`` unit; 1e30: a ray to infinity) meets a box of what
    moved between the frames ``scene`` was taken across (:func:`motion_touches`): the slab test per box."""
    for i in range(scene.moved_count):
        lo = scene.moved_lo[i]
        hi = scene.moved_hi[i]
        t0 = float(0.0)
        t1 = t_max
        for c in range(3):
            if wp.abs(d[c]) < 1.0e-12:
                if a[c] < lo[c] or a[c] > hi[c]:
                    t0 = 1.0  # parallel to this slab and outside it: no overlap (t0 > t1 below)
                    t1 = 0.0
            else:
                ta = (lo[c] - a[c]) / d[c]
                tb = (hi[c] - a[c]) / d[c]
                t0 = wp.max(t0, wp.min(ta, tb))
                t1 = wp.min(t1, wp.max(ta, tb))
        if t0 <= t1:
            return True
    return False


@wp.func
def spawn_origin(scene: SceneData, p: wp.vec3, ng: wp.vec3, d: wp.vec3) -> wp.vec3:
    """Offset ``p`` off the surface to the side ``d`` leaves on (avoids self-intersection)."""
    if wp.dot(d, ng) >= 0.0:
        return p + ng * scene.ray_epsilon
    return p - ng * scene.ray_epsilon


@wp.func
def _bump_gradient(p: wp.vec3, amplitude: float, frequency: float) -> wp.vec3:
    # ∇h for h(p) = A·[sin(f a₁·p) + sin(f a₂·p) + ½ sin(2.1 f a₃·p)] over world position p, three fixed
    # directions a_k: A·f sets the slope, f the wavelength; smooth, so manifold walks (seed 003) converge on it
    a1 = wp.vec3(0.8, 0.1, 0.59)
    a2 = wp.vec3(-0.36, 0.2, 0.91)
    a3 = wp.vec3(0.55, -0.6, -0.58)
    f = frequency
    g = a1 * wp.cos(f * wp.dot(a1, p)) + a2 * wp.cos(f * wp.dot(a2, p)) + a3 * (1.05 * wp.cos(2.1 * f * wp.dot(a3, p)))
    return g * (amplitude * f)


@wp.func
def perturb_normal(n: wp.vec3, p: wp.vec3, amplitude: float, frequency: float) -> wp.vec3:
    """The shading normal of the height field h over the surface with normal ``n`` (the material's bump_* fields)."""
    g = _bump_gradient(p, amplitude, frequency)
    g_t = g - n * wp.dot(g, n)  # tangential part
    return wp.normalize(n - g_t)


@wp.func
def _bump_hessian_times(p: wp.vec3, amplitude: float, frequency: float, v: wp.vec3) -> wp.vec3:
    # H·v for the height field of _bump_gradient: ∂(∇h) along v (each term a_k cos(c f a_k·p) differentiates
    # to −c f a_k (a_k·v) sin(c f a_k·p))
    a1 = wp.vec3(0.8, 0.1, 0.59)
    a2 = wp.vec3(-0.36, 0.2, 0.91)
    a3 = wp.vec3(0.55, -0.6, -0.58)
    f = frequency
    h = (a1 * (wp.dot(a1, v) * wp.sin(f * wp.dot(a1, p))) + a2 * (wp.dot(a2, v) * wp.sin(f * wp.dot(a2, p)))
         + a3 * (1.05 * 2.1 * wp.dot(a3, v) * wp.sin(2.1 * f * wp.dot(a3, p))))
    return h * (-amplitude * f * f)


@wp.func
def perturb_normal_derivative(n: wp.vec3, dn: wp.vec3, p: wp.vec3, dp: wp.vec3, amplitude: float, frequency: float) -> wp.vec3:
    """∂ of :func:`perturb_normal`'s n' = normalize(n − g_t), g_t = g − n(g·n), g = ∇h(p), for the base normal's
    change ``dn`` and the point's ``dp``: ∂g = H ∂p (the height field's Hessian)."""
    g = _bump_gradient(p, amplitude, frequency)
    dg = _bump_hessian_times(p, amplitude, frequency, dp)
    gn = wp.dot(g, n)
    dg_t = dg - dn * gn - n * (wp.dot(dg, n) + wp.dot(g, dn))
    m = n - (g - n * gn)
    length = wp.length(m)
    n_p = m / length
    dm = dn - dg_t
    return (dm - n_p * wp.dot(n_p, dm)) / length


@wp.func
def shadow_ray_along(scene: SceneData, o: wp.vec3, d: wp.vec3, dist: float) -> ShadowRay:
    """The segment o → o + dist·d (d unit, o already lifted off its surface); the end point's surface is excluded."""
    r = ShadowRay()
    r.o = o
    r.d = d
    r.t_max = dist * (1.0 - 1.0e-4) - scene.ray_epsilon
    r.valid = 1
    return r


@wp.func
def shadow_ray_between(scene: SceneData, p0: wp.vec3, n0: wp.vec3, p1: wp.vec3, n1: wp.vec3) -> ShadowRay:
    """The segment between surface points p0 and p1 (geometric normals n0, n1).

    Both ends are lifted off their surfaces toward each other (pbrt-v4's
    ``SpawnRayTo``). Lifting only the origin moves the point where the ray
    meets p1's plane by ε/cos θ₁, which at grazing angles lands *before* p1,
    so p1's own triangle would read as an occluder. A zero ``n1`` (a point
    light) leaves p1 where it is.
    """
    d = p1 - p0
    o = spawn_origin(scene, p0, n0, d)
    t = spawn_origin(scene, p1, n1, -d)
    e = t - o
    dist = wp.length(e)
    r = ShadowRay()
    r.valid = 0
    if dist <= 0.0:
        return r
    r.o = o
    r.d = e / dist
    r.t_max = dist
    r.valid = 1
    return r


@wp.func
def shadow_ray_to_light(scene: SceneData, p: wp.vec3, ng: wp.vec3, ls: LightSample) -> ShadowRay:
    """The shadow ray of next-event sample ``ls`` from surface point ``p`` (geometric normal ``ng``).

    The environment is a direction (a ray to infinity); emitters are surface
    points (:func:`shadow_ray_between`); point lights are points off every surface.
    """
    if ls.is_env != 0:
        return shadow_ray_along(scene, spawn_origin(scene, p, ng, ls.wi), ls.wi, ls.dist)
    n1 = ls.n
    if ls.delta != 0:
        n1 = wp.vec3(0.0, 0.0, 0.0)
    return shadow_ray_between(scene, p, ng, ls.p, n1)


@functools.cache
def _make_ray_queries(shapes: bool, bump: bool) -> tuple[Any, ...]:
    """The ray queries (the last fields of :class:`SurfaceFuncs`, in its order) with or without the analytic shapes,
    and with or without the materials' procedural bump."""
    # the analytic-shape queries (a BVH traversal and three quadrics) only where the scene has shapes: each query is
    # inlined at every call site of every kernel, and a scene without shapes would compile them for nothing
    # (benchmarks/README, "A compile-time regression")

    @wp.func
    def intersect(scene: SceneData, o: wp.vec3, d: wp.vec3, tmax: float) -> SurfaceInteraction:
        """Closest hit of the ray o + t·d (d unit), 0 < t < tmax: triangles, then analytic shapes before that hit."""
        si = SurfaceInteraction()
        si.valid = 0
        q = wp.mesh_query_ray(scene.mesh, o, d, tmax)
        shape = int(-1)
        if wp.static(shapes):
            if scene.shapes.count > 0:  # uniform
                t_shape = tmax
                if q.result:
                    t_shape = q.t
                hit = intersect_shapes(scene.shapes, o, d, t_shape)
                shape = int(hit[1])
                if shape >= 0:
                    s = shape_surface(scene.shapes, shape, o, d, hit[0])
                    si.t = hit[0]
                    si.tri = scene.shapes.prim_base + shape
                    si.bary = s.uv
                    si.p = s.p
                    si.ng = s.n
                    si.uv = s.uv
        if shape < 0:
            if not q.result:
                return si
            tri = q.face
            i0 = scene.indices[3 * tri + 0]
            i1 = scene.indices[3 * tri + 1]
            i2 = scene.indices[3 * tri + 2]
            b0 = q.u
            b1 = q.v
            b2 = 1.0 - b0 - b1
            si.t = q.t
            si.tri = tri
            si.bary = wp.vec2(b0, b1)
            si.p = o + d * q.t
            p0 = scene.positions[i0]
            p1 = scene.positions[i1]
            p2 = scene.positions[i2]
            si.ng = wp.normalize(wp.cross(p1 - p0, p2 - p0))
            flags = scene.tri_flags[tri]
            si.ns = si.ng
            if (flags & TRI_HAS_NORMALS) != 0:
                nn = scene.normals[i0] * b0 + scene.normals[i1] * b1 + scene.normals[i2] * b2
                if wp.length(nn) > 1.0e-12:
                    si.ns = wp.normalize(nn)
            si.uv = wp.vec2(b1, b2)  # Mitsuba's default parametrization for meshes without UVs
            if (flags & TRI_HAS_UVS) != 0:
                si.uv = scene.uvs[i0] * b0 + scene.uvs[i1] * b1 + scene.uvs[i2] * b2
        else:
            si.ns = si.ng  # analytic shapes shade with their exact normal
        si.valid = 1
        ng = si.ng
        ns = si.ns
        mat_id = scene.tri_material[si.tri]
        si.material = mat_id
        si.object = scene.tri_object[si.tri]
        if wp.static(bump):
            mat = scene.materials[mat_id]
            if mat.bump_amplitude > 0.0:
                ns = perturb_normal(ns, si.p, mat.bump_amplitude, mat.bump_frequency)
        if wp.dot(ns, ng) < 0.0:
            ns = -ns
        si.ns = ns
        si.front = int(wp.dot(d, ng) < 0.0)
        return si

    @wp.func
    def shading_normal_derivative(scene: SceneData, si: SurfaceInteraction, dp: wp.vec3) -> wp.vec4:
        """∂n_s at hit ``si`` for the tangent displacement ``dp`` of its point, as (∂n_s, exact).

        The normal :func:`intersect` shades with, differentiated the way it was built: the base normal (an
        analytic shape's, :func:`~grisx.scene.analytic.shape_normal_derivative`; a triangle's interpolated vertex
        normal through its barycentrics; a flat triangle's, constant), then a material's procedural bump
        (:func:`perturb_normal_derivative`). A normal perturbed by anything else (a normal map) has a derivative
        this does not know: w = 0 there, and the caller falls back to differences (grisx.scene.caustics).
        """
        zero = wp.vec4(0.0, 0.0, 0.0, 0.0)
        mat = scene.materials[si.material]
        if mat.perturb != PERTURB_NONE:
            return zero  # a normal or bump map turns the BSDF's frame (Material.perturbed_n): no derivative here
        n = si.ng
        dn = wp.vec3(0.0, 0.0, 0.0)
        on_shape = False
        if wp.static(shapes):
            if si.tri >= scene.shapes.prim_base and scene.shapes.count > 0:
                dn = shape_normal_derivative(scene.shapes, si.tri - scene.shapes.prim_base, si.p, si.ng, dp)
                on_shape = True
        if not on_shape and (scene.tri_flags[si.tri] & TRI_HAS_NORMALS) != 0:
            i0 = scene.indices[3 * si.tri + 0]
            i1 = scene.indices[3 * si.tri + 1]
            i2 = scene.indices[3 * si.tri + 2]
            p2 = scene.positions[i2]
            e0 = scene.positions[i0] - p2
            e1 = scene.positions[i1] - p2
            n2 = scene.normals[i2]
            b0 = si.bary[0]
            b1 = si.bary[1]
            big_n = scene.normals[i0] * b0 + scene.normals[i1] * b1 + n2 * (1.0 - b0 - b1)
            length = wp.length(big_n)
            if length <= 1.0e-12:
                return zero
            n = big_n / length
            # dp = ∂b₀ e₀ + ∂b₁ e₁ in the triangle's plane: the Gram system
            g00 = wp.dot(e0, e0)
            g01 = wp.dot(e0, e1)
            g11 = wp.dot(e1, e1)
            det = g00 * g11 - g01 * g01
            if det <= 0.0:
                return zero
            r0 = wp.dot(e0, dp)
            r1 = wp.dot(e1, dp)
            db0 = (g11 * r0 - g01 * r1) / det
            db1 = (g00 * r1 - g01 * r0) / det
            dbig = (scene.normals[i0] - n2) * db0 + (scene.normals[i1] - n2) * db1
            dn = (dbig - n * wp.dot(n, dbig)) / length
        if wp.static(bump):
            if mat.bump_amplitude > 0.0:
                dn = perturb_normal_derivative(n, dn, si.p, dp, mat.bump_amplitude, mat.bump_frequency)
                n = perturb_normal(n, si.p, mat.bump_amplitude, mat.bump_frequency)
        c = wp.dot(n, si.ns)
        if wp.abs(c) < 0.99999:
            return zero  # n_s is not this normal: something else perturbed it
        if c < 0.0:
            dn = -dn  # n_s was turned to n_g's side
        return wp.vec4(dn[0], dn[1], dn[2], 1.0)

    @wp.func
    def blocked(scene: SceneData, r: ShadowRay) -> bool:
        """Whether anything meets shadow ray ``r`` (:class:`ShadowRay`): the one BVH traversal of the visibility tests."""
        if r.valid == 0:
            return False
        if wp.mesh_query_ray_anyhit(scene.mesh, r.o, r.d, r.t_max):
            return True
        if wp.static(shapes):
            if scene.shapes.count > 0:
                return shapes_occluded(scene.shapes, r.o, r.d, r.t_max)
        return False

    @wp.func
    def occluded(scene: SceneData, o: wp.vec3, d: wp.vec3, dist: float) -> bool:
        """Whether anything blocks the segment o → o + dist·d (d unit); the end point's surface is excluded."""
        return blocked(scene, shadow_ray_along(scene, o, d, dist))

    @wp.func
    def segment_occluded(scene: SceneData, p0: wp.vec3, n0: wp.vec3, p1: wp.vec3, n1: wp.vec3) -> bool:
        """Whether anything blocks the segment between surface points p0 and p1 (geometric normals n0, n1):
        :func:`shadow_ray_between`."""
        return blocked(scene, shadow_ray_between(scene, p0, n0, p1, n1))

    @wp.func
    def light_occluded(scene: SceneData, p: wp.vec3, ng: wp.vec3, ls: LightSample) -> bool:
        """Whether next-event sample ``ls`` is hidden from surface point ``p`` (geometric normal ``ng``):
        :func:`shadow_ray_to_light`."""
        return blocked(scene, shadow_ray_to_light(scene, p, ng, ls))

    return intersect, occluded, segment_occluded, light_occluded, shading_normal_derivative, blocked


@wp.func
def finite_or_dropped(L: wp.vec3, nonfinite: wp.array(dtype=wp.int32)) -> wp.vec3:
    """``L``, or black if any channel is NaN/Inf — then counted in ``nonfinite[0]``.

    A non-finite sample would poison an accumulated pixel forever; every renderer
    drops it here and reports the count (``nonfinite_samples``; the tests require 0).
    """
    if wp.isfinite(L[0]) and wp.isfinite(L[1]) and wp.isfinite(L[2]):
        return L
    wp.atomic_add(nonfinite, 0, 1)
    return wp.vec3(0.0, 0.0, 0.0)


@wp.func
def triangle_barycentrics(scene: SceneData, tri: int, p: wp.vec3) -> wp.vec3:
    """Barycentrics (b₀, b₁, b₂) of ``p`` on triangle ``tri`` (this frame's positions), p = Σ bₖ pₖ, in the order
    of :func:`intersect`'s ``bary`` (b₀ = Warp's u at vertex 0, b₁ = v at vertex 1)."""
    p0 = scene.positions[scene.indices[3 * tri + 0]]
    e1 = scene.positions[scene.indices[3 * tri + 1]] - p0
    e2 = scene.positions[scene.indices[3 * tri + 2]] - p0
    d = p - p0
    d00 = wp.dot(e1, e1)
    d01 = wp.dot(e1, e2)
    d11 = wp.dot(e2, e2)
    den = d00 * d11 - d01 * d01
    if den <= 0.0:
        return wp.vec3(1.0, 0.0, 0.0)  # a degenerate triangle (never hit)
    b1 = (d11 * wp.dot(d, e1) - d01 * wp.dot(d, e2)) / den
    b2 = (d00 * wp.dot(d, e2) - d01 * wp.dot(d, e1)) / den
    return wp.vec3(1.0 - b1 - b2, b1, b2)


@wp.func
def surface_texture(scene: SceneData, texture: int, si: SurfaceInteraction) -> wp.vec3:
    """Texture ``texture`` at surface point ``si``, whatever its kind: a bitmap or checkerboard at ``si.uv``, a mesh
    attribute at the triangle ``si.tri`` and barycentrics ``si.bary`` (0 off the triangles: the loader gives
    attribute textures to meshes only). Every texture slot of a material resolves through this one function."""
    if scene.textures.info[texture].kind == TEXTURE_MESH_ATTRIBUTE:
        tri = si.tri
        if tri < 0 or tri >= scene.shapes.prim_base:
            return wp.vec3(0.0, 0.0, 0.0)
        corners = wp.vec3i(scene.indices[3 * tri + 0], scene.indices[3 * tri + 1], scene.indices[3 * tri + 2])
        return attribute_lookup(scene.textures, texture, tri, corners, wp.vec3(si.bary[0], si.bary[1], 1.0 - si.bary[0] - si.bary[1]))
    return texture_lookup(scene.textures, texture, si.uv)


@wp.func
def surface_texture_1(scene: SceneData, texture: int, si: SurfaceInteraction) -> float:
    """A scalar texture value at ``si`` as Mitsuba's ``eval_1`` gives it (a mask's opacity, a blend's weight, a
    textured roughness): the luminance of :func:`surface_texture`, with a checkerboard's ``eval_1`` convention
    (:func:`grisx.scene.texture.texture_lookup_1`)."""
    if scene.textures.info[texture].kind == TEXTURE_MESH_ATTRIBUTE:
        return luminance(surface_texture(scene, texture, si))
    return texture_lookup_1(scene.textures, texture, si.uv)


@wp.func
def stored_surface(scene: SceneData, material: int, uv: wp.vec2, tri: int, p: wp.vec3, ns: wp.vec3, ng: wp.vec3) -> SurfaceInteraction:
    """A surface point kept by a renderer (material id, uv, primitive, position ``p`` on it, its shading and geometric
    normals) as the record :func:`surface_material` reads: its barycentrics recomputed from ``p`` on a triangle (mesh
    attributes need them), as :func:`intersect` gave them at the hit; the normals are a normal or bump map's frame."""
    si = SurfaceInteraction()
    si.valid = 1
    si.material = material
    si.uv = uv
    si.tri = tri
    si.p = p
    si.ns = ns
    si.ng = ng
    si.bary = wp.vec2(1.0, 0.0)
    if tri >= 0 and tri < scene.shapes.prim_base:
        b = triangle_barycentrics(scene, tri, p)
        si.bary = wp.vec2(b[0], b[1])
    return si


@wp.func
def _mesh_dp_duv(scene: SceneData, si: SurfaceInteraction) -> wp.mat33:
    """Rows ∂p/∂u, ∂p/∂v of the triangle ``si.tri`` (Mitsuba 3's mesh parametrization: by its uvs, else by its
    barycentrics; an arbitrary basis around n_g where the uvs are degenerate); zero rows off the triangles."""
    if si.tri < 0 or si.tri >= scene.shapes.prim_base:
        return wp.mat33(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    i0 = scene.indices[3 * si.tri + 0]
    i1 = scene.indices[3 * si.tri + 1]
    i2 = scene.indices[3 * si.tri + 2]
    e1 = scene.positions[i1] - scene.positions[i0]
    e2 = scene.positions[i2] - scene.positions[i0]
    dp_du = e1  # without uvs the parametrization is barycentric
    dp_dv = e2
    if (scene.tri_flags[si.tri] & TRI_HAS_UVS) != 0:
        duv0 = scene.uvs[i1] - scene.uvs[i0]
        duv1 = scene.uvs[i2] - scene.uvs[i0]
        det = duv0[0] * duv1[1] - duv0[1] * duv1[0]
        if det != 0.0:
            dp_du = (e1 * duv1[1] - e2 * duv0[1]) / det
            dp_dv = (e2 * duv0[0] - e1 * duv1[0]) / det
        else:  # a degenerate parametrization: an arbitrary basis, as Mitsuba
            g = frame_from_normal(si.ng)
            dp_du = g.s
            dp_dv = g.t
    return wp.mat33(dp_du[0], dp_du[1], dp_du[2], dp_dv[0], dp_dv[1], dp_dv[2], 0.0, 0.0, 0.0)


@wp.func
def shading_tangent(scene: SceneData, si: SurfaceInteraction) -> wp.vec3:
    """The shading frame's tangent s = normalize(∂p/∂u − n_s (n_s·∂p/∂u)) (Mitsuba 3's ``initialize_sh_frame``) in
    the local frame of ``si.ns`` (``frame_from_normal``): the direction α_u of an anisotropic BSDF runs along;
    that frame's own s where ∂p/∂u vanishes or lies along n_s (and off the triangles: the loader refuses
    anisotropy on analytic shapes)."""
    dp_du = _mesh_dp_duv(scene, si)[0]
    t = to_local(frame_from_normal(si.ns), dp_du)
    l2 = t[0] * t[0] + t[1] * t[1]
    if l2 <= 0.0:
        return wp.vec3(1.0, 0.0, 0.0)
    r = 1.0 / wp.sqrt(l2)
    return wp.vec3(t[0] * r, t[1] * r, 0.0)


@wp.func
def _perturbed_normal(scene: SceneData, si: SurfaceInteraction, m: Material) -> wp.vec3:
    """A normal or bump map's normal at ``si`` in the local frame of ``si.ns`` (Mitsuba 3's ``normalmap``
    and ``bumpmap`` frames over a mesh's ∂p/∂u, ∂p/∂v, and its shading frame s ∥ ∂p/∂u); unperturbed on an
    analytic shape (the loader refuses the maps there)."""
    if si.tri < 0 or si.tri >= scene.shapes.prim_base:
        return wp.vec3(0.0, 0.0, 1.0)
    duv = _mesh_dp_duv(scene, si)
    dp_du = duv[0]
    dp_dv = duv[1]
    ns = si.ns
    local = frame_from_normal(ns)
    n = wp.vec3(0.0, 0.0, 1.0)
    if m.perturb == PERTURB_NORMALMAP:
        s = to_world(local, shading_tangent(scene, si))
        t = wp.cross(ns, s)
        c = surface_texture(scene, m.perturb_texture, si) * 2.0 - wp.vec3(1.0, 1.0, 1.0)
        n = s * c[0] + t * c[1] + ns * c[2]
    else:
        grad = texture_gradient(scene.textures, m.perturb_texture, si.uv) * m.bump_scale
        du = dp_du + ns * (grad[0] - wp.dot(ns, dp_du))
        dv = dp_dv + ns * (grad[1] - wp.dot(ns, dp_dv))
        n = wp.cross(du, dv)
        if wp.dot(si.ng, n) < 0.0:
            n = -n
    if wp.length_sq(n) <= 0.0:
        return wp.vec3(0.0, 0.0, 1.0)
    return wp.normalize(to_local(local, n))


@wp.func
def _scalar_texture_slot(m: Material, j: int) -> int:
    """Texture id of scalar slot ``j`` of :func:`_resolve_wrappers` (−1: none): 0 a mask's opacity, 1 α_u, 2 α_v,
    3 a blend's weight, 4 … 7 a principled BSDF's textured lobe weights (id · 16 + lobe)."""
    if j == 0:
        return m.opacity_texture
    if j == 1:
        return m.alpha_u_texture
    if j == 2:
        return m.alpha_v_texture
    if j == 3:
        return m.blend_texture
    t = m.lobe_textures[j - 4]
    if t < 0:
        return -1
    return t // 16


@wp.func
def _has_scalar_textures(m: Material) -> bool:
    """Whether any slot of :func:`_scalar_texture_slot` holds a texture (the lobe textures are packed first to last)."""
    return (m.opacity_texture >= 0 or m.alpha_u_texture >= 0 or m.alpha_v_texture >= 0 or m.blend_texture >= 0
            or m.lobe_textures[0] >= 0)


class SurfaceFuncs(NamedTuple):
    """What a kernel asks of the scene's surfaces, compiled for one set of kinds (:func:`make_surface`): the material
    at a hit (``surface_material``, ``surface_material_at``) and the ray queries (``_make_ray_queries``)."""

    surface_material: Any
    surface_material_at: Any
    intersect: Any
    occluded: Any
    segment_occluded: Any
    light_occluded: Any
    shading_normal_derivative: Any
    blocked: Any


@functools.cache
def _make_surface(kinds: frozenset[int]) -> SurfaceFuncs:
    # each wrapper's code only where a material of the scene has it: every kernel inlines surface_material at each
    # of its call sites, and the wrappers were most of a ReSTIR kernel's CUDA compile time (benchmarks/README,
    # "A compile-time regression")
    has_perturb = bool(kinds & {MATERIAL_NORMALMAP, MATERIAL_BUMPMAP})
    has_anisotropic = MATERIAL_ANISOTROPIC in kinds
    has_scalars = MATERIAL_SCALAR_TEXTURES in kinds
    has_reflectance_texture = MATERIAL_REFLECTANCE_TEXTURE in kinds

    @wp.func
    def resolve_wrappers(scene: SceneData, m: Material, si: SurfaceInteraction) -> Material:
        """A mask's ``opacity`` (the luminance of its texture at ``si.uv``, clamped to [0, 1]), a normal or bump map's
        ``perturbed_n`` at ``si``, textured α_u / α_v (their textures' luminance), an anisotropic BSDF's ``tangent``
        (:func:`shading_tangent`), a principled BSDF's textured lobe weights, and a diffuse blend's reflectance
        (1 − w) ρ₀ + w ρ₁ (a general blend's weight w)."""
        if wp.static(has_perturb):
            if m.perturb != PERTURB_NONE:
                m.perturbed_n = _perturbed_normal(scene, si, m)
        if wp.static(has_anisotropic):
            if m.anisotropic != 0:
                m.tangent = shading_tangent(scene, si)
        if wp.static(has_scalars):
            # the scalar textures (Mitsuba's eval_1 of each) in one loop, not unrolled: one texture lookup in the code
            # of every kernel that resolves a material, not eight
            w = m.blend_weight
            j = int(8)  # most materials have none: skip the loop
            if _has_scalar_textures(m):
                j = 0
            while j < 8:
                t = _scalar_texture_slot(m, j)
                if t >= 0:
                    value = surface_texture_1(scene, t, si)
                    if j == 0:
                        m.opacity = wp.clamp(value, 0.0, 1.0)
                    elif j == 1:
                        m.alpha = value  # roughconductor.cpp: m_alpha_u->eval_1(si)
                    elif j == 2:
                        m.alpha_v = value
                    elif j == 3:
                        w = wp.clamp(value, 0.0, 1.0)
                    else:
                        principled_set_slot(m, m.lobe_textures[j - 4] % 16, value)
                elif j >= 4:
                    break  # the lobe textures are packed first to last
                j += 1
            if m.blend_texture >= 0 or m.blend_weight > 0.0:
                if m.blend_partner.shape[0] > 0:  # plugins2: a general blend mixes its two BSDFs in the dispatch, by this weight
                    m.blend_weight = w
                else:
                    m.reflectance = m.reflectance * (1.0 - w) + m.blend_reflectance * w
        return m

    @wp.func
    def surface_material(scene: SceneData, si: SurfaceInteraction) -> Material:
        """The material at ``si`` with its texture (if any) resolved into ``reflectance`` (:func:`surface_texture`), and
        its wrappers' textures (``resolve_wrappers``)."""
        m = scene.materials[si.material]
        if wp.static(has_reflectance_texture):
            if m.texture >= 0:
                m.reflectance = surface_texture(scene, m.texture, si)
        return resolve_wrappers(scene, m, si)

    @wp.func
    def surface_material_at(scene: SceneData, material: int, uv: wp.vec2, tri: int, p: wp.vec3, ns: wp.vec3, ng: wp.vec3) -> Material:
        """The material of a stored surface point (:func:`stored_surface`) with its textures resolved, as at the hit."""
        return surface_material(scene, stored_surface(scene, material, uv, tri, p, ns, ng))

    return SurfaceFuncs(surface_material, surface_material_at, *_make_ray_queries(SCENE_ANALYTIC_SHAPES in kinds, MATERIAL_PROCEDURAL_BUMP in kinds))


def make_surface(kinds: Iterable[int]) -> SurfaceFuncs:
    """``surface_material`` / ``surface_material_at`` and the ray queries (``intersect``, ``occluded``,
    ``segment_occluded``, ``light_occluded``, ``shading_normal_derivative``, and ``blocked``, which traces a
    :class:`ShadowRay`) for the kinds ``kinds`` (the material kinds
    with their wrapper and feature pseudo-kinds: normal/bump maps, anisotropy, scalar and reflectance textures, a
    procedural bump, and ``SCENE_ANALYTIC_SHAPES``), cached per set. A renderer's kernels take them from here with their BSDF dispatch
    (``make_bsdf``); a scene whose kinds lack a pseudo-kind has no such material, or no analytic shape."""
    return _make_surface(frozenset(int(k) for k in kinds))


#: every wrapper and the analytic shapes compiled in (for code outside a kinds-specialised factory)
surface_material = make_surface(ALL_MATERIAL_KINDS).surface_material
surface_material_at = make_surface(ALL_MATERIAL_KINDS).surface_material_at
intersect = make_surface(ALL_MATERIAL_KINDS).intersect
occluded = make_surface(ALL_MATERIAL_KINDS).occluded
segment_occluded = make_surface(ALL_MATERIAL_KINDS).segment_occluded
light_occluded = make_surface(ALL_MATERIAL_KINDS).light_occluded
shading_normal_derivative = make_surface(ALL_MATERIAL_KINDS).shading_normal_derivative


@wp.kernel
def _move_vertices(
    base_positions: wp.array(dtype=wp.vec3),
    base_normals: wp.array(dtype=wp.vec3),
    vertex_object: wp.array(dtype=wp.int32),
    transforms: wp.array(dtype=wp.mat44),
    positions: wp.array(dtype=wp.vec3),
    normals: wp.array(dtype=wp.vec3),
):
    i = wp.tid()
    m = transforms[vertex_object[i]]
    positions[i] = wp.transform_point(m, base_positions[i])
    # rigid motion: the rotation part maps normals too
    n = wp.transform_vector(m, base_normals[i])
    if wp.length(n) > 0.0:
        n = wp.normalize(n)
    normals[i] = n


# ---- builder -------------------------------------------------------------------


def _as_float_array(name: str, a: Any, shape_tail: tuple[int, ...]) -> np.ndarray:
    arr = np.asarray(a, dtype=np.float64)
    if arr.ndim != 1 + len(shape_tail) or arr.shape[1:] != shape_tail:
        raise InvalidValueError(f"{name}: expected shape (N, {', '.join(map(str, shape_tail))}), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InvalidValueError(f"{name}: contains NaN or Inf")
    return arr


def _rgb(name: str, value: Any) -> np.ndarray:
    v = np.asarray(value, dtype=np.float64).reshape(-1)
    if v.size == 1:
        v = np.repeat(v, 3)
    if v.size != 3 or not np.all(np.isfinite(v)) or np.any(v < 0):
        raise InvalidValueError(f"{name}: expected a non-negative RGB triple, got {value!r}")
    return v


class Scene:
    """Builder of a scene: materials, textures, meshes, lights, camera, film and defaults.

    All inputs are validated here, so a bad scene fails at build time with a
    message naming the object, not inside a kernel.
    """

    def __init__(self, name: str = "scene") -> None:
        self.name = name
        self.materials: list[Any] = []
        self.material_names: dict[str, int] = {}
        self.textures: list[np.ndarray | Bitmap | Checkerboard | MeshAttribute] = []
        self.objects: list[_Object] = []
        self.point_lights: list[PointLight] = []
        self.environment: ConstantEnvironment | EnvMap | None = None
        self.camera: Camera = Camera()
        self.camera_path: CameraPath | None = None
        self.film = Film()
        self.defaults: dict[str, Any] = {"spp": 16, "max_depth": 16}
        self.description = ""

    # ---- content --------------------------------------------------------------
    def add_material(self, desc: Any, name: str | None = None) -> int:
        """Register material record ``desc`` (:mod:`grisx.scene.material`); returns its id."""
        self.materials.append(desc)
        mid = len(self.materials) - 1
        if name is not None:
            self.material_names[name] = mid
        return mid

    def add_texture(self, image: np.ndarray | Bitmap | Checkerboard | MeshAttribute, name: str | None = None) -> int:
        """Register an albedo texture — a linear RGB image (H, W, 3), or a :class:`~grisx.scene.texture.Bitmap`,
        :class:`~grisx.scene.texture.Checkerboard` or :class:`~grisx.scene.texture.MeshAttribute` record; returns its id."""
        if isinstance(image, (Checkerboard, MeshAttribute)):
            self.textures.append(image)
            return len(self.textures) - 1
        if isinstance(image, Bitmap):
            self.textures.append(dataclasses.replace(image, image=self._texture_image(image.image, name)))
            return len(self.textures) - 1
        self.textures.append(self._texture_image(image, name))
        return len(self.textures) - 1

    def _texture_image(self, image: np.ndarray, name: str | None) -> np.ndarray:
        img = np.asarray(image, dtype=np.float32)
        if img.ndim == 2:
            img = np.repeat(img[:, :, None], 3, axis=2)
        if img.ndim != 3 or img.shape[2] < 3:
            raise InvalidValueError(f"texture {name or len(self.textures)}: expected (H, W, 3), got {img.shape}")
        return img[:, :, :3]

    def _placement(self, what: str, material: Any, to_world: Any) -> np.ndarray:
        """Check an object's material id and ``to_world`` (finite, invertible); the 4×4 matrix."""
        if not (isinstance(material, (int, np.integer)) and 0 <= material < len(self.materials)):
            raise InvalidParameterError(f"{what}: unknown material id {material!r}")
        m = np.eye(4) if to_world is None else np.asarray(to_world, dtype=np.float64).reshape(4, 4)
        if not np.all(np.isfinite(m)) or abs(np.linalg.det(m[:3, :3])) < 1e-20:
            raise InvalidValueError(f"{what}: to_world must be finite and invertible")
        return m

    def add_mesh(
        self,
        vertices: Any,
        faces: Any,
        *,
        material: int,
        normals: Any = None,
        uvs: Any = None,
        emission: Any = None,
        to_world: Any = None,
        motion: RigidMotion | None = None,
        name: str | None = None,
        attributes: dict[str, Any] | None = None,
    ) -> int:
        """Add a triangle mesh (object-space ``vertices``, ``faces`` as vertex index triples); ``emission``
        makes it an area light: an RGB radiance, or a radiance image ((H, W, 3) linear RGB or a
        :class:`~grisx.scene.texture.Bitmap`) looked up at the mesh's uv (its own, else each triangle's
        (0, 0), (1, 0), (0, 1), as ray hits see them).

        ``attributes``: Mitsuba's mesh attributes, name → (rows, dim) values with one row per vertex
        (``vertex_*``) or per face (``face_*``), read by :class:`~grisx.scene.texture.MeshAttribute` textures."""
        name = name or f"mesh{len(self.objects)}"
        v = _as_float_array(f"mesh '{name}' vertices", vertices, (3,))
        f = np.asarray(faces)
        if f.ndim != 2 or f.shape[1] != 3 or not np.issubdtype(f.dtype, np.integer):
            raise InvalidValueError(f"mesh '{name}' faces: expected integer shape (M, 3), got {f.dtype} {f.shape}")
        if f.size and (f.min() < 0 or f.max() >= len(v)):
            raise InvalidValueError(f"mesh '{name}' faces: vertex index out of range [0, {len(v)})")
        if len(f) == 0:
            raise InvalidValueError(f"mesh '{name}' has no triangles")
        m = self._placement(f"mesh '{name}'", material, to_world)
        vw = v @ m[:3, :3].T + m[:3, 3]
        n = None
        if normals is not None:
            n = _as_float_array(f"mesh '{name}' normals", normals, (3,))
            if len(n) != len(v):
                raise InvalidValueError(f"mesh '{name}': {len(n)} normals for {len(v)} vertices")
            n = n @ np.linalg.inv(m[:3, :3])  # inverse transpose, row-vector form
            lengths = np.linalg.norm(n, axis=1, keepdims=True)
            n = np.where(lengths > 0, n / np.where(lengths > 0, lengths, 1), 0.0)
        uv = None
        if uvs is not None:
            uv = _as_float_array(f"mesh '{name}' uvs", uvs, (2,))
            if len(uv) != len(v):
                raise InvalidValueError(f"mesh '{name}': {len(uv)} uvs for {len(v)} vertices")
        e = None
        if isinstance(emission, Bitmap) or (emission is not None and np.ndim(emission) >= 2):
            e = emission  # a radiance image, looked up at the mesh's uv (Mitsuba's area emitter with a bitmap 'radiance')
        elif emission is not None:
            e = _rgb(f"mesh '{name}' emission", emission)
        attrs = {}
        for key, values in (attributes or {}).items():
            a = np.asarray(values, dtype=np.float64)
            a = a.reshape(-1, 1) if a.ndim == 1 else a
            rows = len(v) if key.startswith("vertex_") else len(f) if key.startswith("face_") else None
            if rows is None:
                raise InvalidValueError(f"mesh '{name}': attribute name {key!r} must start with 'vertex_' or 'face_'")
            if a.ndim != 2 or a.shape[0] != rows or not 1 <= a.shape[1] <= 4 or not np.all(np.isfinite(a)):
                raise InvalidValueError(f"mesh '{name}': attribute {key!r} must be finite with {rows} rows of 1 to 4 "
                                        f"values, got shape {a.shape}")
            attrs[key] = a
        self._check_attributes(f"mesh '{name}'", material, attrs)
        self.objects.append(_Object(name, vw, f.astype(np.int64), n, uv, int(material), e, motion, attributes=attrs))
        return len(self.objects) - 1

    def _check_attributes(self, what: str, material: int, attrs: dict[str, np.ndarray]) -> None:
        """Every mesh attribute that ``material`` reads must be among ``attrs``, with 1 or 3 channels."""
        for tid in sorted(_texture_ids(self.materials[material])):
            tex = self.textures[tid] if 0 <= tid < len(self.textures) else None
            if isinstance(tex, MeshAttribute):
                if tex.name not in attrs:
                    have = ", ".join(sorted(attrs)) or "none"
                    raise InvalidParameterError(f"{what}: its material reads mesh attribute '{tex.name}', which it does not "
                                                f"have (its attributes: {have})")
                if attrs[tex.name].shape[1] not in (1, 3):
                    raise InvalidParameterError(f"{what}: attribute '{tex.name}' has {attrs[tex.name].shape[1]} channels; a "
                                                f"mesh_attribute texture reads 1 (grey) or 3 (RGB), as Mitsuba's RGB variants do")

    def add_shape(self, kind: str, *, material: int, to_world: Any = None, flip_normals: bool = False,
                  name: str | None = None) -> int:
        """Add an analytic ``"sphere"``, ``"disk"`` or ``"cylinder"`` (:mod:`grisx.scene.analytic`: the unit shape
        mapped by ``to_world``). Analytic shapes neither emit nor move: give an emitter or a moving object as a
        mesh (:mod:`grisx.scene.shapes` tessellates the same shapes)."""
        name = name or f"{kind}{len(self.objects)}"
        if kind not in SHAPE_KIND_NAMES:
            raise InvalidParameterError(f"shape '{name}': unknown analytic shape {kind!r} (known: {', '.join(SHAPE_KIND_NAMES)})")
        m = self._placement(f"shape '{name}'", material, to_world)
        self._check_attributes(f"shape '{name}'", material, {})
        shape = AnalyticShape(SHAPE_KIND_NAMES[kind], m, bool(flip_normals))
        lo, hi = shape_bounds(shape)
        corners = np.array([[(lo, hi)[(c >> a) & 1][a] for a in range(3)] for c in range(8)])
        self.objects.append(_Object(name, corners, np.zeros((0, 3), np.int64), None, None, int(material), None, None, shape))
        return len(self.objects) - 1

    def add_point_light(self, position: Sequence[float], intensity: Any, direction: Sequence[float] | None = None,
                        cutoff_angle: float = 20.0, beam_width: float | None = None, texture: Any = None,
                        to_world: Any = None) -> None:
        """A point light; with ``direction`` a spot light (Mitsuba's ``spot``: cone half-angle and beam width in degrees,
        an optional ``texture`` image over the cone, laid out in the spot's frame ``to_world``)."""
        self.point_lights.append(PointLight(position=tuple(float(x) for x in position), intensity=tuple(_rgb("point light intensity", intensity)),
                                            direction=None if direction is None else tuple(float(x) for x in direction),
                                            cutoff_angle=float(cutoff_angle), beam_width=None if beam_width is None else float(beam_width),
                                            texture=texture, to_world=to_world))

    def add_delta_light(self, light: PointLight | Projector | DirectionalLight) -> None:
        """A light that is a delta in position or direction: a :class:`~grisx.scene.lights.PointLight`,
        :class:`~grisx.scene.lights.Projector` or :class:`~grisx.scene.lights.DirectionalLight` record."""
        if not isinstance(light, (PointLight, Projector, DirectionalLight)):
            raise InvalidParameterError(f"add_delta_light takes a PointLight, Projector or DirectionalLight, got {type(light).__name__}")
        self.point_lights.append(light)

    def set_environment(self, env: ConstantEnvironment | EnvMap | None) -> None:
        self.environment = env

    def set_camera(self, camera: Camera, path: CameraPath | None = None) -> None:
        self.camera = camera
        self.camera_path = path

    # ---- queries ----------------------------------------------------------------
    @property
    def triangle_count(self) -> int:
        return sum(len(o.faces) for o in self.objects)

    @property
    def shape_count(self) -> int:
        """The number of analytic shapes (:meth:`add_shape`)."""
        return sum(o.shape is not None for o in self.objects)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        if not self.objects:
            return np.zeros(3), np.zeros(3)
        allv = np.concatenate([o.vertices for o in self.objects])
        return allv.min(axis=0), allv.max(axis=0)

    def _bumpy(self, material: int) -> bool:
        return getattr(unwrap(self.materials[material])[0], "bump_amplitude", 0.0) > 0.0

    def features(self) -> SceneFeatures:
        kinds = frozenset(material_kinds(self.materials)) if self.materials else frozenset()
        delta = {MATERIAL_CONDUCTOR, MATERIAL_DIELECTRIC, MATERIAL_THIN_DIELECTRIC, MATERIAL_NULL, MATERIAL_MASK}
        used = {o.material for o in self.objects}
        used_kinds = frozenset(material_kinds([self.materials[i] for i in sorted(used)])) if used else frozenset()
        env = "none" if self.environment is None else ("constant" if isinstance(self.environment, ConstantEnvironment) else "envmap")
        caustic = any(
            k in (MATERIAL_CONDUCTOR, MATERIAL_DIELECTRIC, MATERIAL_ROUGH_DIELECTRIC) for k in used_kinds
        ) or any(self._bumpy(i) for i in used)
        scene_kinds = {  # the SCENE_* pseudo-kinds (grisx.scene.material): what the kernels compile in besides materials
            SCENE_ANALYTIC_SHAPES: any(o.shape is not None for o in self.objects),
            SCENE_DELTA_LIGHTS: bool(self.point_lights),
            SCENE_ENVMAP: env == "envmap",
            SCENE_EMITTER_TEXTURES: any(_textured_emission(o.emission) for o in self.objects),
            SCENE_MOVING_OBJECTS: any(o.motion is not None for o in self.objects),
        }
        return SceneFeatures(
            material_kinds=(used_kinds or kinds) | {k for k, has in scene_kinds.items() if has},
            has_textures=bool(self.textures),
            has_bump=any(self._bumpy(i) for i in used),
            has_area_lights=any(o.emission is not None for o in self.objects),
            has_point_lights=bool(self.point_lights),
            environment=env,
            has_delta=bool(used_kinds & delta),
            has_dielectric=bool(used_kinds & {MATERIAL_DIELECTRIC, MATERIAL_ROUGH_DIELECTRIC}),
            has_caustic_casters=caustic,
            animated_camera=self.camera_path is not None and len(self.camera_path.keys) > 1,
            animated_objects=any(o.motion is not None for o in self.objects),
        )

    # ---- upload -------------------------------------------------------------------
    def build(self, device: str | wp.context.Device = "cpu") -> BuiltScene:
        """Upload the scene to ``device`` and build its BVH."""
        if not self.objects:
            raise InvalidParameterError(f"scene '{self.name}' has no shapes")
        if not any(o.emission is not None for o in self.objects) and not self.point_lights and self.environment is None:
            raise InvalidParameterError(f"scene '{self.name}' has no light source (area emitter, point light or environment)")
        return BuiltScene(self, resolve_device(device))


def _texture_ids(record: Any) -> set[int]:
    """The texture ids a material record uses (its :class:`~grisx.scene.material.TextureRef` fields, nested records included)."""
    from grisx.scene.material import TextureRef

    if isinstance(record, TextureRef):
        return {int(record.texture_id)}
    if dataclasses.is_dataclass(record) and not isinstance(record, type):
        return set().union(*(_texture_ids(getattr(record, f.name)) for f in dataclasses.fields(record)))
    if isinstance(record, (list, tuple)):
        return set().union(*(_texture_ids(x) for x in record)) if record else set()
    return set()


def _resolve_attributes(scene: Scene) -> list:
    """The scene's textures with every :class:`MeshAttribute` gathered over the scene's vertices or triangles
    (:class:`AttributeTexels`; :meth:`Scene.add_mesh` checked that each mesh whose material reads one has it)."""
    textures = list(scene.textures)
    wanted = {i for i, t in enumerate(textures) if isinstance(t, MeshAttribute)}
    if not wanted:
        return textures
    readers: dict[int, list[_Object]] = {i: [] for i in wanted}
    for o in scene.objects:
        for tid in _texture_ids(scene.materials[o.material]) & wanted:
            readers[tid].append(o)
    n_vertices = sum(len(o.vertices) for o in scene.objects)
    n_faces = sum(len(o.faces) for o in scene.objects)
    for tid in wanted:
        tex = textures[tid]
        per_face = tex.name.startswith("face_")
        values = np.zeros((n_faces if per_face else n_vertices, 3))
        row = 0
        for o in scene.objects:
            rows = len(o.faces) if per_face else len(o.vertices)
            if any(o is r for r in readers[tid]):
                values[row:row + rows] = np.broadcast_to(o.attributes[tex.name], (rows, 3)) * tex.scale
            row += rows
        textures[tid] = AttributeTexels(values, per_face)
    return textures


def _struct_copy(s: Any, **changes: Any) -> Any:
    """A copy of Warp struct instance ``s`` (its arrays shared) with ``changes`` applied."""
    out = type(s)()
    for name in s._cls.vars:
        setattr(out, name, changes.get(name, getattr(s, name)))
    return out


class BuiltScene:
    """A scene on a device: its BVH, the :class:`SceneData` struct, lights and per-frame motion."""

    def __init__(self, scene: Scene, device: wp.context.Device) -> None:
        self.scene = scene
        self.name = scene.name
        self.device = device
        self.features = scene.features()
        self.film = scene.film
        self.defaults = dict(scene.defaults)
        self.camera = scene.camera
        self._camera_data: dict[tuple, CameraData] = {}  # camera_data's last few results, by value
        self.camera_path = scene.camera_path
        #: follow the camera path (renderers set it for animated sequences)
        self.animate_camera = False

        objs = scene.objects
        verts, faces, norms, uvs = [], [], [], []
        vobj, tri_mat, tri_obj, tri_flags = [], [], [], []
        emitter_tris, emitter_radiance = [], []
        emitter_images, emitter_texture, emitter_uvs = [], [], []  # textured emitters' images, per-triangle index and corner uvs
        emitter_group = []  # per emissive triangle: its object (one light to the light selection)
        base = 0
        tri_base = 0
        for oid, o in enumerate(objs):
            nv, nf = len(o.vertices), len(o.faces)
            verts.append(o.vertices)
            faces.append(o.faces + base)
            norms.append(o.normals if o.normals is not None else np.zeros((nv, 3)))
            uvs.append(o.uvs if o.uvs is not None else np.zeros((nv, 2)))
            vobj.append(np.full(nv, oid))
            tri_mat.append(np.full(nf, o.material))
            tri_obj.append(np.full(nf, oid))
            flags = (1 if o.normals is not None else 0) | (2 if o.uvs is not None else 0)
            tri_flags.append(np.full(nf, flags))
            if o.emission is not None:
                emitter_tris.append(np.arange(tri_base, tri_base + nf))
                textured = _textured_emission(o.emission)
                emitter_radiance.append(np.ones((nf, 3)) if textured else np.repeat(o.emission[None, :], nf, axis=0))
                if textured:
                    emitter_images.append(o.emission)
                emitter_texture.append(np.full(nf, len(emitter_images) - 1 if textured else -1))
                corner_uvs = o.uvs[o.faces] if o.uvs is not None else np.tile([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]], (nf, 1, 1))
                emitter_uvs.append(corner_uvs)
                emitter_group.append(np.full(nf, oid))
            base += nv
            tri_base += nf
        if tri_base == 0:  # analytic shapes only: the triangle BVH still needs a triangle (zero area: never hit)
            faces.append(np.zeros((1, 3), np.int64))
            tri_mat.append(np.array([objs[0].material]))
            tri_obj.append(np.zeros(1))
            tri_flags.append(np.zeros(1))
            tri_base = 1
        # analytic shapes are the primitives after the triangles (grisx.scene.analytic, "Primitive ids")
        shape_objs = [(oid, o) for oid, o in enumerate(objs) if o.shape is not None]
        tri_mat.append(np.array([o.material for _, o in shape_objs], dtype=np.int64))
        tri_obj.append(np.array([oid for oid, _ in shape_objs], dtype=np.int64))
        tri_flags.append(np.zeros(len(shape_objs), dtype=np.int64))
        dev = device
        f32 = np.float32
        self.base_positions = wp.array(np.concatenate(verts).astype(f32), dtype=wp.vec3, device=dev)
        self.base_normals = wp.array(np.concatenate(norms).astype(f32), dtype=wp.vec3, device=dev)
        self.positions = wp.clone(self.base_positions)
        self.normals = wp.clone(self.base_normals)
        self.indices = wp.array(np.concatenate(faces).reshape(-1).astype(np.int32), dtype=wp.int32, device=dev)
        self.vertex_object = wp.array(np.concatenate(vobj).astype(np.int32), dtype=wp.int32, device=dev)
        # SAH on every device (Warp's CUDA default is an LBVH): built once on the host (0.45 s for
        # 1M triangles), it traces 7-15% faster at 1080p (benchmarks/reference/vs_mitsuba_h100/bvh_*.json)
        self.mesh = wp.Mesh(points=self.positions, indices=self.indices, bvh_constructor="sah")
        lo, hi = scene.bounds()
        self.bounds = (lo, hi)
        radius = float(np.linalg.norm(hi - lo) / 2)
        if not radius > 0.0:
            radius = 1.0  # a scene of one point: any positive scale
        extent = float(np.max(np.abs(np.concatenate([lo, hi])))) if np.all(np.isfinite(np.concatenate([lo, hi]))) else radius
        self.scene_radius = radius
        self.num_triangles = tri_base
        self.num_shapes = len(shape_objs)
        self.num_vertices = base

        # lights
        etris = np.concatenate(emitter_tris).astype(np.int32) if emitter_tris else np.zeros(0, np.int32)
        erad = np.concatenate(emitter_radiance).astype(f32) if emitter_radiance else np.zeros((0, 3), f32)
        self.lights = build_light_set(
            dev,
            positions=self.positions,
            indices=self.indices,
            emitter_tris=etris,
            emitter_radiance=erad,
            point_lights=list(scene.point_lights),
            environment=scene.environment,
            scene_radius=radius,
            num_primitives=tri_base + len(shape_objs),
            scene_center=0.5 * (lo + hi),
            emitter_textures=emitter_images,
            emitter_texture=np.concatenate(emitter_texture).astype(np.int32) if emitter_texture else None,
            emitter_uvs=np.concatenate(emitter_uvs) if emitter_uvs else None,
            emitter_group=np.concatenate(emitter_group) if emitter_group else None,
        )

        mats = list(scene.materials)
        self.materials = pack_materials(mats, dev)
        self.textures = pack_textures(_resolve_attributes(scene), dev)

        d = SceneData()
        d.mesh = self.mesh.id
        d.positions = self.positions
        d.indices = self.indices
        d.normals = self.normals
        d.uvs = wp.array(np.concatenate(uvs).astype(f32), dtype=wp.vec2, device=dev)
        d.tri_material = wp.array(np.concatenate(tri_mat).astype(np.int32), dtype=wp.int32, device=dev)
        d.tri_object = wp.array(np.concatenate(tri_obj).astype(np.int32), dtype=wp.int32, device=dev)
        d.tri_flags = wp.array(np.concatenate(tri_flags).astype(np.int32), dtype=wp.int32, device=dev)
        d.shapes, self._shape_bvh = build_shape_set([o.shape for _, o in shape_objs], tri_base, dev)
        d.materials = self.materials
        d.textures = self.textures
        d.lights = self.lights
        # relative to the scene's size, and above float32 rounding at its coordinates: a scene scaled by k (all of
        # it, camera included) renders the same image (an absolute floor made a millimetre-sized box 1% darker)
        d.ray_epsilon = 1.0e-4 * radius + 1.0e-6 * extent
        d.scene_radius = radius
        # bounding spheres (box centre, farthest vertex) of the objects: the seed space of a caustic chain
        # (grisx.scene.caustics) is the square that covers an object's sphere as seen from the shading point
        centers = np.array([0.5 * (o.vertices.min(axis=0) + o.vertices.max(axis=0)) for o in objs], dtype=np.float64)
        radii = np.array([float(np.max(np.linalg.norm(o.vertices - c, axis=1))) for o, c in zip(objs, centers)])
        for oid, o in shape_objs:  # a sphere's own: its centre and largest semi-axis (its box's corners lie outside it)
            if o.shape.kind == SHAPE_KIND_NAMES["sphere"]:
                radii[oid] = float(np.linalg.norm(o.shape.to_world[:3, :3], ord=2))
        self._object_centers = centers
        self.object_center = wp.array(centers.astype(f32), dtype=wp.vec3, device=dev)
        d.object_center = self.object_center
        d.object_radius = wp.array(np.maximum(radii, 1.0e-6).astype(f32), dtype=float, device=dev)
        d.moved_lo = wp.zeros(max(len(objs), 1), dtype=wp.vec3, device=dev)
        d.moved_hi = wp.zeros(max(len(objs), 1), dtype=wp.vec3, device=dev)
        d.moved_count = 0
        self.data = d
        #: the scene across frames (:meth:`across_frames`): this frame's geometry, and the previous frame's
        self.data_from_prev = d
        self.data_prev = d

        n_obj = len(objs)
        ident = np.tile(np.eye(4, dtype=f32), (n_obj, 1, 1))
        self.object_transforms = wp.array(ident, dtype=wp.mat44, device=dev)
        self.object_transforms_prev = wp.array(ident, dtype=wp.mat44, device=dev)
        self.frame: float | None = None
        self._host_transforms = ident.astype(np.float64)
        self._host_transforms_prev = ident.astype(np.float64)
        # corners of each object's box at frame 0 (what a rigid motion moves): the boxes of what moved
        self._object_corners = np.array(
            [[[(lo_, hi_)[(c >> a) & 1][a] for a in range(3)] for c in range(8)]
             for lo_, hi_ in ((o.vertices.min(axis=0), o.vertices.max(axis=0)) for o in objs)], dtype=np.float64)
        if self.features.animated_objects:
            # the previous frame's geometry: its own vertices, BVH and light set (emitters may move)
            self.positions_prev = wp.clone(self.base_positions)
            self.normals_prev = wp.clone(self.base_normals)
            self.mesh_prev = wp.Mesh(points=self.positions_prev, indices=self.indices, bvh_constructor="sah")
            self.object_center_prev = wp.clone(self.object_center)
            lights_prev = _struct_copy(self.lights, positions=self.positions_prev)
            moved = {"moved_lo": wp.zeros(len(objs), dtype=wp.vec3, device=dev), "moved_hi": wp.zeros(len(objs), dtype=wp.vec3, device=dev)}
            self.data_prev = _struct_copy(d, mesh=self.mesh_prev.id, positions=self.positions_prev, normals=self.normals_prev,
                                          lights=lights_prev, object_center=self.object_center_prev, **moved)
            self.data_from_prev = _struct_copy(d, **moved)
        self.set_frame(0.0)

    # ---- per frame ----------------------------------------------------------------
    def transforms_at(self, frame: float) -> np.ndarray:
        out = np.tile(np.eye(4), (len(self.scene.objects), 1, 1))
        for i, o in enumerate(self.scene.objects):
            if o.motion is not None:
                out[i] = o.motion.transform(frame)
        return out

    def set_frame(self, frame: float) -> bool:
        """Move objects to ``frame`` (and the previous frame's geometry to ``frame`` − 1); returns whether any
        geometry moved (the BVHs are refit only then)."""
        self.frame = frame
        if not self.features.animated_objects:
            return False  # static geometry: transforms stay identity, nothing to upload or refit
        new = self.transforms_at(frame)
        prev = self.transforms_at(max(frame - 1.0, 0.0))
        self.object_transforms_prev.assign(prev.astype(np.float32))
        moved_prev = not np.array_equal(prev, self._host_transforms_prev)
        if moved_prev:
            self._host_transforms_prev = prev
            self._place(prev, self.positions_prev, self.normals_prev, self.object_center_prev, self.mesh_prev, self.object_transforms_prev)
        self._set_moved(prev, new)
        moved = not np.array_equal(new, self._host_transforms)
        if not moved:
            return False
        self._host_transforms = new
        self.object_transforms.assign(new.astype(np.float32))
        self._place(new, self.positions, self.normals, self.object_center, self.mesh, self.object_transforms)
        return True

    def _place(self, transforms: np.ndarray, positions: wp.array, normals: wp.array, centers: wp.array, mesh: wp.Mesh,
               device_transforms: wp.array) -> None:
        """Move the frame-0 geometry by ``transforms`` (per object) into one frame's vertices, centres and BVH."""
        moved_centers = np.einsum("nij,nj->ni", transforms[:, :3, :3], self._object_centers) + transforms[:, :3, 3]
        centers.assign(moved_centers.astype(np.float32))
        launch(
            _move_vertices,
            dim=self.num_vertices,
            inputs=[self.base_positions, self.base_normals, self.vertex_object, device_transforms],
            outputs=[positions, normals],
            device=self.device,
        )
        mesh.refit()

    def _set_moved(self, prev: np.ndarray, new: np.ndarray) -> None:
        """The boxes of the objects that moved from ``prev`` to ``new``, each over both frames (a little wider
        than the surface offset), for :func:`motion_touches` in the shifts across these frames."""
        moved = [i for i in range(len(new)) if not np.array_equal(prev[i], new[i])]
        lo = np.zeros((len(new), 3), np.float32)
        hi = np.zeros_like(lo)
        pad = 4.0 * float(self.data.ray_epsilon)
        for j, i in enumerate(moved):
            pts = np.concatenate([self._object_corners[i] @ m[:3, :3].T + m[:3, 3] for m in (prev[i], new[i])])
            lo[j], hi[j] = pts.min(axis=0) - pad, pts.max(axis=0) + pad
        self.data_prev.moved_lo.assign(lo)  # shared by both
        self.data_prev.moved_hi.assign(hi)
        for d in (self.data_prev, self.data_from_prev):
            d.moved_count = len(moved)

    def across_frames(self) -> tuple[SceneData, SceneData]:
        """The scene for shifts between the previous frame's domains and this frame's: (this frame's geometry,
        the previous frame's geometry), each knowing what moved in between (:func:`motion_touches`).

        A sample shifted *into* this frame is evaluated in the first; this frame's samples shifted into the
        previous frame's domains (the MIS weights of temporal reuse) in the second: every domain in its own
        frame's scene. Without moving objects both are :attr:`data`.
        """
        return self.data_from_prev, self.data_prev

    def camera_at(self, frame: float) -> Camera:
        """The camera at ``frame``: on the camera path when ``animate_camera`` is set, else the static one.

        Frames before 0 are frame 0 (the first frame has no motion).
        """
        if self.camera_path is None or not self.animate_camera:
            return self.camera
        return dataclasses.replace(self.camera, to_world=self.camera_path.to_world(max(frame, 0.0)))

    def camera_data(self, frame: float, width: int, height: int) -> CameraData:
        """The camera at ``frame`` for a ``width``×``height`` film, as kernels read it (with the film's filter).

        Kept for the last few cameras asked for (by value: every field that goes into it), since every pass
        of a frame asks again (a G-buffer asks for this frame and the last; ReSTIR G-PT's pairs more often).
        """
        cam = self.camera_at(frame)
        key = (cam.to_world.tobytes(), cam.fov, cam.fov_axis, cam.near_clip, cam.far_clip, cam.aperture_radius, cam.focus_distance,
               cam.projection, int(width), int(height), float(self.film.filter_stddev), float(self.film.filter_tent))
        cache = self._camera_data
        d = cache.get(key)
        if d is None:
            d = cam.data(width, height)
            d.filter_stddev = float(self.film.filter_stddev)
            d.filter_tent = float(self.film.filter_tent)
            if len(cache) >= 8:
                cache.clear()
            cache[key] = d
        return d
