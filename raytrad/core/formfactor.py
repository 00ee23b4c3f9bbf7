"""Vertex-to-patch form factors (Wallace, Elmquist and Haines 1989), ray-traced.

The form factor from receiver point x (normal n_x) to a patch split into sub-areas k of
area dA_k with fixed sample points y_k (normal n_k) is::

    F(x <- patch) = sum_k V(x, y_k) * cos(theta_x) * cos(theta_k) * dA_k / (pi r^2 + dA_k)

(the disk approximation of Wallace et al.). It is accurate while a sub-area is small
against its distance; it underestimates near, oblique receivers. So a sub-area closer than
:data:`NEAR_FACTOR` times its size is evaluated exactly instead: each of its triangles gets
the closed-form Lambert point-to-polygon factor, clipped to the receiver's horizon, times
the visibility of the triangle's centroid. Near and far receivers therefore both get the
unoccluded factor to within a fraction of a percent, at a cost that stays bounded.

Pairs that cannot exchange light (receiver behind the patch, patch below the receiver's
horizon) cost no ray.
"""

from __future__ import annotations

import itertools
import logging
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from raytrad.constants import scene_diagonal, tol
from raytrad.core.balance import BALANCE_ITERATIONS, Sparse, closed_patches, sinkhorn
from raytrad.core.gather import (
    EMPTY,
    GATHER_RADII,
    GatherRows,
    GatherShares,
    GatherWeights,
    gathered_irradiance,
    join_gathers,
)
from raytrad.core.kernels import (
    contour_form_factor,
    disk_form_factor,
    linear_corner_shares,
    polygon_form_factor,
    visible_centroid,
)
from raytrad.core.mesh import RadiosityMesh
from raytrad.core.outline import boundary_edges, group, patch_vertices
from raytrad.core.visibility import Occluder, worker_count

log = logging.getLogger(__name__)

#: A sub-area nearer than this multiple of its bounding-box diagonal has its visibility
#: sampled triangle by triangle, weighted by exact factors.
NEAR_FACTOR = 2.0
#: A near triangle closer than this many of its sizes to a receiver spreads its gather
#: weight over its corners by what the receiver sees of each part of it
#: (:func:`~raytrad.core.kernels.linear_corner_shares`, split 3 times within one size,
#: twice beyond), not equally.
SHARE_SIZES = 3.0
#: Receiver-sample pairs per work chunk (bounds memory whatever the receiver count).
PAIRS_PER_CHUNK = 1 << 15
#: Largest relative miss of a closed receiver's row sum that balancing treats as sampling
#: error; beyond it the row is a modelling problem and left alone.
ROW_FIX_LIMIT = 0.25
#: Row sums of an occlusion-free scene within this of 1 count as closed (exact factors).
EXACT_ROW_SUM = 1e-6


# --------------------------------------------------------------------------------------
# Columns of the receiver-by-patch matrix
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Column:
    """Form factors from every receiver to one patch.

    Attributes
    ----------
    receivers : (K,) int64
        Receivers with a non-zero factor, ascending.
    factors : (K,) float64
        F(receiver <- patch) [1].
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
        """Memory the column holds [bytes]."""
        return int(self.receivers.nbytes + self.factors.nbytes + self.gather.nbytes + 64)


class FormFactorEngine:
    """Computes (and caches) columns F(all receivers <- patch).

    Parameters
    ----------
    mesh : RadiosityMesh
    occluder : Occluder or None
        None when nothing in the scene can block light (a convex enclosure): no rays.
    cache_bytes : int
        Memory for cached columns; a column is computed once and reused while it fits.
    """

    def __init__(
        self, mesh: RadiosityMesh, occluder: Occluder | None, cache_bytes: int = 1 << 30
    ) -> None:
        self.mesh = mesh
        self.occluder = occluder
        self.cache_bytes = cache_bytes
        self._cache: dict[int, Column] = {}
        self._cached_bytes = 0
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
        diag = scene_diagonal(mesh.positions)
        self.diagonal = diag
        self._points, self._origins = receiver_points(mesh, tol.ray_offset * diag)
        order = np.lexsort((np.arange(len(mesh.triangle_subarea)), mesh.triangle_subarea))
        self._sub_tri = order
        self._sub_ptr = np.searchsorted(
            mesh.triangle_subarea[order], np.arange(mesh.subarea_count + 1)
        )
        self._tri_corners = mesh.positions[mesh.triangles]
        # Ray targets sit tol.ray_offset off their surface on its lit side: a ray ending a
        # margin short of a point *on* the surface would, at grazing angles, end closer to
        # the surface than float32 resolves, and hit the very surface it aims at.
        self._sub_target = mesh.subarea_point + tol.ray_offset * diag * mesh.subarea_normal
        self._patch_tri, self._patch_tri_ptr = group(mesh.triangle_patch, mesh.patch_count)
        self._vert_index, self._vert_ptr = patch_vertices(mesh)
        self._edge_start, self._edge_end, self._edge_ptr = boundary_edges(mesh)
        self._shares = GatherShares(mesh, self._sub_tri, self._sub_ptr)
        self._gathers: dict[int, GatherWeights] = {}  # kept even when columns are not

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None

    def column(self, patch: int) -> Column:
        """F(receiver <- patch) for every receiver that can see it (balanced, see
        :meth:`balance`, once that has run)."""
        col = self._raw_column(patch)
        if self._row_scale is None:
            return col
        scale = self._row_scale[col.receivers] * self._col_scale[patch]
        return Column(col.receivers, col.factors * scale, col.rays, col.gather)

    def near_field(self) -> list[tuple[int, np.ndarray, GatherWeights]]:
        """(patch, balanced factors to its near receivers, gather weights) of every patch
        with near receivers among the columns computed so far (see
        :mod:`raytrad.core.gather`)."""
        out = []
        for patch, gather in sorted(self._gathers.items()):
            factors = gather.factors
            if self._row_scale is not None:
                factors = factors * self._row_scale[gather.receivers] * self._col_scale[patch]
            out.append((patch, factors, gather))
        return out

    def _raw_column(self, patch: int) -> Column:
        cached = self._cache.get(patch)
        if cached is not None:
            return cached
        col = self._compute(patch)
        self.columns_computed += 1
        self.rays_cast += col.rays
        if len(col.gather.receivers):
            self._gathers[patch] = col.gather
        if patch not in self._summed:
            self._summed.add(patch)
            self._row_sum[col.receivers] += col.factors
            if len(col.receivers) and self._row_scale is None:
                self.max_row_sum = max(self.max_row_sum, float(self._row_sum[col.receivers].max()))
        size = col.nbytes
        if self._cached_bytes + size <= self.cache_bytes:
            self._cache[patch] = col
            self._cached_bytes += size
        return col

    def balance(
        self,
        closed: np.ndarray | None,
        progress: Callable[[int, int], None] | None = None,
        iterations: int = BALANCE_ITERATIONS,
    ) -> dict[str, float]:
        """Rescale the form factors so that they conserve energy exactly.

        Two physical constraints the sampled vertex-to-patch factors miss:

        * a receiver whose whole hemisphere is covered by front faces (``closed``) has
          ``sum_p F_jp = 1``;
        * a patch delivers what it shoots, ``g_p = sum_j a_j F_jp / A_p``: exactly 1 when
          every receiver of the patch is closed (its light has nowhere else to go), at
          most 1 otherwise.

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
            ``progress(done, total)`` while columns are computed.
        iterations : int
            Most row-and-column rounds.

        Returns
        -------
        dict with ``closed_rows`` (rows held to 1), ``closed_columns`` (patches held to
        g = 1), ``capped_columns`` (other patches scaled down to g = 1), ``row_error`` and
        ``capture_excess`` (largest deviations before balancing), ``column_excess``
        (largest g - 1 after it) and ``iterations``.
        """
        mesh = self.mesh
        total = mesh.patch_count
        columns = []
        for patch in range(total):
            columns.append(self._raw_column(patch))
            if progress is not None:
                progress(patch + 1, total)
        sums = self._row_sum.copy()
        if closed is None:
            closed = np.abs(sums - 1.0) < EXACT_ROW_SUM
        fix_rows = closed & (np.abs(sums - 1.0) < ROW_FIX_LIMIT) & (sums > 0)
        lengths = np.array([len(c.receivers) for c in columns])
        rows = np.concatenate([c.receivers for c in columns]) if total else np.zeros(0, int)
        values = np.concatenate([c.factors for c in columns]) if total else np.zeros(0)
        owner = np.repeat(np.arange(total), lengths)
        area = mesh.receiver_area[rows]
        closed_patch = closed_patches(mesh, fix_rows)
        capture0 = np.bincount(owner, weights=area * values, minlength=total) / mesh.patch_area
        row_scale, col_scale, done = sinkhorn(
            Sparse(rows, owner, values, mesh.receiver_count, total),
            area,
            mesh.patch_area,
            fix_rows,
            closed_patch,
            iterations,
        )
        self._row_scale = row_scale
        self._col_scale = col_scale
        final = values * col_scale[owner] * row_scale[rows]
        self._final_rows = np.bincount(rows, weights=final, minlength=mesh.receiver_count)
        self.closed_rows = np.asarray(closed, dtype=bool)
        self.max_row_sum = float(self._final_rows.max(initial=0.0))
        capture = np.bincount(owner, weights=area * final, minlength=total) / mesh.patch_area
        return {
            "closed_rows": int(fix_rows.sum()),
            "closed_columns": int(closed_patch.sum()),
            "capped_columns": int(((col_scale < 1.0) & ~closed_patch).sum()),
            "row_error": float(np.abs(sums[fix_rows] - 1.0).max(initial=0.0)),
            "capture_excess": float(max(0.0, capture0.max(initial=0.0) - 1.0)),
            "column_excess": float(max(0.0, capture.max(initial=0.0) - 1.0)),
            "iterations": done,
        }

    def row_sums(self) -> np.ndarray:
        """(R,) sum_p F_jp of the balanced factors (the raw ones before :meth:`balance`)."""
        return np.array(self._row_sum if self._final_rows is None else self._final_rows)

    def _candidates(
        self, patch: int, x: np.ndarray | None = None, nx: np.ndarray | None = None
    ) -> np.ndarray:
        """Receivers (or points ``x`` with normals ``nx``) that may exchange light with
        ``patch`` (cheap conservative culling)."""
        m = self.mesh
        if x is None or nx is None:
            x, nx = self._points, m.receiver_normal
        center, radius = m.patch_center[patch], m.patch_radius[patch]
        band = tol.horizon * self.diagonal
        facing = (nx @ center - np.einsum("ij,ij->i", nx, x)) > -radius
        if m.patch_planar[patch]:
            normal = m.patch_normal[patch]
            facing &= (x - center) @ normal > band
        return np.nonzero(facing)[0]

    def _compute(self, patch: int) -> Column:
        candidates = self._candidates(patch)
        factors, rays, gather = self._factors(
            self._points[candidates],
            self.mesh.receiver_normal[candidates],
            self._origins[candidates],
            patch,
        )
        keep = factors > 0
        gather = gather.subset(keep[gather.receivers])
        gather = GatherWeights(
            candidates[gather.receivers],
            factors[gather.receivers],
            gather.pointer,
            gather.sources,
            gather.weights,
        )
        return Column(candidates[keep], factors[keep], rays, gather)

    def refined(self, mesh: RadiosityMesh) -> FormFactorEngine:
        """An engine on a refinement of this one's mesh (the same patches and sub-areas,
        finer triangles and more receivers), with this one's balanced column scales, for
        gathering at new receivers (:meth:`gather_at`). It caches no column."""
        engine = FormFactorEngine(mesh, self.occluder, cache_bytes=0)
        engine._col_scale = self._col_scale.copy()
        return engine

    def gather_at(
        self,
        points: np.ndarray,
        normals: np.ndarray,
        radiosity: np.ndarray,
        patch_radiosity: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Irradiance at new points gathered from a solution: a final gather.

        ``H(x) = sum_p F(x <- p) (B̄_p + [B̃_xp - B̄_p])`` with the balanced column scales,
        the near-field bracket where ``x`` is near ``p`` (:mod:`raytrad.core.gather`).
        Equal to ``gathered_irradiance(gather_rows(points, normals), ...)``.

        Parameters
        ----------
        points : (N, 3) float64
            Where to evaluate [m] (receiver evaluation points, see :func:`receiver_points`).
        normals : (N, 3) float64
            Unit normals.
        radiosity : (R, 3) float64
            The solution at this engine's receivers [W m-2].
        patch_radiosity : (P, 3) float64
            Its patch means [W m-2].

        Returns
        -------
        irradiance : (N, 3) float64 [W m-2]
        row_sum : (N,) float64, sum_p F(x <- p) [1] (before any row scaling)
        """
        rows = self.gather_rows(points, normals)
        return gathered_irradiance(rows, radiosity, patch_radiosity), rows.row_sum

    def gather_rows(self, points: np.ndarray, normals: np.ndarray) -> GatherRows:
        """The balanced factors and near-field weights of new points to every patch, kept
        to gather from several radiosities (:func:`~raytrad.core.gather.gathered_irradiance`)
        without tracing again."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
        origins = points + tol.ray_offset * self.diagonal * normals
        rows = GatherRows(len(points), np.zeros(len(points)), [])
        for patch in range(self.mesh.patch_count):
            near = self._candidates(patch, points, normals)
            factors, rays, gather = self._factors(points[near], normals[near], origins[near], patch)
            self.rays_cast += rays
            factors = factors * self._col_scale[patch]
            rows.row_sum[near] += factors
            rows.patches.append((patch, near, factors, gather))
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
        (N,) float64 form factors [1]; rays start ``tol.ray_offset`` x the scene diagonal
        along the normal.
        """
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
        origins = points + tol.ray_offset * self.diagonal * normals
        return self._factors(points, normals, origins, patch)[0]

    def _factors(
        self, x: np.ndarray, nx: np.ndarray, origins: np.ndarray, patch: int
    ) -> tuple[np.ndarray, int, GatherWeights]:
        if len(x) == 0:
            return np.zeros(0), 0, EMPTY
        n_sub = max(1, self.mesh.patch_subareas(patch).stop - self.mesh.patch_subareas(patch).start)
        per_chunk = max(1, PAIRS_PER_CHUNK // max(n_sub, self._edge_count(patch)))
        bounds = [*range(0, len(x), per_chunk), len(x)]
        spans = list(itertools.pairwise(bounds))

        def work(span: tuple[int, int]) -> tuple[np.ndarray, int, GatherWeights]:
            a, b = span
            return self._chunk(x[a:b], nx[a:b], origins[a:b], patch)

        if len(spans) == 1 or worker_count() == 1:
            parts = [work(s) for s in spans]
        else:
            if self._pool is None:
                self._pool = ThreadPoolExecutor(worker_count(), thread_name_prefix="raytrad-ff")
            parts = list(self._pool.map(work, spans))
        return (
            np.concatenate([p[0] for p in parts]),
            sum(p[1] for p in parts),
            join_gathers([p[2] for p in parts], [a for a, _ in spans]),
        )

    def _edge_count(self, patch: int) -> int:
        return int(self._edge_ptr[patch + 1] - self._edge_ptr[patch])

    def _chunk(
        self, x: np.ndarray, nx: np.ndarray, origins: np.ndarray, patch: int
    ) -> tuple[np.ndarray, int, GatherWeights]:
        """F(receiver <- patch) for receivers (x, nx) whose rays start at ``origins``, the
        rays cast, and the gather weights of the near receivers (chunk indices).

        The unoccluded factor is exact (:meth:`_unoccluded`); visibility scales it by the
        visible fraction of the patch seen through its sub-area sample points, each weighted
        by its disk-approximation factor, or, for sub-areas nearer than
        :data:`NEAR_FACTOR` sizes, through each of their triangles weighted exactly. Where
        nothing can occlude, samples are taken only for the near receivers' gather weights.
        """
        m = self.mesh
        unoccluded = self._unoccluded(x, nx, patch)
        sees = unoccluded > 0
        distance = np.linalg.norm(x - m.patch_center[patch], axis=1)
        close = sees & (distance < GATHER_RADII * m.patch_radius[patch])
        if self.occluder is None:
            if not close.any():
                return unoccluded, 0, EMPTY
            sees = close
        sub = m.patch_subareas(patch)
        weight, far_c, far_s, near_c, near_tri, near_target, near_w, near_share = self._samples(
            x, nx, sees, sub
        )
        who = np.concatenate([far_c, near_c])
        blocked = np.zeros(len(who), dtype=bool)
        factors = unoccluded
        if self.occluder is not None:
            targets = np.concatenate([self._sub_target[sub][far_s], near_target])
            blocked = self._blocked(origins[who], targets)
            total = weight.sum(axis=1) + np.bincount(near_c, weights=near_w, minlength=len(x))
            hidden = np.bincount(
                who,
                weights=np.concatenate([weight[far_c, far_s], near_w]) * blocked,
                minlength=len(x),
            )
            visible = np.where(total > 0, 1.0 - hidden / np.where(total > 0, total, 1.0), 0.0)
            factors = unoccluded * np.clip(visible, 0.0, 1.0)
        seen = ~blocked
        far_seen, near_seen = seen[: len(far_c)], seen[len(far_c) :]
        pair = np.cumsum(close) - 1
        f, n = close[far_c] & far_seen, close[near_c] & near_seen
        pointer, sources, shares = self._shares.spread(
            pair[far_c[f]],
            far_s[f] + sub.start,
            weight[far_c[f], far_s[f]],
            pair[near_c[n]],
            near_tri[n],
            near_w[n],
            near_share[n],
            int(close.sum()),
        )
        near = np.flatnonzero(close)
        gather = GatherWeights(near, factors[near], pointer, sources, shares)
        keep = np.diff(pointer) > 0  # a near receiver that sees none of the patch gathers nothing
        return factors, len(who) if self.occluder is not None else 0, gather.subset(keep)

    def _samples(
        self, x: np.ndarray, nx: np.ndarray, sees: np.ndarray, sub: slice
    ) -> tuple[np.ndarray, ...]:
        """The weighted visibility samples of the receivers that see the patch.

        Returns
        -------
        weight : (C, S) float64, disk factors of far samples (0 elsewhere)
        far_c, far_s : (A,) int64, chunk receiver and patch-local sub-area of far samples
        near_c, near_tri, near_target, near_w, near_share : (B,), (B,), (B, 3), (B,),
            (B, 3), chunk receiver, triangle, ray target [m], exact factor and corner
            shares of near triangles
        """
        m = self.mesh
        y = m.subarea_point[sub]
        d = y[None, :, :] - x[:, None, :]
        r2 = np.einsum("csj,csj->cs", d, d)
        r = np.sqrt(r2)
        inv_r = 1.0 / np.where(r > 0, r, 1.0)
        cos_r = np.einsum("csj,cj->cs", d, nx) * inv_r
        cos_s = -np.einsum("csj,sj->cs", d, m.subarea_normal[sub]) * inv_r
        near = r < NEAR_FACTOR * m.subarea_size[sub][None, :]
        far = ~near & (cos_r > 0) & (cos_s > 0)
        # a receiver that sees part of the patch but none of its sample points is handled
        # triangle by triangle
        near |= (sees & ~far.any(axis=1) & ~near.any(axis=1))[:, None]
        near &= sees[:, None]
        far &= sees[:, None]
        weight = np.where(far, disk_form_factor(cos_r, cos_s, r2, m.subarea_area[sub]), 0.0)
        far_c, far_s = np.nonzero(far)
        near_c, near_tri, near_target, near_w, near_share = self._near_field(x, nx, near, sub)
        return weight, far_c, far_s, near_c, near_tri, near_target, near_w, near_share

    def _unoccluded(self, x: np.ndarray, nx: np.ndarray, patch: int) -> np.ndarray:
        """Exact unoccluded F(receiver <- patch).

        Where a planar patch lies wholly above the receiver's horizon, Lambert's formula is
        a sum over the patch's boundary edges alone (interior edges cancel); otherwise each
        triangle facing the receiver is clipped to the horizon and summed.
        """
        m = self.mesh
        lo, hi = self._vert_ptr[patch], self._vert_ptr[patch + 1]
        verts = m.positions[self._vert_index[lo:hi]]
        height = verts @ nx.T - np.einsum("cj,cj->c", x, nx)[None, :]  # (Vp, C)
        band = tol.horizon * self.diagonal
        top = height.max(axis=0)
        # The boundary-contour sum is exact only for a planar patch: seen from a receiver
        # on a folded patch (a warped quad's two triangles) it would count the fold's own
        # surface as a full hemisphere. Folded patches go triangle by triangle.
        above = (height.min(axis=0) >= -band) & (top > band) & bool(m.patch_planar[patch])
        if m.patch_planar[patch]:  # nothing reaches the back of a one-sided patch
            facing = (x - m.patch_center[patch]) @ m.patch_normal[patch] > band
            above &= facing
            top = np.where(facing, top, -np.inf)
        out = np.zeros(len(x))
        if above.any():
            a, b = self._edge_ptr[patch], self._edge_ptr[patch + 1]
            out[above] = contour_form_factor(
                self._edge_start[a:b], self._edge_end[a:b], x[above], nx[above]
            )
        straddle = ~above & (top > band)
        if straddle.any():
            c = np.nonzero(straddle)[0]
            ta, tb = self._patch_tri_ptr[patch], self._patch_tri_ptr[patch + 1]
            tris = self._patch_tri[ta:tb]
            cc = np.repeat(c, len(tris))
            tt = np.tile(tris, len(c))
            f = self._triangle_factors(x[cc], nx[cc], tt)
            out += np.bincount(cc, weights=f, minlength=len(x))
        return out

    def _triangle_factors(self, x: np.ndarray, nx: np.ndarray, tri: np.ndarray) -> np.ndarray:
        """Exact clipped factors to triangles whose lit side faces the receiver, else 0."""
        corners = self._tri_corners[tri]
        in_front = (
            np.einsum("kj,kj->k", x - corners[:, 0], self.mesh.triangle_normal[tri])
            > tol.horizon * self.diagonal
        )
        f = np.zeros(len(tri))
        if in_front.any():
            f[in_front] = polygon_form_factor(corners[in_front], x[in_front], nx[in_front])
        return f

    def _near_field(
        self, x: np.ndarray, nx: np.ndarray, near: np.ndarray, sub: slice
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Exact per-triangle visibility weights for near (receiver, sub-area) pairs.

        Returns
        -------
        chunk_receiver : (K,) int64, index into the chunk
        triangle : (K,) int64
        target : (K, 3) float64, ray target: the centroid of the part of the triangle above
            the receiver's horizon, lifted off the surface [m]
        weight : (K,) float64, unoccluded exact factors (> 0 only)
        shares : (K, 3) float64, each corner's share of what the receiver sees of the
            triangle (:func:`~raytrad.core.kernels.linear_corner_shares` within
            :data:`SHARE_SIZES` triangle sizes, else 1/3)
        """
        c, s = np.nonzero(near)
        if len(c) == 0:
            empty = np.zeros(0, np.int64)
            return empty, empty, np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3))
        s_global = s + sub.start
        start, stop = self._sub_ptr[s_global], self._sub_ptr[s_global + 1]
        counts = stop - start
        pair = np.repeat(np.arange(len(c)), counts)
        offset = np.arange(len(pair)) - np.repeat(np.cumsum(counts) - counts, counts)
        tri = self._sub_tri[np.repeat(start, counts) + offset]
        cc = c[pair]
        f = self._triangle_factors(x[cc], nx[cc], tri)
        keep = f > 0
        cc, tri = cc[keep], tri[keep]
        corners = self._tri_corners[tri]
        target = visible_centroid(corners, x[cc], nx[cc])
        target += tol.ray_offset * self.diagonal * self.mesh.triangle_normal[tri]
        # within a few of its sizes a receiver sees mostly the near part of a triangle
        shares = np.full((len(tri), 3), 1.0 / 3.0)
        size = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1)
        distance = np.linalg.norm(corners.mean(axis=1) - x[cc], axis=1) / size
        for levels, lo, hi in ((3, 0.0, 1.0), (2, 1.0, SHARE_SIZES)):
            part = (distance >= lo) & (distance < hi)
            if part.any():
                shares[part] = linear_corner_shares(
                    corners[part], x[cc[part]], nx[cc[part]], levels
                )
        return cc, tri, target, f[keep], shares

    def _blocked(self, origins: np.ndarray, targets: np.ndarray) -> np.ndarray:
        assert self.occluder is not None
        delta = targets - origins
        length = np.linalg.norm(delta, axis=1)
        direction = delta / np.where(length > 0, length, 1.0)[:, None]
        reach = np.maximum(length - 0.5 * tol.ray_offset * self.diagonal, 0.0)
        return self.occluder.occluded_local(self.occluder.to_local(origins), direction, reach)


def receiver_points(mesh: RadiosityMesh, offset: float) -> tuple[np.ndarray, np.ndarray]:
    """Where each receiver's factors are evaluated, and where its rays start.

    A receiver on an edge where two surfaces meet (a room corner, a block on the floor)
    lies in the other surface's plane: there the factor to that surface is 0 instead of its
    limit (1/2 for a perpendicular wall) and a ray starting there is called occluded or not
    at Embree's whim. So the evaluation point moves a few ``offset`` into the receiver's own
    triangles (staying in its plane), and rays start from there, ``offset`` along the normal.

    Returns
    -------
    points : (R, 3) float64 [m]
    origins : (R, 3) float64 [m]
    """
    x, n = mesh.receiver_position, mesh.receiver_normal
    inward = mesh.receiver_inward - x
    inward -= np.einsum("ij,ij->i", inward, n)[:, None] * n
    length = np.linalg.norm(inward, axis=1)
    step = np.minimum(4.0 * offset, 0.25 * length)
    direction = inward / np.where(length > 0, length, 1.0)[:, None]
    points = x + step[:, None] * direction
    return points, points + offset * n
