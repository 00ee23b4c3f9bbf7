"""OBJ and MTL text read by raytrad itself, before any of it reaches trimesh.

trimesh (5.2) misreads valid OBJ: relative (negative) face indices between interleaved
``v`` blocks resolve against the end of the file (trimesh issue #2364), ``v<TAB>x y z``
lines are skipped, polygons are fan-triangulated (wrong for non-convex ones), and one
bad MTL line drops every material. So :func:`normalise_obj` rewrites the OBJ into the
plain form trimesh reads right (single spaces, absolute indices, triangles only, ``\\``
continuations joined), checking every face index on the way; and :func:`parse_mtl`
reads the MTL values, reporting a bad line by file and line and keeping the rest.

Reference: Wavefront OBJ and MTL, "Advanced Visualizer" manual, appendices B1 and B2.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from raytrad.errors import SceneError
from raytrad.scenefiles.polygons import triangulate_polygons

#: MTL colour statements raytrad reads (lower case): diffuse reflectance, emission.
MTL_COLOURS = ("kd", "ke")
_KINDS = ("v", "vt", "vn")

log = logging.getLogger(__name__)


@dataclass
class ObjText:
    """A normalised OBJ: the text trimesh gets and what was read on the way.

    Attributes
    ----------
    text : bytes
        ``v``/``vt``/``vn``/``f``/``o``/``g``/``usemtl``/``s`` lines, single-spaced, faces
        as triangles with absolute 1-based indices; no ``mtllib`` (the reader adds its own).
    mtllibs : list of str
        The MTL file names of every ``mtllib`` statement, in order.
    polygons : int
        Faces of more than 3 corners that were triangulated.
    """

    text: bytes
    mtllibs: list[str] = field(default_factory=list)
    polygons: int = 0


def normalise_obj(path: Path, text: str) -> ObjText:
    """The OBJ text trimesh reads right (see the module docstring).

    Parameters
    ----------
    path : Path
        The OBJ file, for messages.
    text : str
        Its decoded content.

    Raises
    ------
    SceneError
        A ``v`` line without 3 numbers, a face corner that is not an index, index 0, or
        an index outside the vertices, naming the line.
    """
    text = text.replace("\\\r\n", " ").replace("\\\n", " ")
    reader = _ObjReader(path)
    for number, line in enumerate(text.splitlines(), start=1):
        reader.line(number, line)
    return reader.finish()


class _ObjReader:
    """One pass over the OBJ lines, then the polygons triangulated at the end."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.out: list[str] = []
        self.counts = dict.fromkeys(_KINDS, 0)
        self.highest = dict.fromkeys(_KINDS, (0, 0))  # (index, line number)
        self.positions: list[tuple[float, float, float]] = []
        self.polygons: list[tuple[int, list[list[int]]]] = []  # (output slot, corners)
        self.mtllibs: list[str] = []
        self.short_faces = 0

    def error(self, number: int, message: str) -> SceneError:
        return SceneError(self.path, f"cannot parse as OBJ: line {number}: {message}")

    def line(self, number: int, line: str) -> None:
        words = _without_comment(line.split())
        if not words:
            return
        keyword = words[0]
        if keyword == "v":
            self.vertex(number, words)
        elif keyword in ("vt", "vn"):
            self.counts[keyword] += 1
            numbers = [*words[1:], "0", "0", "0"][: 2 if keyword == "vt" else 3]
            self.out.append(keyword + " " + " ".join(numbers))
        elif keyword == "f":
            self.face(number, words[1:])
        elif keyword == "mtllib":
            self.mtllibs.append(" ".join(words[1:]))
        elif keyword in ("o", "g", "usemtl", "s"):
            self.out.append(" ".join(words))
        # points, lines, curves and surfaces carry no area: not passed on

    def vertex(self, number: int, words: list[str]) -> None:
        try:
            x, y, z = (float(w) for w in words[1:4])
        except ValueError:
            raise self.error(number, f"a vertex needs 3 numbers: {' '.join(words)!r}") from None
        self.counts["v"] += 1
        self.positions.append((x, y, z))
        self.out.append(f"v {words[1]} {words[2]} {words[3]}")

    def face(self, number: int, corners: list[str]) -> None:
        resolved = [self.corner(number, corner) for corner in corners]
        if len(resolved) < 3:
            self.short_faces += 1
        elif len(resolved) == 3:
            self.out.append(_face_line(resolved))
        else:
            self.polygons.append((len(self.out), resolved))
            self.out.append("")

    def corner(self, number: int, corner: str) -> list[int]:
        """Absolute 1-based (v, vt, vn) indices of one face corner; 0 where absent."""
        parts = corner.split("/")
        if len(parts) > 3 or not parts[0]:
            raise self.error(number, f"bad face corner {corner!r}")
        indices = []
        for kind, part in zip(_KINDS, parts, strict=False):
            if not part:
                indices.append(0)
                continue
            try:
                index = int(part)
            except ValueError:
                raise self.error(number, f"bad face corner {corner!r}") from None
            if index == 0:
                raise self.error(number, f"face index 0 in {corner!r} (OBJ indices start at 1)")
            if index < 0:
                index += self.counts[kind] + 1
                if index < 1:
                    raise self.error(
                        number,
                        f"relative index {part} reaches before the first {kind!r} "
                        f"({self.counts[kind]} defined so far)",
                    )
            elif index > self.highest[kind][0]:
                self.highest[kind] = (index, number)
            indices.append(index)
        return indices + [0] * (3 - len(indices))

    def finish(self) -> ObjText:
        for kind in _KINDS:
            index, number = self.highest[kind]
            if index > self.counts[kind]:
                raise self.error(
                    number, f"face refers to {kind!r} {index}, but the file has {self.counts[kind]}"
                )
        if self.short_faces:
            log.warning(
                "%s: dropped %d faces with fewer than 3 corners", self.path, self.short_faces
            )
        if self.polygons:
            self.split_polygons()
        return ObjText(
            ("\n".join(self.out) + "\n").encode("utf-8"), self.mtllibs, len(self.polygons)
        )

    def split_polygons(self) -> None:
        """Fill each polygon's output slot with the triangles covering it."""
        positions = np.array(self.positions, dtype=np.float64).reshape(-1, 3)
        corners = np.concatenate([np.array(c, dtype=np.int64) for _, c in self.polygons])
        sizes = np.array([len(c) for _, c in self.polygons])
        ends = np.cumsum(sizes)
        polygons = [np.arange(end - size, end) for end, size in zip(ends, sizes, strict=True)]
        with np.errstate(all="ignore"):  # non-finite coordinates are reported later
            triangles, source = triangulate_polygons(positions[corners[:, 0] - 1], polygons)
        lines: list[list[str]] = [[] for _ in self.polygons]
        for face, triangle in zip(source.tolist(), triangles, strict=True):
            lines[face].append(_face_line(corners[triangle].tolist()))
        for (slot, _), face_lines in zip(self.polygons, lines, strict=True):
            self.out[slot] = "\n".join(face_lines)


def _without_comment(words: list[str]) -> list[str]:
    """The words before the first one that starts a ``#`` comment."""
    for i, word in enumerate(words):
        if word.startswith("#"):
            return words[:i]
    return words


def _face_line(corners: list[list[int]]) -> str:
    """An ``f`` line of absolute corners (0: that index absent)."""
    words = []
    for v, vt, vn in corners:
        if vn:
            words.append(f"{v}/{vt or ''}/{vn}")
        elif vt:
            words.append(f"{v}/{vt}")
        else:
            words.append(str(v))
    return "f " + " ".join(words)


def parse_mtl(
    label: str, data: bytes, warn: Callable[[str], None]
) -> dict[str, dict[str, tuple[float, float, float]]]:
    """The ``Kd`` and ``Ke`` colours of each material of an MTL file.

    Parameters
    ----------
    label : str
        The MTL file as messages name it.
    data : bytes
        Its content; bytes that are not UTF-8 (a Latin-1 comment, say) are read as U+FFFD.
    warn : callable
        Called with one message per line that cannot be read (``<label> line <n>: ...``);
        such a line is ignored and every other line kept.

    Returns
    -------
    dict
        ``{material name: {"kd": (r, g, b), "ke": (r, g, b)}}``, only the colours given.
        ``Kd r`` means ``Kd r r r``; colours are not range-checked here (the scene is).
    """
    materials: dict[str, dict[str, tuple[float, float, float]]] = {}
    current: dict[str, tuple[float, float, float]] | None = None
    text = data.decode("utf-8", errors="replace")
    for number, line in enumerate(text.splitlines(), start=1):
        words = _without_comment(line.split())
        if not words:
            continue
        keyword = words[0].lower()
        if keyword == "newmtl":  # names as the OBJ's usemtl reads them: single-spaced
            current = materials.setdefault(" ".join(words[1:]), {})
        elif keyword in MTL_COLOURS:
            if current is None:
                warn(f"{label} line {number}: {words[0]} before any newmtl; line ignored")
                continue
            colour = _colour(words[1:])
            if colour is None:
                warn(
                    f"{label} line {number}: {line.strip()[:60]!r} is not 1 or 3 numbers; "
                    "line ignored"
                )
            else:
                current[keyword] = colour
    return materials


def _colour(words: list[str]) -> tuple[float, float, float] | None:
    """1 or 3 numbers as an RGB triple, else None."""
    try:
        values = [float(w) for w in words]
    except ValueError:
        return None
    if len(values) == 1:
        values *= 3
    if len(values) != 3 or any(math.isnan(v) for v in values):
        return None
    return (values[0], values[1], values[2])
