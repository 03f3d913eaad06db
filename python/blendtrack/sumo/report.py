"""Outputs of a SUMO run: ``vehicles.csv``, ``summary.json``, the trace and plots.

``vehicles.csv`` is written as vehicles finish (:class:`VehicleWriter`);
the other files are written to a temporary name and renamed into place, so
an interrupted run never leaves one that looks complete.
"""

from __future__ import annotations

import csv
import json
import math
import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from blendtrack.reporting import save_figure
from blendtrack.sumo.records import RunResult, VehicleRecord

#: The columns of vehicles.csv, in order (more may follow).
VEHICLE_COLUMNS = (
    "id",
    "lateral_error_mean_abs_m",
    "lateral_error_rms_m",
    "lateral_error_max_abs_m",
    "heading_error_rms_deg",
    "mean_speed_mps",
    "lateral_accel_max_mps2",
    "long_jerk_rms_mps3",
    "travel_time_s",
    "collisions",
    "teleports",
)
EXTRA_COLUMNS = (
    "lateral_error_rear_axle_mean_abs_m",
    "lateral_error_front_axle_mean_abs_m",
    "vtype",
    "depart_s",
    "end_s",
    "end_reason",
    "distance_m",
    "steps",
    "red_light_violations",
    "speed_warnings",
    "reverse_warnings",
    "time_above_comfort_s",
    "lane_changes",
    "missed_exits",
    "stops_served",
    "stops_skipped",
    "stop_skip_reasons",
    "red_light_crossings_sumo",
    "emergency_brakings",
)


def vehicle_row(r: VehicleRecord) -> dict[str, Any]:
    n = max(r.steps, 1)
    nan = math.nan
    return {
        "id": r.vid,
        "lateral_error_mean_abs_m": r.sum_abs_e / n if r.steps else nan,
        "lateral_error_rms_m": math.sqrt(r.sum_e2 / n) if r.steps else nan,
        "lateral_error_max_abs_m": r.max_abs_e if r.steps else nan,
        "heading_error_rms_deg": math.degrees(math.sqrt(r.sum_eth2 / n)) if r.steps else nan,
        "mean_speed_mps": r.sum_v / n if r.steps else nan,
        "lateral_accel_max_mps2": r.max_lat_acc if r.steps else nan,
        "long_jerk_rms_mps3": math.sqrt(r.sum_jerk2 / r.jerk_n) if r.jerk_n else nan,
        "travel_time_s": r.end_s - r.depart_s,
        "collisions": r.collisions,
        "teleports": r.teleports,
        "lateral_error_rear_axle_mean_abs_m": r.sum_abs_e_rear / n if r.steps else nan,
        "lateral_error_front_axle_mean_abs_m": r.sum_abs_e_front / n if r.steps else nan,
        "vtype": r.vtype,
        "depart_s": r.depart_s,
        "end_s": r.end_s,
        "end_reason": r.reason,
        "distance_m": r.distance_m,
        "steps": r.steps,
        "red_light_violations": r.red_light_violations,
        "speed_warnings": r.speed_warnings,
        "reverse_warnings": r.reverse_warnings,
        "time_above_comfort_s": r.time_above_comfort_s,
        "lane_changes": r.lane_changes,
        "missed_exits": r.missed_exits,
        "stops_served": r.stops_served,
        "stops_skipped": r.stops_skipped,
        "stop_skip_reasons": r.stop_skip_reasons,
        "red_light_crossings_sumo": r.red_light_crossings_sumo,
        "emergency_brakings": r.emergency_brakings,
    }


def _atomic_write(path: Path, write: Any) -> None:
    tmp = path.with_name(path.name + ".part")
    with open(tmp, "w", newline="") as f:
        write(f)
    os.replace(tmp, path)


def _csv_row(r: VehicleRecord) -> dict[str, Any]:
    return {k: ("" if isinstance(v, float) and not math.isfinite(v) else v) for k, v in vehicle_row(r).items()}


def write_vehicles_csv(records: Iterable[VehicleRecord], path: Path) -> None:
    rows = [_csv_row(r) for r in records]

    def write(f: Any) -> None:
        w = csv.DictWriter(f, fieldnames=[*VEHICLE_COLUMNS, *EXTRA_COLUMNS])
        w.writeheader()
        w.writerows(rows)

    _atomic_write(path, write)


class VehicleWriter:
    """``vehicles.csv`` written as vehicles finish: the header at once, then
    one row per finished vehicle (:meth:`write`, a ``Controlled.finished``
    sink), appended and flushed, so a run killed at any point leaves the
    rows of the vehicles that finished before it (the output folder's
    ``INCOMPLETE`` marker says the run did not end). Same columns and row
    content as :func:`write_vehicles_csv`; the rows come in the order the
    vehicles finished."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._file = open(path, "w", newline="")
        self._csv = csv.DictWriter(self._file, fieldnames=[*VEHICLE_COLUMNS, *EXTRA_COLUMNS])
        self._csv.writeheader()
        self._file.flush()

    def write(self, r: VehicleRecord) -> None:
        self._csv.writerow(_csv_row(r))
        self._file.flush()

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> VehicleWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def vehicle_ids(path: Path) -> set[str]:
    """The ids in a ``vehicles.csv``."""
    with open(path, newline="") as f:
        return {row["id"] for row in csv.DictReader(f)}


def write_json(data: dict[str, Any], path: Path) -> None:
    clean = {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in data.items()}

    def write(f: Any) -> None:
        json.dump(clean, f, indent=2, allow_nan=False)
        f.write("\n")

    _atomic_write(path, write)


def plot_run(result: RunResult, out: Path, comfort: float) -> list[Path]:
    """Lateral-error distribution, speed against curvature, one trajectory."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    files: list[Path] = []
    h = result.histograms
    fig, ax = plt.subplots(figsize=(7, 4))
    if h.n:
        last = int(np.nonzero(h.error_counts)[0].max()) + 1 if h.error_counts.any() else 1
        edges = h.ERROR_EDGES[: last + 1]
        ax.stairs(h.error_counts[:last], edges, fill=True, color="tab:blue")
    ax.set_xlabel("|lateral error| of the control point (m; the last 0.01 m bin holds all beyond 2 m)")
    ax.set_ylabel("samples (every 10th step)")
    ax.set_title("Lateral error of controlled vehicles")
    files.append(save_figure(fig, out / "lateral_error_hist.png", 110))

    fig, ax = plt.subplots(figsize=(7, 4.5))
    if h.n:
        counts = h.speed_curvature_counts
        ki = int(np.nonzero(counts.any(axis=1))[0].max()) + 1
        vi = int(np.nonzero(counts.any(axis=0))[0].max()) + 1
        kmax, vmax = float(h.CURVATURE_EDGES[ki]), float(h.SPEED_EDGES[vi])
        shown = np.ma.masked_equal(counts[:ki, :vi].T, 0)
        mesh = ax.pcolormesh(h.CURVATURE_EDGES[: ki + 1], h.SPEED_EDGES[: vi + 1], shown, cmap="viridis",
                             norm=matplotlib.colors.LogNorm())
        fig.colorbar(mesh, ax=ax, label="samples (every 10th step)")
        k = np.linspace(kmax / 200, kmax, 200)
        ax.plot(k, np.sqrt(comfort / k), "k--", lw=1, label=f"v = sqrt({comfort:g} / |curvature|)")
        ax.set_xlim(0, kmax)
        ax.set_ylim(0, max(vmax * 1.1, 1.0))
        ax.legend(loc="upper right", fontsize=8)
    else:
        ax.text(0.5, 0.5, "no controlled vehicle", ha="center", va="center", transform=ax.transAxes)
    ax.set_xlabel("|path curvature| (1/m)")
    ax.set_ylabel("speed (m/s)")
    ax.set_title("Speed against curvature")
    files.append(save_figure(fig, out / "speed_vs_curvature.png", 110))

    if result.trajectories:
        vid, (traj, ref) = next(iter(result.trajectories.items()))
        fig, ax = plt.subplots(figsize=(7, 6))
        ax.plot(ref[:, 0], ref[:, 1], color="0.6", lw=3, label="lane centreline (reference)")
        ax.plot(traj[:, 1], traj[:, 2], color="tab:red", lw=1, label=f"{vid} (front bumper)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_title(f"Trajectory of {vid} against its lane")
        ax.legend(loc="best", fontsize=8)
        files.append(save_figure(fig, out / "trajectory.png", 110))
    return files


def plot_alpha(trace: Path, file: Path, most: int = 6) -> Path | None:
    """alpha(t) of the ``most`` controlled vehicles with the longest traces,
    when alpha changed during the run (``--alpha auto``); None otherwise (a
    fixed alpha is one number, in summary.json's config)."""
    import pandas as pd

    frame = pd.read_csv(trace, usecols=["t_s", "id", "alpha"])
    if frame.empty or frame["alpha"].nunique() < 2:
        file.unlink(missing_ok=True)
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    longest = frame["id"].value_counts().index[:most]
    fig, ax = plt.subplots(figsize=(8, 4))
    for vid in longest:
        sub = frame[frame["id"] == vid]
        ax.plot(sub["t_s"], sub["alpha"], lw=1, label=str(vid))
    ax.set_ylim(-0.05, 1.05)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("alpha (0 = rear axle, 1 = front axle)")
    ax.set_title(f"alpha(t) of the {len(longest)} longest-driven controlled vehicles")
    ax.legend(loc="best", fontsize=7, ncol=2)
    return save_figure(fig, file, 110)
