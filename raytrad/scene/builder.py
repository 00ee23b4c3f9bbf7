"""Building scenes from quads and triangles: the one builder of test and example geometry.

:class:`SceneBuilder` collects faces with named materials and objects and returns one
validated :class:`~raytrad.scene.Scene`. Each face gets its own vertices; a quad is split
along its 0-2 diagonal; a ``facing`` direction re-winds a face so that its front (lit)
side faces it. The built-in scenes (:mod:`raytrad.scene.builtin`), the tests and the
stress suite all build their geometry here, in the manner of Mitsuba 3's ``cornell_box()``:
a function returns data that a test can edit before use.

Units: positions [m]; reflectance [1]; emitted exitance [W m-2].
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from raytrad.constants import tol
from raytrad.scene.model import Scene, make_scene

Vector = Sequence[float] | np.ndarray
Colour = float | Sequence[float] | np.ndarray
"""A grey value or a linear RGB triple."""


@dataclass(frozen=True)
class Material:
    """A material of a built scene.

    Attributes
    ----------
    reflectance : (3,) float [1]
    emitted_exitance : (3,) float [W m-2]
    double_sided : bool
    """

    reflectance: tuple[float, float, float]
    emitted_exitance: tuple[float, float, float] = (0.0, 0.0, 0.0)
    double_sided: bool = False


def _rgb(value: Colour) -> tuple[float, float, float]:
    r, g, b = np.broadcast_to(np.asarray(value, dtype=np.float64), (3,)).tolist()
    return (r, g, b)


def facing_flip(normal: np.ndarray, facing: Vector) -> bool:
    """True when ``normal`` points away from ``facing`` (the face must be re-wound).

    Raises
    ------
    ValueError
        ``facing`` lies in the face's plane (to :data:`~raytrad.constants.tol` ``.parallel``
        of the two lengths), so it says nothing about which side is the front.
    """
    facing = np.asarray(facing, dtype=np.float64)
    dot = float(normal @ facing)
    if abs(dot) <= tol.parallel * float(np.linalg.norm(normal) * np.linalg.norm(facing)):
        raise ValueError(f"facing {facing.tolist()} lies in the plane of the face")
    return dot < 0.0


class SceneBuilder:
    """Collects faces with named materials and objects, then builds one :class:`Scene`.

    Materials are registered by name (:meth:`material`) and kept in registration order;
    objects in the order their first face arrives (faces added without an object go to
    ``"scene"``).
    """

    def __init__(self) -> None:
        self.materials: dict[str, Material] = {}
        self._positions: list[np.ndarray] = []
        self._triangles: list[np.ndarray] = []
        self._material: list[int] = []
        self._object: list[int] = []
        self._objects: dict[str, int] = {}
        self._count = 0

    def material(
        self,
        name: str,
        reflectance: Colour,
        emitted_exitance: Colour = 0.0,
        double_sided: bool = False,
    ) -> str:
        """Register (or redefine) material ``name``; returns the name.

        Parameters
        ----------
        reflectance : float or (3,) float [1]
        emitted_exitance : float or (3,) float [W m-2]
        double_sided : bool
        """
        self.materials[name] = Material(_rgb(reflectance), _rgb(emitted_exitance), double_sided)
        return name

    def _append(self, corners: np.ndarray, local: np.ndarray, material: str, obj: str) -> None:
        self._positions.append(corners)
        self._triangles.append(self._count + local)
        self._material += [list(self.materials).index(material)] * len(local)
        self._object += [self._objects.setdefault(obj, len(self._objects))] * len(local)
        self._count += len(corners)

    def triangle(
        self, corners: Vector, material: str, facing: Vector | None = None, obj: str = "scene"
    ) -> None:
        """One triangle ((3, 3) corners [m]), re-wound to face ``facing`` if given."""
        corners = np.asarray(corners, dtype=np.float64).reshape(3, 3)
        if facing is not None:
            normal = np.cross(corners[1] - corners[0], corners[2] - corners[0])
            if facing_flip(normal, facing):
                corners = corners[[0, 2, 1]]
        self._append(corners, np.array([[0, 1, 2]]), material, obj)

    def quad(
        self, corners: Vector, material: str, facing: Vector | None = None, obj: str = "scene"
    ) -> None:
        """One planar quad ((4, 3) corners [m] in order around it), split along 0-2.

        With ``facing``, corners ``0, 3, 2, 1`` replace ``0, 1, 2, 3`` where needed so the
        front faces it (the 0-2 diagonal is kept either way).
        """
        corners = np.asarray(corners, dtype=np.float64).reshape(4, 3)
        if facing is not None:
            area = np.cross(corners[2] - corners[0], corners[3] - corners[1])
            if facing_flip(area, facing):
                corners = corners[[0, 3, 2, 1]]
        self._append(corners, np.array([[0, 1, 2], [0, 2, 3]]), material, obj)

    def room(
        self,
        material: str,
        size: Vector = (1.0, 1.0, 1.0),
        skip: Sequence[str] = (),
        face_material: dict[str, str] | None = None,
        obj: str = "scene",
    ) -> None:
        """The inside of the box [0, size]: six inward-facing faces, less those in ``skip``
        (face names as :func:`box_faces`)."""
        face_material = face_material or {}
        for name, corners, outward in box_faces((0.0, 0.0, 0.0), size):
            if name not in skip:
                self.quad(corners, face_material.get(name, material), -outward, obj)

    def block(
        self, material: str, lo: Vector, hi: Vector, bottom: bool = False, obj: str = "scene"
    ) -> None:
        """An outward-facing box [lo, hi]; without its bottom when it stands on a floor."""
        for name, corners, outward in box_faces(lo, hi):
            if name != "y-" or bottom:
                self.quad(corners, material, outward, obj)

    def grid_wall(
        self,
        axis: int,
        level: float,
        u_cuts: Sequence[float],
        v_cuts: Sequence[float],
        material: str,
        facing: Vector,
        cell_material: dict[tuple[int, int], str | None] | None = None,
    ) -> None:
        """A conforming grid of rectangles in the plane ``x[axis] = level``.

        ``cell_material[(i, j)]`` overrides the material of cell (i, j); None leaves a hole.
        """
        cell_material = cell_material or {}
        for i in range(len(u_cuts) - 1):
            for j in range(len(v_cuts) - 1):
                name = cell_material.get((i, j), material)
                if name is None:
                    continue
                lo, hi = (u_cuts[i], v_cuts[j]), (u_cuts[i + 1], v_cuts[j + 1])
                self.quad(rectangle(axis, level, lo, hi), name, facing)

    def build(self, source: str | Path | None = None) -> Scene:
        """The validated scene (every registered material is kept, used or not)."""
        names = list(self.materials)
        materials = [self.materials[n] for n in names]
        return make_scene(
            positions=np.concatenate(self._positions),
            triangles=np.concatenate(self._triangles),
            material_index=np.array(self._material, dtype=np.int64),
            material_names=names,
            material_reflectance=np.array([m.reflectance for m in materials]),
            material_emitted_exitance=np.array([m.emitted_exitance for m in materials]),
            material_double_sided=np.array([m.double_sided for m in materials], dtype=bool),
            source=source,
            object_index=np.array(self._object, dtype=np.int64),
            object_names=list(self._objects),
        )


def quads_scene(
    quads: Sequence[Sequence[Sequence[float]]] | np.ndarray,
    materials: Mapping[str, tuple[Colour, Colour, bool]] | None = None,
    quad_material: Sequence[str] | None = None,
    facing: Sequence[Vector] | np.ndarray | None = None,
    quad_object: Sequence[str] | None = None,
) -> Scene:
    """A scene of planar quads, each with its own four vertices, split along corners 0-2.

    Parameters
    ----------
    quads : (Q, 4, 3) float
        Corners [m], counter-clockwise seen from the front (lit) side unless ``facing``
        re-winds them.
    materials : dict
        name -> (reflectance [1], emitted exitance [W m-2], double-sided), grey scalars or
        RGB triples; default one grey ``"grey"`` of reflectance 0.5 that does not emit.
    quad_material : (Q,) sequence of str
        Material of each quad; default the first material for all.
    facing : (Q, 3) float or None
        A direction on each quad's wanted front side.
    quad_object : (Q,) sequence of str or None
        The object each quad belongs to; default one object, ``"scene"``.
    """
    builder = SceneBuilder()
    for name, (reflectance, emitted, double_sided) in (
        materials or {"grey": (0.5, 0.0, False)}
    ).items():
        builder.material(name, reflectance, emitted, double_sided)
    corners = np.asarray(quads, dtype=np.float64).reshape(-1, 4, 3)
    names = quad_material or [next(iter(builder.materials))] * len(corners)
    objects = quad_object or ["scene"] * len(corners)
    for q, quad in enumerate(corners):
        builder.quad(quad, names[q], None if facing is None else facing[q], objects[q])
    return builder.build()


def rectangle(axis: int, level: float, lo: Vector, hi: Vector) -> np.ndarray:
    """(4, 3) corners of an axis-aligned rectangle in the plane ``x[axis] = level`` [m].

    ``lo`` and ``hi`` are the (u, v) bounds on the two other axes, in increasing axis order.
    """
    u, v = (a for a in range(3) if a != axis)
    corners = np.zeros((4, 3))
    corners[:, axis] = level
    corners[:, u] = [lo[0], hi[0], hi[0], lo[0]]
    corners[:, v] = [lo[1], lo[1], hi[1], hi[1]]
    return corners


def box_faces(lo: Vector, hi: Vector) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """The six faces of an axis-aligned box [lo, hi]: (name, (4, 3) corners, outward normal).

    Names are ``x-``, ``x+``, ``y-``, ``y+``, ``z-``, ``z+``.
    """
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    names = (("x-", "x+"), ("y-", "y+"), ("z-", "z+"))
    faces = []
    for axis in range(3):
        others = [a for a in range(3) if a != axis]
        for side, level in enumerate((lo[axis], hi[axis])):
            outward = np.zeros(3)
            outward[axis] = 1.0 if side else -1.0
            corners = rectangle(axis, level, lo[others], hi[others])
            faces.append((names[axis][side], corners, outward))
    return faces


def icosphere(subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit icosphere: (V, 3) vertices on the unit sphere and (T, 3) outward-wound triangles."""
    t = (1.0 + 5.0**0.5) / 2.0
    vertices = [
        (-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0),
        (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
        (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1),
    ]  # fmt: skip
    faces = [
        (0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11),
        (1, 5, 9), (5, 11, 4), (11, 10, 2), (10, 7, 6), (7, 1, 8),
        (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9),
        (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1),
    ]  # fmt: skip
    points = np.array(vertices, dtype=np.float64)
    points /= np.linalg.norm(points, axis=1)[:, None]
    tris = np.array(faces, dtype=np.int64)
    for _ in range(subdivisions):
        edges = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
        unique, inverse = np.unique(edges, axis=0, return_inverse=True)
        inverse = inverse.reshape(3, -1)
        mid = points[unique].mean(axis=1)
        mid /= np.linalg.norm(mid, axis=1)[:, None]
        m01, m12, m20 = (len(points) + inverse[k] for k in range(3))
        points = np.concatenate([points, mid])
        a, b, c = tris.T
        tris = np.concatenate(
            [
                np.stack([a, m01, m20], axis=1),
                np.stack([b, m12, m01], axis=1),
                np.stack([c, m20, m12], axis=1),
                np.stack([m01, m12, m20], axis=1),
            ]
        )
    return points, tris
