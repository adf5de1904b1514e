"""Light sources and next-event estimation: which light, which point, with what density.

Direct lighting at a point x with normal n estimates

    E = ∫ L_e(y → x) |cos θ_x| dω  ≈  L_e(y → x) |cos θ_x| / p_ω(y),

so a light sampler must return a direction ``wi`` (x → light), the radiance
arriving along it and its density ``pdf`` *in solid angle, including the choice
of light* — and a BSDF-sampled ray that hits a light must be able to ask for
the same density (:func:`light_pdf_emitter`, :func:`environment_pdf`) for MIS.
The conventions are Mitsuba 3's, so a scene file means the same light here.

Light selection
    All lights share one alias table (:mod:`grisx.scene.distribution`).
    Each light has a power: an emissive triangle of area A and radiance L
    emits Φ = π A lum(L) (one-sided Lambertian); a point light of intensity
    I emits 4π lum(I); an environment of radiance L(ω) delivers
    Φ = π R² ∫ lum(L) dω through the scene's bounding sphere of radius R
    (pbrt-v4's estimate); other delta lights as below. ``lum`` is Mitsuba's
    luminance (0.212671, 0.715160, 0.072169). The probability of part k
    (a triangle, or a whole delta light or environment) of light g (an
    emitting shape, or that light itself) among G lit lights is the
    defensive mixture (:func:`selection_weights`)

        P(k) = ¼ Φ_k / Σ Φ  +  ¾ (1 / G) Φ_k / Φ_g,

    mostly uniform over lights, as Mitsuba 3 picks emitters, and a quarter by
    power. Power alone ignores where the light lands: a sky's power flows
    through the whole bounding sphere while a spot a metre from a wall puts
    its little power where the camera looks (mitsuba-data's
    ``test_spot_direct``: by power the spot got 1% of the samples and its
    pixels far more than Mitsuba's variance; Mitsuba's verdict there, the
    spread of its z-values: ½/½ 1.45 and 17 failing values of the 17
    allowed, ¾ uniform 1.20 and 1, all uniform 1.02 and 0). The power
    quarter keeps a scene of many unequal lights within 4× of power
    sampling, the uniform part within 4/3 of Mitsuba's. A scene of one
    light (of any number of triangles) is sampled ∝ power, as before. On the
    built-in scenes of several lights, ``pt``'s per-pixel relative variance
    against power alone (48×36, 2 spp, 24 frames, CPU): red-green-lights
    0.63×, caustic-slab-plane 0.87×, metal-rack 0.89×, many-lights 1.00×,
    checker-grid 1.08×, swimming-pool 1.18×.
    Selection indices: emissive triangles first (emitter order), then delta
    lights, then the environment.

Emissive triangles (Mitsuba ``area``)
    A point is drawn uniformly on the chosen triangle (Mitsuba's
    ``square_to_uniform_triangle``: b₁ = 1 − √(1 − u₀), b₂ = √(1 − u₀) u₁),
    density 1 / A in area, converted to solid angle by the Jacobian

        p_ω = p_A · ‖y − x‖² / |cos θ_y|        (PBR 4th ed., Eq. 4.12)

    with θ_y between the light's geometric normal and the direction to x.
    Emission is one-sided: L_e toward w is the emitter's radiance only when
    w is on the normal's side (the normal follows the winding,
    (p₁ − p₀) × (p₂ − p₀)), else 0 — the density does not care about sides.
    Triangle areas are read from the live positions, so a rigid motion of the
    scene (which moves ``positions`` in place) keeps pdfs exact.

Delta lights (Mitsuba ``point``, ``spot``, ``projector``, ``directional``)
    Lights that are a delta in position or in direction: ``delta = 1``,
    ``pdf`` = the selection probability (a discrete, not a solid-angle,
    density), and ``radiance`` the radiance they deliver at the reference
    point. One function, :func:`delta_light_arrival`, gives it — when a
    light is sampled and when a renderer re-evaluates a stored sample at
    another point (a reuse method's neighbour, a shifted path's vertex):

    * point: intensity I (W/sr), radiance I / d²; selection power 4π lum(I);
    * spot: I·s(ω) / d² with Mitsuba's falloff s(ω) = 1 inside the beam
      (θ ≤ beam_width), (cutoff − θ)/(cutoff − beam_width) between beam and
      cutoff, 0 beyond; with a ``texture`` T, I·s(ω)·T(uv) / d² at
      uv = ½ + ½ (x, y) / (z tan cutoff) of ω in the spot's frame (``spot.cpp``);
      power 2π(1 − cos cutoff) lum(I) (× T's mean luminance), a bound;
    * projector: a perspective camera run backwards (``projector.cpp``): ω in
      the projector's frame (+z forward) lands on the film point
      uv = (½(1 − x/(z t_x)), ½(1 − y/(z t_y))) (the camera's mapping, t the
      half-fov tangents), and delivers E(uv)·π·scale / (z_p² cos θ), z_p the
      reference point's depth — an intensity π·scale·E(uv)/cos³θ, so a plane
      facing it at depth h receives the irradiance π·scale·E(uv)/h²;
      power ∫ I dω = π·scale·4 t_x t_y·mean lum(E) (dω = cos³θ dA on the film
      plane z = 1);
    * directional: irradiance E arriving along −d from infinitely far; the
      sample point sits 2·max(R, ‖x − c‖) back along the beam (beyond every
      surface: R, c the scene's bounding sphere), radiance E; power π R² lum(E)
      (Mitsuba's ``sample_ray`` weight), like the environment's.

Constant environment (Mitsuba ``constant``)
    Radiance L from every direction, sampled uniformly on the sphere
    (Mitsuba's ``square_to_uniform_sphere``), p_ω = 1 / 4π.

Image environment (Mitsuba ``envmap``)
    An equirectangular H × W image; in the emitter's local frame (+Y up) a
    direction d maps to

        u = atan2(d_x, −d_z) / 2π,   v = acos(d_y) / π,
        d = (sin φ sin θ, cos θ, −cos φ sin θ),  φ = 2π u, θ = π v,

    and world directions go through ``to_world`` (a rotation). As in Mitsuba 3,
    pixel column x is centred at u = (x + ½) / W and row y lies at
    v = y / (H − 1) (row 0 at the north pole +Y, row H − 1 at the south pole),
    radiance is interpolated bilinearly between them (wrapping in u) and
    multiplied by ``scale``. Importance sampling uses a piecewise-constant 2D
    distribution over the (W) × (H − 1) cells between pixel centres, each
    weighted by the cell mean of the bilinear luminance (the mean of its four
    corners: nonzero wherever the radiance is) times the band mean of sin θ;
    the density in (u, v) becomes a solid-angle density by

        p_ω = p_uv / (2π² sin θ)               (PBR 4th ed., Eq. 12.8).

``world_dir`` arguments of the environment functions point from the scene
out toward the environment (a ray's direction).

Directions in :class:`LightSample` are unit vectors from the reference point
toward the light; ``dist`` is 1e30 for the environment (whose ``p`` holds the
direction). A sample with ``pdf == 0`` is invalid (no light, zero power,
degenerate geometry) and must be skipped.

Renderers' kernels take ``sample_light``, ``sample_given_light``, ``emitter_radiance``,
``environment_eval``, ``environment_pdf`` and ``delta_light_arrival`` from
:func:`make_lights` with their scene's kinds, which compiles each kind of light
only where the scene has it (the ``SCENE_*`` pseudo-kinds of
:mod:`grisx.scene.material`); the module-level functions of the same names have
every kind compiled in.

References: M. Pharr, W. Jakob, G. Humphreys, *Physically Based Rendering*,
4th ed. (2023), §4.2 (solid angle ↔ area), §12.2–12.5 (light sampling,
``PowerLightSampler``, ``ImageInfiniteLight``); W. Jakob et al., Mitsuba 3,
``src/emitters/{area,point,spot,projector,directional,constant,envmap}.cpp`` and ``warp.h``.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import warp as wp

from grisx.errors import InvalidParameterError, InvalidValueError
from grisx.imageio import srgb_decode
from grisx.theory.gris import LUMINANCE_WEIGHTS, luminance
from grisx.scene.material import SCENE_DELTA_LIGHTS, SCENE_EMITTER_TEXTURES, SCENE_ENVMAP, SCENE_KINDS
from grisx.scene.texture import Bitmap, TextureSet, pack_textures, texture_lookup
from grisx.scene.distribution import (
    AliasTable,
    PiecewiseConstant2D,
    alias_pmf,
    build_alias_table,
    build_piecewise_constant_2d,
    piecewise_constant_2d_pdf,
    sample_alias,
    sample_piecewise_constant_2d,
)

wp.set_module_options({"enable_backward": False})

__all__ = [
    "PointLight",
    "Projector",
    "DirectionalLight",
    "DeltaArrival",
    "delta_light_arrival",
    "LightFuncs",
    "make_lights",
    "DELTA_POINT",
    "DELTA_PROJECTOR",
    "DELTA_DIRECTIONAL",
    "rigid_frame",
    "ConstantEnvironment",
    "EnvMap",
    "ENV_NONE",
    "ENV_CONSTANT",
    "ENV_ENVMAP",
    "LUMINANCE_WEIGHTS",
    "LightSet",
    "LightSample",
    "build_light_set",
    "load_envmap_image",
    "luminance",
    "sample_uniform_triangle",
    "invert_uniform_triangle",
    "sample_uniform_sphere",
    "uniform_sphere_pdf",
    "pdf_area_to_solid_angle",
    "envmap_direction_to_uv",
    "envmap_uv_to_direction",
    "sample_light",
    "sample_given_light",
    "selection_weights",
    "light_pdf_emitter",
    "emitter_radiance",
    "triangle_barycentrics",
    "environment_eval",
    "environment_pdf",
]

DELTA_POINT = wp.constant(0)
DELTA_PROJECTOR = wp.constant(1)
DELTA_DIRECTIONAL = wp.constant(2)
ENV_NONE = wp.constant(0)
ENV_CONSTANT = wp.constant(1)
ENV_ENVMAP = wp.constant(2)

#: ``dist`` of an environment sample (an infinitely distant light)
_ENV_DIST = wp.constant(1.0e30)
_INV_FOUR_PI = wp.constant(1.0 / (4.0 * math.pi))
_INV_TWO_PI_SQ = wp.constant(1.0 / (2.0 * math.pi * math.pi))


# ---- Python records --------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class PointLight:
    """Mitsuba ``point``: isotropic point light of RGB ``intensity`` (W/sr) at ``position``; with a
    ``direction``, Mitsuba's ``spot``: a cone of half-angle ``cutoff_angle`` (degrees), full intensity
    within ``beam_width`` (default ¾ of the cutoff), a linear falloff in angle between them."""

    position: tuple[float, float, float] | np.ndarray
    intensity: tuple[float, float, float] | np.ndarray | float
    direction: tuple[float, float, float] | np.ndarray | None = None
    cutoff_angle: float = 20.0
    beam_width: float | None = None
    #: a spot's ``texture``: a linear RGB image (H, W, 3) multiplying the intensity, spread over the cone
    texture: Any = None
    #: the spot's frame (4×4, local → world; its +z is ``direction``): where the texture's axes lie
    to_world: Any = None


@dataclasses.dataclass(frozen=True)
class Projector:
    """Mitsuba ``projector``: a perspective camera run backwards — the ``irradiance`` image (linear RGB
    (H, W, 3), or one RGB colour) projected from ``to_world`` (4×4, a rigid frame looking down its +z)
    with field of view ``fov`` (degrees) along ``fov_axis`` (the camera's rules, the image's aspect)
    and ``scale``."""

    to_world: Any
    irradiance: Any = 1.0
    scale: float = 1.0
    fov: float = 45.0
    fov_axis: str = "x"


@dataclasses.dataclass(frozen=True)
class DirectionalLight:
    """Mitsuba ``directional``: RGB ``irradiance`` (W/m² on a surface facing it) arriving along the unit
    ``direction`` it travels in, from infinitely far away."""

    direction: tuple[float, float, float] | np.ndarray
    irradiance: tuple[float, float, float] | np.ndarray | float = 1.0


@dataclasses.dataclass(frozen=True)
class ConstantEnvironment:
    """Mitsuba ``constant``: RGB ``radiance`` arriving from every direction."""

    radiance: tuple[float, float, float] | np.ndarray | float


@dataclasses.dataclass(frozen=True)
class EnvMap:
    """Mitsuba ``envmap``: equirectangular radiance ``image`` (H×W×3 linear array, or an EXR/PNG path).

    ``scale`` multiplies the radiance; ``to_world`` (4×4, its upper 3×3 a
    rotation) places the map's +Y-up frame in the world.
    """

    image: Any
    scale: float = 1.0
    to_world: Any = None


# ---- validation helpers --------------------------------------------------------------


def _rgb(value: Any, what: str) -> np.ndarray:
    a = np.asarray(value, dtype=np.float64)
    if a.ndim == 0:
        a = np.full(3, float(a))
    if a.shape != (3,):
        raise InvalidParameterError(f"{what} must be an RGB triple or a scalar, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise InvalidValueError(f"{what} contains NaN or Inf: {a.tolist()}")
    if np.any(a < 0):
        raise InvalidValueError(f"{what} must be non-negative, got {a.tolist()}")
    return a


def _lum(rgb: np.ndarray) -> np.ndarray:
    return np.asarray(rgb, dtype=np.float64) @ np.asarray(LUMINANCE_WEIGHTS)


def load_envmap_image(source: Any) -> np.ndarray:
    """An envmap image as float64 (H, W, 3) linear RGB, from an array or an EXR / PNG / JPEG file."""
    if isinstance(source, (str, os.PathLike)):
        path = Path(source)
        if not path.is_file():
            raise InvalidParameterError(f"envmap image '{path}': no such file")
        suffix = path.suffix.lower()
        if suffix == ".exr":
            from grisx.imageio import read_exr

            img = np.asarray(read_exr(path), dtype=np.float64)
        elif suffix in (".png", ".jpg", ".jpeg"):
            from PIL import Image

            with Image.open(path) as im:
                raw = np.asarray(im.convert("RGB"), dtype=np.float64) / 255.0
            img = srgb_decode(raw)
        else:
            raise InvalidParameterError(f"envmap image '{path}': unsupported format '{suffix}' (use .exr, .png or .jpg)")
        what = f"envmap image '{path}'"
    else:
        img = np.asarray(source, dtype=np.float64)
        what = "envmap image"
    if img.ndim == 2:
        img = np.repeat(img[:, :, None], 3, axis=2)
    if img.ndim != 3 or img.shape[2] not in (1, 3, 4):
        raise InvalidParameterError(f"{what} must have shape (H, W), (H, W, 3) or (H, W, 4), got {img.shape}")
    if img.shape[2] == 1:
        img = np.repeat(img, 3, axis=2)
    img = img[:, :, :3]
    h, w = img.shape[:2]
    if w < 2 or h < 3:
        raise InvalidParameterError(f"{what}: the resolution must be at least 2x3 pixels (W x H), got {w}x{h}")
    if not np.all(np.isfinite(img)):
        raise InvalidValueError(f"{what} contains NaN or Inf")
    if np.any(img < 0):
        raise InvalidValueError(f"{what} contains negative radiance (min {img.min():g})")
    return img


def _rotation(to_world: Any) -> np.ndarray:
    if to_world is None:
        return np.eye(3)
    m = np.asarray(to_world, dtype=np.float64)
    if m.shape not in ((4, 4), (3, 3)):
        raise InvalidParameterError(f"EnvMap.to_world must be a 4x4 (or 3x3) matrix, got shape {m.shape}")
    if not np.all(np.isfinite(m)):
        raise InvalidValueError("EnvMap.to_world contains NaN or Inf")
    r = m[:3, :3]
    if not np.allclose(r.T @ r, np.eye(3), atol=1e-4):
        raise InvalidParameterError("EnvMap.to_world must be a rotation (orthonormal upper 3x3); scaling or shearing an environment is not supported")
    return r


def rigid_frame(to_world: Any, what: str) -> np.ndarray:
    """``to_world`` as a 4×4 array, checked to be a rigid frame (a rotation and a translation)."""
    m = np.asarray(to_world, dtype=np.float64)
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise InvalidParameterError(f"{what} must be a finite 4x4 matrix, got shape {m.shape}")
    r = m[:3, :3]
    if not np.allclose(r.T @ r, np.eye(3), atol=1e-4):
        raise InvalidParameterError(f"{what} must be a rigid frame (orthonormal upper 3x3); scaling a projector or a spot's texture is not supported")
    return m


def _light_image(value: Any, what: str) -> np.ndarray | Bitmap:
    """A light's image: an (H, W, 3) linear RGB array, a :class:`~grisx.scene.texture.Bitmap` (an image
    with a ``to_uv`` map), or one colour (a 1×1 image); validated."""
    if isinstance(value, Bitmap):
        return dataclasses.replace(value, image=_light_image(value.image, what))
    a = np.asarray(value, dtype=np.float64)
    if a.ndim <= 1:
        return _rgb(a, what).reshape(1, 1, 3)
    if a.ndim == 2:
        a = np.repeat(a[:, :, None], 3, axis=2)
    if a.ndim != 3 or a.shape[2] not in (3, 4) or a.shape[0] < 1 or a.shape[1] < 1:
        raise InvalidParameterError(f"{what} must be an RGB colour or an (H, W, 3) image, got shape {a.shape}")
    a = a[:, :, :3]
    if not np.all(np.isfinite(a)) or np.any(a < 0):
        raise InvalidValueError(f"{what} must be finite and non-negative")
    return a


def _pixels(image: np.ndarray | Bitmap) -> np.ndarray:
    return image.image if isinstance(image, Bitmap) else image


# ---- Warp records ------------------------------------------------------------------------


@wp.struct
class LightSet:
    """Every light of a scene and the alias table that selects among them (see the module docstring)."""

    selection: AliasTable  # over [emissive triangles | point lights | environment]
    num_lights: int
    num_emitters: int
    num_points: int
    env_light: int  # selection index of the environment, −1 if none
    # emissive triangles, reading the scene's live world-space geometry
    positions: wp.array(dtype=wp.vec3)
    indices: wp.array(dtype=wp.int32)  # 3 per scene triangle
    tri_emitter: wp.array(dtype=wp.int32)  # per scene triangle: emitter index or −1
    emitter_tri: wp.array(dtype=wp.int32)  # per emitter: scene triangle
    emitter_radiance: wp.array(dtype=wp.vec3)  # per emitter: its radiance (a textured one's scale, 1 from files)
    emitter_texture: wp.array(dtype=wp.int32)  # per emitter: its radiance image in ``textures``; −1: none
    emitter_uv: wp.array(dtype=wp.vec2)  # 3 per emitter: the uv of its triangle's corners (a textured emitter's lookup)
    # point lights
    point_position: wp.array(dtype=wp.vec3)
    point_intensity: wp.array(dtype=wp.vec3)
    point_axis: wp.array(dtype=wp.vec3)  # a spot light's unit axis; 0 for an isotropic point light
    point_cone: wp.array(dtype=wp.vec4)  # cos cutoff, cos beam width, cutoff (rad), 1 / (cutoff − beam width)
    point_kind: wp.array(dtype=wp.int32)  # DELTA_POINT (point, spot), DELTA_PROJECTOR, DELTA_DIRECTIONAL
    point_to_local: wp.array(dtype=wp.mat33)  # world → the light's frame (a textured spot, a projector)
    point_texture: wp.array(dtype=wp.int32)  # its image in ``textures``; −1: none
    point_uv: wp.array(dtype=wp.vec2)  # direction → uv: a spot's (tan cutoff, ·), a projector's (tan fov_x/2, tan fov_y/2)
    textures: TextureSet  # the images of textured lights
    scene_center: wp.vec3  # centre of the scene's bounding sphere (a directional light's samples lie outside it)
    # environment
    env_kind: int  # ENV_NONE, ENV_CONSTANT, ENV_ENVMAP
    env_radiance: wp.vec3  # constant environment
    env_scale: float
    env_image: wp.array(dtype=wp.vec3)  # H × (W + 1): Mitsuba's copy of column 0 appended for periodicity
    env_width: int  # W (without the extra column)
    env_height: int  # H
    env_distribution: PiecewiseConstant2D  # over the W × (H − 1) cells between pixel centres
    env_to_world: wp.mat33
    env_to_local: wp.mat33
    scene_radius: float


@wp.struct
class LightSample:
    """One next-event sample: point, direction ref → light, arriving radiance and its density."""

    p: wp.vec3  # point on the light (the direction itself for the environment)
    n: wp.vec3  # light normal at p (−wi for point lights and the environment)
    wi: wp.vec3  # unit, reference point → light
    dist: float  # distance to p (1e30 for the environment)
    radiance: wp.vec3  # L_e toward the reference point (0 if back-facing); I / d² for point lights
    pdf: float  # solid angle, including selection (selection probability alone for delta lights); 0 = invalid
    pdf_area: float  # area density incl. selection (triangles); = pdf otherwise
    delta: int
    is_env: int
    light: int  # selection index, −1 if invalid
    tri: int  # scene triangle of an emissive-triangle sample, −1 otherwise


# ---- small samplers and conversions ---------------------------------------------------


@wp.func
def sample_uniform_triangle(u: wp.vec2) -> wp.vec3:
    """Barycentrics (b₀, b₁, b₂) uniform on a triangle (Mitsuba's square_to_uniform_triangle)."""
    t = wp.sqrt(wp.max(1.0 - u[0], 0.0))
    b1 = 1.0 - t
    b2 = t * u[1]
    return wp.vec3(1.0 - b1 - b2, b1, b2)


@wp.func
def invert_uniform_triangle(b: wp.vec3) -> wp.vec2:
    """The u that :func:`sample_uniform_triangle` maps to barycentrics b."""
    t = 1.0 - b[1]
    u1 = 0.0
    if t > 0.0:
        u1 = b[2] / t
    return wp.vec2(1.0 - t * t, u1)


@wp.func
def sample_uniform_sphere(u: wp.vec2) -> wp.vec3:
    """Uniform direction on the unit sphere (Mitsuba's square_to_uniform_sphere); pdf 1 / 4π."""
    z = 1.0 - 2.0 * u[1]
    r = wp.sqrt(wp.max(1.0 - z * z, 0.0))
    phi = 2.0 * wp.pi * u[0]
    return wp.vec3(r * wp.cos(phi), r * wp.sin(phi), z)


@wp.func
def uniform_sphere_pdf() -> float:
    return _INV_FOUR_PI


@wp.func
def pdf_area_to_solid_angle(pdf_area: float, dist_sq: float, cos_light: float) -> float:
    """p_ω = p_A · d² / |cos θ_y| (PBR 4th ed., Eq. 4.12); 0 at grazing angles instead of ∞."""
    c = wp.abs(cos_light)
    if c <= 0.0:
        return 0.0
    return pdf_area * dist_sq / c


@wp.func
def envmap_direction_to_uv(d: wp.vec3) -> wp.vec2:
    """Mitsuba envmap mapping, local frame (+Y up): u = atan2(d_x, −d_z) / 2π wrapped to [0, 1), v = acos(d_y) / π."""
    u = wp.atan2(d[0], -d[2]) * (0.5 / wp.pi)
    u = u - wp.floor(u)
    v = wp.acos(wp.clamp(d[1], -1.0, 1.0)) / wp.pi
    return wp.vec2(u, v)


@wp.func
def envmap_uv_to_direction(uv: wp.vec2) -> wp.vec3:
    """Inverse of :func:`envmap_direction_to_uv`: (sin φ sin θ, cos θ, −cos φ sin θ), φ = 2π u, θ = π v."""
    theta = uv[1] * wp.pi
    phi = uv[0] * 2.0 * wp.pi
    st = wp.sin(theta)
    return wp.vec3(wp.sin(phi) * st, wp.cos(theta), -wp.cos(phi) * st)


@wp.func
def _env_pixel(ls: LightSet, x: int, y: int) -> wp.vec3:
    return ls.env_image[y * (ls.env_width + 1) + x]


@wp.func
def _envmap_lookup(ls: LightSet, uv: wp.vec2) -> wp.vec3:
    """Mitsuba 3's envmap eval_spectrum: bilinear between pixel centres (u wraps, v clamps), times scale."""
    w = ls.env_width
    h = ls.env_height
    gu = uv[0] - 0.5 / float(w)  # pixel centres sit half a texel right of the grid lines
    gu = gu - wp.floor(gu)
    x = gu * float(w)
    y = wp.clamp(uv[1], 0.0, 1.0) * float(h - 1)
    px = wp.min(int(x), w - 1)
    py = wp.min(int(y), h - 2)
    fx = x - float(px)
    fy = y - float(py)
    a = _env_pixel(ls, px, py) * (1.0 - fx) + _env_pixel(ls, px + 1, py) * fx
    b = _env_pixel(ls, px, py + 1) * (1.0 - fx) + _env_pixel(ls, px + 1, py + 1) * fx
    return (a * (1.0 - fy) + b * fy) * ls.env_scale


@wp.func
def _envmap_uv_pdf_to_solid_angle(pdf_uv: float, d_local: wp.vec3) -> float:
    sin_theta = wp.sqrt(d_local[0] * d_local[0] + d_local[2] * d_local[2])
    if sin_theta <= 0.0:
        return 0.0
    return pdf_uv * _INV_TWO_PI_SQ / sin_theta


@wp.func
def _envmap_pdf_local(ls: LightSet, d_local: wp.vec3) -> float:
    uv = envmap_direction_to_uv(d_local)
    g = wp.vec2(uv[0] - 0.5 / float(ls.env_width), uv[1])
    g = wp.vec2(g[0] - wp.floor(g[0]), wp.min(g[1], 0.99999994))
    return _envmap_uv_pdf_to_solid_angle(piecewise_constant_2d_pdf(ls.env_distribution, g), d_local)


# ---- queries ----------------------------------------------------------------------------


@wp.func
def _triangle_vertex(ls: LightSet, tri: int, k: int) -> wp.vec3:
    return ls.positions[ls.indices[3 * tri + k]]


@wp.func
def _triangle_area(ls: LightSet, tri: int) -> float:
    p0 = _triangle_vertex(ls, tri, 0)
    return 0.5 * wp.length(wp.cross(_triangle_vertex(ls, tri, 1) - p0, _triangle_vertex(ls, tri, 2) - p0))


@wp.func
def triangle_barycentrics(p0: wp.vec3, p1: wp.vec3, p2: wp.vec3, p: wp.vec3) -> wp.vec3:
    """Barycentrics (b₀, b₁, b₂) of p (on the triangle's plane) with p = b₀ p₀ + b₁ p₁ + b₂ p₂."""
    v0 = p1 - p0
    v1 = p2 - p0
    v2 = p - p0
    d00 = wp.dot(v0, v0)
    d01 = wp.dot(v0, v1)
    d11 = wp.dot(v1, v1)
    d20 = wp.dot(v2, v0)
    d21 = wp.dot(v2, v1)
    denom = d00 * d11 - d01 * d01
    if denom <= 0.0:
        return wp.vec3(1.0, 0.0, 0.0)
    b1 = (d11 * d20 - d01 * d21) / denom
    b2 = (d00 * d21 - d01 * d20) / denom
    return wp.vec3(1.0 - b1 - b2, b1, b2)


@wp.func
def light_pdf_emitter(ls: LightSet, tri: int, ref_p: wp.vec3, light_p: wp.vec3, light_n: wp.vec3) -> float:
    """Solid-angle density (incl. selection) with which :func:`sample_light` picks light_p on ``tri`` from ref_p."""
    if tri < 0:
        return 0.0
    e = ls.tri_emitter[tri]
    if e < 0:
        return 0.0
    area = _triangle_area(ls, tri)
    if area <= 0.0:
        return 0.0
    d = light_p - ref_p
    dist_sq = wp.dot(d, d)
    if dist_sq <= 0.0:
        return 0.0
    cos_light = wp.dot(light_n, d) / (wp.length(light_n) * wp.sqrt(dist_sq))
    return pdf_area_to_solid_angle(alias_pmf(ls.selection, e) / area, dist_sq, cos_light)


@wp.func
def _invalid_sample() -> LightSample:
    s = LightSample()
    s.dist = 0.0
    s.pdf = 0.0
    s.pdf_area = 0.0
    s.delta = 0
    s.is_env = 0
    s.light = -1
    s.tri = -1
    return s


@wp.struct
class DeltaArrival:
    """What a delta light delivers at a reference point: where from, and the radiance it brings."""

    p: wp.vec3  # the light's position (a point beyond the scene's bounding sphere for a directional light)
    wi: wp.vec3  # unit, reference point → light
    dist: float  # 0: no such direction (the reference point is on the light)
    radiance: wp.vec3  # I(−wi) / d² (point, spot, projector) or the irradiance E (directional)


@wp.func
def _spot_falloff(ls: LightSet, k: int, w: wp.vec3) -> float:
    """Mitsuba's spot falloff s(w) toward unit w (from the light): 1 in the beam, linear in angle to 0 at the cutoff."""
    cone = ls.point_cone[k]
    cos_theta = wp.dot(ls.point_axis[k], w)
    if cos_theta <= cone[0]:
        return 0.0
    if cos_theta >= cone[1]:
        return 1.0
    return (cone[2] - wp.acos(wp.clamp(cos_theta, -1.0, 1.0))) * cone[3]


@wp.func
def delta_light_arrival(ls: LightSet, k: int, ref_p: wp.vec3) -> DeltaArrival:
    """Delta light ``k`` (0 ≤ k < num_points) seen from ``ref_p``: the one formula every renderer evaluates
    such a light with, when sampling it and when re-evaluating a stored sample at another point."""
    a = DeltaArrival()
    a.dist = 0.0
    kind = ls.point_kind[k]
    if kind == DELTA_DIRECTIONAL:
        # directional.cpp: a point 2·max(R, ‖x − c‖) back along the beam, beyond every surface
        d = ls.point_axis[k]
        dist = 2.0 * wp.max(ls.scene_radius, wp.length(ref_p - ls.scene_center))
        a.wi = -d
        a.p = ref_p - d * dist
        a.dist = dist
        a.radiance = ls.point_intensity[k]
        return a
    p = ls.point_position[k]
    v = p - ref_p
    dist_sq = wp.dot(v, v)
    if dist_sq <= 0.0:
        return a
    dist = wp.sqrt(dist_sq)
    a.p = p
    a.wi = v / dist
    a.dist = dist
    w = -a.wi  # light → reference point
    intensity = ls.point_intensity[k]
    tex = ls.point_texture[k]
    if kind == DELTA_PROJECTOR:
        # projector.cpp: the film point uv of w (a perspective camera's mapping), E(uv) π·scale / (z² cos θ)
        q = ls.point_to_local[k] * w
        if q[2] <= 0.0:
            return a
        t = ls.point_uv[k]
        uv = wp.vec2(0.5 * (1.0 - q[0] / (q[2] * t[0])), 0.5 * (1.0 - q[1] / (q[2] * t[1])))
        if uv[0] < 0.0 or uv[0] > 1.0 or uv[1] < 0.0 or uv[1] > 1.0:
            return a
        cos_theta = q[2]  # |q| = 1: a rigid frame
        z = dist * cos_theta  # the reference point's depth in the projector's frame
        a.radiance = wp.cw_mul(intensity, texture_lookup(ls.textures, tex, uv)) / (z * z * cos_theta)
        return a
    if wp.dot(ls.point_axis[k], ls.point_axis[k]) > 0.0:  # a spot light
        intensity = intensity * _spot_falloff(ls, k, w)
        if tex >= 0 and wp.length_sq(intensity) > 0.0:
            # spot.cpp: uv = ½ + ½ (x, y) / (z tan cutoff) in the spot's frame
            q = ls.point_to_local[k] * w
            f = 0.5 / (q[2] * ls.point_uv[k][0])
            intensity = wp.cw_mul(intensity, texture_lookup(ls.textures, tex, wp.vec2(0.5 + q[0] * f, 0.5 + q[1] * f)))
    a.radiance = intensity / dist_sq
    return a


class LightFuncs(NamedTuple):
    """Light sampling and emission compiled for one scene's lights (:func:`make_lights`)."""

    emitter_radiance_at: Any
    emitter_radiance: Any
    environment_eval: Any
    environment_pdf: Any
    sample_given_light: Any
    sample_light: Any
    delta_light_arrival: Any


@wp.func
def _no_delta_arrival(ls: LightSet, k: int, ref_p: wp.vec3) -> DeltaArrival:
    """:func:`delta_light_arrival` of a scene without delta lights: never asked, no arrival."""
    a = DeltaArrival()
    a.dist = 0.0
    return a


@functools.cache
def _make_lights(delta: bool, envmap: bool, textured: bool) -> LightFuncs:
    # each kind of light's code only where the scene has it: every kernel inlines light sampling and emission at each
    # of its call sites (the textured lookups of a projector, a spot and an emitter, the environment map's 2D
    # distribution), and a scene of plain area lights would compile them for nothing

    @wp.func
    def emitter_radiance_at(ls: LightSet, e: int, b: wp.vec3) -> wp.vec3:
        """Radiance of emitter ``e`` at barycentrics b of its triangle: its colour, times its image at the point's uv."""
        radiance = ls.emitter_radiance[e]
        if wp.static(textured):
            tex = ls.emitter_texture[e]
            if tex >= 0:
                uv = ls.emitter_uv[3 * e] * b[0] + ls.emitter_uv[3 * e + 1] * b[1] + ls.emitter_uv[3 * e + 2] * b[2]
                radiance = wp.cw_mul(radiance, texture_lookup(ls.textures, tex, uv))
        return radiance

    @wp.func
    def emitter_radiance(ls: LightSet, tri: int, p: wp.vec3, n_geo: wp.vec3, w: wp.vec3) -> wp.vec3:
        """Radiance that scene triangle ``tri`` emits at its point ``p`` toward w (pointing away from it): one-sided,
        front = n_geo's side; a textured emitter's image is looked up at p's uv."""
        if tri < 0:
            return wp.vec3(0.0)
        e = ls.tri_emitter[tri]
        if e < 0 or wp.dot(n_geo, w) <= 0.0:
            return wp.vec3(0.0)
        if wp.static(textured):
            if ls.emitter_texture[e] >= 0:
                b = triangle_barycentrics(_triangle_vertex(ls, tri, 0), _triangle_vertex(ls, tri, 1), _triangle_vertex(ls, tri, 2), p)
                return emitter_radiance_at(ls, e, b)
        return ls.emitter_radiance[e]

    @wp.func
    def environment_eval(ls: LightSet, world_dir: wp.vec3) -> wp.vec3:
        """Radiance arriving from the environment along ``world_dir`` (scene → environment)."""
        if ls.env_kind == ENV_CONSTANT:
            return ls.env_radiance
        if wp.static(envmap):
            if ls.env_kind == ENV_ENVMAP:
                return _envmap_lookup(ls, envmap_direction_to_uv(wp.normalize(ls.env_to_local * world_dir)))
        return wp.vec3(0.0)

    @wp.func
    def environment_pdf(ls: LightSet, world_dir: wp.vec3) -> float:
        """Solid-angle density (incl. selection) with which :func:`sample_light` picks ``world_dir`` on the environment."""
        if ls.env_light < 0:
            return 0.0
        pmf = alias_pmf(ls.selection, ls.env_light)
        if ls.env_kind == ENV_CONSTANT:
            return pmf * uniform_sphere_pdf()
        if wp.static(envmap):
            if ls.env_kind == ENV_ENVMAP:
                return pmf * _envmap_pdf_local(ls, wp.normalize(ls.env_to_local * world_dir))
        return 0.0

    @wp.func
    def sample_given_light(ls: LightSet, light: int, pmf: float, ref_p: wp.vec3, u: wp.vec2) -> LightSample:
        """A point/direction on light ``light`` (a selection index) with u; the densities include ``pmf``, the
        probability the light was picked with (1: the density on this light alone)."""
        s = _invalid_sample()
        if light < 0 or light >= ls.num_lights or pmf <= 0.0:
            return s
        s.light = light
        if light < ls.num_emitters:
            # ---- emissive triangle: uniform in area, then area → solid angle ----
            tri = ls.emitter_tri[light]
            p0 = _triangle_vertex(ls, tri, 0)
            p1 = _triangle_vertex(ls, tri, 1)
            p2 = _triangle_vertex(ls, tri, 2)
            b = sample_uniform_triangle(u)
            p = p0 * b[0] + p1 * b[1] + p2 * b[2]
            c = wp.cross(p1 - p0, p2 - p0)
            twice_area = wp.length(c)
            d = p - ref_p
            dist_sq = wp.dot(d, d)
            if twice_area <= 0.0 or dist_sq <= 0.0:
                s.light = -1
                return s
            n = c / twice_area
            dist = wp.sqrt(dist_sq)
            wi = d / dist
            cos_light = -wp.dot(n, wi)
            s.p = p
            s.n = n
            s.wi = wi
            s.dist = dist
            s.tri = tri
            s.pdf_area = pmf / (0.5 * twice_area)
            s.pdf = pdf_area_to_solid_angle(s.pdf_area, dist_sq, cos_light)
            if cos_light > 0.0:
                s.radiance = emitter_radiance_at(ls, light, b)
            if s.pdf <= 0.0:
                s.light = -1
            return s
        if wp.static(delta):
            if light < ls.num_emitters + ls.num_points:
                # ---- delta lights: point, spot, projector (a delta in position), directional (in direction) ----
                a = delta_light_arrival(ls, light - ls.num_emitters, ref_p)
                if a.dist <= 0.0:
                    s.light = -1
                    return s
                s.p = a.p
                s.wi = a.wi
                s.n = -a.wi
                s.dist = a.dist
                s.radiance = a.radiance
                s.pdf = pmf
                s.pdf_area = pmf
                s.delta = 1
                return s
        # ---- environment ----
        s.is_env = 1
        s.dist = _ENV_DIST
        wi = wp.vec3(0.0)
        if ls.env_kind == ENV_CONSTANT:
            wi = sample_uniform_sphere(u)
            s.radiance = ls.env_radiance
            s.pdf = pmf * uniform_sphere_pdf()
        if wp.static(envmap):
            if ls.env_kind == ENV_ENVMAP:
                g = sample_piecewise_constant_2d(ls.env_distribution, u)
                gu = g.uv[0] + 0.5 / float(ls.env_width)  # back from cell grid to Mitsuba's u (half-texel shift)
                uv = wp.vec2(gu - wp.floor(gu), g.uv[1])
                d_local = envmap_uv_to_direction(uv)
                wi = ls.env_to_world * d_local
                s.radiance = _envmap_lookup(ls, uv)
                s.pdf = pmf * _envmap_uv_pdf_to_solid_angle(g.pdf, d_local)
        s.wi = wi
        s.p = wi
        s.n = -wi
        s.pdf_area = s.pdf
        if s.pdf <= 0.0:
            s.light = -1
            s.radiance = wp.vec3(0.0)
        return s

    @wp.func
    def sample_light(ls: LightSet, ref_p: wp.vec3, u_select: float, u: wp.vec2) -> LightSample:
        """Pick a light ∝ power with u_select, then a point/direction on it with u (see the module docstring)."""
        light = sample_alias(ls.selection, u_select)
        if light < 0:
            return _invalid_sample()
        return sample_given_light(ls, light, alias_pmf(ls.selection, light), ref_p, u)

    return LightFuncs(emitter_radiance_at, emitter_radiance, environment_eval, environment_pdf, sample_given_light, sample_light,
                      delta_light_arrival if delta else _no_delta_arrival)


def make_lights(kinds: Iterable[int]) -> LightFuncs:
    """Light sampling and emission for the kinds ``kinds`` (cached): the delta lights' branch only with
    ``SCENE_DELTA_LIGHTS``, the environment map's with ``SCENE_ENVMAP``, an emitter's radiance image with
    ``SCENE_EMITTER_TEXTURES`` (:class:`~grisx.scene.scene.SceneFeatures` adds them). A renderer's kernels take
    them from here, as their BSDF dispatch from ``make_bsdf``."""
    k = frozenset(int(x) for x in kinds)
    return _make_lights(SCENE_DELTA_LIGHTS in k, SCENE_ENVMAP in k, SCENE_EMITTER_TEXTURES in k)


#: every kind of light compiled in (for code outside a kinds-specialised factory)
_EVERY_LIGHT = make_lights(SCENE_KINDS)
_emitter_radiance_at = _EVERY_LIGHT.emitter_radiance_at
emitter_radiance = _EVERY_LIGHT.emitter_radiance
environment_eval = _EVERY_LIGHT.environment_eval
environment_pdf = _EVERY_LIGHT.environment_pdf
sample_given_light = _EVERY_LIGHT.sample_given_light
sample_light = _EVERY_LIGHT.sample_light



# ---- building -----------------------------------------------------------------------------


def _envmap_cell_weights(img: np.ndarray) -> np.ndarray:
    """(H − 1) × W cell weights: mean corner luminance of the bilinear radiance × band mean of sin θ."""
    h, w = img.shape[:2]
    lum = _lum(img)
    lum = np.concatenate([lum, lum[:, :1]], axis=1)  # Mitsuba's periodic column
    corners = 0.25 * (lum[:-1, :-1] + lum[:-1, 1:] + lum[1:, :-1] + lum[1:, 1:])
    theta = np.arange(h) * (math.pi / (h - 1))
    band_sin = (np.cos(theta[:-1]) - np.cos(theta[1:])) / (math.pi / (h - 1))
    return corners * band_sin[:, None]


def _as_vec3_array(value: Any, device: str | None, what: str) -> wp.array:
    if isinstance(value, wp.array):
        if value.dtype != wp.vec3:
            raise InvalidParameterError(f"{what} must be a Warp array of vec3, got dtype {value.dtype}")
        return value
    a = np.asarray(value, dtype=np.float64)
    if a.size == 0:
        a = a.reshape(0, 3)
    if a.ndim != 2 or a.shape[1] != 3:
        raise InvalidParameterError(f"{what} must have shape (n, 3), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise InvalidValueError(f"{what} contains NaN or Inf")
    return wp.array(a.astype(np.float32), dtype=wp.vec3, device=device)


def _as_index_array(value: Any, device: str | None) -> wp.array:
    if isinstance(value, wp.array):
        if value.dtype != wp.int32:
            raise InvalidParameterError(f"indices must be a Warp array of int32, got dtype {value.dtype}")
        return value
    a = np.asarray(value)
    if a.size == 0:
        a = np.zeros(0, dtype=np.int32)
    if a.dtype.kind not in "iu" or not (a.ndim == 1 and a.size % 3 == 0 or a.ndim == 2 and a.shape[1] == 3):
        raise InvalidParameterError(f"indices must be integers of shape (m, 3) or (3m,), got {a.dtype} {a.shape}")
    return wp.array(a.astype(np.int32).ravel(), dtype=wp.int32, device=device)


#: the share of light selection that is uniform over lights (the rest ∝ power); see "Light selection" above
SELECTION_UNIFORM = 0.75


def selection_weights(power: np.ndarray, groups: np.ndarray) -> np.ndarray:
    """Selection probabilities: a quarter ∝ power, three quarters uniform over lights (a light's share split ∝
    power among its parts) — see "Light selection" in the module docstring. ``groups[k]`` is part k's light."""
    power = np.asarray(power, dtype=np.float64)
    total = power.sum()
    if not total > 0:
        return power
    group_power = np.bincount(groups, weights=power)
    lit = group_power > 0
    share = np.where(lit[groups], power / np.where(lit[groups], group_power[groups], 1.0), 0.0) / np.count_nonzero(lit)
    return (1.0 - SELECTION_UNIFORM) * power / total + SELECTION_UNIFORM * share


@wp.kernel
def _emitter_texture_mean_kernel(ls: LightSet, means: wp.array(dtype=float)):
    """Mean luminance of each textured emitter's image over its triangle, at 4×4 stratified points."""
    e = wp.tid()
    if ls.emitter_texture[e] < 0:
        return
    acc = float(0.0)
    for i in range(4):
        for j in range(4):
            b = sample_uniform_triangle(wp.vec2((float(i) + 0.5) * 0.25, (float(j) + 0.5) * 0.25))
            acc += luminance(_emitter_radiance_at(ls, e, b))
    means[e] = acc / 16.0 / wp.max(luminance(ls.emitter_radiance[e]), 1.0e-30)


def build_light_set(
    device: str | None,
    positions: Any,
    indices: Any,
    emitter_tris: Any = (),
    emitter_radiance: Any = (),
    point_lights: Any = (),
    environment: ConstantEnvironment | EnvMap | None = None,
    scene_radius: float = 1.0,
    num_primitives: int | None = None,
    scene_center: Any = None,
    emitter_textures: Any = (),
    emitter_texture: Any = None,
    emitter_uvs: Any = None,
    emitter_group: Any = None,
) -> LightSet:
    """Pack a scene's lights into a :class:`LightSet`.

    ``positions`` (n, 3) world-space vertices and ``indices`` ((m, 3) or flat
    3m) are numpy arrays or the scene's own Warp arrays (``vec3`` / ``int32``;
    then referenced, not copied, so in-place rigid motion is seen).
    ``emitter_tris`` lists the emissive scene triangles and
    ``emitter_radiance`` their RGB radiance ((k, 3), or one triple for all).
    ``point_lights`` is a sequence of delta lights — :class:`PointLight`,
    :class:`Projector`, :class:`DirectionalLight`; ``environment`` a
    :class:`ConstantEnvironment`, an :class:`EnvMap` or None; ``scene_radius``
    and ``scene_center`` the scene's bounding sphere (the power of the
    environment and of directional lights, where a directional light's
    samples lie; centre (0, 0, 0) if not given);
    ``num_primitives`` the number of primitive ids the scene hands out (its triangles, then its analytic
    shapes, which never emit: :mod:`grisx.scene.analytic`), by default the triangles.
    Textured emitters (Mitsuba's
    ``area`` with a bitmap ``radiance``): ``emitter_textures`` lists images
    ((H, W, 3) or :class:`~grisx.scene.texture.Bitmap`), ``emitter_texture``
    gives each emitter's image index (−1: none) and ``emitter_uvs`` (k, 3, 2)
    its corners' uv; the radiance is ``emitter_radiance`` × the image there.
    ``emitter_group`` names each emitter's light (its shape; default: one
    light of all of them) for :func:`selection_weights`.
    """
    pos = _as_vec3_array(positions, device, "positions")
    idx = _as_index_array(indices, device)
    device = pos.device
    pos_np = pos.numpy().astype(np.float64)
    idx_np = idx.numpy().astype(np.int64).reshape(-1, 3)
    num_tris = idx_np.shape[0]
    if idx_np.size and (idx_np.min() < 0 or idx_np.max() >= pos_np.shape[0]):
        raise InvalidParameterError(f"indices must lie in [0, {pos_np.shape[0]}), got range [{idx_np.min()}, {idx_np.max()}]")

    # ---- emissive triangles ----
    tris = np.asarray(emitter_tris if emitter_tris is not None else (), dtype=np.float64).ravel()
    if tris.size and (np.any(tris != np.round(tris)) or tris.min() < 0 or tris.max() >= num_tris):
        raise InvalidParameterError(f"emitter_tris must be triangle indices in [0, {num_tris})")
    tris = tris.astype(np.int64)
    if np.unique(tris).size != tris.size:
        raise InvalidParameterError("emitter_tris lists a triangle twice")
    rad = np.asarray(emitter_radiance if emitter_radiance is not None else (), dtype=np.float64)
    if tris.size:
        if rad.shape == (3,) or rad.ndim == 0:
            rad = np.broadcast_to(_rgb(rad, "emitter_radiance"), (tris.size, 3))
        if rad.shape != (tris.size, 3):
            raise InvalidParameterError(f"emitter_radiance must have shape ({tris.size}, 3) or (3,), got {rad.shape}")
        if not np.all(np.isfinite(rad)):
            raise InvalidValueError("emitter_radiance contains NaN or Inf")
        if np.any(rad < 0):
            raise InvalidValueError(f"emitter_radiance must be non-negative (min {rad.min():g})")
        p = pos_np[idx_np[tris]]
        areas = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
        emitter_power = math.pi * areas * _lum(rad)  # one-sided Lambertian: Φ = π A L
    else:
        rad = np.zeros((0, 3))
        emitter_power = np.zeros(0)
    tri_emitter = np.full(max(num_tris if num_primitives is None else num_primitives, 1), -1, dtype=np.int32)
    tri_emitter[tris] = np.arange(tris.size, dtype=np.int32)
    light_images: list[np.ndarray | Bitmap] = [_light_image(t, f"emitter_textures[{i}]") for i, t in enumerate(emitter_textures or ())]
    e_tex = np.full(tris.size, -1, dtype=np.int32) if emitter_texture is None else np.asarray(emitter_texture).reshape(-1)
    if e_tex.shape != (tris.size,) or e_tex.dtype.kind not in "iu" or (e_tex.size and (e_tex.min() < -1 or e_tex.max() >= len(light_images))):
        raise InvalidParameterError(f"emitter_texture must give each of the {tris.size} emitters an index into emitter_textures or -1")
    e_uv = np.tile(np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]), (tris.size, 1, 1)) if emitter_uvs is None else np.asarray(emitter_uvs, dtype=np.float64)
    if e_uv.shape != (tris.size, 3, 2) or not np.all(np.isfinite(e_uv)):
        raise InvalidParameterError(f"emitter_uvs must be finite, of shape ({tris.size}, 3, 2), got {e_uv.shape}")

    # ---- delta lights: point, spot, projector, directional ----
    points = list(point_lights or ())
    n_points = len(points)
    pp = np.zeros((n_points, 3))
    pi_ = np.zeros((n_points, 3))
    axes = np.zeros((n_points, 3))
    cones = np.zeros((n_points, 4))
    kinds = np.zeros(n_points, dtype=np.int32)
    to_local = np.tile(np.eye(3), (n_points, 1, 1))
    tex_of = np.full(n_points, -1, dtype=np.int32)
    uv_of = np.zeros((n_points, 2))
    point_power = np.zeros(n_points)
    radius = float(scene_radius)
    for k, light in enumerate(points):
        if isinstance(light, DirectionalLight):
            d = np.asarray(light.direction, dtype=np.float64)
            if d.shape != (3,) or not np.all(np.isfinite(d)) or np.linalg.norm(d) == 0:
                raise InvalidValueError(f"point_lights[{k}].direction must be 3 finite numbers, not all 0, got {d.tolist()}")
            if not math.isfinite(radius) or radius <= 0:
                raise InvalidParameterError(f"scene_radius must be positive and finite with a directional light, got {scene_radius}")
            kinds[k] = int(DELTA_DIRECTIONAL)
            axes[k] = d / np.linalg.norm(d)
            pi_[k] = _rgb(light.irradiance, f"point_lights[{k}].irradiance")
            point_power[k] = math.pi * radius * radius * float(_lum(pi_[k]))  # E through the bounding sphere's disk
            continue
        if isinstance(light, Projector):
            frame = rigid_frame(light.to_world, f"point_lights[{k}].to_world")
            image = _light_image(light.irradiance, f"point_lights[{k}].irradiance")
            scale = float(light.scale)
            if not math.isfinite(scale) or scale < 0:
                raise InvalidValueError(f"point_lights[{k}].scale must be finite and non-negative, got {light.scale}")
            from grisx.scene.camera import tan_half_fov

            h, w = _pixels(image).shape[:2]
            tx, ty = tan_half_fov(float(light.fov), light.fov_axis, w, h)
            kinds[k] = int(DELTA_PROJECTOR)
            pp[k] = frame[:3, 3]
            axes[k] = frame[:3, 2]
            to_local[k] = frame[:3, :3].T
            pi_[k] = math.pi * scale
            uv_of[k] = (tx, ty)
            tex_of[k] = len(light_images)
            light_images.append(image)
            # ∫ I dω = π·scale ∫ E dA over the image plane at z = 1 (dω = cos³θ dA), of area 4 t_x t_y
            point_power[k] = math.pi * scale * 4.0 * tx * ty * float(_lum(_pixels(image)).mean())
            continue
        if not isinstance(light, PointLight):
            raise InvalidParameterError(f"point_lights[{k}] must be a PointLight, Projector or DirectionalLight, got {type(light).__name__}")
        position = np.asarray(light.position, dtype=np.float64)
        if position.shape != (3,) or not np.all(np.isfinite(position)):
            raise InvalidValueError(f"point_lights[{k}].position must be 3 finite numbers, got {position.tolist()}")
        pp[k] = position
        pi_[k] = _rgb(light.intensity, f"point_lights[{k}].intensity")
        solid_angle = 4.0 * math.pi
        if light.direction is not None:
            axis = np.asarray(light.direction, dtype=np.float64)
            cutoff = float(light.cutoff_angle)
            beam = 0.75 * cutoff if light.beam_width is None else float(light.beam_width)
            if axis.shape != (3,) or not np.all(np.isfinite(axis)) or np.linalg.norm(axis) == 0:
                raise InvalidValueError(f"point_lights[{k}].direction must be 3 finite numbers, not all 0, got {axis.tolist()}")
            if not (0.0 < cutoff <= 90.0) or not (0.0 <= beam <= cutoff):
                raise InvalidParameterError(f"point_lights[{k}]: need 0 < cutoff_angle <= 90 and 0 <= beam_width <= cutoff_angle, got {cutoff}, {beam}")
            axes[k] = axis / np.linalg.norm(axis)
            c, b = math.radians(cutoff), math.radians(beam)
            cones[k] = (math.cos(c), math.cos(b), c, 1.0 / (c - b) if c > b else 0.0)
            solid_angle = 2.0 * math.pi * (1.0 - math.cos(c))  # an upper bound of its power / lum(I)
            if light.texture is not None:
                if light.to_world is None:
                    raise InvalidParameterError(f"point_lights[{k}]: a spot's texture needs its to_world frame")
                frame = rigid_frame(light.to_world, f"point_lights[{k}].to_world")
                if not np.allclose(frame[:3, 2], axes[k], atol=1e-5):
                    raise InvalidParameterError(f"point_lights[{k}]: direction must be the +z axis of to_world")
                image = _light_image(light.texture, f"point_lights[{k}].texture")
                to_local[k] = frame[:3, :3].T
                uv_of[k] = (math.tan(c), 0.0)
                tex_of[k] = len(light_images)
                light_images.append(image)
                solid_angle *= float(_lum(_pixels(image)).mean())
        elif light.texture is not None:
            raise InvalidParameterError(f"point_lights[{k}]: a texture needs a spot light (a direction)")
        point_power[k] = solid_angle * float(_lum(pi_[k]))

    # ---- environment ----
    ls = LightSet()
    ls.env_kind = 0
    ls.env_radiance = wp.vec3(0.0)
    ls.env_scale = 1.0
    ls.env_to_world = wp.mat33(np.eye(3, dtype=np.float32))
    ls.env_to_local = wp.mat33(np.eye(3, dtype=np.float32))
    image = np.zeros((3, 2, 3))
    weights = np.ones((1, 1))  # sampling cells of the envmap (a dummy without one)
    env_power: list[float] = []
    if environment is not None:
        r = float(scene_radius)
        if not math.isfinite(r) or r <= 0:
            raise InvalidParameterError(f"scene_radius must be positive and finite with an environment light, got {scene_radius}")
        if isinstance(environment, ConstantEnvironment):
            L = _rgb(environment.radiance, "ConstantEnvironment.radiance")
            ls.env_kind = 1
            ls.env_radiance = wp.vec3(*L.astype(np.float32))
            env_power = [math.pi * r * r * 4.0 * math.pi * float(_lum(L))]
        elif isinstance(environment, EnvMap):
            scale = float(environment.scale)
            if not math.isfinite(scale) or scale < 0:
                raise InvalidValueError(f"EnvMap.scale must be finite and non-negative, got {environment.scale}")
            image = load_envmap_image(environment.image)
            rot = _rotation(environment.to_world)
            ls.env_kind = 2
            ls.env_scale = scale
            ls.env_to_world = wp.mat33(rot.astype(np.float32))
            ls.env_to_local = wp.mat33(rot.T.astype(np.float32))
            weights = _envmap_cell_weights(image)
            # ∫ lum(L) dω = 2π² ∫∫ lum · sin θ du dv over the unit square of cells
            env_power = [math.pi * r * r * scale * 2.0 * math.pi**2 * float(weights.mean())]
        else:
            raise InvalidParameterError(f"environment must be ConstantEnvironment, EnvMap or None, got {type(environment).__name__}")
    h, w = image.shape[:2]
    padded = np.concatenate([image, image[:, :1]], axis=1)
    ls.env_image = wp.array(padded.reshape(-1, 3).astype(np.float32), dtype=wp.vec3, device=device)
    ls.env_width = int(w)
    ls.env_height = int(h)
    ls.env_distribution = build_piecewise_constant_2d(weights, device)
    ls.scene_radius = float(scene_radius)

    ls.positions = pos
    ls.indices = idx
    ls.tri_emitter = wp.array(tri_emitter, dtype=wp.int32, device=device)
    ls.emitter_tri = wp.array(tris.astype(np.int32) if tris.size else np.zeros(1, np.int32), dtype=wp.int32, device=device)
    ls.emitter_radiance = wp.array(rad.astype(np.float32) if tris.size else np.zeros((1, 3), np.float32), dtype=wp.vec3, device=device)
    ls.point_position = wp.array(pp.astype(np.float32) if len(points) else np.zeros((1, 3), np.float32), dtype=wp.vec3, device=device)
    ls.point_intensity = wp.array(pi_.astype(np.float32) if len(points) else np.zeros((1, 3), np.float32), dtype=wp.vec3, device=device)
    ls.point_axis = wp.array(axes.astype(np.float32) if len(points) else np.zeros((1, 3), np.float32), dtype=wp.vec3, device=device)
    ls.point_cone = wp.array(cones.astype(np.float32) if len(points) else np.zeros((1, 4), np.float32), dtype=wp.vec4, device=device)
    ls.point_kind = wp.array(kinds if n_points else np.zeros(1, np.int32), dtype=wp.int32, device=device)
    ls.point_to_local = wp.array(to_local.astype(np.float32) if n_points else np.eye(3, dtype=np.float32)[None], dtype=wp.mat33, device=device)
    ls.point_texture = wp.array(tex_of if n_points else np.full(1, -1, np.int32), dtype=wp.int32, device=device)
    ls.point_uv = wp.array(uv_of.astype(np.float32) if n_points else np.zeros((1, 2), np.float32), dtype=wp.vec2, device=device)
    ls.textures = pack_textures(light_images, device)
    ls.emitter_texture = wp.array(e_tex.astype(np.int32) if tris.size else np.full(1, -1, np.int32), dtype=wp.int32, device=device)
    ls.emitter_uv = wp.array(e_uv.reshape(-1, 2).astype(np.float32) if tris.size else np.zeros((3, 2), np.float32), dtype=wp.vec2, device=device)
    if np.any(e_tex >= 0):
        # a textured triangle's power: π A lum(L) × its image's mean luminance over the triangle (16 points), floored
        # at 1e-3 of the image's mean so that no triangle whose image may be bright somewhere is never picked
        means = wp.zeros(tris.size, dtype=float, device=device)
        ls.selection = build_alias_table(np.ones(1), device)  # every array of the struct set before it goes to a kernel
        wp.launch(_emitter_texture_mean_kernel, tris.size, inputs=[ls, means], device=device)
        floor = np.array([1e-3 * float(_lum(_pixels(light_images[t])).mean()) if t >= 0 else 0.0 for t in e_tex])
        emitter_power = emitter_power * np.where(e_tex >= 0, np.maximum(means.numpy().astype(np.float64), floor), 1.0)

    # ---- selection over all lights ----
    power = np.concatenate([emitter_power, point_power, np.asarray(env_power, dtype=np.float64)])
    groups = np.zeros(tris.size, dtype=np.int64) if emitter_group is None else np.asarray(emitter_group).reshape(-1)
    if groups.shape != (tris.size,) or groups.dtype.kind not in "iu":
        raise InvalidParameterError(f"emitter_group must give each of the {tris.size} emitters an integer group, got {groups.shape}")
    _, groups = np.unique(groups, return_inverse=True)
    n_groups = int(groups.max()) + 1 if tris.size else 0
    groups = np.concatenate([groups, n_groups + np.arange(len(points) + len(env_power))])  # each other light on its own
    ls.num_emitters = int(tris.size)
    ls.num_points = len(points)
    ls.env_light = int(tris.size + len(points)) if env_power else -1
    ls.num_lights = int(power.size)
    ls.selection = build_alias_table(selection_weights(power, groups) if power.size else np.zeros(1), device)
    if not power.size:
        ls.selection.size = 0
    center = np.zeros(3) if scene_center is None else np.asarray(scene_center, dtype=np.float64)
    if center.shape != (3,) or not np.all(np.isfinite(center)):
        raise InvalidValueError(f"scene_center must be 3 finite numbers, got {center.tolist()}")
    ls.scene_center = wp.vec3(*center.astype(np.float32))
    return ls
