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


#: Where the scene's key (area-weighted log-average luminance) may sit at most, as a
#: fraction of display white.
KEY_CEILING = 0.4


def auto_exposure(
    radiosity: np.ndarray, emitting: np.ndarray, area: np.ndarray | None = None
) -> float:
    """Scale of radiance for display: the 97th percentile of the receivers' radiance
    luminance maps to 1, unless that puts the scene's key above :data:`KEY_CEILING`.

    The percentile rule shows a contrasty scene (a lit room with shadows) with its bright
    surfaces just below white; a flat, uniformly bright one (a white room, a furnace)
    would come out nearly all white, so its key, the area-weighted log-average
    luminance, is held at ``KEY_CEILING`` instead.

    Parameters
    ----------
    radiosity : (R, 3) float64 [W m-2]
    emitting : (R,) bool
        Emitters are left out so a bright lamp does not darken the room.
    area : (R,) float or None
        Receiver areas [m2] for the key; zero-area (hidden) receivers are left out. None:
        every receiver weighs the same.

    Returns
    -------
    float, multiplier of radiance [m2 sr W-1]; 1 for an all-black scene.
    """
    keep = ~np.asarray(emitting, dtype=bool)
    if area is not None:
        keep &= np.asarray(area) > 0
    if not keep.any():
        keep = np.ones(len(radiosity), dtype=bool)
    luminance = (radiosity[keep] / math.pi) @ LUMINANCE_WEIGHTS
    weight = np.ones(len(luminance)) if area is None else np.asarray(area)[keep]
    white = float(np.percentile(luminance, 97.0)) if len(luminance) else 0.0
    if white <= 0:
        return 1.0
    lit = (luminance > 0) & (weight > 0)
    if not lit.any():
        return 1.0 / white
    key = math.exp(float(np.average(np.log(luminance[lit]), weights=weight[lit])))
    return min(1.0 / white, KEY_CEILING / key)


def display_colors(
    radiosity: np.ndarray,
    emitting: np.ndarray,
    exposure_stops: float = 0.0,
    area: np.ndarray | None = None,
) -> np.ndarray:
    """8-bit sRGB display colours of per-vertex radiosity.

    Parameters
    ----------
    radiosity : (R, 3) float64 [W m-2]
    emitting : (R,) bool
    exposure_stops : float
        Brightening on top of the automatic exposure [EV].
    area : (R,) float or None
        Receiver areas [m2] (see :func:`auto_exposure`).

    Returns
    -------
    (R, 3) uint8
    """
    scale = auto_exposure(radiosity, emitting, area) * 2.0**exposure_stops
    encoded = srgb_encode(radiosity / math.pi * scale)
    return np.round(encoded * 255.0).astype(np.uint8)
