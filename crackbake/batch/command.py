"""``crackbake batch JOBS -o OUT``: every job of a batch file on Ray, a summary beside them."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from crackbake.cli.common import CONTEXT, Command, err
from crackbake.errors import CrackbakeError

EPILOG = """\b
Examples:
  # every job of jobs.toml on this machine, one job per core
  crackbake batch jobs.toml -o out/
\b
  # after fixing a mesh: run only the jobs whose inputs or options changed
  crackbake batch jobs.toml -o out/ --resume
\b
  # on a running Ray cluster (ray start --head; OUT on storage every node mounts)
  crackbake batch jobs.toml -o /shared/out --address auto
\b
JOBS (TOML): a [defaults] table with any option of the bake command, and [[job]] entries with
mesh (a path or a glob, relative to the file), name (the output sub-folder), any bake option,
and seeds = [...] / presets = [...] for sweeps.  Outputs: OUT/<name>/ (what crackbake MESH -o
OUT/<name> writes), OUT/batch.json, OUT/batch.csv, OUT/batch_sheet.png.  Exit 0: every job ok;
1: some failed (listed at the end); 2: a bad batch file (nothing was run); 130 (Ctrl-C) or
143 (SIGTERM): interrupted, the summary written with the unfinished jobs cancelled.  docs/batch.md.
"""


@click.command("batch", cls=Command, epilog=EPILOG, context_settings=CONTEXT)
@click.argument("jobs", type=click.Path(path_type=Path))
@click.option("-o", "--out", type=click.Path(path_type=Path), required=True,
              help="Output folder: a sub-folder per job and the batch summary.")
@click.option("--workers", type=click.IntRange(min=1),
              help="Most jobs at once [one per core; on a cluster, as many as fit].")
@click.option("--cpus-per-job", type=click.IntRange(min=1),
              help="CPUs each job reserves (and its numba threads) [cores / --workers; 1 on a "
              "cluster].")
@click.option("--address", help="A running Ray cluster: auto, HOST:PORT or ray://HOST:PORT "
              "[start a local Ray for this batch].")
@click.option("--retries", type=click.IntRange(0, 20), default=2, show_default=True,
              help="Re-runs of a job whose worker process died (killed, out of memory); a job "
              "failing on its input is not retried.")
@click.option("--resume", is_flag=True,
              help="Keep a job folder whose manifest has the same job hash (mesh content, "
              "options, crackbake version).")
@click.option("--dry-run", is_flag=True, help="Check the batch file and list its jobs; run none.")
@click.option("-q", "--quiet", is_flag=True, help="Print nothing but errors and failed jobs.")
def batch(jobs: Path, out: Path, workers, cpus_per_job, address, retries, resume, dry_run,
          quiet) -> int:
    """Run every job of the batch file JOBS (TOML) on Ray, each into OUT/<name>/."""
    from crackbake.batch.jobs import BatchFileError, load_jobs

    try:
        job_list = load_jobs(jobs, out)
    except BatchFileError as exc:
        err(f"error: {exc}")
        sys.exit(2)
    if dry_run:
        for job in job_list:
            click.echo(f"{job.name}: crackbake {' '.join(job.argv)} -o {job.params.out_dir}")
        return 0

    from crackbake.batch.progress import report_for
    from crackbake.batch.run import Plan, run_batch
    from crackbake.batch.summary import counts, write_summary

    def echo(line: str) -> None:
        if not quiet or " failed " in line:
            err(line)

    plan = Plan(address=address, workers=workers, cpus_per_job=cpus_per_job, retries=retries,
                resume=resume)
    try:
        records = run_batch(job_list, plan, report_for(sys.stderr, echo, quiet))
    except CrackbakeError as exc:  # already one line naming the fix
        err(f"error: {exc}")
        sys.exit(2)
    except Exception as exc:  # Ray could not start or connect: one line
        text = " ".join(str(exc).split())[:300]
        err(f"error: cannot run the batch on Ray ({type(exc).__name__}: {text})")
        sys.exit(2 if address else 1)
    write_summary(out, records, jobs, plan.ray_info)
    tally = counts(records)
    failed = [r for r in records if r.get("status") in ("failed", "cancelled")]
    if not quiet:
        parts = ", ".join(f"{v} {k}" for k, v in sorted(tally.items()))
        err(f"{len(records)} jobs: {parts}; summary in {out}/batch.json, batch_sheet.png")
    for r in failed:
        err(f"  {r['status']}: {r['name']}: {r.get('error', '')}")
    signum = plan.ray_info.get("interrupted")
    if signum:  # as a shell reports a process ended by that signal: 130 Ctrl-C, 143 SIGTERM
        err(f"interrupted ({'Ctrl-C' if signum == 2 else 'SIGTERM'}): finished folders kept, "
            "unfinished jobs cancelled")
        return 128 + signum
    return 1 if failed else 0
