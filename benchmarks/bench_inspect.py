"""Where ``crackbake inspect`` of a 4096² crack master spends its time, and what a faster
reader could save (issue 25: ≤ 0.5 s whole process on 2 cores); the whole command is
``bench_process.py --cases inspect``.

Each figure is measured in a fresh interpreter (what the command pays), median of N, as wall
and CPU seconds (all threads):

- ``imports``: what ``crackbake inspect`` imports before it reads (click, numpy, OpenEXR, the
  inspect module);
- ``read``: :func:`crackbake.exchange.exr.read_exr` (the OpenEXR bindings: every plane
  allocated, inflated, un-predicted and scattered);
- ``stats``: the table's statistics of those planes (numpy, on threads);
- ``numba``: what a numba kernel costs a fresh process before it runs a byte: ``import
  numba`` and the first call of a kernel already in the on-disk cache;
- ``numba reader``: ``benchmarks/inspect_numba_reader.py`` (a numba decoder that takes the
  same statistics in one pass, keeping no plane) on the file, numba's start-up included;
- ``inflate``: the file's ZIP chunks inflated alone, one thread, with zlib-ng and (when the
  ``deflate`` package is installed) libdeflate: the floor of any reader of these files;
- ``recorded``: what the command does instead on a file crackbake wrote (no ``--png``): the
  ``crackbake:stats`` record checked against the SHA-256 of the file's pixel data
  (:func:`crackbake.exchange.exrstats.recorded_stats`) and the header read by the bindings; on
  a file without a valid record (an older crackbake's, another tool's) it prints ``None`` and
  the command reads the pixels (``read`` + ``stats``).

The command on crackbake's own files is ``imports`` + ``recorded`` (no pixel decoded); on any
other file ``imports`` + ``read`` + ``stats``.  ``numba reader`` against ``read`` + ``stats`` is
why that second route keeps the bindings: numba's
start-up alone cost a fresh process 1.0 CPU-s where the bindings' read and numpy's statistics
together took 1.4 (loaded 2-core machine, 2026-11-26), and the reader's own pass
(libdeflate's inflate is cheap; the ZIP predictor is a running sum over every byte) costs
about as much again.  Its statistics and
planes are checked here against numpy's (:func:`crackbake.exchange.inspect._stats`) and the
bindings', to the bit.

Usage::

    python benchmarks/bench_inspect.py [EXR] [-n 3]

Without EXR a 4096² crack master is baked first (the README example, about 10 s).  The numba
cache (``NUMBA_CACHE_DIR``) should be warm.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# Each probe prints {"wall": s, "cpu": s} for its part, measured inside a fresh interpreter.
_CLOCK = """
import json, resource, sys, time
def cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime
"""
PROBES = {
    "imports": _CLOCK + """
t, c = time.perf_counter(), cpu()
import click, numpy, OpenEXR
import crackbake.cli.inspect, crackbake.exchange.inspect
print(json.dumps({"wall": time.perf_counter() - t, "cpu": cpu() - c}))
""",
    "read": _CLOCK + """
from crackbake.exchange.exr import read_exr
t, c = time.perf_counter(), cpu()
channels, header = read_exr(sys.argv[1])
print(json.dumps({"wall": time.perf_counter() - t, "cpu": cpu() - c}))
""",
    "stats": _CLOCK + """
from crackbake.exchange.exr import read_exr
from crackbake.exchange.inspect import _all_stats
channels, header = read_exr(sys.argv[1])
t, c = time.perf_counter(), cpu()
_all_stats(channels, {})
print(json.dumps({"wall": time.perf_counter() - t, "cpu": cpu() - c}))
""",
    "numba": _CLOCK + """
import numpy as np
sys.path.insert(0, sys.argv[2])
t, c = time.perf_counter(), cpu()
import numba_probe
numba_probe.kernel(np.zeros(8, np.uint8))
print(json.dumps({"wall": time.perf_counter() - t, "cpu": cpu() - c}))
""",
    "numba reader": _CLOCK + """
sys.path.insert(0, sys.argv[3])
t, c = time.perf_counter(), cpu()
import inspect_numba_reader
found = inspect_numba_reader.scan(sys.argv[1])
assert found is not None, "the numba reader does not take this file"
print(json.dumps({"wall": time.perf_counter() - t, "cpu": cpu() - c}))
""",
    "inflate": _CLOCK + """
import struct
import numpy as np
from zlib_ng import zlib_ng
buf = open(sys.argv[1], "rb").read()
p, attrs = 8, {}
while buf[p]:  # the header's attributes: name, type, size, value
    name = buf.index(b"\\0", p)
    kind = buf.index(b"\\0", name + 1)
    size = struct.unpack_from("<i", buf, kind + 1)[0]
    attrs[buf[p:name]] = buf[kind + 5 : kind + 5 + size]
    p = kind + 5 + size
lines = {2: 1, 3: 16}[attrs[b"compression"][0]]  # ZIPS, ZIP
y0, y1 = struct.unpack_from("<i4xi", attrs[b"dataWindow"], 4)
chunks = []
for off in np.frombuffer(buf, "<u8", -(-(y1 - y0 + 1) // lines), p + 1):
    size = struct.unpack_from("<i", buf, int(off) + 4)[0]
    chunks.append(memoryview(buf)[int(off) + 8 : int(off) + 8 + size])
out = {}
t, c = time.perf_counter(), cpu()
sizes = [len(zlib_ng.decompress(d)) for d in chunks]
out["zlib-ng"], wall = cpu() - c, time.perf_counter() - t
try:
    import deflate
except ImportError:
    deflate = None
if deflate is not None:
    c = cpu()
    for d, size in zip(chunks, sizes):
        deflate.zlib_decompress(d, size)
    out["libdeflate"] = cpu() - c
print(json.dumps({"wall": wall, "cpu": out["zlib-ng"], **out, "bytes": sum(sizes)}))
""",
    "recorded": _CLOCK + """
from crackbake.exchange.exr import read_header
from crackbake.exchange.exrstats import recorded_stats
t, c = time.perf_counter(), cpu()
found = recorded_stats(sys.argv[1])
if found is not None:
    read_header(sys.argv[1])
print(json.dumps({"wall": time.perf_counter() - t, "cpu": cpu() - c,
                  "taken": found is not None}))
""",
}

_KERNEL = """
from numba import njit


@njit(cache=True, nogil=True)
def kernel(a):
    s = 0
    for v in a:
        s += v
    return s
"""


def probe(name: str, exr: Path, kernel_dir: Path) -> dict:
    extra = os.environ.get("PYTHONPATH")  # after the tree: an extra site (deflate, say)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), *([extra] if extra else [])]))
    args = [sys.executable, "-c", PROBES[name], str(exr), str(kernel_dir), str(ROOT / "benchmarks")]
    proc = subprocess.run(args, env=env, cwd=ROOT, capture_output=True, text=True, check=True)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def check(exr: Path) -> str:
    """Whether the numba reader's statistics and planes are the bindings' and numpy's, to the
    bit (in this process, which also compiles its kernels into the cache)."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import numpy as np
    from inspect_numba_reader import scan

    from crackbake.exchange.exr import read_exr
    from crackbake.exchange.inspect import _stats

    channels, _ = read_exr(exr)
    found = scan(exr, keep=True)
    if found is None:
        return "not taken (the file is not a ZIP/ZIPS scanline file it reads exactly)"
    bad = []
    for name, plane in channels.items():
        row, s = _stats(name, plane, {}), found["channels"][name]
        same = (row.min, row.max, row.mean, row.nonzero) == (
            s["min"], s["max"], s["sum"] / s["size"], s["nonzero"] / s["size"])
        if not same or not np.array_equal(found["planes"][name].view(np.uint8),
                                          plane.view(np.uint8)):  # fmt: skip
            bad.append(name)
    return f"differ in {bad}" if bad else f"bit-exact ({len(channels)} channels)"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("exr", type=Path, nargs="?", help="a 4096² crack master [baked here]")
    ap.add_argument("-n", type=int, default=3, help="runs per figure (median) [3]")
    a = ap.parse_args()
    scratch = Path(tempfile.mkdtemp(prefix="bench_inspect_"))
    exr = a.exr
    if exr is None:
        out = scratch / "bake"
        subprocess.run([sys.executable, "-m", "crackbake", str(ROOT / "examples" / "spot.obj"),
                        "--preset", "glass", "--impact", "0.334,0.044,0.287", "--res", "4096",
                        "-q", "-o", str(out)], cwd=ROOT, check=True,
                       env=dict(os.environ, PYTHONPATH=str(ROOT)))  # fmt: skip
        exr = out / "spot_cracks.exr"
    kernel_dir = scratch / "kernel"
    kernel_dir.mkdir()
    (kernel_dir / "numba_probe.py").write_text(_KERNEL)
    probe("numba", exr, kernel_dir)  # fills the caches: the runs below load them
    print("numba reader vs bindings + numpy:", check(exr))
    rows = {name: [probe(name, exr, kernel_dir) for _ in range(a.n)] for name in PROBES}
    load = os.getloadavg()[0]
    print(f"\n{exr}: median of {a.n} fresh processes; load average {load:.1f}; "
          f"{os.cpu_count()} CPUs; seconds\n")  # fmt: skip
    print("| part | wall | CPU |")
    print("|---|---|---|")
    for name, runs in rows.items():
        wall = statistics.median(r["wall"] for r in runs)
        cpu = statistics.median(r["cpu"] for r in runs)
        print(f"| {name} | {wall:.3f} | {cpu:.3f} |")
    if not all(r.get("taken") for r in rows["recorded"]):
        print("| recorded | (no valid crackbake:stats record: the command reads the pixels) | |")
    for lib in ("zlib-ng", "libdeflate"):
        vals = [r[lib] for r in rows["inflate"] if lib in r]
        if vals:
            print(f"| inflate, {lib} alone | | {statistics.median(vals):.3f} |")


if __name__ == "__main__":
    main()
