"""Spectra reduced to RGB as Mitsuba 3's RGB variants reduce them.

grisx renders RGB. A Mitsuba scene may give a colour as a spectrum: one
constant, ``wavelength:value`` pairs, an ``.spd`` file of such pairs, or a
``blackbody`` plugin. Mitsuba's RGB variants turn each into an sRGB triple
when the scene is loaded (``Properties::get_texture``, Mitsuba 3.9); these
functions do the same, so the loaded colours are Mitsuba's:

* A **constant** ``v`` is ``(v, v, v)`` — except where an emitter reads it
  (``radiance``, ``intensity``, ``irradiance``): there a flat spectrum is
  ``v · xyz_to_srgb(1, 1, 1)`` ≈ ``v · (1.205, 0.948, 0.909)``, the colour a
  flat emission spectrum has under sRGB's D65 white, so that RGB and
  spectral renders agree (:func:`uniform_rgb`).
* **Sampled** spectra (:func:`spectrum_list_to_srgb`): the piecewise-linear
  spectrum s(λ) (zero outside its first and last wavelength) is integrated
  against the CIE 1931 colour matching functions by the rule Mitsuba uses —
  1000 equally spaced wavelengths over [360, 830] nm,

      XYZ = (830 − 360)/1000 · Σ_i x̄ȳz̄(λ_i) s(λ_i) w(λ_i) / 106.7502593994140625,

  with w = D65 (normalized) for reflectances and w = 1 for emission — then
  mapped to linear sRGB. Reflectances are clamped to [0, 1], unbounded
  quantities (emission; a conductor's ``eta``/``k``) to ≥ 0.
* A **blackbody** of temperature T is Planck's law in W m⁻² sr⁻¹ nm⁻¹
  between ``wavelength_min`` and ``wavelength_max`` — the spectrum
  Mitsuba's spectral variants render (its RGB variants refuse it) — reduced
  like a sampled emission spectrum (:func:`blackbody_rgb`).

The CIE 1931 2° observer and D65 are tabulated every 5 nm from 360 to
830 nm and interpolated linearly, as in Mitsuba (``MI_CIE_SAMPLES`` = 95).

References
----------
[CIE] CIE 015:2018 Colorimetry, tables of the 1931 standard observer and D65.
[Mitsuba3] W. Jakob et al., Mitsuba 3 documentation, "Scene format: spectra"
           and the ``blackbody`` plugin (2022).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from grisx.errors import GrisxError

__all__ = ["CIE_MIN", "CIE_MAX", "XYZ_TO_SRGB", "SRGB_TO_XYZ", "cie_xyz", "cie_d65", "uniform_rgb", "spectrum_list_to_srgb",
           "blackbody_rgb", "read_spd"]

CIE_MIN, CIE_MAX = 360.0, 830.0
CIE_Y_NORMALIZATION = 1.0 / 106.7502593994140625  # Mitsuba's MI_CIE_Y_NORMALIZATION: ∫ ȳ(λ) dλ
#: linear sRGB from CIE XYZ (D65 white)
XYZ_TO_SRGB = np.array([[3.240479, -1.537150, -0.498535],
                        [-0.969256, 1.875991, 0.041556],
                        [0.055648, -0.204043, 1.057311]])
#: CIE XYZ from linear sRGB: Mitsuba 3's ``srgb_to_xyz`` (and its Bitmap's RGB → XYZ conversion)
SRGB_TO_XYZ = np.array([[0.412453, 0.357580, 0.180423],
                        [0.212671, 0.715160, 0.072169],
                        [0.019334, 0.119193, 0.950227]])

#: x̄, ȳ, z̄ of the CIE 1931 2° observer and D65 (divided by 98.99741751876255) at 360, 365, ..., 830 nm
_TABLE = np.array([
    (0.0001299, 3.917e-06, 0.0006061, 0.4711063),  # 360 nm
    (0.0002321, 6.965e-06, 0.001086, 0.4986362),  # 365 nm
    (0.0004149, 1.239e-05, 0.001946, 0.5261663),  # 370 nm
    (0.0007416, 2.202e-05, 0.003486, 0.5154912),  # 375 nm
    (0.001368, 3.9e-05, 0.006450001, 0.5048162),  # 380 nm
    (0.002236, 6.4e-05, 0.01054999, 0.5284158),  # 385 nm
    (0.004243, 0.00012, 0.02005001, 0.5520164),  # 390 nm
    (0.00765, 0.000217, 0.03621, 0.6939726),  # 395 nm
    (0.01431, 0.000396, 0.06785001, 0.8359299),  # 400 nm
    (0.02319, 0.00064, 0.1102, 0.880027),  # 405 nm
    (0.04351, 0.00121, 0.2074, 0.9241251),  # 410 nm
    (0.07763, 0.00218, 0.3713, 0.9339526),  # 415 nm
    (0.13438, 0.004, 0.6456, 0.9437802),  # 420 nm
    (0.21477, 0.0073, 1.03905, 0.9096904),  # 425 nm
    (0.2839, 0.0116, 1.3856, 0.8756016),  # 430 nm
    (0.3285, 0.01684, 1.62296, 0.9674353),  # 435 nm
    (0.34828, 0.023, 1.74706, 1.05927),  # 440 nm
    (0.34806, 0.0298, 1.7826, 1.120595),  # 445 nm
    (0.3362, 0.038, 1.77211, 1.18193),  # 450 nm
    (0.3187, 0.048, 1.7441, 1.185991),  # 455 nm
    (0.2908, 0.06, 1.6692, 1.190051),  # 460 nm
    (0.2511, 0.0739, 1.5281, 1.175142),  # 465 nm
    (0.19536, 0.09098, 1.28764, 1.160242),  # 470 nm
    (0.1421, 0.1126, 1.0419, 1.165606),  # 475 nm
    (0.09564, 0.13902, 0.8129501, 1.17097),  # 480 nm
    (0.05795001, 0.1693, 0.6162, 1.13505),  # 485 nm
    (0.03201, 0.20802, 0.46518, 1.09913),  # 490 nm
    (0.0147, 0.2586, 0.3533, 1.101867),  # 495 nm
    (0.0049, 0.323, 0.272, 1.104615),  # 500 nm
    (0.0024, 0.4073, 0.2123, 1.096776),  # 505 nm
    (0.0093, 0.503, 0.1582, 1.088938),  # 510 nm
    (0.0291, 0.6082, 0.1117, 1.073725),  # 515 nm
    (0.06327, 0.71, 0.07824999, 1.058512),  # 520 nm
    (0.1096, 0.7932, 0.05725001, 1.073149),  # 525 nm
    (0.1655, 0.862, 0.04216, 1.087796),  # 530 nm
    (0.2257499, 0.9148501, 0.02984, 1.07121),  # 535 nm
    (0.2904, 0.954, 0.0203, 1.054623),  # 540 nm
    (0.3597, 0.9803, 0.0134, 1.052805),  # 545 nm
    (0.4334499, 0.9949501, 0.008749999, 1.050997),  # 550 nm
    (0.5120501, 1, 0.005749999, 1.030562),  # 555 nm
    (0.5945, 0.995, 0.0039, 1.010127),  # 560 nm
    (0.6784, 0.9786, 0.002749999, 0.9916127),  # 565 nm
    (0.7621, 0.952, 0.0021, 0.9730981),  # 570 nm
    (0.8425, 0.9154, 0.0018, 0.9703394),  # 575 nm
    (0.9163, 0.87, 0.001650001, 0.9675808),  # 580 nm
    (0.9786, 0.8163, 0.0014, 0.9317092),  # 585 nm
    (1.0263, 0.757, 0.0011, 0.8958375),  # 590 nm
    (1.0567, 0.6949, 0.001, 0.9025074),  # 595 nm
    (1.0622, 0.631, 0.0008, 0.9091773),  # 600 nm
    (1.0456, 0.5668, 0.0006, 0.9071206),  # 605 nm
    (1.0026, 0.503, 0.00034, 0.905065),  # 610 nm
    (0.9384, 0.4412, 0.00024, 0.8954668),  # 615 nm
    (0.8544499, 0.381, 0.00019, 0.8858685),  # 620 nm
    (0.7514, 0.321, 0.0001, 0.8635942),  # 625 nm
    (0.6424, 0.265, 4.999999e-05, 0.8413209),  # 630 nm
    (0.5419, 0.217, 3e-05, 0.8433947),  # 635 nm
    (0.4479, 0.175, 2e-05, 0.8454686),  # 640 nm
    (0.3608, 0.1382, 1e-05, 0.8269206),  # 645 nm
    (0.2835, 0.107, 0, 0.8083726),  # 650 nm
    (0.2187, 0.0816, 0, 0.8093211),  # 655 nm
    (0.1649, 0.061, 0, 0.8102696),  # 660 nm
    (0.1212, 0.04458, 0, 0.8206901),  # 665 nm
    (0.0874, 0.032, 0, 0.8311106),  # 670 nm
    (0.0636, 0.0232, 0, 0.8109403),  # 675 nm
    (0.04677, 0.017, 0, 0.7907702),  # 680 nm
    (0.0329, 0.01192, 0, 0.7475215),  # 685 nm
    (0.0227, 0.00821, 0, 0.7042739),  # 690 nm
    (0.01584, 0.005723, 0, 0.7138085),  # 695 nm
    (0.01135916, 0.004102, 0, 0.7233431),  # 700 nm
    (0.008110916, 0.002929, 0, 0.7371808),  # 705 nm
    (0.005790346, 0.002091, 0, 0.7510196),  # 710 nm
    (0.004109457, 0.001484, 0, 0.6866493),  # 715 nm
    (0.002899327, 0.001047, 0, 0.6222789),  # 720 nm
    (0.00204919, 0.00074, 0, 0.6641062),  # 725 nm
    (0.001439971, 0.00052, 0, 0.7059336),  # 730 nm
    (0.0009999493, 0.0003611, 0, 0.7322039),  # 735 nm
    (0.0006900786, 0.0002492, 0, 0.7584743),  # 740 nm
    (0.0004760213, 0.0001719, 0, 0.7004203),  # 745 nm
    (0.0003323011, 0.00012, 0, 0.6423673),  # 750 nm
    (0.0002348261, 8.48e-05, 0, 0.5556246),  # 755 nm
    (0.0001661505, 6e-05, 0, 0.4688829),  # 760 nm
    (0.000117413, 4.24e-05, 0, 0.5718513),  # 765 nm
    (8.307527e-05, 3e-05, 0, 0.6748196),  # 770 nm
    (5.870652e-05, 2.12e-05, 0, 0.6575333),  # 775 nm
    (4.150994e-05, 1.499e-05, 0, 0.640247),  # 780 nm
    (2.935326e-05, 1.06e-05, 0, 0.6448997),  # 785 nm
    (2.067383e-05, 7.4657e-06, 0, 0.6495523),  # 790 nm
    (1.455977e-05, 5.2578e-06, 0, 0.6250456),  # 795 nm
    (1.025398e-05, 3.7029e-06, 0, 0.6005399),  # 800 nm
    (7.221456e-06, 2.6078e-06, 0, 0.5626955),  # 805 nm
    (5.085868e-06, 1.8366e-06, 0, 0.5248521),  # 810 nm
    (3.581652e-06, 1.2934e-06, 0, 0.5525376),  # 815 nm
    (2.522525e-06, 9.1093e-07, 0, 0.5802233),  # 820 nm
    (1.776509e-06, 6.4153e-07, 0, 0.5947276),  # 825 nm
    (1.251141e-06, 4.5181e-07, 0, 0.6092331),  # 830 nm
])


def _lookup(wavelengths: np.ndarray, columns: slice) -> np.ndarray:
    w = np.asarray(wavelengths, dtype=np.float64)
    nodes = CIE_MIN + 5.0 * np.arange(len(_TABLE))
    out = np.stack([np.interp(w, nodes, _TABLE[:, k], left=0.0, right=0.0) for k in range(4)[columns]], axis=-1)
    return out


def cie_xyz(wavelengths: np.ndarray) -> np.ndarray:
    """x̄, ȳ, z̄ at ``wavelengths`` (nm), shape (..., 3); zero outside [360, 830]."""
    return _lookup(wavelengths, slice(0, 3))


def cie_d65(wavelengths: np.ndarray) -> np.ndarray:
    """The D65 illuminant (normalized as Mitsuba's ``cie_d65``) at ``wavelengths`` (nm)."""
    return _lookup(wavelengths, slice(3, 4))[..., 0]


def _to_srgb(xyz: np.ndarray, bounded: bool) -> tuple[float, float, float]:
    rgb = XYZ_TO_SRGB @ xyz
    rgb = np.clip(rgb, 0.0, 1.0) if bounded else np.maximum(rgb, 0.0)
    return tuple(float(c) for c in rgb)


def _integrate(values_at: np.ndarray, lam: np.ndarray, d65: bool) -> np.ndarray:
    weight = values_at * (cie_d65(lam) if d65 else 1.0)
    return (cie_xyz(lam) * weight[:, None]).sum(axis=0) * (CIE_MAX - CIE_MIN) * CIE_Y_NORMALIZATION / 1000.0


_LAMBDAS = CIE_MIN + np.arange(1000) / 999.0 * (CIE_MAX - CIE_MIN)  # Mitsuba's 1000 integration wavelengths


def uniform_rgb(value: float, emitter: bool) -> tuple[float, float, float]:
    """A constant spectrum's RGB: ``(v, v, v)``, or ``v · xyz_to_srgb(1, 1, 1)`` where an emitter reads it."""
    if not emitter:
        return (float(value),) * 3
    return tuple(float(c) for c in value * XYZ_TO_SRGB.sum(axis=1))


def spectrum_list_to_srgb(wavelengths, values, bounded: bool, d65: bool) -> tuple[float, float, float]:
    """Linear sRGB of a piecewise-linear spectrum given at increasing ``wavelengths`` (nm) — Mitsuba's
    ``spectrum_list_to_srgb``: ``d65`` for reflectances (seen under D65), ``bounded`` clamps to [0, 1]."""
    w = np.asarray(wavelengths, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64)
    if w.ndim != 1 or w.shape != v.shape or len(w) < 1:
        raise GrisxError(f"a sampled spectrum needs as many wavelengths as values (got {w.size} and {v.size})")
    if not (np.all(np.isfinite(w)) and np.all(np.isfinite(v))):
        raise GrisxError("a sampled spectrum has a NaN or infinite wavelength or value")
    if np.any(np.diff(w) < 0):
        raise GrisxError("the wavelengths of a sampled spectrum must increase")
    lam = _LAMBDAS[(_LAMBDAS >= w[0]) & (_LAMBDAS <= w[-1])]
    return _to_srgb(_integrate(np.interp(lam, w, v), lam, d65), bounded)


def blackbody_rgb(temperature: float, wavelength_min: float = CIE_MIN, wavelength_max: float = CIE_MAX) -> tuple[float, float, float]:
    """Linear sRGB radiance of a black body at ``temperature`` kelvin (Planck's law, W m⁻² sr⁻¹ nm⁻¹) emitting
    between ``wavelength_min`` and ``wavelength_max`` nm, as Mitsuba's spectral variants render it."""
    if not (temperature > 0 and math.isfinite(temperature)):
        raise GrisxError(f"a blackbody needs a positive temperature in kelvin, got {temperature}")
    if not (0 < wavelength_min < wavelength_max):
        raise GrisxError(f"a blackbody needs 0 < wavelength_min < wavelength_max, got {wavelength_min}, {wavelength_max}")
    c, h, k = 2.99792458e8, 6.62607004e-34, 1.38064852e-23  # the constants Mitsuba's blackbody plugin uses
    lam = _LAMBDAS[(_LAMBDAS >= wavelength_min) & (_LAMBDAS <= wavelength_max)]
    metres = lam * 1e-9
    with np.errstate(over="ignore"):
        planck = 1e-9 * 2 * h * c * c / (metres**5 * np.expm1(h * c / (k * metres * temperature)))
    return _to_srgb(_integrate(planck, lam, d65=False), bounded=False)


def read_spd(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """An ``.spd`` file: lines of ``wavelength value`` (``#`` starts a comment), as Mitsuba reads them."""
    path = Path(path)
    if not path.is_file():
        raise GrisxError(f"cannot read spectrum '{path}': no such file")
    if path.suffix.lower() != ".spd":
        raise GrisxError(f"cannot read spectrum '{path}': expected an .spd file")
    rows = []
    for number, line in enumerate(path.read_text(errors="replace").splitlines(), start=1):
        fields = line.split("#", 1)[0].split()
        if not fields:
            continue
        try:
            pair = [float(f) for f in fields]
        except ValueError:
            raise GrisxError(f"cannot read spectrum '{path}': line {number}: not numbers: {line.strip()!r}") from None
        if len(pair) != 2:
            raise GrisxError(f"cannot read spectrum '{path}': line {number}: expected 'wavelength value', got {line.strip()!r}")
        rows.append(pair)
    if not rows:
        raise GrisxError(f"cannot read spectrum '{path}': no data")
    data = np.array(rows)
    return data[:, 0], data[:, 1]
