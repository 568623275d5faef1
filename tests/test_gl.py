"""EGL context creation and its error messages, with the real libraries (no mocks).

Missing libraries are reproduced with glcontext's and Mesa's own environment overrides in a child
process, so the message a user sees is exactly what is checked.
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from crackbake.bake.context import (
    GLScope,
    create_context,
    renderer_info,
    shader_dir,
    shader_source,
)

PROBE = (
    "import sys\n"
    "from crackbake.bake.context import create_context\n"
    "from crackbake.bake.egl_ahead import start\n"
    "sys.argv[1:] == ['ahead'] and start()\n"
    "from crackbake.errors import CrackbakeError\n"
    "try:\n"
    "    create_context()\n"
    "except CrackbakeError as e:\n"
    "    print(e)\n"
)


def probe(*args: str, **env: str) -> str:
    r = subprocess.run([sys.executable, "-c", PROBE, *args], capture_output=True, text=True,
                       env={**os.environ, **env}, timeout=60)
    return r.stdout.strip()


def _renderer_is_mesa() -> bool:
    ctx = create_context()
    try:
        return "mesa" in ctx.info["GL_VENDOR"].lower() or "llvmpipe" in ctx.info["GL_RENDERER"]
    finally:
        ctx.release()


def test_context_is_opengl_43_or_later():
    ctx = create_context()
    try:
        assert ctx.version_code >= 430
        info = renderer_info(ctx)
        assert info["renderer"] and info["version"]
    finally:
        ctx.release()


@pytest.mark.parametrize(
    ("env", "names"),
    [
        ({"GLCONTEXT_LINUX_LIBEGL": "/nonexistent/libEGL.so.1"}, "libegl1"),
        ({"GLCONTEXT_LINUX_LIBGL": "/nonexistent/libGL.so.1"}, "libgl1"),
        ({"__EGL_VENDOR_LIBRARY_FILENAMES": "/nonexistent.json"}, "libegl-mesa0"),
        ({"LIBGL_DRIVERS_PATH": "/nonexistent"}, "libgl1-mesa-dri"),
    ],
)
@pytest.mark.parametrize("ahead", [False, True], ids=["alone", "display-ahead"])
def test_missing_libraries_name_the_package_and_the_install_line(env, names, ahead):
    if "LIBGL_DRIVERS_PATH" in env and not _renderer_is_mesa():
        # Mesa's own override: a GPU vendor's EGL (NVIDIA's) never reads it, so the context opens
        pytest.skip("the renderer is not Mesa: LIBGL_DRIVERS_PATH does not apply")
    # the command's display thread (egl_ahead) fails silently: the context says the same
    msg = probe(*(["ahead"] if ahead else []), **env)
    assert f"(package {names}" in msg
    assert "apt-get install -y libegl1 libegl-mesa0 libgl1 libgl1-mesa-dri libgbm1" in msg
    assert "\n" not in msg


def test_the_display_ahead_initialises_the_display_the_context_then_opens():
    code = (
        "import time\n"
        "from crackbake.bake import egl_ahead\n"
        "from crackbake.bake.context import create_context\n"
        "thread = egl_ahead.start()\n"
        "print(egl_ahead.start() is None)\n"  # one thread a process
        "ctx = create_context()\n"
        "print(thread.is_alive(), ctx.version_code >= 430)\n"
        "t = time.perf_counter(); ok = egl_ahead.initialize_display()\n"
        "print(ok, time.perf_counter() - t < 0.5)\n"  # initialised: no driver start again
        "ctx.release()\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=60, check=True).stdout.split()
    assert out == ["True", "False", "True", "True", "True"]


def test_the_display_ahead_follows_the_runs_device_and_library():
    from crackbake.bake.egl_ahead import device_index, initialize_display, start

    assert device_index({}) == 0
    assert device_index({"GLCONTEXT_DEVICE_INDEX": "2"}) == 2
    assert device_index({"CRACKBAKE_EGL_DEVICE": " 1 ", "GLCONTEXT_DEVICE_INDEX": "2"}) == 1
    assert device_index({"CRACKBAKE_EGL_DEVICE": "gpu"}) is None
    assert start({"CRACKBAKE_EGL_DEVICE": "gpu"}) is None  # create_context refuses it itself
    assert start({"CRACKBAKE_EGL_AHEAD": "0"}) is None  # turned off
    assert initialize_display(index=99) is False  # no such device: nothing raised
    assert initialize_display("/nonexistent/libEGL.so.1") is False


def test_shaders_are_found():
    assert (shader_dir() / "crack_bake.frag").is_file()
    assert "#version 430" in shader_source("crack_bake.vert")


def test_scope_releases_its_objects_on_error_and_keeps_the_shared_context(gl_ctx):
    kept = []
    with pytest.raises(RuntimeError), GLScope(gl_ctx) as gl:
        kept.append(gl.keep(gl.ctx.buffer(reserve=64)))
        kept.append(gl.keep(gl.ctx.texture((4, 4), 1, dtype="f4")))
        raise RuntimeError("draw failed")
    # moderngl marks released objects with an invalid glo.
    assert all(obj.glo == 0 or obj.mglo is None or type(obj.mglo).__name__ == "InvalidObject"
               for obj in kept)
    assert gl_ctx.error == "GL_NO_ERROR"
    with GLScope(gl_ctx) as gl:
        assert gl.ctx is gl_ctx
        gl.keep(gl.ctx.buffer(reserve=16))


def test_scope_without_a_context_makes_and_releases_its_own():
    with GLScope() as gl:
        ctx = gl.ctx
        assert ctx.version_code >= 430
        gl.keep(ctx.buffer(reserve=16))
    assert gl.ctx is None


def test_finish_waits_for_the_draw_and_lets_other_threads_run(gl_ctx):
    # moderngl holds the GIL while llvmpipe renders; finish() waits through ctypes instead, so
    # a Python thread (the write stage's encoders, the stress bake's rows) keeps running: its
    # longest stall during the wait stays a small part of the wait.
    import threading
    import time

    import numpy as np

    from crackbake.bake.context import _gl_finish, finish

    assert _gl_finish() is not None  # glvnd's libOpenGL: the EGL set-up test_context needs
    with GLScope(gl_ctx) as gl:
        prog = gl.keep(gl.ctx.program(
            vertex_shader="#version 330\nin vec2 p; void main() { gl_Position = vec4(p, 0, 1); }",
            fragment_shader="#version 330\nout vec4 c; uniform int n; void main() { float s = 0;"
                            " for (int i = 0; i < n; ++i) s += sin(float(i) * gl_FragCoord.x);"
                            " c = vec4(s > -1e9 ? 1.0 : 0.0); }"))  # fmt: skip
        vbo = gl.keep(gl.ctx.buffer(np.array([-1, -1, 3, -1, -1, 3], np.float32)))
        vao = gl.keep(gl.ctx.vertex_array(prog, [(vbo, "2f", "p")]))
        tex = gl.keep(gl.ctx.texture((1024, 1024), 1, dtype="f4"))
        fbo = gl.keep(gl.ctx.framebuffer([tex]))
        fbo.use()

        def timed(n: int) -> tuple[float, float, np.ndarray]:
            """The wait in finish() for a draw of ``n`` iterations a pixel, the spinning
            thread's longest stall during it, and the pixels drawn."""
            prog["n"].value = n
            stall, stop, window = [0.0], threading.Event(), threading.Event()

            def spin():
                last = time.perf_counter()
                while not stop.is_set():
                    now = time.perf_counter()
                    if window.is_set():
                        stall[0] = max(stall[0], now - last)
                    last = now

            thread = threading.Thread(target=spin)
            thread.start()
            try:
                fbo.clear(0.0)
                gl_ctx.finish()
                vao.render()
                window.set()
                start = time.perf_counter()
                finish(gl_ctx)
                waited = time.perf_counter() - start
                window.clear()
            finally:
                stop.set()
                thread.join()
            return waited, stall[0], np.frombuffer(fbo.read(components=1, dtype="f4"), np.float32)

        # 600 iterations keep llvmpipe busy for a good part of a second; a GPU draws them in
        # milliseconds (17 ms on an H200), so the draw grows until the wait can show a stall.
        n = 600
        waited, stall, pixels = timed(n)
        while waited < 0.05 and n < 600 * 4**6:
            n *= 4
            waited, stall, pixels = timed(n)
    assert (pixels == 1.0).all()  # the draw was complete
    assert waited > 0.05, waited  # long enough for a stall to show
    assert stall < 0.5 * waited, (stall, waited)


def test_the_context_made_ahead_is_the_runs_and_draws_as_glcontexts_does():
    """The command's thread creates the run's context (egl_ahead.make_context); the run's first
    create_context takes it, once, and draws what a context of glcontext's draws; with
    CRACKBAKE_EGL_AHEAD=display the thread only initialises the display."""
    code = (
        "import hashlib, os, sys\n"
        "import numpy as np\n"
        "from crackbake.bake import egl_ahead\n"
        "from crackbake.bake.context import create_context, renderer_info\n"
        "thread = egl_ahead.start()\n"
        "thread.join(30)\n"
        "made = bool(egl_ahead._made)\n"
        "def draw(ctx):\n"
        "    prog = ctx.program(vertex_shader='#version 430\\nin vec2 p; out vec2 q;"
        " void main() { q = p; gl_Position = vec4(p, 0.0, 1.0); }',\n"
        "        fragment_shader='#version 430\\nin vec2 q; out vec4 c;"
        " void main() { c = vec4(q * 0.5 + 0.5, sin(q.x * 40.0), 1.0); }')\n"
        "    vbo = ctx.buffer(np.array([-0.9, -0.8, 0.7, -0.6, 0.1, 0.95], 'f4'))\n"
        "    vao = ctx.vertex_array(prog, [(vbo, '2f', 'p')])\n"
        "    fbo = ctx.framebuffer([ctx.texture((97, 61), 4, dtype='f4')])\n"
        "    fbo.use(); ctx.clear(0.1, 0.2, 0.3, 1.0); vao.render()\n"
        "    return hashlib.sha256(fbo.read(components=4, dtype='f4')).hexdigest()\n"
        "first = create_context()\n"
        "a, info_a = draw(first), renderer_info(first)\n"
        "first.release()\n"
        "second = create_context()\n"  # the thread's context is taken once: glcontext's now
        "b, info_b = draw(second), renderer_info(second)\n"
        "second.release()\n"
        "print(made, not egl_ahead._made, a == b, info_a == info_b)\n"
    )
    run = lambda env: subprocess.run([sys.executable, "-c", code], capture_output=True,  # noqa: E731
                                     text=True, timeout=60, check=True,
                                     env={**os.environ, **env}).stdout.split()  # fmt: skip
    assert run({}) == ["True", "True", "True", "True"]
    assert run({"CRACKBAKE_EGL_AHEAD": "display"})[:2] == ["False", "True"]
