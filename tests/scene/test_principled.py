"""Mitsuba 3's ``principled`` and ``principledthin`` BSDFs (grisx.scene.principled): the ladder of test_bsdf.py.

* eval and pdf against Mitsuba 3.9.1's own ``mi.load_dict({"type": "principled", ...})`` at thousands of
  (wo, wi) pairs: uniform on the sphere and drawn by the lobes (skipped, with the reason, where Mitsuba is not
  installed — CI has none; the rest runs without it);
* properties: reciprocity of the reflection lobes (and of the thin sheet's transmission), weight = eval/pdf;
* statistics: χ² of ``bsdf_sample`` against ``bsdf_pdf`` (Šidák over the family), with siblings showing that the
  same check catches a thin sheet's transmission sampled without Burley's roughness scale and a pdf that forgets
  the clearcoat's lobe probability; Monte Carlo albedo from sampling and from eval agree.
"""

from __future__ import annotations

import dataclasses
import glob
import math
import os

import numpy as np
import pytest
from test_bsdf import N_CHI2, Turned, _cell_masses, _chi2, check_albedo, check_chi2, check_weight, direction, evaluate, sample, sphere_dirs

from grisx.errors import InvalidParameterError
from grisx.scene.material import (
    MATERIAL_ANISOTROPIC,
    MATERIAL_PRINCIPLED,
    MATERIAL_PRINCIPLED_THIN,
    Principled,
    PrincipledThin,
    TextureRef,
    _pack_one,
    material_kinds,
)

FULL = dict(base_color=(0.2, 0.8, 0.1), roughness=0.3, metallic=0.3, spec_trans=0.4, spec_tint=0.4, sheen=0.3, sheen_tint=0.5,
            clearcoat=0.6, clearcoat_gloss=0.3, flatness=0.2, specular=0.6)

#: (name, record, the same as a Mitsuba 3 dictionary's parameters)
CASES = [
    ("defaults", Principled(), {}),
    ("diffuse-retro", Principled(base_color=(0.9, 0.4, 0.1), roughness=0.8), {}),
    ("metal", Principled(base_color=(0.9, 0.6, 0.2), metallic=1.0, roughness=0.25), {}),
    ("full", Principled(**FULL), {}),
    ("full-aniso", Principled(**FULL, anisotropic=0.7), {}),
    ("glass", Principled(base_color=(0.8, 0.9, 1.0), spec_trans=1.0, roughness=0.2, eta=1.33), {}),
    ("glass-tinted-sheen", Principled(base_color=(0.3, 0.6, 0.8), spec_trans=0.7, roughness=0.4, sheen=0.9, clearcoat=0.3,
                                      specular=0.4), {}),
    ("flat-eta", Principled(base_color=(0.5, 0.5, 0.5), flatness=1.0, roughness=0.6, eta=1.7, spec_tint=1.0), {}),
    ("two-sided", Principled(base_color=(0.3, 0.5, 0.7), metallic=0.5, clearcoat=0.5, sheen=0.4, roughness=0.35, two_sided=True), {}),
    ("thin-defaults", PrincipledThin(), {}),
    ("thin-full", PrincipledThin(base_color=(0.7, 0.1, 0.1), roughness=0.4, spec_trans=0.5, diff_trans=0.8, sheen=0.5,
                                 sheen_tint=0.5, spec_tint=0.6, flatness=0.3, eta=1.33), {}),
    ("thin-aniso", PrincipledThin(base_color=(0.2, 0.5, 0.9), roughness=0.5, anisotropic=0.6, spec_trans=0.8, diff_trans=1.4,
                                  eta=1.5), {}),
]


def mitsuba_dict(desc) -> dict:
    """Mitsuba 3's dictionary of a principled record."""
    d: dict = {"type": "principledthin" if isinstance(desc, PrincipledThin) else "principled"}
    for f in dataclasses.fields(desc):
        v = getattr(desc, f.name)
        if f.name.startswith("has_") or f.name in ("two_sided", "bump_amplitude", "bump_frequency") or v is None:
            continue
        if f.name == "base_color":
            d[f.name] = {"type": "rgb", "value": list(np.broadcast_to(np.asarray(v, float), (3,)))}
        elif v != f.default or f.name in ("roughness", "eta"):
            d[f.name] = float(v)
    return {"type": "twosided", "bsdf": d} if getattr(desc, "two_sided", False) and isinstance(desc, Principled) else d


def _mitsuba():
    """Mitsuba 3 (llvm_ad_rgb) or a skip naming why not."""
    if "DRJIT_LIBLLVM_PATH" not in os.environ:
        found = sorted(glob.glob("/usr/lib/x86_64-linux-gnu/libLLVM-1[7-9]*.so*"))
        if found:
            os.environ["DRJIT_LIBLLVM_PATH"] = found[-1]
    try:
        import mitsuba as mi
    except ImportError:
        pytest.skip("Mitsuba 3 is not installed (pip install mitsuba; needs libLLVM >= 17): the eval/pdf comparison "
                    "with its principled BSDFs cannot run (CI has no Mitsuba)")
    try:
        mi.set_variant("llvm_ad_rgb")
    except Exception as exc:  # noqa: BLE001 (a Dr.Jit backend that cannot start: say so)
        pytest.skip(f"Mitsuba 3's llvm_ad_rgb variant does not start here: {exc}")
    return mi


def mitsuba_eval_pdf(mi, desc, wo: np.ndarray, wi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mitsuba's bsdf.eval (RGB, cosine included) and bsdf.pdf with si.wi = wo, in the local frame."""
    import drjit as dr

    bsdf = mi.load_dict(mitsuba_dict(desc))
    si = dr.zeros(mi.SurfaceInteraction3f, len(wo))
    si.wi = mi.Vector3f(*(wo[:, i].astype(np.float32) for i in range(3)))
    si.sh_frame = mi.Frame3f(mi.Vector3f(0.0, 0.0, 1.0))
    w = mi.Vector3f(*(wi[:, i].astype(np.float32) for i in range(3)))
    ctx = mi.BSDFContext()
    f = bsdf.eval(ctx, si, w)
    p = bsdf.pdf(ctx, si, w)
    return np.stack([np.asarray(f[i], dtype=np.float64) for i in range(3)], axis=1), np.asarray(p, dtype=np.float64)


def pairs(desc, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """n (wo, wi) pairs: wo uniform on the sphere, wi uniform for half of them and drawn by grisx's sampler (into
    the lobes' peaks) for the other half."""
    rng = np.random.default_rng(seed)
    wo = sphere_dirs(rng.random((n, 2)))
    wi = sphere_dirs(rng.random((n, 2)))
    half = n // 2
    s = sample(desc, wo[half:], n - half, "cpu", seed=seed + 1)
    wi[half:] = np.where(s["valid"][:, None], s["wi"], wi[half:])
    return wo, wi


@pytest.mark.parametrize("index", range(len(CASES)), ids=[c[0] for c in CASES])
def test_eval_and_pdf_match_mitsuba(index, device):
    """eval and pdf equal Mitsuba 3.9.1's at 4000 pairs, to float32 rounding: |Δ| ≤ 2e-4 |ref| + 1e-5 (eval, per
    channel) and likewise for the pdf, except a few pairs at which float32 half vectors put a facet on the other side
    of a grazing direction (≤ 0.2% of the pairs may differ more)."""
    mi = _mitsuba()
    name, desc, _ = CASES[index]
    wo, wi = pairs(desc, 4000, seed=100 + index)
    f, p = evaluate(desc, wo, wi, device)
    ref_f, ref_p = mitsuba_eval_pdf(mi, desc, wo, wi)
    ok = (np.abs(f - ref_f) <= 2e-4 * np.abs(ref_f) + 1e-5).all(axis=1) & (np.abs(p - ref_p) <= 2e-4 * np.abs(ref_p) + 1e-5)
    rel_f = np.max(np.abs(f - ref_f)[ok] / (np.abs(ref_f)[ok] + 1e-3))
    rel_p = np.max(np.abs(p - ref_p)[ok] / (np.abs(ref_p)[ok] + 1e-3))
    bad = np.flatnonzero(~ok)
    print(f"{name}: {ok.mean():.4%} of pairs agree; max rel. error eval {rel_f:.2e}, pdf {rel_p:.2e}; "
          f"nonzero eval {np.mean(ref_f.max(axis=1) > 0):.2f}, worst {[(wo[i].round(4), wi[i].round(4), f[i], ref_f[i], p[i], ref_p[i]) for i in bad[:3]]}")
    assert ok.mean() >= 0.998, f"{name}: {len(bad)} pairs disagree"
    assert np.mean(ref_f.max(axis=1) > 0) > 0.3


def test_mitsuba_comparison_catches_the_clearcoat_with_burleys_normalization(device):
    """The comparison sees a change of one lobe: Burley's clearcoat f = ¼ cc F D G / (4 cos θ_o cos θ_i) (the paper's)
    instead of Mitsuba's ¼ cc F D G (what Mitsuba renders) — emulated by comparing a clearcoat-free material's eval
    plus the paper's clearcoat term against Mitsuba's full one."""
    mi = _mitsuba()
    desc = Principled(base_color=(0.5, 0.5, 0.5), clearcoat=1.0, clearcoat_gloss=0.5, roughness=0.5)
    wo, wi = pairs(desc, 2000, seed=5)
    ref_f, _ = mitsuba_eval_pdf(mi, desc, wo, wi)
    no_cc, _ = mitsuba_eval_pdf(mi, dataclasses.replace(desc, clearcoat=0.0), wo, wi)
    mitsuba_cc = ref_f - no_cc  # ¼ F D G |cos θ_i|
    cos = np.abs(wo[:, 2] * wi[:, 2])[:, None]
    burley = no_cc + mitsuba_cc / (4 * np.maximum(cos, 1e-9))
    f, _ = evaluate(desc, wo, wi, device)
    ok = (np.abs(f - ref_f) <= 2e-4 * np.abs(ref_f) + 1e-5).all(axis=1)
    ok_burley = (np.abs(burley - ref_f) <= 2e-4 * np.abs(ref_f) + 1e-5).all(axis=1)
    assert ok.mean() >= 0.998 and ok_burley.mean() < 0.95, (ok.mean(), ok_burley.mean())


# ---------------------------------------------------------------- statistics: χ², weights, albedo

#: (name, record, θ of wo in degrees); a turned tangent for the anisotropic lobes, the inside of the transmission
CHI2_CASES = [
    ("defaults-30", Principled(), 30.0),
    ("metal-a0.25-70", Principled(base_color=(0.9, 0.6, 0.2), metallic=1.0, roughness=0.25), 70.0),
    ("full-45", Principled(**FULL), 45.0),
    ("full-inside-140", Principled(**FULL), 140.0),
    ("full-aniso-turned-60", Turned(Principled(**FULL, anisotropic=0.7), 35.0), 60.0),
    ("clearcoat-glossy-20", Principled(clearcoat=1.0, clearcoat_gloss=0.9, roughness=0.7), 20.0),
    # (roughness ≥ 0.45 at near-normal incidence: narrower transmission peaks than the cells' quadrature resolves)
    ("glass-10", Principled(spec_trans=1.0, roughness=0.45, eta=1.33), 10.0),
    ("glass-inside-125", Principled(spec_trans=1.0, roughness=0.35, eta=1.5), 125.0),
    ("two-sided-back-110", Principled(metallic=0.5, roughness=0.4, clearcoat=0.5, two_sided=True), 110.0),
    ("thin-30", PrincipledThin(spec_trans=0.5, diff_trans=0.8, roughness=0.4, eta=1.33), 30.0),
    ("thin-back-150", PrincipledThin(spec_trans=0.7, diff_trans=1.4, roughness=0.3), 150.0),
    ("thin-aniso-turned-75", Turned(PrincipledThin(spec_trans=0.8, anisotropic=0.6, roughness=0.5, diff_trans=0.4), -50.0), 75.0),
]


@pytest.mark.parametrize("index", range(len(CHI2_CASES)), ids=[c[0] for c in CHI2_CASES])
def test_chi2_sample_matches_pdf(index, device):
    name, desc, theta = CHI2_CASES[index]
    check_chi2(name, desc, theta, device, 2000 + index, len(CHI2_CASES))


def test_chi2_catches_thin_transmission_sampled_without_burleys_roughness_scale(device):
    # samples of a sheet of η = 1.5 (transmission roughness × 0.625) against the pdf of one whose scale is 1
    # (η = 1.35/0.65 + ... : 0.65 η − 0.35 = 1), the rest identical: the pdf of the scale forgotten
    desc = PrincipledThin(spec_trans=0.9, roughness=0.5, eta=1.5)
    wo = direction(40.0, 40.0)
    s = sample(desc, wo, N_CHI2, device, seed=31)
    unscaled = dataclasses.replace(desc, eta=1.35 / 0.65)
    result = _chi2(s["wi"], s["valid"], _cell_masses(lambda d: evaluate(unscaled, wo, d, device)[1]), tests=len(CHI2_CASES))
    print(f"unscaled transmission roughness: {result}")
    assert not result.passed and result.p_value < 1e-12, result


def test_chi2_catches_a_pdf_without_the_clearcoat_lobe(device):
    # samples with the clearcoat chosen ¼ clearcoat of the time, against the pdf of the same lobes without it
    desc = Principled(clearcoat=1.0, clearcoat_gloss=0.3, roughness=0.6)
    wo = direction(30.0, 40.0)
    s = sample(desc, wo, N_CHI2, device, seed=32)
    result = _chi2(s["wi"], s["valid"], _cell_masses(lambda d: evaluate(dataclasses.replace(desc, clearcoat=0.0), wo, d, device)[1]),
                   tests=len(CHI2_CASES))
    print(f"no clearcoat in the pdf: {result}")
    assert not result.passed and result.p_value < 1e-12, result


@pytest.mark.parametrize("case", CHI2_CASES, ids=[c[0] for c in CHI2_CASES])
def test_weight_is_eval_over_pdf(case, device):
    name, desc, theta = case
    s = check_weight(name, desc, theta, device, valid=0.3)
    v = s["valid"]
    refracted = v & (s["wi"][:, 2] * math.cos(math.radians(theta)) < 0)
    if isinstance(getattr(desc, "desc", desc), Principled) and refracted.any():  # bent: η_it crossed, as Mitsuba's bs.eta
        assert np.all(s["eta"][refracted] != 1.0)
    if isinstance(getattr(desc, "desc", desc), PrincipledThin):
        assert np.all(s["eta"] == 1.0)  # a sheet does not bend


@pytest.mark.parametrize("case", CHI2_CASES, ids=[c[0] for c in CHI2_CASES])
def test_albedo_from_sampling_and_from_eval_agree(case, device):
    check_albedo(*case, device)  # and ≤ 1 (these cases: Burley's retro-reflection and sheen can exceed it elsewhere)


def test_reflection_is_reciprocal(device):
    """f(a, b) = f(b, a) for the reflection lobes (both directions on one side; the thin sheet from either side).
    Not for transmission: Mitsuba's thin sheet tests the facet's sides on the directions as given (G1 and
    mac_mic_compatibility), which swapping them changes, and grisx follows it (test_eval_and_pdf_match_mitsuba)."""
    rng = np.random.default_rng(4)
    a = sphere_dirs(rng.random((3000, 2)))
    b = sphere_dirs(rng.random((3000, 2)))
    for desc in (Principled(**{**FULL, "spec_trans": 0.0}), Principled(**{**FULL, "spec_trans": 0.0}, anisotropic=0.5),
                 PrincipledThin(spec_trans=0.6, diff_trans=0.7, roughness=0.4, sheen=0.5, flatness=0.4, spec_tint=0.3)):
        thin = isinstance(desc, PrincipledThin)
        keep = a[:, 2] * b[:, 2] > 0 if thin else (a[:, 2] > 0) & (b[:, 2] > 0)
        f_ab, _ = evaluate(desc, a[keep], b[keep], device)
        f_ba, _ = evaluate(desc, b[keep], a[keep], device)
        # f cos θ_i: divide by the cosine to compare f
        lhs = f_ab / np.abs(b[keep, 2:3])
        rhs = f_ba / np.abs(a[keep, 2:3])
        np.testing.assert_allclose(lhs, rhs, rtol=2e-3, atol=1e-6, err_msg=type(desc).__name__)
        assert np.mean(lhs.max(axis=1) > 0) > 0.4


# ---------------------------------------------------------------- records and packing


def test_records_pack_as_mitsuba_constructs_them():
    m = _pack_one(Principled(), 0)
    assert abs(m.eta[0] - (2 / (1 - math.sqrt(0.08 * 0.5)) - 1)) < 1e-6  # specular 0.5 → η ≈ 1.5
    assert m.nonlinear == 0 and m.anisotropic == 0
    m = _pack_one(Principled(spec_trans=0.5, eta=1.0), 0)
    assert abs(m.eta[0] - 1.001) < 1e-7 and m.nonlinear == 1  # η = 1 nudged where there is transmission
    m = _pack_one(Principled(spec_trans=0.5, specular=0.0), 0)
    assert abs(m.eta[0] - (2 / (1 - math.sqrt(0.08e-3)) - 1)) < 1e-6
    m = _pack_one(Principled(eta=1.0), 0)
    assert m.eta[0] == 1.0
    m = _pack_one(Principled(metallic=TextureRef(3), sheen=TextureRef(5), roughness=TextureRef(2), anisotropic=TextureRef(4)), 0)
    assert tuple(m.lobe_textures) == (3 * 16 + 0, 5 * 16 + 3, -1, -1)
    assert m.alpha_u_texture == 2 and m.alpha_v_texture == 4 and m.anisotropic == 1
    assert material_kinds([Principled(anisotropic=0.3), PrincipledThin()]) == {MATERIAL_PRINCIPLED, MATERIAL_PRINCIPLED_THIN,
                                                                                 MATERIAL_ANISOTROPIC}
    assert material_kinds([Principled(anisotropic=0.0)]) == {MATERIAL_PRINCIPLED}
    with pytest.raises(InvalidParameterError, match="either eta or specular"):
        _pack_one(Principled(eta=1.5, specular=0.5), 0)
    with pytest.raises(InvalidParameterError, match="a textured eta is not supported"):
        _pack_one(PrincipledThin(eta=TextureRef(0)), 0)
    with pytest.raises(InvalidParameterError, match="eta must be a finite positive number"):
        _pack_one(PrincipledThin(eta=0.0), 0)
    with pytest.raises(InvalidParameterError, match="at most four"):
        _pack_one(Principled(**{n: TextureRef(1) for n in ("metallic", "spec_trans", "sheen", "clearcoat", "flatness")}), 0)
