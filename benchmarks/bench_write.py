"""Write-stage benchmark (issue 25: the 13 default files at 4096² in ≤ 1.0 s): the stage as a
whole and every file of it.

``--maps readme`` (default) runs the README example in this process (``spot.obj --preset glass
--impact 0.334,0.044,0.287 --res 4096``, default formats), captures what the pipeline hands to
:func:`crackbake.exchange.bundle.write_outputs` (crack maps, stress maps, meshes, network) and
then writes that set ``--repeat`` times into fresh output stages, timed as the pipeline times its
``write`` stage (``write_outputs`` plus the files' SHA-256 records).  ``--maps random`` bakes
spot with a random network of about 1,000 segments at each ``--res`` instead (no stress file).

Two tables:

1. **per file** -- each file's job run alone, one after the other, on one thread (OpenEXR's
   worker threads off): wall and CPU seconds, bytes.  The CPU seconds are each job's own cost;
   their sum over the number of cores bounds the concurrent write from below.
2. **the stage** -- the real concurrent write: wall and CPU seconds (all threads, this
   process) of each repeat, first (first-use costs: the preview's shader, page faults), best
   and median of the rest, and the jobs' Gantt lines of the median repeat (start/end seconds
   from the stage's start; the critical path is the job that ends last).

On a busy machine the CPU figures are the steadier comparison (the write's CPU / cores is its
wall time on an idle one).  The numba cache must be warm (``python -m crackbake.precompile``).

``--writers crackbake bindings`` runs each repeat with crackbake's EXR encoder and with the
OpenEXR bindings (what wrote ZIP EXRs before it) in turn, so both see the same load;
``--writers crackbake nostats`` prices the ``crackbake:stats`` record (each plane's statistics
for ``crackbake inspect``, taken on the encoder's threads); ``--writers crackbake@6x4
crackbake@8x8`` compares the encoder pool's sizes (``WRITE_THREADS`` x ``EXR_THREADS``).

Usage::

    python benchmarks/bench_write.py [--maps readme|random] [--res 4096] [--repeat 5]
                                     [--writers crackbake nostats bindings]
                                     [--exr-compression zip]
                                     [--keep DIR] [--per-file-repeat 3] [--levels]
                                     [--save-set FILE | --load-set FILE]

``--levels`` adds a third table: each file's deflate at the zlib levels and strategies it could
use (size against CPU seconds; all lossless), the evidence for the levels the writers use.
``--save-set`` / ``--load-set`` pickle the captured maps, so that two source trees (``git
archive`` of the base commit, say) write the very same maps, run after run in turn.
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import re
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
IMPACT = "0.334,0.044,0.287"


def stand_in_tangents(uvm) -> np.ndarray:
    """(V, 4) per-vertex tangents from each face's UV gradient, Gram-Schmidt on the normal."""
    v, f, uv, n = uvm.vertices, uvm.faces, uvm.uv, uvm.normals
    e1, e2 = v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]
    d1, d2 = uv[f[:, 1]] - uv[f[:, 0]], uv[f[:, 2]] - uv[f[:, 0]]
    det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    det = np.where(np.abs(det) > 1e-20, det, 1e-20)
    t = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) / det[:, None]
    b = (e2 * d1[:, 0:1] - e1 * d2[:, 0:1]) / det[:, None]
    tv, bv = np.zeros_like(v), np.zeros_like(v)
    for k in range(3):
        np.add.at(tv, f[:, k], t)
        np.add.at(bv, f[:, k], b)
    tv -= n * (tv * n).sum(1, keepdims=True)
    tv /= np.maximum(np.linalg.norm(tv, axis=1, keepdims=True), 1e-12)
    w = np.where((np.cross(n, tv) * bv).sum(1) < 0, -1.0, 1.0)
    return np.column_stack([tv, w])


def stand_in_surface(maps):
    """Normal (res, res, 3) float32 and occlusion (res, res) float16 of the right types."""
    d = maps.depth / max(float(maps.depth.max()), 1e-30)
    gy, gx = np.gradient(d.astype(np.float32))
    k = np.float32(0.15 * maps.res / 64)
    n = np.stack([-gx * k, gy * k, np.ones_like(gx)], -1)  # row 0 = top: +v is -row
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    occ = (1.0 - 0.7 * maps.mask.astype(np.float32)).astype(np.float16)
    return n.astype(np.float32), occ


def random_set(res: int) -> dict:
    """write_outputs' arguments for spot with a random network baked at ``res`` (no stress)."""
    from bench_bake import random_network, spot_path

    from crackbake.bake.raster import bake_cracks
    from crackbake.bake.uv import prepare_uvs
    from crackbake.io.mesh import load_mesh
    from crackbake.network import segments
    from crackbake.params import RunParams

    mesh = load_mesh(spot_path())
    network = random_network(mesh)
    uvm = prepare_uvs(mesh, mode="keep", res=res, cache=False)
    try:
        from crackbake.bake.tangents import with_tangents

        uvm = with_tangents(uvm)
    except ImportError:
        uvm = replace(uvm, tangents=stand_in_tangents(uvm))
    try:
        maps = bake_cracks(uvm.vertices, uvm.faces, uvm.uv, segments(network), res,
                           tangents=uvm.tangents)  # fmt: skip
    except TypeError:
        maps = bake_cracks(uvm.vertices, uvm.faces, uvm.uv, segments(network), res)
    if maps.normal is None:
        maps.normal, maps.occlusion = stand_in_surface(maps)
    params = RunParams(mesh=Path(mesh.source), res=res)
    return {"stem": "spot", "params": params, "mesh": mesh, "uvmesh": uvm, "network": network,
            "maps": maps, "stress": None, "effective": None}  # fmt: skip


def readme_set(res: int) -> dict:
    """write_outputs' arguments of the README run at ``res``, captured from the pipeline."""
    import crackbake.exchange.bundle as bundle
    captured: dict = {}
    real = getattr(bundle, "Writer", None)
    if real is None:  # a tree before the early write: the pipeline calls write_outputs
        real_write = bundle.write_outputs

        def capture(stage, stem, params, mesh, uvmesh, network, maps, ctx=None, stress=None,
                    effective=None):  # fmt: skip
            captured.update(stem=stem, params=params, mesh=mesh, uvmesh=uvmesh,
                            network=network, maps=maps, stress=stress,
                            effective=effective)  # fmt: skip
            real_write(stage, stem, params, mesh, uvmesh, network, maps, ctx, stress, effective)

        patch, restore = ("write_outputs", capture), ("write_outputs", real_write)
    else:  # the pipeline starts a Writer before the stress bake and finishes it after

        class Capture(real):
            def __init__(self, stage, stem, params, mesh, uvmesh, network, maps, ctx=None,
                         effective=None, **later):  # fmt: skip
                # ``later``: arguments of newer trees (``closed``, the preview's surface test)
                captured.update(stem=stem, params=params, mesh=mesh, uvmesh=uvmesh,
                                network=network, maps=maps, effective=effective)  # fmt: skip
                super().__init__(stage, stem, params, mesh, uvmesh, network, maps, ctx,
                                 effective, **later)  # fmt: skip

            def finish(self, stress=None):
                captured["stress"] = stress
                super().finish(stress)

        patch, restore = ("Writer", Capture), ("Writer", real)

    out = Path(tempfile.mkdtemp(prefix="bench-write-")) / "run"
    argv = [str(ROOT / "examples" / "spot.obj"), "--preset", "glass", "--impact", IMPACT,
            "--res", str(res), "-o", str(out), "--quiet"]  # fmt: skip
    from crackbake.cli import main as command

    setattr(bundle, *patch)
    try:
        command(argv, standalone_mode=False)
    finally:
        setattr(bundle, *restore)
    manifest = json.loads((out / "manifest.json").read_text())
    captured["pipeline_write"] = manifest["timings_s"]["write"]
    return captured


class _Traced(ThreadPoolExecutor):
    """The write's pool, recording each job's name, start and end (seconds from ``t0``)."""

    t0 = 0.0
    lines: list = []

    def submit(self, fn, /, *args, **kwargs):
        name = _job_name(fn, args)

        def timed():
            t = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                _Traced.lines.append((name, t - _Traced.t0, time.perf_counter() - _Traced.t0))

        return super().submit(timed)


def _job_name(fn, args) -> str:
    if args and isinstance(args[0], Path | str):
        return Path(args[0]).name
    if getattr(fn, "__name__", "") == "_job" and len(args) >= 2:
        key, paths = args[0], args[1]
        return ", ".join(Path(p).name for p in paths) or f"{key[0]} {key[3]} (GLB)"
    return getattr(fn, "__name__", str(fn))


def _traced_main(module, name: str, label):
    """Wrap ``module.name`` (a main-thread step of the write) so it adds a Gantt line."""
    real = getattr(module, name)

    def timed(*args, **kwargs):
        t = time.perf_counter()
        try:
            return real(*args, **kwargs)
        finally:
            what = label(args) if callable(label) else label
            _Traced.lines.append((what, t - _Traced.t0, time.perf_counter() - _Traced.t0))

    setattr(module, name, timed)


def use_writer(name: str) -> None:
    """``crackbake``: ZIP/ZIPS EXRs by crackbake's encoder (the default); ``nostats``: the same
    without the ``crackbake:stats`` record (what the record costs the write); ``bindings``: by
    the OpenEXR bindings, as before it (the same pixels and header), for an A/B in one
    process.  A suffix ``@WxE`` sets the encoder pool's threads (``WRITE_THREADS``) and the
    EXR encoders' workers (``EXR_THREADS``) for that writer: ``crackbake@6x8``."""
    import OpenEXR

    import crackbake.exchange.bundle as b
    import crackbake.exchange.exrzip as ez

    if not hasattr(b, "_own_threads"):
        b._own_threads = (b.WRITE_THREADS, b.EXR_THREADS)
    name, _, pools = name.partition("@")
    b.WRITE_THREADS, b.EXR_THREADS = (tuple(int(n) for n in pools.split("x")) if pools
                                      else b._own_threads)  # fmt: skip

    if not hasattr(ez, "_own_write_scanline"):
        ez._own_write_scanline = ez.write_scanline

    def bindings(path, planes, attributes, compression="zip", threads=0, level=None):
        code = getattr(OpenEXR, f"{compression.upper()}_COMPRESSION")
        header = {"compression": code, "type": OpenEXR.scanlineimage, **attributes}
        OpenEXR.File(header, dict(planes)).write(str(path))

    def nostats(*args, **kwargs):
        return ez._own_write_scanline(*args, **kwargs, stats=False)

    ez.write_scanline = {"crackbake": ez._own_write_scanline, "nostats": nostats}.get(
        name, bindings)


def _writer(name: str) -> str:
    """A ``--writers`` entry, checked: a writer and an optional ``@WxE``."""
    writer, _, pools = name.partition("@")
    if writer not in ("crackbake", "nostats", "bindings") or (
            pools and not re.fullmatch(r"[1-9][0-9]*x[1-9][0-9]*", pools)):
        raise argparse.ArgumentTypeError(f"{name!r}: crackbake, nostats or bindings[@WxE]")
    return name


def per_file(s: dict, ctx, out: Path, compression: str,
             repeat: int = 1) -> list[tuple[str, float, float, int]]:  # fmt: skip
    """Each file's job alone, one after the other, on the calling thread; the least wall and
    CPU seconds of ``repeat`` runs (on a shared machine the least is the steadiest)."""
    import crackbake.exchange.bundle as b
    from crackbake import __version__
    from crackbake.exchange.exr import exr_threads
    from crackbake.exchange.layers import run_attributes
    from crackbake.exchange.materials import GLB_TEXTURE_MAX
    from crackbake.exchange.targets import TARGETS, normal_convention
    from crackbake.io.texture import base_color_texture
    from crackbake.transaction.stage import OutputStage

    params, maps, stem = s["params"], s["maps"], s["stem"]
    exr = {"compression": compression, "run": run_attributes(__version__, s["effective"])}
    rows = []

    def timed(label, fn, *args):
        best = (np.inf, np.inf)
        for _ in range(repeat):
            t, cpu = time.perf_counter(), time.process_time()
            value = fn(*args)
            wall, cpu = time.perf_counter() - t, time.process_time() - cpu
            best = (min(best[0], wall), min(best[1], cpu))
        rows.append([label, *best])
        return value

    with OutputStage(out) as stage, exr_threads(0), ThreadPoolExecutor(1) as pool:
        texture = timed("(asset texture)", base_color_texture, s["mesh"].source, maps.res,
                        params.allow_outside_textures)  # fmt: skip
        timed(f"{stem}_cracks.exr", b._write_exr, stage.path(f"{stem}_cracks.exr"), maps,
              params.float32, *exr.values())  # fmt: skip
        if s["stress"] is not None:
            timed(f"{stem}_stress.exr", b._write_stress_exr, stage.path(f"{stem}_stress.exr"),
                  s["stress"], *exr.values())  # fmt: skip
        enc = b._Encoder(pool, maps, texture)
        normal_y = normal_convention(params.target, params.normal_y)
        for f in TARGETS[params.target].files:
            ny = normal_y if f.content == "normal" else "gl"
            enc.want((f.content, f.bits, ny, maps.res), stage.path(f.name.format(stem=stem)))
        size = min(maps.res, GLB_TEXTURE_MAX)
        keys = {k: enc.want((k, 8, "gl", size)) for k in ("base_color", "normal", "orm")}
        encoded = {}
        for key, paths in enc.requests.items():
            label = ", ".join(Path(p).name for p in paths) or f"{key[0]} {key[3]} (GLB)"
            data = timed(label, enc._job, key, paths, True)
            encoded[key] = pool.submit(lambda d=data: d)
        timed("preview.png", b._write_preview, stage, s["mesh"], s["uvmesh"], s["network"],
              maps, texture, ctx, params.up)  # fmt: skip
        timed("cracks.json", b.write_sidecar, s["network"], stage.path("cracks.json"))
        timed("cracks.obj", b.write_obj, s["network"], stage.path("cracks.obj"))
        timed(f"{stem}.glb", b._write_glb, stage.path(f"{stem}.glb"), stem, s["uvmesh"], maps,
              encoded, keys)  # fmt: skip
        records = timed("(SHA-256 records)", stage.records)
    sizes = {r["name"]: r["bytes"] for r in records}
    for row in rows:
        row.append(sum(sizes.get(n.strip(), 0) for n in row[0].split(",")))
    return [tuple(r) for r in rows]


def levels(s: dict, repeat: int = 2) -> list[tuple[str, str, float, int]]:
    """Deflate settings per file: (file, setting, least CPU seconds of the deflate alone,
    bytes of the deflated data).  The EXRs' chunks (the transform done once beforehand) at
    zlib-ng levels 1-4 and 6 and ISA-L levels 0-2; each PNG's filtered scanlines with
    zlib-ng's Z_RLE (what :mod:`crackbake.exchange.pngenc` writes for the 8-bit maps; the
    level changes nothing), its default strategy at levels 1, 2, 3 and 6, and ISA-L level 1
    (the data map's).  Every setting is lossless: only size and time differ."""
    import zlib

    from zlib_ng import zlib_ng

    import crackbake.exchange.bundle as b
    from crackbake.exchange.exrzip import _predict_channel
    from crackbake.exchange.layers import crack_planes, stress_planes
    from crackbake.exchange.materials import GLB_TEXTURE_MAX
    from crackbake.exchange.pngenc import png_bytes
    from crackbake.exchange.targets import TARGETS, data16_filtered, normal_convention, pack
    from crackbake.io.texture import base_color_texture

    def best_cpu(fn):
        least, value = np.inf, None
        for _ in range(repeat):
            cpu = time.process_time()
            value = fn()
            least = min(least, time.process_time() - cpu)
        return least, value

    def deflate_all(chunks, level, strategy):
        def run():
            total = 0
            for c in chunks:
                z = zlib_ng.compressobj(level, zlib.DEFLATED, 15, 9, strategy)
                total += len(z.compress(c)) + len(z.flush())
            return total
        return run

    def isal_all(chunks, level):
        return lambda: sum(len(isal_zlib.compress(c, level)) for c in chunks)

    try:
        from isal import isal_zlib
    except ImportError:
        isal_zlib = None
    rows = []
    maps, params, stem = s["maps"], s["params"], s["stem"]
    exrs = [(f"{stem}_cracks.exr", crack_planes(maps.channels(), float32=params.float32))]
    if s["stress"] is not None:
        st = s["stress"]
        exrs.append((f"{stem}_stress.exr", stress_planes(st.fields(), units=st.units)))
    for name, planes in exrs:
        words = [np.ascontiguousarray(planes[n]).view(np.uint16).reshape(
            planes[n].shape[0], -1) for n in sorted(planes)]  # fmt: skip
        height, line = words[0].shape[0], 2 * sum(w.shape[1] for w in words)
        offsets = np.cumsum([0] + [w.shape[1] for w in words])
        chunks = []
        for y0 in range(0, height, 16):
            y1 = min(y0 + 16, height)
            out = np.empty((y1 - y0) * line, np.uint8)
            first_odd = int(words[-1][y1 - 1, -1]) & 255
            for c, w in enumerate(words):
                pred, shift = (words[c - 1], 0) if c else (words[-1], 1)
                _predict_channel(w, pred, shift, y0, y1, int(offsets[c]), line // 2,
                                 out.size // 2, first_odd, out)  # fmt: skip
            chunks.append(out)
        for level in (1, 2, 3, 4, 6):
            cpu, size = best_cpu(deflate_all(chunks, level, zlib.Z_DEFAULT_STRATEGY))
            rows.append((name, f"zlib-ng level {level}", cpu, size))
        for level in (0, 1, 2) if isal_zlib is not None else ():
            cpu, size = best_cpu(isal_all(chunks, level))
            rows.append((name, f"ISA-L level {level}", cpu, size))
    texture = base_color_texture(s["mesh"].source, maps.res, params.allow_outside_textures)
    enc = b._Encoder(None, maps, texture)
    normal_y = normal_convention(params.target, params.normal_y)
    files = [(f.name.format(stem=stem), f.content, f.bits,
              normal_y if f.content == "normal" else "gl") for f in TARGETS[params.target].files]
    if maps.res > GLB_TEXTURE_MAX:
        files += [(f"{c} {GLB_TEXTURE_MAX} (GLB)", c, 8, "gl") for c in ("base_color", "orm")]
    for name, content, bits, ny in files:
        filtered = data16_filtered(maps, bands=False) if (content, bits) == ("data", 16) else None
        if filtered is not None:
            data = filtered
        else:
            px = pack(content, maps, bits, ny, base=lambda: enc._base(maps, maps.res))
            blob = png_bytes(px, level=0)  # stored blocks: the filtered rows come back out
            data = np.frombuffer(zlib.decompress(blob[blob.index(b"IDAT") + 4:-16]), np.uint8)
        view = [memoryview(np.ascontiguousarray(data)).cast("B")]
        cpu, size = best_cpu(deflate_all(view, 1, zlib_ng.Z_RLE))
        rows.append((name, "zlib-ng Z_RLE", cpu, size))
        for level in (1, 2, 3, 6):
            cpu, size = best_cpu(deflate_all(view, level, zlib.Z_DEFAULT_STRATEGY))
            rows.append((name, f"zlib-ng level {level}", cpu, size))
        if isal_zlib is not None:
            cpu, size = best_cpu(isal_all(view, 1))
            rows.append((name, "ISA-L level 1", cpu, size))
    return rows


def whole(s: dict, ctx, repeat: int, keep: Path | None, writers: list[str]) -> dict:
    """The concurrent write ``repeat`` times per writer, the writers in turn within each
    repeat: writer -> (walls, cpus, gantt of each repeat, records)."""
    import crackbake.exchange.bundle as b
    from crackbake.transaction.stage import OutputStage

    b.ThreadPoolExecutor = _Traced
    _traced_main(b, "_write_preview", "preview.png (main thread)")
    _traced_main(b, "write_sidecar", "cracks.json (main thread)")
    _traced_main(b, "write_obj", "cracks.obj (main thread)")
    _traced_main(b, "_write_glb", lambda a: f"{Path(a[0]).name} (main thread, waits)")
    out = {w: ([], [], [], None) for w in writers}
    for i in range(repeat):
        for w in writers:
            use_writer(w)
            walls, cpus, gantts, _ = out[w]
            last = keep is not None and i == repeat - 1
            folder = keep / w if last else Path(tempfile.mkdtemp(prefix="bench-write-")) / "o"
            _Traced.lines = []
            with OutputStage(folder) as stage:
                _Traced.t0 = t = time.perf_counter()
                cpu = time.process_time()
                b.write_outputs(stage, s["stem"], s["params"], s["mesh"], s["uvmesh"],
                                s["network"], s["maps"], ctx, s["stress"],
                                s["effective"])  # fmt: skip
                records = stage.records()  # in the pipeline's write stage: the files' SHA-256
                walls.append(time.perf_counter() - t)
                cpus.append(time.process_time() - cpu)
                _Traced.lines.append(("(SHA-256 records)", walls[-1], walls[-1]))
                gantts.append(sorted(_Traced.lines, key=lambda x: x[1]))
                if last:
                    stage.commit()
            out[w] = (walls, cpus, gantts, records)
    use_writer("crackbake")
    return out


def main() -> None:
    from crackbake.bake.context import create_context

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--maps", choices=("readme", "random"), default="readme")
    ap.add_argument("--res", type=int, nargs="+", default=[4096])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--exr-compression", default=None,
                    help="override the run's EXR compression (both EXRs)")  # fmt: skip
    ap.add_argument("--no-per-file", action="store_true", help="only the concurrent write")
    ap.add_argument("--writers", nargs="+", default=["crackbake"], type=_writer,
                    help="crackbake, nostats or bindings, each with an optional @WxE: the "
                         "encoder pool's threads and the EXR workers (crackbake@6x8); run by "
                         "run in turn (nostats: crackbake's encoder without the crackbake:stats "
                         "record; bindings: the OpenEXR bindings, as before crackbake's "
                         "encoder)")  # fmt: skip
    ap.add_argument("--keep", type=Path, help="commit the last write into KEEP")
    ap.add_argument("--per-file-repeat", type=int, default=3,
                    help="runs of each job alone; the table keeps the least")  # fmt: skip
    ap.add_argument("--levels", action="store_true",
                    help="also a table of deflate levels and strategies per file")  # fmt: skip
    ap.add_argument("--save-set", type=Path,
                    help="pickle the captured maps into SAVE_SET (for --load-set)")  # fmt: skip
    ap.add_argument("--load-set", type=Path,
                    help="write the maps pickled by --save-set instead of running the "
                         "pipeline: time two source trees on the very same maps, each with "
                         "PYTHONPATH at its tree")  # fmt: skip
    args = ap.parse_args()
    ctx = create_context()
    summary = []
    for res in args.res:
        if args.load_set is not None:
            s = pickle.loads(args.load_set.read_bytes())
            res = s["maps"].res
        else:
            s = readme_set(res) if args.maps == "readme" else random_set(res)
        if args.save_set is not None:
            args.save_set.write_bytes(pickle.dumps(s, protocol=5))
        if args.exr_compression:
            s["params"] = replace(s["params"], exr_compression=args.exr_compression)
        compression = s["params"].exr_compression
        print(f"\n## {args.maps} maps, {res}², EXR {compression}, {os.cpu_count()} cores, "
              f"load {os.getloadavg()[0]:.1f}"
              + (f", the pipeline's own write {s['pipeline_write']:.2f} s"
                 if "pipeline_write" in s else ""))  # fmt: skip
        files = {}
        if not args.no_per_file:
            for w in args.writers:
                use_writer(w)
                out = Path(tempfile.mkdtemp(prefix="bench-write-")) / "alone"
                files[w] = per_file(s, ctx, out, compression, args.per_file_repeat)
            use_writer("crackbake")
            head = " | ".join(f"{w}: wall s / CPU s / MB" for w in args.writers)
            print(f"\n| file (job alone, one thread, least of {args.per_file_repeat}) | {head} |")
            print("|---|" + "---:|" * len(args.writers))
            names = [r[0] for r in files[args.writers[0]]]
            for k, name in enumerate([*names, "**sum**"]):
                cells = []
                for w in args.writers:
                    rows = files[w]
                    r = rows[k] if k < len(rows) else (
                        name, *(sum(x[j] for x in rows) for j in (1, 2, 3)))  # fmt: skip
                    cells.append(f"{r[1]:.3f} / {r[2]:.3f} / {r[3] / 1e6:.2f}")
                print(f"| {name} | {' | '.join(cells)} |")
        if args.levels:
            print("\n| file | deflate | CPU s (deflate alone) | MB |")
            print("|---|---|---:|---:|")
            for name, setting, cpu, size in levels(s):
                print(f"| {name} | {setting} | {cpu:.3f} | {size / 1e6:.3f} |")
        runs = whole(s, ctx, args.repeat, args.keep, args.writers)
        print("\n| write stage (concurrent) | first | best | median | CPU best / median |")
        print("|---|---:|---:|---:|---:|")
        for w, (walls, cpus, _gantts, records) in runs.items():
            rest = slice(1 if len(walls) > 1 else 0, None)
            med = float(np.median(walls[rest]))
            print(f"| {w}: {len(records)} files, {sum(r['bytes'] for r in records) / 1e6:.1f} MB "
                  f"| {walls[0]:.2f} | {min(walls[rest]):.2f} | {med:.2f} "
                  f"| {min(cpus[rest]):.2f} / {float(np.median(cpus[rest])):.2f} |")  # fmt: skip
        for w, (walls, cpus, gantts, _records) in runs.items():
            rest = slice(1 if len(walls) > 1 else 0, None)
            k = rest.start + int(np.argsort(walls[rest])[len(walls[rest]) // 2])
            print(f"\n{w}: jobs of the median repeat ({walls[k]:.2f} s; start -> end, s):")
            for name, t0, t1 in gantts[k]:
                print(f"  {t0:6.3f} -> {t1:6.3f}  {name}")
            summary.append({"maps": args.maps, "res": res, "compression": compression,
                            "writer": w, "walls": walls, "cpus": cpus,
                            "files": files.get(w, []), "load_avg": os.getloadavg()[0],
                            "cores": os.cpu_count()})  # fmt: skip
    ctx.release()
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
