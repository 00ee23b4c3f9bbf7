"""Shared scenes for the numerical-core tests: builders, prepared meshes and a dense reference.

Scenes are kept small (a few thousand receivers at most) so the default run stays fast; the
expensive ones are session fixtures whose form-factor columns are computed once and shared.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

import numpy as np
import pytest

from raytrad import api
from raytrad.mesh import MeshSettings
from raytrad.reference import dense_solve
from raytrad.scene import Scene, make_scene
from raytrad.scenes import cornell_box, furnace_box
from raytrad.solver import SolveResult, SolveSettings, solve

REPOSITORY = Path(__file__).resolve().parents[1]
SCENES = REPOSITORY / "scenes"

#: The objects of ``cornell_box()`` and ``scenes/cornell-box-uv.glb``, in file order.
CORNELL_OBJECTS = (
    "floor",
    "ceiling",
    "back-wall",
    "right-wall",
    "left-wall",
    "light",
    "short-block",
    "tall-block",
)


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """``raytrad.cli.main(argv)`` in-process: (exit status, stdout, stderr)."""
    from raytrad.cli import main

    try:
        status = main(argv)
    except SystemExit as exc:  # argparse errors and --help
        status = exc.code if isinstance(exc.code, int) else 1
    captured = capsys.readouterr()
    return status, captured.out, captured.err


#: A furnace box at about 1700 receivers and 100 patches: fast, and every test agrees on it.
FURNACE_MESH = MeshSettings(receivers=1500, patches=100)
#: The Cornell box small enough for a dense reference solve in about a second.
CORNELL_MESH = MeshSettings(receivers=2000, patches=100)

Material = tuple[Sequence[float] | float, Sequence[float] | float, bool]
"""(reflectance [1], emitted exitance [W m-2], double-sided); scalars mean grey."""


def quads_scene(
    quads: Sequence[Sequence[Sequence[float]]],
    materials: dict[str, Material] | None = None,
    quad_material: Sequence[str] | None = None,
) -> Scene:
    """A scene of planar quads, each with its own four vertices, split along corners 0-2.

    Parameters
    ----------
    quads : (Q, 4, 3) float
        Corners [m], counter-clockwise seen from the front (lit) side.
    materials : dict
        name -> (reflectance, emitted exitance, double-sided); default one grey ``"grey"``
        of reflectance 0.5 that does not emit.
    quad_material : (Q,) sequence of str
        Material of each quad; default the first material for all.
    """
    materials = materials or {"grey": (0.5, 0.0, False)}
    names = list(materials)
    quad_material = quad_material or [names[0]] * len(quads)
    corners = np.asarray(quads, dtype=np.float64).reshape(-1, 4, 3)
    triangles = 4 * np.arange(len(corners))[:, None, None] + np.array([[0, 1, 2], [0, 2, 3]])
    index = np.array([names.index(name) for name in quad_material])
    return make_scene(
        positions=corners.reshape(-1, 3),
        triangles=triangles.reshape(-1, 3),
        material_index=np.repeat(index, 2),
        material_names=names,
        material_reflectance=[np.broadcast_to(materials[n][0], 3) for n in names],
        material_emitted_exitance=[np.broadcast_to(materials[n][1], 3) for n in names],
        material_double_sided=[materials[n][2] for n in names],
    )


def one_quad_scene(
    corners: Sequence[Sequence[float]], reflectance: float = 0.5, emitted_exitance: float = 0.0
) -> Scene:
    """A single one-sided quad (two triangles) of one grey material."""
    return quads_scene([corners], {"grey": (reflectance, emitted_exitance, False)})


@pytest.fixture
def make_quads() -> Callable[..., Scene]:
    """:func:`quads_scene`, for tests that build their own geometry."""
    return quads_scene


@pytest.fixture
def make_one_quad() -> Callable[..., Scene]:
    """:func:`one_quad_scene`, for tests that need a single quad."""
    return one_quad_scene


@pytest.fixture
def prepare_scene() -> Iterator[Callable[..., api.Prepared]]:
    """Factory ``prepare_scene(scene, mesh_settings)`` -> Prepared, closed after the test."""
    opened: list[api.Prepared] = []

    def prepare(scene: Scene, mesh: MeshSettings = FURNACE_MESH) -> api.Prepared:
        prepared = api.prepare(scene, api.RenderSettings(mesh=mesh))
        opened.append(prepared)
        return prepared

    yield prepare
    for prepared in opened:
        prepared.close()


@pytest.fixture
def prepare_furnace(
    prepare_scene: Callable[..., api.Prepared],
) -> Callable[..., api.Prepared]:
    """Factory ``prepare_furnace(reflectance=0.5, emitted_exitance=1.0)`` -> Prepared."""

    def prepare(reflectance: float = 0.5, emitted_exitance: float = 1.0) -> api.Prepared:
        return prepare_scene(furnace_box(reflectance, emitted_exitance), FURNACE_MESH)

    return prepare


@pytest.fixture(scope="session")
def cornell() -> Iterator[api.Prepared]:
    """The Cornell box on :data:`CORNELL_MESH`; its column cache is shared by every test."""
    prepared = api.prepare(cornell_box(), api.RenderSettings(mesh=CORNELL_MESH))
    yield prepared
    prepared.close()


@pytest.fixture(scope="session")
def cornell_dense(cornell: api.Prepared) -> np.ndarray:
    """(R, 3) receiver radiosity of :func:`cornell` by a direct dense solve [W m-2]."""
    return dense_solve(cornell.mesh, cornell.engine)


@pytest.fixture(scope="session")
def cornell_fine() -> Iterator[tuple[api.Prepared, SolveResult]]:
    """The Cornell box at about 4000 receivers, solved to the default tolerance."""
    prepared = api.prepare(
        cornell_box(), api.RenderSettings(mesh=MeshSettings(receivers=4000, patches=100))
    )
    result = solve(prepared.mesh, prepared.engine, SolveSettings())
    yield prepared, result
    prepared.close()
