"""An independent reference: irradiance at surface points by Monte Carlo path tracing.

It shares nothing with the radiosity solver but the scene and Embree, so agreement between
the two (within the path tracer's standard error) checks form factors, visibility, meshing
and the solve at once.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from raytrad.constants import tol
from raytrad.core.visibility import Occluder
from raytrad.scene import Scene, triangle_areas_normals


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
    rng = np.random.default_rng(seed)
    tracer = Tracer(scene, Occluder(scene.positions, scene.triangles), rng)
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


class Tracer:
    """Vectorised path tracing over many paths from one point (see
    :func:`path_traced_radiosity`), and one-sample direct lighting (:meth:`direct`).

    ``occluder`` may be built on any triangulation of the scene's surfaces (a refined
    mesh): emitters are the scene's, in the occluder's local frame.
    """

    def __init__(self, scene: Scene, occluder: Any, rng: np.random.Generator) -> None:
        self.occluder = occluder
        self.rng = rng
        corners = scene.triangle_vertices()
        areas, self.normal = triangle_areas_normals(corners)
        self.corners = occluder.to_local(corners.reshape(-1, 3)).reshape(-1, 3, 3)
        self.reflectance = scene.reflectance
        self.emission = scene.emitted_exitance
        self.two_sided = scene.double_sided
        self.offset = tol.ray_margin * occluder.diagonal
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
            direction = cosine_directions(normal, self.rng)
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

    def direct(
        self, origin: np.ndarray, normal: np.ndarray, uniforms: np.ndarray | None = None
    ) -> np.ndarray:
        """(N, 3) one-sample estimate of the irradiance from emitters at each origin.

        ``origin`` is in the occluder's local frame. ``uniforms`` ((N, 2) in [0, 1), drawn
        when None) pick the point on the emitters: the first selects by cumulative area
        (its remainder and the second place the point in the triangle by the square-root
        map), so stratified uniforms give stratified emitter samples.
        """
        return self.direct_and_unoccluded(origin, normal, uniforms)[0]

    def direct_and_unoccluded(
        self, origin: np.ndarray, normal: np.ndarray, uniforms: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """(N, 3) :meth:`direct`'s estimate, and (N, 3) the same samples' estimate with
        nothing blocking them: their ratio is the visible share of the emitters' light."""
        if self.emitter_area == 0.0:
            return np.zeros((len(origin), 3)), np.zeros((len(origin), 3))
        if uniforms is None:
            uniforms = self.rng.random((len(origin), 2))
        s = uniforms[:, 0] * self.emitter_area
        pick = np.minimum(
            np.searchsorted(self.emitter_cdf, s, side="right"), len(self.emitters) - 1
        )
        tri = self.emitters[pick]
        before = np.concatenate([[0.0], self.emitter_cdf])[pick]
        size = np.diff(np.concatenate([[0.0], self.emitter_cdf]))[pick]
        root = np.sqrt(np.clip((s - before) / np.maximum(size, 1e-300), 0.0, 1.0))
        u, v = root * (1.0 - uniforms[:, 1]), root * uniforms[:, 1]
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
        bare = np.where(ok, cos_x * cos_y / dist2, 0.0)
        geometry = np.where(blocked, 0.0, bare)
        # emitted radiance E / pi, times the area of all emitters (pdf 1 / area)
        radiance = self.emission[tri] / np.pi
        return (
            radiance * (geometry * self.emitter_area)[:, None],
            radiance * (bare * self.emitter_area)[:, None],
        )


def cosine_directions(normal: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(N, 3) unit directions, cosine-distributed about each (N, 3) unit normal."""
    return cosine_directions_from(normal, rng.random(len(normal)), rng.random(len(normal)))


def cosine_directions_from(normal: np.ndarray, u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """(N, 3) unit directions about each (N, 3) unit normal from (N,) uniform numbers in
    [0, 1): cosine-distributed when ``u1, u2`` are uniform (stratify them to stratify the
    directions). ``u1`` sets the polar angle (``sin^2 theta = u1``), ``u2`` the azimuth."""
    r, phi = np.sqrt(u1), 2.0 * np.pi * u2
    local = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1.0 - u1)], axis=1)
    helper = np.where(np.abs(normal[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    tangent = np.cross(normal, helper)
    tangent /= np.linalg.norm(tangent, axis=1)[:, None]
    bitangent = np.cross(normal, tangent)
    return local[:, :1] * tangent + local[:, 1:2] * bitangent + local[:, 2:] * normal
