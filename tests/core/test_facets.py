"""Facets of the blocking triangles (raytrad.core.facets), from independent geometry:
planes, hulls and bounding spheres of known solids, and the volumes that stand for the
small facets past the limit, checked by distances and coordinates."""

from __future__ import annotations

import numpy as np
import pytest

from raytrad.core.embree import RAYS_VARIABLE
from raytrad.core.facets import (
    KEPT_FACETS,
    LARGE_FACET,
    MAX_FACETS,
    PACKET_FACETS,
    PACKET_KEPT,
    VOLUMES,
    facets,
)
from raytrad.core.mesh import MeshSettings
from raytrad.core.pipeline import prepare
from raytrad.scene.builtin import blocks_room

CUBE = np.array([[x, y, z] for x in (0.0, 1.0) for y in (0.0, 1.0) for z in (0.0, 1.0)])
# the cube's 6 faces as 12 triangles (corner index = 4x + 2y + z)
CUBE_TRIANGLES = np.array(
    [
        [0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5],  # x = 0, x = 1
        [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6],  # y = 0, y = 1
        [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3],  # z = 0, z = 1
    ]
)  # fmt: skip


def _polygon_area(ring: np.ndarray) -> float:
    return 0.5 * float(np.linalg.norm(np.cross(ring, np.roll(ring, -1, axis=0)).sum(axis=0)))


def test_unit_cube_has_six_square_facets() -> None:
    found = facets(CUBE, CUBE_TRIANGLES, diagonal=np.sqrt(3.0))
    assert found is not None and found.count == 6
    # one facet per axis-aligned plane, at offsets 0 and 1
    planes = sorted(
        (int(np.abs(n).argmax()), round(float(d), 12))
        for n, d in zip(found.normal, found.offset, strict=True)
    )
    assert planes == [(0, 0.0), (0, 1.0), (1, 0.0), (1, 1.0), (2, 0.0), (2, 1.0)]
    np.testing.assert_allclose(found.radius, np.sqrt(0.5), rtol=1e-8)
    for q in range(6):
        ring = found.hull[found.hull_ptr[q] : found.hull_ptr[q + 1]]
        assert len(ring) == 4
        assert _polygon_area(ring) == pytest.approx(1.0, rel=1e-12)
        # counter-clockwise about the facet's normal
        turn = np.cross(ring[1] - ring[0], ring[2] - ring[1])
        assert turn @ found.normal[q] > 0


def test_coplanar_triangles_share_a_facet_and_tilted_ones_do_not() -> None:
    # two triangles of a square in z = 0, and a square folded by 1e-3 along its diagonal
    positions = np.array(
        [
            [0, 0, 0],
            [1, 0, 0],
            [1, 1, 0],
            [0, 1, 0],
            [0, 0, 1],
            [1, 0, 1],
            [1, 1, 1.001],
            [0, 1, 1],
        ],
        dtype=float,
    )
    triangles = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    found = facets(positions, triangles, diagonal=2.0)
    assert found is not None and found.count == 3


def test_too_many_large_facets_turn_culling_off() -> None:
    rng = np.random.default_rng(3)
    corners = rng.normal(size=(MAX_FACETS + 1, 3, 3))
    assert facets(corners.reshape(-1, 3), np.arange(corners.size // 3).reshape(-1, 3), 5.0) is None


def test_small_facets_past_the_limit_are_gathered_into_volumes() -> None:
    """A cube's six faces and 1 000 small triangles: the faces stay facets, exactly as
    alone; the small triangles fall into at most VOLUMES volumes, each without a plane,
    whose sphere and box corners hold every one of its triangles' corners."""
    rng = np.random.default_rng(5)
    centre = rng.uniform(0.1, 0.9, size=(1000, 1, 3))
    small = centre + 0.004 * rng.normal(size=(1000, 3, 3))
    positions = np.concatenate([CUBE, small.reshape(-1, 3)])
    triangles = np.concatenate([CUBE_TRIANGLES, 8 + np.arange(3000).reshape(-1, 3)])
    diagonal = np.sqrt(3.0)
    found = facets(positions, triangles, diagonal)
    alone = facets(CUBE, CUBE_TRIANGLES, diagonal)
    assert found is not None and alone is not None
    assert found.count == 6 + VOLUMES <= MAX_FACETS
    assert 0.5 > LARGE_FACET * diagonal and KEPT_FACETS >= 6  # the faces are large
    np.testing.assert_array_equal(found.normal[:6], alone.normal)
    np.testing.assert_array_equal(found.hull[: found.hull_ptr[6]], alone.hull)
    volume = (found.normal == 0).all(axis=1)
    assert volume[6:].all() and not volume[:6].any()
    assert (found.offset[volume] == 0).all()
    # every small triangle lies in some volume's sphere and box (independent check: by
    # distances and coordinates, not by the facets' own grouping)
    covered = np.zeros(1000, dtype=bool)
    for q in np.flatnonzero(volume):
        box = found.hull[found.hull_ptr[q] : found.hull_ptr[q + 1]]
        assert len(box) == 8
        lo, hi = box.min(axis=0), box.max(axis=0)
        inside_box = ((small >= lo) & (small <= hi)).all(axis=(1, 2))
        distance = np.linalg.norm(small - found.center[q], axis=2).max(axis=1)
        covered |= inside_box & (distance <= found.radius[q])
    assert covered.all()
    # a volume is never on either side of anything: every point's side bits are clear
    points = rng.uniform(-1.0, 2.0, size=(300, 3))
    sides = found.sides(points)
    bits = np.unpackbits(sides.astype("<u8").view(np.uint8), axis=-1, bitorder="little")
    words = found.words
    for q in np.flatnonzero(volume):  # front bits in words 0..W-1, behind in W..2W-1
        assert not bits[:, q].any() and not bits[:, 64 * words + q].any()


def test_rays_in_packets_cull_rooms_of_fewer_facets(monkeypatch: pytest.MonkeyPatch) -> None:
    """Embree's packets halve a ray's cost, so the pass culls up to PACKET_FACETS facets
    (and past them keeps at most PACKET_KEPT large ones); single-ray queries keep the
    wider limits. Rooms of 2 x 2 and 3 x 3 blocks have 27 and 52 facets, all but one
    large."""
    assert PACKET_FACETS < MAX_FACETS and PACKET_KEPT < KEPT_FACETS
    small, larger = blocks_room(2), blocks_room(3)
    for scene, count in ((small, 27), (larger, 52)):
        found = facets(scene.positions, scene.triangles, 6.4)
        assert found is not None and found.count == count
    assert facets(small.positions, small.triangles, 6.4, PACKET_FACETS, PACKET_KEPT) is not None
    assert facets(larger.positions, larger.triangles, 6.4, PACKET_FACETS, PACKET_KEPT) is None
    for rays, culled in (("packets", False), ("embreex", True)):
        monkeypatch.setenv(RAYS_VARIABLE, rays)
        prepared = prepare(larger, MeshSettings(receivers=400, patches=60))
        try:
            assert prepared.occluder is not None and prepared.occluder.packets == (not culled)
            assert (prepared.engine._pairs.facets is not None) == culled
        finally:
            prepared.close()
