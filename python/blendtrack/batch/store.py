"""The result store of a batch: one JSON file per finished run.

Layout of the output folder ``DIR``::

    DIR/sweep.toml          a copy of the sweep file (for people)
    DIR/batch.json          the runs of the sweep (id, name, parameters, seed)
    DIR/runs/<run_id>.json  one record per finished run (ok, failed or timeout)
    DIR/work/<run_id>/      what the run wrote (SUMO outputs, its log)
    DIR/results.parquet, DIR/results.csv, DIR/summary.md, DIR/plots/
                            derived from runs/*.json at the end

Every file is written to a temporary name in its folder, flushed to disk
and renamed into place (``os.replace`` is atomic), so a batch killed at any
moment, even with SIGKILL, leaves only complete records; ``--resume`` then
runs what has no ``ok`` record. The batch process is the only writer.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any

from blendtrack import BlendtrackError
from blendtrack.batch.sweep import Run, Sweep

# Temporary files are created 0600; the final files get the usual mode.
_UMASK = os.umask(0o022)
os.umask(_UMASK)

#: Files derived from the records (removed at the start, rebuilt at the end).
DERIVED = ("summary.md", "results.csv", "results.parquet")


class BatchError(BlendtrackError):
    """An output folder a batch cannot use (results of another sweep, results without --resume)."""


def atomic_write(path: Path, data: bytes | str) -> None:
    """Writes ``path`` via a temporary file in the same folder, fsync and rename."""
    raw = data.encode() if isinstance(data, str) else data
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.chmod(tmp, 0o666 & ~_UMASK)
        with os.fdopen(fd, "wb") as f:
            f.write(raw)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    try:  # make the rename itself durable
        dfd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)
    except OSError:
        pass


def _is_num(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def record_problem(rec: dict[str, Any]) -> str | None:
    """What is wrong with the types of a run record's fields (None: nothing)."""
    checks = (
        ("status", lambda v: v in ("ok", "failed", "timeout"), "one of ok, failed, timeout"),
        ("error", lambda v: v is None or isinstance(v, str), "a string"),
        ("attempt", lambda v: v is None or (_is_int(v) and v >= 0), "a whole number >= 0"),
        ("wall_time_s", lambda v: v is None or _is_num(v), "a number"),
        ("seed", lambda v: v is None or _is_int(v), "a whole number"),
        ("params", lambda v: v is None or isinstance(v, dict), "a table"),
        (
            "metrics",
            lambda v: v is None or (isinstance(v, dict) and all(x is None or _is_num(x) for x in v.values())),
            "a table of numbers",
        ),
    )
    for key, ok, what in checks:
        if key in rec and not ok(rec[key]):
            return f"`{key}` must be {what}, got {json.dumps(rec[key])[:60]}"
    return None


def manifest_problem(data: Any) -> str | None:
    """What is wrong with a parsed ``batch.json`` (None: nothing)."""
    if not isinstance(data, dict):
        return f"expected a JSON object, got {type(data).__name__}"
    runs = data.get("runs", [])
    if not isinstance(runs, list):
        return f"`runs` must be a list, got {json.dumps(runs)[:60]}"
    for i, r in enumerate(runs):
        if not (isinstance(r, dict) and all(isinstance(r.get(k), str) for k in ("run_id", "name", "kind", "scenario"))):
            return f"runs[{i}] must have the strings run_id, name, kind and scenario"
        if not isinstance(r.get("params", {}), dict) or not _is_int(r.get("seed")):
            return f"runs[{i}] must have a table `params` and a whole number `seed`"
    swept = data.get("swept", {})
    if not (isinstance(swept, dict) and all(isinstance(v, list) for v in swept.values())):
        return "`swept` must be a table of lists"
    for key in ("scenarios", "seeds"):
        if not isinstance(data.get(key, []), list):
            return f"`{key}` must be a list"
    return None


def atomic_write_all(files: list[tuple[Path, bytes | str]]) -> None:
    """Writes every file to a temporary name first, then renames them all in
    the order given: what takes time (rendering, writing) is done before the
    first rename, so a kill leaves either the old set or, for an instant
    between renames, the earlier names of the new set."""
    tmps: list[tuple[str, Path]] = []
    try:
        for path, data in files:
            raw = data.encode() if isinstance(data, str) else data
            fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
            tmps.append((tmp, path))
            os.chmod(tmp, 0o666 & ~_UMASK)
            with os.fdopen(fd, "wb") as f:
                f.write(raw)
                f.flush()
                os.fsync(f.fileno())
        for tmp, path in tmps:
            os.replace(tmp, path)
    except BaseException:
        for tmp, _ in tmps:
            try:
                os.unlink(tmp)
            except OSError:
                pass
        raise


class ResultStore:
    """Records of the runs of one batch in ``out``."""

    def __init__(self, out: Path):
        self.out = out.resolve()
        self.runs_dir = self.out / "runs"
        self.work_dir = self.out / "work"
        self.manifest_file = self.out / "batch.json"

    def work(self, run_id: str) -> Path:
        return self.work_dir / run_id

    def records(self) -> dict[str, dict[str, Any]]:
        """Every readable record, by run id.

        Raises :class:`BatchError` naming the file for a record whose fields
        have the wrong types (edited by hand, say): a report built from it
        would be wrong, and a resume could not count its attempts.
        """
        out: dict[str, dict[str, Any]] = {}
        if not self.runs_dir.is_dir():
            return out
        for file in sorted(self.runs_dir.glob("*.json")):
            if file.name.startswith("."):
                continue
            try:
                rec = json.loads(file.read_text())
            except (OSError, ValueError):
                continue  # cannot happen with atomic writes; such a run is simply run again
            if isinstance(rec, dict) and rec.get("run_id") == file.stem:
                problem = record_problem(rec)
                if problem:
                    raise BatchError(f"{file}: not a valid run record: {problem} (delete the file to run that run again)")
                out[file.stem] = rec
        return out

    def manifest(self) -> dict[str, Any] | None:
        """``batch.json``, or None when there is none (or it is not JSON).

        Raises :class:`BatchError` for JSON that is not a batch manifest."""
        try:
            data = json.loads(self.manifest_file.read_text())
        except (OSError, ValueError):
            return None
        problem = manifest_problem(data)
        if problem:
            raise BatchError(f"{self.manifest_file}: not a batch manifest: {problem}")
        return data if isinstance(data, dict) else None

    def check(self, sweep: Sweep, resume: bool) -> dict[str, dict[str, Any]]:
        """Checks ``out`` can hold this sweep's results (writing nothing) and returns the records already there.

        Without ``resume``, a folder that already holds a batch is an error;
        with it, a folder made from a different sweep (other run ids) is.
        """
        manifest = self.manifest()
        records = self.records()
        if manifest is None and not records:
            theirs = [name for name in DERIVED if (self.out / name).exists()]
            if theirs:
                raise BatchError(
                    f"{self.out} holds {', '.join(theirs)} but no batch (no batch.json): "
                    "not a batch folder, its files would be replaced; choose another --out"
                )
        if (manifest is not None or records) and not resume:
            n = len(records)
            raise BatchError(
                f"{self.out} already holds a batch ({n} run{'s' if n != 1 else ''} recorded): "
                "pass --resume to continue it, or choose another --out"
            )
        mine = {r.run_id for r in sweep.runs}
        theirs = {r["run_id"] for r in manifest.get("runs", []) if isinstance(r, dict) and "run_id" in r} if manifest else set()
        theirs |= set(records)
        if resume and theirs and theirs != mine:
            gone, new = len(theirs - mine), len(mine - theirs)
            raise BatchError(
                f"{self.out} holds a batch of a different sweep ({gone} of its runs are not in {sweep.file}, "
                f"{new} of the sweep's are not in it): choose another --out"
            )
        return records

    def start(self, sweep: Sweep) -> None:
        """Makes the folders, removes left-over temporary files and the derived
        files (so an interrupted batch leaves no report that looks complete),
        and writes ``batch.json`` and ``sweep.toml``."""
        self.runs_dir.mkdir(parents=True, exist_ok=True)
        self.work_dir.mkdir(parents=True, exist_ok=True)
        for tmp in [*self.runs_dir.glob(".*.tmp"), *self.out.glob(".*.tmp")]:
            tmp.unlink(missing_ok=True)
        for name in DERIVED:
            (self.out / name).unlink(missing_ok=True)
        write_manifest(self.out, sweep)

    def write(self, record: dict[str, Any]) -> None:
        atomic_write(self.runs_dir / f"{record['run_id']}.json", json.dumps(record, indent=2, allow_nan=False) + "\n")


def write_manifest(out: Path, sweep: Sweep) -> None:
    manifest = {
        "sweep_file": str(sweep.file.resolve()),
        "kind": sweep.kind,
        "scenarios": sweep.scenarios,
        "seeds": sweep.seeds,
        "fixed": sweep.fixed,
        "swept": sweep.swept,
        "description": sweep.description,
        "runs": [r.manifest() for r in sweep.runs],
    }
    atomic_write(out / "batch.json", json.dumps(manifest, indent=2) + "\n")
    atomic_write(out / "sweep.toml", sweep.text)


def make_record(run: Run, outcome: dict[str, Any], attempt: int) -> dict[str, Any]:
    """The record of a finished run: its parameters and seed with the executor's outcome."""
    import blendtrack

    return {
        **run.manifest(),
        "status": outcome.get("status", "failed"),
        "error": outcome.get("error", ""),
        "metrics": outcome.get("metrics", {}),
        "wall_time_s": outcome.get("wall_time_s"),
        "started_at": outcome.get("started_at"),
        "finished_at": outcome.get("finished_at"),
        "host": outcome.get("host", ""),
        "exit_code": outcome.get("exit_code"),
        "attempt": attempt,
        "blendtrack_version": blendtrack.__version__,
    }
