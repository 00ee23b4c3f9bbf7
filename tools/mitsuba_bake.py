"""Mitsuba 3 for ``tools/bench_race.py``: radiosity at points on a raytrad scene, path
traced by Mitsuba's own integrator, to fill a lightmap (a second contender beside Cycles)
and to check the race's path-traced reference (a second reference).

A benchmark dependency, never a runtime one: ``pip install mitsuba`` (3.9.1 here, with
Dr.Jit 1.5), and for its vectorised CPU variant ``llvm_ad_rgb`` a shared LLVM library:
Debian's ``libllvm19`` (``apt install libllvm19``). :func:`import_mitsuba` finds
``libLLVM-*.so`` in the usual places and points ``DRJIT_LIBLLVM_PATH`` at the newest
unless it is set. LLVM 15 does not do: Dr.Jit 1.5's kernels use an instruction it cannot
lower (``fmaximum``), and the process aborts.

The scene: one PLY shape per raytrad material (written by trimesh; flat face normals),
Mitsuba's ``diffuse`` BSDF of the material's RGB reflectance (one-sided, black behind like
raytrad's surfaces), an ``area`` emitter of radiance ``M / pi`` on emitting materials (a
Lambertian emitter of exitance ``M``), no environment. At a point ``x`` with normal ``n``,
of reflectance ``rho`` and emitted exitance ``M``, the radiosity ``B = M + rho E``, and
each sample of the irradiance ``E`` is two estimates added, as a path tracer does at a
diffuse vertex:

- direct: one emitter sample from ``x`` (``Scene.sample_emitter_direction`` with the
  shadow ray), ``L cos / pdf``;
- indirect: one cosine-weighted direction from ``x``, traced by Mitsuba's ``path``
  integrator, ``pi (L - Le)``: less the radiance ``Le`` emitted by the surface it hits
  first (that light is the direct estimate's). Not the integrator's ``hide_emitters``:
  a path whose first hit is an emitter then returns nothing at all, and the light the
  emitter reflects (the Cornell box's light has reflectance 0.78) is lost; the floor and
  the block tops, which see the light, came out 0.5-0.8 % dark.

Paths stop at 64 bounces (``max_depth``), as raytrad's path tracer and the Cycles race do,
with Mitsuba's default Russian roulette (unbiased) from the fifth.
"""

from __future__ import annotations

import glob
import os
import re
import sys
import tempfile
from pathlib import Path
from types import ModuleType

import numpy as np
import trimesh

from raytrad.scene import Scene

#: How to install Mitsuba 3 and the LLVM it runs on (see the module docstring).
MITSUBA_INSTALL = "pip install mitsuba; apt install libllvm19"
VARIANT = "llvm_ad_rgb"
#: Path depth of Mitsuba's integrator: 64 bounces after the first hit.
MAX_DEPTH = 65
#: Paths per kernel launch (Dr.Jit keeps each launch's state in memory).
BATCH = 1 << 22
#: Where shared LLVM libraries are looked for, newest version first.
LLVM_GLOBS = (
    "/usr/lib/x86_64-linux-gnu/libLLVM-*.so*",
    "/usr/lib/aarch64-linux-gnu/libLLVM-*.so*",
    "/usr/lib/llvm-*/lib/libLLVM*.so*",
    "/usr/lib64/libLLVM*.so*",
    "/usr/local/lib/libLLVM*.so*",
)
#: The oldest LLVM seen to run Dr.Jit 1.5's kernels here (15 aborts).
LLVM_WORKS = 19


def find_libllvm() -> tuple[str, int] | None:
    """The newest shared LLVM library found in :data:`LLVM_GLOBS` and its major version,
    or None."""
    found = []
    for pattern in LLVM_GLOBS:
        for path in glob.glob(pattern):
            match = re.search(r"LLVM-?(\d+)", Path(path).name) or re.search(r"llvm-(\d+)", path)
            if match:
                found.append((int(match.group(1)), path))
    if not found:
        return None
    version, path = max(found)
    return path, version


def import_mitsuba(threads: int) -> tuple[ModuleType, ModuleType] | str:
    """Mitsuba (variant :data:`VARIANT`) and Dr.Jit on ``threads`` threads, or one line
    saying why not. Sets ``DRJIT_LIBLLVM_PATH`` to :func:`find_libllvm`'s library unless it
    is set; refuses an LLVM older than 16, which would abort the process."""
    if "DRJIT_LIBLLVM_PATH" not in os.environ:
        found = find_libllvm()
        if found is None:
            return f"no shared LLVM library found; install one: {MITSUBA_INSTALL}"
        path, version = found
        if version < 16:
            return f"LLVM {version} ({path}) cannot run Dr.Jit's kernels: {MITSUBA_INSTALL}"
        if version < LLVM_WORKS:
            print(f"mitsuba: LLVM {version} is untested here (19 works)", file=sys.stderr)
        os.environ["DRJIT_LIBLLVM_PATH"] = path
    try:
        import drjit as dr
        import mitsuba as mi

        mi.set_variant(VARIANT)
    except (ImportError, AttributeError) as error:
        return f"mitsuba is not usable ({error}); install it: {MITSUBA_INSTALL}"
    dr.set_thread_count(threads)
    return mi, dr


def mitsuba_scene(mi: ModuleType, scene: Scene) -> object:
    """``scene`` as a Mitsuba scene (see the module docstring), its integrator the ``path``
    integrator."""
    description: dict = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": MAX_DEPTH},
    }
    with tempfile.TemporaryDirectory(prefix="raytrad-mitsuba-") as folder:
        for m in range(len(scene.material_names)):
            triangles = scene.triangles[scene.material_index == m]
            if not len(triangles):
                continue
            used, faces = np.unique(triangles, return_inverse=True)
            path = Path(folder) / f"material{m}.ply"
            shape_mesh = trimesh.Trimesh(scene.positions[used], faces.reshape(-1, 3), process=False)
            path.write_bytes(trimesh.exchange.ply.export_ply(shape_mesh, encoding="binary"))
            shape = {
                "type": "ply",
                "filename": str(path),
                "face_normals": True,
                "bsdf": {
                    "type": "diffuse",
                    "reflectance": {"type": "rgb", "value": scene.material_reflectance[m].tolist()},
                },
            }
            exitance = scene.material_emitted_exitance[m]
            if exitance.max() > 0:
                radiance = (exitance / np.pi).tolist()
                shape["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": radiance}}
            description[f"material{m}"] = shape
        return mi.load_dict(description)


def _irradiance_samples(mi, dr, target, points: np.ndarray, normals: np.ndarray, seed: int):
    """One irradiance sample [W m-2] (direct + indirect, see the module docstring) per row
    of ``points`` and ``normals`` (n, 3): (n, 3) float64."""
    count = len(points)
    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(seed, count)
    where = dr.zeros(mi.SurfaceInteraction3f, count)
    where.p = mi.Point3f(*(mi.Float(points[:, k].astype(np.float32)) for k in range(3)))
    where.n = mi.Normal3f(*(mi.Float(normals[:, k].astype(np.float32)) for k in range(3)))
    where.sh_frame = mi.Frame3f(where.n)
    sample, spectrum = target.sample_emitter_direction(where, sampler.next_2d(), True)
    direct = spectrum * dr.maximum(dr.dot(where.n, sample.d), 0.0)
    direction = where.sh_frame.to_world(mi.warp.square_to_cosine_hemisphere(sampler.next_2d()))
    ray = where.spawn_ray(direction)
    radiance, _, _ = target.integrator().sample(target, sampler, ray)
    first = target.ray_intersect(ray)
    emitted = first.emitter(target).eval(first, first.is_valid())
    irradiance = direct + dr.pi * (radiance - emitted)
    return np.array(irradiance, dtype=np.float64).reshape(3, count).T


def irradiance_at(
    mi: ModuleType,
    dr: ModuleType,
    target: object,
    points: np.ndarray,
    normals: np.ndarray,
    spp: int,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """Mean irradiance [W m-2] at ``points`` (N, 3) facing ``normals`` (N, 3) over ``spp``
    samples each, and its standard error: two (N, 3) arrays. Launches of at most
    :data:`BATCH` paths, each with its own seed."""
    rows = max(1, BATCH // spp)
    mean = np.empty((len(points), 3))
    error = np.empty((len(points), 3))
    for launch, start in enumerate(range(0, len(points), rows)):
        block = slice(start, start + rows)
        repeat = np.repeat(np.arange(len(points[block])), spp)
        got = _irradiance_samples(
            mi, dr, target, points[block][repeat], normals[block][repeat], seed + launch
        ).reshape(-1, spp, 3)
        mean[block] = got.mean(axis=1)
        error[block] = got.std(axis=1, ddof=1) / np.sqrt(spp) if spp > 1 else np.inf
    return mean, error
