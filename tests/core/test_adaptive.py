"""Adaptive refinement (raytrad.core.adaptive): conforming splits, budgets, and where it
refines."""

from __future__ import annotations

import itertools
from collections.abc import Callable

import numpy as np
import pytest

from raytrad.arrays import longest_side
from raytrad.constants import tol
from raytrad.core.adaptive import (
    FOUND_SHARE,
    Refinement,
    RefineSettings,
    _to_split,
    final_gather,
    longest_sides,
    patch_means,
    refine_adaptively,
    subdivide,
)
from raytrad.core.formfactor import FormFactorEngine
from raytrad.core.pairs import receiver_points
from raytrad.core.pipeline import Prepared
from raytrad.core.solver import SolveResult, SolveSettings, solve


def _refine(prepared: Prepared, result: SolveResult, settings: RefineSettings) -> Refinement:
    """Adaptive refinement of ``result`` on the prepared scene's own mesh and engine."""
    return refine_adaptively(
        prepared.scene,
        prepared.mesh,
        prepared.engine,
        prepared.occluder,
        result.radiosity,
        settings,
    )


def _open_edge_length(positions: np.ndarray, triangles: np.ndarray) -> float:
    """Total length of the edges used by one triangle only [m]."""
    edges = np.sort(triangles[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    once = unique[counts == 1]
    return float(np.linalg.norm(positions[once[:, 0]] - positions[once[:, 1]], axis=1).sum())


def test_subdivision_is_conforming_and_keeps_receivers(
    cornell_fine: tuple[Prepared, SolveResult],
) -> None:
    # A T-junction leaves a long edge on one side and two short ones on the other, all
    # used once: the open edge length (the surfaces' outlines) would grow.
    prepared, _ = cornell_fine
    mesh = prepared.mesh
    split = np.zeros(len(mesh.triangles), dtype=bool)
    split[np.random.default_rng(0).choice(len(split), len(split) // 10, replace=False)] = True
    refined, parent = subdivide(mesh, split)
    assert refined.receiver_count > mesh.receiver_count
    np.testing.assert_array_equal(
        refined.receiver_position[: mesh.receiver_count], mesh.receiver_position
    )
    np.testing.assert_allclose(refined.triangle_area.sum(), mesh.triangle_area.sum(), rtol=1e-12)
    np.testing.assert_allclose(
        np.bincount(parent, weights=refined.triangle_area, minlength=len(mesh.triangles)),
        mesh.triangle_area,
        rtol=1e-9,
    )
    np.testing.assert_allclose(
        _open_edge_length(refined.positions, refined.triangles),
        _open_edge_length(mesh.positions, mesh.triangles),
        rtol=1e-9,
    )


def test_longest_sides_carried_through_rounds_are_measured_ones(
    cornell_fine: tuple[Prepared, SolveResult],
) -> None:
    """The sides a round carries over from the mesh before (triangles with their parent's
    corners) are those measured afresh, to the bit, over three subdivisions."""
    prepared, _ = cornell_fine
    mesh, rng = prepared.mesh, np.random.default_rng(3)
    longest = longest_side(mesh.positions[mesh.triangles])
    for _ in range(3):
        split = rng.random(len(mesh.triangles)) < 0.1
        refined, parent = subdivide(mesh, split, longest)
        carried = longest_sides(refined, (mesh.triangles, longest, parent))
        kept = (refined.triangles == mesh.triangles[parent]).all(axis=1)
        assert 0 < kept.sum() < len(kept)
        np.testing.assert_array_equal(carried, longest_side(refined.positions[refined.triangles]))
        mesh, longest = refined, carried


def test_refined_engine_gathers_as_a_fresh_one(
    cornell_fine: tuple[Prepared, SolveResult],
) -> None:
    """The refined engine carries patch outlines, corner sets and facet tables over from
    its parent; a new engine built from scratch on the refined mesh must agree."""
    prepared, _ = cornell_fine
    mesh = prepared.mesh
    split = np.zeros(len(mesh.triangles), dtype=bool)
    split[np.random.default_rng(1).choice(len(split), len(split) // 8, replace=False)] = True
    refined, _ = subdivide(mesh, split)
    new = np.arange(mesh.receiver_count, refined.receiver_count)
    points, normals = refined.receiver_position[new], refined.receiver_normal[new]
    carried = prepared.engine.refined(refined)
    fresh = FormFactorEngine(refined, prepared.occluder, cache_bytes=0)
    try:
        a, b = carried.gather_rows(points, normals), fresh.gather_rows(points, normals)
    finally:
        carried.close()
        fresh.close()
    assert carried.rays_cast == fresh.rays_cast > 0
    for (pa, na, fa, ga), (pb, nb, fb, gb) in zip(a.patches, b.patches, strict=True):
        assert pa == pb
        np.testing.assert_array_equal(na, nb)
        # b has no balanced column scales: compare the raw factors (the patch outline may
        # be summed from another starting edge: rounding of the largest factor)
        raw = fa / prepared.engine._col_scale[pa]
        np.testing.assert_allclose(raw, fb, rtol=1e-12, atol=1e-14 * fb.max(initial=0.0))
        np.testing.assert_array_equal(ga.sources, gb.sources)
        np.testing.assert_allclose(ga.weights, gb.weights, rtol=1e-12, atol=1e-15)


def _final_gather(
    solved: tuple[Prepared, SolveResult],
    points: np.ndarray,
    normals: np.ndarray,
    reflectance: np.ndarray,
    emitted: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, int]:
    """:func:`final_gather` at points of the solved Cornell box: their radiosity, which
    are shut in, and the visibility rays the gather cast."""
    prepared, result = solved
    before = prepared.engine.rays_cast
    out, shut = final_gather(
        prepared.scene,
        prepared.engine,
        prepared.occluder,
        result.radiosity,
        patch_means(prepared.mesh, result.radiosity),
        points,
        normals,
        reflectance,
        emitted,
    )
    return out, shut, prepared.engine.rays_cast - before


def test_black_points_show_their_emission_without_rays(
    cornell_fine: tuple[Prepared, SolveResult],
) -> None:
    """A point of zero reflectance gathers nothing (B = E): no factor, no ray; the other
    points gather exactly what they gather without it."""
    mesh, engine = cornell_fine[0].mesh, cornell_fine[0].engine
    rng = np.random.default_rng(4)
    pick = rng.choice(mesh.receiver_count, 300, replace=False)
    points, _ = receiver_points(mesh, 1e-6 * engine.diagonal)
    x, n = points[pick], mesh.receiver_normal[pick]
    rho = mesh.receiver_reflectance[pick].copy()
    emitted = mesh.receiver_emitted_exitance[pick].copy()
    black = np.arange(len(pick)) % 3 == 0
    rho[black] = 0.0
    emitted[black] = rng.uniform(0.0, 5.0, (int(black.sum()), 3))

    def gathered(keep: np.ndarray) -> tuple[np.ndarray, int]:
        out, _, rays = _final_gather(cornell_fine, x[keep], n[keep], rho[keep], emitted[keep])
        return out, rays

    every, every_rays = gathered(np.ones(len(pick), dtype=bool))
    lit, lit_rays = gathered(~black)
    assert every_rays == lit_rays > 0
    np.testing.assert_array_equal(every[black], emitted[black])
    np.testing.assert_array_equal(every[~black], lit)
    assert (lit[mesh.receiver_area[pick][~black] > 0] > 0).all()  # not hidden: lit


def test_shut_in_points_show_their_emission_without_rays(
    cornell_fine: tuple[Prepared, SolveResult],
) -> None:
    """A point shut in (the floor under a block, found by its probe rays) keeps its
    emission: it casts no visibility ray and gets no factor, and the other points gather
    exactly what they gather without it."""
    mesh, engine = cornell_fine[0].mesh, cornell_fine[0].engine
    hidden = np.flatnonzero(mesh.receiver_area == 0)
    seen = np.flatnonzero(mesh.receiver_area > 0)
    assert len(hidden) >= 20
    rng = np.random.default_rng(5)
    pick = np.concatenate([rng.choice(hidden, 20, replace=False), rng.choice(seen, 100)])
    points, _ = receiver_points(mesh, tol.ray_offset * engine.diagonal)
    emitted = rng.uniform(0.0, 5.0, (len(pick), 3))

    def gathered(keep: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
        return _final_gather(
            cornell_fine,
            points[pick][keep],
            mesh.receiver_normal[pick][keep],
            mesh.receiver_reflectance[pick][keep],
            emitted[keep],
        )

    every, shut, every_rays = gathered(np.ones(len(pick), dtype=bool))
    assert shut[:20].all() and not shut[20:].any()
    open_only, _, open_rays = gathered(~shut)
    assert every_rays == open_rays > 0
    np.testing.assert_array_equal(every[shut], emitted[shut])
    np.testing.assert_array_equal(every[~shut], open_only)


def test_a_stop_within_a_round_keeps_the_look_of_the_round_before(
    cornell_fine: tuple[Prepared, SolveResult],
) -> None:
    """A time limit spent during a round's gather (polled after each patch) ends
    refinement there, without waiting for the round: its new receivers show what the mesh
    before showed at their places, read here by probing that mesh."""
    from raytrad.products.probe import radiosity_at

    prepared, result = cornell_fine
    polls = itertools.count()
    out = refine_adaptively(
        prepared.scene,
        prepared.mesh,
        prepared.engine,
        prepared.occluder,
        result.radiosity,
        RefineSettings(),
        stop=lambda: next(polls) >= 40,  # the first poll is before the round
    )
    assert out.stopped and out.rounds == 0 and out.added > 0
    assert out.interpolated == out.added == out.mesh.receiver_count - prepared.mesh.receiver_count
    assert 40 < next(polls) < prepared.mesh.patch_count  # polled patch by patch
    old = prepared.mesh.receiver_count
    # the centres of the new triangles (a new corner, every corner seen) as each mesh shows
    # them: the refined one by its corners' mean, the one before probed
    corners = out.mesh.triangle_receivers
    seen = np.asarray(out.mesh.receiver_visible)[corners].all(axis=1)
    pick = np.flatnonzero((corners >= old).any(axis=1) & seen & (out.mesh.triangle_area > 0))
    assert len(pick) > 100
    centre = out.mesh.positions[out.mesh.triangles[pick]].mean(axis=1)
    shown = radiosity_at(prepared.mesh, result.radiosity, centre, out.mesh.triangle_normal[pick])
    probed = ~np.isnan(shown).any(axis=1)
    assert probed.mean() > 0.99
    got = out.radiosity[corners[pick]].mean(axis=1)
    np.testing.assert_allclose(got[probed], shown[probed], rtol=1e-4, atol=1e-9)
    np.testing.assert_array_equal(out.radiosity[:old], result.radiosity)


def test_uniform_light_needs_no_refinement(prepare_furnace: Callable[..., Prepared]) -> None:
    prepared = prepare_furnace(0.5, 1.0)
    result = solve(prepared.mesh, prepared.engine, SolveSettings())
    out = _refine(prepared, result, RefineSettings())
    assert out.added == 0 and out.mesh is prepared.mesh


def test_refinement_goes_to_shadow_edges_within_budget(
    cornell_fine: tuple[Prepared, SolveResult],
) -> None:
    prepared, result = cornell_fine
    mesh = prepared.mesh
    budget = mesh.receiver_count + 1500
    out = _refine(prepared, result, RefineSettings(max_receivers=budget))
    assert 0 < out.added <= 1500 and out.mesh.receiver_count == mesh.receiver_count + out.added
    assert sum(out.by_object.values()) <= out.added
    assert np.isfinite(out.radiosity).all() and (out.radiosity >= 0).all()
    # new receivers sit where the solve's radiosity changes fast: the floor around the
    # blocks, not the middle of the back wall
    new = out.mesh.receiver_position[mesh.receiver_count :]
    floor = new[:, 1] < 1e-6
    assert floor.mean() > 0.3
    back_middle = (
        (new[:, 2] > 0.558) & (np.abs(new[:, 0] - 0.28) < 0.1) & (np.abs(new[:, 1] - 0.27) < 0.1)
    )
    assert back_middle.mean() < 0.02
    # the old receivers keep the solve's radiosity
    np.testing.assert_array_equal(out.radiosity[: mesh.receiver_count], result.radiosity)


@pytest.mark.parametrize("extra", [1, 40])
def test_the_receiver_budget_is_never_exceeded(
    cornell_fine: tuple[Prepared, SolveResult], extra: int
) -> None:
    prepared, result = cornell_fine
    budget = prepared.mesh.receiver_count + extra
    out = _refine(prepared, result, RefineSettings(max_receivers=budget))
    assert out.mesh.receiver_count <= budget  # a split's closure splits neighbours too


def test_a_budget_below_the_solved_receivers_says_so(
    cornell_fine: tuple[Prepared, SolveResult], caplog: pytest.LogCaptureFixture
) -> None:
    prepared, result = cornell_fine
    out = _refine(prepared, result, RefineSettings(max_receivers=prepared.mesh.receiver_count - 10))
    assert out.added == 0 and "no refinement: the receiver budget" in caplog.text


def test_a_corner_found_wrong_is_split_though_its_corners_agree(
    prepare_furnace: Callable[..., Prepared],
) -> None:
    # Uniform radiosity: no triangle's corners spread. A receiver whose last gather
    # differed from the interpolation by 0.6 % (above FOUND_SHARE x the threshold, 0.3 %)
    # has its triangles split; one found 0.15 % off does not.
    mesh = prepare_furnace(0.5, 1.0).mesh
    radiosity = np.full((mesh.receiver_count, 3), 2.0)
    settings = RefineSettings()
    assert settings.threshold * FOUND_SHARE == pytest.approx(0.003)
    room = mesh.receiver_count
    assert len(_to_split(mesh, radiosity, settings, 0.0, room)) == 0
    for change, expected in ((0.006, True), (0.0015, False)):
        found = np.zeros(mesh.receiver_count)
        found[7] = change
        split = _to_split(mesh, radiosity, settings, 0.0, room, found)
        around = np.flatnonzero((mesh.triangle_receivers == 7).any(axis=1))
        assert bool(len(split)) is expected
        if expected:
            assert set(split.tolist()) == set(around.tolist())


def test_a_short_budget_weighs_relative_and_absolute_spread(
    prepare_furnace: Callable[..., Prepared],
) -> None:
    # One wall dark (0.02), the others at 2. A receiver on the dark wall at 0.10 spreads
    # its triangles by about their floored mean (0.05 x the scene's level), in absolute
    # terms 0.05 of the level; one on a bright wall at 2.6 spreads its triangles by about
    # a quarter of their mean, a third of the level. The dark spot spreads four times
    # more relatively, the bright one six times more absolutely: area x relative x
    # absolute spread puts the bright one first (ranking by relative spread alone would
    # not), so with room for one triangle, one of the bright receiver's is split.
    mesh = prepare_furnace(0.5, 1.0).mesh
    radiosity = np.full((mesh.receiver_count, 3), 2.0)
    normals = mesh.receiver_normal
    dark_wall = np.abs(normals @ normals[0] - 1.0) < 1e-9
    radiosity[dark_wall] = 0.02
    dark = int(np.flatnonzero(dark_wall)[len(np.flatnonzero(dark_wall)) // 2])
    bright = int(np.flatnonzero(~dark_wall)[len(np.flatnonzero(~dark_wall)) // 2])
    radiosity[dark], radiosity[bright] = 0.10, 2.6
    settings = RefineSettings()
    # both are candidates, the dark one with the larger relative spread
    only = {}
    for receiver in (dark, bright):
        around = (mesh.triangle_receivers == receiver).any(axis=1)
        only[receiver] = set(np.flatnonzero(around).tolist())
    everything = _to_split(mesh, radiosity, settings, 0.0, mesh.receiver_count)
    assert only[dark] <= set(everything.tolist()) and only[bright] <= set(everything.tolist())
    split = _to_split(mesh, radiosity, settings, 0.0, 2)
    assert len(split) == 1
    assert int(split[0]) in only[bright]
