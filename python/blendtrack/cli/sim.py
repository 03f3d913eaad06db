"""``blendtrack sim`` (one closed-loop run) and ``blendtrack paper`` (the
paper's experiments)."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path as FsPath

import blendtrack
from blendtrack.cli.common import Parser, alpha_value, finite, require_file, seed


def _json_metrics(metrics: dict[str, float]) -> dict[str, float | None]:
    """The metrics.json keys; NaN (undefined, e.g. never settled) becomes null: strict JSON."""
    from blendtrack.simulation import METRIC_KEYS

    return {k: (metrics[k] if math.isfinite(metrics[k]) else None) for k in METRIC_KEYS}


def _cmd_sim(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from blendtrack import plots
    from blendtrack.simulation import load_track, simulate

    path = load_track(args.track, args.scale)
    config = blendtrack.ControllerConfig()
    vehicle = blendtrack.VehicleParams()
    if args.config is not None:
        require_file(args.config, "config", blendtrack.ConfigError)
        config, vehicle = blendtrack.load_config(args.config)
    overrides: dict[str, object] = {}
    if args.controller is not None:
        overrides["lateral_controller"] = args.controller.replace("-", "_")
    if args.direction is not None:
        overrides["direction"] = args.direction
    if args.speed is not None:
        overrides["preferred_speed"] = args.speed
    config = config.replace(**overrides).with_alpha(args.alpha)
    alpha: str | None = args.alpha_schedule
    if alpha is not None and config.alpha_mode == "auto":
        raise blendtrack.ConfigError("--alpha-schedule with a config whose alpha_mode is \"auto\" (drop one of them)")
    if args.laps is not None:
        # Generous cap: ten times the lap time at the preferred speed.
        duration = max(60.0, 10.0 * args.laps * path.length_m / config.preferred_speed)
    else:
        duration = args.duration
    out = FsPath(args.out)
    out.mkdir(parents=True, exist_ok=True)
    steps = ["simulate", "timeseries.csv", "metrics.json", "plots"]
    with tqdm(total=len(steps), desc="blendtrack sim", unit="step", file=sys.stderr, disable=None) as bar:
        frame, metrics = simulate(
            path,
            config,
            vehicle,
            alpha=alpha,
            dt_s=args.dt,
            duration_s=duration,
            laps=args.laps,
            noise=args.noise,
            delay_s=args.delay,
            seed=args.seed,
            offset_m=args.offset,
            heading_error_deg=args.heading_error_deg,
        )
        bar.update()
        frame.to_csv(out / "timeseries.csv", index=False)
        bar.update()
        with open(out / "metrics.json", "w") as f:
            json.dump(_json_metrics(metrics), f, indent=2, allow_nan=False)
            f.write("\n")
        bar.update()
        runs = {args.track: frame}
        plots.trajectory(runs, path, out / "trajectory.png")
        plots.lateral_error(runs, out / "lateral_error.png")
        plots.heading_error(runs, out / "heading_error.png")
        plots.steering(runs, out / "steering.png")
        plots.speed(runs, out / "speed.png")
        plots.alpha(runs, out / "alpha.png", "alpha(t)")
        bar.update()
    m = metrics
    print(
        f"{out}: {len(frame)} steps, {m['distance_m']:.1f} m, mean |e| {m['lateral_error_mean_abs_m']:.4f} m, "
        f"after first reaching 0.1 m {m['lateral_error_mean_abs_m_reached']:.4f} m (at {m['reached_time_s']:.2f} s), "
        f"body error {m['body_error_mean_m']:.4f} m (front {m['lateral_error_front_axle_mean_abs_m']:.4f}, "
        f"rear {m['lateral_error_rear_axle_mean_abs_m']:.4f})"
    )
    return 0


def _cmd_paper(args: argparse.Namespace) -> int:
    from blendtrack import paper

    require_file(args.track, "track", blendtrack.PathError)
    report = paper.reproduce(
        FsPath(args.track),
        FsPath(args.out),
        scale=args.scale,
        tests_file=FsPath(args.tests) if args.tests else None,
        quick=args.quick,
    )
    print(report)
    return 0


def add_sim_parser(subcommands: "argparse._SubParsersAction[Parser]") -> None:
    sim = subcommands.add_parser(
        "sim",
        help="run one closed-loop simulation and write its time series, metrics and plots",
        description=(
            "Runs one closed-loop simulation (entirely in Rust) and writes OUT/timeseries.csv, "
            "OUT/metrics.json (lateral/heading error of the control point, steering rate, lateral acceleration, "
            "time to first reach and to settle within 0.1 m, initial overshoot, speed, distance; *_reached = after "
            "first reaching 0.1 m, *_settled = after settling for good; the true front and rear axles' mean |e| and "
            "the body error, the mean of the larger of the two) and the plots trajectory.png, "
            "lateral_error.png, heading_error.png, steering.png, speed.png, alpha.png."
        ),
    )
    sim.add_argument(
        "--track",
        required=True,
        metavar="TRACK",
        help="a TUM csv file (x_m,y_m,w_tr_right_m,w_tr_left_m), straight[:LENGTH_M], circle:RADIUS_M or test_track",
    )
    sim.add_argument("--scale", type=finite("scale", 0.0, strict=True), default=None, metavar="F", help="scale the track by F (> 0)")
    sim.add_argument(
        "--controller",
        choices=["blend", "stanley", "pure-pursuit"],
        default=None,
        help="lateral law: the paper's blend (default), Stanley at the front axle, pure pursuit at the rear axle",
    )
    alpha = sim.add_mutually_exclusive_group()
    alpha.add_argument(
        "--alpha",
        type=alpha_value,
        default=None,
        metavar="A",
        help="blend factor in [0, 1]: 0 = rear axle, 1 = front axle (default 0.5 or the config's), or 'auto': "
        "chosen every step from the direction of travel, speed, curvature ahead and the axle errors "
        "(alpha_mode = \"auto\" and the auto_alpha_* keys of the config)",
    )
    alpha.add_argument(
        "--alpha-schedule",
        default=None,
        metavar="sine:OMEGA",
        help="moving control point alpha(t) = 0.5 (sin(OMEGA t) + 1) (the paper uses sine:0.2)",
    )
    sim.add_argument("--direction", choices=["forward", "backward"], default=None, help="direction of travel (default forward)")
    sim.add_argument("--speed", type=finite("speed", 0.0, strict=True), default=None, metavar="V", help="preferred speed (m/s, > 0; default 3)")
    sim.add_argument("--offset", type=finite("offset"), default=4.0, metavar="M", help="initial lateral offset of the rear axle (m, > 0 left; default 4)")
    sim.add_argument("--heading-error-deg", type=finite("heading error"), default=0.0, metavar="DEG", help="initial heading error (deg; default 0)")
    sim.add_argument(
        "--noise",
        default=None,
        metavar="SPEC",
        help="sensor noise on x, y, heading: uniform:POS_M[:HEADING_DEG] or walk:STEP_M:MAX_M[:HEADING_STEP_DEG:HEADING_MAX_DEG[:INTERVAL_S]] (default none)",
    )
    sim.add_argument("--delay", type=finite("delay", 0.0), default=0.0, metavar="S", help="actuation delay (s, >= 0; default 0)")
    length = sim.add_mutually_exclusive_group()
    length.add_argument("--duration", type=finite("duration", 0.0, strict=True), default=60.0, metavar="S", help="simulated time (s; default 60)")
    length.add_argument("--laps", type=finite("laps", 0.0, strict=True), default=None, metavar="N", help="stop after N laps of the track instead")
    sim.add_argument("--dt", type=finite("dt", 0.0, strict=True, high=1.0), default=0.01, metavar="S", help="time step (s, in (0, 1]; default 0.01)")
    sim.add_argument("--config", default=None, metavar="FILE.toml", help="TOML file with [controller] and [vehicle] tables (flags override it)")
    sim.add_argument("--seed", type=seed, default=0, metavar="N", help="seed of the sensor noise (default 0)")
    sim.add_argument("--out", required=True, metavar="DIR", help="output directory (created if missing)")
    sim.set_defaults(run=_cmd_sim)


def add_paper_parser(subcommands: "argparse._SubParsersAction[Parser]") -> None:
    paper = subcommands.add_parser(
        "paper",
        help="reproduce the paper's experiments and write a report with figures",
        description=(
            "Reproduces the paper's experiments in simulation and writes OUT/report.md with its figures, with two "
            "parameter sets (the paper's as printed; a fair one tuned on the training tracks by scripts/paper_tune.py, "
            "read from configs/paper_tuned.json) and 10 seeds with 95% confidence intervals: (1) claim C1, pure pursuit "
            "vs Stanley vs the blended command (and the automatic alpha) on the scaled-down track from a 4 m offset, "
            "with and without sensor noise and actuation delay; (2) why the delay lowers the error; (3) the moving "
            "control point alpha(t) = 0.5 (sin(0.2 t) + 1); (4) claims C2 and C3 with the six real-vehicle tests of "
            "configs/paper_real_tests.toml on the built-in closed loop, next to the paper's Table 2; (5) the held-out "
            "tracks. Each claim gets a verdict: reproduced or not, by how much, and why."
        ),
    )
    paper.add_argument("--track", required=True, metavar="FILE", help="the Nuerburgring TUM csv (e.g. ../shared/tracks/Nuerburgring.csv)")
    paper.add_argument("--out", required=True, metavar="DIR", help="output directory (created if missing)")
    paper.add_argument(
        "--scale",
        type=finite("scale", 0.0, strict=True),
        default=None,
        metavar="F",
        help="scale of the track for experiments 1-2 (default: chosen so the tightest turn needs at most half the steering limit)",
    )
    paper.add_argument("--tests", default=None, metavar="FILE.toml", help="the six tests (default: configs/paper_real_tests.toml of this repository)")
    paper.add_argument("--quick", action="store_true", help="shorter runs (a smoke test; the numbers are not the report's)")
    paper.set_defaults(run=_cmd_paper)
