"""The one exception type users see.

Every error raised on purpose by crackbake is a :class:`CrackbakeError` whose message is one line
naming the problem and the fix; the CLI prints it and exits non-zero without a traceback.
"""


class CrackbakeError(Exception):
    """A user-facing error: one line, names the problem and how to fix it."""

    exit_code = 2
