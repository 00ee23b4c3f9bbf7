"""The sub-areas' cluster trees (raytrad.core.clusters): their shape against the mesh they
are built from, the cuts a receiver takes through them, and that a cut stays bounded as
a sub-area holds more triangles."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from raytrad.core import compiled, gather
from raytrad.core.clusters import CLUSTER_TRIANGLES, Clusters, build_clusters
from raytrad.core.gather import (
    corner_shares,
    node_means,
    numpy_node_means,
    subarea_means,
    subarea_triangles,
    visible_areas,
)
from raytrad.core.mesh import MeshSettings, RadiosityMesh, build_mesh
from raytrad.scene.builder import quads_scene
from raytrad.scene.builtin import cornell_box
from tests.conftest import CORNELL_MESH

#: Two sub-areas a patch (256 for the light): most sub-areas are split.
CLUSTERED = replace(CORNELL_MESH, samples=2, emitter_samples=4)


@pytest.fixture(scope="module")
def clustered() -> tuple[RadiosityMesh, Clusters]:
    mesh = build_mesh(cornell_box(), CLUSTERED)
    return mesh, build_clusters(mesh, *subarea_triangles(mesh))


def test_trees_split_sub_areas_into_halves_of_their_triangles(
    clustered: tuple[RadiosityMesh, Clusters],
) -> None:
    mesh, tree = clustered
    sub_tri, sub_ptr = subarea_triangles(mesh)
    assert np.array_equal(np.sort(tree.sub_tri), np.arange(len(mesh.triangles)))
    for s in range(mesh.subarea_count):  # a root holds its sub-area's triangles
        root = tree.root[s]
        assert (tree.start[root], tree.stop[root]) == (sub_ptr[s], sub_ptr[s + 1])
        run = tree.sub_tri[sub_ptr[s] : sub_ptr[s + 1]]
        assert np.array_equal(np.sort(run), np.sort(sub_tri[sub_ptr[s] : sub_ptr[s + 1]]))
    inner = tree.left >= 0
    assert inner.sum() > 100
    assert np.array_equal(inner, tree.right >= 0)
    a, b = tree.left[inner], tree.right[inner]
    assert np.array_equal(tree.start[a], tree.start[inner])
    assert np.array_equal(tree.stop[a], tree.start[b])
    assert np.array_equal(tree.stop[b], tree.stop[inner])
    counts = tree.stop - tree.start
    assert counts[inner].min() > CLUSTER_TRIANGLES >= counts[~inner].max()
    assert np.all(np.abs(counts[a] - counts[b]) <= 1)  # median splits
    # the nodes of each patch are one run
    patch = mesh.triangle_patch[tree.sub_tri[tree.start]]
    assert np.array_equal(np.searchsorted(patch, np.arange(mesh.patch_count + 1)), tree.patch_ptr)


def test_node_geometry_against_its_triangles(clustered: tuple[RadiosityMesh, Clusters]) -> None:
    mesh, tree = clustered
    roots = np.zeros(tree.count, bool)
    roots[tree.root] = True
    for n in range(tree.count):
        tris = tree.sub_tri[tree.start[n] : tree.stop[n]]
        corners = mesh.positions[mesh.triangles[tris]].reshape(-1, 3)
        np.testing.assert_allclose(tree.area[n], mesh.triangle_area[tris].sum(), rtol=1e-12)
        if roots[n]:  # the sub-area's own sample point
            s = np.flatnonzero(tree.root == n)[0]
            assert np.array_equal(tree.point[n], mesh.subarea_point[s])
            continue
        np.testing.assert_allclose(
            tree.size[n], np.linalg.norm(np.ptp(corners, axis=0)), rtol=1e-12
        )
        centroids = mesh.positions[mesh.triangles[tris]].mean(axis=1)
        on = np.flatnonzero(
            np.all(np.isclose(centroids, tree.point[n], rtol=0, atol=1e-12), axis=1)
        )
        assert len(on) and np.allclose(mesh.triangle_normal[tris[on[0]]], tree.normal[n])


def test_small_sub_areas_are_their_own_nodes() -> None:
    mesh = build_mesh(cornell_box(), CORNELL_MESH)
    sub_tri, sub_ptr = subarea_triangles(mesh)
    assert np.diff(sub_ptr).max() <= CLUSTER_TRIANGLES
    tree = build_clusters(mesh, sub_tri, sub_ptr)
    assert tree.count == mesh.subarea_count
    assert np.array_equal(tree.root, np.arange(mesh.subarea_count))
    assert np.array_equal(tree.sub_tri, sub_tri)
    assert np.array_equal(tree.size, mesh.subarea_size)


def _probes(mesh: RadiosityMesh, count: int, rng: np.random.Generator) -> np.ndarray:
    """Points on and a little off the mesh's surfaces."""
    k = rng.integers(0, mesh.receiver_count, count)
    lift = rng.choice([0.0, 0.01, 0.05, 0.2], count)[:, None]
    return mesh.receiver_position[k] + lift * mesh.receiver_normal[k]


@pytest.mark.parametrize("scale", [2.0, 5.0])
def test_a_cut_covers_its_node_once_and_takes_far_clusters_whole(
    clustered: tuple[RadiosityMesh, Clusters], scale: float
) -> None:
    mesh, tree = clustered
    rng = np.random.default_rng(3)
    nodes = tree.root[rng.integers(0, mesh.subarea_count, 600)]
    points = _probes(mesh, len(nodes), rng)
    element, item = tree.cuts(nodes, points, scale)
    assert np.all(np.diff(element) >= 0)
    node = np.where(item >= 0, item, -1 - item)
    whole = item >= 0
    assert 0 < whole.mean() < 1
    # each element's items tile its node's slots in order
    for k in range(len(nodes)):
        mine = node[element == k]
        assert tree.start[mine[0]] == tree.start[nodes[k]]
        assert np.array_equal(tree.stop[mine[:-1]], tree.start[mine[1:]])
        assert tree.stop[mine[-1]] == tree.stop[nodes[k]]
    # whole clusters are far in their own sizes, leaves are leaves
    distance = np.linalg.norm(points[element] - tree.point[node], axis=1)
    assert np.all(distance[whole] > scale * tree.size[node[whole]])
    assert np.all(tree.left[node[~whole]] < 0)
    assert not np.any(whole & np.isin(node, nodes))  # an element's own node is split
    if compiled.get() is not None:
        fast = compiled.get()
        stack, cut = np.empty(256, np.int64), np.empty(len(mesh.triangles) * 2, np.int64)
        threshold = scale * tree.size
        for k in range(len(nodes)):
            m = fast._cut(
                nodes[k], points[k], threshold, tree.left, tree.right, tree.point, stack, cut
            )
            assert np.array_equal(cut[:m], item[element == k])


def test_a_cut_stays_bounded_as_the_sub_area_refines() -> None:
    """A receiver one sub-area size from a sub-area takes a few dozen items of its tree
    whatever the triangle count (the near field's per-pair work), where it took every
    triangle before the trees."""
    taken = []
    for receivers in (4000, 16000, 64000):
        scene = quads_scene([[(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]])
        mesh = build_mesh(
            scene, MeshSettings(receivers=receivers, patches=1, samples=1, emitter_samples=1)
        )
        tree = build_clusters(mesh, *subarea_triangles(mesh))
        root = tree.root[0]
        point = np.array([[0.5, -1.0, 0.3]])  # about one size off the square's edge
        _, item = tree.cuts(tree.root[:1], point, 5.0)
        taken.append((len(item), tree.stop[root] - tree.start[root]))
    assert taken[-1][1] > 15 * taken[0][1]  # the sub-area's triangles grew 16-fold
    assert max(t[0] for t in taken) < 1.5 * taken[0][0] < 100, taken


def test_cluster_means_are_area_weighted_over_visible_corners(
    clustered: tuple[RadiosityMesh, Clusters],
) -> None:
    """Every node's mean (sub-areas and clusters), against a loop over its triangles:
    area x the mean of the visible corners, over the area of triangles with any."""
    mesh, tree = clustered
    rng = np.random.default_rng(13)
    visible = rng.random(mesh.receiver_count) > 0.1
    mesh = replace(mesh, receiver_visible=visible)
    radiosity = rng.random((mesh.receiver_count, 3))
    means = subarea_means(mesh)
    extended = means.extend(radiosity)
    assert extended.shape == (mesh.receiver_count + tree.count, 3)
    with pytest.raises(ValueError, match="receivers for a mesh of"):
        means.extend(radiosity[:-1])  # another mesh's radiosity: refused, not misplaced
    np.testing.assert_array_equal(extended[: mesh.receiver_count], radiosity)
    assert np.array_equal(means.patch_ptr, tree.patch_ptr)
    for n in rng.choice(tree.count, 120, replace=False):
        total, area = np.zeros(3), 0.0
        for t in tree.sub_tri[tree.start[n] : tree.stop[n]]:
            seen = [k for k in mesh.triangle_receivers[t] if visible[k]]
            if seen:
                total += mesh.triangle_area[t] * radiosity[seen].mean(axis=0)
                area += mesh.triangle_area[t]
        want = total / area if area > 0 else np.zeros(3)
        np.testing.assert_allclose(extended[mesh.receiver_count + n], want, rtol=1e-12)


@pytest.mark.skipif(compiled.get() is None, reason="numba is not installed")
def test_compiled_node_means_match_numpy(clustered: tuple[RadiosityMesh, Clusters]) -> None:
    """The compiled means loop against its numpy reference, bit for bit, with hidden
    corners and a triangle wholly hidden: the same sums in the same order."""
    mesh, tree = clustered
    rng = np.random.default_rng(14)
    visible = rng.random(mesh.receiver_count) > 0.2
    visible[mesh.triangle_receivers[tree.sub_tri[tree.start[5] : tree.stop[5]]]] = False
    mesh = replace(mesh, receiver_visible=visible)
    share = corner_shares(mesh)
    area = visible_areas(mesh, share)
    args = (tree.sub_tri, area, mesh.triangle_receivers, share, mesh.receiver_count)
    fast = node_means(tree.start, tree.stop, *args)
    slow = numpy_node_means(tree.start, tree.stop, *args)
    for got, want in zip(fast, slow, strict=True):
        np.testing.assert_array_equal(got, want)
    assert fast[0][6] == fast[0][5]  # the hidden node has no mean


def test_cluster_means_do_not_depend_on_batches_or_threads(
    clustered: tuple[RadiosityMesh, Clusters], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Means built in one batch, in many small ones on one thread and on two threads are
    the same to the bit (each node's sums are its own)."""
    mesh, _ = clustered
    monkeypatch.setenv("RAYTRAD_THREADS", "1")
    whole = subarea_means(mesh)  # one batch: the tree holds fewer than MEAN_SLOTS slots
    for threads, slots in (("1", 64), ("2", 64), ("2", 1 << 18)):
        monkeypatch.setenv("RAYTRAD_THREADS", threads)
        monkeypatch.setattr(gather, "MEAN_SLOTS", slots)
        parted = subarea_means(mesh)
        np.testing.assert_array_equal(parted.pointer, whole.pointer)
        np.testing.assert_array_equal(parted.receivers, whole.receivers)
        np.testing.assert_array_equal(parted.shares, whole.shares)


def test_trees_do_not_depend_on_where_the_scene_sits() -> None:
    """A square floor (square clusters: its axes tie) far from the origin splits as at it:
    the longest axis is chosen with ties to the first, not by rounding."""
    trees = []
    for offset in (0.0, 1.0e4):
        corners = np.array([(0, 0, 0), (1, 0, 0), (1, 0, 1), (0, 0, 1)], float) + offset
        floor = quads_scene([corners.tolist()], facing=[(0, 1, 0)])
        settings = MeshSettings(receivers=3000, patches=1, samples=1, emitter_samples=1)
        mesh = build_mesh(floor, settings)
        trees.append(build_clusters(mesh, *subarea_triangles(mesh)))
    assert trees[0].count > 100
    for name in ("sub_tri", "left", "right", "start"):
        np.testing.assert_array_equal(getattr(trees[0], name), getattr(trees[1], name))


def test_first_nearest_is_the_sorts_first() -> None:
    """Each run's nearest slot, the first on ties (distances from a handful of values),
    as a stable sort by (run, distance) puts first."""
    from raytrad.core.clusters import _first_nearest

    rng = np.random.default_rng(4)
    for _ in range(100):
        counts = rng.integers(1, 20, rng.integers(1, 40))
        owner = np.repeat(np.arange(len(counts)), counts)
        offsets = np.concatenate([[0], np.cumsum(counts)[:-1]])
        distance = rng.integers(0, 4, len(owner)) * 0.5
        expected = np.lexsort((np.arange(len(owner)), distance, owner))[offsets]
        np.testing.assert_array_equal(_first_nearest(distance, owner, offsets), expected)
