"""Spilled form-factor columns: what is written is what is read back, in its own types."""

from __future__ import annotations

import os
from collections.abc import Iterator

import numpy as np
import pytest

from raytrad.core.columns import Column, ColumnSpill
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
        back = spill.read(3)
        assert back is not None
        for got in (receivers, back.receivers):
            assert got.dtype == index and np.array_equal(got, column.receivers)
        for got in (factors, back.factors):
            assert got.dtype == value and np.array_equal(got, column.factors)
        assert back.rays == 0  # its rays were counted when it was traced
        for name in ("receivers", "factors", "pointer", "sources", "weights"):
            assert np.array_equal(getattr(back.gather, name), getattr(column.gather, name))
        assert spill.read_factors(4) is None and spill.read(4) is None
        folder = spill.folder
    finally:
        spill.close()
    assert folder and not os.path.exists(folder)


@pytest.fixture
def spilled() -> Iterator[tuple[ColumnSpill, str]]:
    """A spill holding one column of 100 entries as patch 0, and its factors file."""
    spill = ColumnSpill()
    spill.write(0, _column(np.random.default_rng(1), 100, np.int32, np.float32))
    yield spill, os.path.join(spill.folder, "0.npz.factors")
    spill.close()


def test_a_factors_file_cut_short_is_an_error_not_a_short_column(spilled) -> None:
    spill, path = spilled
    with open(path, "r+b") as file:
        file.truncate(os.path.getsize(path) - 4)
    with pytest.raises(OSError, match="cut short"):
        spill.read_factors(0)


@pytest.mark.parametrize("header", [np.array([100, 3, 4]), np.array([100, 4, 2]), b"short"])
def test_a_factors_file_with_a_bad_header_is_an_error(spilled, header) -> None:
    spill, path = spilled
    with open(path, "r+b") as file:
        file.write(header if isinstance(header, bytes) else header.astype(np.int64).tobytes())
        if isinstance(header, bytes):
            file.truncate(len(header))
    with pytest.raises(OSError, match="not a spilled column"):
        spill.read_factors(0)
