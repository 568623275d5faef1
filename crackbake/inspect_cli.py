"""``crackbake inspect FILE.exr``: the channel table, ``--json`` for scripts, ``--png`` pictures."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from crackbake.cli import _Command, _err
from crackbake.errors import CrackbakeError


@click.command(cls=_Command, context_settings={"help_option_names": ["-h", "--help"]})
@click.argument("exr", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option(
    "--png",
    "png_dir",
    type=click.Path(file_okay=False, path_type=Path),
    help="Write false-colour pictures of every layer into this folder.",
)
@click.option("--json", "as_json", is_flag=True, help="Print the table as JSON on stdout.")
def inspect(exr: Path, png_dir: Path | None, as_json: bool) -> None:
    """Describe the channels of EXR: layer, channel, type, min/max/mean, non-zero, units."""
    from crackbake.exchange.inspect import format_table, inspect_exr, write_pictures

    try:
        info, channels = inspect_exr(exr)
        files = write_pictures(info, channels, png_dir) if png_dir is not None else []
    except CrackbakeError as exc:
        _err(f"error: {exc}")
        sys.exit(exc.exit_code)
    click.echo(info.to_json() if as_json else format_table(info))
    if files and not as_json:
        click.echo(f"{len(files)} pictures in {png_dir}")
