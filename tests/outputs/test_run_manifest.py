"""The run manifest tells a complete output set from an interrupted or mixed one
(``raytrad verify DIR``), the case of a re-run killed while writing."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from raytrad.outputs.run_manifest import MANIFEST, verify_outputs
from tests.conftest import SCENES, run_cli

SMALL = ["--receivers", "500", "--patches", "40", "--refine-threshold", "0", "-q"]


def _render(out: Path, capsys: pytest.CaptureFixture[str], *extra: str) -> None:
    argv = ["render", str(SCENES / "cornell-box.obj"), "-o", str(out), *SMALL, *extra]
    status, _, err = run_cli(argv, capsys)
    assert status == 0, err


def test_a_complete_run_lists_every_output_with_its_hash(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _render(tmp_path, capsys, "--image", "--width", "64", "--height", "48")
    manifest = json.loads((tmp_path / MANIFEST).read_text())
    written = {p.name for p in tmp_path.iterdir()} - {MANIFEST}
    assert set(manifest["files"]) == written
    assert manifest["stop_reason"] == "converged"
    assert verify_outputs(tmp_path) == []
    status, out, _ = run_cli(["verify", str(tmp_path)], capsys)
    assert status == 0 and "complete and consistent" in out


def test_a_mixed_or_interrupted_set_is_told_apart(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _render(tmp_path, capsys)
    # a re-run killed in its write phase: one new file beside the old ones
    (tmp_path / "cornell-box.ply").write_bytes((tmp_path / "cornell-box.ply").read_bytes()[:-4])
    problems = verify_outputs(tmp_path)
    assert len(problems) == 1 and "cornell-box.ply" in problems[0] and "mixed" in problems[0]
    status, _, err = run_cli(["verify", str(tmp_path)], capsys)
    assert status == 1 and "mixed set" in err
    # a run killed before it could write the manifest again
    (tmp_path / MANIFEST).unlink()
    assert "no manifest" in verify_outputs(tmp_path)[0]
    (tmp_path / "report.json").unlink()
    _render(tmp_path, capsys)  # a new complete run repairs the set
    assert verify_outputs(tmp_path) == []


def test_a_new_run_removes_the_old_manifest_before_writing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    _render(tmp_path, capsys)
    from raytrad.outputs import write

    def broken(*args: object, **kwargs: object) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(write, "write_radiosity_ply", broken)
    status, _, _ = run_cli(
        ["render", str(SCENES / "cornell-box.obj"), "-o", str(tmp_path), *SMALL], capsys
    )
    assert status == 1
    assert not (tmp_path / MANIFEST).exists()
    assert "no manifest" in verify_outputs(tmp_path)[0]


def test_a_run_stopped_by_a_signal_does_not_verify_until_resumed(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Ctrl-C or SIGTERM writes a whole set of the solution so far; verify says it is
    unfinished, and a resumed run makes it verify."""
    from raytrad import api
    from raytrad.core.mesh import MeshSettings
    from raytrad.settings import RenderSettings

    settings = RenderSettings(mesh=MeshSettings(receivers=500, patches=40))
    stopped = api.render(SCENES / "cornell-box.obj", tmp_path, settings, stop=lambda: True)
    assert stopped.result.stop_reason == "interrupted"
    (problem,) = verify_outputs(tmp_path)
    assert "the run was interrupted" in problem and "resume it" in problem
    status, _, err = run_cli(["verify", str(tmp_path)], capsys)
    assert status == 1 and "interrupted" in err
    api.render(SCENES / "cornell-box.obj", tmp_path, settings, resume=True)
    assert verify_outputs(tmp_path) == []


def test_finished_fails_a_run_stopped_on_a_budget_until_resumed(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A run stopped by --max-shots (as by --time-limit) is a whole set of its best answer:
    plain verify passes it, ``--finished`` does not until a resumed run reaches the
    tolerance."""
    _render(tmp_path, capsys, "--max-shots", "3")
    manifest = json.loads((tmp_path / MANIFEST).read_text())
    assert manifest["stop_reason"] == "max-shots"
    assert "checkpoint" in {entry["key"] for entry in manifest["files"].values()}
    assert verify_outputs(tmp_path) == []
    (problem,) = verify_outputs(tmp_path, finished=True)
    assert "before its tolerance (max-shots" in problem and "--resume" in problem
    status, _, err = run_cli(["verify", str(tmp_path), "--finished"], capsys)
    assert status == 1 and "max-shots" in err
    _render(tmp_path, capsys, "--resume")
    assert json.loads((tmp_path / MANIFEST).read_text())["stop_reason"] == "converged"
    status, out, _ = run_cli(["verify", str(tmp_path), "--finished"], capsys)
    assert status == 0 and "finished" in out


def test_finished_fails_a_set_that_keeps_a_checkpoint(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A solve that converged with its refinement cut short keeps a checkpoint to resume:
    not finished, although its stop reason is "converged"."""
    import hashlib

    _render(tmp_path, capsys)
    checkpoint = tmp_path / "cornell-box.checkpoint.npz"
    checkpoint.write_bytes(b"state")
    manifest = json.loads((tmp_path / MANIFEST).read_text())
    manifest["files"][checkpoint.name] = {
        "key": "checkpoint",
        "bytes": 5,
        "sha256": hashlib.sha256(b"state").hexdigest(),
    }
    (tmp_path / MANIFEST).write_text(json.dumps(manifest))
    assert verify_outputs(tmp_path) == []
    (problem,) = verify_outputs(tmp_path, finished=True)
    assert "had its refinement cut short (a checkpoint kept to resume)" in problem
    assert "--resume to go on" in problem
