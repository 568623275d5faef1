"""Weight maps read as data: reduced reading of big maps, one-line errors for broken files."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from PIL import Image

from crackbake.errors import CrackbakeError, CrackbakeWarning
from crackbake.io.images import _read_pillow, load_weight_map
from tests.test_bad_inputs import png_header_only


@pytest.fixture
def gray_png(tmp_path):
    rng = np.random.default_rng(3)
    pixels = rng.integers(0, 256, (250, 301), dtype=np.uint8)
    Image.fromarray(pixels).save(tmp_path / "w.png")
    return tmp_path / "w.png", pixels / 255.0


def test_big_map_is_read_reduced_to_block_means(gray_png):
    path, pixels = gray_png
    with pytest.warns(CrackbakeWarning, match=r"301x250; read reduced to 101x84 \(3x3 blocks"):
        got = load_weight_map(path, max_edge=101)
    assert got.shape == (84, 101)
    # Block means by numpy, partial blocks at the far edges over the texels they hold.
    want = np.array([[pixels[3 * i:3 * i + 3, 3 * j:3 * j + 3].mean() for j in range(101)]
                     for i in range(84)])
    np.testing.assert_allclose(got, want, atol=1e-6)  # OIIO decodes 8-bit to float32


def test_small_map_is_read_whole_without_a_warning(gray_png):
    path, pixels = gray_png
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = load_weight_map(path)
    np.testing.assert_allclose(got, pixels, atol=1e-6)


def test_without_oiio_a_big_map_is_refused_with_its_size(gray_png):
    path, _ = gray_png
    with pytest.raises(CrackbakeError, match=r"weight map is 301x250, over the 101 texels"):
        _read_pillow(path, 101)


def test_header_bomb_and_truncated_png_are_one_line_errors(tmp_path, capfd):
    (tmp_path / "bomb.png").write_bytes(png_header_only(50_000, 50_000))
    with pytest.raises(CrackbakeError, match="could not read the weight map"):
        load_weight_map(tmp_path / "bomb.png")
    Image.fromarray(np.zeros((64, 64, 3), np.uint8) + 7).save(tmp_path / "ok.png")
    data = (tmp_path / "ok.png").read_bytes()
    (tmp_path / "cut.png").write_bytes(data[: len(data) // 2])
    capfd.readouterr()
    with pytest.raises(CrackbakeError, match=r"could not decode the weight map \(") as info:
        load_weight_map(tmp_path / "cut.png")
    assert "\n" not in str(info.value)
    assert "libpng" not in capfd.readouterr().err  # libpng's own line is folded in, not printed
