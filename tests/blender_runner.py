"""Runs check scripts under a Python that can ``import bpy`` (Blender as a module).

Blender's ``bpy`` wheel needs Python 3.11 and ``numpy<2``, so it usually lives in its own
environment: point ``CRACKBAKE_BLENDER_PYTHON`` at that interpreter (or install the
``blender`` extra into this one).  Tests that need it are skipped when neither works.
The scripts live in ``tests/blender/``; each prints one JSON object as its last stdout line.
"""

from __future__ import annotations

import functools
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

SCRIPTS = Path(__file__).resolve().parent / "blender"


@functools.cache
def blender_python() -> str | None:
    """An interpreter that imports ``bpy``, or None."""
    candidates = [os.environ.get("CRACKBAKE_BLENDER_PYTHON"), sys.executable]
    for exe in filter(None, candidates):
        try:
            ok = subprocess.run(
                [exe, "-c", "import bpy"], capture_output=True, timeout=120
            ).returncode == 0
        except (OSError, subprocess.TimeoutExpired):
            ok = False
        if ok:
            return exe
    return None


def run_blender(script: str, *args: str, timeout: float = 600, env: dict | None = None) -> dict:
    """Run ``tests/blender/<script>`` with ``args`` under Blender's Python; its JSON result.

    ``env`` adds to (or overrides) this process's environment.  Skips the calling test when no
    interpreter with ``bpy`` is available.
    """
    exe = blender_python()
    if exe is None:
        pytest.skip("Blender's bpy is not available (set CRACKBAKE_BLENDER_PYTHON)")
    proc = subprocess.run(
        [exe, str(SCRIPTS / script), *map(str, args)],
        capture_output=True, text=True, timeout=timeout,
        env=None if env is None else {**os.environ, **env},
    )
    if proc.returncode != 0:
        raise AssertionError(f"{script} failed under Blender:\n{proc.stderr[-3000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])
