"""raytrad: ray-traced vertex-to-patch progressive radiosity with ambient overshooting.

The names in ``__all__`` are the public API (``docs/api.md``): the pipeline's steps, its
settings as frozen dataclasses, its errors and batch baking. They are imported when first
used, so ``import raytrad`` stays light (``__init__.pyi`` gives type checkers their
types); every other module is internal and may change.

>>> import raytrad
>>> settings = raytrad.RenderSettings(mesh=raytrad.MeshSettings(receivers=2000))
>>> settings.mesh.receivers
2000
"""

from __future__ import annotations

import importlib
from importlib.metadata import PackageNotFoundError, version
from typing import Any

try:
    __version__ = version("raytrad")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0+unknown"

#: Each public name and the module it lives in.
_PUBLIC = {
    **dict.fromkeys(
        (
            "load",
            "prepare",
            "solve",
            "refine",
            "estimate_error",
            "write",
            "render",
            "solve_scene",
            "compare",
            "comparison_table",
            "make_reference",
            "outputs_current",
            "verify_outputs",
            "Prepared",
            "RenderOutcome",
            "RenderProgress",
        ),
        "raytrad.api",
    ),
    **dict.fromkeys(
        (
            "RenderSettings",
            "MeshSettings",
            "SolveSettings",
            "RefineSettings",
            "LightmapSettings",
            "ImageSettings",
            "Camera",
        ),
        "raytrad.settings",
    ),
    **dict.fromkeys(
        ("RaytradError", "SceneError", "SettingsError", "SolverError"), "raytrad.errors"
    ),
    **dict.fromkeys(("Scene",), "raytrad.scene"),
    **dict.fromkeys(("SceneFile",), "raytrad.scenefiles"),
    **dict.fromkeys(("SolveResult", "SolverState"), "raytrad.core.solver"),
    **dict.fromkeys(
        ("Job", "JobResult", "bake", "run_job", "read_manifest", "LocalPool", "DaskRunner"),
        "raytrad.batch",
    ),
}

__all__ = ["__version__", *_PUBLIC]


def __getattr__(name: str) -> Any:
    if name in _PUBLIC:
        value = getattr(importlib.import_module(_PUBLIC[name]), name)
        globals()[name] = value  # later lookups skip this function
        return value
    raise AttributeError(f"module 'raytrad' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_PUBLIC))
