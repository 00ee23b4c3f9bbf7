"""Vertex-to-patch form factors (Wallace, Elmquist and Haines 1989), ray-traced.

The form factor from receiver point x (normal n_x) to a patch split into sub-areas k of
area dA_k with fixed sample points y_k (normal n_k) is::

    F(x <- patch) = sum_k V(x, y_k) * cos(theta_x) * cos(theta_k) * dA_k / (pi r^2 + dA_k)

(the disk approximation of Wallace et al.). It is accurate while a sub-area is small
against its distance; it underestimates near, oblique receivers. So a sub-area closer than
:data:`NEAR_FACTOR` times its size is evaluated exactly instead: each of its triangles gets
the closed-form Lambert point-to-polygon factor, clipped to the receiver's horizon, times
the visibility of the triangle's centroid: near and far receivers both get the unoccluded
factor to within a fraction of a percent, at a bounded cost. Pairs that cannot exchange
light (receiver behind the patch, patch below its horizon) cost no ray.
"""

from __future__ import annotations

import itertools
import logging
import threading
from collections.abc import Callable, Generator, Iterable, Iterator, Mapping
from concurrent.futures import ThreadPoolExecutor
from typing import Any, TypeVar, overload

import numpy as np

from raytrad.arrays import morton_order
from raytrad.constants import scene_diagonal, tol
from raytrad.core import stages
from raytrad.core.balance import BALANCE_ITERATIONS, balance_streamed, closed_patches
from raytrad.core.columns import (
    Column,
    ColumnSpill,
    column_parts,
    compact_gather,
    pack_columns,
    return_freed_memory,
    unpack_columns,
)
from raytrad.core.gather import (
    EMPTY,
    GatherRows,
    GatherWeights,
    SubareaMeans,
    join_gathers,
)
from raytrad.core.mesh import RadiosityMesh
from raytrad.core.pairs import PairFactors, receiver_points
from raytrad.core.visibility import Occluder, ordered_map, worker_count

log = logging.getLogger(__name__)
_T = TypeVar("_T")

#: Largest relative miss of a closed receiver's row sum that balancing treats as sampling
#: error; beyond it the row is a modelling problem and left alone.
ROW_FIX_LIMIT = 0.25
#: Row sums of an occlusion-free scene within this of 1 count as closed (exact factors).
EXACT_ROW_SUM = 1e-6
#: Columns a worker may have computed or under way beyond the one the pass is taking: the
#: pass's memory stays bounded while a checkpoint is written (a million-receiver column
#: with its gather weights can take 60 MB), and the pass takes the time it took unbounded.
AHEAD_PER_WORKER = 2


#: The arrays of :meth:`FormFactorEngine.balanced_scales`: a value per receiver (0) or
#: per patch (1) each.
BALANCED_SCALES = dict(row_scale=0, row_sums=0, closed_rows=0, column_scale=1, short_patches=1)
#: What :meth:`FormFactorEngine.balance` reports when the pass was cut short.
_UNBALANCED: dict[str, float | bool | str] = {
    "closed_rows": 0,
    "closed_columns": 0,
    "capped_columns": 0,
    "short_columns": 0,
    "short_area": 0.0,
    "row_error": 0.0,
    "capture_excess": 0.0,
    "column_excess": 0.0,
    "column_deficit": 0.0,
    "iterations": 0,
    "stopped": "unbalanced",
}


class _Worker(threading.local):
    """Set in a thread computing one patch: its chunks then run in that thread."""

    active = False


_WORKER = _Worker()


# --------------------------------------------------------------------------------------
# Columns of the receiver-by-patch matrix
# --------------------------------------------------------------------------------------


class FormFactorEngine:
    """Computes (and caches) columns F(all receivers <- patch).

    Parameters
    ----------
    mesh : RadiosityMesh
    occluder : Occluder or None
        None when nothing in the scene can block light (a convex enclosure): no rays.
    cache_bytes : int
        Memory for cached columns, their near-field gather weights included; one that
        does not fit is spilled to a temporary file (:attr:`columns_spilled`) and read
        back when shot again (0: no cache, recomputed each time).
    cull : bool
        Trace only the (receiver, patch) pairs whose shaft an occluder may cross
        (:mod:`raytrad.core.shafts`); False traces every pair (the tests' reference).
    pairs : PairFactors or None
        The pair tables of the engine whose mesh ``mesh`` refines (see :meth:`refined`):
        what does not change under refinement is carried over.
    """

    def __init__(
        self,
        mesh: RadiosityMesh,
        occluder: Occluder | None,
        cache_bytes: int = 1 << 30,
        cull: bool = True,
        pairs: PairFactors | None = None,
    ) -> None:
        self.mesh = mesh
        self.occluder = occluder
        self.cache_bytes = cache_bytes
        self._cache: dict[int, Column] = {}
        self._cached_bytes = 0
        self._spill = ColumnSpill()
        self._lock = threading.Lock()
        self._pool: ThreadPoolExecutor | None = None
        self.rays_cast = 0
        self.columns_computed = 0
        # Row sums sum_p F_jp over the columns computed so far (for the error bound).
        self._row_sum = np.zeros(mesh.receiver_count)
        self._summed: set[int] = set()
        self.max_row_sum = 0.0
        self._row_scale: np.ndarray | None = None
        self._col_scale = np.ones(mesh.patch_count)
        self._final_rows: np.ndarray | None = None
        #: Receivers that see no opening (set by :meth:`balance`).
        self.closed_rows: np.ndarray | None = None
        #: Patches balancing could not hold to deliver what they shoot (``short_columns``).
        self.short_patches = np.zeros(mesh.patch_count, dtype=bool)
        #: Every column computed and balanced (set by :meth:`balance`).
        self.complete = False
        diag = scene_diagonal(mesh.positions)
        self.diagonal = diag
        self._points, self._origins = receiver_points(mesh, tol.ray_offset * diag)
        #: each receiver's height along its normal (its horizon plane's offset) [m]
        self._levels = np.einsum("ij,ij->i", mesh.receiver_normal, self._points)
        self.cull = cull
        self._pairs = (
            PairFactors(mesh, occluder, diag, cull) if pairs is None else pairs.refined(mesh)
        )
        self._receiver_sides: np.ndarray | None = None
        #: Column receiver indices: int32 while they fit (a third less memory per entry).
        self._index = np.int32 if mesh.receiver_count < 2**31 else np.int64
        self._sides_lock = threading.Lock()

    @property
    def _sides(self) -> np.ndarray | None:
        """Packed facet side bits of the receivers' ray origins (once; None unculled)."""
        if self._pairs.facets is None:
            return None
        with self._sides_lock:
            if self._receiver_sides is None:
                self._receiver_sides = self._pairs.sides(self._origins)
        return self._receiver_sides

    @property
    def rays_naive(self) -> int:
        """Rays a vertex-to-patch caster without culling would cast: (receiver, patch)
        pairs that see each other x the patch's sample points."""
        return self._pairs.naive_rays

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None
        self._spill.close()

    def release_columns(self) -> None:
        """Drop the cached and spilled columns once the solve is done with them (a render
        then refines and writes without ``--cache-mb`` of them; a later :meth:`column`
        computes one again). A pass cut short keeps them for its checkpoint."""
        if not self.complete:
            return
        self._cache.clear()
        self._cached_bytes = 0
        self._spill.close()
        return_freed_memory()

    @property
    def columns_spilled(self) -> int:
        """Columns written to spill files beyond the cache (still counted once freed)."""
        return self._spill.spilled_columns

    @property
    def held_bytes(self) -> int:
        """Bytes of the columns held, cached and spilled: what a checkpoint writes [B]."""
        return self._cached_bytes + self._spill.bytes

    def column(self, patch: int) -> Column:
        """F(receiver <- patch) for every receiver that can see it (balanced, see
        :meth:`balance`, once that has run), in float64."""
        col = self.raw_column(patch)
        rows, scale = self.column_scales(patch)
        factors = col.factors * (rows[col.receivers] * scale) if rows is not None else col.factors
        return Column(col.receivers, factors.astype(np.float64, copy=False), col.rays, col.gather)

    def column_scales(self, patch: int) -> tuple[np.ndarray | None, float]:
        """Balancing's (R,) row scales (None before :meth:`balance`) and the column scale
        of ``patch``: :meth:`column` is ``raw * (rows[receivers] * scale)``."""
        if self._row_scale is None:
            return None, 1.0
        return self._row_scale, float(self._col_scale[patch])

    @property
    def subarea_means(self) -> SubareaMeans:
        """The mesh's sub-area means, the near-field gather's sources beyond its receivers."""
        return self._pairs.subarea_means

    def near_field(self) -> list[tuple[int, np.ndarray, GatherWeights]]:
        """(patch, balanced factors to its near receivers, gather weights) of every patch
        with near receivers among the columns computed so far (see
        :mod:`raytrad.core.gather`): from the cache or the spill files, or computed again
        where a spill file could not be written."""
        out = []
        for patch in sorted(self._summed):
            gather = self.raw_column(patch).gather
            if not len(gather.receivers):
                continue
            factors = gather.factors
            if self._row_scale is not None:
                factors = factors * self._row_scale[gather.receivers] * self._col_scale[patch]
            out.append((patch, factors, gather))
        return out

    def raw_column(self, patch: int, mapped: bool = False) -> Column:
        """F(receiver <- patch) before balancing (float32; see :meth:`column_scales`);
        ``mapped``: a spilled one maps its file (:meth:`ColumnSpill.read`)."""
        known = self._known(patch, mapped)
        if known is not None:
            return known
        return self._store(patch, self._compute(patch))

    def _known(self, patch: int, mapped: bool = False) -> Column | None:
        """The column of ``patch`` from the cache or the spill files, or None."""
        cached = self._cache.get(patch)
        return cached if cached is not None else self._spill.read(patch, mapped)

    def _known_factors(self, patch: int) -> tuple[np.ndarray, np.ndarray]:
        """(receivers, raw factors) of a computed column, without its gather weights."""
        cached = self._cache.get(patch)
        if cached is not None:
            return cached.receivers, cached.factors
        spilled = self._spill.read_factors(patch)
        if spilled is not None:
            return spilled
        col = self.raw_column(patch)  # computed again: its spill file failed
        return col.receivers, col.factors

    def _store(self, patch: int, col: Column) -> Column:
        """Count, sum and (while it fits) cache a newly computed column."""
        self.columns_computed += 1
        self.rays_cast += col.rays
        if patch not in self._summed:
            self._summed.add(patch)
            self._row_sum[col.receivers] += col.factors
            if len(col.receivers) and self._row_scale is None:
                self.max_row_sum = max(self.max_row_sum, float(self._row_sum[col.receivers].max()))
        size = col.nbytes
        if self._cached_bytes + size <= self.cache_bytes:
            self._cache[patch] = col
            self._cached_bytes += size
        elif self.cache_bytes > 0:  # spill it, to read back instead of tracing again
            self._spill.write(patch, col)
        return col

    def pass_columns(self) -> dict[str, np.ndarray]:
        """A cut pass's columns, packed flat for a checkpoint (:meth:`restore_columns` reads
        them back); empty once every column is computed. The columns are kept."""
        return {} if self.complete else pack_columns(list(self.pass_column_parts()))

    def pass_column_parts(self, every: bool = False) -> Iterator[dict[str, np.ndarray]]:
        """:meth:`pass_columns` a column at a time (:func:`~raytrad.core.columns.column_parts`),
        a spilled one read back only while it is handed on: what a checkpoint streams to
        disk without holding every column at once. Nothing once every column is computed,
        unless ``every`` (a solve cut short: its resume goes on shooting without a pass;
        before :meth:`release_columns`)."""
        if self.complete and not every:
            return
        for patch in self.pass_order().tolist():
            if patch in self._cache or patch in self._spill:
                yield column_parts(patch, self.raw_column(patch))

    def restore_columns(self, packed: Mapping[str, Any]) -> int:
        """Cache the columns :meth:`pass_columns` packed (a resumed pass computes only the
        others), one at a time (those beyond the cache spilled as they come), and return
        how many; their rays (the earlier run's) are not counted again."""
        count = 0
        for patch, col in unpack_columns(packed, self._index):
            self._store(patch, col)
            count += 1
        return count

    def raw_columns(self, patches: Iterable[int]) -> Generator[tuple[int, Column], None, None]:
        """(patch, column before balancing) for ``patches`` in order, the missing ones
        computed a patch per thread on every core."""
        patches = list(patches)
        todo = [p for p in patches if p not in self._cache and p not in self._spill]
        done = self._per_patch(self._compute, todo, bounded=True)
        try:
            for patch in patches:
                known = self._known(patch)
                yield patch, known if known is not None else self._store(patch, next(done))
        finally:
            done.close()

    def _per_patch(
        self, work: Callable[[int], _T], patches: list[int], bounded: bool = False
    ) -> Generator[_T, None, None]:
        """``work(patch)`` for each patch, in order, on every core; each patch's chunks
        then run in its own thread. ``bounded`` (the pass's columns): at most
        :data:`AHEAD_PER_WORKER` a worker run ahead of the one taken, so that they do not
        pile up in memory while the caller is busy (a checkpoint written); unbounded, a
        slow patch never leaves a core idle behind it."""
        if worker_count() == 1 or len(patches) < 2:
            yield from map(work, patches)
            return

        def task(patch: int) -> _T:
            _WORKER.active = True
            try:
                return work(patch)
            finally:
                _WORKER.active = False

        if not bounded:
            yield from self._executor().map(task, patches)
            return
        yield from ordered_map(self._executor(), task, patches, AHEAD_PER_WORKER * worker_count())

    def _executor(self) -> ThreadPoolExecutor:
        with self._lock:
            if self._pool is None:
                self._pool = ThreadPoolExecutor(worker_count(), thread_name_prefix="raytrad-ff")
            return self._pool

    def balance(
        self,
        closed: np.ndarray | None,
        progress: Callable[[int, int], None] | None = None,
        iterations: int = BALANCE_ITERATIONS,
        stop: Callable[[], bool] | None = None,
    ) -> dict[str, float | bool | str]:
        """Rescale the form factors so that they conserve energy exactly.

        Two physical constraints the sampled vertex-to-patch factors miss:

        * a receiver whose whole hemisphere is covered by front faces (``closed``) has
          ``sum_p F_jp = 1``;
        * a patch delivers what it shoots, ``g_p = sum_j a_j F_jp / A_p``: exactly 1 when
          every receiver of the patch is closed (its light has nowhere else to go; unless
          that takes scaling its factors up by more than ``COLUMN_SCALE_LIMIT``), at most 1
          otherwise.

        At reflectance 0.999 a 0.1% row miss is 100% of radiosity (the
        furnace error is about rho delta / (1 - rho)), and a patch with rho g_p > 1
        creates energy each time it shoots. This computes every column once (they stay
        cached for the solve) and scales rows and columns alternately
        (:func:`~raytrad.core.balance.sinkhorn`: ``F'_jp = r_j F_jp c_p``), then the closed
        rows once more, so that they sum to 1 to rounding whatever the columns reached: a
        closed scene then conserves energy at any mesh size (B = E / (1 - rho) in a closed
        box of uniform E and rho). Rows off by more than :data:`ROW_FIX_LIMIT` are left
        alone: that is a modelling problem, not sampling error.

        Parameters
        ----------
        closed : (R,) bool or None
            Receivers that see no opening; None (a scene where nothing occludes, so the
            factors are exact) takes rows already summing to 1 within :data:`EXACT_ROW_SUM`.
        progress : callable or None
            ``progress(done, total)`` while columns are computed (columns restored from a
            checkpoint are not counted).
        iterations : int
            Most row-and-column rounds.
        stop : callable or None
            Polled after each column (a time budget spent, Ctrl-C): True ends the pass
            early. The columns are computed emitters first, then by the power a patch can
            reflect (area x reflectance), so that a shortened pass has the ones the first
            shots need; the rest are computed when a shot needs them, and nothing is
            balanced (``complete`` is False).

        Returns
        -------
        dict (:meth:`~raytrad.core.balance.Balanced.summary`) with ``complete`` (every
        column computed and balanced).
        """
        mesh = self.mesh
        total = mesh.patch_count
        held: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # neither cached nor spilled
        order = self.pass_order()
        known = sum(1 for p in order.tolist() if p in self._cache or p in self._spill)
        computed = self.raw_columns(order)
        for done, (patch, col) in enumerate(computed, start=1):
            if patch not in self._cache and patch not in self._spill:
                held[patch] = (col.receivers, col.factors)  # balancing needs no gather
            if progress is not None and done > known:  # columns restored take no time
                progress(done - known, total - known)
            if done < total and stop is not None and stop():
                computed.close()  # cancels the columns not started
                log.warning(
                    "form-factor pass stopped after %d of %d columns (time limit or "
                    "interrupt): the factors are not balanced; the rest are computed on "
                    "--resume, or as shots need them",
                    done,
                    total,
                )
                return _UNBALANCED | {"complete": False}
        return self._balance(held, closed, iterations)

    def pass_order(self) -> np.ndarray:
        """Patches by the order the form-factor pass computes them: emitters first, then
        by area x mean reflectance (what a shortened pass should have)."""
        m = self.mesh
        power = m.patch_area * m.patch_reflectance.mean(axis=1)
        return np.lexsort((np.arange(m.patch_count), -power, ~m.patch_emits()))

    def _balance(
        self,
        held: dict[int, tuple[np.ndarray, np.ndarray]],
        closed: np.ndarray | None,
        iterations: int,
    ) -> dict[str, float | bool | str]:
        mesh = self.mesh
        sums = self._row_sum.copy()
        if closed is None:
            closed = np.abs(sums - 1.0) < EXACT_ROW_SUM
        fix_rows = closed & (np.abs(sums - 1.0) < ROW_FIX_LIMIT) & (sums > 0)
        closed_patch = closed_patches(mesh, fix_rows)

        def columns() -> Iterator[tuple[int, np.ndarray, np.ndarray]]:
            # a column at a time: cached, held, or read back from its spill file
            for patch in range(mesh.patch_count):
                factors = held[patch] if patch in held else self._known_factors(patch)
                yield (patch, *factors)

        found = balance_streamed(
            columns, mesh.receiver_area, mesh.patch_area, fix_rows, closed_patch, iterations
        )
        short = found.short(closed_patch)
        self.restore_balance(
            {"row_scale": found.row_scale, "column_scale": found.column_scale}
            | {"row_sums": found.row_sums, "closed_rows": closed, "short_patches": short}
        )
        return found.summary(sums, fix_rows, closed_patch, mesh.patch_area)

    def balanced_scales(self) -> dict[str, np.ndarray]:
        """What :meth:`balance` found, as arrays for a checkpoint ({} before it): the (R,)
        ``row_scale``, ``row_sums`` and ``closed_rows`` and the (P,) ``column_scale`` and
        ``short_patches``. An engine given them by :meth:`restore_balance` shoots, gathers
        and refines as this one does, without a pass."""
        arrays = (self._row_scale, self._final_rows, self.closed_rows, self._col_scale)
        if not self.complete or any(a is None for a in arrays):
            return {}
        names = ("row_scale", "row_sums", "closed_rows", "column_scale")
        found = {n: a for n, a in zip(names, arrays, strict=True) if a is not None}
        return found | {"short_patches": self.short_patches}

    def restore_balance(self, scales: Mapping[str, np.ndarray]) -> None:
        """Take balancing's result (:meth:`balanced_scales`) instead of a pass: the engine
        is complete, and computes a column only when one is asked for, balanced by these.

        Raises
        ------
        KeyError, ValueError
            An array is missing, or of another mesh's size.
        """
        counts = (self.mesh.receiver_count, self.mesh.patch_count)
        arrays = {name: np.asarray(scales[name]) for name in BALANCED_SCALES}
        if any(arrays[n].shape != (counts[k],) for n, k in BALANCED_SCALES.items()):
            raise ValueError("the balanced scales are of another mesh")
        self._row_scale = arrays["row_scale"].astype(np.float64)
        self._col_scale = arrays["column_scale"].astype(np.float64)
        self._final_rows = arrays["row_sums"].astype(np.float64)
        self.closed_rows = arrays["closed_rows"].astype(bool)
        self.short_patches = arrays["short_patches"].astype(bool)
        self.max_row_sum = float(self._final_rows.max(initial=0.0))
        self.complete = True

    def row_sums(self) -> np.ndarray:
        """(R,) sum_p F_jp of the balanced factors (the raw ones before :meth:`balance`)."""
        return np.array(self._row_sum if self._final_rows is None else self._final_rows)

    def _candidates(
        self,
        patch: int,
        x: np.ndarray | None = None,
        nx: np.ndarray | None = None,
        levels: np.ndarray | None = None,
    ) -> np.ndarray:
        """Receivers (or points ``x`` with normals ``nx``, ``levels`` their heights along
        them if known) that may exchange light with ``patch`` (cheap, conservative)."""
        m = self.mesh
        if x is None or nx is None:
            x, nx, levels = self._points, m.receiver_normal, self._levels
        elif levels is None:
            levels = np.einsum("ij,ij->i", nx, x)
        center, radius = m.patch_center[patch], m.patch_radius[patch]
        band = tol.horizon * self.diagonal
        facing = (nx @ center - levels) > -radius
        if m.patch_planar[patch]:
            normal = m.patch_normal[patch]
            facing &= (x - center) @ normal > band
        return np.nonzero(facing)[0]

    def _compute(self, patch: int) -> Column:
        candidates = self._candidates(patch)  # np.take: rows at a sixth of indexing's cost
        factors, rays, gather = self._factors(
            np.take(self._points, candidates, axis=0),
            np.take(self.mesh.receiver_normal, candidates, axis=0),
            np.take(self._origins, candidates, axis=0),
            patch,
            None if self._sides is None else np.take(self._sides, candidates, axis=0),
        )
        keep = factors > 0
        gather = gather.subset(keep[gather.receivers])
        gather = compact_gather(
            GatherWeights(
                candidates[gather.receivers],
                factors[gather.receivers],
                gather.pointer,
                gather.sources,
                gather.weights,
            ),
            self._index,
        )
        return Column(
            candidates[keep].astype(self._index), factors[keep].astype(np.float32), rays, gather
        )

    def refined(self, mesh: RadiosityMesh) -> FormFactorEngine:
        """An engine on a refinement of this one's mesh (the same patches and sub-areas,
        finer triangles and more receivers), with this one's balanced column scales, for
        gathering at new receivers (:meth:`gather_rows`). It caches no column."""
        engine = FormFactorEngine(
            mesh, self.occluder, cache_bytes=0, cull=self.cull, pairs=self._pairs
        )
        engine._col_scale = self._col_scale.copy()
        return engine

    @overload
    def gather_rows(self, points: np.ndarray, normals: np.ndarray) -> GatherRows: ...
    @overload
    def gather_rows(
        self, points: np.ndarray, normals: np.ndarray, stop: Callable[[], bool] | None
    ) -> GatherRows | None: ...
    def gather_rows(
        self, points: np.ndarray, normals: np.ndarray, stop: Callable[[], bool] | None = None
    ) -> GatherRows | None:
        """The balanced factors and near-field weights of new points to every patch, kept
        to gather from several radiosities (:func:`gathered_irradiance`) without tracing
        again; None when ``stop``, polled after each patch, says stop (the rest cancelled).

        The points are taken in Morton order (:func:`~raytrad.arrays.morton_order`), as
        the mesh numbers its receivers, so that a chunk's points and rays lie in one part
        of the scene; the rows index the points as given."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
        order = morton_order(points)
        points, normals = points[order], normals[order]
        origins = points + tol.ray_offset * self.diagonal * normals
        sides = self._pairs.sides(origins)
        levels = np.einsum("ij,ij->i", normals, points)
        rows = GatherRows(len(points), np.zeros(len(points)), [], self.subarea_means)

        def work(patch: int) -> tuple[np.ndarray, np.ndarray, int, GatherWeights]:
            near = self._candidates(patch, points, normals, levels)
            part = None if sides is None else np.take(sides, near, axis=0)
            x, nx, o = (np.take(a, near, axis=0) for a in (points, normals, origins))
            found = self._factors(x, nx, o, patch, part)
            return order[near], found[0], found[1], compact_gather(found[2], self._index)

        patches = list(range(self.mesh.patch_count))
        done = self._per_patch(work, patches)
        try:
            for patch, (near, factors, rays, gather) in zip(patches, done, strict=True):
                self.rays_cast += rays
                rows.add(patch, near, factors, gather, self._col_scale[patch])
                stages.report(stages.FINAL_GATHER, patch + 1, len(patches))
                if stop is not None and stop():
                    return None
        finally:
            done.close()
        return rows

    def factors_at(self, points: np.ndarray, normals: np.ndarray, patch: int) -> np.ndarray:
        """F(point <- patch) for arbitrary receiver points, before balancing.

        Parameters
        ----------
        points : (N, 3) float64
            Receiver positions [m].
        normals : (N, 3) float64
            Receiver unit normals.
        patch : int

        Returns
        -------
        (N,) float64 form factors [1]; rays start ``tol.ray_offset`` x diagonal off them.
        """
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
        origins = points + tol.ray_offset * self.diagonal * normals
        return self._factors(points, normals, origins, patch, self._pairs.sides(origins))[0]

    def _factors(
        self,
        x: np.ndarray,
        nx: np.ndarray,
        origins: np.ndarray,
        patch: int,
        sides: np.ndarray | None,
    ) -> tuple[np.ndarray, int, GatherWeights]:
        if len(x) == 0:
            return np.zeros(0), 0, EMPTY
        per_chunk = self._pairs.chunk_size(patch)
        bounds = [*range(0, len(x), per_chunk), len(x)]
        spans = list(itertools.pairwise(bounds))

        def work(span: tuple[int, int]) -> tuple[np.ndarray, int, GatherWeights]:
            a, b = span
            part = None if sides is None else sides[a:b]
            return self._pairs.chunk(x[a:b], nx[a:b], origins[a:b], patch, part)

        if len(spans) == 1 or worker_count() == 1 or _WORKER.active:
            parts = [work(s) for s in spans]
        else:
            parts = list(self._executor().map(work, spans))
        return (
            np.concatenate([p[0] for p in parts]),
            sum(p[1] for p in parts),
            join_gathers([p[2] for p in parts], [a for a, _ in spans]),
        )
