"""Write the bundled scene files under ``scenes/`` from the builders in
:mod:`raytrad.scene.builtin`.

Writes ``cornell-box.obj``/``.mtl``, ``furnace.obj``/``.mtl`` (reflectance 0.5, emitted
exitance 1 W m-2), ``blocks-room.obj``/``.mtl`` (36 blocks on a room's floor: many
objects), ``ball-box.obj``/``.mtl`` (the Cornell box with a ball of 1 280 triangles: a
curved object), ``shadow.glb`` (glTF, so its double-sided occluder stays
double-sided) and ``cornell-box-uv.glb``: the Cornell box as a game asset would come, one
node per object, authored lightmap UVs in ``TEXCOORD_1`` (an xatlas layout for a 256 x 256
lightmap) and two cameras, ``front`` (the Cornell box camera) and ``corner`` (16:9).
Run from the repository root: ``python tools/make_scenes.py``.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path
from typing import Any

log = logging.getLogger("make_scenes")

REPOSITORY = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    """Write the scene files; return the exit status."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--out", type=Path, default=REPOSITORY / "scenes", help="output directory [scenes/]"
    )
    args = parser.parse_args(argv)
    if str(REPOSITORY) not in sys.path:  # run from a checkout without installing raytrad
        sys.path.insert(0, str(REPOSITORY))
    from raytrad.scene.builtin import (
        ball_box,
        blocks_room,
        cornell_box,
        furnace_box,
        shadow_scene,
    )
    from raytrad.scenefiles import write_glb, write_obj

    out: Path = args.out
    write_obj(cornell_box(), out / "cornell-box.obj")
    write_obj(furnace_box(reflectance=0.5, emitted_exitance=1.0), out / "furnace.obj")
    write_glb(shadow_scene(), out / "shadow.glb")
    write_obj(blocks_room(), out / "blocks-room.obj")
    write_obj(ball_box(), out / "ball-box.obj")
    lightmapped, cameras = _lightmapped_cornell_box()
    write_glb(lightmapped, out / "cornell-box-uv.glb", cameras)
    log.info(
        "wrote cornell-box.obj/.mtl, furnace.obj/.mtl, shadow.glb, cornell-box-uv.glb, "
        "blocks-room.obj/.mtl and ball-box.obj/.mtl to %s",
        out,
    )
    return 0


def _lightmapped_cornell_box() -> tuple[Any, list[Any]]:
    """The Cornell box with authored lightmap UVs and two named cameras."""
    import dataclasses

    from raytrad.products.atlas import generate_atlas
    from raytrad.scene import Camera, NamedCamera
    from raytrad.scene.builtin import CORNELL_CAMERA, cornell_box

    scene = cornell_box()
    _, triangles, uv, _ = generate_atlas(scene.positions, scene.triangles, 256, padding=4)
    scene = dataclasses.replace(scene, lightmap_uv=uv[triangles])
    corner = Camera((0.5, 0.45, 0.05), (0.1, 0.1, 0.5), vertical_fov_deg=50.0)
    return scene, [NamedCamera("front", CORNELL_CAMERA, 1.0), NamedCamera("corner", corner, 16 / 9)]


if __name__ == "__main__":
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    sys.exit(main())
