"""Independent reference solutions of the same discrete system the shooting solvers solve."""

from __future__ import annotations

import numpy as np

from raytrad.formfactor import FormFactorEngine
from raytrad.mesh import RadiosityMesh
from raytrad.solver import patch_average_matrix

#: Largest patch count for which the dense matrices are built.
DENSE_PATCH_LIMIT = 4000


def form_factor_matrix(engine: FormFactorEngine) -> np.ndarray:
    """(R, P) float64 dense matrix of F(receiver <- patch) from the engine's columns."""
    mesh = engine.mesh
    matrix = np.zeros((mesh.receiver_count, mesh.patch_count))
    for patch in range(mesh.patch_count):
        column = engine.column(patch)
        matrix[column.receivers, patch] = column.factors
    return matrix


def dense_solve(mesh: RadiosityMesh, engine: FormFactorEngine) -> np.ndarray:
    """Direct solution of equation (1) of :mod:`raytrad.solver`.

    Solves ``(I - W diag(rho) F) B̄ = W E`` per channel with LAPACK, then
    ``B = E + rho F B̄``.

    Returns
    -------
    (R, 3) float64 receiver radiosity [W m-2].

    Raises
    ------
    ValueError
        More than :data:`DENSE_PATCH_LIMIT` patches.
    """
    if mesh.patch_count > DENSE_PATCH_LIMIT:
        raise ValueError(f"{mesh.patch_count} patches is too many for a dense solve")
    factors = form_factor_matrix(engine)
    average = patch_average_matrix(mesh)  # (P, R)
    emission = mesh.receiver_emitted_exitance
    radiosity = np.empty_like(emission)
    identity = np.eye(mesh.patch_count)
    for c in range(3):
        rho = mesh.receiver_reflectance[:, c]
        system = identity - average @ (rho[:, None] * factors)
        patch_radiosity = np.linalg.solve(system, average @ emission[:, c])
        radiosity[:, c] = emission[:, c] + rho * (factors @ patch_radiosity)
    return radiosity
