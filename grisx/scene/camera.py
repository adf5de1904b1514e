"""Cameras: Mitsuba's perspective sensor, thin lens, orthographic sensor, keyframed paths, and reprojection.

A camera is a frame ``to_world`` (camera → world, 4×4) and a field of view.
grisx follows Mitsuba 3's ``perspective`` sensor exactly, so a scene file
renders the same framing in both:

* camera space looks down **+z**, with **+y up** and **+x to the left**
  (``lookat(origin, target, up)`` builds the columns ``[left, up', dir, origin]``);
* film coordinates ``(sx, sy) ∈ [0,1]²`` run left→right and top→bottom; the
  film point ``(sx, sy)`` looks along camera direction
  ``((1 − 2 sx)·tan(fov_x/2), (1 − 2 sy)·tan(fov_y/2), 1)``;
* ``fov_axis`` (default ``"x"``) says which extent ``fov`` measures: ``x``,
  ``y``, ``diagonal``, ``smaller`` or ``larger``.

A thin lens (``aperture_radius > 0``) samples the lens disk concentrically
and focuses at ``focus_distance`` (Mitsuba's ``thinlens``).

An orthographic camera (Mitsuba's ``orthographic``) shoots parallel rays
along its +z from the film point ``((1 − 2 sx), (1 − 2 sy)/aspect, near_clip)``
of camera space (aspect = width / height); ``to_world`` may scale that film
(Mitsuba files do, ``<scale x="1.5" y="1.5"/>``), and world points project
back by dropping z instead of dividing by it.

:func:`camera_project` is the inverse of :func:`camera_ray` for pinhole
cameras: it maps a world point to continuous pixel coordinates, which is what
motion vectors into the previous frame need (seed 000 uses fractional motion
vectors for pixel pairs; seed 004's temporal reuse uses the integer ones).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
import warp as wp

from grisx.errors import InvalidParameterError
from grisx.theory.random import random_key, random_subkey, random_uniform

wp.set_module_options({"enable_backward": False})

__all__ = [
    "film_weight",
    "filter_reach",
    "gaussian_filter_sample",
    "tent_filter_sample",
    "Camera",
    "CameraPath",
    "CameraData",
    "camera_data_equal",
    "CameraRay",
    "PixelProjection",
    "lookat",
    "camera_ray",
    "camera_project",
    "CameraSample",
    "CAMERA_SAMPLE_STREAM",
    "camera_sample_key",
    "sample_camera",
    "FOV_AXES",
    "tan_half_fov",
]

FOV_AXES = ("x", "y", "diagonal", "smaller", "larger")
PROJECTIONS = ("perspective", "orthographic")


def lookat(origin: Sequence[float], target: Sequence[float], up: Sequence[float]) -> np.ndarray:
    """Mitsuba's ``lookat`` transform (camera → world): columns left, up', dir, origin."""
    o, t, u = (np.asarray(v, dtype=np.float64) for v in (origin, target, up))
    d = t - o
    if not np.all(np.isfinite(d)) or np.linalg.norm(d) == 0:
        raise InvalidParameterError(f"lookat: origin {o.tolist()} and target {t.tolist()} must differ")
    d /= np.linalg.norm(d)
    left = np.cross(u, d)
    if np.linalg.norm(left) < 1e-12:
        raise InvalidParameterError(f"lookat: up {u.tolist()} is parallel to the view direction {d.tolist()}")
    left /= np.linalg.norm(left)
    new_up = np.cross(d, left)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, new_up, d, o
    return m


def tan_half_fov(fov: float, fov_axis: str, width: int, height: int) -> tuple[float, float]:
    """(tan(fov_x/2), tan(fov_y/2)) of a perspective film of ``width``×``height`` whose ``fov`` (degrees)
    measures ``fov_axis`` (Mitsuba's rules; a projector's image follows them too)."""
    if fov_axis not in FOV_AXES:
        raise InvalidParameterError(f"fov_axis must be one of {', '.join(FOV_AXES)}, got {fov_axis!r}")
    if not (0.0 < float(fov) < 180.0):
        raise InvalidParameterError(f"fov must be in (0, 180) degrees, got {fov}")
    aspect = width / height
    t = math.tan(math.radians(fov) / 2)
    axis = fov_axis
    if axis == "smaller":
        axis = "x" if width <= height else "y"
    elif axis == "larger":
        axis = "x" if width >= height else "y"
    if axis == "x":
        return t, t / aspect
    if axis == "y":
        return t * aspect, t
    # diagonal: t is the half-diagonal tangent
    diag = math.hypot(aspect, 1.0)
    return t * aspect / diag, t / diag


@dataclasses.dataclass
class Camera:
    """A camera as Mitsuba's ``perspective``/``thinlens`` sensor describes it, or with ``projection="orthographic"``
    its ``orthographic`` sensor (``fov`` unused: the film spans [−1, 1] × [−1/aspect, 1/aspect] of the camera's
    x and y, scaled by ``to_world``)."""

    to_world: np.ndarray = dataclasses.field(default_factory=lambda: np.eye(4))
    fov: float = 39.3077
    fov_axis: str = "x"
    near_clip: float = 1e-2
    far_clip: float = 1e4
    aperture_radius: float = 0.0
    focus_distance: float = 0.0
    projection: str = "perspective"

    def __post_init__(self) -> None:
        self.to_world = np.asarray(self.to_world, dtype=np.float64).reshape(4, 4)
        if not np.all(np.isfinite(self.to_world)):
            raise InvalidParameterError("camera to_world must be finite")
        if not (0.0 < float(self.fov) < 180.0):
            raise InvalidParameterError(f"camera fov must be in (0, 180) degrees, got {self.fov}")
        if self.fov_axis not in FOV_AXES:
            raise InvalidParameterError(f"camera fov_axis must be one of {', '.join(FOV_AXES)}, got {self.fov_axis!r}")
        if self.aperture_radius < 0 or (self.aperture_radius > 0 and self.focus_distance <= 0):
            raise InvalidParameterError("thin lens needs aperture_radius >= 0 and a positive focus_distance")
        if self.projection not in PROJECTIONS:
            raise InvalidParameterError(f"camera projection must be one of {', '.join(PROJECTIONS)}, got {self.projection!r}")
        if self.projection == "orthographic" and self.aperture_radius > 0:
            raise InvalidParameterError("an orthographic camera has no lens (aperture_radius must be 0)")

    def tan_half_fov(self, width: int, height: int) -> tuple[float, float]:
        """(tan(fov_x/2), tan(fov_y/2)) for a film of ``width``×``height`` (Mitsuba's fov_axis rules)."""
        return tan_half_fov(self.fov, self.fov_axis, width, height)

    def data(self, width: int, height: int) -> CameraData:
        orthographic = self.projection == "orthographic"
        # orthographic.cpp: the film spans x ∈ [−1, 1], y ∈ [−1/aspect, 1/aspect] on the near plane (camera space)
        tx, ty = (1.0, height / width) if orthographic else self.tan_half_fov(width, height)
        c = CameraData()
        c.orthographic = int(orthographic)
        c.to_world = wp.mat44(*self.to_world.astype(np.float32).ravel())
        c.to_camera = wp.mat44(*np.linalg.inv(self.to_world).astype(np.float32).ravel())
        c.tan_half = wp.vec2(tx, ty)
        c.width = int(width)
        c.height = int(height)
        c.aperture_radius = float(self.aperture_radius)
        c.focus_distance = float(self.focus_distance) if self.aperture_radius > 0 else 1.0
        c.near_clip = float(self.near_clip)
        c.far_clip = float(self.far_clip)
        c.filter_stddev = 0.0  # the film's; set by BuiltScene.camera_data
        c.filter_tent = 0.0
        return c


@dataclasses.dataclass
class CameraPath:
    """Keyframed camera: ``(origin, target, up)`` keys interpolated linearly, ``frames_per_key`` frames apart.

    The path loops back to its first key, so it can be rendered for any
    number of frames. Interpolating origin and target (rather than matrices)
    keeps every in-between frame a proper ``lookat``. ``easing`` shapes the
    time between keys: ``smoothstep`` (velocity continuous at the keys, zero
    there) or ``linear`` (constant speed from the first frame on, what a test
    of temporal reuse under a moving camera wants).
    """

    keys: list[tuple[Sequence[float], Sequence[float], Sequence[float]]]
    frames_per_key: float = 30.0
    loop: bool = True
    easing: str = "smoothstep"

    def __post_init__(self) -> None:
        if len(self.keys) < 1:
            raise InvalidParameterError("a camera path needs at least one key")
        if self.frames_per_key <= 0:
            raise InvalidParameterError("frames_per_key must be positive")
        if self.easing not in ("smoothstep", "linear"):
            raise InvalidParameterError(f"camera path easing must be smoothstep or linear, got {self.easing!r}")

    def to_world(self, frame: float) -> np.ndarray:
        keys = [tuple(np.asarray(v, dtype=np.float64) for v in k) for k in self.keys]
        if len(keys) == 1:
            return lookat(*keys[0])
        s = frame / self.frames_per_key
        if self.loop:
            s %= len(keys)
            i = int(math.floor(s)) % len(keys)
        else:
            s = min(max(s, 0.0), len(keys) - 1.0)
            i = min(int(math.floor(s)), len(keys) - 2)
        f = s - i
        a, b = keys[i], keys[(i + 1) % len(keys)]
        if self.easing == "smoothstep":  # velocity is continuous at keys
            f = f * f * (3 - 2 * f)
        return lookat(*(a[j] * (1 - f) + b[j] * f for j in range(3)))


@wp.struct
class CameraData:
    to_world: wp.mat44  # camera → world
    to_camera: wp.mat44  # world → camera
    tan_half: wp.vec2  # tan(fov_x/2), tan(fov_y/2); orthographic: the film's half extents (1, 1/aspect)
    orthographic: int  # 1: parallel rays from the near plane (Mitsuba's orthographic sensor)
    width: int
    height: int
    aperture_radius: float
    focus_distance: float
    near_clip: float
    far_clip: float
    filter_stddev: float  # the film's reconstruction filter: 0 = box, else Mitsuba's gaussian (pixels)
    filter_tent: float  # or, when > 0, Mitsuba's tent of this radius (pixels)


def camera_data_equal(a: CameraData, b: CameraData) -> bool:
    """Whether two camera records are the same camera, field by field (a still camera between two frames)."""
    return all(np.array_equal(np.asarray(getattr(a, name)), np.asarray(getattr(b, name))) for name in CameraData.vars)


@wp.struct
class CameraRay:
    o: wp.vec3
    d: wp.vec3  # unit


@wp.struct
class PixelProjection:
    pixel: wp.vec2  # continuous pixel coordinates (x right, y down; pixel centers at +0.5)
    depth: float  # camera-space z
    valid: int  # in front of the camera
    inside: int  # and inside the film


@wp.func
def _concentric_disk(u: wp.vec2) -> wp.vec2:
    # Shirley–Chiu concentric mapping (pbrt-v4 SampleUniformDiskConcentric)
    a = 2.0 * u[0] - 1.0
    b = 2.0 * u[1] - 1.0
    if a == 0.0 and b == 0.0:
        return wp.vec2(0.0, 0.0)
    r = float(0.0)
    theta = float(0.0)
    if wp.abs(a) > wp.abs(b):
        r = a
        theta = (wp.pi / 4.0) * (b / a)
    else:
        r = b
        theta = wp.pi / 2.0 - (wp.pi / 4.0) * (a / b)
    return wp.vec2(r * wp.cos(theta), r * wp.sin(theta))


@wp.func
def camera_ray(cam: CameraData, px: float, py: float, u_lens: wp.vec2) -> CameraRay:
    """The primary ray through continuous pixel position (px, py) (Mitsuba's perspective/thinlens; orthographic: from
    the film point on the near plane along the camera's +z)."""
    sx = px / float(cam.width)
    sy = py / float(cam.height)
    film = wp.vec2((1.0 - 2.0 * sx) * cam.tan_half[0], (1.0 - 2.0 * sy) * cam.tan_half[1])
    r = CameraRay()
    if cam.orthographic != 0:
        r.o = wp.transform_point(cam.to_world, wp.vec3(film[0], film[1], cam.near_clip))
        r.d = wp.normalize(wp.transform_vector(cam.to_world, wp.vec3(0.0, 0.0, 1.0)))
        return r
    d_cam = wp.vec3(film[0], film[1], 1.0)
    o_cam = wp.vec3(0.0, 0.0, 0.0)
    if cam.aperture_radius > 0.0:
        lens = cam.aperture_radius * _concentric_disk(u_lens)
        focus = d_cam * cam.focus_distance
        o_cam = wp.vec3(lens[0], lens[1], 0.0)
        d_cam = focus - o_cam
    r.o = wp.transform_point(cam.to_world, o_cam)
    r.d = wp.normalize(wp.transform_vector(cam.to_world, d_cam))
    return r


#: random stream of a pixel's camera sample (apart from every renderer's own per-pixel streams)
CAMERA_SAMPLE_STREAM = wp.constant(7919)


@wp.struct
class CameraSample:
    """Where a primary ray leaves from: a continuous pixel position and a point of the unit lens square."""

    pixel: wp.vec2
    lens: wp.vec2


@wp.func
def camera_sample_key(seed: int, frame: int, pixel: int) -> wp.uint32:
    """The key of pixel ``pixel``'s camera sample in ``frame`` (one per pixel and frame).

    The G-buffer, the screen-space ReSTIR renderers' visible points and ReSTIR PT's primary
    vertices all draw from it, so in one frame they see the same point of each pixel: the
    similarity tests and motion vectors of the G-buffer then describe the points reused.
    """
    return random_subkey(random_subkey(random_key(seed, frame), pixel), CAMERA_SAMPLE_STREAM)


#: Mitsuba's gaussian filter reaches 4 standard deviations; tries of the rejection step (each accepts with p > 0.99)
GAUSSIAN_RADIUS = wp.constant(4.0)
GAUSSIAN_TRIES = wp.constant(16)
_SQRT2 = wp.constant(1.4142135623730951)
_SQRT_HALF_PI = wp.constant(1.2533141373155003)  # ∫ e^{−t²/2} dt over ℝ is 2·√(π/2)


@wp.func
def _gaussian_cdf(t: float, stddev: float) -> float:
    return 0.5 * (1.0 + wp.erf(t / (stddev * _SQRT2)))


@wp.func
def sample_gaussian_offset(u: float, stddev: float, lo: float, hi: float) -> float:
    """An offset t ∈ [lo, hi] with density ∝ exp(−t²/2σ²) there (inverse CDF of the truncated gaussian)."""
    a = _gaussian_cdf(lo, stddev)
    b = _gaussian_cdf(hi, stddev)
    q = wp.clamp(2.0 * (a + u * (b - a)) - 1.0, -0.9999999, 0.9999999)
    return wp.clamp(stddev * _SQRT2 * wp.erfinv(q), lo, hi)


@wp.func
def gaussian_filter_sample(key: wp.uint32, x: int, y: int, width: int, height: int, stddev: float) -> wp.vec2:
    """A film position for pixel (x, y) distributed as Mitsuba's ``gaussian`` filter around its centre.

    Mitsuba splats every sample onto the pixels within r = 4σ with weight
    f(t) = max(0, exp(−t²/2σ²) − exp(−r²/2σ²)) per axis and divides by the weights' sum
    (samples come from inside the film only), so a pixel estimates
    ∫ f·L / ∫ f over the film. Drawing the position from f restricted to the film
    estimates the same with weight 1: per axis a gaussian truncated to
    [−r, r] ∩ film by its inverse CDF, then the constant offset removed by rejection,
    accepting with (1 − b/g(t_x))(1 − b/g(t_y)) (b = exp(−r²/2σ²), g the gaussian;
    p > 0.99 per try). Random counters 16, 17, 18, ... of ``key``.
    """
    cx = float(x) + 0.5
    cy = float(y) + 0.5
    r = GAUSSIAN_RADIUS * stddev
    inv2var = 1.0 / (2.0 * stddev * stddev)
    bias = wp.exp(-r * r * inv2var)
    p = wp.vec2(cx, cy)
    for k in range(GAUSSIAN_TRIES):
        tx = sample_gaussian_offset(random_uniform(key, 16 + 3 * k), stddev, wp.max(-r, -cx), wp.min(r, float(width) - cx))
        ty = sample_gaussian_offset(random_uniform(key, 17 + 3 * k), stddev, wp.max(-r, -cy), wp.min(r, float(height) - cy))
        p = wp.vec2(cx + tx, cy + ty)
        accept = (1.0 - bias * wp.exp(tx * tx * inv2var)) * (1.0 - bias * wp.exp(ty * ty * inv2var))
        if random_uniform(key, 18 + 3 * k) < accept:
            break
    return p


@wp.func
def _tent_cdf(t: float, r: float) -> float:
    """∫ from −r to t of (1 − |s|/r) ds, divided by r (the tent's integral): 0 at −r, ½ at 0, 1 at r."""
    q = wp.clamp(t / r, -1.0, 1.0)
    if q <= 0.0:
        return 0.5 * (1.0 + q) * (1.0 + q)
    return 1.0 - 0.5 * (1.0 - q) * (1.0 - q)


@wp.func
def sample_tent_offset(u: float, r: float, lo: float, hi: float) -> float:
    """An offset t ∈ [lo, hi] ⊂ [−r, r] with density ∝ 1 − |t|/r there (inverse CDF of the truncated tent)."""
    v = _tent_cdf(lo, r) + u * (_tent_cdf(hi, r) - _tent_cdf(lo, r))
    t = r * (1.0 - wp.sqrt(wp.max(0.0, 2.0 * (1.0 - v))))
    if v <= 0.5:
        t = r * (wp.sqrt(wp.max(0.0, 2.0 * v)) - 1.0)
    return wp.clamp(t, lo, hi)


@wp.func
def tent_filter_sample(key: wp.uint32, x: int, y: int, width: int, height: int, radius: float) -> wp.vec2:
    """A film position for pixel (x, y) distributed as Mitsuba's ``tent`` filter f(t) = max(0, 1 − |t|/r) per axis
    around its centre, restricted to the film (so the pixel estimates ∫ f·L / ∫ f over the film, as Mitsuba's
    splatting film does; see :func:`gaussian_filter_sample`): per axis by the truncated tent's inverse CDF,
    no rejection. Random counters 16 and 17 of ``key``."""
    cx = float(x) + 0.5
    cy = float(y) + 0.5
    tx = sample_tent_offset(random_uniform(key, 16), radius, wp.max(-radius, -cx), wp.min(radius, float(width) - cx))
    ty = sample_tent_offset(random_uniform(key, 17), radius, wp.max(-radius, -cy), wp.min(radius, float(height) - cy))
    return wp.vec2(cx + tx, cy + ty)


@wp.func
def filter_reach(cam: CameraData) -> float:
    """How far the pixel filter reaches from the pixel's centre: ½ (box), r = 4σ (Mitsuba's gaussian) or the tent's r."""
    if cam.filter_stddev > 0.0:
        return GAUSSIAN_RADIUS * cam.filter_stddev
    if cam.filter_tent > 0.0:
        return cam.filter_tent
    return 0.5


@wp.func
def _gaussian_axis(t: float, r: float, inv2var: float) -> float:
    return wp.max(0.0, wp.exp(-t * t * inv2var) - wp.exp(-r * r * inv2var))


@wp.func
def _gaussian_axis_integral(c: float, size: float, stddev: float) -> float:
    """∫ f(t) dt over the filter's support [−r, r] ∩ the film, for a pixel centre at c on an axis of ``size`` pixels."""
    r = GAUSSIAN_RADIUS * stddev
    a = wp.max(-r, -c)
    b = wp.min(r, size - c)
    s2 = stddev * _SQRT2
    return stddev * _SQRT_HALF_PI * (wp.erf(b / s2) - wp.erf(a / s2)) - wp.exp(-r * r / (2.0 * stddev * stddev)) * (b - a)


@wp.func
def film_weight(cam: CameraData, x: int, y: int, offset: wp.vec2) -> float:
    """ω_i(u) = (support area) · w_i(u − ½): pixel (x, y)'s filter, normalized over its part inside the film (what
    Mitsuba's splatting film converges to), times the area of its support — the weight of a film sample at
    (x, y) + ``offset`` drawn uniformly over that support (:func:`filter_reach`); 0 outside the film."""
    px = float(x) + offset[0]
    py = float(y) + offset[1]
    if px < 0.0 or py < 0.0 or px >= float(cam.width) or py >= float(cam.height):
        return 0.0  # Mitsuba's film takes samples from inside the film only
    sd = cam.filter_stddev
    if cam.filter_tent > 0.0:
        r = cam.filter_tent
        cx = float(x) + 0.5
        cy = float(y) + 0.5
        w = wp.max(0.0, 1.0 - wp.abs(px - cx) / r) * wp.max(0.0, 1.0 - wp.abs(py - cy) / r)
        zx = r * (_tent_cdf(wp.min(r, float(cam.width) - cx), r) - _tent_cdf(wp.max(-r, -cx), r))
        zy = r * (_tent_cdf(wp.min(r, float(cam.height) - cy), r) - _tent_cdf(wp.max(-r, -cy), r))
        return 4.0 * r * r * w / (zx * zy)
    if sd <= 0.0:
        return 1.0
    r = GAUSSIAN_RADIUS * sd
    inv2var = 1.0 / (2.0 * sd * sd)
    cx = float(x) + 0.5
    cy = float(y) + 0.5
    w = _gaussian_axis(px - cx, r, inv2var) * _gaussian_axis(py - cy, r, inv2var)
    z = _gaussian_axis_integral(cx, float(cam.width), sd) * _gaussian_axis_integral(cy, float(cam.height), sd)
    return 4.0 * r * r * w / z


@wp.func
def sample_camera(cam: CameraData, key: wp.uint32, x: int, y: int, jitter: int) -> CameraSample:
    """Pixel (x, y)'s camera sample: with ``jitter`` a point of the pixel's filter footprint — uniform
    over the pixel for a box filter (counters 0–1 of ``key``), :func:`gaussian_filter_sample` for
    Mitsuba's gaussian — and a uniform point of the lens (counters 2–3); else the pixel centre
    through the lens centre."""
    s = CameraSample()
    s.pixel = wp.vec2(float(x) + 0.5, float(y) + 0.5)
    s.lens = wp.vec2(0.5, 0.5)
    if jitter != 0:
        if cam.filter_stddev > 0.0:
            s.pixel = gaussian_filter_sample(key, x, y, cam.width, cam.height, cam.filter_stddev)
        elif cam.filter_tent > 0.0:
            s.pixel = tent_filter_sample(key, x, y, cam.width, cam.height, cam.filter_tent)
        else:
            s.pixel = wp.vec2(float(x) + random_uniform(key, 0), float(y) + random_uniform(key, 1))
        s.lens = wp.vec2(random_uniform(key, 2), random_uniform(key, 3))
    return s


@wp.func
def camera_project(cam: CameraData, p: wp.vec3) -> PixelProjection:
    """Continuous pixel coordinates of world point ``p`` (inverse of the pinhole or orthographic ``camera_ray``)."""
    q = wp.transform_point(cam.to_camera, p)
    out = PixelProjection()
    out.depth = q[2]
    out.valid = 0
    out.inside = 0
    film = wp.vec2(q[0], q[1])
    if cam.orthographic != 0:
        if q[2] < cam.near_clip:  # behind the near plane the rays start from
            return out
    else:
        if q[2] <= 1.0e-8:
            return out
        film = film / q[2]
    out.valid = 1
    sx = 0.5 * (1.0 - film[0] / cam.tan_half[0])
    sy = 0.5 * (1.0 - film[1] / cam.tan_half[1])
    out.pixel = wp.vec2(sx * float(cam.width), sy * float(cam.height))
    if sx >= 0.0 and sx < 1.0 and sy >= 0.0 and sy < 1.0:
        out.inside = 1
    return out
