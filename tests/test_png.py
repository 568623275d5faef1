"""Linear PNGs (crackbake.exchange.png), re-read with Pillow and the PNG header itself."""

from __future__ import annotations

import os
import struct
import warnings

import numpy as np
import pytest
from PIL import Image

from crackbake.errors import CrackbakeError, CrackbakeWarning
from crackbake.exchange import (
    write_png,
)

H, W = 24, 40  # not square, so a transposed image cannot pass
MARK_ROW, MARK_COL = 3, 29


def test_png_8bit_gray_round_trip(tmp_path):
    rng = np.random.default_rng(1)
    img = rng.uniform(0, 1, (H, W)).astype(np.float32)
    img[MARK_ROW, MARK_COL] = 1.0
    img[0, 0] = 1.0005  # within tolerance: clipped quietly
    path = tmp_path / "mask.png"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        write_png(path, img)
    with Image.open(path) as im:
        assert im.mode == "L"
        got = np.asarray(im)
    assert got.shape == (H, W)
    assert np.all(np.abs(got / 255.0 - np.clip(img, 0, 1)) <= 0.5 / 255 + 1e-6)
    assert got[MARK_ROW, MARK_COL] == 255 and got[0, 0] == 255


def test_png_16bit_gray_round_trip(tmp_path):
    rng = np.random.default_rng(2)
    img = rng.uniform(0, 1, (H, W))  # float64 accepted
    path = tmp_path / "height.png"
    write_png(path, img, bits=16, compression_level=1)
    with Image.open(path) as im:
        assert im.mode == "I;16"
        got = np.asarray(im).astype(np.float64)
    # OIIO scales in float32, so rounding is to nearest within ~0.005 of a step.
    assert np.all(np.abs(got / 65535.0 - img) <= 0.505 / 65535)


def _png_ihdr(path) -> tuple[int, int, int, int]:
    data = open(path, "rb").read(33)
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and data[12:16] == b"IHDR"
    w, h, depth, colour = struct.unpack(">IIBB", data[16:26])
    return w, h, depth, colour


def test_png_16bit_rgb_and_8bit_rgba(tmp_path):
    rng = np.random.default_rng(3)
    rgb = rng.uniform(0, 1, (H, W, 3)).astype(np.float32)
    path = tmp_path / "normal16.png"
    write_png(path, rgb, bits=16)
    assert _png_ihdr(path) == (W, H, 16, 2)  # 16-bit truecolour
    with Image.open(path) as im:
        # Pillow reads 16-bit RGB only as 8-bit: the high byte of each 16-bit sample.
        got8 = np.asarray(im.convert("RGB")).astype(int)
    q16 = np.round(rgb.astype(np.float64) * 65535).astype(int)
    assert np.all(np.abs(got8 - (q16 >> 8)) <= 1)

    rgba = rng.uniform(0, 1, (H, W, 4)).astype(np.float32)
    path = tmp_path / "rgba.png"
    write_png(path, rgba)
    assert _png_ihdr(path) == (W, H, 8, 6)
    with Image.open(path) as im:
        got = np.asarray(im)
    assert np.all(np.abs(got / 255.0 - rgba) <= 0.5 / 255 + 1e-6)

    u8 = (rng.uniform(0, 1, (H, W, 3)) * 255).astype(np.uint8)
    path = tmp_path / "u8.png"
    write_png(path, u8)
    with Image.open(path) as im:
        assert np.array_equal(np.asarray(im), u8)


def test_png_out_of_range_warns_and_clips(tmp_path):
    img = np.full((H, W), 0.5, np.float32)
    img[1, 2] = 1.2
    img[2, 3] = -0.3
    img[4, 5] = np.nan
    path = tmp_path / "clipped.png"
    with pytest.warns(CrackbakeWarning, match="outside"):
        write_png(path, img)
    with Image.open(path) as im:
        got = np.asarray(im)
    assert got[1, 2] == 255 and got[2, 3] == 0 and got[4, 5] == 0 and got[0, 0] == 128


def test_png_compression_level_and_bad_inputs(tmp_path):
    y, x = np.mgrid[0:256, 0:256] / 255.0
    img = np.stack([x, y, x * y], -1)
    write_png(tmp_path / "l0.png", img, compression_level=0)
    write_png(tmp_path / "l9.png", img, compression_level=9)
    assert os.path.getsize(tmp_path / "l0.png") > 2 * os.path.getsize(tmp_path / "l9.png")
    for kwargs in (
        {"image": img, "bits": 12},
        {"image": np.zeros((4, 4, 5))},
        {"image": img, "compression_level": 11},
        {"image": np.zeros((4, 4), np.int32)},
    ):
        with pytest.raises(CrackbakeError):
            write_png(tmp_path / "bad.png", **kwargs)
