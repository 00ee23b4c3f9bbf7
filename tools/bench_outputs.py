"""Benchmark of the outputs of a solve: lightmap bakes and camera renders.

The Cornell box with authored lightmap UVs (``scenes/cornell-box-uv.glb``) is solved once;
then, each timed on its own:

* lightmap bakes at a few atlas sizes, with a generated (xatlas) atlas and with the
  model's ``TEXCOORD_1``, reported as texels per second;
* camera renders at a few sizes, as primary rays per second, next to the raw embreex
  closest-hit throughput on the same rays (the baseline, measured in the same run: the
  render's own rays replayed through Embree alone, no shading);
* the automatic camera choice.

    python tools/bench_outputs.py
    python tools/bench_outputs.py --receivers 5000 --sizes 256,1024
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from raytrad import api
from raytrad.core.mesh import MeshSettings
from raytrad.core.visibility import Occluder
from raytrad.products.framing import automatic_camera
from raytrad.products.image import primary_directions, render_radiance
from raytrad.products.lightmap import LightmapSettings, bake_lightmap
from raytrad.scene import Camera
from raytrad.scenefiles import load_scene, read_gltf_cameras
from raytrad.settings import RenderSettings

ROOT = Path(__file__).resolve().parent.parent
SCENE = ROOT / "scenes" / "cornell-box-uv.glb"
T = TypeVar("T")


def _timed(function: Callable[..., T], *args: Any) -> tuple[T, float]:
    """The function's value and its wall time [s]."""
    start = time.perf_counter()
    value = function(*args)
    return value, time.perf_counter() - start


def _raw_embree(prepared: api.Prepared, camera: Camera, width: int, height: int) -> float:
    """Seconds for Embree alone to trace one sample per pixel of the render's rays."""
    mesh = prepared.mesh
    occluder = Occluder(mesh.positions, mesh.triangles)
    try:
        origin = occluder.to_local(np.asarray(camera.position, dtype=np.float64)[None, :])
        direction = primary_directions(camera, width, height, 0.5, 0.5)
        origins = np.broadcast_to(origin, direction.shape)
        _, seconds = _timed(occluder.intersect_barycentric_local, origins, direction)
    finally:
        occluder.close()
    return seconds


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--receivers", type=int, default=20000)
    parser.add_argument("--sizes", default="512,1024,2048", help="lightmap sides [texels]")
    parser.add_argument(
        "--images", default="320x240,640x480,1280x720", help="image sizes WIDTHxHEIGHT"
    )
    parser.add_argument("--spp", type=int, default=4)
    args = parser.parse_args(argv)

    scene = load_scene(SCENE, uv_set=1)
    settings = RenderSettings(mesh=MeshSettings(receivers=args.receivers))
    (prepared, result), solve_seconds = _timed(api.solve_scene, scene, settings)
    mesh = prepared.mesh
    print(
        f"scene {SCENE.name}: {mesh.receiver_count} receivers, {len(mesh.triangles)} "
        f"triangles; solve (form factors + shots) {solve_seconds:.1f} s\n"
    )

    print("lightmap bake          side  texels/s   seconds  covered  overlap")
    corners = prepared.scene.triangle_vertices()
    for side in (int(s) for s in args.sizes.split(",")):
        for label, uv in (
            ("generated atlas", None),
            ("model TEXCOORD_1", prepared.scene.lightmap_uv),
        ):
            lightmap_settings = LightmapSettings(resolution=side)
            lightmap, seconds = _timed(
                bake_lightmap,
                mesh,
                result.radiosity,
                lightmap_settings,
                uv,
                None if uv is None else corners,
            )
            stats = lightmap.stats
            print(
                f"{label:<18} {side:>8} {side * side / seconds:9.3g} {seconds:9.2f} "
                f"{stats['covered_fraction']:8.2f} {stats['overlap_fraction']:8.4f}"
            )

    camera = read_gltf_cameras(SCENE)[0].camera
    print("\nimage          spp  rays/s   embree rays/s  ratio  seconds")
    for size in args.images.split(","):
        width, height = (int(v) for v in size.split("x"))
        _, seconds = _timed(
            render_radiance, mesh, result.radiosity, camera, width, height, args.spp
        )
        side = max(1, int(args.spp**0.5))
        rays = width * height * side * side
        raw = _raw_embree(prepared, camera, width, height) * side * side
        print(
            f"{size:<12} {side * side:>5} {rays / seconds:9.3g} {rays / raw:14.3g} "
            f"{raw / seconds:6.2f} {seconds:8.2f}"
        )

    _, seconds = _timed(automatic_camera, mesh)
    print(f"\nautomatic camera choice (16 candidate views, 48 x 36 probes): {seconds:.2f} s")
    prepared.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
