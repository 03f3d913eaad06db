"""The comparison's numbers: per-vehicle metrics from SUMO's outputs, the
same way for both runs, paired by vehicle, and summarised over seeds."""

from __future__ import annotations

import csv
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from blendtrack.reporting import mean_ci
from blendtrack.sumo.outputs import Track, count_remote_collisions, lateral_series, read_fcd, read_ssm_conflicts, read_statistics, read_tripinfo

#: Per-vehicle metrics: (name, label, unit, lower is better?).
VEHICLE_METRICS: tuple[tuple[str, str, str], ...] = (
    ("travel_time_s", "travel time (to arrival or the end)", "s"),
    ("time_loss_s", "time loss", "s"),
    ("mean_speed_mps", "mean speed", "m/s"),
    ("lat_accel_max_mps2", "max lateral acceleration", "m/s^2"),
    ("lat_accel_rms_mps2", "RMS lateral acceleration", "m/s^2"),
    ("long_jerk_rms_mps3", "RMS longitudinal jerk", "m/s^3"),
    ("time_above_comfort_s", "time above the comfort lateral acceleration", "s"),
    ("lateral_error_rms_m", "RMS lateral error (baseline 0 by construction)", "m"),
    ("co2_g", "CO2", "g"),
    ("fuel_g", "fuel", "g"),
)
#: Per-run network metrics.
NETWORK_METRICS: tuple[tuple[str, str, str], ...] = (
    ("controlled_travel_time_s", "mean travel time, controlled vehicles", "s"),
    ("controlled_time_loss_s", "mean time loss, controlled vehicles", "s"),
    ("background_travel_time_s", "mean travel time, background vehicles", "s"),
    ("background_time_loss_s", "mean time loss, background vehicles", "s"),
    ("throughput", "throughput (vehicles arrived at their destination)", "veh"),
    ("ssm_conflicts", "SSM conflicts (TTC < 3 s or DRAC > 3 m/s^2)", "count"),
    ("collisions", "collisions", "count"),
    ("teleports", "teleports", "count"),
    ("missed_exits", "missed exits (controlled vehicles rerouted from a lane's end)", "veh"),
)


@dataclass
class RunData:
    """What one run (baseline or treatment) gives the comparison."""

    fcd: dict[str, Track]
    trips: dict[str, dict[str, float]]
    controlled: set[str]
    network: dict[str, float]
    lateral_error: dict[str, float]


def vehicle_metrics(tr: Track, trip: dict[str, float] | None, dt: float, comfort: float) -> dict[str, float]:
    _, a_lat, _, _ = lateral_series(tr, dt)
    acc = np.diff(tr.speed) / dt
    jerk = np.diff(acc) / dt
    nan = math.nan
    return {
        "travel_time_s": trip["duration"] if trip else nan,
        "time_loss_s": trip["time_loss"] if trip else nan,
        "mean_speed_mps": float(tr.speed.mean()) if len(tr.speed) else nan,
        "lat_accel_max_mps2": float(np.abs(a_lat).max()) if len(a_lat) else nan,
        "lat_accel_rms_mps2": float(np.sqrt(np.mean(a_lat**2))) if len(a_lat) else nan,
        "long_jerk_rms_mps3": float(np.sqrt(np.mean(jerk**2))) if len(jerk) else nan,
        "time_above_comfort_s": float(np.count_nonzero(np.abs(a_lat) > comfort) * dt),
        "co2_g": trip["co2_g"] if trip else nan,
        "fuel_g": trip["fuel_g"] if trip else nan,
    }


def read_vehicles(vehicles_csv: Path, lateral: str = "lateral_error_rms_m") -> tuple[dict[str, float], set[str]]:
    """From a run's ``vehicles.csv`` (nothing when there is no such file):
    each vehicle's lateral error of column ``lateral`` (RMS by default; NaN
    where empty), and the vehicles that gave up an exit (``missed_exits`` >
    0, none in a file from before that column; ``RunOptions.miss_exit_after_s``)."""
    lat_err: dict[str, float] = {}
    missed: set[str] = set()
    if vehicles_csv.exists():
        with open(vehicles_csv) as f:
            for row in csv.DictReader(f):
                lat_err[row["id"]] = float(row[lateral]) if row[lateral] else math.nan
                if float(row.get("missed_exits") or 0) > 0:
                    missed.add(row["id"])
    return lat_err, missed


def load_run(out: Path, is_controlled: Callable[[str, str], bool]) -> RunData:
    sd = out / "sumo"
    fcd = read_fcd(sd / "fcd.xml")
    controlled = {v for v, tr in fcd.items() if is_controlled(v, tr.vtype)}
    trips = read_tripinfo(sd / "tripinfo.xml")
    collisions, teleports = read_statistics(sd / "statistics.xml")
    # SUMO's count, and the lane collisions it skips under teleport for
    # vehicles moved by (x, y), which blendtrack found (blendtrack.sumo.collisions).
    collisions += count_remote_collisions(out / "collisions.csv")

    def mean_of(ids: list[str], key: str) -> float:
        vals = [trips[i][key] for i in ids]
        return float(np.mean(vals)) if vals else math.nan

    lat_err, missed = read_vehicles(out / "vehicles.csv")
    ctrl = [v for v in trips if v in controlled]
    back = [v for v in trips if v not in controlled]
    network = {
        "controlled_travel_time_s": mean_of(ctrl, "duration"),
        "controlled_time_loss_s": mean_of(ctrl, "time_loss"),
        "background_travel_time_s": mean_of(back, "duration"),
        "background_time_loss_s": mean_of(back, "time_loss"),
        # A controlled vehicle that missed its exit (vehicles.csv) arrives
        # in SUMO's trip info, but not where its trip was going.
        "throughput": float(sum(t["arrived"] for v, t in trips.items() if v not in missed)),
        "ssm_conflicts": float(read_ssm_conflicts(sd / "ssm.xml")),
        "collisions": float(collisions),
        "teleports": float(teleports),
        "missed_exits": float(len(missed)),
    }
    return RunData(fcd, trips, controlled, network, lat_err)


@dataclass
class SeedResult:
    seed: int
    rows: list[dict[str, Any]]
    network: dict[str, dict[str, float]]  # "baseline"/"treatment" -> metrics
    unpaired: int
    base: RunData
    treat: RunData


def pair(seed: int, base: RunData, treat: RunData, dt: float, comfort: float) -> SeedResult:
    ids = sorted(base.controlled & treat.controlled & base.fcd.keys() & treat.fcd.keys())
    rows = []
    for vid in ids:
        mb = vehicle_metrics(base.fcd[vid], base.trips.get(vid), dt, comfort)
        mt = vehicle_metrics(treat.fcd[vid], treat.trips.get(vid), dt, comfort)
        mb["lateral_error_rms_m"] = 0.0
        mt["lateral_error_rms_m"] = treat.lateral_error.get(vid, math.nan)
        row: dict[str, Any] = {"seed": seed, "id": vid}
        for name, _, _ in VEHICLE_METRICS:
            row[f"{name}_baseline"] = mb[name]
            row[f"{name}_treatment"] = mt[name]
        rows.append(row)
    unpaired = len(base.controlled ^ treat.controlled)
    return SeedResult(seed, rows, {"baseline": base.network, "treatment": treat.network}, unpaired, base, treat)


def summarise(results: list[SeedResult]) -> list[dict[str, Any]]:
    """One row per metric: baseline and treatment (mean over seeds of the
    per-seed means), difference (treatment - baseline) and its 95 % CI over seeds."""
    table = []
    for name, label, unit in VEHICLE_METRICS:
        b, t, d = [], [], []
        for r in results:
            pairs = [(row[f"{name}_baseline"], row[f"{name}_treatment"]) for row in r.rows]
            pairs = [(x, y) for x, y in pairs if x == x and y == y]
            if not pairs:
                continue
            mb = float(np.mean([x for x, _ in pairs]))
            mt = float(np.mean([y for _, y in pairs]))
            b.append(mb)
            t.append(mt)
            d.append(mt - mb)
        table.append(_row(name, f"{label} (per controlled vehicle)", unit, b, t, d))
    for name, label, unit in NETWORK_METRICS:
        b = [r.network["baseline"][name] for r in results]
        t = [r.network["treatment"][name] for r in results]
        d = [y - x for x, y in zip(b, t)]
        table.append(_row(name, label, unit, b, t, d))
    return table


def _row(name: str, label: str, unit: str, b: list[float], t: list[float], d: list[float]) -> dict[str, Any]:
    mb = float(np.nanmean(b)) if any(x == x for x in b) else math.nan
    mt = float(np.nanmean(t)) if any(x == x for x in t) else math.nan
    md, lo, hi = mean_ci(d)
    return {"metric": name, "label": label, "unit": unit, "baseline": mb, "treatment": mt, "difference": md,
            "ci_low": lo, "ci_high": hi, "seeds": len([x for x in d if x == x])}
