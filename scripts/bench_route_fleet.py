#!/usr/bin/env python3
"""Benchmark of RouteFleet (the SUMO plugin's Rust engine) alone, no SUMO.

N vehicles drive the highway_onramp mainline (its real lane geometry, built
as the plugin builds it) in one RouteFleet; every step is the plugin's two
calls, plan_sumo (each vehicle's leader is the one ahead of it, a known
slot) and step. Prints the median time per vehicle and step over several
repetitions. A benchmark measures; it asserts nothing.

    .venv/bin/python scripts/bench_route_fleet.py [--vehicles 500] [--steps 200] [--reps 5] [--dt 0.1]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
import sumolib

import blendtrack
from blendtrack.sumo import resolve_scenario
from blendtrack.sumo.geometry import route_geometry


def build(n: int) -> tuple[blendtrack.RouteFleet, np.ndarray, list[str], float]:
    sc = resolve_scenario("highway_onramp")
    net = sumolib.net.readNet(str(sc.net_file), withInternal=True)
    geo = route_geometry(net, ["hw_in", "hw_up", "hw_merge", "hw_down", "hw_out"], 1, defer_changes=True)
    fleet = blendtrack.RouteFleet()
    lanes: dict[str, int] = {}
    ids = [lanes.setdefault(x, len(lanes)) for x in geo.piece_lane]
    track = fleet.add_route(
        blendtrack.Path(geo.points, geo.widths, closed=False),
        blendtrack.ControllerConfig(preferred_speed=30.0, max_obs_deceleration=-4.0),
        piece_start_m=geo.piece_start_s, piece_scale=geo.piece_scale, piece_offset_m=geo.piece_offset,
        piece_lane_length_m=geo.piece_lane_length, piece_lane_pos_m=geo.piece_lane_pos,
        piece_speed_mps=geo.piece_speed, piece_lane=ids, piece_edge=ids, piece_lane_index=geo.piece_index,
        length_m=geo.length_m,
    )
    path = blendtrack.Path(geo.points, geo.widths, closed=False)
    spacing = (geo.length_m - 300.0) / n
    slots, names = [], []
    for k in range(n):
        s = geo.length_m - 300.0 - k * spacing
        x, y = path.point_at(s)
        th = path.heading_at(s)
        names.append(f"veh{k}")
        slots.append(fleet.add_vehicle(track, None, None, reach_m=3.9, length_m=5.0, min_gap_m=2.5,
                                       x=x, y=y, theta=th, v=25.0, name=names[-1]))
    return fleet, np.array(slots, dtype=np.int64), names, spacing


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--vehicles", type=int, default=500)
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--dt", type=float, default=0.1,
                    help="the simulator's step (s); above control_dt (0.05 s) each step is several control steps")
    args = ap.parse_args()
    n = args.vehicles
    per_step: list[float] = []
    for _ in range(args.reps):
        fleet, slots, names, spacing = build(n)
        leaders = [None] + [(names[k - 1], spacing - 7.5) for k in range(1, n)]
        t0 = time.perf_counter()
        for _ in range(args.steps):
            q = fleet.plan_sumo(slots, leaders, lambda vid: 25.0)
            fleet.step(np.zeros(len(q), dtype=bool), args.dt)
        per_step.append((time.perf_counter() - t0) / args.steps)
    med = statistics.median(per_step)
    print(f"RouteFleet plan_sumo + step, {n} vehicles on the highway: median {med * 1e3:.3f} ms per step "
          f"of {args.dt:g} s ({med / n * 1e6:.2f} us per vehicle and step; {args.reps} repetitions of {args.steps} steps; "
          f"min {min(per_step) / n * 1e6:.2f}, max {max(per_step) / n * 1e6:.2f} us)")


if __name__ == "__main__":
    main()
