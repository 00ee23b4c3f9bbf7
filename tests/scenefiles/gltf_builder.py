"""A small glTF 2.0 writer for the conformance tests: buffers, views, accessors, meshes,
nodes, written as ``.gltf`` (data URI or file buffer) or ``.glb``, independently of
raytrad's own writer."""

from __future__ import annotations

import base64
import json
import struct
from pathlib import Path
from typing import Any

import numpy as np

COMPONENT = {"i1": 5120, "u1": 5121, "i2": 5122, "u2": 5123, "u4": 5125, "f4": 5126}
KIND = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4"}

# materials: 0 a grey floor (reflectance 0.5), 1 a lamp of radiance 1 (exitance pi)
MATERIALS = [
    {"name": "floor", "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1]}},
    {
        "name": "lamp",
        "pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1]},
        "emissiveFactor": [1, 1, 1],
    },
]


class Gltf:
    """A glTF document being built, with one binary buffer."""

    def __init__(self) -> None:
        self.doc: dict[str, Any] = {
            "asset": {"version": "2.0"},
            "scene": 0,
            "scenes": [{"nodes": []}],
            "nodes": [],
            "meshes": [],
            "materials": [dict(m) for m in MATERIALS],
            "accessors": [],
            "bufferViews": [],
            "buffers": [],
        }
        self.data = bytearray()

    def view(self, raw: bytes, stride: int | None = None) -> int:
        self.data += b"\0" * (-len(self.data) % 4)
        view: dict[str, Any] = {"buffer": 0, "byteOffset": len(self.data), "byteLength": len(raw)}
        if stride is not None:
            view["byteStride"] = stride
        self.data += raw
        self.doc["bufferViews"].append(view)
        return len(self.doc["bufferViews"]) - 1

    def accessor(self, values: Any, dtype: str, **extra: Any) -> int:
        array = np.asarray(values, dtype="<" + dtype)
        array = array.reshape(len(array), -1)
        spec = {
            "bufferView": self.view(array.tobytes()),
            "componentType": COMPONENT[dtype],
            "count": len(array),
            "type": KIND[array.shape[1]],
            **extra,
        }
        if array.shape[1] == 3 and dtype == "f4":
            spec["min"], spec["max"] = array.min(0).tolist(), array.max(0).tolist()
        self.doc["accessors"].append(spec)
        return len(self.doc["accessors"]) - 1

    def mesh(self, *primitives: dict[str, Any]) -> int:
        self.doc["meshes"].append({"primitives": list(primitives)})
        return len(self.doc["meshes"]) - 1

    def node(self, root: bool = True, **spec: Any) -> int:
        self.doc["nodes"].append(spec)
        index = len(self.doc["nodes"]) - 1
        if root:
            self.doc["scenes"][0]["nodes"].append(index)
        return index

    def quad(self, corners: Any, material: int, index_type: str = "u2") -> dict[str, Any]:
        """A triangle-list primitive of one quad (two triangles 0 1 2, 0 2 3)."""
        return {
            "attributes": {"POSITION": self.accessor(corners, "f4")},
            "indices": self.accessor([0, 1, 2, 0, 2, 3], index_type),
            "material": material,
        }

    def write_gltf(self, path: Path, buffer_file: str | None = None) -> Path:
        doc = json.loads(json.dumps(self.doc))
        if buffer_file is None:
            uri = "data:application/octet-stream;base64," + base64.b64encode(self.data).decode()
        else:
            (path.parent / buffer_file).write_bytes(bytes(self.data))
            uri = buffer_file
        doc["buffers"] = [{"byteLength": len(self.data), "uri": uri}]
        path.write_text(json.dumps(doc))
        return path

    def write_glb(self, path: Path) -> Path:
        doc = json.loads(json.dumps(self.doc))
        doc["buffers"] = [{"byteLength": len(self.data)}]
        text = json.dumps(doc).encode()
        text += b" " * (-len(text) % 4)
        data = bytes(self.data) + b"\0" * (-len(self.data) % 4)
        chunks = struct.pack("<I4s", len(text), b"JSON") + text
        chunks += struct.pack("<I4s", len(data), b"BIN\0") + data
        path.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(chunks)) + chunks)
        return path
