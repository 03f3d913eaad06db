"""RouteFleet (the SUMO plugin's engine) from Python: bad input is a clear
error, never a crash, and the two-call step works as documented."""

from __future__ import annotations

import math

import numpy as np
import pytest

import blendtrack
from blendtrack import RouteFleet


def _fleet() -> tuple[RouteFleet, int]:
    f = RouteFleet()
    xs = np.arange(0.0, 301.0, 1.0)
    path = blendtrack.Path(np.column_stack([xs, np.zeros_like(xs)]))
    track = f.add_route(
        path,
        None,
        piece_start_m=[0.0, 100.0],
        piece_scale=[1.0, 1.0],
        piece_offset_m=[0.0, 0.0],
        piece_lane_length_m=[100.0, 200.0],
        piece_speed_mps=[15.0, 15.0],
        piece_lane=[0, 1],
        piece_edge=[0, 1],
        piece_lane_index=[0, 0],
        length_m=300.0,
        stop_s_m=[100.0],
        stop_light=[0],
        stop_link=[0],
        stop_major=[0],
        stop_via=[2],
        stop_exit_m=[100.0],
    )
    return f, track


def _add(f: RouteFleet, track: int, x: float, v: float, name: str | None = None) -> int:
    return f.add_vehicle(track, None, None, reach_m=3.5, length_m=4.5, min_gap_m=2.5, x=x, y=0.0, theta=0.0, v=v, name=name)


def _step(f: RouteFleet, slots: list[int]) -> dict[str, np.ndarray]:
    n = len(slots)
    nan = [math.nan] * n
    q = f.plan(slots, nan, [-1] * n, nan, [-1] * n, nan)
    return f.step(np.zeros(len(q), dtype=bool), 0.1)


def test_red_light_holds_the_vehicle_and_moves_are_lane_moves() -> None:
    f, track = _fleet()
    slot = _add(f, track, 40.0, 10.0)
    f.set_signal(0, "r")
    for _ in range(300):
        out = _step(f, [slot])
    # Standing at the line: by lane (speed only, or nothing to send).
    assert out["move"][0] in (0, 4) and out["lane"][0] == 0 and out["sumo_speed_mps"][0] < 0.05
    assert 95.0 < f.s_front(slot) < 100.0
    assert f.stats(slot)["red_light_violations"] == 0
    f.set_signal(0, "G")
    for _ in range(100):
        _step(f, [slot])
    assert f.s_front(slot) > 110.0
    stats = f.remove_vehicle(slot)
    # 400 steps of 0.1 s at the default control rate (0.05 s): two control steps each.
    assert stats["steps"] == 800 and len(f) == 0
    # The finished values come with the sums they are made of.
    assert stats["lateral_error_rms_m"] == pytest.approx(math.sqrt(stats["sum_e2"] / 800), rel=1e-12)
    assert stats["mean_speed_mps"] == pytest.approx(stats["sum_v"] / 800, rel=1e-12)
    assert stats["long_jerk_rms_mps3"] == pytest.approx(math.sqrt(stats["sum_jerk2"] / stats["jerk_n"]), rel=1e-12)
    assert isinstance(stats["steps"], int) and isinstance(stats["sum_e2"], float)


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda f, t, s: f.plan([s], [1.0, 2.0], [-1], [0.0], [-1], [0.0]), "leader_gap"),
        (lambda f, t, s: f.plan([s + 7], [1.0], [-1], [0.0], [-1], [0.0]), "slot"),
        (lambda f, t, s: f.step([], 0.1), "plan"),
        (lambda f, t, s: f.retrack(s, 99), "track"),
        (lambda f, t, s: _add(f, t, math.nan, 1.0), "finite"),
        (lambda f, t, s: f.set_signal(1 << 21, "r"), "light"),
        (lambda f, t, s: f.add_route(blendtrack.Path(np.array([[0.0, 0.0], [1.0, 0.0]])), None, piece_start_m=[0.0, -1.0], piece_scale=[1.0, 1.0], piece_offset_m=[0.0, 0.0], piece_lane_length_m=[1.0, 1.0], piece_speed_mps=[1.0, 1.0], piece_lane=[0, 0], piece_edge=[0, 0], piece_lane_index=[0, 0], length_m=1.0), "piece 1"),
        (lambda f, t, s: f.add_route(blendtrack.Path(np.array([[0.0, 0.0], [1.0, 0.0]])), None, piece_start_m=[0.0], piece_scale=[1.0], piece_offset_m=[0.0], piece_lane_length_m=[1.0], piece_speed_mps=[1.0], piece_lane=[-3], piece_edge=[0], piece_lane_index=[0], length_m=1.0), "piece_lane"),
        (lambda f, t, s: f.add_route(blendtrack.Path(np.array([[0.0, 0.0], [1.0, 0.0]])), None, piece_start_m=[0.0, 0.5], piece_scale=[1.0, 1.0], piece_offset_m=[0.0, 0.0], piece_lane_length_m=[1.0, 1.0], piece_speed_mps=[1.0, 1.0], piece_lane=[0, 1], piece_edge=[0, 1], piece_lane_index=[0, 0], length_m=1.0, piece_occurrence=[1, 0]), "piece 1 has occurrence 0 after 1"),
        (lambda f, t, s: f.add_route(blendtrack.Path(np.array([[0.0, 0.0], [1.0, 0.0]])), None, piece_start_m=[0.0], piece_scale=[1.0], piece_offset_m=[0.0], piece_lane_length_m=[1.0], piece_speed_mps=[1.0], piece_lane=[0], piece_edge=[0], piece_lane_index=[0], length_m=1.0, lane_change=(0, 1, 0, 0)), "lane_change has 4 items"),
        (lambda f, t, s: f.retrack(s, t, occurrence=-1), "occurrence"),
    ],
)
def test_bad_calls_raise_input_error_and_leave_the_fleet_usable(call, match) -> None:  # type: ignore[no-untyped-def]
    f, track = _fleet()
    slot = _add(f, track, 40.0, 10.0)
    with pytest.raises(blendtrack.InputError, match=match):
        call(f, track, slot)
    out = _step(f, [slot])
    assert out["move"][0] == 1 and len(f) == 1


def test_plan_sumo_reads_getleader_tuples_and_asks_for_background_speeds() -> None:
    f, track = _fleet()
    lead = _add(f, track, 60.0, 12.0, name="car.0")
    fol = _add(f, track, 40.0, 12.0, name="car.1")
    solo = _add(f, track, 10.0, 12.0, name="car.2")
    asked: list[str] = []

    def speed_of(vid: str) -> float:
        asked.append(vid)
        return 3.0

    slots = [lead, fol, solo]
    nan = [math.nan] * 3
    # car.0 follows a background vehicle; car.1 follows car.0 (known here,
    # so its speed is blendtrack's); car.2 has none ("" as SUMO says).
    f.plan_sumo(slots, [("truck.7", 20.0), ("car.0", 12.0), ("", -1.0)], speed_of)
    out = f.step([], 0.1)
    assert asked == ["truck.7"]
    # Against the same leaders given to plan(): the same commands.
    g, track2 = _fleet()
    for x in (60.0, 40.0, 10.0):
        _add(g, track2, x, 12.0)
    g.plan(slots, [20.0, 12.0, math.nan], [-1, lead, -1], [3.0, math.nan, math.nan], [-1] * 3, nan)
    ref = g.step([], 0.1)
    assert np.array_equal(out["accel_mps2"], ref["accel_mps2"])
    assert out["accel_mps2"][0] < out["accel_mps2"][2], "the slow background leader brakes car.0"
    # A name is one vehicle's; once removed it is free again.
    with pytest.raises(blendtrack.InputError, match="car.1"):
        _add(f, track, 90.0, 1.0, name="car.1")
    f.remove_vehicle(fol)
    _add(f, track, 90.0, 1.0, name="car.1")


@pytest.mark.parametrize(
    "leaders, match",
    [([("a", 1.0)], "has 1 entries, expected 2"), ([7, None], r"leaders\[0\]"), ([("a", "far"), None], "gap"), ([(1, 2.0), None], "id"), ([("a",), None], "items"),
     ([("a", 1.0, "near"), None], "room"), ([("a", 1.0, 2.0, 3.0), None], "3 .id, gap, room.")],
)
def test_plan_sumo_rejects_malformed_leaders(leaders, match) -> None:  # type: ignore[no-untyped-def]
    f, track = _fleet()
    s = [_add(f, track, 40.0, 10.0), _add(f, track, 20.0, 10.0)]
    with pytest.raises(blendtrack.InputError, match=match):
        f.plan_sumo(s, leaders, lambda vid: 0.0)
    f.plan_sumo(s, [None, None], lambda vid: 0.0, [1], [0], [3.0])
    assert len(f.step([], 0.1)["move"]) == 2
    # SUMO's own gap may follow a shortened one.
    f.plan_sumo(s, [("a", 1.0, 4.0), None], lambda vid: 0.0)
    assert len(f.step([], 0.1)["move"]) == 2


def test_bad_settings_are_config_errors() -> None:
    with pytest.raises(blendtrack.ConfigError, match="comfort_lateral_accel_mps2"):
        RouteFleet(comfort_lateral_accel_mps2=-1.0)


def test_plan_sumo_sparse_reads_must_index_the_slots() -> None:
    f, track = _fleet()
    s = [_add(f, track, 40.0, 10.0)]
    with pytest.raises(blendtrack.InputError, match=r"read_index\[0\] = 3"):
        f.plan_sumo(s, [None], lambda vid: 0.0, [3], [0], [1.0])
    with pytest.raises(blendtrack.InputError, match="read_pos"):
        f.plan_sumo(s, [None], lambda vid: 0.0, [0], [0], [])


def test_leaders_on_lanes_feed_the_next_plan_sumo_of_the_same_slots() -> None:
    f, track = _fleet()
    s = [_add(f, track, x, 10.0, name=f"c{k}") for k, x in enumerate((20.0, 50.0, 80.0))]
    _step(f, s)  # the first (placing) moves make the places known
    lanes = f.lanes_with_followers(s).tolist()
    assert lanes == [0]
    # Lane 0 back to front: c0, a background car, c1, c2.
    ask = f.leaders_on_lanes(s, lanes, [["c0", "bg", "c1", "c2"]]).tolist()
    assert ask == [0, 2], "c0 follows a background car, c2 is first on its lane"
    listed = f.listed_leaders()
    assert listed[0] is None and listed[2] is None and listed[1] is not None and listed[1][0] == "c2"
    f.plan_sumo(s, [("bg", 5.0), None], lambda vid: 4.0, leader_index=ask)
    out = f.step([], 0.1)
    assert out["accel_mps2"][0] < out["accel_mps2"][2], "c0 brakes for the slow background car"
    # leader_index without a matching leaders_on_lanes call is an error, not a guess.
    with pytest.raises(blendtrack.InputError, match="leaders_on_lanes"):
        f.plan_sumo(s, [None, None], lambda vid: 0.0, leader_index=[0, 2])
    f.leaders_on_lanes(s, lanes, [["c0", "c1", "c2"]])
    with pytest.raises(blendtrack.InputError, match="slots differ"):
        f.plan_sumo(s[:2], [None], lambda vid: 0.0, leader_index=[0])
    f.leaders_on_lanes(s, lanes, [["c0", "c1", "c2"]])
    with pytest.raises(blendtrack.InputError, match=r"leader_index\[0\] = 7"):
        f.plan_sumo(s, [None], lambda vid: 0.0, leader_index=[7])
    with pytest.raises(blendtrack.InputError, match="not a string"):
        f.leaders_on_lanes(s, lanes, [["c0", 3]])


def test_plan_sumo_soft_leaders_are_braked_for_at_max_deceleration_at_most() -> None:
    """A vehicle to line up behind on the lane beside (a merger's, or the
    changer a courtesy follower lets in) comes on top of the own leader and
    is braked for at the planning deceleration at most: given as the leader
    instead, the same standing vehicle 3 m ahead at 15 m/s asks for far more
    (the stopping law's emergency side)."""
    cfg = blendtrack.ControllerConfig().replace(preferred_speed=15.0)
    b_f = cfg.max_deceleration

    def accel(leaders: list, soft: list | None) -> float:  # type: ignore[type-arg]
        f, track = _fleet()
        slot = f.add_vehicle(track, cfg, None, reach_m=3.5, length_m=4.5, min_gap_m=2.5, x=40.0, y=0.0, theta=0.0, v=15.0)
        f.plan_sumo([slot], leaders, lambda vid: 0.0, soft_leaders=soft)
        return float(f.step([], 0.1)["accel_mps2"][0])

    free = accel([None], None)
    as_leader = accel([("bg", 3.0)], None)
    as_soft = accel([None], [(0, "bg", 3.0)])
    assert as_leader < b_f - 1.0 and as_soft == pytest.approx(b_f, abs=1e-9) and free == 0.0
    # Far enough that the law asks for less than b_f: the same either way.
    assert accel([None], [(0, "bg", 35.0)]) == accel([("bg", 35.0)], None)
    assert b_f < accel([None], [(0, "bg", 35.0)]) < free
    # The own leader still counts in full beside a soft one.
    assert accel([("bg", 3.0)], [(0, "other", 60.0)]) == as_leader
    # No leader in SUMO's words (empty id, gap below -100 m): nothing.
    assert accel([None], [(0, "", 3.0), (0, "bg", -101.0)]) == free


@pytest.mark.parametrize(
    "soft, match",
    [([(0, "a")], r"soft_leaders\[0\] is not an \(index, id, gap\)"), ([(5, "a", 1.0)], "index 5"), ([(0, 7, 1.0)], r"soft_leaders\[0\]"), ([None], r"soft_leaders\[0\]")],
)
def test_plan_sumo_rejects_malformed_soft_leaders(soft, match) -> None:  # type: ignore[no-untyped-def]
    f, track = _fleet()
    s = [_add(f, track, 40.0, 10.0)]
    with pytest.raises(blendtrack.InputError, match=match):
        f.plan_sumo(s, [None], lambda vid: 0.0, soft_leaders=soft)
    f.plan_sumo(s, [None], lambda vid: 0.0)
    assert len(f.step([], 0.1)["move"]) == 1
