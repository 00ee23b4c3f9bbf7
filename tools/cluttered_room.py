"""Write a cluttered room, a benchmark scene of many objects of several kinds for the
form-factor pass (``docs/performance.md``; ``tools/bench_scene.py`` has the furnished room
of the accuracy checks): a 6 x 3 x 5 m room lit by a 1.2 m ceiling panel, two tables
with two chairs each, two shelves, a torus, three cylinders and two balls; 11 662
triangles.

Each table, chair and shelf is one mesh of boxes (top, legs, boards) that do not share
vertices, so the convex blockers see each box; a table's legs stop 5 mm under its top, a
gap narrower than the receivers are spaced (the short columns of balancing). The torus
is not convex, the balls have more faces than a blocker takes.

    python tools/cluttered_room.py OUT.obj     # writes OUT.obj and OUT.mtl
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import trimesh

MATERIALS = """newmtl wall
Kd 0.6 0.6 0.6
Ke 0 0 0
newmtl wood
Kd 0.5 0.4 0.3
Ke 0 0 0
newmtl red
Kd 0.6 0.1 0.1
Ke 0 0 0
newmtl blue
Kd 0.1 0.2 0.6
Ke 0 0 0
newmtl light
Kd 0 0 0
Ke 20 20 20
"""


def _box(extents: tuple[float, float, float], at: tuple[float, float, float]) -> trimesh.Trimesh:
    box = trimesh.creation.box(extents=extents)
    box.apply_translation(at)
    return box


def _table(x: float, z: float) -> trimesh.Trimesh:
    legs = [
        _box((0.05, 0.72, 0.05), (x + sx * 0.55, 0.36, z + sz * 0.35))
        for sx in (-1, 1)
        for sz in (-1, 1)
    ]
    return trimesh.util.concatenate([_box((1.2, 0.05, 0.8), (x, 0.75, z)), *legs])


def _chair(x: float, z: float, angle: float) -> trimesh.Trimesh:
    parts = [_box((0.45, 0.04, 0.45), (0, 0.45, 0)), _box((0.45, 0.5, 0.04), (0, 0.72, -0.21))]
    parts += [
        _box((0.04, 0.43, 0.04), (sx * 0.2, 0.215, sz * 0.2)) for sx in (-1, 1) for sz in (-1, 1)
    ]
    chair = trimesh.util.concatenate(parts)
    chair.apply_transform(trimesh.transformations.rotation_matrix(angle, (0, 1, 0)))
    chair.apply_translation((x, 0, z))
    return chair


def _shelf(x: float, z: float) -> trimesh.Trimesh:
    sides = [_box((0.03, 1.8, 0.35), (x + sx * 0.5, 0.9, z)) for sx in (-1, 1)]
    boards = [_box((1.0, 0.03, 0.35), (x, h, z)) for h in (0.05, 0.5, 0.95, 1.4, 1.78)]
    return trimesh.util.concatenate([*sides, *boards])


def cluttered_room() -> list[tuple[trimesh.Trimesh, str]]:
    """(mesh, material) pairs of the room, counter-clockwise from the lit side."""
    width, height, depth = 6.0, 3.0, 5.0
    room = trimesh.creation.box(extents=(width, height, depth))
    room.apply_translation((0, height / 2, 0))
    room.invert()  # lit inside
    y = height - 1e-3
    panel = [[-0.6, y, -0.6], [0.6, y, -0.6], [0.6, y, 0.6], [-0.6, y, 0.6]]
    parts = [(room, "wall"), (trimesh.Trimesh(panel, [[0, 1, 2], [0, 2, 3]]), "light")]
    for x, z in ((-1.5, -1.0), (1.5, 1.0)):
        parts.append((_table(x, z), "wood"))
        parts += [(_chair(x, z + dz, a), "wood") for dz, a in ((-0.6, 0.0), (0.6, np.pi))]
    parts += [(_shelf(-2.4, 2.2), "wood"), (_shelf(2.2, -2.3), "wood")]
    torus = trimesh.creation.torus(
        major_radius=0.3, minor_radius=0.1, major_sections=64, minor_sections=32
    )
    torus.apply_translation((-1.5, 0.9, -1.0))
    parts.append((torus, "red"))
    for j in range(3):
        can = trimesh.creation.cylinder(radius=0.08, height=0.3, sections=48)
        can.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, (1, 0, 0)))
        can.apply_translation((1.2 + 0.3 * j, 0.925, 1.0))
        parts.append((can, "blue"))
    for subdivisions, radius, at, material in (
        (4, 0.35, (0.5, 0.35, -1.5), "red"),
        (3, 0.12, (-2.4, 0.62, 2.2), "blue"),
    ):
        ball = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
        ball.apply_translation(at)
        parts.append((ball, material))
    return parts


def write(path: Path) -> int:
    """Write ``path`` (.obj) and its .mtl beside it; return the triangle count."""
    path.with_suffix(".mtl").write_text(MATERIALS)
    lines, base, count = [f"mtllib {path.with_suffix('.mtl').name}"], 1, 0
    for k, (mesh, material) in enumerate(cluttered_room()):
        lines += [f"o part{k}", f"usemtl {material}"]
        lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in mesh.vertices]
        lines += [f"f {a} {b} {c}" for a, b, c in mesh.faces + base]
        base += len(mesh.vertices)
        count += len(mesh.faces)
    path.write_text("\n".join(lines) + "\n")
    return count


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("out", type=Path, help="the .obj to write (its .mtl goes beside it)")
    args = parser.parse_args(argv)
    print(f"wrote {args.out}: {write(args.out)} triangles")
    return 0


if __name__ == "__main__":
    sys.exit(main())
