"""Occluders and patches shared by the culling and blocker tests: boxes and sheets, the
issue's constructed cases (a receiver peeking past an occluder's edge, a thin occluder
between parallel plates, one touching the shaft's boundary, one wholly inside the
shaft), Embree on a pass's segments, and a furnished room."""

from __future__ import annotations

import numpy as np

from raytrad.constants import tol
from raytrad.core.visibility import Occluder
from raytrad.scene import Scene
from raytrad.scene.builder import SceneBuilder, icosphere, quads_scene

DIAGONAL = 10.0
LIFT = tol.ray_offset * DIAGONAL


def quad_triangles(quad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.asarray(quad, dtype=float), np.array([[0, 1, 2], [0, 2, 3]])


def box(
    center: np.ndarray, half: np.ndarray, angle: float = 0.0, bottom: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """A box turned ``angle`` about y: its 8 corners and 12 (10 without the bottom)
    triangles, wound outward."""
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    c, s = np.cos(angle), np.sin(angle)
    turn = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    points = center + (signs * half) @ turn.T
    faces = [
        [0, 1, 3, 2],  # x-
        [4, 6, 7, 5],  # x+
        [2, 3, 7, 6],  # y+
        [0, 2, 6, 4],  # z-
        [1, 5, 7, 3],  # z+
    ]
    if bottom:
        faces.append([0, 4, 5, 1])  # y-
    triangles = [[f[0], f[1], f[2]] for f in faces] + [[f[0], f[2], f[3]] for f in faces]
    return points, np.array(triangles)


def join(*parts: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    points, triangles, base = [], [], 0
    for p, t in parts:
        points.append(p)
        triangles.append(t + base)
        base += len(p)
    return np.concatenate(points), np.concatenate(triangles)


def trace(occluder: Occluder, origin: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """Embree on the segments from ``origin`` to ``targets``, as the pass traces them."""
    d = targets - origin
    length = np.linalg.norm(d, axis=1)
    return occluder.occluded_local(
        np.repeat((origin - occluder.origin)[None, :], len(d), axis=0),
        d / length[:, None],
        length - 0.5 * LIFT,
    )


def quad_targets(quad: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
    """Random points of a planar quad, lifted ``LIFT`` along its normal (as ray targets)."""
    normal = np.cross(quad[1] - quad[0], quad[3] - quad[0])
    normal /= np.linalg.norm(normal)
    u, v = rng.random((2, count, 1))
    edge = quad[0] + u * (quad[1] - quad[0])
    far = quad[3] + u * (quad[2] - quad[3])
    return edge + v * (far - edge) + LIFT * normal


#: The constructed cases: an occluder, a patch behind it (a quad), receivers' ray origins
#: on a line, and whether some but not all of them must be blocked (True), none while
#: every one sees part of the patch (False), or none (None).
PATCH = np.array([[-1, 0, 4], [1, 0, 4], [1, 2, 4], [-1, 2, 4.0]])
PLATE = np.array([[-1, 0, 4], [-1, 2, 4], [1, 2, 4], [1, 0, 4.0]])  # facing -z
SWEEP = np.column_stack([np.linspace(-4, 4, 161), np.full(161, 1.0), np.zeros(161)])
CASES = {
    # a box between, receivers sliding sideways: some peek past its edge
    "peeking past an edge": (
        box(np.array([0, 1, 2.0]), np.array([1.2, 1.4, 0.3])),
        PLATE,
        SWEEP,
        True,
    ),
    # a thin occluder (a sheet) between parallel plates, larger than the plate's shadow
    # only in the middle
    "thin sheet between plates": (
        quad_triangles(
            np.array([[-0.8, -0.2, 2], [0.8, -0.2, 2], [0.8, 2.2, 2], [-0.8, 2.2, 2.0]])
        ),
        PLATE,
        SWEEP * [0.5, 1, 1],
        True,
    ),
    # a sheet whose edge lies on the shaft's side: the segments to the patch's edge
    # graze it (Embree may call them either way), so the pair is not blocked
    "touching the shaft's boundary": (
        quad_triangles(np.array([[-2, -2, 2], [0.25, -2, 2], [0.25, 4, 2], [-2, 4, 2.0]])),
        np.array([[-0.5, 0, 4], [-0.5, 2, 4], [0.5, 2, 4], [0.5, 0, 4.0]]),
        np.array([[0.0, 1.0, 0.0]]),
        None,
    ),
    # a box open at the bottom standing on a floor, receivers on the floor (a ray offset
    # above the open face's plane) and a plate behind it: some are hidden
    "behind a box on the floor": (
        box(np.array([0, 1, 2.0]), np.array([1.2, 1.0, 0.3]), bottom=False),
        PLATE + np.array([0, 0.2, 0]),
        SWEEP * [1, 0, 1] + [0, LIFT, 0],
        True,
    ),
    # a small box wholly inside the shaft: rays pass round it
    "inside the shaft": (
        box(np.array([0, 1, 2.0]), np.array([0.2, 0.2, 0.2])),
        PLATE,
        SWEEP,
        False,
    ),
}


def furniture_room(seed: int, blocks: int = 4) -> Scene:
    """A 4 x 3 x 4 m room lit from a ceiling panel, with randomly turned blocks on the floor
    and a tilted double-sided plate floating in it (y up)."""
    rng = np.random.default_rng(seed)
    s, h = 4.0, 3.0
    room = np.array(
        [
            [[0, 0, 0], [0, 0, s], [s, 0, s], [s, 0, 0]],  # floor
            [[0, h, 0], [s, h, 0], [s, h, s], [0, h, s]],  # ceiling
            [[0, 0, 0], [s, 0, 0], [s, h, 0], [0, h, 0]],
            [[0, 0, s], [0, h, s], [s, h, s], [s, 0, s]],
            [[0, 0, 0], [0, h, 0], [0, h, s], [0, 0, s]],
            [[s, 0, 0], [s, 0, s], [s, h, s], [s, h, 0]],
        ],
        dtype=float,
    )
    quads = list(room)
    facing = [(0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1), (1, 0, 0), (-1, 0, 0)]
    material = ["wall"] * 6
    light = np.array(
        [[1.5, h - 0.01, 1.5], [2.5, h - 0.01, 1.5], [2.5, h - 0.01, 2.5], [1.5, h - 0.01, 2.5]]
    )
    quads.append(light)
    facing.append((0, -1, 0))
    material.append("light")
    for _ in range(blocks):
        centre = rng.uniform(0.8, s - 0.8, size=2)
        half = rng.uniform(0.15, 0.4)
        angle = rng.uniform(0, np.pi / 2)
        offsets = half * np.array([[1, 1], [-1, 1], [-1, -1], [1, -1]], dtype=float)
        c, si = np.cos(angle), np.sin(angle)
        xz = centre + offsets @ np.array([[c, si], [-si, c]])
        height = rng.uniform(0.3, 1.2)
        base = np.column_stack([xz[:, 0], np.zeros(4), xz[:, 1]])
        top = base + np.array([0.0, height, 0.0])
        quads.append(top)
        facing.append((0, 1, 0))
        for k in range(4):
            j = (k + 1) % 4
            quads.append(np.array([base[k], base[j], top[j], top[k]]))
            out = 0.5 * (base[k] + base[j]) - base.mean(axis=0)
            facing.append(tuple(out))
        material += ["block"] * 5
    plate = np.array([[1.0, 1.6, 1.0], [2.0, 1.9, 1.0], [2.0, 1.9, 2.0], [1.0, 1.6, 2.0]])
    quads.append(plate)
    facing.append((0, -1, 0))
    material.append("plate")
    return quads_scene(
        np.array(quads),
        {
            "wall": (0.6, 0.0, False),
            "light": (0.0, 10.0, False),
            "block": (0.5, 0.0, False),
            "plate": (0.4, 0.0, True),
        },
        material,
        np.array(facing, dtype=float),
    )


def ball_room(subdivisions: int = 3) -> Scene:
    """A 4 x 3 x 4 m room lit from a ceiling panel, with a box and a tessellated ball of
    ``20 * 4**subdivisions`` triangles on the floor (y up): past the shaft test's facets,
    so its small facets are gathered into volumes."""
    s, h = 4.0, 3.0
    builder = SceneBuilder()
    builder.material("wall", 0.6)
    builder.material("light", 0.0, 10.0)
    builder.material("block", 0.5)
    room = [
        ([[0, 0, 0], [0, 0, s], [s, 0, s], [s, 0, 0]], (0, 1, 0)),
        ([[0, h, 0], [s, h, 0], [s, h, s], [0, h, s]], (0, -1, 0)),
        ([[0, 0, 0], [s, 0, 0], [s, h, 0], [0, h, 0]], (0, 0, 1)),
        ([[0, 0, s], [0, h, s], [s, h, s], [s, 0, s]], (0, 0, -1)),
        ([[0, 0, 0], [0, h, 0], [0, h, s], [0, 0, s]], (1, 0, 0)),
        ([[s, 0, 0], [s, 0, s], [s, h, s], [s, h, 0]], (-1, 0, 0)),
    ]
    for quad, facing in room:
        builder.quad(np.array(quad, dtype=float), "wall", facing, "room")
    y = h - 0.01
    light = [[1.5, y, 1.5], [2.5, y, 1.5], [2.5, y, 2.5], [1.5, y, 2.5]]
    builder.quad(np.array(light), "light", (0, -1, 0), "light")
    points, triangles = box(np.array([2.8, 0.5, 1.2]), np.array([0.4, 0.5, 0.3]), 0.4, False)
    for tri in triangles:
        corners = points[tri]
        builder.triangle(corners, "block", corners.mean(axis=0) - [2.8, 0.5, 1.2], "box")
    unit, triangles = icosphere(subdivisions)
    centre = np.array([1.4, 0.6, 2.4])
    for tri in triangles:
        builder.triangle(centre + 0.6 * unit[tri], "block", unit[tri].mean(axis=0), "ball")
    return builder.build()
