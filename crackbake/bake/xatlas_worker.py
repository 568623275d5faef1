"""Child-process entry point running xatlas: ``python -m crackbake.bake.xatlas_worker [IN OUT]``.

xatlas can segfault (regular closed meshes, upstream jpcy/xatlas#146) or run for minutes, and
either would take the calling process with it; :func:`crackbake.bake.uv.unwrap` therefore runs this
module in a child process with a time limit.  It imports only numpy and xatlas so the child
starts fast.

The child dies with its parent: on Linux it asks the kernel for SIGKILL when the parent exits
(``prctl(PR_SET_PDEATHSIG)``) before importing anything slow, and exits at once when the parent
is already gone.  Without file arguments it reads the input ``.npz`` from stdin and writes the
output ``.npz`` to stdout, so an unwrap leaves no temporary files anywhere, however it ends.

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

import os
import sys

# Environment variable naming the parent's pid, set by crackbake.bake.uv.unwrap.run_worker.
PARENT_ENV = "CRACKBAKE_XATLAS_PARENT"
_PR_SET_PDEATHSIG = 1


def die_with_parent() -> None:
    """SIGKILL this process when its parent exits (Linux); exit now if it already has.

    The parent's pid comes from :data:`PARENT_ENV`; comparing it with ``getppid()`` after the
    ``prctl`` call closes the race where the parent died before the request was made.
    """
    if sys.platform.startswith("linux"):
        import ctypes
        import signal

        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
        except (OSError, AttributeError):
            pass
    parent = os.environ.get(PARENT_ENV)
    if parent and parent.isdigit() and os.getppid() != int(parent):
        os._exit(3)


if __name__ == "__main__":
    die_with_parent()

import io  # noqa: E402  (after die_with_parent: the slow imports below run already guarded)

import numpy as np  # noqa: E402
import xatlas  # noqa: E402

# Repacks tried (each shrinks the scale by SHRINK) before giving up on one page.
MAX_ATTEMPTS = 12
SHRINK = 0.93


def _pack_options(res: int, padding: int, texels_per_unit: float):
    pack = xatlas.PackOptions()
    pack.resolution = int(res)
    pack.padding = int(padding)
    pack.bilinear = True
    # bruteForce ran for minutes on 20k faces at 4096 (measured); never use it.
    pack.bruteForce = False
    pack.texels_per_unit = float(texels_per_unit)
    return pack


def _repack(texels: np.ndarray, indices: np.ndarray, res: int, padding: int, scale: float):
    """Pack existing charts again at ``scale`` x their size: no chart computation (~20x faster)."""
    atlas = xatlas.Atlas()
    atlas.add_uv_mesh(texels.astype(np.float32), indices.astype(np.uint32))
    atlas.generate(xatlas.ChartOptions(), _pack_options(res, padding, scale))
    return atlas


def fit_one_page(
    vertices: np.ndarray, faces: np.ndarray, res: int, padding: int
) -> dict[str, np.ndarray]:
    """Unwrap and pack into one ``res`` x ``res`` page with square texels, as large as fits.

    ``resolution=res`` alone lets xatlas choose its own scale, which gives a page of w x h texels
    that is often not square, can exceed ``res``, or leaves much of it empty.  So the charts are
    computed once (the slow part: about 45 s for 100k faces) and then only *repacked* at the
    scale that fills the page, shrinking by 7 % per try until everything fits one page.
    """
    atlas = xatlas.Atlas()
    atlas.add_mesh(vertices, faces)
    atlas.generate(xatlas.ChartOptions(), _pack_options(res, padding, 0.0))
    vm1, ix1, uv1 = atlas[0]
    w1, h1 = int(atlas.width), int(atlas.height)
    tried = [(w1, h1, int(atlas.atlas_count))]
    texels = uv1.astype(np.float64) * np.array([w1, h1])
    chart_count = int(atlas.chart_count)
    tpu1 = float(atlas.texels_per_unit)
    fits = max(w1, h1) <= res and atlas.atlas_count == 1

    best = (vm1.astype(np.int64), ix1.astype(np.int64), texels, w1, h1) if fits else None
    scale = 0.99 * res / max(w1, h1)
    if not fits or scale > 1.05:  # does not fit, or wastes more than ~10 % of the page
        for _ in range(MAX_ATTEMPTS):
            packed = _repack(texels, ix1, res, padding, scale)
            w, h, pages = int(packed.width), int(packed.height), int(packed.atlas_count)
            tried.append((w, h, pages))
            if pages == 1 and max(w, h) <= res:
                vm2, ix2, uv2 = packed[0]
                best = (
                    vm1.astype(np.int64)[vm2.astype(np.int64)],
                    ix2.astype(np.int64),
                    uv2.astype(np.float64) * np.array([w, h]),
                    w,
                    h,
                )
                break
            scale *= SHRINK
    if best is None:
        raise RuntimeError(
            f"could not fit the charts into one {res}x{res} page after {len(tried)} tries "
            f"(last: {tried[-1][0]}x{tried[-1][1]}, {tried[-1][2]} pages)"
        )
    vmapping, indices, texels, width, height = best
    # Texel positions / res on both axes keep texels square.  The y axis is kept as is (no
    # flip): xatlas's texel y counts rows from 0 like GL's framebuffer rows (row 0 = v 0,
    # bottom) and its charts come in both orientations anyway, so reading y as v-up (OBJ) is as
    # valid as any and keeps chart texel alignment.
    uv = texels / res
    return {
        "vmapping": vmapping,
        "indices": indices,
        "uv": np.clip(uv, 0.0, 1.0),
        "width": np.int64(width),
        "height": np.int64(height),
        "atlas_count": np.int64(1),
        "chart_count": np.int64(chart_count),
        "utilization": np.float64(_utilization(uv, indices)),
        "texels_per_unit": np.float64(tpu1 * (width / w1 if w1 else 1.0)),
        "attempts": np.int64(len(tried)),
        "tried": np.asarray(tried, dtype=np.int64),
    }


def _utilization(uv: np.ndarray, faces: np.ndarray) -> float:
    """Fraction of the page covered by charts (sum of UV triangle areas)."""
    c = uv[faces]
    e1, e2 = c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]
    return float(0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum())


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) not in (0, 2):
        print("usage: python -m crackbake.bake.xatlas_worker [in.npz out.npz]", file=sys.stderr)
        return 2
    if args:
        source, sink = open(args[0], "rb"), open(args[1], "wb")
    else:
        # stdout carries the result: anything else printing there (a library) goes to stderr.
        sink = os.fdopen(os.dup(1), "wb")
        os.dup2(2, 1)
        source = io.BytesIO(sys.stdin.buffer.read())  # np.load needs a seekable file
    with source, np.load(source, allow_pickle=False) as data:
        vertices = np.ascontiguousarray(data["vertices"], dtype=np.float64)
        faces = np.ascontiguousarray(data["faces"], dtype=np.int64)
        res = int(data["res"])
        padding = int(data["padding"])
    result = fit_one_page(vertices, faces, res, padding)
    with sink:
        np.savez(sink, **result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
