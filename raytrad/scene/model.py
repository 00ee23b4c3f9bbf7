"""A scene as a few flat arrays: triangle geometry and per-material optical properties.

Units: positions in metres [m]; reflectance is unitless diffuse albedo per linear RGB
channel in [0, 1]; emitted exitance is radiant exitance per channel [W m-2] (a Lambertian
emitter of radiance L has exitance pi * L).
"""

from __future__ import annotations

import hashlib
import logging
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from raytrad.arrays import unique
from raytrad.constants import FLOAT32_MAX, tol
from raytrad.errors import SceneError

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class Scene:
    """Triangle soup with materials.

    Attributes
    ----------
    positions : (V, 3) float64
        Vertex positions [m].
    triangles : (T, 3) int64
        Vertex indices of each triangle, counter-clockwise seen from the lit (front) side.
    material_index : (T,) int64
        Index into the material arrays for each triangle.
    material_names : tuple of str
        One name per material.
    material_reflectance : (M, 3) float64
        Diffuse reflectance per material and channel [1].
    material_emitted_exitance : (M, 3) float64
        Emitted exitance per material and channel [W m-2].
    material_double_sided : (M,) bool
        True where a surface receives and shoots on both sides.
    object_index : (T,) int64
        Index into ``object_names`` for each triangle: the mesh (glTF node, OBJ object,
        TOML ``[[mesh]]``) it belongs to, for per-mesh lightmaps.
    object_names : tuple of str
        One unique name per object.
    source : Path or None
        The file the scene came from, used in error messages.
    lightmap_uv : (T, 3, 2) float64 or None
        The model's lightmap UVs [1] per triangle corner, normalised with ``v`` growing
        downwards (glTF convention); NaN rows for faces the UV set does not cover. None
        when no UV set was read.
    """

    positions: np.ndarray
    triangles: np.ndarray
    material_index: np.ndarray
    material_names: tuple[str, ...]
    material_reflectance: np.ndarray
    material_emitted_exitance: np.ndarray
    material_double_sided: np.ndarray
    object_index: np.ndarray
    object_names: tuple[str, ...]
    source: Path | None = field(default=None)
    lightmap_uv: np.ndarray | None = field(default=None)

    @property
    def triangle_count(self) -> int:
        return int(self.triangles.shape[0])

    @property
    def reflectance(self) -> np.ndarray:
        """(T, 3) float64 per-triangle reflectance [1]."""
        return np.asarray(self.material_reflectance[self.material_index])

    @property
    def emitted_exitance(self) -> np.ndarray:
        """(T, 3) float64 per-triangle emitted exitance [W m-2]."""
        return np.asarray(self.material_emitted_exitance[self.material_index])

    @property
    def double_sided(self) -> np.ndarray:
        """(T,) bool per-triangle double-sidedness."""
        return np.asarray(self.material_double_sided[self.material_index])

    def triangle_vertices(self) -> np.ndarray:
        """(T, 3, 3) float64 corner positions [m]."""
        return np.asarray(self.positions[self.triangles])

    def select(self, rows: np.ndarray) -> Scene:
        """The scene with only the triangles ``rows`` ((T,) bool mask or (N,) indices)."""
        return replace(
            self,
            triangles=self.triangles[rows],
            material_index=self.material_index[rows],
            object_index=self.object_index[rows],
            lightmap_uv=None if self.lightmap_uv is None else self.lightmap_uv[rows],
        )

    def flipped(self, flip: np.ndarray) -> Scene:
        """The scene with the winding of the triangles where ``flip`` ((T,) bool) reversed."""
        triangles = self.triangles.copy()
        triangles[flip] = triangles[flip][:, ::-1]
        uv = self.lightmap_uv
        if uv is not None:
            uv = uv.copy()
            uv[flip] = uv[flip][:, ::-1]
        return replace(self, triangles=triangles, lightmap_uv=uv)

    def scaled(self, factor: float) -> Scene:
        """The same scene with positions multiplied by ``factor`` > 0 (unit conversion)."""
        if not (np.isfinite(factor) and factor > 0):
            raise SceneError(self.source, f"scale must be a positive number, got {factor}")
        return replace(self, positions=self.positions * float(factor))


def barycentric_coordinates(points: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Barycentric coordinates of points in the planes of triangles.

    Parameters
    ----------
    points : (N, 3) float [m]
        Points (projected onto each triangle's plane by the least-squares solve).
    corners : (N, 3, 3) float
        One triangle's corners per point [m].

    Returns
    -------
    (N, 3) float64 weights of the three corners, summing to 1; NaN rows for degenerate
    triangles (inside nothing: every comparison with them is False).
    """
    corners = np.asarray(corners, dtype=np.float64)
    e1, e2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    d = np.asarray(points, dtype=np.float64) - corners[:, 0]
    d11, d12, d22 = (np.einsum("ij,ij->i", a, b) for a, b in ((e1, e1), (e1, e2), (e2, e2)))
    d1, d2 = np.einsum("ij,ij->i", d, e1), np.einsum("ij,ij->i", d, e2)
    det = d11 * d22 - d12 * d12
    det = np.where(det > 0, det, np.nan)
    u = (d22 * d1 - d12 * d2) / det
    v = (d11 * d2 - d12 * d1) / det
    return np.stack([1.0 - u - v, u, v], axis=1)


def triangle_areas_normals(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Areas and unit normals of triangles.

    Parameters
    ----------
    corners : (T, 3, 3) float
        Triangle corner positions [m].

    Returns
    -------
    areas : (T,) float64
        Triangle areas [m2].
    normals : (T, 3) float64
        Unit normals (right-handed winding); zero rows for degenerate triangles.
    """
    corners = np.asarray(corners, dtype=np.float64)
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    norm = np.linalg.norm(cross, axis=1)
    normals = np.zeros_like(cross)
    ok = norm > 0
    normals[ok] = cross[ok] / norm[ok, None]
    return 0.5 * norm, normals


def make_scene(
    positions: np.ndarray,
    triangles: np.ndarray,
    material_index: np.ndarray,
    material_names: tuple[str, ...] | list[str],
    material_reflectance: np.ndarray,
    material_emitted_exitance: np.ndarray,
    material_double_sided: np.ndarray | None = None,
    source: str | Path | None = None,
    object_index: np.ndarray | None = None,
    object_names: tuple[str, ...] | list[str] | None = None,
    lightmap_uv: np.ndarray | None = None,
) -> Scene:
    """Build a validated :class:`Scene` from arrays (see :class:`Scene` for shapes and units).

    Without ``object_index`` every triangle belongs to one object, named after ``source``'s
    file stem (or "scene").

    Raises
    ------
    SceneError
        Naming ``source`` and the problem, for anything that cannot give a finite answer.
    """
    names = tuple(str(n) for n in material_names)
    m = len(names)
    if material_double_sided is None:
        material_double_sided = np.zeros(m, dtype=bool)
    if object_index is None:
        object_index = np.zeros(len(np.asarray(material_index).reshape(-1)), dtype=np.int64)
        object_names = [Path(source).stem if source is not None else "scene"]
    try:
        scene = _scene_from_arrays(
            positions,
            triangles,
            material_index,
            names,
            material_reflectance,
            material_emitted_exitance,
            material_double_sided,
            source,
        )
        scene = replace(
            scene,
            object_index=np.asarray(object_index, dtype=np.int64).reshape(-1),
            object_names=tuple(str(n) for n in object_names or ()),
            lightmap_uv=None if lightmap_uv is None else np.asarray(lightmap_uv, dtype=np.float64),
        )
    except ValueError as exc:
        raise SceneError(source, f"malformed scene arrays ({exc})") from exc
    return validate_scene(scene)


def _scene_from_arrays(
    positions: np.ndarray,
    triangles: np.ndarray,
    material_index: np.ndarray,
    names: tuple[str, ...],
    material_reflectance: np.ndarray,
    material_emitted_exitance: np.ndarray,
    material_double_sided: np.ndarray,
    source: str | Path | None,
) -> Scene:
    m = len(names)
    return Scene(
        positions=np.asarray(positions, dtype=np.float64).reshape(-1, 3),
        triangles=np.asarray(triangles, dtype=np.int64).reshape(-1, 3),
        material_index=np.asarray(material_index, dtype=np.int64).reshape(-1),
        material_names=names,
        material_reflectance=np.asarray(material_reflectance, dtype=np.float64).reshape(m, 3),
        material_emitted_exitance=np.asarray(material_emitted_exitance, dtype=np.float64).reshape(
            m, 3
        ),
        material_double_sided=np.asarray(material_double_sided, dtype=bool).reshape(m),
        object_index=np.zeros(0, dtype=np.int64),
        object_names=(),
        source=None if source is None else Path(source),
    )


def validate_scene(scene: Scene) -> Scene:
    """Check a scene and drop zero-area triangles (with a warning).

    Returns
    -------
    Scene
        The scene, possibly without its degenerate triangles.

    Raises
    ------
    SceneError
        No faces, bad indices, non-finite coordinates, reflectance outside [0, 1],
        negative or non-finite emission.
    """
    src = scene.source
    if scene.triangles.shape[0] == 0:
        raise SceneError(src, "the mesh has no faces")
    if scene.material_index.shape[0] != scene.triangles.shape[0]:
        raise SceneError(src, "material_index must have one entry per triangle")
    nv = scene.positions.shape[0]
    if scene.triangles.min() < 0 or scene.triangles.max() >= nv:
        raise SceneError(src, f"a face refers to a vertex outside 0..{nv - 1}")
    used = unique(scene.triangles)
    bad = ~np.isfinite(scene.positions[used]).all(axis=1)
    if bad.any():
        raise SceneError(
            src,
            f"{_vertices(int(bad.sum()))} NaN or infinite coordinates (or numbers beyond "
            "the range of the file's number type)",
        )
    huge = np.abs(scene.positions[used]).max(axis=1) > FLOAT32_MAX
    if huge.any():
        raise SceneError(
            src,
            f"{_vertices(int(huge.sum()))} coordinates beyond the float32 range (such as "
            f"{scene.positions[used[huge][0]].tolist()}); check the units or --scale",
        )
    nm = len(scene.material_names)
    if scene.material_index.min() < 0 or scene.material_index.max() >= nm:
        raise SceneError(src, "a face refers to a material that does not exist")
    _check_objects(scene)
    for i, name in enumerate(scene.material_names):
        rho = scene.material_reflectance[i]
        if not np.isfinite(rho).all() or rho.min() < 0.0 or rho.max() > 1.0:
            raise SceneError(
                src, f"material {name!r}: reflectance {rho.tolist()} is outside [0, 1]"
            )
        emission = scene.material_emitted_exitance[i]
        if not np.isfinite(emission).all() or emission.min() < 0.0:
            raise SceneError(
                src, f"material {name!r}: emission {emission.tolist()} must be finite and >= 0"
            )
        if emission.max() > FLOAT32_MAX:
            raise SceneError(
                src,
                f"material {name!r}: emission {emission.tolist()} W m-2 is beyond the float32 "
                "range of the outputs",
            )
    corners = scene.triangle_vertices()
    areas, _ = triangle_areas_normals(corners)
    longest = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1)
    # Degenerate: no area, or an area lost in float64 rounding of its own edge lengths
    # (collinear corners). Slivers of aspect 1e6 and tiny triangles in huge scenes stay.
    degenerate = areas <= tol.degenerate * longest * longest
    if degenerate.all():
        raise SceneError(src, "every face has zero area")
    if degenerate.any():
        log.warning("%s: dropped %d zero-area triangles", src or "<scene>", int(degenerate.sum()))
        scene = scene.select(~degenerate)
    return scene


def _vertices(count: int) -> str:
    return "1 vertex has" if count == 1 else f"{count} vertices have"


def _check_objects(scene: Scene) -> None:
    """SceneError unless object indices and lightmap UVs have one entry per triangle."""
    src, count = scene.source, scene.triangle_count
    if scene.object_index.shape != (count,):
        raise SceneError(src, "object_index must have one entry per triangle")
    no = len(scene.object_names)
    if scene.object_index.min() < 0 or scene.object_index.max() >= no:
        raise SceneError(src, "a face refers to an object that does not exist")
    if len(set(scene.object_names)) != no:
        raise SceneError(src, "object names must be unique")
    uv = scene.lightmap_uv
    if uv is not None:
        if uv.shape != (count, 3, 2):
            raise SceneError(src, f"lightmap UVs must be ({count}, 3, 2), not {uv.shape}")
        if np.isinf(uv).any():
            raise SceneError(src, "the lightmap UV set has infinite coordinates")


def has_emission(scene: Scene) -> bool:
    """True when any triangle emits in any channel."""
    return bool((scene.emitted_exitance > 0).any())


def scene_digests(scene: Scene) -> dict[str, dict[str, str]]:
    """SHA-256 digests of everything a solve of ``scene`` depends on, part by part.

    Returns
    -------
    dict
        ``"materials"``: material name -> digest of its reflectance, emitted exitance and
        sidedness; ``"objects"``: object name -> digest of the corner positions [m] of its
        triangles and the names of their materials, in order. Two scenes with equal
        digests define the same discrete system for equal mesh settings; where they
        differ, the keys say which material or object changed. Object names and lightmap
        UVs do not enter a solve, so only the objects' content counts.
    """
    materials = {
        name: _digest(
            scene.material_reflectance[i],
            scene.material_emitted_exitance[i],
            scene.material_double_sided[i : i + 1],
        )
        for i, name in enumerate(scene.material_names)
    }
    corners = scene.triangle_vertices()
    names = np.array(scene.material_names, dtype=object)
    objects = {}
    for k, name in enumerate(scene.object_names):
        rows = scene.object_index == k
        used = "\n".join(names[scene.material_index[rows]].tolist()).encode()
        objects[name] = _digest(corners[rows], np.frombuffer(used, dtype=np.uint8))
    return {"materials": materials, "objects": objects}


def _digest(*arrays: np.ndarray) -> str:
    """SHA-256 hex digest of arrays' shapes, types and bytes (C order)."""
    digest = hashlib.sha256()
    for array in arrays:
        array = np.ascontiguousarray(array)
        digest.update(f"{array.dtype.str}{array.shape}".encode())
        digest.update(array.tobytes())
    return digest.hexdigest()
