"""What every scene-file reader shares: the options, the triangle accumulator and helpers.

A reader (:data:`raytrad.scenefiles.READERS`) turns one file into a :class:`Collected`:
triangle groups with their materials and objects, and the file's cameras and output
settings. :meth:`Collected.to_scene` then builds the validated
:class:`~raytrad.scene.Scene`.

Units: file coordinates times ``scale`` are metres [m]; reflectance is linear RGB [1];
emitted exitance is [W m-2].
"""

from __future__ import annotations

import errno
import logging
import math
import os
import stat
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from raytrad.errors import SceneError, SettingsError
from raytrad.scene import NamedCamera, Scene, make_scene

log = logging.getLogger(__name__)

DEFAULT_REFLECTANCE = 0.5
"""Grey reflectance [1] given to faces whose file says nothing about their material."""


@dataclass(frozen=True)
class ReadOptions:
    """What a reader is asked for.

    Attributes
    ----------
    scale : float
        Metres per file unit [m].
    uv_set : int or None
        The texture-coordinate set to read as lightmap UVs (glTF ``TEXCOORD_<n>``; OBJ
        ``vt`` and PLY ``s, t`` are set 0); None reads no UVs.
    cameras : bool
        Read the file's cameras (glTF); a TOML ``[camera]`` is always read.
    allow_outside : bool
        Read files the scene refers to (buffers, ``mtllib``, TOML meshes) even when they
        lie outside the scene file's folder; refused by default.
    """

    scale: float = 1.0
    uv_set: int | None = None
    cameras: bool = False
    allow_outside: bool = False


@dataclass(frozen=True)
class Material:
    """One material as read from a file: reflectance [1], emitted exitance [W m-2]."""

    name: str
    reflectance: tuple[float, float, float]
    emitted_exitance: tuple[float, float, float] = (0.0, 0.0, 0.0)
    double_sided: bool = False


@dataclass
class Collected:
    """Triangle groups gathered from one file, each with a material (deduplicated by name).

    Readers pass each group's per-vertex UVs of the set asked for (v down), or nothing
    when the group has none; and set :attr:`cameras` (positions already in metres) and
    :attr:`output` (a TOML file's ``[output]`` values).
    """

    path: Path
    options: ReadOptions = field(default_factory=ReadOptions)
    positions: list[np.ndarray] = field(default_factory=list)
    triangles: list[np.ndarray] = field(default_factory=list)
    material_index: list[np.ndarray] = field(default_factory=list)
    object_index: list[np.ndarray] = field(default_factory=list)
    uv: list[np.ndarray] = field(default_factory=list)
    materials: dict[str, tuple[int, Material]] = field(default_factory=dict)
    objects: dict[str, int] = field(default_factory=dict)
    warned: set[str] = field(default_factory=set)
    vertex_count: int = 0
    cameras: list[NamedCamera] = field(default_factory=list)
    output: dict[str, float | int] = field(default_factory=dict)

    @property
    def uv_set(self) -> int | None:
        """The texture-coordinate set asked for (None: no UVs)."""
        return self.options.uv_set

    def add(
        self,
        positions: np.ndarray,
        triangles: np.ndarray,
        material: Material,
        object_name: str | None = None,
        uv: np.ndarray | None = None,
    ) -> None:
        """Append (n, 3) positions [file units] and (t, 3) local triangles of one material.

        Materials are shared by name; a different material with a name already taken
        (say a file's own "default") is renamed ``<name>_<k>``. ``object_name`` names the
        mesh the faces belong to (None: the file's stem); ``uv`` is (n, 2) lightmap UVs
        [1] of the positions, v down.
        """
        base, k = material.name, 0
        while material.name in self.materials and self.materials[material.name][1] != material:
            k += 1
            material = replace(material, name=f"{base}_{k}")
        if material.name not in self.materials:
            self.materials[material.name] = (len(self.materials), material)
        index = self.materials[material.name][0]
        object_name = self.path.stem if object_name is None else object_name
        obj = self.objects.setdefault(object_name, len(self.objects))
        positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
        triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
        if uv is None:
            uv = np.full((len(positions), 2), np.nan)
        self.positions.append(positions)
        self.triangles.append(triangles + self.vertex_count)
        self.material_index.append(np.full(len(triangles), index, dtype=np.int64))
        self.object_index.append(np.full(len(triangles), obj, dtype=np.int64))
        self.uv.append(np.asarray(uv, dtype=np.float64).reshape(-1, 2))
        self.vertex_count += len(positions)

    def warn_once(self, key: str, message: str, *args: object) -> None:
        """Log a warning about this file the first time ``key`` comes up."""
        if key not in self.warned:
            self.warned.add(key)
            log.warning("%s: " + message, self.path, *args)

    def to_scene(self) -> Scene:
        """The validated scene, positions times the read scale [m]."""
        if not self.triangles or sum(len(t) for t in self.triangles) == 0:
            raise SceneError(self.path, "the file contains no triangle faces")
        materials = [m for _, m in sorted(self.materials.values(), key=lambda im: im[0])]
        triangles = np.concatenate(self.triangles)
        lightmap_uv = None
        if self.uv_set is not None:
            lightmap_uv = np.concatenate(self.uv)[triangles]
        return make_scene(
            positions=np.concatenate(self.positions) * self.options.scale,
            triangles=triangles,
            material_index=np.concatenate(self.material_index),
            material_names=[m.name for m in materials],
            material_reflectance=np.array([m.reflectance for m in materials]),
            material_emitted_exitance=np.array([m.emitted_exitance for m in materials]),
            material_double_sided=np.array([m.double_sided for m in materials], dtype=bool),
            source=self.path,
            object_index=np.concatenate(self.object_index),
            object_names=list(self.objects),
            lightmap_uv=lightmap_uv,
        )


def checked_path(path: str | os.PathLike[str], scale: float) -> tuple[Path, float]:
    """The path of an existing regular file and a valid scale, or the error naming them."""
    path = Path(path)
    scale = float(scale)
    if not (math.isfinite(scale) and scale > 0.0):
        raise SettingsError(f"scale must be a finite number > 0, not {scale}")
    if not path.exists():
        raise SceneError(path, "file not found")
    if not path.is_file():
        raise SceneError(path, "not a regular file")
    return path, scale


def read_reference(
    scene_path: Path, name: str, what: str, allow_outside: bool = False
) -> bytes | None:
    """The bytes of a file a scene file refers to by a relative name, None when missing.

    Parameters
    ----------
    scene_path : Path
        The scene file; ``name`` is relative to its folder.
    name : str
        The reference as the file writes it (an absolute path is allowed only with
        ``allow_outside``).
    what : str
        What refers to it, for messages (``"mtllib"``, ``"buffer 0"``, ...).
    allow_outside : bool
        Read it even when it resolves (symbolic links followed) outside the scene's folder.

    Raises
    ------
    SceneError
        The file lies outside the scene folder, is not a regular file (a FIFO would block
        the read forever, so it is opened without blocking and refused), or cannot be read.
    """
    folder = scene_path.parent.resolve()
    target = (scene_path.parent / name).resolve()
    if not allow_outside and not target.is_relative_to(folder):
        raise SceneError(
            scene_path,
            f"{what} {name!r} lies outside the scene folder {str(folder)!r} "
            "(--allow-outside-files reads it)",
        )
    try:
        fd = os.open(target, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except FileNotFoundError:
        return None
    except OSError as exc:
        if exc.errno in (errno.ENOTDIR, errno.ENAMETOOLONG):
            return None
        raise SceneError(scene_path, f"{what} {name!r}: {exc.strerror or exc}") from None
    with os.fdopen(fd, "rb") as f:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise SceneError(scene_path, f"{what} {name!r} is not a regular file")
        try:
            return f.read()
        except OSError as exc:
            raise SceneError(scene_path, f"{what} {name!r}: {exc.strerror or exc}") from None


def reason(exc: BaseException) -> str:
    """A one-line, short description of a parser exception."""
    text = " ".join(str(exc).split())
    text = text if text else type(exc).__name__
    return text if len(text) <= 160 else text[:157] + "..."


def rgb_of(path: Path, value: Any, what: str) -> tuple[float, float, float]:
    """Three floats from 1 or 3 numbers (or numeric strings); SceneError otherwise."""
    try:
        values = [float(v) for v in np.atleast_1d(np.asarray(value, dtype=object)).tolist()]
    except (TypeError, ValueError):
        raise SceneError(path, f"{what}: {value!r} is not a number or RGB triple") from None
    if len(values) == 1:
        values *= 3
    if len(values) != 3:
        raise SceneError(path, f"{what}: expected 1 or 3 numbers, got {len(values)}")
    return (values[0], values[1], values[2])


def used_vertices(triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(n,) indices of the vertices the triangles use, and (t, 3) triangles over them."""
    used, local = np.unique(np.asarray(triangles, dtype=np.int64).ravel(), return_inverse=True)
    return used, local.reshape(-1, 3)


def compact(vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Only the vertices the triangles use, and the triangles renumbered to them.

    Returns
    -------
    positions : (n, 3) float64
    triangles : (t, 3) int64
    """
    used, local = used_vertices(triangles)
    return np.asarray(vertices, dtype=np.float64)[used], local
