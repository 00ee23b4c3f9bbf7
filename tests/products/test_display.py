"""What is shown: automatic exposure (the percentile rule, the key ceiling for flat bright
scenes) and display encodings against the sRGB formula and the shape of a filmic curve."""

from __future__ import annotations

import math

import numpy as np
import pytest

from raytrad.errors import SettingsError
from raytrad.products.display import (
    KEY_CEILING,
    auto_exposure,
    display_colors,
    display_encode,
)


def _grey(luminance: np.ndarray) -> np.ndarray:
    """(R, 3) radiosity [W m-2] whose radiance luminance is ``luminance``."""
    return np.repeat(np.asarray(luminance, dtype=float)[:, None] * math.pi, 3, axis=1)


def test_contrasty_scene_maps_its_97th_percentile_to_white() -> None:
    # a lit patch among shadow: the key is far below the bright end
    luminance = np.concatenate([np.full(90, 0.01), np.linspace(0.5, 1.0, 10)])
    exposure = auto_exposure(_grey(luminance), np.zeros(100, dtype=bool))
    assert math.isclose(exposure, 1.0 / np.percentile(luminance, 97.0))


def test_uniform_scene_puts_its_key_at_the_ceiling() -> None:
    # a furnace: every receiver at luminance 2; the percentile rule would show all white
    exposure = auto_exposure(_grey(np.full(50, 2.0)), np.zeros(50, dtype=bool))
    assert math.isclose(exposure, KEY_CEILING / 2.0)
    colours = display_colors(_grey(np.full(50, 2.0)), np.zeros(50, dtype=bool))
    assert (colours < 255).all() and np.ptp(colours) == 0


def test_key_is_area_weighted_and_skips_emitters_and_hidden_receivers() -> None:
    luminance = np.array([1.0, 4.0, 100.0, 0.0])
    area = np.array([3.0, 1.0, 1.0, 0.0])  # the last one is hidden
    emitting = np.array([False, False, True, False])
    exposure = auto_exposure(_grey(luminance), emitting, area)
    key = math.exp((3.0 * math.log(1.0) + 1.0 * math.log(4.0)) / 4.0)
    white = np.percentile([1.0, 4.0], 97.0)
    assert math.isclose(exposure, min(1.0 / white, KEY_CEILING / key))


def test_black_scene_has_unit_exposure() -> None:
    assert auto_exposure(np.zeros((5, 3)), np.zeros(5, dtype=bool)) == 1.0


RAMP = np.array([0.0, 0.01, 0.18, 0.5, 1.0, 2.0, 4.0, 16.0])


def _grey_row(values: np.ndarray) -> np.ndarray:
    return np.repeat(values[None, :, None], 3, axis=2).astype(np.float32)


def _srgb(linear: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 encoding, written out independently of raytrad."""
    c = np.clip(linear, 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)


def test_srgb_encoding_matches_the_standard_formula_and_clips() -> None:
    out = display_encode(_grey_row(RAMP), "srgb")[0, :, 0]
    np.testing.assert_allclose(out, np.round(_srgb(RAMP) * 255), atol=1)
    assert out[-4:].tolist() == [255] * 4  # 1, 2, 4 and 16 all clip


def test_aces_rolls_highlights_off_instead_of_clipping() -> None:
    out = display_encode(_grey_row(RAMP), "aces")[0, :, 0].astype(int)
    assert out[0] == 0
    assert (np.diff(out) > 0).all()  # monotonic, and 1, 2, 4, 16 stay distinct
    assert out[-1] < 255
    # a filmic curve keeps headroom: scene white (1.0) shows well below display white
    assert out[4] < 255 - 20


def test_aces_keeps_grey_grey() -> None:
    out = display_encode(_grey_row(RAMP), "aces")[0].astype(int)
    assert (np.ptp(out, axis=1) <= 1).all()


def test_unknown_tonemap_is_a_settings_error() -> None:
    with pytest.raises(SettingsError, match="tone map"):
        display_encode(_grey_row(RAMP), "reinhard")
