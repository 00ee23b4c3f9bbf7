"""Binary glTF 2.0 (``.glb``): the container, and a document builder for writers.

* :func:`split_glb` / :func:`join_glb` / :func:`glb_container` read and write the GLB
  container: a 12-byte header, a JSON chunk and an optional BIN chunk (glTF 2.0 spec,
  section "Binary glTF Layout").
* :class:`GltfDocument` assembles the JSON header and buffer 0 of a new file from numpy
  arrays (accessors, buffer views, meshes, nodes, materials, embedded PNG images), for the
  scene writer (:mod:`raytrad.scenefiles.writers`) and the baked-model writer
  (:mod:`raytrad.outputs.gltf`).
"""

from __future__ import annotations

import json
import struct
from typing import Any

import numpy as np

#: Primitive mode of triangle lists.
TRIANGLES = 4
#: Magic bytes at the start of every GLB file.
GLB_MAGIC = b"glTF"
_JSON_CHUNK, _BIN_CHUNK = 0x4E4F534A, 0x004E4942
_FLOAT, _UNSIGNED_INT = 5126, 5125
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963
#: Bilinear magnification and minification.
_LINEAR = 9729


def split_glb(data: bytes) -> tuple[bytes, bytes]:
    """The JSON chunk's bytes and everything after it (the other chunks, headers included).

    Raises
    ------
    ValueError
        Not a GLB file, a version other than 2, a truncated file, or a first chunk that is
        not JSON; the message says which.
    """
    if len(data) < 20 or data[:4] != GLB_MAGIC:
        raise ValueError("not a binary glTF file (bad magic)")
    _, version, length = struct.unpack_from("<4sII", data, 0)
    if version != 2:
        raise ValueError(f"glTF version {version}, need 2")
    chunk_length, chunk_type = struct.unpack_from("<II", data, 12)
    if length > len(data) or 20 + chunk_length > length:
        raise ValueError(f"truncated ({len(data)} of {length} bytes)")
    if chunk_type != _JSON_CHUNK:
        raise ValueError("the first chunk is not JSON")
    return data[20 : 20 + chunk_length], data[20 + chunk_length : length]


def join_glb(json_bytes: bytes, rest: bytes) -> bytes:
    """A GLB container from a JSON chunk (space-padded to 4 bytes) and the following chunks
    as :func:`split_glb` returns them."""
    json_bytes += b" " * (-len(json_bytes) % 4)
    total = 12 + 8 + len(json_bytes) + len(rest)
    return (
        struct.pack("<4sII", GLB_MAGIC, 2, total)
        + struct.pack("<II", len(json_bytes), _JSON_CHUNK)
        + json_bytes
        + rest
    )


def glb_container(json_bytes: bytes, binary: bytes) -> bytes:
    """GLB bytes: 12-byte header, JSON chunk (space-padded), BIN chunk (zero-padded)."""
    binary += b"\0" * (-len(binary) % 4)
    return join_glb(json_bytes, struct.pack("<II", len(binary), _BIN_CHUNK) + binary)


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


class GltfDocument:
    """A glTF 2.0 document under construction: one scene of top-level nodes, one buffer.

    Writers add meshes, nodes, materials and images through the methods (or the public
    lists), then take the file's bytes from :meth:`glb`.
    """

    def __init__(self, generator: str = "raytrad") -> None:
        self.buffers = GltfBuffers()
        self.asset = {"version": "2.0", "generator": generator}
        self.nodes: list[dict[str, Any]] = []
        self.meshes: list[dict[str, Any]] = []
        self.materials: list[dict[str, Any]] = []
        self.cameras: list[dict[str, Any]] = []
        self.extensions_used: list[str] = []
        self.extras: dict[str, Any] | None = None
        self._images: list[dict[str, Any]] = []
        self._image_of: dict[int, int] = {}

    def primitive(
        self,
        positions: np.ndarray,
        triangles: np.ndarray,
        material: int,
        **attributes: np.ndarray,
    ) -> dict[str, Any]:
        """A triangle-list primitive; extra ``attributes`` by glTF name (``NORMAL=...``).

        Parameters
        ----------
        positions : (V, 3) float
            Stored as float32 ``POSITION``.
        triangles : (T, 3) int
            Indices into ``positions``, stored as uint32.
        material : int
            Index into :attr:`materials`.
        attributes : (V, k) float
            Stored as float32 ``VEC2``/``VEC3`` accessors, in the order given. glTF wants
            the ``TEXCOORD_<n>`` sets to start at 0 and run without a gap (validator:
            ``MESH_PRIMITIVE_INDEXED_SEMANTIC_CONTINUITY``), so a missing lower set shares
            the accessor of the lowest set given (``TEXCOORD_1`` alone also gives
            ``TEXCOORD_0``).
        """
        accessors = {"POSITION": self.buffers.add(np.asarray(positions, dtype="<f4"), "VEC3")}
        for name, values in attributes.items():
            values = np.asarray(values, dtype="<f4")
            accessors[name] = self.buffers.add(values, f"VEC{values.shape[1]}")
        sets = sorted(int(name[9:]) for name in accessors if name.startswith("TEXCOORD_"))
        for k in range(sets[-1] if sets else 0):
            accessors.setdefault(f"TEXCOORD_{k}", accessors[f"TEXCOORD_{sets[0]}"])
        indices = np.asarray(triangles, dtype="<u4").reshape(-1)
        return {
            "attributes": accessors,
            "indices": self.buffers.add(indices, "SCALAR", indices=True),
            "material": material,
            "mode": TRIANGLES,
        }

    def add_mesh_node(self, name: str, primitives: list[dict[str, Any]]) -> int:
        """A mesh of ``primitives`` and a top-level node holding it; the node's index."""
        self.meshes.append({"name": name, "primitives": primitives})
        self.nodes.append({"name": name, "mesh": len(self.meshes) - 1})
        return len(self.nodes) - 1

    def add_material(self, material: dict[str, Any]) -> int:
        """Append a material; its index."""
        self.materials.append(material)
        return len(self.materials) - 1

    def add_png_texture(self, png: bytes) -> int:
        """The texture index of PNG ``png`` (the same bytes object is stored once)."""
        if id(png) not in self._image_of:
            self._image_of[id(png)] = len(self._images)
            self._images.append(
                {"bufferView": self.buffers.add_image(png), "mimeType": "image/png"}
            )
        return self._image_of[id(png)]

    def use_extension(self, name: str) -> None:
        """Declare an extension in ``extensionsUsed`` (once)."""
        if name not in self.extensions_used:
            self.extensions_used.append(name)

    def header(self) -> dict[str, Any]:
        """The JSON header (every index refers into this document)."""
        binary_length = sum(len(b) for b in self.buffers.blobs)
        header: dict[str, Any] = {"asset": self.asset}
        if self._images:
            header["images"] = self._images
            header["samplers"] = [{"magFilter": _LINEAR, "minFilter": _LINEAR}]
            header["textures"] = [{"source": i, "sampler": 0} for i in range(len(self._images))]
        if self.extensions_used:
            header["extensionsUsed"] = list(self.extensions_used)
        header.update(
            {
                "scene": 0,
                "scenes": [{"nodes": list(range(len(self.nodes)))}],
                "nodes": self.nodes,
                "meshes": self.meshes,
                "materials": self.materials,
                "accessors": self.buffers.accessors,
                "bufferViews": self.buffers.views,
                "buffers": [{"byteLength": binary_length}],
            }
        )
        if self.cameras:
            header["cameras"] = self.cameras
        if self.extras is not None:
            header["extras"] = self.extras
        return header

    def glb(self) -> bytes:
        """The document as GLB bytes."""
        return glb_container(json.dumps(self.header()).encode("utf-8"), self.buffers.binary())
