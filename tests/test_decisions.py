"""The SUMO bridge's decisions (lane changes, leaders, junctions, lights) on a
stand-in for SUMO: each answer is checked against the rule's closed form,
worked out by hand here, on both sides of its boundary. No SUMO process:
these run in a second and are the tests ``scripts/mutants`` runs per mutant
of ``lanechange.py`` and ``junctions.py`` (docs/testing.md)."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
import traci.constants as tc

from blendtrack.sumo import junctions as jn
from blendtrack.sumo import lanechange as lc
from blendtrack.sumo.junctions import FOLLOW_MIN_SPEED_MPS, Junctions
from blendtrack.sumo.lanechange import COURTESY_DECEL_MPS2, COURTESY_SPACE_M, LaneChanges

EPS = 1e-6


class FakeVehicle:
    """``sumo.vehicle``: every getter reads a per-vehicle dict."""

    def __init__(self) -> None:
        self.cars: dict[str, dict[str, Any]] = {}
        self.neighbours: dict[tuple[str, int], list[tuple[str, float]]] = {}
        self.links: dict[str, list[tuple[Any, ...]]] = {}
        self.calls: list[tuple[Any, ...]] = []

    def add(self, vid: str, **kw: Any) -> None:
        car = {"speed": 0.0, "pos": 0.0, "lat": 0.0, "width": 2.0, "length": 5.0, "min_gap": 2.5, "lane": "e_0",
               "xy": (0.0, 0.0), "angle": 90.0, "lane_index": 0}
        car.update(kw)
        self.cars[vid] = car

    def getSpeed(self, vid: str) -> float:
        return self.cars[vid]["speed"]

    def getLanePosition(self, vid: str) -> float:
        return self.cars[vid]["pos"]

    def getLateralLanePosition(self, vid: str) -> float:
        return self.cars[vid]["lat"]

    def getWidth(self, vid: str) -> float:
        return self.cars[vid]["width"]

    def getLength(self, vid: str) -> float:
        return self.cars[vid]["length"]

    def getMinGap(self, vid: str) -> float:
        return self.cars[vid]["min_gap"]

    def getAccel(self, vid: str) -> float:
        return self.cars[vid].get("accel", 2.6)

    def getDecel(self, vid: str) -> float:
        return self.cars[vid].get("decel", 4.5)

    def getAllowedSpeed(self, vid: str) -> float:
        return self.cars[vid].get("allowed", 30.0)

    def getSpeedFactor(self, vid: str) -> float:
        return self.cars[vid].get("speed_factor", 1.0)

    def getTau(self, vid: str) -> float:
        return self.cars[vid].get("tau", 1.0)

    def setSpeed(self, vid: str, speed: float) -> None:
        self.cars[vid]
        self.calls.append(("speed", vid, speed))

    def getImpatience(self, vid: str) -> float:
        return self.cars[vid].get("impatience", 0.0)

    def getLaneID(self, vid: str) -> str:
        return self.cars[vid]["lane"]

    def getLaneIndex(self, vid: str) -> int:
        return self.cars[vid]["lane_index"]

    def getRoadID(self, vid: str) -> str:
        return self.cars[vid]["lane"].rpartition("_")[0]

    def getPosition(self, vid: str) -> tuple[float, float]:
        return self.cars[vid]["xy"]

    def getAngle(self, vid: str) -> float:
        return self.cars[vid]["angle"]

    def getNeighbors(self, vid: str, mode: int) -> list[tuple[str, float]]:
        return self.neighbours.get((vid, mode), [])

    def getNextLinks(self, vid: str) -> list[tuple[Any, ...]]:
        return self.links.get(vid, [])

    def openGap(self, vid: str, tau: float, space: float, duration: float, rate: float, decel: float, ref: str) -> None:
        self.cars[vid]  # a vehicle that has left raises, as SUMO does
        self.calls.append(("open", vid, ref, space, decel))

    def deactivateGapControl(self, vid: str) -> None:
        self.cars[vid]
        self.calls.append(("off", vid))

    def changeLane(self, vid: str, index: int, duration: float) -> None:
        self.cars[vid]
        self.calls.append(("hold", vid, index, duration))


class FakeConn:
    def __init__(self) -> None:
        self.vehicle = FakeVehicle()
        self.lanes: dict[str, list[str]] = {}
        # The lights' subscription results (as of the simulation step) and
        # their states now (another client may have switched one since).
        self.tls_results: dict[str, dict[int, str]] = {}
        self.tls_now: dict[str, str] = {}
        self.sumo = SimpleNamespace(
            vehicle=self.vehicle,
            trafficlight=SimpleNamespace(getAllSubscriptionResults=lambda: self.tls_results, getRedYellowGreenState=self.tls_now.__getitem__),
        )
        self.tc = tc
        self.errors = KeyError
        self.dt = 1.0
        # Subscribed to the lights (TraCI, or a step hook); without, each
        # light's state is read (``lights``, ``light_state``).
        self.light_subscriptions = True
        self.lights: tuple[str, ...] = ()
        self.light_state = self.tls_now.__getitem__

    def vehicles_on(self, lane: str) -> list[str]:
        return self.lanes.get(lane, [])

    def get_speed(self, vid: str) -> float:
        return self.vehicle.getSpeed(vid)

    def get_lane_pos(self, vid: str) -> float:
        return self.vehicle.getLanePosition(vid)

    def get_lane_id(self, vid: str) -> str:
        return self.vehicle.getLaneID(vid)


class FakeLane:
    def __init__(self, length: float, width: float = 3.2, n_lanes: int = 3) -> None:
        self.length, self.width, self.n_lanes = length, width, n_lanes

    def getLength(self) -> float:
        return self.length

    def getWidth(self) -> float:
        return self.width

    def getEdge(self) -> Any:
        return SimpleNamespace(getLaneNumber=lambda: self.n_lanes)


class FakeNet:
    def __init__(self, lanes: dict[str, FakeLane]) -> None:
        self.lanes = lanes

    def getLane(self, lane_id: str) -> FakeLane:
        return self.lanes[lane_id]


def lane_changes(conn: FakeConn, plan_decel: float = 4.0, lanes: dict[str, FakeLane] | None = None,
                 feeders: dict[str, tuple[tuple[str, float], ...]] | None = None) -> LaneChanges:
    net = FakeNet(lanes or {})
    feeds = feeders or {}
    network = SimpleNamespace(net=lambda: net, feeders=lambda lane: feeds.get(lane, ()))
    return LaneChanges(conn, network, None, {}, plan_decel)  # type: ignore[arg-type]


# ------------------------------------------------------------ closed forms
def test_tactical_gap_is_the_headway_and_braking_distance_in_closed_form() -> None:
    # 5 m + factor * (1 s * 20 m/s + (20^2 - 10^2) / (2 * 1 m/s^2)) = 5 + factor * 170
    assert lc.tactical_gap(20.0, 10.0, 1.0) == pytest.approx(175.0)
    assert lc.tactical_gap(20.0, 10.0, 0.5) == pytest.approx(90.0)
    # A slower rear vehicle needs no braking term: 5 + 8.
    assert lc.tactical_gap(8.0, 12.0, 1.0) == pytest.approx(13.0)
    # Negative speeds (SUMO's -1001 for "unknown") count as standing.
    assert lc.tactical_gap(-3.0, -7.0, 1.0) == pytest.approx(5.0)
    assert lc.tactical_gap(6.0, -30.0, 1.0) == pytest.approx(5.0 + 6.0 + 18.0)


def test_tactical_gap_follows_its_constants(monkeypatch: pytest.MonkeyPatch) -> None:
    """At 2 m/s^2 of braking and 1.5 s of headway: 5 + 1.5 * 20 + 300 / 4."""
    monkeypatch.setattr(lc, "TACTICAL_DECEL_MPS2", 2.0)
    monkeypatch.setattr(lc, "TACTICAL_HEADWAY_S", 1.5)
    assert lc.tactical_gap(20.0, 10.0, 1.0) == pytest.approx(5.0 + 30.0 + 75.0)


def test_change_length_is_two_seconds_of_travel_within_its_bounds() -> None:
    assert lc.change_length(12.0, math.inf) == pytest.approx(24.0)
    assert lc.change_length(-12.0, math.inf) == pytest.approx(24.0)
    assert lc.change_length(2.0, math.inf) == pytest.approx(10.0)
    assert lc.change_length(45.0, math.inf) == pytest.approx(60.0)
    assert lc.change_length(45.0, 33.0) == pytest.approx(33.0)


def test_could_change_lane_reads_sumo_state_bits() -> None:
    state = {}

    def lcs(vid: str, direction: int) -> tuple[int, int]:
        return state[direction]

    free = tc.LCA_SPEEDGAIN
    state[1] = (free, tc.LCA_BLOCKED)
    assert lc.could_change_lane(lcs, "a", 1)
    state[1] = (free | tc.LCA_BLOCKED, tc.LCA_BLOCKED)
    assert not lc.could_change_lane(lcs, "a", 1)
    state[1] = (tc.LCA_UNKNOWN, tc.LCA_BLOCKED)
    assert not lc.could_change_lane(lcs, "a", 1)
    # Just changed left: SUMO's state (not blocked, left bit) no longer applies.
    state[1] = (free, tc.LCA_LEFT)
    assert not lc.could_change_lane(lcs, "a", 1)
    # The right bit does not say so for a change to the left, and vice versa.
    state[1] = (free, tc.LCA_RIGHT)
    assert lc.could_change_lane(lcs, "a", 1)
    state[-1] = (free, tc.LCA_RIGHT)
    assert not lc.could_change_lane(lcs, "a", -1)
    state[-1] = (free, tc.LCA_LEFT)
    assert lc.could_change_lane(lcs, "a", -1)


# ------------------------------------------------------------ target lane
def test_a_lane_change_lasts_until_its_length_is_covered_pulling_away() -> None:
    """(sqrt(v^2 + 2 a L) - v) / a: from standstill 10 m at 1 m/s^2 take
    sqrt(20) s; at 10 m/s, 20 m take sqrt(140) - 10 s; at 2 m/s^2 from
    standstill, sqrt(10) s. A follower at 18 m/s behind a changer starting
    from standstill closes in 18 sqrt(20) - 10 = 70.5 m over the change,
    so with the changer's mean speed (10 / sqrt(20)) the gap it needs is
    5 + 70.5 m."""
    assert lc.change_duration(0.0, 10.0, 1.0) == pytest.approx(math.sqrt(20.0))
    assert lc.change_duration(10.0, 20.0, 1.0) == pytest.approx(math.sqrt(140.0) - 10.0)
    assert lc.change_duration(0.0, 10.0, 2.0) == pytest.approx(math.sqrt(10.0))
    # Never slower than at the present speed, whatever the acceleration.
    assert lc.change_duration(10.0, 20.0, 0.0) <= 2.0
    conn = FakeConn()
    conn.vehicle.add("me", speed=0.0)
    conn.vehicle.add("f", speed=18.0)
    lcs = lane_changes(conn)
    t = lc.change_duration(0.0, 10.0, 1.0)
    need = 5.0 + 18.0 * t - 10.0
    for gap, clear in [(need + 1e-3, True), (need - 1e-3, False)]:
        conn.vehicle.neighbours = {("me", 0): [("f", gap)]}
        assert lcs.target_lane_clear("me", 1, 10.0 / t, t) is clear, gap


@pytest.mark.parametrize("direction, side", [(1, 0), (-1, 1)])
def test_target_lane_clear_at_its_boundary(direction: int, side: int) -> None:
    """Follower at 14 m/s behind a changer at 10 m/s, 2 s change: it needs
    5 + 2 * 4 = 13 m; a leader at 7 m/s: 5 + 2 * 3 = 11 m. The neighbour
    look-up asks the side the change goes to (getNeighbors bit 0 = right)."""
    conn = FakeConn()
    v = conn.vehicle
    v.add("me", speed=10.0)
    v.add("f", speed=14.0)
    v.add("l", speed=7.0)
    lcs = lane_changes(conn)
    for gap_f, gap_l, clear in [(13.0 + EPS, 11.0 + EPS, True), (13.0 - 1e-3, 11.0 + EPS, False), (13.0 + EPS, 11.0 - 1e-3, False)]:
        v.neighbours = {("me", side): [("f", gap_f)], ("me", side | 2): [("l", gap_l)]}
        assert lcs.target_lane_clear("me", direction, 10.0, 2.0) is clear, (gap_f, gap_l)
    # Exactly at the needed gap (13 m and 11 m, exact in binary) is room enough.
    v.neighbours = {("me", side): [("f", 13.0)], ("me", side | 2): [("l", 11.0)]}
    assert lcs.target_lane_clear("me", direction, 10.0, 2.0)
    # The other side's vehicles are not looked at.
    v.neighbours = {("me", 1 - side): [("f", 0.0)], ("me", (1 - side) | 2): [("l", 0.0)]}
    assert lcs.target_lane_clear("me", direction, 10.0, 2.0)
    # A slower follower and a faster leader need the bare 5 m only.
    v.neighbours = {("me", side): [("l", 5.0 + EPS)], ("me", side | 2): [("f", 5.0 + EPS)]}
    assert lcs.target_lane_clear("me", direction, 10.0, 2.0)
    v.neighbours = {("me", side): [("l", 5.0 - EPS)]}
    assert not lcs.target_lane_clear("me", direction, 10.0, 2.0)


def test_tactical_room_uses_the_tactical_gap_both_ways() -> None:
    """Changer at 20 m/s, follower at 20 (5 + 20 = 25 m), leader at 10:
    5 + 20 + 150 = 175 m at factor 1, 5 + 0.5 * 170 = 90 m at 0.5."""
    conn = FakeConn()
    lcs = lane_changes(conn)
    near = ([(25.0 + EPS, 20.0)], [(175.0 + EPS, 10.0)])
    assert lcs.tactical_room("me", 1, 20.0, 1.0, near)
    assert not lcs.tactical_room("me", 1, 20.0, 1.0, ([(25.0 - EPS, 20.0)], [(175.0 + EPS, 10.0)]))
    assert not lcs.tactical_room("me", 1, 20.0, 1.0, ([(25.0 + EPS, 20.0)], [(175.0 - EPS, 10.0)]))
    assert lcs.tactical_room("me", 1, 20.0, 0.5, ([(15.0 + EPS, 20.0)], [(90.0 + EPS, 10.0)]))
    assert not lcs.tactical_room("me", 1, 20.0, 0.5, ([(15.0 - EPS, 20.0)], [(90.0 + EPS, 10.0)]))


def test_far_lane_room_checks_vehicles_behind_and_ahead() -> None:
    """Changer front at 100 m (length 5, back at 95) at 10 m/s. A vehicle
    on the far lane behind, front at 60 m, minGap 2.5, at 10 m/s: gap
    95 - 60 - 2.5 = 32.5 m against 5 + 0.5 * 10 = 10 m. Ahead, back at
    o_front - 5, gap o_front - 5 - 100 - 2.5 against the same 10 m at 10 m/s."""
    conn = FakeConn()
    v = conn.vehicle
    v.add("me", pos=100.0, speed=10.0)
    lcs = lane_changes(conn)
    conn.lanes["e_2"] = ["b"]
    v.add("b", pos=95.0 - 2.5 - 10.0 - EPS, speed=10.0)
    assert lcs.far_lane_room("me", "e_2", 100.0, 10.0)
    v.cars["b"]["pos"] = 95.0 - 2.5 - 10.0 + 1e-3
    assert not lcs.far_lane_room("me", "e_2", 100.0, 10.0)
    conn.lanes["e_2"] = ["a"]
    v.add("a", pos=100.0 + 2.5 + 5.0 + 10.0 + EPS, speed=10.0)
    assert lcs.far_lane_room("me", "e_2", 100.0, 10.0)
    v.cars["a"]["pos"] = 100.0 + 2.5 + 5.0 + 10.0 - 1e-3
    assert not lcs.far_lane_room("me", "e_2", 100.0, 10.0)
    # Level with the front counts as behind (o_front <= front).
    v.cars["a"]["pos"] = 100.0
    assert not lcs.far_lane_room("me", "e_2", 100.0, 10.0)


# ------------------------------------------------------------ leaders
def test_tighter_leader_ties_and_unknown_speeds() -> None:
    conn = FakeConn()
    v = conn.vehicle
    v.add("a", speed=8.0)
    v.add("b", speed=8.0)
    v.add("stand", speed=-5.0)
    lcs = lane_changes(conn, plan_decel=4.0)
    # Equal virtual obstacle distances: the first stays.
    assert lcs.tighter_leader(("a", 10.0), ("b", 10.0)) == ("a", 10.0)
    # 10 + 64 / 8 = 18 m against a standing one (negative speed) at 17.9 m and 18.1 m.
    assert lcs.tighter_leader(("a", 10.0), ("stand", 17.9)) == ("stand", 17.9)
    assert lcs.tighter_leader(("a", 10.0), ("stand", 18.1)) == ("a", 10.0)
    # SUMO's "no leader" ("", -1) and a gap under -100 give way to the other.
    assert lcs.tighter_leader(("a", -100.5), ("b", 50.0)) == ("b", 50.0)
    assert lcs.tighter_leader(("a", -100.0), ("b", 50.0)) == ("a", -100.0)
    assert lcs.tighter_leader(("", 3.0), ("b", 50.0)) == ("b", 50.0)
    assert lcs.tighter_leader((), ("b", 50.0)) == ("b", 50.0)


def test_soft_leaders_keep_the_tighter_per_vehicle_and_count_them() -> None:
    conn = FakeConn()
    v = conn.vehicle
    for vid in ("f", "c", "m", "n", "g"):
        v.add(vid, speed=0.0)
    lcs = lane_changes(conn)
    lcs._courtesy = {"f": ("c", 30.0), "g": ("gone", 5.0)}
    lcs._merge_leads = {"f": ("n", 20.0), "m": ("n", 4.0)}
    index = {"f": 0, "c": 1, "m": 2, "n": 3, "g": 4}
    assert has_soft(lcs)
    soft = sorted(lcs.soft_leaders(index))
    # f: courtesy to c at 30 m and lining up behind n at 20 m -> the tighter, n.
    assert soft == [(0, "n", 20.0), (2, "n", 4.0)]
    assert lcs.counts["courtesy_steps"] == 1 and lcs.counts["merge_lead_steps"] == 2
    # Taken: the next step starts with none.
    assert not has_soft(lcs) and lcs.soft_leaders(index) == []
    # A courtesy follower that is not controlled (not in index) is skipped.
    lcs._merge_leads = {"x": ("n", 4.0)}
    assert has_soft(lcs) and lcs.soft_leaders(index) == []


def has_soft(lcs: LaneChanges) -> bool:
    return lcs.has_soft_leaders()


def test_ask_courtesy_picks_the_nearest_follower_that_can_brake_gently() -> None:
    """Changer front at 100 m (length 5: back 95) at 10 m/s. Followers on the
    target lane at 80 m and 40 m (minGap 2.5), both controlled: gaps
    95 - f - 2.5 - 5 - 1 = 6.5 m and 46.5 m. The near one at 20 m/s closes
    at 10 m/s, needs 100 / (2 * 2) = 25 m > 6.5 m: it passes; the far one
    at 20 m/s has 46.5 m: it gives way."""
    conn = FakeConn()
    v = conn.vehicle
    v.add("me", pos=100.0, speed=10.0)
    v.add("near", pos=80.0, speed=20.0)
    v.add("far", pos=40.0, speed=20.0)
    v.add("ahead", pos=96.0, speed=30.0)
    conn.lanes["t_0"] = ["far", "near", "ahead"]
    lcs = lane_changes(conn)
    lcs.active = {"near": None, "far": None, "ahead": None}  # type: ignore[dict-item]
    lcs.ask_courtesy("me", "t_0", 100.0, 10.0)
    assert lcs._courtesy == {"far": ("me", pytest.approx(46.5))}
    # Slow enough to brake gently: closing 5 m/s needs 6.25 m < 6.5 m.
    lcs._courtesy = {}
    v.cars["near"]["speed"] = 15.0
    lcs.ask_courtesy("me", "t_0", 100.0, 10.0)
    assert lcs._courtesy == {"near": ("me", pytest.approx(6.5))}
    # A tighter request from another changer replaces a looser one, not the reverse.
    v.add("me2", length=4.0)  # gap 7.5 m: looser
    lcs.ask_courtesy("me2", "t_0", 100.0, 10.0)
    assert lcs._courtesy["near"][0] == "me"
    v.add("me3", length=6.0)
    lcs.ask_courtesy("me3", "t_0", 100.0, 12.0)  # closing 3 m/s: 2.25 m of braking
    assert lcs._courtesy["near"] == ("me3", pytest.approx(5.5))
    # Beyond COURTESY_RANGE_M (150 m) nobody is asked; SUMO's own drivers are skipped.
    lcs._courtesy = {}
    v.cars["near"]["pos"] = 95.0 - 150.0 - EPS
    conn.lanes["t_0"] = ["near"]
    lcs.ask_courtesy("me", "t_0", 100.0, 10.0)
    assert lcs._courtesy == {}
    v.cars["near"]["pos"] = 95.0 - 150.0  # exactly at the range: asked
    lcs.ask_courtesy("me", "t_0", 100.0, 10.0)
    assert "near" in lcs._courtesy
    lcs._courtesy = {}
    lcs.active = {}
    lcs.ask_courtesy("me", "t_0", 100.0, 10.0)
    assert lcs._courtesy == {}
    # A SUMO driver is asked to open the gap (open_gaps) instead; one
    # follower per changer and one changer per follower.
    assert lcs._asked == {"near": "me"}
    lcs.ask_courtesy("me2", "t_0", 100.0, 10.0)
    assert lcs._asked == {"near": "me"}
    # Not for a change that could wait (due early on a lane that goes on),
    # nor with RunOptions(open_gaps=False).
    lcs._asked = {}
    lcs.ask_courtesy("me", "t_0", 100.0, 10.0, urgent=False)
    assert lcs._asked == {} and lcs._courtesy == {}
    lcs.open_gaps_on = False
    lcs.ask_courtesy("me", "t_0", 100.0, 10.0)
    assert lcs._asked == {}
    # Not asked, a SUMO driver is passed over for a controlled vehicle
    # further back, as before gaps were asked of SUMO's drivers.
    conn.lanes["t_0"] = ["far", "near"]
    v.cars["near"]["pos"] = 80.0
    lcs.active = {"far": None}  # type: ignore[dict-item]
    lcs.ask_courtesy("me", "t_0", 100.0, 10.0)
    assert lcs._asked == {} and lcs._courtesy == {"far": ("me", pytest.approx(46.5))}
    lcs._courtesy = {}
    lcs.open_gaps_on = True
    lcs.ask_courtesy("me", "t_0", 100.0, 10.0, urgent=False)
    assert lcs._asked == {} and "far" in lcs._courtesy
    lcs._courtesy = {}
    lcs.ask_courtesy("me", "t_0", 100.0, 10.0)
    assert lcs._asked == {"near": "me"} and lcs._courtesy == {}


def test_open_gaps_switches_off_before_it_switches_on() -> None:
    """SUMO keeps one gap controller per reference vehicle, and switching one
    off clears its reference's entry: every switch-off of a step comes
    first, a follower held for the same changer is not asked again, and a
    vehicle that has left is skipped."""
    conn = FakeConn()
    v = conn.vehicle
    for vid in ("a", "b", "x", "y"):
        v.add(vid)
    lcs = lane_changes(conn)

    def step(asked: dict[str, str]) -> list[tuple[Any, ...]]:
        v.calls = []
        lcs._asked = dict(asked)
        lcs.open_gaps()
        assert lcs._asked == {} and lcs._opening == asked
        return [c[:3] for c in v.calls]

    assert step({"a": "x"}) == [("open", "a", "x")]
    assert v.calls[0][3:] == (COURTESY_SPACE_M, COURTESY_DECEL_MPS2)
    # a fell behind or passed: b opens the gap for x; a is switched off first.
    assert step({"b": "x"}) == [("off", "a"), ("open", "b", "x")]
    assert step({"b": "x"}) == []
    # b is asked by another changer: off, then on for y.
    assert step({"b": "y"}) == [("off", "b"), ("open", "b", "y")]
    assert step({}) == [("off", "b")]
    assert lcs.counts["gaps_opened"] == 3
    # Gone before it could be asked, gone before it was switched off: no error, not counted.
    assert step({"gone": "x"}) == []
    assert step({}) == [] and lcs.counts["gaps_opened"] == 3


def test_ask_courtesy_needs_more_than_half_a_metre() -> None:
    conn = FakeConn()
    v = conn.vehicle
    v.add("me", pos=100.0)
    # gap = 95 - f - 2.5 - 6 = 0.5 exactly at f = 86 (standing: no closing speed).
    v.add("f", pos=86.0, speed=0.0)
    conn.lanes["t_0"] = ["f"]
    lcs = lane_changes(conn)
    lcs.active = {"f": None}  # type: ignore[dict-item]
    lcs.ask_courtesy("me", "t_0", 100.0, 0.0)
    assert lcs._courtesy == {}
    v.cars["f"]["pos"] = 86.0 - 1e-3
    lcs.ask_courtesy("me", "t_0", 100.0, 0.0)
    assert "f" in lcs._courtesy


def test_wait_for_gap_lines_up_behind_the_tighter_neighbour() -> None:
    """Leaders on the target (right: mode 2 | 1) lane and one alongside
    (follower list, gap < 0) taken at gap 0."""
    conn = FakeConn()
    v = conn.vehicle
    v.add("me", pos=100.0, speed=10.0)
    v.add("lead", speed=10.0)
    v.add("side", speed=10.0)
    v.add("back", speed=10.0)
    lcs = lane_changes(conn)
    v.neighbours = {("me", 3): [("lead", 12.0)], ("me", 1): [("back", 7.0)]}
    lcs.wait_for_gap("me", -1, "t_0", 100.0, 10.0)
    assert lcs._merge_leads == {"me": ("lead", 12.0)}
    for alongside in (-2.0, -0.5):
        v.neighbours = {("me", 3): [("lead", 12.0)], ("me", 1): [("side", alongside), ("back", 7.0)]}
        lcs.wait_for_gap("me", -1, "t_0", 100.0, 10.0)
        assert lcs._merge_leads == {"me": ("side", 0.0)}, alongside
    # To the left: bits 2 and 0; a leader alongside (negative gap) is at 0.
    lcs._merge_leads = {}
    v.neighbours = {("me", 2): [("lead", -1.0)]}
    lcs.wait_for_gap("me", 1, "t_1", 100.0, 10.0)
    assert lcs._merge_leads == {"me": ("lead", 0.0)}
    lcs._merge_leads = {}
    v.neighbours = {}
    lcs.wait_for_gap("me", 1, "t_1", 100.0, 10.0)
    assert lcs._merge_leads == {}


def test_wait_for_gap_falls_back_behind_one_moving_alongside_on_the_last_lane() -> None:
    """A change over several lanes waits: a vehicle on its last lane whose
    body overlaps the changer's along the road, moving, is a leader at gap
    0 (``getNeighbors`` sees only the lane beside); one standing, one
    wholly behind or wholly ahead is not."""
    conn = FakeConn()
    v = conn.vehicle
    v.add("me", lane="e_2", pos=100.0, speed=20.0)  # body from 95 to 100
    v.add("level", lane="e_0", pos=98.0, speed=20.0)
    v.add("standing", lane="e_0", pos=99.0, speed=0.0)
    v.add("behind", lane="e_0", pos=95.0, speed=20.0)  # its front at the changer's back
    v.add("ahead", lane="e_0", pos=105.0 + EPS, speed=20.0)  # its back just past the changer's front
    conn.lanes = {"e_0": ["behind", "level", "standing", "ahead"]}
    lcs = lane_changes(conn)
    lcs.wait_for_gap("me", -1, "e_0", 100.0, 20.0)
    assert lcs._merge_leads == {}, "not a change over several lanes: the last lane is not looked at"
    lcs.wait_for_gap("me", -1, "e_0", 100.0, 20.0, last_lane="e_0")
    assert lcs._merge_leads == {"me": ("level", 0.0)}
    lcs._merge_leads = {}
    v.cars["level"]["speed"] = 0.9
    lcs.wait_for_gap("me", -1, "e_0", 100.0, 20.0, last_lane="e_0")
    assert lcs._merge_leads == {}, "under ALONGSIDE_MOVING_MPS"
    assert lcs.alongside_on_lane("me", "e_0", 100.0) == []
    v.cars["ahead"]["pos"] = 105.0 - EPS
    assert lcs.alongside_on_lane("me", "e_0", 100.0) == ["ahead"]


@pytest.mark.parametrize("direction", [1, -1])
def test_a_leader_is_left_behind_once_the_change_clears_it_before_its_min_gap(direction: int) -> None:
    """``left_behind``: the change's smoothstep must have the vehicle clear
    of a standing leader (half the two widths plus ``LANE_CHANGE_CLEAR_M``
    sideways) when its front comes within minGap of the leader's back,
    where SUMO counts a collision; judged at the leader's back, a car on
    highway_onramp "collided" 1.6 m across. Lanes 5 m wide (5 m between
    centres), cars 2 m wide: clear needs 2.5 m, smoothstep 0.5, reached
    10 m into the 20 m change, whose front axle starts 2 m behind the
    front at 95 m: the front at 100 m + gap 7 m."""
    conn = FakeConn()
    v = conn.vehicle
    target = 1 if direction > 0 else 0
    own = "e_0" if direction > 0 else "e_1"
    v.add("me", lane=own, pos=100.0, speed=2.0, lat=direction * 1.0)  # 1 m across: committed
    v.add("lead", lane=own, speed=0.0)
    lcs = lane_changes(conn, lanes={"e_0": FakeLane(200.0, 5.0), "e_1": FakeLane(200.0, 5.0)})
    act = SimpleNamespace(vid="me", change_span=(95.0, 20.0), changing=(direction, target), tactical=False)
    assert lcs.left_behind(act, ("lead", 7.0 + 1e-6)) is True  # type: ignore[arg-type]
    assert lcs.left_behind(act, ("lead", 7.0 - 1e-6)) is False  # type: ignore[arg-type]
    # Not committed (under ABORT_CHANGE_LAT_M across) and, at 6 m/s, too
    # close to stop at the planning deceleration (4 m/s^2: 4.5 m + 5 m): it counts.
    v.cars["me"]["lat"] = direction * 0.3
    v.cars["me"]["speed"] = 6.0
    assert lcs.left_behind(act, ("lead", 7.0 + 1e-6)) is False  # type: ignore[arg-type]
    # The leader's back beyond the lane's end: it counts.
    v.cars["me"]["lat"] = direction * 1.0
    v.cars["me"]["pos"] = 200.0 - 7.5
    act.change_span = (187.5, 20.0)
    assert lcs.left_behind(act, ("lead", 7.0 + 1e-6)) is False  # type: ignore[arg-type]


def test_a_lane_change_starts_where_sumo_has_the_front_when_it_is_a_little_ahead() -> None:
    """``sumo_ahead``: SUMO's front on the same lane up to 5 m ahead of
    blendtrack's is where the change starts; behind it, further ahead (a
    lost vehicle), on another lane or gone, nothing moves."""
    conn = FakeConn()
    v = conn.vehicle
    v.add("me", lane="e_1", pos=32.2)
    lcs = lane_changes(conn)
    assert abs(lcs.sumo_ahead("me", "e_1", 30.0) - 2.2) < EPS
    assert lcs.sumo_ahead("me", "e_1", 32.2) == 0.0
    assert lcs.sumo_ahead("me", "e_1", 33.0) == 0.0, "SUMO behind: never moved back"
    assert lcs.sumo_ahead("me", "e_1", 32.2 - 5.0 - 1e-6) == 0.0, "more than 5 m: a lost vehicle"
    assert abs(lcs.sumo_ahead("me", "e_1", 32.2 - 5.0 + 1e-6) - (5.0 - 1e-6)) < EPS
    assert lcs.sumo_ahead("me", "e_0", 30.0) == 0.0, "on another lane"
    assert lcs.sumo_ahead("gone", "e_1", 30.0) == 0.0


# ------------------------------------------------------------ junctions
def junctions(conn: FakeConn, foes: list[tuple[Any, ...]], plan_decel: float = 4.0,
              crossing: tuple[float, float] | None = None, shapes: dict[str, np.ndarray] | None = None) -> Junctions:
    """Junctions on a fake network: ``foes`` the internal foes of every
    lane, ``crossing`` where every two ways cross (None: they do not),
    ``shapes`` the centrelines of junction lanes (the others far away)."""
    shapes = {} if shapes is None else shapes
    network = SimpleNamespace(internal_foes=lambda via: foes, internal_vias={":j_w"}, waiting_point_after=lambda via: (None, 0.0),
                              junction_lanes=lambda via: (None, []), crossing=lambda via, foe: crossing,
                              # Far from every vehicle unless a test moves it.
                              lane_shape=lambda lane: (shapes.get(lane, np.array([[1e3, 1e3], [1e3 + 1.0, 1e3]])), 3.2))
    return Junctions(conn, network, None, None, plan_decel)  # type: ignore[arg-type]


def test_a_foe_inside_the_junction_counts_until_it_is_past_the_crossing() -> None:
    """The ways cross 10 m into the foe's junction lane: a foe whose back
    is 2.5 m past that has gone by; one nearer is in the way, or arrives
    (accelerating at its accel) within the 4 s the vehicle needs; an
    impatient vehicle lets one come that could still stop for it."""
    conn = FakeConn()
    v = conn.vehicle
    v.add("me")
    v.add("o", pos=17.5 + 1e-3, length=5.0)
    conn.lanes[":j_foe"] = ["o"]
    j = junctions(conn, [(":j_foe", None, 0.0, "", -1)], crossing=(5.0, 10.0))
    assert not j.internal_junction_busy("me", ":j_w", gap=1.0), "back 2.5 m past the crossing"
    v.cars["o"]["pos"] = 17.5 - 1e-3
    assert j.internal_junction_busy("me", ":j_w", gap=1.0), "its back is still near it"
    # Standing 4.5 m before the point (its front 2.5 m short of it):
    # arrives in sqrt(2 * 4.5 / 2.6) = 1.9 s.
    v.cars["o"].update(pos=3.0, speed=0.0)
    assert j.internal_junction_busy("me", ":j_w", gap=1.0)
    assert j.internal_junction_busy("me", ":j_w", horizon_s=1.8) is False
    # Impatient (0.1 x 30 s = 3 s later: 4.9 s >= 4 s): it goes, the foe
    # standing 2 m more than its minGap short of the point.
    v.cars["me"]["impatience"] = 0.1
    assert not j.internal_junction_busy("me", ":j_w", gap=1.0)
    assert j.internal_junction_busy("me", ":j_w"), "no gap given: no impatience"
    # Moving at 5 m/s it could not stop: it drives on 2 s (the two steps the
    # vehicle, 1 m before its line, needs to get over it), 10 m.
    v.cars["o"]["speed"] = 5.0
    j.went.clear()
    assert j.internal_junction_busy("me", ":j_w", gap=1.0)


def test_an_impatient_vehicle_lets_a_foe_come_that_could_stop_and_keeps_its_impatience() -> None:
    """At an internal waiting point, 4 s of horizon: a foe at 8 m/s 31 m
    from its line arrives in 3.9 s. Patient, the vehicle waits; with an
    impatience of 0.1 (3 s) it goes, the foe able to stop (2 s at 8 m/s,
    16 m, then 7.1 m braking at 4.5 m/s^2, within 31 m less its minGap).
    Moving, SUMO's impatience is 0 again: the one it went with holds for
    this waiting point until its front is over the line."""
    conn = FakeConn()
    v = conn.vehicle
    v.add("me")
    v.add("o", pos=19.0, speed=8.0)
    conn.lanes["in_0"] = ["o"]
    j = junctions(conn, [(":j_foe", "in_0", 50.0, "", -1)])
    assert j.internal_junction_busy("me", ":j_w", gap=1.0)
    v.cars["me"]["impatience"] = 0.1
    assert not j.internal_junction_busy("me", ":j_w", gap=1.0)
    assert j.went == {"me": (":j_w", 0.1)}
    v.cars["me"]["impatience"] = 0.0
    assert not j.internal_junction_busy("me", ":j_w", gap=1.0)
    j.went["me"] = (":j_other", 0.1)
    assert j.internal_junction_busy("me", ":j_w", gap=1.0), "kept for another point only"
    # A foe that could not stop counts however impatient: at 12 m/s, 24 m
    # in 2 s and 16 m braking, more than its 31 m less its minGap.
    v.cars["me"]["impatience"] = 1.0
    v.cars["o"]["speed"] = 12.0
    assert j.internal_junction_busy("me", ":j_w", gap=1.0)
    j.forget("me")
    assert "me" not in j.went


def test_impatience_never_counts_on_a_controlled_foe_to_brake() -> None:
    """The foe of the impatience test (8 m/s, 31 m from its line, able to
    stop for the vehicle) is let come by an impatient vehicle when SUMO
    drives it, never when blendtrack does: a controlled vehicle brakes for
    one crossing its way only once that one's body is near its path
    (``junction_blocked``), too late at speed. At Bologna's junction 51 a
    controlled vehicle from the minor road went, impatient, 3.5 s ahead of
    a controlled one at 13.7 m/s on the major road, which drove into it
    (seed 9, 449 s)."""
    conn = FakeConn()
    v = conn.vehicle
    v.add("me", impatience=1.0)
    v.add("o", pos=19.0, speed=8.0)
    conn.lanes["in_0"] = ["o"]
    j = junctions(conn, [(":j_foe", "in_0", 50.0, "", -1)])
    assert not j.internal_junction_busy("me", ":j_w", gap=1.0)
    j.went.clear()
    j.controlled = {"o": None}
    assert j.internal_junction_busy("me", ":j_w", gap=1.0)
    assert j.went == {}


def test_internal_junction_busy_with_a_foe_inside_or_near() -> None:
    conn = FakeConn()
    v = conn.vehicle
    v.add("me")
    conn.lanes[":j_foe"] = ["me"]
    j = junctions(conn, [(":j_foe", None, 50.0, "", -1)])
    assert not j.internal_junction_busy("me", ":j_w"), "the vehicle itself is no foe"
    for foe in ("x", "a"):  # any other vehicle, whatever its id
        conn.lanes[":j_foe"] = ["me", foe]
        assert j.internal_junction_busy("me", ":j_w"), foe
    # On the incoming lane, 50 m long: busy within 4 s (at 10 m/s: 40 m) or 5 m of the line.
    conn.lanes = {"in_0": ["o"]}
    j = junctions(conn, [(":j_foe", "in_0", 50.0, "", -1)])
    v.add("o", pos=10.0 + 1e-3, speed=10.0)
    assert j.internal_junction_busy("me", ":j_w")
    v.cars["o"]["pos"] = 10.0 - 1e-3
    assert not j.internal_junction_busy("me", ":j_w")
    assert j.internal_junction_busy("me", ":j_w", horizon_s=4.1)
    v.cars["o"].update(pos=45.0 + 1e-3, speed=0.0)
    assert j.internal_junction_busy("me", ":j_w")
    v.cars["o"]["pos"] = 45.0 - 1e-3
    assert not j.internal_junction_busy("me", ":j_w")
    # Standing 5 m or nearer to its line: busy, unless it is a controlled
    # vehicle told last step to wait there (it waits for the vehicles
    # inside the junction: the two had waited for each other for good).
    v.cars["o"]["pos"] = 49.0
    assert j.internal_junction_busy("me", ":j_w")
    j.waiting = {"o"}
    assert not j.internal_junction_busy("me", ":j_w")
    v.cars["o"]["speed"] = 0.5  # moving off: about to enter
    assert j.internal_junction_busy("me", ":j_w")
    v.cars["o"]["speed"] = 0.0
    j.new_step()  # nobody was told to wait in the step before
    assert j.internal_junction_busy("me", ":j_w")
    # One of SUMO's drivers standing there whose next link SUMO says lacks
    # priority with a foe approaching (this vehicle in the junction): held.
    # (lane, has priority, is open, has foe, via, state, direction, length)
    v.links["o"] = [("out_0", False, True, True, ":j_foe", "m", "s", 5.0)]
    assert not j.internal_junction_busy("me", ":j_w")
    v.links["o"] = [("out_0", False, True, False, ":j_foe", "m", "s", 5.0)]  # no foe: it goes
    assert j.internal_junction_busy("me", ":j_w")
    v.links["o"] = [("out_0", True, True, True, ":j_foe", "M", "s", 5.0)]  # priority: it goes
    assert j.internal_junction_busy("me", ":j_w")
    # A controlled vehicle is never judged by SUMO's word, only by blendtrack's.
    v.links["o"] = [("out_0", False, True, True, ":j_foe", "m", "s", 5.0)]
    j.controlled = {"o": None}
    assert j.internal_junction_busy("me", ":j_w")


def test_a_held_foe_a_turner_went_on_stays_held_until_the_turner_is_through() -> None:
    """The race traced on the shipped grid (junction D1): a left turner went
    from its waiting point because the oncoming controlled vehicle stood
    held at its line, and in the same step that vehicle was let go; 2.6 s
    later they met. Now the turner going records the hold; the held vehicle
    is kept at its line into that junction while the turner is on the edge
    it went from or on a lane of that junction, and not told to wait since;
    released otherwise (and then not counted as held by anyone this step).
    A vehicle already let go this step is no held foe for a turner deciding
    after it."""
    conn = FakeConn()
    v = conn.vehicle
    v.add("me", lane="in_w_0")
    v.add("o", pos=49.0, speed=0.0, lane="in_0")
    conn.lanes = {"in_0": ["o"]}
    j = junctions(conn, [(":j_foe", "in_0", 50.0, "", -1)])
    j.controlled = {"me": None, "o": None}
    front = {"o": 49.0}
    via = {"o": ":j_foe_0"}  # the held vehicle's next junction lane
    j.fleet = SimpleNamespace(next_stop=lambda slot: (50.0, 0, 0, 0, 7), s_front=lambda slot: front["o"])  # type: ignore[assignment]
    j.tracks = SimpleNamespace(lanes=SimpleNamespace(name=lambda i: via["o"]))  # type: ignore[assignment]
    j._must_yield = lambda vid, slot: False  # type: ignore[method-assign]
    # Not held last step: the standing foe 1 m from its line makes the turner wait.
    assert j.internal_junction_busy("me", ":j_w")
    assert j.holds == {}
    # Held last step: the turner goes and counts on it.
    j.waiting = {"o"}
    assert not j.internal_junction_busy("me", ":j_w")
    assert j.holds == {"o": ("me", "in_w", ":j_")}
    # Its own answer is "go", yet it stays: the turner is on its edge, then in the junction.
    assert j.must_yield("o", 0)
    j.new_step()
    v.cars["me"]["lane"] = ":j_w_0"
    assert j.must_yield("o", 0) and "o" in j._waiting_now
    # The turner told to wait since (at its point, for another foe): released.
    j.new_step()
    j._waiting_now.add("me")
    assert not j.must_yield("o", 0) and j.holds == {}
    # Held again; the turner out of the junction onto the next edge: released.
    j.holds = {"o": ("me", "in_w", ":j_")}
    j.new_step()
    j.new_step()  # the turner's wait is two steps back now
    assert j.must_yield("o", 0)
    v.cars["me"]["lane"] = "out_w_0"
    assert not j.must_yield("o", 0) and j.holds == {}
    # Held again; the turner inside another junction: released.
    j.holds = {"o": ("me", "in_w", ":j_")}
    v.cars["me"]["lane"] = ":k_3_0"
    assert not j.must_yield("o", 0) and j.holds == {}
    # Held again, the turner in the junction, but the held vehicle's next
    # line is into another junction (a hold left over): released.
    j.holds = {"o": ("me", "in_w", ":j_")}
    v.cars["me"]["lane"] = ":j_w_0"
    via["o"] = ":k_1_0"
    assert not j.must_yield("o", 0) and j.holds == {}
    via["o"] = ":j_foe_0"
    # A held vehicle whose front is already past its line is never kept there.
    j.holds = {"o": ("me", "in_w", ":j_")}
    v.cars["me"]["lane"] = ":j_w_0"
    front["o"] = 50.5
    assert not j.must_yield("o", 0) and j.holds == {}
    # Let go this step before the turner decides: no held foe for it.
    front["o"] = 49.0
    j.new_step()
    j.waiting = {"o"}
    assert not j.must_yield("o", 0)
    assert j.internal_junction_busy("me", ":j_w")
    assert j.holds == {}


def test_a_vehicle_just_over_its_line_that_can_stop_is_still_asked() -> None:
    """Braking for its internal waiting point, a left turner on the grid
    stopped 4 cm past it, was taken as in the junction and went on into the
    oncoming vehicle. Past its waiting point by under 0.5 m (the Rust plan
    keeps the stop that long) and able to stop within those 0.5 m at the
    planning deceleration (4 m/s^2: v^2 <= 8 (0.5 - past)), it is still
    asked; further past, or too fast, or past a junction's entry line, it is
    in and clears the junction."""
    conn = FakeConn()
    v = conn.vehicle
    v.add("me", speed=0.8)
    v.add("o", pos=45.0, speed=10.0, lane="in_0")
    conn.lanes = {"in_0": ["o"]}
    j = junctions(conn, [(":j_foe", "in_0", 50.0, "", -1)])
    j.network.is_zipper = lambda via: False
    j.tracks = SimpleNamespace(lanes=SimpleNamespace(name=lambda i: ":j_w"))  # type: ignore[assignment]
    front = {"me": 99.0}
    j.fleet = SimpleNamespace(next_stop=lambda slot: (100.0, 0, 0, 0, 7), s_front=lambda slot: front["me"])  # type: ignore[assignment]
    assert j.must_yield("me", 0), "before its line, with a foe 0.5 s away"
    front["me"] = 100.04
    assert j.must_yield("me", 0), "4 cm over at 0.8 m/s: it can stop"
    boundary = math.sqrt(8.0 * (0.5 - 0.04))
    v.cars["me"]["speed"] = boundary - 1e-6
    assert j.must_yield("me", 0)
    v.cars["me"]["speed"] = boundary + 1e-6
    assert not j.must_yield("me", 0), "too fast to stop within 0.5 m: in"
    v.cars["me"]["speed"] = 0.0
    front["me"] = 100.5
    assert not j.must_yield("me", 0), "0.5 m over: in"
    # Over a junction's entry line (no internal waiting point), any distance
    # over is in: a vehicle crossing a stream, asked again there, stood.
    front["me"] = 100.04
    assert j.must_yield("me", 0)
    j.network.internal_vias = set()
    assert not j.must_yield("me", 0)


def test_internal_junction_busy_reads_the_foes_light() -> None:
    """Foe at 23 m from its line at 13.8 m/s (the traced case): at yellow it
    needs 13.8 * 1 + 13.8^2 / 6 = 45.5 m to stop, so it comes through; at
    red it stops; at green it is 1.7 s away: busy."""
    conn = FakeConn()
    v = conn.vehicle
    v.add("me")
    v.add("o", pos=50.0 - 23.0, speed=13.8)
    conn.lanes = {"in_0": ["o"]}
    j = junctions(conn, [(":j_foe", "in_0", 50.0, "tl", 1)])
    for state, busy in [("rGr", True), ("ryr", True), ("rYr", True), ("grg", False), ("GsG", True), ("rgr", True), ("ror", True), ("rOr", True), ("rur", False)]:
        j.tls_state["tl"] = state
        assert j.internal_junction_busy("me", ":j_w") is busy, state
    # Yellow: just able to stop (45.54 m) is not busy; 1 cm closer is.
    need = 13.8 + 13.8**2 / 6.0
    j.tls_state["tl"] = "ryr"
    v.cars["o"]["pos"] = 50.0 - need - 0.01
    assert not j.internal_junction_busy("me", ":j_w")
    v.cars["o"]["pos"] = 50.0 - need + 0.01
    assert j.internal_junction_busy("me", ":j_w")
    # A link index outside the state string (unknown): the foe is looked at as at green.
    v.cars["o"]["pos"] = 30.0
    j = junctions(conn, [(":j_foe", "in_0", 50.0, "tl", 3)])
    j.tls_state["tl"] = "rrr"
    assert j.internal_junction_busy("me", ":j_w")
    j = junctions(conn, [(":j_foe", "in_0", 50.0, "tl", -1)])
    j.tls_state["tl"] = "rrr"
    assert j.internal_junction_busy("me", ":j_w")
    j = junctions(conn, [(":j_foe", "in_0", 50.0, "tl", 0)])
    j.tls_state["tl"] = "r"
    assert not j.internal_junction_busy("me", ":j_w")
    # The vehicle itself on the incoming lane is no foe.
    conn.lanes = {"in_0": ["me"]}
    v.cars["me"].update(pos=49.0, speed=10.0)
    j.tls_state["tl"] = "G"
    assert not j.internal_junction_busy("me", ":j_w")


def test_refresh_tls_passes_on_changed_lights_only() -> None:
    conn = FakeConn()
    sent: list[tuple[int, str]] = []
    fleet = SimpleNamespace(set_signal=lambda light, state: sent.append((light, state)))
    tracks = SimpleNamespace(lights=SimpleNamespace(id={"a": 0, "b": 1}.__getitem__))
    j = Junctions(conn, None, tracks, fleet, 4.0)  # type: ignore[arg-type]
    key = tc.TL_RED_YELLOW_GREEN_STATE
    conn.tls_results = {"a": {key: "Gr"}, "b": {key: "rG"}}
    conn.tls_now.update(a="Gr", b="rG")
    j.refresh_tls(0.0)
    assert sorted(sent) == [(0, "Gr"), (1, "rG")]
    sent.clear()
    conn.tls_now.update(b="ry")
    j.refresh_tls(0.0)
    assert sent == [(1, "ry")] and j.tls_state == {"a": "Gr", "b": "ry"}
    # A light switched by another client after the step: its state now, not
    # the subscription's of the step (the same on libsumo and TraCI).
    sent.clear()
    conn.tls_now.update(a="rr")
    j.refresh_tls(0.0)
    assert sent == [(0, "rr")]


def test_refresh_tls_reads_each_light_where_none_is_subscribed() -> None:
    """With libsumo and no step hook the lights are not subscribed to:
    each light's state is read, and only the changed ones are passed on."""
    conn = FakeConn()
    conn.light_subscriptions = False
    conn.lights = ("a", "b")
    sent: list[tuple[int, str]] = []
    fleet = SimpleNamespace(set_signal=lambda light, state: sent.append((light, state)))
    tracks = SimpleNamespace(lights=SimpleNamespace(id={"a": 0, "b": 1}.__getitem__))
    j = Junctions(conn, None, tracks, fleet, 4.0)  # type: ignore[arg-type]
    conn.tls_now.update(a="Gr", b="rG")
    j.refresh_tls(0.0)
    assert sent == [(0, "Gr"), (1, "rG")]
    sent.clear()
    conn.tls_now.update(b="ry")
    j.refresh_tls(0.0)
    assert sent == [(1, "ry")] and j.tls_state == {"a": "Gr", "b": "ry"}


def test_a_lanes_vehicles_are_read_from_sumo_once_a_step() -> None:
    """``SumoConnection.vehicles_on``: SUMO's list of a lane's vehicles is
    read on first use in a step and kept for the step's later look-ups."""
    from blendtrack.sumo.connection import SumoConnection

    reads: list[str] = []
    on = {"a_0": ("x", "y"), "b_0": ()}

    class Domain:
        def __getattr__(self, name: str) -> Any:
            return lambda *args: None

    lane = SimpleNamespace(getLastStepVehicleIDs=lambda ln: reads.append(ln) or on[ln])
    conn = SumoConnection.__new__(SumoConnection)
    conn.backend = "traci"
    conn.sumo = SimpleNamespace(vehicle=Domain(), lane=lane, trafficlight=Domain())
    conn.leader_speeds = {}
    conn._bind_calls()
    assert conn.vehicles_on("a_0") == ("x", "y") and conn.vehicles_on("b_0") == ()
    assert conn.vehicles_on_lanes(["b_0", "a_0", "a_0"]) == [(), ("x", "y"), ("x", "y")]
    assert reads == ["a_0", "b_0"]
    on["a_0"] = ("y",)
    conn.new_step()
    assert conn.vehicles_on("a_0") == ("y",) and reads == ["a_0", "b_0", "a_0"]


def yield_setup(links: list[tuple[Any, ...]], via: str = "in_0_to", waiting: tuple[Any, float] = (None, 0.0),
                light: int = -1) -> tuple[FakeConn, Junctions, dict[str, Any]]:
    conn = FakeConn()
    conn.vehicle.add("me", speed=10.0)
    conn.vehicle.links["me"] = links
    seen: dict[str, Any] = {"busy": False, "blocked": False, "horizon": None}
    # The stop 100 m on: (s, light, link index 1, major, via lane 7).
    fleet = SimpleNamespace(next_stop=lambda slot: (100.0, light, 1, 0, 7), s_front=lambda slot: 80.0)
    tracks = SimpleNamespace(lanes=SimpleNamespace(name=lambda k: via), lights=SimpleNamespace(name=lambda k: f"tl{k}"))
    # No link state known (""): the decision rests on SUMO's getNextLinks; no zipper.
    network = SimpleNamespace(internal_vias={":j_w"}, waiting_point_after=lambda v: waiting,
                              is_zipper=lambda v: False, link_state=lambda v: "", lanes_after=lambda v: [], lanes_next=lambda lane: (), internal_foes=lambda v: [])
    j = Junctions(conn, network, tracks, fleet, 4.0)  # type: ignore[arg-type]

    def busy(vid: str, lane: str, horizon_s: float = jn.INTERNAL_YIELD_S, gap: float | None = None) -> bool:
        seen["horizon"] = horizon_s
        seen["lane"] = lane
        return bool(seen["busy"])

    j.internal_junction_busy = busy  # type: ignore[method-assign]
    j.junction_blocked = lambda vid, lane: bool(seen["blocked"])  # type: ignore[method-assign]
    return conn, j, seen


def test_must_yield_on_a_link_without_priority_with_foes() -> None:
    # getNextLinks rows: (lane, has priority, is open, has foe, via lane, ...)
    _, j, seen = yield_setup([("x", True, True, True, "other"), ("in_1", False, True, True, "in_0_to")])
    assert j.must_yield("me", 0)
    _, j, seen = yield_setup([("in_1", True, True, True, "in_0_to")])
    assert not j.must_yield("me", 0)
    _, j, seen = yield_setup([("in_1", False, True, False, "in_0_to")])
    assert not j.must_yield("me", 0)
    seen["blocked"] = True
    assert j.must_yield("me", 0), "a vehicle inside the junction in the way"
    # Only the first link through the via counts.
    _, j, seen = yield_setup([("in_1", True, True, False, "in_0_to"), ("in_1", False, True, True, "in_0_to")])
    assert not j.must_yield("me", 0)
    conn, j, seen = yield_setup([])
    j.fleet.next_stop = lambda slot: None
    seen["blocked"] = True
    assert not j.must_yield("me", 0), "no stop ahead: nothing to yield at"


def test_a_vehicle_that_has_entered_across_a_way_with_priority_is_waited_for() -> None:
    """"me" at 10 m/s is 20 m from its line (it can stop: 100 <= 2 x 4 x
    20) on a link with priority whose way crosses the foe's 5 m in (6 m
    into the foe's junction lane). It crosses, accelerating at 1 m/s^2,
    in sqrt(100 + 2 x (20 + 5 + 2.5 + 5)) - 10 + 1 = 3.85 s. A SUMO driver
    standing 0.01 m into the foe lane gets 2.5 m short of the crossing
    (3.49 m) in sqrt(2 x 3.49 / 2.6) = 1.64 s: waited for. Not when "me"
    could no longer stop at its line (13 m/s: 169 > 160), nor for a driver
    whose back is 2.5 m past the crossing, nor on a foe lane that ends at
    an internal waiting point, nor where the ways merge."""
    conn = FakeConn()
    v = conn.vehicle
    v.add("me", speed=10.0, length=5.0)
    v.add("s", speed=0.0, pos=0.01, length=5.0, lane=":j_foe")
    conn.lanes[":j_foe"] = ["s"]
    stops_inside = {":j_foe": False}
    crossing: dict[str, Any] = {":j_foe": (5.0, 6.0)}
    network = SimpleNamespace(internal_foes=lambda via: [(":j_foe", "foe_in", 50.0, "", -1), (":j_foe2", None, 0.0, "", -1)],
                              crossing=lambda via, foe: crossing[foe],
                              stops_inside=lambda foe: stops_inside[foe])
    fleet = SimpleNamespace(s_front=lambda slot: 80.0)
    j = Junctions(conn, network, None, fleet, 4.0)  # type: ignore[arg-type]
    assert j.entered_across("me", 0, ":j_me", 100.0)
    assert j.counts["entered_across_waits"] == 1
    v.cars["me"]["speed"] = 13.0
    assert not j.entered_across("me", 0, ":j_me", 100.0), "too late to stop at its line"
    v.cars["me"]["speed"] = 10.0
    v.cars["s"]["pos"] = 6.0 + 2.5 + 5.0 + 1e-6
    assert not j.entered_across("me", 0, ":j_me", 100.0), "its back is past the crossing"
    v.cars["s"]["pos"] = 0.01
    crossing[":j_foe"] = None
    assert not j.entered_across("me", 0, ":j_me", 100.0), "the ways merge"
    crossing[":j_foe"] = (5.0, 6.0)
    stops_inside[":j_foe"] = True
    assert not j.entered_across("me", 0, ":j_me", 100.0), "a left turner waits at its internal point"


def test_must_yield_asks_sumo_only_where_the_link_lacks_priority_now() -> None:
    """SUMO's getNextLinks says a link has priority where its state is an
    upper-case letter: at a light showing G for the link (this step's
    state) it is not asked; at g (green without priority) it is, and its
    answer counts."""
    calls: list[str] = []
    for shown, asked, wait in (("rGr", False, False), ("rgr", True, True), ("r", True, True)):
        conn, j, _ = yield_setup([("in_1", False, True, True, "in_0_to")], light=3)
        j.tls_state["tl3"] = shown
        get_links = conn.vehicle.getNextLinks
        calls.clear()
        conn.vehicle.getNextLinks = lambda vid: calls.append(vid) or get_links(vid)  # type: ignore[method-assign]
        assert j.must_yield("me", 0) is wait, shown
        assert bool(calls) is asked, shown
    # Without a light, by the network's state: M has priority, m does not.
    for state, asked in (("M", False), ("m", True)):
        conn, j, _ = yield_setup([("in_1", False, True, True, "in_0_to")])
        j.network.link_state = lambda v, state=state: state  # type: ignore[attr-defined]
        j.link_busy = lambda *a: False  # type: ignore[method-assign]
        calls.clear()
        get_links = conn.vehicle.getNextLinks
        conn.vehicle.getNextLinks = lambda vid: calls.append(vid) or get_links(vid)  # type: ignore[method-assign]
        assert j.must_yield("me", 0) is asked and bool(calls) is asked, state


def keep_clear_setup(out_len: float = 50.0, keep_clear: bool = True, roundabout: frozenset[str] = frozenset()
                     ) -> tuple[FakeConn, Junctions]:
    """``me`` on lane in_0 at 80 m, 6 m/s, its line at 100 m; its way
    :j_0_0 (10 m) leads onto out_0 (``out_len``). Every body 5 m with a
    2.5 m minGap: it needs 7.5 m on out_0."""
    conn = FakeConn()
    conn.vehicle.add("me", speed=6.0, pos=80.0, lane="in_0")
    conn.lanes = {"in_0": ["me"], ":j_0_0": [], "out_0": []}
    after = {":j_0_0": [(":j_0_0", 10.0), ("out_0", out_len)]}
    network = SimpleNamespace(lanes_after=lambda v: after.get(v, []), lanes_next=lambda lane: (), keeps_clear=lambda v: keep_clear,
                              in_roundabout=lambda edge: edge in roundabout)
    return conn, Junctions(conn, network, None, None, 4.0)  # type: ignore[arg-type]


def test_keep_clear_room_behind_the_last_standing_vehicle_in_closed_form() -> None:
    """SUMO's keep-clear rule: the room on the lane out is the back of its
    rearmost standing vehicle less the gross lengths (length + minGap) of
    the moving ones behind it, of the ones inside the junction on the same
    way and of the ones ahead on the vehicle's own lane."""
    conn, j = keep_clear_setup()
    blocked = lambda: j.exit_blocked("me", 0, ":j_0_0", 20.0)  # noqa: E731
    assert not blocked(), "an empty lane out"
    conn.vehicle.add("s", speed=0.0, pos=12.5, lane="out_0")  # back at 7.5 m
    conn.lanes["out_0"] = ["s"]
    assert not blocked(), "exactly 7.5 m of room"
    conn.vehicle.cars["s"]["pos"] = 12.5 - 1e-6
    assert blocked()
    conn.vehicle.cars["s"]["pos"] = 30.0  # back at 25 m
    conn.vehicle.add("m", speed=3.0, pos=20.0, lane="out_0")
    conn.lanes["out_0"] = ["m", "s"]  # back to front
    assert not blocked(), "25 - 7.5 = 17.5 m"
    conn.vehicle.add("i", speed=3.0, pos=5.0, lane=":j_0_0")
    conn.lanes[":j_0_0"] = ["i"]
    conn.vehicle.add("f", speed=0.0, pos=95.0, lane="in_0")
    conn.lanes["in_0"] = ["me", "f"]
    assert blocked(), "25 - 3 * 7.5 = 2.5 m"
    conn.vehicle.cars["s"]["pos"] = 35.0
    assert not blocked(), "30 - 3 * 7.5 = 7.5 m"
    conn.vehicle.cars["s"]["pos"] = 35.0 - 1e-6
    assert blocked()
    conn.vehicle.cars["s"]["speed"] = 0.2
    assert not blocked(), "nobody standing on the lane out: SUMO's drivers go"
    assert j.counts["keep_clear_waits"] == 3


def test_keep_clear_exemptions() -> None:
    """Not judged: a link with keepClear 0, a short lane out, a lane out
    in a roundabout, and a vehicle that cannot stop gently before its line."""
    for kw in ({"keep_clear": False}, {"out_len": 19.0}, {"roundabout": frozenset({"out"})}, {}):
        conn, j = keep_clear_setup(**kw)  # type: ignore[arg-type]
        conn.vehicle.add("s", speed=0.0, pos=6.0, lane="out_0")
        conn.lanes["out_0"] = ["s"]
        # 6 m/s stops within 36 / 8 = 4.5 m at 4 m/s^2.
        assert j.exit_blocked("me", 0, ":j_0_0", 4.5) is (not kw), kw
        assert not j.exit_blocked("me", 0, ":j_0_0", 4.5 - 1e-3), kw


def test_must_yield_at_an_internal_waiting_point_asks_the_foes() -> None:
    _, j, seen = yield_setup([], via=":j_w")
    assert not j.must_yield("me", 0)
    seen["busy"] = True
    assert j.must_yield("me", 0) and seen["lane"] == ":j_w" and seen["horizon"] == jn.INTERNAL_YIELD_S


def test_must_yield_holds_a_fast_turner_at_the_entry() -> None:
    """Stop 20 m ahead (100 - 80), waiting point 6 m in, 1 m short: room
    25 m. Gentle stop at 0.5 * 4 = 2 m/s^2 from v needs v^2 / 4 m: held
    when v > 10 m/s, and it looks 4 s + 25 m / v ahead."""
    conn, j, seen = yield_setup([], waiting=(":j_w", 6.0))
    seen["busy"] = True
    conn.vehicle.cars["me"]["speed"] = 10.0 + 1e-3
    assert j.must_yield("me", 0)
    assert seen["horizon"] == pytest.approx(4.0 + 25.0 / (10.0 + 1e-3)) and seen["lane"] == ":j_w"
    conn.vehicle.cars["me"]["speed"] = 10.0 - 1e-3
    seen["horizon"] = None
    assert not j.must_yield("me", 0) and seen["horizon"] is None
    conn.vehicle.cars["me"]["speed"] = 12.0
    seen["busy"] = False
    assert not j.must_yield("me", 0)


def test_a_foe_standing_at_its_line_with_the_body_across_its_way_is_not_about_to_enter() -> None:
    """At an internal waiting point, a foe standing 1 m from its line (link
    open) counts as about to enter, unless the waiting vehicle's body
    stands across the foe's way: within its half width (1 m) + a car's
    half width (0.9) + 0.3 m of the foe junction lane's centreline. Then
    the foe waits for it (SUMO's drivers yield to a vehicle inside the
    junction in their way), and the two would wait for each other
    (Bologna, junction 9). The body: front (10, 0) facing east, 5 m long;
    the foe lane runs north along x = X, 2.2 m off at X = 12.2. A foe
    that moves, or one farther back on its lane, still counts."""
    conn = FakeConn()
    v = conn.vehicle
    v.add("me", xy=(10.0, 0.0), angle=90.0, length=5.0, width=2.0)
    v.add("o", pos=49.0, speed=0.0)
    conn.lanes["in_0"] = ["o"]
    shapes: dict[str, np.ndarray] = {}
    j = junctions(conn, [(":j_foe", "in_0", 50.0, "", -1)], shapes=shapes)
    assert j.internal_junction_busy("me", ":j_w"), "the foe lane far away"
    shapes[":j_foe"] = np.array([[12.2 + 1e-3, -10.0], [12.2 + 1e-3, 10.0]])
    assert j.internal_junction_busy("me", ":j_w"), "just out of reach"
    shapes[":j_foe"] = np.array([[12.2 - 1e-3, -10.0], [12.2 - 1e-3, 10.0]])
    assert not j.internal_junction_busy("me", ":j_w")
    v.cars["o"]["speed"] = 0.5
    assert j.internal_junction_busy("me", ":j_w"), "moving off: about to enter"
    v.cars["o"]["speed"] = 0.0
    # Across the body itself (the foe lane through its middle): not about to enter.
    shapes[":j_foe"] = np.array([[7.5, -10.0], [7.5, 10.0]])
    assert not j.internal_junction_busy("me", ":j_w")


def test_junction_blocked_by_a_body_within_the_half_width() -> None:
    """Path through the junction along y = 0 from x = 0 to 20; the entering
    vehicle 2 m wide: reach 1 + 0.3 m, plus the other's half width 1 m. A
    vehicle inside facing north (angle 0) with its front at (10, y) and 5 m
    long reaches down to y - 5: blocked while y - 5 < 2.3."""
    import numpy as np

    conn = FakeConn()
    v = conn.vehicle
    v.add("me", width=2.0)
    v.add("o", width=2.0, length=5.0, angle=0.0, xy=(10.0, 7.3 - 1e-3))
    conn.lanes[":j_0"] = ["me", "o"]
    path = np.array([[0.0, 0.0], [20.0, 0.0]])
    origin = {"in_0": "a_0", ":j_0": "b_0"}
    exits: list[str] = []
    network = SimpleNamespace(junction_lanes=lambda via: (path, [":j_0"]), from_lane=lambda lane: origin.get(lane),
                              junction_exits=lambda via: tuple(exits), waiting_points_near=lambda via: ())
    j = Junctions(conn, network, None, None, 4.0)  # type: ignore[arg-type]
    assert j.junction_blocked("me", "in_0") and j.counts["inside_junction_waits"] == 1
    v.cars["o"]["xy"] = (10.0, 7.3 + 1e-3)
    assert not j.junction_blocked("me", "in_0") and j.counts["inside_junction_waits"] == 1
    # Exactly 2.3 m away (7.3 - 5 and 1 + 0.3 + 1 round to the same double): not within.
    v.cars["o"]["xy"] = (10.0, 7.3)
    assert not j.junction_blocked("me", "in_0")
    network.junction_lanes = lambda via: (path, [])
    v.cars["o"]["xy"] = (10.0, 0.0)
    assert not j.junction_blocked("me", "in_0")
    # On a lane out of the junction (SUMO lists it there by its front): in
    # the way only while its back is still inside (lane position under its
    # 5 m length).
    network.junction_lanes = lambda via: (path, [":j_0"])
    conn.lanes[":j_0"] = ["me"]
    conn.lanes["out_0"] = ["o"]
    exits.append("out_0")
    v.cars["o"].update(xy=(10.0, 3.0), pos=5.0 - 1e-3)
    assert j.junction_blocked("me", "in_0")
    v.cars["o"].update(pos=5.0)
    assert not j.junction_blocked("me", "in_0")


def test_junction_blocked_while_a_vehicle_heads_for_a_waiting_point_across_the_way() -> None:
    """Junction lane ":t_0" ends at an internal waiting point whose last 5 m
    lie 1.6 m from the entering vehicle's path (Bologna's junction 27). The
    entering vehicle 2 m wide: reach 1 + 0.3, plus a car's half width 0.9:
    within 2.2 m it waits while any vehicle is on ":t_0", moving there or
    waiting; at 2.2 m and more, or with ":t_0" empty, it goes."""
    import numpy as np

    conn = FakeConn()
    v = conn.vehicle
    v.add("me", width=2.0)
    v.add("turner", width=1.8, length=5.0, angle=90.0, xy=(-30.0, -30.0), speed=4.0)
    conn.lanes[":t_0"] = ["turner"]
    near = {"in_0": ((":t_0", 1.6),)}
    network = SimpleNamespace(junction_lanes=lambda via: (np.array([[0.0, 0.0], [20.0, 0.0]]), [":t_0"]),
                              from_lane=lambda lane: None, junction_exits=lambda via: (),
                              waiting_points_near=lambda via: near.get(via, ()))
    j = Junctions(conn, network, None, None, 4.0)  # type: ignore[arg-type]
    # Its body nowhere near the path yet (moving towards the point): waited for all the same.
    assert j.junction_blocked("me", "in_0") and j.counts == {"inside_junction_waits": 0, "waiting_point_waits": 1, "keep_clear_waits": 0, "entered_across_waits": 0}
    v.cars["turner"]["speed"] = 0.0
    assert j.junction_blocked("me", "in_0")
    near["in_0"] = ((":t_0", 2.2 - 1e-9),)
    assert j.junction_blocked("me", "in_0")
    near["in_0"] = ((":t_0", 2.2 + 1e-9),)
    assert not j.junction_blocked("me", "in_0")
    near["in_0"] = ((":t_0", 1.6),)
    conn.lanes[":t_0"] = ["me"]
    assert not j.junction_blocked("me", "in_0"), "the vehicle itself is no blocker"
    conn.lanes[":t_0"] = []
    assert not j.junction_blocked("me", "in_0") and j.counts["waiting_point_waits"] == 3


def test_the_network_lists_the_waiting_points_near_a_way(tmp_path: Path, build_net: Any) -> None:
    """A crossroads of two-lane roads: the left turn from the south has an
    internal waiting point in the middle; the oncoming straight way from the
    north passes it. Listed with its distance (the straight way's own lanes,
    the left turn from its own lane and lanes without a waiting point are
    not); the distance is the polyline distance from the last 5 m of that
    junction lane to the way."""
    import numpy as np

    from blendtrack.sumo.geometry import polyline_tail, segments_distance
    from blendtrack.sumo.network import WAITING_BODY_M, Network

    net = Network(build_net(tmp_path, '<nodes><node id="c" x="0" y="0" type="priority"/><node id="n" x="0" y="100"/>'
                                      '<node id="s" x="0" y="-100"/><node id="e" x="100" y="0"/><node id="w" x="-100" y="0"/></nodes>',
                            '<edges><edge id="sc" from="s" to="c" priority="3"/><edge id="cn" from="c" to="n" priority="3"/>'
                            '<edge id="nc" from="n" to="c" priority="3"/><edge id="cs" from="c" to="s" priority="3"/>'
                            '<edge id="ec" from="e" to="c" priority="1"/><edge id="cw" from="c" to="w" priority="1"/>'
                            '<edge id="wc" from="w" to="c" priority="1"/><edge id="ce" from="c" to="e" priority="1"/></edges>'))
    sumo_net = net.net()
    straight = [c for c in sumo_net.getEdge("nc").getLane(0).getOutgoing() if c.getTo().getID() == "cs"][0]
    left = [c for c in sumo_net.getEdge("sc").getLane(0).getOutgoing() if c.getTo().getID() == "cw"][0]
    first_left = left.getViaLaneID()
    assert net.connection_of(first_left) is left and sumo_net.getLane(first_left).getOutgoing(), "a waiting point"
    via = straight.getViaLaneID()
    listed = dict(net.waiting_points_near(via))
    path, _ = net.junction_lanes(via)
    tail = polyline_tail(np.asarray(sumo_net.getLane(first_left).getShape(), dtype=float)[:, :2], WAITING_BODY_M)
    assert listed[first_left] == pytest.approx(segments_distance(tail, path))
    assert via not in listed
    own_left = [c for c in sumo_net.getEdge("nc").getLane(0).getOutgoing() if c.getTo().getID() == "ce"][0]
    assert own_left.getViaLaneID() not in listed, "a vehicle from the same lane is ahead: followed"
    # The left turn's way stops at its waiting point; the straight one does not.
    assert net.stops_inside(first_left) and not net.stops_inside(via)
    for lane in listed:
        c = net.connection_of(lane)
        assert c is not None and c.getViaLaneID() == lane and sumo_net.getLane(lane).getOutgoing()[0].getViaLaneID(), lane


def test_a_vehicle_ahead_from_the_same_lane_is_followed_not_waited_for() -> None:
    """A vehicle inside the junction in the path that entered from the same
    lane (a left turner ahead of a straight-on vehicle) blocks only while
    it is slow (below FOLLOW_MIN_SPEED_MPS, or slower than the vehicle
    behind) or its back is not yet past the line (lane position below its
    5 m length); from another lane it blocks whatever it does."""
    import numpy as np

    conn = FakeConn()
    v = conn.vehicle
    v.add("me", width=2.0)
    v.add("o", width=2.0, length=5.0, angle=90.0, xy=(8.0, 0.0), speed=3.0, pos=5.0)
    conn.lanes[":j_0"] = ["o"]
    path = np.array([[0.0, 0.0], [20.0, 0.0]])
    origin = {"in_0": "a_0", ":j_0": "a_0"}
    network = SimpleNamespace(junction_lanes=lambda via: (path, [":j_0"]), from_lane=lambda lane: origin.get(lane),
                              junction_exits=lambda via: (), waiting_points_near=lambda via: ())
    j = Junctions(conn, network, None, None, 4.0)  # type: ignore[arg-type]
    assert not j.junction_blocked("me", "in_0")
    for speed, pos in [(FOLLOW_MIN_SPEED_MPS - 1e-3, 5.0), (3.0, 5.0 - 1e-3)]:
        v.cars["o"].update(speed=speed, pos=pos)
        assert j.junction_blocked("me", "in_0"), (speed, pos)
    v.cars["o"].update(speed=FOLLOW_MIN_SPEED_MPS, pos=5.0)
    assert not j.junction_blocked("me", "in_0")
    # Slower than the vehicle behind it: waited for.
    v.cars["me"].update(speed=FOLLOW_MIN_SPEED_MPS + 1.0)
    assert j.junction_blocked("me", "in_0")
    v.cars["o"].update(speed=FOLLOW_MIN_SPEED_MPS + 1.0)
    assert not j.junction_blocked("me", "in_0")
    origin[":j_0"] = "c_0"
    assert j.junction_blocked("me", "in_0")


# ------------------------------------------------------------ zipper merges
def _zippers(conn: FakeConn, fronts: dict[str, tuple[int, float]]) -> Any:
    """``Zippers`` on a merge of lanes A_0 and B_0 (40 m each), each into a
    35 m junction lane (:J_0_0 from A, :J_1_0 from B) that meet at its end;
    ``fronts``: controlled vehicle -> (slot, blendtrack's front on its track,
    which starts where its lane starts; the stop line at 40 m)."""
    from blendtrack.sumo.tracks import Active
    from blendtrack.sumo.zipper import Zippers

    vias = [":J_0_0", ":J_1_0"]
    slots = {slot: (vid, s) for vid, (slot, s) in fronts.items()}
    fleet = SimpleNamespace(
        next_stop=lambda slot: (40.0, -1, 0, False, 0 if conn.vehicle.cars[slots[slot][0]]["lane"] == "A_0" else 1, 75.0),
        s_front=lambda slot: slots[slot][1])
    conn.get_lane_id = lambda vid: conn.vehicle.cars[vid]["lane"]  # type: ignore[attr-defined]
    conn.get_lane_pos = lambda vid: conn.vehicle.cars[vid]["pos"]  # type: ignore[attr-defined]
    net = FakeNet({"A_0": FakeLane(40.0), "B_0": FakeLane(40.0)})
    z = Zippers(conn, SimpleNamespace(net=lambda: net),  # type: ignore[arg-type]
                SimpleNamespace(fleet=fleet, lanes=SimpleNamespace(name=lambda i: vias[i])), {})  # type: ignore[arg-type]
    # Each stream's foes come along the other's lane, 35 m from its end to the merge point.
    z._zips = {":J_0_0": (35.0, [("B_0", 35.0)]), ":J_1_0": (35.0, [("A_0", 35.0)])}
    return [Active(vid, slot, None, "", None) for vid, (slot, _) in fronts.items()], z  # type: ignore[arg-type]


def test_zipper_orders_two_controlled_vehicles_by_one_measure() -> None:
    """Two controlled vehicles near a zipper: A's front is 5.0 m along its
    lane by its track (SUMO has 5.6 m), B's 5.2 m (SUMO 5.4 m). By their
    tracks B is closer to the merge point (75 - 5.2 = 69.8 m against
    70.0 m): A falls in behind B (gap 70.0 - 69.8 - 5 m length - 2.5 m
    minGap, less than 0: 0), B has nobody to follow. Measured each by its
    own track against the other's SUMO position, each found the other
    closer (A: 75 - 5.4 < 70.0; B: 75 - 5.6 < 69.8) and both waited for good
    (traced on Eccles)."""
    conn = FakeConn()
    conn.vehicle.add("A", lane="A_0", pos=5.6)
    conn.vehicle.add("B", lane="B_0", pos=5.4)
    conn.lanes = {"A_0": ["A"], "B_0": ["B"]}
    order, z = _zippers(conn, {"A": (0, 5.0), "B": (1, 5.2)})
    assert z.leaders(order) == [("A", ("B", 0.0))]
    # A vehicle SUMO drives is placed by SUMO's position: C, 4 m along B_0
    # (71 m from the merge point), is behind A (70 m): nobody follows C, and
    # C is not closer than B for A.
    conn.vehicle.add("C", lane="B_0", pos=4.0)
    conn.lanes["B_0"] = ["C", "B"]
    assert z.leaders(order) == [("A", ("B", 0.0))]
    # 12 m along B_0 (63 m from the merge point), C is ahead of both, and the
    # nearest ahead of A in the order is still B.
    conn.vehicle.cars["C"]["pos"] = 12.0
    conn.lanes["B_0"] = ["B", "C"]
    assert z.leaders(order) == [("A", ("B", 0.0))]


def test_a_barely_started_lane_change_is_given_up_when_its_room_goes(monkeypatch: pytest.MonkeyPatch) -> None:
    """A change the route needs, still within 0.5 m of its lane's centre, is
    checked again each step: standing, a 10 m change takes sqrt(20) s at
    1 m/s^2, so a follower at 18 m/s on the target lane needs 5 + 18
    sqrt(20) - 10 = 75.5 m; just under that the change is given up, just
    over it goes on; past 0.5 m from the centre it is never given up, nor
    at the centre of a lane between (a change over two lanes: given up there
    it was put on that lane's track while SUMO had it a lane on)."""
    from blendtrack.sumo.tracks import Active

    conn = FakeConn()
    conn.vehicle.add("me", speed=0.0, lat=0.1, lane="e_0", lane_index=0)
    conn.vehicle.add("f", speed=18.0)
    lcs = lane_changes(conn)
    aborted: list[str] = []
    monkeypatch.setattr(lcs, "abort_change", lambda act: aborted.append(act.vid))
    act = Active("me", 0, None, "", None, changing=(1, 2), change_from=0, change_edge="e")  # type: ignore[arg-type]
    need = 5.0 + 18.0 * math.sqrt(20.0) - 10.0
    for gap, lat, index, gives_up in [(need - 1e-3, 0.1, 0, True), (need + 1e-3, 0.1, 0, False), (need - 1e-3, 0.6, 0, False),
                                      (need - 1e-3, 0.1, 1, False)]:
        aborted.clear()
        conn.vehicle.cars["me"]["lat"] = lat
        conn.vehicle.cars["me"]["lane_index"] = index
        conn.vehicle.neighbours = {("me", 0): [("f", gap)]}
        lcs.changing_leader(act, None)
        assert aborted == (["me"] if gives_up else []), (gap, lat, index)
    # Two edges on, on a lane of the index it left and near its centre,
    # with no room: the change is over, not given up.
    conn.vehicle.cars["me"].update(lane="g_0", lane_index=0, lat=0.1)
    conn.vehicle.neighbours = {("me", 0): [("f", need - 1e-3)]}
    aborted.clear()
    assert lcs.changing_leader(act, None) is None
    assert aborted == [] and act.changing is None


def test_a_change_under_way_is_seen_by_the_nearest_vehicle_behind_on_each_lane_it_moves_onto() -> None:
    """A change from lane 0 over lane 1 onto lane 2, the changer's front at
    100 m (length 5: back at 95). On each of lanes 1 and 2 the nearest
    vehicle whose front is behind 95 m, within 150 m, sees it: a controlled
    one takes it as a soft leader at its gap (back less its front and
    minGap: 95 - 80 - 2.5 = 12.5 m); behind one of SUMO's drivers, nobody
    (the driver's follower follows the driver). Vehicles alongside or
    ahead, and ones further back, are passed over; with nobody on lane 2,
    one still on the junction lane before it (20 m long, front at 15 m:
    5 m before the lane's start) is the nearest."""
    from blendtrack.sumo.tracks import Active

    conn = FakeConn()
    v = conn.vehicle
    v.add("me", pos=100.0, speed=3.0, lat=0.6, lane="e_0", lane_index=0)
    for vid, pos in [("c1", 80.0), ("c0", 40.0), ("s1", 97.0), ("d2", 60.0), ("c2", 30.0), ("a2", 120.0), ("j", 15.0)]:
        v.add(vid, pos=pos, speed=10.0)
    conn.lanes = {"e_1": ["c0", "c1", "s1"], "e_2": ["c2", "d2", "a2"]}
    lcs = lane_changes(conn, feeders={"e_2": ((":j_1", 20.0),)})
    act = Active("me", 0, None, "", None, changing=(1, 2), change_from=0, change_edge="e")  # type: ignore[arg-type]
    lcs.active.update({"me": act, "c1": act, "c0": act, "c2": act})
    index = {"me": 0, "c1": 1, "c0": 2, "c2": 4}
    lcs.seen_coming(act, 0, 2)
    assert lcs.soft_leaders(index) == [(1, "me", 95.0 - 80.0 - 2.5)]
    assert lcs.counts["cut_in_steps"] == 1 and lcs._asked == {}
    # Lane 2 empty but for one ahead: the controlled one on the junction
    # lane before it, its gap counted from 5 m before the lane.
    conn.lanes["e_2"] = ["a2"]
    conn.lanes[":j_1"] = ["j"]
    lcs.active["j"] = act
    index["j"] = 3
    lcs.seen_coming(act, 0, 2)
    assert sorted(lcs.soft_leaders(index)) == [(1, "me", 12.5), (3, "me", 95.0 + 5.0 - 2.5)]
    # Beyond 150 m behind the back: not seen. On the last lane: nothing to do.
    v.cars["c1"]["pos"] = 95.0 - 150.0 - 1e-3
    conn.lanes["e_1"] = ["c1"]
    conn.lanes[":j_1"] = []
    lcs.seen_coming(act, 0, 2)
    assert not has_soft(lcs)
    lcs.seen_coming(act, 2, 2)
    assert not has_soft(lcs)


def test_the_blind_speed_is_krauss_safe_speed_in_closed_form() -> None:
    """v tau + v^2 / (2 b) = gap + v_l^2 / (2 b): at b = 4.5, tau = 1, a
    leader at 10 m/s 20 m ahead, v = (-9 + sqrt(81 + 4 * 280)) / 2; with no
    gap left, 0; a standing leader and no reaction time, sqrt(2 b gap)."""
    v = lc.blind_speed(20.0, 10.0, 4.5, 1.0)
    assert v == pytest.approx((-9.0 + math.sqrt(81.0 + 4.0 * 280.0)) / 2.0)
    assert v * 1.0 + v * v / 9.0 == pytest.approx(20.0 + 100.0 / 9.0)
    assert lc.blind_speed(0.0, 10.0, 4.5, 1.0) == 0.0
    assert lc.blind_speed(-1.0, 30.0, 4.5, 1.0) == 0.0
    assert lc.blind_speed(8.0, 0.0, 4.0, 0.0) == pytest.approx(8.0)
    assert lc.blind_speed(math.nan, 10.0, 4.5, 1.0) == 0.0
    # Not a number elsewhere: the floor (no reaction time, standing leader, 1e-3 m/s^2).
    assert lc.blind_speed(8.0, 0.0, 4.0, math.nan) == pytest.approx(8.0)
    assert lc.blind_speed(8.0, math.nan, 4.0, 0.0) == pytest.approx(8.0)
    assert lc.blind_speed(8.0, 0.0, math.nan, 0.0) == pytest.approx(math.sqrt(2e-3 * 8.0))


def test_a_sumo_driver_behind_a_change_it_cannot_see_yet_is_capped_for_one_step() -> None:
    """"me" (front 100 m, back 95 m, 8 m/s) changes from e_0 onto e_1.
    SUMO's driver "d" there, front at 80 m at 14 m/s: 12.5 m of gap after
    its minGap, where Krauss's safe speed is -4.5 + sqrt(4.5^2 + 8^2 +
    9 * 12.5) = 9.53 m/s, below the 16.6 m/s it could reach in the 1 s
    step: it gets that speed for this step (and is counted once, however
    many changers cap it; the tightest cap holds), and SUMO's own again at
    the next step's start. One far enough back that the safe speed is out
    of its reach is left alone, as is a driver that has left; the cap
    never exceeds the driver's own top speed there (lane limit times speed
    factor), which ``setSpeed`` would override."""
    from blendtrack.sumo.tracks import Active

    conn = FakeConn()
    v = conn.vehicle
    v.add("me", lane="e_0", pos=100.0, speed=8.0, lane_index=0, lat=0.3)
    v.add("d", lane="e_1", pos=80.0, speed=14.0)
    conn.lanes = {"e_1": ["d"]}
    lcs = lane_changes(conn)
    act = Active("me", 0, None, "", None, changing=(1, 1), change_from=0, change_edge="e")  # type: ignore[arg-type]
    lcs.active["me"] = act
    lcs.seen_coming(act, 0, 1)
    cap = -4.5 + math.sqrt(4.5**2 + 8.0**2 + 9.0 * 12.5)
    assert v.calls == [("speed", "d", pytest.approx(cap))]
    lcs.cap_blind_follower("d", 30.0, 8.0)  # a looser cap: no call
    lcs.cap_blind_follower("d", 5.0, 8.0)  # a tighter one: sent
    assert v.calls[1:] == [("speed", "d", pytest.approx(lc.blind_speed(5.0, 8.0, 4.5, 1.0)))]
    assert lcs.counts["blind_caps"] == 1
    v.calls.clear()
    lcs.release_caps()  # at the start of the next step (``make_due``)
    assert v.calls == [("speed", "d", -1.0)]
    v.calls.clear()
    lcs.release_caps()
    assert v.calls == []
    # 60 m back at 14 m/s: safe speed 19.4 m/s, beyond 14 + 2.6.
    v.cars["d"]["pos"] = 95.0 - 2.5 - 60.0
    lcs.seen_coming(act, 0, 1)
    assert lc.blind_speed(60.0, 8.0, 4.5, 1.0) > 16.6 and v.calls == []
    # Under a lane limit of 8 m/s at speed factor 1.1, the cap is 8.8 m/s.
    v.cars["d"]["pos"] = 80.0
    v.cars["d"].update(allowed=8.0, speed_factor=1.1)
    lcs.cap_blind_follower("d", 12.5, 8.0)
    assert v.calls == [("speed", "d", pytest.approx(8.8))]
    lcs.release_caps()
    v.calls.clear()
    del v.cars["d"]
    conn.get_speed = lambda vid: v.cars[vid]["speed"]  # type: ignore[method-assign]
    lcs.cap_blind_follower("d", 5.0, 8.0)
    assert v.calls == [] and lcs.counts["blind_caps"] == 2


def test_room_on_the_far_lane_counts_a_vehicle_still_in_the_junction_before_it() -> None:
    """A change over two lanes from a standstill, front at 10 m (back 5),
    10 m long: it lasts sqrt(20) s at 1 m/s^2, at a mean 10 / sqrt(20) m/s.
    A vehicle at 13 m/s on the junction lane before the far lane (20 m
    long, front at 10 m: 10 m before the far lane's start) is 5 + 10 - 2.5
    = 12.5 m behind, where 5 + sqrt(20) (13 - 10 / sqrt(20)) = 53.1 m are
    needed: no room. Without it the lane is clear."""
    conn = FakeConn()
    v = conn.vehicle
    v.add("me", pos=10.0, speed=0.0)
    v.add("j", pos=10.0, speed=13.0)
    conn.lanes = {"e_2": [], ":j_1": ["j"]}
    lcs = lane_changes(conn, feeders={"e_2": ((":j_1", 20.0),)})
    assert not lcs.room_on_lane("me", "e_2", 10.0, 0.0, 10.0)
    conn.lanes[":j_1"] = []
    assert lcs.room_on_lane("me", "e_2", 10.0, 0.0, 10.0)
    # Just far enough back: 53.1 m of gap.
    need = 5.0 + math.sqrt(20.0) * (13.0 - 10.0 / math.sqrt(20.0))
    conn.lanes[":j_1"] = ["j"]
    lcs.network.feeders = lambda lane: ((":j_1", 20.0 + need - 12.5 + 1e-3),) if lane == "e_2" else ()  # type: ignore[attr-defined]
    assert lcs.room_on_lane("me", "e_2", 10.0, 0.0, 10.0)


def _only_on(conn: FakeConn, lane: str | None) -> None:
    """Edge ``e``'s six lanes empty but ``lane``, which holds vehicle ``d``."""
    conn.lanes = {f"e_{k}": [] for k in range(6)}
    if lane is not None:
        conn.lanes[lane] = ["d"]


def test_a_change_over_three_lanes_needs_room_behind_on_the_lanes_between() -> None:
    """From lane 1 to lane 4 from a standstill, front at 10 m, 10 m long
    (sqrt(20) s at 1 m/s^2): lane 3, between the lane beside (2) and the
    last (4), is checked for the vehicle behind. A driver at 13 m/s with its
    front at 0 m (the back is at 5 m: a gap of 2.5 m less its minGap) leaves
    no room there (53.1 m needed); on lanes 2, 4 and 5 (checked
    elsewhere, or beyond the change) it does not count here; ahead of the
    front on lane 3 it does not count either; the same way down, from 4 to
    1 (lane 2 between); a change over two lanes has no lane between."""
    conn = FakeConn()
    v = conn.vehicle
    v.add("me", pos=10.0, speed=0.0)
    v.add("d", pos=0.0, speed=13.0)
    lcs = lane_changes(conn)
    for lane, room in [("e_3", False), ("e_2", True), ("e_4", True), ("e_5", True), (None, True)]:
        _only_on(conn, lane)
        assert lcs.room_between("me", "e", 1, 4, 10.0, 0.0, 10.0) is room, lane
    _only_on(conn, "e_3")
    v.cars["d"]["pos"] = 30.0
    assert lcs.room_between("me", "e", 1, 4, 10.0, 0.0, 10.0)
    v.cars["d"]["pos"] = 0.0
    for lane, room in [("e_2", False), ("e_3", True), ("e_1", True)]:
        conn.lanes = {f"e_{k}": [] for k in range(6)}
        conn.lanes[lane] = ["d"]
        assert lcs.room_between("me", "e", 4, 1, 10.0, 0.0, 10.0) is room, lane
    conn.lanes = {f"e_{k}": ["d"] for k in range(6)}
    assert lcs.room_between("me", "e", 1, 3, 10.0, 0.0, 10.0)
    # Just far enough back: the gap the closing speed needs over the change.
    need = 5.0 + math.sqrt(20.0) * (13.0 - 10.0 / math.sqrt(20.0))
    conn.lanes = {f"e_{k}": [] for k in range(6)}
    conn.lanes["e_3"] = ["d"]
    v.cars["d"]["pos"] = 5.0 - 2.5 - need - 1e-3
    assert lcs.room_between("me", "e", 1, 4, 10.0, 0.0, 10.0)


def test_a_change_over_three_lanes_sweeps_behind_the_vehicles_ahead_on_the_lanes_between() -> None:
    """From lane 1 to lane 4 from a standstill, front at 10 m, 10 m long:
    at the planning acceleration (1 m/s^2) the front is 10 u m on after
    sqrt(20 u) s, and the body is over lane 3 while 3 smoothstep(u) - 2
    is within 0.75 of it (u from 0.45 to 0.80 at the 21 samples). A car
    standing ahead there needs its back 10 + 8 + 2.5 (minGap) = 20.5 m
    on: its front at 25 m (back 20) stops the change, at 26 m it does not.
    Lane 2 (beside) and 4 (the last) are others' checks. A car on lane 3
    with its front at 15 m that drives at 13 m/s leaves room; at 1 m/s
    its back is at 13 m when the front reaches 14.5 m (u = 0.45, 3 s):
    no room."""
    conn = FakeConn()
    v = conn.vehicle
    v.add("me", pos=10.0, speed=0.0)
    v.add("d", pos=25.0, speed=0.0)
    lcs = lane_changes(conn)
    for lane, room in [("e_3", False), ("e_2", True), ("e_4", True)]:
        _only_on(conn, lane)
        assert lcs.room_between("me", "e", 1, 4, 10.0, 0.0, 10.0) is room, lane
    _only_on(conn, "e_3")
    v.cars["d"]["pos"] = 26.0
    assert lcs.room_between("me", "e", 1, 4, 10.0, 0.0, 10.0)
    v.cars["d"].update(pos=15.0, speed=13.0)
    assert lcs.room_between("me", "e", 1, 4, 10.0, 0.0, 10.0)
    v.cars["d"].update(speed=1.0)
    assert not lcs.room_between("me", "e", 1, 4, 10.0, 0.0, 10.0)


def test_a_change_past_its_point_of_no_return_goes_back_for_a_vehicle_alongside(monkeypatch: pytest.MonkeyPatch) -> None:
    """A change the route needs, 0.8 m across (past giving up by its
    offset), SUMO still having the vehicle on the lane it leaves: a vehicle
    that has come alongside on the target lane (a follower or a leader whose
    gap is below minus the minGap, 2.5 m: the bodies overlap) sends it back;
    one clear ahead or behind, or only within the minGap, does not, nor
    does one alongside once SUMO has the vehicle past the target lane. In a
    change over two lanes, SUMO having the vehicle on the lane between, a
    vehicle alongside on the next lane sends it back too (traced at Eccles,
    seed 5, 479 s: a change from lane 0 to 3 crossed lane 1 into a vehicle
    alongside on lane 2)."""
    from blendtrack.sumo.tracks import Active

    conn = FakeConn()
    v = conn.vehicle
    v.add("me", speed=20.0, lat=0.8, lane="e_0", lane_index=0)
    v.add("x")
    v.add("y")
    lcs = lane_changes(conn)
    aborted: list[str] = []
    monkeypatch.setattr(lcs, "abort_change", lambda act: aborted.append(act.vid))
    monkeypatch.setattr(lcs, "left_behind", lambda act, lead: False)
    act = Active("me", 0, None, "", None, changing=(1, 1), change_from=0, change_edge="e")  # type: ignore[arg-type]
    # Changing left (side 0): followers mode 0, leaders mode 2.
    for followers, leaders, index, goes_back in [
        ([("x", -3.3)], [], 0, True),
        ([], [("x", -2.6)], 0, True),
        ([("x", 4.0)], [("y", 6.0)], 0, False),
        ([("x", -2.4)], [("y", -1.0)], 0, False),
        ([("x", -3.3)], [], 2, False),
    ]:
        aborted.clear()
        v.cars["me"]["lane_index"] = index
        v.neighbours = {("me", 0): followers, ("me", 2): leaders}
        lcs.changing_leader(act, None)
        assert aborted == (["me"] if goes_back else []), (followers, leaders, index)
    act = Active("me", 0, None, "", None, changing=(1, 2), change_from=0, change_edge="e")  # type: ignore[arg-type]
    v.cars["me"]["lane"] = "e_1"
    for followers, index, goes_back in [([("x", -3.3)], 1, True), ([("x", 4.0)], 1, False)]:
        aborted.clear()
        v.cars["me"]["lane_index"] = index
        v.neighbours = {("me", 0): followers}
        lcs.changing_leader(act, None)
        assert aborted == (["me"] if goes_back else []), (followers, index)


def test_a_leader_on_the_tracks_way_is_taken_when_sumo_has_the_vehicle_beside_it() -> None:
    # Junction edge ":j_0" has lanes ":j_0_0" and ":j_0_1"; the track drives
    # ":j_0_1" (20 m) into "out_1". SUMO has the vehicle on ":j_0_0" at 8 m
    # (moveToXY's choice for the step), where getLeader looks along the other
    # connection and finds a vehicle 25.9 m on; on the track's own way a
    # vehicle stands on "out_1" with its back at 6 - 4.5 = 1.5 m: the gap as
    # getLeader gives it is (20 - 8) + 1.5 - minGap 2.5 = 11 m.
    conn = FakeConn()
    v = conn.vehicle
    v.add("me", lane=":j_0_0", pos=8.0, speed=7.0)
    v.add("other", lane=":j_0_1", pos=3.0, speed=7.0)  # behind "me" on the track's lane: not ahead
    v.add("ahead", lane="out_1", pos=6.0, speed=0.0)
    v.cars["ahead"]["length"] = 4.5
    v.cars["me"]["min_gap"] = 2.5
    conn.lanes = {":j_0_1": ["other"], "out_1": ["ahead"]}
    conn.get_lane_id = lambda vid: v.cars[vid]["lane"]  # type: ignore[attr-defined]
    conn.get_lane_pos = lambda vid: v.cars[vid]["pos"]  # type: ignore[attr-defined]
    after = {":j_0_1": [(":j_0_1", 20.0), ("out_1", 100.0)]}
    j = Junctions(conn, SimpleNamespace(lanes_after=lambda via: after.get(via, []), lanes_next=lambda lane: ()), None, None, 4.0)  # type: ignore[arg-type]
    track = ["in_1", ":j_0_1", "out_1"]
    far = ("elsewhere", 25.9)
    assert j.leader_on_track("me", track, far) == ("ahead", pytest.approx(11.0))
    # A nearer leader from SUMO stays.
    assert j.leader_on_track("me", track, ("close", 4.0)) == ("close", 4.0)
    # On the track's own lane, SUMO's answer stands as it is.
    v.cars["me"]["lane"] = ":j_0_1"
    assert j.leader_on_track("me", track, far) == far
    # On a normal lane too.
    v.cars["me"]["lane"] = "in_1"
    assert j.leader_on_track("me", track, far) == far


def test_beside_its_tracks_lane_the_vehicle_is_measured_where_blendtrack_put_it() -> None:
    # As above, but RouteFleet has the front at 9.5 m on the track's lane
    # ":j_0_1" (SUMO's 8 m is a position on ":j_0_0", which parts from it):
    # the gap is (20 - 9.5) + 1.5 - 2.5 = 9.5 m. A front RouteFleet has on
    # another lane leaves SUMO's position.
    conn = FakeConn()
    v = conn.vehicle
    v.add("me", lane=":j_0_0", pos=8.0, speed=2.0)
    v.add("ahead", lane="out_1", pos=6.0, speed=0.0)
    v.cars["ahead"]["length"] = 4.5
    conn.lanes = {"out_1": ["ahead"]}
    conn.get_lane_id = lambda vid: v.cars[vid]["lane"]  # type: ignore[attr-defined]
    after = {":j_0_1": [(":j_0_1", 20.0), ("out_1", 100.0)]}
    front = {"lane": 1, "pos": 9.5}
    fleet = SimpleNamespace(front_lane_position=lambda slot: (front["lane"], front["pos"]))
    tracks = SimpleNamespace(lanes=SimpleNamespace(names=["in_1", ":j_0_1", "out_1"]))
    j = Junctions(conn, SimpleNamespace(lanes_after=lambda via: after.get(via, []), lanes_next=lambda lane: ()), tracks, fleet, 4.0,  # type: ignore[arg-type]
                  controlled={"me": SimpleNamespace(slot=0)})
    track = ["in_1", ":j_0_1", "out_1"]
    assert j.leader_beyond("me", track) == ("ahead", pytest.approx(9.5))
    assert j.leader_on_track("me", track, ("elsewhere", 25.9)) == ("ahead", pytest.approx(9.5))
    front["lane"] = 0
    assert j.leader_beyond("me", track) == ("ahead", pytest.approx(11.0))


def _fanout_junctions(conn: FakeConn) -> Junctions:
    """Lane "in_1" (20 m) fans out over ":j_0_1" (10 m, into "out_1") and
    ":j_0_2" (10 m, into "out_2")."""
    after = {":j_0_1": [(":j_0_1", 10.0), ("out_1", 100.0)], ":j_0_2": [(":j_0_2", 10.0), ("out_2", 100.0)]}
    net = SimpleNamespace(fanouts=lambda: {"in_1": ((":j_0_1", ":j_0_2"), 20.0)}, lanes_after=lambda via: after.get(via, []), lanes_next=lambda lane: (),
                          from_lane=lambda via: "in_1", junction_lanes=lambda via: (np.zeros((0, 2)), ()))
    return Junctions(conn, net, None, None, 4.0)  # type: ignore[arg-type]


def test_a_leader_past_a_fan_out_on_the_tracks_way_is_taken() -> None:
    # "me" is on "in_1" at 5 m; its track goes through ":j_0_1". SUMO's
    # driver would take ":j_0_2", so getLeader finds nothing (or something
    # far) while a vehicle stands on the track's junction lane at 10 m with
    # its back at 10 - 5 = 5 m: the gap as getLeader gives it is
    # (20 - 5) + 5 - minGap 2.5 = 17.5 m.
    conn = FakeConn()
    v = conn.vehicle
    v.add("me", lane="in_1", pos=5.0, speed=11.0)
    v.add("ahead", lane=":j_0_1", pos=10.0, speed=0.0)
    v.add("beside", lane=":j_0_2", pos=8.0, speed=0.0)
    v.cars["ahead"]["length"] = 5.0
    v.cars["me"]["min_gap"] = 2.5
    conn.lanes = {":j_0_1": ["ahead"], ":j_0_2": ["beside"]}
    j = _fanout_junctions(conn)
    track = ["in_1", "in_1", ":j_0_1", "out_1"]
    assert j.leader_at_fanout("me", "in_1", track, None) == ("ahead", pytest.approx(17.5))
    assert j.leader_at_fanout("me", "in_1", track, ("far", 40.0)) == ("ahead", pytest.approx(17.5))
    # A nearer leader from SUMO stays, and so does one before the lane's end.
    assert j.leader_at_fanout("me", "in_1", track, ("close", 12.0)) == ("close", 12.0)
    # The track's way decides: through ":j_0_2" the vehicle there is the one ahead.
    assert j.leader_at_fanout("me", "in_1", ["in_1", ":j_0_2", "out_2"], None) == ("beside", pytest.approx(15.0 + 8.0 - 5.0 - 2.5))
    # A vehicle on the way beside the track's is not taken (SUMO's getLeader looks there).
    conn.lanes = {":j_0_2": ["beside"]}
    assert j.leader_at_fanout("me", "in_1", track, None) is None
    # On the lane after the junction.
    v.add("later", lane="out_1", pos=30.0, speed=3.0)
    v.cars["later"]["length"] = 5.0
    conn.lanes["out_1"] = ["later"]
    assert j.leader_at_fanout("me", "in_1", track, None) == ("later", pytest.approx(15.0 + 10.0 + 25.0 - 2.5))
    # A track that leaves the lane another way (or does not know the lane) keeps SUMO's answer.
    assert j.leader_at_fanout("me", "in_1", ["in_1", ":k_0_0", "x"], None) is None
    assert j.leader_at_fanout("me", "in_1", ["elsewhere"], ("far", 40.0)) == ("far", 40.0)


def _merge_junctions(conn: FakeConn, controlled: Any = None) -> Junctions:
    """Lane "maj" (50 m) leads through ":m_0_0" (6 m) and lane "min" (40 m)
    through ":m_1_0" (8 m) onto "out" (100 m): two ways merging. Before
    "maj", junction lane ":p_0_0" (10 m) leads onto the 0.2 m lane "short"
    and on through ":s_0_0" (5 m) onto "maj2", where "min2" merges through
    ":s_1_0" (7 m). ``controlled``: the vehicles blendtrack drives."""
    after = {":m_0_0": [(":m_0_0", 6.0), ("out", 100.0)], ":m_1_0": [(":m_1_0", 8.0), ("out", 100.0)],
             ":p_0_0": [(":p_0_0", 10.0), ("short", 0.2)], ":s_0_0": [(":s_0_0", 5.0), ("maj2", 50.0)],
             ":s_1_0": [(":s_1_0", 7.0), ("maj2", 50.0)]}
    ways = {"out": [((":m_0_0", 6.0),), ((":m_1_0", 8.0),)], "maj2": [((":s_0_0", 5.0),), ((":s_1_0", 7.0),)]}
    lengths = {"maj": 50.0, "min": 40.0, "short": 0.2}
    net = SimpleNamespace(lanes_after=lambda via: after.get(via, []), lanes_next=lambda lane: (), ways_into=lambda lane: ways.get(lane, []),
                          lane_length=lengths.__getitem__, lanes_into_merges=lambda: frozenset({"maj", "min", "short"}))
    return Junctions(conn, net, None, None, 4.0, controlled={} if controlled is None else controlled)  # type: ignore[arg-type]


def test_a_vehicle_merging_from_another_junction_lane_is_followed_when_it_gets_there_first() -> None:
    """The merge point is the start of "out". "me" on ":m_0_0" at 2 m is
    6 - 2 = 4 m from it; "foe" on ":m_1_0" at 5 m is 8 - 5 = 3 m from it,
    nearer: its back will be 4 - 3 - 5 = -4 m ahead, the gap as getLeader
    gives it -4 - minGap 2.5 = -6.5 m (stop at once). Farther from the
    merge point, the foe is followed only while it gets there sooner at the
    speeds both have now; standing, or slower, it is not (it follows)."""
    conn = FakeConn()
    v = conn.vehicle
    v.add("me", lane=":m_0_0", pos=2.0, speed=1.0, min_gap=2.5)
    v.add("foe", lane=":m_1_0", pos=5.0, speed=0.5, length=5.0)
    conn.lanes = {":m_1_0": ["foe"]}
    j = _merge_junctions(conn, controlled={"foe": None})
    track = ["maj", ":m_0_0", "out"]
    assert j.leader_at_merge("me", ":m_0_0", track, None) == ("foe", pytest.approx(4.0 - 3.0 - 5.0 - 2.5))
    assert j.leader_at_merge("me", ":m_0_0", track, ("far", 30.0)) == ("foe", pytest.approx(-6.5))
    # A leader of its own nearer than the foe's back stays.
    assert j.leader_at_merge("me", ":m_0_0", track, ("close", -8.0)) == ("close", -8.0)
    # Nor does a standing one that the foe, nearer by gap but at 10 m/s,
    # would hide: stop points -6.5 + 10^2 / (2 x 4) = 6 m against 3 m.
    v.add("stand", speed=0.0)
    v.cars["foe"]["speed"] = 10.0
    assert j.leader_at_merge("me", ":m_0_0", track, ("stand", 3.0)) == ("stand", 3.0)
    assert j.leader_at_merge("me", ":m_0_0", track, ("stand", 7.0)) == ("foe", pytest.approx(-6.5))
    v.cars["foe"]["speed"] = 0.5
    # The foe 6 m from the merge point (at 2 m), "me" 4 m: only sooner counts.
    v.cars["foe"]["pos"] = 2.0
    # 6 m at 0.5 m/s (12 s) against 4 m at 1 m/s (4 s): "me" goes first.
    assert j.leader_at_merge("me", ":m_0_0", track, None) is None
    # 6 m at 2 m/s (3 s) against 4 s: the foe first; gap 4 - 6 - 5 - 2.5.
    v.cars["foe"]["speed"] = 2.0
    assert j.leader_at_merge("me", ":m_0_0", track, None) == ("foe", pytest.approx(-9.5))
    # Exactly as soon (6 m at 1.5 m/s): not sooner, not followed.
    v.cars["foe"]["speed"] = 1.5
    assert j.leader_at_merge("me", ":m_0_0", track, None) is None
    # "me" standing: a moving foe gets there first; a standing one does not.
    v.cars["me"]["speed"] = 0.0
    assert j.leader_at_merge("me", ":m_0_0", track, None) == ("foe", pytest.approx(-9.5))
    v.cars["foe"]["speed"] = 0.0
    assert j.leader_at_merge("me", ":m_0_0", track, None) is None
    # From the lane before: "maj" at 30 m is 20 + 6 = 26 m from the merge
    # point; the foe (standing 6 m from it) is nearer: gap 26 - 6 - 5 - 2.5.
    v.cars["me"].update(lane="maj", pos=30.0)
    assert j.leader_at_merge("me", "maj", track, None) == ("foe", pytest.approx(12.5))
    # Farther than MERGE_LOOKAHEAD_M (30 m) from the merge point: not looked at.
    v.cars["me"]["pos"] = 10.0
    assert j.leader_at_merge("me", "maj", track, ("x", 50.0)) == ("x", 50.0)
    # A way that does not merge, and a vehicle on its own way, are not looked at.
    v.cars["me"]["pos"] = 30.0
    assert j.leader_at_merge("me", "maj", ["maj", ":k_0_0", "x"], None) is None
    conn.lanes = {":m_0_0": ["foe"]}
    assert j.leader_at_merge("me", "maj", track, None) is None


def test_the_leader_a_merging_vehicle_displaces_stays_a_soft_obstacle() -> None:
    """The step's leader look-up (``SumoRun._leaders``) on the merge above:
    "me" stands on "maj" at 30 m, 20 + 6 = 26 m from the merge point;
    "foe" on ":m_1_0" 3 m from it at 10 m/s is nearer (gap 26 - 3 - 5 -
    2.5 = 15.5 m, stop point 15.5 + 10^2 / 8 = 28 m). Where its stop point
    is nearer than that of "me"'s own leader "stand" (standing), "foe"
    becomes the leader and "stand" is handed on as a vehicle to line up
    behind (a soft obstacle), not dropped: over a 1 s step the foe drives
    on while "stand" does not, and with "stand" dropped a controlled car
    drove into it (Bologna, 203[0]). A leader the merge rule keeps is not
    handed on."""
    from blendtrack.sumo.runner import SumoRun

    conn = FakeConn()
    v = conn.vehicle
    v.add("me", lane="maj", pos=30.0, speed=0.0, min_gap=2.5)
    v.add("foe", lane=":m_1_0", pos=5.0, speed=10.0, length=5.0)
    v.add("stand", speed=0.0)
    conn.lanes = {":m_1_0": ["foe"]}
    lead = ["stand", 27.0]
    conn.get_leader = lambda vid, _range: tuple(lead)  # type: ignore[attr-defined]
    conn.vehicles_on_lanes = lambda lanes: [[]]  # type: ignore[attr-defined]
    handed: list[list[tuple[str, Any]]] = []
    geo = SimpleNamespace(piece_lane=["maj", ":m_0_0", "out"], memo={})
    run = SimpleNamespace(
        fleet=SimpleNamespace(lanes_with_followers=lambda slots: np.array([0]),
                              leaders_on_lanes=lambda slots, lanes, on: np.array([0])),
        vehicles=SimpleNamespace(ids=["me"], slots=np.array([0]), order=[SimpleNamespace(geo=geo)]),
        tracks=SimpleNamespace(lanes=SimpleNamespace(names=["maj"])),
        conn=conn,
        network=SimpleNamespace(fanouts=dict),
        junctions=_merge_junctions(conn),
        sumo_leaders=SimpleNamespace(correct=lambda leaders: leaders),
        sublane=SimpleNamespace(active=False),
        lanes=SimpleNamespace(add_merge_leads=handed.append),
    )
    # "stand" 27 m ahead: nearer than the foe's 28 m, it stays the leader.
    assert SumoRun._leaders(run) == ([0], [("stand", 27.0)])  # type: ignore[arg-type]
    assert handed == []
    # 29 m: the foe's 28 m is nearer; "stand" is handed on.
    lead[1] = 29.0
    assert SumoRun._leaders(run) == ([0], [("foe", pytest.approx(15.5))])  # type: ignore[arg-type]
    assert handed == [[("me", ("stand", 29.0))]]
    # No leader of its own: nothing to hand on.
    handed.clear()
    lead[0] = ""
    assert SumoRun._leaders(run) == ([0], [("foe", pytest.approx(15.5))])  # type: ignore[arg-type]
    assert handed == []


def test_a_sumo_driver_about_as_near_a_merge_point_is_followed() -> None:
    """SUMO's drivers from a minor road do not wait for a controlled vehicle
    standing at a merge: one up to MERGE_DEFER_M (3 m) farther from the merge
    point than the controlled vehicle is followed too. "me" on ":m_0_0" at
    2 m is 4 m from the merge point; the SUMO driver standing on ":m_1_0" at
    1.5 m is 6.5 m from it (followed: gap 4 - 6.5 - 5 - 2.5); at 0.5 m, 7.5 m
    (not). A controlled vehicle at 6.5 m is not (the rule stays the same
    from both sides)."""
    conn = FakeConn()
    v = conn.vehicle
    v.add("me", lane=":m_0_0", pos=2.0, speed=0.0, min_gap=2.5)
    v.add("sumo", lane=":m_1_0", pos=1.5, speed=0.0, length=5.0)
    conn.lanes = {":m_1_0": ["sumo"]}
    track = ["maj", ":m_0_0", "out"]
    assert _merge_junctions(conn).leader_at_merge("me", ":m_0_0", track, None) == ("sumo", pytest.approx(-10.0))
    assert _merge_junctions(conn, controlled={"sumo": None}).leader_at_merge("me", ":m_0_0", track, None) is None
    v.cars["sumo"]["pos"] = 0.5
    assert _merge_junctions(conn).leader_at_merge("me", ":m_0_0", track, None) is None


def test_a_merge_past_a_short_lane_is_looked_at_from_the_junction_before() -> None:
    """On ":p_0_0" at 4 m, the way goes on over the 0.2 m lane "short" and
    ":s_0_0" (5 m) to where ":s_1_0" merges: 6 + 0.2 + 5 = 11.2 m ahead. A
    controlled vehicle on ":s_1_0" at 3 m (4 m from the merge point) is
    nearer: gap 11.2 - 4 - 5 - 2.5."""
    conn = FakeConn()
    v = conn.vehicle
    v.add("me", lane=":p_0_0", pos=4.0, speed=0.0, min_gap=2.5)
    v.add("foe", lane=":s_1_0", pos=3.0, speed=0.0, length=5.0)
    conn.lanes = {":s_1_0": ["foe"]}
    j = _merge_junctions(conn, controlled={"foe": None})
    track = ["x", ":p_0_0", "short", ":s_0_0", "maj2"]
    assert j.leader_at_merge("me", ":p_0_0", track, None) == ("foe", pytest.approx(11.2 - 4.0 - 5.0 - 2.5))
    # A track that goes elsewhere after the short lane: nothing.
    assert j.leader_at_merge("me", ":p_0_0", ["x", ":p_0_0", "short", ":k_0_0", "y"], None) is None


def test_the_network_lists_the_lanes_that_fan_out(tmp_path: Path, build_net: Any) -> None:
    """A one-lane edge into a two-lane one: netconvert connects the lane to
    both, so it fans out; the two-lane edge into a one-lane one does not
    (two lanes onto one), nor does a lane with one connection."""
    from blendtrack.sumo.network import Network

    build_net(tmp_path, '<nodes><node id="a" x="0" y="0"/><node id="b" x="100" y="0"/>'
                        '<node id="c" x="200" y="0"/><node id="d" x="300" y="0"/></nodes>',
              '<edges><edge id="one" from="a" to="b" numLanes="1"/><edge id="two" from="b" to="c" numLanes="2"/>'
              '<edge id="last" from="c" to="d" numLanes="1"/></edges>')
    fan = Network(tmp_path / "n.net.xml").fanouts()
    assert set(fan) == {"one_0"}
    vias, length = fan["one_0"]
    assert len(vias) == 2 and all(v.startswith(":b_") for v in vias)
    assert length == pytest.approx(Network(tmp_path / "n.net.xml").net().getLane("one_0").getLength())
    # Ways merging: the lanes of "two" are each reached from "one_0" alone,
    # and "last_0" from "two" alone (the lane that ends has no connection).
    net = Network(tmp_path / "n.net.xml")
    assert net.ways_into("two_0") == [] and net.ways_into("two_1") == [] and net.ways_into("last_0") == []


def test_the_network_lists_the_ways_that_merge(tmp_path: Path, build_net: Any) -> None:
    """Edges "main" and "side" both lead onto the one lane of "out" at
    junction m: two ways (one junction lane each) merge onto "out_0"."""
    from blendtrack.sumo.network import Network

    net = Network(build_net(tmp_path, '<nodes><node id="a" x="0" y="0"/><node id="m" x="100" y="0"/>'
                                      '<node id="s" x="50" y="-60"/><node id="d" x="200" y="0"/></nodes>',
                            '<edges><edge id="main" from="a" to="m" priority="3"/><edge id="side" from="s" to="m" priority="1"/>'
                            '<edge id="out" from="m" to="d" priority="3"/></edges>'))
    ways = net.ways_into("out_0")
    froms = sorted(str(net.from_lane(w[0][0])) for w in ways)
    assert froms == ["main_0", "side_0"], ways
    for way in ways:
        assert all(name.startswith(":m_") and length == pytest.approx(net.lane_length(name)) for name, length in way)
        assert net.lanes_after(way[0][0])[-1][0] == "out_0"
    assert net.ways_into("main_0") == []
    assert net.lanes_into_merges() == {"main_0", "side_0"}
    # Each edge's way onto the merge: its lane and its own junction lanes only.
    for edge in ("main", "side"):
        way = next(w for w in ways if net.from_lane(w[0][0]) == edge + "_0")
        assert net.ways_from(edge, "out_0") == {edge + "_0", *(name for name, _ in way)}
    assert net.ways_from("out", "out_0") == frozenset() and net.ways_from("nowhere", "out_0") == frozenset()


def test_a_leader_counts_when_the_vehicle_is_on_an_edge_without_the_target_lane() -> None:
    """During a change SUMO can have the vehicle on the next edge, which may
    not have the target lane's index: sumolib's ``getLane`` then raises
    IndexError (a run at Eccles ended on it). The leader counts: not left
    behind, and no exception."""
    from blendtrack.sumo.tracks import Active

    class Net(FakeNet):
        def getLane(self, lane_id: str) -> FakeLane:
            edge, _, index = lane_id.rpartition("_")
            if edge == "f" and int(index) >= 2:
                raise IndexError("list index out of range")
            return super().getLane(lane_id)

    conn = FakeConn()
    conn.vehicle.add("me", speed=0.0, lat=0.0, lane="f_1", lane_index=1)
    conn.vehicle.add("lead", speed=0.0)
    lcs = lane_changes(conn)
    net = Net({"f_0": FakeLane(100.0), "f_1": FakeLane(100.0)})
    lcs.network = SimpleNamespace(net=lambda: net)  # type: ignore[assignment]
    act = Active("me", 0, None, "", None, changing=(1, 3), change_span=(10.0, 20.0), change_from=1, change_edge="e")  # type: ignore[arg-type]
    assert lcs.left_behind(act, ("lead", 30.0)) is False


# ------------------------------------------------------- SUMO's leaders
def _sumo_leaders(dt: float, second: tuple[str, float] | None) -> tuple[Any, FakeConn, list[float]]:
    """SumoLeaders over a fake connection at step ``dt``: "l1" (SUMO's, at
    11 m/s, decel 4.5, minGap 2.5) leads, its own leader is ``second`` (id,
    getLeader gap) when within the distance asked; the distances asked are
    listed."""
    from blendtrack.sumo.vehicles import SumoLeaders

    conn = FakeConn()
    v = conn.vehicle
    v.add("l1", speed=11.0)
    v.add("l2", speed=7.3)
    v.getDecel = lambda vid: 4.5  # type: ignore[attr-defined]
    asked: list[float] = []

    def get_leader(vid: str, dist: float) -> Any:
        assert vid == "l1"
        asked.append(dist)
        return second if second is not None and second[1] <= dist else None

    conn.get_leader = get_leader  # type: ignore[attr-defined]
    conn.dt = dt  # type: ignore[attr-defined]
    conn.leader_speed = v.getSpeed  # type: ignore[attr-defined]
    return SumoLeaders(conn, {}, 4.0), conn, asked  # type: ignore[arg-type]


def test_a_sumo_leaders_stop_point_is_bounded_by_its_own_leader_at_long_steps() -> None:
    from blendtrack.sumo.vehicles import euler_brake_gap

    b = 4.0
    brake1 = euler_brake_gap(11.0, 4.5, 1.0)  # 11 + 6.5 = 17.5, less 4.5 each: 6.5 + 2 = 8.5
    assert brake1 == pytest.approx(8.5)
    stop_of = lambda gap: gap + 11.0**2 / (2 * b)  # noqa: E731 - the law's stop point of l1 at that gap

    # Nobody ahead of l1 within its brake gap: the Euler correction alone,
    # the stop point is gap + 8.5.
    sl, _, asked = _sumo_leaders(1.0, None)
    (lid, gap, room), = sl.correct([("l1", 4.4)])
    assert lid == "l1" and stop_of(gap) == pytest.approx(4.4 + 8.5)
    # SUMO's own gap goes along, for the bound of a move by lane position.
    assert room == 4.4
    assert asked == [pytest.approx(8.5)]
    # A vehicle cut in overlapping l1's front (getLeader gap -4.5) at 7.3 m/s:
    # l1's back stops by 4.4 + 2.5 - 4.5 + (7.3 - 4.5) = 5.2 m at the latest.
    sl, _, _ = _sumo_leaders(1.0, ("l2", -4.5))
    (_, gap, _), = sl.correct([("l1", 4.4)])
    assert stop_of(gap) == pytest.approx(4.4 + 2.5 - 4.5 + 2.8)
    # A leader that cannot be passed through never moves l1 back.
    sl, conn, _ = _sumo_leaders(1.0, ("l2", -9.0))
    conn.vehicle.cars["l2"]["speed"] = 0.0
    (_, gap, _), = sl.correct([("l1", 4.4)])
    assert stop_of(gap) == pytest.approx(4.4)
    # One further than l1 could get is no bound: the Euler correction stays.
    sl, _, _ = _sumo_leaders(1.0, ("l2", 8.0))
    (_, gap, _), = sl.correct([("l1", 4.4)])
    assert stop_of(gap) == pytest.approx(4.4 + 8.5)
    # At 0.1 s steps the follower sees l1 brake a tenth of a second later:
    # nobody is asked, the Euler correction alone.
    sl, _, asked = _sumo_leaders(0.1, ("l2", -4.5))
    (_, gap, _), = sl.correct([("l1", 4.4)])
    assert asked == [] and stop_of(gap) == pytest.approx(4.4 + euler_brake_gap(11.0, 4.5, 0.1))
    # Leaders blendtrack drives keep their gap; no leader stays none.
    sl, _, asked = _sumo_leaders(1.0, ("l2", -4.5))
    sl.active = {"l1": None}  # type: ignore[dict-item]
    assert sl.correct([("l1", 4.4), None, ("", -1.0)]) == [("l1", 4.4), None, ("", -1.0)]
    assert asked == []


def test_a_change_waits_for_a_driver_joining_the_target_lane_from_beyond() -> None:
    # "me" (front 50 m, 5 m long) changes from e_0 to e_1 over 20 m; SUMO's
    # driver "far" on e_2 at 60 m wants to change right onto e_1.
    conn = FakeConn()
    v = conn.vehicle
    v.add("me", lane="e_0", pos=50.0, speed=12.0)
    v.add("far", lane="e_2", pos=60.0, speed=12.0)
    conn.lanes = {"e_2": ["far"]}
    wishes = {"far": tc.LCA_RIGHT}
    conn.lane_change_state = lambda vid, d: (wishes[vid] if d < 0 else 0, 0)  # type: ignore[attr-defined]
    lcs = lane_changes(conn, lanes={"e_1": FakeLane(200.0, n_lanes=3), "e_2": FakeLane(200.0, n_lanes=3)})
    joining = lambda: lcs.joining_from_beyond("me", "e", 1, 1, 50.0, 20.0)  # noqa: E731
    assert joining()
    # Blocked, or wanting the other way, or no wish: no.
    wishes["far"] = tc.LCA_RIGHT | tc.LCA_BLOCKED
    assert not joining()
    wishes["far"] = 0
    assert not joining()
    wishes["far"] = tc.LCA_RIGHT
    # Out of reach: past the change's end plus JOIN_LOOK_M, or that far behind the back.
    v.cars["far"]["pos"] = 50.0 + 20.0 + lc.JOIN_LOOK_M + 0.1
    assert not joining()
    v.cars["far"]["pos"] = 45.0 - lc.JOIN_LOOK_M - 0.1
    assert not joining()
    v.cars["far"]["pos"] = 45.0 - lc.JOIN_LOOK_M + 0.1
    assert joining()
    # No lane beyond the target (a change to the edge's last lane).
    assert not lcs.joining_from_beyond("me", "e", 2, 1, 50.0, 20.0)
    # A controlled vehicle there: its SUMO wish does not count, its change onto the target does.
    lcs.active["far"] = SimpleNamespace(vid="far", changing=None)  # type: ignore[assignment]
    assert not joining()
    lcs.active["far"] = SimpleNamespace(vid="far", changing=(-1, 1))  # type: ignore[assignment]
    assert joining()


def test_a_controlled_foe_is_known_by_its_track_wherever_sumo_has_it() -> None:
    """Bologna's 39a in small: "me" (slot 0) stands 1 m before its line on
    the minor road; the major way ":m_0_0" crosses its way 4 m into it,
    after a lane in "maj_0" of 0.2 m. A controlled bus (slot 1) whose
    track enters through ":m_0_0" 6 m ahead of its front, at 4 m/s, is to
    SUMO on "before_1", the lane beside its track's "before_0", on no lane
    SUMO would look at for this link: the bus arrives at the crossing in
    (6 + 4 - 2.5) / 4 = 1.9 s, before "me" can cross, so "me" waits. Where
    SUMO has it on its track's lane, SUMO's word (its links) stands."""
    conn = FakeConn()
    v = conn.vehicle
    v.add("me", lane="min_0", pos=99.0, speed=0.0)
    v.add("bus", lane="before_1", pos=10.0, speed=4.0, length=12.0)
    conn.lanes = {"maj_0": [], ":m_0_0": [], "before_1": ["bus"]}
    prohibitors = {":n_0_0": [(":m_0_0", "maj_0", 0.2, "", -1)]}
    net = SimpleNamespace(prohibitors=lambda via: prohibitors.get(via, []), conflict=lambda via, foe: (5.0, 4.0),
                          edge_lanes=lambda edge: ("maj_0",), feeders=lambda lane: ())
    fronts = {0: 99.0, 1: 50.0}
    lines = {1: [(20.0, 1), (56.0, 0)]}  # slot: (stop line's arc length, its junction lane's id)

    def stops_ahead(slots: list[int], max_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """As the RouteFleet's (tested in Rust): the lines ahead of each front within max_m."""
        rows = [(k, via, s - fronts[slot]) for k, slot in enumerate(slots) for s, via in lines.get(slot, [])
                if 0.0 <= s - fronts[slot] <= max_m]
        return (np.array([r[0] for r in rows], dtype=np.int64), np.array([r[1] for r in rows], dtype=np.int64),
                np.array([r[2] for r in rows]))

    fleet = SimpleNamespace(stops_ahead=stops_ahead, s_front=lambda slot: fronts[slot],
                            front_lane_position=lambda slot: (2, 10.0))
    tracks = SimpleNamespace(lanes=SimpleNamespace(names=[":m_0_0", ":x_0_0", "before_0"]))
    controlled = {"me": SimpleNamespace(slot=0), "bus": SimpleNamespace(slot=1)}
    j = Junctions(conn, net, tracks, fleet, 4.0, controlled=controlled)  # type: ignore[arg-type]
    assert j.approaching_on_tracks() == {":m_0_0": [("bus", pytest.approx(6.0))]}
    assert j.link_busy("me", 0, ":n_0_0", 100.0)
    # Farther back along its track than the look-ahead: not looked for.
    fronts[1] = 56.0 - jn.APPROACH_LOOK_M - 1.0
    j.new_step()
    assert ":m_0_0" not in j.approaching_on_tracks() and not j.link_busy("me", 0, ":n_0_0", 100.0)
    # Past its line (its front inside the junction): the check of the foe
    # lane's vehicles is the one that counts.
    fronts[1] = 57.0
    j.new_step()
    assert not j.link_busy("me", 0, ":n_0_0", 100.0)
    # On its track's lane to SUMO too: SUMO's links tell, not the track.
    fronts[1] = 50.0
    v.cars["bus"]["lane"] = "before_0"
    j.new_step()
    assert not j.link_busy("me", 0, ":n_0_0", 100.0)
    v.cars["bus"]["lane"] = "before_1"
    assert j.link_busy("me", 0, ":n_0_0", 100.0)
    # A SUMO driver where the bus was is not seen (SUMO's own links report it).
    j.controlled = {"me": controlled["me"]}
    j.new_step()
    assert not j.link_busy("me", 0, ":n_0_0", 100.0)


def test_a_foe_beyond_a_short_lane_in_or_changing_onto_it_is_seen() -> None:
    """Bologna's 20b in small: "me" turns right from the minor road into a
    merge with the major way ":m_0_0" (the ways meet 5 m into ours, 9.86 m
    into theirs), whose lane in, "maj_0", is 0.74 m long right after the
    junction before it (":p_0_0" 7 m, then "up_0"; beside them ":p_0_1" and
    "up_1", which lead to "maj_1"). "me", 8.4 m from its line at 6.42 m/s,
    needs 3.7 s to cross. A SUMO driver at 12.4 m/s on "up_1" 8.8 m from
    its end (16.9 m from the point less the clearance: 1.4 s) whose best
    lane is to its right changes there: seen, though its lane-change state
    says "stay". One on "up_0" counts when its next link leads onto
    "maj_0"; none counts that is too far, or stays on its lane."""
    conn = FakeConn()
    v = conn.vehicle
    v.add("me", lane="min_0", pos=91.6, speed=6.42)
    v.add("t", lane="up_1", pos=27.8, speed=12.4, best=[("up_0", 30.0, 0.0, 0), ("up_1", 30.0, 0.0, -1)])
    v.getBestLanes = lambda vid: [(*b, True, []) for b in v.cars[vid]["best"]]  # type: ignore[attr-defined]
    stay = tc.LCA_STAY | tc.LCA_COOPERATIVE
    conn.lane_change_state = lambda vid, d: (stay, stay)  # type: ignore[attr-defined]
    conn.lanes = {"maj_0": [], ":m_0_0": [], "up_1": ["t"]}
    prohibitors = {":n_0_0": [(":m_0_0", "maj_0", 0.74, "", -1)]}
    feeders = {"maj_0": ((":p_0_0", 7.02), ("up_0", 36.58)), "maj_1": ((":p_0_1", 7.02), ("up_1", 36.58))}
    net = SimpleNamespace(prohibitors=lambda via: prohibitors.get(via, []), conflict=lambda via, foe: (5.0, 9.86),
                          edge_lanes=lambda edge: ("maj_0", "maj_1") if edge == "maj" else (),
                          feeders=lambda lane: feeders.get(lane, ()), lane_length=lambda lane: 0.74)
    fleet = SimpleNamespace(s_front=lambda slot: 91.6, stops_ahead=lambda slots, m: (np.zeros(0, np.int64),) * 3)
    j = Junctions(conn, net, SimpleNamespace(lanes=SimpleNamespace(names=[])), fleet, 4.0,  # type: ignore[arg-type]
                  controlled={"me": SimpleNamespace(slot=0)})
    assert j.link_busy("me", 0, ":n_0_0", 100.0), "its best lane is to its right"
    v.cars["t"]["best"] = [("up_0", 30.0, 0.0, 1), ("up_1", 30.0, 0.0, 0)]
    j.new_step()
    assert not j.link_busy("me", 0, ":n_0_0", 100.0), "it stays on its lane"
    conn.lane_change_state = lambda vid, d: (tc.LCA_RIGHT | tc.LCA_STRATEGIC, 0)  # type: ignore[attr-defined]
    assert j.link_busy("me", 0, ":n_0_0", 100.0), "SUMO says it wants to change right"
    v.cars["t"]["speed"] = 8.0  # (36.58 - 27.8 + 8.1) / 8 = 2.1 s: still first
    assert j.link_busy("me", 0, ":n_0_0", 100.0)
    v.cars["t"].update(pos=0.0)  # 44.7 m at 8 m/s: 5.6 s, after "me" has crossed
    assert not j.link_busy("me", 0, ":n_0_0", 100.0)
    # On the lane before "maj_0" itself: a foe if its next link leads there.
    v.cars["t"].update(lane="up_0", pos=27.8, speed=12.4)
    conn.lanes = {"maj_0": [], ":m_0_0": [], "up_0": ["t"]}
    v.links["t"] = [("maj_0", True, True, False, ":p_0_0", "M", "s", 7.02)]
    assert j.link_busy("me", 0, ":n_0_0", 100.0)
    v.links["t"] = [("side_0", True, True, False, ":p_1_0", "M", "r", 7.02)]
    assert not j.link_busy("me", 0, ":n_0_0", 100.0), "it turns away before the short lane"
    # Inside the junction before, on the way onto "maj_0": a foe.
    conn.lanes = {"maj_0": [], ":m_0_0": [], ":p_0_0": ["t"]}
    v.cars["t"].update(lane=":p_0_0", pos=5.0)
    assert j.link_busy("me", 0, ":n_0_0", 100.0)
    # A long lane in is all that is looked along (the foe there is seen on it).
    net.lane_length = lambda lane: 80.0
    prohibitors[":n_0_0"] = [(":m_0_0", "maj_0", 80.0, "", -1)]
    j._prohibitors.clear()
    assert not j.link_busy("me", 0, ":n_0_0", 100.0)


def test_a_sumo_driver_waiting_for_the_controlled_vehicle_s_way_at_an_internal_stop_is_not_followed() -> None:
    """Junction 50 of Bologna in small: the major way ":w_0_0" (12 m) and the
    minor left turn ":w_1_0" (13 m), then its internal waiting point
    ":w_2_0" (3 m), merge onto "out". A SUMO driver standing at the end of
    ":w_1_0" waits there for the major way: followed, the controlled vehicle
    stood and so did it, for good. Moving, or on a way that does not give
    way to the vehicle's, or controlled, it is followed as before."""
    conn = FakeConn()
    v = conn.vehicle
    v.add("me", lane=":w_0_0", pos=5.0, speed=0.0, min_gap=2.5)
    v.add("sumo", lane=":w_1_0", pos=12.9, speed=0.0, length=5.0)
    conn.lanes = {":w_1_0": ["sumo"]}
    after = {":w_0_0": [(":w_0_0", 12.0), ("out", 100.0)]}
    ways = {"out": [((":w_0_0", 12.0),), ((":w_1_0", 13.0), (":w_2_0", 3.0))]}
    prohibitors = {":w_1_0": [(":w_0_0", "maj", 50.0, "", -1)]}

    def junctions(yields: bool, controlled: Any = None) -> Junctions:
        net = SimpleNamespace(lanes_after=lambda via: after.get(via, []), lanes_next=lambda lane: (), ways_into=lambda lane: ways.get(lane, []),
                              lane_length=lambda lane: 50.0, lanes_into_merges=lambda: frozenset({"maj"}),
                              prohibitors=lambda via: prohibitors.get(via, []) if yields else [])
        return Junctions(conn, net, None, None, 4.0, controlled={} if controlled is None else controlled)  # type: ignore[arg-type]

    track = ["maj", ":w_0_0", "out"]
    # 7 m from the merge point against its 13 - 12.9 + 3 = 3.1 m: nearer, but waiting for "me".
    assert junctions(yields=True).leader_at_merge("me", ":w_0_0", track, None) is None
    # Its way has priority: it is followed (gap 7 - 3.1 - 5 - 2.5).
    assert junctions(yields=False).leader_at_merge("me", ":w_0_0", track, None) == ("sumo", pytest.approx(-3.6))
    # Moving, it goes: followed.
    v.cars["sumo"]["speed"] = 1.0
    assert junctions(yields=True).leader_at_merge("me", ":w_0_0", track, None) == ("sumo", pytest.approx(-3.6))
    # Controlled: the rule between two controlled vehicles (nearer goes) holds.
    v.cars["sumo"]["speed"] = 0.0
    assert junctions(yields=True, controlled={"sumo": None}).leader_at_merge("me", ":w_0_0", track, None) == ("sumo", pytest.approx(-3.6))
    # Not yet at its waiting point (4 m before it): followed as before.
    v.cars["sumo"]["pos"] = 9.0
    assert junctions(yields=True).leader_at_merge("me", ":w_0_0", track, None) == ("sumo", pytest.approx(7.0 - 7.0 - 5.0 - 2.5))


def test_before_a_fanout_a_body_standing_across_the_way_on_the_branch_beside_is_the_leader() -> None:
    """Lane "in_0" (100 m, ending at (0, 0)) fans out through ":f_0_0"
    (the track's, straight east to (10, 0)) and ":f_0_1". "me" is on
    "in_0" at 95 m, its front at (-5, 0), with nothing ahead on its own
    way. "other" stands on ":f_0_1" with its body (width 2) from (1, 1.2)
    to (6, 1.2), across the track's way (1.2 m from it, within the half
    widths and the margin, 1 + 0.3 + 1): it is the leader, at the straight
    distance from the front to its body, less its half width and the
    minGap: sqrt(6^2 + 1.2^2) - 1 - 2.5 (Bologna, junction 11: a vehicle
    inserted at speed ran into one such)."""
    conn = FakeConn()
    v = conn.vehicle
    v.add("me", lane="in_0", pos=95.0, speed=13.9, xy=(-5.0, 0.0), angle=90.0)
    v.add("other", lane=":f_0_1", pos=6.0, speed=0.0, xy=(6.0, 1.2), angle=90.0)
    v.cars["me"]["min_gap"] = 2.5
    conn.lanes = {":f_0_1": ["other"]}
    after = {":f_0_0": [(":f_0_0", 10.0), ("out_0", 100.0)]}
    net = SimpleNamespace(
        from_lane=lambda via: "in_0" if via.startswith(":f_0_") else None,
        fanouts=lambda: {"in_0": ((":f_0_0", ":f_0_1"), 100.0)},
        lanes_after=lambda via: after.get(via, []), lanes_next=lambda lane: (),
        junction_lanes=lambda via: (np.array([[0.0, 0.0], [10.0, 0.0]]), (":f_0_1",)),
        junction_exits=lambda via: ("out_1",),
    )
    j = Junctions(conn, net, None, None, 4.0, controlled={})  # type: ignore[arg-type]
    track = ["in_0", ":f_0_0", "out_0"]
    expected = math.hypot(6.0, 1.2) - 1.0 - 2.5
    assert j.leader_at_fanout("me", "in_0", track, None) == ("other", pytest.approx(expected))
    # SUMO's farther leader gives way to it; a nearer one on the lane stays.
    assert j.leader_at_fanout("me", "in_0", track, ("far", 40.0)) == ("other", pytest.approx(expected))
    assert j.leader_at_fanout("me", "in_0", track, ("close", 1.0)) == ("close", 1.0)
    # Clear of the way (the branches have parted there), or moving off: not in the way.
    v.cars["other"]["xy"] = (6.0, 3.5)
    assert j.leader_at_fanout("me", "in_0", track, None) is None
    v.cars["other"].update(xy=(6.0, 1.2), speed=FOLLOW_MIN_SPEED_MPS)
    assert j.leader_at_fanout("me", "in_0", track, None) is None


def test_inside_a_fanout_a_body_standing_across_the_rest_of_the_way_is_the_leader() -> None:
    """Lane "in_0" fans out through ":f_0_0" (to "out_0", straight east from
    (0, 0) to (10, 0)) and ":f_0_1" (to "out_1"). "me" is inside on
    ":f_0_0", its front at (1, 0). "other" stands 0.5 m onto "out_1" with
    its back in the junction: its body (width 2) runs from (1, 1.2) to
    (6, 1.2), 1.2 m beside the way, within the half widths and the margin
    (1 + 0.3 + 1). Gap: 1.2 - 1 (its half width) - minGap 2.5 = -2.3."""
    conn = FakeConn()
    v = conn.vehicle
    v.add("me", lane=":f_0_0", pos=1.0, speed=1.0, xy=(1.0, 0.0), angle=90.0)
    v.add("other", lane="out_1", pos=0.5, speed=0.0, xy=(6.0, 1.2), angle=90.0)
    conn.lanes = {"out_1": ["other"]}
    net = SimpleNamespace(
        from_lane=lambda via: "in_0" if via.startswith(":f_0_") else None,
        fanouts=lambda: {"in_0": ((":f_0_0", ":f_0_1"), 100.0)},
        junction_lanes=lambda via: (np.array([[0.0, 0.0], [10.0, 0.0]]), (":f_0_1",)),
        junction_exits=lambda via: ("out_1",),
    )
    j = Junctions(conn, net, None, None, 4.0, controlled={})  # type: ignore[arg-type]
    track = ["in_0", ":f_0_0", "out_0"]
    assert j.leader_in_fanout("me", ":f_0_0", track, None) == ("other", pytest.approx(-2.3))
    # A nearer leader of its own stays; a farther one gives way to the body.
    assert j.leader_in_fanout("me", ":f_0_0", track, ("near", -3.0)) == ("near", -3.0)
    assert j.leader_in_fanout("me", ":f_0_0", track, ("far", 20.0)) == ("other", pytest.approx(-2.3))
    # Moving off, it is not waited for.
    v.cars["other"]["speed"] = FOLLOW_MIN_SPEED_MPS
    assert j.leader_in_fanout("me", ":f_0_0", track, None) is None
    v.cars["other"]["speed"] = 0.0
    # Clear of the way (3.5 m beside it), or behind the front: not in the way.
    v.cars["other"]["xy"] = (6.0, 3.5)
    assert j.leader_in_fanout("me", ":f_0_0", track, None) is None
    v.cars["other"]["xy"] = (-1.5, 1.2)
    assert j.leader_in_fanout("me", ":f_0_0", track, None) is None
    # Its back out of the junction (SUMO lists it on the lane out only): not looked at.
    v.cars["other"].update(xy=(6.0, 1.2), pos=5.5)
    assert j.leader_in_fanout("me", ":f_0_0", track, None) is None
    # A way that does not start at a fan-out is not looked at.
    v.cars["other"]["pos"] = 0.5
    assert j.leader_in_fanout("me", ":g_0_0", ["in_0", ":g_0_0", "out_0"], ("x", 9.0)) == ("x", 9.0)


def test_a_long_vehicle_moved_by_xy_is_kept_on_its_lane_when_its_front_swings_out() -> None:
    """``SumoRun._keep_route``: the lane "e_0" runs along y = 0 and is 3.2 m
    wide. A 12 m bus whose front is 1.6 m or more off the centreline is kept
    on the lane (keepRoute 1); nearer, or a car, or a junction lane, or a
    change under way: SUMO's nearest lane (3). The length is its vType's
    (the selection's type info, as the fleet's body)."""
    import numpy as np

    from blendtrack.sumo.runner import LONG_VEHICLE_M, SumoRun

    types = {"coach": {"length": 12.0, "width": 2.5}, "sedan": {"length": 5.0, "width": 1.8}}
    selection = SimpleNamespace(type_info=lambda vtype: types[vtype])
    shape = (np.array([[0.0, 0.0], [100.0, 0.0]]), 3.2)
    run = SimpleNamespace(selection=selection, network=SimpleNamespace(lane_shape=lambda lane: shape, edge_lanes=lambda edge: (edge + "_0",)))
    bus = SimpleNamespace(vid="bus", changing=None, record=SimpleNamespace(vtype="coach"))
    car = SimpleNamespace(vid="car", changing=None, record=SimpleNamespace(vtype="sedan"))
    keep = SumoRun._keep_route
    assert keep(run, bus, "e", "e_0", 50.0, 1.6) == 1  # type: ignore[arg-type]
    assert keep(run, bus, "e", "e_0", 50.0, -2.4) == 1  # type: ignore[arg-type]
    assert keep(run, bus, "e", "e_0", 50.0, 1.6 - 1e-9) == 3  # type: ignore[arg-type]
    assert keep(run, bus, ":j_0", ":j_0_0", 50.0, 2.4) == 3  # type: ignore[arg-type]
    assert keep(run, car, "e", "e_0", 50.0, 2.3) == 3 and LONG_VEHICLE_M > 5.0  # type: ignore[arg-type]
    bus.changing = (1, 1)
    assert keep(run, bus, "e", "e_0", 50.0, 2.4) == 3  # type: ignore[arg-type]


def test_no_vehicle_is_moved_by_xy_off_the_network() -> None:
    """``SumoRun._keep_route``: keepRoute 3 lets SUMO take a vehicle off the
    road when its front is further off the lane than half the lane's and
    half its own width (1.6 + 0.9 m for a 1.8 m car on a 3.2 m lane); there
    it is on no lane and nobody sees it. Such a move gets keepRoute 1 (kept
    on a lane of its route), whatever the vehicle, lane or change; a front
    that is near another lane of the edge is not off the road."""
    import numpy as np

    from blendtrack.sumo.runner import OFF_ROAD_MARGIN_M, SumoRun

    types = {"coach": {"length": 12.0, "width": 2.5}, "sedan": {"length": 5.0, "width": 1.8}}
    shapes = {"e_0": (np.array([[0.0, 0.0], [100.0, 0.0]]), 3.2), "e_1": (np.array([[0.0, 3.2], [100.0, 3.2]]), 3.2)}
    edges = {"e": ("e_0", "e_1"), ":j_0": ("e_0",)}
    run = SimpleNamespace(selection=SimpleNamespace(type_info=lambda vtype: types[vtype]),
                          network=SimpleNamespace(lane_shape=shapes.__getitem__, edge_lanes=edges.__getitem__))
    car = SimpleNamespace(vid="car", changing=None, record=SimpleNamespace(vtype="sedan"))
    bus = SimpleNamespace(vid="bus", changing=(1, 1), record=SimpleNamespace(vtype="coach"))
    keep = SumoRun._keep_route
    off = 1.6 + 0.9 - OFF_ROAD_MARGIN_M
    assert keep(run, car, ":j_0", "e_0", 50.0, -off - 1e-6) == 1  # type: ignore[arg-type]
    assert keep(run, car, ":j_0", "e_0", 50.0, -off + 1e-6) == 3  # type: ignore[arg-type]
    # Beyond lane 0 but over lane 1 of the same edge: on the road.
    assert keep(run, car, "e", "e_0", 50.0, off + 1e-6) == 3  # type: ignore[arg-type]
    assert keep(run, car, "e", "e_0", 50.0, -off - 1e-6) == 1  # type: ignore[arg-type]
    # A wider vehicle reaches further before it is off the road; a change under way is no exception.
    assert keep(run, bus, "e", "e_1", 50.0, -2.6) == 3  # type: ignore[arg-type]
    assert keep(run, bus, "e", "e_1", 50.0, -2.8) == 1  # type: ignore[arg-type]


def test_drivers_beyond_the_target_lane_are_held_while_a_change_goes_on() -> None:
    """"me" (front 50 m, 5 m long) changes from e_0 onto e_1, the change
    from 40 m over 20 m. SUMO's drivers on e_2 from 45 - 30 m to 60 + 30 m
    are held on e_2 for FAR_SIDE_HOLD_S, whatever their lane-change model
    wants now; those out of reach and controlled vehicles are left alone;
    nothing before the change has a span."""
    from blendtrack.sumo.tracks import Active

    conn = FakeConn()
    v = conn.vehicle
    v.add("me", lane="e_0", pos=50.0, speed=12.0, lane_index=0)
    for vid, pos in [("w", 70.0), ("calm", 52.0), ("far", 60.0 + lc.JOIN_LOOK_M + 0.1), ("back", 45.0 - lc.JOIN_LOOK_M - 0.1),
                     ("edge", 45.0 - lc.JOIN_LOOK_M + 0.1), ("ctl", 55.0)]:
        v.add(vid, lane="e_2", pos=pos, speed=12.0)
    conn.lanes = {"e_2": ["back", "edge", "calm", "ctl", "w", "far"]}
    lcs = lane_changes(conn)
    act = Active("me", 0, None, "", None, changing=(1, 1), change_from=0, change_edge="e")  # type: ignore[arg-type]
    lcs.active.update({"me": act, "ctl": act})
    lcs.hold_far_side(act, "e", 2, 45.0, 50.0)
    assert v.calls == []  # no span yet: not under way
    act.change_span = (40.0, 20.0)
    lcs.hold_far_side(act, "e", 2, 45.0, 50.0)
    held = lc.FAR_SIDE_HOLD_S
    assert v.calls == [("hold", "edge", 2, held), ("hold", "calm", 2, held), ("hold", "w", 2, held)]
    assert lcs.counts["far_side_holds"] == 3
    # Through seen_coming: the lane beyond e_1 seen from e_0 is e_2.
    v.calls.clear()
    lcs.seen_coming(act, 0, 1)
    assert [c[1] for c in v.calls if c[0] == "hold"] == ["edge", "calm", "w"]
    # No lane there (SUMO raises): nothing, no error.
    conn.vehicles_on = lambda lane: (_ for _ in ()).throw(KeyError(lane))  # type: ignore[method-assign]
    lcs.hold_far_side(act, "e", 3, 45.0, 50.0)
