"""From a scene to a solvable problem: repair, acceleration only where something can
occlude, every column computed and balanced before the first shot."""

from __future__ import annotations

import numpy as np

from raytrad.core.mesh import MeshSettings
from raytrad.core.pipeline import prepare
from raytrad.scene.builtin import cornell_box, furnace_box
from tests.conftest import FURNACE_MESH


def test_a_convex_enclosure_gets_no_acceleration_and_no_rays() -> None:
    with prepare(furnace_box(), FURNACE_MESH) as prepared:
        assert prepared.occluder is None and prepared.closed_receivers is None
        assert prepared.engine.rays_cast == 0
        assert prepared.engine.columns_computed == prepared.mesh.patch_count
        assert set(prepared.timings) == {"mesh", "acceleration", "form_factors"}


def test_an_occluding_scene_is_probed_and_balanced() -> None:
    with prepare(cornell_box(), MeshSettings(receivers=600, patches=40)) as prepared:
        assert prepared.occluder is not None
        closed = prepared.closed_receivers
        assert closed is not None and closed.shape == (prepared.mesh.receiver_count,)
        assert 0 < closed.sum() < len(closed)  # the open front of the box is seen by some
        assert prepared.balance["closed_rows"] > 0
        assert prepared.engine.rays_cast > 0


def test_the_prepared_scene_is_the_repaired_one() -> None:
    scene = furnace_box()
    doubled = scene.select(np.concatenate([np.arange(scene.triangle_count)] * 2))
    with prepare(doubled, FURNACE_MESH) as prepared:  # every face twice: one copy kept
        assert prepared.scene.triangle_count == scene.triangle_count


def test_a_new_engine_has_the_same_balanced_factors() -> None:
    with prepare(cornell_box(), MeshSettings(receivers=400, patches=30)) as prepared:
        fresh = prepared.new_engine()
        try:
            for patch in (0, prepared.mesh.patch_count // 2):
                a, b = prepared.engine.column(patch), fresh.column(patch)
                np.testing.assert_array_equal(a.receivers, b.receivers)
                np.testing.assert_array_equal(a.factors, b.factors)
        finally:
            fresh.close()
