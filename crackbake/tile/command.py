"""``crackbake tile``: a seamlessly tiling crack texture set (the solver on a periodic plate)."""

from __future__ import annotations

from pathlib import Path

import click

from crackbake.cli.common import CONTEXT, Command, err, reported
from crackbake.params import EXR_COMPRESSION_DEFAULT, EXR_COMPRESSIONS, METHODS, preset_names
from crackbake.params import TILE_DEFAULTS as TD

EPILOG = """\b
Examples:
  # a 2 x 2 unit mud tile, 2048 texels
  crackbake tile --preset mud --size 2 --res 2048 -o mud_tile/
\b
  # a glass tile with 4 impacts
  crackbake tile --preset glass --impacts 4 --size 1 -o glass_tile/
\b
Outputs: tile_basecolor.png, tile_normal.png, tile_orm.png, tile_data.png (16 bit),
tile_mask.png, tile_height.png (16 bit), tile_cracks.exr, tile_3x3.png, cracks.json (the
pieces and the period), manifest.json.
"""


@click.command(
    cls=Command,
    epilog=EPILOG,
    context_settings=CONTEXT,
)
@click.option("--preset", default=TD["preset"], show_default=True,
              help=f"Material preset ({', '.join(preset_names())}).")
@click.option("--size", type=float, default=TD["size"], show_default=True,
              help="Tile width/height (the period), mesh units.")
@click.option("--res", type=int, default=TD["res"], show_default=True, help="Texels per side.")
@click.option("--seed", type=int, default=TD["seed"], show_default=True, help="Random seed.")
@click.option("--impacts", type=int, help=f"Random impacts on the tile (glass) [{TD['impacts']}].")
@click.option("--sim-faces", type=int, help=f"Simulation mesh size, in faces [{TD['sim_faces']}].")
@click.option("--method", type=click.Choice(METHODS),
              help="Crack method (only iben runs on a periodic tile).")
@click.option("--exr-compression", type=click.Choice(EXR_COMPRESSIONS),
              default=EXR_COMPRESSION_DEFAULT, show_default=True,
              help="Lossless compression of tile_cracks.exr (as the bake's option).")
@click.option("-o", "--out", type=click.Path(path_type=Path), default=Path(TD["out"]),
              show_default=True, help="Output folder (replaced as a whole).")
@click.option("-q", "--quiet", is_flag=True, help="Print nothing but errors.")
def tile(quiet: bool, **options) -> None:
    """Grow cracks on a periodic plate and bake a texture set that tiles with no seam."""

    from crackbake.jit import light_cache_loads
    from crackbake.tile.periodic import TileParams, build_tile

    params = reported(lambda: TileParams(**options).validate(), quiet)
    light_cache_loads()  # numba's kernels load without its compiler's set-up
    manifest = reported(lambda: build_tile(params), quiet)
    if not quiet:
        s = manifest["solver"]
        err(f"{params.preset} tile {params.size:g} x {params.size:g}, {s.get('cracks', 0)} "
             f"cracks, {params.res}² ({manifest['timings_s']['total']:.1f} s) -> {params.out}/")
