"""Benchmark of the solver methods: ``raytrad compare`` on the bundled scenes.

For the Cornell box, the furnace at reflectance 0.9 and the open shadow scene, every method
runs on the same receivers through one shared form-factor pass, whose seconds count in
each method's times; the table gives seconds and
shots to 1e-2 and 1e-3 true error (relative RMS against a dense solve of the same system),
and the ratio of ambient's shots to 1e-3 to plain progressive refinement's, measured in
the same run.

    python tools/bench_compare.py [--receivers 5000] [--out bench-compare]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from raytrad import api
from raytrad.scene.builtin import cornell_box, furnace_box, shadow_scene
from raytrad.scenefiles import write_glb, write_obj
from raytrad.settings import MeshSettings, RenderSettings, SolveSettings, method_summaries


def scene_files(directory: Path) -> dict[str, Path]:
    """Write the benchmark scenes (the furnace at reflectance 0.9) and return their paths."""
    files = {
        "cornell-box": directory / "cornell-box.obj",
        "furnace-0.9": directory / "furnace-0.9.obj",
        "shadow": directory / "shadow.glb",
    }
    write_obj(cornell_box(), files["cornell-box"])
    write_obj(furnace_box(reflectance=0.9, emitted_exitance=1.0), files["furnace-0.9"])
    write_glb(shadow_scene(), files["shadow"])
    return files


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--receivers", type=int, default=5000)
    parser.add_argument("--patches", type=int, default=400)
    parser.add_argument("--tolerance", type=float, default=1e-5)
    parser.add_argument("--out", type=Path, default=Path("bench-compare"))
    args = parser.parse_args(argv)
    settings = RenderSettings(
        mesh=MeshSettings(receivers=args.receivers, patches=args.patches),
        solve=SolveSettings(tolerance=args.tolerance),
    )
    with tempfile.TemporaryDirectory() as tmp:
        for name, path in scene_files(Path(tmp)).items():
            summary = api.compare(path, args.out / name, list(method_summaries()), settings)
            rows = {row["method"]: row for row in summary["table"]}
            print(
                f"\n## {name}: {summary['receivers']} receivers, {summary['patches']} "
                f"patches, reference {summary['reference']['kind']}\n"
            )
            print(api.comparison_table(summary), end="")
            ambient = rows["ambient"]["shots_to_0.001"]
            progressive = rows["progressive"]["shots_to_0.001"]
            if ambient and progressive:
                print(f"\nambient / progressive shots to 1e-3: {ambient / progressive:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
