"""``blendtrack batch``: parameter sweeps, on one machine or on a Dask cluster.

A sweep file (:mod:`blendtrack.batch.sweep`) names a kind of run (``sim``,
``sumo`` or ``compare``), scenarios, parameter values (a grid, zipped lists,
explicit cases) and seeds; :func:`run_batch` expands it into runs with
stable ids and executes each in a worker process of its own
(:mod:`blendtrack.batch.executor`: local processes by default, or Dask). As
each run finishes, the batch process writes its record atomically
(:mod:`blendtrack.batch.store`); at the end it derives ``results.parquet``,
``results.csv``, the plots and ``summary.md`` from the records
(:mod:`blendtrack.batch.report`).

Interrupting is safe at any moment, SIGKILL included: a record is either
complete or absent, and ``resume=True`` runs every run without an ``ok``
record (failed and timed-out runs are retried) and never one twice.

Example::

    from pathlib import Path
    from blendtrack.batch import BatchOptions, load_sweep, run_batch

    sweep = load_sweep("sweeps/alpha_sweep.toml")
    result = run_batch(sweep, BatchOptions(out=Path("out/alpha"), workers=2))
    print(result.ok, result.failed, result.summary)
"""

from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from blendtrack.batch.store import BatchError, ResultStore, make_record
from blendtrack.batch.sweep import KINDS, PARAMS, Run, Sweep, SweepError, load_sweep, params_for, parse_sweep

__all__ = [
    "KINDS",
    "PARAMS",
    "BatchError",
    "BatchOptions",
    "BatchResult",
    "Run",
    "Sweep",
    "SweepError",
    "default_workers",
    "load_sweep",
    "params_for",
    "parse_sweep",
    "run_batch",
    "write_report",
]


def default_workers() -> int:
    """The number of cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:
        return max(1, os.cpu_count() or 1)


@dataclass
class BatchOptions:
    """How to run a sweep (see ``blendtrack batch --help``)."""

    out: Path
    #: Local worker processes (default: the core count).
    workers: int | None = None
    #: Address of a running Dask scheduler (``tcp://HOST:PORT``).
    scheduler: str | None = None
    #: Start a Dask LocalCluster with this many worker processes.
    dask_local: int | None = None
    #: Keep the ``ok`` records in ``out`` and run the rest.
    resume: bool = False
    #: Per-run time limit (s); overrides the sweep's ``timeout_s``.
    timeout_s: float | None = None
    progress: bool = True


@dataclass
class BatchResult:
    out: Path
    runs: int
    #: Runs with an ok record from an earlier invocation (``resume``), not run again.
    skipped: int
    ok: int
    failed: int
    timeout: int
    wall_time_s: float
    executor: str
    summary: Path


def _executor(opts: BatchOptions) -> Any:
    from blendtrack.batch.executor import DaskExecutor, LocalExecutor

    chosen = [x is not None for x in (opts.scheduler, opts.dask_local)]
    if sum(chosen) > 1:
        raise BatchError("choose one of --scheduler and --dask-local")
    if opts.scheduler is not None:
        return DaskExecutor(address=opts.scheduler)
    if opts.dask_local is not None:
        if opts.dask_local < 1:
            raise BatchError(f"--dask-local must be >= 1, got {opts.dask_local}")
        return DaskExecutor(local_workers=opts.dask_local)
    workers = opts.workers if opts.workers is not None else default_workers()
    if workers < 1:
        raise BatchError(f"--workers must be >= 1, got {workers}")
    return LocalExecutor(workers)


def run_batch(sweep: Sweep, opts: BatchOptions) -> BatchResult:
    """Runs every run of ``sweep`` that has no ok record in ``opts.out``, then writes the report.

    Raises :class:`BatchError` when ``opts.out`` holds another batch (or any
    batch without ``resume``); KeyboardInterrupt stops the running runs and
    leaves the records written so far (and no report).
    """
    from tqdm import tqdm

    from blendtrack.batch.report import write_report

    t0 = time.perf_counter()
    executor = _executor(opts)
    store = ResultStore(opts.out)
    existing = store.check(sweep, opts.resume)
    done = {rid for rid, rec in existing.items() if rec.get("status") == "ok"}
    todo = [r for r in sweep.runs if r.run_id not in done]
    by_id: dict[str, Run] = {r.run_id: r for r in todo}
    timeout = opts.timeout_s if opts.timeout_s is not None else sweep.timeout_s
    counts = {"ok": 0, "failed": 0, "timeout": 0}

    def postfix() -> str:
        remaining = len(todo) - sum(counts.values())
        return f"done {counts['ok']}, failed {counts['failed'] + counts['timeout']}, remaining {remaining}"

    with tqdm(total=len(sweep.runs), initial=len(done), desc="blendtrack batch", unit="run", file=sys.stderr,
              disable=not opts.progress or None, dynamic_ncols=True) as bar:
        bar.set_postfix_str(postfix())
        if not todo:
            store.start(sweep)
        else:
            # The executor first: a scheduler that cannot be reached leaves the folder untouched.
            with executor:
                store.start(sweep)
                tasks = [r.task(store.work(r.run_id), timeout) for r in todo]
                for task, outcome in executor.map_unordered(tasks):
                    run = by_id[task["run_id"]]
                    attempt = int(existing.get(run.run_id, {}).get("attempt", 0) or 0) + 1
                    record = make_record(run, outcome, attempt)
                    store.write(record)
                    status = record["status"] if record["status"] in counts else "failed"
                    counts[status] += 1
                    if status != "ok":
                        tqdm.write(f"blendtrack batch: {run.name} ({run.run_id}) {status}: {record['error']}", file=sys.stderr)
                    bar.set_postfix_str(postfix(), refresh=False)
                    bar.update(1)
    write_report(store.out)
    return BatchResult(
        out=store.out,
        runs=len(sweep.runs),
        skipped=len(done),
        ok=counts["ok"],
        failed=counts["failed"],
        timeout=counts["timeout"],
        wall_time_s=time.perf_counter() - t0,
        executor=executor.description,
        summary=store.out / "summary.md",
    )


def write_report(out: Path) -> Any:
    """Rebuilds results.parquet, results.csv, plots/ and summary.md of the batch in ``out``; returns the results table."""
    from blendtrack.batch.report import write_report as _write

    return _write(out)
