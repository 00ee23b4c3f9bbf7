"""Writing the files a render asks for: the radiosity PLY, lightmaps, the camera image and
the baked model, all from one solve and one exposure.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np

from raytrad.constants import FLOAT32_MAX, defaults
from raytrad.core.hidden import fill_hidden
from raytrad.core.pipeline import Prepared
from raytrad.core.solver import SolveResult
from raytrad.errors import SolverError
from raytrad.formats.images import write_exr, write_png
from raytrad.formats.ply import write_radiosity_ply
from raytrad.outputs.gltf import baked_parts, write_baked_glb
from raytrad.outputs.lightmaps import write_lightmaps
from raytrad.outputs.run_manifest import invalidate
from raytrad.products.display import auto_exposure, display_colors, display_encode
from raytrad.products.framing import image_view
from raytrad.products.image import render_radiance, seen_receivers
from raytrad.products.lightmap import Lightmap, bake_lightmaps
from raytrad.scene import NamedCamera
from raytrad.settings import ImageSettings, RenderSettings


def write_outputs(
    prepared: Prepared,
    result: SolveResult,
    output_dir: Path,
    stem: str,
    settings: RenderSettings,
    camera: NamedCamera | None = None,
) -> tuple[dict[str, Path], dict[str, Any]]:
    """Write every asked-for output; return their paths and facts for the report.

    Parameters
    ----------
    prepared : Prepared
    result : SolveResult
    output_dir : Path
    stem : str
        File names start with it (``<stem>.ply``...).
    settings : RenderSettings
        Resolved (:func:`raytrad.settings.with_scene_defaults`).
    camera : NamedCamera or None
        The scene file's camera for ``--image``, if it has one.

    Returns
    -------
    outputs : dict of str to Path
        Each written file by key (``ply``, ``lightmap``, ``image``, ``gltf``...).
    facts : dict
        The exposure, lightmap statistics and camera, for ``report.json``.
    """
    invalidate(output_dir)  # the folder's set is not complete until the manifest is back
    mesh = prepared.mesh
    emitting = np.asarray((mesh.receiver_emitted_exitance > 0).any(axis=1))
    # hidden receivers take their visible neighbours' radiosity in what is shown
    shown = fill_hidden(mesh, result.radiosity)
    area = mesh.receiver_area
    stops = settings.exposure or 0.0
    exposure = auto_exposure(shown, emitting, area) * 2.0**stops
    colors = display_colors(shown, emitting, stops, area)
    outputs = {"ply": output_dir / f"{stem}.ply"}
    facts: dict[str, Any] = {"exposure": exposure}
    write_radiosity_ply(
        outputs["ply"], mesh.receiver_position, mesh.triangle_receivers, result.radiosity, colors
    )
    metadata = {"scene": str(prepared.scene.source or stem), "method": result.method}
    lightmaps: list[Lightmap] = []
    previews: list[Path] = []
    if settings.lightmap is not None:
        lightmaps = bake_lightmaps(prepared.scene, mesh, shown, settings.lightmap)
        previews = write_lightmaps(lightmaps, output_dir, stem, metadata, exposure, outputs, facts)
    if settings.image is not None:
        exposures = (emitting, stops)
        facts["camera"] = _write_image(
            prepared, shown, settings.image, camera, exposures, metadata, output_dir / stem, outputs
        )
    if settings.gltf:
        outputs["gltf"] = output_dir / f"{stem}.glb"
        pngs = [preview.read_bytes() for preview in previews]  # the PNGs just written
        parts = baked_parts(prepared.scene, mesh, shown, exposure, lightmaps, pngs)
        write_baked_glb(outputs["gltf"], parts, exposure)
    return outputs, facts


def _write_image(
    prepared: Prepared,
    radiosity: np.ndarray,
    image: ImageSettings,
    camera: NamedCamera | None,
    exposures: tuple[np.ndarray, float],
    metadata: dict[str, str],
    base: Path,
    outputs: dict[str, Path],
) -> dict[str, Any]:
    """Render and write ``<base>.exr`` (linear radiance) and ``<base>.png``; the camera
    and the PNG's exposure, set by what the camera sees (:func:`auto_exposure` over the
    receivers in view, weighted by how much of the frame they fill) plus ``--exposure``
    stops; ``exposures`` is (emitting receivers, stops)."""
    height = image.height or defaults.image_height
    view, width, origin = image_view(
        prepared.mesh, image.camera, camera, image.width, height, radiosity, image.up
    )
    radiance = render_radiance(prepared.mesh, radiosity, view, width, height, image.samples)
    emitting, stops = exposures
    exposure = auto_exposure(radiosity, emitting, seen_receivers(prepared.mesh, view)) * 2.0**stops
    outputs["image"] = base.with_name(base.name + ".exr")
    outputs["image_preview"] = base.with_name(base.name + ".png")
    write_exr(
        outputs["image"],
        radiance,
        half=False,
        metadata={
            "raytrad:units": "W sr-1 m-2",
            "raytrad:quantity": "radiance",
            **{f"raytrad:{k}": v for k, v in metadata.items()},
        },
    )
    write_png(outputs["image_preview"], display_encode(radiance * exposure, image.tonemap))
    return {**dataclasses.asdict(view), "name": origin, "exposure": exposure}


def check_output_range(radiosity: np.ndarray, scene_path: Path) -> None:
    """Refuse, before anything is written, a radiosity the float32 outputs cannot hold."""
    peak = float(np.abs(radiosity).max(initial=0.0))
    if not peak < FLOAT32_MAX / 1e3:
        raise SolverError(
            f"{scene_path}: radiosity reaches {peak:.3g} W m-2, beyond the float32 range of "
            "the outputs (lower the emission or use --scale)"
        )
