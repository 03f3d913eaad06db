"""What a SUMO run keeps: per-vehicle records (``vehicles.csv``, written as
vehicles finish), their running totals for the summary, the run's result,
and the per-step trace of the controlled vehicles (``trace.csv``)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

#: trace.csv's columns; the RouteFleet step outputs they come from are TRACE_KEYS.
TRACE_COLUMNS = ("t_s", "id", "x_m", "y_m", "theta_rad", "v_mps", "delta_rad", "alpha", "lateral_error_m", "heading_error_rad", "s_m", "curvature_per_m", "accel_mps2", "virtual_obstacle_m", "edge", "lane_index")
TRACE_KEYS = ("x_m", "y_m", "theta_rad", "v_mps", "delta_rad", "alpha", "lateral_error_m", "heading_error_rad", "s_rear_m", "curvature_per_m", "accel_mps2", "virtual_obstacle_m")


@dataclass
class VehicleRecord:
    """Per-vehicle accumulators for ``vehicles.csv``."""

    vid: str
    vtype: str
    depart_s: float
    end_s: float = math.nan
    reason: str = "running"
    steps: int = 0
    sum_abs_e: float = 0.0
    sum_e2: float = 0.0
    max_abs_e: float = 0.0
    #: |lateral error| sums at the rear and the front axle (the same points for every alpha).
    sum_abs_e_rear: float = 0.0
    sum_abs_e_front: float = 0.0
    sum_eth2: float = 0.0
    sum_v: float = 0.0
    max_lat_acc: float = 0.0
    sum_jerk2: float = 0.0
    jerk_n: int = 0
    last_acc: float = math.nan
    distance_m: float = 0.0
    collisions: int = 0
    teleports: int = 0
    red_light_violations: int = 0
    speed_warnings: int = 0
    reverse_warnings: int = 0
    time_above_comfort_s: float = 0.0
    lane_changes: int = 0
    #: Lane changes its route needed that it gave up, rerouted from the
    #: lane's end (``RunOptions.miss_exit_after_s``): it did not reach its
    #: own destination, whatever SUMO's trip info says of its arrival.
    missed_exits: int = 0
    #: SUMO stops served, and skipped with their reasons (";"-joined; see blendtrack.sumo.stops).
    stops_served: int = 0
    stops_skipped: int = 0
    stop_skip_reasons: str = ""
    #: Stop lines crossed on red by SUMO's own signal state, and steps of
    #: braking SUMO would warn of (blendtrack.sumo.incidents).
    red_light_crossings_sumo: int = 0
    emergency_brakings: int = 0


@dataclass
class RecordTotals:
    """Running sums over the records of the vehicles that finished: what the
    summary needs of them, so a record can go (to ``vehicles.csv``) as soon
    as its vehicle finishes."""

    vehicles: int = 0
    collisions: int = 0
    teleports: int = 0
    red_light_violations: int = 0
    speed_warnings: int = 0
    reverse_warnings: int = 0
    #: Control steps and the sum of |lateral error| over them (a run's mean |e|).
    steps: int = 0
    sum_abs_e: float = 0.0

    def add(self, r: VehicleRecord) -> None:
        self.vehicles += 1
        self.collisions += r.collisions
        self.teleports += r.teleports
        self.red_light_violations += r.red_light_violations
        self.speed_warnings += r.speed_warnings
        self.reverse_warnings += r.reverse_warnings
        self.steps += r.steps
        self.sum_abs_e += r.sum_abs_e


class SampleHistograms:
    """Fixed-bin histograms of the controlled vehicles' samples, for the
    plots: |lateral error| (0.01 m bins to 2 m, the last bin holding all
    beyond) and speed against |curvature| (0.001 1/m by 0.5 m/s bins to
    0.2 1/m and 40 m/s, clipped into the last bins). Their memory is fixed
    whatever the run's length: the samples are folded in and dropped."""

    ERROR_EDGES = np.linspace(0.0, 2.0, 201)
    CURVATURE_EDGES = np.linspace(0.0, 0.2, 201)
    SPEED_EDGES = np.linspace(0.0, 40.0, 81)

    def __init__(self) -> None:
        self.error_counts = np.zeros(len(self.ERROR_EDGES) - 1, dtype=np.int64)
        self.speed_curvature_counts = np.zeros((len(self.CURVATURE_EDGES) - 1, len(self.SPEED_EDGES) - 1), dtype=np.int64)
        self.n = 0

    def add(self, samples: Any) -> None:
        """Folds in ``(|curvature|, speed, |lateral error|, lateral acceleration)`` rows."""
        a = np.asarray(samples, dtype=float).reshape(-1, 4)
        a = a[np.isfinite(a[:, :3]).all(axis=1)]
        if not len(a):
            return
        self.n += len(a)
        e = np.clip(np.abs(a[:, 2]), 0.0, self.ERROR_EDGES[-1] - 1e-12)
        self.error_counts += np.histogram(e, self.ERROR_EDGES)[0]
        k = np.clip(np.abs(a[:, 0]), 0.0, self.CURVATURE_EDGES[-1] - 1e-12)
        v = np.clip(np.abs(a[:, 1]), 0.0, self.SPEED_EDGES[-1] - 1e-12)
        self.speed_curvature_counts += np.histogram2d(k, v, [self.CURVATURE_EDGES, self.SPEED_EDGES])[0].astype(np.int64)


@dataclass
class RunResult:
    #: Every controlled vehicle's record, in the order they were taken over;
    #: empty unless ``RunOptions.keep_records`` (``vehicles.csv`` has them all).
    records: list[VehicleRecord]
    summary: dict[str, Any]
    #: vid -> (trajectory rows (t, x, y, v, e, kappa), its reference points).
    trajectories: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    #: Histograms of the samples of (|curvature|, speed, |lateral error|) of controlled vehicles.
    histograms: SampleHistograms = field(default_factory=SampleHistograms)
    #: Running sums over all the records (kept or not).
    totals: RecordTotals = field(default_factory=RecordTotals)


class Trace:
    """The per-step trace of every controlled vehicle (``RunOptions.trace``):
    kept in memory, or written as it comes once :meth:`stream` has opened a
    file (a long run's memory stays flat)."""

    def __init__(self) -> None:
        self.rows: list[tuple[Any, ...]] = []
        self._file: Any = None
        self._csv: Any = None

    def stream(self, file: Path) -> None:
        """Writes the rows to ``file`` from now on (the header at once), none kept."""
        import csv

        self._file = open(file, "w", newline="")
        self._csv = csv.writer(self._file)
        self._csv.writerow(TRACE_COLUMNS)

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = self._csv = None

    def add(self, t: float, ids: list[str], out: dict[str, np.ndarray], edge_names: list[str]) -> None:
        """This step's rows, from ``RouteFleet.step``'s output ``out`` (in the order of ``ids``)."""
        cols = [out[k].tolist() for k in TRACE_KEYS]
        edges = [edge_names[e] for e in out["edge"].tolist()]
        rows = [(t, *row) for row in zip(ids, *cols, edges, out["lane_index"].tolist())]
        if self._csv is not None:
            self._csv.writerows(rows)
        else:
            self.rows.extend(rows)

    def write(self, file: Path) -> None:
        import csv

        with open(file, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(TRACE_COLUMNS)
            w.writerows(self.rows)
