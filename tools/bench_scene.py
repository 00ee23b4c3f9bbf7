"""Accuracy of a raytrad bake of any scene against the path tracer, object by object.

``tools/bench_accuracy.py`` knows the Cornell box's quads and contact lines; this one takes
any scene file (``--scene``) or, by default, a furnished room none of raytrad's tests or
tunings saw: a 3 x 2.6 x 3.2 m room (one red wall), a table on four thin legs, a shelf
against the back wall, a crate sunk 3 cm into the floor, a cabinet against the side wall
and a ceiling lamp hanging 0.5 mm below the ceiling.

Points: stratified on every scene triangle in proportion to its area (``--points`` in all,
at least 4 a triangle), emitters and points no one sees (shut in) left out; each stands
for its triangle's area over its triangle's point count. The reference is raytrad's path
tracer (:mod:`raytrad.core.pathtrace`) at ``--paths`` paths a point, cached. Prints, for
each ``--receivers``: every object's mean relative error (worst channel), the
area-weighted point RMS with the reference's noise taken out, the share of points off by
more than 10 %, and the reported total error (``error.total_rms``) against that RMS.

    python tools/bench_scene.py --receivers 3000 10000
    python tools/bench_scene.py --scene scenes/colour-room.toml --receivers 5000
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tools"))

import bench_accuracy as acc  # noqa: E402

from raytrad.products.probe import radiosity_at  # noqa: E402
from raytrad.scene import Scene, triangle_areas_normals  # noqa: E402
from raytrad.scene.builder import SceneBuilder, rectangle  # noqa: E402


def furnished_room() -> Scene:
    """The default scene (see the module docstring), in metres, y up."""
    b = SceneBuilder()
    b.material("wall", 0.7)
    b.material("red", (0.6, 0.12, 0.1))
    b.material("floor", (0.45, 0.35, 0.25))
    b.material("wood", (0.5, 0.4, 0.3))
    b.material("crate", 0.6)
    b.material("lamp", 0.0, 40.0)
    b.room("wall", (3.0, 2.6, 3.2), face_material={"x-": "red", "y-": "floor"}, obj="room")
    b.block("wood", (1.0, 0.70, 1.2), (2.1, 0.74, 1.9), bottom=True, obj="table")
    for x in (1.03, 2.03):
        for z in (1.23, 1.83):
            b.block("wood", (x, 0.0, z), (x + 0.04, 0.70, z + 0.04), obj="table")
    b.block("wood", (0.6, 1.3, 2.95), (1.8, 1.33, 3.2), bottom=True, obj="shelf")
    b.block("crate", (2.2, -0.03, 0.4), (2.7, 0.42, 0.85), obj="crate")
    b.block("wood", (2.55, 0.0, 1.9), (3.0, 0.9, 2.6), obj="cabinet")
    b.quad(rectangle(1, 2.6 - 5e-4, (1.2, 1.3), (1.8, 1.9)), "lamp", (0, -1, 0), obj="lamp")
    return b.build("furnished room")


def triangle_probes(scene: Scene, total: int, rng: np.random.Generator) -> acc.Probes:
    """Stratified points on every triangle, about ``total`` in all in proportion to area
    (a ``side`` x ``side`` grid each, side at least 2), by Shirley's area-preserving
    square-to-triangle map. ``quad`` holds each point's triangle."""
    corners = scene.triangle_vertices()
    area, normal = triangle_areas_normals(corners)
    side = np.maximum(2, np.round(np.sqrt(total * area / area.sum()))).astype(int)
    count = side**2
    tri = np.repeat(np.arange(len(area)), count)
    cell = np.arange(len(tri)) - np.repeat(np.cumsum(count) - count, count)
    s = (cell // side[tri] + rng.random(len(tri))) / side[tri]
    t = (cell % side[tri] + rng.random(len(tri))) / side[tri]
    points = acc.on_triangles(corners[tri], s, t)
    return acc.Probes(points, normal[tri], tri, np.full(len(tri), np.inf))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--scene", type=Path, default=None, help="a scene file (default: the room)")
    parser.add_argument(
        "--receivers", type=int, nargs="+", default=[3000, 10000], help="targets to bake at"
    )
    parser.add_argument("--points", type=int, default=6000, help="reference points, about")
    parser.add_argument("--paths", type=int, default=10000, help="reference paths a point")
    parser.add_argument(
        "--cache", type=Path, default=ROOT / ".cache" / "accuracy", help="reference cache"
    )
    args = parser.parse_args(argv)
    if args.scene is None:
        scene, name = furnished_room(), "room"
    else:
        from raytrad import api

        scene, name = api.load(args.scene).scene, args.scene.stem
    probes = triangle_probes(scene, args.points, np.random.default_rng(13))
    emitter = (scene.material_emitted_exitance[scene.material_index] > 0).any(axis=1)
    ref, ref_error = acc.reference(scene, probes, args.paths, args.cache, name, probes.quad)
    shut = acc.shut_in(scene, probes)
    area = triangle_areas_normals(scene.triangle_vertices())[0]
    count = np.bincount(probes.quad, minlength=len(area))
    weight = area[probes.quad] / count[probes.quad]
    counted = ~emitter[probes.quad] & ~shut & (ref.sum(axis=1) > 0)
    print(
        f"{name}: {counted.sum()} of {len(probes.points)} points counted (emitters and points "
        "no one sees left out)"
    )
    for receivers in args.receivers:
        baked = acc.bake(scene, receivers)
        got = radiosity_at(baked.mesh, baked.shown, probes.points, probes.normals)
        ok = counted & ~np.isnan(got).any(axis=1)
        w = np.where(ok, weight, 0.0)
        true = acc.denoised_rms(got, ref, ref_error, w)
        lit = ref > 1e-3 * ref.max(axis=0)
        rel = np.where(lit, np.where(ok[:, None], got, 0.0) / np.where(lit, ref, 1) - 1, 0.0)
        off = float(w @ (np.abs(rel) > 0.1).any(axis=1) / w.sum())
        print(
            f"\n--receivers {receivers}: {baked.solved} solved -> {baked.mesh.receiver_count} "
            f"baked, {baked.seconds:.1f} s"
        )
        obj = scene.object_index[probes.quad]
        for o, oname in enumerate(scene.object_names):
            rows = ok & (obj == o)
            if not rows.any():
                continue
            mean = (w[rows] @ got[rows]) / (w[rows] @ ref[rows]) - 1
            print(f"  {oname:10s} mean {100 * np.abs(mean).max():5.2f} %  ({rows.sum()} points)")
        total = float(baked.total_rms.max())
        print(f"  point RMS, reference noise removed {100 * true:.2f} %; > 10 %: {100 * off:.2f} %")
        print(
            f"  reported total {100 * total:.2f} % = {total / max(true, 1e-12):.2f} x the true "
            f"(algebraic {100 * baked.parts.algebraic.max():.2f} %, discretisation "
            f"{100 * baked.parts.discretisation.max():.2f} %)"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
