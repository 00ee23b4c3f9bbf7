"""Lightmaps: the vertex radiosity of a solve, interpolated into a texture atlas.

Each refined triangle of the :class:`~raytrad.core.mesh.RadiosityMesh` gets lightmap UVs,
either from the model's own lightmap UV set or from an atlas generated with xatlas
(:mod:`raytrad.products.atlas`). The triangles are rasterised into the atlas with their
corner radiosity interpolated linearly, exactly as a renderer interpolates the vertex
colours of the radiosity PLY, and conservatively (every texel a triangle touches gets a
value, so thin triangles are not lost; :mod:`raytrad.products.raster`). Texels outside
every chart are then filled: the first ``padding`` rings around each chart repeat that
chart's edge (:func:`~raytrad.products.raster.grow_charts`), the rest is a push-pull blend
(:func:`raytrad.formats.images.dilate`), so bilinear filtering and the first mipmaps never
read undefined texels or a neighbouring chart. Nothing here writes a file
(:mod:`raytrad.outputs.lightmaps` does).

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

import dataclasses
import logging
import math
import time
from dataclasses import dataclass, field

import numpy as np

from raytrad.arrays import unique
from raytrad.constants import defaults
from raytrad.core.mesh import RadiosityMesh
from raytrad.errors import SceneError, SettingsError
from raytrad.formats.images import dilate
from raytrad.products.atlas import MAX_ATLAS_SIZE, generate_atlas
from raytrad.products.display import display_encode
from raytrad.products.raster import grow_charts, rasterize
from raytrad.scene import Scene

log = logging.getLogger(__name__)

#: Fraction of a model's UV texels covered twice above which the bake warns.
OVERLAP_WARNING = 0.005


@dataclass(frozen=True)
class LightmapSettings:
    """How to lay out and store a lightmap.

    Attributes
    ----------
    resolution : int or None
        Atlas width and height [texels]; used when ``texel_density`` is None. None: the
        scene file's ``lightmap_resolution``, else 1024 (:attr:`side`).
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

    resolution: int | None = None
    texel_density: float | None = None
    padding: int = defaults.lightmap_padding
    half: bool = True
    uv_set: int | str = "auto"
    per_mesh: bool = False

    def __post_init__(self) -> None:
        if self.resolution is not None and not 8 <= self.resolution <= MAX_ATLAS_SIZE:
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
    def side(self) -> int:
        """Atlas width and height [texels]: :attr:`resolution`, else the default."""
        return self.resolution or defaults.lightmap_resolution

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
        ``settings.side``, or sized for ``settings.texel_density`` at the median.
    """
    settings = settings or LightmapSettings()
    rows = np.arange(len(mesh.triangles)) if triangles is None else np.asarray(triangles)
    if existing_uv is None:
        density = settings.texel_density
        used, local = np.unique(mesh.triangle_receivers[rows], return_inverse=True)
        _, new_triangles, uvs, size = generate_atlas(
            mesh.receiver_position[used],
            local.reshape(-1, 3),
            resolution=None if density is not None else settings.side,
            texel_density=density,
            padding=settings.padding,
        )
        return uvs[new_triangles] * np.asarray(size, dtype=np.float64), size
    if source_corners is None:
        raise ValueError("existing lightmap UVs need the scene triangle corners to map through")
    unit_uv = transfer_uvs(mesh, existing_uv, source_corners, rows)
    if settings.texel_density is None:
        side = settings.side
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
    rows = np.arange(len(mesh.triangles)) if triangles is None else unique(triangles)
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


def lightmap_preview(lightmap: Lightmap, exposure: float, gutter: float = 1.0) -> np.ndarray:
    """8-bit sRGB display image of a lightmap.

    Parameters
    ----------
    lightmap : Lightmap
    exposure : float [m2 sr W-1]
        Multiplier of radiance, e.g. :func:`raytrad.products.display.auto_exposure` of the
        solve.
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


def choose_lightmap_uvs(scene: Scene, settings: LightmapSettings | None) -> Scene:
    """The scene with the lightmap UVs the settings will bake with, or without any.

    With ``uv_set="auto"`` the model's UVs are kept only when every face has them (else an
    atlas is generated, with a warning when only some faces have them); with an index
    every face must have them.

    Raises
    ------
    SceneError
        An explicit UV set that some faces lack, naming the file, the set and an object.
    """
    uv = scene.lightmap_uv
    if settings is None or uv is None or settings.uv_set == "atlas":
        return dataclasses.replace(scene, lightmap_uv=None)
    missing = ~np.isfinite(uv).all(axis=(1, 2))
    if not missing.any():
        log.info("%s: baking into the model's UV set %s", scene.source, settings.uv_set_to_read)
        return scene
    count, total = int(missing.sum()), scene.triangle_count
    where = scene.object_names[int(scene.object_index[np.argmax(missing)])]
    if settings.uv_set == "auto":
        if count < total:
            log.warning(
                "%s: UV set 1 (TEXCOORD_1) is missing on %d of %d faces (object %r); "
                "generating a lightmap atlas instead",
                scene.source,
                count,
                total,
                where,
            )
        return dataclasses.replace(scene, lightmap_uv=None)
    raise SceneError(
        scene.source,
        f"UV set {settings.uv_set} is missing on {count} of {total} faces (first in object "
        f"{where!r}); omit --uv-set or use --uv-set atlas to generate a lightmap atlas",
    )


def object_triangles(scene: Scene, mesh: RadiosityMesh) -> list[tuple[str, np.ndarray]]:
    """Each object's name and (t,) indices of its refined mesh triangles, objects in order
    (objects without a triangle in the mesh are left out)."""
    owner = scene.object_index[mesh.triangle_source]
    return [
        (name, np.flatnonzero(owner == i))
        for i, name in enumerate(scene.object_names)
        if (owner == i).any()
    ]


def bake_lightmaps(
    scene: Scene, mesh: RadiosityMesh, radiosity: np.ndarray, settings: LightmapSettings
) -> list[Lightmap]:
    """One lightmap for the scene, or one per object with ``settings.per_mesh``.

    Parameters
    ----------
    scene : Scene
        The scene ``mesh`` was built from (its ``lightmap_uv``, if any, are the model's
        UVs to bake into; see :func:`choose_lightmap_uvs`).
    mesh : RadiosityMesh
    radiosity : (R, 3) float [W m-2]
    settings : LightmapSettings
    """
    uv = scene.lightmap_uv
    corners = None if uv is None else scene.triangle_vertices()
    if not settings.per_mesh:
        return [bake_lightmap(mesh, radiosity, settings, uv, corners)]
    return [
        bake_lightmap(mesh, radiosity, settings, uv, corners, rows, name)
        for name, rows in object_triangles(scene, mesh)
    ]
