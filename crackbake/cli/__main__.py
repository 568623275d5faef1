"""``python -m crackbake.cli``: the ``crackbake`` command, as ``python -m crackbake`` runs it."""

from crackbake.entry import main

if __name__ == "__main__":
    main()
