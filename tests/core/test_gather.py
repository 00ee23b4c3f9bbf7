"""The near-field gather (raytrad.core.gather) against an independent Monte Carlo gather.

The check that found the patch-average bias: a receiver on a block's side just above the
floor sees mostly the dark floor beside the block, not the mean of the floor patch it is
near. Cosine-distributed rays from the receiver that read the solution's own interpolated
radiosity where they land (raytrad.products.probe.hemisphere_gather) know nothing of
patches, form factors or gather weights.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable

import numpy as np
import pytest

from raytrad.core import compiled
from raytrad.core.gather import (
    GatherRows,
    GatherWeights,
    gathered_irradiance,
    numpy_gathered_irradiance,
    numpy_sum_shares,
)
from raytrad.core.kernels import linear_corner_shares, numpy_polygon_form_factor
from raytrad.core.pairs import receiver_points
from raytrad.core.pipeline import Prepared
from raytrad.core.solver import SolveResult, SolveSettings, solve
from raytrad.core.spread import corner_form_factors
from raytrad.products.probe import hemisphere_gather

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def test_block_base_receivers_agree_with_an_independent_gather(
    cornell_fine: tuple[Prepared, SolveResult],
) -> None:
    # Receivers on the blocks' sides in the first row above the floor (2 cm at 4000
    # receivers). Gathering patch means put them 16% too bright on average (some 40%);
    # the near-field gather must agree with the rays within a few percent.
    prepared, result = cornell_fine
    mesh, radiosity = prepared.mesh, result.radiosity
    x, normal = mesh.receiver_position, mesh.receiver_normal
    on_block = (x[:, 0] > 0.01) & (x[:, 0] < 0.54) & (x[:, 2] > 0.01) & (x[:, 2] < 0.55)
    low = (x[:, 1] > 1.5e-3) & (x[:, 1] < 0.03) & (np.abs(normal[:, 1]) < 0.1)
    visible = mesh.receiver_area > 0
    chosen = np.flatnonzero(on_block & low & visible)
    assert len(chosen) > 50
    points, _ = receiver_points(mesh, 1e-5 * prepared.engine.diagonal)
    irradiance, standard_error = hemisphere_gather(
        mesh, radiosity, points[chosen], normal[chosen], rays=16384, seed=1
    )
    gathered = (
        mesh.receiver_emitted_exitance[chosen] + mesh.receiver_reflectance[chosen] * irradiance
    )
    relative = (radiosity[chosen] @ LUMINANCE) / (gathered @ LUMINANCE) - 1.0
    noise = (mesh.receiver_reflectance[chosen] * standard_error) @ LUMINANCE
    noise /= gathered @ LUMINANCE
    assert np.median(noise) < 0.02  # the rays resolve a 5% bias
    assert abs(relative.mean()) < 0.05, relative.mean()
    assert np.percentile(np.abs(relative), 90) < 0.08


def _uniform_barycentric(rng: np.random.Generator, n: int) -> np.ndarray:
    """(n, 3) barycentric coordinates of points uniform over a triangle."""
    a, b = rng.random(n), rng.random(n)
    flip = a + b > 1
    a, b = np.where(flip, 1 - a, a), np.where(flip, 1 - b, b)
    return np.stack([1 - a - b, a, b], axis=1)


def test_corner_shares_match_a_monte_carlo_integral() -> None:
    # s_k = integral of F(x <- y) lambda_k(y) dy / F over the triangle, by sampling
    # points on it uniformly: the factor-weighted mean barycentric coordinate.
    rng = np.random.default_rng(4)
    triangle = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    cases = [
        (np.array([0.3, 0.0, 0.02]), np.array([0.0, 1.0, 0.0])),  # beside an edge
        (np.array([0.05, 0.05, 0.05]), np.array([0.0, 0.0, -1.0])),  # above a corner
        (np.array([0.3, 0.3, 2.0]), np.array([0.0, 0.0, -1.0])),  # far: about 1/3 each
    ]
    bary = _uniform_barycentric(rng, 400_000)
    y = bary @ triangle
    for point, normal in cases:
        d = y - point
        r2 = np.einsum("ij,ij->i", d, d)
        kernel = np.clip(d @ normal, 0, None) * np.abs(d[:, 2])  # cos at x, cos at y (x r^2)
        kernel /= r2**2
        expected = kernel @ bary / kernel.sum()
        shares = linear_corner_shares(triangle[None], point[None], normal[None], levels=3)[0]
        np.testing.assert_allclose(shares, expected, atol=0.015)
        # and much closer than equal shares wherever those are far off
        assert np.abs(shares - expected).max() <= max(0.2 * np.abs(expected - 1 / 3).max(), 2e-3)
        assert abs(shares.sum() - 1.0) < 1e-12


@pytest.mark.parametrize("sizes", [2.0, 3.0, 5.0])
def test_corner_form_factors_match_a_monte_carlo_integral(sizes: float) -> None:
    # A far sub-area's weight goes to its triangles' corners by what the receiver sees of
    # each corner's part: F_k = integral of F(x <- y) lambda_k(y) dy over the triangle.
    # Receivers at 2-5 triangle sizes, on a wall standing on the triangle's plane (a block
    # side above a floor) and above it: the sum against the exact factor (Lambert), each
    # share against uniform sampling of the triangle.
    rng = np.random.default_rng(11)
    triangle = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    up = np.array([0.0, 0.0, 1.0])
    bary = _uniform_barycentric(rng, 400_000)
    y = bary @ triangle
    centre = triangle.mean(axis=0)
    cases = [
        (centre + np.array([-sizes, -0.3, 0.3]), np.array([1.0, 0.0, 0.0])),  # a wall
        (centre + np.array([-sizes, sizes, 0.05]), np.array([0.7071, -0.7071, 0.0])),
        (centre + np.array([0.2, 0.1, sizes]), -up),  # a ceiling above
    ]
    for point, normal in cases:
        weights = corner_form_factors(triangle[None], up[None], point[None], normal[None])[0]
        exact = numpy_polygon_form_factor(triangle[None], point[None], normal[None])[0]
        assert exact > 0
        assert abs(weights.sum() / exact - 1.0) < 0.005 / sizes**2  # a quadrature: O(h^2)
        d = y - point
        r2 = np.einsum("ij,ij->i", d, d)
        kernel = np.clip(d @ normal, 0, None) * np.clip(-(d @ up), 0, None) / r2**2
        expected = kernel @ bary / kernel.sum()
        shares = weights / weights.sum()
        error = np.abs(shares - expected).max()
        assert error < 0.01 / sizes**2 + 0.001  # + the Monte Carlo integral's noise


def test_shots_conserve_power_in_a_closed_box(
    prepare_furnace: Callable[..., Prepared],
) -> None:
    # Near receivers gather what they see of a patch, far ones its mean; every shot must
    # still deliver exactly what it shoots in a closed box (nothing escapes), or high
    # reflectance amplifies the difference by 1 / (1 - rho).
    prepared = prepare_furnace(0.99, 1.0)
    result = solve(prepared.mesh, prepared.engine, SolveSettings(tolerance=1e-4))
    assert result.stop_reason == "converged"
    emitted = result.emitted_power
    assert (np.abs(result.state.escaped) <= 1e-9 * emitted).all()
    np.testing.assert_allclose(result.radiosity * (1 - 0.99), 1.0, rtol=2e-3)


def test_share_sums_per_pair_and_source() -> None:
    """numpy_sum_shares (the reference the compiled means and spreads are held to)
    against sums taken pair by pair."""
    rng = np.random.default_rng(11)
    pairs = 300
    pair = rng.integers(0, pairs, 20000)
    pair[:50] = 7  # one crowded pair; some pairs get nothing
    source = rng.integers(0, 500, 20000)
    source[:50] = 3  # repeated (pair, source): summed
    weight = rng.random(20000) + 1e-3
    weight[100:400] = 0.0  # left out, like negative weights
    weight[400:420] = -1.0
    fast = numpy_sum_shares(pair, source, weight, pairs)
    for p in (0, 7, 150):
        kept = (pair == p) & (weight > 0)
        np.testing.assert_array_equal(fast[1][fast[0][p] : fast[0][p + 1]], np.unique(source[kept]))
    # independent check: each pair's weights sum to 1 and carry the raw sums' proportions
    sums = np.bincount(pair, weights=np.maximum(weight, 0.0), minlength=pairs)
    got = np.add.reduceat(fast[2], fast[0][:-1][np.diff(fast[0]) > 0])
    np.testing.assert_allclose(got, 1.0, rtol=1e-12)
    k = np.flatnonzero(fast[1][fast[0][7] : fast[0][8]] == 3)[0] + fast[0][7]
    mask = (pair == 7) & (source == 3)
    assert fast[2][k] == pytest.approx(weight[mask].sum() / sums[7], rel=1e-12)


@pytest.mark.parametrize("compact", [False, True])
def test_gathered_sums_each_near_receivers_shares(compact: bool) -> None:
    """Compiled (when available) and numpy gathers against a plain loop, on empty rows,
    one crowded row and compact (int32, float32) weights as the columns keep them."""
    rng = np.random.default_rng(12)
    counts = rng.integers(0, 9, 200)
    counts[:5] = 0
    counts[7] = 400
    pointer = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    sources = rng.integers(0, 1000, pointer[-1])
    weights = rng.random(pointer[-1])
    if compact:
        sources, weights = sources.astype(np.int32), weights.astype(np.float32)
    gather = GatherWeights(np.arange(200), rng.random(200), pointer, sources, weights)
    radiosity = rng.random((1000, 3)) * 10.0
    want = np.array(
        [
            sum((float(weights[k]) * radiosity[sources[k]] for k in range(a, b)), np.zeros(3))
            for a, b in itertools.pairwise(pointer)
        ]
    )
    np.testing.assert_allclose(gather.numpy_gathered(radiosity), want, rtol=1e-14, atol=0)
    np.testing.assert_array_equal(gather.gathered(radiosity), gather.numpy_gathered(radiosity))


def test_final_gather_irradiance_sums_every_patchs_rows() -> None:
    """The compiled final gather against its numpy reference (bit for bit) and a plain
    loop: blocks with and without near-field points, points in several blocks, compact
    (int32, float32) weights as the rows keep them."""
    rng = np.random.default_rng(13)
    count, receivers, patches = 60, 400, 7
    radiosity = rng.random((receivers, 3)) * 10.0
    patch_radiosity = rng.random((patches, 3)) * 10.0
    blocks = []
    for patch in range(patches):
        near = np.sort(rng.choice(count, rng.integers(1, count), replace=False))
        factors = rng.random(len(near)) * 0.1
        local = np.sort(rng.choice(len(near), rng.integers(0, len(near) + 1), replace=False))
        if patch == 2:
            local = local[:0]  # no near field for this patch
        lengths = rng.integers(1, 6, len(local))
        pointer = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)
        sources = rng.integers(0, receivers, pointer[-1]).astype(np.int32)
        weights = rng.random(pointer[-1]).astype(np.float32)
        gather = GatherWeights(local.astype(np.int32), factors[local], pointer, sources, weights)
        blocks.append((patch, near, factors, gather))
    rows = GatherRows(count, np.zeros(count), blocks)
    got = gathered_irradiance(rows, radiosity, patch_radiosity)
    np.testing.assert_array_equal(got, numpy_gathered_irradiance(rows, radiosity, patch_radiosity))
    want = np.zeros((count, 3))
    for patch, near, factors, gather in blocks:
        for i, j in enumerate(near):
            want[j] += factors[i] * patch_radiosity[patch]
        for g, i in enumerate(gather.receivers):
            a, b = gather.pointer[g], gather.pointer[g + 1]
            seen = gather.weights[a:b].astype(np.float64) @ radiosity[gather.sources[a:b]]
            want[near[i]] += factors[i] * (seen - patch_radiosity[patch])
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)


def test_means_of_the_nodes_a_gather_reads(cornell: Prepared) -> None:
    """``SubareaMeans.extend`` over only the nodes a gather reads (as refinement's final
    gather asks, not every node of a million-receiver mesh) gives those nodes' means
    exactly as over all nodes, each an area-weighted mean checked directly here."""
    means = cornell.engine.subarea_means
    rng = np.random.default_rng(3)
    radiosity = rng.uniform(0.0, 5.0, size=(means.base, 3))
    whole = means.extend(radiosity)
    count = len(means.pointer) - 1
    nodes = np.unique(rng.integers(0, count, size=50))
    some = means.extend(radiosity, nodes)
    np.testing.assert_array_equal(some[: means.base], radiosity)
    np.testing.assert_array_equal(some[means.base + nodes], whole[means.base + nodes])
    others = np.setdiff1d(np.arange(count), nodes)
    assert not some[means.base + others].any()
    for node in nodes[:5]:
        a, b = means.pointer[node], means.pointer[node + 1]
        expected = means.shares[a:b] @ radiosity[means.receivers[a:b]]
        np.testing.assert_allclose(whole[means.base + node], expected, rtol=1e-12)


def test_subset_keeps_the_rows_asked_for_with_their_entries() -> None:
    """``GatherWeights.subset`` against a row-by-row construction: keeping every row,
    dropping only empty rows (the entries stay as they are), and dropping rows with
    entries."""
    rng = np.random.default_rng(8)
    lengths = rng.integers(0, 4, 40)
    lengths[::5] = 0
    pointer = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)
    weights = GatherWeights(
        np.arange(40) * 3,
        rng.random(40),
        pointer,
        rng.integers(0, 100, pointer[-1]),
        rng.random(pointer[-1]),
    )

    def by_rows(keep: np.ndarray) -> GatherWeights:
        rows = np.flatnonzero(keep)
        parts = [np.arange(pointer[r], pointer[r + 1]) for r in rows]
        index = np.concatenate(parts).astype(np.int64)
        return GatherWeights(
            weights.receivers[rows],
            weights.factors[rows],
            np.concatenate([[0], np.cumsum([len(p) for p in parts])]).astype(np.int64),
            weights.sources[index],
            weights.weights[index],
        )

    assert weights.subset(np.ones(40, dtype=bool)) is weights
    for keep in (lengths > 0, rng.random(40) < 0.6):
        got, want = weights.subset(keep), by_rows(keep)
        for name in ("receivers", "factors", "pointer", "sources", "weights"):
            np.testing.assert_array_equal(getattr(got, name), getattr(want, name))


@pytest.mark.skipif(compiled.get() is None, reason="numba is not installed")
def test_rows_sum_compiled_as_in_numpy(monkeypatch: pytest.MonkeyPatch) -> None:
    """A final gather's row sums, added patch by patch by the compiled loop, are numpy's
    fancy-indexed sums to the bit, and so are the balanced factors kept."""
    rng = np.random.default_rng(4)
    count = 500
    rows = []
    for kernels in (compiled.get(), None):
        monkeypatch.setattr(compiled, "get", lambda k=kernels: k)
        got = GatherRows(count, np.zeros(count), [])
        for patch in range(40):
            near = rng.permutation(count)[: rng.integers(0, count)]
            factors = rng.random(len(near))
            gather = GatherWeights(
                np.zeros(0, np.int32),
                np.zeros(0),
                np.zeros(1, np.int64),
                np.zeros(0, np.int32),
                np.zeros(0, np.float32),
            )
            got.add(patch, near, factors, gather, float(rng.uniform(0.5, 1.5)))
        rng = np.random.default_rng(4)
        rows.append(got)
    fast, slow = rows
    np.testing.assert_array_equal(fast.raw_sum, slow.raw_sum)
    np.testing.assert_array_equal(fast.row_sum, slow.row_sum)
    for (p, near, f, _), (q, near2, f2, _) in zip(fast.patches, slow.patches, strict=True):
        assert p == q
        np.testing.assert_array_equal(near, near2)
        np.testing.assert_array_equal(f, f2)
    assert fast.raw_sum.any() and not np.array_equal(fast.raw_sum, fast.row_sum)
