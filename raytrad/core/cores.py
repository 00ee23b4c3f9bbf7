"""How busy other processes keep the cores this process may use.

The solver's parallel loops (:class:`raytrad.core.compiled.SolverLoops`) launch numba's
threads a few times a shot; each launch waits for all of them. While another process
keeps one of two cores busy, the thread meant for it waits for the scheduler, a few
milliseconds at a time, and the parallel loops run slower than one thread would.
:class:`OtherLoad` measures that load from the kernel's per-CPU times (Linux's
``/proc/stat``, for the CPUs in this process's affinity set) less this process's own
CPU time, over windows of :data:`WINDOW` seconds.
"""

from __future__ import annotations

import os
import time

#: Seconds of wall time a measurement of the other load spans at least; the kernel counts
#: CPU time in ticks of 10 ms, so a window holds about 20 of them on two cores.
WINDOW = 0.1
#: Where Linux keeps every CPU's time.
STAT = "/proc/stat"


class OtherLoad:
    """Cores' worth of CPU time other processes took on this process's CPUs, measured
    over the last window (:meth:`cores`); None where it cannot be read (not Linux)."""

    def __init__(self) -> None:
        try:
            self._cpus = {f"cpu{n}" for n in os.sched_getaffinity(0)}
            self._tick = 1.0 / os.sysconf("SC_CLK_TCK")
        except (AttributeError, ValueError, OSError):  # not Linux
            self._cpus = set()
        self._last = self._sample()
        self.latest: float | None = None

    def _sample(self) -> tuple[float, float, float] | None:
        """(wall, this process's CPU, every process's CPU on our CPUs) [s], or None."""
        if not self._cpus:
            return None
        try:
            with open(STAT, encoding="ascii") as stat:
                lines = stat.read().splitlines()
        except OSError:
            return None
        busy = 0
        for line in lines:
            fields = line.split()
            if fields and fields[0] in self._cpus:
                # user nice system idle iowait irq softirq steal: all but idle and iowait
                times = [int(x) for x in fields[1:9]]
                busy += sum(times) - times[3] - times[4]
        return time.perf_counter(), time.process_time(), busy * self._tick

    def cores(self) -> float | None:
        """Other processes' load over the last window [cores]: updated once
        :data:`WINDOW` seconds have passed since the last update, else the last figure
        (None before the first window ends, or where it cannot be read)."""
        if self._last is None or time.perf_counter() - self._last[0] < WINDOW:
            return self.latest
        now = self._sample()
        if now is None:
            return self.latest
        wall = now[0] - self._last[0]
        others = (now[2] - self._last[2]) - (now[1] - self._last[1])
        self._last = now
        self.latest = max(0.0, others / wall)
        return self.latest
