"""Child-process entry point running xatlas: ``python -m crackbake._xatlas_worker IN OUT``.

xatlas can segfault (regular closed meshes, upstream jpcy/xatlas#146) or run for minutes, and
either would take the calling process with it; :func:`crackbake.uv.unwrap` therefore runs this
module in a child process with a time limit.  It imports only numpy and xatlas so the child
starts fast.

Input arrays (``in.npz``): ``vertices`` (V, 3) float64, ``faces`` (F, 3) int64, ``res`` and
``padding`` (0-d ints).

Output arrays (``out.npz``): ``vmapping`` (V',) int64 into the input vertices, ``indices``
(F, 3) int64 (same face order and corner order as the input), ``uv`` (V', 2) float64 texel
position / ``res`` on both axes (one square page, square texels), ``width`` and ``height`` (the
page xatlas packed into, texels), ``atlas_count``, ``chart_count``, ``utilization``,
``texels_per_unit``, ``attempts`` (xatlas runs needed to fit one page) and ``tried`` (the
(width, height, atlas_count) of every run, (attempts, 3) int64).
"""

from __future__ import annotations

import sys

import numpy as np
import xatlas

# Most xatlas runs are needed when a fixed texels_per_unit still spills onto a second page;
# each retry shrinks by at least 10 %, so 10 runs reach 0.35 x the first scale.
MAX_ATTEMPTS = 10


def _generate(atlas, res: int, padding: int, texels_per_unit: float) -> None:
    chart = xatlas.ChartOptions()
    pack = xatlas.PackOptions()
    pack.resolution = int(res)
    pack.padding = int(padding)
    pack.bilinear = True
    # bruteForce ran for minutes on 20k faces at 4096 (shared/research/deps.md); never use it.
    pack.bruteForce = False
    pack.texels_per_unit = float(texels_per_unit)
    atlas.generate(chart, pack)


def fit_one_page(
    vertices: np.ndarray, faces: np.ndarray, res: int, padding: int
) -> dict[str, np.ndarray]:
    """Unwrap and pack into one ``res`` x ``res`` page with square texels.

    ``resolution=res`` alone lets xatlas choose its own scale, which gives a page of w x h texels
    that is often not square and can exceed ``res``; a fixed scale that is too large spills onto
    several pages.  So: run once with xatlas's own scale, and while the result does not fit one
    page, run again with the scale shrunk by the overflow (2 % margin, at least 10 % per retry
    once xatlas pins the page at ``res``).
    """
    atlas = xatlas.Atlas()
    atlas.add_mesh(vertices, faces)
    _generate(atlas, res, padding, 0.0)
    tried = [(atlas.width, atlas.height, atlas.atlas_count)]
    while max(atlas.width, atlas.height) > res or atlas.atlas_count > 1:
        if len(tried) >= MAX_ATTEMPTS:
            raise RuntimeError(
                f"could not fit the charts into one {res}x{res} page after {len(tried)} runs "
                f"(last: {atlas.width}x{atlas.height}, {atlas.atlas_count} pages)"
            )
        scale = min(0.98 * res / max(atlas.width, atlas.height), 0.9 if len(tried) > 1 else 0.98)
        _generate(atlas, res, padding, atlas.texels_per_unit * scale)
        tried.append((atlas.width, atlas.height, atlas.atlas_count))

    vmapping, indices, uv = atlas[0]
    page, _chart = atlas.get_mesh_vertex_assignment(0)
    if page.size and int(page.max()) != 0:
        raise RuntimeError("xatlas placed vertices on a second page")
    width, height = int(atlas.width), int(atlas.height)
    # xatlas-python returns texel position / (width, height) per axis; going back to texels and
    # dividing both by res keeps texels square.  The y axis is kept as is (no flip): xatlas's
    # texel y counts rows from 0 like GL's framebuffer rows (row 0 = v 0, bottom) and its charts
    # come in both orientations anyway, so reading y as v-up (OBJ) is as valid as any and keeps
    # chart texel alignment.
    uv = uv.astype(np.float64)
    uv[:, 0] *= width / res
    uv[:, 1] *= height / res
    return {
        "vmapping": vmapping.astype(np.int64),
        "indices": indices.astype(np.int64),
        "uv": np.clip(uv, 0.0, 1.0),
        "width": np.int64(width),
        "height": np.int64(height),
        "atlas_count": np.int64(atlas.atlas_count),
        "chart_count": np.int64(atlas.chart_count),
        "utilization": np.float64(np.asarray(atlas.utilization, dtype=np.float64).ravel()[0]),
        "texels_per_unit": np.float64(atlas.texels_per_unit),
        "attempts": np.int64(len(tried)),
        "tried": np.asarray(tried, dtype=np.int64),
    }


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 2:
        print("usage: python -m crackbake._xatlas_worker in.npz out.npz", file=sys.stderr)
        return 2
    with np.load(args[0]) as data:
        vertices = np.ascontiguousarray(data["vertices"], dtype=np.float64)
        faces = np.ascontiguousarray(data["faces"], dtype=np.int64)
        res = int(data["res"])
        padding = int(data["padding"])
    result = fit_one_page(vertices, faces, res, padding)
    with open(args[1], "wb") as fh:
        np.savez(fh, **result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
