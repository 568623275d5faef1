"""Batches: a TOML file of jobs run on Ray, one fresh worker process per job
(``crackbake batch``, docs/batch.md).

- ``jobs.py``: the batch file parsed, expanded (sweeps) and checked as a whole, through the
  bake command's own options and :class:`~crackbake.params.RunParams` checks;
- ``run.py``: the Ray driver (local or a cluster), retries, ``--resume``;
- ``summary.py``: ``batch.json``, ``batch.csv`` and the contact sheet ``batch_sheet.png``;
- ``command.py``: the ``crackbake batch`` command.
"""
