"""Camera renders of a solution: Embree primary rays, radiance B/pi from the receivers.

The image is the converged radiosity seen through a pinhole camera: each ray's hit point
on the refined mesh takes the barycentric interpolation of its triangle's receivers, and
the radiance of a Lambertian surface is B / pi [W sr-1 m-2]. A few stratified samples per
pixel anti-alias edges.
"""

from __future__ import annotations

import math

import numpy as np

from raytrad.constants import defaults
from raytrad.core.mesh import RadiosityMesh
from raytrad.core.shading import shade, triangle_normals, twin_triangles
from raytrad.core.visibility import Occluder
from raytrad.errors import SettingsError
from raytrad.scene import Camera


def primary_directions(
    camera: Camera,
    width: int,
    height: int,
    jitter_x: np.ndarray | float,
    jitter_y: np.ndarray | float,
) -> np.ndarray:
    """(height * width, 3) unit ray directions through each pixel at the given offsets.

    ``jitter_x``, ``jitter_y``: position inside the pixel in [0, 1) (scalars or
    (height, width) arrays); row 0 is the top of the image.
    """
    right, up, forward = camera.basis()
    tan = math.tan(math.radians(camera.vertical_fov_deg) / 2.0)
    ys, xs = np.mgrid[0:height, 0:width]
    px = (xs + jitter_x) / width * 2.0 - 1.0
    py = 1.0 - (ys + jitter_y) / height * 2.0
    direction = (
        forward[None, None, :]
        + (px * tan * width / height)[..., None] * right
        + (py * tan)[..., None] * up
    ).reshape(-1, 3)
    return np.asarray(direction / np.linalg.norm(direction, axis=1)[:, None])


def seen_receivers(
    mesh: RadiosityMesh, camera: Camera, width: int = 64, height: int = 48
) -> np.ndarray:
    """(R,) how much of a small image from ``camera`` each receiver fills [pixels].

    Each pixel's primary ray is split over the corners of the triangle it hits by their
    barycentric weights, so the weights say what the camera sees (for the image's own
    exposure); a receiver out of view gets 0.
    """
    occluder = Occluder(mesh.positions, mesh.triangles)
    try:
        origin = occluder.to_local(np.asarray(camera.position, dtype=np.float64)[None, :])
        direction = primary_directions(camera, width, height, 0.5, 0.5)
        hit, _, weights = occluder.intersect_barycentric_local(
            np.broadcast_to(origin, direction.shape), direction
        )
    finally:
        occluder.close()
    seen = hit >= 0
    counts = np.zeros(len(mesh.receiver_position))
    np.add.at(counts, mesh.triangle_receivers[hit[seen]].ravel(), weights[seen].ravel())
    return counts


def render_radiance(
    mesh: RadiosityMesh,
    radiosity: np.ndarray,
    camera: Camera,
    width: int = defaults.image_width,
    height: int = defaults.image_height,
    samples: int = defaults.image_samples,
    seed: int = 0,
) -> np.ndarray:
    """Render the radiance of a solution.

    Parameters
    ----------
    mesh : RadiosityMesh
    radiosity : (R, 3) float64
        Receiver radiosity [W m-2].
    camera : Camera
    width, height : int
        Image size [pixels].
    samples : int
        Stratified samples per pixel (rounded down to a square number, at least 1).

    Returns
    -------
    (height, width, 3) float32 radiance [W sr-1 m-2]; background 0.
    """
    if width < 1 or height < 1:
        raise SettingsError(f"image size must be positive, got {width}x{height}")
    side = max(1, math.isqrt(max(1, samples)))
    rng = np.random.default_rng(seed)
    _, normal = triangle_normals(mesh)
    twin = twin_triangles(mesh.triangles)
    image = np.zeros((height, width, 3))
    occluder = Occluder(mesh.positions, mesh.triangles)
    try:
        origin = occluder.to_local(np.asarray(camera.position, dtype=np.float64)[None, :])
        for sy in range(side):
            for sx in range(side):
                jitter = rng.random((2, height, width))
                direction = primary_directions(
                    camera, width, height, (sx + jitter[0]) / side, (sy + jitter[1]) / side
                )
                hit, _, weights = occluder.intersect_barycentric_local(
                    np.broadcast_to(origin, direction.shape), direction
                )
                image += shade(hit, weights, direction, mesh, radiosity, normal, twin).reshape(
                    height, width, 3
                )
    finally:
        occluder.close()
    return (image / (side * side) / math.pi).astype(np.float32)
