"""The exceptions raytrad raises: one small hierarchy the CLI turns into one line."""

from __future__ import annotations

from pathlib import Path


class RaytradError(Exception):
    """Base class of every error raytrad raises on purpose."""


class SceneError(RaytradError):
    """A scene file that cannot be used, naming the file and the problem.

    Parameters
    ----------
    path : path-like or None
        The offending file, or None for a scene built in memory.
    problem : str
        What is wrong, in words a user can act on.
    """

    def __init__(self, path: str | Path | None, problem: str) -> None:
        self.path = None if path is None else Path(path)
        self.problem = problem
        where = "<in-memory scene>" if path is None else str(path)
        super().__init__(f"{where}: {problem}")


class SettingsError(RaytradError):
    """An option value outside its valid range."""


class SolverError(RaytradError):
    """A solve that cannot produce a finite answer (for example reflectance 1 in a closed scene)."""
