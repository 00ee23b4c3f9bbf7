"""The discrete system's patch-average matrix W and per-patch spread: compiled kernels
against their numpy references, and W against its definition."""

from __future__ import annotations

import numpy as np
import pytest

from raytrad.core import compiled
from raytrad.core.mesh import MeshSettings, build_mesh
from raytrad.core.system import DiscreteSystem, patch_average_matrix
from raytrad.scene.builtin import cornell_box


@pytest.fixture(scope="module")
def system() -> DiscreteSystem:
    return DiscreteSystem.from_mesh(build_mesh(cornell_box(), MeshSettings(receivers=800)))


def test_w_rows_are_area_weights(system: DiscreteSystem) -> None:
    mesh = build_mesh(cornell_box(), MeshSettings(receivers=800))
    w = patch_average_matrix(mesh)
    # each patch's weights are its receivers' area shares: they sum to 1, and a uniform
    # radiosity averages to itself
    np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=1e-12)
    everyone = np.arange(mesh.receiver_count)
    ones = np.ones((mesh.receiver_count, 3))
    np.testing.assert_allclose(system.average(everyone, ones), 1.0, atol=1e-12)


@pytest.mark.skipif(compiled.get() is None, reason="numba is not installed")
def test_compiled_average_and_spread_agree_with_numpy(system: DiscreteSystem) -> None:
    rng = np.random.default_rng(0)
    count = len(system.receiver_area)
    receivers = np.sort(rng.choice(count, count // 2, replace=False))
    values = rng.normal(size=(len(receivers), 3))
    np.testing.assert_allclose(
        system.average(receivers, values),
        system.numpy_average(receivers, values),
        rtol=0,
        atol=1e-12,
    )
    radiosity = system.receiver_radiosity(rng.uniform(0, 2, (count, 3)))
    entry_shot = rng.uniform(0, 1, (len(system.entry_patch), 3))
    unshot = rng.normal(size=(len(system.patch_area), 3))
    for got, want in zip(
        system.spread(radiosity, entry_shot, unshot),
        system.numpy_spread(radiosity, entry_shot, unshot),
        strict=True,
    ):
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
        assert (want > 0).any()
