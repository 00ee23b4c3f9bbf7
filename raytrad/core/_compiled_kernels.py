"""The loops behind :mod:`raytrad.core.compiled`, written for numba (imported only there).

Plain Python as written here; :func:`raytrad.core.compiled.get` compiles every function in
:data:`KERNELS` with numba (``njit(cache=True, nogil=True)``) and rebinds it in this
module, helpers first, so that the kernels call each other compiled. Each computes the
same formula, in the same order, as its numpy reference in :mod:`raytrad.core.kernels`;
see there for shapes, units and sources.
"""

# mypy: ignore-errors

import math

import numpy as np

#: Every function to compile, each after the helpers it calls.
KERNELS = (
    "edge_term",
    "lambert",
    "clipped_factor",
    "polygon_form_factor",
    "outline_factor",
    "contour_form_factor",
    "clipped_outline",
    "clipped_contour_form_factor",
    "planar_contour_form_factor",
    "piecewise_contour_form_factor",
    "_linear_shares",
    "linear_corner_shares",
    "_visible_centroid",
    "_triangle_corner_weights",
    "subarea_spread",
    "near_triangles",
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
    ux, uy, uz = ux / lu, uy / lu, uz / lu
    vx, vy, vz = vx / lv, vy / lv, vz / lv
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
        return lambert(tri, 3, x, n)
    if not (h0 > 0.0 or h1 > 0.0 or h2 > 0.0):
        return 0.0
    h = (h0, h1, h2)
    count = 0
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
        out[i] = clipped_outline(start, end, 0, len(start), points[i], normals[i])
    return out


def planar_contour_form_factor(start, end, points, normals, patch_normal, patch_center, band):
    """Exact unoccluded factors of a planar patch (outline ``start -> end``): 0 behind it
    or below the receiver's horizon, the whole outline's sum where it lies above, the
    clipped outline's where it straddles (see
    :func:`raytrad.core.contour.numpy_planar_contour_form_factor`, the reference)."""
    out = np.zeros(len(points))
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
            out[i] = outline_factor(start, end, x, n)
        else:
            out[i] = clipped_outline(start, end, 0, len(start), x, n)
    return out


def piecewise_contour_form_factor(
    start, end, edge_ptr, piece_point, piece_normal, points, normals, margin
):
    """Sum over planar pieces facing each receiver by more than ``margin`` of their
    clipped outlines' factors (a folded patch, see :mod:`raytrad.core.contour`)."""
    out = np.zeros(len(points))
    for i in range(len(points)):
        x, n = points[i], normals[i]
        total = 0.0
        for k in range(len(piece_point)):
            c, m = piece_point[k], piece_normal[k]
            front = (x[0] - c[0]) * m[0] + (x[1] - c[1]) * m[1] + (x[2] - c[2]) * m[2]
            if front > margin:
                total += clipped_outline(start, end, edge_ptr[k], edge_ptr[k + 1], x, n)
        out[i] = total
    return out


def _linear_shares(tri, x, n, bary, centroids, part, work, out):
    """One triangle's corner shares into ``out`` (3,) (see :func:`linear_corner_shares`;
    ``part`` (3, 3) and ``work`` (4, 3) are scratch)."""
    total = 0.0
    s0 = s1 = s2 = 0.0
    for s in range(len(bary)):
        for k in range(3):
            for d in range(3):
                part[k, d] = (
                    bary[s, k, 0] * tri[0, d]
                    + bary[s, k, 1] * tri[1, d]
                    + bary[s, k, 2] * tri[2, d]
                )
        f = clipped_factor(part, x, n, work)
        total += f
        s0 += f * centroids[s, 0]
        s1 += f * centroids[s, 1]
        s2 += f * centroids[s, 2]
    if total > 0.0:
        out[0], out[1], out[2] = s0 / total, s1 / total, s2 / total
    else:
        out[0] = out[1] = out[2] = 1.0 / 3.0


def linear_corner_shares(triangles, points, normals, bary, centroids):
    out = np.empty((len(triangles), 3))
    part = np.empty((3, 3))
    work = np.empty((4, 3))
    for i in range(len(triangles)):
        _linear_shares(triangles[i], points[i], normals[i], bary, centroids, part, work, out[i])
    return out


def _visible_centroid(tri, x, n, horizon, out):
    """The mean corner of the part of a triangle above the receiver's horizon into ``out``
    (3,) (:func:`raytrad.core.kernels.visible_centroid` for one pair)."""
    h = np.empty(3)
    reach = 0.0
    above = True
    for k in range(3):
        dx, dy, dz = tri[k, 0] - x[0], tri[k, 1] - x[1], tri[k, 2] - x[2]
        h[k] = dx * n[0] + dy * n[1] + dz * n[2]
        reach = max(reach, dx * dx + dy * dy + dz * dz)
    snap = horizon * math.sqrt(reach)
    for k in range(3):
        if not (abs(h[k]) <= snap or h[k] >= 0.0):
            above = False
    if above:
        for d in range(3):
            out[d] = (tri[0, d] + tri[1, d] + tri[2, d]) / 3.0
        return
    count = 0
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


def near_triangles(
    near,
    sub_start,
    sub_ptr,
    sub_tri,
    tri_corners,
    tri_normal,
    points,
    normals,
    band,
    horizon,
    lift,
    share_sizes,
    bary3,
    centroids3,
    bary2,
    centroids2,
    rule,
    rule_weight,
):
    """The near field of a chunk in one pass (see
    :meth:`raytrad.core.pairs.PairFactors._near_field`, whose numpy path is the reference):
    per near (receiver, sub-area) pair in row-major order, each triangle of the sub-area
    facing the receiver by more than ``band`` with an exact factor above 0: the receiver,
    the triangle, the ray target, the factor and the corner shares, by
    :func:`linear_corner_shares` within ``share_sizes`` triangle sizes and beyond by the
    corner form factors (:func:`_triangle_corner_weights`, 1/3 each where they are 0)."""
    size = 0
    for c in range(near.shape[0]):
        for s in range(near.shape[1]):
            if near[c, s]:
                size += sub_ptr[s + sub_start + 1] - sub_ptr[s + sub_start]
    out_c = np.empty(size, dtype=np.int64)
    out_tri = np.empty(size, dtype=np.int64)
    target = np.empty((size, 3))
    factor = np.empty(size)
    shares = np.empty((size, 3))
    part = np.empty((3, 3))
    work = np.empty((4, 3))
    k = 0
    for c in range(near.shape[0]):
        x, n = points[c], normals[c]
        for s in range(near.shape[1]):
            if not near[c, s]:
                continue
            for q in range(sub_ptr[s + sub_start], sub_ptr[s + sub_start + 1]):
                t = sub_tri[q]
                tri, m = tri_corners[t], tri_normal[t]
                front = (
                    (x[0] - tri[0, 0]) * m[0]
                    + (x[1] - tri[0, 1]) * m[1]
                    + (x[2] - tri[0, 2]) * m[2]
                )
                if not front > band:
                    continue
                f = clipped_factor(tri, x, n, work)
                if not f > 0.0:
                    continue
                out_c[k], out_tri[k], factor[k] = c, t, f
                _visible_centroid(tri, x, n, horizon, target[k])
                for d in range(3):
                    target[k, d] += lift * m[d]
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
                    row = shares[k]
                    _triangle_corner_weights(tri, m, x, n, rule, rule_weight, row)
                    total = row[0] + row[1] + row[2]
                    for v in range(3):
                        row[v] = row[v] / total if total > 0.0 else 1.0 / 3.0
                elif distance < 1.0:
                    _linear_shares(tri, x, n, bary3, centroids3, part, work, shares[k])
                else:
                    _linear_shares(tri, x, n, bary2, centroids2, part, work, shares[k])
                k += 1
    return out_c[:k], out_tri[:k], target[:k], factor[:k], shares[:k]


def sample_weights(points, normals, samples, sample_normals, near_reach, area):
    """Disk-approximation weights of far sample pairs and the near mask (see
    :func:`raytrad.core.kernels.numpy_sample_weights`)."""
    c_count, s_count = len(points), len(samples)
    weight = np.zeros((c_count, s_count))
    far = np.zeros((c_count, s_count), dtype=np.bool_)
    near = np.zeros((c_count, s_count), dtype=np.bool_)
    for c in range(c_count):
        x, n = points[c], normals[c]
        for s in range(s_count):
            dx = samples[s, 0] - x[0]
            dy = samples[s, 1] - x[1]
            dz = samples[s, 2] - x[2]
            r2 = dx * dx + dy * dy + dz * dz
            r = math.sqrt(r2)
            inv_r = 1.0 / (r if r > 0.0 else 1.0)
            if r < near_reach[s]:
                near[c, s] = True
                continue
            cos_r = (dx * n[0] + dy * n[1] + dz * n[2]) * inv_r
            m = sample_normals[s]
            cos_s = -(dx * m[0] + dy * m[1] + dz * m[2]) * inv_r
            if cos_r > 0.0 and cos_s > 0.0:
                far[c, s] = True
                weight[c, s] = cos_r * cos_s * area[s] / (math.pi * r2 + area[s])
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
    i = 0
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
