"""Adaptive against uniform refinement in a block's penumbra and contact shadow.

Where light changes fast: a block on a floor under an area light, against the path
tracer.

The scene (metres, y up): a 3 x 3 m floor (reflectance 0.7), a 0.4 x 0.4 x 0.5 m block
standing on it, turned by 25 degrees (0.6), and a 0.6 x 0.6 m light 1.5 m up, 0.4 m to
the side (emitted exitance 20 W m-2, facing down). Open: no walls, so the light that
reaches the floor is mostly direct, and its shadow has a wide penumbra.

Points: 64 x 64 stratified on the floor and 16 x 16 on each block face, classified on the
floor by the share of the light they see (256 stratified light samples): *umbra* below
2 %, *penumbra* between, *lit* above 98 %; 8 points along each block side's foot at 2,
5, 10 and 20 mm from the contact line, on the floor and on the side (*contact*); and
stratified *foot* points within 5 cm of where the block meets the floor, on the floor
all round the footprint (its corners included) and on each side's bottom strip. The
foot points stand for their region's area in the area-weighted figure, in place of the
coarser grids' points there: at the block's corners the sides' shadow lines meet and the
light changes within millimetres, a sliver 64 x 64 points hardly ever hit, and without
them the area-weighted error of a uniform bake was half what the residual check found
(and what tracing the check's own points confirmed). Each class's error is the relative
RMS with the reference's noise taken out (its standard error squared subtracted from the
mean square difference, as in ``tools/bench_accuracy.py``); the penumbra's reference has
:data:`PENUMBRA_PATHS` times the paths, since its errors are below the noise of the
others'.

Each row bakes adaptively (raytrad's default refinement) at ``--receivers N`` and uniformly
(``--refine-threshold 0``) at a receiver target chosen so that the uniform mesh has at
least as many receivers as the adaptive bake ended with (uniform meshes come in steps, so
the uniform bake may have more); the last column is uniform / adaptive (issue 10's
target: at least 2 in the penumbra and at the contact line). Each bake's reported total
error (``error.total_rms``) is set against its true error over the area points, weighted
by the area each stands for.

    python tools/bench_penumbra.py --receivers 2000 5000
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tools"))

import bench_accuracy as acc  # noqa: E402

from raytrad.core.mesh import MeshSettings, build_mesh  # noqa: E402
from raytrad.core.pipeline import _enclosure_test  # noqa: E402
from raytrad.core.visibility import Occluder  # noqa: E402
from raytrad.products.probe import radiosity_at  # noqa: E402
from raytrad.scene import Scene  # noqa: E402
from raytrad.scene.builder import quads_scene  # noqa: E402

#: Block footprint half-side, height, turn [m, m, degrees]; light side, height, offset [m].
BLOCK = (0.2, 0.5, 25.0)
LIGHT = (0.6, 1.5, 0.4)
MATERIALS = {
    "floor": (0.7, 0.0, False),
    "block": (0.6, 0.0, False),
    "light": (0.0, 20.0, False),
}
#: Light-visibility share bounds of the penumbra.
PENUMBRA = (0.02, 0.98)
#: Reference paths of a penumbra point, as a multiple of ``--paths``.
PENUMBRA_PATHS = 8
#: Width of the *foot* region [m]: the floor within it of the block's footprint (corners
#: included) and the block's sides within it of the floor.
FOOT = 0.05
#: Foot points (:func:`bench_accuracy.foot_probes`): a side x side grid over the footprint
#: grown by FOOT (those outside the footprint kept), and along x up strata on each side's
#: bottom strip.
FOOT_GRID, FOOT_STRIP = 48, (32, 4)


def block_scene() -> Scene:
    """The benchmark's scene (see the module docstring): quads floor, light, block top and
    four sides, in that order."""
    half, height, turn = BLOCK
    c, s = math.cos(math.radians(turn)), math.sin(math.radians(turn))
    xz = np.array([[-half, -half], [half, -half], [half, half], [-half, half]]) @ [[c, s], [-s, c]]
    floor = [(-1.5, 0, -1.5), (1.5, 0, -1.5), (1.5, 0, 1.5), (-1.5, 0, 1.5)]
    side, y, dx = LIGHT
    h = side / 2
    light = [(dx - h, y, -h), (dx + h, y, -h), (dx + h, y, h), (dx - h, y, h)]
    top = [(x, height, z) for x, z in xz]
    sides = [
        [(a[0], 0.0, a[1]), (b[0], 0.0, b[1]), (b[0], height, b[1]), (a[0], height, a[1])]
        for a, b in zip(xz, np.roll(xz, -1, axis=0), strict=True)
    ]
    outward = [(*(0.5 * (a + b)),) for a, b in zip(xz, np.roll(xz, -1, axis=0), strict=True)]
    facing = [(0, 1, 0), (0, -1, 0), (0, 1, 0)] + [(o[0], 0, o[1]) for o in outward]
    quads = np.array([floor, light, top, *sides], dtype=np.float64)
    material = ["floor", "light"] + ["block"] * 5
    return quads_scene(quads, MATERIALS, material, np.array(facing, dtype=np.float64))


def probes(scene: Scene, rng: np.random.Generator) -> tuple[acc.Probes, np.ndarray, np.ndarray]:
    """The points, their class names (see the module docstring) and the area each stands
    for [m2]: a floor or block-face point its quad's area over the quad's point count,
    except in the foot region, whose area the foot points stand for instead, each its
    stratum's; contact points 0."""
    floor = acc.area_probes(scene, 64 * 64, rng)
    on_floor = floor.quad == 0
    block = acc.area_probes(scene, 16 * 16, rng)
    on_block = block.quad >= 2
    contact = acc.contact_probes(scene, 8, first_side=3)
    foot = acc.foot_probes(scene, [[3, 4, 5, 6]], FOOT, rng, FOOT_GRID, FOOT_STRIP)
    parts = (floor, block, contact, foot.probes)
    keep = (on_floor, on_block, np.ones(len(contact.points), bool), np.ones(len(foot.weight), bool))
    out = acc.Probes(
        *(
            np.concatenate([getattr(p, f)[k] for p, k in zip(parts, keep, strict=True)])
            for f in ("points", "normals", "quad", "contact")
        )
    )
    share = light_share(scene, out.points[: on_floor.sum()])
    floor_class = np.where(
        share < PENUMBRA[0], "umbra", np.where(share > PENUMBRA[1], "lit", "penumbra")
    )
    names = np.concatenate(
        [
            floor_class,
            np.full(on_block.sum(), "block"),
            np.full(len(contact.points), "contact"),
            np.full(len(foot.weight), "foot"),
        ]
    )
    area = acc.triangle_areas_normals(scene.triangle_vertices())[0]
    quad_area = area[0::2] + area[1::2]
    grid = (names != "contact") & (names != "foot")
    count = np.bincount(out.quad[grid], minlength=len(quad_area))
    weight = np.where(grid, quad_area[out.quad] / np.maximum(count[out.quad], 1), 0.0)
    weight[grid & foot.covers(out)] = 0.0
    weight[names == "foot"] = foot.weight
    return out, names, weight


def light_share(scene: Scene, points: np.ndarray, side: int = 16) -> np.ndarray:
    """(N,) share of the light each floor point sees, by ``side`` x ``side`` stratified
    samples over the light."""
    corners = acc.quad_corners(scene)[1]
    i, j = np.divmod(np.arange(side * side), side)
    rng = np.random.default_rng(5)
    u, v = (i + rng.random(side * side)) / side, (j + rng.random(side * side)) / side
    on_light = (
        corners[0] + u[:, None] * (corners[1] - corners[0]) + v[:, None] * (corners[3] - corners[0])
    )
    starts = np.repeat(points + 1e-6 * np.array([0, 1, 0]), len(on_light), axis=0)
    ends = np.tile(on_light, (len(points), 1))
    with Occluder(scene.positions, scene.triangles) as occluder:
        down = np.tile([0.0, -1.0, 0.0], (len(ends), 1))
        blocked = occluder.occluded(starts, ends, down).reshape(len(points), -1)
    return 1.0 - blocked.mean(axis=1)


def uniform_target(scene: Scene, receivers: int, ratio: float) -> tuple[int, int]:
    """A ``--receivers`` target whose unrefined mesh has at least ``receivers`` receivers,
    as few as a short search finds, and the receivers it gives.

    Uniform meshes come in steps (the floor is one quad, halved again and again), so the
    count is matched from above: the uniform bake never has fewer receivers than the
    adaptive one it is compared with.
    """
    tried: dict[int, int] = {}
    target = max(16, int(receivers / ratio))
    with Occluder(scene.positions, scene.triangles) as occluder:
        test = _enclosure_test(scene, occluder)
        for _ in range(8):
            if target in tried:
                break
            count = build_mesh(scene, MeshSettings(receivers=target), test).receiver_count
            tried[target] = count
            if receivers <= count < 1.03 * receivers:
                break
            step = receivers / count
            target = max(16, int(target * (min(step, 1.15) if step > 1 else max(step, 0.95))))
    enough = {t: c for t, c in tried.items() if c >= receivers}
    if not enough:
        best = max(tried, key=lambda t: tried[t])
        return best, tried[best]
    best = min(enough, key=lambda t: enough[t])
    return best, enough[best]


def reference(
    scene: Scene, points: acc.Probes, names: np.ndarray, paths: int, cache: Path
) -> tuple[np.ndarray, np.ndarray]:
    """The path-traced reference at ``points`` (see :func:`bench_accuracy.reference`),
    the foot points cached apart from the rest, and the penumbra's traced again with
    :data:`PENUMBRA_PATHS` times the paths: there the bakes' errors are a few tenths of a
    percent, below the noise of ``paths`` paths (0.4 % at 20 000), and taking out a noise
    larger than what is measured leaves too rough a figure to compare two bakes by."""
    ref, ref_error = np.zeros((len(names), 3)), np.zeros((len(names), 3))
    parts = (
        (names != "foot", paths, "block"),
        (names == "foot", paths, "block-foot"),
        (names == "penumbra", paths * PENUMBRA_PATHS, "block-penumbra"),
    )
    for part, traced, name in parts:
        subset = acc.Probes(
            points.points[part], points.normals[part], points.quad[part], points.contact[part]
        )
        ref[part], ref_error[part] = acc.reference(scene, subset, traced, cache, name)
    return ref, ref_error


def errors(
    got: np.ndarray,
    ref: np.ndarray,
    ref_error: np.ndarray,
    names: np.ndarray,
    weight: np.ndarray,
) -> dict:
    """Relative RMS per class, the reference's noise taken out (worst channel); and
    ``area-weighted``, over every area point weighted by the area it stands for, as
    raytrad's reported total error is measured."""
    ok = ~np.isnan(got).any(axis=1) & (ref.sum(axis=1) > 0)
    out = {"area-weighted": acc.denoised_rms(got, ref, ref_error, np.where(ok, weight, 0.0))}
    for name in ("lit", "penumbra", "umbra", "contact", "foot", "block"):
        out[name] = acc.denoised_rms(got, ref, ref_error, (ok & (names == name)).astype(float))
    out["all"] = acc.denoised_rms(
        got, ref, ref_error, (ok & (names != "contact") & (names != "foot")).astype(float)
    )
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--receivers", type=int, nargs="+", default=[2000, 5000], help="targets to bake at"
    )
    parser.add_argument("--paths", type=int, default=20000, help="reference paths a point")
    parser.add_argument(
        "--cache", type=Path, default=ROOT / ".cache" / "accuracy", help="reference cache"
    )
    args = parser.parse_args(argv)
    scene = block_scene()
    points, names, weight = probes(scene, np.random.default_rng(11))
    print("points:", ", ".join(f"{n} {int((names == n).sum())}" for n in np.unique(names)))
    ref, ref_error = reference(scene, points, names, args.paths, args.cache)
    for receivers in args.receivers:
        start = time.perf_counter()
        adaptive = acc.bake(scene, receivers)
        ratio = adaptive.solved / receivers
        target, _ = uniform_target(scene, adaptive.mesh.receiver_count, ratio)
        uniform = acc.bake(scene, target, threshold=0.0)
        rows = {}
        for label, baked in (("adaptive", adaptive), ("uniform", uniform)):
            got = radiosity_at(baked.mesh, baked.shown, points.points, points.normals)
            rows[label] = errors(got, ref, ref_error, names, weight)
        print(
            f"\n--receivers {receivers}: adaptive {adaptive.solved} solved -> "
            f"{adaptive.mesh.receiver_count} baked ({adaptive.seconds:.1f} s); uniform "
            f"--receivers {target}: {uniform.mesh.receiver_count} ({uniform.seconds:.1f} s); "
            f"{time.perf_counter() - start:.0f} s"
        )
        print("| points | uniform | adaptive | uniform / adaptive |\n|---|---|---|---|")
        for name in rows["adaptive"]:
            a, u = rows["adaptive"][name], rows["uniform"][name]
            print(f"| {name} | {100 * u:.2f} % | {100 * a:.2f} % | {u / max(a, 1e-12):.2f} |")
        for label, baked in (("adaptive", adaptive), ("uniform", uniform)):
            true = rows[label]["area-weighted"]
            print(
                f"{label}: reported total error {100 * baked.total_rms.max():.2f} % against "
                f"the true {100 * true:.2f} % (area-weighted): "
                f"{baked.total_rms.max() / max(true, 1e-12):.2f} times"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
