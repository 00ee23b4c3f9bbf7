"""Where an image is seen from: a camera the options give, one the scene file names, or
an automatic framing when neither does.

For automatic framing, candidate views (the classic front view, elevated three-quarter and
side views, views from inside a closed room) are scored with a small probe image of
primary rays (:func:`~raytrad.products.image.primary_directions`); the first within 10 % of
the best wins. Views are built with y up, or z up (``up="z"``, CAD and Blender models
exported without axis conversion).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from raytrad.arrays import unique
from raytrad.constants import defaults
from raytrad.core.mesh import RadiosityMesh
from raytrad.core.shading import triangle_normals, twin_triangles
from raytrad.core.visibility import Occluder
from raytrad.errors import SettingsError
from raytrad.products.image import primary_directions
from raytrad.scene import Camera, NamedCamera
from raytrad.scene.colorimetry import LUMINANCE_WEIGHTS

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


#: Receivers brighter than this fraction of the scene's bright level (the 97th percentile
#: of the receivers' luminance) count as lit when a view is scored.
_LIT_FRACTION = 0.02

#: Scene-to-frame rotation per up axis: the frame has y up (the candidates are built in
#: it), ``positions @ _FRAMES[up]`` are frame coordinates, ``frame @ _FRAMES[up].T`` scene
#: ones. z up: frame (x, y, z) = scene (x, z, -y).
_FRAMES = {
    "y": np.eye(3),
    "z": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]),
}
UP_AXES = tuple(_FRAMES)
"""The up axes framing knows (``--up``)."""


def up_vector(up: str) -> tuple[float, float, float]:
    """The scene's up direction for an up axis name (``"y"`` or ``"z"``)."""
    return _triple(np.array([0.0, 1.0, 0.0]) @ _frame(up).T)


def _frame(up: str) -> np.ndarray:
    if up not in _FRAMES:
        raise SettingsError(f"up axis must be one of {', '.join(UP_AXES)}, not {up!r}")
    return _FRAMES[up]


def automatic_camera(
    mesh: RadiosityMesh,
    vertical_fov_deg: float = defaults.vertical_fov_deg,
    probe: tuple[int, int] = (48, 36),
    radiosity: np.ndarray | None = None,
    up: str = "y",
) -> Camera:
    """The camera for a scene that gives none: the candidate view seeing the most lit surface.

    Candidates are the classic front view (:func:`framing_camera`), elevated
    three-quarter and side views from outside the bounding box (all of it in frame), and
    views from inside it (for closed rooms, whose outside is the back of their walls):
    from its upper corners looking down across it, then back from each side. When the lit
    receivers fill only part of the box (one lit room of several), the same views of
    their own box follow. Each is scored by a ``probe``-sized image of primary rays: the
    fraction of surface hits that see a lit side (front of a one-sided face, either side
    of a two-sided one, not the black back of a wall) of a lit triangle (a corner brighter
    than :data:`_LIT_FRACTION` of the scene's bright level; every triangle without a
    ``radiosity``), times the fraction of the frame covered by surfaces up to a half
    (views that see the scene edge-on or as a speck score low). The first candidate
    within 10 % of the best score wins, so the front view is kept whenever it sees nearly
    as much as any other.

    Parameters
    ----------
    mesh : RadiosityMesh
    vertical_fov_deg : float [degrees]
    probe : (int, int)
        Width and height of the scoring images [pixels].
    radiosity : (R, 3) float or None
        The solution [W m-2], to tell lit surfaces from unlit ones.
    up : str
        The scene's up axis, ``"y"`` (glTF's convention) or ``"z"``.

    Returns
    -------
    Camera
    """
    lit_triangle = _lit_triangles(mesh, radiosity)
    regions = [mesh.positions]
    lit_points = mesh.positions[unique(mesh.triangles[lit_triangle])]
    if lit_triangle.any() and _smaller(lit_points, mesh.positions):
        regions.append(lit_points)
    candidates = [c for region in regions for c in _candidate_cameras(region, vertical_fov_deg, up)]
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
            lit = float(((facing | (twin[hit[seen]] >= 0)) & lit_triangle[hit[seen]]).sum())
            coverage = seen.mean()
            scores.append(lit / max(seen.sum(), 1) * min(1.0, coverage / _FULL_COVERAGE))
    finally:
        occluder.close()
    best = max(scores)
    return candidates[next(i for i, score in enumerate(scores) if score >= 0.9 * best)]


def _lit_triangles(mesh: RadiosityMesh, radiosity: np.ndarray | None) -> np.ndarray:
    """(T,) bool: triangles with a corner brighter than :data:`_LIT_FRACTION` of the
    scene's bright level (all True without a radiosity, or in an all-black scene)."""
    if radiosity is None:
        return np.ones(len(mesh.triangles), dtype=bool)
    luminance = np.asarray(radiosity, dtype=np.float64) @ np.asarray(LUMINANCE_WEIGHTS)
    level = float(np.percentile(luminance, 97.0)) if len(luminance) else 0.0
    if not level > 0.0:
        return np.ones(len(mesh.triangles), dtype=bool)
    bright = luminance > _LIT_FRACTION * level
    return np.asarray(bright[mesh.triangle_receivers].any(axis=1))


def _smaller(part: np.ndarray, whole: np.ndarray) -> bool:
    """Whether ``part``'s bounding box is clearly smaller than ``whole``'s on some axis."""
    extent = np.ptp(whole, axis=0)
    return bool((np.ptp(part, axis=0) < 0.9 * extent).any())


def _candidate_cameras(positions: np.ndarray, vertical_fov_deg: float, up: str) -> list[Camera]:
    """The views :func:`automatic_camera` chooses from, framing ``positions``."""
    frame = _frame(up)
    local = np.asarray(positions, dtype=np.float64) @ frame
    lo, hi = local.min(axis=0), local.max(axis=0)
    centre = 0.5 * (lo + hi)
    half = 0.5 * (hi - lo)
    cameras = [framing_camera(positions, vertical_fov_deg, up)]
    box = centre + half * np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T
    y_up = (0.0, 1.0, 0.0)
    for view in _OUTSIDE_VIEWS:
        direction = np.asarray(view) / np.linalg.norm(view)
        probe = Camera(_triple(centre + direction), _triple(centre), y_up, vertical_fov_deg)
        distance = _fitting_distance(probe, box - centre)
        cameras.append(_in_scene(centre + distance * direction, centre, vertical_fov_deg, frame))
    wide = max(vertical_fov_deg, 60.0)
    below = centre - np.array([0.0, 0.4 * half[1], 0.0])  # the floor in view
    for view in _INSIDE_VIEWS:
        position = centre + half * np.asarray(view)
        try:  # a flat scene has no inside: the view would stand on its target
            look = below if view[1] > 0 else centre
            cameras.append(_in_scene(position, look, wide, frame))
        except SettingsError:
            continue
    return cameras


def _in_scene(position: np.ndarray, target: np.ndarray, fov: float, frame: np.ndarray) -> Camera:
    """A camera given in frame coordinates (y up), in scene coordinates."""
    up = np.array([0.0, 1.0, 0.0]) @ frame.T
    return Camera(_triple(position @ frame.T), _triple(target @ frame.T), _triple(up), fov)


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
    positions: np.ndarray, vertical_fov_deg: float = defaults.vertical_fov_deg, up: str = "y"
) -> Camera:
    """A camera looking along +z (y up; with ``up="z"``, along +y with z up) at the
    scene's bounding box, far enough to see all of it.

    Suits rooms open toward -z (the Cornell box convention); scene files can give their
    own camera.
    """
    frame = _frame(up)
    local = np.asarray(positions, dtype=np.float64) @ frame
    lo, hi = local.min(axis=0), local.max(axis=0)
    centre = 0.5 * (lo + hi)
    half = 0.5 * (hi - lo)
    tan = math.tan(math.radians(vertical_fov_deg) / 2.0)
    distance = max(half[0], half[1]) / tan + half[2]
    position = np.array([centre[0], centre[1], lo[2] - (distance - half[2]) * 1.05])
    return _in_scene(position, centre, vertical_fov_deg, frame)


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
    radiosity: np.ndarray | None = None,
    up: str = "y",
) -> tuple[Camera, int, str]:
    """The camera to render from, the image width [pixels] and where the camera came from.

    ``camera`` (the options') wins, then the scene file's ``named`` camera, then
    :func:`automatic_camera` (seeing the most of what ``radiosity`` lights, ``up`` the
    scene's up axis). A width of None is ``height`` times the file camera's aspect ratio
    when it gives one, else the default width.

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
        automatic = automatic_camera(mesh, radiosity=radiosity, up=up)
        return automatic, width or defaults.image_width, "automatic framing"
    aspect = named.aspect_ratio
    if width is None:
        width = max(1, round(height * aspect)) if aspect else defaults.image_width
    return named.camera, width, named.name
