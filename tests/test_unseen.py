"""Scenarios nobody on this project wrote: the ones that ship with SUMO's own
tools (``$SUMO_HOME/tools/game``, in the eclipse-sumo wheel). Each found
something the shipped scenarios and the two public ones did not: an
``<edgeData>`` dump and ``<flow>``s without an end of their own (the load
check's ``--end 0`` made SUMO refuse six of them), times written as
``15:0:0``, and junctions of type ``unregulated`` (no right-of-way matrix:
sumolib's ``areFoes`` raised a ``KeyError``)."""

from __future__ import annotations

from pathlib import Path

import pytest
import sumolib.miscutils

from blendtrack.sumo import RunOptions, SumoRun, resolve_scenario
from blendtrack.sumo.compare import CompareOptions, selector
from blendtrack.sumo.preflight import check_selection
from blendtrack.sumo.scenario import ScenarioError
from blendtrack.sumo.network import Network
from blendtrack.sumo.sumocfg import sumo_seconds

GAME = Path(__import__("sumo").SUMO_HOME) / "tools" / "game"

needs_game = pytest.mark.skipif(not GAME.is_dir(), reason="the eclipse-sumo wheel has no tools/game")


@pytest.mark.parametrize("text", ["54000", "12.5", "15:0:0", "15:00:00", "1:00:00:30", "0:0:1.5"])
def test_times_are_read_as_sumo_reads_them(text: str) -> None:
    assert sumo_seconds(text) == sumolib.miscutils.parseTime(text)


@pytest.mark.parametrize("text", ["", "1:30", "x", "1:2:3:4:5"])
def test_a_time_sumo_would_not_read_is_refused(text: str) -> None:
    with pytest.raises(ValueError):
        sumo_seconds(text)


@needs_game
def test_times_written_as_hours_are_read_from_a_configuration() -> None:
    sc = resolve_scenario(GAME / "fokr_bs_demo.sumocfg")  # begin 15:0:0, end 16:0:0
    assert sc.end_s == 16 * 3600.0


@needs_game
@pytest.mark.parametrize("name", ["corridor", "cross"])
def test_scenarios_with_dumps_and_open_ended_flows_pass_the_load_check(
    name: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """corridor has flows that begin after 0 s with no end, cross an
    ``<edgeData>`` dump with none: both take the run's end, and SUMO refused
    both when the check ran with ``--end 0``; it now runs the run's window."""
    monkeypatch.setenv("BLENDTRACK_CACHE_DIR", str(tmp_path / "cache"))
    run = SumoRun(resolve_scenario(GAME / f"{name}.sumocfg"), RunOptions(end_s=60, progress=False), None)
    run.conn.check_loads()
    assert list((tmp_path / "cache" / "sumo-loads-ok").iterdir()), "the load was noted"


@needs_game
def test_unregulated_junctions_have_no_foes() -> None:
    """An unregulated junction has no ``<request>``s: no link of it has a
    foe or a prohibitor (SUMO's drivers do not wait there); a priority
    junction of the same network still has them."""
    network = Network(GAME / "grid6" / "grid6.net.xml")
    net = network.net()
    kinds: dict[str, list[str]] = {"unregulated": [], "traffic_light": []}
    for node in net.getNodes():
        if node.getType() in kinds:
            kinds[node.getType()] += [c.getViaLaneID() for c in node.getConnections() if c.getViaLaneID()]
    assert kinds["unregulated"] and kinds["traffic_light"]
    for via in kinds["unregulated"]:
        assert network.internal_foes(via) == [] and network.prohibitors(via) == []
    assert any(network.internal_foes(via) for via in kinds["traffic_light"])


@needs_game
def test_every_vehicle_controlled_through_unregulated_junctions(tmp_path: Path) -> None:
    """SUMO's grid6 (lights, priority and unregulated junctions) with every
    vehicle controlled: it runs, and no vehicle collides or is teleported."""
    run = SumoRun(resolve_scenario(GAME / "grid6.sumocfg"), RunOptions(controlled_fraction=1.0, end_s=90, progress=False), tmp_path)
    summary = run.run().summary
    assert summary["controlled_vehicles"] > 50
    assert (summary["collisions"], summary["teleports"], summary["placement_faults"]) == (0, 0, 0)


@needs_game
def test_a_run_of_a_scenario_that_begins_hours_in(tmp_path: Path) -> None:
    """fokr_bs_demo (Braunschweig: cars, bicycles and pedestrians at a 0.05 s
    step) begins at 15:0:0; a run to 15:00:30 simulates 30 s from there."""
    run = SumoRun(resolve_scenario(GAME / "fokr_bs_demo.sumocfg"),
                  RunOptions(controlled_fraction=0.3, end_s=15 * 3600.0 + 30, progress=False), tmp_path)
    summary = run.run().summary
    assert (summary["begin_s"], summary["end_s"]) == (15 * 3600.0, 15 * 3600.0 + 30)
    assert summary["steps"] == 600


def test_end_on_the_command_line_reads_hours_as_sumo_does() -> None:
    from blendtrack.cli.common import end_time

    assert end_time("15:05:00") == 15 * 3600.0 + 300
    assert end_time("300") == 300.0


@needs_game
def test_rail_vehicles_are_left_to_sumo_and_counted(tmp_path: Path) -> None:
    """rail_demo's three trains (vClass rail, routes repeated 1000 times):
    selected by the fraction, none is taken over (a train has no steering;
    driven, each was handed back with a placement fault within 105 s), all
    three are counted as such, and the trains keep SUMO's own schedule."""
    run = SumoRun(resolve_scenario(GAME / "rail_demo.sumocfg"), RunOptions(controlled_fraction=1.0, end_s=20, progress=False), tmp_path)
    summary = run.run().summary
    assert (summary["controlled_vehicles"], summary["rail_bound_not_controlled"]) == (0, 3)
    assert summary["background_vehicles"] == 3
    assert summary["placement_faults"] == 0


@needs_game
def test_a_selection_of_rail_vehicles_only_is_refused_up_front() -> None:
    sc = resolve_scenario(GAME / "rail_demo.sumocfg")
    with pytest.raises(ScenarioError, match=r"runs on rails \(freightTrain \(rail\)\)"):
        check_selection(sc, RunOptions(controlled_type="freightTrain"))
    assert sc.vtypes().vclass("passengerTrain") == "rail"
    assert sc.vtypes().vclass("DEFAULT_PEDTYPE") == "pedestrian"


@needs_game
def test_compare_counts_no_train_among_the_controlled() -> None:
    """compare's plain twin run picks the same vehicles as the treatment: no train."""
    sc = resolve_scenario(GAME / "rail_demo.sumocfg")
    pick = selector(CompareOptions(controlled_fraction=1.0), sc, 0)
    assert not pick("freight_0", "freightTrain")
    assert not pick("x", "DEFAULT_RAILTYPE")
    assert pick("car", "DEFAULT_VEHTYPE")


@needs_game
def test_a_leader_whose_back_hangs_onto_the_way_ahead_is_seen(tmp_path: Path) -> None:
    """fokr_bs_demo, 15:04:48: SUMO has the controlled car on junction lane
    :109_0_3, beside its track's :109_0_4 (a fan-out); the way through the
    junction ends on the 6.6 m lane -2_6, and a car 1.6-2.3 m onto the
    junction lane after it hangs 2.2-2.9 m back onto -2_6. SUMO's
    ``getLeader`` of the controlled car says a car 41 m away on the other
    branch; the way's leader is that car, about 4 m ahead (unseen, it was
    found 2.5 m ahead when SUMO switched lanes, and the controlled car
    braked at 4.8 m/s^2, harder than the driver behind it expected)."""
    car, hanging = "1695567883563492", "1695567883113408"
    seen: list[tuple[str, object]] = []

    def hook(r: SumoRun, t: float) -> None:
        if t >= 54287.9 and car in r.active:
            r.conn.new_step()  # this step's lane lists
            lane = r.conn.sumo.vehicle.getLaneID(car)
            lead = r.conn.sumo.vehicle.getLeader(car, 100.0)
            seen.append((lane, r.junctions.leader_on_track(car, r.active[car].geo.piece_lane, lead, lane)))

    run = SumoRun(resolve_scenario(GAME / "fokr_bs_demo.sumocfg"),
                  RunOptions(controlled_ids=(car,), end_s=54288.2, progress=False), tmp_path)
    run.step_hooks.append(hook)
    run.run()
    beside = [lead for lane, lead in seen if lane == ":109_0_3"]
    assert beside, seen
    for lead in beside:
        assert isinstance(lead, tuple) and lead[0] == hanging and 3.0 < lead[1] < 5.0, seen
