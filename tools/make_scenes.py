"""Write the bundled scene files under ``scenes/`` from the builders in :mod:`raytrad.scenes`.

Writes ``cornell-box.obj``/``.mtl``, ``furnace.obj``/``.mtl`` (reflectance 0.5, emitted
exitance 1 W m-2) and ``shadow.glb`` (glTF, so its double-sided occluder stays
double-sided). Run from the repository root: ``python tools/make_scenes.py``.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

log = logging.getLogger("make_scenes")

REPOSITORY = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    """Write the scene files; return the exit status."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--out", type=Path, default=REPOSITORY / "scenes", help="output directory [scenes/]"
    )
    args = parser.parse_args(argv)
    if str(REPOSITORY) not in sys.path:  # run from a checkout without installing raytrad
        sys.path.insert(0, str(REPOSITORY))
    from raytrad.scenes import cornell_box, furnace_box, shadow_scene, write_glb, write_obj

    out: Path = args.out
    write_obj(cornell_box(), out / "cornell-box.obj")
    write_obj(furnace_box(reflectance=0.5, emitted_exitance=1.0), out / "furnace.obj")
    write_glb(shadow_scene(), out / "shadow.glb")
    log.info("wrote cornell-box.obj/.mtl, furnace.obj/.mtl and shadow.glb to %s", out)
    return 0


if __name__ == "__main__":
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    sys.exit(main())
