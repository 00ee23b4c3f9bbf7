"""Race raytrad against Blender's Cycles baker and against Mitsuba 3 on the Cornell box, on
the CPU: the time each needs to reach both 1 % worst-surface mean error and 2 % point-wise
RMS; and check the race's reference against Mitsuba's path tracer.

The renderers are measured in one run, at the same probe points and against the same
cached path-traced reference as ``tools/bench_accuracy.py`` (its area and contact probes,
``--per-quad``/``--along``/``--paths``/``--cache`` with the same defaults, so the two tools
share one cache; on a fresh checkout the first run path-traces it, about 4 minutes), with
its error definitions (:func:`bench_accuracy.report`):

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
its own footprint with no subdivision of the mesh. The probes read the texture
bilinearly at their UVs (found from their triangle's barycentric coordinates), times pi.

Both lightmaps are finished alike (``tools/race_atlas.py``): texels whose centre no one
sees (most of 16 rays from it hit the back of a surface: the floor under a block, the
ceiling behind the light) are filled from their seen neighbours, a ring at a time, and
the gutters extended again. Read as baked, those dark texels bleed a texel onto the lit
surface beside them: point-sampled texels (Mitsuba's) then level off near 2.1 % RMS at
5 mm and 2.5 mm alike. The texture's discretisation (each texel averages its footprint,
probes interpolate between texel centres) still puts a floor under Cycles' point RMS,
about 1.7 % at ``--texel 0.005`` before the fill (78 000 texels; fitted as
``RMS^2 = noise^2 / spp + floor^2`` over 64-1 024 spp), some 2.5 % at 10 mm (never under
2 %) and 0.9 % at 2.5 mm (four times the texels, so four times the time per spp): 5 mm is
about Cycles' fastest way to 2 %. A Cycles row's seconds are the wall time of the bake
call (``bpy.ops.object.bake``: Cycles' scene sync, BVH build and sampling) plus finding
the hidden texels and the fill; building the Blender scene (mesh, materials, image) is
timed once, apart (``setup``), and not counted in the race. A 1-spp warm-up bake precedes
the timed ones.

Mitsuba 3 (pip ``mitsuba`` with Debian's ``libllvm19``, its ``llvm_ad_rgb`` variant; a
benchmark dependency, never a runtime one; see ``tools/mitsuba_bake.py``) has no baker:
it fills an atlas laid out as Cycles' (``--mitsuba-texel``, 5 mm as Cycles' by default),
each seen tile texel with the radiosity path traced at the texel's centre
(``--mitsuba-spp`` paths, each an emitter sample and a cosine-weighted path by Mitsuba's
``path`` integrator), on ``--threads`` threads. A row's seconds are the estimate, the
image, finding the hidden texels and the fill; building the Mitsuba scene is ``setup``. A
1-spp warm-up (Dr.Jit compiles its kernels) precedes the timed rows.

Second reference (printed unless ``--mitsuba-reference 0``): Mitsuba at the probes
themselves against the cached reference, which raytrad's own path tracer
(:func:`raytrad.core.pathtrace.path_traced_radiosity`) makes: every surface's mean ratio
and the RMS of their difference over the two standard errors combined (about 1 where
they agree to within their noise).

Units check (printed): each renderer's mean radiosity on the light against the
reference's (emission plus its reflected irradiance) and its emitted exitance, and every
surface's mean ratio renderer / reference at its largest samples.

    python -m pip install --no-deps 'bpy>=4.2' requests zstandard
    python -m pip install mitsuba && apt install libllvm19
    python tools/bench_race.py                 # 2k-20k receivers, 16-1024 spp
    python tools/bench_race.py --against mitsuba --receivers 5000 --mitsuba-spp 64 256

(``--no-deps``: bpy 5.0's wheel pins NumPy 1.x, which raytrad's other dependencies have
outgrown; with NumPy 2 everything but Blender's audio module loads, and the race needs
no audio.)

Exits with status 2 and one line if a renderer ``--against`` names cannot be loaded.
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
    bake,
    probe_set,
    reference,
    report,
    shut_in,
)
from mitsuba_bake import VARIANT, import_mitsuba, irradiance_at, mitsuba_scene
from race_atlas import GUTTER, Atlas, Texels, atlas, bilinear, finish, probe_uv, tile_texels

from raytrad.products.probe import radiosity_at
from raytrad.scene import Scene, triangle_areas_normals
from raytrad.scene.builtin import cornell_box

#: How to install Blender's module beside raytrad (see the module docstring).
BPY_INSTALL = "pip install --no-deps 'bpy>=4.2' requests zstandard"
#: The race's targets: worst-surface mean error and point-wise RMS [1].
WORST_SURFACE_TARGET = 0.01
POINT_RMS_TARGET = 0.02
#: The :func:`bench_accuracy.report` keys of the two errors.
WORST_KEY = "worst surface"
RMS_KEY = "point RMS, reference noise removed"
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
    texels, hiding = timed_texels(scene, layout)
    cycles_bake(bpy, image, WARM_SPP)
    rows = []
    for spp in args.spp:
        radiosity, seconds = cycles_bake(bpy, image, spp)
        start = time.perf_counter()
        finish(radiosity, texels, GUTTER, layout)
        seconds += time.perf_counter() - start + hiding
        got = bilinear(radiosity, uv)
        name = f"{spp} spp"
        rows.append(Row(name, seconds, *errors(got, truth, args.verbose, name), got, setup))
        print(f"  Cycles {name}: {seconds:.1f} s", flush=True)
    return rows, layout


def race_mitsuba(
    mi: ModuleType, dr: ModuleType, scene: Scene, args: argparse.Namespace, truth: tuple
) -> tuple[list[Row], Atlas]:
    """Mitsuba at each samples per texel, into an atlas laid out as Cycles' (at
    ``--mitsuba-texel``), after a warm-up (Dr.Jit compiles its kernels): each seen tile
    texel's centre gets the radiosity :func:`mitsuba_bake.irradiance_at` estimates there,
    the image is finished as Cycles' (:func:`race_atlas.finish`) and the probes read it.
    A row's seconds are the estimate, the image and finding the hidden texels; setup is
    building the Mitsuba scene, once."""
    probes = truth[2]
    start = time.perf_counter()
    target = mitsuba_scene(mi, scene)
    setup = time.perf_counter() - start
    layout = atlas(scene, args.mitsuba_texel)
    texels, hiding = timed_texels(scene, layout)
    seen = texels.visible
    material = scene.material_index[2 * texels.quads[seen]]
    rho = scene.material_reflectance[material]
    emitted = scene.material_emitted_exitance[material]
    points, normals, texel = texels.points[seen], texels.normals[seen], texels.texel[seen]
    uv = probe_uv(scene, layout, probes)
    irradiance_at(mi, dr, target, points, normals, WARM_SPP)
    rows = []
    for spp in args.mitsuba_spp:
        start = time.perf_counter()
        irradiance, _ = irradiance_at(mi, dr, target, points, normals, spp, seed=spp)
        image = np.zeros((layout.height, layout.width, 3))
        image[texel[:, 1], texel[:, 0]] = emitted + rho * irradiance
        finish(image, texels, GUTTER, layout)
        seconds = time.perf_counter() - start + hiding
        got = bilinear(image, uv)
        name = f"{spp} spp"
        rows.append(Row(name, seconds, *errors(got, truth, args.verbose, name), got, setup))
        print(f"  Mitsuba {name}: {seconds:.1f} s", flush=True)
    return rows, layout


def timed_texels(scene: Scene, layout: Atlas) -> tuple[Texels, float]:
    """:func:`race_atlas.tile_texels` and its wall time [s]."""
    start = time.perf_counter()
    texels = tile_texels(scene, layout)
    return texels, time.perf_counter() - start


def check_reference(mi: ModuleType, dr: ModuleType, scene: Scene, truth: tuple, spp: int) -> None:
    """Mitsuba at the probes themselves (``spp`` samples each) against the race's
    path-traced reference: every surface's mean ratio, and the RMS over the probes of
    their difference in units of the two standard errors combined (about 1 when they
    agree to within their noise)."""
    ref, ref_error, probes, _ = truth
    owner = scene.material_index[2 * probes.quad]
    start = time.perf_counter()
    target = mitsuba_scene(mi, scene)
    irradiance, error = irradiance_at(mi, dr, target, probes.points, probes.normals, spp, seed=1)
    rho = scene.material_reflectance[owner]
    got = scene.material_emitted_exitance[owner] + rho * irradiance
    seconds = time.perf_counter() - start
    area = np.isinf(probes.contact) & ~probes.shut
    print(f"\nsecond reference: Mitsuba at the probes, {spp} samples each ({seconds:.1f} s)")
    ratios = [
        f"{surface} {np.round(got[rows].mean(0) / ref[rows].mean(0), 4)}"
        for q, surface in enumerate(CORNELL_SURFACES)
        if (rows := area & (probes.quad == q)).any()
    ]
    print("  Mitsuba / reference means: " + "; ".join(ratios))
    spread = np.sqrt(ref_error**2 + (rho * error) ** 2)
    seen = (spread > 0).all(axis=1) & ~probes.shut
    z = (got[seen] - ref[seen]) / spread[seen]
    print(
        f"  difference / combined standard error, RMS over {seen.sum()} probes (RGB): "
        f"{np.round(np.sqrt((z**2).mean(0)), 3)}"
    )


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


def print_units(label: str, row: Row, truth: tuple, scene: Scene) -> None:
    """The light's mean radiosity (``label``'s, the reference's, the emitted exitance) and
    every surface's mean ratio ``label`` / reference, per channel."""
    ref, _, probes, _ = truth
    area = np.isinf(probes.contact) & ~probes.shut
    light = area & (probes.quad == LIGHT)
    emitted = scene.emitted_exitance[2 * LIGHT]
    print(f"\nunits check, {label} at {row.setting} (radiosity [W m-2], RGB):")
    print(
        f"  light: {label} {np.round(row.got[light].mean(0), 2)}, reference "
        f"{np.round(ref[light].mean(0), 2)}, emitted exitance {np.round(emitted, 2)}"
    )
    ratios = [
        f"{surface} {np.round(row.got[rows].mean(0) / ref[rows].mean(0), 3)}"
        for q, surface in enumerate(CORNELL_SURFACES)
        if (rows := area & (probes.quad == q)).any()
    ]
    print(f"  {label} / reference means: " + "; ".join(ratios))


def first_meeting(rows: list[Row]) -> Row | None:
    """The first row (in the given order) meeting both targets."""
    return next((row for row in rows if row.meets), None)


def print_race(ours: list[Row], others: dict[str, list[Row]]) -> None:
    """The first setting of each renderer meeting both targets and each other renderer's
    time over raytrad's."""
    mine = first_meeting(ours)
    targets = f"worst surface <= {100 * WORST_SURFACE_TARGET:g} % and point RMS "
    targets += f"<= {100 * POINT_RMS_TARGET:g} %"
    print(f"\nrace to {targets}:")
    for label, row in (("raytrad", mine), *((k, first_meeting(v)) for k, v in others.items())):
        print(f"  {label:8s} " + (f"{row.setting}, {row.seconds:.1f} s" if row else "never"))
    for label, rows in others.items():
        theirs = first_meeting(rows)
        if mine and theirs:
            print(f"  {label} / raytrad time: {theirs.seconds / mine.seconds:.2f}")
        elif mine:
            slowest = max(row.seconds for row in rows)
            ratio = slowest / mine.seconds
            print(f"  {label} / raytrad time: > {ratio:.2f} ({label} never met both)")


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
    parser.add_argument(
        "--mitsuba-spp",
        type=int,
        nargs="+",
        default=[16, 64, 256, 512, 1024],
        help="Mitsuba's samples per texel, in the order raced",
    )
    parser.add_argument(
        "--mitsuba-reference",
        type=int,
        default=4096,
        help="Mitsuba's samples per probe for the second reference (0: none)",
    )
    parser.add_argument(
        "--against",
        nargs="+",
        choices=("cycles", "mitsuba"),
        default=["cycles", "mitsuba"],
        help="the renderers raytrad races",
    )
    parser.add_argument("--threads", type=int, default=2, help="Cycles' and Mitsuba's threads")
    parser.add_argument("--texel", type=float, default=0.005, help="Cycles' texel size [m]")
    parser.add_argument(
        "--mitsuba-texel", type=float, default=0.005, help="Mitsuba's texel size [m]"
    )
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
    renderers = load_renderers(args)
    if isinstance(renderers, str):
        print(f"bench_race: {renderers}", file=sys.stderr)
        return 2
    scene = cornell_box()
    probes = probe_set(scene, args.per_quad, args.along)
    ref, ref_error = reference(scene, probes, args.paths, args.cache)
    probes.shut = shut_in(scene, probes)
    triangle_area = triangle_areas_normals(scene.triangle_vertices())[0]
    truth = (ref, ref_error, probes, triangle_area[0::2] + triangle_area[1::2])
    ours = race_raytrad(scene, args.receivers, truth, args.verbose)
    others = {}
    tables = []
    if "cycles" in renderers:
        others["Cycles"], layout = race_cycles(renderers["cycles"], scene, args, truth)
        tables.append(
            f"Cycles ({layout.width} x {layout.height} atlas, {args.texel * 1000:g} mm texels; "
            "seconds: the bake call, hidden texels and fill; setup: the Blender scene, once)"
        )
    if "mitsuba" in renderers:
        mi, dr = renderers["mitsuba"]
        others["Mitsuba"], layout = race_mitsuba(mi, dr, scene, args, truth)
        tables.append(
            f"Mitsuba ({layout.width} x {layout.height} atlas, "
            f"{args.mitsuba_texel * 1000:g} mm texels, "
            "a path per texel centre and sample; seconds: the estimate, the image, hidden "
            "texels and fill; setup: the Mitsuba scene, once)"
        )
    print_table(
        "raytrad (seconds: whole bake: mesh, form factors, solve, refinement; numba warm)", ours
    )
    for title, rows in zip(tables, others.values(), strict=True):
        print_table(title, rows)
    for label, rows in others.items():
        print_units(label, rows[-1], truth, scene)
    if "mitsuba" in renderers and args.mitsuba_reference > 0:
        check_reference(*renderers["mitsuba"], scene, truth, args.mitsuba_reference)
    print_race(ours, others)
    return 0


def load_renderers(args: argparse.Namespace) -> dict | str:
    """The renderers ``args.against`` names, imported (``cycles``: ``bpy``; ``mitsuba``:
    Mitsuba and Dr.Jit), with their versions printed; or one line saying which is
    missing and how to install it."""
    renderers: dict = {}
    if "cycles" in args.against:
        bpy = import_bpy()
        if bpy is None:
            return f"bpy is not importable; install it: {BPY_INSTALL}"
        print(f"Blender {bpy.app.version_string}, Cycles on the CPU with {args.threads} threads")
        renderers["cycles"] = bpy
    if "mitsuba" in args.against:
        loaded = import_mitsuba(args.threads)
        if isinstance(loaded, str):
            return loaded
        mi, dr = loaded
        print(
            f"Mitsuba {mi.__version__} ({VARIANT}, Dr.Jit {dr.__version__}, "
            f"{os.environ['DRJIT_LIBLLVM_PATH']}) on the CPU with {args.threads} threads"
        )
        renderers["mitsuba"] = loaded
    return renderers


if __name__ == "__main__":
    sys.exit(main())
