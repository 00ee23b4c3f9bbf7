"""Resuming a stopped solve: the fingerprint covers the loaded scene and the system
settings, so a resume after editing a file the scene is made of (an ``.mtl`` beside an
OBJ, a mesh file of a TOML scene) is refused with one line saying what changed."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

from raytrad import api
from raytrad.core.solver import SolverState
from raytrad.errors import RaytradError
from raytrad.outputs.resume import (
    difference,
    fingerprint,
    last_save,
    load_refinement,
    load_state,
    save_refinement,
    save_state,
)
from raytrad.scene.builtin import cornell_box, furnace_box
from raytrad.scenefiles import write_obj
from raytrad.settings import MeshSettings, RenderSettings
from tests.conftest import SCENES, run_cli

SETTINGS = RenderSettings(mesh=MeshSettings(receivers=600, patches=40))
SMALL = ["--receivers", "600", "--patches", "40", "-q"]


def _stopped_render(scene: Path, out: Path, shots: int = 5) -> Path:
    """Render ``scene`` into ``out``, stopped after ``shots`` shots; the checkpoint."""
    polls = itertools.count()
    outcome = api.render(scene, out, SETTINGS, stop=lambda: next(polls) >= shots)
    assert outcome.result.stop_reason == "interrupted"
    return outcome.outputs["checkpoint"]


def _resume(scene: Path, out: Path, capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    status, _, err = run_cli(["render", str(scene), "-o", str(out), *SMALL, "--resume"], capsys)
    return status, err


def _state(seed: int) -> SolverState:
    rng = np.random.default_rng(seed)
    return SolverState(
        irradiance=rng.random((7, 3)),
        patch_radiosity=rng.random((3, 3)),
        shot=rng.random((3, 3)),
        captured=np.array([0.5, np.nan, 1.0]),
        shots=11,
        rays=1234,
        seconds=2.5,
        absorbed=rng.random(3),
        escaped=rng.random(3),
        ambient_gain=0.25,
        min_unshot=0.125,
        damping_events=2,
    )


def test_state_round_trips_bit_for_bit(tmp_path: Path) -> None:
    key = fingerprint(furnace_box(), SETTINGS.system_settings())
    state = _state(1)
    save_state(tmp_path / "a.npz", state, key)
    back = load_state(tmp_path / "a.npz", key)
    for name in SolverState.ARRAYS:
        np.testing.assert_array_equal(getattr(back, name), getattr(state, name))
    for name in SolverState.SCALARS:
        assert getattr(back, name) == getattr(state, name)


def test_edited_mtl_is_refused_naming_the_material(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scene = tmp_path / "cornell.obj"
    write_obj(cornell_box(), scene)
    out = tmp_path / "out"
    checkpoint = _stopped_render(scene, out)
    mtl = scene.with_suffix(".mtl")
    text = mtl.read_text()
    assert "Kd 0.63 0.065 0.05" in text
    mtl.write_text(text.replace("Kd 0.63 0.065 0.05", "Kd 0.5 0.065 0.05"))  # red wall
    status, err = _resume(scene, out, capsys)
    assert status == 1
    assert len(err.strip().splitlines()) == 1
    assert "material 'red' changed" in err and str(checkpoint) in err
    assert checkpoint.is_file()  # refused: nothing touched


def test_edited_toml_mesh_file_is_refused_naming_the_mesh(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    write_obj(furnace_box(0.5, 1.0), tmp_path / "box.obj")
    scene = tmp_path / "room.toml"
    scene.write_text('[[mesh]]\nfile = "box.obj"\nname = "room"\n')
    out = tmp_path / "out"
    _stopped_render(scene, out)
    obj = tmp_path / "box.obj"
    obj.write_text(obj.read_text().replace("v 1.0 1.0 1.0", "v 1.0 1.25 1.0"))
    status, err = _resume(scene, out, capsys)
    assert status == 1 and len(err.strip().splitlines()) == 1
    assert "mesh 'room' changed" in err


def test_unchanged_files_resume(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scene = tmp_path / "cornell.obj"
    write_obj(cornell_box(), scene)
    out = tmp_path / "out"
    checkpoint = _stopped_render(scene, out)
    scene.touch()  # a new modification time and the same content resume fine
    status, err = _resume(scene, out, capsys)
    assert status == 0, err
    assert not checkpoint.exists()


def test_scale_change_is_named(tmp_path: Path) -> None:
    key = fingerprint(furnace_box(), SETTINGS.system_settings())
    scaled = RenderSettings(mesh=SETTINGS.mesh, scale=0.5)
    other = fingerprint(furnace_box(), scaled.system_settings())
    assert difference(key, other) == "setting scale changed (1.0 -> 0.5)"
    save_state(tmp_path / "a.npz", _state(2), key)
    with pytest.raises(RaytradError, match=r"setting scale changed \(1.0 -> 0.5\)"):
        load_state(tmp_path / "a.npz", other)


@pytest.mark.parametrize(
    ("edit", "expected"),
    [
        ("receivers", "setting mesh.receivers changed (600 -> 700)"),
        ("object", "the scene gained material 'white'"),
        ("same", ""),
    ],
)
def test_difference_names_the_first_change(edit: str, expected: str) -> None:
    scene = furnace_box()
    key = fingerprint(scene, SETTINGS.system_settings())
    settings = SETTINGS
    if edit == "receivers":
        settings = RenderSettings(mesh=MeshSettings(receivers=700, patches=40))
    if edit == "object":
        scene = cornell_box()
    assert difference(key, fingerprint(scene, settings.system_settings())).startswith(expected)


def test_checkpoint_of_an_old_layout_is_refused(tmp_path: Path) -> None:
    from raytrad.formats.checkpoint import write_checkpoint

    arrays, scalars = _state(3).to_record()
    write_checkpoint(tmp_path / "old.npz", arrays, {"fingerprint": "0123abcd", "scalars": scalars})
    key = fingerprint(furnace_box(), SETTINGS.system_settings())
    with pytest.raises(RaytradError, match="format is unknown"):
        load_state(tmp_path / "old.npz", key)


def test_columns_of_a_cut_pass_round_trip(tmp_path: Path) -> None:
    from raytrad.core.pipeline import prepare
    from raytrad.formats.checkpoint import StoredArray
    from raytrad.outputs.resume import load_pass_columns, resume_point

    polls = itertools.count()
    with prepare(cornell_box(), SETTINGS.mesh, stop=lambda: next(polls) >= 4) as cut:
        packed = cut.engine.pass_columns()
        saved = {p: cut.engine._cache[p] for p in packed["patch"].tolist()}
        streamed = list(cut.engine.pass_column_parts())
    assert len(saved) == 5 and len(streamed) == 5
    key = fingerprint(cornell_box(), SETTINGS.system_settings())
    path = tmp_path / "c.npz"
    # a column at a time through a spool on disk: the same arrays as packed at once
    save_state(path, _state(2), key, iter(streamed))
    columns = load_pass_columns(path)
    assert set(columns) == set(packed)
    # the columns' arrays stay on disk, restored a column at a time (a whole pass at a
    # million receivers is gigabytes); the per-column lengths are read whole
    assert isinstance(columns["sources"], StoredArray)
    assert isinstance(columns["length"], np.ndarray)
    for name, values in packed.items():
        assert columns[name].dtype == values.dtype, name
        np.testing.assert_array_equal(columns[name], values)
    state, resumed, history, scales = resume_point(path, key)
    assert (
        state is None and resumed is not None and history is None and scales is None
    )  # shots through unbalanced factors: redone
    with prepare(cornell_box(), SETTINGS.mesh, stop=lambda: True, columns=columns) as again:
        # stopped at once: the 5 restored columns, none traced again
        assert again.engine.columns_computed == len(saved) and again.engine.rays_cast == 0
        for patch, col in saved.items():
            back = again.engine._cache[patch]
            np.testing.assert_array_equal(back.receivers, col.receivers)
            np.testing.assert_array_equal(back.factors, col.factors)
            for name in ("receivers", "factors", "pointer", "sources", "weights"):
                np.testing.assert_array_equal(getattr(back.gather, name), getattr(col.gather, name))
    # a damaged archive is refused with one line naming the file
    columns["receivers"] = columns["receivers"][:-1]
    save_state(path, _state(2), key, columns)
    with pytest.raises(RaytradError, match=r"c\.npz: cannot read checkpoint"):
        resume_point(path, key)


def test_a_finished_pass_resumes_from_its_balanced_scales(tmp_path: Path) -> None:
    """A checkpoint saved after the pass keeps its balanced scales (a few arrays the size of
    the receivers, not the columns): an engine restored from them traces no pass, and the
    columns it computes when asked are the balanced engine's to the bit. Scales of another
    size, or some missing, are refused with one line naming the file."""
    from raytrad.core.pipeline import prepare
    from raytrad.outputs.resume import SavedScales, resume_point, save_run

    key = fingerprint(cornell_box(), SETTINGS.system_settings())
    path = tmp_path / "s.npz"
    with prepare(cornell_box(), SETTINGS.mesh) as full:
        count = full.mesh.receiver_count
        state = api.solve(full, SETTINGS).state
        full.engine.release_columns()
        save_run(path, state, key, full.engine, balance=lambda: full.balance)
        want = [full.engine.column(p).factors for p in (0, 7, 23)]
        closed, sums = full.engine.closed_rows, full.engine.row_sums()
    back, columns, _, scales = resume_point(path, key)
    assert back is not None and back.shots == state.shots and columns is None
    assert scales is not None and scales.summary == full.balance
    assert scales.scales["row_scale"].shape == (count,)
    with prepare(cornell_box(), SETTINGS.mesh, balanced=scales) as again:
        engine = again.engine
        assert engine.columns_computed == 0 and engine.rays_cast == 0 and engine.complete
        assert again.balance == full.balance
        np.testing.assert_array_equal(engine.closed_rows, closed)
        np.testing.assert_array_equal(engine.row_sums(), sums)
        for p, factors in zip((0, 7, 23), want, strict=True):
            np.testing.assert_array_equal(engine.column(p).factors, factors)
    short = {**scales.scales, "row_scale": scales.scales["row_scale"][:-1]}
    save_state(path, state, key, scales=SavedScales(short, scales.summary))
    with pytest.raises(RaytradError, match=r"s\.npz: cannot read checkpoint \(its balanced"):
        resume_point(path, key)
    missing = {k: v for k, v in scales.scales.items() if k != "column_scale"}
    save_state(path, state, key, scales=SavedScales(missing, scales.summary))
    with pytest.raises(RaytradError, match="balanced scales are incomplete"):
        resume_point(path, key)
    assert resume_point(path, key, "auto") == (None, None, None, None)
    assert resume_point(path, key, False) == (None, None, None, None)


def test_a_converged_solves_columns_are_read_back_only_if_it_must_shoot(
    tmp_path: Path,
) -> None:
    """A solve's checkpoint with every column and the scales (as a time-limited run saves
    it): resumed at the tolerance it reached, its columns are not read back (refinement
    needs only the scales); resumed with a tighter one, they are, for the shots to come."""
    from raytrad.core.convergence import ConvergenceMonitor
    from raytrad.core.pipeline import prepare
    from raytrad.core.solver import SolveSettings, solve
    from raytrad.outputs.resume import resume_point, save_run

    key = fingerprint(cornell_box(), SETTINGS.system_settings())
    path = tmp_path / "w.npz"
    with prepare(cornell_box(), SETTINGS.mesh) as full:
        monitor = ConvergenceMonitor(full.mesh, full.engine)
        result = solve(full.mesh, full.engine, SETTINGS.solve, progress=monitor)
        monitor.finish(result.state)
        save_run(path, result.state, key, full.engine, True, [monitor.log], lambda: full.balance)
    assert result.stop_reason == "converged"
    reached = resume_point(path, key, True, SETTINGS.solve)
    assert reached.state is not None and reached.scales is not None
    assert reached.columns is None
    tighter = resume_point(path, key, True, SolveSettings(tolerance=1e-5))
    assert tighter.scales is not None and tighter.columns is not None
    assert len(tighter.columns["patch"]) == result.state.shot.shape[0]


def test_checkpoints_are_written_every_interval(tmp_path: Path) -> None:
    """--checkpoint-every: with a tiny interval the checkpoint exists during the solve (a
    crash then loses at most that much work); a converged run removes it at the end."""
    seen: list[bool] = []
    checkpoint = tmp_path / "furnace.checkpoint.npz"
    settings = RenderSettings(mesh=MeshSettings(receivers=400, patches=40), checkpoint_seconds=1e-6)
    outcome = api.render(
        SCENES / "furnace.obj",
        tmp_path,
        settings,
        progress=lambda report: seen.append(checkpoint.is_file()),
    )
    assert outcome.result.stop_reason == "converged"
    assert len(seen) > 2 and all(seen[1:])  # saved after every shot from the first on
    assert not checkpoint.exists()


def test_a_crash_in_the_solve_resumes_through_a_pass(tmp_path: Path) -> None:
    """A run that dies in its solve (no chance to save) leaves its last periodic
    checkpoint: the state alone, no columns and no scales, since the resume's shots need
    nearly every column and a pass computes them on every core. The resume traces the
    pass and goes on shooting, to the uninterrupted bake to the bit."""
    from raytrad.formats.ply import read_radiosity_ply

    scene = SCENES / "cornell-box.obj"
    settings = RenderSettings(mesh=MeshSettings(receivers=800, patches=60), checkpoint_seconds=1e-6)
    straight = api.render(scene, tmp_path / "straight", settings)
    out = tmp_path / "crashed"

    def crash(report: object) -> None:
        if getattr(report, "shots", 0) >= 40:
            raise KeyboardInterrupt  # as a kill would end the process: nothing saved after

    with pytest.raises(KeyboardInterrupt):
        api.render(scene, out, settings, progress=crash)
    again = api.render(scene, out, settings, resume=True)
    taken = again.report["resumed"]
    assert not taken["form_factor_scales"] and taken["form_factor_columns"] == 0
    assert 0 < taken["shots"] < straight.result.state.shots
    assert again.result.state.shots == straight.result.state.shots
    assert again.report["solve"]["form_factor_columns"] == again.prepared.mesh.patch_count
    _, _, got = read_radiosity_ply(out / "cornell-box.ply")
    _, _, want = read_radiosity_ply(tmp_path / "straight" / "cornell-box.ply")
    np.testing.assert_array_equal(got, want)


def test_checkpoint_of_the_layout_before_the_cluster_trees_is_refused(tmp_path: Path) -> None:
    """Layout 3 named sub-areas where layout 4 names cluster-tree nodes as gather
    sources: its pass columns would gather from the wrong means, so it is refused."""
    key = fingerprint(furnace_box(), SETTINGS.system_settings())
    old = {**key, "layout": 3}
    save_state(tmp_path / "old.npz", _state(3), old)
    with pytest.raises(RaytradError, match="layout changed"):
        load_state(tmp_path / "old.npz", key)


def test_the_error_log_round_trips_with_the_state(tmp_path: Path) -> None:
    """The solve's error log goes into the checkpoint with its state and comes back as it
    was, infinite estimates included (JSON null); a damaged log is passed over with a
    warning, the state still resumed."""
    from raytrad.core.convergence import ErrorLog
    from raytrad.outputs.resume import resume_point

    key = fingerprint(furnace_box(), SETTINGS.system_settings())
    history = ErrorLog(
        seconds=[0.0, 0.5],
        shots=[0, 11],
        rays=[0, 1234],
        residual=[1.0, 0.25],
        estimate=[[np.inf] * 3, [0.5, 0.25, 0.125]],
        bound_rms=[[np.inf] * 3, [1.0, 0.5, 0.25]],
        bound_max=[[np.inf] * 3, [2.0, 1.0, 0.5]],
    )
    path = tmp_path / "a.npz"
    save_state(path, _state(1), key, history=history)
    state, columns, back, scales = resume_point(path, key)
    assert state is not None and state.shots == 11 and columns is None and scales is None
    assert back == history
    save_state(path, _state(1), key)  # a checkpoint without a log
    assert resume_point(path, key)[2] is None
    broken = ErrorLog(**{**history.__dict__, "residual": [1.0]})  # a column short
    save_state(path, _state(1), key, history=broken)
    state, _, back, _ = resume_point(path, key)
    assert state is not None and back is None


def test_the_rounds_of_a_cut_refinement_round_trip(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """The mesh, radiosity and what the next round reads come back to the bit, for the
    same system and solve only (another solve's rounds are passed over with a warning)."""
    from raytrad.core.adaptive import Refinement, RefineSettings
    from raytrad.core.mesh import build_mesh

    mesh = build_mesh(cornell_box(), SETTINGS.mesh)
    rng = np.random.default_rng(2)
    changes = [(rng.random((5, 3)), rng.random(5)), (rng.random((2, 3)), rng.random(2))]
    done = Refinement(
        mesh,
        rng.random((mesh.receiver_count, 3)),
        settings=RefineSettings(threshold=0.05, rounds=4),
        added=7,
        rounds=2,
        rays=123,
        rays_naive=456,
        found=rng.random(mesh.receiver_count),
        changes=changes,
    )
    path = tmp_path / "scene.refinement.npz"
    key = fingerprint(cornell_box(), SETTINGS.system_settings())
    save_refinement(path, Refinement(mesh, done.radiosity, resumable=done), key, "solve-a")
    back = load_refinement(path, key, "solve-a")
    assert back is not None
    assert (back.added, back.rounds, back.rays, back.rays_naive) == (7, 2, 123, 456)
    assert back.settings == done.settings
    np.testing.assert_array_equal(back.radiosity, done.radiosity)
    np.testing.assert_array_equal(back.found, done.found)
    for (a, b), (c, d) in zip(back.changes, changes, strict=True):
        np.testing.assert_array_equal(a, c)
        np.testing.assert_array_equal(b, d)
    for name, value in vars(mesh).items():
        if value is None:
            assert getattr(back.mesh, name) is None
        else:
            np.testing.assert_array_equal(getattr(back.mesh, name), value)
            assert getattr(back.mesh, name).dtype == value.dtype
    assert load_refinement(path, key, "solve-b") is None
    assert "made for another solve" in caplog.text
    path.write_bytes(b"not a checkpoint")
    assert load_refinement(path, key, "solve-a") is None


def test_a_resumed_run_plans_its_save_at_the_rate_the_last_one_took(tmp_path: Path) -> None:
    """``last_save``: the checkpoint's size and the ``timings_seconds.checkpoint`` of the
    report written after it; nothing from a report older than the checkpoint, a missing
    or a damaged one."""
    import json
    import os

    checkpoint = tmp_path / "scene.checkpoint.npz"
    checkpoint.write_bytes(b"x" * 1000)
    report = tmp_path / "report.json"
    assert last_save(checkpoint) == (0, 0.0)  # no report
    report.write_text(json.dumps({"timings_seconds": {"checkpoint": 2.5}}))
    os.utime(checkpoint, (1e9, 1e9))
    assert last_save(checkpoint) == (1000, 2.5)
    os.utime(checkpoint, (4e9, 4e9))  # written after the report: another run's report
    assert last_save(checkpoint) == (0, 0.0)
    os.utime(checkpoint, (1e9, 1e9))
    for text in ("{", json.dumps({"timings_seconds": {}}), json.dumps([1])):
        report.write_text(text)
        assert last_save(checkpoint) == (0, 0.0)
