"""Where an image is seen from: a camera the options give, one the scene file names, or
an automatic framing when neither does.

For automatic framing, candidate views (the classic front view, elevated three-quarter and
side views, views from inside a closed room) are scored with a small probe image of
primary rays (:func:`~raytrad.products.image.primary_directions`); the first within 10 % of
the best wins (y is up).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from raytrad.constants import defaults
from raytrad.core.mesh import RadiosityMesh
from raytrad.core.shading import triangle_normals, twin_triangles
from raytrad.core.visibility import Occluder
from raytrad.errors import SettingsError
from raytrad.products.image import primary_directions
from raytrad.scene import Camera, NamedCamera

log = logging.getLogger(__name__)

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
    mesh: RadiosityMesh,
    vertical_fov_deg: float = defaults.vertical_fov_deg,
    probe: tuple[int, int] = (48, 36),
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
    _, normal = triangle_normals(mesh)
    twin = twin_triangles(mesh.triangles)
    occluder = Occluder(mesh.positions, mesh.triangles)
    try:
        scores = []
        for camera in candidates:
            origin = occluder.to_local(np.asarray(camera.position, dtype=np.float64)[None, :])
            direction = primary_directions(camera, probe[0], probe[1], 0.5, 0.5)
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


def framing_camera(
    positions: np.ndarray, vertical_fov_deg: float = defaults.vertical_fov_deg
) -> Camera:
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


def file_camera(
    cameras: Sequence[NamedCamera], view: str | None, path: Path | None, kind: str
) -> NamedCamera | None:
    """The scene file's camera named ``view`` (None: the first), or None when it has none.

    Parameters
    ----------
    cameras : sequence of NamedCamera
        The file's cameras (:class:`raytrad.scenefiles.SceneFile`).
    view : str or None
        The camera asked for by name.
    path : Path or None
        The scene file, for messages.
    kind : str
        The file's kind (``gltf``, ``toml``...): only glTF and TOML files name cameras.

    Raises
    ------
    SettingsError
        ``view`` names no camera of the file (the message lists those it has).
    """
    if kind == "toml":
        if view not in (None, "camera"):
            raise SettingsError(
                f"{path}: has no camera named {view!r} (a TOML scene file has one [camera], "
                "named 'camera')"
            )
        return cameras[0] if cameras else None
    if kind != "gltf":
        if view is not None:
            raise SettingsError(f"{path}: only glTF and TOML scene files have cameras to name")
        return None
    if view is None:
        if len(cameras) > 1:
            log.info(
                "%s: %d cameras; using %r (choose with --view: %s)",
                path,
                len(cameras),
                cameras[0].name,
                ", ".join(repr(c.name) for c in cameras),
            )
        return cameras[0] if cameras else None
    for named in cameras:
        if named.name == view:
            return named
    names = ", ".join(repr(c.name) for c in cameras) or "none"
    raise SettingsError(f"{path}: no camera named {view!r} (its cameras: {names})")


def image_view(
    mesh: RadiosityMesh,
    camera: Camera | None,
    named: NamedCamera | None,
    width: int | None,
    height: int,
) -> tuple[Camera, int, str]:
    """The camera to render from, the image width [pixels] and where the camera came from.

    ``camera`` (the options') wins, then the scene file's ``named`` camera, then
    :func:`automatic_camera`. A width of None is ``height`` times the file camera's
    aspect ratio when it gives one, else the default width.

    Returns
    -------
    camera : Camera
    width : int
    origin : str
        ``"settings"``, the file camera's name, or ``"automatic framing"``.
    """
    if camera is not None:
        return camera, width or defaults.image_width, "settings"
    if named is None:
        return automatic_camera(mesh), width or defaults.image_width, "automatic framing"
    aspect = named.aspect_ratio
    if width is None:
        width = max(1, round(height * aspect)) if aspect else defaults.image_width
    return named.camera, width, named.name
