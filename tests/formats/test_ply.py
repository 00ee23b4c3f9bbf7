"""Radiosity PLY: exact binary layout, float32 round trip, errors naming the file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from raytrad.errors import SceneError
from raytrad.formats.ply import read_radiosity_ply, write_radiosity_ply

EXPECTED_HEADER_PROPERTIES = [
    "element vertex 5",
    "property float x",
    "property float y",
    "property float z",
    "property float radiosity_r",
    "property float radiosity_g",
    "property float radiosity_b",
    "property uchar red",
    "property uchar green",
    "property uchar blue",
    "element face 3",
    "property list uchar int vertex_indices",
]


@pytest.fixture
def mesh() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(7)
    return {
        "positions": rng.normal(size=(5, 3)) * 3.0,
        "triangles": np.array([[0, 1, 2], [2, 3, 4], [4, 3, 0]]),
        "radiosity": rng.random((5, 3)) * 100.0,
        "display_rgb": rng.integers(0, 256, size=(5, 3), dtype=np.uint8),
    }


def _split(data: bytes) -> tuple[list[str], bytes]:
    head, body = data.split(b"end_header\n", 1)
    return head.decode("ascii").splitlines(), body


def test_header_names_the_properties_exactly(tmp_path: Path, mesh: dict[str, np.ndarray]) -> None:
    path = tmp_path / "b.ply"
    write_radiosity_ply(path, **mesh)
    lines, _ = _split(path.read_bytes())
    assert lines[:2] == ["ply", "format binary_little_endian 1.0"]
    assert [line for line in lines if not line.startswith(("comment", "ply", "format"))] == (
        EXPECTED_HEADER_PROPERTIES
    )


def test_body_is_packed_little_endian(tmp_path: Path, mesh: dict[str, np.ndarray]) -> None:
    path = tmp_path / "b.ply"
    write_radiosity_ply(path, **mesh)
    _, body = _split(path.read_bytes())
    vertex_size, face_size = 6 * 4 + 3, 1 + 3 * 4
    assert len(body) == 5 * vertex_size + 3 * face_size
    # Decode the second vertex and the last face by hand, byte offsets from the layout.
    second = body[vertex_size : 2 * vertex_size]
    floats = np.frombuffer(second[:24], dtype="<f4")
    np.testing.assert_array_equal(floats[:3], mesh["positions"][1].astype(np.float32))
    np.testing.assert_array_equal(floats[3:], mesh["radiosity"][1].astype(np.float32))
    assert list(second[24:]) == mesh["display_rgb"][1].tolist()
    last_face = body[5 * vertex_size + 2 * face_size :]
    assert last_face[0] == 3
    assert np.frombuffer(last_face[1:], dtype="<i4").tolist() == [4, 3, 0]


def test_round_trip_is_exact_in_float32(tmp_path: Path, mesh: dict[str, np.ndarray]) -> None:
    path = tmp_path / "b.ply"
    write_radiosity_ply(path, **mesh)
    positions, triangles, radiosity = read_radiosity_ply(path)
    assert positions.dtype == np.float64 and radiosity.dtype == np.float64
    assert triangles.dtype == np.int64
    np.testing.assert_array_equal(positions, mesh["positions"].astype(np.float32))
    np.testing.assert_array_equal(radiosity, mesh["radiosity"].astype(np.float32))
    np.testing.assert_array_equal(triangles, mesh["triangles"])


def test_trimesh_reads_the_same_mesh(tmp_path: Path, mesh: dict[str, np.ndarray]) -> None:
    trimesh = pytest.importorskip("trimesh")
    path = tmp_path / "b.ply"
    write_radiosity_ply(path, **mesh)
    loaded = trimesh.load(path, process=False)
    np.testing.assert_array_equal(loaded.faces, mesh["triangles"])
    np.testing.assert_array_equal(loaded.vertices, mesh["positions"].astype(np.float32))
    raw = loaded.metadata["_ply_raw"]["vertex"]["data"]
    np.testing.assert_array_equal(raw["radiosity_g"], mesh["radiosity"][:, 1].astype(np.float32))


def test_plyfile_reads_the_same_mesh(tmp_path: Path, mesh: dict[str, np.ndarray]) -> None:
    plyfile = pytest.importorskip("plyfile")
    path = tmp_path / "c.ply"
    write_radiosity_ply(path, **mesh)
    loaded = plyfile.PlyData.read(str(path))
    vertex = loaded["vertex"].data
    np.testing.assert_array_equal(vertex["x"], mesh["positions"][:, 0].astype(np.float32))
    np.testing.assert_array_equal(vertex["radiosity_b"], mesh["radiosity"][:, 2].astype(np.float32))
    faces = np.stack(loaded["face"].data["vertex_indices"])
    np.testing.assert_array_equal(faces, mesh["triangles"])


def test_missing_radiosity_properties_name_the_file(tmp_path: Path) -> None:
    path = tmp_path / "plain.ply"
    header = (
        "ply\nformat binary_little_endian 1.0\nelement vertex 3\n"
        "property float x\nproperty float y\nproperty float z\n"
        "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
    )
    body = np.eye(3, dtype="<f4").tobytes() + bytes([3]) + np.arange(3, dtype="<i4").tobytes()
    path.write_bytes(header.encode() + body)
    with pytest.raises(SceneError, match="radiosity_r") as info:
        read_radiosity_ply(path)
    assert "plain.ply" in str(info.value)


@pytest.mark.parametrize(
    ("content", "problem"),
    [
        (b"not a ply at all", "not a PLY"),
        (b"ply\nformat ascii 1.0\nelement vertex 0\nend_header\n", "binary_little_endian"),
    ],
)
def test_unreadable_files_name_the_file(tmp_path: Path, content: bytes, problem: str) -> None:
    path = tmp_path / "bad.ply"
    path.write_bytes(content)
    with pytest.raises(SceneError, match=problem) as info:
        read_radiosity_ply(path)
    assert info.value.path == path


def test_truncated_file_is_reported(tmp_path: Path, mesh: dict[str, np.ndarray]) -> None:
    path = tmp_path / "cut.ply"
    write_radiosity_ply(path, **mesh)
    path.write_bytes(path.read_bytes()[:-5])
    with pytest.raises(SceneError, match="truncated"):
        read_radiosity_ply(path)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(SceneError, match="file not found"):
        read_radiosity_ply(tmp_path / "nothing.ply")


def test_bad_arrays_are_rejected_before_writing(
    tmp_path: Path, mesh: dict[str, np.ndarray]
) -> None:
    path = tmp_path / "x.ply"
    with pytest.raises(TypeError, match="display_rgb"):
        write_radiosity_ply(path, **{**mesh, "display_rgb": mesh["display_rgb"] / 255.0})
    with pytest.raises(ValueError, match=r"0\.\.255"):
        write_radiosity_ply(path, **{**mesh, "display_rgb": mesh["display_rgb"].astype(int) + 256})
    with pytest.raises(ValueError, match="radiosity"):
        write_radiosity_ply(path, **{**mesh, "radiosity": mesh["radiosity"][:4]})
    with pytest.raises(ValueError, match="triangle indices"):
        write_radiosity_ply(path, **{**mesh, "triangles": mesh["triangles"] + 3})
    assert not path.exists()
