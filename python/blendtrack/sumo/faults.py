"""Placement faults (issue 18): a controlled vehicle that SUMO has somewhere
else than blendtrack put it, or that is off its lane, is handed back to SUMO
and counted, never driven on silently.

After each SUMO step SUMO's front bumper point of every controlled vehicle
(``vehicle.getPosition``) is compared with where blendtrack's last step put
the front (``x_front_m``, ``y_front_m``: SUMO's own movement over its step
carries a speed-only or (lane, position) move there, an (x, y) move is that
point). Normally they differ by centimetres: a speed-only move lands within
``HOLD_SPEED_MPS * dt`` along the lane, a SUMO that lags is placed again once
0.5 m behind, and SUMO keeps a vehicle on its lane's centreline where
blendtrack's is off it by its lateral error (at most the lane's half width
without a fault). ``JUMP_M`` is far above all of that and far below what a
wrong lap (a lap's length) or another client's move would make.

A lateral error (of the control point, from the step's outputs) larger than
the width of the lane the vehicle is on is a fault too: the vehicle is then
off its lane, tracking a track it is not on.

So is a route index SUMO has for a vehicle that blendtrack placed (by lane
position or by (x, y)) other than the one of the edge blendtrack has it on:
SUMO would then drive it on as if on another lap (``moveToXY`` with
keepRoute matches the nearest lane along the whole route, and where a later
edge of the route passes close to the point, it can pick that one). Only
placed vehicles are asked: SUMO's own movement keeps the index right. Near a
lane's end the two may differ for a step: blendtrack's lane pieces meet
where its smoothed track (a Gaussian of 1.5 m) comes back to the lanes, a
few metres from SUMO's lane ends at a sharp turn (3.2 m measured at a
right-angle one), so any index of the pieces within ``ROUTE_INDEX_SLACK_M``
of the front agrees; another lap is a whole lap away.

A wrong route index is repaired first where SUMO allows (``repair``):
``moveTo`` onto the lane blendtrack has the vehicle on, which SUMO looks up
along the route from its (wrong) index on (then from the route's start).
From an index behind the right one that finds the next occurrence of the
edge; while that is still an earlier one, a ``moveTo`` onto the edge after
it and the lane again go one occurrence on. Only a vehicle still wrong after
that (SUMO ahead, where ``moveTo`` cannot go back) is a fault.
"""

from __future__ import annotations

import math
from itertools import compress
from typing import Any

import numpy as np

#: SUMO's front more than this from blendtrack's (m) is a jump.
JUMP_M = 5.0
#: How far (m) along the track the edge of SUMO's route index may be from
#: blendtrack's front (see the module docs).
ROUTE_INDEX_SLACK_M = 10.0


def repair(vehicle: Any, vid: str, lane: str, pos: float, index: int, ok: set[int]) -> bool:
    """Puts ``vid`` (``vehicle``: SUMO's vehicle domain) on ``lane`` at
    ``pos`` with SUMO's route index ``index`` (any of ``ok`` will do), with
    ``moveTo`` alone (see the module docs); True when SUMO's index is one of
    ``ok`` then."""
    route = vehicle.getRoute(vid)
    for _ in range(len(route)):
        vehicle.moveTo(vid, lane, pos)
        at = int(vehicle.getRouteIndex(vid))
        if at in ok:
            return True
        if at >= index or at + 1 >= len(route):
            return False
        # An earlier occurrence of the edge: one edge on, then look again.
        vehicle.moveTo(vid, f"{route[at + 1]}_0", 0.0)
    return False


class PlacementCheck:
    """Where blendtrack put each controlled vehicle's front last step, and
    the check of SUMO's against it."""

    def __init__(self, lane_names: list[str], network: Any) -> None:
        #: The interned lane names (``Tracks.lanes.names``, grows) and the
        #: ``Network`` (read once a width is asked for: SUMO checks it first).
        self._names = lane_names
        self._network = network
        self._widths = np.zeros(0)
        #: vid -> (x, y) of the front blendtrack put it at.
        self._front: dict[str, tuple[float, float]] = {}
        #: Vehicles found off their lane by last step's outputs.
        self._off_lane: list[str] = []
        #: Vehicles placed last step (by lane position or by (x, y)).
        self._placed: list[str] = []

    def lane_widths(self, lanes: np.ndarray) -> np.ndarray:
        """The widths (m) of the interned lanes ``lanes``."""
        if len(self._widths) < len(self._names):
            more = [self._width(name) for name in self._names[len(self._widths) :]]
            self._widths = np.concatenate([self._widths, np.array(more)])
        return self._widths[lanes]

    def _width(self, name: str) -> float:
        """A lane's width; +inf for a name that is no lane of the network
        (the empty lane of a vehicle SUMO has off the road)."""
        try:
            return float(self._network.net().getLane(name).getWidth())
        except (KeyError, ValueError):
            return math.inf

    def note(self, ids: list[str], out: dict[str, np.ndarray], usable: np.ndarray, placed: np.ndarray) -> None:
        """After a step: the fronts blendtrack put the vehicles ``ids`` at
        (``out``: ``RouteFleet.step``'s; ``usable``: the ones moved;
        ``placed``: the ones placed by lane position or (x, y)), and which
        of them are off their lane."""
        self._placed = [ids[i] for i in np.flatnonzero(placed).tolist()]
        moved = map(ids.__getitem__, np.flatnonzero(usable).tolist())
        self._front.update(zip(moved, zip(out["x_front_m"][usable].tolist(), out["y_front_m"][usable].tolist())))
        # Past the route's end the track has ended: the "lateral error" is
        # the distance past its last point, and SUMO is about to let it arrive.
        off = usable & ~out["past_route_end"] & (np.abs(out["lateral_error_m"]) > self.lane_widths(out["lane"]))
        self._off_lane = [ids[i] for i in np.flatnonzero(off).tolist()]

    def forget(self, vid: str) -> None:
        self._front.pop(vid, None)

    def faults(self, ids: list[str], vehicle: Any, route_indices: Any, get_position: Any = None) -> list[tuple[str, str]]:
        """(vehicle, what) of the vehicles ``ids`` with a placement fault now:
        SUMO has the front more than JUMP_M from blendtrack's, last step left
        it off its lane, or (for the ones placed) SUMO's route index is not
        one of ``route_indices(vid)``. ``vehicle``: SUMO's vehicle domain
        (``get_position``: its ``getPosition``, or a faster binding of it). A
        vehicle SUMO no longer knows is left to the caller's check for
        vanished ones."""
        found = [(vid, "off its lane") for vid in self._off_lane]
        self._off_lane = []
        for vid in self._placed:
            try:
                if int(vehicle.getRouteIndex(vid)) not in route_indices(vid):
                    found.append((vid, "route index"))
            except Exception:
                continue
        self._placed = []
        front = self._front
        if found:
            seen = {vid for vid, _ in found}
            checked = [vid for vid in ids if vid in front and vid not in seen]
        else:
            checked = list(filter(front.__contains__, ids))
        if not checked:
            return found
        get_position = vehicle.getPosition if get_position is None else get_position
        try:
            theirs = list(map(get_position, checked))
        except Exception:
            # One is gone (the caller's check for vanished ones finds it): the others one by one.
            theirs = []
            for vid in checked:
                try:
                    theirs.append(get_position(vid))
                except Exception:
                    theirs.append((front[vid][0], front[vid][1]))
        # math.dist(p, q) is math.hypot(px - qx, py - qy) to the bit (the
        # same C code), here without a Python step per vehicle. A NaN
        # distance is no jump (no comparison holds).
        far = map(JUMP_M.__lt__, map(math.dist, theirs, map(front.__getitem__, checked)))
        found.extend((vid, "jump") for vid in compress(checked, far))
        return found
