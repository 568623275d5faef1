"""Headless OpenGL: the EGL context and the GLSL sources in ``shaders/``.

Always EGL (``backend='egl'``): it needs no display, runs on Mesa llvmpipe on CPU-only machines
and on the GPU's own driver where there is one.  ``CRACKBAKE_EGL_DEVICE`` (or glcontext's
``GLCONTEXT_DEVICE_INDEX``) picks the EGL device when there are several.
"""

from __future__ import annotations

import os
from functools import cache
from pathlib import Path
from types import TracebackType

from crackbake.errors import CrackbakeError

APT_LINE = "apt-get install -y libegl1 libegl-mesa0 libgl1 libgl1-mesa-dri libgbm1"

_HINTS = (
    ("libEGL", "libEGL (package libegl1) is missing"),
    ("libGL", "libGL (package libgl1) is missing"),
    ("found 0 devices", "no EGL vendor library (package libegl-mesa0, or the GPU driver's EGL)"),
    ("0x3001", "the Mesa DRI driver is missing (package libgl1-mesa-dri)"),
)


def create_context():
    """Create a standalone OpenGL 4.3+ context on EGL.

    Returns
    -------
    moderngl.Context

    Raises
    ------
    CrackbakeError
        When EGL, libGL or Mesa's driver is missing, naming the library and the apt-get line.
    """
    import moderngl

    for name in ("CRACKBAKE_EGL_DEVICE", "GLCONTEXT_DEVICE_INDEX"):
        value = os.environ.get(name)
        if value is not None and not value.strip().isdigit():
            # glcontext would fail with int()'s message, and the install hint would mislead.
            raise CrackbakeError(
                f"{name}={value!r} is not an EGL device number; set it to 0, 1, ... or unset it"
            )
    if "CRACKBAKE_EGL_DEVICE" in os.environ:
        os.environ["GLCONTEXT_DEVICE_INDEX"] = os.environ["CRACKBAKE_EGL_DEVICE"].strip()
    from crackbake.bake.egl_ahead import take_context, wait

    wait()  # the command's thread may still be initialising the display (egl_ahead)
    made = take_context()
    if made is not None:
        ctx = _adopt(made)
        if ctx is not None:
            return ctx
    try:
        ctx = moderngl.create_standalone_context(backend="egl", require=430)
    except Exception as exc:
        msg = str(exc)
        device = os.environ.get("GLCONTEXT_DEVICE_INDEX")
        if device is not None and "device" in msg.lower() and "found 0 devices" not in msg:
            raise CrackbakeError(
                f"cannot open EGL device {device} ({msg}); pick another with "
                "CRACKBAKE_EGL_DEVICE or unset it"
            ) from exc
        for needle, hint in _HINTS:
            if needle in msg:
                raise CrackbakeError(
                    f"cannot open a headless OpenGL context: {hint}; install with: {APT_LINE}"
                ) from exc
        raise CrackbakeError(
            f"cannot open a headless OpenGL context ({msg}); on Debian/Ubuntu install: {APT_LINE}"
        ) from exc
    return ctx


def _adopt(made, require: int = 430):
    """A moderngl context on the EGL context the command's thread made
    (:mod:`crackbake.bake.egl_ahead`), current on this thread; None (and that context destroyed)
    where it cannot be used, for :func:`create_context` to open its own as before.

    moderngl takes it as it takes glcontext's (``mgl.create_context(context=loader)``, the call
    its ``init_context`` makes), set up as its standalone context is."""
    from collections import deque

    import moderngl

    from crackbake.bake.egl_ahead import AheadContext

    loader = None
    try:
        loader = AheadContext(made, os.environ.get("GLCONTEXT_LINUX_LIBGL") or "libGL.so.1")
        if not loader.bind():
            raise RuntimeError("eglMakeCurrent refused the context")
        ctx = moderngl.Context.__new__(moderngl.Context)
        ctx.mglo, ctx.version_code = moderngl.mgl.create_context(context=loader)
        ctx._info = ctx._extensions = ctx.extra = ctx._gc_mode = None
        ctx._objects = deque()
        ctx._screen = ctx.fbo = None
        if ctx.version_code < require:
            ctx.release()
            return None
        return ctx
    except Exception:  # noqa: BLE001 - the usual context is opened instead
        if loader is not None:
            loader.release()
        else:
            egl, display, context = made
            egl.eglDestroyContext(display, context)
        return None


class GLScope:
    """The GL objects of one draw, released together when the block ends (errors included).

    ::

        with GLScope(ctx) as gl:
            prog = gl.keep(gl.ctx.program(vertex_shader=..., fragment_shader=...))
            ...

    One context serves a whole run (UV overlap, bake, preview): a scope given the run's context
    releases only what it kept and leaves the context open; a scope given none creates a
    temporary context and releases it too, so standalone calls need no set-up.

    Attributes
    ----------
    ctx : moderngl.Context
        The context to draw with (valid inside the ``with`` block).
    """

    def __init__(self, ctx=None) -> None:
        self.ctx = ctx
        self._own = ctx is None
        self._objects: list = []

    def __enter__(self) -> GLScope:
        if self._own:
            self.ctx = create_context()
        return self

    def keep(self, obj):
        """Register a GL object (buffer, texture, program, ...) for release; returns it."""
        self._objects.append(obj)
        return obj

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if not self._own and self.ctx is not None and self._objects:
            # Rebind framebuffer 0 first: moderngl rebinds the "current" framebuffer after
            # creating one, and a released (deleted) name there raises GL_INVALID_OPERATION in
            # the next draw that shares this context.
            self.ctx.detect_framebuffer(0).use()
        # Reverse order of creation: framebuffers before their attachments, VAOs before buffers.
        while self._objects:
            self._objects.pop().release()
        if self._own and self.ctx is not None:
            self.ctx.release()
            self.ctx = None


def finish(ctx) -> None:
    """Wait for ``ctx``'s GL work, letting other Python threads run meanwhile.

    moderngl holds the GIL in every call, ``Context.finish`` and the readbacks included, so
    while llvmpipe rendered (the crack pass, the stress bake, the preview: seconds at 4096² or
    1.5M faces) the run's other threads stood still at their next Python line: the encoders
    between chunks, the stress bake's rows, the sidecar.  ``glFinish`` called through
    :mod:`ctypes` releases the GIL while it waits.  ``ctx.finish()`` follows it: a no-op once
    the work is done, and the wait itself where the library is missing or ``ctx`` is not the
    context current on this thread.
    """
    gl_finish = _gl_finish()
    if gl_finish is not None:
        gl_finish()
    ctx.finish()


@cache
def _gl_finish():
    """glvnd's ``glFinish`` (the context current on the calling thread) as a ctypes function,
    or None."""
    import ctypes

    try:
        return ctypes.CDLL("libOpenGL.so.0").glFinish
    except (OSError, AttributeError):
        return None


def renderer_info(ctx) -> dict:
    """Vendor, renderer and version strings, for the manifest."""
    info = ctx.info
    return {
        "vendor": info.get("GL_VENDOR", ""),
        "renderer": info.get("GL_RENDERER", ""),
        "version": info.get("GL_VERSION", ""),
    }


def shader_dir() -> Path:
    """The folder holding the GLSL sources.

    An installed wheel carries them as ``crackbake/shaders``; a source checkout (editable install)
    has them at the repository's top level.
    """
    package = Path(__file__).resolve().parents[1]
    for candidate in (package / "shaders", package.parent / "shaders"):
        if candidate.is_dir():
            return candidate
    raise CrackbakeError(
        "crackbake's GLSL shaders are missing from the installation; reinstall crackbake"
    )


@cache
def shader_source(name: str) -> str:
    """Text of ``shaders/<name>``."""
    return (shader_dir() / name).read_text()
