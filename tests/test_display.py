"""Automatic exposure: the percentile rule, and the key ceiling for flat bright scenes."""

from __future__ import annotations

import math

import numpy as np

from raytrad.display import KEY_CEILING, LUMINANCE_WEIGHTS, auto_exposure, display_colors


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


def test_luminance_weights_sum_to_one() -> None:
    assert math.isclose(LUMINANCE_WEIGHTS.sum(), 1.0)
