"""What one run of each kind does, and the metrics it returns.

These functions run inside the worker process of the run (see
:mod:`blendtrack.batch.executor`), never in the batch process: libsumo
allows one simulation per process, and a crash must only end its own run.

- ``sim``: :func:`blendtrack.simulate` with the options of ``blendtrack sim``
  (defaults included: 60 s, a 4 m offset); metrics: its metrics dict
  (:data:`blendtrack.simulation.METRIC_KEYS` and the ``*_reached`` keys).
  Writes ``metrics.json``.
- ``sumo``: :func:`blendtrack.sumo.run_scenario` (as ``blendtrack sumo run``);
  metrics: the counts of ``summary.json`` and the mean over the controlled
  vehicles of each numeric column of ``vehicles.csv``. Writes what
  ``sumo run`` writes.
- ``compare``: one seed of ``blendtrack compare`` (baseline and treatment
  runs, paired by vehicle); metrics: ``baseline_M``, ``treatment_M`` and
  ``difference_M`` (treatment - baseline) for every metric of compare's
  summary table. Writes ``metrics.json`` and both runs.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Any

#: summary.json numbers of a ``sumo`` run that are metrics (the rest describe the run).
SUMO_SUMMARY_METRICS = (
    "controlled_vehicles",
    "background_vehicles",
    "collisions",
    "teleports",
    "red_light_violations",
    "vanished",
    "speed_warnings",
    "reverse_warnings",
)
#: vehicles.csv columns averaged over the controlled vehicles of a ``sumo`` run.
SUMO_VEHICLE_METRICS = (
    "lateral_error_mean_abs_m",
    "lateral_error_rms_m",
    "lateral_error_max_abs_m",
    "lateral_error_rear_axle_mean_abs_m",
    "lateral_error_front_axle_mean_abs_m",
    "heading_error_rms_deg",
    "mean_speed_mps",
    "lateral_accel_max_mps2",
    "long_jerk_rms_mps3",
    "travel_time_s",
    "time_above_comfort_s",
    "lane_changes",
    "distance_m",
)


def _split(params: dict[str, Any]) -> tuple[Any, Any, set[str]]:
    """The run's ControllerConfig and VehicleParams (config file, then the
    parameters) and the [controller] keys set explicitly."""
    import blendtrack

    config, vehicle = blendtrack.ControllerConfig(), blendtrack.VehicleParams()
    keys: set[str] = set()
    if "config" in params:
        from blendtrack.sumo import config_keys

        config, vehicle = blendtrack.load_config(params["config"])
        keys = config_keys(params["config"])
    cfg_fields = set(config.to_dict())
    veh_fields = set(vehicle.to_dict())
    cfg = {k: v for k, v in params.items() if k in cfg_fields}
    config = config.replace(**cfg).with_alpha(params.get("alpha"))
    if "alpha" in params:
        cfg["alpha_mode"] = config.alpha_mode
        if params["alpha"] != "auto":
            cfg["lat_blend_factor"] = params["alpha"]
    vehicle = vehicle.replace(**{k: v for k, v in params.items() if k in veh_fields})
    return config, vehicle, keys | set(cfg)


def _finite(metrics: dict[str, Any]) -> dict[str, float | None]:
    """JSON-safe metrics: numbers as floats, NaN and infinities as None."""
    out: dict[str, float | None] = {}
    for k, v in metrics.items():
        try:
            x = float(v)
        except (TypeError, ValueError):
            continue
        out[k] = x if math.isfinite(x) else None
    return out


def run_sim(task: dict[str, Any], work: Path) -> dict[str, float | None]:
    from blendtrack.simulation import load_track, simulate

    from blendtrack.batch.sweep import SIM_DEFAULTS

    p = {**SIM_DEFAULTS, **task["params"]}
    path = load_track(task["scenario"], p.get("scale"))
    config, vehicle, _ = _split(p)
    laps = p.get("laps")
    # As `blendtrack sim --laps`: a generous cap of ten times the lap time.
    duration = max(60.0, 10.0 * laps * path.length_m / config.preferred_speed) if laps is not None else p["duration_s"]
    _, metrics = simulate(
        path,
        config,
        vehicle,
        alpha=p.get("alpha_schedule"),
        dt_s=p["dt_s"],
        duration_s=duration,
        laps=laps,
        noise=p.get("noise"),
        delay_s=p["delay_s"],
        seed=task["seed"],
        start_s_m=p.get("start_s_m", 0.0),
        offset_m=p["offset_m"],
        heading_error_deg=p["heading_error_deg"],
        initial_speed_mps=p.get("initial_speed_mps", 0.0),
        fixed_speed_mps=p.get("fixed_speed_mps"),
    )
    result = _finite(metrics)
    (work / "metrics.json").write_text(json.dumps(result, indent=2) + "\n")
    return result


def _run_options(task: dict[str, Any]) -> Any:
    from blendtrack import sumo

    p = task["params"]
    config, vehicle, keys = _split(p)
    return sumo.RunOptions(
        controlled_fraction=p.get("controlled_fraction"),
        controlled_type=p.get("controlled_type"),
        max_controlled=p.get("max_controlled"),
        border_margin_m=p.get("border_margin_m", 0.0),
        corridor=p.get("corridor", sumo.RunOptions.corridor),
        stop_at_route_end=p.get("stop_at_route_end", False),
        tactical_lane_changes=p.get("tactical_lane_changes", False),
        open_gaps=p.get("open_gaps", True),
        miss_exit_after_s=p.get("miss_exit_after_s", sumo.RunOptions.miss_exit_after_s),
        control_dt_s=p.get("control_dt_s", 0.05),
        config=config,
        vehicle=vehicle,
        fixed_keys=frozenset(keys),
        end_s=p.get("end"),
        seed=task["seed"],
        progress=False,
    )


def run_sumo(task: dict[str, Any], work: Path) -> dict[str, float | None]:
    import csv

    from blendtrack import sumo

    scenario = sumo.resolve_scenario(task["scenario"])
    options = dataclasses.replace(_run_options(task), keep_records=False)
    result = sumo.run_scenario(scenario, options, work)
    metrics: dict[str, Any] = {k: result.summary[k] for k in SUMO_SUMMARY_METRICS}
    # From vehicles.csv, written as vehicles finished (a NaN is an empty field;
    # the other floats are written exactly).
    with open(work / "vehicles.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    for col in SUMO_VEHICLE_METRICS:
        vals = [float(r[col]) for r in rows if r[col] != ""]
        metrics[col] = sum(vals) / len(vals) if vals else math.nan
    return _finite(metrics)


def run_compare(task: dict[str, Any], work: Path) -> dict[str, float | None]:
    """One seed of ``blendtrack compare`` (the loop body of compare.compare)."""
    from blendtrack import sumo
    from blendtrack.sumo import compare
    from blendtrack.sumo.report import vehicle_ids

    p = task["params"]
    seed = task["seed"]
    scenario = sumo.resolve_scenario(task["scenario"])
    opts = compare.CompareOptions(
        baseline=p.get("baseline", "krauss"),
        controlled_fraction=p.get("controlled_fraction"),
        controlled_type=p.get("controlled_type"),
        seeds=1,
        end_s=p.get("end"),
        run=_run_options(task),
        progress=False,
    )
    end_s = opts.end_s if opts.end_s is not None else scenario.default_end_s
    sc = compare.with_model(scenario, opts.baseline, work / "model")
    compare.run_baseline(sc, seed, end_s, work / "baseline", opts.run.sumo_args)
    ropt = dataclasses.replace(opts.run, seed=seed, end_s=end_s)
    compare.run_treatment(sc, ropt, work / "treatment")
    controlled = vehicle_ids(work / "treatment" / "vehicles.csv")
    base_run = compare.load_run(work / "baseline", compare.selector(opts, sc, seed))
    treat_run = compare.load_run(work / "treatment", lambda vid, vtype: vid in controlled)
    paired = compare.pair(seed, base_run, treat_run, sc.step_length_s, scenario.comfort_lateral_accel_mps2)
    metrics: dict[str, Any] = {}
    for row in compare.summarise([paired]):
        for which in ("baseline", "treatment", "difference"):
            metrics[f"{which}_{row['metric']}"] = row[which]
    metrics["paired_vehicles"] = len(paired.rows)
    result = _finite(metrics)
    (work / "metrics.json").write_text(json.dumps(result, indent=2) + "\n")
    return result


RUNNERS = {"sim": run_sim, "sumo": run_sumo, "compare": run_compare}


def execute(task: dict[str, Any]) -> dict[str, float | None]:
    """Runs one task (see :meth:`blendtrack.batch.sweep.Run.task`) in this process; returns its metrics."""
    work = Path(task["work_dir"])
    work.mkdir(parents=True, exist_ok=True)
    return RUNNERS[task["kind"]](task, work)
