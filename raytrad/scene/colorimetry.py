"""Colorimetry: spectra, colour temperatures, photometric units, luminance and sRGB encoding.

The only module that imports colour-science, and only inside the functions that need it,
so that a scene given in RGB numbers never pays for (or needs) that import. The photometric
conversions (:func:`exitance_from_power`, :func:`exitance_from_flux`, :func:`luminance`),
explicit RGB emitter colours and the sRGB transfer functions (:func:`srgb_encode`,
:func:`srgb_decode`, shared by the PLY reader and every display colour) are plain
arithmetic and import nothing.

Working space: linear (no transfer function) RGB with the sRGB / ITU-R BT.709 primaries and
the CIE D65 white point, the space raytrad's reflectance [1] and emitted exitance [W m-2]
channels live in. Spectral quantities are integrated against the CIE 1931 2° standard
observer.

Units: wavelengths [nm]; reflectance [1]; temperature [K]; radiant power [W]; luminous flux
[lm]; exitance [W m-2]. RGB exitance is in "W-equivalent" units: a channel triple E has the
luminous exitance ``LUMINOUS_EFFICACY * luminance(E)`` [lm m-2].
"""

from __future__ import annotations

import logging
import math
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from functools import lru_cache
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

if TYPE_CHECKING:
    import colour

log = logging.getLogger(__name__)

WORKING_SPACE = "sRGB"
"""colour-science's name of the working space: BT.709 primaries, D65 white (used linear)."""

OBSERVER = "CIE 1931 2 Degree Standard Observer"
"""The colour-matching functions spectra are integrated against."""

CHROMATIC_ADAPTATION = "CAT02"
"""Transform taking reflectance colours seen under another illuminant to the D65 white."""

COLOURCHECKER = "BabelColor Average"
"""The ColorChecker data set :func:`named_reflectance` reads by default."""

LUMINANCE_WEIGHTS = (0.2126, 0.7152, 0.0722)
"""Luminance Y of linear BT.709 RGB (the middle row of the sRGB RGB-to-XYZ matrix) [1]."""

LUMINOUS_EFFICACY = 683.0
"""Maximum luminous efficacy of radiation, at 555 nm (540 THz) [lm W-1]."""


# --------------------------------------------------------------------------- helpers


def luminance(rgb: ArrayLike) -> np.ndarray:
    """Luminance Y of linear working-space RGB.

    Parameters
    ----------
    rgb : (..., 3) float
        Linear RGB, any unit.

    Returns
    -------
    (...) float64
        ``0.2126 R + 0.7152 G + 0.0722 B``, in the unit of ``rgb``.
    """
    return np.asarray(rgb, dtype=np.float64) @ np.asarray(LUMINANCE_WEIGHTS)


def _triple(rgb: ArrayLike, what: str) -> np.ndarray:
    """(..., 3) float64 from RGB that must be finite and >= 0; ValueError otherwise."""
    array = np.asarray(rgb, dtype=np.float64)
    if array.ndim == 0:
        array = np.full(3, float(array))
    if array.shape[-1] != 3:
        raise ValueError(f"{what} must have 3 channels, got shape {array.shape}")
    if not np.isfinite(array).all() or (array < 0).any():
        raise ValueError(f"{what} must be finite and >= 0, got {array.tolist()}")
    return array


def _positive(value: ArrayLike, what: str, allow_zero: bool = False) -> np.ndarray:
    """Float64 array that must be finite and > 0 (or >= 0); ValueError otherwise."""
    array = np.asarray(value, dtype=np.float64)
    bad = ~np.isfinite(array) | (array < 0 if allow_zero else array <= 0)
    if bad.any():
        bound = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{what} must be finite and {bound}, got {array.tolist()}")
    return array


def _lookup(mapping: Any, name: str, what: str) -> Any:
    """``mapping[name]``, case-insensitively; ValueError listing a few valid names."""
    by_lower = {str(key).lower(): key for key in mapping}
    key = by_lower.get(str(name).strip().lower())
    if key is None:
        names = [str(k) for k in mapping]
        shown = ", ".join(repr(n) for n in names[:8])
        more = f" and {len(names) - 8} more" if len(names) > 8 else ""
        raise ValueError(f"unknown {what} {name!r}; valid names include {shown}{more}")
    return mapping[key]


@contextmanager
def _aligning_quietly() -> Iterator[None]:
    """Silence colour-science's notes that it aligned or trimmed spectral shapes.

    Aligning a 10 nm spectrum to the 1 nm observer is what every conversion here does;
    a warning per call would bury the ones that matter.
    """
    from colour.utilities import ColourRuntimeWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ColourRuntimeWarning)
        yield


# --------------------------------------------------------------------------- reflectance

_ASTM_E308_INTERVALS = (1.0, 5.0, 10.0, 20.0)
_ASTM_E308_SAMPLES = 6
"""The fewest samples colour-science's ASTM E308 integration takes."""
_VISIBLE_NM = (380.0, 780.0)
"""Wavelengths a reflectance spectrum must overlap [nm]."""
_CMF_NM = (360, 830)
"""The range of the CIE 1931 colour-matching functions [nm]."""


def _spectral_domain(wavelengths_nm: ArrayLike, values: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Validated wavelengths (n,) and values (..., n), on a grid ASTM E308 accepts.

    At least 6 samples at a regular 1, 5, 10 or 20 nm interval are kept; any other
    sampling is resampled linearly to whole nanometres over at least 360-830 nm
    (held constant beyond its ends). Wavelengths must overlap 380-780 nm (ValueError).
    """
    wavelengths = np.asarray(wavelengths_nm, dtype=np.float64)
    spectrum = np.asarray(values, dtype=np.float64)
    if wavelengths.ndim != 1 or len(wavelengths) < 2:
        raise ValueError("wavelengths must be a list of at least 2 numbers")
    if spectrum.ndim == 0 or spectrum.shape[-1] != len(wavelengths):
        raise ValueError(
            f"values must have one entry per wavelength ({len(wavelengths)}), "
            f"got shape {spectrum.shape}"
        )
    if not (np.isfinite(wavelengths).all() and (wavelengths > 0).all()):
        raise ValueError("wavelengths must be finite and > 0 [nm]")
    steps = np.diff(wavelengths)
    if (steps <= 0).any():
        raise ValueError("wavelengths must increase strictly")
    if not np.isfinite(spectrum).all():
        raise ValueError("values must be finite")
    if wavelengths[-1] <= _VISIBLE_NM[0] or wavelengths[0] >= _VISIBLE_NM[1]:
        raise ValueError(
            f"wavelengths {wavelengths[0]:g}-{wavelengths[-1]:g} nm must overlap "
            f"{_VISIBLE_NM[0]:g}-{_VISIBLE_NM[1]:g} nm"
        )
    regular = np.allclose(steps, steps[0], rtol=0.0, atol=1e-9)
    enough = len(wavelengths) >= _ASTM_E308_SAMPLES
    if enough and regular and any(math.isclose(steps[0], s) for s in _ASTM_E308_INTERVALS):
        return wavelengths, spectrum
    # Whole nanometres over the colour-matching functions' range at least, so that a
    # narrow or partial spectrum still has the samples ASTM E308 integration needs.
    grid = np.arange(
        min(math.floor(wavelengths[0]), _CMF_NM[0]),
        max(math.ceil(wavelengths[-1]), _CMF_NM[1]) + 1.0,
    )
    rows = spectrum.reshape(-1, len(wavelengths))
    resampled = np.stack([np.interp(grid, wavelengths, row) for row in rows])
    return grid, resampled.reshape(*spectrum.shape[:-1], len(grid))


def _reflectance_xyz(
    wavelengths: np.ndarray, spectrum: np.ndarray, illuminant: colour.SpectralDistribution
) -> np.ndarray:
    """(..., 3) CIE XYZ [1] of reflectance spectra (..., n) under an illuminant (Y_white = 1)."""
    import colour

    cmfs = colour.MSDS_CMFS[OBSERVER]
    rows = spectrum.reshape(-1, len(wavelengths))
    xyz = np.empty((len(rows), 3))
    with _aligning_quietly():
        # One SpectralDistribution per row: MultiSpectralDistributions interpolates
        # differently (1e-5), and a spectrum must not depend on its neighbours.
        for i, row in enumerate(rows):
            sd = colour.SpectralDistribution(row, wavelengths)
            xyz[i] = colour.sd_to_XYZ(sd, cmfs, illuminant)
    return xyz.reshape(*spectrum.shape[:-1], 3) / 100.0


@lru_cache(maxsize=16)
def _illuminant(name: str) -> tuple[colour.SpectralDistribution, tuple[float, float, float]]:
    """An illuminant's spectral distribution and the XYZ [1] of the perfect white under it."""
    import colour

    sd = _lookup(colour.SDS_ILLUMINANTS, name, "illuminant")
    cmfs = colour.MSDS_CMFS[OBSERVER]
    with _aligning_quietly():
        xyz = np.asarray(colour.sd_to_XYZ(colour.sd_ones(cmfs.shape), cmfs, sd)) / 100.0
    return sd, (float(xyz[0]), float(xyz[1]), float(xyz[2]))


def reflectance_to_rgb(
    wavelengths_nm: ArrayLike, values: ArrayLike, illuminant: str = "D65"
) -> np.ndarray:
    """Linear working-space RGB reflectance of reflectance spectra seen under an illuminant.

    The spectrum is integrated under the illuminant with the CIE 1931 2° observer (ASTM
    E308 through ``colour.sd_to_XYZ``), adapted from the illuminant's white to D65 (CAT02)
    and converted to linear BT.709 RGB; each channel is then divided by that of the perfect
    white reflector, so the white maps to exactly (1, 1, 1) and a flat spectrum of value
    ``r`` to exactly (r, r, r). The map is linear in ``values``.

    Parameters
    ----------
    wavelengths_nm : (n,) float
        Sample wavelengths, strictly increasing [nm]. A regular 1, 5, 10 or 20 nm sampling
        is used as is, any other is interpolated linearly to 1 nm; values are held constant
        beyond the first and last sample.
    values : (..., n) float
        Spectral reflectance at each wavelength [1], one spectrum per leading index.
    illuminant : str
        A name of ``colour.SDS_ILLUMINANTS`` ("D65", "A", "FL2", ...), case-insensitive.

    Returns
    -------
    (..., 3) float64
        Linear RGB reflectance [1]. Saturated spectra outside the BT.709 gamut give channels
        below 0 (or above 1); they are not clipped here.

    Raises
    ------
    ValueError
        Malformed or non-finite samples, or an unknown illuminant.

    Examples
    --------
    >>> reflectance_to_rgb([400.0, 700.0], [0.5, 0.5])  # doctest: +SKIP
    array([ 0.5,  0.5,  0.5])
    """
    import colour

    wavelengths, spectrum = _spectral_domain(wavelengths_nm, values)
    sd_illuminant, white_xyz = _illuminant(illuminant)
    white_xy = colour.XYZ_to_xy(np.asarray(white_xyz))

    def to_rgb(xyz: np.ndarray) -> np.ndarray:
        return np.asarray(
            colour.XYZ_to_RGB(
                xyz,
                WORKING_SPACE,
                illuminant=white_xy,
                chromatic_adaptation_transform=CHROMATIC_ADAPTATION,
            )
        )

    with _aligning_quietly():
        rgb = to_rgb(_reflectance_xyz(wavelengths, spectrum, sd_illuminant))
        return rgb / to_rgb(np.asarray(white_xyz))


def named_reflectance(name: str, dataset: str = COLOURCHECKER) -> tuple[np.ndarray, np.ndarray]:
    """The measured reflectance spectrum of a colour-chart patch.

    Parameters
    ----------
    name : str
        The patch, case-insensitive, for example "dark skin", "blue sky", "red",
        "white 9.5 (.05 D)" or "neutral 5 (.70 D)".
    dataset : str
        A key of ``colour.SDS_COLOURCHECKERS``; default the BabelColor average of the
        X-Rite ColorChecker Classic.

    Returns
    -------
    wavelengths_nm : (n,) float64
        [nm].
    values : (n,) float64
        Spectral reflectance [1]; pass both to :func:`reflectance_to_rgb`.

    Raises
    ------
    ValueError
        Unknown patch or data set, listing some valid names.
    """
    import colour

    patches = _lookup(colour.SDS_COLOURCHECKERS, dataset, "ColorChecker data set")
    sd = _lookup(patches, name, f"{dataset} patch")
    return np.array(sd.wavelengths, dtype=np.float64), np.array(sd.values, dtype=np.float64)


def reflectance_names(dataset: str = COLOURCHECKER) -> tuple[str, ...]:
    """The patch names :func:`named_reflectance` accepts for ``dataset``."""
    import colour

    return tuple(str(k) for k in _lookup(colour.SDS_COLOURCHECKERS, dataset, "data set"))


# --------------------------------------------------------------------------- emitter colours


def _normalised(rgb: np.ndarray, what: str) -> np.ndarray:
    """(3,) float64 ``rgb`` with negative channels clipped (warned) and luminance Y = 1."""
    if (rgb < 0).any():
        shown = rgb / y if (y := float(luminance(rgb))) > 0 else rgb
        log.warning(
            "%s is outside the BT.709 gamut (RGB %s at Y = 1); negative channels clipped to 0",
            what,
            np.round(shown, 4).tolist(),
        )
        rgb = np.maximum(rgb, 0.0)
    y = float(luminance(rgb))
    if not (math.isfinite(y) and y > 0):
        raise ValueError(f"{what} has no luminance (RGB {rgb.tolist()})")
    return rgb / y


def _spectrum_rgb(sd: colour.SpectralDistribution) -> np.ndarray:
    """(3,) working-space RGB of an emission spectrum, any scale (no chromatic adaptation)."""
    import colour

    cmfs = colour.MSDS_CMFS[OBSERVER]
    with _aligning_quietly():
        xyz = np.asarray(colour.sd_to_XYZ(sd, cmfs))
    matrix = np.asarray(colour.RGB_COLOURSPACES[WORKING_SPACE].matrix_XYZ_to_RGB)
    return np.asarray(matrix @ xyz, dtype=np.float64)


def blackbody_rgb(temperature_k: float) -> np.ndarray:
    """Colour of a Planckian radiator (``colour.sd_blackbody``, Planck's law).

    Parameters
    ----------
    temperature_k : float
        Colour temperature [K], > 0; around 1000 K and below the colour leaves the BT.709
        gamut and is clipped (with a warning).

    Returns
    -------
    (3,) float64
        Linear working-space RGB [1] with luminance Y = 1.
    """
    import colour

    temperature = float(_positive(temperature_k, "temperature_k"))
    with _aligning_quietly():
        sd = colour.sd_blackbody(temperature, colour.MSDS_CMFS[OBSERVER].shape)
    return _normalised(_spectrum_rgb(sd), f"a {temperature:g} K blackbody")


def illuminant_rgb(name: str) -> np.ndarray:
    """Colour of a CIE or other standard illuminant of ``colour.SDS_ILLUMINANTS``.

    Parameters
    ----------
    name : str
        "D65", "D50", "A", "FL2", "LED-B1", ... (case-insensitive).

    Returns
    -------
    (3,) float64
        Linear working-space RGB [1] with luminance Y = 1; D65 is (1, 1, 1) to 1e-4.
    """
    import colour

    sd = _lookup(colour.SDS_ILLUMINANTS, name, "illuminant")
    return _normalised(_spectrum_rgb(sd), f"illuminant {name!r}")


def relative_rgb(rgb: ArrayLike) -> np.ndarray:
    """An explicit linear RGB emitter colour scaled to luminance Y = 1.

    Parameters
    ----------
    rgb : (3,) float
        Linear working-space RGB, >= 0 and not black; any scale.

    Returns
    -------
    (3,) float64
        ``rgb / luminance(rgb)`` [1].
    """
    return _normalised(_triple(rgb, "colour"), "colour")


EMITTER_COLOURS: dict[str, Callable[[Any], np.ndarray]] = {
    "temperature_k": blackbody_rgb,
    "illuminant": illuminant_rgb,
    "colour": relative_rgb,
}
"""Ways to give an emitter's colour, by the scene-file key that selects them."""

SPECTRAL_EMITTER_COLOURS = frozenset({"temperature_k", "illuminant"})
"""The :data:`EMITTER_COLOURS` kinds that need colour-science."""


def emitter_rgb(kind: str, value: Any) -> np.ndarray:
    """Emission colour as a linear RGB chromaticity of unit luminance.

    Parameters
    ----------
    kind : str
        One of :data:`EMITTER_COLOURS`: ``"temperature_k"`` (``value`` a blackbody colour
        temperature [K]), ``"illuminant"`` (``value`` a name of ``colour.SDS_ILLUMINANTS``)
        or ``"colour"`` (``value`` an explicit (3,) linear RGB, any scale).
    value : float, str or (3,) float
        As ``kind`` says.

    Returns
    -------
    (3,) float64
        Linear working-space RGB [1] with luminance ``0.2126 R + 0.7152 G + 0.0722 B = 1``;
        negative (out-of-gamut) channels are clipped to 0 with a warning. No chromatic
        adaptation: a 3000 K light is orange against the D65 white.

    Raises
    ------
    ValueError
        Unknown kind, unknown illuminant, or a value that has no colour.
    """
    method = EMITTER_COLOURS.get(kind)
    if method is None:
        raise ValueError(
            f"unknown emitter colour kind {kind!r}; use one of {', '.join(EMITTER_COLOURS)}"
        )
    return method(value)


# --------------------------------------------------------------------------- sRGB


def srgb_encode(linear: ArrayLike) -> np.ndarray:
    """IEC 61966-2-1 sRGB encoding of linear values, clipped to [0, 1] first.

    Parameters
    ----------
    linear : (...) float
        Linear values [1].

    Returns
    -------
    (...) float64
        Encoded values in [0, 1].
    """
    c = np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1.0 / 2.4) - 0.055)


def srgb_decode(encoded: ArrayLike) -> np.ndarray:
    """Linear values from IEC 61966-2-1 sRGB-encoded ones.

    Parameters
    ----------
    encoded : (...) float
        sRGB-encoded values in [0, 1].

    Returns
    -------
    (...) float64
        Linear values in [0, 1].
    """
    c = np.asarray(encoded, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


# --------------------------------------------------------------------------- photometry


def exitance_from_power(power_w: ArrayLike, area_m2: ArrayLike, rgb: ArrayLike) -> np.ndarray:
    """Emitted exitance of a Lambertian emitter of given radiant power.

    Convention: the mean over the three channels of the emitted power is the radiant power,
    ``mean_c(E_c) * A = P``, so ``E_c = P / A * rgb_c / mean(rgb)``. A grey emitter
    (``rgb`` = (1, 1, 1)) has exitance P / A in every channel.

    Parameters
    ----------
    power_w : (...) float
        Radiant power leaving the emitting surface, >= 0 [W].
    area_m2 : (...) float
        Emitting area, > 0 [m2] (both sides for a double-sided emitter).
    rgb : (..., 3) float
        Emitter colour, linear RGB >= 0 and not black, any scale.

    Returns
    -------
    (..., 3) float64
        Emitted exitance per channel [W m-2].

    Raises
    ------
    ValueError
        Negative or non-finite power, area <= 0, negative or black colour.
    """
    power = _positive(power_w, "power_w", allow_zero=True)
    area = _positive(area_m2, "area_m2")
    colour_rgb = _triple(rgb, "rgb")
    mean = _positive(colour_rgb.mean(axis=-1), "mean of rgb")
    return (power / area)[..., None] * colour_rgb / mean[..., None]


def exitance_from_flux(flux_lm: ArrayLike, area_m2: ArrayLike, rgb: ArrayLike) -> np.ndarray:
    """Emitted exitance of a Lambertian emitter of given luminous flux.

    The luminous exitance of RGB exitance E is ``683 lm W-1 * luminance(E)`` [lm m-2] (the
    channels are W-equivalent at the 555 nm maximum efficacy), so
    ``E_c = flux / (683 A) * rgb_c / luminance(rgb)``.

    Parameters
    ----------
    flux_lm : (...) float
        Luminous flux leaving the emitting surface, >= 0 [lm].
    area_m2 : (...) float
        Emitting area, > 0 [m2] (both sides for a double-sided emitter).
    rgb : (..., 3) float
        Emitter colour, linear RGB >= 0 with luminance > 0, any scale.

    Returns
    -------
    (..., 3) float64
        Emitted exitance per channel [W m-2].

    Raises
    ------
    ValueError
        Negative or non-finite flux, area <= 0, negative colour or one without luminance.
    """
    flux = _positive(flux_lm, "flux_lm", allow_zero=True)
    area = _positive(area_m2, "area_m2")
    colour_rgb = _triple(rgb, "rgb")
    y = _positive(luminance(colour_rgb), "luminance of rgb")
    return (flux / (LUMINOUS_EFFICACY * area))[..., None] * colour_rgb / y[..., None]


__all__ = [
    "CHROMATIC_ADAPTATION",
    "COLOURCHECKER",
    "EMITTER_COLOURS",
    "LUMINANCE_WEIGHTS",
    "LUMINOUS_EFFICACY",
    "OBSERVER",
    "SPECTRAL_EMITTER_COLOURS",
    "WORKING_SPACE",
    "blackbody_rgb",
    "emitter_rgb",
    "exitance_from_flux",
    "exitance_from_power",
    "illuminant_rgb",
    "luminance",
    "named_reflectance",
    "reflectance_names",
    "reflectance_to_rgb",
    "relative_rgb",
    "srgb_decode",
    "srgb_encode",
]
