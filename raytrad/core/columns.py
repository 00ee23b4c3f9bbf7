"""Form-factor columns and where they are kept: in memory, in spill files beyond the
cache, and packed flat for a checkpoint.

A column holds F(receiver <- patch) for the receivers that see one patch, compactly
(int32 receivers, float32 raw factors: 8 bytes an entry) and its near receivers' gather
weights (int32 sources, float32 shares). The engine
(:class:`~raytrad.core.formfactor.FormFactorEngine`) caches columns, weights included, up
to ``--cache-mb``; the rest go to :class:`ColumnSpill`, a small file each in a
temporary folder (honours ``TMPDIR``; one raw file a column, :func:`write_arrays`),
and are read back when a patch shoots again:
reading a column back takes milliseconds where tracing it again took a good fraction of
a second, so a scene whose columns outgrow the cache no longer slows the solve down by
orders of magnitude.
"""

from __future__ import annotations

import ctypes
import logging
import mmap
import os
import tempfile
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from raytrad.core.gather import EMPTY, GatherWeights

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Column:
    """Form factors from every receiver to one patch.

    Attributes
    ----------
    receivers : (K,) int32 (int64 beyond 2**31 receivers)
        Receivers with a non-zero factor, ascending.
    factors : (K,) float32 (raw) or float64 (balanced)
        F(receiver <- patch) [1]. Raw columns are stored in float32: float32's relative
        rounding, 6e-8, is far below the sampled visibility's error, and it cannot leak
        energy, because balancing computes its row and column scales (float64) from the
        stored values themselves, so closed rows still sum to 1 and closed patches still
        capture 1 to float64 rounding. Balanced columns
        (:meth:`raytrad.core.formfactor.FormFactorEngine.column`)
        are float64.
    rays : int
        Visibility rays cast to compute it.
    gather : GatherWeights
        Where on the patch the factor of each near receiver comes from
        (:mod:`raytrad.core.gather`).
    """

    receivers: np.ndarray
    factors: np.ndarray
    rays: int
    gather: GatherWeights = EMPTY

    @property
    def nbytes(self) -> int:
        """Memory the cache counts for the column [bytes]: its receivers, factors and
        near-field gather weights, and 64 for the object."""
        g = self.gather
        arrays = (self.receivers, self.factors, g.receivers, g.factors, g.pointer, g.sources)
        return int(sum(a.nbytes for a in arrays) + g.weights.nbytes + 64)


class ColumnSpill:
    """Columns that did not fit the cache, one temporary file each, with their near-field
    gather weights (so that ``--cache-mb`` bounds both).

    The folder is made on the first write and removed by :meth:`close`. When a file cannot
    be written (no space, no temporary folder), a warning is logged once and nothing more
    is spilled: those columns are then traced again when needed, as without a spill.
    """

    def __init__(self) -> None:
        self._folder: tempfile.TemporaryDirectory[str] | None = None
        self._paths: dict[int, str] = {}
        self._failed = False
        #: Bytes written to spill files.
        self.bytes = 0
        #: Columns spilled since the spill was made (kept by :meth:`close`).
        self.spilled_columns = 0

    def __contains__(self, patch: int) -> bool:
        return patch in self._paths

    def __len__(self) -> int:
        return len(self._paths)

    @property
    def folder(self) -> str | None:
        """The spill folder, or None before the first spill (and after :meth:`close`)."""
        return None if self._folder is None else self._folder.name

    def write(self, patch: int, column: Column) -> bool:
        """Spill one column with its gather weights; False when it could not be written."""
        if self._failed:
            return False
        try:
            if self._folder is None:
                self._folder = tempfile.TemporaryDirectory(prefix="raytrad-columns-")
                log.info(
                    "form factors: columns beyond --cache-mb are spilled to %s", self._folder.name
                )
            path = os.path.join(self._folder.name, f"{patch}{SUFFIX}")
            g = column.gather
            near = (g.receivers, g.factors, g.pointer, g.sources, g.weights)
            write_arrays(path, (column.receivers, column.factors, *near))
        except OSError as error:
            self._failed = True
            log.warning("cannot spill form-factor columns (%s): tracing them again instead", error)
            return False
        self._paths[patch] = path
        self.bytes += column.nbytes
        self.spilled_columns += 1
        return True

    def read(self, patch: int, mapped: bool = False) -> Column | None:
        """A spilled column (its rays not counted again), or None; ``mapped``: its
        arrays map the file (:func:`read_arrays`), for a caller that holds one column at
        a time (a shot).

        Raises
        ------
        OSError
            Its file cannot be read, is cut short or is not a spilled column's."""
        path = self._paths.get(patch)
        if path is None:
            return None
        receivers, factors, *gather = read_arrays(path, mapped=mapped)
        return Column(receivers, factors, 0, GatherWeights(*gather))

    def read_factors(self, patch: int) -> tuple[np.ndarray, np.ndarray] | None:
        """(receivers, factors) of a spilled column, its gather weights left on disk; or
        None. Balancing reads every spilled column's factors once a round (up to 100
        rounds), one column at a time: they map the file (:func:`read_arrays`). Raises
        OSError as :meth:`read`."""
        path = self._paths.get(patch)
        if path is None:
            return None
        receivers, factors = read_arrays(path, 2, mapped=True)
        return receivers, factors

    def close(self) -> None:
        """Remove the spill files."""
        if self._folder is not None:
            self._folder.cleanup()
            self._folder = None
        self._paths.clear()
        self.bytes = 0


#: A spilled column's file name after its patch.
SUFFIX = ".column"
#: The item types a spill file may hold, by the code its header gives.
ITEM_TYPES = (np.dtype(np.int32), np.dtype(np.int64), np.dtype(np.float32), np.dtype(np.float64))
#: The most arrays a spill file holds (a column's seven).
MOST_ARRAYS = 16


def write_arrays(path: str, arrays: tuple[np.ndarray, ...]) -> None:
    """One-dimensional ``arrays`` (of :data:`ITEM_TYPES`) raw in one file, after a header
    of int64: their number, then each one's type code (its index in :data:`ITEM_TYPES`)
    and length; each array is padded to a multiple of 8 bytes, so that all of them read
    back aligned.

    A column's seven arrays read back from this in about 0.2 ms where an ``.npz`` took
    1.6 ms (its members' CRCs and headers; 443 spilled columns of a 106 049-receiver
    Cornell box, 2026-12-06): the solve reads a spilled column at each of its shots.
    """
    header = [len(arrays)]
    for array in arrays:
        header += [ITEM_TYPES.index(array.dtype), len(array)]
    with open(path, "wb") as file:
        file.write(np.array(header, dtype=np.int64).tobytes())
        for array in arrays:
            file.write(np.ascontiguousarray(array).data)  # its buffer, not a copy
            file.write(bytes(-array.nbytes % 8))


def read_arrays(path: str, count: int | None = None, mapped: bool = False) -> list[np.ndarray]:
    """The first ``count`` arrays (all when None) :func:`write_arrays` wrote to ``path``:
    writable, aligned views of one buffer, the file read at once or, with ``mapped``,
    mapped copy-on-write (``mmap.ACCESS_COPY``).

    A mapping reads only the pages the caller touches, straight from the system's file
    cache: a spilled shot's column costs its page faults where a copy cost 0.34 s of a
    1.82 s solve of 1 572 shots over 443 spilled columns (1.54 s mapped, 2026-12-06).
    Writing to an array changes this process's copy, never the file. A mapping holds a
    file descriptor as long as an array of it lives: for callers that hold one column at
    a time.

    Raises
    ------
    OSError
        The file cannot be read, its header is not one :func:`write_arrays` writes, or it
        is cut short."""
    with open(path, "rb") as file:
        size = os.fstat(file.fileno()).st_size
        if mapped and size:
            buffer: mmap.mmap | bytearray = mmap.mmap(file.fileno(), size, access=mmap.ACCESS_COPY)
        else:
            buffer = bytearray(size)
            if file.readinto(buffer) != size:
                raise OSError(f"{path}: changed while it was read")
    return _parsed(path, buffer, count)


def _parsed(path: str, buffer: mmap.mmap | bytearray, count: int | None) -> list[np.ndarray]:
    """:func:`read_arrays`' arrays in ``buffer``, the file at ``path``."""
    size = len(buffer)
    number = int(np.frombuffer(buffer, np.int64, 1)[0]) if size >= 8 else 0
    if not 0 < number <= MOST_ARRAYS or size < 8 * (1 + 2 * number):
        raise OSError(f"{path}: not a spilled column's file")
    header = np.frombuffer(buffer, np.int64, 2 * number, 8)
    codes, lengths = header[0::2], header[1::2]
    if not ((codes >= 0).all() and (codes < len(ITEM_TYPES)).all() and (lengths >= 0).all()):
        raise OSError(f"{path}: not a spilled column's file")
    arrays = []
    offset = 8 * (1 + 2 * number)
    for code, length in zip(codes[:count].tolist(), lengths[:count].tolist(), strict=True):
        item = ITEM_TYPES[code]
        end = offset + length * item.itemsize
        if end > size:
            raise OSError(f"{path}: a spilled column's file is cut short")
        arrays.append(np.frombuffer(buffer, item, length, offset))
        offset = end + (-end % 8)
    return arrays


def return_freed_memory() -> None:
    """Hand memory freed by dropped columns back to the system (glibc's ``malloc_trim``).

    Columns of a few MB freed between larger allocations stay in the C heap otherwise,
    counted in the process's resident memory while refinement builds its own tables.
    Does nothing where the C library has no ``malloc_trim``."""
    try:
        ctypes.CDLL(None).malloc_trim(0)
    except (OSError, AttributeError, TypeError):  # not glibc
        pass


def compact_gather(gather: GatherWeights, index: type) -> GatherWeights:
    """Gather weights as the columns keep them (see :class:`Column`): receiver indices as
    ``index``, shares as float32 (each near receiver's still sum to 1 within float32
    rounding; the solve conserves power separately)."""
    return GatherWeights(
        gather.receivers.astype(index),
        gather.factors,
        gather.pointer.astype(np.int64),
        gather.sources.astype(index),
        gather.weights.astype(np.float32),
    )


def column_parts(patch: int, column: Column) -> dict[str, np.ndarray]:
    """One column as the pieces of :func:`pack_columns`' flat arrays (the same names and
    dtypes): a pass checkpoint writes them column by column."""
    gather = column.gather

    def length(values: np.ndarray) -> np.ndarray:
        return np.array([len(values)], dtype=np.int64)

    return {
        "patch": np.array([patch], dtype=np.int64),
        "length": length(column.receivers),
        "receivers": np.asarray(column.receivers),
        "factors": np.asarray(column.factors, dtype=np.float32),
        "near_length": length(gather.receivers),
        "near_receivers": np.asarray(gather.receivers),
        "near_factors": np.asarray(gather.factors, dtype=np.float64),
        "near_pointer": np.asarray(gather.pointer[1:]),
        "source_length": length(gather.sources),
        "sources": np.asarray(gather.sources),
        "weights": np.asarray(gather.weights, dtype=np.float32),
    }


#: The dtypes of :func:`pack_columns`' arrays when there is no column (else the columns'
#: own: int32 indices below 2**31 receivers).
PACKED_DTYPES = {
    "patch": np.int64,
    "length": np.int64,
    "receivers": np.int64,
    "factors": np.float32,
    "near_length": np.int64,
    "near_receivers": np.int64,
    "near_factors": np.float64,
    "near_pointer": np.int64,
    "source_length": np.int64,
    "sources": np.int64,
    "weights": np.float32,
}


def pack_columns(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Columns as flat arrays for a checkpoint (:func:`unpack_columns` reads them back):
    each of their :func:`column_parts`' pieces concatenated over the columns."""
    return {
        name: np.concatenate([part[name] for part in parts]) if parts else np.zeros(0, dtype)
        for name, dtype in PACKED_DTYPES.items()
    }


def unpack_columns(packed: Mapping[str, Any], index: type) -> Iterator[tuple[int, Column]]:
    """(patch, column) pairs from :func:`pack_columns`' arrays, one at a time; receiver
    indices as ``index`` (int32 or int64), raw factors as float32. ``packed``'s arrays are
    ndarrays or anything a plain slice of which is one (a checkpoint's
    :class:`~raytrad.formats.checkpoint.StoredArray`, read a column at a time)."""
    ends = {
        name: np.concatenate([[0], np.cumsum(packed[name])])
        for name in ("length", "near_length", "source_length")
    }
    for i, patch in enumerate(np.asarray(packed["patch"]).tolist()):
        a, b = ends["length"][i : i + 2]
        g, h = ends["near_length"][i : i + 2]
        u, v = ends["source_length"][i : i + 2]
        gather = GatherWeights(
            np.asarray(packed["near_receivers"][g:h]).astype(index),
            np.asarray(packed["near_factors"][g:h]),
            np.concatenate([[0], packed["near_pointer"][g:h]]).astype(np.int64),
            np.asarray(packed["sources"][u:v]).astype(index),
            np.asarray(packed["weights"][u:v]).astype(np.float32),
        )
        receivers: np.ndarray = np.asarray(packed["receivers"][a:b]).astype(index)
        factors = np.asarray(packed["factors"][a:b]).astype(np.float32)
        yield patch, Column(receivers, factors, 0, gather)


__all__ = [
    "Column",
    "ColumnSpill",
    "column_parts",
    "compact_gather",
    "pack_columns",
    "return_freed_memory",
    "unpack_columns",
]
