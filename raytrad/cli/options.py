"""Command-line options to settings: what ``raytrad render`` and ``compare`` were told, as
:class:`~raytrad.settings.RenderSettings` (also used by ``raytrad bake`` for its jobs)."""

from __future__ import annotations

import argparse
from typing import Any

from raytrad.settings import (
    Camera,
    ImageSettings,
    LightmapSettings,
    MeshSettings,
    RefineSettings,
    RenderSettings,
    SettingsError,
    SolveSettings,
    defaults,
)


def _parse_camera(text: str, up: str = "y") -> Camera:
    try:
        parts = text.split(":")
        position = tuple(float(v) for v in parts[0].split(","))
        target = tuple(float(v) for v in parts[1].split(","))
        fov = float(parts[2]) if len(parts) > 2 else defaults.vertical_fov_deg
        if len(position) != 3 or len(target) != 3 or len(parts) > 3:
            raise ValueError
    except (ValueError, IndexError):
        raise SettingsError(
            f"--camera wants X,Y,Z:TX,TY,TZ[:FOV] (metres, degrees), got {text!r}"
        ) from None
    return Camera(
        (position[0], position[1], position[2]),
        (target[0], target[1], target[2]),
        up=(0.0, 0.0, 1.0) if up == "z" else (0.0, 1.0, 0.0),
        vertical_fov_deg=fov,
    )


def _uv_set(text: str) -> int | str:
    """``--uv-set``: 'auto', 'atlas' or a set index >= 0."""
    if text in ("auto", "atlas"):
        return text
    if text.isascii() and text.isdigit():
        return int(text)
    raise SettingsError(f"--uv-set wants auto, atlas or a UV set number >= 0, got {text!r}")


def _output_settings(args: argparse.Namespace) -> dict[str, Any]:
    """Lightmap, image and glTF settings from the options (None: the scene file's value)."""
    out: dict[str, Any] = {
        "gltf": args.gltf,
        "exposure": args.exposure,
        "refine": RefineSettings(threshold=args.refine_threshold, max_receivers=args.max_receivers),
    }
    if args.lightmap or (args.gltf and args.texel_density is not None):
        out["lightmap"] = LightmapSettings(
            resolution=args.lightmap_resolution,
            texel_density=args.texel_density,
            padding=args.lightmap_padding,
            half=not args.lightmap_float,
            uv_set=_uv_set(args.uv_set),
            per_mesh=args.lightmap_per_mesh,
        )
    elif args.uv_set != "auto" or args.lightmap_per_mesh:
        raise SettingsError("--uv-set and --lightmap-per-mesh need --lightmap")
    if args.view is not None and not args.image:
        raise SettingsError("--view needs --image")
    if args.image:
        out["image"] = ImageSettings(
            width=args.width,
            height=args.height,
            samples=args.spp,
            camera=None if args.camera is None else _parse_camera(args.camera, args.up),
            view=args.view,
            tonemap=args.tonemap,
            up=args.up,
        )
    return out


def render_settings(args: argparse.Namespace, method: str) -> RenderSettings:
    """The settings parsed ``render`` (or ``compare``) options ask for, solved by ``method``.

    Raises
    ------
    SettingsError
        An option value out of range, or options that need another (``--view`` without
        ``--image``...), in one line naming the option.
    """
    extra = _output_settings(args) if args.command == "render" else {}
    return RenderSettings(
        mesh=MeshSettings(
            max_edge=args.max_edge,
            receivers=args.receivers,
            patch_size=args.patch_size,
            patches=args.patches,
            samples=args.samples,
            emitter_samples=args.emitter_samples,
            seed=args.seed,
            imprint=args.imprint,
        ),
        solve=SolveSettings(
            method=method,
            tolerance=args.tolerance,
            time_limit=args.time_limit,
            max_shots=args.max_shots,
            omega=args.omega,
        ),
        scale=args.scale,
        allow_outside_files=args.allow_outside_files,
        cache_mb=args.cache_mb,
        checkpoint_seconds=args.checkpoint_every,
        **extra,
    )
