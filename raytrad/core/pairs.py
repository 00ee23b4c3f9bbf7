"""Form factors of (receiver, patch) pairs, one chunk of receivers at a time.

The unoccluded factor is exact (Lambert's formula over the patch's outline, or triangle by
triangle where the patch straddles the receiver's horizon); visibility scales it by the
visible fraction of the patch seen through its sub-area sample points, each weighted by
its disk-approximation factor, or, for sub-areas nearer than :data:`NEAR_FACTOR` sizes,
through each of their triangles weighted exactly. For receivers near the patch the same
samples say where on the patch the visible factor comes from (the near-field gather
weights, :mod:`raytrad.core.gather`). The per-pair loops run compiled
(:mod:`raytrad.core.kernels`, :mod:`raytrad.core.compiled`).
"""

from __future__ import annotations

import numpy as np

from raytrad.constants import tol
from raytrad.core.gather import EMPTY, GATHER_RADII, GatherShares, GatherWeights
from raytrad.core.kernels import (
    contour_form_factor,
    facing_triangle_sums,
    linear_corner_shares,
    polygon_form_factor,
    sample_weights,
    visibility_rays,
    visible_centroid,
)
from raytrad.core.mesh import RadiosityMesh
from raytrad.core.outline import boundary_edges, group, patch_vertices
from raytrad.core.visibility import Occluder

#: A sub-area nearer than this multiple of its bounding-box diagonal has its visibility
#: sampled triangle by triangle, weighted by exact factors.
NEAR_FACTOR = 2.0
#: A near triangle closer than this many of its sizes to a receiver spreads its gather
#: weight over its corners by what the receiver sees of each part of it
#: (:func:`~raytrad.core.kernels.linear_corner_shares`, split 3 times within one size,
#: twice beyond), not equally.
SHARE_SIZES = 3.0
#: Receiver-sample pairs per work chunk (bounds memory whatever the receiver count).
PAIRS_PER_CHUNK = 1 << 17


class PairFactors:
    """Form factors from chunks of receivers to one patch, with their visibility rays.

    Parameters
    ----------
    mesh : RadiosityMesh
    occluder : Occluder or None
        None when nothing in the scene can block light: no rays.
    diagonal : float
        The scene's diagonal [m] (scales the ray offsets and horizon bands).
    """

    def __init__(self, mesh: RadiosityMesh, occluder: Occluder | None, diagonal: float) -> None:
        self.mesh = mesh
        self.occluder = occluder
        self.diagonal = diagonal
        order = np.lexsort((np.arange(len(mesh.triangle_subarea)), mesh.triangle_subarea))
        self._sub_tri = order
        self._sub_ptr = np.searchsorted(
            mesh.triangle_subarea[order], np.arange(mesh.subarea_count + 1)
        )
        self._tri_corners = mesh.positions[mesh.triangles]
        # Ray targets sit tol.ray_offset off their surface on its lit side: a ray ending a
        # margin short of a point *on* the surface would, at grazing angles, end closer to
        # the surface than float32 resolves, and hit the very surface it aims at.
        self._sub_target = mesh.subarea_point + tol.ray_offset * diagonal * mesh.subarea_normal
        self._patch_tri, self._patch_tri_ptr = group(mesh.triangle_patch, mesh.patch_count)
        self._vert_index, self._vert_ptr = patch_vertices(mesh)
        self._edge_start, self._edge_end, self._edge_ptr = boundary_edges(mesh)
        self._shares = GatherShares(mesh, self._sub_tri, self._sub_ptr)

    def chunk_size(self, patch: int) -> int:
        """Receivers per chunk for ``patch``: :data:`PAIRS_PER_CHUNK` pairs of a receiver
        with a sub-area or a boundary edge."""
        sub = self.mesh.patch_subareas(patch)
        edges = int(self._edge_ptr[patch + 1] - self._edge_ptr[patch])
        return max(1, PAIRS_PER_CHUNK // max(sub.stop - sub.start, edges, 1))

    def chunk(
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
        weight, far, near_c, near_tri, near_target, near_w, near_share = self._samples(
            x, nx, sees, sub
        )
        factors = unoccluded
        if self.occluder is None:
            far_c, far_s = np.nonzero(far)
            who = np.concatenate([far_c, near_c])
            blocked = np.zeros(len(who), dtype=bool)
        else:
            o, d, t, far_c, far_s = visibility_rays(
                origins,
                far,
                self._sub_target[sub],
                near_c,
                near_target,
                self.occluder.origin,
                0.5 * tol.ray_offset * self.diagonal,
            )
            who = np.concatenate([far_c, near_c])
            blocked = self.occluder.occluded_local(o, d, t)
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
        far : (C, S) bool, the far samples
        near_c, near_tri, near_target, near_w, near_share : (B,), (B,), (B, 3), (B,),
            (B, 3), chunk receiver, triangle, ray target [m], exact factor and corner
            shares of near triangles
        """
        m = self.mesh
        weight, far, near = sample_weights(
            x,
            nx,
            m.subarea_point[sub],
            m.subarea_normal[sub],
            NEAR_FACTOR * m.subarea_size[sub],
            m.subarea_area[sub],
        )
        # a receiver that sees part of the patch but none of its sample points is handled
        # triangle by triangle
        near |= (sees & ~far.any(axis=1) & ~near.any(axis=1))[:, None]
        near &= sees[:, None]
        far &= sees[:, None]
        weight[~sees] = 0.0
        near_c, near_tri, near_target, near_w, near_share = self._near_field(x, nx, near, sub)
        return weight, far, near_c, near_tri, near_target, near_w, near_share

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
            ta, tb = self._patch_tri_ptr[patch], self._patch_tri_ptr[patch + 1]
            tris = self._patch_tri[ta:tb]
            out[straddle] = facing_triangle_sums(
                x[straddle],
                nx[straddle],
                self._tri_corners[tris],
                m.triangle_normal[tris],
                tol.horizon * self.diagonal,
            )
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
