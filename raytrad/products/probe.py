"""The baked radiosity at arbitrary surface points: what a lightmap texel or an image pixel
there shows (the vertex radiosity interpolated over the refined triangle under the point).
"""

from __future__ import annotations

import numpy as np

from raytrad.constants import scene_diagonal
from raytrad.core.mesh import RadiosityMesh
from raytrad.core.shading import shade, triangle_normals, twin_triangles
from raytrad.core.visibility import Occluder

#: Probe rays start this fraction of the scene diagonal off the surface [1].
PROBE_LIFT = 1e-4


def radiosity_at(
    mesh: RadiosityMesh, radiosity: np.ndarray, points: np.ndarray, normals: np.ndarray
) -> np.ndarray:
    """Radiosity shown at surface points, on the side their normals face.

    Parameters
    ----------
    mesh : RadiosityMesh
    radiosity : (R, 3) float [W m-2]
        Per receiver (the shown radiosity, see :func:`raytrad.core.hidden.fill_hidden`).
    points : (N, 3) float
        Points on the mesh's surfaces [m].
    normals : (N, 3) float
        Unit normals of the side to read.

    Returns
    -------
    (N, 3) float64 [W m-2]
        NaN where no surface lies under a point (within ``PROBE_LIFT`` of the diagonal).
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    lift = PROBE_LIFT * scene_diagonal(mesh.positions)
    _, normal = triangle_normals(mesh)
    occluder = Occluder(mesh.positions, mesh.triangles)
    try:
        origin = occluder.to_local(points + 2.0 * lift * normals)
        hit, distance, weights = occluder.intersect_barycentric_local(origin, -normals)
    finally:
        occluder.close()
    out = shade(hit, weights, -normals, mesh, radiosity, normal, twin_triangles(mesh.triangles))
    missed = (hit < 0) | (np.abs(distance - 2.0 * lift) > lift)
    out[missed] = np.nan
    return out


def hemisphere_gather(
    mesh: RadiosityMesh,
    radiosity: np.ndarray,
    points: np.ndarray,
    normals: np.ndarray,
    rays: int = 4096,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """Irradiance at surface points gathered from a solution by Monte Carlo.

    Cosine-distributed rays from each point read the radiosity the solution shows where
    they land (:func:`radiosity_at`'s interpolation); the irradiance is the mean of what
    they read, ``H = (1/N) sum B_hit`` (a Lambertian surface of radiosity B has radiance
    B / pi, and cosine sampling has density cos / pi). It checks how a solution's
    receivers gather, independently of form factors and patches.

    Parameters
    ----------
    mesh : RadiosityMesh
    radiosity : (R, 3) float [W m-2]
    points : (N, 3) float [m]
    normals : (N, 3) float, unit
    rays : int
        Rays per point.
    seed : int

    Returns
    -------
    irradiance : (N, 3) float64 [W m-2]
    standard_error : (N, 3) float64 [W m-2]
    """
    from raytrad.core.pathtrace import cosine_directions

    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    rng = np.random.default_rng(seed)
    lift = PROBE_LIFT * scene_diagonal(mesh.positions)
    _, normal = triangle_normals(mesh)
    twin = twin_triangles(mesh.triangles)
    mean = np.zeros((len(points), 3))
    error = np.zeros((len(points), 3))
    occluder = Occluder(mesh.positions, mesh.triangles)
    try:
        for i in range(len(points)):
            direction = cosine_directions(np.tile(normals[i], (rays, 1)), rng)
            origin = np.tile(occluder.to_local(points[i : i + 1] + lift * normals[i]), (rays, 1))
            hit, _, weights = occluder.intersect_barycentric_local(origin, direction)
            seen = shade(hit, weights, direction, mesh, radiosity, normal, twin)
            mean[i] = seen.mean(axis=0)
            error[i] = seen.std(axis=0) / np.sqrt(rays)
    finally:
        occluder.close()
    return mean, error
