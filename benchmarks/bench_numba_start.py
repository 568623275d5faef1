"""numba's start-up in a fresh process (issue 25's fixed per-process cost), with numba's own cache
loads and with :func:`crackbake.jit.light_cache_loads`.

Each probe is a fresh interpreter that imports what a run has imported by then (numpy,
scipy.spatial, scipy.sparse), then times in CPU seconds (user + system, ``getrusage``):

- ``import numba``;
- ``first load``: the first call of a cached kernel (``crackbake.grouping.first_ids``): numba's
  target context set-up (its ``refresh()`` of every registry, or the runtime alone when light)
  and the load itself;
- ``tangent loads``: the kernels of :mod:`crackbake.bake.tangent_kernels` the tangent stage
  calls, loaded by :func:`crackbake.bake.tangents.with_tangents` on a small plate (a fold and
  an unused vertex: the kernels and signatures spot's tangents load);
- ``registries``: whether numba loaded its compiler's registries (1) or not (0).

The two modes run interleaved, ``-n`` pairs; the table gives the median and the minimum.

Usage::

    python benchmarks/bench_numba_start.py [-n 5]

The numba cache (``NUMBA_CACHE_DIR``) must be warm (``python -m crackbake.precompile``).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

_PROBE = """
import json, resource, sys
def cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime
import numpy as np
import scipy.sparse, scipy.spatial  # noqa: F401 - what a run has imported by its first kernel
c0 = cpu()
import numba  # noqa: F401
from numba.core import cpu as nbcpu
refreshed = []
original = nbcpu.CPUContext.load_additional_registries
def counting(self):
    refreshed.append(1)
    return original(self)
nbcpu.CPUContext.load_additional_registries = counting
c1 = cpu()
if sys.argv[1] == "light":
    from crackbake.jit import light_cache_loads
    light_cache_loads()
from crackbake.grouping import first_ids
c2 = cpu()
first_ids(np.arange(10, dtype=np.int64))
c3 = cpu()
from crackbake.bake.tangents import with_tangents
from crackbake.bake.uv import UVMesh
x, y = np.meshgrid(np.linspace(0.0, 1.0, 4), np.linspace(0.0, 1.0, 4))
v = np.column_stack([x.ravel(), y.ravel(), np.zeros(16)])
i = (np.arange(3)[:, None] * 4 + np.arange(3)[None, :]).ravel()
f = np.concatenate([np.column_stack([i, i + 1, i + 5]), np.column_stack([i, i + 5, i + 4])])[:-1]
uv = v[:, :2].copy()
uv[[0, 4, 8, 12], 0] = 0.5
plate = UVMesh(vertices=v, faces=f, uv=uv, normals=np.tile([0.0, 0.0, 1.0], (16, 1)),
               vertex_map=np.arange(16), method="kept", overlap_fraction=0.0, padding_px=0)
c4 = cpu()
with_tangents(plate)
c5 = cpu()
print(json.dumps({"import numba": c1 - c0, "first load": c3 - c2, "tangent loads": c5 - c4,
                  "registries": float(bool(refreshed))}))
"""


def probe(mode: str) -> dict[str, float]:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    r = subprocess.run([sys.executable, "-c", _PROBE, mode], env=env, capture_output=True,
                       text=True, timeout=300)
    if r.returncode != 0:
        raise SystemExit(r.stderr.strip()[-500:])
    return json.loads(r.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("-n", type=int, default=5, help="pairs of fresh processes [5]")
    args = ap.parse_args()
    runs: dict[str, list[dict]] = {"numba": [], "light": []}
    for i in range(args.n):
        for mode in (("numba", "light") if i % 2 == 0 else ("light", "numba")):
            runs[mode].append(probe(mode))
    keys = list(runs["numba"][0])
    print(f"CPU seconds, median (min) of {args.n} fresh processes each; "
          f"load average {os.getloadavg()[0]:.1f}")
    print("| figure | numba's loads | light loads |")
    print("|---|---:|---:|")
    for k in keys:
        cells = []
        for mode in ("numba", "light"):
            v = [r[k] for r in runs[mode]]
            cells.append(f"{statistics.median(v):.3f} ({min(v):.3f})")
        print(f"| {k} | {cells[0]} | {cells[1]} |")


if __name__ == "__main__":
    main()
