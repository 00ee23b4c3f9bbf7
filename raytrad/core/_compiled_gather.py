"""The gather loops behind :mod:`raytrad.core.compiled`, written for numba (imported only
there): how near receivers' gather weights are spread and summed. Plain Python as written
here; :func:`raytrad.core.compiled.get` compiles every function in :data:`KERNELS`, as for
:mod:`raytrad.core._compiled_kernels`. Each computes the same formula, in the same order,
as its numpy reference in :mod:`raytrad.core.gather`; see there for shapes and units.
"""

# mypy: ignore-errors

import math

import numpy as np

#: Every function to compile, each after the helpers it calls.
KERNELS = (
    "_triangle_corner_weights",
    "subarea_spread",
    "_sort_ascending",
    "sum_shares",
    "gather_sums",
)


def _triangle_corner_weights(corners, normal, x, nx, rule, rule_weight, out):
    """Corner form factors of one triangle seen from (x, nx) into ``out`` (3,)
    (:func:`raytrad.core.gather.corner_form_factors`; ``rule`` and ``rule_weight`` its
    points and weights)."""
    for v in range(3):
        out[v] = 0.0
    for q in range(len(rule_weight)):
        b0, b1, b2 = rule[q, 0], rule[q, 1], rule[q, 2]
        dx = b0 * corners[0, 0] + b1 * corners[1, 0] + b2 * corners[2, 0] - x[0]
        dy = b0 * corners[0, 1] + b1 * corners[1, 1] + b2 * corners[2, 1] - x[1]
        dz = b0 * corners[0, 2] + b1 * corners[1, 2] + b2 * corners[2, 2] - x[2]
        r2 = dx * dx + dy * dy + dz * dz
        cos_r = max(dx * nx[0] + dy * nx[1] + dz * nx[2], 0.0)
        cos_s = max(-(dx * normal[0] + dy * normal[1] + dz * normal[2]), 0.0)
        kernel = cos_r * cos_s / (r2 * r2) if r2 > 0.0 else 0.0
        for v in range(3):
            out[v] += kernel * rule_weight[q] * rule[q, v]
    ux = corners[1, 0] - corners[0, 0]
    uy = corners[1, 1] - corners[0, 1]
    uz = corners[1, 2] - corners[0, 2]
    vx = corners[2, 0] - corners[0, 0]
    vy = corners[2, 1] - corners[0, 1]
    vz = corners[2, 2] - corners[0, 2]
    cx, cy, cz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    area = 0.5 * math.sqrt(cx * cx + cy * cy + cz * cz)
    for v in range(3):
        out[v] *= area / (12.0 * math.pi)


def subarea_spread(
    sub_pair,
    subareas,
    sub_weight,
    sub_ptr,
    sub_tri,
    tri_share,
    corner_share,
    corners,
    tri_corners,
    tri_normal,
    points,
    normals,
    sub_point,
    sub_reach,
    src_ptr,
    base,
    rule,
    rule_weight,
):
    """Sub-area elements' weights on their receivers, a far one's on its sub-area's mean
    (:func:`raytrad.core.gather.numpy_subarea_spread`; far elements first, then near
    ones, each in element order)."""
    n = len(subareas)
    far = np.empty(n, dtype=np.bool_)
    count = 0
    for a in range(n):
        s, p = subareas[a], sub_pair[a]
        dx = points[p, 0] - sub_point[s, 0]
        dy = points[p, 1] - sub_point[s, 1]
        dz = points[p, 2] - sub_point[s, 2]
        far[a] = math.sqrt(dx * dx + dy * dy + dz * dz) > sub_reach[s]
        if far[a]:
            count += 1 if src_ptr[s + 1] > src_ptr[s] else 0
        else:
            count += 3 * (sub_ptr[s + 1] - sub_ptr[s])
    out_pair = np.empty(count, dtype=np.int64)
    out_source = np.empty(count, dtype=np.int64)
    out_weight = np.empty(count)
    i = 0
    for a in range(n):
        s = subareas[a]
        if far[a] and src_ptr[s + 1] > src_ptr[s]:  # the sub-area's mean
            out_pair[i] = sub_pair[a]
            out_source[i] = base + s
            out_weight[i] = sub_weight[a]
            i += 1
    raw = np.empty(3)
    for a in range(n):
        if far[a]:
            continue
        s, p = subareas[a], sub_pair[a]
        first = i
        total = 0.0
        for slot in range(sub_ptr[s], sub_ptr[s + 1]):
            t = sub_tri[slot]
            _triangle_corner_weights(
                tri_corners[t], tri_normal[t], points[p], normals[p], rule, rule_weight, raw
            )
            seen = 0.0
            for v in range(3):
                if corner_share[t, v] > 0.0:
                    seen += raw[v]
            scale = (raw[0] + raw[1] + raw[2]) / seen if seen > 0.0 else 0.0
            for v in range(3):
                w = raw[v] * scale if corner_share[t, v] > 0.0 else 0.0
                out_pair[i] = p
                out_source[i] = corners[t, v]
                out_weight[i] = w
                total += w
                i += 1
        if not total > 0.0:
            for slot in range(sub_ptr[s], sub_ptr[s + 1]):
                t = sub_tri[slot]
                j = first + 3 * (slot - sub_ptr[s])
                for v in range(3):
                    out_weight[j + v] = sub_weight[a] * tri_share[slot] * corner_share[t, v]
    return out_pair, out_source, out_weight


def _sort_ascending(values, n):
    """Sort ``values[:n]`` ascending in place: Shell's sort with Knuth's gaps 1, 4, 13,
    40, ... ``np.sort`` would do, but numba compiles its quicksort for seconds on a first
    run; this loop compiles in a fraction of one."""
    gap = 1
    while gap < n // 3:
        gap = 3 * gap + 1
    while gap >= 1:
        for i in range(gap, n):
            v = values[i]
            j = i
            while j >= gap and values[j - gap] > v:
                values[j] = values[j - gap]
                j -= gap
            values[j] = v
        gap //= 3


def sum_shares(pair, source, weight, pairs):
    """Positive weights summed per (pair, source), sources ascending within a pair,
    normalised to sum 1 per pair (see :func:`raytrad.core.gather.numpy_sum_shares`; the
    same sums in the same order). ``pair`` need not be sorted: a stable counting sort
    groups it, and each pair's sources are summed in a dense scratch row."""
    n = len(pair)
    pointer = np.zeros(pairs + 1, dtype=np.int64)
    for i in range(n):
        if weight[i] > 0.0:
            pointer[pair[i] + 1] += 1
    for p in range(pairs):
        pointer[p + 1] += pointer[p]
    fill = pointer[:-1].copy()
    order = np.empty(pointer[pairs], dtype=np.int64)
    for i in range(n):
        if weight[i] > 0.0:
            order[fill[pair[i]]] = i
            fill[pair[i]] += 1
    top = 0
    for i in range(n):
        top = max(top, source[i])
    scratch = np.zeros(top + 1)
    touched = np.empty(n, dtype=np.int64)
    out_source = np.empty(n, dtype=np.int64)
    out_weight = np.empty(n)
    out_pointer = np.zeros(pairs + 1, dtype=np.int64)
    count = 0
    for p in range(pairs):
        used = 0
        for k in range(pointer[p], pointer[p + 1]):
            i = order[k]
            s = source[i]
            if scratch[s] == 0.0:
                touched[used] = s
                used += 1
            scratch[s] += weight[i]
        _sort_ascending(touched, used)
        ascending = touched
        total = 0.0
        for k in range(used):
            s = ascending[k]
            out_source[count + k] = s
            out_weight[count + k] = scratch[s]
            total += scratch[s]
            scratch[s] = 0.0
        for k in range(used):
            out_weight[count + k] /= total
        count += used
        out_pointer[p + 1] = count
    return out_pointer, out_source[:count].copy(), out_weight[:count].copy()


def gather_sums(pointer, sources, weights, radiosity):
    """(G, 3) weighted sums of ``radiosity`` rows per near receiver (CSR ``pointer`` into
    ``sources`` and ``weights``; :meth:`raytrad.core.gather.GatherWeights.gathered`)."""
    count = len(pointer) - 1
    out = np.zeros((count, 3))
    for g in range(count):
        s0 = s1 = s2 = 0.0
        for k in range(pointer[g], pointer[g + 1]):
            w = float(weights[k])
            b = radiosity[sources[k]]
            s0 += w * b[0]
            s1 += w * b[1]
            s2 += w * b[2]
        out[g, 0], out[g, 1], out[g, 2] = s0, s1, s2
    return out
