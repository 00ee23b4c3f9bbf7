"""Form factors of (receiver, patch) pairs, one chunk of receivers at a time.

The unoccluded factor is exact (Lambert's formula over the patch's outline, clipped to a
receiver's horizon where the patch straddles it, :mod:`raytrad.core.contour`);
visibility scales it by the visible fraction of the patch seen through its sub-area
sample points, each weighted by its disk-approximation factor, or, for sub-areas nearer
than :data:`NEAR_FACTOR` sizes, through their clusters (:mod:`raytrad.core.clusters`)
as far from the receiver in their own sizes, and the rest of their triangles, each
weighted exactly. For
receivers near the patch the same samples say where on the patch the visible factor
comes from (the near-field gather weights, :mod:`raytrad.core.gather`). The per-pair
loops run compiled (:mod:`raytrad.core.kernels`, :mod:`raytrad.core.contour`,
:mod:`raytrad.core.compiled`).
"""

from __future__ import annotations

import copy
import itertools
import threading

import numpy as np

from raytrad.constants import tol
from raytrad.core import compiled
from raytrad.core.blockers import Blockers, blockers, target_corners
from raytrad.core.clusters import disk_factors, runs
from raytrad.core.contour import piecewise_contour_form_factor, planar_contour_form_factor
from raytrad.core.facets import PACKET_FACETS, PACKET_KEPT, facets
from raytrad.core.gather import (
    EMPTY,
    GATHER_RADII,
    GatherWeights,
    SubareaMeans,
    subarea_triangles,
)
from raytrad.core.kernels import (
    linear_corner_shares,
    polygon_form_factor,
    sample_weights,
    sub_grid,
    visible_centroid,
)
from raytrad.core.mesh import RadiosityMesh
from raytrad.core.outline import boundary_edges, folded_pieces, patch_vertices
from raytrad.core.shafts import Facets, ShaftEnd, plane_hull, shaft_end
from raytrad.core.spread import RULE_POINTS, RULE_WEIGHTS, GatherShares, corner_form_factors
from raytrad.core.visibility import Occluder

#: A sub-area nearer than this multiple of its bounding-box diagonal has its visibility
#: sampled triangle by triangle, weighted by exact factors.
NEAR_FACTOR = 2.0
#: A near triangle closer than this many of its sizes to a receiver spreads its gather
#: weight over its corners by what the receiver sees of each part of it
#: (:func:`~raytrad.core.kernels.linear_corner_shares`, split 3 times within one size,
#: twice beyond); a farther one by :func:`~raytrad.core.gather.corner_form_factors`.
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

    def __init__(
        self,
        mesh: RadiosityMesh,
        occluder: Occluder | None,
        diagonal: float,
        cull: bool = True,
    ) -> None:
        self.mesh = mesh
        self.occluder = occluder
        self.diagonal = diagonal
        # Ray targets sit tol.ray_offset off their surface on its lit side: a ray ending a
        # margin short of a point *on* the surface would, at grazing angles, end closer to
        # the surface than float32 resolves, and hit the very surface it aims at.
        self._sub_target = mesh.subarea_point + tol.ray_offset * diagonal * mesh.subarea_normal
        self._vert_index, self._vert_ptr = patch_vertices(mesh)
        self._edge_start, self._edge_end, self._edge_ptr = boundary_edges(mesh)
        self._pieces = folded_pieces(mesh)
        #: Rays an unclassified caster would cast: (receiver, patch) pairs that see each
        #: other x the patch's sample points (the naive count shaft culling is set against).
        self.naive_rays = 0
        self._count_lock = threading.Lock()
        self.facets: Facets | None = None
        # the shaft test pays only compiled: its numpy reference costs more than the rays
        if cull and occluder is not None and compiled.get() is not None:
            # cheaper rays (Embree's packets) leave culling fewer scenes where it pays
            limits = (PACKET_FACETS, PACKET_KEPT) if occluder.packets else ()
            self.facets = facets(occluder.positions, occluder.triangles, diagonal, *limits)
        if self.facets is not None:
            lift = tol.ray_offset * diagonal
            self._patch_sides = np.stack(
                [
                    self.facets.patch_sides(
                        mesh.positions[self._vert_index[a:b]],
                        mesh.patch_normal[p] if mesh.patch_planar[p] else None,
                        lift,
                    )
                    for p, (a, b) in enumerate(itertools.pairwise(self._vert_ptr))
                ]
            )
            self._shaft_ends()
        self.blockers: Blockers | None = None
        if self.facets is not None and occluder is not None:  # (so also only compiled)
            self.blockers = blockers(occluder.positions, occluder.triangles, diagonal)
        self._triangle_tables()

    def _shaft_ends(self) -> None:
        """Each patch's end of its shafts (:func:`~raytrad.core.shafts.shaft_end`), and
        its target corners as the convex blockers read them: CSR, with the radius of a
        ball about the patch's centre that holds them."""
        m = self.mesh
        self._ends = [self._shaft_end(p) for p in range(m.patch_count)]
        targets = [end.targets for end in self._ends]
        self._corner_ptr = np.concatenate([[0], np.cumsum([len(t) for t in targets])])
        self._corners = np.concatenate(targets)
        self._corner_reach = np.array(
            [np.linalg.norm(t - m.patch_center[p], axis=1).max() for p, t in enumerate(targets)]
        )

    def _shaft_end(self, patch: int) -> ShaftEnd:
        """The patch's end of its shafts: a planar patch's from its outline's convex hull, a
        folded patch's with the :func:`~raytrad.core.blockers.target_corners` of its
        pieces' corners."""
        m, lift = self.mesh, tol.ray_offset * self.diagonal
        vertices = m.positions[self._vert_index[self._vert_ptr[patch] : self._vert_ptr[patch + 1]]]
        center = m.patch_center[patch]
        reach = float(m.patch_radius[patch] + lift + tol.horizon * self.diagonal)
        if m.patch_planar[patch]:
            normal = m.patch_normal[patch]
            outline = self._edge_start[self._edge_ptr[patch] : self._edge_ptr[patch + 1]]
            return shaft_end(
                vertices, plane_hull(outline, normal), normal, center, reach, None, lift
            )
        pieces = self._pieces
        first = pieces.edge_ptr[pieces.patch_ptr[patch]]
        last = pieces.edge_ptr[pieces.patch_ptr[patch + 1]]
        targets = target_corners(pieces.start[first:last], None, lift)
        return shaft_end(vertices, np.zeros((0, 3)), None, center, reach, targets, lift)

    def _triangle_tables(self) -> None:
        """The tables that follow the mesh's triangles (rebuilt on a refined mesh)."""
        mesh = self.mesh
        self._shares = GatherShares(mesh, *subarea_triangles(mesh))
        self._tri_corners = self._shares.tri_corners  # (T, 3, 3), one copy for both
        self._tree = self._shares.tree
        #: within this distance of a node [m] the near field resolves it further
        self._node_near = NEAR_FACTOR * self._tree.size

    def refined(self, mesh: RadiosityMesh) -> PairFactors:
        """The same pairs on a refinement of this mesh (same patches and sub-areas, its
        vertices kept at their indices, finer triangles): the patch outlines, corner sets
        and facet tables carry over, since bisection adds no corner to a patch's outline
        and no height outside its corners' range; only the triangle tables are rebuilt."""
        kept = len(self.mesh.positions)
        if not np.array_equal(mesh.positions[:kept], self.mesh.positions):
            return PairFactors(mesh, self.occluder, self.diagonal, self.facets is not None)
        out = copy.copy(self)
        out.mesh = mesh
        out.naive_rays = 0
        out._count_lock = threading.Lock()
        out._triangle_tables()
        return out

    @property
    def subarea_means(self) -> SubareaMeans:
        """The sources of far sub-areas' gather weights (:class:`SubareaMeans`)."""
        return self._shares.means

    def sides(self, origins: np.ndarray) -> np.ndarray | None:
        """Packed facet side bits of ray origins for :meth:`chunk` (None: no culling)."""
        return None if self.facets is None else self.facets.sides(origins)

    def chunk_size(self, patch: int) -> int:
        """Receivers per chunk for ``patch``: :data:`PAIRS_PER_CHUNK` pairs of a receiver
        with a sub-area or a boundary edge."""
        sub = self.mesh.patch_subareas(patch)
        edges = int(self._edge_ptr[patch + 1] - self._edge_ptr[patch])
        return max(1, PAIRS_PER_CHUNK // max(sub.stop - sub.start, edges, 1))

    def chunk(
        self,
        x: np.ndarray,
        nx: np.ndarray,
        origins: np.ndarray,
        patch: int,
        sides: np.ndarray | None = None,
    ) -> tuple[np.ndarray, int, GatherWeights]:
        """F(receiver <- patch) for receivers (x, nx) whose rays start at ``origins``, the
        rays cast, and the gather weights of the near receivers (chunk indices).

        The unoccluded factor is exact (:meth:`_unoccluded`); visibility scales it by the
        visible fraction of the patch seen through its sub-area sample points, each weighted
        by its disk-approximation factor, or, for sub-areas nearer than
        :data:`NEAR_FACTOR` sizes, through each of their triangles weighted exactly. Only
        receivers whose shaft to the patch an occluder may cross are traced (``sides``, the
        origins' packed facet bits from :meth:`sides`; None traces every receiver, see
        :mod:`raytrad.core.shafts`), and of those only the ones no convex occluder hides
        wholly (:mod:`raytrad.core.blockers`: their factor is 0 without a ray); samples
        are taken for the traced receivers and for the near receivers' gather weights.
        """
        m = self.mesh
        unoccluded = self._unoccluded(x, nx, patch)
        sees = unoccluded > 0
        sub = m.patch_subareas(patch)
        with self._count_lock:
            self.naive_rays += int(sees.sum()) * (sub.stop - sub.start)
        doubt = sees if self.occluder is not None else np.zeros_like(sees)
        if self.facets is not None and sides is not None and doubt.any():
            doubt = doubt & ~self.facets.clear(
                origins, sides, self._patch_sides[patch], self._ends[patch]
            )
        if self.blockers is not None and doubt.any():
            hidden = np.zeros_like(doubt)
            hidden[doubt] = self.blockers.blocked(
                np.compress(doubt, origins, axis=0),
                self._corners[self._corner_ptr[patch] : self._corner_ptr[patch + 1]],
                m.patch_center[patch],
                float(self._corner_reach[patch]),
                probe=True,
            )
            unoccluded = np.where(hidden, 0.0, unoccluded)
            sees &= ~hidden
            doubt &= ~hidden
        offset = x - m.patch_center[patch]
        distance = np.sqrt(np.einsum("cj,cj->c", offset, offset))
        close = sees & (distance < GATHER_RADII * m.patch_radius[patch])
        sampled = doubt | close
        if not sampled.any():
            return unoccluded, 0, EMPTY
        weight, far, tri_items, node_items = self._samples(x, nx, sampled, sub)
        near_c, near_tri, near_target, near_w, near_share = tri_items
        node_c, node, node_target, node_w = node_items
        factors, far_hidden, hidden, rays = self._visibility(
            unoccluded,
            doubt,
            origins,
            sub,
            weight,
            far,
            np.concatenate([near_c, node_c]),
            np.concatenate([near_target, node_target]),
            np.concatenate([near_w, node_w]),
        )
        near_hidden, node_hidden = hidden[: len(near_c)], hidden[len(near_c) :]
        rows, pointer, sources, shares = self._shares.spread_chunk(
            close,
            (weight, far, far_hidden),
            self._tree.root[sub],
            (near_c, near_tri, near_w, near_share, near_hidden),
            (node_c, node, node_w, node_hidden),
            x,
            nx,
        )
        return factors, rays, GatherWeights(rows, factors[rows], pointer, sources, shares)

    def _visibility(
        self,
        unoccluded: np.ndarray,
        doubt: np.ndarray,
        origins: np.ndarray,
        sub: slice,
        weight: np.ndarray,
        far: np.ndarray,
        near_c: np.ndarray,
        near_target: np.ndarray,
        near_w: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        """Trace the samples of the receivers in doubt; the others see all of the patch.

        Returns
        -------
        factors : (C,) float64, visible factors
        far_hidden : (C, S) bool, blocked far samples
        near_hidden : (B,) bool, blocked near items (triangles and clusters)
        rays : int
        """
        if self.occluder is None or not doubt.any():
            return unoccluded, np.zeros(far.shape, bool), np.zeros(len(near_c), bool), 0
        shorten = 0.5 * tol.ray_offset * self.diagonal
        if self.occluder.packets:  # made and traced in one compiled loop
            far_hidden, near_hidden, rays = self.occluder.occluded_samples(
                origins, far, doubt, self._sub_target[sub], near_c, near_target, shorten
            )
        else:
            far_hidden, near_hidden, rays = self._traced(
                origins, far, doubt, sub, near_c, near_target, shorten
            )
        factors = visible_factors(
            unoccluded, doubt, weight, far_hidden, near_c, near_w, near_hidden
        )
        return factors, far_hidden, near_hidden, rays

    def _traced(
        self,
        origins: np.ndarray,
        far: np.ndarray,
        doubt: np.ndarray,
        sub: slice,
        near_c: np.ndarray,
        near_target: np.ndarray,
        shorten: float,
    ) -> tuple[np.ndarray, np.ndarray, int]:
        """(far_hidden, near_hidden, rays) as :meth:`Occluder.occluded_samples` gives them,
        from the rays written out (:meth:`Occluder.sample_rays`) and traced by
        :meth:`Occluder.occluded_local` (embreex, or the numpy kernels)."""
        assert self.occluder is not None
        far_hidden = np.zeros(far.shape, dtype=bool)  # C order: written through a flat view
        near_hidden = np.zeros(len(near_c), dtype=bool)
        traced = doubt[near_c]
        o, d, t, far_c, far_s = self.occluder.sample_rays(
            origins, far, doubt, self._sub_target[sub], near_c, near_target, shorten
        )
        blocked = self.occluder.occluded_local(o, d, t)
        count = len(far_c)
        flat = (far_c * far.shape[1] + far_s)[blocked[:count]]  # flat: faster than 2-D
        far_hidden.reshape(-1)[flat] = True
        near_hidden[np.flatnonzero(traced)[blocked[count:]]] = True
        return far_hidden, near_hidden, len(blocked)

    def _samples(
        self, x: np.ndarray, nx: np.ndarray, sees: np.ndarray, sub: slice
    ) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
        """The weighted visibility samples of the receivers that see the patch.

        Returns
        -------
        weight : (C, S) float64, disk factors of far samples (0 elsewhere)
        far : (C, S) bool, the far samples
        triangles : near triangles (:meth:`_near_field`)
        clusters : near sub-areas' clusters taken whole (:meth:`_near_field`)
        """
        m = self.mesh
        # a receiver that sees part of the patch but none of its sample points is handled
        # triangle by triangle
        weight, far, near = sample_weights(
            x,
            nx,
            sees,
            m.subarea_point[sub],
            m.subarea_normal[sub],
            NEAR_FACTOR * m.subarea_size[sub],
            m.subarea_area[sub],
        )
        items = self._near_field(x, nx, near, sub)
        return weight, far, items[:5], items[5:]

    def _unoccluded(self, x: np.ndarray, nx: np.ndarray, patch: int) -> np.ndarray:
        """Exact unoccluded F(receiver <- patch).

        A planar patch's factor is a sum over its boundary edges alone (interior edges
        cancel): the whole outline where the patch lies above the receiver's horizon, the
        outline clipped to the horizon where it straddles it
        (:mod:`raytrad.core.contour`). A folded patch (a warped quad's two triangles)
        goes piece by planar piece, each piece's outline clipped: seen from a receiver on
        it, the patch's own contour sum would count the fold's surface as a full
        hemisphere.
        """
        m = self.mesh
        band = tol.horizon * self.diagonal
        if m.patch_planar[patch]:
            a, b = self._edge_ptr[patch], self._edge_ptr[patch + 1]
            return planar_contour_form_factor(
                self._edge_start[a:b],
                self._edge_end[a:b],
                x,
                nx,
                m.patch_normal[patch],
                m.patch_center[patch],
                band,
            )
        return piecewise_contour_form_factor(self._pieces, patch, x, nx, band)

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
    ) -> tuple[np.ndarray, ...]:
        """Exact per-triangle visibility weights for near (receiver, sub-area) pairs, and
        the clusters of the sub-areas' trees taken whole.

        Each near pair walks its sub-area's cluster tree (:mod:`raytrad.core.clusters`):
        a cluster farther than :data:`NEAR_FACTOR` of its sizes is one sample, as a far
        sub-area is; a leaf's triangles are taken one by one.

        Returns
        -------
        chunk_receiver : (K,) int64, index into the chunk
        triangle : (K,) int64
        target : (K, 3) float64, ray target: the centroid of the part of the triangle above
            the receiver's horizon, lifted off the surface [m]
        weight : (K,) float64, unoccluded exact factors (> 0 only)
        shares : (K, 3) float64, each corner's share of what the receiver sees of the
            triangle (:func:`~raytrad.core.kernels.linear_corner_shares` within
            :data:`SHARE_SIZES` triangle sizes, else
            :func:`~raytrad.core.spread.corner_form_factors`)
        cluster_receiver, cluster : (H,) int64
            The clusters taken whole that face the receiver, and its chunk index.
        cluster_target : (H, 3) float64, their sample points, lifted [m]
        cluster_weight : (H,) float64, their disk factors (> 0 only)
        """
        fast = compiled.get()
        if fast is None:
            return self._numpy_near_field(x, nx, near, sub)
        tree = self._tree
        return tuple(
            fast.near_triangles(
                np.ascontiguousarray(near, dtype=np.bool_),
                sub.start,
                tree.root,
                tree.arrays,
                self._node_near,
                self._tri_corners,
                self.mesh.triangle_normal,
                np.ascontiguousarray(x, dtype=np.float64),
                np.ascontiguousarray(nx, dtype=np.float64),
                tol.horizon * self.diagonal,
                tol.horizon,
                tol.ray_offset * self.diagonal,
                SHARE_SIZES,
                sub_grid(3),
                sub_grid(2),
                RULE_POINTS,
                RULE_WEIGHTS,
            )
        )

    def _numpy_near_field(
        self, x: np.ndarray, nx: np.ndarray, near: np.ndarray, sub: slice
    ) -> tuple[np.ndarray, ...]:
        """The numpy reference of :meth:`_near_field` (the compiled path does the same in
        one loop, :func:`~raytrad.core._compiled_near.near_triangles`)."""
        c, s = np.nonzero(near)
        tree = self._tree
        element, item = tree.cuts(tree.root[s + sub.start], x[c], NEAR_FACTOR)
        whole = item >= 0
        node_c, node = c[element[whole]], item[whole]
        node_w = disk_factors(
            x[node_c], nx[node_c], tree.point[node], tree.normal[node], tree.area[node]
        )
        facing = node_w > 0
        node_c, node, node_w = node_c[facing], node[facing], node_w[facing]
        node_target = tree.point[node] + tol.ray_offset * self.diagonal * tree.normal[node]
        leaf = -1 - item[~whole]
        owner, slot = runs(tree.start[leaf], tree.stop[leaf])
        tri = tree.sub_tri[slot]
        cc = c[element[~whole][owner]]
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
        far = distance >= SHARE_SIZES
        if far.any():
            raw = corner_form_factors(
                corners[far], self.mesh.triangle_normal[tri[far]], x[cc[far]], nx[cc[far]]
            )
            total = raw.sum(axis=1, keepdims=True)
            shares[far] = np.divide(raw, total, out=shares[far], where=total > 0)
        for levels, lo, hi in ((3, 0.0, 1.0), (2, 1.0, SHARE_SIZES)):
            part = (distance >= lo) & (distance < hi)
            if part.any():
                shares[part] = linear_corner_shares(
                    corners[part], x[cc[part]], nx[cc[part]], levels
                )
        return cc, tri, target, f[keep], shares, node_c, node, node_target, node_w


def visible_factors(
    unoccluded: np.ndarray,
    doubt: np.ndarray,
    weight: np.ndarray,
    far_hidden: np.ndarray,
    near_c: np.ndarray,
    near_w: np.ndarray,
    near_hidden: np.ndarray,
) -> np.ndarray:
    """The visibility-weighted accumulation, compiled when available (see
    :func:`numpy_visible_factors`, the reference)."""
    fast = compiled.get()
    if fast is None:
        return numpy_visible_factors(
            unoccluded, doubt, weight, far_hidden, near_c, near_w, near_hidden
        )
    return np.asarray(
        fast.visible_factors(
            np.ascontiguousarray(unoccluded, dtype=np.float64),
            np.ascontiguousarray(doubt, dtype=np.bool_),
            np.ascontiguousarray(weight, dtype=np.float64),
            np.ascontiguousarray(far_hidden, dtype=np.bool_),
            np.ascontiguousarray(near_c, dtype=np.int64),
            np.ascontiguousarray(near_w, dtype=np.float64),
            np.ascontiguousarray(near_hidden, dtype=np.bool_),
        )
    )


def numpy_visible_factors(
    unoccluded: np.ndarray,
    doubt: np.ndarray,
    weight: np.ndarray,
    far_hidden: np.ndarray,
    near_c: np.ndarray,
    near_w: np.ndarray,
    near_hidden: np.ndarray,
) -> np.ndarray:
    """Form factors of a chunk's receivers: for those in ``doubt``, the unoccluded factor
    times the visible share of the samples' weights, else the unoccluded factor.

    Parameters
    ----------
    unoccluded : (C,) float64
        Exact unoccluded factors [1].
    doubt : (C,) bool
        The receivers whose samples were traced.
    weight : (C, S) float64
        Far samples' disk factors (0 where not a far sample) [1].
    far_hidden : (C, S) bool
        Far samples found blocked.
    near_c : (B,) int64, near_w : (B,) float64, near_hidden : (B,) bool
        Near triangles' receivers, exact factors [1] and whether found blocked.

    Returns
    -------
    (C,) float64 [1]; a receiver in doubt with no sample weight gets 0.
    """
    count = len(unoccluded)
    total = weight.sum(axis=1) + np.bincount(near_c, weights=near_w, minlength=count)
    hidden = (weight * far_hidden).sum(axis=1) + np.bincount(
        near_c, weights=near_w * near_hidden, minlength=count
    )
    visible = np.where(total > 0, 1.0 - hidden / np.where(total > 0, total, 1.0), 0.0)
    return np.asarray(np.where(doubt, unoccluded * np.clip(visible, 0.0, 1.0), unoccluded))


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
