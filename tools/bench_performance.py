"""Speed of the form-factor pass and the whole render, each against a baseline measured in
the same run.

Three parts:

1. **Pass against raw Embree.** The scene's form-factor pass (every column, as
   ``raytrad render`` computes it before the first shot) is timed with shaft culling and
   convex blockers (the default), with shaft culling alone and tracing every pair; the
   default and unculled passes are run again with their rays recorded, and those rays
   replayed, with the same threads, in the same process (beyond 2**25 rays, a sample of
   their batches, its time scaled by the rays), twice: through embreex's occlusion
   query (``EmbreeScene.run``, one ray at a time: the issue's raw Embree) and through
   Embree's 8-ray packets, as the pass traces them (``raytrad.core.embree``). The last
   two columns set each pass against each doing the unculled pass's job: above 100% the
   pass finishes the job faster than Embree alone traces it.
   ``rays / naive`` sets rays cast against receivers x samples of the pairs that see
   each other.
2. **Compiled against numpy kernels; the solve.** The same pass with
   ``RAYTRAD_KERNELS=numpy`` (the numpy reference kernels) in the same process, a last
   row of table 1, and the check that every variant gives the same factors; then, on a
   line of its own, a default solve over the cached columns with the compiled shot and
   with ``numpy_step``, against the pass time. ``--no-numpy`` leaves out the numpy pass
   and shot (minutes on a scene of many thousand triangles).
3. **Whole renders and scale.** ``raytrad render`` of the scene at each
   ``--receivers``, as a child process: seconds per stage from ``report.json``, shots,
   rays and peak memory; with ``--previous RAYTRAD`` (the ``raytrad`` executable of
   another install, e.g. the previous release in its own venv) the same renders by it,
   alternating, and the time ratio. The growth exponent of the total time is fitted over
   the sizes. With ``--accuracy``, each render's PLY is also scored against
   ``tools/bench_accuracy.py``'s path-traced reference (worst surface, point RMS); with
   ``--previous`` too, a last table gives, for each size of the other install, the
   fastest render of this one at least as accurate by both errors: the speed-up at
   equal accuracy.

The scene is the bundled Cornell box unless ``--scene`` names another file (any format
``raytrad render`` reads; ``--accuracy`` needs the Cornell box, whose reference it has).

    python tools/bench_performance.py                                # 5000 receivers
    python tools/bench_performance.py --scene scenes/blocks-room.obj --no-renders
    python tools/bench_performance.py --scene big.obj --no-renders --no-numpy  # many triangles
    python tools/bench_performance.py --receivers 5000 20000 --previous ../venv-prev/bin/raytrad
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import io
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from raytrad.constants import scene_diagonal  # noqa: E402
from raytrad.core import embree, pairs, pipeline, shot, solver  # noqa: E402
from raytrad.core.hidden import fill_hidden  # noqa: E402
from raytrad.core.mesh import MeshSettings  # noqa: E402
from raytrad.core.pipeline import prepare  # noqa: E402
from raytrad.core.visibility import Occluder  # noqa: E402
from raytrad.formats.ply import read_radiosity_ply  # noqa: E402
from raytrad.products.probe import PROBE_LIFT  # noqa: E402
from raytrad.scene import triangle_areas_normals  # noqa: E402
from raytrad.scene.builtin import cornell_box  # noqa: E402

SCENE = ROOT / "scenes" / "cornell-box.obj"
#: The scene file the tables measure (``--scene``).
_CHOSEN = {"scene": SCENE}
#: bench_accuracy's defaults (``--per-quad``, ``--along``, ``--paths``): its cached reference.
PROBES_PER_QUAD, PROBES_ALONG, PATHS = 256, 8, 20000
#: PLY vertices darker than this share of the median are taken as hidden (:func:`ply_at`).
HIDDEN_LEVEL = 1e-3
#: Runs argv[1:] and prints its peak resident memory [KiB] (Linux ru_maxrss).
_MEASURE = (
    "import resource, subprocess, sys; subprocess.run(sys.argv[1:], check=True); "
    "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)"
)


@functools.cache
def _scene() -> Any:
    """The scene of ``--scene``, loaded once."""
    from raytrad import api
    from raytrad.settings import RenderSettings

    return api.load(_CHOSEN["scene"], RenderSettings()).scene


#: Most rays a recorded pass keeps for the replay (32 bytes each: about 1 GiB). A pass
#: casting more (a hall of four furnished rooms at 10 000 receivers: some 3e8, which took
#: 24 GB) keeps a sample of its batches, and the replay's time is scaled by the rays.
RECORDED_RAYS = 2**25


class Recording:
    """The ray batches of a pass, every ``stride``-th batch of those cast: when the kept
    ones pass :data:`RECORDED_RAYS`, every other one is dropped and the stride doubled
    (safe from the pass's threads)."""

    def __init__(self, limit: int | None = None) -> None:
        self.batches: list[tuple[int, tuple[np.ndarray, np.ndarray, np.ndarray]]] = []
        self.limit = RECORDED_RAYS if limit is None else limit
        self.stride, self.seen, self.rays, self.kept = 1, 0, 0, 0
        self._lock = threading.Lock()

    def add(self, o: np.ndarray, d: np.ndarray, t: np.ndarray) -> None:
        with self._lock:
            index, self.seen = self.seen, self.seen + 1
            self.rays += len(o)
            if index % self.stride:
                return
            self.batches.append(
                (index, (np.array(o, np.float32), np.array(d, np.float32), np.array(t)))
            )
            self.kept += len(o)
            while self.kept > self.limit and len(self.batches) > 1:
                self.stride *= 2
                self.batches = [b for b in self.batches if b[0] % self.stride == 0]
                self.kept = sum(len(b[1][0]) for b in self.batches)

    @property
    def share(self) -> float:
        """The kept rays' share of those cast [1]."""
        return self.kept / self.rays if self.rays else 1.0


def timed_pass(
    receivers: int, record: bool, cull: bool = True, convex: bool = True
) -> tuple[float, object, Recording]:
    """(seconds of the form-factor pass, the prepared scene, its recorded ray batches);
    ``convex`` False leaves the convex blockers out (shaft culling alone)."""
    recorded = Recording()
    original = Occluder.occluded_local

    def recording(self, o, d, t):  # type: ignore[no-untyped-def]
        if record:
            recorded.add(o, d, t)
        return original(self, o, d, t)

    samples = Occluder.occluded_samples

    def recording_samples(self, origins, far, doubt, targets, near, near_targets, shorten):  # type: ignore[no-untyped-def]
        if record:  # the pass's rays made in packets, written out too (as the numpy path)
            rays = self.sample_rays(origins, far, doubt, targets, near, near_targets, shorten)
            recorded.add(*rays[:3])
        return samples(self, origins, far, doubt, targets, near, near_targets, shorten)

    Occluder.occluded_local = recording  # type: ignore[method-assign]
    Occluder.occluded_samples = recording_samples  # type: ignore[method-assign]
    engine = pipeline.FormFactorEngine
    pipeline.FormFactorEngine = functools.partial(engine, cull=cull)  # type: ignore[misc]
    find = pairs.blockers
    if not convex:
        pairs.blockers = lambda *_: None  # type: ignore[assignment]
    try:
        prepared = prepare(_scene(), MeshSettings(receivers=receivers))
    finally:
        Occluder.occluded_local = original  # type: ignore[method-assign]
        Occluder.occluded_samples = samples  # type: ignore[method-assign]
        pipeline.FormFactorEngine = engine  # type: ignore[misc]
        pairs.blockers = find
    return prepared.timings["form_factors"], prepared, recorded


def _replayed(receivers: int, cull: bool) -> tuple[float, float, int]:
    """(embreex's seconds, Embree packets' seconds, rays) answering a pass's occlusion
    queries, recorded in a run of the pass of its own: once through embreex's single-ray
    query (``EmbreeScene.run``, the issue's raw Embree) and once through the packets the
    pass itself uses (:mod:`raytrad.core.embree`; embreex again where they are not
    available). From a sample of its batches beyond :data:`RECORDED_RAYS`, the seconds
    are scaled by the rays cast over the rays replayed (said on a line)."""
    _, prepared, recorded = timed_pass(receivers, record=True, cull=cull)
    batches = [batch for _, batch in recorded.batches]
    try:
        occluder = prepared.occluder
        with _rays_through("embreex"):
            single = Occluder(occluder.positions, occluder.triangles)
        try:
            seconds, rays = replay(single, batches)
        finally:
            single.close()
        packet_seconds, _ = replay(occluder, batches)
    finally:
        prepared.close()
    if recorded.share < 1.0:
        print(
            f"(raw Embree from a sample: {rays:.3g} of {recorded.rays:.3g} rays, one batch "
            f"in {recorded.stride}, {seconds:.2f} s and {packet_seconds:.2f} s in packets, "
            f"scaled by {1 / recorded.share:.1f})"
        )
        seconds /= recorded.share
        packet_seconds /= recorded.share
    return seconds, packet_seconds, recorded.rays


@contextlib.contextmanager
def _rays_through(kind: str) -> Iterator[None]:
    """``RAYTRAD_RAYS`` set to ``kind`` for the occluders made meanwhile."""
    before = os.environ.get(embree.RAYS_VARIABLE)
    os.environ[embree.RAYS_VARIABLE] = kind
    try:
        yield
    finally:
        if before is None:
            del os.environ[embree.RAYS_VARIABLE]
        else:
            os.environ[embree.RAYS_VARIABLE] = before


def _dense(engine: object, patch: int) -> np.ndarray:
    """(R,) balanced form factors of every receiver to ``patch``."""
    column = engine.column(patch)  # type: ignore[attr-defined]
    out = np.zeros(engine.mesh.receiver_count)  # type: ignore[attr-defined]
    out[column.receivers] = column.factors
    return out


def replay(occluder: Occluder, batches: list) -> tuple[float, int]:
    """Seconds for ``occluder`` to answer the recorded occlusion queries (same threads)."""
    start = time.perf_counter()
    rays = 0
    for o, d, t in batches:
        occluder.occluded_local(o, d, t)
        rays += len(o)
    return time.perf_counter() - start, rays


def _worst(prepared: object, factors: list[np.ndarray]) -> float:
    """Largest difference of ``prepared``'s factors from ``factors`` (every 7th column)."""
    patches = range(0, prepared.mesh.patch_count, 7)  # type: ignore[attr-defined]
    return max(
        float(np.abs(_dense(prepared.engine, p) - f).max())  # type: ignore[attr-defined]
        for p, f in zip(patches, factors, strict=True)
    )


def _solve_seconds(prepared: object, shoot: object) -> tuple[float, int]:
    """(seconds, shots) of a default solve over the prepared columns with ``shoot``."""
    original = solver._shoot
    solver._shoot = shoot  # type: ignore[assignment]
    try:
        start = time.perf_counter()
        result = solver.solve(prepared.mesh, prepared.engine)  # type: ignore[attr-defined]
        return time.perf_counter() - start, result.state.shots
    finally:
        solver._shoot = original  # type: ignore[assignment]


def pass_table(receivers: int, with_numpy: bool = True) -> None:
    """The pass against raw Embree (table 1) and the solve (a line below); ``with_numpy``
    False leaves out the numpy kernels' pass and shot (on a scene of many thousand
    triangles the numpy pass takes minutes)."""
    from raytrad.core import compiled

    compiled.get()  # compile (or load) before timing
    prepare(_scene(), MeshSettings(receivers=200)).close()
    # each pass is timed without recording its rays (copying them costs up to a third of
    # a pass), and run again recording them for the replay
    seconds, prepared, _ = timed_pass(receivers, record=False)
    try:
        naive = prepared.engine.rays_naive
        factors = [_dense(prepared.engine, p) for p in range(0, prepared.mesh.patch_count, 7)]
        solve_fast, shots = _solve_seconds(prepared, solver._shoot)
        solve_numpy = _solve_seconds(prepared, shot.numpy_step)[0] if with_numpy else None
    finally:
        prepared.close()
    single, packets, rays = _replayed(receivers, cull=True)
    every_seconds, every, _ = timed_pass(receivers, record=False, cull=False)
    try:
        every_worst = _worst(every, factors)
    finally:
        every.close()
    every_embree, every_packets, every_rays = _replayed(receivers, cull=False)
    shafts_seconds, shafts_only, _ = timed_pass(receivers, record=False, convex=False)
    shafts_rays = shafts_only.engine.rays_cast  # type: ignore[attr-defined]
    shafts_worst = _worst(shafts_only, factors)
    shafts_only.close()
    numpy_row = _numpy_pass(receivers, factors) if with_numpy else None
    print(
        f"\nform-factor pass, {_CHOSEN['scene'].name}, --receivers {receivers} "
        f"({prepared.mesh.receiver_count} receivers, {prepared.mesh.patch_count} patches; "
        f"naive count receivers x samples: {naive:.3g} rays)"
    )
    print(
        "| pass | seconds | rays | rays / naive | raw embreex on every ray / pass | raw "
        "Embree packets on every ray / pass |"
    )
    print("|---|---|---|---|---|---|")
    rows = [
        ("raw embreex occlusion, every ray of the unculled pass", every_embree, every_rays),
        ("raw embreex occlusion, the default pass's rays", single, rays),
        ("raw Embree packets, every ray of the unculled pass", every_packets, every_rays),
        ("raw Embree packets, the default pass's rays", packets, rays),
        (
            "raytrad pass, every pair traced (no shaft culling, no blockers)",
            every_seconds,
            every_rays,
        ),
        ("raytrad pass, shaft culling, no convex blockers", shafts_seconds, shafts_rays),
        ("raytrad pass, shaft culling and convex blockers (default)", seconds, rays),
    ]
    if numpy_row is not None:
        rows.append(("raytrad pass, numpy kernels (no culling, no blockers)", *numpy_row[:2]))
    for name, took, count in rows:
        print(
            f"| {name} | {took:.2f} | {count:.3g} | {count / naive:.2f} | "
            f"{100 * every_embree / took:.0f}% | {100 * every_packets / took:.0f}% |"
        )
    numpy_text = "" if numpy_row is None else f"compiled / numpy: {seconds / numpy_row[0]:.2f}; "
    print(
        f"default / unculled pass time: {seconds / every_seconds:.2f}; default / shafts "
        f"alone: {seconds / shafts_seconds:.2f}; {numpy_text}largest factor difference "
        f"(every 7th column) unculled {every_worst:.1e}, shafts alone {shafts_worst:.1e}"
        + ("" if numpy_row is None else f", numpy kernels {numpy_row[2]:.1e}")
    )
    shot_text = (
        ""
        if solve_numpy is None
        else f", numpy shot {solve_numpy:.2f} s ({100 * solve_numpy / seconds:.0f}%); "
        f"compiled / numpy {solve_fast / solve_numpy:.2f}"
    )
    print(
        f"\nsolve over the cached columns ({shots} shots): compiled shot {solve_fast:.2f} s "
        f"({100 * solve_fast / seconds:.1f}% of the pass){shot_text}"
    )


def _numpy_pass(receivers: int, factors: list[np.ndarray]) -> tuple[float, int, float]:
    """The pass with the numpy reference kernels: seconds, rays and the largest factor
    difference from the compiled pass's ``factors`` (every 7th column)."""
    os.environ["RAYTRAD_KERNELS"] = "numpy"
    try:
        numpy_seconds, reference, _ = timed_pass(receivers, record=False)
        numpy_rays = reference.engine.rays_cast  # type: ignore[attr-defined]
        worst = _worst(reference, factors)
        reference.close()
    finally:
        del os.environ["RAYTRAD_KERNELS"]
    return numpy_seconds, numpy_rays, worst


def render_once(raytrad: str, receivers: int, truth: Truth | None) -> dict[str, float]:
    """One ``raytrad render`` as a child: stage seconds, shots, rays, peak MiB, wall s;
    with ``truth``, also its PLY's errors (``worst``, ``rms``, see :class:`Truth`)."""
    with tempfile.TemporaryDirectory() as out:
        # a small Python parent runs the render, so that the child's peak memory is its
        # own (a child forked from this process would count this process's memory too)
        start = time.perf_counter()
        scene = _CHOSEN["scene"]
        command = [raytrad, "render", str(scene), "-o", out, "--receivers", str(receivers), "-q"]
        done = subprocess.run(
            [sys.executable, "-c", _MEASURE, *command],
            check=True,
            capture_output=True,
            text=True,
        )
        wall = time.perf_counter() - start
        peak_kib = float(done.stdout.split()[-1])
        report = json.loads((Path(out) / "report.json").read_text())
        errors = {} if truth is None else truth.errors(Path(out) / f"{scene.stem}.ply")
    timings = report["timings_seconds"]
    return {
        "wall": wall,
        "form_factors": timings["form_factors"],
        "solve": timings["solve"],
        "refine": timings.get("refine", 0.0),
        "shots": report["solve"]["shots"],
        "rays": report["solve"]["rays"],
        "receivers": report["statistics"]["receivers"],
        "peak_mib": peak_kib / 1024.0,
        **errors,
    }


@dataclass
class Truth:
    """``tools/bench_accuracy.py``'s probes and cached path-traced reference (the race's,
    ``tools/bench_race.py``): a render's worst-surface mean error and point-wise RMS,
    reference noise removed, read from its PLY."""

    probes: Any
    reference: np.ndarray
    reference_error: np.ndarray
    quad_area: np.ndarray

    @classmethod
    def cornell(cls) -> Truth:
        from bench_accuracy import probe_set, reference, shut_in

        scene = cornell_box()
        probes = probe_set(scene, PROBES_PER_QUAD, PROBES_ALONG)
        ref, ref_error = reference(scene, probes, PATHS, ROOT / ".cache" / "accuracy")
        probes.shut = shut_in(scene, probes)
        area = triangle_areas_normals(scene.triangle_vertices())[0]
        return cls(probes, ref, ref_error, area[0::2] + area[1::2])

    def errors(self, ply: Path) -> dict[str, float]:
        """``worst`` and ``rms`` [1] of the radiosity PLY ``ply`` at the probes."""
        from bench_accuracy import report

        got = ply_at(ply, self.probes.points, self.probes.normals)
        with contextlib.redirect_stdout(io.StringIO()):
            out = report("", got, self.reference, self.reference_error, self.probes, self.quad_area)
        return {"worst": out["worst surface"], "rms": out["point RMS, reference noise removed"]}


def ply_at(path: Path, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(N, 3) radiosity of a radiosity PLY at surface points (N, 3) on the side their unit
    ``normals`` face: its vertex values interpolated over the triangle under each point,
    as :func:`raytrad.products.probe.radiosity_at` reads a mesh (NaN where no triangle
    facing that way lies within ``PROBE_LIFT`` of the diagonal). Read from the file, so
    that a render by any install, another release's too, is measured alike. The PLY holds
    the solve's radiosity, hidden receivers (under a block) near their emission: vertices
    below :data:`HIDDEN_LEVEL` of the median count as hidden (the Cornell box lights every
    surface anyone sees far above that) and are filled as images and lightmaps fill them
    (:func:`fill_hidden`)."""
    positions, triangles, radiosity = read_radiosity_ply(path)
    level = radiosity.max(axis=1)
    seen = SimpleNamespace(
        receiver_visible=level > HIDDEN_LEVEL * np.median(level), triangle_receivers=triangles
    )
    radiosity = fill_hidden(seen, radiosity)  # type: ignore[arg-type]
    lift = PROBE_LIFT * scene_diagonal(positions)
    _, facing = triangle_areas_normals(positions[triangles])
    with Occluder(positions, triangles) as occluder:
        origin = occluder.to_local(points + 2.0 * lift * normals)
        hit, distance, weights = occluder.intersect_barycentric_local(origin, -normals)
    out = np.full((len(points), 3), np.nan)
    ok = (hit >= 0) & (np.abs(distance - 2.0 * lift) <= lift)
    ok[ok] = np.einsum("ij,ij->i", facing[hit[ok]], normals[ok]) > 0
    out[ok] = np.einsum("nk,nkc->nc", weights[ok], radiosity[triangles[hit[ok]]])
    return out


def render_table(sizes: list[int], previous: str | None, runs: int, truth: Truth | None) -> None:
    here = str(Path(sys.executable).parent / "raytrad")
    rows = []
    for receivers in sizes:
        now, old = [], []
        for _ in range(runs):  # alternate, so that drift hits both alike
            now.append(render_once(here, receivers, truth))
            if previous:
                old.append(render_once(previous, receivers, truth))
        rows.append((receivers, now, old))
    print("\nwhole renders (child processes; medians of", runs, "runs)")
    head = (
        "| --receivers | receivers | wall s | form factors s | solve s | refine s | shots "
        "| rays | peak MiB |"
    )
    if truth:
        head += " worst surface % | point RMS % |"
    if previous:
        head += " previous wall s | now / previous |"
        if truth:
            head += " previous worst % | previous RMS % |"
    print(head)
    print("|" + "---|" * (head.count("|") - 1))
    for receivers, now, old in rows:
        med = _medians(now)
        line = (
            f"| {receivers} | {med['receivers']:.0f} | {med['wall']:.1f} | "
            f"{med['form_factors']:.1f} | "
            f"{med['solve']:.1f} | {med['refine']:.1f} | {med['shots']:.0f} | {med['rays']:.3g} | "
            f"{med['peak_mib']:.0f} |"
        )
        if truth:
            line += f" {100 * med['worst']:.2f} | {100 * med['rms']:.2f} |"
        if old:
            ratio = np.median([a["wall"] / b["wall"] for a, b in zip(now, old, strict=True)])
            line += f" {_medians(old)['wall']:.1f} | {ratio:.3f} |"
            if truth:
                line += f" {100 * _medians(old)['worst']:.2f} | {100 * _medians(old)['rms']:.2f} |"
        print(line)
    if len(rows) >= 2:
        n = np.log([_medians(now)["receivers"] for _, now, _ in rows])
        t = np.log([_medians(now)["wall"] for _, now, _ in rows])
        print(f"total time grows as receivers^{np.polyfit(n, t, 1)[0]:.2f} over these sizes")
    if truth and previous:
        equal_accuracy_table(rows)


def _medians(runs: list[dict[str, float]]) -> dict[str, float]:
    return {k: float(np.median([r[k] for r in runs])) for k in runs[0]}


def equal_accuracy_table(rows: list) -> None:
    """For each size of the previous install, the fastest render of this one that is at
    least as accurate by both errors, and the ratio of their wall times."""
    print("\nat the previous install's accuracy (both errors no larger; medians)")
    print(
        "| previous --receivers | wall s | worst % | RMS % | now --receivers | wall s "
        "| worst % | RMS % | now / previous |"
    )
    print("|" + "---|" * 9)
    now = [(receivers, _medians(runs)) for receivers, runs, _ in rows]
    for receivers, _, old in rows:
        before = _medians(old)
        good = [
            (r, m) for r, m in now if m["worst"] <= before["worst"] and m["rms"] <= before["rms"]
        ]
        line = (
            f"| {receivers} | {before['wall']:.1f} | {100 * before['worst']:.2f} | "
            f"{100 * before['rms']:.2f} |"
        )
        if not good:
            print(line + " none as accurate | | | | |")
            continue
        r, m = min(good, key=lambda item: item[1]["wall"])
        print(
            line + f" {r} | {m['wall']:.1f} | {100 * m['worst']:.2f} | {100 * m['rms']:.2f} | "
            f"{m['wall'] / before['wall']:.2f} |"
        )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--receivers",
        type=int,
        nargs="+",
        default=[5000],
        help="--receivers targets: the pass tables use the first, the render table all",
    )
    parser.add_argument(
        "--scene", type=Path, default=SCENE, help="scene file [the bundled Cornell box]"
    )
    parser.add_argument("--previous", default=None, help="another install's raytrad executable")
    parser.add_argument("--runs", type=int, default=1, help="renders per size and install")
    parser.add_argument("--no-pass", action="store_true", help="skip the pass tables")
    parser.add_argument("--no-renders", action="store_true", help="skip the render table")
    parser.add_argument(
        "--no-numpy",
        action="store_true",
        help="leave the numpy kernels' pass and shot out of the pass tables (minutes on a "
        "scene of many thousand triangles)",
    )
    parser.add_argument(
        "--accuracy",
        action="store_true",
        help=(
            "score each render's PLY against bench_accuracy's path-traced reference "
            "(path-traced into .cache/accuracy on first use, about 4 minutes); with "
            "--previous, also the speed-up at equal accuracy"
        ),
    )
    args = parser.parse_args(argv)
    if args.accuracy and args.no_renders:
        parser.error("--accuracy scores the renders: it cannot go with --no-renders")
    if args.accuracy and args.scene.resolve() != SCENE.resolve():
        parser.error("--accuracy has a reference for the bundled Cornell box only")
    _CHOSEN["scene"] = args.scene.resolve()
    if not args.no_pass:
        pass_table(args.receivers[0], with_numpy=not args.no_numpy)
    if not args.no_renders:
        truth = Truth.cornell() if args.accuracy else None
        render_table(args.receivers, args.previous, args.runs, truth)
    return 0


if __name__ == "__main__":
    sys.exit(main())
