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
import tempfile
import zipfile
from collections.abc import Iterator, Mapping
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


def write_checkpoint(
    path: str | os.PathLike[str],
    arrays: Mapping[str, np.ndarray | SpooledArray],
    record: dict[str, Any],
) -> None:
    """Write ``arrays`` and the JSON-serialisable ``record`` to ``path`` atomically.

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


def read_checkpoint(path: str | os.PathLike[str]) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Read a file written by :func:`write_checkpoint`: its arrays and its record.

    Raises
    ------
    RaytradError
        Naming the file: unreadable, not an archive, or without a record.
    """
    try:
        with np.load(Path(path), allow_pickle=False) as data:
            record = json.loads(str(data[RECORD]))
            arrays = {name: np.array(data[name]) for name in data.files if name != RECORD}
    except (OSError, EOFError, KeyError, ValueError, zipfile.BadZipFile) as exc:
        raise RaytradError(f"{path}: cannot read checkpoint ({exc or type(exc).__name__})") from exc
    if not isinstance(record, dict):
        raise RaytradError(f"{path}: cannot read checkpoint (its record is not a table)")
    return arrays, record
