"""Picture of a run's decal placed on its mesh by the transform written in decals.json.

Usage: python examples/decal_picture.py MESH OUT_DIR PICTURE.png [DECAL_INDEX]

Left: the decal's alpha applied back onto the mesh's UV layout through its written matrix
(crackbake.decals.apply, what an engine's decal projector does), dark red over the tinted
footprint.  Right: the run's UV bake (``<stem>_mask.png``, the gltf target's mask) in blue, from
the same camera, looking down the projector's axis from a three-quarter angle.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
from PIL import Image

from crackbake.bake.context import create_context
from crackbake.bake.preview import render_preview
from crackbake.decals.apply import apply_decal, uv_surface
from crackbake.io.mesh import load_mesh


def main(mesh_path: str, out_dir: str, picture: str, index: int = 0, res: int = 4096) -> None:
    mesh = load_mesh(mesh_path)
    out = Path(out_dir)
    entry = json.loads((out / "decals.json").read_text())["decals"][index]
    alpha = np.asarray(Image.open(out / entry["files"]["alpha"]), np.float64) / 255
    ctx = create_context()
    try:
        pts, face = uv_surface(mesh.vertices, mesh.faces, mesh.uv, res, ctx=ctx)
        value, covered = apply_decal(pts, face, mesh.vertices, mesh.faces, entry, alpha)
        colour = np.full((res, res, 3), 170.0)
        colour[covered] = [200, 200, 215]  # the projector's footprint, tinted
        colour += (np.array([120.0, 10, 10]) - colour) * value[..., None]
        mask = Image.open(out / f"{Path(mesh_path).stem}_mask.png").resize((res, res))
        uv_mask = np.asarray(mask, np.float64)[..., None] / 255
        uv_colour = np.full((res, res, 3), 170.0)
        uv_colour += (np.array([10.0, 30, 140]) - uv_colour) * uv_mask
        m = np.array(entry["matrix"])
        view = m[:3, 2] + 0.35 * m[:3, 0] + 0.25 * m[:3, 1]
        panels = [
            render_preview(mesh.vertices, mesh.faces, mesh.uv, mesh.normals,
                           c.astype(np.uint8), 768, view_dir=tuple(view), target=m[:3, 3],
                           distance=3.0 * entry["width"], ctx=ctx)
            for c in (colour, uv_colour)
        ]  # fmt: skip
        img = np.concatenate(panels, axis=1)
    finally:
        ctx.release()
    Image.fromarray(img).save(picture)


if __name__ == "__main__":
    main(*sys.argv[1:3], sys.argv[3], *(int(a) for a in sys.argv[4:]))
