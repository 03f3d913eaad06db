"""Controlled vehicles serve their SUMO ``<stop>``s (blendtrack.sumo.stops),
on a small two-lane road generated here: checked against SUMO's own word
(its stop-output and tripinfo), and against SUMO's own driver on the same
stops."""

from __future__ import annotations

import csv
import json
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from blendtrack import sumo
from blendtrack.sumo.connection import sumo_binary
from blendtrack.sumo.runner import RunOptions, SumoRun
from blendtrack.sumo.stops import Stops

# SUMO starts a stop once the front is within its tolerance of the end
# position and the vehicle at most at 0.1 m/s: 0.5 m for a stopping place
# (a bus stop), 0.2 m for a lane stop (its default start). blendtrack aims
# the halt 0.2 m short and the stopping law's creep carries the front 0.155
# to 0.207 m on (stops.AIM_SHORT_M): at rest it is within 0.05 m of the end,
# and SUMO may start the stop a little before that, within its tolerance.
BUS_STOP_TOL_M = 0.5
LANE_STOP_TOL_M = 0.2
PAST_END_M = 0.05
DT = 1.0

NODES = """<nodes>
  <node id="A" x="0" y="0"/><node id="B" x="300" y="0"/><node id="C" x="600" y="0"/>
</nodes>"""
EDGES = """<edges>
  <edge id="AB" from="A" to="B" numLanes="2" speed="13.89"/>
  <edge id="BC" from="B" to="C" numLanes="2" speed="13.89"/>
</edges>"""
ADDITIONAL = """<additional>
  <busStop id="bs" lane="AB_0" startPos="150" endPos="170"/>
  <parkingArea id="pa" lane="BC_1" startPos="100" endPos="140" roadsideCapacity="3"/>
</additional>"""
# "bus": the bus stop (10 s), a lane stop (5 s) and one until t = 90 s.
# "car": no stops. "odd": a stop on the lane beside its track (it changes
# lanes to serve it). "near": one on the lane beside, too close to reach (skipped).
# "park": a parking area (8 s). "trig": a stop waiting for a person who never comes.
ROUTES = """<routes>
  <vType id="bus" vClass="bus" length="12" minGap="3" accel="2.6" decel="4.5" sigma="0"/>
  <vType id="car" length="5" minGap="2.5" accel="2.6" decel="4.5" sigma="0"/>
  <vehicle id="{prefix}bus" type="bus" depart="0" departLane="0" departSpeed="max">
    <route edges="AB BC"/>
    <stop busStop="bs" duration="10"/>
    <stop lane="BC_0" endPos="150" duration="5"/>
    <stop lane="BC_0" endPos="250" until="90"/>
  </vehicle>
  <vehicle id="{prefix}car" type="car" depart="5" departLane="1" departSpeed="max"><route edges="AB BC"/></vehicle>
  <vehicle id="{prefix}odd" type="car" depart="8" departLane="1" departSpeed="max">
    <route edges="AB BC"/>
    <stop lane="AB_0" endPos="200" duration="5"/>
  </vehicle>
  <vehicle id="{prefix}park" type="car" depart="12" departLane="1" departSpeed="max">
    <route edges="AB BC"/>
    <stop parkingArea="pa" duration="8"/>
  </vehicle>
  <vehicle id="{prefix}trig" type="car" depart="20" departLane="1" departSpeed="max">
    <route edges="AB BC"/>
    <stop lane="AB_1" endPos="250" triggered="person" duration="3"/>
  </vehicle>
  <vehicle id="{prefix}near" type="car" depart="30" departLane="1" departSpeed="max">
    <route edges="AB BC"/>
    <stop lane="AB_0" endPos="15" duration="5"/>
  </vehicle>
</routes>"""


def _scenario(folder: Path, prefix: str) -> Path:
    """The road, its bus stop and the three vehicles (ids prefixed ``prefix``); the .sumocfg."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "n.nod.xml").write_text(NODES)
    (folder / "n.edg.xml").write_text(EDGES)
    netconvert = Path(sumo_binary()).with_name("netconvert")
    subprocess.run(
        [str(netconvert), "-n", "n.nod.xml", "-e", "n.edg.xml", "-o", "n.net.xml", "--no-turnarounds"],
        cwd=folder, check=True, capture_output=True,
    )
    (folder / "s.add.xml").write_text(ADDITIONAL)
    (folder / "r.rou.xml").write_text(ROUTES.format(prefix=prefix))
    cfg = folder / "stops.sumocfg"
    cfg.write_text(
        '<configuration><input><net-file value="n.net.xml"/><route-files value="r.rou.xml"/>'
        f'<additional-files value="s.add.xml"/></input><time><step-length value="{DT}"/></time></configuration>'
    )
    return cfg


def _stopinfos(path: Path) -> dict[str, list[dict[str, str]]]:
    out: dict[str, list[dict[str, str]]] = {}
    for s in ET.parse(path).getroot().iter("stopinfo"):
        out.setdefault(s.get("id", ""), []).append(dict(s.attrib))
    return out


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The same road run twice: every vehicle controlled, then none (SUMO's own drivers)."""
    base = tmp_path_factory.mktemp("stops")
    outs = []
    for name, fraction in (("ctrl", 1.0), ("plain", 0.0)):
        cfg = _scenario(base / f"sc_{name}", "")
        out = base / name
        stop_out = out / "stopout.xml"
        out.mkdir()
        sc = sumo.resolve_scenario(str(cfg))
        run_opts = RunOptions(end_s=200, progress=False, sumo_args=("--stop-output", str(stop_out)), controlled_fraction=fraction)
        sumo.run_scenario(sc, run_opts, out)
        outs.append(out)
    return outs[0], outs[1]


def _vehicles(out: Path) -> dict[str, dict[str, str]]:
    with open(out / "vehicles.csv") as f:
        return {r["id"]: r for r in csv.DictReader(f)}


def test_a_controlled_bus_serves_its_stops_where_and_as_long_as_sumo_says(runs: tuple[Path, Path]) -> None:
    ctrl, plain = runs
    mine, sumos = _stopinfos(ctrl / "stopout.xml"), _stopinfos(plain / "stopout.xml")
    assert [s.get("busStop", s["lane"]) for s in mine["bus"]] == ["bs", "BC_0", "BC_0"]
    assert [s.get("busStop", s["lane"]) for s in sumos["bus"]] == ["bs", "BC_0", "BC_0"]
    ends = (170.0, 150.0, 250.0)
    tols = (BUS_STOP_TOL_M, LANE_STOP_TOL_M, LANE_STOP_TOL_M)
    for s, end, tol, theirs in zip(mine["bus"], ends, tols, sumos["bus"]):
        pos = float(s["pos"])
        assert end - tol <= pos <= end + PAST_END_M, f"front at {pos}, stop ends at {end}"
        # SUMO's own driver stands within the same tolerance of the end.
        assert end - tol <= float(theirs["pos"]) <= end + PAST_END_M
    dwell = [float(s["ended"]) - float(s["started"]) for s in mine["bus"]]
    assert abs(dwell[0] - 10.0) <= DT and abs(dwell[1] - 5.0) <= DT, dwell
    assert abs(float(mine["bus"][2]["ended"]) - 90.0) <= DT, "left at until"
    assert float(mine["bus"][2]["started"]) < 90.0 - 5.0, "reached well before until"
    rows = _vehicles(ctrl)
    bus = rows["bus"]
    assert (bus["stops_served"], bus["stops_skipped"], bus["end_reason"]) == ("3", "0", "arrived")
    assert int(bus["collisions"]) == 0 and int(bus["teleports"]) == 0
    summary = json.loads((ctrl / "summary.json").read_text())
    assert summary["stops_served"] == 3 + 1 + 1 and summary["stops_skipped"] == 1 and summary["stop_lane_changes"] == 1
    assert summary["collisions"] == 0


def test_a_stop_on_the_lane_beside_is_reached_by_a_lane_change(runs: tuple[Path, Path]) -> None:
    """"odd" keeps lane 1 where the route needs no change; its stop is on
    lane 0 of the same edge: on that edge it changes lanes towards the stop,
    as SUMO's own driver does, and serves it where SUMO's driver does."""
    ctrl, plain = runs
    odd = _vehicles(ctrl)["odd"]
    assert (odd["stops_served"], odd["stops_skipped"], odd["end_reason"]) == ("1", "0", "arrived")
    mine, sumos = _stopinfos(ctrl / "stopout.xml")["odd"], _stopinfos(plain / "stopout.xml")["odd"]
    assert [s["lane"] for s in mine] == [s["lane"] for s in sumos] == ["AB_0"]
    assert 200.0 - LANE_STOP_TOL_M <= float(mine[0]["pos"]) <= 200.0 + PAST_END_M
    assert abs(float(mine[0]["ended"]) - float(mine[0]["started"]) - 5.0) <= DT
    assert int(odd["collisions"]) == 0


def test_a_stop_off_the_track_is_skipped_and_does_not_hold_the_vehicle(runs: tuple[Path, Path]) -> None:
    ctrl, plain = runs
    near = _vehicles(ctrl)["near"]
    # Its stop, on lane 0, ends 15 m into the edge it departs on lane 1:
    # no room to change lanes before it. It is skipped and removed from
    # SUMO's schedule, so SUMO neither serves it nor holds the vehicle at
    # the lane's end.
    assert (near["stops_served"], near["stops_skipped"], near["stop_skip_reasons"]) == ("0", "1", "off_track")
    assert near["end_reason"] == "arrived"
    assert "near" not in _stopinfos(ctrl / "stopout.xml")
    # Through at free speed: 600 m at the 13.89 m/s limit (a vehicle held at
    # the end of lane AB for a stop would take far longer).
    assert float(near["travel_time_s"]) < 600.0 / 13.89 + 5.0


def test_a_vehicle_without_stops_is_never_looked_at_again(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # Only the stopless car is controlled: the stop module reads SUMO's stops
    # once at the take-over and never again, so its driving is what it was
    # without stops (the behaviour snapshot checks the bytes).
    cfg = _scenario(tmp_path / "sc", "")
    calls: list[str] = []

    def update(self: Stops) -> None:
        calls.append("update")

    monkeypatch.setattr(Stops, "update", update)
    sc = sumo.resolve_scenario(str(cfg))
    run = SumoRun(sc, RunOptions(end_s=100, progress=False, controlled_ids=("car",)), None)
    result = run.run()
    (rec,) = result.records
    assert rec.vid == "car" and rec.reason == "arrived"
    assert (rec.stops_served, rec.stops_skipped) == (0, 0)
    assert calls == [] and not run.stops.pending


def test_a_parking_area_is_served_and_an_unmet_trigger_holds_as_in_sumo(runs: tuple[Path, Path]) -> None:
    ctrl, plain = runs
    mine, sumos = _stopinfos(ctrl / "stopout.xml"), _stopinfos(plain / "stopout.xml")
    (park,) = mine["park"]
    assert (park["lane"], park.get("parkingArea"), park["parking"]) == ("BC_1", "pa", "1")
    # SUMO's own driver halts at the lot it picks inside the area; the
    # controlled one at the area's end, which SUMO accepts as well.
    assert 100.0 <= float(park["pos"]) <= 140.0 + PAST_END_M
    assert abs(float(park["ended"]) - float(park["started"]) - 8.0) <= DT
    rows = _vehicles(ctrl)
    assert (rows["park"]["stops_served"], rows["park"]["end_reason"]) == ("1", "arrived")
    # Nobody boards "trig": SUMO holds it at its stop for good, its own driver
    # as well as the controlled one (no stop ends, neither arrives).
    assert "trig" not in mine and "trig" not in sumos
    trig = rows["trig"]
    assert (trig["end_reason"], trig["stops_served"], trig["stops_skipped"]) == ("end", "0", "0")
    arrived = {t.get("id") for t in ET.parse(ctrl / "sumo" / "tripinfo.xml").getroot().iter("tripinfo")}
    assert "trig" not in arrived and {"bus", "car", "odd", "park"} <= arrived


QUEUE_ADDITIONAL = """<additional>
  <busStop id="bs" lane="AB_0" startPos="110" endPos="170"/>
</additional>"""
# Two buses at one bus stop: "first" halts at its end for 10 s, "second"
# behind it (SUMO starts its stop there, short of the end) for 30 s, so it
# still dwells after "first" has left; a car follows on the same lane.
QUEUE_ROUTES = """<routes>
  <vType id="bus" vClass="bus" length="12" minGap="3" accel="2.6" decel="4.5" sigma="0"/>
  <vType id="car" length="5" minGap="2.5" accel="2.6" decel="4.5" sigma="0"/>
  <vehicle id="first" type="bus" depart="0" departLane="0" departSpeed="max">
    <route edges="AB BC"/><stop busStop="bs" duration="10"/>
  </vehicle>
  <vehicle id="second" type="bus" depart="3" departLane="0" departSpeed="max">
    <route edges="AB BC"/><stop busStop="bs" duration="30"/>
  </vehicle>
  <vehicle id="car" type="car" depart="25" departLane="0" departSpeed="max"><route edges="AB BC"/></vehicle>
</routes>"""


def test_a_bus_dwelling_short_of_the_stop_end_stands_where_sumo_holds_it(tmp_path: Path) -> None:
    folder = tmp_path / "queue"
    cfg = _scenario(folder, "")
    (folder / "s.add.xml").write_text(QUEUE_ADDITIONAL)
    (folder / "r.rou.xml").write_text(QUEUE_ROUTES)
    stop_out = tmp_path / "stopout.xml"
    run = SumoRun(sumo.resolve_scenario(str(cfg)),
                  RunOptions(end_s=120, progress=False, controlled_fraction=1.0, sumo_args=("--stop-output", str(stop_out))),
                  tmp_path / "o")
    # While SUMO has "second" stopped: blendtrack's front against SUMO's,
    # and whether "first" has left the bus stop's lane by then.
    seen = {"worst_m": 0.0, "dwell_steps_after_first_left": 0}

    def watch(r: SumoRun, t: float) -> None:
        v = r.conn.sumo.vehicle
        act = r.active.get("second")
        if act is None or "second" not in v.getIDList() or not v.isStopped("second"):
            return
        lane, pos = r.fleet.front_lane_position(act.slot)
        assert r.tracks.lanes.names[lane] == v.getLaneID("second")
        seen["worst_m"] = max(seen["worst_m"], abs(pos - float(v.getLanePosition("second"))))
        if "first" not in v.getIDList() or v.getLaneID("first") != "AB_0":
            seen["dwell_steps_after_first_left"] += 1

    run.step_hooks.append(watch)
    result = run.run()
    # At a standstill blendtrack's front and SUMO's agree (within the halt's creep).
    assert seen["worst_m"] < 0.3, f"blendtrack's front {seen['worst_m']:.2f} m from SUMO's while SUMO held the bus"
    stops = _stopinfos(stop_out)
    (first,), (second,) = stops["first"], stops["second"]
    # SUMO started "second"'s stop behind "first", well short of the end.
    assert float(second["pos"]) < 170.0 - 12.0
    assert abs(float(second["ended"]) - float(second["started"]) - 30.0) <= DT
    assert seen["dwell_steps_after_first_left"] >= 5, "the case: still dwelling after the bus ahead left"
    recs = {r.vid: r for r in result.records}
    assert {k: recs[k].collisions for k in recs} == {"first": 0, "second": 0, "car": 0}
    assert (recs["second"].stops_served, recs["second"].reason) == (1, "arrived")


def test_a_stop_just_past_a_junction_is_reached_by_the_connection_onto_its_lane(tmp_path: Path) -> None:
    """One lane ("AB") widens to two ("BC") at junction B, both lanes of BC
    reached from AB_0. "x0" stops 15 m into BC_0, "x1" 15 m into BC_1: no
    room to change lanes on BC first, so each track must take the connection
    onto its stop's lane at B (without that, the track takes one of the two
    connections for both, and the other vehicle's stop was skipped)."""
    folder = tmp_path / "sc"
    folder.mkdir()
    (folder / "n.nod.xml").write_text('<nodes><node id="A" x="0" y="0"/><node id="B" x="200" y="0"/>'
                                      '<node id="C" x="400" y="0"/></nodes>')
    (folder / "n.edg.xml").write_text('<edges><edge id="AB" from="A" to="B" numLanes="1" speed="13.89"/>'
                                      '<edge id="BC" from="B" to="C" numLanes="2" speed="13.89"/></edges>')
    netconvert = Path(sumo_binary()).with_name("netconvert")
    subprocess.run([str(netconvert), "-n", "n.nod.xml", "-e", "n.edg.xml", "-o", "n.net.xml", "--no-turnarounds"],
                   cwd=folder, check=True, capture_output=True)
    (folder / "r.rou.xml").write_text(
        '<routes><vType id="car" length="5" minGap="2.5" accel="2.6" decel="4.5" sigma="0"/>'
        '<vehicle id="x0" type="car" depart="0" departSpeed="max"><route edges="AB BC"/><stop lane="BC_0" endPos="15" duration="3"/></vehicle>'
        '<vehicle id="x1" type="car" depart="10" departSpeed="max"><route edges="AB BC"/><stop lane="BC_1" endPos="15" duration="3"/></vehicle>'
        '</routes>')
    cfg = folder / "s.sumocfg"
    cfg.write_text('<configuration><input><net-file value="n.net.xml"/><route-files value="r.rou.xml"/></input>'
                   f'<time><step-length value="{DT}"/></time></configuration>')
    out = tmp_path / "out"
    out.mkdir()
    stop_out = out / "stopout.xml"
    sumo.run_scenario(sumo.resolve_scenario(str(cfg)), RunOptions(end_s=120, progress=False, controlled_fraction=1.0,
                                                                  sumo_args=("--stop-output", str(stop_out))), out)
    rows = _vehicles(out)
    for vid, lane in (("x0", "BC_0"), ("x1", "BC_1")):
        assert (rows[vid]["stops_served"], rows[vid]["stops_skipped"], rows[vid]["end_reason"]) == ("1", "0", "arrived"), rows[vid]
        (st,) = _stopinfos(stop_out)[vid]
        assert st["lane"] == lane and 15.0 - LANE_STOP_TOL_M <= float(st["pos"]) <= 15.0 + PAST_END_M
