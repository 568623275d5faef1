"""The crackbake subprocess: its command line, its ``--progress jsonl`` events, cancelling.

No ``bpy`` here: Blender's timer only calls :meth:`Job.poll`, which never blocks (two reader
threads move the child's lines into queues), so the UI keeps running while a bake does.
"""

from __future__ import annotations

import json
import os
import queue
import shlex
import shutil
import signal
import subprocess
import threading
import time
from dataclasses import dataclass, field


def split_command(command: str) -> list[str]:
    """The preference's command string as an argument list (quoted paths allowed)."""
    return shlex.split(command, posix=os.name != "nt")


def check_command(command: str, timeout: float = 60.0) -> tuple[str | None, str | None]:
    """Run ``COMMAND --version``: ``(version, None)``, or ``(None, a one-line reason)``."""
    try:
        argv = split_command(command)
    except ValueError as exc:
        return None, f"the crackbake command '{command}' cannot be parsed ({exc})"
    if not argv:
        return None, "no crackbake command is set (Preferences > Add-ons > Crackbake)"
    try:
        proc = subprocess.run([*argv, "--version"], capture_output=True, text=True,
                              timeout=timeout, stdin=subprocess.DEVNULL)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return None, (f"cannot run the crackbake command '{command}' ({exc}); set its path in "
                      "Preferences > Add-ons > Crackbake (crackbake blender-addon fills it in)")
    words = proc.stdout.split()
    if proc.returncode != 0 or len(words) < 2 or words[0].rstrip(",") != "crackbake":
        said = (proc.stderr or proc.stdout).strip().splitlines()
        return None, (f"'{command} --version' did not answer as crackbake does (exit "
                      f"{proc.returncode}{': ' + said[-1] if said else ''}); set the command in "
                      "Preferences > Add-ons > Crackbake")
    return words[-1], None


def impact_arg(point, radius: float, strength: float) -> str:
    """``X,Y,Z:R:S`` for ``--impact`` (17 significant digits: the point survives the trip); a
    radius of 0 leaves it to crackbake (the preset's)."""
    x, y, z = (f"{float(c):.17g}" for c in point)
    r = f"{float(radius):.17g}" if radius > 0 else ""
    return f"{x},{y},{z}:{r}:{float(strength):.17g}"


@dataclass
class Job:
    """A running ``crackbake ... --progress jsonl``.

    Attributes
    ----------
    argv : list of str
        The command line.
    workdir : str
        Temporary folder of the run (the exported mesh); removed by :meth:`cleanup`.
    """

    argv: list[str]
    workdir: str
    env: dict | None = None
    events: queue.Queue = field(default_factory=queue.Queue)
    stderr_lines: list[str] = field(default_factory=list)
    fraction: float = 0.0
    message: str = "starting"
    warnings: list[str] = field(default_factory=list)
    summary: dict | None = None
    error: str | None = None
    cancelled: bool = False
    proc: subprocess.Popen | None = None
    started: float = 0.0  # time.perf_counter() at the start and when the end was seen
    ended: float = 0.0
    _threads: list[threading.Thread] = field(default_factory=list)

    def start(self) -> Job:
        self.started = time.perf_counter()
        kw = {}
        if os.name == "nt":
            kw["creationflags"] = subprocess.CREATE_NEW_PROCESS_GROUP
        else:
            kw["start_new_session"] = True  # a Ctrl-C in Blender's terminal is not the bake's
        self.proc = subprocess.Popen(self.argv, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, env=self.env, **kw)
        for pipe, sink in ((self.proc.stdout, self._read_events),
                           (self.proc.stderr, self._read_stderr)):
            t = threading.Thread(target=sink, args=(pipe,), daemon=True)
            t.start()
            self._threads.append(t)
        return self

    def _read_events(self, pipe) -> None:
        for raw in pipe:
            try:
                self.events.put(json.loads(raw))
            except ValueError:  # not an event (a library printing on stdout): keep as text
                self.events.put({"event": "detail", "message": raw.decode("utf-8", "replace")
                                 .strip()})
        pipe.close()

    def _read_stderr(self, pipe) -> None:
        for raw in pipe:
            self.stderr_lines.append(raw.decode("utf-8", "replace").rstrip())
        pipe.close()

    def poll(self) -> bool:
        """Take the events that arrived (never blocks); True once the process has ended and
        every line of it has been read."""
        while True:
            try:
                self._take(self.events.get_nowait())
            except queue.Empty:
                break
        if self.proc is None or self.proc.poll() is None:
            return False
        self.ended = self.ended or time.perf_counter()
        if any(t.is_alive() for t in self._threads):
            return False
        self._drain()
        return True

    def wait(self, timeout: float | None = None) -> None:
        """Block until the run ends (scripts: ``bpy.ops.crackbake.bake(wait=True)``)."""
        self.proc.wait(timeout)
        self.ended = self.ended or time.perf_counter()
        for t in self._threads:
            t.join(timeout)
        self._drain()

    def _drain(self) -> None:
        while not self.events.empty():
            self._take(self.events.get_nowait())
        if self.summary is None and self.error is None:
            last = next((ln for ln in reversed(self.stderr_lines) if ln.strip()), "")
            self.error = (last.removeprefix("error: ")
                          or f"crackbake ended with exit code {self.proc.returncode}")

    def _take(self, event: dict) -> None:
        kind = event.get("event")
        if "fraction" in event and event["fraction"] is not None:
            self.fraction = max(self.fraction, float(event["fraction"]))
        if kind in ("stage", "detail") and event.get("message"):
            self.message = event["message"]
        elif kind == "warning":
            self.warnings.append(event.get("message", ""))
        elif kind == "done":
            self.summary = event.get("summary") or {}
            self.message = "done"
        elif kind == "error":
            self.error = event.get("message") or "crackbake failed"
            self.cancelled = bool(event.get("cancelled"))

    def cancel(self) -> None:
        """Ask crackbake to stop (SIGTERM: it unwinds, the output folder keeps its last set)."""
        if self.proc is None or self.proc.poll() is not None:
            return
        self.cancelled = True
        try:
            if os.name == "nt":
                self.proc.send_signal(signal.CTRL_BREAK_EVENT)
            else:
                self.proc.send_signal(signal.SIGTERM)
        except OSError:
            pass

    def kill(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()

    def cleanup(self) -> None:
        shutil.rmtree(self.workdir, ignore_errors=True)
