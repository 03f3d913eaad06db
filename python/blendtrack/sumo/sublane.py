"""Leaders under SUMO's sublane model (``--lateral-resolution``).

With the sublane model SUMO's drivers keep a lateral position inside their
lane and change lanes gradually, so a vehicle on the lane beside can reach
well into a controlled vehicle's lane. ``vehicle.getLeader`` looks along
the vehicle's own lanes only and does not see it, nor does
``getNeighbors`` once a vehicle alongside on that lane hides it: at Eccles
(30 %, ``--lateral-resolution 0.8``) a driver on lane 2 held 1.5 m towards
lane 1 while slowing to 1.6 m/s, and the controlled car on lane 1 behind it
ran into its back (seed 0, 414 s, ``latGap -0.06``); a driver moving over
from lane 0 stopped half across, and the controlled car coming out of the
junction behind ran into it (seed 7, 573 s).

So each step the vehicles off their lane's centre (by more than
``OFF_CENTRE_M``) are listed once, with their front, back and width, and
each controlled vehicle takes as a leader the nearest of them ahead on
another lane whose body comes within ``LATERAL_MARGIN_M`` of its own
sideways, measured along its heading in the plane (within
``RANGE_M``): the gap is from its front plus its minGap to that body's
back, as ``getLeader`` gives it. Without the sublane model nothing here
runs.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

#: A vehicle this far (m) or more from its lane's centre is checked.
OFF_CENTRE_M = 0.2
#: Sideways clearance (m) below which a body ahead counts as in the way.
LATERAL_MARGIN_M = 0.2
#: How far ahead (m, straight along the heading) bodies are looked for.
RANGE_M = 50.0


class SublaneLeaders:
    """The leaders ``getLeader`` misses under the sublane model (see the
    module docs); ``active`` is False without it."""

    def __init__(self, vehicle: Any, lateral_resolution: float) -> None:
        self.vehicle = vehicle
        self.active = lateral_resolution > 0.0
        self._size: dict[str, tuple[float, float]] = {}
        self._ids: list[str] = []
        self._lanes: list[str] = []
        #: Per listed vehicle: front x, y, back x, y, half width.
        self._bodies = np.zeros((0, 5))

    def _dims(self, vid: str) -> tuple[float, float]:
        """(length, width) of ``vid``, read once."""
        d = self._size.get(vid)
        if d is None:
            d = self._size[vid] = (float(self.vehicle.getLength(vid)), float(self.vehicle.getWidth(vid)))
        return d

    def forget(self, vid: str) -> None:
        self._size.pop(vid, None)

    def new_step(self) -> None:
        """Lists the vehicles off their lane's centre now."""
        veh = self.vehicle
        ids = list(veh.getIDList())
        lats = list(map(veh.getLateralLanePosition, ids))
        off = [vid for vid, lat in zip(ids, lats) if abs(float(lat)) >= OFF_CENTRE_M]
        rows = []
        for vid in off:
            x, y = veh.getPosition(vid)
            a = math.radians(float(veh.getAngle(vid)))  # SUMO: clockwise from north
            length, width = self._dims(vid)
            rows.append((x, y, x - length * math.sin(a), y - length * math.cos(a), 0.5 * width))
        self._ids = off
        self._lanes = [str(veh.getLaneID(vid)) for vid in off]
        self._bodies = np.array(rows, dtype=float).reshape(-1, 5)

    def nearest(self, vid: str, lead: Any) -> Any:
        """``lead`` (``getLeader``'s answer for ``vid`` after blendtrack's own
        corrections, None for none) or the nearest listed body ahead on
        another lane that reaches into ``vid``'s way, if its gap is
        smaller."""
        if not self._ids:
            return lead
        veh = self.vehicle
        x, y = veh.getPosition(vid)
        a = math.radians(float(veh.getAngle(vid)))
        ux, uy = math.sin(a), math.cos(a)
        b = self._bodies
        # Along the heading and sideways (left positive) of front and back.
        fx, fy, bx, by = b[:, 0] - x, b[:, 1] - y, b[:, 2] - x, b[:, 3] - y
        lon_back = bx * ux + by * uy
        lon_front = fx * ux + fy * uy
        side_f = ux * fy - uy * fx
        side_b = ux * by - uy * bx
        half = 0.5 * self._dims(vid)[1]
        reach = half + b[:, 4] + LATERAL_MARGIN_M
        inside = (np.minimum(side_f, side_b) < reach) & (np.maximum(side_f, side_b) > -reach)
        ahead = (lon_back > 0.0) & (lon_front < RANGE_M)
        hits = np.flatnonzero(inside & ahead)
        if not len(hits):
            return lead
        own_lane = str(veh.getLaneID(vid))
        min_gap = float(veh.getMinGap(vid))
        best, best_gap = lead, (float(lead[1]) if lead else math.inf)
        for k in hits.tolist():
            other = self._ids[k]
            if other == vid or self._lanes[k] == own_lane:
                continue  # getLeader's own
            gap = float(lon_back[k]) - min_gap
            if gap < best_gap:
                best, best_gap = (other, gap), gap
        return best
