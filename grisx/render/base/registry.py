"""The render-method registry: each renderer file declares its params and registers itself.

As in Mitsuba 3 (a plugin per file) and pbrt-v4 (``Create`` reading a parameter
dictionary), a renderer module ends with one :func:`register` call naming the
method, a one-line summary, the factory and its :class:`~grisx.params.Param`
list. A param's *default* is the renderer class's keyword default, read from its
constructor by :func:`renderer_params` (``Param(name, ..., doc)``), so each default
is written once; ``--param k=v`` values are parsed and range-checked by
:func:`method_params`, and a bad one is an error naming the render method.

:data:`PLUGINS` lists the renderer modules; :func:`load_plugins` imports them
(the driver does, once), which fills :data:`METHODS`. A new renderer adds its
module to :data:`PLUGINS`.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
from collections.abc import Callable, Mapping
from typing import Any

from grisx.errors import InvalidParameterError, UnknownNameError
from grisx.params import Param

__all__ = ["VOCABULARY", "SYNONYMS", "RenderContext", "RenderMethod", "METHODS", "PLUGINS", "register", "renderer_params", "create_renderer", "method_params", "load_plugins"]

#: The shared vocabulary: a param name that more than one method takes means the same thing in all
#: of them (``grisx methods M`` gives each method's own wording and default). New renderers use
#: these names; ``tests/test_vocabulary.py`` fails on a synonym of one of them.
VOCABULARY = {
    "max_depth": ("int", "longest path in segments from the camera, Mitsuba's meaning (-1 unbounded, 1 emitters, 2 direct light)"),
    "rr_depth": ("int", "depth from which Russian roulette may end paths (Mitsuba's rule)"),
    "jitter": ("bool", "a new camera sample per pixel and frame (the box filter pt estimates); false: pixel centres"),
    "temporal": ("bool", "reuse the previous frame's reservoirs (reprojected)"),
    "spatial": ("bool", "reuse neighbouring pixels' reservoirs"),
    "neighbors": ("int", "spatial neighbours per pixel and round"),
    "radius": ("float", "spatial reuse radius in pixels"),
    "history_cap": ("float", "cap on the confidence M a reused temporal reservoir brings"),
    "unbiased": ("bool", "false: the cheaper biased variant of the method's MIS/visibility (an ablation)"),
    "jacobian": ("bool", "false: shift Jacobians taken as 1 (the biased ablation)"),
    "max_jacobian": ("float", "reject shifts whose |J| exceeds this bound, counted the same way in the MIS (still unbiased); 0: never"),
    "candidates": ("int", "initial candidates per pixel and frame"),
    "shift": ("choice", "the shift map of path reuse: hybrid, reconnection or replay"),
    "spatial_rounds": ("int", "rounds of spatial reuse per frame"),
    "rough_threshold": ("float", "hybrid shift: vertices rougher than this may be reconnected"),
    "near_field": ("float", "hybrid shift: reconnection segments must be longer than this fraction of the scene radius"),
    "alpha": ("choice", "control-variate coefficient: heuristic (seed 002, Eq. 9), one, or the biased sample"),
    "difference_mis": ("choice", "MIS weights of the control variates' difference estimator (seed 002, Eq. 10-11)"),
    "temporal_cv": ("bool", "temporal control variates (seed 002, Eq. 6) on or off"),
    "spatial_cv": ("bool", "spatial control variates (seed 002, Eq. 8) on or off"),
    "light_candidates": ("int", "ReSTIR DI: initial light-sampled candidates per pixel"),
    "bsdf_candidates": ("int", "ReSTIR DI: initial BSDF-sampled candidates per pixel"),
    "reconstruction": ("choice", "gradient-domain methods: the screened Poisson reconstruction of the frame, l2 or l1 (grisx.poisson)"),
    "symmetric": ("bool", "gradient-domain methods: both pixels' base paths with MIS (seed 000, Eq. 3-4); false: the one-sided, biased Eq. 2"),
    "poisson_alpha": ("float", "gradient-domain methods: weight alpha of the primal term of the screened Poisson reconstruction"),
    "max_trials": ("int", "SMS: cap on Bernoulli trials per caustic solution (0 = unbounded; any cap loses energy)"),
    "chain": ("int", "SMS: most specular vertices of a caustic chain"),
    "inline_trials": ("int", "SMS: Bernoulli trials a solution runs in its sample pass before the rest run in a stage of their own (same result)"),
    "tiles": ("int", "SMS: N, the sample space cut into N x N tiles with 3 x 3 trust regions"),
    "prior": ("bool", "SMS: per-frame prior over tiles from presampled walks per pixel block"),
    "presamples": ("int", "SMS: unrestricted walks per pixel block, caster and frame that build the prior"),
    "block": ("int", "SMS: prior blocks are B x B pixels"),
    "direct": ("choice", "where direct light comes from: nee (the method's own paths) or restir-di (ReSTIR DI on the same G-buffer)"),
    "prefixes": ("int", "integration prefixes per pixel and frame, each connected to suffixes (seed 001, Eq. 23)"),
    "gather_k": ("int", "supporting prefixes (nearest in world space) whose suffixes each integration prefix borrows"),
    "roulette": ("bool", "Russian-roulette canonical suffix of the final gather (seed 001, Eq. 23); false: one per prefix"),
    "canonical_suffixes": ("int", "R: prefixes of the final gather that trace their canonical suffix under roulette, each weighted N/R"),
    "canonical": ("bool", "false: leave the canonical sample out of the MIS (biased: coverage lost, seed 001 Eq. 17)"),
}
#: names that mean one of the above and must not be used for it
SYNONYMS = {
    "max_bounces": "max_depth", "bounces": "max_depth", "depth": "max_depth", "rr_start": "rr_depth",
    "jacobian_max": "max_jacobian", "j_max": "max_jacobian", "temporal_cap": "history_cap", "m_cap": "history_cap",
    "neighbours": "neighbors", "num_neighbors": "neighbors", "spatial_radius": "radius", "use_jacobian": "jacobian",
    "jittered": "jitter", "pixel_jitter": "jitter", "num_candidates": "candidates",
    "poisson": "reconstruction", "norm": "reconstruction", "screening": "poisson_alpha",
}

#: the renderer modules, each of which registers its methods when imported
PLUGINS = ("grisx.render.views", "grisx.render.pt", "grisx.render.restir_di", "grisx.render.restir_gi", "grisx.render.restir_pt", "grisx.render.restcv", "grisx.render.decoupled", "grisx.render.area_restir", "grisx.render.gpt", "grisx.render.restir_gpt", "grisx.render.suffix_restir", "grisx.render.sms")


@dataclasses.dataclass
class RenderContext:
    """What a renderer is created with."""

    built: Any  # BuiltScene
    width: int
    height: int
    params: dict[str, Any]  # the method's params, resolved, plus "spp"
    seed: int
    timer: Any  # PassTimer
    method: str


@dataclasses.dataclass(frozen=True)
class RenderMethod:
    """A named renderer: ``factory(ctx: RenderContext)`` → object with ``render_frame(frame)``."""

    name: str
    summary: str
    factory: Callable[[RenderContext], Any]
    params: tuple[Param, ...] = ()
    kind: str = "radiance"  # "radiance" (linear RGB) or "debug" (a G-buffer view)
    #: the path tracer's max_depth whose image this method estimates (None: the scene's own)
    reference_max_depth: int | None = None
    #: whether ``spp`` (samples per pixel per frame) means anything to it; the others take one sample a frame
    uses_spp: bool = False

    def create(self, ctx: RenderContext) -> Any:
        return self.factory(ctx)


METHODS: dict[str, RenderMethod] = {}


def register(method: RenderMethod) -> RenderMethod:
    """Add ``method`` to :data:`METHODS` (a renderer module calls this once per method it offers)."""
    if method.name in METHODS and METHODS[method.name].factory is not method.factory:
        raise InvalidParameterError(f"render method '{method.name}' is registered twice")
    METHODS[method.name] = method
    return method


def renderer_params(cls: type, *params: Param) -> tuple[Param, ...]:
    """``params`` with each default taken from ``cls``'s constructor (write ``...`` as the default)."""
    signature = inspect.signature(cls.__init__).parameters
    out = []
    for p in params:
        if p.name not in signature:
            raise TypeError(f"{cls.__name__} has no keyword '{p.name}' for its declared param")
        out.append(dataclasses.replace(p, default=signature[p.name].default) if p.default is ... else p)
    return tuple(out)


def create_renderer(cls: type, ctx: RenderContext) -> Any:
    """``cls(built, width, height, seed=, timer=, **its registered params)``: the factory of most renderers."""
    names = {p.name for p in METHODS[ctx.method].params}
    return cls(ctx.built, ctx.width, ctx.height, seed=ctx.seed, timer=ctx.timer, **{k: v for k, v in ctx.params.items() if k in names})


def composed_direct(direct: str, max_depth: int) -> str:
    """The direct-light pass a renderer composes, given its path depth: ``direct`` itself, except that
    at ``max_depth=1`` (emitters seen directly, no direct light) ReSTIR DI — whose image is the path
    tracer's at depth 2 — has nothing to add: the renderer's own NEE, which adds nothing there, stands."""
    return "nee" if max_depth == 1 else direct


def load_plugins() -> dict[str, RenderMethod]:
    """Import every module of :data:`PLUGINS` (each registers its methods) and return :data:`METHODS`."""
    for module in PLUGINS:
        importlib.import_module(module)
    return METHODS


def method_params(method: str, params: Mapping[str, Any] | None) -> dict[str, Any]:
    """Defaults of ``method`` merged with ``params``, parsed and range-checked."""
    if method not in METHODS:
        raise UnknownNameError("render method", method, sorted(METHODS))
    m = METHODS[method]
    known = {p.name: p for p in m.params}
    out = {name: p.default for name, p in known.items()}
    for key, value in (params or {}).items():
        if key not in known:
            raise UnknownNameError(f"param of render method '{method}'", key, sorted(known))
        out[key] = known[key].parse(value, f"render method '{method}'")
    return out
