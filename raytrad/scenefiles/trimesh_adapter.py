"""The one module that imports :mod:`trimesh`, lazily: OBJ, glTF and PLY parsing.

trimesh parses the scene graph, plain triangles and binary PLY; raytrad reads material
values, OBJ indices and glTF accessors itself (the readers hand trimesh name-only tokens
and rewritten files, and serve every referenced file from memory through
:func:`bytes_resolver`), so what crosses this adapter is geometry, node transforms and
material *names*.
"""

from __future__ import annotations

import io
import re
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from raytrad.constants import tol
from raytrad.errors import SceneError
from raytrad.scenefiles.common import Collected, Material, reason, used_vertices


def bytes_resolver(files: dict[str, bytes]) -> Any:
    """A trimesh resolver serving the given files by name, and refusing any other.

    The readers read every referenced file themselves (path checks, non-blocking opens,
    :func:`~raytrad.scenefiles.common.read_reference`), so trimesh never opens a file.
    """
    from trimesh.resolvers import Resolver

    class _Resolver(Resolver):
        def __init__(self) -> None:
            pass

        def get(self, key: str) -> bytes:
            if key not in files:
                raise OSError(f"{key}: not provided")
            return files[key]

        def write(self, name: str, data: Any) -> None:
            raise OSError(f"{name}: read only")

        def namespaced(self, namespace: str) -> Any:
            return self

        def keys(self) -> Any:
            return files.keys()

    return _Resolver()


def parse_scene(path: Path, data: bytes, file_type: str, label: str, **options: Any) -> Any:
    """A ``trimesh.Scene`` from file bytes; SceneError ``cannot parse as <label>`` otherwise.

    Parameters
    ----------
    path : Path
        The file, for messages and as the default resolver's directory.
    data : bytes
        The (possibly rewritten) file content.
    file_type : str
        trimesh's file type (``obj``, ``gltf``, ``glb``).
    options
        More keyword arguments for ``trimesh.load_scene`` (``resolver``, ...).
    """
    import trimesh

    options.setdefault("resolver", bytes_resolver({}))
    try:
        with warnings.catch_warnings():  # trimesh's numpy warnings are noise to a user
            warnings.simplefilter("ignore", RuntimeWarning)
            return trimesh.load_scene(
                io.BytesIO(data), file_type=file_type, process=False, **options
            )
    except Exception as exc:  # trimesh raises many types for malformed input
        raise SceneError(path, f"cannot parse as {label}: {reason(exc)}") from exc


def material_name(geometry: Any) -> str | None:
    """The name of a trimesh geometry's material, None without one."""
    name = getattr(getattr(geometry.visual, "material", None), "name", None)
    return name if isinstance(name, str) else None


def node_object(tm_scene: Any, node: str) -> str:
    """The glTF node a trimesh geometry node stands for.

    trimesh names the primitives of a mesh with several ``<node>_<6 hex digits>`` under a
    geometry-less parent ``<node>``; a single primitive is the node itself.
    """
    parent = tm_scene.graph.transforms.parents.get(node)
    if (
        parent is not None
        and parent not in tm_scene.graph.nodes_geometry
        and re.fullmatch(re.escape(str(parent)) + r"_[0-9a-f]{6}", node)
    ):
        return str(parent)
    return node


def _top_down_uv(geometry: Any) -> np.ndarray | None:
    """(n, 2) per-vertex UVs of a trimesh geometry with v down, or None without any.

    trimesh stores UVs with v up (OBJ's convention; it flips glTF's), so v is flipped back.
    """
    uv = getattr(geometry.visual, "uv", None)
    if uv is None or len(uv) != len(geometry.vertices):
        return None
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    return np.column_stack([uv[:, 0], 1.0 - uv[:, 1]])


def is_mirror(linear: np.ndarray) -> bool:
    """True when the (3, 3) ``linear`` part of a transform mirrors (turns front faces back).

    A determinant within :data:`~raytrad.constants.tol` ``.singular`` of the product of the
    column lengths is a flattening transform whose sign is rounding noise: not a mirror.
    """
    linear = np.asarray(linear, dtype=np.float64)
    scale = float(np.prod(np.linalg.norm(linear, axis=0)))
    determinant = float(np.linalg.det(linear))
    return determinant < -tol.singular * scale


def add_trimesh_scene(
    collected: Collected,
    tm_scene: Any,
    material_of: Callable[[Any], Material],
    object_of: Callable[[str, Any], str | None] | None = None,
    uv_available: bool = True,
    node_order: list[str] | None = None,
) -> None:
    """Add every triangle geometry of a trimesh scene, placed by its node transform.

    Geometry without faces (points, paths) is skipped. A transform that mirrors
    (:func:`is_mirror`) would turn front faces into back faces, so their winding is
    reversed to keep the front side facing where the mirrored surface faces.
    ``object_of(node, geometry)`` names the object (mesh) the geometry belongs to (None,
    or no ``object_of``: the file's stem); ``uv_available``: whether trimesh's UVs are the
    set asked for; ``node_order``: object names in file order, to add objects in.
    """
    import trimesh

    objects = object_of or (lambda node, geometry: None)
    placed = []
    for node in tm_scene.graph.nodes_geometry:
        matrix, geometry_name = tm_scene.graph[node]
        geometry = tm_scene.geometry.get(geometry_name)
        if isinstance(geometry, trimesh.Trimesh) and len(geometry.faces):
            placed.append((matrix, geometry, objects(str(node), geometry)))
    if node_order:  # objects in the file's order, not trimesh's graph order
        rank = {name: i for i, name in enumerate(node_order)}
        placed.sort(key=lambda item: rank.get(item[2] or "", len(rank)))
    for matrix, geometry, object_name in placed:
        if geometry.vertices.ndim != 2 or geometry.vertices.shape[1] != 3:
            raise SceneError(
                collected.path,
                f"vertices must have 3 coordinates, found {geometry.vertices.shape[-1]}",
            )
        used, local = used_vertices(geometry.faces)
        vertices = np.asarray(geometry.vertices, dtype=np.float64)[used]
        uv = _top_down_uv(geometry) if uv_available and collected.uv_set is not None else None
        transform = np.asarray(matrix, dtype=np.float64)
        with np.errstate(invalid="ignore", over="ignore"):  # non-finite input is reported later
            positions = vertices @ transform[:3, :3].T + transform[:3, 3]
            mirror = is_mirror(transform[:3, :3]) if np.isfinite(transform).all() else False
        if mirror:
            local = local[:, ::-1]
        collected.add(
            positions,
            local,
            material_of(geometry),
            object_name,
            None if uv is None else uv[used],
        )


def read_ply_elements(path: Path) -> dict[str, Any]:
    """trimesh's raw PLY elements (``{"vertex": {"data": ...}, "face": {...}}``).

    Raises
    ------
    SceneError
        ``cannot parse as PLY`` with trimesh's reason.
    """
    from trimesh.exchange.ply import load_ply

    try:
        with path.open("rb") as f:
            raw: dict[str, Any] = load_ply(f, fix_texture=False, skip_materials=True)["metadata"][
                "_ply_raw"
            ]
    except Exception as exc:  # trimesh raises many types for malformed input
        raise SceneError(path, f"cannot parse as PLY: {reason(exc)}") from exc
    return raw
