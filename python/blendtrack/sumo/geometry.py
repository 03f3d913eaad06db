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

The geometry itself (resampling, arc lengths, the smoothstep blend of a lane
change, the Gaussian smoothing, the pieces' runs near their lanes, segment
distances) is the Rust core's ``blendtrack::polyline``, one call per piece or
per route; this module keeps what is SUMO's: lane choice, lane shapes and
positions, junctions, carriageway widths and SUMO's angle.
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from blendtrack import PathError
from blendtrack._blendtrack import (
    polyline_arc_lengths,
    polyline_blend,
    polyline_distance,
    polyline_join,
    polyline_resample,
)

#: Track points within this distance (m) of their lane's centreline count as
#: near it (on a curve of radius R the smoothing alone moves the track about
#: ``smoothing_m**2 / (2 R)`` inward: 4 cm at R = 30 m); stretches of a piece
#: near and away from it (kinks at lane joints) become pieces of their own,
#: at least this many points long.
NEAR_LANE_M = 0.06
MIN_RUN_PTS = 4

#: Turns of the smoothed track sharper than this radius (m) are rounded off
#: (``blendtrack::polyline::turns``): kinks of the map that no car follows,
#: such as a lane that overshoots its junction and comes back. A car of the
#: default wheelbase (2.6 m) and steering limit (40 deg) turns its front axle
#: on a circle of about 4 m at full lock.
MIN_TURN_RADIUS_M = 4.0


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
    #: Index into ``edges`` of each piece's edge (a junction lane: of the
    #: edge before it), as SUMO's route index counts: a route that drives an
    #: edge twice has two occurrences of its pieces, told apart by this.
    piece_occurrence: list[int] = field(default_factory=list)
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
    #: Turns rounded off (``MIN_TURN_RADIUS_M``): where each sharp stretch
    #: starts and ends (arc length, m) and the peak |curvature| (1/m) left
    #: in it, above 1 / radius where no rounding tried got under it.
    rounded: list[tuple[float, float, float]] = field(default_factory=list)
    #: (edge index in ``edges``, target lane index) when a lane change is
    #: due: the track stops at the end of a lane that does not continue.
    pending_change: tuple[int, int] | None = None
    #: The pending change is due early (``EARLY_CHANGE_ROOM_M``): the track
    #: goes on along the lane past its edge, to where the lane ends for the
    #: route, and a vehicle that could not change on that edge gets a new
    #: track on the next (``Tracks.retry_early_change``).
    pending_early: bool = False
    #: Per lane of the track that fans out (``Network.fanouts``): the
    #: track's next normal lane after it (``Tracks.geometry`` fills it).
    fanout_next: dict[str, str] = field(default_factory=dict)
    #: Total arc length (m).
    length_m: float = 0.0
    #: SUMO's station at each point: the lane position SUMO gives a vehicle
    #: whose front is there (``moveToXY`` maps it onto the nearest lane),
    #: counted on from lane to lane along the route, non-decreasing. Where
    #: the track cuts inside a sharp turn it jumps ahead of the arc length
    #: (``blendtrack::polyline::chain``); ``RouteFleet`` uses it to keep the
    #: gaps SUMO will measure. Empty: none (a station is the arc length).
    station: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: What other modules derive from this geometry and the network alone,
    #: kept once found (``Junctions.leader_at_merge``: the merge ahead of
    #: each lane).
    memo: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)


def _shape(lane: Any) -> np.ndarray:
    """A lane's centreline as SUMO has it, (N, 2)."""
    return np.asarray(lane.getShape(), dtype=float)


def _best_connection(conns: list[Any]) -> Any:
    # Prefer going straight, then the gentlest turn; SUMO direction codes.
    rank = {"s": 0, "r": 1, "l": 1, "R": 2, "L": 2, "t": 3}
    return min(conns, key=lambda c: rank.get(c.getDirection(), 4))


#: Per network read: a connection's via lane -> ``_via_chain``'s lanes.
#: The junction checks walk the same chains over and over (46,504 walks
#: in 120 s of the 7 x 7 grid with every vehicle controlled).
_VIA_CHAINS: weakref.WeakKeyDictionary[Any, dict[str, tuple[Any, ...]]] = weakref.WeakKeyDictionary()


def _via_chain(net: Any, conn: Any) -> tuple[Any, ...]:
    """The internal lanes a connection passes through, in order (kept per
    network: the network is read once and not changed)."""
    via = conn.getViaLaneID()
    try:
        memo = _VIA_CHAINS[net]
    except KeyError:
        memo = _VIA_CHAINS[net] = {}
    except TypeError:
        # A network object that cannot be weakly referenced: not kept.
        return _walk_via_chain(net, via)
    hit = memo.get(via)
    if hit is None:
        hit = memo[via] = _walk_via_chain(net, via)
    return hit


def _walk_via_chain(net: Any, via: str) -> tuple[Any, ...]:
    lanes = []
    seen = set()
    while via and via not in seen:
        seen.add(via)
        lane = net.getLane(via)
        lanes.append(lane)
        nxt = [c for c in lane.getOutgoing() if c.getViaLaneID()]
        via = nxt[0].getViaLaneID() if nxt else ""
    return tuple(lanes)


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
    #: Index into the route's edges of the piece's edge (of the edge before
    #: it for a junction lane): which time the route drives that edge.
    occurrence: int = 0


def _lane_piece(
    lane: Any, spacing_m: float, shape: np.ndarray | None = None, lane_s: np.ndarray | None = None, on_lane: bool = True
) -> _Piece:
    """A piece on ``lane``: its whole centreline resampled every
    ``spacing_m`` (``shape`` None; even spacing keeps the smoothing, which
    counts in points, the same everywhere along the track), or the given
    points with their arc lengths along the lane's shape."""
    raw = _shape(lane)
    if shape is None or lane_s is None:
        shape, lane_s, raw_length = polyline_resample(raw, spacing_m)
    else:
        raw_length = float(polyline_arc_lengths(raw)[-1])
    return _Piece(
        shape,
        0.5 * float(lane.getWidth()),
        lane.getEdge().getID(),
        lane.getIndex(),
        lane.getID(),
        float(lane.getSpeed()),
        float(lane.getLength()),
        lane_s,
        max(raw_length, 1e-9),
        on_lane,
    )


#: After a lane change the virtual borders come back from the carriageway's
#: edges to the lane's over this many times the change's length, at least
#: LANE_CHANGE_TAPER_MIN_M metres.
LANE_CHANGE_TAPER_FACTOR = 3.0
LANE_CHANGE_TAPER_MIN_M = 100.0
#: A change the route needs is made on an edge already when the lane would
#: otherwise end within this many metres per lane to cross past it (a
#: change takes up to 60 m, plus room to wait for a gap).
EARLY_CHANGE_ROOM_M = 150.0


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
    # a resampled, each point blended with b's at the same relative arc length.
    pts, w, da, tb, start, length = polyline_blend(_shape(a), _shape(b), spacing_m, start_m, length_m)
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
    prefer: dict[int, int] | None = None,
) -> tuple[list[_Piece], tuple[int, int] | None, bool]:
    """Lane pieces along the route: normal lanes, junction lanes, and lane
    changes within an edge where the current lane does not continue.

    A needed lane change on the first edge follows ``change`` = (start, length
    in m along the lane) when given. Otherwise, with ``defer_changes`` the
    pieces stop at the end of the lane that does not continue and the second
    value says where the change is due: (edge index, target lane index); the
    caller rebuilds once the change can be made. Without it the change spans
    the whole edge. A change due early (``change_early``) on a lane that goes
    on is pending the same way, but the pieces follow the lane on to where
    it ends for the route; the third value says so. ``change`` = (start,
    length, target lane index) is a
    change the route does not need (to overtake, to keep right): onto that
    lane of the first edge, which must go on along the route.
    ``prefer`` (edge index -> lane index, not the first edge): a lane the
    track must be on at that edge (a stop's), where the rest of the route
    can be driven from it and the edge before connects onto it: the route
    then goes on to that edge only onto that lane, and the track gets there
    as it does wherever a lane does not go on (connections first, then a
    lane change).
    """
    objs = []
    for eid in edges:
        try:
            objs.append(net.getEdge(eid))
        except KeyError:
            raise PathError(f"route edge {eid!r} is not in the network") from None

    revisits = len(set(edges)) < len(edges)

    # Edge index -> the lane of ``prefer`` taken there: the only lane the
    # route goes on to on that edge (filled backwards, below).
    taken: dict[int, str] = {}

    def conns_to(lane: Any, k: int) -> list[Any]:
        if k >= len(objs):
            return []
        cs = [c for c in lane.getOutgoing() if c.getTo() is objs[k]]
        only = taken.get(k)
        return [c for c in cs if c.getToLane().getID() == only] if only is not None else cs

    def preferred(k: int, lanes: set[str]) -> set[str]:
        # The lane ``prefer`` asks for on edge k, when the rest of the route
        # can be driven from it without a change and the edge before has a
        # connection onto it: from then on the route goes on only there.
        want = prefer.get(k) if prefer else None
        if want is None or k == 0 or not 0 <= want < objs[k].getLaneNumber():
            return lanes
        lane_id = objs[k].getLane(want).getID()
        if lane_id not in lanes or not any(c.getToLane().getID() == lane_id for ln in objs[k - 1].getLanes() for c in conns_to(ln, k)):
            return lanes
        taken[k] = lane_id
        return {lane_id}

    # Lanes from which the rest of the route needs no lane change (backwards).
    no_change: list[set[str]] = [set() for _ in objs]
    no_change[-1] = preferred(len(objs) - 1, {ln.getID() for ln in objs[-1].getLanes()})
    for k in range(len(objs) - 2, -1, -1):
        for ln in objs[k].getLanes():
            if any(c.getToLane().getID() in no_change[k + 1] for c in conns_to(ln, k + 1)):
                no_change[k].add(ln.getID())
        no_change[k] = preferred(k, no_change[k])

    def piece(lane: Any) -> _Piece:
        return _lane_piece(lane, spacing_m)

    def change_early(lane: Any, k: int) -> bool:
        """Is the change the route needs further on due on edge ``k``
        already? It is when ``lane`` leads on to a lane that ends within
        ``EARLY_CHANGE_ROOM_M`` per lane to cross past this edge, and a lane
        of this edge needs no change: SUMO's drivers change well before, and
        left to a 67 m edge, two lanes over, controlled vehicles stood there
        (Eccles)."""
        if lane.getID() in no_change[k] or revisits:
            # A route that drives an edge more than once keeps its changes
            # where the lane ends: brought an edge forward there, the change
            # put the vehicles of tests/test_loops.py off the road (to do:
            # the change's occurrence with the early edge).
            return False
        goals = [ln.getIndex() for ln in objs[k].getLanes() if ln.getID() in no_change[k]]
        if not goals:
            return False
        room = EARLY_CHANGE_ROOM_M * min(abs(g - lane.getIndex()) for g in goals)
        run, j, cur = 0.0, k, lane
        while run < room:
            nxt = conns_to(cur, j + 1)
            if not nxt:
                return True  # the lane ends (for the route) this close
            cur, j = nxt[0].getToLane(), j + 1
            run += float(cur.getLength())
        return False

    def change_target(lane: Any, k: int) -> Any:
        """The lane of edge ``k`` a change from ``lane`` goes to: the
        nearest that leads on to edge ``k + 1``, one needing no later change
        first."""
        able = [ln for ln in objs[k].getLanes() if conns_to(ln, k + 1)]
        if not able:
            raise PathError(
                f"no lane of edge {edges[k]!r} connects to edge {edges[k + 1]!r}: the route is not drivable"
            )
        best = [ln for ln in able if ln.getID() in no_change[k]] or able
        return min(best, key=lambda ln: abs(ln.getIndex() - lane.getIndex()))

    out: list[_Piece] = []
    # A change due early on a lane that goes on: (edge index, target lane index).
    early: tuple[int, int] | None = None
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
        # Every piece from here on is of edge k (or its junction lanes) until the next k.
        tag_from = len(out)
        if k + 1 == len(objs):
            if not first_done:
                out.append(piece(lane))
            _tag(out, tag_from, k)
            break
        cs = conns_to(lane, k + 1)
        if defer_changes and not (k == 0 and change is not None) and cs and (early is not None or change_early(lane, k)):
            # Due early, but the lane goes on: the track follows it (the
            # vehicle does not stand at the edge's end waiting for a gap, with
            # the lane's traffic behind it: Eccles, three lanes to cross on a
            # 123 m edge, one stood 80 s and its lane queued behind it); the
            # change is tried on this edge, then on the next ones.
            if early is None:
                early = (k, change_target(lane, k).getIndex())
            out.append(piece(lane))
        elif not cs and defer_changes and early is not None:
            # Where the lane ends for the route after an early change was due.
            out.append(piece(lane))
            _tag(out, tag_from, k)
            return out, early, True
        elif first_done:
            pass
        elif not cs or change_early(lane, k):
            # Change to the nearest lane of this edge that continues.
            target = change_target(lane, k)
            if k == 0 and change is not None:
                out.extend(_lane_change_pieces(lane, target, spacing_m, change[0], change[1]))
            elif defer_changes:
                out.append(piece(lane))
                _tag(out, tag_from, k)
                return out, (k, target.getIndex()), False
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
        _tag(out, tag_from, k)
        lane = c.getToLane()
    return out, early, early is not None


def _chain_piece(pc: _Piece) -> tuple[np.ndarray, np.ndarray, bool, float]:
    """A piece as ``polyline_join`` takes it: points, their positions along
    the lane's shape, on the lane or not, SUMO's length per metre of shape.
    A lane whose shape has no length (a junction lane netconvert leaves at
    one point, 0.1 m long to SUMO) spans its SUMO length over its points,
    so that the stations after it count it as SUMO does."""
    if pc.shape_length_m < 1e-6:
        return pc.shape, np.linspace(0.0, pc.length_m, len(pc.shape)), pc.on_lane, 1.0
    return pc.shape, pc.lane_s, pc.on_lane, pc.length_m / pc.shape_length_m


def _tag(pieces: list[_Piece], start: int, occurrence: int) -> None:
    """``pieces[start:]`` are of the route's edge ``occurrence``."""
    for pc in pieces[start:]:
        pc.occurrence = occurrence


def route_geometry(
    net: Any,
    edges: Sequence[str],
    start_lane_index: int = 0,
    spacing_m: float = 1.0,
    smoothing_m: float = 1.5,
    defer_changes: bool = False,
    change: tuple[float, float] | tuple[float, float, int] | None = None,
    border_margin_m: float = 0.0,
    carriageway: bool = False,
    prefer: dict[int, int] | None = None,
    min_turn_radius_m: float = MIN_TURN_RADIUS_M,
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
    ``border_margin_m``; with ``carriageway`` a normal lane's are the
    distances to the edges of its whole edge (junction lanes keep their half
    width; a lane change's are the carriageway's anyway). ``prefer``: lanes
    to take where the route allows (see ``_pieces``). Stretches of the
    smoothed track still sharper than ``min_turn_radius_m`` are smoothed
    again, more widely, until they are not (0: left as they are).
    Raises :class:`blendtrack.PathError` for an empty or undrivable route.
    """
    if len(edges) == 0:
        raise PathError("the route has no edges")
    pieces, pending, early = _pieces(net, edges, start_lane_index, spacing_m, defer_changes, change, prefer)
    # Joined and smoothed in Rust: the pieces end to end (sharing a point
    # where one starts at the last one's end), the Gaussian smoothing, and
    # each piece cut where the track comes near its lane's centreline or
    # leaves it (the smoothing rounds the kinks at lane joints over a few
    # metres), every arc length on the smoothed track (the path the
    # controllers follow). The runs near the centreline can be handed to
    # SUMO as (lane, position): where a lane starts (its position 0) the
    # run starts at that point of the track.
    joined = polyline_join(
        [_chain_piece(pc) for pc in pieces],
        smoothing_m / spacing_m,
        NEAR_LANE_M,
        MIN_RUN_PTS,
        1.0 / min_turn_radius_m if min_turn_radius_m > 0 else 0.0,
    )
    wid: list[np.ndarray] = []
    stops: list[tuple[float, str, int, bool, str, float]] = []
    for k, i in enumerate(joined["kept"]):
        pc, n = pieces[i], joined["kept_points"][k]
        if pc.tls is not None:
            # The stop line is where the incoming lane ends, before any gap
            # to the junction lane's first point (about 1 m in the urban grid).
            stops.append((joined["before_s"][k], pc.tls[0], pc.tls[1], pc.tls[2], pc.lane, math.inf))
        if not pc.lane.startswith(":"):
            # The junction is left here: the exit of its entry and of its
            # internal junction, if any.
            for j in range(len(stops) - 1, -1, -1):
                if not math.isinf(stops[j][5]):
                    break
                stops[j] = (*stops[j][:5], joined["entry_s"][k])
        if carriageway and pc.on_lane and not pc.lane.startswith(":"):
            # On its lane (also after a change: no taper back to the lane's).
            lane = net.getLane(pc.lane)
            wid.append(_carriageway_widths(lane, lane, np.zeros(n)) + border_margin_m)
        elif pc.widths is not None:
            wid.append(pc.widths[len(pc.widths) - n:] + border_margin_m)
        else:
            wid.append(np.full((n, 2), pc.half_width_m + border_margin_m))
    pieces_of = [pieces[i] for i in joined["run_piece"]]
    return RouteGeometry(
        points=joined["points"],
        widths=np.concatenate(wid),
        piece_start_s=joined["run_start_s"],
        piece_lane=[p.lane for p in pieces_of],
        piece_edge=[p.edge for p in pieces_of],
        piece_index=[p.index for p in pieces_of],
        piece_speed=np.array([p.speed_mps for p in pieces_of]),
        piece_lane_pos=joined["run_station"],
        piece_scale=joined["run_scale"],
        piece_lane_length=np.array([p.length_m for p in pieces_of]),
        piece_occurrence=[p.occurrence for p in pieces_of],
        piece_offset=joined["run_offset"],
        length_m=joined["length_m"],
        station=joined["station"],
        pending_change=pending,
        pending_early=early,
        stops=stops,
        edges=tuple(edges),
        rounded=[(float(a), float(b), float(k)) for a, b, k in joined["rounded"]],
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


def path_ahead(path: np.ndarray, point: np.ndarray) -> np.ndarray:
    """The polyline ``path`` (n x 2, n >= 2) from the point nearest ``point``
    on it onwards (that point first)."""
    a, b = path[:-1], path[1:]
    d = b - a
    den = np.einsum("ij,ij->i", d, d)
    t = np.clip(np.einsum("ij,ij->i", point - a, d) / np.where(den > 0.0, den, 1.0), 0.0, 1.0)
    q = a + t[:, None] * d
    k = int(np.argmin(np.einsum("ij,ij->i", q - point, q - point)))
    return np.vstack([q[k], path[k + 1 :]])


def polyline_tail(points: np.ndarray, length: float) -> np.ndarray:
    """The last ``length`` metres of the polyline ``points`` (n x 2, n >= 2),
    starting at the point that far from its end (the whole polyline when it
    is shorter)."""
    s = polyline_arc_lengths(points)
    start = s[-1] - length
    if start <= 0.0:
        return points
    k = int(np.searchsorted(s, start, side="right"))
    u = (start - s[k - 1]) / (s[k] - s[k - 1])
    return np.vstack([points[k - 1] + u * (points[k] - points[k - 1]), points[k:]])


def segments_distance(p: np.ndarray, q: np.ndarray) -> float:
    """Smallest distance between the polylines ``p`` and ``q`` (n x 2 each):
    zero where two segments cross, else the smallest of the end point to
    segment distances; infinite when either is empty (Rust,
    ``blendtrack::polyline::segments_distance``). Raises
    :class:`blendtrack.PathError` for a coordinate that is not finite."""
    a, b = np.asarray(p, dtype=float), np.asarray(q, dtype=float)
    return polyline_distance(a.reshape(0, 2) if a.size == 0 else a, b.reshape(0, 2) if b.size == 0 else b)
