"""The run manifest: a last small file that says an output folder holds one complete set.

Every file of a render is written atomically, but a run killed while writing can leave
new files beside old ones. So a render first removes the folder's
``raytrad-run.json`` (before it writes any output), and writes it anew last, listing every
output with its size and SHA-256. A reader, or ``raytrad verify DIR``
(:func:`verify_outputs`), then tells a complete, consistent set from an interrupted or mixed one:
no manifest, a listed file missing, or a file whose hash differs.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from raytrad import __version__
from raytrad.formats.atomic import atomic_write
from raytrad.scenefiles import SceneFile
from raytrad.settings import RenderSettings

MANIFEST = "raytrad-run.json"
#: Solve stop reasons of a run that ended on a budget before its tolerance (with a
#: checkpoint to resume): ``raytrad verify --finished`` fails such a set.
EARLY_STOPS = ("time-limit", "max-shots")


def invalidate(output_dir: Path) -> None:
    """Remove the folder's manifest before a run writes anything into it."""
    (Path(output_dir) / MANIFEST).unlink(missing_ok=True)


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def content_key(loaded: SceneFile, settings: RenderSettings) -> str:
    """SHA-256 of what a render's outputs are made from: the loaded scene (geometry,
    materials, names, lightmap UVs, cameras, output defaults), the resolved settings and
    the raytrad version.

    ``raytrad bake`` skips a job whose folder verifies and whose manifest holds this key.
    Settings that do not change the outputs (the cache size, the checkpoint interval) are
    left out.
    """
    digest = hashlib.sha256(f"raytrad {__version__}\n".encode())
    scene = loaded.scene
    for item in dataclasses.fields(scene):
        value = getattr(scene, item.name)
        if isinstance(value, np.ndarray):
            digest.update(f"{item.name} {value.dtype} {value.shape}\n".encode())
            digest.update(np.ascontiguousarray(value).tobytes())
        elif item.name != "source":  # the same content read from elsewhere is the same
            digest.update(f"{item.name} {value!r}\n".encode())
    fixed = dataclasses.replace(settings, cache_mb=0.0, checkpoint_seconds=1.0)
    described = {
        "settings": dataclasses.asdict(fixed),
        "cameras": [repr(camera) for camera in loaded.cameras],
        "output": loaded.output,
    }
    digest.update(json.dumps(described, sort_keys=True, default=repr).encode())
    return digest.hexdigest()


def write_manifest(
    output_dir: Path, outputs: dict[str, Path], report: dict[str, Any], key: str | None = None
) -> Path:
    """Write the manifest (atomically, last) listing every output file of the run.

    Parameters
    ----------
    output_dir : Path
    outputs : dict of str to Path
        The run's files by key (``ply``, ``report``, ``lightmap``...), all in ``output_dir``.
    report : dict
        The run's report, for the scene and the stop reason.
    key : str or None
        The run's :func:`content_key`.

    Returns
    -------
    Path of the manifest.
    """
    output_dir = Path(output_dir)
    files = {
        path.name: {"key": key, "bytes": path.stat().st_size, "sha256": _sha256(path)}
        for key, path in sorted(outputs.items())
        if Path(path).is_file()
    }
    manifest = {
        "raytrad": __version__,
        "written": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "scene": report.get("scene"),
        "stop_reason": report.get("solve", {}).get("stop_reason"),
        "content_key": key,
        "files": files,
    }
    path = output_dir / MANIFEST
    with atomic_write(path, "w") as handle:
        json.dump(manifest, handle, indent=2)
    return path


def read_manifest(directory: str | os.PathLike[str]) -> dict[str, Any] | None:
    """The folder's manifest as written, or None when it has none or it is unreadable."""
    try:
        manifest = json.loads((Path(directory) / MANIFEST).read_text())
    except (OSError, ValueError):
        return None
    return manifest if isinstance(manifest, dict) else None


def complete_set_key(directory: str | os.PathLike[str]) -> str | None:
    """The :func:`content_key` of the set in ``directory`` when the set verifies and its
    run was not interrupted; None otherwise."""
    manifest = read_manifest(directory)
    if manifest is None or verify_outputs(directory):
        return None
    key = manifest.get("content_key")
    return key if isinstance(key, str) else None


def verify_outputs(directory: str | os.PathLike[str], finished: bool = False) -> list[str]:
    """What is wrong with the output set in ``directory``; empty when it is complete and
    consistent (every file the manifest lists is there with its size and hash).

    Parameters
    ----------
    directory : path
    finished : bool
        Also count a run that ended before its tolerance as a problem: stopped by
        ``--time-limit`` or ``--max-shots``, or with its refinement cut short, it is a
        whole set of the best answer it had, and it left a checkpoint for ``--resume``.
        Without this such a set verifies (it is what the budget asked for).

    Returns
    -------
    list of str
        One line per problem: no manifest (a run killed while writing, or none), an
        unreadable manifest, a run stopped by Ctrl-C or a signal (its outputs are the
        solution so far), with ``finished`` a run that stopped early, a listed file
        missing, or one whose size or hash differs (a mixed set).
    """
    directory = Path(directory)
    path = directory / MANIFEST
    if not path.is_file():
        return [
            f"{path}: no manifest: the set is incomplete (a run was interrupted or is "
            "still writing) or was not written by raytrad"
        ]
    try:
        manifest = json.loads(path.read_text())
        files = manifest["files"]
    except (ValueError, KeyError, TypeError) as exc:
        return [f"{path}: unreadable manifest ({exc})"]
    problems = []
    if manifest.get("stop_reason") == "interrupted":
        problems.append(
            f"{path}: the run was interrupted (Ctrl-C or a signal): its outputs are the "
            "solution so far; resume it to finish"
        )
    elif finished and (early := _early_stop(manifest)):
        solve_stop = manifest.get("stop_reason") in EARLY_STOPS
        what = "stopped before its tolerance" if solve_stop else "had its refinement cut short"
        problems.append(
            f"{path}: the run {what} ({early}): its outputs are the best answer it had; "
            "render again with --resume to go on (each resumed run gets its --time-limit "
            "again, and goes on from the refinement rounds kept; without a limit it "
            "finishes)"
        )
    for name, entry in sorted(files.items()):
        file = directory / name
        if not file.is_file():
            problems.append(f"{file}: listed but missing")
        elif file.stat().st_size != entry.get("bytes") or _sha256(file) != entry.get("sha256"):
            problems.append(f"{file}: differs from the run that wrote the manifest (mixed set)")
    return problems


def _early_stop(manifest: dict[str, Any]) -> str | None:
    """How a run ended before its tolerance (its solve stopped on a budget, or it kept a
    checkpoint to resume: its refinement was cut short), or None when it did not."""
    reasons = []
    if manifest.get("stop_reason") in EARLY_STOPS:
        reasons.append(str(manifest["stop_reason"]))
    files = manifest.get("files")
    if isinstance(files, dict) and any(
        isinstance(entry, dict) and entry.get("key") == "checkpoint" for entry in files.values()
    ):
        reasons.append("a checkpoint kept to resume")
    return ", ".join(reasons) or None
