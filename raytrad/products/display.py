"""What is shown of a solve: exposure, tone mapping and display encoding of radiosity (the
radiosity shown where the solve hid receivers is :func:`raytrad.core.hidden.fill_hidden`).

These decide how radiance becomes 8-bit display values for every product (PLY colours,
lightmap previews, camera images, glTF colours). The colour arithmetic they use, luminance
weights and the sRGB transfer function, lives in :mod:`raytrad.scene.colorimetry`; the
filmic curve comes from OpenImageIO's colour management (:mod:`raytrad.formats.images`).
"""

from __future__ import annotations

import math

import numpy as np

from raytrad.errors import SettingsError
from raytrad.formats import images
from raytrad.scene.colorimetry import LUMINANCE_WEIGHTS, srgb_encode

#: Where the scene's key (area-weighted log-average luminance) may sit at most, as a
#: fraction of display white.
KEY_CEILING = 0.4

#: Display encodings of :func:`display_encode`.
TONEMAPS = ("srgb", "aces")

#: OpenImageIO's built-in colour configuration: display, scene-linear space, and the prefix
#: of the ACES output transform's view name (its version differs between releases).
_DISPLAY, _LINEAR, _ACES_VIEW = "sRGB - Display", "Linear Rec.709 (sRGB)", "ACES"


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
    luminance = (radiosity[keep] / math.pi) @ np.asarray(LUMINANCE_WEIGHTS)
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
    return display_encode(radiosity / math.pi * scale)


def display_encode(linear: np.ndarray, tonemap: str = "srgb") -> np.ndarray:
    """8-bit display values of exposed linear Rec. 709 values.

    Parameters
    ----------
    linear : (..., 3) float
        Scene-linear values, already multiplied by the exposure [1].
    tonemap : str
        ``"srgb"``: clipped to [0, 1], then sRGB-encoded (IEC 61966-2-1);
        ``"aces"``: the ACES SDR output transform of OpenImageIO's built-in OCIO
        configuration for an sRGB display, a filmic curve that rolls highlights off
        instead of clipping them (1.0 shows as about 0.71, 16 as 0.97).

    Returns
    -------
    (..., 3) uint8
    """
    if tonemap not in TONEMAPS:
        raise SettingsError(f"tone map must be one of {', '.join(TONEMAPS)}, not {tonemap!r}")
    if tonemap == "srgb":
        encoded = srgb_encode(linear)
    else:
        pixels = np.maximum(np.asarray(linear, dtype=np.float32), 0.0)
        shape = pixels.shape
        image = pixels.reshape(-1, 1, 3) if pixels.ndim != 3 else pixels
        encoded = images.display_transform(image, _DISPLAY, _aces_view(), _LINEAR).reshape(shape)
    return np.round(np.clip(encoded, 0.0, 1.0) * 255.0).astype(np.uint8)


def _aces_view() -> str:
    """The ACES SDR view of the built-in configuration's sRGB display."""
    views = [v for v in images.display_views(_DISPLAY) if v.startswith(_ACES_VIEW)]
    sdr = [v for v in views if "SDR" in v] or views
    if not sdr:
        raise SettingsError("this OpenImageIO build has no ACES view for an sRGB display")
    return sdr[0]
