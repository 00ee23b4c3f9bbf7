"""Balancing sampled form factors so that they conserve energy: Sinkhorn scaling of the
receiver-by-patch matrix, ``F'_jp = r_j F_jp c_p`` (see
:meth:`raytrad.core.formfactor.FormFactorEngine.balance` for the constraints)."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from types import SimpleNamespace
from typing import NamedTuple

import numpy as np

from raytrad.core import compiled
from raytrad.core.mesh import RadiosityMesh

#: Most row-and-column rounds of :func:`sinkhorn`. Most scenes converge in a dozen (the
#: Cornell box in 9); the others stop when their rounds stall (:data:`BALANCE_STALL`).
BALANCE_ITERATIONS = 100
#: Balancing stops when every patch captures what it should to within this (closed
#: patches 1, unless held at :data:`COLUMN_SCALE_LIMIT`; the others at most 1) [1].
BALANCE_CONVERGED = 1e-9
#: ... or when that largest miss has not halved in this many rounds. A scene whose
#: receivers nearly all see surfaces all round cannot meet every constraint: each row and
#: column together hold ``sum_j a_j sum_p F'_jp = sum_p A_p g_p``, and with the closed
#: rows at 1 the closed patches' areas must sum to the receivers'. Sinkhorn then drifts
#: towards the nearest scales that would, a little each round, and the drift slowly
#: undoes :data:`COLUMN_SCALE_LIMIT` (its scales are relative to the rows'). In a room of
#: 36 blocks (0.4 % of its receivers see an opening) the miss fell from 7e-4 after 5
#: rounds to 9e-5 after 20 and 4.5e-5 after 100; in the cluttered room (short patches,
#: below) from 5e-3 after 15 rounds to 1.4e-3 after 30 and 1.1e-3 after 100. Stopping
#: when the miss stalls moved the balanced factors by 7.6e-5 and 7.3e-4 of their sum
#: against 100 rounds (2026-12-03); the rows are held to 1 either way.
BALANCE_STALL = 10
#: ... once that miss is within this [1]. A light 1 mm under a ceiling, facing it, misses
#: by 0.3 for a dozen rounds before its misses fall (to 3e-2 after 30 rounds and 1.2e-2
#: after 90): stopped on the first stall, a patch delivered 1.24 times what it shoots.
BALANCE_STALL_MISS = 1e-2
#: Most a patch's factors are scaled up to deliver what it shoots (a closed patch). Beyond
#: it, the shortfall is not sampling error but surfaces nearer each other than the
#: receivers are spaced: a light 1 mm under a ceiling, facing it, whose receivers' areas
#: over it sum to 70 % of its own. Their rows are held to 1, so scaling the column up
#: raised only its small factors, to receivers outside the gap: the light's column came out
#: 87 times its factors, the walls 3 times as bright as with the limit (30 times a path
#: tracer's), and refinement's new points by the light, which take the column scales
#: without the row scales, 1 040 W m-2 where nothing can show more than 12. The shortfall
#: is left unbalanced (:meth:`Balanced.summary`'s ``short_columns``), as a row off by more
#: than ``ROW_FIX_LIMIT`` is. The bundled scenes' columns scale by 1.13 at most (the room
#: of blocks; 1.02 the Cornell box).
COLUMN_SCALE_LIMIT = 1.25


class Sparse(NamedTuple):
    """A receiver-by-patch matrix as coordinates: entry k is ``values[k]`` at row
    ``rows[k]`` (receiver), column ``columns[k]`` (patch)."""

    rows: np.ndarray
    columns: np.ndarray
    values: np.ndarray
    row_count: int
    column_count: int


def sinkhorn(
    factors: Sparse,
    receiver_area: np.ndarray,
    patch_area: np.ndarray,
    fixed_rows: np.ndarray,
    closed_columns: np.ndarray,
    iterations: int = BALANCE_ITERATIONS,
) -> tuple[np.ndarray, np.ndarray, int, str]:
    """Row and column scales that hold the ``fixed_rows`` to a sum of 1, the
    ``closed_columns`` to a capture of 1 (scaled up by :data:`COLUMN_SCALE_LIMIT` at most)
    and every other column to a capture of at most 1.

    The capture of patch p is ``g_p = sum_j a_j F_jp / A_p``. Rows and columns are scaled
    alternately until every capture is within :data:`BALANCE_CONVERGED` of its goal, or
    the rounds stall (:func:`stop_reason`); the rows are scaled last, so the fixed rows sum
    to 1 to rounding.

    Parameters
    ----------
    factors : Sparse
        F_jp, (R, P).
    receiver_area : (K,) float64
        ``a_j`` of each entry's receiver [m2].
    patch_area : (P,) float64 [m2]
    fixed_rows : (R,) bool
    closed_columns : (P,) bool
    iterations : int

    Returns
    -------
    row_scale : (R,) float64
    column_scale : (P,) float64
    iterations : int, rounds taken
    stopped : str, why they stopped (:func:`stop_reason`, or ``"rounds"``: ``iterations``)
    """
    rows, owner, values = factors.rows, factors.columns, factors.values
    total = factors.column_count
    col_scale = np.ones(total)
    misses: list[float] = []
    stopped = ""
    while len(misses) < iterations:
        row_scale = _row_scales(factors, values * col_scale[owner], fixed_rows)
        weight = receiver_area * values * row_scale[rows]
        capture = np.bincount(owner, weights=weight, minlength=total) / patch_area
        misses.append(capture_miss(capture, col_scale, closed_columns))
        new_col = np.ones(total)
        np.divide(
            1.0, capture, out=new_col, where=(capture > 1.0) | (closed_columns & (capture > 0))
        )
        np.minimum(new_col, COLUMN_SCALE_LIMIT, out=new_col)
        col_scale = new_col
        stopped = stop_reason(misses)
        if stopped:
            break
    row_scale = _row_scales(factors, values * col_scale[owner], fixed_rows)
    return row_scale, col_scale, len(misses), stopped or "rounds"


def capture_miss(capture: np.ndarray, column_scale: np.ndarray, closed: np.ndarray) -> float:
    """The largest miss of a round's captures ``g_p = capture_p x column_scale_p`` [1]:
    ``|g - 1|`` of a closed patch (none for one held at :data:`COLUMN_SCALE_LIMIT` short
    of 1), ``g - 1`` above 1 of any other; patches that capture nothing miss nothing.

    Parameters
    ----------
    capture : (P,) float64
        Captures at column scale 1 under the round's row scales [1].
    column_scale : (P,) float64
        The scales before the round's.
    closed : (P,) bool
    """
    g = capture * column_scale
    short = closed & (column_scale >= COLUMN_SCALE_LIMIT) & (g < 1.0)
    miss = np.where(closed & ~short, np.abs(g - 1.0), np.maximum(g - 1.0, 0.0))
    return float(np.max(miss, where=capture > 0, initial=0.0))


def stop_reason(misses: list[float]) -> str:
    """Why balancing stops after the rounds whose misses (:func:`capture_miss`) are
    ``misses``: ``"converged"``, the last is within :data:`BALANCE_CONVERGED`;
    ``"stalled"``, it is within :data:`BALANCE_STALL_MISS` and not half the one
    :data:`BALANCE_STALL` rounds before it; else ``""`` (it goes on)."""
    last = misses[-1]
    if last <= BALANCE_CONVERGED:
        return "converged"
    stalled = len(misses) > BALANCE_STALL and last > 0.5 * misses[-1 - BALANCE_STALL]
    return "stalled" if stalled and last <= BALANCE_STALL_MISS else ""


class Balanced(NamedTuple):
    """What :func:`balance_columns` found.

    Attributes
    ----------
    row_scale : (R,) float64
    column_scale : (P,) float64
    iterations : int
    capture_before, capture_after : (P,) float64, ``g_p`` before and after [1]
    row_sums : (R,) float64, ``sum_p F'_jp`` of the balanced factors [1]
    stopped : str, why the rounds stopped: ``"converged"``, ``"stalled"``
        (:func:`stop_reason`) or ``"rounds"`` (the most allowed)
    """

    row_scale: np.ndarray
    column_scale: np.ndarray
    iterations: int
    capture_before: np.ndarray
    capture_after: np.ndarray
    row_sums: np.ndarray
    stopped: str

    def short(self, closed_columns: np.ndarray) -> np.ndarray:
        """(P,) bool: the ``closed_columns`` held at :data:`COLUMN_SCALE_LIMIT`, short of
        delivering what they shoot."""
        return closed_columns & (self.column_scale >= COLUMN_SCALE_LIMIT)

    def summary(
        self,
        row_sum: np.ndarray,
        fixed_rows: np.ndarray,
        closed_columns: np.ndarray,
        patch_area: np.ndarray,
    ) -> dict[str, float | bool | str]:
        """What balancing did, for the log and ``report.json``, from the raw ``row_sum``
        (R,), the ``fixed_rows`` (R,) and ``closed_columns`` (P,) it was given and the
        ``patch_area`` (P,) [m2].

        Returns
        -------
        dict with ``closed_rows`` (rows held to 1), ``closed_columns`` (patches held to
        g = 1), ``capped_columns`` (other patches scaled down to g = 1), ``short_columns``
        (closed patches held at :data:`COLUMN_SCALE_LIMIT`, short of g = 1) and
        ``short_area`` (their share of the patches' area), ``row_error`` and
        ``capture_excess`` (largest deviations before balancing), ``column_excess``
        (largest g - 1 after it), ``column_deficit`` (largest 1 - g of the short patches
        after it), ``iterations`` and ``stopped``.
        """
        short = self.short(closed_columns)
        area = float(patch_area.sum())
        return {
            "closed_rows": int(fixed_rows.sum()),
            "closed_columns": int(closed_columns.sum()),
            "capped_columns": int(((self.column_scale < 1.0) & ~closed_columns).sum()),
            "short_columns": int(short.sum()),
            "short_area": float(patch_area[short].sum() / area) if area > 0 else 0.0,
            "row_error": float(np.abs(row_sum[fixed_rows] - 1.0).max(initial=0.0)),
            "capture_excess": float(max(0.0, self.capture_before.max(initial=0.0) - 1.0)),
            "column_excess": float(max(0.0, self.capture_after.max(initial=0.0) - 1.0)),
            "column_deficit": float(max(0.0, 1.0 - self.capture_after[short].min(initial=1.0))),
            "iterations": self.iterations,
            "stopped": self.stopped,
            "complete": True,
        }


#: ``columns()`` of :func:`balance_streamed`: a fresh iterator over (patch, rows, values)
#: of every patch, ascending.
ColumnSource = Callable[[], Iterable[tuple[int, np.ndarray, np.ndarray]]]


def balance_streamed(
    columns: ColumnSource,
    receiver_area: np.ndarray,
    patch_area: np.ndarray,
    fixed_rows: np.ndarray,
    closed_columns: np.ndarray,
    iterations: int = BALANCE_ITERATIONS,
) -> Balanced:
    """:func:`sinkhorn` one column at a time, with the captures and row sums: balancing
    holds no more than one column beyond what ``columns`` keeps (the form-factor cache;
    spilled columns are read back each round).

    Each round is one sweep over the columns: patch p's capture under the current row
    scales gives its new column scale, and its entries are then added to the next
    round's row sums at that scale. That is the order :func:`sinkhorn` computes in, so the
    results are the same (to rounding) in ``iterations + 2`` sweeps. The per-column loops
    are compiled when available (:func:`numpy_balance_columns` is the reference).

    Parameters
    ----------
    columns : callable
        ``columns()`` iterates (patch, rows, values) of every patch in ascending patch
        order, each time it is called: rows (K_p,) int receivers, values (K_p,) float32 or
        float64 F_jp [1]; a patch not yielded has no entries.
    receiver_area : (R,) float64 [m2]
    patch_area : (P,) float64 [m2]
    fixed_rows : (R,) bool
    closed_columns : (P,) bool
    iterations : int
    """
    step = _column_steps()
    area = np.ascontiguousarray(receiver_area, dtype=np.float64)
    total = len(patch_area)
    col_scale = np.ones(total)
    capture0 = np.zeros(total)
    row_sum = np.zeros(len(area))
    ones = np.ones(len(area))
    for p, rows, values in columns():
        capture0[p] = step.column_final(rows, values, area, ones, 1.0, row_sum) / patch_area[p]
    row_scale = _fixed_row_scales(row_sum, fixed_rows)
    misses: list[float] = []
    stopped = ""
    while len(misses) < iterations:
        row_sum[:] = 0.0
        new = np.ones(total)  # a patch with no entries captures nothing: scale 1
        capture = np.zeros(total)
        for p, rows, values in columns():
            capture[p], new[p] = step.column_sweep(
                rows,
                values,
                area,
                row_scale,
                float(patch_area[p]),
                bool(closed_columns[p]),
                COLUMN_SCALE_LIMIT,
                row_sum,
            )
        misses.append(capture_miss(capture, col_scale, closed_columns))
        col_scale = new
        row_scale = _fixed_row_scales(row_sum, fixed_rows)
        stopped = stop_reason(misses)
        if stopped:
            break
    done = len(misses)
    row_sums = np.zeros(len(area))
    capture = np.zeros(total)
    for p, rows, values in columns():
        final = step.column_final(rows, values, area, row_scale, float(col_scale[p]), row_sums)
        capture[p] = final / patch_area[p]
    return Balanced(row_scale, col_scale, done, capture0, capture, row_sums, stopped or "rounds")


def balance_columns(
    pointer: np.ndarray,
    rows: np.ndarray,
    values: np.ndarray,
    receiver_area: np.ndarray,
    patch_area: np.ndarray,
    fixed_rows: np.ndarray,
    closed_columns: np.ndarray,
    iterations: int = BALANCE_ITERATIONS,
) -> Balanced:
    """:func:`balance_streamed` over columns stored end to end.

    Parameters
    ----------
    pointer : (P + 1,) int64
        CSR pointers of each patch's entries.
    rows : (K,) int
        Receiver of each entry.
    values : (K,) float32 or float64
        F_jp [1] (the scales and sums are float64 either way).
    receiver_area : (R,) float64 [m2]
    patch_area : (P,) float64 [m2]
    fixed_rows : (R,) bool
    closed_columns : (P,) bool
    iterations : int
    """
    rows, values = np.ascontiguousarray(rows), np.ascontiguousarray(values)

    def columns() -> Iterator[tuple[int, np.ndarray, np.ndarray]]:
        for p in range(len(pointer) - 1):
            yield p, rows[pointer[p] : pointer[p + 1]], values[pointer[p] : pointer[p + 1]]

    return balance_streamed(
        columns, receiver_area, patch_area, fixed_rows, closed_columns, iterations
    )


def numpy_column_sweep(
    rows: np.ndarray,
    values: np.ndarray,
    receiver_area: np.ndarray,
    row_scale: np.ndarray,
    patch_area: float,
    closed: bool,
    limit: float,
    row_sum: np.ndarray,
) -> tuple[float, float]:
    """One column's step of a balancing round (:func:`balance_streamed`): its capture
    ``g = sum a F r / A`` under the row scales, its new scale (:func:`_column_scale`, at
    most ``limit``), and its factors at that scale added to ``row_sum``.

    Returns
    -------
    capture : float [1]
    scale : float [1]
    """
    capture = float(np.sum(receiver_area[rows] * values * row_scale[rows])) / patch_area
    scale = _column_scale(capture, closed, limit)
    row_sum[rows] += np.asarray(values, dtype=np.float64) * scale  # a column's rows differ
    return capture, scale


def _column_scale(capture: float, closed: bool, limit: float = COLUMN_SCALE_LIMIT) -> float:
    """A column's scale for its capture: 1 / capture when it is closed or above 1, at most
    :data:`COLUMN_SCALE_LIMIT` (and 1 when it captures nothing)."""
    if capture > 1.0 or (closed and capture > 0.0):
        return min(1.0 / capture, limit)
    return 1.0


def _fixed_row_scales(row_sum: np.ndarray, fix: np.ndarray) -> np.ndarray:
    """(R,) scales that bring the ``fix`` rows' sums to 1 (1 elsewhere)."""
    return np.where(fix & (row_sum > 0), 1.0 / np.maximum(row_sum, 1e-300), 1.0)


def _column_steps() -> SimpleNamespace:
    """The per-column loops of :func:`balance_streamed`: compiled, or numpy."""
    fast = compiled.get()
    if fast is not None:
        return SimpleNamespace(
            column_sweep=fast.column_sweep,
            column_final=fast.column_final,
        )
    return SimpleNamespace(
        column_sweep=numpy_column_sweep,
        column_final=numpy_column_final,
    )


def numpy_column_final(
    rows: np.ndarray,
    values: np.ndarray,
    receiver_area: np.ndarray,
    row_scale: np.ndarray,
    scale: float,
    row_sums: np.ndarray,
) -> float:
    """Adds one column's balanced factors ``F r c`` to ``row_sums``; returns its capture
    ``sum a F r c`` [m2]."""
    final = np.asarray(values, dtype=np.float64) * scale * row_scale[rows]
    row_sums[rows] += final
    return float(np.sum(receiver_area[rows] * final))


def numpy_balance_columns(
    pointer: np.ndarray,
    rows: np.ndarray,
    values: np.ndarray,
    receiver_area: np.ndarray,
    patch_area: np.ndarray,
    fixed_rows: np.ndarray,
    closed_columns: np.ndarray,
    iterations: int = BALANCE_ITERATIONS,
) -> Balanced:
    """:func:`balance_columns` in numpy (the reference)."""
    total = len(patch_area)
    owner = np.repeat(np.arange(total), np.diff(pointer))
    area = receiver_area[rows]
    capture0 = np.bincount(owner, weights=area * values, minlength=total) / patch_area
    row_scale, col_scale, done, stopped = sinkhorn(
        Sparse(rows, owner, values, len(receiver_area), total),
        area,
        patch_area,
        fixed_rows,
        closed_columns,
        iterations,
    )
    final = values * col_scale[owner] * row_scale[rows]
    row_sums = np.bincount(rows, weights=final, minlength=len(receiver_area))
    capture = np.bincount(owner, weights=area * final, minlength=total) / patch_area
    return Balanced(row_scale, col_scale, done, capture0, capture, row_sums, stopped)


def _row_scales(factors: Sparse, values: np.ndarray, fix: np.ndarray) -> np.ndarray:
    """(R,) scales that make the ``fix`` rows of ``values`` sum to 1 (1 elsewhere)."""
    row_sum = np.bincount(factors.rows, weights=values, minlength=factors.row_count)
    return _fixed_row_scales(row_sum, fix)


def closed_patches(mesh: RadiosityMesh, closed: np.ndarray) -> np.ndarray:
    """(P,) bool: patches all of whose visible receivers are ``closed``: their light has
    nowhere to go but other surfaces."""
    corner_patch = np.repeat(mesh.triangle_patch, 3)
    corner = mesh.triangle_receivers.reshape(-1)
    counts = mesh.receiver_area[corner] > 0  # hidden receivers do not shoot
    open_corners = counts & ~closed[corner]
    out = np.bincount(corner_patch, weights=open_corners, minlength=mesh.patch_count) == 0
    return np.asarray(
        out & (np.bincount(corner_patch, weights=counts, minlength=mesh.patch_count) > 0)
    )


__all__ = [
    "BALANCE_CONVERGED",
    "BALANCE_ITERATIONS",
    "BALANCE_STALL",
    "BALANCE_STALL_MISS",
    "COLUMN_SCALE_LIMIT",
    "Balanced",
    "ColumnSource",
    "Sparse",
    "balance_columns",
    "balance_streamed",
    "capture_miss",
    "closed_patches",
    "numpy_balance_columns",
    "numpy_column_sweep",
    "sinkhorn",
    "stop_reason",
]
