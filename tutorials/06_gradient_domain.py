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
# # Tutorial 6 — Gradient-domain estimators: gradient *after* vs gradient *with* ReSTIR
#
# Gradient-domain rendering estimates, besides pixel values $F_i$, the
# differences of adjacent pixels
#
# $$\Delta_{ij} = \int_{\Omega_i} f_i - \int_{\Omega_j} f_j \qquad\text{(seed 000, Eq. 1)}$$
#
# with *correlated* samples: a path $x$ of pixel $i$ is moved to pixel $j$ by an
# inner shift $T_{ij}$ and the two contributions are subtracted. Since
# $T_{ij}$ is usually only a *partial* bijection, both pixels sample and MIS
# weights $\omega_{ij}$ split the work (Eq. 3–4). The final image is a screened
# Poisson reconstruction from the primal and the gradients.
#
# Seed 000 (Wang et al., *Gradient-domain ReSTIR Path Tracing*) asks how to
# combine this with ReSTIR. **Gradient after ReSTIR** resamples each pixel in
# the primal domain and shifts the kept path (Eq. 10–13); **Gradient with
# ReSTIR** resamples *in the paired-pixel domain*
# $\mathcal X = \Omega_i\times\{0\}\cup\Omega_j\times\{1\}$ with the target
# $\hat p = \omega^*|G_{ij}|$ (Eq. 14–20), optionally *positivized* into two
# reservoirs (Eq. 23–26). Everything here runs the functions of
# `grisx.theory.gradient` — the ones a renderer calls.
#
# Run as a script (`python tutorials/06_gradient_domain.py [--quick]`) or open
# it as a notebook with jupytext. `GRISX_QUICK=1` uses few trials; figures go
# to `$GRISX_TUTORIAL_OUT` (default `tutorials/out/`); `GRISX_DEVICE` picks the
# Warp device (default `cpu`).

# %% [markdown]
# ## What you will learn
#
# 1. The toy of the paper's Fig. 3: two pixels whose integrands agree near the
#    origin and differ elsewhere, and an ``offset`` that makes the inner shift
#    partial.
# 2. Why the *symmetric*, MIS-weighted difference is needed on a partial
#    bijection — and how a z-test catches the one-sided Eq. 2.
# 3. Where gradient-after and gradient-with put their samples (Fig. 3's
#    histogram), and what positivization buys.
# 4. RMSE against time for every method, and the equal-time ratio of
#    gradient-with over gradient-after.
# 5. Reuse across pixel pairs: a 1D row, the outer shift $T^*=(\tau, k)$,
#    temporal reuse, dense vs adaptive spatial reuse, and a 1D screened
#    Poisson reconstruction.
# 6. The same functions in the scene renderers `gpt`, `gradient-after-restir`
#    and `restir-gpt`: gradient images and their reconstruction.

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
from grisx.theory.toys.f1_f2 import f1f2_exact, f1f2_integrand_np  # noqa: E402
from grisx.theory.toys.gradient_row import row_exact_pixels, row_layout, solve_poisson_1d  # noqa: E402

QUICK = setup.quick
TRIALS = 20_000 if QUICK else 400_000
ROW_TRIALS = 600 if QUICK else 20_000
SEED = 0
DEVICE = setup.device

OUT = setup.out
T_START = setup.start
print(f"mode: {'QUICK' if QUICK else 'default'}  trials per run: {TRIALS:,}  seed: {SEED}  figures -> {OUT}")

save = setup.save


def run(method: str, trials: int = TRIALS, problem: str = "f1-f2", **params):
    return run_toy(problem, method, trials=trials, seed=SEED, params=params, device=DEVICE)


# %% [markdown]
# ## 1. Two pixels that agree near the origin
#
# Pixel 1 integrates $f_1$ over $\Omega_1=[-2,2]$, pixel 2 integrates $f_2$
# over $\Omega_2=[-2+d, 2+d]$. Both share a tall peak at 0; $f_1$ has a small
# extra peak at −1.2, $f_2$ one at 1.1. The inner shift is $x\mapsto x$: with
# $d>0$ it is defined only on the overlap (a partial bijection).

# %%
OFFSET = 0.5
x = np.linspace(-2, 2.5, 2000)
f1 = np.where(np.abs(x) <= 2, f1f2_integrand_np(0, x), np.nan)
f2 = np.where((x >= -2 + OFFSET) & (x <= 2 + OFFSET), f1f2_integrand_np(1, x), np.nan)
fig, ax = plt.subplots(figsize=(7, 3.2))
ax.plot(x, f1, label="$f_1$ on $\\Omega_1$")
ax.plot(x, f2, label=f"$f_2$ on $\\Omega_2$ (d = {OFFSET})")
ax.plot(x, np.nan_to_num(f1) - np.nan_to_num(f2), "k", lw=1, label="$f_1 - f_2$")
ax.axvspan(2, 2 + OFFSET, color="0.9", label="only pixel 2 reaches here")
ax.set_xlabel("x")
ax.legend(fontsize=8)
ax.set_title("the f1-f2 toy (seed 000, Fig. 3)")
save(fig, "06_f1_f2.png")
print(f"exact Δ: d = 0 → {f1f2_exact(0.0):.6f},  d = {OFFSET} → {f1f2_exact(OFFSET):.6f}")
# Δ happens not to depend on d (f2's floor and peaks lie inside both windows), but a
# one-sided estimator does: it misses the floor over [2, 2 + d].

# %% [markdown]
# ## 2. Every method is unbiased — the one-sided difference is not
#
# `mc-difference` samples the pixels independently; `gradient-pt` shifts
# both pixels' base paths and weights them with the balance heuristic (Eq. 4);
# `gradient-after-restir` and `gradient-with-restir` resample first. With
# $d > 0$, `gradient-pt symmetric=false` (Eq. 2: pixel 1's paths only,
# $\omega=1$) never sees $\Omega_2\setminus\Omega_1$ and is biased by
# $\int_{2}^{2+d} f_2 \approx 0.1\,d$.

# %%
CASES = [
    ("mc-difference", {}),
    ("gradient-pt", {}),
    ("gradient-after-restir", {}),
    ("gradient-with-restir", {}),
    ("gradient-with-restir", {"positivize": False}),
    ("gradient-pt", {"symmetric": False}),
]
problem = get_problem("f1-f2")
print(f"{'method':24s} {'params':22s} {'d':>4s} {'estimate':>10s} {'exact':>10s} {'z':>7s}  verdict")
for d in (0.0, OFFSET):
    for method, params in CASES:
        est = run(method, offset=d, **params)
        biased = problem.is_biased(method, est.params)
        z = z_test(est.estimate, est.stderr, est.exact, k=DEFAULT_K)
        verdict = ("caught (|z| > %g)" % BIASED_K if z.max_abs_z > BIASED_K else "NOT caught") if biased else ("ok" if z.passed else "FAIL")
        print(f"{method:24s} {str(params):22s} {d:4.1f} {est.estimate:10.5f} {est.exact:10.5f} {est.z:7.2f}  {verdict}")

# %% [markdown]
# ## 3. Where the samples go (Fig. 3)
#
# Gradient-after's primal reservoirs select paths in proportion to $f_1$ or
# $f_2$: mostly the shared peak, where $f_1 - f_2 = 0$ and the sample is
# wasted. Gradient-with's target $\omega^*|G|$ is zero there and selects the
# two peaks where the pixels differ. (`return_samples=True` gives the kept
# $x$ of each trial; for gradient-after trial $t$ reports pixel $t \bmod 2$.)

# %%
M_HIST = 32
after = run_toy("f1-f2", "gradient-after-restir", trials=TRIALS // 4, seed=SEED, params={"candidates": M_HIST, "offset": 0.0}, device=DEVICE, return_samples=True)
with_ = run_toy("f1-f2", "gradient-with-restir", trials=TRIALS // 4, seed=SEED, params={"candidates": M_HIST, "positivize": False, "offset": 0.0}, device=DEVICE, return_samples=True)
fig, ax = plt.subplots(1, 2, figsize=(11, 3.4), sharey=True)
bins = np.linspace(-2, 2, 81)
for a, est, name in ((ax[0], after, "gradient after ReSTIR"), (ax[1], with_, "gradient with ReSTIR")):
    a.hist(est.samples, bins=bins, density=True, color="C0" if a is ax[0] else "C3", alpha=0.8)
    a.set_title(f"{name}: selected x (M = {M_HIST} per pixel)")
    a.set_xlabel("x")
    a2 = a.twinx()
    a2.plot(bins, np.abs(f1f2_integrand_np(0, bins) - f1f2_integrand_np(1, bins)), "k", lw=0.8)
    a2.set_yticks([])
ax[0].set_ylabel("density of selected x  (black: |f1 − f2|)")
save(fig, "06_fig3_histogram.png")
for est, name in ((after, "after"), (with_, "with")):
    s = est.samples
    print(f"gradient-{name}: P(|x| < 0.4) = {np.mean(np.abs(s) < 0.4):.2f}, "
          f"P(near the differing peaks) = {np.mean((np.abs(s + 1.2) < 0.3) | (np.abs(s - 1.1) < 0.3)):.2f}")

# %% [markdown]
# ## 4. Positivization
#
# $\omega^* G$ changes sign: with one reservoir ($\hat p=\omega^*|G|$) a trial
# returns either a positive or a negative value ("sign noise"). Two
# reservoirs `pos`/`neg` with targets $\max(\pm\omega^*G, 0)$, fed the *same*
# candidates, each estimate one sign's integral; their sum is $\Delta$.
# With temporal reuse (`frames`), `cross_sign=true` also merges the previous
# frame's reservoir of the other sign. Here the outer shift (a zoom) never
# flips a sign, so cross-sign reuse only adds cost — the paper reports the
# same in practice (Sec. 4.4).

# %%
print(f"{'configuration':44s} {'var/trial':>10s} {'us/trial':>9s}")
for label, params in (
    ("one reservoir, p̂ = ω*|G| (Eq. 19)", {"positivize": False}),
    ("pos + neg reservoirs (Eq. 23–26)", {}),
    ("pos + neg, 2 frames of temporal reuse", {"frames": 2}),
    ("pos + neg, 2 frames, reuse across signs", {"frames": 2, "cross_sign": True}),
):
    est = run("gradient-with-restir", trials=TRIALS // 2, offset=OFFSET, **params)
    print(f"{label:44s} {est.stderr**2 * est.trials:10.4g} {1e6 * est.seconds / est.trials:9.2f}")

# %% [markdown]
# ## 5. RMSE against time
#
# Each method runs a ladder of trial counts; the RMSE of the mean (its
# standard error) is plotted against the seconds it took. Lines further down
# and left are better; the equal-time efficiency ratio is
# $(\mathrm{var}\cdot t)_{\text{after}} / (\mathrm{var}\cdot t)_{\text{with}}$.
# (`benchmarks/gradient.py` does this with repeats and saves JSON.)

# %%
LADDER = (2_000, 6_000, 20_000) if QUICK else (10_000, 30_000, 100_000, 300_000)
METHODS = [
    ("mc-difference", {}),
    ("gradient-pt", {}),
    ("gradient-after-restir", {}),
    ("gradient-with-restir", {}),
    ("gradient-with-restir", {"positivize": False}),
]
fig, ax = plt.subplots(figsize=(7, 4))
eff = {}
for method, params in METHODS:
    label = method + ("" if not params else " " + ",".join(f"{k}={v}" for k, v in params.items()))
    pts = [run(method, trials=n, offset=OFFSET, **params) for n in LADDER]
    ax.loglog([e.seconds for e in pts], [e.stderr for e in pts], "o-", label=label)
    last = pts[-1]
    eff[label] = 1.0 / (last.stderr**2 * last.trials * last.seconds / last.trials)
ax.set_xlabel("seconds")
ax.set_ylabel("RMSE of the mean")
ax.set_title(f"f1-f2, d = {OFFSET}, M = 8 per pixel ({DEVICE})")
ax.grid(True, which="both", alpha=0.3)
ax.legend(fontsize=8)
save(fig, "06_rmse_vs_time.png")
ratio = eff["gradient-with-restir"] / eff["gradient-after-restir"]
print(f"equal-time efficiency ratio gradient-with / gradient-after: {ratio:.2f}")
print(f"gradient-pt / gradient-after: {eff['gradient-pt'] / eff['gradient-after-restir']:.2f}  "
      "(on this cheap 1D toy plain shift-mapped differences are hard to beat: the identity shift cancels the shared peak exactly)")

# %% [markdown]
# Gradient-with beats gradient-after at equal time (the paper's claim), but
# plain `gradient-pt` beats both here. That is not an accident: without reuse,
# the positivized gradient-with estimate $\sum w_+ - \sum w_-$ equals
# $\frac1M\sum_l \omega^*G/p$ over the shared candidates — gradient-PT's
# estimator on the same samples (the table in section 4 shows the same
# variance, 0.048). Resampling only decides *which* sample is kept, which
# pays off when that sample is **reused** (temporal reuse halves the variance
# above) and when evaluating a path costs much more than a weight, as in a
# renderer; on a 1D toy the reservoir bookkeeping is pure overhead.
#
# ## 6. Reuse across pixel pairs: a 1D row
#
# `gradient-row` is a row of stripes (albedo 0.3/0.9, seed 000's Fig. 6 in
# 1D). Pairs $(i{+}1, i)$ give forward differences. Gradient-with reuses a
# pair's reservoirs over frames (temporal) and other pairs' reservoirs
# (spatial) through the outer shift $T^*(x,k)=(\tau(x),k)$, whose Jacobian is
# $|\partial\tau/\partial x|$ (Eq. 21–22). `spatial=dense` merges random
# neighbours everywhere; `spatial=adaptive` merges only at *edge pairs*
# (albedo jump above a threshold) and only from similar edge pairs.

# %%
ROW = {"pixels": 16, "stripe": 4}
albedo = row_layout(16, 4)
edges = np.nonzero(np.abs(np.diff(albedo)) > 0.1)[0]
results = {}
for label, method, params in (
    ("gradient-pt", "gradient-pt", {}),
    ("with, no spatial", "gradient-with-restir", {"spatial": "none", "frames": 0}),
    ("with, dense", "gradient-with-restir", {"spatial": "dense", "frames": 0}),
    ("with, adaptive", "gradient-with-restir", {"spatial": "adaptive", "frames": 0}),
):
    results[label] = run(method, trials=ROW_TRIALS, problem="gradient-row", **ROW, **params)
print(f"{'method':18s} {'edge var':>9s} {'flat var':>9s} {'merges/pair':>11s} {'us/trial':>9s} {'max|z|':>7s}")
for label, est in results.items():
    var = np.asarray(est.stderr) ** 2 * est.trials
    merges = est.stats["spatial_merges"] if est.stats else 0.0
    print(f"{label:18s} {var[edges].mean():9.4f} {np.delete(var, edges).mean():9.5f} {merges:11.2f} "
          f"{1e6 * est.seconds / est.trials:9.1f} {z_test(est.estimate, est.stderr, est.exact).max_abs_z:7.2f}")

# %% [markdown]
# Adaptive reuse spends its merges where the gradients are (about one pair in
# four here) and leaves flat pairs alone; dense reuse pays for a merge at
# every pair and, at edge pairs, mostly draws *flat* neighbours whose samples
# do not fit.
#
# Spatial reuse only helps when the outer shift carries a neighbour's
# integrand onto the pair's own. In this row the light drifts along the row
# (`light_drift`, 0.004 per pixel in the pixel coordinate $u$ that $\tau$
# keeps fixed), so a pair 8 pixels away sees it 0.032 off (its width is 0.07).
# Without a temporal history any extra samples help; with three frames of
# history the pair's own samples fit better than the neighbour's, and reuse
# pays only when the neighbours really match (`light_drift=0`):

# %%
print(f"{'3 earlier frames':30s} {'edge var':>9s}")
for drift in (0.004, 0.0):
    for sp in ("none", "adaptive"):
        est = run("gradient-with-restir", trials=ROW_TRIALS, problem="gradient-row", **ROW, spatial=sp, frames=3, light_drift=drift)
        var = np.asarray(est.stderr) ** 2 * est.trials
        print(f"light_drift={drift:<6g} spatial={sp:9s} {var[edges].mean():9.5f}")

# %% [markdown]
# ## 7. Reconstruction: a 1D screened Poisson solve
#
# `output=pixels` estimates the primal row with plain MC and solves
# $(\alpha^2 I + D^\top D)\,I = \alpha^2 P + D^\top\Delta$ per trial (L2, so
# the reconstruction of unbiased inputs is unbiased). Below, one trial's
# gradients and primal from the same budget, reconstructed by
# `solve_poisson_1d` (the same Thomas solver the toy uses, checked against
# `grisx.poisson` in the tests).

# %%
exact = row_exact_pixels(16, 4)
rng = np.random.default_rng(SEED)
est_px = run("gradient-with-restir", trials=ROW_TRIALS, problem="gradient-row", **ROW, spatial="adaptive", frames=0, output="pixels")
print(f"reconstructed pixels: max|z| = {z_test(est_px.estimate, est_px.stderr, est_px.exact).max_abs_z:.2f} over 16 pixels")
noisy_primal = exact + rng.normal(scale=0.08, size=16)
noisy_grad = np.diff(exact) + rng.normal(scale=0.02, size=15)
recon = solve_poisson_1d(noisy_primal, noisy_grad, alpha=0.2)[0]
fig, ax = plt.subplots(figsize=(7, 3.2))
ax.plot(exact, "k-", label="exact $F_i$")
ax.plot(noisy_primal, "o", ms=4, label="noisy primal (σ = 0.08)")
ax.plot(recon, "s-", ms=4, label="screened Poisson with gradients (σ = 0.02)")
ax.errorbar(np.arange(16) + 0.15, est_px.estimate, yerr=4 * np.asarray(est_px.stderr), fmt=".", label=f"toy output=pixels, mean of {ROW_TRIALS} trials ± 4σ")
ax.set_xlabel("pixel")
ax.legend(fontsize=7)
ax.set_title("1D row: gradients turn a noisy primal into a clean reconstruction")
save(fig, "06_row_poisson.png")

# %% [markdown]
# ## 8. In a scene: the same functions in the renderer
#
# The renderers of `grisx.render` call the very functions this tutorial ran on
# the toys: `pair_value` (ω*G, Eq. 14–16) and `pair_estimate` (Eq. 17) for every
# pixel pair, `signed_target`/`pair_update` (Eq. 19, 25–26) and the
# `pair_balance_*` MIS of a positivized merge, `outer_shift_of` (Eq. 21–22) for
# reuse between pairs. Each pixel's sample carries its film position (Area
# ReSTIR's sample space), so the inner shift between pixels i and j is a film
# translation followed by the hybrid path shift.
#
# * `gpt` — gradient-domain path tracing (B.2): fresh base paths shifted to
#   the four neighbours;
# * `gradient-after-restir` — B.1: Area ReSTIR's kept paths shifted;
# * `restir-gpt` — paired-pixel reservoirs, temporal and adaptive spatial
#   reuse of pairs, positivization.
#
# Each returns the screened Poisson image (L2 by default) and keeps the
# primal, dx and dy (`renderer.extra()`; the render CLI writes them as EXRs).
# The numbers below are one frame's errors at a tiny size on the CPU, not the
# paper's equal-time comparison (that is `benchmarks/gradient_domain.py`, on CUDA).
# At a few frames the gradients still have outliers (failed or badly
# conditioned shifts): the L2 reconstruction, unbiased, spreads them; the L1
# one (IRLS), slightly biased, suppresses them — Lehtinen et al.'s observation.
#
# `reconstruct` is a one-off. A renderer solves every frame from the same three
# buffers, so it keeps a `grisx.poisson.ScreenedPoisson` bound to them: buffers
# and (on a GPU) one CUDA graph made once, CG's stopping rule on the device. CG
# is preconditioned by a multigrid V-cycle (`grisx.poisson.multigrid`): the
# system's condition number is about 200 at α = 0.2, Jacobi-preconditioned CG
# needs some 60 iterations for a relative residual of 1e-5, the V-cycle about 10.

# %%
from grisx.eval.metrics import relmse  # noqa: E402
from grisx.poisson import forward_gradient, reconstruct  # noqa: E402
from grisx.render.driver import render  # noqa: E402

SCENE = "cornell-box"
SCENE_RES = (48, 36) if QUICK else (160, 120)
SCENE_FRAMES = 4 if QUICK else 16
REF_SPP = 64 if QUICK else 1024
scene_ref = render(SCENE, "pt", spp=REF_SPP, res=SCENE_RES, device=DEVICE, seed=SEED + 99, params={"max_depth": 6}).image
ref_grad = forward_gradient(scene_ref)
scene_runs = {}
for method in ("area-restir", "gpt", "gradient-after-restir", "restir-gpt"):
    t0 = time.perf_counter()
    spp = 1 if method == "gpt" else None  # gpt: one fresh sample per pixel and frame, like the others
    res = render(SCENE, method, res=SCENE_RES, frames=SCENE_FRAMES, spp=spp, device=DEVICE, seed=SEED, params={"max_depth": 6})
    scene_runs[method] = res
    grads = ""
    if res.extra:
        l1 = reconstruct(res.extra["primal"], res.extra["dx"], res.extra["dy"], norm="L1")  # the same frame, robust to outliers
        grads = f" (L2), L1 {relmse(l1, scene_ref):.3f}, primal {relmse(res.extra['primal'], scene_ref):.3f}, dx {relmse(res.extra['dx'][:, :-1], ref_grad.dx[:, :-1]):.3f}"
    print(f"{method:22s} last frame ({SCENE_FRAMES} frames, static camera): relMSE {relmse(res.image, scene_ref):.3f}{grads}  ({time.perf_counter() - t0:.1f} s incl. compiling)")

# %%
g = scene_runs["restir-gpt"].extra
panels = [("primal", g["primal"]), ("dx", g["dx"]), ("dy", g["dy"]), ("L2 reconstruction", scene_runs["restir-gpt"].image),
          ("L1 reconstruction", reconstruct(g["primal"], g["dx"], g["dy"], norm="L1")), (f"pt, {REF_SPP} spp", scene_ref)]
fig, axes = plt.subplots(1, len(panels), figsize=(3.2 * len(panels), 2.8))
for ax, (name, img) in zip(axes, panels):
    lum = img @ np.array([0.2126, 0.7152, 0.0722])
    if name in ("dx", "dy"):
        lim = np.percentile(np.abs(lum), 99) + 1e-6
        ax.imshow(lum, cmap="coolwarm", vmin=-lim, vmax=lim)
    else:
        ax.imshow(np.clip(img / (np.percentile(scene_ref, 99) + 1e-6), 0, 1) ** (1 / 2.2))
    ax.set_title(f"{name}", fontsize=8)
    ax.axis("off")
fig.suptitle(f"restir-gpt on {SCENE}, one frame of {SCENE_FRAMES} ({SCENE_RES[0]}×{SCENE_RES[1]}, {DEVICE})", fontsize=9)
save(fig, "06_scene_gradients.png")

# %% [markdown]
# ## Summary and references
#
# * The paired-pixel domain turns Eq. 3's *two* integrals into one, so ReSTIR
#   can resample pixel *differences*: gradient-with picks paths where
#   $f_1 - f_2$ is large, gradient-after where $f_1$ or $f_2$ is.
# * MIS between the two pixels' paths is not optional on a partial bijection:
#   the one-sided estimator is biased, and the z-test says so.
# * Positivization removes sign noise; reuse across signs matters only where a
#   shift can flip a sign.
# * Adaptive spatial reuse spends merges only on edge pairs.
#
# References: seed 000 (Wang et al., *Gradient-domain ReSTIR Path Tracing*),
# Eq. 1–4, 10–26, Fig. 3, 6, 9, 10; Kettunen et al., *Gradient-domain path
# tracing*, ACM TOG 34(4), 2015; Lin et al., *Generalized resampled importance
# sampling*, ACM TOG 41(4), 2022; Chang et al., *Parameter-space ReSTIR*, 2023.

# %%
print(f"done in {time.perf_counter() - T_START:.1f} s")
