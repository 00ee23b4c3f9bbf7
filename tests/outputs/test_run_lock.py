"""One run at a time per output folder: a live holder is refused by name, a stale lock
(its process gone) is taken over, and a run that fails leaves no empty folder behind."""

from __future__ import annotations

import json
import logging
import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from raytrad import api
from raytrad.core.mesh import MeshSettings
from raytrad.errors import SettingsError
from raytrad.outputs.run_lock import LOCK, RunLock
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
