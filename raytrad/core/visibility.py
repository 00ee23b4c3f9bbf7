"""Visibility between points: the one adapter module that imports embreex.

Embree works in float32. Coordinates are shifted so the scene's bounding-box centre is the
origin before conversion, so a model placed kilometres from the origin keeps the same
precision as one at the origin; every query point goes through the same shift.
"""

from __future__ import annotations

import importlib.util
import itertools
import logging
import math
import os
import threading
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Executor, ThreadPoolExecutor
from typing import Any, TypeVar

import numpy as np

from raytrad.arrays import unique
from raytrad.constants import scene_diagonal, tol
from raytrad.core import compiled, embree
from raytrad.core.kernels import visibility_rays

log = logging.getLogger(__name__)

#: Rays handed to Embree in one call; one chunk's arrays stay a few megabytes.
RAY_CHUNK = 1 << 16

_MISS, _FRONT, _BACK, _COVER = 0, 1, 2, 3  # _COVER: a back face nearer than COVER_GAP

#: A surface point more than :data:`COVER_SHARE` of whose probe rays end on the back of a
#: single-sided surface nearer than this fraction of the scene's diagonal is covered: a
#: lamp set just below the ceiling (0.05% in the Cornell box), a thin rug on a floor, a
#: poster on a wall. It is hidden like a point shut in under a block
#: (:meth:`Occluder.probe_hemispheres`): no one sees it but at grazing angles, and linear
#: interpolation toward its dark value would draw a dark rim round the cover on the
#: visible surface beside it. Kept small: a hidden point is shown with its visible
#: neighbours' radiosity, so the floor under a table, which a camera can look into, must
#: not be hidden.
COVER_GAP = 2e-3
#: The share of probe rays that makes a point covered. A receiver right on the cover's
#: outline scores about 0.45, one 0.16 mm outside the Cornell lamp's edge about the same
#: and one 0.5 mm outside about 0.2, 1 mm outside 0.06 (cosine-weighted rays under a
#: lamp 0.5 mm down, inside COVER_GAP; its own darkness reaches no farther); at 0.4, 64 rays
#: left a third of those on the outline visible and dark, and the triangles from them drew
#: a rim 2 mm wide. The floor beside a block sees the block's front, not its back: 0.
COVER_SHARE = 0.2


#: Environment variable capping the threads of one render (``raytrad bake`` sets it in
#: each job's process so that jobs running side by side share the cores).
THREADS_VARIABLE = "RAYTRAD_THREADS"

_T = TypeVar("_T")
_R = TypeVar("_R")


def worker_count() -> int:
    """Threads for ray batches and the form-factor pass: every core the process may use,
    or fewer when :data:`THREADS_VARIABLE` holds a whole number >= 1."""
    try:
        cores = max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        cores = max(1, os.cpu_count() or 1)
    text = os.environ.get(THREADS_VARIABLE, "").strip()
    if text.isascii() and text.isdigit() and int(text) >= 1:
        return min(cores, int(text))
    return cores


def ordered_map(
    pool: Executor, work: Callable[[_T], _R], items: Iterable[_T], ahead: int
) -> Iterator[_R]:
    """``work(item)`` for each item on ``pool``, yielded in order, with at most ``ahead``
    items submitted beyond the one yielded (``Executor.map`` submits them all, so results
    pile up in memory while the caller is busy). Closing the iterator cancels the items
    not started.

    Parameters
    ----------
    pool : concurrent.futures.Executor
    work : callable
    items : iterable
    ahead : int, >= 1
    """
    todo = iter(items)
    pending = deque(pool.submit(work, item) for item in itertools.islice(todo, max(1, ahead)))
    try:
        while pending:
            result = pending.popleft().result()
            pending.extend(pool.submit(work, item) for item in itertools.islice(todo, 1))
            yield result
    finally:
        for future in pending:
            future.cancel()


class Occluder:
    """Segment occlusion queries against a triangle mesh.

    Parameters
    ----------
    positions : (V, 3) float64
        Vertex positions [m].
    triangles : (T, 3) int
        Triangles that can block light.
    robust : bool
        Embree's robust traversal mode (slower; watertight edges).

    Notes
    -----
    Rays go through Embree's 8-ray packets (:mod:`raytrad.core.embree`, about twice as
    fast on coherent rays) where the library embreex ships is found, else through
    embreex's ``EmbreeScene.run``; both answer the same queries with the same answers.
    Either releases the GIL, so batches run on all cores from a thread pool; each call
    gets at most :data:`RAY_CHUNK` rays, so memory stays bounded.
    """

    def __init__(self, positions: np.ndarray, triangles: np.ndarray, robust: bool = False):
        positions = np.asarray(positions, dtype=np.float64)
        #: The blocking geometry, world coordinates (for shaft culling).
        self.positions, self.triangles = positions, np.asarray(triangles)
        used = unique(triangles)
        lo, hi = positions[used].min(axis=0), positions[used].max(axis=0)
        self.origin = 0.5 * (lo + hi)
        self.diagonal = scene_diagonal(np.stack([lo, hi]))
        local = np.ascontiguousarray(positions - self.origin, dtype=np.float32)
        self._packets = _packet_scene(local, self.triangles, robust)
        if self._packets is None:
            self._scene = _embreex_scene(local, self.triangles, robust)
        self._workers = worker_count()
        self._pool: ThreadPoolExecutor | None = None
        self._lock = threading.Lock()
        self.rays_cast = 0

    @property
    def packets(self) -> bool:
        """Whether rays go through Embree's packets (:mod:`raytrad.core.embree`), not
        embreex's single-ray queries."""
        return self._packets is not None

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None

    def __enter__(self) -> Occluder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def to_local(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) float64 world points [m] to the float32-friendly local frame [m]."""
        return np.asarray(points, dtype=np.float64) - self.origin

    def occluded_local(
        self, origins: np.ndarray, directions: np.ndarray, distances: np.ndarray
    ) -> np.ndarray:
        """Occlusion of rays already in the local frame.

        Parameters
        ----------
        origins : (N, 3) float
            Ray origins in the local frame [m].
        directions : (N, 3) float
            Unit directions.
        distances : (N,) float
            Segment lengths [m]; hits beyond them do not count.

        Returns
        -------
        (N,) bool, True where something blocks the open segment.
        """
        n = len(origins)
        with self._lock:
            self.rays_cast += n
        if n == 0:
            return np.zeros(0, dtype=bool)
        o = np.ascontiguousarray(origins, dtype=np.float32)
        d = np.ascontiguousarray(directions, dtype=np.float32)
        t = np.ascontiguousarray(distances, dtype=np.float32)
        if n <= RAY_CHUNK or self._workers == 1:
            return self._run(o, d, t)
        bounds = [*list(range(0, n, RAY_CHUNK)), n]
        parts = self._threads().map(
            lambda ab: self._run(o[ab[0] : ab[1]], d[ab[0] : ab[1]], t[ab[0] : ab[1]]),
            itertools.pairwise(bounds),
        )
        return np.concatenate(list(parts))

    def occluded_samples(
        self,
        origins: np.ndarray,
        far: np.ndarray,
        doubt: np.ndarray,
        targets: np.ndarray,
        near_receivers: np.ndarray,
        near_targets: np.ndarray,
        shorten: float,
    ) -> tuple[np.ndarray, np.ndarray, int]:
        """A chunk's visibility rays, made and traced in Embree's packets without being
        written out (only when :attr:`packets`; :func:`~raytrad.core.kernels.visibility_rays`
        and :meth:`occluded_local` answer the same otherwise).

        Parameters
        ----------
        origins : (C, 3) float64
            World ray origins of the chunk's receivers [m].
        far : (C, S) bool
            (receiver, sample) pairs to trace, of the receivers in ``doubt`` (C,) bool.
        targets : (S, 3) float64
            The samples' ray targets [m].
        near_receivers : (B,) int64
            Chunk receiver of each near item; traced when it is in ``doubt``.
        near_targets : (B, 3) float64
            Its target [m].
        shorten : float
            Each ray stops this short of its target [m].

        Returns
        -------
        far_hidden : (C, S) bool
            Blocked far samples.
        near_hidden : (B,) bool
            Blocked near items.
        rays : int
        """
        if self._packets is None:
            raise RuntimeError("occluded_samples needs Embree's packets (Occluder.packets)")
        far_hidden = np.zeros(far.shape, dtype=bool)
        near_hidden = np.zeros(len(near_receivers), dtype=bool)
        rays = _loops().traced_samples(
            self._packets.pointer,
            origins,
            far,
            doubt,
            targets,
            near_receivers,
            near_targets,
            self.origin,
            shorten,
            far_hidden,
            near_hidden,
        )
        with self._lock:
            self.rays_cast += rays
        return far_hidden, near_hidden, int(rays)

    def sample_rays(
        self,
        origins: np.ndarray,
        far: np.ndarray,
        doubt: np.ndarray,
        targets: np.ndarray,
        near_receivers: np.ndarray,
        near_targets: np.ndarray,
        shorten: float,
    ) -> tuple[np.ndarray, ...]:
        """The rays :meth:`occluded_samples` traces (arguments as there), written out in
        this occluder's local frame by :func:`~raytrad.core.kernels.visibility_rays`: the
        far pairs of the receivers in doubt, then the near items whose receiver is;
        returns its (origin, direction, reach, far_c, far_s)."""
        traced = doubt[near_receivers]
        return visibility_rays(
            origins,
            far & doubt[:, None],
            targets,
            near_receivers[traced],
            np.compress(traced, near_targets, axis=0),
            self.origin,
            shorten,
        )

    def _threads(self) -> ThreadPoolExecutor:
        """The pool the batches run on (made on first use; never called from its own
        threads, whose batches would wait for each other)."""
        with self._lock:
            if self._pool is None:
                self._pool = ThreadPoolExecutor(self._workers, thread_name_prefix="raytrad-rays")
            return self._pool

    def _run(self, o: np.ndarray, d: np.ndarray, t: np.ndarray) -> np.ndarray:
        out = np.empty(len(o), dtype=bool)
        if self._packets is not None:
            _loops().occluded_packets(self._packets.pointer, o, d, t, out)
            return out
        for start in range(0, len(o), RAY_CHUNK):
            stop = start + RAY_CHUNK
            hit = self._scene.run(
                o[start:stop], d[start:stop], dists=t[start:stop].copy(), query="OCCLUDED"
            )
            out[start:stop] = np.asarray(hit) != -1
        return out

    def intersect_local(
        self, origins: np.ndarray, directions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Closest hits of rays in the local frame.

        Parameters
        ----------
        origins : (N, 3) float
            Ray origins in the local frame [m].
        directions : (N, 3) float
            Unit directions.

        Returns
        -------
        triangle : (N,) int64, index of the triangle hit, -1 for a miss
        distance : (N,) float64, distance to the hit [m] (inf for a miss)
        """
        o = np.ascontiguousarray(origins, dtype=np.float32)
        d = np.ascontiguousarray(directions, dtype=np.float32)
        with self._lock:
            self.rays_cast += len(o)
        triangle, distance, _ = self._intersect(o, d, barycentric=False)
        return triangle, distance

    def intersect_barycentric_local(
        self, origins: np.ndarray, directions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Closest hits with the hit point's barycentric coordinates.

        Returns
        -------
        triangle : (N,) int64, -1 for a miss
        distance : (N,) float64 [m], inf for a miss
        barycentric : (N, 3) float64, weights of the triangle's corners 0, 1, 2
        """
        o = np.ascontiguousarray(origins, dtype=np.float32)
        d = np.ascontiguousarray(directions, dtype=np.float32)
        return self._intersect(o, d, barycentric=True)

    def _intersect(
        self, o: np.ndarray, d: np.ndarray, barycentric: bool
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Closest hits of float32 rays, in batches of :data:`RAY_CHUNK`; the barycentric
        weights only when asked for ((0, 3) otherwise: a probe needs none)."""
        triangle = np.empty(len(o), dtype=np.int64)
        distance = np.empty(len(o))
        if self._packets is not None:
            u, v = np.empty(len(o)), np.empty(len(o))
            _loops().intersect_packets(self._packets.pointer, o, d, triangle, distance, u, v)
            weights = np.stack([1.0 - u - v, u, v], axis=1) if barycentric else np.zeros((0, 3))
            return triangle, distance, weights
        weights = np.zeros((len(o) if barycentric else 0, 3))
        for start in range(0, len(o), RAY_CHUNK):
            stop = start + RAY_CHUNK
            hit = self._scene.run(o[start:stop], d[start:stop], query="INTERSECT", output=True)
            triangle[start:stop] = hit["primID"]
            distance[start:stop] = np.where(hit["primID"] >= 0, hit["tfar"], np.inf)
            if barycentric:
                u, v = np.asarray(hit["u"], np.float64), np.asarray(hit["v"], np.float64)
                weights[start:stop] = np.stack([1.0 - u - v, u, v], axis=1)
        return triangle, distance, weights

    def enclosed(
        self,
        points: np.ndarray,
        normals: np.ndarray,
        triangle_normals: np.ndarray,
        double_sided: np.ndarray,
        rays: int = 16,
    ) -> np.ndarray:
        """Which surface points are shut in: every ray from them hits a back face.

        A floor point under a closed block sees only the block's inside (the backs of its
        single-sided faces) in every direction: it can neither receive nor send light.

        Parameters
        ----------
        points : (N, 3) float64
            World points [m] on surfaces.
        normals : (N, 3) float64
            Their unit normals.
        triangle_normals : (T, 3) float64
            Unit normals of this occluder's triangles.
        double_sided : (T,) bool
            Triangles that have no back.
        rays : int
            Directions tried per point (a fixed stratified cosine set).

        Returns
        -------
        (N,) bool
        """
        hits = self._hemisphere_hits(points, normals, triangle_normals, double_sided, rays)
        return np.asarray((hits >= _BACK).all(axis=1))

    def probe_hemispheres(
        self,
        points: np.ndarray,
        normals: np.ndarray,
        triangle_normals: np.ndarray,
        double_sided: np.ndarray,
        rays: int = 64,
    ) -> tuple[np.ndarray, np.ndarray]:
        """(closed, enclosed), both (N,) bool, from one set of probe rays.

        ``closed``: every ray hits the front of a surface, so the point sees no opening and
        no light-swallowing back face and its form factors must sum to 1
        (``FormFactorEngine.balance``); ``enclosed``: every ray hits a back face
        (:meth:`enclosed`), or more than :data:`COVER_SHARE` hit a back face within
        :data:`COVER_GAP` (the point is covered). Parameters as :meth:`enclosed`.
        """
        hits = self._hemisphere_hits(points, normals, triangle_normals, double_sided, rays)
        covered = (hits == _COVER).mean(axis=1) > COVER_SHARE
        return (hits == _FRONT).all(axis=1), (hits >= _BACK).all(axis=1) | covered

    def _hemisphere_hits(
        self,
        points: np.ndarray,
        normals: np.ndarray,
        triangle_normals: np.ndarray,
        double_sided: np.ndarray,
        rays: int,
    ) -> np.ndarray:
        """(N, rays) int8: _MISS, _FRONT, _BACK or _COVER for a fixed cosine set of
        directions, in blocks of points whose rays fill about :data:`RAY_CHUNK` on every
        core (each ray's code is its own: the same codes however the threads run)."""
        directions = _fibonacci_hemisphere(rays)  # (K, 3) about +z
        origin = self.to_local(points) + tol.ray_margin * self.diagonal * normals
        tangent, bitangent = _frames(normals)
        out = np.empty((len(points), rays), dtype=np.int8)

        def probe(block: slice) -> None:
            d = (
                directions[None, :, 0, None] * tangent[block, None, :]
                + directions[None, :, 1, None] * bitangent[block, None, :]
                + directions[None, :, 2, None] * normals[block, None, :]
            ).reshape(-1, 3)
            o = np.repeat(origin[block], rays, axis=0)
            hit, distance = self.intersect_local(o, d)
            ok = hit >= 0
            back = np.zeros(len(hit), dtype=bool)
            # a grazing hit (the ray along the surface) counts as its front
            grazing = tol.parallel
            back[ok] = (np.einsum("ij,ij->i", triangle_normals[hit[ok]], d[ok]) > grazing) & (
                ~double_sided[hit[ok]]
            )
            cover = back & (distance < COVER_GAP * self.diagonal)
            code = np.where(~ok, _MISS, np.where(cover, _COVER, np.where(back, _BACK, _FRONT)))
            out[block] = code.reshape(-1, rays)

        per = max(1, RAY_CHUNK // rays)
        blocks = [slice(a, a + per) for a in range(0, len(points), per)]
        if self._workers == 1 or len(blocks) < 2:
            for block in blocks:
                probe(block)
        else:
            list(self._threads().map(probe, blocks))
        return out

    def occluded(
        self, starts: np.ndarray, ends: np.ndarray, end_normals: np.ndarray | None = None
    ) -> np.ndarray:
        """(N,) bool: is the open segment between world points ``starts`` and ``ends`` blocked?

        Parameters
        ----------
        starts, ends : (N, 3) float64
            Segment end points [m].
        end_normals : (N, 3) float64 or None
            Unit normals of the surfaces the segments end on, on the side they arrive from.
            Give them whenever ``ends`` lie on a surface: each end is then lifted off it by
            ``tol.ray_offset`` of the scene diagonal, so a grazing segment is not blocked by
            the very surface it ends on (float32 cannot resolve a margin taken along the
            segment).

        Only the interior of the segment counts: a margin of ``tol.ray_margin`` of the
        scene diagonal is left free at the end.
        """
        ends = np.asarray(ends, dtype=np.float64)
        if end_normals is not None:
            lift = tol.ray_offset * self.diagonal
            ends = ends + lift * np.asarray(end_normals, dtype=np.float64)
        a = self.to_local(starts)
        delta = self.to_local(ends) - a
        length = np.linalg.norm(delta, axis=1)
        direction = delta / np.maximum(length, 1e-300)[:, None]
        margin = tol.ray_margin * self.diagonal
        return self.occluded_local(a, direction, np.maximum(length - margin, 0.0))


def _packet_scene(
    local: np.ndarray, triangles: np.ndarray, robust: bool
) -> embree.PacketScene | None:
    """An Embree scene for packet queries (:mod:`raytrad.core.embree`), or None where
    they cannot be had: numba's kernels off or missing, the library not found,
    ``RAYTRAD_RAYS=embreex``, or Embree refusing the scene (logged; embreex then answers
    the same queries). The compiled loops load on the first query
    (:func:`raytrad.core.compiled.rays`)."""
    if not compiled.wanted() or importlib.util.find_spec("numba") is None:
        return None
    if not embree.available():
        return None
    try:
        return embree.PacketScene(local, triangles, robust)
    except OSError as error:
        log.warning("Embree's packets failed (%s): rays go through embreex", error)
        return None


def _loops() -> Any:
    """The compiled packet loops (an occluder with packets exists only where they can
    be had)."""
    loops = compiled.rays()
    if loops is None or not hasattr(loops, "traced_samples"):  # pragma: no cover
        raise RuntimeError("Embree's packet loops are missing (raytrad.core._compiled_rays)")
    return loops


def _embreex_scene(local: np.ndarray, triangles: np.ndarray, robust: bool) -> Any:
    """embreex's scene of the triangles, its BVH built now (the first query commits it),
    so that timings are honest."""
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    scene = rtcore_scene.EmbreeScene(robust=robust)
    TriangleMesh(scene, local, np.ascontiguousarray(triangles, dtype=np.int32))
    scene.run(
        np.zeros((1, 3), np.float32),
        np.full((1, 3), 3.0**-0.5, np.float32),
        dists=np.zeros(1, np.float32),
        query="OCCLUDED",
    )
    return scene


def nothing_can_occlude(positions: np.ndarray, triangles: np.ndarray, tolerance: float) -> bool:
    """True when no segment between two scene points can cross a triangle.

    That holds when every vertex lies on or in front of every triangle's plane: the scene is
    the inside of a convex shell (a furnace box, a sphere seen from inside). Such a scene
    needs no visibility rays at all.

    Parameters
    ----------
    positions : (V, 3) float64 [m]
    triangles : (T, 3) int
    tolerance : float
        Distance behind a plane still counted as on it [m].
    """
    points = positions[unique(triangles)]
    if len(points) * len(triangles) > 50_000_000:
        return False  # too big to prove convex cheaply; rays decide instead
    corners = positions[triangles]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    length = np.linalg.norm(normal, axis=1)
    ok = length > 0
    normal = normal[ok] / length[ok, None]
    offset = np.einsum("ij,ij->i", normal, corners[ok, 0])
    for start in range(0, len(normal), 256):
        sl = slice(start, start + 256)
        signed = points @ normal[sl].T - offset[sl][None, :]
        if (signed < -tolerance).any():
            return False
    return True


def _fibonacci_hemisphere(count: int) -> np.ndarray:
    """(count, 3) unit directions spread evenly over the +z hemisphere, cosine-weighted."""
    i = np.arange(count) + 0.5
    radius = np.sqrt(i / count)
    angle = i * math.pi * (3.0 - math.sqrt(5.0))
    return np.stack(
        [radius * np.cos(angle), radius * np.sin(angle), np.sqrt(1.0 - radius**2)], axis=1
    )


def _frames(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents completing each (N, 3) unit normal to an orthonormal frame."""
    helper = np.where(np.abs(normals[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    tangent = np.cross(normals, helper)
    tangent /= np.linalg.norm(tangent, axis=1)[:, None]
    return tangent, np.cross(normals, tangent)
