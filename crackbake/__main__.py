"""``python -m crackbake``: the ``crackbake`` command."""

from crackbake.cli import main

if __name__ == "__main__":
    main(prog_name="crackbake")
