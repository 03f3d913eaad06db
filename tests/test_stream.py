"""vehicles.csv written as vehicles finish (issue 22): the streamed rows are
the rows of the records, a killed run keeps the rows of the vehicles that
finished and its folder says INCOMPLETE."""

from __future__ import annotations

import csv
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from blendtrack import sumo
from blendtrack.sumo.report import EXTRA_COLUMNS, VEHICLE_COLUMNS, vehicle_row

ROOT = Path(__file__).resolve().parents[1]
GRID = ROOT / "sumo_scenarios" / "urban_grid"
COLUMNS = [*VEHICLE_COLUMNS, *EXTRA_COLUMNS]


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        assert reader.fieldnames == COLUMNS
        return list(reader)


def _csv_text(value: object) -> str:
    """What csv.DictWriter writes for a value of ``vehicle_row`` (NaN: empty)."""
    if isinstance(value, float) and not math.isfinite(value):
        return ""
    return str(value)


def test_streamed_rows_are_the_records_rows_and_the_summary_their_sums(tmp_path: Path) -> None:
    # The urban grid, every vehicle controlled, 150 s: the first vehicles
    # finish after about 47 s, so the file holds finished vehicles and (at the
    # end) ones still driving.
    out = tmp_path / "o"
    result = sumo.run_scenario(
        sumo.resolve_scenario(str(GRID)),
        sumo.RunOptions(controlled_fraction=1.0, end_s=150.0, progress=False, sumo_args=("--no-warnings", "true")),
        out,
    )
    rows = _rows(out / "vehicles.csv")
    kept = {r.vid: {k: _csv_text(v) for k, v in vehicle_row(r).items()} for r in result.records}
    assert len(rows) == len(kept) == result.summary["controlled_vehicles"]
    assert {row["id"]: row for row in rows} == kept
    reasons = [row["end_reason"] for row in rows]
    assert "arrived" in reasons and "end" in reasons
    # Finish order: every vehicle still driving at the end comes after all that finished before.
    first_end = reasons.index("end")
    assert all(r == "end" for r in reasons[first_end:])
    assert [float(row["end_s"]) for row in rows] == sorted(float(row["end_s"]) for row in rows)
    # The summary's sums (running totals) against the records'.
    s = result.summary
    for key in ("teleports", "red_light_violations", "speed_warnings", "reverse_warnings"):
        assert s[key] == sum(getattr(r, key) for r in result.records), key
    assert s["controlled_vehicles_in_collisions"] == sum(r.collisions for r in result.records)
    assert result.totals.steps == sum(r.steps for r in result.records) > 0
    assert result.totals.sum_abs_e == pytest.approx(sum(r.sum_abs_e for r in result.records), rel=1e-12)


def test_records_are_not_kept_without_keep_records(tmp_path: Path) -> None:
    out = tmp_path / "o"
    result = sumo.run_scenario(
        sumo.resolve_scenario(str(GRID)),
        sumo.RunOptions(controlled_fraction=1.0, end_s=80.0, progress=False, keep_records=False,
                        sumo_args=("--no-warnings", "true")),
        out,
    )
    rows = _rows(out / "vehicles.csv")
    assert result.records == [] and len(rows) == result.summary["controlled_vehicles"] == result.totals.vehicles > 0
    assert not (out / "INCOMPLETE").exists()


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL], ids=["SIGTERM", "SIGKILL"])
def test_a_killed_run_keeps_the_finished_rows_and_says_incomplete(tmp_path: Path, sig: signal.Signals) -> None:
    out = tmp_path / "o"
    cmd = [sys.executable, "-m", "blendtrack.cli", "sumo", "run", str(GRID), "--controlled-fraction", "1", "--end", "3600",
           "--quiet", "--sumo-args", "--no-warnings true", "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    csv_file = out / "vehicles.csv"
    # A guard against a hung child, not a timing assertion: the first rows
    # come after ~47 simulated s, seconds of wall time even on a loaded machine.
    deadline = time.monotonic() + 600
    try:
        while not (csv_file.exists() and csv_file.read_text().count("\n") >= 4):
            assert proc.poll() is None, f"the run ended before any vehicle finished: {proc.communicate()}"
            assert time.monotonic() < deadline, "no vehicle finished within 600 s of wall time"
            time.sleep(0.2)
        os.kill(proc.pid, sig)
        _, err = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    if sig == signal.SIGTERM:
        assert proc.returncode == 130 and "interrupted" in err, err
    else:
        assert proc.returncode == -signal.SIGKILL
    rows = _rows(csv_file)
    assert len(rows) >= 3
    for row in rows:
        # Only vehicles that finished: none written as still driving at an end.
        assert row["end_reason"] not in ("", "end", "running"), row
        depart, end = float(row["depart_s"]), float(row["end_s"])
        assert 0.0 <= depart <= end < 3600.0
        assert float(row["travel_time_s"]) == pytest.approx(end - depart)
        assert int(row["steps"]) >= 0 and float(row["distance_m"]) >= 0.0
    assert len({row["id"] for row in rows}) == len(rows)
    assert (out / "INCOMPLETE").is_file()
    assert not (out / "summary.json").exists()


#: Run in a fresh process (libsumo: one simulation per process): the urban
#: grid, every vehicle controlled, no records kept; every 20 simulated s the
#: VehicleRecord objects alive are counted (after a full collection) beside
#: the vehicles driving and those finished.
_COUNT_RECORDS = r"""
import gc, json, sys
from blendtrack import sumo
from blendtrack.sumo.records import VehicleRecord
samples = []
arrived = set()
def hook(run, t):
    if round(t * 10) % 200 == 0:
        gc.collect()
        alive = sum(isinstance(o, VehicleRecord) for o in gc.get_objects())
        samples.append((alive, len(run.active), run.vehicles.totals.vehicles, len(arrived)))
    # SUMO's arrivals, counted after the sample: this step's are dropped
    # after the hooks.
    arrived.update(run.sumo.simulation.getArrivedIDList())
opts = sumo.RunOptions(controlled_fraction=1.0, end_s=200.0, progress=False, keep_records=False,
                       sumo_args=("--no-warnings", "true"))
run = sumo.SumoRun(sumo.resolve_scenario(sys.argv[1]), opts, None)
run.step_hooks.append(hook)
run.run()
print(json.dumps(samples))
"""


def test_a_finished_vehicles_record_is_freed() -> None:
    # What a run keeps of a vehicle that left is bounded: the records alive
    # are exactly those of the vehicles still driving (hooks run before the
    # step's arrivals are dropped, so each driving vehicle has one), however
    # many finished before.
    import json

    p = subprocess.run([sys.executable, "-c", _COUNT_RECORDS, str(GRID)], capture_output=True, text=True, timeout=900)
    assert p.returncode == 0, p.stderr
    samples = json.loads(p.stdout.strip().splitlines()[-1])
    assert len(samples) == 10
    assert all(alive == driving for alive, driving, _, _ in samples), samples
    # Vehicles finished, their records gone: at least every vehicle SUMO
    # took out at its route's end before the sample (all are controlled).
    assert all(finished >= sumo_arrived for _, _, finished, sumo_arrived in samples), samples
    assert samples[-1][3] > 0, samples
