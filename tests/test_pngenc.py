"""The PNG encoder every written PNG goes through (crackbake.exchange.pngenc): read back
bit-exact by Pillow and by OpenImageIO; data maps carry no colour chunk, colour images an sRGB
chunk alone.

The chunks are read back from the file bytes (PNG chunk layout, independent of the encoder),
and Pillow confirms what it makes of the tags.
"""

from __future__ import annotations

import io
import struct
import zlib

import numpy as np
import pytest
from PIL import Image

from crackbake.errors import CrackbakeError
from crackbake.exchange.pngenc import png_bytes

COLOUR_CHUNKS = {b"sRGB", b"gAMA", b"cHRM", b"iCCP"}


def _oiio(data: bytes, tmp_path, nchan, fmt) -> np.ndarray:
    import OpenImageIO as oiio

    path = tmp_path / "x.png"
    path.write_bytes(data)
    cfg = oiio.ImageSpec()
    cfg.attribute("oiio:UnassociatedAlpha", 1)  # alpha as stored, not premultiplied
    inp = oiio.ImageInput.open(str(path), cfg)
    px = inp.read_image(0, 0, 0, nchan, fmt)
    inp.close()
    return px


def png_chunks(data: bytes) -> dict[bytes, bytes]:
    """Chunk type -> data of every chunk up to IEND, CRCs checked, in file order."""
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    out, i = {}, 8
    while i < len(data):
        (n,) = struct.unpack(">I", data[i : i + 4])
        kind, body = data[i + 4 : i + 8], data[i + 8 : i + 8 + n]
        (crc,) = struct.unpack(">I", data[i + 8 + n : i + 12 + n])
        assert zlib.crc32(kind + body) == crc, kind
        out.setdefault(kind, body)
        i += 12 + n
    return out


def _image(shape, dtype=np.uint8):
    top = np.iinfo(dtype).max
    return np.random.default_rng(5).integers(0, top + 1, shape).astype(dtype)


@pytest.mark.parametrize("shape", [(5, 7), (6, 4, 2), (9, 3, 3), (4, 11, 4)])
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, ">u2"])
def test_round_trip_is_exact(tmp_path, shape, dtype):
    rng = np.random.default_rng(len(shape) + shape[0])
    a = rng.integers(0, np.iinfo(np.uint16 if dtype != np.uint8 else np.uint8).max + 1, shape)
    a[: shape[0] // 2] = a[0]  # runs, as real maps have
    a = a.astype(dtype)
    data = png_bytes(a, level=1)
    nchan = 1 if a.ndim == 2 else a.shape[2]
    got = _oiio(data, tmp_path, nchan, "uint8" if a.dtype.itemsize == 1 else "uint16")
    np.testing.assert_array_equal(got.reshape(a.shape), a)
    if a.dtype == np.uint8:
        np.testing.assert_array_equal(np.asarray(Image.open(io.BytesIO(data))), a)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("shape", [(6, 10), (6, 10, 3), (6, 10, 4)])
def test_data_maps_are_untagged(dtype, shape):
    data = png_bytes(_image(shape, dtype))
    chunks = png_chunks(data)
    assert not COLOUR_CHUNKS & set(chunks), sorted(chunks)
    assert chunks[b"IHDR"][8] == 8 * np.dtype(dtype).itemsize
    with Image.open(io.BytesIO(data)) as im:
        assert not {"srgb", "gamma", "chromaticity", "icc_profile"} & set(im.info)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_colour_images_carry_an_srgb_chunk_alone(dtype):
    data = png_bytes(_image((6, 10, 3), dtype), srgb=True)
    chunks = png_chunks(data)
    assert COLOUR_CHUNKS & set(chunks) == {b"sRGB"}
    assert chunks[b"sRGB"] == b"\x00"  # rendering intent 0, perceptual
    assert data.index(b"sRGB") < data.index(b"IDAT")  # colour chunks precede the image data
    with Image.open(io.BytesIO(data)) as im:
        assert "srgb" in im.info


def test_values_are_the_same_whatever_the_tag(tmp_path):
    for dtype in (np.uint8, np.uint16):
        img = _image((6, 10, 3), dtype)
        fmt = "uint8" if dtype == np.uint8 else "uint16"
        a = _oiio(png_bytes(img), tmp_path, 3, fmt)
        b = _oiio(png_bytes(img, srgb=True), tmp_path, 3, fmt)
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(a, img)


def test_compression_level_trades_size():
    y, x = np.mgrid[0:256, 0:256]
    img = np.stack([x // 16 * 16, y // 16 * 16, np.zeros_like(x)], -1).astype(np.uint8)
    assert len(png_bytes(img, level=0)) > 2 * len(png_bytes(img, level=9))


def test_bad_input_is_refused():
    with pytest.raises(CrackbakeError, match="uint8 or uint16"):
        png_bytes(np.zeros((2, 2), np.float32))
    with pytest.raises(CrackbakeError, match="uint8 or uint16"):
        png_bytes(np.zeros((2, 2, 5), np.uint8))
    with pytest.raises(CrackbakeError, match="uint8 or uint16"):
        png_bytes(np.zeros((2, 2), np.int32))


def _map_like(rng: np.random.Generator, shape: tuple, dtype) -> np.ndarray:
    """A crack-map-like image: flat ground, a few sharp strokes and a smooth ramp."""
    top = np.iinfo(dtype).max
    img = np.zeros(shape, dtype)
    img[..., 0] = (np.linspace(0, top, shape[1])[None, :] * np.ones((shape[0], 1))).astype(dtype)
    for _ in range(20):
        r, c = rng.integers(0, shape[0]), rng.integers(0, shape[1] - 40)
        img[r : r + 3, c : c + 40] = rng.integers(0, top, shape[2], endpoint=True)
    return img


@pytest.mark.parametrize(("shape", "dtype"), [((512, 384, 4), np.uint16), ((300, 500, 3), np.uint8),
                                              ((256, 256, 1), np.uint8)])  # fmt: skip
def test_zlib_ng_writes_the_bytes_stdlib_zlib_writes(monkeypatch, shape, dtype):
    """The maps' deflate (level 1, Z_RLE) goes through zlib-ng when it is installed: it must
    give the files stdlib zlib gives, byte for byte (the speed-up changes no output)."""
    pytest.importorskip("zlib_ng")
    from crackbake.exchange import pngenc

    img = _map_like(np.random.default_rng(sum(shape)), shape, dtype)
    assert pngenc._rle_zlib is not zlib  # the fast path is really taken
    fast = png_bytes(img)
    assert png_bytes(img, level=6) == fast  # run lengths only: the level changes nothing
    monkeypatch.setattr(pngenc, "_rle_zlib", zlib)
    assert png_bytes(img) == fast
    assert png_bytes(img, level=6) == fast
    # Decoded by stdlib zlib and the Up filter undone: the pixels round-trip (PIL would narrow
    # 16-bit RGBA to 8 bits).
    idat = fast[fast.index(b"IDAT") + 4 : fast.index(b"IEND") - 8]
    rows = np.frombuffer(zlib.decompress(idat), np.uint8).reshape(shape[0], -1)
    assert (rows[:, 0] == 2).all()
    raw = np.cumsum(rows[:, 1:], axis=0, dtype=np.uint8)  # wraps mod 256, as the filter did
    want = np.ascontiguousarray(img.astype(img.dtype.newbyteorder(">"))).view(np.uint8)
    assert np.array_equal(raw, want.reshape(shape[0], -1))


def test_data_deflate_round_trips():
    """The data texture's deflate (zlib-ng level 3) writes a PNG whose IDAT inflates to the
    very filtered rows the Z_RLE path deflates."""
    from crackbake.exchange.pngenc import data_deflate, png_rows

    img = _map_like(np.random.default_rng(9), (200, 300, 4), np.uint16)
    plain = png_bytes(img)
    idat = plain[plain.index(b"IDAT") + 4 : plain.index(b"IEND") - 8]
    rows = np.frombuffer(zlib.decompress(idat), np.uint8).reshape(200, -1)
    ours = png_rows(rows, 300, 16, 4, deflate=data_deflate)
    assert ours[: ours.index(b"IDAT") - 4] == plain[: plain.index(b"IDAT") - 4]  # same header
    got = ours[ours.index(b"IDAT") + 4 : ours.index(b"IEND") - 8]
    assert zlib.decompress(got) == rows.tobytes()
    assert zlib.crc32(ours[ours.index(b"IDAT") : ours.index(b"IEND") - 8]) == int.from_bytes(
        ours[ours.index(b"IEND") - 8 : ours.index(b"IEND") - 4], "big")


@pytest.mark.parametrize(("shape", "dtype"), [((37, 53, 3), np.uint8), ((29, 47, 4), ">u2"),
                                              ((31, 49, 1), "<u2"), ((1, 45, 2), np.uint8)])
def test_bands_give_the_file_of_all_rows_at_once(monkeypatch, shape, dtype):
    """png_bytes filters and deflates a band of rows at a time (BAND_BYTES): whatever the band
    height (one row, a few, rows that do not divide the height, all), the same file as one
    band of every row, which is the file before bands came in."""
    import crackbake.exchange.pngenc as enc

    img = _map_like(np.random.default_rng(21), shape, np.dtype(dtype))
    if shape[2] == 1:
        img = img[..., 0]  # (H, W): grey
    monkeypatch.setattr(enc, "BAND_BYTES", 1 << 30)
    whole = {level: enc.png_bytes(img, level=level) for level in (1, 6)}
    line = 1 + img[0].size * img.dtype.itemsize
    for band in (1, line, 3 * line + 1, 4 * line):
        monkeypatch.setattr(enc, "BAND_BYTES", band)
        for level, want in whole.items():
            assert enc.png_bytes(img, level=level) == want
    raw = np.frombuffer(zlib.decompress(whole[1][whole[1].index(b"IDAT") + 4 : -16]), np.uint8)
    assert raw.size == img.shape[0] * line


def test_adler32_combine_equals_adler32_of_the_whole():
    from crackbake.exchange.pngenc import adler32_combine

    rng = np.random.default_rng(3)
    for a_len, b_len in ((0, 0), (1, 0), (0, 5), (65521, 3), (100_000, 70_001), (7, 5_552)):
        a, b = rng.bytes(a_len), rng.bytes(b_len)
        assert adler32_combine(zlib.adler32(a), zlib.adler32(b), len(b)) == zlib.adler32(a + b)


def test_one_segment_is_the_data_streams_file():
    from crackbake.exchange.pngenc import data_compressor, png_bands, png_segments

    rows = _image((13, 1 + 8 * 9), np.uint8)
    rows[:, 0] = 2
    whole = png_bands([rows], 9, 13, 16, 4, compressor=data_compressor())
    assert png_segments([lambda: [rows]], 9, 13, 16, 4, threads=2) == whole
    halves = png_segments([lambda: [rows[:6]], lambda: [rows[6:]]], 9, 13, 16, 4)
    assert halves != whole
    assert zlib.decompress(halves[halves.index(b"IDAT") + 4: -16]) == rows.tobytes()
