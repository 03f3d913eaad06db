"""Tuning sweep for `blendtrack paper`'s fair parameter set, and the held-out
evaluation of every controller and of the automatic alpha.

Run from the repository root (a few minutes):

    .venv/bin/python scripts/paper_tune.py

1. Tunes each controller's own parameters on the TRAINING tracks (the
   built-in test_track and ../shared/tracks/Nuerburgring.csv) in the forward
   scenario of blendtrack.paper_eval (8 m/s, 4 m start offset, noise and
   delay), seeds 0-2, minimising the mean |lateral error| of its control
   point over the run: pure pursuit's look-ahead (gain and minimum),
   Stanley's k, the rear law's d (minimum and gain) and L (gain), and the
   blend's alpha (with the tuned Stanley and rear-law parameters).
2. Evaluates both parameter sets (the paper's, the tuned one) on the
   HELD-OUT tracks (every other ../shared/tracks/*.csv), seeds 0-2.
3. Compares the automatic alpha (its auto_alpha_* defaults were tuned on the
   training tracks only, see docs/paper.md) with alpha = 1 (Stanley), 0 (the
   rear law) and 0.5 on body_error_mean_m, forward and backward, on the
   held-out tracks, with the paper's parameters.

Writes configs/paper_tuned.json (read by `blendtrack paper`),
docs/auto_alpha_held_out.png and docs/auto_alpha_history.png (alpha(t) on
the Nuerburgring; `--history-only` writes just that figure, in seconds).
"""

from __future__ import annotations

import itertools
import json
import sys
import time
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from blendtrack import VehicleParams  # noqa: E402
from blendtrack import paper_eval as pe  # noqa: E402

SEEDS = (0, 1, 2)
VEHICLE = VehicleParams()

GRIDS: dict[str, list[dict[str, float]]] = {
    "pure pursuit": [
        {"pure_pursuit_gain_s": g, "pure_pursuit_min_lookahead_m": m} for g, m in itertools.product((0.25, 0.5, 0.75, 1.0), (1.5, 3.0, 4.5))
    ],
    "Stanley": [{"stanley_gain": k} for k in (0.5, 0.75, 1.0, 1.5, 2.0)],
    "rear law (alpha 0)": [
        {"target_distance_min_m": dm, "target_distance_gain_s": kd, "curvature_lookahead_gain_s": kl}
        for dm, kd, kl in itertools.product((1.0, 2.0, 4.0), (0.25, 0.5, 1.0, 2.0), (0.5, 1.0, 2.0))
    ],
}
ALPHAS = (0.25, 0.5, 0.75)


def score(label: str, keys: dict[str, Any], tracks: dict[str, Any], seeds: tuple[int, ...] = SEEDS, metric: str = "lateral_error_mean_abs_m") -> float:
    cfg = pe.ControllerConfig(**{**pe.CONTROLLERS[label], **keys})
    vals = [pe.run(p, cfg, VEHICLE, pe.FORWARD, seed)[1][metric] for p in tracks.values() for seed in seeds]
    return float(np.mean(vals))


def tune(training: dict[str, Any]) -> tuple[dict[str, dict[str, float]], dict[str, list[Any]]]:
    best: dict[str, dict[str, float]] = {}
    table: dict[str, list[Any]] = {}
    for label, grid in GRIDS.items():
        scored = sorted(((score(label, keys, training), keys) for keys in grid), key=lambda x: x[0])
        best[label] = scored[0][1]
        table[label] = [[s, k] for s, k in scored]
        print(label, scored[0], flush=True)
    base = {**best["Stanley"], **best["rear law (alpha 0)"]}
    scored = sorted(((score("blend", {**base, "lat_blend_factor": a}, training), {"lat_blend_factor": a}) for a in ALPHAS), key=lambda x: x[0])
    best["blend"] = scored[0][1]
    table["blend"] = [[s, k] for s, k in scored]
    print("blend", scored[0], flush=True)
    return best, table


def held_out(tracks: dict[str, Any], tuned: dict[str, Any]) -> dict[str, Any]:
    """Per parameter set, controller and track: the metrics over seeds."""
    keep = ("lateral_error_mean_abs_m", "lateral_error_mean_abs_m_reached", "initial_overshoot_m", "reached_time_s", "body_error_mean_m")
    out: dict[str, Any] = {}
    for set_name in ("paper", "fair"):
        out[set_name] = {}
        for label in pe.CONTROLLERS:
            cfg = pe.paper_config(label) if set_name == "paper" else pe.fair_config(label, tuned)
            out[set_name][label] = {}
            for name, p in tracks.items():
                ms = [pe.run(p, cfg, VEHICLE, pe.FORWARD, seed)[1] for seed in SEEDS]
                out[set_name][label][name] = {k: [m[k] for m in ms] for k in keep}
    return out


def auto_alpha_comparison(tracks: dict[str, Any]) -> dict[str, Any]:
    """body_error_mean_m of alpha 1, 0.5, 0 and auto, forward and backward, paper parameters."""
    cases = {"alpha 1 (Stanley)": 1.0, "alpha 0.5": 0.5, "alpha 0 (rear law)": 0.0, "auto alpha": "auto"}
    out: dict[str, Any] = {}
    for sc in (pe.FORWARD, pe.BACKWARD):
        out[sc.direction] = {}
        for label, a in cases.items():
            cfg = pe.ControllerConfig(lateral_controller="blend", lat_blend_factor=a if a != "auto" else 0.5)
            alpha = "auto" if a == "auto" else None
            out[sc.direction][label] = {
                name: [pe.run(p, cfg, VEHICLE, sc, seed, alpha=alpha)[1]["body_error_mean_m"] for seed in SEEDS] for name, p in tracks.items()
            }
    return out


def plot_auto(comp: dict[str, Any], file: Any) -> None:
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=False)
    for ax, (direction, cases) in zip(axes, comp.items()):
        names = list(next(iter(cases.values())))
        x = np.arange(len(names))
        w = 0.8 / len(cases)
        for i, (label, per_track) in enumerate(cases.items()):
            means = [np.mean(per_track[n]) for n in names]
            ax.bar(x + (i - (len(cases) - 1) / 2) * w, means, w, label=label)
        ax.set_xticks(x, names, rotation=30, fontsize=8)
        ax.set_ylabel("body error, mean of max(|e_front|, |e_rear|) (m)")
        ax.set_title(f"Held-out tracks, {direction} (3 seeds)")
        ax.grid(axis="y", alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(file, dpi=110)
    plt.close(fig)


def plot_history(file: Any) -> None:
    """alpha(t), |curvature| at the control point and both axles' errors: auto alpha on the Nuerburgring, forward, paper parameters."""
    p = pe.track("Nuerburgring", VEHICLE)
    frame, _ = pe.run(p, pe.ControllerConfig(), VEHICLE, pe.FORWARD, 0, alpha="auto")
    st, _ = pe.run(p, pe.ControllerConfig(lateral_controller="stanley"), VEHICLE, pe.FORWARD, 0)
    fig, axes = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
    window = frame["t_s"] < 80.0
    axes[0].plot(frame["t_s"][window], frame["alpha"][window], lw=0.8)
    axes[0].set_ylabel("auto alpha")
    axes[1].plot(frame["t_s"][window], frame["curvature_per_m"][window].abs(), lw=0.8, color="C2")
    axes[1].set_ylabel("|curvature| (1/m)")
    for df, label, ls in ((frame, "auto", "-"), (st, "Stanley", ":")):
        w = df["t_s"] < 80.0
        axes[2].plot(df["t_s"][w], df["lateral_error_front_m"][w], ls, lw=0.8, color="C0", label=f"{label}, front axle")
        axes[2].plot(df["t_s"][w], df["lateral_error_rear_m"][w], ls, lw=0.8, color="C3", label=f"{label}, rear axle")
    axes[2].set_ylim(-0.4, 0.4)
    axes[2].set_ylabel("lateral error (m)")
    axes[2].set_xlabel("t (s)")
    axes[2].legend(fontsize=7, ncol=2)
    for ax in axes:
        ax.grid(alpha=0.3)
    axes[0].set_title("Automatic alpha, scaled Nuerburgring, 8 m/s, noise + delay (first 80 s; start 4 m off)")
    fig.tight_layout()
    fig.savefig(file, dpi=110)
    plt.close(fig)


def main() -> int:
    plot_history(pe.REPO_ROOT / "docs" / "auto_alpha_history.png")
    if "--history-only" in sys.argv[1:]:
        return 0
    t0 = time.time()
    training = {n: pe.track(n, VEHICLE) for n in pe.TRAINING}
    held = {n: pe.track(n, VEHICLE) for n in pe.held_out_tracks()}
    if not held:
        print(f"no held-out tracks in {pe.SHARED_TRACKS}", file=sys.stderr)
        return 2
    best, table = tune(training)
    result: dict[str, Any] = {
        "training_tracks": list(training),
        "held_out_tracks": list(held),
        "seeds": list(SEEDS),
        "objective": "mean |lateral error| of the control point over one lap, forward scenario (blendtrack.paper_eval.FORWARD)",
        "parameters": best,
        "sweep": table,
    }
    result["held_out"] = held_out(held, result)
    result["auto_alpha"] = auto_alpha_comparison(held)
    pe.TUNED_FILE.write_text(json.dumps(result, indent=1) + "\n")
    plot_auto(result["auto_alpha"], pe.REPO_ROOT / "docs" / "auto_alpha_held_out.png")
    print(f"wrote {pe.TUNED_FILE} in {time.time() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
