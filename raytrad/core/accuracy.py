"""How wrong is the bake against the physical answer: the total error and its parts.

The algebraic error log (:mod:`raytrad.core.convergence`) covers only how far the shooting
is from the solution of the *discrete* system. The bake also differs from the physical
answer because of the discretisation. Every figure here is a relative RMS per channel over
the receivers that do not emit (:func:`~raytrad.core.convergence.counted_receivers`).

* **discretisation** (the residual check): the residual of the continuous radiosity
  equation ``r(x) = E(x) + rho(x) H[B](x) - B(x)`` at ``samples`` points on the
  (refined) mesh, where ``B(x)`` is what the bake shows there (the vertex radiosity
  interpolated over the triangle) and ``H[B](x)`` the irradiance the bake sends to the
  point, estimated by Monte Carlo independently of patches, their form factors and
  visibility samples: direct light by stratified emitter sampling (the sampled share not
  blocked times the exact unoccluded irradiance, :func:`_direct_halves`), the rest by
  stratified cosine-distributed rays reading the bake where they land. The points are
  importance-sampled: half by area, half by area times the squared spread of the
  triangle's corners, where the interpolation errs (a block's corners and penumbrae: a
  small share of the area that area-uniform points mostly miss); each is weighted back
  by its area density over its sampling density. The residual's RMS, with the Monte
  Carlo noise subtracted and :data:`STANDARD_ERRORS` standard errors of its own estimate
  added, is amplified by interreflection: the error ``e`` solves ``(I - K) e = r``, and
  ``|e| <~ |r| / (1 - rho g)`` with rho the mean reflectance and g the mean capture
  fraction of the patches. It sees every way the bake misses the equation: linear
  interpolation across shadow edges and contact lines, the patch-average bias, sampled
  visibility, energy lost by the discrete system, and the algebraic error of the final
  state itself;
* **algebraic**: the solve's own estimate of the change still to come
  (:func:`~raytrad.core.convergence.error_estimate`) at its end; the guaranteed bound
  stays in the error log under its own name;
* **conservation**: closed receivers whose form-factor rows could not be held to 1,
  amplified by interreflection, ``rho delta / (1 - rho)``.

The total at the end is ``sqrt(max(discretisation, algebraic)^2 + conservation^2)``:
``error.total_rms`` in ``report.json``. The ``total_rms`` column of the error log adds,
at every earlier log point, that point's guaranteed algebraic bound to the final total
(the error there is at most the way still to go plus the final error).
"""

from __future__ import annotations

from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from raytrad.constants import tol
from raytrad.core.formfactor import FormFactorEngine
from raytrad.core.hidden import fill_hidden
from raytrad.core.kernels import numpy_polygon_form_factor
from raytrad.core.mesh import RadiosityMesh
from raytrad.core.pathtrace import Tracer, cosine_directions_from
from raytrad.core.shading import shade, triangle_normals, twin_triangles
from raytrad.core.visibility import Occluder, ordered_map, worker_count
from raytrad.scene import Scene

#: Points sampled for the discretisation part.
SAMPLES = 2048

#: The discretisation part is named the dominant one only above this many times the
#: algebraic part (:attr:`ErrorParts.dominant`).
OWN_SHARE = 2.0

#: Rays per point for the discretisation part: a quarter sample the emitters, the rest
#: the hemisphere, stratified.
RAYS = 1024

#: Standard errors of its own estimate added to the residual's mean square: the error is
#: confined to a few places (a block's corners, penumbrae), so the estimate is skewed and
#: one standard error was under the true error in 2 of 10 checks of a block's bake.
STANDARD_ERRORS = 2.0

#: Points traced together (memory: about 200 bytes per ray).
_CHUNK = 64

#: Most (point, emitter triangle) pairs whose exact unoccluded irradiance the check
#: computes for its direct light (:func:`_direct_halves`), in numpy (2 us a pair: about
#: 1 s, and no kernel to compile for a check the Cornell box needs 2 048 pairs for);
#: beyond it (an emissive mesh of hundreds of triangles) the direct light is sampled
#: alone.
EXACT_DIRECT_PAIRS = 1 << 19


@dataclass(frozen=True)
class ErrorParts:
    """The estimated total error of a bake and its parts, relative RMS per channel [1].

    Attributes
    ----------
    algebraic, discretisation, conservation : (3,) float64
        See the module docstring.
    samples : int
        Points the discretisation part was measured at.
    discretisation_standard_error : (3,) float64
        The discretisation part's own standard error, from the check's sampling
        (:attr:`Residual.standard_error`) [1].
    """

    algebraic: np.ndarray
    discretisation: np.ndarray
    conservation: np.ndarray
    samples: int = 0
    discretisation_standard_error: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @property
    def total(self) -> np.ndarray:
        """(3,) float64: ``sqrt(max(discretisation, algebraic)^2 + conservation^2)``."""
        measured = np.maximum(self.discretisation, self.algebraic)
        return np.asarray(np.sqrt(measured**2 + self.conservation**2))

    @property
    def dominant(self) -> str:
        """The name of the largest part (worst channel). The residual check behind the
        discretisation part sees the algebraic error too, so it is named only when it
        exceeds :data:`OWN_SHARE` times the algebraic part: below that an unfinished solve
        can explain it (a run stopped by its time limit after a few shots)."""
        algebraic = float(np.max(self.algebraic))
        parts = {
            "algebraic": algebraic,
            "discretisation": float(np.max(self.discretisation)),
            "conservation": float(np.max(self.conservation)),
        }
        if parts["discretisation"] <= OWN_SHARE * algebraic:
            parts["discretisation"] = 0.0
        return max(parts, key=lambda name: parts[name])


@dataclass(frozen=True)
class Residual:
    """The Monte Carlo residual check of a bake (see the module docstring).

    Attributes
    ----------
    error : (3,) float64
        The discretisation error estimate [1]: ``residual`` (plus one standard error)
        times ``gain``.
    residual : (3,) float64
        RMS of the residual with the Monte Carlo noise subtracted, relative [1].
    noise : (3,) float64
        RMS of the Monte Carlo noise of the points' estimates, relative [1].
    gain : (3,) float64
        Interreflection amplification ``1 / (1 - rho g)`` [1].
    samples : int
    standard_error : (3,) float64
        ``error``'s own standard error from the check's sampling of points and rays [1]:
        the mean square's standard error carried through the square root (the delta
        method). A check with another seed lands within about this of ``error`` (the
        Cornell box's default bake, 8 seeds: 3.6e-3 to 5.6e-3, standard deviation
        6.8e-4, against 5.1e-4 to 7.7e-4 computed here).
    """

    error: np.ndarray
    residual: np.ndarray
    noise: np.ndarray
    gain: np.ndarray
    samples: int
    standard_error: np.ndarray = field(default_factory=lambda: np.zeros(3))


def discretisation_error(
    scene: Scene,
    mesh: RadiosityMesh,
    radiosity: np.ndarray,
    counted: np.ndarray,
    capture: float,
    samples: int = SAMPLES,
    rays: int = RAYS,
    seed: int = 0,
) -> Residual:
    """The discretisation error of a bake, from the residual of the radiosity equation.

    Parameters
    ----------
    scene : Scene
        The repaired scene (its emitters are sampled for direct light).
    mesh : RadiosityMesh
        The mesh ``radiosity`` lives on (refined or not).
    radiosity : (R, 3) float64 [W m-2]
        The baked radiosity per receiver (hidden ones are shown as
        :func:`~raytrad.core.hidden.fill_hidden` fills them).
    counted : (R,) bool
        Receivers the error is taken over (:func:`~raytrad.core.convergence.counted_receivers`).
    capture : float
        Mean fraction of what a patch shoots that lands on surfaces [1].
    samples : int
        Points drawn over counted triangles whose corners are all seen (see
        :func:`_surface_samples`).
    rays : int
        Rays per point.
    seed : int

    Returns
    -------
    Residual
        Zeros when there is nothing to sample or nothing reflects.
    """
    # what the bake shows: a ray landing by a hidden receiver (a table leg's foot) reads
    # its neighbours' radiosity, as an image does, not the solve's zero
    radiosity = fill_hidden(mesh, radiosity)
    area = mesh.receiver_area * counted
    norm = np.sqrt(area @ radiosity**2 / max(float(area.sum()), 1e-300))
    seen = (mesh.receiver_area > 0) & counted
    usable = seen[mesh.triangle_receivers].all(axis=1) & (mesh.triangle_area > 0)
    zero = np.zeros(3)
    if samples < 1 or rays < 2 or not usable.any() or not (norm > 0).any():
        return Residual(zero, zero, zero, np.ones(3), 0)
    rng = np.random.default_rng(seed)
    tri, weights, share = _surface_samples(
        mesh, usable, _spread(mesh, radiosity, norm), samples, rng
    )
    receivers = mesh.triangle_receivers[tri]
    shown = np.einsum("nk,nkc->nc", weights, radiosity[receivers])
    irradiance, variance, shut = _gathered(scene, mesh, radiosity, tri, weights, rays, rng)
    rho = mesh.receiver_reflectance[receivers[:, 0]]
    residual = mesh.receiver_emitted_exitance[receivers[:, 0]] + rho * irradiance - shown
    noise = rho**2 * variance
    # a point shut in (the gap behind a lamp) is seen by no one, like a hidden receiver
    keep = ~shut
    residual, noise, share, samples = residual[keep], noise[keep], share[keep], int(keep.sum())
    if samples == 0:
        return Residual(zero, zero, zero, np.ones(3), 0)
    # per point E[r^2] = r_true^2 + noise; the share-weighted (self-normalised) means
    # undo the importance sampling
    excess = residual**2 - noise
    weight = share / share.sum()
    mean = np.maximum(weight @ excess, 0.0)
    spread = np.sqrt(weight**2 @ (excess - weight @ excess) ** 2)
    noise = weight @ noise
    rel = np.where(norm > 0, 1.0 / np.where(norm > 0, norm, 1.0), 0.0)
    reflectance = area @ mesh.receiver_reflectance / max(float(area.sum()), 1e-300)
    gain = 1.0 / np.maximum(1.0 - reflectance * min(capture, 1.0), 1e-6)
    root = np.sqrt(mean + STANDARD_ERRORS * spread)
    # d sqrt(m) = dm / (2 sqrt(m)): the mean square's standard error through the root
    slope = np.where(root > 0, 0.5 / np.where(root > 0, root, 1.0), 0.0)
    return Residual(
        error=root * rel * gain,
        residual=np.sqrt(mean) * rel,
        noise=np.sqrt(noise) * rel,
        gain=gain,
        samples=samples,
        standard_error=slope * spread * rel * gain,
    )


def _spread(mesh: RadiosityMesh, radiosity: np.ndarray, norm: np.ndarray) -> np.ndarray:
    """(T,) float64: each triangle's largest corner spread of radiosity relative to the
    bake's RMS ``norm`` (worst channel), squared [1]."""
    corners = radiosity[mesh.triangle_receivers]  # (T, 3, 3)
    spread = corners.max(axis=1) - corners.min(axis=1)
    rel = spread / np.where(norm > 0, norm, np.inf)
    return np.nan_to_num(rel.max(axis=1) ** 2, posinf=0.0)


def _surface_samples(
    mesh: RadiosityMesh,
    usable: np.ndarray,
    spread: np.ndarray,
    samples: int,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points on the ``usable`` triangles, importance-sampled where the radiosity changes.

    Interpolation error is largest where a triangle's corners differ (penumbrae, contact
    shadows), a small share of the area that uniform points mostly miss. Half the points
    are drawn by area and half by area times the squared corner ``spread``
    (:func:`_spread`, a defensive mixture: no triangle is sampled less than half as often
    as by area alone); each point's ``share`` is its area density over its sampling
    density, so ``mean(share * f)`` estimates the area mean of ``f`` without bias.

    Returns
    -------
    tri : (N,) int64
    weights : (N, 3) float64
        Barycentric weights, area-uniform within the triangle.
    share : (N,) float64 [1]
    """
    area = np.where(usable, mesh.triangle_area, 0.0)
    by_area = area / area.sum()
    by_spread = area * spread
    total = float(by_spread.sum())
    density = by_area if total <= 0 else 0.5 * (by_area + by_spread / total)
    cumulative = np.cumsum(density)
    tri = np.searchsorted(cumulative, rng.random(samples) * cumulative[-1], side="right")
    tri = np.minimum(tri, len(area) - 1)
    share = by_area[tri] / density[tri]
    u, v = rng.random(samples), rng.random(samples)
    flip = u + v > 1.0
    u, v = np.where(flip, 1.0 - u, u), np.where(flip, 1.0 - v, v)
    return tri, np.stack([1.0 - u - v, u, v], axis=1), share


def _gathered(
    scene: Scene,
    mesh: RadiosityMesh,
    radiosity: np.ndarray,
    tri: np.ndarray,
    weights: np.ndarray,
    rays: int,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(N, 3) irradiance the bake sends to the sample points, its variance, and (N,) bool
    which points are shut in.

    Direct light by emitter sampling
    (:meth:`~raytrad.core.pathtrace.Tracer.direct_and_unoccluded`) as a share of the
    exact unoccluded irradiance (:func:`_direct_halves`), the rest by stratified
    cosine-distributed rays reading the bake's *reflected* radiosity ``B - E`` where they
    land (emission is the direct part's). The rays form two
    independent halves (a checkerboard of the strata, half the emitter samples each):
    with ``H_a``, ``H_b`` their estimates, ``H = (H_a + H_b) / 2`` has variance
    ``E[(H_a - H_b)^2] / 4``, however well stratification works (the direct light's
    ratio estimate is biased by order 1 / samples). A point is shut
    in when most of its rays hit the back of single-sided surfaces (as
    :meth:`~raytrad.core.visibility.Occluder.probe_hemispheres` decides for receivers),
    or when its rays find backs and nothing else: no surface's front sees it, so no light
    reaches it and none leaves it for another surface (the part of a crate sunk into a
    floor, below the floor: what it shows is seen by no one in the room).
    """
    side = max(2, int(np.sqrt(rays * 3 // 4)) // 2 * 2)  # strata per axis, even
    light_side = max(2, int(np.sqrt(max(rays - side * side, 4))) // 2 * 2)
    points = np.einsum("nk,nkj->nj", weights, mesh.positions[mesh.triangles[tri]])
    normals = mesh.triangle_normal[tri]
    reflected = radiosity - mesh.receiver_emitted_exitance
    _, triangle_normal = triangle_normals(mesh)
    twin = twin_triangles(mesh.triangles)
    irradiance = np.zeros((len(tri), 3))
    variance = np.zeros((len(tri), 3))
    shut = np.zeros(len(tri), dtype=bool)
    occluder = Occluder(mesh.positions, mesh.triangles)
    workers = worker_count()
    try:
        tracer = Tracer(scene, occluder, rng)
        origin = occluder.to_local(points) + tol.ray_margin * occluder.diagonal * normals
        exact = None  # the unoccluded direct light, where affordable (:func:`_direct_halves`)
        if len(tracer.emitters) * len(tri) <= EXACT_DIRECT_PAIRS:
            exact = _unoccluded_direct(tracer, origin, normals)

        def draws() -> Iterator[tuple[slice, np.ndarray, np.ndarray]]:
            """Each chunk's stratified uniforms, drawn here in order (the same numbers
            however the threads run)."""
            for start in range(0, len(tri), _CHUNK):
                part = slice(start, min(start + _CHUNK, len(tri)))
                n = part.stop - part.start
                yield part, _strata(n, light_side, rng), _strata(n, side, rng)

        def work(
            item: tuple[slice, np.ndarray, np.ndarray],
        ) -> tuple[slice, np.ndarray, np.ndarray]:
            part, u_light, u = item
            n = part.stop - part.start
            o = np.repeat(origin[part], light_side**2, axis=0)
            light = tracer.direct_and_unoccluded(
                o, np.repeat(normals[part], light_side**2, axis=0), u_light
            )
            normal = np.repeat(normals[part], side**2, axis=0)
            direction = cosine_directions_from(normal, u[:, 0], u[:, 1])
            o = np.repeat(origin[part], side**2, axis=0)
            hit, _, w = occluder.intersect_barycentric_local(o, direction)
            seen = shade(hit, w, direction, mesh, reflected, triangle_normal, twin)
            direct = _direct_halves(*light, None if exact is None else exact[part], n, light_side)
            halves = direct + _halves(seen, n, side)  # (n, 2, 3)
            back = _back_hits(hit, direction, triangle_normal, twin).reshape(n, -1)
            front = ((hit >= 0).reshape(n, -1) & ~back).any(axis=1)
            return part, halves, (back.mean(axis=1) > 0.5) | (back.any(axis=1) & ~front)

        with ThreadPoolExecutor(workers, thread_name_prefix="raytrad-error") as pool:
            for part, halves, shut_in in ordered_map(pool, work, draws(), 2 * workers):
                irradiance[part] = halves.mean(axis=1)
                variance[part] = (halves[:, 0] - halves[:, 1]) ** 2 / 4.0
                shut[part] = shut_in
    finally:
        occluder.close()
    return irradiance, variance, shut


def _unoccluded_direct(tracer: Tracer, origin: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """(N, 3) exact irradiance from every emitter triangle of ``tracer`` at each origin
    (its occluder's local frame) with nothing in the way, ``sum_e E_e F(x <- e)``
    [W m-2]: Lambert's formula on each triangle clipped to the origin's horizon
    (:func:`~raytrad.core.kernels.numpy_polygon_form_factor`), a single-sided one only
    from its front."""
    out = np.zeros((len(origin), 3))
    emitters = tracer.emitters
    step = max(1, (1 << 16) // max(len(origin), 1))  # emitter triangles at a time
    for a in range(0, len(emitters), step):
        part = emitters[a : a + step]
        corners = np.tile(tracer.corners[part], (len(origin), 1, 1))
        x = np.repeat(origin, len(part), axis=0)
        facing = np.tile(tracer.normal[part], (len(origin), 1))
        seen = np.einsum("ij,ij->i", x - corners[:, 0], facing) > 0
        seen |= np.tile(tracer.two_sided[part], len(origin))
        factor = np.zeros(len(x))
        if seen.any():
            n = np.repeat(normal, len(part), axis=0)
            factor[seen] = numpy_polygon_form_factor(corners[seen], x[seen], n[seen])
        out += factor.reshape(len(origin), len(part)) @ tracer.emission[part]
    return out


def _direct_halves(
    light: np.ndarray, bare: np.ndarray, exact: np.ndarray | None, n: int, side: int
) -> np.ndarray:
    """(n, 2, 3): the direct light at n points, two independent estimates each.

    With the exact unoccluded irradiance ``exact`` (n, 3), each half is a ratio estimate:
    ``exact x sum(light) / sum(bare)``, the share of the emitter samples' light that is
    not blocked times what all of it would give. Where nothing blocks the emitters it is
    exact, whatever the samples; near an emitter, where one area sample in many carries
    most of the light, area sampling alone was noise (a ceiling 1 mm over a light read
    0.25-2.5 times its irradiance at a point, and the check's noise swamped the residual).
    The ratio's bias falls as 1 / samples. Without ``exact`` (too many emitter triangles
    for the points, :data:`EXACT_DIRECT_PAIRS`), or where no sample faces an emitter, the
    plain estimate ``light``.
    """
    plain = _halves(light, n, side)
    if exact is None:
        return plain
    total = _halves(bare, n, side)
    ratio = np.divide(plain, total, out=np.zeros_like(plain), where=total > 0)
    return np.where(total > 0, exact[:, None, :] * ratio, plain)


def _strata(n: int, side: int, rng: np.random.Generator) -> np.ndarray:
    """(n * side^2, 2) uniforms in [0, 1): for each of n points, one jittered sample in
    each cell of a ``side`` x ``side`` grid."""
    i, j = np.divmod(np.arange(side * side), side)
    jitter = rng.random((n, side * side, 2))
    return ((np.stack([i, j], axis=1)[None] + jitter) / side).reshape(-1, 2)


def _halves(values: np.ndarray, n: int, side: int) -> np.ndarray:
    """(n, 2, 3): the means of (n * side^2, 3) stratified values over the two colours of
    the strata's checkerboard, two independent estimates per point."""
    i, j = np.divmod(np.arange(side * side), side)
    black = (i + j) % 2 == 0
    values = values.reshape(n, side * side, 3)
    return np.stack([values[:, black].mean(axis=1), values[:, ~black].mean(axis=1)], axis=1)


def _back_hits(
    hit: np.ndarray, direction: np.ndarray, normal: np.ndarray, twin: np.ndarray
) -> np.ndarray:
    """(N,) bool: rays that hit the back of a single-sided triangle."""
    out = np.zeros(len(hit), dtype=bool)
    ok = np.nonzero(hit >= 0)[0]
    tri = hit[ok]
    out[ok] = (np.einsum("ij,ij->i", normal[tri], direction[ok]) > 0) & (twin[tri] < 0)
    return out


def conservation_error(engine: FormFactorEngine, mesh: RadiosityMesh) -> np.ndarray:
    """Relative radiosity error from rows of closed receivers not summing to 1.

    ``(1 / A) sum_j a_j |1 - sum_p F_jp| rho_j / (1 - rho_m)`` over the closed receivers,
    ``rho_m`` the area-weighted mean reflectance (a lost fraction delta of what a receiver
    gathers is lost again at every bounce).

    Returns
    -------
    (3,) float64 [1]
    """
    closed = engine.closed_rows
    if closed is None or not closed.any():
        return np.zeros(3)
    deficit = np.abs(1.0 - engine.row_sums())
    a = mesh.receiver_area * closed
    total = float(mesh.receiver_area.sum())
    rho = mesh.receiver_reflectance
    mean_rho = (mesh.receiver_area @ rho) / max(total, 1e-300)
    lost = (a * deficit) @ rho / max(total, 1e-300)
    return np.asarray(lost / np.maximum(1.0 - mean_rho, 1e-12))


def total_error_column(bound_rms: list[list[float]], parts: ErrorParts) -> list[list[float]]:
    """The ``total_rms`` column of an error log: at each log point but the last, its
    algebraic bound plus the final total; at the last, the final total."""
    total = parts.total
    rows = [(np.asarray(row, dtype=np.float64) + total).tolist() for row in bound_rms[:-1]]
    return [*rows, total.tolist()] if bound_rms else []


__all__ = [
    "RAYS",
    "SAMPLES",
    "ErrorParts",
    "Residual",
    "conservation_error",
    "discretisation_error",
    "total_error_column",
]
