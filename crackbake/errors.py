"""The one exception type users see, and the one warning type.

Every error raised on purpose by crackbake is a :class:`CrackbakeError` whose message is one line
naming the problem and the fix; the CLI prints it and exits non-zero without a traceback.
"""


class CrackbakeError(Exception):
    """A user-facing error: one line, names the problem and how to fix it."""

    exit_code = 2


class CrackbakeWarning(UserWarning):
    """Something was adjusted or looks wrong but the run can go on."""
