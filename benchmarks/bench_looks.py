"""How each preset's cracks look, measured: issue 18 §5's figures.

Run: ``python benchmarks/bench_looks.py [--res 1024] [--presets mud concrete ...] [--keep DIR]
[--blender /path/to/bpy/python]``.  Each preset runs the ``crackbake`` command (default seed,
``--formats exr,png,glb``) on ``examples/spot.obj`` and on a flat 1 x 1 plate (2 x 12^2
triangles, UVs = xy); glass gets an impact (spot's flank, the plate's centre) and concrete runs
twice, without and with that impact.  Per run it prints, from ``cracks.json``
(:mod:`crackbake.metrics.looks`): the mean width over the cell size (``sqrt`` of the mean cell
area), the crack area share (length x width over the surface area), the median coefficient of
variation of the width along a crack (and of the solver's widths, the look's width noise
divided out: what runs had before the looks); on the plate also the mask's mean (the drawn
share: the plate's texels all have the same area).  ``--picture`` renders the spot GLBs in
Blender into one labelled sheet (``docs/presets_blender.png``).  With a Blender Python
(``--blender`` or ``CRACKBAKE_BLENDER_PYTHON``) it renders a grazing-light close-up of each
spot GLB in Cycles (``tests/blender/groove_contrast.py``) and prints the groove contrast: the
mean display brightness of the groove walls facing the light minus that of the walls facing
away.
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

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from crackbake.io.mesh import load_mesh
from crackbake.looks import WIDTH_NOISE_SCALE, width_factors
from crackbake.metrics.cells import network_stats
from crackbake.metrics.looks import crack_area_share, width_cell_ratio, width_cv
from crackbake.precompile import plate_obj

ROOT = Path(__file__).resolve().parents[1]
SPOT = ROOT / "examples" / "spot.obj"
PRESETS = ("glass", "crackle", "glaze", "mud", "concrete", "ice")
IMPACT = {"spot": "0.334,0.044,0.287", "plate": "0.5,0.5,0"}
#: Close-up of the groove contrast render: a point on spot (glTF, Y-up) and the view size.
CLOSE_UP = {"spot": ("0.334", "0.044", "0.287", "0.35")}


def solver_widths(cracks: list[dict], look: dict, seed: int, diagonal: float) -> list:
    """The widths the solver gave, before the look's width noise (the noise is seeded per
    crack, so it is recomputed and divided out exactly): what runs before the looks had."""
    v = look.get("width_variation", 0.0)
    out = []
    for c in cracks:
        w = np.asarray(c["width"])
        if v > 0:
            rng = np.random.default_rng([seed, 0x100C5, int(c["id"])])
            w = w / width_factors(np.asarray(c["points"]), v, WIDTH_NOISE_SCALE * diagonal, rng)
        out.append(w)
    return out


def run(mesh: Path, preset: str, res: int, out: Path, seed: int, extra: list[str]) -> float:
    cmd = [sys.executable, "-m", "crackbake", str(mesh), "--preset", preset, "--res", str(res),
           "--formats", "exr,png,glb", "--seed", str(seed), "-o", str(out), "-q", *extra]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if proc.returncode != 0:
        raise RuntimeError(f"{preset} on {mesh.name} failed: {proc.stderr.strip()[-400:]}")
    return time.perf_counter() - t0


def groove_contrast(python: str, glb: Path, where: tuple[str, ...], out: Path) -> dict:
    script = ROOT / "tests" / "blender" / "groove_contrast.py"
    proc = subprocess.run([python, str(script), str(glb), str(out), *where],
                          capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"groove_contrast.py failed: {proc.stderr[-600:]}")
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    result["grazing_png"] = result.pop("out")
    return result


#: Widest opening before the looks, of the diagonal (the solver's widest point was exactly
#: crack_width_rel x diagonal; mud's is now sized by its cells, concrete's is 0.0035).
WIDTH_BEFORE = {"mud": 0.003, "concrete": 0.0015}


def before(out: Path, mesh: Path, preset: str, raw: list, args, folder: Path) -> Path:
    """The run as crackbake drew it before the looks: its network with the solver's widths (at
    the preset's old width) re-baked with ``--cracks`` and no preset, i.e. the default look
    (which bakes bit for bit as before: tests/test_looks.py)."""
    side = json.loads((out / "cracks.json").read_text())
    widest = max(float(np.max(w)) for w in raw)
    k = WIDTH_BEFORE[preset] * load_mesh(mesh).diagonal / widest if preset in WIDTH_BEFORE else 1.0
    for c, w in zip(side["cracks"], raw, strict=True):
        ratio = np.asarray(c["depth"]) / np.maximum(np.asarray(c["width"]), 1e-300)
        c["width"] = (w * k).tolist()
        c["depth"] = (w * k * ratio).tolist()
    path = folder / f"{out.name}_before.json"
    path.write_text(json.dumps(side))
    old = folder / f"{out.name}_before"
    cmd = [sys.executable, "-m", "crackbake", str(mesh), "--cracks", str(path), "--res",
           str(args.res), "--formats", "glb", "-o", str(old), "-q"]
    proc = subprocess.run(cmd, capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})
    if proc.returncode != 0:
        raise RuntimeError(f"re-bake of {out.name} failed: {proc.stderr.strip()[-400:]}")
    return old


def measure(mesh: Path, kind: str, preset: str, impact: bool, args, folder: Path) -> dict:
    name = f"{kind}_{preset}" + ("_impact" if impact and preset != "glass" else "")
    out = folder / name
    extra = ["--impact", IMPACT[kind]] if impact else []
    secs = run(mesh, preset, args.res, out, args.seed, extra)
    cracks = json.loads((out / "cracks.json").read_text())["cracks"]
    pts = [np.asarray(c["points"]) for c in cracks]
    wid = [np.asarray(c["width"]) for c in cracks]
    surf = load_mesh(mesh)
    st = network_stats(pts, wid, surf.vertices, surf.faces)
    look = json.loads((out / "manifest.json").read_text())["params"]["look"]
    raw = solver_widths(cracks, look, args.seed, surf.diagonal)
    row = {"run": name, "seconds": secs, "out": str(out), "width_cv_solver": width_cv(pts, raw),
           "width_cell": width_cell_ratio(st.mean_width, st.mean_cell_area),
           "area_share": crack_area_share(pts, wid, surf.vertices, surf.faces),
           "width_cv": width_cv(pts, wid), "cells": st.cells}
    if kind == "plate":
        mask = np.asarray(Image.open(out / f"{mesh.stem}_mask.png"), np.float64)
        row["mask_mean"] = float(mask.mean() / 255.0)
    if args.blender and kind in CLOSE_UP:
        row.update(groove_contrast(args.blender, out / f"{mesh.stem}.glb", CLOSE_UP[kind],
                                   folder / f"{name}_grazing.png"))
        old = before(out, mesh, preset, raw, args, folder)
        row["contrast_before"] = groove_contrast(
            args.blender, old / f"{mesh.stem}.glb", CLOSE_UP[kind],
            folder / f"{name}_grazing_before.png")["contrast"]
    return row


def picture(rows: list[dict], python: str, path: Path, folder: Path, size: int = 440) -> None:
    """The spot GLB of each preset (glass with its impact, concrete without) rendered in Blender
    (``tests/blender/render_presets.py``: Cycles, one grazing sun), one labelled panel each."""
    import shutil

    spot = [r for r in rows if r["run"].startswith("spot_") and not r["run"].endswith("_impact")]
    glbs = []
    for r in spot:
        glb = folder / f"{r['run'][5:]}.glb"
        shutil.copy(Path(r["out"]) / "spot.glb", glb)
        glbs.append(str(glb))
    script = ROOT / "tests" / "blender" / "render_presets.py"
    # Spot's flank around the glass impact, seen a little from the front and above.
    view = ["-0.35", "-0.35", "-1.0"]
    target = ["0.25", "0.1", "0.3", "1.0"]
    proc = subprocess.run([python, str(script), str(folder), str(size), *view, *target, *glbs],
                          capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"render_presets.py failed: {proc.stderr[-600:]}")
    cols = 3
    n_rows = (len(glbs) + cols - 1) // cols
    sheet = Image.new("RGB", (cols * size, n_rows * size))
    font = ImageFont.load_default(size=24)
    for k, glb in enumerate(glbs):
        img = Image.open(Path(glb).with_suffix(".png")).convert("RGB")
        x0, y0 = (k % cols) * size, (k // cols) * size
        sheet.paste(img, (x0, y0))
        ImageDraw.Draw(sheet).text((x0 + 12, y0 + 8), Path(glb).stem, fill=(235, 235, 235),
                                   font=font)
    # A palette keeps the sheet near 400 KB without visible banding.
    sheet.quantize(colors=160, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE).save(
        path, optimize=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--res", type=int, default=1024)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--presets", nargs="+", default=list(PRESETS))
    ap.add_argument("--meshes", nargs="+", default=["spot", "plate"])
    ap.add_argument("--blender", default=os.environ.get("CRACKBAKE_BLENDER_PYTHON"))
    ap.add_argument("--keep", type=Path, help="keep the run folders here")
    ap.add_argument("--json", type=Path, help="write the rows here")
    ap.add_argument("--picture", type=Path, help="render the spot GLBs in Blender into this PNG")
    ap.add_argument("--no-contrast", action="store_true", help="skip the groove renders")
    ap.add_argument("--picture-only", type=Path, metavar="ROWS_JSON",
                    help="only render --picture from the rows (--json) of an earlier --keep run")
    args = ap.parse_args()
    python = args.blender
    if args.no_contrast:
        args.blender = None
    if args.picture_only:
        rows = json.loads(args.picture_only.read_text())
        picture(rows, python, args.picture, args.keep or args.picture_only.parent)
        return
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.keep or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        meshes = {"spot": SPOT, "plate": plate_obj(folder / "plate.obj", 12, uv_margin=0.0)}
        rows = []
        for kind in args.meshes:
            for preset in args.presets:
                runs = [True] if preset == "glass" else [False]
                runs += [True] if preset == "concrete" else []
                for impact in runs:
                    rows.append(measure(meshes[kind], kind, preset, impact, args, folder))
                    print(json.dumps(rows[-1]), file=sys.stderr)
        print("| run | width / cell | crack area | width CV (solver) | width CV | mask mean | "
              "groove contrast before | after |")
        print("|---|---|---|---|---|---|---|---|")
        for r in rows:
            mm = f"{r['mask_mean']:.3f}" if "mask_mean" in r else "–"
            gc = f"{r['contrast']:+.3f}" if "contrast" in r else "–"
            gb = f"{r['contrast_before']:+.3f}" if "contrast_before" in r else "–"
            print(f"| {r['run']} | {r['width_cell']:.4f} | {r['area_share']:.4f} | "
                  f"{r['width_cv_solver']:.3f} | {r['width_cv']:.3f} | {mm} | {gb} | {gc} |")
        if args.json:
            args.json.write_text(json.dumps(rows, indent=1))
        if args.picture and python:
            picture(rows, python, args.picture, folder)


if __name__ == "__main__":
    main()
