"""atomic_write: all-or-nothing replacement of a file."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from raytrad.formats.atomic import atomic_write


def _leftovers(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir() if p.name.endswith(".tmp"))


def test_writes_bytes_and_leaves_no_temp_file(tmp_path: Path) -> None:
    target = tmp_path / "out.bin"
    with atomic_write(target) as f:
        f.write(b"\x00\x01radiosity")
        assert not target.exists()  # nothing visible until the body has finished
    assert target.read_bytes() == b"\x00\x01radiosity"
    assert _leftovers(tmp_path) == []


def test_text_mode_is_utf8_with_lf(tmp_path: Path) -> None:
    target = tmp_path / "a.mtl"
    with atomic_write(target, "w") as f:
        f.write("newmtl blanc\u00e9\nKd 1 2 3\n")
    assert target.read_bytes() == "newmtl blanc\u00e9\nKd 1 2 3\n".encode()


def test_failure_keeps_old_file_and_removes_temp(tmp_path: Path) -> None:
    target = tmp_path / "scene.obj"
    target.write_bytes(b"old content")
    with pytest.raises(RuntimeError, match="boom"), atomic_write(target) as f:
        f.write(b"half-written new content")
        raise RuntimeError("boom")
    assert target.read_bytes() == b"old content"
    assert _leftovers(tmp_path) == []


def test_failure_without_old_file_creates_nothing(tmp_path: Path) -> None:
    target = tmp_path / "new.ply"
    with pytest.raises(KeyError), atomic_write(target) as f:
        f.write(b"x")
        raise KeyError("k")
    assert list(tmp_path.iterdir()) == []


def test_temp_file_is_hidden_in_the_same_directory(tmp_path: Path) -> None:
    target = tmp_path / "out.ply"
    with atomic_write(target) as f:
        temp = Path(f.name)
        assert temp.parent == tmp_path
        assert temp.name.startswith(".out.ply.") and temp.name.endswith(".tmp")
    assert not temp.exists()


def test_creates_missing_parent_directories(tmp_path: Path) -> None:
    target = tmp_path / "a" / "b" / "out.txt"
    with atomic_write(target, "w") as f:
        f.write("ok")
    assert target.read_text() == "ok"


def test_replaced_file_keeps_its_permissions(tmp_path: Path) -> None:
    target = tmp_path / "keep.txt"
    target.write_text("old")
    target.chmod(0o640)
    with atomic_write(target, "w") as f:
        f.write("new")
    assert stat.S_IMODE(target.stat().st_mode) == 0o640


def test_new_file_gets_umask_permissions_not_private_temp_ones(tmp_path: Path) -> None:
    old = os.umask(0o022)
    try:
        with atomic_write(tmp_path / "new.txt", "w") as f:
            f.write("x")
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "new.txt").stat().st_mode) == 0o644


def test_rejects_append_and_read_modes(tmp_path: Path) -> None:
    for mode in ("a", "r", "rb", "w+"):
        with pytest.raises(ValueError, match="mode"), atomic_write(tmp_path / "x", mode):
            pass
