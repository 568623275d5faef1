"""The bad-input catalogue: every input a user can get wrong, run as a real ``crackbake`` process.

Each case must exit with code 2, print exactly one line on stderr (``error: ...``, no traceback,
no numpy repr), and leave nothing behind: no output folder, no staging folder, no stray file.
The cases run concurrently in a module fixture (one process each, a few at a time); each case is
still its own test.  Most run in forks of one process that imported crackbake once
(tests/cli_forks.py: the same entry point, exit status and output as ``python -m crackbake``,
without its 2-3 CPU seconds of imports each); a few, listed in ``SUBPROCESS``, run as
``python -m crackbake`` in a fresh interpreter.
"""

from __future__ import annotations

import json
import os
import re
import resource
import shutil
import struct
import subprocess
import sys
import time
import zlib
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest
from cli_forks import run_commands

from crackbake.params import Impact

REPO = Path(__file__).resolve().parents[1]

# A 4 x 4-cell plate with UVs inside the unit square: solves in a fraction of a second.
N = 4
PLATE = "\n".join(
    [f"v {i / N:g} {j / N:g} {0.02 * ((i * 7 + j * 3) % 5):g}" for i in range(N + 1)
     for j in range(N + 1)]
    + [f"vt {0.05 + 0.9 * i / N:g} {0.05 + 0.9 * j / N:g}" for i in range(N + 1)
       for j in range(N + 1)]
    + [
        line
        for i in range(N)
        for j in range(N)
        for a, b in [(i * (N + 1) + j + 1, (i + 1) * (N + 1) + j + 1)]
        for line in (f"f {a}/{a} {b}/{b} {b + 1}/{b + 1}",
                     f"f {a}/{a} {b + 1}/{b + 1} {a + 1}/{a + 1}")
    ]
) + "\n"
TRI = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n"


def _sidecar(plate: Path) -> dict:
    """A valid one-crack sidecar for the plate (made in-process with the library)."""
    from crackbake.io.mesh import load_mesh
    from crackbake.io.sidecar import to_dict
    from crackbake.network import Crack, CrackNetwork, mesh_info

    mesh = load_mesh(plate)
    tri = mesh.vertices[mesh.faces[0]]
    pts = np.array([tri @ [0.6, 0.2, 0.2], tri @ [0.2, 0.6, 0.2]])
    crack = Crack(id=0, points=pts, faces=np.array([0, 0]), time=np.array([0.0, 1.0]),
                  width=np.array([0.01, 0.01]), depth=np.array([0.005, 0.005]))
    return to_dict(CrackNetwork(cracks=[crack], mesh=mesh_info(mesh)))


def png_header_only(width: int, height: int) -> bytes:
    """A PNG of a few dozen bytes whose header declares ``width`` x ``height`` RGB pixels (a
    decompression bomb's shape: the pixel data is a 16-byte stream)."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data)))

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr)
            + chunk(b"IDAT", zlib.compress(b"\0" * 16)) + chunk(b"IEND", b""))


def _nested(depth: int):
    value: object = 1
    for _ in range(depth):
        value = [value]
    return value


def _sidecar_variants(folder: Path, side: dict) -> None:
    """Sidecars that pass JSON decoding and then crashed (issue 19): one file per case."""
    def variant(name: str, change) -> None:
        bad = json.loads(json.dumps(side))
        change(bad)
        (folder / name).write_text(json.dumps(bad))

    crack = lambda d: d["cracks"][0]  # noqa: E731
    variant("id_huge.json", lambda d: crack(d).update(id=2**70))
    variant("id_minus1.json", lambda d: crack(d).update(id=-1))
    variant("id_2_24.json", lambda d: crack(d).update(id=2**24))
    variant("points_1e300.json", lambda d: crack(d)["points"][0].__setitem__(0, 1e300))
    variant("width_1e308.json", lambda d: crack(d)["width"].__setitem__(0, 1e308))
    variant("params_deep.json", lambda d: d.setdefault("params", {}).update(x=_nested(900)))
    variant("params_width.json", lambda d: d.setdefault("params", {}).update(crack_width=1e300))
    variant("impact_strength.json", lambda d: d.update(
        impacts=[{"point": [0.5, 0.5, 0.0], "radius": 0.1, "strength": 1e300}]))
    # Nested 100000 deep: the JSON decoder itself recursed past Python's limit.
    (folder / "deep.json").write_text(
        '{"format": "crackbake-cracks", "version": 1, "cracks": ' + "[" * 100_000
        + "]" * 100_000 + "}")


def _inputs(folder: Path) -> None:
    """Every input file the cases name, written into ``folder``."""
    (folder / "plate.obj").write_text(PLATE)
    side = _sidecar(folder / "plate.obj")
    (folder / "side.json").write_text(json.dumps(side))
    _sidecar_variants(folder, side)
    (folder / "bomb.png").write_bytes(png_header_only(50_000, 50_000))
    from PIL import Image

    rng = np.random.default_rng(0)
    Image.fromarray(rng.integers(0, 256, (64, 64, 3), dtype=np.uint8)).save(folder / "ok.png")
    data = (folder / "ok.png").read_bytes()
    (folder / "truncated.png").write_bytes(data[: len(data) // 2])
    (folder / "bomb20k.png").write_bytes(png_header_only(20_000, 20_000))
    for stem, image in (("bomb", "bomb20k.png"), ("trunc", "truncated.png")):
        (folder / f"{stem}.mtl").write_text(f"newmtl m\nmap_Kd {image}\n")
        (folder / f"{stem}_tex.obj").write_text(f"mtllib {stem}.mtl\nusemtl m\n" + PLATE)
    lines = PLATE.splitlines()
    first_face = next(i for i, line in enumerate(lines) if line.startswith("f "))
    corners = lines[first_face].split()
    corners[1] = corners[1].split("/")[0] + "/99"  # 25 vt lines: 99 is out of range
    (folder / "bad_vt.obj").write_text("\n".join(
        lines[:first_face] + [" ".join(corners)] + lines[first_face + 1:]) + "\n")
    first_vt = next(i for i, line in enumerate(lines) if line.startswith("vt "))
    (folder / "inf_uv.obj").write_text("\n".join(
        lines[:first_vt] + ["vt inf 0.5"] + lines[first_vt + 1:]) + "\n")
    bad = json.loads(json.dumps(side))
    bad["cracks"][0]["faces"][0] = True
    (folder / "bool_face.json").write_text(json.dumps(bad))
    bad = json.loads(json.dumps(side))
    bad["cracks"][0]["width"][0] = -5.0
    (folder / "neg_width.json").write_text(json.dumps(bad))
    bad = json.loads(json.dumps(side))
    bad["mesh"]["faces"] = 7
    (folder / "other_mesh.json").write_text(json.dumps(bad))
    (folder / "corrupt.json").write_text('{"format": "crackbake-cracks", ')
    (folder / "notes.txt").write_text("hello")
    (folder / "empty.obj").write_bytes(b"")
    (folder / "empty.ply").write_bytes(b"")
    (folder / "empty.glb").write_bytes(b"")
    (folder / "points.obj").write_text(TRI)
    (folder / "words.obj").write_text("hello world\nthis is not a mesh\n")
    (folder / "zero_index.obj").write_text(TRI + "f 0 1 2\n")
    (folder / "missing_vertex.obj").write_text(TRI + "f 1 2 3\nf 2 4 9\n")
    (folder / "short_vertex.obj").write_text("v 0 0 0\nv 1 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\n")
    (folder / "nan.obj").write_text("v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n")
    (folder / "flat.obj").write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n")
    (folder / "letters.obj").write_text(TRI + "f 1 x 3\n")
    (folder / "garbage.ply").write_bytes(b"ply\nformat binary_little_endian 1.0\n\x00\xff" * 3)
    (folder / "garbage.glb").write_bytes(b"glTF\x02\x00\x00\x00" + bytes(range(40)))
    (folder / "garbage.stl").write_bytes(b"solid x\nfacet normal 0 0 nan\nendsolid\n")
    (folder / "noext").write_text(PLATE)
    (folder / "not_an_image.png").write_text("not a png")
    (folder / "maps").mkdir()
    (folder / "album").mkdir()
    (folder / "album" / "photo.jpg").write_bytes(b"\xff\xd8 a photo")
    _exr_inputs(folder)
    _gltf_inputs(folder)


def _exr_inputs(folder: Path) -> None:
    """good.exr, trunc.exr (its first half) and huge.exr (a 60001^2 data window declared)."""
    import struct

    from crackbake.exchange.exr import write_exr

    ramp = np.linspace(0, 1, 64 * 64, dtype=np.float32).reshape(64, 64)
    write_exr(folder / "good.exr", {"R": ramp, "G": ramp})
    data = (folder / "good.exr").read_bytes()
    (folder / "trunc.exr").write_bytes(data[: len(data) // 2])
    at = data.index(b"dataWindow\0box2i\0") + len(b"dataWindow\0box2i\0") + 4  # after the size
    assert struct.unpack_from("<4i", data, at) == (0, 0, 63, 63)
    huge = bytearray(data)
    struct.pack_into("<4i", huge, at, 0, 0, 60000, 60000)
    (folder / "huge.exr").write_bytes(bytes(huge))


def _gltf_inputs(folder: Path) -> None:
    """The plate as glTF with its first buffer renamed: zerobuf.gltf names zero.bin (a link to
    /dev/zero, made per case), upbuf.gltf a real buffer outside its folder (a name not beside
    the mesh: trimesh's resolver also tries the bare file name there)."""
    import trimesh

    files = trimesh.load(folder / "plate.obj", process=False).export(file_type="gltf")
    doc = json.loads(files.pop("model.gltf"))
    for name, blob in files.items():
        (folder / name).write_bytes(blob)
    (folder / "sub").mkdir()
    (folder / "sub" / "outside.bin").write_bytes(files[doc["buffers"][0]["uri"]])
    for stem, uri in (("zerobuf", "zero.bin"), ("upbuf", "../_inputs/sub/outside.bin")):
        doc["buffers"][0]["uri"] = uri
        (folder / f"{stem}.gltf").write_text(json.dumps(doc))


def _specials(folder: Path) -> None:
    """FIFOs and links to /dev/zero, made in each case's folder (copying them would block)."""
    for name in ("pipe.obj", "pipe.json", "pipe.png", "pipe.exr"):
        os.mkfifo(folder / name)
    for name in ("zero.obj", "zero.json", "zero.bin"):
        (folder / name).symlink_to("/dev/zero")


IMPACT = "0.5,0.5,0.05"
# (case id, arguments, words the one stderr line must hold).  "{d}" is the case folder.
CASES: list[tuple[str, list[str], str]] = [
    # --- command line syntax (click) ---
    ("no arguments", [], "missing argument 'MESH'"),
    ("unknown option", ["plate.obj", "--foo"], "no such option '--foo'"),
    ("res not a number", ["plate.obj", "--res", "abc"], "'abc' is not a valid integer"),
    ("unknown preset", ["plate.obj", "--preset", "granite"], "'granite' is not one of"),
    ("unknown method", ["plate.obj", "--method", "magic"], "'magic' is not one of"),
    ("unknown uv mode", ["plate.obj", "--uv", "guess"], "'guess' is not one of"),
    ("unknown format", ["plate.obj", "--formats", "jpg"], "comma-separated subset"),
    ("empty formats", ["plate.obj", "--formats", ","], "comma-separated subset"),
    # --- ranges ---
    ("res too small", ["plate.obj", "--shrink", "1", "--res", "10"], "--res 10 is out of range"),
    ("res too big", ["plate.obj", "--shrink", "1", "--res", "20000"], "--res 20000"),
    ("crack width 1e300", ["plate.obj", "--impact", IMPACT, "--crack-width", "1e300"],
     "--crack-width 1e+300 is out of range"),
    ("crack width negative", ["plate.obj", "--shrink", "1", "--crack-width", "-1"],
     "--crack-width -1 is out of range"),
    ("depth ratio nan", ["plate.obj", "--shrink", "1", "--depth-ratio", "nan"],
     "--depth-ratio nan is out of range"),
    ("profile zero", ["plate.obj", "--shrink", "1", "--profile", "0"], "--profile 0 is out"),
    ("max distance inf", ["plate.obj", "--shrink", "1", "--max-distance", "inf"],
     "--max-distance inf"),
    ("max steps overflow", ["plate.obj", "--shrink", "1", "--max-steps", "9" * 20],
     "--max-steps 99999999999999999999 is out of range"),
    ("tip factor 2", ["plate.obj", "--shrink", "1", "--tip-factor", "2"], "--tip-factor 2 is"),
    ("hoop 1e300", ["plate.obj", "--impact", IMPACT, "--hoop", "1e300"], "--hoop 1e+300"),
    ("shrink inf", ["plate.obj", "--shrink", "inf"], "--shrink inf is out of range"),
    ("noise negative", ["plate.obj", "--shrink", "1", "--noise", "-1"], "--noise -1 is out"),
    ("toughness negative", ["plate.obj", "--shrink", "1", "--toughness", "-1"], "--toughness -1"),
    ("curvature syntax", ["plate.obj", "--curvature", "abc"], "expected BIAS[:DENSITY]"),
    ("curvature 1e300", ["plate.obj", "--curvature", "1e300"], "--curvature-bias 1e+300"),
    ("sim faces 5", ["plate.obj", "--shrink", "1", "--sim-faces", "5"], "--sim-faces 5 is out"),
    ("seed negative", ["plate.obj", "--shrink", "1", "--seed", "-1"], "--seed -1"),
    ("unwrap timeout inf", ["plate.obj", "--shrink", "1", "--unwrap-timeout", "inf"],
     "--unwrap-timeout inf"),
    ("padding negative", ["plate.obj", "--shrink", "1", "--padding", "-1"], "--padding -1"),
    ("dilate negative", ["plate.obj", "--shrink", "1", "--dilate", "-3"], "--dilate -3"),
    # --- impacts and directions ---
    ("impact syntax", ["plate.obj", "--impact", "1,2"], "expected X,Y,Z[:RADIUS[:STRENGTH]]"),
    ("impact nan", ["plate.obj", "--impact", "nan,0,0"], "--impact 'nan,0,0'"),
    ("impact radius negative", ["plate.obj", "--impact", "0.5,0.5,0:-1"], "the radius must"),
    ("impact strength 1e300", ["plate.obj", "--impact", f"{IMPACT}:0.2:1e300"],
     "the strength must be a number above 0 up to 1e+06"),
    ("impact strength zero", ["plate.obj", "--impact", f"{IMPACT}:0.2:0"], "the strength must"),
    ("impact far away", ["plate.obj", "--impact", "1e308,1e308,1e308", "--sim-faces", "300"],
     "mesh diagonals from the surface"),
    ("direction zero", ["plate.obj", "--direction", "0,0,0"], "must not be zero"),
    ("direction 1e300", ["plate.obj", "--direction", "1,0,0:1e300"], "the strength must lie"),
    ("nothing to crack", ["plate.obj"], "nothing to crack"),
    ("preset needs impact", ["plate.obj", "--preset", "glass"], "needs an impact point"),
    # --- mesh files ---
    ("mesh missing", ["missing.obj", "--shrink", "1"], "file not found"),
    ("mesh is a folder", ["maps", "--shrink", "1"], "is a directory"),
    ("wrong suffix", ["notes.txt", "--shrink", "1"], "unsupported format '.txt'"),
    ("no suffix", ["noext", "--shrink", "1"], "unsupported format '(none)'"),
    ("empty obj", ["empty.obj", "--shrink", "1"], "no triangles"),
    ("empty ply", ["empty.ply", "--shrink", "1"], "the file is empty, so it holds no triangles"),
    ("empty glb", ["empty.glb", "--shrink", "1"], "the file is empty, so it holds no triangles"),
    ("vertices only", ["points.obj", "--shrink", "1"], "crackbake needs a triangle mesh"),
    ("text not obj", ["words.obj", "--shrink", "1"], "crackbake needs a triangle mesh"),
    ("obj index 0", ["zero_index.obj", "--shrink", "1"], "OBJ indices start at 1"),
    ("obj missing vertex", ["missing_vertex.obj", "--shrink", "1"],
     "vertices the file does not have (line 6: vertex 9, but only 4 vertices)"),
    ("obj short vertex", ["short_vertex.obj", "--shrink", "1"], "fewer than three coordinates"),
    ("obj nan vertex", ["nan.obj", "--shrink", "1"], "1 vertex has NaN"),
    ("obj zero area", ["flat.obj", "--shrink", "1"], "every face has zero area"),
    ("obj letters", ["letters.obj", "--shrink", "1"], "could not read the OBJ file"),
    ("ply garbage", ["garbage.ply", "--shrink", "1"], "could not read the PLY file"),
    ("glb garbage", ["garbage.glb", "--shrink", "1"], "could not read the GLB file"),
    ("stl garbage", ["garbage.stl", "--shrink", "1"], "garbage.stl"),
    # --- weight maps and attributes ---
    ("weight map missing", ["plate.obj", "--shrink", "1", "--weight-map", "none.png"],
     "--weight-map none.png: file not found"),
    ("weight map folder", ["plate.obj", "--shrink", "1", "--weight-map", "maps"],
     "--weight-map maps: is a folder; pass an image file"),
    ("weight map corrupt", ["plate.obj", "--shrink", "1", "--weight-map", "not_an_image.png"],
     "could not read the weight map"),
    ("weight attribute missing", ["plate.obj", "--shrink", "1", "--weight-attribute", "paint"],
     "paint"),
    # --- sidecars ---
    ("sidecar missing", ["plate.obj", "--cracks", "none.json"], "file not found"),
    ("sidecar corrupt", ["plate.obj", "--cracks", "corrupt.json"], "not valid JSON"),
    ("sidecar bool face", ["plate.obj", "--cracks", "bool_face.json"],
     "'faces' is not an array of integers"),
    ("sidecar negative width", ["plate.obj", "--cracks", "neg_width.json"],
     "negative width (-5); width must be >= 0"),
    ("sidecar other mesh", ["plate.obj", "--cracks", "other_mesh.json"],
     "bake it on the mesh it was made for"),
    # --- files that are not regular files, files outside the mesh's folder (issue 19 §2) ---
    ("mesh fifo", ["pipe.obj", "--shrink", "1"],
     "pipe.obj: is a FIFO (named pipe), not a regular file"),
    ("mesh dev zero via symlink", ["zero.obj", "--shrink", "1"],
     "zero.obj: is a character device, not a regular file"),
    ("sidecar fifo", ["plate.obj", "--cracks", "pipe.json"], "pipe.json: is a FIFO"),
    ("sidecar dev zero via symlink", ["plate.obj", "--cracks", "zero.json"],
     "zero.json: is a character device"),
    ("weight map fifo", ["plate.obj", "--shrink", "1", "--weight-map", "pipe.png"],
     "--weight-map pipe.png: is a FIFO"),
    ("gltf buffer dev zero", ["zerobuf.gltf", "--shrink", "1", "--allow-outside-textures"],
     "zerobuf.gltf: 'zero.bin': is a character device"),
    ("gltf buffer outside its folder", ["upbuf.gltf", "--shrink", "1"],
     "upbuf.gltf: names '../_inputs/sub/outside.bin', which lies outside the mesh's folder; "
     "move it beside the mesh or pass --allow-outside-textures"),
    ("gltf buffer dev zero outside", ["zerobuf.gltf", "--shrink", "1"],
     "names 'zero.bin', which lies outside the mesh's folder"),
    # --- crackbake inspect (issue 19 §3) ---
    ("inspect truncated exr", ["inspect", "trunc.exr"], "cannot read EXR 'trunc.exr': "),
    ("inspect huge data window", ["inspect", "huge.exr"],
     "cannot read EXR 'huge.exr': its data window is 60001x60001 pixels"),
    ("inspect fifo", ["inspect", "pipe.exr"], "pipe.exr: is a FIFO"),
    ("inspect png dev null", ["inspect", "good.exr", "--png", "/dev/null"],
     "output '/dev/null' exists and is not a folder; choose a folder with --png"),
    ("inspect png user folder", ["inspect", "good.exr", "--png", "album"],
     "output folder 'album' is not empty and has no crackbake manifest.json"),
    # --- sidecars that passed validation and then crashed (issue 19) ---
    ("sidecar nested 100000 deep", ["plate.obj", "--cracks", "deep.json"],
     "nests lists or objects thousands deep"),
    ("sidecar params nested 900 deep", ["plate.obj", "--cracks", "params_deep.json"],
     "nests lists or objects more than 32 deep"),
    ("sidecar id 2**70", ["plate.obj", "--cracks", "id_huge.json"],
     "crack ids must lie in 0..16777215"),
    ("sidecar id -1", ["plate.obj", "--cracks", "id_minus1.json"],
     "has id -1; crack ids must lie in 0..16777215"),
    ("sidecar id 2**24", ["plate.obj", "--cracks", "id_2_24.json"],
     "has id 16777216; crack ids must lie in 0..16777215"),
    ("sidecar points 1e300", ["plate.obj", "--cracks", "points_1e300.json"],
     "has a point coordinate of 1e+300"),
    ("sidecar width 1e308", ["plate.obj", "--cracks", "width_1e308.json"],
     "has width 1e+308; width must be at most 1e+15 mesh units"),
    ("sidecar params width 1e300", ["plate.obj", "--cracks", "params_width.json"],
     '"params"."crack_width" is 1e+300; it must be a number above 0 up to 1e+15'),
    ("sidecar impact strength 1e300", ["plate.obj", "--cracks", "impact_strength.json"],
     '"impacts"[0]."strength" is 1e+300'),
    # --- images ---
    ("weight map truncated png", ["plate.obj", "--shrink", "1", "--weight-map", "truncated.png"],
     "could not decode the weight map (IDAT: Read error"),
    ("weight map 50000 squared header", ["plate.obj", "--shrink", "1", "--weight-map",
                                          "bomb.png"], "could not read the weight map"),
    # --- memory (issue 19): refused before the heavy stages, with the option to lower ---
    ("res 16384 under 10 GiB", ["plate.obj", "--shrink", "1", "--res", "16384",
                                "--max-memory", "10"],
     "but --max-memory allows 10.0 GiB; lower --res"),
    ("stress res 16384 under 16 GiB", ["plate.obj", "--shrink", "1", "--stress-res", "16384",
                                       "--max-memory", "16"],
     "but --max-memory allows 16.0 GiB; lower --stress-res"),
    ("sim faces 20M under 8 GiB", ["plate.obj", "--shrink", "1", "--sim-faces", "20000000",
                                   "--max-memory", "8"],
     "but --max-memory allows 8.0 GiB; lower --sim-faces"),
    ("max memory zero", ["plate.obj", "--shrink", "1", "--max-memory", "0"],
     "--max-memory 0 is out of range"),
    ("egl device abc", ["plate.obj", "--shrink", "1", "--sim-faces", "300"],
     "CRACKBAKE_EGL_DEVICE='abc' is not an EGL device number"),
    ("res 8192 under a 3 GB address-space cap", ["plate.obj", "--shrink", "1", "--res", "8192"],
     "of address space"),
    ("res 4096 unwrap under a 2 GB address-space cap",
     ["plate.obj", "--shrink", "1", "--res", "4096", "--uv", "unwrap"],
     "allows 1.9 GiB; lower --res"),
]
# Inputs that run (exit 0) with one warning line naming the problem (issue 19's "small ones"
# and optional textures): (case id, arguments, words the warning line must hold).
WARN_CASES: list[tuple[str, list[str], str]] = [
    ("vt index out of range", ["bad_vt.obj", "--shrink", "1", "--sim-faces", "300"],
     "(line 51: vt 99, but only 25 vt lines); ignoring every UV"),
    ("inf uv", ["inf_uv.obj", "--shrink", "1", "--sim-faces", "300"],
     "1 UVs hold infinite values; ignoring them all"),
    ("texture header 20000 squared", ["bomb_tex.obj", "--shrink", "1", "--sim-faces", "300"],
     "base-colour texture bomb20k.png is unreadable"),
    ("texture truncated", ["trunc_tex.obj", "--shrink", "1", "--sim-faces", "300"],
     "base-colour texture truncated.png is unreadable (image file is truncated); using grey"),
    ("home missing", ["plate.obj", "--shrink", "1", "--sim-faces", "300", "--uv", "unwrap"],
     "the home folder"),
]
# Cases that need more than arguments: an environment variable, a memory cap.
ENVIRON = {"egl device abc": {"CRACKBAKE_EGL_DEVICE": "abc"},
           "home missing": {"HOME": "{d}/nohome", "CRACKBAKE_CACHE_DIR": None,
                            "XDG_CACHE_HOME": None}}
RLIMIT_AS = {"res 8192 under a 3 GB address-space cap": 3 * 10**9,
             "res 4096 unwrap under a 2 GB address-space cap": 2 * 10**9}


# Cases run as ``python -m crackbake`` in a fresh interpreter, the way a user runs it: the
# command line's own errors, the checks made before any heavy import, the address-space caps
# (the cap covers the interpreter's imports too) and the environment a process starts with.
# Every other case runs in a fork of one process that imported crackbake once
# (tests/cli_forks.py): the same entry point, exit status and output, without 2-3 CPU seconds of
# imports each.
SUBPROCESS = ("no arguments", "unknown option", "nothing to crack", "mesh fifo", "egl device abc",
              "home missing", *RLIMIT_AS)


def _command(root: Path, case: tuple[str, list[str], str]) -> dict:
    """The case's folder (inputs copied, FIFOs made) and its command for cli_forks."""
    name, args, _ = case
    folder = root / name.replace(" ", "_")
    shutil.copytree(root / "_inputs", folder)
    _specials(folder)
    env = {**os.environ, "PYTHONPATH": str(REPO), "CRACKBAKE_CACHE_DIR": str(folder / ".cache")}
    for key, value in ENVIRON.get(name, {}).items():  # None removes the variable
        if value is None:
            env.pop(key, None)
        else:
            env[key] = value.format(d=folder)
    common = [] if args[:1] == ["inspect"] else ["--res", "64", "-o", "out"]
    # A read that blocks (a FIFO) must fail the case, not hang the catalogue.
    return {"args": [*common, *args], "cwd": str(folder), "env": env,
            "rlimit_as": RLIMIT_AS.get(name), "timeout": 60 if "fifo" in name else 300}


def _subprocess(command: dict) -> dict:
    cap = command["rlimit_as"]

    def limit() -> None:  # in the child, before exec: the cap covers the whole run
        resource.setrlimit(resource.RLIMIT_AS, (cap, cap))

    t0 = time.perf_counter()
    try:
        r = subprocess.run(
            [sys.executable, "-m", "crackbake", *command["args"]], cwd=command["cwd"],
            capture_output=True, text=True, env=command["env"], timeout=command["timeout"],
            preexec_fn=limit if cap else None,
        )
        rc, stderr, stdout = r.returncode, r.stderr, r.stdout
    except subprocess.TimeoutExpired as exc:
        rc, stderr, stdout = "timed out", str(exc), ""
    return {"secs": time.perf_counter() - t0, "rc": rc, "stderr": stderr, "stdout": stdout}


def _listing(folder: str) -> list[Path]:
    return sorted(p.relative_to(folder) for p in Path(folder).rglob("*"))


@pytest.fixture(scope="module")
def results(tmp_path_factory) -> dict:
    root = tmp_path_factory.mktemp("bad_inputs")
    (root / "_inputs").mkdir()
    _inputs(root / "_inputs")
    commands = {case[0]: _command(root, case) for case in CASES + WARN_CASES}
    before = {name: _listing(c["cwd"]) for name, c in commands.items()}
    forked = [name for name in commands if name not in SUBPROCESS]
    with ThreadPoolExecutor(max_workers=1) as pool:  # one beside the forks, 4 at a time in all
        alone = pool.map(_subprocess, [commands[n] for n in SUBPROCESS])
        done = dict(zip(forked, run_commands([commands[n] for n in forked], workers=3),
                        strict=True))
        done.update(zip(SUBPROCESS, alone, strict=True))
    for name, r in done.items():
        r["new"] = [str(p) for p in _listing(commands[name]["cwd"]) if p not in before[name]]
    return done


def test_catalogue_is_large_and_unique():
    names = [c[0] for c in CASES + WARN_CASES]
    assert len(names) >= 40 and len(set(names)) == len(names)


@pytest.mark.parametrize(("name", "args", "message"), CASES, ids=[c[0] for c in CASES])
def test_bad_input_is_one_clear_line(results, name, args, message):
    r = results[name]
    lines = r["stderr"].splitlines()
    assert r["rc"] == 2, r["stderr"]
    assert len(lines) == 1, r["stderr"]
    line = lines[0]
    assert line.startswith("error: ") and message in line, line
    assert "Traceback" not in line and "np." not in line and "internal error" not in line
    assert r["stdout"] == ""
    # Nothing but complete entries of the mesh cache (crackbake.bake.mesh_cache: what the run
    # measured of the asset before the error, kept for the corrected run), in its cache folder.
    left = [p for p in r["new"] if p != ".cache" and not re.fullmatch(
        r"\.cache/(gutter|tangents|uvcheck|simmesh|up)-[0-9a-f]{64}\.npys", p)]  # fmt: skip
    assert left == [], f"left behind: {r['new']}"


@pytest.mark.parametrize(("name", "args", "message"), WARN_CASES, ids=[c[0] for c in WARN_CASES])
def test_recoverable_input_runs_with_one_warning(results, name, args, message):
    """A broken optional part (UVs, texture, cache folder) costs a warning, never the run."""
    r = results[name]
    assert r["rc"] == 0, r["stderr"]
    warned = [line for line in r["stderr"].splitlines() if line.startswith("warning: ")]
    assert len(warned) == 1 and message in warned[0], r["stderr"]
    assert "Traceback" not in r["stderr"] and "libpng" not in r["stderr"]
    # Only the output folder (and the test's own cache folder) appear: no home folder made.
    assert all(p.split("/")[0] in ("out", ".cache") for p in r["new"]), r["new"]



@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"max_steps": np.int64(0)}, "--max-steps 0 is out of range; use a number from 1"),
        ({"crack_width": np.float32(np.inf)}, "--crack-width inf is out of range"),
        ({"depth_ratio": np.float64(1e300)},
         r"--depth-ratio 1e\+300 is out of range; use a number from 0 up to 1000"),
        ({"noise": True}, "--noise 'True' is not a number"),
        ({"shrink_rate": "fast"}, "--shrink-rate 'fast' is not a number"),
        ({"impacts": (Impact(point=(np.float64(np.nan), 0.0, 0.0)),)},
         r"impact point \(nan, 0, 0\): must be three finite numbers"),
        ({"impacts": (Impact(point=(0.0, 0.0, 0.0), strength=np.float64(1e300)),)},
         r"impact strength 1e\+300 is out of range"),
        ({"directions": ((1.0, 0.0, 0.0, np.float64(-1e300)),)}, "--direction strength -1e\\+300"),
    ],
    ids=["int64", "float32 inf", "depth 1e300", "bool", "text", "nan point", "strength",
         "direction"],
)
def test_library_params_give_the_same_plain_messages(fields, message):
    """Scripts building RunParams with numpy scalars get the CLI's messages, no numpy reprs."""
    from crackbake.errors import CrackbakeError
    from crackbake.params import RunParams

    with pytest.raises(CrackbakeError, match=message) as info:
        RunParams(mesh=Path("plate.obj"), **fields).validate()
    assert "np." not in str(info.value)


# ------------------------------------------- paths a mesh names outside its folder (issue 19 §2)

def _textured(root: Path) -> dict[str, Path]:
    """Meshes naming a red texture outside their folder (and FIFOs inside it), each with a
    sidecar: name -> mesh path."""
    import trimesh
    from PIL import Image

    asset, secret = root / "asset", root / "secret"
    asset.mkdir()
    secret.mkdir()
    Image.new("RGB", (8, 8), (255, 0, 0)).save(secret / "red.png")
    (secret / "x.mtl").write_text("newmtl m\nmap_Kd red.png\n")
    mtls = {
        "obj_absolute": f"newmtl m\nmap_Kd {secret / 'red.png'}\n",
        "obj_dotdot": "newmtl m\nmap_Kd ../secret/red.png\n",
        "fifo_map": "newmtl m\nmap_Kd pipe.png\n",
    }
    meshes = {}
    for stem, lib in [*((s, f"{s}.mtl") for s in mtls), ("mtllib_dotdot", "../secret/x.mtl"),
                      ("fifo_mtllib", "pipe.mtl")]:
        (asset / f"{stem}.obj").write_text(f"mtllib {lib}\nusemtl m\n" + PLATE)
        meshes[stem] = asset / f"{stem}.obj"
    for stem, text in mtls.items():
        (asset / f"{stem}.mtl").write_text(text)
    os.mkfifo(asset / "pipe.png")
    os.mkfifo(asset / "pipe.mtl")
    # glTF: the plate with a green texture of its own, its image URI then pointed at red.png
    Image.new("RGB", (8, 8), (0, 255, 0)).save(asset / "green.png")
    (asset / "green.mtl").write_text("newmtl m\nmap_Kd green.png\n")
    (asset / "green.obj").write_text("mtllib green.mtl\nusemtl m\n" + PLATE)
    files = trimesh.load(asset / "green.obj", process=False).export(file_type="gltf")
    doc = json.loads(files.pop("model.gltf"))
    for name, blob in files.items():
        (asset / name).write_bytes(blob)
    doc["images"] = [{"uri": "../secret/red.png"}]
    (asset / "gltf_uri.gltf").write_text(json.dumps(doc))
    meshes["gltf_uri"] = asset / "gltf_uri.gltf"
    for stem, mesh in meshes.items():
        (asset / f"{stem}.json").write_text(json.dumps(_sidecar(mesh)))
    return meshes


TEXTURE_CASES = [
    # (mesh, the path as the file names it: None for a FIFO, --allow-outside-textures)
    ("obj_absolute", "{root}/secret/red.png", False),
    ("obj_absolute", "{root}/secret/red.png", True),
    ("obj_dotdot", "../secret/red.png", False),
    ("obj_dotdot", "../secret/red.png", True),
    ("mtllib_dotdot", "../secret/x.mtl", False),
    ("mtllib_dotdot", "../secret/x.mtl", True),
    ("gltf_uri", "../secret/red.png", False),
    ("gltf_uri", "../secret/red.png", True),
    ("fifo_map", None, False),
    ("fifo_mtllib", None, False),
]


def _bake_command(root: Path, meshes: dict, case: tuple) -> dict:
    stem, _, allow = case
    mesh = meshes[stem]
    env = {**os.environ, "PYTHONPATH": str(REPO), "CRACKBAKE_CACHE_DIR": str(root / ".cache")}
    args = [str(mesh), "--cracks", str(mesh.with_suffix(".json")), "--res", "64",
            "--formats", "png", "-o", str(root / f"out_{stem}_{allow}"),
            *(["--allow-outside-textures"] * allow)]
    return {"args": args, "cwd": str(root), "env": env, "timeout": 120}  # a FIFO must not hang


def _colour(root: Path, case: tuple, r: dict) -> dict:
    stem, _, allow = case
    colour = None
    if r["rc"] == 0:
        from PIL import Image

        with Image.open(root / f"out_{stem}_{allow}" / f"{stem}_basecolor.png") as im:
            colour = np.median(np.asarray(im.convert("RGB")).reshape(-1, 3), axis=0)
    return {**r, "colour": colour}


@pytest.fixture(scope="module")
def textured(tmp_path_factory) -> tuple[Path, dict]:
    """The bakes run in forks of one process (tests/cli_forks.py), as the catalogue's do."""
    root = tmp_path_factory.mktemp("textures")
    meshes = _textured(root)
    done = run_commands([_bake_command(root, meshes, c) for c in TEXTURE_CASES], workers=4)
    return root, {(c[0], c[2]): _colour(root, c, r)
                  for c, r in zip(TEXTURE_CASES, done, strict=True)}


@pytest.mark.parametrize(("stem", "named", "allow"), TEXTURE_CASES,
                         ids=[f"{c[0]}{'-allowed' if c[2] else ''}" for c in TEXTURE_CASES])
def test_textures_outside_the_mesh_folder_are_not_read(textured, stem, named, allow):
    """Refused with one warning naming the path, the base colour grey; the flag reads it."""
    root, results = textured
    r = results[(stem, allow)]
    assert r["rc"] == 0, r["stderr"]
    warned = [ln for ln in r["stderr"].splitlines()
              if ln.startswith("warning: ") and "base colour" in ln]
    red, green, blue = r["colour"]
    if allow:
        assert not warned, warned
        assert red > 200 and green < 60 and blue < 60, r["colour"]  # the outside red texture
        return
    assert len(warned) == 1, r["stderr"]
    if named is None:
        assert "is a FIFO (named pipe), not a regular file, so it was not read" in warned[0]
    else:
        path = named.format(root=root)
        assert f"'{path}'" in warned[0] and "lies outside the mesh's folder" in warned[0]
        assert "--allow-outside-textures" in warned[0]
    assert abs(red - blue) < 25 and abs(red - green) < 25, r["colour"]  # grey, not red


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full")
def test_json_to_a_full_stdout_is_one_line_after_the_commit(tmp_path):
    """``--json > /dev/full``: the run is complete, the summary cannot be written; one error
    line saying so (it was a traceback), exit 2, the output set in place."""
    (tmp_path / "plate.obj").write_text(PLATE)
    env = {**os.environ, "PYTHONPATH": str(REPO), "CRACKBAKE_CACHE_DIR": str(tmp_path / ".c")}
    with open("/dev/full", "w") as full:
        r = subprocess.run(
            [sys.executable, "-m", "crackbake", "plate.obj", "--shrink", "1", "--res", "64",
             "--sim-faces", "300", "-o", "out", "-q", "--json"],
            cwd=tmp_path, stdout=full, stderr=subprocess.PIPE, text=True, env=env, timeout=300,
        )
    assert r.returncode == 2, r.stderr
    lines = r.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: cannot write the --json summary"), lines
    assert "the outputs are complete in out/" in lines[0]
    assert (tmp_path / "out" / "manifest.json").is_file()
