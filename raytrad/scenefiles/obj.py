"""OBJ + MTL scene files: geometry through trimesh, ``Kd`` and ``Ke`` read from the MTL.

``Kd`` is the diffuse reflectance [1] and ``Ke`` the emitted exitance [W m-2]. Objects are
``o`` statements, or ``g`` groups in a file without any ``o``; ``vt`` coordinates are UV
set 0. The OBJ and MTL text is read by :mod:`raytrad.scenefiles.obj_text`; trimesh gets
plain triangles and material names only.
"""

from __future__ import annotations

import logging
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
    read_reference,
)
from raytrad.scenefiles.obj_text import normalise_obj, parse_mtl

log = logging.getLogger(__name__)
Colour = tuple[float, float, float]

_DEFAULT_MATERIAL = Material("default", (DEFAULT_REFLECTANCE,) * 3)
_STAND_IN_MTL = b"__raytrad_objects__.mtl"
_OBJECT_TAG = re.compile(r"^(.*)__raytrad_object_(\d+)__$", re.DOTALL)
_OBJECT_LINE = re.compile(rb"^[ \t]*(o|g|usemtl)(?:[ \t]+([^\r\n]*?))?[ \t]*(\r?)$", re.MULTILINE)


def read_obj(path: Path, options: ReadOptions) -> Collected:
    """OBJ geometry through trimesh; ``Kd`` (reflectance) and ``Ke`` [W m-2] from the MTL.

    The OBJ is normalised first (:func:`~raytrad.scenefiles.obj_text.normalise_obj`) and
    the MTL files read by raytrad (:func:`~raytrad.scenefiles.obj_text.parse_mtl`);
    trimesh sees only material names. ``vt`` coordinates are UV set 0. trimesh keeps them
    per corner only when it may split vertices by (v, vt) pair (``maintain_order=False``),
    so that is how UVs are read.
    """
    data = path.read_bytes()
    if b"\0" in data:
        raise SceneError(path, "cannot parse as OBJ: binary data (NUL bytes), not OBJ text")
    # Undecodable bytes (a Latin-1 comment, say) become U+FFFD instead of failing.
    normalised = normalise_obj(path, data.decode("utf-8", errors="replace"))
    collected = Collected(path, options)
    declared = _read_mtllibs(collected, normalised.mtllibs)
    text, object_names, material_objects = _tag_objects(normalised.text)
    stand_in = _stand_in_mtl(text, declared, material_objects)
    tm_scene = trimesh_adapter.parse_scene(
        path,
        b"mtllib " + _STAND_IN_MTL + b"\n" + text,
        "obj",
        "OBJ",
        resolver=trimesh_adapter.bytes_resolver({_STAND_IN_MTL.decode(): stand_in}),
        group_material=True,
        maintain_order=options.uv_set != 0,
    )

    def object_of(node: str, geometry: Any) -> str | None:
        tagged = _OBJECT_TAG.match(trimesh_adapter.material_name(geometry) or "")
        return None if tagged is None else object_names[int(tagged.group(2))]

    trimesh_adapter.add_trimesh_scene(
        collected,
        tm_scene,
        lambda g: _obj_material(collected, declared, g),
        object_of,
        uv_available=options.uv_set == 0,
        node_order=object_names,
    )
    return collected


def _read_mtllibs(collected: Collected, names: list[str]) -> dict[str, dict[str, Colour]]:
    """The materials of every ``mtllib`` file (the first definition of a name wins).

    A missing file is warned about; one outside the scene folder or not a regular file is
    an error (:func:`~raytrad.scenefiles.common.read_reference`). A name with spaces is
    tried whole first, then as several files.
    """
    path = collected.path
    materials: dict[str, dict[str, Colour]] = {}
    for statement in names:
        files = [statement] if (path.parent / statement).is_file() else statement.split()
        for name in files:
            data = read_reference(path, name, "mtllib", collected.options.allow_outside)
            if data is None:
                collected.warn_once(f"mtllib:{name}", "mtllib %r not found", name)
                continue
            label = f"{(path.parent / name).as_posix()}"
            for material, values in parse_mtl(label, data, log.warning).items():
                materials.setdefault(material, values)
    return materials


def _stand_in_mtl(
    text: bytes, declared: dict[str, dict[str, Colour]], material_objects: dict[str, set[int]]
) -> bytes:
    """The MTL trimesh reads: every material name, declared or used, with no values, and
    the object-tagged copies of :func:`_tag_objects`."""
    used = {
        m.group(1).decode("utf-8")
        for m in re.finditer(rb"^usemtl ([^\r\n]*)$", text, re.MULTILINE)
        if not _OBJECT_TAG.match(m.group(1).decode("utf-8"))
    }
    names = sorted(set(declared) | used)
    plain = "".join(f"newmtl {name}\nKd 1 1 1\n" for name in names)
    tagged = "".join(
        f"newmtl {base}__raytrad_object_{k}__\nKd 1 1 1\n"
        for base, objects in sorted(material_objects.items())
        for k in sorted(objects)
    )
    return (plain + tagged).encode("utf-8")


def _tag_objects(text: bytes) -> tuple[bytes, list[str], dict[str, set[int]]]:
    """OBJ text whose ``usemtl`` names also say which object they are used in.

    trimesh (5.2) groups OBJ faces by material but mislabels its objects, so the object
    goes into the material name: ``usemtl M`` inside object ``k`` becomes ``usemtl
    M__raytrad_object_k__``, and each ``o`` line restates the current material, tagged.
    Objects are ``o`` statements, or ``g`` groups in a file without any ``o``; a file with
    neither is returned unchanged. :func:`_stand_in_mtl` declares the tagged names.

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


def _obj_material(
    collected: Collected, declared: dict[str, dict[str, Colour]], geometry: Any
) -> Material:
    """The MTL material of one trimesh geometry, or the grey default (warned once)."""
    name = trimesh_adapter.material_name(geometry)
    tagged = _OBJECT_TAG.match(name) if name is not None else None
    name = name if tagged is None else tagged.group(1)
    if name is None or name not in declared:
        collected.warn_once(
            "default",
            "faces without an MTL material get reflectance %s grey and no emission",
            DEFAULT_REFLECTANCE,
        )
        return _DEFAULT_MATERIAL
    values = declared[name]
    if "kd" in values:
        reflectance = values["kd"]
    else:
        collected.warn_once(
            f"kd:{name}", "material %r has no Kd; using reflectance %s", name, DEFAULT_REFLECTANCE
        )
        reflectance = (DEFAULT_REFLECTANCE,) * 3
    return Material(name, reflectance, values.get("ke", (0.0, 0.0, 0.0)), double_sided=False)
