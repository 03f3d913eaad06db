#!/usr/bin/env python3
"""Benchmark of the SUMO plugin against plain SUMO (issues #4 and #19).

Three cases, each at equal demand with and without the plugin:

- ``grid``: a generated 7 x 7 signalised grid (netgenerate: 150 m blocks,
  two lanes per direction, guessed traffic lights; randomTrips: 1,200
  vehicles over 300 s between fringe edges, up to ~770 in the network at
  once), written once under ``out/bench/grid7``;
- ``highway``: the shipped ``highway_onramp`` at demand x2 (SUMO's --scale);
- ``bologna``: ``../shared/scenarios_real/bologna_acosta`` (real city
  centre, signalised, buses).

Each case runs plain SUMO through libsumo (nothing but ``simulationStep``
in the loop; the same SUMO command line the plugin uses, seed 0), then the
plugin with 0, 10, 100 and every vehicle controlled (the first ones to
depart), and with 10 % of them (``10%``: the plugin's own selection, a seeded
hash of the vehicle ids, as ``--controlled-fraction 0.1`` picks them). Each run is a fresh process, right after a plain run of its own,
over --reps repetitions: the machines this runs on are shared and their
speed drifts by tens of per cent within minutes, so each ratio is of a run
and the plain run just before it, and medians are printed.

Columns: wall time and the process's CPU time, each with its ratio to the
paired plain run's (median of the ratios; on a loaded machine CPU time is
the steadier of the two, and it leaves out the plugin's check of the
scenario in a child SUMO, which is skipped once cached); SUMO's step (its
thread's CPU time inside ``simulationStep``) and its ratio; the rest (CPU
time of Python, the Rust engine and the libsumo calls outside the step) per
controlled vehicle-step; the mean and peak number of vehicles in the
network. ``--profile`` then runs the
every-vehicle case once more under cProfile and prints where its time goes
(SUMO's step, each libsumo call kind, the Rust engine, Python's own time);
cProfile slows the Python part, so read it as shares, not as wall time.

Targets (issue 19): every vehicle controlled at most 2x plain (goal 1.3x),
10 % controlled at most 1.2x. A benchmark measures; it asserts nothing.

    .venv/bin/python scripts/bench_sumo.py [--cases grid,highway,bologna] [--reps 3] [--profile]
    .venv/bin/python scripts/bench_sumo.py --quick    # 60 s of each, counts 0 and all, one repetition
"""

from __future__ import annotations

import argparse
import cProfile
import multiprocessing
import pstats
import statistics
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from blendtrack.sumo import RunOptions, SumoRun, resolve_scenario
from blendtrack.sumo.connection import SumoConnection

ROOT = Path(__file__).resolve().parents[1]
GRID_DIR = ROOT / "out" / "bench" / "grid7"
#: name: (scenario, SUMO --scale, default simulated seconds)
CASES: dict[str, tuple[str, float, float]] = {
    "grid": (str(GRID_DIR), 1.0, 300.0),
    "highway": ("highway_onramp", 2.0, 300.0),
    "bologna": (str(ROOT.parent / "shared" / "scenarios_real" / "bologna_acosta"), 1.0, 300.0),
}
ALL = -1
#: A row of the table: a number of vehicles (the first to depart), ALL, or a
#: fraction (float) picked as ``--controlled-fraction`` does.
Count = int | float


def parse_counts(text: str) -> list[Count]:
    """``--counts``: comma-separated numbers of vehicles, ``all``, or ``P%``."""
    out: list[Count] = []
    for tok in text.split(","):
        tok = tok.strip()
        try:
            if tok == "all":
                out.append(ALL)
            elif tok.endswith("%"):
                frac = float(tok[:-1]) / 100.0
                if not 0.0 < frac <= 1.0:
                    raise ValueError
                out.append(frac)
            else:
                n = int(tok)
                if n < 0:
                    raise ValueError
                out.append(n)
        except ValueError:
            raise SystemExit(f"bench_sumo: --counts: {tok!r} is not a number of vehicles, 'all' or a percentage "
                             f"in (0, 100]%") from None
    return out


def label(n: Count) -> str:
    return "all" if n == ALL else f"{100 * n:g}%" if isinstance(n, float) else str(n)

GRID_CFG = """<configuration>
    <input><net-file value="grid7.net.xml"/><route-files value="grid7.rou.xml"/></input>
    <time><begin value="0"/><end value="300"/><step-length value="0.1"/></time>
    <processing><collision.check-junctions value="true"/><collision.action value="warn"/></processing>
    <report><no-step-log value="true"/></report>
</configuration>
"""


def build_grid() -> None:
    """The 7 x 7 grid of issue 19, generated with SUMO's own tools (fixed seeds)."""
    cfg = GRID_DIR / "grid7.sumocfg"
    if cfg.is_file():
        return
    GRID_DIR.mkdir(parents=True, exist_ok=True)
    bindir = Path(sys.executable).parent
    import sumo

    tools = Path(sumo.__file__).parent / "tools"
    subprocess.run([str(bindir / "netgenerate"), "--grid", "--grid.number", "7", "--grid.length", "150",
                    "--grid.attach-length", "100", "-L", "2", "--tls.guess", "true", "--no-turnarounds", "true",
                    "--seed", "1", "-o", "grid7.net.xml"], cwd=GRID_DIR, check=True, capture_output=True)
    # 0.25 s between departures over 300 s: 1,200 trips between fringe edges,
    # at least 600 m long (four blocks).
    subprocess.run([sys.executable, str(tools / "randomTrips.py"), "-n", "grid7.net.xml", "-o", "grid7.trips.xml",
                    "-r", "grid7.rou.xml", "--seed", "1", "-b", "0", "-e", "300", "-p", "0.25", "--fringe-factor", "100",
                    "--min-distance", "600", "--validate"], cwd=GRID_DIR, check=True, capture_output=True)
    cfg.write_text(GRID_CFG)


def _options(end: float, scale: float, n: Count) -> RunOptions:
    if isinstance(n, float):
        fraction, most = n, None
    else:
        fraction, most = (1.0 if n != 0 else 0.0), (None if n == ALL else n)
    return RunOptions(controlled_fraction=fraction, max_controlled=most, end_s=end,
                      sumo_args=("--scale", str(scale), "--no-warnings", "true"), progress=False)


def plain(scenario_name: str, end: float, scale: float) -> dict[str, Any]:
    import libsumo

    scenario = resolve_scenario(scenario_name)
    # SUMO's command line as the plugin builds it (outputs under a temporary
    # folder, same seed and options).
    conn = SumoConnection(scenario, _options(end, scale, 0), None)
    cmd = conn.command()
    t0, c0 = time.perf_counter(), time.process_time()
    libsumo.start(cmd)
    n = 0
    stepping = 0.0
    counts: list[int] = []
    while libsumo.simulation.getTime() < end - 1e-9 and libsumo.simulation.getMinExpectedNumber() > 0:
        t = time.thread_time()
        libsumo.simulationStep()
        stepping += time.thread_time() - t
        counts.append(len(libsumo.vehicle.getIDList()))
        n += 1
    libsumo.close()
    return {"wall": time.perf_counter() - t0, "cpu": time.process_time() - c0, "sumo_step": stepping, "steps": n,
            "counts": counts}


def _timed_run(scenario_name: str, end: float, scale: float, n: Count) -> tuple[SumoRun, dict[str, Any]]:
    run = SumoRun(resolve_scenario(scenario_name), _options(end, scale, n), None)
    acc = {"sumo_step": 0.0}
    counts: list[int] = []
    sumo_step: Any = None

    def timed_step() -> None:
        t = time.thread_time()
        sumo_step()
        acc["sumo_step"] += time.thread_time() - t
        # Counted here, not in a step hook: with a hook the plugin reads
        # every light's state anew each step (a hook may switch one).
        counts.append(len(run.sumo.vehicle.getIDList()))

    start = run.conn.start

    def start_and_time() -> None:
        nonlocal sumo_step
        start()
        sumo_step = run.sumo.simulationStep
        run.sumo.simulationStep = timed_step

    run.conn.start = start_and_time  # type: ignore[method-assign]
    return run, {"acc": acc, "counts": counts}


def plugin(scenario_name: str, end: float, scale: float, n: Count) -> dict[str, Any]:
    # Loaded before the clocks start, as in ``plain``: loading libsumo's
    # library takes 0.3-0.5 s of CPU, as much as plain SUMO's whole 300 s
    # of Bologna, and is the same for both.
    import libsumo  # noqa: F401

    run, extra = _timed_run(scenario_name, end, scale, n)
    t0, c0 = time.perf_counter(), time.process_time()
    res = run.run()
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return {"wall": wall, "cpu": cpu, "sumo_step": extra["acc"]["sumo_step"], "counts": extra["counts"],
            "veh_steps": sum(r.steps for r in res.records), **res.summary}


def _category(func: tuple[str, int, str]) -> str:
    """A cProfile entry's bucket: SUMO's step, a libsumo call, the Rust engine, or Python."""
    name = func[2]
    if "simulation_step" in name:  # the SWIG function itself, not libsumo's Python wrapper around it
        return "SUMO step"
    if "libsumo" in name:
        call = name.split(".")[-1].rstrip(">").replace("vehicle_", "vehicle.")
        return f"libsumo {call}"
    if "RouteFleet" in name or "blendtrack._native" in name or "builtins.RouteFleet" in name:
        return "Rust " + name.split("'")[1] if "'" in name else "Rust"
    return "Python"


def profiled(scenario_name: str, end: float, scale: float, n: Count) -> dict[str, Any]:
    run, _ = _timed_run(scenario_name, end, scale, n)
    prof = cProfile.Profile()
    prof.enable()
    run.run()
    prof.disable()
    stats = pstats.Stats(prof).stats  # type: ignore[attr-defined]
    buckets: dict[str, list[float]] = {}
    for func, (_cc, nc, tt, _ct, _callers) in stats.items():
        b = buckets.setdefault(_category(func), [0.0, 0.0])
        b[0] += tt
        b[1] += nc
    return {k: (v[0], int(v[1])) for k, v in buckets.items()}


def in_fresh_process(fn: Any, *args: Any) -> Any:
    """libsumo runs one simulation per process reliably: every run gets its
    own (spawned) process; the time is measured inside it, from SUMO's start
    (Python's start and imports excluded)."""
    with ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn")) as pool:
        return pool.submit(fn, *args).result()


def bench_case(case: str, end: float, reps: int, counts: list[Count], profile: bool) -> None:
    scenario, scale, _ = CASES[case]
    plains: list[dict[str, Any]] = []
    runs: dict[Count, list[dict[str, Any]]] = {n: [] for n in counts}
    ratios: dict[str, dict[Count, list[float]]] = {k: {n: [] for n in counts} for k in ("wall", "cpu", "sumo_step")}
    for rep in range(reps):
        print(f"{case} rep {rep + 1}/{reps}:", end="", flush=True)
        for n in counts:
            p = in_fresh_process(plain, scenario, end, scale)
            plains.append(p)
            r = in_fresh_process(plugin, scenario, end, scale, n)
            runs[n].append(r)
            for k, rk in ratios.items():
                rk[n].append(r[k] / p[k])
            print(f" plain {p['wall']:.2f} s, {label(n)}: {r['wall']:.2f} s;", end="", flush=True)
        print()

    def med(rs: list[dict[str, Any]], key: str) -> float:
        return statistics.median(r[key] for r in rs)

    pc = plains[0]["counts"]
    print(f"\n{case}: {scenario} demand x{scale:g}, {end:g} s simulated, {plains[0]['steps']} steps, medians of {reps} "
          f"repetition(s); x: median over the repetitions of each run over the plain run just before it; cpu: the "
          f"process's CPU time, step: SUMO's step (its thread's CPU time), rest: cpu - step")
    print(f"{'controlled':>10} {'wall s':>7} {'x wall':>6} {'cpu s':>7} {'x cpu':>6} {'x range':>11} {'step s':>7} "
          f"{'x step':>6} {'rest s':>7} {'us/veh-step':>11} {'veh mean/peak':>13}")
    print(f"{'plain':>10} {med(plains, 'wall'):7.2f} {1.0:6.2f} {med(plains, 'cpu'):7.2f} {1.0:6.2f} {'':>11} "
          f"{med(plains, 'sumo_step'):7.2f} {1.0:6.2f} {'':>7} {'':>11} {statistics.mean(pc):6.0f}/{max(pc):<6d}")
    for n in counts:
        rs = runs[n]
        rest = statistics.median(r["cpu"] - r["sumo_step"] for r in rs)
        vs = rs[0]["veh_steps"]
        per = rest / vs * 1e6 if vs else float("nan")
        c = rs[0]["counts"]
        rc = ratios["cpu"][n]
        print(f"{rs[0]['controlled_vehicles']:>10} {med(rs, 'wall'):7.2f} {statistics.median(ratios['wall'][n]):6.2f} "
              f"{med(rs, 'cpu'):7.2f} {statistics.median(rc):6.2f} {f'{min(rc):.2f}-{max(rc):.2f}':>11} "
              f"{med(rs, 'sumo_step'):7.2f} {statistics.median(ratios['sumo_step'][n]):6.2f} {rest:7.2f} {per:11.2f} "
              f"{statistics.mean(c):6.0f}/{max(c):<6d}  (background {rs[0]['background_vehicles']}, collisions "
              f"{rs[0]['collisions']}, teleports {rs[0]['teleports']}, moves speed/lane/xy {rs[0]['moves_speed_only']}/"
              f"{rs[0]['moves_lane_position']}/{rs[0]['moves_xy']}; row {label(n)})", flush=True)
    if profile:
        prof = in_fresh_process(profiled, scenario, end, scale, ALL)
        total = sum(t for t, _ in prof.values())
        print(f"cProfile, every vehicle controlled (total {total:.2f} s under the profiler):")
        for k, (t, nc) in sorted(prof.items(), key=lambda kv: -kv[1][0])[:14]:
            print(f"  {k:<44} {t:7.2f} s {100 * t / total:5.1f} %  {nc:>10d} calls")
    print(flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", default="grid,highway,bologna", help=f"comma-separated, of {', '.join(CASES)}")
    ap.add_argument("--end", type=float, default=None, help="simulated seconds (default: each case's own, 300 s)")
    ap.add_argument("--counts", default="0,10,10%,100,all",
                    help="controlled vehicles per run: a number (the first to depart), 'all', or 'P%%' (that "
                         "share, picked as --controlled-fraction does)")
    ap.add_argument("--reps", type=int, default=3, help="interleaved repetitions (medians are printed)")
    ap.add_argument("--profile", action="store_true", help="also profile the every-vehicle run of each case")
    ap.add_argument("--quick", action="store_true", help="60 s, counts 0 and all, one repetition, with the profile")
    args = ap.parse_args()
    cases = args.cases.split(",")
    unknown = [c for c in cases if c not in CASES]
    if unknown:
        print(f"bench_sumo: unknown case(s) {', '.join(unknown)} (known: {', '.join(CASES)})", file=sys.stderr)
        sys.exit(2)
    if args.quick:
        args.end, args.counts, args.reps, args.profile = 60.0, "0,all", 1, True
    counts = parse_counts(args.counts)
    if "grid" in cases:
        build_grid()
    for case in cases:
        bench_case(case, args.end if args.end is not None else CASES[case][2], args.reps, counts, args.profile)


if __name__ == "__main__":
    main()
