"""Write a file so that readers see either the old content or the complete new content."""

from __future__ import annotations

import contextlib
import logging
import os
import re
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

log = logging.getLogger(__name__)

_MODES = ("w", "wb")


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike[str], mode: str = "wb") -> Iterator[IO[Any]]:
    """Open a temporary file next to ``path`` and move it over ``path`` when the body succeeds.

    The data goes to a hidden temporary file in the same directory (so the final
    :func:`os.replace` is an atomic rename on one file system), is flushed and fsynced,
    and only then replaces ``path``. If the body raises, the temporary file is deleted,
    ``path`` is left as it was and the exception propagates.

    Parameters
    ----------
    path : path-like
        The file to write. Its parent directory is created if missing.
    mode : {"wb", "w"}
        Binary, or text (UTF-8 with ``"\\n"`` line endings).

    Yields
    ------
    file object
        The open temporary file to write to.
    """
    if mode not in _MODES:
        raise ValueError(f"atomic_write mode must be one of {_MODES}, not {mode!r}")
    text = mode == "w"
    with (
        atomic_path(path, suffix=".tmp") as temporary,
        open(
            temporary, mode, encoding="utf-8" if text else None, newline="\n" if text else None
        ) as handle,
    ):
        yield handle
        handle.flush()
        os.fsync(handle.fileno())


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str], suffix: str | None = None) -> Iterator[Path]:
    """A temporary path next to ``path`` that replaces ``path`` when the body succeeds.

    For writers that take a file name (OpenImageIO chooses the format by extension, so the
    default suffix keeps the target's). The file is fsynced before the rename; on error it
    is removed and ``path`` is left as it was.

    Parameters
    ----------
    path : path-like
        The file to write; its parent directory is created if missing.
    suffix : str or None
        Suffix of the temporary name; default ``.tmp`` plus the target's suffix.
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    handle, name = tempfile.mkstemp(
        dir=target.parent,
        prefix=f".{target.name}.",
        suffix=f".tmp{target.suffix}" if suffix is None else suffix,
    )
    os.close(handle)
    temporary = Path(name)
    try:
        yield temporary
        with open(temporary, "rb+") as written:
            os.fsync(written.fileno())
        os.chmod(temporary, _final_permissions(target))
        os.replace(temporary, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            temporary.unlink()
        raise
    _fsync_directory(target.parent)


def _final_permissions(target: Path) -> int:
    """Permission bits for the new file: those of the file it replaces, else 0o666 & ~umask.

    (A temporary file is created 0o600; without this every written file would be private.)
    """
    try:
        return target.stat().st_mode & 0o7777
    except FileNotFoundError:
        return 0o666 & ~_umask()


def _umask() -> int:
    """The process umask, read without changing it where the platform allows."""
    with contextlib.suppress(OSError, ValueError):
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _fsync_directory(directory: Path) -> None:
    """Make the rename durable (POSIX); a no-op where directories cannot be opened."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        log.debug("could not fsync directory %s", directory)
    finally:
        os.close(fd)


#: Names :func:`atomic_path` and :func:`atomic_write` give their temporary files:
#: ``.<target>.<8 random characters>.tmp[<suffix>]``.
_TEMPORARY = re.compile(r"^\..+\.[a-z0-9_]{8}\.tmp(\.[A-Za-z0-9]+)?$")


def leftover_temporaries(directory: str | os.PathLike[str]) -> list[Path]:
    """Temporary files of atomic writes in ``directory`` that never became their target:
    what a process killed mid-write (``kill -9``) leaves. Only a caller that knows no
    write is under way there (holding the folder's run lock) may remove them."""
    folder = Path(directory)
    if not folder.is_dir():
        return []
    return sorted(p for p in folder.iterdir() if p.is_file() and _TEMPORARY.match(p.name))
