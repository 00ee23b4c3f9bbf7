"""Writing binary glTF 2.0: the container, buffers, and the baked model.

The baked model (:func:`write_baked_glb`) carries the solution two ways:

* ``COLOR_0``: per-vertex linear colour, the radiance B/pi times the exposure, clipped to
  [0, 1], shown by any viewer through an unlit material (``KHR_materials_unlit``);
* with a lightmap: ``TEXCOORD_1`` and the lightmap image (8-bit sRGB PNG of the same exposed
  radiance) as the ``emissiveTexture`` on texture coordinate 1, so common viewers show the
  bake; the float EXR lightmap written beside it holds the unclipped radiosity.

``extras.raytrad`` records the exposure, so radiance = COLOR_0 / exposure [W sr-1 m-2].
"""

from __future__ import annotations

import json
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from raytrad.io.atomic import atomic_write

TRIANGLES = 4
_FLOAT, _UNSIGNED_INT = 5126, 5125
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963


class GltfBuffers:
    """Accessors, buffer views and the bytes of glTF buffer 0, built up array by array."""

    def __init__(self) -> None:
        self.blobs: list[bytes] = []
        self.views: list[dict[str, object]] = []
        self.accessors: list[dict[str, object]] = []

    def _view(self, data: bytes, target: int | None) -> int:
        offset = sum(len(b) for b in self.blobs)
        padding = b"\0" * (-len(data) % 4)
        self.blobs.append(data + padding)
        view: dict[str, object] = {"buffer": 0, "byteOffset": offset, "byteLength": len(data)}
        if target is not None:
            view["target"] = target
        self.views.append(view)
        return len(self.views) - 1

    def add(self, data: np.ndarray, kind: str, indices: bool = False) -> int:
        """Append a float32 (n, k) or uint32 (n,) array; return its accessor index.

        Parameters
        ----------
        data : ndarray
            float32 rows (``VEC2``/``VEC3``) or uint32 indices (``SCALAR``).
        kind : str
            glTF accessor type.
        indices : bool
            An index buffer (element array target).
        """
        view = self._view(
            np.ascontiguousarray(data).tobytes(),
            _ELEMENT_ARRAY_BUFFER if indices else _ARRAY_BUFFER,
        )
        accessor: dict[str, object] = {
            "bufferView": view,
            "componentType": _FLOAT if data.dtype.kind == "f" else _UNSIGNED_INT,
            "count": int(data.shape[0]),
            "type": kind,
        }
        if kind == "VEC3" and len(data):  # required on POSITION accessors
            accessor["min"] = data.min(axis=0).tolist()
            accessor["max"] = data.max(axis=0).tolist()
        self.accessors.append(accessor)
        return len(self.accessors) - 1

    def add_image(self, png: bytes) -> int:
        """Append PNG bytes; return the buffer-view index for an ``images`` entry."""
        return self._view(png, None)

    def binary(self) -> bytes:
        return b"".join(self.blobs)


def glb_container(json_bytes: bytes, binary: bytes) -> bytes:
    """GLB bytes: 12-byte header, JSON chunk (space-padded), BIN chunk (zero-padded)."""
    json_bytes += b" " * (-len(json_bytes) % 4)
    binary += b"\0" * (-len(binary) % 4)
    total = 12 + 8 + len(json_bytes) + 8 + len(binary)
    return b"".join(
        [
            struct.pack("<4sII", b"glTF", 2, total),
            struct.pack("<II", len(json_bytes), 0x4E4F534A),
            json_bytes,
            struct.pack("<II", len(binary), 0x004E4942),
            binary,
        ]
    )


@dataclass(frozen=True, eq=False)
class BakedPart:
    """One mesh of the baked model: a glTF node with one primitive.

    Attributes
    ----------
    name : str
    positions : (V, 3) float [m]
    normals : (V, 3) float, unit
    triangles : (T, 3) int, counter-clockwise from the lit side
    colour : (V, 3) float
        Linear display colour in [0, 1] (radiance times the exposure).
    lightmap_uv : (V, 2) float or None
        Lightmap coordinates in [0, 1] (glTF convention: v down).
    lightmap_png : bytes or None
        This part's lightmap image; parts may share one (the same bytes object is stored
        once). Requires ``lightmap_uv``.
    """

    name: str
    positions: np.ndarray
    normals: np.ndarray
    triangles: np.ndarray
    colour: np.ndarray
    lightmap_uv: np.ndarray | None = None
    lightmap_png: bytes | None = None


def write_baked_glb(
    path: Path,
    parts: list[BakedPart],
    exposure: float,
    extras: dict[str, Any] | None = None,
) -> None:
    """Write the baked model as one ``.glb`` (atomically), one node per part.

    Parameters
    ----------
    path : Path
    parts : list of BakedPart
    exposure : float
        Multiplier from radiance [W sr-1 m-2] to the parts' ``colour`` (recorded in extras).
    extras : dict or None
        More facts for ``extras.raytrad`` (units, settings, version).
    """
    gltf = GltfBuffers()
    header: dict[str, Any] = {"asset": {"version": "2.0", "generator": "raytrad"}}
    materials: list[dict[str, Any]] = []
    textures: dict[int, int] = {}  # id(png) -> texture index
    images: list[dict[str, Any]] = []
    meshes: list[dict[str, Any]] = []
    unlit: int | None = None  # the shared unlit material's index, once a part needs it
    for part in parts:
        attributes = {
            "POSITION": gltf.add(np.asarray(part.positions, dtype="<f4"), "VEC3"),
            "NORMAL": gltf.add(np.asarray(part.normals, dtype="<f4"), "VEC3"),
            "COLOR_0": gltf.add(np.clip(np.asarray(part.colour, dtype="<f4"), 0.0, 1.0), "VEC3"),
        }
        if part.lightmap_png is not None and part.lightmap_uv is not None:
            attributes["TEXCOORD_1"] = gltf.add(np.asarray(part.lightmap_uv, dtype="<f4"), "VEC2")
            if id(part.lightmap_png) not in textures:
                textures[id(part.lightmap_png)] = len(images)
                images.append(
                    {"bufferView": gltf.add_image(part.lightmap_png), "mimeType": "image/png"}
                )
            materials.append(_lightmap_material(part.name, textures[id(part.lightmap_png)]))
            material = len(materials) - 1
        else:
            if unlit is None:
                unlit = len(materials)
                materials.append(_UNLIT_MATERIAL)
            material = unlit
        indices = np.asarray(part.triangles, dtype="<u4").reshape(-1)
        primitive = {
            "attributes": attributes,
            "indices": gltf.add(indices, "SCALAR", True),
            "material": material,
            "mode": TRIANGLES,
        }
        meshes.append({"name": part.name, "primitives": [primitive]})
    if images:
        header["images"] = images
        header["samplers"] = [{"magFilter": 9729, "minFilter": 9729}]
        header["textures"] = [{"source": i, "sampler": 0} for i in range(len(images))]
    if unlit is not None:
        header["extensionsUsed"] = ["KHR_materials_unlit"]
    binary = gltf.binary()
    header.update(
        {
            "scene": 0,
            "scenes": [{"nodes": list(range(len(parts)))}],
            "nodes": [{"name": part.name, "mesh": i} for i, part in enumerate(parts)],
            "meshes": meshes,
            "materials": materials,
            "accessors": gltf.accessors,
            "bufferViews": gltf.views,
            "buffers": [{"byteLength": len(binary)}],
            "extras": {"raytrad": {"exposure": exposure, **(extras or {})}},
        }
    )
    with atomic_write(path) as handle:
        handle.write(glb_container(json.dumps(header).encode("utf-8"), binary))


_UNLIT_MATERIAL: dict[str, Any] = {
    "name": "baked",
    "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1], "metallicFactor": 0.0},
    "extensions": {"KHR_materials_unlit": {}},
}
"""Shows ``COLOR_0`` as is, in viewers that know the extension."""


def _lightmap_material(name: str, texture: int) -> dict[str, Any]:
    """A material showing lightmap ``texture`` (on ``TEXCOORD_1``) as emission."""
    return {
        "name": f"{name}-lightmap",
        "pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1], "metallicFactor": 0.0},
        "emissiveFactor": [1, 1, 1],
        "emissiveTexture": {"index": texture, "texCoord": 1},
    }
