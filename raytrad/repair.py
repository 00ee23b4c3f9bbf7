"""Fixing what CAD export and hand modelling get wrong, with a warning for each fix.

* **Duplicate faces**: the same triangle twice (coincident coplanar faces) would receive and
  shoot twice, doubling the light it sends. One copy is kept. A copy with the opposite
  winding is the other side of a two-sided surface and stays.
* **Inverted faces**: in a connected, edge-sharing surface (a closed room, a block), every
  shared edge is walked in opposite directions by its two faces. Faces whose winding
  disagrees with the larger part (by area) of their surface were modelled inside out: a room
  wall facing outside would swallow all the light reaching its back. They are flipped.
"""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np

from raytrad.mesh import merge_vertices
from raytrad.scene import Scene, triangle_areas_normals

log = logging.getLogger(__name__)


def repair_scene(scene: Scene) -> Scene:
    """The scene without duplicate faces and with consistent winding (see module doc)."""
    used = np.unique(scene.triangles)
    extent = float(np.ptp(scene.positions[used], axis=0).max())
    _, merged = merge_vertices(scene.positions, scene.triangles, extent * 1e-9)
    where = scene.source or "<scene>"
    keep = _first_of_duplicates(merged)
    if not keep.all():
        log.warning(
            "%s: dropped %d duplicate faces (the same triangle twice would double its light)",
            where,
            int((~keep).sum()),
        )
        scene = replace(
            scene, triangles=scene.triangles[keep], material_index=scene.material_index[keep]
        )
        merged = merged[keep]
    areas, _ = triangle_areas_normals(scene.triangle_vertices())
    flip = inverted_faces(merged, areas)
    if flip.any():
        log.warning(
            "%s: flipped %d faces whose winding disagrees with the rest of their surface "
            "(inside-out faces would swallow the light reaching their back)",
            where,
            int(flip.sum()),
        )
        triangles = scene.triangles.copy()
        triangles[flip] = triangles[flip][:, ::-1]
        scene = replace(scene, triangles=triangles)
    return scene


def _first_of_duplicates(triangles: np.ndarray) -> np.ndarray:
    """(T,) bool: True for the first face of each set with the same corners and winding."""
    # the same cyclic order starting from the smallest vertex identifies a winding
    start = np.argmin(triangles, axis=1)
    order = (start[:, None] + np.arange(3)[None, :]) % 3
    canonical = np.take_along_axis(triangles, order, axis=1)
    _, first = np.unique(canonical, axis=0, return_index=True)
    keep = np.zeros(len(triangles), dtype=bool)
    keep[first] = True
    return keep


def inverted_faces(triangles: np.ndarray, areas: np.ndarray) -> np.ndarray:
    """(T,) bool: faces to flip so each edge-connected surface has one winding.

    Two faces sharing an edge (and only two: non-manifold edges carry no constraint) agree
    when they walk it in opposite directions. Orientation parity is propagated over the
    agreement graph; within each connected part the parity class with less area flips.

    Parameters
    ----------
    triangles : (T, 3) int64
        Faces over merged vertices.
    areas : (T,) float64
        Face areas [m2].
    """
    count = len(triangles)
    a = triangles.reshape(-1)
    b = np.roll(triangles, -1, axis=1).reshape(-1)
    key = np.stack([np.minimum(a, b), np.maximum(a, b)], axis=1)
    forward = a < b
    face = np.repeat(np.arange(count), 3)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    manifold = counts[inverse] == 2
    order = np.argsort(inverse[manifold], kind="stable")
    f = face[manifold][order].reshape(-1, 2)
    d = forward[manifold][order].reshape(-1, 2)
    # same direction along the shared edge means the two windings disagree
    disagree = d[:, 0] == d[:, 1]
    label, parity = _parity_components(count, f, disagree)
    flip = np.zeros(count, dtype=bool)
    for part in np.unique(label[parity == 1]):
        members = label == part
        odd = members & (parity == 1)
        if areas[odd].sum() < areas[members & (parity == 0)].sum():
            flip |= odd
        else:
            flip |= members & (parity == 0)
    return flip


def _parity_components(
    count: int, pairs: np.ndarray, odd: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Connected components of faces, and each face's parity relative to its root.

    Breadth-first over the pair graph, vectorised by frontier; parity(b) = parity(a) xor odd.
    """
    label = np.full(count, -1, dtype=np.int64)
    parity = np.zeros(count, dtype=np.int8)
    if len(pairs) == 0:
        return np.arange(count), parity
    both = np.concatenate([pairs, pairs[:, ::-1]])
    both_odd = np.concatenate([odd, odd]).astype(np.int8)
    order = np.argsort(both[:, 0], kind="stable")
    src, dst, rel = both[order, 0], both[order, 1], both_odd[order]
    ptr = np.searchsorted(src, np.arange(count + 1))
    isolated = ptr[1:] == ptr[:-1]
    label[isolated] = np.nonzero(isolated)[0]
    for root in np.nonzero(~isolated)[0]:
        if label[root] >= 0:
            continue
        label[root] = root
        frontier = np.array([root])
        while len(frontier):
            starts, stops = ptr[frontier], ptr[frontier + 1]
            n = stops - starts
            idx = np.repeat(starts, n) + (np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n))
            nxt, p = dst[idx], parity[src[idx]] ^ rel[idx]
            new = label[nxt] < 0
            nxt, p = nxt[new], p[new]
            nxt, first = np.unique(nxt, return_index=True)
            label[nxt] = root
            parity[nxt] = p[first]
            frontier = nxt
    return label, parity
