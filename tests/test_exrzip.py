"""crackbake.exchange.exrzip: ZIP/ZIPS scanline EXRs encoded by crackbake itself.

Each file is checked against two independent implementations: the OpenEXR bindings (which
decode it, and write the reference file whose header it must equal) and OpenImageIO.
"""

from __future__ import annotations

import json
import struct

import numpy as np
import OpenEXR
import OpenImageIO as oiio
import pytest

from crackbake.errors import CrackbakeError
from crackbake.exchange.exr import exr_threads, read_exr, write_exr
from crackbake.exchange.exrzip import SCANLINE_COMPRESSIONS, to_half, write_scanline

H, W = 37, 53  # not a multiple of ZIP's 16 lines: a short last chunk


def _planes(seed: int = 3) -> dict[str, np.ndarray]:
    """Sparse crack-like planes, random bits and every pixel type."""
    rng = np.random.default_rng(seed)
    mask = np.zeros((H, W), np.float16)
    mask[5:9, 10:30] = rng.uniform(0, 1, (4, 20))
    bits = rng.integers(0, 2**16, (H, W), dtype=np.uint16).view(np.float16)
    bits[np.isnan(bits)] = 0
    dist = np.full((H, W), 0.05, np.float32)
    dist[:, 20:] = rng.uniform(0, 0.05, (H, W - 20))
    return {
        "crack.mask.V": mask,
        "crack.time.V": bits,  # incompressible: chunks stored as they are
        "crack.distance.V": dist,
        "crack.id.V": rng.integers(0, 2**32, (H, W), dtype=np.uint32),
        "a.b.V": rng.standard_normal((H, W)).astype(np.float32),
    }


ATTRS = {"owner": "crackbake test", "crackbake:layout": 1, "crackbake:maxDistance": 0.25,
         "crackbake:channels": '{"a": 1}'}  # fmt: skip


def _same(got: dict, want: dict) -> None:
    assert sorted(got) == sorted(want)
    for name, plane in want.items():
        assert got[name].dtype == plane.dtype, name
        assert np.array_equal(got[name].view(np.uint8), plane.view(np.uint8)), name


def _oiio(path) -> dict[str, np.ndarray]:
    inp = oiio.ImageInput.open(str(path))
    assert inp is not None, oiio.geterror()
    spec = inp.spec()
    kinds = {"half": np.float16, "float": np.float32, "uint": np.uint32}
    out = {}
    for i, name in enumerate(spec.channelnames):
        fmt = str(spec.channelformat(i))
        out[name] = inp.read_image(0, 0, i, i + 1, fmt)[:, :, 0].astype(kinds[fmt], copy=False)
    inp.close()
    return out


@pytest.mark.parametrize("compression", sorted(SCANLINE_COMPRESSIONS))
def test_pixels_and_header_as_the_bindings_write_them(tmp_path, compression):
    planes = _planes()
    ours, theirs = tmp_path / "ours.exr", tmp_path / "theirs.exr"
    write_exr(ours, planes, ATTRS, compression=compression)
    header = {"compression": getattr(OpenEXR, f"{compression.upper()}_COMPRESSION"),
              "type": OpenEXR.scanlineimage, **ATTRS}  # fmt: skip
    OpenEXR.File(header, {k: v.copy() for k, v in planes.items()}).write(str(theirs))
    got, got_header = read_exr(ours)
    _same(got, planes)
    _same(_oiio(ours), planes)
    want_header = read_exr(theirs)[1]
    # The one attribute the bindings do not write: inspect's record (test_exrstats.py)
    record = json.loads(got_header.pop("crackbake:stats"))
    assert sorted(record["channels"]) == sorted(planes)
    assert {k: str(v) for k, v in got_header.items()} == {
        k: str(v) for k, v in want_header.items()
    }
    assert got_header["compression"] == compression
    # about the bindings' size (another deflate, the same transform)
    assert ours.stat().st_size < 1.3 * theirs.stat().st_size


def test_threads_split_the_chunks_the_file_stays_the_same(tmp_path):
    planes = _planes(5)
    blobs = []
    for n in (0, 1, 3):
        path = tmp_path / f"t{n}.exr"
        with exr_threads(n):
            write_exr(path, planes, ATTRS)
        blobs.append(path.read_bytes())
    assert blobs[0] == blobs[1] == blobs[2]
    _same(read_exr(tmp_path / "t3.exr")[0], planes)


def test_chunk_table_and_stored_chunks(tmp_path):
    """The offset table points at each chunk's first scanline; a chunk of random bits (no
    smaller when deflated) is stored as it is: size = the raw size."""
    rng = np.random.default_rng(1)
    noise = rng.integers(0, 2**32, (H, W), dtype=np.uint32)
    path = tmp_path / "noise.exr"
    write_scanline(path, {"n.V": noise}, {}, "zip")
    blob = path.read_bytes()
    chunks = -(-H // 16)
    end = len(blob)
    table = np.frombuffer(blob, "<u8", count=chunks, offset=_header_end(blob))
    for k, offset in enumerate(table):
        y, size = struct.unpack_from("<ii", blob, int(offset))
        assert y == 16 * k
        assert size == min(16, H - y) * W * 4  # stored raw
        nxt = int(table[k + 1]) if k + 1 < chunks else end
        assert int(offset) + 8 + size == nxt
    _same(read_exr(path)[0], {"n.V": noise})


def _header_end(blob: bytes) -> int:
    """Offset just after the header's terminating null (walks the attributes)."""
    pos = 8
    while blob[pos] != 0:
        pos = blob.index(b"\0", pos) + 1  # name
        pos = blob.index(b"\0", pos) + 1  # type
        (size,) = struct.unpack_from("<i", blob, pos)
        pos += 4 + size
    return pos + 1


def test_long_names_flag(tmp_path):
    """Names beyond 31 bytes need the version's long-names bit, or readers refuse the file."""
    name = "crackbake:" + "x" * 40
    path = tmp_path / "long.exr"
    write_exr(path, {"v.V": np.ones((4, 4), np.float16)}, {name: "long"})
    (version,) = struct.unpack_from("<I", path.read_bytes(), 4)
    assert version == 2 | 0x400
    assert read_exr(path)[1][name] == "long"
    short = tmp_path / "short.exr"
    write_exr(short, {"v.V": np.ones((4, 4), np.float16)}, {"crackbake:x": "short"})
    assert struct.unpack_from("<I", short.read_bytes(), 4)[0] == 2


def test_names_beyond_255_bytes_refused(tmp_path):
    with pytest.raises(CrackbakeError, match="cannot write EXR .* at most 255"):
        write_exr(tmp_path / "x.exr", {"v.V": np.ones((4, 4), np.float16)}, {"c:" + "x" * 300: 1})
    assert not (tmp_path / "x.exr").exists()


def test_unwritable_path_is_one_clear_error(tmp_path):
    with pytest.raises(CrackbakeError, match="cannot write EXR .*folder exists"):
        write_exr(tmp_path / "missing" / "x.exr", _planes(), compression="zip")


@pytest.mark.reference
def test_blender_decodes_every_chunk(tmp_path):
    """Blender's own EXR reader (bpy 5.0) gives back each plane of a multi-chunk ZIP file whose
    last chunk is short and one of whose planes is random bits, pass by pass."""
    from tests.blender_runner import run_blender

    planes = {k: v for k, v in _planes(9).items() if v.dtype != np.uint32}  # no UINT passes
    path = tmp_path / "zip.exr"
    write_exr(path, planes, ATTRS)
    out = tmp_path / "blender"
    out.mkdir()
    got = run_blender("exr_passes.py", str(path), str(out))
    assert sorted(got["layers"]) == ["a", "crack"]
    seen = set()
    for info in got["passes"]:
        name = f"{info['layer']}.{info['pass']}.V"
        (plane,) = read_exr(info["file"])[0].values()
        np.testing.assert_array_equal(plane, planes[name].astype(np.float32), err_msg=name)
        seen.add(name)
    assert seen == set(planes)


def test_to_half_is_numpys_cast():
    """Every upper 16 bits of a float32 with the low bits that steer the rounding (ties, one
    below, one above, with and without the kept bit set), and 1M random patterns: numpy's
    half bits, signalling NaNs aside (they come out quiet)."""
    hi = np.arange(1 << 16, dtype=np.uint32) << 16
    lo = np.array([(a << 12) | b for a in range(16) for b in (0, 1, 0x7FF, 0x800, 0x801, 0xFFF)],
                  np.uint32)  # fmt: skip
    rng = np.random.default_rng(2)
    bits = np.concatenate([(hi[:, None] | lo[None, :]).ravel(),
                           rng.integers(0, 2**32, 1 << 20, dtype=np.uint64).astype(np.uint32)])
    f = bits.view(np.float32).reshape(-1, 1024)
    got = to_half(f).view(np.uint16)
    with np.errstate(over="ignore", invalid="ignore"):
        want = f.astype(np.float16).view(np.uint16)
    assert got.shape == f.shape
    signalling = np.isnan(f) & ((bits.reshape(f.shape) & 0x00400000) == 0)
    np.testing.assert_array_equal(got[~signalling], want[~signalling])
    assert np.isnan(got[signalling].view(np.float16)).all()
    # strided input (a vector map's component), and other dtypes go through numpy
    normal = rng.standard_normal((64, 48, 3)).astype(np.float32)
    np.testing.assert_array_equal(to_half(normal[:, :, 1]), normal[:, :, 1].astype(np.float16))
    assert to_half(np.ones(3, np.float64)).dtype == np.float16


def _zip_transform(chunk: np.ndarray) -> np.ndarray:
    """Test oracle: ZIP's transform of a chunk's bytes as the OpenEXR layout describes it
    (even bytes then odd bytes, each minus the one before plus 128, mod 256, the first kept)."""
    t = np.concatenate([chunk[0::2], chunk[1::2]]).astype(np.int32)
    out = t.copy()
    out[1:] = (t[1:] - t[:-1] + 128) & 255
    return out.astype(np.uint8)


@pytest.mark.parametrize("compression", sorted(SCANLINE_COMPRESSIONS))
def test_each_chunk_is_the_transform_of_its_scanlines(tmp_path, compression):
    """Every deflated chunk inflates to the transform of its scanlines gathered in numpy, the
    channels in name order (the kernels predict each channel's rows where they lie)."""
    import zlib

    planes = _planes(11)
    path = tmp_path / "t.exr"
    write_scanline(path, planes, {}, compression)
    blob = path.read_bytes()
    lines = SCANLINE_COMPRESSIONS[compression][0]
    rows = [planes[n].view(np.uint8).reshape(H, -1) for n in sorted(planes)]
    chunks = -(-H // lines)
    table = np.frombuffer(blob, "<u8", count=chunks, offset=_header_end(blob))
    deflated = 0
    for offset in table:
        y, size = struct.unpack_from("<ii", blob, int(offset))
        raw = np.concatenate([r[y:y + lines] for r in rows], axis=1).reshape(-1)
        data = blob[int(offset) + 8:int(offset) + 8 + size]
        if size == raw.size:
            assert data == raw.tobytes()
            continue
        deflated += 1
        np.testing.assert_array_equal(np.frombuffer(zlib.decompress(data), np.uint8),
                                      _zip_transform(raw))  # fmt: skip
    assert deflated > 0


@pytest.mark.parametrize("width", [1, 2, 3, 64])
def test_narrow_and_wide_rows_decode(tmp_path, width):
    """The predictor's row views hold ``width - 1`` words (none for one pixel): every width
    decodes to the planes in OpenEXR and OpenImageIO, smooth rows (deflated chunks) and
    random ones (stored chunks) alike."""
    rng = np.random.default_rng(width)
    ramp = np.linspace(0, 1, 40 * width, dtype=np.float32).reshape(40, width)
    planes = {
        "a.V": ramp.astype(np.float16),
        "b.V": ramp * 3,
        "c.V": rng.integers(0, 2**32, (40, width), dtype=np.uint32),
    }
    path = tmp_path / "n.exr"
    write_scanline(path, planes, {}, "zip")
    _same(read_exr(path)[0], planes)
    _same(_oiio(path), planes)


@pytest.mark.parametrize("level", [None, 1, 2, 6])
def test_every_deflate_gives_the_same_pixels(tmp_path, level):
    """The default chunks' deflate (zlib-ng at ZIP_LEVEL) and zlib-ng's explicit levels:
    different streams, the same file for OpenEXR and OpenImageIO."""
    planes = _planes(13)
    path = tmp_path / f"l{level}.exr"
    write_scanline(path, planes, ATTRS, "zip", level=level)
    _same(read_exr(path)[0], planes)
    _same(_oiio(path), planes)


def test_deflate_is_a_zlib_stream():
    import zlib

    from crackbake.exchange import exrzip

    data = np.random.default_rng(2).integers(0, 3, 200_000, dtype=np.uint8).tobytes()
    for level in (None, 1, 2):
        assert zlib.decompress(exrzip.deflate(data, level)) == data


def _crack_like(size: int, seed: int) -> dict[str, np.ndarray]:
    """Planes like a bake's: cracks as thin bright lines on flat ground, their distance field
    and ids; long runs and repeats for the matcher to find (unlike :func:`_planes`)."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size].astype(np.float32) / size
    dist = np.full((size, size), 1.0, np.float32)
    for _ in range(40):
        a, b, c = rng.uniform(-1, 1, 3)
        dist = np.minimum(dist, np.abs(a * x + b * y + c) / np.hypot(a, b)).astype(np.float32)
    mask = np.clip(1.0 - dist * 200.0, 0.0, 1.0)
    return {"crack.distance.V": dist, "crack.mask.V": mask.astype(np.float16),
            "crack.id.V": np.floor(dist * 50).astype(np.float32),
            "crack.normal.NX": (np.sin(40 * dist) * mask).astype(np.float16)}  # fmt: skip


def test_concurrent_writes_give_the_same_bytes(tmp_path):
    # ISA-L's deflate gave different (valid) streams for the same chunk when two of its calls
    # ran at once (exrzip.ZIP_LEVEL): files written side by side on threads must still be byte
    # for byte the one a lone write gives.  That showed on real bakes' chunks (1-4 of 12-30
    # files); on this data it did not, so this guards the property, not that one library.
    import threading

    planes = _crack_like(1024, 4)
    alone = tmp_path / "alone.exr"
    write_scanline(alone, planes, {})
    want = alone.read_bytes()
    got: list[bytes] = []

    def write(i: int) -> None:
        for k in range(4):
            path = tmp_path / f"t{i}_{k}.exr"
            write_scanline(path, planes, {}, threads=2)
            got.append(path.read_bytes())

    workers = [threading.Thread(target=write, args=(i,)) for i in range(3)]
    for w in workers:
        w.start()
    for w in workers:
        w.join()
    assert len(got) == 12
    assert sum(g != want for g in got) == 0


def test_uniform_chunks_reuse_the_first_ones_data(tmp_path, monkeypatch):
    """A chunk whose channels each hold one value throughout takes the data of the first
    such chunk of the same values and height: the file is the one each chunk encoded alone
    gives, bit for bit (OpenEXR and OpenImageIO read the pixels back), with fewer deflates."""
    import crackbake.exchange.exrzip as ez

    h, w = 16 * 7 + 5, 40  # a short last chunk, uniform too
    half = np.zeros((h, w), np.float16)
    single = np.full((h, w), 0.05, np.float32)
    ids = np.full((h, w), 7, np.uint32)
    half[20:22, 3:9] = 0.5  # chunk 1 differs
    single[16 * 4 : 16 * 5] = -0.0  # chunk 4: other bits, uniform (-0 is not +0)
    ids[16 * 5 + 3, 11] = 8  # chunk 5 differs in one texel of one channel
    planes = {"a.V": half, "b.V": single, "c.V": ids, "d.V": np.full((h, w), np.nan, np.float16)}
    names = sorted(planes)
    arrays = [np.ascontiguousarray(planes[n]) for n in names]
    rows = [a.view(np.uint8).reshape(h, -1) for a in arrays]
    line = sum(r.shape[1] for r in rows)
    starts = range(0, h, 16)
    calls = []
    real = ez.deflate
    monkeypatch.setattr(ez, "deflate",
                        lambda data, level=None: calls.append(1) or real(data, level))
    alone = ez._chunks(rows, starts, 16, h, line, None)
    n_alone = len(calls)
    reused = ez._chunks(rows, starts, 16, h, line, None, [a.dtype.itemsize for a in arrays])
    assert reused == alone
    assert n_alone == 8 and len(calls) - n_alone == 5  # chunks 0, 1, 4, 5 and the short 7th
    path = tmp_path / "u.exr"
    write_scanline(path, planes, {}, "zip", threads=1)
    _same(read_exr(path)[0], planes)
    img = oiio.ImageInput.open(str(path))
    channel = list(img.spec().channelnames).index("b.V")
    pixels = img.read_image("float")
    img.close()
    np.testing.assert_array_equal(pixels[..., channel], single)
