"""Colorimetry adapter: reference values from colour-science's own paths and hand arithmetic."""

from __future__ import annotations

import logging
import math
import subprocess
import sys

import numpy as np
import pytest

from raytrad.scene import colorimetry
from raytrad.scene.colorimetry import (
    LUMINANCE_WEIGHTS,
    LUMINOUS_EFFICACY,
    blackbody_rgb,
    emitter_rgb,
    exitance_from_flux,
    exitance_from_power,
    illuminant_rgb,
    luminance,
    named_reflectance,
    reflectance_names,
    reflectance_to_rgb,
)

colour = pytest.importorskip("colour")

# The reference path below calls colour-science directly, which notes every shape alignment.
pytestmark = pytest.mark.filterwarnings("ignore::colour.utilities.ColourRuntimeWarning")


def _reference_srgb(patch: str) -> np.ndarray:
    """Linear sRGB of a BabelColor patch under D65 by colour-science's own route."""
    sd = colour.SDS_COLOURCHECKERS["BabelColor Average"][patch]
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    xyz = colour.sd_to_XYZ(sd, cmfs, colour.SDS_ILLUMINANTS["D65"]) / 100.0
    return np.asarray(colour.XYZ_to_sRGB(xyz, apply_cctf_encoding=False))


# --------------------------------------------------------------------------- reflectance


@pytest.mark.parametrize(
    "wavelengths",
    [
        np.arange(380.0, 781.0, 10.0),  # regular, used as is
        np.arange(360.0, 831.0, 1.0),
        np.array([400.0, 437.5, 612.0, 700.0]),  # irregular, resampled to 1 nm
        np.array([300.0, 900.0]),
    ],
)
@pytest.mark.parametrize("illuminant", ["D65", "A", "FL2"])
def test_flat_spectrum_keeps_its_value_under_any_illuminant(
    wavelengths: np.ndarray, illuminant: str
) -> None:
    rgb = reflectance_to_rgb(wavelengths, np.full(len(wavelengths), 0.5), illuminant)
    assert rgb.shape == (3,)
    np.testing.assert_allclose(rgb, 0.5, atol=1e-3)
    white = reflectance_to_rgb(wavelengths, np.ones(len(wavelengths)), illuminant)
    np.testing.assert_allclose(white, 1.0, atol=1e-9)


@pytest.mark.parametrize("patch", ["dark skin", "blue sky", "red", "neutral 5 (.70 D)"])
def test_colorchecker_patch_matches_colour_science_srgb(patch: str) -> None:
    rgb = reflectance_to_rgb(*named_reflectance(patch))
    np.testing.assert_allclose(rgb, _reference_srgb(patch), atol=1e-3)


def test_every_colorchecker_patch_matches_colour_science_srgb() -> None:
    for patch in reflectance_names():
        np.testing.assert_allclose(
            reflectance_to_rgb(*named_reflectance(patch)), _reference_srgb(patch), atol=1e-3
        )


def test_dark_skin_reference_value() -> None:
    # Linear sRGB of BabelColor Average "dark skin" under D65 (sRGB-encoded about 115, 81, 67).
    rgb = reflectance_to_rgb(*named_reflectance("dark skin"))
    np.testing.assert_allclose(rgb, [0.1725, 0.0838, 0.0576], atol=1e-3)


def test_reflectance_to_rgb_is_whole_array_and_linear() -> None:
    wavelengths, dark_skin = named_reflectance("dark skin")
    _, blue_sky = named_reflectance("blue sky")
    stack = np.stack([[dark_skin, blue_sky], [0.5 * dark_skin, 0.5 * dark_skin + 0.5 * blue_sky]])
    rgb = reflectance_to_rgb(wavelengths, stack)
    assert rgb.shape == (2, 2, 3)
    one = reflectance_to_rgb(wavelengths, dark_skin)
    two = reflectance_to_rgb(wavelengths, blue_sky)
    np.testing.assert_allclose(rgb[0, 0], one, rtol=1e-12)
    np.testing.assert_allclose(rgb[0, 1], two, rtol=1e-12)
    np.testing.assert_allclose(rgb[1, 0], 0.5 * one, rtol=1e-12)
    np.testing.assert_allclose(rgb[1, 1], 0.5 * (one + two), rtol=1e-12)


def test_out_of_gamut_patch_is_returned_unclipped() -> None:
    assert reflectance_to_rgb(*named_reflectance("cyan"))[0] < 0.0


@pytest.mark.parametrize(
    ("wavelengths", "values", "message"),
    [
        ([400.0, 500.0, 600.0], [0.5, np.nan, 0.5], "finite"),
        ([400.0, 400.0, 600.0], [0.5, 0.5, 0.5], "increase"),
        ([400.0, 500.0], [0.5, 0.5, 0.5], "one entry per wavelength"),
        ([500.0], [0.5], "at least 2"),
        ([np.nan, 500.0], [0.5, 0.5], "finite"),
    ],
)
def test_malformed_spectra_raise(
    wavelengths: list[float], values: list[float], message: str
) -> None:
    with pytest.raises(ValueError, match=message):
        reflectance_to_rgb(wavelengths, values)


def test_named_reflectance_is_case_insensitive_and_lists_names_when_unknown() -> None:
    wavelengths, values = named_reflectance("Dark Skin")
    assert wavelengths.shape == values.shape and wavelengths[0] == 380.0
    with pytest.raises(ValueError, match=r"'dark skin'.*'light skin'"):
        named_reflectance("skin")
    assert len(reflectance_names()) == 24 and "white 9.5 (.05 D)" in reflectance_names()


def test_unknown_illuminant_lists_valid_names() -> None:
    with pytest.raises(ValueError, match=r"unknown illuminant 'D66'.*'D65'"):
        reflectance_to_rgb([400.0, 700.0], [0.5, 0.5], "D66")


# --------------------------------------------------------------------------- emitters


def test_6500k_blackbody_is_near_white_with_unit_luminance() -> None:
    rgb = blackbody_rgb(6500.0)
    assert luminance(rgb) == pytest.approx(1.0)
    assert np.all(np.abs(rgb - rgb.mean()) < 0.1 * rgb.mean())


@pytest.mark.parametrize("temperature", [2700.0, 3000.0])
def test_incandescent_blackbody_is_warm(temperature: float) -> None:
    r, g, b = blackbody_rgb(temperature)
    assert r > g > b > 0.0


def test_blackbody_outside_the_gamut_is_clipped_with_a_warning(
    caplog: pytest.LogCaptureFixture,
) -> None:
    with caplog.at_level(logging.WARNING, logger="raytrad.scene.colorimetry"):
        rgb = blackbody_rgb(1000.0)
    assert "outside the BT.709 gamut" in caplog.text
    assert rgb.min() == 0.0 and luminance(rgb) == pytest.approx(1.0)


def test_d65_illuminant_is_white_and_a_is_warm() -> None:
    np.testing.assert_allclose(illuminant_rgb("D65"), 1.0, atol=1e-3)
    r, g, b = illuminant_rgb("a")
    assert r > g > b


def test_emitter_rgb_dispatches_through_the_registry() -> None:
    assert set(colorimetry.EMITTER_COLOURS) == {"temperature_k", "illuminant", "colour"}
    np.testing.assert_allclose(emitter_rgb("temperature_k", 3000.0), blackbody_rgb(3000.0))
    np.testing.assert_allclose(emitter_rgb("illuminant", "D50"), illuminant_rgb("D50"))
    np.testing.assert_allclose(emitter_rgb("colour", [2.0, 2.0, 2.0]), [1.0, 1.0, 1.0])
    np.testing.assert_allclose(emitter_rgb("colour", [1.0, 0.0, 0.0]), [1 / 0.2126, 0.0, 0.0])
    with pytest.raises(ValueError, match="unknown emitter colour kind"):
        emitter_rgb("kelvin", 3000.0)
    with pytest.raises(ValueError, match="no luminance"):
        emitter_rgb("colour", [0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match=">= 0"):
        emitter_rgb("colour", [1.0, -0.1, 0.0])
    with pytest.raises(ValueError, match="> 0"):
        emitter_rgb("temperature_k", float("nan"))


def test_luminance_weights_are_the_srgb_matrix_row() -> None:
    matrix = colour.RGB_COLOURSPACES["sRGB"].matrix_RGB_to_XYZ
    np.testing.assert_allclose(LUMINANCE_WEIGHTS, matrix[1], atol=1e-4)
    assert luminance([1.0, 1.0, 1.0]) == pytest.approx(1.0)
    assert luminance(np.ones((4, 2, 3))).shape == (4, 2)


# --------------------------------------------------------------------------- photometry


def test_exitance_from_power_spreads_the_mean_channel_power() -> None:
    # 10 W over 2 m2: 5 W m-2 on average over the channels.
    np.testing.assert_allclose(exitance_from_power(10.0, 2.0, [1.0, 1.0, 1.0]), [5.0, 5.0, 5.0])
    np.testing.assert_allclose(exitance_from_power(10.0, 2.0, [2.0, 1.0, 0.0]), [10.0, 5.0, 0.0])
    exitance = exitance_from_power([10.0, 3.0], [2.0, 0.5], [[1.0, 1.0, 1.0], [3.0, 2.0, 1.0]])
    np.testing.assert_allclose(exitance, [[5.0, 5.0, 5.0], [9.0, 6.0, 3.0]])
    assert exitance.mean(axis=1) @ [2.0, 0.5] == pytest.approx(13.0)


def test_exitance_from_flux_against_hand_numbers() -> None:
    # 683 lm over 1 m2 of white: 1 W m-2 in each channel (Y = 1 W m-2 = 683 lm m-2).
    np.testing.assert_allclose(exitance_from_flux(683.0, 1.0, [1.0, 1.0, 1.0]), 1.0)
    # 1000 lm of pure red over 0.5 m2: 1000 / (683 * 0.5 * 0.2126) = 13.77355... W m-2.
    red = exitance_from_flux(1000.0, 0.5, [1.0, 0.0, 0.0])
    np.testing.assert_allclose(red, [13.773554, 0.0, 0.0], rtol=1e-6)
    warm = blackbody_rgb(3000.0)
    exitance = exitance_from_flux(450.0, 0.01365, warm)
    assert LUMINOUS_EFFICACY * luminance(exitance) * 0.01365 == pytest.approx(450.0)


@pytest.mark.parametrize(
    ("amount", "area", "rgb", "message"),
    [
        (-1.0, 1.0, [1.0, 1.0, 1.0], ">= 0"),
        (np.nan, 1.0, [1.0, 1.0, 1.0], "finite"),
        (1.0, 0.0, [1.0, 1.0, 1.0], "area_m2"),
        (1.0, 1.0, [0.0, 0.0, 0.0], "> 0"),
        (1.0, 1.0, [1.0, np.nan, 1.0], "finite"),
        (1.0, 1.0, [1.0, 1.0], "3 channels"),
    ],
)
def test_photometric_conversions_reject_bad_input(
    amount: float, area: float, rgb: list[float], message: str
) -> None:
    for convert in (exitance_from_power, exitance_from_flux):
        with pytest.raises(ValueError, match=message):
            convert(amount, area, rgb)


def test_importing_the_adapter_does_not_import_colour_science() -> None:
    code = (
        "import sys\n"
        "from raytrad.scene import colorimetry as c\n"
        "c.exitance_from_flux(100.0, 1.0, c.emitter_rgb('colour', [1, 0.5, 0.2]))\n"
        "c.exitance_from_power(100.0, 1.0, [1, 1, 1])\n"
        "assert 'colour' not in sys.modules, 'colour imported'\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_luminance_weights_sum_to_one() -> None:
    assert math.isclose(sum(colorimetry.LUMINANCE_WEIGHTS), 1.0)
