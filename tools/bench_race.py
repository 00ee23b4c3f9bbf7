"""Race raytrad against Blender's Cycles baker on the Cornell box, on the CPU: the time each
needs to reach both 1 % worst-surface mean error and 2 % point-wise RMS.

Both renderers are measured in one run, at the same probe points and against the same
cached path-traced reference as ``tools/bench_accuracy.py`` (its area and contact probes,
``--per-quad``/``--along``/``--paths``/``--cache`` with the same defaults, so the two tools
share one cache), with its error definitions (:func:`bench_accuracy.report`):

- worst-surface mean error: the largest, over surfaces other than the light and over RGB
  channels, of ``|mean(got) / mean(reference) - 1|`` at the surface's area probes;
- point-wise RMS: the area-weighted relative RMS of ``got - reference`` at the area
  probes, worst channel, with the reference's own variance taken out (``point RMS,
  reference noise removed``).

raytrad: :func:`bench_accuracy.bake` at each ``--receivers``, timed as the wall time of
the whole bake (mesh, form factors, solve, refinement; the error estimate that follows
is not counted), in this process, after one warm-up bake of 1 000 receivers so the
numba kernels are compiled.

Cycles (pip ``bpy``, installed as below; a benchmark dependency, never a runtime one):
the scene's triangles built directly into one Blender mesh (no file in between), one
diffuse material per raytrad material with the same RGB reflectance, the
light's emission the same exitance (a Lambertian emitter of exitance ``M`` has radiance
``M / pi``; Cycles' Emission shader emits radiance colour x strength), every back face
black like raytrad's single-sided surfaces, a black world, no clamping, 64 bounces (raytrad's
path tracer also stops at 64), no denoising or adaptive sampling. It bakes the COMBINED
pass (emission + direct + indirect diffuse: the outgoing radiance ``L = B / pi`` of a
Lambertian surface) on the CPU with ``--threads`` threads at each ``--spp`` samples per
texel, into one float image texture: a lightmap atlas with one tile per quad (each quad's
two triangles mapped affinely onto a rectangle of its edges' lengths at ``--texel``
metres per texel, 2 texels of gutter filled by Blender's bake margin). An image rather than
vertex colours since a lightmap is what both produce, and because a texel is sampled over
its own footprint with no subdivision of the mesh. The texture's discretisation (each
texel averages its footprint, probes interpolate between texel centres) puts a floor under
Cycles' point RMS, about 1.7 % at ``--texel 0.005`` (78 000 texels; fitted as
``RMS^2 = noise^2 / spp + floor^2`` over 64-1 024 spp), some 2.5 % at 10 mm (never under
2 %) and 0.9 % at 2.5 mm (four times the texels, so four times the time per spp): 5 mm is
about Cycles' fastest way to 2 %. The probes read the texture bilinearly at their UVs
(found from their triangle's barycentric coordinates), times pi. A Cycles row's seconds are the
wall time of the bake call (``bpy.ops.object.bake``: Cycles' scene sync, BVH build and
sampling); building the Blender scene (mesh, materials, image) is timed once, apart
(``setup``), and not counted in the race. A 1-spp warm-up bake precedes the timed ones.

Units check (printed): the light's mean radiosity from Cycles against the reference's
(emission plus its reflected irradiance) and against its emitted exitance, and every
surface's mean ratio Cycles / reference at the largest ``--spp``.

    python -m pip install --no-deps 'bpy>=4.2' requests zstandard
    python tools/bench_race.py                        # 2k-20k receivers, 16-1024 spp
    python tools/bench_race.py --receivers 5000 --spp 64 256 --threads 2 --verbose

(``--no-deps``: bpy 5.0's wheel pins NumPy 1.x, which raytrad's other dependencies have
outgrown; with NumPy 2 everything but Blender's audio module loads, and the race needs
no audio.)

Exits with status 2 and one line if ``bpy`` cannot be imported.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_accuracy import (
    CORNELL_SURFACES,
    ROOT,
    Probes,
    area_probes,
    bake,
    contact_probes,
    quad_corners,
    reference,
    report,
    shut_in,
)

from raytrad.products.probe import radiosity_at
from raytrad.scene import Scene, triangle_areas_normals
from raytrad.scene.builtin import cornell_box
from raytrad.scene.model import barycentric_coordinates

#: How to install Blender's module beside raytrad (see the module docstring).
BPY_INSTALL = "pip install --no-deps 'bpy>=4.2' requests zstandard"
#: The race's targets: worst-surface mean error and point-wise RMS [1].
WORST_SURFACE_TARGET = 0.01
POINT_RMS_TARGET = 0.02
#: The :func:`bench_accuracy.report` keys of the two errors.
WORST_KEY = "worst surface"
RMS_KEY = "point RMS, reference noise removed"
#: Texels of gutter around each atlas tile, filled by Blender's bake margin.
GUTTER = 2
#: Receivers of raytrad's warm-up bake (numba compilation), samples of Cycles'.
WARM_RECEIVERS = 1000
WARM_SPP = 1
LIGHT = CORNELL_SURFACES.index("light")


@dataclass
class Row:
    """One timed bake: its setting, seconds, errors [1] and radiosity at the probes."""

    setting: str
    seconds: float
    worst: float
    rms: float
    got: np.ndarray
    setup: float | None = None

    @property
    def meets(self) -> bool:
        return self.worst <= WORST_SURFACE_TARGET and self.rms <= POINT_RMS_TARGET


@dataclass
class Atlas:
    """A lightmap layout: (T, 3, 2) UVs per triangle corner in [0, 1] (v up, Blender's
    convention), and the image's size in texels."""

    uv: np.ndarray
    width: int
    height: int


@contextlib.contextmanager
def silenced(fd: int) -> Iterator[None]:
    """Drop what anything in this process (Blender's C code included) writes to file
    descriptor ``fd`` (1: stdout, 2: stderr) within the block."""
    for stream in (sys.stdout, sys.stderr):
        stream.flush()
    saved = os.dup(fd)
    try:
        with tempfile.TemporaryFile() as sink:
            os.dup2(sink.fileno(), fd)
            try:
                yield
            finally:
                for stream in (sys.stdout, sys.stderr):
                    stream.flush()
                os.dup2(saved, fd)
    finally:
        os.close(saved)


def import_bpy() -> ModuleType | None:
    """Blender's ``bpy``, or None if it cannot be imported. What the import writes to
    stdout and stderr is dropped: bpy 5.0's wheels, built against NumPy 1.x, fail to load
    their audio module under NumPy 2 with a long message, and the rest of bpy works."""
    try:
        with silenced(1), silenced(2):
            import bpy
    except ImportError:
        return None
    return bpy


def atlas(scene: Scene, texel: float, gutter: int = GUTTER) -> Atlas:
    """One rectangular tile per quad (corners 0-1-2-3, triangles 0-1-2 and 0-2-3), of
    ``|c1 - c0|`` by ``|c3 - c0|`` at ``texel`` [m] per texel, shelf-packed with ``gutter``
    texels around each. Each triangle maps affinely onto half its tile, so the map is
    continuous across the diagonal and the texel density uniform on parallelograms."""
    corners = quad_corners(scene)
    size = np.ceil(np.linalg.norm(corners[:, [1, 3]] - corners[:, [0]], axis=2) / texel).astype(int)
    padded = size + 2 * gutter
    width = max(int(np.ceil(1.1 * np.sqrt(np.prod(padded, axis=1).sum()))), padded[:, 0].max())
    origin = np.zeros_like(size)
    x = y = shelf = 0
    for q in np.argsort(-padded[:, 1], kind="stable"):
        if x + padded[q, 0] > width:
            x, y, shelf = 0, y + shelf, 0
        origin[q] = (x + gutter, y + gutter)
        x, shelf = x + padded[q, 0], max(shelf, padded[q, 1])
    height = y + shelf
    unit = np.array([[0, 0], [1, 0], [1, 1], [0, 1]])
    tile = origin[:, None] + unit[None] * size[:, None]  # (Q, 4, 2) texels
    uv = np.empty((2 * len(corners), 3, 2))
    uv[0::2], uv[1::2] = tile[:, [0, 1, 2]], tile[:, [0, 2, 3]]
    return Atlas(uv / [width, height], int(width), int(height))


def probe_uv(scene: Scene, layout: Atlas, probes: Probes) -> np.ndarray:
    """(N, 2) UVs of the probes: each lies in its quad's plane; of the quad's two triangles
    the one it is inside (the larger least barycentric coordinate) maps it."""
    corners = scene.triangle_vertices()
    both = [2 * probes.quad, 2 * probes.quad + 1]
    bary = [barycentric_coordinates(probes.points, corners[t]) for t in both]
    second = bary[1].min(axis=1) > bary[0].min(axis=1)
    triangle = np.where(second, both[1], both[0])
    weights = np.where(second[:, None], bary[1], bary[0])
    return np.einsum("ij,ijk->ik", weights, layout.uv[triangle])


def bilinear(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """(N, C) values of ``image`` (H, W, C), row 0 at v = 0, at ``uv`` (N, 2), bilinear
    between texel centres (clamped at the border) as a GPU samples a lightmap."""
    height, width = image.shape[:2]
    xy = uv * [width, height] - 0.5
    low = np.floor(xy).astype(int)
    frac = xy - low
    x0, y0 = np.clip(low[:, 0], 0, width - 1), np.clip(low[:, 1], 0, height - 1)
    x1, y1 = np.clip(low[:, 0] + 1, 0, width - 1), np.clip(low[:, 1] + 1, 0, height - 1)
    fx, fy = frac[:, :1], frac[:, 1:]
    return (1 - fy) * ((1 - fx) * image[y0, x0] + fx * image[y0, x1]) + fy * (
        (1 - fx) * image[y1, x0] + fx * image[y1, x1]
    )


def _material(bpy: ModuleType, name: str, rho: np.ndarray, exitance: np.ndarray, image: object):
    """A Blender material: front faces diffuse of reflectance ``rho`` (3,) [1] plus an
    emission of exitance ``exitance`` (3,) [W m-2] (radiance ``exitance / pi``), back faces
    black (raytrad's single-sided surfaces neither reflect nor emit there); ``image``'s
    texture node active, the bake target."""
    material = bpy.data.materials.new(name)
    if material.node_tree is None:  # Blender < 5.0: materials start without nodes
        material.use_nodes = True
    nodes, links = material.node_tree.nodes, material.node_tree.links
    nodes.clear()
    front = nodes.new("ShaderNodeBsdfDiffuse")
    front.inputs["Color"].default_value = (*rho, 1.0)
    radiance = exitance / np.pi
    strength = float(radiance.max())
    if strength > 0:
        emission = nodes.new("ShaderNodeEmission")
        emission.inputs["Color"].default_value = (*(radiance / strength), 1.0)
        emission.inputs["Strength"].default_value = strength
        both = nodes.new("ShaderNodeAddShader")
        links.new(front.outputs[0], both.inputs[0])
        links.new(emission.outputs[0], both.inputs[1])
        front = both
        material.cycles.emission_sampling = "FRONT"
    back = nodes.new("ShaderNodeBsdfDiffuse")
    back.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    side = nodes.new("ShaderNodeMixShader")
    links.new(nodes.new("ShaderNodeNewGeometry").outputs["Backfacing"], side.inputs[0])
    links.new(front.outputs[0], side.inputs[1])
    links.new(back.outputs[0], side.inputs[2])
    links.new(side.outputs[0], nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
    texture = nodes.new("ShaderNodeTexImage")
    texture.image = image
    nodes.active = texture
    return material


def blender_scene(bpy: ModuleType, scene: Scene, layout: Atlas, threads: int) -> object:
    """Build ``scene`` in an empty Blender file for Cycles baking (see the module
    docstring) and return the bake target image (float, non-colour: linear radiance)."""
    with silenced(1), silenced(2):  # "Unable to initialise audio"
        bpy.ops.wm.read_factory_settings(use_empty=True)
    world = bpy.data.worlds.new("black")
    world.color = (0.0, 0.0, 0.0)
    for node in world.node_tree.nodes if world.node_tree else []:
        if node.type == "BACKGROUND":  # a new world's nodes light it grey (0.05)
            node.inputs["Strength"].default_value = 0.0
    target = bpy.context.scene
    target.world = world
    image = bpy.data.images.new("lightmap", layout.width, layout.height, float_buffer=True)
    image.colorspace_settings.name = "Non-Color"
    mesh = bpy.data.meshes.new("cornell")
    mesh.from_pydata(scene.positions.tolist(), [], scene.triangles.tolist())
    for m, name in enumerate(scene.material_names):
        mesh.materials.append(
            _material(
                bpy,
                name,
                scene.material_reflectance[m],
                scene.material_emitted_exitance[m],
                image,
            )
        )
    mesh.polygons.foreach_set("material_index", scene.material_index.astype(np.int32))
    mesh.uv_layers.new(name="lightmap").data.foreach_set("uv", layout.uv.astype(np.float32).ravel())
    mesh.update()
    obj = bpy.data.objects.new("cornell", mesh)
    target.collection.objects.link(obj)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    target.render.engine = "CYCLES"
    target.render.threads_mode = "FIXED"
    target.render.threads = threads
    cycles = target.cycles
    cycles.device = "CPU"
    cycles.use_adaptive_sampling = False
    cycles.use_denoising = False
    cycles.sample_clamp_direct = cycles.sample_clamp_indirect = 0.0
    cycles.max_bounces = cycles.diffuse_bounces = 64
    return image


def cycles_bake(bpy: ModuleType, image: object, spp: int) -> tuple[np.ndarray, float]:
    """Bake the COMBINED pass at ``spp`` samples per texel: (H, W, 3) radiosity
    [W m-2] (pi x the baked outgoing radiance) and the bake call's wall time [s]."""
    bpy.context.scene.cycles.samples = spp
    start = time.perf_counter()
    with silenced(1):  # "Info: Baking map saved to internal image"
        bpy.ops.object.bake(
            type="COMBINED",
            pass_filter={"EMIT", "DIRECT", "INDIRECT", "DIFFUSE"},
            margin=GUTTER,
            margin_type="EXTEND",
            use_clear=True,
        )
    seconds = time.perf_counter() - start
    pixels = np.empty(image.size[0] * image.size[1] * 4, dtype=np.float32)
    image.pixels.foreach_get(pixels)
    return np.pi * pixels.reshape(image.size[1], image.size[0], 4)[..., :3], seconds


def errors(got: np.ndarray, truth: tuple, verbose: bool, name: str) -> tuple[float, float]:
    """Worst-surface mean error and point-wise RMS [1] of ``got`` (N, 3) [W m-2] by
    :func:`bench_accuracy.report`; ``truth`` is its (ref, ref_error, probes, quad_area)."""
    ref, ref_error, probes, quad_area = truth
    sink = contextlib.nullcontext() if verbose else contextlib.redirect_stdout(io.StringIO())
    with sink:
        out = report(name, got, ref, ref_error, probes, quad_area)
    return out[WORST_KEY], out[RMS_KEY]


def race_raytrad(scene: Scene, receivers: list[int], truth: tuple, verbose: bool) -> list[Row]:
    """raytrad at each receiver count, after a warm-up bake."""
    probes = truth[2]
    bake(scene, WARM_RECEIVERS)
    rows = []
    for count in receivers:
        baked = bake(scene, count)
        got = radiosity_at(baked.mesh, baked.shown, probes.points, probes.normals)
        name = f"{count} receivers ({baked.solved} solved, {baked.mesh.receiver_count} baked)"
        rows.append(Row(name, baked.seconds, *errors(got, truth, verbose, name), got))
        print(f"  raytrad {name}: {baked.seconds:.1f} s", flush=True)
    return rows


def race_cycles(
    bpy: ModuleType, scene: Scene, args: argparse.Namespace, truth: tuple
) -> tuple[list[Row], Atlas]:
    """Cycles at each samples per texel, after a warm-up bake."""
    probes = truth[2]
    start = time.perf_counter()
    layout = atlas(scene, args.texel)
    image = blender_scene(bpy, scene, layout, args.threads)
    setup = time.perf_counter() - start
    uv = probe_uv(scene, layout, probes)
    cycles_bake(bpy, image, WARM_SPP)
    rows = []
    for spp in args.spp:
        radiosity, seconds = cycles_bake(bpy, image, spp)
        got = bilinear(radiosity, uv)
        name = f"{spp} spp"
        rows.append(Row(name, seconds, *errors(got, truth, args.verbose, name), got, setup))
        print(f"  Cycles {name}: {seconds:.1f} s", flush=True)
    return rows, layout


def print_table(title: str, rows: list[Row]) -> None:
    """One renderer's rows: setting, seconds, the two errors [%], both targets met."""
    setup = rows[0].setup is not None
    print(f"\n{title}")
    head = f"  {'setting':42s} {'seconds':>8s}"
    head += f" {'setup s':>8s}" if setup else ""
    print(head + f" {'worst surface':>14s} {'point RMS':>10s}  meets both")
    for row in rows:
        line = f"  {row.setting:42s} {row.seconds:8.1f}"
        line += f" {row.setup:8.2f}" if setup else ""
        verdict = "yes" if row.meets else "no"
        print(line + f" {100 * row.worst:13.2f}% {100 * row.rms:9.2f}%  {verdict}")


def print_units(cycles: Row, truth: tuple, scene: Scene) -> None:
    """The light's mean radiosity (Cycles, reference, emitted exitance) and every surface's
    mean ratio Cycles / reference, per channel."""
    ref, _, probes, _ = truth
    area = np.isinf(probes.contact) & ~probes.shut
    light = area & (probes.quad == LIGHT)
    emitted = scene.emitted_exitance[2 * LIGHT]
    print(f"\nunits check at {cycles.setting} (radiosity [W m-2], RGB):")
    print(
        f"  light: Cycles {np.round(cycles.got[light].mean(0), 2)}, reference "
        f"{np.round(ref[light].mean(0), 2)}, emitted exitance {np.round(emitted, 2)}"
    )
    ratios = [
        f"{surface} {np.round(cycles.got[rows].mean(0) / ref[rows].mean(0), 3)}"
        for q, surface in enumerate(CORNELL_SURFACES)
        if (rows := area & (probes.quad == q)).any()
    ]
    print("  Cycles / reference means: " + "; ".join(ratios))


def first_meeting(rows: list[Row]) -> Row | None:
    """The first row (in the given order) meeting both targets."""
    return next((row for row in rows if row.meets), None)


def print_race(ours: list[Row], theirs: list[Row]) -> None:
    """The first setting of each meeting both targets and the ratio of their times."""
    mine, cycles = first_meeting(ours), first_meeting(theirs)
    targets = f"worst surface <= {100 * WORST_SURFACE_TARGET:g} % and point RMS "
    targets += f"<= {100 * POINT_RMS_TARGET:g} %"
    print(f"\nrace to {targets}:")
    for label, row in (("raytrad", mine), ("Cycles", cycles)):
        print(f"  {label:8s} " + (f"{row.setting}, {row.seconds:.1f} s" if row else "never"))
    if mine and cycles:
        print(f"  Cycles / raytrad time: {cycles.seconds / mine.seconds:.2f}")
    elif mine:
        slowest = max(row.seconds for row in theirs)
        print(f"  Cycles / raytrad time: > {slowest / mine.seconds:.2f} (Cycles never met both)")


def probe_set(scene: Scene, per_quad: int, along: int) -> Probes:
    """bench_accuracy's probes: area probes (seed 7) then contact probes, its order."""
    area = area_probes(scene, per_quad, np.random.default_rng(7))
    contact = contact_probes(scene, along)
    fields = ("points", "normals", "quad", "contact")
    return Probes(*(np.concatenate([getattr(area, f), getattr(contact, f)]) for f in fields))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--receivers",
        type=int,
        nargs="+",
        default=[2000, 5000, 7500, 10000, 20000],
        help="raytrad's receiver targets, in the order raced",
    )
    parser.add_argument(
        "--spp",
        type=int,
        nargs="+",
        default=[16, 64, 256, 512, 1024],
        help="Cycles' samples per texel, in the order raced",
    )
    parser.add_argument("--threads", type=int, default=2, help="Cycles' CPU threads")
    parser.add_argument("--texel", type=float, default=0.005, help="Cycles' texel size [m]")
    parser.add_argument("--per-quad", type=int, default=256, help="area probes per quad")
    parser.add_argument("--along", type=int, default=8, help="contact probes along a line")
    parser.add_argument("--paths", type=int, default=20000, help="reference paths per point")
    parser.add_argument(
        "--cache",
        type=Path,
        default=ROOT / ".cache" / "accuracy",
        help="reference cache (bench_accuracy's)",
    )
    parser.add_argument("--verbose", action="store_true", help="every surface's error")
    args = parser.parse_args(argv)
    bpy = import_bpy()
    if bpy is None:
        print(f"bench_race: bpy is not importable; install it: {BPY_INSTALL}", file=sys.stderr)
        return 2
    print(f"Blender {bpy.app.version_string}, Cycles on the CPU with {args.threads} threads")
    scene = cornell_box()
    probes = probe_set(scene, args.per_quad, args.along)
    ref, ref_error = reference(scene, probes, args.paths, args.cache)
    probes.shut = shut_in(scene, probes)
    triangle_area = triangle_areas_normals(scene.triangle_vertices())[0]
    truth = (ref, ref_error, probes, triangle_area[0::2] + triangle_area[1::2])
    ours = race_raytrad(scene, args.receivers, truth, args.verbose)
    theirs, layout = race_cycles(bpy, scene, args, truth)
    print_table(
        "raytrad (seconds: whole bake: mesh, form factors, solve, refinement; numba warm)", ours
    )
    print_table(
        f"Cycles ({layout.width} x {layout.height} atlas, {args.texel * 1000:g} mm texels; "
        "seconds: the bake call; setup: building the Blender scene, once)",
        theirs,
    )
    print_units(theirs[-1], truth, scene)
    print_race(ours, theirs)
    return 0


if __name__ == "__main__":
    sys.exit(main())
