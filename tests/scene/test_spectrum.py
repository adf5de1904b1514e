"""Spectra reduced to RGB (grisx.scene.spectrum and the loader's <spectrum>): values Mitsuba 3.9.1's scalar_rgb
variant produced for the same inputs (mi.traverse of the loaded plugins, mi.spectrum_list_to_srgb), and
mitsuba-data's spectral Cornell box (tests/scene/data/mitsuba_data)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from grisx.scene import spectrum
from grisx.scene.material import CONDUCTOR_PRESETS, Conductor, Diffuse, conductor_material
from grisx.scene.mitsuba import load_mitsuba

MD = Path(__file__).parent / "data" / "mitsuba_data"
TOL = dict(rtol=2e-5, atol=2e-6)  # Mitsuba computes in float32


def doc(body: str) -> str:
    return '<scene version="3.0.0">\n' + body + "\n</scene>\n"


def test_a_flat_emission_spectrum_has_the_colour_of_flat_light_under_d65():
    np.testing.assert_allclose(spectrum.uniform_rgb(1.0, emitter=True), [1.20479, 0.948291, 0.908916], **TOL)
    assert spectrum.uniform_rgb(0.3, emitter=False) == (0.3, 0.3, 0.3)
    s = load_mitsuba(doc('<shape type="sphere"><emitter type="area"><spectrum name="radiance" value="2"/></emitter></shape>\n'
                         '<emitter type="point"><spectrum name="intensity" value="1"/></emitter>'))
    np.testing.assert_allclose(s.objects[0].emission, [2 * 1.20479, 2 * 0.948291, 2 * 0.908916], **TOL)


@pytest.mark.parametrize("where, values, expected", [
    ('<bsdf type="diffuse"><spectrum name="reflectance" value="{}"/></bsdf>', "400:0.1, 500:0.5, 600:0.8, 700:0.2",
     [0.731215, 0.646851, 0.271934]),  # seen under D65, in [0, 1]
    ('<emitter type="area"><spectrum name="radiance" value="{}"/></emitter>', "400:1, 500:2, 600:3, 700:4",
     [4.02061, 2.31368, 1.24453]),  # emission: no D65, unbounded
    ('<bsdf type="conductor"><spectrum name="eta" value="{}"/></bsdf>', "400:1, 500:2, 600:3, 700:4",
     [3.40779, 2.42912, 1.40304]),  # unbounded, under D65
])
def test_sampled_spectra_as_mitsuba_reduces_them(where, values, expected):
    s = load_mitsuba(doc('<shape type="sphere">' + where.format(values) + "</shape>"))
    if "emitter" in where:
        got = s.objects[0].emission
    else:
        m = s.materials[s.objects[0].material]
        got = m.reflectance if isinstance(m, Diffuse) else m.eta
    np.testing.assert_allclose(got, expected, **TOL)


def test_out_of_gamut_reflectances_are_clamped_emission_only_at_zero():
    # a narrow red line: outside sRGB, negative green and blue
    w, v = [600, 610, 620], [0, 50, 0]
    assert min(spectrum.spectrum_list_to_srgb(w, v, bounded=True, d65=True)) == 0.0
    assert max(spectrum.spectrum_list_to_srgb(w, v, bounded=True, d65=True)) == 1.0
    r, g, b = spectrum.spectrum_list_to_srgb(w, v, bounded=False, d65=False)
    assert r > 1.0 and g >= 0.0 and b == 0.0


def test_spd_files_as_mitsuba_reads_them():
    s = load_mitsuba(doc(f'<path value="{MD / "ior"}"/>\n<shape type="sphere"><bsdf type="conductor">'
                         '<spectrum name="eta" filename="Au.eta.spd"/><spectrum name="k" filename="Au.k.spd"/></bsdf></shape>'))
    m = s.materials[s.objects[0].material]
    assert isinstance(m, Conductor)
    np.testing.assert_allclose(m.eta, [0.0798705, 0.404652, 1.55897], **TOL)
    np.testing.assert_allclose(m.k, [3.38675, 2.50071, 1.76891], **TOL)


@pytest.mark.parametrize("name", ["Au", "a-C", "AlSb"])
def test_named_conductors_are_mitsubas_ior_files_reduced_without_d65(name):
    """``material="NAME"`` is data/ior/NAME.{eta,k}.spd reduced unbounded, without D65, negatives clamped (AlSb's red)."""
    for got, part in zip(CONDUCTOR_PRESETS[name], ("eta", "k")):
        w, v = spectrum.read_spd(MD / "ior" / f"{name}.{part}.spd")
        np.testing.assert_allclose(got, spectrum.spectrum_list_to_srgb(w, v, bounded=False, d65=False), **TOL)
    assert CONDUCTOR_PRESETS["AlSb"][0][0] == CONDUCTOR_PRESETS["AlSb"][1][0] == 0.0  # clamped, as Mitsuba's srgb texture clamps it
    # eta = 0 is a mirror whatever k (Mitsuba's fresnel_conductor away from normal incidence): k = 1 as in 'none'
    assert conductor_material("AlSb") == (CONDUCTOR_PRESETS["AlSb"][0], (1.0,) + CONDUCTOR_PRESETS["AlSb"][1][1:])


def test_every_mitsuba_conductor_material_loads():
    """All 71 materials of Mitsuba 3's data/ior, as conductor and roughconductor presets."""
    names = [n for n in CONDUCTOR_PRESETS if n != "none"]
    assert len(names) == 71
    for name in names:
        for plugin in ("conductor", "roughconductor"):
            s = load_mitsuba(doc(f'<shape type="sphere"><bsdf type="{plugin}"><string name="material" value="{name}"/></bsdf></shape>'))
            m = s.materials[s.objects[0].material]
            assert (m.eta, m.k) == conductor_material(name), (plugin, name)


@pytest.mark.parametrize("temperature, expected", [
    (1500, [0.346319, 0.0460866, 0.0]), (3000, [733.11, 349.569, 112.71]), (6500, [43918.5, 41407.1, 43582.8]),
])
def test_blackbody_is_plancks_law_reduced_as_emission(temperature, expected):
    # expected: mi.spectrum_list_to_srgb of Planck's law sampled every 0.1 nm (bounded=False, d65=False)
    np.testing.assert_allclose(spectrum.blackbody_rgb(temperature), expected, rtol=2e-5, atol=1e-6)
    s = load_mitsuba(doc('<shape type="sphere"><emitter type="area"><spectrum type="blackbody" name="radiance">'
                         f'<float name="temperature" value="{temperature}"/></spectrum></emitter></shape>'))
    np.testing.assert_allclose(s.objects[0].emission, expected, rtol=2e-5, atol=1e-6)
    assert spectrum.blackbody_rgb(6500, 500, 600)[2] < 0.5 * spectrum.blackbody_rgb(6500)[2]  # a band of it


def test_the_cie_tables_integrate_as_mitsubas():
    lam = np.linspace(360, 830, 1000)  # Mitsuba's integration rule: its normalization makes ∫ȳ = 1
    assert abs(spectrum.cie_xyz(lam)[:, 1].sum() * 470 / 1000 * spectrum.CIE_Y_NORMALIZATION - 1.0) < 1e-4
    np.testing.assert_allclose(spectrum.cie_xyz(555.0), [0.51205, 1.0, 0.00575], rtol=1e-5)
    np.testing.assert_allclose(spectrum.cie_d65(555.0), 1.0305622816085815, rtol=1e-6)


@pytest.mark.parametrize("name", ["cbox.xml", "cbox-spectral.xml"])
def test_mitsuba_datas_spectral_cornell_box(name):
    s = load_mitsuba(MD / "cbox" / name)
    colours = sorted({tuple(round(c, 4) for c in m.reflectance) for m in s.materials})  # two BSDFs share a spectrum
    expected = [[0.0682825, 0.39776, 0.0862909], [0.49132, 0.0492281, 0.0509219],
                [0.735013, 0.735625, 0.736264], [0.776367, 0.77981, 0.776029]]
    np.testing.assert_allclose(colours, expected, atol=1e-4)
    lights = [o.emission for o in s.objects if o.emission is not None]
    assert len(lights) == 1
    np.testing.assert_allclose(lights[0], [20.7108, 10.8546, 2.77115], **TOL)


def test_mitsuba_datas_rgb_cornell_box_with_includes_and_a_referenced_emitter():
    s = load_mitsuba(MD / "cbox" / "cbox-rgb.xml")
    colours = sorted({tuple(m.reflectance) for m in s.materials})
    np.testing.assert_allclose(colours, sorted([(0.570068, 0.0430135, 0.0443706), (0.105421, 0.37798, 0.076425),
                                                (0.885809, 0.698859, 0.666422), (0.45, 0.3, 0.9),
                                                (0.936461, 0.740433, 0.705267)]), **TOL)
    lights = [o.emission for o in s.objects if o.emission is not None]
    np.testing.assert_allclose(lights, [[18.387, 10.9873, 2.75357]], **TOL)
