"""ReSTIR GI: spatiotemporal reservoir resampling of indirect light (Ouyang et al. 2021; seed 004).

The radiance leaving a visible point x_v toward the camera splits into what
the path tracer's first two segments give (emission and direct light) and
the indirect part

    L_ind(x_v, ω_o) = ∫_{H²} f(ω_o, ω_i) L_r(x_s(ω_i), −ω_i) ⟨cos θ_i⟩ dω_i,

where x_s(ω_i) is the first surface along ω_i (the *sample point*) and L_r
the radiance it *reflects* toward x_v (its own emission is direct light).
ReSTIR GI resamples sample points between pixels and frames (seed 004,
Sec. 4–5); each frame runs the phases of its Figure 4:

1. **Initial sampling** (Alg. 2). A direction from the source pdf p_q —
   ``source=bsdf`` (default), ``cosine`` or ``uniform`` (the paper's choice) —
   a ray to x_s, and L_r at x_s by **path tracing with NEE and MIS**: the
   reference path tracer's own ``trace_path`` (:func:`grisx.render.pt.make_trace_path`)
   started at x_v toward x_s, minus the emission at x_s. The **Sample** record
   of Fig. 3 keeps the visible point and normal, the sample point and its
   normal, the outgoing radiance and the path's random key.
2. **Temporal resampling** (Alg. 3) into the temporal reservoir buffer: the
   previous frame's temporal reservoir at the reprojected pixel (confidence
   capped at 10; the paper: 30) and the new sample with w = p̂/p (seed 004,
   Eq. 5, 9/10).
3. **Spatial resampling** (Alg. 4) into the spatial reservoir buffer: the
   previous frame's spatial reservoir (confidence capped at 30; the paper: 500) and this
   pixel's temporal reservoir, plus up to *maxIterations* temporal reservoirs
   of neighbours (9 while the spatial reservoir holds fewer than half the cap,
   else 3) that pass the similarity test (normals within 25°, depth within
   0.05), chosen within an **adaptive radius** (10% of the image, halved after
   each rejection down to 3 px). A pixel whose spatial reservoir is still poor
   (confidence below ``low_m``) reuses its neighbours' previous *spatial*
   reservoirs instead (Fig. 10).
4. **Shading** (Eq. 8): f ⟨cos⟩ L_r(y) · W of the spatial reservoir.

Both reservoir buffers are double-buffered, so a pass never reads what it writes.

**Stages** (``DESIGN.md``, "GPU execution"). Each phase runs as small kernels with one
path tracer or one shift each: ``validate_pass`` (every ``validation_interval`` frames
in scenes that move), ``direct_pass`` (sky, emission and direct light at x_v; whole
paths on mirrors and glass), ``initial_pass`` (the direction and the sample point x_s),
``sample_radiance_pass`` (L_o at x_s: the path tracer alone in its kernel, with
``exact_bsdf``'s records compiled in only when asked for, started from the hit the initial
pass found; the direct pass starts from the G-buffer's: no ray is traced twice), ``initial_target_pass``,
``temporal_pass``, ``spatial_resample_pass`` (draws the domains — history and
neighbours — into a :class:`~grisx.render.base.reuse.DomainList` and streams their
shifted candidates through one call site of the shift) and ``spatial_mis_pass`` (Z over
the same domains), ``shade_pass``. Reservoirs keep *where* their kept sample lives (a
domain code), not a copy of it, until the sample is written once. Split this way, no
kernel reaches the 255-register cap on sm_90 (the one-kernel spatial pass had 255
registers and 2 KB of spills); the images are bit-identical to the one-kernel passes.

**Targets.** ``target=full`` is Eq. 9, p̂ = lum(L_o f ⟨cos θ_i⟩);
``target=radiance`` is Eq. 10, p̂ = lum(L_o). Both are zero outside the
visible point's hemisphere and where x_v is behind the sample point's surface.

**Reconnection shift and Eq. 11.** A sample point x_2^q found from x_1^q is
reused at x_1^r by connecting x_1^r to the same x_2^q; its resampling weight
is seed 000's Eq. 9 with the Jacobian |J_{q→r}| of seed 004, Eq. 11
(:func:`~grisx.theory.shift.reconnection_jacobian_3d`; geometric normal at x_2).
``jacobian=false`` drops it — the bias of seed 004, Fig. 7. (Alg. 4 l. 11 of
the paper *divides* p̂ by its J; the GRIS weight of seed 000, Eq. 9 multiplies
by |∂T/∂x| = Eq. 11's J_{q→r}, which is what is done here.) L_r at x_2 is
reused unchanged: the paper's Lambertian assumption (Sec. 5), exact for
diffuse sample points, biased for glossy ones.

**exact_bsdf=true** re-evaluates x_s's BSDF toward each visible point that
reuses the sample. The path at x_s keeps its two techniques apart
(:class:`~grisx.render.pt.PathRadiance` records: the NEE direction and its
radiance × MIS weight / pdf, the continuation's direction and all it gathers
over its pdf), so L_r(x_s → x_v') = f(x_v' ← x_s ← ω_nee) L_nee +
f(x_v' ← x_s ← ω_bs) L_bs. For this to be one function of the sample whatever
visible point traced it, nothing at x_s may depend on the direction it was
seen from: the continuation there is cosine-weighted (not BSDF-sampled) and
both MIS weights use that density. Sample points on delta or transmitting
BSDFs cannot be reconnected at all; with the option they are used only by
the visible point that found them (target 0 elsewhere, and Z counts so). On
diffuse sample points the option changes nothing (a test checks it). Its
records (80 bytes a sample) live in a buffer of their own, allocated only with
the option (:class:`GISamples`), and its code in a module of its own: every
reuse pass moves whole samples, and without the records a sample is 120 bytes,
not 200 (door-ajar at 1080p: 18.9 → 16.3 ms a frame, benchmarks/README); 96 in
scenes whose objects do not move, which keep no box either.

**MIS weights** (``mis``). Both reuse passes are GRIS over domains — the
history, the neighbours and the pixel's own (canonical) sample — and need
weights m_i(y) that sum to one over the domains that can produce y.

* ``mis=support`` is the paper's (Alg. 3 l. 6, Alg. 4 l. 16–19): candidates
  are streamed with weights c_i p̂(y_i) W_i |J| and the *kept* sample y gets
  W = w_sum / (Z(y) p̂(y)) (:func:`~grisx.theory.reservoir.reservoir_finalize_mis`),
  Z(y) the confidence of the domains that can produce y (support counting,
  :func:`~grisx.theory.mis.support_count_term`). It is unbiased, but the
  weights of the candidates *not* kept stay in w_sum undivided: a sample
  that few domains support is kept rarely and then carries w_sum / Z with a
  small Z. Its frames have heavy tails: 12 independent runs of closed-room
  at 128×72, per-frame relMSE of frames 16–31, had mean 1.25 and worst run
  5.8 under the static camera (pt at 1 spp: 0.54), 3.0 and 19.3 along the
  camera path.
* ``mis=pairwise`` (default) weighs every candidate *before* selection
  (so f(y) W = (f/p̂)(y) Σ_i w_i, RIS's own light-tailed form): each domain
  against the canonical one only (:func:`~grisx.theory.mis.pairwise_mis_neighbor`,
  Bitterli 2022, Ch. 9), the temporal pass's two domains by the balance
  heuristic (:func:`~grisx.theory.mis.two_domain_balance`; seed 001,
  Eq. 15). p̂_{←i}(y) of a candidate shifted from domain i is its own target
  over |J|; of the canonical sample, that sample reconnected at domain i's
  visible point in domain i's frame (``target_at_domain``) — the ray the
  Z test traced. Same rays, in stages ``spatial_canonical_pass`` (m_c) and
  ``spatial_merge_pass``.

In both modes ``unbiased=true`` tests each domain's support by its own target
and a **visibility ray** from its visible point to y; ``unbiased=false``
assumes every domain sees every sample — cheaper and biased where visibility
differs between neighbours (seed 004, Fig. 9). Visibility at the current
pixel (Alg. 4 l. 12) is tested in both: shading has no other shadow ray.

**Defaults that differ from the paper** (measured; ``benchmarks/README.md``,
"ReSTIR GI's MIS weights and caps"): pairwise MIS; ``source=bsdf``; and caps
of 10 (history) and 30 (spatial) instead of 30 and 500. A balance or
pairwise weight trusts each domain's confidence against the canonical
sample's: a history with c = 500 against a canonical sample with c ≤ 30
split over k pairs can carry ≈ 500·k/30 times its share where the sample is
worth more here than at home, and a camera that moves finds those places
(closed-room at 128×72 along the camera path, pairwise weights and uniform
directions, mean per-frame relMSE of 12 runs: 1.23 at a spatial cap of 500, 0.27 at 100, 0.23 at 30; static camera
0.147 / 0.138 / 0.145, the long memory buys nothing). At a glossy visible
point a uniform direction rarely falls in the lobe and, when it does,
w = p̂/p is a firefly that reuse then carries (glossy-room along the path:
17.7 uniform, 1.52 BSDF-sampled; pt at 1 spp 1.67). On the protocol (H100,
1080p) the history cap of 10 beat 30 in all eight cells tried, most on
glossy-room under the moving camera (gain over pt 0.67 → 1.21).
``source=uniform, history_cap=30, spatial_cap=500, mis=support`` is Alg. 2–4
as published.

**Jacobian rejection** (not in the paper; ``max_jacobian`` = τ, default 10;
0 turns it off and gives the paper's algorithm). A reconnection to a sample
point much closer to the new visible point than to the old one has a huge
|J| ∝ d_q²/d_r²: at a concave corner, where jittered visible points come
arbitrarily close to a sample point on the other wall, its second moment is
unbounded, and single frames carry fireflies thousands of times the pixel's
value (Cornell box, 48×36, jittered: frames with relMSE 921 against a typical
0.2). Shifts with |J| > τ are treated as undefined (a partial bijection), and
a domain supports a sample (Z counts it; its p̂_{←i} is non-zero) only if its
own shift to the current pixel passes the same test, so the estimator stays unbiased (the tests check it, τ = 2 and 10) with
light tails.

**Where x_1 is.** Initial rays leave from the visible point lifted ε off its
surface on the viewer's side (``spawn_origin``, as the path tracer's rays do),
and targets, Jacobians and visibility are measured from that same point: at
a concave edge a sample point lies only a few ε away, and measuring from the
surface point instead loses it. Shadow rays are offset at both ends.

**Multi-bounce tiles** (Sec. 5). ``mb_fraction`` = q: per frame, each 64×32
tile follows full paths at x_s with probability q (Russian roulette at the
tile level, reweighted: L_1 + (L_full − L_1)/q), otherwise only direct light
at x_s (L_1). ``max_depth`` is the path tracer's (Mitsuba's meaning, from the
camera), so the image estimates what ``pt`` shows.

**Sample validation** (Sec. 4.3, 5). Every ``validation_interval`` frames the
initial pass replays the path of each pixel's previous temporal and spatial
sample with its stored random key (bit-exact on a static scene) and clears
the reservoir when the radiance moved by more than ``validation_tolerance``
(relative) or x_s is no longer visible. A scene with no moving object is
skipped: there the replay is bit-exact and cannot fail (a moving camera does
not change the radiance leaving x_s), and on the H200 at 1080p the replay made
every sixth frame 3–4× as slow as the others.

**Moving objects.** Validation is the paper's heuristic; what keeps temporal reuse
unbiased is that every domain is evaluated in its own frame's scene
(:meth:`~grisx.scene.scene.BuiltScene.across_frames`: last frame's visible points test
visibility in last frame's geometry, in Z too) and that a sample's L_o is reused across
frames only where nothing moved in the box of the path that estimated it (``box_lo``,
``box_hi``, compiled in only for scenes with moving objects): else the shift from last
frame is undefined and Z does not count that domain.

**Direct light.** ``direct=nee``: the path tracer's two first segments at the
visible point's camera ray (emission + NEE and BSDF sampling with MIS); ``direct=restir-di``:
:class:`~grisx.render.restir_di.ReSTIRDI` on the same G-buffer, as the paper does.
``direct=auto`` (the default) takes ReSTIR DI where the scene has more than
:data:`AUTO_DI_LIGHTS` lights (emissive triangles and point lights) and NEE
otherwise, because that is where each is better, measured by the benchmark
protocol (H100, 1920×1080, jittered, per-frame relMSE gain over ``pt`` at
equal time, static / moving camera; ``benchmarks/reference/protocol_h100``):

=============  ==============  ==============
scene          direct=nee      direct=restir-di
=============  ==============  ==============
many-lights    0.64 / 0.29     **8.6 / 2.3**   (800 emissive triangles)
door-ajar      6.0 / 3.2       8.2 / 3.0       (one light, mostly indirect)
cornell-box    **3.5** / 1.1   2.4 / 1.0
glossy-room    1.2 / 0.42      1.1 / 0.20
closed-room    **2.0** / 0.13  1.1 / 0.86
=============  ==============  ==============

With one or two lights NEE's direct light is nearly noise-free already and
ReSTIR DI's extra passes cost more time than its reuse saves; with hundreds
NEE picks a light that matters rarely and ReSTIR DI wins by an order of
magnitude. Visible points
with a delta lobe or a rough-dielectric BSDF (mirrors, glass, a smooth plastic's
coat: no source pdf over the hemisphere reaches a delta lobe, and transmission
leaves the sampled hemisphere) are path traced instead, with no reservoir.

**Pixels.** Each frame's visible point is at a random position in its pixel
(``jitter=true``, the default), so the image estimates the same box-filtered
pixel as ``pt``; ``jitter=false`` puts it at the pixel centre, whose
reference is ``PathTracer(..., jitter=False)`` at the same ``max_depth``.

References: Y. Ouyang, S. Liu, M. Kettunen, M. Pharr, J. Pantaleoni, "ReSTIR GI:
Path resampling for real-time path tracing", CGF 40(8), 2021 (seed 004:
Alg. 1–4, Eq. 5–11, Fig. 3, 7, 9, 10); seed 000, Eq. 9 (GRIS weights);
B. Bitterli et al. 2020, Sec. 4.3 (the 1/Z weight of the kept sample).
"""

from __future__ import annotations

import math
import types
from typing import Any

import warp as wp

from grisx.device import PATH_REGISTERS, launch, specialized_module
from grisx.params import Param
from grisx.render.base.registry import RenderMethod, composed_direct, create_renderer, register, renderer_params
from grisx.scene.bsdf import MATERIAL_ROUGH_DIELECTRIC, cosine_hemisphere_pdf, make_bsdf, sample_cosine_hemisphere
from grisx.scene.material import MATERIAL_PRINCIPLED, MATERIAL_PRINCIPLED_THIN, SCENE_MOVING_OBJECTS
from grisx.scene.frame import frame_from_normal, to_local, to_world
from grisx.scene.gbuffer import GBuffer, GBufferData
from grisx.scene.lights import luminance, make_lights
from grisx.render.base.screen import ScreenFrame, ScreenSpaceRenderer, frame_key, kernel_cache, pixel_key, screen_frame, visible_normal, write_pixel
from grisx.render.base.trace import STRATEGIES, make_trace_path
from grisx.render.base.reuse import (
    DOMAIN_HISTORY,
    DOMAIN_PREVIOUS,
    DomainList,
    domain_code,
    domain_flags,
    domain_pixel,
    SIMILARITY_DEPTH,
    SIMILARITY_NORMAL_COS,
    DoubleBuffer,
    NeighborPixel,
    adaptive_radius,
    pixels_similar,
    spatial_neighbor,
    temporal_neighbor,
)
from grisx.scene.scene import (
    SceneData,
    SurfaceInteraction,
    motion_touches,
    spawn_origin,
    make_surface,
)
from grisx.theory.gris import ris_weight
from grisx.theory.mis import (
    pairwise_mis_canonical_term,
    pairwise_mis_neighbor,
    support_count,
    support_count_term,
    support_mis,
    target_from,
    two_domain_balance,
)
from grisx.theory.random import random_subkey, random_uniform
from grisx.theory.reservoir import (
    Reservoir,
    confidence_capped,
    reservoir_empty,
    reservoir_finalize,
    reservoir_finalize_mis,
    reservoir_merge,
    reservoir_update,
)
from grisx.theory.shift import JACOBIAN_BOUND_ONE_SIDED, jacobian_bounded, reconnection_jacobian_3d

wp.set_module_options({"enable_backward": False})

__all__ = [
    "GISample",
    "GISamples",
    "GISampleCore",
    "GISampleExact",
    "GISampleBox",
    "gi_samples",
    "SOURCES",
    "TARGETS",
    "DIRECT",
    "sample_uniform_hemisphere",
    "uniform_hemisphere_pdf",
    "make_restir_gi_kernels",
    "ReSTIRGI",
    "create_restir_gi",
]

#: initial-sample source pdfs (seed 004, Sec. 4.1)
SOURCES = {"uniform": 0, "cosine": 1, "bsdf": 2}
#: target functions: Eq. 9 and Eq. 10
TARGETS = {"full": 0, "radiance": 1}
#: direct-light estimators
DIRECT = {"nee": 0, "restir-di": 1}
#: ``direct=auto`` takes ReSTIR DI above this many lights (see "Direct light" above)
AUTO_DI_LIGHTS = 16


def resolve_direct(direct: str, built: Any, max_depth: int) -> str:
    """``nee`` or ``restir-di``: ``auto`` by the scene's number of lights (see the module docstring)."""
    if direct == "auto":
        direct = "restir-di" if int(built.data.lights.num_lights) > AUTO_DI_LIGHTS else "nee"
    return composed_direct(direct, max_depth)

@wp.struct
class SourceSample:
    """A direction from the source pdf p_q and its density (solid angle; 0: none)."""

    wi: wp.vec3
    pdf: float


_SOURCE_UNIFORM = wp.constant(0)
_SOURCE_COSINE = wp.constant(1)
_TARGET_FULL = wp.constant(0)
_STRATEGY_MIS = wp.constant(STRATEGIES["mis"])
_INV_2PI = wp.constant(1.0 / (2.0 * math.pi))
_TILE_W = wp.constant(64)
_TILE_H = wp.constant(32)
#: MIS weights of the reuse passes (``mis``): pairwise MIS, each candidate weighed before selection, or the
#: paper's support counting, 1/Z applied to the kept sample (Alg. 3 l. 6, Alg. 4 l. 16–19)
MIS = {"pairwise": 0, "support": 1}
_MIS_PAIRWISE = wp.constant(MIS["pairwise"])
KEPT_NONE = wp.constant(-2)  # the spatial pass's kept sample: none, this pixel's own, else a domain code
KEPT_OWN = wp.constant(-1)


@wp.struct
class GISample:
    """Seed 004, Fig. 3: the visible point that generated the sample, the sample point, L_o, the random key."""

    xv: wp.vec3  # visible point x_v
    nv: wp.vec3  # its normal (viewer side)
    xs: wp.vec3  # sample point x_s
    ns: wp.vec3  # its geometric normal, turned toward x_v (the side L_o leaves on)
    lo: wp.vec3  # radiance reflected at x_s toward x_v (emission at x_s excluded: that is direct light)
    ray_o: wp.vec3  # the ray x_v → x_s as traced (origin offset, direction), for a bit-exact replay
    ray_d: wp.vec3
    key: wp.uint32  # random key of the path at x_s
    multi: int  # 1: the tile followed multi-bounce paths
    box_lo: wp.vec3  # the box of what L_o depends on (x_s, the path's hits and light samples; unbounded past an
    box_hi: wp.vec3  # escape): reused across frames only where nothing in it moved (``motion_touches``)
    valid: int
    # ---- exact_bsdf: x_s's BSDF and the two techniques of its path, to re-evaluate L_o toward any x_v ----
    exact: int  # 0: lo reused as if Lambertian; 1: re-evaluated from the records below; 2: its own direction only
    mat_s: int  # material, texture coordinates and triangle at x_s
    uv_s: wp.vec2
    tri_s: int
    ns_s: wp.vec3  # shading normal at x_s (the path tracer's frame there)
    nee_wi: wp.vec3
    nee_li: wp.vec3
    bs_wi: wp.vec3
    bs_li: wp.vec3


@wp.struct
class GIEval:
    """A sample seen from a visible point: f ⟨cos⟩ L_o (RGB), p̂, and the connecting segment."""

    rgb: wp.vec3
    target: float
    wi: wp.vec3
    dist: float


@wp.struct
class NeighborDomain:
    """A neighbour's reservoir (confidence capped), its sample and its visible point."""

    res: Reservoir
    sample: GISample
    si: SurfaceInteraction
    wo: wp.vec3


@wp.struct
class SpatialPlan:
    """Alg. 4 l. 2–3 at one pixel: last frame's pixel of its surface, the neighbours to draw, and whether
    they are neighbours' last spatial reservoirs (Fig. 10)."""

    history: NeighborPixel
    iterations: int
    from_spatial: int


@wp.struct
class GIShift:
    """A sample reconnected at another visible point: its target there and its weight's Jacobian."""

    target: float
    jacobian: float


@wp.func
def gi_shift_none() -> GIShift:
    """No shift evaluated: target 0, |J| = 1 (what a merge gets for a reservoir of weight 0, which adds its confidence alone)."""
    out = GIShift()
    out.target = 0.0
    out.jacobian = 1.0
    return out


@wp.func
def domain_of_last_frame(code: wp.int32) -> int:
    """1 for a reuse domain of last frame (its visible point is seen in last frame's scene), else 0."""
    if domain_flags(code) & DOMAIN_PREVIOUS:
        return 1
    return 0


@wp.func
def frame_scene(scene: SceneData, scene_prev: SceneData, previous: int) -> SceneData:
    """The scene of a domain's frame: last frame's where ``previous``. A pass that evaluates a domain of either frame
    through one call site inlines that evaluation once (its rays and BSDF), not once for each scene."""
    if previous != 0:
        return scene_prev
    return scene


@wp.func
def sample_uniform_hemisphere(u: wp.vec2) -> wp.vec3:
    """Uniform direction on the hemisphere z > 0 (local frame)."""
    z = u[0]
    r = wp.sqrt(wp.max(0.0, 1.0 - z * z))
    phi = 2.0 * wp.pi * u[1]
    return wp.vec3(r * wp.cos(phi), r * wp.sin(phi), z)


@wp.func
def uniform_hemisphere_pdf(w: wp.vec3) -> float:
    """1 / 2π above the horizon, 0 below."""
    if w[2] > 0.0:
        return _INV_2PI
    return 0.0


@wp.func
def gi_sample_none() -> GISample:
    s = GISample()
    s.key = wp.uint32(0)
    s.multi = 0
    s.valid = 0
    s.exact = 0
    s.mat_s = 0
    return s


# ---- sample buffers: what is stored of a GISample, in three arrays ----
# Every reuse pass moves whole samples (a history's or a neighbour's, to this pixel's output), and each lane's store
# of a record is a store per word at the record's stride. exact_bsdf's records are 20 of a sample's 50 words and off by
# default, so they live in an array of their own, allocated only with exact_bsdf: without them a door-ajar frame takes
# 16.3 ms instead of 18.9 (H200, 1080p; benchmarks/README, "ReSTIR GI's samples without their exact records"). The box
# of what L_o depends on (6 words) is read only in scenes with moving objects, and lives apart likewise.
@wp.struct
class GISampleCore:
    """What a sample buffer stores of every :class:`GISample`: its fields up to ``valid`` but the box."""

    xv: wp.vec3
    nv: wp.vec3
    xs: wp.vec3
    ns: wp.vec3
    lo: wp.vec3
    ray_o: wp.vec3
    ray_d: wp.vec3
    key: wp.uint32
    multi: int
    valid: int


@wp.struct
class GISampleBox:
    """The box of what a stored sample's L_o depends on (:class:`GISample`'s ``box_lo``, ``box_hi``): scenes with
    moving objects only."""

    box_lo: wp.vec3
    box_hi: wp.vec3


@wp.struct
class GISampleExact:
    """``exact_bsdf``'s records of a stored :class:`GISample` (its fields from ``exact`` on)."""

    exact: int
    mat_s: int
    uv_s: wp.vec2
    tri_s: int
    ns_s: wp.vec3
    nee_wi: wp.vec3
    nee_li: wp.vec3
    bs_wi: wp.vec3
    bs_li: wp.vec3


@wp.struct
class GISamples:
    """A buffer of samples, one a pixel (:func:`gi_samples` allocates it; :func:`gi_load`, :func:`gi_store` read and
    write it): each sample's core at ``core[y, x]``; where ``with_exact``, its ``exact_bsdf`` records at
    ``exact[y, x]``; where ``with_box``, its box at ``box[y, x]``. Without them ``exact`` or ``box`` is a 1×1
    placeholder, and every sample reads as the paper's Lambertian reuse (``exact`` = 0, as :func:`gi_sample_none`) or
    with an empty box (no scene object moves: nothing reads it)."""

    core: wp.array2d(dtype=GISampleCore)
    exact: wp.array2d(dtype=GISampleExact)
    box: wp.array2d(dtype=GISampleBox)
    with_exact: int
    with_box: int


def gi_samples(height: int, width: int, exact: bool, moving: bool, device: Any) -> GISamples:
    """An empty sample buffer (every sample invalid) for a height × width image; ``exact``: with the records;
    ``moving``: with the boxes (a scene whose objects move)."""
    b = GISamples()
    b.core = wp.zeros((height, width), dtype=GISampleCore, device=device)
    b.exact = wp.zeros((height, width) if exact else (1, 1), dtype=GISampleExact, device=device)
    b.box = wp.zeros((height, width) if moving else (1, 1), dtype=GISampleBox, device=device)
    b.with_exact = int(bool(exact))
    b.with_box = int(bool(moving))
    return b


def gi_samples_copy(dst: GISamples, src: GISamples) -> None:
    """Copy buffer ``src`` into ``dst`` (same size, records and boxes)."""
    wp.copy(dst.core, src.core)
    if src.with_exact:
        wp.copy(dst.exact, src.exact)
    if src.with_box:
        wp.copy(dst.box, src.box)


@wp.func
def gi_load(b: GISamples, y: int, x: int) -> GISample:
    """The sample at (y, x) of buffer ``b``."""
    c = b.core[y, x]
    s = gi_sample_none()
    s.xv = c.xv
    s.nv = c.nv
    s.xs = c.xs
    s.ns = c.ns
    s.lo = c.lo
    s.ray_o = c.ray_o
    s.ray_d = c.ray_d
    s.key = c.key
    s.multi = c.multi
    s.valid = c.valid
    if b.with_box != 0:
        box = b.box[y, x]
        s.box_lo = box.box_lo
        s.box_hi = box.box_hi
    if b.with_exact != 0:
        rec = b.exact[y, x]
        s.exact = rec.exact
        s.mat_s = rec.mat_s
        s.uv_s = rec.uv_s
        s.tri_s = rec.tri_s
        s.ns_s = rec.ns_s
        s.nee_wi = rec.nee_wi
        s.nee_li = rec.nee_li
        s.bs_wi = rec.bs_wi
        s.bs_li = rec.bs_li
    return s


@wp.func
def gi_store(b: GISamples, y: int, x: int, s: GISample):
    """Write sample ``s`` at (y, x) of buffer ``b`` (its records only where the buffer has them)."""
    c = GISampleCore()
    c.xv = s.xv
    c.nv = s.nv
    c.xs = s.xs
    c.ns = s.ns
    c.lo = s.lo
    c.ray_o = s.ray_o
    c.ray_d = s.ray_d
    c.key = s.key
    c.multi = s.multi
    c.valid = s.valid
    b.core[y, x] = c
    if b.with_box != 0:
        box = GISampleBox()
        box.box_lo = s.box_lo
        box.box_hi = s.box_hi
        b.box[y, x] = box
    if b.with_exact != 0:
        rec = GISampleExact()
        rec.exact = s.exact
        rec.mat_s = s.mat_s
        rec.uv_s = s.uv_s
        rec.tri_s = s.tri_s
        rec.ns_s = s.ns_s
        rec.nee_wi = s.nee_wi
        rec.nee_li = s.nee_li
        rec.bs_wi = s.bs_wi
        rec.bs_li = s.bs_li
        b.exact[y, x] = rec


@wp.struct
class InitialSample:
    """Alg. 2's draw at a visible point: the sample (``valid`` 0 where there is none), its source pdf p_q, and the
    hit x_s that the path tracer at x_s starts from."""

    s: GISample
    pdf: float
    hit: SurfaceInteraction


@wp.struct
class SampleRadiance:
    """L_r at a sample point toward the visible point that found it, and the path's technique records."""

    lo: wp.vec3
    nee_wi: wp.vec3
    nee_li: wp.vec3
    bs_wi: wp.vec3
    bs_li: wp.vec3
    recorded: int
    box_lo: wp.vec3
    box_hi: wp.vec3




@kernel_cache
def make_restir_gi_kernels(kinds: frozenset[int], exact: bool = False) -> Any:
    """ReSTIR GI's functions and kernels compiled for the material kinds ``kinds`` (cached; with SCENE_MOVING_OBJECTS,
    the box of what each L_o depends on); ``exact``: with ``exact_bsdf``'s records and their BSDF re-evaluation, in a
    module of their own (without it every sample is the Lambertian reuse, and no kernel carries that code)."""
    moving = SCENE_MOVING_OBJECTS in kinds
    bsdf = make_bsdf(kinds)
    surface = make_surface(kinds)  # the wrappers and shapes of these kinds only
    lights = make_lights(kinds)  # the lights of these kinds only
    emitter_radiance, environment_eval = lights.emitter_radiance, lights.environment_eval
    surface_material = surface.surface_material
    surface_material_at = surface.surface_material_at
    intersect, segment_occluded = surface.intersect, surface.segment_occluded
    trace_path = make_trace_path(kinds, bounds=moving)  # with moving objects, the box of what L_o depends on
    has_rough_dielectric = MATERIAL_ROUGH_DIELECTRIC in kinds
    has_principled = MATERIAL_PRINCIPLED in kinds or MATERIAL_PRINCIPLED_THIN in kinds

    @wp.func
    def path_traced_here(scene: SceneData, si: SurfaceInteraction) -> bool:
        """Visible points ReSTIR GI leaves to the path tracer: delta lobes (mirrors, glass, a plastic's coat: no
        source pdf over the hemisphere reaches them), rough dielectrics and the principled kinds (transmission)."""
        m = surface_material(scene, si)
        if bsdf.has_delta_lobe(m) != 0:
            return True
        if wp.static(has_rough_dielectric):
            if m.kind == MATERIAL_ROUGH_DIELECTRIC:
                return True
        if wp.static(has_principled):  # their transmission lobes cross the surface, as a rough dielectric's
            if m.kind == MATERIAL_PRINCIPLED or m.kind == MATERIAL_PRINCIPLED_THIN:
                return True
        return False

    @wp.func
    def domain_point(scene: SceneData, si: SurfaceInteraction, wo: wp.vec3) -> wp.vec3:
        """x_1 of a pixel's domain: its visible point lifted off the surface on the viewer's side.

        Initial rays leave from here (as the path tracer's do), so targets, Jacobians and visibility
        are measured from the very point the samples' directions were drawn at; measured from the
        surface point instead, a sample point a few ε away (at a concave edge) reads as behind or hidden.
        """
        return spawn_origin(scene, si.p, si.ng, visible_normal(si, wo))

    @wp.func
    def reflected_radiance(scene: SceneData, s: GISample, toward: wp.vec3) -> wp.vec3:
        """L_r leaving x_s in direction ``toward``: the stored L_o (the paper's Lambertian reuse), or with
        ``exact_bsdf`` x_s's BSDF re-evaluated for both techniques of its path (PathRadiance's records)."""
        if wp.static(exact):
            if s.exact == 2:  # a delta or transmitting BSDF at x_s: no other visible point can reconnect to it
                if wp.dot(toward, -s.ray_d) >= 1.0 - 1.0e-6:
                    return s.lo
                return wp.vec3(0.0)
            if s.exact != 0:
                m = surface_material_at(scene, s.mat_s, s.uv_s, s.tri_s, s.xs, s.ns_s, s.ns)
                frame = frame_from_normal(s.ns_s)
                wo_s = to_local(frame, toward)
                f_nee = bsdf.eval(m, wo_s, to_local(frame, s.nee_wi))
                f_bs = bsdf.eval(m, wo_s, to_local(frame, s.bs_wi))
                return wp.max(wp.cw_mul(f_nee, s.nee_li) + wp.cw_mul(f_bs, s.bs_li), wp.vec3(0.0))
        return s.lo  # exact = 0 (every sample without exact_bsdf)

    @wp.func
    def gi_eval(scene: SceneData, si: SurfaceInteraction, wo: wp.vec3, s: GISample, target_mode: int) -> GIEval:
        """Sample ``s`` reconnected to visible point ``si``: f ⟨cos⟩ L_o and p̂ (Eq. 9 or 10); 0 outside the domain."""
        ev = GIEval()
        ev.rgb = wp.vec3(0.0, 0.0, 0.0)
        ev.target = 0.0
        ev.wi = wp.vec3(0.0, 0.0, 1.0)
        ev.dist = 0.0
        if s.valid == 0 or si.valid == 0:
            return ev
        x1 = domain_point(scene, si, wo)
        d = s.xs - x1
        dist = wp.length(d)
        if dist <= 0.0:
            return ev
        wi = d / dist
        ev.wi = wi
        ev.dist = dist
        nv = visible_normal(si, wo)
        if wp.dot(nv, wi) <= 0.0 or wp.dot(si.ng, wi) * wp.dot(si.ng, wo) <= 0.0 or wp.dot(s.ns, wi) >= 0.0:
            return ev# outside the visible point's (shading and geometric) hemisphere, or x_v behind x_s's surface
        m = surface_material(scene, si)
        frame = frame_from_normal(si.ns)
        f = bsdf.eval(m, to_local(frame, wo), to_local(frame, wi))
        lo = reflected_radiance(scene, s, -wi)
        ev.rgb = wp.cw_mul(f, lo)
        t = luminance(ev.rgb)  # seed 004, Eq. 9
        if target_mode != _TARGET_FULL:
            t = luminance(lo)  # seed 004, Eq. 10
        if t > 0.0:  # false for NaN
            ev.target = t
        else:
            ev.rgb = wp.vec3(0.0, 0.0, 0.0)
        return ev

    @wp.func
    def sample_visible(scene: SceneData, si: SurfaceInteraction, wo: wp.vec3, ev: GIEval, s: GISample) -> bool:
        """Whether the segment x_v → x_s is free (both ends lifted off their surfaces: ``segment_occluded``)."""
        return not segment_occluded(scene, domain_point(scene, si, wo), visible_normal(si, wo), s.xs, s.ns)

    @wp.func
    def target_shifted(scene: SceneData, si: SurfaceInteraction, wo: wp.vec3, s: GISample, target_mode: int, test_visibility: int) -> float:
        """p̂ at ``si`` of a sample reconnected from elsewhere; 0 if x_s is hidden from ``si`` (Alg. 4 l. 12)."""
        ev = gi_eval(scene, si, wo, s, target_mode)
        if ev.target > 0.0 and test_visibility != 0:
            if not sample_visible(scene, si, wo, ev, s):
                return 0.0
        return ev.target

    @wp.func
    def reconnection_jacobian(
        scene: SceneData, si_src: SurfaceInteraction, wo_src: wp.vec3, si_dst: SurfaceInteraction, wo_dst: wp.vec3, s: GISample
    ) -> float:
        """|J_{q→r}| of seed 004, Eq. 11 for sample ``s`` moved from visible point src to dst (1 for the same point)."""
        x1_src = domain_point(scene, si_src, wo_src)
        x1_dst = domain_point(scene, si_dst, wo_dst)
        if wp.length_sq(x1_src - x1_dst) == 0.0:
            return 1.0
        return reconnection_jacobian_3d(x1_src, x1_dst, s.xs, s.ns)

    @wp.func
    def shift_accepted(jacobian: float, max_jacobian: float) -> bool:
        """Whether a reconnection is used at all: |J| ≤ ``max_jacobian`` (0: always).

        A shift that would magnify a sample's weight by more than the bound is treated as undefined —
        a partial bijection. Z counting applies the same test to every domain (Alg. 4 l. 17), so the
        estimator stays unbiased; it only loses the rare reuse that makes fireflies.
        """
        return jacobian_bounded(jacobian, max_jacobian, JACOBIAN_BOUND_ONE_SIDED)

    @wp.func
    def reconnect(
        scene: SceneData,
        si_src: SurfaceInteraction,
        wo_src: wp.vec3,
        si_dst: SurfaceInteraction,
        wo_dst: wp.vec3,
        s: GISample,
        target_mode: int,
        test_visibility: int,
        use_jacobian: int,
        max_jacobian: float,
        across: int,
    ) -> GIShift:
        """Sample ``s`` of visible point src reused at dst: p̂ there (Alg. 4 l. 11–12; 0 when the shift is
        rejected) and the |J| its resampling weight takes (Eq. 11; 1 with ``jacobian=false``). ``across``:
        src is last frame's, and the shift is undefined where what L_o depends on moved since."""
        out = GIShift()
        j = reconnection_jacobian(scene, si_src, wo_src, si_dst, wo_dst, s)
        out.jacobian = 1.0
        if use_jacobian != 0:
            out.jacobian = j
        out.target = 0.0
        if shift_accepted(j, max_jacobian) and not reused_part_moved(scene, s, across):
            out.target = target_shifted(scene, si_dst, wo_dst, s, target_mode, test_visibility)
        return out

    @wp.func
    def reused_part_moved(scene: SceneData, s: GISample, across: int) -> bool:
        """Whether a shift across frames (``across``) would reuse an L_o that may differ in the other frame."""
        if wp.static(not moving):
            return False  # nothing moves (and the buffers keep no boxes)
        if across == 0:
            return False
        return motion_touches(scene, s.box_lo, s.box_hi)

    @wp.func
    def domain_supports(scene: SceneData, si: SurfaceInteraction, wo: wp.vec3, s: GISample, target_mode: int, unbiased: int) -> int:
        """Whether the domain of visible point ``si`` can produce sample ``s`` (Alg. 4 l. 17); always when biased."""
        if unbiased == 0:
            return 1
        ev = gi_eval(scene, si, wo, s, target_mode)
        if ev.target > 0.0 and sample_visible(scene, si, wo, ev, s):
            return 1
        return 0

    @wp.func
    def domain_counts(
        scene: SceneData,
        si_src: SurfaceInteraction,
        wo_src: wp.vec3,
        si_dst: SurfaceInteraction,
        wo_dst: wp.vec3,
        s: GISample,
        target_mode: int,
        test_support: int,
        unbiased: int,
        max_jacobian: float,
        across: int,
    ) -> bool:
        """Whether src's domain counts in Z for the sample ``s`` kept at dst (Alg. 4 l. 17): it can produce
        ``s`` (tested when ``test_support``, else assumed) and, when unbiased, its own shift to dst is
        accepted — the very test its candidates passed. A domain of last frame (``across``) is tested in
        last frame's ``scene``, and cannot produce a sample whose L_o may have changed since."""
        if unbiased != 0 and reused_part_moved(scene, s, across):
            return False
        if domain_supports(scene, si_src, wo_src, s, target_mode, test_support) == 0:
            return False
        return unbiased == 0 or shift_accepted(reconnection_jacobian(scene, si_src, wo_src, si_dst, wo_dst, s), max_jacobian)

    @wp.func
    def target_back(target_at_source: float, jacobian: float) -> float:
        """p̂_{←i}(y) of a sample y = T(x) shifted from domain i with weight Jacobian |∂T/∂x| = ``jacobian``:
        p̂_i(x) / |∂T/∂x| (the inverse reconnection's Jacobian is the reciprocal of Eq. 11's)."""
        if jacobian > 0.0:
            return target_from(target_at_source, 1.0 / jacobian)
        return 0.0

    @wp.func
    def target_at_domain(
        scene: SceneData,
        si_src: SurfaceInteraction,
        wo_src: wp.vec3,
        si_dst: SurfaceInteraction,
        wo_dst: wp.vec3,
        s: GISample,
        target_mode: int,
        test_visibility: int,
        use_jacobian: int,
        max_jacobian: float,
        across: int,
    ) -> float:
        """p̂_{←src}(s) = p̂_src(T⁻¹ s) |∂T⁻¹/∂s| (seed 001, Eq. 16) for a sample ``s`` at visible point dst:
        domain src's target of it, carried to dst through the inverse reconnection — 0 where src cannot
        produce it, by the very tests its own candidates pass (:func:`reconnect`). Domain src is evaluated
        in ``scene`` (last frame's for a domain of last frame, ``across``)."""
        if reused_part_moved(scene, s, across):
            return 0.0
        j = reconnection_jacobian(scene, si_src, wo_src, si_dst, wo_dst, s)  # src → dst, at T⁻¹ s (x_s is fixed)
        if not shift_accepted(j, max_jacobian):
            return 0.0
        t = target_shifted(scene, si_src, wo_src, s, target_mode, test_visibility)
        if use_jacobian == 0:
            return t
        return target_back(t, j)

    @wp.func
    def outgoing_radiance(
        scene: SceneData, o: wp.vec3, d: wp.vec3, hit: SurfaceInteraction, key: wp.uint32, max_depth: int, rr_depth: int, multi: int,
        mb_fraction: float, exact_bsdf: int,
    ) -> SampleRadiance:
        """L_r at ``hit``, the first hit of the ray (o, d) (traced by the caller): the path tracer's estimate minus
        the hit's emission, with the path's records at that hit (for ``exact_bsdf``).

        ``max_depth`` counts segments from x_v (−1: unbounded). Tiles without
        multi-bounce paths keep one bounce (direct light at x_s, L_1); the others
        add (L_full − L_1)/q, which share their first segments' random numbers.
        """
        depth = max_depth
        prefix_depth = int(-1)
        if not (max_depth >= 0 and max_depth <= 2) and not (multi != 0 and mb_fraction >= 1.0):
            if multi == 0:
                depth = 2  # L_1: one bounce at x_s
            else:
                prefix_depth = 2  # L_1 and L_full from one path
        r = trace_path(scene, o, d, key, depth, rr_depth, _STRATEGY_MIS, prefix_depth, exact_bsdf, hit)
        le = emitter_radiance(scene.lights, hit.tri, hit.p, hit.ng, -d)
        out = SampleRadiance()
        out.lo = r.total - le
        out.bs_li = r.bs_li
        if prefix_depth > 0:
            # tile-level Russian roulette, reweighted (seed 004, Sec. 5); NEE at x_s lies within L_1
            out.lo = r.prefix - le + (r.total - r.prefix) / mb_fraction
            out.bs_li = r.bs_li_prefix + (r.bs_li - r.bs_li_prefix) / mb_fraction
        out.lo = wp.max(out.lo, wp.vec3(0.0))
        out.nee_wi = r.nee_wi
        out.nee_li = r.nee_li
        out.bs_wi = r.bs_wi
        out.recorded = r.recorded
        out.box_lo = r.box_lo
        out.box_hi = r.box_hi
        return out

    @wp.func
    def validate(
        scene: SceneData, s: GISample, max_depth: int, rr_depth: int, mb_fraction: float, tolerance: float
    ) -> bool:
        """Replay the sample's path with its own random numbers; false when L_o or visibility changed (Sec. 4.3)."""
        if s.valid == 0:
            return True
        hit = intersect(scene, s.ray_o, s.ray_d, 1.0e30)
        if hit.valid == 0 or wp.length(hit.p - s.xs) > 1.0e-3 * wp.length(s.xs - s.xv):  # relative: units do not matter
            return False
        lo = outgoing_radiance(scene, s.ray_o, s.ray_d, hit, s.key, max_depth, rr_depth, s.multi, mb_fraction, int(s.exact != 0)).lo
        a = luminance(lo)
        b = luminance(s.lo)
        return wp.abs(a - b) <= tolerance * wp.max(a, b)  # relative: a scene 10⁻⁶ as bright validates alike

    @wp.func
    def neighbor_domain(
        sf: ScreenFrame,
        nb: NeighborPixel,
        from_spatial: int,
        temporal_cap: float,
        spatial_cap: float,
        res_t: wp.array2d(dtype=Reservoir),
        s_t: GISamples,
        res_s_prev: wp.array2d(dtype=Reservoir),
        s_s_prev: GISamples,
    ) -> NeighborDomain:
        """Neighbour ``nb``'s reservoir (confidence capped), sample and visible point: this frame's temporal
        reservoir, or last frame's spatial one for a pixel still low on confidence (Fig. 10)."""
        n = NeighborDomain()
        if from_spatial != 0:
            n.res = res_s_prev[nb.y, nb.x]
            n.sample = gi_load(s_s_prev, nb.y, nb.x)
            n.si = sf.si_prev[nb.y, nb.x]
            n.wo = sf.wo_prev[nb.y, nb.x]
            n.res.confidence = confidence_capped(n.res.confidence, spatial_cap)
        else:
            n.res = res_t[nb.y, nb.x]
            n.sample = gi_load(s_t, nb.y, nb.x)
            n.si = sf.si[nb.y, nb.x]
            n.wo = sf.wo[nb.y, nb.x]
            n.res.confidence = confidence_capped(n.res.confidence, temporal_cap)
        return n

    @wp.func
    def pick_neighbor(
        g: GBufferData,
        g_n: GBufferData,
        x: int,
        y: int,
        it: int,
        rejections: int,
        key: wp.uint32,
        adaptive: int,
        radius: float,
        min_radius: float,
    ) -> NeighborPixel:
        """Alg. 4 l. 5–8: the ``it``-th random neighbour (adaptive or fixed radius); invalid if not similar."""
        width = g.hit.shape[1]
        height = g.hit.shape[0]
        rad = radius
        if adaptive != 0:
            rad = adaptive_radius(width, height, rejections, min_radius)
        nb = spatial_neighbor(x, y, width, height, rad, wp.vec2(random_uniform(key, 4 * it + 8), random_uniform(key, 4 * it + 9)))
        if nb.valid != 0:
            if not pixels_similar(g, x, y, g_n, nb.x, nb.y, SIMILARITY_NORMAL_COS, SIMILARITY_DEPTH):
                nb.valid = 0
        return nb

    @wp.func
    def depth_from_visible_point(max_depth: int) -> int:
        """The path at x_s continues the camera path: one segment fewer (−1: unbounded)."""
        if max_depth < 0:
            return -1
        return max_depth - 1

    # ---- the initial pass's jobs, one function each ----
    @wp.func
    def validate_history(
        scene: SceneData,
        x: int,
        y: int,
        depth_from_xv: int,
        rr_depth: int,
        mb_fraction: float,
        tolerance: float,
        res_t_prev: wp.array2d(dtype=Reservoir),
        s_t_prev: GISamples,
        res_s_prev: wp.array2d(dtype=Reservoir),
        s_s_prev: GISamples,
    ):
        """Sample validation (Sec. 4.3): replay last frame's temporal and spatial samples; clear those that changed."""
        which = int(0)
        while which < 2:  # the temporal, then the spatial sample (a loop: one copy of the path tracer in the kernel)
            s_prev = gi_load(s_t_prev, y, x)
            if which == 1:
                s_prev = gi_load(s_s_prev, y, x)
            if not validate(scene, s_prev, depth_from_xv, rr_depth, mb_fraction, tolerance):
                if which == 0:
                    res_t_prev[y, x] = reservoir_empty()
                    gi_store(s_t_prev, y, x, gi_sample_none())
                else:
                    res_s_prev[y, x] = reservoir_empty()
                    gi_store(s_s_prev, y, x, gi_sample_none())
            which += 1

    @wp.func
    def sample_source(scene: SceneData, si: SurfaceInteraction, wo: wp.vec3, nv: wp.vec3, source: int, key: wp.uint32) -> SourceSample:
        """Alg. 2: a direction ω_i at the visible point from the source pdf p_q (uniform, cosine or the BSDF)."""
        out = SourceSample()
        out.wi = wp.vec3(0.0)
        out.pdf = 0.0
        u = wp.vec2(random_uniform(key, 0), random_uniform(key, 1))
        if source == _SOURCE_UNIFORM:
            fv = frame_from_normal(nv)
            wl = sample_uniform_hemisphere(u)
            out.wi = to_world(fv, wl)
            out.pdf = uniform_hemisphere_pdf(wl)
        elif source == _SOURCE_COSINE:
            fv = frame_from_normal(nv)
            wl = sample_cosine_hemisphere(u)
            out.wi = to_world(fv, wl)
            out.pdf = cosine_hemisphere_pdf(wl)
        else:
            m = surface_material(scene, si)
            fs = frame_from_normal(si.ns)
            bs = bsdf.sample(m, to_local(fs, wo), random_uniform(key, 2), u)
            if bs.valid != 0 and bs.delta == 0:
                out.wi = to_world(fs, bs.wi)
                out.pdf = bs.pdf
        return out

    @wp.func
    def tile_multi_bounce(sf: ScreenFrame, x: int, y: int, width: int, mb_fraction: float) -> int:
        """Tile Russian roulette (Sec. 5): 1 if this pixel's 64×32 tile follows multi-bounce paths this frame."""
        tile = (y // _TILE_H) * ((width + _TILE_W - 1) // _TILE_W) + x // _TILE_W
        return int(random_uniform(random_subkey(frame_key(sf, 1), tile), 0) < mb_fraction)

    module = specialized_module(__name__ + (".exact" if exact else ""), kinds)

    # ---- the initial pass (Alg. 2) in three stages, one path tracer each: validation, direct light, the sample ----
    @wp.kernel(module=module, cuda_max_registers=PATH_REGISTERS)
    def validate_pass(
        scene: SceneData,
        sf: ScreenFrame,
        max_depth: int,
        rr_depth: int,
        mb_fraction: float,
        tolerance: float,
        res_t_prev: wp.array2d(dtype=Reservoir),
        s_t_prev: GISamples,
        res_s_prev: wp.array2d(dtype=Reservoir),
        s_s_prev: GISamples,
    ):
        """Sample validation (Sec. 4.3), launched every ``validation_interval`` frames in scenes that move."""
        y, x = wp.tid()
        if sf.si[y, x].valid == 0:
            return
        validate_history(scene, x, y, depth_from_visible_point(max_depth), rr_depth, mb_fraction, tolerance, res_t_prev, s_t_prev, res_s_prev, s_s_prev)

    @wp.kernel(module=module, cuda_max_registers=PATH_REGISTERS)
    def direct_pass(
        scene: SceneData,
        sf: ScreenFrame,
        max_depth: int,
        rr_depth: int,
        direct_mode: int,
        base: wp.array2d(dtype=wp.vec3),
    ):
        """What is not ReSTIR GI's: the sky, emission and direct light at x_v (``direct=nee``), whole paths on mirrors and glass."""
        y, x = wp.tid()
        key = pixel_key(sf, x, y, 0)
        si = sf.si[y, x]
        wo = sf.wo[y, x]
        base[y, x] = wp.vec3(0.0)
        # the visible point's camera ray (its origin on the lens is t back along wo from the hit)
        ray_d = -wo
        ray_o = si.p + wo * si.t
        if si.valid == 0:
            if direct_mode == 0:
                base[y, x] = environment_eval(scene.lights, ray_d)
            return
        traced_here = path_traced_here(scene, si)
        if traced_here or direct_mode == 0:
            # ---- the camera path: all of it on mirrors and glass (no reservoir there), else its first two
            # segments = emission and direct light (NEE + BSDF sampling with MIS) ----
            cam_depth = max_depth
            if not traced_here and (max_depth < 0 or max_depth > 2):
                cam_depth = 2
            cam_path = trace_path(scene, ray_o, ray_d, random_subkey(key, 1), cam_depth, rr_depth, _STRATEGY_MIS, 2, 0, si)  # from the G-buffer's hit
            base[y, x] = cam_path.total
            if traced_here and direct_mode != 0:
                base[y, x] = cam_path.total - cam_path.prefix  # ReSTIR DI has the first two segments

    # the sample itself in three stages, so that the path tracer runs in a kernel of its own with nothing
    # else live across it (pt's occupancy): the sample point, L_o there, the target
    @wp.func
    def initial_sample(scene: SceneData, sf: ScreenFrame, x: int, y: int, source: int, mb_fraction: float,
                       key: wp.uint32, si: SurfaceInteraction, wo: wp.vec3) -> InitialSample:
        """Alg. 2 at a visible point that has a reservoir: a direction from the source pdf p_q, and the ray to the
        sample point x_s (no sample where the direction or the ray gives none)."""
        out = InitialSample()
        out.s = gi_sample_none()
        nv = visible_normal(si, wo)
        ss = sample_source(scene, si, wo, nv, source, key)
        if ss.pdf <= 0.0:
            return out
        wi = wp.normalize(ss.wi)
        if wp.dot(wi, nv) <= 0.0:
            return out
        if wp.dot(wi, si.ng) * wp.dot(wo, si.ng) <= 0.0:
            return out  # below the geometric surface (shading normals): not a reflection this estimator reconnects
        o = domain_point(scene, si, wo)
        hit = intersect(scene, o, wi, 1.0e30)
        if hit.valid == 0:
            return out  # the sky: direct light's business
        s = out.s
        s.multi = tile_multi_bounce(sf, x, y, sf.si.shape[1], mb_fraction)
        s.key = random_subkey(key, 2)
        s.xv = si.p
        s.nv = nv
        s.xs = hit.p
        ns = hit.ng
        if wp.dot(ns, wi) > 0.0:
            ns = -ns
        s.ns = ns
        s.ray_o = o
        s.ray_d = wi
        if wp.static(exact):
            s.mat_s = hit.material
            s.uv_s = hit.uv
            s.tri_s = hit.tri
            s.ns_s = hit.ns
        s.valid = 1
        out.s = s
        out.pdf = ss.pdf
        out.hit = hit
        return out

    @wp.kernel(module=module)
    def initial_pass(
        scene: SceneData,
        sf: ScreenFrame,
        source: int,
        max_depth: int,
        mb_fraction: float,
        res_out: wp.array2d(dtype=Reservoir),
        s_out: GISamples,
        source_pdf: wp.array2d(dtype=float),
        sample_hit: wp.array2d(dtype=SurfaceInteraction),
    ):
        """Alg. 2: a direction from the source pdf p_q and the ray to the sample point x_s; each output written once
        (a 200-byte record stored by every lane at its stride is a store per word: written twice, it was half the pass)."""
        y, x = wp.tid()
        si = sf.si[y, x]
        r = reservoir_empty()
        src = InitialSample()
        src.s = gi_sample_none()
        # the sky, mirrors and glass: the direct pass has all of it
        if si.valid != 0 and not path_traced_here(scene, si):
            r.confidence = 1.0  # one initial sample: M = 1 (Alg. 1 UPDATE), even if it carries no weight
            if max_depth < 0 or max_depth > 2:  # else nothing indirect to estimate
                src = initial_sample(scene, sf, x, y, source, mb_fraction, pixel_key(sf, x, y, 0), si, sf.wo[y, x])
        res_out[y, x] = r
        gi_store(s_out, y, x, src.s)
        if src.s.valid != 0:
            source_pdf[y, x] = src.pdf
            sample_hit[y, x] = src.hit  # the path tracer at x_s starts from it: x_v → x_s is traced once

    # the path tracer alone in its kernel, exact_bsdf's records compiled in only in its module (a runtime flag kept
    # the records' registers live in every run)
    @wp.kernel(module=module, cuda_max_registers=PATH_REGISTERS)
    def sample_radiance_pass(
        scene: SceneData,
        max_depth: int,
        rr_depth: int,
        mb_fraction: float,
        sample_hit: wp.array2d(dtype=SurfaceInteraction),
        samples: GISamples,
    ):
        """L_o at the sample point by path tracing (NEE + MIS), tile-level multi-bounce roulette."""
        y, x = wp.tid()
        s = gi_load(samples, y, x)
        if s.valid == 0:
            return
        sr = outgoing_radiance(scene, s.ray_o, s.ray_d, sample_hit[y, x], s.key, depth_from_visible_point(max_depth), rr_depth, s.multi,
                               mb_fraction, wp.static(int(exact)))
        # the fields it computed, not the whole record back (a store per word and lane)
        samples.core[y, x].lo = sr.lo
        if wp.static(moving):  # the buffer has the boxes
            samples.box[y, x].box_lo = sr.box_lo
            samples.box[y, x].box_hi = sr.box_hi
        if wp.static(exact):  # exact_bsdf: the buffer has the records
            samples.exact[y, x].exact = 2 - sr.recorded
            samples.exact[y, x].nee_wi = sr.nee_wi
            samples.exact[y, x].nee_li = sr.nee_li
            samples.exact[y, x].bs_wi = sr.bs_wi
            samples.exact[y, x].bs_li = sr.bs_li

    @wp.kernel(module=module)
    def initial_target_pass(
        scene: SceneData,
        sf: ScreenFrame,
        target_mode: int,
        source_pdf: wp.array2d(dtype=float),
        samples: GISamples,
        res_out: wp.array2d(dtype=Reservoir),
    ):
        """p̂ of the sample at its own visible point, and its one-sample reservoir (W = 1/p_q)."""
        y, x = wp.tid()
        s = gi_load(samples, y, x)
        if s.valid == 0:
            return
        si = sf.si[y, x]
        wo = sf.wo[y, x]
        ev = gi_eval(scene, si, wo, s, target_mode)
        if ev.target > 0.0 and not sample_visible(scene, si, wo, ev, s):
            # x_s was found as the first hit, but other pixels test it with a shadow ray: use the same test
            # here, so that every domain's support is decided by one function (else Z could miss a domain)
            ev.target = 0.0
        r = res_out[y, x]
        r = reservoir_update(r, ris_weight(1.0, ev.target, source_pdf[y, x]), ev.target, 0.0, 0.0)  # seed 004, Eq. 5
        res_out[y, x] = reservoir_finalize(r)  # W = 1/p_q

    @wp.kernel(module=module)
    def temporal_pass(
        scene: SceneData,
        scene_prev: SceneData,
        sf: ScreenFrame,
        use_history: int,
        cap: float,
        target_mode: int,
        use_jacobian: int,
        unbiased: int,
        max_jacobian: float,
        mis_mode: int,
        res_in: wp.array2d(dtype=Reservoir),
        s_in: GISamples,
        res_prev: wp.array2d(dtype=Reservoir),
        s_prev: GISamples,
        res_out: wp.array2d(dtype=Reservoir),
        s_out: GISamples,
    ):
        y, x = wp.tid()
        key = pixel_key(sf, x, y, 3)
        r_new = res_in[y, x]
        si = sf.si[y, x]
        tn = NeighborPixel()
        tn.valid = 0
        if si.valid != 0 and use_history != 0 and r_new.confidence > 0.0:
            tn = temporal_neighbor(sf.g, sf.g_prev, x, y, SIMILARITY_NORMAL_COS, SIMILARITY_DEPTH)
        if tn.valid == 0:  # no history (or reprojection failed: the history is reset, seed 004, Sec. 5)
            res_out[y, x] = r_new  # each output written once: these struct stores are most of the pass's traffic
            gi_store(s_out, y, x, gi_load(s_in, y, x))
            return
        wo = sf.wo[y, x]
        si_p = sf.si_prev[tn.y, tn.x]
        wo_p = sf.wo_prev[tn.y, tn.x]
        r_p = res_prev[tn.y, tn.x]
        r_p.confidence = confidence_capped(r_p.confidence, cap)
        # the visible point or the scene moved: visibility of x_s from last frame's x_v is in question
        moved = int(wp.length_sq(si_p.p - si.p) > 0.0 or scene.moved_count > 0)
        # ---- Alg. 3: the history reservoir (reconnected if the visible point moved), then the new sample ----
        out = reservoir_empty()
        # a reservoir of weight W = 0 adds its confidence alone, whatever the MIS weight and target it is given: the
        # rays that would evaluate them are not traced (the same images, bit for bit)
        sh = gi_shift_none()
        if r_p.ucw > 0.0:
            sh = reconnect(scene, si_p, wo_p, si, wo, gi_load(s_prev, tn.y, tn.x), target_mode, moved, use_jacobian, max_jacobian, 1)
        m_h = r_p.confidence  # support counting streams c_i and applies 1/Z to the kept sample below
        m_n = r_new.confidence
        if mis_mode == _MIS_PAIRWISE:
            # pairwise MIS with one neighbour: the generalized balance heuristic over the two domains (seed 001,
            # Eq. 15), each candidate weighed before selection. p̂_{←h} of the history's shifted sample is its own
            # target over |J|; p̂_{←h} of the new one needs it reconnected at last frame's x_v, in last frame's scene
            t_n_from_h = float(0.0)
            if r_new.ucw > 0.0:
                t_n_from_h = target_at_domain(scene_prev, si_p, wo_p, si, wo, gi_load(s_in, y, x), target_mode, unbiased * moved, use_jacobian,
                                              max_jacobian, 1)
            m_h = two_domain_balance(r_p.confidence, target_back(r_p.target, sh.jacobian), r_new.confidence, sh.target)
            m_n = two_domain_balance(r_new.confidence, r_new.target, r_p.confidence, t_n_from_h)
        out = reservoir_merge(out, r_p, m_h, sh.target, sh.jacobian, random_uniform(key, 0))
        kept = int(0)  # which sample is kept (0: none, 1: the history's, 2: the new one), loaded once below
        if out.selected:
            kept = 1
        out = reservoir_merge(out, r_new, m_n, r_new.target, 1.0, random_uniform(key, 1))
        if out.selected:
            kept = 2
        sel = gi_sample_none()
        if kept == 1:
            sel = gi_load(s_prev, tn.y, tn.x)
        elif kept == 2:
            sel = gi_load(s_in, y, x)
        if mis_mode == _MIS_PAIRWISE:
            out = reservoir_finalize(out)
        else:
            # ---- W = w / (Z p̂): Z counts the domains that can produce the kept sample (Alg. 3 l. 6 with Alg. 4's Z) ----
            z = support_count_term(r_new.confidence, out.target)
            if sel.valid != 0:
                z = support_count(z, r_p.confidence, domain_counts(scene_prev, si_p, wo_p, si, wo, sel, target_mode, unbiased * moved,
                                                                   unbiased, max_jacobian, 1))
            out = reservoir_finalize_mis(out, support_mis(1.0, out.target, z))
        res_out[y, x] = out
        gi_store(s_out, y, x, sel)

    @wp.func
    def domain_of(
        sf: ScreenFrame,
        code: wp.int32,
        temporal_cap: float,
        spatial_cap: float,
        res_t: wp.array2d(dtype=Reservoir),
        s_t: GISamples,
        res_s_prev: wp.array2d(dtype=Reservoir),
        s_s_prev: GISamples,
    ) -> NeighborDomain:
        """The domain a :func:`~grisx.render.base.reuse.domain_code` names (reservoir, sample, visible point)."""
        return neighbor_domain(sf, domain_pixel(code, sf.si.shape[1]), int(domain_flags(code) != 0), temporal_cap, spatial_cap,
                               res_t, s_t, res_s_prev, s_s_prev)

    # ---- the spatial pass (Alg. 4): which domains a pixel reuses (shared by both MIS modes' stages) ----
    @wp.func
    def spatial_plan(
        sf: ScreenFrame,
        x: int,
        y: int,
        use_history: int,
        spatial_cap: float,
        iterations_low: int,
        iterations_high: int,
        low_m: float,
        res_s_prev: wp.array2d(dtype=Reservoir),
    ) -> SpatialPlan:
        """Alg. 4 l. 2–3: last frame's spatial reservoir of this surface (reprojected), how many neighbours
        to draw, and whether they are neighbours' last spatial reservoirs (this pixel's M is low: Fig. 10)."""
        plan = SpatialPlan()
        plan.history = NeighborPixel()
        plan.history.valid = 0
        c_s = float(0.0)
        if use_history != 0:
            tn = temporal_neighbor(sf.g, sf.g_prev, x, y, SIMILARITY_NORMAL_COS, SIMILARITY_DEPTH)
            if tn.valid != 0:
                plan.history = tn
                c_s = confidence_capped(res_s_prev[tn.y, tn.x].confidence, spatial_cap)
        plan.iterations = iterations_high
        if c_s < 0.5 * spatial_cap:
            plan.iterations = iterations_low
        plan.from_spatial = int(use_history != 0 and c_s < low_m)
        return plan

    @wp.func
    def spatial_domain(
        sf: ScreenFrame, plan: SpatialPlan, x: int, y: int, d: int, rejections: int, key: wp.uint32, adaptive: int, radius: float,
        min_radius: float,
    ) -> NeighborPixel:
        """Draw ``d``: −1 the history, d ≥ 0 the d-th neighbour (Alg. 4 l. 5–8); invalid if not similar."""
        if d < 0:
            return plan.history
        if plan.from_spatial != 0:
            return pick_neighbor(sf.g, sf.g_prev, x, y, d, rejections, key, adaptive, radius, min_radius)
        return pick_neighbor(sf.g, sf.g, x, y, d, rejections, key, adaptive, radius, min_radius)

    @wp.func
    def spatial_domain_flags(plan: SpatialPlan, d: int) -> int:
        """Draw ``d``'s domain flags: the history is last frame's; neighbours are too while M is low (Fig. 10)."""
        if d < 0:
            return DOMAIN_PREVIOUS | DOMAIN_HISTORY
        return plan.from_spatial * DOMAIN_PREVIOUS

    @wp.func
    def spatial_domain_u(key: wp.uint32, d: int) -> float:
        """The random number that merges draw ``d``'s candidate."""
        if d < 0:
            return random_uniform(key, 0)
        return random_uniform(key, 4 * d + 10)

    @wp.func
    def draw_spatial_domains(
        sf: ScreenFrame,
        plan: SpatialPlan,
        x: int,
        y: int,
        key: wp.uint32,
        adaptive: int,
        radius: float,
        min_radius: float,
        domains: wp.array3d(dtype=wp.int32),
        slots: wp.array3d(dtype=wp.int32),
    ) -> int:
        """Draw the pixel's domains once into the DomainList (codes, draw indices d): the history (d = −1),
        then the neighbours (Alg. 4 l. 4–10). Every later stage reads these very domains. Returns the count."""
        width = sf.si.shape[1]
        count = int(0)
        rejections = int(0)
        for d in range(-1, plan.iterations):
            nb = spatial_domain(sf, plan, x, y, d, rejections, key, adaptive, radius, min_radius)
            if d >= 0 and nb.valid == 0:
                rejections += 1
            if nb.valid != 0 and count < domains.shape[2]:
                domains[y, x, count] = domain_code(nb.x, nb.y, width, spatial_domain_flags(plan, d))
                slots[y, x, count] = d
                count += 1
        return count

    @wp.func
    def domains_confidence(
        sf: ScreenFrame,
        x: int,
        y: int,
        count: int,
        temporal_cap: float,
        spatial_cap: float,
        res_t: wp.array2d(dtype=Reservoir),
        res_s_prev: wp.array2d(dtype=Reservoir),
        domains: wp.array3d(dtype=wp.int32),
    ) -> float:
        """Σ_i c_i over the pixel's drawn domains (capped confidences; each domain's reservoir alone is read)."""
        width = sf.si.shape[1]
        total = float(0.0)
        for j in range(count):
            code = domains[y, x, j]
            nb = domain_pixel(code, width)
            if domain_flags(code) != 0:
                total += confidence_capped(res_s_prev[nb.y, nb.x].confidence, spatial_cap)
            else:
                total += confidence_capped(res_t[nb.y, nb.x].confidence, temporal_cap)
        return total

    @wp.func
    def shift_tests_visibility(scene: SceneData, code: wp.int32, si_src: SurfaceInteraction, si_dst: SurfaceInteraction) -> int:
        """Whether a shift from domain ``code`` needs a shadow ray: always, but for this surface's own history
        when neither its visible point nor the scene moved (then x_s was visible from it already)."""
        if domain_flags(code) & DOMAIN_HISTORY:
            return int(wp.length_sq(si_src.p - si_dst.p) > 0.0 or scene.moved_count > 0)
        return 1

    # ---- mis=support, the paper's Alg. 4 in two stages: resample the candidates, then count Z over the same domains ----
    @wp.kernel(module=module, cuda_max_registers=PATH_REGISTERS)
    def spatial_resample_pass(
        scene: SceneData,
        sf: ScreenFrame,
        use_history: int,
        temporal_cap: float,
        spatial_cap: float,
        iterations_low: int,
        iterations_high: int,
        adaptive: int,
        radius: float,
        min_radius: float,
        low_m: float,
        target_mode: int,
        use_jacobian: int,
        max_jacobian: float,
        res_t: wp.array2d(dtype=Reservoir),
        s_t: GISamples,
        res_s_prev: wp.array2d(dtype=Reservoir),
        s_s_prev: GISamples,
        res_out: wp.array2d(dtype=Reservoir),
        s_out: GISamples,
        kept: wp.array2d(dtype=wp.int32),
        domains: wp.array3d(dtype=wp.int32),
        slots: wp.array3d(dtype=wp.int32),
        domain_count: wp.array2d(dtype=wp.int32),
    ):
        y, x = wp.tid()
        key = pixel_key(sf, x, y, 4)
        r_t = res_t[y, x]
        si = sf.si[y, x]
        if si.valid == 0 or r_t.confidence <= 0.0:
            res_out[y, x] = r_t  # not resampled: passed through (the MIS stage writes every other pixel's sample)
            gi_store(s_out, y, x, gi_load(s_t, y, x))
            domain_count[y, x] = -1
            return
        wo = sf.wo[y, x]
        out = reservoir_empty()
        # the kept sample is tracked by the domain it lives in (KEPT_OWN: this pixel's), not copied at each
        # selection; the MIS stage loads it once
        sel = int(KEPT_NONE)
        plan = spatial_plan(sf, x, y, use_history, spatial_cap, iterations_low, iterations_high, low_m, res_s_prev)
        count = draw_spatial_domains(sf, plan, x, y, key, adaptive, radius, min_radius, domains, slots)
        # ---- one loop, one call site of the shift, in the paper's order: the history (d = −1), this pixel's
        # temporal reservoir, then the neighbours' temporal reservoirs (spatial ones while this pixel's M is
        # low: Fig. 10), Alg. 4 l. 4–14 ----
        own_at = int(0)
        if count > 0 and slots[y, x, 0] < 0:
            own_at = 1
        for i in range(count + 1):
            if i == own_at:  # ---- this pixel's temporal reservoir ----
                r_t.confidence = confidence_capped(r_t.confidence, temporal_cap)
                out = reservoir_merge(out, r_t, r_t.confidence, r_t.target, 1.0, random_uniform(key, 1))
                if out.selected:
                    sel = KEPT_OWN
            else:
                j = i - int(i > own_at)
                code = domains[y, x, j]
                n = domain_of(sf, code, temporal_cap, spatial_cap, res_t, s_t, res_s_prev, s_s_prev)
                sh = reconnect(scene, n.si, n.wo, si, wo, n.sample, target_mode, shift_tests_visibility(scene, code, n.si, si),  # Alg. 4 l. 11–12
                               use_jacobian, max_jacobian, int(domain_flags(code) != 0))
                out = reservoir_merge(out, n.res, n.res.confidence, sh.target, sh.jacobian, spatial_domain_u(key, slots[y, x, j]))
                if out.selected:
                    sel = code
        res_out[y, x] = out  # W is set by the MIS stage
        kept[y, x] = wp.int32(sel)
        domain_count[y, x] = wp.int32(count)

    @wp.kernel(module=module, cuda_max_registers=PATH_REGISTERS)
    def spatial_mis_pass(
        scene: SceneData,
        scene_prev: SceneData,
        sf: ScreenFrame,
        temporal_cap: float,
        spatial_cap: float,
        target_mode: int,
        unbiased: int,
        max_jacobian: float,
        res_t: wp.array2d(dtype=Reservoir),
        s_t: GISamples,
        res_s_prev: wp.array2d(dtype=Reservoir),
        s_s_prev: GISamples,
        kept: wp.array2d(dtype=wp.int32),
        domains: wp.array3d(dtype=wp.int32),
        domain_count: wp.array2d(dtype=wp.int32),
        res_out: wp.array2d(dtype=Reservoir),
        s_out: GISamples,
    ):
        y, x = wp.tid()
        count = int(domain_count[y, x])
        if count < 0:
            return  # not resampled: the resample stage copied the temporal reservoir through
        si = sf.si[y, x]
        wo = sf.wo[y, x]
        out = res_out[y, x]
        code = kept[y, x]
        sel = gi_sample_none()
        if code == KEPT_OWN:
            sel = gi_load(s_t, y, x)
        elif code != KEPT_NONE:
            sel = domain_of(sf, code, temporal_cap, spatial_cap, res_t, s_t, res_s_prev, s_s_prev).sample
        # ---- Alg. 4 l. 15–19: Z = confidence of the domains that can produce the kept sample ----
        z = support_count_term(confidence_capped(res_t[y, x].confidence, temporal_cap), out.target)
        if sel.valid != 0:
            for j in range(count):
                c = domains[y, x, j]
                n = domain_of(sf, c, temporal_cap, spatial_cap, res_t, s_t, res_s_prev, s_s_prev)
                test_support = unbiased * shift_tests_visibility(scene, c, n.si, si)
                if n.res.confidence > 0.0:
                    # the kept sample's own domain supports it without a ray: its reservoir's target is p̂ of that
                    # very sample at its visible point, visibility included (a kept sample has target > 0)
                    own = c == code
                    if own:
                        test_support = 0
                    previous = domain_of_last_frame(c)  # a domain of last frame, in last frame's scene
                    counts = domain_counts(frame_scene(scene, scene_prev, previous), n.si, n.wo, si, wo, sel, target_mode, test_support, unbiased,
                                           max_jacobian, previous)
                    z = support_count(z, n.res.confidence, counts and (not own or n.res.target > 0.0))
        out = reservoir_finalize_mis(out, support_mis(1.0, out.target, z))
        res_out[y, x] = out
        gi_store(s_out, y, x, sel)

    # ---- mis=pairwise in two stages: the canonical sample's weight against each domain, then the merge ----
    @wp.kernel(module=module, cuda_max_registers=PATH_REGISTERS)
    def spatial_canonical_pass(
        scene: SceneData,
        scene_prev: SceneData,
        sf: ScreenFrame,
        use_history: int,
        temporal_cap: float,
        spatial_cap: float,
        iterations_low: int,
        iterations_high: int,
        adaptive: int,
        radius: float,
        min_radius: float,
        low_m: float,
        target_mode: int,
        unbiased: int,
        use_jacobian: int,
        max_jacobian: float,
        res_t: wp.array2d(dtype=Reservoir),
        s_t: GISamples,
        res_s_prev: wp.array2d(dtype=Reservoir),
        s_s_prev: GISamples,
        res_out: wp.array2d(dtype=Reservoir),
        s_out: GISamples,
        domains: wp.array3d(dtype=wp.int32),
        slots: wp.array3d(dtype=wp.int32),
        domain_count: wp.array2d(dtype=wp.int32),
        m_canonical: wp.array2d(dtype=float),
    ):
        y, x = wp.tid()
        key = pixel_key(sf, x, y, 4)
        r_c = res_t[y, x]
        si = sf.si[y, x]
        domain_count[y, x] = -1
        if si.valid == 0 or r_c.confidence <= 0.0:
            res_out[y, x] = r_c  # not resampled: passed through
            gi_store(s_out, y, x, gi_load(s_t, y, x))
            return
        wo = sf.wo[y, x]
        # ---- the domains, drawn once into the DomainList (the merge stage reads the same ones) ----
        plan = spatial_plan(sf, x, y, use_history, spatial_cap, iterations_low, iterations_high, low_m, res_s_prev)
        k = draw_spatial_domains(sf, plan, x, y, key, adaptive, radius, min_radius, domains, slots)
        c_c = confidence_capped(r_c.confidence, temporal_cap)
        total = c_c + domains_confidence(sf, x, y, k, temporal_cap, spatial_cap, res_t, res_s_prev, domains)
        # ---- m_c = Σ_i (pair i's share of the canonical sample): y_c carried to each domain ----
        y_c = gi_load(s_t, y, x)
        m_c = pairwise_mis_canonical_term(0.0, 0.0, c_c, r_c.target, 0, total)  # no domain: 1
        if k > 0:
            m_c = float(0.0)
        if r_c.ucw <= 0.0:
            k_rays = 0  # the canonical sample weighs m_c · p̂ · W = 0 whatever m_c is: no ray to trace for it
        else:
            k_rays = k
        for j in range(k_rays):
            code = domains[y, x, j]
            n = domain_of(sf, code, temporal_cap, spatial_cap, res_t, s_t, res_s_prev, s_s_prev)
            test = unbiased * shift_tests_visibility(scene, code, n.si, si)
            previous = domain_of_last_frame(code)  # p̂_{←j}(y_c), each domain in its own frame's scene
            t_cj = target_at_domain(frame_scene(scene, scene_prev, previous), n.si, n.wo, si, wo, y_c, target_mode, test, use_jacobian, max_jacobian,
                                    previous)
            m_c += pairwise_mis_canonical_term(n.res.confidence, t_cj, c_c, r_c.target, k, total)
        m_canonical[y, x] = m_c
        domain_count[y, x] = k

    @wp.kernel(module=module, cuda_max_registers=PATH_REGISTERS)
    def spatial_merge_pass(
        scene: SceneData,
        sf: ScreenFrame,
        temporal_cap: float,
        spatial_cap: float,
        target_mode: int,
        use_jacobian: int,
        max_jacobian: float,
        res_t: wp.array2d(dtype=Reservoir),
        s_t: GISamples,
        res_s_prev: wp.array2d(dtype=Reservoir),
        s_s_prev: GISamples,
        domains: wp.array3d(dtype=wp.int32),
        slots: wp.array3d(dtype=wp.int32),
        domain_count: wp.array2d(dtype=wp.int32),
        m_canonical: wp.array2d(dtype=float),
        res_out: wp.array2d(dtype=Reservoir),
        s_out: GISamples,
    ):
        y, x = wp.tid()
        k = int(domain_count[y, x])
        if k < 0:
            return  # not resampled: the canonical stage passed the temporal reservoir through
        key = pixel_key(sf, x, y, 4)
        si = sf.si[y, x]
        wo = sf.wo[y, x]
        r_c = res_t[y, x]
        c_c = confidence_capped(r_c.confidence, temporal_cap)
        total = c_c + domains_confidence(sf, x, y, k, temporal_cap, spatial_cap, res_t, res_s_prev, domains)
        # ---- the canonical sample with weight m_c, then each domain's sample reconnected here (Alg. 4 l. 11–12),
        # weighed against the canonical domain only (pairwise MIS: Bitterli 2022, Ch. 9; seed 000, Eq. 9) ----
        out = reservoir_empty()
        r_c.confidence = c_c
        out = reservoir_merge(out, r_c, m_canonical[y, x], r_c.target, 1.0, random_uniform(key, 1))
        sel = int(KEPT_NONE)
        if out.selected:
            sel = KEPT_OWN
        for j in range(k):
            code = domains[y, x, j]
            n = domain_of(sf, code, temporal_cap, spatial_cap, res_t, s_t, res_s_prev, s_s_prev)
            across = int(domain_flags(code) != 0)
            sh = gi_shift_none()  # a reservoir of weight W = 0 adds its confidence alone (as in the temporal pass): no ray
            if n.res.ucw > 0.0:
                sh = reconnect(scene, n.si, n.wo, si, wo, n.sample, target_mode, shift_tests_visibility(scene, code, n.si, si), use_jacobian,
                               max_jacobian, across)
            t_jj = target_back(n.res.target, sh.jacobian)  # p̂_{←j} of its own shifted sample: its target at home over |J| (1 without)
            m_j = pairwise_mis_neighbor(n.res.confidence, t_jj, c_c, sh.target, k, total)
            out = reservoir_merge(out, n.res, m_j, sh.target, sh.jacobian, spatial_domain_u(key, slots[y, x, j]))
            if out.selected:
                sel = code
        out = reservoir_finalize(out)  # W = Σ w / p̂(y): every weight was applied before selection
        res_out[y, x] = out
        if sel == KEPT_OWN:
            gi_store(s_out, y, x, gi_load(s_t, y, x))
        elif sel != KEPT_NONE:
            gi_store(s_out, y, x, domain_of(sf, sel, temporal_cap, spatial_cap, res_t, s_t, res_s_prev, s_s_prev).sample)
        else:
            gi_store(s_out, y, x, gi_sample_none())

    @wp.kernel(module=module)
    def shade_pass(
        scene: SceneData,
        sf: ScreenFrame,
        target_mode: int,
        base: wp.array2d(dtype=wp.vec3),
        res: wp.array2d(dtype=Reservoir),
        samples: GISamples,
        direct: wp.array2d(dtype=wp.vec3),
        use_direct: int,
        image: wp.array2d(dtype=wp.vec3),
        nonfinite: wp.array(dtype=wp.int32),
    ):
        y, x = wp.tid()
        L = base[y, x]
        if use_direct != 0:
            L += direct[y, x]
        r = res[y, x]
        if r.ucw > 0.0:
            ev = gi_eval(scene, sf.si[y, x], sf.wo[y, x], gi_load(samples, y, x), target_mode)
            L += ev.rgb * r.ucw  # seed 004, Eq. 8 (with Eq. 6's W from the spatial reservoir)
        write_pixel(image, nonfinite, y, x, L)

    return types.SimpleNamespace(
        gi_eval=gi_eval, validate_pass=validate_pass, direct_pass=direct_pass, initial_pass=initial_pass,
        sample_radiance_pass=sample_radiance_pass, initial_target_pass=initial_target_pass, temporal_pass=temporal_pass, spatial_resample_pass=spatial_resample_pass,
        spatial_mis_pass=spatial_mis_pass, spatial_canonical_pass=spatial_canonical_pass, spatial_merge_pass=spatial_merge_pass,
        shade_pass=shade_pass
    )


class ReSTIRGI(ScreenSpaceRenderer):
    """ReSTIR GI over a built scene; ``render_frame(frame)`` returns the full image (H×W×3, linear)."""

    def __init__(
        self,
        built: Any,
        width: int,
        height: int,
        *,
        seed: int = 0,
        source: str = "bsdf",
        target: str = "full",
        jacobian: bool = True,
        unbiased: bool = True,
        mis: str = "pairwise",
        temporal: bool = True,
        spatial: bool = True,
        history_cap: float = 10.0,
        spatial_cap: float = 30.0,
        iterations_low: int = 9,
        iterations_high: int = 3,
        adaptive_radius: bool = True,
        radius: float = 30.0,
        min_radius: float = 3.0,
        low_m: float = 10.0,
        max_depth: int = 16,
        rr_depth: int = 5,
        mb_fraction: float = 0.25,
        validation_interval: int = 6,
        validation_tolerance: float = 0.2,
        direct: str = "auto",
        exact_bsdf: bool = False,
        max_jacobian: float = 10.0,
        jitter: bool = True,
        timer: Any = None,
    ) -> None:
        self.built = built
        self.width, self.height = int(width), int(height)
        self.seed = int(seed)
        self.source = SOURCES[source]
        self.target = TARGETS[target]
        self.jacobian = int(bool(jacobian))
        self.unbiased = int(bool(unbiased))
        self.mis = MIS[mis]
        self.temporal = bool(temporal)
        self.spatial = bool(spatial)
        self.history_cap = float(history_cap)  # the M cap of temporal reservoirs (the paper's temporal cap)
        self.spatial_cap = float(spatial_cap)
        self.iterations_low = int(iterations_low)
        self.iterations_high = int(iterations_high)
        self.adaptive = int(bool(adaptive_radius))
        self.radius = float(radius)
        self.min_radius = float(min_radius)
        self.low_m = float(low_m)
        self.max_depth = int(max_depth)
        self.rr_depth = int(rr_depth)
        self.mb_fraction = float(mb_fraction)
        self.validation_interval = int(validation_interval)
        self.validation_tolerance = float(validation_tolerance)
        self.direct_name = resolve_direct(direct, built, self.max_depth)
        self.direct = DIRECT[self.direct_name]
        self.resolved_params = {"direct": self.direct_name}  # what "auto" became, for render --json
        self.exact_bsdf = int(bool(exact_bsdf))
        self.max_jacobian = float(max_jacobian)
        self.jitter = bool(jitter)
        self.timer = timer
        self.k = make_restir_gi_kernels(built.features.kernel_kinds, bool(self.exact_bsdf))
        dev = self.device = built.device
        shape = (self.height, self.width)
        self.di = None
        if self.direct == DIRECT["restir-di"]:
            # composed through the registry, not imported: renderers do not import each other
            from grisx.render.base.registry import METHODS, RenderContext

            ctx = RenderContext(built, width, height, {"jitter": jitter}, seed + 7919, timer, "restir-di")
            self.di = METHODS["restir-di"].create(ctx)
            self.gbuffer = self.di.gbuffer
        else:
            self.gbuffer = GBuffer(self.width, self.height, dev, material=self.GBUFFER_MATERIAL)
        moving = SCENE_MOVING_OBJECTS in built.features.kernel_kinds  # the samples keep their boxes

        def pair() -> tuple[wp.array, GISamples]:
            """A reservoir buffer and its sample buffer."""
            return wp.zeros(shape, dtype=Reservoir, device=dev), gi_samples(self.height, self.width, self.exact_bsdf != 0, moving, dev)

        self.initial = pair()  # the initial sample buffer (as one-sample reservoirs)
        self.temporal_buf = DoubleBuffer(pair)  # temporal reservoir buffer
        self.spatial_buf = DoubleBuffer(pair)  # spatial reservoir buffer
        # the spatial pass's two stages share the domains drawn and the kept sample's domain
        self.domains = DomainList(self.height, self.width, max(self.iterations_low, self.iterations_high) + 1, dev)
        self.kept = wp.zeros(shape, dtype=wp.int32, device=dev)
        self.m_canonical = wp.zeros(shape, dtype=float, device=dev)  # mis=pairwise: the canonical sample's weight
        # the initial stages hand over p_q of the direction and the hit at x_s (the path tracer starts there)
        self.source_pdf = wp.zeros(shape, dtype=float, device=dev)
        self.sample_hit = wp.zeros(shape, dtype=SurfaceInteraction, device=dev)  # x_s, from the initial pass to the path tracer
        self.base = wp.zeros(shape, dtype=wp.vec3, device=dev)
        self.image = wp.zeros(shape, dtype=wp.vec3, device=dev)
        self.nonfinite = wp.zeros(1, dtype=wp.int32, device=dev)
        self.frames_rendered = 0

    def reset(self, seed: int | None = None) -> None:
        """Forget all history (the next frame starts fresh), optionally with a new seed: an independent run."""
        super().reset(seed)
        if self.di is not None:
            self.di.reset(None if seed is None else int(seed) + 7919)

    def kernels(self) -> list[Any]:
        radiance = self.k.sample_radiance_pass
        ks = [self.gbuffer.kernel(self.built), self.k.validate_pass, self.k.direct_pass, self.k.initial_pass, radiance, self.k.initial_target_pass,
              self.k.temporal_pass, *self._spatial_kernels(), self.k.shade_pass]
        return ks + (self.di.kernels() if self.di is not None else [])

    def _spatial_kernels(self) -> list[Any]:
        if self.mis == MIS["pairwise"]:
            return [self.k.spatial_canonical_pass, self.k.spatial_merge_pass]
        return [self.k.spatial_resample_pass, self.k.spatial_mis_pass]

    def render_frame(self, frame: int) -> wp.array:
        dim = (self.height, self.width)
        dev = self.device
        data = self.built.data
        history = int(self.frames_rendered > 0)
        if self.di is not None:
            self.di.prepare(frame)
        else:
            with self._phase("gbuffer"):
                self.gbuffer.fill(self.built, float(frame), self.seed, self.jitter)
        sf = screen_frame(self.gbuffer, self.seed, frame)
        self.temporal_buf.swap()
        self.spatial_buf.swap()
        validate_now = int(
            history
            and self.validation_interval > 0
            and frame % self.validation_interval == 0
            and self.built.features.animated_objects  # else nothing can change: the replay would be bit-exact
        )
        if validate_now:
            with self._phase("gi_validate"):
                launch(
                    self.k.validate_pass,
                    dim=dim,
                    inputs=[data, sf, self.max_depth, self.rr_depth, self.mb_fraction, self.validation_tolerance],
                    outputs=[self.temporal_buf.previous[0], self.temporal_buf.previous[1], self.spatial_buf.previous[0], self.spatial_buf.previous[1]],
                    device=dev,
                )
        with self._phase("gi_direct"):
            launch(self.k.direct_pass, dim=dim, inputs=[data, sf, self.max_depth, self.rr_depth, self.direct], outputs=[self.base], device=dev)
        with self._phase("gi_initial"):
            launch(
                self.k.initial_pass,
                dim=dim,
                inputs=[data, sf, self.source, self.max_depth, self.mb_fraction],
                outputs=[self.initial[0], self.initial[1], self.source_pdf, self.sample_hit],
                device=dev,
            )
            launch(
                self.k.sample_radiance_pass,
                dim=dim,
                inputs=[data, self.max_depth, self.rr_depth, self.mb_fraction, self.sample_hit],
                outputs=[self.initial[1]],
                device=dev,
            )
            launch(
                self.k.initial_target_pass,
                dim=dim,
                inputs=[data, sf, self.target, self.source_pdf, self.initial[1]],
                outputs=[self.initial[0]],
                device=dev,
            )
        t_out = self.temporal_buf.current
        # this frame's geometry knowing what moved since the last, and the last frame's: shifts from last
        # frame's domains and their Z tests (each domain in its own frame's scene)
        scene, scene_prev = self.built.across_frames()
        with self._phase("gi_temporal"):
            launch(
                self.k.temporal_pass,
                dim=dim,
                inputs=[
                    scene, scene_prev, sf, int(history and self.temporal), self.history_cap, self.target, self.jacobian, self.unbiased,
                    self.max_jacobian, self.mis, self.initial[0], self.initial[1], self.temporal_buf.previous[0],
                    self.temporal_buf.previous[1],
                ],
                outputs=[t_out[0], t_out[1]],
                device=dev,
            )
        s_out = self.spatial_buf.current
        if self.spatial and self.mis == MIS["pairwise"]:
            with self._phase("gi_spatial"):
                launch(
                    self.k.spatial_canonical_pass,
                    dim=dim,
                    inputs=[
                        scene, scene_prev, sf, history, self.history_cap, self.spatial_cap, self.iterations_low, self.iterations_high,
                        self.adaptive, self.radius, self.min_radius, self.low_m, self.target, self.unbiased, self.jacobian,
                        self.max_jacobian, t_out[0], t_out[1], self.spatial_buf.previous[0], self.spatial_buf.previous[1],
                    ],
                    outputs=[s_out[0], s_out[1], self.domains.codes, self.domains.slots, self.domains.count, self.m_canonical],
                    device=dev,
                )
                launch(
                    self.k.spatial_merge_pass,
                    dim=dim,
                    inputs=[
                        scene, sf, self.history_cap, self.spatial_cap, self.target, self.jacobian, self.max_jacobian,
                        t_out[0], t_out[1], self.spatial_buf.previous[0], self.spatial_buf.previous[1],
                        self.domains.codes, self.domains.slots, self.domains.count, self.m_canonical,
                    ],
                    outputs=[s_out[0], s_out[1]],
                    device=dev,
                )
        elif self.spatial:
            with self._phase("gi_spatial"):
                launch(
                    self.k.spatial_resample_pass,
                    dim=dim,
                    inputs=[
                        scene, sf, history, self.history_cap, self.spatial_cap, self.iterations_low, self.iterations_high,
                        self.adaptive, self.radius, self.min_radius, self.low_m, self.target, self.jacobian,
                        self.max_jacobian, t_out[0], t_out[1], self.spatial_buf.previous[0], self.spatial_buf.previous[1],
                    ],
                    outputs=[s_out[0], s_out[1], self.kept, self.domains.codes, self.domains.slots, self.domains.count],
                    device=dev,
                )
                launch(
                    self.k.spatial_mis_pass,
                    dim=dim,
                    inputs=[
                        scene, scene_prev, sf, self.history_cap, self.spatial_cap, self.target, self.unbiased, self.max_jacobian,
                        t_out[0], t_out[1], self.spatial_buf.previous[0], self.spatial_buf.previous[1],
                        self.kept, self.domains.codes, self.domains.count,
                    ],
                    outputs=[s_out[0], s_out[1]],
                    device=dev,
                )
        else:
            wp.copy(s_out[0], t_out[0])
            gi_samples_copy(s_out[1], t_out[1])
        direct = self.base
        if self.di is not None:
            direct = self.di.direct_light(frame)
        with self._phase("gi_shade"):
            launch(
                self.k.shade_pass,
                dim=dim,
                inputs=[data, sf, self.target, self.base, s_out[0], s_out[1], direct, int(self.di is not None)],
                outputs=[self.image, self.nonfinite],
                device=dev,
            )
        self.frames_rendered += 1
        return self.image

    @property
    def nonfinite_samples(self) -> int:
        """Pixels whose estimate was NaN/Inf and was dropped (over the renderer's lifetime; 0 expected)."""
        return super().nonfinite_samples + (self.di.nonfinite_samples if self.di is not None else 0)


def create_restir_gi(ctx: Any) -> ReSTIRGI:
    return create_renderer(ReSTIRGI, ctx)


# ---- registration (grisx.render.base.registry): the method, its params (defaults: the constructor's) ----

register(
    RenderMethod(
        "restir-gi",
        "ReSTIR GI (seed 004): sample points resampled in temporal and spatial reservoir buffers with the reconnection Jacobian (Eq. 11); full global illumination",
        create_restir_gi,
        params=renderer_params(
            ReSTIRGI,
            Param("source", ..., "initial direction pdf (Alg. 2)", kind="choice", choices=("uniform", "cosine", "bsdf")),
            Param("target", ..., "full: Eq. 9 (L_o f cos); radiance: Eq. 10 (L_o)", kind="choice", choices=("full", "radiance")),
            Param("jacobian", ..., "reconnection Jacobian of Eq. 11 (false reproduces Fig. 7's bias)", kind="bool"),
            Param("unbiased", ..., "true: each domain's support tested with a visibility ray (Alg. 4 l. 16-19); false: every domain assumed to see every sample (biased)", kind="bool"),
            Param("mis", ..., "reuse weights: pairwise (each candidate weighed against this pixel's own sample before selection) or support (the paper: 1/Z of the kept sample)", kind="choice", choices=("pairwise", "support")),
            Param("temporal", ..., "temporal resampling (Alg. 3)", kind="bool"),
            Param("spatial", ..., "spatial resampling (Alg. 4)", kind="bool"),
            Param("history_cap", ..., "M cap of temporal reservoirs (the history cap; the paper's temporal cap)", minimum=0.0),
            Param("spatial_cap", ..., "M cap of spatial reservoirs", minimum=0.0),
            Param("iterations_low", ..., "maxIterations while the spatial reservoir's M < spatial_cap/2", kind="int", minimum=0, maximum=64),
            Param("iterations_high", ..., "maxIterations otherwise", kind="int", minimum=0, maximum=64),
            Param("adaptive_radius", ..., "radius 10% of the image, halved per rejected neighbour down to min_radius; false: fixed radius", kind="bool"),
            Param("radius", ..., "fixed spatial radius in pixels (adaptive_radius=false)", minimum=1.0),
            Param("min_radius", ..., "smallest adaptive radius in pixels", minimum=1.0),
            Param("low_m", ..., "a pixel whose spatial reservoir has M below this reuses neighbours' spatial reservoirs (Fig. 10); 0: never", minimum=0.0),
            Param("max_depth", ..., "longest path in segments from the camera, Mitsuba's meaning (as pt); default: the scene's", kind="int", minimum=-1),
            Param("rr_depth", ..., "depth from which Russian roulette may end the paths at sample points", kind="int", minimum=1),
            Param("mb_fraction", ..., "probability that a 64x32 tile follows multi-bounce paths (tile Russian roulette)", minimum=1e-3, maximum=1.0),
            Param("validation_interval", ..., "replay and validate reservoir samples every N frames; 0: never", kind="int", minimum=0),
            Param("validation_tolerance", ..., "relative change of L_o that invalidates a sample", minimum=0.0),
            Param("direct", ..., "direct light: nee (path-traced, NEE + BSDF with MIS), restir-di, or auto (restir-di above 16 lights: where it is better, measured)", kind="choice", choices=("auto", "nee", "restir-di")),
            Param("exact_bsdf", ..., "re-evaluate the sample point's BSDF toward each visible point reusing it; false: its radiance reused as if Lambertian (the paper)", kind="bool"),
            Param("max_jacobian", ..., "reject reconnections with |J| above this (counted the same way in Z: still unbiased); 0: never (the paper)", minimum=0.0),
            Param("jitter", ..., "visible point uniform over the pixel each frame (box filter: what pt estimates); false: pixel centres", kind="bool"),
        ),
    )
)
