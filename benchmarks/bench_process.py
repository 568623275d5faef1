"""Whole-process speed (issue 25): every figure as fresh ``crackbake`` processes, median of N.

Each case runs the real command in a new interpreter (what an artist's re-bake from Blender
or a batch job pays: imports, EGL, every stage, the exit); the table gives the wall seconds
and the CPU seconds (user + system of the child, all its threads) of each, plus the stage
times the runs' ``manifest.json`` files record (in the order they run: ``coverage``, the
faces' coverage drawn for the gutter fill planned ahead, runs before the solver, and the crack
bake's render targets are allocated on a thread meanwhile, so work moved out of ``bake`` shows
in the wall and CPU figures).  On a busy machine the CPU seconds are the steadier comparison.

Cases (floors from issue 25):

- ``help`` / ``version``: ``crackbake --help`` and ``--version`` (≤ 0.15 s);
- ``bake``: the README example, ``spot.obj --preset glass --impact 0.334,0.044,0.287 --res
  4096`` with the default formats (≤ 4.0 s on 2 cores with llvmpipe); its ``write`` stage (the
  13 files, ≤ 1.0 s), its ``bake`` stage (≤ 1.5 s) and the start-up before the first stage
  (``start``: wall minus the manifest's ``total``, which also holds the exit; ≤ 0.25 s);
- ``bake_cold``: the same bake with an empty cache folder (the first bake of an asset: no
  mesh cache, so the UV check, the tangent frames and the sim mesh are computed; the ``bake``
  case's runs after its first read them, as an artist's next bake of the asset does, whatever
  the impact);
- ``rebake``: the same mesh re-baked from that run's ``cracks.json`` (``--cracks``, ≤ 2.5 s), the
  artist's repeated re-bake: the mesh cache (``crackbake.bake.mesh_cache``) holds the asset's
  gutter plan, tangent frames and UV check from the bake before;
- ``rebake_cold``: the same re-bake with an empty cache folder (the first re-bake of an asset);
- ``inspect``: ``crackbake inspect`` on that run's 4096² crack EXR (≤ 0.5 s);
- ``load``: the ``load`` stage of spot with a 1024² base colour texture bound by an MTL
  (generated here; ≤ 0.1 s), from a 512² run;
- ``first``: the start-up to the first stage, exactly: a 512² glass bake with ``--progress
  jsonl``, timed from the launch to the arrival of its ``load`` stage event (≤ 0.25 s; the
  ``bake`` case's ``start`` also holds the exit after ``total``);
- ``bigload``: ``load_mesh`` of spot subdivided to 1.5M faces (``bench_scale``'s OBJ, made
  once) in a fresh interpreter, as the ``load`` stage runs it (≤ 3 s).

Usage::

    python benchmarks/bench_process.py [-n 3] [--cases bake rebake ...] [--repo OTHER_CHECKOUT]
                                       [--other-env NAME=VALUE] [--compile-deps]

``--repo`` runs every case against another checkout too (``git worktree add /tmp/old main``),
interleaved run by run with this one so both see the same load, and adds its column and the
ratio.  ``--other-env NAME=VALUE`` (repeatable) sets variables for the other column only; without
``--repo`` the other column is this tree under them: ``--other-env OPENBLAS_NUM_THREADS=16``
compares OpenBLAS's threads with the one thread crackbake starts it with.  The
numba cache (``NUMBA_CACHE_DIR``) must be warm for both trees (``python -m
crackbake.precompile``): compilation is not what this measures.  Nor is the compiling of
modules from source: where Python writes no bytecode (``PYTHONDONTWRITEBYTECODE``) and a
dependency was installed without it (the H200 hosts' numpy), every process compiled 130 of
numpy's modules again (``import numpy`` 0.33-0.41 s there).  The script says so, one line per
package, and ``--compile-deps`` byte-compiles them first, as ``pip install`` would have.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
import zlib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
IMPACT = "0.334,0.044,0.287"
CASES = ("help", "version", "bake", "bake_cold", "rebake", "rebake_cold", "inspect", "load",
         "first", "bigload")
#: Floors of issue 25, seconds: (case, figure) -> floor.
FLOORS = {
    ("help", "wall"): 0.15,
    ("version", "wall"): 0.15,
    ("bake", "wall"): 4.0,
    ("bake", "start"): 0.25,
    ("bake", "bake"): 1.5,
    ("bake", "write"): 1.0,
    ("bake_cold", "wall"): 4.0,
    ("rebake", "wall"): 2.5,
    ("rebake_cold", "wall"): 2.5,
    ("inspect", "wall"): 0.5,
    ("load", "load"): 0.1,
    ("first", "first"): 0.25,
    ("bigload", "load"): 3.0,
}
#: A fresh interpreter that times the mesh load as the pipeline's ``load`` stage calls it.
_LOAD_SNIPPET = """
import sys, time
from crackbake.io.mesh import load_mesh
t = time.perf_counter()
load_mesh(sys.argv[1])
print(time.perf_counter() - t)
"""


def _png(path: Path, size: int = 1024) -> None:
    """An RGB gradient with some texture noise, as an 8-bit PNG (no dependency but zlib)."""
    import struct

    import numpy as np

    y, x = np.mgrid[0:size, 0:size]
    rng = np.random.default_rng(0)
    img = np.stack([x * 255 // size, y * 255 // size, (x ^ y) & 255], -1).astype(np.int16)
    img = np.clip(img + rng.integers(-8, 9, img.shape), 0, 255).astype(np.uint8)
    rows = np.concatenate([np.zeros((size, 1), np.uint8), img.reshape(size, -1)], 1)

    def chunk(kind: bytes, data: bytes) -> bytes:
        crc = zlib.crc32(kind + data)
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", crc)

    ihdr = struct.pack(">IIBBBBB", size, size, 8, 2, 0, 0, 0)
    idat = zlib.compress(rows.tobytes(), 6)
    head = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr)
    path.write_bytes(head + chunk(b"IDAT", idat) + chunk(b"IEND", b""))


def textured_spot(folder: Path) -> Path:
    """examples/spot.obj with a generated 1024² texture bound through an MTL, and UVs kept."""
    folder.mkdir(parents=True, exist_ok=True)
    _png(folder / "spot_texture.png")
    (folder / "spot.mtl").write_text("newmtl spot\nKd 1 1 1\nmap_Kd spot_texture.png\n")
    text = (ROOT / "examples" / "spot.obj").read_text()
    (folder / "spot.obj").write_text("mtllib spot.mtl\nusemtl spot\n" + text)
    return folder / "spot.obj"


def run(repo: Path, args: list[str], out: Path | None = None, cache: Path | None = None,
        extra_env: dict | None = None) -> dict:
    """One fresh process of ``python -m crackbake ARGS`` on ``repo``'s code: wall, CPU, stages.

    With ``--progress jsonl`` in ``args``, ``first`` is the time from the launch to the first
    stage's event; ``args`` starting with ``-c`` run that Python snippet instead, whose last
    stdout line (a number of seconds) is ``load``.  ``cache``: the run's cache folder
    (``CRACKBAKE_CACHE_DIR``), never the user's."""
    # The tree first; what PYTHONPATH already holds after it (an extra site, say).
    extra = os.environ.get("PYTHONPATH")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(repo), *([extra] if extra else [])]))
    if cache is not None:
        env["CRACKBAKE_CACHE_DIR"] = str(cache)
    env.update(extra_env or {})
    if out is not None and out.exists():
        shutil.rmtree(out)
    command = [sys.executable, *args] if args[0] == "-c" else [sys.executable, "-m", "crackbake",
                                                                *args]  # fmt: skip
    watch = "--progress" in args or args[0] == "-c"
    t = time.perf_counter()
    proc = subprocess.Popen(command, env=env, cwd=repo, stderr=subprocess.PIPE,
                            stdout=subprocess.PIPE if watch else subprocess.DEVNULL)  # fmt: skip
    first, last = None, ""
    if watch:
        for line in proc.stdout:  # as the child writes them: the time they arrive
            if first is None and b'"stage": "load"' in line:
                first = time.perf_counter() - t
            last = line.decode(errors="replace").strip() or last
        proc.stdout.close()
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t
    proc.returncode = os.waitstatus_to_exitcode(status)
    err = proc.stderr.read().decode(errors="replace")
    proc.stderr.close()
    if proc.returncode != 0:
        raise SystemExit(f"{repo}: crackbake {' '.join(args)} failed ({proc.returncode}): {err}")
    row = {"wall": wall, "cpu": usage.ru_utime + usage.ru_stime}
    if first is not None:
        row["first"] = first
    if args[0] == "-c":
        row["load"] = float(last)
    if out is not None:
        timings = json.loads((out / "manifest.json").read_text())["timings_s"]
        row.update({k: float(v) for k, v in timings.items()})
        row["start"] = wall - timings["total"]
    return row


def case_args(case: str, scratch: Path, tag: str) -> tuple[list[str], Path | None]:
    spot = ROOT / "examples" / "spot.obj"
    if case == "help":
        return ["--help"], None
    if case == "version":
        return ["--version"], None
    if case in ("bake", "bake_cold"):
        out = scratch / f"{tag}_{case}"
        return [str(spot), "--preset", "glass", "--impact", IMPACT, "--res", "4096",
                "-q", "-o", str(out)], out  # fmt: skip
    if case in ("rebake", "rebake_cold"):
        out = scratch / f"{tag}_{case}"
        return [str(spot), "--cracks", str(scratch / f"{tag}_cracks.json"), "--res", "4096",
                "-q", "-o", str(out)], out  # fmt: skip
    if case == "inspect":
        return ["inspect", str(scratch / f"{tag}_cracks.exr")], None
    if case == "load":
        out = scratch / f"{tag}_load"
        return [str(scratch / "textured" / "spot.obj"), "--preset", "glass", "--impact", IMPACT,
                "--res", "512", "-q", "-o", str(out)], out  # fmt: skip
    if case == "first":
        out = scratch / f"{tag}_first"
        return [str(spot), "--preset", "glass", "--impact", IMPACT, "--res", "512",
                "--progress", "jsonl", "-o", str(out)], out  # fmt: skip
    if case == "bigload":
        sys.path.insert(0, str(ROOT / "benchmarks"))
        from bench_scale import subdivided_spot

        return ["-c", _LOAD_SNIPPET, str(subdivided_spot(4))], None
    raise ValueError(case)


#: The figures reported for each case, besides wall and CPU.
STAGES = {
    "bake": ("start", "load", "unwrap", "tangents", "coverage", "simmesh", "stress", "solve",
             "bake", "stress_bake", "write"),
    "bake_cold": ("start", "simmesh", "stress", "solve", "bake", "write"),
    "rebake": ("start", "load", "cracks", "unwrap", "tangents", "coverage", "bake", "write"),
    "rebake_cold": ("start", "load", "cracks", "unwrap", "tangents", "coverage", "bake", "write"),
    "load": ("load",),
    "first": ("first", "load"),
    "bigload": ("load",),
}  # fmt: skip


#: The packages a bake imports from Python source (their modules' bytecode matters).
DEPENDENCIES = ("numpy", "numba", "llvmlite", "trimesh", "moderngl", "glcontext", "click",
                "zlib_ng", "yaml")  # fmt: skip


def without_bytecode(packages) -> list[tuple[str, Path, int]]:
    """``(name, folder, count)`` of each installed package among ``packages`` with modules that
    have no ``.pyc``, where this Python writes none itself (``PYTHONDONTWRITEBYTECODE``); empty
    elsewhere (the first process writes them).  Test folders are not counted."""
    import importlib.util

    if not sys.dont_write_bytecode:
        return []
    out = []
    for name in packages:
        spec = importlib.util.find_spec(name)
        if spec is None or not spec.submodule_search_locations:
            continue
        folder = Path(list(spec.submodule_search_locations)[0])
        missing = sum(1 for f in folder.rglob("*.py") if "tests" not in f.parts
                      and not Path(importlib.util.cache_from_source(str(f))).exists())  # fmt: skip
        if missing:
            out.append((name, folder, missing))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("-n", type=int, default=3, help="runs per case (median) [3]")
    ap.add_argument("--cases", nargs="+", choices=CASES, default=list(CASES))
    ap.add_argument("--repo", type=Path, help="another checkout to compare against (A/B)")
    ap.add_argument("--keep", type=Path, help="scratch folder to use and keep")
    ap.add_argument("--other-env", action="append", default=[], metavar="NAME=VALUE",
                    help="environment of the other column only (without --repo: this tree)")
    ap.add_argument("--compile-deps", action="store_true",
                    help="byte-compile the dependencies' modules that have no bytecode (as pip "
                         "would have) where this Python writes none")  # fmt: skip
    a = ap.parse_args()
    envs = {"this": {}, "other": dict(item.split("=", 1) for item in a.other_env)}
    repos = {"this": ROOT}
    if a.repo is not None or envs["other"]:
        repos = {"other": (a.repo or ROOT).resolve(), "this": ROOT}
    sys.path.insert(0, str(ROOT))
    from crackbake.precompile import compile_bytecode

    for repo in repos.values():  # as `make setup` leaves them (PYTHONDONTWRITEBYTECODE)
        compile_bytecode(repo / "crackbake")
    for name, folder, missing in without_bytecode(DEPENDENCIES):
        if a.compile_deps:
            compile_bytecode(folder)
        else:
            print(f"bench_process: {missing} of {name}'s modules have no bytecode and this Python "
                  f"writes none, so every process compiles them (the H200 host's numpy: 0.1 s of "
                  f"start-up); add --compile-deps, or run python -m compileall {folder}",
                  file=sys.stderr)  # fmt: skip
    scratch = Path(a.keep or tempfile.mkdtemp(prefix="bench_process_"))
    scratch.mkdir(parents=True, exist_ok=True)
    textured_spot(scratch / "textured")
    # The re-bake and inspect cases need one bake's sidecar and EXR per tree.
    for tag, repo in repos.items():
        if {"rebake", "rebake_cold", "inspect"} & set(a.cases):
            args, out = case_args("bake", scratch, tag)
            run(repo, args, out, scratch / f"cache_{tag}", envs[tag])
            shutil.copy(out / "cracks.json", scratch / f"{tag}_cracks.json")
            shutil.copy(out / "spot_cracks.exr", scratch / f"{tag}_cracks.exr")
    rows: dict[tuple[str, str], list[dict]] = {}
    for case in a.cases:
        for _ in range(a.n):
            for tag, repo in repos.items():  # interleaved: both trees see the same load
                args, out = case_args(case, scratch, tag)
                cache = scratch / f"cache_{tag}"  # one per tree, warmed by the runs before
                if case in ("bake_cold", "rebake_cold"):
                    cache = scratch / f"cold_{tag}"
                    shutil.rmtree(cache, ignore_errors=True)
                rows.setdefault((case, tag), []).append(run(repo, args, out, cache, envs[tag]))
                print(".", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    load = os.getloadavg()[0]
    print(f"\nmedian of {a.n} fresh processes per cell; load average at the end {load:.1f}; "
          f"{os.cpu_count()} CPUs; seconds\n")  # fmt: skip
    tags = list(repos)
    header = ["case", "figure", "floor"]
    for t in tags:
        header += [f"{t} s (min)"]
    header += [f"{t} CPU s" for t in tags]
    if len(tags) == 2:
        header += ["this / other"]
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for case in a.cases:
        for fig in ("wall", *STAGES.get(case, ())):
            cells = [case, fig, f"{FLOORS[(case, fig)]:.2f}" if (case, fig) in FLOORS else ""]
            meds = []
            for t in tags:
                vals = [r[fig] for r in rows[(case, t)] if fig in r]
                if not vals:
                    cells.append("–")
                    meds.append(None)
                    continue
                meds.append(statistics.median(vals))
                cells.append(f"{meds[-1]:.3f} ({min(vals):.3f})")
            for t in tags:
                cells.append(
                    f"{statistics.median(r['cpu'] for r in rows[(case, t)]):.2f}"
                    if fig == "wall" else ""
                )  # fmt: skip
            if len(tags) == 2:
                ok = None not in meds and meds[0] > 0
                cells.append(f"{meds[1] / meds[0]:.2f}" if ok else "")
            print("| " + " | ".join(cells) + " |")
    if a.keep is None:
        shutil.rmtree(scratch, ignore_errors=True)


if __name__ == "__main__":
    main()
