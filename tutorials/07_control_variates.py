# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # Tutorial 7 — Spatio-temporal control variates with ReSTIR (ReSTCV)
#
# ReSTIR resamples with a **scalar** target — the luminance of the path
# contribution — and shades each pixel with the one sample its reservoir kept,
# $\langle F_i\rangle = f_i(Y)\,W_Y$. The UCW $W_Y$ fits the luminance well,
# but the colour comes from $f_i(Y)/\hat p_i(Y)$ of that single sample: under a
# red and a green light every pixel is either red or green, never the yellow it
# should be (seed 002, Sec. 4 and Fig. 2). That is **colour noise**.
#
# Shi et al. (SIGGRAPH 2026, seed 002) cure it with **control variates**: a
# neighbour's (or the previous frame's) colour estimate $\langle F_j\rangle$
# stands in for pixel $i$'s, corrected by an estimate of the *difference*,
#
# $$\langle F_i\rangle_{\leftarrow j} = \alpha_{ij}\langle F_j\rangle + \langle F_i - \alpha_{ij}F_j\rangle \qquad\text{(Eq. 7)}$$
#
# and these "from-$j$" estimates are composited with weights $q_j = M_j$
# (the reservoirs' confidences, capped at 20; Eq. 6 and 8). The difference is
# estimated from the two **reservoir samples** with MIS weights built from the
# confidences and targets (Eq. 10–11), and the colour estimate $F$ travels in
# the reservoir (Listing 1). Everything stays unbiased, and the colour is
# accumulated over space and time instead of being re-drawn every frame.
#
# The toy problem `chromatic-cv` is a small image of a textured plane under a
# red and a green light, rendered over $T$ static frames, with exact pixel
# colours. Every estimator here runs the functions of
# `grisx.theory.control_variate` (plus the reservoir, GRIS and MIS core): the
# same functions a ReSTCV renderer calls.
#
# Run it as a script (`python tutorials/07_control_variates.py [--quick]`) or
# as a notebook (jupytext). `GRISX_QUICK=1` uses few trials; figures go to
# `$GRISX_TUTORIAL_OUT` (default `tutorials/out/`); `GRISX_DEVICE=cuda` runs
# the kernels on a GPU.

# %% [markdown]
# ## What you will learn
#
# 1. Why a luminance target leaves **colour noise** in ReSTIR, and what
#    decoupled shading, image-space CVs (ICV), STCV and ReSTCV each do about it.
# 2. How to **measure** colour noise: per-channel variance, and a chroma error
#    that ignores brightness.
# 3. That all six estimators are **unbiased** per pixel and channel (Šidák
#    z-test), and that dropping Eq. 11's MIS weights is not.
# 4. The role of the CV coefficient $\alpha_{ij} = \min(\rho_i/\rho_j, 2)$
#    (Eq. 9) at albedo edges — the analogue of the paper's Fig. 3.
# 5. Where ReSTIR's samples help the **difference** estimate (ReSTCV against
#    STCV) and where plain MC differences are already good.
# 6. That the renderer (`--method restcv`, `stcv`) runs these same functions on
#    a scene: the red–green plane by ReSTIR PT and by ReSTCV side by side.

# %% Setup
import time

import numpy as np


# quick mode, device, figure folder and the off-screen backend (before pyplot is imported)
from grisx.tutorial import tutorial_setup

setup = tutorial_setup(globals().get("__file__"))
INTERACTIVE = setup.interactive
import matplotlib.pyplot as plt  # noqa: E402

from grisx.testing import BIASED_K, DEFAULT_K, z_test  # noqa: E402
from grisx.theory.toys import get_problem, run_toy  # noqa: E402

QUICK = setup.quick
TRIALS = 150 if QUICK else 2000
SEED = 0
DEVICE = setup.device

OUT = setup.out
T_START = setup.start
print(f"mode: {'QUICK' if QUICK else 'default'}  trials per run: {TRIALS:,}  seed: {SEED}  figures -> {OUT}")

save = setup.save


PROBLEM = get_problem("chromatic-cv")
SCENE = {"size": 16, "frames": 8}
METHODS = ("mc", "restir", "decoupled", "icv", "stcv", "restcv")
LABELS = {
    "mc": "MC",
    "restir": "ReSTIR",
    "decoupled": "decoupled",
    "icv": "ICV",
    "stcv": "STCV",
    "restcv": "ReSTCV",
}


def exact_image(params=SCENE) -> np.ndarray:
    p = PROBLEM.resolve_params("mc", {k: v for k, v in params.items() if k in ("size", "frames", "candidates", "light_width")})
    n = p["size"]
    return PROBLEM.exact(p).reshape(n, n, 3)


def show(img: np.ndarray, scale: float) -> np.ndarray:
    """Linear RGB → display: a common exposure, sRGB-ish gamma, clipped."""
    return np.clip(img / scale, 0, 1) ** (1 / 2.2)


LUMA = np.array([0.2126, 0.7152, 0.0722])


def chroma(img: np.ndarray) -> np.ndarray:
    """Opponent chroma (R − Y, B − Y), Y the luminance: the colour part of an RGB value, linear in it."""
    y = img @ LUMA
    return np.stack([img[..., 0] - y, img[..., 2] - y], axis=-1)


def colour_stats(imgs: np.ndarray, exact: np.ndarray) -> dict:
    """Per-channel relative variance, and the relative RMS chroma error over pixels and trials.

    chroma error = √ mean ‖chroma(est) − chroma(exact)‖² / Y(exact)²: wrong *colour* in units of the
    pixel's brightness. Being linear in the estimate it stays finite for the signed estimates of
    control variates, where a chromaticity r/(r+g+b) would blow up.
    """
    var = imgs.var(axis=0, ddof=1)  # per pixel and channel
    rel_var = (var / (exact**2 + 1e-3)).reshape(-1, 3).mean(axis=0)
    d = chroma(imgs) - chroma(exact)[None]
    chroma_err = np.sqrt(np.mean((d**2).sum(axis=-1) / (exact @ LUMA)[None] ** 2))
    return {"rel_var": rel_var, "chroma_error": float(chroma_err)}


# %% [markdown]
# ## 1. The scene and one frame of each method
#
# A 16×16 grid over a plane with tiles, a disc and a bar of different albedo.
# Two lights sit on a line above it: red around $x=\tfrac14$, green around
# $x=\tfrac34$. Each pixel integrates $f_i(x) = \rho_i \odot L(x)\,G_i(x)$ over
# the light coordinate; the middle columns should be yellow.
#
# Each method renders 8 static frames with 2 light samples per pixel and frame;
# we show the last frame of one run:
#
# * **MC**: the frame's two samples, $f/p$ averaged.
# * **ReSTIR**: RIS on $\hat p = \text{lum}(f)$, temporal and spatial reuse
#   (3 random neighbours), shading $f(Y)W_Y$.
# * **decoupled** (Wyman & Panteleev 2021): the same reuse, shaded with every
#   candidate the passes saw.
# * **ICV** (Rousselle et al. 2016): one frame's MC images as control variates
#   of each other (Eq. 3), differences by plain MC (Eq. 4–5).
# * **STCV**: Eq. 6 over time then Eq. 8 over space, MC differences.
# * **ReSTCV**: ReSTIR with Listing 1 — differences from reservoir samples
#   (Eq. 10–11), $F$ in the reservoir.

# %%
exact = exact_image()
scale = float(np.percentile(exact, 99.5))
one_frame = {m: PROBLEM.images(m, trials=1, seed=3, params=SCENE, device=DEVICE)[0] for m in METHODS}
fig, axes = plt.subplots(1, len(METHODS) + 1, figsize=(2.1 * (len(METHODS) + 1), 2.5))
axes[0].imshow(show(exact, scale), interpolation="nearest")
axes[0].set_title("exact")
for ax, m in zip(axes[1:], METHODS):
    ax.imshow(show(one_frame[m], scale), interpolation="nearest")
    ax.set_title(LABELS[m])
for ax in axes:
    ax.set_xticks([])
    ax.set_yticks([])
fig.suptitle("chromatic-cv: the last of 8 static frames, 2 light samples per pixel and frame (one run)")
save(fig, "07_frames.png")

# %% [markdown]
# ReSTIR's pixels are saturated red or green: one sample, one light. Decoupled
# shading mixes a few candidates; ICV mixes neighbours but its MC base images
# are noisy; STCV and ReSTCV accumulate colour over eight frames and are close
# to the exact image.
#
# ## 2. Unbiasedness: z-tests per pixel and channel
#
# One trial renders all frames of the whole image from its own random stream,
# so trials are independent and the mean over trials must approach the exact
# colours in every pixel and channel. Reuse makes the *pixels* of one trial
# correlated, which does not matter here: each component is tested over
# independent trials, and the 768 verdicts share a Šidák-corrected threshold.
# The one known-biased configuration, `difference_mis=none` (Eq. 10 with
# $\hat\omega = 1$ on both sides, counting each difference twice), must fail.

# %%
Z_TRIALS = TRIALS * 2
print(f"{'method':24s} {'max|z|':>8s} {'threshold':>10s}  verdict")
for m, extra in [(m, {}) for m in METHODS] + [("restcv", {"difference_mis": "none"})]:
    est = run_toy("chromatic-cv", m, trials=Z_TRIALS, seed=SEED, params={**SCENE, **extra}, device=DEVICE)
    res = z_test(est.estimate, est.stderr, est.exact, k=DEFAULT_K)
    biased = PROBLEM.is_biased(m, est.params)
    label = m + (" difference_mis=none" if extra else "")
    verdict = ("caught" if res.max_abs_z > BIASED_K else "NOT caught") if biased else ("pass" if res.passed else "FAIL")
    print(f"{label:24s} {res.max_abs_z:8.2f} {res.threshold:10.2f}  {verdict}")

# %% [markdown]
# ## 3. Colour noise per method
#
# Two measures over many independent runs of the last frame:
#
# * **per-channel relative variance**, $\operatorname{Var}[\langle F_{i,c}\rangle] / (F_{i,c}^2 + 10^{-3})$
#   averaged over pixels — how noisy each channel is;
# * **chroma error**, the RMS error of the opponent colour components
#   $(R-Y,\ B-Y)$ ($Y$ the luminance) relative to the pixel's true $Y$, over
#   pixels and runs — wrong *colour* in units of brightness. (A chromaticity
#   $r/(r+g+b)$ would blow up on the signed estimates that control variates
#   can produce in dark pixels; this measure is linear in the estimate.)

# %%
stats = {}
for m in METHODS:
    imgs = PROBLEM.images(m, trials=TRIALS, seed=SEED + 1, params=SCENE, device=DEVICE)
    stats[m] = colour_stats(imgs, exact)
    print(f"{LABELS[m]:10s} rel. variance R/G/B = {np.array2string(stats[m]['rel_var'], precision=4)}  chroma error = {stats[m]['chroma_error']:.4f}")

fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 3.6))
x = np.arange(len(METHODS))
for c, colour in enumerate(("tab:red", "tab:green", "tab:blue")):
    ax1.bar(x + (c - 1) * 0.27, [stats[m]["rel_var"][c] for m in METHODS], width=0.27, color=colour, label="RGB"[c])
ax1.set_yscale("log")
ax1.set_xticks(x, [LABELS[m] for m in METHODS], rotation=25)
ax1.set_ylabel("relative variance per channel")
ax1.legend(title="channel")
ax1.set_title("per-channel variance of one frame")
ax2.bar(x, [stats[m]["chroma_error"] for m in METHODS], color="0.4")
ax2.set_xticks(x, [LABELS[m] for m in METHODS], rotation=25)
ax2.set_ylabel("relative RMS chroma error")
ax2.set_title("colour error (R−Y, B−Y) / Y")
save(fig, "07_colour_noise.png")

# %% [markdown]
# ReSTIR improves on MC, but unevenly: its red channel stays far noisier than
# its green one. The luminance target draws the green light about three times
# as often as the red one, and every red sample is then shaded with a large
# $f/\hat p$ — the gap between the scalar target and the colour of Sec. 4.
# Decoupled shading more than halves that. ICV lowers MC's variance but has
# only one frame of MC images to work with. The two spatio-temporal
# control-variate methods cut the variance of every channel by more than an
# order of magnitude and the chroma error several-fold — the colour is
# accumulated, not re-drawn. (With `light_width=0.5`, where the lights fill the light domain,
# ReSTIR's red channel is even noisier than plain MC's.)
#
# ## 4. The coefficient $\alpha_{ij}$ (Eq. 9; the paper's Fig. 3)
#
# With $\alpha = 1$ a neighbour across an albedo edge is a poor control
# variate: $F_i - F_j$ is large, and so is the variance of its estimate.
# $\alpha_{ij} = \min(\rho_i/\rho_j, 2)$ per channel rescales the neighbour's
# colour to pixel $i$'s albedo — exact when both see the same light — and the
# clamp at 2 keeps dark neighbours from being amplified. Below: one frame,
# and the per-pixel variance (summed over channels) of ReSTCV with each choice.

# %%
alpha_imgs = {}
for a in ("heuristic", "one"):
    alpha_imgs[a] = PROBLEM.images("restcv", trials=TRIALS, seed=SEED + 2, params={**SCENE, "alpha": a}, device=DEVICE)
var_maps = {a: alpha_imgs[a].var(axis=0, ddof=1).sum(axis=-1) for a in alpha_imgs}
vmax = float(max(v.max() for v in var_maps.values()))
fig, axes = plt.subplots(1, 5, figsize=(13, 2.9))
albedo = PROBLEM.spec(16, 0.1, DEVICE).albedo.numpy().reshape(16, 16, 3)
axes[0].imshow(albedo, interpolation="nearest")
axes[0].set_title("albedo ρ")
for k, a in enumerate(("heuristic", "one")):
    axes[1 + k].imshow(show(alpha_imgs[a][0], scale), interpolation="nearest")
    axes[1 + k].set_title(f"ReSTCV, α = {'min(ρi/ρj, 2)' if a == 'heuristic' else '1'}")
    im = axes[3 + k].imshow(var_maps[a], vmin=0, vmax=vmax, cmap="magma", interpolation="nearest")
    axes[3 + k].set_title(f"variance, α = {'Eq. 9' if a == 'heuristic' else '1'}")
for ax in axes:
    ax.set_xticks([])
    ax.set_yticks([])
fig.colorbar(im, ax=axes[3:], shrink=0.8)
save(fig, "07_alpha_ablation.png")
for a in ("heuristic", "one"):
    s = colour_stats(alpha_imgs[a], exact)
    print(f"alpha={a:9s}  rel. variance R/G/B = {np.array2string(s['rel_var'], precision=4)}  chroma error = {s['chroma_error']:.4f}")

# %% [markdown]
# With $\alpha = 1$ the variance concentrates along the albedo edges (tiles,
# disc, bar); Eq. 9 removes most of it, exactly as Fig. 3 of the paper shows
# on the VeachAjar door.
#
# ## 5. Accumulation over frames, and where ReSTIR's samples help
#
# STCV and ReSTCV differ only in how the differences are estimated: plain MC
# samples (Eq. 4) or the reservoirs' samples (Eq. 10). When the lights fill
# the light domain, uniform samples are already good; when the lights are
# small, most uniform samples see nothing, while ReSTIR's reservoirs hold
# samples on the lights. Left: relative variance of the last frame against the
# number of frames (small lights). Right: against the light width, 8 frames.

# %%
frame_counts = (1, 2, 4, 8) if QUICK else (1, 2, 4, 8, 16)
widths = (0.05, 0.1, 0.25, 0.5)
curve_methods = ("restir", "stcv", "restcv")
by_frames = {m: [] for m in curve_methods}
by_width = {m: [] for m in curve_methods}
for m in curve_methods:
    for f in frame_counts:
        est = run_toy("chromatic-cv", m, trials=TRIALS, seed=SEED + 3, params={**SCENE, "frames": f}, device=DEVICE)
        by_frames[m].append(float(np.mean(np.asarray(est.stderr) ** 2 * est.trials / (np.asarray(est.exact) ** 2 + 1e-3))))
    for w in widths:
        est = run_toy("chromatic-cv", m, trials=TRIALS, seed=SEED + 4, params={**SCENE, "light_width": w}, device=DEVICE)
        by_width[m].append(float(np.mean(np.asarray(est.stderr) ** 2 * est.trials / (np.asarray(est.exact) ** 2 + 1e-3))))
fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 3.6))
for m in curve_methods:
    ax1.plot(frame_counts, by_frames[m], "o-", label=LABELS[m])
    ax2.plot(widths, by_width[m], "o-", label=LABELS[m])
for ax in (ax1, ax2):
    ax.set_yscale("log")
    ax.set_ylabel("relative variance of the last frame")
    ax.legend()
ax1.set_xscale("log", base=2)
ax1.set_xlabel("frames T")
ax1.set_title("temporal accumulation (light width 0.1)")
ax2.set_xlabel("light width (0.5 = the lights fill [0, 1))")
ax2.set_title("difference estimates: reservoir vs MC samples")
save(fig, "07_frames_and_lights.png")
for m in ("stcv", "restcv"):
    st = run_toy("chromatic-cv", m, trials=50, seed=SEED, params=SCENE, device=DEVICE).stats
    print(
        f"{LABELS[m]:7s} uses {st['difference_samples_per_pixel_frame']:.1f} difference samples per pixel and frame,"
        f" {100 * st['difference_samples_on_light_fraction']:.0f} % of them on a light"
    )
for m in curve_methods:
    print(f"{LABELS[m]:8s} by frames {np.array2string(np.array(by_frames[m]), precision=4)}  by width {np.array2string(np.array(by_width[m]), precision=4)}")

# %% [markdown]
# The run statistics say why (seed 002, Sec. 6.1: "more valid samples
# contributing"): of STCV's uniform difference samples only the 20 % that hit
# a light carry information, while most of ReSTCV's reservoir samples lie on
# one — fewer samples, but better ones.
#
# ReSTIR's variance levels off after a few frames: temporal reuse improves
# *which* sample the reservoir holds, but one sample's colour stays as noisy
# in frame 16 as in frame 4. Both control-variate methods keep falling until the confidence cap
# (20) stops the history from growing. Across light widths the order of STCV
# and ReSTCV can swap: with the default small lights, the reservoirs' samples
# make better differences; when the lights fill the domain, uniform MC
# samples estimate differences better than ReSTIR's luminance-distributed ones,
# which under-sample the red light (the paper makes the same point about
# STCV's good showing on simply lit scenes).
#
# ## 6. The same functions in the renderer: the red–green plane
#
# The renderer `restcv` (`grisx/render/restcv.py`) is ReSTIR PT
# (`grisx/render/restir_pt.py`) with Listing 1's few changes, compiled into the
# same kernels: the path reservoir carries $\langle F\rangle$, each temporal
# and spatial reuse step forms $\alpha_{ij}\langle F_j\rangle + \langle F_i -
# \alpha_{ij}F_j\rangle$ from the two reservoirs' paths and the two shifts
# ReSTIR PT evaluates for its MIS anyway, and the pixel shows $\langle
# F\rangle$. It calls `cv_alpha`, `reservoir_difference`, `cv_estimate`,
# `compositing_weight` and `cv_composite_*` — the functions the toy above ran.
# `stcv` is the baseline that keeps each frame's own samples, and
# `restir-pt-decoupled` shades with every reuse candidate (the same hooks into
# ReSTIR PT's passes, `decoupled_contribution` from the same module).
#
# Below: the built-in scene `red-green-lights` (seed 002, Fig. 2: a white plane
# under a red and a green light), one frame after 16 frames of history under a
# static camera, against the path tracer. The number is the colour noise: the
# RMS chroma error against the reference over the lit plane, relative to its
# luminance, over a few independent runs.

# %%
from grisx.render.driver import render  # noqa: E402

RES = (48, 36) if QUICK else (128, 96)
RUNS = 2 if QUICK else 4
ref = render("red-green-lights", "pt", spp=64 if QUICK else 512, res=RES, seed=99).image.astype(np.float64)
lit = (ref @ LUMA) > 1e-3 * (ref @ LUMA).max()
lit[: RES[1] // 3] = False  # the plane only: the lights seen directly (top rows) are the same in every method
renders, noise = {}, {}
for m in ("restir-pt", "restir-pt-decoupled", "stcv", "restcv"):
    imgs = np.asarray([render("red-green-lights", m, frames=16, res=RES, seed=s, camera="static").image for s in range(RUNS)], dtype=np.float64)
    renders[m] = imgs[0]
    d = chroma(imgs) - chroma(ref)[None]
    noise[m] = float(np.sqrt(np.mean((d[:, lit] ** 2).sum(axis=-1) / (ref[lit] @ LUMA)[None] ** 2)))
    print(f"{m:20s} colour noise (relative RMS chroma error) {noise[m]:.3f}")
scale = np.percentile(ref[lit] @ LUMA, 95) * 2.0
fig, axes = plt.subplots(1, 5, figsize=(16, 2.8))
for ax, (name, img) in zip(axes, [*renders.items(), ("pt (reference)", ref)]):
    ax.imshow(show(img, scale), interpolation="nearest")
    ax.set_title(name if name not in noise else f"{name}\nchroma error {noise[name]:.2f}", fontsize=9)
    ax.axis("off")
save(fig, "07_renderer_red_green.png")

# %% [markdown]
# ReSTIR PT's pixels are red or green; decoupled shading mixes the colours of
# one pass's few candidates only; ReSTCV's and STCV's are the yellow
# mixture, with most of the colour noise gone, and the tests
# (`tests/render/test_restcv.py`) check both unbiased against the path tracer
# per 8×8 block, on this plane and in a closed room at depth 32, under a still
# and a moving camera. On this directly lit plane the shifts are nearly exact,
# so STCV's fresh samples already make good differences.
#
# ## Summary
#
# * A scalar (luminance) target cannot fix the colour of a single sample:
#   ReSTIR has colour noise even where it fits the luminance well.
# * Control variates reuse *colour estimates* across space and time and pay
#   only for a difference estimate; with the reservoir samples (Eq. 10–11) the
#   difference costs a few extra integrand evaluations per reuse candidate.
# * Unbiasedness rests on the two MIS weights of Eq. 11 summing to one and on
#   α and q not depending on the samples; break the former and a z-test finds it.
# * $\alpha_{ij} = \min(\rho_i/\rho_j, 2)$ is what makes neighbours across
#   albedo edges useful.
#
# ## References
#
# * Z. Shi, C. Wu, L. Wu, K. Xu. *Spatio-Temporal Control Variates with ReSTIR
#   for Real-Time Rendering.* SIGGRAPH 2026 (seed 002): Eq. 2–11, Listing 1, Fig. 2–3.
# * F. Rousselle, W. Jarosz, J. Novák. *Image-space control variates for
#   rendering.* ACM TOG 35(6), 2016.
# * C. Wyman, A. Panteleev. *Rearchitecting spatiotemporal resampling for
#   production.* HPG 2021 (decoupled shading).
# * D. Lin et al. *Generalized resampled importance sampling: foundations of
#   ReSTIR.* ACM TOG 41(4), 2022 (confidence weights, the cap of 20).
# * Code: `grisx/theory/control_variate.py`, `grisx/theory/toys/chromatic_cv.py`,
#   `tests/theory/test_control_variate.py`, `benchmarks/control_variates.py`;
#   the renderers `grisx/render/restcv.py` and their tests `tests/render/test_restcv.py`.

# %%
print(f"tutorial 07 done in {time.perf_counter() - T_START:.1f} s")
