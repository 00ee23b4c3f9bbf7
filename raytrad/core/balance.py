"""Balancing sampled form factors so that they conserve energy: Sinkhorn scaling of the
receiver-by-patch matrix, ``F'_jp = r_j F_jp c_p`` (see
:meth:`raytrad.core.formfactor.FormFactorEngine.balance` for the constraints)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from raytrad.core import compiled
from raytrad.core.mesh import RadiosityMesh

#: Most row-and-column rounds of :func:`sinkhorn`.
BALANCE_ITERATIONS = 500
#: Balancing stops when no column scale changes by more than this.
BALANCE_CONVERGED = 1e-12


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
) -> tuple[np.ndarray, np.ndarray, int]:
    """Row and column scales that hold the ``fixed_rows`` to a sum of 1, the
    ``closed_columns`` to a capture of 1 and every other column to a capture of at most 1.

    The capture of patch p is ``g_p = sum_j a_j F_jp / A_p``. Rows and columns are scaled
    alternately until no column scale changes by more than :data:`BALANCE_CONVERGED`; the
    rows are scaled last, so the fixed rows sum to 1 to rounding.

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
    """
    rows, owner, values = factors.rows, factors.columns, factors.values
    total = factors.column_count
    col_scale = np.ones(total)
    done = 0
    while done < iterations:
        done += 1
        row_scale = _row_scales(factors, values * col_scale[owner], fixed_rows)
        weight = receiver_area * values * row_scale[rows]
        capture = np.bincount(owner, weights=weight, minlength=total) / patch_area
        new_col = np.ones(total)
        np.divide(1.0, capture, out=new_col, where=(capture > 1.0) | closed_columns)
        change = np.abs(new_col / col_scale - 1.0).max(initial=0.0)
        col_scale = new_col
        if change < BALANCE_CONVERGED:
            break
    return _row_scales(factors, values * col_scale[owner], fixed_rows), col_scale, done


class Balanced(NamedTuple):
    """What :func:`balance_columns` found.

    Attributes
    ----------
    row_scale : (R,) float64
    column_scale : (P,) float64
    iterations : int
    capture_before, capture_after : (P,) float64, ``g_p`` before and after [1]
    row_sums : (R,) float64, ``sum_p F'_jp`` of the balanced factors [1]
    """

    row_scale: np.ndarray
    column_scale: np.ndarray
    iterations: int
    capture_before: np.ndarray
    capture_after: np.ndarray
    row_sums: np.ndarray


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
    """:func:`sinkhorn` on columns stored end to end, with the captures and row sums.

    Compiled when available: one loop over the entries per round and no per-entry
    temporaries, so balancing needs no memory beyond the columns themselves;
    :func:`numpy_balance_columns` is the reference.

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
    fast = compiled.get()
    if fast is None:
        return numpy_balance_columns(
            pointer, rows, values, receiver_area, patch_area, fixed_rows, closed_columns, iterations
        )
    out = fast.sinkhorn_columns(
        np.ascontiguousarray(pointer, dtype=np.int64),
        np.ascontiguousarray(rows),
        np.ascontiguousarray(values),
        np.ascontiguousarray(receiver_area, dtype=np.float64),
        np.ascontiguousarray(patch_area, dtype=np.float64),
        np.ascontiguousarray(fixed_rows, dtype=np.bool_),
        np.ascontiguousarray(closed_columns, dtype=np.bool_),
        int(iterations),
        BALANCE_CONVERGED,
    )
    return Balanced(out[0], out[1], int(out[2]), out[3], out[4], out[5])


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
    row_scale, col_scale, done = sinkhorn(
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
    return Balanced(row_scale, col_scale, done, capture0, capture, row_sums)


def _row_scales(factors: Sparse, values: np.ndarray, fix: np.ndarray) -> np.ndarray:
    """(R,) scales that make the ``fix`` rows of ``values`` sum to 1 (1 elsewhere)."""
    row_sum = np.bincount(factors.rows, weights=values, minlength=factors.row_count)
    return np.where(fix & (row_sum > 0), 1.0 / np.maximum(row_sum, 1e-300), 1.0)


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
    "Balanced",
    "Sparse",
    "balance_columns",
    "closed_patches",
    "numpy_balance_columns",
    "sinkhorn",
]
