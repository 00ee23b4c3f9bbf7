"""Scene builders for the stress suite: boxes, blocks, fins, windows and CAD-style defects.

Every builder returns a validated :class:`~raytrad.scene.Scene` in metres. Quads are given
corner by corner in order around the quad and re-wound here so their front (lit) side faces
a given direction; nothing in this module knows the expected answers.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from raytrad.scene import Scene, make_scene

Vector = Sequence[float] | np.ndarray
Material = tuple[float, float, bool]
"""(grey reflectance [1], grey emitted exitance [W m-2], double-sided)."""


class SceneBuilder:
    """Collects quads and triangles with named grey materials, then builds one Scene."""

    def __init__(self) -> None:
        self.materials: dict[str, Material] = {}
        self.positions: list[np.ndarray] = []
        self.triangles: list[np.ndarray] = []
        self.material: list[int] = []
        self._count = 0

    def material_named(
        self, name: str, reflectance: float, emitted: float = 0.0, double_sided: bool = False
    ) -> str:
        self.materials[name] = (reflectance, emitted, double_sided)
        return name

    def _index(self, name: str) -> int:
        return list(self.materials).index(name)

    def triangle(self, corners: np.ndarray, material: str, facing: Vector | None = None) -> None:
        """One triangle; re-wound so its normal has a positive component along ``facing``."""
        corners = np.asarray(corners, dtype=np.float64).reshape(3, 3)
        if facing is not None:
            normal = np.cross(corners[1] - corners[0], corners[2] - corners[0])
            if normal @ np.asarray(facing, dtype=np.float64) < 0:
                corners = corners[[0, 2, 1]]
        self.positions.append(corners)
        self.triangles.append(self._count + np.arange(3)[None, :])
        self.material.append(self._index(material))
        self._count += 3

    def quad(self, corners: np.ndarray, material: str, facing: Vector | None = None) -> None:
        """One planar quad (corners in order around it), split along the 0-2 diagonal."""
        corners = np.asarray(corners, dtype=np.float64).reshape(4, 3)
        if facing is not None:
            area = np.cross(corners[2] - corners[0], corners[3] - corners[1])
            if area @ np.asarray(facing, dtype=np.float64) < 0:
                corners = corners[[0, 3, 2, 1]]
        self.positions.append(corners)
        self.triangles.append(self._count + np.array([[0, 1, 2], [0, 2, 3]]))
        self.material += [self._index(material)] * 2
        self._count += 4

    def build(self) -> Scene:
        names = list(self.materials)
        return make_scene(
            positions=np.concatenate(self.positions),
            triangles=np.concatenate(self.triangles),
            material_index=np.array(self.material),
            material_names=names,
            material_reflectance=[[self.materials[n][0]] * 3 for n in names],
            material_emitted_exitance=[[self.materials[n][1]] * 3 for n in names],
            material_double_sided=[self.materials[n][2] for n in names],
        )


def rectangle(axis: int, level: float, lo: Vector, hi: Vector) -> np.ndarray:
    """(4, 3) corners of an axis-aligned rectangle in the plane ``x[axis] = level``.

    ``lo`` and ``hi`` are the (u, v) bounds on the two other axes, in increasing axis order.
    """
    u, v = (a for a in range(3) if a != axis)
    corners = np.zeros((4, 3))
    corners[:, axis] = level
    corners[:, u] = [lo[0], hi[0], hi[0], lo[0]]
    corners[:, v] = [lo[1], lo[1], hi[1], hi[1]]
    return corners


def box_faces(lo: Vector, hi: Vector) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """The six faces of an axis-aligned box: (name, corners (4, 3), outward normal (3,))."""
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


def add_room(
    builder: SceneBuilder,
    material: str,
    size: Vector = (1.0, 1.0, 1.0),
    skip: Sequence[str] = (),
    face_material: dict[str, str] | None = None,
) -> None:
    """The inside of the box [0, size]: six inward-facing faces, less those in ``skip``."""
    face_material = face_material or {}
    for name, corners, outward in box_faces((0.0, 0.0, 0.0), size):
        if name not in skip:
            builder.quad(corners, face_material.get(name, material), -outward)


def add_block(
    builder: SceneBuilder, material: str, lo: Vector, hi: Vector, bottom: bool = False
) -> None:
    """An outward-facing box [lo, hi]; without its bottom when it stands on a floor."""
    for name, corners, outward in box_faces(lo, hi):
        if name != "y-" or bottom:
            builder.quad(corners, material, outward)


def grid_wall(
    builder: SceneBuilder,
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
            corners = rectangle(axis, level, (u_cuts[i], v_cuts[j]), (u_cuts[i + 1], v_cuts[j + 1]))
            builder.quad(corners, name, facing)


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
