"""The command line's progress display: log records of the ``crackbake`` loggers on stderr.

Four modes, picked by :func:`display_mode`:

``live``
    stderr is a terminal: one status line per stage, redrawn in place (``\\r``) with the stage's
    newest detail (solver steps, bake passes, files) and its running time, then kept as
    ``<stage>[: <detail>], done in 1.2 s`` when the next stage starts.
``verbose``
    ``-v``: every record as its own line with the time since start, terminal or not.
``plain``
    stderr is a file or a pipe: no progress at all (scripts read the summary or ``--json``);
    warnings and the closing summary still show.
``quiet``
    ``-q``: nothing but the error line.

Records of the ``crackbake.pipeline`` logger start a stage, except those starting with a number
(a stage's result, such as "12 cracks started, ..."); those and the records of every other
``crackbake.*`` logger are details of the running stage.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import TextIO

STAGE_LOGGER = "crackbake.pipeline"
#: Seconds between redraws of the live line (the running time ticks even when no record comes).
TICK_SECONDS = 0.2
_CLEAR = "\r\x1b[K"  # carriage return, erase to the end of the line


def display_mode(stream: TextIO, quiet: bool, verbose: bool) -> str:
    """``quiet``, ``verbose``, ``live`` (``stream`` is a terminal) or ``plain``."""
    if quiet:
        return "quiet"
    if verbose:
        return "verbose"
    try:
        tty = stream.isatty()
    except (AttributeError, ValueError):  # closed or not a real stream
        tty = False
    return "live" if tty else "plain"


class Display(logging.Handler):
    """Shows log records and warnings on ``stream`` in one of the :func:`display_mode` modes.

    Use as a context manager around the run: it attaches itself to the ``crackbake`` logger and
    finishes the live line (and its ticker thread) on the way out.
    """

    def __init__(self, stream: TextIO, mode: str, t0: float | None = None) -> None:
        super().__init__(logging.INFO)
        self.stream = stream
        self.mode = mode
        self.t0 = time.perf_counter() if t0 is None else t0
        self._lock = threading.RLock()
        self._stage: str | None = None
        self._detail = ""
        self._stage_t0 = self.t0
        self._stop = threading.Event()
        self._ticker: threading.Thread | None = None
        self._saved: tuple[int, bool] | None = None

    # --- logging.Handler ----------------------------------------------------------------------

    def emit(self, record: logging.LogRecord) -> None:
        try:
            message = record.getMessage()
            if self.mode == "verbose":
                self._write(f"[{time.perf_counter() - self.t0:6.1f}s] {message}\n")
            elif self.mode == "live":
                if record.name == STAGE_LOGGER and not message[:1].isdigit():
                    self._start_stage(message)
                else:
                    with self._lock:
                        self._detail = message
                        self._draw()
        except Exception:  # the display must never break the run
            self.handleError(record)

    # --- what the CLI calls -------------------------------------------------------------------

    def warn(self, message: str) -> None:
        """A warning line (kept above the live line), unless quiet."""
        if self.mode == "quiet":
            return
        with self._lock:
            if self.mode == "live" and self._stage is not None:
                self._write(_CLEAR)
            self._write(f"warning: {message}\n")
            self._draw()

    def __enter__(self) -> Display:
        root = logging.getLogger("crackbake")
        self._saved = (root.level, root.propagate)
        root.addHandler(self)
        root.setLevel(logging.INFO)
        root.propagate = False  # the CLI owns the display: no second copy via the root logger
        if self.mode == "live":
            self._ticker = threading.Thread(target=self._tick, name="crackbake-display",
                                            daemon=True)
            self._ticker.start()
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self._stop.set()
        if self._ticker is not None:
            self._ticker.join()
        with self._lock:
            if self.mode == "live" and self._stage is not None:
                # A failed stage is cleared (the error line says what happened).
                self._finish_stage(done=exc_type is None)
        root = logging.getLogger("crackbake")
        root.removeHandler(self)
        if self._saved is not None:
            root.setLevel(self._saved[0])
            root.propagate = self._saved[1]

    # --- live line ----------------------------------------------------------------------------

    def _start_stage(self, message: str) -> None:
        with self._lock:
            if self._stage is not None:
                self._finish_stage(done=True)
            self._stage, self._detail = message, ""
            self._stage_t0 = time.perf_counter()
            self._draw()

    def _finish_stage(self, done: bool) -> None:
        secs = time.perf_counter() - self._stage_t0
        detail = f": {self._detail}" if self._detail else ""
        self._write(f"{_CLEAR}{self._stage}{detail}, done in {secs:.1f} s\n" if done else _CLEAR)
        self._stage, self._detail = None, ""

    def _draw(self) -> None:
        if self.mode != "live" or self._stage is None:
            return
        secs = time.perf_counter() - self._stage_t0
        detail = f": {self._detail}" if self._detail else ""
        line = f"{self._stage}{detail} ({secs:.1f} s)"
        # One row only: a wrapped line would leave its first rows behind on every redraw.
        import shutil  # only for a terminal's live line: 4 ms of start-up otherwise

        width = shutil.get_terminal_size((100, 24)).columns - 1
        if len(line) > width:
            line = line[: max(width - 3, 0)] + "..."
        self._write(_CLEAR + line)

    def _tick(self) -> None:
        while not self._stop.wait(TICK_SECONDS):
            with self._lock:
                self._draw()

    def _write(self, text: str) -> None:
        self.stream.write(text)
        self.stream.flush()
