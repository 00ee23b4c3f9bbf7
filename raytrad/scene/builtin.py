"""Built-in scenes, in metres: the Cornell box, the white furnace, an open shadow scene, a
room of many blocks and the Cornell box with a tessellated ball.

Every function returns a validated :class:`~raytrad.scene.Scene` built with
:class:`~raytrad.scene.builder.SceneBuilder`: quads split along their first diagonal
(corners 0-2) and wound so the front (lit) side faces the interior of an enclosure or away
from a solid. Files of them (``scenes/``) are written by :mod:`raytrad.scenefiles.writers`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from raytrad.constants import defaults
from raytrad.errors import SettingsError
from raytrad.scene.builder import SceneBuilder, icosphere, quads_scene
from raytrad.scene.camera import Camera
from raytrad.scene.model import Scene

MM = 1e-3
"""Metres per millimetre [m]."""

# Cornell box (Cornell Program of Computer Graphics data), in mm (y up, open at z = 0).
CORNELL_FLOOR = ((552.8, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 559.2), (549.6, 0.0, 559.2))
CORNELL_CEILING = (
    (556.0, 548.8, 0.0),
    (556.0, 548.8, 559.2),
    (0.0, 548.8, 559.2),
    (0.0, 548.8, 0.0),
)
CORNELL_BACK_WALL = (
    (549.6, 0.0, 559.2),
    (0.0, 0.0, 559.2),
    (0.0, 548.8, 559.2),
    (556.0, 548.8, 559.2),
)
CORNELL_RIGHT_WALL = ((0.0, 0.0, 559.2), (0.0, 0.0, 0.0), (0.0, 548.8, 0.0), (0.0, 548.8, 559.2))
CORNELL_LEFT_WALL = (
    (552.8, 0.0, 0.0),
    (549.6, 0.0, 559.2),
    (556.0, 548.8, 559.2),
    (556.0, 548.8, 0.0),
)
CORNELL_LIGHT_XZ = ((343.0, 227.0), (343.0, 332.0), (213.0, 332.0), (213.0, 227.0))
CORNELL_LIGHT_Y = 548.8 - 0.5
"""The light sits 0.5 mm below the ceiling so the two do not overlap [mm]."""
CORNELL_SHORT_BLOCK_XZ = ((130.0, 65.0), (82.0, 225.0), (240.0, 272.0), (290.0, 114.0))
CORNELL_SHORT_BLOCK_HEIGHT = 165.0
CORNELL_TALL_BLOCK_XZ = ((423.0, 247.0), (265.0, 296.0), (314.0, 456.0), (472.0, 406.0))
CORNELL_TALL_BLOCK_HEIGHT = 330.0

CORNELL_MATERIALS: dict[str, tuple[tuple[float, ...], tuple[float, ...], bool]] = {
    "white": ((0.725, 0.71, 0.68), (0.0, 0.0, 0.0), False),
    "red": ((0.63, 0.065, 0.05), (0.0, 0.0, 0.0), False),
    "green": ((0.14, 0.45, 0.091), (0.0, 0.0, 0.0), False),
    "light": ((0.78, 0.78, 0.78), (math.pi * 17.0, math.pi * 12.0, math.pi * 4.0), False),
}
"""name -> (reflectance [1], emitted exitance [W m-2], double-sided)."""

_UP = (0.0, 1.0, 0.0)
_DOWN = (0.0, -1.0, 0.0)


def _block(top_xz: Sequence[Sequence[float]], height: float) -> tuple[np.ndarray, np.ndarray]:
    """Top and four sides of a vertical prism standing on y = 0 (no bottom).

    Returns
    -------
    corners : (5, 4, 3) float64
        Quad corners, in the units of the input.
    facing : (5, 3) float64
        Outward directions: up for the top, away from the centre for the sides.
    """
    xz = np.asarray(top_xz, dtype=np.float64)
    nxt = np.roll(xz, -1, axis=0)
    zero, h = np.zeros(4), np.full(4, height)

    def at(points: np.ndarray, y: np.ndarray) -> np.ndarray:
        return np.column_stack([points[:, 0], y, points[:, 1]])

    top = at(xz, h)[None]
    sides = np.stack([at(xz, zero), at(nxt, zero), at(nxt, h), at(xz, h)], axis=1)
    outward = 0.5 * (xz + nxt) - xz.mean(axis=0)
    facing = np.vstack([_UP, at(outward, zero)])
    return np.concatenate([top, sides]), facing


def cornell_box() -> Scene:
    """The Cornell box (Cornell Program of Computer Graphics data) in metres, with its usual
    RGB materials.

    Walls, floor and ceiling are one quad each, the blocks five quads each (top and four
    sides), the light a quad 0.5 mm below the ceiling facing down. Materials: ``white``
    (floor, ceiling, back wall, blocks), ``red`` (left wall, x = 0.55 m), ``green`` (right
    wall, x = 0), ``light`` (reflectance 0.78, emitted exitance pi * (17, 12, 4) [W m-2]).
    """
    light = [(x, CORNELL_LIGHT_Y, z) for x, z in CORNELL_LIGHT_XZ]
    short_corners, short_facing = _block(CORNELL_SHORT_BLOCK_XZ, CORNELL_SHORT_BLOCK_HEIGHT)
    tall_corners, tall_facing = _block(CORNELL_TALL_BLOCK_XZ, CORNELL_TALL_BLOCK_HEIGHT)
    room = np.array(
        [
            CORNELL_FLOOR,
            CORNELL_CEILING,
            CORNELL_BACK_WALL,
            CORNELL_RIGHT_WALL,
            CORNELL_LEFT_WALL,
            light,
        ]
    )
    room_facing = np.array([_UP, _DOWN, (0, 0, -1), (1, 0, 0), (-1, 0, 0), _DOWN], dtype=float)
    corners = np.concatenate([room, short_corners, tall_corners]) * MM
    facing = np.concatenate([room_facing, short_facing, tall_facing])
    quad_material = ["white", "white", "white", "green", "red", "light"] + ["white"] * 10
    quad_object = ["floor", "ceiling", "back-wall", "right-wall", "left-wall", "light"]
    quad_object += ["short-block"] * 5 + ["tall-block"] * 5
    return quads_scene(corners, CORNELL_MATERIALS, quad_material, facing, quad_object)


#: The ball of :func:`ball_box`: its centre [mm], radius [mm] and icosphere subdivisions
#: (20 x 4**3 = 1 280 triangles).
BALL_CENTRE_MM = (450.0, 80.1, 120.0)
BALL_RADIUS_MM = 80.0
BALL_SUBDIVISIONS = 3


def ball_box() -> Scene:
    """The Cornell box (:func:`cornell_box`, the same quads, materials and objects) with a
    ``white`` ball of 1 280 triangles (object ``ball``) between the short block and the
    red wall, 0.1 mm above the floor: a curved object, each of whose triangles is a plane
    of its own, as a modelled scene's rounded furniture is."""
    base = cornell_box()
    builder = SceneBuilder()
    for name, (reflectance, emitted, double_sided) in CORNELL_MATERIALS.items():
        builder.material(name, reflectance, emitted, double_sided)
    corners = base.positions[base.triangles]
    for t in range(base.triangle_count):
        builder.triangle(
            corners[t],
            base.material_names[base.material_index[t]],
            obj=base.object_names[base.object_index[t]],
        )
    unit, triangles = icosphere(BALL_SUBDIVISIONS)
    centre = np.array(BALL_CENTRE_MM) * MM
    for tri in triangles:
        builder.triangle(centre + BALL_RADIUS_MM * MM * unit[tri], "white", obj="ball")
    return builder.build()


CORNELL_CAMERA = Camera(
    (0.278, 0.273, -0.800), (0.278, 0.273, 0.0), (0.0, 1.0, 0.0), defaults.vertical_fov_deg
)
"""The Cornell box camera of the Cornell data [m, degrees]."""


def furnace_box(
    reflectance: float | Sequence[float] = 0.5,
    emitted_exitance: float | Sequence[float] = 1.0,
    size: float = 1.0,
) -> Scene:
    """A closed cube lit from inside by its own walls: the white-furnace test.

    Every point of the inner surface has radiosity ``E / (1 - rho)`` [W m-2].

    Parameters
    ----------
    reflectance : float or (3,) float
        Reflectance of every face [1].
    emitted_exitance : float or (3,) float
        Emitted exitance of every face [W m-2].
    size : float
        Edge length [m]; the cube spans [0, size] on each axis.
    """
    if not (math.isfinite(size) and size > 0.0):
        raise SettingsError(f"furnace box size must be a finite number > 0, not {size}")
    rho = tuple(np.broadcast_to(np.asarray(reflectance, dtype=np.float64), (3,)).tolist())
    emitted = tuple(np.broadcast_to(np.asarray(emitted_exitance, dtype=np.float64), (3,)).tolist())
    unit_square = np.array([(0, 0), (1, 0), (1, 1), (0, 1)], dtype=np.float64)
    corners, facing = [], []
    for axis in range(3):
        u, v = [a for a in range(3) if a != axis]
        for side in (0.0, 1.0):
            quad = np.zeros((4, 3))
            quad[:, axis] = side
            quad[:, [u, v]] = unit_square
            corners.append(quad * size)
            facing.append(np.eye(3)[axis] * (1.0 if side == 0.0 else -1.0))
    return quads_scene(
        np.array(corners), {"furnace": (rho, emitted, False)}, ["furnace"] * 6, np.array(facing)
    )


def _horizontal_square(centre: Sequence[float], side: float) -> np.ndarray:
    """(4, 3) corners of an axis-aligned square in a plane y = const [m]."""
    x, y, z = centre
    h = 0.5 * side
    return np.array([(x - h, y, z - h), (x + h, y, z - h), (x + h, y, z + h), (x - h, y, z + h)])


SHADOW_MATERIALS: dict[str, tuple[tuple[float, ...], tuple[float, ...], bool]] = {
    "floor": ((0.6, 0.6, 0.6), (0.0, 0.0, 0.0), False),
    "light": ((0.0, 0.0, 0.0), (10.0, 10.0, 10.0), False),
    "occluder": ((0.5, 0.5, 0.5), (0.0, 0.0, 0.0), True),
}
"""name -> (reflectance [1], emitted exitance [W m-2], double-sided)."""


def shadow_scene() -> Scene:
    """An open scene: a square light above a floor with a square occluder in between (y up).

    Floor 2 x 2 m at y = 0 centred on the origin (reflectance 0.6, facing up); light
    0.5 x 0.5 m at y = 1.5 m facing down (single-sided, reflectance 0, emitted exitance
    10 [W m-2]); occluder 0.6 x 0.6 m at y = 0.75 m (double-sided, reflectance 0.5).
    """
    corners = np.array(
        [
            _horizontal_square((0.0, 0.0, 0.0), 2.0),
            _horizontal_square((0.0, 1.5, 0.0), 0.5),
            _horizontal_square((0.0, 0.75, 0.0), 0.6),
        ]
    )
    facing = np.array([_UP, _DOWN, _UP])
    names = ["floor", "light", "occluder"]
    return quads_scene(corners, SHADOW_MATERIALS, names, facing, names)


BLOCKS_ROOM_SIZE = (4.0, 3.0, 4.0)
"""The blocks room's width (x), height (y) and depth (z) [m]."""
BLOCKS_ROOM_MATERIALS: dict[str, tuple[tuple[float, ...], tuple[float, ...], bool]] = {
    "wall": ((0.6, 0.6, 0.6), (0.0, 0.0, 0.0), False),
    "block": ((0.5, 0.45, 0.4), (0.0, 0.0, 0.0), False),
    "light": ((0.0, 0.0, 0.0), (10.0, 10.0, 10.0), False),
}
"""name -> (reflectance [1], emitted exitance [W m-2], double-sided)."""


def blocks_room(blocks_per_side: int = 6, seed: int = 1) -> Scene:
    """A room of many objects: ``blocks_per_side`` x ``blocks_per_side`` blocks on the floor.

    A closed 4 x 3 x 4 m room (``wall``, reflectance 0.6, y up) lit by a 1 x 1 m square
    light 1 cm below the ceiling's centre (``light``, emitted exitance 10 W m-2, facing
    down). The floor is cut into a grid of square cells; each holds one block
    (``block``, reflectance (0.5, 0.45, 0.4)) standing on the floor, turned by a random
    angle about the vertical, 0.3-0.6 of a cell wide and 0.2-1.0 m tall, so no two blocks
    touch. Each block is five quads (top and sides; its foot is open, as a crate's).
    The same ``seed`` gives the same scene. A test of many occluders and contact
    outlines: 36 blocks give 187 planar facets (the default), within the shaft
    culling's limit for single-ray queries (:data:`raytrad.core.facets.MAX_FACETS`) and
    past the one for Embree's packets (:data:`~raytrad.core.facets.PACKET_FACETS`); 8 x
    8 give 327, past both.

    Parameters
    ----------
    blocks_per_side : int, >= 1
    seed : int
    """
    if blocks_per_side < 1:
        raise SettingsError(f"blocks_per_side must be at least 1, not {blocks_per_side}")
    width, height, depth = BLOCKS_ROOM_SIZE
    rng = np.random.default_rng(seed)
    quads = [
        [(0, 0, 0), (0, 0, depth), (width, 0, depth), (width, 0, 0)],
        [(0, height, 0), (width, height, 0), (width, height, depth), (0, height, depth)],
        [(0, 0, 0), (width, 0, 0), (width, height, 0), (0, height, 0)],
        [(0, 0, depth), (0, height, depth), (width, height, depth), (width, 0, depth)],
        [(0, 0, 0), (0, height, 0), (0, height, depth), (0, 0, depth)],
        [(width, 0, 0), (width, 0, depth), (width, height, depth), (width, height, 0)],
        _horizontal_square((0.5 * width, height - 0.01, 0.5 * depth), 1.0).tolist(),
    ]
    facing = [_UP, _DOWN, (0, 0, 1), (0, 0, -1), (1, 0, 0), (-1, 0, 0), _DOWN]
    material = ["wall"] * 6 + ["light"]
    objects = ["floor", "ceiling", "wall-z0", "wall-z1", "wall-x0", "wall-x1", "light"]
    cell = np.array([width, depth]) / blocks_per_side
    square = np.array([[1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]])
    for i in range(blocks_per_side):
        for j in range(blocks_per_side):
            centre = (np.array([i, j]) + 0.5) * cell
            half = cell.min() * rng.uniform(0.15, 0.3)
            angle = rng.uniform(0.0, 0.5 * np.pi)
            turn = np.array([[np.cos(angle), np.sin(angle)], [-np.sin(angle), np.cos(angle)]])
            xz = centre + half * square @ turn
            corners, faces = _block(xz, rng.uniform(0.2, 1.0))
            quads += corners.tolist()
            facing += faces.tolist()
            material += ["block"] * len(corners)
            objects += [f"block-{i}-{j}"] * len(corners)
    return quads_scene(quads, BLOCKS_ROOM_MATERIALS, material, facing, objects)


BUILTIN_SCENES: dict[str, Callable[[], Scene]] = {
    "cornell-box": cornell_box,
    "furnace": furnace_box,
    "shadow": shadow_scene,
    "blocks-room": blocks_room,
    "ball-box": ball_box,
}
"""Built-in scenes by name (each callable with no arguments)."""
