"""Vertex-to-patch form factors (Wallace, Elmquist and Haines 1989), ray-traced.

The form factor from receiver point x (normal n_x) to a patch split into sub-areas k of
area dA_k with fixed sample points y_k (normal n_k) is::

    F(x <- patch) = sum_k V(x, y_k) * cos(theta_x) * cos(theta_k) * dA_k / (pi r^2 + dA_k)

(the disk approximation, REFERENCE.md section 2). It is accurate while a sub-area is small
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
from raytrad.core.kernels import (
    contour_form_factor,
    disk_form_factor,
    polygon_form_factor,
    visible_centroid,
)
from raytrad.core.mesh import RadiosityMesh
from raytrad.core.visibility import Occluder, worker_count

log = logging.getLogger(__name__)

#: A sub-area nearer than this multiple of its bounding-box diagonal has its visibility
#: sampled triangle by triangle, weighted by exact factors.
NEAR_FACTOR = 2.0
#: Receiver-sample pairs per work chunk (bounds memory whatever the receiver count).
PAIRS_PER_CHUNK = 1 << 15
#: Largest relative miss of a closed receiver's row sum that balancing treats as sampling
#: error; beyond it the row is a modelling problem and left alone.
ROW_FIX_LIMIT = 0.05
#: Row sums of an occlusion-free scene within this of 1 count as closed (exact factors).
EXACT_ROW_SUM = 1e-6
#: Balancing stops when no column scale changes by more than this.
BALANCE_CONVERGED = 1e-12


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
    """

    receivers: np.ndarray
    factors: np.ndarray
    rays: int


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
        self._patch_tri, self._patch_tri_ptr = _group(mesh.triangle_patch, mesh.patch_count)
        self._vert_index, self._vert_ptr = _patch_vertices(mesh)
        self._edge_start, self._edge_end, self._edge_ptr = _boundary_edges(mesh)

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
        return Column(col.receivers, col.factors * scale, col.rays)

    def _raw_column(self, patch: int) -> Column:
        cached = self._cache.get(patch)
        if cached is not None:
            return cached
        col = self._compute(patch)
        self.columns_computed += 1
        self.rays_cast += col.rays
        if patch not in self._summed:
            self._summed.add(patch)
            self._row_sum[col.receivers] += col.factors
            if len(col.receivers) and self._row_scale is None:
                self.max_row_sum = max(self.max_row_sum, float(self._row_sum[col.receivers].max()))
        size = col.receivers.nbytes + col.factors.nbytes + 64
        if self._cached_bytes + size <= self.cache_bytes:
            self._cache[patch] = col
            self._cached_bytes += size
        return col

    def balance(
        self,
        closed: np.ndarray | None,
        progress: Callable[[int, int], None] | None = None,
        iterations: int = 100,
    ) -> dict[str, float]:
        """Rescale the form factors so that they conserve energy exactly.

        Two physical constraints the sampled factors miss by a fraction of a percent:

        * a receiver whose whole hemisphere is covered by front faces (``closed``) has
          ``sum_p F_jp = 1``;
        * a patch cannot deliver more power than it shoots: ``g_p = sum_j a_j F_jp / A_p
          <= 1``.

        At reflectance 0.999 a 0.1% miss is 100% of radiosity (REFERENCE.md: the furnace
        error is about rho delta / (1 - rho)), and a patch with rho g_p > 1 creates energy
        each time it shoots, which ambient overshooting amplifies into divergence. This
        computes every column once (they stay cached for the solve) and alternates row and
        column scalings (Sinkhorn iteration) until both constraints hold to
        :data:`BALANCE_CONVERGED`. Rows off by more than :data:`ROW_FIX_LIMIT` are left
        alone: that is a modelling problem, not sampling noise.

        Parameters
        ----------
        closed : (R,) bool or None
            Receivers that see no opening; None (a scene where nothing occludes, so the
            factors are exact) takes rows already summing to 1 within :data:`EXACT_ROW_SUM`.
        progress : callable or None
            ``progress(done, total)`` while columns are computed.

        Returns
        -------
        dict with ``closed_rows`` (rows held to 1), ``capped_columns`` (patches held to
        g = 1), ``row_error`` and ``capture_excess`` (largest deviations before balancing).
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
        row_scale = np.ones(mesh.receiver_count)
        col_scale = np.ones(total)
        capture0 = np.bincount(owner, weights=area * values, minlength=total) / mesh.patch_area
        for _ in range(iterations):
            scaled = values * col_scale[owner]
            row_sum = np.bincount(rows, weights=scaled, minlength=mesh.receiver_count)
            row_scale = np.where(fix_rows & (row_sum > 0), 1.0 / np.maximum(row_sum, 1e-300), 1.0)
            capture = (
                np.bincount(owner, weights=area * values * row_scale[rows], minlength=total)
                / mesh.patch_area
            )
            new_col = np.ones(total)
            np.divide(1.0, capture, out=new_col, where=capture > 1.0)
            done = np.abs(new_col - col_scale).max(initial=0.0) < BALANCE_CONVERGED
            col_scale = new_col
            if done:
                break
        self._row_scale = row_scale
        self._col_scale = col_scale
        final = np.bincount(rows, weights=values * col_scale[owner], minlength=mesh.receiver_count)
        self.max_row_sum = float((final * row_scale).max(initial=0.0))
        return {
            "closed_rows": int(fix_rows.sum()),
            "capped_columns": int((col_scale < 1.0).sum()),
            "row_error": float(np.abs(sums[fix_rows] - 1.0).max(initial=0.0)),
            "capture_excess": float(max(0.0, capture0.max(initial=0.0) - 1.0)),
        }

    def _candidates(self, patch: int) -> np.ndarray:
        """Receivers that may exchange light with ``patch`` (cheap conservative culling)."""
        m = self.mesh
        x = self._points
        center, radius = m.patch_center[patch], m.patch_radius[patch]
        band = tol.horizon * self.diagonal
        facing = (m.receiver_normal @ center - np.einsum("ij,ij->i", m.receiver_normal, x)) > (
            -radius
        )
        if m.patch_planar[patch]:
            normal = m.patch_normal[patch]
            facing &= (x - center) @ normal > band
        return np.nonzero(facing)[0]

    def _compute(self, patch: int) -> Column:
        candidates = self._candidates(patch)
        factors, rays = self._factors(
            self._points[candidates],
            self.mesh.receiver_normal[candidates],
            self._origins[candidates],
            patch,
        )
        keep = factors > 0
        return Column(candidates[keep], factors[keep], rays)

    def factors_at(self, points: np.ndarray, normals: np.ndarray, patch: int) -> np.ndarray:
        """F(point <- patch) for arbitrary receiver points.

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
    ) -> tuple[np.ndarray, int]:
        if len(x) == 0:
            return np.zeros(0), 0
        n_sub = max(1, self.mesh.patch_subareas(patch).stop - self.mesh.patch_subareas(patch).start)
        per_chunk = max(1, PAIRS_PER_CHUNK // max(n_sub, self._edge_count(patch)))
        bounds = [*range(0, len(x), per_chunk), len(x)]
        spans = list(itertools.pairwise(bounds))

        def work(span: tuple[int, int]) -> tuple[np.ndarray, int]:
            a, b = span
            return self._chunk(x[a:b], nx[a:b], origins[a:b], patch)

        if len(spans) == 1 or worker_count() == 1:
            parts = [work(s) for s in spans]
        else:
            if self._pool is None:
                self._pool = ThreadPoolExecutor(worker_count(), thread_name_prefix="raytrad-ff")
            parts = list(self._pool.map(work, spans))
        return np.concatenate([p[0] for p in parts]), sum(p[1] for p in parts)

    def _edge_count(self, patch: int) -> int:
        return int(self._edge_ptr[patch + 1] - self._edge_ptr[patch])

    def _chunk(
        self, x: np.ndarray, nx: np.ndarray, origins: np.ndarray, patch: int
    ) -> tuple[np.ndarray, int]:
        """F(receiver <- patch) for receivers (x, nx) whose rays start at ``origins``.

        The unoccluded factor is exact (:meth:`_unoccluded`); visibility scales it by the
        visible fraction of the patch seen through its sub-area sample points, each weighted
        by its disk-approximation factor, or, for sub-areas nearer than
        :data:`NEAR_FACTOR` sizes, through each of their triangles weighted exactly.
        """
        unoccluded = self._unoccluded(x, nx, patch)
        if self.occluder is None:
            return unoccluded, 0
        m = self.mesh
        sub = m.patch_subareas(patch)
        y = m.subarea_point[sub]
        d = y[None, :, :] - x[:, None, :]
        r2 = np.einsum("csj,csj->cs", d, d)
        r = np.sqrt(r2)
        inv_r = 1.0 / np.where(r > 0, r, 1.0)
        cos_r = np.einsum("csj,cj->cs", d, nx) * inv_r
        cos_s = -np.einsum("csj,sj->cs", d, m.subarea_normal[sub]) * inv_r
        near = r < NEAR_FACTOR * m.subarea_size[sub][None, :]
        far = ~near & (cos_r > 0) & (cos_s > 0)
        sees = unoccluded > 0
        # a receiver that sees part of the patch but none of its sample points is handled
        # triangle by triangle
        near |= (sees & ~far.any(axis=1) & ~near.any(axis=1))[:, None]
        near &= sees[:, None]
        far &= sees[:, None]
        weight = np.where(far, disk_form_factor(cos_r, cos_s, r2, m.subarea_area[sub]), 0.0)
        far_c, far_s = np.nonzero(far)
        near_c, near_target, near_w = self._near_field(x, nx, near, sub)
        targets = np.concatenate([self._sub_target[sub][far_s], near_target])
        who = np.concatenate([far_c, near_c])
        blocked = self._blocked(origins[who], targets)
        total = weight.sum(axis=1) + np.bincount(near_c, weights=near_w, minlength=len(x))
        hidden = np.bincount(
            who,
            weights=np.concatenate([weight[far_c, far_s], near_w]) * blocked,
            minlength=len(x),
        )
        visible = np.where(total > 0, 1.0 - hidden / np.where(total > 0, total, 1.0), 0.0)
        return unoccluded * np.clip(visible, 0.0, 1.0), len(who)

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
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Exact per-triangle visibility weights for near (receiver, sub-area) pairs.

        Returns
        -------
        chunk_receiver : (K,) int64, index into the chunk
        target : (K, 3) float64, ray target: the centroid of the part of the triangle above
            the receiver's horizon, lifted off the surface [m]
        weight : (K,) float64, unoccluded exact factors (> 0 only)
        """
        c, s = np.nonzero(near)
        if len(c) == 0:
            return np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0)
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
        target = visible_centroid(self._tri_corners[tri], x[cc], nx[cc])
        target += tol.ray_offset * self.diagonal * self.mesh.triangle_normal[tri]
        return cc, target, f[keep]

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


def _group(labels: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Items sorted by label, and CSR pointers ((count + 1,) int64) into them."""
    order = np.argsort(labels, kind="stable")
    return order, np.searchsorted(labels[order], np.arange(count + 1))


def _patch_vertices(mesh: RadiosityMesh) -> tuple[np.ndarray, np.ndarray]:
    """The distinct vertices of each patch's triangles, grouped by patch (CSR)."""
    key = np.unique(
        np.stack([np.repeat(mesh.triangle_patch, 3), mesh.triangles.reshape(-1)], axis=1), axis=0
    )
    return key[:, 1], np.searchsorted(key[:, 0], np.arange(mesh.patch_count + 1))


def _boundary_edges(mesh: RadiosityMesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Oriented boundary edges of each patch: edges used by one of its triangles only.

    Consecutive collinear boundary edges are merged (Lambert's sum is additive along a
    straight edge), so a refined rectangular patch has 4 edges however fine its triangles.

    Returns
    -------
    start, end : (E, 3) float64, edge endpoints [m], in the winding of their triangle
    pointer : (P + 1,) int64, CSR pointers by patch
    """
    tri = mesh.triangles
    a = tri.reshape(-1)
    b = np.roll(tri, -1, axis=1).reshape(-1)
    patch = np.repeat(mesh.triangle_patch, 3)
    key = np.stack([patch, np.minimum(a, b), np.maximum(a, b)], axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    single = counts[inverse.reshape(-1)] == 1
    order = np.argsort(patch[single], kind="stable")
    a, b, patch = a[single][order], b[single][order], patch[single][order]
    a, b, patch = _merge_collinear(mesh.positions, a, b, patch)
    pointer = np.searchsorted(patch, np.arange(mesh.patch_count + 1))
    return mesh.positions[a], mesh.positions[b], pointer


def _merge_collinear(
    positions: np.ndarray, a: np.ndarray, b: np.ndarray, patch: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Join boundary edges (a -> b) whose shared vertex is straight (collinear neighbours).

    Only vertices with exactly one incoming and one outgoing boundary edge of the same
    patch are candidates, so non-manifold boundaries are left as they are.
    """
    n = len(a)
    start_key = patch * (positions.shape[0] + 1) + a
    end_key = patch * (positions.shape[0] + 1) + b
    sorted_start = np.argsort(start_key, kind="stable")
    pos = np.searchsorted(start_key[sorted_start], end_key)
    pos_c = np.minimum(pos, n - 1)
    found = start_key[sorted_start[pos_c]] == end_key
    # a vertex with two outgoing edges is ambiguous: no merging there
    dup_start = np.zeros(n, dtype=bool)
    ks = start_key[sorted_start]
    twice = np.zeros(n, dtype=bool)
    twice[1:] |= ks[1:] == ks[:-1]
    twice[:-1] |= ks[1:] == ks[:-1]
    dup_start[sorted_start] = twice
    nxt = np.where(found, sorted_start[pos_c], -1)
    ok = (nxt >= 0) & ~dup_start[np.maximum(nxt, 0)]
    d0 = positions[b] - positions[a]
    d1 = np.where(ok[:, None], d0[np.maximum(nxt, 0)], 0.0)
    cross = np.linalg.norm(np.cross(d0, d1), axis=1)
    scale = np.linalg.norm(d0, axis=1) * np.linalg.norm(d1, axis=1)
    straight = ok & (cross <= tol.collinear * scale) & (np.einsum("ij,ij->i", d0, d1) > 0)
    if not straight.any():
        return a, b, patch
    # the end of each edge's chain: follow straight joints (pointer jumping)
    jump = np.where(straight, nxt, np.arange(n))
    for _ in range(64):
        jumped = jump[jump]
        if np.array_equal(jumped, jump):
            break
        jump = jumped
    removed_start = np.zeros(n, dtype=bool)
    removed_start[nxt[straight]] = True
    keep = ~removed_start
    if not keep.any():  # a closed straight loop cannot happen for a real polygon
        return a, b, patch
    return a[keep], b[jump[keep]], patch[keep]
