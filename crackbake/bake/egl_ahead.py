"""The EGL display initialised, and the run's context created, on a thread while a bake's
modules import.

``eglInitialize`` loads and starts the GL driver: about 25 ms of CPU on Mesa's llvmpipe, and
more on a GPU's driver; creating the context and making it current took another 23 ms on
llvmpipe and 48-54 ms on an H200's driver (docs/benchmarks.md).  All of it was on every run's
path in :func:`crackbake.bake.context.create_context`.  Called through ctypes (which releases
the GIL around each foreign call) on a thread that the ``crackbake`` command starts before it
imports the bake's modules, it runs beside those imports.  The thread creates the context as
glcontext's standalone EGL context does (the same config, OpenGL 4.3 core, no surface), makes it
current once (the driver's set-up of it) and lets it go; the run's thread then takes it
(:func:`take_context`) and hands it to moderngl through a loader (:class:`AheadContext`), as
moderngl would load glcontext's.

Any failure is silent (a missing libEGL, no device, a context refused):
:func:`~crackbake.bake.context.create_context` then opens its own, or meets the failure again and
reports it with its install hint.  Only ctypes and the standard library are imported, so
starting it costs no start-up.
"""

from __future__ import annotations

import os
import threading

#: EGL_EXT_platform_device's platform, as glcontext asks for its standalone display.
EGL_PLATFORM_DEVICE_EXT = 0x313F
#: glcontext's standalone config: a pbuffer-capable RGB8 config with depth, OpenGL renderable.
CONFIG_ATTRIBS = (0x3033, 0x0001, 0x3022, 8, 0x3023, 8, 0x3024, 8, 0x3025, 8, 0x3040, 0x0008,
                  0x3038)
#: EGL_OPENGL_API.
EGL_OPENGL_API = 0x30A2
#: The context the run asks for (crackbake.bake.context: ``require=430``), core profile, as
#: glcontext's standalone context asks for it.
CONTEXT_ATTRIBS = (0x3098, 4, 0x30FB, 3, 0x30FD, 0x0001, 0x3038)
#: How long :func:`wait` waits for the thread at most (seconds): a driver that hangs in its
#: initialisation is left to hang in glcontext's call instead, where it would have anyway.
WAIT_S = 10.0

_started: list[threading.Thread] = []
#: The context the thread made, for the run's thread to take once: (libEGL, display, context).
_made: list[tuple] = []


def device_index(environ: dict | None = None) -> int | None:
    """The EGL device :func:`~crackbake.bake.context.create_context` will open
    (``CRACKBAKE_EGL_DEVICE``, else ``GLCONTEXT_DEVICE_INDEX``, else 0), or None when the
    variable is not a number (create_context refuses it)."""
    env = os.environ if environ is None else environ
    for name in ("CRACKBAKE_EGL_DEVICE", "GLCONTEXT_DEVICE_INDEX"):
        value = env.get(name)
        if value is not None:
            value = value.strip()
            return int(value) if value.isdigit() else None
    return 0


def initialize_display(library: str = "libEGL.so.1", index: int = 0) -> bool:
    """Initialise EGL's display of device ``index`` through ``library``; True on success.

    The calls glcontext's standalone EGL context makes first (``eglQueryDevicesEXT``,
    ``eglGetPlatformDisplayEXT`` on :data:`EGL_PLATFORM_DEVICE_EXT`, ``eglInitialize``),
    without a context.  Never raises.
    """
    return _display(library, index) is not None


def _display(library: str, index: int):
    """(libEGL, the initialised display of device ``index``), or None."""
    import ctypes

    try:
        egl = ctypes.CDLL(library)
        proc = egl.eglGetProcAddress
        proc.restype = ctypes.c_void_p
        proc.argtypes = [ctypes.c_char_p]
        query_address = proc(b"eglQueryDevicesEXT")
        display_address = proc(b"eglGetPlatformDisplayEXT")
        if not query_address or not display_address:
            return None
        query = ctypes.CFUNCTYPE(ctypes.c_uint, ctypes.c_int, ctypes.c_void_p,
                                 ctypes.POINTER(ctypes.c_int))(query_address)
        get_display = ctypes.CFUNCTYPE(ctypes.c_void_p, ctypes.c_uint, ctypes.c_void_p,
                                       ctypes.c_void_p)(display_address)
        count = ctypes.c_int(0)
        if not query(0, None, ctypes.byref(count)) or index >= count.value:
            return None
        devices = (ctypes.c_void_p * count.value)()
        if not query(count.value, devices, ctypes.byref(count)) or index >= count.value:
            return None
        display = get_display(EGL_PLATFORM_DEVICE_EXT, devices[index], None)
        if not display:
            return None
        initialize = egl.eglInitialize
        initialize.restype = ctypes.c_uint
        initialize.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
        if not initialize(display, None, None):
            return None
        return egl, display
    except Exception:  # noqa: BLE001 - only a head start; create_context reports the failure
        return None


def _egl_functions(egl) -> None:
    """Set the argument and result types of the EGL calls made here (ctypes)."""
    import ctypes

    p, u, i = ctypes.c_void_p, ctypes.c_uint, ctypes.c_int
    for name, result, args in (("eglChooseConfig", u, [p, p, p, i, p]), ("eglBindAPI", u, [u]),
                               ("eglCreateContext", p, [p, p, p, p]),
                               ("eglMakeCurrent", u, [p, p, p, p]),
                               ("eglDestroyContext", u, [p, p])):  # fmt: skip
        function = getattr(egl, name)
        function.restype, function.argtypes = result, args


def make_context(library: str = "libEGL.so.1", index: int = 0):
    """The run's EGL context, created on this thread and current on none: (libEGL, display,
    context), or None where EGL refuses a step.  Never raises."""
    import ctypes

    found = _display(library, index)
    if found is None:
        return None
    egl, display = found
    try:
        _egl_functions(egl)
        attribs = (ctypes.c_int * len(CONFIG_ATTRIBS))(*CONFIG_ATTRIBS)
        config, count = ctypes.c_void_p(), ctypes.c_int(0)
        if (not egl.eglChooseConfig(display, attribs, ctypes.byref(config), 1,
                                    ctypes.byref(count)) or count.value < 1
                or not egl.eglBindAPI(EGL_OPENGL_API)):  # fmt: skip
            return None
        context = egl.eglCreateContext(display, config, None,
                                       (ctypes.c_int * len(CONTEXT_ATTRIBS))(*CONTEXT_ATTRIBS))
        if not context:
            return None
        # Current once here (the driver sets the context up on its first binding), then let go:
        # EGL binds a context to one thread at a time.
        if not (egl.eglMakeCurrent(display, None, None, context)
                and egl.eglMakeCurrent(display, None, None, None)):
            egl.eglDestroyContext(display, context)
            return None
        return egl, display, context
    except Exception:  # noqa: BLE001
        return None


def _ahead(library: str, index: int) -> None:
    made = make_context(library, index)
    if made is not None:
        _made.append(made)


def take_context():
    """The context the thread made, once, for the run's thread (:func:`wait` first); None when
    there is none (not started, failed, or taken)."""
    return _made.pop() if _made else None


class AheadContext:
    """A context made by the thread, as moderngl's loader (``moderngl.mgl.create_context(
    context=...)``): glcontext's methods, through ctypes.  Functions are looked up as glcontext
    does (libGL's own symbol, else ``eglGetProcAddress``)."""

    def __init__(self, made, libgl: str) -> None:
        import ctypes

        self.egl, self.display, self.context = made
        self.libgl = ctypes.CDLL(libgl)
        self._proc = self.egl.eglGetProcAddress

    def bind(self) -> bool:
        """Make the context current on the calling thread; True on success."""
        return bool(self.egl.eglMakeCurrent(self.display, None, None, self.context))

    def load_opengl_function(self, name: str) -> int:
        import ctypes

        try:
            return ctypes.cast(getattr(self.libgl, name), ctypes.c_void_p).value or 0
        except AttributeError:
            return self._proc(name.encode()) or 0

    load = load_opengl_function

    def release(self) -> None:
        if self.context:
            self.egl.eglMakeCurrent(self.display, None, None, None)
            self.egl.eglDestroyContext(self.display, self.context)
            self.context = None

    def __enter__(self) -> None:
        if self.context:
            self.bind()

    def __exit__(self, *args) -> None:
        self.egl.eglMakeCurrent(self.display, None, None, None)


def start(environ: dict | None = None) -> threading.Thread | None:
    """:func:`make_context` for the device and library the run's context will use, on a
    daemon thread, started; None when one was already started, the device variable is not a
    number, or ``CRACKBAKE_EGL_AHEAD=0`` turns it off (a driver that would rather initialise
    on the context's thread); ``CRACKBAKE_EGL_AHEAD=display`` initialises the display only (the
    context is then created on the run's thread, by glcontext)."""
    env = os.environ if environ is None else environ
    index = device_index(env)
    mode = env.get("CRACKBAKE_EGL_AHEAD", "1").strip().lower()
    if index is None or _started or mode == "0":
        return None
    library = env.get("GLCONTEXT_LINUX_LIBEGL") or "libEGL.so.1"  # glcontext's own override
    target = initialize_display if mode == "display" else _ahead
    thread = threading.Thread(target=target, args=(library, index), name="crackbake-egl",
                              daemon=True)
    thread.start()
    _started.append(thread)
    return thread


def wait() -> None:
    """Let a started :func:`start` thread finish first (up to :data:`WAIT_S`), so the driver is
    never initialised from two threads at once."""
    for thread in _started:
        thread.join(WAIT_S)
