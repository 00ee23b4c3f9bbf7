"""One home for numerical tolerances and shared defaults (in the manner of trimesh's ``tol``).

Tolerances
----------
Every length tolerance is *relative to the size of the scene* it is used in, so a model in
millimetres, in kilometres or placed far from the origin makes the same decisions. Two size
measures are used, and each tolerance says which:

* the **extent**: the largest side of the bounding box of the used vertices [m]
  (:func:`scene_extent`);
* the **diagonal**: the length of that bounding box's diagonal [m] (:func:`scene_diagonal`).

A decision taken on the *sign* of a computed quantity (a fitted slope, a determinant, a
point's side of a plane, a height above a receiver's horizon, a 2-D orientation) compares
it against a band scaled to the data it came from, never against zero, wherever the branch
it picks changes the answer discontinuously. Signs whose branches agree in the limit (a
sample whose weight goes to zero with its cosine) need no band.

Defaults
--------
:data:`defaults` holds the values more than one module offers a first-time user (image
size, field of view, lightmap size), named once here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Tolerances:
    """Relative tolerances; multiply by the size measure each names.

    Attributes
    ----------
    merge : float
        Vertices closer than ``merge`` x extent are one vertex (repair, meshing) [1].
    on_edge : float
        A vertex within ``on_edge`` x extent of an edge's interior lies on it: a
        T-junction [1].
    plane : float
        A vertex within ``plane`` x extent behind a triangle's plane counts as on it when
        proving that nothing can occlude (a convex enclosure) [1].
    ray_offset : float
        Rays start, and end, ``ray_offset`` x diagonal off the surface, along its normal:
        float32 cannot resolve a smaller lift at grazing angles [1].
    ray_margin : float
        Segment occlusion tests leave ``ray_margin`` x diagonal free at their far end, and
        hemisphere probes start that far off their surface [1].
    horizon : float
        A point within ``horizon`` x diagonal of a receiver's tangent plane (or a patch's
        plane) is on it: horizon clipping, facing and culling tests [1].
    parallel : float
        Unit vectors whose dot product is within ``parallel`` of +-1 are parallel (planar
        patches, coplanar faces); a unit-vector dot product within ``parallel`` of 0 is
        grazing [1].
    collinear : float
        Edges whose cross product is at most ``collinear`` x the product of their lengths
        are collinear [1].
    tie : float
        Values equal to within ``tie`` of the largest are tied, so rounding never decides
        (longest edge, bisection) [1].
    degenerate : float
        A triangle of area at most ``degenerate`` x its longest edge squared has no
        area: collinear corners up to float64 rounding [1].
    singular : float
        A (3, 3) transform whose determinant is at most ``singular`` x the product of its
        column lengths flattens space; its sign (a mirror or not) is noise [1].
    fit : float
        A fitted slope whose change over the fitted span is at most ``fit`` x the largest
        magnitude of the fitted values is flat [1].
    """

    merge: float = 1e-9
    on_edge: float = 1e-7
    plane: float = 1e-7
    ray_offset: float = 1e-5
    ray_margin: float = 1e-6
    horizon: float = 1e-9
    parallel: float = 1e-9
    collinear: float = 1e-12
    tie: float = 1e-9
    degenerate: float = 1e-13
    singular: float = 1e-12
    fit: float = 1e-9


#: The tolerances raytrad uses.
tol = Tolerances()

FLOAT32_MAX = float(np.finfo(np.float32).max)
"""The largest float32 [1]: outputs (PLY, EXR, glTF) hold float32, so coordinates and
emission beyond it are refused on load."""


@dataclass(frozen=True)
class Defaults:
    """Values offered to a first-time user by more than one module.

    Attributes
    ----------
    vertical_fov_deg : float
        Vertical field of view of a camera that gives none [degrees] (the Cornell box
        camera's).
    image_width, image_height : int
        Camera image size [pixels] when neither options nor the scene file give one.
    image_samples : int
        Samples per pixel of a camera image.
    lightmap_resolution : int
        Side of a generated lightmap atlas [texels].
    lightmap_padding : int
        Texels between lightmap charts.
    cache_mb : float
        Memory for cached form-factor columns [MiB].
    """

    vertical_fov_deg: float = 39.3
    image_width: int = 640
    image_height: int = 480
    image_samples: int = 4
    lightmap_resolution: int = 1024
    lightmap_padding: int = 4
    cache_mb: float = 1024.0


#: The defaults raytrad offers.
defaults = Defaults()


def scene_extent(positions: np.ndarray) -> float:
    """Largest side of the bounding box of ``positions`` ((N, 3) float) [m]."""
    return float(np.ptp(np.asarray(positions, dtype=np.float64), axis=0).max())


def scene_diagonal(positions: np.ndarray) -> float:
    """Length of the diagonal of the bounding box of ``positions`` ((N, 3) float) [m]."""
    return float(np.linalg.norm(np.ptp(np.asarray(positions, dtype=np.float64), axis=0)))


def sign_with_band(value: np.ndarray, band: np.ndarray | float) -> np.ndarray:
    """-1, 0 or +1: the sign of ``value``, 0 where ``|value| <= band``.

    Parameters
    ----------
    value : array_like
        The computed quantity.
    band : array_like
        Its tolerance, scaled to the data it came from (broadcast against ``value``).

    Returns
    -------
    ndarray of int8
    """
    value = np.asarray(value, dtype=np.float64)
    return np.where(np.abs(value) <= band, 0, np.sign(value)).astype(np.int8)


__all__ = [
    "FLOAT32_MAX",
    "Defaults",
    "Tolerances",
    "defaults",
    "scene_diagonal",
    "scene_extent",
    "sign_with_band",
    "tol",
]
