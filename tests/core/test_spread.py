"""Where a near receiver's weight of a sub-area or cluster lies (raytrad.core.spread):
the compiled spread against its numpy reference, and the clusters' spread against the
triangle-by-triangle one it replaces, on a radiosity linear across the surfaces."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from raytrad.core import clusters, compiled
from raytrad.core.gather import subarea_triangles
from raytrad.core.mesh import MeshSettings, RadiosityMesh, build_mesh
from raytrad.core.spread import (
    MIDPOINT_SIZES,
    GatherShares,
    corner_form_factors,
    numpy_corner_elements,
    numpy_spread_shares,
    numpy_subarea_spread,
    spread_shares,
)
from raytrad.scene.builder import quads_scene
from raytrad.scene.builtin import cornell_box
from tests.conftest import CORNELL_MESH

#: One sub-area a patch (two for the light) of a coarse patching: sub-areas of 40-200
#: triangles, split three to five times.
CLUSTERED = replace(CORNELL_MESH, patches=25, samples=1, emitter_samples=2)


@pytest.fixture(scope="module")
def mesh() -> RadiosityMesh:
    return build_mesh(cornell_box(), CLUSTERED)


def _elements(mesh: RadiosityMesh, shares: GatherShares, seed: int) -> tuple[np.ndarray, ...]:
    """Receivers 3-20 cm off the Cornell box's surfaces, looking back at them, each with
    elements on the sub-areas near it and on random ones."""
    rng = np.random.default_rng(seed)
    pairs = 200
    home = rng.integers(0, mesh.subarea_count, pairs)
    lift = rng.choice([0.03, 0.1, 0.2], pairs)[:, None]
    points = mesh.subarea_point[home] + lift * mesh.subarea_normal[home]
    normals = -mesh.subarea_normal[home]
    near = np.argsort(np.linalg.norm(mesh.subarea_point[None] - points[:, None], axis=2), axis=1)
    subareas = np.concatenate([near[:, 1:8].reshape(-1), rng.integers(0, mesh.subarea_count, 600)])
    sub_pair = np.concatenate([np.repeat(np.arange(pairs), 7), rng.integers(0, pairs, 600)])
    nodes = shares.tree.root[subareas]
    return sub_pair, nodes, rng.random(len(nodes)), points, normals


def _dense(spread: tuple[np.ndarray, ...], stride: int) -> np.ndarray:
    """(pairs, stride) weights of a spread's CSR (pointer, sources, weights)."""
    pointer, sources, weights = spread
    out = np.zeros((len(pointer) - 1, stride))
    out[np.repeat(np.arange(len(pointer) - 1), np.diff(pointer)), sources] = weights
    return out


def _check_csr(spread: tuple[np.ndarray, ...]) -> None:
    """Sources ascending and distinct within a pair, weights positive summing to 1."""
    pointer, sources, weights = spread
    assert pointer[0] == 0 and pointer[-1] == len(sources) == len(weights)
    assert (weights > 0).all()
    for p in range(len(pointer) - 1):
        row = slice(pointer[p], pointer[p + 1])
        assert (np.diff(sources[row]) > 0).all()
        if pointer[p + 1] > pointer[p]:
            assert abs(weights[row].sum() - 1.0) < 1e-12


@pytest.mark.skipif(compiled.get() is None, reason="numba is not installed")
def test_compiled_spread_matches_numpy(mesh: RadiosityMesh) -> None:
    """On the coarse patching (clusters taken whole) and on a finer one (sub-areas far
    enough to hand their weight on whole), with triangle elements beside the nodes: the
    compiled loop that sums as it spreads against the reference's entries summed by
    numpy."""
    kinds = np.zeros(3, int)
    finer = build_mesh(cornell_box(), replace(CORNELL_MESH, samples=2, emitter_samples=4))
    for each in (mesh, finer):
        shares = GatherShares(each, *subarea_triangles(each))
        sub_pair, nodes, weight, points, normals = _elements(each, shares, 5)
        rng = np.random.default_rng(11)
        triangles = rng.integers(0, len(each.triangles), 300)
        elements = (
            rng.integers(0, 200, 300),
            triangles,
            rng.random(300),
            rng.dirichlet(np.ones(3), 300),
        )
        fast = spread_shares(sub_pair, nodes, weight, points, normals, shares, elements)
        slow = numpy_spread_shares(sub_pair, nodes, weight, points, normals, shares, elements)
        np.testing.assert_array_equal(fast[0], slow[0])
        np.testing.assert_array_equal(fast[1], slow[1])
        np.testing.assert_allclose(fast[2], slow[2], rtol=1e-12, atol=1e-15)
        _check_csr(fast)
        # the three kinds of entries: nodes handed on whole, clusters, triangles' corners
        entries = numpy_subarea_spread(sub_pair, nodes, weight, points, normals, shares)[1]
        base = each.receiver_count
        handed = np.isin(entries - base, nodes)
        kinds += [handed.sum(), ((entries >= base) & ~handed).sum(), (entries < base).sum()]
    assert kinds.min() > 20, kinds


@pytest.mark.skipif(compiled.get() is None, reason="numba is not installed")
def test_triangle_elements_spread_over_their_seen_corners_as_numpy_does(
    mesh: RadiosityMesh, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A triangle element's weight goes to its seen corners, a hidden corner's share moved
    to the others (a triangle with every corner hidden, whose corners' own shares are 0,
    gives nothing); the compiled spread sums them with the nodes' as the reference does,
    and the numpy path is the reference."""
    shares = GatherShares(mesh, *subarea_triangles(mesh))
    rng = np.random.default_rng(3)
    sub_pair, nodes, weight, points, normals = _elements(mesh, shares, 8)
    count = 500
    triangles = rng.integers(0, len(mesh.triangles), count)
    shares.corner_share = shares.corner_share.copy()
    shares.corner_share[triangles[:40], rng.integers(0, 3, 40)] = 0.0  # one corner hidden
    shares.corner_share[triangles[40:45]] = 0.0  # all hidden
    tri_share = rng.dirichlet(np.ones(3), count)
    elements = (rng.integers(0, 200, count), triangles, rng.random(count), tri_share)
    reference = numpy_corner_elements(*elements, shares)
    spread = reference[2].reshape(-1, 3)
    assert (spread[shares.corner_share[triangles] == 0] == 0).all()  # hidden: nothing
    seen = (shares.corner_share[triangles] > 0).any(axis=1)
    assert (~seen).sum() >= 5
    np.testing.assert_allclose(spread[seen].sum(axis=1), elements[2][seen], rtol=1e-14)
    # triangles alone: each pair's weights are its corners' entries summed, normalised
    none = np.zeros(0, np.int64)
    alone = spread_shares(none, none, np.zeros(0), points, normals, shares, elements)
    stride = mesh.receiver_count
    totals = np.bincount(
        reference[0] * stride + reference[1], weights=reference[2], minlength=200 * stride
    ).reshape(200, stride)
    expected = totals / np.where(totals.sum(axis=1) > 0, totals.sum(axis=1), 1.0)[:, None]
    np.testing.assert_allclose(_dense(alone, stride), expected, rtol=1e-13, atol=1e-16)
    # with the nodes
    fast = spread_shares(sub_pair, nodes, weight, points, normals, shares, elements)
    monkeypatch.setattr(compiled, "get", lambda: None)
    slow = spread_shares(sub_pair, nodes, weight, points, normals, shares, elements)
    reference_csr = numpy_spread_shares(sub_pair, nodes, weight, points, normals, shares, elements)
    for a, b in zip(slow, reference_csr, strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(fast[1], slow[1])
    np.testing.assert_allclose(fast[2], slow[2], rtol=1e-12, atol=1e-15)


def test_a_near_receiver_whose_cut_has_no_leaf_spreads_over_clusters(
    mesh: RadiosityMesh,
) -> None:
    """A receiver near a sub-area (within its node's reach) but far enough in the sizes of
    its clusters that its cut takes only clusters whole, walking no triangle: numpy's
    ``bincount`` of no triangles is int64 even with weights, and the reference's sums
    once failed on it (a scene with tessellated balls, in the benchmark's numpy pass)."""
    shares = GatherShares(mesh, *subarea_triangles(mesh))
    tree = shares.tree
    found = []
    for s in range(mesh.subarea_count):
        node = tree.root[s]
        for lift in np.linspace(0.01, 1.5, 60):
            point = mesh.subarea_point[s] + lift * mesh.subarea_normal[s]
            if np.linalg.norm(point - tree.point[node]) > shares.node_reach[node]:
                continue
            _, item = tree.cuts(np.array([node]), point[None], MIDPOINT_SIZES)
            if (item >= 0).all():
                found.append((node, point, -mesh.subarea_normal[s]))
                break
    assert found, "no such receiver in this patching"
    nodes = np.array([f[0] for f in found])
    points = np.array([f[1] for f in found])
    normals = np.array([f[2] for f in found])
    weight = np.linspace(0.5, 1.0, len(found))
    count = len(found)
    slow = numpy_subarea_spread(np.arange(count), nodes, weight, points, normals, shares)
    assert (slow[1] >= mesh.receiver_count).all()  # clusters (and nodes) only
    assert np.isfinite(slow[2]).all() and (slow[2] >= 0).all() and slow[2].sum() > 0
    if compiled.get() is not None:
        fast = spread_shares(np.arange(count), nodes, weight, points, normals, shares)
        _check_csr(fast)
        stride = mesh.receiver_count + tree.count
        totals = np.bincount(slow[0] * stride + slow[1], weights=slow[2], minlength=count * stride)
        totals = totals.reshape(count, stride)
        np.testing.assert_allclose(
            _dense(fast, stride), totals / totals.sum(axis=1)[:, None], rtol=1e-12, atol=1e-15
        )


def test_clusters_spread_a_linear_radiosity_as_the_triangles_do(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """What receivers above a large floor (one sub-area of 32 000 triangles) gather of
    it through its clusters (a far cluster's weight on its mean) against the
    triangle-by-triangle spread the trees replace (every triangle's corners, as when no
    sub-area is split), for a radiosity linear in position: they differ by second-order
    terms of the clusters' sizes over their distance, with a hundredth of the entries."""
    floor = quads_scene([[(0, 0, 0), (4, 0, 0), (4, 0, 4), (0, 0, 4)]], facing=[(0, 1, 0)])
    settings = MeshSettings(receivers=16000, patches=1, samples=1, emitter_samples=1)
    mesh = build_mesh(floor, settings)
    tree_shares = GatherShares(mesh, *subarea_triangles(mesh))
    monkeypatch.setattr(clusters, "CLUSTER_TRIANGLES", 1 << 30)
    flat_shares = GatherShares(mesh, *subarea_triangles(mesh))
    assert flat_shares.tree.count == 1 < tree_shares.tree.count
    rng = np.random.default_rng(9)
    count = 60
    points = np.column_stack(
        [rng.uniform(-1, 5, count), rng.uniform(0.05, 2.0, count), rng.uniform(-1, 5, count)]
    )
    normals = np.tile([0.0, -1.0, 0.0], (count, 1))
    radiosity = 1.0 + mesh.receiver_position @ np.array([0.3, 0.0, -0.2])
    gathered, entries = [], []
    for shares in (tree_shares, flat_shares):
        pair, source, w = numpy_subarea_spread(
            np.arange(count),
            shares.tree.root[np.zeros(count, int)],
            np.ones(count),
            points,
            normals,
            shares,
        )
        values = shares.means.extend(np.repeat(radiosity[:, None], 3, axis=1))[:, 0]
        total = np.bincount(pair, weights=w, minlength=count)
        gathered.append(np.bincount(pair, weights=w * values[source], minlength=count) / total)
        entries.append(len(source))
    assert entries[0] < entries[1] / 50
    difference = np.abs(gathered[0] - gathered[1]) / np.ptp(radiosity)
    assert difference.max() < 0.015 and difference.mean() < 0.003, difference
    # while the floor's mean, all a receiver would get without the near field, is off by
    # tens of times as much
    mean = shares.means.extend(np.repeat(radiosity[:, None], 3, axis=1))[-1, 0]
    assert np.abs(mean - gathered[1]).mean() / np.ptp(radiosity) > 20 * difference.mean()


def test_corner_form_factors_sum_to_the_triangle_factor() -> None:
    """The rule's nine points against Lambert's exact factor of a triangle four of its
    sizes away (the spread's weights are form factors, as a cluster's disk factor is)."""
    triangle = np.array([[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]])
    up = np.array([[0.0, 0.0, 1.0]])
    point = np.array([[0.3, 0.3, 4.0]])
    weights = corner_form_factors(triangle, up, point, -up)[0]
    exact = 0.5 / (np.pi * 16.0)  # area cos cos / (pi r^2), to 1/r^2 corrections
    assert abs(weights.sum() / exact - 1.0) < 0.02


def _chunk_inputs(mesh: RadiosityMesh, shares: GatherShares, seed: int) -> tuple:
    """What a chunk of 120 receivers hands :meth:`GatherShares.spread_chunk`: some
    receivers not close, some far samples and near items blocked, rows with nothing."""
    rng = np.random.default_rng(seed)
    count, samples = 120, 6
    _, nodes, _, points, normals = _elements(mesh, shares, seed)
    points, normals = points[:count], normals[:count]
    close = rng.random(count) < 0.7
    sample_weight = rng.uniform(0, 0.01, (count, samples))
    far = rng.random((count, samples)) < 0.5
    far[:8] = False  # no far sample: a row of near items alone, or of nothing
    far_hidden = far & (rng.random((count, samples)) < 0.3)
    root = shares.tree.root[rng.integers(0, mesh.subarea_count, samples)]
    tri_count, node_count = 400, 60
    near_c = np.sort(rng.integers(4, count, tri_count))  # receivers 0-3 see nothing near
    triangles = (
        near_c,
        rng.integers(0, len(mesh.triangles), tri_count),
        rng.uniform(0, 0.002, tri_count),
        rng.dirichlet(np.ones(3), tri_count),
        rng.random(tri_count) < 0.2,
    )
    node_c = np.sort(rng.integers(4, count, node_count))
    clusters = (node_c, nodes[:node_count], rng.uniform(0, 0.003, node_count))
    clusters = (*clusters, rng.random(node_count) < 0.2)
    return close, (sample_weight, far, far_hidden), root, triangles, clusters, points, normals


@pytest.mark.skipif(compiled.get() is None, reason="numba is not installed")
@pytest.mark.parametrize("seed", [1, 2])
def test_compiled_chunk_spread_matches_numpy(
    mesh: RadiosityMesh, monkeypatch: pytest.MonkeyPatch, seed: int
) -> None:
    """The chunk's elements built in the compiled loop (far samples not blocked, then
    clusters, then triangles, per close receiver) and its rows without weights dropped,
    against the numpy path: the same rows, pointers and sources, the weights to 1e-12."""
    shares = GatherShares(mesh, *subarea_triangles(mesh))
    inputs = _chunk_inputs(mesh, shares, seed)
    fast = shares.spread_chunk(*inputs)
    monkeypatch.setattr(compiled, "get", lambda: None)
    slow = shares.spread_chunk(*inputs)
    for a, b in zip(fast[:3], slow[:3], strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_allclose(fast[3], slow[3], rtol=1e-12, atol=1e-15)
    close = inputs[0]
    rows = fast[0]
    assert close[rows].all() and (np.diff(rows) > 0).all()
    assert 0 < len(rows) < close.sum()  # some close receivers gather nothing
    assert (np.diff(fast[1]) > 0).all()
    _check_csr(fast[1:])


@pytest.mark.skipif(compiled.get() is None, reason="numba is not installed")
def test_compiled_gather_rows_match_numpy(monkeypatch: pytest.MonkeyPatch) -> None:
    """A final gather's rows (every patch's factors and near-field weights at new points,
    through every kernel of a chunk) against the numpy kernels'."""
    from raytrad.constants import tol
    from raytrad.core.pairs import receiver_points
    from raytrad.core.pipeline import prepare

    prepared = prepare(cornell_box(), replace(CORNELL_MESH, receivers=600))
    try:
        mesh, engine = prepared.mesh, prepared.engine
        points, _ = receiver_points(mesh, tol.ray_offset * engine.diagonal)
        pick = np.random.default_rng(0).choice(mesh.receiver_count, 150, replace=False)
        fast = engine.gather_rows(points[pick], mesh.receiver_normal[pick])
        monkeypatch.setattr(compiled, "get", lambda: None)
        slow = engine.gather_rows(points[pick], mesh.receiver_normal[pick])
    finally:
        prepared.close()
    near_rows = 0
    for (p, near, f, g), (q, near2, f2, g2) in zip(fast.patches, slow.patches, strict=True):
        assert p == q
        np.testing.assert_array_equal(near, near2)
        np.testing.assert_allclose(f, f2, rtol=1e-12, atol=1e-15)
        for a, b in ((g.receivers, g2.receivers), (g.pointer, g2.pointer), (g.sources, g2.sources)):
            np.testing.assert_array_equal(a, b)
        # weights are float32, a row's summing to 1; compared as what they carry, times
        # the row's factor: a row seen at grazing (factor 1e-10) has shares that are
        # ratios of Lambert sums cancelling to 1e-13, so its normalised weights differ by
        # up to 7e-8 between the paths (see the CHANGELOG), its contributions by 1e-17
        rows = np.repeat(np.arange(len(g.receivers)), np.diff(g.pointer))
        np.testing.assert_allclose(
            g.weights * g.factors[rows], g2.weights * g2.factors[rows], rtol=2.4e-7, atol=1e-15
        )
        near_rows += len(g.receivers)
    assert near_rows > 100
