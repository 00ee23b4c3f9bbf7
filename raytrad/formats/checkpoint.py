"""The checkpoint file: named arrays and a JSON record in one ``.npz``, written atomically.

What goes in is decided above this layer (:mod:`raytrad.outputs.resume`: the solver state
and the fingerprint of the system it belongs to); this module only stores and reads it
back, bit for bit.
"""

from __future__ import annotations

import json
import os
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from raytrad.errors import RaytradError
from raytrad.formats.atomic import atomic_write

#: Name of the JSON record inside the archive (not usable as an array name).
RECORD = "__record__"


def write_checkpoint(
    path: str | os.PathLike[str], arrays: dict[str, np.ndarray], record: dict[str, Any]
) -> None:
    """Write ``arrays`` and the JSON-serialisable ``record`` to ``path`` atomically.

    Parameters
    ----------
    path : path-like
        The ``.npz`` file; its directory is created if missing.
    arrays : dict of str to ndarray
        Stored losslessly (``numpy.savez``, no pickling).
    record : dict
        Plain values (numbers, strings, lists, dicts), stored as JSON.
    """
    if RECORD in arrays:
        raise ValueError(f"{RECORD!r} is reserved for the record")
    contents: dict[str, Any] = {RECORD: np.array(json.dumps(record, sort_keys=True)), **arrays}
    with atomic_write(path) as handle:
        np.savez(handle, **contents)


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
