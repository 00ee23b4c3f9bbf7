"""Images through OpenImageIO: the only module that imports :mod:`OpenImageIO`.

* :func:`write_exr` writes linear floating-point pixels (half or float) with metadata in
  the OpenEXR header; :func:`write_png` writes 8-bit display images. Both are atomic: the
  image goes to a hidden temporary file in the target's directory (with the target's
  extension, which is how OpenImageIO chooses the format), then replaces the target.
* :func:`dilate` fills texels outside the lightmap charts from their neighbours
  (push-pull), so bilinear filtering and mipmaps never read undefined texels.
* :func:`read_image` reads any image back as float32, :func:`read_attributes` its header.
* :func:`display_transform` applies a display/view transform of OpenImageIO's built-in
  colour management (the filmic ACES curve, say); which one is chosen is decided in
  :mod:`raytrad.products.display`.
"""

from __future__ import annotations

import logging
import os
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from raytrad.formats.atomic import atomic_path

log = logging.getLogger(__name__)

#: Largest finite half-float value; brighter pixels are written as float instead.
HALF_MAX = 65504.0

_CHANNEL_NAMES = {1: ("Y",), 2: ("Y", "A"), 3: ("R", "G", "B"), 4: ("R", "G", "B", "A")}


def write_exr(
    path: str | os.PathLike[str],
    pixels: np.ndarray,
    half: bool = True,
    metadata: Mapping[str, str | float] | None = None,
) -> None:
    """Write an OpenEXR image atomically (ZIP compression, scanlines).

    Parameters
    ----------
    path : path-like
        Target ``.exr`` file; its directory is created if missing.
    pixels : (H, W, C) or (H, W) float
        Linear values, row 0 at the top; C in 1..4 (Y, YA, RGB, RGBA).
    half : bool
        16-bit half floats (about 3 significant digits); pixels beyond
        :data:`HALF_MAX` make the file 32-bit float instead, with a warning.
    metadata : mapping of str to str or float
        Header attributes, written under their given names (``raytrad:units``...);
        ints are stored as ints, other numbers as floats.

    Raises
    ------
    OSError
        OpenImageIO could not write the file (nothing is left at ``path``).
    """
    import OpenImageIO as oiio

    pixels = _as_hwc(pixels)
    height, width, channels = pixels.shape
    if half and np.nanmax(np.abs(pixels), initial=0.0) > HALF_MAX:
        log.warning("%s: values beyond the half-float range; writing 32-bit floats", path)
        half = False
    spec = oiio.ImageSpec(width, height, channels, oiio.HALF if half else oiio.FLOAT)
    spec.channelnames = _CHANNEL_NAMES[channels]
    spec.attribute("compression", "zip")
    for name, value in (metadata or {}).items():
        spec.attribute(name, _attribute_value(value))
    with atomic_path(path) as temporary:
        _write_file(temporary, pixels.astype(np.float32), spec)


def write_png(path: str | os.PathLike[str], rgb8: np.ndarray) -> None:
    """Write an 8-bit PNG atomically.

    Parameters
    ----------
    path : path-like
        Target ``.png`` file; its directory is created if missing.
    rgb8 : (H, W, C) or (H, W) uint8
        Display-encoded (sRGB) values, row 0 at the top; C in 1..4.
    """
    import OpenImageIO as oiio

    rgb8 = _as_hwc(rgb8)
    if rgb8.dtype != np.uint8:
        raise TypeError(f"write_png takes uint8 pixels, not {rgb8.dtype}")
    height, width, channels = rgb8.shape
    spec = oiio.ImageSpec(width, height, channels, oiio.UINT8)
    spec.channelnames = _CHANNEL_NAMES[channels]
    spec.attribute("oiio:ColorSpace", "sRGB")
    with atomic_path(path) as temporary:
        _write_file(temporary, rgb8, spec)


def encode_png(rgb8: np.ndarray) -> bytes:
    """The bytes of an 8-bit PNG (to embed in a glTF file, say); see :func:`write_png`."""
    with tempfile.TemporaryDirectory() as directory:
        path = Path(directory) / "image.png"
        write_png(path, rgb8)
        return path.read_bytes()


def read_image(path: str | os.PathLike[str]) -> np.ndarray:
    """Read an image as float32.

    Returns
    -------
    (H, W, C) float32
        Values as stored (8-bit files scaled to [0, 1]), row 0 at the top.

    Raises
    ------
    OSError
        The file cannot be opened or read.
    """
    import OpenImageIO as oiio

    image = _open(path)
    try:
        spec = image.spec()
        pixels = image.read_image(oiio.FLOAT)
        if pixels is None:
            raise OSError(f"{path}: {image.geterror()}")
    finally:
        image.close()
    return np.asarray(pixels, dtype=np.float32).reshape(spec.height, spec.width, -1)


def read_attributes(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Header attributes of an image by name (``compression``, ``raytrad:units``...).

    Raises
    ------
    OSError
        The file cannot be opened.
    """
    image = _open(path)
    try:
        return {a.name: a.value for a in image.spec().extra_attribs}
    finally:
        image.close()


def _open(path: str | os.PathLike[str]) -> Any:
    import OpenImageIO as oiio

    image = oiio.ImageInput.open(os.fspath(path))
    if image is None:
        raise OSError(f"{path}: {oiio.geterror()}")
    return image


def dilate(pixels: np.ndarray, coverage: np.ndarray) -> np.ndarray:
    """Fill uncovered texels from the covered ones around them (push-pull).

    OpenImageIO's ``fillholes_pushpull`` averages covered texels into coarser and coarser
    levels, then pulls the averages back into every hole: texels next to a chart get
    values of that chart, far ones a smooth blend. Covered texels are kept exactly.

    Parameters
    ----------
    pixels : (H, W, C) float
        Values; those of uncovered texels are ignored.
    coverage : (H, W) bool
        True where a texel holds a value.

    Returns
    -------
    (H, W, C) float32
        ``pixels`` with every texel defined (all zero when nothing is covered).
    """
    import OpenImageIO as oiio

    pixels = _as_hwc(pixels)
    height, width, channels = pixels.shape
    coverage = np.asarray(coverage, dtype=bool)
    if coverage.shape != (height, width):
        raise ValueError(f"coverage {coverage.shape} does not match pixels {pixels.shape}")
    if not coverage.any():
        return np.zeros(pixels.shape, dtype=np.float32)
    alpha = coverage.astype(np.float32)[..., None]
    premultiplied = np.concatenate([np.where(alpha > 0, pixels, 0.0), alpha], axis=2)
    spec = oiio.ImageSpec(width, height, channels + 1, oiio.FLOAT)
    spec.channelnames = (*tuple(f"c{k}" for k in range(channels)), "A")
    spec.alpha_channel = channels
    source = oiio.ImageBuf(spec)
    source.set_pixels(oiio.ROI(), np.ascontiguousarray(premultiplied, dtype=np.float32))
    filled = oiio.ImageBufAlgo.fillholes_pushpull(source)
    if filled.has_error:
        raise RuntimeError(f"push-pull dilation failed: {filled.geterror()}")
    result = np.asarray(filled.get_pixels(oiio.FLOAT), dtype=np.float32)
    result = result.reshape(height, width, channels + 1)
    # every texel ends with alpha 1, so the premultiplied colour is the colour
    return np.ascontiguousarray(result[..., :channels])


def _write_file(path: Path, pixels: np.ndarray, spec: Any) -> None:
    """Write ``pixels`` with ``spec`` to ``path``, raising OSError on failure."""
    import OpenImageIO as oiio

    output = oiio.ImageOutput.create(str(path))
    if output is None:
        raise OSError(f"{path}: {oiio.geterror()}")
    try:
        if not output.open(str(path), spec):
            raise OSError(f"{path}: {output.geterror()}")
        if not output.write_image(np.ascontiguousarray(pixels)):
            raise OSError(f"{path}: {output.geterror()}")
    finally:
        output.close()


def _as_hwc(pixels: np.ndarray) -> np.ndarray:
    pixels = np.asarray(pixels)
    if pixels.ndim == 2:
        pixels = pixels[..., None]
    if pixels.ndim != 3 or pixels.shape[2] not in _CHANNEL_NAMES:
        raise ValueError(f"pixels must be (H, W) or (H, W, 1..4), not {pixels.shape}")
    return pixels


def _attribute_value(value: object) -> str | int | float:
    if isinstance(value, bool | np.bool_):
        return int(value)
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return float(value)
    if isinstance(value, str):
        return value
    raise TypeError(f"metadata values must be str or numbers, not {type(value).__name__}")


def display_transform(pixels: np.ndarray, display: str, view: str, space: str) -> np.ndarray:
    """Apply an OCIO display/view transform of OpenImageIO's built-in colour configuration.

    Parameters
    ----------
    pixels : (H, W, C) float
        Values in colour space ``space`` (for example ``"Linear Rec.709 (sRGB)"``).
    display, view : str
        The display and view of the configuration (for example ``"sRGB - Display"`` and
        an ACES output transform from :func:`display_views`).
    space : str
        Colour space of ``pixels``.

    Returns
    -------
    (H, W, C) float32
        Display-encoded values, nominally in [0, 1].

    Raises
    ------
    RuntimeError
        OpenImageIO could not apply the transform.
    """
    import OpenImageIO as oiio

    pixels = np.ascontiguousarray(pixels, dtype=np.float32)
    encoded = oiio.ImageBufAlgo.ociodisplay(oiio.ImageBuf(pixels), display, view, space)
    if encoded.has_error:
        raise RuntimeError(f"OpenImageIO colour conversion failed: {encoded.geterror()}")
    return np.asarray(encoded.get_pixels(oiio.FLOAT), dtype=np.float32).reshape(pixels.shape)


def display_views(display: str) -> list[str]:
    """The view names OpenImageIO's built-in colour configuration offers for ``display``."""
    import OpenImageIO as oiio

    return [str(v) for v in oiio.ColorConfig().getViewNames(display)]
