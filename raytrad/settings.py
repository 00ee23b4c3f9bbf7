"""Everything a run can be told, as frozen dataclasses that validate themselves.

:class:`RenderSettings` gathers the settings of each stage, which live beside the code
they steer and are re-exported here: :class:`~raytrad.core.mesh.MeshSettings` (the
discretisation), :class:`~raytrad.core.solver.SolveSettings` (method and stopping rules),
:class:`~raytrad.products.lightmap.LightmapSettings` and :class:`ImageSettings`.

A setting left at None that a scene file can give (a TOML ``[output]`` table) takes the
file's value, else the default: :func:`with_scene_defaults` resolves them once the file
is read.

>>> from raytrad.settings import MeshSettings, RenderSettings, SolveSettings
>>> settings = RenderSettings(mesh=MeshSettings(receivers=5000),
...                           solve=SolveSettings(method="progressive"))
>>> settings.solve.tolerance
0.001
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from raytrad.constants import defaults
from raytrad.core.adaptive import RefineSettings
from raytrad.core.mesh import MeshSettings
from raytrad.core.patch_factors import check_patch_factor_memory
from raytrad.core.solver import SHOOTING_METHODS, SolveSettings
from raytrad.errors import SettingsError
from raytrad.products.display import TONEMAPS
from raytrad.products.lightmap import LightmapSettings
from raytrad.scene import Camera

MAX_IMAGE_SIDE = 16384
"""The widest or tallest image raytrad renders [pixels]."""

MAX_IMAGE_SAMPLES = 4096
"""The most samples per pixel of an image."""


@dataclass(frozen=True)
class ImageSettings:
    """A camera render of the solution (``raytrad render --image``).

    Attributes
    ----------
    width : int or None
        Image width [pixels]; None: ``height`` times the aspect ratio of the scene file's
        camera when it gives one (glTF ``aspectRatio``), else the scene file's
        ``image_width``, else 640.
    height : int or None
        Image height [pixels]; None: the scene file's ``image_height``, else 480.
    samples : int
        Samples per pixel (stratified; rounded down to a square).
    camera : Camera or None
        None: the scene file's camera (a TOML ``[camera]``, a glTF camera), else an
        automatic framing.
    view : str or None
        Which of the scene file's cameras to use, by name (a glTF camera node's name);
        None: the first. Ignored when ``camera`` is given.
    tonemap : str
        Display encoding of the PNG: ``"srgb"`` (clip, sRGB) or ``"aces"`` (filmic ACES
        output transform; see :func:`raytrad.products.display.display_encode`).
    up : str
        The scene's up axis for automatic framing: ``"y"`` (glTF's convention) or ``"z"``
        (CAD, Blender without axis conversion).
    """

    width: int | None = None
    height: int | None = None
    samples: int = defaults.image_samples
    camera: Camera | None = None
    view: str | None = None
    tonemap: str = "srgb"
    up: str = "y"

    def __post_init__(self) -> None:
        small = [v for v in (self.width, self.height, self.samples) if v is not None and v < 1]
        if small:
            raise SettingsError("image width, height and samples must be at least 1")
        sides = [v for v in (self.width, self.height) if v is not None]
        if max(sides, default=0) > MAX_IMAGE_SIDE or self.samples > MAX_IMAGE_SAMPLES:
            raise SettingsError(
                f"image width and height must be at most {MAX_IMAGE_SIDE} pixels and samples "
                f"at most {MAX_IMAGE_SAMPLES}"
            )
        if self.up not in ("y", "z"):
            raise SettingsError(f"up axis must be y or z, not {self.up!r}")
        if self.tonemap not in TONEMAPS:
            raise SettingsError(
                f"tone map must be one of {', '.join(TONEMAPS)}, not {self.tonemap!r}"
            )


@dataclass(frozen=True)
class RenderSettings:
    """Everything ``raytrad render`` can be told.

    Attributes
    ----------
    mesh : MeshSettings
        Discretisation (receivers, patches, samples, seed).
    solve : SolveSettings
        Method and stopping rules.
    refine : RefineSettings
        Adaptive refinement after the solve (threshold 0 turns it off).
    scale : float
        Multiplies scene coordinates to get metres (0.001 for a model in millimetres).
    exposure : float or None
        Extra exposure of the display colours [EV]; None: the scene file's, else 0.
    cache_mb : float
        Memory for cached form-factor columns [MiB].
    checkpoint_seconds : float
        Seconds between checkpoints of a long solve.
    lightmap : LightmapSettings or None
        Bake and write an EXR lightmap (and its preview PNG).
    image : ImageSettings or None
        Render the solution from a camera (linear EXR and display PNG).
    gltf : bool
        Write the baked model as ``.glb``.
    allow_outside_files : bool
        Read files the scene refers to (buffers, ``mtllib``, TOML meshes) that lie
        outside the scene file's folder; refused by default.
    """

    mesh: MeshSettings = field(default_factory=MeshSettings)
    solve: SolveSettings = field(default_factory=SolveSettings)
    refine: RefineSettings = field(default_factory=RefineSettings)
    scale: float = 1.0
    exposure: float | None = None
    cache_mb: float = defaults.cache_mb
    checkpoint_seconds: float = 60.0
    lightmap: LightmapSettings | None = None
    image: ImageSettings | None = None
    gltf: bool = False
    allow_outside_files: bool = False

    def __post_init__(self) -> None:
        if not (self.scale > 0 and math.isfinite(self.scale)):
            raise SettingsError(f"scale must be a positive number, got {self.scale}")
        if not (self.cache_mb >= 0 and math.isfinite(self.cache_mb)):
            raise SettingsError(f"cache must be a finite number >= 0 MiB, got {self.cache_mb}")
        if not (self.checkpoint_seconds > 0 and math.isfinite(self.checkpoint_seconds)):
            raise SettingsError(
                f"checkpoint interval must be a finite number > 0 s, got {self.checkpoint_seconds}"
            )
        if self.exposure is not None and not math.isfinite(self.exposure):
            raise SettingsError(f"exposure must be a finite number of stops, got {self.exposure}")
        self.check_method(self.solve.method)

    def check_method(self, method: str) -> None:
        """Refuse, before any work, a method whose patch-to-patch factors would not fit
        at the asked-for patch count (:mod:`raytrad.core.patch_factors`)."""
        if method in SHOOTING_METHODS and SHOOTING_METHODS[method].patch_factors:
            check_patch_factor_memory(self.mesh.patches, method)

    def system_settings(self) -> dict[str, Any]:
        """The settings that define the discrete system (for checkpoint fingerprints)."""
        return {"mesh": dataclasses.asdict(self.mesh), "scale": self.scale}


def with_scene_defaults(
    settings: RenderSettings, output: Mapping[str, float | int]
) -> RenderSettings:
    """``settings`` with what it leaves at None taken from a scene file's ``[output]``
    values (:data:`raytrad.scenefiles.toml_scene.OUTPUT_KEYS`), else the defaults."""
    exposure = settings.exposure
    if exposure is None:
        exposure = float(output.get("exposure", 0.0))
    lightmap = settings.lightmap
    if lightmap is not None:
        density = lightmap.texel_density
        if density is None and "texel_density" in output:
            density = float(output["texel_density"])
        resolution = lightmap.resolution or int(
            output.get("lightmap_resolution", defaults.lightmap_resolution)
        )
        lightmap = dataclasses.replace(lightmap, resolution=resolution, texel_density=density)
    image = settings.image
    if image is not None:
        width = image.width
        if width is None and "image_width" in output:
            width = int(output["image_width"])
        height = image.height or int(output.get("image_height", defaults.image_height))
        image = dataclasses.replace(image, width=width, height=height)
    return dataclasses.replace(settings, exposure=exposure, lightmap=lightmap, image=image)


def method_summaries() -> dict[str, str]:
    """Each solver method's name and one-line summary, from the registry."""
    return {name: method.summary for name, method in SHOOTING_METHODS.items()}


__all__ = [
    "Camera",
    "ImageSettings",
    "LightmapSettings",
    "MeshSettings",
    "RefineSettings",
    "RenderSettings",
    "SettingsError",
    "SolveSettings",
    "defaults",
    "method_summaries",
    "with_scene_defaults",
]
