"""Scene files: one entrance that reads any supported file into a scene, its cameras and
its output defaults, in one parse of the file; the per-format readers; the scene writers.

>>> from raytrad.scenefiles import load_scene_file
>>> loaded = load_scene_file("scenes/cornell-box-uv.glb", cameras=True)  # doctest: +SKIP
>>> loaded.scene.triangle_count, [c.name for c in loaded.cameras]        # doctest: +SKIP
(36, ['front', 'corner'])

Readers are registered by file suffix in :data:`READERS`. This package is the only one
that uses trimesh (through :mod:`raytrad.scenefiles.trimesh_adapter`).
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from raytrad.errors import SceneError, SettingsError
from raytrad.scene import NamedCamera, Scene
from raytrad.scenefiles.common import Collected, ReadOptions, checked_path
from raytrad.scenefiles.gltf import read_glb, read_gltf, read_gltf_cameras
from raytrad.scenefiles.obj import read_obj
from raytrad.scenefiles.ply import read_ply
from raytrad.scenefiles.toml_scene import read_toml
from raytrad.scenefiles.writers import write_glb, write_obj

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SceneFile:
    """What a scene file holds.

    Attributes
    ----------
    scene : Scene
        Validated, ``source`` the file.
    cameras : tuple of NamedCamera
        The file's cameras, positions in metres: a TOML ``[camera]`` (named ``"camera"``),
        or a glTF file's perspective cameras when asked for; empty otherwise.
    output : dict
        Output defaults the file gives (a TOML ``[output]`` table), by key of
        :data:`raytrad.scenefiles.toml_scene.OUTPUT_KEYS`.
    kind : str
        The reader that read it: ``obj``, ``gltf``, ``ply`` or ``toml``.
    """

    scene: Scene
    cameras: tuple[NamedCamera, ...] = ()
    output: dict[str, float | int] = field(default_factory=dict)
    kind: str = ""


def _read_toml(path: Path, options: ReadOptions) -> Collected:
    return read_toml(path, options, _load_mesh)


#: Readers by lower-case file suffix: ``reader(path, options) -> Collected``, and the
#: kind of file each reads.
READERS: dict[str, tuple[str, Callable[[Path, ReadOptions], Collected]]] = {
    ".obj": ("obj", read_obj),
    ".gltf": ("gltf", read_gltf),
    ".glb": ("gltf", read_glb),
    ".ply": ("ply", read_ply),
    ".toml": ("toml", _read_toml),
}


def load_scene_file(
    path: str | os.PathLike[str],
    scale: float = 1.0,
    uv_set: int | None = None,
    cameras: bool = False,
    allow_outside: bool = False,
) -> SceneFile:
    """Read a scene file, dispatching on its suffix through :data:`READERS`.

    Parameters
    ----------
    path : path-like
        An ``.obj`` (with its ``.mtl``), ``.gltf``, ``.glb``, ``.ply`` or ``.toml`` file.
    scale : float
        Metres per file unit [m], for example 0.001 for a file in millimetres.
    uv_set : int or None
        Read this texture-coordinate set as the lightmap UVs (``Scene.lightmap_uv``): glTF
        ``TEXCOORD_<n>``; OBJ ``vt`` and PLY ``s, t`` (or ``u, v``) are set 0. Faces
        without it get NaN UVs. None reads no UVs.
    cameras : bool
        Also read a glTF file's cameras (a TOML ``[camera]`` is always read).
    allow_outside : bool
        Read referenced files (buffers, ``mtllib``, TOML meshes) that lie outside the
        scene file's folder; refused by default.

    Returns
    -------
    SceneFile

    Raises
    ------
    SceneError
        Naming the file: missing, unsupported type, unparseable, no triangle faces,
        non-finite coordinates, reflectance outside [0, 1] or negative emission.
    SettingsError
        If ``scale`` is not a finite positive number or ``uv_set`` is negative.
    """
    path, scale = checked_path(path, scale)
    if uv_set is not None and uv_set < 0:
        raise SettingsError(f"uv set must be >= 0, not {uv_set}")
    entry = READERS.get(path.suffix.lower())
    if entry is None:
        supported = ", ".join(sorted(READERS))
        raise SceneError(
            path, f"unsupported file type {path.suffix or '(no suffix)'!r}; use one of {supported}"
        )
    kind, reader = entry
    # Overflowing or invalid values are reported by name below, not as numpy warnings.
    with np.errstate(all="ignore"):
        try:
            collected = reader(path, ReadOptions(scale, uv_set, cameras, allow_outside))
        except OSError as exc:
            raise SceneError(path, f"cannot read the file: {exc.strerror or exc}") from exc
        except RecursionError:
            raise SceneError(path, "cannot parse: nesting too deep") from None
        scene = collected.to_scene()
    log.info(
        "%s: %d triangles, %d materials%s",
        path,
        scene.triangle_count,
        len(scene.material_names),
        f", {len(collected.cameras)} cameras" if collected.cameras else "",
    )
    return SceneFile(scene, tuple(collected.cameras), dict(collected.output), kind)


def load_scene(
    path: str | os.PathLike[str],
    scale: float = 1.0,
    uv_set: int | None = None,
    allow_outside: bool = False,
) -> Scene:
    """The scene of a scene file (see :func:`load_scene_file`)."""
    return load_scene_file(path, scale, uv_set, allow_outside=allow_outside).scene


def _load_mesh(path: Path, options: ReadOptions) -> Scene:
    """How a TOML ``[[mesh]]`` file is read: any other supported file, in metres."""
    return load_scene(path, 1.0, options.uv_set, allow_outside=options.allow_outside)


__all__ = [
    "READERS",
    "SceneFile",
    "load_scene",
    "load_scene_file",
    "read_gltf_cameras",
    "write_glb",
    "write_obj",
]
