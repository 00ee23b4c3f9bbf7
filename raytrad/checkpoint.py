"""Saving and resuming a solve: the solver state in one ``.npz`` written atomically.

A checkpoint carries a fingerprint of everything that defines the discrete system (scene
content, mesh and form-factor settings); resuming with anything else is refused rather than
silently mixing two systems.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

import numpy as np

from raytrad.errors import RaytradError
from raytrad.io.atomic import atomic_write
from raytrad.solver import SolverState

_ARRAYS = ("irradiance", "patch_radiosity", "shot", "captured", "absorbed", "escaped")
_SCALARS = ("shots", "rays", "seconds", "ambient_gain", "min_unshot", "damping_events")


def fingerprint(scene_bytes: bytes, settings: dict[str, Any]) -> str:
    """SHA-256 of the scene content and the settings that shape the discrete system."""
    digest = hashlib.sha256(scene_bytes)
    digest.update(json.dumps(settings, sort_keys=True, default=str).encode())
    return digest.hexdigest()


def save_checkpoint(path: Path, state: SolverState, key: str) -> None:
    """Write ``state`` to ``path`` atomically (temp file + rename)."""
    arrays = {name: getattr(state, name) for name in _ARRAYS}
    scalars = {name: float(getattr(state, name)) for name in _SCALARS}
    with atomic_write(path) as handle:
        np.savez(handle, fingerprint=np.array(key), scalars=np.array(json.dumps(scalars)), **arrays)


def load_checkpoint(path: Path, key: str) -> SolverState:
    """Read a checkpoint written by :func:`save_checkpoint` for the same system.

    Raises
    ------
    RaytradError
        The file is unreadable or belongs to another scene or other settings.
    """
    try:
        with np.load(path, allow_pickle=False) as data:
            if str(data["fingerprint"]) != key:
                raise RaytradError(
                    f"{path}: checkpoint was made for another scene or other settings; "
                    "delete it or run without --resume"
                )
            scalars = json.loads(str(data["scalars"]))
            arrays = {name: np.array(data[name]) for name in _ARRAYS}
    except (OSError, KeyError, ValueError) as exc:
        raise RaytradError(f"{path}: cannot read checkpoint ({exc})") from exc
    return SolverState(
        **arrays,
        shots=int(scalars["shots"]),
        rays=int(scalars["rays"]),
        seconds=float(scalars["seconds"]),
        ambient_gain=float(scalars["ambient_gain"]),
        min_unshot=float(scalars["min_unshot"]),
        damping_events=int(scalars.get("damping_events", 0)),
    )
