"""The Python API: from a scene file to written results in one call, or step by step.

>>> from raytrad import api
>>> outcome = api.render("scenes/cornell-box.obj", "out")          # doctest: +SKIP
>>> outcome.result.radiosity.shape                                  # doctest: +SKIP
(20184, 3)
"""

from __future__ import annotations

import dataclasses
import json
import logging
import re
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from raytrad import __version__
from raytrad.camera import Camera, NamedCamera
from raytrad.checkpoint import fingerprint, load_checkpoint, save_checkpoint
from raytrad.convergence import ConvergenceMonitor, ErrorLog, Reference
from raytrad.display import auto_exposure, display_colors
from raytrad.errors import RaytradError, SceneError, SettingsError
from raytrad.formfactor import RAY_OFFSET, FormFactorEngine, receiver_points
from raytrad.image import automatic_camera, render_radiance
from raytrad.io.atomic import atomic_write
from raytrad.io.exr import TONEMAPS, display_encode, write_exr, write_png
from raytrad.io.gltf import BakedPart, write_baked_glb
from raytrad.io.loaders import load_scene
from raytrad.io.ply import write_radiosity_ply
from raytrad.lightmap import (
    Lightmap,
    LightmapSettings,
    bake_lightmap,
    lightmap_vertices,
    write_lightmap,
    write_lightmap_preview,
)
from raytrad.mesh import MeshSettings, RadiosityMesh, build_mesh, fill_hidden, hide_receivers
from raytrad.plot import plot_convergence
from raytrad.reference import analytic_furnace, dense_solve, reference_from_ply
from raytrad.repair import repair_scene
from raytrad.scene import Scene, has_emission, triangle_areas_normals
from raytrad.solver import SolveResult, SolverState, SolveSettings, check_solvable, solve
from raytrad.visibility import Occluder, nothing_can_occlude

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ImageSettings:
    """A camera render of the solution (``raytrad render --image``).

    Attributes
    ----------
    width : int or None
        Image width [pixels]; None: ``height`` times the aspect ratio of the scene file's
        camera when it gives one (glTF ``aspectRatio``), else 640.
    height : int
        Image height [pixels].
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
        output transform; see :func:`raytrad.io.exr.display_encode`).
    """

    width: int | None = None
    height: int = 480
    samples: int = 4
    camera: Camera | None = None
    view: str | None = None
    tonemap: str = "srgb"

    def __post_init__(self) -> None:
        if (self.width is not None and self.width < 1) or self.height < 1 or self.samples < 1:
            raise SettingsError("image width, height and samples must be at least 1")
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
    scale : float
        Multiplies scene coordinates to get metres (0.001 for a model in millimetres).
    exposure : float
        Extra exposure of the PLY display colours [EV].
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
    """

    mesh: MeshSettings = field(default_factory=MeshSettings)
    solve: SolveSettings = field(default_factory=SolveSettings)
    scale: float = 1.0
    exposure: float = 0.0
    cache_mb: float = 1024.0
    checkpoint_seconds: float = 60.0
    lightmap: LightmapSettings | None = None
    image: ImageSettings | None = None
    gltf: bool = False

    def __post_init__(self) -> None:
        if not (self.scale > 0 and np.isfinite(self.scale)):
            raise SettingsError(f"scale must be a positive number, got {self.scale}")
        m = self.mesh
        if m.max_edge is not None and not m.max_edge > 0:
            raise SettingsError(f"max edge must be positive, got {m.max_edge}")
        if m.receivers < 1 or m.patches < 1 or m.samples < 1 or m.emitter_samples < 1:
            raise SettingsError("receivers, patches and samples must be at least 1")
        if m.patch_size is not None and not m.patch_size > 0:
            raise SettingsError(f"patch size must be positive, got {m.patch_size}")
        if self.cache_mb < 0:
            raise SettingsError(f"cache must be >= 0 MiB, got {self.cache_mb}")

    def system_settings(self) -> dict[str, Any]:
        """The settings that define the discrete system (for checkpoint fingerprints)."""
        return {"mesh": dataclasses.asdict(self.mesh), "scale": self.scale}


@dataclass
class Prepared:
    """A scene made ready to solve: its mesh and form-factor engine."""

    scene: Scene
    mesh: RadiosityMesh
    engine: FormFactorEngine
    occluder: Occluder | None
    timings: dict[str, float]
    closed_receivers: np.ndarray | None = None
    balance: dict[str, float] = field(default_factory=dict)

    def close(self) -> None:
        self.engine.close()
        if self.occluder is not None:
            self.occluder.close()

    def new_engine(self) -> FormFactorEngine:
        """A fresh engine on the same mesh (no cached columns), closed rows normalised."""
        engine = FormFactorEngine(self.mesh, self.occluder, cache_bytes=self.engine.cache_bytes)
        engine.balance(self.closed_receivers)
        return engine


@dataclass
class RenderOutcome:
    """What :func:`render` did and wrote."""

    result: SolveResult
    prepared: Prepared
    outputs: dict[str, Path]
    report: dict[str, Any]
    error_log: ErrorLog


def make_reference(spec: str, prepared: Prepared) -> Reference:
    """A reference solution for the true-error log.

    Parameters
    ----------
    spec : str
        ``dense`` (direct solve of the same discrete system), ``analytic`` (B = E/(1-rho),
        closed scenes of uniform materials) or the path of a previous result PLY.

    Raises
    ------
    RaytradError
        When the reference does not apply to this scene.
    """
    mesh = prepared.mesh
    if spec == "dense":
        try:
            radiosity = dense_solve(mesh, prepared.engine)
        except ValueError as exc:
            raise SettingsError(f"{exc}; use fewer patches or a previous result") from exc
        return Reference(radiosity, "dense", "direct solve of the same discrete system")
    if spec == "analytic":
        if prepared.occluder is not None:
            raise SettingsError(
                "the analytic reference B = E/(1-rho) needs a closed convex enclosure"
            )
        try:
            radiosity = analytic_furnace(mesh)
        except ValueError as exc:
            raise SettingsError(str(exc)) from exc
        return Reference(radiosity, "analytic", "closed enclosure: B = E / (1 - rho)")
    return Reference(reference_from_ply(spec, mesh), "file", f"previous result {spec}")


@contextmanager
def _timed(timings: dict[str, float], stage: str) -> Iterator[None]:
    start = time.perf_counter()
    try:
        yield
    finally:
        timings[stage] = timings.get(stage, 0.0) + time.perf_counter() - start


def prepare(scene: Scene, settings: RenderSettings | None = None) -> Prepared:
    """Repair, mesh and balance ``scene``: everything before the first shot.

    Duplicate and inside-out faces are fixed (with warnings, :mod:`raytrad.repair`); no
    acceleration structure is built when nothing can occlude (a convex enclosure); every
    form-factor column is computed and balanced (:meth:`FormFactorEngine.balance`).
    """
    settings = settings or RenderSettings()
    timings: dict[str, float] = {}
    with _timed(timings, "mesh"):
        scene = repair_scene(scene)
    with _timed(timings, "acceleration"):
        used = np.unique(scene.triangles)
        extent = float(np.ptp(scene.positions[used], axis=0).max())
        occluder = None
        if not nothing_can_occlude(scene.positions, scene.triangles, 1e-7 * extent):
            occluder = Occluder(scene.positions, scene.triangles)
    with _timed(timings, "mesh"):
        enclosed = None
        if occluder is not None:
            _, normals = triangle_areas_normals(scene.triangle_vertices())
            shut_in = occluder  # bound for the closure below

            def enclosed(points: np.ndarray, point_normals: np.ndarray) -> np.ndarray:
                return shut_in.enclosed(points, point_normals, normals, scene.double_sided)

        mesh = build_mesh(scene, settings.mesh, enclosed)
    check_solvable(mesh)  # before any form factor is computed
    closed = None
    with _timed(timings, "form_factors"):
        if occluder is not None:
            _, normals = triangle_areas_normals(scene.triangle_vertices())
            points, _ = receiver_points(mesh, RAY_OFFSET * occluder.diagonal)
            closed, hidden = occluder.probe_hemispheres(
                points, mesh.receiver_normal, normals, scene.double_sided
            )
            mesh = hide_receivers(mesh, hidden)
        engine = FormFactorEngine(mesh, occluder, cache_bytes=int(settings.cache_mb * (1 << 20)))
        balance = engine.balance(closed)
    log.info(
        "form factors: %d closed rows held to 1 (largest miss %.2e), %d patches held to "
        "capture 1 (largest excess %.2e)",
        balance["closed_rows"],
        balance["row_error"],
        balance["capped_columns"],
        balance["capture_excess"],
    )
    return Prepared(scene, mesh, engine, occluder, timings, closed, balance)


def render(
    scene_path: str | Path,
    output_dir: str | Path,
    settings: RenderSettings | None = None,
    resume: bool = False,
    progress: Callable[[SolverState, float, float], None] | None = None,
    stop: Callable[[], bool] | None = None,
    reference: str | None = None,
    plot: bool = False,
) -> RenderOutcome:
    """Load, mesh, solve and write ``<output_dir>/<stem>.ply`` and ``report.json``.

    Parameters
    ----------
    scene_path : path-like
        OBJ (+MTL), glTF 2.0 (.gltf/.glb) or PLY file.
    output_dir : path-like
        Created if missing; outputs are replaced atomically.
    settings : RenderSettings
    resume : bool
        Continue from ``<output_dir>/<stem>.checkpoint.npz`` if it exists.
    progress : callable or None
        ``progress(state, residual, error_estimate)`` after each shot.
    stop : callable or None
        Polled before each shot; True stops the solve, writes the outputs so far and a
        checkpoint to resume from.
    reference : str or None
        Measure the true error against this reference (see :func:`make_reference`).
    plot : bool
        Also write ``convergence.png`` (error against time).

    Raises
    ------
    SceneError
        Bad scene file (nothing is written).
    """
    settings = settings or RenderSettings()
    scene_path = Path(scene_path)
    output_dir = Path(output_dir)
    timings: dict[str, float] = {}
    with _timed(timings, "load"):
        scene, camera = _load(scene_path, settings)
        scene = checked_lightmap_uvs(scene, settings.lightmap)
    if not has_emission(scene):
        log.warning("%s: the scene has no emitter; every radiosity is zero", scene_path)
    prepared = prepare(scene, settings)
    timings.update(prepared.timings)
    try:
        ref = None
        if reference is not None:
            with _timed(timings, "reference"):
                ref = make_reference(reference, prepared)
    except BaseException:
        prepared.close()
        raise
    monitor = ConvergenceMonitor(prepared.mesh, prepared.engine, ref)
    stem = scene_path.stem
    checkpoint = output_dir / f"{stem}.checkpoint.npz"
    key = fingerprint(scene_path.read_bytes(), settings.system_settings())
    state = None
    if resume and checkpoint.exists():
        state = load_checkpoint(checkpoint, key)
        log.info("resuming from %s at shot %d", checkpoint, state.shots)

    last_save = [time.perf_counter()]

    def on_shot(s: SolverState, residual: float) -> None:
        monitor(s, residual)
        if progress is not None:
            progress(s, residual, monitor.latest_estimate)
        if time.perf_counter() - last_save[0] >= settings.checkpoint_seconds:
            output_dir.mkdir(parents=True, exist_ok=True)
            save_checkpoint(checkpoint, s, key)
            last_save[0] = time.perf_counter()

    try:
        with _timed(timings, "solve"):
            result = solve(prepared.mesh, prepared.engine, settings.solve, state, on_shot, stop)
        error_log = monitor.finish(result.state)
        with _timed(timings, "write"):
            outputs, facts = _write_outputs(prepared, result, output_dir, stem, settings, camera)
            if plot:
                outputs["plot"] = output_dir / "convergence.png"
                plot_convergence(outputs["plot"], {result.method: error_log}, str(scene_path))
        if result.stop_reason in ("interrupted", "time-limit", "max-shots"):
            save_checkpoint(checkpoint, result.state, key)  # --resume continues from here
            outputs["checkpoint"] = checkpoint
        elif checkpoint.exists():
            checkpoint.unlink()
        report = build_report(scene_path, prepared, result, settings, timings, outputs)
        report["outputs_detail"] = facts
        report["reference"] = (
            None if ref is None else {"kind": ref.kind, "description": ref.description}
        )
        columns = error_log.as_dict()  # non-finite values become null (strict JSON)
        report["convergence"] = columns
        report["error"] = {
            name: (columns[name][-1] if columns[name] else None)
            for name in ("estimate", "bound_rms", "bound_max", "true_rms", "true_max")
        }
        report_path = output_dir / "report.json"
        with atomic_write(report_path, "w") as handle:
            json.dump(report, handle, indent=2, allow_nan=False)
        outputs["report"] = report_path
    finally:
        prepared.close()
    return RenderOutcome(result, prepared, outputs, report, error_log)


def _load(path: Path, settings: RenderSettings) -> tuple[Scene, NamedCamera | None]:
    """The scene (with the lightmap UV set asked for) and the camera of the scene file.

    The camera is a TOML file's ``[camera]`` or a glTF file's camera (``image.view`` by
    name, else the first), looked for only when an image is asked for; None otherwise.
    """
    scale = settings.scale
    uv_set = None if settings.lightmap is None else settings.lightmap.uv_set_to_read
    suffix = path.suffix.lower()
    if suffix == ".toml" and path.is_file():
        from raytrad.io.toml_scene import load_scene_description

        description = load_scene_description(path, scale=scale, uv_set=uv_set)
        camera = description.camera
        named = None if camera is None else NamedCamera("camera", camera)
        if settings.image is not None and settings.image.view not in (None, "camera"):
            raise SettingsError(
                f"{path}: has no camera named {settings.image.view!r} (a TOML scene file "
                "has one [camera], named 'camera')"
            )
        return description.scene, named
    scene = load_scene(path, scale=scale, uv_set=uv_set)
    if settings.image is None or suffix not in (".gltf", ".glb"):
        if settings.image is not None and settings.image.view is not None:
            raise SettingsError(f"{path}: only glTF and TOML scene files have cameras to name")
        return scene, None
    return scene, _gltf_camera(path, scale, settings.image.view)


def _gltf_camera(path: Path, scale: float, view: str | None) -> NamedCamera | None:
    """The glTF camera named ``view`` (None: the first), or None when the file has none."""
    from raytrad.io.gltf_camera import read_gltf_cameras

    cameras = read_gltf_cameras(path, scale)
    if view is None:
        if len(cameras) > 1:
            log.info(
                "%s: %d cameras; using %r (choose with --view: %s)",
                path,
                len(cameras),
                cameras[0].name,
                ", ".join(repr(c.name) for c in cameras),
            )
        return cameras[0] if cameras else None
    for named in cameras:
        if named.name == view:
            return named
    names = ", ".join(repr(c.name) for c in cameras) or "none"
    raise SettingsError(f"{path}: no camera named {view!r} (its cameras: {names})")


def checked_lightmap_uvs(scene: Scene, settings: LightmapSettings | None) -> Scene:
    """The scene with the lightmap UVs the settings will bake with, or without any.

    With ``uv_set="auto"`` the model's UVs are kept only when every face has them (else an
    atlas is generated, with a warning when only some faces have them); with an index
    every face must have them.

    Raises
    ------
    SceneError
        An explicit UV set that some faces lack, naming the file, the set and an object.
    """
    uv = scene.lightmap_uv
    if settings is None or uv is None or settings.uv_set == "atlas":
        return dataclasses.replace(scene, lightmap_uv=None)
    missing = ~np.isfinite(uv).all(axis=(1, 2))
    if not missing.any():
        log.info("%s: baking into the model's UV set %s", scene.source, settings.uv_set_to_read)
        return scene
    count, total = int(missing.sum()), scene.triangle_count
    where = scene.object_names[int(scene.object_index[np.argmax(missing)])]
    if settings.uv_set == "auto":
        if count < total:
            log.warning(
                "%s: UV set 1 (TEXCOORD_1) is missing on %d of %d faces (object %r); "
                "generating a lightmap atlas instead",
                scene.source,
                count,
                total,
                where,
            )
        return dataclasses.replace(scene, lightmap_uv=None)
    raise SceneError(
        scene.source,
        f"UV set {settings.uv_set} is missing on {count} of {total} faces (first in object "
        f"{where!r}); omit --uv-set or use --uv-set atlas to generate a lightmap atlas",
    )


def _write_outputs(
    prepared: Prepared,
    result: SolveResult,
    output_dir: Path,
    stem: str,
    settings: RenderSettings,
    camera: NamedCamera | None = None,
) -> tuple[dict[str, Path], dict[str, Any]]:
    """Write every asked-for output; return their paths and facts for the report."""
    mesh = prepared.mesh
    emitting = np.asarray((mesh.receiver_emitted_exitance > 0).any(axis=1))
    # hidden receivers take their visible neighbours' radiosity in what is shown
    shown = fill_hidden(mesh, result.radiosity)
    area = mesh.receiver_area
    exposure = auto_exposure(shown, emitting, area) * 2.0**settings.exposure
    colors = display_colors(shown, emitting, settings.exposure, area)
    outputs = {"ply": output_dir / f"{stem}.ply"}
    facts: dict[str, Any] = {"exposure": exposure}
    write_radiosity_ply(
        outputs["ply"], mesh.receiver_position, mesh.triangle_receivers, result.radiosity, colors
    )
    metadata = {"scene": str(prepared.scene.source or stem), "method": result.method}
    lightmaps: list[Lightmap] = []
    previews: list[Path] = []
    if settings.lightmap is not None:
        lightmaps = _bake_lightmaps(prepared, shown, settings.lightmap)
        previews = _write_lightmaps(lightmaps, output_dir, stem, metadata, exposure, outputs, facts)
    if settings.image is not None:
        view, width = _image_view(mesh, settings.image, camera)
        image = settings.image
        radiance = render_radiance(mesh, shown, view, width, image.height, image.samples)
        outputs["image"] = output_dir / f"{stem}.exr"
        outputs["image_preview"] = output_dir / f"{stem}.png"
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
        facts["camera"] = dataclasses.asdict(view)
        facts["camera"]["name"] = (
            "settings" if image.camera else camera.name if camera else "automatic framing"
        )
    if settings.gltf:
        outputs["gltf"] = output_dir / f"{stem}.glb"
        pngs = [preview.read_bytes() for preview in previews]  # the PNGs just written
        _write_gltf(outputs["gltf"], prepared, shown, exposure, lightmaps, pngs)
    return outputs, facts


def _write_gltf(
    path: Path,
    prepared: Prepared,
    radiosity: np.ndarray,
    exposure: float,
    lightmaps: list[Lightmap],
    pngs: list[bytes],
) -> None:
    """The baked model: one node per object, with its lightmap (``pngs``: each
    lightmap's preview PNG, in order) when one was baked."""
    mesh = prepared.mesh
    colour = radiosity / np.pi * exposure
    parts = []
    by_name = {lightmap.name: k for k, lightmap in enumerate(lightmaps)}
    for name, rows in _object_triangles(prepared):
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
    write_baked_glb(
        path,
        parts,
        exposure,
        {"version": __version__, "colour": "linear Rec.709: radiance [W sr-1 m-2] x exposure"},
    )


def _image_view(
    mesh: RadiosityMesh, image: ImageSettings, camera: NamedCamera | None
) -> tuple[Camera, int]:
    """The camera to render from and the image width [pixels] (see :class:`ImageSettings`)."""
    if image.camera is not None:
        return image.camera, image.width or 640
    if camera is None:
        return automatic_camera(mesh), image.width or 640
    aspect = camera.aspect_ratio
    width = image.width or (max(1, round(image.height * aspect)) if aspect else 640)
    return camera.camera, width


def _object_triangles(prepared: Prepared) -> list[tuple[str, np.ndarray]]:
    """Each object's name and (t,) indices of its refined mesh triangles, objects in order."""
    scene = prepared.scene
    owner = scene.object_index[prepared.mesh.triangle_source]
    return [
        (name, np.flatnonzero(owner == i))
        for i, name in enumerate(scene.object_names)
        if (owner == i).any()
    ]


def _bake_lightmaps(
    prepared: Prepared, radiosity: np.ndarray, settings: LightmapSettings
) -> list[Lightmap]:
    """One lightmap for the scene, or one per object with ``settings.per_mesh``."""
    scene, mesh = prepared.scene, prepared.mesh
    uv = scene.lightmap_uv
    corners = None if uv is None else scene.triangle_vertices()
    if not settings.per_mesh:
        return [bake_lightmap(mesh, radiosity, settings, uv, corners)]
    return [
        bake_lightmap(mesh, radiosity, settings, uv, corners, rows, name)
        for name, rows in _object_triangles(prepared)
    ]


def _file_names(names: list[str]) -> list[str]:
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


def _write_lightmaps(
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
    for lightmap, safe in zip(lightmaps, _file_names([m.name for m in lightmaps]), strict=True):
        exr = outputs[f"lightmap:{lightmap.name}"] = output_dir / f"{stem}.{safe}.lightmap.exr"
        png = outputs[f"lightmap_preview:{lightmap.name}"] = exr.with_suffix(".png")
        write_lightmap(exr, lightmap, {**metadata, "object": lightmap.name})
        write_lightmap_preview(png, lightmap, exposure)
        facts["lightmaps"][lightmap.name] = {"size": list(lightmap.size), **lightmap.stats}
        previews.append(png)
    return previews


def build_report(
    scene_path: Path,
    prepared: Prepared,
    result: SolveResult,
    settings: RenderSettings,
    timings: dict[str, float],
    outputs: dict[str, Path],
) -> dict[str, Any]:
    """The JSON-ready summary of a render: settings, statistics, timings, energy ledger."""
    mesh, state = prepared.mesh, result.state
    rays = prepared.engine.rays_cast  # this run's rays, the form-factor pre-pass included
    tracing = state.seconds + timings.get("form_factors", 0.0)
    rays_per_second = rays / tracing if tracing > 0 else 0.0
    return {
        "raytrad_version": __version__,
        "scene": str(scene_path),
        "settings": {
            "mesh": dataclasses.asdict(settings.mesh),
            "solve": dataclasses.asdict(settings.solve),
            "scale": settings.scale,
            "exposure": settings.exposure,
            "cache_mb": settings.cache_mb,
            "lightmap": None
            if settings.lightmap is None
            else dataclasses.asdict(settings.lightmap),
            "image": None if settings.image is None else dataclasses.asdict(settings.image),
            "gltf": settings.gltf,
        },
        "statistics": {
            "scene_triangles": prepared.scene.triangle_count,
            "triangles": len(mesh.triangles),
            "receivers": mesh.receiver_count,
            "patches": mesh.patch_count,
            "subareas": mesh.subarea_count,
            "occlusion_tested": prepared.occluder is not None,
            "form_factor_balance": prepared.balance,
        },
        "timings_seconds": timings,
        "solve": {
            "method": result.method,
            "stop_reason": result.stop_reason,
            "shots": state.shots,
            "rays": rays,
            "rays_per_second": rays_per_second,
            "form_factor_columns": prepared.engine.columns_computed,
            "residual": result.residual,
            "seconds": state.seconds,
            "ambient_gain": state.ambient_gain,
            "divergence_damped": state.damping_events,
        },
        "energy_watts": {
            "emitted": result.emitted_power.tolist(),
            "absorbed": state.absorbed.tolist(),
            "escaped": state.escaped.tolist(),
            "unshot": result.unshot_power.tolist(),
        },
        "outputs": {k: str(v) for k, v in outputs.items()},
    }


def solve_scene(
    scene: Scene, settings: RenderSettings | None = None
) -> tuple[Prepared, SolveResult]:
    """Mesh and solve an in-memory scene; nothing is written (for batch jobs and tests)."""
    settings = settings or RenderSettings()
    prepared = prepare(scene, settings)
    try:
        result = solve(prepared.mesh, prepared.engine, settings.solve)
    finally:
        prepared.close()
    return prepared, result


__all__ = [
    "Prepared",
    "RaytradError",
    "RenderOutcome",
    "RenderSettings",
    "build_report",
    "prepare",
    "render",
    "solve_scene",
]
