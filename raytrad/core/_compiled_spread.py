"""The solve's per-patch loops behind :mod:`raytrad.core.compiled`, written for numba
(imported only there): each patch's spread (how its receivers differ in what they still
have to shoot), the unshot totals the solve watches, and ambient overshooting's choice of
the next shooter. Plain Python as written here; :func:`raytrad.core.compiled.get`
compiles every function in :data:`KERNELS`. Each computes what its numpy reference
computes (:mod:`raytrad.core.solver`, :mod:`raytrad.core.system`); see there for shapes
and units.

A shot changes the radiosity of the patches its far receivers belong to by its plan's
sums (:mod:`raytrad.core._compiled_solver`); their spread is then known only within a
bound, their *drift* ``d_p``, ``|spread_p - stored_p| <= d_p`` (:func:`add_drift`), and is
summed again when it could matter: when the choice could fall on the patch
(:func:`ambient_choice`), or the residual could be within its tolerance
(:func:`refresh_stale`). The solve chooses and stops as it would with every spread summed
after every shot, to the bit.
"""

# mypy: ignore-errors

import numpy as np

#: ``numba.prange`` once :mod:`raytrad.core.compiled` compiles these loops (``range`` as
#: plain Python): its loops run on several threads in a kernel's :data:`PARALLEL` copy and
#: one after another in the kernel itself, with the same results.
prange = range

#: Kernels also compiled with ``parallel=True``, as ``<name>_parallel``
#: (:func:`raytrad.core.compiled.solver_loops` chooses).
PARALLEL = ("ambient_choice", "refresh_stale")

#: Runs of about equal entries :func:`_touched_runs` splits the touched patches into.
SPREAD_PARTS = 16

#: A drift's allowance for rounding, relative to the patch's radiosity, shot, peak and
#: spread: the spread summed again may differ from the real one by a few units in the
#: last place of those [1].
DRIFT_ROUNDING = 1e-9

#: Every function to compile, each after the helpers it calls.
KERNELS = (
    "_spread_row",
    "patch_spread_rows",
    "_touched_runs",
    "unshot_totals",
    "add_drift",
    "_ambient_light",
    "_chosen",
    "ambient_choice",
    "refresh_stale",
)


def _spread_row(
    p,
    u0,
    u1,
    u2,
    patch_entries,
    patch_ptr,
    patch_receiver,
    patch_weight,
    radiosity,
    entry_shot,
    spread,
    peak,
):
    """Patch ``p``'s ``sum_k W_pk |dB_pk - dB_p|`` and ``max_k |dB_pk|`` into row ``p`` of
    ``spread`` and ``peak``, its unshot radiosity ``dB_p`` being (u0, u1, u2): its entries
    (``patch_entries[patch_ptr[p]:patch_ptr[p + 1]]``, ascending; their receivers and
    weights ``patch_receiver`` and ``patch_weight`` in the same order) summed from zero in
    that order."""
    s0 = s1 = s2 = m0 = m1 = m2 = 0.0
    for q in range(patch_ptr[p], patch_ptr[p + 1]):
        e = patch_entries[q]
        k = patch_receiver[q]
        w = patch_weight[q]
        own0 = radiosity[k, 0] - entry_shot[e, 0]
        own1 = radiosity[k, 1] - entry_shot[e, 1]
        own2 = radiosity[k, 2] - entry_shot[e, 2]
        s0 += w * abs(own0 - u0)
        s1 += w * abs(own1 - u1)
        s2 += w * abs(own2 - u2)
        m0 = max(m0, abs(own0))
        m1 = max(m1, abs(own1))
        m2 = max(m2, abs(own2))
    spread[p, 0], spread[p, 1], spread[p, 2] = s0, s1, s2
    peak[p, 0], peak[p, 1], peak[p, 2] = m0, m1, m2


def patch_spread_rows(
    rows,
    patch_entries,
    patch_ptr,
    patch_receiver,
    patch_weight,
    radiosity,
    entry_shot,
    unshot,
    spread,
    peak,
):
    """Per patch of ``rows`` ``sum_k W_pk |dB_pk - dB_p|`` and ``max_k |dB_pk|`` (see
    :meth:`raytrad.core.system.DiscreteSystem.numpy_spread`), into ``spread`` and ``peak``
    (P, 3) in place, each patch by :func:`_spread_row`, so a patch's sums do not depend on
    which other patches are summed with it."""
    for i in range(len(rows)):
        p = rows[i]
        _spread_row(
            p,
            unshot[p, 0],
            unshot[p, 1],
            unshot[p, 2],
            patch_entries,
            patch_ptr,
            patch_receiver,
            patch_weight,
            radiosity,
            entry_shot,
            spread,
            peak,
        )


def _touched_runs(touched, patch_ptr):
    """The patches marked in ``touched`` ((P,) bool), whose marks it clears, ascending
    ((M,) int64), and the ends of :data:`SPREAD_PARTS` runs of them of about equal entries
    ((SPREAD_PARTS + 1,) int64), so that the threads summing their spreads share the
    work whichever patches a shot touched."""
    rows = np.empty(len(touched), dtype=np.int64)
    count = 0
    total = 0
    for p in range(len(touched)):
        if touched[p]:
            touched[p] = False
            rows[count] = p
            count += 1
            total += patch_ptr[p + 1] - patch_ptr[p]
    parts = SPREAD_PARTS
    ends = np.full(parts + 1, count, dtype=np.int64)
    ends[0] = 0
    summed = 0
    part = 1
    for i in range(count):
        summed += patch_ptr[rows[i] + 1] - patch_ptr[rows[i]]
        while part < parts and summed * parts >= total * part:
            ends[part] = i + 1
            part += 1
    return rows[:count], ends


def unshot_totals(patch_radiosity, shot, spread, area, drift):
    """``sum_p A_p |dB_p|``, ``sum_p A_p (|dB_p| + spread_p)`` and ``sum_p A_p d_p`` (the
    drift of the stored spreads), each over the three channels [W] (see
    :func:`raytrad.core.shot.unshot_totals`)."""
    absolute = magnitude = width = 0.0
    for p in range(len(area)):
        a = area[p]
        for c in range(3):
            u = abs(patch_radiosity[p, c] - shot[p, c])
            absolute += a * u
            magnitude += a * (u + spread[p, c])
            width += a * drift[p, c]
    return absolute, magnitude, width


def add_drift(p, change, patch_radiosity, shot, spread, peak, drift):
    """Patch ``p``'s drift after a shot added ``change`` ((3,) [W m-2], each channel's
    ``c S_p >= 0`` or <= 0 with ``c`` the shot per unit factor and ``S_p = sum_k W_pk
    rho_k F_k``) to its radiosity through receivers whose own radiosity each gained
    ``c rho_k F_k``: ``sum_k W_pk |delta_k - change| <= 2 |change|`` (the weights sum to
    1), so the spread moved by at most that, with :data:`DRIFT_ROUNDING`."""
    for c in range(3):
        scale = abs(patch_radiosity[p, c]) + abs(shot[p, c]) + peak[p, c] + spread[p, c]
        drift[p, c] += 2.000001 * abs(change[c]) + DRIFT_ROUNDING * (scale + drift[p, c])


def _ambient_light(patch_radiosity, shot, area, reflectance, captured, gain):
    """Ambient overshooting's unshot power ``sum_p A_p dB_p`` [W] and ambient term
    (formula 3) [W m-2], (3,) each (see :func:`raytrad.core.solver.ambient_light`)."""
    count = len(area)
    total_area = known_area = known_capture = 0.0
    for p in range(count):
        total_area += area[p]
        if captured[p] == captured[p]:  # not NaN: the patch has shot
            known_area += area[p]
            known_capture += captured[p] * area[p]
    mean_capture = known_capture / known_area if known_area > 0.0 else 1.0
    power = np.zeros(3)
    lost = np.zeros(3)
    for p in range(count):
        a = area[p]
        capture = captured[p] if captured[p] == captured[p] else mean_capture
        for c in range(3):
            power[c] += a * (patch_radiosity[p, c] - shot[p, c])
            lost[c] += a * (1.0 - reflectance[p, c] * capture)
    ambient = np.empty(3)
    floor = 1e-300 * total_area
    for c in range(3):
        ambient[c] = max(power[c] / max(lost[c], floor), 0.0) * gain  # formula 3
    return power, ambient


def _chosen(p, patch_radiosity, shot, spread, area, reflectance, power, ambient, drift):
    """Patch ``p``'s ``A_p sum_c (|amount_pc| + spread_pc + d_pc)`` (its value for the
    choice, exact when its drift ``d_p`` is zero, an upper bound otherwise)."""
    chosen = 0.0
    for c in range(3):
        cap = max(power[c], 0.0) / area[p]
        value = min(patch_radiosity[p, c] - shot[p, c] + reflectance[p, c] * ambient[c], cap)
        chosen += abs(value) + spread[p, c] + drift[p, c]
    return area[p] * chosen


def ambient_choice(
    patch_radiosity,
    shot,
    spread,
    peak,
    drift,
    area,
    reflectance,
    captured,
    gain,
    amount,
    patch_entries,
    patch_ptr,
    patch_receiver,
    patch_weight,
    radiosity,
    entry_shot,
    touched,
):
    """Ambient overshooting's shooter (see :func:`raytrad.core.solver._ambient_amount`
    and the selection in :func:`raytrad.core.solver.solve`): the first patch of largest
    ``A_p sum_c (|amount_pc| + spread_pc)`` and that value; its amount ((3,) [W m-2])
    into ``amount``. A NaN value is chosen first, as ``np.argmax`` would.

    Patches whose spread has drifted (``drift`` (P, 3) > 0) are summed again first where
    their bound reaches the largest exact value (every one when a value is NaN), their
    marks in ``touched``; the others cannot be chosen, so the choice is the one every
    spread summed again would give."""
    count = len(area)
    power, ambient = _ambient_light(patch_radiosity, shot, area, reflectance, captured, gain)
    floor = -np.inf
    unknown = False
    for p in range(count):
        value = _chosen(p, patch_radiosity, shot, spread, area, reflectance, power, ambient, drift)
        if value != value:
            unknown = True
        elif drift[p, 0] == 0.0 and drift[p, 1] == 0.0 and drift[p, 2] == 0.0:
            floor = max(floor, value)
    stale = False
    for p in range(count):
        if drift[p, 0] > 0.0 or drift[p, 1] > 0.0 or drift[p, 2] > 0.0:
            value = _chosen(
                p, patch_radiosity, shot, spread, area, reflectance, power, ambient, drift
            )
            if unknown or not value < floor:
                touched[p] = True
                stale = True
    if stale:
        rows, ends = _touched_runs(touched, patch_ptr)
        for run in prange(SPREAD_PARTS):  # rows apart: the same sums on any number of threads
            for i in range(ends[run], ends[run + 1]):
                p = rows[i]
                _spread_row(
                    p,
                    patch_radiosity[p, 0] - shot[p, 0],
                    patch_radiosity[p, 1] - shot[p, 1],
                    patch_radiosity[p, 2] - shot[p, 2],
                    patch_entries,
                    patch_ptr,
                    patch_receiver,
                    patch_weight,
                    radiosity,
                    entry_shot,
                    spread,
                    peak,
                )
                drift[p, 0] = drift[p, 1] = drift[p, 2] = 0.0
    best = -1
    top = 0.0
    for p in range(count):
        magnitude = _chosen(
            p, patch_radiosity, shot, spread, area, reflectance, power, ambient, drift
        )
        if best < 0 or magnitude > top or (magnitude != magnitude and top == top):
            best, top = p, magnitude
    for c in range(3):
        cap = max(power[c], 0.0) / area[best]
        u = patch_radiosity[best, c] - shot[best, c]
        amount[c] = min(u + reflectance[best, c] * ambient[c], cap)  # formulas 4 and 5
    return best, top


def refresh_stale(
    touched,
    patch_entries,
    patch_ptr,
    patch_receiver,
    patch_weight,
    radiosity,
    entry_shot,
    patch_radiosity,
    shot,
    spread,
    peak,
    drift,
    area,
):
    """Every patch whose spread has drifted summed again (each apart, in
    :func:`_touched_runs`' runs), its drift zeroed, so that the stored spread and peak are
    exact; returns :func:`unshot_totals` then."""
    for p in range(len(touched)):
        if drift[p, 0] > 0.0 or drift[p, 1] > 0.0 or drift[p, 2] > 0.0:
            touched[p] = True
    rows, ends = _touched_runs(touched, patch_ptr)
    for run in prange(SPREAD_PARTS):  # rows apart: the same sums on any number of threads
        for i in range(ends[run], ends[run + 1]):
            p = rows[i]
            _spread_row(
                p,
                patch_radiosity[p, 0] - shot[p, 0],
                patch_radiosity[p, 1] - shot[p, 1],
                patch_radiosity[p, 2] - shot[p, 2],
                patch_entries,
                patch_ptr,
                patch_receiver,
                patch_weight,
                radiosity,
                entry_shot,
                spread,
                peak,
            )
            drift[p, 0] = drift[p, 1] = drift[p, 2] = 0.0
    return unshot_totals(patch_radiosity, shot, spread, area, drift)
