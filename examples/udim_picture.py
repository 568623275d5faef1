"""The UDIM picture of docs/outputs.md: a textured 2 x 2-tile asset, its tiles, its USD in Blender.

Usage::

    python examples/udim_picture.py asset DIR
    crackbake DIR/plate.obj --preset concrete --sim-faces 6000 --res 512 --seed 2 \\
        --formats png,usd,preview --target blender -o OUT
    python tests/blender/import_usd.py OUT/plate.usda RENDER.png   # under Blender's Python
    python examples/udim_picture.py montage OUT RENDER.png PICTURE.png

``asset`` writes ``plate.obj``: four unit squares (32 x 32 quads each), square (i, j) with its
UVs inset on tile 1001 + i + 10 j, one material whose MTL names ``albedo.<UDIM>.png``, and a
generated 512² texture per tile (a hue, stripes or rings, blocky noise).  ``montage`` lays the
run's four ``plate_base_color.<UDIM>.png`` tiles out as they lie in UV space (1011 and 1012 on
top), labelled, beside the render.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

SQUARES = {1001: (0, 0), 1002: (1, 0), 1011: (0, 1), 1012: (1, 1)}
COLOURS = {1001: (176, 92, 60), 1002: (70, 110, 160), 1011: (96, 140, 80), 1012: (205, 180, 120)}


def asset(folder: Path, n: int = 32, inset: float = 0.05, res: int = 512) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    t = np.linspace(0, 1, n + 1)
    x, y = np.meshgrid(t, t, indexing="ij")
    pts = np.stack([x.ravel(), y.ravel()], 1)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    quad = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)]).reshape(-1, 3)
    lines = ["mtllib plate.mtl"]
    for i, j in SQUARES.values():
        lines += [f"v {p[0] + i:.6f} {p[1] + j:.6f} 0" for p in pts]
    for i, j in SQUARES.values():
        uv = np.array([i, j]) + inset + (1 - 2 * inset) * pts
        lines += [f"vt {u:.6f} {v:.6f}" for u, v in uv]
    lines.append("usemtl tiles")
    for k in range(len(SQUARES)):
        lines += ["f " + " ".join(f"{q}/{q}" for q in f) for f in quad + k * len(pts) + 1]
    (folder / "plate.obj").write_text("\n".join(lines) + "\n")
    (folder / "plate.mtl").write_text("newmtl tiles\nKd 1 1 1\nmap_Kd albedo.<UDIM>.png\n")
    rng = np.random.default_rng(3)
    yy, xx = np.mgrid[:res, :res] / res
    patterns = [np.sin(40 * xx), np.sin(40 * yy), np.sin(30 * (xx + yy)),
                np.sin(50 * np.hypot(xx - 0.5, yy - 0.5))]  # fmt: skip
    for (number, rgb), pattern in zip(COLOURS.items(), patterns, strict=True):
        noise = np.kron(rng.normal(0, 1, (res // 8, res // 8)), np.ones((8, 8)))
        img = np.asarray(rgb, float) * (1 + 0.12 * pattern[..., None] + 0.05 * noise[..., None])
        Image.fromarray(np.clip(img, 0, 255).astype(np.uint8)).save(folder / f"albedo.{number}.png")


def montage(out: Path, render: str, picture: str, cell: int = 320) -> None:
    shot = Image.open(render).convert("RGB")
    size = (2 * cell + 16 + shot.width, max(2 * cell, shot.height))
    canvas = Image.new("RGB", size, (40, 40, 44))
    draw = ImageDraw.Draw(canvas)
    for number, (col, row) in SQUARES.items():
        x0, y0 = col * cell, (1 - row) * cell  # v up: the row of tiles 1011, 1012 on top
        tile = Image.open(out / f"plate_base_color.{number}.png").convert("RGB")
        canvas.paste(tile.resize((cell - 4, cell - 4), Image.Resampling.LANCZOS), (x0 + 2, y0 + 2))
        draw.rectangle([x0 + 6, y0 + 6, x0 + 66, y0 + 24], fill=(0, 0, 0))
        draw.text((x0 + 10, y0 + 9), str(number), fill=(255, 255, 255))
    canvas.paste(shot, (2 * cell + 16, 0))
    canvas.quantize(256, Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE).save(
        picture, optimize=True)


if __name__ == "__main__":
    if sys.argv[1:2] == ["asset"]:
        asset(Path(sys.argv[2]))
    elif sys.argv[1:2] == ["montage"]:
        montage(Path(sys.argv[2]), sys.argv[3], sys.argv[4])
    else:
        sys.exit(__doc__)
