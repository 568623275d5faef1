"""``python -m crackbake``: the ``crackbake`` command."""

from crackbake.entry import main

if __name__ == "__main__":
    main()
