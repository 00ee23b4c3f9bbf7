"""Group 4: the Cornell box in millimetres, metres and kilometres, and 1e5 m from the origin.

Radiosity [W m-2] does not depend on the unit of length or the placement, so every variant
must give the metre version's radiosity. The mesh settings scale with the scene, so the
receivers are the same points in the same order.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import pytest

from raytrad.core.pipeline import prepare
from raytrad.core.solver import SolveSettings, solve
from raytrad.scene.builtin import cornell_box
from raytrad.scenefiles import load_scene, write_obj

from .cases import (
    MAX_SHOTS,
    TIME_LIMIT,
    Run,
    assert_finished,
    assert_within,
    case,
    cornell_mesh,
    cornell_metre_reference,
    run_case,
    surface_means,
    to_metres,
)

VARIANTS = ["mm", "km", "far"]


@functools.cache
def _scale_run(variant: str) -> Run:
    """Each variant is solved once for both tests below."""
    return run_case(case(f"scale-{variant}"))


@pytest.mark.parametrize("variant", VARIANTS)
def test_surface_means_do_not_depend_on_scale_or_placement(variant: str) -> None:
    run = _scale_run(variant)
    assert_finished(run)
    reference, _ = cornell_metre_reference()
    assert run.mesh.receiver_count == len(reference)
    assert_within(run)  # each quad's area-weighted mean B within 1% of the metre version


@pytest.mark.parametrize("variant", VARIANTS)
def test_receivers_do_not_depend_on_scale_or_placement(variant: str) -> None:
    run = _scale_run(variant)
    reference, _ = cornell_metre_reference()
    metre_positions = to_metres(variant)(run.mesh.receiver_position)
    assert metre_positions.shape == (len(reference), 3)
    lit = reference > 1e-3 * reference.max(axis=0)
    error = np.abs(run.result.radiosity[lit] / reference[lit] - 1.0)
    assert error.max() <= 0.01, f"{int((error > 0.01).sum())} receiver-channels off by > 1%"


def test_model_in_millimetres_loaded_with_scale(tmp_path: Path) -> None:
    # The usual CAD case: the file is in millimetres, the user passes scale = 0.001.
    path = tmp_path / "cornell-mm.obj"
    write_obj(cornell_box().scaled(1e3), path)
    scene = load_scene(path, scale=1e-3)
    prepared = prepare(scene, cornell_mesh(1.0))
    try:
        result = solve(
            prepared.mesh,
            prepared.engine,
            SolveSettings(tolerance=1e-5, max_shots=MAX_SHOTS, time_limit=TIME_LIMIT),
        )
    finally:
        prepared.close()
    assert result.stop_reason == "converged"
    assert np.isfinite(result.radiosity).all()
    _, reference = cornell_metre_reference()
    means = surface_means(prepared.mesh, prepared.scene, result.radiosity, to_metres("m"))
    np.testing.assert_allclose(means, reference, rtol=1e-2)
