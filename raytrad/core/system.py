"""The discrete radiosity system's static arrays: the patch-average matrix W and what
the solver reads per receiver and per patch.

A patch's radiosity is the area-weighted mean of its receivers', ``B_p = sum_k W_pk B_k``
with ``W_pk = (a_k / 3 summed over the patch's triangles at k) / A_p`` (hidden receivers
count for nothing). :class:`DiscreteSystem` holds W as CSR by receiver and by patch, and
computes what the solver needs of it per shot.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from raytrad.core import compiled
from raytrad.core.gather import SubareaMeans, subarea_means
from raytrad.core.mesh import RadiosityMesh

#: Blocks the compiled shot splits a column into, each summed apart and added in order
#: (:mod:`raytrad.core._compiled_solver`): fixed, so that a shot's sums are the same on
#: one thread or several.
SHOT_BLOCKS = 8
#: Bytes :class:`ShotPlans` may hold; a column beyond them finds its plan at every shot.
PLAN_BYTES = 64 << 20


class ShotPlans:
    """What the compiled shots of one column share, its plan (see ``shoot`` in
    :mod:`raytrad.core._compiled_solver`): the rows of its near receivers in the column
    ((G,) int32), its sums ((5,) [m2]) and the patches its far receivers change with
    their sums ((Q,) int32, (Q, 3) [1]). Kept per patch for one form-factor engine and
    its balancing scales, in at most :data:`PLAN_BYTES`. A column's first shot finds its
    plan, the next ones read it; a column whose plan is not kept finds it at every shot,
    the same to the bit."""

    def __init__(self) -> None:
        self._engine: Any = None
        self._plans: dict[int, tuple[tuple[np.ndarray, ...], Any, float, int]] = {}
        self.bytes = 0

    def get(
        self, engine: Any, patch: int, near_count: int, scales: tuple[Any, float]
    ) -> tuple[tuple[np.ndarray, ...], bool]:
        """(the plan's four arrays, whether they are known) for the column of ``patch``
        of ``engine`` at balancing ``scales`` (row scales, column scale); arrays for the
        shot to fill, with False, until :meth:`keep` has kept them."""
        if self._engine is None or self._engine() is not engine:
            self._engine = weakref.ref(engine)
            self._plans.clear()
            self.bytes = 0
        plan = self._plans.get(patch)
        if plan is not None and plan[1] is scales[0] and plan[2] == scales[1]:
            return plan[0], True
        empty = (np.zeros(near_count, np.int32), np.zeros(5), np.zeros(0, np.int32))
        return (*empty, np.zeros((0, 3))), False

    def keep(self, patch: int, plan: tuple[np.ndarray, ...], scales: tuple[Any, float]) -> None:
        """Keep the plan a shot of ``patch`` found (in place of one for other scales),
        while the bytes allow."""
        size = sum(array.nbytes for array in plan) + 512  # the tuples, the arrays' headers
        stale = self._plans.pop(patch, None)
        if stale is not None:
            self.bytes -= stale[3]
        if self.bytes + size <= PLAN_BYTES:
            self.bytes += size
            self._plans[patch] = (plan, scales[0], scales[1], size)


@dataclass(frozen=True)
class DiscreteSystem:
    """Static arrays of the discrete system."""

    patch_area: np.ndarray  # (P,)
    patch_reflectance: np.ndarray  # (P, 3)
    receiver_area: np.ndarray  # (R,)
    receiver_reflectance: np.ndarray  # (R, 3)
    receiver_emission: np.ndarray  # (R, 3)
    receiver_ptr: np.ndarray  # (R + 1,) CSR rows of W^T
    entry_patch: np.ndarray  # (nnz,)
    entry_weight: np.ndarray  # (nnz,) W[patch, receiver]
    entry_receiver: np.ndarray  # (nnz,)
    patch_entries: np.ndarray  # (nnz,) entries grouped by patch
    patch_ptr: np.ndarray  # (P + 1,) CSR pointers into patch_entries
    patch_receiver: np.ndarray  # (nnz,) entry_receiver[patch_entries], read by patch
    patch_weight: np.ndarray  # (nnz,) entry_weight[patch_entries], read by patch
    subarea_means: SubareaMeans  # the near-field gather's sources beyond the receivers
    patch_nodes: np.ndarray  # (P + 1,) each patch's sub-areas and clusters, CSR pointers
    scratch: np.ndarray  # (R + N, 3) zeros, a work array of _shoot
    touched: np.ndarray  # (P,) bool: the patches a shot changed (see respread)
    held: np.ndarray  # (SHOT_BLOCKS, P, 3) zeros, a work array of the compiled shot
    far_held: np.ndarray  # (SHOT_BLOCKS, P, 3) zeros, another
    spread_drift: np.ndarray  # (P, 3) how far each patch's stored spread may be off [W m-2]
    plans: ShotPlans = field(default_factory=ShotPlans)  # the compiled shot's, per column

    @classmethod
    def from_mesh(cls, mesh: RadiosityMesh, means: SubareaMeans | None = None) -> DiscreteSystem:
        """The system of ``mesh``; ``means`` are its sub-area means when the caller has
        them (the form-factor engine's, whose gather weights name them), else made here."""
        tri_patch = np.repeat(mesh.triangle_patch, 3)
        receiver = mesh.triangle_receivers.reshape(-1)
        weight = np.repeat(mesh.triangle_area / 3.0, 3) / mesh.patch_area[tri_patch]
        if mesh.receiver_visible is not None:  # hidden receivers do not count
            weight = weight * mesh.receiver_visible[receiver]
        # merge duplicate (receiver, patch) entries
        key = receiver * mesh.patch_count + tri_patch
        uniq, inverse = np.unique(key, return_inverse=True)
        w = np.bincount(inverse.reshape(-1), weights=weight)
        r = uniq // mesh.patch_count
        ptr = np.searchsorted(r, np.arange(mesh.receiver_count + 1))
        entry_patch = uniq % mesh.patch_count
        by_patch = np.argsort(entry_patch, kind="stable")
        means = subarea_means(mesh) if means is None else means
        return cls(
            patch_area=mesh.patch_area,
            patch_reflectance=mesh.patch_reflectance,
            receiver_area=mesh.receiver_area,
            receiver_reflectance=mesh.receiver_reflectance,
            receiver_emission=mesh.receiver_emitted_exitance,
            receiver_ptr=ptr,
            entry_patch=entry_patch,
            entry_weight=w,
            entry_receiver=r,
            patch_entries=by_patch,
            patch_receiver=r[by_patch],
            patch_weight=w[by_patch],
            patch_ptr=np.searchsorted(entry_patch[by_patch], np.arange(mesh.patch_count + 1)),
            subarea_means=means,
            patch_nodes=means.patch_ptr,
            scratch=np.zeros((mesh.receiver_count + len(means.pointer) - 1, 3)),
            touched=np.zeros(mesh.patch_count, dtype=bool),
            held=np.zeros((SHOT_BLOCKS, mesh.patch_count, 3)),
            far_held=np.zeros((SHOT_BLOCKS, mesh.patch_count, 3)),
            spread_drift=np.zeros((mesh.patch_count, 3)),
        )

    def spread(
        self, radiosity: np.ndarray, entry_shot: np.ndarray, unshot: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """How the receivers of each patch differ in what they still have to shoot.

        Compiled when available (:mod:`raytrad.core.compiled`); :meth:`numpy_spread` is
        the reference.

        Parameters
        ----------
        radiosity : (R, 3) float64
            Radiosity of each receiver, ``emission + reflectance * irradiance`` [W m-2].
        entry_shot : (nnz, 3) float64
            Radiosity each (patch, receiver) entry has shot [W m-2].
        unshot : (P, 3) float64
            Unshot radiosity of each patch [W m-2].

        Returns
        -------
        spread : (P, 3) float64, ``sum_k W_pk |dB_pk - dB_p|`` [W m-2]
        peak : (P, 3) float64, ``max_k |dB_pk|`` [W m-2]
        """
        fast = compiled.get()
        if fast is None:
            return self.numpy_spread(radiosity, entry_shot, unshot)
        count = len(self.patch_area)
        zeros = (np.zeros((count, 3)), np.zeros((count, 3)))
        return self._sum_rows(fast, np.arange(count), *zeros, (radiosity, entry_shot, unshot))

    def respread(
        self,
        spread: np.ndarray,
        peak: np.ndarray,
        radiosity: np.ndarray,
        entry_shot: np.ndarray,
        unshot: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`spread` after a shot, from the spread and peak before it: only the
        patches the shot marked in :attr:`touched` (those with a receiver in its column,
        whose radiosity and unshot radiosity changed, and the shooter, whose receivers'
        shots changed) are summed again, each over its entries in the order
        :meth:`spread` takes them, so the result is :meth:`spread`'s to the bit; the marks
        are cleared. Arguments as :meth:`spread`, ``spread`` and ``peak`` (P, 3)."""
        rows = np.flatnonzero(self.touched)
        self.touched[:] = False
        fast = compiled.get()
        if fast is None:
            return self.spread(radiosity, entry_shot, unshot)
        shots = (radiosity, entry_shot, unshot)
        return self._sum_rows(fast, rows, np.array(spread), np.array(peak), shots)

    def _sum_rows(
        self,
        fast: Any,
        rows: np.ndarray,
        spread: np.ndarray,
        peak: np.ndarray,
        shots: tuple[np.ndarray, np.ndarray, np.ndarray],
    ) -> tuple[np.ndarray, np.ndarray]:
        """``spread`` and ``peak`` with the patches ``rows`` summed again by the compiled
        kernels ``fast``, in place (each patch over its entries in ascending order);
        ``shots`` is (radiosity, entry_shot, unshot) as :meth:`spread` takes them."""
        radiosity, entry_shot, unshot = shots
        fast.patch_spread_rows(
            rows,
            self.patch_entries,
            self.patch_ptr,
            self.patch_receiver,
            self.patch_weight,
            np.ascontiguousarray(radiosity),
            np.ascontiguousarray(entry_shot),
            np.ascontiguousarray(unshot),
            spread,
            peak,
        )
        return spread, peak

    def numpy_spread(
        self, radiosity: np.ndarray, entry_shot: np.ndarray, unshot: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`spread` in numpy (the reference)."""
        own = radiosity[self.entry_receiver] - entry_shot
        deviation = self.entry_weight[:, None] * np.abs(own - unshot[self.entry_patch])
        count = len(self.patch_area)
        peak = np.zeros((count, 3))
        np.maximum.at(peak, self.entry_patch, np.abs(own))
        spread = np.stack(
            [np.bincount(self.entry_patch, deviation[:, c], minlength=count) for c in range(3)],
            axis=1,
        )
        return spread, peak

    def receiver_radiosity(
        self, irradiance: np.ndarray, receivers: np.ndarray | None = None
    ) -> np.ndarray:
        """(K, 3) ``emission + reflectance * irradiance`` [W m-2] of the (K,) ``receivers``
        (every one when None) from their (K, 3) irradiance [W m-2]."""
        if receivers is None:
            return np.asarray(self.receiver_emission + self.receiver_reflectance * irradiance)
        return np.asarray(
            self.receiver_emission[receivers] + self.receiver_reflectance[receivers] * irradiance
        )

    def average(self, receivers: np.ndarray, values: np.ndarray) -> np.ndarray:
        """``W[:, receivers] @ values``: patch means of per-receiver values ((K, 3) -> (P, 3)).

        Compiled when available; :meth:`numpy_average` is the reference."""
        fast = compiled.get()
        if fast is None:
            return self.numpy_average(receivers, values)
        return np.asarray(
            fast.patch_average(
                np.ascontiguousarray(receivers, dtype=np.int64),
                np.ascontiguousarray(values, dtype=np.float64),
                self.receiver_ptr,
                self.entry_patch,
                self.entry_weight,
                len(self.patch_area),
            )
        )

    def numpy_average(self, receivers: np.ndarray, values: np.ndarray) -> np.ndarray:
        """:meth:`average` in numpy (the reference)."""
        start, stop = self.receiver_ptr[receivers], self.receiver_ptr[receivers + 1]
        counts = stop - start
        rows = np.repeat(np.arange(len(receivers)), counts)
        entries = np.repeat(start, counts) + (
            np.arange(len(rows)) - np.repeat(np.cumsum(counts) - counts, counts)
        )
        p = self.entry_patch[entries]
        w = self.entry_weight[entries]
        out = np.empty((len(self.patch_area), 3))
        for c in range(3):
            out[:, c] = np.bincount(p, weights=w * values[rows, c], minlength=len(self.patch_area))
        return out


def patch_average_matrix(mesh: RadiosityMesh) -> np.ndarray:
    """(P, R) float64 dense W: patch radiosity as the area-weighted mean of its receivers."""
    problem = DiscreteSystem.from_mesh(mesh)
    matrix = np.zeros((mesh.patch_count, mesh.receiver_count))
    rows = np.repeat(np.arange(mesh.receiver_count), np.diff(problem.receiver_ptr))
    matrix[problem.entry_patch, rows] = problem.entry_weight
    return matrix
