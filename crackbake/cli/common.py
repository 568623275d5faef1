"""What the crackbake commands share: one-line usage errors, stderr lines, a run's warnings and
errors reported the same way."""

from __future__ import annotations

import os
import sys
import warnings
from collections.abc import Callable
from typing import TypeVar

import click

from crackbake.errors import CrackbakeError, CrackbakeWarning

#: click settings of the commands: ``-h`` as well as ``--help``, help text up to 100 columns.
CONTEXT = {"help_option_names": ["-h", "--help"], "max_content_width": 100}

T = TypeVar("T")


class Command(click.Command):
    """A click command whose usage errors are one line in crackbake's own style.

    click prints three (usage, hint, ``Error: ...``); scripts and people both read one line
    better: ``error: <what is wrong>; run crackbake --help``, exit code 2.
    """

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True, **extra):
        if not standalone_mode:
            return super().main(args, prog_name, complete_var, standalone_mode, **extra)
        try:
            rv = super().main(args, prog_name, complete_var, False, **extra)
        except click.ClickException as exc:
            err(f"error: {usage_line(exc)}; run crackbake --help")
            sys.exit(exc.exit_code)
        except click.exceptions.Abort:
            err("interrupted")
            sys.exit(130)
        sys.exit(rv if isinstance(rv, int) else 0)


def usage_line(exc: click.ClickException) -> str:
    """click's message on one line, lower-case start and no closing full stop."""
    text = " ".join(exc.format_message().split()).replace(". (", " (").rstrip(".")
    if len(text) > 1 and text[0].isupper() and text[1].islower():
        text = text[0].lower() + text[1:]
    return text


def silence(stream) -> None:
    """Point ``stream``'s file descriptor at /dev/null, so the interpreter's final flush of
    what could not be written raises nothing more (the Python docs' recipe for SIGPIPE)."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, stream.fileno())
        os.close(devnull)
    except (OSError, ValueError, AttributeError):  # not a real file (tests capture streams)
        pass


def err(msg: str) -> None:
    """One line on stderr (a full or closed stderr is silenced: the exit code still says it)."""
    try:
        click.echo(msg, err=True)
    except OSError:
        silence(sys.stderr)


def reported(run: Callable[[], T], quiet: bool) -> T:
    """``run()`` as the subcommands report it: each CrackbakeWarning one ``warning:`` line
    (none with ``quiet``), a CrackbakeError one ``error:`` line and its exit code."""

    def show(message, *_args, **_kwargs) -> None:
        if not quiet:
            err(f"warning: {message}")

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("always", CrackbakeWarning)
            warnings.showwarning = show
            return run()
    except CrackbakeError as exc:
        err(f"error: {exc}")
        sys.exit(exc.exit_code)
