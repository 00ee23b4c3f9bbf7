"""Reference solutions to measure the true error against: a direct solve of the same
discrete system, the closed-form furnace, a previous result, a long converged run.

None of them reads a file: a previous result comes in as arrays
(:func:`reference_at_receivers`); :func:`raytrad.api.make_reference` reads it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from raytrad.constants import scene_diagonal
from raytrad.core.convergence import Reference
from raytrad.core.formfactor import FormFactorEngine
from raytrad.core.gather import near_field_irradiance
from raytrad.core.mesh import RadiosityMesh
from raytrad.core.solver import SolveSettings, solve
from raytrad.core.system import patch_average_matrix
from raytrad.errors import SceneError, SettingsError
from raytrad.scene import triangle_areas_normals

#: Largest patch count for which the dense matrices are built.
DENSE_PATCH_LIMIT = 4000
#: Largest receivers x patches (dense form-factor matrix entries, 8 bytes each).
DENSE_SIZE_LIMIT = 60_000_000
#: Most near-field rounds of :func:`dense_solve`, and the change that ends them [1].
DENSE_NEAR_FIELD_ROUNDS = 200
DENSE_NEAR_FIELD_CHANGE = 1e-13
#: A previous result whose vertices lie within this fraction of the scene diagonal of the
#: receivers is a result on the same receivers.
SAME_RECEIVERS = 1e-6


def form_factor_matrix(engine: FormFactorEngine) -> np.ndarray:
    """(R, P) float64 dense matrix of F(receiver <- patch) from the engine's columns."""
    mesh = engine.mesh
    matrix = np.zeros((mesh.receiver_count, mesh.patch_count))
    for patch in range(mesh.patch_count):
        column = engine.column(patch)
        matrix[column.receivers, patch] = column.factors
    return matrix


def dense_solve(mesh: RadiosityMesh, engine: FormFactorEngine) -> np.ndarray:
    """Direct solution of equation (1) of :mod:`raytrad.core.solver`, near field included.

    Solves ``(I - W diag(rho) F) B̄ = W E'`` per channel with LAPACK (one LU factorisation
    per channel), then ``B = E' + rho F B̄``, where ``E' = E + rho N(B)`` carries the
    near-field correction ``N`` (:func:`~raytrad.core.gather.near_field_irradiance`) of
    the previous iterate; the iteration contracts by about rho times the near-field share
    of the factors and stops when an iterate changes B by less than
    :data:`DENSE_NEAR_FIELD_CHANGE` of its largest value.

    Returns
    -------
    (R, 3) float64 receiver radiosity [W m-2].

    Raises
    ------
    ValueError
        More than :data:`DENSE_PATCH_LIMIT` patches.
    """
    from scipy.linalg import lu_factor, lu_solve

    if (
        mesh.patch_count > DENSE_PATCH_LIMIT
        or mesh.patch_count * mesh.receiver_count > DENSE_SIZE_LIMIT
    ):
        raise ValueError(
            f"{mesh.receiver_count} receivers x {mesh.patch_count} patches is too large "
            "for a dense solve"
        )
    factors = form_factor_matrix(engine)
    average = patch_average_matrix(mesh)  # (P, R)
    emission = mesh.receiver_emitted_exitance
    rho = mesh.receiver_reflectance
    identity = np.eye(mesh.patch_count)
    systems = [lu_factor(identity - average @ (rho[:, c, None] * factors)) for c in range(3)]
    near = engine.near_field()
    radiosity = np.array(emission, dtype=np.float64)
    for _ in range(DENSE_NEAR_FIELD_ROUNDS):
        correction = near_field_irradiance(
            near, radiosity, average @ radiosity, factors, mesh.receiver_area, engine.subarea_means
        )
        source = emission + rho * correction
        new = np.empty_like(radiosity)
        for c in range(3):
            patch_radiosity = lu_solve(systems[c], average @ source[:, c])
            new[:, c] = source[:, c] + rho[:, c] * (factors @ patch_radiosity)
        change = np.abs(new - radiosity).max()
        radiosity = new
        if not near or change <= DENSE_NEAR_FIELD_CHANGE * np.abs(radiosity).max():
            break
    return radiosity


def analytic_furnace(mesh: RadiosityMesh) -> np.ndarray:
    """B = E / (1 - rho) at every receiver, for a closed scene of uniform rho and E.

    Raises
    ------
    ValueError
        When reflectance or emission is not uniform (the closed form does not apply).
    """
    rho, emission = mesh.receiver_reflectance, mesh.receiver_emitted_exitance
    if np.ptp(rho, axis=0).max() > 0 or np.ptp(emission, axis=0).max() > 0:
        raise ValueError(
            "the analytic reference needs uniform reflectance and emission on every surface"
        )
    return emission / (1.0 - rho)


def reference_at_receivers(
    positions: np.ndarray,
    triangles: np.ndarray,
    radiosity: np.ndarray,
    mesh: RadiosityMesh,
    source: str | Path | None = None,
) -> np.ndarray:
    """Radiosity of a previous result at this mesh's receivers.

    The same mesh settings give the same receivers in the same order, which are used as
    they are. Otherwise each receiver takes the value of the nearest reference vertex whose
    surface faces the same way (a finer converged run is a good reference).

    Parameters
    ----------
    positions : (V, 3) float [m]
    triangles : (T, 3) int
    radiosity : (V, 3) float [W m-2]
        A previous result (as :func:`raytrad.formats.ply.read_radiosity_ply` reads it).
    mesh : RadiosityMesh
    source : path-like or None
        Where the result came from, for messages.

    Returns
    -------
    (R, 3) float64 [W m-2]

    Raises
    ------
    SceneError
        The result has no vertex facing like some receiver.
    """
    diagonal = scene_diagonal(mesh.receiver_position)
    if positions.shape == mesh.receiver_position.shape and np.allclose(
        positions, mesh.receiver_position, rtol=0.0, atol=SAME_RECEIVERS * diagonal
    ):
        return np.asarray(radiosity, dtype=np.float64)
    return _nearest_facing(source, positions, triangles, radiosity, mesh)


def named_reference(
    spec: str, mesh: RadiosityMesh, engine: FormFactorEngine, can_occlude: bool
) -> Reference:
    """The reference ``dense`` (direct solve of the same discrete system) or ``analytic``
    (B = E/(1-rho), closed convex enclosures of uniform materials).

    Raises
    ------
    SettingsError
        It does not apply to this scene (too many patches for a dense solve, something can
        occlude, materials not uniform), or ``spec`` names neither.
    """
    if spec == "dense":
        try:
            radiosity = dense_solve(mesh, engine)
        except ValueError as exc:
            raise SettingsError(f"{exc}; use fewer patches or a previous result") from exc
        return Reference(radiosity, "dense", "direct solve of the same discrete system")
    if spec == "analytic":
        if can_occlude:
            raise SettingsError(
                "the analytic reference B = E/(1-rho) needs a closed convex enclosure"
            )
        try:
            radiosity = analytic_furnace(mesh)
        except ValueError as exc:
            raise SettingsError(str(exc)) from exc
        return Reference(radiosity, "analytic", "closed enclosure: B = E / (1 - rho)")
    raise SettingsError(f"unknown reference {spec!r}: dense, analytic or a result PLY")


def automatic_reference(
    mesh: RadiosityMesh, engine: FormFactorEngine, tolerance: float
) -> Reference:
    """A dense solve when it fits in memory, else an ambient solve of the same system to
    ``min(1e-6, tolerance / 100)``, described as such."""
    size = mesh.patch_count * mesh.receiver_count
    if mesh.patch_count <= DENSE_PATCH_LIMIT and size <= DENSE_SIZE_LIMIT:
        return Reference(
            dense_solve(mesh, engine), "dense", "direct solve of the same discrete system"
        )
    result = solve(mesh, engine, SolveSettings("ambient", tolerance=min(1e-6, tolerance * 1e-2)))
    return Reference(
        result.radiosity,
        "converged",
        f"ambient solve of the same system to a residual of {result.residual:.1e} "
        "(too large for a dense solve)",
    )


def _nearest_facing(
    path: str | Path | None,
    positions: np.ndarray,
    triangles: np.ndarray,
    radiosity: np.ndarray,
    mesh: RadiosityMesh,
) -> np.ndarray:
    from scipy.spatial import cKDTree

    _, face_normal = triangle_areas_normals(positions[triangles])
    normal = np.zeros_like(positions)
    for k in range(3):
        np.add.at(normal, triangles[:, k], face_normal)
    normal /= np.maximum(np.linalg.norm(normal, axis=1), 1e-300)[:, None]
    tree = cKDTree(positions)
    count = min(16, len(positions))
    _, candidates = tree.query(mesh.receiver_position, k=count)
    candidates = candidates.reshape(len(mesh.receiver_position), count)
    facing = np.einsum("rkj,rj->rk", normal[candidates], mesh.receiver_normal) > 0.5
    if not facing.any(axis=1).all():
        raise SceneError(path, "reference has no vertex facing like some receivers")
    best = candidates[np.arange(len(candidates)), np.argmax(facing, axis=1)]
    return radiosity[best]
