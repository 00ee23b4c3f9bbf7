"""``raytrad compare``: every method on the same receivers, against one reference."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from raytrad.cli import main
from raytrad.core.solver import SHOOTING_METHODS
from tests.conftest import SCENES

METHODS = list(SHOOTING_METHODS)
SMALL = ["--receivers", "800", "--patches", "60", "-q"]
COMPARED = {"furnace": SCENES / "furnace.obj", "cornell": SCENES / "cornell-box.obj"}
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _strict_constant(name: str) -> float:
    raise ValueError(f"{name} is not JSON (RFC 8259)")


@pytest.fixture(scope="module")
def compared(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Path, dict[str, Any]]]:
    """Both scenes compared with every method: name -> (output dir, compare.json)."""
    done = {}
    for name, scene in COMPARED.items():
        out = tmp_path_factory.mktemp(name) / "out"
        status = main(
            ["compare", str(scene), "-o", str(out), "--methods", ",".join(METHODS), *SMALL]
        )
        assert status == 0
        summary = json.loads((out / "compare.json").read_text(), parse_constant=_strict_constant)
        done[name] = (out, summary)
    return done


@pytest.mark.parametrize("name", list(COMPARED))
def test_compare_writes_json_markdown_and_plot(
    compared: dict[str, tuple[Path, dict[str, Any]]], name: str
) -> None:
    out, summary = compared[name]
    assert sorted(p.name for p in out.iterdir()) == ["compare.json", "compare.md", "compare.png"]
    assert (out / "compare.png").read_bytes()[:8] == PNG_SIGNATURE
    assert summary["reference"]["kind"] == "dense"  # small enough for a direct solve
    # one row per method, in the order asked, in the JSON and in the Markdown table
    assert [row["method"] for row in summary["table"]] == METHODS
    assert set(summary["logs"]) == set(METHODS)
    markdown = (out / "compare.md").read_text()
    rows = [line for line in markdown.splitlines() if line.startswith("| ")]
    assert len(rows) == 1 + len(METHODS)  # the head and one row per method
    assert [row.split("|")[1].strip() for row in rows[1:]] == METHODS
    for row in summary["table"]:
        assert row["stop_reason"] == "converged"
        assert row["final_true_rms"] < 1e-3
        assert row["shots_to_0.01"] <= row["shots_to_0.001"] <= row["shots"]
    # one form-factor pass for all: the same rays and set-up seconds in every row
    assert len({row["rays"] for row in summary["table"]}) == 1
    assert len({row["setup_seconds"] for row in summary["table"]}) == 1


@pytest.mark.parametrize("name", list(COMPARED))
def test_ambient_reaches_1e3_in_fewer_shots_than_progressive(
    compared: dict[str, tuple[Path, dict[str, Any]]], name: str
) -> None:
    rows = {row["method"]: row for row in compared[name][1]["table"]}
    ambient, progressive = rows["ambient"]["shots_to_0.001"], rows["progressive"]["shots_to_0.001"]
    ratio = ambient / progressive
    print(
        f"{name}: shots to 1e-3 true error, ambient {ambient} / progressive {progressive}"
        f" = {ratio:.2f}"
    )
    assert ratio < 0.8


def test_unknown_method_lists_the_valid_ones(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    argv = [
        "compare",
        str(COMPARED["furnace"]),
        "-o",
        str(out),
        "--methods",
        "progressive,gauss-seidel",
        *SMALL,
    ]
    status = main(argv)
    captured = capsys.readouterr()
    assert status == 1
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("raytrad: error: "), captured.err
    assert "gauss-seidel" in lines[0]
    for method in METHODS:
        assert method in lines[0]
    assert not out.exists()
