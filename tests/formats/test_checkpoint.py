"""The checkpoint file: named arrays and a JSON record back bit for bit, atomically; large
arrays left on disk and read a slice at a time, their checksums checked."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np
import pytest

from raytrad.errors import RaytradError
from raytrad.formats.checkpoint import (
    RECORD,
    Spool,
    StoredArray,
    drop_cached,
    read_checkpoint,
    write_checkpoint,
)


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


def _written(path: Path) -> dict[str, np.ndarray]:
    """A checkpoint of plain arrays (``.npy`` 1.0 headers) and spooled ones (2.0)."""
    rng = np.random.default_rng(2)
    plain = {"f": rng.random(1000), "small": np.arange(3, dtype=np.int32), "m": np.eye(3)}
    spooled = rng.integers(0, 1 << 40, 5000)
    with Spool() as spool:
        spool.add({"s": spooled[:1234]})
        spool.add({"s": spooled[1234:]})
        write_checkpoint(path, {**plain, **spool.arrays()}, {"k": 1})
    return {**plain, "s": spooled}


def test_lazy_arrays_stay_on_disk_and_read_in_slices(tmp_path: Path) -> None:
    path = tmp_path / "c.npz"
    arrays = _written(path)
    back, record = read_checkpoint(path, lazy={"f", "s", "m", "absent"})
    assert record == {"k": 1} and set(back) == set(arrays)
    assert isinstance(back["f"], StoredArray) and isinstance(back["s"], StoredArray)
    assert isinstance(back["m"], np.ndarray)  # not 1-D: read whole
    assert isinstance(back["small"], np.ndarray)  # not asked for
    for name in ("f", "s"):
        stored, want = back[name], arrays[name]
        assert len(stored) == len(want) and stored.shape == want.shape
        assert stored.dtype == want.dtype and stored.ndim == 1
        for a, b in ((0, 10), (1233, 1235), (len(want) - 3, len(want)), (7, 7), (0, None)):
            got = stored[a:b]
            assert isinstance(got, np.ndarray) and got.dtype == want.dtype
            np.testing.assert_array_equal(got, want[a:b])
        np.testing.assert_array_equal(np.asarray(stored), want)
    np.testing.assert_array_equal(back["m"], arrays["m"])


def test_a_damaged_lazy_array_is_refused_by_its_checksum(tmp_path: Path) -> None:
    """One flipped byte in a lazily read member's data: numpy's own reader would catch it
    by the zip's CRC when it reads the member; reading in place checks the CRC first."""
    path = tmp_path / "c.npz"
    _written(path)
    with zipfile.ZipFile(path) as archive:
        info = archive.getinfo("s.npy")
    data = bytearray(path.read_bytes())
    data[info.header_offset + 200] ^= 0xFF  # past the local and .npy headers
    path.write_bytes(bytes(data))
    with pytest.raises(RaytradError, match="cannot read checkpoint") as caught:
        read_checkpoint(path, lazy={"s"})
    assert str(path) in str(caught.value) and "checksum" in str(caught.value)
    with pytest.raises(RaytradError, match="cannot read checkpoint"):
        read_checkpoint(path)  # read whole: the same damage found by numpy


def test_a_compressed_member_is_read_whole(tmp_path: Path) -> None:
    """An archive not written by raytrad (compressed members) still reads: a member that
    cannot be read in place comes back whole."""
    path = tmp_path / "c.npz"
    values = np.arange(100.0)
    np.savez_compressed(path, a=values, **{RECORD: np.array(json.dumps({"k": 2}))})
    back, record = read_checkpoint(path, lazy={"a"})
    assert record == {"k": 2} and isinstance(back["a"], np.ndarray)
    np.testing.assert_array_equal(back["a"], values)


def test_a_checkpoint_cut_short_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "c.npz"
    _written(path)
    path.write_bytes(path.read_bytes()[:-4000])
    with pytest.raises(RaytradError, match="cannot read checkpoint"):
        read_checkpoint(path, lazy={"s", "f"})


def _resident_pages(path: Path) -> int:
    """Pages of ``path`` in the system's file cache (Linux's ``mincore`` on a mapping that
    touches none of them)."""
    import ctypes
    import mmap

    size = path.stat().st_size
    pages = -(-size // mmap.PAGESIZE)
    with open(path, "rb") as file, mmap.mmap(file.fileno(), size, access=mmap.ACCESS_COPY) as m:
        view = ctypes.c_char.from_buffer(m)
        vector = (ctypes.c_ubyte * pages)()
        libc = ctypes.CDLL(None, use_errno=True)
        libc.mincore.argtypes = (ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p)
        if libc.mincore(ctypes.addressof(view), size, vector) != 0:
            pytest.skip("mincore failed here")
        del view
    return sum(v & 1 for v in vector)


@pytest.mark.skipif(not hasattr(__import__("os"), "posix_fadvise"), reason="no posix_fadvise")
def test_a_written_checkpoint_leaves_the_file_cache(tmp_path: Path) -> None:
    """A checkpoint of gigabytes kept in the file cache pushed the spilled columns out of
    it; once fsynced it is dropped (``drop_cached``). A file written alike and not
    dropped stays cached, so the count is not vacuous."""
    import os

    values = np.arange(1 << 20, dtype=np.float64)  # 8 MiB
    kept = tmp_path / "kept.bin"
    with open(kept, "wb") as file:
        file.write(values.tobytes())
        file.flush()
        os.fsync(file.fileno())
    if _resident_pages(kept) == 0:
        pytest.skip("this file system keeps no written page in the cache")
    path = tmp_path / "c.npz"
    write_checkpoint(path, {"values": values}, {})
    probe = tmp_path / "probe.bin"
    probe.write_bytes(values.tobytes())
    with open(probe, "rb+") as file:
        os.fsync(file.fileno())
        drop_cached(file.fileno())
    if _resident_pages(probe) > 0:
        pytest.skip("this file system keeps its pages whatever the advice (tmpfs)")
    assert _resident_pages(path) == 0 and _resident_pages(kept) > 0
    np.testing.assert_array_equal(read_checkpoint(path)[0]["values"], values)
