"""The exact unoccluded factor of a planar patch from its outline alone.

Lambert's formula for a planar polygon is a sum over its boundary edges; the interior
edges of a triangulated patch cancel. So a patch's factor costs its outline's edges
however finely it is triangulated:

* :func:`contour_form_factor`: the patch wholly above the receiver's horizon;
* :func:`planar_contour_form_factor`: either, chosen per receiver (0 behind the patch or
  with all of it below the horizon), in one pass;
* :func:`clipped_contour_form_factor`: the patch straddling it (a floor patch running
  under a block, seen from the block's side). The part above the horizon is bounded by
  the outline's edges clipped to the receiver's tangent plane and by cuts along the line
  where the patch's plane meets it. Each cut runs from a point where the outline leaves
  the half-space to the next point where it comes back; all of them lie on that one
  line, which misses the receiver, and there Lambert's edge terms are signed angles that
  add up, ``term(a, b) = term(o, b) - term(o, a)`` for any point ``o`` of the line. So the
  cuts sum to the entry points' terms from ``o`` less the exit points', whichever exit
  pairs with whichever entry: no sorting of the crossings, holes and concave outlines
  included.

Per triangle (:func:`~raytrad.core.kernels.numpy_facing_triangle_sums`) the straddling case
costs the patch's triangle count per receiver, which grows with refinement: the pairs'
cost grew as receivers squared over patches. On the outline it stays put.

* :func:`piecewise_contour_form_factor`: a folded patch (a warped quad, a patch of a
  curved surface), piece by planar piece (a piece per scene triangle), each piece seen
  from its front only and clipped to the horizon. The compiled loop sums the pieces
  that face the receiver and lie wholly above its horizon as one region, on the
  region's own outline: their signed sums share a sign, and an edge between two of them
  is walked once each way. A ball's patch of 512 triangles, seen from the floor beside
  it, then costs the edges around its lit part, not three per triangle.

Both run compiled (:mod:`raytrad.core.compiled`) when available; the ``numpy_`` twins
are the reference the tests compare them with.

References
----------
Baum, D. R., Rushmeier, H. E. and Winget, J. M. (1989). Improving radiosity solutions
through the use of analytically determined form-factors. SIGGRAPH '89, 325-334.
"""

from __future__ import annotations

import math

import numpy as np

from raytrad.core import compiled
from raytrad.core.kernels import _f64, edge_sum, edge_terms
from raytrad.core.outline import Pieces


def contour_form_factor(
    start: np.ndarray, end: np.ndarray, points: np.ndarray, normals: np.ndarray
) -> np.ndarray:
    """Lambert's formula over a boundary contour, compiled when available (see
    :func:`numpy_contour_form_factor`, the reference)."""
    fast = compiled.get()
    if fast is None:
        return numpy_contour_form_factor(start, end, points, normals)
    return fast.contour_form_factor(_f64(start), _f64(end), _f64(points), _f64(normals))


def numpy_contour_form_factor(
    start: np.ndarray, end: np.ndarray, points: np.ndarray, normals: np.ndarray
) -> np.ndarray:
    """Lambert's formula summed over the boundary edges of a surface.

    Parameters
    ----------
    start, end : (E, 3) float64
        Oriented boundary edges of one surface [m], wholly above every receiver's horizon.
    points : (C, 3) float64
        Receiver positions [m].
    normals : (C, 3) float64
        Receiver unit normals.

    Returns
    -------
    (C,) float64 unoccluded form factors [1].
    """
    return edge_sum(
        start[None, :, :] - points[:, None, :], end[None, :, :] - points[:, None, :], normals
    )


def clipped_contour_form_factor(
    start: np.ndarray, end: np.ndarray, points: np.ndarray, normals: np.ndarray
) -> np.ndarray:
    """Lambert's formula over a planar contour clipped to each receiver's horizon,
    compiled when available (see :func:`numpy_clipped_contour_form_factor`, the
    reference)."""
    fast = compiled.get()
    if fast is None:
        return numpy_clipped_contour_form_factor(start, end, points, normals)
    return fast.clipped_contour_form_factor(_f64(start), _f64(end), _f64(points), _f64(normals))


def numpy_clipped_contour_form_factor(
    start: np.ndarray, end: np.ndarray, points: np.ndarray, normals: np.ndarray
) -> np.ndarray:
    """Exact unoccluded factor of the part of a planar surface above each receiver's
    horizon, from its outline (see the module notes).

    Equal, up to rounding, to the sum over the surface's triangles of their
    horizon-clipped factors (:func:`~raytrad.core.kernels.numpy_facing_triangle_sums`)
    where the surface faces the receiver. A corner exactly on the horizon counts as above
    it, as in :func:`~raytrad.core.kernels.clip_to_horizon`.

    Parameters
    ----------
    start, end : (E, 3) float64
        Oriented boundary edges of one planar surface [m] (every loop, holes included,
        in the winding of its triangles).
    points : (C, 3) float64
        Receiver positions [m], off the surface's plane.
    normals : (C, 3) float64
        Receiver unit normals.

    Returns
    -------
    (C,) float64 unoccluded form factors [1]; 0 where nothing is above the horizon.
    """
    u = start[None, :, :] - points[:, None, :]  # (C, E, 3)
    v = end[None, :, :] - points[:, None, :]
    hu = np.einsum("cej,cj->ce", u, normals)
    hv = np.einsum("cej,cj->ce", v, normals)
    in_u, in_v = hu >= 0.0, hv >= 0.0
    crossing = in_u != in_v
    t = hu / np.where(crossing, hu - hv, 1.0)
    p = u + np.where(crossing, t, 0.0)[:, :, None] * (v - u)  # where it crosses [m]
    a = np.where(in_u[:, :, None], u, p)
    b = np.where(in_v[:, :, None], v, p)
    kept = np.where(in_u | in_v, edge_terms(a, b, normals), 0.0).sum(axis=1)
    # cuts along the horizon: entries' terms from the first crossing, less the exits'
    first = np.argmax(crossing, axis=1)
    o = np.broadcast_to(p[np.arange(len(points)), first][:, None, :], p.shape)
    sign = np.where(crossing, np.where(in_v, 1.0, -1.0), 0.0)
    cuts = (sign * edge_terms(o, p, normals)).sum(axis=1)
    return np.abs(kept + cuts) / (2.0 * math.pi)


def piecewise_contour_form_factor(
    pieces: Pieces, patch: int, points: np.ndarray, normals: np.ndarray, margin: float
) -> np.ndarray:
    """The factor of a folded patch, piece by planar piece, compiled when available (see
    :func:`numpy_piecewise_contour_form_factor`, the reference)."""
    fast = compiled.get()
    lo, hi = pieces.patch_ptr[patch], pieces.patch_ptr[patch + 1]
    if fast is None:
        return numpy_piecewise_contour_form_factor(pieces, patch, points, normals, margin)
    return fast.piecewise_contour_form_factor(
        _f64(pieces.start),
        _f64(pieces.end),
        np.ascontiguousarray(pieces.edge_ptr[lo : hi + 1], dtype=np.int64),
        _f64(pieces.point[lo:hi]),
        _f64(pieces.normal[lo:hi]),
        pieces.twin_piece[pieces.edge_ptr[lo] : pieces.edge_ptr[hi]] - lo,
        _f64(points),
        _f64(normals),
        float(margin),
    )


def numpy_piecewise_contour_form_factor(
    pieces: Pieces, patch: int, points: np.ndarray, normals: np.ndarray, margin: float
) -> np.ndarray:
    """Exact unoccluded factor of a folded patch: the sum over its planar pieces
    (:func:`~raytrad.core.outline.folded_pieces`) that face each receiver by more than
    ``margin`` of their outlines' horizon-clipped factors.

    Equal, up to rounding, to the triangle-by-triangle sum
    (:func:`~raytrad.core.kernels.numpy_facing_triangle_sums`), at a cost that follows
    the scene's triangles in the patch, not the refined ones.

    Parameters
    ----------
    pieces : Pieces
    patch : int
    points, normals : (C, 3) float64
        Receiver positions [m] and unit normals.
    margin : float
        Height in front of a piece's plane below which it is not seen, and above the
        receiver's horizon that some corner must reach for the patch to count [m].

    Returns
    -------
    (C,) float64 form factors [1].
    """
    out = np.zeros(len(points))
    # a patch within ``margin`` of the horizon or below it (its heights are extreme at its
    # pieces' outlines' corners) gives nothing
    first, last = pieces.patch_ptr[patch], pieces.patch_ptr[patch + 1]
    corners = pieces.start[pieces.edge_ptr[first] : pieces.edge_ptr[last]]
    top = (corners @ normals.T).max(axis=0, initial=-np.inf) - np.einsum(
        "cj,cj->c", points, normals
    )
    seen = top > margin
    if seen.any():
        out[seen] = _numpy_pieces(pieces, patch, points[seen], normals[seen], margin)
    return out


def _numpy_pieces(
    pieces: Pieces, patch: int, points: np.ndarray, normals: np.ndarray, margin: float
) -> np.ndarray:
    """(C,) the sum over the patch's pieces facing each point by more than ``margin`` of
    their horizon-clipped outlines' factors [1]."""
    out = np.zeros(len(points))
    for k in range(pieces.patch_ptr[patch], pieces.patch_ptr[patch + 1]):
        front = (points - pieces.point[k]) @ pieces.normal[k] > margin
        if front.any():
            lo, hi = pieces.edge_ptr[k], pieces.edge_ptr[k + 1]
            out[front] += numpy_clipped_contour_form_factor(
                pieces.start[lo:hi], pieces.end[lo:hi], points[front], normals[front]
            )
    return out


def planar_contour_form_factor(
    start: np.ndarray,
    end: np.ndarray,
    points: np.ndarray,
    normals: np.ndarray,
    patch_normal: np.ndarray,
    patch_center: np.ndarray,
    band: float,
) -> np.ndarray:
    """A planar patch's exact unoccluded factor, compiled when available (see
    :func:`numpy_planar_contour_form_factor`, the reference)."""
    fast = compiled.get()
    if fast is None:
        return numpy_planar_contour_form_factor(
            start, end, points, normals, patch_normal, patch_center, band
        )
    return np.asarray(
        fast.planar_contour_form_factor(
            _f64(start),
            _f64(end),
            _f64(points),
            _f64(normals),
            _f64(patch_normal),
            _f64(patch_center),
            float(band),
        )
    )


def numpy_planar_contour_form_factor(
    start: np.ndarray,
    end: np.ndarray,
    points: np.ndarray,
    normals: np.ndarray,
    patch_normal: np.ndarray,
    patch_center: np.ndarray,
    band: float,
) -> np.ndarray:
    """Exact unoccluded factor of a one-sided planar patch with outline ``start -> end``:
    0 for receivers not in front of it by more than ``band`` or with all of it below
    their horizon, the whole outline's sum (:func:`numpy_contour_form_factor`) where it
    lies above, the clipped outline's (:func:`numpy_clipped_contour_form_factor`) where
    it straddles. A plane's heights are extreme at its outline's corners.

    Parameters
    ----------
    start, end : (E, 3) float64
        The outline's edges [m].
    points, normals : (C, 3) float64
        Receiver positions [m] and unit normals.
    patch_normal, patch_center : (3,) float64
        The patch's lit side and centre [m].
    band : float
        Heights within it of a plane count as on it [m].

    Returns
    -------
    (C,) float64 form factors [1].
    """
    height = start @ normals.T - np.einsum("cj,cj->c", points, normals)[None, :]  # (E, C)
    facing = (points - patch_center) @ patch_normal > band
    top = np.where(facing, height.max(axis=0), -np.inf)
    above = (height.min(axis=0) >= -band) & (top > band)
    out = np.zeros(len(points))
    if above.any():
        out[above] = numpy_contour_form_factor(start, end, points[above], normals[above])
    straddle = ~above & (top > band)
    if straddle.any():
        out[straddle] = numpy_clipped_contour_form_factor(
            start, end, points[straddle], normals[straddle]
        )
    return out


__all__ = [
    "clipped_contour_form_factor",
    "contour_form_factor",
    "numpy_clipped_contour_form_factor",
    "numpy_contour_form_factor",
    "numpy_piecewise_contour_form_factor",
    "numpy_planar_contour_form_factor",
    "piecewise_contour_form_factor",
    "planar_contour_form_factor",
]
