"""Analytic shapes: Mitsuba 3's ``sphere``, ``disk`` and ``cylinder`` intersected exactly.

A tessellated sphere is a polyhedron: its silhouette is a polygon, its
interpolated normals are not the normals of any surface, and a Newton solver
walking a specular chain across it (seed 003's manifold walks) sees a
derivative that jumps at every edge. Mitsuba intersects these shapes in closed
form; so does grisx, with Mitsuba's object-space conventions (the tessellated
twins in :mod:`grisx.scene.shapes` use the same ones):

==============  ============================================  ======================  =====================
shape           object space                                  uv                      normal
==============  ============================================  ======================  =====================
``sphere``      x² + y² + z² = 1                              (φ/2π, θ/π), θ = acos z outward, ``-`` if flipped
``disk``        z = 0, x² + y² ≤ 1                            (r, φ/2π)               +z (``to_world``'s inverse transpose)
``cylinder``    x² + y² = 1, 0 ≤ z ≤ 1 (open tube, no caps)   (φ/2π, z)               outward
==============  ============================================  ======================  =====================

with φ = atan2(y, x) ∈ [0, 2π). A shape is its ``to_world`` matrix (any
invertible affine map: a scaled sphere is an ellipsoid) and its orientation.

**Intersection.** The ray o + t·d (d unit, world space) is mapped to object
space as o' = M⁻¹o, d' = M⁻¹d *without* renormalizing d', so the root t is the
world distance. Quadrics are solved the robust way Mitsuba's ``sphere.cpp``
does: first the foot of the perpendicular from the centre (axis) onto the ray,
t_c = −(o'·d')/(d'·d'), then the half chord ±√((1 − |o' + t_c d'|²)/(d'·d')).
The naive discriminant B² − 4AC loses every digit when the ray starts far
away; this form loses none. The hit point is then re-projected onto the surface
(normalized on the sphere, z = 0 on the disk, unit radius on the cylinder), so
the point handed to a shading or spawning routine lies on the shape to float32
rounding, as Mitsuba does.

**Acceleration.** Shapes sit in their own ``wp.Bvh`` over world bounding
boxes, beside the triangle BVH of :class:`~grisx.scene.scene.BuiltScene`. A
closest-hit query traces the triangles first and asks this BVH only for boxes
before that hit (``bvh_query_next``'s ``max_dist``); a scene without analytic
shapes skips the query on a uniform branch (``count`` 0).

**Primitive ids.** Shape *k* is primitive ``prim_base + k`` (``prim_base`` =
the scene's triangle count), so every per-primitive table of the scene —
material, object, flags, emitter — is indexed by one id whatever the shape.
Emissive shapes stay tessellated (light sampling draws points on triangles);
the loader makes that choice.

References
----------
Mitsuba 3, ``src/shapes/{sphere,disk,cylinder}.cpp`` (intersection,
parametrization, orientation); M. Pharr et al., *Physically Based Rendering*,
4th ed., §6.2 and §6.8.3 (robust quadratics).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import warp as wp

wp.set_module_options({"enable_backward": False})

__all__ = [
    "SHAPE_SPHERE",
    "SHAPE_DISK",
    "SHAPE_CYLINDER",
    "SHAPE_KIND_NAMES",
    "AnalyticShape",
    "ShapeSet",
    "ShapeSurface",
    "shape_bounds",
    "build_shape_set",
    "intersect_shapes",
    "shapes_occluded",
    "shape_surface",
    "shape_normal_derivative",
]

SHAPE_SPHERE = wp.constant(0)
SHAPE_DISK = wp.constant(1)
SHAPE_CYLINDER = wp.constant(2)
SHAPE_KIND_NAMES = {"sphere": 0, "disk": 1, "cylinder": 2}

_NO_HIT = 3.0e38


@dataclasses.dataclass(frozen=True)
class AnalyticShape:
    """One analytic shape on the host: its kind (``SHAPE_KIND_NAMES``), ``to_world`` (4×4) and orientation."""

    kind: int
    to_world: np.ndarray
    flip_normals: bool = False

    @property
    def orientation(self) -> float:
        """+1 where the normal is the object-space one mapped to world (Mitsuba's rules for each shape), −1 flipped.

        ``sphere.cpp`` and ``cylinder.cpp`` flip a shape whose scale is negative (an inside-out sphere); the
        disk's normal is ``to_world``'s inverse transpose of +z, flipped only by ``flip_normals``.
        """
        mirrored = self.kind != SHAPE_KIND_NAMES["disk"] and np.linalg.det(self.to_world[:3, :3]) < 0.0
        return -1.0 if self.flip_normals != mirrored else 1.0


def shape_bounds(shape: AnalyticShape) -> tuple[np.ndarray, np.ndarray]:
    """World-space bounding box of ``shape``: exact for the ellipsoid, disk and tube images of the unit shapes."""
    m = np.asarray(shape.to_world, dtype=np.float64)
    a, c = m[:3, :3], m[:3, 3]
    if shape.kind == SHAPE_KIND_NAMES["sphere"]:  # |row_i| is the half extent of M·(unit ball) along axis i
        h = np.linalg.norm(a, axis=1)
        return c - h, c + h
    if shape.kind == SHAPE_KIND_NAMES["disk"]:
        h = np.linalg.norm(a[:, :2], axis=1)
        return c - h, c + h
    h = np.linalg.norm(a[:, :2], axis=1)  # cylinder: the unit circle at z = 0 and at z = 1
    top = c + a[:, 2]
    return np.minimum(c, top) - h, np.maximum(c, top) + h


@wp.struct
class ShapeSet:
    """The analytic shapes of a scene on the device (``count`` 0: none, and nothing is queried)."""

    bvh: wp.uint64
    count: int
    prim_base: int  # primitive id of shape 0: the scene's triangle count
    kind: wp.array(dtype=wp.int32)
    to_object: wp.array(dtype=wp.mat44)
    to_world: wp.array(dtype=wp.mat44)
    orientation: wp.array(dtype=float)  # +1 / −1 (AnalyticShape.orientation)


@wp.struct
class ShapeSurface:
    """A point on shape ``shape``: world position, unit geometric normal (oriented), uv."""

    p: wp.vec3
    n: wp.vec3
    uv: wp.vec2


def build_shape_set(shapes: list[AnalyticShape], prim_base: int, device: wp.context.Device) -> tuple[ShapeSet, wp.Bvh | None]:
    """Upload ``shapes`` (their BVH is returned too: the caller keeps it alive)."""
    s = ShapeSet()
    s.count = len(shapes)
    s.prim_base = int(prim_base)
    n = max(len(shapes), 1)
    to_world = np.tile(np.eye(4), (n, 1, 1))
    kinds = np.zeros(n, np.int32)
    orient = np.ones(n, np.float32)
    for i, sh in enumerate(shapes):
        to_world[i] = sh.to_world
        kinds[i] = sh.kind
        orient[i] = sh.orientation
    s.kind = wp.array(kinds, dtype=wp.int32, device=device)
    s.to_world = wp.array(to_world.astype(np.float32), dtype=wp.mat44, device=device)
    s.to_object = wp.array(np.linalg.inv(to_world).astype(np.float32), dtype=wp.mat44, device=device)
    s.orientation = wp.array(orient, dtype=float, device=device)
    bvh = None
    s.bvh = wp.uint64(0)
    if shapes:
        lo, hi = zip(*(shape_bounds(sh) for sh in shapes))
        lo, hi = np.array(lo), np.array(hi)
        pad = 1.0e-5 * np.maximum(np.abs(lo), np.abs(hi)).max(axis=1, keepdims=True) + 1.0e-7  # float32 rounding
        bvh = wp.Bvh(wp.array((lo - pad).astype(np.float32), dtype=wp.vec3, device=device),
                     wp.array((hi + pad).astype(np.float32), dtype=wp.vec3, device=device))
        s.bvh = bvh.id
    return s, bvh


# ---- object space ---------------------------------------------------------------


@wp.func
def _quadric_roots(o: wp.vec3, d: wp.vec3, axes: wp.vec3) -> wp.vec2:
    """Roots t of |o + t d|² = 1 over the coordinates ``axes`` selects ((1, 1, 1): the unit sphere; (1, 1, 0):
    the unit cylinder's tube), by the foot of the perpendicular (module docstring); (3e38, 3e38): a miss."""
    om = wp.cw_mul(o, axes)
    dm = wp.cw_mul(d, axes)
    a = wp.dot(dm, dm)
    if a <= 0.0:
        return wp.vec2(_NO_HIT, _NO_HIT)
    tc = -wp.dot(om, dm) / a
    foot = om + dm * tc
    h2 = 1.0 - wp.dot(foot, foot)  # |foot| ≤ 1: no cancellation against a far origin
    if h2 < 0.0:
        return wp.vec2(_NO_HIT, _NO_HIT)
    s = wp.sqrt(h2 / a)
    return wp.vec2(tc - s, tc + s)


@wp.func
def _shape_t(kind: int, o: wp.vec3, d: wp.vec3, t_max: float) -> float:
    """Nearest t in (0, t_max) where the object-space ray o + t·d meets unit shape ``kind``; 3e38 if none."""
    if kind == SHAPE_DISK:
        if d[2] == 0.0:
            return _NO_HIT
        t = -o[2] / d[2]
        if t <= 0.0 or t >= t_max:
            return _NO_HIT
        x = o[0] + t * d[0]
        y = o[1] + t * d[1]
        if x * x + y * y > 1.0:
            return _NO_HIT
        return t
    if kind == SHAPE_SPHERE:
        r = _quadric_roots(o, d, wp.vec3(1.0, 1.0, 1.0))
        if r[0] > 0.0 and r[0] < t_max:
            return r[0]
        if r[1] > 0.0 and r[1] < t_max:
            return r[1]
        return _NO_HIT
    # cylinder: the tube x² + y² = 1 cut to 0 ≤ z ≤ 1
    r = _quadric_roots(o, d, wp.vec3(1.0, 1.0, 0.0))
    for k in range(2):
        t = r[k]
        if t > 0.0 and t < t_max:
            z = o[2] + t * d[2]
            if z >= 0.0 and z <= 1.0:
                return t
    return _NO_HIT


# ---- queries (world space) ------------------------------------------------------------


@wp.func
def intersect_shapes(shapes: ShapeSet, o: wp.vec3, d: wp.vec3, t_max: float) -> wp.vec2:
    """Closest analytic hit of the ray o + t·d (d unit), 0 < t < t_max: (t, shape index), or (t_max, −1)."""
    best_t = t_max
    best = int(-1)
    query = wp.bvh_query_ray(shapes.bvh, o, d)
    k = int(0)
    while wp.bvh_query_next(query, k, best_t):
        m = shapes.to_object[k]
        t = _shape_t(shapes.kind[k], wp.transform_point(m, o), wp.transform_vector(m, d), best_t)
        if t < best_t:
            best_t = t
            best = k
    return wp.vec2(best_t, float(best))


@wp.func
def shapes_occluded(shapes: ShapeSet, o: wp.vec3, d: wp.vec3, t_max: float) -> bool:
    """Whether any analytic shape meets the ray o + t·d (d unit) for 0 < t < t_max."""
    query = wp.bvh_query_ray(shapes.bvh, o, d)
    k = int(0)
    while wp.bvh_query_next(query, k, t_max):
        m = shapes.to_object[k]
        if _shape_t(shapes.kind[k], wp.transform_point(m, o), wp.transform_vector(m, d), t_max) < t_max:
            return True
    return False


@wp.func
def _phi_over_2pi(x: float, y: float) -> float:
    u = wp.atan2(y, x) * (0.5 / wp.pi)
    if u < 0.0:
        u += 1.0
    return u


@wp.func
def shape_surface(shapes: ShapeSet, k: int, o: wp.vec3, d: wp.vec3, t: float) -> ShapeSurface:
    """The surface point of shape ``k`` where the ray o + t·d met it (re-projected onto the shape), its
    oriented geometric normal and Mitsuba's uv."""
    m = shapes.to_object[k]
    q = wp.transform_point(m, o + d * t)
    kind = shapes.kind[k]
    n = wp.vec3(0.0, 0.0, 1.0)
    uv = wp.vec2(0.0, 0.0)
    if kind == SHAPE_SPHERE:
        q = wp.normalize(q)
        n = q
        uv = wp.vec2(_phi_over_2pi(q[0], q[1]), wp.acos(wp.clamp(q[2], -1.0, 1.0)) / wp.pi)
    elif kind == SHAPE_DISK:
        q = wp.vec3(q[0], q[1], 0.0)
        uv = wp.vec2(wp.sqrt(q[0] * q[0] + q[1] * q[1]), _phi_over_2pi(q[0], q[1]))
    else:
        r = wp.sqrt(q[0] * q[0] + q[1] * q[1])
        if r > 0.0:
            q = wp.vec3(q[0] / r, q[1] / r, q[2])
        n = wp.vec3(q[0], q[1], 0.0)
        uv = wp.vec2(_phi_over_2pi(q[0], q[1]), q[2])
    out = ShapeSurface()
    out.p = wp.transform_point(shapes.to_world[k], q)
    # normals map by the inverse transpose: n_world ∝ (M⁻¹)ᵀ n_object
    out.n = wp.normalize(wp.transform_vector(wp.transpose(m), n)) * shapes.orientation[k]
    out.uv = uv
    return out


@wp.func
def shape_normal_derivative(shapes: ShapeSet, k: int, p: wp.vec3, n: wp.vec3, dp: wp.vec3) -> wp.vec3:
    """∂n: how the unit normal ``n`` of shape ``k`` at surface point ``p`` turns when ``p`` moves by the tangent
    displacement ``dp`` (the Weingarten map; exact, no differences): the object-space normal's change mapped by
    the inverse transpose, with its component along ``n`` removed (n stays unit)."""
    m = shapes.to_object[k]
    dq = wp.transform_vector(m, dp)
    kind = shapes.kind[k]
    dn_obj = wp.vec3(0.0, 0.0, 0.0)  # the disk is flat
    if kind == SHAPE_SPHERE:
        dn_obj = dq  # n_obj = q on the unit sphere (dq ⟂ q)
    elif kind == SHAPE_CYLINDER:
        dn_obj = wp.vec3(dq[0], dq[1], 0.0)  # n_obj = (q_x, q_y, 0)
    q = wp.transform_point(m, p)
    n_obj = q
    if kind == SHAPE_CYLINDER:
        n_obj = wp.vec3(q[0], q[1], 0.0)
    big_n = wp.transform_vector(wp.transpose(m), n_obj)  # the unnormalized world normal
    dbig = wp.transform_vector(wp.transpose(m), dn_obj) * shapes.orientation[k]
    return (dbig - n * wp.dot(n, dbig)) / wp.length(big_n)
