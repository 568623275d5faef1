"""SIGINT and SIGTERM during a run: both unwind the run like Ctrl-C, never mid-commit.

Python turns SIGINT into :class:`KeyboardInterrupt`, but SIGTERM (what ``kill``, ``timeout``,
schedulers and containers send) kills the process on the spot, leaving the staging folder behind.
:func:`interruptible` makes both raise :class:`Interrupt` so every ``finally`` and ``with`` block
cleans up, and :func:`deferred` holds them back while the output folder is being swapped.
"""

from __future__ import annotations

import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TypeVar

from crackbake.errors import CrackbakeError

SIGNALS = (signal.SIGINT, signal.SIGTERM)
T = TypeVar("T")


class Interrupt(KeyboardInterrupt):
    """SIGINT or SIGTERM arrived; ``signum`` says which."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = int(signum)


class RunInterrupted(CrackbakeError):
    """A run stopped by SIGINT/SIGTERM; the message says what the output folder holds.

    ``exit_code`` is 128 + the signal number (130 for SIGINT, 143 for SIGTERM), as shells report
    a process ended by that signal.
    """

    def __init__(self, message: str, signum: int = signal.SIGINT) -> None:
        super().__init__(message)
        self.signum = int(signum)
        self.exit_code = 128 + self.signum


class _State(threading.local):
    depth = 0  # nesting of deferred()
    pending: int | None = None
    # The last signal of this run, kept even when its exception was lost: raised inside a C
    # extension's import or a callback, it can come back as another error or not at all.
    received: int | None = None
    active: bool = False  # inside interruptible()


_state = _State()


#: Code of Python's import machinery: an exception raised there can leave the global import
#: lock (or a module's lock) held for good, and every later import in any thread then waits for
#: ever.  A re-bake stopped while its main thread imported a module hung so, its encoder threads
#: blocked on their own imports and the main thread waiting for them.
_IMPORT_CODE = ("<frozen importlib._bootstrap>", "<frozen importlib._bootstrap_external>")


def _importing(frame) -> bool:
    """Whether ``frame`` or one of its callers runs Python's import machinery."""
    while frame is not None:
        if frame.f_code.co_filename in _IMPORT_CODE:
            return True
        frame = frame.f_back
    return False


def _handler(signum, frame) -> None:
    _state.received = signum
    if _state.depth > 0:
        _state.pending = signum  # raised when the deferred block ends
        return
    if _importing(frame):  # raised once the import is done (signalled again then)
        _signal_after_import(signum)
        return
    raise Interrupt(signum)


#: Seconds between two looks at the main thread while a signal waits for its import to end.
_IMPORT_POLL = 0.005


def _signal_after_import(signum: int) -> None:
    """Send ``signum`` to the main thread again as soon as no import runs in it (a watcher
    thread): the handler then raises :class:`Interrupt` outside the import machinery."""
    main = threading.main_thread().ident

    def watch() -> None:
        while True:
            time.sleep(_IMPORT_POLL)
            frame = sys._current_frames().get(main)
            if frame is None:  # the main thread is gone: nothing left to stop
                return
            if not _importing(frame):
                break
        signal.pthread_kill(main, signum)

    threading.Thread(target=watch, name="crackbake-signal", daemon=True).start()


@contextmanager
def interruptible() -> Iterator[None]:
    """SIGINT and SIGTERM raise :class:`Interrupt` in the main thread while the block runs.

    Signals the process ignores (``nohup``, background jobs) stay ignored; the previous handlers
    come back when the block ends.  Off the main thread (where Python cannot set handlers) this
    does nothing.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _state.received = None
    _state.active = True
    previous = {}
    for sig in SIGNALS:
        old = signal.getsignal(sig)
        if old is not signal.SIG_IGN:
            previous[sig] = old
            signal.signal(sig, _handler)
    try:
        yield
    finally:
        _state.active = False
        for sig, old in previous.items():
            signal.signal(sig, old if old is not None else signal.SIG_DFL)


@contextmanager
def deferred() -> Iterator[None]:
    """Hold SIGINT/SIGTERM (under :func:`interruptible`) until the block ends, then raise.

    For short sections that must not stop half-way: the swap of the output folder.
    """
    _state.depth += 1
    try:
        yield
    finally:
        _state.depth -= 1
    if _state.depth == 0 and _state.pending is not None:
        signum, _state.pending = _state.pending, None
        raise Interrupt(signum)


def received() -> int | None:
    """The signal that arrived under :func:`interruptible` (None if none did)."""
    return _state.received


def run_staged(stage, body: Callable[[], T]) -> T:
    """Run ``body()`` in ``with interruptible(), stage:``; an interrupt -> :class:`RunInterrupted`.

    ``stage`` is the run's :class:`~crackbake.transaction.stage.OutputStage`; its
    ``interrupted_message()`` says what the output folder holds after the interrupt.
    """
    try:
        with interruptible(), stage:
            return body()
    except KeyboardInterrupt as exc:  # the folder keeps its previous set
        signum = getattr(exc, "signum", signal.SIGINT)
        raise RunInterrupted(stage.interrupted_message(), signum) from None
    except Exception:
        # A signal raised inside a C extension (an import, a callback) can surface as another
        # error (ImportError "initialization failed"): the run was interrupted all the same.
        signum = received()
        if signum is None:
            raise
        raise RunInterrupted(stage.interrupted_message(), signum) from None


def raise_if_received() -> None:
    """Raise :class:`Interrupt` if a signal arrived whose exception did not reach the run (a
    C extension swallowed or converted it), so a run that was asked to stop never commits.

    Only inside :func:`interruptible`: a signal an earlier run in this process received (a
    library caller's, a test's) must not stop a later commit made outside it."""
    if _state.active and _state.received is not None:
        raise Interrupt(_state.received)
