"""Writing lightmaps: the EXR (radiosity, half or float, with metadata) and a preview PNG,
one per scene (``<stem>.lightmap.exr``) or one per mesh (``<stem>.<mesh>.lightmap.exr``).
"""

from __future__ import annotations

import dataclasses
import os
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from raytrad import __version__
from raytrad.formats.images import write_exr, write_png
from raytrad.products.lightmap import Lightmap, lightmap_preview


def lightmap_metadata(
    lightmap: Lightmap, metadata: Mapping[str, str | float] | None = None
) -> dict[str, str | float]:
    """EXR header attributes of a lightmap: units, convention, settings, statistics.

    Keys without a namespace get ``raytrad:`` (``scene`` -> ``raytrad:scene``).
    """
    attributes: dict[str, str | float] = {
        "raytrad:version": __version__,
        "raytrad:quantity": "radiosity",
        "raytrad:units": "W m-2",
        "raytrad:uv_origin": "top-left",
    }
    for name, value in dataclasses.asdict(lightmap.settings).items():
        attributes[f"raytrad:lightmap_{name}"] = "none" if value is None else value
    attributes.update({f"raytrad:{k}": v for k, v in lightmap.stats.items()})
    for name, value in (metadata or {}).items():
        attributes[name if ":" in name else f"raytrad:{name}"] = value
    return attributes


def write_lightmap(
    path: str | os.PathLike[str],
    lightmap: Lightmap,
    metadata: Mapping[str, str | float] | None = None,
) -> None:
    """Write the lightmap as an OpenEXR file (half or float per its settings), atomically.

    Parameters
    ----------
    path : path-like
        Target ``.exr`` file.
    lightmap : Lightmap
    metadata : mapping of str to str or float
        Extra header attributes (scene, solve settings...); see :func:`lightmap_metadata`.
    """
    write_exr(
        path,
        lightmap.pixels,
        half=lightmap.settings.half,
        metadata=lightmap_metadata(lightmap, metadata),
    )


def write_lightmap_preview(
    path: str | os.PathLike[str], lightmap: Lightmap, exposure: float, gutter: float = 1.0
) -> None:
    """Write :func:`~raytrad.products.lightmap.lightmap_preview` as a PNG, atomically."""
    write_png(path, lightmap_preview(lightmap, exposure, gutter))


def file_names(names: list[str]) -> list[str]:
    """Names made safe and unique for file names ("a/b c" -> "a_b_c", repeats numbered)."""
    out: list[str] = []
    for name in names:
        safe = re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("._") or "mesh"
        base, k = safe, 0
        while safe.lower() in (o.lower() for o in out):
            k += 1
            safe = f"{base}_{k}"
        out.append(safe)
    return out


def write_lightmaps(
    lightmaps: list[Lightmap],
    output_dir: Path,
    stem: str,
    metadata: dict[str, str],
    exposure: float,
    outputs: dict[str, Path],
    facts: dict[str, Any],
) -> list[Path]:
    """Write each lightmap's EXR and preview PNG; record paths and statistics.

    One scene lightmap is ``<stem>.lightmap.exr``; per-mesh ones are
    ``<stem>.<object>.lightmap.exr`` under output keys ``lightmap:<object>``. Returns the
    preview PNGs, in lightmap order.
    """
    if len(lightmaps) == 1 and not lightmaps[0].name:
        lightmap = lightmaps[0]
        outputs["lightmap"] = output_dir / f"{stem}.lightmap.exr"
        outputs["lightmap_preview"] = output_dir / f"{stem}.lightmap.png"
        write_lightmap(outputs["lightmap"], lightmap, metadata)
        write_lightmap_preview(outputs["lightmap_preview"], lightmap, exposure)
        facts["lightmap"] = {"size": list(lightmap.size), **lightmap.stats}
        return [outputs["lightmap_preview"]]
    facts["lightmaps"] = {}
    previews = []
    for lightmap, safe in zip(lightmaps, file_names([m.name for m in lightmaps]), strict=True):
        exr = outputs[f"lightmap:{lightmap.name}"] = output_dir / f"{stem}.{safe}.lightmap.exr"
        png = outputs[f"lightmap_preview:{lightmap.name}"] = exr.with_suffix(".png")
        write_lightmap(exr, lightmap, {**metadata, "object": lightmap.name})
        write_lightmap_preview(png, lightmap, exposure)
        facts["lightmaps"][lightmap.name] = {"size": list(lightmap.size), **lightmap.stats}
        previews.append(png)
    return previews
