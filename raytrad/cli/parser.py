"""The ``raytrad`` argument parser: commands, options, help and their defaults."""

from __future__ import annotations

import argparse
from pathlib import Path

from raytrad import __version__
from raytrad.settings import (
    ImageSettings,
    LightmapSettings,
    MeshSettings,
    RefineSettings,
    RenderSettings,
    defaults,
    method_summaries,
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="raytrad",
        description="Ray-traced radiosity: bake converged diffuse interreflection into the "
        "vertices of a scene (vertex-to-patch progressive radiosity, Embree visibility).",
    )
    parser.add_argument("--version", action="version", version=f"raytrad {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    render = sub.add_parser(
        "render",
        help="solve a scene and write per-vertex radiosity (PLY) and report.json",
        description="Solve SCENE and write DIR/<name>.ply (float radiosity_r/g/b [W m-2] "
        "and 8-bit display colours per vertex) and DIR/report.json (settings, timings, "
        "energy ledger, error log).",
        epilog=_UNITS,
    )
    _add_common(render, default_tolerance=1e-3)
    render.add_argument(
        "--method",
        choices=list(method_summaries()),
        default="ambient",
        help=f"solver ({_methods_text()}); default: %(default)s",
    )
    render.add_argument(
        "--exposure",
        type=float,
        default=None,
        metavar="EV",
        help="brighten the PLY display colours by EV stops on top of the automatic exposure "
        "(default: the scene file's [output] exposure, else 0)",
    )
    outputs = render.add_argument_group(
        "lightmaps, images and glTF (a TOML scene's [output] and [camera] give defaults)"
    )
    outputs.add_argument(
        "--lightmap",
        action="store_true",
        help="bake DIR/<name>.lightmap.exr (radiosity [W m-2], half float) in the model's "
        "lightmap UVs or a generated atlas (see --uv-set), and a preview PNG",
    )
    outputs.add_argument(
        "--lightmap-resolution",
        type=int,
        default=None,
        metavar="TEXELS",
        help=f"atlas size in texels (default: {defaults_text('lightmap_resolution')})",
    )
    outputs.add_argument(
        "--texel-density",
        type=float,
        default=None,
        metavar="PER_METRE",
        help="texels per metre instead of a fixed atlas size",
    )
    outputs.add_argument(
        "--lightmap-padding",
        type=int,
        default=LightmapSettings().padding,
        metavar="TEXELS",
        help="padding between charts (default: %(default)s)",
    )
    outputs.add_argument(
        "--lightmap-float",
        action="store_true",
        help="write the lightmap as 32-bit float instead of half",
    )
    outputs.add_argument(
        "--uv-set",
        default="auto",
        metavar="auto|atlas|N",
        help="lightmap UVs: 'auto' uses the model's glTF TEXCOORD_1 when every face has it, "
        "else generates an atlas; 'atlas' always generates one; N uses the model's UV set N "
        "(glTF TEXCOORD_N; OBJ vt and PLY s,t are set 0) (default: %(default)s)",
    )
    outputs.add_argument(
        "--lightmap-per-mesh",
        action="store_true",
        help="one lightmap per mesh (glTF node, OBJ object, TOML [[mesh]]): "
        "DIR/<name>.<mesh>.lightmap.exr",
    )
    outputs.add_argument(
        "--image",
        action="store_true",
        help="render DIR/<name>.exr (linear radiance [W sr-1 m-2]) and "
        "DIR/<name>.png (exposed, sRGB) from a camera",
    )
    outputs.add_argument(
        "--width",
        type=int,
        default=None,
        help="image width (default: height x the glTF camera's aspect ratio, else "
        f"{defaults_text('image_width')})",
    )
    outputs.add_argument(
        "--height",
        type=int,
        default=None,
        help=f"image height (default: {defaults_text('image_height')})",
    )
    outputs.add_argument(
        "--spp",
        type=int,
        default=ImageSettings().samples,
        help="samples per pixel for anti-aliasing (default: %(default)s)",
    )
    outputs.add_argument(
        "--camera",
        default=None,
        metavar="X,Y,Z:TX,TY,TZ[:FOV]",
        help="camera position and look-at point [m] and vertical field of "
        "view [degrees]; default: the scene file's (TOML [camera], glTF camera), else an "
        "automatic framing",
    )
    outputs.add_argument(
        "--up",
        choices=("y", "z"),
        default="y",
        help="the scene's up axis, for the automatic camera and --camera: y (glTF, most "
        "engines) or z (CAD, Blender without axis conversion) (default: %(default)s)",
    )
    outputs.add_argument(
        "--tonemap",
        choices=("srgb", "aces"),
        default="srgb",
        help="display encoding of the image PNG: 'srgb' clips then encodes; 'aces' is the "
        "filmic ACES output transform of OpenImageIO's colour management (default: %(default)s)",
    )
    outputs.add_argument(
        "--view",
        default=None,
        metavar="NAME",
        help="which of a glTF file's cameras to render from, by node name (default: the first)",
    )
    outputs.add_argument(
        "--gltf",
        action="store_true",
        help="write the baked model DIR/<name>.glb (vertex colours COLOR_0; "
        "with --lightmap also TEXCOORD_1 and the lightmap image)",
    )
    refine = render.add_argument_group("adaptive refinement after the solve")
    refine.add_argument(
        "--refine-threshold",
        type=float,
        default=RefineSettings().threshold,
        metavar="FRACTION",
        help="split elements whose corners' radiosity differs by more than this fraction "
        "of their level (shadow edges, contact lines), or where a new receiver's gather "
        "differed from the interpolation by more than 3%% of this fraction of its own "
        "value (0.3%% at 0.1); 0 turns refinement "
        "off (default: %(default)s)",
    )
    refine.add_argument(
        "--max-receivers",
        type=int,
        default=None,
        metavar="N",
        help="receiver budget of the refined mesh (default: twice the solved receivers)",
    )
    render.add_argument(
        "--reference",
        default=None,
        metavar="REF",
        help="log the true error against REF: 'dense' (direct solve of the same system, "
        "small scenes), 'analytic' (closed uniform enclosure, B = E/(1-rho)) or a previous "
        "result .ply",
    )
    render.add_argument(
        "--plot", action="store_true", help="also write DIR/convergence.png: error against time"
    )
    render.add_argument(
        "--resume",
        action="store_true",
        help="continue a stopped run (Ctrl-C, SIGTERM, --time-limit, --max-shots, or a killed "
        "run's last periodic checkpoint, see --checkpoint-every) from its checkpoint in DIR; "
        "--max-shots counts the whole solve's shots, --time-limit this command's seconds",
    )
    compare = sub.add_parser(
        "compare",
        help="run several solver methods on one scene and compare error against time",
        description="Run each method on the same receivers and form-factor settings and "
        "write DIR/compare.png (true error against time), DIR/compare.md and "
        "DIR/compare.json (seconds and shots to 1e-2 and 1e-3 true error, final error, "
        "rays).",
        epilog=_UNITS,
    )
    _add_common(compare, default_tolerance=1e-4)
    compare.add_argument(
        "--methods",
        default=",".join(method_summaries()),
        help="comma-separated methods (default: %(default)s)",
    )
    compare.add_argument(
        "--reference",
        default=None,
        metavar="REF",
        help="'dense', 'analytic' or a previous result .ply; default: a dense solve when it "
        "fits in memory, else a long converged run (the output says which)",
    )
    verify = sub.add_parser(
        "verify",
        help="check that an output folder holds one complete, consistent run",
        description="Check DIR against its raytrad-run.json: every output the last run "
        "listed is there, unchanged, and the run finished. Exit 0 when complete and "
        "consistent, 1 otherwise (a run killed while writing or stopped by Ctrl-C or a "
        "signal, or old and new files side by side).",
    )
    verify.add_argument("directory", type=Path, metavar="DIR")
    verify.add_argument(
        "--finished",
        action="store_true",
        help="also exit 1 when the run stopped before its tolerance (--time-limit, "
        "--max-shots, or refinement cut short): a whole set of the best answer it had, "
        "with a checkpoint to --resume",
    )
    _add_bake(sub)
    return parser


def _add_bake(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    bake = sub.add_parser(
        "bake",
        help="render every job of a TOML manifest, on this machine or a Dask cluster",
        description="Render the jobs of MANIFEST: [defaults] and [[job]] tables of render\n"
        "options, scene and output paths relative to the manifest. Jobs whose outputs are\n"
        "up to date are skipped, failed ones retried, and a summary is printed and written\n"
        "to bake-summary.json beside the manifest. Exit 0 when every job is done or\n"
        "skipped, 1 when one failed, 128 + N when stopped by signal N.",
        epilog=_BAKE_EXAMPLE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    bake.add_argument("manifest", type=Path, metavar="MANIFEST", help="the TOML manifest")
    where = bake.add_mutually_exclusive_group()
    where.add_argument(
        "--workers",
        type=int,
        default=None,
        metavar="N",
        help="jobs at once on this machine, each in its own process (default: one per core; "
        "the cores are shared out among them)",
    )
    where.add_argument(
        "--local-cluster",
        type=int,
        default=None,
        metavar="N",
        help="run on a Dask LocalCluster of N workers (needs raytrad[distributed])",
    )
    where.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="submit to a running Dask scheduler, e.g. tcp://host:8786 (needs "
        "raytrad[distributed])",
    )
    bake.add_argument(
        "--retries",
        type=int,
        default=2,
        metavar="N",
        help="further attempts for a job that failed in a way trying again can mend (a lost "
        "worker, an internal error, a full disk); a broken scene is not retried "
        "(default: %(default)s)",
    )
    bake.add_argument(
        "--summary",
        type=Path,
        default=None,
        metavar="PATH",
        help="where to write the JSON summary (default: bake-summary.json beside MANIFEST)",
    )
    bake.add_argument("-q", "--quiet", action="store_true", help="print only errors")
    bake.add_argument("-v", "--verbose", action="store_true", help="log details")


_BAKE_EXAMPLE = """\
example manifest:
  [defaults]            # any render option, by its long name with _ for -
  receivers = 20000
  lightmap = true
  [[job]]
  scene = "levels/a.glb"   # relative to the manifest
  output = "out/a"
  [[job]]
  scene = "levels/b.obj"
  output = "out/b"
  tolerance = 1e-4         # per-job override
"""


_UNITS = (
    "Units: scene coordinates in metres (see --scale); OBJ Kd = reflectance, Ke = emitted "
    "exitance [W m-2]; glTF emissive = radiance [W sr-1 m-2]."
)


def _methods_text() -> str:
    return ", ".join(f"{name}: {summary}" for name, summary in method_summaries().items())


def defaults_text(name: str) -> str:
    """A default value of :class:`~raytrad.settings.RenderSettings` and its parts, for help,
    when a scene file can override it."""
    return f"the scene file's [output] {name}, else {getattr(defaults, name)}"


def _add_common(parser: argparse.ArgumentParser, default_tolerance: float) -> None:
    """Options shared by ``render`` and ``compare``: scene, output, mesh, stopping rules."""
    defaults = MeshSettings()
    add = parser.add_argument
    add(
        "scene",
        type=Path,
        metavar="SCENE",
        help="scene file: .obj (+.mtl), .gltf, .glb, .ply or .toml",
    )
    add(
        "-o",
        "--output",
        type=Path,
        default=Path("raytrad-out"),
        metavar="DIR",
        help="output directory (default: %(default)s)",
    )
    add(
        "--tolerance",
        type=float,
        default=default_tolerance,
        help="stop when the unshot power falls below this fraction of the emitted power "
        "(default: %(default)g)",
    )
    add(
        "--time-limit",
        type=float,
        default=None,
        metavar="SECONDS",
        help="bound the whole run (form factors, solve, refinement) to about this many "
        "seconds; every emitter still shoots once",
    )
    add("--max-shots", type=int, default=None, metavar="N", help="stop after N shots")
    add(
        "--omega",
        type=float,
        default=1.3,
        help="overrelaxation factor for the overrelaxation method (default: %(default)s)",
    )
    add(
        "--receivers",
        type=int,
        default=defaults.receivers,
        metavar="N",
        help="target receiver (vertex) count: it sets the longest edge from the scene's "
        "area, and edges halve in steps and receivers split at creases, so meshes "
        "usually get up to 60%% more (the Cornell box: 25 911 at 20 000, 59 786 at "
        "60 000), up to about 90%% where many objects stand on "
        "surfaces (their contact outlines are imprinted; the summary and report.json "
        "say how many); every vertex of the scene is kept, so a finely tessellated "
        "scene gets more (a room of 5 942 vertices, tools/cluttered_room.py: 14 177 at "
        "3000) (default: %(default)s)",
    )
    add(
        "--max-edge",
        type=float,
        default=None,
        metavar="METRES",
        help="refine until no edge is longer than this [m] (overrides --receivers)",
    )
    add(
        "--patches",
        type=int,
        default=defaults.patches,
        metavar="N",
        help="target shooting-patch count (default: %(default)s)",
    )
    add(
        "--patch-size",
        type=float,
        default=None,
        metavar="METRES",
        help="largest patch extent [m] (overrides --patches)",
    )
    add(
        "--samples",
        type=int,
        default=defaults.samples,
        metavar="N",
        help="visibility sample points per patch (default: %(default)s)",
    )
    add(
        "--emitter-samples",
        type=int,
        default=defaults.emitter_samples,
        metavar="N",
        help="sample points per emitting patch; more give smoother direct shadows "
        "(default: %(default)s)",
    )
    add(
        "--seed",
        type=int,
        default=defaults.seed,
        help="seed of the sample points; same seed, same result (default: %(default)s)",
    )
    add(
        "--no-imprint",
        dest="imprint",
        action="store_false",
        help="do not put contact lines (another surface's outline on a surface: a block's "
        "foot on the floor) into the mesh",
    )
    add(
        "--scale",
        type=float,
        default=1.0,
        help="multiply coordinates by this to get metres, e.g. 0.001 for millimetres "
        "(default: %(default)s)",
    )
    add(
        "--allow-outside-files",
        action="store_true",
        help="read files the scene refers to (buffers, mtllib, TOML meshes) even outside "
        "the scene file's folder",
    )
    add(
        "--cache-mb",
        type=float,
        default=RenderSettings().cache_mb,
        metavar="MIB",
        help="memory for reusing form factors (and their near-field gather weights) between "
        "shots of a patch; the rest go to temporary files (default: %(default)s)",
    )
    add(
        "--checkpoint-every",
        type=float,
        default=RenderSettings().checkpoint_seconds,
        metavar="SECONDS",
        help="seconds between checkpoints of a long form-factor pass or solve; a pass "
        "checkpoint also waits at least 9 times as long as the last one took to write "
        "(default: %(default)s)",
    )
    add("-q", "--quiet", action="store_true", help="no progress bar, only warnings and errors")
    add("-v", "--verbose", action="store_true", help="log details")
