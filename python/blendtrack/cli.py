"""Command-line interface: ``blendtrack SUBCOMMAND ...``.

Each subcommand is a function ``_cmd_NAME(args) -> int`` registered in
``_build_parser`` with its own arguments; ``main`` returns its exit code.
Argument errors exit with code 2 and print exactly one line to stderr (no
usage block, no traceback), so scripts and logs show the reason and nothing
else. Errors that blendtrack raises for bad input (``BlendtrackError``: an
unknown track, an unreadable file, an out-of-range value) are argument
errors too.

Subcommands:
- ``version``: print the version.
- ``sim``: one closed-loop run; writes timeseries.csv, metrics.json and plots.
- ``paper``: reproduces the paper's experiments; writes report.md and figures.
- ``sumo``: the SUMO plugin (``sumo run``, ``sumo list``).
- ``compare``: blendtrack against SUMO's own drivers on a scenario, paired by
  vehicle over several seeds; writes report.md, report.html, comparison.csv.
- ``batch``: a parameter sweep from a TOML file, each run in its own worker
  process (local, or on a Dask cluster); resumable; writes results.parquet,
  results.csv and summary.md. Exits with code 1 when a run failed.

Ctrl-C prints one line and exits with code 130.
"""

from __future__ import annotations

import argparse
import json
import math
import shlex
import signal
import sys
import warnings
from collections.abc import Sequence
from pathlib import Path as FsPath
from typing import Any, NoReturn

import blendtrack


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors; subcommand parsers inherit it."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def _sumo_args(text: str) -> tuple[str, ...]:
    """``--sumo-args``: the options split as a shell would."""
    try:
        return tuple(shlex.split(text))
    except ValueError as e:
        raise argparse.ArgumentTypeError(f"--sumo-args {text!r}: {e}") from None


def _require_file(name: str, kind: str, error: type[Exception]) -> None:
    """Raises ``error`` naming ``name`` and why it cannot be read as a ``kind`` file."""
    from blendtrack.simulation import file_problem

    problem = file_problem(name)
    if problem:
        raise error(f"cannot read {kind} file {name}: {problem}")


def _cmd_version(args: argparse.Namespace) -> int:
    print(blendtrack.__version__)
    return 0


def _bounded(kind: str, whole: bool, low: float | None, high: float | None, strict: bool = False, bounds: str | None = None):  # type: ignore[no-untyped-def]
    """argparse type: a finite number (a whole one with ``whole``) in
    [low, high] (low excluded with ``strict``); ``bounds`` words the range in
    the error instead of the two separate limits."""

    def parse(text: str) -> float | int:
        try:
            value: float | int = int(text) if whole else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{kind} must be a {'whole number' if whole else 'number'}, got {text!r}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{kind} must be finite, got {text!r}")
        below = low is not None and (value <= low if strict else value < low)
        above = high is not None and value > high
        if bounds is not None and (below or above):
            raise argparse.ArgumentTypeError(f"{kind} must be in {bounds}, got {text}")
        if below:
            raise argparse.ArgumentTypeError(f"{kind} must be {'>' if strict else '>='} {low:g}, got {text}")
        if above:
            raise argparse.ArgumentTypeError(f"{kind} must be <= {high:g}, got {text}")
        return value

    parse.__name__ = kind
    return parse


def _finite(kind: str, low: float | None = None, strict: bool = False, high: float | None = None):  # type: ignore[no-untyped-def]
    """argparse type: a finite float within bounds."""
    return _bounded(kind, False, low, high, strict)


def _whole(what: str, low: int = 1, high: int | None = None, bounds: str | None = None):  # type: ignore[no-untyped-def]
    """argparse type: a whole number in [low, high]."""
    return _bounded(what, True, low, high, bounds=bounds)


#: argparse type of a seed: the core's u64.
_seed = _whole("seed", 0, 2**64 - 1, bounds="[0, 2**64)")
#: argparse type of compare's --seeds.
_seeds = _whole("seeds")


def _alpha_value(text: str) -> float | str:
    """argparse type of ``--alpha``: a number in [0, 1] or ``auto``."""
    if text.strip().lower() == "auto":
        return "auto"
    value: float = _finite("alpha", 0.0, high=1.0)(text)
    return value


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
        _require_file(args.config, "config", blendtrack.ConfigError)
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

    _require_file(args.track, "track", blendtrack.PathError)
    report = paper.reproduce(
        FsPath(args.track),
        FsPath(args.out),
        scale=args.scale,
        tests_file=FsPath(args.tests) if args.tests else None,
        quick=args.quick,
    )
    print(report)
    return 0


def _add_sim_parser(subcommands: "argparse._SubParsersAction[_Parser]") -> None:
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
    sim.add_argument("--scale", type=_finite("scale", 0.0, strict=True), default=None, metavar="F", help="scale the track by F (> 0)")
    sim.add_argument(
        "--controller",
        choices=["blend", "stanley", "pure-pursuit"],
        default=None,
        help="lateral law: the paper's blend (default), Stanley at the front axle, pure pursuit at the rear axle",
    )
    alpha = sim.add_mutually_exclusive_group()
    alpha.add_argument(
        "--alpha",
        type=_alpha_value,
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
    sim.add_argument("--speed", type=_finite("speed", 0.0, strict=True), default=None, metavar="V", help="preferred speed (m/s, > 0; default 3)")
    sim.add_argument("--offset", type=_finite("offset"), default=4.0, metavar="M", help="initial lateral offset of the rear axle (m, > 0 left; default 4)")
    sim.add_argument("--heading-error-deg", type=_finite("heading error"), default=0.0, metavar="DEG", help="initial heading error (deg; default 0)")
    sim.add_argument(
        "--noise",
        default=None,
        metavar="SPEC",
        help="sensor noise on x, y, heading: uniform:POS_M[:HEADING_DEG] or walk:STEP_M:MAX_M[:HEADING_STEP_DEG:HEADING_MAX_DEG[:INTERVAL_S]] (default none)",
    )
    sim.add_argument("--delay", type=_finite("delay", 0.0), default=0.0, metavar="S", help="actuation delay (s, >= 0; default 0)")
    length = sim.add_mutually_exclusive_group()
    length.add_argument("--duration", type=_finite("duration", 0.0, strict=True), default=60.0, metavar="S", help="simulated time (s; default 60)")
    length.add_argument("--laps", type=_finite("laps", 0.0, strict=True), default=None, metavar="N", help="stop after N laps of the track instead")
    sim.add_argument("--dt", type=_finite("dt", 0.0, strict=True, high=1.0), default=0.01, metavar="S", help="time step (s, in (0, 1]; default 0.01)")
    sim.add_argument("--config", default=None, metavar="FILE.toml", help="TOML file with [controller] and [vehicle] tables (flags override it)")
    sim.add_argument("--seed", type=_seed, default=0, metavar="N", help="seed of the sensor noise (default 0)")
    sim.add_argument("--out", required=True, metavar="DIR", help="output directory (created if missing)")
    sim.set_defaults(run=_cmd_sim)


def _add_paper_parser(subcommands: "argparse._SubParsersAction[_Parser]") -> None:
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
        type=_finite("scale", 0.0, strict=True),
        default=None,
        metavar="F",
        help="scale of the track for experiments 1-2 (default: chosen so the tightest turn needs at most half the steering limit)",
    )
    paper.add_argument("--tests", default=None, metavar="FILE.toml", help="the six tests (default: configs/paper_real_tests.toml of this repository)")
    paper.add_argument("--quick", action="store_true", help="shorter runs (a smoke test; the numbers are not the report's)")
    paper.set_defaults(run=_cmd_paper)


def _sumo_config(
    file: str | None,
) -> tuple[blendtrack.ControllerConfig | None, blendtrack.VehicleParams | None, set[str]]:
    """The --config file of the SUMO commands: (controller, vehicle, keys the
    file sets in [controller]); all empty without a file."""
    from blendtrack import sumo

    if file is None:
        return None, None, set()
    _require_file(file, "config", blendtrack.ConfigError)
    config, vehicle = blendtrack.load_config(file)
    return config, vehicle, sumo.config_keys(file)


def _run_options(args: argparse.Namespace, **extra: Any) -> Any:
    """The RunOptions of the options `sumo run` and `compare` share
    (_add_scenario_options, _add_output_options), plus ``extra``."""
    from blendtrack import sumo

    config, vehicle, keys = _sumo_config(args.config)
    return sumo.RunOptions(
        alpha=args.alpha,
        config=config,
        vehicle=vehicle,
        fixed_keys=frozenset(keys),
        border_margin_m=args.border_margin,
        corridor=args.corridor,
        stop_at_route_end=args.stop_at_route_end,
        tactical_lane_changes=args.tactical_lane_changes,
        control_dt_s=args.control_dt,
        sumo_args=args.sumo_args,
        **extra,
    )


def _cmd_sumo_run(args: argparse.Namespace) -> int:
    from blendtrack import sumo
    from blendtrack.sumo.selection import parse_ids

    scenario = sumo.resolve_scenario(args.scenario)
    options = _run_options(
        args,
        controlled_fraction=args.controlled_fraction,
        controlled_type=args.controlled_type,
        controlled_ids=parse_ids(args.controlled_ids or ()),
        end_s=args.end,
        seed=args.seed,
        backend="traci" if args.gui else args.backend,
        gui=args.gui,
        trace=args.trace,
        fcd=args.fcd,
        ssm=args.ssm,
        progress=not args.quiet,
        keep_records=False,
    )
    out = FsPath(args.out)
    # SIGTERM stops the run as Ctrl-C does: SUMO is closed, the rows of the
    # vehicles that finished stay in vehicles.csv, the folder stays INCOMPLETE.
    previous = signal.signal(signal.SIGTERM, _raise_interrupt)
    try:
        result = sumo.run_scenario(scenario, options, out)
    except KeyboardInterrupt:
        print(f"blendtrack sumo run: interrupted; {out} is marked INCOMPLETE, vehicles.csv holds the vehicles that finished",
              file=sys.stderr)
        return 130
    finally:
        signal.signal(signal.SIGTERM, previous)
    s = result.summary
    mean_e = result.totals.sum_abs_e / max(result.totals.steps, 1)
    print(
        f"{out}: {scenario.name}, {s['end_s']:.0f} s simulated in {s['wall_time_s']:.1f} s; "
        f"{s['controlled_vehicles']} controlled, {s['background_vehicles']} background vehicles; "
        f"mean |e| {mean_e:.3f} m; collisions {s['collisions']} (with any vehicle: {s.get('collisions_all', 0)}), teleports {s['teleports']}, "
        f"red-light violations {s['red_light_violations']} (by SUMO's signal state: {s.get('red_light_crossings_sumo', 0)}), "
        f"emergency brakings {s.get('emergency_brakings', 0)}"
    )
    return 0


def _cmd_compare(args: argparse.Namespace) -> int:
    from blendtrack import sumo
    from blendtrack.sumo import compare

    scenario = sumo.resolve_scenario(args.scenario)
    run = _run_options(args)
    opts = compare.CompareOptions(
        baseline=args.baseline,
        controlled_fraction=args.controlled_fraction,
        controlled_type=args.controlled_type,
        seeds=args.seeds,
        end_s=args.end,
        run=run,
        progress=not args.quiet,
    )
    out = FsPath(args.out)
    compare.compare(scenario, opts, out)
    print(f"{out / 'report.md'}: {scenario.name}, {args.seeds} seed(s), baseline {args.baseline}; also report.html, comparison.csv")
    return 0


def _add_scenario_options(parser: argparse.ArgumentParser, ids: bool) -> None:
    """The scenario and what drives it, shared by `sumo run` and `compare`:
    the selection of controlled vehicles, alpha, config and driving options."""
    parser.add_argument(
        "scenario", metavar="SCENARIO", help="scenario name or folder, or a SUMO configuration file (.sumocfg, .cfg, .xml)"
    )
    which = parser.add_mutually_exclusive_group()
    which.add_argument(
        "--controlled-fraction",
        type=_finite("fraction", 0.0, high=1.0),
        metavar="P",
        help="control this fraction of all vehicles, chosen by a seeded hash of their ids (0..1)",
    )
    which.add_argument(
        "--controlled-type",
        metavar="T",
        help="control every vehicle of vType T, or of the members of vTypeDistribution T "
        "(default: vTypes with blendtrack.controlled=true)",
    )
    if ids:
        which.add_argument(
            "--controlled-ids", metavar="IDS", action="append", help="control these vehicle ids (comma-separated, repeatable)"
        )
    parser.add_argument(
        "--alpha",
        type=_alpha_value,
        metavar="A",
        help="blend factor for every controlled vehicle (0 = rear axle, 1 = front axle), or 'auto' (chosen every step "
        "from direction, speed, curvature ahead and errors)",
    )
    parser.add_argument("--config", metavar="FILE.toml", help="[controller] and [vehicle] parameters (paper names)")
    _add_driving_options(parser)


def _add_output_options(parser: argparse.ArgumentParser, sumo_args_where: str) -> None:
    """SUMO's own options, the progress bar and the output folder."""
    parser.add_argument(
        "--sumo-args",
        type=_sumo_args,
        default=(),
        metavar="'OPTS'",
        help=f"extra options for SUMO itself, one quoted string, {sumo_args_where}; an option SUMO does not know is a "
        "one-line error",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument("--out", required=True, metavar="DIR", help="output directory (created if missing)")


def _add_driving_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--control-dt",
        type=_finite("control dt", 0.0, strict=True),
        default=0.05,
        metavar="S",
        help="control rate in seconds (> 0; default 0.05): in every SUMO step the controllers and the bicycle model "
        "run ceil(step / S) times, leaders and signals held for the step, and the vehicle is placed once; "
        "S >= the step length gives one control step per SUMO step",
    )
    parser.add_argument(
        "--border-margin",
        type=_finite("border margin", 0.0),
        default=0.0,
        metavar="M",
        help="widen the virtual borders by M metres on each side of the lane (>= 0; default 0: the lane's width)",
    )
    parser.add_argument(
        "--corridor",
        choices=("lane", "arc", "carriageway"),
        default="lane",
        help="what limits the speed in curves: lane (default) the paper's virtual borders at the lane's half width and its "
        "ray cast; arc the curve speeds sqrt(a_y / |curvature|) previewed along "
        "the path, a_y = curve_lateral_accel of --config or the scenario's comfort bound (2 m/s^2 unless its scenario.toml "
        "says otherwise); carriageway the paper's ray cast with the borders at the edges of the whole road (docs/sumo.md)",
    )
    parser.add_argument(
        "--stop-at-route-end",
        action="store_true",
        help="controlled vehicles stop at the end of their route (default: they leave at speed, as SUMO's drivers do)",
    )
    parser.add_argument(
        "--tactical-lane-changes",
        action="store_true",
        help="controlled vehicles also change lanes where their route does not need it, when SUMO's lane-change model "
        "would (to overtake, keep right, make room) and the target lane has room (default: only the changes the route needs). "
        "Experimental: tried on 2 networks and 3 seeds; on the urban grid it adds teleports (docs/safety.md)",
    )


def _add_compare_parser(subcommands: "argparse._SubParsersAction[_Parser]") -> None:
    cmp = subcommands.add_parser(
        "compare",
        help="blendtrack against SUMO's own drivers on a scenario, paired by vehicle, over seeds",
        description=(
            "For each seed 0..N-1 runs SCENARIO twice with the same demand, seed and end time: the baseline "
            "(plain SUMO, every vehicle on SUMO's car-following model) and the treatment (the selected vehicles "
            "driven by blendtrack). Pairs each controlled vehicle with its baseline twin (same id) and writes "
            "DIR/comparison.csv (per-vehicle pairs), DIR/network.csv, DIR/report.md and a self-contained "
            "DIR/report.html (summary table with 95% CIs over seeds, plots, a paragraph made from the numbers), "
            "and the runs in DIR/runs/. Ctrl-C leaves no report."
        ),
    )
    _add_scenario_options(cmp, ids=False)
    cmp.add_argument(
        "--baseline",
        choices=("krauss", "idm", "eidm", "acc"),
        default="krauss",
        help="car-following model of every vType in both runs: krauss = as in the scenario (default), or IDM, EIDM, ACC",
    )
    cmp.add_argument("--seeds", type=_seeds, default=3, metavar="N", help="run seeds 0..N-1 (default 3)")
    cmp.add_argument("--end", type=_finite("end time", 0.0, strict=True), metavar="S", help="simulated end time (s; default: the scenario's)")
    _add_output_options(cmp, "in both runs of every pair")
    cmp.set_defaults(run=_cmd_compare)


def _cmd_batch(args: argparse.Namespace) -> int:
    from blendtrack import batch

    sweep = batch.load_sweep(args.sweep)
    out_dir = args.out if args.out is not None else sweep.out
    if out_dir is None:
        raise batch.BatchError(f"no output folder: pass --out DIR or set out = \"DIR\" in {args.sweep}")
    out = FsPath(out_dir)
    if args.report_only:
        frame = batch.write_report(out)
        counts = ", ".join(f"{n} {s}" for s, n in frame["status"].value_counts().items())
        print(f"{out / 'summary.md'}: {len(frame)} runs ({counts}); also results.parquet, results.csv")
        return 0 if (frame["status"] == "ok").all() else 1
    options = batch.BatchOptions(
        out=out,
        workers=args.workers,
        scheduler=args.scheduler,
        dask_local=args.dask_local,
        resume=args.resume,
        timeout_s=args.timeout,
        progress=not args.quiet,
    )
    # SIGTERM (kill, a cluster's job scheduler) stops the batch as Ctrl-C does:
    # the running runs are killed with their SUMO processes, the records stay.
    previous = signal.signal(signal.SIGTERM, _raise_interrupt)
    try:
        result = batch.run_batch(sweep, options)
    except KeyboardInterrupt:
        done = len(list((out / "runs").glob("*.json"))) if (out / "runs").is_dir() else 0
        print(
            f"blendtrack batch: interrupted; {done} of {len(sweep.runs)} runs recorded in {out / 'runs'} "
            "(continue with --resume)",
            file=sys.stderr,
        )
        return 130
    finally:
        signal.signal(signal.SIGTERM, previous)
    failed = result.failed + result.timeout
    before = f" ({result.skipped} from before)" if result.skipped else ""
    print(
        f"{result.summary}: {result.runs} runs: {result.ok + result.skipped} ok{before}, {result.failed} failed, "
        f"{result.timeout} timed out; {result.wall_time_s:.1f} s on {result.executor}; also results.parquet, results.csv"
    )
    return 1 if failed else 0


def _raise_interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt


def _add_batch_parser(subcommands: "argparse._SubParsersAction[_Parser]") -> None:
    b = subcommands.add_parser(
        "batch",
        help="run a parameter sweep from a TOML file (local worker processes or a Dask cluster), resumable",
        description=(
            "Runs every run of the sweep file SWEEP.toml (kind sim, sumo or compare; scenarios x [grid] x [zip] x "
            "[[cases]] x seeds), each in a worker process of its own, and writes DIR/runs/<id>.json as each run "
            "finishes (atomically: a record is complete or absent, even after SIGKILL), then DIR/results.parquet, "
            "DIR/results.csv (one row per run), DIR/plots/ and DIR/summary.md (runs per status, each metric against "
            "each swept parameter with its 95% CI over seeds, the best parameter set per metric, failed runs). A run "
            "that fails, crashes or times out is recorded as such and the others go on; --resume runs again only what "
            "has no ok record. Exit code: 0 when every run is ok, 1 when some failed, 2 on bad input, 130 on Ctrl-C. "
            "See docs/batch.md for the file format and for running on a Dask cluster."
        ),
    )
    b.add_argument("sweep", metavar="SWEEP.toml", help="the sweep file")
    where = b.add_mutually_exclusive_group()
    where.add_argument(
        "--workers",
        type=_whole("workers", high=256),
        metavar="N",
        help="local worker processes, one run each at a time (<= 256; default: the number of cores)",
    )
    where.add_argument(
        "--dask-local",
        type=_whole("dask-local", high=256),
        metavar="N",
        help="start a Dask LocalCluster of N (<= 256) single-threaded worker processes and run there",
    )
    where.add_argument(
        "--scheduler",
        metavar="tcp://HOST:PORT",
        help="run on the Dask cluster of this scheduler (every worker needs the same blendtrack and the scenario paths)",
    )
    b.add_argument("--resume", action="store_true", help="continue the batch in DIR: skip runs with an ok record, retry failed ones")
    b.add_argument("--timeout", type=_finite("timeout", 0.0, strict=True), metavar="S", help="per-run time limit in seconds (overrides the sweep's timeout_s)")
    b.add_argument("--report-only", action="store_true", help="run nothing: rebuild results and summary.md from DIR/runs/")
    b.add_argument("--quiet", action="store_true", help="no progress bar")
    b.add_argument("--out", metavar="DIR", help="output folder (default: the sweep's out)")
    b.set_defaults(run=_cmd_batch)


def _cmd_sumo_list(args: argparse.Namespace) -> int:
    from blendtrack import sumo

    for name in sumo.available_scenarios():
        sc = sumo.resolve_scenario(name)
        first = " ".join(str(sc.meta.get("description", "")).split())
        print(f"{name:<18} {first[:100]}")
    return 0


def _add_sumo_parser(subcommands: "argparse._SubParsersAction[_Parser]") -> None:
    sumo_p = subcommands.add_parser(
        "sumo",
        help="drive SUMO vehicles with blendtrack (run a scenario, list scenarios)",
        description="The SUMO plugin: blendtrack controllers drive selected vehicles among SUMO's own drivers.",
    )
    sub = sumo_p.add_subparsers(dest="sumo_command", metavar="SUBCOMMAND", required=True)
    lst = sub.add_parser("list", help="list the scenarios shipped in sumo_scenarios/")
    lst.set_defaults(run=_cmd_sumo_list)
    run = sub.add_parser(
        "run",
        help="run a scenario with blendtrack driving the selected vehicles",
        description=(
            "Runs SCENARIO (a folder of sumo_scenarios/ by name or path, or any SUMO configuration) with the selected "
            "vehicles driven by blendtrack along their lanes and everybody else on SUMO's own models. Writes "
            "OUT/vehicles.csv (one row per controlled vehicle), OUT/summary.json, the plots "
            "lateral_error_hist.png, speed_vs_curvature.png and trajectory.png, SUMO's tripinfo (with "
            "emissions), collision output and log in OUT/sumo/, and on request the per-step trace, FCD and SSM "
            "outputs. Without --controlled-*, the vehicles of vTypes carrying the parameter "
            "blendtrack.controlled=true are controlled; vType parameters blendtrack.<key> override any "
            "[controller] or [vehicle] key for that type."
        ),
    )
    _add_scenario_options(run, ids=True)
    run.add_argument("--end", type=_finite("end time", 0.0, strict=True), metavar="S", help="simulated end time (s; default: the scenario's)")
    run.add_argument("--seed", type=_seed, default=0, metavar="N", help="seed of SUMO and of the vehicle selection (default 0)")
    run.add_argument("--gui", action="store_true", help="show the run in sumo-gui (through TraCI)")
    run.add_argument(
        "--backend",
        choices=("libsumo", "traci"),
        default="libsumo",
        help="libsumo (in-process, fast; default) or traci (sockets, as --gui uses)",
    )
    run.add_argument("--trace", action="store_true", help="also write OUT/trace.csv, one row per controlled vehicle and step")
    run.add_argument("--fcd", action="store_true", help="also write SUMO's floating car data to OUT/sumo/fcd.xml")
    run.add_argument("--ssm", action="store_true", help="also write SUMO's SSM conflicts (TTC, DRAC, PET) to OUT/sumo/ssm.xml")
    _add_output_options(run, "(e.g. --sumo-args '--scale 2': demand x2)")
    run.set_defaults(run=_cmd_sumo_run)


def _build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="blendtrack",
        description="Path tracking with dynamic control point blending.",
    )
    subcommands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    version = subcommands.add_parser("version", help="print the version and exit")
    version.set_defaults(run=_cmd_version)
    _add_sim_parser(subcommands)
    _add_paper_parser(subcommands)
    _add_sumo_parser(subcommands)
    _add_compare_parser(subcommands)
    _add_batch_parser(subcommands)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Runs the CLI on ``argv`` (default: ``sys.argv[1:]``); returns the exit code."""
    args = _build_parser().parse_args(argv)
    # A warning is one line too, saying what happened (no source line).
    command = args.command

    def one_line(message: Warning | str, category: type[Warning], filename: str, lineno: int, line: str | None = None) -> str:
        return f"blendtrack {command}: warning: {message}\n"

    warnings.formatwarning = one_line
    try:
        exit_code: int = args.run(args)
    except blendtrack.BlendtrackError as e:
        message = " ".join(str(e).split())
        print(f"blendtrack {args.command}: error: {message}", file=sys.stderr)
        return 2
    except OSError as e:
        print(f"blendtrack {args.command}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"blendtrack {args.command}: interrupted", file=sys.stderr)
        return 130
    return exit_code


if __name__ == "__main__":
    sys.exit(main())
