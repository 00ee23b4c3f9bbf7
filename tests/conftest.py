"""Shared scenes for the numerical-core tests: builders, prepared meshes and a dense reference.

Scenes are kept small (a few thousand receivers at most) so the default run stays fast; the
expensive ones are session fixtures whose form-factor columns are computed once and shared.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

import numpy as np
import pytest

from raytrad.core.mesh import MeshSettings
from raytrad.core.pipeline import Prepared, prepare
from raytrad.core.reference import dense_solve
from raytrad.core.solver import SolveResult, SolveSettings, solve
from raytrad.scene import Scene, make_scene, triangle_areas_normals
from raytrad.scene.builder import quads_scene
from raytrad.scene.builtin import cornell_box, furnace_box

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


def npm_package(directory: Path, package: str) -> None:
    """Make sure the npm ``package`` pinned in ``directory``'s package.json is installed
    there (``npm install``), or skip the test saying why it cannot be."""
    import shutil
    import subprocess

    if (directory / "node_modules" / package).is_dir():
        return
    npm = shutil.which("npm")
    if npm is None:
        pytest.skip(f"npm is needed to install {package} (not installed)")
    done = subprocess.run(
        [npm, "install", "--no-audit", "--no-fund", "--prefix", str(directory)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    if done.returncode != 0:
        pytest.skip(f"could not install {package} from npm: {done.stderr[-300:]}")


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


def one_quad_scene(
    corners: Sequence[Sequence[float]], reflectance: float = 0.5, emitted_exitance: float = 0.0
) -> Scene:
    """A single one-sided quad (two triangles) of one grey material."""
    return quads_scene([corners], {"grey": (reflectance, emitted_exitance, False)})


def triangle_soup(
    corners: np.ndarray,
    uv: np.ndarray | None,
    object_index: Sequence[int] | None = None,
    object_names: Sequence[str] | None = None,
) -> Scene:
    """A scene of triangles with their own three vertices each, one grey material.

    Parameters
    ----------
    corners : (T, 3, 3) float
        Corner positions [m], counter-clockwise from the front side.
    uv : (T, 3, 2) float or None
        Corner lightmap UVs.
    object_index : (T,) int or None
        Object of each triangle; default one object per triangle, named ``t<i>``.
    """
    corners = np.asarray(corners, dtype=np.float64)
    count = len(corners)
    if object_index is None:
        object_index = range(count)
        object_names = [f"t{i}" for i in range(count)]
    return make_scene(
        positions=corners.reshape(-1, 3),
        triangles=np.arange(3 * count).reshape(-1, 3),
        material_index=np.zeros(count, dtype=np.int64),
        material_names=["grey"],
        material_reflectance=[[0.5, 0.5, 0.5]],
        material_emitted_exitance=[[0.0, 0.0, 0.0]],
        object_index=np.asarray(object_index),
        object_names=object_names,
        lightmap_uv=uv,
    )


def uv_at_corner(corners: np.ndarray, uv: np.ndarray, point: np.ndarray) -> np.ndarray:
    """The UV recorded for ``point`` among one triangle's (3, 3) corners and (3, 2) UVs."""
    at = np.nonzero(np.abs(corners - point).max(axis=1) < 1e-12)[0]
    assert len(at) == 1
    return uv[at[0]]


def areas_by_material(scene: Scene) -> dict[str, float]:
    """Total area [m2] of each material's faces, computed from the corners."""
    areas, _ = triangle_areas_normals(scene.triangle_vertices())
    return {
        name: float(areas[scene.material_index == i].sum())
        for i, name in enumerate(scene.material_names)
    }


@pytest.fixture
def make_quads() -> Callable[..., Scene]:
    """:func:`quads_scene`, for tests that build their own geometry."""
    return quads_scene


@pytest.fixture
def make_one_quad() -> Callable[..., Scene]:
    """:func:`one_quad_scene`, for tests that need a single quad."""
    return one_quad_scene


@pytest.fixture
def prepare_scene() -> Iterator[Callable[..., Prepared]]:
    """Factory ``prepare_scene(scene, mesh_settings)`` -> Prepared, closed after the test."""
    opened: list[Prepared] = []

    def make(scene: Scene, mesh: MeshSettings = FURNACE_MESH) -> Prepared:
        prepared = prepare(scene, mesh)
        opened.append(prepared)
        return prepared

    yield make
    for prepared in opened:
        prepared.close()


@pytest.fixture
def prepare_furnace(
    prepare_scene: Callable[..., Prepared],
) -> Callable[..., Prepared]:
    """Factory ``prepare_furnace(reflectance=0.5, emitted_exitance=1.0)`` -> Prepared."""

    def make(reflectance: float = 0.5, emitted_exitance: float = 1.0) -> Prepared:
        return prepare_scene(furnace_box(reflectance, emitted_exitance), FURNACE_MESH)

    return make


@pytest.fixture(scope="session")
def cornell() -> Iterator[Prepared]:
    """The Cornell box on :data:`CORNELL_MESH`; its column cache is shared by every test."""
    prepared = prepare(cornell_box(), CORNELL_MESH)
    yield prepared
    prepared.close()


@pytest.fixture(scope="session")
def cornell_dense(cornell: Prepared) -> np.ndarray:
    """(R, 3) receiver radiosity of :func:`cornell` by a direct dense solve [W m-2]."""
    return dense_solve(cornell.mesh, cornell.engine)


@pytest.fixture(scope="session")
def cornell_fine() -> Iterator[tuple[Prepared, SolveResult]]:
    """The Cornell box at about 4000 receivers, solved to the default tolerance."""
    prepared = prepare(cornell_box(), MeshSettings(receivers=4000, patches=100))
    result = solve(prepared.mesh, prepared.engine, SolveSettings())
    yield prepared, result
    prepared.close()
