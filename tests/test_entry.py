"""The console-script entry (crackbake.entry): one line and exit 2 off Linux, the command on it."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from crackbake.entry import platform_error

ROOT = Path(__file__).resolve().parents[1]


def _run(code: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=env, timeout=120)


def test_other_systems_get_one_line_and_exit_2():
    for platform in ("win32", "darwin", "cygwin"):
        msg = platform_error(platform)
        assert msg and "Linux" in msg and platform in msg and "\n" not in msg
    # A whole process that believes it is on Windows: no traceback, nothing imported.
    r = _run("import sys; sys.platform = 'win32'; from crackbake.entry import main; main()")
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and "runs on Linux only" in r.stderr, r.stderr
    assert "Traceback" not in r.stderr


def test_linux_runs_the_command():
    assert platform_error("linux") is None
    r = _run("import sys; sys.argv = ['crackbake', '--version']; "
             "from crackbake.entry import main; main()")
    assert r.returncode == 0, r.stderr
    assert "crackbake" in r.stdout


def test_the_exit_skips_teardown_but_keeps_what_an_exit_owes(tmp_path):
    """The command's end: exit status as SystemExit's, atexit handlers run, non-daemon threads
    joined, buffered output flushed; only the interpreter's teardown is skipped."""
    flag = tmp_path / "thread-done"
    code = (
        "import atexit, sys, threading, time\n"
        "atexit.register(lambda: print('atexit ran'))\n"
        f"threading.Thread(target=lambda: (time.sleep(0.3), open({str(flag)!r}, 'w').close()))"
        ".start()\n"
        "sys.argv = ['crackbake', '--help']\n"
        "sys.stdout.write('buffered, no newline')\n"
        "from crackbake.entry import main; main()\n"
        "print('not reached')\n"
    )
    r = _run(code)
    assert r.returncode == 0, r.stderr
    assert "Usage:" in r.stdout and "buffered, no newline" in r.stdout
    assert "atexit ran" in r.stdout and "not reached" not in r.stdout
    assert flag.exists()  # the thread was joined, not killed
    # A failing command keeps its status (click's usage error: 2).
    r = _run("import sys; sys.argv = ['crackbake', '--no-such-option']; "
             "from crackbake.entry import main; main()")
    assert r.returncode == 2 and "no-such-option" in r.stderr


def test_the_exit_is_pythons_own_under_a_profiler():
    """A profiler writes its results after the command returns: no os._exit under one."""
    r = _run("import sys, cProfile; sys.argv = ['crackbake', '--help']\n"
             "from crackbake.entry import main\n"
             "p = cProfile.Profile(); p.enable()\n"
             "try:\n    main()\nexcept SystemExit as e:\n    p.disable(); print('exit', e.code)\n")
    assert r.returncode == 0, r.stderr
    assert "exit 0" in r.stdout
