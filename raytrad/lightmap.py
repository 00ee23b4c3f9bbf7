"""Lightmaps: the vertex radiosity of a solve, interpolated into a texture atlas.

Each refined triangle of the :class:`~raytrad.mesh.RadiosityMesh` gets lightmap UVs, either
from the model's own lightmap UV set or from an atlas generated with xatlas
(:mod:`raytrad.io.xatlas_adapter`). The triangles are rasterised into the atlas with their
corner radiosity interpolated linearly, exactly as a renderer interpolates the vertex
colours of the radiosity PLY, and conservatively (every texel a triangle touches gets a
value, so thin triangles are not lost). Texels outside every chart are then filled: the
first ``padding`` rings around each chart repeat that chart's edge (:func:`grow_charts`),
the rest is a push-pull blend (:func:`raytrad.io.exr.dilate`), so bilinear filtering and
the first mipmaps never read undefined texels or a neighbouring chart.

Conventions
-----------
* Texel space: texel ``(i, j)`` (column ``i``, row ``j``) covers ``[i, i + 1] x [j, j + 1]``;
  its centre is ``(i + 0.5, j + 0.5)``. Normalised UVs are texel coordinates divided by
  the atlas width and height. Row 0 is the top row of the image, so ``v`` grows downwards
  (the glTF convention; an OBJ ``vt`` has ``v`` flipped).
* Pixel values are radiosity (radiant exitance) [W m-2] per linear RGB channel; the
  radiance of a Lambertian surface is radiosity / pi [W m-2 sr-1].
* When the atlas is generated, its vertices are the mesh's *receivers*: surfaces meeting at
  a crease or a material change, and the two sides of a double-sided face, are separate
  charts, so light never bleeds across them in the texture either.
"""

from __future__ import annotations

import logging
import math
import os
import time
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field

import numpy as np

from raytrad import __version__
from raytrad.errors import SceneError, SettingsError
from raytrad.io.exr import dilate, display_encode, write_exr, write_png
from raytrad.io.xatlas_adapter import MAX_ATLAS_SIZE, generate_atlas
from raytrad.mesh import RadiosityMesh

log = logging.getLogger(__name__)

#: Fraction of a model's UV texels covered twice above which the bake warns.
OVERLAP_WARNING = 0.005

#: Most (triangle, texel) candidates held in memory at once by :func:`rasterize`.
RASTER_BUDGET = 1 << 21

#: Triangle bounding boxes up to this many texels wide are grouped by exact width.
_EXACT_BUCKET = 8
#: Wider boxes are grouped by widths growing by this factor (at most 25 % wasted tests).
_BUCKET_GROWTH = 1.25


@dataclass(frozen=True)
class LightmapSettings:
    """How to lay out and store a lightmap.

    Attributes
    ----------
    resolution : int
        Atlas width and height [texels]; used when ``texel_density`` is None.
    texel_density : float or None
        Texels per metre [texels m-1]; the atlas grows to fit the charts at this density.
    padding : int
        Empty texels between charts of a generated atlas [texels] (filled by dilation).
    half : bool
        Store 16-bit half floats in the EXR (else 32-bit float).
    uv_set : int or str
        Where the lightmap UVs come from: ``"auto"`` (the model's glTF ``TEXCOORD_1``
        when every face has it, else a generated atlas), ``"atlas"`` (always generate one
        with xatlas), or the index of the model's texture-coordinate set (glTF
        ``TEXCOORD_<n>``; OBJ ``vt`` and PLY ``s, t`` are set 0), which every face must
        have. The UVs themselves are passed to :func:`bake_lightmap`.
    per_mesh : bool
        One lightmap per mesh (glTF node, OBJ ``o`` object or else ``g`` group, TOML
        ``[[mesh]]``) instead of one per scene.
    """

    resolution: int = 1024
    texel_density: float | None = None
    padding: int = 4
    half: bool = True
    uv_set: int | str = "auto"
    per_mesh: bool = False

    def __post_init__(self) -> None:
        if not 8 <= self.resolution <= MAX_ATLAS_SIZE:
            raise SettingsError(
                f"lightmap resolution must be in [8, {MAX_ATLAS_SIZE}], not {self.resolution}"
            )
        density = self.texel_density
        if density is not None and not (math.isfinite(density) and density > 0):
            raise SettingsError(f"texel density must be a positive number, not {density}")
        if self.padding < 0:
            raise SettingsError(f"lightmap padding must be >= 0 texels, not {self.padding}")
        uv_set = self.uv_set
        if isinstance(uv_set, bool) or not (
            uv_set in ("auto", "atlas") or (isinstance(uv_set, int) and uv_set >= 0)
        ):
            raise SettingsError(f"uv set must be 'auto', 'atlas' or an index >= 0, not {uv_set!r}")

    @property
    def uv_set_to_read(self) -> int | None:
        """The model's texture-coordinate set to load: 1 for auto, None for atlas."""
        if self.uv_set == "atlas":
            return None
        return 1 if self.uv_set == "auto" else int(self.uv_set)


@dataclass(frozen=True, eq=False)
class Lightmap:
    """A baked lightmap.

    Attributes
    ----------
    pixels : (H, W, 3) float32 [W m-2]
        Radiosity per texel, dilated into the padding between charts.
    coverage : (H, W) bool
        Texels touched by some triangle (before dilation).
    uv : (T, 3, 2) float64 [1]
        Normalised lightmap UV of each corner of each refined mesh triangle.
    stats : dict of str to float
        ``texel_density_min``, ``texel_density_median``, ``texel_density_max``
        [texels m-1] (area-weighted over triangles), ``covered_fraction`` [1],
        ``overlap_fraction`` [1] (of the texels whose centre some triangle covers, those
        covered by two or more: overlapping UV charts) and ``seconds`` (bake time) [s].
    settings : LightmapSettings
    triangles : (T,) int64 or None
        The refined mesh triangles this lightmap covers (one mesh's, per-mesh); None: all,
        in mesh order. ``uv`` rows follow this order.
    name : str
        The object the lightmap belongs to ("" for the whole scene).
    """

    pixels: np.ndarray
    coverage: np.ndarray
    uv: np.ndarray
    stats: dict[str, float]
    settings: LightmapSettings = field(default_factory=LightmapSettings)
    triangles: np.ndarray | None = None
    name: str = ""

    @property
    def size(self) -> tuple[int, int]:
        """Width and height [texels]."""
        return int(self.pixels.shape[1]), int(self.pixels.shape[0])


# --------------------------------------------------------------------------------------
# UVs and texel density
# --------------------------------------------------------------------------------------


def lightmap_uvs(
    mesh: RadiosityMesh,
    settings: LightmapSettings | None = None,
    existing_uv: np.ndarray | None = None,
    source_corners: np.ndarray | None = None,
    triangles: np.ndarray | None = None,
) -> tuple[np.ndarray, tuple[int, int]]:
    """Lightmap coordinates of every refined triangle corner, in texel space.

    Parameters
    ----------
    mesh : RadiosityMesh
    settings : LightmapSettings
    existing_uv : (S, 3, 2) float or None
        The model's lightmap UVs [1] per corner of each scene triangle (normalised, row 0
        at the top), for the scene the mesh was built from (``Prepared.scene``: indices
        as in ``mesh.triangle_source``). None generates an atlas.
    source_corners : (S, 3, 3) float or None
        Corner positions [m] of those scene triangles, in the order of ``existing_uv``
        (``scene.triangle_vertices()``); required with ``existing_uv``. Each refined corner
        takes the UV at its barycentric position in its scene triangle.
    triangles : (t,) int or None
        Lay out only these refined triangles (one mesh's); None: all.

    Returns
    -------
    uv : (T, 3, 2) float64 [texels]
        Of ``triangles`` when given (t rows).
    size : (int, int)
        Atlas width and height [texels]. With existing UVs the atlas is square: of
        ``settings.resolution``, or sized for ``settings.texel_density`` at the median.
    """
    settings = settings or LightmapSettings()
    rows = np.arange(len(mesh.triangles)) if triangles is None else np.asarray(triangles)
    if existing_uv is None:
        density = settings.texel_density
        used, local = np.unique(mesh.triangle_receivers[rows], return_inverse=True)
        _, new_triangles, uvs, size = generate_atlas(
            mesh.receiver_position[used],
            local.reshape(-1, 3),
            resolution=None if density is not None else settings.resolution,
            texel_density=density,
            padding=settings.padding,
        )
        return uvs[new_triangles] * np.asarray(size, dtype=np.float64), size
    if source_corners is None:
        raise ValueError("existing lightmap UVs need the scene triangle corners to map through")
    unit_uv = transfer_uvs(mesh, existing_uv, source_corners, rows)
    if settings.texel_density is None:
        side = settings.resolution
    else:
        median = texel_density_stats(unit_uv, mesh.triangle_area[rows])["texel_density_median"]
        side = math.ceil(settings.texel_density / median) if median > 0 else 0
        if not 8 <= side <= MAX_ATLAS_SIZE:
            raise SettingsError(
                f"a texel density of {settings.texel_density} texels m-1 needs a "
                f"{side} x {side} lightmap for these UVs; allowed sides are 8 to {MAX_ATLAS_SIZE}"
            )
    return unit_uv * side, (side, side)


def transfer_uvs(
    mesh: RadiosityMesh,
    existing_uv: np.ndarray,
    source_corners: np.ndarray,
    triangles: np.ndarray | None = None,
) -> np.ndarray:
    """Per-corner UVs of the refined mesh, interpolated from those of the scene triangles.

    Parameters
    ----------
    mesh : RadiosityMesh
    existing_uv : (S, 3, 2) float
        UV of each corner of each scene triangle [1].
    source_corners : (S, 3, 3) float
        Corner positions of the scene triangles [m].
    triangles : (t,) int or None
        Only these refined triangles; None: all.

    Returns
    -------
    (T, 3, 2) float64
        UV of each corner of each refined triangle [1] (same units as ``existing_uv``);
        ``t`` rows with ``triangles``.

    Raises
    ------
    SceneError
        Non-finite UVs on a triangle the mesh uses.
    """
    existing_uv = np.asarray(existing_uv, dtype=np.float64)
    source_corners = np.asarray(source_corners, dtype=np.float64)
    count = int(mesh.triangle_source.max()) + 1 if len(mesh.triangle_source) else 0
    if existing_uv.ndim != 3 or existing_uv.shape[1:] != (3, 2) or len(existing_uv) < count:
        raise ValueError(f"existing UVs must be (S >= {count}, 3, 2), not {existing_uv.shape}")
    if source_corners.shape != (*existing_uv.shape[:2], 3):
        raise ValueError(
            f"source corners {source_corners.shape} do not match UVs {existing_uv.shape}"
        )
    rows = slice(None) if triangles is None else np.asarray(triangles)
    source = mesh.triangle_source[rows]
    uv = existing_uv[source]
    if not np.isfinite(uv).all():
        raise SceneError(None, "the lightmap UV set has non-finite coordinates")
    if (uv < 0.0).any() or (uv > 1.0).any():
        log.warning("lightmap UVs outside [0, 1]: those texels are left out of the atlas")
    corners = source_corners[source]  # (T, 3, 3)
    points = mesh.positions[mesh.triangles[rows]]  # (T, 3, 3)
    e0 = corners[:, 1] - corners[:, 0]
    e1 = corners[:, 2] - corners[:, 0]
    rel = points - corners[:, :1]
    d00 = np.einsum("ti,ti->t", e0, e0)[:, None]
    d01 = np.einsum("ti,ti->t", e0, e1)[:, None]
    d11 = np.einsum("ti,ti->t", e1, e1)[:, None]
    d20 = np.einsum("tki,ti->tk", rel, e0)
    d21 = np.einsum("tki,ti->tk", rel, e1)
    denom = d00 * d11 - d01 * d01
    b1 = (d11 * d20 - d01 * d21) / denom
    b2 = (d00 * d21 - d01 * d20) / denom
    b0 = 1.0 - b1 - b2
    return np.asarray(
        b0[..., None] * uv[:, None, 0]
        + b1[..., None] * uv[:, None, 1]
        + b2[..., None] * uv[:, None, 2]
    )


def texel_density(uv: np.ndarray, area: np.ndarray) -> np.ndarray:
    """Texels per metre of each triangle: sqrt(texel area / surface area).

    Parameters
    ----------
    uv : (T, 3, 2) float [texels]
    area : (T,) float [m2]

    Returns
    -------
    (T,) float64 [texels m-1]; 0 where ``area`` is 0.
    """
    uv = np.asarray(uv, dtype=np.float64)
    e0 = uv[:, 1] - uv[:, 0]
    e1 = uv[:, 2] - uv[:, 0]
    texels = 0.5 * np.abs(e0[:, 0] * e1[:, 1] - e0[:, 1] * e1[:, 0])
    area = np.asarray(area, dtype=np.float64)
    return np.sqrt(np.divide(texels, area, out=np.zeros_like(texels), where=area > 0))


def texel_density_stats(uv: np.ndarray, area: np.ndarray) -> dict[str, float]:
    """Smallest, area-weighted median and largest texel density.

    Parameters
    ----------
    uv : (T, 3, 2) float [texels]
    area : (T,) float [m2]

    Returns
    -------
    dict
        ``texel_density_min``, ``texel_density_median``, ``texel_density_max``
        [texels m-1] over triangles of non-zero area; the median is the density that
        half the surface area has less of.
    """
    area = np.asarray(area, dtype=np.float64)
    density = texel_density(uv, area)
    used = area > 0
    if not used.any():
        return {"texel_density_min": 0.0, "texel_density_median": 0.0, "texel_density_max": 0.0}
    density, weight = density[used], area[used]
    order = np.argsort(density)
    cumulative = np.cumsum(weight[order])
    middle = order[np.searchsorted(cumulative, 0.5 * cumulative[-1])]
    return {
        "texel_density_min": float(density.min()),
        "texel_density_median": float(density[middle]),
        "texel_density_max": float(density.max()),
    }


# --------------------------------------------------------------------------------------
# Rasterisation
# --------------------------------------------------------------------------------------


def rasterize(
    uv_corners: np.ndarray,
    values_at_corners: np.ndarray,
    size: tuple[int, int],
    priority: np.ndarray | None = None,
    centre_count: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Interpolate per-corner values over triangles into an image, conservatively.

    A texel whose centre lies in a triangle takes the barycentric interpolation of the
    triangle's corner values at the centre. A texel that a triangle only touches (its
    square overlaps the triangle but not its centre, e.g. along a thin sliver) takes the
    interpolation at the point of the triangle nearest the centre. Where several
    triangles claim a texel the nearest wins (a centre inside is at distance 0), then the
    lower ``priority``.

    Triangles are processed in groups of equal bounding-box size (rounded up), each group
    testing all texels of all its boxes at once by broadcasting, so no Python loop runs
    per triangle or texel.

    Parameters
    ----------
    uv_corners : (T, 3, 2) float [texels]
        Corner positions in texel space (texel ``(i, j)`` covers ``[i, i+1] x [j, j+1]``).
    values_at_corners : (T, 3, C) float
        Value at each corner (radiosity [W m-2] for a lightmap).
    size : (int, int)
        Image width and height [texels].
    priority : (T,) int or None
        Tie-break between triangles at the same distance (lower wins), e.g. the front of a
        double-sided face over its back copy when both share UVs.
    centre_count : (H * W,) int64 or None
        If given, incremented for each triangle of priority 0 whose interior (not an
        edge) holds the texel's centre: more than 1 where UV charts overlap.

    Returns
    -------
    pixels : (H, W, C) float32
        Interpolated values; 0 where uncovered.
    coverage : (H, W) bool
        True where some triangle touches the texel.
    """
    uv = np.asarray(uv_corners, dtype=np.float64)
    values = np.asarray(values_at_corners, dtype=np.float64)
    width, height = int(size[0]), int(size[1])
    if uv.ndim != 3 or uv.shape[1:] != (3, 2):
        raise ValueError(f"uv_corners must be (T, 3, 2), not {uv.shape}")
    if values.ndim != 3 or values.shape[:2] != uv.shape[:2]:
        raise ValueError(f"values_at_corners must be (T, 3, C), not {values.shape}")
    channels = values.shape[2]
    rank = np.zeros(len(uv), dtype=np.int64) if priority is None else np.asarray(priority)

    best_distance = np.full(width * height, np.inf)
    best_rank = np.zeros(width * height, dtype=np.int64)
    pixels = np.zeros((width * height, channels), dtype=np.float32)

    limit = np.array([width - 1, height - 1])
    finite = np.asarray(np.isfinite(uv).all(axis=(1, 2)))
    safe = np.where(finite[:, None, None], uv, 0.0)
    lo = np.floor(safe.min(axis=1)).astype(np.int64)
    hi = np.maximum(np.ceil(safe.max(axis=1)).astype(np.int64) - 1, lo)
    visible = finite & (hi >= 0).all(axis=1) & (lo <= limit).all(axis=1)
    lo, hi = np.clip(lo, 0, limit), np.clip(hi, 0, limit)
    extent = hi - lo + 1
    box = np.stack([_bucket(extent[:, 0]), _bucket(extent[:, 1])], axis=1)
    todo = np.nonzero(visible)[0]
    shapes, group = np.unique(box[todo], axis=0, return_inverse=True)
    group = group.reshape(-1)
    order = np.argsort(group, kind="stable")
    bounds = np.searchsorted(group[order], np.arange(len(shapes) + 1))
    for g, (box_w, box_h) in enumerate(shapes):
        members = todo[order[bounds[g] : bounds[g + 1]]]
        dx, dy = (a.reshape(-1) for a in np.meshgrid(np.arange(box_w), np.arange(box_h)))
        step = max(1, RASTER_BUDGET // int(box_w * box_h))
        for start in range(0, len(members), step):
            tri = members[start : start + step]
            k, j, weights, distance = _cover_boxes(uv[tri] - lo[tri, None, :], dx, dy)
            inside_box = (dx[j] <= hi[tri[k], 0] - lo[tri[k], 0]) & (
                dy[j] <= hi[tri[k], 1] - lo[tri[k], 1]
            )
            k, j, weights, distance = (
                k[inside_box],
                j[inside_box],
                weights[inside_box],
                distance[inside_box],
            )
            t = tri[k]
            x, y = lo[t, 0] + dx[j], lo[t, 1] + dy[j]
            if centre_count is not None:
                # strictly inside: a centre on an edge (xatlas puts vertices on texel
                # centres) belongs to two neighbours, not to an overlap
                inside = (distance == 0.0) & (rank[t] == 0) & (weights.min(axis=1) > 1e-9)
                np.add.at(centre_count, (y * width + x)[inside], 1)
            _keep_nearest(
                y * width + x,
                distance,
                rank[t],
                np.einsum("nk,nkc->nc", weights, values[t]),
                best_distance,
                best_rank,
                pixels,
            )
    coverage = np.isfinite(best_distance).reshape(height, width)
    return pixels.reshape(height, width, channels), coverage


def _cover_boxes(
    corners: np.ndarray, dx: np.ndarray, dy: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Texels of a common box grid that each triangle touches, with their weights.

    Parameters
    ----------
    corners : (N, 3, 2) float [texels]
        Triangles relative to the corner of their bounding box's first texel.
    dx, dy : (B,) int
        Texel offsets of the box grid.

    Returns
    -------
    triangle : (M,) int64
        Index into ``corners`` of each touched (triangle, texel) pair.
    texel : (M,) int64
        Index into ``dx`` / ``dy``.
    weights : (M, 3) float64
        Barycentric coordinates of the texel centre if it lies in the triangle, else of
        the triangle's point nearest the centre (non-negative, summing to 1).
    distance : (M,) float64 [texels]
        From the centre to the triangle (0 inside).
    """
    edge = np.roll(corners, -1, axis=1) - corners  # edge i runs from corner i to i + 1
    # cross(edge_i, centre - corner_i) = ex * cy - ey * cx + (ey * px - ex * py)
    offset = edge[..., 1] * corners[..., 0] - edge[..., 0] * corners[..., 1]  # (N, 3)
    # cross(p1 - p0, p2 - p0), with p2 - p0 = -edge 2
    twice_area = edge[:, 0, 1] * edge[:, 2, 0] - edge[:, 0, 0] * edge[:, 2, 1]
    flat = twice_area == 0.0
    orientation = np.where(flat, 0.0, np.sign(twice_area))
    # the texel square (half-size 1/2) reaches past edge i when the edge's function at the
    # centre, signed positive inside, exceeds -(|ex| + |ey|) / 2
    reach = 0.5 * np.abs(edge).sum(axis=2)
    cx, cy = dx + 0.5, dy + 0.5
    touched = np.ones((len(corners), len(dx)), dtype=bool)
    inside = ~flat[:, None] & touched
    for i in range(3):
        cross = (
            edge[:, i, 0, None] * cy[None, :]
            - edge[:, i, 1, None] * cx[None, :]
            + offset[:, i, None]
        )
        signed = np.where(flat[:, None], -np.abs(cross), orientation[:, None] * cross)
        inside &= signed >= 0.0
        touched &= signed + reach[:, i, None] >= -1e-12 * (1.0 + reach[:, i, None])
    triangle, texel = np.nonzero(touched | inside)
    centre = np.stack([cx[texel], cy[texel]], axis=1)
    crosses = edge[triangle, :, 0] * centre[:, None, 1] - edge[triangle, :, 1] * centre[:, None, 0]
    crosses += offset[triangle]
    weights = np.roll(crosses, 2, axis=1) / np.where(flat, 1.0, twice_area)[triangle, None]
    distance = np.zeros(len(triangle))
    outside = np.nonzero(~inside[triangle, texel])[0]
    if len(outside):
        w, d = _nearest_on_edges(corners[triangle[outside]], centre[outside])
        weights[outside], distance[outside] = w, d
    return triangle, texel, weights, distance


def _nearest_on_edges(corners: np.ndarray, centre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Barycentric weights of, and distance to, the nearest point on each triangle's edges.

    Parameters
    ----------
    corners : (N, 3, 2) float
    centre : (N, 2) float

    Returns
    -------
    weights : (N, 3) float64
    distance : (N,) float64
    """
    edge = np.roll(corners, -1, axis=1) - corners
    rel = centre[:, None, :] - corners
    length2 = (edge * edge).sum(axis=2)
    along = np.divide(
        (rel * edge).sum(axis=2), length2, out=np.zeros_like(length2), where=length2 > 0
    )
    along = np.clip(along, 0.0, 1.0)
    gap2 = ((rel - along[..., None] * edge) ** 2).sum(axis=2)
    nearest = np.argmin(gap2, axis=1)
    row = np.arange(len(corners))
    t = along[row, nearest]
    weights = np.zeros((len(corners), 3))
    weights[row, nearest] = 1.0 - t
    weights[row, (nearest + 1) % 3] = t
    return weights, np.sqrt(gap2[row, nearest])


def _keep_nearest(
    texel: np.ndarray,
    distance: np.ndarray,
    rank: np.ndarray,
    value: np.ndarray,
    best_distance: np.ndarray,
    best_rank: np.ndarray,
    pixels: np.ndarray,
) -> None:
    """Write candidates that beat what the texels hold (nearest, then lowest rank)."""
    if len(texel) == 0:
        return
    order = np.lexsort((rank, distance, texel))
    texel, distance, rank = texel[order], distance[order], rank[order]
    first = np.ones(len(texel), dtype=bool)
    first[1:] = texel[1:] != texel[:-1]
    chosen = order[first]
    texel, distance, rank = texel[first], distance[first], rank[first]
    held_distance, held_rank = best_distance[texel], best_rank[texel]
    better = (distance < held_distance) | ((distance == held_distance) & (rank < held_rank))
    texel = texel[better]
    best_distance[texel] = distance[better]
    best_rank[texel] = rank[better]
    pixels[texel] = value[chosen[better]]


def grow_charts(
    pixels: np.ndarray, coverage: np.ndarray, rings: int
) -> tuple[np.ndarray, np.ndarray]:
    """Extend charts outwards by ``rings`` texels before the push-pull fill.

    Each ring gives every uncovered texel next to a covered one (of its 8 neighbours) the
    mean of those neighbours. The padding around a chart thus repeats the chart's own edge
    instead of a push-pull blend that may include a bright neighbouring chart (a lamp),
    which bilinear filtering and mipmaps would bleed into the chart.

    Parameters
    ----------
    pixels : (H, W, C) float
    coverage : (H, W) bool
    rings : int

    Returns
    -------
    pixels : (H, W, C) float32
        Uncovered texels beyond the rings are 0.
    coverage : (H, W) bool
        Covered texels and the rings.
    """
    value = np.where(coverage[..., None], np.asarray(pixels, dtype=np.float64), 0.0)
    covered = np.asarray(coverage, dtype=bool).copy()
    height, width = covered.shape
    shifts = [(a, b) for a in (-1, 0, 1) for b in (-1, 0, 1) if (a, b) != (0, 0)]
    for _ in range(rings):
        padded_value = np.pad(value, ((1, 1), (1, 1), (0, 0)))
        padded_count = np.pad(covered.astype(np.float64), 1)
        total = np.zeros_like(value)
        count = np.zeros(covered.shape)
        for a, b in shifts:
            rows, cols = slice(1 + a, 1 + a + height), slice(1 + b, 1 + b + width)
            total += padded_value[rows, cols]
            count += padded_count[rows, cols]
        ring = ~covered & (count > 0)
        if not ring.any():
            break
        value[ring] = total[ring] / count[ring, None]
        covered |= ring
    return value.astype(np.float32), covered


def _bucket(extent: np.ndarray) -> np.ndarray:
    """Box sizes rounded up: exact to 8 texels, then in steps of 25 %."""
    extent = np.asarray(extent, dtype=np.int64)
    big = extent > _EXACT_BUCKET
    steps = np.ceil(np.log(np.maximum(extent, 1) / _EXACT_BUCKET) / math.log(_BUCKET_GROWTH) - 1e-9)
    rounded = np.ceil(_EXACT_BUCKET * _BUCKET_GROWTH ** np.maximum(steps, 0)).astype(np.int64)
    return np.where(big, np.maximum(rounded, extent), extent)


# --------------------------------------------------------------------------------------
# Baking and writing
# --------------------------------------------------------------------------------------


def bake_lightmap(
    mesh: RadiosityMesh,
    radiosity: np.ndarray,
    settings: LightmapSettings | None = None,
    existing_uv: np.ndarray | None = None,
    source_corners: np.ndarray | None = None,
    triangles: np.ndarray | None = None,
    name: str = "",
) -> Lightmap:
    """Bake receiver radiosity into a lightmap atlas.

    Parameters
    ----------
    mesh : RadiosityMesh
    radiosity : (R, 3) float [W m-2]
        Radiosity of each receiver (``SolveResult.radiosity``).
    settings : LightmapSettings
    existing_uv, source_corners
        The model's lightmap UVs and the corners they belong to (see
        :func:`lightmap_uvs`); None generates an atlas. Where the two sides of a
        double-sided face share UVs, the front side's radiosity is baked.
    triangles : (t,) int or None
        Bake only these refined triangles (one mesh, for per-mesh lightmaps; kept sorted
        in :attr:`Lightmap.triangles`); None: all.
    name : str
        The object's name, kept in :attr:`Lightmap.name`.

    Returns
    -------
    Lightmap
    """
    settings = settings or LightmapSettings()
    radiosity = np.asarray(radiosity, dtype=np.float64)
    if radiosity.shape != (mesh.receiver_count, 3):
        raise ValueError(f"radiosity must be ({mesh.receiver_count}, 3), not {radiosity.shape}")
    if isinstance(settings.uv_set, int) and existing_uv is None:
        raise SettingsError(f"uv set {settings.uv_set} was asked for but no UVs were given")
    started = time.perf_counter()
    rows = np.arange(len(mesh.triangles)) if triangles is None else np.unique(triangles)
    uv, size = lightmap_uvs(mesh, settings, existing_uv, source_corners, rows)
    priority = None
    if existing_uv is not None and source_corners is not None:
        priority = _back_copies(mesh, np.asarray(source_corners, dtype=np.float64), rows)
    values = radiosity[mesh.triangle_receivers[rows]]
    counts = np.zeros(size[0] * size[1], dtype=np.int64)
    pixels, coverage = rasterize(uv, values, size, priority, counts)

    grown, reached = grow_charts(pixels, coverage, max(settings.padding, 1))
    filled = dilate(grown, reached)
    stats = texel_density_stats(uv, mesh.triangle_area[rows])
    stats["covered_fraction"] = float(coverage.mean())
    stats["overlap_fraction"] = float((counts > 1).sum() / max((counts > 0).sum(), 1))
    if existing_uv is not None and stats["overlap_fraction"] > OVERLAP_WARNING:
        log.warning(
            "lightmap%s: the model's UVs overlap on %.1f %% of their texels; overlapping "
            "surfaces share those texels and show one value (%s)",
            f" {name!r}" if name else "",
            100.0 * stats["overlap_fraction"],
            "use --uv-set atlas, or --lightmap-per-mesh if each mesh has its own UV square"
            if not name
            else "use --uv-set atlas",
        )
    stats["seconds"] = time.perf_counter() - started
    log.info(
        "lightmap%s %d x %d: %.1f %% covered, %.4g to %.4g texels m-1 (median %.4g), %.2f s",
        f" {name!r}" if name else "",
        size[0],
        size[1],
        100.0 * stats["covered_fraction"],
        stats["texel_density_min"],
        stats["texel_density_max"],
        stats["texel_density_median"],
        stats["seconds"],
    )
    normalised = uv / np.asarray(size, dtype=np.float64)
    return Lightmap(
        filled, coverage, normalised, stats, settings, None if triangles is None else rows, name
    )


def _back_copies(
    mesh: RadiosityMesh, source_corners: np.ndarray, triangles: np.ndarray
) -> np.ndarray:
    """(t,) int64: 1 for reversed copies of double-sided faces among ``triangles``, else 0."""
    corners = source_corners[mesh.triangle_source[triangles]]
    facing = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normal = mesh.triangle_normal[triangles]
    return (np.einsum("ti,ti->t", facing, normal) < 0).astype(np.int64)


def lightmap_vertices(
    mesh: RadiosityMesh, lightmap: Lightmap, triangles: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """An indexed mesh carrying the lightmap UVs (for glTF ``TEXCOORD_1``).

    Receivers are split where their corners have different UVs (on chart seams); the
    rest stay shared. UVs closer than 2**-24 are taken as equal.

    Parameters
    ----------
    mesh : RadiosityMesh
    lightmap : Lightmap
    triangles : (t,) int or None
        Refined mesh triangles to include (one object's), all of them in the lightmap;
        None: every triangle of the lightmap.

    Returns
    -------
    receiver : (N,) int64
        The receiver each vertex stands for (index ``receiver_position``, radiosity...).
    triangles : (t, 3) int64
        Vertex indices of each included triangle, in the given order and mesh winding.
    uv : (N, 2) float64
        Normalised lightmap UV [1] (row 0 at the top).
    """
    covered = np.arange(len(mesh.triangles)) if lightmap.triangles is None else lightmap.triangles
    local = np.arange(len(covered)) if triangles is None else np.searchsorted(covered, triangles)
    if triangles is not None and not np.array_equal(covered[local % len(covered)], triangles):
        raise ValueError("the lightmap does not cover every triangle asked for")
    corner_receiver = mesh.triangle_receivers[covered[local]].reshape(-1)
    corner_uv = lightmap.uv[local].reshape(-1, 2)
    key = np.column_stack([corner_receiver, np.round(corner_uv * 2.0**24).astype(np.int64)])
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    return corner_receiver[first], inverse.reshape(-1, 3), corner_uv[first]


def lightmap_metadata(
    lightmap: Lightmap, metadata: Mapping[str, str | float] | None = None
) -> dict[str, str | float]:
    """EXR header attributes of a lightmap: units, convention, settings, statistics.

    Keys without a namespace get ``raytrad:`` (``scene`` -> ``raytrad:scene``).
    """
    attributes: dict[str, str | float] = {
        "raytrad:version": __version__,
        "raytrad:quantity": "radiosity",
        "raytrad:units": "W m-2",
        "raytrad:uv_origin": "top-left",
    }
    for name, value in asdict(lightmap.settings).items():
        attributes[f"raytrad:lightmap_{name}"] = "none" if value is None else value
    attributes.update({f"raytrad:{k}": v for k, v in lightmap.stats.items()})
    for name, value in (metadata or {}).items():
        attributes[name if ":" in name else f"raytrad:{name}"] = value
    return attributes


def write_lightmap(
    path: str | os.PathLike[str],
    lightmap: Lightmap,
    metadata: Mapping[str, str | float] | None = None,
) -> None:
    """Write the lightmap as an OpenEXR file (half or float per its settings), atomically.

    Parameters
    ----------
    path : path-like
        Target ``.exr`` file.
    lightmap : Lightmap
    metadata : mapping of str to str or float
        Extra header attributes (scene, solve settings...); see :func:`lightmap_metadata`.
    """
    write_exr(
        path,
        lightmap.pixels,
        half=lightmap.settings.half,
        metadata=lightmap_metadata(lightmap, metadata),
    )


def lightmap_preview(lightmap: Lightmap, exposure: float, gutter: float = 1.0) -> np.ndarray:
    """8-bit sRGB display image of a lightmap.

    Parameters
    ----------
    lightmap : Lightmap
    exposure : float [m2 sr W-1]
        Multiplier of radiance, e.g. :func:`raytrad.display.auto_exposure` of the solve.
    gutter : float
        Brightness factor of texels outside every chart (the dilated padding); below 1 it
        shows the chart layout.

    Returns
    -------
    (H, W, 3) uint8
    """
    radiance = lightmap.pixels.astype(np.float64) / math.pi * exposure
    radiance *= np.where(lightmap.coverage, 1.0, gutter)[..., None]
    return display_encode(radiance)


def write_lightmap_preview(
    path: str | os.PathLike[str], lightmap: Lightmap, exposure: float, gutter: float = 1.0
) -> None:
    """Write :func:`lightmap_preview` as a PNG, atomically."""
    write_png(path, lightmap_preview(lightmap, exposure, gutter))
