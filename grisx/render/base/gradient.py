"""Gradient images from per-pixel path samples, and their screened-Poisson reconstruction.

Every gradient-domain renderer ends the same way: a primal image P, the forward differences
dx[y, x] ≈ I[y, x+1] − I[y, x] and dy[y, x] ≈ I[y+1, x] − I[y, x] (the convention of
:mod:`grisx.poisson.gradient`), and the screened Poisson image of the three (L2 or L1, α = 0.2),
which is what the renderer returns as its frame. :class:`GradientFrame` holds these buffers on
the device and the reconstruction's settings; the renderers keep a :class:`~grisx.poisson.ScreenedPoisson`
bound to them (buffers and CUDA graph made once; on the CPU, L2 is the exact DCT solve), timed as the phase
``reconstruction``: it counts in the frame time, as in seed 000, Sec. 5.

**Gradients from primal samples** (``# ---- gradients from primal samples ----``): the estimator
of Gradient-domain path tracing (Kettunen et al. 2015; B.2) and of *Gradient after ReSTIR*
(seed 000, Sec. 4.1; B.1). Pixel a holds one sample (u, y) with UCW W — a path tracer's
RIS-chosen path, or ReSTIR's kept path — and shifts it to each of its four neighbours b: the
film sample keeps u in b (``area_domain`` of :func:`~grisx.render.base.area.make_area_domain`) and the path is shifted
from there (the *inner shift* T_ab, the hybrid shift of :mod:`~grisx.render.base.path_shift`).
For the pair (i, j) = (left, right) or (top, bottom) with Δ_ij = I_i − I_j (seed 000, Eq. 1),
pixel a contributes

    ⟨Δ_ij⟩_a = ω*_ij(y, k) G_ij(y, k) · W_y                          (seed 000, Eq. 11, 14–16)

with k = 0 if a = i, k = 1 if a = j; ω* is the balance heuristic on the two pixels' targets
p̂ = luminance(m_t f) (Eq. 13: the pdfs of Eq. 4 are unknown after resampling), and
:func:`~grisx.theory.gradient.pair_value` / :func:`~grisx.theory.gradient.pair_estimate` compute
it, the functions the ``f1-f2`` toy is verified with. Δ_ij is the sum of the two pixels' parts,
and dx[i] = −Δ_{i,i+x̂}. The emission seen directly at x₁ is the path of length 0: its pair value
uses the film densities, equal on both sides (a translation), so ω* = ½ there (Eq. 4).
Unbiased wherever W is an unbiased contribution weight over the pixel's whole domain
(seed 000, Sec. 4.1): ω*G vanishes where p̂_a does, and ω_ij(x) + ω_ji(T_ij x) = 1.

References: seed 000 (Wang et al., Gradient-domain ReSTIR Path Tracing), Eq. 1, 11–16; Kettunen et
al., "Gradient-domain path tracing", 2015; :mod:`grisx.poisson`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import warp as wp

from grisx.device import launch, specialized_module
from grisx.errors import InvalidParameterError
from grisx.render.base.area import FilmSample, make_area_domain
from grisx.render.base.path_shift import PathReservoir, ShiftParams, make_path_shift, path_target
from grisx.render.base.screen import kernel_cache
from grisx.scene.camera import CameraData
from grisx.scene.scene import SceneData, finite_or_dropped
from grisx.theory.gradient import PAIR_BASE_I, PAIR_BASE_J, pair_estimate, pair_value, shifted_difference

wp.set_module_options({"enable_backward": False})

__all__ = ["GradientFrame", "make_gradient_kernels", "RECONSTRUCTIONS", "NEIGHBOR_OFFSETS", "DIFFERENCES_NONE", "DIFFERENCES_EMISSION", "DIFFERENCES_PATHS"]

#: the reconstruction norms (grisx.poisson's L2 and L1), as --param reconstruction=l2|l1
RECONSTRUCTIONS = {"l2": "L2", "l1": "L1"}
#: what the gradient pass adds to a pixel's halves besides its primal: nothing (the caller adds the differences itself),
#: the emission's differences alone, or those and the kept path's (the ``differences`` argument)
DIFFERENCES_NONE = wp.constant(0)
DIFFERENCES_EMISSION = wp.constant(1)
DIFFERENCES_PATHS = wp.constant(2)
#: the four neighbours of a pixel, in the order of the half-gradient slots: right, left, down, up
NEIGHBOR_OFFSETS = ((1, 0), (-1, 0), (0, 1), (0, -1))


@wp.func
def _neighbor(slot: int) -> wp.vec2i:
    if slot == 0:
        return wp.vec2i(1, 0)
    if slot == 1:
        return wp.vec2i(-1, 0)
    if slot == 2:
        return wp.vec2i(0, 1)
    return wp.vec2i(0, -1)


@wp.func
def _pair_side(slot: int) -> int:
    """k of pixel a in its pair with neighbour ``slot``: a is i (left/top, k = 0) toward right/down, j (k = 1) toward left/up."""
    if slot == 0 or slot == 2:
        return PAIR_BASE_I
    return PAIR_BASE_J


@kernel_cache
def make_gradient_kernels(kinds: frozenset[int]) -> dict[str, Any]:
    """The gradient passes compiled for the material kinds ``kinds`` (cached)."""
    shift = make_path_shift(kinds).shift
    area_domain = make_area_domain(kinds)
    module = specialized_module(__name__, kinds)

    # ---- gradients from primal samples ----
    @wp.kernel(module=module)
    def gradient_pass(
        scene: SceneData,
        cam: CameraData,
        sp: ShiftParams,
        scale: float,
        differences: int,
        symmetric: int,
        film_direct: wp.array2d(dtype=FilmSample),
        film: wp.array2d(dtype=FilmSample),
        direct: wp.array2d(dtype=wp.vec3),
        reservoirs: wp.array2d(dtype=PathReservoir),
        primal: wp.array2d(dtype=wp.vec3),
        halves: wp.array3d(dtype=wp.vec3),
        nonfinite: wp.array(dtype=wp.int32),
    ):
        """Add ``scale`` × pixel a's primal estimate L_e + f(y) W_y and its four parts ⟨Δ⟩_a (Eq. 11).

        ``direct`` is L_e seen by the film sample ``film_direct`` (the canonical one); ``film`` holds the
        film samples of the ``reservoirs``' kept paths (the same array when nothing was reused). ``differences``:
        :data:`DIFFERENCES_PATHS` the emission's and the kept path's, :data:`DIFFERENCES_EMISSION` the emission's alone,
        :data:`DIFFERENCES_NONE` none (ReSTIR G-PT adds the emission's in its pair pass and resamples the paths' own);
        ``symmetric`` = 0 is the one-sided Eq. 2 (pixel i alone, ω = 1): biased where T_ij is partial.
        """
        y, x = wp.tid()
        h = film.shape[0]
        w = film.shape[1]
        pr = reservoirs[y, x]
        fs = film[y, x]
        fs_direct = film_direct[y, x]
        le = direct[y, x]
        has_path = pr.res.ucw > 0.0 and pr.path.length > 0
        L = le
        if has_path:
            L = L + pr.path.f * pr.res.ucw  # f(y) · W_y (seed 000, Eq. 7)
        primal[y, x] = primal[y, x] + finite_or_dropped(L, nonfinite) * scale
        t_a = path_target(pr.path)
        same_film = fs.offset == fs_direct.offset and fs.lens == fs_direct.lens
        slots = int(4)  # a dynamic bound: Warp unrolls a constant range, and this body inlines a shift and two camera rays
        if differences == DIFFERENCES_NONE:
            slots = 0
        for slot in range(slots):
            o = _neighbor(slot)
            bx = x + o[0]
            by = y + o[1]
            if bx < 0 or bx >= w or by < 0 or by >= h:
                continue
            k = _pair_side(slot)
            ad = area_domain(scene, cam, bx, by, fs_direct)  # u kept in pixel b: a film translation, |J| = 1
            # emission at x₁ (a path of length 0): equal film densities on both sides, ω* = ½ (Eq. 4)
            d = pair_value(k, le, ad.emission, 1.0, 1.0, 1.0, True)
            if has_path and differences == DIFFERENCES_PATHS:
                if not same_film:
                    ad = area_domain(scene, cam, bx, by, fs)  # the kept sample came from another film sample
                s = shift(scene, ad.dom, pr.path, sp)  # the inner shift T_ab (hybrid)
                v = pair_value(k, pr.path.f, s.path.f, t_a, path_target(s.path), s.jacobian, s.valid)  # Eq. 13–16
                if symmetric == 0:
                    v = wp.vec3(0.0)
                    if k == PAIR_BASE_I:
                        v = shifted_difference(pr.path.f, s.path.f, s.jacobian, s.valid)  # Eq. 2, one-sided
                d = d + pair_estimate(v, pr.res.ucw)  # Eq. 11
            halves[slot, y, x] = halves[slot, y, x] + finite_or_dropped(d, nonfinite) * scale

    @wp.kernel(module=module)
    def combine_pass(halves: wp.array3d(dtype=wp.vec3), dx: wp.array2d(dtype=wp.vec3), dy: wp.array2d(dtype=wp.vec3)):
        """dx[a] = −(⟨Δ⟩_a + ⟨Δ⟩_{a+x̂}) = I[a+x̂] − I[a] (Eq. 1; 0 in the last column), dy likewise."""
        y, x = wp.tid()
        h = dx.shape[0]
        w = dx.shape[1]
        gx = wp.vec3(0.0)
        gy = wp.vec3(0.0)
        if x + 1 < w:
            gx = -(halves[0, y, x] + halves[1, y, x + 1])
        if y + 1 < h:
            gy = -(halves[2, y, x] + halves[3, y + 1, x])
        dx[y, x] = gx
        dy[y, x] = gy

    return {"gradient": gradient_pass, "combine": combine_pass}


class GradientFrame:
    """A frame's primal, dx and dy on the device, their parts from every pixel, and the reconstruction's norm and α."""

    def __init__(self, width: int, height: int, device: Any, reconstruction: str = "l2", alpha: float = 0.2) -> None:
        if reconstruction not in RECONSTRUCTIONS:
            raise InvalidParameterError(f"reconstruction must be one of {', '.join(RECONSTRUCTIONS)}, not '{reconstruction}'")
        if not alpha > 0.0:
            raise InvalidParameterError(f"the screened Poisson weight alpha must be > 0, got {alpha}")
        shape = (height, width)
        self.device = device
        self.norm = RECONSTRUCTIONS[reconstruction]
        self.alpha = float(alpha)
        self.primal = wp.zeros(shape, dtype=wp.vec3, device=device)
        self.halves = wp.zeros((4, height, width), dtype=wp.vec3, device=device)
        self.dx = wp.zeros(shape, dtype=wp.vec3, device=device)
        self.dy = wp.zeros(shape, dtype=wp.vec3, device=device)
        self.image = self.primal

    def begin(self) -> None:
        """Zero the sums of a new frame."""
        self.primal.zero_()
        self.halves.zero_()

    def gradients(self, kernels: dict[str, Any]) -> None:
        """dx and dy from the pixels' parts (after the last ``gradient`` pass of the frame)."""
        launch(kernels["combine"], dim=self.dx.shape, inputs=[self.halves], outputs=[self.dx, self.dy], device=self.device)

    def extra(self) -> dict[str, np.ndarray]:
        """The last frame's primal, dx and dy (the render CLI writes them as EXRs beside the image)."""
        return {"primal": self.primal.numpy(), "dx": self.dx.numpy(), "dy": self.dy.numpy()}
