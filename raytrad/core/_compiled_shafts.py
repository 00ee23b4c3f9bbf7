"""The pair classification loops behind :mod:`raytrad.core.compiled`, written for numba
(imported only there): the shaft test (pairs nothing can block) and the convex-blocker
test (pairs one occluder hides wholly). Plain Python as written here;
:func:`raytrad.core.compiled.get` compiles every function in :data:`KERNELS`. Each
computes what its numpy reference computes (:func:`raytrad.core.shafts.numpy_shaft_clear`,
:func:`raytrad.core.blockers.numpy_blocked`); see there for shapes and units.
"""

# mypy: ignore-errors

import math

import numpy as np

#: Every function to compile, each after the helpers it calls.
KERNELS = (
    "_outside_pyramid",
    "_facet_outside",
    "_beyond_patch",
    "_capsule_misses",
    "shaft_clear",
    "_heights",
    "_sheet_hides",
    "_solid_hides",
    "_group_candidates",
    "_origin_hider",
    "blocked_pairs",
)

FACE, HOLE, SHEET, EDGE = 0, 1, 2, 3
#: Origins per group of :func:`blocked_pairs`, which share one list of candidate
#: blockers.
BLOCKER_GROUP = 16

#: The index of a word's lowest set bit ``low`` (the word with only that bit) is
#: ``_BIT_INDEX[(low * _DE_BRUIJN) >> 58]``: each 6-bit window of this de Bruijn sequence
#: occurs once. A multiply and a lookup, where ``log2`` of a float took a conversion and
#: a library call: the shaft test took 0.66 of its time in a room of 187 facets (the same
#: answers).
_DE_BRUIJN = 0x022FDD63CC95386D
_BIT_INDEX = np.zeros(64, dtype=np.int64)
for _bit in range(64):
    _BIT_INDEX[((1 << _bit) * _DE_BRUIJN & 0xFFFFFFFFFFFFFFFF) >> 58] = _bit


def _heights(points, normal, offset):
    """(K, N) signed heights of points above each plane [m]."""
    out = np.empty((len(offset), len(points)))
    for k in range(len(offset)):
        for i in range(len(points)):
            p = points[i]
            out[k, i] = p[0] * normal[k, 0] + p[1] * normal[k, 1] + p[2] * normal[k, 2] - offset[k]
    return out


def _sheet_hides(h_o, h_v, kind, lo, hi, margin):
    """Whether the sheet of planes ``lo:hi`` hides every corner (heights ``h_v`` (K, V))
    from an origin (heights ``h_o`` (K,)): the corners on the other side of its plane,
    each segment crossing it inside the shrunk edges."""
    s = lo
    while kind[s] != SHEET:
        s += 1
    if abs(h_o[s]) < margin:
        return False
    for v in range(h_v.shape[1]):
        if (h_o[s] > 0 and h_v[s, v] > -margin) or (h_o[s] < 0 and h_v[s, v] < margin):
            return False
    for v in range(h_v.shape[1]):
        t = h_o[s] / (h_o[s] - h_v[s, v])
        for k in range(lo, hi):
            if kind[k] == EDGE and h_o[k] + t * (h_v[k, v] - h_o[k]) > -margin:
                return False
    return True


def _solid_hides(h_o, h_v, kind, lo, hi, margin, lift, gap):
    """Whether the solid of planes ``lo:hi``, shrunk by ``margin``, meets every segment
    from an origin to a corner (heights as :func:`_sheet_hides`), with the origin
    outside it and the blocking point more than two ray offsets from the rays' ends."""
    outside = False
    for k in range(lo, hi):
        if kind[k] == FACE and h_o[k] >= 2.0 * margin:
            outside = True
        if kind[k] == HOLE and h_o[k] > -0.5 * lift:
            return False
    if not outside:
        return False
    latest = 0.0
    for v in range(h_v.shape[1]):
        enter, leave = 0.0, 1.0
        for k in range(lo, hi):
            start = h_o[k] + margin
            slope = (h_v[k, v] + margin) - start
            if slope < 0.0:
                enter = max(enter, -start / slope)
            elif slope > 0.0:
                leave = min(leave, -start / slope)
            elif start > 0.0:
                return False
        if enter > leave:
            return False
        latest = max(latest, enter)
    return (1.0 - latest) * gap >= 2.0 * lift


def _origin_hider(
    o,
    found,
    candidates,
    recent,
    patch_center,
    reach,
    normal,
    offset,
    kind,
    plane_ptr,
    center,
    radius,
    margin,
    lift,
    h_o,
    h_v,
):
    """The blocker that hides every corner from origin ``o`` (heights ``h_v``), of the
    group's ``found`` candidates, ``recent`` (the one that hid the last origin) tried
    first; -1 when none does. ``h_o`` is scratch for the origin's plane heights."""
    dx = patch_center[0] - o[0]
    dy = patch_center[1] - o[1]
    dz = patch_center[2] - o[2]
    length2 = dx * dx + dy * dy + dz * dz
    # the capsule test only chooses which blockers get the exact test, so its
    # rounding (a product by the inverse, squares; 0.80 of the division's and
    # root's time) may differ from the reference's: a blocker passed over leaves
    # the pair traced, to the same factor
    inverse = 1.0 / length2 if length2 > 0.0 else 0.0
    gap = math.sqrt(length2) - reach
    for step in range(-1, found):
        if step < 0:
            b = recent
            if b < 0:
                continue
        else:
            b = candidates[step]
            if b == recent:
                continue
        cx, cy, cz = center[b, 0] - o[0], center[b, 1] - o[1], center[b, 2] - o[2]
        t = min(max((cx * dx + cy * dy + cz * dz) * inverse, 0.0), 1.0)
        ex, ey, ez = cx - t * dx, cy - t * dy, cz - t * dz
        if ex * ex + ey * ey + ez * ez > (radius[b] + reach) ** 2:
            continue
        lo, hi = plane_ptr[b], plane_ptr[b + 1]
        for k in range(lo, hi):
            h_o[k] = o[0] * normal[k, 0] + o[1] * normal[k, 1] + o[2] * normal[k, 2] - offset[k]
        sheet = False
        for k in range(lo, hi):
            if kind[k] == SHEET:
                sheet = True
        if sheet:
            hides = _sheet_hides(h_o, h_v, kind, lo, hi, margin)
        else:
            hides = _solid_hides(h_o, h_v, kind, lo, hi, margin, lift, gap)
        if hides:
            return b
    return np.int64(-1)


def blocked_pairs(
    origins,
    corners,
    patch_center,
    reach,
    normal,
    offset,
    kind,
    plane_ptr,
    center,
    radius,
    margin,
    lift,
    probe,
):
    """(N,) bool: origins from which one blocker hides every corner (see
    :func:`raytrad.core.blockers.numpy_blocked`, ``probe`` as there).

    The origins go in groups of :data:`BLOCKER_GROUP` consecutive ones (the pass's
    receivers are in Morton order, so a group lies in one part of the scene): a blocker
    whose sphere does not come within its radius + ``reach`` + the group's radius of the
    segment from the group's centre to the patch's misses every origin's capsule, and only
    the others are tried per origin, the one that hid the last origin first. With
    ``probe``, a group's first and last origins are tested first, and the others only
    when one of those two is hidden."""
    out = np.zeros(len(origins), dtype=np.bool_)
    h_v = _heights(corners, normal, offset)
    h_o = np.empty(len(offset))
    count = len(radius)
    candidates = np.empty(count, dtype=np.int64)
    recent = np.int64(-1)  # the blocker that hid the last origin: tried first
    for first in range(0, len(origins), BLOCKER_GROUP):
        last = min(first + BLOCKER_GROUP, len(origins))
        found = _group_candidates(
            origins, first, last, patch_center, reach, center, radius, candidates
        )
        if found == 0:
            continue
        probing = probe and last - first > 2
        for step in range(last - first):
            i = first + step
            if probing:  # the ends first, then the others if an end is hidden
                if step == 2 and not (out[first] or out[last - 1]):
                    break
                i = first if step == 0 else (last - 1 if step == 1 else first + step - 1)
            b = _origin_hider(
                origins[i],
                found,
                candidates,
                recent,
                patch_center,
                reach,
                normal,
                offset,
                kind,
                plane_ptr,
                center,
                radius,
                margin,
                lift,
                h_o,
                h_v,
            )
            if b >= 0:
                out[i] = True
                recent = b
    return out


def _group_candidates(origins, first, last, patch_center, reach, center, radius, candidates):
    """The blockers whose capsule test any origin ``first:last`` could pass, written to
    ``candidates``; returns their count. Every segment from an origin within ``r`` of a
    point ``g`` to the patch's centre lies within ``r`` of the segment from ``g`` (the
    two differ by ``(1 - t) (o - g)`` at each parameter ``t``)."""
    gx, gy, gz = 0.0, 0.0, 0.0
    for i in range(first, last):
        gx += origins[i, 0]
        gy += origins[i, 1]
        gz += origins[i, 2]
    share = 1.0 / (last - first)
    gx, gy, gz = gx * share, gy * share, gz * share
    spread = 0.0
    for i in range(first, last):
        ox, oy, oz = origins[i, 0] - gx, origins[i, 1] - gy, origins[i, 2] - gz
        spread = max(spread, ox * ox + oy * oy + oz * oz)
    # a relative slack for the rounding of the centre and of the tests against it
    spread = math.sqrt(spread) * (1.0 + 1e-9) + 1e-9 * (
        reach + math.sqrt(gx * gx + gy * gy + gz * gz)
    )
    dx, dy, dz = patch_center[0] - gx, patch_center[1] - gy, patch_center[2] - gz
    length2 = dx * dx + dy * dy + dz * dz
    found = 0
    for b in range(len(radius)):
        cx, cy, cz = center[b, 0] - gx, center[b, 1] - gy, center[b, 2] - gz
        t = (cx * dx + cy * dy + cz * dz) / length2 if length2 > 0.0 else 0.0
        t = min(max(t, 0.0), 1.0)
        ex, ey, ez = cx - t * dx, cy - t * dy, cz - t * dz
        if math.sqrt(ex * ex + ey * ey + ez * ez) <= radius[b] + reach + spread:
            candidates[found] = b
            found += 1
    return found


def shaft_clear(
    origins,
    sides,
    patch_sides,
    normals,
    offsets,
    centers,
    radii,
    hull,
    hull_ptr,
    band,
    patch_center,
    patch_reach,
    targets,
    outline,
    patch_normal,
    margins,
):
    """Receivers whose shaft to a patch no facet can block (see
    :func:`raytrad.core.shafts.numpy_shaft_clear`): per receiver, the candidate facets are
    a few word operations on packed side bits; only those get the capsule, pyramid and
    separating-plane tests, the facet that kept the last receiver in doubt first (it
    mostly keeps its neighbour in doubt too, and one such facet settles the answer)."""
    flat = margins[0]
    limits = np.array([margins[0], margins[1], margins[2], margins[3], band])
    count = len(radii)
    words = sides.shape[1] // 2
    tail = count - 64 * (words - 1)
    last = np.uint64(0xFFFFFFFFFFFFFFFF)
    if tail < 64:
        last = (np.uint64(1) << np.uint64(tail)) - np.uint64(1)
    out = np.ones(origins.shape[0], dtype=np.bool_)
    recent = np.int64(-1)  # the facet that left the last receiver in doubt: tried first
    for c in range(origins.shape[0]):
        ox, oy, oz = origins[c, 0], origins[c, 1], origins[c, 2]
        dx = patch_center[0] - ox
        dy = patch_center[1] - oy
        dz = patch_center[2] - oz
        length2 = dx * dx + dy * dy + dz * dz
        for w in range(-1, words):
            if w < 0:  # the recent facet alone, if a candidate
                if recent < 0:
                    continue
                k = recent // 64
                cand = np.uint64(1) << np.uint64(recent % 64)
                cand &= ~(
                    (sides[c, k] & patch_sides[k]) | (sides[c, words + k] & patch_sides[words + k])
                )
            else:
                same = (sides[c, w] & patch_sides[w]) | (
                    sides[c, words + w] & patch_sides[words + w]
                )
                cand = ~same
                if w == words - 1:
                    cand &= last
                if 0 <= recent and recent // 64 == w:
                    cand &= ~(np.uint64(1) << np.uint64(recent % 64))
            base = 64 * (recent // 64) if w < 0 else 64 * w
            while cand != np.uint64(0):
                low = cand & (~cand + np.uint64(1))
                cand ^= low
                q = base + _BIT_INDEX[(low * np.uint64(_DE_BRUIJN)) >> np.uint64(58)]
                if _capsule_misses(
                    centers[q, 0] - ox,
                    centers[q, 1] - oy,
                    centers[q, 2] - oz,
                    dx,
                    dy,
                    dz,
                    length2,
                    radii[q] + patch_reach,
                ):
                    continue
                height = normals[q, 0] * ox + normals[q, 1] * oy + normals[q, 2] * oz - offsets[q]
                if not _outside_pyramid(
                    ox,
                    oy,
                    oz,
                    height,
                    band,
                    hull,
                    hull_ptr[q],
                    hull_ptr[q + 1],
                    dx,
                    dy,
                    dz,
                    patch_reach,
                    targets,
                    flat + band,
                ) and not _beyond_patch(
                    ox, oy, oz, hull, hull_ptr[q], hull_ptr[q + 1], outline, patch_normal, limits
                ):
                    out[c] = False
                    recent = q
                    break
            if not out[c]:
                break
    return out


def _capsule_misses(px, py, pz, dx, dy, dz, length2, reach):
    """Whether a sphere at ``p`` (relative to a ray origin) lies farther than ``reach``
    from the segment from the origin to ``d`` (``length2 = |d|^2``)."""
    t = 0.0
    if length2 > 0.0:
        t = min(max((px * dx + py * dy + pz * dz) / length2, 0.0), 1.0)
    ex = px - t * dx
    ey = py - t * dy
    ez = pz - t * dz
    return ex * ex + ey * ey + ez * ez > reach * reach


def _outside_pyramid(ox, oy, oz, height, band, hull, a, b, dx, dy, dz, reach, targets, margin):
    """Whether the ball (o + d, reach), or every one of ``targets`` by more than
    ``margin``, lies wholly outside one side plane of the pyramid from ``o`` through the
    hull ``hull[a:b]`` (counter-clockwise about the facet normal; ``height`` is o's above
    the facet's plane)."""
    if abs(height) <= band or b - a < 3:
        return False
    sign = -1.0 if height > 0.0 else 1.0
    for k in range(a, b):
        j = k + 1 if k + 1 < b else a
        ax = hull[k, 0] - ox
        ay = hull[k, 1] - oy
        az = hull[k, 2] - oz
        bx = hull[j, 0] - ox
        by = hull[j, 1] - oy
        bz = hull[j, 2] - oz
        nx = sign * (ay * bz - az * by)
        ny = sign * (az * bx - ax * bz)
        nz = sign * (ax * by - ay * bx)
        norm = math.sqrt(nx * nx + ny * ny + nz * nz)
        if nx * dx + ny * dy + nz * dz < -reach * norm:
            return True
        if len(targets) == 0:
            continue
        limit = -margin * norm
        outside = True
        for v in range(len(targets)):
            t = targets[v]
            if nx * (t[0] - ox) + ny * (t[1] - oy) + nz * (t[2] - oz) >= limit:
                outside = False
                break
        if outside:
            return True
    return False


def _beyond_patch(ox, oy, oz, hull, a, b, outline, normal, limits):
    """Whether the patch's plane or a side plane of the shaft from ``o`` through the
    patch's convex outline separates the facet ``hull[a:b]`` from the shaft (see
    :func:`raytrad.core.shafts.numpy_shaft_clear`; ``limits`` the facets' flatness, the
    targets' lift, the patch's lowest height and height range, and the plane band)."""
    if len(outline) < 3:
        return False
    flat, lift, level, thick, band = limits[0], limits[1], limits[2], limits[3], limits[4]
    # the patch's plane: every target is about lift above its lowest point, the facet
    # below half that
    cut = level + 0.5 * lift
    if normal[0] * ox + normal[1] * oy + normal[2] * oz > cut + flat + band:
        below = True
        for k in range(a, b):
            h = normal[0] * hull[k, 0] + normal[1] * hull[k, 1] + normal[2] * hull[k, 2]
            if h >= cut - flat - band:
                below = False
                break
        if below:
            return True
    return _facet_outside(ox, oy, oz, hull, a, b, outline, 2.0 * lift + flat + band + thick)


def _facet_outside(ox, oy, oz, hull, a, b, outline, margin):
    """Whether the facet ``hull[a:b]`` lies more than ``margin`` outside one side plane of
    the shaft from ``o`` through the patch's convex outline (targets within ``margin`` /
    2 of the outline's plane)."""
    count = len(outline)
    mx, my, mz = 0.0, 0.0, 0.0
    for v in range(count):
        mx += outline[v, 0] / count
        my += outline[v, 1] / count
        mz += outline[v, 2] / count
    for k in range(count):
        j = k + 1 if k + 1 < count else 0
        ax = outline[k, 0] - ox
        ay = outline[k, 1] - oy
        az = outline[k, 2] - oz
        bx = outline[j, 0] - ox
        by = outline[j, 1] - oy
        bz = outline[j, 2] - oz
        nx = ay * bz - az * by
        ny = az * bx - ax * bz
        nz = ax * by - ay * bx
        norm = math.sqrt(nx * nx + ny * ny + nz * nz)
        inner = nx * (mx - ox) + ny * (my - oy) + nz * (mz - oz)
        if norm == 0.0 or abs(inner) <= 1e-9 * norm * (abs(mx - ox) + abs(my - oy) + abs(mz - oz)):
            continue
        if inner < 0.0:
            nx, ny, nz = -nx, -ny, -nz
        limit = -margin * norm
        outside = True
        for v in range(a, b):
            if nx * (hull[v, 0] - ox) + ny * (hull[v, 1] - oy) + nz * (hull[v, 2] - oz) >= limit:
                outside = False
                break
        if outside:
            return True
    return False
