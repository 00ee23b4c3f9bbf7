"""report.json against its schema (docs/report.schema.json), the plot, lazy imports, and
references that cannot be used."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
import pytest

from raytrad.cli import main
from raytrad.scene import make_scene
from raytrad.scene.builtin import furnace_box
from raytrad.scenefiles import write_obj
from tests.conftest import REPOSITORY, SCENES, run_cli

SCHEMA_PATH = REPOSITORY / "docs" / "report.schema.json"
FURNACE_OBJ = SCENES / "furnace.obj"  # unit cube, Kd 0.5, Ke 1: B = 2 everywhere
SMALL = ["--receivers", "800", "--patches", "60", "-q"]
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
COLUMNS = (
    "seconds",
    "shots",
    "rays",
    "residual",
    "estimate",
    "bound_rms",
    "bound_max",
    "true_rms",
    "true_max",
    "total_rms",
)


def _strict_constant(name: str) -> float:
    raise ValueError(f"{name} is not JSON (RFC 8259)")


def load_strict(path: Path) -> Any:
    """Parse JSON as any other language would: NaN and Infinity are errors."""
    return json.loads(path.read_text(), parse_constant=_strict_constant)


def _render(out: Path, *args: str) -> dict[str, Any]:
    assert main(["render", *args, "-o", str(out), *SMALL]) == 0
    report: dict[str, Any] = json.loads((out / "report.json").read_text())
    return report


@pytest.fixture(scope="module")
def schema() -> dict[str, Any]:
    loaded: dict[str, Any] = json.loads(SCHEMA_PATH.read_text())
    return loaded


@pytest.fixture(scope="module")
def furnace_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    """The furnace rendered with ``--reference analytic --plot``: (output dir, report)."""
    out = tmp_path_factory.mktemp("furnace") / "out"
    report = _render(out, str(FURNACE_OBJ), "--reference", "analytic", "--plot")
    return out, report


@pytest.fixture(scope="module")
def shadow_report(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The open shadow scene (glTF binary), no reference."""
    return _render(tmp_path_factory.mktemp("shadow") / "out", str(SCENES / "shadow.glb"))


@pytest.fixture(scope="module")
def stopped_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    """The furnace stopped by ``--max-shots 3``: no error bound exists yet."""
    out = tmp_path_factory.mktemp("stopped") / "out"
    return out, _render(out, str(FURNACE_OBJ), "--max-shots", "3")


# --------------------------------------------------------------------------------------
# The schema
# --------------------------------------------------------------------------------------


def test_schema_is_a_valid_draft_2020_12_schema(schema: dict[str, Any]) -> None:
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    jsonschema.Draft202012Validator.check_schema(schema)
    # every top-level key is required, and each says what it is
    assert sorted(schema["required"]) == sorted(schema["properties"])
    for name, prop in schema["properties"].items():
        assert prop.get("description"), name


def _validate(schema: dict[str, Any], report: dict[str, Any]) -> None:
    validator = jsonschema.Draft202012Validator(schema)
    errors = sorted(validator.iter_errors(report), key=lambda e: list(e.absolute_path))
    assert not errors, "\n".join(f"{list(e.absolute_path)}: {e.message}" for e in errors[:10])


def test_furnace_report_with_reference_matches_the_schema(
    schema: dict[str, Any], furnace_run: tuple[Path, dict[str, Any]]
) -> None:
    out, report = furnace_run
    _validate(schema, load_strict(out / "report.json"))
    assert report["reference"]["kind"] == "analytic"
    assert report["statistics"]["ray_queries"] == "none"  # a convex enclosure
    assert report["solve"]["stop_reason"] == "converged"
    assert report["refinement"]["stopped"] is False  # it ran to its end


def test_shadow_report_without_reference_matches_the_schema(
    schema: dict[str, Any], shadow_report: dict[str, Any]
) -> None:
    _validate(schema, shadow_report)
    assert shadow_report["reference"] is None
    assert shadow_report["statistics"]["occlusion_tested"] is True
    assert shadow_report["statistics"]["ray_queries"] == "packets"  # the library is found
    assert shadow_report["convergence"]["true_rms"] == []
    assert shadow_report["error"]["true_rms"] is None


def test_stopped_report_matches_the_schema(
    schema: dict[str, Any], stopped_run: tuple[Path, dict[str, Any]]
) -> None:
    _, report = stopped_run
    _validate(schema, report)
    assert report["solve"]["stop_reason"] == "max-shots"
    assert "checkpoint" in report["outputs"]
    assert report["timings_seconds"]["checkpoint"] > 0  # its writing counts in the total


def test_stopped_report_is_strict_json(stopped_run: tuple[Path, dict[str, Any]]) -> None:
    out, _ = stopped_run
    report = load_strict(out / "report.json")  # raises on Infinity
    assert report["error"]["bound_rms"] == [None, None, None]


def test_schema_refuses_what_render_never_writes(
    schema: dict[str, Any], furnace_run: tuple[Path, dict[str, Any]]
) -> None:
    _, report = furnace_run
    validator = jsonschema.Draft202012Validator(schema)

    def broken(change: Any) -> dict[str, Any]:
        copy: dict[str, Any] = json.loads(json.dumps(report))
        change(copy)
        return copy

    mutations = {
        "missing key": lambda r: r.pop("energy_watts"),
        "unknown key": lambda r: r.update(extra=1),
        "two channels": lambda r: r["energy_watts"].update(emitted=[1.0, 2.0]),
        "bad stop reason": lambda r: r["solve"].update(stop_reason="bored"),
        "bad method": lambda r: r["settings"]["solve"].update(method="jacobi"),
        "negative error": lambda r: r["convergence"]["true_rms"][0].__setitem__(0, -1.0),
        "null true error": lambda r: r["convergence"]["true_rms"][0].__setitem__(0, None),
        "reference without true error": lambda r: r["convergence"].update(true_rms=[]),
        "stopped without checkpoint": lambda r: r["solve"].update(stop_reason="max-shots"),
        "string seconds": lambda r: r["timings_seconds"].update(solve="1s"),
    }
    for name, change in mutations.items():
        assert not validator.is_valid(broken(change)), name


# --------------------------------------------------------------------------------------
# Content of the report
# --------------------------------------------------------------------------------------


def test_energy_ledger_balances(
    furnace_run: tuple[Path, dict[str, Any]], shadow_report: dict[str, Any]
) -> None:
    for report in (furnace_run[1], shadow_report):
        energy = {k: np.array(v) for k, v in report["energy_watts"].items()}
        total = energy["absorbed"] + energy["escaped"] + energy["unshot"]
        np.testing.assert_allclose(total, energy["emitted"], rtol=1e-9, atol=0)
    # the closed furnace loses (almost) nothing; the open scene loses most of its light
    assert np.all(np.abs(furnace_run[1]["energy_watts"]["escaped"]) < 1e-3 * 6.0)
    escaped = np.array(shadow_report["energy_watts"]["escaped"])
    assert np.all(escaped > 0.1 * np.array(shadow_report["energy_watts"]["emitted"]))


def test_timings_name_every_stage(furnace_run: tuple[Path, dict[str, Any]]) -> None:
    timings = furnace_run[1]["timings_seconds"]
    assert "checkpoint" not in timings  # a finished run keeps none
    assert {"load", "acceleration", "mesh", "solve", "write", "reference"} <= set(timings)
    assert set(timings) <= {
        "load",
        "kernels",
        "acceleration",
        "mesh",
        "form_factors",
        "reference",
        "solve",
        "refine",
        "error",
        "write",
        "checkpoint",
    }
    assert all(isinstance(v, float) and v >= 0 for v in timings.values())


def test_convergence_png_is_written(furnace_run: tuple[Path, dict[str, Any]]) -> None:
    out, report = furnace_run
    png = out / "convergence.png"
    assert png.is_file() and png.stat().st_size > 1000
    assert png.read_bytes()[:8] == PNG_SIGNATURE
    assert Path(report["outputs"]["plot"]) == png
    assert sorted(p.name for p in out.iterdir()) == [
        "convergence.png",
        "furnace.ply",
        "raytrad-run.json",
        "report.json",
    ]


def test_convergence_log_holds_what_is_plotted(furnace_run: tuple[Path, dict[str, Any]]) -> None:
    # convergence.png plots these columns (true: solid, estimate: dashed, bound: dotted)
    report = furnace_run[1]
    log = report["convergence"]
    assert set(log) == set(COLUMNS)
    lengths = {name: len(log[name]) for name in COLUMNS}
    assert len(set(lengths.values())) == 1, lengths
    assert lengths["seconds"] > 20
    for name in ("estimate", "bound_rms", "bound_max", "true_rms", "true_max"):
        assert all(len(row) == 3 for row in log[name]), name
    true = np.array(log["true_rms"], dtype=float)
    bound = np.array([[math.inf if v is None else v for v in row] for row in log["bound_rms"]])
    assert np.all(bound >= true)
    assert np.isfinite(bound[-1]).all()
    assert np.all(np.diff(log["shots"]) > 0) and log["shots"][-1] == report["solve"]["shots"]
    assert log["residual"][-1] == pytest.approx(report["solve"]["residual"], rel=1e-9)
    # the closing summary is the last row
    for name in ("estimate", "bound_rms", "bound_max", "true_rms", "true_max"):
        assert report["error"][name] == log[name][-1], name
    # and the true error is against B = 2: below the tolerance-implied level at the end
    assert max(report["error"]["true_rms"]) < 1e-2
    # the total error estimate covers the true error at every log point
    total = np.array([[math.inf if v is None else v for v in row] for row in log["total_rms"]])
    assert np.all(total >= true)
    assert report["error"]["total_rms"] == log["total_rms"][-1]


def test_render_without_plot_imports_neither_matplotlib_nor_colour(tmp_path: Path) -> None:
    without = [
        "render",
        str(FURNACE_OBJ),
        "-o",
        str(tmp_path / "a"),
        *SMALL,
        "--reference",
        "analytic",
    ]
    with_plot = ["render", str(FURNACE_OBJ), "-o", str(tmp_path / "b"), *SMALL, "--plot"]
    code = (
        "import sys\n"
        "from raytrad.cli import main\n"
        f"assert main({without!r}) == 0\n"
        "print('matplotlib' in sys.modules, 'colour' in sys.modules)\n"
        f"assert main({with_plot!r}) == 0\n"
        "print('matplotlib' in sys.modules)\n"  # the probe itself works
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["False", "False", "True"]


# --------------------------------------------------------------------------------------
# References that cannot be used: exit 1, one line, nothing written
# --------------------------------------------------------------------------------------


def _refused(argv: list[str], out: Path, capsys: pytest.CaptureFixture[str]) -> str:
    status, stdout, err = run_cli(argv, capsys)
    assert status == 1, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("raytrad: error: ")
    assert "Traceback" not in err and stdout == ""
    assert not out.exists() or not any(out.iterdir()), list(out.iterdir())
    return lines[0]


def test_dense_reference_of_a_scene_too_large(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr("raytrad.core.reference.DENSE_SIZE_LIMIT", 1000)
    out = tmp_path / "out"
    argv = ["render", str(FURNACE_OBJ), "-o", str(out), *SMALL, "--reference", "dense"]
    message = _refused(argv, out, capsys)
    assert "too large" in message and "dense" in message


def test_analytic_reference_of_the_cornell_box(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    scene = SCENES / "cornell-box.obj"
    argv = ["render", str(scene), "-o", str(out), *SMALL, "--reference", "analytic"]
    message = _refused(argv, out, capsys)
    assert "analytic" in message and "closed" in message


def test_analytic_reference_of_a_non_uniform_enclosure(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    box = furnace_box()
    material = np.zeros(box.triangle_count, dtype=np.int64)
    material[:2] = 1  # one face emits, the others do not: B = E / (1 - rho) does not hold
    scene = make_scene(
        box.positions,
        box.triangles,
        material,
        ["wall", "lamp"],
        [[0.5] * 3] * 2,
        [[0.0] * 3, [1.0] * 3],
    )
    write_obj(scene, tmp_path / "lamp.obj")
    out = tmp_path / "out"
    argv = ["render", str(tmp_path / "lamp.obj"), "-o", str(out), *SMALL, "--reference", "analytic"]
    message = _refused(argv, out, capsys)
    assert "uniform" in message


def test_missing_reference_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    missing = tmp_path / "missing.ply"
    argv = ["render", str(FURNACE_OBJ), "-o", str(out), *SMALL, "--reference", str(missing)]
    message = _refused(argv, out, capsys)
    assert str(missing) in message and "not found" in message
