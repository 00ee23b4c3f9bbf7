"""The gather loops behind :mod:`raytrad.core.compiled`, written for numba (imported only
there): how near receivers' gather weights are summed per source and gathered (their
spread over sub-areas' corners, ``spread_shares``, lives with the triangle loops it shares
in :mod:`raytrad.core._compiled_near`, and sums with :func:`_add` and :func:`_emit`).
Plain Python as written
here; :func:`raytrad.core.compiled.get` compiles every function in :data:`KERNELS`, as for
:mod:`raytrad.core._compiled_kernels`. Each computes the same formula, in the same order,
as its numpy reference in :mod:`raytrad.core.gather`; see there for shapes and units.
"""

# mypy: ignore-errors

import numpy as np

#: The helpers that allocate nothing and return no array, compiled without reference
#: counting (see :func:`raytrad.core.compiled._jit`): the spread calls them once an entry.
BORROWING = ("_add", "_emit")

#: Every function to compile, each after the helpers it calls.
KERNELS = (
    "_sort_ascending",
    "by_pair",
    "_add",
    "_emit",
    "node_means",
    "_gathered",
    "gather_sums",
    "block_irradiance",
    "add_row",
)


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


def node_means(start, stop, sub_tri, visible_area, corners, corner_share, receivers):
    """Each node's mean of its visible receivers, for the nodes whose triangles are the
    slots ``start[i]:stop[i]`` of ``sub_tri``: CSR ``pointer`` (nodes + 1,), ``sources``
    and ``weights`` (see :func:`raytrad.core.gather.numpy_node_means`; the same sums in
    the same order, without its (slots, 3) temporaries). ``corners`` (T, 3) are the
    triangles' receivers (below ``receivers``) and ``corner_share`` (T, 3) their shares."""
    nodes = len(start)
    entries = np.int64(0)
    widest = np.int64(0)
    for i in range(nodes):
        width = 3 * (stop[i] - start[i])
        entries += width
        widest = max(widest, width)
    scratch = np.zeros(receivers)
    touched = np.empty(widest, dtype=np.int64)
    out_source = np.empty(entries, dtype=np.int64)
    out_weight = np.empty(entries)
    out_pointer = np.zeros(nodes + 1, dtype=np.int64)
    count = np.int64(0)
    for i in range(nodes):
        total = 0.0
        for slot in range(start[i], stop[i]):
            total += visible_area[sub_tri[slot]]
        used = np.int64(0)
        for slot in range(start[i], stop[i]):
            t = sub_tri[slot]
            share = visible_area[t] / total if total > 0.0 else 0.0
            for k in range(3):
                used = _add(corners[t, k], share * corner_share[t, k], scratch, touched, used)
        count = _emit(touched, used, scratch, out_source, out_weight, count)
        out_pointer[i + 1] = count
    return out_pointer, out_source[:count].copy(), out_weight[:count].copy()


def by_pair(pair, pairs):
    """A stable counting sort of the indices of ``pair`` (values below ``pairs``): CSR
    ``pointer`` (pairs + 1,) into ``order`` (N,), both int64."""
    pointer = np.zeros(pairs + 1, dtype=np.int64)
    for i in range(len(pair)):
        pointer[pair[i] + 1] += 1
    for p in range(pairs):
        pointer[p + 1] += pointer[p]
    fill = pointer[:-1].copy()
    order = np.empty(len(pair), dtype=np.int64)
    for i in range(len(pair)):
        order[fill[pair[i]]] = i
        fill[pair[i]] += 1
    return pointer, order


def _add(source, weight, scratch, touched, used):
    """A positive ``weight`` added to ``scratch[source]``, the source listed in
    ``touched[used]`` when it is the first of its pair; returns the new count listed."""
    if weight > 0.0:
        if scratch[source] == 0.0:
            touched[used] = source
            used += 1
        scratch[source] += weight
    return used


def _emit(touched, used, scratch, out_source, out_weight, count):
    """One pair's sums from ``scratch`` into ``out_*[count:]``, sources ascending and
    weights normalised to sum 1 (``scratch`` left zero); returns the new count."""
    _sort_ascending(touched, used)
    total = 0.0
    for k in range(used):
        s = touched[k]
        out_source[count + k] = s
        out_weight[count + k] = scratch[s]
        total += scratch[s]
        scratch[s] = 0.0
    for k in range(used):
        out_weight[count + k] /= total
    return count + used


def _gathered(g, pointer, sources, weights, radiosity):
    """Near receiver ``g``'s weighted sum of ``radiosity`` rows, (s0, s1, s2)."""
    s0 = s1 = s2 = 0.0
    for k in range(pointer[g], pointer[g + 1]):
        w = float(weights[k])
        b = radiosity[sources[k]]
        s0 += w * b[0]
        s1 += w * b[1]
        s2 += w * b[2]
    return s0, s1, s2


def gather_sums(pointer, sources, weights, radiosity):
    """(G, 3) weighted sums of ``radiosity`` rows per near receiver (CSR ``pointer`` into
    ``sources`` and ``weights``; :meth:`raytrad.core.gather.GatherWeights.gathered`)."""
    count = len(pointer) - 1
    out = np.zeros((count, 3))
    for g in range(count):
        out[g, 0], out[g, 1], out[g, 2] = _gathered(g, pointer, sources, weights, radiosity)
    return out


def block_irradiance(out, mean, near, factors, local, pointer, sources, weights, radiosity):
    """One patch's part of a final gather, added to ``out`` (N, 3) (see
    :func:`raytrad.core.gather.numpy_gathered_irradiance`, the same sums in the same
    order): ``F B̄_p`` (``mean`` (3,)) at each point ``near``, then ``F (B̃ - B̄_p)`` at
    its near-field points (``local``, indices into ``near``), ``B̃`` summed as
    :func:`gather_sums` sums it."""
    b0, b1, b2 = mean[0], mean[1], mean[2]
    for i in range(len(near)):
        j, f = near[i], factors[i]
        out[j, 0] += f * b0
        out[j, 1] += f * b1
        out[j, 2] += f * b2
    for g in range(len(local)):
        s0, s1, s2 = _gathered(g, pointer, sources, weights, radiosity)
        i = local[g]
        j, f = near[i], factors[i]
        out[j, 0] += f * (s0 - b0)
        out[j, 1] += f * (s1 - b1)
        out[j, 2] += f * (s2 - b2)


def add_row(raw_sum, row_sum, near, factors, scale, scaled):
    """One patch's row added to a final gather's sums in place (see
    :meth:`raytrad.core.gather.GatherRows.add`): ``factors`` to ``raw_sum`` at the points
    ``near`` (each once), ``factors * scale`` into ``scaled`` and to ``row_sum``."""
    for i in range(len(near)):
        j = near[i]
        f = factors[i]
        raw_sum[j] += f
        s = f * scale
        scaled[i] = s
        row_sum[j] += s
