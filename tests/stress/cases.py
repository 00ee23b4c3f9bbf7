"""The stress cases: each a scene, an independent expected value and how to measure the error.

Shared by the tests in this directory and by ``tools/stress_table.py`` (which prints the
table in docs/stability.md). A case knows nothing about raytrad's internals: its expected
value comes from physics (white furnace, power balance, symmetry, continuity), from a
direct dense solve of the same discrete system (open scenes), or from the same scene at
another scale.

Every solve here has a shot cap and a time limit, so a regression cannot hang the suite.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from raytrad.core import pipeline
from raytrad.core.formfactor import Column
from raytrad.core.mesh import MeshSettings
from raytrad.core.pipeline import Prepared
from raytrad.core.reference import dense_solve
from raytrad.core.solver import SolveResult, SolveSettings, solve
from raytrad.errors import RaytradError
from raytrad.scene import Scene, make_scene, triangle_areas_normals
from raytrad.scene.builder import SceneBuilder, box_faces, rectangle
from raytrad.scene.builtin import cornell_box, furnace_box

#: Shot cap of every ambient solve in the suite (the slowest case needs about 17 000).
MAX_SHOTS = 60_000
#: Wall-clock cap of every solve in the suite [s].
TIME_LIMIT = 60.0
#: Default stopping tolerance: unshot power / emitted power. The radiosity error it leaves
#: is of the same order, far below the 1% the tests ask for.
TOLERANCE = 1e-4

#: Small meshes: a furnace box at about 1700 receivers and 100 patches.
BOX_MESH = MeshSettings(receivers=1500, patches=100)
#: Boxes with something inside, and open rooms.
ROOM_MESH = MeshSettings(receivers=2000, patches=150)

Measure = Callable[["Run"], float]


@dataclass
class Run:
    """One solve of one case: what the measure functions look at."""

    case: StressCase
    prepared: Prepared
    result: SolveResult
    setup_seconds: float

    @property
    def mesh(self) -> Any:
        return self.prepared.mesh


@dataclass(frozen=True)
class StressCase:
    """A stress scene with an independent expected value.

    Attributes
    ----------
    name : str
        Short identifier (also the pytest id).
    group : int
        The numbered group of the issue (1-7; 8 for the divergence guard).
    title : str
        What the scene is, for the table.
    expected : str
        The expected value, in words and numbers, for the table.
    build : callable
        ``build() -> Scene``.
    measure : callable
        ``measure(run) -> float``: the largest relative error against the expected value.
    mesh : MeshSettings
    tolerance : float
        Solver stopping tolerance.
    rtol : float
        Largest error accepted by the tests.
    wrap_engine : callable or None
        ``wrap_engine(engine) -> engine`` to solve with altered form factors.
    """

    name: str
    group: int
    title: str
    expected: str
    build: Callable[[], Scene]
    measure: Measure
    mesh: MeshSettings = BOX_MESH
    tolerance: float = TOLERANCE
    rtol: float = 0.01
    wrap_engine: Callable[[Any], Any] | None = None


# --------------------------------------------------------------------------------------
# Running
# --------------------------------------------------------------------------------------


def prepare(case: StressCase) -> tuple[Prepared, float]:
    """Mesh and balance the case's scene; returns the Prepared and the seconds it took."""
    start = time.perf_counter()
    prepared = pipeline.prepare(case.build(), case.mesh)
    return prepared, time.perf_counter() - start


def solve_prepared(
    case: StressCase,
    prepared: Prepared,
    method: str = "ambient",
    max_shots: int = MAX_SHOTS,
    time_limit: float = TIME_LIMIT,
) -> SolveResult:
    engine = prepared.engine if case.wrap_engine is None else case.wrap_engine(prepared.engine)
    settings = SolveSettings(
        method=method, tolerance=case.tolerance, max_shots=max_shots, time_limit=time_limit
    )
    return solve(prepared.mesh, engine, settings)


def run_case(case: StressCase, method: str = "ambient", **limits: Any) -> Run:
    """Prepare and solve ``case`` with ``method`` (the Prepared is closed afterwards)."""
    prepared, setup = prepare(case)
    try:
        result = solve_prepared(case, prepared, method, **limits)
    finally:
        prepared.close()
    return Run(case, prepared, result, setup)


# --------------------------------------------------------------------------------------
# Measures
# --------------------------------------------------------------------------------------


def furnace_error(rho: float, emitted: float) -> Measure:
    """Largest relative deviation from B = E / (1 - rho) over all receivers."""
    expected = emitted / (1.0 - rho)

    def measure(run: Run) -> float:
        return float(np.abs(run.result.radiosity / expected - 1.0).max())

    return measure


def power_error(expected_power: float) -> Measure:
    """Relative deviation of sum_j a_j B_j from ``expected_power`` [W], worst channel."""

    def measure(run: Run) -> float:
        power = run.mesh.receiver_area @ run.result.radiosity
        return float(np.abs(power / expected_power - 1.0).max())

    return measure


def dense_error(run: Run) -> float:
    """Largest per-receiver relative deviation from a dense direct solve of the same system.

    Receivers darker than 1e-6 of the brightest are left out (a relative error of nothing).
    """
    reference = dense_solve(run.mesh, run.prepared.engine)
    lit = reference > 1e-6 * reference.max()
    return float((np.abs(run.result.radiosity - reference)[lit] / reference[lit]).max())


def ledger_error(result: SolveResult) -> float:
    """|emitted - absorbed - escaped - unshot| / emitted, worst channel."""
    state = result.state
    balance = result.emitted_power - state.absorbed - state.escaped - result.unshot_power
    return float((np.abs(balance) / result.emitted_power).max())


def combined(*measures: Measure) -> Measure:
    def measure(run: Run) -> float:
        return max(m(run) for m in measures)

    return measure


# --------------------------------------------------------------------------------------
# Group 1: closed boxes of high reflectance
# --------------------------------------------------------------------------------------

HIGH_RHO = (0.9, 0.99, 0.999)


def furnace_case(rho: float) -> StressCase:
    return StressCase(
        name=f"furnace-{rho}",
        group=1,
        title=f"closed cube, rho = {rho} everywhere, E = 1 everywhere",
        expected=f"B = E/(1-rho) = {1 / (1 - rho):.4g} at every receiver",
        build=lambda: furnace_box(rho, 1.0),
        measure=furnace_error(rho, 1.0),
    )


def lamp_box(rho: float, lamp: str = "y+", emitted: float = 1.0) -> Scene:
    """The unit cube, rho everywhere, the face ``lamp`` (1 m2) emitting ``emitted``."""
    b = SceneBuilder()
    b.material("wall", rho)
    b.material("lamp", rho, emitted)
    b.room("wall", face_material={lamp: "lamp"})
    return b.build()


def one_lamp_case(rho: float) -> StressCase:
    return StressCase(
        name=f"one-lamp-{rho}",
        group=1,
        title=f"closed cube, rho = {rho}, only the ceiling emits (E = 1, 1 m2)",
        expected=f"sum a B = A E/(1-rho) = {1 / (1 - rho):.4g} W",
        build=lambda: lamp_box(rho),
        measure=power_error(1.0 / (1.0 - rho)),
    )


def block_room(rho: float, standing: bool) -> Scene:
    """The lamp box with a 0.3 x 0.3 x 0.4 m block inside: floating, or standing on the floor.

    A standing block has no bottom face (it sits on the floor); a floating one is closed.
    """
    b = SceneBuilder()
    b.material("wall", rho)
    b.material("lamp", rho, 1.0)
    b.room("wall", face_material={"y+": "lamp"})
    if standing:
        b.block("wall", (0.3, 0.0, 0.3), (0.6, 0.5, 0.7))
    else:
        b.block("wall", (0.3, 0.2, 0.3), (0.6, 0.5, 0.7), bottom=True)
    return b.build()


def block_case(rho: float, standing: bool) -> StressCase:
    where = "standing on the floor" if standing else "floating"
    return StressCase(
        name=f"block-{'standing' if standing else 'floating'}-{rho}",
        group=1,
        title=f"closed cube with a block {where} (non-convex), rho = {rho}, ceiling emits",
        expected=f"sum a B = A E/(1-rho) = {1 / (1 - rho):.4g} W",
        build=lambda: block_room(rho, standing),
        measure=power_error(1.0 / (1.0 - rho)),
        mesh=ROOM_MESH,
    )


# --------------------------------------------------------------------------------------
# Group 2: reflectance exactly 1
# --------------------------------------------------------------------------------------


def lossless_open_scene() -> Scene:
    """A white floor (rho = 1) under a square lamp (rho = 1): light escapes to the sky."""
    b = SceneBuilder()
    b.material("floor", 1.0)
    b.material("lamp", 1.0, 10.0)
    b.quad(rectangle(1, 0.0, (0, 0), (1, 1)), "floor", (0, 1, 0))
    b.quad(rectangle(1, 1.0, (0.4, 0.4), (0.6, 0.6)), "lamp", (0, -1, 0))
    return b.build()


# --------------------------------------------------------------------------------------
# Group 3: open rooms of reflectance 0.99
# --------------------------------------------------------------------------------------

OPEN_RHO = 0.99
LAMP_CUTS = (0.0, 0.4, 0.6, 1.0)
"""Ceiling grid: the 0.2 x 0.2 m centre cell is the lamp (conforming with the ceiling)."""


def open_room(rho: float, opening: str) -> Scene:
    """A 1 m room of reflectance ``rho`` lit by a ceiling lamp, with an opening.

    ``opening``: ``front`` (the whole z = 1 wall missing), or ``window-<w>``: a w x w hole in
    the middle of the z = 1 wall (the wall a conforming 3 x 3 grid less its centre).
    """
    b = SceneBuilder()
    b.material("wall", rho)
    b.material("lamp", rho, 10.0)
    b.room("wall", skip=("y+", "z+"))
    b.grid_wall(1, 1.0, LAMP_CUTS, LAMP_CUTS, "wall", (0, -1, 0), {(1, 1): "lamp"})
    if opening.startswith("window-"):
        w = float(opening.removeprefix("window-"))
        cuts = (0.0, 0.5 - w / 2, 0.5 + w / 2, 1.0)
        b.grid_wall(2, 1.0, cuts, cuts, "wall", (0, 0, -1), {(1, 1): None})
    return b.build()


def open_case(opening: str) -> StressCase:
    what = "no front wall" if opening == "front" else opening.replace("-", " ") + " m hole"
    return StressCase(
        name=f"open-{opening}",
        group=3,
        title=f"open room, rho = {OPEN_RHO} everywhere, ceiling lamp, {what}",
        expected="dense direct solve of the same system; energy ledger closes",
        build=lambda: open_room(OPEN_RHO, opening),
        measure=combined(dense_error, lambda run: ledger_error(run.result)),
        mesh=ROOM_MESH,
    )


# --------------------------------------------------------------------------------------
# Group 4: scale and translation
# --------------------------------------------------------------------------------------

CORNELL_EDGE = 0.05
"""Longest refined edge of the Cornell box in metres [m] (about 2000 receivers)."""
CORNELL_PATCH = 0.14
"""Largest patch of the Cornell box in metres [m] (about 120 patches)."""

SCALES: dict[str, tuple[float, float]] = {
    "m": (1.0, 0.0),
    "mm": (1e-3, 0.0),
    "km": (1e3, 0.0),
    "far": (1.0, 1e5),
}
"""Variant -> (scale factor, translation [m]) applied to the Cornell box in metres."""


def scaled_cornell(variant: str) -> Scene:
    factor, shift = SCALES[variant]
    scene = cornell_box().scaled(factor)
    return dataclasses.replace(scene, positions=scene.positions + shift)


def cornell_mesh(factor: float) -> MeshSettings:
    return MeshSettings(max_edge=CORNELL_EDGE * factor, patch_size=CORNELL_PATCH * factor)


def to_metres(variant: str) -> Callable[[np.ndarray], np.ndarray]:
    factor, shift = SCALES[variant]
    return lambda points: (np.asarray(points) - shift) / factor


def surface_means(
    mesh: Any, scene: Scene, radiosity: np.ndarray, metres: Callable[[np.ndarray], np.ndarray]
) -> np.ndarray:
    """(16, 3) area-weighted mean radiosity of each quad of :func:`cornell_box`.

    Each refined triangle is assigned to the quad of the metre-scale box whose triangle's
    plane holds it (same facing, centroid within 1e-6 m of the plane and inside the
    triangle's bounding box; some Cornell quads are not planar), so the result does not
    depend on triangle order, scale or placement.
    """
    reference = cornell_box()
    corners = reference.positions[reference.triangles]  # (32, 3, 3): quad q = triangles 2q, 2q+1
    _, normal = triangle_areas_normals(corners)
    offset = np.einsum("ti,ti->t", normal, corners[:, 0])
    lo, hi = corners.min(axis=1) - 1e-6, corners.max(axis=1) + 1e-6
    centroid = metres(mesh.positions[mesh.triangles].mean(axis=1))
    on_plane = np.abs(centroid @ normal.T - offset[None, :]) < 1e-6
    facing = mesh.triangle_normal @ normal.T > 0.99
    inside = ((centroid[:, None, :] >= lo[None]) & (centroid[:, None, :] <= hi[None])).all(axis=2)
    match = on_plane & facing & inside
    quads = 16
    quad_match = match.reshape(len(match), quads, 2).any(axis=2)
    if not (quad_match.sum(axis=1) == 1).all():
        raise AssertionError("a refined triangle matches no Cornell quad, or several")
    quad = np.argmax(quad_match, axis=1)
    triangle_b = radiosity[mesh.triangle_receivers].mean(axis=1)  # (T, 3)
    weight = mesh.triangle_area
    total = np.bincount(quad, weights=weight, minlength=quads)
    means = np.stack(
        [np.bincount(quad, weights=weight * triangle_b[:, c], minlength=quads) for c in range(3)],
        axis=1,
    )
    return means / total[:, None]


@functools.lru_cache(maxsize=1)
def cornell_metre_reference() -> tuple[np.ndarray, np.ndarray]:
    """Receiver radiosity and per-quad means of the Cornell box in metres (ambient, 1e-5)."""
    prepared = pipeline.prepare(scaled_cornell("m"), cornell_mesh(1.0))
    try:
        result = solve(
            prepared.mesh,
            prepared.engine,
            SolveSettings(tolerance=1e-5, max_shots=MAX_SHOTS, time_limit=TIME_LIMIT),
        )
    finally:
        prepared.close()
    means = surface_means(prepared.mesh, prepared.scene, result.radiosity, to_metres("m"))
    return result.radiosity, means


def scale_error(variant: str) -> Measure:
    def measure(run: Run) -> float:
        _, reference = cornell_metre_reference()
        mesh, radiosity = run.mesh, run.result.radiosity
        means = surface_means(mesh, run.prepared.scene, radiosity, to_metres(variant))
        return float(np.abs(means / reference - 1.0).max())

    return measure


def scale_case(variant: str) -> StressCase:
    factor, _ = SCALES[variant]
    what = {
        "mm": "scaled to millimetres (0.55 mm box)",
        "km": "scaled to kilometres (550 m box)",
        "far": "translated by 1e5 m",
    }[variant]
    return StressCase(
        name=f"scale-{variant}",
        group=4,
        title=f"Cornell box {what}",
        expected="the metre version: area-weighted mean B of each of the 16 quads",
        build=lambda: scaled_cornell(variant),
        measure=scale_error(variant),
        mesh=cornell_mesh(factor),
        tolerance=1e-5,
    )


# --------------------------------------------------------------------------------------
# Group 5: emitters
# --------------------------------------------------------------------------------------

HALL = 10.0
"""Edge of the hall that holds the tiny bulb [m]."""
BULB_SIDE = 1e-3
"""Side of the square bulb [m]: 1e-6 m2."""
BULB_EXITANCE = 1e9
"""Emitted exitance of the bulb [W m-2]: 1000 W in all."""


def bulb_hall(rho: float = 0.9) -> Scene:
    """A 10 m cube of reflectance rho with a 1 mm2 bulb 1 mm below the ceiling, facing down."""
    b = SceneBuilder()
    b.material("wall", rho)
    b.material("bulb", rho, BULB_EXITANCE)
    b.room("wall", size=(HALL, HALL, HALL))
    h, c = BULB_SIDE / 2, HALL / 2
    b.quad(rectangle(1, HALL - 1e-3, (c - h, c - h), (c + h, c + h)), "bulb", (0, -1, 0))
    return b.build()


LED_COUNT = 10
"""Lights per axis of the 10 x 10 x 10 lattice of small emitters."""
LED_EXITANCE = 100.0
"""Emitted exitance of each small emitter [W m-2]."""
LED_AREA = 2e-4
"""Area of each small emitter (a triangle of base 2 cm and height 2 cm) [m2]."""


def many_emitters(rho: float = 0.9) -> Scene:
    """The unit cube with 1000 small double-sided emitting triangles on a lattice inside."""
    b = SceneBuilder()
    b.material("wall", rho)
    b.material("led", rho, LED_EXITANCE, True)
    b.room("wall")
    steps = 0.1 + 0.8 * np.arange(LED_COUNT) / (LED_COUNT - 1)
    for x in steps:
        for y in steps:
            for z in steps:
                c = np.array([x, y, z])
                tri = c + np.array([(-0.01, 0, -0.01), (0.01, 0, -0.01), (0, 0, 0.01)])
                b.triangle(tri, "led", (0, -1, 0))
    return b.build()


REFLECTING_LAMP = 10.0
"""Emitted exitance of the 0.2 x 0.2 m lamp cell that also reflects [W m-2]."""


def reflecting_lamp_room(rho: float = 0.9) -> Scene:
    """Closed cube of reflectance rho; the 0.04 m2 centre cell of the ceiling grid emits."""
    b = SceneBuilder()
    b.material("wall", rho)
    b.material("lamp", rho, REFLECTING_LAMP)
    b.room("wall", skip=("y+",))
    b.grid_wall(1, 1.0, LAMP_CUTS, LAMP_CUTS, "wall", (0, -1, 0), {(1, 1): "lamp"})
    return b.build()


def lamp_continuity_error(run: Run) -> float:
    """Where lamp and ceiling meet, both sample the same irradiance: B_lamp - E = B_ceiling.

    Compares the receiver pairs (lamp side, ceiling side) at each vertex of the lamp's rim.
    """
    mesh, radiosity = run.mesh, run.result.radiosity
    lamp = (mesh.receiver_emitted_exitance > 0).any(axis=1)
    ceiling = ~lamp & (np.abs(mesh.receiver_position[:, 1] - 1.0) < 1e-9)
    lamp_idx, ceiling_idx = np.nonzero(lamp)[0], np.nonzero(ceiling)[0]
    distance = np.linalg.norm(
        mesh.receiver_position[lamp_idx][:, None] - mesh.receiver_position[ceiling_idx][None],
        axis=2,
    )
    pair_lamp, pair_ceiling = np.nonzero(distance < 1e-9)
    if len(pair_lamp) < 8:
        raise AssertionError("the lamp's rim has too few shared vertices")
    reflected = radiosity[lamp_idx[pair_lamp]] - REFLECTING_LAMP
    neighbour = radiosity[ceiling_idx[pair_ceiling]]
    return float(np.abs(reflected / neighbour - 1.0).max())


PANEL_EXITANCE = 5.0
"""Emitted exitance of each side of the double-sided panel [W m-2]."""
PANEL_SIDE = 0.4
"""Side of the square double-sided panel [m]."""


def double_sided_panel_room(rho: float = 0.9) -> Scene:
    """Closed cube with a 0.4 m square double-sided emitting panel at mid-height."""
    b = SceneBuilder()
    b.material("wall", rho)
    b.material("panel", rho, PANEL_EXITANCE, True)
    b.room("wall")
    lo, hi = 0.5 - PANEL_SIDE / 2, 0.5 + PANEL_SIDE / 2
    b.quad(rectangle(1, 0.5, (lo, lo), (hi, hi)), "panel")
    return b.build()


def panel_sides_error(run: Run) -> float:
    """Relative difference of the mean radiosity of the panel's two sides (mirror symmetry)."""
    mesh, radiosity = run.mesh, run.result.radiosity
    panel = (mesh.receiver_emitted_exitance > 0).any(axis=1)
    up = panel & (mesh.receiver_normal[:, 1] > 0.5)
    down = panel & (mesh.receiver_normal[:, 1] < -0.5)
    a = mesh.receiver_area
    mean_up = a[up] @ radiosity[up] / a[up].sum()
    mean_down = a[down] @ radiosity[down] / a[down].sum()
    return float(np.abs(mean_up / mean_down - 1.0).max())


# --------------------------------------------------------------------------------------
# Group 6: CAD defects, in the white furnace (rho = 0.9, E = 1) and with one lamp
# --------------------------------------------------------------------------------------

DEFECT_RHO = 0.9

WallBuilder = Callable[[SceneBuilder, np.ndarray, np.ndarray, str], None]
"""``wall(builder, corners, outward, material)`` adds one face of the box its own way."""


def defect_box(
    walls: dict[str, WallBuilder] | None = None,
    extra: Callable[[SceneBuilder], None] | None = None,
    lamp: bool = False,
    rho: float = DEFECT_RHO,
) -> Scene:
    """The unit cube: a furnace (all faces emit 1) or, with ``lamp``, only the ceiling emits.

    ``walls`` maps face names (``x-``, ``x+``, ``y-``, ``y+``, ``z-``, ``z+``) to builders
    that replace the plain inward-facing quad; ``extra`` adds more geometry (material
    ``fin``: double-sided, emitting like the walls).
    """
    walls = walls or {}
    b = SceneBuilder()
    wall_emission = 0.0 if lamp else 1.0
    b.material("wall", rho, wall_emission)
    b.material("lamp", rho, 1.0)
    b.material("fin", rho, wall_emission, True)
    for name, corners, outward in box_faces((0, 0, 0), (1, 1, 1)):
        material = "lamp" if lamp and name == "y+" else "wall"
        if name in walls:
            walls[name](b, corners, outward, material)
        else:
            b.quad(corners, material, -outward)
    if extra is not None:
        extra(b)
    return b.build()


def _plane_of(corners: np.ndarray) -> tuple[int, float]:
    axis = int(np.argmin(np.ptp(corners, axis=0)))
    return axis, float(corners[0, axis])


def sliver_wall(b: SceneBuilder, corners: np.ndarray, outward: np.ndarray, m: str) -> None:
    """The wall in three strips, the middle one 1e-6 m wide: triangles of aspect ratio 1e6."""
    axis, level = _plane_of(corners)
    for lo, hi in (((0, 0), (1, 0.5)), ((0, 0.5), (1, 0.5 + 1e-6)), ((0, 0.5 + 1e-6), (1, 1))):
        b.quad(rectangle(axis, level, lo, hi), m, -outward)


def duplicated_wall(b: SceneBuilder, corners: np.ndarray, outward: np.ndarray, m: str) -> None:
    """The same quad twice (identical triangles): coincident coplanar faces."""
    b.quad(corners, m, -outward)
    b.quad(corners, m, -outward)


def retriangulated_duplicate(
    b: SceneBuilder, corners: np.ndarray, outward: np.ndarray, m: str
) -> None:
    """The quad twice, the copy split along the other diagonal (coincident, not identical)."""
    b.quad(corners, m, -outward)
    b.quad(corners[[1, 2, 3, 0]], m, -outward)


def t_junction_wall(b: SceneBuilder, corners: np.ndarray, outward: np.ndarray, m: str) -> None:
    """Left half one quad, right half two: the right quads' shared corner is a T-vertex."""
    axis, level = _plane_of(corners)
    b.quad(rectangle(axis, level, (0, 0), (0.5, 1)), m, -outward)
    b.quad(rectangle(axis, level, (0.5, 0), (1, 0.5)), m, -outward)
    b.quad(rectangle(axis, level, (0.5, 0.5), (1, 1)), m, -outward)


def inverted_wall(b: SceneBuilder, corners: np.ndarray, outward: np.ndarray, m: str) -> None:
    """The wall wound the wrong way: front facing out of the box, back facing in."""
    b.quad(corners, m, outward)


def inverted_t_junction_wall(
    b: SceneBuilder, corners: np.ndarray, outward: np.ndarray, m: str
) -> None:
    """:func:`t_junction_wall`, inside out: two of its quads share no whole edge with the box."""
    axis, level = _plane_of(corners)
    b.quad(rectangle(axis, level, (0, 0), (0.5, 1)), m, outward)
    b.quad(rectangle(axis, level, (0.5, 0), (1, 0.5)), m, outward)
    b.quad(rectangle(axis, level, (0.5, 0.5), (1, 1)), m, outward)


def diagonal_partition(b: SceneBuilder) -> None:
    """A double-sided wall on the box's diagonal plane y = z: two non-manifold edges.

    Its edges are the floor/back-wall edge and the ceiling/front-wall edge, each then shared
    by three faces; the side walls' own 0-2 diagonals run along its ends (conforming).
    """
    b.quad([(0, 0, 0), (1, 0, 0), (1, 1, 1), (0, 1, 1)], "fin")


def corner_fin(b: SceneBuilder) -> None:
    """A double-sided fin 0.3 m up the diagonal plane y = z from the floor/back-wall edge.

    Its bottom edge is that edge (three faces share it: non-manifold); its ends lie along
    the side walls' diagonals, its top corners in the middle of those diagonals.
    """
    b.quad([(0, 0, 0), (1, 0, 0), (1, 0.3, 0.3), (0, 0.3, 0.3)], "fin")


def with_degenerate_faces(scene: Scene) -> Scene:
    """``scene`` plus zero-area triangles (repeated and collinear corners) and a stray vertex.

    The stray vertex, unused by any face, sits 1e6 m away as CAD exports leave them.
    """
    n = len(scene.positions)
    extra_points = np.array(
        [[0.5, 0.5, 0.5], [0.7, 0.7, 0.7], [0.2, 0.2, 0.2], [0.4, 0.4, 0.4], [0.6, 0.6, 0.6]]
    )
    stray = np.array([[1e6, 1e6, 1e6]])
    degenerate = np.array(
        [[0, 0, 1], [n, n + 1, n], [0, 1, 0], [n, n, n], [n + 2, n + 3, n + 4]]  # last: collinear
    )
    triangles = np.concatenate([scene.triangles, degenerate])
    material = np.concatenate([scene.material_index, np.zeros(len(degenerate), dtype=np.int64)])
    return make_scene(
        np.concatenate([scene.positions, extra_points, stray]),
        triangles,
        material,
        scene.material_names,
        scene.material_reflectance,
        scene.material_emitted_exitance,
        scene.material_double_sided,
    )


def with_duplicate_vertices(scene: Scene, copies: int = 3, seed: int = 0) -> Scene:
    """``scene`` with every vertex stored ``copies`` times, faces picking copies at random."""
    rng = np.random.default_rng(seed)
    triangles = scene.triangles * copies + rng.integers(0, copies, size=scene.triangles.shape)
    return make_scene(
        np.repeat(scene.positions, copies, axis=0),
        triangles,
        scene.material_index,
        scene.material_names,
        scene.material_reflectance,
        scene.material_emitted_exitance,
        scene.material_double_sided,
    )


def defect_cases(name: str, title: str, build: Callable[[bool], Scene]) -> list[StressCase]:
    """The furnace and the one-lamp version of a defect (``build(lamp) -> Scene``)."""
    rho = DEFECT_RHO
    return [
        StressCase(
            name=f"{name}-furnace",
            group=6,
            title=f"{title}; furnace, rho = {rho}, E = 1",
            expected=f"B = E/(1-rho) = {1 / (1 - rho):.4g} at every receiver",
            build=lambda: build(False),
            measure=furnace_error(rho, 1.0),
        ),
        StressCase(
            name=f"{name}-lamp",
            group=6,
            title=f"{title}; rho = {rho}, ceiling emits E = 1",
            expected=f"sum a B = A E/(1-rho) = {1 / (1 - rho):.4g} W",
            build=lambda: build(True),
            measure=power_error(1.0 / (1.0 - rho)),
        ),
    ]


# --------------------------------------------------------------------------------------
# Group 7: no light anywhere
# --------------------------------------------------------------------------------------


def dark_room() -> Scene:
    b = SceneBuilder()
    b.material("wall", 0.9)
    b.room("wall")
    return b.build()


AWAY_EXITANCE = 10.0


def lamp_facing_away() -> Scene:
    """A floor (rho 0.8) and, 0.5 m above it, a lamp (rho 0.5) facing up into the empty sky."""
    b = SceneBuilder()
    b.material("floor", 0.8)
    b.material("lamp", 0.5, AWAY_EXITANCE)
    b.quad(rectangle(1, 0.0, (0, 0), (1, 1)), "floor", (0, 1, 0))
    b.quad(rectangle(1, 0.5, (0.3, 0.3), (0.7, 0.7)), "lamp", (0, 1, 0))
    return b.build()


def dark_error(run: Run) -> float:
    """Largest radiosity (expected exactly 0), in W m-2 (there is no scale to divide by)."""
    return float(np.abs(run.result.radiosity).max())


def away_error(run: Run) -> float:
    """max(non-emitter B / E, |escaped / emitted - 1|): nothing is lit, everything escapes."""
    mesh, result = run.mesh, run.result
    others = ~(mesh.receiver_emitted_exitance > 0).any(axis=1)
    lit = float(np.abs(result.radiosity[others]).max()) / AWAY_EXITANCE
    escaped = float(np.abs(result.state.escaped / result.emitted_power - 1.0).max())
    return max(lit, escaped)


# --------------------------------------------------------------------------------------
# Divergence: form factors that are off by a known factor
# --------------------------------------------------------------------------------------


class ScaledEngine:
    """A form-factor engine whose every factor is multiplied by ``factor``.

    On a convex box (exact, balanced factors: every row sums to 1) a factor k < 1 is a
    scene whose form factors sum to k: its exact solution is B = E / (1 - k rho). This is
    the situation of REFERENCE.md section 5.1, where ambient overshooting diverged.
    """

    def __init__(self, engine: Any, factor: float) -> None:
        self.engine = engine
        self.factor = factor

    @property
    def rays_cast(self) -> int:
        return int(self.engine.rays_cast)

    @property
    def subarea_means(self) -> Any:
        return self.engine.subarea_means

    def column(self, patch: int) -> Column:
        column = self.engine.column(patch)
        return Column(column.receivers, column.factors * self.factor, column.rays)

    def raw_column(self, patch: int, mapped: bool = False) -> Column:
        column = self.engine.raw_column(patch, mapped)
        return Column(column.receivers, column.factors, column.rays)

    def column_scales(self, patch: int) -> tuple[np.ndarray, float]:
        rows, scale = self.engine.column_scales(patch)
        if rows is None:
            rows = np.ones(self.engine.mesh.receiver_count)
        return rows, scale * self.factor


def short_factors_case(rho: float = 0.999, factor: float = 0.99) -> StressCase:
    effective = rho * factor
    return StressCase(
        name=f"short-factors-{rho}",
        group=8,
        title=f"closed cube, rho = {rho}, every form factor x {factor} (rows sum to {factor})",
        expected=f"B = E/(1-{factor} rho) = {1 / (1 - effective):.4g} at every receiver",
        build=lambda: furnace_box(rho, 1.0),
        measure=furnace_error(effective, 1.0),
        wrap_engine=lambda engine: ScaledEngine(engine, factor),
    )


# --------------------------------------------------------------------------------------
# The catalogue
# --------------------------------------------------------------------------------------


def _catalogue() -> list[StressCase]:
    cases: list[StressCase] = []
    cases += [furnace_case(rho) for rho in HIGH_RHO]
    cases += [one_lamp_case(rho) for rho in HIGH_RHO]
    cases += [block_case(OPEN_RHO, standing=False), block_case(OPEN_RHO, standing=True)]
    cases += [open_case(o) for o in ("front", "window-0.2", "window-0.05")]
    cases += [scale_case(v) for v in ("mm", "km", "far")]
    cases += [
        StressCase(
            name="tiny-bulb",
            group=5,
            title="10 m hall, rho = 0.9; one 1e-6 m2 bulb at 1e9 W m-2, 1 mm below the ceiling",
            expected=f"sum a B = 1000 W/(1-rho) = {1000 / 0.1:.5g} W",
            build=bulb_hall,
            measure=power_error(BULB_SIDE**2 * BULB_EXITANCE / (1 - 0.9)),
            mesh=MeshSettings(receivers=1500, patches=100, emitter_samples=16),
        ),
        StressCase(
            name="1000-emitters",
            group=5,
            title="unit cube, rho = 0.9; 1000 double-sided 2 cm triangles emitting 100 W m-2",
            expected="sum a B = 2 n A E/(1-rho) = 400 W",
            build=many_emitters,
            measure=power_error(2 * LED_COUNT**3 * LED_AREA * LED_EXITANCE / (1 - 0.9)),
            mesh=MeshSettings(receivers=1000, patches=60, emitter_samples=1, samples=8),
        ),
        StressCase(
            name="reflecting-lamp",
            group=5,
            title="unit cube, rho = 0.9; a 0.2 m ceiling cell emits 10 W m-2 and reflects",
            expected="sum a B = 4 W; on the lamp's rim B_lamp - E = B_ceiling",
            build=reflecting_lamp_room,
            measure=combined(
                power_error(0.04 * REFLECTING_LAMP / (1 - 0.9)), lamp_continuity_error
            ),
        ),
        StressCase(
            name="double-sided-emitter",
            group=5,
            title="unit cube, rho = 0.9; a 0.4 m panel emitting 5 W m-2 from both sides",
            expected="sum a B = 2 A E/(1-rho) = 16 W; both sides equal",
            build=double_sided_panel_room,
            measure=combined(
                power_error(2 * PANEL_SIDE**2 * PANEL_EXITANCE / (1 - 0.9)), panel_sides_error
            ),
        ),
    ]
    cases += defect_cases(
        "sliver",
        "one wall with a 1e-6 m strip (aspect ratio 1e6)",
        lambda lamp: defect_box({"x+": sliver_wall}, lamp=lamp),
    )
    cases += defect_cases(
        "duplicate-face",
        "one wall (the ceiling for the lamp) modelled twice, identical triangles",
        lambda lamp: defect_box({"y+": duplicated_wall}, lamp=lamp),
    )
    cases += defect_cases(
        "duplicate-retriangulated",
        "one wall (the ceiling for the lamp) twice, the copy split on the other diagonal",
        lambda lamp: defect_box({"y+": retriangulated_duplicate}, lamp=lamp),
    )
    cases += defect_cases(
        "t-junction",
        "one wall in three quads with a T-vertex",
        lambda lamp: defect_box({"x+": t_junction_wall}, lamp=lamp),
    )
    cases += defect_cases(
        "non-manifold-partition",
        "a double-sided diagonal partition: two edges shared by three faces",
        lambda lamp: defect_box(extra=diagonal_partition, lamp=lamp),
    )
    cases += defect_cases(
        "non-manifold-fin",
        "a double-sided 0.3 m fin on the floor/back-wall edge (non-manifold edge)",
        lambda lamp: defect_box(extra=corner_fin, lamp=lamp),
    )
    cases += defect_cases(
        "inverted-wall",
        "one wall wound inside out",
        lambda lamp: defect_box({"x-": inverted_wall}, lamp=lamp),
    )
    cases += defect_cases(
        "inverted-t-junction-wall",
        "one wall inside out, tessellated with a T-vertex (not edge-connected to the box)",
        lambda lamp: defect_box({"x+": inverted_t_junction_wall}, lamp=lamp),
    )
    cases += defect_cases(
        "zero-area",
        "5 zero-area triangles and a stray vertex 1e6 m away",
        lambda lamp: with_degenerate_faces(defect_box(lamp=lamp)),
    )
    cases += defect_cases(
        "duplicate-vertices",
        "every vertex stored three times",
        lambda lamp: with_duplicate_vertices(defect_box(lamp=lamp)),
    )
    cases += [
        StressCase(
            name="no-emitter",
            group=7,
            title="closed cube, rho = 0.9, nothing emits",
            expected="B = 0, stop reason no-emission",
            build=dark_room,
            measure=dark_error,
        ),
        StressCase(
            name="emitter-facing-away",
            group=7,
            title="open: a lamp 0.5 m above a floor, facing up, away from everything",
            expected="B = 0 off the lamp; escaped = emitted",
            build=lamp_facing_away,
            measure=away_error,
        ),
        short_factors_case(),
    ]
    return cases


CASES: list[StressCase] = _catalogue()
BY_NAME: dict[str, StressCase] = {case.name: case for case in CASES}
assert len(BY_NAME) == len(CASES), "stress case names must be unique"


def case(name: str) -> StressCase:
    return BY_NAME[name]


def lossless_check(scene: Scene) -> float:
    """Seconds until ``prepare`` refuses a scene (it must raise RaytradError)."""
    start = time.perf_counter()
    try:
        pipeline.prepare(scene, BOX_MESH).close()
    except RaytradError:
        return time.perf_counter() - start
    raise AssertionError("the scene was accepted")


__all__ = ["BY_NAME", "CASES", "Run", "StressCase", "case", "run_case"]


def assert_finished(run: Run, reason: str = "converged") -> None:
    """The solve ended the expected way, with finite radiosity everywhere."""
    result = run.result
    assert np.isfinite(result.radiosity).all(), "non-finite radiosity"
    assert result.stop_reason == reason, (
        f"{run.case.name}: stopped by {result.stop_reason!r} after {result.state.shots} shots "
        f"(residual {result.residual:.3g})"
    )


def assert_within(run: Run) -> float:
    """The case's error is finite and within its tolerance; returns the error."""
    error = run.case.measure(run)
    assert math.isfinite(error)
    assert error <= run.case.rtol, f"{run.case.name}: error {error:.3g} > {run.case.rtol}"
    return error
