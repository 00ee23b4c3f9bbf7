"""The near-field gather: a receiver close to a shooting patch sees the patch's radiosity
as it varies across it, not its mean.

Shooting delivers each patch's *mean* radiosity B̄_p to every receiver (equation 1 of
:mod:`raytrad.core.solver`). A receiver a few patch sizes away from a patch straddling a
shadow edge (a point on a block's side just above the floor, beside a floor patch half in
the block's shadow) sees mostly one part of it, whose radiosity can be far from the mean:
the bias does not shrink with more receivers, only with smaller patches.

So for every (receiver, patch) pair nearer than :data:`GATHER_RADII` patch radii, the
form-factor engine also keeps where on the patch the receiver's visible factor comes
from: the visible weight of each sub-area sample (disk approximation) and of each near
triangle (exact factor), spread onto the patch's receivers (a triangle over its corners,
a sub-area over its triangles by area). The gathered radiosity is then

    B̃_jp = sum_k g_jpk B_k,       sum_k g_jpk = 1,

and the solve converges to ``B_j = E_j + rho_j sum_p F_jp (B̄_p + [B̃_jp - B̄_p])``: the
bracket, summed over near pairs, is :func:`near_field_irradiance`, added to the shooting
solution as a correction that is itself shot on (:func:`raytrad.core.solver.solve`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from raytrad.core import compiled
from raytrad.core.mesh import RadiosityMesh

#: Pairs whose receiver is nearer than this many patch radii to the patch's centre gather
#: the patch's radiosity as it varies across it.
GATHER_RADII = 6.0

#: A sub-area nearer than this many of its sizes (bounding-box diagonals) to a receiver
#: spreads the receiver's weight of it by what the receiver sees of each of its triangles'
#: corners (:func:`corner_form_factors`); a farther one by area over its receivers.
MIDPOINT_SIZES = 5.0


@dataclass(frozen=True)
class GatherWeights:
    """Where a patch's visible factor comes from, for its near receivers.

    Attributes
    ----------
    receivers : (G,) int64
        Near receivers, ascending (a subset of the column's receivers).
    factors : (G,) float64
        Their form factors to the patch, before balancing [1].
    pointer : (G + 1,) int64
        CSR pointers into ``sources`` and ``weights`` by near receiver.
    sources : (S,) int64
        Receivers of the patch the radiosity is gathered from, or, from ``R`` (the
        receiver count) on, the mean of sub-area ``source - R`` (:class:`SubareaMeans`).
    weights : (S,) float64
        Their share; each near receiver's shares sum to 1.
    """

    receivers: np.ndarray
    factors: np.ndarray
    pointer: np.ndarray
    sources: np.ndarray
    weights: np.ndarray

    def gathered(self, radiosity: np.ndarray) -> np.ndarray:
        """(G, 3) radiosity each near receiver sees on the patch [W m-2], from the
        receiver ``radiosity`` and the sub-area means after it ((R + SA, 3),
        :meth:`SubareaMeans.extend`); compiled when available (see
        :meth:`numpy_gathered`)."""
        fast = compiled.get()
        if fast is None:
            return self.numpy_gathered(radiosity)
        return np.asarray(
            fast.gather_sums(
                self.pointer, self.sources, self.weights, np.ascontiguousarray(radiosity, float)
            )
        )

    def numpy_gathered(self, radiosity: np.ndarray) -> np.ndarray:
        """The reference of :meth:`gathered`: ``sum_k g_jpk B_k`` per near receiver, each
        row summed in order (as the compiled loop; a running sum over all rows would
        carry the other rows' rounding)."""
        owner = np.repeat(np.arange(len(self.receivers)), np.diff(self.pointer))
        values = self.weights.astype(np.float64)[:, None] * radiosity[self.sources]
        count = len(self.receivers)
        return np.stack(
            [np.bincount(owner, weights=values[:, k], minlength=count) for k in range(3)],
            axis=1,
        )

    def subset(self, keep: np.ndarray) -> GatherWeights:
        """Only the near receivers where ``keep`` ((G,) bool) holds."""
        counts = np.diff(self.pointer)[keep]
        _, index = _csr_slots(self.pointer, np.flatnonzero(keep))
        pointer = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        return GatherWeights(
            self.receivers[keep],
            self.factors[keep],
            pointer,
            self.sources[index],
            self.weights[index],
        )


EMPTY = GatherWeights(
    np.zeros(0, np.int64), np.zeros(0), np.zeros(1, np.int64), np.zeros(0, np.int64), np.zeros(0)
)


def join_gathers(parts: list[GatherWeights], offsets: list[int]) -> GatherWeights:
    """Chunks' gather weights as one, chunk receiver indices shifted by ``offsets``."""
    if len(parts) == 1:
        return parts[0]
    counts = [len(p.sources) for p in parts]
    starts = np.cumsum([0, *counts[:-1]])
    return GatherWeights(
        np.concatenate([p.receivers + o for p, o in zip(parts, offsets, strict=True)]),
        np.concatenate([p.factors for p in parts]),
        np.concatenate([[0]] + [p.pointer[1:] + s for p, s in zip(parts, starts, strict=True)]),
        np.concatenate([p.sources for p in parts]),
        np.concatenate([p.weights for p in parts]),
    )


@dataclass
class GatherRows:
    """What :meth:`FormFactorEngine.gather_rows` found: per patch, the points that see it
    (indices), their balanced factors and their near-field gather weights."""

    count: int
    row_sum: np.ndarray
    patches: list[tuple[int, np.ndarray, np.ndarray, GatherWeights]]
    means: SubareaMeans | None = None  # the sources beyond the receivers


def gathered_irradiance(
    rows: GatherRows, radiosity: np.ndarray, patch_radiosity: np.ndarray
) -> np.ndarray:
    """(N, 3) irradiance [W m-2] the points of ``rows`` gather from a solution: receiver
    ``radiosity`` (R, 3) and its patch means ``patch_radiosity`` (P, 3) [W m-2]."""
    irradiance = np.zeros((rows.count, 3))
    if rows.means is not None:
        radiosity = rows.means.extend(radiosity)
    for patch, near, factors, gather in rows.patches:
        irradiance[near] += factors[:, None] * patch_radiosity[patch]
        if len(gather.receivers):
            excess = gather.gathered(radiosity) - patch_radiosity[patch]
            local = gather.receivers
            irradiance[near[local]] += factors[local, None] * excess
    return irradiance


@dataclass(frozen=True)
class SubareaMeans:
    """Each sub-area's mean radiosity as a source of the near-field gather.

    A receiver far from a sub-area (beyond :data:`MIDPOINT_SIZES` of its sizes) spreads
    its weight of the sub-area by area over the sub-area's visible receivers: that says
    no more than their area-weighted mean. So its gather weights name the mean instead,
    as source ``base + s``, one entry whatever the sub-area's receiver count (which grows
    with refinement); :meth:`extend` appends the means to a radiosity.

    Attributes
    ----------
    base : int
        The mesh's receiver count.
    pointer : (SA + 1,) int64
        CSR pointers into ``receivers`` and ``shares`` by sub-area.
    receivers : (Q,) int64
        Each sub-area's visible receivers (corners of its triangles).
    shares : (Q,) float64
        Their area shares, summing to 1 per sub-area with any.
    """

    base: int
    pointer: np.ndarray
    receivers: np.ndarray
    shares: np.ndarray

    def extend(self, radiosity: np.ndarray) -> np.ndarray:
        """(R + SA, 3) the (R, 3) receiver ``radiosity`` followed by its sub-area means.

        Raises
        ------
        ValueError
            ``radiosity`` is not of this mesh's R receivers (the means would land at the
            wrong sources).
        """
        if len(radiosity) != self.base:
            raise ValueError(f"radiosity of {len(radiosity)} receivers for a mesh of {self.base}")
        return np.concatenate([radiosity, self.of(np.arange(len(self.pointer) - 1), radiosity)])

    def of(self, subareas: np.ndarray, radiosity: np.ndarray) -> np.ndarray:
        """(K, 3) means of ``radiosity`` ((R, 3) or longer) over the (K,) ``subareas``."""
        owner, index = _csr_slots(self.pointer, subareas)
        values = self.shares[index, None] * radiosity[self.receivers[index]]
        count = len(subareas)
        means = [np.bincount(owner, weights=values[:, k], minlength=count) for k in range(3)]
        return np.stack(means, axis=1)


def subarea_triangles(mesh: RadiosityMesh) -> tuple[np.ndarray, np.ndarray]:
    """The triangles grouped by sub-area ((T,) int64, ascending within one) and CSR
    pointers into them ((SA + 1,) int64)."""
    order = np.lexsort((np.arange(len(mesh.triangle_subarea)), mesh.triangle_subarea))
    return order, np.searchsorted(mesh.triangle_subarea[order], np.arange(mesh.subarea_count + 1))


def subarea_means(mesh: RadiosityMesh) -> SubareaMeans:
    """The sub-area means of ``mesh`` (as :class:`GatherShares` makes them)."""
    sub_tri, sub_ptr = subarea_triangles(mesh)
    corner_share = corner_shares(mesh)
    tri_share = _area_shares(mesh, corner_share, sub_tri, sub_ptr)
    return _means(mesh, corner_share, tri_share, sub_tri, sub_ptr)


def corner_shares(mesh: RadiosityMesh) -> np.ndarray:
    """(T, 3) share of each triangle's corners in its radiosity: 1/3 each, a hidden
    corner's going to the visible ones (all 0 where every corner is hidden)."""
    visible = (
        np.ones(mesh.receiver_count, bool)
        if mesh.receiver_visible is None
        else np.asarray(mesh.receiver_visible, bool)
    )
    share = visible[mesh.triangle_receivers].astype(np.float64)
    counts = share.sum(axis=1, keepdims=True)
    return np.divide(share, counts, out=np.zeros_like(share), where=counts > 0)


def _area_shares(
    mesh: RadiosityMesh, corner_share: np.ndarray, sub_tri: np.ndarray, sub_ptr: np.ndarray
) -> np.ndarray:
    """(T,) area share of ``sub_tri[k]`` in its sub-area (0 for triangles none sees)."""
    area = mesh.triangle_area[sub_tri] * (corner_share[sub_tri].sum(axis=1) > 0)
    owner = np.repeat(np.arange(len(sub_ptr) - 1), np.diff(sub_ptr))
    total = np.bincount(owner, weights=area, minlength=len(sub_ptr) - 1)
    return np.divide(area, total[owner], out=np.zeros_like(area), where=total[owner] > 0)


def _means(
    mesh: RadiosityMesh,
    corner_share: np.ndarray,
    tri_share: np.ndarray,
    sub_tri: np.ndarray,
    sub_ptr: np.ndarray,
) -> SubareaMeans:
    owner = np.repeat(np.arange(len(sub_ptr) - 1), np.diff(sub_ptr))
    pointer, receivers, shares = numpy_sum_shares(
        np.repeat(owner, 3),
        mesh.triangle_receivers[sub_tri].reshape(-1),
        (tri_share[:, None] * corner_share[sub_tri]).reshape(-1),
        len(sub_ptr) - 1,
    )
    return SubareaMeans(mesh.receiver_count, pointer, receivers, shares)


class GatherShares:
    """How a unit of visible weight on a triangle or a sub-area spreads over receivers.

    A near triangle's weight goes to its visible corners by the shares it comes with
    (what the receiver sees of each part of it); a sub-area's to its triangles' visible
    corners by :func:`corner_form_factors`, what the receiver sees of each corner's
    part (by area where the receiver sees none of it). Hidden receivers (shut in
    under a block) get nothing: their radiosity is not what the triangle shows.
    """

    def __init__(self, mesh: RadiosityMesh, sub_tri: np.ndarray, sub_ptr: np.ndarray) -> None:
        #: (T, 3) share of each corner of each triangle (0 for hidden corners)
        self.corner_share = corner_shares(mesh)
        self.corners = mesh.triangle_receivers
        # sub-area s: its triangles (sub_tri[sub_ptr[s]:sub_ptr[s+1]]) weighted by area
        self.sub_tri = sub_tri
        self.sub_ptr = sub_ptr
        self.tri_share = _area_shares(mesh, self.corner_share, sub_tri, sub_ptr)
        self.tri_corners = mesh.positions[mesh.triangles]
        self.tri_normal = mesh.triangle_normal
        self.sub_point = mesh.subarea_point
        self.sub_reach = MIDPOINT_SIZES * mesh.subarea_size
        #: each sub-area's mean: the source of far receivers' weights of it
        self.means = _means(mesh, self.corner_share, self.tri_share, sub_tri, sub_ptr)

    def spread(
        self,
        sub_pair: np.ndarray,
        subareas: np.ndarray,
        sub_weight: np.ndarray,
        tri_pair: np.ndarray,
        triangles: np.ndarray,
        tri_weight: np.ndarray,
        tri_share: np.ndarray,
        points: np.ndarray,
        normals: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Receiver shares of element weights, summed per (pair, receiver).

        Parameters
        ----------
        sub_pair, subareas, sub_weight : (A,) int, int, float
            Pair index, global sub-area and visible weight of sub-area elements.
        tri_pair, triangles, tri_weight : (B,) int, int, float
            Pair index, triangle and visible weight of triangle elements.
        tri_share : (B, 3) float
            How each triangle element's weight splits over its corners (rows summing to
            1); hidden corners' shares go to the visible ones.
        points, normals : (pairs, 3) float
            Each pair's receiver position [m] and unit normal.

        Returns
        -------
        pointer : (pairs + 1,) int64
        sources : (S,) int64
        weights : (S,) float64, normalised to sum 1 per pair (pairs with no weight: empty)
        """
        sub_pairs, sub_sources, sub_weights = subarea_spread(
            sub_pair,
            subareas,
            sub_weight,
            self.sub_ptr,
            self.sub_tri,
            self.tri_share,
            self.corner_share,
            self.corners,
            self.tri_corners,
            self.tri_normal,
            points,
            normals,
            self.sub_point,
            self.sub_reach,
            self.means.pointer,
            self.means.base,
        )
        seen = self.corner_share[triangles] > 0
        own = np.where(seen, tri_share, 0.0)
        total = own.sum(axis=1, keepdims=True)
        own = np.divide(own, total, out=self.corner_share[triangles].copy(), where=total > 0)
        pair = np.concatenate([sub_pairs, np.repeat(tri_pair, 3)])
        source = np.concatenate([sub_sources, self.corners[triangles].reshape(-1)])
        weight = np.concatenate([sub_weights, (tri_weight[:, None] * own).reshape(-1)])
        return sum_shares(pair, source, weight, len(points))


def subarea_spread(*arrays: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sub-area elements' weights on their triangles' corners, compiled when available
    (see :func:`numpy_subarea_spread`, the reference, for the arguments)."""
    fast = compiled.get()
    if fast is None:
        return numpy_subarea_spread(*arrays)
    *given, base = arrays
    ints = (0, 1, 3, 4, 7, 14)
    cast = [
        np.ascontiguousarray(a, dtype=np.int64 if i in ints else np.float64)
        for i, a in enumerate(given)
    ]
    pair, source, weight = fast.subarea_spread(*cast, int(base), RULE_POINTS, RULE_WEIGHTS)
    return pair, source, weight


def numpy_subarea_spread(
    sub_pair: np.ndarray,
    subareas: np.ndarray,
    sub_weight: np.ndarray,
    sub_ptr: np.ndarray,
    sub_tri: np.ndarray,
    tri_share: np.ndarray,
    corner_share: np.ndarray,
    corners: np.ndarray,
    tri_corners: np.ndarray,
    tri_normal: np.ndarray,
    points: np.ndarray,
    normals: np.ndarray,
    sub_point: np.ndarray,
    sub_reach: np.ndarray,
    src_ptr: np.ndarray,
    base: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where on a sub-area a receiver's visible weight of it lies, as corner weights.

    Within ``sub_reach`` of the sub-area's sample point, each corner of each of the
    sub-area's triangles weighs what the receiver sees of its part of the triangle
    (:func:`corner_form_factors`, a form factor), a hidden corner's weight going to
    the triangle's visible ones in proportion; where the receiver sees none of it, by
    area over them. A sub-area farther away hands its sampled weight to its mean
    (source ``base + s``, :class:`SubareaMeans`): spread by area over its receivers, as
    it would be, it would say no more than the mean, at the cost of an entry for each of
    them, and their count grows with refinement.

    Parameters
    ----------
    sub_pair, subareas, sub_weight : (A,) int64, int64, float64
        Pair index, global sub-area and sampled visible weight of each element.
    sub_ptr : (SA + 1,) int64
        CSR pointers of the sub-areas' triangles into ``sub_tri``.
    sub_tri : (T,) int64
        Triangles grouped by sub-area.
    tri_share : (T,) float64
        Area share of ``sub_tri[k]`` in its sub-area (0 for triangles no one sees).
    corner_share : (T, 3) float64
        Share of each triangle's corners, 0 for hidden ones (rows sum to 1 or 0).
    corners : (T, 3) int64
        Each triangle's receivers.
    tri_corners : (T, 3, 3) float64
        Corner positions [m].
    tri_normal : (T, 3) float64
        Unit normals.
    points, normals : (pairs, 3) float64
        Each pair's receiver position [m] and unit normal.
    sub_point, sub_reach : (SA, 3), (SA,) float64
        Sub-areas' sample points and the distance within which they spread by
        :func:`corner_form_factors` [m].
    src_ptr : (SA + 1,) int64
        CSR pointers of each sub-area's visible receivers (:class:`SubareaMeans`); a
        sub-area with none gets nothing.
    base : int
        The receiver count: sub-area ``s``'s mean is source ``base + s``.

    Returns
    -------
    pair, source : (N,) int64
        Pair and receiver (or ``base`` + sub-area) of each weight.
    weight : (N,) float64 >= 0
    """
    far = np.linalg.norm(points[sub_pair] - sub_point[subareas], axis=1) > sub_reach[subareas]
    handed = far & (src_ptr[subareas + 1] > src_ptr[subareas])  # a mean to hand on to
    near = np.flatnonzero(~far)
    element, slot = _csr_slots(sub_ptr, subareas[near])
    tri = sub_tri[slot]
    share = corner_share[tri]
    pair = sub_pair[near][element]
    raw = corner_form_factors(tri_corners[tri], tri_normal[tri], points[pair], normals[pair])
    kept = np.where(share > 0, raw, 0.0)
    seen = kept.sum(axis=1)
    kept *= np.divide(raw.sum(axis=1), seen, out=np.zeros_like(seen), where=seen > 0)[:, None]
    total = np.bincount(element, weights=kept.sum(axis=1), minlength=len(near))[element]
    by_area = (sub_weight[near][element] * tri_share[slot])[:, None] * share
    weight = np.where(total[:, None] > 0, kept, by_area)
    return (
        np.concatenate([sub_pair[handed], np.repeat(pair, 3)]),
        np.concatenate([base + subareas[handed], corners[tri].reshape(-1)]),
        np.concatenate([sub_weight[handed], weight.reshape(-1)]),
    )


def _csr_slots(pointer: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For CSR ``pointer`` and the (K,) ``rows`` picked: which pick each entry of the
    picked rows belongs to, and the entry's index, both (sum of row lengths,) int64."""
    counts = pointer[rows + 1] - pointer[rows]
    owner = np.repeat(np.arange(len(rows)), counts)
    index = np.repeat(pointer[rows] - np.cumsum(counts) + counts, counts)
    return owner, index + np.arange(len(owner))


#: The points of :func:`corner_form_factors`' rule as barycentric coordinates (9, 3), and
#: their weights (9,): the edge-midpoint rule on each of the four triangles a midpoint
#: split makes, i.e. the quarter points of the edges (weight 1) and the midpoints of the
#: inner edges (weight 2, each shared by two parts).
RULE_POINTS = np.array(
    [
        [0.75, 0.25, 0.0],
        [0.25, 0.75, 0.0],
        [0.0, 0.75, 0.25],
        [0.0, 0.25, 0.75],
        [0.25, 0.0, 0.75],
        [0.75, 0.0, 0.25],
        [0.5, 0.25, 0.25],
        [0.25, 0.5, 0.25],
        [0.25, 0.25, 0.5],
    ]
)
RULE_WEIGHTS = np.array([1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 2.0, 2.0, 2.0])


def corner_form_factors(
    triangles: np.ndarray, triangle_normals: np.ndarray, points: np.ndarray, normals: np.ndarray
) -> np.ndarray:
    """(N, 3) unoccluded form factor from a receiver to each corner's part of a triangle:
    the integral over the triangle of the point-to-point kernel
    ``cos(theta_r) cos(theta_s) / (pi r**2)`` times the corner's barycentric coordinate.

    For far sub-areas, whose single sample says how much of them a receiver sees but not
    where: spreading that weight equally over the corners would give a receiver just above
    a floor the floor's mean across the sub-area, when it sees mostly the part nearest it.
    Integrated by the edge-midpoint rule (exact for quadratics) on the triangle's four
    midpoint-split parts (:data:`RULE_POINTS`, 9 kernel values): at 2 triangle sizes from
    the receiver, the corner shares are within 0.002 of the exact ones and the sum within
    0.1 % of the exact factor (the plain edge-midpoint rule: 0.02 and 1 %).

    Parameters
    ----------
    triangles : (N, 3, 3) float64
        Corners [m].
    triangle_normals : (N, 3) float64
        Their unit normals.
    points, normals : (N, 3) float64
        Receiver positions [m] and unit normals.

    Returns
    -------
    (N, 3) float64 >= 0 [1]; all 0 where the receiver sees none of the rule's points.
    """
    at = np.einsum("qk,nkj->nqj", RULE_POINTS, triangles)
    d = at - points[:, None, :]
    r2 = np.einsum("nqj,nqj->nq", d, d)
    cos_r = np.maximum(np.einsum("nqj,nj->nq", d, normals), 0.0)
    cos_s = np.maximum(-np.einsum("nqj,nj->nq", d, triangle_normals), 0.0)
    kernel = np.divide(cos_r * cos_s, r2 * r2, out=np.zeros_like(r2), where=r2 > 0)
    area = 0.5 * np.linalg.norm(
        np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]), axis=1
    )
    return area[:, None] / (12.0 * np.pi) * ((kernel * RULE_WEIGHTS) @ RULE_POINTS)


def sum_shares(
    pair: np.ndarray, source: np.ndarray, weight: np.ndarray, pairs: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weights summed per (pair, source), compiled when available (see
    :func:`numpy_sum_shares`, the reference)."""
    fast = compiled.get()
    if fast is None:
        return numpy_sum_shares(pair, source, weight, pairs)
    pointer, sources, weights = fast.sum_shares(
        np.ascontiguousarray(pair, dtype=np.int64),
        np.ascontiguousarray(source, dtype=np.int64),
        np.ascontiguousarray(weight, dtype=np.float64),
        int(pairs),
    )
    return pointer, sources, weights


def numpy_sum_shares(
    pair: np.ndarray, source: np.ndarray, weight: np.ndarray, pairs: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positive weights summed per (pair, source) and normalised per pair; the others are
    left out.

    Parameters
    ----------
    pair, source : (N,) int
        Pair index (any order) and receiver of each weight.
    weight : (N,) float64
    pairs : int

    Returns
    -------
    pointer : (pairs + 1,) int64, CSR by pair
    sources : (S,) int64, ascending within a pair
    weights : (S,) float64, summing to 1 per pair
    """
    keep = weight > 0
    pair, source, weight = pair[keep], source[keep], weight[keep]
    stride = int(source.max(initial=0)) + 1
    unique, inverse = np.unique(pair * stride + source, return_inverse=True)
    summed = np.bincount(inverse.reshape(-1), weights=weight)
    owner, sources = unique // stride, unique % stride
    totals = np.bincount(owner, weights=summed, minlength=pairs)
    pointer = np.searchsorted(owner, np.arange(pairs + 1)).astype(np.int64)
    return pointer, sources.astype(np.int64), summed / totals[owner]


def near_field_irradiance(
    gathers: list[tuple[int, np.ndarray, GatherWeights]],
    radiosity: np.ndarray,
    patch_radiosity: np.ndarray,
    factors: np.ndarray,
    receiver_area: np.ndarray,
    means: SubareaMeans,
) -> np.ndarray:
    """Irradiance a receiver gets beyond the patch means: sum_p F_jp (B̃_jp - B̄_p) at
    near receivers, less the same power taken from the far ones.

    The solver's shots conserve power (:func:`raytrad.core.solver._conserve`): what the
    near receivers of a patch gain or lose against the mean, its far receivers lose or
    gain in proportion to ``a_j F_jp``. This is the same operator on a whole radiosity.

    Parameters
    ----------
    gathers : list of (patch, factors, GatherWeights)
        Each patch with near receivers: its (balanced) factors to them and its weights.
    radiosity : (R, 3) float [W m-2]
        Receiver radiosity.
    patch_radiosity : (P, 3) float [W m-2]
        Patch means of ``radiosity`` (``W B``).
    factors : (R, P) float
        The dense form-factor matrix, near factors included [1].
    receiver_area : (R,) float [m2]
    means : SubareaMeans
        Of the mesh (the gather's sources beyond its receivers).

    Returns
    -------
    (R, 3) float64 [W m-2]
    """
    out = np.zeros_like(radiosity, dtype=np.float64)
    extended = means.extend(radiosity)
    for patch, near_factors, gather in gathers:
        excess = near_factors[:, None] * (gather.gathered(extended) - patch_radiosity[patch])
        np.add.at(out, gather.receivers, excess)
        column = np.array(factors[:, patch], dtype=np.float64)
        column[gather.receivers] = 0.0
        caught = float(receiver_area @ column)
        if not caught > 0.0:
            column = np.zeros_like(column)
            column[gather.receivers] = near_factors
            caught = float(receiver_area @ column)
        if caught > 0.0:
            power = receiver_area[gather.receivers] @ excess  # (3,) [W]
            out -= column[:, None] * (power / caught)[None, :]
    return out
