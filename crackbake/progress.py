"""``--progress jsonl``: the run's progress as one JSON object a line, for GUIs and pipelines.

The human display (:mod:`crackbake.display`) draws for a person on stderr; this one writes
events a program reads on **stdout**, flushed after each line, while stderr keeps its usual
lines (warnings, the one-line error, the closing summary).  Every event has ``event`` (its kind)
and ``t`` (seconds since the command started); the kinds, in the order a run gives them:

``start``
    ``{"event": "start", "version": "0.9.0", "fraction": 0.0}``
``stage``
    a stage begins: ``stage`` (an id of :data:`STAGES`), ``message`` (the human line, such as
    ``"baking 2048x2048"``), ``fraction``.
``detail``
    news from the running stage (solver events, unwrap progress): ``stage``, ``message``,
    ``fraction`` (the stage's start value: no stage knows its own share done).
``warning``
    ``message``: a CrackbakeWarning, as the ``warning:`` line on stderr says it.
``done``
    the last line of a run that wrote its outputs: ``fraction`` 1.0, ``summary`` (what ``--json``
    prints: ``out_dir``, ``files``, ``mesh``, ``uv``, ``cracks``, ``timings_s``, ``warnings``).
``error``
    the last line of a failed run: ``message`` (the stderr error line without ``error:``),
    ``exit_code``, and ``cancelled`` (true when SIGINT or SIGTERM stopped it; the output folder
    is then unchanged).

``fraction`` estimates the share of the run done, from the stage that is running and typical
stage weights (:data:`STAGES`); it never goes back, and it is not proportional to time.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from typing import TextIO

#: The bake's stages in pipeline order, with the share of a typical run each takes (solver
#: and bake dominate; the numbers only shape a progress bar).  A skipped stage counts as done.
STAGES: dict[str, float] = {
    "load": 0.04,
    "cracks": 0.02,
    "unwrap": 0.08,
    "simmesh": 0.06,
    "stress": 0.06,
    "solve": 0.40,
    "bake": 0.18,
    "stress_bake": 0.06,
    "write": 0.08,
    "decals": 0.02,
}
FORMAT = "jsonl"


def stage_start(stage: str) -> float:
    """Share of the run done when ``stage`` starts: the weights of the stages before it."""
    names = list(STAGES)
    return round(sum(STAGES[n] for n in names[: names.index(stage)]) / sum(STAGES.values()), 4)


class JsonlProgress(logging.Handler):
    """Writes the run's events to ``stream`` as JSON lines (see the module's docstring).

    Log records of the ``crackbake`` loggers that carry ``extra={"stage": ID}`` start a stage;
    every other record is a detail of the running one.  Use as a context manager around the
    run, as :class:`crackbake.display.Display` (both can be attached at once).  A stream that
    fails (the reader went away) is dropped: the run goes on.
    """

    def __init__(self, stream: TextIO, t0: float | None = None) -> None:
        super().__init__(logging.INFO)
        self.stream: TextIO | None = stream
        self.t0 = time.perf_counter() if t0 is None else t0
        self.stage: str | None = None
        self.fraction = 0.0
        self._lock = threading.Lock()
        self._saved: tuple[int, bool] | None = None

    def event(self, kind: str, **fields) -> None:
        """Write one event line (``event``, ``t``, then ``fields``)."""
        line = json.dumps({"event": kind, "t": round(time.perf_counter() - self.t0, 3), **fields})
        with self._lock:
            if self.stream is None:
                return
            try:
                self.stream.write(line + "\n")
                self.stream.flush()
            except (OSError, ValueError):  # a closed pipe: the reader is gone, the run is not
                self.stream = None

    def emit(self, record: logging.LogRecord) -> None:
        try:
            message = record.getMessage()
            stage = getattr(record, "stage", None)
            if stage in STAGES:
                self.stage = stage
                self.fraction = max(self.fraction, stage_start(stage))
                self.event("stage", stage=stage, message=message, fraction=self.fraction)
            else:
                self.event("detail", stage=self.stage, message=message, fraction=self.fraction)
        except Exception:  # progress must never break the run
            self.handleError(record)

    def start(self, version: str) -> None:
        self.event("start", version=version, fraction=0.0)

    def warn(self, message: str) -> None:
        self.event("warning", message=message)

    def done(self, summary: dict) -> None:
        self.fraction = 1.0
        self.event("done", fraction=1.0, summary=summary)

    def error(self, message: str, exit_code: int, cancelled: bool = False) -> None:
        self.event("error", message=message, exit_code=int(exit_code), cancelled=cancelled)

    def __enter__(self) -> JsonlProgress:
        root = logging.getLogger("crackbake")
        self._saved = (root.level, root.propagate)
        root.addHandler(self)
        root.setLevel(logging.INFO)
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        root = logging.getLogger("crackbake")
        root.removeHandler(self)
        if self._saved is not None:
            root.setLevel(self._saved[0])
            root.propagate = self._saved[1]
