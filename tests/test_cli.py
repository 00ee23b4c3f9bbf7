"""The command line and the render API: outputs, one-line errors, exit status, resuming."""

from __future__ import annotations

import dataclasses
import itertools
import json
import logging
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from raytrad import api
from raytrad.cli import _print_summary
from raytrad.core.adaptive import RefineSettings
from raytrad.core.mesh import MeshSettings
from raytrad.core.pipeline import error_samples
from raytrad.core.solver import SHOOTING_METHODS, SolveSettings
from raytrad.formats.ply import read_radiosity_ply
from raytrad.outputs import resume as resuming
from raytrad.scene.builtin import cornell_box
from raytrad.scenefiles import write_obj
from raytrad.settings import RenderSettings
from tests.conftest import SCENES, run_cli

FURNACE_OBJ = SCENES / "furnace.obj"  # unit cube, Kd 0.5, Ke 1: B = 2 everywhere
SMALL = ["--receivers", "800", "--patches", "60", "-q"]
TRIANGLE = "v 0 0 0\nv 1 0 0\nv 0 1 0\n"


def _ledger_balances(energy: dict[str, list[float]]) -> bool:
    emitted = np.array(energy["emitted"])
    total = np.array(energy["absorbed"]) + np.array(energy["escaped"]) + np.array(energy["unshot"])
    return bool(np.allclose(total, emitted, rtol=1e-9, atol=0))


def test_render_furnace(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    status, _, err = run_cli(["render", str(FURNACE_OBJ), "-o", str(out), *SMALL], capsys)
    assert status == 0, err
    positions, triangles, radiosity = read_radiosity_ply(out / "furnace.ply")
    assert len(positions) > 500 and len(triangles) > 500
    report = json.loads((out / "report.json").read_text())
    # The default tolerance bounds the unshot power (1e-3 of the emitted), not the
    # pointwise error, which is largest in the corners; the report's bound holds it.
    worst = np.abs(radiosity - 2.0).max()
    assert 0 < worst <= min(report["error"]["bound_max"]) and worst < 5e-3 * 2.0
    assert report["solve"]["stop_reason"] == "converged"
    assert report["solve"]["residual"] <= 1e-3
    assert report["statistics"]["receivers"] == len(positions)
    assert report["energy_watts"]["emitted"] == pytest.approx([6.0, 6.0, 6.0], rel=1e-12)
    assert _ledger_balances(report["energy_watts"])
    assert report["settings"]["mesh"]["imprint"] is True
    # nothing written but the results (no temporary files, no checkpoint)
    assert sorted(p.name for p in out.iterdir()) == [
        "furnace.ply",
        "raytrad-run.json",
        "report.json",
    ]


def test_the_report_says_which_columns_were_spilled(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Columns beyond ``--cache-mb`` go to spill files (the issue: "state which"), and the
    report counts them; the render is the same to the byte as one whose cache held every
    column."""
    scene = str(SCENES / "cornell-box.obj")
    reports, plys = [], []
    for name, cache in (("cached", []), ("spilled", ["--cache-mb", "0.05"])):
        out = tmp_path / name
        status, _, err = run_cli(["render", scene, "-o", str(out), *SMALL, *cache], capsys)
        assert status == 0, err
        reports.append(json.loads((out / "report.json").read_text())["solve"])
        plys.append((out / "cornell-box.ply").read_bytes())
    patches = reports[1]["form_factor_columns"]
    assert reports[0]["columns_spilled"] == 0
    assert 0 < reports[1]["columns_spilled"] <= patches
    assert plys[0] == plys[1]


def test_no_imprint_is_a_mesh_setting(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    argv = ["render", str(FURNACE_OBJ), "-o", str(out), *SMALL, "--no-imprint"]
    argv += ["--tolerance", "1e-4"]
    status, _, err = run_cli(argv, capsys)
    assert status == 0, err
    report = json.loads((out / "report.json").read_text())
    assert report["settings"]["mesh"]["imprint"] is False
    np.testing.assert_allclose(read_radiosity_ply(out / "furnace.ply")[2], 2.0, rtol=2.5e-4)


def test_max_shots_stops_early_and_says_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    status, _, err = run_cli(
        ["render", str(FURNACE_OBJ), "-o", str(out), "--max-shots", "3", *SMALL], capsys
    )
    assert status == 0, err
    report = json.loads((out / "report.json").read_text())
    assert report["solve"]["stop_reason"] == "max-shots"
    assert report["solve"]["shots"] == 3
    assert report["solve"]["residual"] > 1e-3
    assert _ledger_balances(report["energy_watts"])
    _, _, radiosity = read_radiosity_ply(out / "furnace.ply")
    assert radiosity.mean() < 0.99 * 2.0  # three shots are not the converged 2.0


def test_a_resume_says_what_it_took(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], caplog: pytest.LogCaptureFixture
) -> None:
    """``--resume`` without a checkpoint says it starts afresh; a solve cut after the pass
    keeps every column, and the resumed run's summary says its pass traced nothing."""
    scene, out = SCENES / "cornell-box.obj", tmp_path / "out"
    small = ["--receivers", "800", "--patches", "60"]
    status, _, err = run_cli(["render", str(scene), "-o", str(out), "--resume", *small], capsys)
    assert status == 0, err
    assert "no checkpoint to resume from; starting afresh" in caplog.text
    argv = ["render", str(scene), "-o", str(out), "--max-shots", "5", *small]
    assert run_cli(argv, capsys)[0] == 0
    status, stdout, err = run_cli(
        ["render", str(scene), "-o", str(out), "--resume", *small], capsys
    )
    assert status == 0, err
    assert "0 in the form-factor pass of this run" in stdout
    assert "every column came from the checkpoint" in stdout
    assert "rays/s" not in stdout.split("rays       ")[1].split("\n")[0]  # no rate of nothing
    report = json.loads((out / "report.json").read_text())
    assert report["resumed"]["shots"] == 5 and report["solve"]["stop_reason"] == "converged"


def test_python_dash_m_exit_status(tmp_path: Path) -> None:
    def raytrad(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, "-m", "raytrad", "render", *args],
            capture_output=True,
            text=True,
            timeout=120,
        )

    good = raytrad(str(FURNACE_OBJ), "-o", str(tmp_path / "good"), *SMALL)
    assert good.returncode == 0, good.stderr
    assert (tmp_path / "good" / "furnace.ply").is_file()
    missing = tmp_path / "missing.obj"
    bad = raytrad(str(missing), "-o", str(tmp_path / "bad"), "-q")
    assert bad.returncode == 1
    assert bad.stderr.strip().splitlines() == [f"raytrad: error: {missing}: file not found"]


BAD_INPUTS = {
    "missing.obj": None,
    "scene.stl": "solid nothing\nendsolid nothing\n",
    "garbage.obj": "this is not a mesh\nat all\n",
    "binary.obj": bytes(range(256)) * 4,
    "no-vertex.obj": "f 1 2 3\n",
    "nan.obj": "v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    "kd.obj": ("mtllib kd.mtl\n" + TRIANGLE + "usemtl m\nf 1 2 3\n", "newmtl m\nKd 1.5 0.5 0.5\n"),
    "ke.obj": (
        "mtllib ke.mtl\n" + TRIANGLE + "usemtl m\nf 1 2 3\n",
        "newmtl m\nKd 0.5 0.5 0.5\nKe -1 0 0\n",
    ),
    "two-coordinates.obj": "v 0 0\nv 1 0\nv 0 1\nf 1 2 3\n",
    "index-zero.obj": TRIANGLE + "f 0 1 2\n",
    "relative-too-far.obj": TRIANGLE + "f -4 -2 -1\n",
    "index-past-end.obj": TRIANGLE + "f 1 2 4\n",
    "huge.obj": "v 1e300 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    "beyond-float32.obj": "v 1e39 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    "glow.obj": (
        "mtllib glow.mtl\n" + TRIANGLE + "usemtl m\nf 1 2 3\n",
        "newmtl m\nKd 0.5 0.5 0.5\nKe 1e200 1e200 1e200\n",
    ),
    # one stray vertex 5e8 m away: refining it would never end
    "far-vertex.obj": TRIANGLE + "v 5e8 0 0.5\nf 1 2 3\nf 2 4 3\n",
    "deep.toml": "a = " + "[" * 1200 + "]" * 1200 + "\n",
    "deep.gltf": "[" * 1200 + "]" * 1200,
    "short-line.ply": (
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
        "end_header\n0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
    ),
    "middle-endian.ply": (
        "ply\nformat binary_middle_endian 1.0\nelement vertex 0\nproperty float x\nend_header\n"
    ),
}


@pytest.mark.parametrize("name", list(BAD_INPUTS))
def test_bad_scene_is_one_line_and_writes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], name: str
) -> None:
    content = BAD_INPUTS[name]
    scene = tmp_path / name
    if isinstance(content, tuple):  # OBJ + MTL
        scene.write_text(content[0])
        scene.with_suffix(".mtl").write_text(content[1])
    elif isinstance(content, bytes):
        scene.write_bytes(content)
    elif content is not None:
        scene.write_text(content)
    out = tmp_path / "out"
    status, stdout, err = run_cli(["render", str(scene), "-o", str(out), "-q"], capsys)
    assert status == 1
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("raytrad: error: ") and name in lines[0]
    assert "Traceback" not in err and stdout == ""
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.parametrize(
    ("option", "value", "word"),
    [
        ("--exposure", "nan", "exposure"),
        ("--checkpoint-every", "0", "checkpoint interval"),
        ("--checkpoint-every", "nan", "checkpoint interval"),
        ("--exposure", "inf", "exposure"),
        ("--cache-mb", "nan", "cache"),
        ("--receivers", "1000000000000", "receivers"),
        ("--max-receivers", "100000000000", "max receivers"),
        ("--max-edge", "1e-9", "refining would make"),
        ("--image --width", "10000000", "width"),
        ("--image --width", "0", "width"),
        ("--image --camera", "nan,1,1:0,0,0", "camera"),
        ("--lightmap --lightmap-resolution", "0", "lightmap resolution"),
        ("--tolerance", "0", "tolerance"),
        ("--tolerance", "1.5", "tolerance"),
        ("--samples", "0", "samples"),
        ("--receivers", "0", "receivers"),
        ("--scale", "-1", "scale"),
        ("--scale", "nan", "scale"),
        ("--omega", "2", "omega"),
        ("--max-edge", "-0.1", "max edge"),
        ("--method", "gauss-seidel", "method"),
        ("--samples", "many", "samples"),
    ],
)
def test_bad_option_values_are_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], option: str, value: str, word: str
) -> None:
    out = tmp_path / "out"
    status, _, err = run_cli(
        ["render", str(FURNACE_OBJ), "-o", str(out), *option.split(), value, "-q"], capsys
    )
    assert status != 0
    assert word in err.lower()
    assert "Traceback" not in err
    assert not out.exists()


def test_render_help_lists_every_method(capsys: pytest.CaptureFixture[str]) -> None:
    status, out, _ = run_cli(["render", "--help"], capsys)
    assert status == 0
    for method in SHOOTING_METHODS:
        assert method in out


def test_scene_without_emitter_warns_and_writes_zeros(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], caplog: pytest.LogCaptureFixture
) -> None:
    scene = tmp_path / "dark.obj"
    scene.write_text("mtllib dark.mtl\n" + TRIANGLE + "v 1 1 0\nusemtl m\nf 1 2 3\nf 2 4 3\n")
    (tmp_path / "dark.mtl").write_text("newmtl m\nKd 0.5 0.5 0.5\nKe 0 0 0\n")
    out = tmp_path / "out"
    with caplog.at_level(logging.WARNING):
        status, _, err = run_cli(["render", str(scene), "-o", str(out), *SMALL], capsys)
    assert status == 0, err
    assert any(
        "no emitter" in r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING
    )
    _, _, radiosity = read_radiosity_ply(out / "dark.ply")
    assert len(radiosity) > 100
    np.testing.assert_array_equal(radiosity, 0.0)
    report = json.loads((out / "report.json").read_text())
    assert report["solve"]["stop_reason"] == "no-emission"


def test_radiosity_beyond_float32_is_refused_before_writing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # Ke 1e200 solves in float64 (B ~ 1e200) but the PLY and EXR are float32: inf there.
    scene = tmp_path / "hot.obj"
    scene.write_text("mtllib hot.mtl\n" + TRIANGLE + "v 1 1 0\nusemtl m\nf 1 2 3\nf 2 4 3\n")
    (tmp_path / "hot.mtl").write_text("newmtl m\nKd 0.5 0.5 0.5\nKe 1e200 1e200 1e200\n")
    out = tmp_path / "out"
    status, _, err = run_cli(["render", str(scene), "-o", str(out), *SMALL], capsys)
    assert status == 1
    assert "hot.obj" in err and "float32" in err
    assert not out.exists() or not any(out.iterdir())


def test_interrupted_render_resumes_to_the_same_answer(tmp_path: Path) -> None:
    write_obj(cornell_box(), tmp_path / "cornell.obj")  # occluders: rays and sample points
    scene = tmp_path / "cornell.obj"
    settings = RenderSettings(
        mesh=MeshSettings(receivers=800, patches=60), solve=SolveSettings(tolerance=1e-4)
    )
    straight = api.render(scene, tmp_path / "straight", settings)
    assert straight.result.stop_reason == "converged"

    out = tmp_path / "resumed"
    shots: list[int] = []  # Ctrl-C after the 20th shot (the pass polls it too)
    first = api.render(
        scene,
        out,
        settings,
        progress=lambda report: shots.append(report.shots),
        stop=lambda: len(shots) >= 20,
    )
    checkpoint = out / "cornell.checkpoint.npz"
    assert first.result.stop_reason == "interrupted"
    assert first.result.state.shots == 20
    assert checkpoint.is_file() and first.outputs["checkpoint"] == checkpoint
    assert json.loads((out / "report.json").read_text())["solve"]["stop_reason"] == "interrupted"

    assert straight.report["resumed"] is None and first.report["resumed"] is None
    second = api.render(scene, out, settings, resume=True)
    assert second.result.stop_reason == "converged"
    assert second.result.state.shots == straight.result.state.shots
    resumed = second.report["resumed"]
    # the checkpoint holds the finished pass: the resume casts no form-factor ray
    assert resumed["shots"] == 20
    assert resumed["form_factor_columns"] == first.prepared.mesh.patch_count
    assert second.report["solve"]["rays"] == 0
    assert 0 < resumed["solve_seconds"] <= first.result.state.seconds
    np.testing.assert_allclose(second.result.radiosity, straight.result.radiosity, rtol=1e-9)
    assert not checkpoint.exists()
    # the report's error log covers the whole solve, the shots before the resume too
    for name in ("shots", "residual", "estimate", "bound_rms"):  # null: not finite yet
        got, want = (
            np.array(r["convergence"][name], float) for r in (second.report, straight.report)
        )
        np.testing.assert_allclose(got, want, rtol=1e-9)
    _, _, written = read_radiosity_ply(out / "cornell.ply")
    np.testing.assert_array_equal(written, straight.result.radiosity.astype(np.float32))


def test_a_time_limited_refinement_resumes_without_pass_or_solve(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A time-limited run whose refinement is cut keeps a checkpoint of the converged
    solve with the pass's balanced scales and no column (the scales are all refinement
    needs; 630 MB of columns at 60 000 receivers were written for nothing): ``--resume``
    traces no pass, computes no column, shoots no shot, refines to the end and gives the
    uninterrupted bake."""
    from raytrad.core import adaptive, pipeline

    scene = SCENES / "cornell-box.obj"
    settings = RenderSettings(
        mesh=MeshSettings(receivers=800, patches=60), solve=SolveSettings(time_limit=1000.0)
    )
    api.render(scene, tmp_path / "straight", settings)
    gathering = [False]
    original = adaptive._gather

    def gather(*args: object, **kwargs: object) -> object:
        gathering[0] = True  # the budget is spent once refinement gathers
        return original(*args, **kwargs)

    monkeypatch.setattr(adaptive, "_gather", gather)
    spent = pipeline.RunBudget.__call__
    monkeypatch.setattr(pipeline.RunBudget, "__call__", lambda budget: gathering[0])
    out = tmp_path / "cut"
    first = api.render(scene, out, settings)
    monkeypatch.setattr(adaptive, "_gather", original)
    monkeypatch.setattr(pipeline.RunBudget, "__call__", spent)
    assert first.result.stop_reason == "converged" and first.refinement.stopped
    assert first.outputs["checkpoint"].is_file()
    assert resuming.load_pass_columns(first.outputs["checkpoint"]) == {}
    # the round cut short added receivers it did not gather, and the summary says so
    cut = first.report["refinement"]
    assert cut["receivers_interpolated"] == cut["receivers_added"] > 0 and cut["rounds"] == 0
    _print_summary(first.report, {})
    summary = capsys.readouterr().out
    assert f"{cut['receivers_interpolated']} of them interpolated" in summary
    assert f"+{cut['receivers_added']} receivers in 0 rounds and one cut short" in summary
    # the discretisation part comes with its own standard error (the check's sampling)
    error = first.report["error"]
    worst = int(np.argmax(error["parts"]["discretisation"]))
    spread = error["discretisation_standard_error"][worst]
    assert 0 < spread < error["parts"]["discretisation"][worst]
    assert f"discretisation {error['parts']['discretisation'][worst]:.2e} ± {spread:.2e}" in (
        summary
    )
    # the scene line counts every receiver baked, and says how many were solved
    receivers = first.report["statistics"]["receivers"]
    assert receivers == cut["receivers_solved"] + cut["receivers_added"]
    assert (
        f"{receivers} receivers ({cut['receivers_solved']} solved, the rest added by "
        "refinement)" in summary
    )
    second = api.render(scene, out, settings, resume=True)
    resumed = second.report["resumed"]
    assert resumed["form_factor_columns"] == 0 and resumed["form_factor_scales"]
    assert second.report["solve"]["form_factor_columns"] == 0
    assert resumed["shots"] == first.result.state.shots == second.result.state.shots
    assert second.report["solve"]["rays"] == 0 and not second.refinement.stopped
    assert not (out / "cornell-box.checkpoint.npz").exists()
    _, _, want = read_radiosity_ply(tmp_path / "straight" / "cornell-box.ply")
    _, _, got = read_radiosity_ply(out / "cornell-box.ply")
    np.testing.assert_array_equal(got, want)


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_ctrl_c_while_refining_keeps_the_solve_and_its_rounds(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    caplog: pytest.LogCaptureFixture,
) -> None:
    """Ctrl-C in the second refinement round of a run without a time limit (so no
    checkpoint was written after the solve, and refinement released the columns): the
    run exits 130 with the bake so far, the solve's state, the pass's balanced scales and
    the finished round; --resume traces no pass and shoots nothing, goes on from that
    round and gives the uninterrupted bake, leaving no checkpoint."""
    import os

    from raytrad.core import adaptive

    scene = SCENES / "cornell-box.obj"
    mesh = MeshSettings(receivers=800, patches=60)
    straight = api.render(scene, tmp_path / "straight", RenderSettings(mesh=mesh))
    assert straight.refinement.rounds >= 3
    gathers = [0]
    original = adaptive._gather

    def gather(*args: object, **kwargs: object) -> object:
        gathers[0] += 1
        if gathers[0] == 2:  # the second round's gather: as a user's Ctrl-C would come
            os.kill(os.getpid(), signal.SIGINT)
        return original(*args, **kwargs)

    monkeypatch.setattr(adaptive, "_gather", gather)
    out = tmp_path / "cut"
    argv = ["render", str(scene), "-o", str(out), "--receivers", "800", "--patches", "60"]
    status, _, err = run_cli([*argv, "-q"], capsys)
    monkeypatch.setattr(adaptive, "_gather", original)
    assert status == 130, err
    assert "refinement stopped in round 2 (interrupted)" in caplog.text  # it knows which
    report = json.loads((out / "report.json").read_text())
    assert report["solve"]["stop_reason"] == "interrupted" and report["refinement"]["stopped"]
    assert any("interrupted" in line for line in api.verify_outputs(out))
    _print_summary(report, {})
    summary = capsys.readouterr().out
    assert "converged after" in summary and "(then interrupted while refining)" in summary
    assert "stopped early by an interrupt" in summary
    assert report["refinement"]["rounds"] == 1
    assert (out / "cornell-box.checkpoint.npz").is_file()
    assert (out / "cornell-box.refinement.npz").is_file()
    status, _, err = run_cli([*argv, "-q", "--resume"], capsys)
    assert status == 0, err
    resumed = json.loads((out / "report.json").read_text())
    assert resumed["resumed"]["shots"] == report["solve"]["shots"] == resumed["solve"]["shots"]
    # the pass's balanced scales came back with the state: no pass, no column, no ray
    assert resumed["resumed"]["form_factor_scales"]
    assert resumed["resumed"]["form_factor_columns"] == 0
    assert resumed["solve"]["form_factor_columns"] == resumed["solve"]["rays"] == 0
    balance = report["statistics"]["form_factor_balance"]
    assert resumed["statistics"]["form_factor_balance"] == balance and balance["complete"]
    _print_summary(resumed, {})
    summary = capsys.readouterr().out
    assert "rays       0 in the form-factor pass of this run (the finished pass's balanced" in (
        summary
    )
    assert resumed["resumed"]["refinement_rounds"] == 1
    assert "; 1 of the rounds and their rays from an earlier run)" in summary
    assert not resumed["refinement"]["stopped"]
    assert not (out / "cornell-box.checkpoint.npz").exists()
    assert not (out / "cornell-box.refinement.npz").exists()
    _, _, got = read_radiosity_ply(out / "cornell-box.ply")
    _, _, want = read_radiosity_ply(tmp_path / "straight" / "cornell-box.ply")
    np.testing.assert_array_equal(got, want)


def test_a_cut_refinement_resumes_from_its_last_round(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Refinement cut short keeps its finished rounds beside the checkpoint: each resume
    goes on from them (one more round under the same limit, where it used to make the
    same rounds again), and the last gives the uninterrupted bake, leaving no file."""
    from raytrad.core import adaptive

    scene = SCENES / "cornell-box.obj"
    settings = RenderSettings(
        mesh=MeshSettings(receivers=800, patches=60), solve=SolveSettings(time_limit=1000.0)
    )
    straight = api.render(scene, tmp_path / "straight", settings)
    assert straight.refinement.rounds >= 3
    gathers = [0]
    original = adaptive._gather

    def gather(*args: object, **kwargs: object) -> object:
        gathers[0] += 1
        return original(*args, **kwargs)

    monkeypatch.setattr(adaptive, "_gather", gather)
    out = tmp_path / "cut"
    kept = out / "cornell-box.refinement.npz"
    checkpoint = out / "cornell-box.checkpoint.npz"
    rounds, written = [], []
    for resume in (False, True):  # the budget is spent in each run's second gather
        gathers[0] = 0
        cut = api.render(scene, out, settings, resume=resume, stop=lambda: gathers[0] >= 2)
        assert cut.refinement.stopped and cut.outputs["refinement"] == kept and kept.is_file()
        rounds.append(cut.refinement.rounds)
        written.append(checkpoint.stat().st_mtime_ns)
    assert rounds == [1, 2]  # the resume went on from round 1
    assert cut.report["resumed"]["refinement_rounds"] == 1
    # its solve had converged: the checkpoint already held its state and every column
    assert written[1] == written[0] and "checkpoint" not in cut.report["timings_seconds"]
    # rounds made under other refinement settings are not gone on from
    other = dataclasses.replace(settings, refine=RefineSettings(threshold=0.2))
    gathers[0] = 0
    cut = api.render(scene, out, other, resume=True, stop=lambda: gathers[0] >= 2)
    assert cut.refinement.rounds == 1 and cut.report["resumed"]["refinement_rounds"] == 0
    last = api.render(scene, out, settings, resume=True)
    assert not last.refinement.stopped and last.refinement.rounds == straight.refinement.rounds
    assert last.refinement.rays == straight.refinement.rays
    assert not kept.exists() and not checkpoint.exists()
    _, _, want = read_radiosity_ply(tmp_path / "straight" / "cornell-box.ply")
    _, _, got = read_radiosity_ply(out / "cornell-box.ply")
    np.testing.assert_array_equal(got, want)
    assert (
        last.report["refinement"]["receivers_added"]
        == straight.report["refinement"]["receivers_added"]
    )


def test_a_stop_in_the_form_factor_pass_saves_and_resumes(tmp_path: Path) -> None:
    scene = SCENES / "cornell-box.obj"
    settings = RenderSettings(
        mesh=MeshSettings(receivers=800, patches=60), solve=SolveSettings(tolerance=1e-4)
    )
    straight = api.render(scene, tmp_path / "straight", settings)
    out = tmp_path / "stopped"
    polls = itertools.count()  # Ctrl-C after the 5th form-factor column
    first = api.render(scene, out, settings, stop=lambda: next(polls) >= 5)
    assert first.result.stop_reason == "interrupted" and first.result.state.shots == 0
    report = json.loads((out / "report.json").read_text())
    assert report["statistics"]["form_factor_balance"]["complete"] is False
    assert (out / "cornell-box.checkpoint.npz").is_file() and (out / "cornell-box.ply").is_file()
    second = api.render(scene, out, settings, resume=True)
    assert second.result.stop_reason == "converged"
    resumed = json.loads((out / "report.json").read_text())["resumed"]
    columns = report["solve"]["form_factor_columns"]  # those the cut pass finished
    want = {"shots": 0, "solve_seconds": 0.0, "form_factor_columns": columns}
    assert resumed == want | {"form_factor_scales": False, "refinement_rounds": 0}
    assert columns >= 1
    # the columns of the cut pass came from the checkpoint: fewer rays, the same answer
    assert second.result.state.rays < straight.result.state.rays
    assert second.result.state.shots == straight.result.state.shots
    np.testing.assert_array_equal(second.result.radiosity, straight.result.radiosity)


def test_a_time_limited_pass_resumed_gives_the_uninterrupted_result(tmp_path: Path) -> None:
    scene = SCENES / "cornell-box.obj"
    mesh = MeshSettings(receivers=800, patches=60)
    straight = api.render(scene, tmp_path / "straight", RenderSettings(mesh=mesh))
    out = tmp_path / "limited"
    limited = RenderSettings(mesh=mesh, solve=SolveSettings(time_limit=1e-3))
    first = api.render(scene, out, limited)
    assert first.result.stop_reason == "time-limit" and first.result.state.shots >= 1
    second = api.render(scene, out, RenderSettings(mesh=mesh), resume=True)
    assert second.result.stop_reason == "converged"
    assert second.result.state.shots == straight.result.state.shots
    np.testing.assert_array_equal(second.result.radiosity, straight.result.radiosity)


def test_resume_refuses_a_checkpoint_of_other_settings(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    settings = RenderSettings(mesh=MeshSettings(receivers=800, patches=60))
    polls = itertools.count()
    api.render(FURNACE_OBJ, out, settings, stop=lambda: next(polls) >= 3)
    assert (out / "furnace.checkpoint.npz").is_file()
    # a different mesh is a different discrete system: the checkpoint must not be mixed in
    status, _, err = run_cli(
        ["render", str(FURNACE_OBJ), "-o", str(out), "--receivers", "900", "--resume", "-q"],
        capsys,
    )
    assert status == 1
    assert "checkpoint" in err and len(err.strip().splitlines()) == 1


def test_time_limit_bounds_the_form_factor_pass(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], caplog: pytest.LogCaptureFixture
) -> None:
    """../shared/cases/time-limit-not-bounding, in small: a budget spent before the pass
    ends gives the direct light, a report, a PLY and a checkpoint, and says so."""
    out = tmp_path / "out"
    argv = ["render", str(SCENES / "cornell-box.obj"), "-o", str(out), "--receivers", "1500"]
    status, summary, _ = run_cli([*argv, "--patches", "80", "--time-limit", "0.001"], capsys)
    assert status == 0
    report = json.loads((out / "report.json").read_text())
    assert report["statistics"]["form_factor_balance"]["complete"] is False
    # refinement had no time left either, and the report and the summary say so
    assert report["refinement"]["stopped"] is True
    assert report["refinement"]["receivers_added"] == 0
    assert report["refinement"]["receivers_interpolated"] == 0
    assert "refined    nothing: the time limit came first" in summary
    assert "solved, the rest added" not in summary  # nothing was added
    assert "form-factor pass stopped after" in caplog.text
    # a few shots: the residual check's number is the larger, but it counts the unfinished
    # solve, so the algebraic part is named, and the summary says why
    error = report["error"]
    assert error["dominant"] == "algebraic"
    assert max(error["parts"]["discretisation"]) > max(error["parts"]["algebraic"])
    # the time is spent: the residual check traces an eighth of its points (those not
    # shut in count)
    solved = report["refinement"]["receivers_solved"]
    quick = error_samples(solved, quick=True)[0]
    assert 0.9 * quick <= error["samples"] <= quick < error_samples(solved)[0]
    assert "the discretisation figure includes the unfinished solve's own error" in summary
    solve = report["solve"]
    assert solve["stop_reason"] == "time-limit"
    # every lamp patch shot once, nothing else: the lamp is a few patches of 80
    assert 1 <= solve["shots"] <= 4
    assert {p.name for p in out.iterdir()} >= {"cornell-box.ply", "cornell-box.checkpoint.npz"}
    _, _, radiosity = read_radiosity_ply(out / "cornell-box.ply")
    assert np.isfinite(radiosity).all() and (radiosity > 0).mean() > 0.5  # lit, not just E


@pytest.mark.parametrize("fault", [RuntimeError("boom\nsecond line"), MemoryError()])
def test_an_internal_fault_is_one_line_and_a_traceback_with_v(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    fault: BaseException,
) -> None:
    def broken(*args: object, **kwargs: object) -> None:
        raise fault

    monkeypatch.setattr(api, "render", broken)
    argv = ["render", str(FURNACE_OBJ), "-o", str(tmp_path / "out"), "-q"]
    status, _, err = run_cli(argv, capsys)
    assert status == 1
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"raytrad: error: {FURNACE_OBJ}: ")
    if isinstance(fault, RuntimeError):
        assert "internal error (RuntimeError: boom second line)" in lines[0]
        with pytest.raises(RuntimeError):
            run_cli([*argv[:-1], "-v"], capsys)
    else:
        assert "out of memory" in lines[0]


@pytest.mark.skipif(not hasattr(signal, "SIGTERM") or sys.platform == "win32", reason="POSIX")
def test_sigterm_stops_cleanly_with_a_checkpoint_and_resumes(tmp_path: Path) -> None:
    """SIGTERM (how schedulers stop work) is handled like Ctrl-C: the results so far, the
    report marked interrupted and a checkpoint are written, the exit status is 143, and
    --resume finishes to the uninterrupted answer."""
    scene = tmp_path / "cornell.obj"
    write_obj(cornell_box(), scene)
    out = tmp_path / "out"
    argv = [sys.executable, "-m", "raytrad", "render", str(scene), "-o", str(out)]
    argv += ["--receivers", "800", "--patches", "60", "--tolerance", "1e-4"]
    process = subprocess.Popen(argv, stderr=subprocess.PIPE, text=True)
    assert process.stderr is not None
    for line in process.stderr:  # the scene is loaded: the handler is in place
        if "triangles" in line:
            process.send_signal(signal.SIGTERM)
            break
    process.stderr.read()
    assert process.wait(timeout=300) == 128 + signal.SIGTERM
    report = json.loads((out / "report.json").read_text())
    assert report["solve"]["stop_reason"] == "interrupted"
    assert (out / "cornell.checkpoint.npz").is_file() and (out / "cornell.ply").is_file()

    straight = api.render(
        scene,
        tmp_path / "straight",
        RenderSettings(
            mesh=MeshSettings(receivers=800, patches=60), solve=SolveSettings(tolerance=1e-4)
        ),
    )
    resumed = subprocess.run([*argv, "--resume", "-q"], capture_output=True, text=True)
    assert resumed.returncode == 0, resumed.stderr
    _, _, radiosity = read_radiosity_ply(out / "cornell.ply")
    np.testing.assert_array_equal(radiosity, straight.result.radiosity.astype(np.float32))


def test_the_summary_counts_one_refinement_round_in_the_singular(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """'+N receivers in 1 round', not '1 rounds' (a newcomer's report)."""
    report = {
        "scene": "box.obj",
        "statistics": {"receivers": 10, "patches": 2, "subareas": 4, "occlusion_tested": True},
        "solve": {
            "method": "ambient",
            "stop_reason": "converged",
            "shots": 3,
            "residual": 1e-4,
            "rays": 100,
            "rays_naive": 200,
            "rays_per_second": 1e6,
        },
        "timings_seconds": {"solve": 0.1},
        "refinement": {
            "receivers_added": 5,
            "rounds": 1,
            "receivers_solved": 5,
            "rays": 50,
            "rays_naive": 80,
        },
    }
    _print_summary(report, {})
    assert "+5 receivers in 1 round (solved 5;" in capsys.readouterr().out


def test_progress_bars_follow_the_stages(capsys: pytest.CaptureFixture[str]) -> None:
    """On a terminal: a bar for the pass's columns, one for the solve's shots, one for
    each final gather's patches, each closed when the next stage starts."""
    from raytrad.cli import _Progress

    bars = _Progress(enabled=True)
    bars.enabled = True  # as on a terminal (pytest's stderr is not one)
    for done in range(1, 4):
        bars.stage("form factors", done, 3)
    assert bars._stage is None  # the pass's bar ends with its last column
    bars(api.RenderProgress(5, 0.1, 100, 0.5, 0.1, 1.0))
    assert bars._bar is not None and bars._bar.n == 5
    bars(api.RenderProgress(6, 0.1, 100, 0.25, 0.1, 1.0))  # within the throttle
    bars.stage("final gather", 1, 2)
    assert bars._bar is None and bars._stage is not None  # the solve's bar closed
    first = bars._stage[1]
    bars.stage("final gather", 2, 2)
    assert bars._stage is None  # the round's gather is done
    bars.stage("final gather", 1, 2)  # the next round's: a new bar
    assert bars._stage is not None and bars._stage[1] is not first
    bars.close()
    err = capsys.readouterr().err
    assert "form factors" in err and "6shot" in err and "final gather" in err
    assert "residual 2.50e-01" in err  # the solve's bar closed on its last figures
    assert "rays/s -" in err  # no rate over a tenth of a second
