"""The registries a long run keeps bounded (issue 22): RouteFleet hands a
removed track's id out again, and the SUMO bridge keeps the shared tracks
driven plus at most IDLE_TRACKS others."""

from __future__ import annotations

from pathlib import Path

import numpy as np

import blendtrack
from blendtrack import ControllerConfig, RouteFleet
from blendtrack.sumo.network import Network
from blendtrack.sumo.tracks import IDLE_TRACKS, Tracks

GRID_NET = Path(__file__).resolve().parents[1] / "sumo_scenarios" / "urban_grid" / "urban_grid.net.xml"


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
    assert ((edges[1],), 0) not in tracks.geo_cache
    tracks.geometry((edges[1],), 0)
    assert fleet.track_capacity <= IDLE_TRACKS + 2
    slot = fleet.add_vehicle(driven, None, None, reach_m=3.5, length_m=4.5, min_gap_m=2.5, x=float(x), y=float(y),
                             theta=0.0, v=5.0)
    fleet.remove_vehicle(slot)
    # Once left, the driven track is one idle track among the others: the bound holds.
    tracks.leave(driven)
    assert len(tracks.geo_cache) == fleet.n_tracks == IDLE_TRACKS
    assert fleet.track_capacity <= IDLE_TRACKS + 2
