"""Bake manifests: a TOML file of jobs, read into :class:`JobSpec` records.

A manifest has a ``[defaults]`` table of ``raytrad render`` options (by long name, ``_``
for ``-``) and one ``[[job]]`` table per scene::

    [defaults]
    receivers = 20000
    lightmap = true

    [[job]]
    scene = "levels/a.glb"      # relative to the manifest
    output = "out/a"            # relative to the manifest
    tolerance = 1e-4            # per-job override

This module checks the manifest's shape (tables, keys, types, paths) and merges each
job's options over the defaults; what the options mean is the command line's business
(:mod:`raytrad.cli.bake` turns them into :class:`~raytrad.settings.RenderSettings`).
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from raytrad.errors import SettingsError

#: Keys a job has besides options: where its scene is, where its outputs go, its name.
JOB_KEYS = ("scene", "output", "name")
#: Option values a manifest may hold (TOML tables and arrays are no option's value).
OPTION_TYPES = (bool, int, float, str)
#: Largest manifest read [bytes]; a manifest is a short list of jobs.
MAX_BYTES = 16 << 20


@dataclass(frozen=True)
class JobSpec:
    """One ``[[job]]`` of a manifest, before its options are understood.

    Attributes
    ----------
    name : str
        The job's ``name``, else its ``output`` as written in the manifest.
    scene : Path
        Scene file, resolved against the manifest's folder.
    output : Path
        Output folder, resolved against the manifest's folder.
    options : dict of str to bool, int, float or str
        ``[defaults]`` overridden by the job's own options, by option name (``_`` for
        ``-``; the manifest may spell them either way).
    own : frozenset of str
        The options the job sets itself (the others come from ``[defaults]``).
    """

    name: str
    scene: Path
    output: Path
    options: dict[str, bool | int | float | str] = field(default_factory=dict)
    own: frozenset[str] = frozenset()


def read_manifest(path: str | Path) -> list[JobSpec]:
    """The jobs of the manifest at ``path``, in order.

    Raises
    ------
    SettingsError
        One line naming the manifest (and the job) and what is wrong: unreadable or not
        TOML, no ``[[job]]``, a job without ``scene`` or ``output``, an option value that
        is a table or array, two jobs with one name or one output folder.
    """
    path = Path(path)
    document = _parse(path)
    unknown = sorted(set(document) - {"defaults", "job"})
    if unknown:
        raise SettingsError(
            f"{path}: unknown table {unknown[0]!r}; a manifest has [defaults] and [[job]]"
        )
    defaults = document.get("defaults", {})
    if not isinstance(defaults, dict):
        raise SettingsError(f"{path}: 'defaults' must be a table ([defaults])")
    for key in JOB_KEYS:
        if key in defaults:
            raise SettingsError(f"{path}: [defaults] cannot hold {key!r}; each job gives its own")
    defaults = _options(path, "[defaults]", defaults)
    jobs = document.get("job")
    if not isinstance(jobs, list) or not jobs or not all(isinstance(j, dict) for j in jobs):
        raise SettingsError(f"{path}: no jobs; add a [[job]] table with scene and output")
    specs = [_job(path, number, job, defaults) for number, job in enumerate(jobs, start=1)]
    _check_distinct(path, specs)
    return specs


def _parse(path: Path) -> dict[str, Any]:
    try:
        with path.open("rb") as handle:
            data = handle.read(MAX_BYTES + 1)
    except OSError as exc:
        raise SettingsError(f"{path}: cannot read the manifest ({exc.strerror or exc})") from exc
    if len(data) > MAX_BYTES:
        raise SettingsError(f"{path}: manifest larger than {MAX_BYTES >> 20} MiB")
    try:
        return tomllib.loads(data.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise SettingsError(f"{path}: manifest is not UTF-8 text ({exc.reason})") from exc
    except tomllib.TOMLDecodeError as exc:
        raise SettingsError(f"{path}: not a valid TOML manifest ({exc})") from exc
    except RecursionError:
        raise SettingsError(f"{path}: manifest nested too deeply") from None


def _job(path: Path, number: int, job: dict[str, Any], defaults: dict[str, Any]) -> JobSpec:
    where = f"job {number}"
    for key in ("scene", "output"):
        value = job.get(key)
        if not isinstance(value, str) or not value.strip():
            raise SettingsError(f'{path}: {where} needs {key} = "..." (a path)')
    name = job.get("name", job["output"])
    if not isinstance(name, str) or not name.strip():
        raise SettingsError(f"{path}: {where}: name must be a non-empty string")
    options = _options(
        path, f"{where} ({name})", {k: v for k, v in job.items() if k not in JOB_KEYS}
    )
    folder = path.resolve().parent
    return JobSpec(
        name=name,
        scene=folder / Path(job["scene"]).expanduser(),
        output=folder / Path(job["output"]).expanduser(),
        options={**defaults, **options},
        own=frozenset(options),
    )


def _options(path: Path, where: str, table: dict[str, Any]) -> dict[str, Any]:
    """``table``'s options by name with ``_`` for ``-`` (``time-limit`` is ``time_limit``),
    each a plain value.

    Raises
    ------
    SettingsError
        An option given twice (both spellings), or a table or array as a value.
    """
    options: dict[str, Any] = {}
    for key, value in table.items():
        name = key.replace("-", "_")
        if name in options:
            raise SettingsError(f"{path}: {where}: option {name!r} is given twice")
        options[name] = value
    _check_options(path, where, options)
    return options


def _check_options(path: Path, where: str, options: dict[str, Any]) -> None:
    for key, value in options.items():
        if not isinstance(value, OPTION_TYPES):
            raise SettingsError(
                f"{path}: {where}: option {key!r} must be a string, number or true/false, "
                f"not a {type(value).__name__}"
            )


def _check_distinct(path: Path, specs: list[JobSpec]) -> None:
    names: dict[str, int] = {}
    outputs: dict[Path, str] = {}
    for spec in specs:
        if spec.name in names:
            raise SettingsError(f"{path}: two jobs are named {spec.name!r}")
        names[spec.name] = 1
        folder = spec.output.resolve()
        if folder in outputs:
            raise SettingsError(
                f"{path}: jobs {outputs[folder]!r} and {spec.name!r} write to the same "
                f"folder {spec.output}; give each job its own output"
            )
        outputs[folder] = spec.name
