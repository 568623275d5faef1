"""Compare the EXR writers crackbake could use on a realistic bake.

Writes a single-part scanline EXR of 6 half + 5 float channels (sparse crack maps and smooth
stress fields) with the OpenEXR Python bindings and with OpenImageIO, at 2048² and 4096², and
prints write time and file size.  OpenImageIO takes one interleaved buffer, so its time is split
into ``prep`` (building that buffer from the planes) and ``write``; OpenEXR takes the planes as
they are.  Also times PNG writing (OIIO and Pillow, 8 and 16 bit) at the largest size.

Usage::

    python benchmarks/bench_exr.py [--sizes 2048 4096] [--repeat 2] [--threads 1 2 4]
                                   [--compression zip] [--no-png]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import OpenEXR
import OpenImageIO as oiio

NORMAL = ("crack.normal.NX", "crack.normal.NY", "crack.normal.NZ")
HALF = ("crack.mask.V", "crack.width.V", "crack.time.V", *NORMAL)
FLOAT = ("crack.depth.V", "crack.distance.V", "stress.xx.V", "stress.xy.V", "stress.yy.V")

COMPRESSION = {
    "none": OpenEXR.NO_COMPRESSION,
    "zip": OpenEXR.ZIP_COMPRESSION,
    "zips": OpenEXR.ZIPS_COMPRESSION,
    "piz": OpenEXR.PIZ_COMPRESSION,
    "zstd": OpenEXR.ZSTD_COMPRESSION,
}


def _crack_lines(size: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Random-walk polylines rasterised as points: returns (mask, time) float32 (size, size)."""
    mask = np.zeros((size, size), np.float32)
    time_ = np.zeros((size, size), np.float32)
    n_cracks = 60
    steps = size  # each crack about one image width long
    for _ in range(n_cracks):
        start = rng.uniform(0, size, 2)
        heading = rng.uniform(0, 2 * np.pi) + np.cumsum(rng.normal(0, 0.05, steps))
        xy = start + np.cumsum(np.stack([np.cos(heading), np.sin(heading)], 1) * 0.7, axis=0)
        ij = np.round(xy).astype(np.int64)
        keep = np.all((ij >= 0) & (ij < size), axis=1)
        ij = ij[keep]
        mask[ij[:, 1], ij[:, 0]] = 1.0
        time_[ij[:, 1], ij[:, 0]] = np.linspace(0, 1, steps, dtype=np.float32)[keep]
    # Soft shoulders a few texels wide, like the analytic anti-aliasing of the bake.
    soft = mask.copy()
    for d in (1, 2, 3):
        fall = 1.0 - d / 4.0
        for axis in (0, 1):
            for s in (d, -d):
                np.maximum(soft, np.roll(mask, s, axis=axis) * fall, out=soft)
    return soft, time_


def make_channels(size: int, seed: int = 0) -> dict[str, np.ndarray]:
    """6 half channels (sparse crack data) + 5 float channels (depth, distance, smooth stress)."""
    rng = np.random.default_rng(seed)
    mask, time_ = _crack_lines(size, rng)
    gy, gx = np.gradient(mask)
    nx = np.clip(-gx, -0.9, 0.9)
    ny = np.clip(gy, -0.9, 0.9)
    nz = np.sqrt(np.maximum(1.0 - nx * nx - ny * ny, 0.0))
    y, x = np.mgrid[0:size, 0:size].astype(np.float32) / size
    impacts = rng.uniform(0.2, 0.8, (3, 2))
    r = np.min([np.hypot(x - a, y - b) for a, b in impacts], axis=0)
    stress = 1e6 / (r + 0.05)
    chans = {
        "crack.mask.V": mask,
        "crack.width.V": mask * np.float32(0.002),
        "crack.time.V": time_,
        "crack.normal.NX": nx,
        "crack.normal.NY": ny,
        "crack.normal.NZ": nz,
        "crack.depth.V": mask * np.float32(0.01) * (1 + 0.3 * np.sin(40 * x)),
        "crack.distance.V": np.minimum(r, 0.3) * np.float32(2.5),
        "stress.xx.V": stress * np.cos(6 * x + 1) * np.sin(5 * y),
        "stress.xy.V": stress * 0.3 * np.sin(7 * x * y),
        "stress.yy.V": stress * np.cos(4 * y - 2 * x),
    }
    return {
        k: np.ascontiguousarray(v, np.float16 if k in HALF else np.float32)
        for k, v in chans.items()
    }


def write_openexr(path: str, chans: dict[str, np.ndarray], compression: str, threads: int) -> float:
    hdr = {"compression": COMPRESSION[compression], "type": OpenEXR.scanlineimage}
    t = time.perf_counter()
    # File() replaces the dict's arrays with Channel objects: give it a copy.
    OpenEXR.File(hdr, dict(chans), num_threads=threads).write(path)
    return time.perf_counter() - t


def write_oiio(
    path: str, chans: dict[str, np.ndarray], compression: str, threads: int
) -> tuple[float, float]:
    names = list(chans)
    t0 = time.perf_counter()
    h, w = next(iter(chans.values())).shape
    buf = np.empty((h, w, len(names)), np.float32)
    for i, n in enumerate(names):
        buf[:, :, i] = chans[n]
    t1 = time.perf_counter()
    oiio.attribute("exr_threads", threads)
    spec = oiio.ImageSpec(w, h, len(names), "float")
    spec.channelnames = tuple(names)
    spec.channelformats = tuple(
        oiio.TypeDesc("half" if chans[n].dtype == np.float16 else "float") for n in names
    )
    spec.attribute("compression", compression)
    out = oiio.ImageOutput.create(path)
    if not out.open(path, spec):
        raise RuntimeError(oiio.geterror())
    out.write_image(buf)
    out.close()
    return t1 - t0, time.perf_counter() - t1


def _best(fn: Callable[[], object], repeat: int) -> tuple[object, ...]:
    runs = [fn() for _ in range(repeat)]
    if isinstance(runs[0], tuple):
        return min(runs, key=sum)
    return (min(runs),)


def bench_exr(sizes, repeat, threads, compression, tmp: Path) -> None:
    print(f"EXR, 6 half + 5 float channels, {compression}, best of {repeat}; {os.cpu_count()} CPUs")
    print(
        f"{'library':<10}{'size':>6}{'threads':>8}{'prep s':>8}{'write s':>9}{'total s':>9}"
        f"{'MiB':>8}"
    )
    for size in sizes:
        chans = make_channels(size)
        for n in threads:
            p = str(tmp / f"exr_{size}.exr")
            (w,) = _best(lambda p=p, n=n, c=chans: write_openexr(p, c, compression, n), repeat)
            mib = os.path.getsize(p) / 2**20
            print(f"{'OpenEXR':<10}{size:>6}{n:>8}{0.0:>8.2f}{w:>9.2f}{w:>9.2f}{mib:>8.1f}")
            p = str(tmp / f"oiio_{size}.exr")
            prep, w = _best(lambda p=p, n=n, c=chans: write_oiio(p, c, compression, n), repeat)
            mib = os.path.getsize(p) / 2**20
            print(f"{'OIIO':<10}{size:>6}{n:>8}{prep:>8.2f}{w:>9.2f}{prep + w:>9.2f}{mib:>8.1f}")
        del chans


def bench_png(size: int, repeat: int, tmp: Path) -> None:
    from PIL import Image

    chans = make_channels(size)
    rgb = np.stack([chans[n] for n in NORMAL], -1)
    rgb = rgb.astype(np.float32) * 0.5 + 0.5
    mask = chans["crack.mask.V"].astype(np.float32)
    print(f"\nPNG at {size}², zlib level 6 unless noted, best of {repeat} (quantise + write)")
    print(f"{'writer':<30}{'image':<8}{'s':>7}{'MiB':>8}")

    def oiio_png(img, bits, level=None):
        def run():
            t = time.perf_counter()
            c = 1 if img.ndim == 2 else img.shape[2]
            spec = oiio.ImageSpec(size, size, c, "uint8" if bits == 8 else "uint16")
            if level is not None:
                spec.attribute("png:compressionLevel", level)
            out = oiio.ImageOutput.create(p)
            out.open(p, spec)
            # OIIO's Python write_image misreads 2-D arrays: always give it (H, W, C).
            out.write_image(img if img.ndim == 3 else img[:, :, None])
            out.close()
            return time.perf_counter() - t

        return run

    def pil_png(img, level=6):
        def run():
            t = time.perf_counter()
            q = (np.clip(img, 0, 1) * 255 + 0.5).astype(np.uint8)
            Image.fromarray(q).save(p, compress_level=level)
            return time.perf_counter() - t

        return run

    p = str(tmp / "x.png")
    for label, img in (("mask", mask), ("normal", rgb)):
        for wname, fn in (
            ("OIIO 8-bit", oiio_png(img, 8)),
            ("OIIO 8-bit level 1", oiio_png(img, 8, 1)),
            ("Pillow 8-bit", pil_png(img)),
            ("Pillow 8-bit level 1", pil_png(img, 1)),
            ("OIIO 16-bit", oiio_png(img, 16)),
            ("OIIO 16-bit level 1", oiio_png(img, 16, 1)),
        ):
            (s,) = _best(fn, repeat)
            print(f"{wname:<30}{label:<8}{s:>7.2f}{os.path.getsize(p) / 2**20:>8.1f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[2048, 4096])
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--threads", type=int, nargs="+", default=[2])
    ap.add_argument("--compression", default="zip", choices=sorted(COMPRESSION))
    ap.add_argument("--no-png", action="store_true")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        bench_exr(args.sizes, args.repeat, args.threads, args.compression, tmp)
        if not args.no_png:
            bench_png(max(args.sizes), args.repeat, tmp)


if __name__ == "__main__":
    main()
