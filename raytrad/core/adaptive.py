"""Adaptive refinement: more receivers where the light changes fast across an element.

After the solve, every refined triangle whose corners' radiosity differs by more than the
threshold (relative to its own level, with a floor at a fraction of the scene's mean so
that noise in the dark does not count) is split, conformingly: the longest-edge closure of
:func:`raytrad.core.refine.refine` splits neighbours as needed, so no T-junction appears.
The new receivers get their radiosity by a final gather over the solve's shooting patches
(:meth:`~raytrad.core.formfactor.FormFactorEngine.gather_rows`: their own visibility rays,
the patches' converged radiosity, the near field as it varies across a patch). Shadow
boundaries, contact lines and the surroundings of lamps are refined; flat regions are not.
From the second round on, a triangle is also split when a corner the last round added
gathered far from the interpolation it replaced (:data:`FOUND_SHARE`): the interpolation
was found wrong there even where the corners agree (the bright edge of a penumbra).
Rounds repeat until no element exceeds the threshold or the receiver budget is spent.

The patches, their sub-areas and the solved system stay as they are; the existing
receivers keep their index and their radiosity. What a new receiver's gathered value
differs from the interpolation it replaces measures the discretisation error there
(``change_rms`` in the returned :class:`Refinement`).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from raytrad.arrays import corner_max, corner_mean, corner_min, longest_side
from raytrad.constants import tol
from raytrad.core.columns import return_freed_memory
from raytrad.core.formfactor import ROW_FIX_LIMIT, FormFactorEngine
from raytrad.core.gather import gathered_irradiance
from raytrad.core.mesh import MAX_RECEIVERS, RadiosityMesh, surface_receivers
from raytrad.core.pairs import receiver_points
from raytrad.core.refine import refine
from raytrad.core.visibility import Occluder
from raytrad.errors import SettingsError
from raytrad.scene import Scene, barycentric_coordinates, triangle_areas_normals

log = logging.getLogger(__name__)

#: Final-gather passes over the new receivers of a round: the first reads its new
#: neighbours' interpolated radiosity, the next what they gathered (same factors).
GATHER_PASSES = 2

#: A triangle is also split when a corner the last round added gathered a luminance that
#: differs from the interpolation it replaced by more than this share of the threshold
#: (relative to its level, floored as the spread is): the interpolation was found wrong
#: there, though the corners may spread little (the bright edge of a penumbra, where the
#: light bends), and the error of linear interpolation falls about fourfold with each
#: halving of the triangle. On ``tools/bench_penumbra.py`` at 10 000 receivers, 0.1 left
#: the penumbra's bright edge 0.3 % off (uniform refinement: 0.17 %); 0.03 with
#: :func:`_to_split`'s ranking halves the penumbra's error against uniform refinement.
FOUND_SHARE = 0.03

#: Luminance weights of linear Rec. 709 RGB, to compare radiosity across channels.
_LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


@dataclass(frozen=True)
class RefineSettings:
    """When and how far to refine.

    Attributes
    ----------
    threshold : float
        Split a triangle whose corners' luminance spreads by more than this fraction of
        its mean (the mean floored at ``floor`` x the scene's mean) [1]; 0 disables.
    max_receivers : int or None
        Receiver budget of the refined mesh; None: twice the receivers before refinement.
    rounds : int
        Most refinement rounds.
    smallest : float
        Triangles whose longest edge is below this fraction of the scene's diagonal are
        not split [1].
    floor : float
        See ``threshold`` [1].
    """

    threshold: float = 0.1
    max_receivers: int | None = None
    rounds: int = 6
    smallest: float = 2e-3
    floor: float = 0.05

    def __post_init__(self) -> None:
        if not (self.threshold >= 0 and np.isfinite(self.threshold)):
            raise SettingsError(f"refine threshold must be >= 0, got {self.threshold}")
        if self.max_receivers is not None and not 1 <= self.max_receivers <= MAX_RECEIVERS:
            raise SettingsError(
                f"max receivers must be 1 to {MAX_RECEIVERS:,}, got {self.max_receivers}"
            )
        if self.rounds < 0:
            raise SettingsError(f"refinement rounds must be >= 0, got {self.rounds}")


@dataclass
class Refinement:
    """What adaptive refinement did.

    Attributes
    ----------
    mesh : RadiosityMesh
        The refined mesh (the input mesh when nothing was refined).
    radiosity : (R', 3) float64 [W m-2]
        Radiosity of its receivers: the solve's for the old ones, gathered for the new.
    added : int
        Receivers added.
    rounds : int
        Rounds that added receivers and gathered them.
    interpolated : int
        Of ``added``, the receivers of a round cut short before its gather finished: they
        keep the interpolation of the mesh before it (0 unless ``stopped``).
    by_object : dict of str to int
        Receivers added per scene object.
    change_rms : (3,) float64
        Relative RMS (area-weighted) of what the new receivers' gathered radiosity
        changed against the interpolation it replaced [1]: the discretisation error the
        refinement found.
    rays, rays_naive : int
        Visibility rays the new receivers' gathers cast, and the rays an unclassified
        caster would have cast (see
        :attr:`~raytrad.core.formfactor.FormFactorEngine.rays_naive`).
    stopped : bool
        The time limit or an interrupt stopped it before its last round: the mesh is
        coarser than an uninterrupted run's.
    resumable : Refinement or None
        When ``stopped``: the refinement as its last complete round left it, which
        :func:`refine_adaptively` goes on from (``start``) to the uninterrupted result.
    found, changes
        What a round carries to the next (each receiver's last gather against its
        interpolation, see :data:`FOUND_SHARE`; each round's changes and the new
        receivers' areas, for ``change_rms``).
    settings : RefineSettings or None
        The settings the rounds were made with (a resume goes on only under the same).
    """

    mesh: RadiosityMesh
    radiosity: np.ndarray
    added: int = 0
    rounds: int = 0
    interpolated: int = 0
    by_object: dict[str, int] = field(default_factory=dict)
    change_rms: np.ndarray = field(default_factory=lambda: np.zeros(3))
    rays: int = 0
    rays_naive: int = 0
    stopped: bool = False
    resumable: Refinement | None = field(default=None, repr=False)
    found: np.ndarray | None = field(default=None, repr=False)
    changes: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list, repr=False)
    settings: RefineSettings | None = field(default=None, repr=False)


def goes_on_from(start: Refinement, settings: RefineSettings) -> bool:
    """Whether :func:`refine_adaptively` under ``settings`` goes on from the rounds of
    ``start`` (an earlier refinement's ``resumable`` part): they were made with the same
    settings; otherwise it starts again."""
    return start.settings == settings


def refine_adaptively(
    scene: Scene,
    mesh: RadiosityMesh,
    engine: FormFactorEngine,
    occluder: Occluder | None,
    radiosity: np.ndarray,
    settings: RefineSettings,
    stop: Callable[[], bool] | None = None,
    start: Refinement | None = None,
) -> Refinement:
    """Refine ``mesh`` where ``radiosity`` changes fast and gather the new receivers.

    Parameters
    ----------
    scene : Scene
        The (repaired) scene ``mesh`` was built from.
    mesh : RadiosityMesh
    engine : FormFactorEngine
        The balanced engine of the solve (its patches shoot to the new receivers).
    occluder : Occluder or None
        The scene's visibility structure (None: nothing occludes).
    radiosity : (R, 3) float64
        The solution at ``mesh``'s receivers [W m-2].
    settings : RefineSettings
    stop : callable or None
        Polled before each round and after each patch of a round's gather (a time budget
        spent, Ctrl-C): True ends refinement there (a round cut short keeps its receivers
        at the interpolation of the mesh before it; ``resumable`` the rounds before).
    start : Refinement or None
        The ``resumable`` part of an earlier refinement of the same solve (``mesh`` and
        ``radiosity``), to go on from: its rounds are not made again, and the result is
        the uninterrupted refinement's.
    """
    budget = settings.max_receivers or 2 * mesh.receiver_count
    out = Refinement(mesh, np.asarray(radiosity, dtype=np.float64), settings=settings)
    if start is not None and goes_on_from(start, settings):
        out = replace(start, stopped=False, interpolated=0, resumable=None)
    elif start is not None:
        log.warning("the refinement rounds kept were made with other settings: starting again")
    if settings.threshold <= 0:
        return out
    if budget <= mesh.receiver_count:
        log.warning(
            "no refinement: the receiver budget (--max-receivers %d) is not above the %d "
            "receivers solved",
            budget,
            mesh.receiver_count,
        )
        return out
    patch_radiosity = patch_means(mesh, radiosity)
    smallest = settings.smallest * engine.diagonal
    changes = list(out.changes)
    # see FOUND_SHARE: nothing found before round 1
    found = np.zeros(mesh.receiver_count) if out.found is None else out.found
    sides: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # see longest_sides
    for _ in range(settings.rounds - out.rounds):
        done = replace(out, found=found, changes=list(changes))  # what a resume goes on from
        if stop is not None and stop():
            out.stopped = True
            out.resumable = done
            if out.rounds:
                log.warning(
                    "refinement stopped after %d round%s (%s): the mesh is coarser than an "
                    "uninterrupted run's",
                    out.rounds,
                    "" if out.rounds == 1 else "s",
                    stop_cause(stop),
                )
            else:
                log.warning("refinement skipped: %s", stop_cause(stop))
            break
        room = budget - out.mesh.receiver_count
        longest = longest_sides(out.mesh, sides)
        order = _to_split(out.mesh, out.radiosity, settings, smallest, room, found, longest)
        refined, parent = out.mesh, np.zeros(0, dtype=np.int64)
        while len(order):  # the closure splits neighbours too: never beyond the budget
            split = np.zeros(len(out.mesh.triangles), dtype=bool)
            split[order] = True
            refined, parent = subdivide(out.mesh, split, longest)
            if refined.receiver_count <= budget:
                break
            order = order[: len(order) // 2]
        if not len(order):
            break
        new = np.arange(out.mesh.receiver_count, refined.receiver_count)
        if len(new) == 0:
            break
        level = _level(out.mesh, out.radiosity)
        before = _interpolated(out.mesh, out.radiosity, refined, parent, new)
        # the near field is gathered from the refined mesh: a receiver close to a sharp
        # edge (a shadow at a block's corner) sees it as sharp as the mesh has it now
        current = np.concatenate([out.radiosity, before])
        coarse = (out.mesh.triangles, longest, parent)
        out.mesh = refined  # the coarser mesh goes before the refined tables are built
        near = engine.refined(refined)
        try:
            refined, gathered = _gather(
                scene, refined, near, occluder, current, patch_radiosity, new, stop
            )
        finally:
            near.close()
        out.rays += near.rays_cast
        out.rays_naive += near.rays_naive
        del near  # its tables, the size of the mesh's, go before the next round's are built
        return_freed_memory()
        if gathered is None:  # stopped within the round: the last mesh's look, kept
            _keep_interpolated(out, refined, before, new, stop_cause(stop))
            out.resumable = done
            break
        changes.append((before - gathered, refined.receiver_area[new]))
        found = np.concatenate([found, _found(level, before, gathered, settings)])
        found[new[refined.receiver_area[new] == 0]] = 0.0  # hidden: nothing to interpolate
        out.radiosity = np.concatenate([out.radiosity, gathered])
        sides = coarse
        out.mesh = refined
        out.added += len(new)
        out.rounds += 1
    if out.added:
        owner = scene.object_index[out.mesh.triangle_source]
        first = np.full(out.mesh.receiver_count, -1)
        first[out.mesh.triangle_receivers.reshape(-1)] = np.repeat(owner, 3)
        added = first[mesh.receiver_count :]
        counts = np.bincount(added[added >= 0], minlength=len(scene.object_names))
        out.by_object = {n: int(c) for n, c in zip(scene.object_names, counts, strict=True) if c}
        out.change_rms = _change_rms(changes, out.mesh, out.radiosity)
        cut = f" and one cut short ({out.interpolated} of them interpolated)"
        log.info(
            "refinement: %d receivers added in %d round%s%s (%s)",
            out.added,
            out.rounds,
            "" if out.rounds == 1 else "s",
            cut if out.interpolated else "",
            ", ".join(f"{n} {c}" for n, c in out.by_object.items()),
        )
    return out


def longest_sides(
    mesh: RadiosityMesh, before: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
) -> np.ndarray:
    """(T,) each triangle's longest side [m] (:func:`~raytrad.arrays.longest_side`).
    ``before``: the triangles of the mesh ``mesh`` was subdivided from (:func:`subdivide`;
    its positions are ``mesh``'s first ones), their longest sides and each triangle's
    parent among them; a triangle that kept its parent's corners keeps its side, to the
    bit, and only the others are measured."""
    if before is None or len(before[2]) != len(mesh.triangles):
        return longest_side(mesh.positions[mesh.triangles])
    old_triangles, old_longest, parent = before
    kept = (mesh.triangles == old_triangles[parent]).all(axis=1)
    longest = old_longest[parent]
    changed = np.flatnonzero(~kept)
    longest[changed] = longest_side(mesh.positions[mesh.triangles[changed]])
    return longest


def stop_cause(stop: Callable[[], bool] | None) -> str:
    """What a True ``stop`` poll meant, in words: its ``cause()`` where it has one (a run's
    :class:`~raytrad.core.pipeline.RunBudget` knows whether its time was spent or Ctrl-C
    asked), else either."""
    cause = getattr(stop, "cause", None)
    return str(cause()) if callable(cause) else "time limit spent or interrupted"


def _keep_interpolated(
    out: Refinement, refined: RadiosityMesh, before: np.ndarray, new: np.ndarray, cause: str
) -> None:
    """A round stopped before its gather finished: its new receivers keep the
    interpolation of the mesh before it (``before``, their emission where hidden), which
    shows exactly what that mesh shows, and refinement ends there (``out.stopped``)."""
    hidden = ~np.asarray(refined.receiver_visible, dtype=bool)[new]
    before = before.copy()
    before[hidden] = refined.receiver_emitted_exitance[new[hidden]]
    out.radiosity = np.concatenate([out.radiosity, before])
    out.mesh = refined
    out.added += len(new)
    out.interpolated = len(new)
    out.stopped = True
    log.warning(
        "refinement stopped in round %d (%s): its %d new receivers show the interpolation "
        "of the round before",
        out.rounds + 1,
        cause,
        len(new),
    )


def _to_split(
    mesh: RadiosityMesh,
    radiosity: np.ndarray,
    settings: RefineSettings,
    smallest: float,
    room: int,
    found: np.ndarray | None = None,
    longest: np.ndarray | None = None,
) -> np.ndarray:
    """The triangles to split this round, about ``room`` receivers' worth: those whose
    corners spread by more than the threshold, or with a corner whose last gather
    ``found`` ((R,) relative luminance change, see :data:`FOUND_SHARE`) the interpolation
    wrong. When the budget does not reach them all, the triangles straddling a contact
    line come first, then the others by area x relative spread x absolute spread (in
    units of the scene's mean luminance): between ranking by the relative error (each
    surface's mean counts, however dark) and by the absolute one (the bake's
    area-weighted RMS). ``longest``: (T,) each triangle's longest side [m]
    (:func:`~raytrad.arrays.longest_side`, computed when not given)."""
    luminance = radiosity @ _LUMINANCE
    visible = mesh.receiver_area > 0
    if room <= 0 or not visible.any():
        return np.zeros(0, dtype=np.int64)
    level = _level(mesh, radiosity)
    if not level > 0.0:  # nothing lit (no emitter): nothing changes fast
        return np.zeros(0, dtype=np.int64)
    corner = luminance[mesh.triangle_receivers]
    corner_seen = visible[mesh.triangle_receivers]
    mean = corner_mean(corner)
    spread = (corner_max(corner) - corner_min(corner)) / np.maximum(mean, settings.floor * level)
    # a triangle with hidden and visible corners straddles a contact line (a block's
    # base on the floor): what it shows there is a guess, so it is always refined
    straddles = corner_seen.any(axis=1) & ~corner_seen.all(axis=1)
    spread = np.where(straddles, np.inf, np.where(corner_seen.all(axis=1), spread, 0.0))
    if found is not None and len(found) == len(luminance):
        wrong = found[mesh.triangle_receivers].max(axis=1) / FOUND_SHARE
        spread = np.maximum(spread, np.where(corner_seen.all(axis=1), wrong, 0.0))
    if longest is None:
        longest = longest_side(mesh.positions[mesh.triangles])
    candidate = (spread > settings.threshold) & (longest > smallest)
    # worst first by area x relative spread x absolute spread (in units of the scene's
    # mean luminance): a triangle at a tenth of the mean needs about three times the
    # relative spread of one at the mean to come first
    scale = np.maximum(mean, settings.floor * level) / level
    key = np.where(np.isinf(spread), np.inf, spread**2 * scale * mesh.triangle_area)
    order = np.argsort(-np.where(candidate, key, -np.inf), kind="stable")
    # each split adds about one receiver per triangle (a midpoint shared by two)
    return order[: min(int(candidate.sum()), max(1, room // 2))]


def _level(mesh: RadiosityMesh, radiosity: np.ndarray) -> float:
    """The scene's area-weighted mean luminance over visible receivers [W m-2]."""
    visible = mesh.receiver_area > 0
    if not visible.any():
        return 0.0
    luminance = radiosity @ _LUMINANCE
    return float(np.average(luminance[visible], weights=mesh.receiver_area[visible]))


def _found(
    level: float, before: np.ndarray, gathered: np.ndarray, settings: RefineSettings
) -> np.ndarray:
    """(N,) how far new receivers' gathered luminance is from the interpolation ``before``
    it replaced, relative to their own, floored at ``settings.floor`` times ``level``
    (:func:`_level` of the mesh before the round) [1]."""
    got = gathered @ _LUMINANCE
    floor = max(settings.floor * level, 1e-300)
    return np.asarray(np.abs(got - before @ _LUMINANCE) / np.maximum(got, floor))


def subdivide(
    mesh: RadiosityMesh, split: np.ndarray, longest: np.ndarray | None = None
) -> tuple[RadiosityMesh, np.ndarray]:
    """The mesh with the ``split`` ((T,) bool) triangles bisected, conformingly
    (``longest``: (T,) each triangle's longest side [m], computed when not given).

    Receivers keep their index (new ones are appended); patches and sub-areas are
    unchanged, new triangles inherit their parent's patch, sub-area, source triangle and
    surface. Receivers of the new vertices are not yet gathered or probed: their
    ``receiver_visible`` is True.

    Returns
    -------
    mesh : RadiosityMesh
    parent : (T',) int64, the input triangle each new triangle lies in
    """
    if mesh.triangle_surface is None:
        raise ValueError("adaptive refinement needs the mesh's triangle surfaces")
    if longest is None:
        longest = longest_side(mesh.positions[mesh.triangles])
    limit = np.where(split, 0.75 * longest, np.inf)
    positions, triangles, parent = refine(
        mesh.positions, mesh.triangles, limit, max_rounds=1, quiet=True
    )
    surface = mesh.triangle_surface[parent]
    area, normal = triangle_areas_normals(positions[triangles])
    receivers, r_pos, r_normal, r_area, r_inward = surface_receivers(
        positions, triangles, surface, area, normal
    )
    old = mesh.receiver_count
    if not np.array_equal(r_pos[:old], mesh.receiver_position):
        raise RuntimeError("refinement renumbered existing receivers")
    # a new receiver's material is that of the old receivers of its triangle's surface
    material_of = np.empty(len(r_pos), dtype=np.int64)
    material_of[receivers.reshape(-1)] = np.repeat(mesh.triangle_receivers[parent][:, 0], 3)
    visible = np.ones(len(r_pos), dtype=bool)
    if mesh.receiver_visible is not None:
        visible[:old] = mesh.receiver_visible
    refined = replace(
        mesh,
        receiver_position=r_pos,
        receiver_normal=r_normal,
        receiver_area=r_area * visible,
        receiver_inward=r_inward,
        receiver_reflectance=mesh.receiver_reflectance[material_of],
        receiver_emitted_exitance=mesh.receiver_emitted_exitance[material_of],
        triangle_receivers=receivers,
        triangle_area=area,
        triangle_normal=normal,
        triangle_patch=mesh.triangle_patch[parent],
        triangle_subarea=mesh.triangle_subarea[parent],
        triangle_source=mesh.triangle_source[parent],
        triangle_surface=surface,
        positions=positions,
        triangles=triangles,
        receiver_visible=visible,
    )
    return refined, parent


def final_gather(
    scene: Scene,
    engine: FormFactorEngine,
    occluder: Occluder | None,
    radiosity: np.ndarray,
    patch_radiosity: np.ndarray,
    points: np.ndarray,
    normals: np.ndarray,
    reflectance: np.ndarray,
    emitted_exitance: np.ndarray,
    own: np.ndarray | None = None,
    stop: Callable[[], bool] | None = None,
) -> tuple[np.ndarray | None, np.ndarray]:
    """Radiosity at surface points gathered from a solution, and which points are hidden.

    ``B(x) = E + rho sum_p F(x <- p) (B̄_p + [B̃_xp - B̄_p])``
    (:meth:`~raytrad.core.formfactor.FormFactorEngine.gather_rows`); a point that sees
    surfaces all round (probe rays) has its factors summed to 1 as balancing does; a
    point shut in (under a block) keeps its emission, and so does a point of zero
    reflectance: neither gets a factor or a ray.

    Parameters
    ----------
    scene : Scene
        The repaired scene (for the probe rays' hit sides).
    engine : FormFactorEngine
        On the mesh whose ``radiosity`` is given (:meth:`FormFactorEngine.refined`).
    occluder : Occluder or None
    radiosity : (R, 3) float64 [W m-2]
    patch_radiosity : (P, 3) float64 [W m-2]
    points, normals : (N, 3) float64
        Evaluation points [m] (off edges, see
        :func:`~raytrad.core.pairs.receiver_points`) and unit normals.
    reflectance, emitted_exitance : (N, 3) float64
        Of the surfaces the points lie on [1], [W m-2].
    own : (N,) int or None
        When the points are receivers of the mesh (new ones, whose ``radiosity`` is a
        first guess): their indices. They see each other, so the gather is repeated
        :data:`GATHER_PASSES` times, each reading what the last one gathered (from the
        same factors, traced once).
    stop : callable or None
        Polled after each patch's rows (a time budget spent, Ctrl-C): True abandons the
        gather.

    Returns
    -------
    radiosity : (N, 3) float64 [W m-2], or None when ``stop`` abandoned the gather
    hidden : (N,) bool
    """
    hidden = np.zeros(len(points), dtype=bool)
    closed = np.zeros(len(points), dtype=bool)
    if occluder is not None:
        _, scene_normals = triangle_areas_normals(scene.triangle_vertices())
        closed, hidden = occluder.probe_hemispheres(
            points, normals, scene_normals, scene.double_sided
        )
    # a point on a black surface, or shut in, shows its emission whatever reaches it: no
    # rows, no rays
    lit = np.flatnonzero(np.asarray(reflectance).any(axis=1) & ~hidden)
    rows = engine.gather_rows(points[lit], normals[lit], stop)
    if rows is None:
        return None, hidden
    scale = np.ones(len(lit))
    if occluder is not None:
        # rows judged before the column scales, as balancing judges the receivers' rows
        fix = closed[lit] & (np.abs(rows.raw_sum - 1.0) < ROW_FIX_LIMIT) & (rows.row_sum > 0)
        scale = np.where(fix, rows.row_sum, 1.0)
    radiosity = np.array(radiosity, dtype=np.float64)
    result = np.array(emitted_exitance, dtype=np.float64)
    for _ in range(1 if own is None else GATHER_PASSES):
        irradiance = gathered_irradiance(rows, radiosity, patch_radiosity) / scale[:, None]
        result[lit] = emitted_exitance[lit] + reflectance[lit] * irradiance
        result[hidden] = emitted_exitance[hidden]
        if own is not None:
            radiosity[own] = result
    return result, hidden


def _gather(
    scene: Scene,
    mesh: RadiosityMesh,
    engine: FormFactorEngine,
    occluder: Occluder | None,
    radiosity: np.ndarray,
    patch_radiosity: np.ndarray,
    new: np.ndarray,
    stop: Callable[[], bool] | None = None,
) -> tuple[RadiosityMesh, np.ndarray | None]:
    """The new receivers' radiosity by a final gather (None: ``stop`` abandoned it);
    hidden ones marked in the mesh."""
    points, _ = receiver_points(mesh, tol.ray_offset * engine.diagonal)
    gathered, hidden = final_gather(
        scene,
        engine,
        occluder,
        radiosity,
        patch_radiosity,
        points[new],
        mesh.receiver_normal[new],
        mesh.receiver_reflectance[new],
        mesh.receiver_emitted_exitance[new],
        own=new,
        stop=stop,
    )
    visible = np.array(mesh.receiver_visible, dtype=bool)
    visible[new] = ~hidden
    mesh = replace(mesh, receiver_visible=visible, receiver_area=mesh.receiver_area * visible)
    return mesh, gathered


def patch_means(mesh: RadiosityMesh, radiosity: np.ndarray) -> np.ndarray:
    """(P, 3) area-weighted mean radiosity of each patch's visible receivers (``W B``)."""
    corner = mesh.triangle_receivers.reshape(-1)
    weight = np.repeat(mesh.triangle_area / 3.0, 3) * (mesh.receiver_area[corner] > 0)
    patch = np.repeat(mesh.triangle_patch, 3)
    total = np.bincount(patch, weights=weight, minlength=mesh.patch_count)
    out = np.stack(
        [
            np.bincount(patch, weights=weight * radiosity[corner, c], minlength=mesh.patch_count)
            for c in range(3)
        ],
        axis=1,
    )
    return out / np.maximum(total, 1e-300)[:, None]


def _interpolated(
    mesh: RadiosityMesh,
    radiosity: np.ndarray,
    refined: RadiosityMesh,
    parent: np.ndarray,
    new: np.ndarray,
) -> np.ndarray:
    """(N, 3) radiosity the old mesh showed at the new receivers (linear interpolation
    within the parent triangle)."""
    owner = np.full(refined.receiver_count, -1)
    owner[refined.triangle_receivers.reshape(-1)] = np.repeat(parent, 3)
    tri = owner[new]
    corners = mesh.positions[mesh.triangles[tri]]
    weights = barycentric_coordinates(refined.receiver_position[new], corners)
    values = radiosity[mesh.triangle_receivers[tri]]
    return np.asarray(np.einsum("nk,nkc->nc", weights, values))


def _change_rms(
    changes: list[tuple[np.ndarray, np.ndarray]], mesh: RadiosityMesh, radiosity: np.ndarray
) -> np.ndarray:
    """(3,) area-weighted RMS of the changes over all receivers, relative to the RMS
    radiosity (a change on a few receivers is a small error of the whole)."""
    area = mesh.receiver_area
    norm = np.sqrt(area @ radiosity**2)
    total = sum((a @ d**2 for d, a in changes), np.zeros(3))
    return np.asarray(np.sqrt(total) / np.where(norm > 0, norm, 1.0))
