"""glTF 2.0 geometry decoded and checked by raytrad, handed to trimesh as plain triangles.

trimesh (5.2) ignores sparse accessors and ``normalized`` integers, reads triangle fans
as nothing, accepts any ``byteStride`` and lets an index past the vertices end in a
traceback. So every accessor a triangle primitive uses is decoded here, by the glTF 2.0
specification (section 3.6 "Binary Data Storage", 3.7 "Geometry"): buffers (GLB ``BIN``
chunk, data URIs, files beside the scene, through
:func:`~raytrad.scenefiles.common.read_reference`), buffer views and strides, sparse
substitution, normalized and quantized (``KHR_mesh_quantization``) integers, triangle
strips and fans, indices checked against the vertices. The document is then rewritten so
that each primitive is a triangle list of float32 positions (and the UV set asked for)
with uint32 indices in one new buffer; nodes, meshes and materials keep their indices.
"""

from __future__ import annotations

import base64
import binascii
import copy
import struct
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from raytrad.errors import SceneError
from raytrad.scenefiles.common import read_reference

#: The buffer the rewritten document refers to (served to trimesh by name).
GEOMETRY_BUFFER = "__raytrad_geometry__.bin"

#: Required extensions raytrad reads (anything else required is refused by name).
SUPPORTED_REQUIRED = frozenset(
    {"KHR_materials_emissive_strength", "KHR_mesh_quantization", "KHR_texture_transform"}
)

_COMPONENTS = {5120: "i1", 5121: "u1", 5122: "i2", 5123: "u2", 5125: "u4", 5126: "f4"}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_NORMALIZED_SCALE = {5120: 127.0, 5121: 255.0, 5122: 32767.0, 5123: 65535.0}
_INDEX_TYPES = (5121, 5123, 5125)
_TRIANGLES, _STRIP, _FAN = 4, 5, 6
_GLB_BIN = 0x004E4942


class _Document:
    """A glTF document with its buffers, decoding accessors on demand (each once)."""

    def __init__(self, path: Path, document: dict[str, Any], buffers: list[bytes]) -> None:
        self.path = path
        self.json = document
        self.buffers = buffers
        self.decoded: dict[int, np.ndarray] = {}

    def error(self, message: str) -> SceneError:
        return SceneError(self.path, f"cannot read glTF geometry: {message}")

    def item(self, key: str, index: Any, what: str) -> dict[str, Any]:
        items = self.json.get(key)
        valid = isinstance(index, int) and not isinstance(index, bool)
        if not valid or not isinstance(items, list) or not 0 <= index < len(items):
            raise self.error(f"{what} refers to {key} {index!r}, which does not exist")
        item = items[index]
        if not isinstance(item, dict):
            raise self.error(f"{key} {index} is not an object")
        return item

    def accessor(self, index: Any, what: str) -> np.ndarray:
        """(count, width) float64 values of an accessor (normalized ints scaled to [-1, 1])."""
        spec = self.item("accessors", index, what)
        if index not in self.decoded:
            self.decoded[index] = self._decode(index, spec)
        return self.decoded[index]

    def _decode(self, index: int, spec: dict[str, Any]) -> np.ndarray:
        what = f"accessor {index}"
        component, kind, count = spec.get("componentType"), spec.get("type"), spec.get("count")
        if component not in _COMPONENTS or kind not in _WIDTH:
            raise self.error(f"{what}: componentType {component!r} or type {kind!r} is invalid")
        if not isinstance(count, int) or count < 1:
            raise self.error(f"{what}: count {count!r} must be a whole number >= 1")
        dtype = np.dtype("<" + _COMPONENTS[component])
        width = _WIDTH[kind]
        if "bufferView" in spec:
            values = self._read(what, spec, dtype, count, width)
        else:
            values = np.zeros((count, width), dtype)
        values = values.astype(np.float64)
        if "sparse" in spec:
            self._substitute(what, spec["sparse"], values, dtype, width)
        if spec.get("normalized") is True and component in _NORMALIZED_SCALE:
            values = np.maximum(values / _NORMALIZED_SCALE[component], -1.0)
        return values

    def _view(self, what: str, index: Any) -> tuple[bytes, dict[str, Any]]:
        """The bytes of a buffer view and its spec."""
        view = self.item("bufferViews", index, what)
        buffer = view.get("buffer")
        if not isinstance(buffer, int) or not 0 <= buffer < len(self.buffers):
            raise self.error(
                f"bufferView {index} refers to buffer {buffer!r}, which does not exist"
            )
        start, length = view.get("byteOffset", 0), view.get("byteLength")
        data = self.buffers[buffer]
        if not (isinstance(start, int) and isinstance(length, int) and start >= 0 and length >= 1):
            raise self.error(f"bufferView {index}: bad byteOffset or byteLength")
        if start + length > len(data):
            raise self.error(
                f"bufferView {index} ends at byte {start + length}, past its buffer's {len(data)}"
            )
        return data[start : start + length], view

    def _read(
        self, what: str, spec: dict[str, Any], dtype: np.dtype[Any], count: int, width: int
    ) -> np.ndarray:
        data, view = self._view(what, spec["bufferView"])
        element = dtype.itemsize * width
        stride = view.get("byteStride", element)
        if "byteStride" in view and (
            not isinstance(stride, int) or not 4 <= stride <= 252 or stride % 4
        ):
            raise self.error(
                f"bufferView {spec['bufferView']}: byteStride {stride!r} must be a multiple of "
                "4 from 4 to 252"
            )
        if stride < element:
            raise self.error(
                f"{what}: its elements ({element} bytes) overlap at byteStride {stride}"
            )
        offset = spec.get("byteOffset", 0)
        if not isinstance(offset, int) or offset < 0:
            raise self.error(f"{what}: bad byteOffset {offset!r}")
        end = offset + stride * (count - 1) + element
        if end > len(data):
            raise self.error(f"{what} needs {end} bytes of its bufferView, which has {len(data)}")
        raw = np.frombuffer(data, dtype=np.uint8, count=end - offset, offset=offset)
        rows = np.lib.stride_tricks.as_strided(raw, (count, element), (stride, 1))
        return np.ascontiguousarray(rows).view(dtype).reshape(count, width)

    def _substitute(
        self, what: str, sparse: Any, values: np.ndarray, dtype: np.dtype[Any], width: int
    ) -> None:
        """Apply an accessor's sparse substitution to ``values`` in place."""
        if not isinstance(sparse, dict):
            raise self.error(f"{what}: sparse is not an object")
        count = sparse.get("count")
        indices, substitutes = sparse.get("indices"), sparse.get("values")
        if not (isinstance(count, int) and 1 <= count <= len(values)):
            raise self.error(f"{what}: sparse count {count!r} must be 1 to {len(values)}")
        if not isinstance(indices, dict) or indices.get("componentType") not in _INDEX_TYPES:
            raise self.error(f"{what}: sparse indices must be unsigned integers")
        if not isinstance(substitutes, dict):
            raise self.error(f"{what}: sparse values missing")
        index_type = np.dtype("<" + _COMPONENTS[indices["componentType"]])
        rows = self._read(what + " sparse indices", indices, index_type, count, 1).ravel()
        new = self._read(what + " sparse values", substitutes, dtype, count, width)
        if (np.diff(rows.astype(np.int64)) <= 0).any() or rows.max() >= len(values):
            raise self.error(
                f"{what}: sparse indices must increase strictly and stay below {len(values)}"
            )
        values[rows.astype(np.int64)] = new


def plain_geometry(
    path: Path,
    document: dict[str, Any],
    buffers: list[bytes],
    warn: Callable[[str, str], None],
) -> tuple[dict[str, Any], bytes]:
    """The document rewritten to plain triangle lists, and the one buffer it refers to.

    Parameters
    ----------
    path : Path
        The glTF file, for messages.
    document : dict
        Its JSON (not modified), after the UV set asked for was made ``TEXCOORD_0``.
    buffers : list of bytes
        The data of each of ``document["buffers"]`` (:func:`load_buffers`).
    warn : callable
        ``warn(key, message)``, called once per kind of thing left out (points, lines).

    Returns
    -------
    document : dict
        Meshes whose primitives are ``mode`` 4 with a float32 ``POSITION``, ``TEXCOORD_0``
        where the file has it, and uint32 ``indices``; one buffer, :data:`GEOMETRY_BUFFER`.
    data : bytes

    Raises
    ------
    SceneError
        An unsupported required extension, a reference to something that does not exist,
        a bad stride or accessor, an index outside the vertices, an unknown mode, or a
        node tree with a cycle; naming what is at fault.
    """
    required = document.get("extensionsRequired", [])
    unsupported = sorted(set(required) - SUPPORTED_REQUIRED) if isinstance(required, list) else []
    if unsupported:
        raise SceneError(
            path,
            f"requires glTF extension(s) raytrad does not support: "
            f"{', '.join(map(str, unsupported))}",
        )
    source = _Document(path, document, buffers)
    _check_nodes(source)
    out = copy.deepcopy(document)
    writer = _Writer()
    meshes = out.get("meshes", [])
    for m, mesh in enumerate(meshes if isinstance(meshes, list) else []):
        primitives = mesh.get("primitives") if isinstance(mesh, dict) else None
        if not isinstance(primitives, list):
            raise source.error(f"mesh {m} has no primitives list")
        kept = []
        for p, primitive in enumerate(primitives):
            plain = _plain_primitive(source, writer, f"mesh {m} primitive {p}", primitive, warn)
            if plain is not None:
                kept.append(plain)
        mesh["primitives"] = kept
    out["accessors"], out["bufferViews"] = writer.accessors, writer.views
    out["buffers"] = [{"byteLength": len(writer.data), "uri": GEOMETRY_BUFFER}]
    for key in ("extensionsRequired", "extensionsUsed"):
        out.pop(key, None)
    return out, bytes(writer.data)


def _plain_primitive(
    source: _Document,
    writer: _Writer,
    what: str,
    primitive: Any,
    warn: Callable[[str, str], None],
) -> dict[str, Any] | None:
    """One primitive as a plain triangle list, or None for points and lines."""
    if not isinstance(primitive, dict) or not isinstance(primitive.get("attributes"), dict):
        raise source.error(f"{what} has no attributes")
    mode = primitive.get("mode", _TRIANGLES)
    if mode in (0, 1, 2, 3):
        warn("points-lines", "primitives of points or lines carry no area; left out")
        return None
    if mode not in (_TRIANGLES, _STRIP, _FAN):
        raise source.error(f"{what}: mode {mode!r} is not a glTF primitive mode (0-6)")
    attributes = primitive["attributes"]
    if "POSITION" not in attributes:
        raise source.error(f"{what} has no POSITION")
    positions = source.accessor(attributes["POSITION"], what)
    if positions.shape[1] != 3:
        raise source.error(f"{what}: POSITION must be VEC3")
    if "indices" in primitive:
        spec = source.item("accessors", primitive["indices"], what)
        if spec.get("componentType") not in _INDEX_TYPES or spec.get("type") != "SCALAR":
            raise source.error(f"{what}: indices must be unsigned integer scalars")
        indices = source.accessor(primitive["indices"], what).ravel().astype(np.int64)
    else:
        indices = np.arange(len(positions), dtype=np.int64)
    if indices.size and indices.max() >= len(positions):
        raise source.error(
            f"{what}: index {int(indices.max())} is outside the vertices 0..{len(positions) - 1}"
        )
    triangles = _triangle_list(source, what, mode, indices)
    plain: dict[str, Any] = {
        "attributes": {"POSITION": writer.add(positions, "<f4", "VEC3")},
        "indices": writer.add(triangles.reshape(-1, 1), "<u4", "SCALAR"),
        "mode": _TRIANGLES,
    }
    if "TEXCOORD_0" in attributes:
        uv = source.accessor(attributes["TEXCOORD_0"], what)
        if uv.shape != (len(positions), 2):
            raise source.error(f"{what}: TEXCOORD_0 must be VEC2 with one entry per vertex")
        plain["attributes"]["TEXCOORD_0"] = writer.add(uv, "<f4", "VEC2")
    if "material" in primitive:
        source.item("materials", primitive["material"], what)
        plain["material"] = primitive["material"]
    return plain


def _triangle_list(source: _Document, what: str, mode: int, indices: np.ndarray) -> np.ndarray:
    """(t, 3) triangles of a list, strip or fan, each wound as its primitive."""
    if mode == _TRIANGLES:
        if len(indices) % 3:
            raise source.error(f"{what}: {len(indices)} indices do not make whole triangles")
        return indices.reshape(-1, 3)
    count = max(len(indices) - 2, 0)
    first = np.arange(count)
    if mode == _FAN:
        return np.stack([np.full(count, indices[0]), indices[first + 1], indices[first + 2]], 1)
    # strip: every other triangle is reversed to keep the winding (spec 3.7.2.1)
    even = first % 2 == 0
    a = np.where(even, indices[first], indices[first + 1])
    b = np.where(even, indices[first + 1], indices[first])
    return np.stack([a, b, indices[first + 2]], axis=1)


def _check_nodes(source: _Document) -> None:
    """Every node's mesh and children exist, no node has two parents, and no cycle."""
    nodes = source.json.get("nodes", [])
    if not isinstance(nodes, list):
        raise source.error("'nodes' is not a list")
    parent: dict[int, int] = {}
    for n, node in enumerate(nodes):
        if not isinstance(node, dict):
            raise source.error(f"node {n} is not an object")
        if "mesh" in node:
            source.item("meshes", node["mesh"], f"node {n}")
        children = node.get("children", [])
        if not isinstance(children, list):
            raise source.error(f"node {n}: children is not a list")
        for child in children:
            source.item("nodes", child, f"node {n}")
            if child in parent or child == n:
                raise source.error(f"node {child} has more than one parent (or is its own)")
            parent[child] = n
    for n in range(len(nodes)):  # walking up from any node must end at a root
        seen, at = set(), n
        while at in parent:
            if at in seen:
                raise source.error(f"the node tree has a cycle through node {n}")
            seen.add(at)
            at = parent[at]
    scenes = source.json.get("scenes", [])
    for s, scene in enumerate(scenes if isinstance(scenes, list) else []):
        roots = scene.get("nodes", []) if isinstance(scene, dict) else []
        if not isinstance(roots, list):
            raise source.error(f"scene {s}: nodes is not a list")
        for root in roots:
            source.item("nodes", root, f"scene {s}")
    if "scene" in source.json:
        source.item("scenes", source.json["scene"], "the default scene")


class _Writer:
    """Accessors, buffer views and the bytes of the rewritten document's one buffer."""

    def __init__(self) -> None:
        self.accessors: list[dict[str, Any]] = []
        self.views: list[dict[str, Any]] = []
        self.data = bytearray()

    def add(self, values: np.ndarray, dtype: str, kind: str) -> int:
        """Append ``values`` as ``dtype`` (``"<f4"`` or ``"<u4"``); the new accessor's index."""
        raw = np.ascontiguousarray(values, dtype=np.dtype(dtype)).tobytes()
        self.data += b"\0" * (-len(self.data) % 4)
        self.views.append({"buffer": 0, "byteOffset": len(self.data), "byteLength": len(raw)})
        self.data += raw
        component = {"<f4": 5126, "<u4": 5125}[dtype]
        self.accessors.append(
            {
                "bufferView": len(self.views) - 1,
                "componentType": component,
                "count": len(values),
                "type": kind,
            }
        )
        return len(self.accessors) - 1


def load_buffers(
    path: Path, document: dict[str, Any], glb_bin: bytes | None, allow_outside: bool
) -> list[bytes]:
    """The data of each buffer: the GLB ``BIN`` chunk, a base64 data URI, or a file.

    Raises
    ------
    SceneError
        A buffer that is missing, outside the scene folder, not a regular file, not
        base64, or shorter than its ``byteLength``.
    """
    specs = document.get("buffers", [])
    if not isinstance(specs, list):
        raise SceneError(path, "cannot read glTF geometry: 'buffers' is not a list")
    buffers = []
    for b, spec in enumerate(specs):
        what = f"buffer {b}"
        if not isinstance(spec, dict):
            raise SceneError(path, f"cannot read glTF geometry: {what} is not an object")
        uri = spec.get("uri")
        if uri is None:
            if b != 0 or glb_bin is None:
                raise SceneError(path, f"{what} has no uri and there is no GLB BIN chunk")
            data = glb_bin
        elif not isinstance(uri, str):
            raise SceneError(path, f"{what}: uri {uri!r} is not a string")
        elif uri.startswith("data:"):
            data = _data_uri(path, what, uri)
        else:
            from urllib.parse import unquote

            found = read_reference(path, unquote(uri), what, allow_outside)
            if found is None:
                raise SceneError(path, f"{what} {uri!r} not found")
            data = found
        length = spec.get("byteLength")
        if not isinstance(length, int) or length > len(data):
            raise SceneError(path, f"{what} has {len(data)} bytes, its byteLength says {length!r}")
        buffers.append(data)
    return buffers


def _data_uri(path: Path, what: str, uri: str) -> bytes:
    head, _, payload = uri.partition(",")
    if not head.endswith(";base64"):
        raise SceneError(path, f"{what}: only base64 data URIs are supported")
    try:
        return base64.b64decode(payload, validate=True)
    except (binascii.Error, ValueError):
        raise SceneError(path, f"{what}: the data URI is not valid base64") from None


def glb_bin_chunk(rest: bytes) -> bytes | None:
    """The ``BIN`` chunk's data from what follows a GLB's JSON chunk, None without one."""
    if len(rest) < 8:
        return None
    length, kind = struct.unpack_from("<II", rest, 0)
    if kind != _GLB_BIN:
        return None
    return rest[8 : 8 + length]
