"""PNG colour tags: data maps carry no colour chunk, colour images carry sRGB + gAMA + cHRM.

The chunks are read back from the file bytes (PNG chunk layout, independent of the writers), and
Pillow and OpenImageIO confirm what they make of the tags.
"""

from __future__ import annotations

import struct
import zlib

import numpy as np
import OpenImageIO as oiio
import pytest
from PIL import Image

from crackbake.errors import CrackbakeError
from crackbake.exchange.png import write_png

COLOUR_CHUNKS = {b"sRGB", b"gAMA", b"cHRM", b"iCCP"}


def png_chunks(path) -> dict[bytes, bytes]:
    """Chunk type -> data of every chunk before IEND, CRCs checked."""
    data = open(path, "rb").read()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    out, i = {}, 8
    while i < len(data):
        (n,) = struct.unpack(">I", data[i : i + 4])
        kind, body = data[i + 4 : i + 8], data[i + 8 : i + 8 + n]
        (crc,) = struct.unpack(">I", data[i + 8 + n : i + 12 + n])
        assert zlib.crc32(kind + body) == crc, kind
        if kind not in out:
            out[kind] = body
        i += 12 + n
    return out


def _image(shape):
    return np.random.default_rng(5).uniform(0, 1, shape).astype(np.float32)


@pytest.mark.parametrize("bits", [8, 16])
@pytest.mark.parametrize("shape", [(6, 10), (6, 10, 3), (6, 10, 4)])
def test_data_maps_are_untagged(tmp_path, bits, shape):
    path = tmp_path / "data.png"
    write_png(path, _image(shape), bits=bits)  # data is the default
    chunks = png_chunks(path)
    assert not COLOUR_CHUNKS & set(chunks), sorted(chunks)
    assert chunks[b"IHDR"][8] == bits
    with Image.open(path) as im:
        assert not {"srgb", "gamma", "chromaticity", "icc_profile"} & set(im.info)


@pytest.mark.parametrize("bits", [8, 16])
def test_colour_images_are_tagged_srgb(tmp_path, bits):
    path = tmp_path / "colour.png"
    write_png(path, _image((6, 10, 3)), bits=bits, color="srgb")
    chunks = png_chunks(path)
    assert COLOUR_CHUNKS - {b"iCCP"} <= set(chunks)
    assert struct.unpack(">I", chunks[b"gAMA"])[0] == 45455  # 1/2.2
    white = struct.unpack(">2I", chunks[b"cHRM"][:8])
    assert white == (31270, 32900)  # D65
    # Chunk order: colour chunks before the image data.
    data = open(path, "rb").read()
    assert data.index(b"sRGB") < data.index(b"IDAT")
    with Image.open(path) as im:
        assert "srgb" in im.info and im.info["gamma"] == pytest.approx(0.45455)


def test_values_are_the_same_whatever_the_tag(tmp_path):
    img = _image((6, 10, 3))
    for bits in (8, 16):
        write_png(tmp_path / "d.png", img, bits=bits)
        write_png(tmp_path / "c.png", img, bits=bits, color="srgb")
        with Image.open(tmp_path / "d.png") as d, Image.open(tmp_path / "c.png") as c:
            if bits == 8:
                np.testing.assert_array_equal(np.asarray(d), np.asarray(c))
        a = oiio.ImageInput.open(str(tmp_path / "d.png")).read_image("uint16")
        b = oiio.ImageInput.open(str(tmp_path / "c.png")).read_image("uint16")
        np.testing.assert_array_equal(a, b)


def test_unknown_colour_is_refused(tmp_path):
    with pytest.raises(CrackbakeError, match="'data' or 'srgb'"):
        write_png(tmp_path / "x.png", _image((4, 4)), color="linear")
