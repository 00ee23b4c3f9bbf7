"""Batch baking against the plain way: the bundled scenes rendered one after another with
``raytrad render`` (a shell loop), then as one ``raytrad bake`` manifest on the local pool
and on a Dask LocalCluster, and the manifest again with every job up to date (skipped).

Every row is a whole command timed in the same run, so the ratios hold on a noisy machine.

    python tools/bench_bake.py [--receivers 5000] [--repeat 1]
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPOSITORY = Path(__file__).resolve().parents[1]
SCENES = ("cornell-box.obj", "shadow.glb", "furnace.obj", "colour-room.toml")


def _run(argv: list[str]) -> float:
    start = time.perf_counter()
    done = subprocess.run(argv, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(argv)} failed ({done.returncode}):\n{done.stderr}")
    return seconds


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--receivers", type=int, default=5000)
    parser.add_argument("--repeat", type=int, default=1, help="timed runs of each row")
    args = parser.parse_args()
    raytrad = [sys.executable, "-m", "raytrad"]
    work = Path(tempfile.mkdtemp(prefix="bench-bake-"))
    try:
        for name in SCENES:
            shutil.copy(REPOSITORY / "scenes" / name, work / name)
        for extra in ("cornell-box.mtl", "furnace.mtl"):
            shutil.copy(REPOSITORY / "scenes" / extra, work / extra)
        manifest = work / "bake.toml"
        manifest.write_text(
            f"[defaults]\nreceivers = {args.receivers}\n"
            + "".join(
                f'[[job]]\nscene = "{name}"\noutput = "out/{Path(name).stem}"\n' for name in SCENES
            )
        )
        rows: list[tuple[str, list[float]]] = []

        def sequential() -> float:
            total = 0.0
            for name in SCENES:
                out = work / "seq" / Path(name).stem
                total += _run(
                    [
                        *raytrad,
                        "render",
                        str(work / name),
                        "-o",
                        str(out),
                        "-q",
                        "--receivers",
                        str(args.receivers),
                    ]
                )
            return total

        def bake(*options: str, fresh: bool = True) -> float:
            if fresh:
                shutil.rmtree(work / "out", ignore_errors=True)
            return _run([*raytrad, "bake", str(manifest), "-q", *options])

        plans = [
            ("raytrad render, one scene after another", sequential),
            ("raytrad bake, local pool (default)", bake),
        ]
        if importlib.util.find_spec("distributed") is not None:
            plans.append(("raytrad bake --local-cluster 2", lambda: bake("--local-cluster", "2")))
        plans.append(("raytrad bake again, every job up to date", lambda: bake(fresh=False)))
        for label, plan in plans:
            rows.append((label, [plan() for _ in range(args.repeat)]))
    finally:
        shutil.rmtree(work, ignore_errors=True)

    base = min(rows[0][1])
    print(
        f"{len(SCENES)} scenes at --receivers {args.receivers}, {os.cpu_count()} cores, "
        f"best of {args.repeat}\n"
    )
    print("| command | seconds | vs one after another |")
    print("|---|---|---|")
    for label, seconds in rows:
        best = min(seconds)
        print(f"| {label} | {best:.1f} | {best / base:.2f} |")


if __name__ == "__main__":
    main()
