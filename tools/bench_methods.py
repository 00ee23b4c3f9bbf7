"""The ranking of Feda's overshooting methods, measured: shots and seconds to a true error.

For each scene of a suite (the Cornell box; closed furnace boxes at reflectance 0.5, 0.9
and 0.99; an open scene; a room of mixed colours) the form factors are computed once and
shared, a dense direct solve of the same discrete system is the reference, and every
method of :data:`raytrad.core.solver.SHOOTING_METHODS` runs, with plain progressive
refinement as the baseline and overrelaxation swept over omega = 1.1 ... 1.9 (the best
marked). After every shot the receivers' radiosity is compared with the reference
(area-weighted relative RMS); the table gives the shots and solver seconds (the error
measurement left out) at which 1e-2 and 1e-3 were first reached, and what building the
patch-to-patch factors cost the three methods that need them.

    python tools/bench_methods.py [--receivers 1500] [--patches 150] [--max-shots 40000]

Prints a markdown table (docs/methods.md holds a run and what it means).
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from raytrad.core.mesh import MeshSettings
from raytrad.core.patch_factors import PatchFactors, patch_factor_mb
from raytrad.core.pipeline import Prepared, prepare
from raytrad.core.reference import dense_solve
from raytrad.core.solver import SHOOTING_METHODS, SolverState, SolveSettings, solve
from raytrad.core.system import DiscreteSystem
from raytrad.scene import Scene
from raytrad.scene.builtin import cornell_box, furnace_box, shadow_scene
from raytrad.scenefiles import load_scene

TARGETS = (1e-2, 1e-3)
OMEGAS = (1.1, 1.3, 1.5, 1.7, 1.9)


def suite() -> dict[str, Callable[[], Scene]]:
    """The scenes, by name."""
    return {
        "Cornell box": cornell_box,
        "closed box rho 0.5": lambda: furnace_box(0.5, 1.0),
        "closed box rho 0.9": lambda: furnace_box(0.9, 1.0),
        "closed box rho 0.99": lambda: furnace_box(0.99, 1.0),
        "open scene (shadow)": shadow_scene,
        "mixed reflectances (colour room)": lambda: load_scene("scenes/colour-room.toml"),
    }


@dataclass
class Run:
    """Shots and solver seconds at which each target error was first reached."""

    method: str
    omega: float | None
    shots: dict[float, int | None]
    seconds: dict[float, float | None]


def measure(
    prepared: Prepared, reference: np.ndarray, method: str, omega: float, max_shots: int
) -> Run:
    """Solve with ``method`` until the true error reaches the last target."""
    problem = DiscreteSystem.from_mesh(prepared.mesh)
    area = prepared.mesh.receiver_area
    scale = float(area @ (reference**2).sum(axis=1))
    shots: dict[float, int | None] = dict.fromkeys(TARGETS)
    seconds: dict[float, float | None] = dict.fromkeys(TARGETS)
    overhead = [0.0]

    def watch(state: SolverState, residual: float) -> None:
        begin = time.perf_counter()
        radiosity = problem.receiver_emission + problem.receiver_reflectance * state.irradiance
        error = math.sqrt(float(area @ ((radiosity - reference) ** 2).sum(axis=1)) / scale)
        for target in TARGETS:
            if shots[target] is None and error <= target:
                shots[target] = state.shots
                seconds[target] = state.seconds - overhead[0]
        overhead[0] += time.perf_counter() - begin

    settings = SolveSettings(method=method, tolerance=1e-9, max_shots=max_shots, omega=omega)
    solve(
        prepared.mesh,
        prepared.engine,
        settings,
        progress=watch,
        stop=lambda: shots[TARGETS[-1]] is not None,
    )
    return Run(method, omega if method == "overrelaxation" else None, shots, seconds)


def _cell(value: float | None, digits: int = 0) -> str:
    if value is None:
        return "—"
    return f"{value:.{digits}f}" if digits else f"{int(value)}"


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--receivers", type=int, default=1500)
    parser.add_argument("--patches", type=int, default=150)
    parser.add_argument("--max-shots", type=int, default=40000)
    args = parser.parse_args()
    mesh_settings = MeshSettings(receivers=args.receivers, patches=args.patches)
    print("| scene | method | omega | shots to 1e-2 | s to 1e-2 | shots to 1e-3 | s to 1e-3 |")
    print("|---|---|---|---|---|---|---|")
    costs = []
    for name, make in suite().items():
        with prepare(make(), mesh_settings) as prepared:
            reference = dense_solve(prepared.mesh, prepared.engine)
            problem = DiscreteSystem.from_mesh(prepared.mesh)
            begin = time.perf_counter()
            PatchFactors.from_columns(problem, prepared.engine, problem.receiver_reflectance)
            costs.append(
                (
                    name,
                    prepared.mesh.patch_count,
                    time.perf_counter() - begin,
                    prepared.timings.get("form_factors", float("nan")),
                )
            )
            runs = [
                measure(prepared, reference, method, omega, args.max_shots)
                for method in SHOOTING_METHODS
                for omega in (OMEGAS if method == "overrelaxation" else (1.0,))
            ]
            relaxed = [r for r in runs if r.method == "overrelaxation"]
            best = min(relaxed, key=lambda r: r.shots[TARGETS[-1]] or math.inf)
            for run in runs:
                omega = (
                    ""
                    if run.omega is None
                    else f"{run.omega:.1f}" + (" (best)" if run is best else "")
                )
                print(
                    f"| {name} | {run.method} | {omega} | {_cell(run.shots[1e-2])} | "
                    f"{_cell(run.seconds[1e-2], 3)} | {_cell(run.shots[1e-3])} | "
                    f"{_cell(run.seconds[1e-3], 3)} |",
                    flush=True,
                )
    print()
    print(
        "| scene | patches | patch-to-patch factors [s] | their memory [MiB] | "
        "form-factor pass [s] |"
    )
    print("|---|---|---|---|---|")
    for name, count, seconds, pass_seconds in costs:
        print(
            f"| {name} | {count} | {seconds:.3f} | {patch_factor_mb(count):.2f} | "
            f"{pass_seconds:.2f} |"
        )


if __name__ == "__main__":
    main()
