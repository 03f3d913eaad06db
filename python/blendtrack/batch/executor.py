"""Executors: where the runs of a batch execute.

Every run executes in a fresh Python process of its own
(:func:`run_isolated` starts ``python -m blendtrack.batch._child``): libsumo
allows one simulation per process, and a run that crashes (a segmentation
fault in SUMO, the out-of-memory killer) or overruns its time limit ends
only that process, never the batch. The outcome of a run is a plain dict
(status, error, metrics, times, host), the same whichever executor ran it:

- :class:`LocalExecutor`: N threads on this machine, each starting and
  waiting for one run process at a time (threads only wait; the work is in
  the processes).
- :class:`DaskExecutor`: one Dask task per run on a ``LocalCluster`` of N
  single-threaded worker processes (``--dask-local N``) or on an existing
  cluster (``--scheduler tcp://HOST:PORT``). The task is
  :func:`run_isolated` itself, so on a Dask worker too each run has its own
  process. The outcomes come back to the batch process, which alone writes
  the results.

A run process that outlives its ``timeout_s`` is killed with its children
(SUMO processes) and the run is recorded with status ``timeout``.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Iterable, Iterator, Mapping
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait
from pathlib import Path
from typing import Any

from blendtrack import BlendtrackError


class BatchExecutorError(BlendtrackError):
    """An executor that cannot start (no scheduler at the address, a version mismatch)."""


#: Lines of the run's log quoted in the error of a process that died.
_TAIL_LINES = 3

_live: set[subprocess.Popen[bytes]] = set()
_live_lock = threading.Lock()
#: Set by kill_running: a run process started after it is killed at once.
_stopping = threading.Event()


def _signal_name(number: int) -> str:
    try:
        return signal.Signals(number).name
    except ValueError:
        return f"signal {number}"


def _kill_tree(proc: subprocess.Popen[bytes]) -> None:
    """Kills a run process and every process it started (SUMO)."""
    try:
        import psutil

        try:
            children = psutil.Process(proc.pid).children(recursive=True)
        except psutil.Error:
            children = []
        for child in children:
            try:
                child.kill()
            except psutil.Error:
                pass
    except ImportError:
        pass
    try:
        proc.kill()
    except OSError:
        pass
    proc.wait()


def kill_running() -> None:
    """Kills every run process this process started that is still running (on Ctrl-C)."""
    with _live_lock:
        _stopping.set()
        procs = list(_live)
    for proc in procs:
        _kill_tree(proc)


def _tail(log: Path) -> str:
    try:
        lines = [ln.strip() for ln in log.read_text(errors="replace").splitlines() if ln.strip()]
    except OSError:
        return ""
    return " | ".join(lines[-_TAIL_LINES:])


def child_env(base: Mapping[str, str]) -> dict[str, str]:
    """The environment of a run's process: ``base`` with plots to files,
    unbuffered output, and numpy's OpenBLAS on one thread unless ``base``
    says otherwise. Nothing in a run needs BLAS threads, and OpenBLAS
    starts one that spins at import: 0.1 s of CPU per run (user time of
    importing the runner, five pairs on an idle 2-core machine: 0.70-0.85 s
    against 0.57-0.67 s), taken from the other workers' runs."""
    return {"OPENBLAS_NUM_THREADS": "1", **base, "MPLBACKEND": "Agg", "PYTHONUNBUFFERED": "1"}


def run_isolated(task: dict[str, Any]) -> dict[str, Any]:
    """Runs one task in a new process and returns its outcome.

    The run's folder ``task["work_dir"]`` is emptied first (a retried run
    starts clean); the process's output goes to ``run.log`` in it. Outcome
    keys: ``status`` (ok, failed, timeout), ``error`` (one line, empty when
    ok), ``metrics``, ``wall_time_s``, ``started_at`` / ``finished_at``
    (Unix time), ``host``, ``exit_code``.
    """
    work = Path(task["work_dir"])
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True, exist_ok=True)
    task_file = work / "task.json"
    result_file = work / "result.json"
    task_file.write_text(json.dumps({**task, "parent_pid": os.getpid()}, indent=2))
    env = child_env(os.environ)
    timeout = task.get("timeout_s")
    started = time.time()
    t0 = time.perf_counter()
    outcome: dict[str, Any] = {"status": "failed", "error": "", "metrics": {}}
    with open(work / "run.log", "wb") as log:
        proc = subprocess.Popen(
            [sys.executable, "-m", "blendtrack.batch._child", str(task_file), str(result_file)],
            stdin=subprocess.DEVNULL,
            stdout=log,
            stderr=subprocess.STDOUT,
            cwd=work,
            env=env,
        )
        with _live_lock:
            _live.add(proc)
            stopping = _stopping.is_set()
        try:
            if stopping:  # started while the batch was being interrupted
                _kill_tree(proc)
            code = proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            _kill_tree(proc)
            code = proc.returncode
            outcome.update(status="timeout", error=f"timed out after {timeout:g} s (the run's processes were killed)")
        finally:
            with _live_lock:
                _live.discard(proc)
    outcome["wall_time_s"] = time.perf_counter() - t0
    outcome["started_at"] = started
    outcome["finished_at"] = time.time()
    outcome["host"] = socket.gethostname()
    outcome["exit_code"] = code
    if outcome["status"] == "timeout":
        return outcome
    if result_file.is_file():
        try:
            result = json.loads(result_file.read_text())
        except (OSError, ValueError) as e:
            outcome["error"] = f"unreadable result of the run process: {e}"
            return outcome
        outcome["status"] = result.get("status", "failed")
        outcome["error"] = result.get("error", "")
        outcome["metrics"] = result.get("metrics", {})
        return outcome
    tail = _tail(work / "run.log")
    if code is not None and code < 0:
        why = f"worker process died ({_signal_name(-code)}, signal {-code})"
    else:
        why = f"worker process exited with code {code} without a result"
    outcome["error"] = f"{why}: {tail}" if tail else why
    return outcome


def _failure(task: dict[str, Any], error: str) -> dict[str, Any]:
    now = time.time()
    return {"status": "failed", "error": error, "metrics": {}, "wall_time_s": 0.0, "started_at": now,
            "finished_at": now, "host": "", "exit_code": None}


class LocalExecutor:
    """Runs on this machine, at most ``workers`` run processes at a time."""

    def __init__(self, workers: int):
        self.workers = workers
        self.description = f"local, {workers} worker process{'es' if workers != 1 else ''}"
        self._pool: ThreadPoolExecutor | None = None

    def __enter__(self) -> LocalExecutor:
        _stopping.clear()
        self._pool = ThreadPoolExecutor(max_workers=self.workers, thread_name_prefix="blendtrack-batch")
        return self

    def __exit__(self, *exc: object) -> None:
        assert self._pool is not None
        if exc[0] is not None:  # interrupted: stop what runs, start nothing more
            self._pool.shutdown(wait=False, cancel_futures=True)
            kill_running()
        self._pool.shutdown(wait=True, cancel_futures=True)

    def map_unordered(self, tasks: Iterable[dict[str, Any]]) -> Iterator[tuple[dict[str, Any], dict[str, Any]]]:
        """Yields (task, outcome) as runs finish."""
        assert self._pool is not None
        pending: dict[Future[dict[str, Any]], dict[str, Any]] = {self._pool.submit(run_isolated, t): t for t in tasks}
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                task = pending.pop(fut)
                try:
                    outcome = fut.result()
                except Exception as e:  # starting the process failed (e.g. no space for the run folder)
                    outcome = _failure(task, f"could not start the run: {type(e).__name__}: {e}")
                yield task, outcome


def _blendtrack_version() -> str:
    import blendtrack

    return str(blendtrack.__version__)


def _stop_heartbeat(dask_worker: Any) -> None:
    """Run on each worker of our own LocalCluster before it closes."""
    dask_worker.periodic_callbacks["heartbeat"].stop()


class DaskExecutor:
    """Runs on a Dask cluster: a new ``LocalCluster`` of ``local_workers``
    single-threaded processes, or the scheduler at ``address``."""

    def __init__(self, address: str | None = None, local_workers: int | None = None):
        if (address is None) == (local_workers is None):
            raise ValueError("give either a scheduler address or a number of local workers")
        self.address = address
        self.local_workers = local_workers
        self.description = f"Dask LocalCluster, {local_workers} worker processes" if address is None else f"Dask scheduler {address}"
        self._cluster: Any = None
        self._client: Any = None

    def __enter__(self) -> DaskExecutor:
        import logging

        from distributed import Client, LocalCluster

        # The cluster's own log lines (worker start/stop, closing comms) would
        # tear through the progress bar; errors still show.
        for name in ("distributed", "distributed.nanny", "distributed.scheduler", "distributed.worker", "distributed.core"):
            logging.getLogger(name).setLevel(logging.ERROR)
        try:
            if self.address is None:
                # The worker processes start with SIGINT ignored (Python keeps an
                # inherited SIG_IGN), so Ctrl-C reaches the batch process alone,
                # which closes the cluster; no traceback from every worker.
                # The same for the workers' log lines (they read it when they start).
                os.environ.setdefault("DASK_LOGGING__DISTRIBUTED", "error")
                main = threading.current_thread() is threading.main_thread()
                old = signal.signal(signal.SIGINT, signal.SIG_IGN) if main else None
                try:
                    self._cluster = LocalCluster(
                        n_workers=self.local_workers,
                        threads_per_worker=1,
                        processes=True,
                        # No dashboard. The scheduler still serves its health
                        # routes over HTTP, by default on 8787, and warns when
                        # that port is taken (a second batch): a free port.
                        dashboard_address=None,
                        scheduler_kwargs={"dashboard": False, "dashboard_address": ":0"},
                        # A task only waits for its run process, whose memory is its own.
                        memory_limit=0,
                    )
                finally:
                    if main:
                        signal.signal(signal.SIGINT, old)
                self._client = Client(self._cluster)
            else:
                try:
                    self._client = Client(self.address, timeout="20s")
                except (OSError, TimeoutError) as e:
                    raise BatchExecutorError(f"cannot connect to the Dask scheduler {self.address}: {e}") from None
            try:
                versions = self._client.run(_blendtrack_version)
            except Exception as e:  # a worker without blendtrack cannot even load the function
                raise BatchExecutorError(f"a Dask worker cannot run blendtrack: {type(e).__name__}: {' '.join(str(e).split())}") from None
        except BaseException:
            self.__exit__(None, None, None)
            raise
        mine = _blendtrack_version()
        other = {w: v for w, v in versions.items() if v != mine}
        if other:
            self.__exit__(None, None, None)
            worker, version = next(iter(other.items()))
            raise BatchExecutorError(f"Dask worker {worker} has blendtrack {version}, this machine {mine}: install the same version everywhere")
        if not versions:
            print(f"blendtrack batch: waiting for Dask workers to join {self.address}", file=sys.stderr)
        return self

    def __exit__(self, *exc: object) -> None:
        if self._client is not None:
            if self._cluster is not None:
                # A worker whose heartbeat is on its way while the cluster closes
                # logs "Failed to communicate with scheduler" with a traceback:
                # a race in Dask's shutdown, not a fault of the batch. Our own
                # workers stop beating before they are closed.
                try:
                    self._client.run(_stop_heartbeat, on_error="ignore")
                except Exception:
                    pass
            try:
                self._client.close()
            except Exception:
                pass
            self._client = None
        if self._cluster is not None:
            try:
                self._cluster.close()
            except Exception:
                pass
            self._cluster = None

    def map_unordered(self, tasks: Iterable[dict[str, Any]]) -> Iterator[tuple[dict[str, Any], dict[str, Any]]]:
        from distributed import as_completed

        client = self._client
        futures = {}
        for t in tasks:
            # A fresh key per submission: a retried run is a new task, never a cached result.
            fut = client.submit(run_isolated, t, key=f"blendtrack-run-{t['run_id']}-{uuid.uuid4().hex[:8]}", pure=False, retries=0)
            futures[fut] = t
        try:
            for fut in as_completed(list(futures)):
                task = futures[fut]
                try:
                    outcome = fut.result()
                except Exception as e:  # the Dask worker died (KilledWorker), or the task was lost
                    outcome = _failure(task, f"Dask task failed: {type(e).__name__}: {' '.join(str(e).split())}")
                yield task, outcome
        finally:
            client.cancel(list(futures))


