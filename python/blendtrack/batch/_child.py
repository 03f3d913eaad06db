"""The worker process of one run: ``python -m blendtrack.batch._child TASK.json RESULT.json``.

Reads the task, runs it (:func:`blendtrack.batch.kinds.execute`) and writes
``{"status": "ok", "metrics": {...}}`` or ``{"status": "failed", "error":
"..."}`` to RESULT.json (temporary file + rename, so the parent never reads
half a result). The traceback of a failure goes to stderr, which the parent
keeps in the run's ``run.log``. A process that dies without writing a
result (a segmentation fault in SUMO, a kill) is detected by the parent
from its exit status.

On Linux the process asks the kernel to kill it when its parent dies
(``PR_SET_PDEATHSIG``), so a batch killed with SIGKILL leaves no run behind.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import time
import traceback
from pathlib import Path


def _die_with_parent(parent_pid: int) -> None:
    if not sys.platform.startswith("linux"):
        return
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        pr_set_pdeathsig = 1
        libc.prctl(pr_set_pdeathsig, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):
        return
    if os.getppid() != parent_pid:  # the parent died before prctl
        os._exit(1)


def one_line(e: BaseException) -> str:
    """``Type: message`` on one line."""
    text = " ".join(str(e).split())
    return f"{type(e).__name__}: {text}" if text else type(e).__name__


def main(argv: list[str]) -> int:
    task_file, result_file = Path(argv[0]), Path(argv[1])
    task = json.loads(task_file.read_text())
    _die_with_parent(int(task.get("parent_pid", os.getppid())))
    os.environ.setdefault("MPLBACKEND", "Agg")
    t0 = time.perf_counter()
    result: dict[str, object]
    try:
        from blendtrack.batch.kinds import execute

        result = {"status": "ok", "metrics": execute(task)}
    except Exception as e:
        traceback.print_exc()
        result = {"status": "failed", "error": one_line(e)}
    result["run_time_s"] = time.perf_counter() - t0
    tmp = result_file.with_name(result_file.name + ".tmp")
    tmp.write_text(json.dumps(result, allow_nan=False))
    os.replace(tmp, result_file)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
