"""Scene writers: a :class:`~raytrad.scene.Scene` as OBJ + MTL or as binary glTF 2.0.

They write what the readers of this package read back exactly: ``Kd``/``Ke`` with full
float64 precision, glTF factors with the emission as a radiance. ``tools/make_scenes.py``
writes the bundled ``scenes/`` with them.
"""

from __future__ import annotations

import logging
import math
import os
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from raytrad.formats.atomic import atomic_write
from raytrad.formats.glb import GltfDocument
from raytrad.scene import NamedCamera, Scene

log = logging.getLogger(__name__)


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
    (``emissiveFactor`` times ``KHR_materials_emissive_strength``), which the glTF reader
    (:mod:`raytrad.scenefiles.gltf`) multiplies back by pi. The scene's ``lightmap_uv``
    (if any) is stored as ``TEXCOORD_1``, with a vertex per corner.

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
    document = GltfDocument()
    for k, object_name in enumerate(scene.object_names):
        primitives = [
            _glb_primitive(
                document, scene, (scene.object_index == k) & (scene.material_index == i), i
            )
            for i in range(len(names))
        ]
        kept = [p for p in primitives if p is not None]
        if kept:
            document.add_mesh_node(object_name, kept)
    for i, name in enumerate(names):
        document.add_material(_gltf_material(scene, i, name))
    for k, named in enumerate(cameras):
        document.nodes.append(_camera_node(named, k))
        document.cameras.append({"type": "perspective", "perspective": _perspective(named)})
    if any("extensions" in m for m in document.materials):
        document.use_extension("KHR_materials_emissive_strength")
    with atomic_write(glb_path, "wb") as f:
        f.write(document.glb())


def _glb_primitive(
    document: GltfDocument, scene: Scene, selected: np.ndarray, material: int
) -> dict[str, Any] | None:
    """The primitive of the ``selected`` (T,) triangles, or None when there are none."""
    triangles = scene.triangles[selected]
    if len(triangles) == 0:
        return None
    if scene.lightmap_uv is None:
        used, local = np.unique(triangles.ravel(), return_inverse=True)
        return document.primitive(scene.positions[used], local.reshape(-1, 3), material)
    # a vertex per corner: UVs are per corner
    positions = scene.positions[triangles].reshape(-1, 3)
    local = np.arange(positions.shape[0]).reshape(-1, 3)
    uv = scene.lightmap_uv[selected].reshape(-1, 2)
    return document.primitive(positions, local, material, TEXCOORD_1=uv)


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
