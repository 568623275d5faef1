"""UDIM benchmark: N tiles against N times one tile (issue 23's floor: at most 1.1 x N x one).

A generated plate of N unit squares (an n x n quad grid each), square k's UVs inset on tile k
(1001, 1002, ...), and the same random crack network copied onto every square (about 1,000
segments a square), so every tile holds the same work.  One tile is the same square alone,
its UVs on 0-1 (the ordinary single-page path).  The distance clamp is fixed
(``MAX_DISTANCE``): the default, 2 % of the mesh diagonal, grows with the plate and with it
every texel's work (4 tiles at 1024: 19.6 s of bake with the default clamp, 13.5 s with the
fixed one), which is not the tiles' cost.  Each configuration runs the real pipeline
(``crackbake.pipeline.run`` with ``--cracks``) after a warm-up, ``--repeat`` times, the
configurations taking turns (round 1 runs 1, 2, 4, 8 tiles, then round 2 ...), so a change in
the machine's load falls on all of them alike; the table gives the medians of the ``bake``
stage (the GPU bake of every tile) and of ``write`` (every file of every tile, the GLB packing
included), their ratio to N x the one-tile time, and the ratio of the best runs (the least
disturbed by other work on a shared machine).  ``--texture``: the asset has its own base colour
(``albedo.<UDIM>.png``, one generated ``--res``² image per tile; ``albedo.png`` for one tile),
composited under the cracks of every tile.

Usage::

    python benchmarks/bench_udim.py [--res 1024] [--tiles 1 2 4 8] [--repeat 3]
                                    [--formats exr,png,glb] [--texture]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from crackbake.io.mesh import load_mesh  # noqa: E402
from crackbake.io.sidecar import write_sidecar  # noqa: E402
from crackbake.network import Crack, CrackNetwork, mesh_info  # noqa: E402
from crackbake.params import RunParams  # noqa: E402
from crackbake.pipeline import run  # noqa: E402

INSET = 0.05
#: Distance clamp, mesh units: 2 % of one square's diagonal.
MAX_DISTANCE = 0.028


def write_plate(path: Path, tiles: int, n: int = 48) -> None:
    """OBJ of ``tiles`` unit squares side by side in x, square k on UDIM tile 1001 + k (k < 10,
    then the next row); one square alone is on the 0-1 page."""
    t = np.linspace(0.0, 1.0, n + 1)
    x, y = np.meshgrid(t, t, indexing="ij")
    pts = np.stack([x.ravel(), y.ravel()], 1)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    quad = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)]).reshape(-1, 3)
    lines = []
    for k in range(tiles):
        lines += [f"v {p[0] + k:.6f} {p[1]:.6f} 0" for p in pts]
    for k in range(tiles):
        tu, tv = k % 10, k // 10
        lines += [f"vt {tu + INSET + (1 - 2 * INSET) * p[0]:.6f} "
                  f"{tv + INSET + (1 - 2 * INSET) * p[1]:.6f}" for p in pts]  # fmt: skip
    for k in range(tiles):
        for f in quad + k * len(pts) + 1:
            lines.append("f " + " ".join(f"{i}/{i}" for i in f))
    path.write_text("\n".join(lines) + "\n")


def write_network(mesh_path: Path, out: Path, tiles: int, cracks: int = 40, points: int = 26,
                  seed: int = 0) -> None:
    """The same random polylines on every square (``cracks`` x ``points - 1`` segments each)."""
    mesh = load_mesh(mesh_path)
    rng = np.random.default_rng(seed)
    walks = []
    for _ in range(cracks):
        start = rng.uniform(0.1, 0.9, 2)
        step = rng.normal(0, 0.02, (points, 2)).cumsum(0) + rng.normal(0, 0.015, 2) * np.arange(
            points)[:, None]  # fmt: skip
        walks.append(np.clip(start + step, 0.01, 0.99))
    centroids = mesh.vertices[mesh.faces].mean(axis=1)
    out_cracks = []
    for k in range(tiles):
        for w in walks:
            p = np.c_[w + [k, 0.0], np.zeros(points)]
            face = np.array([np.argmin(((centroids - q) ** 2).sum(1)) for q in p])
            out_cracks.append(Crack(id=len(out_cracks), points=p, faces=face,
                                    time=np.linspace(0, 1, points),
                                    width=np.full(points, 0.004), depth=np.full(points, 0.002)))
    write_sidecar(CrackNetwork(cracks=out_cracks, mesh=mesh_info(mesh)), out)


def write_textures(obj: Path, tiles: int, res: int) -> None:
    """An MTL naming ``albedo.<UDIM>.png`` (``albedo.png`` for one tile) and a noise texture
    per tile, and the ``mtllib``/``usemtl`` lines in ``obj``."""
    from PIL import Image

    rng = np.random.default_rng(1)
    one = tiles == 1
    name = "albedo.png" if one else "albedo.<UDIM>.png"
    (obj.parent / f"{obj.stem}.mtl").write_text(f"newmtl m\nmap_Kd {name}\n")
    obj.write_text(f"mtllib {obj.stem}.mtl\nusemtl m\n" + obj.read_text())
    for k in range(tiles):
        img = rng.integers(40, 220, (res, res, 3), dtype=np.uint8)
        number = 1001 + k % 10 + 10 * (k // 10)
        Image.fromarray(img).save(obj.parent / name.replace("<UDIM>", str(number)))


def prepare(folder: Path, tiles: int, res: int, formats: tuple[str, ...],
            texture: bool) -> dict:
    """The plate, its network and its run parameters; one warm-up run."""
    sub = folder / f"t{tiles}"
    sub.mkdir()
    obj = sub / f"plate{tiles}.obj"
    side = sub / f"plate{tiles}.json"
    write_plate(obj, tiles)
    write_network(obj, side, tiles)
    if texture:
        write_textures(obj, tiles, res)
    # A fixed distance clamp: the default (2 % of the diagonal) grows with the plate, and with
    # it the work per texel; the same clamp gives every tile the one-tile work.
    params = dict(mesh=obj, cracks=side, res=res, formats=formats, target="unreal",
                  max_distance=MAX_DISTANCE)
    run(RunParams(out=sub / "warm", **params))
    return params


def once(folder: Path, tiles: int, params: dict, r: int) -> tuple[float, float, float, bool]:
    """(bake, write, whole run) seconds of one run, and whether it was baked as UDIM tiles."""
    t = time.perf_counter()
    result = run(RunParams(out=folder / f"t{tiles}" / f"o{r}", **params))
    total = time.perf_counter() - t
    timings = result.manifest["timings_s"]
    return timings["bake"], timings["write"], total, bool(result.manifest["uv"].get("udim"))


def ratio(rows: list[dict], key: str, pick) -> dict[int, float]:
    one = next((r for r in rows if r["tiles"] == 1), None)
    if one is None:
        return {}
    return {r["tiles"]: pick(r[key]) / (r["tiles"] * pick(one[key])) for r in rows}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--res", type=int, default=1024)
    ap.add_argument("--tiles", type=int, nargs="+", default=[1, 2, 4, 8])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--formats", default="exr,png,glb")
    ap.add_argument("--texture", action="store_true")
    args = ap.parse_args()
    formats = tuple(args.formats.split(","))
    rows = {n: {"tiles": n, "bake": [], "write": [], "total": [], "udim": False}
            for n in args.tiles}
    with warnings.catch_warnings(), tempfile.TemporaryDirectory(prefix="bench_udim_") as tmp:
        warnings.simplefilter("ignore")
        folder = Path(tmp)
        params = {n: prepare(folder, n, args.res, formats, args.texture) for n in args.tiles}
        for r in range(args.repeat):  # the configurations take turns
            for n in args.tiles:
                bake, write, total, udim = once(folder, n, params[n], r)
                rows[n]["bake"].append(bake)
                rows[n]["write"].append(write)
                rows[n]["total"].append(total)
                rows[n]["udim"] = udim
    rows = list(rows.values())
    med = statistics.median
    rb, rw, rt = (ratio(rows, k, med) for k in ("bake", "write", "total"))
    bb = ratio(rows, "bake", min)
    print(f"res {args.res} per tile, formats {args.formats}, texture {args.texture}, "
          f"medians of {args.repeat} (configurations in turn)")
    print("| tiles | UDIM | bake s | bake / (N x one) | best bake / (N x one) | write s | "
          "write / (N x one) | run s | run / (N x one) |")
    print("|---:|:--:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        n = r["tiles"]

        def f(d, n=n):
            return f"{d[n]:.2f}" if n in d else "-"

        print(f"| {n} | {'yes' if r['udim'] else 'no'} | {med(r['bake']):.3f} | {f(rb)} | "
              f"{f(bb)} | {med(r['write']):.3f} | {f(rw)} | {med(r['total']):.2f} | {f(rt)} |")


if __name__ == "__main__":
    main()
