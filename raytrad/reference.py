"""Independent reference solutions of the same discrete system the shooting solvers solve."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from raytrad.errors import SceneError
from raytrad.formfactor import FormFactorEngine
from raytrad.mesh import RadiosityMesh
from raytrad.scene import Scene, triangle_areas_normals
from raytrad.solver import patch_average_matrix

#: Largest patch count for which the dense matrices are built.
DENSE_PATCH_LIMIT = 4000
#: Largest receivers x patches (dense form-factor matrix entries, 8 bytes each).
DENSE_SIZE_LIMIT = 60_000_000


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
    radiosity = np.empty_like(emission)
    identity = np.eye(mesh.patch_count)
    for c in range(3):
        rho = mesh.receiver_reflectance[:, c]
        system = identity - average @ (rho[:, None] * factors)
        patch_radiosity = np.linalg.solve(system, average @ emission[:, c])
        radiosity[:, c] = emission[:, c] + rho * (factors @ patch_radiosity)
    return radiosity


def path_traced_radiosity(
    scene: Scene,
    points: np.ndarray,
    normals: np.ndarray,
    paths: int = 20000,
    seed: int = 0,
    max_bounces: int = 64,
) -> tuple[np.ndarray, np.ndarray]:
    """Irradiance at surface points by Monte Carlo path tracing: an independent reference.

    Shares nothing with the radiosity solver but the scene and Embree. The irradiance is
    ``H(x) = H_direct(x) + rho(y1) [H_direct(y1) + rho(y2) [...]]`` along cosine-distributed
    paths x -> y1 -> y2 ..., with the direct term from one emitter sample per vertex (next
    event estimation: area-weighted point on the emitters, shadow ray) and Russian roulette
    after three bounces. Single-sided surfaces emit and reflect on their front only.

    Parameters
    ----------
    scene : Scene
    points : (N, 3) float64
        Points on surfaces of ``scene`` [m].
    normals : (N, 3) float64
        Their unit normals (the lit side).
    paths : int
        Paths per point.

    Returns
    -------
    irradiance : (N, 3) float64
        Estimated irradiance H [W m-2]; the radiosity is E + rho H.
    standard_error : (N, 3) float64
        One standard error of the estimate [W m-2].
    """
    from raytrad.visibility import Occluder

    rng = np.random.default_rng(seed)
    tracer = _Tracer(scene, Occluder(scene.positions, scene.triangles), rng)
    mean = np.zeros((len(points), 3))
    error = np.zeros((len(points), 3))
    try:
        for i, (x, n) in enumerate(zip(points, normals, strict=True)):
            total = tracer.irradiance_paths(x, n, paths, max_bounces)
            mean[i] = total.mean(axis=0)
            error[i] = total.std(axis=0) / np.sqrt(paths)
    finally:
        tracer.occluder.close()
    return mean, error


class _Tracer:
    """Vectorised path tracing over many paths from one point (see path_traced_radiosity)."""

    def __init__(self, scene: Scene, occluder: Any, rng: np.random.Generator) -> None:
        self.occluder = occluder
        self.rng = rng
        corners = scene.triangle_vertices()
        areas, self.normal = triangle_areas_normals(corners)
        self.corners = occluder.to_local(corners.reshape(-1, 3)).reshape(-1, 3, 3)
        self.reflectance = scene.reflectance
        self.emission = scene.emitted_exitance
        self.two_sided = scene.double_sided
        self.offset = 1e-6 * occluder.diagonal
        emitters = np.nonzero((self.emission > 0).any(axis=1))[0]
        self.emitters = emitters
        self.emitter_cdf = np.cumsum(areas[emitters])
        self.emitter_area = float(self.emitter_cdf[-1]) if len(emitters) else 0.0

    def irradiance_paths(
        self, x: np.ndarray, n: np.ndarray, paths: int, max_bounces: int
    ) -> np.ndarray:
        """(paths, 3) per-path irradiance estimates at point x (normal n) [W m-2]."""
        origin = np.tile(self.occluder.to_local(x[None, :]) + self.offset * n, (paths, 1))
        normal = np.tile(n, (paths, 1))
        throughput = np.ones((paths, 3))
        total = np.zeros((paths, 3))
        alive = np.arange(paths)
        for bounce in range(max_bounces):
            total[alive] += throughput * self.direct(origin, normal)
            direction = _cosine_directions(normal, self.rng)
            hit, distance = self.occluder.intersect_local(origin, direction)
            ok = hit >= 0
            cos_hit = np.zeros(len(hit))
            cos_hit[ok] = np.einsum("ij,ij->i", self.normal[hit[ok]], direction[ok])
            ok &= (cos_hit < 0) | self.two_sided[np.maximum(hit, 0)]
            alive, throughput, direction = alive[ok], throughput[ok], direction[ok]
            hit, distance, origin, cos_hit = hit[ok], distance[ok], origin[ok], cos_hit[ok]
            if len(alive) == 0:
                break
            throughput = throughput * self.reflectance[hit]
            normal = self.normal[hit] * -np.sign(cos_hit)[:, None]
            origin = origin + direction * distance[:, None] + self.offset * normal
            if bounce >= 2:
                survive = np.clip(throughput.max(axis=1), 0.05, 1.0)
                keep = self.rng.random(len(alive)) < survive
                throughput = throughput[keep] / survive[keep, None]
                alive, origin, normal = alive[keep], origin[keep], normal[keep]
        return total

    def direct(self, origin: np.ndarray, normal: np.ndarray) -> np.ndarray:
        """(N, 3) one-sample estimate of the irradiance from emitters at each origin."""
        if self.emitter_area == 0.0:
            return np.zeros((len(origin), 3))
        pick = np.searchsorted(self.emitter_cdf, self.rng.random(len(origin)) * self.emitter_area)
        tri = self.emitters[np.minimum(pick, len(self.emitters) - 1)]
        u, v = self.rng.random(len(origin)), self.rng.random(len(origin))
        flip = u + v > 1.0
        u, v = np.where(flip, 1.0 - u, u), np.where(flip, 1.0 - v, v)
        c = self.corners[tri]
        target = c[:, 0] + u[:, None] * (c[:, 1] - c[:, 0]) + v[:, None] * (c[:, 2] - c[:, 0])
        delta = target - origin
        dist2 = np.einsum("ij,ij->i", delta, delta)
        dist = np.sqrt(dist2)
        direction = delta / dist[:, None]
        cos_x = np.einsum("ij,ij->i", direction, normal)
        cos_y = -np.einsum("ij,ij->i", direction, self.normal[tri])
        cos_y = np.where(self.two_sided[tri], np.abs(cos_y), cos_y)
        ok = (cos_x > 0) & (cos_y > 0)
        blocked = np.ones(len(origin), dtype=bool)
        if ok.any():
            blocked[ok] = self.occluder.occluded_local(
                origin[ok], direction[ok], dist[ok] - 2.0 * self.offset
            )
        geometry = np.where(ok & ~blocked, cos_x * cos_y / dist2, 0.0)
        # emitted radiance E / pi, times the area of all emitters (pdf 1 / area)
        return self.emission[tri] / np.pi * (geometry * self.emitter_area)[:, None]


def _cosine_directions(normal: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(N, 3) unit directions, cosine-distributed about each (N, 3) unit normal."""
    u1, u2 = rng.random(len(normal)), rng.random(len(normal))
    r, phi = np.sqrt(u1), 2.0 * np.pi * u2
    local = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1.0 - u1)], axis=1)
    helper = np.where(np.abs(normal[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    tangent = np.cross(normal, helper)
    tangent /= np.linalg.norm(tangent, axis=1)[:, None]
    bitangent = np.cross(normal, tangent)
    return local[:, :1] * tangent + local[:, 1:2] * bitangent + local[:, 2:] * normal


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


def reference_from_ply(path: str | Path, mesh: RadiosityMesh) -> np.ndarray:
    """Radiosity of a previous result (a raytrad PLY) at this mesh's receivers.

    The same mesh settings give the same receivers in the same order, which are used as
    they are. Otherwise each receiver takes the value of the nearest reference vertex whose
    surface faces the same way (a finer converged run is a good reference).

    Raises
    ------
    SceneError
        The file is not a raytrad result, or has no vertex facing like some receiver.
    """
    from raytrad.io.ply import read_radiosity_ply

    path = Path(path)
    positions, triangles, radiosity = read_radiosity_ply(path)
    diagonal = float(np.linalg.norm(np.ptp(mesh.receiver_position, axis=0)))
    if positions.shape == mesh.receiver_position.shape and np.allclose(
        positions, mesh.receiver_position, rtol=0.0, atol=1e-6 * diagonal
    ):
        return radiosity
    return _nearest_facing(path, positions, triangles, radiosity, mesh)


def _nearest_facing(
    path: Path,
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
