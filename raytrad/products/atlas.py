"""Lightmap UV atlases from xatlas: the only module that imports :mod:`xatlas`, lazily.

xatlas cuts a triangle mesh into charts, flattens each chart and packs the charts into
one rectangle. Its texel coordinates put texel ``i`` over ``[i, i + 1]``; the UVs returned
here are those coordinates divided by the atlas width and height, in [0, 1].
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np

from raytrad.errors import SettingsError

log = logging.getLogger(__name__)

#: Largest atlas side xatlas is asked for [texels]; a bigger one is almost surely a unit error.
MAX_ATLAS_SIZE = 16384

#: Factor by which the texel density shrinks each time the charts overflow one atlas.
_SHRINK = 0.96
_MAX_TRIES = 60


def generate_atlas(
    positions: np.ndarray,
    triangles: np.ndarray,
    resolution: int | None = None,
    texel_density: float | None = None,
    padding: int = 2,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[int, int]]:
    """Chart, flatten and pack a triangle mesh into a single atlas.

    Parameters
    ----------
    positions : (V, 3) float [m]
        Vertex positions.
    triangles : (T, 3) int
        Vertex indices. Vertices shared by two triangles keep them in one chart where
        xatlas can; give separate vertices to keep surfaces in separate charts.
    resolution : int or None
        Atlas size [texels]: the atlas is ``resolution`` x ``resolution`` and the texel
        density is the largest (within 4 %) whose charts still fit in it.
    texel_density : float or None
        Texels per metre [texels m-1]; the atlas grows to fit. Exclusive with
        ``resolution``. With neither, xatlas picks a density for about 1024 x 1024.
    padding : int
        Empty texels kept between charts [texels].

    Returns
    -------
    vmapping : (N,) int64
        Input vertex of each atlas vertex (vertices on chart seams are split).
    new_triangles : (T, 3) int64
        Atlas vertex indices, triangle ``t`` being input triangle ``t``.
    uvs : (N, 2) float64
        Atlas coordinates in [0, 1]: texel coordinates over ``atlas_size``; ``v`` grows
        with the image row (row 0 is the top, as in glTF).
    atlas_size : (int, int)
        Width and height [texels].

    Raises
    ------
    SettingsError
        Both or an invalid ``resolution`` / ``texel_density``, or an atlas beyond
        :data:`MAX_ATLAS_SIZE`.
    """
    if resolution is not None and texel_density is not None:
        raise SettingsError("give a lightmap resolution or a texel density, not both")
    if resolution is not None and not 8 <= resolution <= MAX_ATLAS_SIZE:
        raise SettingsError(
            f"lightmap resolution must be in [8, {MAX_ATLAS_SIZE}], not {resolution}"
        )
    if texel_density is not None and not (np.isfinite(texel_density) and texel_density > 0):
        raise SettingsError(f"texel density must be a positive number, not {texel_density}")
    if padding < 0:
        raise SettingsError(f"lightmap padding must be >= 0 texels, not {padding}")
    positions = np.ascontiguousarray(positions, dtype=np.float32)
    triangles = np.ascontiguousarray(triangles, dtype=np.uint32)

    if texel_density is not None:
        atlas = _pack(positions, triangles, 0, float(texel_density), padding)
    elif resolution is None:
        atlas = _pack(positions, triangles, 0, 0.0, padding)
    else:
        atlas = _pack_into(positions, triangles, int(resolution), padding)
    width, height = int(atlas.width), int(atlas.height)
    if max(width, height) > MAX_ATLAS_SIZE:
        raise SettingsError(
            f"the lightmap atlas would be {width} x {height} texels; lower the texel density"
        )
    vmapping, new_triangles, uvs = atlas[0]
    vmapping = np.asarray(vmapping, dtype=np.int64)
    new_triangles = np.asarray(new_triangles, dtype=np.int64).reshape(-1, 3)
    if new_triangles.shape != triangles.shape or not np.array_equal(
        vmapping[new_triangles], triangles
    ):
        raise RuntimeError("xatlas changed the triangle order; cannot map UVs back")
    log.info(
        "xatlas: %d charts in %d x %d texels at %.4g texels m-1 (%.0f %% used)",
        int(atlas.chart_count),
        width,
        height,
        float(atlas.texels_per_unit),
        100.0 * float(atlas.utilization),
    )
    return vmapping, new_triangles, np.asarray(uvs, dtype=np.float64), (width, height)


def _pack(
    positions: np.ndarray, triangles: np.ndarray, resolution: int, density: float, padding: int
) -> Any:
    """One ``xatlas.Atlas`` generated with the given pack options."""
    import xatlas

    atlas = xatlas.Atlas()
    atlas.add_mesh(positions, triangles)
    pack = xatlas.PackOptions()
    pack.resolution = resolution
    pack.texels_per_unit = density
    pack.padding = padding
    pack.bilinear = True  # room around charts for the texels bilinear filtering reads
    atlas.generate(xatlas.ChartOptions(), pack)
    return atlas


def _pack_into(positions: np.ndarray, triangles: np.ndarray, resolution: int, padding: int) -> Any:
    """Pack into exactly ``resolution`` squared texels, at the densest density that fits.

    xatlas's own estimate for a resolution gives an atlas of about that size, but not
    exactly; at a fixed size and density it spills charts into further atlases instead.
    The estimate is scaled to the wanted size, then shrunk until everything fits in one.
    """
    estimate = _pack(positions, triangles, resolution, 0.0, padding)
    side = max(int(estimate.width), int(estimate.height), 1)
    density = float(estimate.texels_per_unit) * resolution / side
    for _ in range(_MAX_TRIES):
        atlas = _pack(positions, triangles, resolution, density, padding)
        if int(atlas.atlas_count) == 1:
            return atlas
        density *= _SHRINK
    raise SettingsError(
        f"the charts do not fit in one {resolution} x {resolution} atlas; "
        "raise the lightmap resolution or lower the padding"
    )
