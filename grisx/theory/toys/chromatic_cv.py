"""``chromatic-cv``: colour noise of ReSTIR and its cure by spatio-temporal control variates (seed 002).

A size × size grid of pixels looks at a diffuse plane lit by two lights on a
line above it, a red one centred at x = ¼ and a green one at x = ¾, each of
width w = ``light_width`` (seed 002, Fig. 2; w = ½ makes them touch and fill
the light domain). Pixel i at horizontal position a_i and "height" h_i
integrates over the light coordinate x ∈ [0, 1) the RGB function

    f_i(x) = ρ_i ⊙ L(x) · G_i(x),   G_i(x) = h_i² / ((x − a_i)² + h_i²),
    L(x) = L_red on |x − ¼| < w/2,  L_green on |x − ¾| < w/2,  0 elsewhere,

with a textured albedo ρ_i (tiles with sharp edges, a disc and a bar), so

    F_i = ρ_i ⊙ Σ_{lights (c, L)} L h_i [atan((c + w/2 − a_i)/h_i) − atan((c − w/2 − a_i)/h_i)]   (exact)

Pixels near the middle should be yellow, yet every single light sample is
either red or green. The scene is static over ``frames`` frames; the reported
estimate is the **last frame's image**, components = pixels × 3 (RGB,
row-major: ``(y·size + x)·3 + c``). One trial renders all frames of the whole
grid. Candidates are uniform on [0, 1) (p = 1); every frame draws
``candidates`` of them per pixel.

Methods (all share the passes below; the core lives in
:mod:`grisx.theory.control_variate`, :mod:`~grisx.theory.reservoir`,
:mod:`~grisx.theory.gris` and :mod:`~grisx.theory.mis`):

``mc``         Σ f(x)/(C p(x)) over the frame's C samples.
``restir``     RIS with the luminance target p̂_i = lum(f_i) (seed 000, Eq. 6),
               temporal reuse of the pixel's previous reservoir, spatial reuse
               of ``neighbors`` random pixels within ``radius`` (GRIS, identity
               shift, generalized balance MIS with confidences, M capped at 20),
               shading f_i(Y)W_Y (Listing 1 line 45).
``decoupled``  ``restir``'s passes, shaded with every candidate of the temporal
               and spatial pass, Σ w f/p̂ (Wyman & Panteleev 2021), composited
               by candidate counts.
``icv``        image-space CV (seed 002, Eq. 3; Rousselle et al. 2016) on each
               frame alone: ⟨F_i⟩_{←j} = α_ij ⟨F_j⟩_MC + ⟨F_i − α_ij F_j⟩ with the
               direct MC difference of Eq. 4–5 from both pixels' samples.
``stcv``       Eq. 6 (temporal, q_init = 1, q_prev = M) then Eq. 8 (spatial),
               differences by Eq. 4–5 (direct MC).
``restcv``     ``restir`` with Listing 1: the reservoir carries F; each pass forms
               α_ij F_j + Eq. 10's difference from the two reservoir samples with
               Eq. 11's MIS weights, composited with q_j = M_j (≤ 20); shading
               returns F.

``alpha`` chooses Eq. 9's heuristic α_ij = min(ρ_i/ρ_j, 2) or α = 1 (Fig. 3's
ablation). ``difference_mis`` picks Eq. 11's weights for ``restcv``:
``confidence`` (Eq. 11), ``balance`` (Eq. 11 with M = 1; still unbiased) or
``none`` (ω = 1 on both sides; biased: each pair's difference is counted twice).

Run statistics (``Estimate.stats``, the JSON's ``stats``) of the CV methods:
difference samples used with a neighbour per pixel and frame, and the
fraction of them that lie on a light with W > 0 — the "valid samples" of
seed 002, Sec. 6.1 (uniform samples hit a light with probability 2w; most
reservoir samples do).

Shifts between pixels are the identity on the shared light domain (|J| = 1),
and the temporal neighbour of pixel i is pixel i of the previous frame (a
static scene with a still camera). In ``stcv`` the temporal difference of
Eq. 4 takes the current frame's samples for both sides: its two terms only
need X_i ~ p_i and X_j ~ p_j marginally, and p_j = p_i here.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import warp as wp

from grisx.device import resolve_device, synchronize
from grisx.errors import InvalidParameterError
from grisx.theory.control_variate import (
    ALPHA_MODES,
    DIFFERENCE_MIS,
    Q_CAP,
    Q_INIT,
    compositing_weight,
    cv_alpha,
    cv_composite_add,
    cv_composite_empty,
    cv_composite_value,
    cv_estimate,
    decoupled_contribution,
    difference_estimate,
    difference_sample,
    luminance,
    mc_contribution,
    reservoir_difference,
)
from grisx.theory.gris import resampling_weight, ris_weight, ucw_from_source_pdf
from grisx.theory.mis import MIS_BALANCE, mis_weight, two_domain_balance
from grisx.theory.random import random_key, random_subkey, random_uniform
from grisx.theory.reservoir import (
    Reservoir,
    confidence_capped,
    reservoir_empty,
    reservoir_finalize,
    reservoir_update,
)
from grisx.theory.toys.base import BiasedVariant, Method, Param, ToyProblem, TrialBatch
from grisx.theory.toys.domains import interval_pdf, sample_interval

# grisx never differentiates through its kernels: skip adjoint code (halves compile time)
wp.set_module_options({"enable_backward": False})

__all__ = ["ChromaticCV", "ChromaticSpec", "chromatic_layout", "chromatic_exact", "METHOD_IDS", "DIFFERENCE_MIS"]

#: method name → kernel switch
METHOD_IDS = {"mc": 0, "restir": 1, "decoupled": 2, "icv": 3, "stcv": 4, "restcv": 5}
_MC = wp.constant(0)
_RESTIR = wp.constant(1)
_DECOUPLED = wp.constant(2)
_ICV = wp.constant(3)
_STCV = wp.constant(4)
_RESTCV = wp.constant(5)

#: Eq. 11's weights for restcv: confidence-weighted, unit-confidence, or none (biased)

#: colours of the two halves of the strip light (seed 002, Fig. 2: red and green)
LIGHT_RED = (1.0, 0.08, 0.03)
LIGHT_GREEN = (0.06, 0.9, 0.1)
_L_RED = wp.constant(wp.vec3(*LIGHT_RED))
_L_GREEN = wp.constant(wp.vec3(*LIGHT_GREEN))
_PALETTE = np.array(
    [
        [0.80, 0.80, 0.80],  # white plaster
        [0.90, 0.40, 0.20],  # orange tiles
        [0.25, 0.50, 0.90],  # blue disc
        [0.45, 0.85, 0.30],  # green bar
    ]
)

_PASS_TEMPORAL = wp.constant(1)
_PASS_NEIGHBOURS = wp.constant(2)
_PASS_SPATIAL = wp.constant(3)


@wp.struct
class ChromaticSpec:
    width: int
    light_width: float
    albedo: wp.array(dtype=wp.vec3)
    position: wp.array(dtype=float)
    height: wp.array(dtype=float)


@wp.struct
class ImageState:
    """Per trial and pixel: a reservoir, its sample y and its colour estimate F (Listing 1's Reservoir)."""

    res: wp.array2d(dtype=Reservoir)
    y: wp.array2d(dtype=float)
    colour: wp.array2d(dtype=wp.vec3)


@wp.struct
class PassInputs:
    """The inputs of one reuse pass of one pixel, gathered per trial: l = 0 is the pixel itself.

    ``pixel`` names each input's pixel; ``confidence`` and ``target_from`` are
    the rows that :func:`~grisx.theory.mis.mis_weight` reads.
    """

    res: wp.array2d(dtype=Reservoir)
    y: wp.array2d(dtype=float)
    colour: wp.array2d(dtype=wp.vec3)
    pixel: wp.array2d(dtype=int)
    confidence: wp.array2d(dtype=float)
    target_from: wp.array2d(dtype=float)


@wp.struct
class PassResult:
    """What a reuse pass leaves in pixel i: reservoir, its sample, its colour estimate F."""

    res: Reservoir
    y: float
    colour: wp.vec3
    sides: float  # difference-estimate samples used with a neighbour (stats)
    on_light: float  # … of which lie on a light with a non-zero weight


@wp.func
def chromatic_integrand(spec: ChromaticSpec, i: int, x: float) -> wp.vec3:
    """f_i(x) = ρ_i ⊙ L(x) G_i(x) on x ∈ [0, 1)."""
    half = 0.5 * spec.light_width
    light = wp.vec3(0.0, 0.0, 0.0)
    if wp.abs(x - 0.25) < half:
        light = _L_RED
    if wp.abs(x - 0.75) < half:
        light = _L_GREEN
    d = x - spec.position[i]
    h = spec.height[i]
    return wp.cw_mul(spec.albedo[i], light) * (h * h / (d * d + h * h))


@wp.func
def chromatic_target(spec: ChromaticSpec, i: int, x: float) -> float:
    """ReSTIR's scalar target p̂_i = lum(f_i) (seed 002, Sec. 4)."""
    return luminance(chromatic_integrand(spec, i, x))


@wp.func
def _on_light(spec: ChromaticSpec, x: float, ucw: float) -> float:
    # 1 for a difference sample that can carry information: it lies on a light and has W > 0
    if ucw > 0.0 and (wp.abs(x - 0.25) < 0.5 * spec.light_width or wp.abs(x - 0.75) < 0.5 * spec.light_width):
        return 1.0
    return 0.0


@wp.func
def _direct_difference(spec: ChromaticSpec, t: int, i: int, j: int, xs: wp.array2d(dtype=float), candidates: int, alpha: wp.vec3) -> wp.vec3:
    # ⟨F_i − α F_j⟩ by Eq. 4 with the frame's fresh samples, W = 1/p, Eq. 5's balance weights
    out = wp.vec3(0.0, 0.0, 0.0)
    p = interval_pdf(0.0, 1.0)
    for c in range(candidates):
        x_i = xs[t, i * candidates + c]
        x_j = xs[t, j * candidates + c]
        s_i = difference_sample(two_domain_balance(1.0, p, 1.0, p), ucw_from_source_pdf(p), chromatic_integrand(spec, i, x_i), chromatic_integrand(spec, j, x_i), 1.0)
        s_j = difference_sample(two_domain_balance(1.0, p, 1.0, p), ucw_from_source_pdf(p), chromatic_integrand(spec, j, x_j), chromatic_integrand(spec, i, x_j), 1.0)
        out = out + difference_estimate(s_i, s_j, alpha)
    return out / float(candidates)


@wp.func
def _reservoir_difference(
    spec: ChromaticSpec, i: int, j: int, r_i: Reservoir, y_i: float, r_j: Reservoir, y_j: float, alpha: wp.vec3, dmis: int
) -> wp.vec3:
    # ⟨F_i − α F_j⟩ by Eq. 10 from the reservoirs' samples; T_{i→j} = identity, |J| = 1.
    # The targets are the luminances of the four integrand values Eq. 10 needs anyway.
    f_i_yi = chromatic_integrand(spec, i, y_i)
    f_j_yi = chromatic_integrand(spec, j, y_i)
    f_j_yj = chromatic_integrand(spec, j, y_j)
    f_i_yj = chromatic_integrand(spec, i, y_j)
    return reservoir_difference(r_i, r_j, f_i_yi, f_j_yi, f_j_yj, f_i_yj, 1.0, 1.0, alpha, dmis)  # Eq. 10–11


@wp.func
def _reuse_pass(
    spec: ChromaticSpec,
    t: int,
    i: int,
    domains: int,
    method: int,
    candidates: int,
    alpha_mode: int,
    dmis: int,
    key: wp.uint32,
    g: PassInputs,
    xs: wp.array2d(dtype=float),
) -> PassResult:
    # One reuse pass of pixel i over the gathered inputs l = 0 … domains−1
    # (l = 0 is pixel i's own input: the canonical domain). Listing 1, ReusePass.
    for l in range(g.confidence.shape[1]):
        # rows are sized for the spatial pass; unused entries get confidence 0, which
        # takes them out of the balance heuristic's sums
        g.confidence[t, l] = 0.0
        g.target_from[t, l] = 0.0
        if l < domains:
            g.confidence[t, l] = g.res[t, l].confidence
    r = reservoir_empty()
    y = float(0.0)
    composite = cv_composite_empty()
    decoupled = wp.vec3(0.0, 0.0, 0.0)
    sides = float(0.0)
    on_light = float(0.0)
    r_i = g.res[t, 0]
    y_i = g.y[t, 0]
    for l in range(domains):
        j = g.pixel[t, l]
        r_j = g.res[t, l]
        y_j = g.y[t, l]
        # ---- control variates: ⟨F_i⟩_{←j} = α_ij F_j + ⟨F_i − α_ij F_j⟩ (Eq. 7), weight q_j = M_j (Eq. 6, 8) ----
        if method == _ICV or method == _STCV or method == _RESTCV:
            alpha = cv_alpha(alpha_mode, spec.albedo[i], spec.albedo[j])
            diff = wp.vec3(0.0, 0.0, 0.0)
            if method == _RESTCV:
                diff = _reservoir_difference(spec, i, j, r_i, y_i, r_j, y_j, alpha, dmis)
                if l > 0:
                    sides += 2.0
                    on_light += _on_light(spec, y_i, r_i.ucw) + _on_light(spec, y_j, r_j.ucw)
            else:
                diff = _direct_difference(spec, t, i, j, xs, candidates, alpha)
                if l > 0:
                    for c in range(candidates):
                        sides += 2.0
                        on_light += _on_light(spec, xs[t, i * candidates + c], 1.0) + _on_light(spec, xs[t, j * candidates + c], 1.0)
            composite = cv_composite_add(composite, cv_estimate(g.colour[t, l], alpha, diff), compositing_weight(r_j.confidence))
        # ---- GRIS resampling (seed 000, Eq. 9): shift T_{j→i} = identity, |J| = 1 ----
        w = float(0.0)
        p_hat = float(0.0)
        if method != _ICV and method != _STCV and r_j.ucw > 0.0:
            for m in range(domains):
                g.target_from[t, m] = chromatic_target(spec, g.pixel[t, m], y_j)  # p̂_{←m}(z), identity shift
            p_hat = g.target_from[t, 0]
            w = resampling_weight(mis_weight(MIS_BALANCE, l, 0, g.confidence[t], g.target_from[t]), p_hat, r_j.ucw, 1.0)
            if method == _DECOUPLED:
                decoupled = decoupled + decoupled_contribution(w, p_hat, chromatic_integrand(spec, i, y_j))
        r = reservoir_update(r, w, p_hat, r_j.confidence, random_uniform(key, l))
        if r.selected:
            y = y_j
    out = PassResult()
    r = reservoir_finalize(r)
    r.confidence = confidence_capped(r.confidence, Q_CAP)
    out.res = r
    out.y = y
    out.colour = decoupled
    out.sides = sides
    out.on_light = on_light
    if method == _ICV or method == _STCV or method == _RESTCV:
        out.colour = cv_composite_value(composite)  # Listing 1, line 29
    return out


@wp.func
def _gather(t: int, l: int, src: ImageState, pixel: int, g: PassInputs):
    g.res[t, l] = src.res[t, pixel]
    g.y[t, l] = src.y[t, pixel]
    g.colour[t, l] = src.colour[t, pixel]
    g.pixel[t, l] = pixel


@wp.func
def _store(t: int, i: int, dst: ImageState, res: Reservoir, y: float, colour: wp.vec3):
    dst.res[t, i] = res
    dst.y[t, i] = y
    dst.colour[t, i] = colour


@wp.func
def _mirror(v: int, n: int) -> int:
    if v < 0:
        return -v
    if v >= n:
        return 2 * (n - 1) - v
    return v


@wp.kernel(enable_backward=False)
def chromatic_cv_kernel(
    spec: ChromaticSpec,
    method: int,
    frames: int,
    candidates: int,
    neighbors: int,
    radius: int,
    alpha_mode: int,
    dmis: int,
    seed: int,
    first_trial: int,
    initial: ImageState,
    final: ImageState,
    temporal_out: ImageState,
    xs: wp.array2d(dtype=float),
    g: PassInputs,
    values: wp.array2d(dtype=float),
    counters: wp.array2d(dtype=float),
):
    # ``initial``: this frame's initial reservoirs; ``temporal_out``: after temporal reuse;
    # ``final``: after spatial reuse — the previous frame's result during temporal reuse
    t = wp.tid()
    key = random_key(seed, first_trial + t)
    pixels = spec.albedo.shape[0]
    width = spec.width
    side = 2 * radius + 1
    inv_c = 1.0 / float(candidates)
    p = interval_pdf(0.0, 1.0)
    temporal = method == _RESTIR or method == _DECOUPLED or method == _STCV or method == _RESTCV
    sides = float(0.0)
    on_light = float(0.0)
    for frame in range(frames):
        fkey = random_subkey(key, frame)
        # ---- initial sampling: C candidates, RIS on p̂ = lum(f), F_init = MC (Listing 1, lines 35–36) ----
        for i in range(pixels):
            r = reservoir_empty()
            y = float(0.0)
            colour = wp.vec3(0.0, 0.0, 0.0)
            for c in range(candidates):
                counter = 2 * (i * candidates + c)
                x = sample_interval(random_uniform(fkey, counter), 0.0, 1.0)
                f = chromatic_integrand(spec, i, x)
                p_hat = luminance(f)
                r = reservoir_update(r, ris_weight(inv_c, p_hat, p), p_hat, 0.0, random_uniform(fkey, counter + 1))
                if r.selected:
                    y = x
                colour = colour + mc_contribution(f, p, candidates)
                xs[t, i * candidates + c] = x
            r = reservoir_finalize(r)
            r.confidence = Q_INIT  # one frame's initial reservoir: M = q_init = 1
            _store(t, i, initial, r, y, colour)
        if method == _MC:
            continue
        # ---- temporal reuse: pixel i of the previous frame (Eq. 6; Listing 1, lines 37–39) ----
        tkey = random_subkey(fkey, _PASS_TEMPORAL)
        for i in range(pixels):
            if temporal and frame > 0:
                _gather(t, 0, initial, i, g)
                _gather(t, 1, final, i, g)
                out = _reuse_pass(spec, t, i, 2, method, candidates, alpha_mode, dmis, random_subkey(tkey, i), g, xs)
                sides += out.sides
                on_light += out.on_light
                _store(t, i, temporal_out, out.res, out.y, out.colour)
            else:
                _store(t, i, temporal_out, initial.res[t, i], initial.y[t, i], initial.colour[t, i])
        # ---- spatial reuse: i and `neighbors` random pixels within `radius` (Eq. 8; Listing 1, lines 40–42) ----
        nkey = random_subkey(fkey, _PASS_NEIGHBOURS)
        skey = random_subkey(fkey, _PASS_SPATIAL)
        for i in range(pixels):
            _gather(t, 0, temporal_out, i, g)
            px = i % width
            py = i // width
            for n in range(neighbors):
                # a uniform offset in the (2R+1)² window without its centre, mirrored at the borders
                o = int(random_uniform(nkey, i * neighbors + n) * float(side * side - 1))
                if o >= (side * side - 1) // 2:
                    o = o + 1
                qx = _mirror(px + o % side - radius, width)
                qy = _mirror(py + o // side - radius, width)
                _gather(t, n + 1, temporal_out, qy * width + qx, g)
            out = _reuse_pass(spec, t, i, neighbors + 1, method, candidates, alpha_mode, dmis, random_subkey(skey, i), g, xs)
            sides += out.sides
            on_light += out.on_light
            colour = out.colour
            if method == _DECOUPLED:
                # every candidate seen in reuse: the temporal pass's (2, or the C initial ones
                # in frame 0) and the spatial pass's, weighted by their counts
                before = float(candidates)
                if frame > 0:
                    before = 2.0
                both = cv_composite_add(cv_composite_empty(), temporal_out.colour[t, i], before)
                both = cv_composite_add(both, out.colour, float(neighbors + 1))
                colour = cv_composite_value(both)
            _store(t, i, final, out.res, out.y, colour)
    # ---- shading of the last frame (Listing 1, lines 43–45) ----
    for i in range(pixels):
        colour = final.colour[t, i]
        if method == _MC:
            colour = initial.colour[t, i]
        if method == _RESTIR:
            colour = chromatic_integrand(spec, i, final.y[t, i]) * final.res[t, i].ucw
        for ch in range(3):
            values[t, i * 3 + ch] = colour[ch]
    if counters.shape[1] == 2:
        counters[t, 0] = sides
        counters[t, 1] = on_light


# ---- host side: scene layout, exact values, the problem ------------------------------


def chromatic_layout(size: int) -> dict[str, np.ndarray]:
    """Per-pixel albedo ρ (P × 3), horizontal position a and height h of the size × size grid."""
    py, px = np.divmod(np.arange(size * size), size)
    u = (px + 0.5) / size
    v = (py + 0.5) / size
    tile = max(2, size // 4)
    index = (px // tile + py // tile) % 2  # white / orange checker
    index = np.where((u - 0.62) ** 2 + (v - 0.4) ** 2 < 0.22**2, 2, index)  # blue disc
    index = np.where((v > 0.72) & (v < 0.86) & (u > 0.1), 3, index)  # green bar
    return {"albedo": _PALETTE[index], "position": u, "height": 0.2 + 0.3 * v}


def chromatic_exact(size: int, light_width: float = 0.5) -> np.ndarray:
    """F_i per pixel and channel (P × 3) in float64, from the closed form in the module docstring."""
    lay = chromatic_layout(size)
    a, h = lay["position"], lay["height"]

    def segment(centre: float) -> np.ndarray:
        lo, hi = centre - 0.5 * light_width, centre + 0.5 * light_width
        return h * (np.arctan((hi - a) / h) - np.arctan((lo - a) / h))

    red = segment(0.25)
    green = segment(0.75)
    light = red[:, None] * np.array(LIGHT_RED) + green[:, None] * np.array(LIGHT_GREEN)
    return lay["albedo"] * light


_COMMON = ("size", "frames", "candidates", "light_width")
_REUSE = ("neighbors", "radius")


class ChromaticCV(ToyProblem):
    name = "chromatic-cv"
    summary = "RGB pixels under a red and a green light over T static frames: ReSTIR's colour noise against spatio-temporal control variates (seed 002)"
    params = (
        Param("size", 16, "grid width = height in pixels", kind="int", minimum=2, maximum=64),
        Param("frames", 4, "static frames T; the last frame's image is the estimate", kind="int", minimum=1, maximum=64),
        Param("candidates", 2, "light samples (initial candidates) C per pixel and frame", kind="int", minimum=1, maximum=64),
        Param("light_width", 0.1, "width of each light (centred at ¼ and ¾ of [0, 1)): 0.5 fills the domain, smaller ones leave it dark between", minimum=0.01, maximum=0.5),
        Param("neighbors", 3, "random spatial neighbours per pixel and frame", kind="int", minimum=1, maximum=8),
        Param("radius", 2, "spatial neighbours come from the (2R+1)² window", kind="int", minimum=1, maximum=8),
        Param("alpha", "heuristic", "CV coefficient: Eq. 9's min(ρ_i/ρ_j, 2) or 1", kind="choice", choices=tuple(ALPHA_MODES)),
        Param(
            "difference_mis",
            "confidence",
            "Eq. 11's MIS weights: confidence (Eq. 11), balance (M = 1), none (ω = 1: biased)",
            kind="choice",
            choices=tuple(DIFFERENCE_MIS),
        ),
    )
    methods = (
        Method("mc", "Σ f/(C p) over the frame's C uniform light samples", _COMMON),
        Method("restir", "RIS on lum(f), temporal + spatial GRIS, shading f(Y)W_Y", _COMMON + _REUSE),
        Method("decoupled", "restir's passes, shaded with every reuse candidate (Wyman & Panteleev 2021)", _COMMON + _REUSE),
        Method("icv", "image-space CV per frame (Eq. 3) with direct MC differences (Eq. 4–5)", _COMMON + _REUSE + ("alpha",)),
        Method("stcv", "spatio-temporal CV (Eq. 6–8) with direct MC differences (Eq. 4–5)", _COMMON + _REUSE + ("alpha",)),
        Method(
            "restcv",
            "ReSTIR carrying F (Listing 1): differences from reservoir samples (Eq. 10–11), q_j = M_j ≤ 20",
            _COMMON + _REUSE + ("alpha", "difference_mis"),
        ),
    )
    biased_variants = (
        BiasedVariant(
            "restcv",
            {"difference_mis": "none"},
            "ω = 1 on both sides of Eq. 10: each pair's difference F_i − α F_j is counted twice",
        ),
    )
    chunk_trials = 8192  # ≈ 30 KB of per-trial scratch at 16×16 pixels, C = 2

    def __init__(self) -> None:
        self._scratch_key: tuple[Any, ...] | None = None
        self._scratch: list[wp.array] = []

    def components(self, params: Mapping[str, Any]) -> int:
        return int(params["size"]) ** 2 * 3

    def check_params(self, method: str, params: dict[str, Any]) -> None:
        if "radius" in params:
            if params["radius"] >= params["size"]:
                raise InvalidParameterError(f"param 'radius' of toy '{self.name}' must be below size ({params['size']}), got {params['radius']}")

    def exact(self, params: Mapping[str, Any]) -> np.ndarray:
        return chromatic_exact(int(params["size"]), float(params["light_width"])).ravel()

    def kernels(self) -> list[Any]:
        return [chromatic_cv_kernel]

    def spec(self, size: int, light_width: float, device: Any) -> ChromaticSpec:
        lay = chromatic_layout(size)
        s = ChromaticSpec()
        s.width = size
        s.light_width = light_width
        s.albedo = wp.array(lay["albedo"].astype(np.float32), dtype=wp.vec3, device=device)
        s.position = wp.array(lay["position"].astype(np.float32), dtype=float, device=device)
        s.height = wp.array(lay["height"].astype(np.float32), dtype=float, device=device)
        return s

    def _buffers(self, trials: int, pixels: int, candidates: int, domains: int, device: Any) -> list[Any]:
        """Scratch of one chunk: initial, final and temporal_out images, the samples xs, the pass inputs."""
        key = (trials, pixels, candidates, domains, str(device))
        if key != self._scratch_key:

            def image() -> ImageState:
                s = ImageState()
                s.res = wp.zeros((trials, pixels), dtype=Reservoir, device=device)
                s.y = wp.zeros((trials, pixels), dtype=float, device=device)
                s.colour = wp.zeros((trials, pixels), dtype=wp.vec3, device=device)
                return s

            g = PassInputs()
            g.res = wp.zeros((trials, domains), dtype=Reservoir, device=device)
            g.y = wp.zeros((trials, domains), dtype=float, device=device)
            g.colour = wp.zeros((trials, domains), dtype=wp.vec3, device=device)
            g.pixel = wp.zeros((trials, domains), dtype=int, device=device)
            g.confidence = wp.zeros((trials, domains), dtype=float, device=device)
            g.target_from = wp.zeros((trials, domains), dtype=float, device=device)
            self._scratch = [image(), image(), image(), wp.zeros((trials, pixels * candidates), dtype=float, device=device), g]
            self._scratch_key = key
        return self._scratch

    def launch(self, method: str, params: Mapping[str, Any], seed: int, first_trial: int, batch: TrialBatch, device: Any) -> None:
        n = batch.values.shape[0]
        size = int(params["size"])
        candidates = int(params["candidates"])
        neighbors = int(params.get("neighbors", 1))
        buffers = self._buffers(n, size * size, candidates, neighbors + 1, device)
        wp.launch(
            chromatic_cv_kernel,
            dim=n,
            inputs=[
                self.spec(size, float(params["light_width"]), device),
                METHOD_IDS[method],
                int(params["frames"]),
                candidates,
                neighbors,
                int(params.get("radius", 1)),
                ALPHA_MODES[params.get("alpha", "heuristic")],
                DIFFERENCE_MIS[params.get("difference_mis", "confidence")],
                seed,
                first_trial,
                *buffers,
                batch.values,
                batch.counters if batch.counters is not None else wp.zeros((n, 0), dtype=float, device=device),
            ],
            device=device,
        )

    def counter_names(self, method: str, params: Mapping[str, Any]) -> tuple[str, ...]:
        """Difference-estimate samples used with a neighbour, and those on a light (CV methods only)."""
        return ("difference_samples", "difference_samples_on_light") if method in ("icv", "stcv", "restcv") else ()

    def stats(self, method: str, params: Mapping[str, Any], totals: Mapping[str, float], trials: int) -> dict[str, Any]:
        """Per pixel and frame: difference samples, and the fraction on a light (seed 002, Sec. 6.1's "valid samples")."""
        per = trials * int(params["size"]) ** 2 * int(params["frames"])
        used = totals["difference_samples"]
        return {
            "difference_samples_per_pixel_frame": float(used / per),
            "difference_samples_on_light_fraction": float(totals["difference_samples_on_light"] / used) if used > 0 else 0.0,
        }

    def images(self, method: str, trials: int, seed: int = 0, params: Mapping[str, Any] | None = None, device: str = "cpu") -> np.ndarray:
        """Per-trial last-frame images, shape (trials, size, size, 3): for noise pictures and colour statistics.

        Trial t is the same as trial t of :meth:`run` with the same seed.
        """
        resolved = self.resolve_params(method, params)
        dev = resolve_device(device)
        size = int(resolved["size"])
        out = np.empty((trials, size * size * 3), dtype=np.float32)
        chunk = min(trials, self.chunk_trials)
        values = wp.empty((chunk, size * size * 3), dtype=float, device=dev)
        done = 0
        while done < trials:
            m = min(chunk, trials - done)
            batch = TrialBatch(values=values[:m], samples=None)
            self.launch(method, resolved, int(seed), done, batch, dev)
            out[done : done + m] = batch.values.numpy()
            done += m
        synchronize(dev)
        return out.reshape(trials, size, size, 3)
