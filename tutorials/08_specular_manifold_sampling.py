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
# # Tutorial 8 — Specular manifold sampling: Bernoulli trials, trust regions, priors and ReSTIR
#
# A caustic path (light → mirror/glass → diffuse point) is pinned down by the
# *specular constraint*: the path must obey the law of reflection at every
# specular vertex. Specular manifold sampling (SMS, Zeltner et al. 2020) finds
# such paths with Newton's method — a **manifold walk** from a random *seed* u
# in a 2D primary sample space U = [0, 1)² to a solution u* of C(u) = 0.
#
# The catch is the pdf. Which solution a walk reaches depends on which
# **convergence basin** the seed fell into, so the probability of a solution is
# the basin's area P(u*) — unknown. SMS estimates its *reciprocal* without bias
# by **Bernoulli trials**: draw fresh seeds until one walks to the same u*; the
# count K has E[K] = 1/P(u*) and is the sample's unbiased contribution weight
# (seed 003, Eq. 1–2). Hong et al. (seed 003) make this cheaper and less noisy:
#
# * **trust regions** — cut U into N × N tiles and stop walks that leave the
#   3 × 3 tiles around their seed; Bernoulli trials then only search the
#   *conditional sample space* C(u*) and W = K / P(C) (Eq. 4–6, 8);
# * **priors** — presampled walks of nearby pixels mark the tiles I that hold
#   solutions, and seeds come from α p_I + (1 − α) p_U (Eq. 7, 9);
# * **ReSTIR** — reuse solutions across pixels and frames with the *manifold
#   shift* (a short walk from the neighbour's solution, checked by walking back)
#   and pairwise MIS (Sec. 5).
#
# Everything below runs `grisx.theory.manifold`, the same Warp functions a
# scene-layer caustics renderer calls, on the `sms-toy` problem, whose four
# solutions per pixel are known in closed form.
#
# Run it as a script (`python tutorials/08_specular_manifold_sampling.py
# [--quick]`) or open it as a notebook with jupytext. `GRISX_QUICK=1` uses few
# trials; figures go to `$GRISX_TUTORIAL_OUT` (default `tutorials/out/`);
# `GRISX_DEVICE` picks the device (default cpu).

# %% [markdown]
# ## What you will learn
#
# 1. What the toy "specular chain" is and what its convergence basins look like
#    (seed 003, Fig. 2 in toy form), with and without trust regions.
# 2. Why the Bernoulli-trial count is an unbiased inverse probability, checked
#    against basin areas measured by brute force.
# 3. How a cap on the trials loses energy — and why trust regions lose less.
# 4. The cost statistics of seed 003's Table 1 (success rate, Newton
#    iterations per sample and per solution, Bernoulli trials per solution) for
#    SMS, tiles with and without prior, and ReSTIR, next to their error.
# 5. The same functions in a scene: a caustic chain through a bumpy glass slab
#    solved on real geometry, and the caustic rendered by `pt`, `sms`,
#    `sms-partitioned` and `sms-restir` at equal time.

# %% Setup
import time

import matplotlib
import numpy as np


# quick mode, device, figure folder and the off-screen backend (before pyplot is imported)
from grisx.tutorial import tutorial_setup

setup = tutorial_setup(globals().get("__file__"))
INTERACTIVE = setup.interactive
import matplotlib.colors  # noqa: E402
import matplotlib.patches  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402

from grisx.testing import DEFAULT_K, z_test  # noqa: E402
from grisx.theory.toys import run_toy  # noqa: E402
from grisx.theory.toys.sms_toy import basin_map, bernoulli_samples  # noqa: E402

QUICK = setup.quick
TRIALS = 3_000 if QUICK else 100_000
SEED = 0
DEVICE = setup.device

OUT = setup.out
T_START = setup.start
print(f"mode: {'QUICK' if QUICK else 'default'}  trials per run: {TRIALS:,}  seed: {SEED}  figures -> {OUT}")

save = setup.save


# %% [markdown]
# ## 1. The toy specular chain and its basins
#
# Pixel v has the constraint
#
# $$ C(u; v) = \bigl(g(2\pi(u_0 + u_1); k_0) - a_v,\; g(2\pi u_1; k_1) - b_v\bigr),\qquad
#    g(\theta; k) = \sin\bigl(2\arctan(k\tan\tfrac\theta2)\bigr), $$
#
# a sheared pair of sines seen through a warp that stretches θ ≈ 0 by k. Each
# axis has two roots, so there are four solutions, in closed form, drifting
# smoothly with the pixel. Newton's method uses the analytic Jacobian. The warp
# makes the basins uneven: the solutions where the warp stretches have thin
# basins (hard to reach), and near the folds (g' = 0) the walks jump around
# the torus chaotically — the fractal fringes below.
#
# Left: every seed coloured by the solution its walk reaches (plain SMS).
# Right: the same with N = 10 tiles and 3 × 3 trust regions (seed 003, Fig. 2):
# a walk that leaves its trust region stops (white), so each basin shrinks to
# its intersection with the conditional sample space C(u*) (boxes).

# %%
RES = 256 if QUICK else 768
VIEW = 1
TILES_FIG = 10
free = basin_map(view=VIEW, resolution=RES, tiles=0, device=DEVICE)
part = basin_map(view=VIEW, resolution=RES, tiles=TILES_FIG, device=DEVICE)
sols = free["solutions"]
colors = ["tab:red", "tab:blue", "tab:green", "tab:orange"]
cmap = matplotlib.colors.ListedColormap(["white"] + colors)
areas = [float(np.mean(free["basin"] == k)) for k in range(4)]

fig, axes = plt.subplots(1, 2, figsize=(11, 5.4))
for ax, data, title in ((axes[0], free, "SMS: convergence basins"), (axes[1], part, f"N = {TILES_FIG}: basins ∩ C(u*)")):
    ax.imshow(data["basin"] + 1, origin="lower", extent=(0, 1, 0, 1), cmap=cmap, vmin=-0.5, vmax=4.5, interpolation="nearest")
    for k, (x, y) in enumerate(sols):
        ax.scatter([x], [y], marker="*", s=220, c="white", edgecolors="k", linewidths=1.2, zorder=5)
        ax.annotate(f"u*_{k}", (x, y), xytext=(6, 6), textcoords="offset points", fontsize=9, weight="bold", zorder=6)
    ax.set_title(title)
    ax.set_xlabel("$u_0$")
    ax.set_ylabel("$u_1$")
for k, (x, y) in enumerate(sols):
    tx, ty = int(x * TILES_FIG), int(y * TILES_FIG)
    for ox in (-1, 0, 1):  # draw C(u*) with periodic wrap
        for oy in (-1, 0, 1):
            axes[1].add_patch(matplotlib.patches.Rectangle(((tx - 1 + ox * TILES_FIG) / TILES_FIG, (ty - 1 + oy * TILES_FIG) / TILES_FIG), 3 / TILES_FIG, 3 / TILES_FIG, fill=False, ec=colors[k], lw=1.5))
axes[1].set_xlim(0, 1)
axes[1].set_ylim(0, 1)
axes[1].set_xticks(np.linspace(0, 1, TILES_FIG + 1), minor=True)
axes[1].set_yticks(np.linspace(0, 1, TILES_FIG + 1), minor=True)
axes[1].grid(which="minor", color="0.6", lw=0.4)
axes[0].legend(handles=[matplotlib.patches.Patch(color=c, label=f"u*_{k}: P = {a:.3f}") for k, (c, a) in enumerate(zip(colors, areas))], loc="upper right", fontsize=8, framealpha=0.9)
save(fig, "08_basins.png")
print("basin areas P(u*_k):", np.round(areas, 4), "  mean Newton steps per walk:", round(float(free["iterations"].mean()), 2), "(SMS) vs", round(float(part["iterations"].mean()), 2), f"(N = {TILES_FIG})")

# %% [markdown]
# ## 2. Bernoulli trials: E[K] = 1/P
#
# Draw fresh seeds until one reaches the same solution (the same, as Newton
# measures it: ∂C/∂u maps the two ends within 10× the walk's tolerance, for a
# walk stops anywhere |C| is small enough). The count K is
# geometric with success probability P(u*), so E[K] = 1/P(u*) (Eq. 2), and
# f(u*)·K estimates f(u*)/P(u*) without knowing P. With trust regions the
# seeds come from C(u*) only, E[K] = P(C)/P'(u*), and W = K/P(C) (Eq. 5).
# Below: the mean of K over many runs of the core's Bernoulli function against
# the basin areas measured on a stratified seed grid.

# %%
n_bern = 4_000 if QUICK else 50_000
grid_res = 512 if QUICK else 1024
print(f"{'solution':>8} {'P (grid)':>9} {'1/P':>8} {'mean K':>8} {'±':>6}   {'N=8: P(C)/P_prime':>18} {'mean K':>8}")
grid0 = basin_map(view=VIEW, resolution=grid_res, jitter=SEED, device=DEVICE)["basin"]
grid8 = basin_map(view=VIEW, resolution=grid_res, tiles=8, jitter=SEED, device=DEVICE)["basin"]
for k in range(4):
    p, p8 = float(np.mean(grid0 == k)), float(np.mean(grid8 == k))
    kk = bernoulli_samples(VIEW, k, n_bern, seed=SEED + k, device=DEVICE)["trials"]
    k8 = bernoulli_samples(VIEW, k, n_bern, seed=SEED + k, tiles=8, device=DEVICE)["trials"]
    print(f"{k:>8} {p:9.4f} {1 / p:8.2f} {kk.mean():8.2f} {kk.std() / np.sqrt(n_bern):6.2f}   {9 / 64 / p8:18.2f} {k8.mean():8.2f}")

# %% [markdown]
# ## 3. Capping the trials loses energy
#
# Interactive renderers cannot wait for unbounded trials, so they cap K at
# `max_trials`. Then E[min(K, cap)] = (1 − (1 − P)^cap)/P: the hard solutions
# lose energy. Trust regions raise the probability inside C, so the same cap
# loses less (seed 003, Fig. 7). We measure the relative bias
# (estimate − exact)/exact, averaged over the 8 pixels.
#
# A cap is not needed for speed, though. Trials are independent given their
# index t (trial t draws its seed from counters 4t … of the solution's key),
# so K — one plus the index of the first trial that hits — can be found by
# running many trials of one solution at once and keeping the smallest index
# that hits. grisx's renderers do that on a GPU (`grisx.render.sms.BernoulliStage`):
# a solution runs one trial in its sample pass and the rest in a stage of their
# own, with the serial loop's K bit for bit. On `caustic-slab-plane` at 1080p,
# where single solutions need thousands of trials, uncapped manifold sampling
# takes about 19 ms a frame on an H200; run in series, one such pixel held its
# warp and the pass took about 160 ms.

# %%
caps = [1, 2, 4, 8, 16, 32, 128]
loss = {"sms": [], "sms-partitioned": []}
for cap in caps:
    for method in loss:
        params = {"max_trials": cap} | ({"prior": False, "tiles": 8} if method != "sms" else {})
        est = run_toy("sms-toy", method, trials=TRIALS, seed=SEED, params=params, device=DEVICE)
        rel = (np.asarray(est.estimate) - est.exact) / est.exact
        loss[method].append((float(rel.mean()), float(np.mean(np.asarray(est.stderr) / est.exact) / np.sqrt(len(rel)))))
fig, ax = plt.subplots(figsize=(6.5, 4))
for method, label in (("sms", "SMS"), ("sms-partitioned", "N = 8, no prior")):
    m = np.array(loss[method])
    ax.errorbar(caps, -m[:, 0] * 100, yerr=m[:, 1] * 100, marker="o", capsize=3, label=label)
ax.set_xscale("log", base=2)
ax.set_xlabel("max_trials (cap on Bernoulli trials)")
ax.set_ylabel("energy loss (%)")
ax.axhline(0, color="k", lw=0.6)
ax.legend()
ax.set_title("Capped Bernoulli trials lose energy")
save(fig, "08_energy_loss.png")
for method in loss:
    print(method, "energy loss % by cap:", {c: round(-100 * m, 2) for c, (m, _) in zip(caps, loss[method])})

# %% [markdown]
# ## 4. The statistics table (seed 003, Table 1 in toy form)
#
# Every method with unbounded trials (so all are unbiased: see max|z|) on the
# same 8 pixels. Columns: success rate of the sampling walk, Newton iterations
# per sample (the sampling walk), Bernoulli trials per solution, Newton
# iterations per solution (spent in the Bernoulli trials), all Newton
# iterations per sample (including prior presampling and ReSTIR's shifts), the
# RMSE of one trial and the max |z| against the exact sums. ReSTIR's row is the
# last of 4 frames.
#
# Read the table along two axes. Growing N makes the inverse probability cheap
# (Bernoulli trials and Newton iterations per solution fall) but the success
# rate and with it the variance suffer; the prior restores the success rate
# and lowers the variance again. Here the prior is paid for with 64 presampled
# walks per 8-pixel block and frame (8 per pixel, against 0.5 per pixel in
# seed 003's 16 × 16 blocks), which the "all Newton" column shows.

# %%
rows = [("sms", "SMS", {})]
for tiles in (4, 8, 16, 32):
    rows.append(("sms-partitioned", f"N={tiles}", {"tiles": tiles, "prior": False}))
    rows.append(("sms-partitioned", f"N={tiles} + prior", {"tiles": tiles, "prior": True}))
rows.append(("sms-restir", "N=16 + prior + ReSTIR", {"tiles": 16, "prior": True}))
table = []
for method, label, params in rows:
    est = run_toy("sms-toy", method, trials=TRIALS, seed=SEED, params={"max_trials": 0} | params, device=DEVICE)
    s = est.stats
    check = z_test(est.estimate, est.stderr, est.exact, k=DEFAULT_K)
    table.append((label, s["success_rate"], s["newton_per_sample"], s["bernoulli_per_solution"], s["newton_per_solution"], s["newton_total_per_sample"], est.rmse, check.max_abs_z))
header = f"{'method':<24}{'success':>8}{'Newton/':>9}{'Bern./':>8}{'Newton/':>9}{'all Newton/':>12}{'RMSE':>8}{'max|z|':>8}"
print(header)
print(f"{'':<24}{'rate':>8}{'sample':>9}{'sol.':>8}{'sol.':>9}{'sample':>12}{'(1 trial)':>8}")
for r in table:
    print(f"{r[0]:<24}{r[1]:8.1%}{r[2]:9.2f}{r[3]:8.2f}{r[4]:9.2f}{r[5]:12.2f}{r[6]:8.2f}{r[7]:8.2f}")
sms_row = table[0]
best = min(table[1:-1], key=lambda r: r[4])
print(f"Newton iterations per solution: SMS {sms_row[4]:.2f} -> {best[0]} {best[4]:.2f} (ratio {sms_row[4] / best[4]:.1f}x; seed 003: 67 -> 8.7 slab, 1183 -> 39 plane)")

fig, ax = plt.subplots(figsize=(7, 4))
labels = [r[0] for r in table]
ax.barh(labels, [r[4] for r in table], color=["tab:gray"] + ["tab:blue", "tab:green"] * 4 + ["tab:purple"])
ax.invert_yaxis()
ax.set_xlabel("Newton iterations per solution (Bernoulli trials)")
ax.set_title("Trust regions cut the cost of the inverse probability")
save(fig, "08_table.png")

# %% [markdown]
# ## 5. In a scene: the toy's functions on real geometry
#
# `grisx.scene.caustics` gives the walk a real constraint. From a shading point
# x₁ on the floor, a seed u picks a direction toward the slab (a square around
# its bounding sphere); the ray is traced through the slab's canonical lobes —
# refraction in, refraction out, with the bumped shading normals — and
# C(u) = (where the last ray meets the light's plane) − x_n. Newton's method
# on C is `make_manifold_sampler`'s walk, the same function the toy used above;
# so are the Bernoulli trials, the tiles, P(C), the prior and the manifold
# shift of `sms-restir`. The chain's solutions obey Snell's law at both
# vertices (checked in `tests/render/test_sms.py` from the vertices alone).
#
# The renderers split the image by ownership: SMS owns the paths
# x₁ → (1–2 delta vertices on their canonical lobes) → emitter whose first
# direction lies in a caster's seed square (at most 2r wide) and meets the
# caster at |cos| ≥ 0.1 (near the silhouette no walk converges reliably);
# the path tracer drops exactly
# those emitter hits. So `pt` and every SMS method estimate the same image,
# and the comparison below is at equal time against a `pt` reference.

# %%
from grisx.render.driver import load_scene, render  # noqa: E402
from grisx.scene.caustics import solve_chains  # noqa: E402

built = load_scene("caustic-slab").build(DEVICE)
slab = next(i for i, o in enumerate(built.scene.objects) if o.name == "slab")
seeds = np.random.default_rng(SEED).random((512, 2))
walks = solve_chains(built, (0.05, 0.0, 0.0), (0, 1, 0), slab, (0.1, 1.6, 0.05), (0, -1, 0), seeds)
ok = walks["converged"] == 1
found = walks["u"][ok]
distinct = []
for u in found:
    if all(np.linalg.norm(((u - v) + 0.5) % 1.0 - 0.5) > 1e-3 for v in distinct):
        distinct.append(u)
print(f"{ok.sum()} of {len(seeds)} seeds converged, to {len(distinct)} distinct solutions; "
      f"geometry terms |dω/dA(x_n)| {np.round(np.unique(np.round(walks['geometry'][ok], 3))[:6], 3)}")

SCENE_RES = (48, 36) if QUICK else (128, 96)
REF_SPP = 1024 if QUICK else 8192
reference = render("caustic-slab", "pt", res=SCENE_RES, spp=REF_SPP, seed=SEED + 1, device=DEVICE).image.astype(np.float64)


def relmse(img: np.ndarray) -> float:
    return float(np.mean((img - reference) ** 2 / (reference**2 + 1e-2)))


# the cost of one pass of each method (compiled already: a second short render), then equal time
methods = [("pt", {}), ("sms", {}), ("sms-partitioned", {}), ("sms-restir", {})]
per_pass = {}
for m, prm in methods:
    for _ in range(2):
        r = render("caustic-slab", m, res=SCENE_RES, **({"spp": 4} if m != "sms-restir" else {"frames": 4, "accumulate": True}), params=prm, device=DEVICE, seed=SEED)
    per_pass[m] = r.seconds / 4
budget = 40 * max(per_pass.values())
scene_rows = []
images = {}
for m, prm in methods:
    n = max(1, int(budget / per_pass[m]))
    kw = {"spp": n} if m != "sms-restir" else {"frames": n, "accumulate": True}
    r = render("caustic-slab", m, res=SCENE_RES, params=prm, device=DEVICE, seed=SEED + 7, **kw)
    images[m] = r.image
    st = r.settings.get("statistics", {})
    scene_rows.append((m, n, r.seconds, relmse(r.image), st.get("success_rate", float("nan")), st.get("newton_per_solution", float("nan")), st.get("bernoulli_per_solution", float("nan"))))
print(f"{'method':<18}{'passes':>7}{'seconds':>9}{'relMSE':>10}{'success':>9}{'Newton/sol':>11}{'Bern./sol':>10}")
for r in scene_rows:
    print(f"{r[0]:<18}{r[1]:7d}{r[2]:9.3f}{r[3]:10.4f}{r[4]:9.1%}{r[5]:11.2f}{r[6]:10.2f}")

fig, axes = plt.subplots(1, len(methods) + 1, figsize=(3.2 * (len(methods) + 1), 2.8))
for ax, (name, img) in zip(axes, [("pt reference", reference)] + [(f"{m} (equal time)", images[m]) for m, _ in methods]):
    ax.imshow(np.clip(img / (1.0 + img), 0, 1) ** (1 / 2.2))
    ax.set_title(name, fontsize=9)
    ax.axis("off")
save(fig, "08_scene.png")

# %% [markdown]
# ## What to take away
#
# * A walk's destination is a *discrete* random variable; its probability is a
#   basin area, and Bernoulli trials estimate 1/area without bias (Eq. 1–3).
# * Trust regions shrink basins to C(u*) and make the trials cheap: fewer
#   trials (P(C)/P' instead of 1/P) and shorter walks — but alone they lower
#   the success rate and raise variance as N grows.
# * The prior (Eq. 7–9) puts seeds back where solutions are: success rate and
#   variance recover while the per-solution cost stays low; its presampling
#   is worth it when shared by many pixels. Its p_U share
#   keeps every solution reachable, so it stays unbiased even when the
#   presamples miss a solution — at the price of rare large weights (seed 003,
#   Fig. 10).
# * A cap on the trials is a bias, not a variance trade: measure its energy loss.
# * ReSTIR reuses solutions through manifold shifts (4 walks per neighbour with
#   pairwise MIS) and removes most of the remaining noise.
#
# ## References
#
# * P. Hong, M. Duan, B. Wang, C. Yuksel, T. Zeltner, D. Lin, "Sample Space
#   Partitioning and Spatiotemporal Resampling for Specular Manifold Sampling",
#   SIGGRAPH Asia 2025 (seed 003).
# * T. Zeltner, I. Georgiev, W. Jakob, "Specular Manifold Sampling for Rendering
#   High-Frequency Caustics and Glints", SIGGRAPH 2020.
# * W. Jakob, S. Marschner, "Manifold Exploration", SIGGRAPH 2012.
# * T. E. Booth, "Unbiased Monte Carlo Estimation of the Reciprocal of an
#   Integral", Nuclear Science and Engineering 156 (2007).

# %%
print(f"done in {time.perf_counter() - T_START:.1f} s")
