#!/usr/bin/env python3
"""Benchmark of the SUMO plugin against plain SUMO (issue #4).

Runs one scenario with the same demand (SUMO's --scale multiplies it) as:
plain SUMO through libsumo (every vehicle on SUMO's own models, nothing but
simulationStep in the loop), then the plugin with 0, 10, 100 and 1000
controlled vehicles (the first ones to depart). Prints wall times, the ratio
to plain SUMO and the time per controlled vehicle and step, all measured in
this one run, each case in a fresh process (libsumo runs one simulation
per process reliably). Target: at 1000 controlled vehicles, at most 2x plain SUMO.
A benchmark measures; it asserts nothing.

    .venv/bin/python scripts/bench_sumo.py [--scenario highway_onramp] [--scale 2] [--end 600]
"""

from __future__ import annotations

import argparse
import multiprocessing
import time
from concurrent.futures import ProcessPoolExecutor
from typing import Any

from blendtrack.sumo import RunOptions, SumoRun, resolve_scenario
from blendtrack.sumo.runner import sumo_binary


def plain(scenario_name: str, end: float, scale: float) -> dict[str, Any]:
    import libsumo

    scenario = resolve_scenario(scenario_name)
    t0 = time.perf_counter()
    libsumo.start([sumo_binary(), "-c", str(scenario.sumocfg), "--end", str(end), "--scale", str(scale),
                   "--no-step-log", "true", "--no-warnings", "true"])
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
    t0 = time.perf_counter()
    res = run.run()
    wall = time.perf_counter() - t0
    return {"wall": wall, "veh_steps": sum(r.steps for r in res.records), **res.summary}


def in_fresh_process(fn: Any, *args: Any) -> dict[str, Any]:
    """libsumo runs one simulation per process reliably: every case gets its
    own (spawned) process; the time is measured inside it, start-up excluded."""
    with ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn")) as pool:
        return pool.submit(fn, *args).result()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenario", default="highway_onramp")
    ap.add_argument("--scale", type=float, default=2.0, help="demand multiplier (SUMO --scale)")
    ap.add_argument("--end", type=float, default=600.0)
    ap.add_argument("--counts", default="0,10,100,1000")
    args = ap.parse_args()
    sc = resolve_scenario(args.scenario)
    p = in_fresh_process(plain, sc.name, args.end, args.scale)
    base = p["wall"]
    print(f"scenario {sc.name}, demand x{args.scale:g}, {args.end:g} s simulated, {p['steps']} steps")
    print(f"{'controlled':>10} {'wall (s)':>9} {'x plain':>8} {'us / controlled veh / step':>27}")
    print(f"{'plain SUMO':>10} {base:9.2f} {1.0:8.2f} {'':>27}", flush=True)
    for n in (int(x) for x in args.counts.split(",")):
        r = in_fresh_process(plugin, sc.name, args.end, args.scale, n)
        wall = r["wall"]
        per = (wall - base) / r["veh_steps"] * 1e6 if r["veh_steps"] else float("nan")
        print(f"{r['controlled_vehicles']:>10} {wall:9.2f} {wall / base:8.2f} {per:27.1f}"
              f"   (background {r['background_vehicles']}, collisions {r['collisions']},"
              f" teleports {r['teleports']}, backend {r['backend']})", flush=True)


if __name__ == "__main__":
    main()
