"""Many short ``crackbake`` commands, each in a process of its own, for the price of one import.

A command that fails on its input spends most of its CPU importing numpy, scipy, trimesh and
numba (2-3 s each time); a catalogue of a hundred such commands is mostly imports.  Here one
server process imports the command's modules once and forks a child per command.  The child is a
real process running the real entry point (``crackbake.entry.main``, what ``python -m crackbake``
runs) in its own working directory and environment, under its own address-space cap, with its
stdout and stderr on files and stdin on /dev/null; its exit status is the command's.  What a
fork does not show, a fresh interpreter's imports, the callers check with real subprocesses.

Run as a script it is the server: a JSON list of commands on stdin, a JSON list of results on
stdout; with ``--stream``, one command per stdin line and its result as one stdout line, until
stdin closes.  Tests call :func:`run_commands` for a catalogue run at once, :func:`run` in place
of ``subprocess.run([sys.executable, "-m", "crackbake", ...])`` (one server per test process).
"""

from __future__ import annotations

import atexit
import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

# What the commands import on their way to an error or a small bake (crackbake.pipeline and the
# modules it imports inside functions), so that no child imports them again.
PRELOAD = (
    "crackbake.cli", "crackbake.pipeline", "trimesh", "numba", "scipy.spatial", "moderngl",
    "PIL.Image", "crackbake.geometry_kernels", "crackbake.bake.context", "crackbake.bake.raster",
    "crackbake.bake.uv", "crackbake.bake.tangents", "crackbake.bake.stress",
    "crackbake.exchange.bundle", "crackbake.exchange.manifest", "crackbake.simulate.simmesh",
    "crackbake.simulate.stress", "crackbake.simulate.timing",
    "crackbake.simulate.solver.iben",
)


def run_commands(commands: list[dict], workers: int = 4, timeout: float = 600) -> list[dict]:
    """Run ``crackbake`` commands in forks of one server process, ``workers`` at a time.

    Parameters
    ----------
    commands : list of dict
        Each with ``args`` (list of str, the command line after ``crackbake``), ``cwd`` (str),
        ``env`` (dict, the whole environment), and optionally ``rlimit_as`` (bytes, an
        address-space cap set in the child) and ``timeout`` (seconds, default 300: the child is
        killed after it and its ``rc`` is ``"timed out"``).
    workers : int
        Children running at once.
    timeout : float
        Seconds for the whole catalogue.

    Returns
    -------
    list of dict
        Per command, in order: ``rc`` (int exit status or "timed out"), ``stdout``, ``stderr``
        (str) and ``secs`` (wall seconds of the child).
    """
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    r = subprocess.run([sys.executable, __file__, str(workers)], input=json.dumps(commands),
                       capture_output=True, text=True, env=env, timeout=timeout)
    if r.returncode != 0:
        raise RuntimeError(f"cli_forks server failed (exit {r.returncode}):\n{r.stderr}")
    return json.loads(r.stdout)


def _child(command: dict, out: str, err: str) -> None:
    """In the forked child: become the command, run it, exit with its status."""
    import logging

    # The server's exit handlers are not the command's (a fresh process has its own).
    atexit._clear()
    code: object = 1
    try:
        os.chdir(command["cwd"])
        os.environ.clear()
        os.environ.update(command["env"])
        cap = command.get("rlimit_as")
        if cap:
            resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)
        for fd, path in ((1, out), (2, err)):
            os.dup2(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600), fd)
        sys.argv = ["crackbake", *command["args"]]
        from crackbake.entry import main

        main()
        code = 0
    except SystemExit as exc:  # as the interpreter turns SystemExit into a status
        code = exc.code
    except BaseException:  # noqa: BLE001 - a traceback is what the catalogue must catch
        import traceback

        traceback.print_exc()
        code = 1
    finally:
        if code is None:
            code = 0
        elif not isinstance(code, int):
            print(code, file=sys.stderr)
            code = 1
        try:
            atexit._run_exitfuncs()
            logging.shutdown()
            sys.stdout.flush()
            sys.stderr.flush()
        finally:
            os._exit(code & 0xFF)


def _preload() -> None:
    import importlib

    for name in PRELOAD:
        importlib.import_module(name)


def serve(commands: list[dict], workers: int) -> list[dict]:
    results: list[dict | None] = [None] * len(commands)
    pending = list(enumerate(commands))
    running: dict[int, tuple[int, float, float, str, str]] = {}
    tmp = tempfile.mkdtemp(prefix="cli-forks-")  # not TemporaryDirectory: a child's exit
    try:                                          # must not run its clean-up
        while pending or running:
            while pending and len(running) < workers:
                i, command = pending.pop(0)
                out, err = f"{tmp}/{i}.out", f"{tmp}/{i}.err"
                sys.stdout.flush()
                sys.stderr.flush()
                pid = os.fork()
                if pid == 0:
                    _child(command, out, err)
                start = time.monotonic()
                running[pid] = (i, start, start + command.get("timeout", 300), out, err)
            pid, status = os.waitpid(-1, os.WNOHANG)
            if pid == 0:
                now = time.monotonic()
                for p, (i, _, deadline, _, _) in list(running.items()):
                    if now > deadline:
                        os.kill(p, signal.SIGKILL)
                        os.waitpid(p, 0)
                        _, start, _, out, err = running.pop(p)
                        results[i] = {"rc": "timed out", "stdout": "", "secs": now - start,
                                      "stderr": f"killed after {now - start:.0f} s"}
                time.sleep(0.01)
                continue
            i, start, _, out, err = running.pop(pid)
            rc = os.waitstatus_to_exitcode(status)
            results[i] = {"rc": rc, "secs": time.monotonic() - start,
                          "stdout": Path(out).read_text(errors="replace"),
                          "stderr": Path(err).read_text(errors="replace")}
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return results  # type: ignore[return-value]


_SERVER: subprocess.Popen | None = None
_LOCK = threading.Lock()


def _stop(server: subprocess.Popen) -> None:
    """End the server with this process and wait for it (its children's CPU counts here)."""
    server.stdin.close()
    server.wait(60)


def run(args: list, *, cwd: str | Path | None = None, env: dict | None = None,
        timeout: float = 300) -> subprocess.CompletedProcess:
    """``crackbake *args`` in a fork of this test process's server, as ``subprocess.run`` with
    ``capture_output=True, text=True`` would run ``python -m crackbake *args``.

    Parameters
    ----------
    args : list
        The command line after ``crackbake`` (items turned into str).
    cwd, env : the working directory and the whole environment (default: this process's).
    timeout : float
        Seconds; past them the child is killed and :class:`subprocess.TimeoutExpired` raised.
    """
    global _SERVER
    command = {"args": [str(a) for a in args], "cwd": str(cwd or os.getcwd()),
               "env": dict(os.environ if env is None else env), "timeout": timeout}
    with _LOCK:
        if _SERVER is None or _SERVER.poll() is not None:
            # lives as long as this process: its stdin closes with it, and it ends
            _SERVER = subprocess.Popen(
                [sys.executable, __file__, "--stream"], stdin=subprocess.PIPE,
                stdout=subprocess.PIPE, text=True, env={**os.environ, "PYTHONPATH": str(REPO)})
            atexit.register(_stop, _SERVER)
        _SERVER.stdin.write(json.dumps(command) + "\n")
        _SERVER.stdin.flush()
        line = _SERVER.stdout.readline()
    if not line:
        raise RuntimeError("the cli_forks server ended")
    r = json.loads(line)
    argv = ["crackbake", *command["args"]]
    if r["rc"] == "timed out":
        raise subprocess.TimeoutExpired(argv, timeout)
    return subprocess.CompletedProcess(argv, r["rc"], r["stdout"], r["stderr"])


if __name__ == "__main__":
    _preload()
    if sys.argv[1] == "--stream":
        for text in sys.stdin:
            print(json.dumps(serve([json.loads(text)], 1)[0]), flush=True)
    else:
        print(json.dumps(serve(json.loads(sys.stdin.read()), int(sys.argv[1]))))
