"""Bake manifests: paths, defaults and overrides, and one-line refusals of bad ones; job
options understood exactly as ``raytrad render`` understands its own."""

from __future__ import annotations

from pathlib import Path

import pytest

from raytrad.batch import read_manifest
from raytrad.cli.bake import _render_parser, job_from_spec
from raytrad.settings import SettingsError

#: The manifest of the issue, as a new user would write it.
EXAMPLE = """\
[defaults]            # any `raytrad render` option, by its long name with _ for -
receivers = 20000
lightmap = true
[[job]]
scene = "levels/a.glb"   # relative to the manifest
output = "out/a"         # relative to the manifest
[[job]]
scene = "levels/b.obj"
output = "out/b"
tolerance = 1e-4         # per-job override
"""


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "jobs" / "bake.toml"
    path.parent.mkdir(exist_ok=True)
    path.write_text(text)
    return path


def test_paths_are_relative_to_the_manifest_and_options_merge(tmp_path: Path) -> None:
    path = _write(tmp_path, EXAMPLE)
    a, b = read_manifest(path)
    folder = path.resolve().parent
    assert (a.scene, a.output) == (folder / "levels/a.glb", folder / "out/a")
    assert (b.scene, b.output) == (folder / "levels/b.obj", folder / "out/b")
    assert a.name == "out/a" and b.name == "out/b"
    assert a.options == {"receivers": 20000, "lightmap": True}
    assert b.options == {"receivers": 20000, "lightmap": True, "tolerance": 1e-4}


def test_job_options_become_the_settings_the_command_line_gives(tmp_path: Path) -> None:
    path = _write(tmp_path, EXAMPLE)
    render = _render_parser()
    a, b = (job_from_spec(spec, path, render) for spec in read_manifest(path))
    for job in (a, b):
        assert job.settings.mesh.receivers == 20000
        assert job.settings.lightmap is not None
        assert job.settings.image is None and not job.settings.gltf
    assert a.settings.solve.tolerance == 1e-3  # render's default
    assert b.settings.solve.tolerance == 1e-4
    assert a.settings.solve.method == "ambient"


def test_every_kind_of_option_value(tmp_path: Path) -> None:
    path = _write(
        tmp_path,
        '[defaults]\nmethod = "positive"\ntime-limit = 30\nimage = true\nwidth = 64.0\n'
        'camera = "0,1,3:0,1,0:40"\ngltf = false\ncheckpoint_every = 5\n'
        '[[job]]\nscene = "s.obj"\noutput = "o"\nname = "lobby"\n',
    )
    (spec,) = read_manifest(path)
    job = job_from_spec(spec, path, _render_parser())
    assert job.name == "lobby"
    settings = job.settings
    assert settings.solve.method == "positive" and settings.solve.time_limit == 30.0
    assert settings.image is not None and settings.image.width == 64
    assert settings.image.camera is not None and settings.image.camera.position == (0, 1, 3)
    assert not settings.gltf and settings.checkpoint_seconds == 5.0


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[defaults]\nreceivers = 10\n", "no jobs"),
        ("[[job]]\noutput = 'o'\n", "job 1 needs scene"),
        ("[[job]]\nscene = 's.obj'\n", "job 1 needs output"),
        ("[defaults]\nscene = 's.obj'\n[[job]]\nscene='s'\noutput='o'\n", "cannot hold 'scene'"),
        ("[[job]]\nscene = 's'\noutput = 'o'\nreceivers = [1, 2]\n", "'receivers' must be"),
        ("[[job]]\nscene='a'\noutput='o'\n[[job]]\nscene='b'\noutput='o/.'\n", "same folder"),
        (
            "[[job]]\nscene='a'\noutput='o'\nname='x'\n[[job]]\nscene='b'\noutput='p'\nname='x'\n",
            "two jobs are named 'x'",
        ),
        ("[jobs]\nscene = 's'\n", "unknown table 'jobs'"),
        ("[[job]\nscene = 's'\n", "not a valid TOML manifest"),
        ("[[job]]\nscene='s'\noutput='o'\ntime-limit=1\ntime_limit=2\n", "given twice"),
        ("defaults = 3\n[[job]]\nscene='s'\noutput='o'\n", "'defaults' must be a table"),
    ],
)
def test_bad_manifests_are_refused_in_one_line(tmp_path: Path, text: str, message: str) -> None:
    path = _write(tmp_path, text)
    with pytest.raises(SettingsError) as caught:
        read_manifest(path)
    assert str(path) in str(caught.value) and message in str(caught.value)
    assert "\n" not in str(caught.value)


def test_a_bad_default_is_blamed_on_the_defaults(tmp_path: Path) -> None:
    path = _write(tmp_path, "[defaults]\nrecievers = 5\n[[job]]\nscene = 's'\noutput = 'o'\n")
    (spec,) = read_manifest(path)
    with pytest.raises(SettingsError, match=r"bake\.toml: \[defaults\]: unknown option 'rec"):
        job_from_spec(spec, path, _render_parser())


def test_a_missing_manifest_is_one_line(tmp_path: Path) -> None:
    with pytest.raises(SettingsError, match=r"nowhere\.toml: cannot read the manifest"):
        read_manifest(tmp_path / "nowhere.toml")


@pytest.mark.parametrize(
    ("option", "message"),
    [
        ("recievers = 100", "unknown option 'recievers'; did you mean 'receivers'?"),
        ("lightmap = 1", "lightmap wants true or false"),
        ("receivers = true", "receivers wants a value"),
        ("receivers = 'many'", "invalid int value"),
        ("tolerance = -1.0", "tolerance"),
        ("view = 'front'", "--view needs --image"),
        ("resume = true", "'resume' cannot be set in a manifest"),
        ("method = 'fastest'", "invalid choice"),
    ],
)
def test_bad_job_options_name_the_job_and_the_option(
    tmp_path: Path, option: str, message: str
) -> None:
    path = _write(tmp_path, f"[[job]]\nscene = 's.obj'\noutput = 'o'\nname = 'hall'\n{option}\n")
    (spec,) = read_manifest(path)
    with pytest.raises(SettingsError) as caught:
        job_from_spec(spec, path, _render_parser())
    text = str(caught.value)
    assert text.startswith(f"{path}: job 'hall': ") and message in text, text
    assert "\n" not in text
