"""Mitsuba 3 scene files (XML): a documented subset, read into a :class:`~grisx.scene.scene.Scene`.

Research scenes are shared as Mitsuba XML. :func:`load_mitsuba` reads the
subset below with **Mitsuba 3's meaning** for every element (geometry of the
analytic shapes, ``fov_axis``, one-sided area emitters, radiance units,
``max_depth``), so the same file gives the same picture in Mitsuba and in
grisx. Anything outside the subset — an element, a plugin type, a parameter,
an attribute — raises :class:`~grisx.errors.SceneFileError` whose message
starts with ``file:line:`` and names the element and the attribute or
parameter; so does malformed XML. Nothing is silently ignored, except the
few output-format options listed as "accepted, ignored".

Supported subset
----------------
Document
    ``<scene version="X.Y.Z">`` (required; versions < 2 — Mitsuba 0.x files —
    have their camelCase parameter names converted to snake_case, as Mitsuba 3
    does). ``<default name value>`` (top level of a file) and ``$name`` in any
    attribute value: the ``params`` argument overrides defaults (the first
    default of a name wins; a default may follow its use); an unknown
    ``$name`` is an error, and so is a ``params`` name the files never use.
    ``<path value>`` (top level): a folder searched for file names before
    the ones given earlier and the scene's folder (Mitsuba's file resolver;
    relative to the file that holds it). ``<include filename>`` anywhere: the
    file (found next to the including file, else through the resolver) is
    read in place — a ``<scene>``'s children, or its one object; its own
    ``<path>``, ``<default>`` and version apply; errors in it name it.
    ``id`` on any object and ``<ref id [name]>`` to BSDFs, textures, and to
    top-level ``film``/``sampler``/``rfilter`` objects from a sensor (in any
    order; ids are unique).
Values
    ``float``, ``integer``, ``boolean`` (true/false), ``string``,
    ``point``/``vector`` (``x, y, z`` attributes or ``value="x, y, z"``),
    Mitsuba 0.x's ``srgb`` (sRGB-encoded: 1 or 3 numbers, or ``#rrggbb``),
    ``rgb`` (``value``: 3 numbers, or 1 broadcast), ``spectrum`` (a constant
    ``value``, ``wavelength:value`` pairs, an ``.spd`` ``filename``, or
    ``type="blackbody"`` with ``temperature`` [K], ``wavelength_min``,
    ``wavelength_max`` in emitters), reduced to RGB as Mitsuba 3's RGB variants
    do — a flat emission spectrum is not white under sRGB's D65 white point
    (:mod:`grisx.scene.spectrum`). Numbers may be separated by commas and/or spaces.
    Where a colour is expected, ``rgb``, ``spectrum`` and ``float`` are accepted.
Transforms ``<transform name="to_world">``
    ``translate`` (x/y/z or value), ``rotate`` (axis as x/y/z or value,
    ``angle`` in degrees, right-handed; the axis is not normalized, as in Mitsuba), ``scale`` (value: 1 or 3 numbers, or
    x/y/z), ``matrix`` (value: 16 numbers row-major, or 9 for the linear
    part), ``lookat`` (origin, target, optional up); each one is applied after
    the ones before it (M ← op · M), as Mitsuba composes them.
``sensor``
    ``perspective`` (``fov`` with ``fov_axis`` x [default] / y / diagonal /
    smaller / larger, or ``focal_length`` ["50mm" default, 35 mm film
    diagonal], ``near_clip`` [1e-2], ``far_clip`` [1e4], ``to_world``;
    ``focus_distance`` accepted, no effect on a pinhole), ``thinlens``
    (plus ``aperture_radius``, ``focus_distance``, both required here) and
    ``orthographic`` (``near_clip``, ``far_clip``, ``to_world``, whose scale
    sizes the film: parallel rays over [−1, 1] × [−1/aspect, 1/aspect]).
    Nested ``film`` and ``sampler``. At most one sensor.
``film``
    ``hdrfilm``: ``width`` [768], ``height`` [576]; ``pixel_format``,
    ``component_format``, ``file_format`` accepted, ignored (output encoding), and
    ``banner`` (Mitsuba 3 ignores it too).
    Nested ``rfilter``: ``box`` (each pixel averages its own area),
    ``gaussian`` (``stddev`` [0.5], radius 4·stddev, Mitsuba's default when no
    filter is given) or ``tent`` (``radius`` [1]): camera rays are drawn from the filter around the pixel
    centre, so a pixel estimates what Mitsuba's splatting film converges to
    (:func:`grisx.scene.camera.gaussian_filter_sample`, :func:`~grisx.scene.camera.tent_filter_sample`).
    ``mitchell``, ``lanczos`` and ``catmullrom`` (negative lobes) are errors.
``sampler``
    ``independent``, ``stratified``, ``multijitter``, ``orthogonal``,
    ``ldsampler``: ``sample_count`` [4] → ``scene.defaults["spp"]``; ``seed``
    accepted, ignored (grisx seeds its own streams).
``integrator``
    ``path`` (and ``volpath``, identical without media): ``max_depth`` [-1 =
    unbounded] → ``scene.defaults["max_depth"]`` with Mitsuba's meaning (1 =
    directly visible emitters only, 2 = direct lighting, ...); ``rr_depth``
    [5] → ``scene.defaults["rr_depth"]``; ``hide_emitters`` false only.
    Others are read as what they estimate: ``ptracer`` (the same image traced
    from the lights) as path tracing at its ``max_depth``; ``direct``
    (``emitter_samples``, ``bsdf_samples``, ``shading_samples``: sampling
    choices) as ``max_depth`` 2; ``moment`` and ``aov`` as their one nested
    integrator (their extra channels are not rendered); ``volpathmis``,
    ``prb``, ``prb_basic``, ``prbvolpath`` and Mitsuba 0.x's ``bdpt``,
    ``pssmlt``, ``mlt``, ``erpt`` (unbiased estimators of the same image) as
    path tracing, with a :class:`~grisx.errors.GrisxWarning` saying so.
    ``stokes`` is refused (Stokes vectors; Mitsuba's RGB variants refuse it too).
``shape``
    ``rectangle``, ``cube`` (``face_normals``), ``sphere`` (``center``,
    ``radius``), ``cylinder`` (``p0``, ``p1``, ``radius``), ``disk``, ``obj`` (``filename``, ``face_normals``, ``flip_tex_coords`` [true]),
    ``ply`` (``filename``, ``face_normals``, ``flip_tex_coords`` [false]), ``serialized`` (``filename``,
    ``shape_index`` [0], ``face_normals``; :mod:`grisx.scene.serialized`); all with ``to_world`` and
    ``flip_normals``; a nested or referenced ``bsdf`` (default: diffuse 0.5 — black
    on a shape with an emitter, as in Mitsuba 3) and a nested ``emitter type="area"``. Geometry: :mod:`grisx.scene.shapes`.
    A PLY file's extra vertex and face properties become mesh attributes, named and grouped as
    Mitsuba's ``ply`` does (``vertex_color``, ``face_weight``, ...; :func:`grisx.scene.shapes.ply_attributes`).
    ``shapegroup`` (shapes without emitters, invisible by themselves) and ``instance`` (one ``<ref>``
    to a group, ``to_world``): each instance is flattened into world-space meshes at load time
    (``to_world`` of the instance · ``to_world`` of the member; a mirroring instance keeps the members'
    front sides, as Mitsuba's ``instance.cpp``), at the cost of the members' vertices once per
    instance. ``sdfgrid`` (``filename``: a ``.vol`` grid, ``normals`` smooth [default] or analytic) is
    read as a fine triangle mesh of its zero set with Mitsuba's shading normals (:mod:`grisx.scene.sdfgrid`:
    within 0.006 voxels of Mitsuba's surface, no uv, no emission); ``linearcurve`` (``filename``) as a fine
    mesh of its round linear curves with Mitsuba's normals and uv, ``bsplinecurve`` likewise
    (open tubes; :mod:`grisx.scene.curves`). Under a mirroring ``to_world`` (det < 0) a shape's front side is Mitsuba's: where the
    normals of a rectangle, a cube, a disk or a mesh with normals point (the winding is reversed to
    agree, :func:`grisx.scene.shapes.finish_mesh`), the winding's side for a mesh without normals, and
    inside out for a sphere or tube (``sphere.cpp``). A cube keeps its per-face normals with
    ``face_normals``, as Mitsuba 3.9.1's does.
``bsdf``
    ``diffuse`` (``reflectance``: colour or ``bitmap`` texture [0.5]);
    ``conductor`` / ``roughconductor`` (``material`` [none]: any of Mitsuba's
    71 ``data/ior`` presets, ``a-C`` to ``W``, in RGB as its rgb variants read them; or ``eta``/``k``,
    ``specular_reflectance``; rough: ``alpha`` [0.1] (roughconductor: a number or a texture), or
    roughconductor's anisotropic ``alpha_u`` and ``alpha_v`` (numbers or textures; on meshes), ``distribution``
    ``beckmann`` [default, as Mitsuba] or ``ggx``, ``sample_visible``);
    ``dielectric`` / ``roughdielectric`` (``int_ior`` [bk7], ``ext_ior`` [air]
    as numbers or Mitsuba's named IORs, ``specular_reflectance``,
    ``specular_transmittance``; rough: ``alpha`` (a number or a texture), ``distribution``,
    ``sample_visible``); ``thindielectric`` (``int_ior``, ``ext_ior``,
    ``specular_reflectance``, ``specular_transmittance``); ``twosided`` around
    one non-transmissive BSDF; ``null``; the wrappers ``mask`` (``opacity``
    [0.5]: a number or a texture, its luminance), ``normalmap`` (``normalmap``:
    a texture, read it ``raw``) and ``bumpmap`` (its one nested texture, any name;
    ``scale`` [1]), both with ``flip_invalid_normals`` and
    ``use_shadowing_function`` [true], around one BSDF (at most one mask, outermost,
    and one normalmap or bumpmap; a twosided goes inside a normalmap or bumpmap);
    ``blendbsdf`` (``weight``: a number or a texture, mesh attributes included) of two
    ``diffuse`` BSDFs (the first reflectance may be a texture), or of any two plain BSDFs, the
    second untextured and isotropic (:class:`~grisx.scene.material.BlendBSDF`); ``pplastic``
    (``diffuse_reflectance``, ``specular_reflectance``, ``int_ior``/``ext_ior`` or ``eta``,
    ``alpha`` or ``alpha_u``/``alpha_v``, numbers or textures, ``distribution``,
    ``sample_visible``), ``polarizer`` (``transmittance``; ``theta``, ``polarizing`` accepted) and
    ``retarder`` (``transmittance``; ``theta``, ``delta`` accepted) as Mitsuba's RGB variants
    evaluate them; ``principled`` (``base_color``
    [0.5]: a colour or a texture; ``roughness`` [0.5], ``anisotropic``, ``metallic``, ``spec_trans``,
    ``spec_tint``, ``sheen``, ``sheen_tint``, ``flatness``, ``clearcoat``, ``clearcoat_gloss`` [0]: numbers or
    textures, at most four of the lobe weights textured besides roughness and anisotropic; ``eta`` or
    ``specular`` [0.5]) and ``principledthin`` (the same without metallic and clearcoat, with ``diff_trans``
    [0] and ``eta`` [1.5], a number); their sampling rates only at Mitsuba's default 1. ``hair`` and
    ``measured_polarized`` are refused (not implemented), and so is the ``stokes`` integrator (Mitsuba's RGB
    variants refuse it too).
``emitter``
    ``area`` (inside a shape, or top-level with an ``id`` that one shape
    references; ``radiance``, required: a colour or a bitmap looked up at the
    shape's uv), ``constant``
    (``radiance`` [1]), ``envmap`` (``filename``, ``scale`` [1], ``to_world``;
    ``mis_compensation`` accepted, ignored), ``point`` (``position`` or
    ``to_world``, ``intensity`` [1]), ``spot`` (``to_world``: the cone points
    along its local +z; ``intensity`` [1], ``cutoff_angle`` [20°],
    ``beam_width`` [¾ of the cutoff], ``texture``: a bitmap spread over the
    cone), ``projector`` (``to_world``, a rigid frame looking down its +z;
    ``irradiance``: colour or bitmap [1]; ``scale`` [1]; ``fov``/``fov_axis``
    or ``focal_length`` as a sensor's, the image's aspect), ``directional``
    (``direction`` or ``to_world``'s +z; ``irradiance`` [1], not a texture).
    At most one environment. (:mod:`grisx.scene.lights`)
``texture``
    ``bitmap``: ``filename`` (PNG/JPEG/BMP via pillow, 8-bit or 16-bit grey, sRGB-decoded
    to linear with the exact sRGB curve as Mitsuba does unless ``raw="true"``;
    EXR via :func:`grisx.imageio.read_exr`, linear), ``filter_type`` bilinear
    [default] / nearest, ``wrap_mode`` repeat [default] / mirror / clamp, ``format`` (storage
    precision: read, and the texels kept in float) (:mod:`grisx.scene.texture`).
    ``checkerboard``: ``color0`` [0.4], ``color1`` [0.2] (constant colours).
    ``rawconstant``: ``value`` (a vector, or a colour) used as is.
    Both take ``to_uv`` (a ``<transform>``; its x/y rows and translation make
    Mitsuba's 2D affine map). ``mesh_attribute``: ``name`` (``vertex_*``: blended
    with the hit's barycentrics; ``face_*``: the face's value), ``scale`` [1]; a
    1-channel attribute is grey, a 3-channel one RGB; every mesh that uses it must
    have it (:mod:`grisx.scene.texture`). Textures are supported as diffuse ``reflectance``,
    a plastic's ``diffuse_reflectance`` (not a mesh attribute there: a plastic
    needs its texture's mean, as in Mitsuba), a mask's ``opacity`` and the maps of
    ``normalmap`` and ``bumpmap`` (not mesh attributes there).
    Area emitters take a bitmap ``radiance``, spots a bitmap ``texture``, projectors a
    bitmap ``irradiance``.

File names are looked up in the ``<path>`` folders, then the XML file's directory (the current directory
for XML given as a string). Elements not listed (``medium``, other plugin types ...) are errors.

References
----------
[Mitsuba3] W. Jakob et al., Mitsuba 3 documentation, "Scene file format" and
           the plugin reference, https://mitsuba.readthedocs.io (2022).
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
import warnings
from pathlib import Path
from typing import Any
from xml.parsers import expat

import numpy as np

from grisx.errors import GrisxError, GrisxWarning, SceneFileError
from grisx.scene import shapes, spectrum
from grisx.scene.serialized import load_serialized
from grisx.scene.sdfgrid import read_vol, sdfgrid_mesh
from grisx.scene.curves import bspline_curve_mesh, linear_curve_mesh, read_curves
from grisx.scene import transform as xf
from grisx.scene.camera import Camera, lookat
from grisx.scene.lights import ConstantEnvironment, DirectionalLight, EnvMap, Projector, load_envmap_image, rigid_frame
from grisx.scene.texture import FILTER_TYPES, WRAP_MODES, Bitmap, Checkerboard, MeshAttribute
from grisx.imageio import srgb_decode as srgb_to_linear
from grisx.scene.material import (
    BlendBSDF,
    BumpMap,
    Conductor,
    Dielectric,
    Mask,
    NormalMap,
    Null,
    MICROFACET_DISTRIBUTIONS,
    Diffuse,
    Plastic,
    Principled,
    PrincipledThin,
    PolarizedPlastic,
    Polarizer,
    Retarder,
    RoughConductor,
    RoughDielectric,
    RoughPlastic,
    ThinDielectric,
    TextureRef,
    conductor_material,
    is_anisotropic,
    pack_materials,
    principled_has,
    unwrap,
)
from grisx.scene.scene import Film, Scene

__all__ = ["load_mitsuba", "NAMED_IORS", "load_image"]

#: Mitsuba 3's named indices of refraction (``include/mitsuba/render/ior.h``).
NAMED_IORS: dict[str, float] = {
    "vacuum": 1.0,
    "helium": 1.000036,
    "hydrogen": 1.000132,
    "air": 1.000277,
    "carbon dioxide": 1.00045,
    "water": 1.3330,
    "acetone": 1.36,
    "ethanol": 1.361,
    "carbon tetrachloride": 1.461,
    "glycerol": 1.4729,
    "benzene": 1.501,
    "silicone oil": 1.52045,
    "bromine": 1.661,
    "water ice": 1.31,
    "fused quartz": 1.458,
    "pyrex": 1.470,
    "acrylic glass": 1.49,
    "polypropylene": 1.49,
    "bk7": 1.5046,
    "sodium chloride": 1.544,
    "amber": 1.55,
    "pet": 1.5750,
    "diamond": 2.419,
}

_VALUE_TAGS = {"float", "integer", "boolean", "string", "point", "vector", "rgb", "srgb", "spectrum"}
_OBJECT_TAGS = {"shape", "bsdf", "emitter", "sensor", "film", "rfilter", "sampler", "integrator", "texture"}
_TRANSFORM_OPS = {"translate", "rotate", "scale", "matrix", "lookat"}
_ALLOWED_ATTRS: dict[str, set[str]] = {
    "scene": {"version"},
    "default": {"name", "value"},
    "path": {"value"},
    "include": {"filename", "name"},
    "ref": {"id", "name"},
    "transform": {"name"},
    "float": {"name", "value"},
    "integer": {"name", "value"},
    "boolean": {"name", "value"},
    "string": {"name", "value"},
    "rgb": {"name", "value"},
    "srgb": {"name", "value"},
    "spectrum": {"name", "value", "filename", "type", "id"},
    "point": {"name", "value", "x", "y", "z"},
    "vector": {"name", "value", "x", "y", "z"},
    "translate": {"value", "x", "y", "z"},
    "rotate": {"value", "x", "y", "z", "angle"},
    "scale": {"value", "x", "y", "z"},
    "matrix": {"value"},
    "lookat": {"origin", "target", "up"},
    **{t: {"type", "id", "name"} for t in _OBJECT_TAGS},
}
_PARAM_RE = re.compile(r"\$([A-Za-z_][A-Za-z0-9_]*)")


# ---- XML with line numbers -------------------------------------------------------


@dataclasses.dataclass
class _Node:
    tag: str
    attrs: dict[str, str]
    line: int
    children: list[_Node] = dataclasses.field(default_factory=list)
    path: str | None = None  # the file it was read from (an <include>d file's own), None for XML given as a string

    def label(self) -> str:
        """How the element is named in messages: tag plus its type/name/id attributes."""
        extra = "".join(f' {k}="{self.attrs[k]}"' for k in ("type", "name", "id") if k in self.attrs)
        return self.tag + extra


class _Ctx:
    """Where the file is, for messages and relative paths.

    ``search`` is Mitsuba's file resolver: the folders that ``<path>`` elements
    prepend, then the scene file's folder; a relative file name is looked up in
    each in turn (:meth:`resolve`).
    """

    def __init__(self, path: str | None, base_dir: Path):
        self.path, self.base_dir = path, base_dir
        self.search: list[Path] = [base_dir]

    def resolve(self, filename: str) -> Path:
        """A file name as Mitsuba's resolver finds it: the first search folder that has it (else the scene's folder)."""
        for folder in self.search:
            candidate = folder / filename
            if candidate.exists():
                return candidate
        return self.base_dir / filename

    def where(self, node: _Node) -> str:
        """``file:line: <element>``, as errors begin."""
        return str(self.error(node, "")).rstrip()

    def error(self, node: _Node | None, message: str, attribute: str | None = None) -> SceneFileError:
        return SceneFileError(
            message,
            path=node.path if node is not None and node.path is not None else self.path,
            line=None if node is None else node.line,
            element=None if node is None else node.label(),
            attribute=attribute,
        )


def _parse_xml(data: bytes, ctx: _Ctx, path: str | None = None) -> _Node:
    parser = expat.ParserCreate()
    stack: list[_Node] = []
    roots: list[_Node] = []

    def start(tag: str, attrs: dict[str, str]) -> None:
        node = _Node(tag, dict(attrs), parser.CurrentLineNumber, path=path)
        (stack[-1].children if stack else roots).append(node)
        stack.append(node)

    def end(tag: str) -> None:
        stack.pop()

    def text(data: str) -> None:
        if data.strip():
            where = stack[-1] if stack else None
            raise ctx.error(where, f"unexpected text {data.strip()[:40]!r} (values go in attributes)")

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.CharacterDataHandler = text
    try:
        parser.Parse(data, True)
    except expat.ExpatError as exc:
        raise SceneFileError(
            f"malformed XML: {expat.ErrorString(exc.code)} (column {exc.offset + 1})", path=path or ctx.path, line=exc.lineno
        ) from None
    return roots[0]


def _camel_to_snake(name: str) -> str:
    return re.sub(r"(?<=[a-z0-9])(?=[A-Z])", "_", name).lower()  # toWorld → to_world, intIOR → int_ior


#: why some elements and plugin types are refused (what grisx cannot render), said in their error
_WHY_NOT = {
    **dict.fromkeys(("medium", "phase", "volume", "homogeneous", "heterogeneous", "volpath_media"),
                    "participating media are not rendered by grisx (surfaces only)"),
    # plugins2: polarizer and retarder load as Mitsuba's RGB variants read them; these do not
    "stokes": "it outputs Stokes vectors, and Mitsuba 3's RGB variants refuse it too ('This integrator should only be "
              "used in polarized mode!'); grisx renders unpolarized RGB radiance",
    "measured_polarized": "a measured polarimetric BRDF (Baek et al. 2020) is not implemented by grisx (Mitsuba 3's RGB "
                          "variants refuse it too unless one 'wavelength' is given)",
    "hair": "Chiang et al.'s hair BSDF is not implemented by grisx",
    **dict.fromkeys(("mitchell", "lanczos", "catmullrom"),
                    "grisx films filter with box, gaussian or tent only (a filter with negative lobes would need "
                    "signed camera-sample weights in every renderer)"),
    "depth": "grisx integrators render radiance",
}

#: Mitsuba's limit on nested <include>s (MI_XML_INCLUDE_MAX_RECURSION); deeper means a cycle, in practice
_MAX_INCLUDE_DEPTH = 15


def _version_major(root: _Node, ctx: _Ctx) -> int:
    version = root.attrs.get("version")
    if version is None:
        raise ctx.error(root, "missing attribute 'version' (e.g. version=\"3.0.0\")", "version")
    try:
        return int(version.split(".")[0])
    except ValueError:
        raise ctx.error(root, f"attribute 'version': cannot parse '{version}'", "version") from None


def _upgrade(node: _Node) -> None:
    """Mitsuba 0.x names → Mitsuba 3's, as its ``upgrade_tree`` does: camelCase → snake_case, ``lookAt`` → ``lookat``,
    a diffuse BSDF's ``diffuse_reflectance`` → ``reflectance``."""
    if node.tag == "lookAt":
        node.tag = "lookat"
    if "name" in node.attrs and node.tag != "default":
        node.attrs["name"] = _camel_to_snake(node.attrs["name"])
    for child in node.children:
        _upgrade(child)
        if node.tag == "bsdf" and node.attrs.get("type") == "diffuse" and child.attrs.get("name") == "diffuse_reflectance":
            child.attrs["name"] = "reflectance"


def _param_text(v: Any) -> str:
    return v if isinstance(v, str) else (str(v).lower() if isinstance(v, bool) else repr(v) if isinstance(v, float) else str(v))


class _Expander:
    """Reads ``<path>`` into the file resolver and splices ``<include>``d files in place (first pass, in document
    order, as Mitsuba's parser does); then applies ``<default>``/``$name`` substitution and the attribute
    whitelists to the whole tree (second pass, so a default may come after its use, e.g. in a later include)."""

    def __init__(self, ctx: _Ctx, params: dict[str, Any] | None):
        self.ctx = ctx
        self.values = {str(k): _param_text(v) for k, v in (params or {}).items()}
        self.given = set(self.values)
        self.used: set[str] = set()

    # -- first pass: <default>, <path>, <include>
    def expand(self, node: _Node, depth: int, top: bool) -> list[_Node]:
        """``node``'s children with includes spliced in; ``top``: ``node`` is a file's <scene>."""
        out: list[_Node] = []
        for child in node.children:
            if child.tag in ("default", "path", "include"):
                self.attributes(child)
            if child.tag in ("default", "path") and not top:
                raise self.ctx.error(child, f"<{child.tag}> is only allowed directly inside <scene>")
            if child.tag == "default":
                for a in ("name", "value"):
                    if a not in child.attrs:
                        raise self.ctx.error(child, f"missing attribute '{a}'", a)
                self.used.add(child.attrs["name"])
                self.values.setdefault(child.attrs["name"], child.attrs["value"])  # a caller's value, or the first, wins
            elif child.tag == "path":
                self.path(child)
            elif child.tag == "include":
                out.extend(self.include(child, depth))
            else:
                child.children = self.expand(child, depth, top=False)
                out.append(child)
        return out

    def _folder(self, node: _Node) -> Path:
        return Path(node.path).resolve().parent if node.path is not None else self.ctx.base_dir

    def _find(self, node: _Node, attr: str, what: str, exists: Any) -> Path:
        """``node``'s ``attr``: relative to its file's folder, else found by the resolver (Mitsuba's order)."""
        if attr not in node.attrs:
            raise self.ctx.error(node, f"missing attribute '{attr}'", attr)
        value = node.attrs[attr]
        for found in (self._folder(node) / value, self.ctx.resolve(value)):
            if exists(found):
                return found
        raise self.ctx.error(node, f"attribute '{attr}': {what} '{value}' not found (relative to {self._folder(node)})", attr)

    def path(self, node: _Node) -> None:
        """``<path value>``: a folder, searched first from now on."""
        self.ctx.search.insert(0, self._find(node, "value", "folder", Path.is_dir).resolve())

    def include(self, node: _Node, depth: int) -> list[_Node]:
        """``<include filename>``: the file's <scene> children (or its one object) in place of the element."""
        path = self._find(node, "filename", "included file", Path.is_file)
        if depth >= _MAX_INCLUDE_DEPTH:
            raise self.ctx.error(node, f"<include> nested deeper than {_MAX_INCLUDE_DEPTH} files (does a file include itself?)")
        root = _parse_xml(path.read_bytes(), self.ctx, str(path))
        if _version_major(root, self.ctx) < 2:
            _upgrade(root)
        del root.attrs["version"]
        if root.tag == "scene":
            return self.expand(root, depth + 1, top=True)
        root.children = self.expand(root, depth + 1, top=False)
        return [root]

    # -- second pass: $name substitution and attribute whitelists
    def attributes(self, node: _Node) -> None:
        allowed = _ALLOWED_ATTRS.get(node.tag)
        if allowed is None:
            why = _WHY_NOT.get(node.tag, "")
            raise self.ctx.error(node, f"unsupported element <{node.tag}>{why and ': ' + why}")
        for attr, raw in list(node.attrs.items()):
            if attr not in allowed:
                raise self.ctx.error(node, f"unsupported attribute '{attr}'", attr)

            def sub(m: re.Match[str], attr: str = attr) -> str:
                if m.group(1) not in self.values:
                    raise self.ctx.error(node, f"attribute '{attr}': unknown parameter '${m.group(1)}' "
                                               f"(no <default> and not passed in params)", attr)
                self.used.add(m.group(1))
                return self.values[m.group(1)]

            node.attrs[attr] = _PARAM_RE.sub(sub, raw)

    def visit(self, node: _Node) -> None:
        for child in node.children:
            self.attributes(child)
            self.visit(child)


def _prepare(root: _Node, ctx: _Ctx, params: dict[str, Any] | None) -> None:
    """Check the root; apply ``default``/``$param`` substitution, ``<path>``, ``<include>`` and the attribute
    whitelists; upgrade 0.x names. A ``params`` name that the file never uses is an error (as in Mitsuba)."""
    if root.tag != "scene":
        raise ctx.error(root, "the root element must be <scene>")
    if _version_major(root, ctx) < 2:
        _upgrade(root)
    expander = _Expander(ctx, params)
    root.children = expander.expand(root, 0, top=True)
    expander.attributes(root)
    expander.visit(root)
    unknown = sorted(expander.given - expander.used)
    if unknown:
        known = sorted(n for n in expander.used if n not in expander.given) or ["none"]
        raise SceneFileError(f"unknown scene parameter(s) {', '.join(repr(n) for n in unknown)}: the file has no "
                             f"<default> or $name by that name (its parameters: {', '.join(known)})", path=ctx.path)


# ---- numbers and transforms ------------------------------------------------------


def _numbers(ctx: _Ctx, node: _Node, attr: str, counts: tuple[int, ...]) -> list[float]:
    raw = node.attrs.get(attr)
    if raw is None:
        raise ctx.error(node, f"missing attribute '{attr}'", attr)
    parts = [p for p in re.split(r"[,\s]+", raw.strip()) if p]
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        raise ctx.error(node, f"attribute '{attr}': cannot parse numbers from '{raw}'", attr) from None
    if len(vals) not in counts or not all(math.isfinite(v) for v in vals):
        want = " or ".join(str(c) for c in counts)
        raise ctx.error(node, f"attribute '{attr}': expected {want} finite number(s), got '{raw}'", attr)
    if any(abs(v) > _FLOAT32_MAX for v in vals):  # kernels compute in float32: it would be Inf there
        raise ctx.error(node, f"attribute '{attr}': '{raw}' is beyond float32's range (|x| <= 3.4e38)", attr)
    return vals


_FLOAT32_MAX = float(np.finfo(np.float32).max)


def _xyz(ctx: _Ctx, node: _Node, default: float) -> np.ndarray:
    """A 3-vector from ``value`` or from ``x``/``y``/``z`` attributes (missing ones = ``default``)."""
    if "value" in node.attrs:
        if any(a in node.attrs for a in "xyz"):
            raise ctx.error(node, "give either 'value' or 'x'/'y'/'z', not both", "value")
        v = _numbers(ctx, node, "value", (1, 3))
        return np.array(v * 3 if len(v) == 1 else v, dtype=np.float64)
    out = np.full(3, float(default))
    for i, a in enumerate("xyz"):
        if a in node.attrs:
            out[i] = _numbers(ctx, node, a, (1,))[0]
    return out


def _coordinate_system_s(d: np.ndarray) -> np.ndarray:
    # Mitsuba's coordinate_system(n).first (Duff et al. 2017): the 'up' used when lookat omits it
    sign = math.copysign(1.0, d[2])
    a = -1.0 / (sign + d[2])
    b = d[0] * d[1] * a
    return np.array([1.0 + sign * d[0] * d[0] * a, sign * b, -sign * d[0]])


def _parse_transform(ctx: _Ctx, node: _Node) -> np.ndarray:
    m = np.eye(4)
    for op in node.children:
        if op.tag not in _TRANSFORM_OPS:
            raise ctx.error(op, f"unsupported element <{op.tag}> inside <transform> "
                                f"(expected {', '.join(sorted(_TRANSFORM_OPS))})")
        if op.tag == "translate":
            t = xf.translate(_xyz(ctx, op, 0.0))
        elif op.tag == "scale":
            t = xf.scale(_xyz(ctx, op, 1.0))
        elif op.tag == "rotate":
            if "angle" not in op.attrs:
                raise ctx.error(op, "missing attribute 'angle' (degrees)", "angle")
            axis = _xyz(ctx, op, 0.0)
            if np.linalg.norm(axis) == 0:
                raise ctx.error(op, "rotation axis is zero (give x/y/z or value)", "value")
            t = xf.rotate(axis, _numbers(ctx, op, "angle", (1,))[0])  # right-handed, degrees
        elif op.tag == "matrix":
            v = _numbers(ctx, op, "value", (9, 16))
            t = np.eye(4)
            if len(v) == 16:
                t = np.array(v).reshape(4, 4)
            else:
                t[:3, :3] = np.array(v).reshape(3, 3)
        else:  # lookat
            o = np.array(_numbers(ctx, op, "origin", (3,)))
            tgt = np.array(_numbers(ctx, op, "target", (3,)))
            d = tgt - o
            if np.linalg.norm(d) == 0:
                raise ctx.error(op, "origin and target coincide", "target")
            up = np.array(_numbers(ctx, op, "up", (3,))) if "up" in op.attrs else _coordinate_system_s(d / np.linalg.norm(d))
            try:
                t = lookat(o, tgt, up)  # Mitsuba's look_at: columns left, up', dir, origin
            except GrisxError as exc:
                raise ctx.error(op, str(exc), "up") from None
        m = t @ m
    return m


# ---- images ----------------------------------------------------------------------


def load_image(path: str | os.PathLike, raw: bool = False) -> np.ndarray:
    """Read an image as linear float32 (H, W, 3), row 0 at the top.

    EXR is linear already; PNG/JPEG/BMP are sRGB-decoded unless ``raw``. Grey
    images are broadcast to RGB and alpha is dropped.
    """
    path = Path(path)
    if not path.is_file():
        raise GrisxError(f"cannot read image '{path}': no such file")
    suffix = path.suffix.lower()
    if suffix == ".exr":
        from grisx.imageio import read_exr

        img = read_exr(path).astype(np.float64)
    elif suffix in (".png", ".jpg", ".jpeg", ".bmp"):
        from PIL import Image

        try:
            with Image.open(path) as im:
                if im.mode in ("I;16", "I;16B", "I;16L", "I"):
                    arr = np.asarray(im, dtype=np.float64) / 65535.0
                else:
                    arr = np.asarray(im.convert("RGBA" if "A" in im.mode or im.mode == "P" else "RGB"), dtype=np.float64) / 255.0
        except OSError as exc:
            raise GrisxError(f"cannot read image '{path}': {exc}") from None
        img = arr if raw else srgb_to_linear(arr)
    else:
        raise GrisxError(f"cannot read image '{path}': unsupported format '{suffix}' (use .exr, .png, .jpg or .bmp)")
    if img.ndim == 2:
        img = img[:, :, None]
    if img.shape[2] in (2, 4):  # grey+alpha or RGBA: drop alpha
        img = img[:, :, :-1]
    if img.shape[2] == 1:
        img = np.repeat(img, 3, axis=2)
    if not np.all(np.isfinite(img)):
        raise GrisxError(f"image '{path}' contains NaN or Inf")
    return np.ascontiguousarray(img[:, :, :3], dtype=np.float32)


# ---- plugin properties -----------------------------------------------------------


class _Props:
    """The parameters and nested objects of one plugin element; tracks which were used."""

    def __init__(self, loader: _Loader, node: _Node):
        self.loader, self.ctx, self.node = loader, loader.ctx, node
        self.values: dict[str, _Node] = {}
        self.objects: list[_Node] = []
        self.used: set[str] = set()
        self.used_objects: set[int] = set()
        for child in node.children:
            if child.tag == "default":
                raise self.ctx.error(child, "<default> is only allowed directly inside <scene>")
            is_texture = child.tag == "texture" or (child.tag == "ref" and loader.ref_target(child).tag == "texture")
            if child.tag in _VALUE_TAGS or child.tag == "transform" or is_texture:
                name = child.attrs.get("name")
                if name is None:
                    raise self.ctx.error(child, "missing attribute 'name'", "name")
                if name in self.values:
                    raise self.ctx.error(child, f"parameter '{name}' given twice (first on line {self.values[name].line})", "name")
                self.values[name] = child
            elif child.tag in _OBJECT_TAGS or child.tag == "ref":
                self.objects.append(child)
            else:
                raise self.ctx.error(child, f"unsupported element <{child.tag}> inside <{node.label()}>")

    # -- lookup helpers
    def has(self, name: str) -> bool:
        return name in self.values

    def _get(self, name: str, tags: tuple[str, ...]) -> _Node | None:
        node = self.values.get(name)
        if node is None:
            return None
        self.used.add(name)
        tag = node.tag if node.tag != "ref" else "texture"
        if tag not in tags:
            raise self.ctx.error(node, f"parameter '{name}' must be given as <{'> or <'.join(tags)}>, not <{tag}>", name)
        return node

    def float(self, name: str, default: float | None = None) -> float:
        node = self._get(name, ("float", "integer"))
        if node is None:
            if default is None:
                raise self.ctx.error(self.node, f"missing required parameter '{name}'", name)
            return float(default)
        return _numbers(self.ctx, node, "value", (1,))[0]

    def int(self, name: str, default: int) -> int:
        node = self._get(name, ("integer",))
        if node is None:
            return default
        raw = node.attrs.get("value", "")
        try:
            return int(raw.strip())
        except ValueError:
            raise self.ctx.error(node, f"attribute 'value': '{raw}' is not an integer", "value") from None

    def bool(self, name: str, default: bool) -> bool:
        node = self._get(name, ("boolean",))
        if node is None:
            return default
        raw = node.attrs.get("value", "").strip().lower()
        if raw not in ("true", "false"):
            raise self.ctx.error(node, f"attribute 'value': '{raw}' is not true or false", "value")
        return raw == "true"

    def string(self, name: str, default: str | None = None) -> str:
        node = self._get(name, ("string",))
        if node is None:
            if default is None:
                raise self.ctx.error(self.node, f"missing required parameter '{name}'", name)
            return default
        if "value" not in node.attrs:
            raise self.ctx.error(node, "missing attribute 'value'", "value")
        return node.attrs["value"]

    def choice(self, name: str, default: str | None, allowed: tuple[str, ...], why: str = "") -> str:
        value = self.string(name, default)
        if value.lower() not in allowed:
            node = self.values.get(name, self.node)
            raise self.ctx.error(node, f"parameter '{name}' = '{value}' is not supported "
                                       f"(supported: {', '.join(allowed)}){why}", name)
        return value.lower()

    def point(self, name: str, default: tuple[float, float, float]) -> np.ndarray:
        node = self._get(name, ("point", "vector"))
        if node is None:
            return np.asarray(default, dtype=np.float64)
        return _xyz(self.ctx, node, 0.0)

    def transform(self, name: str) -> np.ndarray | None:
        node = self._get(name, ("transform",))
        return None if node is None else _parse_transform(self.ctx, node)

    def color(self, name: str, default: float | tuple[float, ...] | None, texture: bool = False, kind: str = "reflectance") -> Any:
        """RGB from ``rgb``/``spectrum``/``float``, or a :class:`TextureRef` where ``texture``. ``kind``: what the
        colour is — ``reflectance`` (bounded), ``unbounded`` (eta, k) or ``emission`` — which decides how
        Mitsuba reduces a spectrum to RGB."""
        node = self.values.get(name)
        if node is None:
            if default is None:
                raise self.ctx.error(self.node, f"missing required parameter '{name}'", name)
            d = (default,) * 3 if isinstance(default, (int, float)) else tuple(default)
            return tuple(float(x) for x in d)
        if node.tag in ("texture", "ref"):
            self.used.add(name)
            if not texture:
                raise self.ctx.error(node, f"parameter '{name}': textures are supported only as diffuse "
                                           f"'reflectance' and a plastic's 'diffuse_reflectance'; give a constant <rgb>", name)
            return self.loader.texture_ref(node)
        node = self._get(name, ("rgb", "srgb", "spectrum", "float"))
        if node.tag == "spectrum":
            return self._spectrum(name, node, kind)
        if node.tag == "srgb":  # Mitsuba 0.x: sRGB-encoded, as numbers in [0, 1] or "#rrggbb"
            raw = node.attrs.get("value", "").strip()
            if re.fullmatch(r"#[0-9a-fA-F]{6}", raw):
                v = [int(raw[i:i + 2], 16) / 255.0 for i in (1, 3, 5)]
            else:
                v = _numbers(self.ctx, node, "value", (1, 3))
            return tuple(float(c) for c in srgb_to_linear(np.array(v * 3 if len(v) == 1 else v)))
        counts = (1, 3) if node.tag == "rgb" else (1,)
        v = _numbers(self.ctx, node, "value", counts)
        return tuple(v * 3 if len(v) == 1 else v)

    def emission(self, name: str, default: float | None) -> Any:
        """An emitter's colour (RGB, reduced as an emission spectrum) or its bitmap texture (an image or a :class:`Bitmap`)."""
        node = self.values.get(name)
        if node is not None and node.tag in ("texture", "ref"):
            self.used.add(name)
            tex = self.loader.texture_record(node)
            if not isinstance(tex, (np.ndarray, Bitmap)):
                raise self.ctx.error(node, f"parameter '{name}': an emitter's texture must be a bitmap", name)
            return tex
        return self.color(name, default, kind="emission")

    def fov(self) -> tuple[float, str]:
        """(fov in degrees, fov_axis) from ``fov``/``fov_axis`` or ``focal_length`` (Mitsuba's parse_fov)."""
        if self.has("fov") and self.has("focal_length"):
            raise self.ctx.error(self.node, "give either 'fov' or 'focal_length', not both", "focal_length")
        if self.has("fov"):
            return self.float("fov"), self.choice("fov_axis", "x", ("x", "y", "diagonal", "smaller", "larger"))
        # Mitsuba: focal length of a 35 mm camera, measured along the film diagonal
        f = self.string("focal_length", "50mm").strip()
        try:
            fl = float(f[:-2] if f.endswith("mm") else f)
        except ValueError:
            raise self.ctx.error(self.values.get("focal_length", self.node), f"cannot parse focal_length '{f}' (e.g. \"50mm\")", "focal_length") from None
        return math.degrees(2 * math.atan(math.hypot(36.0, 24.0) / (2 * fl))), "diagonal"

    def _spectrum(self, name: str, node: _Node, kind: str) -> tuple[float, float, float]:
        """A ``<spectrum>`` as Mitsuba's RGB variants reduce it (:mod:`grisx.scene.spectrum`)."""
        emitter = kind == "emission"
        if "type" in node.attrs:  # a spectrum plugin
            t = self.loader._require_type(node, ("blackbody",))
            if not emitter:
                raise self.ctx.error(node, f"parameter '{name}': a {t} spectrum is an emission spectrum "
                                           f"(give it to an emitter's radiance or intensity)", "type")
            p = _Props(self.loader, node)
            temperature = p.float("temperature")
            lo, hi = p.float("wavelength_min", spectrum.CIE_MIN), p.float("wavelength_max", spectrum.CIE_MAX)
            p.finish()
            try:
                return spectrum.blackbody_rgb(temperature, lo, hi)
            except GrisxError as exc:
                raise self.ctx.error(node, f"parameter '{name}': {exc}") from None
        if ("value" in node.attrs) == ("filename" in node.attrs):
            raise self.ctx.error(node, "a <spectrum> takes either 'value' or 'filename'", "value")
        try:
            if "filename" in node.attrs:
                wavelengths, values = spectrum.read_spd(self.ctx.resolve(node.attrs["filename"]))
            elif ":" not in node.attrs["value"]:
                return spectrum.uniform_rgb(_numbers(self.ctx, node, "value", (1,))[0], emitter)
            else:
                pairs = [p.split(":") for p in re.split(r"[,\s]+", node.attrs["value"].strip()) if p]
                if any(len(pair) != 2 for pair in pairs):
                    raise GrisxError(f"expected wavelength:value pairs, got '{node.attrs['value']}'")
                try:
                    wavelengths, values = np.array([[float(a), float(b)] for a, b in pairs]).T
                except ValueError:
                    raise GrisxError(f"cannot parse wavelength:value pairs from '{node.attrs['value']}'") from None
            # reflectances are seen under D65 and clamped to [0, 1]; emission and unbounded values (eta, k) are not
            return spectrum.spectrum_list_to_srgb(wavelengths, values, bounded=kind == "reflectance", d65=not emitter)
        except GrisxError as exc:
            attr = "filename" if "filename" in node.attrs else "value"
            raise self.ctx.error(node, f"parameter '{name}', attribute '{attr}': {exc}", attr) from None

    def ior(self, name: str, default: str) -> float:
        node = self.values.get(name)
        if node is not None and node.tag == "string":
            key = self.string(name).strip().lower()
            if key not in NAMED_IORS:
                raise self.ctx.error(node, f"parameter '{name}': unknown named IOR '{key}' "
                                           f"(known: {', '.join(NAMED_IORS)})", name)
            return NAMED_IORS[key]
        if node is None:
            return NAMED_IORS[default]
        return self.float(name)

    def take_objects(self, tags: tuple[str, ...]) -> list[_Node]:
        """Nested (or referenced) objects whose kind is in ``tags``; marks them used."""
        out = []
        for i, child in enumerate(self.objects):
            kind = self.loader.ref_target(child).tag if child.tag == "ref" else child.tag
            if kind in tags:
                self.used_objects.add(i)
                out.append(child)
        return out

    def finish(self) -> None:
        """Every parameter and nested object must have been used (as Mitsuba's 'unreferenced property' check)."""
        for name, node in self.values.items():
            if name not in self.used:
                raise self.ctx.error(node, f"unsupported parameter '{name}' of <{self.node.label()}>", name)
        for i, child in enumerate(self.objects):
            if i not in self.used_objects:
                raise self.ctx.error(child, f"unexpected <{child.label()}> inside <{self.node.label()}>")


# ---- the loader --------------------------------------------------------------------

_SAMPLERS = ("independent", "stratified", "multijitter", "orthogonal", "ldsampler")
_SHAPES = ("obj", "ply", "serialized", "rectangle", "cube", "sphere", "disk", "cylinder", "sdfgrid", "linearcurve", "bsplinecurve",
           "shapegroup", "instance")


@dataclasses.dataclass(frozen=True)
class _ShapePart:
    """A shape as read, before it enters the scene: its type, object-space mesh (``None``: a sphere, disk or
    cylinder, analytic unless it emits), ``to_world``, material id, emission."""

    kind: str
    mesh: shapes.MeshData | None
    to_world: np.ndarray
    material: int
    emission: Any
    name: str
    node: _Node  # the element errors name
    flip_normals: bool = False  # of an analytic shape (a mesh has it applied already)


class _Loader:
    def __init__(self, root: _Node, ctx: _Ctx, scene: Scene):
        self.root, self.ctx, self.scene = root, ctx, scene
        self.ids: dict[str, _Node] = {}
        self.records: dict[int, Any] = {}  # id(node) -> material record
        self.material_ids: dict[int, int] = {}  # id(node) -> scene material id
        self.texture_ids: dict[int, int] = {}  # id(node) -> scene texture id
        self.texture_records: dict[int, tuple[Any, str]] = {}  # id(node) -> (texture record, name)
        self.texture_means: dict[int, float] = {}  # scene texture id -> mean value
        self.default_materials: dict[str, int] = {}  # "default" / "default_emitter" -> scene material id
        self.shape_count = 0
        self.instance_count = 0
        self.groups: dict[int, list[_ShapePart]] = {}  # id(shapegroup node) -> its members
        self.sdf_meshes: dict[tuple[str, str], shapes.MeshData] = {}  # (grid file, normals) -> its mesh
        self.area_emitters_used: set[int] = set()  # id(node) of area emitters attached to a shape
        self.sensor_seen: _Node | None = None
        self.environment_seen: _Node | None = None
        self._collect_ids(root)

    def _collect_ids(self, node: _Node) -> None:
        for child in node.children:
            if "id" in child.attrs and child.tag in _OBJECT_TAGS:
                key = child.attrs["id"]
                if key in self.ids:
                    raise self.ctx.error(child, f"duplicate id '{key}' (first on line {self.ids[key].line})", "id")
                self.ids[key] = child
            self._collect_ids(child)

    def ref_target(self, ref: _Node) -> _Node:
        key = ref.attrs.get("id")
        if key is None:
            raise self.ctx.error(ref, "missing attribute 'id'", "id")
        if key not in self.ids:
            raise self.ctx.error(ref, f"reference to unknown id '{key}'", "id")
        return self.ids[key]

    def _deref(self, node: _Node, kind: str) -> _Node:
        target = self.ref_target(node) if node.tag == "ref" else node
        if target.tag != kind:
            raise self.ctx.error(node, f"expected a <{kind}>, but id '{node.attrs.get('id')}' is a <{target.tag}>", "id")
        return target

    @staticmethod
    def _type(node: _Node) -> str:
        return node.attrs.get("type", "")

    def _require_type(self, node: _Node, supported: tuple[str, ...]) -> str:
        t = self._type(node)
        if not t:
            raise self.ctx.error(node, "missing attribute 'type'", "type")
        if t not in supported:
            why = _WHY_NOT.get(t, "")
            raise self.ctx.error(node, f"unsupported {node.tag} type '{t}'{why and ': ' + why} (supported: {', '.join(supported)})", "type")
        return t

    # -- top level
    def run(self) -> None:
        emitters = [c for c in self.root.children if c.tag == "emitter"]  # after the shapes that reference them
        for child in [c for c in self.root.children if c.tag != "emitter"] + emitters:
            tag = child.tag
            if tag in ("film", "sampler", "rfilter") and "id" in child.attrs:
                continue  # read where a sensor references it (Mitsuba instantiates these by reference too)
            if tag == "shape":
                self.shape(child)
            elif tag == "bsdf":
                self.bsdf_record(child)  # validate now; added to the scene when a shape uses it
            elif tag == "texture":
                self.texture_id(child)
            elif tag == "emitter":
                self.emitter(child)
            elif tag == "sensor":
                self.sensor(child)
            elif tag == "integrator":
                self.integrator(child)
            else:
                raise self.ctx.error(child, f"unsupported element <{tag}> inside <scene>")

    # -- textures
    def texture_record(self, node: _Node) -> Any:
        """The ``<texture>`` (nested or by reference) as a record: a linear image, a :class:`Bitmap`, a :class:`Checkerboard`
        or a :class:`MeshAttribute`."""
        node = self._deref(node, "texture")
        if id(node) in self.texture_records:
            return self.texture_records[id(node)][0]
        t = self._require_type(node, ("bitmap", "checkerboard", "mesh_attribute", "rawconstant"))
        p = _Props(self, node)
        if t == "rawconstant":  # a constant read as is (no spectral conversion): an image of one texel
            node_value = p.values.get("value")
            value = p.point("value", (0.0, 0.0, 0.0)) if node_value is not None and node_value.tag in ("vector", "point") \
                else np.asarray(p.color("value", 1.0, kind="unbounded"), dtype=np.float64)
            p.finish()
            tex0 = np.asarray(value, dtype=np.float64).reshape(1, 1, 3)
            self.texture_records[id(node)] = (tex0, node.attrs.get("id") or "rawconstant")
            return tex0
        if t == "mesh_attribute":  # the hit mesh's own values: no uv, no mean (Mitsuba's Texture::mean is undefined)
            try:
                attribute = MeshAttribute(p.string("name"), p.float("scale", 1.0))
            except GrisxError as exc:
                raise self.ctx.error(p.values.get("name", node), str(exc), "name") from None
            p.finish()
            self.texture_records[id(node)] = (attribute, node.attrs.get("id") or attribute.name)
            return attribute
        to_uv = p.transform("to_uv")
        # Mitsuba's to_uv is a 2D affine map: of a 4x4 transform, rows and columns x, y and the translation
        uv_map = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0)) if to_uv is None else tuple(tuple(float(to_uv[r, c]) for c in (0, 1, 3)) for r in (0, 1))
        if t == "checkerboard":
            tex: Any = Checkerboard(color0=p.color("color0", 0.4), color1=p.color("color1", 0.2), to_uv=uv_map)
            name = node.attrs.get("id") or "checkerboard"
        else:
            filename = p.string("filename")
            name = node.attrs.get("id") or filename
            raw = p.bool("raw", False)
            p.choice("format", "auto", ("auto", "variant", "float16", "fp16", "uint8"))  # storage precision only
            filter_type = p.choice("filter_type", "bilinear", tuple(FILTER_TYPES))
            wrap_mode = p.choice("wrap_mode", "repeat", tuple(WRAP_MODES))
            image = self.image(node, filename, raw)
            plain = to_uv is None and filter_type == "bilinear" and wrap_mode == "repeat"
            tex = image if plain else Bitmap(image, to_uv=uv_map, wrap_mode=wrap_mode, filter_type=filter_type)
        p.finish()
        self.texture_records[id(node)] = (tex, name)
        return tex

    def texture_id(self, node: _Node) -> int:
        node = self._deref(node, "texture")
        if id(node) in self.texture_ids:
            return self.texture_ids[id(node)]
        tex = self.texture_record(node)
        name = self.texture_records[id(node)][1]
        tid = self.scene.add_texture(tex, name=name)
        self.texture_ids[id(node)] = tid
        if isinstance(tex, MeshAttribute):
            return tid  # no mean: Mitsuba's Texture::mean is undefined for it
        # Mitsuba's texture.mean() (a plastic's lobe sampling weights)
        self.texture_means[tid] = float(np.mean(np.asarray(tex.color0) + np.asarray(tex.color1)) / 2.0) if isinstance(tex, Checkerboard) \
            else float(np.mean(tex if isinstance(tex, np.ndarray) else tex.image))
        return tid

    def texture_ref(self, node: _Node) -> TextureRef:
        return TextureRef(self.texture_id(node))

    def image(self, node: _Node, filename: str, raw: bool = False) -> np.ndarray:
        path = self.ctx.resolve(filename)
        try:
            return load_image(path, raw=raw)
        except GrisxError as exc:
            raise self.ctx.error(node, f"parameter 'filename': {exc}", "filename") from None

    # -- BSDFs
    def bsdf_record(self, node: _Node) -> Any:
        node = self._deref(node, "bsdf")
        if id(node) in self.records:
            return self.records[id(node)]
        t = self._require_type(node, ("diffuse", "conductor", "roughconductor", "dielectric", "roughdielectric", "thindielectric",
                                      "plastic", "roughplastic", "twosided", "null", "mask", "normalmap", "bumpmap",
                                      "blendbsdf", "principled", "principledthin", "pplastic", "polarizer", "retarder"))
        p = _Props(self, node)
        if t == "twosided":
            inner = p.take_objects(("bsdf",))
            if len(inner) != 1:
                raise self.ctx.error(node, f"twosided needs exactly one nested BSDF, got {len(inner)} "
                                           f"(different front and back BSDFs are not supported)")
            rec = self._two_sided(node, self.bsdf_record(inner[0]))
        elif t in ("mask", "normalmap", "bumpmap"):
            inner = p.take_objects(("bsdf",))
            if len(inner) != 1:
                raise self.ctx.error(node, f"{t} needs exactly one nested BSDF, got {len(inner)}")
            nested = self.bsdf_record(inner[0])
            if t == "mask":
                opacity = p.values.get("opacity")
                if opacity is not None and opacity.tag in ("texture", "ref"):
                    rec = Mask(nested, self._uv_texture(p, "opacity"))
                else:
                    rec = Mask(nested, p.float("opacity", 0.5))
            else:
                flags = {"flip_invalid_normals": p.bool("flip_invalid_normals", True),
                         "use_shadowing_function": p.bool("use_shadowing_function", True)}
                if t == "normalmap":
                    if "normalmap" not in p.values or p.values["normalmap"].tag not in ("texture", "ref"):
                        raise self.ctx.error(node, "normalmap needs a texture named 'normalmap'")
                    rec = NormalMap(nested, self._uv_texture(p, "normalmap"), **flags)
                else:  # the one nested texture, whatever its name (bumpmap.cpp)
                    textures = [n for n, v in p.values.items() if v.tag in ("texture", "ref")]
                    if len(textures) != 1:
                        raise self.ctx.error(node, f"bumpmap needs exactly one nested texture, got {len(textures)}")
                    rec = BumpMap(nested, self._uv_texture(p, textures[0]), scale=p.float("scale", 1.0), **flags)
        elif t == "blendbsdf":
            inner = p.take_objects(("bsdf",))
            if len(inner) != 2:
                raise self.ctx.error(node, f"blendbsdf needs exactly two nested BSDFs, got {len(inner)}")
            first, second = (self.bsdf_record(n) for n in inner)  # any two BSDFs (plugins2); packing checks the pair
            if "weight" not in p.values:
                raise self.ctx.error(node, "missing required parameter 'weight'", "weight")
            weight = self._uv_texture(p, "weight", attributes=True) if p.values["weight"].tag in ("texture", "ref") \
                else p.float("weight")
            rec = BlendBSDF(first, second, weight)
        elif t in ("principled", "principledthin"):
            rec = self._principled(p, t)
        elif t == "null":
            rec = Null()
        # ---- plugins2 (issue 38): Mitsuba's polarization plugins as its RGB (unpolarized) variants evaluate them ----
        elif t in ("polarizer", "retarder"):
            for name in ("theta", "delta") if t == "retarder" else ("theta",):
                p.color(name, 0.0, texture=True, kind="unbounded")  # an angle: no effect on unpolarized light
            if t == "polarizer":
                p.bool("polarizing", True)  # unpolarized light loses half to a polarizer or a depolarizer alike
            rec = (Polarizer if t == "polarizer" else Retarder)(transmittance=p.color("transmittance", 1.0))
        elif t == "pplastic":
            diffuse = p.color("diffuse_reflectance", 0.5, texture=True)
            kw = {"diffuse_reflectance": diffuse, "diffuse_mean": self._texture_mean(p, "diffuse_reflectance", diffuse),
                  "specular_reflectance": p.color("specular_reflectance", 1.0)}
            if p.has("eta"):  # pplastic.cpp: eta, or int_ior and ext_ior
                if p.has("int_ior") or p.has("ext_ior"):
                    raise self.ctx.error(p.values["eta"], "give either 'eta' or 'int_ior'/'ext_ior', not both (as in Mitsuba 3)", "eta")
                kw["int_ior"], kw["ext_ior"] = p.float("eta"), 1.0
            else:
                kw["int_ior"], kw["ext_ior"] = p.ior("int_ior", "polypropylene"), p.ior("ext_ior", "air")
            rec = self._smooth_or_rough(p, True, kw, PolarizedPlastic, PolarizedPlastic)
        # ---- end plugins2 ----
        elif t == "diffuse":
            rec = Diffuse(reflectance=p.color("reflectance", 0.5, texture=True))
        elif t in ("conductor", "roughconductor"):
            kw: dict[str, Any] = {}
            material = p.string("material", "none")
            if p.has("eta") or p.has("k") or material == "none":
                if material != "none":
                    raise self.ctx.error(node, "give either 'material' or 'eta'/'k', not both", "material")
                kw["eta"] = p.color("eta", 0.0, kind="unbounded")
                kw["k"] = p.color("k", 1.0, kind="unbounded")
            else:
                try:
                    kw["eta"], kw["k"] = conductor_material(material)
                except GrisxError as exc:
                    raise self.ctx.error(p.values["material"], f"parameter 'material': {exc}", "material") from None
            kw["specular_reflectance"] = p.color("specular_reflectance", 1.0)
            rec = self._smooth_or_rough(p, t == "roughconductor", kw, Conductor, RoughConductor)
        elif t in ("plastic", "roughplastic"):
            diffuse = p.color("diffuse_reflectance", 0.5, texture=True)
            kw = {
                "diffuse_reflectance": diffuse,
                "diffuse_mean": self._texture_mean(p, "diffuse_reflectance", diffuse),
                "specular_reflectance": p.color("specular_reflectance", 1.0),
                "int_ior": p.ior("int_ior", "polypropylene"),
                "ext_ior": p.ior("ext_ior", "air"),
                "nonlinear": p.bool("nonlinear", False),
            }
            if t == "roughplastic" and (p.has("alpha_u") or p.has("alpha_v")):
                raise self.ctx.error(p.values.get("alpha_u", p.values.get("alpha_v")),
                                     "roughplastic does not support anisotropic roughness (alpha_u/alpha_v), as in Mitsuba 3; "
                                     "give one 'alpha'", "alpha_u" if p.has("alpha_u") else "alpha_v")
            rec = self._smooth_or_rough(p, t == "roughplastic", kw, Plastic, RoughPlastic)
        else:  # dielectric, roughdielectric, thindielectric
            kw = {
                "int_ior": p.ior("int_ior", "bk7"),
                "ext_ior": p.ior("ext_ior", "air"),
                "specular_reflectance": p.color("specular_reflectance", 1.0),
                "specular_transmittance": p.color("specular_transmittance", 1.0),
            }
            if t == "thindielectric":
                rec = ThinDielectric(**kw)
            else:
                rec = self._smooth_or_rough(p, t == "roughdielectric", kw, Dielectric, RoughDielectric)
        p.finish()
        try:  # validate values now (negative colours, alpha <= 0, equal IORs ...) so the error names this line
            pack_materials([rec], device="cpu")
        except GrisxError as exc:
            raise self.ctx.error(node, str(exc).replace("material 0 ", "", 1)) from None
        self.records[id(node)] = rec
        return rec

    # ---- principled (principled.cpp, principledthin.cpp constructors) ----

    #: lobe sampling rates each plugin reads, all 1 by default (principled.cpp reads clearcoat_sampling_rate with 1,
    #: though its documentation says 0)
    _PRINCIPLED_RATES = {
        "principled": ("main_specular_sampling_rate", "clearcoat_sampling_rate", "diffuse_reflectance_sampling_rate"),
        "principledthin": ("specular_reflectance_sampling_rate", "specular_transmittance_sampling_rate",
                           "diffuse_transmittance_sampling_rate", "diffuse_reflectance_sampling_rate"),
    }

    def _principled(self, p: _Props, t: str) -> Principled | PrincipledThin:
        """A ``principled`` or ``principledthin`` record: base_color an RGB or a texture, every weight a number or a
        texture (Mitsuba's ``get_texture``); non-default sampling rates and a textured ``eta`` are refused."""
        thin = t == "principledthin"
        for name in self._PRINCIPLED_RATES[t]:
            if p.has(name) and p.float(name) != 1.0:
                raise self.ctx.error(p.values[name], f"parameter '{name}' of {t}: sampling rates other than 1 are not "
                                                     f"supported (its pdf would need them in every kernel)", name)
        kw: dict[str, Any] = {"base_color": p.color("base_color", 0.5, texture=True)}
        weights = ["roughness", "anisotropic", "spec_trans", "spec_tint", "sheen", "sheen_tint", "flatness"]
        weights += ["diff_trans"] if thin else ["metallic", "clearcoat", "clearcoat_gloss"]
        for name in weights:
            if name not in p.values:
                continue
            node = p.values[name]
            kw[name] = self._uv_texture(p, name, attributes=True) if node.tag in ("texture", "ref") else p.float(name)
        if thin:
            if p.has("eta") and p.values["eta"].tag in ("texture", "ref"):
                raise self.ctx.error(p.values["eta"], "parameter 'eta' of principledthin: a textured eta is not supported "
                                                      "(give a number)", "eta")
            kw["eta"] = p.float("eta", 1.5)
            return PrincipledThin(**kw)
        if p.has("eta") and p.has("specular"):
            raise self.ctx.error(p.values["specular"], "give either 'eta' or 'specular', not both (as in Mitsuba 3)", "specular")
        if p.has("eta"):
            kw["eta"] = p.float("eta")
        elif p.has("specular"):
            kw["specular"] = p.float("specular")
        return Principled(**kw)

    def _texture_mean(self, p: _Props, name: str, value: Any) -> float | None:
        """Mitsuba's ``texture.mean()`` of parameter ``name`` (``None`` for a constant); a mesh attribute has none."""
        if not isinstance(value, TextureRef):
            return None
        if value.texture_id not in self.texture_means:
            raise self.ctx.error(p.values[name], f"parameter '{name}': this BSDF needs its texture's mean, which a "
                                                 f"mesh_attribute texture does not have (Mitsuba refuses it too)", name)
        return self.texture_means[value.texture_id]

    def _uv_texture(self, p: _Props, name: str, attributes: bool = False) -> TextureRef:
        """Texture parameter ``name`` of a mask, normalmap, bumpmap (looked up over uv, not a mesh attribute) or
        blendbsdf (``attributes``: a mesh attribute too)."""
        p.used.add(name)
        ref = self.texture_ref(p.values[name])
        if not attributes and ref.texture_id not in self.texture_means:
            raise self.ctx.error(p.values[name], f"parameter '{name}': a mesh_attribute texture is not supported here "
                                                 f"(only as a diffuse reflectance)", name)
        return ref

    def _two_sided(self, node: _Node, rec: Any) -> Any:
        """``rec`` with its front BSDF on both sides (through a mask, which is the same from either side)."""
        if isinstance(rec, Mask):
            return dataclasses.replace(rec, bsdf=self._two_sided(node, rec.bsdf))
        if isinstance(rec, (NormalMap, BumpMap)):
            raise self.ctx.error(node, "twosided around a normalmap or bumpmap is not supported (put the twosided inside it)")
        transmissive = isinstance(rec, PrincipledThin) or (isinstance(rec, Principled) and principled_has(rec, "spec_trans"))
        if isinstance(rec, (Dielectric, RoughDielectric, ThinDielectric)) or transmissive:
            raise self.ctx.error(node, "twosided cannot wrap a transmissive BSDF (as in Mitsuba)")
        if isinstance(rec, BlendBSDF):  # both blended BSDFs seen from either side
            return dataclasses.replace(rec, bsdf0=self._two_sided(node, rec.bsdf0), bsdf1=self._two_sided(node, rec.bsdf1))
        return dataclasses.replace(rec, two_sided=True)

    def _smooth_or_rough(self, p: _Props, rough: bool, kw: dict[str, Any], smooth: type, rough_cls: type) -> Any:
        if not rough:
            return smooth(**kw)
        distribution = p.choice("distribution", "beckmann", tuple(MICROFACET_DISTRIBUTIONS))  # Mitsuba's default
        kw["sample_visible"] = p.bool("sample_visible", True)  # a sampling choice: the expected image is the same
        if rough_cls in (RoughConductor, PolarizedPlastic) and (p.has("alpha_u") or p.has("alpha_v")):
            # microfacet.h: both alpha_u and alpha_v (numbers or textures), and then no alpha
            if not (p.has("alpha_u") and p.has("alpha_v")):
                given = "alpha_u" if p.has("alpha_u") else "alpha_v"
                raise self.ctx.error(p.values[given], "both 'alpha_u' and 'alpha_v' must be specified (as in Mitsuba 3)", given)
            if p.has("alpha"):
                raise self.ctx.error(p.values["alpha"], "give either 'alpha' or 'alpha_u'/'alpha_v', not both", "alpha")
            kw["alpha_u"], kw["alpha_v"] = (self._uv_texture(p, n) if p.values[n].tag in ("texture", "ref") else p.float(n)
                                            for n in ("alpha_u", "alpha_v"))
        elif p.has("alpha") and p.values["alpha"].tag in ("texture", "ref"):
            kw["alpha"] = self._uv_texture(p, "alpha")  # one texture for α_u and α_v (roughplastic: refused at packing)
        if "alpha" not in kw:
            kw["alpha"] = 0.1 if "alpha_u" in kw else p.float("alpha", 0.1)
        return rough_cls(distribution=distribution, **kw)

    def default_material(self, name: str) -> int:
        """Mitsuba's BSDF for a shape given none: diffuse 0.5, or diffuse 0 if the shape emits (``Shape::Shape``)."""
        if name not in self.default_materials:
            self.default_materials[name] = self.scene.add_material(Diffuse((0.0,) * 3 if name == "default_emitter" else (0.5,) * 3), name=name)
        return self.default_materials[name]

    def material_id(self, node: _Node) -> int:
        target = self._deref(node, "bsdf")
        if id(target) not in self.material_ids:
            rec = self.bsdf_record(target)
            self.material_ids[id(target)] = self.scene.add_material(rec, name=target.attrs.get("id"))
        return self.material_ids[id(target)]

    # -- shapes
    def shape(self, node: _Node) -> None:
        """A top-level ``<shape>``: one object of the scene, a ``shapegroup`` (read now, placed by instances) or
        an ``instance`` of one (its members flattened into world space, see :meth:`instance`)."""
        t = self._type(node)
        if t == "shapegroup":
            self.shapegroup(node)
        elif t == "instance":
            self.instance(node)
        else:
            self._add_shape(self.shape_part(node))

    def shapegroup(self, node: _Node) -> list[_ShapePart]:
        """Mitsuba's ``shapegroup``: its shapes, invisible on their own, read once (``Instance``s place copies).

        As in Mitsuba, a group holds shapes only — no emitters (``Instancing of emitters is not supported``), no
        nested groups or instances."""
        if id(node) in self.groups:
            return self.groups[id(node)]
        p = _Props(self, node)
        members = []
        for child in p.take_objects(("shape",)):
            if child.tag == "ref":
                raise self.ctx.error(child, "a shapegroup holds nested <shape>s, not references")
            if self._type(child) in ("shapegroup", "instance"):
                raise self.ctx.error(child, f"a {self._type(child)} inside a shapegroup (Mitsuba permits no nesting)", "type")
            part = self.shape_part(child)
            if part.emission is not None:
                raise self.ctx.error(child, "a shape inside a shapegroup cannot emit (Mitsuba does not instance emitters)")
            members.append(part)
        p.finish()
        if not members:
            raise self.ctx.error(node, "an empty shapegroup (it needs at least one nested <shape>)")
        self.groups[id(node)] = members
        return members

    def instance(self, node: _Node) -> None:
        """Mitsuba's ``instance``: a copy of a ``shapegroup``'s shapes placed by the instance's ``to_world``.

        grisx flattens it at load time: each member becomes a world-space mesh, or an analytic shape, with the
        transform ``to_world(instance) · to_world(member)`` (one triangle BVH, no instance level; an instanced
        sphere under a non-uniform instance scale is an ellipsoid, as in Mitsuba). What it costs: a mesh
        member's vertices, normals and uvs once per instance (about 100 bytes per vertex and 12 per triangle on
        the device, plus their BVH nodes), where Mitsuba stores them once. Orientation as Mitsuba's
        ``instance.cpp``: its normals are the member's normals under the instance transform, ``M⁻ᵀ n``, so a
        mirroring instance (det M < 0) keeps its members' front sides, where a mesh's winding alone would turn
        them (the winding is reversed to match) and where an analytic sphere or tube would read the mirror as
        "inside out" (its orientation is turned back).
        """
        p = _Props(self, node)
        to_world = p.transform("to_world")
        to_world = np.eye(4) if to_world is None else to_world
        groups = p.take_objects(("shape",))
        if len(groups) != 1:
            raise self.ctx.error(node, f"an instance needs exactly one <ref> to a shapegroup, got {len(groups)}")
        group = self._deref(groups[0], "shape")
        if self._type(group) != "shapegroup":
            raise self.ctx.error(groups[0], f"an instance takes a shapegroup, not a shape of type '{self._type(group)}'")
        p.finish()
        members = self.shapegroup(group)
        mirror = bool(np.linalg.det(to_world[:3, :3]) < 0)
        self.instance_count += 1
        for part in members:
            mesh, flip = part.mesh, part.flip_normals
            if mirror and mesh is not None:
                mesh = dataclasses.replace(mesh, faces=mesh.faces[:, [0, 2, 1]])
            elif mirror and part.kind in ("sphere", "cylinder"):
                flip = not flip  # analytic: sphere.cpp/cylinder.cpp turn a shape whose own to_world mirrors inside out;
                # under a mirroring instance Mitsuba keeps the member's orientation (a disk's normal is M⁻ᵀ z either way)
            self._add_shape(dataclasses.replace(part, mesh=mesh, flip_normals=flip, to_world=to_world @ part.to_world,
                                                name=f"{part.name}@instance{self.instance_count}", node=node))

    def _add_shape(self, part: _ShapePart) -> None:
        try:
            if part.mesh is None and part.emission is None:
                # intersected exactly, as Mitsuba does (grisx.scene.analytic); an emitter stays a mesh, since
                # next-event estimation samples points on triangles
                self.scene.add_shape(part.kind, material=part.material, to_world=part.to_world, flip_normals=part.flip_normals,
                                     name=part.name)
            else:
                mesh = part.mesh
                if mesh is None:  # an emitting sphere, disk or tube, tessellated: a mirrored sphere or tube is inside out
                    # (sphere.cpp, cylinder.cpp: as its winding), a disk's normal is to_world's inverse transpose of +z
                    mesh = {"sphere": shapes.sphere, "disk": shapes.disk, "cylinder": shapes.cylinder}[part.kind](flip_normals=part.flip_normals)
                    if part.kind == "disk":
                        mesh = shapes.finish_mesh(mesh, to_world=part.to_world)
                self.scene.add_mesh(mesh.vertices, mesh.faces, material=part.material, normals=mesh.normals, uvs=mesh.uvs,
                                    emission=part.emission, to_world=part.to_world, name=part.name, attributes=mesh.attributes)
        except GrisxError as exc:
            raise self.ctx.error(part.node, str(exc)) from None

    def shape_part(self, node: _Node) -> _ShapePart:
        """A ``<shape>`` read into a mesh, its ``to_world``, material and emission (not yet in the scene)."""
        t = self._require_type(node, _SHAPES)
        p = _Props(self, node)
        emitters = p.take_objects(("emitter",))
        if emitters and t in ("sdfgrid", "linearcurve", "bsplinecurve"):  # before the (costly) tessellation
            raise self.ctx.error(emitters[0], f"a {t} cannot be an area emitter here (Mitsuba's sdfgrid cannot either)")
        to_world = p.transform("to_world")
        to_world = np.eye(4) if to_world is None else to_world
        flip = p.bool("flip_normals", False)
        try:
            # a mirroring to_world: the front side stays where the normals point (shapes.finish_mesh)
            if t == "rectangle":  # rectangle.cpp: its normal is to_world's inverse transpose of +z, mirrored or not
                mesh = shapes.finish_mesh(shapes.rectangle(flip_normals=flip), to_world=to_world)
            elif t == "cube":  # a mesh in Mitsuba too: it takes face_normals, and keeps its (per-face) vertex normals
                p.bool("face_normals", False)  # anyway (cube.cpp sets them; a mesh shades with them where it has them)
                mesh = shapes.finish_mesh(shapes.cube(flip_normals=flip), to_world=to_world)
            elif t == "disk":
                mesh = None  # analytic, or tessellated below if it emits
            elif t == "sphere":
                center = p.point("center", (0.0, 0.0, 0.0))
                radius = p.float("radius", 1.0)
                # sphere.cpp: to_world · translate(center) · scale(radius); a negative radius turns it inside out
                to_world = to_world @ xf.translate(center) @ xf.scale(radius)
                to_world = self._sphere_similarity(node, to_world)
                mesh = None
            elif t == "cylinder":
                p0 = np.asarray(p.point("p0", (0.0, 0.0, 0.0)))
                p1 = np.asarray(p.point("p1", (0.0, 0.0, 1.0)))
                radius = p.float("radius", 1.0)
                length = float(np.linalg.norm(p1 - p0))
                if not (length > 0.0 and math.isfinite(length)) or not (radius > 0.0 and math.isfinite(radius)):
                    raise self.ctx.error(node, f"a cylinder needs p0 != p1 and a positive radius, got p0 {p0.tolist()}, "
                                               f"p1 {p1.tolist()}, radius {radius}")
                # cylinder.cpp: to_world · translate(p0) · to_frame(Frame3f(d / |d|)) · scale(radius, radius, |d|)
                to_world = to_world @ xf.translate(p0) @ xf.to_frame((p1 - p0) / length) @ xf.scale((radius, radius, length))
                mesh = None
            elif t in ("linearcurve", "bsplinecurve"):  # curves as a world-space mesh (grisx.scene.curves): radii ignore to_world
                if flip:
                    raise self.ctx.error(p.values["flip_normals"], f"Mitsuba's {t} takes no flip_normals", "flip_normals")
                if t == "bsplinecurve":
                    p.float("silhouette_sampling_weight", 1.0)  # a differentiable-rendering choice: no effect on the image
                    mesh = bspline_curve_mesh(read_curves(self.ctx.resolve(p.string("filename")), min_points=4), to_world)
                else:
                    mesh = linear_curve_mesh(read_curves(self.ctx.resolve(p.string("filename"))), to_world)
                to_world = np.eye(4)
            elif t == "sdfgrid":  # a fine mesh of the grid's zero set (grisx.scene.sdfgrid); no uv, no emission
                if flip:
                    raise self.ctx.error(p.values["flip_normals"], "Mitsuba's sdfgrid takes no flip_normals", "flip_normals")
                normals = p.choice("normals", "smooth", ("smooth", "analytic"))
                key = (str(self.ctx.resolve(p.string("filename"))), normals)
                if key not in self.sdf_meshes:  # a grid used twice is tessellated once
                    self.sdf_meshes[key] = sdfgrid_mesh(read_vol(key[0]), normals)
                mesh = shapes.finish_mesh(self.sdf_meshes[key], to_world=to_world)
            elif t == "serialized":
                filename = p.string("filename")
                index = p.int("shape_index", 0)
                if index < 0:
                    raise self.ctx.error(p.values["shape_index"], f"shape_index must be >= 0, got {index}", "shape_index")
                mesh = shapes.finish_mesh(load_serialized(self.ctx.resolve(filename), index),
                                          face_normals=p.bool("face_normals", False), flip_normals=flip, to_world=to_world)
            else:
                filename = p.string("filename")
                face_normals = p.bool("face_normals", False)
                flip_tex = p.bool("flip_tex_coords", t == "obj")  # Mitsuba: true for obj, false for ply
                suffix = Path(filename).suffix.lower()
                if suffix != "." + t:
                    raise self.ctx.error(p.values["filename"], f"a <shape type=\"{t}\"> needs a .{t} file, got '{filename}'", "filename")
                mesh = shapes.load_mesh(self.ctx.resolve(filename), face_normals=face_normals,
                                        flip_normals=flip, flip_tex_coords=flip_tex, to_world=to_world)
        except GrisxError as exc:
            if isinstance(exc, SceneFileError):
                raise
            raise self.ctx.error(node, str(exc)) from None
        bsdfs = p.take_objects(("bsdf",))
        if len(bsdfs) > 1:
            raise self.ctx.error(bsdfs[1], "a shape takes one BSDF")
        emission = None
        emitters = p.take_objects(("emitter",))
        if len(emitters) > 1:
            raise self.ctx.error(emitters[1], "a shape takes one emitter")
        if emitters:
            em = self._deref(emitters[0], "emitter")  # nested, or a top-level area emitter by reference
            if id(em) in self.area_emitters_used:
                raise self.ctx.error(emitters[0], f"the area emitter on line {em.line} is attached to two shapes")
            self.area_emitters_used.add(id(em))
            self._require_type(em, ("area",))
            ep = _Props(self, em)
            emission = ep.emission("radiance", None)  # a colour, or a bitmap looked up at the shape's uv
            ep.finish()
        if bsdfs:
            mid = self.material_id(bsdfs[0])
            if t in ("sphere", "disk", "cylinder") and emission is None \
                    and any(isinstance(w, (NormalMap, BumpMap)) for w in unwrap(self.scene.materials[mid])[1]):
                raise self.ctx.error(bsdfs[0], f"a normalmap or bumpmap on an analytic {t} is not supported "
                                               f"(its shading frame needs a mesh's uv parametrization: use an obj, ply or serialized mesh)")
            if t in ("sphere", "disk", "cylinder") and emission is None and is_anisotropic(self.scene.materials[mid]):
                inner = unwrap(self.scene.materials[mid])[0]
                what = "a principled BSDF with 'anisotropic'" if isinstance(inner, (Principled, PrincipledThin)) \
                    else f"an anisotropic {self._type(bsdfs[0])} (alpha_u != alpha_v)"
                raise self.ctx.error(bsdfs[0], f"{what} on an analytic {t} is not "
                                               f"supported (its tangent needs a mesh's uv parametrization: use an obj, ply or serialized mesh)")
        else:  # Mitsuba's default: diffuse 0.5, but black on an emitter (an emitting shape reflects nothing)
            mid = self.default_material("default_emitter" if emission is not None else "default")
        p.finish()
        self.shape_count += 1
        name = node.attrs.get("id") or f"{t}{self.shape_count}"
        return _ShapePart(t, mesh, to_world, mid, emission, name, node, flip)

    def _sphere_similarity(self, node: _Node, to_world: np.ndarray) -> np.ndarray:
        """What Mitsuba's ``sphere.cpp`` renders for ``to_world``: a sphere of centre M·0 and radius |M·x̂|. A
        non-uniform scale or a shear (an ellipsoid) is warned about there and here, and dropped alike: the
        rotation of M's polar decomposition is kept."""
        a = to_world[:3, :3]
        u, sv, vt = np.linalg.svd(a)
        if np.ptp(sv) <= 1e-6 * sv.max():
            return to_world
        warnings.warn(f"{self.ctx.where(node)} a sphere's to_world has a non-uniform scale or a shear: rendered, as "
                      f"Mitsuba renders it, as a sphere of radius |to_world·(1, 0, 0)|", GrisxWarning, stacklevel=2)
        rot = u @ vt  # the polar decomposition's orthogonal factor (a reflection stays one: it turns the sphere inside out)
        out = np.eye(4)
        out[:3, :3] = rot * float(np.linalg.norm(a[:, 0]))
        out[:3, 3] = to_world[:3, 3]
        return out

    # -- emitters outside shapes
    def emitter(self, node: _Node) -> None:
        t = self._type(node)
        if t == "area" and (node.attrs.get("id") is None or id(node) not in self.area_emitters_used):
            raise self.ctx.error(node, "an area emitter must be nested inside a <shape> or referenced by one", "type")
        if t == "area":
            return
        t = self._require_type(node, ("constant", "envmap", "point", "spot", "directional", "projector"))
        p = _Props(self, node)
        if t == "spot":  # a cone along the local +z of to_world (Mitsuba's spotlight)
            to_world = p.transform("to_world")
            m = np.eye(4) if to_world is None else to_world
            intensity = p.color("intensity", 1.0, kind="emission")
            texture = p.emission("texture", None) if p.has("texture") else None
            if texture is not None and not isinstance(texture, (np.ndarray, Bitmap)):
                raise self.ctx.error(p.values["texture"], "a spot's 'texture' must be a bitmap (Mitsuba: spatially varying)", "texture")
            cutoff = p.float("cutoff_angle", 20.0)
            beam = p.float("beam_width", cutoff * 0.75)
            if not (0.0 < cutoff <= 90.0) or not (0.0 <= beam <= cutoff):
                raise self.ctx.error(node, f"spot needs 0 < cutoff_angle <= 90 and 0 <= beam_width <= cutoff_angle, got {cutoff} and {beam}", "cutoff_angle")
            p.finish()
            try:
                if texture is not None:
                    rigid_frame(m, "a textured spot's to_world")
                self.scene.add_point_light(tuple(float(x) for x in m[:3, 3]), intensity, direction=tuple(float(x) for x in m[:3, 2]),
                                           cutoff_angle=cutoff, beam_width=beam, texture=texture, to_world=m)
            except GrisxError as exc:
                raise self.ctx.error(node, str(exc)) from None
            return
        if t == "directional":  # directional.cpp: along 'direction', or the local +z of to_world
            to_world = p.transform("to_world")
            if to_world is not None and p.has("direction"):
                raise self.ctx.error(node, "give either 'direction' or 'to_world', not both", "direction")
            direction = to_world[:3, 2] if to_world is not None else p.point("direction", (0.0, 0.0, 1.0))
            if p.has("irradiance") and p.values["irradiance"].tag in ("texture", "ref"):
                raise self.ctx.error(p.values["irradiance"], "a directional emitter's 'irradiance' cannot be a texture (as in Mitsuba)", "irradiance")
            irradiance = p.color("irradiance", 1.0, kind="emission")
            p.finish()
            try:
                self.scene.add_delta_light(DirectionalLight(direction=tuple(float(x) for x in direction), irradiance=irradiance))
            except GrisxError as exc:
                raise self.ctx.error(node, str(exc)) from None
            return
        if t == "projector":  # projector.cpp: a perspective camera run backwards
            to_world = p.transform("to_world")
            irradiance = p.emission("irradiance", 1.0)
            scale = p.float("scale", 1.0)
            fov, fov_axis = p.fov()
            p.finish()
            try:
                frame = rigid_frame(np.eye(4) if to_world is None else to_world, "a projector's to_world")
                self.scene.add_delta_light(Projector(to_world=frame, irradiance=irradiance, scale=scale, fov=fov, fov_axis=fov_axis))
            except GrisxError as exc:
                raise self.ctx.error(node, str(exc)) from None
            return
        if t == "point":
            to_world = p.transform("to_world")
            if to_world is not None and p.has("position"):
                raise self.ctx.error(node, "give either 'position' or 'to_world', not both", "position")
            pos = to_world[:3, 3] if to_world is not None else p.point("position", (0.0, 0.0, 0.0))
            intensity = p.color("intensity", 1.0, kind="emission")
            p.finish()
            try:
                self.scene.add_point_light(tuple(float(x) for x in pos), intensity)
            except GrisxError as exc:
                raise self.ctx.error(node, str(exc)) from None
            return
        if self.environment_seen is not None:
            raise self.ctx.error(node, f"only one environment emitter is allowed (first on line {self.environment_seen.line})")
        self.environment_seen = node
        if t == "constant":
            env: Any = ConstantEnvironment(radiance=p.color("radiance", 1.0, kind="emission"))
        else:
            filename = p.string("filename")
            scale = p.float("scale", 1.0)
            to_world = p.transform("to_world")
            p.bool("mis_compensation", False)  # a sampling choice: the expected image is the same
            try:
                image = load_envmap_image(self.ctx.resolve(filename))
            except GrisxError as exc:
                raise self.ctx.error(p.values["filename"], f"parameter 'filename': {exc}", "filename") from None
            env = EnvMap(image=image, scale=scale, to_world=np.eye(4) if to_world is None else to_world)
        p.finish()
        self.scene.set_environment(env)

    # -- sensor, film, sampler, integrator
    def sensor(self, node: _Node) -> None:
        if self.sensor_seen is not None:
            raise self.ctx.error(node, f"only one sensor is supported (first on line {self.sensor_seen.line})")
        self.sensor_seen = node
        t = self._require_type(node, ("perspective", "thinlens", "orthographic"))
        p = _Props(self, node)
        films = p.take_objects(("film",))
        samplers = p.take_objects(("sampler",))
        for group in (films, samplers):
            if len(group) > 1:
                raise self.ctx.error(group[1], f"a sensor takes one <{group[1].tag}>")
        if films:
            self.film(films[0])
        if samplers:
            self.sampler(samplers[0])
        to_world = p.transform("to_world")
        fov, fov_axis = p.fov() if t != "orthographic" else (Camera.fov, "x")  # an orthographic film has no fov
        near = p.float("near_clip", 1e-2)
        far = p.float("far_clip", 1e4)
        if not (0 < near < far):
            raise self.ctx.error(node, f"need 0 < near_clip < far_clip, got {near}, {far}", "near_clip")
        if t == "thinlens":
            aperture = p.float("aperture_radius")
            focus = p.float("focus_distance")
        elif t == "perspective":
            p.float("focus_distance", 0.0)  # no effect on a pinhole camera
            aperture, focus = 0.0, 0.0
        else:
            aperture, focus = 0.0, 0.0
        p.finish()
        try:
            cam = Camera(to_world=np.eye(4) if to_world is None else to_world, fov=fov, fov_axis=fov_axis,
                         near_clip=near, far_clip=far, aperture_radius=aperture, focus_distance=focus,
                         projection="orthographic" if t == "orthographic" else "perspective")
        except GrisxError as exc:
            raise self.ctx.error(node, str(exc)) from None
        self.scene.set_camera(cam)

    def film(self, node: _Node) -> None:
        node = self._deref(node, "film")
        self._require_type(node, ("hdrfilm",))
        p = _Props(self, node)
        width = p.int("width", 768)
        height = p.int("height", 576)
        for ignored in ("pixel_format", "component_format", "file_format"):
            if p.has(ignored):
                p.string(ignored)  # output encoding only
        if p.has("banner"):
            p.bool("banner", False)  # Mitsuba 0.x's logo in the output file; Mitsuba 3 ignores it too ("no banner in Mitsuba 3")
        filters = p.take_objects(("rfilter",))
        if len(filters) > 1:
            raise self.ctx.error(filters[1], "a film takes one <rfilter>")
        stddev, tent = 0.5, 0.0  # no <rfilter>: Mitsuba's default, a gaussian of standard deviation 0.5 px
        if filters:
            f = self._deref(filters[0], "rfilter")
            ft = self._require_type(f, ("box", "gaussian", "tent"))
            fp = _Props(self, f)
            stddev = fp.float("stddev", 0.5) if ft == "gaussian" else 0.0
            tent = fp.float("radius", 1.0) if ft == "tent" else 0.0
            fp.finish()
            if ft == "gaussian" and not (0 < stddev <= 64):
                raise self.ctx.error(fp.values.get("stddev", f), f"stddev must be in (0, 64] pixels, got {stddev}", "stddev")
            if ft == "tent" and not (0 < tent <= 64):
                raise self.ctx.error(fp.values.get("radius", f), f"radius must be in (0, 64] pixels, got {tent}", "radius")
        p.finish()
        try:
            self.scene.film = Film(width, height, filter_stddev=stddev, filter_tent=tent)
        except GrisxError as exc:
            raise self.ctx.error(node, str(exc)) from None

    def sampler(self, node: _Node) -> None:
        node = self._deref(node, "sampler")
        self._require_type(node, _SAMPLERS)
        p = _Props(self, node)
        spp = p.int("sample_count", 4)
        p.int("seed", 0)  # grisx seeds its own streams
        p.bool("jitter", True)  # stratified/ldsampler option: a sampling choice
        p.finish()
        if spp < 1:
            raise self.ctx.error(p.values.get("sample_count", node), f"sample_count must be >= 1, got {spp}", "sample_count")
        self.scene.defaults["spp"] = spp

    def integrator(self, node: _Node) -> None:
        """An integrator read as what it estimates: path tracing at its ``max_depth`` (see the module docstring)."""
        node = self._deref(node, "integrator")
        t = self._require_type(node, _PATH_INTEGRATORS + _DIRECT_INTEGRATORS + _WRAPPER_INTEGRATORS + tuple(_PT_ALIKE))
        p = _Props(self, node)
        if t in _WRAPPER_INTEGRATORS:  # moment / aov: the image channels are the nested integrator's
            if t == "aov":
                p.string("aovs", "")  # extra channels; grisx renders the image only
            inner = p.take_objects(("integrator",))
            p.finish()
            if len(inner) != 1:
                raise self.ctx.error(node, f"a {t} integrator needs exactly one nested integrator here, got {len(inner)}")
            self.integrator(inner[0])
            return
        if t in _DIRECT_INTEGRATORS:  # direct illumination = paths of two segments, sampled as the estimator likes
            for name in ("shading_samples", "emitter_samples", "bsdf_samples"):
                p.int(name, 1)
            max_depth, rr_depth = 2, 5
        else:
            max_depth = p.int("max_depth", -1)
            rr_depth = p.int("rr_depth", 5)
        if t == "ptracer":
            p.int("samples_per_pass", 0)  # a scheduling choice
        if t in _PT_ALIKE:
            for name in _PT_ALIKE[t]:
                if name in p.values:
                    p.used.add(name)  # the estimator's own sampling options: the expected image is the same
            warnings.warn(f"{self.ctx.where(node)} read as path tracing (pt) at max_depth {max_depth}: "
                          f"an unbiased estimator of the same image", GrisxWarning, stacklevel=2)
        if p.bool("hide_emitters", False):
            raise self.ctx.error(p.values["hide_emitters"], "hide_emitters=true is not supported", "hide_emitters")
        p.finish()
        if max_depth < -1:
            raise self.ctx.error(p.values.get("max_depth", node), f"max_depth must be -1 (unbounded) or >= 0, got {max_depth}", "max_depth")
        if rr_depth < 1:
            raise self.ctx.error(p.values.get("rr_depth", node), f"rr_depth must be >= 1, got {rr_depth}", "rr_depth")
        self.scene.defaults["max_depth"] = max_depth
        self.scene.defaults["rr_depth"] = rr_depth


_PATH_INTEGRATORS = ("path", "volpath", "ptracer")  # volpath without media is path; ptracer: the same image from the lights
_DIRECT_INTEGRATORS = ("direct",)
_WRAPPER_INTEGRATORS = ("moment", "aov")
#: unbiased estimators of the path-traced image (Mitsuba 3 and 0.x plugins), read as ``pt`` with a notice;
#: the names are the sampling options they take, which change no expected value
_PT_ALIKE: dict[str, tuple[str, ...]] = {
    "volpathmis": (),
    "prb": (),
    "prb_basic": (),
    "prbvolpath": (),
    "bdpt": ("light_image", "sample_direct"),
    "pssmlt": ("bidirectional", "direct_samples", "luminance_samples", "two_stage", "p_large"),
    "mlt": ("direct_samples", "luminance_samples", "two_stage", "bidirectional_mutation", "lens_perturbation",
            "multi_chain_perturbation", "caustic_perturbation", "manifold_perturbation", "lambda"),
    "erpt": ("direct_samples", "luminance_samples", "chain_length", "num_chains", "max_chains",
             "lens_perturbation", "multi_chain_perturbation", "caustic_perturbation", "manifold_perturbation", "lambda"),
}


def load_mitsuba(path_or_string: str | os.PathLike, params: dict[str, Any] | None = None) -> Scene:
    """Read a Mitsuba 3 scene (a file path, or XML text starting with ``<``) into a :class:`Scene`.

    ``params`` sets ``$name`` parameters (overriding ``<default>`` values).
    Raises :class:`~grisx.errors.SceneFileError` for anything malformed or
    outside the supported subset (module docstring), naming file, line,
    element and attribute.
    """
    if isinstance(path_or_string, str) and path_or_string.lstrip().startswith("<"):
        data = path_or_string.encode("utf-8")
        ctx = _Ctx(None, Path.cwd())
        name = "mitsuba"
    else:
        if not str(path_or_string).strip():
            raise GrisxError("the scene file path is empty (give a Mitsuba XML file, or XML text starting with '<')")
        path = Path(path_or_string)
        if path.is_dir():
            raise SceneFileError(f"'{path}' is a directory, not a scene file", path=str(path))
        if not path.is_file():
            raise SceneFileError(f"no such scene file '{path}'", path=str(path))
        data = path.read_bytes()
        ctx = _Ctx(str(path), path.resolve().parent)
        name = path.stem
    root = _parse_xml(data, ctx)
    _prepare(root, ctx, params)
    scene = Scene(name)
    scene.description = f"Mitsuba scene '{ctx.path or '<string>'}'"
    _Loader(root, ctx, scene).run()
    return scene
