"""Cameras of a glTF 2.0 document as raytrad pinhole cameras.

Only the document's JSON is used (:mod:`raytrad.scenefiles.gltf` parses it once, for the
geometry and the cameras). The nodes of the default scene are walked from its roots,
composing each node's local transform (``matrix``, or translation x rotation x scale) into
a world transform, and every node holding a perspective camera becomes a
:class:`~raytrad.scene.Camera`. A glTF camera looks along its local -Z axis with +Y up.
Orthographic cameras are skipped with a warning: raytrad renders pinhole cameras only.
Every problem with the file is a :class:`~raytrad.errors.SceneError` naming it.

Units: file coordinates times ``scale`` are metres [m]; the file's ``yfov`` is in radians,
the camera's vertical field of view in degrees.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from raytrad.constants import tol
from raytrad.errors import SceneError, SettingsError
from raytrad.scene import Camera, NamedCamera

log = logging.getLogger(__name__)

_LOCAL_FORWARD = np.array([0.0, 0.0, -1.0])
_LOCAL_UP = np.array([0.0, 1.0, 0.0])


def cameras_from_document(
    path: Path, document: dict[str, Any], scale: float = 1.0
) -> list[NamedCamera]:
    """The perspective cameras of a parsed glTF 2.0 document's default scene.

    Parameters
    ----------
    path : Path
        The file the document came from, for messages.
    document : dict
        The glTF JSON, as parsed (not yet rewritten for the geometry reader).
    scale : float
        Metres per file unit [m]; multiplies camera positions, not directions.

    Returns
    -------
    list of NamedCamera
        In depth-first order of the scene's node tree (roots and children as listed);
        empty if the scene holds no cameras. The default scene is ``scene``, else scene 0,
        else (no ``scenes``) every node that is no node's child.

    Raises
    ------
    SceneError
        Naming the file: not glTF 2.0, bad indices, a cycle in the node tree, non-finite or
        malformed transforms, a degenerate camera transform, ``yfov`` missing or outside
        (0, pi) radians, ``aspectRatio`` not positive.
    """
    _check_version(path, document)
    nodes = _objects(path, document, "nodes")
    if not any("camera" in node for node in nodes):
        return []
    cameras = _objects(path, document, "cameras")
    found: list[NamedCamera] = []
    for index, world in _walk(path, nodes, _scene_roots(path, document, nodes)):
        if "camera" in nodes[index]:
            named = _named_camera(path, cameras, nodes[index], index, world, scale)
            if named is not None:
                found.append(named)
    return found


# --------------------------------------------------------------------------- the document


def _check_version(path: Path, document: dict[str, Any]) -> None:
    """SceneError unless ``document`` is a glTF 2.x top-level object."""
    if not isinstance(document, dict):
        raise SceneError(path, "not a glTF file: the JSON is not an object")
    asset = document.get("asset")
    if not isinstance(asset, dict) or not isinstance(asset.get("version"), str):
        raise SceneError(path, "not a glTF file: no 'asset' object with a 'version'")
    if not asset["version"].startswith("2."):
        raise SceneError(path, f"glTF version {_short(asset['version'])}, need 2.0")


def _objects(path: Path, document: dict[str, Any], key: str) -> list[dict[str, Any]]:
    """The top-level list ``key`` (empty if absent), checked to hold only JSON objects."""
    items = document.get(key, [])
    if not isinstance(items, list):
        raise SceneError(path, f"glTF {key!r} is not a list")
    for i, item in enumerate(items):
        if not isinstance(item, dict):
            raise SceneError(path, f"glTF {key} {i} is not an object")
    return items


def _short(value: object) -> str:
    """``repr(value)`` on one line, cut to 60 characters, for error messages."""
    text = " ".join(repr(value).split())
    return text if len(text) <= 60 else text[:57] + "..."


def _index(path: Path, value: object, count: int, what: str) -> int:
    """``value`` as an index into a list of ``count`` items; SceneError naming ``what``."""
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < count:
        raise SceneError(path, f"{what} {_short(value)}, which is not an index in [0, {count})")
    return value


def _indices(path: Path, value: object, count: int, what: str) -> list[int]:
    """A JSON list of indices into ``count`` items (``what`` names it in errors)."""
    if not isinstance(value, list):
        raise SceneError(path, f"{what} is not a list")
    return [_index(path, v, count, f"{what} has") for v in value]


# --------------------------------------------------------------------------- the node tree


def _scene_roots(path: Path, document: dict[str, Any], nodes: list[dict[str, Any]]) -> list[int]:
    """Root node indices of the default scene (every parentless node if there are no scenes)."""
    scenes = _objects(path, document, "scenes")
    if not scenes and "scene" not in document:
        children = {
            child
            for i, node in enumerate(nodes)
            for child in _indices(path, node.get("children", []), len(nodes), f"node {i} children")
        }
        return [i for i in range(len(nodes)) if i not in children]
    chosen = _index(path, document.get("scene", 0), len(scenes), "glTF 'scene' is")
    return _indices(path, scenes[chosen].get("nodes", []), len(nodes), f"scene {chosen} nodes")


def _walk(
    path: Path, nodes: list[dict[str, Any]], roots: list[int]
) -> Iterator[tuple[int, np.ndarray]]:
    """Depth-first (index, (4, 4) world transform [file units]) of every node under ``roots``.

    Raises SceneError for a node that is its own ancestor (a cycle).
    """
    identity = np.eye(4)
    stack: list[tuple[int, np.ndarray, frozenset[int]]] = [
        (root, identity, frozenset()) for root in reversed(roots)
    ]
    while stack:
        index, parent, ancestors = stack.pop()
        if index in ancestors:
            raise SceneError(path, f"node {index} is its own ancestor (a cycle in the node tree)")
        node = nodes[index]
        with np.errstate(over="ignore", invalid="ignore"):  # overflow is reported per camera
            world = parent @ _local_matrix(path, node, index)
        yield index, world
        children = _indices(path, node.get("children", []), len(nodes), f"node {index} children")
        inner = ancestors | {index}
        stack.extend((child, world, inner) for child in reversed(children))


def _local_matrix(path: Path, node: dict[str, Any], index: int) -> np.ndarray:
    """A node's (4, 4) local transform: ``matrix`` (column-major) if given, else T @ R @ S."""
    if "matrix" in node:
        matrix = _numbers(path, node["matrix"], 16, f"node {index} matrix").reshape(4, 4).T
        if not np.allclose(matrix[3], (0.0, 0.0, 0.0, 1.0), rtol=0.0, atol=1e-6):
            raise SceneError(path, f"node {index} matrix is not affine (last row not 0 0 0 1)")
        return matrix
    translation = _numbers(path, node.get("translation", [0, 0, 0]), 3, f"node {index} translation")
    rotation = _numbers(path, node.get("rotation", [0, 0, 0, 1]), 4, f"node {index} rotation")
    scale = _numbers(path, node.get("scale", [1, 1, 1]), 3, f"node {index} scale")
    length = float(np.linalg.norm(rotation))
    if length == 0.0:
        raise SceneError(path, f"node {index} rotation is the zero quaternion")
    matrix = np.eye(4)
    matrix[:3, :3] = _quaternion_matrix(rotation / length) * scale  # R @ diag(scale)
    matrix[:3, 3] = translation
    return matrix


def _quaternion_matrix(quaternion: np.ndarray) -> np.ndarray:
    """The (3, 3) rotation matrix of a unit quaternion.

    Parameters
    ----------
    quaternion : (4,) float
        ``(x, y, z, w)``, glTF order, of norm 1.

    Returns
    -------
    (3, 3) float64
        Rotating column vectors: ``v' = R @ v``.
    """
    x, y, z, w = (float(q) for q in quaternion)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _numbers(path: Path, value: object, count: int, what: str) -> np.ndarray:
    """A JSON list of ``count`` finite numbers as a (count,) float64 array."""
    if (
        not isinstance(value, list)
        or len(value) != count
        or any(isinstance(v, bool) or not isinstance(v, int | float) for v in value)
    ):
        raise SceneError(path, f"{what} must be a list of {count} numbers, not {_short(value)}")
    try:
        array = np.array([float(v) for v in value])
    except OverflowError:  # an integer beyond float range
        array = np.full(count, np.inf)
    if not np.isfinite(array).all():
        raise SceneError(path, f"{what} has non-finite values")
    return array


# --------------------------------------------------------------------------- cameras


def _named_camera(
    path: Path,
    cameras: list[dict[str, Any]],
    node: dict[str, Any],
    node_index: int,
    world: np.ndarray,
    scale: float,
) -> NamedCamera | None:
    """The camera of one node placed by its (4, 4) world transform; None if orthographic."""
    camera_index = _index(path, node["camera"], len(cameras), f"node {node_index} camera is")
    spec = cameras[camera_index]
    name = _name(node) or _name(spec) or f"camera {camera_index}"
    kind = spec.get("type")
    if kind == "orthographic":
        log.warning(
            "%s: camera %r is orthographic and skipped; raytrad renders pinhole cameras only",
            path,
            name,
        )
        return None
    perspective = spec.get("perspective")
    if kind != "perspective" or not isinstance(perspective, dict):
        raise SceneError(
            path, f"camera {camera_index} ({name!r}) is neither a perspective nor orthographic"
        )
    fov_deg = _vertical_fov_deg(path, perspective, camera_index)
    aspect = _aspect_ratio(path, perspective, camera_index)
    position, forward, up = _pose(path, world, node_index, scale)
    try:
        camera = Camera(_triple(position), _triple(position + forward), _triple(up), fov_deg)
    except SettingsError as exc:  # e.g. look_at rounds to position far from the origin
        raise SceneError(path, f"node {node_index} camera {name!r}: {exc}") from None
    return NamedCamera(name, camera, aspect)


def _name(item: dict[str, Any]) -> str | None:
    """The ``name`` of a glTF object if it is a non-empty string."""
    name = item.get("name")
    return name if isinstance(name, str) and name else None


def _vertical_fov_deg(path: Path, perspective: dict[str, Any], index: int) -> float:
    """``yfov`` [rad], required in (0, pi), as degrees."""
    yfov = perspective.get("yfov")
    if isinstance(yfov, bool) or not isinstance(yfov, int | float):
        raise SceneError(path, f"camera {index} yfov must be a number, not {_short(yfov)}")
    if not 0.0 < yfov < math.pi:
        raise SceneError(path, f"camera {index} yfov {yfov} is not in (0, pi) radians")
    return math.degrees(yfov)


def _aspect_ratio(path: Path, perspective: dict[str, Any], index: int) -> float | None:
    """``aspectRatio`` [1] (width / height), finite and > 0, or None if absent."""
    if "aspectRatio" not in perspective:
        return None
    aspect = perspective["aspectRatio"]
    if (
        isinstance(aspect, bool)
        or not isinstance(aspect, int | float)
        or not (math.isfinite(aspect) and aspect > 0.0)
    ):
        raise SceneError(path, f"camera {index} aspectRatio {_short(aspect)} is not a number > 0")
    return float(aspect)


def _pose(
    path: Path, world: np.ndarray, node_index: int, scale: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position [m], unit forward and unit up of a camera with (4, 4) world transform.

    Directions are the local -Z and +Y axes through the 3x3 part (so non-uniform scale
    tilts them as it tilts the geometry), normalised; ``scale`` only multiplies the position.

    Returns
    -------
    position : (3,) float64 [m]
    forward : (3,) float64 [1]
    up : (3,) float64 [1]
    """
    with np.errstate(over="ignore", invalid="ignore"):
        position = world[:3, 3] * scale
    if not (np.isfinite(world).all() and np.isfinite(position).all()):
        raise SceneError(path, f"node {node_index}: the camera's world transform is not finite")
    directions = world[:3, :3] @ np.stack([_LOCAL_FORWARD, _LOCAL_UP], axis=1)  # (3, 2)
    lengths = np.linalg.norm(directions, axis=0)
    if not (lengths > 0.0).all():
        raise SceneError(path, f"node {node_index}: degenerate camera transform (zero scale)")
    forward, up = (directions / lengths).T
    if np.linalg.norm(np.cross(forward, up)) < tol.parallel:
        raise SceneError(
            path, f"node {node_index}: degenerate camera transform (view and up are parallel)"
        )
    return position, forward, up


def _triple(vector: np.ndarray) -> tuple[float, float, float]:
    """A (3,) array as a tuple of Python floats."""
    return (float(vector[0]), float(vector[1]), float(vector[2]))
