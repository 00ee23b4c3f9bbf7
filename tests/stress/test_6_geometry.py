"""Group 6: what CAD export does to geometry, in a closed unit cube of reflectance 0.9.

Each defect is tried twice: as a white furnace (every face emits E = 1, so B = E / (1 - rho)
= 10 at every receiver) and with only the ceiling emitting (sum a B = 1 m2 x E / (1 - rho)
= 10 W). Where raytrad repairs a defect it must say so in a warning.
"""

from __future__ import annotations

import logging

import pytest

from .cases import assert_finished, assert_within, case, run_case

KINDS = ["furnace", "lamp"]


def _check(name: str) -> None:
    run = run_case(case(name))
    assert_finished(run)
    assert_within(run)


def _warned(caplog: pytest.LogCaptureFixture, *words: str) -> bool:
    return any(
        record.levelno >= logging.WARNING and all(w in record.getMessage() for w in words)
        for record in caplog.records
    )


@pytest.mark.parametrize("kind", KINDS)
def test_sliver_triangles(kind: str) -> None:
    # a 1e-6 m strip across a 1 m wall: two triangles of aspect ratio 1e6
    _check(f"sliver-{kind}")


@pytest.mark.parametrize("kind", KINDS)
def test_coincident_identical_faces_are_dropped_with_a_warning(
    kind: str, caplog: pytest.LogCaptureFixture
) -> None:
    # the ceiling twice: the copy must not double its light (for the lamp: 10 W, not 20 W)
    with caplog.at_level(logging.WARNING):
        _check(f"duplicate-face-{kind}")
    assert _warned(caplog, "duplicate")


@pytest.mark.parametrize("kind", KINDS)
def test_coincident_retriangulated_faces_are_merged_with_a_warning(
    kind: str, caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level(logging.WARNING):
        _check(f"duplicate-retriangulated-{kind}")
    assert _warned(caplog, "duplicate")


@pytest.mark.parametrize("kind", KINDS)
def test_t_junctions(kind: str) -> None:
    # one wall as a half quad next to two quarter quads: a vertex on the middle of an edge
    _check(f"t-junction-{kind}")


@pytest.mark.parametrize("kind", KINDS)
def test_non_manifold_edges_of_a_partition(kind: str) -> None:
    # a double-sided diagonal wall: its two edges are each shared by three faces
    _check(f"non-manifold-partition-{kind}")


def test_non_manifold_fin_in_a_corner_furnace() -> None:
    _check("non-manifold-fin-furnace")


def test_non_manifold_fin_in_a_corner_lamp() -> None:
    _check("non-manifold-fin-lamp")


@pytest.mark.parametrize("kind", KINDS)
def test_inverted_wall_is_fixed_with_a_warning(kind: str, caplog: pytest.LogCaptureFixture) -> None:
    # A wall whose front faces away from the whole scene and whose back faces the inside is
    # a modelling error: fixed, with a warning, the box is a white furnace again.
    with caplog.at_level(logging.WARNING):
        _check(f"inverted-wall-{kind}")
    assert _warned(caplog, "flipped")


@pytest.mark.parametrize("kind", KINDS)
def test_inverted_wall_with_t_junctions_is_fixed_with_a_warning(
    kind: str, caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level(logging.WARNING):
        _check(f"inverted-t-junction-wall-{kind}")
    assert _warned(caplog, "flipped")


@pytest.mark.parametrize("kind", KINDS)
def test_zero_area_faces_are_dropped_with_a_warning(
    kind: str, caplog: pytest.LogCaptureFixture
) -> None:
    # repeated and collinear corners, plus an unused vertex 1e6 m away
    with caplog.at_level(logging.WARNING):
        _check(f"zero-area-{kind}")
    assert _warned(caplog, "zero-area")


@pytest.mark.parametrize("kind", KINDS)
def test_duplicate_vertices(kind: str) -> None:
    _check(f"duplicate-vertices-{kind}")
