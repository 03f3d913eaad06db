"""Speed-up of `blendtrack batch` with more workers: one 16-run sweep, run
with 1 and 2 local worker processes (and a Dask LocalCluster of 2), in this
one invocation.

    .venv/bin/python scripts/bench_batch.py [--end 150] [--no-dask]

The sweep: `sumo run` on the rural loop for END simulated seconds, alpha in
0.0, 0.15, ..., 1.05 capped at 1 (8 values) x 2 seeds. Each run is a
process of its own (Python start-up, SUMO start-up, the run, its plots), a
few seconds each. Prints a table: wall time of the whole batch, of its runs
(the batch minus the report, timed on its own afterwards), and the speed-up
over 1 worker. The machine's other load is not controlled: run it on an idle
machine for clean numbers.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

from blendtrack.batch import BatchOptions, default_workers, load_sweep, run_batch, write_report

SWEEP = """
kind = "sumo"
scenarios = ["rural_loop"]
seeds = 2
[fixed]
end = {end}
[grid]
alpha = [0.0, 0.15, 0.3, 0.45, 0.6, 0.75, 0.9, 1.0]
"""


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--end", type=float, default=150.0, help="simulated seconds per run (default 150)")
    ap.add_argument("--no-dask", action="store_true", help="leave out the Dask LocalCluster row")
    args = ap.parse_args()

    with tempfile.TemporaryDirectory(prefix="bench_batch-") as tmp:
        file = Path(tmp) / "bench.toml"
        file.write_text(SWEEP.format(end=args.end))
        sweep = load_sweep(file)
        assert len(sweep.runs) == 16
        setups: list[tuple[str, dict[str, int]]] = [("local, 1 worker", {"workers": 1}), ("local, 2 workers", {"workers": 2})]
        if not args.no_dask:
            setups.append(("Dask LocalCluster, 2 workers", {"dask_local": 2}))
        rows = []
        for label, kw in setups:
            out = Path(tmp) / label.replace(" ", "_").replace(",", "")
            print(f"{label}: running 16 runs ...", file=sys.stderr, flush=True)
            result = run_batch(sweep, BatchOptions(out=out, progress=False, **kw))  # type: ignore[arg-type]
            if result.ok != 16:
                print(f"{label}: {result.failed + result.timeout} runs failed; see {out}/summary.md", file=sys.stderr)
                return 1
            t0 = time.perf_counter()
            frame = write_report(out)
            report_s = time.perf_counter() - t0
            per_run = float(frame["wall_time_s"].sum())
            rows.append((label, result.wall_time_s, result.wall_time_s - report_s, per_run))

    base_total, base_runs = rows[0][1], rows[0][2]
    cores = default_workers()
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"16 runs of `sumo run rural_loop --end {args.end:g}`; {cores} cores available; load average at the end {load:.2f}")
    print()
    print("| executor | batch wall (s) | runs wall (s) | sum of run times (s) | speed-up (batch) | speed-up (runs) |")
    print("|---|---|---|---|---|---|")
    for label, total, runs, per_run in rows:
        print(f"| {label} | {total:.1f} | {runs:.1f} | {per_run:.1f} | {base_total / total:.2f}x | {base_runs / runs:.2f}x |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
