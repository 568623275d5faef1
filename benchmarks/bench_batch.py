"""Batch benchmark (issue 21's floors): ``crackbake batch`` against the same jobs run one after
another as plain ``crackbake`` processes, whole-process wall times.

Jobs: spot with 4 presets x 3 seeds (12 jobs, ``--res 1024`` by default; glass gets an
impact).  Measured, each in a fresh process:

- ``plain``: the 12 ``crackbake MESH ...`` runs one after another (the sum is the reference);
- ``batch --workers 1``: the engine's cost (floor: <= 1.05 x the sum);
- ``batch --workers 2``: two jobs at once (floor on this 2-core machine: <= 0.75 x the sum);
- Ray's start-up time and the per-job engine overhead (the batch's wall minus its jobs' run
  times, per job, for ``--workers 1``; floor: <= 1 s).

Each row also gives CPU seconds (user + system of the process and all its descendants, sampled
every 0.1 s from ``/proc``: the last 0.1 s of each process is missed), and a second table breaks
them down by process: the jobs' own (the plain processes; in a batch each job's ``cpu_s`` from
``batch.json``), the workers' boot before their job (``boot_cpu_s``: Python, importing Ray,
waiting for the task) and the rest of their life (their exit, an idle worker that never got a
job), the driver (the ``crackbake batch`` process), and Ray's daemons by name (raylet,
gcs_server, dashboard, its agents, and the log and autoscaler monitors where they run).  CPU
seconds are steadier than wall times on a busy machine: compare those.
``--repeat N`` runs plain and the batches alternately N times (ratios to the fastest plain sum).
Times on a shared machine are noisy: run it on a quiet one.

``--driver-memory N``: the batch driver's peak resident memory with N queued jobs (floor: <= 500
MB whatever the count).  N jobs of a 320-face sphere at ``--res 64 --sim-faces 1500`` (mud,
seeds 1..N) run with ``--workers 1``; the driver's ``VmRSS``/``VmHWM`` (``/proc``) are sampled
every 50 ms for ``--sample-s`` seconds, then it gets SIGINT, as from Ctrl-C, and writes its
summary (``batch.json`` and the contact sheet for all N jobs, the cancelled ones included); the
peak covers all of it.

Usage::

    python benchmarks/bench_batch.py [--res 1024] [--seeds 3] [--presets mud crackle glaze glass]
                                     [--skip-plain] [--repeat 2] [--markdown]
    python benchmarks/bench_batch.py --driver-memory 1000 [--sample-s 90]
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SPOT = ROOT / "examples" / "spot.obj"
IMPACT = "0.334,0.044,0.287"
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "RAY_USAGE_STATS_ENABLED": "0"}


def job_options(preset: str, seed: int) -> list[str]:
    extra = ["--impact", IMPACT] if preset == "glass" else []
    return ["--preset", preset, "--seed", str(seed), *extra]


def batch_file(folder: Path, res: int, presets: list[str], seeds: int) -> Path:
    lines = [f"[defaults]\nres = {res}\n"]
    for preset in presets:
        impact = f'impact = "{IMPACT}"\n' if preset == "glass" else ""
        lines.append(f'[[job]]\nmesh = "{SPOT}"\npreset = "{preset}"\n{impact}'
                     f"seeds = {list(range(1, seeds + 1))}\n")
    path = folder / "bench.toml"
    path.write_text("\n".join(lines))
    return path


def _tree(pid: int) -> list[int]:
    """``pid`` and every process below it (``/proc/*/task/*/children``)."""
    found, todo = [pid], [pid]
    while todo:
        for task in Path(f"/proc/{todo.pop()}/task").glob("*"):
            try:
                kids = [int(k) for k in (task / "children").read_text().split()]
            except OSError:
                continue
            todo += kids
            found += kids
    return found


def _cpu_s(pid: int) -> tuple[str, float] | None:
    """A process's start time (its identity with the pid) and user + system seconds."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    tick = os.sysconf("SC_CLK_TCK")
    return fields[19], (int(fields[11]) + int(fields[12])) / tick


#: The breakdown's columns: which process a CPU-second went to, by its command line (Ray's
#: workers retitle themselves ``ray::IDLE``, ``ray::crackbake:JOB`` ...; its agents
#: ``ray::DashboardAgent``, ``ray::RuntimeEnvAgent``).
PARTS = (("gcs_server", "ray/gcs/gcs_server"), ("raylet", "ray/raylet/raylet"),
         ("dashboard", "ray/dashboard/dashboard.py"), ("dashboard agent", "DashboardAgent"),
         ("runtime-env agent", "RuntimeEnvAgent"), ("log monitor", "log_monitor.py"),
         ("autoscaler monitor", "autoscaler/_private/monitor.py"),
         ("workers", "ray::"), ("workers", "default_worker.py"))


def _part(pid: int, root: int) -> str | None:
    """The breakdown column of ``pid`` (a descendant of the timed process ``root``)."""
    if pid == root:
        return "driver"
    try:
        cmd = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(
            errors="replace")
    except OSError:
        return None
    return next((name for name, key in PARTS if key in cmd), "other")


def timed(args: list[str], cwd: Path) -> tuple[float, float, dict[str, float]]:
    """Wall seconds and CPU seconds of one ``crackbake`` process and all its descendants (Ray's
    daemons and workers for a batch, which their parents do not all reap): each process's
    user + system time from ``/proc``, sampled every 0.1 s, the last sample counted; and those
    CPU seconds by process (:data:`PARTS`, ``driver`` the timed process itself)."""
    seen: dict[tuple[int, str], float] = {}
    part: dict[tuple[int, str], str] = {}
    with tempfile.TemporaryFile() as err:  # a file, not a pipe nobody reads meanwhile
        t = time.perf_counter()
        proc = subprocess.Popen([sys.executable, "-m", "crackbake", *args], cwd=cwd, env=ENV,
                                stdout=subprocess.DEVNULL, stderr=err)
        while proc.poll() is None:
            for pid in _tree(proc.pid):
                got = _cpu_s(pid)
                if got:
                    key = (pid, got[0])
                    seen[key] = got[1]
                    # a new process may not have exec'd or retitled itself yet: look again
                    if part.get(key, "other") == "other":
                        part[key] = _part(pid, proc.pid) or "other"
            time.sleep(0.1)
        wall = time.perf_counter() - t
        if proc.returncode != 0:
            err.seek(0)
            text = err.read().decode(errors="replace")
            raise SystemExit(f"crackbake {' '.join(args)} failed:\n{text[-2000:]}")
    by_part: dict[str, float] = {}
    for key, cpu in seen.items():
        by_part[part[key]] = by_part.get(part[key], 0.0) + cpu
    by_part["worker processes"] = sum(p == "workers" for p in part.values())
    return wall, sum(seen.values()), by_part


def _status(pid: int) -> dict[str, int]:
    """VmRSS and VmHWM of ``pid`` in kB ({} once it has exited)."""
    try:
        text = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return {}
    return {k: int(v.split()[0]) for k, v in (line.split(":", 1) for line in text.splitlines())
            if k in ("VmRSS", "VmHWM")}


def driver_memory(n: int, sample_s: float) -> None:
    """Peak RSS of the batch driver with ``n`` queued jobs (see the module docstring)."""
    import trimesh

    with tempfile.TemporaryDirectory(prefix="bench_batch_mem_") as tmp:
        tmp = Path(tmp)
        trimesh.creation.icosphere(subdivisions=2).export(tmp / "ball.obj")
        (tmp / "jobs.toml").write_text(
            '[defaults]\nres = 64\nsim-faces = 1500\npreset = "mud"\nformats = "png,preview"\n'
            '[[job]]\n'
            f'mesh = "ball.obj"\nseeds = {list(range(1, n + 1))}\n')
        t0 = time.perf_counter()
        proc = subprocess.Popen(
            [sys.executable, "-m", "crackbake", "batch", "jobs.toml", "-o", "out",
             "--workers", "1"], cwd=tmp, env=ENV, stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE, text=True,
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        timeline: list[tuple[float, int]] = []
        peak = 0
        sent = False
        while proc.poll() is None:
            st = _status(proc.pid)
            if st:
                peak = max(peak, st["VmHWM"])
                timeline.append((time.perf_counter() - t0, st["VmRSS"]))
            if not sent and time.perf_counter() - t0 > sample_s:
                proc.send_signal(signal.SIGINT)
                sent, t_int = True, time.perf_counter() - t0
            time.sleep(0.05)
        err = proc.stderr.read()
        doc = json.loads((tmp / "out" / "batch.json").read_text())
        sheet = (tmp / "out" / "batch_sheet.png").stat().st_size
    print(f"{n} jobs queued, --workers 1, SIGINT after {t_int:.0f} s; exit {proc.returncode}; "
          f"counts {doc['counts']}; sheet {sheet / 2**20:.1f} MiB")
    print(f"driver peak RSS (VmHWM): {peak / 1024:.0f} MB (floor: <= 500 MB)")
    step = max(1, len(timeline) // 12)
    print("driver RSS over time: " + ", ".join(
        f"{t:.0f} s {rss / 1024:.0f} MB" for t, rss in timeline[::step]))
    if proc.returncode not in (130, 0):
        print(err[-2000:])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--res", type=int, default=1024)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--presets", nargs="+", default=["mud", "crackle", "glaze", "glass"])
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--skip-plain", action="store_true", help="only the batch runs")
    ap.add_argument("--repeat", type=int, default=1,
                    help="run plain and the batches alternately this many times")
    ap.add_argument("--markdown", action="store_true")
    ap.add_argument("--driver-memory", type=int, metavar="N",
                    help="only the driver's peak memory with N queued jobs")
    ap.add_argument("--sample-s", type=float, default=90.0,
                    help="with --driver-memory: seconds of running before the SIGINT")
    a = ap.parse_args()
    if a.driver_memory:
        driver_memory(a.driver_memory, a.sample_s)
        return

    rows = []
    breakdowns = []
    with tempfile.TemporaryDirectory(prefix="bench_batch_") as tmp:
        tmp = Path(tmp)
        jobs = batch_file(tmp, a.res, a.presets, a.seeds)
        n = len(a.presets) * a.seeds
        plain = None

        def run_plain() -> tuple[float, float]:
            wall = cpu = 0.0
            for preset in a.presets:
                for seed in range(1, a.seeds + 1):
                    w, c, _ = timed([str(SPOT), "--res", str(a.res), "-q",
                                     "-o", f"plain_{preset}_{seed}_{len(rows)}",
                                     *job_options(preset, seed)], tmp)
                    wall, cpu = wall + w, cpu + c
            return wall, cpu

        for rep in range(a.repeat):
            if not a.skip_plain:
                wall, cpu = run_plain()
                plain = wall if plain is None else min(plain, wall)
                name = f"plain, one after another #{rep + 1}"
                rows.append((name, wall, cpu, None, None))
                breakdowns.append((name, {"jobs": cpu}))
            for w in a.workers:
                out = tmp / f"batch_w{w}_{rep}"
                wall, cpu, parts = timed(["batch", str(jobs), "-o", str(out), "--workers",
                                          str(w), "-q"], tmp)
                doc = json.loads((out / "batch.json").read_text())
                start = doc["ray"]["start_s"]
                run = sum(j["run_s"] for j in doc["jobs"])
                overhead = (wall - start - run / w) / n
                name = f"batch --workers {w} #{rep + 1}"
                rows.append((name, wall, cpu, start, overhead))
                # the workers' CPU: before their job, the job, and the rest (the idle workers
                # Ray prestarts, a worker's exit after its job)
                boot = sum(j.get("boot_cpu_s", 0.0) for j in doc["jobs"])
                job = sum(j.get("cpu_s", 0.0) for j in doc["jobs"])
                workers = parts.pop("workers", 0.0)
                started = parts.pop("worker processes")
                print(f"batch --workers {w}: {started} worker processes for {n} jobs",
                      file=sys.stderr)
                parts.update({"worker boot": boot, "jobs": job,
                              "workers' rest": workers - boot - job})
                breakdowns.append((name, parts))

    head = f"{n} jobs, spot, --res {a.res}"
    if a.markdown:
        print(f"| {head} | wall s | x plain sum | CPU s | Ray start s | engine s/job |")
        print("|---|---|---|---|---|---|")
    else:
        print(head + (" (ratios: to the fastest plain sum)" if a.repeat > 1 else ""))
    for name, wall, cpu, start, overhead in rows:
        ratio = f"{wall / plain:.2f}" if plain else "-"
        s = f"{start:.1f}" if start is not None else "-"
        o = f"{overhead:.2f}" if overhead is not None else "-"
        if a.markdown:
            print(f"| {name} | {wall:.1f} | {ratio} | {cpu:.1f} | {s} | {o} |")
        else:
            print(f"  {name:<30} {wall:8.1f} s  x{ratio:<5} cpu {cpu:7.1f} s  start {s:>5} s  "
                  f"engine {o:>5} s/job")
    print_breakdown(breakdowns, a.markdown)


#: The breakdown's columns in order (those no run used are left out).
COLUMNS = ("jobs", "worker boot", "workers' rest", "driver", "raylet", "gcs_server",
           "dashboard", "dashboard agent", "runtime-env agent", "log monitor",
           "autoscaler monitor", "other")


def print_breakdown(breakdowns: list[tuple[str, dict[str, float]]], markdown: bool) -> None:
    """Where each run's CPU seconds went, by process: ``jobs`` the plain processes, or the
    batch's job bodies (``cpu_s`` in ``batch.json``), ``worker boot`` the workers' CPU before
    their job (``boot_cpu_s``), then Ray's daemons and the driver."""
    cols = [c for c in COLUMNS if any(abs(p.get(c, 0.0)) >= 0.05 for _, p in breakdowns)]
    print()
    if markdown:
        print("| CPU s by process | " + " | ".join(cols) + " | total |")
        print("|---|" + "---|" * (len(cols) + 1))
    else:
        print("CPU seconds by process")
        print(f"  {'':<30} " + " ".join(f"{c[:10]:>10}" for c in cols) + f" {'total':>8}")
    for name, parts in breakdowns:
        cells = [parts.get(c, 0.0) for c in cols]
        if markdown:
            print(f"| {name} | " + " | ".join(f"{v:.1f}" for v in cells)
                  + f" | {sum(parts.values()):.1f} |")
        else:
            print(f"  {name:<30} " + " ".join(f"{v:10.1f}" for v in cells)
                  + f" {sum(parts.values()):8.1f}")


if __name__ == "__main__":
    main()
