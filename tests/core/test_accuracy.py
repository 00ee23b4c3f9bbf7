"""The total error estimate (raytrad.core.accuracy) against known errors."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from raytrad.core.accuracy import (
    ErrorParts,
    _gathered,
    _spread,
    _surface_samples,
    discretisation_error,
    total_error_column,
)
from raytrad.core.convergence import counted_receivers
from raytrad.core.mesh import MeshSettings, RadiosityMesh, build_mesh
from raytrad.core.pipeline import Prepared
from raytrad.core.solver import SolveSettings, solve
from raytrad.scene.builder import SceneBuilder, rectangle


def test_exact_furnace_solution_has_no_residual(prepare_furnace: Callable[..., Prepared]) -> None:
    # B = E / (1 - rho) satisfies the radiosity equation at every point: what the check
    # reports is its Monte Carlo noise, which it subtracts.
    prepared = prepare_furnace(0.5, 1.0)
    mesh = prepared.mesh
    exact = np.full((mesh.receiver_count, 3), 2.0)
    residual = discretisation_error(
        prepared.scene, mesh, exact, counted_receivers(mesh), 1.0, samples=1024, rays=1024
    )
    assert residual.samples == 1024
    assert (residual.residual < 0.005).all()
    # what is reported is STANDARD_ERRORS standard errors of that subtraction,
    # amplified: the noise floor of the check (every wall here is an emitter, sampled by
    # area: noisy near the box's edges), which keeps the estimate on the safe side
    assert (residual.error < 0.07).all()
    np.testing.assert_allclose(residual.gain, 2.0)


def test_a_wrong_solution_is_found_and_not_understated(
    prepare_furnace: Callable[..., Prepared],
) -> None:
    # 10% too bright everywhere: the true relative error is 0.1. The residual
    # B' - E - rho H' = 0.1 E / (1 - rho) is 1/11 of B', amplified by 1 / (1 - rho):
    # the estimate must cover the truth, within the factor 3 the targets allow.
    prepared = prepare_furnace(0.5, 1.0)
    mesh = prepared.mesh
    wrong = np.full((mesh.receiver_count, 3), 2.2)
    residual = discretisation_error(
        prepared.scene, mesh, wrong, counted_receivers(mesh), 1.0, samples=256, rays=256
    )
    np.testing.assert_allclose(residual.residual, 1 / 22, rtol=0.1)
    assert (residual.error >= 1 / 11).all() and (residual.error <= 3 / 11).all()


def test_total_error_column_adds_the_bake_error_to_each_bound() -> None:
    parts = ErrorParts(
        algebraic=np.full(3, 0.001),
        discretisation=np.array([0.02, 0.03, 0.04]),
        conservation=np.zeros(3),
    )
    np.testing.assert_allclose(parts.total, [0.02, 0.03, 0.04])
    assert parts.dominant == "discretisation"
    # a solve stopped after a few shots: the residual check sees its algebraic error, so
    # a discretisation part not well above it is not named (a newcomer's time-limited run:
    # algebraic 0.569, discretisation 0.728)
    stopped = ErrorParts(np.full(3, 0.569), np.full(3, 0.728), np.zeros(3))
    assert stopped.dominant == "algebraic"
    column = total_error_column([[np.inf] * 3, [0.5, 0.5, 0.5], [0.001] * 3], parts)
    assert len(column) == 3
    assert all(v is None or v == np.inf for v in column[0])
    np.testing.assert_allclose(column[1], [0.52, 0.53, 0.54])
    np.testing.assert_allclose(column[2], parts.total)


def test_points_no_front_sees_are_skipped() -> None:
    # A block sunk 5 cm into the floor of a closed room: its sides below the floor see the
    # floor's back and the void beneath, no surface's front; no light reaches them and
    # none leaves them for anyone in the room. The residual check skips them (they were
    # a 9.5 times overestimate of a furnished room's error: a point there gathers 0 and
    # shows the lit value of the floor line above). Points above the floor are kept.
    builder = SceneBuilder()
    builder.material("white", 0.7)
    builder.material("lamp", 0.0, 5.0)
    builder.room("white", (1.0, 1.0, 1.0))
    builder.block("white", (0.3, -0.05, 0.3), (0.6, 0.25, 0.6))
    builder.quad(rectangle(1, 1.0 - 5e-4, (0.3, 0.3), (0.62, 0.62)), "lamp", (0, -1, 0))
    scene = builder.build()
    mesh = build_mesh(scene, MeshSettings(receivers=2000))
    centroid = mesh.positions[mesh.triangles].mean(axis=1)
    side = (np.abs(mesh.triangle_normal[:, 1]) < 1e-9) & (centroid[:, 0] > 0.29)
    side &= centroid[:, 0] < 0.61
    below = np.flatnonzero(side & (centroid[:, 1] < -0.01))
    above = np.flatnonzero(side & (centroid[:, 1] > 0.01))
    assert len(below) and len(above)
    tri = np.concatenate([below, above])
    weights = np.full((len(tri), 3), 1.0 / 3.0)
    radiosity = np.ones((mesh.receiver_count, 3))
    rng = np.random.default_rng(0)
    _, _, shut = _gathered(scene, mesh, radiosity, tri, weights, 256, rng)
    assert shut[: len(below)].all()
    assert not shut[len(below) :].any()


def _bump(mesh: RadiosityMesh, size: float) -> tuple[np.ndarray, np.ndarray]:
    """(R,) bool: receivers of receiver 0's surface within ``size`` of it, and the (T,)
    bool triangles they touch."""
    normal = mesh.receiver_normal[0]
    same = np.abs(mesh.receiver_normal @ normal - 1.0) < 1e-9
    near = np.linalg.norm(mesh.receiver_position - mesh.receiver_position[0], axis=1) < size
    bump = same & near
    return bump, bump[mesh.triangle_receivers].any(axis=1)


def test_points_go_where_the_light_changes_and_are_weighted_back(
    prepare_furnace: Callable[..., Prepared],
) -> None:
    # A bright spot on one wall: half the points are drawn by area times the corners'
    # squared spread, so the triangles around it get far more than their area's share;
    # each point's share (area density over sampling density) undoes that, so the
    # weighted count of points in any set of triangles estimates its area.
    mesh = prepare_furnace(0.5, 1.0).mesh
    radiosity = np.full((mesh.receiver_count, 3), 2.0)
    bump, touched = _bump(mesh, 0.05)
    radiosity[bump] = 3.0
    norm = np.full(3, 2.0)
    usable = mesh.triangle_area > 0
    tri, weights, share = _surface_samples(
        mesh, usable, _spread(mesh, radiosity, norm), 20000, np.random.default_rng(1)
    )
    np.testing.assert_allclose(weights.sum(axis=1), 1.0)
    area_share = mesh.triangle_area[touched].sum() / mesh.triangle_area.sum()
    drawn = touched[tri].mean()
    assert drawn > 20 * area_share
    weighted = share @ touched[tri] / share.sum()
    np.testing.assert_allclose(weighted, area_share, rtol=0.1)


def _lamp_over_floor(prepare_scene: Callable[..., Prepared]) -> tuple[Prepared, np.ndarray]:
    """An open floor under a small lamp (1 500 receivers) and its solved radiosity."""
    builder = SceneBuilder()
    builder.material("floor", 0.5)
    builder.material("lamp", 0.0, 10.0)
    builder.quad(rectangle(1, 0.0, (0.0, 0.0), (1.0, 1.0)), "floor", (0, 1, 0))
    builder.quad(rectangle(1, 1.0, (0.4, 0.4), (0.6, 0.6)), "lamp", (0, -1, 0))
    prepared = prepare_scene(builder.build(), MeshSettings(receivers=1500))
    return prepared, solve(prepared.mesh, prepared.engine, SolveSettings()).radiosity


def test_an_error_confined_to_a_spot_is_found_at_every_seed(
    prepare_scene: Callable[..., Prepared],
) -> None:
    # An open floor under a small lamp, solved: its light is smooth, so the bake is
    # nearly exact and the check's gather nearly noise-free (direct light, stratified).
    # One floor receiver shown twice as bright is then the error (a vertex gathered
    # wrong), its RMS exact from the linear elements' mass matrix. Its triangles are
    # 0.15 % of the floor: area-uniform points would miss them in most draws of 256;
    # drawn by spread, every seed finds them and reports no less than the error and at
    # most three times it.
    prepared, baked = _lamp_over_floor(prepare_scene)
    mesh = prepared.mesh
    floor = mesh.receiver_normal[:, 1] > 0.5
    centre = np.flatnonzero(floor)[
        np.argmin(np.linalg.norm(mesh.receiver_position[floor] - [0.3, 0.0, 0.7], axis=1))
    ]
    spot = np.arange(mesh.receiver_count) == centre
    radiosity = baked.copy()
    radiosity[spot] *= 2.0
    counted = counted_receivers(mesh)
    usable = counted[mesh.triangle_receivers].all(axis=1)
    error = (radiosity - baked)[:, 1]
    corner = error[mesh.triangle_receivers]  # (T, 3)
    mean_square = (corner.sum(axis=1) ** 2 + (corner**2).sum(axis=1)) / 12.0  # over each
    area = mesh.receiver_area * counted
    norm = np.sqrt(area @ radiosity[:, 1] ** 2 / area.sum())
    weight = mesh.triangle_area * usable
    truth = float(np.sqrt(weight @ mean_square / weight.sum()) / norm)
    touched = spot[mesh.triangle_receivers].any(axis=1)
    assert weight[touched].sum() < 0.002 * weight.sum()
    for seed in range(4):
        residual = discretisation_error(
            prepared.scene, mesh, radiosity, counted, 0.0, samples=256, rays=256, seed=seed
        )
        assert residual.error[1] >= truth
        assert residual.error[1] <= 3.0 * truth


def test_the_standard_error_says_how_far_another_seed_lands(
    prepare_scene: Callable[..., Prepared],
) -> None:
    """The check is a sample of points and rays: each check's own standard error
    (``Residual.standard_error``, from its own data alone) agrees with the spread of the
    figure over 16 seeds within a factor of 2, both for a smooth bake (nearly exact: the
    figure is the check's noise floor) and for an error confined to one vertex (a skewed
    sample, the harder case)."""
    prepared, baked = _lamp_over_floor(prepare_scene)
    mesh = prepared.mesh
    spot = baked.copy()
    spot[np.argmin(np.linalg.norm(mesh.receiver_position - [0.3, 0.0, 0.7], axis=1))] *= 2.0
    counted = counted_receivers(mesh)
    for radiosity in (baked, spot):
        checks = [
            discretisation_error(
                prepared.scene, mesh, radiosity, counted, 0.0, samples=256, rays=256, seed=seed
            )
            for seed in range(16)
        ]
        figures = np.array([c.error[1] for c in checks])
        standard_errors = np.array([c.standard_error[1] for c in checks])
        assert (standard_errors > 0).all() and (standard_errors < figures).all()
        ratio = figures.std(ddof=1) / standard_errors.mean()
        assert 0.5 < ratio < 2.0, ratio


def test_the_estimate_does_not_depend_on_the_threads(
    prepare_furnace: Callable[..., Prepared], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Chunks are traced on every core, their random numbers drawn in order beforehand:
    one thread and two give the same numbers to the bit."""
    prepared = prepare_furnace(0.5, 1.0)
    mesh = prepared.mesh
    wrong = np.full((mesh.receiver_count, 3), 2.2)
    found = []
    for threads in ("1", "2"):
        monkeypatch.setenv("RAYTRAD_THREADS", threads)
        found.append(
            discretisation_error(
                prepared.scene, mesh, wrong, counted_receivers(mesh), 1.0, samples=300, rays=256
            )
        )
    np.testing.assert_array_equal(found[0].residual, found[1].residual)
    np.testing.assert_array_equal(found[0].error, found[1].error)


def test_the_direct_light_near_an_emitter_is_exact_where_nothing_blocks_it() -> None:
    """The check's direct light is a ratio estimate: the exact unoccluded irradiance
    (Lambert's formula on each emitter triangle) times the sampled share that is not
    blocked. Under a 1 m square light of 20 W m-2 at 1 mm and 5 cm, the exact part matches
    the closed form for a point on the normal through a rectangle's centre (four corner
    factors), and with nothing in the way both halves equal it: no noise, where area
    sampling alone read 0.25-2.5 times it from a millimetre away."""
    from types import SimpleNamespace

    from raytrad.core.accuracy import _direct_halves, _unoccluded_direct
    from raytrad.scene import triangle_areas_normals
    from tests.core.analytic import corner_factor

    corners = np.array([[[0, 0, 0], [1, 1, 0], [1, 0, 0]], [[0, 0, 0], [0, 1, 0], [1, 1, 0]]])
    _, facing = triangle_areas_normals(corners.astype(float))  # both face -z
    tracer = SimpleNamespace(
        emitters=np.arange(2),
        corners=corners.astype(float),
        normal=facing,
        two_sided=np.zeros(2, dtype=bool),
        emission=np.full((2, 3), 20.0),
    )
    heights = np.array([0.001, 0.05])
    origin = np.stack([np.full(2, 0.5), np.full(2, 0.5), -heights], axis=1)
    up = np.tile([0.0, 0.0, 1.0], (2, 1))
    exact = _unoccluded_direct(tracer, origin, up)
    want = [20.0 * 4.0 * corner_factor(0.5, 0.5, h) for h in heights]
    np.testing.assert_allclose(exact[:, 0], want, rtol=1e-9)
    # the light's back faces the points: a single-sided emitter lights only its front
    assert not _unoccluded_direct(tracer, origin * [1, 1, -1], -up).any()
    rng = np.random.default_rng(0)
    bare = rng.lognormal(0.0, 2.0, size=(2 * 16, 3))  # heavy-tailed samples, 4 x 4 strata
    halves = _direct_halves(bare, bare, exact, 2, 4)
    np.testing.assert_allclose(halves, np.repeat(exact[:, None, :], 2, axis=1), rtol=1e-12)
    # half the light blocked in every sample: half of the exact light
    halves = _direct_halves(0.5 * bare, bare, exact, 2, 4)
    np.testing.assert_allclose(halves, 0.5 * np.repeat(exact[:, None, :], 2, axis=1))
    # no exact part (too many emitter triangles): the plain sample means
    plain = _direct_halves(bare, bare, None, 2, 4)
    assert not np.allclose(plain[:, 0], plain[:, 1])
