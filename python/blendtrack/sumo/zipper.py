"""Zipper merges (junction type ``zipper``, link state ``Z``): two streams
become one lane and take turns. A controlled vehicle approaching a zipper
link does not stop at its line while foes approach (as at any other link
without priority); it orders itself with the other stream by distance to
the merge point and falls in behind the foe just ahead of it in that order,
which it takes as a soft leader (braked for at ``max_deceleration`` at
most), as SUMO's drivers do (``MSLink``'s zipper speed)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from blendtrack.sumo.connection import SumoConnection
from blendtrack.sumo.geometry import _via_chain
from blendtrack.sumo.network import Network
from blendtrack.sumo.tracks import Active, Tracks

#: A controlled vehicle looks for foes once it is this close to the merge
#: point (m): at 31 m/s (a motorway's limit) 4 s, time to fall back behind a
#: foe at the planning deceleration of 4 m/s^2 from a speed difference of
#: up to 18 m/s (v^2 / 2b = 40 m, the rest is the gap).
ZIPPER_RANGE_M = 120.0
class Zippers:
    """Soft leaders for controlled vehicles approaching a zipper merge."""

    def __init__(self, conn: SumoConnection, network: Network, tracks: Tracks, active: dict[str, Active]) -> None:
        self.conn = conn
        self.network = network
        self.tracks = tracks
        #: The runner's controlled vehicles by id (read only here).
        self.active = active
        #: Zipper junction lane -> (its length, the foes' lanes: (lane id,
        #: distance from the lane's end to the merge point)); built lazily.
        self._zips: dict[str, tuple[float, list[tuple[str, float]]]] | None = None
        self.counts = {"zipper_steps": 0}

    def zipper_vias(self) -> dict[str, tuple[float, list[tuple[str, float]]]]:
        """Every zipper link's first junction lane, with the lanes its foes
        come along (see ``_zips``)."""
        if self._zips is None:
            self._zips = {}
            net = self.network.net()
            merges: dict[str, list[tuple[str, float, list[tuple[str, float]]]]] = {}
            for edge in net.getEdges():
                for lane in edge.getLanes():
                    for c in lane.getOutgoing():
                        if c.getState() != "Z" or not c.getViaLaneID():
                            continue
                        chain = _via_chain(net, c)
                        via, via_len = chain[0].getID(), sum(float(x.getLength()) for x in chain)
                        merges.setdefault(c.getToLane().getID(), []).append((via, via_len, self._upstream(lane, chain, via_len)))
            for streams in merges.values():
                for via, via_len, _ in streams:
                    foes = [lane for other, _, lanes in streams if other != via for lane in lanes]
                    self._zips[via] = (via_len, foes)
        return self._zips

    @staticmethod
    def _upstream(lane: Any, chain: Sequence[Any], via_len: float) -> list[tuple[str, float]]:
        """The lanes a foe comes along to the merge point through ``via``,
        each with the distance from its end to the merge point: the zipper
        link's junction lane and incoming lane, then back up lanes that lead
        nowhere else, up to ``ZIPPER_RANGE_M``."""
        out, rest = [], via_len
        for part in chain:
            rest -= float(part.getLength())
            out.append((part.getID(), rest))
        out.append((lane.getID(), via_len))
        dist = via_len + float(lane.getLength())
        while dist < ZIPPER_RANGE_M:
            # Lanes straight into this one (a junction lane, if any, else the lane before).
            incoming = lane.getIncoming()
            incoming = [x for x in incoming if x.getID().startswith(":")] or incoming
            if len(incoming) != 1 or len(incoming[0].getOutgoing()) != 1:
                break
            lane = incoming[0]
            out.append((lane.getID(), dist))
            dist += float(lane.getLength())
        return out

    def own_distance(self, act: Active) -> tuple[str, float] | None:
        """(zipper junction lane, distance of the front to its merge point
        in m) of a controlled vehicle near a zipper link, or None."""
        zips = self.zipper_vias()
        lane = self.conn.get_lane_id(act.vid)
        hit = zips.get(lane)
        if hit is not None:
            return lane, hit[0] - float(self.conn.get_lane_pos(act.vid))
        stop = self.tracks.fleet.next_stop(act.slot)
        if stop is None:
            return None
        via = self.tracks.lanes.name(stop[4])
        hit = zips.get(via)
        if hit is None:
            return None
        dist = stop[0] - self.tracks.fleet.s_front(act.slot) + hit[0]
        return (via, dist) if dist < ZIPPER_RANGE_M else None

    def leaders(self, order: list[Active]) -> list[tuple[str, tuple[str, float]]]:
        """This step's soft leaders at zipper merges: (controlled vehicle,
        (foe, gap in m as SUMO's leader gaps)), the foe the vehicle falls in
        behind: of the other streams' vehicles closer to the merge point, the
        nearest in that order."""
        if not order or not self.zipper_vias():
            return []
        v = self.conn.sumo.vehicle
        # Every controlled vehicle's distance by its own track: a controlled
        # foe is ordered by the same measure as the vehicle itself. Measured
        # by SUMO's lane position instead (half a metre off blendtrack's
        # front on Eccles), two controlled vehicles 0.2 m apart each found
        # the other closer and both waited for good.
        mine = {act.vid: self.own_distance(act) for act in order}
        out = []
        for act in order:
            near = mine[act.vid]
            if near is None:
                continue
            via, own = near
            best: tuple[str, float] | None = None
            for lane, offset in self._zips[via][1]:  # type: ignore[index]
                lane_len = float(self.network.net().getLane(lane).getLength())
                for other in self.conn.vehicles_on(lane):
                    theirs = mine.get(other)
                    dist = theirs[1] if theirs is not None else lane_len - float(v.getLanePosition(other)) + offset
                    # Closer to the merge point goes first, as SUMO's drivers
                    # order themselves (a margin for SUMO's foes, to be safe,
                    # had both sides of a level pair waiting for the other).
                    if dist >= own or (best is not None and dist <= best[1]):
                        continue
                    best = (other, dist)
            if best is not None:
                other, dist = best
                gap = max(own - dist - float(v.getLength(other)) - float(v.getMinGap(act.vid)), 0.0)
                out.append((act.vid, (other, gap)))
                self.counts["zipper_steps"] += 1
        return out
