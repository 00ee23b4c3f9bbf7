"""``raytrad bake --local-cluster 2`` on a real Dask LocalCluster: a worker killed mid-job
loses nothing, and a rerun skips every job."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from raytrad import api
from raytrad.core.mesh import MeshSettings
from raytrad.formats.ply import read_radiosity_ply
from raytrad.scene.builtin import cornell_box, furnace_box
from raytrad.scenefiles import write_obj
from raytrad.settings import RenderSettings
from tests.batch.test_bake import _summary, _wait_for_lock

pytest.importorskip("distributed")

POSIX = pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")


@POSIX
@pytest.mark.slow  # 40 s: a LocalCluster of two, a worker killed; CI runs it (-m slow)
def test_a_killed_dask_worker_is_retried_and_a_rerun_skips_all(tmp_path: Path) -> None:
    write_obj(cornell_box(), tmp_path / "cornell.obj")
    write_obj(furnace_box(reflectance=0.5), tmp_path / "furnace.obj")
    write_obj(furnace_box(reflectance=0.8, size=2.0), tmp_path / "big.obj")
    manifest = tmp_path / "bake.toml"
    manifest.write_text(
        "[defaults]\nreceivers = 3000\npatches = 60\ncheckpoint_every = 0.2\n"
        + "".join(
            f'[[job]]\nscene = "{name}.obj"\noutput = "out/{name}"\n'
            for name in ("cornell", "furnace", "big")
        )
    )
    argv = [sys.executable, "-m", "raytrad", "bake", str(manifest), "--local-cluster", "2"]
    process = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    worker = _wait_for_lock(tmp_path / "out/cornell", process)
    time.sleep(1.0)
    os.kill(worker, signal.SIGKILL)  # the worker process running the Cornell box
    _, err = process.communicate(timeout=600)
    stderr = err.decode()
    assert process.returncode == 0, stderr
    # the task ran again on a live worker, which took over the dead run's folder
    assert f"taking over the lock of a run that is gone (pid {worker})" in stderr
    jobs = _summary(tmp_path)
    assert {job["status"] for job in jobs.values()} == {"done"}
    assert jobs["out/cornell"]["recovered"] or jobs["out/cornell"]["resumed"]
    for name in ("cornell", "furnace", "big"):
        assert api.verify_outputs(tmp_path / "out" / name) == []
    alone = api.render(
        tmp_path / "cornell.obj",
        tmp_path / "alone",
        RenderSettings(mesh=MeshSettings(receivers=3000, patches=60)),
    )
    _, _, baked = read_radiosity_ply(tmp_path / "out/cornell/cornell.ply")
    np.testing.assert_array_equal(baked, alone.result.radiosity.astype(np.float32))

    rerun = subprocess.run([*argv, "-q"], capture_output=True, text=True, timeout=600)
    assert rerun.returncode == 0, rerun.stderr
    record = json.loads((tmp_path / "bake-summary.json").read_text())
    assert record["counts"]["skipped"] == 3
    assert record["runner"].startswith("Dask LocalCluster: 2 workers")


def test_bake_submits_to_a_running_scheduler(tmp_path: Path) -> None:
    """``--scheduler ADDRESS``: jobs go to a cluster raytrad did not start; each render
    takes its worker machine's cores divided by the worker's threads."""
    from distributed import LocalCluster

    write_obj(furnace_box(reflectance=0.5), tmp_path / "furnace.obj")
    manifest = tmp_path / "bake.toml"
    manifest.write_text(
        '[defaults]\nreceivers = 600\npatches = 40\n[[job]]\nscene = "furnace.obj"\n'
        'output = "out/furnace"\n[[job]]\nscene = "gone.obj"\noutput = "out/gone"\n'
    )
    with LocalCluster(
        n_workers=1, threads_per_worker=2, processes=True, dashboard_address=None
    ) as cluster:
        argv = [sys.executable, "-m", "raytrad", "bake", str(manifest), "--scheduler"]
        done = subprocess.run(
            [*argv, cluster.scheduler_address], capture_output=True, text=True, timeout=600
        )
    assert done.returncode == 1, done.stderr  # the missing scene
    jobs = _summary(tmp_path)
    assert jobs["out/furnace"]["status"] == "done" and jobs["out/gone"]["status"] == "failed"
    assert "file not found" in jobs["out/gone"]["message"]
    assert api.verify_outputs(tmp_path / "out/furnace") == []
    record = json.loads((tmp_path / "bake-summary.json").read_text())
    assert record["runner"] == f"Dask scheduler {cluster.scheduler_address}"
