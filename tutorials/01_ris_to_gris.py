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
# # Tutorial 1 — From RIS to GRIS: resampling, shift maps and reservoir chains
#
# Resampled importance sampling (RIS) lets a renderer draw samples roughly
# proportional to a function $\hat p$ it can *evaluate* but not *sample*.
# Generalized RIS (GRIS) goes further: it resamples candidates that were drawn
# for *another* integral (another pixel, another frame) after moving them with a
# **shift map**. Chaining GRIS — every pixel reusing its neighbours' reservoirs,
# again and again — is ReSTIR.
#
# This tutorial walks through that ladder on the toy problems of
# `grisx.theory.toys`. Every toy has an exact answer, so each claim ("this
# estimator is unbiased", "dropping the Jacobian biases it") is checked by a
# number: the z-score
#
# $$ z = \frac{\langle F\rangle - F}{\operatorname{stderr}}, $$
#
# which is $\approx\mathcal N(0,1)$ for an unbiased estimator and grows like
# $\sqrt{N}$ with the trial count $N$ for a biased one.
#
# All estimators here run the **same Warp functions** that grisx's renderers
# call (`grisx.theory.gris`, `.reservoir`, `.mis`, `.shift`): what you verify
# on a toy is what renders a scene.
#
# Run it as a script (`python tutorials/01_ris_to_gris.py [--quick]`) or open
# it as a notebook (`jupytext --to notebook tutorials/01_ris_to_gris.py`, or
# open the `.py` directly in Jupyter with jupytext installed).
# `GRISX_QUICK=1` (or `--quick`) uses few trials so that everything runs in
# seconds; figures go to `$GRISX_TUTORIAL_OUT` (default `tutorials/out/`).

# %% [markdown]
# ## What you will learn
#
# 1. How RIS turns $M$ candidates into one sample $y$ and an **unbiased
#    contribution weight** (UCW) $W_y$, and what $f(y)\,W_y$ estimates.
# 2. Where RIS puts its samples (a histogram that tends to $\hat p/\!\int\hat p$),
#    and how its error falls with $M$ for a good and a mediocre $\hat p$.
# 3. Why $\hat p$ must be positive wherever $f$ is — and how a z-test catches
#    the bias when it is not.
# 4. GRIS: the resampling weight $m\,\hat p(T(x))\,W_x\,|\partial T/\partial x|$,
#    the role of the Jacobian, and which MIS weights stay unbiased when a shift
#    is only a *partial* bijection.
# 5. Reservoir chains (repeated spatial passes): lower variance, still unbiased.
# 6. The reconnection shift of ReSTIR GI in flatland, its Jacobian (seed 004,
#    Eq. 11), and why naive $1/M$ weights are biased behind an occluder.

# %% Setup
import time

import matplotlib
import numpy as np


# quick mode, device, figure folder and the off-screen backend (before pyplot is imported)
from grisx.tutorial import tutorial_setup

setup = tutorial_setup(globals().get("__file__"))
INTERACTIVE = setup.interactive
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.ticker  # noqa: E402
import warp as wp  # noqa: E402

from grisx.testing import BIASED_K, DEFAULT_K, z_test  # noqa: E402
from grisx.theory.toys import get_problem, run_toy  # noqa: E402

QUICK = setup.quick
TRIALS = 20_000 if QUICK else 500_000
SEED = 0
# Every kernel and array of this tutorial lives on one device (set GRISX_DEVICE=cuda for a GPU).
DEVICE = setup.device

OUT = setup.out
T_START = setup.start
print(f"mode: {'QUICK' if QUICK else 'default'}  trials per run: {TRIALS:,}  seed: {SEED}  figures -> {OUT}")

save = setup.save


def z_axis(ax, z_values, threshold: float) -> None:
    """A symmetric-log z axis with plain tick labels and the pass band shaded."""
    ax.set_yscale("symlog", linthresh=5, linscale=1.2)
    top = max(10.0, float(np.max(np.abs(np.concatenate([np.atleast_1d(z) for z in z_values])))) * 1.3)
    ticks = [t for t in (4, 10, 30, 100, 300, 1000, 3000) if t <= top]
    ax.set_yticks([-t for t in ticks[::-1]] + [0] + ticks, [str(-t) for t in ticks[::-1]] + ["0"] + [str(t) for t in ticks])
    ax.yaxis.set_minor_locator(matplotlib.ticker.NullLocator())
    ax.set_ylim(-top, top)
    ax.axhspan(-threshold, threshold, color="tab:green", alpha=0.12, label=f"|z| ≤ {threshold:.2f} (4σ, Šidák-corrected)")
    ax.axhline(0.0, color="k", lw=0.6)
    ax.grid(True, axis="y", alpha=0.3)


def verdict(est, biased: bool = False) -> str:
    """z-test an Estimate (Šidák-corrected over pixels) and say what it means."""
    check = z_test(est.estimate, est.stderr, est.exact, k=DEFAULT_K)
    if biased:
        return f"max|z| = {check.max_abs_z:7.1f}  -> " + ("bias caught" if check.max_abs_z > BIASED_K else "bias NOT caught at this N")
    return f"max|z| = {check.max_abs_z:7.2f}  -> " + ("consistent with unbiased" if check.passed else f"FAILS the {check.threshold:.2f}-sigma test")


# %% [markdown]
# ## Step 1 — Monte Carlo against RIS on `ris-1d`
#
# The toy integrates a floor with two Gaussian bumps over $[0,1]$,
#
# $$ f(x) = 0.2 + e^{-((x-0.3)/0.06)^2} + 0.5\,e^{-((x-0.72)/0.1)^2}, \qquad F=\int_0^1 f(x)\,dx \text{ (exact, via erf)}. $$
#
# Candidates are uniform, $p(x)=1$.
#
# **Monte Carlo** (`mc`) averages $M$ samples: $\langle F\rangle_{MC} = \frac1M\sum_i f(x_i)/p(x_i)$.
#
# **RIS** (`ris`) draws $M$ candidates $x_1,\dots,x_M$, gives each the
# *resampling weight* (seed 000, Eq. 6)
#
# $$ w_l = m_l(x_l)\,\frac{\hat p(x_l)}{p_l(x_l)}, \qquad m_l = \frac1M, $$
#
# keeps **one** candidate $y$ with probability $w_l/\sum_k w_k$ (a weighted
# reservoir does this in one streaming pass), and assigns it the
# *unbiased contribution weight* (seed 000, Eq. 8)
#
# $$ W_y = \frac{1}{\hat p(y)}\sum_{l=1}^{M} w_l . $$
#
# The estimate is (seed 000, Eq. 7)
#
# $$ \langle F\rangle_{\text{RIS}} = f(y)\,W_y . $$
#
# $W_y$ plays the role of $1/p(y)$ for a density we never have to compute:
# the density of $y$ after resampling is intractable, but $E[f(y)W_y] = F$
# whenever $\hat p>0$ wherever $f\neq 0$. For large $M$, $y$ is distributed
# like $\hat p/\!\int\hat p$.
#
# A useful identity: with $\hat p = f$ the estimate does not depend on *which*
# candidate was kept,
#
# $$ f(y)\,W_y = f(y)\,\frac{1}{f(y)}\sum_l \frac{f(x_l)}{M\,p(x_l)} = \frac1M\sum_l \frac{f(x_l)}{p(x_l)} , $$
#
# i.e. RIS with the perfect target *is* Monte Carlo with $M$ samples. What RIS
# adds is the *sample* $y$, distributed nearly like $f$, which later steps can
# reuse — and, in a renderer, the option of a cheap $\hat p$ (no visibility
# ray) with one expensive evaluation of $f$ per trial.
#
# `target` chooses $\hat p$: `integrand` ($\hat p=f$), `approx` (one wide
# bump, $0.3+e^{-((x-0.45)/0.25)^2}$ — positive everywhere but a poor fit) and
# `narrow` (step 2).
#
# ### Under the hood: one RIS trial written with the core functions
#
# The toy's kernel is a loop over candidates around three core calls:
# `ris_weight` (Eq. 6), `reservoir_update` (streaming selection) and
# `reservoir_finalize` (Eq. 8). Here is the same loop, recording every
# candidate of one trial so we can look at it. Random numbers are a pure
# function of (seed, trial, counter), so this reproduces trial 0 of
# `run_toy(..., trials=1)` exactly.

# %%
from grisx.theory.gris import ris_weight  # noqa: E402
from grisx.theory.random import random_key, random_uniform  # noqa: E402
from grisx.theory.reservoir import reservoir_empty, reservoir_finalize, reservoir_update  # noqa: E402
from grisx.theory.toys.ris_1d import TARGETS, ris1d_integrand, ris1d_target  # noqa: E402


@wp.kernel
def ris_one_trial(
    seed: int,
    trial: int,
    target_kind: int,
    xs: wp.array(dtype=float),
    ws: wp.array(dtype=float),
    kept_flags: wp.array(dtype=int),
    result: wp.array(dtype=float),
):
    key = random_key(seed, trial)
    m = xs.shape[0]
    r = reservoir_empty()
    y = float(0.0)
    for i in range(m):
        x = random_uniform(key, 2 * i)  # uniform candidate on [0, 1): p(x) = 1
        target = ris1d_target(target_kind, x)
        w = ris_weight(1.0 / float(m), target, 1.0)  # seed 000, Eq. 6
        r = reservoir_update(r, w, target, 1.0, random_uniform(key, 2 * i + 1))
        if r.selected:
            y = x
        xs[i] = x
        ws[i] = w
        kept_flags[i] = int(r.selected)
    r = reservoir_finalize(r)  # W_y, seed 000 Eq. 8
    result[0] = y
    result[1] = r.ucw
    result[2] = ris1d_integrand(y) * r.ucw  # seed 000, Eq. 7


M_DEMO = 4
xs_d, ws_d = wp.zeros(M_DEMO, dtype=float), wp.zeros(M_DEMO, dtype=float)
kept_d, res_d = wp.zeros(M_DEMO, dtype=int), wp.zeros(3, dtype=float)
wp.launch(ris_one_trial, dim=1, inputs=[SEED, 0, TARGETS.index("integrand"), xs_d, ws_d, kept_d, res_d])
print(f"one RIS trial, M = {M_DEMO}, p̂ = f:")
for i, (x, w, k) in enumerate(zip(xs_d.numpy(), ws_d.numpy(), kept_d.numpy())):
    print(f"  candidate {i}: x = {x:.4f}  w = p̂(x)/(M p(x)) = {w:.4f}" + ("   <- kept (so far)" if k else ""))
y_d, W_d, fw_d = res_d.numpy()
print(f"  selected y = {y_d:.4f}, W_y = Σw / p̂(y) = {W_d:.4f}, estimate f(y) W_y = {fw_d:.5f}")
one = run_toy("ris-1d", "ris", trials=1, seed=SEED, params={"candidates": M_DEMO})
print(f"  run_toy(trials=1) gives {one.estimate:.5f}  (exact F = {one.exact:.5f})")

# %% [markdown]
# ### Many trials: estimates, z-scores, and where the samples go
#
# `run_toy` runs `trials` independent trials (one Warp thread each) and
# returns an `Estimate` with `estimate`, `stderr`, `exact`, `seconds`, and —
# with `return_samples=True` — the selected $y$ of every trial.

# %%
EXACT_1D = float(get_problem("ris-1d").exact({})[0])
print(f"exact F = {EXACT_1D:.6f}")
for method, params in (("mc", {}), ("ris", {"target": "integrand"}), ("ris", {"target": "approx"})):
    e = run_toy("ris-1d", method, trials=TRIALS, seed=SEED, params={"candidates": 8, **params})
    label = f"{method} {params.get('target', '')}".strip()
    print(f"  {label:14s} M=8: {e.estimate:.6f} ± {e.stderr:.6f}  z = {e.z:+.2f}  RMSE/trial = {e.rmse:.4f}  {verdict(e)}")


# %%
# Evaluate f and p̂ on a grid with the core's own Warp functions (for plotting).
@wp.kernel
def eval_ris1d(target_kind: int, xs: wp.array(dtype=float), f: wp.array(dtype=float), target: wp.array(dtype=float)):
    i = wp.tid()
    f[i] = ris1d_integrand(xs[i])
    target[i] = ris1d_target(target_kind, xs[i])


def ris1d_curves(target: str, n: int = 2001):
    x = np.linspace(0.0, 1.0, n, dtype=np.float32)
    xs, f, t = wp.array(x), wp.zeros(n, dtype=float), wp.zeros(n, dtype=float)
    wp.launch(eval_ris1d, dim=n, inputs=[TARGETS.index(target), xs, f, t])
    return x.astype(np.float64), f.numpy().astype(np.float64), t.numpy().astype(np.float64)


HIST_M = (1, 4, 32)
fig, axes = plt.subplots(1, 2, figsize=(12, 4.4), sharey=True)
for ax, target in zip(axes, ("integrand", "approx")):
    x, f, t = ris1d_curves(target)
    for m, color in zip(HIST_M, ("tab:blue", "tab:orange", "tab:green")):
        s = run_toy("ris-1d", "ris", trials=TRIALS, seed=SEED, params={"candidates": m, "target": target}, return_samples=True).samples
        ax.hist(s, bins=100, range=(0, 1), density=True, histtype="step", lw=1.5, color=color, label=f"selected y, M = {m}")
    ax.plot(x, t / np.trapezoid(t, x), "k--", lw=1.3, label=r"$\hat p/\int\hat p$ (limit $M\to\infty$)")
    if target != "integrand":
        ax.plot(x, f / np.trapezoid(f, x), color="0.55", lw=1.0, label=r"$f/\int f$ (ideal density)")
    ax.set(title=f"ris-1d, target = {target}", xlabel="x", xlim=(0, 1))
    ax.legend(fontsize=8, loc="upper right")
axes[0].set_ylabel("density of the selected sample y")
fig.suptitle("Where RIS puts its samples: M = 1 is the uniform source pdf; larger M approaches the target", fontsize=11)
save(fig, "01_ris_histograms.png")

# %% [markdown]
# With $M=1$ RIS is plain importance sampling from $p$ (uniform). As $M$
# grows the histogram approaches $\hat p/\!\int\hat p$ — *not* $f/\!\int f$
# when $\hat p\neq f$ (right panel): the leftover mismatch is what $W_y$ and
# $f(y)$ correct for, and it is why a poor target leaves variance behind.
#
# ### Error against the number of candidates
#
# The error of one trial (`Estimate.rmse`: $\sqrt{N\,\text{stderr}^2+\text{bias}^2}$)
# for $M = 1\dots 64$. Note the fair comparison: `mc` with $M$ *samples*
# evaluates $f$ $M$ times, RIS evaluates $\hat p$ $M$ times but $f$ only once.
# RIS pays off when $\hat p$ is much cheaper than $f$ (in a renderer: no
# visibility ray), which a toy where $\hat p = f$ cannot show.
#
# For a fixed $\hat p$, RIS's one-sample variance tends, as $M\to\infty$, to
# that of importance sampling from $q=\hat p/\!\int\hat p$:
# $\operatorname{Var} = \int f^2/q - F^2$. That limit is zero for $\hat p = f$
# and is drawn as a horizontal line for `approx`.

# %%
M_SWEEP = (1, 2, 4, 8, 16, 32, 64)
curves = {"mc (M samples averaged)": ("mc", {}), "ris, target = integrand": ("ris", {"target": "integrand"}), "ris, target = approx": ("ris", {"target": "approx"})}
rmse = {label: [] for label in curves}
for label, (method, params) in curves.items():
    for m in M_SWEEP:
        rmse[label].append(run_toy("ris-1d", method, trials=TRIALS, seed=SEED, params={"candidates": m, **params}).rmse)
print("RMSE of one trial (relative to F):")
print("  M      " + "".join(f"{m:>9d}" for m in M_SWEEP))
for label, values in rmse.items():
    print(f"  {label[:24]:24s}" + "".join(f"{v / EXACT_1D:9.4f}" for v in values))

fig, ax = plt.subplots(figsize=(6.4, 4.4))
for (label, values), marker in zip(rmse.items(), ("o", "s", "^")):
    ax.loglog(M_SWEEP, np.array(values) / EXACT_1D, marker=marker, label=label)
ref = rmse["mc (M samples averaged)"][0] / EXACT_1D * np.array(M_SWEEP, dtype=float) ** -0.5
ax.loglog(M_SWEEP, ref, "k:", lw=1, label=r"$\propto M^{-1/2}$")
x, f, t = ris1d_curves("approx")
q = t / np.trapezoid(t, x)
limit = np.sqrt(np.trapezoid(f * f / q, x) - EXACT_1D**2) / EXACT_1D
print(f"  M -> inf limit of ris target=approx (importance sampling from p̂/∫p̂): {limit:.4f}")
ax.axhline(limit, color="tab:green", ls="--", lw=1, label=r"approx: limit $M\to\infty$, $\sqrt{\int f^2/q - F^2}\,/F$")
ax.set(xlabel="candidates M", ylabel="relative RMSE of one trial", title=f"ris-1d: error against M ({TRIALS:,} trials per point)")
ax.set_xticks(M_SWEEP, [str(m) for m in M_SWEEP])
ax.grid(True, which="both", alpha=0.3)
ax.legend(fontsize=8)
save(fig, "01_ris_rmse_vs_M.png")

# %% [markdown]
# `mc` and `ris, target = integrand` lie on top of each other — the identity
# above. `approx` does not improve with $M$ at all: it already sits at its
# $M\to\infty$ limit, because importance sampling from this wide bump is no
# better than uniform sampling for an $f$ with two narrow bumps. A target has
# to resemble $f$ to help.
#
# ## Step 2 — When $\hat p$ misses part of the support
#
# RIS can only select candidates with $w_l > 0$, i.e. where $\hat p > 0$. Its
# expectation is therefore
#
# $$ E\big[f(y)W_y\big] = \int_{\{\hat p>0\}} f(x)\,dx , $$
#
# which equals $F$ only if $\hat p > 0$ wherever $f \neq 0$. The `narrow`
# target is $f$ on $[0, 0.5]$ and **zero** on $(0.5, 1]$: RIS never selects
# there, and silently loses $\int_{0.5}^{1} f$. No amount of trials fixes it —
# the z-score grows like $\sqrt N$.

# %%
narrow = run_toy("ris-1d", "ris", trials=TRIALS, seed=SEED, params={"target": "narrow"}, return_samples=True)
x, f, _ = ris1d_curves("integrand")
missing = float(np.trapezoid(np.where(x > 0.5, f, 0.0), x))
check = z_test(narrow.estimate, narrow.stderr, narrow.exact)
print(f"ris target=narrow: {narrow.estimate:.5f} ± {narrow.stderr:.5f}   exact {narrow.exact:.5f}   z = {narrow.z:+.1f}   ({check})")
print(f"  predicted expectation F − ∫_0.5^1 f = {narrow.exact - missing:.5f}  (missing mass {missing:.5f})")
print(f"  largest selected sample: {narrow.samples.max():.4f}  (never beyond 0.5)")
for n in (TRIALS // 16, TRIALS // 4, TRIALS):
    e = run_toy("ris-1d", "ris", trials=n, seed=SEED, params={"target": "narrow"})
    print(f"  N = {n:>9,}: z = {e.z:+8.1f}")

fig, ax = plt.subplots(figsize=(6.4, 4.0))
ax.hist(narrow.samples, bins=100, range=(0, 1), density=True, histtype="stepfilled", alpha=0.45, color="tab:red", label="selected y, target = narrow")
ax.plot(x, f / EXACT_1D, "k--", lw=1.2, label=r"$f/\int f$")
ax.axvspan(0.5, 1.0, color="0.85", zorder=0, label=r"$\hat p = 0$ here: never selected")
ax.set(xlabel="x", ylabel="density", xlim=(0, 1), title=f"Support violation: z = {narrow.z:+.0f} with {TRIALS:,} trials")
ax.legend(fontsize=8)
save(fig, "01_ris_narrow_support.png")

# %% [markdown]
# ## Step 3 — GRIS with shift maps on `gris-shift`
#
# Now there are $K=5$ "pixels". Pixel $k$ integrates $f_k$ over its own domain
# $\Omega_k = \varphi_k(U_k)$, the image of a reference interval under a map
# $\varphi_k$:
#
# | pixel | map | $\varphi(u)$ | $\Omega$ |
# |---|---|---|---|
# | 0 | identity | $u$ | $[0,1]$ |
# | 1 | translation | $u+0.5$ | $[0.5,1.5]$ |
# | 2 | scaling | $2u-1$ | $[-1,1]$ |
# | 3 | non-linear | $(e^{2u}-1)/(e^2-1)$ | $[0,1]$ |
# | 4 | partial | $u$, only $u\le 0.6$ | $[0,0.6]$ |
#
# The shift from pixel $j$ to pixel $i$ is $T_{j\to i}=\varphi_i\circ\varphi_j^{-1}$
# with $|\partial T/\partial x| = \varphi_i'(u)/\varphi_j'(u)$. Every shift into
# or out of pixel 4 is a **partial bijection**: samples with $u>0.6$ have no image.
#
# Each pixel first runs RIS with $M=4$ candidates (step 1). A **spatial pass**
# then lets every pixel $i$ resample the reservoirs $(y_j, W_j)$ of all
# pixels, shifted into its own domain, with the GRIS resampling weight
# (seed 000, Eq. 9)
#
# $$ w_j = m_j\big(T_j(y_j)\big)\;\hat p_i\big(T_j(y_j)\big)\;W_{y_j}\;\left|\frac{\partial T_j}{\partial y_j}\right| . $$
#
# Eq. 6 is the special case $T=\mathrm{id}$, $W=1/p$. The reservoir's UCW is
# again $W_y = \frac{1}{\hat p_i(y)}\sum_j w_j$ (Eq. 8), and the pixel estimate
# $f_i(y)W_y$ (Eq. 7). The Jacobian is there because $W_{y_j}$ is a weight with
# respect to measure in $\Omega_j$; moving the sample changes the measure.
#
# **MIS weights.** GRIS is unbiased when, at every $y$ with $f_i(y)\ne 0$,
# the weights of the domains that *can produce* $y$ sum to one. With
# confidences $c_j$ (here $c_j = M$) and the target carried over from domain
# $j$, $\hat p_{\leftarrow j}(y) = \hat p_j(T_j^{-1}(y))\,|\partial T_j^{-1}/\partial y|$
# (seed 001, Eq. 16; zero where $T_j^{-1}$ is undefined):
#
# * `balance` — generalized balance heuristic (seed 001, Eq. 15):
#   $m_j(y) = \dfrac{c_j\,\hat p_{\leftarrow j}(y)}{\sum_k c_k\,\hat p_{\leftarrow k}(y)}$;
# * `pairwise` — each neighbour weighed only against the canonical (own) pixel
#   (Bitterli 2022; Lin et al. 2022), $O(M)$ instead of $O(M^2)$;
# * `uniform` — support-counting $m_j = c_j / Z(y)$ with
#   $Z(y) = \sum_{k:\,\hat p_{\leftarrow k}(y)>0} c_k$ (seed 004, Alg. 4);
# * `naive` — $m_j = c_j/\sum_k c_k$, counting *every* pixel.
#
# Two known-biased variants are ablations: `jacobian=false` (drop
# $|\partial T/\partial y|$) and `mis=naive`.

# %%
from grisx.theory.toys.gris_shift import GRISShiftSpec, gris_shift_integrand  # noqa: E402
from grisx.theory.toys.shifts import MAP_KINDS, phi, phi_derivative  # noqa: E402

GRIS_RUNS = {
    "passes=0 (RIS only)": ({"passes": 0}, False),
    "balance": ({"mis": "balance"}, False),
    "pairwise": ({"mis": "pairwise"}, False),
    "uniform (1/Z)": ({"mis": "uniform"}, False),
    "naive (c/Σc)": ({"mis": "naive"}, True),
    "balance, jacobian=false": ({"mis": "balance", "jacobian": False}, True),
}
gris = {}
for label, (params, biased) in GRIS_RUNS.items():
    gris[label] = e = run_toy("gris-shift", "gris", trials=TRIALS, seed=SEED, params=params)
    assert biased == get_problem("gris-shift").is_biased("gris", e.params)
K = len(gris["balance"].exact)
print(f"gris-shift, K = {K} pixels, M = 4 candidates, {TRIALS:,} trials; exact = {np.round(gris['balance'].exact, 5)}")
print(f"  {'variant':26s}" + "".join(f"   z[{k}] {MAP_KINDS[k % 5][:5]:5s}" for k in range(K)) + "   verdict")
for label, e in gris.items():
    print(f"  {label:26s}" + "".join(f"{z:+14.2f}" for z in e.z) + "   " + verdict(e, GRIS_RUNS[label][1]))


# %% [markdown]
# ### Why `naive` is biased — and where
#
# Take a point $y$ of pixel $i$ with reference coordinate $u>0.6$. Pixel 4
# (the partial map) cannot produce it: its domain ends at $u = 0.6$. The
# naive weights still give pixel 4 the share $c_4/\sum c = 1/K$ of *every*
# point, so at such $y$ the weights of the pixels that can produce it sum to
# $(K-1)/K$. The estimate of pixel $i$ then has expectation
#
# $$ E\big[\langle F_i\rangle\big] = F_i - \frac1K\int_{u>0.6} f_i , $$
#
# i.e. the bias shows in the **other** pixels, caused by the partial-bijection
# pixel. Pixel 4 itself stays unbiased: every $y\in\Omega_4$ has $u \le 0.6$
# and can be produced by all pixels. `uniform` fixes this by counting only
# the pixels whose carried-over target is positive at $y$ ($Z(y)$), `balance`
# and `pairwise` do so automatically because $\hat p_{\leftarrow 4}(y)=0$ there.
# Let us check the predicted bias against the measured one, integrating $f_i$
# with the toy's own Warp integrand.

# %%
@wp.kernel
def integrand_in_u(spec: GRISShiftSpec, k: int, us: wp.array(dtype=float), out: wp.array(dtype=float)):
    # f_k(φ_k(u)) φ_k'(u): pixel k's integrand in the reference coordinate u
    i = wp.tid()
    kind = spec.kind[k]
    out[i] = gris_shift_integrand(spec, k, phi(kind, us[i])) * phi_derivative(kind, us[i])


def integral_beyond(k: int, u0: float = 0.6, n: int = 4001) -> float:
    """∫_{u > u0} f_k, with the toy's own Warp integrand (trapezoid rule)."""
    params = gris["naive (c/Σc)"].params
    spec = get_problem("gris-shift").spec(params, wp.get_device())
    u = np.linspace(u0, 1.0, n, dtype=np.float32)
    out = wp.zeros(n, dtype=float)
    wp.launch(integrand_in_u, dim=n, inputs=[spec, k, wp.array(u), out])
    return float(np.trapezoid(out.numpy().astype(np.float64), u.astype(np.float64)))


naive = gris["naive (c/Σc)"]
predicted = np.array([-integral_beyond(k) / K for k in range(K)])
measured = np.asarray(naive.estimate) - np.asarray(naive.exact)
print("naive MIS bias per pixel: predicted −(1/K)∫_{u>0.6} f_k  vs  measured (± stderr)")
for k in range(K):
    print(f"  pixel {k} ({MAP_KINDS[k % 5]:11s}): predicted {predicted[k]:+.5f}   measured {measured[k]:+.5f} ± {naive.stderr[k]:.5f}")

# %%
colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
pixel_names = [f"{k}: {MAP_KINDS[k % 5]}" for k in range(K)]
fig, axes = plt.subplots(1, 3, figsize=(17, 4.8))
for ax, want_biased in zip(axes[:2], (False, True)):
    runs = [(n, label, e) for n, (label, e) in enumerate(gris.items()) if GRIS_RUNS[label][1] == want_biased]
    width = 0.8 / len(runs)
    for slot, (n_run, label, e) in enumerate(runs):
        xk = np.arange(K) - 0.4 + (slot + 0.5) * width
        rel = (np.asarray(e.estimate) / np.asarray(e.exact) - 1.0) * 100.0
        err = 2.0 * np.asarray(e.stderr) / np.asarray(e.exact) * 100.0
        ax.errorbar(xk, rel, yerr=err, fmt="o", ms=4, capsize=3, color=colors[n_run], label=label)
        if label.startswith("naive"):
            ax.scatter(xk, predicted / np.asarray(e.exact) * 100.0, marker="_", s=260, color="k", zorder=3, label=r"naive: predicted bias $-\frac{1}{K}\int_{u>0.6} f_k$")
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_xticks(np.arange(K), pixel_names, fontsize=8.5)
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend(fontsize=8)
    ax.set(xlabel="pixel (shift map kind)", ylabel="(estimate − exact) / exact  [%]")
axes[0].set_title("Unbiased variants: estimate vs exact (bars: ±2 stderr)", fontsize=10)
axes[1].set_title("Known-biased variants: estimate vs exact (bars: ±2 stderr)", fontsize=10)
ax = axes[2]
width = 0.8 / len(gris)
for n_run, (label, e) in enumerate(gris.items()):
    ax.bar(np.arange(K) - 0.4 + (n_run + 0.5) * width, e.z, width=width, color=colors[n_run], label=label)
z_axis(ax, [e.z for e in gris.values()], z_test(gris["balance"].estimate, gris["balance"].stderr, gris["balance"].exact).threshold)
ax.set_xticks(np.arange(K), pixel_names, fontsize=8.5)
ax.set(xlabel="pixel (shift map kind)", ylabel="z = (estimate − exact) / stderr   (symlog)")
ax.set_title(f"z-scores of all variants, {TRIALS:,} trials", fontsize=10)
ax.legend(fontsize=7.5, ncol=2, loc="upper center", bbox_to_anchor=(0.5, -0.17))
fig.suptitle("gris-shift: one spatial GRIS pass (K = 5 pixels, M = 4) — MIS choices and the Jacobian ablation", fontsize=11)
fig.tight_layout()
save(fig, "01_gris_shift_mis.png")

# %% [markdown]
# The unbiased variants (`passes=0`, `balance`, `pairwise`, `uniform`) sit
# within a few standard errors of the exact values in every pixel. Dropping
# the Jacobian is wrong wherever $|\partial T/\partial y| \ne 1$ — every pixel
# here receives samples from the scaling and the non-linear pixel — and the
# `naive` weights lose the predicted share in pixels 0–3 while pixel 4 is fine.
#
# ## Step 4 — Reservoir chains: repeated spatial passes
#
# The output of a GRIS pass is again a set of reservoirs $(y_i, W_{y_i})$ with
# valid UCWs, so the pass can be applied to its own output. That chain is
# ReSTIR. Whatever the number of passes, the estimator stays **unbiased**: the
# confidences (here $c=M$, summed and capped at `cap`=20 after each pass)
# do not depend on the samples, so the MIS weights still sum to one at every
# point. The pixels become *correlated* within a trial, but trials are
# independent, so the per-pixel z-test over trials remains valid.
#
# Whether a pass *reduces variance* is a different question. Watch the
# standard errors below: in one trial only $K\cdot M = 20$ candidates are
# ever drawn. The first pass lets every pixel draw on all of them; later passes
# re-resample the *same* information, adding selection noise but no new
# candidates. (In a renderer new candidates arrive every frame through temporal
# reuse, and neighbourhoods differ per pixel — that is where long chains pay
# off.) Remember also that with $\hat p = f$ the per-pixel RIS baseline is
# already Monte Carlo with $M$ samples (step 1).

# %%
PASSES = (0, 1, 2, 3)
chain = {p: run_toy("gris-shift", "gris", trials=TRIALS, seed=SEED, params={"passes": p, "mis": "balance"}) for p in PASSES}
print(f"gris-shift, mis=balance, {TRIALS:,} trials: standard error per pixel (and z) against the number of passes")
for p, e in chain.items():
    cells = "".join(f"  {se:.2e} ({z:+5.2f})" for se, z in zip(e.stderr, e.z))
    print(f"  passes={p}: {cells}   {e.seconds:.2f} s   {verdict(e)}")

fig, axes = plt.subplots(1, 2, figsize=(12, 4.3))
for k in range(K):
    se = np.array([chain[p].stderr[k] for p in PASSES]) * np.sqrt(TRIALS)
    axes[0].plot(PASSES, se / chain[0].exact[k], marker="o", label=f"pixel {k}: {MAP_KINDS[k % 5]}")
    axes[1].plot(PASSES, [chain[p].z[k] for p in PASSES], marker="o", label=f"pixel {k}")
axes[0].set(xlabel="spatial passes", ylabel="relative std. dev. of one trial  (stderr·√N / F)", title="Spread of one trial per pixel (mis = balance)", yscale="log")
axes[0].set_xticks(PASSES)
axes[0].grid(True, which="both", alpha=0.3)
axes[0].legend(fontsize=8)
thr = z_test(chain[0].estimate, chain[0].stderr, chain[0].exact).threshold
axes[1].axhspan(-thr, thr, color="tab:green", alpha=0.12, label=f"|z| ≤ {thr:.2f}")
axes[1].set(xlabel="spatial passes", ylabel="z = (estimate − exact) / stderr", title="The chain stays unbiased at every length", ylim=(-thr - 1, thr + 1))
axes[1].set_xticks(PASSES)
axes[1].grid(True, alpha=0.3)
axes[1].legend(fontsize=8, ncol=2)
save(fig, "01_reservoir_chain.png")

# %% [markdown]
# All z-scores stay inside the band: the chain is unbiased at every length.
# The spread tells a more nuanced story than "more reuse is better": one pass
# helps the pixels whose neighbours' samples carry over well (translation,
# scaling), but it *hurts* the partial pixel 4 — many of its neighbours'
# samples lie where its shift is undefined ($u>0.6$), so they replace part of
# its own well-placed candidates — and further passes, with no new candidates,
# only add resampling noise. MIS weights built from targets $\hat p$ rather
# than from the (intractable) densities of the reservoirs guarantee
# unbiasedness, not lower variance.

# %% [markdown]
# ## Step 5 — Reconnection in flatland (`reconnection-flatland`)
#
# ReSTIR GI (seed 004) resamples *paths*: pixel $q$'s sample is a direction
# from its visible point $x_1^q$ that hits a sample point $x_2^q$. Pixel $r$
# reuses it by **reconnecting** its own visible point $x_1^r$ to the same
# $x_2^q$. Directions are measured in solid angle at each visible point, so
# the shift has the Jacobian (seed 004, Eq. 11)
#
# $$ |J_{q\to r}| = \frac{|\cos\phi_2^r|}{|\cos\phi_2^q|}\cdot\frac{\lVert x_1^q - x_2^q\rVert^2}{\lVert x_1^r - x_2^q\rVert^2}, $$
#
# where $\phi_2^q,\phi_2^r$ are the angles between $x_1^q - x_2^q$, $x_1^r - x_2^q$
# and the normal at $x_2^q$. In flatland (2D), solid angle is plane angle,
# $d\theta = \cos\phi\,ds/r$, so the squared distance ratio becomes a plain
# ratio (exponent $n-1$ with $n=2$). In GRIS this is the
# $|\partial T/\partial y|$ of Eq. 9.
#
# The scene: five visible points on the floor look up at a tilted emitter
# whose radiance varies along it; a small occluder hangs in between. Pixel
# $k$ integrates $\int \frac{\rho_k}{2}\cos\theta\,L(s(\theta))\,V\,d\theta$.
# Behind the occluder, some pixels **cannot see** a sample point that others
# can: a partial shift again. `naive` $1/M$ weights count those pixels anyway
# (the biased ReSTIR of seed 004, Sec. 4.3); `uniform` ($1/Z$, seed 004
# Alg. 4 lines 16–19 — the "visibility ray" check) counts only pixels whose
# target is positive at the sample.

# %%
from grisx.theory.toys.reconnection_flatland import flatland_scene  # noqa: E402

FLAT_RUNS = {
    "passes=0 (RIS only)": ({"passes": 0}, False),
    "uniform (1/Z)": ({"mis": "uniform"}, False),
    "balance": ({"mis": "balance"}, False),
    "naive (1/M)": ({"mis": "naive"}, True),
    "uniform, jacobian=false": ({"mis": "uniform", "jacobian": False}, True),
    "naive, no occluder": ({"mis": "naive", "occluder": False}, False),
}
flat = {}
for label, (params, biased) in FLAT_RUNS.items():
    flat[label] = e = run_toy("reconnection-flatland", "gris", trials=TRIALS, seed=SEED, params=params)
    assert biased == get_problem("reconnection-flatland").is_biased("gris", e.params)
KF = len(flat["uniform (1/Z)"].exact)
print(f"reconnection-flatland, {KF} pixels, {TRIALS:,} trials")
print(f"  exact (occluder)   : {np.round(flat['uniform (1/Z)'].exact, 5)}")
print(f"  exact (no occluder): {np.round(flat['naive, no occluder'].exact, 5)}")
for label, e in flat.items():
    print(f"  {label:25s}" + "".join(f"{z:+9.2f}" for z in e.z) + "   " + verdict(e, FLAT_RUNS[label][1]))

# %%
scene = flatland_scene(KF)
fig, axes = plt.subplots(1, 2, figsize=(13, 4.6), gridspec_kw={"width_ratios": [1, 1.3]})
ax = axes[0]
(a, b), (oa, ob) = scene["emitter"], scene["occluder"]
ax.plot([a[0], b[0]], [a[1], b[1]], color="gold", lw=4, label="emitter  L(s) = 1 + 0.8 sin 3πs")
ax.plot([oa[0], ob[0]], [oa[1], ob[1]], color="k", lw=4, label="occluder")
vis = scene["visible"]
ax.plot([-1.3, 1.1], [0, 0], color="0.6", lw=1)
ax.scatter(vis[:, 0], vis[:, 1], color="tab:blue", zorder=3, label="visible points $x_1^k$")
for k, p in enumerate(vis):
    ax.annotate(str(k), p, textcoords="offset points", xytext=(0, -13), ha="center", fontsize=9)
# one reconnection: pixel 1's sample point x2 (s = 0.1 on the emitter), reused at pixel 3
x2 = a + 0.1 * (b - a)
ax.plot([vis[1][0], x2[0]], [vis[1][1], x2[1]], "tab:blue", lw=1.3, label=r"sample of pixel q=1: $x_1^q \to x_2^q$")
ax.plot([vis[3][0], x2[0]], [vis[3][1], x2[1]], "tab:red", lw=1.3, ls="--", label=r"reconnection at pixel r=3: $x_1^r \to x_2^q$")
ax.scatter([x2[0]], [x2[1]], color="tab:red", zorder=3, marker="*", s=110)
# a reconnection the occluder blocks: pixel 2 cannot see this sample point (V = 0)
x2b = a + 0.55 * (b - a)
ax.plot([vis[2][0], x2b[0]], [vis[2][1], x2b[1]], color="0.45", lw=1.1, ls=":", label="blocked reconnection (pixel 2): V = 0")
ax.scatter([x2b[0]], [x2b[1]], color="0.45", zorder=3, marker="*", s=80)
ax.set(aspect="equal", xlim=(-1.35, 1.15), ylim=(-0.2, 1.15), title="flatland scene (pixels 0–4)", xlabel="x", ylabel="y")
ax.legend(fontsize=7.5, loc="upper center", bbox_to_anchor=(0.5, -0.22), ncol=2, framealpha=0.9)

ax = axes[1]
width = 0.8 / len(flat)
for n_run, (label, e) in enumerate(flat.items()):
    xk = np.arange(KF) - 0.4 + (n_run + 0.5) * width
    ax.bar(xk, e.z, width=width, color=colors[n_run], label=label + (" (biased)" if FLAT_RUNS[label][1] else ""))
z_axis(ax, [e.z for e in flat.values()], z_test(flat["uniform (1/Z)"].estimate, flat["uniform (1/Z)"].stderr, flat["uniform (1/Z)"].exact).threshold)
ax.set_xticks(np.arange(KF), [f"pixel {k}" for k in range(KF)])
ax.set(ylabel="z = (estimate − exact) / stderr   (symlog)", title=f"reconnection-flatland, one pass: z-scores, {TRIALS:,} trials")
ax.legend(fontsize=7.5, ncol=2, loc="upper center", bbox_to_anchor=(0.5, -0.08))
save(fig, "01_reconnection_flatland.png")

# %% [markdown]
# Without the Jacobian, samples reused from a pixel that sees the sample point
# at a different distance and angle are weighted as if their densities
# matched: a systematic error whose sign depends on the pixel (seed 004,
# Fig. 7). With `naive` $1/M$ weights the occluded pixels are counted for
# sample points they cannot see, and the estimate is too dark; without the
# occluder every pixel sees the whole emitter, the supports agree, and
# `naive` coincides with `uniform` — unbiased.
#
# **Where a weight is applied matters too.** Here $m_j(y_j)$ multiplies each
# candidate's weight before one is selected, so the kept sample's
# $f(y)\,W = (f/\hat p)(y)\sum_i w_i$: with $\hat p \propto f$ the estimate does
# not depend on which candidate won. Seed 004's Alg. 4 (after Bitterli et al.
# 2020, Sec. 4.3) streams $c_i\,\hat p\,W_i\,|J|$ and divides only the *kept*
# sample by $Z(y)$: unbiased as well (the expectation over the selection gives
# back $\sum_i m_i$), but a sample few domains support is kept rarely and then
# carries all of $\sum_i w_i / Z$ with a small $Z$. In the renderer that is
# `restir-gi`'s `mis=support`. Its default `mis=pairwise` weighs each
# candidate first; with it (and the renderer's other defaults: BSDF-sampled
# directions, smaller confidence caps) the per-frame relMSE of a closed room
# under a moving camera fell from 3.0 to 0.2, where pt at 1 spp has 0.53
# (`benchmarks/README.md`, "ReSTIR GI's MIS weights and caps").
#
# ## Summary
#
# | estimator | resampling weight | unbiased when |
# |---|---|---|
# | RIS (seed 000, Eq. 6–8) | $w = m\,\hat p(x)/p(x)$ | $\hat p>0$ wherever $f\ne0$ |
# | GRIS (seed 000, Eq. 9) | $w = m\,\hat p(T(x))\,W_x\,\lvert\partial T/\partial x\rvert$ | MIS weights of the domains that can produce $y$ sum to 1; Jacobian included |
# | ReSTIR chain | GRIS applied to its own output | as GRIS, with deterministic confidences |
#
# ## References
#
# * J. Talbot, D. Cline, P. Egbert. *Importance Resampling for Global
#   Illumination.* Eurographics Symposium on Rendering, 2005.
# * B. Bitterli, C. Wyman, M. Pharr, P. Shirley, A. Lefohn, W. Jarosz.
#   *Spatiotemporal Reservoir Resampling for Real-Time Ray Tracing with
#   Dynamic Direct Lighting.* ACM TOG 39(4), 2020.
# * D. Lin, M. Kettunen, B. Bitterli, J. Pantaleoni, C. Yuksel, C. Wyman.
#   *Generalized Resampled Importance Sampling: Foundations of ReSTIR.*
#   ACM TOG 41(4), 2022.
# * B. Bitterli. *Correlations and Reuse for Fast and Accurate Physically
#   Based Light Transport.* PhD thesis, Dartmouth College, 2022 (pairwise MIS).
# * **seed 000** — Y.-C. Wang, M. Kettunen, D. Lin, C. Wyman, L. Wu, S. Zhao.
#   *Gradient-domain ReSTIR Path Tracing.* (Eq. 6–9 quoted above.)
# * **seed 001** — M. Kettunen, D. Lin, R. Ramamoorthi, T. Bashford-Rogers,
#   C. Wyman. *Conditional Resampled Importance Sampling and ReSTIR.*
#   (Eq. 15–16: generalized balance heuristic.)
# * **seed 004** — Y. Ouyang, S. Liu, M. Kettunen, M. Pharr, J. Pantaleoni.
#   *ReSTIR GI: Path Resampling for Real-Time Path Tracing.* CGF 40(8), 2021.
#   (Eq. 11: reconnection Jacobian; Alg. 4: $1/Z$ weights.)
#
# The plain-text copies of the seed papers are in `shared/seeds/`.

# %%
print(f"tutorial finished in {time.perf_counter() - T_START:.1f} s ({'QUICK' if QUICK else 'default'} mode)")
