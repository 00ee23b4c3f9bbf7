"""One shot through a form-factor column: what the solver's every step does to its state.

A patch shoots an amount of radiosity through its column (the receivers that see it and
their factors, :mod:`raytrad.core.formfactor`): every receiver of the column gains
irradiance, its radiosity and the patch averages it belongs to change, and the shooter's
receivers record what they shot; then the spread of the patches it changed is summed
again, and the unshot power the solve watches is totalled (:func:`unshot_totals`).
:func:`shoot` does all three in one compiled call (:mod:`raytrad.core.compiled`) when
available, else :func:`numpy_step` (:func:`numpy_shoot` and the rest in numpy, the
reference it is tested against). The solve that chooses the shooters is
:mod:`raytrad.core.solver`'s.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from raytrad.core import compiled
from raytrad.core.formfactor import FormFactorEngine
from raytrad.core.solver_state import SolverState
from raytrad.core.system import DiscreteSystem
from raytrad.core.visibility import worker_count


def unshot_totals(
    problem: DiscreteSystem, state: SolverState, fast: Any = None
) -> tuple[float, float, float]:
    """``sum_p A_p |dB_p|``, ``sum_p A_p (|dB_p| + spread_p)`` and ``sum_p A_p d_p``,
    each summed over the channels [W]: the unshot power the divergence guards watch, the
    residual's numerator, and how far that may be off while some patches' spreads have
    drifted by ``d_p`` (``DiscreteSystem.spread_drift``, see
    :mod:`raytrad.core._compiled_spread`). ``fast``: the compiled kernels
    (:func:`raytrad.core.compiled.get`), or None for numpy (the reference, whose spreads
    never drift)."""
    if fast is not None:
        absolute, magnitude, width = fast.unshot_totals(
            state.patch_radiosity,
            state.shot,
            state.spread,
            problem.patch_area,
            problem.spread_drift,
        )
        return float(absolute), float(magnitude), float(width)
    area = problem.patch_area
    absolute = float((area @ np.abs(state.unshot)).sum())
    return absolute, float((area @ state.unshot_magnitude).sum()), 0.0


def shoot(
    problem: DiscreteSystem,
    state: SolverState,
    engine: FormFactorEngine,
    patch: int,
    amount: np.ndarray,
    loops: Any = None,
    lazy: bool = False,
) -> tuple[float, float, float]:
    """Shoot ``amount`` ((3,) [W m-2]) from ``patch`` through its form-factor column, sum
    the spread of the patches that changed again, and return :func:`unshot_totals`
    after the shot. One compiled loop when available (:mod:`raytrad.core.compiled`), which
    balances the raw column as it goes, else :func:`numpy_step`, the reference it is
    tested against. ``lazy`` (compiled only): the patches only the column's far
    receivers changed get a drift instead (see :mod:`raytrad.core._compiled_spread`);
    the solve's choice sums them again where it matters. ``loops``:
    :func:`raytrad.core.compiled.solver_loops` to shoot with (found here when None; the
    solve finds them once)."""
    if state.radiosity.shape != state.irradiance.shape:  # a state :func:`solve` did not set
        state.radiosity = problem.receiver_radiosity(state.irradiance)
    if state.spread.shape != state.shot.shape or state.peak.shape != state.shot.shape:
        state.spread, state.peak = problem.spread(state.radiosity, state.entry_shot, state.unshot)
    if loops is None:
        fast = compiled.get()
        if fast is None:
            return numpy_step(problem, state, engine, patch, amount)
        loops = compiled.solver_loops(fast, worker_count())
    column = engine.raw_column(patch, mapped=True)  # held for this shot alone
    scales = engine.column_scales(patch)
    row_scale, column_scale = scales
    gather = column.gather
    means = problem.subarea_means
    plan, known = problem.plans.get(engine, patch, len(gather.receivers), scales)
    absolute, magnitude, width, *found = loops.shoot(
        patch,
        np.ascontiguousarray(amount, dtype=np.float64),
        problem.patch_entries,
        problem.patch_ptr,
        problem.patch_receiver,
        problem.patch_weight,
        problem.receiver_ptr,
        problem.entry_patch,
        problem.entry_weight,
        problem.receiver_emission,
        problem.receiver_reflectance,
        problem.receiver_area,
        problem.patch_area,
        column.receivers,
        column.factors,
        _UNSCALED if row_scale is None else row_scale,
        column_scale,
        gather.receivers,
        gather.pointer,
        gather.sources,
        gather.weights,
        problem.patch_nodes[patch],
        problem.patch_nodes[patch + 1],
        means.pointer,
        means.receivers,
        means.shares,
        means.base,
        state.irradiance,
        state.radiosity,
        state.entry_shot,
        state.patch_radiosity,
        state.shot,
        state.absorbed,
        state.escaped,
        state.captured,
        state.spread,
        state.peak,
        problem.scratch,
        problem.touched,
        problem.held,
        problem.far_held,
        *plan,
        known,
        problem.spread_drift,
        lazy,
    )
    if not known:
        problem.plans.keep(patch, (*plan[:2], *found), scales)
    state.shots += 1
    return float(absolute), float(magnitude), float(width)


#: The compiled shot's row scales before balancing (none).
_UNSCALED = np.zeros(0)


def numpy_step(
    problem: DiscreteSystem,
    state: SolverState,
    engine: FormFactorEngine,
    patch: int,
    amount: np.ndarray,
    loops: Any = None,
    lazy: bool = False,
) -> tuple[float, float, float]:
    """:func:`shoot` in numpy, its reference: :func:`numpy_shoot`, the spread summed
    again (:meth:`DiscreteSystem.respread`) and :func:`unshot_totals`. Called as
    :func:`shoot` is; ``loops`` and ``lazy`` are not used."""
    numpy_shoot(problem, state, engine, patch, amount)
    state.spread, state.peak = problem.respread(
        state.spread, state.peak, state.radiosity, state.entry_shot, state.unshot
    )
    return unshot_totals(problem, state)


def numpy_shoot(
    problem: DiscreteSystem,
    state: SolverState,
    engine: FormFactorEngine,
    patch: int,
    amount: np.ndarray,
) -> None:
    """Shoot ``amount`` ((3,) [W m-2]) from ``patch`` through its form-factor column
    (``engine.column(patch)``).

    Each of the patch's receivers shoots its own unshot radiosity plus the patch's
    overshoot (``amount`` minus the patch's unshot radiosity), so that the patch mean is
    ``amount``. A far receiver gets ``F_jp * amount``; a near one
    (:mod:`raytrad.core.gather`) gets ``F_jp`` times what it sees of the patch, the
    gather-weighted mean of the receivers' shots, and the far ones give back what that
    gained or lost against the mean (:func:`_conserve`).
    """
    column = engine.column(patch)
    entries = problem.patch_entries[problem.patch_ptr[patch] : problem.patch_ptr[patch + 1]]
    sources = problem.entry_receiver[entries]
    own = state.radiosity[sources] - state.entry_shot[entries]
    weight = problem.entry_weight[entries]
    overshoot = amount - weight @ own
    shots = own + overshoot[None, :]  # (n, 3), their W-mean is ``amount``
    state.entry_shot[entries] += shots
    j, f = column.receivers, column.factors
    irradiance = f[:, None] * amount[None, :]  # (K, 3)
    gather = column.gather
    if len(gather.receivers):
        problem.scratch[sources] = shots
        means = problem.subarea_means
        nodes = np.arange(problem.patch_nodes[patch], problem.patch_nodes[patch + 1])
        problem.scratch[means.base + nodes] = means.of(nodes, problem.scratch)
        near = np.searchsorted(j, gather.receivers)
        irradiance[near] = f[near, None] * gather.gathered(problem.scratch)
        problem.scratch[sources] = 0.0
        problem.scratch[means.base + nodes] = 0.0
        _conserve(irradiance, f, amount, problem.receiver_area[j], near)
    state.irradiance[j] += irradiance
    state.radiosity[j] = problem.receiver_radiosity(state.irradiance[j], j)
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
    problem.touched[:] = True  # the next spread is summed whole


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
