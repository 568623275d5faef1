"""Drying cycles (``--cycles N``): junction angles against N, the relaxation time, the cost.

Run: ``python benchmarks/bench_cycles.py [--seeds 0 1 2] [--plate-faces 20000]
[--spot-faces 100000] [--picture docs/mud_cycles.png]``.

For each mesh (a flat 1 x 1 plate and ``examples/spot.obj``) and seed, the mud preset is solved
once in-process (:func:`crackbake.pipeline.solve`, timed: sim mesh + stress + solve), then
:func:`crackbake.simulate.cycles.redry` takes it to N = 2..12 dryings (N = 8 timed).  Prints:

* the mean junction angle (:func:`crackbake.metrics.angles.mean_junction_angle`: the largest of
  the three angles at each degree-3 junction, 180 = T, 120 = Y) against N, mean and spread over
  the seeds;
* the relaxation time fitted over N = 1..8 (:func:`crackbake.metrics.angles.relaxation_time`)
  per seed, with its mean and spread (Goehring et al. 2010 measured about 4 generations);
* the cost floor of issue 24: ``--cycles 8`` must cost at most 8 x one mud solve; the table
  gives (solve + 7 re-dryings) / solve.

Timings are wall seconds on whatever machine runs it: rerun on a quiet one before quoting them.
``--picture`` writes mud at N = 1, 2, 4, 8 on the plate and on spot (seed 0): the networks of
the table drawn over the shaded mesh (orthographic, PIL only: a GL preview of eight networks
takes minutes on llvmpipe), crack strokes as wide as ``crack.width``.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from crackbake.io.mesh import load_mesh
from crackbake.metrics.angles import mean_junction_angle, relaxation_time
from crackbake.params import RunParams
from crackbake.pipeline import solve
from crackbake.precompile import plate_obj
from crackbake.simulate.cycles import redry

ROOT = Path(__file__).resolve().parents[1]
SPOT = ROOT / "examples" / "spot.obj"
NS = (1, 2, 3, 4, 5, 6, 8, 12)
FIT = (1, 2, 3, 4, 5, 6, 8)
SHOWN = (1, 2, 4, 8)


def measure(path: Path, sim_faces: int, seed: int) -> dict:
    """One mud solve and its re-dryings: angles per N, fitted tau, timings, the networks."""
    mesh = load_mesh(path)
    params, relative = RunParams(mesh=path, preset="mud", sim_faces=sim_faces,
                                 seed=seed).resolved()
    t = time.perf_counter()
    net = solve(mesh, params, relative, {})[0]
    t_solve = time.perf_counter() - t
    angles, nets, t_cycles = {}, {}, float("nan")
    for n in NS:
        t = time.perf_counter()
        out = redry(net, mesh.vertices, mesh.faces, n, seed)
        if n == 8:
            t_cycles = time.perf_counter() - t
        angles[n] = mean_junction_angle(out)
        nets[n] = out
    tau = relaxation_time(FIT, [angles[n] for n in FIT])
    return {"mesh": mesh, "angles": angles, "tau": tau, "t_solve": t_solve,
            "t_cycles": t_cycles, "nets": nets}


#: Picture views: direction towards the viewer and the screen's up, per mesh.
VIEWS = {"plate": ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0)), "spot": ((0.75, 0.25, 0.62), (0.0, 1.0, 0.0))}
CLAY, CRACK = np.array([185, 168, 148]), (52, 40, 32)


def render(mesh, net, view, size: int = 720) -> Image.Image:
    """The mesh shaded and the network's cracks drawn over it, orthographic, CPU only (PIL):
    faces painted back to front, a crack segment drawn where the face seen at its midpoint
    lies at its depth (hidden cracks stay hidden)."""
    from crackbake.geometry import face_normals

    d = np.asarray(view[0], float) / np.linalg.norm(view[0])
    e1 = np.cross(view[1], d)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(d, e1)
    v = mesh.vertices
    xy = np.c_[v @ e1, v @ e2]
    lo, hi = xy.min(0), xy.max(0)
    k = 2 * size * 0.94 / float((hi - lo).max())  # drawn at 2x, then reduced (antialiasing)
    off = (2 * size - k * (hi - lo)) / 2

    def px(p):
        q = np.c_[p @ e1, p @ e2]
        return np.c_[off[0] + k * (q[:, 0] - lo[0]), 2 * size - off[1] - k * (q[:, 1] - lo[1])]

    img = Image.new("RGB", (2 * size, 2 * size), (41, 42, 50))
    ids = Image.new("I", img.size, -1)
    draw, draw_ids = ImageDraw.Draw(img), ImageDraw.Draw(ids)
    n = face_normals(v, mesh.faces)
    depth = v[mesh.faces].mean(axis=1) @ d
    screen = px(v)
    for f in np.argsort(depth):  # far first
        if n[f] @ d <= 0:
            continue
        poly = [tuple(screen[i]) for i in mesh.faces[f]]
        draw.polygon(poly, fill=tuple(int(c) for c in CLAY * (0.35 + 0.65 * float(n[f] @ d))))
        draw_ids.polygon(poly, fill=int(f))
    seen = np.asarray(ids)
    tol = 0.02 * float(np.linalg.norm(hi - lo))
    for c in net.cracks:
        p = px(c.points)
        mid = (0.5 * (p[1:] + p[:-1])).round().astype(int).clip(0, 2 * size - 1)
        face = seen[mid[:, 1], mid[:, 0]]
        pdepth = 0.5 * (c.points[1:] + c.points[:-1]) @ d
        show = (face >= 0) & (np.abs(depth[np.maximum(face, 0)] - pdepth) < tol)
        width = np.maximum(k * 0.5 * (c.width[1:] + c.width[:-1]), 2.0)
        for i in np.flatnonzero(show):
            draw.line([tuple(p[i]), tuple(p[i + 1])], fill=CRACK, width=int(round(width[i])))
    return img.resize((size, size), Image.LANCZOS)


def picture(rows: dict, path: Path, panel: int = 420) -> None:
    """Mud at N = 1, 2, 4, 8 (columns) on the plate and on spot (rows), labelled."""
    sheet = Image.new("RGB", (len(SHOWN) * panel, len(rows) * panel), (41, 42, 50))
    font = ImageFont.load_default(size=22)
    for i, (name, r) in enumerate(rows.items()):
        for j, n in enumerate(SHOWN):
            img = render(r["mesh"], r["nets"][n], VIEWS[name], panel - 8)
            x0, y0 = j * panel, i * panel
            sheet.paste(img, (x0 + 4, y0 + 4))
            label = f"{name} N={n}: {r['angles'][n]:.0f} deg"
            draw = ImageDraw.Draw(sheet)
            box = draw.textbbox((x0 + 12, y0 + 8), label, font=font)
            draw.rectangle((box[0] - 6, box[1] - 4, box[2] + 6, box[3] + 4), fill=(41, 42, 50))
            draw.text((x0 + 12, y0 + 8), label, fill=(235, 235, 235), font=font)
    # A palette keeps the sheet small without visible banding (as bench_presets does).
    sheet.quantize(colors=96, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE).save(
        path, optimize=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--plate-faces", type=int, default=20000)
    ap.add_argument("--spot-faces", type=int, default=100000)
    ap.add_argument("--picture", type=Path)
    ap.add_argument("--only", choices=["plate", "spot"], help="measure one mesh")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench_cycles_") as tmp:
        paths = {"plate": plate_obj(Path(tmp) / "plate.obj", 4, uv_margin=0.0), "spot": SPOT}
        faces = {"plate": args.plate_faces, "spot": args.spot_faces}
        if args.only:
            paths = {args.only: paths[args.only]}
        results = {name: [measure(paths[name], faces[name], s) for s in args.seeds]
                   for name in paths}
        print(f"mean junction angle (degrees; 180 = T, 120 = Y), mud, seeds {args.seeds}\n")
        print("| mesh | " + " | ".join(f"N={n}" for n in NS) + " | tau (N=1..8) |")
        print("|---|" + "---|" * (len(NS) + 1))
        for name, rs in results.items():
            cells = []
            for n in NS:
                a = np.array([r["angles"][n] for r in rs])
                cells.append(f"{a.mean():.1f} ± {a.std():.1f}")
            taus = np.array([r["tau"] for r in rs])
            per = ", ".join(f"{t:.2f}" for t in taus)
            print(f"| {name} | " + " | ".join(cells)
                  + f" | {taus.mean():.2f} ± {taus.std():.2f} ({per}) |")
        print("\ncost of --cycles 8 against one mud solve (wall seconds, this machine)\n")
        print("| mesh | seed | solve s | 7 re-dryings s | (solve + cycles) / solve | floor |")
        print("|---|---|---|---|---|---|")
        for name, rs in results.items():
            for s, r in zip(args.seeds, rs, strict=True):
                ratio = (r["t_solve"] + r["t_cycles"]) / r["t_solve"]
                print(f"| {name} | {s} | {r['t_solve']:.2f} | {r['t_cycles']:.3f} | "
                      f"{ratio:.3f} | <= 8 |")
        if args.picture:
            picture({name: rs[0] for name, rs in results.items()}, args.picture)
            print(f"\nwrote {args.picture}")


if __name__ == "__main__":
    main()
