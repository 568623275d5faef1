"""Render targets allocated ahead on a second thread (crackbake.bake.prefetch), on a real EGL
context: zeroed, renderable, and a bake drawn into them gives the same pixels as one that
creates its own."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import plate_mesh

from crackbake.bake.context import GLScope
from crackbake.bake.crack_targets import image_specs, target_specs
from crackbake.bake.prefetch import ImagePrefetch, TargetPrefetch
from crackbake.bake.raster import bake_cracks
from crackbake.network import Segments


def _segments(n: int, seed: int) -> Segments:
    rng = np.random.default_rng(seed)
    a = rng.random((n, 3)) * [1, 1, 0]
    b = a + (rng.random((n, 3)) - 0.5) * [0.3, 0.3, 0]
    w = rng.random((n, 2)) * 0.02
    return Segments(a=a, b=b, width=w, depth=w * 0.5, time=rng.random((n, 2)),
                    crack_id=np.arange(n, dtype=np.int64))  # fmt: skip


def test_prefetched_textures_are_zeroed_and_renderable(gl_ctx):
    specs = [((64, 32), 4, "f4"), ((64, 32), 1, "f2"), ((64, 32), 1, "f4"), ((64, 32), 1, "f1")]
    prefetch = TargetPrefetch(gl_ctx, specs)
    try:
        with GLScope(gl_ctx) as gl:
            for size, components, dtype in specs:
                tex = prefetch.take(gl, size, components, dtype)
                assert tex is not None, (components, dtype)
                assert (tex.size, tex.components, tex.dtype) == (size, components, dtype)
                fbo = gl.keep(gl.ctx.framebuffer(color_attachments=[tex]))
                kind = {"f1": np.uint8, "f2": np.float16, "f4": np.float32}[dtype]
                before = np.frombuffer(fbo.read(components=components, dtype=dtype), kind)
                assert before.size == 64 * 32 * components and not before.any()
                fbo.use()
                fbo.clear(0.5, 0.5, 0.5, 0.5)
                after = np.frombuffer(fbo.read(components=components, dtype=dtype), kind)
                expect = 128 if dtype == "f1" else 0.5  # R8 stores 0.5 as 128/255
                assert np.all(after.astype(np.float64) == pytest.approx(expect, abs=1))
            # Each spec was prefetched once: a second take finds none.
            assert prefetch.take(gl, (64, 32), 4, "f4") is None
            assert prefetch.take(gl, (32, 32), 1, "f4") is None  # never asked for
    finally:
        prefetch.close()


def test_the_allocation_runs_without_the_gil(gl_ctx):
    """The thread allocates through ctypes: the main thread keeps running Python meanwhile."""
    prefetch = TargetPrefetch(gl_ctx, [((2048, 2048), 4, "f4")] * 2)
    spins = 0
    while prefetch._thread is not None and prefetch._thread.is_alive():
        spins += 1
    prefetch.close()
    # 128 MiB zero-filled takes tens of milliseconds: the loop ran many times meanwhile, or the
    # allocation had already ended (no spin at all) before the loop began.
    assert spins == 0 or spins > 100


def test_prefetched_images_are_zeroed_and_taken_once(gl_ctx):
    prefetch = TargetPrefetch(gl_ctx, [], [((3, 40, 50), "<f4"), ((40, 50), "|u1")])
    image = prefetch.take_array((3, 40, 50), np.float32)
    assert image.shape == (3, 40, 50) and image.dtype == np.float32 and not image.any()
    assert prefetch.take_array((3, 40, 50), np.float32) is None
    assert prefetch.take_array((40, 50), np.uint8) is not None
    assert prefetch.take_array((40, 50), np.float16) is None  # never asked for
    prefetch.close()


def test_images_made_ahead_are_handed_out_by_the_targets(gl_ctx):
    # A run makes the readback images before its GL context exists (ImagePrefetch) and hands
    # them to the targets' prefetch later: take_array gives those, each once; the targets'
    # own image list is not made a second time, and close closes the images too.
    images = ImagePrefetch([((3, 40, 50), "<f4"), ((40, 50), "<f2")])
    prefetch = TargetPrefetch(gl_ctx, [], [((3, 40, 50), "<f4")], images=images)
    image = prefetch.take_array((3, 40, 50), np.float32)
    assert image is not None and image.shape == (3, 40, 50) and not image.any()
    assert prefetch.take_array((3, 40, 50), np.float32) is None  # the targets made none
    half = prefetch.take_array((40, 50), np.float16)
    assert half.dtype == np.float16 and not half.any()
    prefetch.close()
    assert images._thread is None and images._arrays == {}


def test_close_frees_what_the_bake_did_not_take(gl_ctx):
    prefetch = TargetPrefetch(gl_ctx, [((128, 128), 4, "f4")] * 3)
    with GLScope(gl_ctx) as gl:
        assert prefetch.take(gl, (128, 128), 4, "f4") is not None
    prefetch.close()
    with GLScope(gl_ctx) as gl:
        assert prefetch.take(gl, (128, 128), 4, "f4") is None


@pytest.mark.parametrize("tile", [256, 128])  # one band, and four
def test_bake_into_prefetched_targets_gives_the_same_pixels(gl_ctx, tile):
    res = 256
    m = plate_mesh(6, wobble=0.02, seed=3)
    v, f = np.asarray(m.vertices, float), np.asarray(m.faces)
    uv = v[:, :2] * 0.9 + 0.05  # a gutter all round: the dilation runs
    normals = np.tile([0.0, 0.0, 1.0], (len(v), 1))
    tangents = np.tile([1.0, 0.0, 0.0, 1.0], (len(v), 1))
    segs = _segments(30, 5)
    kw = dict(max_distance=0.05, tile=tile, ctx=gl_ctx, normals=normals, tangents=tangents)
    own = bake_cracks(v, f, uv, segs, res, **kw)
    prefetch = TargetPrefetch(gl_ctx, target_specs(res, tile, with_normals=True),
                              image_specs(res, with_normals=True))
    try:
        taken = bake_cracks(v, f, uv, segs, res, targets=prefetch, **kw)
        # The bake took every texture and image prefetched for it.
        assert prefetch._ready == {k: [] for k in prefetch._ready}
        assert prefetch._arrays == {k: [] for k in prefetch._arrays}
    finally:
        prefetch.close()
    assert own.mask.any() and own.normal is not None
    for name, image in own.channels().items():
        other = taken.channels()[name]
        assert other.dtype == image.dtype and other.tobytes() == image.tobytes(), name
    assert np.array_equal(own.inside, taken.inside)
