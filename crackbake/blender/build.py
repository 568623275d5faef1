"""``crackbake blender-addon -o DIR``: the Blender extension as an installable zip.

The zip holds one folder, ``crackbake_blender/``: ``addon/``'s sources (``__init__.py``'s
``bl_info`` with crackbake's version), its ``blender_manifest.toml`` with the same version, and
a generated ``defaults.py``: the command that runs this environment's crackbake (pre-filled in
the extension's preferences), the preset and method names, and the bake options' help texts
(the panel's tooltips say what ``crackbake --help`` says).
"""

from __future__ import annotations

import os
import shlex
import sys
import zipfile
from pathlib import Path

import click

from crackbake import __version__
from crackbake.cli.common import CONTEXT, Command, reported
from crackbake.errors import CrackbakeError

ADDON = Path(__file__).resolve().parent / "addon"
MANIFEST = "blender_manifest.toml"
#: The zip's one folder: an extension's files may sit in one (Blender 4.2+), a legacy add-on's
#: must (older Blenders unpack the zip into their add-ons folder; this is its module name).
FOLDER = "crackbake_blender"
_BL_VERSION = '"version": (0, 0, 0),'
#: The bake options whose help the extension shows (click parameter names).
HELP_OPTIONS = ("preset", "method", "seed", "res", "min_px", "impacts", "weight_attribute",
                "shrink", "noise", "spacing", "sim_faces", "directions", "curvature",
                "invert_weights")


def zip_name(version: str = __version__) -> str:
    return f"crackbake_blender-{version}.zip"


def version_tuple(version: str = __version__) -> tuple[int, int, int]:
    """``bl_info``'s version: the leading number of each of the first three parts ("0.1.0rc1"
    -> (0, 1, 0))."""
    parts = []
    for part in version.split(".")[:3]:
        digits = ""
        for ch in part:
            if not ch.isdigit():
                break
            digits += ch
        parts.append(int(digits or 0))
    return tuple(parts + [0] * (3 - len(parts)))


def init_source() -> str:
    """``addon/__init__.py`` with crackbake's version in its ``bl_info``."""
    text = (ADDON / "__init__.py").read_text(encoding="utf-8")
    if _BL_VERSION not in text:
        raise RuntimeError(f"{ADDON / '__init__.py'}: bl_info has no {_BL_VERSION} to fill in")
    return text.replace(_BL_VERSION, f'"version": {version_tuple()!r},')


def default_command() -> str:
    """How this environment runs crackbake: ``<python> -m crackbake`` (the interpreter that
    built the zip, so the extension runs the same crackbake, whatever is on Blender's PATH)."""
    exe = sys.executable or "python3"
    quote = shlex.quote if os.name != "nt" else (lambda s: f'"{s}"' if " " in s else s)
    return f"{quote(exe)} -m crackbake"


def defaults_source(command: str) -> str:
    """The generated ``defaults.py``."""
    from crackbake.cli.bake import bake
    from crackbake.params import METHODS, preset_names

    helps = {p.name: " ".join((p.help or "").split()) for p in bake.params
             if isinstance(p, click.Option) and p.name in HELP_OPTIONS}
    return (
        '"""Written by crackbake blender-addon: the command that built this extension, the '
        'names\nand help texts of its options."""\n\n'
        f"VERSION = {__version__!r}\n"
        f"COMMAND = {command!r}\n"
        f"PRESETS = {tuple(preset_names())!r}\n"
        f"METHODS = {tuple(METHODS)!r}\n"
        f"HELP = {helps!r}\n"
    )


def build_extension(out_dir: str | Path, command: str | None = None) -> Path:
    """Write ``crackbake_blender-<version>.zip`` into ``out_dir`` (made if missing).

    Parameters
    ----------
    out_dir : str or Path
        Folder of the zip.
    command : str, optional
        The preferences' crackbake command [:func:`default_command`].

    Returns
    -------
    Path
        The zip.

    Raises
    ------
    CrackbakeError
        ``out_dir`` is a file or cannot be written.
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise CrackbakeError(f"-o {out}: not a folder; give a folder for the zip")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise CrackbakeError(f"-o {out}: cannot make the folder ({exc.strerror or exc})") from None
    target = out / zip_name()
    partial = target.with_name(target.name + ".partial")
    manifest = (ADDON / MANIFEST).read_text(encoding="utf-8").replace("@VERSION@", __version__)
    try:
        with zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as zf:
            entries = [(MANIFEST, manifest),
                       ("defaults.py", defaults_source(command or default_command()))]
            entries += [(p.name, init_source() if p.name == "__init__.py"
                         else p.read_text(encoding="utf-8"))
                        for p in sorted(ADDON.glob("*.py"))]
            for name, text in entries:
                # a fixed date: the same sources and command give the same bytes
                info = zipfile.ZipInfo(f"{FOLDER}/{name}", date_time=(2020, 1, 1, 0, 0, 0))
                info.compress_type, info.external_attr = zipfile.ZIP_DEFLATED, 0o644 << 16
                zf.writestr(info, text.encode("utf-8"))
        partial.replace(target)
    except OSError as exc:
        partial.unlink(missing_ok=True)
        raise CrackbakeError(f"cannot write {target} ({exc.strerror or exc})") from None
    return target


@click.command("blender-addon", cls=Command, context_settings=CONTEXT)
@click.option("-o", "--out", "out_dir", type=click.Path(path_type=Path), default=Path("."),
              show_default=True, help="Folder of the zip.")
@click.option("--command", "command", metavar="CMD",
              help="The crackbake command the extension runs [this environment's: "
              "'<python> -m crackbake'].")
def blender_addon(out_dir: Path, command: str | None) -> None:
    """Write the Blender extension (crackbake_blender-<version>.zip, Blender 4.2+): install it
    from Preferences > Get Extensions > Install from Disk, or with
    `blender --command extension install-file -r user_default -e ZIP`.  Older Blenders (3.4+)
    install the same zip as a legacy add-on: Preferences > Add-ons > Install."""
    path = reported(lambda: build_extension(out_dir, command), quiet=False)
    click.echo(str(path.resolve()))
