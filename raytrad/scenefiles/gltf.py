"""glTF 2.0 scene files (``.gltf`` with its buffers, ``.glb``): geometry, materials, cameras.

The JSON is parsed once. Cameras are read from it as they are (when asked for,
:mod:`raytrad.scenefiles.gltf_cameras`); material values are read from it exactly, then
each material is replaced by a name-only token; the geometry is decoded and checked by
:mod:`raytrad.scenefiles.gltf_geometry`, and the rewritten document handed to trimesh for
the node tree, so trimesh never interprets (or rejects) a material value or an accessor.

reflectance = ``pbrMetallicRoughness.baseColorFactor[:3]`` [1]; emitted exitance =
pi x ``emissiveFactor`` x ``KHR_materials_emissive_strength.emissiveStrength`` [W m-2]
(glTF emission is a radiance).
"""

from __future__ import annotations

import json
import math
import os
import re
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from raytrad.errors import SceneError
from raytrad.formats.glb import GLB_MAGIC, split_glb
from raytrad.scene import NamedCamera
from raytrad.scenefiles import trimesh_adapter
from raytrad.scenefiles.common import (
    Collected,
    Material,
    ReadOptions,
    checked_path,
    reason,
    rgb_of,
)
from raytrad.scenefiles.gltf_cameras import cameras_from_document
from raytrad.scenefiles.gltf_geometry import (
    GEOMETRY_BUFFER,
    glb_bin_chunk,
    load_buffers,
    plain_geometry,
)

_MATERIAL_TOKEN = re.compile(r"^__raytrad_material_(\d+)__$")
_DEFAULT_MATERIAL = Material("default", (1.0, 1.0, 1.0))


def read_gltf(path: Path, options: ReadOptions) -> Collected:
    """A ``.gltf`` file (JSON, buffers beside it or as data URIs)."""
    document = parse_json(path, path.read_bytes(), "glTF")
    return _read(path, options, document, None)


def read_glb(path: Path, options: ReadOptions) -> Collected:
    """A binary ``.glb`` file: its JSON chunk and its ``BIN`` chunk."""
    json_bytes, rest = _split(path, path.read_bytes())
    document = parse_json(path, json_bytes, "GLB")
    return _read(path, options, document, glb_bin_chunk(rest))


def _read(path: Path, options: ReadOptions, document: Any, glb_bin: bytes | None) -> Collected:
    """Materials and cameras read here, geometry decoded here
    (:mod:`~raytrad.scenefiles.gltf_geometry`), the node tree through trimesh."""
    collected, materials = _collect(path, options, document)
    buffers = load_buffers(path, document, glb_bin, options.allow_outside)
    plain, data = plain_geometry(path, document, buffers, collected.warn_once)
    payload = json.dumps(plain).encode("utf-8")
    return _add_geometry(collected, payload, data, materials, _node_names(document))


def read_gltf_cameras(path: str | os.PathLike[str], scale: float = 1.0) -> list[NamedCamera]:
    """The perspective cameras of a ``.gltf`` or ``.glb`` file's default scene.

    A file starting with the GLB magic is read as binary whatever its suffix. See
    :func:`~raytrad.scenefiles.gltf_cameras.cameras_from_document` for the order,
    the units and the errors.
    """
    path, scale = checked_path(path, scale)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise SceneError(path, f"cannot read the file: {exc.strerror or exc}") from exc
    binary = path.suffix.lower() == ".glb" or data[:4] == GLB_MAGIC
    text = _split(path, data)[0].rstrip(b" \0") if binary else data
    return cameras_from_document(path, parse_json(path, text, "glTF"), scale)


def parse_json(path: Path, data: bytes, label: str) -> Any:
    """The JSON of a glTF file or GLB chunk; SceneError ``cannot parse as <label>``."""
    try:
        return json.loads(data.decode("utf-8-sig"))
    except (ValueError, RecursionError) as exc:  # JSONDecodeError, UnicodeDecodeError
        where = "bad JSON chunk: " if label == "GLB" else ""
        why = "nesting too deep" if isinstance(exc, RecursionError) else reason(exc)
        raise SceneError(path, f"cannot parse as {label}: {where}{why}") from None


def _split(path: Path, data: bytes) -> tuple[bytes, bytes]:
    try:
        return split_glb(data)
    except ValueError as exc:
        raise SceneError(path, f"cannot parse as GLB: {exc}") from None


def _collect(path: Path, options: ReadOptions, document: Any) -> tuple[Collected, list[Material]]:
    """A collector holding the document's cameras (when asked for), and the document's
    materials; the document is rewritten for trimesh (material tokens, the UV set asked
    for)."""
    collected = Collected(path, options)
    if options.cameras and isinstance(document, dict):
        collected.cameras = cameras_from_document(path, document, options.scale)
    materials = _gltf_materials(collected, document)
    _select_texcoord(collected, document)
    return collected, materials


def _gltf_materials(collected: Collected, document: Any) -> list[Material]:
    """Read every material of a glTF document and replace it by a name-only token.

    trimesh then sees ``{"name": "__raytrad_material_<i>__"}`` for material ``i``, which
    tells which material a loaded primitive uses without trimesh interpreting (or
    rejecting) any material value; images and textures are dropped for the same reason.
    """
    path = collected.path
    if not isinstance(document, dict):
        raise SceneError(path, "cannot parse as glTF: the JSON is not an object")
    specs = document.get("materials", [])
    if not isinstance(specs, list):
        raise SceneError(path, "glTF 'materials' is not a list")
    materials: list[Material] = []
    names: set[str] = set()
    for i, spec in enumerate(specs):
        if not isinstance(spec, dict):
            raise SceneError(path, f"glTF material {i} is not an object")
        try:
            material = _gltf_material(collected, i, spec)
        except (AttributeError, TypeError) as exc:  # a key of the wrong JSON type
            raise SceneError(path, f"glTF material {i} is malformed: {reason(exc)}") from None
        name = material.name if material.name not in names else f"{material.name}_{i}"
        names.add(name)
        materials.append(replace(material, name=name))
    if specs:
        document["materials"] = [{"name": f"__raytrad_material_{i}__"} for i in range(len(specs))]
    for key in ("textures", "images", "samplers"):
        document.pop(key, None)
    return materials


def _select_texcoord(collected: Collected, document: dict[str, Any]) -> None:
    """Make ``TEXCOORD_<uv_set>`` the set trimesh reads, ``TEXCOORD_0``, in every primitive.

    trimesh reads only ``TEXCOORD_0``, and only for primitives with a material, so
    primitives without one get a token past the file's materials (glTF's default
    material, see :func:`_add_geometry`). Without a ``uv_set`` nothing changes.
    """
    uv_set = collected.uv_set
    if uv_set is None:
        return
    tokens = document.setdefault("materials", [])
    default = len(tokens)
    needs_default = False
    for mesh in document.get("meshes", []) if isinstance(document.get("meshes"), list) else []:
        primitives = mesh.get("primitives", []) if isinstance(mesh, dict) else []
        for primitive in primitives if isinstance(primitives, list) else []:
            attributes = primitive.get("attributes") if isinstance(primitive, dict) else None
            if not isinstance(attributes, dict):
                continue
            accessor = attributes.pop(f"TEXCOORD_{uv_set}", None)
            for name in [a for a in attributes if a.startswith("TEXCOORD_")]:
                del attributes[name]
            if accessor is not None:
                attributes["TEXCOORD_0"] = accessor
            if "material" not in primitive:
                primitive["material"] = default
                needs_default = True
    if needs_default:
        tokens.append({"name": f"__raytrad_material_{default}__"})


def _gltf_material(collected: Collected, index: int, spec: dict[str, Any]) -> Material:
    """Reflectance, emitted exitance (pi x emitted radiance [W m-2]) and sidedness.

    reflectance = ``pbrMetallicRoughness.baseColorFactor[:3]``;
    emitted radiance = ``emissiveFactor`` x ``KHR_materials_emissive_strength.emissiveStrength``
    [W m-2 sr-1].
    """
    path = collected.path
    name = str(spec.get("name") or f"material_{index}")
    what = f"material {name!r}"
    pbr = spec.get("pbrMetallicRoughness") or {}
    base = pbr.get("baseColorFactor", [1.0, 1.0, 1.0, 1.0])
    if not isinstance(base, list) or len(base) not in (3, 4):
        raise SceneError(path, f"{what}: baseColorFactor {base!r} is not an RGBA list")
    reflectance = rgb_of(path, base[:3], f"{what} baseColorFactor")
    factor = np.array(rgb_of(path, spec.get("emissiveFactor", [0.0, 0.0, 0.0]), what))
    extension = (spec.get("extensions") or {}).get("KHR_materials_emissive_strength") or {}
    strength = extension.get("emissiveStrength", 1.0)
    if not isinstance(strength, int | float) or isinstance(strength, bool):
        raise SceneError(path, f"{what}: emissiveStrength {strength!r} is not a number")
    emitted = math.pi * (factor * float(strength))
    if not np.isfinite(emitted).all():
        raise SceneError(
            path,
            f"{what}: emission pi x emissiveFactor {factor.tolist()} x emissiveStrength "
            f"{strength} overflows",
        )
    if "baseColorTexture" in pbr or "emissiveTexture" in spec:
        collected.warn_once(
            "texture", "material textures are ignored; their constant factors are used"
        )
    double_sided = spec.get("doubleSided", False)
    if not isinstance(double_sided, bool):
        raise SceneError(path, f"{what}: doubleSided {double_sided!r} is not true or false")
    return Material(name, reflectance, (emitted[0], emitted[1], emitted[2]), double_sided)


def _node_names(document: dict[str, Any]) -> list[str]:
    """The names of a glTF document's nodes, in file order (unnamed ones left out)."""
    nodes = document.get("nodes")
    if not isinstance(nodes, list):
        return []
    return [str(n["name"]) for n in nodes if isinstance(n, dict) and "name" in n]


def _add_geometry(
    collected: Collected,
    payload: bytes,
    data: bytes,
    materials: list[Material],
    node_order: list[str] | None = None,
) -> Collected:
    """Parse the rewritten glTF (JSON ``payload``, buffer ``data``) with trimesh and collect
    its triangles."""
    path = collected.path
    resolver = trimesh_adapter.bytes_resolver({GEOMETRY_BUFFER: data})
    tm_scene = trimesh_adapter.parse_scene(path, payload, "gltf", "glTF", resolver=resolver)

    def material_of(geometry: Any) -> Material:
        token = trimesh_adapter.material_name(geometry)
        match = _MATERIAL_TOKEN.match(token) if token is not None else None
        if match is None or int(match.group(1)) >= len(materials):
            collected.warn_once(
                "default",
                "primitives without a material use glTF's default (reflectance 1, which "
                "has no finite solution in a closed scene)",
            )
            return _DEFAULT_MATERIAL
        return materials[int(match.group(1))]

    trimesh_adapter.add_trimesh_scene(
        collected,
        tm_scene,
        material_of,
        lambda node, geometry: trimesh_adapter.node_object(tm_scene, node),
        node_order=node_order,
    )
    return collected
