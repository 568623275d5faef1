"""What each material preset grows, measured: the per-preset table of the README.

Run: ``python benchmarks/bench_presets.py [--res 2048] [--presets crackle glaze ...]
[--picture docs/presets.png] [--keep DIR]``.  Each preset runs the ``crackbake`` command (default
seed, default resolution, PNG maps and ``preview.png``) on ``examples/spot.obj`` and on a flat
1 x 1 plate (2 x 12^2 triangles, UVs = xy); the measures come from its ``cracks.json``
(:mod:`crackbake.metrics.cells`).  Prints a markdown table: crack polylines, total length,
mean polyline length, mean cell area and cell count, mean width (the physical
``crack.width``), straightness (geodesic chord / arc between junctions), mean T-junction stem
angle, the 8-bit mask's largest value, and wall seconds of the run (solve + bake + write, one
process).  Lengths are in mesh units: spot's bounding-box diagonal is 2.59, the plate's 1.41.
``--picture`` composes the ``preview.png`` of each spot run into one labelled panel per preset.
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
from crackbake.metrics.cells import network_stats
from crackbake.precompile import plate_obj

ROOT = Path(__file__).resolve().parents[1]
SPOT = ROOT / "examples" / "spot.obj"
PRESETS = ("glass", "crackle", "glaze", "mud", "concrete", "ice")
#: Impact of the glass runs: spot's flank (the README's example) and the plate's centre.
IMPACT = {"spot": "0.334,0.044,0.287", "plate": "0.5,0.5,0"}


def run(mesh: Path, preset: str, res: int, out: Path, seed: int, impact: str) -> float:
    """One ``crackbake`` run; its wall seconds."""
    cmd = [sys.executable, "-m", "crackbake", str(mesh), "--preset", preset, "--res", str(res),
           "--formats", "png,preview", "--seed", str(seed), "-o", str(out), "-q"]
    if preset == "glass":
        cmd += ["--impact", impact]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if proc.returncode != 0:
        raise RuntimeError(f"{preset} on {mesh.name} failed: {proc.stderr.strip()[-400:]}")
    return time.perf_counter() - t0


def measure(mesh: Path, preset: str, res: int, folder: Path, seed: int, kind: str) -> dict:
    out = folder / f"{kind}_{preset}"
    secs = run(mesh, preset, res, out, seed, IMPACT[kind])
    cracks = json.loads((out / "cracks.json").read_text())["cracks"]
    surf = load_mesh(mesh)
    st = network_stats([np.asarray(c["points"]) for c in cracks],
                       [np.asarray(c["width"]) for c in cracks], surf.vertices, surf.faces,
                       [np.asarray(c["faces"]) for c in cracks])
    row = st.to_dict()
    row.update(mesh=kind, preset=preset, seconds=secs, out=str(out))
    mask = np.asarray(Image.open(out / f"{mesh.stem}_mask.png"))
    mask = mask if mask.ndim == 2 else mask[..., 0]
    row["mask_max"] = int(mask.max())
    row["mask_mean"] = float(mask.mean())
    return row


def table(rows: list[dict]) -> str:
    head = ("| mesh | preset | cracks | length | mean length | mean cell area | cells | "
            "mean width | straightness | stem angle | mask max | s |")
    lines = [head, "|" + "---|" * 12]
    for r in rows:
        lines.append(
            f"| {r['mesh']} | {r['preset']} | {r['cracks']} | {r['length']:.2f} | "
            f"{r['length'] / max(r['cracks'], 1):.3f} | "
            f"{r['mean_cell_area']:.2e} | {r['cells']} | {r['mean_width']:.2e} | "
            f"{r['straightness']:.3f} | {r['stem_angle']:.0f}° | {r['mask_max']} | "
            f"{r['seconds']:.0f} |"
        )
    return "\n".join(lines)


def picture(rows: list[dict], path: Path, panel: int = 420, cols: int = 3) -> None:
    """One labelled panel per preset from the spot runs' ``preview.png`` (cropped to the mesh)."""
    spot = [r for r in rows if r["mesh"] == "spot"]
    n_rows = (len(spot) + cols - 1) // cols
    sheet = Image.new("RGB", (cols * panel, n_rows * panel), (41, 42, 50))
    font = ImageFont.load_default(size=26)
    for k, r in enumerate(spot):
        img = Image.open(Path(r["out"]) / "preview.png").convert("RGB")
        a = np.asarray(img).astype(int)
        fg = np.abs(a - a[0, 0]).sum(axis=2) > 12  # the background is flat
        ys, xs = np.nonzero(fg)
        if len(ys):
            img = img.crop((xs.min(), ys.min(), xs.max() + 1, ys.max() + 1))
        img.thumbnail((panel - 16, panel - 16), Image.LANCZOS)
        x0, y0 = (k % cols) * panel, (k // cols) * panel
        sheet.paste(img, (x0 + (panel - img.width) // 2, y0 + (panel - img.height) // 2))
        ImageDraw.Draw(sheet).text((x0 + 12, y0 + 8), r["preset"], fill=(235, 235, 235),
                                   font=font)
    # A palette keeps the grey renders under ~300 KB without visible banding.
    sheet.quantize(colors=96, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE).save(
        path, optimize=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--res", type=int, default=2048)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--presets", nargs="+", default=list(PRESETS))
    ap.add_argument("--meshes", nargs="+", default=["spot", "plate"])
    ap.add_argument("--picture", type=Path, help="write the spot panels here (PNG)")
    ap.add_argument("--keep", type=Path, help="keep the run folders here")
    ap.add_argument("--json", type=Path, help="write the rows here")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.keep or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        meshes = {"spot": SPOT, "plate": plate_obj(folder / "plate.obj", 12, uv_margin=0.0)}
        rows = []
        for kind in args.meshes:
            for preset in args.presets:
                rows.append(measure(meshes[kind], preset, args.res, folder, args.seed, kind))
                print(f"  {kind} {preset}: {rows[-1]['seconds']:.0f} s", file=sys.stderr)
        print(table(rows))
        if args.json:
            args.json.write_text(json.dumps(rows, indent=1))
        if args.picture:
            picture(rows, args.picture)


if __name__ == "__main__":
    main()
