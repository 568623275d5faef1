"""The output folder as a transaction: a run's whole set of files appears at once, or nothing
changes, and SIGINT/SIGTERM unwind a run cleanly (never mid-swap).

``stage.py`` holds :class:`OutputStage` (staging folder, records, commit) and
:func:`sha256_file`; ``outdir.py`` the folder checks, the lock, leftovers and the swap;
``interrupt.py`` the signal handling (:func:`interruptible`, :func:`run_staged`).
"""

from crackbake.transaction.interrupt import Interrupt, RunInterrupted, interruptible, run_staged
from crackbake.transaction.stage import OutputStage, sha256_file

__all__ = [
    "Interrupt",
    "OutputStage",
    "RunInterrupted",
    "interruptible",
    "run_staged",
    "sha256_file",
]
