"""The fused nogil packing kernels equal the numpy paths they replace, texel for texel.

Inputs cover every float16 class the maps can hold (0, 1, fractions, out-of-range, NaN where
the path defines it) and unit normals along the axes (the truncation edges 0.5 and top + 0.5).
"""

from __future__ import annotations

import zlib
from types import SimpleNamespace

import numpy as np
import pytest

from crackbake.exchange import bundle, materials, targets
from crackbake.exchange.halving import base_color_half, normal_half
from crackbake.exchange.packing import (
    half_max,
    lut_planes,
    normal_q,
    quantise_float,
    take_half,
)

RES = 96


def normal_numpy(normal: np.ndarray, bits: int, normal_y: str) -> np.ndarray:
    """Test oracle for :func:`normal_q`: ``n * h + h + 0.5`` truncated, h = top / 2, in numpy."""
    top = 255 if bits == 8 else 65535
    n = np.asarray(normal, np.float32)
    half = np.float32(top / 2)
    q = n * half
    q += half + np.float32(0.5)
    if normal_y == "dx":
        np.subtract(np.float32(top + 1), q[..., 1], out=q[..., 1])  # -y h + h + 0.5
    # Unit vectors give [0.5, top + 0.5]: the cast's truncation is the rounding, no clip needed.
    return q.astype(np.uint8 if bits == 8 else ">u2")


def _halves(rng, nan: bool = True) -> np.ndarray:
    x = rng.random((RES, RES)).astype(np.float16)
    x[:8] = 0
    x[8:12] = 1
    x[12:14] = 1.7  # over range: clipped
    x[14:16] = -0.3
    if nan:
        x[16:18] = np.nan
    return x


def _unit_normals(rng) -> np.ndarray:
    n = rng.normal(size=(RES, RES, 3)).astype(np.float32)
    axes = [(0, 0, 1), (0, 0, -1), (1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0)]
    n[:6] = np.array(axes, np.float32)[:, None, :]
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


@pytest.fixture(scope="module")
def maps():
    rng = np.random.default_rng(7)
    return SimpleNamespace(
        mask=_halves(rng), occlusion=_halves(rng), normal=_unit_normals(rng),
        texture=rng.integers(0, 256, (RES, RES, 3)).astype(np.uint8),
    )  # fmt: skip


def _numpy_stack(content, m, bits):
    """The per-plane numpy quantisation stacked: the path :func:`targets._packed` replaces."""
    shape = m.mask.shape
    c0, c1 = targets._const(shape, 0.0, bits), targets._const(shape, 1.0, bits)
    occ = c1 if m.occlusion is None else targets.quantise(m.occlusion, bits)
    planes = {
        "orm": (occ, targets._roughness(m.mask, bits), c0),
        "mask_map": (c0, occ, c1, targets._roughness(m.mask, bits, smooth=True)),
        "metallic_smoothness": (c0, c0, c0, targets._roughness(m.mask, bits, smooth=True)),
    }[content]
    return np.stack(planes, axis=-1)


@pytest.mark.parametrize("content", ["orm", "mask_map", "metallic_smoothness"])
@pytest.mark.parametrize("bits", [8, 16])
@pytest.mark.parametrize("occluded", [True, False])
def test_lut_planes_pack_equals_numpy_stack(maps, content, bits, occluded):
    m = SimpleNamespace(mask=maps.mask, occlusion=maps.occlusion if occluded else None)
    got = targets.pack(content, m, bits)
    want = _numpy_stack(content, m, bits)
    assert got.dtype == (np.uint8 if bits == 8 else np.dtype(">u2"))  # PNG's byte order
    np.testing.assert_array_equal(got, want)


def test_lut_planes_sources_and_constants():
    a = np.array([[0.0, 1.0]], np.float16)
    b = np.array([[0.5, 0.25]], np.float16)
    ident = np.arange(65536, dtype=np.uint16).astype(">u2")  # the bit pattern itself
    out = lut_planes(a, b, [(0, ident), (1, ident), (2, np.full(65536, 7, ">u2"))])
    assert out.dtype == np.dtype(">u2") and out.shape == (1, 2, 3)
    np.testing.assert_array_equal(out[..., 0], a.view(np.uint16))
    np.testing.assert_array_equal(out[..., 1], b.view(np.uint16))
    np.testing.assert_array_equal(out[..., 2], 7)
    assert out.tobytes()[:2] == a.view(np.uint16)[0, 0].astype(">u2").tobytes()


@pytest.mark.parametrize("bits", [8, 16])
@pytest.mark.parametrize("normal_y", ["gl", "dx"])
def test_normal_kernel_equals_numpy(maps, bits, normal_y):
    got = normal_q(maps.normal, bits, flip_y=normal_y == "dx")
    want = normal_numpy(maps.normal, bits, normal_y)
    assert got.dtype == want.dtype
    np.testing.assert_array_equal(got, want)
    # the bake's planar storage (CrackMaps.normal is a (H, W, 3) view of (3, H, W))
    planar = np.moveaxis(np.ascontiguousarray(np.moveaxis(maps.normal, -1, 0)), 0, -1)
    np.testing.assert_array_equal(normal_q(planar, bits, flip_y=normal_y == "dx"), want)
    top = 255 if bits == 8 else 65535
    # (0, 0, 1) -> (half, half, top) whatever the convention; +y flips under dx.
    assert got[0, 0].tolist() == [top // 2 + 1, top // 2 + 1, top]
    assert got[4, 0, 1] == (top if normal_y == "gl" else 0)  # (top + 1) - (top + 0.5)


@pytest.mark.parametrize("occluded", [True, False])
@pytest.mark.parametrize("textured", [True, False])
def test_base_color_kernel_equals_numpy(maps, occluded, textured):
    occ = maps.occlusion if occluded else None
    tex = maps.texture if textured else None
    assert materials._base_color_fused(maps.mask, None, occ, tex) is not None
    got = materials.base_color(maps.mask, occlusion=occ, texture=tex)
    # float32 inputs take the numpy path (unit_u8's arithmetic, the table gather)
    occ32 = None if occ is None else occ.astype(np.float32)
    with np.errstate(invalid="ignore"):  # NaN -> 0 in both paths
        want = materials.base_color(maps.mask.astype(np.float32), occlusion=occ32, texture=tex)
    assert got.dtype == np.uint8
    np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("occluded", [True, False])
@pytest.mark.parametrize("textured", [True, False])
@pytest.mark.parametrize("levels", [1, 2])
def test_preview_pages_equal_numpy(occluded, textured, levels):
    rng = np.random.default_rng(3)
    m = SimpleNamespace(
        mask=_halves(rng, nan=False), occlusion=_halves(rng, nan=False) if occluded else None,
        normal=_unit_normals(rng),
    )  # fmt: skip
    tex = rng.integers(0, 256, (RES, RES, 3)).astype(np.uint8) if textured else None
    size = RES >> levels
    colour, normal = bundle._preview_pages(m, tex, True, size=size)
    # the numpy path: float box filter, base colour, renormalised normal quantised
    small = bundle._smaller(m, size)
    want_colour = materials.base_color(
        small.mask, occlusion=small.occlusion,
        texture=None if tex is None else materials.downsample(tex, size),
    )  # fmt: skip
    assert colour.shape == (size, size, 3) and normal.shape == (size, size, 3)
    np.testing.assert_array_equal(colour, want_colour)
    np.testing.assert_array_equal(normal, normal_numpy(small.normal, 8, "gl"))


def test_half_kernels_on_float32_and_half_agree():
    rng = np.random.default_rng(5)
    mask = _halves(rng, nan=False)
    table = materials.base_color_table(False)
    np.testing.assert_array_equal(
        base_color_half(mask, None, table), base_color_half(mask.astype(np.float32), None, table)
    )
    n = _unit_normals(rng)
    planar = np.moveaxis(np.ascontiguousarray(np.moveaxis(n, -1, 0)), 0, -1)
    assert normal_half(n).shape == (RES // 2, RES // 2, 3)
    np.testing.assert_array_equal(normal_half(planar), normal_half(n))


def test_half_max_equals_numpy():
    rng = np.random.default_rng(11)
    x = (rng.random((64, 64)) * 300 - 100).astype(np.float16)
    assert half_max(x) == float(np.max(x))
    x[5, 7] = np.inf
    assert half_max(x) == np.inf
    x[9, 9] = np.nan
    assert np.isnan(half_max(x)) and np.isnan(np.max(x))
    assert half_max(np.full((3, 3), -2.5, np.float16)) == -2.5


def test_filtered_data_rows_give_the_same_png():
    from crackbake.exchange.pngenc import png_bytes, png_rows

    rng = np.random.default_rng(13)
    depth = (rng.random((RES, RES)) * 0.02).astype(np.float32)
    depth[3, :5] = [np.nan, -1.0, 0.0, 0.02, 1.0]  # NaN -> 0, clipped at both ends
    m = SimpleNamespace(
        mask=_halves(rng), width=(rng.random((RES, RES)) * 0.01).astype(np.float32),
        time=_halves(rng), depth=depth, occlusion=None,
    )  # fmt: skip
    rows = targets.data16_filtered(m, bands=False)
    assert rows.shape == (RES, 1 + 8 * RES) and (rows[:, 0] == 2).all()
    pixels = targets.pack("data", m, 16)
    assert png_rows(rows, RES, 16, 4) == png_bytes(pixels)
    # the unfiltered first row is the big-endian pixels themselves
    assert rows[0, 1:].tobytes() == pixels[0].tobytes()


def test_data_rows_band_by_band_are_the_same_rows_and_file():
    # The write stage's bands (one reused buffer, each band's "above" row carried over) give
    # the very scanlines of the one-pass kernel, and the streamed deflate the very file.
    from crackbake.exchange.packing import data16_bands
    from crackbake.exchange.pngenc import data_compressor, data_deflate, png_bands, png_rows

    rng = np.random.default_rng(14)
    m = SimpleNamespace(
        mask=_halves(rng), width=(rng.random((RES, RES)) * 0.01).astype(np.float32),
        time=_halves(rng), depth=(rng.random((RES, RES)) * 0.02).astype(np.float32),
        occlusion=None,
    )  # fmt: skip
    rows = targets.data16_filtered(m, bands=False)
    scales = targets.data_scales(m)
    args = (m.mask, m.width, m.time, m.depth, targets._data16_luts(), scales["width"],
            scales["depth"])  # fmt: skip
    line = 1 + 8 * RES
    for band_bytes in (1, 3 * line, 5 * line + 7, 10 * RES * line):  # 1 row, 3, 5, all of them
        bands = [b.copy() for b in data16_bands(*args, band_bytes=band_bytes)]
        assert len(bands) == -(-RES // max(1, min(RES, band_bytes // line)))
        assert np.array_equal(np.concatenate(bands), rows)
    whole = png_rows(rows, RES, 16, 4, deflate=data_deflate)
    streamed = png_bands(data16_bands(*args, band_bytes=3 * line), RES, RES, 16, 4,
                         compressor=data_compressor())  # fmt: skip
    assert streamed == whole


def test_data_segments_give_the_rows_and_pixels_whatever_the_threads(tmp_path):
    # The write stage deflates the data map in row segments, each from an empty window, on
    # worker threads: the same scanlines (each segment's first row filtered against the row
    # above it), one valid zlib stream (zlib checks the Adler-32), the same file for any
    # thread count, and read back as the very pixels by OpenImageIO.
    import OpenImageIO as oiio

    from crackbake.exchange.pngenc import png_segments

    rng = np.random.default_rng(15)
    m = SimpleNamespace(
        mask=_halves(rng), width=(rng.random((RES, RES)) * 0.01).astype(np.float32),
        time=_halves(rng), depth=(rng.random((RES, RES)) * 0.02).astype(np.float32),
        occlusion=None,
    )  # fmt: skip
    rows = targets.data16_filtered(m, bands=False)
    for seg_rows in (1, 7, RES - 1, RES):
        segments = targets.data16_segments(m, rows=seg_rows)
        assert len(segments) == -(-RES // seg_rows)
        got = np.concatenate([b.copy() for seg in segments for b in seg()])
        assert np.array_equal(got, rows), seg_rows
    segments = targets.data16_segments(m, rows=7)
    files = {png_segments(segments, RES, RES, 16, 4, threads=t) for t in (0, 1, 3, 8)}
    assert len(files) == 1
    data = files.pop()
    idat = data[data.index(b"IDAT") + 4: data.index(b"IEND") - 8]
    assert zlib.decompress(idat) == rows.tobytes()
    path = tmp_path / "data.png"
    path.write_bytes(data)
    cfg = oiio.ImageSpec()
    cfg.attribute("oiio:UnassociatedAlpha", 1)  # the samples as stored (alpha is time)
    inp = oiio.ImageInput.open(str(path), cfg)
    px = inp.read_image(0, 0, 0, 4, oiio.UINT16)
    inp.close()
    assert np.array_equal(px, targets.pack("data", m, 16))


def test_fused_data_texture_equals_numpy_quantise():
    """The fused 16-bit data texture equals the per-plane numpy quantisation, with float32
    widths past half's 65504 (crack.width is float32: mesh units are unbounded)."""
    rng = np.random.default_rng(17)
    width = (rng.random((RES, RES)) * 2e5).astype(np.float32)
    width[2, :3] = [-1.0, 0.0, 3e5]  # widths are >= 0, but clipped anyway
    depth = (rng.random((RES, RES)) * 0.02).astype(np.float32)
    m = SimpleNamespace(mask=_halves(rng), width=width, time=_halves(rng), depth=depth,
                        occlusion=None)
    scales = targets.data_scales(m)
    assert scales["width"] > 65504
    got = targets.pack("data", m, 16)
    want = np.stack([targets.quantise(m.mask, 16), targets.quantise(width, 16, scales["width"]),
                     targets.quantise(depth, 16, scales["depth"]), targets.quantise(m.time, 16)],
                    axis=-1)
    np.testing.assert_array_equal(got, want)
    assert int(got[..., 1].max()) == 65535  # the widest texel reaches full scale


def quantise_numpy(plane: np.ndarray, bits: int, scale: float) -> np.ndarray:
    """Test oracle for :func:`quantise_float`: the numpy expression it replaced."""
    top = 255 if bits == 8 else 65535
    with np.errstate(all="ignore"):
        q = np.asarray(plane, np.float32) * np.float32(top / scale)
        q += np.float32(0.5)
    np.nan_to_num(q, copy=False, nan=0.0)
    np.clip(q, 0, top, out=q)
    return q.astype(np.uint8 if bits == 8 else ">u2")


@pytest.mark.parametrize("bits", [8, 16])
@pytest.mark.parametrize("scale", [1.0, 0.37, 7.0, 1e-30])
def test_quantise_float_equals_numpy(bits, scale):
    rng = np.random.default_rng(bits)
    edges = np.array([np.nan, np.inf, -np.inf, 0.0, -0.0, 1.0, np.nextafter(1, 0),
                      np.nextafter(1, 2), 0.5 / 255, 254.5 / 255, 3e38, -3e38], np.float32)
    x = np.concatenate([
        edges,
        rng.standard_normal(50_000).astype(np.float32) * 2,
        rng.integers(0, 2**32, 50_000, dtype=np.uint64).astype(np.uint32).view(np.float32),
    ])  # fmt: skip
    want = quantise_numpy(x, bits, scale)
    got = quantise_float(x, bits, scale)
    assert got.dtype == want.dtype
    np.testing.assert_array_equal(got, want)
    depth = x[: 300 * 300].reshape(300, 300)
    maps = SimpleNamespace(mask=np.zeros((300, 300), np.float16), depth=depth,
                           width=np.zeros((300, 300), np.float32), normal=None,
                           occlusion=None)  # fmt: skip
    depth_scale = targets.data_scales(maps)["depth"]
    np.testing.assert_array_equal(targets.pack("depth", maps, bits),
                                  quantise_numpy(depth, bits, depth_scale))  # fmt: skip


@pytest.mark.parametrize("dtype", [np.uint8, ">u2", np.float32])
def test_take_half_equals_numpy_take(dtype):
    rng = np.random.default_rng(3)
    lut = rng.integers(0, 255, 65536).astype(dtype)
    plane = _halves(rng)
    got = take_half(lut, plane)
    assert got.dtype == lut.dtype and got.shape == plane.shape
    np.testing.assert_array_equal(got, np.take(lut, plane.view(np.uint16)))
