"""TOML scene descriptions: what OBJ, glTF and PLY files cannot say.

A ``.toml`` scene places mesh files (``[[mesh]]``, each with a transform), overrides their
materials by name with RGB numbers, measured spectra, ColorChecker patches, emitters given
by exitance, radiance, radiant power or luminous flux and coloured by a blackbody
temperature, a standard illuminant or RGB, and adds a ``[camera]`` and ``[output]``
settings. The schema, with a complete example, is in ``docs/scene-files.md``.

Every key is checked: a key nothing reads, a value of the wrong type or range, or a missing
mesh file is a :class:`~raytrad.errors.SceneError` naming the TOML file and the dotted key
(``mesh[0].materials.white.reflectance``). colour-science is imported (through
:mod:`raytrad.scene.colorimetry`) only when the file uses a spectral or photometric colour:
a spectrum, a named reflectance, a colour temperature or a named illuminant.

Units: coordinates [m]; reflectance [1] linear RGB; exitance [W m-2]; radiance
[W sr-1 m-2]; power [W]; luminous flux [lm]; temperature [K]; angles [degrees].
"""

from __future__ import annotations

import logging
import math
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from raytrad.constants import defaults, tol
from raytrad.errors import SceneError
from raytrad.scene import Camera, NamedCamera, Scene, colorimetry, triangle_areas_normals
from raytrad.scenefiles import toml_values as tv
from raytrad.scenefiles.common import Collected, Material, ReadOptions, compact

log = logging.getLogger(__name__)

#: ``load_mesh(path, options)``: how a ``[[mesh]]`` file is loaded with the TOML file's
#: read options (the scene-file entrance, handed in so that this reader does not import it).
LoadMesh = Callable[[Path, ReadOptions], Scene]

TOP_KEYS = ("mesh", "materials", "camera", "output")
"""Keys allowed at the top level of a scene file."""

MESH_KEYS = ("file", "name", "transform", "translate", "rotate_deg", "scale", "materials")
"""Keys allowed in each ``[[mesh]]`` table."""

REFLECTANCE_KEYS = ("reflectance", "reflectance_spectrum", "reflectance_named")
"""Ways to give a material's reflectance (at most one per material)."""

AMOUNT_KEYS = ("exitance", "radiance", "power_w", "flux_lm")
"""Ways to give how much a material emits (at most one per material)."""

COLOUR_KEYS = tuple(colorimetry.EMITTER_COLOURS)
"""Ways to give an emitter's colour (at most one; needs an amount key)."""

MATERIAL_KEYS = (*REFLECTANCE_KEYS, "double_sided", *AMOUNT_KEYS, *COLOUR_KEYS)
"""Keys allowed in ``[materials.NAME]`` and ``[mesh.materials.NAME]`` tables."""

SPECTRUM_KEYS = ("wavelengths", "values")
"""Keys of a ``reflectance_spectrum`` table."""

CAMERA_KEYS = ("position", "look_at", "up", "vertical_fov_deg")
"""Keys allowed in ``[camera]``."""

TEMPERATURE_RANGE_K = (1000.0, 40000.0)
"""Accepted blackbody colour temperatures [K]."""


@dataclass(frozen=True)
class OutputKey:
    """One accepted ``[output]`` key: its type, range and meaning (with unit)."""

    kind: type[int] | type[float]
    low: float
    high: float
    low_open: bool
    description: str


OUTPUT_KEYS: dict[str, OutputKey] = {
    "exposure": OutputKey(
        float, -math.inf, math.inf, False, "extra exposure of display colours [EV]"
    ),
    "lightmap_resolution": OutputKey(
        int, 8, 16384, False, "texels along each side of the lightmap atlas [1]"
    ),
    "texel_density": OutputKey(float, 0.0, math.inf, True, "lightmap texels per metre [m-1]"),
    "image_width": OutputKey(int, 1, 16384, False, "camera image width [px]"),
    "image_height": OutputKey(int, 1, 16384, False, "camera image height [px]"),
}
"""Keys accepted in ``[output]``; their values are stored, validated, for the caller."""


def read_toml(path: Path, options: ReadOptions, load_mesh: LoadMesh) -> Collected:
    """A TOML scene file: its placed meshes, its camera and its ``[output]`` values.

    Parameters
    ----------
    path : Path
        The ``.toml`` file; mesh files are found relative to its directory.
    options : ReadOptions
        ``scale`` multiplies every position, the camera's included [m per scene unit]
        (scene files are in metres, so normally 1); ``uv_set`` is read from the mesh files.
    load_mesh : callable
        Loads a mesh file (:data:`LoadMesh`).

    Returns
    -------
    Collected
        With the camera (named ``"camera"``) in :attr:`~Collected.cameras` and the
        ``[output]`` values by key of :data:`OUTPUT_KEYS` in :attr:`~Collected.output`.

    Raises
    ------
    SceneError
        Naming the TOML file and, where one is at fault, the dotted key: unparseable TOML,
        unknown keys, wrong types or ranges, missing or unloadable mesh files (naming both
        files), material names no mesh has.
    """
    return _describe(_parse(path, options, load_mesh), options)


# --------------------------------------------------------------------------- materials


@dataclass(frozen=True, eq=False)
class _Emission:
    """An emission definition; power and flux wait for the area they spread over.

    ``exitance`` [W m-2] is final when the file gives exitance or radiance; otherwise
    ``power_w`` [W] or ``flux_lm`` [lm] is spread over the area of every face this
    definition ends up on, in the colour ``rgb`` (luminance 1).
    """

    key: tv.Key
    rgb: tuple[float, float, float]
    exitance: tuple[float, float, float] | None = None
    power_w: float | None = None
    flux_lm: float | None = None


@dataclass(frozen=True)
class _Override:
    """The material properties one TOML table sets; None where it leaves the file's value."""

    reflectance: tuple[float, float, float] | None = None
    double_sided: bool | None = None
    emission: _Emission | None = None


def _parse_materials(key: tv.Key, value: Any) -> dict[str, _Override]:
    """A table of material tables by name (``[materials]``, ``[mesh.materials]``)."""
    return {
        name: _parse_material(key / name, spec)
        for name, spec in tv.table(key, value, _any_name(value)).items()
    }


def _parse_material(key: tv.Key, value: Any) -> _Override:
    """A ``[materials.NAME]`` or ``[mesh.materials.NAME]`` table."""
    table = tv.table(key, value, MATERIAL_KEYS)
    double_sided = None
    if "double_sided" in table:
        double_sided = tv.boolean(key / "double_sided", table["double_sided"])
    return _Override(_parse_reflectance(key, table), double_sided, _parse_emission(key, table))


def _parse_reflectance(key: tv.Key, table: dict[str, Any]) -> tuple[float, float, float] | None:
    which = tv.one_of(key, table, REFLECTANCE_KEYS)
    if which is None:
        return None
    where = key / which
    value = table[which]
    if which == "reflectance":
        return tv.triple(tv.rgb(where, value, 0.0, 1.0))
    if which == "reflectance_spectrum":
        spectrum = tv.table(where, value, SPECTRUM_KEYS)
        wavelengths = tv.numbers(
            where / "wavelengths", tv.required(where, spectrum, "wavelengths"), None, 0.0
        )
        values = tv.numbers(
            where / "values", tv.required(where, spectrum, "values"), len(wavelengths), 0.0, 1.0
        )
        rgb = tv.colorimetry(where, colorimetry.reflectance_to_rgb, wavelengths, values)
    else:
        name = tv.string(where, value)
        spectrum_nm = tv.colorimetry(where, lambda: np.stack(colorimetry.named_reflectance(name)))
        rgb = tv.colorimetry(where, colorimetry.reflectance_to_rgb, *spectrum_nm)
    clipped = np.clip(rgb, 0.0, 1.0)
    if not np.array_equal(clipped, rgb):
        log.warning(
            "%s: %s: linear RGB %s is outside [0, 1] (outside the BT.709 gamut); clipped",
            key.file,
            where.dotted,
            np.round(rgb, 4).tolist(),
        )
    return tv.triple(clipped)


def _parse_emission(key: tv.Key, table: dict[str, Any]) -> _Emission | None:
    amount = tv.one_of(key, table, AMOUNT_KEYS)
    colour_kind = tv.one_of(key, table, COLOUR_KEYS)
    if amount is None:
        if colour_kind is not None:
            raise (key / colour_kind).error(
                f"an emission colour needs an amount: add one of {', '.join(AMOUNT_KEYS)}"
            )
        return None
    rgb = np.ones(3)
    if colour_kind is not None:
        where = key / colour_kind
        value = table[colour_kind]
        if colour_kind == "temperature_k":
            value = tv.number(where, value, *TEMPERATURE_RANGE_K)
        elif colour_kind == "illuminant":
            value = tv.string(where, value)
        else:
            value = tv.rgb(where, value)
        rgb = tv.colorimetry(where, colorimetry.emitter_rgb, colour_kind, value)
    where = key / amount
    value = table[amount]
    if amount in ("exitance", "radiance"):
        if isinstance(value, list) and colour_kind is not None:
            raise where.error(
                f"an RGB {amount} has its own colour; give one number with "
                f"'{(key / colour_kind).dotted}'"
            )
        exitance = tv.rgb(where, value) * rgb
        if amount == "radiance":
            exitance = math.pi * exitance  # Lambertian: E = pi L
        return _Emission(key, tv.triple(rgb), exitance=tv.triple(exitance))
    number = tv.number(where, value, 0.0)
    if amount == "power_w":
        return _Emission(key, tv.triple(rgb), power_w=number)
    return _Emission(key, tv.triple(rgb), flux_lm=number)


# --------------------------------------------------------------------------- meshes


@dataclass(frozen=True, eq=False)
class _Part:
    """The faces of one material of one placed mesh.

    ``positions`` (n, 3) float64 [m, before the load scale], ``triangles`` (t, 3) int64,
    ``area`` their total area [m2, before the load scale], and the resolved material
    (its emitted exitance final unless ``emission`` spreads a power or flux); the object
    they belong to and (n, 2) lightmap UVs (NaN where the mesh file has none).
    """

    positions: np.ndarray
    triangles: np.ndarray
    area: float
    material: Material
    emission: _Emission | None
    object_name: str
    uv: np.ndarray


def _rotation(axis: int, degrees: float) -> np.ndarray:
    """(3, 3) rotation by ``degrees`` about coordinate axis 0, 1 or 2 (right-handed)."""
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    matrix = np.eye(3)
    matrix[i, i], matrix[i, j], matrix[j, i], matrix[j, j] = c, -s, s, c
    return matrix


def _parse_transform(key: tv.Key, table: dict[str, Any]) -> np.ndarray:
    """(4, 4) ``world_from_file``: ``transform``, or ``translate`` . Rz Ry Rx . ``scale``."""
    parts = [k for k in ("translate", "rotate_deg", "scale") if k in table]
    world_from_file = np.eye(4)
    if "transform" in table:
        if parts:
            raise (key / parts[0]).error(f"cannot be combined with '{(key / 'transform').dotted}'")
        where = key / "transform"
        rows = table["transform"]
        if not isinstance(rows, list) or len(rows) != 4:
            raise where.error(f"expected 4 rows of 4 numbers (row-major), got {tv.show(rows)}")
        world_from_file = np.stack([tv.numbers(where.index(i), r, 4) for i, r in enumerate(rows)])
        if not np.array_equal(world_from_file[3], [0.0, 0.0, 0.0, 1.0]):
            raise where.error(
                f"the last row must be [0, 0, 0, 1] (an affine transform), got "
                f"{world_from_file[3].tolist()}"
            )
    else:
        if "scale" in table:
            factors = tv.rgb(key / "scale", table["scale"], -math.inf)
            world_from_file[:3, :3] = np.diag(factors)
        if "rotate_deg" in table:
            angles = tv.numbers(key / "rotate_deg", table["rotate_deg"], 3)
            rotation = _rotation(2, angles[2]) @ _rotation(1, angles[1]) @ _rotation(0, angles[0])
            world_from_file[:3, :3] = rotation @ world_from_file[:3, :3]
        if "translate" in table:
            world_from_file[:3, 3] = tv.numbers(key / "translate", table["translate"], 3)
    linear = world_from_file[:3, :3]
    determinant = float(np.linalg.det(linear))
    size = float(np.prod(np.linalg.norm(linear, axis=0)))
    if not (math.isfinite(determinant) and abs(determinant) > tol.singular * size):
        where = key / ("transform" if "transform" in table else "scale")
        raise where.error("the transform is singular (it flattens the mesh)")
    return world_from_file


def _load_mesh(
    key: tv.Key, table: dict[str, Any], options: ReadOptions, load_mesh: LoadMesh
) -> tuple[Path, Scene]:
    """The mesh file of a ``[[mesh]]`` table, loaded; errors name both files."""
    where = key / "file"
    name = tv.string(where, tv.required(key, table, "file"))
    mesh_path = key.file.parent / name
    if mesh_path.suffix.lower() == ".toml":
        raise where.error(f"{name!r}: a scene file cannot include another TOML scene")
    folder = key.file.parent.resolve()
    if not options.allow_outside and not mesh_path.resolve().is_relative_to(folder):
        raise where.error(
            f"mesh file {name!r} lies outside the scene folder {str(folder)!r} "
            "(--allow-outside-files reads it)"
        )
    if not mesh_path.exists():
        raise where.error(f"mesh file {str(mesh_path)!r} not found")
    if not mesh_path.is_file():
        raise where.error(f"mesh file {str(mesh_path)!r} is not a regular file")
    try:
        return mesh_path, load_mesh(mesh_path, options)
    except SceneError as exc:
        raise where.error(f"cannot load mesh file: {exc}") from None


def _overlay(material: Material, override: _Override | None) -> tuple[Material, _Emission | None]:
    """``material`` with what ``override`` sets; the emission when it still needs an area."""
    if override is None:
        return material, None
    if override.reflectance is not None:
        material = replace(material, reflectance=override.reflectance)
    if override.double_sided is not None:
        material = replace(material, double_sided=override.double_sided)
    emission = override.emission
    if emission is not None and emission.exitance is not None:
        return replace(material, emitted_exitance=emission.exitance), None
    return material, emission


def _parse_mesh(
    key: tv.Key,
    value: Any,
    shared: dict[str, _Override],
    options: ReadOptions,
    taken: set[str],
    load_mesh: LoadMesh,
) -> tuple[list[_Part], set[str]]:
    """The placed parts of one ``[[mesh]]`` and the material names its file has.

    The mesh is one object named by its ``name`` key (else the file's stem; ``_<k>``
    appended when taken), or ``<name>/<object>`` for each object of a file with several.
    """
    table = tv.table(key, value, MESH_KEYS)
    world_from_file = _parse_transform(key, table)
    overrides_key = key / "materials"
    overrides = _parse_materials(overrides_key, table.get("materials", {}))
    mesh_path, mesh = _load_mesh(key, table, options, load_mesh)
    object_names = _object_names(key, table, mesh_path, mesh, taken)
    names = set(mesh.material_names)
    for name in overrides:
        if name not in names:
            raise (overrides_key / name).error(
                f"{mesh_path.name!r} has no material of this name "
                f"(it has: {', '.join(sorted(names))})"
            )
    positions = mesh.positions @ world_from_file[:3, :3].T + world_from_file[:3, 3]
    triangles = mesh.triangles
    mirror = np.linalg.det(world_from_file[:3, :3]) < 0.0  # not singular: the sign is sure
    if mirror:  # keep the front side lit
        triangles = triangles[:, ::-1]
    areas, _ = triangle_areas_normals(positions[triangles])
    uv = mesh.lightmap_uv
    if uv is not None and mirror:
        uv = uv[:, ::-1]
    parts = []
    groups = np.unique(np.column_stack([mesh.material_index, mesh.object_index]), axis=0)
    for index, obj in groups.tolist():
        name = mesh.material_names[index]
        mine = (mesh.material_index == index) & (mesh.object_index == obj)
        material = Material(
            name,
            tv.triple(mesh.material_reflectance[index]),
            tv.triple(mesh.material_emitted_exitance[index]),
            bool(mesh.material_double_sided[index]),
        )
        material, pending = _overlay(material, shared.get(name))
        override = overrides.get(name)
        if override is not None:
            material, own = _overlay(material, override)
            if override.emission is not None:  # the mesh's emission replaces the shared one
                pending = own
        if uv is None:
            local_positions, local_triangles = compact(positions, triangles[mine])
            local_uv = np.full((len(local_positions), 2), np.nan)
        else:  # one vertex per corner keeps each corner's UV
            corners = triangles[mine]
            local_positions = positions[corners].reshape(-1, 3)
            local_triangles = np.arange(corners.size).reshape(-1, 3)
            local_uv = uv[mine].reshape(-1, 2)
        parts.append(
            _Part(
                local_positions,
                local_triangles,
                float(areas[mine].sum()),
                material,
                pending,
                object_names[obj],
                local_uv,
            )
        )
    return parts, names


def _object_names(
    key: tv.Key, table: dict[str, Any], mesh_path: Path, mesh: Scene, taken: set[str]
) -> list[str]:
    """Unique names of the objects of one ``[[mesh]]`` (see :func:`_parse_mesh`)."""
    base = tv.string(key / "name", table["name"]) if "name" in table else mesh_path.stem
    if "name" in table and base in taken:
        raise (key / "name").error(f"another [[mesh]] is already named {base!r}")
    name, k = base, 0
    while name in taken:
        k += 1
        name = f"{base}_{k}"
    if len(mesh.object_names) == 1:
        names = [name]
    else:
        names = [f"{name}/{inner}" for inner in mesh.object_names]
    taken.update(names)
    taken.add(name)
    return names


def _any_name(value: Any) -> tuple[str, ...]:
    """Every key of a table whose keys are names (material overrides)."""
    return tuple(value) if isinstance(value, dict) else ()


# --------------------------------------------------------------------------- camera, output


def _parse_camera(key: tv.Key, value: Any) -> Camera:
    table = tv.table(key, value, CAMERA_KEYS)
    position = tv.numbers(key / "position", tv.required(key, table, "position"), 3)
    look_at = tv.numbers(key / "look_at", tv.required(key, table, "look_at"), 3)
    up = tv.numbers(key / "up", table.get("up", [0.0, 1.0, 0.0]), 3)
    fov = defaults.vertical_fov_deg
    if "vertical_fov_deg" in table:
        fov = tv.number(key / "vertical_fov_deg", table["vertical_fov_deg"], 0.0, 180.0, True)
        if fov >= 180.0:
            raise (key / "vertical_fov_deg").error(f"{fov:g} is outside (0, 180)")
    forward = look_at - position
    if np.linalg.norm(forward) == 0.0:
        raise (key / "look_at").error(f"equals '{(key / 'position').dotted}'")
    if np.linalg.norm(np.cross(forward, up)) <= tol.parallel * np.linalg.norm(
        forward
    ) * np.linalg.norm(up):
        raise (key / "up").error("is zero or parallel to the view direction")
    return Camera(tv.triple(position), tv.triple(look_at), tv.triple(up), fov)


def _parse_output(key: tv.Key, value: Any) -> dict[str, float | int]:
    table = tv.table(key, value, OUTPUT_KEYS)
    output: dict[str, float | int] = {}
    for name, given in table.items():
        spec, where = OUTPUT_KEYS[name], key / name
        if spec.kind is int and not (isinstance(given, int) and not isinstance(given, bool)):
            raise where.error(f"expected an integer, got {tv.show(given)}")
        number = tv.number(where, given, spec.low, spec.high, spec.low_open)
        output[name] = int(given) if spec.kind is int else number
    return output


# --------------------------------------------------------------------------- the file


@dataclass(frozen=True, eq=False)
class _Parsed:
    """A checked scene file whose power and flux emitters still need the load scale."""

    path: Path
    parts: list[_Part]
    camera: Camera | None
    output: dict[str, float | int]


def _read_toml(path: Path) -> dict[str, Any]:
    try:
        with path.open("rb") as f:
            return tomllib.load(f)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(path, f"cannot parse as TOML: {exc}") from None
    except UnicodeDecodeError as exc:
        raise SceneError(path, f"cannot parse as TOML: not UTF-8 text ({exc.reason})") from None
    except RecursionError:
        raise SceneError(path, "cannot parse as TOML: nesting too deep") from None
    except OSError as exc:
        raise SceneError(path, f"cannot read the file: {exc.strerror or exc}") from exc


def _parse(path: Path, options: ReadOptions, load_mesh: LoadMesh) -> _Parsed:
    """Read and check a TOML scene file and load and place its meshes."""
    root = tv.Key(path)
    document = tv.table(root, _read_toml(path), TOP_KEYS)
    materials_key = root / "materials"
    shared = _parse_materials(materials_key, document.get("materials", {}))
    meshes = tv.required(root, document, "mesh")
    if not isinstance(meshes, list) or not meshes:
        raise (root / "mesh").error("expected one or more [[mesh]] tables")
    parts: list[_Part] = []
    found: set[str] = set()
    taken: set[str] = set()
    for i, mesh in enumerate(meshes):
        mesh_parts, names = _parse_mesh(
            (root / "mesh").index(i), mesh, shared, options, taken, load_mesh
        )
        parts.extend(mesh_parts)
        found |= names
    for name in shared:
        if name not in found:
            raise (materials_key / name).error(
                f"no mesh has a material of this name (they have: {', '.join(sorted(found))})"
            )
    camera = _parse_camera(root / "camera", document["camera"]) if "camera" in document else None
    output = _parse_output(root / "output", document.get("output", {}))
    return _Parsed(path, parts, camera, output)


def _describe(parsed: _Parsed, options: ReadOptions) -> Collected:
    """The scene at the read scale [m per scene unit], power and flux spread over scaled
    areas, with the camera (scaled) and the output values."""
    scale = options.scale
    emitting_area: dict[_Emission, float] = {}
    for part in parsed.parts:
        if part.emission is not None:
            sides = 2.0 if part.material.double_sided else 1.0
            area = part.area * scale * scale * sides
            emitting_area[part.emission] = emitting_area.get(part.emission, 0.0) + area
    collected = Collected(parsed.path, options)
    for part in parsed.parts:
        material, emission = part.material, part.emission
        if emission is not None:
            convert = (
                colorimetry.exitance_from_power
                if emission.power_w is not None
                else colorimetry.exitance_from_flux
            )
            amount = emission.power_w if emission.power_w is not None else emission.flux_lm
            exitance = tv.colorimetry(
                emission.key, convert, amount, emitting_area[emission], emission.rgb
            )
            material = replace(material, emitted_exitance=tv.triple(exitance))
        collected.add(part.positions, part.triangles, material, part.object_name, part.uv)
    camera = parsed.camera
    if camera is not None:
        if scale != 1.0:
            camera = replace(
                camera,
                position=tv.triple(np.multiply(camera.position, scale)),
                look_at=tv.triple(np.multiply(camera.look_at, scale)),
            )
        collected.cameras = [NamedCamera("camera", camera)]
    collected.output = dict(parsed.output)
    return collected


__all__ = [
    "AMOUNT_KEYS",
    "CAMERA_KEYS",
    "COLOUR_KEYS",
    "MATERIAL_KEYS",
    "MESH_KEYS",
    "OUTPUT_KEYS",
    "REFLECTANCE_KEYS",
    "SPECTRUM_KEYS",
    "TEMPERATURE_RANGE_K",
    "TOP_KEYS",
    "LoadMesh",
    "OutputKey",
    "read_toml",
]
