"""Gradient-domain estimators over pixel pairs, built once from a problem's hooks.

A gradient toy has pixels (each with a domain, a source pdf and an integrand
that may change from frame to frame), *pairs* of pixels (i, j) whose
difference Δ_ij it estimates, an *inner shift* between the two pixels of a
pair, and an *outer shift* τ that carries a base path from a pixel of one pair
(or frame) to the corresponding pixel of another. :func:`make_gradient_kernels`
turns these hooks into one kernel per method; every formula inside comes from
:mod:`grisx.theory.gradient` and the GRIS core.

``mc-difference``         independent MC in both pixels, ⟨F_i⟩ − ⟨F_j⟩ (Eq. 1);
``gradient-pt``           shift-mapped differences from both pixels with the
                          balance heuristic ω (Eq. 2–4, Kettunen et al. 2015);
                          ``symmetric = false`` keeps the base pixel i only with
                          ω = 1 (Eq. 2) — biased where T_ij is partial;
``gradient-after-restir`` primal ReSTIR in every pixel (RIS with p̂ = f, then
                          temporal reuse through τ), then ω̂ G W of both pixels'
                          kept paths with the generalized balance heuristic
                          (Eq. 10–13);
``gradient-with-restir``  ReSTIR in the paired-pixel domain X (Eq. 14–20):
                          candidates from both pixels, temporal reuse of the
                          pair's previous reservoirs and spatial reuse of other
                          pairs' reservoirs through T* = (τ, k) (Eq. 21–22),
                          generalized-balance MIS over all inputs, optionally
                          positivized with ``pos``/``neg`` reservoirs over
                          shared candidates and reuse across signs (Eq. 23–26).

Frames run 0 … F; the estimate is that of frame F (``frames`` = F prior
frames of temporal reuse). Confidences depend only on M, the frame and the
neighbour sets — never on samples — so the MIS weights sum to one and every
chain stays unbiased.

Hooks (Warp functions taking the problem's spec struct first):
``pair_pixel(spec, p, k) -> int`` (pixel of part k of pair p),
``sample_x(spec, frame, pixel, u) -> x``, ``x_pdf(spec, frame, pixel, x)``,
``integrand(spec, frame, pixel, x)``,
``inner_shift(spec, frame, src, dst, x) -> ShiftResult``,
``tau(spec, frame_src, pixel_src, frame_dst, pixel_dst, x) -> ShiftResult``,
``neighbor(spec, key, p, n) -> int`` (n-th spatial neighbour pair of p, −1 for none).
"""



from typing import Any

import warp as wp

from grisx.theory.gradient import (
    PairShift,
    outer_shift,
    pair_balance_add,
    pair_balance_empty,
    pair_balance_mis,
    pair_contribution,
    pair_estimate,
    pair_input_slot,
    pair_outer_weight,
    pair_slot_sign,
    pair_source_inputs,
    pair_update,
    pair_value,
    signed_target,
)
from grisx.theory.gris import ris_weight, ucw_from_source_pdf
from grisx.theory.mis import target_from, two_domain_balance
from grisx.theory.random import random_key, random_subkey, random_uniform
from grisx.theory.reservoir import (
    Reservoir,
    confidence_capped,
    reservoir_empty,
    reservoir_finalize,
    reservoir_merge,
    reservoir_update,
)

# grisx never differentiates through its kernels: skip adjoint code (halves compile time)
wp.set_module_options({"enable_backward": False})

__all__ = ["make_gradient_kernels", "GRADIENT_METHODS", "MAX_SOURCES"]

GRADIENT_METHODS = ("mc-difference", "gradient-pt", "gradient-after-restir", "gradient-with-restir")
#: inputs of one merge: the pair's own reservoir plus at most MAX_SOURCES − 1 others
MAX_SOURCES = 8

# layers of the per-trial reservoir state of gradient-with-restir
_PREV = wp.constant(0)  # the previous frame's final reservoirs
_CUR = wp.constant(1)  # input of the current stage
_OUT = wp.constant(2)  # output of the current stage


@wp.func
def _identity_pair_shift(x: float, k: int) -> PairShift:
    s = PairShift()
    s.x = x
    s.k = k
    s.jacobian = 1.0
    s.valid = True
    return s


def make_gradient_kernels(
    spec_type: Any,
    pair_pixel: Any,
    sample_x: Any,
    x_pdf: Any,
    integrand: Any,
    inner_shift: Any,
    tau: Any,
    neighbor: Any,
) -> dict[str, Any]:
    """Build the four method kernels of :data:`GRADIENT_METHODS` for one problem's hooks."""

    # ---- the pair integrand, from the core (Eq. 4, 13, 15, 16) --------------------
    @wp.func
    def value_at(spec: spec_type, frame: int, p: int, k: int, x: float, use_targets: int) -> float:
        # ω*G at (x, k) in pair p; ω from the pixels' pdfs (Eq. 4/16) or from the
        # targets p̂ = f of primal ReSTIR (generalized balance heuristic, Eq. 13)
        base = pair_pixel(spec, p, k)
        other = pair_pixel(spec, p, 1 - k)
        f_b = integrand(spec, frame, base, x)
        s = inner_shift(spec, frame, base, other, x)
        f_o = float(0.0)
        d_o = float(0.0)
        if s.valid:
            f_o = integrand(spec, frame, other, s.x)
            d_o = x_pdf(spec, frame, other, s.x)
            if use_targets != 0:
                d_o = f_o
        d_b = x_pdf(spec, frame, base, x)
        if use_targets != 0:
            d_b = f_b
        return pair_value(k, f_b, f_o, d_b, d_o, s.jacobian, s.valid)

    @wp.func
    def pair_shift(spec: spec_type, frame_src: int, p_src: int, frame_dst: int, p_dst: int, k: int, x: float) -> PairShift:
        # T* = (τ, identity on k), Eq. 21–22
        if frame_src == frame_dst and p_src == p_dst:
            return _identity_pair_shift(x, k)
        return outer_shift(tau(spec, frame_src, pair_pixel(spec, p_src, k), frame_dst, pair_pixel(spec, p_dst, k), x), k)

    @wp.func
    def carried_value(spec: spec_type, s: PairShift, frame_l: int, p_l: int, k: int) -> float:
        # ω*G in domain l at T*⁻¹(y) (0 where the shift fails: its target is dropped anyway)
        if not s.valid:
            return 0.0
        return value_at(spec, frame_l, p_l, k, s.x, 0)

    # ---- mc-difference --------------------------------------------------------------
    @wp.kernel(module="unique", enable_backward=False)
    def mc_difference(spec: spec_type, candidates: int, frame: int, seed: int, first_trial: int, values: wp.array2d(dtype=float)):
        t, p = wp.tid()
        key = random_subkey(random_key(seed, first_trial + t), p)
        est = float(0.0)
        inv_m = 1.0 / float(candidates)
        for k in range(2):
            pix = pair_pixel(spec, p, k)
            sign = 1.0 - 2.0 * float(k)  # ⟨F_i⟩ − ⟨F_j⟩ (Eq. 1)
            for c in range(candidates):
                x = sample_x(spec, frame, pix, random_uniform(key, k * candidates + c))
                est += sign * inv_m * integrand(spec, frame, pix, x) * ucw_from_source_pdf(x_pdf(spec, frame, pix, x))
        values[t, p] = est

    # ---- gradient-pt (Kettunen et al. 2015) -----------------------------------------
    @wp.kernel(module="unique", enable_backward=False)
    def gradient_pt(
        spec: spec_type, candidates: int, frame: int, symmetric: int, seed: int, first_trial: int, values: wp.array2d(dtype=float)
    ):
        t, p = wp.tid()
        key = random_subkey(random_key(seed, first_trial + t), p)
        est = float(0.0)
        inv_m = 1.0 / float(candidates)
        parts = 1 + symmetric
        for k in range(parts):
            pix = pair_pixel(spec, p, k)
            for c in range(candidates):
                x = sample_x(spec, frame, pix, random_uniform(key, k * candidates + c))
                ucw = inv_m * ucw_from_source_pdf(x_pdf(spec, frame, pix, x))
                if symmetric != 0:
                    v = value_at(spec, frame, p, k, x, 0)  # ω G, Eq. 3–4
                else:
                    # the one-sided Eq. 2 (ω = 1, base pixel i only): misses ∫_{Ω_j \ Ω_j'} f_j
                    other = pair_pixel(spec, p, 1)
                    s = inner_shift(spec, frame, pix, other, x)
                    f_o = float(0.0)
                    if s.valid:
                        f_o = integrand(spec, frame, other, s.x)
                    v = pair_contribution(0, integrand(spec, frame, pix, x), f_o, s.jacobian, s.valid)
                est += pair_estimate(v, ucw)
        values[t, p] = est

    # ---- gradient-after-restir ---------------------------------------------------------
    @wp.kernel(module="unique", enable_backward=False)
    def gradient_after(
        spec: spec_type,
        candidates: int,
        frames: int,
        use_jacobian: int,
        confidence_cap: float,
        seed: int,
        first_trial: int,
        res: wp.array2d(dtype=Reservoir),
        ys: wp.array2d(dtype=float),
        values: wp.array2d(dtype=float),
        samples: wp.array2d(dtype=float),
        keep_samples: int,
    ):
        t = wp.tid()
        key = random_key(seed, first_trial + t)
        pixels = res.shape[1]
        inv_m = 1.0 / float(candidates)
        for frame in range(frames + 1):
            fkey = random_subkey(key, frame)
            for pix in range(pixels):
                # ---- initial candidates: RIS with p̂ = f (seed 000, Eq. 6–8) ----
                r = reservoir_empty()
                y = float(0.0)
                for c in range(candidates):
                    x = sample_x(spec, frame, pix, random_uniform(fkey, 2 * (pix * candidates + c)))
                    p_hat = integrand(spec, frame, pix, x)
                    r = reservoir_update(r, ris_weight(inv_m, p_hat, x_pdf(spec, frame, pix, x)), p_hat, 1.0, random_uniform(fkey, 2 * (pix * candidates + c) + 1))
                    if r.selected:
                        y = x
                r = reservoir_finalize(r)
                if frame > 0:
                    # ---- temporal reuse: the pixel's previous reservoir through τ (Eq. 9) ----
                    prev = res[t, pix]
                    c_c = r.confidence
                    c_p = prev.confidence
                    canonical = r
                    m_key = random_subkey(fkey, 1 + pix)
                    r = reservoir_empty()
                    # canonical sample y: weight against the previous frame's target carried forward
                    t_prev = float(0.0)
                    back = tau(spec, frame, pix, frame - 1, pix, y)
                    if back.valid:
                        t_prev = target_from(integrand(spec, frame - 1, pix, back.x), back.jacobian)
                    t_cur = integrand(spec, frame, pix, y)
                    m = two_domain_balance(c_c, t_cur, c_p, t_prev)
                    r = reservoir_merge(r, canonical, m, t_cur, 1.0, random_uniform(m_key, 0))
                    y_new = y
                    s = tau(spec, frame - 1, pix, frame, pix, ys[t, pix])
                    if s.valid:
                        t_cur = integrand(spec, frame, pix, s.x)
                        t_prev = target_from(integrand(spec, frame - 1, pix, ys[t, pix]), 1.0)
                        # p̂_{←prev}(T y) = p̂_prev(y)·|∂T⁻¹/∂(Ty)| = p̂_prev(y)/|∂T/∂y|
                        if s.jacobian > 0.0:
                            t_prev = t_prev / s.jacobian
                        m = two_domain_balance(c_p, t_prev, c_c, t_cur)
                        jac = s.jacobian
                        if use_jacobian == 0:
                            jac = 1.0  # the ablation: biased wherever |∂τ/∂x| ≠ 1
                        r = reservoir_merge(r, prev, m, t_cur, jac, random_uniform(m_key, 1))
                    else:
                        r = reservoir_update(r, 0.0, 0.0, c_p, 0.0)
                    if r.selected:
                        y_new = s.x
                    y = y_new
                    r = reservoir_finalize(r)
                    r.confidence = confidence_capped(r.confidence, confidence_cap)
                res[t, pix] = r
                ys[t, pix] = y
        # ---- gradients: ω̂ G W of both pixels' kept paths (seed 000, Eq. 11–13) ----
        for p in range(values.shape[1]):
            est = float(0.0)
            for k in range(2):
                pix = pair_pixel(spec, p, k)
                est += pair_estimate(value_at(spec, frames, p, k, ys[t, pix], 1), res[t, pix].ucw)
            values[t, p] = est
            if keep_samples != 0:
                samples[t, p] = ys[t, pair_pixel(spec, p, t % 2)]  # trial parity picks which pixel's path

    # ---- gradient-with-restir ------------------------------------------------------------
    @wp.func
    def merge_pair(
        spec: spec_type,
        frame: int,
        p: int,
        slot: int,
        positivize: int,
        cross_sign: int,
        use_jacobian: int,
        sources: int,
        src_layer: wp.array(dtype=int),
        src_pair: wp.array(dtype=int),
        src_frame: wp.array(dtype=int),
        state: wp.array2d(dtype=Reservoir),
        xs: wp.array2d(dtype=float),
        ks: wp.array2d(dtype=int),
        mkey: wp.uint32,
    ) -> Reservoir:
        # GRIS over the pair's own reservoir (source 0) and the other sources, through T*,
        # with generalized-balance MIS over every input (l, e) — across signs with cross_sign
        # (seed 000, Sec. 4.4; seed 001, Eq. 15–16)
        sign = pair_slot_sign(positivize, slot)
        r = reservoir_empty()
        y = float(0.0)
        yk = int(0)
        for l in range(sources):
            for e in range(pair_source_inputs(l, positivize, cross_sign)):
                idx = src_pair[l] * 2 + pair_input_slot(slot, e)
                rin = state[src_layer[l], idx]
                sh = pair_shift(spec, src_frame[l], src_pair[l], frame, p, ks[src_layer[l], idx], xs[src_layer[l], idx])
                if sh.valid and rin.ucw > 0.0:
                    target = signed_target(sign, value_at(spec, frame, p, sh.k, sh.x, 0))
                    bal = pair_balance_empty()
                    for l2 in range(sources):
                        inputs = pair_source_inputs(l2, positivize, cross_sign)
                        c_same = state[src_layer[l2], src_pair[l2] * 2 + slot].confidence
                        c_other = float(0.0)
                        if inputs > 1:
                            c_other = state[src_layer[l2], src_pair[l2] * 2 + pair_input_slot(slot, 1)].confidence
                        own = int(-1)
                        if l2 == l:
                            own = e
                        back = pair_shift(spec, frame, p, src_frame[l2], src_pair[l2], sh.k, sh.x)  # T*⁻¹ into l2
                        bal = pair_balance_add(bal, sign, inputs, c_same, c_other, carried_value(spec, back, src_frame[l2], src_pair[l2], sh.k), back.jacobian, back.valid, own)
                    m = pair_balance_mis(bal, rin.confidence)
                    if use_jacobian == 0:
                        sh.jacobian = 1.0  # the ablation: biased wherever |∂τ/∂x| ≠ 1
                    w = pair_outer_weight(m, target, rin.ucw, sh)  # seed 000, Eq. 20
                    r = reservoir_update(r, w, target, rin.confidence, random_uniform(mkey, 2 * l + e))
                    if r.selected:
                        y = sh.x
                        yk = sh.k
                else:
                    r = reservoir_update(r, 0.0, 0.0, rin.confidence, 0.0)
        r = reservoir_finalize(r)
        xs[_OUT, p * 2 + slot] = y
        ks[_OUT, p * 2 + slot] = yk
        return r

    @wp.kernel(module="unique", enable_backward=False)
    def gradient_with(
        spec: spec_type,
        candidates: int,
        frames: int,
        spatial_passes: int,
        neighbors: int,
        positivize: int,
        cross_sign: int,
        use_jacobian: int,
        confidence_cap: float,
        seed: int,
        first_trial: int,
        state: wp.array3d(dtype=Reservoir),
        xs: wp.array3d(dtype=float),
        ks: wp.array3d(dtype=int),
        src_layer: wp.array2d(dtype=int),
        src_pair: wp.array2d(dtype=int),
        src_frame: wp.array2d(dtype=int),
        values: wp.array2d(dtype=float),
        samples: wp.array2d(dtype=float),
        keep_samples: int,
        counters: wp.array2d(dtype=float),
        keep_counters: int,
    ):
        t = wp.tid()
        key = random_key(seed, first_trial + t)
        pairs = values.shape[1]
        slots = 1 + positivize
        inv_m = 1.0 / float(candidates)
        merges = float(0.0)
        for frame in range(frames + 1):
            fkey = random_subkey(key, frame)
            # ---- initial candidates in X = Ω_i×{0} ∪ Ω_j×{1}, shared by pos and neg (Eq. 14, 23–26) ----
            ckey = random_subkey(fkey, 0)
            for p in range(pairs):
                for slot in range(slots):
                    r = reservoir_empty()
                    y = float(0.0)
                    yk = int(0)
                    for k in range(2):
                        pix = pair_pixel(spec, p, k)
                        for c in range(candidates):
                            n = (p * 2 + k) * candidates + c
                            # the same u for x in both slots: the candidates are shared
                            x = sample_x(spec, frame, pix, random_uniform(ckey, 3 * n))
                            v = value_at(spec, frame, p, k, x, 0)
                            # each part's M candidates are one technique; the other part cannot produce x: m = 1/M
                            ucw = ucw_from_source_pdf(x_pdf(spec, frame, pix, x))
                            r = pair_update(r, pair_slot_sign(positivize, slot), v, inv_m, ucw, 1.0, 1.0, random_uniform(ckey, 3 * n + 1 + slot))
                            if r.selected:
                                y = x
                                yk = k
                    state[t, _CUR, p * 2 + slot] = reservoir_finalize(r)
                    xs[t, _CUR, p * 2 + slot] = y
                    ks[t, _CUR, p * 2 + slot] = yk
            # ---- temporal reuse: the pair's previous reservoirs through T* (Eq. 20–22) ----
            if frame > 0:
                tkey = random_subkey(fkey, 1)
                for p in range(pairs):
                    src_layer[t, 0] = _CUR
                    src_pair[t, 0] = p
                    src_frame[t, 0] = frame
                    src_layer[t, 1] = _PREV
                    src_pair[t, 1] = p
                    src_frame[t, 1] = frame - 1
                    for slot in range(slots):
                        r = merge_pair(spec, frame, p, slot, positivize, cross_sign, use_jacobian, 2, src_layer[t], src_pair[t], src_frame[t], state[t], xs[t], ks[t], random_subkey(tkey, p * 2 + slot))
                        r.confidence = confidence_capped(r.confidence, confidence_cap)
                        state[t, _OUT, p * 2 + slot] = r
                for q in range(2 * pairs):
                    state[t, _CUR, q] = state[t, _OUT, q]
                    xs[t, _CUR, q] = xs[t, _OUT, q]
                    ks[t, _CUR, q] = ks[t, _OUT, q]
            # ---- spatial reuse: other pairs' reservoirs through T* (Eq. 20–22) ----
            for sp in range(spatial_passes):
                skey = random_subkey(fkey, 2 + sp)
                nkey = random_subkey(fkey, 1000 + sp)
                for p in range(pairs):
                    src_layer[t, 0] = _CUR
                    src_pair[t, 0] = p
                    src_frame[t, 0] = frame
                    sources = int(1)
                    for n in range(neighbors):
                        q = neighbor(spec, random_subkey(nkey, p), p, n)
                        if q >= 0 and q != p and sources < MAX_SOURCES:
                            src_layer[t, sources] = _CUR
                            src_pair[t, sources] = q
                            src_frame[t, sources] = frame
                            sources += 1
                    merges += float(sources - 1)
                    for slot in range(slots):
                        if sources > 1:
                            r = merge_pair(spec, frame, p, slot, positivize, cross_sign, use_jacobian, sources, src_layer[t], src_pair[t], src_frame[t], state[t], xs[t], ks[t], random_subkey(skey, p * 2 + slot))
                            r.confidence = confidence_capped(r.confidence, confidence_cap)
                            state[t, _OUT, p * 2 + slot] = r
                        else:
                            # no neighbour: the pair keeps what it has (no merge, no cost)
                            state[t, _OUT, p * 2 + slot] = state[t, _CUR, p * 2 + slot]
                            xs[t, _OUT, p * 2 + slot] = xs[t, _CUR, p * 2 + slot]
                            ks[t, _OUT, p * 2 + slot] = ks[t, _CUR, p * 2 + slot]
                for q in range(2 * pairs):
                    state[t, _CUR, q] = state[t, _OUT, q]
                    xs[t, _CUR, q] = xs[t, _OUT, q]
                    ks[t, _CUR, q] = ks[t, _OUT, q]
            for q in range(2 * pairs):
                state[t, _PREV, q] = state[t, _CUR, q]
                xs[t, _PREV, q] = xs[t, _CUR, q]
                ks[t, _PREV, q] = ks[t, _CUR, q]
        # ---- the estimate: Σ over pos/neg of ω*G(y)·W_y (seed 000, Eq. 17, 24) ----
        for p in range(pairs):
            est = float(0.0)
            for slot in range(slots):
                r = state[t, _CUR, p * 2 + slot]
                est += pair_estimate(value_at(spec, frames, p, ks[t, _CUR, p * 2 + slot], xs[t, _CUR, p * 2 + slot], 0), r.ucw)
            values[t, p] = est
            if keep_samples != 0:
                samples[t, p] = xs[t, _CUR, p * 2 + (t % slots)]  # positivized: trial parity picks pos or neg
        if keep_counters != 0:
            counters[t, 0] = merges

    return {
        "mc-difference": mc_difference,
        "gradient-pt": gradient_pt,
        "gradient-after-restir": gradient_after,
        "gradient-with-restir": gradient_with,
    }


class GradientScratch:
    """Per-trial state of the gradient kernels, reused across chunks of trials."""

    def __init__(self) -> None:
        self._key: tuple[int, int, int, str] | None = None
        self.buffers: dict[str, wp.array] = {}

    def get(self, trials: int, pixels: int, pairs: int, device: Any) -> dict[str, wp.array]:
        key = (trials, pixels, pairs, str(device))
        if key != self._key:
            self.buffers = {
                "res": wp.empty((trials, pixels), dtype=Reservoir, device=device),
                "ys": wp.empty((trials, pixels), dtype=float, device=device),
                "state": wp.empty((trials, 3, 2 * pairs), dtype=Reservoir, device=device),
                "xs": wp.empty((trials, 3, 2 * pairs), dtype=float, device=device),
                "ks": wp.zeros((trials, 3, 2 * pairs), dtype=int, device=device),
                "src_layer": wp.zeros((trials, MAX_SOURCES), dtype=int, device=device),
                "src_pair": wp.zeros((trials, MAX_SOURCES), dtype=int, device=device),
                "src_frame": wp.zeros((trials, MAX_SOURCES), dtype=int, device=device),
                "dummy": wp.zeros((trials, 1), dtype=float, device=device),
            }
            self._key = key
        return self.buffers


def launch_gradient_method(
    kernels: dict[str, Any],
    scratch: GradientScratch,
    method: str,
    spec: Any,
    params: dict[str, Any],
    pixels: int,
    seed: int,
    first_trial: int,
    values: wp.array,
    samples: wp.array | None,
    counters: wp.array | None,
    device: Any,
) -> None:
    """Launch ``method``'s kernel writing per-trial pair estimates into ``values`` (n, pairs)."""
    n, pairs = values.shape
    buf = scratch.get(n, pixels, pairs, device)
    frames = int(params.get("frames", 0))
    m = int(params["candidates"])
    keep = samples is not None
    smp = samples if keep else values
    if method == "mc-difference":
        wp.launch(kernels[method], dim=(n, pairs), inputs=[spec, m, frames, seed, first_trial, values], device=device)
    elif method == "gradient-pt":
        wp.launch(kernels[method], dim=(n, pairs), inputs=[spec, m, frames, int(bool(params.get("symmetric", True))), seed, first_trial, values], device=device)
        if keep:
            samples.fill_(0.0)
    elif method == "gradient-after-restir":
        wp.launch(
            kernels[method],
            dim=n,
            inputs=[spec, m, frames, int(bool(params.get("jacobian", True))), float(params.get("cap", 20.0)), seed, first_trial,
                    buf["res"], buf["ys"], values, smp, int(keep)],
            device=device,
        )
    else:
        cnt = counters if counters is not None else buf["dummy"]
        wp.launch(
            kernels[method],
            dim=n,
            inputs=[
                spec, m, frames, int(params.get("spatial_passes", 0)), int(params.get("neighbors", 0)),
                int(bool(params.get("positivize", True))), int(bool(params.get("cross_sign", False))),
                int(bool(params.get("jacobian", True))), float(params.get("cap", 20.0)), seed, first_trial,
                buf["state"], buf["xs"], buf["ks"], buf["src_layer"], buf["src_pair"], buf["src_frame"],
                values, smp, int(keep), cnt, int(counters is not None),
            ],
            device=device,
        )
