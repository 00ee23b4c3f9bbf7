"""``raytrad bake`` on the local process pool: per-job failures, skipping by content,
retries of a killed worker, and a bake stopped by SIGTERM that resumes."""

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
from raytrad.batch import Job, JobResult, LocalPool, bake
from raytrad.core.mesh import MeshSettings
from raytrad.core.solver import SolveSettings
from raytrad.formats.ply import read_radiosity_ply
from raytrad.scene.builtin import cornell_box, furnace_box
from raytrad.scenefiles import write_obj
from raytrad.settings import RenderSettings
from tests.conftest import run_cli

POSIX = pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
#: Small jobs: a couple of seconds each on one core.
SMALL = RenderSettings(mesh=MeshSettings(receivers=800, patches=60))


def _scenes(folder: Path) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    write_obj(cornell_box(), folder / "cornell.obj")
    write_obj(furnace_box(reflectance=0.5), folder / "furnace.obj")


def _manifest(folder: Path, extra: str = "", defaults: str = "", receivers: int = 800) -> Path:
    path = folder / "bake.toml"
    path.write_text(
        f"[defaults]\nreceivers = {receivers}\npatches = 60\n{defaults}\n"
        '[[job]]\nscene = "cornell.obj"\noutput = "out/cornell"\n'
        '[[job]]\nscene = "furnace.obj"\noutput = "out/furnace"\n' + extra
    )
    return path


def _summary(folder: Path) -> dict[str, dict]:
    record = json.loads((folder / "bake-summary.json").read_text())
    return {job["name"]: job for job in record["jobs"]}


def test_a_missing_scene_fails_alone_and_a_rerun_skips_the_rest(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _scenes(tmp_path)
    manifest = _manifest(tmp_path, '[[job]]\nscene = "gone.obj"\noutput = "out/gone"\n')
    status, out, err = run_cli(["bake", str(manifest)], capsys)
    assert status == 1
    jobs = _summary(tmp_path)
    assert [jobs[n]["status"] for n in ("out/cornell", "out/furnace", "out/gone")] == [
        "done",
        "done",
        "failed",
    ]
    gone = jobs["out/gone"]
    assert gone["attempts"] == 1  # a missing file is not retried
    assert gone["message"] == f"{tmp_path / 'gone.obj'}: file not found"
    assert f"out/gone: failed in 0.0 s: {tmp_path / 'gone.obj'}: file not found" in err
    assert not (tmp_path / "out/gone").exists()
    assert "1 failed" in out and "2 done" in out

    # each job's outputs are those of a render of its own, bit for bit
    for name in ("cornell", "furnace"):
        assert api.verify_outputs(tmp_path / "out" / name) == []
        alone = api.render(tmp_path / f"{name}.obj", tmp_path / "alone" / name, SMALL)
        _, _, baked = read_radiosity_ply(tmp_path / "out" / name / f"{name}.ply")
        np.testing.assert_array_equal(baked, alone.result.radiosity.astype(np.float32))
        assert jobs[f"out/{name}"]["error"] == pytest.approx(
            max(alone.report["error"]["total_rms"])
        )

    # a rerun skips what is up to date; a changed scene or option renders again
    status, _, _ = run_cli(["bake", str(manifest), "-q"], capsys)
    assert status == 1
    jobs = _summary(tmp_path)
    assert jobs["out/cornell"]["status"] == jobs["out/furnace"]["status"] == "skipped"
    write_obj(furnace_box(reflectance=0.6), tmp_path / "furnace.obj")
    _manifest(tmp_path, "", defaults="tolerance = 1e-3")
    status, _, _ = run_cli(["bake", str(manifest), "--summary", str(tmp_path / "s.json")], capsys)
    assert status == 0
    record = json.loads((tmp_path / "s.json").read_text())
    assert [job["status"] for job in record["jobs"]] == ["skipped", "done"]
    assert record["counts"]["skipped"] == 1 and record["counts"]["done"] == 1


def test_options_that_change_the_outputs_render_again(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _scenes(tmp_path)
    manifest = _manifest(tmp_path)
    assert run_cli(["bake", str(manifest), "-q"], capsys)[0] == 0
    _manifest(tmp_path, defaults="tolerance = 1e-2")
    assert run_cli(["bake", str(manifest), "-q"], capsys)[0] == 0
    assert {job["status"] for job in _summary(tmp_path).values()} == {"done"}
    _manifest(tmp_path, defaults="tolerance = 1e-2\ncheckpoint_every = 7")  # no effect
    assert run_cli(["bake", str(manifest), "-q"], capsys)[0] == 0
    assert {job["status"] for job in _summary(tmp_path).values()} == {"skipped"}


class _FlakyRunner:
    """Runs jobs in this process; the first attempt of ``flaky`` is lost, as when its
    worker process is killed."""

    description = "test"
    slots = 2

    def __init__(self, flaky: str) -> None:
        self.flaky, self.lost, self.pending = flaky, False, []

    def submit(self, job: Job) -> Job:
        self.pending.append(job)
        return job

    def wait(self, handles):  # type: ignore[no-untyped-def]
        job = self.pending.pop(0)
        if job.name == self.flaky and not self.lost:
            self.lost = True
            return [(job, ConnectionError("worker gone"))]
        return [(job, JobResult(job.name, "done"))]

    def interrupt(self) -> None: ...

    def close(self) -> None: ...

    def abort(self) -> None: ...


def test_the_driver_retries_lost_jobs_a_bounded_number_of_times(tmp_path: Path) -> None:
    jobs = [Job(n, tmp_path / f"{n}.obj", tmp_path / n) for n in ("a", "b")]
    results = bake(jobs, _FlakyRunner("b"), retries=2)
    assert [(r.name, r.status, r.attempts) for r in results] == [("a", "done", 1), ("b", "done", 2)]
    results = bake(jobs, _FlakyRunner("b"), retries=0)
    assert results[1].status == "failed" and "worker lost (ConnectionError" in results[1].message


class _InterruptedRunner(_FlakyRunner):
    """Ctrl-C arrives while the driver waits."""

    def __init__(self) -> None:
        super().__init__("")
        self.calls: list[str] = []

    def wait(self, handles):  # type: ignore[no-untyped-def]
        raise KeyboardInterrupt

    def interrupt(self) -> None:
        self.calls.append("interrupt")

    def close(self) -> None:
        self.calls.append("close")

    def abort(self) -> None:
        self.calls.append("abort")


class _FailingRunner(_InterruptedRunner):
    def wait(self, handles):  # type: ignore[no-untyped-def]
        raise MemoryError


def test_an_exception_while_waiting_stops_and_closes_the_runner(tmp_path: Path) -> None:
    jobs = [Job("a", tmp_path / "a.obj", tmp_path / "a")]
    runner = _InterruptedRunner()
    with pytest.raises(KeyboardInterrupt):
        bake(jobs, runner)
    assert runner.calls == ["abort"]
    runner = _FailingRunner()
    with pytest.raises(MemoryError):
        bake(jobs, runner)
    assert runner.calls == ["interrupt", "close"]


def test_jobs_must_have_their_own_names_and_folders(tmp_path: Path) -> None:
    twins = [
        Job("a", tmp_path / "s.obj", tmp_path / "o"),
        Job("b", tmp_path / "s.obj", tmp_path / "x" / ".." / "o"),  # the same folder
    ]
    with pytest.raises(ValueError, match="same output"):
        bake(twins, _FlakyRunner(""))
    twins = [
        Job("a", tmp_path / "s.obj", tmp_path / "o"),
        Job("a", tmp_path / "s.obj", tmp_path / "p"),
    ]
    with pytest.raises(ValueError, match="same name"):
        bake(twins, _FlakyRunner(""))


def _wait_for_lock(folder: Path, process: subprocess.Popen[bytes], seconds: float = 120) -> int:
    """The pid of the process holding ``folder``'s lock, once it has one."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if process.poll() is not None:
            raise AssertionError(f"the bake ended first: {process.communicate()[1].decode()}")
        try:
            return int(json.loads((folder / "raytrad.lock").read_text())["pid"])
        except (OSError, ValueError, KeyError):
            time.sleep(0.05)
    raise AssertionError(f"no job started in {folder}")


def _wait_for_file(path: Path, process: subprocess.Popen[bytes], seconds: float = 120) -> None:
    """Return once ``path`` exists (the bake still running)."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if process.poll() is not None:
            raise AssertionError(f"the bake ended first: {process.communicate()[1].decode()}")
        if path.is_file():
            return
        time.sleep(0.02)
    raise AssertionError(f"no {path.name} in {seconds} s")


@pytest.mark.slow  # about 45 s: two bakes, one killed, one stopped and resumed
@POSIX
def test_a_killed_pool_worker_is_retried_and_a_sigterm_bake_resumes(tmp_path: Path) -> None:
    """kill -9 of a job's process: the job is retried and completes. SIGTERM to the bake:
    running jobs save checkpoints, the bake exits 143, and the next bake resumes them to
    the uninterrupted answer."""
    _scenes(tmp_path)
    manifest = _manifest(tmp_path, defaults="checkpoint_every = 0.2", receivers=3000)
    argv = [sys.executable, "-m", "raytrad", "bake", str(manifest), "--workers", "1"]
    bake_process = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    worker = _wait_for_lock(tmp_path / "out/cornell", bake_process)
    time.sleep(1.0)
    os.kill(worker, signal.SIGKILL)
    _, err = bake_process.communicate(timeout=600)
    assert bake_process.returncode == 0, err.decode()
    jobs = _summary(tmp_path)
    assert jobs["out/cornell"]["status"] == "done" and jobs["out/cornell"]["attempts"] == 2
    assert "worker lost" in err.decode() and "trying again" in err.decode()
    assert all(api.verify_outputs(tmp_path / "out" / n) == [] for n in ("cornell", "furnace"))

    # SIGTERM mid-job: a checkpoint, exit 143; the next bake resumes it
    assert not (tmp_path / "out/cornell/cornell.checkpoint.npz").exists()  # none left over
    _manifest(tmp_path, defaults="checkpoint_every = 0.2\ntolerance = 1e-5", receivers=3000)
    bake_process = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    _wait_for_lock(tmp_path / "out/cornell", bake_process)
    # the job's first periodic checkpoint says it is under way (a fixed sleep raced it:
    # the job came to finish within 2 s as renders got faster)
    _wait_for_file(tmp_path / "out/cornell/cornell.checkpoint.npz", bake_process)
    bake_process.send_signal(signal.SIGTERM)
    _, err = bake_process.communicate(timeout=600)
    assert bake_process.returncode == 128 + signal.SIGTERM, err.decode()
    jobs = _summary(tmp_path)
    assert jobs["out/cornell"]["status"] == "interrupted"
    assert jobs["out/furnace"]["status"] == "not run"
    assert (tmp_path / "out/cornell/cornell.checkpoint.npz").is_file()

    done = subprocess.run([*argv[:-2], "-q"], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    jobs = _summary(tmp_path)
    assert jobs["out/cornell"]["status"] == "done" and jobs["out/cornell"]["resumed"]
    straight = api.render(
        tmp_path / "cornell.obj",
        tmp_path / "straight",
        RenderSettings(
            mesh=MeshSettings(receivers=3000, patches=60), solve=SolveSettings(tolerance=1e-5)
        ),
    )
    _, _, baked = read_radiosity_ply(tmp_path / "out/cornell/cornell.ply")
    np.testing.assert_array_equal(baked, straight.result.radiosity.astype(np.float32))


def test_a_local_pool_shares_the_cores(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr("raytrad.batch.pool.worker_count", lambda: 8)
    assert (LocalPool(None, 3).slots, LocalPool(None, 3).threads) == (3, 2)
    assert (LocalPool(None, 20).slots, LocalPool(None, 20).threads) == (8, 1)
    assert (LocalPool(2, 20).slots, LocalPool(2, 20).threads) == (2, 4)
    with pytest.raises(ValueError, match="workers must be >= 1"):
        LocalPool(0, 3)


def test_a_job_asking_for_the_plot_is_rendered_until_the_plot_is_there(tmp_path: Path) -> None:
    from raytrad.batch import run_job

    _scenes(tmp_path)
    settings = RenderSettings(mesh=MeshSettings(receivers=300, patches=30))
    job = Job("furnace", tmp_path / "furnace.obj", tmp_path / "out", settings)
    assert run_job(job).status == "done"
    assert run_job(job).status == "skipped"
    with_plot = Job("furnace", job.scene, job.output, settings, plot=True)
    assert run_job(with_plot).status == "done"
    assert (tmp_path / "out/convergence.png").is_file()
    assert run_job(with_plot).status == "skipped"


@POSIX
def test_a_second_ctrl_c_aborts_the_bake(tmp_path: Path) -> None:
    _scenes(tmp_path)
    manifest = _manifest(tmp_path, receivers=6000)
    argv = [sys.executable, "-m", "raytrad", "bake", str(manifest), "--workers", "1"]
    process = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    worker = _wait_for_lock(tmp_path / "out/cornell", process)
    process.send_signal(signal.SIGINT)
    time.sleep(0.5)
    process.send_signal(signal.SIGINT)
    _, err = process.communicate(timeout=60)
    assert process.returncode == 130, err.decode()
    assert "aborted" in err.decode()
    with pytest.raises(ProcessLookupError):  # the job's process was killed, not left behind
        for _ in range(50):
            os.kill(worker, 0)
            time.sleep(0.1)


def test_a_job_stopped_while_refining_is_interrupted_and_resumed(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A job a signal stops in its second refinement round is ``interrupted``, not done
    (it used to count as done, and the next bake skipped its coarser mesh); the next run
    resumes it from its solve and its round to the uninterrupted bake, and the one after
    skips it."""
    from raytrad.batch import jobs
    from raytrad.core import adaptive

    scene = tmp_path / "cornell.obj"
    write_obj(cornell_box(), scene)
    settings = RenderSettings(mesh=MeshSettings(receivers=800, patches=60))
    straight = api.render(scene, tmp_path / "straight", settings)
    gathers = [0]
    original = adaptive._gather

    def gather(*args: object, **kwargs: object) -> object:
        gathers[0] += 1
        if gathers[0] == 2:  # as the job's signal handler would set it
            monkeypatch.setattr(jobs._StopOnSignal, "requested", True)
        return original(*args, **kwargs)

    monkeypatch.setattr(adaptive, "_gather", gather)
    job = Job("cornell", scene, tmp_path / "out", settings)
    first = jobs.run_job(job)
    assert first.status == "interrupted" and first.stop_reason == "interrupted"
    assert (tmp_path / "out" / "cornell.checkpoint.npz").is_file()
    monkeypatch.setattr(jobs._StopOnSignal, "requested", False)
    monkeypatch.setattr(adaptive, "_gather", original)
    second = jobs.run_job(job)
    assert second.status == "done" and second.resumed
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["resumed"]["form_factor_scales"]  # the pass's scales: no pass traced
    assert report["solve"]["form_factor_columns"] == report["solve"]["rays"] == 0
    _, _, got = read_radiosity_ply(tmp_path / "out" / "cornell.ply")
    np.testing.assert_array_equal(got, straight.result.radiosity.astype(np.float32))
    assert jobs.run_job(job).status == "skipped"
