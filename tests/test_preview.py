"""The preview renders the textured mesh the right way round."""

from __future__ import annotations

import numpy as np

from crackbake.bake.preview import render_preview


def test_dark_texture_corner_shows_in_the_matching_corner_of_the_picture():
    # A square plate facing +z, UVs = xy; the camera looks from +z with y up.
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    f = np.array([[0, 1, 2], [0, 2, 3]])
    uv = v[:, :2].copy()
    n = np.tile([0.0, 0.0, 1.0], (4, 1))
    color = np.full((64, 64, 3), 220, np.uint8)
    color[:16, :16] = 0  # image row 0 = v = 1: the top-left of the texture is UV (0, 1)
    pic = render_preview(v, f, uv, n, color, size=256, view_dir=(0, 0, 1), up=(0, 1, 0))
    gray = pic.mean(axis=2)
    quarter = 256 // 4
    # The plate fills most of the frame; its top-left (x = 0, y = 1) is the picture's top-left.
    top_left = gray[quarter : quarter + 20, quarter : quarter + 20].mean()
    bottom_right = gray[-quarter - 20 : -quarter, -quarter - 20 : -quarter].mean()
    assert top_left < 40 and bottom_right > 120
