#!/usr/bin/env python3
"""Memory over a long SUMO run: blendtrack against plain SUMO (issue 22).

Runs one scenario twice, each in a process of its own: `blendtrack sumo run`
with every vehicle controlled, then plain SUMO through libsumo (nothing but
simulationStep). While each runs, the process's resident set size (RSS)
is sampled every --interval seconds of wall time together with the
simulated time it has reached (plain: printed by the child; blendtrack: read
off its progress bar). Writes OUT/memory.csv (case, wall_s, sim_s, rss_mb;
appended and flushed as it samples, so a run cut short keeps its curve so
far) and OUT/memory.png, and prints, per case, RSS at the --ref time and at the
end, and their ratio. A benchmark measures; it asserts nothing.

    scripts/build_scenarios long                     # out/scenarios/highway_1h, highway_day
    .venv/bin/python scripts/bench_memory.py out/scenarios/highway_1h --ref 900 --out out/memory_1h
    .venv/bin/python scripts/bench_memory.py out/scenarios/highway_day --ref 7200 --out out/memory_day
    # the day at a tenth of its demand (SUMO's --scale, in both runs):
    .venv/bin/python scripts/bench_memory.py out/scenarios/highway_day --ref 7200 --sumo-args "--scale 0.1" --out out/memory_day_10
    # the two cases side by side (e.g. in two processes), then one figure:
    ... --only plain --out out/plain; ... --only blendtrack --out out/bt; ... --merge out/plain out/bt --out out/both
"""

from __future__ import annotations

import argparse
import csv
import os
import re
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import psutil

PLAIN = r"""
import sys, libsumo
from blendtrack.sumo import resolve_scenario
from blendtrack.sumo.runner import sumo_binary
sc = resolve_scenario(sys.argv[1])
end = float(sys.argv[2])
libsumo.start([sumo_binary(), "-c", str(sc.sumocfg), "--seed", "0", "--end", str(end), "--no-step-log", "true",
               "--duration-log.disable", "true", "--no-warnings", "true", *sys.argv[3].split()])
last = -1
while libsumo.simulation.getTime() < end - 1e-9 and libsumo.simulation.getMinExpectedNumber() > 0:
    libsumo.simulationStep()
    t = int(libsumo.simulation.getTime())
    if t != last:
        print(t, flush=True)
        last = t
libsumo.close()
"""

PROGRESS = re.compile(r"(\d+)/(\d+)")


def watch(cmd: list[str], case: str, interval: float, sink: Any, flush: Callable[[], None]) -> list[tuple[str, float, float, float]]:
    """Runs ``cmd`` and samples its RSS (each sample also to ``sink``); the
    simulated time comes from its stdout (one number a line) or its progress
    bar on stderr."""
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=False, bufsize=0)
    sim_t = [0.0]

    def reader(stream, is_progress: bool) -> None:  # type: ignore[no-untyped-def]
        buf = b""
        while True:
            chunk = stream.read(256)
            if not chunk:
                return
            buf = (buf + chunk)[-4096:]
            text = buf.decode(errors="replace")
            if is_progress:
                found = PROGRESS.findall(text)
                if found:
                    sim_t[0] = float(found[-1][0])
            else:
                lines = [ln for ln in text.splitlines() if ln.strip().isdigit()]
                if lines:
                    sim_t[0] = float(lines[-1])

    threads = [threading.Thread(target=reader, args=(proc.stdout, False), daemon=True),
               threading.Thread(target=reader, args=(proc.stderr, True), daemon=True)]
    for th in threads:
        th.start()
    ps = psutil.Process(proc.pid)
    t0 = time.monotonic()
    rows = []
    while proc.poll() is None:
        try:
            rss = ps.memory_info().rss / 2**20
        except psutil.Error:
            break
        rows.append((case, time.monotonic() - t0, sim_t[0], rss))
        sink.writerow(rows[-1])
        flush()
        time.sleep(interval)
    proc.wait()
    if proc.returncode != 0:
        sys.exit(f"bench_memory: {case} failed with exit code {proc.returncode}")
    return rows


def at(rows: list[tuple[str, float, float, float]], sim_s: float) -> float:
    """RSS (MB) of the first sample at or after ``sim_s`` simulated seconds."""
    for r in rows:
        if r[2] >= sim_s:
            return r[3]
    return rows[-1][3]


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scenario", help="scenario folder or configuration")
    p.add_argument("--end", type=float, default=None, help="simulated end (s; default: the scenario's)")
    p.add_argument("--ref", type=float, default=900.0, help="simulated time whose RSS the end is compared with")
    p.add_argument("--interval", type=float, default=2.0, help="wall seconds between samples")
    p.add_argument("--fraction", type=float, default=1.0, help="controlled fraction for the blendtrack run")
    p.add_argument("--sumo-args", default="", help="extra SUMO options for both runs, e.g. \"--scale 0.1\" (a tenth of the demand)")
    p.add_argument("--only", choices=["blendtrack", "plain"], help="run one of the two cases")
    p.add_argument("--merge", type=Path, nargs="+", metavar="DIR",
                   help="run nothing: table and figure of the memory.csv files in these folders (e.g. two --only runs)")
    p.add_argument("--out", type=Path, required=True)
    args = p.parse_args()

    from blendtrack.sumo import resolve_scenario

    sc = resolve_scenario(args.scenario)
    end = args.end if args.end is not None else (sc.default_end_s or 3600.0)
    args.out.mkdir(parents=True, exist_ok=True)
    py = sys.executable
    bt = str(Path(py).with_name("blendtrack"))
    rows: list[tuple[str, float, float, float]] = []
    if args.merge:
        for d in args.merge:
            with open(d / "memory.csv", newline="") as f:
                rows += [(r["case"], float(r["wall_s"]), float(r["sim_s"]), float(r["rss_mb"])) for r in csv.DictReader(f)]
    else:
        with open(args.out / "memory.csv", "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["case", "wall_s", "sim_s", "rss_mb"])
            if args.only in (None, "blendtrack"):
                rows += watch([bt, "sumo", "run", str(args.scenario), "--controlled-fraction", str(args.fraction), "--end",
                               str(end), "--sumo-args", f"--no-warnings true {args.sumo_args}", "--out", str(args.out / "run")],
                              f"blendtrack, {args.fraction:.0%} controlled", args.interval, w, f.flush)
            if args.only in (None, "plain"):
                rows += watch([py, "-c", PLAIN, str(sc.sumocfg), str(end), args.sumo_args], "plain SUMO", args.interval, w,
                              f.flush)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    # "The end": the last sample still simulating (after it come the output
    # files and plots, whose memory is the peak's, not the run's).
    print(f"| case | RSS at {args.ref:g} s (MB) | RSS at the end (MB) | end / ref | peak, outputs included (MB) |")
    print("|---|---|---|---|---|")
    for case in dict.fromkeys(r[0] for r in rows):
        sel = [r for r in rows if r[0] == case]
        ax.plot([r[2] / 3600 for r in sel], [r[3] for r in sel], label=case)
        ref = at(sel, args.ref)
        # Samples at the last simulated time reached may be the outputs
        # being written (the progress bar stops at end - 1 s: a 1 h run's
        # plots were sampled at "3599 s", 290 MB against 252 MB the step
        # before): the end is the last sample before that time.
        final = max(r[2] for r in sel)
        running = [r for r in sel if r[2] < min(end, final)]
        last = running[-1] if running else sel[-1]
        print(f"| {case} | {ref:.1f} | {last[3]:.1f} (at {last[2]:g} s) | {last[3] / ref:.3f} | {max(r[3] for r in sel):.1f} |")
    ax.set_xlabel("simulated time (h)")
    ax.set_ylabel("resident set size (MB)")
    scale = f" ({args.sumo_args})" if args.sumo_args else ""
    ax.set_title(f"{sc.name}{scale}: memory over the run")
    ax.legend()
    fig.tight_layout()
    fig.savefig(args.out / "memory.png", dpi=120)
    print(f"wrote {args.out / 'memory.csv'} and {args.out / 'memory.png'}")
    return 0


if __name__ == "__main__":
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    sys.exit(main())
