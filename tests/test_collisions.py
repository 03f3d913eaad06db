"""Collisions SUMO skips: along a lane, with a vehicle moved by ``moveToXY``
in the last 10 s, under ``collision.action teleport``
(:mod:`blendtrack.sumo.collisions`). On real SUMO, over TraCI (one libsumo
simulation per process)."""

from __future__ import annotations

import csv
import json
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from blendtrack.sumo import RunOptions
from blendtrack.sumo.collisions import RemoteCollisions
from blendtrack.sumo.connection import sumo_binary
from blendtrack.sumo.scenario import resolve_scenario
from blendtrack.sumo.runner import SumoRun



ROUTES = """<routes>
    <vType id="car" length="5" minGap="2.5"/>
    <vehicle id="L" type="car" depart="0" departPos="300" departSpeed="0"><route edges="ab"/><stop lane="ab_0" endPos="305" duration="1000"/></vehicle>
    <vehicle id="F" type="car" depart="0" departPos="100" departSpeed="0"><route edges="ab"/></vehicle>
    <vehicle id="B" type="car" depart="0" departPos="20" departSpeed="0"><route edges="ab"/></vehicle>
</routes>
"""


@contextmanager
def _road(folder: Path, build_net: Any, action: str) -> Iterator[Any]:
    """A straight 500 m lane eastwards: ``L`` stands at 300 m, ``F`` (the one
    the tests move) starts at 100 m and ``B`` behind it at 20 m."""
    import traci

    net = build_net(folder, '<nodes><node id="a" x="0" y="0"/><node id="b" x="500" y="0"/></nodes>',
                    '<edges><edge id="ab" from="a" to="b" numLanes="1" speed="15"/></edges>')
    (folder / "r.rou.xml").write_text(ROUTES)
    traci.start([sumo_binary(), "-n", str(net), "-r", str(folder / "r.rou.xml"), "--collision.action", action,
                 "--no-step-log", "--no-warnings", "--step-length", "0.1"])
    try:
        traci.simulationStep()
        traci.vehicle.setSpeed("B", 0.0)  # stays well behind
        yield traci
    finally:
        traci.close()


def _put_behind(traci: Any, follower: str, leader: str, gap_m: float) -> None:
    """``follower``'s front ``gap_m`` behind ``leader``'s back, by ``moveToXY`` (the road runs east)."""
    x, y = traci.vehicle.getPosition(leader)
    traci.vehicle.moveToXY(follower, "ab", 0, x - traci.vehicle.getLength(leader) - gap_m, y, 90.0, 2)
    traci.vehicle.setSpeed(follower, 0.0)


def _sumo_pairs(traci: Any) -> set[tuple[str, str]]:
    return {(c.collider, c.victim) for c in traci.simulation.getCollisions()}


def test_sumo_skips_a_vehicle_moved_by_xy_under_teleport_and_the_check_finds_it_once(tmp_path: Path, build_net: Any) -> None:
    with _road(tmp_path, build_net, "teleport") as traci:
        follower, leader = "F", "L"
        check = RemoteCollisions(traci.vehicle, "teleport", float(traci.simulation.getOption("collision.mingap-factor")))
        assert check.active
        found: list[list[tuple[str, str, str]]] = []
        sumo_saw: list[set[tuple[str, str]]] = []
        # 1 m behind the leader's back (inside its 2.5 m minGap: a collision
        # by SUMO's rule) for 5 steps, then 20 m behind, then 1 m again.
        for gap in [1.0] * 5 + [20.0] * 3 + [1.0] * 2:
            _put_behind(traci, follower, leader, gap)
            check.moved_xy(follower, traci.simulation.getTime())
            traci.simulationStep()
            sumo_saw.append(_sumo_pairs(traci))
            found.append(check.check(traci.simulation.getTime(), sumo_saw[-1]))
    # SUMO saw none of it (the exemption this module is for) ...
    assert not any(sumo_saw)
    # ... and the check counts each stretch of overlap once, when it starts
    # (a placement lands at the end of the step after the call).
    hits = [k for k, f in enumerate(found) if f]
    assert len(hits) == 2 and hits[0] <= 1 and 8 <= hits[1] <= 9, found
    assert all(f == [(follower, leader, f[0][2])] and f[0][2] for f in found if f)


def test_a_gap_kept_and_other_actions_give_nothing(tmp_path: Path, build_net: Any) -> None:
    with _road(tmp_path, build_net, "teleport") as traci:
        follower, leader = "F", "L"
        check = RemoteCollisions(traci.vehicle, "teleport", -1.0)
        for _ in range(5):
            _put_behind(traci, follower, leader, 3.0)  # more than the minGap
            check.moved_xy(follower, traci.simulation.getTime())
            traci.simulationStep()
            assert check.check(traci.simulation.getTime(), _sumo_pairs(traci)) == []
    with _road(tmp_path / "w", build_net, "warn") as traci:
        follower, leader = "F", "L"
        check = RemoteCollisions(traci.vehicle, "warn", -1.0)
        assert not check.active
        seen = set()
        for _ in range(3):
            _put_behind(traci, follower, leader, 1.0)
            check.moved_xy(follower, traci.simulation.getTime())
            traci.simulationStep()
            seen |= _sumo_pairs(traci)
            assert check.check(traci.simulation.getTime(), set()) == []
        # Under warn SUMO reports it itself.
        assert (follower, leader) in seen


def test_a_pair_sumo_reported_is_not_counted_again(tmp_path: Path, build_net: Any) -> None:
    with _road(tmp_path, build_net, "teleport") as traci:
        follower, leader = "F", "L"
        check = RemoteCollisions(traci.vehicle, "teleport", -1.0)
        _put_behind(traci, follower, leader, 1.0)
        check.moved_xy(follower, traci.simulation.getTime())
        traci.simulationStep()
        traci.simulationStep()
        assert check.check(traci.simulation.getTime(), {(follower, leader)}) == []


def _plant_driver(run: SumoRun, lane: str, pos: float, speed: float, skip: Any) -> str | None:
    """Puts one of SUMO's drivers (not controlled, not in ``skip``, not
    inside a junction) on ``lane`` at ``pos`` with ``speed`` (``moveTo``,
    which is not remote control); its id, or None when no driver's route
    has that lane."""
    veh = run.sumo.vehicle
    for other in veh.getIDList():
        if other in run.active or other in skip or veh.getLaneID(other).startswith(":"):
            continue
        try:
            veh.moveTo(other, lane, pos)
        except Exception:
            continue  # the lane is not on its route
        veh.setSpeed(other, speed)
        return other
    return None


def _grid_under_teleport(tmp_path: Path, end_s: float, hook: Any) -> tuple[SumoRun, Any]:
    """The shipped grid, half its vehicles controlled, under teleport, with ``hook`` after each step."""
    run = SumoRun(resolve_scenario("urban_grid"),
                  RunOptions(controlled_fraction=0.5, end_s=end_s, seed=0, progress=False, keep_records=True,
                             sumo_args=("--collision.action", "teleport")),
                  tmp_path)
    run.step_hooks.append(hook)
    return run, run.run()


def test_a_run_under_teleport_counts_a_collision_sumo_skipped(tmp_path: Path) -> None:
    """End to end on the shipped grid under teleport: right after a
    controlled vehicle's (x, y) move, one of SUMO's drivers is put 1 m
    behind it (``moveTo``, which is not remote control). SUMO does not
    count it; the run does and hands the controlled vehicle back."""
    planted: list[tuple[str, str]] = []

    def plant(run: SumoRun, t: float) -> None:
        if planted or t < 30.0:
            return
        veh = run.sumo.vehicle
        moved = [v for v, when in run.remote_collisions._moved.items() if t - when < 2.0 and v in run.active]
        for vid in moved:
            lane = veh.getLaneID(vid)
            back = veh.getLanePosition(vid) - veh.getLength(vid)
            if lane.startswith(":") or back < 12.0:
                continue
            other = _plant_driver(run, lane, back - 1.0, veh.getSpeed(vid), run.remote_collisions._moved)
            if other is not None:
                planted.append((other, vid))
                return

    run, result = _grid_under_teleport(tmp_path, 60.0, plant)
    assert planted, "no controlled vehicle moved by (x, y) on a normal lane to plant a driver behind"
    found = [(c, v) for _, c, v, *_ in run.remote_found]
    assert planted[0] in found
    assert result.summary["collision_action"] == "teleport"
    assert result.summary["collisions_remote_checked"] == len(found)
    assert result.summary["collisions"] >= 1
    assert {r.vid: r.reason for r in result.records}[planted[0][1]] == "collision"


def test_a_controlled_collider_sumo_teleports_counts_as_a_collision(tmp_path: Path) -> None:
    """Under teleport SUMO teleports the collider in the step of the
    collision, and lists it among both the step's teleports and its
    colliding vehicles. One of SUMO's drivers is put with its back 1 m
    behind the front of a controlled vehicle SUMO checks (no (x, y) move
    within the window), standing: SUMO reports the controlled vehicle as
    the collider and teleports it. The run counts the collision and ends
    the vehicle's record with it (dropped for the teleport first, its
    collision was not counted: 0 in the summary and the CLI's line, 1 in
    SUMO's output; Bologna with the sublane model, 573 s)."""
    planted: list[tuple[str, str]] = []

    def plant(run: SumoRun, t: float) -> None:
        if planted or t < 30.0:
            return
        veh = run.sumo.vehicle
        for vid in list(run.active):
            if vid in run.remote_collisions._moved:
                continue
            lane = veh.getLaneID(vid)
            front = veh.getLanePosition(vid)
            if lane.startswith(":") or front < 20.0 or front > veh.getLength(vid) + run.network.lane_length(lane) - 30.0:
                continue
            # (4.5 or 5 m long: the planted back 0.5-1 m behind the front.)
            other = _plant_driver(run, lane, front + 4.0, 0.0, ())
            if other is not None:
                planted.append((vid, other))
                return

    run, result = _grid_under_teleport(tmp_path, 45.0, plant)
    assert planted, "no controlled vehicle on a normal lane to plant a standing driver on"
    car = planted[0][0]
    xml = (tmp_path / "sumo" / "collisions.xml").read_text()
    assert f'collider="{car}"' in xml, xml
    assert {r.vid: r.reason for r in result.records}[car] == "collision"
    assert result.summary["collisions"] >= 1


def test_collisions_csv_holds_sumos_and_the_checks_in_time_order(tmp_path: Path) -> None:
    from blendtrack.sumo import _count_collisions
    from blendtrack.sumo.records import RunResult

    (tmp_path / "sumo").mkdir()
    (tmp_path / "sumo" / "collisions.xml").write_text(
        '<collisions>\n<collision time="10.00" type="junction" lane=":j_0_0" collider="a" victim="b" colliderType="t" victimType="t"/>\n'
        '<collision time="30.00" type="collision" lane="e_0" collider="c" victim="d" colliderType="t" victimType="t"/>\n</collisions>\n')
    (tmp_path / "vehicles.csv").write_text("id\nb\nx\n")
    result = RunResult([], {})
    _count_collisions(result, tmp_path, [(20.0, "x", "y", "f_1", "car", "bus")])
    with open(tmp_path / "collisions.csv") as f:
        rows = list(csv.DictReader(f))
    assert [(r["time_s"], r["collider"], r["detected_by"], r["controlled_involved"]) for r in rows] == [
        ("10.0", "a", "sumo", "1"), ("20.0", "x", "blendtrack", "1"), ("30.0", "c", "sumo", "0")]
    assert rows[1]["lane"] == "f_1" and rows[1]["victim_type"] == "bus" and rows[1]["type"] == "collision"
    assert result.summary == {"collisions_all": 3, "collisions_with_controlled": 2}


def test_the_check_forgets_vehicles_that_left(tmp_path: Path) -> None:
    check = RemoteCollisions(object(), "teleport", -1.0)
    check.moved_xy("a", 1.0)
    check.forget("a")
    assert check.check(2.0, set()) == []
    inactive = RemoteCollisions(object(), "warn", -1.0)
    inactive.moved_xy("a", 1.0)
    assert inactive.check(2.0, set()) == []


@pytest.mark.parametrize("factor", [0.0, 0.5])
def test_the_mingap_factor_sets_how_close_is_a_collision(factor: float, tmp_path: Path, build_net: Any) -> None:
    with _road(tmp_path, build_net, "teleport") as traci:
        follower, leader = "F", "L"
        check = RemoteCollisions(traci.vehicle, "teleport", factor)
        # 1 m behind the back, minGap 2.5 m: a collision when 1 < factor x 2.5.
        _put_behind(traci, follower, leader, 1.0)
        check.moved_xy(follower, traci.simulation.getTime())
        traci.simulationStep()
        traci.simulationStep()
        got = check.check(traci.simulation.getTime(), set())
    assert bool(got) == (1.0 < factor * 2.5)


class _FakeSumo:
    """Vehicle and lane domains over fixed data, for ``_same_way``."""

    def __init__(self, cars: dict[str, tuple[str, float, float]], links: dict[str, list[tuple[str, str]]],
                 routes: dict[str, tuple[str, ...]] | None = None) -> None:
        self.cars, self.links, self.routes = cars, links, routes or {}

    def getLaneID(self, vid: str) -> str:
        return self.cars[vid][0]

    def getLanePosition(self, vid: str) -> float:
        return self.cars[vid][1]

    def getLength(self, vid: str) -> float:
        return self.cars[vid][2]

    def getRoute(self, vid: str) -> tuple[str, ...]:
        return self.routes.get(vid, ())

    def getRouteIndex(self, vid: str) -> int:
        return len(self.routes.get(vid, ())) - 1

    def getLinks(self, lane: str) -> list[tuple[Any, ...]]:
        return [(to, True, True, False, via, "M", "s", 5.0) for to, via in self.links.get(lane, [])]


def test_only_pairs_sumos_lane_check_compares_count() -> None:
    """Same lane, or the victim's back hanging onto the collider's lane
    (its front on a lane that lane leads to, directly or by a junction
    lane, and its back past that junction lane): compared. Two lanes that merge further on, a victim wholly on
    its own lane, a vehicle off the network: not."""
    links = {"a_0": [("c_0", ":j_0_0")], "b_0": [("c_0", ":j_1_0")]}
    cars = {
        "f": ("a_0", 90.0, 5.0), "lead": ("a_0", 95.0, 5.0),
        "in_j": (":j_0_0", 2.0, 5.0),     # back hangs onto a_0
        "out": ("c_0", 1.0, 5.0),         # back hangs past the 3 m junction lane onto a_0
        "out_in_j": ("c_0", 2.0, 5.0),    # back hangs onto the junction lane only
        "other_way": (":j_1_0", 2.0, 5.0),  # from b_0: merges with a_0's way at c_0
        "clear": (":j_0_0", 6.0, 5.0),    # wholly on the junction lane
        "gone": ("", 0.0, 5.0),
    }
    fake = _FakeSumo(cars, links)
    inside = {("a_0", "c_0"): 3.0, ("b_0", "c_0"): 3.0}
    check = RemoteCollisions(fake, "teleport", -1.0, fake, None, lambda a, b: inside.get((a, b)))
    assert check._same_way("f", "lead") == "a_0"
    assert check._same_way("f", "in_j") == "a_0"
    assert check._same_way("f", "out") == "a_0"
    assert check._same_way("f", "out_in_j") is None
    assert check._same_way("f", "other_way") is None
    assert check._same_way("f", "clear") is None
    assert check._same_way("f", "gone") is None and check._same_way("gone", "f") is None


def test_at_a_merge_only_the_victims_own_way_counts() -> None:
    """Onto c_0 the ways from a_0 (through :j_0_0) and b_0 (through :j_1_0)
    merge. A victim with its front on c_0 and its back hanging back came
    by one of them, known from the edge before on its route: compared with
    a collider on that way only (Bologna's 42: SUMO's own check, under
    ``warn``, reported nothing for a car standing on the other junction
    lane). Where the route does not say (no edge before), compared as
    before."""
    links = {"a_0": [("c_0", ":j_0_0")], "b_0": [("c_0", ":j_1_0")], ":j_0_0": [("c_0", "")], ":j_1_0": [("c_0", "")]}
    cars = {"on_a": (":j_0_0", 2.0, 5.0), "on_b": (":j_1_0", 2.0, 5.0), "from_b": ("c_0", 1.0, 5.0), "unknown": ("c_0", 1.0, 5.0)}
    fake = _FakeSumo(cars, links, routes={"from_b": ("b", "c"), "unknown": ("c",)})
    ways = {("a", "c_0"): frozenset({"a_0", ":j_0_0"}), ("b", "c_0"): frozenset({"b_0", ":j_1_0"})}
    check = RemoteCollisions(fake, "teleport", -1.0, fake, lambda edge, lane: ways.get((edge, lane), frozenset()))
    assert check._same_way("on_b", "from_b") == ":j_1_0"
    assert check._same_way("on_a", "from_b") is None
    assert check._same_way("on_a", "unknown") == ":j_0_0"


def test_a_compare_counts_the_collisions_blendtrack_found(tmp_path: Path) -> None:
    """The compare's collision count is SUMO's statistics plus the rows of
    ``collisions.csv`` blendtrack found where SUMO does not look."""
    from blendtrack.sumo.outputs import COLLISION_COLUMNS, count_remote_collisions

    f = tmp_path / "collisions.csv"
    with open(f, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=COLLISION_COLUMNS)
        w.writeheader()
        for by in ("sumo", "blendtrack", "blendtrack"):
            w.writerow({k: "" for k in COLLISION_COLUMNS} | {"detected_by": by})
    assert count_remote_collisions(f) == 2
    assert count_remote_collisions(tmp_path / "none.csv") == 0


def test_a_pair_sumo_reports_after_blendtrack_found_it_is_counted_once(tmp_path: Path) -> None:
    """blendtrack finds a pair SUMO does not look at (a vehicle moved by
    (x, y) under teleport) and hands its vehicle back; the two stay in
    contact and SUMO reports them once its exemption runs out. That report
    is listed in collisions.csv as a repeat, not counted again, in the
    run's summary nor in a compare's count (SUMO's statistics include it)."""
    from blendtrack.sumo import _count_collisions
    from blendtrack.sumo.records import RunResult
    from blendtrack.sumo.outputs import REPEAT, count_remote_collisions

    sd = tmp_path / "sumo"
    sd.mkdir()
    (sd / "collisions.xml").write_text(
        '<collisions>'
        '<collision time="519.00" type="collision" lane="58[0]_0" collider="a" victim="b" colliderType="car" victimType="car"/>'
        '<collision time="530.00" type="collision" lane="58[0]_0" collider="a" victim="b" colliderType="car" victimType="car"/>'
        '<collision time="519.00" type="collision" lane="x_0" collider="c" victim="d" colliderType="car" victimType="car"/>'
        '</collisions>')
    (tmp_path / "vehicles.csv").write_text("id\na\n")
    result = RunResult(records=[], summary={})
    # blendtrack found (a, b) at 509 s: SUMO's 519 s report is the same
    # contact; its 530 s one (21 s on) and (c, d) are collisions of their own.
    _count_collisions(result, tmp_path, [(509.0, "a", "b", "58[0]_0", "car", "car")])
    with open(tmp_path / "collisions.csv") as f:
        rows = list(csv.DictReader(f))
    assert [(r["time_s"], r["collider"], r["detected_by"]) for r in rows] == [
        ("509.0", "a", "blendtrack"), ("519.0", "a", REPEAT), ("519.0", "c", "sumo"), ("530.0", "a", "sumo")]
    assert result.summary["collisions_all"] == 3
    assert result.summary["collisions_with_controlled"] == 2
    # A compare adds to SUMO's statistics (3 reports, the repeat among
    # them) blendtrack's one find less the repeat: 3 collisions in all.
    assert count_remote_collisions(tmp_path / "collisions.csv") == 0
