"""Display encodings of raytrad.io.exr against the sRGB formula and the shape of a filmic curve."""

from __future__ import annotations

import numpy as np
import pytest

from raytrad.errors import SettingsError
from raytrad.io.exr import display_encode

RAMP = np.array([0.0, 0.01, 0.18, 0.5, 1.0, 2.0, 4.0, 16.0])


def _grey(values: np.ndarray) -> np.ndarray:
    return np.repeat(values[None, :, None], 3, axis=2).astype(np.float32)


def _srgb(linear: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 encoding, written out independently of OpenImageIO."""
    c = np.clip(linear, 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)


def test_srgb_encoding_matches_the_standard_formula_and_clips() -> None:
    out = display_encode(_grey(RAMP), "srgb")[0, :, 0]
    np.testing.assert_allclose(out, np.round(_srgb(RAMP) * 255), atol=1)
    assert out[-4:].tolist() == [255] * 4  # 1, 2, 4 and 16 all clip


def test_aces_rolls_highlights_off_instead_of_clipping() -> None:
    out = display_encode(_grey(RAMP), "aces")[0, :, 0].astype(int)
    assert out[0] == 0
    assert (np.diff(out) > 0).all()  # monotonic, and 1, 2, 4, 16 stay distinct
    assert out[-1] < 255
    # a filmic curve keeps headroom: scene white (1.0) shows well below display white
    assert out[4] < 255 - 20


def test_aces_keeps_grey_grey() -> None:
    out = display_encode(_grey(RAMP), "aces")[0].astype(int)
    assert (np.ptp(out, axis=1) <= 1).all()


def test_unknown_tonemap_is_a_settings_error() -> None:
    with pytest.raises(SettingsError, match="tone map"):
        display_encode(_grey(RAMP), "reinhard")
