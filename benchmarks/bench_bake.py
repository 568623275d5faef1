"""Bake benchmark: per-stage times and peak memory from mesh to written files.

For each mesh and resolution a fresh child process runs the real stages (load, UVs, render,
readback, dilation, EXR/PNG/GLB write) on a crack network of about 1,000 segments, so every row
pays first-run costs (shader JIT, page faults) as a one-shot CLI run does, and its peak RSS is
its own.  The EXR write is compared with a bare write of the same planes by OpenImageIO and by
the OpenEXR bindings.  Each row bakes twice: the plain maps, then the same maps plus the
depth-normal and occlusion maps (``bake_normals``: tangents given), so the two costs compare in one
process.

Tangents come from ``crackbake.bake.tangents.with_tangents`` (MikkTSpace) when present, else from
:func:`simple_tangents` here (per-vertex UV-derivative tangents; the same cost for the bake).

Meshes: spot (its own UVs; ../shared/meshes/spot.obj or examples/spot.obj) and a generated
100k-face bumpy torus (unwrapped with xatlas; cached after the first run).

Usage::

    python benchmarks/bench_bake.py [--res 1024 2048 4096 8192] [--mesh spot torus100k]
                                    [--markdown]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "meshes"


def spot_path() -> Path:
    shared = SHARED / "spot.obj"
    return shared if shared.exists() else ROOT / "examples" / "spot.obj"


def torus_100k(path: Path) -> Path:
    """A bumpy torus of 316 x 158 x 2 = 99,856 faces, written as OBJ without UVs."""
    if path.exists():
        return path
    n_u, n_v, big, small = 316, 158, 1.0, 0.35
    u = np.linspace(0, 2 * np.pi, n_u, endpoint=False)
    v = np.linspace(0, 2 * np.pi, n_v, endpoint=False)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    r = small * (1 + 0.04 * np.sin(7 * uu) * np.cos(5 * vv))  # bumps keep xatlas off its crash
    x = (big + r * np.cos(vv)) * np.cos(uu)
    y = (big + r * np.cos(vv)) * np.sin(uu)
    z = r * np.sin(vv)
    verts = np.stack([x, y, z], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(n_u), np.arange(n_v), indexing="ij")
    a = i * n_v + j
    b = ((i + 1) % n_u) * n_v + j
    c = ((i + 1) % n_u) * n_v + (j + 1) % n_v
    d = i * n_v + (j + 1) % n_v
    faces = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)]).reshape(-1, 3)
    with open(path, "w") as fh:
        fh.write("".join(f"v {p[0]:.7f} {p[1]:.7f} {p[2]:.7f}\n" for p in verts))
        fh.write("".join(f"f {t[0] + 1} {t[1] + 1} {t[2] + 1}\n" for t in faces))
    return path


def random_network(mesh, n_cracks: int = 20, steps: int = 50, seed: int = 0):
    """About n_cracks * steps segments walking over the surface (the demo generator's walker)."""
    sys.path.insert(0, str(ROOT / "examples"))
    from make_demo_cracks import Surface, arc01, walk

    from crackbake.network import Crack, CrackNetwork, mesh_info

    rng = np.random.default_rng(seed)
    surface = Surface(mesh)
    cracks = []
    step = 0.006 * mesh.diagonal
    starts = rng.choice(len(mesh.faces), n_cracks, replace=False)
    for k, f in enumerate(starts):
        start = mesh.vertices[mesh.faces[f]].mean(axis=0)
        p, fa = walk(surface, start, rng.normal(size=3), steps, step, rng)
        if len(p) < 2:
            continue
        w = 0.001 * mesh.diagonal * (1 - arc01(p)) ** 0.5 + 1e-5
        cracks.append(Crack(id=k, points=p, faces=fa, time=arc01(p), width=w, depth=0.5 * w))
    return CrackNetwork(cracks=cracks, mesh=mesh_info(mesh))


def simple_tangents(vertices, faces, uv, normals) -> np.ndarray:
    """(V, 4) per-vertex tangents: face UV derivatives summed per vertex, made orthogonal to the
    normal, w the bitangent sign (a stand-in for MikkTSpace when it is not importable)."""
    p0, p1, p2 = (vertices[faces[:, k]] for k in range(3))
    t0, t1, t2 = (uv[faces[:, k]] for k in range(3))
    e1, e2, q1, q2 = p1 - p0, p2 - p0, t1 - t0, t2 - t0
    det = q1[:, 0] * q2[:, 1] - q1[:, 1] * q2[:, 0]
    r = np.where(np.abs(det) > 1e-20, 1.0 / np.where(det == 0, 1, det), 0.0)[:, None]
    dpdu = (e1 * q2[:, 1:2] - e2 * q1[:, 1:2]) * r
    dpdv = (e2 * q1[:, 0:1] - e1 * q2[:, 0:1]) * r
    tan = np.zeros((len(vertices), 3))
    bit = np.zeros((len(vertices), 3))
    for k in range(3):
        np.add.at(tan, faces[:, k], dpdu)
        np.add.at(bit, faces[:, k], dpdv)
    tan -= normals * (tan * normals).sum(1, keepdims=True)
    length = np.linalg.norm(tan, axis=1, keepdims=True)
    tan = np.where(length > 0, tan / np.where(length > 0, length, 1), [1.0, 0.0, 0.0])
    w = np.where((np.cross(normals, tan) * bit).sum(1) < 0, -1.0, 1.0)
    return np.column_stack([tan, w])


def uvmesh_tangents(uvm):
    """(vertices, faces, uv, normals, tangents) to bake the normal map with."""
    try:
        from crackbake.bake.tangents import with_tangents
    except ImportError:
        tangents = simple_tangents(uvm.vertices, uvm.faces, uvm.uv, uvm.normals)
        return uvm.vertices, uvm.faces, uvm.uv, uvm.normals, tangents, "simple"
    t = with_tangents(uvm)
    return t.vertices, t.faces, t.uv, t.normals, t.tangents, "mikktspace"


def bare_exr_writes(planes: dict[str, np.ndarray], folder: Path) -> dict[str, float]:
    """Seconds for the plainest write of the same planes by each library (ZIP, same types)."""
    import OpenEXR
    import OpenImageIO as oiio

    out = {}
    t = time.perf_counter()
    OpenEXR.File(
        {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, dict(planes)
    ).write(str(folder / "bare_openexr.exr"))
    out["openexr"] = time.perf_counter() - t

    names = list(planes)
    h, w = next(iter(planes.values())).shape
    t = time.perf_counter()
    buf = np.empty((h, w, len(names)), np.float32)  # OIIO takes one interleaved buffer
    for k, n in enumerate(names):
        buf[..., k] = planes[n]
    spec = oiio.ImageSpec(w, h, len(names), "float")
    spec.channelnames = tuple(names)
    spec.channelformats = tuple(
        oiio.TypeDesc("half" if planes[n].dtype == np.float16 else "float") for n in names
    )
    spec.attribute("compression", "zip")
    o = oiio.ImageOutput.create(str(folder / "bare_oiio.exr"))
    o.open(str(folder / "bare_oiio.exr"), spec)
    o.write_image(buf)
    o.close()
    out["oiio"] = time.perf_counter() - t
    return out


def child(mesh_name: str, res: int) -> dict:
    from crackbake.bake.raster import bake_cracks
    from crackbake.bake.uv import prepare_uvs
    from crackbake.exchange import GLB_TEXTURE_MAX, base_color, write_exr, write_glb
    from crackbake.exchange.layers import crack_planes
    from crackbake.exchange.pngenc import png_bytes, write_bytes
    from crackbake.exchange.targets import quantise
    from crackbake.io.mesh import load_mesh
    from crackbake.network import segments

    row: dict = {"mesh": mesh_name, "res": res}
    path = spot_path() if mesh_name == "spot" else torus_100k(
        Path(tempfile.gettempdir()) / "crackbake_bench_torus100k.obj"
    )
    t = time.perf_counter()
    mesh = load_mesh(path)
    row["load"] = time.perf_counter() - t
    row["faces"] = len(mesh.faces)
    network = random_network(mesh)
    segs = segments(network)
    row["segments"] = len(segs.a)
    t = time.perf_counter()
    # No cache: the row shows what an unwrap costs (a cache hit takes a few ms).
    uvm = prepare_uvs(mesh, mode="keep" if mesh_name == "spot" else "unwrap", res=res, cache=False)
    row["uv"] = time.perf_counter() - t
    row["uv_method"] = uvm.method
    t = time.perf_counter()
    maps = bake_cracks(uvm.vertices, uvm.faces, uvm.uv, segs, res)
    row["bake"] = time.perf_counter() - t
    for k in ("candidates", "setup", "render", "readback", "dilate"):
        row[k] = maps.timings.get(k, 0.0)
    row["render+read+dilate"] = row["render"] + row["readback"] + row["dilate"]
    t = time.perf_counter()
    v, f, uv, n, tangents, row["tangents"] = uvmesh_tangents(uvm)
    row["tangent_s"] = time.perf_counter() - t
    t = time.perf_counter()
    nmaps = bake_cracks(v, f, uv, segs, res, normals=n, tangents=tangents)
    row["bake_normals"] = time.perf_counter() - t
    for k in ("setup", "render", "readback", "dilate"):
        row[f"{k}_normals"] = nmaps.timings.get(k, 0.0)
    row["normals"] = nmaps.timings["normals"]  # the compute pass over the crack texels
    row["render+read+dilate_normals"] = sum(nmaps.timings[k] for k in ("render", "readback",
                                                                         "dilate", "normals"))
    row["normal_vs_plain"] = row["render+read+dilate_normals"] / row["render+read+dilate"]
    del nmaps
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        planes = crack_planes(maps.channels(), float32=False)
        # Two alternating rounds, best of each: single writes vary by +-30 % on 2 busy cores.
        ours, bares = [], []
        for _ in range(2):
            t = time.perf_counter()
            write_exr(tmp / "out.exr", planes, {"crackbake:version": "bench"})
            ours.append(time.perf_counter() - t)
            bares.append(bare_exr_writes(planes, tmp))
        row["exr"] = min(ours)
        row["exr_MB"] = (tmp / "out.exr").stat().st_size / 1e6
        row["bare_openexr"] = min(b["openexr"] for b in bares)
        row["bare_oiio"] = min(b["oiio"] for b in bares)
        row["exr_vs_bare"] = row["exr"] / min(row["bare_openexr"], row["bare_oiio"])
        t = time.perf_counter()
        # the path real runs take: quantise, then the in-memory encoder
        write_bytes(tmp / "mask.png", png_bytes(quantise(maps.mask, 8)))
        scale = max(float(maps.depth.max()), 1e-30)
        write_bytes(tmp / "depth.png", png_bytes(quantise(maps.depth, 16, scale)))
        row["png"] = time.perf_counter() - t
        t = time.perf_counter()
        write_glb(tmp / "m.glb", uvm.vertices, uvm.faces, uvm.uv, uvm.normals,
                  base_color(maps.mask, GLB_TEXTURE_MAX))
        row["glb"] = time.perf_counter() - t
    row["peak_rss_GiB"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    return row


COLUMNS = [
    ("mesh", "{}"), ("faces", "{}"), ("res", "{}"), ("segments", "{}"), ("load", "{:.2f}"),
    ("uv", "{:.2f}"), ("render", "{:.2f}"), ("readback", "{:.2f}"), ("dilate", "{:.2f}"),
    ("render+read+dilate", "{:.2f}"), ("render+read+dilate_normals", "{:.2f}"),
    ("normal_vs_plain", "{:.2f}"), ("exr", "{:.2f}"), ("bare_openexr", "{:.2f}"),
    ("bare_oiio", "{:.2f}"), ("exr_vs_bare", "{:.2f}"), ("png", "{:.2f}"), ("glb", "{:.2f}"),
    ("peak_rss_GiB", "{:.2f}"),
]  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, nargs="+", default=[1024, 2048, 4096, 8192])
    ap.add_argument("--mesh", nargs="+", default=["spot", "torus100k"])
    ap.add_argument("--child", nargs=2, metavar=("MESH", "RES"), help=argparse.SUPPRESS)
    ap.add_argument("--json", type=Path, help="also write the rows to this JSON file")
    args = ap.parse_args()
    if args.child:
        print(json.dumps(child(args.child[0], int(args.child[1]))))
        return
    rows = []
    print("| " + " | ".join(c for c, _ in COLUMNS) + " |")
    print("|" + "---|" * len(COLUMNS))
    for mesh_name in args.mesh:
        for res in args.res:
            r = subprocess.run(
                [sys.executable, __file__, "--child", mesh_name, str(res)],
                capture_output=True, text=True, env={**os.environ, "PYTHONWARNINGS": "ignore"},
            )
            if r.returncode != 0:
                print(f"| {mesh_name} | failed at {res}: {r.stderr.strip().splitlines()[-1]} |")
                continue
            row = json.loads(r.stdout.strip().splitlines()[-1])
            rows.append(row)
            print("| " + " | ".join(f.format(row[c]) for c, f in COLUMNS) + " |", flush=True)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2))


if __name__ == "__main__":
    main()
