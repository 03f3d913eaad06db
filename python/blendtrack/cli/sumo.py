"""``blendtrack sumo run``, ``blendtrack sumo list`` and ``blendtrack
compare``: the SUMO plugin's commands and the options they share."""

from __future__ import annotations

import argparse
import signal
import sys
from pathlib import Path as FsPath
from typing import Any

import blendtrack
from blendtrack.cli.common import Parser, alpha_value, end_time, finite, raise_interrupt, require_file, seed, seeds, sumo_args

#: ``RunOptions.miss_exit_after_s``'s default, listed here so that parsing
#: does not load the SUMO bridge (a test holds the two equal).
MISS_EXIT_AFTER_S = 20.0


def _sumo_config(
    file: str | None,
) -> tuple[blendtrack.ControllerConfig | None, blendtrack.VehicleParams | None, set[str]]:
    """The --config file of the SUMO commands: (controller, vehicle, keys the
    file sets in [controller]); all empty without a file."""
    from blendtrack import sumo

    if file is None:
        return None, None, set()
    require_file(file, "config", blendtrack.ConfigError)
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
        open_gaps=args.open_gaps,
        miss_exit_after_s=args.miss_exit_after,
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
    previous = signal.signal(signal.SIGTERM, raise_interrupt)
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
    n_rail = s.get("rail_bound_not_controlled", 0)
    rail = f" ({n_rail} of them selected but on rails, left to SUMO)" if n_rail else ""
    print(
        f"{out}: {scenario.name}, {s['end_s'] - s['begin_s']:.0f} s simulated in {s['wall_time_s']:.1f} s; "
        f"{s['controlled_vehicles']} controlled, {s['background_vehicles']} background vehicles"
        f"{rail}; "
        f"mean |e| {mean_e:.3f} m; collisions with a controlled vehicle {s.get('collisions_with_controlled', s['collisions'])} "
        f"(of any vehicles: {s.get('collisions_all', 0)}), teleports {s['teleports']}, "
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
        type=finite("fraction", 0.0, high=1.0),
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
        type=alpha_value,
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
        type=sumo_args,
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
        type=finite("control dt", 0.0, strict=True),
        default=0.05,
        metavar="S",
        help="control rate in seconds (> 0; default 0.05): in every SUMO step the controllers and the bicycle model "
        "run ceil(step / S) times, leaders and signals held for the step, and the vehicle is placed once; "
        "S >= the step length gives one control step per SUMO step",
    )
    parser.add_argument(
        "--border-margin",
        type=finite("border margin", 0.0),
        default=0.0,
        metavar="M",
        help="widen the virtual borders by M metres on each side of the lane (>= 0; default 0: the lane's width)",
    )
    parser.add_argument(
        "--corridor",
        choices=("lane", "arc", "road", "auto", "carriageway"),
        default="auto",
        help="what limits the speed in curves: lane the paper's virtual borders at the lane's half width and its "
        "ray cast; arc the curve speeds sqrt(a_y / |curvature|) previewed along "
        "the path, a_y = curve_lateral_accel of --config or the scenario's comfort bound (2 m/s^2 unless its scenario.toml "
        "says otherwise); road the faster of the two (lane's ray cast and arc's curve speeds); auto (default) road where the lane's speed limit is 60 km/h or more (its curve speeds at half the comfort bound), lane under it; carriageway the paper's ray cast with the borders at the edges of the whole road (docs/sumo.md)",
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
    parser.add_argument(
        "--no-open-gaps",
        dest="open_gaps",
        action="store_false",
        help="never ask a SUMO driver to open a gap for a controlled vehicle waiting to change lanes (default: the driver "
        "behind on the target lane is asked through TraCI openGap, braking at most 2 m/s^2, as SUMO's drivers do for each other)",
    )
    parser.add_argument(
        "--miss-exit-after",
        type=finite("miss exit after", 0.0),
        default=MISS_EXIT_AFTER_S,
        metavar="S",
        help="a controlled vehicle that has stood S seconds at the end of its lane waiting for a lane change its route needs "
        "there gives the exit up, drives on along its lane and is rerouted to its destination (out of the network when no "
        f"way leads back; missed_exits in summary.json and vehicles.csv); 0: it waits, as SUMO's drivers do (default {MISS_EXIT_AFTER_S:g})",
    )


def add_compare_parser(subcommands: "argparse._SubParsersAction[Parser]") -> None:
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
    cmp.add_argument("--seeds", type=seeds, default=3, metavar="N", help="run seeds 0..N-1 (default 3)")
    cmp.add_argument("--end", type=end_time, metavar="S",
                     help="simulated end time (s, or H:M:S as SUMO reads times; default: the scenario's)")
    _add_output_options(cmp, "in both runs of every pair")
    cmp.set_defaults(run=_cmd_compare)


def _cmd_sumo_list(args: argparse.Namespace) -> int:
    from blendtrack import sumo

    for name in sumo.available_scenarios():
        sc = sumo.resolve_scenario(name)
        first = " ".join(str(sc.meta.get("description", "")).split())
        print(f"{name:<18} {first[:100]}")
    return 0


def add_sumo_parser(subcommands: "argparse._SubParsersAction[Parser]") -> None:
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
    run.add_argument("--end", type=end_time, metavar="S",
                     help="simulated end time (s, or H:M:S as SUMO reads times; default: the scenario's)")
    run.add_argument("--seed", type=seed, default=0, metavar="N", help="seed of SUMO and of the vehicle selection (default 0)")
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
