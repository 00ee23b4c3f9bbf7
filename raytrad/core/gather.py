"""The near-field gather: a receiver close to a shooting patch sees the patch's radiosity
as it varies across it, not its mean.

Shooting delivers each patch's *mean* radiosity B̄_p to every receiver (equation 1 of
:mod:`raytrad.core.solver`). A receiver a few patch sizes away from a patch straddling a
shadow edge (a point on a block's side just above the floor, beside a floor patch half in
the block's shadow) sees mostly one part of it, whose radiosity can be far from the mean:
the bias does not shrink with more receivers, only with smaller patches.

So for every (receiver, patch) pair nearer than :data:`GATHER_RADII` patch radii, the
form-factor engine also keeps where on the patch the receiver's visible factor comes
from: the visible weight of each sub-area sample and cluster (disk approximation) and of
each near triangle (exact factor), spread onto the patch's receivers and onto the means
of its sub-areas and clusters (:mod:`raytrad.core.spread`). The gathered radiosity is then

    B̃_jp = sum_k g_jpk B_k,       sum_k g_jpk = 1,

and the solve converges to ``B_j = E_j + rho_j sum_p F_jp (B̄_p + [B̃_jp - B̄_p])``: the
bracket, summed over near pairs, is :func:`near_field_irradiance`, added to the shooting
solution as a correction that is itself shot on (:func:`raytrad.core.solver.solve`).
"""

from __future__ import annotations

import functools
import itertools
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from raytrad.core import compiled
from raytrad.core.clusters import Clusters, build_clusters, runs
from raytrad.core.mesh import RadiosityMesh
from raytrad.core.visibility import worker_count

#: Pairs whose receiver is nearer than this many patch radii to the patch's centre gather
#: the patch's radiosity as it varies across it.
GATHER_RADII = 6.0

#: A sub-area nearer than this many of its sizes (bounding-box diagonals) to a receiver
#: spreads the receiver's weight of it by what the receiver sees of each of its triangles'
#: corners (:func:`corner_form_factors`); a farther one by area over its receivers.
MIDPOINT_SIZES = 5.0
#: Node slots (a triangle counted once for each node holding it) per batch while the
#: means are summed: bounds the temporaries at a million receivers.
MEAN_SLOTS = 1 << 18


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
        """Only the near receivers where ``keep`` ((G,) bool) holds (itself when it holds
        everywhere; the same entries when only rows without any are dropped)."""
        keep = np.asarray(keep, dtype=bool)
        if keep.all():
            return self
        ends = self.pointer[1:]
        if (ends[~keep] == self.pointer[:-1][~keep]).all():  # empty rows alone go
            pointer = np.concatenate([self.pointer[:1], ends[keep]])
            return GatherWeights(
                self.receivers[keep], self.factors[keep], pointer, self.sources, self.weights
            )
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
    (indices), their balanced factors and their near-field gather weights; ``row_sum`` and
    ``raw_sum`` (N,) sum them balanced and before the column scales."""

    count: int
    row_sum: np.ndarray
    patches: list[tuple[int, np.ndarray, np.ndarray, GatherWeights]]
    means: SubareaMeans | None = None  # the sources beyond the receivers
    raw_sum: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.raw_sum = np.zeros(self.count)

    def add(
        self,
        patch: int,
        near: np.ndarray,
        factors: np.ndarray,
        gather: GatherWeights,
        scale: float = 1.0,
    ) -> None:
        """Patch ``patch``'s row: the points ``near`` (indices, each once) that see it,
        their ``factors`` before the patch's column ``scale`` and their gather weights."""
        fast = compiled.get()
        if fast is None or factors.dtype != np.float64:
            self.raw_sum[near] += factors
            factors = factors * scale
            self.row_sum[near] += factors
        else:  # the same sums in one loop (the fancy indexing held the GIL for 0.6 s)
            scaled = np.empty(len(factors))
            fast.add_row(
                self.raw_sum,
                self.row_sum,
                np.ascontiguousarray(near, dtype=np.int64),
                np.ascontiguousarray(factors),
                float(scale),
                scaled,
            )
            factors = scaled
        self.patches.append((patch, near, factors, gather))

    @functools.cached_property
    def read_nodes(self) -> np.ndarray:
        """(K,) int64: the nodes whose means the rows' gather weights read, ascending
        (none without ``means``); read once the rows are complete."""
        if self.means is None:
            return np.zeros(0, dtype=np.int64)
        base = self.means.base
        read = np.zeros(len(self.means.pointer) - 1, dtype=bool)
        for _, _, _, g in self.patches:
            read[g.sources[g.sources >= base] - base] = True
        return np.flatnonzero(read)


def gathered_irradiance(
    rows: GatherRows, radiosity: np.ndarray, patch_radiosity: np.ndarray
) -> np.ndarray:
    """(N, 3) irradiance [W m-2] the points of ``rows`` gather from a solution: receiver
    ``radiosity`` (R, 3) and its patch means ``patch_radiosity`` (P, 3) [W m-2]; compiled
    when available (see :func:`numpy_gathered_irradiance`, the reference: the same sums in
    the same order)."""
    if rows.means is not None:  # only the means the rows read (a few new points' worth)
        radiosity = rows.means.extend(radiosity, rows.read_nodes)
    fast = compiled.get()
    if fast is None:
        return numpy_gathered_irradiance(rows, radiosity, patch_radiosity)
    irradiance = np.zeros((rows.count, 3))
    radiosity = np.ascontiguousarray(radiosity, dtype=np.float64)
    patch_radiosity = np.ascontiguousarray(patch_radiosity, dtype=np.float64)
    for patch, near, factors, gather in rows.patches:
        fast.block_irradiance(
            irradiance,
            patch_radiosity[patch],
            np.ascontiguousarray(near, dtype=np.int64),
            np.ascontiguousarray(factors, dtype=np.float64),
            gather.receivers,
            gather.pointer,
            gather.sources,
            gather.weights,
            radiosity,
        )
    return irradiance


def numpy_gathered_irradiance(
    rows: GatherRows, radiosity: np.ndarray, patch_radiosity: np.ndarray
) -> np.ndarray:
    """:func:`gathered_irradiance` in numpy, ``radiosity`` extended by the means the rows
    read: per patch, ``F B̄_p`` at every point that sees it, then ``F (B̃ - B̄_p)`` at its
    near-field points."""
    irradiance = np.zeros((rows.count, 3))
    for patch, near, factors, gather in rows.patches:
        irradiance[near] += factors[:, None] * patch_radiosity[patch]
        if len(gather.receivers):
            excess = gather.gathered(radiosity) - patch_radiosity[patch]
            local = gather.receivers
            irradiance[near[local]] += factors[local, None] * excess
    return irradiance


@dataclass(frozen=True)
class SubareaMeans:
    """Each sub-area's and cluster's mean radiosity as a source of the near-field gather.

    A receiver far from a sub-area (beyond :data:`MIDPOINT_SIZES` of its sizes) spreads
    its weight of the sub-area by area over the sub-area's visible receivers: that says
    no more than their area-weighted mean. So its gather weights name the mean instead,
    as source ``base + s``, one entry whatever the sub-area's receiver count (which grows
    with refinement); :meth:`extend` appends the means to a radiosity. The clusters inside
    a sub-area (:mod:`raytrad.core.clusters`) are sources the same way, one entry for a
    cluster far from the receiver in its own sizes; node ``n`` of the cluster tree is
    source ``base + n`` (sub-area ``s`` is node ``s`` where no sub-area is split).

    Attributes
    ----------
    base : int
        The mesh's receiver count.
    pointer : (N + 1,) int64
        CSR pointers into ``receivers`` and ``shares`` by node.
    receivers : (Q,) int64
        Each node's visible receivers (corners of its triangles).
    shares : (Q,) float64
        Their area shares, summing to 1 per node with any.
    patch_ptr : (P + 1,) int64
        Each patch's nodes (CSR pointers; a shot makes its patch's means).
    """

    base: int
    pointer: np.ndarray
    receivers: np.ndarray
    shares: np.ndarray
    patch_ptr: np.ndarray

    def extend(self, radiosity: np.ndarray, nodes: np.ndarray | None = None) -> np.ndarray:
        """(R + N, 3) the (R, 3) receiver ``radiosity`` followed by its nodes' means: of
        every node, or only of ``nodes`` ((K,) int, the ones a gather reads; the others
        are left 0).

        Raises
        ------
        ValueError
            ``radiosity`` is not of this mesh's R receivers (the means would land at the
            wrong sources).
        """
        if len(radiosity) != self.base:
            raise ValueError(f"radiosity of {len(radiosity)} receivers for a mesh of {self.base}")
        count = len(self.pointer) - 1
        if nodes is not None:
            out = np.zeros((self.base + count, 3))
            out[: self.base] = radiosity
            out[self.base + nodes] = self.of(nodes, radiosity)
            return out
        owner = np.repeat(np.arange(count), np.diff(self.pointer))
        means = _weighted_sums(owner, self.shares, self.receivers, radiosity, count)
        return np.concatenate([radiosity, means])

    def of(self, nodes: np.ndarray, radiosity: np.ndarray) -> np.ndarray:
        """(K, 3) means of ``radiosity`` ((R, 3) or longer) over the (K,) ``nodes``."""
        owner, index = _csr_slots(self.pointer, nodes)
        return _weighted_sums(
            owner, self.shares[index], self.receivers[index], radiosity, len(nodes)
        )


def _weighted_sums(
    owner: np.ndarray,
    shares: np.ndarray,
    receivers: np.ndarray,
    radiosity: np.ndarray,
    count: int,
) -> np.ndarray:
    """(count, 3) ``sum shares * radiosity[receivers]`` per ``owner``, a channel at a time
    (no (Q, 3) temporaries: at a million receivers a refinement round's means read about
    eight million shares)."""
    out = np.empty((count, 3))
    for k in range(3):
        out[:, k] = np.bincount(owner, weights=shares * radiosity[receivers, k], minlength=count)
    return out


def subarea_triangles(mesh: RadiosityMesh) -> tuple[np.ndarray, np.ndarray]:
    """The triangles grouped by sub-area ((T,) int64, ascending within one) and CSR
    pointers into them ((SA + 1,) int64)."""
    order = np.lexsort((np.arange(len(mesh.triangle_subarea)), mesh.triangle_subarea))
    return order, np.searchsorted(mesh.triangle_subarea[order], np.arange(mesh.subarea_count + 1))


def subarea_means(mesh: RadiosityMesh) -> SubareaMeans:
    """The sub-area and cluster means of ``mesh`` (as :class:`GatherShares` makes them)."""
    sub_tri, sub_ptr = subarea_triangles(mesh)
    return cluster_means(mesh, corner_shares(mesh), build_clusters(mesh, sub_tri, sub_ptr))


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


def visible_areas(mesh: RadiosityMesh, corner_share: np.ndarray) -> np.ndarray:
    """(T,) each triangle's area where any of its corners is visible, else 0 [m2]
    (``corner_share`` (T, 3), :func:`corner_shares`): what a mean or a spread by area
    weighs it."""
    return np.asarray(mesh.triangle_area * (corner_share.sum(axis=1) > 0))


def cluster_means(mesh: RadiosityMesh, corner_share: np.ndarray, tree: Clusters) -> SubareaMeans:
    """Each node of ``tree`` (sub-areas and their clusters) as an area-weighted mean of its
    visible receivers: a triangle weighs its area if any corner is visible (``corner_share``
    (T, 3), :func:`corner_shares`), split over those corners.

    The nodes go in batches of at most :data:`MEAN_SLOTS` slots (nodes share slots with
    their halves), on every core (:func:`~raytrad.core.visibility.worker_count`): each
    refinement round rebuilds these means for the whole mesh while nothing else runs."""
    visible_area = visible_areas(mesh, corner_share)
    lengths = np.cumsum(tree.stop - tree.start)
    workers = worker_count()
    slots = int(lengths[-1]) if len(lengths) else 0
    share = -(-slots // workers)  # a core's share, rounded up
    step = min(MEAN_SLOTS, max(MEAN_SLOTS // 64, share))
    bounds = [0]
    while bounds[-1] < tree.count:
        first = bounds[-1]
        bounds.append(max(first + 1, int(np.searchsorted(lengths, lengths[first] + step))))

    def batch(span: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        nodes = slice(*span)
        return node_means(
            tree.start[nodes],
            tree.stop[nodes],
            tree.sub_tri,
            visible_area,
            mesh.triangle_receivers,
            corner_share,
            mesh.receiver_count,
        )

    spans = list(itertools.pairwise(bounds))
    if len(spans) > 1 and workers > 1:
        with ThreadPoolExecutor(min(workers, len(spans))) as pool:
            parts = list(pool.map(batch, spans))
    else:
        parts = [batch(span) for span in spans]
    pointers = [np.zeros(1, np.int64)]
    for pointer, _, _ in parts:
        pointers.append(pointer[1:] + pointers[-1][-1])
    return SubareaMeans(
        mesh.receiver_count,
        np.concatenate(pointers),
        np.concatenate([np.zeros(0, np.int64)] + [part[1] for part in parts]),
        np.concatenate([np.zeros(0)] + [part[2] for part in parts]),
        tree.patch_ptr,
    )


def node_means(
    start: np.ndarray,
    stop: np.ndarray,
    sub_tri: np.ndarray,
    visible_area: np.ndarray,
    corners: np.ndarray,
    corner_share: np.ndarray,
    receivers: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each node's area-weighted mean of its visible receivers, compiled when available
    (see :func:`numpy_node_means`, the reference: the same sums in the same order)."""
    fast = compiled.get()
    if fast is None:
        return numpy_node_means(
            start, stop, sub_tri, visible_area, corners, corner_share, receivers
        )
    return fast.node_means(
        np.ascontiguousarray(start, dtype=np.int64),
        np.ascontiguousarray(stop, dtype=np.int64),
        np.ascontiguousarray(sub_tri, dtype=np.int64),
        np.ascontiguousarray(visible_area, dtype=np.float64),
        np.ascontiguousarray(corners, dtype=np.int64),
        np.ascontiguousarray(corner_share, dtype=np.float64),
        int(receivers),
    )


def numpy_node_means(
    start: np.ndarray,
    stop: np.ndarray,
    sub_tri: np.ndarray,
    visible_area: np.ndarray,
    corners: np.ndarray,
    corner_share: np.ndarray,
    receivers: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each node's area-weighted mean of its visible receivers.

    Parameters
    ----------
    start, stop : (K,) int64
        Each node's slots ``start:stop`` of ``sub_tri``.
    sub_tri : (S,) int64
        Triangles (:class:`~raytrad.core.clusters.Clusters` ``sub_tri``).
    visible_area : (T,) float64
        Each triangle's weight [m2] (:func:`visible_areas`).
    corners : (T, 3) int64
        Each triangle's receivers, below ``receivers``.
    corner_share : (T, 3) float64
        Each corner's share of its triangle (:func:`corner_shares`).
    receivers : int
        The receiver count (the length of the compiled loop's scratch row).

    Returns
    -------
    pointer : (K + 1,) int64
    sources : (Q,) int64, receivers ascending within a node
    weights : (Q,) float64, summing to 1 a node (none for a node with no visible area)
    """
    owner, slots = runs(start, stop)
    tri = sub_tri[slots]
    area = visible_area[tri]
    total = np.bincount(owner, weights=area, minlength=len(start))[owner]
    share = np.divide(area, total, out=np.zeros_like(area), where=total > 0)
    return numpy_sum_shares(
        np.repeat(owner, 3),
        corners[tri].reshape(-1),
        (share[:, None] * corner_share[tri]).reshape(-1),
        len(start),
    )


def _csr_slots(pointer: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For CSR ``pointer`` and the (K,) ``rows`` picked: which pick each entry of the
    picked rows belongs to, and the entry's index, both (sum of row lengths,) int64."""
    counts = pointer[rows + 1] - pointer[rows]
    owner = np.repeat(np.arange(len(rows)), counts)
    index = np.repeat(pointer[rows] - np.cumsum(counts) + counts, counts)
    return owner, index + np.arange(len(owner))


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
