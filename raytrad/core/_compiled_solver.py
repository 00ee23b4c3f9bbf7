"""The solve's and balancing's loops behind :mod:`raytrad.core.compiled`, written for numba
(imported only there): a shot through a cached column, the solver's per-patch spread and
average, balancing's Sinkhorn scaling. Plain Python as written here;
:func:`raytrad.core.compiled.get` compiles every function in :data:`KERNELS`. Each
computes what its numpy reference computes (:mod:`raytrad.core.solver`,
:mod:`raytrad.core.balance`, :mod:`raytrad.core.system`); see there for shapes and units.
"""

# mypy: ignore-errors

import numpy as np

#: Every function to compile, each after the helpers it calls.
KERNELS = (
    "patch_spread",
    "patch_average",
    "shoot",
    "column_capture",
    "column_accumulate",
    "column_final",
)


def patch_spread(
    entry_receiver,
    entry_patch,
    entry_weight,
    emission,
    reflectance,
    irradiance,
    entry_shot,
    unshot,
    patch_count,
):
    """Per patch ``sum_k W_pk |dB_pk - dB_p|`` and ``max_k |dB_pk|`` (see
    :meth:`raytrad.core.system.DiscreteSystem.numpy_spread`)."""
    spread = np.zeros((patch_count, 3))
    peak = np.zeros((patch_count, 3))
    for e in range(len(entry_receiver)):
        k = entry_receiver[e]
        p = entry_patch[e]
        for c in range(3):
            own = emission[k, c] + reflectance[k, c] * irradiance[k, c] - entry_shot[e, c]
            spread[p, c] += entry_weight[e] * abs(own - unshot[p, c])
            peak[p, c] = max(peak[p, c], abs(own))
    return spread, peak


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


def shoot(
    entries,
    entry_receiver,
    entry_weight,
    emission,
    reflectance,
    irradiance,
    entry_shot,
    amount,
    receivers,
    factors,
    near_receivers,
    near_pointer,
    near_sources,
    near_weights,
    area,
    receiver_ptr,
    entry_patch,
    patch_radiosity,
    scratch,
    sub_lo,
    sub_hi,
    mean_ptr,
    mean_receivers,
    mean_shares,
    base,
):
    """One shot through a cached column, in place (see
    :func:`raytrad.core.solver.numpy_shoot`, the reference, for the steps). Returns the
    power caught by the receivers, the power they reflect ((3,) each, [W]) and
    ``sum_j a_j F_jp`` [m2]. The patch's sub-areas and clusters (nodes ``sub_lo:sub_hi``)
    get the means of its receivers' shots at ``scratch[base + s]`` (their CSR ``mean_*``)."""
    n = len(entries)
    own = np.empty((n, 3))
    mean = np.zeros(3)
    for i in range(n):
        e = entries[i]
        k = entry_receiver[e]
        for c in range(3):
            own[i, c] = emission[k, c] + reflectance[k, c] * irradiance[k, c] - entry_shot[e, c]
            mean[c] += entry_weight[e] * own[i, c]
    for i in range(n):
        e = entries[i]
        k = entry_receiver[e]
        for c in range(3):
            value = own[i, c] + (amount[c] - mean[c])
            entry_shot[e, c] += value
            scratch[k, c] = value
    count = len(receivers)
    received = np.empty((count, 3))
    for r in range(count):
        for c in range(3):
            received[r, c] = factors[r] * amount[c]
    near_count = len(near_receivers)
    if near_count:
        for s in range(sub_lo, sub_hi):
            for q in range(mean_ptr[s], mean_ptr[s + 1]):
                for c in range(3):
                    scratch[base + s, c] += mean_shares[q] * scratch[mean_receivers[q], c]
        near = np.empty(near_count, dtype=np.int64)
        r = 0
        for g in range(near_count):  # both ascending
            while receivers[r] != near_receivers[g]:
                r += 1
            near[g] = r
        excess = np.zeros(3)
        for g in range(near_count):
            r = near[g]
            seen0 = seen1 = seen2 = 0.0
            for s in range(near_pointer[g], near_pointer[g + 1]):
                w = near_weights[s]
                source = near_sources[s]
                seen0 += w * scratch[source, 0]
                seen1 += w * scratch[source, 1]
                seen2 += w * scratch[source, 2]
            a = area[receivers[r]]
            f = factors[r]
            received[r, 0] = f * seen0
            received[r, 1] = f * seen1
            received[r, 2] = f * seen2
            for c in range(3):
                excess[c] += a * (received[r, c] - f * amount[c])
        is_near = np.zeros(count, dtype=np.bool_)
        for g in range(near_count):
            is_near[near[g]] = True
        caught = 0.0
        for r in range(count):
            if not is_near[r]:
                caught += area[receivers[r]] * factors[r]
        target_near = not caught > 0.0
        if target_near:
            caught = 0.0
            for g in range(near_count):
                caught += area[receivers[near[g]]] * factors[near[g]]
        if caught > 0.0:
            for r in range(count):
                if is_near[r] == target_near:
                    for c in range(3):
                        received[r, c] -= factors[r] * (excess[c] / caught)
        for i in range(n):
            k = entry_receiver[entries[i]]
            for c in range(3):
                scratch[k, c] = 0.0
        for s in range(sub_lo, sub_hi):
            for c in range(3):
                scratch[base + s, c] = 0.0
    else:
        for i in range(n):
            k = entry_receiver[entries[i]]
            for c in range(3):
                scratch[k, c] = 0.0
    power = np.zeros(3)
    reflected = np.zeros(3)
    capture = 0.0
    bounce = np.empty(3)
    for r in range(count):
        k = receivers[r]
        a = area[k]
        capture += a * factors[r]
        for c in range(3):
            value = received[r, c]
            irradiance[k, c] += value
            bounce[c] = reflectance[k, c] * value
            power[c] += a * value
            reflected[c] += a * bounce[c]
        for e in range(receiver_ptr[k], receiver_ptr[k + 1]):  # each (patch, c) in order
            w = entry_weight[e]
            p = entry_patch[e]
            patch_radiosity[p, 0] += w * bounce[0]
            patch_radiosity[p, 1] += w * bounce[1]
            patch_radiosity[p, 2] += w * bounce[2]
    return power, reflected, capture


def column_capture(rows, values, receiver_area, row_scale):
    """``sum a F r`` of one column (see :func:`raytrad.core.balance.numpy_column_capture`)."""
    capture = 0.0
    for k in range(len(rows)):
        j = rows[k]
        capture += receiver_area[j] * values[k] * row_scale[j]
    return capture


def column_accumulate(rows, values, scale, row_sum):
    """``row_sum[rows] += values * scale`` (see
    :func:`raytrad.core.balance.numpy_column_accumulate`)."""
    for k in range(len(rows)):
        row_sum[rows[k]] += values[k] * scale


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
