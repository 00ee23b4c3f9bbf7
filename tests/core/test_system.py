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


@pytest.mark.skipif(compiled.get() is None, reason="numba is not installed")
@pytest.mark.parametrize("share", [0.05, 0.3, 0.9])
def test_respread_sums_the_touched_patches_again_to_the_bit(
    system: DiscreteSystem, share: float
) -> None:
    """After a change confined to some patches (their receivers' radiosity, their entries'
    shots and their unshot radiosity), :meth:`respread` from the spread before gives
    :meth:`spread` of the new state exactly, and clears its marks; a stale patch would
    show (every touched patch's inputs change)."""
    rng = np.random.default_rng(1)
    count, patches = len(system.receiver_area), len(system.patch_area)
    radiosity = system.receiver_radiosity(rng.uniform(0, 2, (count, 3)))
    entry_shot = rng.uniform(0, 1, (len(system.entry_patch), 3))
    unshot = rng.normal(size=(patches, 3))
    spread, peak = system.spread(radiosity, entry_shot, unshot)
    touched = rng.random(patches) < share
    # the receivers of touched patches change, and with them every patch they belong to
    entries = np.flatnonzero(touched[system.entry_patch])
    changed = np.unique(system.entry_receiver[entries])
    radiosity = radiosity.copy()
    radiosity[changed] += rng.uniform(0.1, 1.0, (len(changed), 3))
    touched[system.entry_patch[np.isin(system.entry_receiver, changed)]] = True
    entry_shot = entry_shot.copy()
    entry_shot[touched[system.entry_patch]] += 0.25
    unshot = np.where(touched[:, None], unshot - 0.5, unshot)
    system.touched[:] = touched
    again = system.respread(spread, peak, radiosity, entry_shot, unshot)
    whole = system.spread(radiosity, entry_shot, unshot)
    for got, want, before in zip(again, whole, (spread, peak), strict=True):
        np.testing.assert_array_equal(got, want)
        assert (got[touched] != before[touched]).any(axis=1).all()
        np.testing.assert_array_equal(got[~touched], before[~touched])
    assert not system.touched.any()
