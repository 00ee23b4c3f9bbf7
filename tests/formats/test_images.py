"""Images through OpenImageIO: EXR and PNG files written atomically and read back, and
push-pull hole filling."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from raytrad.formats import images
from raytrad.formats.images import encode_png, read_attributes, read_image, write_exr, write_png


def _leftovers(directory: Path) -> list[str]:
    return [p.name for p in directory.iterdir() if p.name.startswith(".")]


def test_exr_round_trip_keeps_values_and_metadata(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    pixels = rng.random((5, 7, 3)).astype(np.float32) * 100.0
    write_exr(tmp_path / "a.exr", pixels, half=False, metadata={"raytrad:units": "W m-2", "n": 3})
    np.testing.assert_array_equal(read_image(tmp_path / "a.exr"), pixels)
    attributes = read_attributes(tmp_path / "a.exr")
    assert attributes["raytrad:units"] == "W m-2"
    assert attributes["n"] == 3
    assert _leftovers(tmp_path) == []


def test_half_exr_keeps_three_significant_digits(tmp_path: Path) -> None:
    pixels = np.array([[[0.1, 1.0, 1234.5]]], dtype=np.float32)
    write_exr(tmp_path / "h.exr", pixels)
    np.testing.assert_allclose(read_image(tmp_path / "h.exr"), pixels, rtol=1e-3)


def test_png_round_trip(tmp_path: Path) -> None:
    rgb8 = np.random.default_rng(5).integers(0, 256, (4, 6, 3), dtype=np.uint8)
    write_png(tmp_path / "a.png", rgb8)
    np.testing.assert_array_equal(np.round(read_image(tmp_path / "a.png") * 255), rgb8)
    with pytest.raises(TypeError, match="uint8"):
        write_png(tmp_path / "b.png", rgb8.astype(np.float32))


def test_exr_write_failure_leaves_no_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    real_write = images._write_file
    written: list[Path] = []

    def write_then_fail(path: Path, pixels: np.ndarray, spec: object) -> None:
        real_write(path, pixels, spec)
        written.append(path)
        assert path.exists() and path.parent == tmp_path and path.suffix == ".exr"
        raise OSError("disk full")

    monkeypatch.setattr(images, "_write_file", write_then_fail)
    target = tmp_path / "lightmap.exr"
    with pytest.raises(OSError, match="disk full"):
        write_exr(target, np.ones((4, 4, 3)))
    assert written and list(tmp_path.iterdir()) == []

    target.write_bytes(b"previous lightmap")
    with pytest.raises(OSError, match="disk full"):
        write_exr(target, np.ones((4, 4, 3)))
    assert target.read_bytes() == b"previous lightmap"
    assert _leftovers(tmp_path) == []


def test_exr_beyond_half_range_is_written_as_float(tmp_path: Path) -> None:
    pixels = np.full((2, 3, 3), 1.0e6, dtype=np.float32)
    write_exr(tmp_path / "bright.exr", pixels, half=True)
    back = read_image(tmp_path / "bright.exr")
    np.testing.assert_array_equal(back, pixels)


def test_png_bytes_and_file_agree(tmp_path: Path) -> None:
    rgb8 = np.random.default_rng(6).integers(0, 256, (5, 7, 3), dtype=np.uint8)
    data = encode_png(rgb8)
    assert data.startswith(b"\x89PNG")
    (tmp_path / "a.png").write_bytes(data)
    np.testing.assert_array_equal(np.round(read_image(tmp_path / "a.png") * 255), rgb8)


def test_dilation_keeps_covered_texels_and_fills_the_rest() -> None:
    rng = np.random.default_rng(4)
    pixels = rng.random((16, 16, 3)).astype(np.float32) + 0.5
    coverage = np.zeros((16, 16), dtype=bool)
    coverage[4:9, 3:7] = True
    filled = images.dilate(np.where(coverage[..., None], pixels, np.nan), coverage)
    np.testing.assert_array_equal(filled[coverage], pixels[coverage])
    assert np.isfinite(filled).all()
    inside = pixels[coverage]
    assert (filled >= inside.min(axis=0) - 1e-6).all()
    assert (filled <= inside.max(axis=0) + 1e-6).all()
