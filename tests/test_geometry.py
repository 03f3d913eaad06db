"""Polyline geometry in Rust (``blendtrack._blendtrack.polyline_*``) and the
SUMO bridge's use of it (``blendtrack.sumo.geometry``), checked against
NumPy reference implementations written here, closed forms, and sumolib's
own lane positions."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import blendtrack
from blendtrack._blendtrack import (
    polyline_arc_lengths,
    polyline_blend,
    polyline_distance,
    polyline_join,
    polyline_resample,
    polyline_smooth,
)

SCENARIOS = Path(__file__).resolve().parents[1] / "sumo_scenarios"


# NumPy references (the operations the SUMO bridge used before the port).
def ref_arc(shape: np.ndarray) -> np.ndarray:
    return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(shape, axis=0).T))])


def ref_resample(shape: np.ndarray, spacing_m: float) -> np.ndarray:
    s = ref_arc(shape)
    n = max(1, int(np.ceil(s[-1] / spacing_m)))
    t = np.linspace(0.0, s[-1], n + 1)
    return np.column_stack([np.interp(t, s, shape[:, 0]), np.interp(t, s, shape[:, 1])])


def ref_smooth(points: np.ndarray, sigma_pts: float) -> np.ndarray:
    if sigma_pts <= 0 or len(points) < 5:
        return points
    half = int(np.ceil(3 * sigma_pts))
    k = np.exp(-0.5 * (np.arange(-half, half + 1) / sigma_pts) ** 2)
    k /= k.sum()
    padded = np.pad(points, ((half, half), (0, 0)), mode="edge")
    out = np.column_stack([np.convolve(padded[:, i], k, mode="valid") for i in range(2)])
    out[0], out[-1] = points[0], points[-1]
    return out


def ref_distance(p: np.ndarray, q: np.ndarray) -> float:
    """Brute force over a fine sampling of both polylines (an upper bound
    within the sampling step of the true distance)."""

    def sample(v: np.ndarray) -> np.ndarray:
        if len(v) == 1:
            return v
        t = np.linspace(0.0, 1.0, 401)[:, None]
        return np.concatenate([a + t * (b - a) for a, b in zip(v[:-1], v[1:])])

    a, b = sample(p), sample(q)
    return float(np.min(np.hypot(a[:, None, 0] - b[None, :, 0], a[:, None, 1] - b[None, :, 1])))


def random_polyline(rng: np.random.Generator, n: int) -> np.ndarray:
    # Segment lengths from centimetres to tens of metres, as SUMO lane shapes have.
    steps = rng.normal(size=(n - 1, 2)) * rng.choice([0.01, 0.5, 3.0, 40.0], size=(n - 1, 1))
    return np.cumsum(np.vstack([rng.uniform(-500, 500, size=(1, 2)), steps]), axis=0)


@pytest.mark.parametrize("seed", range(20))
def test_arc_lengths_and_resampling_equal_numpy_to_the_bit(seed: int) -> None:
    rng = np.random.default_rng(seed)
    shape = random_polyline(rng, int(rng.integers(2, 40)))
    assert np.array_equal(polyline_arc_lengths(shape), ref_arc(shape))
    spacing = float(rng.choice([0.3, 1.0, 2.5]))
    pts, s, total = polyline_resample(shape, spacing)
    assert np.array_equal(pts, ref_resample(shape, spacing))
    assert np.array_equal(s, ref_arc(pts))
    assert total == ref_arc(shape)[-1]


def test_resampling_a_straight_gives_even_points() -> None:
    pts, s, total = polyline_resample(np.array([[0.0, 0.0], [10.0, 0.0]]), 3.0)
    assert pts.tolist() == [[0.0, 0.0], [2.5, 0.0], [5.0, 0.0], [7.5, 0.0], [10.0, 0.0]]
    assert s.tolist() == [0.0, 2.5, 5.0, 7.5, 10.0] and total == 10.0


@pytest.mark.parametrize("seed", range(10))
def test_smoothing_equals_numpy_to_the_bit(seed: int) -> None:
    # Up to 11 taps (sigma <= 5/3 points; the SUMO bridge uses 1.5): NumPy's
    # convolve sums the products in order then; above, it hands them to BLAS
    # (vectorised, fused multiply-adds) and differs in the last bits.
    rng = np.random.default_rng(100 + seed)
    pts = random_polyline(rng, int(rng.integers(3, 200)))
    for sigma in (0.0, 0.5, 1.0, 1.5):
        assert np.array_equal(polyline_smooth(pts, sigma), ref_smooth(pts, sigma))


def test_smoothing_a_circle_shrinks_it_by_the_closed_form() -> None:
    r, dth = 30.0, 1.0 / 30.0
    th = np.arange(80) * dth
    circle = np.column_stack([r * np.cos(th), r * np.sin(th)])
    sm = polyline_smooth(circle, 1.5)
    j = np.arange(-5, 6)
    k = np.exp(-0.5 * (j / 1.5) ** 2)
    factor = float((k / k.sum() * np.cos(j * dth)).sum())
    assert np.allclose(np.hypot(*sm[6:-6].T), r * factor, atol=1e-9, rtol=0)
    assert r - r * factor == pytest.approx(1.5**2 / (2 * r), rel=0.01)


def test_blend_between_parallel_lines_is_the_smoothstep() -> None:
    a = np.array([[0.0, 0.0], [100.0, 0.0]])
    b = np.array([[0.0, 3.5], [100.0, 3.5]])
    pts, w, s_a, s_b, start, length = polyline_blend(a, b, 1.0, 20.0, 50.0)
    u = np.clip((np.arange(101) - 20.0) / 50.0, 0.0, 1.0)
    assert np.allclose(w, 3 * u**2 - 2 * u**3, atol=1e-15, rtol=0)
    assert np.allclose(pts[:, 1], 3.5 * w, atol=1e-12, rtol=0) and np.allclose(pts[:, 0], np.arange(101.0))
    assert np.array_equal(s_a, np.arange(101.0)) and np.allclose(s_b, np.arange(101.0), atol=1e-12, rtol=0)
    assert (start, length) == (20.0, 50.0)
    # Defaults: over the whole line; a start beyond it is clamped to its end.
    assert polyline_blend(a, b, 10.0)[4:] == (0.0, 100.0)
    assert polyline_blend(a, b, 10.0, 500.0, 0.0)[4:] == (100.0, 1e-6)


def test_segment_distances_closed_forms_and_brute_force() -> None:
    seg = np.array([[0.0, 0.0], [1.0, 0.0]])
    assert polyline_distance(seg, np.array([[2.0, 1.0], [3.0, 1.0]])) == pytest.approx(math.sqrt(2.0), abs=1e-15)
    assert polyline_distance(np.array([[0.0, -1.0], [0.0, 1.0]]), np.array([[-1.0, 0.0], [1.0, 0.0]])) == 0.0
    assert polyline_distance(np.array([[5.0, 4.0]]), np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]])) == 4.0
    assert polyline_distance(np.zeros((0, 2)), seg) == math.inf
    rng = np.random.default_rng(7)
    for _ in range(30):
        p = rng.uniform(0, 20, size=(int(rng.integers(1, 5)), 2))
        q = rng.uniform(0, 20, size=(int(rng.integers(1, 5)), 2))
        d, ref = polyline_distance(p, q), ref_distance(p, q)
        # The sampled reference is an upper bound within its sampling step.
        assert d <= ref + 1e-12 and ref - d < 0.2, (p, q, d, ref)


def test_sumo_segments_distance_and_body_segment() -> None:
    from blendtrack.sumo.geometry import body_segment, segments_distance

    class Veh:
        def getPosition(self, vid: str) -> tuple[float, float]:
            return (10.0, 0.0)

        def getAngle(self, vid: str) -> float:
            return 90.0  # heading east (SUMO: clockwise from north)

        def getLength(self, vid: str) -> float:
            return 5.0

        def getWidth(self, vid: str) -> float:
            return 1.8

    body, half = body_segment(Veh(), "x")
    assert np.allclose(body, [[5.0, 0.0], [10.0, 0.0]], atol=1e-12) and half == 0.9
    assert segments_distance(body, np.array([[13.0, -20.0], [13.0, 20.0]])) == pytest.approx(3.0)
    assert segments_distance(body, np.array([[8.0, -5.0], [8.0, 5.0]])) == 0.0
    assert segments_distance(body, np.zeros((0, 2))) == math.inf
    with pytest.raises(blendtrack.PathError, match="not finite"):
        segments_distance(body, np.array([[0.0, math.nan], [1.0, 1.0]]))


def test_join_of_two_pieces_on_a_straight() -> None:
    a = np.column_stack([np.arange(11.0), np.zeros(11)])
    b = np.column_stack([np.arange(10.0, 21.0), np.zeros(11)])
    out = polyline_join([(a, np.arange(11.0), True, 1.0), (b, np.arange(11.0), True, 0.5)], 1.5, 0.06, 4)
    # The edge padding pulls the points near the ends along the line; inside they stay.
    line = np.column_stack([np.arange(21.0), np.zeros(21)])
    assert np.allclose(out["points"][5:16], line[5:16], atol=1e-12, rtol=0) and np.all(out["points"][:, 1] == 0.0)
    assert out["length_m"] == 20.0 and out["kept"] == [0, 1] and out["kept_points"] == [11, 10]
    assert out["run_piece"] == [0, 1] and np.allclose(out["run_start_s"], [0.0, 10.0], atol=1e-12)
    assert np.allclose(out["run_scale"], [1.0, 0.5], atol=1e-12) and out["run_station"].tolist() == [0.0, 0.0]
    assert out["start_s"] == out["before_s"] and out["entry_s"] == pytest.approx([0.0, 11.0], abs=1e-12)


@pytest.mark.parametrize(
    ("points", "match"),
    [
        (np.zeros((0, 2)), "at least 2 point"),
        (np.array([[1.0, 2.0]]), "at least 2 point"),
        (np.array([[0.0, 0.0], [math.nan, 1.0]]), "point 1 is not finite"),
        (np.array([[0.0, 0.0], [math.inf, 1.0]]), "point 1 is not finite"),
    ],
)
def test_unusable_shapes_are_path_errors(points: np.ndarray, match: str) -> None:
    with pytest.raises(blendtrack.PathError, match=match):
        polyline_resample(points, 1.0)
    with pytest.raises(blendtrack.PathError, match=match):
        polyline_blend(points, np.array([[0.0, 0.0], [1.0, 0.0]]), 1.0)


def test_bad_arguments_are_input_errors() -> None:
    line = np.array([[0.0, 0.0], [1.0, 0.0]])
    with pytest.raises(blendtrack.InputError, match=r"shape \(N, 2\)"):
        polyline_resample(np.zeros((3, 3)), 1.0)
    with pytest.raises(blendtrack.InputError, match="spacing_m"):
        polyline_resample(line, 0.0)
    with pytest.raises(blendtrack.InputError, match="2 values for 1 points|1 values for 2 points"):
        polyline_join([(line, np.zeros(1), True, 1.0)], 1.5, 0.06, 4)
    with pytest.raises(blendtrack.PathError, match="at least 1"):
        polyline_join([], 1.5, 0.06, 4)
    with pytest.raises(blendtrack.PathError, match="not finite"):
        polyline_join([(np.array([[0.0, math.nan]]), np.zeros(1), True, 1.0)], 1.5, 0.06, 4)


def test_route_geometry_maps_track_positions_to_sumo_lane_positions() -> None:
    """Independent check of the pieces' (lane, position) table: on each run
    near its lane's centreline, a track point's lane position (lane_pos +
    (s - start) * scale, SUMO's length units) agrees with sumolib's own
    projection of that point onto the lane (scaled from shape to SUMO
    length) to within centimetres."""
    sumolib = pytest.importorskip("sumolib")
    from blendtrack.sumo.geometry import NEAR_LANE_M, route_geometry

    net = sumolib.net.readNet(str(SCENARIOS / "urban_grid" / "urban_grid.net.xml"), withInternal=True)
    # A route of three edges through two junctions, turning at the second.
    first = net.getEdges(withInternal=False)[0]
    second = next(iter(first.getOutgoing()))
    third = next(e for e in second.getOutgoing() if e.getToNode() is not first.getFromNode())
    edges = (first.getID(), second.getID(), third.getID())
    g = route_geometry(net, edges, 0)
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(g.points, axis=0).T))])
    assert g.length_m == pytest.approx(s[-1], abs=1e-9)
    # The core's Path (sqrt segment lengths, duplicate points dropped) measures
    # the arc lengths the piece table is given in (hypot) to within rounding.
    path = blendtrack.Path(g.points, g.widths, closed=False)
    assert path.length_m == pytest.approx(g.length_m, abs=1e-9)
    assert len(path) == len(s) and np.allclose(path.vertex_s(), s, atol=1e-9, rtol=0)
    assert np.all(np.diff(g.piece_start_s) > 0)
    checked = 0
    for k, lane_id in enumerate(g.piece_lane):
        if g.piece_offset[k] > NEAR_LANE_M:
            continue
        end = g.piece_start_s[k + 1] if k + 1 < len(g.piece_lane) else g.length_m
        lane = net.getLane(lane_id)
        shape_len = float(ref_arc(np.asarray(lane.getShape(), dtype=float))[-1])
        for i in np.flatnonzero((s > g.piece_start_s[k] + 0.5) & (s < end - 0.5)):
            ours = g.piece_lane_pos[k] + (s[i] - g.piece_start_s[k]) * g.piece_scale[k]
            pos, dist = lane.getClosestLanePosAndDist(tuple(g.points[i]))
            assert dist < 0.1
            assert ours == pytest.approx(pos * lane.getLength() / shape_len, abs=0.05), (lane_id, i)
            checked += 1
    assert checked > 50
    assert all(0.0 <= st[0] <= g.length_m for st in g.stops) and g.stops


def test_a_preferred_lane_is_reached_as_a_lane_the_route_needs(tmp_path: Path, build_net: Any) -> None:
    """Three two-lane edges straight on (lane 0 to lane 0, 1 to 1): from
    lane 1 the track stays on lane 1. Asked for lane 0 of the last edge (a
    stop's lane), it gets there as for a lane the route needs: a change on
    an earlier edge (pending, with ``defer_changes``), never on the last
    edge itself. A lane index the edge does not have is no constraint."""
    sumolib = pytest.importorskip("sumolib")
    from blendtrack.sumo.geometry import route_geometry

    path = build_net(tmp_path, '<nodes><node id="A" x="0" y="0"/><node id="B" x="300" y="0"/>'
                               '<node id="C" x="600" y="0"/><node id="D" x="900" y="0"/></nodes>',
                     '<edges><edge id="AB" from="A" to="B" numLanes="2"/><edge id="BC" from="B" to="C" numLanes="2"/>'
                     '<edge id="CD" from="C" to="D" numLanes="2"/></edges>')
    net = sumolib.net.readNet(str(path), withInternal=True)
    edges = ("AB", "BC", "CD")
    plain = route_geometry(net, edges, 1)
    assert [x for x in plain.piece_lane if not x.startswith(":")] == ["AB_1", "BC_1", "CD_1"]
    assert plain.pending_change is None
    stop = route_geometry(net, edges, 1, prefer={2: 0})
    normal = [x for x in stop.piece_lane if not x.startswith(":")]
    assert normal[0] == "AB_1" and normal[-1] == "CD_0" and "CD_1" not in normal, normal
    deferred = route_geometry(net, edges, 1, defer_changes=True, prefer={2: 0})
    assert deferred.pending_change is not None and deferred.pending_change[1] == 0 and deferred.pending_change[0] < 2
    assert route_geometry(net, edges, 1, prefer={2: 5}).piece_lane == plain.piece_lane


def _curvature(points: np.ndarray) -> np.ndarray:
    """Turning angle at each inner point over the mean of its two segments (1/m)."""
    d = np.diff(points, axis=0)
    seg = np.hypot(d[:, 0], d[:, 1])
    turn = np.arctan2(d[:-1, 0] * d[1:, 1] - d[:-1, 1] * d[1:, 0], (d[:-1] * d[1:]).sum(axis=1))
    return turn / (0.5 * (seg[:-1] + seg[1:]))


def test_a_kink_no_car_follows_is_rounded_to_the_turning_radius(tmp_path: Path, build_net: Any) -> None:
    """A lane with a zigzag in it (8 m sideways within 9.4 m, two turns of
    about 122 deg: a mapping slip such as Bologna's 58[0], which overshoots
    its junction and comes back). Smoothed as usual the track still turns on
    a radius well under a metre there; with the rounding, nowhere under
    MIN_TURN_RADIUS_M, and the track stays on the lane elsewhere. Its lane
    positions still rise along the track (a vehicle handed to SUMO is never
    put back)."""
    import sumolib

    from blendtrack.sumo.geometry import MIN_TURN_RADIUS_M, route_geometry

    net_file = build_net(
        tmp_path,
        '<nodes><node id="a" x="0" y="0"/><node id="b" x="200" y="8"/><node id="c" x="300" y="8"/></nodes>',
        '<edges><edge id="ab" from="a" to="b" numLanes="1" shape="0,0 100,0 95,8 200,8"/>'
        '<edge id="bc" from="b" to="c" numLanes="1"/></edges>',
    )
    net = sumolib.net.readNet(str(net_file), withInternal=True)
    plain = route_geometry(net, ["ab", "bc"], 0, min_turn_radius_m=0.0)
    assert np.abs(_curvature(plain.points)).max() > 1.0 and plain.rounded == []
    g = route_geometry(net, ["ab", "bc"], 0)
    k = np.abs(_curvature(g.points))
    assert k.max() <= 1.0 / MIN_TURN_RADIUS_M + 1e-9, k.max()
    assert len(g.rounded) >= 1 and all(kk <= 1.0 / MIN_TURN_RADIUS_M for _, _, kk in g.rounded)
    a, b, _ = g.rounded[0]
    assert 80.0 < a < b < 120.0, g.rounded
    # Away from the zigzag the track is the lane's (within the smoothing's 6 cm).
    lane = np.asarray(net.getLane("ab_0").getShape())
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(g.points, axis=0).T))])
    for p in g.points[(s > 5.0) & (s < 60.0)]:
        assert polyline_distance(np.array([p, p]), lane) < 0.06
    # Lane positions along the track: on each lane, rising with arc length.
    for lane_id in ("ab_0", "bc_0"):
        at = [i for i, name in enumerate(g.piece_lane) if name == lane_id]
        starts = [g.piece_lane_pos[i] for i in at]
        assert starts == sorted(starts), (lane_id, starts)
        assert all(g.piece_scale[i] > 0 for i in at)


def test_sumo_stations_jump_where_the_track_cuts_a_corner(tmp_path: Path, build_net: Any) -> None:
    """A lane with a right-angle bend (100 m east, then 100 m north) and an
    edge after it: the rounded track cuts inside the bend. Each track
    point's station (``RouteGeometry.station``) is checked against sumolib's
    own projection of the point onto the nearest of the route's lanes (the
    lane SUMO's moveToXY puts it on), at that lane's offset along the route
    and in SUMO's length units, made non-decreasing: within 0.1 m. Around
    the bend the station jumps ahead of the arc length by about what the
    track cuts off, and the table is accepted by RouteFleet (one station a
    point of the Path), a wrong length rejected with a clear error."""
    sumolib = pytest.importorskip("sumolib")
    from blendtrack.sumo.geometry import route_geometry

    net_file = build_net(
        tmp_path,
        '<nodes><node id="a" x="0" y="0"/><node id="b" x="100" y="100"/><node id="c" x="100" y="200"/></nodes>',
        '<edges><edge id="ab" from="a" to="b" numLanes="1" shape="0,0 100,0 100,100"/>'
        '<edge id="bc" from="b" to="c" numLanes="1"/></edges>',
    )
    net = sumolib.net.readNet(str(net_file), withInternal=True)
    g = route_geometry(net, ["ab", "bc"], 0)
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(g.points, axis=0).T))])
    assert len(g.station) == len(g.points) and np.all(np.diff(g.station) >= 0.0)
    # The route's lanes in order with their offsets (SUMO lengths).
    lanes, offset = [], 0.0
    for lane_id in dict.fromkeys(g.piece_lane):
        lane = net.getLane(lane_id)
        lanes.append((lane, offset))
        offset += lane.getLength()
    brute = []
    for p in g.points:
        best = min(
            (lane.getClosestLanePosAndDist(tuple(p)) + (lane, off) for lane, off in lanes),
            key=lambda r: r[1],
        )
        pos, _, lane, off = best
        shape_len = float(ref_arc(np.asarray(lane.getShape(), dtype=float))[-1])
        brute.append(off + pos * lane.getLength() / shape_len)
    brute = np.maximum.accumulate(np.array(brute))
    assert np.abs(g.station - brute).max() < 0.1, np.abs(g.station - brute).max()
    # Before the bend the station is the arc length; past it, the arc length
    # plus what the track cuts off; in between a jump of over a metre.
    lead = g.station - s
    assert abs(lead[s < 60.0]).max() < 0.05
    cut = offset - g.length_m
    assert cut > 1.0 and lead[-1] == pytest.approx(cut, abs=0.1)
    assert np.diff(lead).max() > 1.0
    fleet = blendtrack.RouteFleet()
    path = blendtrack.Path(g.points, g.widths, closed=False)
    kw = dict(
        piece_start_m=g.piece_start_s, piece_scale=g.piece_scale, piece_offset_m=g.piece_offset,
        piece_lane_length_m=g.piece_lane_length, piece_speed_mps=g.piece_speed, piece_lane=list(range(len(g.piece_lane))),
        piece_edge=list(range(len(g.piece_lane))), piece_lane_index=g.piece_index, length_m=g.length_m,
        piece_lane_pos_m=g.piece_lane_pos,
    )
    assert fleet.add_route(path, None, station_m=g.station, **kw) >= 0
    with pytest.raises(blendtrack.InputError, match=r"route: \d+ stations for \d+ track points"):
        fleet.add_route(path, None, station_m=g.station[:-1], **kw)
