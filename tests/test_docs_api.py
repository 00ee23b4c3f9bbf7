"""``docs/api.md``'s examples run as written, in order, in a folder holding ``scenes/``."""

from __future__ import annotations

import re
import shutil
import tempfile
from pathlib import Path

import pytest

import raytrad
from tests.conftest import REPOSITORY, SCENES

DOC = REPOSITORY / "docs" / "api.md"


def _blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", DOC.read_text(), flags=re.DOTALL)


def test_the_api_page_examples_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    pytest.importorskip("distributed")
    shutil.copytree(SCENES, tmp_path / "scenes")
    monkeypatch.chdir(tmp_path)
    blocks = _blocks()
    assert len(blocks) >= 5
    before = set(Path(tempfile.gettempdir()).glob("raytrad-job-*"))
    namespace: dict[str, object] = {"__name__": "docs_api"}
    for number, block in enumerate(blocks, start=1):
        try:
            exec(compile(block, f"{DOC}:block {number}", "exec"), namespace)
        except Exception as exc:
            raise AssertionError(f"docs/api.md block {number} failed: {exc!r}") from exc
    printed = capsys.readouterr().out
    assert "tolerance" in printed  # the SettingsError example
    assert (tmp_path / "out/baked/box.glb").is_file()
    assert (tmp_path / "out/baked/box.lightmap.exr").is_file()
    assert not (tmp_path / "out/vertex/box.lightmap.exr").exists()
    assert set(Path(tempfile.gettempdir()).glob("raytrad-job-*")) == before  # none left


def test_every_public_name_resolves_and_is_documented() -> None:
    stub = (REPOSITORY / "raytrad" / "__init__.pyi").read_text()
    stubbed = set(re.findall(r"import \w+ as (\w+)", stub))
    public = set(raytrad.__all__) - {"__version__"}
    assert stubbed == public
    for name in public:
        value = getattr(raytrad, name)
        assert (value.__doc__ or "").strip(), f"raytrad.{name} has no docstring"
    with pytest.raises(AttributeError):
        raytrad.no_such_name  # noqa: B018
