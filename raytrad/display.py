"""Display colours for per-vertex radiosity: exposure, then the sRGB transfer function."""

from __future__ import annotations

import math

import numpy as np

#: Rec. 709 / sRGB luminance weights of linear RGB.
LUMINANCE_WEIGHTS = np.array([0.2126, 0.7152, 0.0722])


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 sRGB encoding of linear values in [0, 1] (clipped first)."""
    c = np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1.0 / 2.4) - 0.055)


def auto_exposure(radiosity: np.ndarray, emitting: np.ndarray) -> float:
    """Scale that maps the 97th percentile of the receivers' radiance luminance to 1.

    Parameters
    ----------
    radiosity : (R, 3) float64 [W m-2]
    emitting : (R,) bool
        Emitters are left out so a bright lamp does not darken the room.

    Returns
    -------
    float, multiplier of radiance [m2 sr W-1]; 1 for an all-black scene.
    """
    lit = radiosity[~emitting] if (~emitting).any() else radiosity
    luminance = (lit / math.pi) @ LUMINANCE_WEIGHTS
    key = float(np.percentile(luminance, 97.0)) if len(luminance) else 0.0
    return 1.0 / key if key > 0 else 1.0


def display_colors(
    radiosity: np.ndarray, emitting: np.ndarray, exposure_stops: float = 0.0
) -> np.ndarray:
    """8-bit sRGB display colours of per-vertex radiosity.

    Parameters
    ----------
    radiosity : (R, 3) float64 [W m-2]
    emitting : (R,) bool
    exposure_stops : float
        Brightening on top of the automatic exposure [EV].

    Returns
    -------
    (R, 3) uint8
    """
    scale = auto_exposure(radiosity, emitting) * 2.0**exposure_stops
    encoded = srgb_encode(radiosity / math.pi * scale)
    return np.round(encoded * 255.0).astype(np.uint8)
