"""The registries a long run keeps bounded (issue 22): RouteFleet hands a
removed track's id out again, the SUMO bridge keeps the shared tracks
driven plus at most IDLE_TRACKS others, each for at most IDLE_TRACK_S, and a
vehicle's own lane-change track goes once it has left the change's edge."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

import blendtrack
from blendtrack import ControllerConfig, RouteFleet
from blendtrack.sumo.network import Network
from blendtrack.sumo.tracks import IDLE_TRACK_S, IDLE_TRACKS, SHARE_AFTER_M, Tracks

ROOT = Path(__file__).resolve().parents[1]
GRID_NET = ROOT / "sumo_scenarios" / "urban_grid" / "urban_grid.net.xml"


def _route(f: RouteFleet, length: float) -> int:
    xs = np.arange(0.0, length + 1.0, 1.0)
    path = blendtrack.Path(np.column_stack([xs, np.zeros_like(xs)]))
    return f.add_route(
        path, None, piece_start_m=[0.0], piece_scale=[1.0], piece_offset_m=[0.0], piece_lane_length_m=[length],
        piece_speed_mps=[15.0], piece_lane=[0], piece_edge=[0], piece_lane_index=[0], length_m=length,
        stop_s_m=[], stop_light=[], stop_link=[], stop_major=[], stop_via=[], stop_exit_m=[],
    )


def test_route_fleet_reuses_removed_track_ids() -> None:
    f = RouteFleet()
    kept = _route(f, 100.0)
    slot = f.add_vehicle(kept, None, None, reach_m=3.5, length_m=4.5, min_gap_m=2.5, x=10.0, y=0.0, theta=0.0, v=5.0)
    for i in range(300):
        ids = [_route(f, 50.0 + i % 7 + k) for k in range(3)]
        # Three at once beside the driven one: ids 1, 2, 3 every time.
        assert sorted(ids) == [1, 2, 3]
        for t in ids:
            f.remove_route(t)
        assert f.n_tracks == 1
    assert f.track_capacity == 4
    # The driven track was never touched: its vehicle is still on it.
    assert f.s_front(slot) > 10.0


def test_shared_tracks_nobody_drives_are_bounded() -> None:
    fleet = RouteFleet()
    network = Network(GRID_NET)
    tracks = Tracks(fleet, network, ControllerConfig(), 0.0)
    edges = sorted(e.getID() for e in network.net().getEdges())
    assert len(edges) > 2 * IDLE_TRACKS, "enough routes to overflow the idle tracks"
    # The first route is driven throughout; every other one is built and left.
    geo, driven = tracks.geometry((edges[0],), 0)
    x, y = geo.points[5]
    tracks.enter(driven)
    built = {}
    for edge in edges[1:]:
        built[edge] = tracks.geometry((edge,), 0)[1]
        assert fleet.n_tracks <= IDLE_TRACKS + 1
    assert fleet.n_tracks == IDLE_TRACKS + 1 and len(tracks.geo_cache) == IDLE_TRACKS + 1
    assert tracks.geometry((edges[0],), 0)[1] == driven, "the driven track is kept"
    assert tracks.geometry((edges[-1],), 0)[1] == built[edges[-1]], "the last one left is kept"
    # A route evicted long ago is built again, on a reused id.
    assert ((edges[1],), 0, ()) not in tracks.geo_cache
    tracks.geometry((edges[1],), 0)
    assert fleet.track_capacity <= IDLE_TRACKS + 2
    slot = fleet.add_vehicle(driven, None, None, reach_m=3.5, length_m=4.5, min_gap_m=2.5, x=float(x), y=float(y),
                             theta=0.0, v=5.0)
    fleet.remove_vehicle(slot)
    # Once left, the driven track is one idle track among the others: the bound holds.
    tracks.leave(driven)
    assert len(tracks.geo_cache) == fleet.n_tracks == IDLE_TRACKS
    assert fleet.track_capacity <= IDLE_TRACKS + 2


def test_idle_shared_tracks_expire_after_idle_track_s() -> None:
    fleet = RouteFleet()
    tracks = Tracks(fleet, Network(GRID_NET), ControllerConfig(), 0.0)
    edges = sorted(e.getID() for e in tracks.network.net().getEdges())
    tracks.expire(10.0)
    _, early = tracks.geometry((edges[0],), 0)  # idle from t = 10 s
    tracks.expire(50.0)
    _, later = tracks.geometry((edges[1],), 0)  # idle from t = 50 s
    _, driven = tracks.geometry((edges[2],), 0)
    tracks.enter(driven)
    tracks.expire(10.0 + IDLE_TRACK_S)
    assert fleet.n_tracks == 3, "idle for exactly IDLE_TRACK_S: still kept"
    tracks.expire(10.0 + IDLE_TRACK_S + 1.0)
    assert ((edges[0],), 0, ()) not in tracks.geo_cache and fleet.n_tracks == 2
    tracks.expire(10.0 * IDLE_TRACK_S)
    # The later idle one goes too; the driven one stays however long it is driven.
    assert list(tracks.geo_cache) == [((edges[2],), 0, ())] and fleet.n_tracks == 1
    assert tracks.geometry((edges[2],), 0)[1] == driven
    # Left at 10 IDLE_TRACK_S, it goes IDLE_TRACK_S later.
    tracks.leave(driven)
    tracks.expire(11.0 * IDLE_TRACK_S - 1.0)
    assert fleet.n_tracks == 1
    tracks.expire(11.0 * IDLE_TRACK_S + 1.0)
    assert fleet.n_tracks == 0 and not tracks.geo_cache


def test_a_vehicle_leaves_its_lane_change_track_on_the_next_edge(tmp_path: Path) -> None:
    # The highway's merge, every vehicle controlled: merging vehicles change
    # lanes on a track of their own. Once a vehicle is SHARE_AFTER_M into a
    # normal lane of another edge and no longer changing, it is back on the shared track of
    # its route from that lane within ROUTE_CHECK_EVERY steps (the check is
    # staggered over the vehicles), its own track freed.
    from blendtrack import sumo
    from blendtrack.sumo.runner import ROUTE_CHECK_EVERY, SumoRun

    scenario = sumo.resolve_scenario(str(ROOT / "sumo_scenarios" / "highway_onramp"))
    run = SumoRun(scenario, sumo.RunOptions(controlled_fraction=1.0, end_s=150.0, progress=False,
                                            sumo_args=("--no-warnings", "true")), tmp_path / "o")
    overdue: dict[str, int] = {}
    worst = {"steps": 0, "own_tracks": 0, "released": 0}
    owned_before: set[str] = set()

    def watch(r: SumoRun, t: float) -> None:
        owned = set()
        for vid, act in r.vehicles.active.items():
            if act.own_track is None:
                continue
            owned.add(vid)
            lane_id, pos = r.fleet.front_lane_position(act.slot)
            lane = r.tracks.lanes.names[lane_id]
            past = act.changing is None and not lane.startswith(":") and lane.rpartition("_")[0] != act.geo.edges[0]
            if past and pos >= SHARE_AFTER_M:
                overdue[vid] = overdue.get(vid, 0) + 1
                worst["steps"] = max(worst["steps"], overdue[vid])
            else:
                overdue.pop(vid, None)
        worst["own_tracks"] = max(worst["own_tracks"], len(owned))
        worst["released"] += len({v for v in owned_before - owned if v in r.vehicles.active})
        owned_before.clear()
        owned_before.update(owned)

    run.step_hooks.append(watch)
    result = run.run()
    assert result.summary["controlled_vehicles"] > 50 and worst["own_tracks"] > 0, "lane changes on own tracks happened"
    assert worst["released"] > 0, "vehicles went back to shared tracks while still driving"
    # One step for the hook seeing the state before the control step, and the stagger.
    assert worst["steps"] <= ROUTE_CHECK_EVERY + 1


SHARED = Path(os.environ.get("BLENDTRACK_SHARED_DIR") or ROOT.parent / "shared")
BOLOGNA_NET = SHARED / "scenarios_real" / "bologna_acosta" / "acosta_buslanes.net.xml"


@pytest.mark.skipif(not BOLOGNA_NET.exists(), reason="../shared/scenarios_real is not beside the repo")
def test_a_vehicle_on_a_lane_that_fans_out_follows_sumos_choice_of_junction_lane() -> None:
    """Bologna's 43[0]_1 fans out onto :34_0_1 (to 43[1]_1) and :34_0_2 (to
    43[1]_2). A vehicle on it, its front 5 m in or more, whose best lanes
    (SUMO's ``getBestLanes``: what SUMO's movement follows) continue onto
    the other lane than its track's, is put on the track that takes that
    one, from where it is; one whose best lanes agree with the track, or
    whose front is not yet 5 m in, stays."""
    from blendtrack.sumo.tracks import FANOUT_AFTER_M, Active

    network = Network(BOLOGNA_NET)
    fleet = RouteFleet()
    tracks = Tracks(fleet, network, ControllerConfig(), 0.0)
    geo, track = tracks.geometry(("43[0]", "43[1]"), 1)
    ours = geo.fanout_next["43[0]_1"]
    other = "43[1]_2" if ours == "43[1]_1" else "43[1]_1"

    def vehicle_at(front_m: float) -> Active:
        # The front at front_m along the track (43[0]_1 starts it), heading along it.
        i = int(front_m) - 3
        (x0, y0), (x1, y1) = geo.points[i], geo.points[i + 1]
        theta = float(np.arctan2(y1 - y0, x1 - x0))
        slot = fleet.add_vehicle(track, None, None, reach_m=3.0, length_m=4.5, min_gap_m=2.5,
                                 x=float(x0), y=float(y0), theta=theta, v=10.0)
        tracks.enter(track)
        return Active(vid=f"v{slot}", slot=slot, geo=geo, route_id="r", record=None, track=track)  # type: ignore[arg-type]

    def best(next_lane: str) -> list[tuple[object, ...]]:
        return [("43[0]_0", 500.0, 1, 1, True, ("43[0]_0", "43[1]_0")),
                ("43[0]_1", 1200.0, 0, 0, True, ("43[0]_1", next_lane))]

    act = vehicle_at(12.0)
    assert fleet.front_lane_position(act.slot)[1] >= FANOUT_AFTER_M
    assert not tracks.follow_fanout(act, best(ours)) and act.geo is geo
    assert tracks.follow_fanout(act, best(other))
    assert act.geo is not geo and act.geo.fanout_next["43[0]_1"] == other
    assert fleet.vehicle_track(act.slot) == act.track != track
    assert fleet.front_lane_position(act.slot)[1] == pytest.approx(12.0, abs=0.5), "moved nowhere"
    early = vehicle_at(4.0)
    assert fleet.front_lane_position(early.slot)[1] < FANOUT_AFTER_M
    assert not tracks.follow_fanout(early, best(other)) and early.geo is geo
