"""The in-memory PNG encoder (crackbake.exchange.pngenc): read back bit-exact by Pillow and by
OpenImageIO, sRGB only when asked."""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image

from crackbake.errors import CrackbakeError
from crackbake.exchange.pngenc import png_bytes


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


def test_srgb_chunk_only_when_asked():
    a = np.zeros((2, 2, 3), np.uint8)
    assert b"sRGB" in png_bytes(a, srgb=True)
    plain = png_bytes(a)
    assert all(c not in plain for c in (b"sRGB", b"gAMA", b"cHRM", b"iCCP"))


def test_bad_input_is_refused():
    with pytest.raises(CrackbakeError, match="uint8 or uint16"):
        png_bytes(np.zeros((2, 2), np.float32))
    with pytest.raises(CrackbakeError, match="uint8 or uint16"):
        png_bytes(np.zeros((2, 2, 5), np.uint8))
