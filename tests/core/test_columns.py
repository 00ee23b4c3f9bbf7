"""Spilled form-factor columns: what is written is what is read back, in its own types."""

from __future__ import annotations

import os
from collections.abc import Iterator

import numpy as np
import pytest

from raytrad.core.columns import (
    ITEM_TYPES,
    MOST_ARRAYS,
    SUFFIX,
    Column,
    ColumnSpill,
    read_arrays,
    write_arrays,
)
from raytrad.core.gather import GatherWeights


def _column(rng: np.random.Generator, count: int, index: type, value: type) -> Column:
    receivers = np.sort(rng.choice(10 * count + 10, size=count, replace=False)).astype(index)
    factors = rng.random(count).astype(value)
    near = min(count, 5)
    gather = GatherWeights(
        receivers[:near].copy(),
        factors[:near].astype(np.float64),
        np.arange(near + 1, dtype=np.int64),
        np.arange(near, dtype=index),
        np.full(near, 1.0, dtype=np.float32),
    )
    return Column(receivers, factors, 7, gather)


@pytest.mark.parametrize(
    ("count", "index", "value"),
    [
        (0, np.int32, np.float32),
        (1, np.int32, np.float32),
        (1001, np.int32, np.float32),
        (333, np.int64, np.float64),
        (7, np.int32, np.float64),
    ],
)
def test_a_spilled_column_reads_back_the_same(count: int, index: type, value: type) -> None:
    spill = ColumnSpill()
    column = _column(np.random.default_rng(count), count, index, value)
    try:
        assert spill.write(3, column)
        receivers, factors = spill.read_factors(3)
        for mapped in (False, True):  # read at once, or mapped (a shot's)
            back = spill.read(3, mapped)
            assert back is not None
            for got in (receivers, back.receivers):
                assert got.dtype == index and np.array_equal(got, column.receivers)
            for got in (factors, back.factors):
                assert got.dtype == value and np.array_equal(got, column.factors)
            assert back.rays == 0  # its rays were counted when it was traced
            for name in ("receivers", "factors", "pointer", "sources", "weights"):
                got, wrote = getattr(back.gather, name), getattr(column.gather, name)
                assert got.dtype == wrote.dtype and np.array_equal(got, wrote)
            arrays = (back.receivers, back.factors, *vars(back.gather).values())
            for got in (receivers, factors, *arrays):  # the compiled shot's types
                assert got.flags.writeable and got.flags.aligned and got.flags.c_contiguous
            back.factors[:1] = 5  # this process's copy: the file keeps what was written
        assert np.array_equal(spill.read(3).factors, column.factors)
        assert spill.read_factors(4) is None and spill.read(4) is None
        folder = spill.folder
    finally:
        spill.close()
    assert folder and not os.path.exists(folder)


@pytest.fixture
def spilled() -> Iterator[tuple[ColumnSpill, str]]:
    """A spill holding one column of 100 entries as patch 0, and its file."""
    spill = ColumnSpill()
    spill.write(0, _column(np.random.default_rng(1), 100, np.int32, np.float32))
    yield spill, os.path.join(spill.folder, "0" + SUFFIX)
    spill.close()


@pytest.mark.parametrize("cut", [8, 8 * 15 - 4])  # into the last array; into the header
def test_a_spilled_file_cut_short_is_an_error_not_a_short_column(spilled, cut) -> None:
    spill, path = spilled
    with open(path, "r+b") as file:
        file.truncate(os.path.getsize(path) - cut if cut == 8 else cut)
    for mapped in (False, True):
        with pytest.raises(OSError, match=r"cut short|not a spilled column"):
            spill.read(0, mapped)
    if cut == 8:  # the factors come first: they are still whole
        receivers, factors = spill.read_factors(0)
        assert len(receivers) == len(factors) == 100
    else:
        with pytest.raises(OSError, match="not a spilled column"):
            spill.read_factors(0)


@pytest.mark.parametrize(
    "header",
    [
        np.array([0]),  # no arrays
        np.array([MOST_ARRAYS + 1]),
        np.array([7, 0, 100, 9, 100]),  # no such item type
        np.array([7, 0, -1, 2, 100]),  # a negative length
        b"short",
    ],
)
def test_a_spilled_file_with_a_bad_header_is_an_error(spilled, header) -> None:
    spill, path = spilled
    with open(path, "r+b") as file:
        file.write(header if isinstance(header, bytes) else header.astype(np.int64).tobytes())
        if isinstance(header, bytes):
            file.truncate(len(header))
    with pytest.raises(OSError, match="not a spilled column"):
        spill.read_factors(0)
    for mapped in (False, True):
        with pytest.raises(OSError, match="not a spilled column"):
            spill.read(0, mapped)


def test_written_arrays_read_back_aligned_whatever_their_lengths(tmp_path) -> None:
    """Each array is padded to 8 bytes: an odd number of int32 before float64 still reads
    back aligned, and each of the item types round-trips."""
    arrays = tuple(
        np.arange(n, dtype=t) * 3
        for n, t in zip((3, 1, 0, 5, 2), ITEM_TYPES + ITEM_TYPES[:1], strict=True)
    )
    path = str(tmp_path / ("a" + SUFFIX))
    write_arrays(path, arrays)
    assert os.path.getsize(path) == 8 * 11 + 16 + 8 + 0 + 40 + 8
    back = read_arrays(path)
    assert len(back) == 5 and len(read_arrays(path, 2)) == 2
    for got, wrote in zip(back, arrays, strict=True):
        assert got.dtype == wrote.dtype and np.array_equal(got, wrote) and got.flags.aligned
