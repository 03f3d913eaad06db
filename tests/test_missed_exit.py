"""A lane change the route needs that never finds room (issue 18, part 2):
with ``RunOptions.miss_exit_after_s`` the controlled vehicle gives the exit
up after standing that long at its lane's end and drives on, rerouted; with
0 it waits, as SUMO's drivers do. A synthetic three-lane road whose exit
leaves from the left lane, which a parked vehicle covers to its end, so
the change over two lanes from the right lane never has room."""

from __future__ import annotations

import csv
import json
import math
import subprocess
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
import sumolib

from blendtrack import sumo
from blendtrack.sumo.connection import sumo_binary
from blendtrack.sumo.lanechange import MISS_EXIT_NEAR_END_M, MISS_EXIT_SPEED_MPS, LaneChanges, out_of_network
from blendtrack.sumo.runner import RunOptions
from blendtrack.sumo.scenario import ScenarioError

END_S = 120


def _scenario(tmp_path: Path) -> Path:
    d = tmp_path / "net"
    d.mkdir()
    (d / "n.nod.xml").write_text(
        '<nodes><node id="a" x="-400" y="0"/><node id="m" x="0" y="0" type="priority"/>'
        '<node id="e" x="400" y="0"/><node id="x" x="300" y="120"/></nodes>'
    )
    (d / "n.edg.xml").write_text(
        '<edges><edge id="in" from="a" to="m" numLanes="3" speed="20"/><edge id="out" from="m" to="e" numLanes="2" speed="20"/>'
        '<edge id="ramp" from="m" to="x" numLanes="1" speed="20"/></edges>'
    )
    # The right two lanes go on along the road, only the left one to the ramp.
    (d / "n.con.xml").write_text(
        '<connections><connection from="in" to="out" fromLane="0" toLane="0"/><connection from="in" to="out" fromLane="1" toLane="1"/>'
        '<connection from="in" to="ramp" fromLane="2" toLane="0"/></connections>'
    )
    netconvert = str(Path(sumo_binary(False)).with_name("netconvert"))
    subprocess.run([netconvert, "-n", "n.nod.xml", "-e", "n.edg.xml", "-x", "n.con.xml", "-o", "n.net.xml", "--no-turnarounds",
                    "--no-warnings"], cwd=d, check=True, capture_output=True)
    # The left lane is covered from 20 m to its end by one vehicle 370 m
    # long (a line of parked cars, as far as the room check goes), parked
    # for the whole run; the exiting car departs on the right lane, two
    # lanes from the ramp, and the middle lane is empty.
    (d / "n.rou.xml").write_text(
        '<routes><vType id="car" accel="2.6" decel="4.5" sigma="0" length="5" minGap="2.5" maxSpeed="20"/>'
        '<vType id="long" accel="2.6" decel="4.5" sigma="0" length="370" minGap="2.5" maxSpeed="20"/>'
        '<vehicle id="parked" type="long" depart="0" departLane="2" departPos="390" departSpeed="0"><route edges="in ramp"/>'
        '<stop lane="in_2" endPos="391" duration="10000"/></vehicle>'
        '<vehicle id="exiting" type="car" depart="1" departLane="0" departSpeed="max"><route edges="in ramp"/></vehicle></routes>'
    )
    (d / "n.sumocfg").write_text(
        '<configuration><input><net-file value="n.net.xml"/><route-files value="n.rou.xml"/></input></configuration>'
    )
    return d / "n.sumocfg"


def _run(cfg: Path, out: Path, after: float) -> tuple[dict[str, Any], dict[str, str], float]:
    """(summary, the exiting car's vehicles.csv row, the time it stood < 0.5 m/s)."""
    out.mkdir()
    opts = RunOptions(controlled_ids=("exiting",), end_s=END_S, trace=True, progress=False, miss_exit_after_s=after,
                      sumo_args=("--no-warnings", "true", "--tripinfo-output", str(out / "tripinfo.xml")))
    sumo.run_scenario(sumo.resolve_scenario(cfg), opts, out)
    summary = json.loads((out / "summary.json").read_text())
    with open(out / "vehicles.csv") as f:
        row = next(r for r in csv.DictReader(f) if r["id"] == "exiting")
    with open(out / "trace.csv") as f:
        stood = sum(1.0 for r in csv.DictReader(f) if r["id"] == "exiting" and float(r["v_mps"]) < MISS_EXIT_SPEED_MPS)
    return summary, row, stood


def _arrived_on(tripinfo: Path, vid: str) -> str | None:
    for t in sumolib.xml.parse(str(tripinfo), "tripinfo"):
        if t.id == vid and float(t.arrival) >= 0:
            return str(t.arrivalLane)
    return None


def test_a_vehicle_that_never_finds_room_waits_by_default_and_drives_on_when_asked(tmp_path: Path) -> None:
    cfg = _scenario(tmp_path)
    summary, row, stood = _run(cfg, tmp_path / "wait", 0.0)
    # With 0 it waits at the end of its lane for the rest of the run.
    assert summary["missed_exits"] == 0 and row["missed_exits"] == "0"
    assert stood > END_S - 60, stood
    assert row["end_reason"] not in ("arrived",), row
    summary, row, stood = _run(cfg, tmp_path / "miss", 10.0)
    assert summary["missed_exits"] == 1 and row["missed_exits"] == "1"
    assert summary["collisions_all"] == 0 and summary["placement_faults"] == 0
    # It stood 10 s at the end (a step or two more while slowing to a stop), then drove out along the road.
    assert 10.0 <= stood <= 14.0, stood
    assert row["end_reason"] == "arrived", row
    # Out along the road (on its lane 0), not on the ramp it could not reach.
    assert _arrived_on(tmp_path / "miss" / "tripinfo.xml", "exiting") == "out_0"
    assert _arrived_on(tmp_path / "wait" / "tripinfo.xml", "exiting") is None


def test_miss_exit_after_must_be_a_finite_number_of_seconds_at_least_0() -> None:
    for bad in (-1.0, float("nan"), float("inf"), "10"):
        with pytest.raises(ScenarioError, match="miss exit after"):
            RunOptions(miss_exit_after_s=bad)  # type: ignore[arg-type]
    assert RunOptions(miss_exit_after_s=0.0).miss_exit_after_s == 0.0
    assert RunOptions().miss_exit_after_s == 20.0


def test_the_wait_counts_standing_near_the_end_only_and_starts_again_otherwise() -> None:
    """``stood_too_long``: the SUMO steps (1 s here) a vehicle has stood
    (under ``MISS_EXIT_SPEED_MPS``) within ``MISS_EXIT_NEAR_END_M`` of its
    lane's end add up to ``miss_exit_after_s``; moving or further back
    starts again; 0 never."""
    conn = SimpleNamespace(dt=1.0)
    lcs = LaneChanges(conn, None, None, {}, 4.0, miss_exit_after_s=3.0)  # type: ignore[arg-type]
    near, slow = MISS_EXIT_NEAR_END_M, MISS_EXIT_SPEED_MPS - 1e-9
    assert [lcs.stood_too_long("v", near, slow) for _ in range(3)] == [False, False, True]
    assert not lcs.stood_too_long("v", near, MISS_EXIT_SPEED_MPS), "moving: starts again"
    assert [lcs.stood_too_long("v", near, 0.0) for _ in range(3)] == [False, False, True]
    assert not lcs.stood_too_long("v", near + 1e-9, 0.0), "further back: starts again"
    assert not lcs.stood_too_long("v", 0.0, 0.0)
    lcs.drop("v")
    assert [lcs.stood_too_long("v", 0.0, 0.0) for _ in range(3)] == [False, False, True]
    never = LaneChanges(conn, None, None, {}, 4.0)  # type: ignore[arg-type]
    assert not any(never.stood_too_long("v", 0.0, 0.0) for _ in range(100))


def test_the_wait_starts_again_for_a_vehicle_with_no_change_due() -> None:
    """A wait counted at one lane's end does not carry over to the next
    change that comes due (a rebuilt track, say): ``make_due`` keeps the
    counts of the vehicles whose change is due this step only."""
    conn = SimpleNamespace(dt=1.0, sumo=SimpleNamespace(vehicle=None))
    tracks = SimpleNamespace(lanes=SimpleNamespace(name=str))
    lcs = LaneChanges(conn, None, tracks, {}, 4.0, miss_exit_after_s=3.0)  # type: ignore[arg-type]
    lcs.stood_too_long("due", 0.0, 0.0)
    lcs.stood_too_long("gone", 0.0, 0.0)
    lcs.due = [("due", 0, 0.0, 0.0)]  # not controlled here: nothing is tried
    lcs.make_due()
    assert lcs._stood == {"due": 1.0}
    assert [lcs.stood_too_long("gone", 0.0, 0.0) for _ in range(3)] == [False, False, True]


def test_out_of_the_network_along_the_widest_road(tmp_path: Path) -> None:
    net = sumolib.net.readNet(str(_scenario(tmp_path).with_name("n.net.xml")))
    # From "in" the road (2 lanes) is wider than the ramp (1); "out" leads nowhere.
    assert out_of_network(net.getEdge("in"), "passenger") == ["in", "out"]
    assert out_of_network(net.getEdge("ramp"), "passenger") == ["ramp"]
    assert out_of_network(net.getEdge("in"), "passenger", limit=1) == ["in"]


def test_compare_leaves_vehicles_that_missed_their_exit_out_of_the_throughput(tmp_path: Path) -> None:
    """``compare``'s throughput counts vehicles arrived at their own
    destination: one that missed its exit is read off ``vehicles.csv``."""
    from blendtrack.sumo.compare.metrics import read_vehicles

    assert read_vehicles(tmp_path / "none.csv") == ({}, set())
    f = tmp_path / "vehicles.csv"
    f.write_text("id,lateral_error_rms_m,missed_exits\na,0.1,0\nb,0.2,1\nc,,2\nd,0.3,\n")
    lat_err, missed = read_vehicles(f)
    assert missed == {"b", "c"}
    assert lat_err["a"] == 0.1 and lat_err["d"] == 0.3 and math.isnan(lat_err["c"])
    f.write_text("id,lateral_error_rms_m,lane_changes\na,0.1,1\n")  # a file from before the column
    assert read_vehicles(f) == ({"a": 0.1}, set())


def test_the_cli_and_the_sweeps_default_to_the_runs_own_wait() -> None:
    import argparse

    from blendtrack.batch.sweep import PARAMS
    from blendtrack.cli.sumo import _add_driving_options

    parser = argparse.ArgumentParser()
    _add_driving_options(parser)
    cli = next(a for a in parser._actions if a.dest == "miss_exit_after")
    assert cli.default == RunOptions.miss_exit_after_s
    assert "miss_exit_after_s" in PARAMS
    with pytest.raises(SystemExit):
        parser.parse_args(["--miss-exit-after", "-1"])
