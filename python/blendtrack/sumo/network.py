"""Static analysis of the SUMO network (sumolib), done lazily and cached:
which connection a junction lane belongs to, the junction lanes near a path
through a junction, the foes of an internal junction lane, and the internal
waiting point of a turn."""

from __future__ import annotations

from typing import Any

import numpy as np

from blendtrack.sumo.geometry import _via_chain, segments_distance

#: Junction lanes further than this from a path (m) never carry a vehicle in
#: its way: a wide body's half width (1.25 m) plus a car's reach (0.9 m +
#: ``junctions.INSIDE_MARGIN_M``) plus 0.5 m. Parallel lanes (3.2 m and more
#: apart) are not checked, so a junction that only joins lane after lane (a
#: highway's edges) asks nothing.
INSIDE_LANE_REACH_M = 3.0


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
        #: Per junction entry lane: its internal waiting point and the distance to it.
        self._waiting_points: dict[str, tuple[str | None, float]] = {}
        self._foes: dict[str, list[tuple[str, str | None, float, str, int]]] = {}

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
            if c is not None:
                chain = [part.getID() for part in _via_chain(net, c)]
                own = chain[chain.index(via):] if via in chain else chain
                if own:
                    path = np.concatenate([np.asarray(net.getLane(x).getShape(), dtype=float)[:, :2] for x in own])
                    node = c.getFrom().getToNode()
                    seen = set(chain)
                    for other in node.getConnections():
                        for part in _via_chain(net, other):
                            lid = part.getID()
                            if lid in seen:
                                continue
                            seen.add(lid)
                            pts = np.asarray(part.getShape(), dtype=float)[:, :2]
                            if segments_distance(pts, path) < INSIDE_LANE_REACH_M:
                                near.append(lid)
            hit = (path, tuple(near))
            self._inside[via] = hit
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

    def internal_foes(self, via: str) -> list[tuple[str, str | None, float, str, int]]:
        """Foe junction lanes of an internal junction lane: (foe lane, the normal
        lane leading into it or None, that lane's length, its traffic light, link
        index). From the network's right-of-way matrix (sumolib), not from
        libsumo's ``lane.getInternalFoes``: that call leaves state behind which
        crashes a later simulation in the same process (libsumo 1.28)."""
        hit = self._foes.get(via)
        if hit is None:
            net = self.net()
            hit = []
            c = self.connection_of(via)
            if c is not None:
                node = c.getFrom().getToNode()
                i = node.getLinkIndex(c)
                for other in node.getConnections():
                    j = node.getLinkIndex(other)
                    if other is c or i < 0 or j < 0 or not node.areFoes(i, j):
                        continue
                    chain = [part.getID() for part in _via_chain(net, other)]
                    if not chain:
                        continue
                    src = other.getFromLane()
                    hit.append((chain[0], src.getID(), float(src.getLength()), other.getTLSID() or "", int(other.getTLLinkIndex())))
                    hit.extend((part, None, 0.0, "", -1) for part in chain[1:])
            self._foes[via] = hit
        return hit
