"""The ``crackbake`` console script: a platform check, then the command.

crackbake needs Linux (headless OpenGL through EGL, ``fcntl`` locks on the output folder,
``renameat2(RENAME_EXCHANGE)`` for its atomic swap).  Elsewhere the modules behind the command
would fail to import with a traceback; this entry point says so in one line instead, before
importing any of them.
"""

from __future__ import annotations

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
    from crackbake.cli import main as command

    command(prog_name="crackbake")


if __name__ == "__main__":
    main()
