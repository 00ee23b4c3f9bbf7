"""Built-in test scenes, in metres, and writers that store a scene as OBJ + MTL or GLB.

Every builder returns a validated :class:`~raytrad.scene.Scene` whose quads are split
along their first diagonal (corners 0-2) and wound so the front (lit) side faces the
interior of an enclosure or away from a solid.
"""

from __future__ import annotations

import json
import logging
import math
import os
import re
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from raytrad.camera import Camera, NamedCamera
from raytrad.errors import SettingsError
from raytrad.io.atomic import atomic_write
from raytrad.io.gltf import TRIANGLES, GltfBuffers, glb_container
from raytrad.scene import Scene, make_scene

log = logging.getLogger(__name__)

MM = 1e-3
"""Metres per millimetre [m]."""

# Cornell box, REFERENCE.md section 4, in millimetres (y up, open at z = 0).
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


def _oriented(corners: np.ndarray, facing: np.ndarray) -> np.ndarray:
    """Quads re-wound, where needed, so their front side faces ``facing``.

    Parameters
    ----------
    corners : (Q, 4, 3) float
        Quad corners in order around the quad.
    facing : (Q, 3) float
        Any vector on the wanted front side.

    Returns
    -------
    (Q, 4, 3) float64
        Corners ``0, 1, 2, 3`` or ``0, 3, 2, 1`` (the 0-2 diagonal is kept either way).
    """
    corners = np.array(corners, dtype=np.float64)
    vector_area = np.cross(corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 1])
    flip = np.einsum("qi,qi->q", vector_area, np.asarray(facing, dtype=np.float64)) < 0.0
    corners[flip] = corners[flip][:, [0, 3, 2, 1]]
    return corners


def _quad_scene(
    corners: np.ndarray,
    facing: np.ndarray,
    quad_material: Sequence[str],
    materials: dict[str, tuple[tuple[float, ...], tuple[float, ...], bool]],
    quad_object: Sequence[str] | None = None,
) -> Scene:
    """A scene of quads (two triangles each, four own vertices each).

    Parameters
    ----------
    corners : (Q, 4, 3) float
        Quad corners [m].
    facing : (Q, 3) float
        Direction each quad's front side must face.
    quad_material : (Q,) sequence of str
        Material name of each quad.
    materials : dict
        name -> (reflectance (3,) [1], emitted exitance (3,) [W m-2], double-sided).
    quad_object : (Q,) sequence of str or None
        The object (mesh) each quad belongs to; None: one object, "scene".
    """
    corners = _oriented(corners, facing)
    objects = list(dict.fromkeys(quad_object or ["scene"]))
    owner = np.array([objects.index(o) for o in quad_object or ["scene"] * len(corners)])
    q = corners.shape[0]
    names = list(materials)
    triangles = 4 * np.arange(q)[:, None, None] + np.array([[0, 1, 2], [0, 2, 3]])
    index = np.array([names.index(m) for m in quad_material], dtype=np.int64)
    return make_scene(
        positions=corners.reshape(-1, 3),
        triangles=triangles.reshape(-1, 3),
        material_index=np.repeat(index, 2),
        material_names=names,
        material_reflectance=np.array([materials[n][0] for n in names]),
        material_emitted_exitance=np.array([materials[n][1] for n in names]),
        material_double_sided=np.array([materials[n][2] for n in names], dtype=bool),
        object_index=np.repeat(owner, 2),
        object_names=objects,
    )


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
    """The Cornell box of REFERENCE.md section 4 in metres, with its usual RGB materials.

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
    return _quad_scene(corners, facing, quad_material, CORNELL_MATERIALS, quad_object)


CORNELL_CAMERA = Camera((0.278, 0.273, -0.800), (0.278, 0.273, 0.0), (0.0, 1.0, 0.0), 39.3)
"""The Cornell box camera of REFERENCE.md [m, degrees]."""


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
    return _quad_scene(
        np.array(corners), np.array(facing), ["furnace"] * 6, {"furnace": (rho, emitted, False)}
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
    return _quad_scene(corners, facing, names, SHADOW_MATERIALS, names)


BUILTIN_SCENES: dict[str, Callable[[], Scene]] = {
    "cornell-box": cornell_box,
    "furnace": furnace_box,
    "shadow": shadow_scene,
}
"""Built-in scenes by name (each callable with no arguments)."""


# --------------------------------------------------------------------------- writers


def _file_names(names: Sequence[str]) -> list[str]:
    """Material names usable in OBJ/MTL: no whitespace (replaced by ``_``), all distinct."""
    result: list[str] = []
    for i, name in enumerate(names):
        clean = re.sub(r"\s+", "_", name.strip()) or f"material_{i}"
        if clean in result:
            clean = f"{clean}_{i}"
        if clean != name:
            log.warning("material %r is written as %r", name, clean)
        result.append(clean)
    return result


def _triple(values: np.ndarray) -> str:
    """Three floats written with ``repr`` so they read back bit for bit."""
    return " ".join(repr(float(v)) for v in values)


def write_obj(scene: Scene, obj_path: str | os.PathLike[str]) -> None:
    """Write a scene as OBJ plus an MTL file of the same stem beside it (both atomically).

    Positions are in metres; ``Kd`` is the diffuse reflectance (linear RGB) and ``Ke`` the
    emitted exitance [W m-2], both with full float64 precision. Faces are grouped by
    material with ``usemtl``. OBJ/MTL has no way to say a material is double-sided, so
    that flag is lost (noted in an MTL comment and a logged warning); use GLB
    (:func:`write_glb`) for scenes that need it.

    Parameters
    ----------
    scene : Scene
        The scene to write.
    obj_path : path-like
        The ``.obj`` file; the ``.mtl`` goes to ``obj_path.with_suffix(".mtl")``.
    """
    obj_path = Path(obj_path)
    mtl_path = obj_path.with_suffix(".mtl")
    names = _file_names(scene.material_names)
    mtl = ["# raytrad materials: Kd = diffuse reflectance [1], Ke = emitted exitance [W m-2]"]
    for i, name in enumerate(names):
        if scene.material_double_sided[i]:
            log.warning("%s: OBJ cannot store that %r is double-sided", obj_path, name)
            mtl.append("# double-sided in raytrad (OBJ/MTL cannot say so)")
        mtl += [f"newmtl {name}", f"Kd {_triple(scene.material_reflectance[i])}"]
        mtl += [f"Ke {_triple(scene.material_emitted_exitance[i])}", ""]
    obj = ["# raytrad scene, positions in metres [m]", f"mtllib {mtl_path.name}"]
    obj += [f"v {x!r} {y!r} {z!r}" for x, y, z in scene.positions.tolist()]
    for i, name in enumerate(names):
        faces = scene.triangles[scene.material_index == i] + 1
        if len(faces):
            obj.append(f"usemtl {name}")
            obj += [f"f {a} {b} {c}" for a, b, c in faces.tolist()]
    with atomic_write(mtl_path, "w") as f:
        f.write("\n".join(mtl))
    with atomic_write(obj_path, "w") as f:
        f.write("\n".join(obj) + "\n")


def _gltf_material(scene: Scene, i: int, name: str) -> dict[str, object]:
    """glTF material ``i``: baseColorFactor = reflectance, emission as radiance E / pi.

    The emitted radiance is stored as ``emissiveFactor`` (at most 1 per channel) times
    ``KHR_materials_emissive_strength`` when it exceeds 1 [W m-2 sr-1].
    """
    radiance = scene.material_emitted_exitance[i] / math.pi
    peak = float(radiance.max())
    material: dict[str, object] = {
        "name": name,
        "pbrMetallicRoughness": {
            "baseColorFactor": [*scene.material_reflectance[i].tolist(), 1.0],
            "metallicFactor": 0.0,
            "roughnessFactor": 1.0,
        },
        "doubleSided": bool(scene.material_double_sided[i]),
    }
    if peak > 0.0:
        strength = max(peak, 1.0)
        material["emissiveFactor"] = (radiance / strength).tolist()
        if strength > 1.0:
            material["extensions"] = {
                "KHR_materials_emissive_strength": {"emissiveStrength": strength}
            }
    return material


def write_glb(
    scene: Scene, glb_path: str | os.PathLike[str], cameras: Sequence[NamedCamera] = ()
) -> None:
    """Write a scene as binary glTF 2.0 (atomically): one node and mesh per object, one
    primitive per material, and one node per camera.

    Unlike OBJ, glTF keeps double-sidedness. Positions are stored as float32 [m];
    reflectance as ``baseColorFactor``; emitted exitance E [W m-2] as the radiance E / pi
    (``emissiveFactor`` times ``KHR_materials_emissive_strength``), which
    :func:`raytrad.io.loaders.load_scene` multiplies back by pi. The scene's
    ``lightmap_uv`` (if any) is stored as ``TEXCOORD_1``, with a vertex per corner.

    Parameters
    ----------
    scene : Scene
        The scene to write.
    glb_path : path-like
        The ``.glb`` file.
    cameras : sequence of NamedCamera
        Perspective cameras, stored as nodes looking along their local -Z.
    """
    names = [n or f"material_{i}" for i, n in enumerate(scene.material_names)]
    gltf = GltfBuffers()
    meshes: list[dict[str, object]] = []
    for k, object_name in enumerate(scene.object_names):
        primitives = [
            _glb_primitive(gltf, scene, (scene.object_index == k) & (scene.material_index == i), i)
            for i in range(len(names))
        ]
        primitives = [p for p in primitives if p is not None]
        if primitives:
            meshes.append({"name": object_name, "primitives": primitives})
    materials = [_gltf_material(scene, i, n) for i, n in enumerate(names)]
    binary = b"".join(gltf.blobs)
    nodes: list[dict[str, object]] = [{"name": m["name"], "mesh": k} for k, m in enumerate(meshes)]
    nodes += [_camera_node(named, k) for k, named in enumerate(cameras)]
    header: dict[str, object] = {
        "asset": {"version": "2.0", "generator": "raytrad"},
        "scene": 0,
        "scenes": [{"nodes": list(range(len(nodes)))}],
        "nodes": nodes,
        "meshes": meshes,
        "materials": materials,
        "accessors": gltf.accessors,
        "bufferViews": gltf.views,
        "buffers": [{"byteLength": len(binary)}],
    }
    if cameras:
        header["cameras"] = [
            {"type": "perspective", "perspective": _perspective(named)} for named in cameras
        ]
    if any("extensions" in m for m in materials):
        header["extensionsUsed"] = ["KHR_materials_emissive_strength"]
    with atomic_write(glb_path, "wb") as f:
        f.write(glb_container(json.dumps(header).encode("utf-8"), binary))


def _glb_primitive(
    gltf: GltfBuffers, scene: Scene, selected: np.ndarray, material: int
) -> dict[str, object] | None:
    """The primitive of the ``selected`` (T,) triangles, or None when there are none."""
    triangles = scene.triangles[selected]
    if len(triangles) == 0:
        return None
    attributes: dict[str, int] = {}
    if scene.lightmap_uv is None:
        used, local = np.unique(triangles.ravel(), return_inverse=True)
        positions = scene.positions[used]
    else:  # a vertex per corner: UVs are per corner
        positions = scene.positions[triangles].reshape(-1, 3)
        local = np.arange(positions.shape[0])
        uv = scene.lightmap_uv[selected].reshape(-1, 2)
        attributes["TEXCOORD_1"] = gltf.add(uv.astype("<f4"), "VEC2")
    attributes["POSITION"] = gltf.add(positions.astype("<f4"), "VEC3")
    return {
        "attributes": attributes,
        "indices": gltf.add(local.astype("<u4"), "SCALAR", indices=True),
        "material": material,
        "mode": TRIANGLES,
    }


def _camera_node(named: NamedCamera, index: int) -> dict[str, object]:
    """A node placing camera ``index``: its local -Z is the view direction, +Y up."""
    right, up, forward = named.camera.basis()
    return {
        "name": named.name,
        "camera": index,
        "translation": [float(v) for v in named.camera.position],
        "rotation": _quaternion(np.column_stack([right, up, -forward])),
    }


def _perspective(named: NamedCamera) -> dict[str, float]:
    view = {"yfov": math.radians(named.camera.vertical_fov_deg), "znear": 0.01}
    if named.aspect_ratio is not None:
        view["aspectRatio"] = named.aspect_ratio
    return view


def _quaternion(rotation: np.ndarray) -> list[float]:
    """Unit quaternion [x, y, z, w] of a (3, 3) rotation matrix (glTF's order)."""
    from scipy.spatial.transform import Rotation

    return [float(q) for q in Rotation.from_matrix(rotation).as_quat()]
