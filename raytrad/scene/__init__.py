"""The scene data model: a scene as a few flat arrays, cameras, colorimetry of materials,
the scene builder and the built-in scenes. Data only: nothing here reads or writes files.
"""

from __future__ import annotations

from raytrad.scene.camera import Camera, NamedCamera
from raytrad.scene.model import (
    Scene,
    barycentric_coordinates,
    has_emission,
    make_scene,
    scene_digests,
    triangle_areas_normals,
    validate_scene,
)

__all__ = [
    "Camera",
    "NamedCamera",
    "Scene",
    "barycentric_coordinates",
    "has_emission",
    "make_scene",
    "scene_digests",
    "triangle_areas_normals",
    "validate_scene",
]
