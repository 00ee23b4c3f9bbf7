"""PLY conformance: ASCII and binary (both byte orders), n-gon faces, extra properties,
and the malformed headers and bodies that must be refused; values computed by hand."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from raytrad.errors import SceneError
from raytrad.scenefiles import load_scene
from tests.scenefiles.conformance import L_FLOOR, LAMP, inside_notch, measure

# the L floor (one 6-gon, reflectance 0.5) and the lamp (one quad, exitance 20) 1 m above
VERTICES = [*L_FLOOR, *LAMP]
FACES = [(list(range(6)), (0.5, 0.5, 0.5), (0, 0, 0)), ([6, 7, 8, 9], (0, 0, 0), (20, 20, 20))]
EXTRA_VERTEX = ["nx", "ny", "nz"]  # ignored extra properties
HEADER = [
    "element vertex {nv}",
    *(f"property float {p}" for p in ("x", "y", "z", *EXTRA_VERTEX)),
    "element face {nf}",
    "property list uchar int vertex_indices",
    *(f"property float reflectance_{c}" for c in "rgb"),
    *(f"property float emitted_exitance_{c}" for c in "rgb"),
    "property uchar flags",
]


def _header(fmt: str, nv: int = len(VERTICES), nf: int = len(FACES)) -> bytes:
    lines = ["ply", f"format {fmt} 1.0", "comment made by the test", *HEADER, "end_header"]
    return ("\n".join(lines).format(nv=nv, nf=nf) + "\n").encode()


def _ascii_body() -> list[str]:
    rows = [f"{x} {y} {z} 0 1 0" for x, y, z in VERTICES]
    for corners, rho, emission in FACES:
        numbers = [len(corners), *corners, *rho, *emission, 7]
        rows.append(" ".join(map(str, numbers)))
    return rows


def _binary_body(order: str) -> bytes:
    out = b"".join(struct.pack(order + "6f", x, y, z, 0, 1, 0) for x, y, z in VERTICES)
    for corners, rho, emission in FACES:
        out += struct.pack(order + "B", len(corners))
        out += struct.pack(order + f"{len(corners)}i", *corners)
        out += struct.pack(order + "6fB", *rho, *emission, 7)
    return out


def _files() -> dict[str, bytes]:
    return {
        "ascii": _header("ascii") + "\n".join(_ascii_body()).encode() + b"\n",
        "ascii, CRLF and trailing blank line": (
            _header("ascii") + "\r\n".join(_ascii_body()).encode() + b"\r\n\r\n"
        ),
        "binary little endian": _header("binary_little_endian") + _binary_body("<"),
        "binary big endian": _header("binary_big_endian") + _binary_body(">"),
    }


@pytest.mark.parametrize("case", sorted(_files()))
def test_every_encoding_reads_the_same_geometry(tmp_path: Path, case: str) -> None:
    path = tmp_path / "scene.ply"
    path.write_bytes(_files()[case])
    scene = load_scene(path)
    measured = measure(scene)
    assert measured.area == pytest.approx(3.04, rel=1e-6)
    assert inside_notch(scene) == 0.0
    assert measured.triangles == 4 + 2
    assert measured.emitted_power == pytest.approx(20 * 0.04, rel=1e-6)
    np.testing.assert_allclose(measured.lower, [0, 0, 0])
    np.testing.assert_allclose(measured.upper, [2, 1, 2])
    assert (measured.normals[:, 1] > 0.999).sum() == 4  # the floor faces up


def _broken() -> dict[str, tuple[bytes, str]]:
    body = _ascii_body()
    return {
        "short vertex line": (
            _header("ascii") + "\n".join(["0.5 0.5", *body[1:]]).encode(),
            "element 'vertex': row 0: property 'z': early end-of-line",
        ),
        "vertex count larger than the data": (
            _header("ascii", nv=len(VERTICES) + 5) + "\n".join(body).encode(),
            "element 'vertex': row 10: expected end-of-line",
        ),
        "list count larger than its values": (
            _header("ascii") + "\n".join([*body[:-1], "5 6 7 8 9 0 0 0 20 20 20 7"]).encode(),
            "element 'face': row 1: property 'flags': early end-of-line",
        ),
        "ascii file cut in the face list": (
            _header("ascii") + "\n".join(body[:-1]).encode(),
            "element 'face': row 1: early end-of-file",
        ),
        "unknown format": (
            _header("binary_middle_endian") + _binary_body("<"),
            "unknown 'format binary_middle_endian 1.0'",
        ),
        "unknown version": (_header("ascii").replace(b"1.0", b"2.0") + b"\n", "unknown"),
        "binary cut short": (_files()["binary little endian"][:-20], "element 'face'"),
    }


@pytest.mark.parametrize("case", sorted(_broken()))
def test_malformed_files_are_refused_in_one_line(tmp_path: Path, case: str) -> None:
    data, problem = _broken()[case]
    path = tmp_path / "scene.ply"
    path.write_bytes(data)
    with pytest.raises(SceneError) as info:
        load_scene(path)
    message = str(info.value)
    assert message.startswith(str(path)) and "cannot parse as PLY" in message
    assert problem in message and "\n" not in message


def test_a_face_index_outside_the_vertices_is_refused(tmp_path: Path) -> None:
    body = _ascii_body()
    body[-1] = body[-1].replace("4 6 7 8 9", "4 6 7 8 99")
    path = tmp_path / "scene.ply"
    path.write_bytes(_header("ascii") + "\n".join(body).encode())
    with pytest.raises(SceneError, match=r"a face refers to a vertex outside 0\.\.9"):
        load_scene(path)
