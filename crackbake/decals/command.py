"""``crackbake decals``: a decal library (N crack variants on a plate, packed into atlases)."""

from __future__ import annotations

import json
from pathlib import Path

import click

from crackbake.cli.common import CONTEXT, Command, err, reported
from crackbake.params import DECALS_DEFAULTS as DD
from crackbake.params import NORMAL_Y, preset_names

EPILOG = """\b
Examples:
  # 16 glass impacts, 0.5 units wide, 1024 texels each
  crackbake decals --preset glass -n 16 --size 0.5 --res 1024 -o lib/
\b
  # mud patches for Unreal (DirectX normals)
  crackbake decals --preset mud -n 9 --size 2 --normal-y dx -o mud_decals/
\b
  # 64 variants baked by the workers of a running Ray cluster
  crackbake decals --preset crackle -n 64 --address auto -o lib/
\b
Outputs: decals_alpha.png, decals_normal.png, decals_orm.png, decals_height.png (16 bit),
contact_sheet.png, decals.json (each variant's atlas rectangle as UV scale/bias), manifest.json.
"""


@click.command(
    cls=Command,
    epilog=EPILOG,
    context_settings=CONTEXT,
)
@click.option(
    "--preset",
    default=DD["preset"],
    show_default=True,
    help=f"Material preset ({', '.join(preset_names())}); glass gets one impact per variant.",
)
@click.option("-n", "n", type=int, default=DD["n"], show_default=True, help="Number of variants.")
@click.option(
    "--size",
    type=float,
    default=DD["size"],
    show_default=True,
    help="Decal width/height, mesh units.",
)
@click.option(
    "--res", type=int, default=DD["res"], show_default=True, help="Texels per side of one variant."
)
@click.option("--seed", type=int, default=DD["seed"], show_default=True, help="Library seed.")
@click.option(
    "--normal-y",
    type=click.Choice(NORMAL_Y),
    default=DD["normal_y"],
    show_default=True,
    help="Normal-map Y: gl (+Y, OpenGL: Unity, Godot, glTF) or dx (-Y, DirectX: Unreal).",
)
@click.option("--depth", type=float, help="Projector depth, mesh units [size / 4].")
@click.option("--sim-faces", type=int, help="Simulation mesh size per variant, in faces.")
@click.option(
    "-o", "--out", type=click.Path(path_type=Path), default=Path(DD["out"]), show_default=True,
    help="Output folder (replaced as a whole).",
)  # fmt: skip
@click.option("--address", help="Bake the variants on a running Ray cluster: auto, HOST:PORT "
              "or ray://HOST:PORT (pip install 'crackbake[batch]'; docs/batch.md) [this process].")
@click.option("-q", "--quiet", is_flag=True, help="Print nothing but errors.")
@click.option("--json", "as_json", is_flag=True, help="Print decals.json's content on stdout.")
def decals(quiet: bool, as_json: bool, address: str | None, **options) -> None:
    """Bake N crack decal variants on a flat plate into mip-safe atlases plus decals.json."""

    from crackbake.decals.library import LibraryParams, build_library
    from crackbake.jit import light_cache_loads

    params = reported(lambda: LibraryParams(**options).validate(), quiet)
    light_cache_loads()  # numba's kernels load without its compiler's set-up
    doc = reported(lambda: build_library(params, address), quiet)
    if as_json:
        click.echo(json.dumps(doc, indent=1))
    if not quiet:
        a = doc["atlas"]
        t = doc["timings_s"]
        err(
            f"{len(doc['decals'])} {doc['preset']} decals in a {a['width']}x{a['height']} atlas "
            f"({t['total']:.1f} s) -> {params.out}/"
        )
