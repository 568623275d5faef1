"""``crackbake inspect FILE.exr``: the channel table, ``--json`` for scripts, ``--png`` pictures."""

from __future__ import annotations

import json
import sys
from dataclasses import replace
from pathlib import Path

import click

from crackbake.cli.common import Command, err, reported
from crackbake.errors import CrackbakeError


@click.command(cls=Command, context_settings={"help_option_names": ["-h", "--help"]})
@click.argument("exr", type=click.Path(dir_okay=False, path_type=Path))
@click.option(
    "--png",
    "png_dir",
    type=click.Path(file_okay=False, path_type=Path),
    help="Write false-colour pictures of every layer into this folder.",
)
@click.option("--json", "as_json", is_flag=True, help="Print the table as JSON on stdout.")
def inspect(exr: Path, png_dir: Path | None, as_json: bool) -> None:
    """Describe the channels of EXR: layer, channel, type, min/max/mean, non-zero, units.

    A UDIM set reads as one: name.<UDIM>.exr (quote it in a shell) gives one row per channel
    over every tile and, with --png, the pictures of each tile (prefixed with its number).
    """
    try:  # warnings as one line each, a CrackbakeError as one line and its exit code
        info, files = reported(lambda: _inspect(exr, png_dir), quiet=False)
    except Exception as exc:  # a bug: one line, like the bake command
        text = " ".join(str(exc).split())[:200]
        err(f"internal error: {type(exc).__name__}: {text}")
        sys.exit(1)
    from crackbake.exchange.inspect import format_table

    click.echo(info.to_json() if as_json else format_table(info))
    if files and not as_json:
        click.echo(f"{len(files)} pictures in {png_dir}")


def _inspect(exr: Path, png_dir: Path | None):
    """The inspection of ``exr`` and the pictures written into ``png_dir`` (final paths).

    ``png_dir`` is written like a bake's output folder (:class:`OutputStage`): the pictures and
    a ``manifest.json`` appear at once, a folder of the user's own files is refused, symlinks
    are never written through, and an interrupt leaves the folder as it was.
    """
    from crackbake.exchange.inspect import UDIM_TOKEN, inspect_exr, inspect_udim, write_pictures

    if UDIM_TOKEN in exr.name:
        info, per_tile = inspect_udim(exr, pixels=png_dir is not None)
    else:
        if not exr.exists():  # a FIFO or device exists: inspect_exr names what it is
            raise CrackbakeError(
                f"EXR '{exr}' does not exist; check the path (a UDIM set is name.<UDIM>.exr)"
            )
        info, channels = inspect_exr(exr, pixels=png_dir is not None)
        per_tile = None
    if png_dir is None:
        return info, []
    from crackbake import __version__
    from crackbake.transaction.interrupt import run_staged
    from crackbake.transaction.stage import OutputStage

    def body() -> list[Path]:
        if per_tile is None:
            written = write_pictures(info, channels, stage.staging_dir)
        else:
            written = []
            for number, chans in per_tile.items():
                tile_info = replace(info, path=str(exr).replace("<UDIM>", str(number)))
                written += write_pictures(tile_info, chans, stage.staging_dir, prefix=f"{number}_")
        manifest = {
            "crackbake": __version__,
            "kind": "inspect",
            "source": str(exr),
            "files": stage.records(),
        }
        text = json.dumps(manifest, indent=2) + "\n"
        try:
            stage.path("manifest.json").write_text(text, encoding="utf-8")
        except OSError as exc:
            raise CrackbakeError(
                f"cannot write '{png_dir}': {exc.strerror or exc}; check that the folder is "
                "writable and has space"
            ) from exc
        stage.commit()
        return [stage.final / p.name for p in written]

    stage = OutputStage(png_dir, option="--png")
    return info, run_staged(stage, body)
