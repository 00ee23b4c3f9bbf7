"""Form-factor columns and where they are kept: in memory, in spill files beyond the
cache, and packed flat for a checkpoint.

A column holds F(receiver <- patch) for the receivers that see one patch, compactly
(int32 receivers, float32 raw factors: 8 bytes an entry) and its near receivers' gather
weights (int32 sources, float32 shares). The engine
(:class:`~raytrad.core.formfactor.FormFactorEngine`) caches columns, weights included, up
to ``--cache-mb``; the rest go to :class:`ColumnSpill`, two small files each in a
temporary folder (honours ``TMPDIR``: the factors raw, the gather weights in an ``.npz``),
and are read back when a patch shoots again:
reading a column back takes milliseconds where tracing it again took a good fraction of
a second, so a scene whose columns outgrow the cache no longer slows the solve down by
orders of magnitude.
"""

from __future__ import annotations

import ctypes
import logging
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
            path = os.path.join(self._folder.name, f"{patch}.npz")
            _write_factors(path + _FACTORS, column.receivers, column.factors)
            g = column.gather
            np.savez(
                path,
                near_receivers=g.receivers,
                near_factors=g.factors,
                near_pointer=g.pointer,
                sources=g.sources,
                weights=g.weights,
            )
        except OSError as error:
            self._failed = True
            log.warning("cannot spill form-factor columns (%s): tracing them again instead", error)
            return False
        self._paths[patch] = path
        self.bytes += column.nbytes
        return True

    def read(self, patch: int) -> Column | None:
        """A spilled column (its rays not counted again), or None."""
        path = self._paths.get(patch)
        if path is None:
            return None
        with np.load(path) as data:
            gather = GatherWeights(
                data["near_receivers"],
                data["near_factors"],
                data["near_pointer"],
                data["sources"],
                data["weights"],
            )
        return Column(*_read_factors(path + _FACTORS), 0, gather)

    def read_factors(self, patch: int) -> tuple[np.ndarray, np.ndarray] | None:
        """(receivers, factors) of a spilled column, its gather weights left on disk; or
        None. Balancing reads every spilled column's factors once a round (up to 100
        rounds): a raw file takes about a seventh of the time an ``.npz`` member does
        (whose header numpy parses each time; 0.11 against 0.81 ms for 19 000 entries)."""
        path = self._paths.get(patch)
        if path is None:
            return None
        return _read_factors(path + _FACTORS)

    def close(self) -> None:
        """Remove the spill files."""
        if self._folder is not None:
            self._folder.cleanup()
            self._folder = None
        self._paths.clear()
        self.bytes = 0


#: The suffix of a spilled column's raw factors file, after its ``.npz`` name.
_FACTORS = ".factors"
#: A raw factors file's dtypes by item size: receivers, factors.
_RECEIVER_TYPES = {4: np.int32, 8: np.int64}
_FACTOR_TYPES = {4: np.float32, 8: np.float64}


def _write_factors(path: str, receivers: np.ndarray, factors: np.ndarray) -> None:
    """A column's receivers and factors raw, after a header of three int64: the count and
    the two item sizes."""
    header = np.array([len(receivers), receivers.itemsize, factors.itemsize], dtype=np.int64)
    with open(path, "wb") as file:
        for part in (header, receivers, factors):
            file.write(np.ascontiguousarray(part).tobytes())


def _read_factors(path: str) -> tuple[np.ndarray, np.ndarray]:
    """The receivers and factors :func:`_write_factors` wrote."""
    with open(path, "rb") as file:
        header = np.fromfile(file, np.int64, 3)
        known = len(header) == 3 and int(header[1]) in _RECEIVER_TYPES
        if not (known and int(header[2]) in _FACTOR_TYPES):
            raise OSError(f"{path}: not a spilled column's factors file")
        count = int(header[0])
        receivers = np.fromfile(file, _RECEIVER_TYPES[int(header[1])], count)
        factors = np.fromfile(file, _FACTOR_TYPES[int(header[2])], count)
    if len(factors) != count:
        raise OSError(f"{path}: a spilled column's factors file is cut short")
    return receivers, factors


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
