"""Patch outlines (raytrad.core.outline): which piece of a folded patch lies across each
of a piece's edges, from edges written out by hand."""

from __future__ import annotations

import numpy as np

from raytrad.core.outline import _twin_pieces

A, B, C, D, E = (
    np.array(p, dtype=float) for p in ([0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.2], [0.5, -1, 0.1])
)


def _edges(*loops: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    start = np.array([p for loop in loops for p in loop])
    end = np.array([loop[(k + 1) % len(loop)] for loop in loops for k in range(len(loop))])
    piece = np.repeat(np.arange(len(loops)), [len(loop) for loop in loops])
    return start, end, piece


def test_two_pieces_across_one_edge_are_each_others_twins() -> None:
    # piece 0: A -> B -> C, piece 1: B -> A -> ... wound alike, so they share B -> A
    start, end, piece = _edges([A, B, C], [B, A, E])
    twin = _twin_pieces(start, end, piece, np.zeros(len(piece), dtype=np.int64))
    np.testing.assert_array_equal(twin, [1, -1, -1, 0, -1, -1])


def test_another_patch_is_never_a_twin() -> None:
    start, end, piece = _edges([A, B, C], [B, A, E])
    twin = _twin_pieces(start, end, piece, np.array([0, 0, 0, 1, 1, 1]))
    assert (twin == -1).all()


def test_an_edge_three_pieces_meet_at_has_no_twin() -> None:
    # pieces 0 and 2 both run A -> B; piece 1 runs B -> A: no pairing is one to one
    start, end, piece = _edges([A, B, C], [B, A, E], [A, B, D])
    twin = _twin_pieces(start, end, piece, np.zeros(len(piece), dtype=np.int64))
    assert twin[0] == -1 and twin[3] == -1 and twin[6] == -1
    # the other edges have no neighbour either
    assert (twin == -1).all()
