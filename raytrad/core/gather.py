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

import numpy as np

from raytrad.core import compiled
from raytrad.core.mesh import RadiosityMesh

#: Pairs whose receiver is nearer than this many patch radii to the patch's centre gather
#: the patch's radiosity as it varies across it.
GATHER_RADII = 3.0


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
        Receivers of the patch the radiosity is gathered from.
    weights : (S,) float64
        Their share; each near receiver's shares sum to 1.
    """

    receivers: np.ndarray
    factors: np.ndarray
    pointer: np.ndarray
    sources: np.ndarray
    weights: np.ndarray

    def gathered(self, radiosity: np.ndarray) -> np.ndarray:
        """(G, 3) radiosity each near receiver sees on the patch [W m-2]."""
        values = self.weights[:, None] * radiosity[self.sources]
        sums = np.cumsum(np.vstack([np.zeros((1, 3)), values]), axis=0)
        return np.asarray(sums[self.pointer[1:]] - sums[self.pointer[:-1]])

    def subset(self, keep: np.ndarray) -> GatherWeights:
        """Only the near receivers where ``keep`` ((G,) bool) holds."""
        counts = np.diff(self.pointer)[keep]
        starts = self.pointer[:-1][keep]
        index = np.repeat(starts - np.cumsum(counts) + counts, counts) + np.arange(counts.sum())
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


def gathered_irradiance(
    rows: GatherRows, radiosity: np.ndarray, patch_radiosity: np.ndarray
) -> np.ndarray:
    """(N, 3) irradiance [W m-2] the points of ``rows`` gather from a solution: receiver
    ``radiosity`` (R, 3) and its patch means ``patch_radiosity`` (P, 3) [W m-2]."""
    irradiance = np.zeros((rows.count, 3))
    for patch, near, factors, gather in rows.patches:
        irradiance[near] += factors[:, None] * patch_radiosity[patch]
        if len(gather.receivers):
            excess = gather.gathered(radiosity) - patch_radiosity[patch]
            local = gather.receivers
            irradiance[near[local]] += factors[local, None] * excess
    return irradiance


class GatherShares:
    """How a unit of visible weight on a triangle or a sub-area spreads over receivers.

    A near triangle's weight goes to its visible corners by the shares it comes with
    (what the receiver sees of each part of it); a sub-area's to its triangles by area,
    then to their visible corners equally. Hidden receivers (shut in under a block)
    get nothing: their radiosity is not what the triangle shows.
    """

    def __init__(self, mesh: RadiosityMesh, sub_tri: np.ndarray, sub_ptr: np.ndarray) -> None:
        corners = mesh.triangle_receivers
        visible = (
            np.ones(mesh.receiver_count, bool)
            if mesh.receiver_visible is None
            else np.asarray(mesh.receiver_visible, bool)
        )
        share = visible[corners].astype(np.float64)
        counts = share.sum(axis=1, keepdims=True)
        #: (T, 3) share of each corner of each triangle
        self.corner_share = np.divide(share, counts, out=np.zeros_like(share), where=counts > 0)
        self.corners = corners
        # sub-area s: its triangles (sub_tri[sub_ptr[s]:sub_ptr[s+1]]) weighted by area
        area = mesh.triangle_area[sub_tri] * (counts[sub_tri, 0] > 0)
        owner = np.repeat(np.arange(len(sub_ptr) - 1), np.diff(sub_ptr))
        total = np.bincount(owner, weights=area, minlength=len(sub_ptr) - 1)
        self.sub_tri = sub_tri
        self.sub_ptr = sub_ptr
        self.tri_share = np.divide(
            area, total[owner], out=np.zeros_like(area), where=total[owner] > 0
        )

    def spread(
        self,
        sub_pair: np.ndarray,
        subareas: np.ndarray,
        sub_weight: np.ndarray,
        tri_pair: np.ndarray,
        triangles: np.ndarray,
        tri_weight: np.ndarray,
        tri_share: np.ndarray,
        pairs: int,
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
        pairs : int
            Number of pairs.

        Returns
        -------
        pointer : (pairs + 1,) int64
        sources : (S,) int64
        weights : (S,) float64, normalised to sum 1 per pair (pairs with no weight: empty)
        """
        counts = self.sub_ptr[subareas + 1] - self.sub_ptr[subareas]
        element = np.repeat(np.arange(len(subareas)), counts)
        offset = np.arange(len(element)) - np.repeat(np.cumsum(counts) - counts, counts)
        slot = np.repeat(self.sub_ptr[subareas], counts) + offset
        tri = np.concatenate([self.sub_tri[slot], triangles])
        weight = np.concatenate([sub_weight[element] * self.tri_share[slot], tri_weight])
        pair = np.concatenate([sub_pair[element], tri_pair])
        source = self.corners[tri].reshape(-1)
        seen = self.corner_share[triangles] > 0
        own = np.where(seen, tri_share, 0.0)
        total = own.sum(axis=1, keepdims=True)
        own = np.divide(own, total, out=self.corner_share[triangles].copy(), where=total > 0)
        corner_share = np.concatenate([self.corner_share[self.sub_tri[slot]], own])
        weight = (weight[:, None] * corner_share).reshape(-1)
        pair = np.repeat(pair, 3)
        keep = weight > 0
        return sum_shares(pair[keep], source[keep], weight[keep], pairs)


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
    """Positive weights summed per (pair, source) and normalised per pair.

    Parameters
    ----------
    pair, source : (N,) int
        Pair index (any order) and receiver of each weight.
    weight : (N,) float64
        Positive weights.
    pairs : int

    Returns
    -------
    pointer : (pairs + 1,) int64, CSR by pair
    sources : (S,) int64, ascending within a pair
    weights : (S,) float64, summing to 1 per pair
    """
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

    Returns
    -------
    (R, 3) float64 [W m-2]
    """
    out = np.zeros_like(radiosity, dtype=np.float64)
    for patch, near_factors, gather in gathers:
        excess = near_factors[:, None] * (gather.gathered(radiosity) - patch_radiosity[patch])
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
