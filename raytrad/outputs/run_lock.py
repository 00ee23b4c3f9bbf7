"""One run at a time per output folder: ``raytrad.lock``, with a stale-lock check.

Two renders into one folder would overwrite each other's files and delete each other's
checkpoint. A render holds ``<output_dir>/raytrad.lock`` (created exclusively, holding
its process id and host) from before it reads a checkpoint until it has written its
manifest. A second render into the folder is refused, naming the first, while that
process lives; a lock left by a process that is gone (killed with ``kill -9``, say) is
taken over with a warning.
"""

from __future__ import annotations

import json
import logging
import os
import socket
from pathlib import Path
from types import TracebackType

from raytrad.errors import SettingsError

log = logging.getLogger(__name__)

LOCK = "raytrad.lock"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process
        return True
    return True


class RunLock:
    """Context manager holding an output folder's lock (see the module docstring).

    The folder is created if missing, and removed again on release when the run left it
    empty (a run that failed before writing anything).

    Raises
    ------
    SettingsError
        Another live process holds the lock.
    """

    def __init__(self, output_dir: str | os.PathLike[str]) -> None:
        self.directory = Path(output_dir)
        self.path = self.directory / LOCK
        self.created = False

    def __enter__(self) -> RunLock:
        self.created = not self.directory.exists()
        self.directory.mkdir(parents=True, exist_ok=True)
        host = socket.gethostname()
        for _ in range(2):
            try:
                fd = os.open(self.path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            except FileExistsError:
                self._clear_stale(host)
                continue
            with os.fdopen(fd, "w") as handle:
                json.dump({"pid": os.getpid(), "host": host}, handle)
            return self
        raise SettingsError(f"{self.directory}: could not take the lock {self.path}")

    def _clear_stale(self, host: str) -> None:
        """Remove a lock whose process is gone; refuse one whose process lives."""
        try:
            holder = json.loads(self.path.read_text())
            pid, holder_host = int(holder["pid"]), str(holder["host"])
        except (OSError, ValueError, KeyError, TypeError):
            pid, holder_host = -1, host  # unreadable: a writer died mid-write
        if holder_host != host or (pid > 0 and _alive(pid)):
            where = f"pid {pid}" + ("" if holder_host == host else f" on {holder_host}")
            raise SettingsError(
                f"{self.directory}: another raytrad run ({where}) is writing to this folder; "
                f"wait for it, choose another output folder, or remove {self.path} if that "
                "run is gone"
            )
        log.warning("%s: taking over the lock of a run that is gone (pid %d)", self.path, pid)
        self.path.unlink(missing_ok=True)

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        self.path.unlink(missing_ok=True)
        if self.created and not any(self.directory.iterdir()):
            self.directory.rmdir()
