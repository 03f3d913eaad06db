"""Stops (SUMO's ``<stop>``) of controlled vehicles: at bus stops, container
stops, charging stations, parking areas and lane positions.

A controlled vehicle drives with speed mode 0, so SUMO's own driver no
longer brakes for its stops: left alone, SUMO halts it with an emergency
stop at the end of the stop's lane ("no connection to the next edge") and
serves the stop there, or, once blendtrack moves it on, aborts or skips it.
Here each controlled vehicle's next stop is a *halt* of the RouteFleet: a
standing obstacle on its track, braked for at the planning deceleration
like a red stop line, placed so that the front comes to rest at the stop's
end position (SUMO's convention for where a stopped vehicle's front is).

The dwell is SUMO's. SUMO starts a stop once the vehicle is on the stop's
lane, at or past the stop's start (a lane stop's start is 0.2 m before its
end unless given; a stopping place's is 0.5 m before the free end) and at
most 0.1 m/s; that holds for a vehicle on speed mode 0 whose speed blendtrack
sets (checked on SUMO 1.28: ``isStopped``, ``getStopState`` and the
stop-output agree), and SUMO then holds it at standstill whatever speed is
set, for ``duration``, until ``until``, or until its person or container
trigger is met, exactly as for its own drivers (a trigger that is never met
holds the vehicle for good, as in SUMO). While SUMO says the vehicle is
stopped the halt stays; once SUMO ends the stop the halt goes, the stop
counts as served, and the vehicle drives on to the next one. Where SUMO
starts the stop short of its end (behind another vehicle in a bus stop), the
halt moves to where the vehicle stands for the dwell.

A stop the vehicle cannot serve is skipped, counted with its reason, and
removed from SUMO's schedule (``replaceStop`` with an empty edge), so that
SUMO does not hold the vehicle for it at the end of a lane:

- ``off_track``: the stop's lane is not on the vehicle's track ahead and can
  no longer be reached. A stop on another lane of an edge of the route is
  reached the way SUMO's drivers reach it: from an earlier edge the vehicle
  is put on a track that needs the stop's lane there (``_take_lane``);
  once on the stop's edge on another lane it changes lanes towards it, one
  lane at a time, whenever the lane beside has room
  (``LaneChanges.try_tactical_change``; the change's track then holds the
  stop), until its front is within ``STOP_LANE_ROOM_M`` of the stop's end;
  then the stop is skipped (and so is one SUMO drops meanwhile);
- ``passed``: the front is already past the stop (taken over beyond it);
- ``not_started``: the vehicle stood at the halt for ``START_WAIT_STEPS``
  steps and SUMO did not start the stop.

SUMO 1.28 keeps a ``setSpeed`` of a vehicle that has stops ahead for one
step only: from the next step on its own model drives it again (from a
standstill at its own acceleration, past the speed limit under speed mode
0), while blendtrack's vehicle stands. The RouteFleet sends nothing for a
vehicle that keeps its speed (a standing one, ``Move.Hold``), relying on
SUMO keeping the last command, as it does for a vehicle without stops; so
for a vehicle with stops the speed is sent again every step.

A stop SUMO drops by itself (a teleport skips it) counts as ``sumo``.
A route that passes the stop's lane twice: the stop is placed at the first
pass at or after where the front is (SUMO's stop data carry no route index).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from blendtrack import RouteFleet
from blendtrack.sumo.connection import SumoConnection
from blendtrack.sumo.geometry import RouteGeometry
from blendtrack.sumo.network import Network
from blendtrack.sumo.tracks import Active, Interned

#: The halt is placed this far (m) before the stop's end position: the
#: stopping law's last creep carries the front 0.155 to 0.207 m past its
#: obstacle (measured in the traffic engine's tests, 3 to 19 m/s, control
#: steps 0.05 and 0.1 s), so the front rests within about 0.05 m of the end
#: position, well within SUMO's 0.2 m (lane stop) or 0.5 m (stopping place).
AIM_SHORT_M = 0.2
#: A halt is never placed closer than this (m) to the lane's end: a front
#: resting past it would be on the next lane, where SUMO does not stop it.
LANE_END_ROOM_M = 0.05
#: A stop whose end position is this far (m) or more behind the front when it
#: becomes the next one is passed.
PASSED_M = 1.0
#: Standing at the halt (front within ``AT_HALT_M`` of it, below
#: ``STANDING_MPS``) this many steps without SUMO starting the stop: skipped.
#: SUMO starts a stop in the step the vehicle comes within range at halting
#: speed, so a few steps are plenty.
START_WAIT_STEPS = 5
AT_HALT_M = 0.5
STANDING_MPS = 0.1
#: A vehicle on the edge of its next stop but on another lane changes
#: towards the stop's lane while its front is more than this (m) before the
#: stop's end (room for the change, 8 m at least, and to stop after it).
STOP_LANE_ROOM_M = 20.0


def stop_key(st: Any) -> tuple[str, float, str]:
    """What tells two of SUMO's stops apart: lane, end position, stopping place."""
    return (st.lane, round(float(st.endPos), 3), st.stoppingPlaceID)


def halt_position(end_pos: float, lane_length: float) -> float:
    """The lane position where the front halts for a stop ending at
    ``end_pos`` on a lane ``lane_length`` long: ``AIM_SHORT_M`` short of it,
    at least ``LANE_END_ROOM_M`` before the lane's end."""
    return min(end_pos, lane_length - LANE_END_ROOM_M) - AIM_SHORT_M


@dataclass
class _Pending:
    """A controlled vehicle's next stop, as far as blendtrack is concerned."""

    act: Active
    #: The stop the halt is for (``stop_key``), and the track it was placed on.
    key: tuple[str, float, str] | None = None
    geo: RouteGeometry | None = None
    #: SUMO has the vehicle stopped at it.
    dwelling: bool = False
    #: Steps stood at the halt without SUMO starting the stop.
    waited: int = 0
    #: The stop (SUMO's data) a lane change towards its lane was begun for:
    #: SUMO drops a vehicle's next stop when the vehicle is put onto the
    #: stop's lane from another (by ``moveToXY`` or ``moveTo``; SUMO 1.28
    #: warns "skips stop"), so it is given back (``_restore``).
    restore: Any = None
    #: The track built to take the next stop's lane (``_take_lane``), with
    #: that lane's edge and index, once built.
    preferred: Any = None
    #: The next stop is off the track but its lane can still be reached.
    reaching: bool = False


class Stops:
    """The stops of the controlled vehicles that have any."""

    def __init__(self, conn: SumoConnection, fleet: RouteFleet, network: Network, lanes: Interned,
                 lane_changes: Any = None) -> None:
        self.conn = conn
        self.fleet = fleet
        self.network = network
        #: The lane ids of the RouteFleet's tracks.
        self.lanes = lanes
        #: The runner's ``LaneChanges``: changes towards a stop's lane (None: none are made).
        self.lane_changes = lane_changes
        #: vid -> its next stop, for the vehicles with stops left.
        self.pending: dict[str, _Pending] = {}
        self.counts = {"stops_served": 0, "stops_skipped": 0, "stop_lane_changes": 0}
        #: SUMO's ``isStopped`` answers of this step (``dwelling`` asks
        #: before the placement check, ``update`` reuses them later in the
        #: same step: no SUMO step in between).
        self._stopped: dict[str, bool] = {}

    def take_over(self, act: Active) -> None:
        """``act`` was just taken over: it is followed if SUMO has stops for it."""
        if self.conn.sumo.vehicle.getStops(act.vid, 1):
            self.pending[act.vid] = _Pending(act)

    def drop(self, vid: str) -> None:
        self.pending.pop(vid, None)

    def dwelling(self) -> set[str]:
        """The vehicles SUMO has stopped at a stop now (asked of SUMO: the
        step just taken may have started the stop): during the dwell SUMO
        owns their place (a parking stop takes the vehicle off its lane), so
        the placement check leaves them alone."""
        is_stopped = self.conn.sumo.vehicle.isStopped
        self._stopped = {}

        def stopped(vid: str) -> bool:
            try:
                answer = self._stopped[vid] = bool(is_stopped(vid))
            except Exception:
                return False  # gone: the check for vanished vehicles sees to it
            return answer

        return {vid for vid, p in self.pending.items() if p.dwelling or stopped(vid)}

    def keep_speeds(self, ids: list[str], held: list[int], speeds: Any) -> None:
        """Sends again the speed of each vehicle with stops that the step
        moved without a SUMO call (indices ``held`` into ``ids``): SUMO keeps
        such a vehicle's speed command for one step only (see the module docs)."""
        pending, set_speed = self.pending, self.conn.set_speed
        for i in held:
            if ids[i] in pending:
                set_speed(ids[i], float(speeds[i]))

    def update(self) -> None:
        """Each vehicle's halt for this step, from SUMO's word on its stops:
        before ``RouteFleet.plan``, after every retrack of the step."""
        for vid, p in list(self.pending.items()):
            self._update(vid, p)
        self._stopped = {}

    def _update(self, vid: str, p: _Pending) -> None:
        v = self.conn.sumo.vehicle
        stopped = self._stopped.get(vid)
        if stopped is None:
            stopped = bool(v.isStopped(vid))
        if p.dwelling and not stopped:
            # SUMO ended the stop: served; on to the next one.
            p.act.record.stops_served += 1
            self.counts["stops_served"] += 1
            p.dwelling, p.key = False, None
            self._clear(p)
        if stopped:
            if not p.dwelling or math.isnan(self.fleet.halt(p.act.slot)):
                # SUMO starts a stop wherever the vehicle halts within its
                # range: behind another bus at a bus stop, short of the end.
                # The halt moves to where the front stands, so blendtrack's
                # vehicle stands there with SUMO's until the dwell ends. Left
                # at the stop's end (or cleared by a retrack), it drove on
                # toward the end once the bus ahead had left while SUMO held
                # the bus, and the car behind, which judged its gap from
                # blendtrack's place, ran into the bus (Bologna, seed 2).
                self.fleet.set_halt(p.act.slot, self.fleet.s_front(p.act.slot) - AIM_SHORT_M)
                p.dwelling = True
            return
        nxt = v.getStops(vid, 1)
        if p.restore is not None and (not nxt or stop_key(nxt[0]) != stop_key(p.restore)):
            nxt = self._restore(vid, p)
        if not nxt:
            self._clear(p)
            del self.pending[vid]
            return
        st = nxt[0]
        key = stop_key(st)
        if p.key is not None and key != p.key:
            # SUMO dropped the stop blendtrack was halting for (a teleport
            # skips it), or the one whose lane it was still making for.
            self._skipped(p, "off_track" if p.reaching else "sumo")
        # A new stop, or a new track (a retrack clears the halt: a lane
        # change, a reroute): the halt is placed (again).
        if key != p.key or p.geo is not p.act.geo or math.isnan(self.fleet.halt(p.act.slot)):
            self._place(vid, p, st, key)
        elif p.key is not None:
            self._check_started(vid, p)

    def _place(self, vid: str, p: _Pending, st: Any, key: tuple[str, float, str]) -> None:
        """The halt for SUMO's next stop ``st`` on the vehicle's present track."""
        slot = p.act.slot
        sf = self.fleet.s_front(slot)
        pos = halt_position(float(st.endPos), self.network.lane_length(st.lane))
        # On the first piece of the stop's lane covering the position, ahead
        # of the front (a lane the track drives twice: the next time).
        lane = self.lanes.get(st.lane, -1)
        s = self.fleet.arc_at_lane_position(slot, lane, pos, sf - PASSED_M)
        if s is None:
            # Off the track ahead, or behind the front.
            behind = self.fleet.arc_at_lane_position(slot, lane, pos, -math.inf)
            if behind is None and self._towards_lane(vid, p, st):
                # Still reachable: followed, so that SUMO dropping it (the
                # vehicle went past on another lane) counts.
                p.key, p.geo, p.reaching = key, p.act.geo, True
                return
            self._skip(vid, p, "passed" if behind is not None else "off_track")
            return
        self.fleet.set_halt(slot, s)
        p.key, p.geo, p.waited, p.reaching = key, p.act.geo, 0, False

    def _restore(self, vid: str, p: _Pending) -> Any:
        """Gives SUMO back the stop ``p.restore`` as the vehicle's next one;
        its stops as SUMO then has them (none when SUMO refuses: the stop
        counts as skipped by SUMO)."""
        st, p.restore = p.restore, None
        v = self.conn.sumo.vehicle
        edge, _, index = str(st.lane).rpartition("_")
        target = st.stoppingPlaceID or edge
        try:
            v.insertStop(vid, 0, target, float(st.endPos), int(index), float(st.duration), int(st.stopFlags),
                         float(st.startPos), float(st.until))
            return v.getStops(vid, 1)
        except Exception:
            self._skipped(p, "sumo")
            return v.getStops(vid, 1)

    def _towards_lane(self, vid: str, p: _Pending, st: Any) -> bool:
        """For a stop on another lane of an edge of the route ahead: a
        change one lane towards it when the vehicle is on that edge (and the
        lane beside has room); True while the stop's lane can still be
        reached (see the module docs)."""
        edge, _, index = str(st.lane).rpartition("_")
        if self.lane_changes is None or edge.startswith(":") or not index.isdigit():
            return False
        v = self.conn.sumo.vehicle
        try:
            road = v.getRoadID(vid)
            at = max(int(v.getRouteIndex(vid)), 0)
            if edge not in tuple(v.getRoute(vid))[at:]:
                return False
            if road != edge:
                # Not on the stop's edge yet: a track that enters it on the stop's lane.
                self._take_lane(p, edge, int(index))
                return True
            pos, current = float(v.getLanePosition(vid)), int(v.getLaneIndex(vid))
        except Exception:
            return False
        want = int(index)
        if current == want or pos > float(st.endPos) - STOP_LANE_ROOM_M:
            return False
        if p.act.changing is None and self.lane_changes.try_tactical_change(p.act, 1 if want > current else -1, for_stop=True):
            self.counts["stop_lane_changes"] += 1
            p.restore = st
        return True

    def _take_lane(self, p: _Pending, edge: str, want: int) -> None:
        """Puts ``p``'s vehicle on the track of its route from the lane it is
        on that needs lane ``want`` of ``edge`` (``Tracks.onto_shared_track``
        with the stop's lane, once blendtrack has its front ``SHARE_AFTER_M``
        into a normal lane of an earlier edge of its track); built once per
        track the vehicle is on."""
        act = p.act
        if self.lane_changes is None or act.changing is not None or act.own_track is not None:
            return
        if p.preferred is not None and p.preferred[0] is act.geo and p.preferred[1:] == (edge, want):
            return
        geo = self.lane_changes.tracks.onto_shared_track(act, 0, (edge, want))
        if geo is not None:
            p.preferred = (geo, edge, want)

    def _check_started(self, vid: str, p: _Pending) -> None:
        """A vehicle standing at its halt that SUMO does not stop is let go."""
        slot = p.act.slot
        halt = self.fleet.halt(slot)
        v = self.fleet.state(slot)[3]
        if abs(v) < STANDING_MPS and abs(self.fleet.s_front(slot) - halt) < AT_HALT_M:
            p.waited += 1
            if p.waited >= START_WAIT_STEPS:
                self._skip(vid, p, "not_started")
        else:
            p.waited = 0

    def _skip(self, vid: str, p: _Pending, reason: str) -> None:
        """Skips SUMO's next stop of ``vid``: counted, removed from SUMO's schedule."""
        self._skipped(p, reason)
        self._clear(p)
        p.key, p.reaching = None, False
        try:
            self.conn.sumo.vehicle.replaceStop(vid, 0, "")
        except Exception:
            # SUMO refused (the stop is already gone): nothing of it left to hold the vehicle.
            pass

    def _skipped(self, p: _Pending, reason: str) -> None:
        rec = p.act.record
        rec.stops_skipped += 1
        rec.stop_skip_reasons = f"{rec.stop_skip_reasons};{reason}" if rec.stop_skip_reasons else reason
        self.counts["stops_skipped"] += 1

    def _clear(self, p: _Pending) -> None:
        self.fleet.set_halt(p.act.slot, math.nan)
        p.geo = None
