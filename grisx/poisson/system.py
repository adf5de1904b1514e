"""A screened Poisson system that lives as long as a renderer: one reconstruction per frame, at no setup cost.

:func:`grisx.poisson.solve` is a one-off: it checks its inputs, allocates a dozen device
buffers, captures a CUDA graph, solves and measures. A gradient-domain renderer reconstructs
*every frame* from the same three buffers, and seed 000 (Sec. 5) counts that reconstruction in
the frame time (11 ms for L2, 300 ms for L1 at 1080p). :class:`ScreenedPoisson` is bound to
those buffers once and keeps what does not change between frames:

* **buffers**: the planar work arrays of :class:`~grisx.poisson.cg.PlanarSystem` and the image
  it writes, allocated once;
* **one CUDA graph**: the layout conversions, the assembly of ``b`` and the whole solve are
  captured on the first call and replayed after it (one launch a frame). L2's stopping rule
  runs on the device (:func:`~grisx.poisson.cg.cg_loop`: a conditional loop node), so nothing is
  read back inside the loop; L1 runs its fixed IRLS schedule;
* **the previous frame's image as the initial iterate** (``warm_start``, default on): where
  consecutive frames are alike (a static camera, reservoirs carried over) CG starts next to the
  answer. The stopping rule is the same as a cold start's, so L2's image is as accurate either
  way; :meth:`ScreenedPoisson.reset` makes the next frame start from its primal again (a renderer
  calls it when its sequence restarts, so a seed gives the same images every time).

Nothing else runs: no NaN/Inf check (the renderers drop non-finite samples before they reach
these buffers) and no diagnostic pass — :meth:`ScreenedPoisson.measure` computes the true
residual and the energy when asked, and :attr:`ScreenedPoisson.iterations` reads CG's count.

Example
-------
>>> import numpy as np, warp as wp
>>> from grisx.poisson import ScreenedPoisson, forward_gradient
>>> truth = np.random.default_rng(0).random((6, 8, 3)).astype(np.float32)
>>> g = forward_gradient(truth)
>>> arrays = [wp.array(a.astype(np.float32), dtype=wp.vec3, device="cpu") for a in (truth, g.dx, g.dy)]
>>> system = ScreenedPoisson(*arrays, alpha=0.2, norm="L2")
>>> bool(np.allclose(system.solve().numpy(), truth, atol=1e-4))
True
"""

from __future__ import annotations

from typing import Any

import warp as wp

from grisx.errors import InvalidParameterError
from grisx.poisson import operators as ops
from grisx.poisson.cg import CGReport, LoopState, Measurement, allocate_system, assemble, capture, cg_loop, cg_report, measure_system
from grisx.poisson.l1 import DEFAULT_EPS, get_preset, irls
from grisx.poisson.reconstruct import DEFAULT_MAX_ITER, DEFAULT_TOL, _check_options, _check_shapes, _pick_device, as_warp_input, reconstruct

__all__ = ["ScreenedPoisson", "FrameReconstruction", "FRAME_TOL", "frame_tol"]


class ScreenedPoisson:
    """The screened Poisson image of three device buffers (primal, dx, dy), re-solved each frame.

    ``primal``, ``dx`` and ``dy`` are Warp arrays of one shape — ``(H, W)`` of ``wp.vec3`` (a
    renderer's frame) or ``(H, W, C)`` float32 — on one device; :meth:`solve` reads what they hold
    when it is called and returns :attr:`image`, a buffer of the primal's form that the next call
    overwrites. ``norm``, ``alpha``, ``tol``, ``max_iter`` (L2) and ``preset``/``eps`` (L1) mean what
    they mean for :func:`grisx.poisson.solve`; its ``solver="cg"`` and ``"irls"`` are what runs.
    """

    def __init__(self, primal: wp.array, dx: wp.array, dy: wp.array, *, alpha: float = 0.2, norm: str = "L2",
                 tol: float = DEFAULT_TOL, max_iter: int = DEFAULT_MAX_ITER, preset: str = "default",
                 eps: float = DEFAULT_EPS, warm_start: bool = False, preconditioner: str | None = None) -> None:
        inputs = [as_warp_input(name, a) for name, a in (("primal", primal), ("dx", dx), ("dy", dy))]
        _check_shapes(inputs[0], inputs[1:])
        self.device = _pick_device(None, inputs)
        # the checks of grisx.poisson.solve, with the solver this system runs for the norm
        self.norm, _ = _check_options(norm, alpha, "irls" if str(norm).upper() == "L1" else "cg", self.device, tol, max_iter, eps)
        self.alpha, self.tol, self.max_iter = float(alpha), float(tol), int(max_iter)
        self.schedule = get_preset(preset)
        self.eps = float(eps)
        self.warm_start = bool(warm_start)
        self._inputs = inputs
        h, w, c = inputs[0].shape
        self.height, self.width, self.channels = h, w, c
        planar = [wp.empty((c, h * w), dtype=wp.float32, device=self.device) for _ in range(4)]
        chosen = preconditioner or (self.schedule.preconditioner if self.norm == "L1" else "multigrid")
        self.system = allocate_system(planar[0], planar[1], planar[2], planar[3], h, w, self.alpha,
                                      weighted=self.norm == "L1", preconditioner=chosen)
        self.image = wp.empty(primal.shape, dtype=primal.dtype, device=self.device)
        self._image_hwc = as_warp_input("image", self.image).hwc
        self._cold = wp.ones(1, dtype=wp.int32, device=self.device)  # the next solve starts from the primal
        self._loop = LoopState.allocate(self.device)
        self._weighted = False
        self._run: Any = None  # the captured frame (a CUDA graph's launch), made on the first solve

    # ---- one frame ----
    def _frame(self) -> None:
        """Every launch of one reconstruction: the inputs in planar layout, the start, the solve, the image."""
        s, (h, w, c) = self.system, (self.height, self.width, self.channels)
        for inp, dst in zip(self._inputs, (s.primal, s.gx, s.gy)):
            wp.launch(ops.hwc_to_planar, dim=(h, w, c), inputs=[inp.hwc, dst, w], device=self.device)
        wp.launch(ops.cold_start, dim=(c, h * w), inputs=[s.x, s.primal, self._cold], device=self.device)
        if self.norm == "L2":
            assemble(s, weighted=False)
            cg_loop(s, False, self.tol, self.max_iter, self._loop)
        else:
            self._weighted = irls(s, self.schedule.outer, self.schedule.inner, self.eps, graph_steps=False)
        wp.launch(ops.planar_to_hwc, dim=(h, w, c), inputs=[s.x, self._image_hwc, w], device=self.device)

    def solve(self) -> wp.array:
        """The screened Poisson image of what the bound buffers hold now (:attr:`image`)."""
        if self._run is None:
            self._run = capture(self.system, self._frame)
        self._run()
        # the next frame starts from this one's image, unless warm starts are off
        self._cold.fill_(0 if self.warm_start else 1)
        return self.image

    def reset(self) -> None:
        """Start the next solve from its primal (a renderer's sequence restarts)."""
        self._cold.fill_(1)

    # ---- diagnostics (host reads; not part of a frame) ----
    @property
    def iterations(self) -> int:
        """CG iterations of the last L2 solve; for L1, the schedule's outer × inner."""
        if self.norm == "L1":
            return self.schedule.outer * self.schedule.inner
        return int(self._loop.iterations.numpy()[0])

    def report(self) -> CGReport:
        """How the last L2 solve's CG ended (iterations, max relative residual by its recurrence)."""
        if self.norm != "L2":
            raise InvalidParameterError("report() describes an L2 solve; this system solves L1")
        return cg_report(self.system, self.tol, self._loop)

    def measure(self) -> Measurement:
        """True residual of the last linear system and the energies of the last image (host reads)."""
        return measure_system(self.system, self._weighted)


# CG's stopping rule for a rendered frame's L2 image: relative residual 1e-4, not the 1e-5 of a one-off solve.
# A frame's primal and gradients carry Monte Carlo noise far above that: on ReSTIR G-PT's own frames (door-ajar
# 320×180, cornell-box 480×270, camera path, against the exact DCT solve) the image then differs from the exact
# solve by relMSE 1.5e-8–1.3e-7 (the frame's own relMSE against a 256-spp pt reference: 0.05–0.13); on cornell-box
# by 0.6–0.8% at the 99.9th percentile pixel and ≤ 5.3% at the worst. 7–8 multigrid-preconditioned CG iterations
# against 9–10 (benchmarks/reference/poisson_frame_tol_h200_2026-11-28/).
FRAME_TOL = 1e-4


def frame_tol(samples: int = 1) -> float:
    """CG's stopping rule for buffers that average ``samples`` frames' worth of samples (a path tracer's spp, averaged
    instances): FRAME_TOL / √samples, never below the one-off solve's DEFAULT_TOL. The frame's Monte Carlo error falls
    as 1/√samples and CG's error is bounded by a multiple of its residual, so the tolerance falls alike to keep the
    bound the same fraction of the noise (on ``tests/poisson/test_poisson_system.py``'s frames the algebraic MSE is
    2.6e-6 of the noise's at 1, 16, 100 and 1000 samples; FRAME_TOL alone lets it grow to 3.2e-4 at 1000)."""
    if samples < 1:
        raise InvalidParameterError(f"frame_tol needs samples >= 1, not {samples}")
    return max(DEFAULT_TOL, FRAME_TOL / float(samples) ** 0.5)


class FrameReconstruction:
    """A renderer's screened Poisson image of three buffers, re-solved each frame: L2 on the CPU by the exact DCT
    solve (:func:`~grisx.poisson.reconstruct`), otherwise by a :class:`ScreenedPoisson` bound to the buffers (its
    buffers and CUDA graph made once) that stops L2's CG at ``tol`` (:data:`FRAME_TOL`: a frame is noisy, so its
    image needs no float32-floor accuracy; :func:`frame_tol` for buffers that hold more samples). What the
    gradient-domain renderers run, and what a benchmark that reconstructs their averaged buffers itself must run to
    time the same thing."""

    def __init__(self, primal: wp.array, dx: wp.array, dy: wp.array, *, alpha: float = 0.2, norm: str = "L2",
                 tol: float = FRAME_TOL) -> None:
        self.primal, self.dx, self.dy = primal, dx, dy
        self.alpha, self.norm = float(alpha), norm
        cpu_l2 = str(norm).upper() == "L2" and wp.get_device(primal.device).is_cpu
        self.system = None if cpu_l2 else ScreenedPoisson(primal, dx, dy, alpha=alpha, norm=norm, tol=tol)

    def solve(self) -> Any:
        """The image of what the buffers hold now."""
        if self.system is None:
            return reconstruct(self.primal, self.dx, self.dy, alpha=self.alpha, norm=self.norm, check_finite=False, measure=False)
        return self.system.solve()

    def reset(self) -> None:
        """A new sequence: the next solve starts from its primal."""
        if self.system is not None:
            self.system.reset()
