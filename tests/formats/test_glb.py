"""The GLB container and the glTF document builder, checked against the byte layout of
the glTF 2.0 specification ("Binary glTF Layout") written out here."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest

from raytrad.formats.glb import GltfDocument, glb_container, join_glb, split_glb


def _chunks(data: bytes) -> list[tuple[int, bytes]]:
    """(type, payload) of every chunk, read by the spec's layout."""
    magic, version, length = struct.unpack_from("<4sII", data)
    assert (magic, version, length) == (b"glTF", 2, len(data))
    chunks, offset = [], 12
    while offset < len(data):
        size, kind = struct.unpack_from("<II", data, offset)
        assert size % 4 == 0
        chunks.append((kind, data[offset + 8 : offset + 8 + size]))
        offset += 8 + size
    return chunks


def test_container_layout_and_split() -> None:
    data = glb_container(b'{"asset":{"version":"2.0"}}', b"\x01\x02\x03")
    (json_kind, text), (bin_kind, blob) = _chunks(data)
    assert (json_kind, bin_kind) == (0x4E4F534A, 0x004E4942)
    assert json.loads(text) == {"asset": {"version": "2.0"}} and text.endswith(b" ")
    assert blob == b"\x01\x02\x03\x00"
    json_bytes, rest = split_glb(data)
    assert json_bytes == text and join_glb(json_bytes, rest) == data


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (b"glTX" + bytes(16), "bad magic"),
        (struct.pack("<4sII", b"glTF", 1, 20) + bytes(8), "version 1"),
        (struct.pack("<4sIIII", b"glTF", 2, 100, 4, 0x4E4F534A) + b"{}  ", "truncated"),
        (struct.pack("<4sIIII", b"glTF", 2, 24, 4, 0x004E4942) + b"\0\0\0\0", "not JSON"),
    ],
)
def test_broken_containers_say_why(data: bytes, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        split_glb(data)


def test_document_accessors_views_and_buffer_agree() -> None:
    document = GltfDocument()
    positions = np.array([[0, 0, 0], [1, 0, 0], [0, 2, 0]], dtype=np.float64)
    material = document.add_material({"name": "m"})
    png = b"\x89PNG fake"
    texture = document.add_png_texture(png)
    assert document.add_png_texture(png) == texture  # the same bytes are stored once
    primitive = document.primitive(positions, [[0, 1, 2]], material, TEXCOORD_1=np.zeros((3, 2)))
    document.add_mesh_node("tri", [primitive])
    document.use_extension("X")
    document.use_extension("X")
    header, (_, binary) = None, (None, None)
    (_, text), (_, binary) = _chunks(document.glb())
    header = json.loads(text)
    assert header["extensionsUsed"] == ["X"]
    assert header["scenes"] == [{"nodes": [0]}] and header["nodes"] == [{"name": "tri", "mesh": 0}]
    assert header["buffers"] == [{"byteLength": len(binary)}]
    accessors = header["accessors"]
    position = accessors[primitive["attributes"]["POSITION"]]
    assert position["count"] == 3 and position["max"] == [1.0, 2.0, 0.0]
    view = header["bufferViews"][position["bufferView"]]
    stored = np.frombuffer(binary, "<f4", 9, view["byteOffset"]).reshape(3, 3)
    np.testing.assert_array_equal(stored, positions)
    indices = accessors[primitive["indices"]]
    view = header["bufferViews"][indices["bufferView"]]
    assert np.frombuffer(binary, "<u4", 3, view["byteOffset"]).tolist() == [0, 1, 2]
    image_view = header["bufferViews"][header["images"][0]["bufferView"]]
    start = image_view["byteOffset"]
    assert binary[start : start + image_view["byteLength"]] == png
    assert all(v["byteOffset"] % 4 == 0 for v in header["bufferViews"])
