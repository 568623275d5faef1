"""What a batch prints while it runs: one line per finished job on a pipe or a log, a live bar
(done / failed / running / ETA) on a terminal.

The bar is click's own ``progressbar`` (click is already a dependency of the command line; rich
and tqdm are not dependencies of crackbake or of Ray, and the bar needs nothing they add).
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import IO

import click

#: Clears the terminal line the bar is drawn on, so a finished job's line can replace it.
CLEAR_LINE = "\r\033[K"


class LineReport:
    """One line per finished job through ``echo`` (a pipe, a log file, ``--quiet``)."""

    def __init__(self, echo: Callable[[str], None] = print) -> None:
        self.echo = echo

    def start(self, total: int) -> None:
        """``total`` jobs are about to run."""

    def running(self, count: int) -> None:
        """``count`` jobs are in flight now."""

    def finished(self, record: dict, line: str) -> None:
        """A job ended (``record["status"]``); ``line`` says how, in one line."""
        self.echo(line)

    def close(self) -> None:
        """The batch ended (or was interrupted): leave the terminal clean."""


class BarReport(LineReport):
    """A live bar on a terminal: ``batch [####----]  5/12  42%  00:01:10  1 failed, 2 running``;
    the lines of failed jobs are printed above it as they end (``echo_all``: every job's)."""

    def __init__(self, file: IO[str] | None = None, echo_all: bool = False) -> None:
        self.file = file or sys.stderr
        super().__init__(self._above)
        self.echo_all = echo_all
        self.bar = None
        self.failed = 0
        self.in_flight = 0

    def _info(self, _item) -> str:
        parts = [f"{self.failed} failed"] if self.failed else []
        return ", ".join([*parts, f"{self.in_flight} running"])

    def _above(self, line: str) -> None:
        self.file.write(CLEAR_LINE + line + "\n")
        self.file.flush()

    def start(self, total: int) -> None:
        self.bar = click.progressbar(length=total, label="batch", file=self.file, show_pos=True,
                                     show_eta=True, item_show_func=self._info, width=24)
        self.bar.__enter__()

    def running(self, count: int) -> None:
        if count != self.in_flight:
            self.in_flight = count
            if self.bar is not None:
                self.bar.update(0, count)

    def finished(self, record: dict, line: str) -> None:
        if record.get("status") not in ("ok", "skipped"):
            self.failed += 1
            self._above(line)
        elif self.echo_all:
            self._above(line)
        if self.bar is not None:
            self.bar.update(1, record.get("name"))

    def close(self) -> None:
        if self.bar is not None:
            self.bar.__exit__(None, None, None)
            self.bar = None


def report_for(stream: IO[str], echo: Callable[[str], None], quiet: bool) -> LineReport:
    """A bar when ``stream`` is a terminal (and not ``quiet``), else finished-job lines."""
    isatty = getattr(stream, "isatty", None)
    if not quiet and isatty is not None and isatty():
        return BarReport(stream)
    return LineReport(echo)
