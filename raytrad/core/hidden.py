"""Receivers the solve hides, and what a bake shows there.

A receiver under a block standing on the floor (see
:func:`hide_receivers`) keeps only its emission in the solve. Every
product that interpolates the radiosity (images, lightmaps, the residual check of
:mod:`raytrad.core.accuracy`, which reads the bake where its rays land) reads
:func:`fill_hidden`'s values instead.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from raytrad.arrays import unique
from raytrad.core.mesh import RadiosityMesh


def fill_hidden(mesh: RadiosityMesh, radiosity: np.ndarray, rings: int = 64) -> np.ndarray:
    """Radiosity for display, with hidden receivers given their visible neighbours' mean.

    A hidden receiver (under a block standing on the floor, see
    :func:`hide_receivers`) keeps only its own emission in the solve,
    but the triangles joining it to visible receivers are partly visible: interpolating
    toward its value would draw a dark saw-tooth rim along the block's base in images and
    lightmaps. Filling it from its edge neighbours on the same surface (receivers are split
    at creases and material changes), ring by ring inward, removes that rim; what no one
    sees is unchanged.

    Parameters
    ----------
    mesh : RadiosityMesh
    radiosity : (R, 3) float [W m-2]
    rings : int
        Most rings of hidden receivers filled inward from the visible ones.

    Returns
    -------
    (R, 3) float64 [W m-2]
        ``radiosity`` where visible (and where no visible receiver is within ``rings``).
    """
    out = np.array(radiosity, dtype=np.float64)
    if mesh.receiver_visible is None:
        return out
    known = np.asarray(mesh.receiver_visible, dtype=bool).copy()
    if known.all():
        return out
    tri = mesh.triangle_receivers
    a = np.concatenate([tri[:, 0], tri[:, 1], tri[:, 2], tri[:, 1], tri[:, 2], tri[:, 0]])
    b = np.concatenate([tri[:, 1], tri[:, 2], tri[:, 0], tri[:, 0], tri[:, 1], tri[:, 2]])
    filled = ~known[a]  # only hidden receivers are filled: the edges from them
    a, b = a[filled], b[filled]
    count = len(out)
    key = unique(a.astype(np.int64) * count + b)  # each neighbour once, sorted by a, b
    a, b = key // count, key % count
    for _ in range(rings):
        todo = ~known
        if not todo.any():
            break
        use = known[b] & todo[a]
        if not use.any():
            break
        total = np.zeros_like(out)
        np.add.at(total, a[use], out[b[use]])
        seen = np.bincount(a[use], minlength=count)
        ring = seen > 0
        out[ring] = total[ring] / seen[ring, None]
        known |= ring
    return out


def hide_receivers(mesh: RadiosityMesh, hidden: np.ndarray) -> RadiosityMesh:
    """The mesh with receivers that can neither see nor be seen taken out of the surface.

    A receiver under a block standing on the floor sees only the block's inside. Its
    radiosity stays as computed (its emission), but it no longer counts in its patch's
    mean radiosity, its area is zero and its patch's area shrinks by its share, so a patch
    half under the block shoots its visible half's radiosity from its visible area, and a
    closed room loses no energy through the block's footprint.

    Parameters
    ----------
    mesh : RadiosityMesh
    hidden : (R,) bool
    """
    if not hidden.any():
        return mesh
    visible = ~np.asarray(hidden, dtype=bool)
    corner_share = np.repeat(mesh.triangle_area / 3.0, 3) * visible[mesh.triangle_receivers].ravel()
    patch_area = np.bincount(
        np.repeat(mesh.triangle_patch, 3), weights=corner_share, minlength=mesh.patch_count
    )
    floor = 1e-12 * float(mesh.patch_area.sum())
    return replace(
        mesh,
        receiver_area=mesh.receiver_area * visible,
        patch_area=np.maximum(patch_area, floor),
        receiver_visible=visible,
    )
