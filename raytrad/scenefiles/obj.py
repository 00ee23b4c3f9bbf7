"""OBJ + MTL scene files: geometry through trimesh, ``Kd`` and ``Ke`` read from the MTL.

``Kd`` is the diffuse reflectance [1] and ``Ke`` the emitted exitance [W m-2]. Objects are
``o`` statements, or ``g`` groups in a file without any ``o``; ``vt`` coordinates are UV
set 0.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from raytrad.errors import SceneError
from raytrad.scenefiles import trimesh_adapter
from raytrad.scenefiles.common import (
    DEFAULT_REFLECTANCE,
    Collected,
    Material,
    ReadOptions,
    rgb_of,
)

_DEFAULT_MATERIAL = Material("default", (DEFAULT_REFLECTANCE,) * 3)
_SCALAR_COLOUR = re.compile(
    rb"^([ \t]*K[ads][ \t]+)(\S+)[ \t]*(\r?)$", re.IGNORECASE | re.MULTILINE
)
_STAND_IN_MTL = b"__raytrad_objects__.mtl"
_OBJECT_TAG = re.compile(r"^(.*)__raytrad_object_(\d+)__$", re.DOTALL)
_OBJECT_LINE = re.compile(rb"^[ \t]*(o|g|usemtl)(?:[ \t]+([^\r\n]*?))?[ \t]*(\r?)$", re.MULTILINE)


def read_obj(path: Path, options: ReadOptions) -> Collected:
    """OBJ geometry through trimesh; ``Kd`` (reflectance) and ``Ke`` [W m-2] from the MTL.

    ``vt`` coordinates are UV set 0. trimesh keeps them per corner only when it may split
    vertices by (v, vt) pair (``maintain_order=False``), so that is how UVs are read.
    """
    data = path.read_bytes()
    if b"\0" in data:
        raise SceneError(path, "cannot parse as OBJ: binary data (NUL bytes), not OBJ text")
    # Undecodable bytes (a Latin-1 comment, say) become U+FFFD instead of failing in trimesh.
    text = data.decode("utf-8", errors="replace").encode("utf-8")
    text, object_names, material_objects = _tag_objects(text)
    mtl = _MtlRewriter(material_objects)
    collected = Collected(path, options)
    tm_scene = trimesh_adapter.parse_scene(
        path,
        text,
        "obj",
        "OBJ",
        resolver=trimesh_adapter.file_resolver(path.parent, mtl),
        group_material=True,
        maintain_order=options.uv_set != 0,
    )
    if not mtl.declared and re.search(rb"^[ \t]*mtllib", data, re.MULTILINE):
        collected.warn_once("mtllib", "its mtllib file is missing or declares no materials")

    def object_of(node: str, geometry: Any) -> str | None:
        tagged = _OBJECT_TAG.match(trimesh_adapter.material_name(geometry) or "")
        return None if tagged is None else object_names[int(tagged.group(2))]

    trimesh_adapter.add_trimesh_scene(
        collected,
        tm_scene,
        lambda g: _obj_material(collected, mtl.declared, g),
        object_of,
        uv_available=options.uv_set == 0,
        node_order=object_names,
    )
    return collected


def _tag_objects(text: bytes) -> tuple[bytes, list[str], dict[str, set[int]]]:
    """OBJ text whose ``usemtl`` names also say which object they are used in.

    trimesh (5.2) groups OBJ faces by material but mislabels its objects, so the object
    goes into the material name: ``usemtl M`` inside object ``k`` becomes ``usemtl
    M__raytrad_object_k__``, and each ``o`` line restates the current material, tagged.
    Objects are ``o`` statements, or ``g`` groups in a file without any ``o``; a file with
    neither is returned unchanged. A file without ``mtllib`` gets one naming a stand-in
    MTL file, which :class:`_MtlRewriter` fills with the tagged names.

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


class _MtlRewriter:
    """Fixes MTL text for trimesh and notes the materials it declares.

    The MTL format allows ``Kd r`` for ``Kd r r r``, but trimesh 5.2 then fails to build
    every material of the file (silently), so one-number ``Kd``/``Ka``/``Ks`` lines are
    repeated to three numbers. The ``newmtl`` names read are kept in :attr:`declared` to
    tell MTL materials from the placeholder trimesh gives faces that have none. Each
    material of ``material_objects`` is repeated under the object-tagged names of
    :func:`_tag_objects` (with an empty body when the MTL lacks it), so every tagged face
    group keeps its name through trimesh, which reads only the file's first ``mtllib``.
    """

    def __init__(self, material_objects: dict[str, set[int]]) -> None:
        self.material_objects = material_objects
        self.declared: set[str] = set()

    def __call__(self, name: str, data: bytes | None) -> bytes:
        is_mtl = name.lower().endswith(".mtl")
        if data is None:
            if not self.material_objects or not is_mtl:
                raise OSError(f"{name}: not found")
            data = b""  # a missing (or the stand-in) MTL still carries the objects
        if not is_mtl:
            return data
        data = _SCALAR_COLOUR.sub(rb"\1\2 \2 \2\3", data)
        text = data.decode("utf-8", errors="replace")
        real = {
            " ".join(words[1:])
            for words in (line.split() for line in text.splitlines())
            if len(words) > 1 and words[0].lower() == "newmtl"
        }
        self.declared.update(real)
        return data + _tagged_copies(data, self.material_objects)


def _tagged_copies(mtl: bytes, material_objects: dict[str, set[int]]) -> bytes:
    """MTL blocks repeated under the object-tagged names of :func:`_tag_objects`.

    A material the MTL declares is copied with its body; one it lacks (or no material,
    ``""``) gets an empty block, read as the grey default.
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


def _obj_material(collected: Collected, declared: set[str], geometry: Any) -> Material:
    """The MTL material of one trimesh geometry, or the grey default (warned once)."""
    values = trimesh_adapter.material_values(geometry)
    name = trimesh_adapter.material_name(geometry)
    tagged = _OBJECT_TAG.match(name) if name is not None else None
    name = name if tagged is None else tagged.group(1)
    if values is None or name not in declared:
        collected.warn_once(
            "default",
            "faces without an MTL material get reflectance %s grey and no emission",
            DEFAULT_REFLECTANCE,
        )
        return _DEFAULT_MATERIAL
    name = str(name)
    path = collected.path
    if "kd" in values:
        reflectance = rgb_of(path, values["kd"], f"material {name!r} Kd")
    else:
        collected.warn_once(
            f"kd:{name}", "material %r has no Kd; using reflectance %s", name, DEFAULT_REFLECTANCE
        )
        reflectance = (DEFAULT_REFLECTANCE,) * 3
    emission = values.get("ke")
    emitted = (
        (0.0, 0.0, 0.0) if emission is None else rgb_of(path, emission, f"material {name!r} Ke")
    )
    return Material(name, reflectance, emitted, double_sided=False)
