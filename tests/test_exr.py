"""EXR masters (crackbake.exchange.exr): written with the OpenEXR bindings, re-read with
OpenImageIO (two independent implementations agree, or the file is wrong)."""

from __future__ import annotations

import numpy as np
import OpenImageIO as oiio
import pytest

from crackbake.errors import CrackbakeError
from crackbake.exchange import (
    read_exr,
    write_exr,
)

H, W = 24, 40  # not square, so a transposed image cannot pass
MARK_ROW, MARK_COL = 3, 29


def _half_values(rng: np.random.Generator, shape) -> np.ndarray:
    """Every kind of half: random bit patterns (NaN excluded: NaN != NaN), +-0, inf, subnormal."""
    bits = rng.integers(0, 2**16, size=shape, dtype=np.uint16)
    a = bits.view(np.float16)
    a[np.isnan(a)] = 0
    a.flat[:4] = [-0.0, np.inf, -np.inf, np.float16(6e-8)]
    return a


def _channels() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(7)
    mask = np.zeros((H, W), np.float16)
    mask[MARK_ROW, MARK_COL] = 1.0
    stress = (rng.standard_normal((H, W)) * 1e7).astype(np.float32)
    stress.flat[0] = np.float32(1e-40)  # subnormal float survives too
    return {
        "crack.mask.V": mask,
        "crack.width.V": _half_values(rng, (H, W)),
        "crack.normal.NX": rng.uniform(-1, 1, (H, W)).astype(np.float16),
        "stress.xx.V": stress,
        "crack.depth.V": rng.uniform(0, 1e-2, (H, W)).astype(np.float32),
        "crack.id.V": rng.integers(0, 2**32, (H, W), dtype=np.uint32),
    }


ATTRS = {
    "crackbake:version": "0.1.0",
    "crackbake:units": "mesh",
    "crackbake:uvConvention": "texel (0,0) = uv (0,1)",
    "crackbake:seed": 12345,
    "crackbake:scale": 0.25,
}


def _oiio_read(path) -> tuple[dict[str, np.ndarray], oiio.ImageSpec]:
    """Each channel in its stored type (a mixed-type read in one call crashes OIIO 3.2)."""
    inp = oiio.ImageInput.open(str(path))
    assert inp is not None, oiio.geterror()
    spec = inp.spec()
    out = {}
    for i, name in enumerate(spec.channelnames):
        fmt = spec.channelformat(i)
        out[name] = inp.read_image(0, 0, i, i + 1, fmt)[:, :, 0]
    inp.close()
    return out, spec


def test_exr_round_trip_read_by_openimageio(tmp_path):
    chans = _channels()
    path = tmp_path / "master.exr"
    write_exr(path, chans, ATTRS)
    got, spec = _oiio_read(path)

    assert set(got) == set(chans)
    assert (spec.width, spec.height) == (W, H)
    kinds = {n: str(spec.channelformat(i)) for i, n in enumerate(spec.channelnames)}
    want = {
        np.dtype(np.float16): "half",
        np.dtype(np.float32): "float",
        np.dtype(np.uint32): "uint",
    }
    assert kinds == {n: want[a.dtype] for n, a in chans.items()}
    for name, a in chans.items():
        b = got[name]
        assert b.dtype == a.dtype, name
        # Bit-identical, -0.0 / inf / subnormals included.
        assert np.array_equal(b.view(f"u{a.itemsize}"), a.view(f"u{a.itemsize}")), name

    assert spec.get_string_attribute("compression") == "zip"
    assert spec.getattribute("crackbake:version") == "0.1.0"
    assert spec.getattribute("crackbake:units") == "mesh"
    assert spec.getattribute("crackbake:uvConvention") == ATTRS["crackbake:uvConvention"]
    assert spec.getattribute("crackbake:seed") == 12345
    assert spec.getattribute("crackbake:scale") == pytest.approx(0.25)


def test_exr_row_zero_is_top(tmp_path):
    path = tmp_path / "marker.exr"
    write_exr(path, {"crack.mask.V": _channels()["crack.mask.V"]})
    buf = oiio.ImageBuf(str(path))
    # OIIO's y axis points down from the first scanline; the marker must be where we put it.
    assert buf.getpixel(MARK_COL, MARK_ROW)[0] == 1.0
    px = buf.get_pixels(oiio.FLOAT)[:, :, 0]
    assert np.argwhere(px == 1.0).tolist() == [[MARK_ROW, MARK_COL]]
    assert buf.spec().get_string_attribute("openexr:lineOrder") == "increasingY"


def test_exr_own_reader_and_input_left_alone(tmp_path):
    chans = _channels()
    before = {k: v.copy() for k, v in chans.items()}
    path = tmp_path / "own.exr"
    write_exr(path, chans, ATTRS, compression="zstd")
    # The bindings rewrite the dict they are given; ours must be untouched.
    assert set(chans) == set(before)
    assert all(isinstance(v, np.ndarray) and np.array_equal(v, before[k]) for k, v in chans.items())
    got, header = read_exr(path)
    assert header["compression"] == "zstd"
    assert header["crackbake:units"] == "mesh"
    for name, a in before.items():
        assert got[name].dtype == a.dtype
        assert np.array_equal(got[name].view(f"u{a.itemsize}"), a.view(f"u{a.itemsize}"))


@pytest.mark.parametrize("compression", ["none", "zips", "piz", "zstd"])
def test_exr_other_lossless_compressions_recorded(tmp_path, compression):
    chans = _channels()
    path = tmp_path / f"{compression}.exr"
    write_exr(path, chans, compression=compression)
    got, spec = _oiio_read(path)
    assert spec.get_string_attribute("compression") == compression
    for name, a in chans.items():
        assert np.array_equal(got[name].view(f"u{a.itemsize}"), a.view(f"u{a.itemsize}"))


@pytest.mark.parametrize("compression", ["dwaa", "dwab", "b44", "pxr24", "DWAA"])
def test_exr_lossy_compression_refused(tmp_path, compression):
    path = tmp_path / "lossy.exr"
    with pytest.raises(CrackbakeError, match="lossy") as info:
        write_exr(path, _channels(), compression=compression)
    assert "\n" not in str(info.value)
    assert not path.exists()


def test_exr_bad_inputs(tmp_path):
    path = tmp_path / "bad.exr"
    a = np.zeros((4, 4), np.float16)
    cases = [
        ({}, None, "zip"),
        ({"a": np.zeros((4, 4))}, None, "zip"),  # float64: refused, not silently converted
        ({"a": a, "b": np.zeros((4, 5), np.float32)}, None, "zip"),
        ({"a": np.zeros((4, 4, 3), np.float16)}, None, "zip"),
        ({"a": a}, {"crackbake:big": 2**40}, "zip"),
        ({"a": a}, {"compression": "zip"}, "zip"),
        ({"a": a}, {"crackbake:list": [1, 2]}, "zip"),
        ({"a": a}, None, "lzma"),
    ]
    for chans, attrs, comp in cases:
        with pytest.raises(CrackbakeError) as info:
            write_exr(path, chans, attrs, compression=comp)
        assert "\n" not in str(info.value)
    with pytest.raises(CrackbakeError, match="cannot write"):
        write_exr(tmp_path / "missing" / "x.exr", {"a": a})
    # Strided views are fine (copied to C order).
    write_exr(path, {"a": np.zeros((4, 8), np.float16)[:, ::2]})
    assert read_exr(path)[0]["a"].shape == (4, 4)
