"""Tuning of auto_alpha_backward and a leave-one-track-out check of it.

First prints the auto_alpha_backward that is best on the two TRAINING tracks
(test_track and the Nuerburgring; the config default, whose held-out results
`scripts/paper_tune.py` writes). Then asks whether more training data would
make auto alpha win backward everywhere, without ever scoring a track it
tuned on: for each of the nine tracks (test_track and
../shared/tracks/*.csv), it picks the auto_alpha_backward (the only
backward-only key, so forward is unchanged) that is best on the other eight,
then compares that pick with alpha 1, 0.5 and 0 on the track left out.
Backward scenario of blendtrack.paper_eval (1 m/s, 2 m offset, first 800 m,
noise and 0.1 s delay), seeds 0-2, body_error_mean_m.

    .venv/bin/python scripts/auto_alpha_loo.py          (a few minutes)

Prints the training scores and a markdown table (docs/paper.md, "Automatic alpha").
"""

from __future__ import annotations

import numpy as np

from blendtrack import VehicleParams
from blendtrack import paper_eval as pe

SEEDS = (0, 1, 2)
BASES = (0.5, 0.6, 0.7, 0.8, 0.9, 1.0)
FIXED = (1.0, 0.5, 0.0)
VEHICLE = VehicleParams()


def body(path: pe.Path, cfg: pe.ControllerConfig) -> float:
    return float(np.mean([pe.run(path, cfg, VEHICLE, pe.BACKWARD, s)[1]["body_error_mean_m"] for s in SEEDS]))


def main() -> int:
    names = [*pe.TRAINING, *pe.held_out_tracks()]
    tracks = {n: pe.track(n, VEHICLE) for n in names}
    fixed = {a: {n: body(p, pe.ControllerConfig(lateral_controller="blend", lat_blend_factor=a)) for n, p in tracks.items()} for a in FIXED}
    auto = {
        b: {n: body(p, pe.ControllerConfig(lateral_controller="blend", alpha_mode="auto", auto_alpha_backward=b)) for n, p in tracks.items()}
        for b in BASES
    }
    best = {n: min(fixed[a][n] for a in FIXED) for n in names}
    train = {b: float(np.mean([auto[b][n] / best[n] for n in pe.TRAINING])) for b in BASES}
    print("auto_alpha_backward on the training tracks, body error / best fixed alpha's (mean of the two):")
    print(", ".join(f"{b}: {r:.3f}" for b, r in train.items()), f"-> {min(train, key=lambda b: train[b])}\n")
    print("| left out | auto_alpha_backward picked on the other 8 | auto alpha | alpha 1 | alpha 0.5 | alpha 0 | auto best |")
    print("|---|---|---|---|---|---|---|")
    wins = 0
    for held in names:
        rest = [n for n in names if n != held]
        pick = min(BASES, key=lambda b: float(np.mean([auto[b][n] / best[n] for n in rest])))
        a = auto[pick][held]
        win = a < best[held]
        wins += win
        cells = " | ".join(f"{fixed[x][held]:.4f}" for x in FIXED)
        print(f"| {held} | {pick} | {a:.4f} | {cells} | {'yes' if win else 'no'} |")
    print(f"\nauto alpha best on {wins} of {len(names)} left-out tracks")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
