"""The ``crackbake`` console script: a platform check, then the command.

crackbake needs Linux (headless OpenGL through EGL, ``fcntl`` locks on the output folder,
``renameat2(RENAME_EXCHANGE)`` for its atomic swap).  Elsewhere the modules behind the command
would fail to import with a traceback; this entry point says so in one line instead, before
importing any of them.
"""

from __future__ import annotations

import os
import sys


def platform_error(platform: str = sys.platform) -> str | None:
    """The one-line error for a system crackbake does not run on, or None on Linux."""
    if platform.startswith("linux"):
        return None
    return (f"crackbake: error: crackbake runs on Linux only (it needs EGL, fcntl and renameat2); "
            f"this system is '{platform}'; run it on Linux, in a Linux container or in WSL2")


def main() -> None:
    """Run the ``crackbake`` command, or exit 2 with one line on a system other than Linux."""
    error = platform_error(sys.platform)
    if error:
        print(error, file=sys.stderr)
        raise SystemExit(2)
    if sys.argv[1:] in (["--version"], ["-V"]):
        # What click's version option prints, without importing click and the command's
        # modules: a version check (scripts, the Blender add-on) costs the interpreter only.
        from crackbake import __version__

        print(f"crackbake, version {__version__}")
        return
    huge_pages()
    quiet_blas()
    numba_skips_coverage()
    if bakes(sys.argv[1:]):
        # the GL driver starts on a thread while the command's modules import
        from crackbake.bake.egl_ahead import start

        start()
        fewer_collections()
        if not _rebakes(sys.argv[1:]):
            # and the run's heap is faulted in on another (a re-bake has no stress field or
            # solver, whose arrays are most of what its thread touches first)
            from crackbake.prefault import start as prefault

            prefault(_res(sys.argv[1:]))
    from crackbake.cli import main as command

    try:
        command(prog_name="crackbake")
    except SystemExit as exc:
        leave(exc.code)
    leave(0)


#: glibc's tunable that makes malloc ask for transparent huge pages (glibc 2.35 and later; an
#: older glibc ignores it).
HUGE_PAGES = "glibc.malloc.hugetlb=1"
#: Arguments that only print (help, the version): no run to speed up.
_NO_RUN = {"--help", "-h", "--version", "-V"}
#: The group's named commands (crackbake.cli.group.COMMANDS), not restarted: their buffers are
#: numpy's (already in huge pages) or small.
SUBCOMMANDS = ("inspect", "decals", "tile", "batch", "blender-addon")
#: The smallest ``--res`` restarted for (the default, 2048²): below it the render targets are
#: too small for their freeing to outweigh a second interpreter start (at 512², 4 MB each).
HUGE_PAGES_RES = 2048


def huge_pages() -> None:
    """Restart this process once, in place (same pid, arguments and descriptors), with glibc's
    malloc on transparent huge pages, when it is the ``crackbake`` command running a job.

    glibc reads its tunables only when a process starts.  Without them the GL driver's
    render targets (llvmpipe keeps textures in malloc'd memory, 256 MB per 4096² float target)
    are mapped in 4 KiB pages, which the kernel frees one by one at the exit: after the README
    bake the last event to the process's end took 0.13-0.35 s on a loaded 2-core machine
    against 0.07-0.12 s with the tunable (a 4096² float framebuffer alone: 0.12-0.30 s against
    0.02-0.08 s), for a bare interpreter's start before the first stage (about 20-30 ms of
    CPU; docs/benchmarks.md, "The gap after total").  The process keeps its pid, arguments and
    descriptors; nothing has been read or written yet.  Only a bake of ``--res`` 2048 or more
    restarts (smaller targets free quickly).  Left alone: a help or version
    call, a caller that set ``glibc.malloc.hugetlb`` itself, an interpreter not on glibc, and
    ``main`` called from another program (only ``crackbake`` and ``python -m crackbake``
    restart, with their own command line).
    """
    tunables = os.environ.get("GLIBC_TUNABLES", "")
    argv = sys.argv[1:]
    if ("glibc.malloc.hugetlb" in tunables or not bakes(argv) or not sys.executable
            or _res(argv) < HUGE_PAGES_RES or not _is_command() or gpu_present()):
        return
    try:
        if not os.confstr("CS_GNU_LIBC_VERSION").startswith("glibc"):
            return
    except (ValueError, OSError):
        return
    os.environ["GLIBC_TUNABLES"] = f"{tunables}:{HUGE_PAGES}" if tunables else HUGE_PAGES
    sys.stdout.flush()
    sys.stderr.flush()
    try:
        os.execv(sys.executable, [sys.executable, *sys.orig_argv[1:]])
    except OSError:  # no restart: the run goes on in 4 KiB pages
        pass


def bakes(argv: list[str]) -> bool:
    """True when ``argv`` runs the default command (a bake or re-bake), not a named command, a
    help or a version call: the runs that open a GL context at once."""
    return bool(argv) and argv[0] not in SUBCOMMANDS and _NO_RUN.isdisjoint(argv)


def gpu_present(dev: str = "/dev") -> bool:
    """True when the machine shows a GPU's device node (NVIDIA's, or a DRM render node).

    There the driver keeps the render targets in the GPU's own memory, so the restart of
    :func:`huge_pages` would only cost its second interpreter start: on an H200 VM the README
    bake's start-up grew by 0.09 s with it and its exit gained nothing (docs/benchmarks.md,
    "On a GPU").  Mesa's llvmpipe, which needs no device node, is the case the restart is for.
    """
    if os.path.exists(os.path.join(dev, "nvidia0")):
        return True
    try:
        return any(name.startswith("renderD") for name in os.listdir(os.path.join(dev, "dri")))
    except OSError:
        return False


def _res(argv: list[str]) -> int:
    """The bake's ``--res`` as given in ``argv`` (the last one, as click takes it), or the
    default 2048; 0 when it is not a number (click then says so)."""
    res = "2048"
    for i, arg in enumerate(argv):
        if arg == "--res" and i + 1 < len(argv):
            res = argv[i + 1]
        elif arg.startswith("--res="):
            res = arg.removeprefix("--res=")
    try:
        return int(res)
    except ValueError:
        return 0


#: The garbage collector's thresholds for a bake (Python's are 700, 10, 10).
GC_THRESHOLDS = (50_000, 100, 1000)


def fewer_collections() -> None:
    """Collect garbage cycles rarely in a bake: a bake makes few, but its imports leave about
    85,000 tracked objects that every older-generation collection walks again.  With Python's
    thresholds the README bake ran 140 collections on its main thread and 50 on others, 62-126
    ms in all (``gc.callbacks``), each holding the GIL; with these, two, 43-48 ms, and the same
    peak memory."""
    import gc

    gc.set_threshold(*GC_THRESHOLDS)


def _rebakes(argv: list[str]) -> bool:
    """True when ``argv`` re-bakes a crack network (``--cracks``)."""
    return any(arg == "--cracks" or arg.startswith("--cracks=") for arg in argv)


def _is_command() -> bool:
    """True when this process is ``crackbake ARGS`` or ``python -m crackbake ARGS`` (so that
    re-running its original command line runs the same command), not a program that imported
    :func:`main`."""
    orig = getattr(sys, "orig_argv", None)
    if not orig or orig[len(orig) - len(sys.argv) + 1:] != sys.argv[1:]:
        return False
    spec = getattr(sys.modules.get("__main__"), "__spec__", None)
    if spec is not None:  # python -m crackbake
        return spec.name in ("crackbake.__main__", "crackbake.entry")
    # The console script: python SCRIPT ARGS, where the script is sys.argv[0].
    script = len(orig) - len(sys.argv)
    return (script > 0 and orig[script] == sys.argv[0]
            and os.path.basename(sys.argv[0]).startswith("crackbake"))


def quiet_blas(environ: dict | None = None) -> None:
    """One OpenBLAS thread for this process unless the user chose a count, before numpy loads.

    numpy's import calls BLAS once (its sanity check), and OpenBLAS then wakes a thread per
    core that spins for a while after every call.  A run's BLAS work is small ((N, 3) products),
    so those threads only burn the cores the encoders, llvmpipe and batch neighbours need: on a
    16-core H200 VM the README bake used 12.2 CPU s with them and 6.1 without, in the same wall
    (median 3.46 against 3.34 s, 4 pairs); ``import numpy`` alone 2.2 against 0.25 CPU s.  On 2
    cores the runs were within noise.
    """
    env = os.environ if environ is None else environ
    if not any(k in env for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")):
        env["OPENBLAS_NUM_THREADS"] = "1"


class _NumbaCoverageFinder:
    """A ``sys.meta_path`` entry that refuses ``coverage`` to numba's coverage hook only."""

    def find_spec(self, name: str, path=None, target=None):
        if name != "coverage":
            return None
        frame = sys._getframe(1)
        while frame is not None:
            if frame.f_globals.get("__name__") == "numba.misc.coverage_support":
                raise ModuleNotFoundError("crackbake: coverage is not running", name=name)
            frame = frame.f_back
        return None


def numba_skips_coverage(environ: dict | None = None) -> bool:
    """Keep numba's import from importing coverage.py where that can serve nothing; True when set.

    numba imports ``coverage`` whenever it is installed (``numba.misc.coverage_support``), for
    a hook that reports compiled lines only with ``NUMBA_JIT_COVERAGE=1`` and only to a
    coverage run started before it: 0.09 s of every run's start-up on a machine that has it (a
    developer's, a CI image, the GPU VMs).  A run under coverage (already imported) or with
    ``NUMBA_JIT_COVERAGE`` set keeps numba's own behaviour, and any other module that imports
    coverage gets it.
    """
    env = os.environ if environ is None else environ
    if "coverage" in sys.modules or env.get("NUMBA_JIT_COVERAGE", "0").strip() not in ("", "0"):
        return False
    if not any(isinstance(f, _NumbaCoverageFinder) for f in sys.meta_path):
        sys.meta_path.insert(0, _NumbaCoverageFinder())
    return True


def leave(code: object) -> None:
    """End the process with ``code`` as ``SystemExit(code)`` would, without Python's teardown.

    By the time the command returns, its files are written and renamed into place.  The
    interpreter's finalisation would then free every object one by one and unload the GL driver
    and numba's LLVM: 0.6-1.0 s of wall time after a 4096² bake, on every run.  What an exit owes
    is kept: non-daemon threads are joined and the ``atexit`` handlers run (logging's flush,
    Ray's shutdown, multiprocessing's children), then stdout and stderr are flushed.  Under a
    profiler or a tracer (``python -m cProfile``, coverage) the exit is Python's own, so that
    they can write their results.
    """
    if _observed():
        raise SystemExit(code)
    import atexit
    import threading

    shutdown = getattr(threading, "_shutdown", None)  # what the interpreter calls first
    if shutdown is not None:
        shutdown()
    atexit._run_exitfuncs()
    if code is None:
        status = 0
    elif isinstance(code, int):
        status = code
    else:  # as the interpreter does with SystemExit("message")
        print(code, file=sys.stderr)
        status = 1
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe: nothing more can be said there
            pass
    os._exit(status & 0xFF)


def _observed() -> bool:
    """True under a profiler, a tracer or a debugger: the old hooks (``sys.setprofile``,
    ``sys.settrace``) or, from Python 3.12, a tool of ``sys.monitoring`` (cProfile itself uses
    it there, and coverage.py can)."""
    if sys.getprofile() is not None or sys.gettrace() is not None:
        return True
    monitoring = getattr(sys, "monitoring", None)
    if monitoring is None:
        return False
    tools = (monitoring.DEBUGGER_ID, monitoring.COVERAGE_ID, monitoring.PROFILER_ID)
    return any(monitoring.get_tool(tool) is not None for tool in tools)


if __name__ == "__main__":
    main()
