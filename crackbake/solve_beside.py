"""The solve in a forked child process, beside the run's GL and UV stages (issue 25).

Where the bake runs on a GPU it takes a fifth of a second, and a run is one core's work: the
run's thread imports, makes the EGL context, prepares the UVs, then builds the sim mesh and the
stress field and solves.  The solve needs neither GL nor the UVs, and the UV stage does not
need the cracks, so once the inputs are checked the run forks: the child solves while the
parent makes the context, prepares the UVs and loads the later stages' kernels.  A thread could
not do this: both sides hold the GIL most of the time (tried, docs/benchmarks.md).

The child sends back, over a pipe, in order:

* its log records, which the parent hands to its own loggers once it waits for the result
  (so the progress stream keeps its order: the UV stage, then the sim mesh ...) and as they
  come from then on (a long solve still reports its progress);
* its warnings, which the parent issues again (so the CLI shows them, and records them in the
  summary, as from an in-process solve);
* the result and the child's stage times (pickled), or the error it raised.

Where the child cannot send a result (something in it does not pickle, the child died), the
parent solves in-process as if there had been no child.  A fork is made only where it is safe:
on Linux, with no other Python thread running than the display's ticker, whose locks the child
never takes (it logs, warns and prints only through the pipe).  The child dies with the parent
(``PR_SET_PDEATHSIG``) and leaves through ``os._exit``: nothing of the parent's (the output
folder's staging, ``atexit``) runs in it.
"""

from __future__ import annotations

import logging
import os
import pickle
import sys
import threading
import traceback
import warnings
from collections.abc import Callable

#: Python threads a fork may leave behind: they take no lock the child uses.
_SAFE_THREADS = ("crackbake-display",)

#: Fewest cores a run forks on by default.  On 2 cores the child and the parent's own work (the
#: readback images, llvmpipe's start, the later kernels' loads) share the machine, and the
#: README bake measured 1.06x slower than solving in turn (docs/benchmarks.md); the fork pays
#: where the parent's start-up and the solve each get a core.
MIN_CORES = 4

#: Environment variable that overrides the default: ``1`` forks wherever :func:`can_fork`, ``0``
#: never (the benchmarks' A/B, and a way out should a host misbehave under a fork).
ENV = "CRACKBAKE_SOLVE_BESIDE"


def wanted(asked: bool | None = None) -> bool:
    """Whether a run solves beside: ``asked`` when given, else :data:`ENV` when set, else at
    least :data:`MIN_CORES` cores available to this process."""
    if asked is not None:
        return bool(asked)
    env = os.environ.get(ENV, "").strip()
    if env in ("0", "1"):
        return env == "1"
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cores = os.cpu_count() or 1
    return cores >= MIN_CORES


def can_fork() -> bool:
    """True where :func:`start` forks (Linux, no Python thread running but the display's)."""
    if not sys.platform.startswith("linux") or not hasattr(os, "fork"):
        return False
    me = threading.current_thread()
    return all(t is me or t.name in _SAFE_THREADS for t in threading.enumerate())


class Beside:
    """``fn(*args, timings=...)`` running in a forked child; :meth:`result` waits for it.

    Use :func:`start`, which returns None where no fork is made.
    """

    def __init__(self, pid: int, stream, fn: Callable, args: tuple) -> None:
        self.pid = pid
        self.fell_back = False  #: the child sent no result and :meth:`result` solved here
        self._stream = stream
        self._fn = fn
        self._args = args

    def result(self, timings: dict[str, float], before_wait: Callable[[], None] | None = None):
        """The child's ``fn`` result, its stage times added to ``timings``; its log records and
        warnings replayed here.  ``before_wait`` runs first (the parent's own work while the
        child solves).  Raises what ``fn`` raised in the child; where the child sent no result,
        ``fn`` runs here instead."""
        try:
            if before_wait is not None:
                before_wait()
            while True:
                try:
                    kind, payload = pickle.load(self._stream)
                except Exception:  # noqa: BLE001 - EOF or a cut message: the child is gone
                    kind, payload = "fallback", None
                if kind == "log":
                    record = logging.makeLogRecord(payload)
                    logging.getLogger(record.name).handle(record)
                elif kind == "warn":
                    message, category, filename, lineno = payload
                    warnings.warn_explicit(message, category, filename, lineno)
                elif kind == "done":
                    value, child_timings = payload
                    timings.update(child_timings)
                    return value
                elif kind == "error":
                    raise payload
                else:
                    break
        finally:
            self.close()
        self.fell_back = True
        logging.getLogger(__name__).info("the solver's child process sent no result: solving here")
        return self._fn(*self._args, timings=timings)

    def close(self) -> None:
        """Stop the child if it still runs, and reap it."""
        if self.pid <= 0:
            return
        pid, self.pid = self.pid, 0
        try:
            self._stream.close()
        except OSError:
            pass
        try:
            done, _status = os.waitpid(pid, os.WNOHANG)
            if done == 0:
                import signal

                os.kill(pid, signal.SIGKILL)
                os.waitpid(pid, 0)
        except ChildProcessError:
            pass


def start(fn: Callable, *args) -> Beside | None:
    """Fork, and run ``fn(*args, timings=<dict>)`` in the child; None where no fork is made
    (:func:`can_fork`), and the caller runs ``fn`` itself."""
    if not can_fork():
        return None
    read, write = os.pipe()
    parent = os.getpid()
    with warnings.catch_warnings():
        # numpy's BLAS threads wait idle, and OpenBLAS stops them around a fork itself.
        warnings.filterwarnings("ignore", ".*fork.*", DeprecationWarning)
        pid = os.fork()
    if pid == 0:  # the child
        code = 0
        try:
            os.close(read)
            _child(os.fdopen(write, "wb"), parent, fn, args)
        except BaseException:  # noqa: BLE001 - the parent solves itself: nothing may escape
            code = 1
        finally:
            os._exit(code)
    os.close(write)
    return Beside(pid, os.fdopen(read, "rb"), fn, args)


class _Forward(logging.Handler):
    """The child's log records, to the parent."""

    def __init__(self, send: Callable) -> None:
        super().__init__(logging.NOTSET)
        self._send = send

    def emit(self, record: logging.LogRecord) -> None:
        state = dict(record.__dict__)
        state["msg"] = record.getMessage()
        state["args"] = None
        state["exc_info"] = state["exc_text"] = None
        self._send("log", state)


def _child(stream, parent: int, fn: Callable, args: tuple) -> None:
    from crackbake.child import die_with_parent

    os.environ["CRACKBAKE_SOLVE_PARENT"] = str(parent)
    die_with_parent("CRACKBAKE_SOLVE_PARENT")
    # Nothing of the child reaches the terminal but through the parent; fresh stream objects,
    # so no lock a parent thread held at the fork is ever taken here.
    sys.stdout = sys.stderr = open(os.devnull, "w")  # noqa: SIM115 - lives until _exit
    lock = threading.Lock()

    def send(kind: str, payload) -> None:
        # Pickled whole before a byte is written: a payload that fails leaves no half message.
        data = pickle.dumps((kind, payload), protocol=pickle.HIGHEST_PROTOCOL)
        with lock:  # the solver's warm-up thread may log too
            stream.write(data)
            stream.flush()

    forward = _Forward(send)
    for name in [None, *logging.root.manager.loggerDict]:
        logger = logging.getLogger(name)
        for handler in list(getattr(logger, "handlers", ())):
            logger.removeHandler(handler)
    logging.root.addHandler(forward)
    crackbake_logger = logging.getLogger("crackbake")
    crackbake_logger.propagate = True

    def show(message, category, filename, lineno, file=None, line=None) -> None:
        send("warn", (str(message), category, filename, lineno))

    warnings.showwarning = show
    timings: dict[str, float] = {}
    try:
        value = fn(*args, timings=timings)
    except BaseException as exc:  # noqa: BLE001 - sent to the parent, raised there
        try:
            exc.add_note("in the solver's child process:\n" + traceback.format_exc())
            pickle.loads(pickle.dumps(exc, protocol=pickle.HIGHEST_PROTOCOL))
            send("error", exc)
        except Exception:  # noqa: BLE001 - an error that does not pickle: the parent re-solves
            send("fallback", None)
        return
    try:
        send("done", (value, timings))
    except Exception:  # noqa: BLE001 - a result that does not pickle: the parent re-solves
        send("fallback", None)
