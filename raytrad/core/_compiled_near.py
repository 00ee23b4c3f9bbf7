"""The near field's loops behind :mod:`raytrad.core.compiled`, written for numba (imported
only there): the walk through a sub-area's cluster tree, a near (receiver, sub-area)
pair's elements, and the spread of the elements' weights over receivers and means,
summed per source (with :mod:`raytrad.core._compiled_gather`'s sums).

Plain Python as written here, compiled like :mod:`raytrad.core._compiled_kernels`, whose
compiled helpers these call through the module (bound compiled by the time these run).
Each computes the same formula, in the same order, as its numpy reference:
:meth:`raytrad.core.pairs.PairFactors._numpy_near_field`,
:func:`raytrad.core.spread.numpy_spread_shares`, :func:`raytrad.core.clusters.numpy_cuts`.
"""

# mypy: ignore-errors

import math

import numpy as np

from raytrad.core import _compiled_gather as _g
from raytrad.core import _compiled_kernels as _k

#: The helpers that allocate nothing and return no array, compiled without reference
#: counting (see :func:`raytrad.core.compiled._jit`): a near triangle's step alone passed
#: some 20 arrays a call, each counted in and out.
BORROWING = (
    "_triangle_corner_weights",
    "_cut",
    "_disk",
    "_triangle",
    "_node_items",
    "_corner_items",
)

#: Every function to compile, each after the helpers it calls.
KERNELS = (
    "_triangle_corner_weights",
    "_cut",
    "_disk",
    "_buffers",
    "_triangle",
    "_node_items",
    "_corner_items",
    "spread_shares",
    "chunk_elements",
    "spread_chunk",
    "near_triangles",
)

#: Depth of the walk's stack: two entries a level (a million levels' worth of halving).
STACK = 256


def _triangle_corner_weights(corners, normal, x, nx, rule, rule_weight, out):
    """Corner form factors of one triangle seen from (x, nx) into ``out`` (3,)
    (:func:`raytrad.core.spread.corner_form_factors`; ``rule`` and ``rule_weight`` its
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


def _cut(first, x, threshold, left, right, point, stack, cut):
    """The items below node ``first`` seen from ``x`` into ``cut``, in the order of their
    slots; returns their count (see :func:`raytrad.core.clusters.numpy_cuts`): a node
    with halves farther than ``threshold`` is taken whole (``>= 0``), a leaf as its
    triangles (``-1 - leaf``); ``first`` itself is never taken whole."""
    stack[0] = first
    top = 1
    m = 0
    while top > 0:
        top -= 1
        n = stack[top]
        if left[n] < 0:
            cut[m] = -1 - n
            m += 1
            continue
        if n != first:
            dx, dy, dz = x[0] - point[n, 0], x[1] - point[n, 1], x[2] - point[n, 2]
            if math.sqrt(dx * dx + dy * dy + dz * dz) > threshold[n]:
                cut[m] = n
                m += 1
                continue
        stack[top] = right[n]  # the left half on top: slots in order
        stack[top + 1] = left[n]
        top += 2
    return m


def _disk(x, nx, point, normal, area):
    """The disk-approximation factor of a node (``point``, unit ``normal``, ``area``)
    seen from (``x``, ``nx``), 0 where either faces away (see
    :func:`raytrad.core.clusters.disk_factors`)."""
    dx, dy, dz = point[0] - x[0], point[1] - x[1], point[2] - x[2]
    r2 = dx * dx + dy * dy + dz * dz
    r = math.sqrt(r2)
    inv_r = 1.0 / (r if r > 0.0 else 1.0)
    cos_r = (dx * nx[0] + dy * nx[1] + dz * nx[2]) * inv_r
    cos_s = -(dx * normal[0] + dy * normal[1] + dz * normal[2]) * inv_r
    if cos_r > 0.0 and cos_s > 0.0:
        return cos_r * cos_s * area / (math.pi * r2 + area)
    return 0.0


def _buffers(nodes, start, stop):
    """The walk's stack and a cut buffer long enough for any of ``nodes``' subtrees."""
    longest = 1
    for a in range(len(nodes)):
        longest = max(longest, 2 * (stop[nodes[a]] - start[nodes[a]]) + 1)
    return np.empty(STACK, dtype=np.int64), np.empty(longest, dtype=np.int64)


def spread_shares(
    sub_pair,
    nodes,
    sub_weight,
    points,
    normals,
    tables,
    tri_pair,
    triangles,
    tri_weight,
    tri_share,
):
    """The node elements' and triangle elements' weights on receivers and means, summed
    per (pair, source) and normalised per pair, in one loop: what
    :func:`raytrad.core.gather.numpy_sum_shares` makes of
    :func:`raytrad.core.spread.numpy_subarea_spread`'s and
    :func:`raytrad.core.spread.numpy_corner_elements`' entries (CSR ``pointer`` by pair,
    ``sources`` ascending within one, ``weights``). A pair's entries are summed in the
    order the entries of a spread would come (its nodes handed on whole, then its near
    nodes' items in the order of their slots, then its triangles' corners, each in element
    order), without the entries being written out. ``tables`` are
    :meth:`raytrad.core.spread.GatherShares._tables` (the tree's arrays, its nodes' and
    triangles' tables, the means' pointer and base, the corner rule)."""
    tree, node_reach, node_visible, visible_area, corner_share, corners = tables[:6]
    tri_corners, tri_normal, mean_ptr, base, rule, rule_weight = tables[6:]
    _, start, stop, left, right, node_point, _, _ = tree
    n = len(nodes)
    far = np.empty(n, dtype=np.bool_)
    stack, cut = _buffers(nodes, start, stop)
    count = 3 * len(triangles)
    widest = 0
    for a in range(n):
        s, p = nodes[a], sub_pair[a]
        dx = points[p, 0] - node_point[s, 0]
        dy = points[p, 1] - node_point[s, 1]
        dz = points[p, 2] - node_point[s, 2]
        far[a] = math.sqrt(dx * dx + dy * dy + dz * dz) > node_reach[s]
        if far[a]:
            count += 1 if mean_ptr[s + 1] > mean_ptr[s] else 0
            continue
        m = _cut(s, points[p], node_reach, left, right, node_point, stack, cut)
        items = 0
        for q in range(m):
            item = cut[q]
            if item >= 0:
                items += 1 if mean_ptr[item + 1] > mean_ptr[item] else 0
            else:
                items += 3 * (stop[-1 - item] - start[-1 - item])
        count += items
        widest = max(widest, items)
    node_ptr, node_order = _g.by_pair(sub_pair, len(points))
    tri_ptr, tri_order = _g.by_pair(tri_pair, len(points))
    item_source = np.empty(widest, dtype=np.int64)
    item_weight = np.empty(widest)
    item_area = np.empty(widest)  # each item's visible area: its weight when nothing is seen
    scratch = np.zeros(base + len(start))
    touched = np.empty(count, dtype=np.int64)
    out_source = np.empty(count, dtype=np.int64)
    out_weight = np.empty(count)
    out_pointer = np.zeros(len(points) + 1, dtype=np.int64)
    tables = (node_reach, node_visible, visible_area, corner_share)
    triangle_tables = (corners, tri_corners, tri_normal, mean_ptr)
    rules = (rule, rule_weight)
    work = (stack, cut, np.empty(3))
    buffers = (item_source, item_weight, item_area)
    done = np.int64(0)
    for p in range(len(points)):
        used = np.int64(0)
        for r in range(node_ptr[p], node_ptr[p + 1]):  # the nodes handed on whole
            a = node_order[r]
            s = nodes[a]
            if far[a] and mean_ptr[s + 1] > mean_ptr[s]:
                used = _g._add(base + s, sub_weight[a], scratch, touched, used)
        for r in range(node_ptr[p], node_ptr[p + 1]):
            a = node_order[r]
            if not far[a]:
                element = (nodes[a], sub_weight[a], base)
                view = (points[p], normals[p])
                items = _node_items(
                    element, view, tree, tables, triangle_tables, rules, work, buffers
                )
                for j in range(items):
                    used = _g._add(item_source[j], item_weight[j], scratch, touched, used)
        for r in range(tri_ptr[p], tri_ptr[p + 1]):
            b = tri_order[r]
            used = _corner_items(
                b, triangles, tri_weight, tri_share, corner_share, corners, scratch, touched, used
            )
        done = _g._emit(touched, used, scratch, out_source, out_weight, done)
        out_pointer[p + 1] = done
    return out_pointer, out_source[:done].copy(), out_weight[:done].copy()


def spread_chunk(
    close,
    weight,
    far,
    far_hidden,
    root,
    near_c,
    near_tri,
    near_w,
    near_share,
    near_hidden,
    node_c,
    node,
    node_w,
    node_hidden,
    points,
    normals,
    tables,
):
    """A chunk's gather weights from its samples (see
    :meth:`raytrad.core.spread.GatherShares.spread_chunk`, whose numpy path is the
    reference): the elements of :func:`chunk_elements` spread and summed by
    :func:`spread_shares`, then the close receivers that gather anything (chunk indices)
    and their CSR pointer into the sources and weights."""
    pair, sub_pair, nodes, sub_weight = chunk_elements(
        close, weight, far, far_hidden, root, node_c, node, node_w, node_hidden
    )
    count = 0
    for k in range(len(near_c)):
        if close[near_c[k]] and not near_hidden[k]:
            count += 1
    tri_pair = np.empty(count, dtype=np.int64)
    triangles = np.empty(count, dtype=np.int64)
    tri_weight = np.empty(count)
    tri_share = np.empty((count, 3))
    b = 0
    for k in range(len(near_c)):
        if close[near_c[k]] and not near_hidden[k]:
            tri_pair[b], triangles[b], tri_weight[b] = pair[near_c[k]], near_tri[k], near_w[k]
            for v in range(3):
                tri_share[b, v] = near_share[k, v]
            b += 1
    rows = np.flatnonzero(close)
    pointer, sources, weights = spread_shares(
        sub_pair,
        nodes,
        sub_weight,
        points[rows],
        normals[rows],
        tables,
        tri_pair,
        triangles,
        tri_weight,
        tri_share,
    )
    kept = 0
    for p in range(len(rows)):
        if pointer[p + 1] > pointer[p]:  # a receiver that sees none of the patch: no row
            rows[kept] = rows[p]
            pointer[kept + 1] = pointer[p + 1]
            kept += 1
    return rows[:kept].copy(), pointer[: kept + 1].copy(), sources, weights


def chunk_elements(close, weight, far, far_hidden, root, node_c, node, node_w, node_hidden):
    """Each chunk receiver's pair index (its rank among the ``close`` ones) and the node
    elements of the close receivers: their far samples that are not hidden, row by row
    (node ``root[s]``, weight ``weight[c, s]``), then the near field's clusters taken
    whole that are not hidden, in their order (see
    :func:`raytrad.core.spread.numpy_chunk_elements`)."""
    count_c, count_s = far.shape
    pair = np.empty(count_c, dtype=np.int64)
    pairs = 0
    count = 0
    for c in range(count_c):
        pair[c] = pairs
        if close[c]:
            pairs += 1
            for s in range(count_s):
                if far[c, s] and not far_hidden[c, s]:
                    count += 1
    for h in range(len(node_c)):
        if close[node_c[h]] and not node_hidden[h]:
            count += 1
    sub_pair = np.empty(count, dtype=np.int64)
    nodes = np.empty(count, dtype=np.int64)
    sub_weight = np.empty(count)
    i = 0
    for c in range(count_c):
        if close[c]:
            for s in range(count_s):
                if far[c, s] and not far_hidden[c, s]:
                    sub_pair[i], nodes[i], sub_weight[i] = pair[c], root[s], weight[c, s]
                    i += 1
    for h in range(len(node_c)):
        if close[node_c[h]] and not node_hidden[h]:
            sub_pair[i], nodes[i], sub_weight[i] = pair[node_c[h]], node[h], node_w[h]
            i += 1
    return pair, sub_pair, nodes, sub_weight


def _node_items(element, view, tree, tables, triangle_tables, rules, work, buffers):
    """A near node element (``element``: node, sampled weight, the means' ``base``) seen
    from ``view`` (x, nx): its items' sources and weights into ``buffers``
    (``item_source``, ``item_weight``, ``item_area``), in the order of their slots;
    returns their count (see :func:`spread_shares`, which packs the other tuples)."""
    s, weight, base = element
    x, nx = view
    node_reach, node_visible, visible_area, corner_share = tables
    corners, tri_corners, tri_normal, mean_ptr = triangle_tables
    rule, rule_weight = rules
    stack, cut, raw = work
    item_source, item_weight, item_area = buffers
    sub_tri, start, stop, left, right, node_point, node_normal, node_area = tree
    i = 0
    total = 0.0
    m = _cut(s, x, node_reach, left, right, node_point, stack, cut)
    for q in range(m):
        item = cut[q]
        if item >= 0:
            if mean_ptr[item + 1] > mean_ptr[item]:
                w = _disk(x, nx, node_point[item], node_normal[item], node_area[item])
                item_source[i], item_weight[i] = base + item, w
                item_area[i] = node_visible[item]
                total += w
                i += 1
            continue
        leaf = -1 - item
        for slot in range(start[leaf], stop[leaf]):
            t = sub_tri[slot]
            _triangle_corner_weights(tri_corners[t], tri_normal[t], x, nx, rule, rule_weight, raw)
            seen = 0.0
            for v in range(3):
                if corner_share[t, v] > 0.0:
                    seen += raw[v]
            scale = (raw[0] + raw[1] + raw[2]) / seen if seen > 0.0 else 0.0
            for v in range(3):
                w = raw[v] * scale if corner_share[t, v] > 0.0 else 0.0
                item_source[i], item_weight[i] = corners[t, v], w
                item_area[i] = visible_area[t] * corner_share[t, v]
                total += w
                i += 1
    if not total > 0.0:  # seeing none of it: the sampled weight by visible area
        scale = weight / node_visible[s] if node_visible[s] > 0.0 else 0.0
        for j in range(i):
            item_weight[j] = scale * item_area[j]
    return i


def _corner_items(
    b, triangles, tri_weight, tri_share, corner_share, corners, scratch, touched, used
):
    """Triangle element ``b``'s weight added over its corners (a hidden corner's share
    going to the others; see :func:`spread_shares`); returns the new count listed."""
    t = triangles[b]
    own0 = tri_share[b, 0] if corner_share[t, 0] > 0.0 else 0.0
    own1 = tri_share[b, 1] if corner_share[t, 1] > 0.0 else 0.0
    own2 = tri_share[b, 2] if corner_share[t, 2] > 0.0 else 0.0
    seen = own0 + own1 + own2
    if seen > 0.0:
        own0, own1, own2 = own0 / seen, own1 / seen, own2 / seen
    else:
        own0, own1, own2 = corner_share[t, 0], corner_share[t, 1], corner_share[t, 2]
    w = tri_weight[b]
    used = _g._add(corners[t, 0], w * own0, scratch, touched, used)
    used = _g._add(corners[t, 1], w * own1, scratch, touched, used)
    return _g._add(corners[t, 2], w * own2, scratch, touched, used)


def _triangle(tri, m, x, n, limits, rules, scratch, target, shares, factor, k):
    """One near triangle of :func:`near_triangles` into ``target``, ``shares`` and
    ``factor[k]``; False where it does not face the receiver or gives no factor.
    ``limits`` is (band, horizon, lift, share_sizes), ``rules`` the subdivisions' grids
    (:func:`raytrad.core.kernels.sub_grid`, 3 and 2 levels) and the corner rule's points
    and weights, ``scratch`` two work arrays and the grids' (:func:`grid_scratch`)."""
    band, horizon, lift, share_sizes = limits
    grid3, grid2, rule, rule_weight = rules
    part, work, shared = scratch
    front = (x[0] - tri[0, 0]) * m[0] + (x[1] - tri[0, 1]) * m[1] + (x[2] - tri[0, 2]) * m[2]
    if not front > band:
        return False
    f = _k.clipped_factor(tri, x, n, work)
    if not f > 0.0:
        return False
    factor[k] = f
    _k._visible_centroid(tri, x, n, horizon, target)
    for d in range(3):
        target[d] += lift * m[d]
    longest = 0.0
    for e in range(3):
        p = (e + 2) % 3
        ex, ey, ez = tri[e, 0] - tri[p, 0], tri[e, 1] - tri[p, 1], tri[e, 2] - tri[p, 2]
        longest = max(longest, math.sqrt(ex * ex + ey * ey + ez * ez))
    mx = (tri[0, 0] + tri[1, 0] + tri[2, 0]) / 3.0 - x[0]
    my = (tri[0, 1] + tri[1, 1] + tri[2, 1]) / 3.0 - x[1]
    mz = (tri[0, 2] + tri[1, 2] + tri[2, 2]) / 3.0 - x[2]
    distance = math.sqrt(mx * mx + my * my + mz * mz) / longest
    if distance >= share_sizes:
        _triangle_corner_weights(tri, m, x, n, rule, rule_weight, shares)
        total = shares[0] + shares[1] + shares[2]
        for v in range(3):
            shares[v] = shares[v] / total if total > 0.0 else 1.0 / 3.0
    elif distance < 1.0:
        _k._linear_shares(tri, x, n, grid3, shared, part, work, shares)
    else:
        _k._linear_shares(tri, x, n, grid2, shared, part, work, shares)
    return True


def near_triangles(
    near,
    sub_start,
    root,
    tree,
    node_near,
    tri_corners,
    tri_normal,
    points,
    normals,
    band,
    horizon,
    lift,
    share_sizes,
    grid3,
    grid2,
    rule,
    rule_weight,
):
    """The near field of a chunk in one pass (see
    :meth:`raytrad.core.pairs.PairFactors._near_field`, whose numpy path is the reference):
    per near (receiver, sub-area) pair in row-major order, the items of its cut
    (:func:`_cut` at ``node_near``) in the order of their slots: a cluster taken whole
    facing the receiver, with its disk factor and ray target (its point, lifted); each
    triangle of a leaf facing the receiver by more than ``band`` with an exact factor
    above 0: the receiver, the triangle, the ray target, the factor and the corner shares,
    by :func:`linear_corner_shares` within ``share_sizes`` triangle sizes and beyond by
    the corner form factors (:func:`_triangle_corner_weights`, 1/3 each where they are
    0). ``tree`` is :attr:`raytrad.core.clusters.Clusters.arrays`."""
    sub_tri, start, stop, left, right, node_point, node_normal, node_area = tree
    stack, cut = _buffers(root, start, stop)
    size = 0
    whole = 0
    for c in range(near.shape[0]):
        for s in range(near.shape[1]):
            if near[c, s]:
                m = _cut(
                    root[s + sub_start], points[c], node_near, left, right, node_point, stack, cut
                )
                for q in range(m):
                    if cut[q] >= 0:
                        whole += 1
                    else:
                        size += stop[-1 - cut[q]] - start[-1 - cut[q]]
    out_c = np.empty(size, dtype=np.int64)
    out_tri = np.empty(size, dtype=np.int64)
    target = np.empty((size, 3))
    factor = np.empty(size)
    shares = np.empty((size, 3))
    node_c = np.empty(whole, dtype=np.int64)
    node_id = np.empty(whole, dtype=np.int64)
    node_target = np.empty((whole, 3))
    node_w = np.empty(whole)
    limits = (band, horizon, lift, share_sizes)
    rules = (grid3, grid2, rule, rule_weight)
    scratch = (np.empty((3, 3)), np.empty((4, 3)), _k.grid_scratch(grid3))
    k = np.int64(0)
    h = np.int64(0)
    for c in range(near.shape[0]):
        x, n = points[c], normals[c]
        for s in range(near.shape[1]):
            if not near[c, s]:
                continue
            m = _cut(root[s + sub_start], x, node_near, left, right, node_point, stack, cut)
            for q in range(m):
                item = cut[q]
                if item >= 0:
                    w = _disk(x, n, node_point[item], node_normal[item], node_area[item])
                    if w > 0.0:
                        node_c[h], node_id[h], node_w[h] = c, item, w
                        for d in range(3):
                            node_target[h, d] = node_point[item, d] + lift * node_normal[item, d]
                        h += 1
                    continue
                leaf = -1 - item
                for slot in range(start[leaf], stop[leaf]):
                    t = sub_tri[slot]
                    if _triangle(
                        tri_corners[t],
                        tri_normal[t],
                        x,
                        n,
                        limits,
                        rules,
                        scratch,
                        target[k],
                        shares[k],
                        factor,
                        k,
                    ):
                        out_c[k], out_tri[k] = c, t
                        k += 1
    return (
        out_c[:k],
        out_tri[:k],
        target[:k],
        factor[:k],
        shares[:k],
        node_c[:h],
        node_id[:h],
        node_target[:h],
        node_w[:h],
    )
