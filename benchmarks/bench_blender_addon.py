"""The Blender extension's overhead over the plain command (issue 22's floor: at most 1.5 s
beyond the CLI run on spot at 2048²).

Runs ``crackbake spot.obj --preset glass --impact ... --res 2048 --target blender --formats png``
from a shell-like subprocess (after a warm-up run, so numba's kernels load from the cache), then
the same bake through the extension under Blender's Python (installed into a temporary user
profile): ``bpy.ops.crackbake.bake(wait=True)``.  Prints the operator's wall time split into
export, crackbake's run and loading the result, and the overhead: operator time minus the CLI's
wall time.

``--timer`` instead bakes spot in the background at ``--res`` (4096 by default) and calls the
extension's timer function as Blender's timer does (tests/blender/addon_bake.py, mode
``background``): each call must return within 0.05 s while crackbake runs beside it, so the
interface never stalls during a large bake.  It prints the calls and the slowest ones, and exits
1 above that floor.  (This was a test; a wall-clock floor is a benchmark's to measure.)

Usage::

    CRACKBAKE_BLENDER_PYTHON=.venv-blender/bin/python python benchmarks/bench_blender_addon.py \\
        [--res 2048] [-n 3] [--timer]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SPOT = ROOT / "examples" / "spot.obj"
IMPACT = (0.334, 0.044, 0.287)  # on spot's flank

CHILD = """
import json, os, sys, time
import bpy
zip_path, spot, out, res = sys.argv[1:5]
impact = [float(c) for c in sys.argv[5].split(",")]
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default",
                                         enable_on_install=True)
ops = sys.modules["bl_ext.user_default.crackbake.ops"]
bpy.ops.wm.obj_import(filepath=spot, forward_axis="Y", up_axis="Z")  # OBJ coordinates kept
obj = bpy.context.selected_objects[0]
bpy.context.view_layer.objects.active = obj
s = obj.crackbake
s.output_dir, s.res, s.preset = out + os.sep, int(res), "glass"
bpy.ops.crackbake.add_impact(location=impact)
bpy.ops.crackbake.check_command()  # the one-off --version check, not part of a bake
t = time.perf_counter()
r = bpy.ops.crackbake.bake(wait=True)
total = time.perf_counter() - t
print(json.dumps({"result": sorted(r), "total": total, **ops.LAST_TIMINGS}))
sys.stdout.flush()
os._exit(0)
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--res", type=int, default=None, help="2048, or 4096 with --timer")
    parser.add_argument("-n", "--pairs", type=int, default=3,
                        help="CLI and extension runs, taken in turn (the median is reported)")
    parser.add_argument("--timer", action="store_true",
                        help="time the extension's timer calls during a background bake")
    args = parser.parse_args()
    if args.timer:
        return timer(args.res or 4096)
    args.res = args.res or 2048
    bpy_python = os.environ.get("CRACKBAKE_BLENDER_PYTHON") or str(
        ROOT / ".venv-blender" / "bin" / "python")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    with tempfile.TemporaryDirectory(prefix="bench-addon-") as tmp:
        tmp = Path(tmp)
        from crackbake.blender.build import build_extension

        zip_path = build_extension(tmp / "zip")
        impact = ",".join(map(str, IMPACT))
        cli = [sys.executable, "-m", "crackbake", str(SPOT), "--preset", "glass", "--impact",
               impact, "--res", str(args.res), "--target", "blender", "--formats", "png",
               "--uv", "keep", "-q"]
        subprocess.run([*cli, "-o", str(tmp / "warm")], check=True, env=env)
        (tmp / "child.py").write_text(CHILD)
        pairs = []
        # in turn, so that a change of the machine's load falls on both sides alike
        for i in range(args.pairs):
            t = time.perf_counter()
            subprocess.run([*cli, "-o", str(tmp / f"cli{i}")], check=True, env=env)
            cli_s = time.perf_counter() - t
            (tmp / f"user{i}").mkdir()
            proc = subprocess.run(
                [bpy_python, str(tmp / "child.py"), str(zip_path), str(SPOT),
                 str(tmp / f"ext{i}"), str(args.res), impact],
                env={**env, "BLENDER_USER_RESOURCES": str(tmp / f"user{i}")},
                capture_output=True, text=True, check=True)
            pairs.append((cli_s, json.loads(proc.stdout.strip().splitlines()[-1])))
    print(f"spot, glass, one impact, {args.res}² (--target blender --formats png), "
          f"{args.pairs} pairs in turn\n")
    print("| pair | CLI run (wall) | bake operator (wait=True) | export | crackbake run in it "
          "| load images, node group | **overhead** (operator - CLI) |")
    print("|---|---|---|---|---|---|---|")
    for i, (cli_s, ext) in enumerate(pairs):
        print(f"| {i + 1} | {cli_s:.2f} | {ext['total']:.2f} | {ext['export']:.2f} | "
              f"{ext['run']:.2f} | {ext['finish']:.2f} | {ext['total'] - cli_s:+.2f} |")
    over = sorted(ext["total"] - cli_s for cli_s, ext in pairs)
    own = sorted(ext["export"] + ext["finish"] for _, ext in pairs)
    print(f"\nmedian overhead {over[len(over) // 2]:+.2f} s (floor 1.5 s); the extension's own "
          f"steps (export + loading) median {own[len(own) // 2]:.2f} s")


TIMER_FLOOR_S = 0.05  # one timer call may hold Blender's interface this long at most


def timer(res: int) -> None:
    """Bake spot at ``res`` in the background through the extension; time each timer call."""
    sys.path.insert(0, str(ROOT / "tests"))
    from blender_runner import run_blender

    with tempfile.TemporaryDirectory(prefix="bench-addon-timer-") as tmp:
        tmp = Path(tmp)
        from crackbake.blender.build import build_extension

        zip_path = build_extension(tmp / "zip")
        (tmp / "user").mkdir()
        (tmp / "tmp").mkdir()
        env = {"BLENDER_USER_RESOURCES": str(tmp / "user"), "TMPDIR": str(tmp / "tmp"),
               "PYTHONPATH": str(ROOT), "CRACKBAKE_CACHE_DIR": str(tmp / "c"),
               "CRACKBAKE_TEST_SIM_FACES": "3000"}
        out = run_blender("addon_bake.py", zip_path, SPOT, tmp / "out", res, "background",
                          env=env)
    run = out["run"]
    sizes = sorted({v["size"][0] for v in out["state"]["images"].values()})
    print(f"spot, glass, background bake at {res}² through the extension ({out['bake_s']:.1f} s)")
    print(f"status: {run['status']}; images loaded at {sizes}")
    print(f"timer calls during the run: {run['polls'] - 1}, slowest {run['max_poll_s']:.4f} s "
          f"(floor {TIMER_FLOOR_S} s); five slowest {[round(t, 4) for t in run['slowest']]}")
    print(f"last call (loads the result): {run['finish_s']:.2f} s")
    ok = (run["status"].endswith("cracks") and run["polls"] > 10 and sizes == [res]
          and run["max_poll_s"] < TIMER_FLOOR_S)
    if not ok:
        raise SystemExit(f"FAILED: the timer blocked or the bake did not finish: {run}")


if __name__ == "__main__":
    main()
