"""Scene files (OBJ + MTL, glTF 2.0, PLY) to a validated :class:`~raytrad.scene.Scene`.

trimesh parses the geometry (imported lazily, only here); material values are read exactly
from the files themselves: MTL ``Kd``/``Ke`` floats, glTF JSON factors, PLY face properties.
Every failure is a :class:`~raytrad.errors.SceneError` naming the file.

Units: file coordinates times ``scale`` are metres [m]; reflectance is linear RGB [1];
emitted exitance is [W m-2].
"""

from __future__ import annotations

import io
import json
import logging
import math
import os
import re
import struct
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from raytrad.errors import SceneError, SettingsError
from raytrad.scene import Scene, make_scene

if TYPE_CHECKING:
    import trimesh

log = logging.getLogger(__name__)

DEFAULT_REFLECTANCE = 0.5
"""Grey reflectance [1] given to faces whose file says nothing about their material."""


@dataclass(frozen=True)
class _Material:
    """One material as read from a file: reflectance [1], emitted exitance [W m-2]."""

    name: str
    reflectance: tuple[float, float, float]
    emitted_exitance: tuple[float, float, float] = (0.0, 0.0, 0.0)
    double_sided: bool = False


_DEFAULT_OBJ_MATERIAL = _Material("default", (DEFAULT_REFLECTANCE,) * 3)


@dataclass
class _Collected:
    """Triangle groups gathered from one file, each with a material (deduplicated by name).

    ``uv_set`` is the texture-coordinate set asked for as lightmap UVs (None: none);
    loaders pass each group's per-vertex UVs of that set (v down), or nothing when the
    group has none.
    """

    path: Path
    uv_set: int | None = None
    positions: list[np.ndarray] = field(default_factory=list)
    triangles: list[np.ndarray] = field(default_factory=list)
    material_index: list[np.ndarray] = field(default_factory=list)
    object_index: list[np.ndarray] = field(default_factory=list)
    uv: list[np.ndarray] = field(default_factory=list)
    materials: dict[str, tuple[int, _Material]] = field(default_factory=dict)
    objects: dict[str, int] = field(default_factory=dict)
    warned: set[str] = field(default_factory=set)
    vertex_count: int = 0

    def add(
        self,
        positions: np.ndarray,
        triangles: np.ndarray,
        material: _Material,
        object_name: str | None = None,
        uv: np.ndarray | None = None,
    ) -> None:
        """Append (n, 3) positions [file units] and (t, 3) local triangles of one material.

        Materials are shared by name; a different material with a name already taken
        (say a file's own "default") is renamed ``<name>_<k>``. ``object_name`` names the
        mesh the faces belong to (None: the file's stem); ``uv`` is (n, 2) lightmap UVs
        [1] of the positions, v down.
        """
        base, k = material.name, 0
        while material.name in self.materials and self.materials[material.name][1] != material:
            k += 1
            material = replace(material, name=f"{base}_{k}")
        if material.name not in self.materials:
            self.materials[material.name] = (len(self.materials), material)
        index = self.materials[material.name][0]
        object_name = self.path.stem if object_name is None else object_name
        obj = self.objects.setdefault(object_name, len(self.objects))
        positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
        triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
        if uv is None:
            uv = np.full((len(positions), 2), np.nan)
        self.positions.append(positions)
        self.triangles.append(triangles + self.vertex_count)
        self.material_index.append(np.full(len(triangles), index, dtype=np.int64))
        self.object_index.append(np.full(len(triangles), obj, dtype=np.int64))
        self.uv.append(np.asarray(uv, dtype=np.float64).reshape(-1, 2))
        self.vertex_count += len(positions)

    def warn_once(self, key: str, message: str, *args: object) -> None:
        """Log a warning about this file the first time ``key`` comes up."""
        if key not in self.warned:
            self.warned.add(key)
            log.warning("%s: " + message, self.path, *args)

    def to_scene(self, scale: float) -> Scene:
        """The validated scene, positions times ``scale`` [m]."""
        if not self.triangles or sum(len(t) for t in self.triangles) == 0:
            raise SceneError(self.path, "the file contains no triangle faces")
        materials = [m for _, m in sorted(self.materials.values(), key=lambda im: im[0])]
        triangles = np.concatenate(self.triangles)
        lightmap_uv = None
        if self.uv_set is not None:
            lightmap_uv = np.concatenate(self.uv)[triangles]
        return make_scene(
            positions=np.concatenate(self.positions) * scale,
            triangles=triangles,
            material_index=np.concatenate(self.material_index),
            material_names=[m.name for m in materials],
            material_reflectance=np.array([m.reflectance for m in materials]),
            material_emitted_exitance=np.array([m.emitted_exitance for m in materials]),
            material_double_sided=np.array([m.double_sided for m in materials], dtype=bool),
            source=self.path,
            object_index=np.concatenate(self.object_index),
            object_names=list(self.objects),
            lightmap_uv=lightmap_uv,
        )


def checked_path(path: str | os.PathLike[str], scale: float) -> tuple[Path, float]:
    """The path of an existing regular file and a valid scale, or the error naming them."""
    path = Path(path)
    scale = float(scale)
    if not (math.isfinite(scale) and scale > 0.0):
        raise SettingsError(f"scale must be a finite number > 0, not {scale}")
    if not path.exists():
        raise SceneError(path, "file not found")
    if not path.is_file():
        raise SceneError(path, "not a regular file")
    return path, scale


def load_scene(
    path: str | os.PathLike[str], scale: float = 1.0, uv_set: int | None = None
) -> Scene:
    """Load a scene file, dispatching on its suffix through :data:`LOADERS`.

    Parameters
    ----------
    path : path-like
        An ``.obj`` (with its ``.mtl``), ``.gltf``, ``.glb`` or ``.ply`` file.
    scale : float
        Metres per file unit [m], for example 0.001 for a file in millimetres.
    uv_set : int or None
        Read this texture-coordinate set as the lightmap UVs (``Scene.lightmap_uv``): glTF
        ``TEXCOORD_<n>``; OBJ ``vt`` and PLY ``s, t`` (or ``u, v``) are set 0. Faces
        without it get NaN UVs. None reads no UVs.

    Returns
    -------
    Scene
        Validated, with ``source`` set to ``path``.

    Raises
    ------
    SceneError
        Naming the file: missing, unsupported type, unparseable, no triangle faces,
        non-finite coordinates, reflectance outside [0, 1] or negative emission.
    SettingsError
        If ``scale`` is not a finite positive number.
    """
    path, scale = checked_path(path, scale)
    if uv_set is not None and uv_set < 0:
        raise SettingsError(f"uv set must be >= 0, not {uv_set}")
    loader = LOADERS.get(path.suffix.lower())
    if loader is None:
        supported = ", ".join(sorted(LOADERS))
        raise SceneError(
            path, f"unsupported file type {path.suffix or '(no suffix)'!r}; use one of {supported}"
        )
    try:
        collected = loader(path, uv_set)
    except OSError as exc:
        raise SceneError(path, f"cannot read the file: {exc.strerror or exc}") from exc
    scene = collected.to_scene(scale)
    log.info(
        "%s: %d triangles, %d materials", path, scene.triangle_count, len(scene.material_names)
    )
    return scene


# --------------------------------------------------------------------------- shared helpers


def _reason(exc: BaseException) -> str:
    """A one-line, short description of a parser exception."""
    text = " ".join(str(exc).split())
    text = text if text else type(exc).__name__
    return text if len(text) <= 160 else text[:157] + "..."


def _rgb(path: Path, value: Any, what: str) -> tuple[float, float, float]:
    """Three floats from 1 or 3 numbers (or numeric strings); SceneError otherwise."""
    try:
        values = [float(v) for v in np.atleast_1d(np.asarray(value, dtype=object)).tolist()]
    except (TypeError, ValueError):
        raise SceneError(path, f"{what}: {value!r} is not a number or RGB triple") from None
    if len(values) == 1:
        values *= 3
    if len(values) != 3:
        raise SceneError(path, f"{what}: expected 1 or 3 numbers, got {len(values)}")
    return (values[0], values[1], values[2])


def _compact(vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Only the vertices the triangles use, and the triangles renumbered to them.

    Returns
    -------
    positions : (n, 3) float64
    triangles : (t, 3) int64
    """
    used, local = _used_vertices(triangles)
    return np.asarray(vertices, dtype=np.float64)[used], local


def _used_vertices(triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(n,) indices of the vertices the triangles use, and (t, 3) triangles over them."""
    used, local = np.unique(np.asarray(triangles, dtype=np.int64).ravel(), return_inverse=True)
    return used, local.reshape(-1, 3)


def _node_object(tm_scene: trimesh.Scene, node: str) -> str:
    """The glTF node a trimesh geometry node stands for.

    trimesh names the primitives of a mesh with several ``<node>_<6 hex digits>`` under a
    geometry-less parent ``<node>``; a single primitive is the node itself.
    """
    parent = tm_scene.graph.transforms.parents.get(node)
    if (
        parent is not None
        and parent not in tm_scene.graph.nodes_geometry
        and re.fullmatch(re.escape(str(parent)) + r"_[0-9a-f]{6}", node)
    ):
        return str(parent)
    return node


def _top_down_uv(collected: _Collected, geometry: trimesh.Trimesh) -> np.ndarray | None:
    """(n, 2) per-vertex UVs of a trimesh geometry with v down, or None without any.

    trimesh stores UVs with v up (OBJ's convention; it flips glTF's), so v is flipped back.
    """
    if collected.uv_set is None:
        return None
    uv = getattr(geometry.visual, "uv", None)
    if uv is None or len(uv) != len(geometry.vertices):
        return None
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    return np.column_stack([uv[:, 0], 1.0 - uv[:, 1]])


def _add_trimesh_scene(
    collected: _Collected,
    tm_scene: trimesh.Scene,
    material_of: Callable[[trimesh.Trimesh], _Material],
    object_of: Callable[[str, trimesh.Trimesh], str | None] | None = None,
    uv_available: bool = True,
    node_order: list[str] | None = None,
) -> None:
    """Add every triangle geometry of a trimesh scene, placed by its node transform.

    Geometry without faces (points, paths) is skipped. A transform that mirrors
    (negative determinant) would turn front faces into back faces, so their winding is
    reversed to keep the front side facing where the mirrored surface faces.
    ``object_of(node, geometry)`` names the object (mesh) the geometry belongs to (None,
    or no ``object_of``: the file's stem); ``uv_available``: whether trimesh's UVs are the
    set asked for; ``node_order``: object names in file order, to add objects in.
    """
    import trimesh

    objects = object_of or (lambda node, geometry: None)
    placed = []
    for node in tm_scene.graph.nodes_geometry:
        matrix, geometry_name = tm_scene.graph[node]
        geometry = tm_scene.geometry.get(geometry_name)
        if isinstance(geometry, trimesh.Trimesh) and len(geometry.faces):
            placed.append((matrix, geometry, objects(str(node), geometry)))
    if node_order:  # objects in the file's order, not trimesh's graph order
        rank = {name: i for i, name in enumerate(node_order)}
        placed.sort(key=lambda item: rank.get(item[2] or "", len(rank)))
    for matrix, geometry, object_name in placed:
        if geometry.vertices.ndim != 2 or geometry.vertices.shape[1] != 3:
            raise SceneError(
                collected.path,
                f"vertices must have 3 coordinates, found {geometry.vertices.shape[-1]}",
            )
        used, local = _used_vertices(geometry.faces)
        vertices = np.asarray(geometry.vertices, dtype=np.float64)[used]
        uv = _top_down_uv(collected, geometry) if uv_available else None
        transform = np.asarray(matrix, dtype=np.float64)
        with np.errstate(invalid="ignore", over="ignore"):  # non-finite input is reported later
            positions = vertices @ transform[:3, :3].T + transform[:3, 3]
        if np.linalg.det(transform[:3, :3]) < 0.0:
            local = local[:, ::-1]
        collected.add(
            positions,
            local,
            material_of(geometry),
            object_name,
            None if uv is None else uv[used],
        )


# --------------------------------------------------------------------------- OBJ + MTL

_SCALAR_COLOUR = re.compile(
    rb"^([ \t]*K[ads][ \t]+)(\S+)[ \t]*(\r?)$", re.IGNORECASE | re.MULTILINE
)


def _load_obj(path: Path, uv_set: int | None = None) -> _Collected:
    """OBJ geometry through trimesh; ``Kd`` (reflectance) and ``Ke`` [W m-2] from the MTL.

    ``vt`` coordinates are UV set 0. trimesh keeps them per corner only when it may split
    vertices by (v, vt) pair (``maintain_order=False``), so that is how UVs are read.
    """
    import trimesh

    data = path.read_bytes()
    if b"\0" in data:
        raise SceneError(path, "cannot parse as OBJ: binary data (NUL bytes), not OBJ text")
    # Undecodable bytes (a Latin-1 comment, say) become U+FFFD instead of failing in trimesh.
    text = data.decode("utf-8", errors="replace").encode("utf-8")
    text, object_names, material_objects = _tag_objects(text)
    resolver = _mtl_resolver(path.parent, material_objects)
    collected = _Collected(path, uv_set)
    try:
        tm_scene = trimesh.load_scene(  # = trimesh.load(..., force="scene")
            io.BytesIO(text),
            file_type="obj",
            resolver=resolver,
            process=False,
            group_material=True,
            maintain_order=uv_set != 0,
        )
    except Exception as exc:  # trimesh raises many types for malformed input
        raise SceneError(path, f"cannot parse as OBJ: {_reason(exc)}") from exc
    declared: set[str] = resolver.declared  # type: ignore[attr-defined]
    if not declared and re.search(rb"^[ \t]*mtllib", data, re.MULTILINE):
        collected.warn_once("mtllib", "its mtllib file is missing or declares no materials")

    def object_of(node: str, geometry: trimesh.Trimesh) -> str | None:
        material = getattr(geometry.visual, "material", None)
        tagged = _OBJECT_TAG.match(str(getattr(material, "name", "")))
        return None if tagged is None else object_names[int(tagged.group(2))]

    _add_trimesh_scene(
        collected,
        tm_scene,
        lambda g: _obj_material(collected, declared, g),
        object_of,
        uv_available=uv_set == 0,
        node_order=object_names,
    )
    return collected


_STAND_IN_MTL = b"__raytrad_objects__.mtl"
_OBJECT_TAG = re.compile(r"^(.*)__raytrad_object_(\d+)__$", re.DOTALL)
_OBJECT_LINE = re.compile(rb"^[ \t]*(o|g|usemtl)(?:[ \t]+([^\r\n]*?))?[ \t]*(\r?)$", re.MULTILINE)


def _tag_objects(text: bytes) -> tuple[bytes, list[str], dict[str, set[int]]]:
    """OBJ text whose ``usemtl`` names also say which object they are used in.

    trimesh (5.2) groups OBJ faces by material but mislabels its objects, so the object
    goes into the material name: ``usemtl M`` inside object ``k`` becomes ``usemtl
    M__raytrad_object_k__``, and each ``o`` line restates the current material, tagged.
    Objects are ``o`` statements, or ``g`` groups in a file without any ``o``; a file with
    neither is returned unchanged. A file without ``mtllib`` gets one naming a stand-in
    MTL file, which the resolver of :func:`_mtl_resolver` fills with the tagged names.

    Returns
    -------
    text : bytes
    object_names : list of str
        Name of object ``k`` (repeated names are one object).
    material_objects : dict of str to set of int
        The objects each material name (``""`` for none) is used in.
    """
    keyword = b"o" if re.search(rb"^[ \t]*o[ \t]+\S", text, re.MULTILINE) else b"g"
    if not re.search(rb"^[ \t]*" + keyword + rb"[ \t]+\S", text, re.MULTILINE):
        return text, [], {}
    tagger = _ObjectTagger(keyword)
    text = _OBJECT_LINE.sub(tagger, text)
    if not re.search(rb"^[ \t]*mtllib[ \t]", text, re.MULTILINE):
        text = b"mtllib " + _STAND_IN_MTL + b"\n" + text  # to declare the tagged names
    return text, tagger.names, tagger.used


class _ObjectTagger:
    """The ``re.sub`` callback of :func:`_tag_objects`, keeping the current material and
    object as it walks the ``o``/``g``/``usemtl`` lines in file order."""

    def __init__(self, keyword: bytes) -> None:
        self.keyword = keyword
        self.material = ""
        self.object = -1
        self.names: list[str] = []
        self.used: dict[str, set[int]] = {}

    def tagged(self) -> bytes:
        self.used.setdefault(self.material, set()).add(self.object)
        return f"usemtl {self.material}__raytrad_object_{self.object}__".encode()

    def __call__(self, match: re.Match[bytes]) -> bytes:
        word, cr = match.group(1), match.group(3)
        rest = (match.group(2) or b"").decode("utf-8", errors="replace")
        if word == b"usemtl":
            self.material = rest
            return self.tagged() + cr if self.object >= 0 else match.group(0)
        if word != self.keyword or not rest:
            return match.group(0)
        if rest not in self.names:
            self.names.append(rest)
        self.object = self.names.index(rest)
        return match.group(0) + b"\n" + self.tagged() + cr


def _mtl_resolver(
    directory: Path, material_objects: dict[str, set[int]] | None = None
) -> trimesh.resolvers.FilePathResolver:
    """A file resolver that fixes MTL text for trimesh and notes the materials it declares.

    The MTL format allows ``Kd r`` for ``Kd r r r``, but trimesh 5.2 then fails to build
    every material of the file (silently), so one-number ``Kd``/``Ka``/``Ks`` lines are
    repeated to three numbers. The ``newmtl`` names read are kept in ``.declared`` to tell
    MTL materials from the placeholder trimesh gives faces that have none. Each material
    of ``material_objects`` is repeated under the object-tagged names of
    :func:`_tag_objects` (with an empty body when the MTL lacks it), so every tagged face
    group keeps its name through trimesh, which reads only the file's first ``mtllib``.
    """
    from trimesh.resolvers import FilePathResolver

    class _MtlResolver(FilePathResolver):
        declared: set[str]

        def get(self, name: str) -> bytes:
            try:
                data: bytes = super().get(name)
            except OSError:
                if not material_objects or not name.lower().endswith(".mtl"):
                    raise
                data = b""  # a missing (or the stand-in) MTL still carries the objects
            if name.lower().endswith(".mtl"):
                data = _SCALAR_COLOUR.sub(rb"\1\2 \2 \2\3", data)
                text = data.decode("utf-8", errors="replace")
                real = {
                    " ".join(words[1:])
                    for words in (line.split() for line in text.splitlines())
                    if len(words) > 1 and words[0].lower() == "newmtl"
                }
                self.declared.update(real)
                data += _tagged_copies(data, real, material_objects or {})
            return data

    resolver = _MtlResolver(str(directory))
    resolver.declared = set()
    return resolver


def _tagged_copies(mtl: bytes, real: set[str], material_objects: dict[str, set[int]]) -> bytes:
    """MTL blocks repeated under the object-tagged names of :func:`_tag_objects`.

    A material the MTL declares (in ``real``) is copied with its body; one it lacks (or
    no material, ``""``) gets an empty block, read as the grey default.
    """
    bodies: dict[str, bytes] = {}
    for block in re.split(rb"(?m)^(?=[ \t]*newmtl[ \t])", mtl):
        head, _, body = block.partition(b"\n")
        words = head.decode("utf-8", errors="replace").split()
        if len(words) > 1 and words[0].lower() == "newmtl":
            bodies.setdefault(" ".join(words[1:]), body)
    copies = [
        f"\nnewmtl {base}__raytrad_object_{k}__\n".encode() + bodies.get(base, b"")
        for base, objects in sorted(material_objects.items())
        for k in sorted(objects)
    ]
    return b"".join(copies)


def _obj_material(
    collected: _Collected, declared: set[str], geometry: trimesh.Trimesh
) -> _Material:
    """The MTL material of one trimesh geometry, or the grey default (warned once)."""
    material = getattr(geometry.visual, "material", None)
    name = getattr(material, "name", None)
    tagged = _OBJECT_TAG.match(name) if isinstance(name, str) else None
    name = name if tagged is None else tagged.group(1)
    if material is None or name not in declared:
        collected.warn_once(
            "default",
            "faces without an MTL material get reflectance %s grey and no emission",
            DEFAULT_REFLECTANCE,
        )
        return _DEFAULT_OBJ_MATERIAL
    name = str(name)
    path = collected.path
    values: dict[str, Any] = dict(getattr(material, "kwargs", None) or {})
    if "kd" in values:
        reflectance = _rgb(path, values["kd"], f"material {name!r} Kd")
    else:
        collected.warn_once(
            f"kd:{name}", "material %r has no Kd; using reflectance %s", name, DEFAULT_REFLECTANCE
        )
        reflectance = (DEFAULT_REFLECTANCE,) * 3
    emission = values.get("ke")
    emitted = (0.0, 0.0, 0.0) if emission is None else _rgb(path, emission, f"material {name!r} Ke")
    return _Material(name, reflectance, emitted, double_sided=False)


# --------------------------------------------------------------------------- glTF 2.0

_GLB_MAGIC = b"glTF"
_GLB_JSON = 0x4E4F534A
_MATERIAL_TOKEN = re.compile(r"^__raytrad_material_(\d+)__$")
_GLTF_DEFAULT_MATERIAL = _Material("default", (1.0, 1.0, 1.0))


def _load_gltf(path: Path, uv_set: int | None = None) -> _Collected:
    """A ``.gltf`` file (JSON, buffers beside it or as data URIs)."""
    try:
        document = json.loads(path.read_bytes().decode("utf-8-sig"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise SceneError(path, f"cannot parse as glTF: {_reason(exc)}") from None
    collected = _Collected(path, uv_set)
    materials = _gltf_materials(collected, document)
    _select_texcoord(collected, document)
    payload = json.dumps(document).encode("utf-8")
    return _load_gltf_payload(collected, payload, "gltf", materials, _node_names(document))


def _load_glb(path: Path, uv_set: int | None = None) -> _Collected:
    """A binary ``.glb`` file: its JSON chunk is rewritten, the BIN chunk kept as is."""
    json_bytes, rest = _split_glb(path, path.read_bytes())
    try:
        document = json.loads(json_bytes.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise SceneError(path, f"cannot parse as GLB: bad JSON chunk: {_reason(exc)}") from None
    collected = _Collected(path, uv_set)
    materials = _gltf_materials(collected, document)
    _select_texcoord(collected, document)
    payload = _join_glb(json.dumps(document).encode("utf-8"), rest)
    return _load_gltf_payload(collected, payload, "glb", materials, _node_names(document))


def _split_glb(path: Path, data: bytes) -> tuple[bytes, bytes]:
    """The JSON chunk's bytes and everything after it (the other chunks, headers included)."""
    if len(data) < 20 or data[:4] != _GLB_MAGIC:
        raise SceneError(path, "cannot parse as GLB: not a binary glTF file (bad magic)")
    _, version, length = struct.unpack_from("<4sII", data, 0)
    if version != 2:
        raise SceneError(path, f"cannot parse as GLB: glTF version {version}, need 2")
    chunk_length, chunk_type = struct.unpack_from("<II", data, 12)
    if length > len(data) or 20 + chunk_length > length:
        raise SceneError(path, f"cannot parse as GLB: truncated ({len(data)} of {length} bytes)")
    if chunk_type != _GLB_JSON:
        raise SceneError(path, "cannot parse as GLB: the first chunk is not JSON")
    return data[20 : 20 + chunk_length], data[20 + chunk_length : length]


def _join_glb(json_bytes: bytes, rest: bytes) -> bytes:
    """A GLB container from a JSON chunk (space-padded to 4 bytes) and the following chunks."""
    json_bytes += b" " * (-len(json_bytes) % 4)
    total = 12 + 8 + len(json_bytes) + len(rest)
    return (
        struct.pack("<4sII", _GLB_MAGIC, 2, total)
        + struct.pack("<II", len(json_bytes), _GLB_JSON)
        + json_bytes
        + rest
    )


def _gltf_materials(collected: _Collected, document: Any) -> list[_Material]:
    """Read every material of a glTF document and replace it by a name-only token.

    trimesh then sees ``{"name": "__raytrad_material_<i>__"}`` for material ``i``, which
    tells which material a loaded primitive uses without trimesh interpreting (or
    rejecting) any material value; images and textures are dropped for the same reason.
    """
    path = collected.path
    if not isinstance(document, dict):
        raise SceneError(path, "cannot parse as glTF: the JSON is not an object")
    specs = document.get("materials", [])
    if not isinstance(specs, list):
        raise SceneError(path, "glTF 'materials' is not a list")
    materials: list[_Material] = []
    names: set[str] = set()
    for i, spec in enumerate(specs):
        if not isinstance(spec, dict):
            raise SceneError(path, f"glTF material {i} is not an object")
        try:
            material = _gltf_material(collected, i, spec)
        except (AttributeError, TypeError) as exc:  # a key of the wrong JSON type
            raise SceneError(path, f"glTF material {i} is malformed: {_reason(exc)}") from None
        name = material.name if material.name not in names else f"{material.name}_{i}"
        names.add(name)
        materials.append(replace(material, name=name))
    if specs:
        document["materials"] = [{"name": f"__raytrad_material_{i}__"} for i in range(len(specs))]
    for key in ("textures", "images", "samplers"):
        document.pop(key, None)
    return materials


def _select_texcoord(collected: _Collected, document: dict[str, Any]) -> None:
    """Make ``TEXCOORD_<uv_set>`` the set trimesh reads, ``TEXCOORD_0``, in every primitive.

    trimesh reads only ``TEXCOORD_0``, and only for primitives with a material, so
    primitives without one get a token past the file's materials (glTF's default
    material, see :func:`_load_gltf_payload`). Without a ``uv_set`` nothing changes.
    """
    uv_set = collected.uv_set
    if uv_set is None:
        return
    tokens = document.setdefault("materials", [])
    default = len(tokens)
    needs_default = False
    for mesh in document.get("meshes", []) if isinstance(document.get("meshes"), list) else []:
        primitives = mesh.get("primitives", []) if isinstance(mesh, dict) else []
        for primitive in primitives if isinstance(primitives, list) else []:
            attributes = primitive.get("attributes") if isinstance(primitive, dict) else None
            if not isinstance(attributes, dict):
                continue
            accessor = attributes.pop(f"TEXCOORD_{uv_set}", None)
            for name in [a for a in attributes if a.startswith("TEXCOORD_")]:
                del attributes[name]
            if accessor is not None:
                attributes["TEXCOORD_0"] = accessor
            if "material" not in primitive:
                primitive["material"] = default
                needs_default = True
    if needs_default:
        tokens.append({"name": f"__raytrad_material_{default}__"})


def _gltf_material(collected: _Collected, index: int, spec: dict[str, Any]) -> _Material:
    """Reflectance, emitted exitance (pi x emitted radiance [W m-2]) and sidedness.

    reflectance = ``pbrMetallicRoughness.baseColorFactor[:3]``;
    emitted radiance = ``emissiveFactor`` x ``KHR_materials_emissive_strength.emissiveStrength``
    [W m-2 sr-1].
    """
    path = collected.path
    name = str(spec.get("name") or f"material_{index}")
    what = f"material {name!r}"
    pbr = spec.get("pbrMetallicRoughness") or {}
    base = pbr.get("baseColorFactor", [1.0, 1.0, 1.0, 1.0])
    if not isinstance(base, list) or len(base) not in (3, 4):
        raise SceneError(path, f"{what}: baseColorFactor {base!r} is not an RGBA list")
    reflectance = _rgb(path, base[:3], f"{what} baseColorFactor")
    factor = np.array(_rgb(path, spec.get("emissiveFactor", [0.0, 0.0, 0.0]), what))
    extension = (spec.get("extensions") or {}).get("KHR_materials_emissive_strength") or {}
    strength = extension.get("emissiveStrength", 1.0)
    if not isinstance(strength, int | float) or isinstance(strength, bool):
        raise SceneError(path, f"{what}: emissiveStrength {strength!r} is not a number")
    emitted = math.pi * (factor * float(strength))
    if "baseColorTexture" in pbr or "emissiveTexture" in spec:
        collected.warn_once(
            "texture", "material textures are ignored; their constant factors are used"
        )
    double_sided = spec.get("doubleSided", False)
    if not isinstance(double_sided, bool):
        raise SceneError(path, f"{what}: doubleSided {double_sided!r} is not true or false")
    return _Material(name, reflectance, (emitted[0], emitted[1], emitted[2]), double_sided)


def _node_names(document: dict[str, Any]) -> list[str]:
    """The names of a glTF document's nodes, in file order (unnamed ones left out)."""
    nodes = document.get("nodes")
    if not isinstance(nodes, list):
        return []
    return [str(n["name"]) for n in nodes if isinstance(n, dict) and "name" in n]


def _load_gltf_payload(
    collected: _Collected,
    payload: bytes,
    file_type: str,
    materials: list[_Material],
    node_order: list[str] | None = None,
) -> _Collected:
    """Parse the rewritten glTF/GLB bytes with trimesh and collect its triangles."""
    import trimesh
    from trimesh.resolvers import FilePathResolver

    path = collected.path
    try:
        tm_scene = trimesh.load_scene(  # = trimesh.load(..., force="scene")
            io.BytesIO(payload),
            file_type=file_type,
            resolver=FilePathResolver(str(path.parent)),
            process=False,
        )
    except Exception as exc:  # trimesh raises many types for malformed input
        label = "glTF" if file_type == "gltf" else "GLB"
        raise SceneError(path, f"cannot parse as {label}: {_reason(exc)}") from exc

    def material_of(geometry: trimesh.Trimesh) -> _Material:
        token = getattr(getattr(geometry.visual, "material", None), "name", None)
        match = _MATERIAL_TOKEN.match(token) if isinstance(token, str) else None
        if match is None or int(match.group(1)) >= len(materials):
            collected.warn_once(
                "default",
                "primitives without a material use glTF's default (reflectance 1, which "
                "has no finite solution in a closed scene)",
            )
            return _GLTF_DEFAULT_MATERIAL
        return materials[int(match.group(1))]

    _add_trimesh_scene(
        collected,
        tm_scene,
        material_of,
        lambda node, geometry: _node_object(tm_scene, node),
        node_order=node_order,
    )
    return collected


# --------------------------------------------------------------------------- PLY

_REFLECTANCE_PROPERTIES = ("reflectance_r", "reflectance_g", "reflectance_b")
_EMISSION_PROPERTIES = ("emitted_exitance_r", "emitted_exitance_g", "emitted_exitance_b")
_COLOUR_PROPERTIES = ("red", "green", "blue")


def _load_ply(path: Path, uv_set: int | None = None) -> _Collected:
    """PLY polygons (fan-triangulated) with per-face materials.

    Face properties ``reflectance_r/g/b`` [1] and ``emitted_exitance_r/g/b`` [W m-2], else
    ``red/green/blue`` uchar colours decoded from sRGB, else one grey default material.
    UV set 0 is the vertex properties ``s, t``, ``u, v`` or ``texture_u, texture_v`` (v up,
    as MeshLab and Blender write them).
    """
    from trimesh.exchange.ply import load_ply

    try:
        with path.open("rb") as f:
            raw = load_ply(f, fix_texture=False, skip_materials=True)["metadata"]["_ply_raw"]
        positions = np.column_stack([raw["vertex"]["data"][a] for a in "xyz"])
    except Exception as exc:  # trimesh raises many types for malformed input
        raise SceneError(path, f"cannot parse as PLY: {_reason(exc)}") from exc
    collected = _Collected(path, uv_set)
    uv = _ply_uv(raw["vertex"]["data"]) if uv_set == 0 else None
    face = raw.get("face") or {}
    if not face.get("length"):
        return collected
    columns = _ply_face_columns(face["data"])
    indices = columns.get("vertex_indices", columns.get("vertex_index"))
    if indices is None:
        raise SceneError(path, "PLY faces have no 'vertex_indices' list")
    triangles, source_face = _fan_triangulate(indices)
    if triangles.size and (triangles.min() < 0 or triangles.max() >= len(positions)):
        raise SceneError(path, f"a face refers to a vertex outside 0..{len(positions) - 1}")
    face_materials, materials = _ply_face_materials(collected, columns, len(indices))
    triangle_material = face_materials[source_face]
    for m, material in enumerate(materials):
        selected = triangles[triangle_material == m]
        if len(selected):
            used, local = _used_vertices(selected)
            collected.add(positions[used], local, material, None, None if uv is None else uv[used])
    return collected


def _ply_uv(vertex: Any) -> np.ndarray | None:
    """(n, 2) vertex UVs with v down from PLY vertex data, or None without UV properties."""
    names = set(getattr(getattr(vertex, "dtype", None), "names", None) or vertex)
    for u, v in (("s", "t"), ("u", "v"), ("texture_u", "texture_v")):
        if u in names and v in names:
            return np.column_stack(
                [np.asarray(vertex[u], dtype=np.float64), 1.0 - np.asarray(vertex[v], np.float64)]
            )
    return None


def _ply_face_columns(data: Any) -> dict[str, np.ndarray]:
    """Per-face arrays by property name from trimesh's raw PLY face data.

    trimesh gives a dict of arrays (ASCII, or binary with mixed polygon sizes) or one
    structured array whose list properties are ``(count, values)`` records.
    """
    if isinstance(data, dict):
        return {str(k): np.asarray(v) for k, v in data.items()}
    columns: dict[str, np.ndarray] = {}
    for name in data.dtype.names or ():
        column = data[name]
        if column.dtype.names and "f1" in column.dtype.names:
            column = column["f1"]
        columns[name] = np.asarray(column)
    return columns


def _fan_triangulate(polygons: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fan triangles of PLY polygons, in face order.

    Parameters
    ----------
    polygons : (F, k) int or (F,) object array of int arrays
        Vertex indices per face; faces with fewer than 3 corners are dropped.

    Returns
    -------
    triangles : (T, 3) int64
    source_face : (T,) int64
        The face each triangle came from.
    """
    if polygons.dtype != object and polygons.ndim == 2:
        groups = {polygons.shape[1]: (np.arange(len(polygons)), polygons.astype(np.int64))}
    else:
        lengths = np.array([len(p) for p in polygons], dtype=np.int64)
        groups = {}
        for k in np.unique(lengths[lengths >= 3]).tolist():
            faces = np.flatnonzero(lengths == k)
            groups[k] = (faces, np.stack([polygons[i] for i in faces]).astype(np.int64))
    triangles, sources = [np.empty((0, 3), np.int64)], [np.empty(0, np.int64)]
    for k, (faces, corners) in groups.items():
        if k < 3:
            continue
        fan = np.stack([corners[:, [0, j, j + 1]] for j in range(1, k - 1)], axis=1)
        triangles.append(fan.reshape(-1, 3))
        sources.append(np.repeat(faces, k - 2))
    triangle_array, source = np.concatenate(triangles), np.concatenate(sources)
    order = np.argsort(source, kind="stable")
    return triangle_array[order], source[order]


def _ply_face_materials(
    collected: _Collected, columns: dict[str, np.ndarray], face_count: int
) -> tuple[np.ndarray, list[_Material]]:
    """(F,) material index per PLY face and the distinct materials."""
    reflectance: np.ndarray | None = None
    if all(p in columns for p in _REFLECTANCE_PROPERTIES):
        reflectance = np.column_stack([columns[p] for p in _REFLECTANCE_PROPERTIES])
    elif all(columns.get(p, np.empty(0)).dtype == np.uint8 for p in _COLOUR_PROPERTIES):
        reflectance = _srgb_decode(np.column_stack([columns[p] for p in _COLOUR_PROPERTIES]) / 255)
    emission = np.zeros((face_count, 3))
    if all(p in columns for p in _EMISSION_PROPERTIES):
        emission = np.column_stack([columns[p] for p in _EMISSION_PROPERTIES])
    defaulted = reflectance is None
    if reflectance is None:
        collected.warn_once(
            "default",
            "PLY faces have no reflectance or colour properties; using reflectance %s grey",
            DEFAULT_REFLECTANCE,
        )
        reflectance = np.full((face_count, 3), DEFAULT_REFLECTANCE)
    values = np.column_stack([reflectance, emission]).astype(np.float64)
    distinct, inverse = np.unique(values, axis=0, return_inverse=True)
    names = [f"ply_material_{i}" for i in range(len(distinct))]
    if defaulted and len(distinct) == 1:
        names = ["default"]
    materials = [
        _Material(name, (v[0], v[1], v[2]), (v[3], v[4], v[5]))
        for name, v in zip(names, distinct.tolist(), strict=True)
    ]
    return inverse.reshape(-1), materials


def _srgb_decode(encoded: np.ndarray) -> np.ndarray:
    """Linear values from sRGB-encoded ones (IEC 61966-2-1).

    Parameters
    ----------
    encoded : (...) float
        sRGB-encoded values in [0, 1].

    Returns
    -------
    (...) float64
        Linear values in [0, 1].
    """
    c = np.asarray(encoded, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _load_toml(path: Path, uv_set: int | None = None) -> _Collected:
    """A TOML scene description: meshes, materials, camera (:mod:`raytrad.io.toml_scene`)."""
    from raytrad.io.toml_scene import collect_toml

    return collect_toml(path, uv_set)


LOADERS: dict[str, Callable[[Path, int | None], _Collected]] = {
    ".obj": _load_obj,
    ".gltf": _load_gltf,
    ".glb": _load_glb,
    ".ply": _load_ply,
    ".toml": _load_toml,
}
"""Scene loaders by lower-case file suffix; :func:`load_scene` dispatches through this."""
