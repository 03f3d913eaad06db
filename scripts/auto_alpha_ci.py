"""Held-out comparison of the automatic alpha with 95 % confidence intervals.

For every held-out track (../shared/tracks/*.csv other than the training
ones) and both scenarios of blendtrack.paper_eval (paper parameters), runs
auto alpha (the config defaults) and alpha 1, 0.5 and 0 with the same seeds
(0-9: the same sensor noise for every controller) and reports, per track,
the mean body_error_mean_m of each and the paired difference auto alpha minus
the best fixed alpha on that track, with its 95 % confidence interval
(Student t over the seeds, scipy). A difference whose interval holds 0 is
not significant at 5 %.

    .venv/bin/python scripts/auto_alpha_ci.py [--seeds N]     (a few minutes)

Prints markdown tables (docs/paper.md, "Automatic alpha").
"""

from __future__ import annotations

import sys

import numpy as np
from scipy import stats

from blendtrack import VehicleParams
from blendtrack import paper_eval as pe

VEHICLE = VehicleParams()
FIXED = {"alpha 1": 1.0, "alpha 0.5": 0.5, "alpha 0": 0.0}


def bodies(path: pe.Path, cfg: pe.ControllerConfig, sc: pe.Scenario, seeds: range) -> np.ndarray:
    return np.array([pe.run(path, cfg, VEHICLE, sc, s)[1]["body_error_mean_m"] for s in seeds])


def paired_ci(d: np.ndarray) -> tuple[float, float, float]:
    """Mean of the paired differences and its 95 % interval (Student t)."""
    m = float(np.mean(d))
    h = float(stats.t.ppf(0.975, len(d) - 1) * np.std(d, ddof=1) / np.sqrt(len(d)))
    return m, m - h, m + h


def main(argv: list[str]) -> int:
    n = int(argv[argv.index("--seeds") + 1]) if "--seeds" in argv else 10
    if n < 2:
        print("--seeds: at least 2 seeds are needed for an interval", file=sys.stderr)
        return 2
    seeds = range(n)
    tracks = {name: pe.track(name, VEHICLE) for name in pe.held_out_tracks()}
    for sc in (pe.FORWARD, pe.BACKWARD):
        print(f"\n{sc.direction}, {n} seeds: mean body_error_mean_m (m); auto minus the best fixed alpha, 95 % CI (mm)\n")
        print("| track | alpha 1 | alpha 0.5 | alpha 0 | auto alpha | auto - best fixed (mm) | significant |")
        print("|---|---|---|---|---|---|---|")
        wins = 0
        for name, p in tracks.items():
            fixed = {label: bodies(p, pe.ControllerConfig(lateral_controller="blend", lat_blend_factor=a), sc, seeds) for label, a in FIXED.items()}
            auto = bodies(p, pe.ControllerConfig(lateral_controller="blend", alpha_mode="auto"), sc, seeds)
            best = min(fixed, key=lambda label: float(np.mean(fixed[label])))
            m, lo, hi = paired_ci(auto - fixed[best])
            wins += m < 0
            sig = "no" if lo <= 0.0 <= hi else ("auto better" if hi < 0 else "auto worse")
            cells = " | ".join(f"{np.mean(fixed[label]):.4f}" for label in FIXED)
            print(f"| {name} | {cells} | {np.mean(auto):.4f} | {1000 * m:+.2f} [{1000 * lo:+.2f}, {1000 * hi:+.2f}] vs {best} | {sig} |", flush=True)
        print(f"\n{sc.direction}: auto alpha best on {wins} of {len(tracks)} held-out tracks")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
