"""The batch driver on Ray: one task per job, each in a fresh worker process.

A job runs :func:`crackbake.pipeline.run` exactly as the bake command does, into its own
folder through the output transaction.  Its task declares ``num_cpus`` (and the worker's
``NUMBA_NUM_THREADS`` follows it) and ``memory``, the run's estimated peak
(:func:`crackbake.memory.estimate_peak`), so Ray never packs more big jobs on a node than its
memory holds (a local Ray's driver holds the memory itself, so that every task has one shape
and Ray starts them in order; see :func:`_drive`).  ``max_calls=1``: the worker process exits
after its job, so no GL context, numba state or leaked memory passes from one asset to the next.

numba's kernel cache is a folder on each node's own disk, seeded from the package's precompiled
kernels (:mod:`crackbake.batch.numba_cache`): nodes never write the same cache files over a
shared file system.

Faults: a worker that dies (SIGKILL, the OOM killer, a lost node) is a system failure Ray
retries (``max_retries``); the staging folder it left is removed by the retry's output
transaction.  A job failing on its input (a :class:`CrackbakeError`) returns its one-line error
and is not retried: the same input would fail the same way.
"""

from __future__ import annotations

import logging
import os
import resource
import signal
import socket
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from crackbake.batch.jobs import Job, face_count
from crackbake.batch.progress import LineReport

# Nothing here may import numba at module level: a worker unpickles this module before its job
# sets NUMBA_NUM_THREADS (crackbake.transaction's package imports the pipeline's kernels).

#: Least object store Ray accepts; the tasks return small dicts, so more only takes /dev/shm.
OBJECT_STORE_BYTES = 80 * 2**20
#: Logical CPUs a local Ray gets beyond the jobs' own: room for the next job's worker to boot.
SPARE_CPUS = 1
#: The local Ray's resource counting job slots (``--workers``).
SLOT = "crackbake_job"
#: Seconds a cancelled job gets to unwind (remove its staging folder) before its worker is
#: killed.
CANCEL_GRACE_S = 10.0


@dataclass
class Plan:
    """How a batch runs: Ray's address (None: a local Ray started here), the most jobs at once,
    CPUs per job, retries of a dead worker, whether finished folders are kept."""

    address: str | None = None
    workers: int | None = None
    cpus_per_job: int | None = None
    retries: int = 2
    resume: bool = False
    ray_info: dict = field(default_factory=dict)


def _prepare_worker() -> dict:
    """Set up a fresh worker before numba is imported (it has not been): its thread pool
    follows the task's CPUs and its cache is a folder on this node's own disk
    (:mod:`crackbake.batch.numba_cache`).  Returns where the task runs (node, host, pid) and
    those settings."""
    import ray

    from crackbake.batch.numba_cache import use_node_cache

    context = ray.get_runtime_context()
    cpus = context.get_assigned_resources().get("CPU", 1)
    os.environ["NUMBA_NUM_THREADS"] = str(max(1, int(cpus)))
    return {"node": context.get_node_id(), "host": socket.gethostname(), "pid": os.getpid(),
            "numba_threads": os.environ["NUMBA_NUM_THREADS"], "numba_cache": use_node_cache()}


def _run_variants(params, chunk: list) -> tuple[list, list[str]]:
    """The task body of ``crackbake decals --address``: bake ``chunk``'s variants in a fresh
    worker; the baked variants and the warnings they raised."""
    import warnings

    from crackbake.errors import CrackbakeWarning

    _prepare_worker()
    from crackbake.decals.library import bake_variants

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", CrackbakeWarning)
        baked = bake_variants(params, chunk)
    _before_exit()
    return baked, [str(w.message) for w in caught if issubclass(w.category, CrackbakeWarning)]


def map_variants(params, variants: list, plan: Plan) -> list:
    """Bake a decal library's ``variants`` on Ray (``plan.address``): contiguous chunks, two per
    job slot, each a task in a fresh worker; the :class:`~crackbake.decals.library.Baked`
    variants in order.  A variant's :class:`CrackbakeError` is raised here, its warnings are
    warned here; Ctrl-C cancels the tasks."""
    import warnings

    from crackbake.errors import CrackbakeError, CrackbakeWarning

    try:
        ray, owned = _start_ray(plan)
    except ImportError:
        raise CrackbakeError("--address needs Ray: pip install 'crackbake[batch]'") from None
    except CrackbakeError:
        raise
    except Exception as exc:  # no cluster there
        text = " ".join(str(exc).split())[:200]
        raise CrackbakeError(f"cannot reach a Ray cluster at --address {plan.address} "
                             f"({type(exc).__name__}: {text}); start one with ray start --head "
                             "or leave --address out") from None
    refs = []
    try:
        per_job = plan.cpus_per_job or 1
        slots = max(1, int(ray.cluster_resources().get("CPU", 1) // per_job))
        count = min(len(variants), 2 * slots)
        size = -(-len(variants) // count)
        task = ray.remote(max_calls=1)(_run_variants)
        refs = [task.options(num_cpus=per_job, max_retries=plan.retries, retry_exceptions=False,
                             name=f"crackbake:decals:{k // size}")
                .remote(params, variants[k:k + size]) for k in range(0, len(variants), size)]
        baked = []
        for chunk, caught in ray.get(refs):  # a task's CrackbakeError comes back as one
            baked += chunk
            for message in caught:
                warnings.warn(message, CrackbakeWarning, stacklevel=2)
        return baked
    except KeyboardInterrupt:
        for ref in refs:
            ray.cancel(ref)
        raise
    finally:
        if owned:
            _stop_ray(ray)


def _cpu_s() -> float:
    """User + system CPU seconds of this process so far."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def _run_job(params, extra: dict) -> dict:
    """The task body (in a fresh worker): one pipeline run, its outcome as a record."""
    import warnings

    from crackbake.errors import CrackbakeError, CrackbakeWarning

    t0 = time.perf_counter()
    cpu0 = _cpu_s()
    record = _prepare_worker()
    try:
        from crackbake.pipeline import run

        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", CrackbakeWarning)
            result = run(params, manifest_extra=extra)
        record.update(
            status="ok",
            files=[f["name"] for f in result.files] + ["manifest.json"],
            pipeline_s=result.manifest["timings_s"],
            warnings=[str(w.message) for w in caught if issubclass(w.category, CrackbakeWarning)],
        )
    except CrackbakeError as exc:
        record.update(status="failed", error=f"error: {exc}", exit_code=exc.exit_code)
    except MemoryError:
        record.update(status="failed", exit_code=2,
                      error="error: ran out of memory; lower --res, --stress-res or --sim-faces")
    except Exception as exc:  # a bug: one line, as the bake command says it
        text = " ".join(str(exc).split())[:200]
        record.update(status="failed", exit_code=1,
                      error=f"internal error: {type(exc).__name__}: {text}")
    record["run_s"] = round(time.perf_counter() - t0, 3)
    # The worker's CPU before the job (Python, Ray, unpickling the task) and the job's own.
    record["boot_cpu_s"] = round(cpu0, 3)
    record["cpu_s"] = round(_cpu_s() - cpu0, 3)
    # A fresh process per job: its peak is the job's (plus the Ray worker's own ~100 MB).
    record["peak_rss_mb"] = round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)
    _before_exit()
    return record


def _before_exit() -> None:
    """Spare the worker's exit (``max_calls=1``: it ends after this task) a last sweep of the
    job's objects: the interpreter's shutdown collects garbage over every object still alive
    (numba's and llvmlite's by the hundred thousand), about 0.7 CPU-s a job on the 2-core test
    machine; frozen objects are not swept (``gc.freeze``), and the process ends anyway."""
    import gc

    gc.freeze()


#: Seconds to wait for a TCP answer at --address before refusing it: Ray itself retries an
#: unreachable GCS for minutes, printing a log line every few seconds.
REACH_TIMEOUT_S = 5.0


def _reach(address: str) -> None:
    """Refuse ``--address HOST:PORT`` (or ``ray://HOST:PORT``) at once when nothing accepts a
    TCP connection there; ``auto`` and other forms are left to Ray."""
    import socket

    from crackbake.errors import CrackbakeError

    hostport = address.split("://", 1)[1] if address.startswith("ray://") else address
    host, sep, port = hostport.rstrip("/").rpartition(":")
    if not sep or not port.isdigit() or not host:
        return
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout=REACH_TIMEOUT_S):
            pass
    except OSError as exc:
        why = exc.strerror or type(exc).__name__
        raise CrackbakeError(f"cannot reach a Ray cluster at --address {address} ({why}); start "
                             "one there with ray start --head, check the host and port, or "
                             "leave --address out") from None


def _start_ray(plan: Plan):
    """Connect to ``plan.address`` or start a local Ray sized to this machine; returns ray and
    whether this process owns the instance (and must shut it down)."""
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")  # an embedded engine reports nothing
    import ray

    if ray.is_initialized():  # a script (or a test session) already connected: use that Ray
        return ray, False
    quiet = {"include_dashboard": False, "log_to_driver": False,
             "logging_level": logging.ERROR}
    if plan.address is not None:
        _reach(plan.address)
        try:
            ray.init(address=plan.address, **{k: v for k, v in quiet.items()
                                              if k != "include_dashboard"})
        except Exception as exc:  # ConnectionError, a version mismatch, a refused client
            from crackbake.errors import CrackbakeError

            text = " ".join(str(exc).split())[:200]
            raise CrackbakeError(f"cannot reach a Ray cluster at --address {plan.address} "
                                 f"({type(exc).__name__}: {text}); start one with ray start "
                                 "--head or leave --address out") from None
        return ray, False
    slots, per_job = local_slots(plan)
    # The local workers (children of the raylet started here) import this crackbake, installed
    # or not; no runtime_env, so Ray keeps its pool of prestarted workers.
    here = str(Path(__file__).resolve().parents[2])
    os.environ["PYTHONPATH"] = os.pathsep.join(
        p for p in (here, os.environ.get("PYTHONPATH")) if p)
    # SPARE_CPUS more CPUs than the jobs take, and the job slots as a resource of their own
    # (which is what holds the jobs at once to ``slots``): with a job queued behind the running
    # ones, the raylet starts a worker for it on the spare CPU while they run (it prestarts
    # only up to the free CPUs), so the next job finds a booted worker instead of waiting for a
    # fresh Python to import Ray.  Each job is still its own process (max_calls=1).
    node_options = {"num_cpus": slots * per_job + SPARE_CPUS, "resources": {SLOT: slots},
                    "object_store_memory": OBJECT_STORE_BYTES}
    global _LOCAL_NODE
    _LOCAL_NODE = _start_local_node(node_options)
    if _LOCAL_NODE is None:  # a Ray without the node API used here: all of Ray's daemons
        ray.init(**node_options, **quiet)
    else:
        try:
            ray.init(address=_LOCAL_NODE.address, **{k: v for k, v in quiet.items()
                                                     if k != "include_dashboard"})
        except BaseException:
            _stop_ray(ray)
            raise
    plan.ray_info["local"] = True
    return ray, True


#: The local Ray node this process started (:func:`_start_local_node`), stopped by
#: :func:`_stop_ray`.
_LOCAL_NODE = None


def _start_local_node(options: dict):
    """Start a local Ray head node without the daemons a batch has no use for; None where this
    Ray's node API differs (then ``ray.init`` starts the node with all of them).

    ``ray.init`` starts Ray's log monitor (it scans the session's log folder every 0.1 s to
    forward the workers' output, which ``log_to_driver=False`` discards) and the autoscaler's
    monitor (a fixed-size local node never scales); on the 2-core test machine the two took
    about 6 CPU-s of a 4-job batch, on the same cores as the jobs.  ``ray.init`` does not let
    them be left out; the node class it uses does (as ``ray.cluster_utils`` uses it)."""
    try:
        from ray._private.node import Node
        from ray._private.parameter import RayParams

        params = RayParams(**options, include_dashboard=False, include_log_monitor=False,
                           no_monitor=True)
    except (ImportError, TypeError, AttributeError):
        return None
    # As ray.init's own: its reaper stops the node's processes if this one dies without
    # shutting it down.
    return Node(params, head=True, shutdown_at_exit=False, spawn_reaper=True)


def _stop_ray(ray) -> None:
    """Disconnect from Ray and stop the local node this process started."""
    global _LOCAL_NODE
    ray.shutdown()
    node, _LOCAL_NODE = _LOCAL_NODE, None
    if node is not None:
        node.destroy_external_storage()
        node.kill_all_processes(check_alive=False, allow_graceful=True)


def local_slots(plan: Plan) -> tuple[int, int]:
    """Jobs at once and CPUs per job on a local Ray: ``--workers`` (default: the cores over
    ``--cpus-per-job``, or the cores), each with the cores over the workers."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    if plan.workers:
        slots = plan.workers
        per_job = plan.cpus_per_job or max(1, cores // min(slots, cores))
    else:
        per_job = plan.cpus_per_job or 1
        slots = max(1, cores // per_job)
    return slots, per_job


def _largest_memory(ray) -> float:
    """Bytes of the ``memory`` resource on the largest live node."""
    return max((n["Resources"].get("memory", 0.0) for n in ray.nodes() if n.get("Alive")),
               default=0.0)


def resume_record(job: Job, job_hash: str) -> dict | None:
    """The record of a job ``--resume`` keeps: its folder's manifest has the same job hash."""
    import json

    manifest = Path(job.params.out_dir) / "manifest.json"
    try:
        doc = json.loads(manifest.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(doc, dict) or doc.get("batch", {}).get("hash") != job_hash:
        return None
    files = [f["name"] for f in doc.get("files", []) if isinstance(f, dict)]
    return {"status": "skipped", "files": files + ["manifest.json"],
            "pipeline_s": doc.get("timings_s", {})}


def run_batch(jobs: list[Job], plan: Plan, report: LineReport | Callable[[str], None] = print,
              ) -> list[dict]:
    """Run ``jobs`` on Ray; one record per job, in the batch file's order.

    Each record holds ``name``, ``status`` (``ok``, ``failed``, ``skipped``, ``cancelled``),
    ``error`` (one line) where it failed, ``node``, ``host``, ``pid``, timings, the peak
    resident memory and the memory estimate, the files written.  ``report`` hears of every
    finished job (a :class:`~crackbake.batch.progress.LineReport`, or a callable that gets one
    line per finished job).  A local Ray started here is shut down before returning (a Ray this
    process already connected to is used and left running).

    SIGINT (Ctrl-C) or SIGTERM: the running tasks are cancelled (each one's output transaction
    removes its staging folder), the queued ones never start, finished folders stay; the
    unfinished jobs are ``cancelled`` and ``plan.ray_info["interrupted"]`` holds the signal's
    number.
    """
    from crackbake.memory import estimate_peak, run_sizes
    from crackbake.transaction.interrupt import interruptible, received

    if not isinstance(report, LineReport):
        report = LineReport(report)
    records: list[dict] = []
    todo: list[tuple[int, Job, dict]] = []
    hashes: dict[Path, dict] = {}
    faces: dict[Path, int] = {}
    for i, job in enumerate(jobs):
        key = Path(job.params.mesh)
        if key not in hashes or job.params.weight_map or job.params.cracks:
            hashes[key] = job.input_hashes()
        h = job.job_hash(hashes[key])
        if key not in faces:
            faces[key] = face_count(key)
        estimate = estimate_peak(**run_sizes(job.params.resolved()[0], faces=faces[key]))
        record = {"name": job.name, "index": job.index, "mesh": str(job.params.mesh),
                  "folder": str(job.params.out_dir), "hash": h,
                  "memory_estimate_mb": round(estimate.rss / 2**20, 1)}
        skipped = resume_record(job, h) if plan.resume else None
        if skipped is not None:
            record.update(skipped)
        else:
            todo.append((i, job, {"batch": {"job": job.name, "hash": h}}))
        records.append(record)
    for r in records:
        if r.get("status") == "skipped":
            report.echo(f"skipped {r['name']} (finished, same job hash)")
    if not todo:
        return records

    t_start = time.perf_counter()
    owned = False
    ray = None
    report.start(len(todo))
    try:
        ray, owned = _start_ray(plan)
        plan.ray_info.update(start_s=round(time.perf_counter() - t_start, 3),
                             nodes=len([n for n in ray.nodes() if n.get("Alive")]),
                             cpus=ray.cluster_resources().get("CPU", 0),
                             gpus=ray.cluster_resources().get("GPU", 0))
        # SIGTERM (a scheduler, ``kill``, ``timeout``) unwinds like Ctrl-C instead of killing
        # the driver with its local Ray under the running jobs.  Installed after ray.init,
        # whose own SIGTERM handler aborts the process.
        with interruptible():
            _drive(ray, todo, records, plan, report)
    except KeyboardInterrupt as exc:  # before Ray was up, or between the driver's steps
        plan.ray_info["interrupted"] = received() or getattr(exc, "signum", signal.SIGINT)
    finally:
        report.close()
        if owned:
            _stop_ray(ray)
    if plan.ray_info.get("interrupted"):
        for r in records:
            if "status" not in r:
                r.update(status="cancelled", error=f"cancelled ({_signal_name(plan)}) before "
                         "it started")
    return records


def _signal_name(plan: Plan) -> str:
    signum = plan.ray_info.get("interrupted", signal.SIGINT)
    return "Ctrl-C" if signum == signal.SIGINT else signal.Signals(signum).name


def _outcome(ray, ref, plan: Plan) -> dict:
    """A finished task's record, or the failure Ray reports for it."""
    try:
        return ray.get(ref)
    except ray.exceptions.TaskCancelledError:
        return {"status": "cancelled", "error": f"cancelled ({_signal_name(plan)})"}
    except ray.exceptions.OutOfMemoryError:
        return {"status": "failed", "exit_code": 1, "error": (
            "error: the node ran out of memory running it (after "
            f"{plan.retries} retries); lower --res or run fewer jobs per node")}
    except (ray.exceptions.WorkerCrashedError, ray.exceptions.RayError) as exc:
        text = " ".join(str(exc).split())[:200]
        return {"status": "failed", "exit_code": 1, "error": (
            f"error: its worker died {plan.retries + 1} times ({type(exc).__name__}: {text})")}


def _drive(ray, todo, records, plan: Plan, report: LineReport) -> None:
    """Submit the jobs lazily, at most ``window`` in flight (so the driver's memory does not
    grow with the batch), and gather each as it ends."""
    from crackbake.transaction.interrupt import received

    task = ray.remote(max_calls=1)(_run_job)
    largest = _largest_memory(ray)
    local = bool(plan.ray_info.get("local"))
    if local:
        # The slot resource holds the jobs at once; one job more in flight, queued on Ray, so
        # its worker boots on the spare CPU while the others run.  Its tasks all have one
        # shape (the memory is held here, not asked of Ray), so Ray starts them in the batch
        # file's order: tasks of different shapes are queued apart, in no order.
        slots, per_job = local_slots(plan)
        window = slots + 1
    else:
        cores = ray.cluster_resources().get("CPU", 1)
        per_job = plan.cpus_per_job or (max(1, int(cores) // plan.workers) if plan.workers
                                        else 1)
        slots = plan.workers or max(1, int(cores // per_job))
        # On a cluster ``--workers`` is held by what is in flight; otherwise twice the slots.
        window = plan.workers or slots * 2
    queue = deque(todo)
    pending: dict = {}
    done = 0
    total = len(todo)

    def finish(i: int, outcome: dict) -> None:
        nonlocal done
        done += 1
        r = records[i]
        r.update(outcome)
        line = f"[{done}/{total}] {r['status']:<6} {r['name']}"
        if r["status"] == "ok":
            line += f"  {r.get('run_s', 0):.1f} s, {r.get('peak_rss_mb', 0):.0f} MB peak"
            if r.get("node"):
                line += f", node {r['node'][:8]}"
        elif r.get("error"):
            line += f"  {r['error']}"
        report.finished(r, line)

    try:
        while queue or pending:
            while queue and len(pending) < window:
                i, job, extra = queue[0]
                need = records[i]["memory_estimate_mb"] * 2**20
                if largest and need > largest:
                    queue.popleft()
                    finish(i, {"status": "failed", "exit_code": 2, "error": (
                        f"error: needs an estimated {need / 2**30:.1f} GiB, more than any node "
                        f"offers ({largest / 2**30:.1f} GiB); lower --res, --stress-res or "
                        "--sim-faces")})
                    continue
                if local:
                    # The node's memory, held here as Ray would: the jobs in flight (queued
                    # or running) and this one must fit, or it waits for one to end.
                    held = sum(records[k]["memory_estimate_mb"] for k, _ in pending.values())
                    if pending and held * 2**20 + need > largest:
                        break
                    shape = {"resources": {SLOT: 1}}
                else:
                    shape = {"memory": int(need)}
                queue.popleft()
                ref = task.options(
                    num_cpus=per_job, max_retries=plan.retries, retry_exceptions=False,
                    name=f"crackbake:{job.name}", **shape,
                ).remote(job.params, extra)
                pending[ref] = (i, time.perf_counter())
            report.running(min(len(pending), slots))
            ready, _ = ray.wait(list(pending), num_returns=1)
            for ref in ready:
                i, t_sub = pending.pop(ref)
                outcome = _outcome(ray, ref, plan)
                outcome["wall_s"] = round(time.perf_counter() - t_sub, 3)
                finish(i, outcome)
    except KeyboardInterrupt as exc:
        # Ray's wait turns the handler's Interrupt into a plain KeyboardInterrupt: the signal
        # that came is what the handler saw.
        plan.ray_info["interrupted"] = received() or getattr(exc, "signum", signal.SIGINT)
        _cancel(ray, pending, records, plan, slots)


def _cancel(ray, pending: dict, records: list[dict], plan: Plan, slots: int) -> None:
    """Cancel the tasks in flight.

    A running job gets :data:`CANCEL_GRACE_S` (or until another Ctrl-C) to unwind: Ray raises
    KeyboardInterrupt in its worker and the output transaction removes its staging folder.  A
    job still running then (inside a long compiled call, where Python cannot raise) has its
    worker killed, and the driver removes what it staged, under the folder's lock (which the
    kernel frees with the dead process, so no live run can own it).  A job that had committed
    its folder before the cancel reached it keeps its ``ok`` record.
    """
    for ref in pending:
        ray.cancel(ref)
    left = dict(pending)
    why = f"cancelled ({_signal_name(plan)})"
    # Ray starts a local batch's jobs in order: those past the first ``slots`` in flight were
    # still queued.
    queued = {i for i, _ in list(pending.values())[slots:]} if plan.ray_info.get("local") \
        else set()

    def gather(timeout: float) -> None:
        end = time.monotonic() + timeout
        while left and time.monotonic() < end:
            ready, _ = ray.wait(list(left), num_returns=1, timeout=end - time.monotonic())
            for ref in ready:
                i, _ = left.pop(ref)
                outcome = _outcome(ray, ref, plan)
                if outcome.get("exit_code") in (128 + signal.SIGINT, 128 + signal.SIGTERM):
                    outcome = {"status": "cancelled", "error": f"{why} while running"}
                elif outcome.get("status") == "cancelled" and i in queued:
                    outcome = {"status": "cancelled", "error": f"{why} before it started"}
                records[i].update(outcome)

    try:
        gather(CANCEL_GRACE_S)
    except KeyboardInterrupt:  # asked twice: stop waiting
        pass
    killed = [i for i, _ in left.values()]
    if left:
        for ref in left:
            ray.cancel(ref, force=True)
        try:
            gather(10.0)
        except KeyboardInterrupt:
            pass
    for i in killed:
        if records[i].get("status") == "ok":  # it committed before the kill reached it
            continue
        left_behind = _remove_staging(Path(records[i]["folder"]))
        records[i].update(status="cancelled", error=f"{why} while running; its worker was "
                          "killed" + (f"; {left_behind}" if left_behind else ""))


def _remove_staging(folder: Path) -> str | None:
    """Remove what a killed job staged beside ``folder``; None, or why it could not."""
    from crackbake.errors import CrackbakeError
    from crackbake.transaction.outdir import FolderLock, remove_leftovers, target_dir

    final = target_dir(folder)
    try:
        with FolderLock(final):
            remove_leftovers(final)
    except CrackbakeError:  # its worker still holds the lock: the next run cleans up
        return "its staging folder is left until the next run into that folder"
    return None
