"""What the conformance tests measure of a loaded scene, independently of any loader.

Every expected value in the conformance tables is worked out by hand from the file the
test writes (areas of squares and L-shapes, counts, bounds, emitted power = exitance x
area); these helpers only add up the loaded triangles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from raytrad.scene import Scene

# A 1 m x 1 m floor at y = 0 facing up (Kd 0.5) and a 0.2 m x 0.2 m lamp (Ke 10) 1 m
# above its centre facing down: area 1.04 m2, emitted power 0.04 x 10 = 0.4 W.
FLOOR = ((0, 0, 0), (0, 0, 1), (1, 0, 1), (1, 0, 0))
LAMP = ((0.4, 1, 0.4), (0.6, 1, 0.4), (0.6, 1, 0.6), (0.4, 1, 0.6))
FLOOR_AND_LAMP_MTL = "newmtl floor\nKd 0.5 0.5 0.5\nnewmtl lamp\nKd 0 0 0\nKe 10 10 10\n"

# An L-shaped floor: the 2 m square minus its quarter x > 1, z > 1 (3 m2), one face
# facing up, starting at a corner next to the notch.
L_FLOOR = ((2, 0, 1), (2, 0, 0), (0, 0, 0), (0, 0, 2), (1, 0, 2), (1, 0, 1))


@dataclass(frozen=True)
class Measured:
    """Totals of a loaded scene."""

    triangles: int
    area: float
    by_material: dict[str, float]
    emitted_power: float
    lower: np.ndarray
    upper: np.ndarray
    normals: np.ndarray

    def area_of(self, name: str) -> float:
        return self.by_material.get(name, 0.0)


def measure(scene: Scene) -> Measured:
    """Triangle count, total area [m2], area per material, emitted power [W] (mean of the
    channels), bounds [m] and (t, 3) unit normals."""
    corners = scene.positions[scene.triangles]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    area = 0.5 * np.linalg.norm(cross, axis=1)
    by_material = {
        name: float(area[scene.material_index == i].sum())
        for i, name in enumerate(scene.material_names)
    }
    exitance = scene.material_emitted_exitance[scene.material_index].mean(axis=1)
    used = scene.positions[np.unique(scene.triangles)]
    return Measured(
        triangles=len(scene.triangles),
        area=float(area.sum()),
        by_material=by_material,
        emitted_power=float(exitance @ area),
        lower=used.min(axis=0),
        upper=used.max(axis=0),
        normals=cross / np.linalg.norm(cross, axis=1, keepdims=True),
    )


def inside_notch(scene: Scene) -> float:
    """Area [m2] of the triangles whose centroid lies in the L floor's notch."""
    corners = scene.positions[scene.triangles]
    centroid = corners.mean(axis=1)
    notch = (centroid[:, 0] > 1 + 1e-9) & (centroid[:, 2] > 1 + 1e-9)
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    return float(0.5 * np.linalg.norm(cross[notch], axis=1).sum())
