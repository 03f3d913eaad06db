"""``blendtrack batch``: a parameter sweep from a TOML file."""

from __future__ import annotations

import argparse
import signal
import sys
from pathlib import Path as FsPath

from blendtrack.cli.common import Parser, finite, raise_interrupt, whole


def _cmd_batch(args: argparse.Namespace) -> int:
    from blendtrack import batch

    sweep = batch.load_sweep(args.sweep)
    out_dir = args.out if args.out is not None else sweep.out
    if out_dir is None:
        raise batch.BatchError(f"no output folder: pass --out DIR or set out = \"DIR\" in {args.sweep}")
    out = FsPath(out_dir)
    if args.report_only:
        frame = batch.write_report(out)
        counts = ", ".join(f"{n} {s}" for s, n in frame["status"].value_counts().items())
        print(f"{out / 'summary.md'}: {len(frame)} runs ({counts}); also results.parquet, results.csv")
        return 0 if (frame["status"] == "ok").all() else 1
    options = batch.BatchOptions(
        out=out,
        workers=args.workers,
        scheduler=args.scheduler,
        dask_local=args.dask_local,
        resume=args.resume,
        timeout_s=args.timeout,
        progress=not args.quiet,
    )
    # SIGTERM (kill, a cluster's job scheduler) stops the batch as Ctrl-C does:
    # the running runs are killed with their SUMO processes, the records stay.
    previous = signal.signal(signal.SIGTERM, raise_interrupt)
    try:
        result = batch.run_batch(sweep, options)
    except KeyboardInterrupt:
        done = len(list((out / "runs").glob("*.json"))) if (out / "runs").is_dir() else 0
        print(
            f"blendtrack batch: interrupted; {done} of {len(sweep.runs)} runs recorded in {out / 'runs'} "
            "(continue with --resume)",
            file=sys.stderr,
        )
        return 130
    finally:
        signal.signal(signal.SIGTERM, previous)
    failed = result.failed + result.timeout
    before = f" ({result.skipped} from before)" if result.skipped else ""
    print(
        f"{result.summary}: {result.runs} runs: {result.ok + result.skipped} ok{before}, {result.failed} failed, "
        f"{result.timeout} timed out; {result.wall_time_s:.1f} s on {result.executor}; also results.parquet, results.csv"
    )
    return 1 if failed else 0


def add_batch_parser(subcommands: "argparse._SubParsersAction[Parser]") -> None:
    b = subcommands.add_parser(
        "batch",
        help="run a parameter sweep from a TOML file (local worker processes or a Dask cluster), resumable",
        description=(
            "Runs every run of the sweep file SWEEP.toml (kind sim, sumo or compare; scenarios x [grid] x [zip] x "
            "[[cases]] x seeds), each in a worker process of its own, and writes DIR/runs/<id>.json as each run "
            "finishes (atomically: a record is complete or absent, even after SIGKILL), then DIR/results.parquet, "
            "DIR/results.csv (one row per run), DIR/plots/ and DIR/summary.md (runs per status, each metric against "
            "each swept parameter with its 95% CI over seeds, the best parameter set per metric, failed runs). A run "
            "that fails, crashes or times out is recorded as such and the others go on; --resume runs again only what "
            "has no ok record. Exit code: 0 when every run is ok, 1 when some failed, 2 on bad input, 130 on Ctrl-C. "
            "See docs/batch.md for the file format and for running on a Dask cluster."
        ),
    )
    b.add_argument("sweep", metavar="SWEEP.toml", help="the sweep file")
    where = b.add_mutually_exclusive_group()
    where.add_argument(
        "--workers",
        type=whole("workers", high=256),
        metavar="N",
        help="local worker processes, one run each at a time (<= 256; default: the number of cores)",
    )
    where.add_argument(
        "--dask-local",
        type=whole("dask-local", high=256),
        metavar="N",
        help="start a Dask LocalCluster of N (<= 256) single-threaded worker processes and run there",
    )
    where.add_argument(
        "--scheduler",
        metavar="tcp://HOST:PORT",
        help="run on the Dask cluster of this scheduler (every worker needs the same blendtrack and the scenario paths)",
    )
    b.add_argument("--resume", action="store_true", help="continue the batch in DIR: skip runs with an ok record, retry failed ones")
    b.add_argument("--timeout", type=finite("timeout", 0.0, strict=True), metavar="S", help="per-run time limit in seconds (overrides the sweep's timeout_s)")
    b.add_argument("--report-only", action="store_true", help="run nothing: rebuild results and summary.md from DIR/runs/")
    b.add_argument("--quiet", action="store_true", help="no progress bar")
    b.add_argument("--out", metavar="DIR", help="output folder (default: the sweep's out)")
    b.set_defaults(run=_cmd_batch)
