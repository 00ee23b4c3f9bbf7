"""One run at a time per output folder: a live holder is refused by name, a stale lock
(its process gone) is taken over, and a run that fails leaves no empty folder behind."""

from __future__ import annotations

import json
import logging
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from raytrad import api
from raytrad.core.mesh import MeshSettings
from raytrad.errors import SettingsError
from raytrad.outputs.run_lock import LOCK, STALE_SECONDS, FolderLocked, RunLock
from raytrad.settings import RenderSettings
from tests.conftest import SCENES

SETTINGS = RenderSettings(mesh=MeshSettings(receivers=400, patches=40))


def _hold(directory: Path, pid: int) -> None:
    directory.mkdir(parents=True, exist_ok=True)
    (directory / LOCK).write_text(json.dumps({"pid": pid, "host": socket.gethostname()}))


def test_a_live_holder_is_refused_by_name(tmp_path: Path) -> None:
    holder = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        _hold(tmp_path, holder.pid)
        with pytest.raises(SettingsError, match=f"another raytrad run \\(pid {holder.pid}\\)"):
            api.render(SCENES / "furnace.obj", tmp_path, SETTINGS)
        assert sorted(p.name for p in tmp_path.iterdir()) == [LOCK]  # nothing written
    finally:
        holder.kill()
        holder.wait()


def test_a_stale_lock_is_taken_over(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    _hold(tmp_path, gone.pid)
    with caplog.at_level(logging.WARNING):
        outcome = api.render(SCENES / "furnace.obj", tmp_path, SETTINGS)
    assert "taking over the lock" in caplog.text
    assert outcome.result.stop_reason == "converged"
    assert not (tmp_path / LOCK).exists()  # released at the end


def test_the_lock_is_released_and_an_empty_new_folder_removed(tmp_path: Path) -> None:
    out = tmp_path / "new"
    with pytest.raises(RuntimeError), RunLock(out):
        assert (out / LOCK).is_file()
        assert json.loads((out / LOCK).read_text())["pid"] == os.getpid()
        raise RuntimeError("the run failed before writing anything")
    assert not out.exists()
    with RunLock(out):
        (out / "kept.txt").write_text("written")
    assert sorted(p.name for p in out.iterdir()) == ["kept.txt"]


def _hold_elsewhere(directory: Path, seconds_ago: float) -> None:
    """A lock held on another host, last touched ``seconds_ago``."""
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / LOCK
    path.write_text(json.dumps({"pid": 1, "host": "render-node-7.invalid"}))
    touched = time.time() - seconds_ago
    os.utime(path, (touched, touched))


def test_a_lock_on_another_host_is_stale_only_when_its_heartbeat_stops(tmp_path: Path) -> None:
    _hold_elsewhere(tmp_path / "fresh", seconds_ago=5)
    with pytest.raises(FolderLocked, match=r"pid 1 on render-node-7\.invalid") as caught:
        RunLock(tmp_path / "fresh").__enter__()
    assert caught.value.elsewhere

    _hold_elsewhere(tmp_path / "silent", seconds_ago=STALE_SECONDS + 1)
    with RunLock(tmp_path / "silent") as lock:
        assert json.loads(lock.path.read_text())["host"] == socket.gethostname()


def test_the_holder_touches_its_lock(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr("raytrad.outputs.run_lock.HEARTBEAT_SECONDS", 0.05)
    with RunLock(tmp_path) as lock:
        old = time.time() - 1000
        os.utime(lock.path, (old, old))
        time.sleep(0.5)
        assert time.time() - lock.path.stat().st_mtime < 10
    assert not lock.path.exists()


def test_a_bake_job_waits_out_a_lost_workers_lock_elsewhere(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A task rescheduled after its worker died on another host finds that host's lock:
    it waits until the heartbeat has been silent long enough, then renders."""
    from raytrad.batch import Job, run_job

    monkeypatch.setattr("raytrad.outputs.run_lock.STALE_SECONDS", 1.0)
    monkeypatch.setattr("raytrad.batch.jobs.STALE_SECONDS", 1.0)
    monkeypatch.setattr("raytrad.batch.jobs.LOCK_POLL_SECONDS", 0.3)
    _hold_elsewhere(tmp_path / "out", seconds_ago=0)
    start = time.monotonic()
    result = run_job(Job("furnace", SCENES / "furnace.obj", tmp_path / "out", SETTINGS))
    assert result.status == "done", result.message
    assert time.monotonic() - start >= 1.0
    assert api.verify_outputs(tmp_path / "out") == []


def test_temporaries_a_killed_run_left_are_removed_by_the_next(tmp_path: Path) -> None:
    """kill -9 mid-write leaves ``.<name>.XXXXXXXX.tmp<suffix>`` files; the next run in the
    folder, holding its lock, removes them and nothing else."""
    import tempfile

    tmp_path.mkdir(exist_ok=True)
    left = [
        tempfile.mkstemp(dir=tmp_path, prefix=".scene.lightmap.png.", suffix=".tmp.png")[1],
        tempfile.mkstemp(dir=tmp_path, prefix=".report.json.", suffix=".tmp")[1],
    ]
    kept = [tmp_path / ".notes", tmp_path / "draft.tmp", tmp_path / ".a.b.tmp"]
    for path in kept:
        path.write_text("mine")
    api.render(SCENES / "furnace.obj", tmp_path, SETTINGS)
    assert not any(Path(p).exists() for p in left)
    assert all(path.read_text() == "mine" for path in kept)
