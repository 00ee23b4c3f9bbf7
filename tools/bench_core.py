"""Benchmark of the core solve on the bundled Cornell box.

For each receiver count and method: the form-factor pass (every column, traced from
scratch), shots and seconds of the solve to the tolerance, rays cast and the effective
rays/s (rays divided by form-factor plus solve time: everything else the code does is in
that figure), next to the raw embreex occlusion throughput on the same rays, measured in
the same run (a sample of the run's own rays is recorded, then replayed through Embree
alone on all cores).

    python tools/bench_core.py                         # 20k and 100k receivers
    python tools/bench_core.py --receivers 5000 --methods ambient
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

from raytrad import api
from raytrad.core.embree import RAYS_VARIABLE
from raytrad.core.mesh import MeshSettings
from raytrad.core.solver import SHOOTING_METHODS, SolveSettings, solve
from raytrad.core.visibility import Occluder
from raytrad.scenefiles import load_scene
from raytrad.settings import RenderSettings

ROOT = Path(__file__).resolve().parent.parent


class _Recorder:
    """Replaces ``Occluder.occluded_local`` and ``Occluder.occluded_samples`` (class-wide)
    to keep a sample of the rays traced; the pass's rays, made and traced in Embree's
    packets without being written out, are made again for the record
    (:meth:`~raytrad.core.visibility.Occluder.sample_rays`, the same rays)."""

    def __init__(self, budget: int) -> None:
        self.budget = budget
        self.parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self.kept = 0
        self.inner = Occluder.occluded_local
        self.samples = Occluder.occluded_samples

    def _keep(self, o: np.ndarray, d: np.ndarray, t: np.ndarray) -> None:
        if self.kept < self.budget:
            self.parts.append((o.astype(np.float32), d.astype(np.float32), t.astype(np.float32)))
            self.kept += len(o)

    def __enter__(self) -> _Recorder:
        recorder = self

        def recording(occluder: Occluder, o: np.ndarray, d: np.ndarray, t: np.ndarray):  # type: ignore[no-untyped-def]
            recorder._keep(o, d, t)
            return recorder.inner(occluder, o, d, t)

        def recording_samples(occluder, origins, far, doubt, targets, near, near_targets, shorten):  # type: ignore[no-untyped-def]
            rays = occluder.sample_rays(origins, far, doubt, targets, near, near_targets, shorten)
            recorder._keep(*rays[:3])
            return recorder.samples(
                occluder, origins, far, doubt, targets, near, near_targets, shorten
            )

        Occluder.occluded_local = recording  # type: ignore[method-assign]
        Occluder.occluded_samples = recording_samples  # type: ignore[method-assign]
        return self

    def __exit__(self, *exc: object) -> None:
        Occluder.occluded_local = self.inner  # type: ignore[method-assign]
        Occluder.occluded_samples = self.samples  # type: ignore[method-assign]

    def rays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        o, d, t = (np.concatenate([p[k] for p in self.parts]) for k in range(3))
        return o, d, t


def raw_throughput(occluder: Occluder, rays: tuple[np.ndarray, np.ndarray, np.ndarray]) -> float:
    """Rays/s of embreex alone (its single-ray query, whatever ``occluder`` traces with)
    on recorded rays, split across all cores (best of 3)."""
    before = os.environ.get(RAYS_VARIABLE)
    os.environ[RAYS_VARIABLE] = "embreex"
    try:
        occluder = Occluder(occluder.positions, occluder.triangles)
    finally:
        if before is None:
            del os.environ[RAYS_VARIABLE]
        else:
            os.environ[RAYS_VARIABLE] = before
    o, d, t = rays
    best = 0.0
    for _ in range(3):
        start = time.perf_counter()
        occluder.occluded_local(o, d, t)
        best = max(best, len(o) / (time.perf_counter() - start))
    return best


def run(receivers: int, method: str, tolerance: float) -> dict[str, float | int | str]:
    scene = load_scene(ROOT / "scenes" / "cornell-box.obj")
    settings = RenderSettings(mesh=MeshSettings(receivers=receivers))
    with _Recorder(budget=4_000_000) as recorder:
        prepared = api.prepare(scene, settings)  # every column traced here, rays recorded
    try:
        setup = prepared.timings.get("mesh", 0.0) + prepared.timings.get("acceleration", 0.0)
        form_factors = prepared.timings["form_factors"]
        result = solve(prepared.mesh, prepared.engine, SolveSettings(method, tolerance))
        assert prepared.occluder is not None
        raw = raw_throughput(prepared.occluder, recorder.rays())
        rays = prepared.engine.rays_cast
    finally:
        prepared.close()
    state = result.state
    tracing = form_factors + state.seconds
    return {
        "receivers": prepared.mesh.receiver_count,
        "patches": prepared.mesh.patch_count,
        "method": method,
        "stop": result.stop_reason,
        "shots": state.shots,
        "setup_s": setup,
        "form_factor_s": form_factors,
        "solve_s": state.seconds,
        "rays": rays,
        "solve_rays_per_s": rays / tracing,
        "embree_rays_per_s": raw,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--receivers",
        default="20000,100000",
        help="comma-separated target receiver counts (default: %(default)s)",
    )
    parser.add_argument(
        "--methods",
        default=",".join(SHOOTING_METHODS),
        help="comma-separated methods (default: %(default)s)",
    )
    parser.add_argument("--tolerance", type=float, default=1e-3)
    args = parser.parse_args(argv)
    header = (
        f"{'receivers':>9} {'patches':>7} {'method':<14} {'stop':<10} {'shots':>6} "
        f"{'mesh s':>6} {'F s':>7} {'solve s':>7} {'total s':>7} {'rays':>11} "
        f"{'rays/s':>9} {'embree rays/s':>13} {'ratio':>6}"
    )
    print(header)
    print("-" * len(header))
    for count in (int(c) for c in args.receivers.split(",")):
        for method in args.methods.split(","):
            r = run(count, method, args.tolerance)
            ratio = float(r["solve_rays_per_s"]) / float(r["embree_rays_per_s"])
            total = float(r["form_factor_s"]) + float(r["solve_s"])
            print(
                f"{r['receivers']:>9} {r['patches']:>7} {r['method']:<14} {r['stop']:<10} "
                f"{r['shots']:>6} {r['setup_s']:>6.2f} {r['form_factor_s']:>7.2f} "
                f"{r['solve_s']:>7.2f} {total:>7.2f} {r['rays']:>11} "
                f"{r['solve_rays_per_s']:>9.3g} {r['embree_rays_per_s']:>13.3g} {ratio:>6.2f}",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
