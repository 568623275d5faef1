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
