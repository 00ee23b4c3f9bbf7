"""The loops behind :mod:`raytrad.core.compiled`, written for numba (imported only there).

Plain Python as written here; :func:`raytrad.core.compiled.get` compiles every function in
:data:`KERNELS` with numba (``njit(cache=True, nogil=True)``) and rebinds it in this
module, helpers first, so that the kernels call each other compiled. Each computes the
same formula, in the same order, as its numpy reference in :mod:`raytrad.core.kernels`;
see there for shapes, units and sources.

An integer handed to a helper starts as ``np.int64(0)``, never the literal ``0``, in
every ``_compiled_*`` module: while numba infers a loop's types it first sees such a
counter as ``Literal[int](0)`` and compiles the helper for that too, then again for
``int64`` (a second compile of the near field's triangle step cost about a second of a
first run's compiling).
"""

# mypy: ignore-errors

import math

import numpy as np

#: The helpers that allocate nothing and return no array, compiled without reference
#: counting (see :func:`raytrad.core.compiled._jit`): the per-pair and per-triangle steps.
BORROWING = (
    "_unit_edge_term",
    "edge_term",
    "lambert",
    "clipped_factor",
    "outline_factor",
    "_unit_outline_factor",
    "clipped_outline",
    "_edge_at",
    "_linear_shares",
    "_visible_centroid",
    "_segment",
)

#: Every function to compile, each after the helpers it calls.
KERNELS = (
    "_unit_edge_term",
    "edge_term",
    "lambert",
    "clipped_factor",
    "polygon_form_factor",
    "outline_factor",
    "_successors",
    "_unit_outline_factor",
    "contour_form_factor",
    "clipped_outline",
    "clipped_contour_form_factor",
    "planar_contour_form_factor",
    "_edge_at",
    "_corner_ball",
    "piecewise_contour_form_factor",
    "grid_scratch",
    "_linear_shares",
    "linear_corner_shares",
    "_visible_centroid",
    "sample_weights",
    "_segment",
    "visibility_rays",
    "visible_factors",
)


def edge_term(ux, uy, uz, vx, vy, vz, n):
    """``gamma n.(u x v) / |u x v|`` of one edge, u and v from the receiver to its ends
    (a term of :func:`raytrad.core.kernels.edge_sum`; 0 for an edge through the receiver)."""
    lu = max(math.sqrt(ux * ux + uy * uy + uz * uz), 1e-300)
    lv = max(math.sqrt(vx * vx + vy * vy + vz * vz), 1e-300)
    return _unit_edge_term(ux / lu, uy / lu, uz / lu, vx / lv, vy / lv, vz / lv, n)


def _unit_edge_term(ux, uy, uz, vx, vy, vz, n):
    """:func:`edge_term` of unit directions u and v."""
    cx = uy * vz - uz * vy
    cy = uz * vx - ux * vz
    cz = ux * vy - uy * vx
    sin = math.sqrt(cx * cx + cy * cy + cz * cz)
    if sin > 0.0:
        gamma = math.atan2(sin, ux * vx + uy * vy + uz * vz)
        return gamma * ((cx * n[0] + cy * n[1] + cz * n[2]) / sin)
    return 0.0


def lambert(poly, count, x, n):
    """Lambert's formula over the first ``count`` corners of ``poly``."""
    total = 0.0
    for e in range(count):
        a = poly[e]
        b = poly[(e + 1) % count]
        total += edge_term(
            a[0] - x[0], a[1] - x[1], a[2] - x[2], b[0] - x[0], b[1] - x[1], b[2] - x[2], n
        )
    return abs(total) / (2.0 * math.pi)


def clipped_factor(tri, x, n, work):
    """Exact factor of one triangle clipped to the receiver's horizon
    (polygon_form_factor for one pair; ``work`` is a (4, 3) scratch buffer)."""
    h0 = (tri[0, 0] - x[0]) * n[0] + (tri[0, 1] - x[1]) * n[1] + (tri[0, 2] - x[2]) * n[2]
    h1 = (tri[1, 0] - x[0]) * n[0] + (tri[1, 1] - x[1]) * n[1] + (tri[1, 2] - x[2]) * n[2]
    h2 = (tri[2, 0] - x[0]) * n[0] + (tri[2, 1] - x[1]) * n[1] + (tri[2, 2] - x[2]) * n[2]
    if h0 >= 0.0 and h1 >= 0.0 and h2 >= 0.0:
        return lambert(tri, np.int64(3), x, n)
    if not (h0 > 0.0 or h1 > 0.0 or h2 > 0.0):
        return 0.0
    h = (h0, h1, h2)
    count = np.int64(0)
    for k in range(3):
        j = (k + 1) % 3
        ha, hb = h[k], h[j]
        if ha >= 0.0 and count < 4:
            work[count, 0] = tri[k, 0]
            work[count, 1] = tri[k, 1]
            work[count, 2] = tri[k, 2]
            count += 1
        if (ha >= 0.0) != (hb >= 0.0) and count < 4:
            t = ha / (ha - hb)
            for d in range(3):
                work[count, d] = tri[k, d] + t * (tri[j, d] - tri[k, d])
            count += 1
    if count < 3:
        return 0.0
    return lambert(work, count, x, n)


def polygon_form_factor(polygons, points, normals):
    out = np.empty(len(polygons))
    work = np.empty((4, 3))
    for i in range(len(polygons)):
        out[i] = clipped_factor(polygons[i], points[i], normals[i], work)
    return out


def outline_factor(start, end, x, n):
    """Lambert's formula over a whole outline ``start -> end`` seen from (x, n)."""
    total = 0.0
    for e in range(len(start)):
        a, b = start[e], end[e]
        total += edge_term(
            a[0] - x[0], a[1] - x[1], a[2] - x[2], b[0] - x[0], b[1] - x[1], b[2] - x[2], n
        )
    return abs(total) / (2.0 * math.pi)


def _successors(start, end):
    """(E,) int64: for each edge, an edge that starts where it ends (-1: none)."""
    count = len(start)
    out = np.full(count, -1, dtype=np.int64)
    for e in range(count):
        for k in range(count):
            if start[k, 0] == end[e, 0] and start[k, 1] == end[e, 1] and start[k, 2] == end[e, 2]:
                out[e] = k
                break
    return out


def _unit_outline_factor(start, end, successor, x, n, unit):
    """:func:`outline_factor` with each corner's direction from ``x`` normalised once
    (into the (E, 3) scratch ``unit``) and read at both its edges: the same terms, bit
    for bit, in the same order."""
    for k in range(len(start)):
        ux, uy, uz = start[k, 0] - x[0], start[k, 1] - x[1], start[k, 2] - x[2]
        lu = max(math.sqrt(ux * ux + uy * uy + uz * uz), 1e-300)
        unit[k, 0], unit[k, 1], unit[k, 2] = ux / lu, uy / lu, uz / lu
    total = 0.0
    for e in range(len(start)):
        ux, uy, uz = unit[e, 0], unit[e, 1], unit[e, 2]
        k = successor[e]
        if k >= 0:
            vx, vy, vz = unit[k, 0], unit[k, 1], unit[k, 2]
        else:
            vx, vy, vz = end[e, 0] - x[0], end[e, 1] - x[1], end[e, 2] - x[2]
            lv = max(math.sqrt(vx * vx + vy * vy + vz * vz), 1e-300)
            vx, vy, vz = vx / lv, vy / lv, vz / lv
        total += _unit_edge_term(ux, uy, uz, vx, vy, vz, n)
    return abs(total) / (2.0 * math.pi)


def contour_form_factor(start, end, points, normals):
    out = np.empty(len(points))
    for i in range(len(points)):
        out[i] = outline_factor(start, end, points[i], normals[i])
    return out


def clipped_outline(start, end, lo, hi, x, n):
    """Lambert's formula over the planar outline ``start[lo:hi] -> end[lo:hi]`` clipped
    to the receiver's horizon: kept parts of the edges, and the cuts along the horizon as
    the entries' terms from the first crossing less the exits' (see
    :mod:`raytrad.core.contour`)."""
    total = 0.0
    cuts = 0.0
    found = False
    ox = oy = oz = 0.0
    for e in range(lo, hi):
        ux, uy, uz = start[e, 0] - x[0], start[e, 1] - x[1], start[e, 2] - x[2]
        vx, vy, vz = end[e, 0] - x[0], end[e, 1] - x[1], end[e, 2] - x[2]
        hu = ux * n[0] + uy * n[1] + uz * n[2]
        hv = vx * n[0] + vy * n[1] + vz * n[2]
        in_u, in_v = hu >= 0.0, hv >= 0.0
        if in_u and in_v:
            total += edge_term(ux, uy, uz, vx, vy, vz, n)
            continue
        if not (in_u or in_v):
            continue
        t = hu / (hu - hv)
        px, py, pz = ux + t * (vx - ux), uy + t * (vy - uy), uz + t * (vz - uz)
        if not found:
            ox, oy, oz = px, py, pz
            found = True
        if in_u:  # leaves the half-space at p
            total += edge_term(ux, uy, uz, px, py, pz, n)
            cuts -= edge_term(ox, oy, oz, px, py, pz, n)
        else:  # comes back at p
            total += edge_term(px, py, pz, vx, vy, vz, n)
            cuts += edge_term(ox, oy, oz, px, py, pz, n)
    return abs(total + cuts) / (2.0 * math.pi)


def clipped_contour_form_factor(start, end, points, normals):
    out = np.empty(len(points))
    for i in range(len(points)):
        out[i] = clipped_outline(start, end, np.int64(0), len(start), points[i], normals[i])
    return out


def planar_contour_form_factor(start, end, points, normals, patch_normal, patch_center, band):
    """Exact unoccluded factors of a planar patch (outline ``start -> end``): 0 behind it
    or below the receiver's horizon, the whole outline's sum where it lies above, the
    clipped outline's where it straddles (see
    :func:`raytrad.core.contour.numpy_planar_contour_form_factor`, the reference)."""
    out = np.zeros(len(points))
    successor = _successors(start, end)
    unit = np.empty((len(start), 3))
    for i in range(len(points)):
        x, n = points[i], normals[i]
        front = (
            (x[0] - patch_center[0]) * patch_normal[0]
            + (x[1] - patch_center[1]) * patch_normal[1]
            + (x[2] - patch_center[2]) * patch_normal[2]
        )
        if not front > band:
            continue
        level = x[0] * n[0] + x[1] * n[1] + x[2] * n[2]
        top, low = -np.inf, np.inf
        for e in range(len(start)):
            h = start[e, 0] * n[0] + start[e, 1] * n[1] + start[e, 2] * n[2] - level
            top, low = max(top, h), min(low, h)
        if not top > band:
            continue
        if low >= -band:
            out[i] = _unit_outline_factor(start, end, successor, x, n, unit)
        else:
            out[i] = clipped_outline(start, end, np.int64(0), len(start), x, n)
    return out


def _edge_at(start, end, e, x, n):
    """:func:`edge_term` of the edge ``start[e] -> end[e]`` seen from ``x``."""
    return edge_term(
        start[e, 0] - x[0],
        start[e, 1] - x[1],
        start[e, 2] - x[2],
        end[e, 0] - x[0],
        end[e, 1] - x[1],
        end[e, 2] - x[2],
        n,
    )


def _corner_ball(start, lo, hi):
    """(5,) a ball round the points ``start[lo:hi]``: their mean and the largest distance
    from it [m], then a rounding allowance for heights measured against it (1e-12 of the
    coordinates' size, thousands of times a dot product's rounding) [m]."""
    ball = np.zeros(5)
    for e in range(lo, hi):
        for j in range(3):
            ball[j] += start[e, j]
    for j in range(3):
        ball[j] /= max(hi - lo, 1)
    far = 0.0
    for e in range(lo, hi):
        dx, dy, dz = start[e, 0] - ball[0], start[e, 1] - ball[1], start[e, 2] - ball[2]
        far = max(far, dx * dx + dy * dy + dz * dz)
    ball[3] = math.sqrt(far)
    ball[4] = 1e-12 * (abs(ball[0]) + abs(ball[1]) + abs(ball[2]) + ball[3])
    return ball


def piecewise_contour_form_factor(
    start, end, edge_ptr, piece_point, piece_normal, twin, points, normals, margin
):
    """Sum over planar pieces facing each receiver by more than ``margin`` of their
    clipped outlines' factors (a folded patch, see :mod:`raytrad.core.contour`).

    The pieces that face a receiver and lie wholly above its horizon are summed as one
    region: their signed outline sums share a sign, and an edge between two of them is
    walked once each way, so only the region's own outline is summed (edges whose
    ``twin`` piece, relative to the first, is not in the region). The others that face
    it straddle its horizon and are clipped one by one. A receiver whose horizon the
    patch stays within ``margin`` of, or below, gets 0.

    A receiver whose horizon a ball round the corners lies wholly above, by more than
    rounding, skips both loops over the corners' heights: every corner is above it. One
    that sees every piece whole sums the rim alone (the edges without a twin, in the
    order the region's loop takes them: the same sum to the bit)."""
    out = np.zeros(len(points))
    count = len(piece_point)
    state = np.zeros(count, dtype=np.int8)  # 0 not seen, 1 in the region, 2 clipped
    base = edge_ptr[0]
    ball = _corner_ball(start, base, edge_ptr[count])
    rim = np.empty(edge_ptr[count] - base, dtype=np.int64)  # edges without a twin, in order
    rims = 0
    for e in range(base, edge_ptr[count]):
        if not 0 <= twin[e - base] < count:
            rim[rims] = e
            rims += 1
    for i in range(len(points)):
        x, n = points[i], normals[i]
        # the ball's lowest point above the horizon by more than the margin and rounding
        lowest = (ball[0] - x[0]) * n[0] + (ball[1] - x[1]) * n[1] + (ball[2] - x[2]) * n[2]
        size = abs(x[0]) + abs(x[1]) + abs(x[2])
        above = lowest - ball[3] > margin + ball[4] + 1e-12 * size
        if not above:
            level = x[0] * n[0] + x[1] * n[1] + x[2] * n[2]
            top = -np.inf
            for e in range(base, edge_ptr[count]):
                h = start[e, 0] * n[0] + start[e, 1] * n[1] + start[e, 2] * n[2] - level
                top = max(top, h)
            if not top > margin:
                continue
        whole = 0  # pieces in the region: all of them, and its outline is the rim's
        for k in range(count):
            c, m = piece_point[k], piece_normal[k]
            front = (x[0] - c[0]) * m[0] + (x[1] - c[1]) * m[1] + (x[2] - c[2]) * m[2]
            state[k] = 0
            if front > margin:
                state[k] = 1
                whole += 1
                if above:
                    continue
                for e in range(edge_ptr[k], edge_ptr[k + 1]):
                    h = (
                        (start[e, 0] - x[0]) * n[0]
                        + (start[e, 1] - x[1]) * n[1]
                        + (start[e, 2] - x[2]) * n[2]
                    )
                    if h < 0.0:
                        state[k] = 2
                        whole -= 1
                        break
        # the region's outline: edges of its pieces whose twin is not in it, in order
        total = region = 0.0
        if whole == count:  # every piece: the rim alone, in the same order
            for r in range(rims):
                region += _edge_at(start, end, rim[r], x, n)
        for k in range(count if whole < count else 0):
            if state[k] == 2:
                total += clipped_outline(start, end, edge_ptr[k], edge_ptr[k + 1], x, n)
            elif state[k] == 1:
                for e in range(edge_ptr[k], edge_ptr[k + 1]):
                    t = twin[e - base]
                    if not (0 <= t < count and state[t] == 1):  # else its two ways cancel
                        region += _edge_at(start, end, e, x, n)
        out[i] = total + abs(region) / (2.0 * math.pi)
    return out


def grid_scratch(grid):
    """Work arrays for :func:`_linear_shares` on ``grid`` or any smaller one: corner
    positions, unit directions and heights (V, 3), (V, 3), (V,); edge terms and whether
    each is known (E,), (E,)."""
    vertices, edges = len(grid[0]), len(grid[4])
    return (
        np.empty((vertices, 3)),
        np.empty((vertices, 3)),
        np.empty(vertices),
        np.empty(edges),
        np.zeros(edges, dtype=np.bool_),
    )


def _linear_shares(tri, x, n, grid, scratch, part, work, out):
    """One triangle's corner shares into ``out`` (3,) (see :func:`linear_corner_shares`).

    ``grid`` is the midpoint subdivision as shared corners and edges
    (:func:`raytrad.core.kernels.sub_grid`): each corner's direction from the receiver is
    normalised once, and each edge's term computed once for the two parts beside it (the
    other takes its negation, bit for bit), so a part wholly above the horizon sums the
    same three terms, in the same order, as :func:`lambert` does; a part that straddles it
    is clipped by :func:`clipped_factor` from the same corners. ``scratch`` is
    :func:`grid_scratch`'s, ``part`` (3, 3) and ``work`` (4, 3) are scratch too."""
    vertex_bary, tri_vertex, edge_of, edge_sign, edge_ends, centroids = grid
    pos, unit, height, term, known = scratch
    for v in range(len(vertex_bary)):
        for d in range(3):
            pos[v, d] = (
                vertex_bary[v, 0] * tri[0, d]
                + vertex_bary[v, 1] * tri[1, d]
                + vertex_bary[v, 2] * tri[2, d]
            )
        ux, uy, uz = pos[v, 0] - x[0], pos[v, 1] - x[1], pos[v, 2] - x[2]
        height[v] = ux * n[0] + uy * n[1] + uz * n[2]
        lu = max(math.sqrt(ux * ux + uy * uy + uz * uz), 1e-300)
        unit[v, 0], unit[v, 1], unit[v, 2] = ux / lu, uy / lu, uz / lu
    for e in range(len(edge_ends)):
        known[e] = False
    total = 0.0
    s0 = s1 = s2 = 0.0
    for s in range(len(tri_vertex)):
        h0, h1, h2 = height[tri_vertex[s, 0]], height[tri_vertex[s, 1]], height[tri_vertex[s, 2]]
        if h0 >= 0.0 and h1 >= 0.0 and h2 >= 0.0:
            acc = 0.0
            for k in range(3):
                e = edge_of[s, k]
                if not known[e]:
                    a, b = edge_ends[e, 0], edge_ends[e, 1]
                    term[e] = _unit_edge_term(
                        unit[a, 0], unit[a, 1], unit[a, 2], unit[b, 0], unit[b, 1], unit[b, 2], n
                    )
                    known[e] = True
                acc += edge_sign[s, k] * term[e]
            f = abs(acc) / (2.0 * math.pi)
        elif not (h0 > 0.0 or h1 > 0.0 or h2 > 0.0):
            f = 0.0
        else:
            for k in range(3):
                for d in range(3):
                    part[k, d] = pos[tri_vertex[s, k], d]
            f = clipped_factor(part, x, n, work)
        total += f
        s0 += f * centroids[s, 0]
        s1 += f * centroids[s, 1]
        s2 += f * centroids[s, 2]
    if total > 0.0:
        out[0], out[1], out[2] = s0 / total, s1 / total, s2 / total
    else:
        out[0] = out[1] = out[2] = 1.0 / 3.0


def linear_corner_shares(triangles, points, normals, grid):
    out = np.empty((len(triangles), 3))
    part = np.empty((3, 3))
    work = np.empty((4, 3))
    scratch = grid_scratch(grid)
    for i in range(len(triangles)):
        _linear_shares(triangles[i], points[i], normals[i], grid, scratch, part, work, out[i])
    return out


def _visible_centroid(tri, x, n, horizon, out):
    """The mean corner of the part of a triangle above the receiver's horizon into ``out``
    (3,) (:func:`raytrad.core.kernels.visible_centroid` for one pair)."""
    reach = 0.0
    h0 = h1 = h2 = 0.0
    for k in range(3):
        dx, dy, dz = tri[k, 0] - x[0], tri[k, 1] - x[1], tri[k, 2] - x[2]
        height = dx * n[0] + dy * n[1] + dz * n[2]
        if k == 0:
            h0 = height
        elif k == 1:
            h1 = height
        else:
            h2 = height
        reach = max(reach, dx * dx + dy * dy + dz * dz)
    snap = horizon * math.sqrt(reach)
    if (
        (abs(h0) <= snap or h0 >= 0.0)
        and (abs(h1) <= snap or h1 >= 0.0)
        and (abs(h2) <= snap or h2 >= 0.0)
    ):
        for d in range(3):
            out[d] = (tri[0, d] + tri[1, d] + tri[2, d]) / 3.0
        return
    h = (h0, h1, h2)
    count = np.int64(0)
    out[0] = out[1] = out[2] = 0.0
    for k in range(3):
        j = (k + 1) % 3
        if h[k] >= 0.0 and count < 4:
            for d in range(3):
                out[d] += tri[k, d]
            count += 1
        if (h[k] >= 0.0) != (h[j] >= 0.0) and count < 4:
            t = h[k] / (h[k] - h[j])
            for d in range(3):
                out[d] += tri[k, d] + t * (tri[j, d] - tri[k, d])
            count += 1
    for d in range(3):
        out[d] /= max(count, 1)


def sample_weights(points, normals, sees, samples, sample_normals, near_reach, area):
    """Disk-approximation weights of far sample pairs and the near mask of the receivers
    that see the patch (see :func:`raytrad.core.kernels.numpy_sample_weights`)."""
    c_count, s_count = len(points), len(samples)
    weight = np.zeros((c_count, s_count))
    far = np.zeros((c_count, s_count), dtype=np.bool_)
    near = np.zeros((c_count, s_count), dtype=np.bool_)
    for c in range(c_count):
        if not sees[c]:
            continue
        x, n = points[c], normals[c]
        found = False
        for s in range(s_count):
            dx = samples[s, 0] - x[0]
            dy = samples[s, 1] - x[1]
            dz = samples[s, 2] - x[2]
            r2 = dx * dx + dy * dy + dz * dz
            r = math.sqrt(r2)
            inv_r = 1.0 / (r if r > 0.0 else 1.0)
            if r < near_reach[s]:
                near[c, s] = True
                found = True
                continue
            cos_r = (dx * n[0] + dy * n[1] + dz * n[2]) * inv_r
            m = sample_normals[s]
            cos_s = -(dx * m[0] + dy * m[1] + dz * m[2]) * inv_r
            if cos_r > 0.0 and cos_s > 0.0:
                far[c, s] = True
                found = True
                weight[c, s] = cos_r * cos_s * area[s] / (math.pi * r2 + area[s])
        if not found:
            for s in range(s_count):
                near[c, s] = True
    return weight, far, near


def visibility_rays(origins, far, sub_targets, near_c, near_targets, shift, shorten):
    """float32 rays of a chunk: first every far (receiver, sample) pair in row-major order
    of ``far``, then the near ones (see :func:`raytrad.core.kernels.numpy_visibility_rays`)."""
    far_count = 0
    for c in range(far.shape[0]):
        for s in range(far.shape[1]):
            if far[c, s]:
                far_count += 1
    count = far_count + len(near_c)
    o = np.empty((count, 3), dtype=np.float32)
    d = np.empty((count, 3), dtype=np.float32)
    t = np.empty(count, dtype=np.float32)
    far_c = np.empty(far_count, dtype=np.int64)
    far_s = np.empty(far_count, dtype=np.int64)
    i = np.int64(0)
    for c in range(far.shape[0]):
        for s in range(far.shape[1]):
            if far[c, s]:
                far_c[i] = c
                far_s[i] = s
                _segment(origins[c], sub_targets[s], shift, shorten, o[i], d[i], t, i)
                i += 1
    for k in range(len(near_c)):
        _segment(origins[near_c[k]], near_targets[k], shift, shorten, o[i], d[i], t, i)
        i += 1
    return o, d, t, far_c, far_s


def visible_factors(unoccluded, doubt, weight, far_hidden, near_c, near_w, near_hidden):
    """Unoccluded factors scaled by the weighted visible fraction of the samples (see
    :func:`raytrad.core.pairs.numpy_visible_factors`)."""
    total = np.zeros(len(unoccluded))
    hidden = np.zeros(len(unoccluded))
    for c in range(weight.shape[0]):
        if not doubt[c]:  # its factor is the unoccluded one: no sum needed
            continue
        for s in range(weight.shape[1]):
            total[c] += weight[c, s]
            if far_hidden[c, s]:
                hidden[c] += weight[c, s]
    for k in range(len(near_c)):
        total[near_c[k]] += near_w[k]
        if near_hidden[k]:
            hidden[near_c[k]] += near_w[k]
    out = np.empty(len(unoccluded))
    for c in range(len(unoccluded)):
        if doubt[c]:
            visible = 1.0 - hidden[c] / total[c] if total[c] > 0.0 else 0.0
            out[c] = unoccluded[c] * min(max(visible, 0.0), 1.0)
        else:
            out[c] = unoccluded[c]
    return out


def _segment(a, b, shift, shorten, o, d, t, i):
    """One ray from ``a`` towards ``b``, written in place (``t[i]``, the rows ``o``, ``d``)."""
    dx = b[0] - a[0]
    dy = b[1] - a[1]
    dz = b[2] - a[2]
    length = math.sqrt(dx * dx + dy * dy + dz * dz)
    scale = length if length > 0.0 else 1.0
    o[0] = a[0] - shift[0]
    o[1] = a[1] - shift[1]
    o[2] = a[2] - shift[2]
    d[0] = dx / scale
    d[1] = dy / scale
    d[2] = dz / scale
    t[i] = max(length - shorten, 0.0)
