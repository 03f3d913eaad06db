"""Junctions: which controlled vehicles must yield at the stop line ahead
(links without priority with foes approaching, an internal waiting point
with a foe in the way, a vehicle inside the junction in the path), and the
traffic lights' states passed on to the RouteFleet."""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np

from blendtrack import RouteFleet
from blendtrack.sumo.connection import SumoConnection
from blendtrack.sumo.geometry import body_segment, path_ahead, segments_distance
from blendtrack.sumo.lights import SignalAhead
from blendtrack.sumo.network import Network, edge_of
from blendtrack.sumo.tracks import Tracks

# How far before a junction without priority a vehicle asks SUMO whether foes approach (m).
YIELD_LOOKAHEAD_M = 30.0
# At an internal junction (the waiting point of a turn across oncoming lanes)
# a vehicle waits while a foe is this many seconds or metres from its stop line.
INTERNAL_YIELD_S = 4.0
INTERNAL_YIELD_NEAR_M = 5.0
# A foe at a yellow light is taken to come through unless it can stop
# braking at YELLOW_RUN_DECEL_MPS2 after YELLOW_RUN_REACTION_S seconds.
YELLOW_RUN_REACTION_S = 1.0
YELLOW_RUN_DECEL_MPS2 = 3.0
#: Where a vehicle stops short of a waiting point it must stop at (m).
STOP_MARGIN_M = 1.0
#: A vehicle whose front is past its internal waiting point by less than
#: this (m), and that could stop within it, is still asked whether to wait:
#: the Rust plan keeps a stop until the front is 0.5 m past it.
STOP_PASSED_M = 0.5
#: Share of the planning deceleration a turner should need to stop at its
#: internal waiting point once past the entry line.
ENTRY_SLOW_DECEL = 0.5
#: At a link without priority a vehicle waits while a prohibiting foe would
#: reach the junction before it has crossed it plus this margin (s).
CROSS_MARGIN_S = 1.0
#: Room (m) between a vehicle crossing a foe's way and the foe at the point
#: where the ways cross: about half a lane's width plus a margin.
CONFLICT_CLEAR_M = 2.5
#: A foe lane into a junction shorter than this (m) is not all a vehicle
#: at a link without priority looks along: foes on the lanes before it,
#: through the junction before, are looked for too (``Network.feeders``).
#: Bologna's junction 20b: the major road comes in on 77ab, 0.74 m long,
#: right after another junction; a foe at 12.4 m/s on the lane before it,
#: 2 m from its end, was not seen, and a controlled car turning right from
#: 56b went into the merge and met it (seeds 4, 10, 21 and 26).
FEEDER_LANE_M = 30.0
#: How far ahead along their tracks controlled vehicles are looked for as
#: foes approaching a link (``Junctions.approaching_on_tracks``).
APPROACH_LOOK_M = 100.0
#: A vehicle counts as standing below this speed (m/s; SUMO's own halting
#: threshold): at a stop sign or an all-way stop it has halted when it stood...
HALT_SPEED_MPS = 0.1
#: ... with its front within this of its stop line (m; it stops
#: ``standstill_margin_m``, 1 m, short of it).
HALT_NEAR_M = 3.0
#: A vehicle that entered a junction from the same lane and is still in the
#: way of one about to enter is followed, not waited for, only while it
#: moves at this speed or more (m/s) and at least as fast as the one behind:
#: it then leaves the way ahead of it. Slower, it is waited for. (SUMO's
#: halting speed alone, 0.1 m/s, let a vehicle crawling at 0.4-0.5 m/s on
#: the other branch of a lane that fans out be run into: Bologna, 56m.)
FOLLOW_MIN_SPEED_MPS = 2.0
#: A controlled vehicle this close (m) to the point where its way through a
#: junction merges with others (the end of its junction lanes) looks for
#: vehicles on the merging ways (``leader_at_merge``).
MERGE_LOOKAHEAD_M = 30.0
#: A vehicle SUMO drives on a merging way is followed also when it is up to
#: this much (m) farther from the merge point than the controlled vehicle:
#: SUMO's drivers from a minor road do not wait for a controlled vehicle
#: that stands at or near the merge (Bologna, junction 39a: both stood, the
#: SUMO driver 7.2 m from the merge point, the controlled vehicle about 6 m,
#: both went).
MERGE_DEFER_M = 3.0
#: A vehicle inside a junction is in the way of one about to enter when its
#: body comes within this much of the half width of the entering vehicle's
#: path through the junction (m).
INSIDE_MARGIN_M = 0.3
#: The half width (m) of the car taken to stand at an internal waiting point
#: (``Junctions.junction_blocked``).
WAITING_HALF_WIDTH_M = 0.9
#: Impatience (SUMO's junction model, ``MSLink::blockedByFoe``): a vehicle
#: that has waited takes an approaching foe that could still stop for it as
#: arriving its impatience (SUMO's ``vehicle.getImpatience``: the vType's
#: impatience plus the waiting time over ``--time-to-impatience``, 180 s by
#: default, at most 1) times this many seconds later (SUMO's
#: ``arrivalTimeBraking`` of a foe that can stop). A foe that could not stop
#: counts as it comes, however long the wait.
IMPATIENT_DELAY_S = 30.0


#: A ``leader_at_merge`` memo's mark for a lane not looked up yet (None
#: there is a value: no merge ahead of that lane on that track).
NOT_LOOKED_UP = object()


def _track_lane_beside(lane: str, track_lanes: list[str]) -> str:
    """The track's junction lane on the junction edge of ``lane`` (SUMO's,
    beside the track's: ``moveToXY`` or its driver's choice of lane at the
    entry can put a vehicle there), or ``lane`` when the track has none."""
    edge = edge_of(lane)
    return next((x for x in track_lanes if x.startswith(":") and edge_of(x) == edge), lane)


def lacks_priority(link: Any) -> bool:
    """SUMO's word on a link of ``getNextLinks`` (lane, has priority, is
    open, has foe, via, ...): no priority, and a foe approaching."""
    return (not link[1]) and bool(link[3])


#: Lanes out shorter than this are not judged by the keep-clear rule: a
#: short lane between two close junctions holds a queue as long as a car.
EXIT_MIN_LANE_M = 20.0


class Junctions:
    """Yield answers for ``RouteFleet.plan_sumo``'s questions, and the lights' states."""

    def __init__(self, conn: SumoConnection, network: Network, tracks: Tracks, fleet: RouteFleet, plan_decel: float,
                 plan_accel: float = 1.0, controlled: Any = None) -> None:
        self.conn = conn
        self.network = network
        self.tracks = tracks
        self.fleet = fleet
        #: The deceleration (m/s^2, > 0) a vehicle plans to stop with.
        self.plan_decel = plan_decel
        #: The acceleration (m/s^2, > 0) a vehicle crosses a junction with.
        self.plan_accel = max(plan_accel, 0.1)
        #: Per vehicle: the junction lane of the stop sign (or all-way stop)
        #: it has halted at.
        self.halted: dict[str, str] = {}
        #: Each traffic light's last state (as SUMO's state string).
        self.tls_state: dict[str, str] = {}
        #: Each light's state for the coming step as last passed to the RouteFleet.
        self.tls_coming: dict[str, str] = {}
        #: The lights' coming states (made once SUMO runs).
        self.ahead: SignalAhead | None = None
        #: Can a light have been switched since SUMO's step (a step hook,
        #: another TraCI client)? Then ``refresh_tls`` reads each anew.
        self.lights_anew = True
        self.counts = {"inside_junction_waits": 0, "waiting_point_waits": 0, "keep_clear_waits": 0, "entered_across_waits": 0}
        #: The controlled vehicles told to wait at their line last step, and
        #: this step's so far (``new_step`` moves them over).
        self.waiting: set[str] = set()
        self._waiting_now: set[str] = set()
        #: The controlled vehicles told this step that they may go.
        self._going_now: set[str] = set()
        #: A controlled vehicle held at its line -> the turner that went
        #: counting on it staying there, the edge the turner was on then and
        #: the prefix of that junction's lane ids (``internal_junction_busy``;
        #: kept while the turner is on that edge or in that junction, see
        #: ``must_yield``).
        self.holds: dict[str, tuple[str, str, str]] = {}
        #: The controlled vehicles (the runner's dict of them, by id).
        self.controlled: Any = {} if controlled is None else controlled
        #: Per vehicle that went impatient: the junction lane it goes
        #: through and the impatience it went with (``_Patience``).
        self.went: dict[str, tuple[str, float]] = {}
        #: Junction lane -> its ``Network.prohibitors``, each with its
        #: ``Network.conflict`` (where the two ways cross) appended.
        self._prohibitors: dict[str, list[tuple[str, str | None, float, str, int, float, float]]] = {}
        self._approaching: dict[str, list[tuple[str, float]]] | None = None
        #: (merge target, own junction lane) -> ``_merging_lanes``.
        self._merging: dict[tuple[str, str], list[tuple[str, float, float, bool]]] = {}

    def new_step(self) -> None:
        """This step's yield answers begin: last step's waiters are known."""
        self.waiting, self._waiting_now = self._waiting_now, set()
        self._going_now = set()
        self._approaching = None

    def refresh_tls(self, t: float) -> None:
        """Reads the lights' states after SUMO's step to ``t`` (``tls_state``)
        and passes each light's state for the coming step, as
        :class:`~blendtrack.sumo.lights.SignalAhead` gives it, to the
        RouteFleet where it changed.

        With ``lights_anew`` each light's state is read anew (a microsecond
        each with libsumo): the subscription's value is the one of the
        simulation step, and a light another client switched since (a step
        hook of this process, which runs after the step, or another TraCI
        client) would be seen a step late. Both backends read it so then,
        so that they drive alike. Without (libsumo and no step hook:
        nothing can have switched a light since the step) the
        subscription's value is the state now, and is taken as it is;
        where the lights are not subscribed to (``SumoConnection.subscribe_lights``)
        each is read, which gives the same state."""
        if not self.conn.light_subscriptions:
            get_state = self.conn.light_state
            states: Any = ((tls, get_state(tls)) for tls in self.conn.lights)
        else:
            tl = self.conn.sumo.trafficlight
            results = tl.getAllSubscriptionResults()
            key = self.conn.tc.TL_RED_YELLOW_GREEN_STATE
            anew = self.lights_anew
            states = ((tls, tl.getRedYellowGreenState(tls) if anew else results[tls][key]) for tls in results)
        if self.ahead is None:
            self.ahead = SignalAhead(self.conn.sumo.trafficlight)
        light = self.tracks.lights.id
        set_signal, coming, known, sent = self.fleet.set_signal, self.ahead.coming, self.tls_state, self.tls_coming
        for tls, state in states:
            known[tls] = state
            ahead = coming(tls, state, t)
            if sent.get(tls) != ahead:
                sent[tls] = ahead
                set_signal(light(tls), ahead)

    def must_yield(self, vid: str, slot: int) -> bool:
        """SUMO's view of the link ahead: does it lack priority with foes
        approaching? (The vehicles told so are noted: ``waiting``.)"""
        wait = self._must_yield(vid, slot)
        if not wait and vid in self.holds:
            wait = self._held_for_turner(vid, slot)
        if wait:
            self._waiting_now.add(vid)
        else:
            self._going_now.add(vid)
        return wait

    def _held_for_turner(self, vid: str, slot: int) -> bool:
        """``vid``, standing at its line, was counted on by a turner that went
        from its internal waiting point (``holds``): it stays at its line
        into that junction while that turner is still on its way, on the
        edge it went from or inside that junction, and not told to wait
        since. Released in the same step,
        it had driven into the turner's way: on the shipped grid a left
        turner went because the oncoming vehicle was held, and the oncoming
        vehicle was let go in that very step (junction D1, a collision
        2.6 s later when it pulled away at 2.6 m/s^2)."""
        turner, edge, junction = self.holds[vid]
        stop = self.fleet.next_stop(slot)
        if stop is not None and stop[0] >= self.fleet.s_front(slot) and turner in self.controlled \
                and turner not in self.waiting and turner not in self._waiting_now \
                and self.tracks.lanes.name(stop[4]).startswith(junction):
            try:
                road = str(self.conn.sumo.vehicle.getRoadID(turner))
            except self.conn.errors:
                road = ""
            if road.startswith(junction) or road == edge:
                return True
        del self.holds[vid]
        return False

    def _must_yield(self, vid: str, slot: int) -> bool:
        stop = self.fleet.next_stop(slot)
        if stop is None:
            return False
        via = self.tracks.lanes.name(stop[4])
        past = self.fleet.s_front(slot) - stop[0]
        if past > 0.0 and (past >= STOP_PASSED_M or via not in self.network.internal_vias
                           or self.conn.get_speed(vid) ** 2 > 2.0 * self.plan_decel * (STOP_PASSED_M - past)):
            # Its front is past the line (a step of 1 s can carry it there
            # while the way was clear): it is in, and clears the junction.
            # Told to wait it stood there, in the crossing road's way. Just
            # over an internal waiting point and able to stop within
            # STOP_PASSED_M of it, it is still asked (the Rust plan keeps
            # the stop until then): braking for it, a left turner on the
            # grid stopped 4 cm past it, went on as if in, and met the
            # oncoming vehicle. (Not at a junction's entry: a vehicle
            # crossing a stream as SUMO's impatient drivers do, asked again
            # just over its line, stood there.)
            self.went.pop(vid, None)
            return False
        if self.network.is_zipper(via):
            # Taken in turns, not waited at: the order comes from ``Zippers``
            # as a soft leader (a zipper link without a light is listed
            # among the internal waiting points too: link index -1).
            return self.junction_blocked(vid, via)
        if via in self.network.internal_vias:
            if self.internal_junction_busy(vid, via, gap=max(stop[0] - self.fleet.s_front(slot), 0.0)):
                return True
        else:
            state = self.network.link_state(via)
            if state in "sw" and state and self.halted.get(vid) != via:
                # A stop sign or an all-way stop: stand at the line first.
                gap = stop[0] - self.fleet.s_front(slot)
                if gap > HALT_NEAR_M or float(self.conn.sumo.vehicle.getSpeed(vid)) >= HALT_SPEED_MPS:
                    return True
                self.halted[vid] = via
            if state == "w":
                # All-way stop: once halted, first come first served.
                if self.allway_busy(vid, via):
                    return True
            elif state and state not in "MGOZ" and self.link_busy(vid, slot, via, stop[0]):
                return True
            elif state and state in "MGO" and self.entered_across(vid, slot, via, stop[0]):
                return True
            # SUMO's word on foes, but not at an all-way stop, where it
            # reports the foes halted at their lines as foes, nor where the
            # link has priority now (no need to ask: ``lacks_priority`` is
            # False for it whatever the foes).
            ask = state != "w" and not self._has_priority_now(stop, state)
            for link in (self.conn.sumo.vehicle.getNextLinks(vid) if ask else ()):
                # (lane, has priority, is open, has foe, via lane, state, direction, length)
                if link[4] == via:
                    if lacks_priority(link):
                        return True
                    break
            if self.exit_blocked(vid, slot, via, stop[0] - self.fleet.s_front(slot)):
                return True
            inner, offset = self.network.waiting_point_after(via)
            if inner is not None:
                # A turn with an internal waiting point a few metres into the
                # junction: too fast to stop there, the vehicle would cross
                # the oncoming lanes without looking (the point is asked
                # about only once the entry is passed). While it could not
                # stop there gently (ENTRY_SLOW_DECEL of the planning
                # deceleration) and the point would make it wait, it is held
                # at the entry line, so it slows; once slow it goes on to
                # wait at the point, as SUMO's drivers do.
                v = max(float(self.conn.sumo.vehicle.getSpeed(vid)), 0.0)
                room = stop[0] - self.fleet.s_front(slot) + offset - STOP_MARGIN_M
                gentle = ENTRY_SLOW_DECEL * self.plan_decel
                # Foes are looked for as far ahead as the vehicle needs to
                # reach the point, on top of the point's own horizon: it
                # decides here for a point it gets to later (traced: with 4 s
                # only, a left turner 30 m from its point at 12.6 m/s went on,
                # and the straight-on foe, 5.7 s away, met it in the turn).
                horizon = INTERNAL_YIELD_S + room / max(v, 1.0)
                if v * v > 2.0 * gentle * room and self.internal_junction_busy(vid, inner, horizon):
                    return True
        return self.junction_blocked(vid, via)

    def exit_blocked(self, vid: str, slot: int, via: str, gap: float) -> bool:
        """Is there no room for ``vid`` on the lane out of its way ``via``
        behind a standing vehicle (SUMO's drivers' keep-the-junction-clear
        rule, ``MSVehicle::checkRewindLinkLanes``)? The room is the back of
        the rearmost vehicle standing (below ``HALT_SPEED_MPS``) on the
        lane out, less the length plus minGap of every vehicle between:
        moving ones behind it on that lane, the ones on the way's junction
        lanes and the ones ahead of ``vid`` on its own lane; blocked when
        that is less than ``vid``'s own length plus minGap. Not judged: a
        connection with ``keepClear="0"`` and a vehicle or a lane out in a
        roundabout (as SUMO does not), a lane out under ``EXIT_MIN_LANE_M``,
        a vehicle on a junction lane, and one that cannot stop before its
        line at the planning deceleration (``gap``: its front to the line).
        Without it, on the shipped grid with every vehicle controlled,
        vehicles went in behind a queue, stood inside the junction across
        the crossing ways, and 4 of the ones they blocked waited there
        until SUMO teleported them."""
        network = self.network
        after = network.lanes_after(via)
        if len(after) < 2 or not network.keeps_clear(via):
            return False
        out, out_len = after[-1]
        if out_len < EXIT_MIN_LANE_M or network.in_roundabout(edge_of(out)):
            return False
        conn = self.conn
        veh = conn.sumo.vehicle
        lane = conn.get_lane_id(vid)
        if lane.startswith(":") or network.in_roundabout(edge_of(lane)):
            return False
        v = max(float(conn.get_speed(vid)), 0.0)
        if v * v > 2.0 * self.plan_decel * max(gap, 0.0):
            return False
        get_pos, get_speed = conn.get_lane_pos, conn.get_speed
        brutto = self._brutto
        space, lengths = None, 0.0
        for other in conn.vehicles_on(out):
            if other != vid and float(get_speed(other)) < HALT_SPEED_MPS:
                space = float(get_pos(other)) - float(veh.getLength(other)) - lengths
                break
            lengths += brutto(other)
        if space is None:
            return False
        for inside, _ in after[:-1]:
            for other in conn.vehicles_on(inside):
                if other != vid:
                    space -= brutto(other)
        own = float(get_pos(vid))
        for other in conn.vehicles_on(lane):
            if other != vid and float(get_pos(other)) > own:
                space -= brutto(other)
        if space >= brutto(vid):
            return False
        self.counts["keep_clear_waits"] += 1
        return True

    def _brutto(self, vid: str) -> float:
        veh = self.conn.sumo.vehicle
        return float(veh.getLength(vid)) + float(veh.getMinGap(vid))

    def _has_priority_now(self, stop: Any, state: str) -> bool:
        """Has the link of ``stop`` (``RouteFleet.next_stop``'s) priority
        now, as SUMO's ``getNextLinks`` would say (a link's state an upper
        case letter)? A signalised link by its light's state this step
        (read anew by ``refresh_tls``), any other by the network's
        ``state``; an unknown one is not taken to have it."""
        light, index = stop[1], stop[2]
        if light >= 0:
            lights = self.tls_state.get(self.tracks.lights.name(light), "")
            return 0 <= index < len(lights) and lights[index].isupper()
        return state in ("M", "O", "G")

    def leader_beyond(self, vid: str, track_lanes: list[str], lane: str | None = None) -> tuple[str, float] | None:
        """The leader of ``vid`` when it is on a junction lane and ``getLeader``
        found none: the nearest vehicle on the rest of its way through the
        junction (its connection's junction lanes, then the lane it leads to),
        as (id, gap as ``getLeader`` gives it), or None. From a junction lane
        before an internal junction (the first part of a left turn) SUMO's
        ``getLeader`` does not look onto the lane after the waiting point
        (traced on Bologna: a left turner waited there, ``getLeader`` of the
        controlled vehicle behind it said None, and it drove into it). SUMO
        may have the vehicle on the lane beside its track's on the same
        junction edge (its own choice of lane at the entry; the track's
        ``track_lanes`` come next): the way ahead is then the track's lane's.
        ``lane``: SUMO's lane of ``vid``, when already read this step."""
        if lane is None:
            lane = self.conn.get_lane_id(vid)
        if not lane.startswith(":"):
            return None
        return self._leader_on_way(vid, lane, lane not in track_lanes, track_lanes)

    def _leader_on_way(self, vid: str, lane: str, beside: bool, track_lanes: list[str]) -> tuple[str, float] | None:
        """``leader_beyond`` for ``vid`` on junction lane ``lane`` (SUMO's),
        ``beside`` its track's."""
        pos = float(self.conn.get_lane_pos(vid))
        if beside:
            own = _track_lane_beside(lane, track_lanes)
            if own != lane:
                # SUMO's position on the lane beside is not one on the
                # track's: lanes of a fan-out start together and part (traced
                # on Bologna: 1.35 m taken for a gap of 0.1 m, the vehicle
                # then stood 9 cm into its leader's minGap). Where it put the
                # front on the track's lane is blendtrack's own.
                pos = self._front_on(vid, own, pos)
                lane = own
        veh = self.conn.sumo.vehicle

        def on_first(on: list[str]) -> list[str]:
            # On its own lane getLeader has looked; on the track's lane
            # beside it, the vehicles ahead of it count.
            return [x for x in on if float(veh.getLanePosition(x)) > pos] if beside else []

        return self._first_on_way(vid, self.network.lanes_after(lane), -pos, on_first)

    def _first_on_way(self, vid: str, way: list[tuple[str, float]], dist: float,
                      on_first: Any = None) -> tuple[str, float] | None:
        """The first vehicle but ``vid`` on ``way`` (lanes with their lengths,
        in order; ``on_first`` filters the first lane's), with its gap as
        ``getLeader`` gives it; ``dist``: from ``vid``'s front to the start
        of the first lane."""
        veh = self.conn.sumo.vehicle

        def back(other: str) -> float:
            return float(veh.getLanePosition(other)) - float(veh.getLength(other))

        for k, (nxt, length) in enumerate(way):
            # SUMO lists a lane's vehicles back to front.
            on = [x for x in self.conn.vehicles_on(nxt) if x != vid]
            if k == 0 and on_first is not None:
                on = on_first(on)
            if on:
                return on[0], dist + back(on[0]) - float(veh.getMinGap(vid))
            dist += length
        if not way:
            return None
        # Past the way's last lane: a vehicle just beyond its end, on any
        # lane after it, with its back still on it (SUMO counts such a
        # vehicle on the lane as well, and its getLeader sees it there).
        # The way ends where its lane parts (a fan-out, or any junction):
        # a car whose front was 1.6 m onto the next junction lane hung 2.9 m
        # back onto a 6.6 m lane, unseen by a controlled car on its way
        # through the junction before, until SUMO put that one on its
        # track's lane 2.5 m behind it (SUMO's fokr_bs_demo, 30 %, 54288 s).
        best: tuple[str, float] | None = None
        for nxt in self.network.lanes_next(way[-1][0]):
            on = [x for x in self.conn.vehicles_on(nxt) if x != vid]
            if not on:
                continue
            hang = back(on[0])
            if hang < 0.0 and (best is None or dist + hang < best[1]):
                best = (on[0], dist + hang)
        return None if best is None else (best[0], best[1] - float(veh.getMinGap(vid)))

    def leader_at_fanout(self, vid: str, lane: str, track_lanes: list[str], lead: Any) -> Any:
        """``lead`` (``getLeader``'s answer for ``vid``, None for none) or,
        when ``vid`` is on a lane that fans out (``Network.fanouts``) and its
        track goes through one of those connections, the nearest vehicle on
        the track's way through the junction if that is nearer. SUMO's
        ``getLeader`` looks along the connection its driver would take,
        which can be the one beside the track's (traced on Bologna with every
        vehicle controlled: a vehicle standing just past a fan-out on the
        track's lane was not seen until the follower, 11 m/s, was on the
        junction, 6.6 m behind it; it ran into it). Also a vehicle standing
        on a branch beside with its body across the track's way
        (``leader_in_fanout``, looked for from the lane before as well)."""
        vias, length = self.network.fanouts()[lane]
        k = next((n for n, x in enumerate(track_lanes) if x == lane), None)
        if k is None:
            return lead
        own = next((x for x in track_lanes[k + 1 :] if x != lane), None)
        if own not in vias:
            return lead
        to_end = length - float(self.conn.get_lane_pos(vid))
        if lead is not None and float(lead[1]) <= to_end:
            return lead  # ahead on its own lane: nearer than anything beyond
        found = self._first_on_way(vid, self.network.lanes_after(own), to_end)
        if found is not None and (lead is None or found[1] < float(lead[1])):
            lead = found
        # A vehicle standing on the branch beside, its body across the
        # track's way where the branches have not yet parted, is in the way
        # too: seen only once inside (``leader_in_fanout``), a vehicle SUMO
        # had inserted at 13.9 m/s 23 m before such a fan-out was 5 m from
        # one at its next 1 s step and ran into it (Bologna, junction 11).
        return self.leader_in_fanout(vid, own, track_lanes, lead)

    def leader_in_fanout(self, vid: str, lane: str, track_lanes: list[str], lead: Any) -> Any:
        """``lead`` (as ``getLeader`` gives it, None for none) or, for ``vid``
        inside a junction on a way that starts where its lane fans out
        (``Network.fanouts``), the nearest vehicle standing (below
        ``FOLLOW_MIN_SPEED_MPS``) with its body across the rest of that way:
        on the branch beside, or just past that branch's exit with its back
        still in the junction. The gap is the straight distance from the
        front to that body less the minGap (never more than along the way).
        ``getLeader`` looks along the vehicle's own lanes only, and the check
        of bodies in the way (``junction_blocked``) is made before the line:
        a controlled vehicle a 1 s step had carried 0.8 m past its line,
        standing there, drove on into the back of one standing 0.5 m onto the
        lane beside (Bologna, junction 8)."""
        own = lane if lane in track_lanes else _track_lane_beside(lane, track_lanes)
        origin = self.network.from_lane(own)
        if origin is None or origin not in self.network.fanouts():
            return lead
        path, lanes = self.network.junction_lanes(own)
        if not lanes or len(path) < 2:
            return lead
        veh = self.conn.sumo.vehicle
        ahead = None
        best, best_gap = lead, (float(lead[1]) if lead else math.inf)
        for other in self._inside_junction(vid, own, lanes):
            if lead is not None and other == lead[0] or float(self.conn.get_speed(other)) >= FOLLOW_MIN_SPEED_MPS:
                continue
            if ahead is None:
                # The way's rest and the front, once there is a body to check.
                front = np.asarray(veh.getPosition(vid), dtype=float)
                ahead = path_ahead(path, front)
                reach = 0.5 * float(veh.getWidth(vid)) + INSIDE_MARGIN_M
            body, half = body_segment(veh, other)
            if segments_distance(body, ahead) >= reach + half:
                continue
            gap = max(segments_distance(body, front[None, :]) - half, 0.0) - float(veh.getMinGap(vid))
            if gap < best_gap:
                best, best_gap = (other, gap), gap
        return best

    def leader_at_merge(self, vid: str, lane: str, track_lanes: list[str], lead: Any,
                        memo: dict[str, Any] | None = None) -> Any:
        """``lead`` (as ``getLeader`` gives it, None for none) or, when
        ``vid`` is within ``MERGE_LOOKAHEAD_M`` of where its way through a
        junction merges with other ways onto one lane, the vehicle on one of
        those ways that gets there first, if its back is nearer than
        ``lead``: a vehicle nearer the merge point, or one that reaches it
        sooner at the speeds both have now. SUMO's ``getLeader`` looks along
        the vehicle's own lanes only, so a vehicle merging from another
        junction lane was not seen until both fronts were on the lane after
        (Bologna, junction 39a: two controlled vehicles collided there, and
        a SUMO driver from the minor road at 5.8 m/s into a controlled one
        entering at 1 m/s). Between two controlled vehicles the rule is the
        same from both sides, so one of them goes; once both stand, the
        nearer one. Of ``lead`` and such a vehicle the one followed is the
        one whose stop point (gap plus braking distance at the planning
        deceleration) is nearer: a merging vehicle nearer but faster than a
        standing leader must not hide it.

        ``memo``: a dict kept with ``track_lanes`` (``RouteGeometry.memo``)
        where the merge ahead of each lane, which depends on the track and
        the network only, is kept once found."""
        if memo is None:
            way = self._way_to_merge(lane, track_lanes)
        else:
            way = memo.get(lane, NOT_LOOKED_UP)
            if way is NOT_LOOKED_UP:
                way = memo[lane] = self._way_to_merge(lane, track_lanes)
        if way is None:
            return lead
        own, target, ahead, start = way
        get_speed, get_pos, vehicles_on = self.conn.get_speed, self.conn.get_lane_pos, self.conn.vehicles_on
        # Farther than MERGE_LOOKAHEAD_M the answer is ``lead`` whoever is on
        # the merging ways: their lanes are read only within it.
        p = float(get_pos(vid))
        pos = ahead - (self._front_on(vid, start, p) if start is not None else p)
        if pos > MERGE_LOOKAHEAD_M:
            return lead
        veh = self.conn.sumo.vehicle
        speed, read_speed = 0.0, True
        best, best_stop = lead, math.inf
        for name, rest, length, waits in self._merging_lanes(target, own):
            for other in vehicles_on(name):
                if other == vid:
                    continue
                if read_speed:
                    speed, read_speed = float(get_speed(vid)), False
                at = float(get_pos(other))
                its = rest - at
                other_speed = float(get_speed(other))
                if waits and other_speed < HALT_SPEED_MPS and at > length - HALT_NEAR_M and other not in self.controlled:
                    # A SUMO driver standing at the waiting point waits
                    # for us: followed, neither goes (Bologna, junction
                    # 50: a controlled vehicle turning right from the
                    # major road stood 6.8 m from the merge behind a left
                    # turner at its internal stop, 0.1 m from it, and the
                    # queue behind stood until SUMO teleported it).
                    continue
                # Nearer the merge point (a SUMO driver: about as near),
                # or sooner there at the speeds both have now.
                near = pos + (0.0 if other in self.controlled else MERGE_DEFER_M)
                if its >= near and not (other_speed > 0.0 and its * speed < pos * other_speed):
                    continue
                gap = pos - its - float(veh.getLength(other)) - float(veh.getMinGap(vid))
                if best is not None and math.isinf(best_stop):
                    best_stop = self._stop_point(best)
                stop = self._stop_at(gap, other_speed)
                if best is None or stop < best_stop:
                    best, best_stop = (other, gap), stop
        return best

    def _merging_lanes(self, target: str, own: str) -> list[tuple[str, float, float, bool]]:
        """The lanes of the ways onto ``target`` other than the one through
        ``own``, in order, each with the distance from its start to the
        start of ``target`` (m), its length, and whether it is the junction
        lane before an internal waiting point of a way our own has priority
        over (its vehicles stop at its end for ours); kept per (target, own)."""
        key = (target, own)
        hit = self._merging.get(key)
        if hit is None:
            hit = []
            for chain in self.network.ways_into(target):
                if any(name == own for name, _ in chain):
                    continue
                rest = sum(length for _, length in chain)
                for k, (name, length) in enumerate(chain):
                    waits = k + 1 < len(chain) and name.startswith(":") and self._yields_to(name, own)
                    hit.append((name, rest, length, waits))
                    rest -= length
            self._merging[key] = hit
        return hit

    def _yields_to(self, via: str, own: str) -> bool:
        """Must the way through junction lane ``via`` give way to the one
        through ``own`` (the network's right-of-way matrix)?"""
        return any(lane == own for lane, *_ in self.network.prohibitors(via))

    def _stop_point(self, lead: Any) -> float:
        """How far ahead (m, as ``getLeader``'s gap) leader ``lead`` (id,
        gap) can stop at the planning deceleration: what the stopping law
        depends on, so the nearer of two leaders by this is the one to follow."""
        try:
            speed = float(self.conn.sumo.vehicle.getSpeed(lead[0]))
        except Exception:
            speed = 0.0
        return self._stop_at(float(lead[1]), speed)

    def _stop_at(self, gap: float, speed: float) -> float:
        """The stop point of a leader ``gap`` ahead at ``speed`` (see ``_stop_point``)."""
        return gap + max(speed, 0.0) ** 2 / (2.0 * self.plan_decel)

    def _way_to_merge(self, lane: str, track_lanes: list[str]) -> tuple[str, str, float, str | None] | None:
        """For a vehicle on SUMO lane ``lane`` with the track ``track_lanes``:
        (its junction lane ahead or under it on its track, the lane its way
        through the junction leads to, that lane's start from the start of
        ``lane`` or, with the fourth item, from the start of that item, the
        track's junction lane beside ``lane``, on which blendtrack's front
        position counts) when that lane is one several ways merge onto;
        else None. Depends on the track and the network only."""
        if lane.startswith(":"):
            own = lane if lane in track_lanes else _track_lane_beside(lane, track_lanes)
            start = own
            after = self.network.lanes_after(own)
            if len(after) < 2:
                return None
            ahead = sum(length for _, length in after[:-1])
            if not self.network.ways_into(after[-1][0]):
                # The lane after may be a short one before the next junction
                # (Bologna: 77cd, 0.2 m, between junctions 20c and 39a).
                further = self._merge_beyond(after[-1][0], track_lanes, ahead)
                if further is None:
                    return None
                own, target, ahead = further
            else:
                target = after[-1][0]
            return own, target, ahead, (start if start != lane else None)
        if lane not in self.network.lanes_into_merges():
            return None
        found = self._merge_beyond(lane, track_lanes, 0.0, math.inf)
        if found is None:
            return None
        via, target, to_end = found
        return via, target, to_end, None

    def _merge_beyond(self, lane: str, track_lanes: list[str], ahead: float,
                      limit: float = MERGE_LOOKAHEAD_M) -> tuple[str, str, float] | None:
        """From the start of normal lane ``lane`` of the track (``ahead`` m
        from the vehicle's lane start), the next junction lane on the track
        if its way merges onto a lane within ``limit`` (m from the vehicle's
        lane start): (that junction lane, the lane it leads to, their
        distance from the vehicle's lane start); else None."""
        try:
            k = track_lanes.index(lane)
        except ValueError:
            return None
        if k + 1 >= len(track_lanes) or not track_lanes[k + 1].startswith(":"):
            return None
        via = track_lanes[k + 1]
        after = self.network.lanes_after(via)
        ahead += self.network.lane_length(lane) + sum(length for _, length in after[:-1])
        if len(after) < 2 or ahead > limit or not self.network.ways_into(after[-1][0]):
            return None
        return via, after[-1][0], ahead

    def _front_on(self, vid: str, lane: str, fallback: float) -> float:
        """The lane position blendtrack has ``vid``'s front at on ``lane``
        (a lane of its track), or ``fallback`` when the front is not on it."""
        act = self.controlled.get(vid)
        if act is None or self.fleet is None:
            return fallback
        lane_id, pos = self.fleet.front_lane_position(act.slot)
        return float(pos) if self.tracks.lanes.names[lane_id] == lane else fallback

    def leader_on_track(self, vid: str, track_lanes: list[str], lead: Any, lane: str | None = None) -> Any:
        """``lead`` (``getLeader``'s answer for ``vid``, found) or, when SUMO
        has ``vid`` on a junction lane beside its track's, the nearest
        vehicle on the track's way through the junction if that is nearer.
        SUMO's ``moveToXY`` can map a vehicle onto the neighbouring lane of
        the same junction edge for a step, and ``getLeader`` then looks
        along that lane's connection (traced on Bologna: 25.9 m to a vehicle
        on another lane, the vehicle 15.9 m ahead on its own way unseen for
        the step; it sped up and then stood inside the minGap of that one).
        ``lane``: as for ``leader_beyond``."""
        if lane is None:
            lane = self.conn.get_lane_id(vid)
        if not lane.startswith(":") or lane in track_lanes:
            return lead
        own = self._leader_on_way(vid, lane, True, track_lanes)
        if own is not None and own[1] < float(lead[1]):
            return own
        return lead

    def junction_blocked(self, vid: str, via: str) -> bool:
        """Is a vehicle inside the junction in the way of ``vid``, about to
        enter it through ``via``: its body (SUMO's front point, angle, length
        and width) within the half width of ``vid``'s path through the
        junction plus ``INSIDE_MARGIN_M``? A left turner waiting at its
        internal stop point can reach into a crossing lane, and a follower's
        lane can diverge from it barely apart; ``getLeader`` reports neither
        (they are on other junction lanes), SUMO's drivers see them through
        the junction's foe lanes, so blendtrack checks the geometry itself.
        Asked only near a junction whose lanes come near this one.

        Nor does it enter while a vehicle is on its way to, or waits at, an
        internal waiting point where a car would stand within that reach of
        the path (``Network.waiting_points_near``): once it waits there, the
        two wait for each other. A controlled bus that went in stood behind
        the left turner waiting across its lane, and the turner, a SUMO
        driver, waited for the bus inside the junction before its crossing:
        135-414 s each time (Bologna, junction 27); held at its line the bus
        is no approaching foe to SUMO, the turner goes, then the bus."""
        path, lanes = self.network.junction_lanes(via)
        if not lanes:
            return False
        veh = self.conn.sumo.vehicle
        reach = 0.5 * float(veh.getWidth(vid)) + INSIDE_MARGIN_M
        for other in self._inside_junction(vid, via, lanes):
            body, half = body_segment(veh, other)
            if segments_distance(body, path) < reach + half:
                self.counts["inside_junction_waits"] += 1
                return True
        vehicles_on = self.conn.vehicles_on
        for lane, dist in self.network.waiting_points_near(via):
            if dist < reach + WAITING_HALF_WIDTH_M and any(other != vid for other in vehicles_on(lane)):
                self.counts["waiting_point_waits"] += 1
                return True
        return False

    def _inside_junction(self, vid: str, via: str, lanes: Sequence[str]) -> Iterator[str]:
        """The vehicles other than ``vid`` with a body in the junction on the
        junction ``lanes`` near ``via``'s way, lazily (``junction_blocked``
        stops at the first in the way), less those to follow."""
        veh = self.conn.sumo.vehicle
        get_speed, get_pos, vehicles_on = self.conn.get_speed, self.conn.get_lane_pos, self.conn.vehicles_on

        def back_out(other: str) -> bool:
            """Is the back of ``other`` past the start of its lane?"""
            return float(get_pos(other)) >= float(veh.getLength(other))

        origin = self.network.from_lane(via)
        from_lane = self.network.from_lane
        follow_speed = None
        for lane, on in [(lane, on) for lane in lanes if (on := vehicles_on(lane))]:
            # A vehicle that entered from the same lane and drives on ahead
            # (its back past the line, at FOLLOW_MIN_SPEED_MPS or more and
            # no slower than this one) is one to follow, not a foe: waiting
            # until it had left the path, a straight-on vehicle behind left
            # turners crossed a green light only after each of them
            # (Bologna, 204c).
            same = origin is not None and from_lane(lane) == origin
            for other in on:
                if other == vid:
                    continue
                if same and back_out(other):
                    if follow_speed is None:
                        follow_speed = max(FOLLOW_MIN_SPEED_MPS, float(get_speed(vid)))
                    if float(get_speed(other)) >= follow_speed:
                        continue
                yield other
        # A vehicle that has left the junction by another way with its back
        # still in it (standing just past the exit, say): SUMO lists it on
        # the lane out only. Not checked, a controlled vehicle swept through
        # the back of one standing 0.9 m past the exit of the neighbouring
        # branch of a lane that fans out (Bologna, 8).
        for lane in self.network.junction_exits(via):
            for other in vehicles_on(lane):
                if other != vid and not back_out(other):
                    yield other

    def _body_in_way(self, vid: str, foe: str, memo: dict[str, bool]) -> bool:
        """Does ``vid``'s body (as SUMO has it) come within
        ``WAITING_HALF_WIDTH_M`` + ``INSIDE_MARGIN_M`` of the centreline of
        the foe junction lane ``foe``? A vehicle standing at the line before
        that lane then waits for ``vid`` (SUMO's drivers yield to a vehicle
        inside the junction in their way), whatever its light says. Where an
        internal waiting point lies beyond oncoming lanes, a car waiting
        there stands across them: at Bologna's junction 9 a controlled left
        turner stood 42 s at its point for oncoming cars that stood at their
        green line for it, left when the light changed, and the first car
        of the next phase drove into it (seed 4, 363 s). Kept per foe lane
        in ``memo`` for one check."""
        hit = memo.get(foe)
        if hit is None:
            shape, _ = self.network.lane_shape(foe)
            body, half = body_segment(self.conn.sumo.vehicle, vid)
            hit = memo[foe] = segments_distance(body, shape) < half + WAITING_HALF_WIDTH_M + INSIDE_MARGIN_M
        return hit

    def _held_at_line(self, other: str) -> bool:
        """Is ``other`` (standing) held at its stop line: a controlled
        vehicle blendtrack told to wait last step, or one of SUMO's drivers
        whose next link SUMO says lacks priority with a foe (the rule
        ``must_yield`` applies to controlled vehicles)?"""
        if other in self.waiting:
            # Unless it was told this step that it may go.
            return other not in self._going_now
        if other in self.controlled:
            return False
        try:
            links = self.conn.sumo.vehicle.getNextLinks(other)
        except Exception:
            return False
        return bool(links) and lacks_priority(links[0])

    def forget(self, vid: str) -> None:
        """``vid`` is no longer controlled."""
        self.halted.pop(vid, None)
        self.went.pop(vid, None)
        self.holds.pop(vid, None)

    def allway_busy(self, vid: str, via: str) -> bool:
        """At an all-way stop, halted at the line: a foe inside the junction
        on its way, or one halted at its own line (its front within
        ``HALT_NEAR_M`` plus the standstill margin of it) that has waited
        longer, goes first; foes still approaching have to halt too."""
        veh = self.conn.sumo.vehicle
        vehicles_on = self.conn.vehicles_on
        mine = float(veh.getWaitingTime(vid))
        for foe, incoming, lane_length, _, _ in self.network.internal_foes(via):
            if any(other != vid for other in vehicles_on(foe)):
                return True
            if incoming is None:
                continue
            for other in vehicles_on(incoming):
                if other == vid:
                    continue
                near = lane_length - float(veh.getLanePosition(other)) < HALT_NEAR_M + STOP_MARGIN_M
                if near and float(veh.getSpeed(other)) < HALT_SPEED_MPS and float(veh.getWaitingTime(other)) > mine:
                    return True
        return False

    def link_busy(self, vid: str, slot: int, via: str, stop_s: float) -> bool:
        """At a link without priority: is a foe with priority over it inside
        the junction on its way, or would one approaching on the lane before
        it reach the point where the two ways cross before ``vid`` has
        crossed it? ``vid`` crosses from where it is, from its speed at
        ``plan_accel``, until its back is ``CONFLICT_CLEAR_M`` past the point;
        a foe arrives at its speed, its front ``CONFLICT_CLEAR_M`` short of
        the point. SUMO's ``getNextLinks`` reports foes arriving within about
        a second only, too late for a vehicle that needs five to cross from
        standstill at 1 m/s^2."""
        foes = self._prohibitors.get(via)
        if foes is None:
            conflict = self.network.conflict
            foes = self._prohibitors[via] = [(*foe, *conflict(via, foe[0])) for foe in self.network.prohibitors(via)]
        if not foes:
            return False
        veh = self.conn.sumo.vehicle
        vehicles_on, get_speed, get_pos = self.conn.vehicles_on, self.conn.get_speed, self.conn.get_lane_pos
        v = max(float(get_speed(vid)), 0.0)
        gap = max(stop_s - self.fleet.s_front(slot), 0.0)
        length = float(veh.getLength(vid))
        patience = _Patience(self, vid, via, v, gap)

        def first(other: str, d: float, t_cross: float) -> bool:
            """Does ``other``, ``d`` from the crossing point (less the
            clearance) at its speed, get there before ``t_cross``, and is
            not let come?"""
            speed = float(get_speed(other))
            arrive = 0.0 if d < INTERNAL_YIELD_NEAR_M else d / max(speed, 1e-9)
            return arrive < t_cross and not patience.lets_go(other, d, speed, arrive, t_cross)

        for foe, incoming, lane_length, tls, link, ours, theirs in foes:
            t_cross = self._crossing_time(v, gap + ours, length)
            # (No vehicle on the foe lane: none inside it in the way.)
            if vehicles_on(foe) and self._inside_in_time(vid, via, foe, t_cross, patience):
                return True
            if incoming is None:
                continue
            if tls:
                state = self.tls_state.get(tls, "")
                if 0 <= link < len(state) and state[link] not in "GgsOoyY":
                    continue  # the foe's light is red: it stops
            for other in vehicles_on(incoming):
                if other != vid and first(other, lane_length - float(get_pos(other)) + theirs - CONFLICT_CLEAR_M, t_cross):
                    return True
            if lane_length < FEEDER_LANE_M and self._foe_before(vid, incoming, lane_length + theirs - CONFLICT_CLEAR_M, first, t_cross):
                return True
            # A controlled foe SUMO has on another lane than its track's is
            # known by its track: a 12 m bus swung out of an S bend stood on
            # lane 1 to SUMO while its way went through lane 0's link, and
            # neither SUMO's links nor the lane in (0.2 m long) showed it;
            # a car from the minor road went, and met it (Bologna, 39a).
            for other, to_line in self.approaching_on_tracks().get(foe, ()):
                if other != vid and self._off_its_lane(other) \
                        and first(other, to_line + theirs - CONFLICT_CLEAR_M, t_cross):
                    return True
        return False

    def entered_across(self, vid: str, slot: int, via: str, stop_s: float) -> bool:
        """At a link with priority: has a vehicle already entered the
        junction on a foe's way that crosses ours (on the first junction
        lane of a foe link, past its own line), and would it be in the way
        (``_inside_in_time``) before ``vid`` has crossed, from where it is
        at its speed and ``plan_accel``? Asked only while ``vid`` can stop
        at its line at ``plan_decel``. A vehicle inside the junction looks
        only at the vehicles on the junction's lanes, not at the ones
        coming: at Bologna's 39a (seed 10, 376-379 s) a SUMO driver from
        the minor road 59 crept 0.01 m over its line and stood, then pulled
        away while a controlled car came through 20c on the major road, and
        they met inside. Foe lanes that end at an internal waiting point
        (left turners waiting for us there) do not count."""
        v = max(float(self.conn.get_speed(vid)), 0.0)
        gap = max(stop_s - self.fleet.s_front(slot), 0.0)
        if v * v > 2.0 * self.plan_decel * gap:
            return False
        length = float(self.conn.sumo.vehicle.getLength(vid))
        vehicles_on = self.conn.vehicles_on
        for foe, incoming, *_ in self.network.internal_foes(via):
            if incoming is None or not vehicles_on(foe) or self.network.stops_inside(foe):
                continue
            crossing = self.network.crossing(via, foe)
            if crossing is None:
                continue  # the ways merge: ``leader_at_merge``
            t_cross = self._crossing_time(v, gap + crossing[0], length)
            if self._inside_in_time(vid, via, foe, t_cross, None):
                self.counts["entered_across_waits"] += 1
                return True
        return False

    def _crossing_time(self, v: float, to_point: float, length: float) -> float:
        """The time (s) a vehicle at speed ``v`` needs, accelerating at
        ``plan_accel``, to get its back (``length``) ``CONFLICT_CLEAR_M``
        past the point where two ways cross, ``to_point`` ahead of its
        front, plus ``CROSS_MARGIN_S``."""
        a = self.plan_accel
        dist = to_point + CONFLICT_CLEAR_M + length
        return (math.sqrt(v * v + 2.0 * a * dist) - v) / a + CROSS_MARGIN_S

    def _foe_before(self, vid: str, incoming: str, beyond: float, first: Any, t_cross: float) -> bool:
        """Is a foe on its way onto the short lane ``incoming`` from beyond
        the junction before it (``Network.feeders``), or about to change
        onto it from a lane beside it (or from before that lane), first at
        the crossing point (``first(other, distance, t_cross)``), ``beyond``
        (m) past ``incoming``'s start? One on a normal lane before
        ``incoming`` counts only when its next link leads onto it (it may
        turn elsewhere); one on or before a lane beside it only when SUMO
        says its driver wants to change toward it (Bologna's 20b: drivers
        from 77[1][0]'s lane 1 change onto 77ab's lane 0, 0.74 m long, and
        so onto the merge a car turning right from 56b takes)."""
        vehicles_on, get_pos = self.conn.vehicles_on, self.conn.get_lane_pos
        lanes = self.network.edge_lanes(edge_of(incoming))
        if incoming not in lanes:
            lanes = (incoming,)
        mine = lanes.index(incoming)
        for k, lane in enumerate(lanes):
            # Lanes are right to left: a driver to the right changes left (1).
            toward = (k < mine) - (k > mine)
            # Beside it: as near as on ``incoming`` itself, if it changes.
            ways = ((lane, 0.0),) + self.network.feeders(lane) if toward else self.network.feeders(incoming)
            for feeder, back in ways:
                for other in vehicles_on(feeder):
                    if other == vid or not first(other, back - float(get_pos(other)) + beyond, t_cross):
                        continue
                    if toward:
                        if self._wants_toward(other, toward):
                            return True
                        continue
                    if feeder.startswith(":"):
                        return True
                    try:
                        links = self.conn.sumo.vehicle.getNextLinks(other)
                    except self.conn.errors:
                        continue
                    if links and links[0][0] == incoming:
                        return True
        return False

    def _wants_toward(self, other: str, toward: int) -> bool:
        """Does SUMO's driver ``other`` want to change lanes toward
        ``toward`` (1 left, -1 right): its lane-change state says so, or its
        lane is not among its best lanes and the best are that way (at
        Bologna's 20b a driver whose best lane was to its right said "stay"
        a second before it changed there)?"""
        tc = self.conn.tc
        try:
            state, _ = self.conn.lane_change_state(other, toward)
            if state & (tc.LCA_LEFT if toward > 0 else tc.LCA_RIGHT):
                return True
            lane = self.conn.get_lane_id(other)
            best = self.conn.sumo.vehicle.getBestLanes(other)
        except self.conn.errors:
            return False
        # (lane, length, occupation, offset to the best lane, continues, next lanes)
        offset = next((int(b[3]) for b in best if b[0] == lane), 0)
        return offset != 0 and (offset > 0) == (toward > 0)

    def _off_its_lane(self, vid: str) -> bool:
        """Does SUMO have the controlled vehicle ``vid`` on another lane than
        the one its front is on along its track?"""
        lane, _ = self.fleet.front_lane_position(self.controlled[vid].slot)
        return bool(self.tracks.lanes.names[lane] != self.conn.get_lane_id(vid))

    def approaching_on_tracks(self) -> dict[str, list[tuple[str, float]]]:
        """Per first junction lane of a link: the controlled vehicles whose
        tracks enter a junction through it within ``APPROACH_LOOK_M`` ahead,
        with the distance from their front to its line (the RouteFleet's
        ``stops_ahead``); built once a step, when first asked."""
        if self._approaching is None:
            found: dict[str, list[tuple[str, float]]] = {}
            vids = list(self.controlled)
            if vids:
                controlled = self.controlled
                index, via, gap = self.fleet.stops_ahead([controlled[v].slot for v in vids], APPROACH_LOOK_M)
                names = self.tracks.lanes.names
                for k, lane, d in zip(index.tolist(), via.tolist(), gap.tolist()):
                    found.setdefault(names[lane], []).append((vids[k], d))
            self._approaching = found
        return self._approaching

    def _inside_in_time(self, vid: str, via: str, foe: str, needed_s: float, patience: _Patience | None) -> bool:
        """Is a vehicle on the foe junction lane ``foe`` in the way of
        ``vid`` entering through ``via`` (at a link or an internal waiting
        point) for the ``needed_s`` seconds it needs? One whose back is
        ``CONFLICT_CLEAR_M`` past the point where the two ways cross has
        gone by; one with its front within ``CONFLICT_CLEAR_M`` of the point
        is in it; one before it arrives accelerating at its vType's accel
        from its speed, and is let come by an impatient vehicle if it could
        stop (``_Patience``). Where the ways do not cross from ``foe`` on
        (they merge, or cross on a junction lane before it), any vehicle on
        it is in the way. (Counted in the way wherever it was, a stream
        crawling through a junction past the crossing kept a bus waiting
        at Bologna's junction 40 until SUMO teleported it.)"""
        on = [other for other in self.conn.vehicles_on(foe) if other != vid]
        if not on:
            return False
        crossing = self.network.crossing(via, foe)
        if crossing is None:
            return True
        theirs = crossing[1]
        veh = self.conn.sumo.vehicle
        get_pos, get_speed = self.conn.get_lane_pos, self.conn.get_speed
        for other in on:
            pos = float(get_pos(other))
            if pos - float(veh.getLength(other)) > theirs + CONFLICT_CLEAR_M:
                continue
            d = theirs - CONFLICT_CLEAR_M - pos
            if d <= 0.0:
                return True
            speed = max(float(get_speed(other)), 0.0)
            acc = max(float(veh.getAccel(other)), 0.1)
            arrive = (math.sqrt(speed * speed + 2.0 * acc * d) - speed) / acc
            if arrive < needed_s and (patience is None or not patience.lets_go(other, d, speed, arrive, needed_s)):
                return True
        return False

    def internal_junction_busy(self, vid: str, via: str, horizon_s: float = INTERNAL_YIELD_S,
                               foes: list[tuple[str, str | None, float, str, int]] | None = None,
                               gap: float | None = None) -> bool:
        """At the waiting point of a turn across oncoming lanes: is a foe
        inside the junction, or about to enter it through an open link?

        SUMO's ``getNextLinks`` does not report this internal link, so
        the check is ours: a vehicle on a foe junction lane, or one on the
        lane leading to it, with its link open, within ``horizon_s`` seconds
        (``INTERNAL_YIELD_S`` at the point) or ``INTERNAL_YIELD_NEAR_M``
        metres of the stop line. ``gap``: the vehicle's distance to the
        point, when it is the point it stands at, for its impatience
        (``_Patience``; None: none).
        """
        vehicles_on, get_speed, get_pos = self.conn.vehicles_on, self.conn.get_speed, self.conn.get_lane_pos
        patience = None if gap is None else _Patience(self, vid, via, max(float(get_speed(vid)), 0.0), gap)
        # Controlled foes held at their line, counted on if the vehicle goes.
        counted_on: list[str] = []
        # Foe junction lane -> is our body in the way of a vehicle on it?
        in_its_way: dict[str, bool] = {}
        for foe, incoming, length, tls, link in (self.network.internal_foes(via) if foes is None else foes):
            if self._inside_in_time(vid, via, foe, horizon_s, patience):
                return True
            if incoming is None:
                continue
            yellow = False
            if tls:
                state = self.tls_state.get(tls, "")
                if 0 <= link < len(state) and state[link] in "yY":
                    yellow = True
                elif 0 <= link < len(state) and state[link] not in "GgsOo":
                    continue  # the foe's light is red: it stops
            for other in vehicles_on(incoming):
                if other == vid:
                    continue
                dist = length - get_pos(other)
                speed = float(get_speed(other))
                if speed < HALT_SPEED_MPS and (self._held_at_line(other) or self._body_in_way(vid, foe, in_its_way)):
                    # Standing at its line and held there (for this vehicle
                    # inside the junction, among others): it does not enter
                    # while this one is in there. Counted as about to
                    # enter, the two waited for each other until SUMO
                    # teleported them (Bologna, junctions 50 and 51: 300 s,
                    # in each of three seeds). A controlled one is kept
                    # there while this one goes (``holds``). Nor does one
                    # whose way this vehicle's body stands across, link
                    # open or not (``_body_in_way``).
                    if other in self.controlled:
                        counted_on.append(other)
                    continue
                if yellow:
                    # At yellow a foe stops only if it can: one too close
                    # comes through (traced: a left turner went when the
                    # oncoming light turned yellow, and a vehicle 23 m from
                    # its line at 13.8 m/s drove on into it).
                    if dist < speed * YELLOW_RUN_REACTION_S + speed * speed / (2.0 * YELLOW_RUN_DECEL_MPS2):
                        return True
                elif dist < INTERNAL_YIELD_NEAR_M or dist < horizon_s * speed:
                    arrive = 0.0 if dist < INTERNAL_YIELD_NEAR_M else dist / max(speed, 1e-9)
                    if patience is None or not patience.lets_go(other, dist, speed, arrive, horizon_s):
                        return True
        if counted_on:
            try:
                edge = str(self.conn.sumo.vehicle.getRoadID(vid))
            except self.conn.errors:
                return False
            # ":J_3_0" (junction J's lane) -> ":J_", the prefix of J's lane and edge ids.
            junction = via.rsplit("_", 2)[0] + "_"
            for other in counted_on:
                self.holds[other] = (vid, edge, junction)
        return False


class _Patience:
    """How long ``vid`` has waited at its line, in SUMO's terms, and which
    approaching foes it therefore lets come: SUMO's impatience
    (``MSLink::blockedByFoe``). A foe that could still stop before the ways
    cross counts as arriving ``impatience x IMPATIENT_DELAY_S`` later than
    it would. "Could stop": its front its minGap short of the point,
    braking at its decel from when it sees the vehicle inside the junction
    (through the junction's foe lanes), at its speed until then: the time the vehicle
    needs to get its front over the line from where it is at its crossing
    acceleration, in whole steps (SUMO's driver plans each step with where
    the vehicle was at the end of the step before, and a speed-only move
    puts it there only during that step; braking, SUMO's Euler steps stop
    it about ``v dt / 2`` shorter than the continuous brake distance taken
    here). The impatience is read from SUMO once, and only when a foe
    would make the vehicle wait.

    A vehicle that went keeps the impatience it went with until its front
    is over the line: moving, SUMO's waiting time is 0 again, and without
    it a vehicle that had waited 19 s to cross a stream (a vehicle every
    5 s) moved 0.8 m, was told to wait at its new place, and waited 24 s
    more there (``tests/test_junctions.py``)."""

    def __init__(self, junctions: Junctions, vid: str, via: str, v: float, gap: float) -> None:
        self.j = junctions
        self.vid = vid
        self.via = via
        a, dt = junctions.plan_accel, junctions.conn.dt
        #: Seconds a foe drives on before it brakes for the vehicle: the
        #: steps until the vehicle's front is over the line.
        t_in = (math.sqrt(v * v + 2.0 * a * max(gap, 0.0)) - v) / a
        self.t_seen = max(math.ceil(t_in / dt - 1e-9), 1) * dt
        self._impatience: float | None = None

    def impatience(self) -> float:
        if self._impatience is None:
            imp = min(max(float(self.j.conn.sumo.vehicle.getImpatience(self.vid)), 0.0), 1.0)
            went = self.j.went.get(self.vid)
            if went is not None and went[0] == self.via:
                imp = max(imp, went[1])
            self._impatience = imp
        return self._impatience

    def lets_go(self, foe: str, dist: float, speed: float, arrive: float, needed_s: float) -> bool:
        """Does the vehicle go although ``foe``, ``dist`` metres short of
        where their ways cross (or of its line) at ``speed``, would arrive
        there in ``arrive`` seconds, within the ``needed_s`` it waits for?
        Only if the foe could still stop, and once delayed by the impatience
        arrives ``needed_s`` or later. Never for a controlled foe: it brakes
        for a vehicle crossing its way only once that one's body is near its
        path (``junction_blocked``), too late at speed (Bologna, junction
        51: a controlled vehicle at 13.7 m/s drove into an impatient one)."""
        imp = self.impatience()
        if imp <= 0.0 or foe in self.j.controlled:
            return False
        if arrive + imp * IMPATIENT_DELAY_S < needed_s:
            return False
        j = self.j
        veh = j.conn.sumo.vehicle
        room = dist - float(veh.getMinGap(foe)) - speed * self.t_seen
        if room < speed * speed / (2.0 * max(float(veh.getDecel(foe)), 0.1)):
            return False
        self.j.went[self.vid] = (self.via, imp)
        return True
