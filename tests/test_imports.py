"""The package's layering, checked in a fresh interpreter: what a module pulls in on import."""

from __future__ import annotations

import subprocess
import sys

# Imports every module under crackbake.simulate and prints the crackbake.metrics modules loaded.
_SIMULATE = """
import importlib, pkgutil, sys
import crackbake.simulate as sim
names = [m.name for m in pkgutil.walk_packages(sim.__path__, "crackbake.simulate.")]
for name in names:
    importlib.import_module(name)
print(len(names))
print(" ".join(sorted(m for m in sys.modules if m.startswith("crackbake.metrics"))))
"""


def test_simulate_does_not_import_metrics():
    """The simulation depends on no measure of its results (metrics/ reads networks)."""
    r = subprocess.run([sys.executable, "-c", _SIMULATE], capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    count, loaded = (r.stdout.splitlines() + ["", ""])[:2]
    assert int(count) > 20  # the walk really reached the solver's modules
    assert loaded == "", f"crackbake.simulate imports {loaded}"
