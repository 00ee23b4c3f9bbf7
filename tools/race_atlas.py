"""Lightmap atlases for ``tools/bench_race.py``: the layout Cycles bakes into and Mitsuba
fills, the texels' centres on the surfaces, which texels no one sees, how the image is
finished (hidden texels and gutters filled) and read at the probes."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from bench_accuracy import Probes, hidden_points, quad_corners

from raytrad.scene import Scene
from raytrad.scene.model import barycentric_coordinates

#: Texels of gutter around each atlas tile.
GUTTER = 2


@dataclass
class Atlas:
    """A lightmap layout: (T, 3, 2) UVs per triangle corner in [0, 1] (v up, Blender's
    convention), the image's size in texels, and each quad's tile: (Q, 2) texel column
    and row of its first texel, (Q, 2) texels along its edges c0-c1 and c0-c3."""

    uv: np.ndarray
    width: int
    height: int
    origin: np.ndarray
    size: np.ndarray


def atlas(scene: Scene, texel: float, gutter: int = GUTTER) -> Atlas:
    """One rectangular tile per quad (corners 0-1-2-3, triangles 0-1-2 and 0-2-3), of
    ``|c1 - c0|`` by ``|c3 - c0|`` at ``texel`` [m] per texel, shelf-packed with ``gutter``
    texels around each. Each triangle maps affinely onto half its tile, so the map is
    continuous across the diagonal and the texel density uniform on parallelograms."""
    corners = quad_corners(scene)
    size = np.ceil(np.linalg.norm(corners[:, [1, 3]] - corners[:, [0]], axis=2) / texel).astype(int)
    padded = size + 2 * gutter
    width = max(int(np.ceil(1.1 * np.sqrt(np.prod(padded, axis=1).sum()))), padded[:, 0].max())
    origin = np.zeros_like(size)
    x = y = shelf = 0
    for q in np.argsort(-padded[:, 1], kind="stable"):
        if x + padded[q, 0] > width:
            x, y, shelf = 0, y + shelf, 0
        origin[q] = (x + gutter, y + gutter)
        x, shelf = x + padded[q, 0], max(shelf, padded[q, 1])
    height = y + shelf
    unit = np.array([[0, 0], [1, 0], [1, 1], [0, 1]])
    tile = origin[:, None] + unit[None] * size[:, None]  # (Q, 4, 2) texels
    uv = np.empty((2 * len(corners), 3, 2))
    uv[0::2], uv[1::2] = tile[:, [0, 1, 2]], tile[:, [0, 2, 3]]
    return Atlas(uv / [width, height], int(width), int(height), origin, size)


def probe_uv(scene: Scene, layout: Atlas, probes: Probes) -> np.ndarray:
    """(N, 2) UVs of the probes: each lies in its quad's plane; of the quad's two triangles
    the one it is inside (the larger least barycentric coordinate) maps it."""
    corners = scene.triangle_vertices()
    both = [2 * probes.quad, 2 * probes.quad + 1]
    bary = [barycentric_coordinates(probes.points, corners[t]) for t in both]
    second = bary[1].min(axis=1) > bary[0].min(axis=1)
    triangle = np.where(second, both[1], both[0])
    weights = np.where(second[:, None], bary[1], bary[0])
    return np.einsum("ij,ijk->ik", weights, layout.uv[triangle])


def bilinear(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """(N, C) values of ``image`` (H, W, C), row 0 at v = 0, at ``uv`` (N, 2), bilinear
    between texel centres (clamped at the border) as a GPU samples a lightmap."""
    height, width = image.shape[:2]
    xy = uv * [width, height] - 0.5
    low = np.floor(xy).astype(int)
    frac = xy - low
    x0, y0 = np.clip(low[:, 0], 0, width - 1), np.clip(low[:, 1], 0, height - 1)
    x1, y1 = np.clip(low[:, 0] + 1, 0, width - 1), np.clip(low[:, 1] + 1, 0, height - 1)
    fx, fy = frac[:, :1], frac[:, 1:]
    return (1 - fy) * ((1 - fx) * image[y0, x0] + fx * image[y0, x1]) + fy * (
        (1 - fx) * image[y1, x0] + fx * image[y1, x1]
    )


def texel_points(corners: np.ndarray, origin: np.ndarray, size: np.ndarray):
    """Every tile texel's centre on its quad: (K, 3) points, (K, 3) normals, (K,) quad
    indices and (K, 2) texel (column, row) in the image. ``corners`` (Q, 4, 3) are the
    quads' corners (triangles 0-1-2 and 0-2-3), ``origin`` and ``size`` (Q, 2) their tiles
    (:class:`Atlas`): a tile's texel (i, j) is at (u, v) = ((i + 1/2) / size_u,
    (j + 1/2) / size_v), on triangle 0-1-2 where u >= v (``c0 + u (c1 - c0) + v (c2 - c1)``)
    and on 0-2-3 elsewhere (``c0 + v (c3 - c0) + u (c2 - c3)``), as the atlas maps them."""
    quads = np.repeat(np.arange(len(size)), size[:, 0] * size[:, 1])
    first = np.concatenate([[0], np.cumsum(size[:, 0] * size[:, 1])[:-1]])
    local = np.arange(len(quads)) - first[quads]
    j, i = np.divmod(local, size[quads, 0])
    u = (i + 0.5) / size[quads, 0]
    v = (j + 0.5) / size[quads, 1]
    c = corners[quads]
    lower = (u >= v)[:, None]
    u, v = u[:, None], v[:, None]
    points = np.where(
        lower,
        c[:, 0] + u * (c[:, 1] - c[:, 0]) + v * (c[:, 2] - c[:, 1]),
        c[:, 0] + v * (c[:, 3] - c[:, 0]) + u * (c[:, 2] - c[:, 3]),
    )
    normals = np.where(
        lower,
        np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]),
        np.cross(c[:, 2] - c[:, 0], c[:, 3] - c[:, 0]),
    )
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    texel = origin[quads] + np.stack([i, j], axis=1)
    return points, normals, quads, texel


@dataclass
class Texels:
    """An atlas's tile texels: (K, 3) centres and normals, (K,) quads, (K, 2) texel
    (column, row), and (H, W) masks of the texels inside a tile and of those seen (inside
    and not hidden: :func:`hidden_texels`)."""

    points: np.ndarray
    normals: np.ndarray
    quads: np.ndarray
    texel: np.ndarray
    inside: np.ndarray
    seen: np.ndarray

    @property
    def visible(self) -> np.ndarray:
        """(K,) bool: which of the K texels are seen."""
        return self.seen[self.texel[:, 1], self.texel[:, 0]]


def tile_texels(scene: Scene, layout: Atlas) -> Texels:
    """The tile texels of ``layout`` with their centres (:func:`texel_points`) and which
    are hidden (:func:`hidden_texels`)."""
    points, normals, quads, texel = texel_points(quad_corners(scene), layout.origin, layout.size)
    inside = np.zeros((layout.height, layout.width), dtype=bool)
    inside[texel[:, 1], texel[:, 0]] = True
    seen = inside.copy()
    hidden = hidden_texels(scene, points, normals)
    seen[texel[hidden, 1], texel[hidden, 0]] = False
    return Texels(points, normals, quads, texel, inside, seen)


def finish(image: np.ndarray, texels: Texels, gutter: int, layout: Atlas) -> None:
    """Fill the hidden texels of ``image`` (H, W, C) from the seen ones (:func:`dilate`),
    then extend every tile's edge into its gutter (:func:`fill_gutters`), in place."""
    dilate(image, texels.seen, texels.inside)
    fill_gutters(image, layout.origin, layout.size, gutter)


def hidden_texels(scene: Scene, points: np.ndarray, normals: np.ndarray, rays: int = 16):
    """(N,) bool: texel centres no one sees, under or inside geometry (a floor texel under
    a block, the ceiling behind the light): :func:`bench_accuracy.hidden_points`, which
    finds the probes the race leaves out too. A lightmap baker leaves such texels out and
    fills them from their neighbours (:func:`dilate`); read as they are, they bleed their
    darkness a texel onto what is seen. Traced with raytrad's Embree adapter, whatever
    renderer made the image."""
    return hidden_points(scene, points, normals, rays)


def fill_gutters(image: np.ndarray, origin: np.ndarray, size: np.ndarray, gutter: int) -> None:
    """Extend each tile's edge texels ``gutter`` texels outwards in ``image`` (H, W, C), in
    place: Blender's ``EXTEND`` bake margin."""
    for (x, y), (w, h) in zip(origin, size, strict=True):
        tile = image[y : y + h, x : x + w]
        padded = np.pad(tile, ((gutter, gutter), (gutter, gutter), (0, 0)), mode="edge")
        image[y - gutter : y + h + gutter, x - gutter : x + w + gutter] = padded


def dilate(image: np.ndarray, known: np.ndarray, inside: np.ndarray) -> None:
    """Fill the texels of ``image`` (H, W, C) that are ``inside`` a tile but not ``known``
    (both (H, W) bool) with the mean of their known 4-neighbours, a ring at a time, in
    place; gutters (not ``inside``) are neither read nor filled, so no tile takes
    another's values."""
    known = known & inside
    while True:
        total = np.zeros_like(image)
        count = np.zeros(known.shape)
        for axis, step in ((0, 1), (0, -1), (1, 1), (1, -1)):
            total += np.roll(image * known[..., None], step, axis=axis)
            count += np.roll(known, step, axis=axis)
        ring = inside & ~known & (count > 0)
        if not ring.any():
            return
        image[ring] = total[ring] / count[ring][:, None]
        known = known | ring
