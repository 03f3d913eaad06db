"""Incidents judged by SUMO's own state on small synthetic networks: red-light
crossings read off SUMO's signal states (with the scenario's program, with a
light switched by another client, and with blendtrack's signal table
falsified, to show the check can fail), and collisions under every
``collision.action`` counted as SUMO's collision output has them."""

from __future__ import annotations

import csv
import math
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import pytest

from blendtrack import sumo
from blendtrack.sumo import report
from blendtrack.sumo.connection import sumo_binary
from blendtrack.sumo.runner import RunOptions, SumoRun

#: One signalised crossing: W -> E and S -> N, one lane each, 200 m arms,
#: a fixed-time program of 40 s cycles (netconvert's own phases, yellow
#: included).
NODES = """<nodes>
  <node id="W" x="-200" y="0"/><node id="E" x="200" y="0"/>
  <node id="S" x="0" y="-200"/><node id="N" x="0" y="200"/>
  <node id="J" x="0" y="0" type="traffic_light"/>
</nodes>"""
EDGES = """<edges>
  <edge id="WJ" from="W" to="J" numLanes="1" speed="13.89"/><edge id="JE" from="J" to="E" numLanes="1" speed="13.89"/>
  <edge id="SJ" from="S" to="J" numLanes="1" speed="13.89"/><edge id="JN" from="J" to="N" numLanes="1" speed="13.89"/>
</edges>"""
VTYPES = """  <vType id="auto" length="4.5" minGap="2.5" accel="2.6" decel="4.5" emergencyDecel="9.0" sigma="0"/>
  <vType id="human" length="4.5" minGap="2.5" accel="2.6" decel="4.5" emergencyDecel="9.0"/>
"""
FLOWS = """<routes>
""" + VTYPES + """  <route id="we" edges="WJ JE"/><route id="sn" edges="SJ JN"/>
  <flow id="we" type="auto" route="we" begin="0" end="120" period="8" departSpeed="max"/>
  <flow id="sn" type="auto" route="sn" begin="0" end="120" period="10" departSpeed="max"/>
</routes>"""
#: Two vehicles on W -> E: the background vehicle "b" ahead, the controlled "c" behind.
PAIR = """<routes>
""" + VTYPES + """  <route id="we" edges="WJ JE"/>
  <vehicle id="b" type="human" route="we" depart="0" departPos="120" departSpeed="0"/>
  <vehicle id="c" type="auto" route="we" depart="0" departPos="20" departSpeed="5"/>
</routes>"""


@pytest.fixture(scope="module")
def net(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("crossing")
    (d / "x.nod.xml").write_text(NODES)
    (d / "x.edg.xml").write_text(EDGES)
    netconvert = str(Path(sumo_binary()).with_name("netconvert"))
    subprocess.run([netconvert, "-n", str(d / "x.nod.xml"), "-e", str(d / "x.edg.xml"), "-o", str(d / "x.net.xml"),
                    "--tls.cycle.time", "40", "--no-turnarounds", "true"], check=True, capture_output=True, timeout=120)
    return d / "x.net.xml"


def _scheduled(routes: str) -> int:
    """Departures the flows of ``routes`` schedule (begin + k period before end)."""
    n = 0
    for f in ET.fromstring(routes).iter("flow"):
        begin, end, period = (float(f.get(k, "nan")) for k in ("begin", "end", "period"))
        n += max(math.ceil((end - begin) / period - 1e-9), 0)
    return n


def _scenario(net: Path, folder: Path, routes: str, action: str = "teleport", junctions: bool = True, step: float = 0.1) -> sumo.Scenario:
    """The scenario; ``junctions`` False leaves SUMO's collision.check-junctions
    out of its configuration (as most published scenarios do)."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "x.rou.xml").write_text(routes)
    check = '<collision.check-junctions value="true"/>' if junctions else ""
    (folder / "x.sumocfg").write_text(f"""<configuration>
  <input><net-file value="{net}"/><route-files value="x.rou.xml"/></input>
  <time><begin value="0"/><step-length value="{step}"/></time>
  <processing><collision.action value="{action}"/>{check}</processing>
  <report><no-step-log value="true"/><no-warnings value="false"/></report>
</configuration>""")
    return sumo.resolve_scenario(folder / "x.sumocfg")


def _red_lights(out: Path) -> list[dict[str, str]]:
    with open(out / "red_lights.csv") as f:
        return list(csv.DictReader(f))


def test_controlled_vehicles_cross_no_red_light_by_sumos_state(net: Path, tmp_path: Path) -> None:
    """Every vehicle controlled on a signalised crossing for two cycles:
    SUMO's own signal state at each stop-line crossing is never red."""
    sc = _scenario(net, tmp_path / "sc", FLOWS)
    res = sumo.run_scenario(sc, RunOptions(controlled_fraction=1.0, end_s=150, progress=False), tmp_path / "o")
    s = res.summary
    assert s["red_light_crossings_sumo"] == 0, _red_lights(tmp_path / "o")
    # FLOWS schedule every departure by 120 s of the 150 (15 W -> E, 12
    # S -> N; a red of about 20 s queues at most 3 vehicles on a 200 m arm,
    # so none is held back).
    assert s["controlled_vehicles"] == _scheduled(FLOWS) == 27, s["controlled_vehicles"]
    # The check saw the crossings, one per vehicle through the junction: at
    # least every vehicle SUMO took out at its route's end (it crossed), at
    # most one per vehicle.
    arrived = sum(r.reason == "arrived" for r in res.records)
    assert 0 < arrived <= s["signal_crossings_checked"] <= s["controlled_vehicles"], (arrived, s["signal_crossings_checked"])
    assert all(row["state"] in "yY" or row["state_at_moves"] in "yY" for row in _red_lights(tmp_path / "o"))
    assert s["red_light_violations"] == 0 and s["collisions_all"] == 0


def test_the_plan_gets_the_state_a_light_will_have_while_sumo_moves(net: Path, tmp_path: Path) -> None:
    """At a 1 s step the moves pushed at t run in SUMO's step from t, under
    the state SUMO shows at t + 1: the state passed to the RouteFleet at t
    is that one (the light's fixed-time program switches at the start of
    the step), and no controlled vehicle crosses on red by SUMO's state."""
    sc = _scenario(net, tmp_path / "sc", FLOWS, step=1.0)
    run = SumoRun(sc, RunOptions(controlled_fraction=1.0, end_s=150, progress=False), tmp_path / "o")
    seen: list[tuple[float, str, str]] = []
    refresh = run.junctions.refresh_tls

    def record(t: float) -> None:
        refresh(t)
        seen.append((t, run.junctions.tls_state["J"], run.junctions.tls_coming["J"]))

    run.junctions.refresh_tls = record  # type: ignore[method-assign]
    res = run.run()
    assert len(seen) > 100
    switches = 0
    for (t0, now0, sent0), (t1, now1, _) in zip(seen, seen[1:]):
        assert t1 == t0 + 1.0
        assert sent0 == now1, (t0, now0, sent0, now1)
        switches += now1 != now0
    # Every switch of the program was passed on a step ahead of the state read.
    assert switches >= 8
    assert res.summary["red_light_crossings_sumo"] == 0, _red_lights(tmp_path / "o")
    assert res.summary["red_light_violations"] == 0


def _client_program(run: SumoRun, t: float) -> None:
    """Another client runs the light: W -> E green 0-14 s of each 30 s,
    yellow 14-18, red 18-30; S -> N the other way round. Set every step,
    as a client would, with setRedYellowGreenState."""
    tl = run.sumo.trafficlight
    links = tl.getControlledLinks("J")
    phase = t % 30.0
    we = "G" if phase < 14.0 else "y" if phase < 18.0 else "r"
    sn = "r" if phase < 15.0 else "G" if phase < 26.0 else "y" if phase < 30.0 else "r"
    state = "".join((we if ls and ls[0][0].startswith("WJ") else sn) for ls in links)
    if tl.getRedYellowGreenState("J") != state:
        tl.setRedYellowGreenState("J", state)


def test_a_light_switched_by_another_client_is_obeyed(net: Path, tmp_path: Path) -> None:
    sc = _scenario(net, tmp_path / "sc", FLOWS)
    run = SumoRun(sc, RunOptions(controlled_fraction=1.0, end_s=150, progress=False), tmp_path / "o")
    run.step_hooks.append(_client_program)
    res = run.run()
    s = res.summary
    assert s["red_light_crossings_sumo"] == 0, run.incidents.crossings
    # One check per vehicle through the junction: at least every vehicle SUMO
    # took out at its route's end, at most one per vehicle.
    arrived = sum(r.reason == "arrived" for r in res.records)
    assert 0 < arrived <= s["signal_crossings_checked"] <= s["controlled_vehicles"], (arrived, s["signal_crossings_checked"])


def test_a_falsified_signal_table_is_caught_by_sumos_state(net: Path, tmp_path: Path) -> None:
    """The check can fail: blendtrack's signal table told "green" every step
    (a table that misses switches), its vehicles drive through red, and
    SUMO's state says so while blendtrack's own count cannot."""
    sc = _scenario(net, tmp_path / "sc", FLOWS)
    run = SumoRun(sc, RunOptions(controlled_fraction=1.0, end_s=150, progress=False), tmp_path / "o")

    def green(r: SumoRun, t: float) -> None:
        n = len(r.sumo.trafficlight.getRedYellowGreenState("J"))
        r.junctions.refresh_tls = lambda t: None  # type: ignore[method-assign]
        if "J" in r.tracks.lights.ids:
            r.fleet.set_signal(r.tracks.lights.id("J"), "G" * n)

    run.step_hooks.append(green)
    s = run.run().summary
    assert s["red_light_crossings_sumo"] >= 1, s
    assert s["red_light_violations"] == 0, "blendtrack's own count reads the falsified table"
    rows = run.incidents.crossings
    assert all(tls == "J" and a in "ru" and b in "ru" for _, _, tls, _, a, b in rows if a in "ru" and b in "ru")


def _push_onto(run: SumoRun, t: float) -> None:
    """At 6 s the standing background vehicle "b" is moved onto the nose of
    the controlled "c" (its back 0.5 m behind c's front): c drives into it."""
    v = run.sumo.vehicle
    if t < 6.0 or getattr(run, "_pushed", False) or "c" not in run.active:
        return
    v.setSpeedMode("b", 0)
    v.moveTo("b", v.getLaneID("c"), v.getLanePosition("c") + 4.5 - 0.5)
    v.setSpeed("b", 0.0)
    run._pushed = True  # type: ignore[attr-defined]


@pytest.mark.parametrize("action", ["teleport", "warn", "remove", "none"])
def test_collisions_are_counted_as_sumo_records_them_under_every_action(net: Path, tmp_path: Path, action: str) -> None:
    sc = _scenario(net, tmp_path / "sc", PAIR, action)
    out = tmp_path / "o"
    run = SumoRun(sc, RunOptions(controlled_ids=("c",), end_s=20, progress=False), out)
    run.step_hooks.append(_push_onto)
    result = run.run()
    # What run_scenario streams as the vehicles finish; the collision count reads the ids from it.
    report.write_vehicles_csv(result.records, out / "vehicles.csv")
    sumo._count_collisions(result, out, run.remote_found)
    assert getattr(run, "_pushed", False)
    root = ET.parse(out / "sumo" / "collisions.xml").getroot()
    events: list[dict[str, Any]] = [c.attrib for c in root.iter("collision")]
    s = result.summary
    assert s["collisions_all"] == len(events)
    assert s["collisions_with_controlled"] == sum(1 for c in events if "c" in (c["collider"], c["victim"]))
    assert s["collision_action"] == action
    if action == "none":
        # SUMO 1.28 detects nothing under "none" (its collision output stays
        # empty): the summary says which action was in force.
        assert events == []
    else:
        # SUMO records the collision whatever it then does about it.
        assert len(events) >= 1 and s["collisions_with_controlled"] >= 1, events
    if action == "teleport":
        # The collider is teleported: counted as a collision and as a teleport.
        assert s["teleports_controlled"] >= 1


#: The controlled "c" on W -> E and the background "b" on S -> N, b still far from the junction.
CROSSING = """<routes>
""" + VTYPES + """  <route id="we" edges="WJ JE"/><route id="sn" edges="SJ JN"/>
  <vehicle id="c" type="auto" route="we" depart="0" departPos="150" departSpeed="5"/>
  <vehicle id="b" type="human" route="sn" depart="0" departPos="20" departSpeed="0"/>
</routes>"""


def _put_across(run: SumoRun, t: float) -> None:
    """Once c is inside the junction, b is moved onto its own way through
    the junction (the S -> N junction lane) with its body across c's: the
    two ways cross at right angles, so the shapes overlap in the junction,
    not along a lane."""
    v, lane = run.sumo.vehicle, run.sumo.lane
    if getattr(run, "_across", False) or "c" not in run.active or not v.getLaneID("c").startswith(":"):
        return
    via = next(link[4] for link in lane.getLinks("SJ_0") if link[0] == "JN_0")
    (x0, y0), *_ = lane.getShape(via)
    _, cy = v.getPosition("c")
    pos = min(max(cy - y0 + 2.0, 4.5), lane.getLength(via))
    v.setSpeedMode("b", 0)
    v.moveTo("b", via, pos)
    v.setSpeed("b", 0.0)
    run._across = True  # type: ignore[attr-defined]


@pytest.mark.parametrize("user_args", [(), ("--collision.check-junctions", "false")])
def test_a_collision_inside_a_junction_is_counted_where_the_scenario_does_not_ask(
        net: Path, tmp_path: Path, user_args: tuple[str, ...]) -> None:
    """SUMO checks collisions inside junctions only when told to; blendtrack
    tells it unless the scenario or the user says otherwise. Without it (the
    user's --sumo-args turn it off here) the same overlap goes uncounted."""
    sc = _scenario(net, tmp_path / "sc", CROSSING, "warn", junctions=False)
    out = tmp_path / "o"
    run = SumoRun(sc, RunOptions(controlled_ids=("c",), end_s=40, progress=False, sumo_args=user_args), out)
    cmd = run.conn.command()
    assert cmd.count("--collision.check-junctions") == 1, cmd
    assert cmd[cmd.index("--collision.check-junctions") + 1] == ("false" if user_args else "true"), cmd
    run.step_hooks.append(_put_across)
    result = run.run()
    report.write_vehicles_csv(result.records, out / "vehicles.csv")
    sumo._count_collisions(result, out, run.remote_found)
    assert getattr(run, "_across", False)
    with open(out / "collisions.csv") as f:
        rows = list(csv.DictReader(f))
    if user_args:
        assert result.summary["collisions_all"] == 0 and rows == []
    else:
        assert result.summary["collisions_with_controlled"] >= 1, rows
        assert {r["type"] for r in rows} == {"junction"} and all(r["controlled_involved"] == "1" for r in rows), rows


def test_the_scenarios_own_junction_check_is_not_overridden(net: Path, tmp_path: Path) -> None:
    sc = _scenario(net, tmp_path / "sc", CROSSING, junctions=True)
    cmd = SumoRun(sc, RunOptions(controlled_ids=("c",), end_s=1, progress=False), tmp_path / "o").conn.command()
    assert "--collision.check-junctions" not in cmd, cmd


@pytest.mark.parametrize("junctions", [False, True])
def test_the_plain_run_of_a_compare_checks_junctions_as_the_treatment_does(net: Path, tmp_path: Path, junctions: bool) -> None:
    """Both runs of a pair count collisions the same way: the baseline's
    command line takes the junction check exactly where the treatment's does."""
    from blendtrack.sumo.compare.runs import baseline_command

    sc = _scenario(net, tmp_path / "sc", CROSSING, junctions=junctions)
    treatment = SumoRun(sc, RunOptions(controlled_ids=("c",), end_s=1, progress=False), tmp_path / "o").conn.command()
    for args in ((), ("--collision.check-junctions", "false")):
        base = baseline_command(sc, 0, 1.0, tmp_path / "b", args)
        flag = [base[i + 1] for i, a in enumerate(base) if a == "--collision.check-junctions"]
        if args:
            assert flag == ["false"], base
        else:
            assert flag == ([] if junctions else ["true"]), base
            assert ("--collision.check-junctions" in treatment) == (not junctions)


def test_emergency_brakings_are_counted_by_sumos_rule(net: Path, tmp_path: Path) -> None:
    """Under collision.action none the controlled "c" brakes as hard as it
    can once "b" stands on its nose: SUMO warns of emergency braking (decel
    at emergencyDecel 9 against decel 4.5) and the count has every step SUMO
    warned of (SUMO's speeds differ from the pushed ones by rounding at the
    boundary of 9.0 m/s^2, so it may have more)."""
    import re

    sc = _scenario(net, tmp_path / "sc", PAIR, "none")
    out = tmp_path / "o"
    run = SumoRun(sc, RunOptions(controlled_ids=("c",), end_s=20, progress=False), out)
    run.step_hooks.append(_push_onto)
    result = run.run()
    warned = re.findall(r"Vehicle 'c' performs emergency braking", (out / "sumo" / "sumo.log").read_text())
    assert warned, "SUMO warned"
    rec = {r.vid: r for r in result.records}["c"]
    assert rec.emergency_brakings >= len(warned) and result.summary["emergency_brakings"] == rec.emergency_brakings
