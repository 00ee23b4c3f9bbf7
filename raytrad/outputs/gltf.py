"""The baked model as binary glTF 2.0 (``raytrad render --gltf``).

The model carries the solution two ways:

* ``COLOR_0``: per-vertex linear colour, the radiance B/pi times the exposure, clipped to
  [0, 1], shown by any viewer through an unlit material (``KHR_materials_unlit``);
* with a lightmap: ``TEXCOORD_1`` and the lightmap image (8-bit sRGB PNG of the same exposed
  radiance) as the ``emissiveTexture`` on texture coordinate 1, so common viewers show the
  bake; the float EXR lightmap written beside it holds the unclipped radiosity.

``extras.raytrad`` records the exposure, so radiance = COLOR_0 / exposure [W sr-1 m-2].
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from raytrad import __version__
from raytrad.core.mesh import RadiosityMesh
from raytrad.formats.atomic import atomic_write
from raytrad.formats.glb import GltfDocument
from raytrad.products.lightmap import Lightmap, lightmap_vertices, object_triangles
from raytrad.scene import Scene


@dataclass(frozen=True, eq=False)
class BakedPart:
    """One mesh of the baked model: a glTF node with one primitive.

    Attributes
    ----------
    name : str
    positions : (V, 3) float [m]
    normals : (V, 3) float, unit
    triangles : (T, 3) int, counter-clockwise from the lit side
    colour : (V, 3) float
        Linear display colour in [0, 1] (radiance times the exposure).
    lightmap_uv : (V, 2) float or None
        Lightmap coordinates in [0, 1] (glTF convention: v down).
    lightmap_png : bytes or None
        This part's lightmap image; parts may share one (the same bytes object is stored
        once). Requires ``lightmap_uv``.
    """

    name: str
    positions: np.ndarray
    normals: np.ndarray
    triangles: np.ndarray
    colour: np.ndarray
    lightmap_uv: np.ndarray | None = None
    lightmap_png: bytes | None = None


def write_baked_glb(
    path: Path,
    parts: list[BakedPart],
    exposure: float,
    extras: dict[str, Any] | None = None,
) -> None:
    """Write the baked model as one ``.glb`` (atomically), one node per part.

    Parameters
    ----------
    path : Path
    parts : list of BakedPart
    exposure : float
        Multiplier from radiance [W sr-1 m-2] to the parts' ``colour`` (recorded in extras).
    extras : dict or None
        More facts for ``extras.raytrad``; the version and the colour convention are
        always recorded.
    """
    document = GltfDocument()
    unlit: int | None = None  # the shared unlit material's index, once a part needs it
    for part in parts:
        attributes = {
            "NORMAL": part.normals,
            "COLOR_0": np.clip(np.asarray(part.colour, dtype="<f4"), 0.0, 1.0),
        }
        if part.lightmap_png is not None and part.lightmap_uv is not None:
            attributes["TEXCOORD_1"] = part.lightmap_uv
            texture = document.add_png_texture(part.lightmap_png)
            material = document.add_material(_lightmap_material(part.name, texture))
        else:
            if unlit is None:
                unlit = document.add_material(_UNLIT_MATERIAL)
                document.use_extension("KHR_materials_unlit")
            material = unlit
        primitive = document.primitive(part.positions, part.triangles, material, **attributes)
        document.add_mesh_node(part.name, [primitive])
    document.extras = {"raytrad": {"exposure": exposure, **_EXTRAS, **(extras or {})}}
    with atomic_write(path) as handle:
        handle.write(document.glb())


def baked_parts(
    scene: Scene,
    mesh: RadiosityMesh,
    radiosity: np.ndarray,
    exposure: float,
    lightmaps: list[Lightmap],
    pngs: list[bytes],
) -> list[BakedPart]:
    """One part per object of ``scene``, coloured by ``radiosity`` ((R, 3) [W m-2]).

    ``pngs`` are each lightmap's preview PNG, in order; with lightmaps each part carries
    its own (per mesh) or the scene's, and its lightmap UVs.
    """
    colour = radiosity / math.pi * exposure
    by_name = {lightmap.name: k for k, lightmap in enumerate(lightmaps)}
    parts = []
    for name, rows in object_triangles(scene, mesh):
        uv, png = None, None
        if lightmaps:
            k = by_name.get(name, 0)  # a scene lightmap is named ""
            png = pngs[k]
            receiver, triangles, uv = lightmap_vertices(mesh, lightmaps[k], rows)
        else:
            receiver, local = np.unique(mesh.triangle_receivers[rows], return_inverse=True)
            triangles = local.reshape(-1, 3)
        parts.append(
            BakedPart(
                name,
                mesh.receiver_position[receiver],
                mesh.receiver_normal[receiver],
                triangles,
                colour[receiver],
                uv,
                png,
            )
        )
    return parts


_EXTRAS = {
    "version": __version__,
    "colour": "linear Rec.709: radiance [W sr-1 m-2] x exposure",
}
"""What ``extras.raytrad`` always says besides the exposure."""

_UNLIT_MATERIAL: dict[str, Any] = {
    "name": "baked",
    "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1], "metallicFactor": 0.0},
    "extensions": {"KHR_materials_unlit": {}},
}
"""Shows ``COLOR_0`` as is, in viewers that know the extension."""


def _lightmap_material(name: str, texture: int) -> dict[str, Any]:
    """A material showing lightmap ``texture`` (on ``TEXCOORD_1``) as emission."""
    return {
        "name": f"{name}-lightmap",
        "pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1], "metallicFactor": 0.0},
        "emissiveFactor": [1, 1, 1],
        "emissiveTexture": {"index": texture, "texCoord": 1},
    }
