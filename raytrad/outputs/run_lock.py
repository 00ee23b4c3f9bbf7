"""One run at a time per output folder: ``raytrad.lock``, with a stale-lock check.

Two renders into one folder would overwrite each other's files and delete each other's
checkpoint. A render holds ``<output_dir>/raytrad.lock`` (created exclusively, holding
its process id and host) from before it reads a checkpoint until it has written its
manifest. A second render into the folder is refused, naming the first, while that
process lives; a lock left by a process that is gone (killed with ``kill -9``, say) is
taken over with a warning. A holder on another host (a Dask cluster sharing the folder)
counts as gone once its lock has not been touched for :data:`STALE_SECONDS`.
"""

from __future__ import annotations

import json
import logging
import os
import socket
import threading
import time
from pathlib import Path
from types import TracebackType

from raytrad.errors import SettingsError
from raytrad.formats.atomic import leftover_temporaries

log = logging.getLogger(__name__)

LOCK = "raytrad.lock"
#: Seconds between a holder's touches of its lock.
HEARTBEAT_SECONDS = 30.0
#: Seconds without a touch after which a lock held on another host counts as gone.
STALE_SECONDS = 120.0


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process
        return True
    return True


class FolderLocked(SettingsError):
    """Another run holds the folder's lock.

    Attributes
    ----------
    elsewhere : bool
        The holder runs on another host, so whether it lives is known only from its
        heartbeat; its lock goes stale :data:`STALE_SECONDS` after the last one.
    """

    def __init__(self, message: str, elsewhere: bool) -> None:
        super().__init__(message)
        self.elsewhere = elsewhere


class RunLock:
    """Context manager holding an output folder's lock (see the module docstring).

    The folder is created if missing, and removed again on release when the run left it
    empty (a run that failed before writing anything). While held, a daemon thread touches
    the lock every :data:`HEARTBEAT_SECONDS`, so that runs on other hosts sharing the
    folder (a Dask cluster) can tell a live holder from a lost one.

    Raises
    ------
    FolderLocked
        Another live process holds the lock.
    """

    def __init__(self, output_dir: str | os.PathLike[str]) -> None:
        self.directory = Path(output_dir)
        self.path = self.directory / LOCK
        self.created = False
        self._stop_heartbeat = threading.Event()

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
            self._remove_leftovers()
            threading.Thread(target=self._heartbeat, name="raytrad-lock", daemon=True).start()
            return self
        raise SettingsError(f"{self.directory}: could not take the lock {self.path}")

    def _remove_leftovers(self) -> None:
        """Remove the temporary files of writes a killed run left (holding the lock, no
        other write can be under way here)."""
        leftovers = leftover_temporaries(self.directory)
        for path in leftovers:
            path.unlink(missing_ok=True)
        if leftovers:
            count = len(leftovers)
            files = "file" if count == 1 else "files"
            log.info("%s: removed %d temporary %s a killed run left", self.directory, count, files)

    def _heartbeat(self) -> None:
        while not self._stop_heartbeat.wait(HEARTBEAT_SECONDS):
            try:
                os.utime(self.path)
            except OSError:  # removed under us: nothing left to keep alive
                return

    def _clear_stale(self, host: str) -> None:
        """Remove a lock whose process is gone; refuse one whose process lives. On another
        host, a lock whose heartbeat stopped :data:`STALE_SECONDS` ago counts as gone."""
        try:
            holder = json.loads(self.path.read_text())
            pid, holder_host = int(holder["pid"]), str(holder["host"])
            quiet = time.time() - self.path.stat().st_mtime
        except (OSError, ValueError, KeyError, TypeError):
            pid, holder_host, quiet = -1, host, 0.0  # unreadable: a writer died mid-write
        elsewhere = holder_host != host
        if (elsewhere and quiet < STALE_SECONDS) or (not elsewhere and pid > 0 and _alive(pid)):
            where = f"pid {pid}" + (f" on {holder_host}" if elsewhere else "")
            raise FolderLocked(
                f"{self.directory}: another raytrad run ({where}) is writing to this folder; "
                f"wait for it, choose another output folder, or remove {self.path} if that "
                "run is gone",
                elsewhere,
            )
        log.warning("%s: taking over the lock of a run that is gone (pid %d)", self.path, pid)
        self.path.unlink(missing_ok=True)

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        self._stop_heartbeat.set()
        self.path.unlink(missing_ok=True)
        if self.created and not any(self.directory.iterdir()):
            self.directory.rmdir()
