"""Collisions SUMO does not look for: along a lane, with a vehicle moved by
``moveToXY`` in the last 10 s, under ``collision.action teleport``.

SUMO's lane collision check (``MSLane::detectCollisionBetween``) returns
at once, under ``collision.action teleport`` (SUMO's default), when either
vehicle is *remote affected*: moved by ``moveToXY`` within the last 10 s
of simulated time. blendtrack moves controlled vehicles that way inside
junctions, mid lane change and off their lane's centreline, so under that
action a rear-end collision with such a vehicle would never reach SUMO's
collision output, nor ``collisions_all``. (Measured with SUMO 1.28 on the
shipped ring: a vehicle put onto its leader with ``moveToXY`` every step
is reported at once under ``warn``, and only 10.1 s after the last
``moveToXY`` under ``teleport``; ``tests/test_collisions.py``.) SUMO's
junction check (shapes overlapping inside a junction, with
``--collision.check-junctions``) has no such exemption.

So, under ``teleport`` only, blendtrack checks every vehicle it moved by
(x, y) within the window itself, after each SUMO step, by SUMO's own rule:
the follower's front within ``collision.mingap-factor`` x its ``minGap``
of the leader's back (``getLeader`` and ``getFollower`` give that gap,
minus the whole ``minGap``), where SUMO would compare the two: on the
same lane, or the leader's back hanging onto the follower's lane (past
the junction lanes between, where its front is beyond them). A pair
SUMO reported itself in the same step is not counted twice, and a pair
stays one collision while it stays too close (SUMO would have teleported
the collider; blendtrack cannot, and counts the overlap once). What the
check cannot see: the instant of SUMO's own check (after the vehicles'
moves, before a ``moveToXY`` lands; blendtrack looks after the whole
step), and collisions under other actions, which SUMO checks in full.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

#: SUMO's window of remote influence (``MSVehicle::Influencer::isRemoteAffected``), s.
REMOTE_WINDOW_S = 10.0
#: SUMO's NUMERICAL_EPS: a gap must be below minus this to count.
NUMERICAL_EPS = 0.001
#: SUMO's default fraction of minGap below which vehicles have collided
#: (``collision.mingap-factor`` -1 leaves it to the car-following model,
#: whose default is 1).
DEFAULT_MINGAP_FACTOR = 1.0


class RemoteCollisions:
    """The lane collisions SUMO skips for vehicles moved by (x, y) (see the
    module docs). ``active`` is False under every action but ``teleport``:
    then SUMO checks every pair itself and this does nothing."""

    def __init__(self, vehicle: Any, action: str, mingap_factor: float, lane: Any = None,
                 ways_from: Callable[[str, str], frozenset[str]] | None = None,
                 through: Callable[[str, str], float | None] | None = None) -> None:
        self.vehicle = vehicle
        #: ``Network.through_length``, for ``_same_way``.
        self.through = through
        #: SUMO's lane domain (the links out of a lane), for ``_same_way``.
        self.lane = lane
        #: ``Network.ways_from``, for ``_came_by``.
        self.ways_from = ways_from
        self._next: dict[str, frozenset[str]] = {}
        self.active = action == "teleport"
        self.factor = DEFAULT_MINGAP_FACTOR if mingap_factor < 0 else mingap_factor
        #: vehicle -> simulated time of its last moveToXY.
        self._moved: dict[str, float] = {}
        #: The (collider, victim) pairs too close at the last check.
        self._touching: set[tuple[str, str]] = set()
        self._min_gap: dict[str, float] = {}

    def moved_xy(self, vid: str, t: float) -> None:
        """``vid`` was moved by (x, y) at simulated time ``t``."""
        if self.active:
            self._moved[vid] = t

    def forget(self, vid: str) -> None:
        """``vid`` left the simulation (arrived, or starts a teleport)."""
        self._moved.pop(vid, None)
        self._min_gap.pop(vid, None)

    def check(self, t: float, reported: set[tuple[str, str]]) -> list[tuple[str, str, str]]:
        """New collisions at simulated time ``t`` (after SUMO's step): (collider,
        victim, lane) of each pair with a vehicle moved by (x, y) within
        ``REMOTE_WINDOW_S`` (one step of slack) that is closer than SUMO
        allows, not in ``reported`` (SUMO's own this step) and not too close
        at the last check already."""
        if not self._moved:
            self._touching = set()
            return []
        # One step of slack: a pair SUMO checks again is in ``reported``.
        horizon = t - REMOTE_WINDOW_S - 1.0
        veh = self.vehicle
        touching: set[tuple[str, str]] = set()
        found: list[tuple[str, str, str]] = []
        for vid in [v for v, when in self._moved.items() if when < horizon]:
            del self._moved[vid]
        for vid in self._moved:
            try:
                ahead = veh.getLeader(vid, 0.0)
                behind = veh.getFollower(vid, 0.0)
            except Exception:
                continue  # gone (or teleporting): nothing on a lane to check
            for collider, victim, gap in ((vid, ahead[0] if ahead else "", ahead[1] if ahead else 0.0), (behind[0], vid, behind[1])):
                if not collider or not victim:
                    continue
                # getLeader's gap is the leader's back minus the follower's
                # front minus the follower's whole minGap (all of it counts
                # at SUMO's default factor of 1).
                slack = 0.0 if self.factor == 1.0 else (1.0 - self.factor) * self._gap_of(collider)
                if gap + slack >= -NUMERICAL_EPS:
                    continue
                pair = (collider, victim)
                if pair in touching:
                    continue
                lane = self._same_way(collider, victim)
                if lane is None:
                    continue
                touching.add(pair)
                if pair in self._touching or pair in reported:
                    continue
                found.append((collider, victim, lane))
        self._touching = touching
        return found

    def _same_way(self, collider: str, victim: str) -> str | None:
        """The collider's lane if SUMO's lane check would compare the two
        there: both on that lane, or the victim's back on it (the victim's
        front on a lane that lane leads to, directly or through a junction
        lane, on its way from the edge before: ``_came_by``); None
        otherwise (``getLeader`` and ``getFollower`` also report vehicles on
        lanes that merge further on, which SUMO's lane check does not
        compare)."""
        veh = self.vehicle
        try:
            a, b = str(veh.getLaneID(collider)), str(veh.getLaneID(victim))
            if not a or not b:
                return None  # off the network: on no lane
            if a == b:
                return a
            back = float(veh.getLanePosition(victim)) - float(veh.getLength(victim))
            if back >= 0.0:
                return None  # its back is on its own lane only
            nxt = self._next.get(a)
            if nxt is None:
                links = self.lane.getLinks(a) if self.lane is not None else ()
                nxt = self._next[a] = frozenset(x for link in links for x in (str(link[0]), str(link[4])) if x)
            if b not in nxt or not self._came_by(victim, a, b):
                return None
            if self.through is not None and not b.startswith(":"):
                # Front on the lane after the junction: the back reaches
                # the collider's lane only past the junction lanes between.
                # Hanging back onto those alone it was counted with a car
                # on the lane before that went the other way of a fan-out,
                # 1.5 m short of it (SUMO's fokr_bs_demo, 54291 s; SUMO's
                # own check, under warn, reported nothing).
                inside = self.through(a, b)
                if inside is not None and back >= -inside:
                    return None
        except Exception:
            return None
        return a

    def _came_by(self, victim: str, a: str, b: str) -> bool:
        """Can the back of ``victim``, whose front is on lane ``b``, hang
        onto lane ``a``? Onto a normal lane ``b`` several ways can lead (a
        merge): only the victim's way from the edge before on its route
        counts (``ways_from``: that edge's lanes with a connection to
        ``b`` and the connections' junction lanes). At Bologna's 42 a
        controlled car standing on junction lane :42_2_0, 5 m before it
        merges with :42_0_0, was counted in a collision with a car that had
        come through :42_0_0 and was on the lane after with its back still
        on :42_0_0: SUMO's own check (the same run under ``collision.action
        warn``) reported nothing. True where the way is not known."""
        if b.startswith(":") or self.ways_from is None:
            return True  # a junction lane has one lane into it
        route = self.vehicle.getRoute(victim)
        k = int(self.vehicle.getRouteIndex(victim))
        if not 0 < k < len(route) or b.rpartition("_")[0] != route[k]:
            return True
        ways = self.ways_from(route[k - 1], b)
        return not ways or a in ways

    def _gap_of(self, vid: str) -> float:
        hit = self._min_gap.get(vid)
        if hit is None:
            try:
                hit = float(self.vehicle.getMinGap(vid))
            except Exception:
                hit = 0.0
            self._min_gap[vid] = hit
        return hit
