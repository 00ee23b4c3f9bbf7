"""The checkpoint file: named arrays and a JSON record back bit for bit, atomically."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from raytrad.errors import RaytradError
from raytrad.formats.checkpoint import RECORD, Spool, read_checkpoint, write_checkpoint


def test_round_trip(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    arrays = {"a": rng.random((4, 3)), "b": np.array([np.nan, -0.0, np.inf]), "c": np.arange(5)}
    record = {"shots": 12, "name": "x", "nested": {"k": [1, 2.5, None]}}
    write_checkpoint(tmp_path / "c.npz", arrays, record)
    back, got = read_checkpoint(tmp_path / "c.npz")
    assert got == record and set(back) == set(arrays)
    for name, array in arrays.items():
        np.testing.assert_array_equal(back[name], array)
        assert back[name].dtype == array.dtype
    assert [p.name for p in tmp_path.iterdir()] == ["c.npz"]  # no temporary left


def test_spooled_arrays_are_stored_as_their_pieces_concatenated(tmp_path: Path) -> None:
    """Pieces appended to a spool (on disk, a column at a time) read back as numpy's own
    concatenation, in the dtype the spool was given or its first piece's, beside plain
    arrays; the spool's folder is gone afterwards."""
    rng = np.random.default_rng(1)
    pieces = [
        {"i": rng.integers(0, 1 << 20, n, dtype=np.int32), "f": rng.random(n), "n": np.array([n])}
        for n in (0, 7, 1, 3000)
    ]
    with Spool({"f": np.float32}) as spool:
        for piece in pieces:
            spool.add(piece)
        folder = next(iter(spool.arrays().values())).path.parent
        write_checkpoint(tmp_path / "c.npz", {"plain": np.eye(2), **spool.arrays()}, {"k": 1})
    assert not folder.exists()
    back, record = read_checkpoint(tmp_path / "c.npz")
    assert record == {"k": 1}
    np.testing.assert_array_equal(back["plain"], np.eye(2))
    for name, dtype in (("i", np.int32), ("f", np.float32), ("n", np.int64)):
        want = np.concatenate([p[name] for p in pieces]).astype(dtype)
        assert back[name].dtype == dtype
        np.testing.assert_array_equal(back[name], want)
    with np.load(tmp_path / "c.npz") as data:  # numpy's reader takes it as its own
        np.testing.assert_array_equal(data["i"], back["i"])


def test_the_record_name_is_reserved(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="reserved"):
        write_checkpoint(tmp_path / "c.npz", {RECORD: np.zeros(1)}, {})
    assert not (tmp_path / "c.npz").exists()


@pytest.mark.parametrize("content", [b"", b"not a zip", None])
def test_unreadable_files_are_one_error_naming_the_file(
    tmp_path: Path, content: bytes | None
) -> None:
    path = tmp_path / "c.npz"
    if content is None:
        np.savez(path, a=np.zeros(2))  # an archive without a record
    else:
        path.write_bytes(content)
    with pytest.raises(RaytradError, match="cannot read checkpoint") as caught:
        read_checkpoint(path)
    assert str(path) in str(caught.value)
