"""crackbake against Blender's Cycles bake, whole processes in pairs (issue 25: ≥ 4× faster).

Each pair runs, one after the other in alternating order (so a change of the shared machine's
load falls on both sides alike):

(a) ``crackbake examples/spot.obj --preset glass --impact 0.334,0.044,0.287 --res 4096``: the
    README bake, default formats (13 files), a fresh interpreter;
(b) a fresh Python 3.11 interpreter with Blender as a module (``bpy``, the environment
    ``make test`` installs: ``.venv-blender``) that imports spot, gives it a procedural mask
    material (a Noise texture into a Color Ramp into an Emission shader), Cycles-bakes ``EMIT``
    into a new 4096² image on the CPU (one sample a texel, Blender's default 16 px margin) and
    saves it as a PNG.

(b) is the least a Blender user pays to get *any* mask baked at that size: one trivial
procedural, no simulation, one 8-bit file; (a) solves the cracks and writes every map.  Both
are timed as wall seconds of the whole child process (interpreter start, imports, mesh load, the
bake, the write, the exit); the CPU seconds (user + system, all threads) are shown as well.
The first pair is a warm-up (numba's and Blender's caches, the page cache) and not counted.

Usage::

    python benchmarks/bench_peer.py [-n 3] [--res 4096] [--blender .venv-blender/bin/python]
        [--samples 1]

The numba cache (``NUMBA_CACHE_DIR``) must be warm (``python -m crackbake.precompile``).
crackbake's modules are byte-compiled first (``compile_bytecode``), as ``make setup`` leaves them:
where ``PYTHONDONTWRITEBYTECODE`` is set, a module edited since would be compiled from source in
every timed run.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SPOT = ROOT / "examples" / "spot.obj"
IMPACT = "0.334,0.044,0.287"
FLOOR = 4.0

#: The Blender side, run as ``BPY_PYTHON -c CHILD SPOT OUT RES SAMPLES``; prints JSON timings.
CHILD = r"""
import json, sys, time
t0 = time.perf_counter()
import bpy
spot, out, res, samples = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
t_import = time.perf_counter()
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.wm.obj_import(filepath=spot)
obj = bpy.context.selected_objects[0]
bpy.context.view_layer.objects.active = obj
t_load = time.perf_counter()

mat = bpy.data.materials.new("mask")
mat.use_nodes = True
nodes, links = mat.node_tree.nodes, mat.node_tree.links
nodes.clear()
coord = nodes.new("ShaderNodeTexCoord")
noise = nodes.new("ShaderNodeTexNoise")
noise.inputs["Scale"].default_value = 12.0
noise.inputs["Detail"].default_value = 4.0
ramp = nodes.new("ShaderNodeValToRGB")
ramp.color_ramp.elements[0].position = 0.45
ramp.color_ramp.elements[1].position = 0.55
emit = nodes.new("ShaderNodeEmission")
output = nodes.new("ShaderNodeOutputMaterial")
links.new(coord.outputs["Object"], noise.inputs["Vector"])
links.new(noise.outputs["Fac"], ramp.inputs["Fac"])
links.new(ramp.outputs["Color"], emit.inputs["Color"])
links.new(emit.outputs["Emission"], output.inputs["Surface"])
image = bpy.data.images.new("mask", res, res, alpha=False)
target = nodes.new("ShaderNodeTexImage")
target.image = image
nodes.active = target  # Cycles bakes into the active image node
obj.data.materials.clear()
obj.data.materials.append(mat)

scene = bpy.context.scene
scene.render.engine = "CYCLES"
scene.cycles.device = "CPU"
scene.cycles.samples = samples
scene.cycles.use_denoising = False
t_setup = time.perf_counter()
bpy.ops.object.bake(type="EMIT")
t_bake = time.perf_counter()
image.filepath_raw = out
image.file_format = "PNG"
image.save()
t_save = time.perf_counter()
print(json.dumps({"import": t_import - t0, "load": t_load - t_import, "setup": t_setup - t_load,
                  "bake": t_bake - t_setup, "save": t_save - t_bake}))
"""


def run(argv: list[str], env: dict) -> tuple[float, float, str]:
    """Wall and CPU (user + system of the child and its threads) seconds; its stdout."""
    t = time.perf_counter()
    proc = subprocess.Popen(argv, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t
    out, err = proc.stdout.read().decode(), proc.stderr.read().decode(errors="replace")
    proc.stdout.close()
    proc.stderr.close()
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"{' '.join(argv[:3])}... failed: {err[-2000:]}")
    return wall, usage.ru_utime + usage.ru_stime, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-n", "--pairs", type=int, default=3, help="timed pairs (median) [3]")
    ap.add_argument("--res", type=int, default=4096)
    ap.add_argument("--samples", type=int, default=1, help="Cycles samples a texel [1]")
    ap.add_argument("--blender", default=os.environ.get("CRACKBAKE_BLENDER_PYTHON")
                    or str(ROOT / ".venv-blender" / "bin" / "python"),
                    help="a Python that imports bpy [.venv-blender/bin/python]")
    a = ap.parse_args()
    sys.path.insert(0, str(ROOT))
    from crackbake.precompile import compile_bytecode

    compile_bytecode()
    extra = os.environ.get("PYTHONPATH")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), *([extra] if extra else [])]))
    bpy_env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    rows: dict[str, list[tuple[float, float]]] = {"crackbake": [], "cycles": []}
    stages: dict[str, list[dict]] = {"crackbake": [], "cycles": []}
    with tempfile.TemporaryDirectory(prefix="bench_peer_") as tmp:
        tmp = Path(tmp)

        def crackbake(i: int) -> None:
            out = tmp / f"cb{i}"
            wall, cpu, _ = run([sys.executable, "-m", "crackbake", str(SPOT), "--preset",
                                "glass", "--impact", IMPACT, "--res", str(a.res), "-q",
                                "-o", str(out)], env)  # fmt: skip
            if i > 0:
                rows["crackbake"].append((wall, cpu))
                stages["crackbake"].append(
                    json.loads((out / "manifest.json").read_text())["timings_s"])

        def cycles(i: int) -> None:
            png = tmp / f"cycles{i}.png"
            wall, cpu, out = run([a.blender, "-c", CHILD, str(SPOT), str(png), str(a.res),
                                  str(a.samples)], bpy_env)  # fmt: skip
            if not png.exists():
                raise SystemExit("Blender wrote no image")
            if i > 0:
                rows["cycles"].append((wall, cpu))
                stages["cycles"].append(json.loads(out.strip().splitlines()[-1]))

        for i in range(a.pairs + 1):  # pair 0 warms the caches
            first, second = (crackbake, cycles) if i % 2 == 0 else (cycles, crackbake)
            first(i)
            second(i)
            print(".", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    print(f"\n{a.pairs} pairs after a warm-up pair, alternating order; {a.res}²; Cycles "
          f"{a.samples} sample(s) a texel on the CPU; load average at the end "
          f"{os.getloadavg()[0]:.1f}, {os.cpu_count()} CPUs\n")
    print("| pair | crackbake s (CPU s) | Cycles EMIT s (CPU s) | Cycles / crackbake |")
    print("|---|---:|---:|---:|")
    pairs = list(zip(rows["crackbake"], rows["cycles"], strict=True))
    for i, ((cw, cc), (bw, bc)) in enumerate(pairs, 1):
        print(f"| {i} | {cw:.2f} ({cc:.1f}) | {bw:.2f} ({bc:.1f}) | {bw / cw:.2f}× |")
    cw = statistics.median(w for w, _ in rows["crackbake"])
    bw = statistics.median(w for w, _ in rows["cycles"])
    ratios = sorted(b[0] / c[0] for c, b in pairs)
    print(f"| **median** | **{cw:.2f}** | **{bw:.2f}** | **{bw / cw:.2f}×** "
          f"(pairs {ratios[0]:.2f}–{ratios[-1]:.2f}; floor {FLOOR:.0f}×) |")
    med = {k: statistics.median(s[k] for s in stages["cycles"]) for k in stages["cycles"][0]}
    print("\nCycles child, median s: " + ", ".join(f"{k} {v:.2f}" for k, v in med.items()))
    keys = ("load", "simmesh", "stress", "solve", "bake", "stress_bake", "write", "total")
    cb = {k: statistics.median(s[k] for s in stages["crackbake"]) for k in keys
          if all(k in s for s in stages["crackbake"])}
    print("crackbake stages, median s: " + ", ".join(f"{k} {v:.2f}" for k, v in cb.items())
          + f"; start-up and exit {cw - cb.get('total', 0):.2f}")


if __name__ == "__main__":
    main()
