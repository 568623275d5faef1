"""The crack bake's render targets, allocated ahead on a second thread while the CPU stages run.

llvmpipe zero-fills every new texture on the calling thread: the crack bake's targets at 4096²
(seven channel targets, 400 MB; 1.2 GB when three RGBA32F surface targets came with them) cost
about 0.4 CPU-s of page faults and ``memset`` (0.9 then) that the bake stage waited for.  Their
sizes are known as soon as the run's ``--res`` and ``--tile`` are, long before the crack network
is, so :class:`TargetPrefetch` creates them in a second EGL context that shares the run
context's objects, on a thread of its own, while the UVs, the simulation mesh, the stress field
and the solver run on the main one.
moderngl holds the GIL in every call; this thread calls EGL and GL through :mod:`ctypes`, which
releases it, so the main thread's Python and numba are never held up by it.

The same thread also allocates the numpy images the bake reads the targets back into, and touches
every page of them (``ndarray.fill`` releases the GIL): 0.1-0.5 CPU-s of page faults the readback
paid.  The bake (:func:`crackbake.bake.raster.bake_cracks`, ``targets=``) then takes each texture
of the size, components and type it needs, wrapped as a moderngl texture of the run context
(``Context.external_texture``).  The storage has the internal format ``ctx.texture`` gives and
the same zero contents, so the pixels are those of targets created in place.  Where the second
context cannot be had (no ``libEGL.so.1``/``libOpenGL.so.0`` by those names, a driver without
shared contexts) or a size was not prefetched, the bake creates its targets as before.
"""

from __future__ import annotations

import ctypes
import logging
import os
import threading
import time
from ctypes import POINTER, byref, c_int, c_uint, c_void_p

import numpy as np

logger = logging.getLogger(__name__)

#: (width, height), components, dtype: a texture as ``ctx.texture(size, components, dtype=...)``.
Spec = tuple[tuple[int, int], int, str]
#: shape, numpy dtype: an image the readback fills.
ArraySpec = tuple[tuple[int, ...], str]

# GL and EGL enums.
_TEXTURE_2D = 0x0DE1
_RED, _RGBA = 0x1903, 0x1908
_UNSIGNED_BYTE, _FLOAT, _HALF_FLOAT = 0x1401, 0x1406, 0x140B
_EGL_CONFIG_ID, _EGL_NONE, _EGL_OPENGL_API = 0x3028, 0x3038, 0x30A2
_EGL_CONTEXT_MAJOR, _EGL_CONTEXT_MINOR, _EGL_PROFILE_MASK, _EGL_CORE = 0x3098, 0x30FB, 0x30FD, 1

#: (components, dtype) -> internal format, format, type: what moderngl's ``ctx.texture`` uses.
_FORMATS = {
    (1, "f1"): (0x8229, _RED, _UNSIGNED_BYTE),  # R8
    (1, "f2"): (0x822D, _RED, _HALF_FLOAT),  # R16F
    (1, "f4"): (0x822E, _RED, _FLOAT),  # R32F
    (4, "f4"): (0x8814, _RGBA, _FLOAT),  # RGBA32F
}


def _libraries():
    """libEGL and libOpenGL (glvnd) with the signatures used here, or None."""
    try:
        egl = ctypes.CDLL("libEGL.so.1")
        gl = ctypes.CDLL("libOpenGL.so.0")
    except OSError:
        return None
    for name in ("eglGetCurrentDisplay", "eglGetCurrentContext", "eglCreateContext"):
        getattr(egl, name).restype = c_void_p
    egl.eglQueryContext.argtypes = [c_void_p, c_void_p, c_int, POINTER(c_int)]
    egl.eglChooseConfig.argtypes = [c_void_p, POINTER(c_int), POINTER(c_void_p), c_int,
                                    POINTER(c_int)]  # fmt: skip
    egl.eglCreateContext.argtypes = [c_void_p, c_void_p, c_void_p, POINTER(c_int)]
    egl.eglMakeCurrent.argtypes = [c_void_p, c_void_p, c_void_p, c_void_p]
    egl.eglDestroyContext.argtypes = [c_void_p, c_void_p]
    egl.eglBindAPI.argtypes = [c_uint]
    gl.glTexImage2D.argtypes = [c_uint, c_int, c_int, c_int, c_int, c_int, c_uint, c_uint,
                                c_void_p]  # fmt: skip
    gl.glGenTextures.argtypes = [c_int, POINTER(c_uint)]
    gl.glDeleteTextures.argtypes = [c_int, POINTER(c_uint)]
    gl.glBindTexture.argtypes = [c_uint, c_uint]
    gl.glGetError.restype = c_uint
    return egl, gl


def _shared_context(egl) -> tuple[c_void_p, c_void_p] | None:
    """A GL 4.3 core context sharing the objects of the context current on this thread (the
    run's), with the same config: (display, context), or None."""
    display = egl.eglGetCurrentDisplay()
    current = egl.eglGetCurrentContext()
    if not display or not current:
        return None
    config_id = c_int(0)
    config = c_void_p(None)  # EGL_NO_CONFIG_KHR when the run's context has none
    if egl.eglQueryContext(display, current, _EGL_CONFIG_ID, byref(config_id)) and config_id.value:
        found = c_int(0)
        wanted = (c_int * 3)(_EGL_CONFIG_ID, config_id.value, _EGL_NONE)
        if not egl.eglChooseConfig(display, wanted, byref(config), 1, byref(found)) or not found:
            return None
    egl.eglBindAPI(_EGL_OPENGL_API)
    attribs = (c_int * 7)(_EGL_CONTEXT_MAJOR, 4, _EGL_CONTEXT_MINOR, 3, _EGL_PROFILE_MASK,
                          _EGL_CORE, _EGL_NONE)  # fmt: skip
    context = egl.eglCreateContext(display, config, current, attribs)
    return (display, context) if context else None


#: Seconds the thread pauses between two textures, so that the run's thread gets the texture
#: lock in between (:meth:`TargetPrefetch._textures`).
_PAUSE = 0.002

#: How much nicer than the run the threads working ahead are: they should take an idle core, not
#: the solver's (on Linux a thread's nice value is its own).
BACKGROUND_NICE = 5


def background() -> None:
    """Lower the calling thread's priority by :data:`BACKGROUND_NICE` (where the OS allows)."""
    try:
        nice = os.getpriority(os.PRIO_PROCESS, 0)  # Linux: the calling thread
        os.setpriority(os.PRIO_PROCESS, 0, min(19, nice + BACKGROUND_NICE))
    except (AttributeError, OSError):
        pass


class ImagePrefetch:
    """Zero-filled numpy images of the given specs, allocated on a thread of their own and every
    page touched there (``ndarray.fill`` releases the GIL); :meth:`take` hands one to the bake.

    For the readback images of a bake whose size is known as soon as the mesh is loaded: the
    run's start-up (imports, EGL, the UV stage) holds the GIL on one core, so the images' page
    faults (0.6 GB at 4096²) fill the other core there instead of competing with the stress
    field and the solver's warm-up for both.
    """

    def __init__(self, arrays: list[ArraySpec]) -> None:
        self._arrays: dict[ArraySpec, list[np.ndarray]] = {}
        self._thread: threading.Thread | None = threading.Thread(
            target=self._allocate, args=(list(arrays),), name="crackbake-images", daemon=True)
        self._thread.start()

    def _allocate(self, arrays: list[ArraySpec]) -> None:
        background()
        for shape, dtype in arrays:
            image = np.empty(shape, dtype)
            image.fill(0)  # faults every page in here, not in the bake's readback
            self._arrays.setdefault((tuple(shape), np.dtype(dtype).str), []).append(image)

    def wait(self) -> None:
        """Block until every image is made."""
        if self._thread is not None:
            self._thread.join()
            self._thread = None

    def take(self, shape: tuple[int, ...], dtype) -> np.ndarray | None:
        """A prefetched zero-filled image of that shape and dtype, or None."""
        self.wait()
        images = self._arrays.get((tuple(shape), np.dtype(dtype).str))
        return images.pop() if images else None

    def close(self) -> None:
        """Wait for the thread and drop the images no bake took."""
        self.wait()
        self._arrays.clear()


class TargetPrefetch:
    """Textures of the given specs, created on a thread of their own in a context that shares
    ``ctx``'s objects, and zero-filled numpy images; :meth:`take` and :meth:`take_array` hand
    them to the bake, :meth:`close` frees what was not taken.  Create it on the thread where
    ``ctx`` is current (the run's main thread).

    Parameters
    ----------
    ctx : moderngl.Context
        The run's context (current on this thread).
    specs : list of ((width, height), components, dtype)
        The textures to create, each as ``ctx.texture(size, components, dtype=dtype)`` would;
        (components, dtype) one of (1, "f1"), (1, "f2"), (1, "f4"), (4, "f4").
    arrays : list of (shape, dtype), optional
        numpy images to allocate and zero-fill (every page touched) on the thread too.
    images : ImagePrefetch, optional
        Images made ahead elsewhere: :meth:`take_array` hands out theirs (``arrays`` is then
        ignored), and :meth:`close` closes it.
    """

    def __init__(self, ctx, specs: list[Spec], arrays: list[ArraySpec] = (),
                 images: ImagePrefetch | None = None) -> None:  # fmt: skip
        self.ctx = ctx
        self._images = images
        if images is not None:
            arrays = ()
        self._ready: dict[Spec, list[int]] = {}
        self._arrays: dict[ArraySpec, list[np.ndarray]] = {}
        self._error: str | None = None
        self._thread: threading.Thread | None = None
        self._lib = _libraries()
        shared = None
        if self._lib is not None:
            # The share group must be ctx's: make it current (a no-op in a run, where it is).
            # Another context may be current here: a released one stays current in EGL until
            # another is made current.  No __exit__: moderngl's would leave none current.
            ctx.__enter__()
            shared = _shared_context(self._lib[0])
        if shared is None:
            self._error = "no shared EGL context"
        specs = [s for s in specs if (s[1], s[2]) in _FORMATS]
        self._thread = threading.Thread(target=self._allocate, args=(shared, specs, arrays),
                                        name="crackbake-targets", daemon=True)  # fmt: skip
        self._thread.start()

    def _allocate(self, shared: tuple, specs: list[Spec], arrays: list[ArraySpec]) -> None:
        """The thread: make the shared context current, create every texture, finish; then
        the images."""
        background()
        if shared is not None:
            self._textures(shared, specs)
        for shape, dtype in arrays:
            image = np.empty(shape, dtype)
            image.fill(0)  # faults every page in here, not in the bake's readback
            self._arrays.setdefault((tuple(shape), np.dtype(dtype).str), []).append(image)

    def _textures(self, shared: tuple, specs: list[Spec]) -> None:
        egl, gl = self._lib
        display, context = shared
        egl.eglBindAPI(_EGL_OPENGL_API)  # per thread
        if not egl.eglMakeCurrent(display, None, None, context):
            self._error = "eglMakeCurrent failed"
            egl.eglDestroyContext(display, context)
            return
        try:
            for k, ((width, height), components, dtype) in enumerate(specs):
                if k:
                    # Mesa holds the share group's texture lock while it zero-fills a texture,
                    # and its lock is not fair: without a pause between two textures a GL call
                    # of the run's thread that needs it (a texture of the UV check, of the
                    # coverage) waits for all of them, not for one.
                    time.sleep(_PAUSE)
                internal, fmt, kind = _FORMATS[(components, dtype)]
                name = c_uint(0)
                gl.glGenTextures(1, byref(name))
                gl.glBindTexture(_TEXTURE_2D, name.value)
                # NULL data: llvmpipe allocates and zero-fills here, without the GIL.
                gl.glTexImage2D(_TEXTURE_2D, 0, internal, width, height, 0, fmt, kind, None)
                gl.glBindTexture(_TEXTURE_2D, 0)
                if gl.glGetError():
                    gl.glDeleteTextures(1, byref(name))
                    self._error = f"glTexImage2D failed for {width}x{height} {dtype}"
                    break
                key = ((width, height), components, dtype)
                self._ready.setdefault(key, []).append(name.value)
            # Complete before another context uses the storage.
            gl.glFinish()
        finally:
            egl.eglMakeCurrent(display, None, None, None)
            # The textures stay: they belong to the share group, which the run's context keeps.
            egl.eglDestroyContext(display, context)

    def wait(self) -> None:
        """Block until the thread has created every texture and image."""
        if self._thread is not None:
            self._thread.join()
            self._thread = None
            if self._error:
                logger.debug("render targets not prefetched: %s", self._error)

    def take(self, gl, size: tuple[int, int], components: int, dtype: str):
        """A prefetched texture of that size, components and dtype as a moderngl texture of
        the run's context, kept in the bake's :class:`~crackbake.bake.context.GLScope` ``gl``
        (its storage deleted with it), or None when there is none left."""
        self.wait()
        names = self._ready.get(((int(size[0]), int(size[1])), components, dtype))
        if not names:
            return None
        name = names.pop()
        gl.keep(_Delete(self._lib[1], name))  # released after the wrapper (reverse order)
        return gl.keep(self.ctx.external_texture(name, tuple(size), components, 0, dtype))

    def take_array(self, shape: tuple[int, ...], dtype) -> np.ndarray | None:
        """A prefetched zero-filled image of that shape and dtype, or None."""
        if self._images is not None:
            return self._images.take(shape, dtype)
        self.wait()
        images = self._arrays.get((tuple(shape), np.dtype(dtype).str))
        return images.pop() if images else None

    def close(self) -> None:
        """Wait for the thread and delete the textures no bake took (the run's context is
        current on this thread)."""
        self.wait()
        for names in self._ready.values():
            for name in names:
                _Delete(self._lib[1], name).release()
        self._ready.clear()
        self._arrays.clear()
        if self._images is not None:
            self._images.close()


class _Delete:
    """Deletes one GL texture name on release (moderngl does not delete external textures)."""

    def __init__(self, gl, name: int) -> None:
        self.gl = gl
        self.name = name

    def release(self) -> None:
        if self.name:
            self.gl.glDeleteTextures(1, byref(c_uint(self.name)))
            self.name = 0
