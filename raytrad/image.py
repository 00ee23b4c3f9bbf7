"""Camera renders of a solution: Embree primary rays, radiance B/pi from the receivers.

The image is the converged radiosity seen through a pinhole camera: each ray's hit point
on the refined mesh takes the barycentric interpolation of its triangle's receivers, and
the radiance of a Lambertian surface is B / pi [W sr-1 m-2]. A few stratified samples per
pixel anti-alias edges.
"""

from __future__ import annotations

import math

import numpy as np

from raytrad.camera import Camera
from raytrad.errors import SettingsError
from raytrad.mesh import RadiosityMesh
from raytrad.visibility import Occluder

#: Directions from the scene's centre toward outside viewpoints tried by
#: :func:`automatic_camera`, after the classic front view of :func:`framing_camera`:
#: elevated three-quarter views, then the four sides.
_OUTSIDE_VIEWS = (
    (1.0, 0.8, -1.0),
    (-1.0, 0.8, -1.0),
    (1.0, 0.8, 1.0),
    (-1.0, 0.8, 1.0),
    (0.0, 0.0, 1.0),
    (1.0, 0.0, 0.0),
    (-1.0, 0.0, 0.0),
)
#: Fraction of the frame covered by surfaces that counts as filled for the view score.
_FULL_COVERAGE = 0.5
#: Where inside viewpoints stand, as fractions of the half-extent from the centre: the
#: four upper corners (looking down across the room), then back from each side.
_INSIDE_VIEWS = (
    (0.8, 0.6, -0.8),
    (-0.8, 0.6, -0.8),
    (0.8, 0.6, 0.8),
    (-0.8, 0.6, 0.8),
    (0.0, 0.0, -0.8),
    (0.0, 0.0, 0.8),
    (0.8, 0.0, 0.0),
    (-0.8, 0.0, 0.0),
)


def automatic_camera(
    mesh: RadiosityMesh, vertical_fov_deg: float = 39.3, probe: tuple[int, int] = (48, 36)
) -> Camera:
    """The camera for a scene that gives none: the candidate view seeing the most surface.

    Candidates are the classic front view (:func:`framing_camera`), elevated
    three-quarter and side views from outside the bounding box (all of it in frame), and
    views from inside it (for closed rooms, whose outside is the back of their walls):
    from its upper corners looking down across it, then back from each side. Each is scored by a
    ``probe``-sized image of primary rays: the fraction of surface hits that see a lit side
    (front of a one-sided face, either side of a two-sided one, not the black back of a
    wall), times the fraction of the frame covered by surfaces up to a half (views that
    see the scene edge-on or as a speck score low). The first candidate
    within 10 % of the best score wins, so the front view is kept whenever it sees nearly
    as much as any other (y is up).

    Parameters
    ----------
    mesh : RadiosityMesh
    vertical_fov_deg : float [degrees]
    probe : (int, int)
        Width and height of the scoring images [pixels].

    Returns
    -------
    Camera
    """
    candidates = _candidate_cameras(mesh.positions, vertical_fov_deg)
    _, normal = _triangle_normals(mesh)
    twin = twin_triangles(mesh.triangles)
    occluder = Occluder(mesh.positions, mesh.triangles)
    try:
        scores = []
        for camera in candidates:
            origin = occluder.to_local(np.asarray(camera.position, dtype=np.float64)[None, :])
            direction = _primary_directions(camera, probe[0], probe[1], 0.5, 0.5)
            hit, _, _ = occluder.intersect_barycentric_local(
                np.broadcast_to(origin, direction.shape), direction
            )
            seen = hit >= 0
            facing = np.einsum("ij,ij->i", normal[hit[seen]], direction[seen]) < 0
            lit = float((facing | (twin[hit[seen]] >= 0)).sum())
            coverage = seen.mean()
            scores.append(lit / max(seen.sum(), 1) * min(1.0, coverage / _FULL_COVERAGE))
    finally:
        occluder.close()
    best = max(scores)
    return candidates[next(i for i, score in enumerate(scores) if score >= 0.9 * best)]


def _candidate_cameras(positions: np.ndarray, vertical_fov_deg: float) -> list[Camera]:
    """The views :func:`automatic_camera` chooses from."""
    lo, hi = positions.min(axis=0), positions.max(axis=0)
    centre = 0.5 * (lo + hi)
    half = 0.5 * (hi - lo)
    target = (float(centre[0]), float(centre[1]), float(centre[2]))
    cameras = [framing_camera(positions, vertical_fov_deg)]
    box = centre + half * np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T
    for view in _OUTSIDE_VIEWS:
        direction = np.asarray(view) / np.linalg.norm(view)
        probe = Camera(_triple(centre + direction), target, (0.0, 1.0, 0.0), vertical_fov_deg)
        distance = _fitting_distance(probe, box - centre)
        position = centre + distance * direction
        cameras.append(Camera(_triple(position), target, (0.0, 1.0, 0.0), vertical_fov_deg))
    wide = max(vertical_fov_deg, 60.0)
    below = _triple(centre - np.array([0.0, 0.4 * half[1], 0.0]))  # the floor in view
    for view in _INSIDE_VIEWS:
        position = centre + half * np.asarray(view)
        look = below if view[1] > 0 else target
        try:  # a flat scene has no inside: the view would stand on its target
            cameras.append(Camera(_triple(position), look, (0.0, 1.0, 0.0), wide))
        except SettingsError:
            continue
    return cameras


def _fitting_distance(camera: Camera, offsets: np.ndarray) -> float:
    """Distance [m] from the target at which ``camera``'s direction frames every offset.

    A point at ``offset`` from the target has depth ``distance + offset . forward``; it is
    in a square frame when its sideways and upward offsets are at most depth x tan(fov/2).
    5 % margin; never closer than just outside the points.
    """
    right, up, forward = camera.basis()
    tan = math.tan(math.radians(camera.vertical_fov_deg) / 2.0)
    along = offsets @ forward
    sideways = np.maximum(np.abs(offsets @ right), np.abs(offsets @ up))
    return 1.05 * float(max((sideways / tan - along).max(), (-along).max() * 1.05 + 1e-9))


def _triple(values: np.ndarray) -> tuple[float, float, float]:
    return (float(values[0]), float(values[1]), float(values[2]))


def _primary_directions(
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


def framing_camera(positions: np.ndarray, vertical_fov_deg: float = 39.3) -> Camera:
    """A camera looking along +z at the scene's bounding box, far enough to see all of it.

    Suits rooms open toward -z (the Cornell box convention); scene files can give their
    own camera.
    """
    lo, hi = positions.min(axis=0), positions.max(axis=0)
    centre = 0.5 * (lo + hi)
    half = 0.5 * (hi - lo)
    tan = math.tan(math.radians(vertical_fov_deg) / 2.0)
    distance = max(half[0], half[1]) / tan + half[2]
    position = (float(centre[0]), float(centre[1]), float(lo[2] - (distance - half[2]) * 1.05))
    target = (float(centre[0]), float(centre[1]), float(centre[2]))
    return Camera(position, target, (0.0, 1.0, 0.0), vertical_fov_deg)


def twin_triangles(triangles: np.ndarray) -> np.ndarray:
    """(T,) int64: the reversed copy of each triangle (other side of a two-sided surface),
    or -1."""
    key = np.sort(triangles, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    twin = np.full(len(triangles), -1, dtype=np.int64)
    pairs = counts[inverse] == 2
    order = np.argsort(inverse[pairs], kind="stable")
    members = np.nonzero(pairs)[0][order].reshape(-1, 2)
    twin[members[:, 0]] = members[:, 1]
    twin[members[:, 1]] = members[:, 0]
    return twin


def render_radiance(
    mesh: RadiosityMesh,
    radiosity: np.ndarray,
    camera: Camera,
    width: int = 640,
    height: int = 480,
    samples: int = 4,
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
    _, normal = _triangle_normals(mesh)
    twin = twin_triangles(mesh.triangles)
    image = np.zeros((height, width, 3))
    occluder = Occluder(mesh.positions, mesh.triangles)
    try:
        origin = occluder.to_local(np.asarray(camera.position, dtype=np.float64)[None, :])
        for sy in range(side):
            for sx in range(side):
                jitter = rng.random((2, height, width))
                direction = _primary_directions(
                    camera, width, height, (sx + jitter[0]) / side, (sy + jitter[1]) / side
                )
                hit, _, weights = occluder.intersect_barycentric_local(
                    np.broadcast_to(origin, direction.shape), direction
                )
                image += _shade(hit, weights, direction, mesh, radiosity, normal, twin).reshape(
                    height, width, 3
                )
    finally:
        occluder.close()
    return (image / (side * side) / math.pi).astype(np.float32)


def _triangle_normals(mesh: RadiosityMesh) -> tuple[np.ndarray, np.ndarray]:
    corners = mesh.positions[mesh.triangles]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    length = np.linalg.norm(cross, axis=1)
    return length, cross / np.maximum(length, 1e-300)[:, None]


def _shade(
    hit: np.ndarray,
    weights: np.ndarray,
    direction: np.ndarray,
    mesh: RadiosityMesh,
    radiosity: np.ndarray,
    normal: np.ndarray,
    twin: np.ndarray,
) -> np.ndarray:
    """(N, 3) radiosity seen along each ray: the side of the surface facing the camera.

    A hit on the back of a single-sided surface is black (no light leaves its back); on a
    two-sided surface it takes the reversed copy, whose corners come in reverse order.
    """
    out = np.zeros((len(hit), 3))
    ok = hit >= 0
    tri = hit[ok]
    w = weights[ok]
    facing = np.einsum("ij,ij->i", normal[tri], direction[ok]) < 0
    back = ~facing & (twin[tri] >= 0)
    tri = np.where(back, twin[tri], tri)
    w = np.where(back[:, None], _reversed_weights(mesh.triangles, hit[ok], tri, w), w)
    visible = facing | back
    values = np.einsum("nk,nkc->nc", w, radiosity[mesh.triangle_receivers[tri]])
    out[np.nonzero(ok)[0][visible]] = values[visible]
    return out


def _reversed_weights(
    triangles: np.ndarray, hit: np.ndarray, twin: np.ndarray, weights: np.ndarray
) -> np.ndarray:
    """Barycentric weights of the same point in the twin triangle (corners permuted)."""
    out = np.zeros_like(weights)
    for k in range(3):
        match = triangles[twin] == triangles[hit][:, k : k + 1]
        out += match * weights[:, k : k + 1]
    return out
