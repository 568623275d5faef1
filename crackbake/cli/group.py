"""``crackbake``: a command group whose default command is the bake.

``crackbake MESH [OPTIONS]`` bakes (:mod:`crackbake.cli.bake`); a first argument that is a
command's name runs that command instead: ``crackbake inspect FILE.exr``, ``crackbake decals``,
``crackbake tile``, ``crackbake batch JOBS``, ``crackbake blender-addon``.  The name wins over
a file of the same name in the working folder: a mesh file named ``tile`` (or ``inspect``,
``decals``, ``batch``) is baked when given as a path, ``crackbake ./tile``.
``crackbake --help`` and ``--version`` are the bake's.

The commands are imported when they run, so ``crackbake MESH`` loads none of them (and a bad
option fails before any heavy import), and ``crackbake inspect`` does not load the bake's
options (their presets, their defaults: about 0.1 s, issue 25).
"""

from __future__ import annotations

import importlib
import sys

import click

#: Command name -> ``module:attribute`` of its click command.
COMMANDS = {
    "inspect": "crackbake.cli.inspect:inspect",
    "decals": "crackbake.decals.command:decals",
    "tile": "crackbake.tile.command:tile",
    "batch": "crackbake.batch.command:batch",
    "blender-addon": "crackbake.blender.build:blender_addon",
}


def _load(target: str) -> click.Command:
    module, attr = target.split(":")
    return getattr(importlib.import_module(module), attr)


class DefaultGroup(click.Group):
    """A click group that runs ``default`` unless the first argument names one of ``commands``
    (each, and ``default``, given as ``"module:attribute"``, imported on first use).

    Each command parses its own arguments and prints its own help and one-line errors; the
    group only routes, so ``crackbake MESH ...`` behaves exactly as the bake command alone.
    """

    def __init__(self, name: str, default: str, commands: dict[str, str], **attrs):
        super().__init__(name, **attrs)
        self.default_target = default
        self.lazy = dict(commands)

    @property
    def default(self) -> click.Command:
        """The default command (the bake), imported on first use."""
        return _load(self.default_target)

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(self.lazy)

    def get_command(self, ctx: click.Context | None, cmd_name: str) -> click.Command | None:
        return _load(self.lazy[cmd_name]) if cmd_name in self.lazy else None

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True, **extra):
        argv = sys.argv[1:] if args is None else list(args)
        command = self.get_command(None, argv[0]) if argv else None
        if command is not None:
            name = f"{prog_name or 'crackbake'} {argv[0]}"
            return command.main(argv[1:], name, complete_var, standalone_mode, **extra)
        return self.default.main(args, prog_name, complete_var, standalone_mode, **extra)


main = DefaultGroup("crackbake", default="crackbake.cli.bake:bake", commands=COMMANDS)
