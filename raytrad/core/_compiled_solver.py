"""The solve's and balancing's loops behind :mod:`raytrad.core.compiled`, written for numba
(imported only there): a shot through a cached column (with the spread it changes,
:mod:`raytrad.core._compiled_spread`), the solver's patch average, balancing's Sinkhorn
scaling. Plain Python as written here;
:func:`raytrad.core.compiled.get` compiles every function in :data:`KERNELS`. Each
computes what its numpy reference computes (:mod:`raytrad.core.solver`,
:mod:`raytrad.core.balance`, :mod:`raytrad.core.system`); see there for shapes and units.
"""

# mypy: ignore-errors

import numpy as np

from raytrad.core import _compiled_spread as _s

#: ``numba.prange`` once :mod:`raytrad.core.compiled` compiles these loops (``range`` as
#: plain Python): its loops run on several threads in a kernel's :data:`PARALLEL` copy and
#: one after another in the kernel itself, with the same results.
prange = range

#: Kernels also compiled with ``parallel=True``, as ``<name>_parallel``
#: (:func:`raytrad.core.compiled.solver_loops` chooses).
PARALLEL = ("shoot",)

#: Every function to compile, each after the helpers it calls.
KERNELS = (
    "_factor",
    "_first_at_least",
    "patch_average",
    "_near_rows",
    "_subarea_shots",
    "_captures",
    "_far_patches",
    "shoot",
    "column_sweep",
    "column_final",
)


def patch_average(receivers, values, receiver_ptr, entry_patch, entry_weight, patch_count):
    """``W[:, receivers] @ values`` (see :meth:`raytrad.core.system.DiscreteSystem.average`)."""
    out = np.zeros((patch_count, 3))
    for i in range(len(receivers)):
        k = receivers[i]
        for e in range(receiver_ptr[k], receiver_ptr[k + 1]):
            p = entry_patch[e]
            w = entry_weight[e]
            out[p, 0] += w * values[i, 0]
            out[p, 1] += w * values[i, 1]
            out[p, 2] += w * values[i, 2]
    return out


def _factor(r, k, raw_factors, row_scale, column_scale):
    """Row ``r`` of a column (receiver ``k``) balanced: ``raw_factors[r] * (row_scale[k] *
    column_scale)``, or ``raw_factors[r]`` when ``row_scale`` is empty."""
    if len(row_scale):
        return raw_factors[r] * (row_scale[k] * column_scale)
    return raw_factors[r] * 1.0


def _first_at_least(values, count, bound):
    """The first index of ``values[:count]`` (ascending) whose value is at least
    ``bound`` (``count`` when none is)."""
    lo = 0
    hi = count
    while lo < hi:
        mid = (lo + hi) // 2
        if values[mid] < bound:
            lo = mid + 1
        else:
            hi = mid
    return lo


def _near_rows(receivers, near_receivers, near):
    """The rows of ``near_receivers`` in ``receivers`` (both ascending) into ``near``."""
    r = 0
    for g in range(len(near_receivers)):
        while receivers[r] != near_receivers[g]:
            r += 1
        near[g] = r


def _subarea_shots(sub_lo, sub_hi, mean_ptr, mean_receivers, mean_shares, base, scratch):
    """The means of the shooter's receivers' shots over its sub-areas and clusters (nodes
    ``sub_lo:sub_hi``, CSR ``mean_*``) into ``scratch[base + s]``."""
    for s in range(sub_lo, sub_hi):
        m0 = m1 = m2 = 0.0
        for q in range(mean_ptr[s], mean_ptr[s + 1]):
            share = mean_shares[q]
            source = mean_receivers[q]
            m0 += share * scratch[source, 0]
            m1 += share * scratch[source, 1]
            m2 += share * scratch[source, 2]
        scratch[base + s, 0], scratch[base + s, 1], scratch[base + s, 2] = m0, m1, m2


def _captures(b, blocks, near, receivers, raw_factors, row_scale, column_scale, area):
    """``sum_j a_j F_jp`` over the far and over the near receivers (rows ``near``) of
    block ``b`` of ``blocks`` of a column [m2]."""
    count = len(receivers)
    r0 = count * b // blocks
    r1 = count * (b + 1) // blocks
    g = _first_at_least(near, len(near), r0)
    far = close = 0.0
    for r in range(r0, r1):
        k = receivers[r]
        f = _factor(r, k, raw_factors, row_scale, column_scale)
        if g < len(near) and near[g] == r:
            g += 1
            close += area[k] * f
        else:
            far += area[k] * f
    return far, close


def _far_patches(far_held):
    """The patches with a sum in ``far_held`` ((B, P, 3), left zero) and their sums over
    the blocks in order: (Q,) int32 ascending, (Q, 3)."""
    blocks, count = far_held.shape[0], far_held.shape[1]
    kept = np.zeros(count, dtype=np.bool_)
    total = 0
    for p in range(count):
        for b in range(blocks):
            if far_held[b, p, 0] != 0.0 or far_held[b, p, 1] != 0.0 or far_held[b, p, 2] != 0.0:
                kept[p] = True
        total += kept[p]
    patches = np.empty(total, dtype=np.int32)
    values = np.zeros((total, 3))
    i = 0
    for p in range(count):
        if kept[p]:
            patches[i] = p
            for b in range(blocks):
                for c in range(3):
                    values[i, c] += far_held[b, p, c]
                    far_held[b, p, c] = 0.0
            i += 1
    return patches, values


def shoot(
    patch,
    amount,
    patch_entries,
    patch_ptr,
    patch_receiver,
    patch_weight,
    receiver_ptr,
    entry_patch,
    entry_weight,
    emission,
    reflectance,
    area,
    patch_area,
    receivers,
    raw_factors,
    row_scale,
    column_scale,
    near_receivers,
    near_pointer,
    near_sources,
    near_weights,
    sub_lo,
    sub_hi,
    mean_ptr,
    mean_receivers,
    mean_shares,
    base,
    irradiance,
    radiosity,
    entry_shot,
    patch_radiosity,
    shot,
    absorbed,
    escaped,
    captured,
    spread,
    peak,
    scratch,
    touched,
    held,
    far_held,
    near,
    sums,
    plan_patches,
    plan_values,
    known,
    drift,
    lazy,
):
    """Shoot ``amount`` ((3,) [W m-2]) from ``patch`` through its cached column, in place,
    and bring the state's spread up to date after it (see
    :func:`raytrad.core.shot.numpy_shoot`, the reference, for the steps, and
    :meth:`raytrad.core.system.DiscreteSystem.respread`). Returns the unshot totals after
    the shot (``_compiled_spread.unshot_totals``: the unshot power, the residual's
    numerator and the stored spreads' drift [W]), and the column's far patches and sums
    (below). With ``lazy`` the patches only its far receivers change are not summed
    again: their drift (``drift`` (P, 3)) grows instead (``_compiled_spread.add_drift``).

    The arguments are the system's (:class:`raytrad.core.system.DiscreteSystem`), the
    column's (its receivers, raw factors and balancing scales: its factors are
    ``raw_factors * (row_scale[receivers] * column_scale)``, ``raw_factors`` when
    ``row_scale`` is empty; its near receivers' gather), the patch's sub-areas and
    clusters (nodes ``sub_lo:sub_hi``, which get the means of its receivers' shots at
    ``scratch[base + s]``), the state's (:class:`raytrad.core.solver_state.SolverState`;
    ``radiosity``, ``emission + reflectance * irradiance``, is kept with the
    irradiance), work arrays and the column's plan. The patches whose radiosity or shot
    changes are marked in ``touched`` ((P,) bool) and summed again for their spread,
    which clears the marks.

    The column's receivers and its near receivers are taken in ``len(held)`` blocks (the
    same blocks however many threads run them: :data:`PARALLEL`), each summing apart
    (``held`` and ``far_held`` (B, P, 3) zeros, left zero), and the blocks' sums are
    added in block order; the spread sums each patch apart.

    A far receiver's irradiance is ``F_jp c`` with ``c`` the same for every far receiver
    of the shot (the amount, less what the near ones took), so what the far receivers
    bring to each patch's radiosity and to the power is ``c`` times sums of the column
    alone. Those, with the rows of its near receivers, are its plan, which every shot of
    the column reads: ``near`` (G,) int32 rows, ``sums`` (5,): ``sum_j a_j F_jp`` over
    the far and the near receivers [m2], ``sum_j a_j rho_j F_jp`` over the far ones
    (3,) [m2]; ``plan_patches`` (Q,) int32 and ``plan_values`` (Q, 3) ``sum_j W_qj
    rho_j F_jp`` over the far receivers, per patch ``q`` they change [1]. With ``known``
    False the shot finds the plan first: it fills ``near`` and ``sums`` and returns the
    patches and their sums (the given ones when ``known``)."""
    count = len(receivers)
    first = patch_ptr[patch]
    n = patch_ptr[patch + 1] - first
    own = np.empty((n, 3))
    mean0 = mean1 = mean2 = 0.0
    for i in range(n):
        e = patch_entries[first + i]
        k = patch_receiver[first + i]
        w = patch_weight[first + i]
        for c in range(3):
            own[i, c] = radiosity[k, c] - entry_shot[e, c]
        mean0 += w * own[i, 0]
        mean1 += w * own[i, 1]
        mean2 += w * own[i, 2]
    over0, over1, over2 = amount[0] - mean0, amount[1] - mean1, amount[2] - mean2
    for i in range(n):
        e = patch_entries[first + i]
        k = patch_receiver[first + i]
        v0, v1, v2 = own[i, 0] + over0, own[i, 1] + over1, own[i, 2] + over2
        entry_shot[e, 0] += v0
        entry_shot[e, 1] += v1
        entry_shot[e, 2] += v2
        scratch[k, 0], scratch[k, 1], scratch[k, 2] = v0, v1, v2
    near_count = len(near_receivers)
    seen = np.empty((near_count, 3))
    blocks = len(held)
    part = np.zeros((blocks, 9))
    give0 = give1 = give2 = 0.0
    far_gives = True
    if near_count:
        if not known:
            _near_rows(receivers, near_receivers, near)
        _subarea_shots(sub_lo, sub_hi, mean_ptr, mean_receivers, mean_shares, base, scratch)
        for b in prange(blocks):
            e0 = e1 = e2 = 0.0
            for g in range(near_count * b // blocks, near_count * (b + 1) // blocks):
                r = near[g]
                seen0 = seen1 = seen2 = 0.0
                for s in range(near_pointer[g], near_pointer[g + 1]):
                    w = near_weights[s]
                    source = near_sources[s]
                    seen0 += w * scratch[source, 0]
                    seen1 += w * scratch[source, 1]
                    seen2 += w * scratch[source, 2]
                k = receivers[r]
                a = area[k]
                f = _factor(r, k, raw_factors, row_scale, column_scale)
                seen[g, 0], seen[g, 1], seen[g, 2] = f * seen0, f * seen1, f * seen2
                e0 += a * (seen[g, 0] - f * amount[0])
                e1 += a * (seen[g, 1] - f * amount[1])
                e2 += a * (seen[g, 2] - f * amount[2])
            part[b, 0], part[b, 1], part[b, 2] = e0, e1, e2
            if not known:
                part[b, 3], part[b, 4] = _captures(
                    b, blocks, near, receivers, raw_factors, row_scale, column_scale, area
                )
        excess0 = excess1 = excess2 = caught = caught_near = 0.0
        for b in range(blocks):
            excess0 += part[b, 0]
            excess1 += part[b, 1]
            excess2 += part[b, 2]
            caught += part[b, 3]
            caught_near += part[b, 4]
        if known:
            caught, caught_near = sums[0], sums[1]
        else:
            sums[0], sums[1] = caught, caught_near
        if not caught > 0.0:
            far_gives = False
            caught = caught_near
        if caught > 0.0:
            give0, give1, give2 = excess0 / caught, excess1 / caught, excess2 / caught
            if not far_gives:
                for g in range(near_count):
                    r = near[g]
                    k = receivers[r]
                    f = _factor(r, k, raw_factors, row_scale, column_scale)
                    seen[g, 0] -= f * give0
                    seen[g, 1] -= f * give1
                    seen[g, 2] -= f * give2
        else:
            far_gives = False
        for s in range(sub_lo, sub_hi):
            scratch[base + s, 0] = scratch[base + s, 1] = scratch[base + s, 2] = 0.0
    else:
        far_gives = False
        if not known:
            sums[0] = sums[1] = 0.0
            for b in range(blocks):
                sums[0] += _captures(
                    b, blocks, near, receivers, raw_factors, row_scale, column_scale, area
                )[0]
    for i in range(n):
        k = patch_receiver[first + i]
        scratch[k, 0] = scratch[k, 1] = scratch[k, 2] = 0.0
    # what every far receiver gets per unit factor [W m-2]
    c0, c1, c2 = amount[0], amount[1], amount[2]
    if far_gives:
        c0, c1, c2 = c0 - give0, c1 - give1, c2 - give2
    for b in prange(blocks):
        r0 = count * b // blocks
        r1 = count * (b + 1) // blocks
        g = _first_at_least(near, near_count, r0)
        p0 = p1 = p2 = q0 = q1 = q2 = t0 = t1 = t2 = 0.0
        last = far_last = -1
        h0 = h1 = h2 = s0 = s1 = s2 = 0.0
        for r in range(r0, r1):
            k = receivers[r]
            f = _factor(r, k, raw_factors, row_scale, column_scale)
            if g < near_count and near[g] == r:
                v0, v1, v2 = seen[g, 0], seen[g, 1], seen[g, 2]
                g += 1
            else:
                irradiance[k, 0] += f * c0
                irradiance[k, 1] += f * c1
                irradiance[k, 2] += f * c2
                for c in range(3):
                    radiosity[k, c] = emission[k, c] + reflectance[k, c] * irradiance[k, c]
                if known:
                    continue
                # the plan: this far receiver's a rho F and W rho F per unit shot
                u0, u1, u2 = reflectance[k, 0] * f, reflectance[k, 1] * f, reflectance[k, 2] * f
                a = area[k]
                t0 += a * u0
                t1 += a * u1
                t2 += a * u2
                for e in range(receiver_ptr[k], receiver_ptr[k + 1]):
                    w = entry_weight[e]
                    p = entry_patch[e]
                    if p != far_last:
                        if far_last >= 0:
                            far_held[b, far_last, 0] = s0
                            far_held[b, far_last, 1] = s1
                            far_held[b, far_last, 2] = s2
                        far_last = p
                        s0, s1, s2 = far_held[b, p, 0], far_held[b, p, 1], far_held[b, p, 2]
                    s0 += w * u0
                    s1 += w * u1
                    s2 += w * u2
                continue
            a = area[k]
            irradiance[k, 0] += v0
            irradiance[k, 1] += v1
            irradiance[k, 2] += v2
            radiosity[k, 0] = emission[k, 0] + reflectance[k, 0] * irradiance[k, 0]
            radiosity[k, 1] = emission[k, 1] + reflectance[k, 1] * irradiance[k, 1]
            radiosity[k, 2] = emission[k, 2] + reflectance[k, 2] * irradiance[k, 2]
            b0 = reflectance[k, 0] * v0
            b1 = reflectance[k, 1] * v1
            b2 = reflectance[k, 2] * v2
            p0 += a * v0
            p1 += a * v1
            p2 += a * v2
            q0 += a * b0
            q1 += a * b1
            q2 += a * b2
            for e in range(receiver_ptr[k], receiver_ptr[k + 1]):
                w = entry_weight[e]
                p = entry_patch[e]
                if p != last:
                    if last >= 0:
                        held[b, last, 0], held[b, last, 1], held[b, last, 2] = h0, h1, h2
                    last = p
                    touched[p] = True
                    h0, h1, h2 = held[b, p, 0], held[b, p, 1], held[b, p, 2]
                h0 += w * b0
                h1 += w * b1
                h2 += w * b2
        if last >= 0:
            held[b, last, 0], held[b, last, 1], held[b, last, 2] = h0, h1, h2
        if far_last >= 0:
            far_held[b, far_last, 0], far_held[b, far_last, 1] = s0, s1
            far_held[b, far_last, 2] = s2
        part[b, 0], part[b, 1], part[b, 2] = p0, p1, p2
        part[b, 3], part[b, 4], part[b, 5] = q0, q1, q2
        part[b, 6], part[b, 7], part[b, 8] = t0, t1, t2
    if not known:
        for c in range(3):
            sums[2 + c] = 0.0
            for b in range(blocks):
                sums[2 + c] += part[b, 6 + c]
        plan_patches, plan_values = _far_patches(far_held)
    power = np.zeros(3)
    reflected = np.zeros(3)
    for b in range(blocks):
        for c in range(3):
            power[c] += part[b, c]
            reflected[c] += part[b, 3 + c]
    for p in range(len(touched)):
        if touched[p]:
            for b in range(blocks):
                for c in range(3):
                    patch_radiosity[p, c] += held[b, p, c]
                    held[b, p, c] = 0.0
    power[0] += c0 * sums[0]
    power[1] += c1 * sums[0]
    power[2] += c2 * sums[0]
    reflected[0] += c0 * sums[2]
    reflected[1] += c1 * sums[3]
    reflected[2] += c2 * sums[4]
    change = np.empty(3)
    for i in range(len(plan_patches)):
        p = plan_patches[i]
        change[0], change[1] = c0 * plan_values[i, 0], c1 * plan_values[i, 1]
        change[2] = c2 * plan_values[i, 2]
        patch_radiosity[p, 0] += change[0]
        patch_radiosity[p, 1] += change[1]
        patch_radiosity[p, 2] += change[2]
        if lazy and not touched[p] and p != patch:  # the near receivers' are summed again
            _s.add_drift(p, change, patch_radiosity, shot, spread, peak, drift)
        else:
            touched[p] = True
    area_p = patch_area[patch]
    for c in range(3):
        shot[patch, c] += amount[c]
        absorbed[c] += power[c] - reflected[c]
        escaped[c] += area_p * amount[c] - power[c]
    captured[patch] = (sums[0] + sums[1]) / area_p
    touched[patch] = True  # its receivers' shots and its own shot changed
    rows, ends = _s._touched_runs(touched, patch_ptr)
    for run in prange(_s.SPREAD_PARTS):  # rows apart: the same sums on any number of threads
        for i in range(ends[run], ends[run + 1]):
            p = rows[i]
            _s._spread_row(
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
    absolute, magnitude, width = _s.unshot_totals(patch_radiosity, shot, spread, patch_area, drift)
    return absolute, magnitude, width, plan_patches, plan_values


def column_sweep(rows, values, receiver_area, row_scale, patch_area, closed, limit, row_sum):
    """One column's step of a balancing round: its capture, its new scale, and its factors
    at that scale added to ``row_sum``; returns (capture, scale) (see
    :func:`raytrad.core.balance.numpy_column_sweep`)."""
    total = 0.0
    for k in range(len(rows)):
        j = rows[k]
        total += receiver_area[j] * values[k] * row_scale[j]
    capture = total / patch_area
    scale = 1.0
    if capture > 1.0 or (closed and capture > 0.0):
        scale = min(1.0 / capture, limit)
    for k in range(len(rows)):
        row_sum[rows[k]] += values[k] * scale
    return capture, scale


def column_final(rows, values, receiver_area, row_scale, scale, row_sums):
    """Balanced factors into ``row_sums``, and the capture (see
    :func:`raytrad.core.balance.numpy_column_final`)."""
    capture = 0.0
    for k in range(len(rows)):
        j = rows[k]
        final = values[k] * scale * row_scale[j]
        row_sums[j] += final
        capture += receiver_area[j] * final
    return capture
