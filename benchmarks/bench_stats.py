"""What each plane's statistics cost (:func:`crackbake.exchange.exrstats.plane_stats`: the
``crackbake:stats`` record the EXR writer takes on its encoder threads, and ``crackbake
inspect``'s pixel path), per plane of a real master, in this tree and optionally another's.

Usage::

    python benchmarks/bench_stats.py EXR [EXR ...] [-n 5] [--repo /work/main]

Each plane is timed alone on one thread, best of N (ms), after one untimed call (numba's
kernels load from its cache; ``NUMBA_CACHE_DIR`` should be warm).  With ``--repo`` the other
tree's ``plane_stats`` (its ``crackbake/exchange/exrstats.py``, loaded by path) is timed on
the same planes, interleaved, and the two results are compared field by field.
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from crackbake.exchange.exr import read_exr  # noqa: E402
from crackbake.exchange.exrstats import plane_stats  # noqa: E402


def _other(repo: Path):
    spec = importlib.util.spec_from_file_location(
        "other_exrstats", repo / "crackbake" / "exchange" / "exrstats.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.plane_stats


def _best(fn, arr, n: int) -> float:
    fn(arr)
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        fn(arr)
        times.append(time.perf_counter() - t0)
    return min(times) * 1e3


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("exr", nargs="+")
    ap.add_argument("-n", type=int, default=5)
    ap.add_argument("--repo", type=Path, default=None)
    args = ap.parse_args()
    other = _other(args.repo) if args.repo else None
    total_new = total_old = 0.0
    print(f"{'plane':32s} {'type':6s} {'this ms':>8s}" + (f" {'other ms':>9s}  diff" if other
                                                          else ""))
    for path in args.exr:
        planes, _ = read_exr(path)
        for name, arr in sorted(planes.items()):
            new = _best(plane_stats, arr, args.n)
            total_new += new
            line = f"{Path(path).stem + ':' + name:32s} {str(arr.dtype):6s} {new:8.1f}"
            if other:
                old = _best(other, arr, args.n)
                total_old += old
                a, b = plane_stats(arr), other(arr)
                diff = [k for k in a if a[k] != b[k]]
                detail = ", ".join(f"{k} {a[k]!r} vs {b[k]!r}" for k in diff)
                line += f" {old:9.1f}  {detail or 'same'}"
            print(line)
    print(f"{'total':39s} {total_new:8.1f}" + (f" {total_old:9.1f}" if other else ""))


if __name__ == "__main__":
    main()
