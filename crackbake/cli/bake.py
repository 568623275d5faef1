"""``crackbake MESH``, the bake: parses options, builds :class:`RunParams`, calls the pipeline.

The default command of the ``crackbake`` group (:mod:`crackbake.cli.group`)."""

from __future__ import annotations

import signal
import sys
import threading
import time
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

import click

from crackbake import __version__
from crackbake.cli.common import CONTEXT, Command, err, silence
from crackbake.errors import CrackbakeError, CrackbakeWarning
from crackbake.params import (
    CRACK_WIDTH_REL_DEFAULT,
    DECAL_RES_DEFAULT,
    DEFAULT_MAX_DISTANCE_FRACTION,
    EXR_COMPRESSION_DEFAULT,
    EXR_COMPRESSIONS,
    FORMATS,
    FORMATS_DEFAULT,
    METHODS,
    MIN_PX_DEFAULT,
    NORMAL_Y,
    PADDING_MIN,
    PADDING_RES_PER_TEXEL,
    PROFILE_DEFAULT,
    RES_DEFAULT,
    RES_MAX,
    RES_MIN,
    SEED_DEFAULT,
    SIM_FACES_DEFAULT,
    SIM_PROXY_DEFAULT,
    SIM_PROXY_MODES,
    SPACING_DEFAULT,
    STRESS_RES_DEFAULT,
    TARGET_DEFAULT,
    TARGETS,
    UNWRAP_TIMEOUT_DEFAULT,
    UP_AXES,
    UV_DEFAULT,
    UV_MODES,
    load_preset,
    parse_direction,
    parse_impact,
    preset_names,
)
from crackbake.params import (
    SOLVER_DEFAULTS as D,
)
from crackbake.params.speed import MATERIAL_DEFAULT, MATERIALS, THICKNESS_DEFAULT

if TYPE_CHECKING:
    from crackbake.params import RunParams

# What only a run needs (the display, the interrupt, RunParams' dataclass) is imported in the
# command's body: ``crackbake --help`` pays for click and the options alone (issue 25).

#: Options that shape only the command's own console output, not the run (:func:`run_params`
#: never sees them; the batch command refuses them in a job).
CONSOLE_OPTIONS = ("quiet", "verbose", "as_json", "progress")

EPILOG = """\b
Examples:
  # glass impact on the cow's flank, 4096x4096 maps on its own UVs
  crackbake examples/spot.obj --preset glass --impact 0.334,0.044,0.287 --res 4096
\b
  # drying mud over the whole surface, the simpler thesis method, a different seed
  crackbake examples/spot.obj --preset mud --method thesis --seed 7
\b
  # re-bake an existing crack network (cracks.json) without solving
  crackbake examples/spot.obj --cracks spot_cracks/cracks.json --res 8192
\b
  # a mesh without UVs: unwrap it with xatlas (cached), write EXR + GLB only
  crackbake statue.ply --cracks cracks.json --uv unwrap --formats exr,glb -o out/
\b
  # scripted batch use: quiet, machine-readable summary on stdout
  crackbake wall.glb --cracks wall_cracks.json --quiet --json > run.json
\b
\b
  # Unreal texture set (DirectX normals, packed ORM); describe the EXR master
  crackbake examples/spot.obj --preset mud --target unreal -o mud_ue/
  crackbake inspect mud_ue/spot_cracks.exr --png mud_ue/inspect/
\b
  # a decal library: 16 glass impacts in mip-safe atlases (crackbake decals --help)
  crackbake decals --preset glass -n 16 --size 0.5 --res 1024 -o lib/
\b
  # a seamlessly tiling mud texture set (crackbake tile --help)
  crackbake tile --preset mud --size 2 --res 2048 -o mud_tile/
\b
  # the Blender 4.2+ extension: click impacts, bake into the material (docs/blender.md)
  crackbake blender-addon -o dist/
\b
Outputs (in ./<mesh-stem>_cracks/ unless -o): <stem>_cracks.exr (crack.<map>.V layers: mask,
width, time, depth, distance, id, occlusion; crack.normal.NX/NY/NZ), <stem>_stress.exr, the
--target PNGs (gltf: basecolor, normal, orm, data, mask, depth), <stem>.glb, preview.png,
cracks.json, cracks.obj, manifest.json.  Full reference: README.md.
"""


def _spacing_defaults() -> str:
    """``--spacing``'s default and the presets' own: ``0.1; crackle 0.025``."""
    own = [f"{n} {load_preset(n)['spacing']}" for n in preset_names()
           if "spacing" in load_preset(n)]
    return "; ".join([f"{SPACING_DEFAULT}", *own])


class _LateHelp(click.Option):
    """An option whose help is ``late_help()``, made when first read (the help page, the
    add-on's tooltips): ``--spacing``'s reads every preset's TOML, a third of this module's
    import time, which a run does not need (issue 25)."""

    def __init__(self, *args, late_help, **kwargs):
        super().__init__(*args, **kwargs)
        self._late = late_help

    @property
    def help(self) -> str | None:
        if callable(self._late):
            self._late = self._late()
        return self._late

    @help.setter
    def help(self, value: str | None) -> None:
        self._late = value


def _parse_curvature(text: str | None) -> tuple[float | None, float | None]:
    if text is None:
        return None, None
    try:
        parts = [float(p) for p in text.split(":")]
    except ValueError:
        parts = []
    if not 1 <= len(parts) <= 2:
        raise CrackbakeError(f"--curvature '{text}': expected BIAS[:DENSITY], e.g. 1:0.5")
    return parts[0], parts[1] if len(parts) > 1 else None


def _split_formats(_ctx, _param, value: str) -> tuple[str, ...]:
    items = tuple(v.strip().lower() for v in value.split(",") if v.strip())
    bad = [v for v in items if v not in FORMATS]
    if bad or not items:
        raise click.BadParameter(f"use a comma-separated subset of {','.join(FORMATS)}")
    return items


@click.command(
    "bake",
    cls=Command,
    epilog=EPILOG,
    context_settings=CONTEXT,
)
@click.argument("mesh", type=click.Path(path_type=Path))
@click.option(
    "--impact",
    "impacts",
    multiple=True,
    metavar="X,Y,Z[:R[:S]]",
    help="Impact point, optional radius (mesh units, or a fraction of the bounding-box diagonal "
    "with a d suffix: 0.2d) and strength; X,Y,Z[:R]:speed=V instead gives the impact speed in "
    "m/s, and the star's radial crack count follows the measured law (--thickness, "
    "--material). Repeatable.",
)
@click.option(
    "--cracks",
    type=click.Path(path_type=Path),
    help="Bake this crack network (a cracks.json sidecar) instead of solving.",
)
@click.option(
    "--preset",
    type=click.Choice(preset_names()),
    help="Material preset setting coherent solver and stress defaults (options given "
    "explicitly win).",
)
@click.option(
    "--method",
    type=click.Choice(METHODS),
    help="iben: Iben & O'Brien (cracks cut through triangles) [default]; thesis: MSc variant "
    "(cracks grown to their end along mesh edges).",
)
@click.option("--detail", type=float, help="Simulation mesh edge length, mesh units.")
@click.option("--sim-faces", type=int, help=f"Simulation mesh size in faces [{SIM_FACES_DEFAULT}].")
@click.option(
    "--sim-proxy",
    type=click.Choice(SIM_PROXY_MODES),
    default=SIM_PROXY_DEFAULT,
    show_default=True,
    help="Simulate on a decimated stand-in of the asset: auto when the asset has over twice "
    "--sim-faces (and over 200k faces); always; never (refine the asset's own faces).",
)
@click.option("--shrink", type=float, help="Uniform shrinkage tension (crackle, glaze, mud).")
@click.option("--shrink-rate", type=float, help="Shrinkage added per solver step (relative).")
@click.option(
    "--direction",
    "directions",
    multiple=True,
    metavar="X,Y,Z[:S]",
    help="Directional tension (parallel cracks across it). Repeatable.",
)
@click.option(
    "--curvature",
    metavar="BIAS[:DENSITY]",
    help="Curvature terms: cracks along the least-curved direction; more where curved.",
)
@click.option(
    "--weight-map",
    type=click.Path(path_type=Path),
    help="Grayscale image multiplying the stress through the mesh UVs (logos, masks).",
)
@click.option(
    "--weight-attribute",
    help="Vertex attribute (PLY/GLB) multiplying the stress; 'color' for vertex colours.",
)
@click.option("--invert-weights", is_flag=True, help="Use 1 - weight.")
@click.option("--noise", type=float, help="Seeded random perturbation of the field (0.1 = 10%).")
@click.option(
    "--thickness",
    type=float,
    help="Plate thickness in mm for impacts given a speed (the crack count grows as its cube "
    f"root) [{THICKNESS_DEFAULT:g}].",
)
@click.option(
    "--material",
    type=click.Choice(tuple(MATERIALS)),
    help="Plate material for impacts given a speed: glass (annealed) or plexiglas "
    f"[{MATERIAL_DEFAULT}].",
)
@click.option("--hoop", type=float, help=f"Impact hoop/radial tension ratio [{D['hoop']}].")
@click.option(
    "--spacing",
    type=float,
    cls=_LateHelp,
    late_help=lambda: "Crack spacing: each crack's stress-shadow radius as a fraction of the "
    f"bounding-box diagonal; smaller gives smaller cells [{_spacing_defaults()}].",
)
@click.option(
    "--cycles",
    type=int,
    default=1,
    show_default=True,
    help="Wetting and drying cycles of a shrinkage network (mud, crackle, concrete): each new "
    "drying re-cracks along the old cracks and the junctions drift from T (90 degrees) toward Y "
    "(120), over about 4 cycles.",
)
@click.option(
    "--toughness", type=float, help=f"Failure threshold relative to the field [{D['toughness']}]."
)
@click.option(
    "--tip-factor",
    type=float,
    help=f"Share of excess stress pushed to crack tips (0..1) [{D['tip_factor']}].",
)
@click.option("--relax-steps", type=int, help=f"Relaxation passes per crack [{D['relax_steps']}].")
@click.option("--relax-rate", type=float, help=f"iben relaxation strength [{D['relax_rate']}].")
@click.option(
    "--relax-share",
    type=float,
    help=f"thesis: share passed to neighbours per pass [{D['relax_share']}].",
)
@click.option("--max-cracks", type=int, help=f"Stop after this many cracks [{D['max_cracks']}].")
@click.option(
    "--max-steps", type=int, help=f"Stop after this many solver steps [{D['max_steps']}]."
)
@click.option("--max-crack-length", type=float, help="Longest single crack, mesh units.")
@click.option(
    "--crack-width",
    type=float,
    help=f"Widest crack opening, mesh units [{CRACK_WIDTH_REL_DEFAULT:.1%} of diagonal].",
)
@click.option("--depth-ratio", type=float, help=f"Crack depth / width [{D['depth_ratio']}].")
@click.option(
    "--res",
    type=int,
    default=RES_DEFAULT,
    show_default=True,
    help=f"Texture size in texels ({RES_MIN}..{RES_MAX}).",
)
@click.option(
    "-o", "--out", type=click.Path(path_type=Path), help="Output folder [./<mesh-stem>_cracks/]."
)
@click.option(
    "--uv",
    type=click.Choice(UV_MODES),
    default=UV_DEFAULT,
    show_default=True,
    help="auto: keep usable UVs, else unwrap with xatlas.",
)
@click.option(
    "--padding",
    type=int,
    help=f"xatlas chart gutter in texels [about res/{PADDING_RES_PER_TEXEL}, at least "
    f"{PADDING_MIN}].",
)
@click.option(
    "--dilate",
    type=int,
    help="Limit the gutter fill to this many texels [fill every empty texel].",
)
@click.option(
    "--max-distance",
    type=float,
    help=f"Clamp of crack.distance in mesh units [{DEFAULT_MAX_DISTANCE_FRACTION:.0%} of the "
    "bounding-box diagonal].",
)
@click.option(
    "--profile",
    type=float,
    default=PROFILE_DEFAULT,
    show_default=True,
    help="Crack depth profile exponent: 1 = V, 0.5 = rounded U, 2 = sharp slot.",
)
@click.option(
    "--min-px",
    type=float,
    default=MIN_PX_DEFAULT,
    show_default=True,
    help="Least drawn crack width in texels (mask, depth, normal); crack.width keeps the "
    "physical width. 0 = physical only.",
)
@click.option(
    "--look",
    "look",
    multiple=True,
    metavar="KEY=VALUE",
    help="Override one key of the preset's look (repeatable): color=R,G,B (sRGB 0..255), "
    "mode=darken|lighten|multiply, roughness, normal_strength, width_variation, chipping, curl "
    "(docs/maps.md, Crack looks).",
)
@click.option("--seed", type=int, default=SEED_DEFAULT, show_default=True, help="Random seed.")
@click.option(
    "--formats",
    default=",".join(FORMATS_DEFAULT),
    show_default=True,
    callback=_split_formats,
    help="Which outputs to write (cracks.json, cracks.obj and manifest.json always are); "
    "also usd (<stem>.usda with its material) and usdz (AR Quick Look); both need the usd "
    "extra.",
)
@click.option(
    "--decal",
    type=float,
    metavar="SIZE",
    help="Also bake a projected decal per --impact, SIZE mesh units wide (decals.json).",
)
@click.option(
    "--decal-res",
    type=int,
    help=f"Decal texture size in texels [min(--res, {DECAL_RES_DEFAULT})].",
)
@click.option(
    "--stress-res",
    type=int,
    help=f"Stress map size in texels [min(--res, {STRESS_RES_DEFAULT})].",
)
@click.option(
    "--frames",
    type=int,
    metavar="N",
    help="Also write N PNG frames of the cracks growing (<stem>_growth_0000.png ...), N >= 2.",
)
@click.option(
    "--target",
    type=click.Choice(TARGETS),
    default=TARGET_DEFAULT,
    show_default=True,
    help="Engine profile: PNG names, packed maps, normal convention, bit depths.",
)
@click.option(
    "--normal-y",
    type=click.Choice(NORMAL_Y),
    help="Normal-map Y convention: gl (+Y, OpenGL) or dx (-Y, DirectX) [the target's].",
)
@click.option(
    "--up",
    type=click.Choice(UP_AXES),
    help="The preview's up axis [y, or z when the mesh clearly stands on its -Z side].",
)
@click.option("--float", "float32", is_flag=True, help="Write every EXR channel as 32-bit float.")
@click.option(
    "--exr-compression",
    type=click.Choice(EXR_COMPRESSIONS),
    default=EXR_COMPRESSION_DEFAULT,
    show_default=True,
    help="Lossless compression of the EXR files: zip (scanline blocks of 16), zips (one line), "
    "piz (wavelet, best on noisy data), none.",
)
@click.option("--object", "object_name", help="Pick this object from a multi-object file.")
@click.option(
    "--allow-outside-textures",
    is_flag=True,
    help="Read the material files, textures and glTF buffers the mesh names even outside its "
    "folder (refused by default).",
)
@click.option(
    "--unwrap-timeout",
    type=float,
    default=UNWRAP_TIMEOUT_DEFAULT,
    show_default=True,
    help="Seconds xatlas may run before giving up.",
)
@click.option(
    "--max-memory",
    type=float,
    metavar="GIB",
    help="Memory the run may use, GiB, in place of the detected limit (cgroup, ulimit -v or "
    "physical memory) its estimated peak is checked against before the heavy stages.",
)
@click.option("--no-cache", is_flag=True, help="Do not read or write the unwrap and mesh caches.")
@click.option("-q", "--quiet", is_flag=True, help="Print nothing but errors.")
@click.option("-v", "--verbose", is_flag=True, help="Print stage timings and details.")
@click.option("--json", "as_json", is_flag=True, help="Print a machine-readable summary on stdout.")
@click.option(
    "--progress",
    type=click.Choice(["jsonl"]),
    help="Write the run's progress to stdout as one JSON object a line (stage, fraction, "
    "warnings, then the summary or the error; docs/progress.md), for GUIs and pipelines.",
)
@click.version_option(__version__, "-V", "--version", prog_name="crackbake")
def bake(mesh: Path, quiet: bool, verbose: bool, as_json: bool, progress: str | None,
         **options) -> None:
    """Grow cracks on MESH and bake them into textures (EXR, PNG, GLB)."""
    t0 = time.perf_counter()
    from crackbake.display import Display, display_mode
    from crackbake.transaction.interrupt import RunInterrupted

    recorded: list[str] = []
    stderr = sys.stderr
    display = Display(stderr, display_mode(stderr, quiet, verbose), t0)
    events = _progress(progress, as_json, t0)

    def show(message, category, *_args, **_kwargs) -> None:
        recorded.append(str(message))
        display.warn(str(message))
        events.warn(str(message))

    def fail(line: str, code: int, cancelled: bool = False) -> None:
        err(line)
        events.error(line.removeprefix("error: "), code, cancelled)
        sys.exit(code)

    try:
        # Checked before the pipeline's heavy imports (GL, numba): a typo fails in 0.2 s.
        params = run_params(mesh, options).validate()
        from crackbake.pipeline import run

        with warnings.catch_warnings(), display, events:
            warnings.simplefilter("always", CrackbakeWarning)
            warnings.showwarning = show
            result = run(params)
    except CrackbakeError as exc:
        fail(f"error: {exc}", exc.exit_code, cancelled=isinstance(exc, RunInterrupted))
    except KeyboardInterrupt:
        fail("interrupted; no outputs were written", 130, cancelled=True)
    except MemoryError:  # past the estimate (--max-memory above the real limit, a busy machine)
        fail("error: ran out of memory; no outputs were written. Lower --res, --stress-res or "
             "--sim-faces, or free memory (crackbake.memory estimates a run's peak)", 2)
    except Exception as exc:  # a bug: say so, keep the traceback behind --verbose
        if verbose:
            raise
        text = " ".join(str(exc).split())[:200]
        fail(f"internal error: {type(exc).__name__}: {text} (rerun with --verbose for details)",
             1)

    result.warnings = recorded
    # The output set is committed: a Ctrl-C now could only cut the summary short, or land in
    # the interpreter's shutdown as "Exception ignored ... KeyboardInterrupt".
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        events.done(result.summary())
        if as_json:
            import json

            click.echo(json.dumps(result.summary(), indent=2))
            sys.stdout.flush()
        if not quiet:
            _report(result, verbose)
    except OSError as exc:  # a full disk or closed pipe behind stdout/stderr
        silence(sys.stdout)
        what = "--json summary to stdout" if as_json else "summary"
        err(f"error: cannot write the {what} ({exc.strerror or exc}); the outputs are "
             f"complete in {result.out_dir}/")
        sys.exit(2)


class _NoProgress:
    """Stands in for :class:`crackbake.progress.JsonlProgress` without ``--progress``."""

    def __getattr__(self, _name):
        return lambda *_a, **_k: None

    def __enter__(self):
        return self

    def __exit__(self, *_exc) -> None:
        pass


def _progress(mode: str | None, as_json: bool, t0: float):
    """The ``--progress`` writer on stdout (its ``start`` event written), or a no-op one."""
    if mode is None:
        return _NoProgress()
    if as_json:
        raise click.UsageError("--progress jsonl and --json both write to stdout: use one (the "
                               "progress stream ends with the summary)")
    from crackbake.progress import JsonlProgress

    events = JsonlProgress(sys.stdout, t0)
    events.start(__version__)
    return events


def run_params(mesh: Path, o: dict) -> RunParams:
    """:class:`RunParams` from the parsed options (``o`` holds :func:`bake`'s keyword
    arguments)."""
    bias, density = _parse_curvature(o.pop("curvature"))
    impacts = tuple(parse_impact(t) for t in o.pop("impacts"))
    directions = tuple(parse_direction(d) for d in o.pop("directions"))
    from crackbake.looks import parse_look  # numpy: not loaded for --help and --version
    from crackbake.params import RunParams

    look = parse_look(o.pop("look"))
    return RunParams(
        look=look,
        mesh=mesh,
        impacts=impacts,
        directions=directions,
        curvature_bias=bias,
        curvature_density=density,
        cache=not o.pop("no_cache"),
        weight_invert=o.pop("invert_weights"),
        **o,
    )


def _report(result, verbose: bool) -> None:
    """The closing summary on stderr: mesh, UVs, cracks, (timings,) files written."""
    m = result.manifest
    lo, hi = m["mesh"]["bbox_min"], m["mesh"]["bbox_max"]
    bbox = " x ".join(f"{b - a:.4g}" for a, b in zip(lo, hi, strict=True))
    uv_found = "found" if m["mesh"]["has_uv"] else "none in the file"
    udim = m["uv"].get("udim")
    tiles = f" on {len(udim['tiles'])} UDIM tiles" if udim else ""
    err(
        f"mesh: {m['mesh']['vertices']} vertices, {m['mesh']['faces']} faces, "
        f"bbox {bbox}; UVs {uv_found}, {m['uv']['method']}{tiles}, "
        f"{m['uv']['coverage']:.0%} of the texture used; "
        f"cracks: {m['cracks']['cracks']} ({m['cracks']['points']} points)"
    )
    if verbose:
        for stage, secs in m["timings_s"].items():
            err(f"  {stage:<8} {secs:8.3f} s")
    err(f"wrote {len(result.files) + 1} files to {result.out_dir}/")
    for f in result.files:
        err(f"  {f['name']:<28} {f['bytes'] / 1e6:8.2f} MB")
    manifest = Path(result.out_dir) / "manifest.json"
    if manifest.is_file():
        err(f"  {'manifest.json':<28} {manifest.stat().st_size / 1e6:8.2f} MB")

