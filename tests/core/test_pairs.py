"""Per-pair form factors (raytrad.core.pairs): the exact unoccluded factor of every patch,
planar or folded, computed on outlines, against the triangle-by-triangle clipped sum over
the patch's refined triangles."""

from __future__ import annotations

import numpy as np
import pytest

from raytrad.constants import tol
from raytrad.core import compiled
from raytrad.core import pairs as pairs_module
from raytrad.core.contour import numpy_planar_contour_form_factor, planar_contour_form_factor
from raytrad.core.kernels import numpy_facing_triangle_sums
from raytrad.core.mesh import MeshSettings, RadiosityMesh, build_mesh
from raytrad.core.pairs import PairFactors
from raytrad.core.pipeline import Prepared
from raytrad.scene.builder import SceneBuilder, box_faces, icosphere, quads_scene

#: Agreement asked of the outline and the triangle sums (rounding over ~100 triangles).
AGREE = 1e-12


def _triangle_truth(pairs: PairFactors, patch: int, x: np.ndarray, n: np.ndarray) -> np.ndarray:
    m = pairs.mesh
    tri = np.flatnonzero(m.triangle_patch == patch)
    margin = tol.horizon * pairs.diagonal
    corners = m.positions[m.triangles[tri]]
    return numpy_facing_triangle_sums(x, n, corners, m.triangle_normal[tri], margin)


def _probes(mesh: RadiosityMesh, rng: np.random.Generator, count: int = 400):
    """Points around the mesh with random normals (most patches straddle their horizon)."""
    lo, hi = mesh.positions.min(axis=0), mesh.positions.max(axis=0)
    x = lo + rng.uniform(-0.1, 1.1, (count, 3)) * (hi - lo)
    n = rng.normal(size=(count, 3))
    return x, n / np.linalg.norm(n, axis=1, keepdims=True)


def _check_patches(mesh: RadiosityMesh, patches: np.ndarray, seed: int) -> float:
    pairs = PairFactors(mesh, None, float(np.linalg.norm(np.ptp(mesh.positions, axis=0))))
    x, n = _probes(mesh, np.random.default_rng(seed))
    seen = 0.0
    for patch in patches:
        got = pairs._unoccluded(x, n, int(patch))
        want = _triangle_truth(pairs, int(patch), x, n)
        np.testing.assert_allclose(got, want, rtol=0, atol=AGREE)
        seen += float((want > 0).mean())
    return seen / len(patches)


def test_folded_cornell_wall_patches_match_the_triangle_sum(cornell: Prepared) -> None:
    """The Cornell box's left wall is a warped quad: its patches are folded."""
    mesh = cornell.mesh
    folded = np.flatnonzero(~mesh.patch_planar)
    assert len(folded) > 0
    planar = np.flatnonzero(mesh.patch_planar)[::40]
    assert _check_patches(mesh, np.concatenate([folded, planar]), seed=1) > 0.2


@pytest.mark.parametrize("lift", [0.05, 0.5])
def test_strongly_folded_quad_matches_the_triangle_sum(lift: float) -> None:
    """A quad with one corner lifted: patches across the fold hold parts of both of its
    triangles, each refined into many; the probes see them from every side."""
    scene = quads_scene(
        [
            [[0, 0, 0], [2, 0, 0], [2, 2, lift], [0, 2, 0]],
            [[0, 0, 2], [0, 2, 2], [2, 2, 2], [2, 0, 2]],  # a ceiling facing down
        ]
    )
    mesh = build_mesh(scene, MeshSettings(receivers=1500, patches=6))
    folded = np.flatnonzero(~mesh.patch_planar)
    assert len(folded) >= 2
    assert np.bincount(mesh.triangle_patch)[folded].min() > 20  # refined: many triangles
    assert _check_patches(mesh, np.arange(mesh.patch_count), seed=2) > 0.2


def _ball_mesh() -> RadiosityMesh:
    """A ball of 320 triangles in a box: a curved surface, whose patches are folded and
    hold a piece per scene triangle."""
    builder = SceneBuilder()
    builder.material("grey", 0.5)
    unit, triangles = icosphere(2)
    for tri in triangles:
        builder.triangle(0.5 * unit[tri], "grey")
    for name, corners, outward in box_faces((-1.0, -1.0, -1.0), (1.0, 1.0, 1.0)):
        builder.quad(corners, "grey", -np.asarray(outward), name)
    return build_mesh(builder.build(), MeshSettings(receivers=3000, patches=150))


def _seen_whole(mesh: RadiosityMesh, patch: int, x: np.ndarray, n: np.ndarray) -> np.ndarray:
    """(C,) whether every triangle of the patch faces x and lies above its horizon,
    measured on the triangles (the outline's shortcut applies there)."""
    tri = np.flatnonzero(mesh.triangle_patch == patch)
    corners = mesh.positions[mesh.triangles[tri]]
    faces = np.einsum("ctj,tj->ct", x[:, None, :] - corners[None, :, 0], mesh.triangle_normal[tri])
    above = np.einsum("cvj,cj->cv", corners.reshape(-1, 3)[None] - x[:, None], n)
    return (faces > 1e-9).all(axis=1) & (above >= 0).all(axis=1)


def _ball_above(mesh: RadiosityMesh, patch: int, x: np.ndarray, n: np.ndarray) -> np.ndarray:
    """(C,) whether a ball round the patch's corners lies above each horizon."""
    corners = mesh.positions[np.unique(mesh.triangles[mesh.triangle_patch == patch])]
    center = corners.mean(axis=0)
    radius = np.linalg.norm(corners - center, axis=1).max()
    return np.einsum("cj,cj->c", center - x, n) - radius > 1e-9


def test_ball_patches_match_the_triangle_sum_seen_whole_or_not(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A ball's folded patches (a piece per scene triangle) against the triangle sum,
    from probes that see some patches whole (the outline's shortcut) and others in part
    (piece by piece): compiled and numpy alike."""
    mesh = _ball_mesh()
    folded = np.flatnonzero(~mesh.patch_planar)
    assert len(folded) >= 10
    pairs = PairFactors(mesh, None, float(np.linalg.norm(np.ptp(mesh.positions, axis=0))))
    x, n = _probes(mesh, np.random.default_rng(6), 300)
    outside = np.linalg.norm(x, axis=1) > 0.55
    x, n = x[outside], n[outside]
    whole = parts = above = 0
    results = []
    for patch in folded:
        got = pairs._unoccluded(x, n, int(patch))
        want = _triangle_truth(pairs, int(patch), x, n)
        np.testing.assert_allclose(got, want, rtol=0, atol=AGREE)
        seen = _seen_whole(mesh, int(patch), x, n)
        whole += int(seen.sum())
        parts += int(((want > 0) & ~seen).sum())
        above += int((_ball_above(mesh, int(patch), x, n) & (want > 0)).sum())
        results.append(got)
    # whole (the rim's sum), in part, and whole with its ball above the horizon (the
    # corner loops skipped) all occur
    assert whole > 200 and parts > 200 and above > 100, (whole, parts, above)
    monkeypatch.setenv("RAYTRAD_KERNELS", "numpy")
    assert compiled.get() is None
    for patch, got in zip(folded, results, strict=True):
        np.testing.assert_allclose(pairs._unoccluded(x, n, int(patch)), got, rtol=0, atol=AGREE)


@pytest.mark.skipif(compiled.get() is None, reason="needs the compiled kernels")
@pytest.mark.parametrize("seed", range(3))
def test_compiled_visible_factors_match_numpy(seed: int) -> None:
    """The visibility-weighted accumulation: random weights and blocked samples, with
    receivers that have no sample weight, every sample blocked, or none traced."""
    rng = np.random.default_rng(seed)
    count, samples, near = 300, 18, 500
    unoccluded = rng.uniform(0, 0.2, count)
    doubt = rng.random(count) < 0.7
    weight = rng.uniform(0, 0.01, (count, samples)) * (rng.random((count, samples)) < 0.6)
    weight[:10] = 0.0  # no far samples
    far_hidden = (rng.random((count, samples)) < 0.4) & (weight > 0)
    far_hidden[10:20] = weight[10:20] > 0  # every far sample blocked
    near_c = np.sort(rng.integers(20, count, near))
    near_w = rng.uniform(0, 0.005, near)
    near_hidden = rng.random(near) < 0.4
    args = (unoccluded, doubt, weight, far_hidden, near_c, near_w, near_hidden)
    fast = pairs_module.visible_factors(*args)
    reference = pairs_module.numpy_visible_factors(*args)
    np.testing.assert_allclose(fast, reference, rtol=1e-12, atol=1e-15)
    assert (fast[:10][doubt[:10]] == 0).all()
    assert (fast[10:20][doubt[10:20]] == 0).all()
    np.testing.assert_array_equal(fast[~doubt], unoccluded[~doubt])
    assert ((fast > 0) & (fast < unoccluded)).sum() > 100


@pytest.mark.skipif(compiled.get() is None, reason="needs the compiled kernels")
def test_compiled_planar_contour_form_factor_matches_numpy(
    cornell: Prepared, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The planar patches' one-loop compiled factor against the numpy path, from random
    probes and from probes on patches' own planes and edges (coplanar, grazing)."""
    mesh = cornell.mesh
    pairs = PairFactors(mesh, None, float(np.linalg.norm(np.ptp(mesh.positions, axis=0))))
    x, n = _probes(mesh, np.random.default_rng(3))
    # on the receivers themselves, with their normals: coplanar with their own patches
    pick = np.random.default_rng(4).choice(mesh.receiver_count, 300, replace=False)
    x = np.concatenate([x, mesh.receiver_position[pick]])
    n = np.concatenate([n, mesh.receiver_normal[pick]])
    patches = np.flatnonzero(mesh.patch_planar)[::7]
    fast = [pairs._unoccluded(x, n, int(p)) for p in patches]
    monkeypatch.setenv("RAYTRAD_KERNELS", "numpy")
    assert compiled.get() is None
    for p, got in zip(patches, fast, strict=True):
        want = pairs._unoccluded(x, n, int(p))
        np.testing.assert_allclose(got, want, rtol=0, atol=AGREE)
    assert sum(float((f > 0).mean()) for f in fast) / len(fast) > 0.2


@pytest.mark.skipif(compiled.get() is None, reason="needs the compiled kernels")
def test_compiled_near_field_matches_numpy(cornell: Prepared) -> None:
    """The one-loop near field (facing test, exact factor, visible centroid, corner
    shares at 3 and 2 subdivision levels, far shares) against the numpy path, from
    receivers on and around the patches (on their edges: triangles straddling the
    horizon) and random probes."""
    mesh = cornell.mesh
    pairs = PairFactors(mesh, None, float(np.linalg.norm(np.ptp(mesh.positions, axis=0))))
    rng = np.random.default_rng(5)
    probes, probe_normals = _probes(mesh, rng, 200)
    seen = {"far": 0, "split": 0, "items": 0}
    for patch in np.flatnonzero(mesh.patch_planar)[::9]:
        sub = mesh.patch_subareas(int(patch))
        close = np.argsort(
            np.linalg.norm(mesh.receiver_position - mesh.patch_center[patch], axis=1)
        )
        pick = close[:150]
        x = np.concatenate([mesh.receiver_position[pick], probes])
        n = np.concatenate([mesh.receiver_normal[pick], probe_normals])
        near = rng.random((len(x), sub.stop - sub.start)) < 0.5
        got = pairs._near_field(x, n, near, sub)
        want = pairs._numpy_near_field(x, n, near, sub)
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])
        for a, b in zip(got[2:], want[2:], strict=True):
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)
        corners = pairs._tri_corners[want[1]]
        size = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1)
        distance = np.linalg.norm(corners.mean(axis=1) - x[want[0]], axis=1) / size
        seen["far"] += int((distance >= 3.0).sum())
        seen["split"] += int((distance < 1.0).sum())
        seen["items"] += len(want[0])
    assert min(seen.values()) > 50, seen


@pytest.mark.skipif(compiled.get() is None, reason="needs the compiled kernels")
def test_compiled_near_field_matches_numpy_through_cluster_trees() -> None:
    """The near field's walk through split sub-areas (a coarse patching, one sub-area a
    patch): clusters taken whole (disk factor, lifted sample point) and the leaves'
    triangles, against the numpy path, item by item and in the same order."""
    from raytrad.scene.builtin import cornell_box

    mesh = build_mesh(cornell_box(), MeshSettings(receivers=2000, patches=25, samples=1))
    pairs = PairFactors(mesh, None, float(np.linalg.norm(np.ptp(mesh.positions, axis=0))))
    assert pairs._tree.count > 3 * mesh.subarea_count
    rng = np.random.default_rng(8)
    probes, probe_normals = _probes(mesh, rng, 300)
    clusters = triangles = 0
    for patch in range(mesh.patch_count):
        sub = mesh.patch_subareas(patch)
        lifted = mesh.receiver_position[::7] + 1e-3 * mesh.receiver_normal[::7]
        x = np.concatenate([lifted, probes])
        n = np.concatenate([mesh.receiver_normal[::7], probe_normals])
        near = np.ones((len(x), sub.stop - sub.start), dtype=bool)
        got = pairs._near_field(x, n, near, sub)
        want = pairs._numpy_near_field(x, n, near, sub)
        for k in (0, 1, 5, 6):  # receivers, triangles, cluster receivers, clusters
            np.testing.assert_array_equal(got[k], want[k])
        for k in (2, 3, 4, 7, 8):
            np.testing.assert_allclose(got[k], want[k], rtol=1e-12, atol=1e-12)
        clusters += len(want[6])
        triangles += len(want[1])
        # a cluster taken whole lies beyond NEAR_FACTOR of its sizes from the receiver
        tree = pairs._tree
        d = np.linalg.norm(x[want[5]] - tree.point[want[6]], axis=1)
        assert np.all(d > pairs_module.NEAR_FACTOR * tree.size[want[6]])
    assert clusters > 1000 and triangles > 1000, (clusters, triangles)


@pytest.mark.skipif(compiled.get() is None, reason="needs the compiled kernels")
def test_compiled_outline_sum_reads_each_corner_at_both_its_edges() -> None:
    """The compiled sum normalises each corner's direction once and reads it at the edge
    that ends there too: an outline listed out of order (a square with a hole, the
    edges shuffled) and one edge whose end starts no edge (the unmatched path) give the
    numpy sum, and the whole square gives the closed-form factor of a parallel square."""
    outer = np.array([[0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1.0]])
    inner = np.array([[0.3, 0.3, 1], [0.3, 0.6, 1], [0.6, 0.6, 1], [0.6, 0.3, 1.0]])
    start = np.concatenate([outer, inner])
    end = np.concatenate([np.roll(outer, -1, axis=0), np.roll(inner, -1, axis=0)])
    order = np.random.default_rng(6).permutation(len(start))
    start, end = start[order], end[order]
    normal, center = np.array([0.0, 0.0, -1.0]), start.mean(axis=0)
    rng = np.random.default_rng(7)
    x = np.column_stack([rng.uniform(-1, 2, (400, 2)), rng.uniform(-1, 0.9, 400)])
    n = rng.normal(size=(400, 3))
    n[:200] = [0.0, 0.0, 1.0]  # facing the square: every corner above the horizon
    n /= np.linalg.norm(n, axis=1)[:, None]
    loose = end.copy()
    loose[0, 1] += 0.05  # one edge ends where no edge starts
    for s, e in ((start, end), (start, loose)):
        got = planar_contour_form_factor(s, e, x, n, normal, center, 1e-12)
        want = numpy_planar_contour_form_factor(s, e, x, n, normal, center, 1e-12)
        np.testing.assert_allclose(got, want, rtol=0, atol=AGREE)
        assert (got[:200] > 0).all()
    # a point under a corner of a parallel unit square a unit away (closed form for a
    # differential area to a parallel rectangle with a corner above it, A = B = 1)
    square = planar_contour_form_factor(
        outer,
        np.roll(outer, -1, axis=0),
        np.zeros((1, 3)),
        np.array([[0.0, 0.0, 1.0]]),
        normal,
        outer.mean(axis=0),
        1e-12,
    )
    a = b = 1.0
    exact = (
        a / np.sqrt(1 + a * a) * np.arctan(b / np.sqrt(1 + a * a))
        + b / np.sqrt(1 + b * b) * np.arctan(a / np.sqrt(1 + b * b))
    ) / (2 * np.pi)
    assert square[0] == pytest.approx(exact, rel=1e-12)
