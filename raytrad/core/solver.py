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
* ``positive``, ``super_shoot_gather``, ``enhanced_super_shoot_gather``: formulas 6, 8
  and 9, gathering over patch-to-patch factors built from the traced columns
  (:mod:`raytrad.core.patch_factors`); the last chooses its shooter by
  ``|dB + rho Ambient|`` and is capped at the total unshot power like formula 5.

All methods shoot per RGB channel with float64 accumulation, choose the shooter by the
magnitude actually shot summed over channels, shoot negative unshot radiosity too, and
stop on the remaining unshot power relative to the emitted power.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from raytrad.core import compiled, patch_factors
from raytrad.core.formfactor import FormFactorEngine
from raytrad.core.mesh import RadiosityMesh
from raytrad.core.patch_factors import PatchFactors
from raytrad.core.shot import shoot as _shoot
from raytrad.core.shot import unshot_totals
from raytrad.core.solver_state import SolverState
from raytrad.core.system import DiscreteSystem
from raytrad.core.visibility import worker_count
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

ShootAmount = Callable[
    ["DiscreteSystem", SolverState, SolveSettings, "PatchFactors | None"], np.ndarray
]


def _progressive_amount(
    problem: DiscreteSystem, state: SolverState, settings: SolveSettings, factors: Any
) -> np.ndarray:
    """plain progressive refinement (Cohen et al. 1988)"""
    return state.unshot


def _overrelaxation_amount(
    problem: DiscreteSystem, state: SolverState, settings: SolveSettings, factors: Any
) -> np.ndarray:
    """progressive refinement shooting omega times the unshot radiosity"""
    return settings.omega * state.unshot


def filled_capture(captured: np.ndarray, patch_area: np.ndarray) -> np.ndarray:
    """(P,) capture fractions, the area-weighted mean of the measured ones (1 before any
    shot) standing in for patches that have not shot yet."""
    known = np.isfinite(captured)
    if known.all():  # the usual case once every patch has shot
        return captured.copy()
    mean_capture = 1.0
    if known.any():  # np.average's arithmetic, without its checks (a solve calls this a shot)
        weights = patch_area[known]
        mean_capture = float((captured[known] * weights).sum() / weights.sum())
    return np.where(known, captured, mean_capture)


def ambient_light(
    problem: DiscreteSystem, state: SolverState, unshot_power: np.ndarray | None = None
) -> np.ndarray:
    """(3,) the ambient term of formula 3 [W m-2], with the measured capture fraction in
    the amplification, never negative, times the damping gain. ``unshot_power`` is
    ``patch_area @ state.unshot`` ((3,) [W]) when the caller has it."""
    area = problem.patch_area
    capture = filled_capture(state.captured, area)
    lost = area @ (1.0 - problem.patch_reflectance * capture[:, None])  # (3,)
    if unshot_power is None:
        unshot_power = area @ state.unshot
    ambient = unshot_power / np.maximum(lost, 1e-300 * area.sum())  # formula 3
    return np.asarray(np.maximum(ambient, 0.0) * state.ambient_gain)


def _ambient_amount(
    problem: DiscreteSystem, state: SolverState, settings: SolveSettings, factors: Any
) -> np.ndarray:
    """ambient overshooting (Feda 1992), the default and usually fastest

    Formulas 3-5, with the measured capture fraction in the amplification.
    """
    unshot = state.unshot
    area = problem.patch_area
    power = area @ unshot
    amount = unshot + problem.patch_reflectance * ambient_light(problem, state, power)[None, :]
    cap = np.maximum(power, 0.0)[None, :] / area[:, None]
    return np.minimum(amount, cap)  # formulas 4 and 5


def _raised(problem: DiscreteSystem, state: SolverState) -> np.ndarray:
    """(P, 3) ``dB + rho Ambient``, the unshot radiosity raised by the ambient light."""
    return state.unshot + problem.patch_reflectance * ambient_light(problem, state)[None, :]


def _positive_amount(
    problem: DiscreteSystem, state: SolverState, settings: SolveSettings, factors: Any
) -> np.ndarray:
    """positive overshooting: shoots what it gathers of the positive unshot radiosity"""
    return patch_factors.positive_overshoot(state.unshot, factors)


def _super_shoot_gather_amount(
    problem: DiscreteSystem, state: SolverState, settings: SolveSettings, factors: Any
) -> np.ndarray:
    """super-shoot-gather: positive overshooting and the shooter's interreflections"""
    return patch_factors.super_shoot_gather(state.unshot, factors)


def _enhanced_amount(
    problem: DiscreteSystem, state: SolverState, settings: SolveSettings, factors: Any
) -> np.ndarray:
    """enhanced super-shoot-gather: super-shoot-gather over ambient-raised unshot radiosity"""
    raised = _raised(problem, state)
    return patch_factors.enhanced_super_shoot_gather(
        state.unshot, raised, problem.patch_area, factors
    )


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
    patch_factors : bool
        Needs patch-to-patch form factors (:mod:`raytrad.core.patch_factors`).
    selected_by_raised : bool
        Choose the shooter by ``|dB + rho Ambient|`` (as ambient overshooting, formula
        9's selection), but never by more than the amount itself: a patch whose shot the
        energy cap holds back would otherwise be chosen again and again.
    """

    amount: ShootAmount
    damped: bool = False
    patch_factors: bool = False
    selected_by_raised: bool = False

    @property
    def summary(self) -> str:
        """One line saying what the method does (the first line of ``amount``'s docstring)."""
        return (self.amount.__doc__ or "").strip().splitlines()[0]


#: Registry of shooting methods; the CLI's choices, its help and the docs come from here.
SHOOTING_METHODS: dict[str, ShootingMethod] = {
    "progressive": ShootingMethod(_progressive_amount),
    "overrelaxation": ShootingMethod(_overrelaxation_amount),
    "ambient": ShootingMethod(_ambient_amount, damped=True),
    "positive": ShootingMethod(_positive_amount, patch_factors=True),
    "super_shoot_gather": ShootingMethod(_super_shoot_gather_amount, patch_factors=True),
    "enhanced_super_shoot_gather": ShootingMethod(
        _enhanced_amount, damped=True, patch_factors=True, selected_by_raised=True
    ),
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
        Supplies the form-factor column of each shooting patch: the raw column and its
        balancing scales to the compiled shot, the balanced column to the numpy one.
    settings : SolveSettings
        Method and stopping rules.
    state : SolverState or None
        A state to resume from (as saved by :mod:`raytrad.outputs.resume`); None starts
        afresh.
    progress : callable or None
        Called as ``progress(state, residual)`` after each shot: the residual before it,
        or a bound above that while some spreads drift (the compiled ambient solve, see
        :mod:`raytrad.core._compiled_spread`; ``state.settled()`` makes them exact).
    stop : callable or None
        Polled before each shot; True ends the solve with reason ``interrupted`` and a
        consistent state (the CLI sets it on Ctrl-C, so the run can be resumed).

    Returns
    -------
    SolveResult
    """
    settings = settings or SolveSettings()
    check_solvable(mesh)
    problem = DiscreteSystem.from_mesh(mesh, engine.subarea_means)
    state = state or new_state(mesh, problem)
    if state.entry_shot.shape != (len(problem.entry_patch), 3):
        raise SolverError("the state to resume was made for another mesh")
    method = SHOOTING_METHODS[settings.method]
    factors = None
    if method.patch_factors:
        patch_factors.check_patch_factor_memory(mesh.patch_count, settings.method)
        factors = patch_factors.PatchFactors.from_columns(
            problem, engine, problem.receiver_reflectance
        )
    area = problem.patch_area
    everyone = np.arange(mesh.receiver_count)
    emitted = area @ problem.average(everyone, problem.receiver_emission)
    emitted_total = float(emitted.sum())
    start = time.perf_counter() - state.seconds
    rays_before = state.rays  # from a checkpoint; the engine counts this run's rays
    reason = "no-emission" if emitted_total <= 0 else ""
    residual = 0.0
    state.radiosity = problem.receiver_radiosity(state.irradiance)
    state.spread, state.peak = problem.spread(state.radiosity, state.entry_shot, state.unshot)
    emitters = np.flatnonzero((problem.average(everyone, problem.receiver_emission) > 0).any(1))
    direct = False
    fast = compiled.get()
    loops = None if fast is None else compiled.solver_loops(fast, worker_count())
    choose = _compiled_choice(settings.method, loops)
    lazy = choose is not None and LAZY_SPREAD
    if lazy:

        def settle() -> None:
            _settle(problem, state, loops)

        state.settle = settle
    totals = unshot_totals(problem, state, fast)
    try:
        while not reason:
            if totals[2] and (totals[1] - totals[2]) / emitted_total <= settings.tolerance:
                totals = _settle(problem, state, loops)  # the stop as with every spread exact
            residual = (totals[1] + totals[2]) / emitted_total  # the residual, or above it
            direct = direct or bool((state.shot[emitters] != 0).any(axis=1).all())
            reason = _stop_reason(state, settings, residual, time.perf_counter() - start, direct)
            if not reason and stop is not None and stop():
                reason = "interrupted"
            if reason:
                break
            if loops is not None:
                loops.tick()  # the parallel loops, or the serial ones while a core is busy
            if choose is not None:
                patch, top, amount = choose(problem, state)
            else:
                patch, top, amount = _numpy_choice(problem, state, settings, method, factors)
            if top <= 0:
                reason = "converged"
                break
            totals = _shoot(problem, state, engine, patch, amount, loops, lazy)
            state.rays = rays_before + engine.rays_cast
            state.seconds = time.perf_counter() - start
            _guard_growth(state, totals[0], settings)
            _check_divergence(state, totals[0], emitted_total)
            if progress is not None:
                progress(state, residual)
        state.settled()
    finally:  # a solve's state leaves it settled, or without its settle hook
        state.settle = None
    state.seconds = time.perf_counter() - start
    state.rays = rays_before + engine.rays_cast
    residual = (
        float((area @ state.unshot_magnitude).sum()) / emitted_total if emitted_total else 0.0
    )
    radiosity = problem.receiver_radiosity(state.irradiance)
    if not np.isfinite(radiosity).all():
        raise SolverError("the solve produced non-finite radiosity")
    log.info(  # the stage's end in a log without progress bars (CI), as the pass's
        "solve: %s after %d shots (%.2f s of solving, a resumed run's included), residual %.2e",
        reason,
        state.shots,
        state.seconds,
        residual,
    )
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


def _compiled_choice(
    method: str, loops: Any
) -> Callable[[DiscreteSystem, SolverState], tuple[int, float, np.ndarray]] | None:
    """The compiled shooter choice for ``method`` (ambient overshooting's,
    ``ambient_choice`` of ``loops``, :func:`raytrad.core.compiled.solver_loops` or the
    kernels themselves), called as ``choose(problem, state)`` and returning what
    :func:`_numpy_choice` (its reference) returns; None: the numpy one then. It sums
    again the drifted spreads that could change the choice (see
    :mod:`raytrad.core._compiled_spread`)."""
    if loops is None or method != "ambient":
        return None

    def choose(problem: DiscreteSystem, state: SolverState) -> tuple[int, float, np.ndarray]:
        amount = np.empty(3)
        patch, top = loops.ambient_choice(
            state.patch_radiosity,
            state.shot,
            state.spread,
            state.peak,
            problem.spread_drift,
            problem.patch_area,
            problem.patch_reflectance,
            state.captured,
            state.ambient_gain,
            amount,
            problem.patch_entries,
            problem.patch_ptr,
            problem.patch_receiver,
            problem.patch_weight,
            state.radiosity,
            state.entry_shot,
            problem.touched,
        )
        return int(patch), float(top), amount

    return choose


def _settle(problem: DiscreteSystem, state: SolverState, loops: Any) -> tuple[float, float, float]:
    """Sum again every spread a lazy shot left to drift (``refresh_stale`` of ``loops``);
    returns :func:`raytrad.core.shot.unshot_totals`, exact now."""
    absolute, magnitude, width = loops.refresh_stale(
        problem.touched,
        problem.patch_entries,
        problem.patch_ptr,
        problem.patch_receiver,
        problem.patch_weight,
        state.radiosity,
        state.entry_shot,
        state.patch_radiosity,
        state.shot,
        state.spread,
        state.peak,
        problem.spread_drift,
        problem.patch_area,
    )
    return float(absolute), float(magnitude), float(width)


def _numpy_choice(
    problem: DiscreteSystem,
    state: SolverState,
    settings: SolveSettings,
    method: ShootingMethod,
    factors: PatchFactors | None,
) -> tuple[int, float, np.ndarray]:
    """The shooter: (patch, its ``A_p sum_c (|amount_pc| + spread_pc)``, its amount (3,)),
    the first patch of the largest such value, chosen by ``method``'s amounts."""
    amount = method.amount(problem, state, settings, factors)
    chosen_by = np.abs(amount)
    if method.selected_by_raised:  # but never by more than the patch would shoot
        chosen_by = np.minimum(np.abs(_raised(problem, state)), chosen_by)
    chosen_by += state.spread
    # the channels' sum, as .sum(axis=1) adds them but without its overhead (a shot)
    magnitude = problem.patch_area * (chosen_by[:, 0] + chosen_by[:, 1] + chosen_by[:, 2])
    patch = int(np.argmax(magnitude))
    return patch, float(magnitude[patch]), amount[patch]


#: Whether the compiled ambient solve lets the spreads of the patches a shot's far
#: receivers changed drift until they could matter (:mod:`raytrad.core._compiled_spread`);
#: it chooses and stops the same either way, to the bit.
LAZY_SPREAD = True

#: Unshot power beyond this multiple of the emitted power means divergence: overshooting
#: legitimately leaves unshot power of order rho / (1 - rho) times the emitted power.
DIVERGENCE_LIMIT = 1e9


def _check_divergence(state: SolverState, total: float, emitted_total: float) -> None:
    """Raise when the unshot power has grown past any legitimate overshoot.

    That happens only when the discrete system has no finite solution: some closed set of
    surfaces returns more than it receives (reflectance times form-factor sum >= 1).
    ``total`` is the unshot power ``sum_p A_p |dB_p|`` summed over channels [W].
    """
    if not math.isfinite(total) or total > DIVERGENCE_LIMIT * emitted_total:
        raise SolverError(
            f"the solve diverged after {state.shots} shots: the unshot power grew to "
            f"{total / emitted_total:.3g} times the emitted power; the scene reflects more "
            "than it receives somewhere (reflectance times form-factor sum >= 1)"
        )


def _guard_growth(state: SolverState, total: float, settings: SolveSettings) -> None:
    """Halve the overshoot of a damped method when the unshot power grows well past its
    minimum.

    Shooting never increases the absolute unshot power unless it overshoots by more than the
    iteration tolerates (the omega >= 2 regime); growth is the sign of divergence.
    ``total`` is the unshot power ``sum_p A_p |dB_p|`` summed over channels [W].
    """
    if not SHOOTING_METHODS[settings.method].damped:
        return
    if total < state.min_unshot:
        state.min_unshot = total
    elif total > 4.0 * state.min_unshot and state.ambient_gain > 1e-3:
        state.ambient_gain *= 0.5
        state.damping_events += 1
        state.min_unshot = total
        log.info("unshot power grew; ambient overshoot damped to %.3g", state.ambient_gain)
