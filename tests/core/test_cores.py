"""Other processes' load on this process's CPUs (:mod:`raytrad.core.cores`), measured
against a CPU-time file and clocks set by the test, and against a real busy process."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

from raytrad.core import cores


class _Clocks:
    """``time.perf_counter`` and ``time.process_time`` set by the test."""

    def __init__(self) -> None:
        self.wall = 100.0
        self.cpu = 5.0

    def perf_counter(self) -> float:
        return self.wall

    def process_time(self) -> float:
        return self.cpu


def _stat(path: Path, busy: dict[int, int], idle: int = 1000) -> None:
    """A ``/proc/stat`` whose CPU ``n`` has spent ``busy[n]`` ticks in user time."""
    lines = [f"cpu  {sum(busy.values())} 0 0 {idle} 0 0 0 0 0 0"]
    lines += [f"cpu{n} {b} 0 0 {idle} 7 0 0 0 0 0" for n, b in busy.items()]
    path.write_text("\n".join([*lines, "intr 1 2 3", "ctxt 4"]) + "\n", encoding="ascii")


@pytest.mark.skipif(not hasattr(cores.os, "sched_getaffinity"), reason="Linux only")
def test_other_load_is_the_cpu_time_of_our_cpus_less_our_own_over_a_window(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Over a window: ticks of the CPUs we may use (user, nice, system, irq, softirq,
    steal; not idle, not iowait, not other CPUs') less our own CPU time, per wall second;
    nothing new within a window, and never below zero."""
    stat = tmp_path / "stat"
    clocks = _Clocks()
    monkeypatch.setattr(cores, "STAT", str(stat))
    monkeypatch.setattr(cores, "time", clocks)
    monkeypatch.setattr(cores.os, "sched_getaffinity", lambda pid: {0, 1})
    monkeypatch.setattr(cores.os, "sysconf", lambda name: 100)
    _stat(stat, {0: 1000, 1: 2000, 2: 0})
    load = cores.OtherLoad()
    assert load.cores() is None  # no window yet
    _stat(stat, {0: 1000 + 20, 1: 2000 + 10, 2: 99_999})  # 0.3 s busy on ours in 0.2 s
    clocks.wall += 0.2
    clocks.cpu += 0.1  # 0.1 s of it ours
    assert load.cores() == pytest.approx(1.0)
    _stat(stat, {0: 1000 + 40, 1: 2000 + 10, 2: 99_999})
    clocks.wall += 0.05  # within the window: the last figure
    assert load.cores() == pytest.approx(1.0)
    clocks.wall += 0.06
    clocks.cpu += 0.3  # more than the ticks say (their 10 ms steps): zero, not negative
    assert load.cores() == 0.0


def test_other_load_is_unknown_where_the_cpu_times_cannot_be_read(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """No ``/proc/stat`` (not Linux, a sandbox): no figure, and no error."""
    monkeypatch.setattr(cores, "STAT", str(tmp_path / "missing"))
    load = cores.OtherLoad()
    time.sleep(cores.WINDOW * 1.2)
    assert load.cores() is None


@pytest.mark.skipif(
    not Path(cores.STAT).exists() or len(cores.os.sched_getaffinity(0)) < 2,
    reason="needs Linux's CPU times and two CPUs",
)
def test_a_busy_process_on_our_cpus_counts_as_other_load() -> None:
    """A process spinning on one of our CPUs counts as most of a core."""
    load = cores.OtherLoad()
    spin = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        time.sleep(0.3)
        load.cores()  # the window that saw the process start
        time.sleep(cores.WINDOW * 3)
        measured = load.cores()
    finally:
        spin.kill()
        spin.wait()
    assert measured is not None and measured > 0.6
