"""From a scene to a solvable problem: repair, acceleration only where something can
occlude, every column computed and balanced before the first shot (unless the run's time
budget cuts the pass short)."""

from __future__ import annotations

import dataclasses
import itertools
import logging
import time
from types import SimpleNamespace

import numpy as np
import pytest

from raytrad.core import pipeline
from raytrad.core.mesh import MeshSettings, RadiosityMesh
from raytrad.core.pipeline import RunBudget, error_samples, prepare
from raytrad.core.solver import SolveSettings, solve
from raytrad.scene import has_emission
from raytrad.scene.builtin import cornell_box, furnace_box
from tests.conftest import FURNACE_MESH


def test_a_convex_enclosure_gets_no_acceleration_and_no_rays() -> None:
    with prepare(furnace_box(), FURNACE_MESH) as prepared:
        assert prepared.occluder is None and prepared.closed_receivers is None
        assert prepared.engine.rays_cast == 0
        assert prepared.engine.columns_computed == prepared.mesh.patch_count
        assert set(prepared.timings) == {"kernels", "mesh", "acceleration", "form_factors"}


def test_an_occluding_scene_is_probed_and_balanced() -> None:
    with prepare(cornell_box(), MeshSettings(receivers=600, patches=40)) as prepared:
        assert prepared.occluder is not None
        closed = prepared.closed_receivers
        assert closed is not None and closed.shape == (prepared.mesh.receiver_count,)
        assert 0 < closed.sum() < len(closed)  # the open front of the box is seen by some
        assert prepared.balance["closed_rows"] > 0
        assert prepared.engine.rays_cast > 0


def test_the_prepared_scene_is_the_repaired_one() -> None:
    scene = furnace_box()
    doubled = scene.select(np.concatenate([np.arange(scene.triangle_count)] * 2))
    with prepare(doubled, FURNACE_MESH) as prepared:  # every face twice: one copy kept
        assert prepared.scene.triangle_count == scene.triangle_count


def test_no_emitter_warning_comes_after_repair(caplog: pytest.LogCaptureFixture) -> None:
    # the lamp's triangles, first written again as white: repair keeps the first copy of
    # a duplicate, so the lamp goes and the scene emits nothing
    scene = cornell_box()
    lamp = np.flatnonzero(scene.emitted_exitance.any(axis=1))
    white = scene.material_names.index("white")
    rows = np.concatenate([lamp, np.arange(scene.triangle_count)])
    doubled = scene.select(rows)
    material = doubled.material_index.copy()
    material[: len(lamp)] = white
    doubled = dataclasses.replace(doubled, material_index=material)
    assert has_emission(doubled)
    with caplog.at_level(logging.WARNING), prepare(doubled, MeshSettings(receivers=300)) as done:
        assert not has_emission(done.scene)
    assert "the scene has no emitter" in caplog.text


def test_a_new_engine_has_the_same_balanced_factors() -> None:
    with prepare(cornell_box(), MeshSettings(receivers=400, patches=30)) as prepared:
        fresh = prepared.new_engine()
        try:
            for patch in (0, prepared.mesh.patch_count // 2):
                a, b = prepared.engine.column(patch), fresh.column(patch)
                np.testing.assert_array_equal(a.receivers, b.receivers)
                np.testing.assert_array_equal(a.factors, b.factors)
        finally:
            fresh.close()


class _After:
    """A stop request that turns True after ``n`` polls (a time budget, deterministic)."""

    def __init__(self, n: int) -> None:
        self.n, self.polls = n, 0

    def __call__(self) -> bool:
        self.polls += 1
        return self.polls > self.n


def test_a_stop_cuts_the_form_factor_pass_short_emitters_first() -> None:
    settings = MeshSettings(receivers=600, patches=40)
    with prepare(cornell_box(), settings, stop=_After(2)) as prepared:
        engine, mesh = prepared.engine, prepared.mesh
        assert prepared.balance["complete"] is False
        # 3 columns (polled after each), none balanced; the first the lamp's
        assert engine.columns_computed == 3 < mesh.patch_count
        emits = (mesh.receiver_emitted_exitance[mesh.triangle_receivers] > 0).any(axis=(1, 2))
        lamp = set(mesh.triangle_patch[emits].tolist())
        assert lamp and set(list(engine._cache)[: min(3, len(lamp))]) <= lamp
        # the solve computes the other columns as it needs them
        result = solve(mesh, engine, SolveSettings(tolerance=1e-2))
        assert result.stop_reason == "converged"
        assert engine.columns_computed > 3


def test_a_time_limit_spent_before_the_solve_still_gives_direct_light() -> None:
    settings = MeshSettings(receivers=600, patches=40)
    with prepare(cornell_box(), settings, stop=_After(0)) as cut:
        result = solve(cut.mesh, cut.engine, SolveSettings("progressive", time_limit=1e-9))
        assert result.stop_reason == "time-limit"
        lamp_patches = result.state.shots  # every emitter shot once, nothing else
        assert np.count_nonzero(result.state.shot.any(axis=1)) == lamp_patches >= 1
    with prepare(cornell_box(), settings) as full:
        direct = solve(full.mesh, full.engine, SolveSettings("progressive", max_shots=lamp_patches))
        assert np.array_equal(direct.state.shot.any(axis=1), result.state.shot.any(axis=1))
    # the lamp's direct light, through factors not balanced: they differ by the sampling
    # error balancing corrects, under 3 % at this coarse mesh and a fraction of it typically
    lit = direct.radiosity.sum(axis=1) > 1e-3 * direct.radiosity.sum(axis=1).max()
    assert lit.mean() > 0.5
    np.testing.assert_allclose(result.radiosity[lit], direct.radiosity[lit], rtol=0.03)
    assert np.median(np.abs(result.radiosity[lit] / direct.radiosity[lit] - 1)) < 3e-3


def test_run_budget_counts_from_the_run_start() -> None:
    budget = RunBudget(10.0, start=time.perf_counter() - 4.0)
    assert not budget()
    limited = budget.solve_settings(SolveSettings(), resumed_seconds=2.0)
    assert limited.time_limit is not None and 7.0 < limited.time_limit <= 8.0
    assert RunBudget(10.0, start=time.perf_counter() - 11.0)()
    assert RunBudget(None, stop=lambda: True)()
    assert RunBudget(None).solve_settings(SolveSettings(), 0.0).time_limit is None
    # what a True poll meant, for refinement's warnings (adaptive.stop_cause)
    from raytrad.core.adaptive import stop_cause

    spent = RunBudget(10.0, stop=lambda: False, start=time.perf_counter() - 11.0)
    assert stop_cause(spent) == "time limit spent"
    assert stop_cause(RunBudget(None, stop=lambda: True)) == "interrupted"
    assert stop_cause(lambda: True) == "time limit spent or interrupted"  # a bare poll


def test_run_budget_keeps_back_the_time_to_write_the_columns() -> None:
    """A time-limited run writes every column so far after its solve: the budget keeps
    that time back while the pass's engine holds them, and gives it back once they go."""
    budget = RunBudget(10.0, start=time.perf_counter() - 4.0)  # 6 s left
    held = SimpleNamespace(held_bytes=int(3.0 * pipeline.SAVE_BYTES_PER_SECOND))  # 3 s
    budget.held(held)  # type: ignore[arg-type]
    assert 2.9 < budget.reserve() < 3.1 and not budget()
    limited = budget.solve_settings(SolveSettings(), resumed_seconds=0.0)
    assert limited.time_limit is not None and 2.0 < limited.time_limit <= 3.0
    held.held_bytes = int(7.0 * pipeline.SAVE_BYTES_PER_SECOND)  # the pass went on
    assert budget()
    held.held_bytes = 0  # saved, and dropped (a whole pass's, once the solve is done)
    assert budget.reserve() == 0.0 and not budget()
    # a real pass: the engine is held from its creation, and what it holds is its columns
    scene = cornell_box()
    settings = MeshSettings(receivers=400, patches=30)
    budget = RunBudget(1e6)
    prepared = prepare(scene, settings, stop=budget)
    try:
        assert budget.engine is prepared.engine and prepared.engine.held_bytes > 0
        assert budget.reserve() == prepared.engine.held_bytes / pipeline.SAVE_BYTES_PER_SECOND
        prepared.engine.release_columns()
        assert prepared.engine.held_bytes == 0
    finally:
        prepared.close()


def test_the_pass_promises_no_time_left_from_a_burst(
    caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Columns finish in bursts, one a thread: two finishing together used to print "about
    # 0 s left" at the start of a 541-column pass. No time is given until enough columns
    # have finished; then the rate since the first column's end.
    clock = iter([0.0, 13.0, 13.0, 20.0, 31.0])  # start, column 1, column 2, 17, 41
    monkeypatch.setattr(pipeline, "time", SimpleNamespace(perf_counter=lambda: next(clock)))
    monkeypatch.setattr(pipeline, "PASS_LOG_SECONDS", 0.0)
    report = pipeline._pass_progress()
    with caplog.at_level(logging.INFO, logger="raytrad.core.pipeline"):
        report(1, 541)
        report(2, 541)
        report(17, 541)
        report(41, 541)
    lines = [r.getMessage() for r in caplog.records]
    assert lines[0] == "form factors: 2 of 541 columns done in 13 s, time left not known yet"
    # 16 columns in 7 s after the first: 524 left take 229 s
    assert lines[1] == (
        "form factors: 17 of 541 columns done in 20 s, about 229 s left to finish the pass"
    )
    assert lines[2].endswith("about 225 s left to finish the pass")  # 40 in 18 s: 500 left


def test_the_residual_check_grows_with_the_bake_then_trades_points_for_rays() -> None:
    # a quarter of the receivers, 256 to 2048 points of 1024 rays; past twice the cap,
    # half the points with twice the rays (the error is small against a point's noise)
    assert error_samples(500) == (256, 1024)
    assert error_samples(4000) == (1000, 1024)
    assert error_samples(12000) == (2048, 1024)
    assert error_samples(26000) == (1024, 2048)
    cost = [np.prod(error_samples(r)) for r in range(1000, 60000, 500)]
    assert all(b >= a for a, b in itertools.pairwise(cost))
    # a run whose time is spent checks an eighth of the points, at least 64
    assert error_samples(26000, quick=True) == (128, 2048)
    assert error_samples(12000, quick=True) == (256, 1024)
    assert error_samples(500, quick=True) == (64, 1024)


def test_the_time_left_weighs_the_columns_done_and_left(
    caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    # the pass computes large patches first: the first 20 columns weigh 3 each, the other
    # 80 weigh 1. After 20 columns, 19 timed (weight 57) in 19 s: the 80 left weigh 80,
    # 26.7 s (a count of columns would say 80 s). After 40 (weight 77 timed in 39 s): the
    # 60 left weigh 60, 30.4 s (60 s by count)
    clock = iter([0.0, 1.0, 20.0, 40.0])
    monkeypatch.setattr(pipeline, "time", SimpleNamespace(perf_counter=lambda: next(clock)))
    monkeypatch.setattr(pipeline, "PASS_LOG_SECONDS", 0.0)
    weights = np.array([3.0] * 20 + [1.0] * 80)
    report = pipeline._pass_progress(weights)
    with caplog.at_level(logging.INFO, logger="raytrad.core.pipeline"):
        report(1, 100)
        report(20, 100)
        report(40, 100)
    lines = [r.getMessage() for r in caplog.records]
    assert lines[0].endswith("about 27 s left to finish the pass")  # 57 in 19 s: 80 left
    assert lines[1].endswith("about 30 s left to finish the pass")  # 77 in 39 s: 60 left


def test_column_weights_follow_the_triangles_in_pass_order(cornell) -> None:
    mesh, engine = cornell.mesh, cornell.engine
    order = engine.pass_order()
    weights = pipeline.column_weights(mesh, order)
    triangles = np.bincount(mesh.triangle_patch, minlength=mesh.patch_count)[order]
    assert weights.shape == (mesh.patch_count,) and (weights > 1.0).all()
    np.testing.assert_allclose(weights.mean(), 2.0)
    assert np.array_equal(np.argsort(weights, kind="stable"), np.argsort(triangles, kind="stable"))


def _light_under_a_ceiling(gap: float):
    """A 1 m room (reflectance 0.6) whose only light (0.3 m square, 20 W m-2) hangs
    ``gap`` under the ceiling, facing it."""
    from raytrad.scene.builder import quads_scene

    def quad(axis: int, at: float, lo: float = 0.0, hi: float = 1.0) -> list:
        u, v = [i for i in range(3) if i != axis]
        out = []
        for a, b in ((lo, lo), (hi, lo), (hi, hi), (lo, hi)):
            corner = [0.0, 0.0, 0.0]
            corner[axis], corner[u], corner[v] = at, a, b
            out.append(corner)
        return out

    sides = [(axis, at) for axis in range(3) for at in (0.0, 1.0)]
    inward = np.zeros((6, 3))
    inward[np.arange(6), [axis for axis, _ in sides]] = [1.0 - 2.0 * at for _, at in sides]
    light = quad(1, 1.0 - gap, 0.35, 0.65)
    return quads_scene(
        [*(quad(axis, at) for axis, at in sides), light],
        {"wall": (0.6, 0.0, False), "light": (0.0, 20.0, False)},
        ["wall"] * 6 + ["light"],
        facing=[*inward, [0.0, 1.0, 0.0]],
    )


def test_a_light_a_millimetre_under_a_ceiling_lights_no_more_than_it_can(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """No surface of reflectance 0.6 lit by emitters of 20 W m-2 can show more than 12 W
    m-2 (if the brightest non-emitter showed B > 0.6 x 20, what it gathers, at most
    max(20, B), would give it less). A light 1 mm under a ceiling, facing it, broke that:
    the receivers over it catch 70 % of what it shoots, balancing scaled its factors 87
    times to make up the rest from receivers outside the gap, and refinement's new points
    there, which take the column scales but not the row scales, came out at 729 W m-2
    (1 040 at 5 000 receivers), and the walls at 0.083 W m-2 on average. The column scale
    is now limited (balancing says so), and a new point's row is judged before it: 12.0
    and 0.029. (A path tracer finds the walls under 0.001: what is left is the ceiling
    patches' mean, bright over the light, shot from all of each patch.)"""
    from raytrad import api
    from raytrad.settings import RenderSettings

    settings = RenderSettings(mesh=MeshSettings(receivers=3000))
    with caplog.at_level(logging.WARNING, logger="raytrad"):
        prepared = api.prepare(_light_under_a_ceiling(0.001), settings)
    try:
        assert prepared.balance["short_columns"] > 0
        assert 0.2 < prepared.balance["column_deficit"] < 0.5
        assert "deliver less than they shoot, 77% of it at worst" in caplog.text
        result = api.solve(prepared, settings)
        baked, refined, _ = api.refine(prepared, result, settings)
        mesh = baked.mesh
        lit = ~(mesh.receiver_emitted_exitance > 0).any(axis=1)
        assert refined.radiosity[lit].max() <= 12.0 * (1.0 + 1e-6)
        walls = lit & (np.abs(mesh.receiver_normal[:, 1]) < 0.5)
        assert refined.radiosity[walls, 0].mean() < 0.05
        # the residual check's direct light 1 mm from the light: exact where unblocked
        # (area samples alone made it noise, and the estimate 250 %)
        parts = pipeline.total_error(prepared, baked, refined, np.zeros(3))
        assert parts.discretisation.max() < 0.3
    finally:
        prepared.close()


def test_short_patches_are_warned_of_when_they_matter() -> None:
    """A short patch that emits, or short patches of 0.1 % of the surface or more, are a
    warning; a table leg's top under its table (0.08 % of a room) is information."""
    mesh = SimpleNamespace(
        receiver_emitted_exitance=np.array([[0.0] * 3, [0.0] * 3, [0.0] * 3, [5.0] * 3]),
        triangle_receivers=np.array([[0, 1, 2], [1, 2, 3]]),
        triangle_patch=np.array([0, 1]),
        patch_count=2,
    )
    mesh.patch_emits = lambda: RadiosityMesh.patch_emits(mesh)  # type: ignore[arg-type]
    level = pipeline._short_level
    assert level(mesh, np.array([True, False]), 8e-4) == logging.INFO
    assert level(mesh, np.array([True, False]), 2e-3) == logging.WARNING
    assert level(mesh, np.array([False, True]), 1e-6) == logging.WARNING  # it emits


def test_a_percentage_is_whole_from_one_and_small_ones_keep_two_digits() -> None:
    assert [pipeline._percent(v) for v in (77.26, 1.0, 99.96, 0.00116, 0.5, 0.0)] == [
        "77",
        "1",
        "100",
        "0.0012",
        "0.5",
        "0",
    ]
