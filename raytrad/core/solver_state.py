"""Everything a solve accumulates, enough to resume it (:class:`SolverState`), kept apart
from the solver (:mod:`raytrad.core.solver`) that changes it and the checkpoints
(:mod:`raytrad.formats.checkpoint`) that store it."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np


@dataclass
class SolverState:
    """Everything a solve accumulates; enough to resume it.

    Attributes
    ----------
    irradiance : (R, 3) float64
        Irradiance received by each receiver from all shots so far [W m-2].
    patch_radiosity : (P, 3) float64
        ``W B`` kept incrementally [W m-2].
    shot : (P, 3) float64
        Radiosity shot so far by each patch [W m-2].
    captured : (P,) float64
        Measured fraction of a shot from each patch caught by receivers, NaN until shot.
    shots, rays : int
        Shots taken and visibility rays cast.
    absorbed, escaped : (3,) float64
        Power absorbed by receivers and lost to the outside so far [W].
    ambient_gain : float
        Damping of the ambient overshoot (1 = formula 4 as published).
    damping_events : int
        Times growth of the unshot power (the sign of divergence) halved the overshoot.
    entry_shot : (N, 3) float64
        Radiosity shot so far by each (patch, receiver) entry of ``W`` (a receiver on a
        patch border belongs to each of its patches) [W m-2]; ``shot = W entry_shot``.
        Near receivers gather what a patch shoots as it varies across its receivers
        (:mod:`raytrad.core.gather`), so the shots are kept per entry.
    spread : (P, 3) float64
        ``sum_k W_pk |dB_pk - dB_p|``: how far the unshot radiosity of the patch's
        entries spreads about their mean [W m-2]. Shooting the mean leaves it to the near
        receivers; it counts as unshot (:attr:`unshot_magnitude`). Derived from the other
        arrays (not checkpointed).
    peak : (P, 3) float64
        ``max_k |dB_pk|``, the largest unshot radiosity of the patch's entries: what a
        near receiver may see of it [W m-2]. Derived like ``spread``.
    radiosity : (R, 3) float64
        ``emission + reflectance * irradiance`` of each receiver [W m-2], kept with the
        irradiance by each shot (so that ``spread`` reads one array, not three). Derived
        like ``spread``.
    settle : callable or None
        Set by a solve whose spreads some shots left to drift (the compiled ambient
        solve, :mod:`raytrad.core._compiled_spread`): sums them again, so that ``spread``
        and ``peak`` are exact. Whatever reads them during a solve calls :meth:`settled`
        first; a solve settles them before it returns.
    """

    irradiance: np.ndarray
    patch_radiosity: np.ndarray
    shot: np.ndarray
    captured: np.ndarray
    shots: int = 0
    rays: int = 0
    seconds: float = 0.0
    absorbed: np.ndarray = field(default_factory=lambda: np.zeros(3))
    escaped: np.ndarray = field(default_factory=lambda: np.zeros(3))
    ambient_gain: float = 1.0
    min_unshot: float = math.inf
    damping_events: int = 0
    entry_shot: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    spread: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    peak: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    radiosity: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    settle: Callable[[], None] | None = field(default=None, init=False, repr=False, compare=False)

    def settled(self) -> SolverState:
        """The state with its ``spread`` and ``peak`` exact (see ``settle``)."""
        if self.settle is not None:
            self.settle()
        return self

    @property
    def unshot(self) -> np.ndarray:
        """(P, 3) float64 unshot radiosity of each patch [W m-2]."""
        return np.asarray(self.patch_radiosity - self.shot)

    @property
    def unshot_peak(self) -> np.ndarray:
        """(P, 3) float64 ``max_k |dB_pk|`` (at least ``|unshot|``) [W m-2]."""
        self.settled()
        peak = self.peak if self.peak.shape == self.shot.shape else 0.0
        return np.asarray(np.maximum(np.abs(self.unshot), peak))

    @property
    def unshot_magnitude(self) -> np.ndarray:
        """(P, 3) float64 ``|unshot| + spread``: at least ``sum_k W_pk |dB_pk|``, what is
        still to shoot whoever sees it [W m-2]."""
        self.settled()
        spread = self.spread if self.spread.shape == self.shot.shape else 0.0
        return np.asarray(np.abs(self.unshot) + spread)

    #: The arrays and the scalars that make up a state (what a checkpoint stores).
    ARRAYS = (
        "irradiance",
        "patch_radiosity",
        "shot",
        "captured",
        "absorbed",
        "escaped",
        "entry_shot",
    )
    SCALARS = ("shots", "rays", "seconds", "ambient_gain", "min_unshot", "damping_events")

    def to_record(self) -> tuple[dict[str, np.ndarray], dict[str, float]]:
        """The state as named arrays and plain scalars, for a checkpoint."""
        arrays = {name: np.asarray(getattr(self, name)) for name in self.ARRAYS}
        return arrays, {name: float(getattr(self, name)) for name in self.SCALARS}

    @classmethod
    def from_record(cls, arrays: dict[str, np.ndarray], scalars: dict[str, float]) -> SolverState:
        """The state :meth:`to_record` gave (KeyError when something is missing)."""
        return cls(
            **{name: np.array(arrays[name]) for name in cls.ARRAYS},
            shots=int(scalars["shots"]),
            rays=int(scalars["rays"]),
            seconds=float(scalars["seconds"]),
            ambient_gain=float(scalars["ambient_gain"]),
            min_unshot=float(scalars["min_unshot"]),
            damping_events=int(scalars.get("damping_events", 0)),
        )
