#!/usr/bin/env python3
"""Benchmark of the SUMO plugin against plain SUMO (issue #4).

Runs one scenario with the same demand (SUMO's --scale multiplies it) as:
plain SUMO through libsumo (every vehicle on SUMO's own models, nothing but
simulationStep in the loop), then the plugin with 0, 10, 100 and 1000
controlled vehicles (the first ones to depart), all with SUMO's same options
and seed. Each case runs in a fresh process (libsumo runs one simulation per
process reliably), right after a plain run of its own, over --reps
repetitions (plain, 0, plain, 10, ..., plain, 0, ...): the machines this
runs on are shared and their speed drifts by tens of per cent within
minutes, so each ratio is of a case and the plain run just before it, and
the medians are printed. Target:
at 1000 controlled vehicles, at most 2x plain SUMO. A benchmark measures; it
asserts nothing.

    .venv/bin/python scripts/bench_sumo.py [--scenario highway_onramp] [--scale 2] [--end 600] [--reps 3]
"""

from __future__ import annotations

import argparse
import multiprocessing
import statistics
import time
from concurrent.futures import ProcessPoolExecutor
from typing import Any

from blendtrack.sumo import RunOptions, SumoRun, resolve_scenario
from blendtrack.sumo.connection import sumo_binary


def plain(scenario_name: str, end: float, scale: float) -> dict[str, Any]:
    import libsumo

    scenario = resolve_scenario(scenario_name)
    # Timed from SUMO's start, as the plugin's run is (which also checks the
    # scenario in a child SUMO and reads the network for the lane geometry).
    t0 = time.perf_counter()
    # The options the plugin gives SUMO (SumoConnection.command): the same seed
    # (another one is other traffic), no logs.
    libsumo.start([sumo_binary(), "-c", str(scenario.sumocfg), "--seed", "0", "--end", str(end), "--scale", str(scale),
                   "--no-step-log", "true", "--duration-log.disable", "true", "--no-warnings", "true"])
    n = 0
    while libsumo.simulation.getTime() < end - 1e-9 and libsumo.simulation.getMinExpectedNumber() > 0:
        libsumo.simulationStep()
        n += 1
    libsumo.close()
    return {"wall": time.perf_counter() - t0, "steps": n}


def plugin(scenario_name: str, end: float, scale: float, n: int) -> dict[str, Any]:
    opts = RunOptions(controlled_fraction=1.0 if n > 0 else 0.0, max_controlled=n, end_s=end,
                      sumo_args=("--scale", str(scale), "--no-warnings", "true"), progress=False)
    run = SumoRun(resolve_scenario(scenario_name), opts, None)
    stepping = 0.0
    sumo_step: Any = None

    def timed_step() -> None:
        nonlocal stepping
        t = time.perf_counter()
        sumo_step()
        stepping += time.perf_counter() - t

    start = run.start

    def start_and_time() -> None:
        nonlocal sumo_step
        start()
        sumo_step = run.sumo.simulationStep
        run.sumo.simulationStep = timed_step

    run.start = start_and_time  # type: ignore[method-assign]
    t0 = time.perf_counter()
    res = run.run()
    wall = time.perf_counter() - t0
    return {"wall": wall, "sumo_step": stepping, "veh_steps": sum(r.steps for r in res.records), **res.summary}


def in_fresh_process(fn: Any, *args: Any) -> dict[str, Any]:
    """libsumo runs one simulation per process reliably: every case gets its
    own (spawned) process; the time is measured inside it, from SUMO's start
    (Python's start and imports excluded)."""
    with ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn")) as pool:
        return pool.submit(fn, *args).result()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenario", default="highway_onramp")
    ap.add_argument("--scale", type=float, default=2.0, help="demand multiplier (SUMO --scale)")
    ap.add_argument("--end", type=float, default=600.0)
    ap.add_argument("--counts", default="0,10,100,1000")
    ap.add_argument("--reps", type=int, default=3, help="interleaved repetitions (medians are printed)")
    args = ap.parse_args()
    sc = resolve_scenario(args.scenario)
    counts = [int(x) for x in args.counts.split(",")]
    plains: list[float] = []
    runs: dict[int, list[dict[str, Any]]] = {n: [] for n in counts}
    ratios: dict[int, list[float]] = {n: [] for n in counts}
    for rep in range(args.reps):
        print(f"rep {rep + 1}/{args.reps}:", end="", flush=True)
        for n in counts:
            # A plain run right before each case: the ratio is of two runs a
            # few seconds apart.
            p = in_fresh_process(plain, sc.name, args.end, args.scale)
            plains.append(p["wall"])
            r = in_fresh_process(plugin, sc.name, args.end, args.scale, n)
            runs[n].append(r)
            ratios[n].append(r["wall"] / p["wall"])
            print(f" plain {p['wall']:.2f} s, {n}: {r['wall']:.2f} s;", end="", flush=True)
        print()
    base = statistics.median(plains)
    print(f"\nscenario {sc.name}, demand x{args.scale:g}, {args.end:g} s simulated, {p['steps']} steps, "
          f"medians of {args.reps} repetitions; x plain: the median of each run over the plain run just before it; "
          f"ratio range {', '.join(f'{n}: {min(ratios[n]):.2f}-{max(ratios[n]):.2f}' for n in counts)}")
    print(f"{'controlled':>10} {'wall (s)':>9} {'x plain':>8} {'SUMO step (s)':>14} {'rest (s)':>9} {'us / veh / step':>16}")
    print(f"{'plain SUMO':>10} {base:9.2f} {1.0:8.2f} {base:14.2f} {'':>9} {'':>16}")
    for n in counts:
        rs = runs[n]
        wall = statistics.median(r["wall"] for r in rs)
        step = statistics.median(r["sumo_step"] for r in rs)
        rest = statistics.median(r["wall"] - r["sumo_step"] for r in rs)
        vs = rs[0]["veh_steps"]
        per = rest / vs * 1e6 if vs else float("nan")
        print(f"{rs[0]['controlled_vehicles']:>10} {wall:9.2f} {statistics.median(ratios[n]):8.2f} {step:14.2f} {rest:9.2f} {per:16.2f}"
              f"   (background {rs[0]['background_vehicles']}, collisions {rs[0]['collisions']},"
              f" teleports {rs[0]['teleports']}, backend {rs[0]['backend']})", flush=True)


if __name__ == "__main__":
    main()
