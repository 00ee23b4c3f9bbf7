"""Reference solutions: a previous result mapped onto the receivers, the dense solve and the
analytic furnace, each against a value known independently.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from raytrad.cli import main
from raytrad.core.convergence import true_error
from raytrad.core.mesh import MeshSettings, RadiosityMesh
from raytrad.core.pipeline import Prepared, prepare
from raytrad.core.reference import automatic_reference, reference_at_receivers
from raytrad.formats.ply import read_radiosity_ply, write_radiosity_ply
from raytrad.scene.builtin import furnace_box
from raytrad.scenefiles import load_scene
from tests.conftest import SCENES

FURNACE_OBJ = SCENES / "furnace.obj"  # unit cube, Kd 0.5, Ke 1: B = 2 everywhere
SMALL = ["--receivers", "800", "--patches", "60"]


def _prepare_obj(path: Path, receivers: int, patches: int) -> Prepared:
    return prepare(load_scene(path), MeshSettings(receivers=receivers, patches=patches))


def reference_from_ply(path: Path, mesh: RadiosityMesh) -> np.ndarray:
    """A previous result's radiosity at ``mesh``'s receivers (as ``--reference PLY``)."""
    positions, triangles, radiosity = read_radiosity_ply(path)
    return reference_at_receivers(positions, triangles, radiosity, mesh, path)


def test_reference_ply_of_the_same_settings_is_used_as_is(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = tmp_path / "out"
    assert main(["render", str(FURNACE_OBJ), "-o", str(out), *SMALL, "-q"]) == 0
    _, _, radiosity = read_radiosity_ply(out / "furnace.ply")
    prepared = _prepare_obj(FURNACE_OBJ, 800, 60)
    try:
        # the same receivers in the same order: no nearest-vertex matching at all
        def no_matching(*args: object) -> np.ndarray:
            raise AssertionError("nearest-vertex matching used for identical receivers")

        monkeypatch.setattr("raytrad.core.reference._nearest_facing", no_matching)
        reference = reference_from_ply(out / "furnace.ply", prepared.mesh)
    finally:
        prepared.close()
    np.testing.assert_array_equal(reference, radiosity)
    np.testing.assert_allclose(reference, 2.0, rtol=1e-2)


def test_reference_ply_of_a_finer_mesh_maps_onto_a_coarser_one(tmp_path: Path) -> None:
    fine = tmp_path / "fine"
    status = main(
        [
            "render",
            str(FURNACE_OBJ),
            "-o",
            str(fine),
            "--receivers",
            "3000",
            "--patches",
            "60",
            "--tolerance",
            "1e-5",
            "-q",
        ]
    )
    assert status == 0
    positions, _, fine_radiosity = read_radiosity_ply(fine / "furnace.ply")
    np.testing.assert_allclose(fine_radiosity, 2.0, rtol=1e-3)  # B = E / (1 - rho) = 2
    coarse = _prepare_obj(FURNACE_OBJ, 800, 60)
    try:
        assert coarse.mesh.receiver_count < len(positions) / 2
        reference = reference_from_ply(fine / "furnace.ply", coarse.mesh)
    finally:
        coarse.close()
    assert reference.shape == (coarse.mesh.receiver_count, 3)
    np.testing.assert_allclose(reference, 2.0, rtol=1e-2)


def test_reference_ply_of_a_finer_mesh_takes_the_value_of_the_same_face(
    tmp_path: Path,
) -> None:
    # Every face of the furnace gets its own value in the reference: a receiver in a corner
    # of the coarse mesh must take the value of its own face, not of the nearest vertex of
    # a neighbouring face at the same position.
    fine = prepare(furnace_box(), MeshSettings(receivers=3000, patches=60))
    coarse = prepare(furnace_box(), MeshSettings(receivers=800, patches=60))
    fine.close()
    coarse.close()

    def face_value(normals: np.ndarray) -> np.ndarray:
        axis = np.argmax(np.abs(normals), axis=1)
        value = 1.0 + axis + 3.0 * (np.take_along_axis(normals, axis[:, None], 1)[:, 0] > 0)
        return np.repeat(value[:, None], 3, axis=1)

    m = fine.mesh
    path = tmp_path / "faces.ply"
    colours = np.zeros((m.receiver_count, 3), dtype=np.uint8)
    write_radiosity_ply(
        path, m.receiver_position, m.triangle_receivers, face_value(m.receiver_normal), colours
    )
    reference = reference_from_ply(path, coarse.mesh)
    np.testing.assert_array_equal(reference, face_value(coarse.mesh.receiver_normal))


def test_automatic_reference_is_dense_for_a_small_scene(
    cornell: Prepared, cornell_dense: np.ndarray
) -> None:
    reference = automatic_reference(cornell.mesh, cornell.engine, 1e-3)
    assert reference.kind == "dense"
    np.testing.assert_allclose(reference.radiosity, cornell_dense, rtol=1e-12)


def test_automatic_reference_is_a_converged_run_when_dense_is_too_large(
    cornell: Prepared, cornell_dense: np.ndarray, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr("raytrad.core.reference.DENSE_SIZE_LIMIT", 10)
    reference = automatic_reference(cornell.mesh, cornell.engine, 1e-3)
    assert reference.kind == "converged"
    assert "dense" in reference.description  # says why
    rms, _ = true_error(reference.radiosity, cornell_dense, cornell.mesh.receiver_area)
    print(f"converged reference against dense: relative RMS {rms.max():.2e}")
    assert rms.max() < 1e-4


def test_automatic_reference_follows_the_limit_of_the_reference_module(
    cornell: Prepared, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr("raytrad.core.reference.DENSE_SIZE_LIMIT", 10)
    assert automatic_reference(cornell.mesh, cornell.engine, 1e-3).kind == "converged"
