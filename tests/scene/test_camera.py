"""Cameras: an orthonormal frame, and degenerate views refused with tolerances scaled to
their coordinates (so a camera far from the origin is not refused for rounding)."""

from __future__ import annotations

import numpy as np
import pytest

from raytrad.errors import SettingsError
from raytrad.scene import Camera


def test_basis_is_orthonormal_and_right_handed() -> None:
    right, up, forward = Camera((0, 0, 0), (1, 2, 3), (0, 1, 0)).basis()
    frame = np.stack([right, up, forward])
    np.testing.assert_allclose(frame @ frame.T, np.eye(3), atol=1e-15)
    np.testing.assert_allclose(np.cross(right, up), -forward, atol=1e-15)


def test_far_from_the_origin_a_short_view_is_a_view() -> None:
    camera = Camera((5e8, 0.0, 0.0), (5e8 + 1e-3, 0.0, 0.0), (0.0, 1.0, 0.0))
    assert camera.basis()[2].tolist() == [1.0, 0.0, 0.0]


@pytest.mark.parametrize(
    ("position", "look_at", "up"),
    [
        ((1.0, 2.0, 3.0), (1.0, 2.0, 3.0), (0.0, 1.0, 0.0)),  # no direction
        ((1e9, 0.0, 0.0), (1e9 + 1e-7, 0.0, 0.0), (0.0, 1.0, 0.0)),  # below rounding there
        ((0.0, 0.0, 0.0), (0.0, 5.0, 0.0), (0.0, 2.0, 1e-12)),  # up along the view
        ((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, 0.0, 0.0)),  # no up
    ],
)
def test_degenerate_views_are_refused(
    position: tuple[float, float, float],
    look_at: tuple[float, float, float],
    up: tuple[float, float, float],
) -> None:
    with pytest.raises(SettingsError):
        Camera(position, look_at, up)


@pytest.mark.parametrize("fov", [0.0, 180.0, -5.0])
def test_field_of_view_must_be_open(fov: float) -> None:
    with pytest.raises(SettingsError, match="field of view"):
        Camera((0, 0, 0), (0, 0, 1), vertical_fov_deg=fov)
