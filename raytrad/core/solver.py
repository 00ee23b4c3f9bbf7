"""Shooting solvers: progressive refinement and its overshooting accelerations.

The discrete system
-------------------
Receivers j carry radiosity B_j [W m-2]; patches p shoot. The radiosity of patch p is the
area-weighted mean of its receivers, ``B̄ = W B``. With vertex-to-patch form factors
F_jp (:mod:`raytrad.core.formfactor`)::

    B_j = E_j + rho_j * sum_p F_jp * B̄_p                                          (1)

so the patch radiosities solve ``B̄ = W E + W diag(rho) F B̄``. Shooting is Southwell
iteration on that system (Gortler et al. 1994): patch p has unshot radiosity
``dB_p = B̄_p - shot_p``; shooting amount s from p adds ``F_jp s`` to the irradiance of
every receiver and ``s`` to ``shot_p``. Receivers keep their irradiance, patches keep what
they have shot, and every other quantity is derived (Wallace et al.: vertices to elements
to patches).

The methods (``../shared/papers/feda-overshooting.txt``)
---------------------------------------------------------
* ``progressive``: s = dB_p (Cohen et al. 1988).
* ``overrelaxation``: s = omega dB_p (formula 2).
* ``ambient``: s = min(dB_p + rho_p Ambient, sum_q dB_q A_q / A_p) (formulas 3-5). The
  ambient term assumes every shot is caught by the scene; raytrad replaces the enclosure
  assumption by the fraction of each shot that receivers actually caught (measured from the
  form factors, so open scenes and form-factor error do not inflate it), and halves the
  overshoot whenever the unshot power grows (see :class:`AmbientState`).

All methods shoot per RGB channel with float64 accumulation, choose the shooter by the
magnitude actually shot summed over channels, shoot negative unshot radiosity too, and
stop on the remaining unshot power relative to the emitted power.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from raytrad.core import compiled
from raytrad.core.columns import Column
from raytrad.core.formfactor import FormFactorEngine
from raytrad.core.mesh import RadiosityMesh
from raytrad.core.system import DiscreteSystem
from raytrad.errors import SettingsError, SolverError

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SolveSettings:
    """When and how to stop, and the method.

    Attributes
    ----------
    method : str
        A key of :data:`SHOOTING_METHODS`.
    tolerance : float
        Stop when the unshot power is below this fraction of the emitted power [1].
    time_limit : float or None
        Stop after this many seconds of solving, once every emitter has shot (direct
        light is never cut short) [s].
    max_shots : int or None
        Stop after this many shots.
    omega : float
        Overrelaxation factor (``overrelaxation`` only), in [1, 2).
    """

    method: str = "ambient"
    tolerance: float = 1e-3
    time_limit: float | None = None
    max_shots: int | None = None
    omega: float = 1.3

    def __post_init__(self) -> None:
        if self.method not in SHOOTING_METHODS:
            raise SettingsError(
                f"unknown method {self.method!r}; choose one of {', '.join(SHOOTING_METHODS)}"
            )
        if not (0.0 < self.tolerance < 1.0):
            raise SettingsError(f"tolerance must lie in (0, 1), got {self.tolerance}")
        if self.time_limit is not None and self.time_limit <= 0:
            raise SettingsError(f"time limit must be positive, got {self.time_limit}")
        if self.max_shots is not None and self.max_shots < 0:
            raise SettingsError(f"max shots must be >= 0, got {self.max_shots}")
        if not (1.0 <= self.omega < 2.0):
            raise SettingsError(f"omega must lie in [1, 2), got {self.omega}")


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

    @property
    def unshot(self) -> np.ndarray:
        """(P, 3) float64 unshot radiosity of each patch [W m-2]."""
        return np.asarray(self.patch_radiosity - self.shot)

    @property
    def unshot_peak(self) -> np.ndarray:
        """(P, 3) float64 ``max_k |dB_pk|`` (at least ``|unshot|``) [W m-2]."""
        peak = self.peak if self.peak.shape == self.shot.shape else 0.0
        return np.asarray(np.maximum(np.abs(self.unshot), peak))

    @property
    def unshot_magnitude(self) -> np.ndarray:
        """(P, 3) float64 ``|unshot| + spread``: at least ``sum_k W_pk |dB_pk|``, what is
        still to shoot whoever sees it [W m-2]."""
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


@dataclass(frozen=True)
class SolveResult:
    """What a solve produced.

    Attributes
    ----------
    radiosity : (R, 3) float64
        Radiosity of each receiver [W m-2].
    state : SolverState
    stop_reason : str
        ``converged``, ``time-limit``, ``max-shots``, ``no-emission`` or ``interrupted``.
    residual : float
        Unshot power relative to emitted power when the solve stopped [1].
    emitted_power : (3,) float64 [W]
    unshot_power : (3,) float64 [W], signed
    method : str
    """

    radiosity: np.ndarray
    state: SolverState
    stop_reason: str
    residual: float
    emitted_power: np.ndarray
    unshot_power: np.ndarray
    method: str


# --------------------------------------------------------------------------------------
# Shooting amounts: one function per method (the registry)
# --------------------------------------------------------------------------------------

ShootAmount = Callable[["DiscreteSystem", SolverState, SolveSettings], np.ndarray]


def _progressive_amount(
    problem: DiscreteSystem, state: SolverState, settings: SolveSettings
) -> np.ndarray:
    """plain progressive refinement (Cohen et al. 1988)"""
    return state.unshot


def _overrelaxation_amount(
    problem: DiscreteSystem, state: SolverState, settings: SolveSettings
) -> np.ndarray:
    """progressive refinement shooting omega times the unshot radiosity"""
    return settings.omega * state.unshot


def filled_capture(captured: np.ndarray, patch_area: np.ndarray) -> np.ndarray:
    """(P,) capture fractions, the area-weighted mean of the measured ones (1 before any
    shot) standing in for patches that have not shot yet."""
    known = np.isfinite(captured)
    mean_capture = 1.0
    if known.any():
        mean_capture = float(np.average(captured[known], weights=patch_area[known]))
    return np.where(known, captured, mean_capture)


def _ambient_amount(
    problem: DiscreteSystem, state: SolverState, settings: SolveSettings
) -> np.ndarray:
    """ambient overshooting (Feda 1992), the default and usually fastest

    Formulas 3-5, with the measured capture fraction in the amplification.
    """
    unshot = state.unshot
    area = problem.patch_area
    unshot_power = area @ unshot  # (3,)
    capture = filled_capture(state.captured, area)
    lost = area @ (1.0 - problem.patch_reflectance * capture[:, None])  # (3,)
    ambient = unshot_power / np.maximum(lost, 1e-300 * area.sum())  # formula 3
    ambient = np.maximum(ambient, 0.0) * state.ambient_gain
    amount = unshot + problem.patch_reflectance * ambient[None, :]  # formula 4
    cap = np.maximum(unshot_power, 0.0)[None, :] / area[:, None]
    return np.minimum(amount, cap)  # formula 5


@dataclass(frozen=True)
class ShootingMethod:
    """One entry of the method registry.

    Attributes
    ----------
    amount : callable
        ``amount(problem, state, settings) -> (P, 3)``: what every patch would shoot now.
        The first line of its docstring is the method's summary.
    damped : bool
        Halve the overshoot whenever the unshot power grows well past its minimum (the
        sign of divergence; see :func:`_guard_growth`).
    """

    amount: ShootAmount
    damped: bool = False

    @property
    def summary(self) -> str:
        """One line saying what the method does (the first line of ``amount``'s docstring)."""
        return (self.amount.__doc__ or "").strip().splitlines()[0]


#: Registry of shooting methods; the CLI's choices, its help and the docs come from here.
SHOOTING_METHODS: dict[str, ShootingMethod] = {
    "progressive": ShootingMethod(_progressive_amount),
    "overrelaxation": ShootingMethod(_overrelaxation_amount),
    "ambient": ShootingMethod(_ambient_amount, damped=True),
}


# --------------------------------------------------------------------------------------
# The solve
# --------------------------------------------------------------------------------------


def new_state(mesh: RadiosityMesh, problem: DiscreteSystem | None = None) -> SolverState:
    """The state before any shot: patches hold their emission as unshot radiosity."""
    problem = problem or DiscreteSystem.from_mesh(mesh)
    everyone = np.arange(mesh.receiver_count)
    return SolverState(
        irradiance=np.zeros((mesh.receiver_count, 3)),
        patch_radiosity=problem.average(everyone, mesh.receiver_emitted_exitance),
        shot=np.zeros((mesh.patch_count, 3)),
        captured=np.full(mesh.patch_count, np.nan),
        entry_shot=np.zeros((len(problem.entry_patch), 3)),
    )


def check_solvable(mesh: RadiosityMesh) -> None:
    """Refuse systems without a finite solution before any work.

    In a channel where every patch reflects everything (reflectance 1) and something
    emits, no energy is ever lost in a closed scene: the radiosity grows without bound.
    """
    emits: list[bool] = np.any(mesh.receiver_emitted_exitance > 0, axis=0).tolist()
    lossless: list[bool] = np.all(mesh.patch_reflectance >= 1.0, axis=0).tolist()
    bad = [name for c, name in enumerate("RGB") if emits[c] and lossless[c]]
    if bad:
        raise SolverError(
            f"every surface has reflectance 1 in channel {', '.join(bad)}: a closed scene "
            "then has no finite solution (lower the reflectance below 1)"
        )


def solve(
    mesh: RadiosityMesh,
    engine: FormFactorEngine,
    settings: SolveSettings | None = None,
    state: SolverState | None = None,
    progress: Callable[[SolverState, float], None] | None = None,
    stop: Callable[[], bool] | None = None,
) -> SolveResult:
    """Solve the radiosity system of ``mesh`` by shooting.

    Parameters
    ----------
    mesh : RadiosityMesh
    engine : FormFactorEngine
        Supplies the form-factor column of each shooting patch.
    settings : SolveSettings
        Method and stopping rules.
    state : SolverState or None
        A state to resume from (as saved by :mod:`raytrad.outputs.resume`); None starts
        afresh.
    progress : callable or None
        Called as ``progress(state, residual)`` after each shot.
    stop : callable or None
        Polled before each shot; True ends the solve with reason ``interrupted`` and a
        consistent state (the CLI sets it on Ctrl-C, so the run can be resumed).

    Returns
    -------
    SolveResult
    """
    settings = settings or SolveSettings()
    check_solvable(mesh)
    problem = DiscreteSystem.from_mesh(mesh)
    state = state or new_state(mesh, problem)
    if state.entry_shot.shape != (len(problem.entry_patch), 3):
        raise SolverError("the state to resume was made for another mesh")
    amount_of = SHOOTING_METHODS[settings.method].amount
    area = problem.patch_area
    everyone = np.arange(mesh.receiver_count)
    emitted = area @ problem.average(everyone, problem.receiver_emission)
    emitted_total = float(emitted.sum())
    start = time.perf_counter() - state.seconds
    rays_before = state.rays  # from a checkpoint; the engine counts this run's rays
    reason = "no-emission" if emitted_total <= 0 else ""
    residual = 0.0
    state.spread, state.peak = problem.spread(state.irradiance, state.entry_shot, state.unshot)
    emitters = np.flatnonzero((problem.average(everyone, problem.receiver_emission) > 0).any(1))
    while not reason:
        residual = float((area @ state.unshot_magnitude).sum()) / emitted_total
        direct = bool((state.shot[emitters] != 0).any(axis=1).all())
        reason = _stop_reason(state, settings, residual, time.perf_counter() - start, direct)
        if not reason and stop is not None and stop():
            reason = "interrupted"
        if reason:
            break
        amount = amount_of(problem, state, settings)
        magnitude = area * (np.abs(amount) + state.spread).sum(axis=1)
        patch = int(np.argmax(magnitude))
        if magnitude[patch] <= 0:
            reason = "converged"
            break
        _shoot(problem, state, engine.column(patch), patch, amount[patch])
        state.spread, state.peak = problem.spread(state.irradiance, state.entry_shot, state.unshot)
        state.rays = rays_before + engine.rays_cast
        state.seconds = time.perf_counter() - start
        _guard_growth(state, area, settings)
        _check_divergence(state, area, emitted_total)
        if progress is not None:
            progress(state, residual)
    state.seconds = time.perf_counter() - start
    state.rays = rays_before + engine.rays_cast
    residual = (
        float((area @ state.unshot_magnitude).sum()) / emitted_total if emitted_total else 0.0
    )
    radiosity = problem.receiver_emission + problem.receiver_reflectance * state.irradiance
    if not np.isfinite(radiosity).all():
        raise SolverError("the solve produced non-finite radiosity")
    return SolveResult(
        radiosity=radiosity,
        state=state,
        stop_reason=reason,
        residual=residual,
        emitted_power=emitted,
        unshot_power=area @ state.unshot,
        method=settings.method,
    )


def _stop_reason(
    state: SolverState, settings: SolveSettings, residual: float, elapsed: float, direct: bool
) -> str:
    """Why to stop now ("" to go on); the time limit waits for ``direct``: every emitter
    has shot once, so that a time-limited answer always has its direct light."""
    if residual <= settings.tolerance:
        return "converged"
    if settings.max_shots is not None and state.shots >= settings.max_shots:
        return "max-shots"
    if settings.time_limit is not None and elapsed >= settings.time_limit and direct:
        return "time-limit"
    return ""


def _shoot(
    problem: DiscreteSystem, state: SolverState, column: Column, patch: int, amount: np.ndarray
) -> None:
    """Shoot ``amount`` ((3,) [W m-2]) from ``patch`` through its form-factor column: one
    compiled loop when available (:mod:`raytrad.core.compiled`), else :func:`numpy_shoot`,
    the reference it is tested against."""
    fast = compiled.get()
    if fast is None:
        numpy_shoot(problem, state, column, patch, amount)
        return
    gather = column.gather
    power, reflected, capture = fast.shoot(
        problem.patch_entries[problem.patch_ptr[patch] : problem.patch_ptr[patch + 1]],
        problem.entry_receiver,
        problem.entry_weight,
        problem.receiver_emission,
        problem.receiver_reflectance,
        state.irradiance,
        state.entry_shot,
        np.ascontiguousarray(amount, dtype=np.float64),
        column.receivers,
        column.factors,
        gather.receivers,
        gather.pointer,
        gather.sources,
        gather.weights,
        problem.receiver_area,
        problem.receiver_ptr,
        problem.entry_patch,
        state.patch_radiosity,
        problem.scratch,
    )
    area_p = problem.patch_area[patch]
    state.shot[patch] += amount
    state.absorbed += power - reflected
    state.escaped += area_p * amount - power
    state.captured[patch] = capture / area_p
    state.shots += 1


def numpy_shoot(
    problem: DiscreteSystem, state: SolverState, column: Column, patch: int, amount: np.ndarray
) -> None:
    """Shoot ``amount`` ((3,) [W m-2]) from ``patch`` through its form-factor column.

    Each of the patch's receivers shoots its own unshot radiosity plus the patch's
    overshoot (``amount`` minus the patch's unshot radiosity), so that the patch mean is
    ``amount``. A far receiver gets ``F_jp * amount``; a near one
    (:mod:`raytrad.core.gather`) gets ``F_jp`` times what it sees of the patch, the
    gather-weighted mean of the receivers' shots, and the far ones give back what that
    gained or lost against the mean (:func:`_conserve`).
    """
    entries = problem.patch_entries[problem.patch_ptr[patch] : problem.patch_ptr[patch + 1]]
    sources = problem.entry_receiver[entries]
    radiosity = (
        problem.receiver_emission[sources]
        + problem.receiver_reflectance[sources] * state.irradiance[sources]
    )
    own = radiosity - state.entry_shot[entries]
    weight = problem.entry_weight[entries]
    overshoot = amount - weight @ own
    shots = own + overshoot[None, :]  # (n, 3), their W-mean is ``amount``
    state.entry_shot[entries] += shots
    j, f = column.receivers, column.factors
    irradiance = f[:, None] * amount[None, :]  # (K, 3)
    gather = column.gather
    if len(gather.receivers):
        problem.scratch[sources] = shots
        near = np.searchsorted(j, gather.receivers)
        irradiance[near] = f[near, None] * gather.gathered(problem.scratch)
        problem.scratch[sources] = 0.0
        _conserve(irradiance, f, amount, problem.receiver_area[j], near)
    state.irradiance[j] += irradiance
    reflected = problem.receiver_reflectance[j] * irradiance
    state.patch_radiosity += problem.average(j, reflected)
    area_p = problem.patch_area[patch]
    state.shot[patch] += amount
    a = problem.receiver_area[j]
    caught = a @ irradiance  # (3,) power landing on receivers [W]
    state.absorbed += caught - a @ reflected
    state.escaped += area_p * amount - caught
    state.captured[patch] = float(a @ f) / area_p
    state.shots += 1


def _conserve(
    irradiance: np.ndarray,
    factors: np.ndarray,
    amount: np.ndarray,
    area: np.ndarray,
    near: np.ndarray,
) -> None:
    """Give the far receivers of a shot the power its near receivers' gather added or took.

    The discrete gather weights are not exactly reciprocal, so the near receivers of a
    patch catch a little more or less power than the patch mean would deliver; unchecked,
    closed scenes of high reflectance amplify that by ``1 / (1 - rho)``. The far
    receivers, which see the patch as its mean, absorb the difference in proportion to
    their factors (the near ones, when a patch has no far receivers), so every shot
    delivers exactly ``sum_j a_j F_jp * amount`` in power.

    Parameters
    ----------
    irradiance : (K, 3) float
        The shot's irradiance at the column's receivers, updated in place [W m-2].
    factors : (K,) float
        The column's form factors [1].
    amount : (3,) float
        Radiosity shot [W m-2].
    area : (K,) float
        Receiver areas [m2].
    near : (G,) int
        Rows of the near receivers.
    """
    excess = area[near] @ (irradiance[near] - factors[near, None] * amount[None, :])  # [W]
    target = np.ones(len(factors), bool)
    target[near] = False
    caught = float(area[target] @ factors[target])
    if not caught > 0.0:
        target, caught = ~target, float(area[near] @ factors[near])
    if caught > 0.0:
        irradiance[target] -= factors[target, None] * (excess / caught)[None, :]


#: Unshot power beyond this multiple of the emitted power means divergence: overshooting
#: legitimately leaves unshot power of order rho / (1 - rho) times the emitted power.
DIVERGENCE_LIMIT = 1e9


def _check_divergence(state: SolverState, area: np.ndarray, emitted_total: float) -> None:
    """Raise when the unshot power has grown past any legitimate overshoot.

    That happens only when the discrete system has no finite solution: some closed set of
    surfaces returns more than it receives (reflectance times form-factor sum >= 1).
    """
    total = float((area @ np.abs(state.unshot)).sum())
    if not np.isfinite(total) or total > DIVERGENCE_LIMIT * emitted_total:
        raise SolverError(
            f"the solve diverged after {state.shots} shots: the unshot power grew to "
            f"{total / emitted_total:.3g} times the emitted power; the scene reflects more "
            "than it receives somewhere (reflectance times form-factor sum >= 1)"
        )


def _guard_growth(state: SolverState, area: np.ndarray, settings: SolveSettings) -> None:
    """Halve the overshoot of a damped method when the unshot power grows well past its
    minimum.

    Shooting never increases the absolute unshot power unless it overshoots by more than the
    iteration tolerates (the omega >= 2 regime); growth is the sign of divergence.
    """
    if not SHOOTING_METHODS[settings.method].damped:
        return
    total = float((area @ np.abs(state.unshot)).sum())
    if total < state.min_unshot:
        state.min_unshot = total
    elif total > 4.0 * state.min_unshot and state.ambient_gain > 1e-3:
        state.ambient_gain *= 0.5
        state.damping_events += 1
        state.min_unshot = total
        log.info("unshot power grew; ambient overshoot damped to %.3g", state.ambient_gain)
