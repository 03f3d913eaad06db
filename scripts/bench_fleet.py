#!/usr/bin/env python3
"""Benchmark of Fleet.step (issue #3 target: 10,000 vehicles in under 5 ms).

10,000 vehicles spread over the built-in test track, 0.3 m off the path,
all stepped in one call per step with the next state integrated (dt given),
as the SUMO plugin will call it. Prints the median (and quartiles) of
--repeats timed steps after --warmup untimed ones. A benchmark measures; it
asserts nothing. Run: .venv/bin/python scripts/bench_fleet.py
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

import blendtrack


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--vehicles", type=int, default=10_000)
    parser.add_argument("--repeats", type=int, default=50)
    parser.add_argument("--warmup", type=int, default=5)
    parser.add_argument("--dt", type=float, default=0.1, help="SUMO-like step (s)")
    args = parser.parse_args()

    path = blendtrack.Path.test_track(1.0)
    fleet = blendtrack.Fleet()
    track = fleet.add_track(path)
    n = args.vehicles
    slots = np.array([fleet.add_vehicle(track) for _ in range(n)], dtype=np.int64)
    s = np.linspace(0.0, path.length_m, n, endpoint=False)
    pts = np.array([path.point_at(float(x)) for x in s])
    heading = np.array([path.heading_at(float(x)) for x in s])
    normal = np.stack([-np.sin(heading), np.cos(heading)], axis=1)
    xy = pts + 0.3 * normal
    state = {"x": xy[:, 0], "y": xy[:, 1], "theta": heading, "v": np.full(n, 3.0), "delta": np.zeros(n)}
    times = []
    for i in range(args.warmup + args.repeats):
        t0 = time.perf_counter()
        out = fleet.step(slots, **state, dt=args.dt)
        elapsed = time.perf_counter() - t0
        if i >= args.warmup:
            times.append(elapsed)
        state = {"x": out["x_m"], "y": out["y_m"], "theta": out["theta_rad"], "v": out["v_mps"], "delta": out["delta_rad"]}
    q = statistics.quantiles(times, n=4)
    print(
        f"Fleet.step, {n} vehicles, {args.repeats} repeats: median {statistics.median(times) * 1e3:.2f} ms "
        f"(quartiles {q[0] * 1e3:.2f} / {q[2] * 1e3:.2f} ms), {statistics.median(times) / n * 1e9:.0f} ns per vehicle; "
        f"all ok: {bool(out['ok'].all())}, mean |e| {np.abs(out['lateral_error_m']).mean():.3f} m"
    )


if __name__ == "__main__":
    main()
