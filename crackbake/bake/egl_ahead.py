"""The EGL display initialised on a thread while a bake's modules import.

``eglInitialize`` loads and starts the GL driver: about 25 ms of CPU on Mesa's llvmpipe, and
more on a GPU's driver, on every run's path in :func:`crackbake.bake.context.create_context`.
Called through ctypes (which releases the GIL around each foreign call) on a thread that the
``crackbake`` command starts before it imports the bake's modules, it runs beside those imports.
EGL gives one display per device, so glcontext's own ``eglInitialize`` of that display later
finds it initialised and returns at once.

Only the display is prepared here: the context is still glcontext's, created and made current
on the run's thread as before.  Any failure is silent (a missing libEGL, no device):
:func:`~crackbake.bake.context.create_context` meets it again and reports it with its install
hint.  Only ctypes and the standard library are imported, so starting it costs no start-up.
"""

from __future__ import annotations

import os
import threading

#: EGL_EXT_platform_device's platform, as glcontext asks for its standalone display.
EGL_PLATFORM_DEVICE_EXT = 0x313F
#: How long :func:`wait` waits for the thread at most (seconds): a driver that hangs in its
#: initialisation is left to hang in glcontext's call instead, where it would have anyway.
WAIT_S = 10.0

_started: list[threading.Thread] = []


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
    import ctypes

    try:
        egl = ctypes.CDLL(library)
        proc = egl.eglGetProcAddress
        proc.restype = ctypes.c_void_p
        proc.argtypes = [ctypes.c_char_p]
        query_address = proc(b"eglQueryDevicesEXT")
        display_address = proc(b"eglGetPlatformDisplayEXT")
        if not query_address or not display_address:
            return False
        query = ctypes.CFUNCTYPE(ctypes.c_uint, ctypes.c_int, ctypes.c_void_p,
                                 ctypes.POINTER(ctypes.c_int))(query_address)
        get_display = ctypes.CFUNCTYPE(ctypes.c_void_p, ctypes.c_uint, ctypes.c_void_p,
                                       ctypes.c_void_p)(display_address)
        count = ctypes.c_int(0)
        if not query(0, None, ctypes.byref(count)) or index >= count.value:
            return False
        devices = (ctypes.c_void_p * count.value)()
        if not query(count.value, devices, ctypes.byref(count)) or index >= count.value:
            return False
        display = get_display(EGL_PLATFORM_DEVICE_EXT, devices[index], None)
        if not display:
            return False
        initialize = egl.eglInitialize
        initialize.restype = ctypes.c_uint
        initialize.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
        return bool(initialize(display, None, None))
    except Exception:  # noqa: BLE001 - only a head start; create_context reports the failure
        return False


def start(environ: dict | None = None) -> threading.Thread | None:
    """:func:`initialize_display` for the device and library the run's context will use, on a
    daemon thread, started; None when one was already started, the device variable is not a
    number, or ``CRACKBAKE_EGL_AHEAD=0`` turns it off (a driver that would rather initialise
    on the context's thread)."""
    env = os.environ if environ is None else environ
    index = device_index(env)
    if index is None or _started or env.get("CRACKBAKE_EGL_AHEAD", "1").strip() == "0":
        return None
    library = env.get("GLCONTEXT_LINUX_LIBEGL") or "libEGL.so.1"  # glcontext's own override
    thread = threading.Thread(target=initialize_display, args=(library, index),
                              name="crackbake-egl", daemon=True)
    thread.start()
    _started.append(thread)
    return thread


def wait() -> None:
    """Let a started :func:`start` thread finish first (up to :data:`WAIT_S`), so the driver is
    never initialised from two threads at once."""
    for thread in _started:
        thread.join(WAIT_S)
