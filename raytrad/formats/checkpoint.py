"""The checkpoint file: named arrays and a JSON record in one ``.npz``, written atomically.

What goes in is decided above this layer (:mod:`raytrad.outputs.resume`: the solver state
and the fingerprint of the system it belongs to); this module only stores and reads it
back, bit for bit. Arrays too large to hold at once (a form-factor pass's columns at a
million receivers: gigabytes) are gathered piece by piece in a :class:`Spool` on disk
and copied into the archive in blocks, so writing a checkpoint holds one piece at a time.
"""

from __future__ import annotations

import json
import os
import shutil
import struct
import tempfile
import zipfile
import zlib
from collections.abc import Collection, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from raytrad.errors import RaytradError
from raytrad.formats.atomic import atomic_write

#: Name of the JSON record inside the archive (not usable as an array name).
RECORD = "__record__"


@dataclass(frozen=True)
class SpooledArray:
    """A 1-D array gathered on disk by a :class:`Spool`: its raw file, dtype and length."""

    path: Path
    dtype: np.dtype
    length: int

    def blocks(self, items: int = 1 << 22) -> Iterator[np.ndarray]:
        """The array in pieces of at most ``items`` values."""
        with open(self.path, "rb") as handle:
            while chunk := handle.read(items * self.dtype.itemsize):
                yield np.frombuffer(chunk, dtype=self.dtype)


class Spool:
    """Named 1-D arrays appended piece by piece to raw files in a temporary folder (the
    system's), each cast to the dtype its first piece gives (or ``dtypes`` names); a
    context manager that deletes the folder on exit."""

    def __init__(self, dtypes: dict[str, Any] | None = None) -> None:
        self._folder = Path(tempfile.mkdtemp(prefix="raytrad-spool-"))
        self._dtypes = {name: np.dtype(d) for name, d in (dtypes or {}).items()}
        self._lengths: dict[str, int] = {}

    def __enter__(self) -> Spool:
        return self

    def __exit__(self, *exc: object) -> None:
        shutil.rmtree(self._folder, ignore_errors=True)

    def add(self, pieces: dict[str, np.ndarray]) -> None:
        """Append each of ``pieces`` to its array."""
        for name, values in pieces.items():
            dtype = self._dtypes.setdefault(name, np.asarray(values).dtype)
            flat = np.ascontiguousarray(values, dtype=dtype).reshape(-1)
            with open(self._folder / name, "ab") as handle:
                handle.write(flat.tobytes())
            self._lengths[name] = self._lengths.get(name, 0) + len(flat)

    def arrays(self) -> dict[str, SpooledArray]:
        """The arrays so far, for :func:`write_checkpoint`."""
        return {
            name: SpooledArray(self._folder / name, self._dtypes[name], length)
            for name, length in self._lengths.items()
        }


def drop_cached(descriptor: int, start: int = 0, length: int = 0) -> None:
    """Ask the system to drop bytes ``start:start + length`` (0: to the end) of the open
    file ``descriptor`` from its file cache (``POSIX_FADV_DONTNEED``; those not written
    to disk yet stay). Nothing where the system has no such call.

    A checkpoint is read back only by a later run's ``--resume``. At a million receivers
    a pass checkpoint is gigabytes, written while the spilled columns
    (:class:`raytrad.core.columns.ColumnSpill`) sit in the same cache: kept there,
    checkpoints, their spool and the spill outgrew a 24 GiB machine's memory, and the
    solve then read the spilled columns back from the disk (2.0 s of reading and slower
    shots, against 0.13 s in a process that wrote no checkpoint, 2026-12-06). Only
    pages already on disk are dropped: advising it on a :class:`Spool`'s pieces, dirty
    and deleted right after, would start their writing instead."""
    advise = getattr(os, "posix_fadvise", None)
    if advise is None:  # pragma: no cover - not on Linux
        return
    try:
        advise(descriptor, start, length, os.POSIX_FADV_DONTNEED)
    except OSError:  # a file system without it: the cache keeps the pages
        pass


def write_checkpoint(
    path: str | os.PathLike[str],
    arrays: Mapping[str, np.ndarray | SpooledArray],
    record: dict[str, Any],
) -> None:
    """Write ``arrays`` and the JSON-serialisable ``record`` to ``path`` atomically, and
    drop it from the system's file cache once it is on disk (:func:`drop_cached`).

    Parameters
    ----------
    path : path-like
        The ``.npz`` file; its directory is created if missing.
    arrays : dict of str to ndarray or SpooledArray
        Stored losslessly (``.npy`` members of an uncompressed zip, as ``numpy.savez``
        writes them, no pickling); a spooled array is copied from its file in blocks.
    record : dict
        Plain values (numbers, strings, lists, dicts), stored as JSON.
    """
    if RECORD in arrays:
        raise ValueError(f"{RECORD!r} is reserved for the record")
    contents: dict[str, Any] = {RECORD: np.array(json.dumps(record, sort_keys=True)), **arrays}
    with (
        atomic_write(path) as handle,
        zipfile.ZipFile(handle, mode="w", compression=zipfile.ZIP_STORED, allowZip64=True) as zf,
    ):
        for name, values in contents.items():
            with zf.open(name + ".npy", mode="w", force_zip64=True) as member:
                if isinstance(values, SpooledArray):
                    header: dict[str, Any] = {
                        "descr": np.lib.format.dtype_to_descr(values.dtype),
                        "fortran_order": False,
                        "shape": (values.length,),
                    }
                    np.lib.format.write_array_header_2_0(member, header)
                    for block in values.blocks():
                        member.write(block.tobytes())
                else:
                    np.lib.format.write_array(member, np.asanyarray(values), allow_pickle=False)
    with open(path, "rb") as written:  # fsynced by atomic_write: its pages are clean
        drop_cached(written.fileno())


def read_checkpoint(
    path: str | os.PathLike[str], lazy: Collection[str] = ()
) -> tuple[dict[str, np.ndarray | StoredArray], dict[str, Any]]:
    """Read a file written by :func:`write_checkpoint`: its arrays and its record.

    Parameters
    ----------
    path : path-like
    lazy : collection of str
        Names of 1-D arrays to leave on disk: each comes back as a :class:`StoredArray`,
        read a slice at a time (a form-factor pass's columns: gigabytes at a million
        receivers, which a resume hands on a column at a time), after its checksum has
        been checked by reading it through once. A member that cannot be read in place
        (compressed, or not 1-D) is read whole.

    Raises
    ------
    RaytradError
        Naming the file: unreadable, not an archive, without a record, or damaged.
    """
    try:
        with np.load(Path(path), allow_pickle=False) as data:
            record = json.loads(str(data[RECORD]))
            stored = _stored_arrays(Path(path), set(lazy) & set(data.files))
            arrays: dict[str, np.ndarray | StoredArray] = {
                name: stored[name] if name in stored else np.array(data[name])
                for name in data.files
                if name != RECORD
            }
    except (OSError, EOFError, KeyError, ValueError, zipfile.BadZipFile) as exc:
        raise RaytradError(f"{path}: cannot read checkpoint ({exc or type(exc).__name__})") from exc
    if not isinstance(record, dict):
        raise RaytradError(f"{path}: cannot read checkpoint (its record is not a table)")
    return arrays, record


@dataclass(frozen=True)
class StoredArray:
    """A 1-D array left in a checkpoint file (:func:`read_checkpoint`'s ``lazy``): sliced,
    it reads just that slice, as a new ndarray.

    Attributes
    ----------
    path : Path
        The checkpoint.
    offset : int
        Byte offset of the array's first value in the file.
    dtype : numpy.dtype
    length : int
    """

    path: Path
    offset: int
    dtype: np.dtype
    length: int

    ndim = 1

    def __len__(self) -> int:
        return self.length

    @property
    def shape(self) -> tuple[int]:
        return (self.length,)

    def __array__(self, dtype: Any = None, copy: bool | None = None) -> np.ndarray:
        """The whole array, read (``np.asarray`` of a stored array)."""
        values = self[:]
        return values if dtype is None else values.astype(dtype)

    def __getitem__(self, index: slice) -> np.ndarray:
        start, stop, step = index.indices(self.length)
        if step != 1:
            raise IndexError("a stored array is read in plain slices")
        count = max(stop - start, 0)
        with open(self.path, "rb") as handle:
            handle.seek(self.offset + start * self.dtype.itemsize)
            values = np.fromfile(handle, dtype=self.dtype, count=count)
        if len(values) != count:
            raise RaytradError(f"{self.path}: cannot read checkpoint (it was cut short)")
        return values


#: Bytes of a zip member's local header before its name and extra field.
_LOCAL_HEADER = 30


def _stored_arrays(path: Path, names: set[str]) -> dict[str, StoredArray]:
    """The ``names`` (of ``.npy`` members) that can be read in place, as
    :class:`StoredArray`; each member's CRC checked by reading it through in blocks.

    Raises
    ------
    ValueError
        A member's checksum or headers do not hold.
    """
    out = {}
    with zipfile.ZipFile(path) as archive, open(path, "rb") as handle:
        for name in sorted(names):
            info = archive.getinfo(name + ".npy")
            if info.compress_type != zipfile.ZIP_STORED:
                continue
            handle.seek(info.header_offset)
            local = handle.read(_LOCAL_HEADER)
            if local[:4] != b"PK\x03\x04":
                raise ValueError(f"member {name} has no local header")
            name_length, extra_length = struct.unpack("<HH", local[26:30])
            start = info.header_offset + _LOCAL_HEADER + name_length + extra_length
            handle.seek(start)
            version = np.lib.format.read_magic(handle)
            if version == (1, 0):
                shape, fortran, dtype = np.lib.format.read_array_header_1_0(handle)
            elif version == (2, 0):
                shape, fortran, dtype = np.lib.format.read_array_header_2_0(handle)
            else:
                continue
            if len(shape) != 1 or fortran or dtype.hasobject:
                continue
            offset = handle.tell()
            if offset - start + shape[0] * dtype.itemsize != info.file_size:
                raise ValueError(f"member {name} is not the size its header says")
            if _crc(handle, start, info.file_size) != info.CRC:
                raise ValueError(f"member {name} is damaged (its checksum differs)")
            out[name] = StoredArray(path, offset, dtype, int(shape[0]))
    return out


def _crc(handle: Any, start: int, size: int, block: int = 1 << 24) -> int:
    """CRC-32 of ``size`` bytes of ``handle`` from ``start``, read in blocks."""
    handle.seek(start)
    crc = 0
    while size > 0:
        data = handle.read(min(block, size))
        if not data:
            raise ValueError("the file ends early")
        crc = zlib.crc32(data, crc)
        size -= len(data)
    return crc
