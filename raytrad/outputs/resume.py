"""Resuming a stopped solve: its state saved with the fingerprint of the system it solves.

The fingerprint covers what the solve depends on: the loaded scene's geometry and
materials (:func:`raytrad.scene.scene_digests`, so an edited ``.mtl`` beside an OBJ or an
edited mesh file of a TOML scene counts, not only the bytes of the file named on the
command line) and the settings that shape the discrete system. A resume against anything
else is refused with one line saying what changed.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import os
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from raytrad.core.adaptive import Refinement, RefineSettings, goes_on_from
from raytrad.core.convergence import ErrorLog
from raytrad.core.formfactor import BALANCED_SCALES, FormFactorEngine
from raytrad.core.mesh import RadiosityMesh
from raytrad.core.solver import SolveResult, SolverState, SolveSettings
from raytrad.errors import RaytradError
from raytrad.formats.checkpoint import Spool, read_checkpoint, write_checkpoint
from raytrad.scene import Scene, scene_digests

log = logging.getLogger(__name__)

#: Version of the checkpoint layout; a checkpoint of another layout is refused.
LAYOUT = 5  # 4: gather sources beyond the receivers are cluster-tree nodes; 5: receivers
# numbered in Morton order (a column of layout 4 indexes another numbering)
#: Prefix of the arrays holding the columns of a form-factor pass cut short.
PASS = "pass_"
#: Prefix of the arrays holding a refinement's mesh (:func:`save_refinement`).
MESH = "mesh_"
#: Prefix of the arrays holding a finished pass's balanced scales (:class:`SavedScales`).
SCALES = "balanced_"


class SavedScales(NamedTuple):
    """A finished form-factor pass as a checkpoint keeps it without its columns: the
    balanced ``scales``
    (:meth:`~raytrad.core.formfactor.FormFactorEngine.balanced_scales`) and the
    ``summary`` of what balancing did. A resume builds its engine from them
    (:meth:`~raytrad.core.formfactor.FormFactorEngine.restore_balance`) and traces no
    pass: refinement needs only the scales, and a shot that needs a column computes it."""

    scales: dict[str, np.ndarray]
    summary: dict[str, Any]


class ResumePoint(NamedTuple):
    """What ``--resume`` continues from (:func:`resume_point`); None where the checkpoint
    has nothing of it, every field without a checkpoint."""

    state: SolverState | None = None
    columns: dict[str, Any] | None = None
    history: ErrorLog | None = None
    scales: SavedScales | None = None


def fingerprint(scene: Scene, system_settings: dict[str, Any]) -> dict[str, Any]:
    """What a checkpoint must match to be resumed: scene digests and system settings.

    Parameters
    ----------
    scene : Scene
        The scene as loaded (before repair: repair is a function of it).
    system_settings : dict
        The settings that define the discrete system
        (:meth:`raytrad.settings.RenderSettings.system_settings`), plain values.
    """
    return {"layout": LAYOUT, "settings": _flat(system_settings), **scene_digests(scene)}


def save_state(
    path: str | os.PathLike[str],
    state: SolverState,
    key: dict[str, Any],
    columns: dict[str, np.ndarray] | Iterable[dict[str, np.ndarray]] | None = None,
    whole_pass: bool = False,
    history: ErrorLog | None = None,
    scales: SavedScales | None = None,
) -> None:
    """Write ``state``, its fingerprint ``key`` and the ``columns`` of a form-factor pass
    (cut short, or whole under a solve cut short) to ``path`` atomically: packed
    (:meth:`~raytrad.core.formfactor.FormFactorEngine.pass_columns`) or column by column
    (:meth:`~raytrad.core.formfactor.FormFactorEngine.pass_column_parts`), gathered on
    disk first (:class:`~raytrad.formats.checkpoint.Spool`) so that no more than a
    column is held at once. ``whole_pass``: the columns are every column of a finished
    pass, and ``state`` was shot through them (:func:`resume_point` keeps both).
    ``history``: the solve's error log so far, which the resumed run's report goes on.
    ``scales``: the finished pass's balanced scales (a few arrays the size of the
    receivers), with which a resume needs no pass."""
    state_arrays, scalars = state.to_record()
    arrays: dict[str, Any] = dict(state_arrays)
    record = {"fingerprint": key, "scalars": scalars, "whole_pass": whole_pass}
    if history is not None:
        record["history"] = history.as_dict()
    if scales is not None and scales.scales:
        arrays |= {SCALES + name: values for name, values in scales.scales.items()}
        record["balance"] = scales.summary
    if columns is None or isinstance(columns, dict):
        arrays |= {PASS + name: values for name, values in (columns or {}).items()}
        write_checkpoint(path, arrays, record)
        return
    with Spool() as spool:
        for parts in columns:
            spool.add(parts)
        arrays |= {PASS + name: values for name, values in spool.arrays().items()}
        write_checkpoint(path, arrays, record)


def save_run(
    path: str | os.PathLike[str],
    state: SolverState,
    key: dict[str, Any],
    engine: FormFactorEngine,
    whole_pass: bool = False,
    logs: list[ErrorLog] | None = None,
    balance: Callable[[], dict[str, Any]] | None = None,
) -> None:
    """:func:`save_state` with what a run's ``engine`` holds: the columns of its pass (cut
    short; every one with ``whole_pass``) and, once the pass is balanced, with
    ``whole_pass`` or when the engine holds no column (released after the solve, or
    ``--cache-mb 0``), its balanced scales with balancing's summary, ``balance()``
    (:class:`SavedScales`; not asked for otherwise); the solve's error log is ``logs[0]``
    (none while ``logs`` is empty).

    A state saved during the solve keeps no scales: its resume's shots need nearly every
    column, which a pass computes on every core faster than shots ask for them one at a
    time (the default Cornell box killed at shot 192 resumed in 15.8 s through a pass,
    against 17.3 s from scales, its solve then 6.9 s against a 5.2 s pass and 0.9 s of
    shots)."""
    done = engine.balanced_scales() if whole_pass or not engine.held_bytes else {}
    scales = SavedScales(done, dict(balance() if balance else {})) if done else None
    columns = engine.pass_column_parts(whole_pass)
    save_state(path, state, key, columns, whole_pass, logs[0] if logs else None, scales)


def last_save(checkpoint: Path) -> tuple[int, float]:
    """(bytes, seconds) of the save that wrote ``checkpoint``: its size and the
    ``timings_seconds.checkpoint`` of the ``report.json`` beside it, when that report was
    written after it; else (0, 0.0). A resumed run plans its own save at that rate
    (:meth:`raytrad.core.pipeline.RunBudget.measured`): a checkpoint holds every column so
    far, so each run of a time-limited chain writes more, and at 150 000 receivers the
    runs wrote at 84-110 MB/s against the 150 planned, ending 2-7 s past a 20 s limit
    (a newcomer's chain, 2026-12-06)."""
    report = checkpoint.parent / "report.json"
    try:
        if report.stat().st_mtime < checkpoint.stat().st_mtime:
            return 0, 0.0  # another run's report: the checkpoint came later
        seconds = float(json.loads(report.read_text())["timings_seconds"]["checkpoint"])
        return checkpoint.stat().st_size, seconds
    except (OSError, ValueError, KeyError, TypeError):
        return 0, 0.0


def columns_kept(engine: FormFactorEngine, result: SolveResult) -> bool:
    """Whether the checkpoint a run saves after its solve keeps every column of ``engine``
    (:func:`save_run`'s ``whole_pass``): a solve cut short does, since its resume shoots
    on. A converged one's resume refines and writes from the balanced scales alone, so
    its columns are released here and the checkpoint keeps the scales: at 60 000
    receivers a time-limited run had written 630 MB of columns its resume never read."""
    if result.stop_reason == "converged":
        engine.release_columns()
        return False
    return engine.complete


def resume_point(
    path: Path,
    key: dict[str, Any],
    resume: bool | str = True,
    solve: SolveSettings | None = None,
) -> ResumePoint:
    """What ``--resume`` continues from: the saved solver state, the columns of a
    form-factor pass cut short, the error log of the solve so far and the balanced scales
    of a finished pass (:class:`ResumePoint`; every field None without a checkpoint, or
    with ``resume`` False; the log None when the checkpoint has none, or an unreadable one).

    With ``resume`` ``"auto"`` (batch jobs), a checkpoint that does not match or cannot be
    read is passed over with a warning, and the run starts afresh.

    A state saved while the pass was incomplete is dropped (None): its shots went through
    factors not yet balanced, so the solve starts again once the pass is done (those were
    only the first, direct-light shots), and a resumed run gives the uninterrupted answer.
    A state saved after the pass comes back with its scales, or every column when a solve
    cut short saved them: the resume shoots, or refines, without tracing the pass again.
    When the state's solve had reached ``solve``'s tolerance (its error log's last row)
    and the scales were kept, the columns stay on disk: refinement needs none, and a shot
    that does computes its column (a time limit's chain resumed 630 MB it never read).

    Raises
    ------
    RaytradError
        As :func:`load_state`, when ``resume`` is True; also when the scales are damaged.
    """
    if not resume:
        return ResumePoint()
    strict = resume is True
    if not Path(path).exists():
        say = log.warning if strict else log.info  # batch jobs resume whenever they can
        say("%s: no checkpoint to resume from; starting afresh", path)
        return ResumePoint()
    try:
        arrays, record = read_checkpoint(path, lazy=_LAZY)  # the columns stay on disk
        state = _saved_state(path, arrays, record, key)
        columns, whole = _pass_columns(path, arrays, record)
        scales = _saved_scales(path, arrays, record, state)
    except RaytradError as exc:
        if strict:
            raise
        log.warning("%s; starting afresh", exc)
        return ResumePoint()
    if columns and not whole:
        log.info(
            "resuming the form-factor pass from %s: %d columns computed before the stop "
            "(by the pass, or for the solve's shots after it)",
            path,
            len(columns["patch"]),
        )
        return ResumePoint(columns=columns)
    history = _history(path, record)
    if columns and scales is not None and _converged(history, state, solve):
        log.info("%s: the solve had converged; its columns are not read back", path)
        columns = {}
    log.info("resuming from %s at shot %d", path, state.shots)
    return ResumePoint(state, columns or None, history, scales)


def _converged(history: ErrorLog | None, state: SolverState, solve: SolveSettings | None) -> bool:
    """Whether the error log of a saved ``state`` ends at its shots with a residual within
    ``solve``'s tolerance (False without either)."""
    if history is None or solve is None or not history.shots:
        return False
    return history.shots[-1] == state.shots and history.residual[-1] <= solve.tolerance


def _saved_scales(
    path: str | os.PathLike[str], arrays: dict[str, Any], record: dict[str, Any], state: SolverState
) -> SavedScales | None:
    """The balanced scales :func:`save_state` kept in a checkpoint's ``arrays`` and
    ``record`` (None: it kept none), checked against the sizes of ``state``."""
    scales = {name[len(SCALES) :]: a for name, a in arrays.items() if name.startswith(SCALES)}
    if not scales:
        return None
    sizes = (len(state.irradiance), len(state.shot))
    if set(scales) != set(BALANCED_SCALES) or not isinstance(record.get("balance"), dict):
        raise RaytradError(f"{path}: cannot read checkpoint (its balanced scales are incomplete)")
    if any(np.shape(scales[n]) != (sizes[k],) for n, k in BALANCED_SCALES.items()):
        raise RaytradError(f"{path}: cannot read checkpoint (its balanced scales are damaged)")
    return SavedScales({n: np.asarray(a) for n, a in scales.items()}, record["balance"])


def _history(path: str | os.PathLike[str], record: dict[str, Any]) -> ErrorLog | None:
    """The error log saved in a checkpoint's ``record`` (None: none, or unreadable)."""
    if record.get("history") is None:
        return None
    try:
        return ErrorLog.from_dict(record["history"])
    except (ValueError, TypeError, KeyError) as exc:
        log.warning("%s: its error log cannot be read (%s): the report's starts anew", path, exc)
        return None


def load_pass_columns(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The form-factor columns :func:`save_state` stored in ``path`` ({} if none: the pass
    was complete), the large arrays left on disk
    (:class:`~raytrad.formats.checkpoint.StoredArray`, read a column at a time by
    :meth:`~raytrad.core.formfactor.FormFactorEngine.restore_columns`). Read after
    :func:`load_state` has checked the fingerprint."""
    return _pass_columns(path, *read_checkpoint(path, lazy=_LAZY))[0]


def _pass_columns(
    path: str | os.PathLike[str], arrays: dict[str, Any], record: dict[str, Any]
) -> tuple[dict[str, Any], bool]:
    """:func:`load_pass_columns` from a checkpoint's ``arrays`` and ``record``, and
    whether they are a whole pass (``whole_pass``)."""
    columns = {name[len(PASS) :]: a for name, a in arrays.items() if name.startswith(PASS)}
    if columns and not _consistent(columns):
        raise RaytradError(f"{path}: cannot read checkpoint (its form-factor columns are damaged)")
    return columns, bool(record.get("whole_pass", False))


#: Packed column arrays, and the length array that partitions each.
_PARTS = {
    "receivers": "length",
    "factors": "length",
    "near_receivers": "near_length",
    "near_factors": "near_length",
    "near_pointer": "near_length",
    "sources": "source_length",
    "weights": "source_length",
}


#: The packed column arrays a resume reads a column at a time
#: (:class:`~raytrad.formats.checkpoint.StoredArray`): a whole pass at a million
#: receivers is gigabytes, more than the run's memory bound.
_LAZY = frozenset(PASS + name for name in _PARTS)


def _consistent(columns: dict[str, Any]) -> bool:
    """Every packed array is there, partitioned exactly by its lengths, one per patch."""
    names = {"patch", *_PARTS, *_PARTS.values()}
    if not names <= set(columns) or any(columns[n].ndim != 1 for n in names):
        return False
    count = len(columns["patch"])
    if any(len(columns[n]) != count or (columns[n] < 0).any() for n in set(_PARTS.values())):
        return False
    return all(len(columns[a]) == int(columns[n].sum()) for a, n in _PARTS.items())


def load_state(path: str | os.PathLike[str], key: dict[str, Any]) -> SolverState:
    """The state saved in ``path``, if it was saved for the system ``key`` describes.

    Raises
    ------
    RaytradError
        The file is unreadable, or was made for another system: the message names the
        first difference (a setting, a material, an object of the scene).
    """
    return _saved_state(path, *read_checkpoint(path), key)


def _saved_state(
    path: str | os.PathLike[str],
    arrays: dict[str, Any],
    record: dict[str, Any],
    key: dict[str, Any],
) -> SolverState:
    """:func:`load_state` from a checkpoint's ``arrays`` and ``record``."""
    saved = record.get("fingerprint")
    change = difference(saved, key) if isinstance(saved, dict) else "its format is unknown"
    if change:
        raise RaytradError(
            f"{path}: cannot resume: {change} since the checkpoint was made; delete it or "
            "run without --resume"
        )
    try:
        return SolverState.from_record(arrays, record["scalars"])
    except (KeyError, TypeError, ValueError) as exc:
        raise RaytradError(f"{path}: cannot read checkpoint (missing {exc})") from exc


def difference(saved: dict[str, Any], current: dict[str, Any]) -> str:
    """The first way ``current`` differs from ``saved``, in words; "" when they match."""
    if saved.get("layout") != current.get("layout"):
        return "the checkpoint layout changed (it was made by another raytrad version)"
    for name, value in current["settings"].items():
        before = saved.get("settings", {}).get(name)
        if before != value:
            return f"setting {name} changed ({before} -> {value})"
    for group, what in (("materials", "material"), ("objects", "mesh")):
        before, now = saved.get(group, {}), current[group]
        for name in now:
            if name not in before:
                return f"the scene gained {what} {name!r}"
            if before[name] != now[name]:
                detail = " (reflectance, emission or sidedness)" if what == "material" else ""
                return f"{what} {name!r} changed{detail}"
        for name in before:
            if name not in now:
                return f"the scene lost {what} {name!r}"
    return ""


def _flat(settings: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested settings as ``{"mesh.receivers": 20000, ...}`` (JSON-ready values)."""
    out: dict[str, Any] = {}
    for name, value in settings.items():
        if isinstance(value, dict):
            out.update(_flat(value, f"{prefix}{name}."))
        else:
            out[f"{prefix}{name}"] = value
    return out


def checkpoint_path(output_dir: Path, stem: str) -> Path:
    """Where a run's checkpoint lives: ``<output_dir>/<stem>.checkpoint.npz``."""
    return output_dir / f"{stem}.checkpoint.npz"


def refinement_path(checkpoint: Path) -> Path:
    """Where a run keeps the rounds of a refinement cut short, beside its ``checkpoint``
    (:func:`checkpoint_path`): ``<output_dir>/<stem>.refinement.npz``."""
    return checkpoint.with_name(checkpoint.name.replace(".checkpoint.npz", ".refinement.npz"))


def save_refinement(
    path: str | os.PathLike[str], refinement: Refinement, key: dict[str, Any], solve: str
) -> None:
    """Write the rounds of a refinement cut short (its ``resumable`` part: the refined mesh,
    its radiosity and what the next round reads) to ``path`` atomically, with the
    checkpoint's fingerprint ``key`` and the ``solve`` it refined (:func:`solve_digest`)."""
    done = refinement.resumable
    if done is None:
        raise ValueError("the refinement was not cut short")
    arrays: dict[str, Any] = {
        MESH + f.name: getattr(done.mesh, f.name)
        for f in dataclasses.fields(done.mesh)
        if getattr(done.mesh, f.name) is not None
    }
    arrays |= {"radiosity": done.radiosity, "found": done.found}
    for k, (change, area) in enumerate(done.changes):
        arrays |= {f"change_{k}": change, f"change_area_{k}": area}
    counts = {"added": done.added, "rounds": done.rounds}
    counts |= {"rays": done.rays, "rays_naive": done.rays_naive}
    record = {"fingerprint": key, "solve": solve, "counts": counts}
    if done.settings is not None:
        record["refine"] = dataclasses.asdict(done.settings)
    write_checkpoint(path, arrays, record | {"changes": len(done.changes)})


def load_refinement(
    path: str | os.PathLike[str], key: dict[str, Any], solve: str
) -> Refinement | None:
    """The rounds :func:`save_refinement` kept in ``path``, when they refined this
    ``solve`` of this system (``key``); None otherwise (no file: a warning when it is
    unreadable or of another solve, and the refinement starts from its first round)."""
    if not Path(path).exists():
        return None
    try:
        arrays, record = read_checkpoint(path)
        if record.get("fingerprint") != key or record.get("solve") != solve:
            log.warning("%s: made for another solve; refinement starts again", path)
            return None
        fields = {
            name[len(MESH) :]: np.asarray(values)
            for name, values in arrays.items()
            if name.startswith(MESH)
        }
        mesh = RadiosityMesh(**fields)
        changes = [
            (np.asarray(arrays[f"change_{k}"]), np.asarray(arrays[f"change_area_{k}"]))
            for k in range(int(record["changes"]))
        ]
        counts = {name: int(value) for name, value in record["counts"].items()}
        found = np.asarray(arrays["found"])
        radiosity = np.asarray(arrays["radiosity"])
        settings = RefineSettings(**record["refine"]) if "refine" in record else None
    except (RaytradError, KeyError, TypeError, ValueError) as exc:
        log.warning("%s: cannot read the refinement kept (%s); it starts again", path, exc)
        return None
    log.info("resuming refinement from %s after round %d", path, counts["rounds"])
    return Refinement(
        mesh,
        radiosity,
        added=counts["added"],
        rounds=counts["rounds"],
        rays=counts["rays"],
        rays_naive=counts["rays_naive"],
        found=found,
        changes=changes,
        settings=settings,
    )


def kept_refinement(checkpoint: Path, key: dict[str, Any], solve: np.ndarray) -> Refinement | None:
    """The rounds a run kept beside ``checkpoint`` of its refinement cut short
    (:func:`load_refinement`), when they refined the ``solve`` radiosity."""
    return load_refinement(refinement_path(checkpoint), key, solve_digest(solve))


def keep_checkpoint(
    checkpoint: Path,
    keep: bool,
    refinement: Refinement,
    key: dict[str, Any],
    solve: np.ndarray,
) -> dict[str, Path]:
    """The files a run leaves to resume from, by output name: with ``keep``, its
    ``checkpoint`` and, when ``refinement`` was cut short after a round, that round's
    mesh beside it (:func:`save_refinement`); without, none, and both are removed."""
    rounds = refinement_path(checkpoint)
    done = refinement.resumable
    kept = {"checkpoint": checkpoint} if keep else {}
    if keep and done is not None and done.rounds > 0:
        save_refinement(rounds, refinement, key, solve_digest(solve))
        return kept | {"refinement": rounds}
    if not keep:
        checkpoint.unlink(missing_ok=True)
    rounds.unlink(missing_ok=True)
    return kept


def solve_digest(radiosity: np.ndarray) -> str:
    """A SHA-256 of a solve's receiver radiosity: a refinement kept resumes only on the
    same solve (a resumed solve that converged gives it to the bit)."""
    return hashlib.sha256(np.ascontiguousarray(radiosity, dtype=np.float64).tobytes()).hexdigest()


def unchanged(taken: dict[str, Any] | None, state: SolverState, patches: int) -> bool:
    """Whether the checkpoint a run resumed from (``taken``, :func:`resume_facts`) already
    holds what the run would save after its solve: the whole pass (every column of its
    ``patches``, or its balanced scales) and this ``state``'s shots (a solve that had
    converged, resumed to refine further). Writing it again took 3-4 s of a 20 s limit at
    60 000 receivers for the same bytes; otherwise a run under a budget saves every column
    with its state, so that ``--resume`` goes on shooting, or refining, without a pass."""
    if taken is None or taken["shots"] != state.shots:
        return False
    return bool(taken["form_factor_columns"] == patches or taken["form_factor_scales"])


def resume_facts(
    state: SolverState | None,
    columns: dict[str, Any] | None,
    scales: SavedScales | None = None,
) -> dict[str, Any] | None:
    """What a run took from its checkpoint, for ``report.json``'s ``"resumed"``: the
    solve's shots and seconds (0 where the pass was cut short: the solve then starts
    afresh), the form-factor columns it did not compute again, whether it took a finished
    pass's balanced ``scales`` (and traced no pass), and the refinement rounds (0 here;
    :func:`taken_rounds`); None for a run that did not resume."""
    if state is None and not columns:
        return None
    return {
        "shots": state.shots if state is not None else 0,
        "solve_seconds": float(state.seconds) if state is not None else 0.0,
        "form_factor_columns": len(columns["patch"]) if columns else 0,
        "form_factor_scales": scales is not None,
        "refinement_rounds": 0,
    }


def taken_rounds(
    taken: dict[str, Any] | None, rounds: Refinement | None, settings: RefineSettings
) -> dict[str, Any] | None:
    """``taken`` (:func:`resume_facts`) with the refinement rounds the run goes on from:
    those ``rounds`` kept (:func:`kept_refinement`) when made with these ``settings``
    (:func:`~raytrad.core.adaptive.goes_on_from`; refinement starts again otherwise)."""
    if taken is None or rounds is None or not goes_on_from(rounds, settings):
        return taken
    return taken | {"refinement_rounds": rounds.rounds}
