"""Static analysis of the SUMO network (sumolib), done lazily and cached:
which connection a junction lane belongs to, the junction lanes near a path
through a junction, the foes of an internal junction lane, and the internal
waiting point of a turn."""

from __future__ import annotations

from typing import Any

import numpy as np

from blendtrack.sumo.geometry import _via_chain, polyline_tail, segments_distance

#: Junction lanes further than this from a path (m) never carry a vehicle in
#: its way: a wide body's half width (1.25 m) plus a car's reach (0.9 m +
#: ``junctions.INSIDE_MARGIN_M``) plus 0.5 m. Parallel lanes (3.2 m and more
#: apart) are not checked, so a junction that only joins lane after lane (a
#: highway's edges) asks nothing.
INSIDE_LANE_REACH_M = 3.0

#: The part of a junction lane before an internal waiting point that a car
#: standing there covers (m): its length.
WAITING_BODY_M = 5.0


def edge_of(lane: str) -> str:
    """The edge of the lane id ``lane`` (SUMO's lane ids are ``<edge>_<index>``)."""
    return lane.rsplit("_", 1)[0]


def _matrix_bit(rows: dict[int, str], i: int, j: int) -> bool:
    """Bit ``j`` of row ``i`` of a junction's right-of-way matrix (sumolib's
    ``Node._foes`` or ``_prohibits``: per link index a string, link 0 last).
    False where the junction has no such row or bit: an unregulated junction
    (``type="unregulated"``) has no ``<request>``s at all, and neither its
    links nor a link that is not the junction's (index -1) have foes. SUMO's
    ``tools/game/grid6`` has four such junctions; sumolib's ``areFoes`` raised
    a ``KeyError`` there."""
    row = rows.get(i) if i >= 0 and j >= 0 else None
    return row is not None and j < len(row) and row[len(row) - j - 1] == "1"


class Network:
    """The network of one scenario, read once (with its internal lanes) when first needed."""

    def __init__(self, net_file: Any) -> None:
        self.net_file = net_file
        self._net: Any = None
        #: Junction lanes that start at an internal junction (see geometry's
        #: stops), as the registered tracks have met them.
        self.internal_vias: set[str] = set()
        self._conn_of_via: dict[str, Any] | None = None
        #: Per junction entry lane: (its path through the junction, the other
        #: junction lanes that come near it); see ``junction_lanes``.
        self._inside: dict[str, tuple[np.ndarray, tuple[str, ...]]] = {}
        #: Per junction entry lane: the lanes out of the junction after those
        #: near lanes (its own way's excepted); see ``junction_exits``.
        self._exits: dict[str, tuple[str, ...]] = {}
        #: Per junction entry lane: the junction lanes that end at an
        #: internal waiting point near its path; see ``waiting_points_near``.
        self._waiting_near: dict[str, tuple[tuple[str, float], ...]] = {}
        #: Per junction entry lane: its internal waiting point and the distance to it.
        self._waiting_points: dict[str, tuple[str | None, float]] = {}
        self._foes: dict[str, list[tuple[str, str | None, float, str, int]]] = {}
        self._after: dict[str, list[tuple[str, float]]] = {}
        self._next: dict[str, tuple[str, ...]] = {}
        self._through: dict[tuple[str, str], float | None] = {}
        self._prohibitors: dict[str, list[tuple[str, str | None, float, str, int]]] = {}
        self._ways_from: dict[tuple[str, str], frozenset[str]] = {}
        self._stops_inside: dict[str, bool] = {}
        self._states: dict[str, str] = {}
        self._conflicts: dict[tuple[str, str], tuple[float, float]] = {}
        self._crossings: dict[tuple[str, str], tuple[float, float] | None] = {}
        self._from_lanes: dict[str, str | None] = {}
        #: Per node (by id): each of its connections' link index (sumolib's
        #: ``Node.getLinkIndex``, which walks the node's connections anew on
        #: every call).
        self._link_indices: dict[str, dict[Any, int]] = {}
        self._fanouts: dict[str, tuple[tuple[str, ...], float]] | None = None
        self._into: dict[str, list[tuple[tuple[str, float], ...]]] | None = None
        self._feeders: dict[str, tuple[tuple[str, float], ...]] = {}
        self._lengths: dict[str, float] = {}
        self._shapes: dict[str, tuple[np.ndarray, float]] = {}
        self._edge_lanes: dict[str, tuple[str, ...]] = {}
        self._into_merges: frozenset[str] | None = None
        self._not_keep_clear: frozenset[str] | None = None
        self._roundabout_edges: frozenset[str] | None = None

    def net(self) -> Any:
        """The sumolib network."""
        if self._net is None:
            import sumolib

            self._net = sumolib.net.readNet(str(self.net_file), withInternal=True)
        return self._net

    def connection_of(self, via: str) -> Any:
        """The network connection whose junction lanes include ``via`` (None if none)."""
        if self._conn_of_via is None:
            net = self.net()
            self._conn_of_via = {}
            for edge in net.getEdges():
                for ln in edge.getLanes():
                    for c in ln.getOutgoing():
                        for part in _via_chain(net, c):
                            self._conn_of_via[part.getID()] = c
        return self._conn_of_via.get(via)

    def from_lane(self, via: str) -> str | None:
        """The lane the connection through junction lane ``via`` leaves
        from (None for a lane of no connection)."""
        try:
            return self._from_lanes[via]
        except KeyError:
            c = self.connection_of(via)
            hit = self._from_lanes[via] = None if c is None else str(c.getFromLane().getID())
            return hit

    def fanouts(self) -> dict[str, tuple[tuple[str, ...], float]]:
        """Per normal lane that fans out, two or more of its connections
        leading to one edge (one lane onto several lanes of the next edge):
        (the first junction lanes of those connections, the lane's length).
        Which of them SUMO's driver takes is its own choice of lane, so
        ``getLeader`` may look along another than the track's."""
        if self._fanouts is None:
            self._fanouts = {}
            for edge in self.net().getEdges():
                if edge.getFunction() == "internal":
                    continue
                for ln in edge.getLanes():
                    by_edge: dict[str, list[str]] = {}
                    for c in ln.getOutgoing():
                        via = c.getViaLaneID()
                        if via:
                            by_edge.setdefault(c.getTo().getID(), []).append(via)
                    vias = tuple(v for group in by_edge.values() if len(group) > 1 for v in group)
                    if vias:
                        self._fanouts[ln.getID()] = (vias, float(ln.getLength()))
        return self._fanouts

    def ways_into(self, lane: str) -> list[tuple[tuple[str, float], ...]]:
        """The ways through junctions onto ``lane`` (a normal lane): for
        each connection to it, its junction lanes with their lengths, in
        order; [] when fewer than two lead there (no merge)."""
        if self._into is None:
            net = self.net()
            into: dict[str, list[tuple[tuple[str, float], ...]]] = {}
            for edge in net.getEdges():
                if edge.getFunction() == "internal":
                    continue
                for ln in edge.getLanes():
                    for c in ln.getOutgoing():
                        chain = tuple((part.getID(), float(part.getLength())) for part in _via_chain(net, c))
                        if chain:
                            into.setdefault(c.getToLane().getID(), []).append(chain)
            self._into = {k: v for k, v in into.items() if len(v) > 1}
        return self._into.get(lane, [])

    def ways_from(self, edge: str, lane: str) -> frozenset[str]:
        """The lanes of ``edge`` with a connection to ``lane`` and those
        connections' junction lanes (empty when none leads there)."""
        key = (edge, lane)
        hit = self._ways_from.get(key)
        if hit is None:
            net = self.net()
            found: set[str] = set()
            try:
                lanes = net.getEdge(edge).getLanes()
            except KeyError:
                lanes = []
            for ln in lanes:
                for c in ln.getOutgoing():
                    if c.getToLane().getID() == lane:
                        found.add(ln.getID())
                        found.update(part.getID() for part in _via_chain(net, c))
            hit = self._ways_from[key] = frozenset(found)
        return hit

    def feeders(self, lane: str) -> tuple[tuple[str, float], ...]:
        """The lanes that lead onto ``lane`` (a normal lane) through one
        junction: its junction lanes and the normal lanes before them, each
        with the distance (m) from its start to ``lane``'s start, so that a
        position ``p`` on it is ``p - distance`` in ``lane``'s positions."""
        hit = self._feeders.get(lane)
        if hit is None:
            net = self.net()
            out: dict[str, float] = {}
            try:
                conns = net.getLane(lane).getIncomingConnections()
            except (KeyError, AttributeError):
                conns = []
            for c in conns:
                before = c.getFromLane()
                if before.getID().startswith(":"):
                    continue
                chain = _via_chain(net, c)
                dist = 0.0
                for part in reversed(chain):
                    dist += float(part.getLength())
                    out.setdefault(part.getID(), dist)
                out.setdefault(before.getID(), dist + float(before.getLength()))
            hit = self._feeders[lane] = tuple(out.items())
        return hit

    def lanes_into_merges(self) -> frozenset[str]:
        """The normal lanes with a connection onto a lane that several ways
        merge onto (``ways_into``)."""
        if self._into_merges is None:
            self.ways_into("")
            assert self._into is not None
            self._into_merges = frozenset(
                ln.getID()
                for edge in self.net().getEdges() if edge.getFunction() != "internal"
                for ln in edge.getLanes()
                if any(c.getToLane().getID() in self._into for c in ln.getOutgoing())
            )
        return self._into_merges

    def lane_length(self, lane: str) -> float:
        """The length of ``lane`` (m)."""
        hit = self._lengths.get(lane)
        if hit is None:
            hit = self._lengths[lane] = float(self.net().getLane(lane).getLength())
        return hit

    def lane_shape(self, lane: str) -> tuple[np.ndarray, float]:
        """The centreline of ``lane`` (n x 2) and its width (m)."""
        hit = self._shapes.get(lane)
        if hit is None:
            ln = self.net().getLane(lane)
            hit = self._shapes[lane] = (np.asarray(ln.getShape(), dtype=float)[:, :2], float(ln.getWidth()))
        return hit

    def edge_lanes(self, edge: str) -> tuple[str, ...]:
        """The lanes of ``edge`` (normal or a junction's), right to left; () for an unknown edge."""
        hit = self._edge_lanes.get(edge)
        if hit is None:
            net = self.net()
            hit = self._edge_lanes[edge] = tuple(ln.getID() for ln in net.getEdge(edge).getLanes()) if net.hasEdge(edge) else ()
        return hit

    def is_zipper(self, via: str) -> bool:
        """Is ``via`` a junction lane of a zipper link (state Z)?"""
        c = self.connection_of(via)
        return c is not None and c.getState() == "Z"

    def junction_lanes(self, via: str) -> tuple[np.ndarray, tuple[str, ...]]:
        """The path (points) through the junction from the junction lane
        ``via`` on, and the junction's other lanes that come within
        ``INSIDE_LANE_REACH_M`` of it (none: nothing to check)."""
        hit = self._inside.get(via)
        if hit is None:
            net = self.net()
            c = self.connection_of(via)
            path = np.zeros((0, 2))
            near: list[str] = []
            exits: list[str] = []
            if c is not None:
                chain = [part.getID() for part in _via_chain(net, c)]
                own = chain[chain.index(via):] if via in chain else chain
                if own:
                    path = np.concatenate([self.lane_shape(x)[0] for x in own])
                    node = c.getFrom().getToNode()
                    seen = set(chain)
                    own_exit = c.getToLane().getID()
                    for other in node.getConnections():
                        for part in _via_chain(net, other):
                            lid = part.getID()
                            if lid in seen:
                                continue
                            seen.add(lid)
                            if segments_distance(self.lane_shape(lid)[0], path) < INSIDE_LANE_REACH_M:
                                near.append(lid)
                                out = other.getToLane().getID()
                                if out != own_exit and out not in exits:
                                    exits.append(out)
            hit = (path, tuple(near))
            self._inside[via] = hit
            self._exits[via] = tuple(exits)
        return hit

    def junction_exits(self, via: str) -> tuple[str, ...]:
        """The lanes out of the junction that the near lanes of
        ``junction_lanes(via)`` lead onto, ``via``'s own way's excepted: a
        vehicle there whose back is still in the junction stands in the
        near lane, though SUMO lists it on the lane its front is on."""
        self.junction_lanes(via)
        return self._exits.get(via, ())

    def waiting_points_near(self, via: str) -> tuple[tuple[str, float], ...]:
        """The junction lanes near ``via``'s path (``junction_lanes``) that
        end at an internal waiting point, each with the distance from the
        path to the lane's last ``WAITING_BODY_M`` (where a car waiting
        there stands); not those from ``via``'s own lane (a vehicle there is
        ahead of the one on ``via``: followed, not waited for). Some networks
        put a left turn's waiting point within reach of another way: a car
        waiting there stands across it (Bologna, junction 27: 1.6 m from the
        bus lane's centreline, and SUMO's own bus drives into it in every
        seed)."""
        hit = self._waiting_near.get(via)
        if hit is None:
            path, near = self.junction_lanes(via)
            found = []
            net = self.net()
            origin = self.from_lane(via)
            for lane in near:
                c = self.connection_of(lane)
                chain = [part.getID() for part in _via_chain(net, c)] if c is not None else []
                if lane not in chain or chain[-1] == lane or self.from_lane(lane) == origin:
                    continue
                tail = polyline_tail(self.lane_shape(lane)[0], WAITING_BODY_M)
                dist = segments_distance(tail, path)
                if dist < INSIDE_LANE_REACH_M:
                    found.append((lane, float(dist)))
            hit = self._waiting_near[via] = tuple(found)
        return hit

    def waiting_point_after(self, via: str) -> tuple[str | None, float]:
        """The internal waiting point on the junction path that starts with
        ``via`` (its junction lane, and its distance from the entry line along
        the lanes), or (None, 0)."""
        hit = self._waiting_points.get(via)
        if hit is None:
            hit = (None, 0.0)
            c = self.connection_of(via)
            if c is not None:
                offset = 0.0
                for part in _via_chain(self.net(), c):
                    if part.getID() != via and part.getID() in self.internal_vias:
                        hit = (part.getID(), offset)
                        break
                    offset += float(part.getLength())
            self._waiting_points[via] = hit
        return hit

    def stops_inside(self, via: str) -> bool:
        """Does the way through junction lane ``via`` stop at an internal
        waiting point after it (a turn across oncoming lanes)? Unlike
        ``waiting_point_after``, known for any junction lane, not only the
        ones on a controlled vehicle's track."""
        hit = self._stops_inside.get(via)
        if hit is None:
            hit = self._stops_inside[via] = any(self.after_internal_junction(part) for part, _ in self.lanes_after(via)[1:-1])
        return hit

    def after_internal_junction(self, via: str) -> bool:
        """Does the junction lane ``via`` start at an internal junction (the
        waiting point of a turn across oncoming lanes), not at the junction's
        entry? (An unsignalised entry has link index -1 like an internal
        junction, so the index does not tell.)"""
        c = self.connection_of(via)
        if c is None:
            return False
        chain = _via_chain(self.net(), c)
        return bool(chain) and chain[0].getID() != via

    def link_state(self, via: str) -> str:
        """The right-of-way state of the connection whose junction lanes
        include ``via`` (``M`` major, ``m`` minor, ``=`` right before left,
        ``s`` stop sign, ``w`` all-way stop, ``Z`` zipper, or a light's
        ``o``/``O``); "" when unknown."""
        hit = self._states.get(via)
        if hit is None:
            c = self.connection_of(via)
            hit = self._states[via] = (c.getState() or "") if c is not None else ""
        return hit

    def prohibitors(self, via: str) -> list[tuple[str, str | None, float, str, int]]:
        """The foes a vehicle entering the junction through ``via`` must give
        way to: the connections that prohibit its own by the network's
        right-of-way matrix (sumolib's ``Node.forbids``), in the form of
        ``internal_foes``. At a right-before-left junction only the ones from
        the right; a connection from the left gives way to this one."""
        hit = self._prohibitors.get(via)
        if hit is None:
            hit = self._prohibitors[via] = self._conflicting(via, self._forbids)
        return hit

    def internal_foes(self, via: str) -> list[tuple[str, str | None, float, str, int]]:
        """Foe junction lanes of an internal junction lane: (foe lane, the normal
        lane leading into it or None, that lane's length, its traffic light, link
        index). From the network's right-of-way matrix (sumolib), not from
        libsumo's ``lane.getInternalFoes``: that call leaves state behind which
        crashes a later simulation in the same process (libsumo 1.28)."""
        hit = self._foes.get(via)
        if hit is None:

            def foes(node: Any, c: Any, other: Any) -> bool:
                i, j = self._link_index(node, c), self._link_index(node, other)
                # What ``Node.areFoes`` reads.
                return _matrix_bit(node._foes, i, j)

            hit = self._foes[via] = self._conflicting(via, foes)
        return hit

    def _link_index(self, node: Any, c: Any) -> int:
        """``node.getLinkIndex(c)``, computed once per node for all its connections."""
        indices = self._link_indices.get(node.getID())
        if indices is None:
            indices = self._link_indices[node.getID()] = {other: node.getLinkIndex(other) for other in node.getConnections()}
        hit = indices.get(c)
        return node.getLinkIndex(c) if hit is None else hit

    def _forbids(self, node: Any, c: Any, other: Any) -> bool:
        """sumolib's ``node.forbids(other, c)`` (does ``other`` prohibit
        ``c`` by the right-of-way matrix?) with the link indices cached."""
        prohibitor, prohibited = self._link_index(node, other), self._link_index(node, c)
        # What ``Node.forbids`` reads, by the indices it would compute.
        return _matrix_bit(node._prohibits, prohibited, prohibitor)

    def _conflicting(self, via: str, conflicts: Any) -> list[tuple[str, str | None, float, str, int]]:
        """The junction lanes of the connections ``other`` of ``via``'s
        junction for which ``conflicts(node, c, other)`` holds (``c``: the
        connection of ``via``): the first of each chain with (the normal lane
        leading into it, that lane's length, its traffic light, link index),
        the rest of the chain with (None, 0, "", -1)."""
        net = self.net()
        hit: list[tuple[str, str | None, float, str, int]] = []
        c = self.connection_of(via)
        if c is None:
            return hit
        node = c.getFrom().getToNode()
        for other in node.getConnections():
            if other is c or not conflicts(node, c, other):
                continue
            chain = [part.getID() for part in _via_chain(net, other)]
            if not chain:
                continue
            src = other.getFromLane()
            hit.append((chain[0], src.getID(), float(src.getLength()), other.getTLSID() or "", int(other.getTLLinkIndex())))
            hit.extend((part, None, 0.0, "", -1) for part in chain[1:])
        return hit

    def lanes_after(self, via: str) -> list[tuple[str, float]]:
        """The junction lane ``via`` and the lanes after it on its connection
        (the rest of its junction lanes, then the lane the connection leads
        to), each with its length; [] when ``via`` is no junction lane."""
        hit = self._after.get(via)
        if hit is None:
            hit = []
            c = self.connection_of(via)
            if c is not None:
                chain = list(_via_chain(self.net(), c))
                ids = [part.getID() for part in chain]
                if via in ids:
                    hit = [(part.getID(), float(part.getLength())) for part in chain[ids.index(via):]]
                    to = c.getToLane()
                    hit.append((to.getID(), float(to.getLength())))
            self._after[via] = hit
        return hit

    def lanes_next(self, lane: str) -> tuple[str, ...]:
        """The first lanes after normal lane ``lane``: each of its
        connections' first junction lane (or the lane it leads to, where
        it has none); () for a lane the network does not have."""
        hit = self._next.get(lane)
        if hit is None:
            hit = self._next[lane] = tuple(dict.fromkeys(c.getViaLaneID() or c.getToLane().getID() for c in self._outgoing(lane)))
        return hit

    def through_length(self, lane: str, to: str) -> float | None:
        """The length of the junction lanes of normal lane ``lane``'s
        connection to lane ``to`` (0 for one without junction lanes), or
        None when ``lane`` has no connection to ``to``."""
        key = (lane, to)
        if key not in self._through:
            self._through[key] = next(
                (sum(float(part.getLength()) for part in _via_chain(self.net(), c))
                 for c in self._outgoing(lane) if c.getToLane().getID() == to), None)
        return self._through[key]

    def _outgoing(self, lane: str) -> list[Any]:
        """sumolib's connections out of ``lane`` ([] for a lane the network does not have)."""
        try:
            return list(self.net().getLane(lane).getOutgoing())
        except (KeyError, ValueError):
            return []

    def keeps_clear(self, via: str) -> bool:
        """Must the junction be kept clear on the way of ``via`` (the
        connection's ``keepClear``, true unless the network says 0)?"""
        if self._not_keep_clear is None:
            import sumolib

            self._not_keep_clear = frozenset(
                c.via for c in sumolib.xml.parse_fast(str(self.net_file), "connection", ["keepClear", "via"])
                if c.keepClear in ("0", "false"))
        return via not in self._not_keep_clear

    def in_roundabout(self, edge: str) -> bool:
        """Is ``edge`` part of a roundabout?"""
        if self._roundabout_edges is None:
            self._roundabout_edges = frozenset(e for r in self.net().getRoundabouts() for e in r.getEdges())
        return edge in self._roundabout_edges

    def conflict(self, via: str, foe: str) -> tuple[float, float]:
        """Where the way through the junction from ``via`` on first meets the
        way of the foe connection whose first junction lane is ``foe``: the
        distance to that point along each (m, from the start of ``via`` and
        of ``foe``); where they never cross (they merge), the ends of both."""
        return self._between(self._conflicts, first_crossing, via, foe)

    def crossing(self, via: str, foe: str) -> tuple[float, float] | None:
        """``conflict(via, foe)`` where the two ways cross, None where they
        do not (they merge, or ``foe`` is a junction lane past the crossing)."""
        return self._between(self._crossings, crossing_point, via, foe)

    def _between(self, cache: dict[tuple[str, str], Any], measure: Any, via: str, foe: str) -> Any:
        """``measure`` of the ways through the junction from ``via`` and from
        ``foe`` (their paths), once per pair (kept in ``cache``)."""
        key = (via, foe)
        try:
            return cache[key]
        except KeyError:
            path, _ = self.junction_lanes(via)
            other, _ = self.junction_lanes(foe)
            hit = cache[key] = measure(path, other)
            return hit


def _arc(p: np.ndarray) -> np.ndarray:
    """Arc length at each point of the polyline ``p``."""
    if len(p) < 2:
        return np.zeros(len(p))
    return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(p, axis=0).T))])


def first_crossing(p: np.ndarray, q: np.ndarray) -> tuple[float, float]:
    """The arc lengths along ``p`` and along ``q`` (polylines, n x 2) of the
    first point of ``p`` where they cross; their lengths where they never do."""
    hit = crossing_point(p, q)
    if hit is not None:
        return hit
    sp, sq = _arc(p), _arc(q)
    return float(sp[-1]) if len(sp) else 0.0, float(sq[-1]) if len(sq) else 0.0


def crossing_point(p: np.ndarray, q: np.ndarray) -> tuple[float, float] | None:
    """``first_crossing`` where the polylines cross, None where they never do."""
    sp, sq = _arc(p), _arc(q)
    for i in range(len(p) - 1):
        a, d = p[i], p[i + 1] - p[i]
        for j in range(len(q) - 1):
            b, e = q[j], q[j + 1] - q[j]
            den = d[0] * e[1] - d[1] * e[0]
            if abs(den) < 1e-12:
                continue
            w = b - a
            t = (w[0] * e[1] - w[1] * e[0]) / den
            u = (w[0] * d[1] - w[1] * d[0]) / den
            if 0.0 <= t <= 1.0 and 0.0 <= u <= 1.0:
                return float(sp[i] + t * (sp[i + 1] - sp[i])), float(sq[j] + u * (sq[j + 1] - sq[j]))
    return None
