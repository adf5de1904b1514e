"""Gradients from primal samples: gradient-domain path tracing (B.2) and Gradient after ReSTIR (B.1).

The two baselines of seed 000 (Sec. 4.1, 5) estimate the differences between adjacent pixels
from each pixel's *primal* sample, shifted to its four neighbours by the inner shift — the film
translation of :mod:`grisx.render.base.area` followed by the hybrid path shift — and weighted by
the paired-pixel MIS of :mod:`grisx.theory.gradient` (``pair_value``, ``pair_estimate``: the
functions the ``f1-f2`` toy is verified with). The estimator is written once, in
:mod:`grisx.render.base.gradient`; the two methods differ only in where the samples come from.
Each frame ends with the screened Poisson reconstruction (``reconstruction=l2|l1``, α =
``poisson_alpha``), which is the image returned; the primal, dx and dy images are
``extra()`` (the render CLI writes them as EXRs beside the image).

``gpt`` — **gradient-domain path tracing** (Kettunen et al. 2015 with the hybrid shift):
    ``spp`` independent samples per pixel, each the film sample (u, l) uniform over the pixel and
    lens, one traced path and the path chosen among its light connections by RIS (Area ReSTIR's
    canonical sample without any reuse: ``stream_candidates`` of
    :mod:`~grisx.render.base.path_shift`), with UCW W. Pixel a's base path y is shifted to each
    neighbour b and

        ⟨Δ_ab⟩_a = ω*(y, k) G(y, k) · W                                  (seed 000, Eq. 11, 14–16)

    the two pixels' parts summing to the difference; ω* is the balance heuristic of Eq. 4 written
    on the targets (Eq. 13). Differences from Kettunen et al.: one light connection per traced path
    is shifted (the RIS-chosen one) instead of every vertex's, and ω uses the targets p̂ = luminance(f)
    in place of the path pdfs (any ω with ω_ij(x) + ω_ji(T x) = 1 is unbiased).
``gradient-after-restir`` — **Gradient after ReSTIR** (seed 000, Sec. 4.1, Eq. 10–13):
    Area ReSTIR (:mod:`grisx.render.area_restir`) resamples each pixel in the primal domain; the
    kept sample (u, l, y) with its UCW W is shifted to the four neighbours and evaluated as above,
    W being an unbiased contribution weight of the whole pixel domain. The primal image is Area
    ReSTIR's own.

The emission seen directly at x₁ enters dx and dy as a path of length 0 from the canonical film
sample (ω* = ½, equal film densities on both sides). ``jacobian=false`` (|J| = 1 in every inner
shift) and ``symmetric=false`` (the one-sided Eq. 2: pixel i's base paths alone, ω = 1, which misses
the paths of pixel j that T_ij does not reach) are the known-biased siblings the tests catch.

References: seed 000 (Wang et al., Gradient-domain ReSTIR Path Tracing), Sec. 3.1, 4.1, Eq. 1–4,
10–16; M. Kettunen, M. Manzi, M. Aittala, J. Lehtinen, F. Durand, M. Zwicker, "Gradient-domain
path tracing", ACM TOG 34(4), 2015.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import warp as wp

from grisx.device import launch
from grisx.params import Param
from grisx.poisson import FrameReconstruction, frame_tol
from grisx.render.area_restir import AREA_KEYS, AreaReSTIR, area_params
from grisx.render.base.gradient import DIFFERENCES_PATHS, RECONSTRUCTIONS, GradientFrame, make_gradient_kernels
from grisx.render.base.registry import RenderMethod, create_renderer, register, renderer_params

wp.set_module_options({"enable_backward": False})

__all__ = ["GradientPT", "GradientAfterReSTIR", "create_gpt", "create_gradient_after_restir", "gradient_params"]


class GradientFromPrimal(AreaReSTIR):
    """What both baselines share: Area ReSTIR's samples, the gradient pass and the reconstruction."""

    def __init__(self, built: Any, width: int, height: int, *, reconstruction: str = "l2", poisson_alpha: float = 0.2, symmetric: bool = True,
                 frame_samples: int = 1, **area: Any) -> None:
        super().__init__(built, width, height, **area)
        self.symmetric = bool(symmetric)
        self.gradient = g = GradientFrame(self.width, self.height, built.device, reconstruction, poisson_alpha)
        self.gk = make_gradient_kernels(built.features.kernel_kinds)
        # the frame's reconstruction, as accurate as a frame of ``frame_samples`` samples a pixel needs
        self.poisson = FrameReconstruction(g.primal, g.dx, g.dy, alpha=g.alpha, norm=g.norm, tol=frame_tol(frame_samples))

    def kernels(self) -> list[Any]:
        return [*super().kernels(), *self.gk.values()]

    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        self.poisson.reset()  # a new sequence starts from its primal (what matters with warm starts on)

    def add_gradients(self, frame: int, reservoirs: wp.array, film: wp.array, scale: float, differences: int = DIFFERENCES_PATHS) -> None:
        """Add ``scale`` × the primal and the pixels' parts of dx, dy from the kept samples (film sample ``film``):
        ``differences`` says which parts (:data:`~grisx.render.base.gradient.DIFFERENCES_PATHS`: the emission's and the paths')."""
        cam, _ = self.cameras(frame)
        b = self.built
        with self._phase("gradients"):
            launch(
                self.gk["gradient"], dim=(self.height, self.width),
                inputs=[b.data, cam, self.shift_params, float(scale), int(differences), int(self.symmetric), self.films[3], film, self.direct, reservoirs],
                outputs=[self.gradient.primal, self.gradient.halves, self.nonfinite], device=b.device,
            )

    def finish(self) -> wp.array:
        """dx, dy from the parts and the screened Poisson image: the frame."""
        with self._phase("gradients"):
            self.gradient.gradients(self.gk)
        return self.reconstructed()

    #: false: frames return the primal and leave the reconstruction to the caller (a benchmark averaging instances first)
    reconstruct_frames = True

    def reconstructed(self) -> wp.array:
        """The screened Poisson image of this frame's primal, dx and dy (the frame), or the primal alone."""
        g = self.gradient
        if not self.reconstruct_frames:
            self.image = g.primal
            return self.image
        with self._phase("reconstruction"):
            self.image = self.poisson.solve()
        return self.image

    def extra(self) -> dict[str, np.ndarray]:
        return self.gradient.extra()


class GradientPT(GradientFromPrimal):
    """Gradient-domain path tracing (B.2): ``spp`` fresh samples per pixel and frame, no reuse (module docstring)."""

    on_sample: Any = None  # called after each sample pass (the driver's progress)

    def __init__(self, built: Any, width: int, height: int, *, spp: int = 1, **options: Any) -> None:
        super().__init__(built, width, height, temporal=False, spatial_rounds=0, frame_samples=max(1, int(spp)), **options)
        self.spp = int(spp)

    def render_frame(self, frame: int) -> wp.array:
        """``spp`` canonical samples per pixel, each shifted to the neighbours; then the reconstruction."""
        self.gradient.begin()
        for s in range(self.spp):
            cur, film = self.canonical(frame, stream_frame=frame * self.spp + s)
            self.add_gradients(frame, cur, film, 1.0 / self.spp)
            if self.on_sample is not None:  # the driver's progress within a frame
                self.on_sample()
        self.frames_rendered += 1
        return self.finish()


class GradientAfterReSTIR(GradientFromPrimal):
    """Gradient after ReSTIR (B.1): Area ReSTIR's kept samples shifted to the neighbours (module docstring)."""

    def render_frame(self, frame: int) -> wp.array:
        cur, film = self.resample(frame)
        self.gradient.begin()
        self.add_gradients(frame, cur, film, 1.0)
        return self.finish()


def create_gpt(ctx: Any) -> GradientPT:
    r = create_renderer(GradientPT, ctx)
    r.spp = int(ctx.params.get("spp", 1))
    return r


def create_gradient_after_restir(ctx: Any) -> GradientAfterReSTIR:
    return create_renderer(GradientAfterReSTIR, ctx)


def gradient_params(keep: tuple[str, ...] = AREA_KEYS, symmetric: bool = True) -> tuple[Param, ...]:
    """Area ReSTIR's params ``keep`` (its defaults), the reconstruction's and (``symmetric``) the one-sided ablation."""
    own = renderer_params(
        GradientFromPrimal,
        Param("reconstruction", ..., "screened Poisson reconstruction of the frame: l2 (unbiased) or l1 (robust, slightly biased)", kind="choice", choices=tuple(RECONSTRUCTIONS)),
        Param("poisson_alpha", ..., "weight alpha of the primal term of the screened Poisson reconstruction (Kettunen et al. 2015: 0.2)", minimum=1e-6),
        *((Param("symmetric", ..., "both pixels' base paths with MIS (Eq. 3-4, 13); false: the one-sided Eq. 2, biased where the inner shift is partial", kind="bool"),) if symmetric else ()),
    )
    return area_params(keep) + own


# ---- registration (grisx.render.base.registry) ----

register(
    RenderMethod(
        "gpt",
        "gradient-domain path tracing (Kettunen et al. 2015, seed 000's B.2): base paths shifted to the 4 neighbours by the hybrid shift, screened Poisson reconstruction",
        create_gpt,
        params=gradient_params(("shift", "candidates", "max_depth", "rr_depth", "rough_threshold", "near_field", "jacobian", "max_jacobian")),
        uses_spp=True,
    )
)
register(
    RenderMethod(
        "gradient-after-restir",
        "Gradient after ReSTIR (seed 000's B.1): Area ReSTIR's kept samples shifted to the 4 neighbours, screened Poisson reconstruction",
        create_gradient_after_restir,
        params=gradient_params(),
    )
)
