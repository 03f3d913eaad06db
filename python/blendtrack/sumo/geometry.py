"""Reference tracks from SUMO lane geometry.

A controlled vehicle follows the centreline of its lane along its route:
the normal lanes of the route's edges joined by the internal junction lanes
(``:``-prefixed, the connections' *via* lanes) between them. This module
turns a route (a list of edge ids) into that polyline, with per-point lane
widths for the virtual borders, and keeps a table from arc length to the
SUMO lane under it so that ``moveToXY`` can be given the edge and lane as
hints (SPEC §7: cheap calls when the hints are right).

Lane choice: starting from the vehicle's lane on the first edge, each next
lane is the one reached by a connection from the current lane to the next
edge (preferring one from which the rest of the route needs no lane change,
then one that continues to the edge after, then the straightest). When the
current lane has no connection to the next edge (a lane drop, a turn taken
from the wrong lane), the track changes lane along that edge: it moves
smoothly (smoothstep) from the current lane's centreline to the nearest lane
that continues, either over the whole edge or, for the SUMO runner, only
once SUMO's lane-change model says the target lane has room (the track then
stops at the lane's end until a rebuild with the change in it).

The shapes are resampled every ``spacing_m`` metres (SUMO shapes have long
straight pieces and short kinks at lane joints); the core's path smooths the
tangent heading between vertices, so curvature is continuous enough for the
controllers.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from blendtrack import PathError

#: Track points within this distance (m) of their lane's centreline count as
#: near it (on a curve of radius R the smoothing alone moves the track about
#: ``smoothing_m**2 / (2 R)`` inward: 4 cm at R = 30 m); stretches of a piece
#: near and away from it (kinks at lane joints) become pieces of their own,
#: at least this many points long.
NEAR_LANE_M = 0.06
MIN_RUN_PTS = 4


@dataclass
class RouteGeometry:
    """Centreline of a vehicle's lane chain along its route."""

    #: (N, 2) points, world frame (SUMO network coordinates), metres.
    points: np.ndarray
    #: (N, 2) right and left widths of the lane at each point (half widths).
    widths: np.ndarray
    #: Arc length at which each lane piece starts, increasing.
    piece_start_s: np.ndarray
    #: SUMO lane id of each piece (internal lanes start with ':').
    piece_lane: list[str]
    #: Edge id of each piece, and the lane index within it.
    piece_edge: list[str]
    piece_index: list[int]
    #: Speed limit of each piece (m/s).
    piece_speed: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: SUMO's lane position where the piece starts (0 unless the piece
    #: starts inside its lane, after a lane change), and SUMO's lane position
    #: per metre of track over the piece: a position on the track maps to
    #: ``lane_pos + (s - start) * scale`` on the piece's lane.
    piece_lane_pos: np.ndarray = field(default_factory=lambda: np.zeros(0))
    piece_scale: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: SUMO's length of each piece's lane (m).
    piece_lane_length: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: Largest distance (m) between the track and the piece's SUMO lane
    #: centreline (the smoothing rounds the kinks where lanes meet); +inf
    #: where the track crosses between lanes (a lane change). Near the
    #: centreline a vehicle can be handed to SUMO as (lane, position).
    piece_offset: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: Junction entries along the track, sorted by arc length: (arc length of
    #: the stop line, traffic light id or "" when unsignalised, link index,
    #: True when the link has priority by the network (state "M"), the first
    #: junction lane's id, arc length where the junction is left). An entry
    #: with link index -1 is an internal junction: the waiting point inside
    #: the junction of a turn across oncoming lanes (its lane is the junction
    #: lane after that point).
    stops: list[tuple[float, str, int, bool, str, float]] = field(default_factory=list)
    #: Route edges this geometry was built for.
    edges: tuple[str, ...] = field(default_factory=tuple)
    #: (edge index in ``edges``, target lane index) when the track stops at
    #: the end of a lane that does not continue and a lane change is due.
    pending_change: tuple[int, int] | None = None
    #: Total arc length (m).
    length_m: float = 0.0


def _arc(shape: np.ndarray) -> np.ndarray:
    """Cumulative arc length at each point of a polyline."""
    return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(shape, axis=0).T))])


def _resample(shape: np.ndarray, spacing_m: float) -> np.ndarray:
    """Points evenly spaced along ``shape``, at most ``spacing_m`` apart, from
    its first point to its last (even spacing keeps the smoothing, which
    counts in points, the same everywhere along the track)."""
    s = _arc(shape)
    n = max(1, int(np.ceil(s[-1] / spacing_m)))
    t = np.linspace(0.0, s[-1], n + 1)
    return np.column_stack([np.interp(t, s, shape[:, 0]), np.interp(t, s, shape[:, 1])])


def _best_connection(conns: list[Any]) -> Any:
    # Prefer going straight, then the gentlest turn; SUMO direction codes.
    rank = {"s": 0, "r": 1, "l": 1, "R": 2, "L": 2, "t": 3}
    return min(conns, key=lambda c: rank.get(c.getDirection(), 4))


def _via_chain(net: Any, conn: Any) -> list[Any]:
    """The internal lanes a connection passes through, in order."""
    lanes = []
    via = conn.getViaLaneID()
    seen = set()
    while via and via not in seen:
        seen.add(via)
        lane = net.getLane(via)
        lanes.append(lane)
        nxt = [c for c in lane.getOutgoing() if c.getViaLaneID()]
        via = nxt[0].getViaLaneID() if nxt else ""
    return lanes


def _smoothstep(u: np.ndarray) -> np.ndarray:
    u = np.clip(u, 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


@dataclass
class _Piece:
    shape: np.ndarray
    half_width_m: float
    edge: str
    index: int
    lane: str
    speed_mps: float
    #: SUMO's length of the lane.
    length_m: float
    #: Arc length along the SUMO lane's own shape at each point of ``shape``
    #: (where the points lie on it) or of the point abreast of it.
    lane_s: np.ndarray
    #: Geometric length of the SUMO lane's shape (SUMO's lane position is
    #: ``lane_s * length_m / shape_length_m``).
    shape_length_m: float
    #: False where the points leave the lane's centreline (the middle of a lane change).
    on_lane: bool = True
    #: (traffic light id or "", link index, major) when this piece enters a junction.
    tls: tuple[str, int, bool] | None = None
    #: Per point (right, left) distances (m) to the virtual borders, where
    #: they are not the lane's half width (the middle of a lane change).
    widths: np.ndarray | None = None


def _lane_piece(
    lane: Any, spacing_m: float, shape: np.ndarray | None = None, lane_s: np.ndarray | None = None, on_lane: bool = True
) -> _Piece:
    """A piece on ``lane``: its whole resampled centreline (``shape`` None),
    or the given points with their arc lengths along the lane's shape."""
    raw = np.asarray(lane.getShape(), dtype=float)
    if shape is None or lane_s is None:
        shape = _resample(raw, spacing_m)
        lane_s = _arc(shape)
    return _Piece(
        shape,
        0.5 * float(lane.getWidth()),
        lane.getEdge().getID(),
        lane.getIndex(),
        lane.getID(),
        float(lane.getSpeed()),
        float(lane.getLength()),
        lane_s,
        max(float(_arc(raw)[-1]), 1e-9),
        on_lane,
    )


#: After a lane change the virtual borders come back from the carriageway's
#: edges to the lane's over this many times the change's length, at least
#: LANE_CHANGE_TAPER_MIN_M metres.
LANE_CHANGE_TAPER_FACTOR = 3.0
LANE_CHANGE_TAPER_MIN_M = 100.0


def _carriageway_widths(a: Any, b: Any, w: np.ndarray) -> np.ndarray:
    """(right, left) distances from the points of a lane change (``w`` of
    the way from lane ``a``'s centreline to lane ``b``'s, two lanes of one
    edge) to the edges of the whole carriageway, all the edge's lanes side
    by side (SUMO's lane index 0 on the right). During a change the vehicle
    may use the road, not only one lane: with a lane's half width the path's
    S-bend and the vehicle's angle across its lane would put the virtual
    border 15-25 m ahead, and the curvature-aware law would brake every
    changing vehicle hard (from 20 m/s to under 10)."""
    lanes = sorted(a.getEdge().getLanes(), key=lambda ln: ln.getIndex())
    widths = [float(ln.getWidth()) for ln in lanes]
    right_edge = np.cumsum([0.0, *widths])

    def centre(lane: Any) -> float:
        i = lane.getIndex()
        return float(right_edge[i] + 0.5 * widths[i])

    offset = centre(a) + w * (centre(b) - centre(a))
    return np.column_stack([offset, right_edge[-1] - offset])


def _lane_change_pieces(
    a: Any, b: Any, spacing_m: float, start_m: float | None = None, length_m: float | None = None
) -> list[_Piece]:
    """Points that move smoothly (smoothstep) from lane ``a``'s centreline to
    lane ``b``'s (two lanes of one edge), between ``start_m`` and
    ``start_m + length_m`` along ``a`` (default: over the whole edge), as up
    to three pieces: on ``a`` before the change, the change itself (off both
    centrelines; on ``b`` for SUMO), on ``b`` after it."""
    sa = _resample(np.asarray(a.getShape(), dtype=float), spacing_m)
    sb = np.asarray(b.getShape(), dtype=float)
    # Sample b at the same relative arc length as each point of a.
    da, db = _arc(sa), _arc(sb)
    total = max(da[-1], 1e-9)
    tb = da / total * db[-1]
    pb = np.column_stack([np.interp(tb, db, sb[:, 0]), np.interp(tb, db, sb[:, 1])])
    start = 0.0 if start_m is None else min(max(start_m, 0.0), total)
    length = (total - start) if length_m is None else max(length_m, 1e-6)
    w = _smoothstep((da - start) / length)
    pts = (1.0 - w[:, None]) * sa + w[:, None] * pb
    before, after = w <= 0.0, w >= 1.0
    middle = ~(before | after)
    out = []
    if before.any():
        out.append(_lane_piece(a, spacing_m, pts[before], da[before]))
    if middle.any():
        piece = _lane_piece(b, spacing_m, pts[middle], tb[middle], on_lane=False)
        piece.widths = _carriageway_widths(a, b, w[middle])
        out.append(piece)
    if after.any():
        piece = _lane_piece(b, spacing_m, pts[after], tb[after])
        if middle.any():
            # Back from the carriageway to the lane's half width over a
            # taper: a step at the change's end would cross the lane the
            # vehicle leaves, a wall straight ahead of it until it turns.
            edges = _carriageway_widths(a, b, np.ones(int(after.sum())))
            taper = max(LANE_CHANGE_TAPER_FACTOR * length, LANE_CHANGE_TAPER_MIN_M)
            u = np.clip((da[after] - (start + length)) / taper, 0.0, 1.0)[:, None]
            piece.widths = (1.0 - u) * edges + u * piece.half_width_m
        out.append(piece)
    return out


def _pieces(
    net: Any,
    edges: Sequence[str],
    start_index: int,
    spacing_m: float,
    defer_changes: bool = False,
    change: tuple[float, float] | tuple[float, float, int] | None = None,
) -> tuple[list[_Piece], tuple[int, int] | None]:
    """Lane pieces along the route: normal lanes, junction lanes, and lane
    changes within an edge where the current lane does not continue.

    A needed lane change on the first edge follows ``change`` = (start, length
    in m along the lane) when given. Otherwise, with ``defer_changes`` the
    pieces stop at the end of the lane that does not continue and the second
    value says where the change is due: (edge index, target lane index); the
    caller rebuilds once the change can be made. Without it the change spans
    the whole edge. ``change`` = (start, length, target lane index) is a
    change the route does not need (to overtake, to keep right): onto that
    lane of the first edge, which must go on along the route.
    """
    objs = []
    for eid in edges:
        try:
            objs.append(net.getEdge(eid))
        except KeyError:
            raise PathError(f"route edge {eid!r} is not in the network") from None

    def conns_to(lane: Any, k: int) -> list[Any]:
        if k >= len(objs):
            return []
        return [c for c in lane.getOutgoing() if c.getTo() is objs[k]]

    # Lanes from which the rest of the route needs no lane change (backwards).
    no_change: list[set[str]] = [set() for _ in objs]
    no_change[-1] = {ln.getID() for ln in objs[-1].getLanes()}
    for k in range(len(objs) - 2, -1, -1):
        for ln in objs[k].getLanes():
            if any(c.getToLane().getID() in no_change[k + 1] for c in conns_to(ln, k + 1)):
                no_change[k].add(ln.getID())

    def piece(lane: Any) -> _Piece:
        return _lane_piece(lane, spacing_m)

    out: list[_Piece] = []
    lane = objs[0].getLane(min(max(start_index, 0), objs[0].getLaneNumber() - 1))
    # A change the route does not need: the pieces of the first edge are the change's.
    chosen = change is not None and len(change) == 3
    if chosen:
        assert change is not None and len(change) == 3
        target_index = change[2]
        if not 0 <= target_index < objs[0].getLaneNumber() or target_index == lane.getIndex():
            raise PathError(f"edge {edges[0]!r} has no lane {target_index} to change to from lane {lane.getIndex()}")
        goal = objs[0].getLane(target_index)
        if len(objs) > 1 and not conns_to(goal, 1):
            raise PathError(f"lane {goal.getID()!r} does not go on to edge {edges[1]!r}")
        out.extend(_lane_change_pieces(lane, goal, spacing_m, change[0], change[1]))
        lane = goal
    for k in range(len(objs)):
        first_done = chosen and k == 0
        if k + 1 == len(objs):
            if not first_done:
                out.append(piece(lane))
            break
        cs = conns_to(lane, k + 1)
        if first_done:
            pass
        elif not cs:
            # Change to the nearest lane of this edge that continues.
            able = [ln for ln in objs[k].getLanes() if conns_to(ln, k + 1)]
            if not able:
                raise PathError(
                    f"no lane of edge {edges[k]!r} connects to edge {edges[k + 1]!r}: the route is not drivable"
                )
            best = [ln for ln in able if ln.getID() in no_change[k]] or able
            target = min(best, key=lambda ln: abs(ln.getIndex() - lane.getIndex()))
            if k == 0 and change is not None:
                out.extend(_lane_change_pieces(lane, target, spacing_m, change[0], change[1]))
            elif defer_changes:
                out.append(piece(lane))
                return out, (k, target.getIndex())
            else:
                out.extend(_lane_change_pieces(lane, target, spacing_m))
            lane = target
            cs = conns_to(lane, k + 1)
        else:
            out.append(piece(lane))
        # Prefer a connection needing no later lane change, then one whose lane
        # goes on to the edge after next.
        onward = (
            [c for c in cs if c.getToLane().getID() in no_change[k + 1]]
            or [c for c in cs if conns_to(c.getToLane(), k + 2)]
            or cs
        )
        c = _best_connection(onward)
        vias = [piece(v) for v in _via_chain(net, c)]
        if vias:
            vias[0].tls = (c.getTLSID() or "", int(c.getTLLinkIndex()), c.getState() == "M")
        for v in vias[1:]:
            # An internal junction (a left turn crossing the oncoming lanes):
            # SUMO's drivers wait there for oncoming traffic, and so do ours.
            v.tls = ("", -1, False)
        out.extend(vias)
        lane = c.getToLane()
    return out, None


def _runs(far: np.ndarray, min_len: int) -> list[tuple[int, int]]:
    """[a, b) ranges of equal ``far``, covering it in order, after a stretch
    of near points shorter than ``min_len`` is counted as far (a piece only
    gets cheap moves where it is near for a while)."""
    far = far.copy()
    cuts = [0, *(np.flatnonzero(far[1:] != far[:-1]) + 1).tolist(), len(far)]
    for a, b in zip(cuts[:-1], cuts[1:]):
        if not far[a] and b - a < min_len:
            far[a:b] = True
    cuts = [0, *(np.flatnonzero(far[1:] != far[:-1]) + 1).tolist(), len(far)]
    return list(zip(cuts[:-1], cuts[1:]))


def _smooth(points: np.ndarray, sigma_pts: float) -> np.ndarray:
    """Gaussian smoothing along the polyline (ends held in place)."""
    if sigma_pts <= 0 or len(points) < 5:
        return points
    half = int(np.ceil(3 * sigma_pts))
    k = np.exp(-0.5 * (np.arange(-half, half + 1) / sigma_pts) ** 2)
    k /= k.sum()
    padded = np.pad(points, ((half, half), (0, 0)), mode="edge")
    out = np.column_stack([np.convolve(padded[:, i], k, mode="valid") for i in range(2)])
    out[0], out[-1] = points[0], points[-1]
    return out


def route_geometry(
    net: Any,
    edges: Sequence[str],
    start_lane_index: int = 0,
    spacing_m: float = 1.0,
    smoothing_m: float = 1.5,
    defer_changes: bool = False,
    change: tuple[float, float] | tuple[float, float, int] | None = None,
    border_margin_m: float = 0.0,
) -> RouteGeometry:
    """Builds the reference track of a vehicle on ``edges`` starting in lane ``start_lane_index``.

    ``net`` is a ``sumolib`` network read with ``withInternal=True``. The
    centreline is smoothed with a Gaussian of ``smoothing_m`` metres (standard
    deviation) to round the kinks where SUMO's lane shapes meet (up to 28 deg
    at the junctions of the urban grid); on a curve of radius R this moves
    the path inward by about ``smoothing_m**2 / (2 R)`` (4 cm at R = 30 m).
    ``defer_changes`` and ``change`` control lane changes (see ``_pieces``):
    with ``defer_changes`` the track may stop at the end of a lane that does
    not continue, and ``pending_change`` says where and to which lane. The
    widths (the virtual borders) are each lane's half width plus
    ``border_margin_m``.
    Raises :class:`blendtrack.PathError` for an empty or undrivable route.
    """
    if len(edges) == 0:
        raise PathError("the route has no edges")
    pts: list[np.ndarray] = []
    wid: list[np.ndarray] = []
    starts: list[float] = []
    kept: list[_Piece] = []
    #: Per kept piece: the range of its points in the concatenated track
    #: (from the point it shares with the piece before, where its lane
    #: starts, if any), and their arc lengths along the lane's shape.
    first: list[int] = []
    end: list[int] = []
    lane_s: list[np.ndarray] = []
    stops: list[tuple[float, str, int, bool, str, float]] = []
    s = 0.0
    n_pts = 0
    last: np.ndarray | None = None
    pieces, pending = _pieces(net, edges, start_lane_index, spacing_m, defer_changes, change)
    for pc in pieces:
        shape, ls = pc.shape, pc.lane_s
        shared = last is not None and np.hypot(*(shape[0] - last)) < 1e-6
        if shared:
            shape = shape[1:]
        if len(shape) == 0:
            continue
        # The stop line is where the incoming lane ends, before any gap to
        # the junction lane's first point (about 1 m in the urban grid).
        end_of_previous = s
        if shared:
            # The lane starts at the point it shares with the piece before.
            starts.append(s)
            first.append(n_pts - 1)
        if last is not None:
            s += float(np.hypot(*(shape[0] - last)))
        if not shared:
            starts.append(s)
            first.append(n_pts)
        lane_s.append(ls)
        kept.append(pc)
        if pc.tls is not None:
            stops.append((end_of_previous, pc.tls[0], pc.tls[1], pc.tls[2], pc.lane, math.inf))
        if not pc.lane.startswith(":"):
            # The junction is left here: the exit of its entry and of its
            # internal junction, if any.
            for j in range(len(stops) - 1, -1, -1):
                if not math.isinf(stops[j][5]):
                    break
                stops[j] = (*stops[j][:5], s)
        s += float(_arc(shape)[-1])
        pts.append(shape)
        if pc.widths is not None:
            wid.append(pc.widths[len(pc.widths) - len(shape):] + border_margin_m)
        else:
            wid.append(np.full((len(shape), 2), pc.half_width_m + border_margin_m))
        n_pts += len(shape)
        end.append(n_pts)
        last = shape[-1]
    raw = np.concatenate(pts)
    points = _smooth(raw, smoothing_m / spacing_m)
    # Arc lengths on the smoothed track (the path the controllers follow):
    # every arc length above is mapped through the points.
    s_raw, s_sm = _arc(raw), _arc(points)

    def smoothed(x: float) -> float:
        return float(np.interp(x, s_raw, s_sm))

    starts = [smoothed(x) for x in starts]

    # Each piece is cut where the track comes near its lane's centreline or
    # leaves it (the smoothing rounds the kinks at lane joints over a few
    # metres): the runs near it can be handed to SUMO as (lane, position).
    out: dict[str, list[Any]] = {k: [] for k in ("start", "k", "lane_pos", "scale", "offset")}
    for k, pc in enumerate(kept):
        i0, i1 = first[k], end[k]
        # The smoothed point's offset from the raw one (which lies on the
        # lane), across and along the lane's local direction.
        r = raw[i0:i1]
        tangent = np.gradient(r, axis=0) if len(r) > 1 else np.array([[1.0, 0.0]])
        tangent /= np.maximum(np.hypot(*tangent.T), 1e-12)[:, None]
        shift = points[i0:i1] - r
        across = tangent[:, 0] * shift[:, 1] - tangent[:, 1] * shift[:, 0]
        along = (tangent * shift).sum(axis=1)
        pos = (lane_s[k] + along) * (pc.length_m / pc.shape_length_m)
        dev = np.abs(across) if pc.on_lane else np.full(i1 - i0, math.inf)
        for a, b in _runs(dev > NEAR_LANE_M, MIN_RUN_PTS):
            # The run's points, and the one after it (the track between them is the run's too).
            c = min(b + 1, i1 - i0)
            ds = s_sm[i0 + c - 1] - s_sm[i0 + a]
            rise = pos[c - 1] - pos[a]
            scale = float(rise / ds) if ds > 1e-9 and rise > 0 else pc.length_m / pc.shape_length_m
            start, lane_pos = (starts[k] if a == 0 else float(s_sm[i0 + a])), float(pos[a])
            if a == 0 and lane_s[k][0] == 0.0:
                # Where the lane starts, along the track (the smoothing shifts
                # the points along a little): lane position 0 there, so a
                # vehicle SUMO carries over the lane's start lands in place.
                start, lane_pos = start - lane_pos / scale, 0.0
                if out["start"]:
                    start = max(start, out["start"][-1] + 1e-6)
            out["start"].append(start)
            out["k"].append(k)
            out["lane_pos"].append(lane_pos)
            out["scale"].append(scale)
            out["offset"].append(float(dev[a:b].max()))
    pieces_of = [kept[k] for k in out["k"]]
    return RouteGeometry(
        points=points,
        widths=np.concatenate(wid),
        piece_start_s=np.array(out["start"]),
        piece_lane=[p.lane for p in pieces_of],
        piece_edge=[p.edge for p in pieces_of],
        piece_index=[p.index for p in pieces_of],
        piece_speed=np.array([p.speed_mps for p in pieces_of]),
        piece_lane_pos=np.array(out["lane_pos"]),
        piece_scale=np.array(out["scale"]),
        piece_lane_length=np.array([p.length_m for p in pieces_of]),
        piece_offset=np.array(out["offset"]),
        length_m=float(s_sm[-1]),
        pending_change=pending,
        stops=[(smoothed(st[0]), st[1], st[2], st[3], st[4], smoothed(st[5]) if math.isfinite(st[5]) else st[5]) for st in stops],
        edges=tuple(edges),
    )


def body_segment(veh: Any, vid: str) -> tuple[np.ndarray, float]:
    """A vehicle's body as SUMO has it: its centreline from the back to the
    front point (2 x 2) and its half width (from SUMO's front point, angle,
    length and width)."""
    x, y = veh.getPosition(vid)
    a = math.radians(float(veh.getAngle(vid)))
    length = float(veh.getLength(vid))
    ux, uy = math.sin(a), math.cos(a)  # SUMO's angle: clockwise from north
    return np.array([[x - length * ux, y - length * uy], [x, y]]), 0.5 * float(veh.getWidth(vid))


def segments_distance(p: np.ndarray, q: np.ndarray) -> float:
    """Smallest distance between the polylines ``p`` and ``q`` (n x 2 each):
    zero where two segments cross, else the smallest of the end point to
    segment distances."""
    if len(p) == 0 or len(q) == 0:
        return math.inf
    if len(p) == 1:
        p = np.vstack([p, p])
    if len(q) == 1:
        q = np.vstack([q, q])
    a, b = p[:-1][:, None, :], p[1:][:, None, :]
    c, d = q[:-1][None, :, :], q[1:][None, :, :]

    def cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]

    d1, d2 = cross(b - a, c - a), cross(b - a, d - a)
    d3, d4 = cross(d - c, a - c), cross(d - c, b - c)
    if np.any((d1 * d2 < 0) & (d3 * d4 < 0)):
        return 0.0

    def point_seg(pt: np.ndarray, s0: np.ndarray, s1: np.ndarray) -> np.ndarray:
        e = s1 - s0
        den = np.maximum(np.sum(e * e, axis=-1), 1e-12)
        t = np.clip(np.sum((pt - s0) * e, axis=-1) / den, 0.0, 1.0)
        return np.hypot(*np.moveaxis(s0 + t[..., None] * e - pt, -1, 0))

    return float(min(point_seg(a, c, d).min(), point_seg(b, c, d).min(), point_seg(c, a, b).min(), point_seg(d, a, b).min()))
