"""The run manifest: a last small file that says an output folder holds one complete set.

Every file of a render is written atomically, but a run killed while writing can leave
new files beside old ones. So a render first removes the folder's
``raytrad-run.json`` (before it writes any output), and writes it anew last, listing every
output with its size and SHA-256. A reader, or ``raytrad verify DIR``
(:func:`verify_outputs`), then tells a complete, consistent set from an interrupted or mixed one:
no manifest, a listed file missing, or a file whose hash differs.
"""

from __future__ import annotations

import hashlib
import json
import time
from pathlib import Path
from typing import Any

from raytrad import __version__
from raytrad.formats.atomic import atomic_write

MANIFEST = "raytrad-run.json"


def invalidate(output_dir: Path) -> None:
    """Remove the folder's manifest before a run writes anything into it."""
    (Path(output_dir) / MANIFEST).unlink(missing_ok=True)


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def write_manifest(output_dir: Path, outputs: dict[str, Path], report: dict[str, Any]) -> Path:
    """Write the manifest (atomically, last) listing every output file of the run.

    Parameters
    ----------
    output_dir : Path
    outputs : dict of str to Path
        The run's files by key (``ply``, ``report``, ``lightmap``...), all in ``output_dir``.
    report : dict
        The run's report, for the scene and the stop reason.

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
        "files": files,
    }
    path = output_dir / MANIFEST
    with atomic_write(path, "w") as handle:
        json.dump(manifest, handle, indent=2)
    return path


def verify_outputs(directory: str | Path) -> list[str]:
    """What is wrong with the output set in ``directory``; empty when it is complete and
    consistent (every file the manifest lists is there with its size and hash).

    Returns
    -------
    list of str
        One line per problem: no manifest (an interrupted run, or none), an unreadable
        manifest, a listed file missing, or one whose size or hash differs (a mixed set).
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
    for name, entry in sorted(files.items()):
        file = directory / name
        if not file.is_file():
            problems.append(f"{file}: listed but missing")
        elif file.stat().st_size != entry.get("bytes") or _sha256(file) != entry.get("sha256"):
            problems.append(f"{file}: differs from the run that wrote the manifest (mixed set)")
    return problems
