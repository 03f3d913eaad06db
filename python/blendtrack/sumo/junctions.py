"""Junctions: which controlled vehicles must yield at the stop line ahead
(links without priority with foes approaching, an internal waiting point
with a foe in the way, a vehicle inside the junction in the path), and the
traffic lights' states passed on to the RouteFleet."""

from __future__ import annotations

from blendtrack import RouteFleet
from blendtrack.sumo.connection import SumoConnection
from blendtrack.sumo.geometry import body_segment, segments_distance
from blendtrack.sumo.network import Network
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
#: Share of the planning deceleration a turner should need to stop at its
#: internal waiting point once past the entry line.
ENTRY_SLOW_DECEL = 0.5
#: A vehicle inside a junction is in the way of one about to enter when its
#: body comes within this much of the half width of the entering vehicle's
#: path through the junction (m).
INSIDE_MARGIN_M = 0.3


class Junctions:
    """Yield answers for ``RouteFleet.plan_sumo``'s questions, and the lights' states."""

    def __init__(self, conn: SumoConnection, network: Network, tracks: Tracks, fleet: RouteFleet, plan_decel: float) -> None:
        self.conn = conn
        self.network = network
        self.tracks = tracks
        self.fleet = fleet
        #: The deceleration (m/s^2, > 0) a vehicle plans to stop with.
        self.plan_decel = plan_decel
        #: Each traffic light's last state (as SUMO's state string).
        self.tls_state: dict[str, str] = {}
        self.counts = {"inside_junction_waits": 0}

    def refresh_tls(self) -> None:
        """Passes the lights that changed this step to the RouteFleet."""
        tc = self.conn.tc
        light = self.tracks.lights.id
        set_signal = self.fleet.set_signal
        for tls, res in self.conn.sumo.trafficlight.getAllSubscriptionResults().items():
            state = res.get(tc.TL_RED_YELLOW_GREEN_STATE, "")
            if self.tls_state.get(tls) != state:
                self.tls_state[tls] = state
                set_signal(light(tls), state)

    def must_yield(self, vid: str, slot: int) -> bool:
        """SUMO's view of the link ahead: does it lack priority with foes approaching?"""
        stop = self.fleet.next_stop(slot)
        if stop is None:
            return False
        via = self.tracks.lanes.name(stop[4])
        if self.network.is_zipper(via):
            # Taken in turns, not waited at: the order comes from ``Zippers``
            # as a soft leader (a zipper link without a light is listed
            # among the internal waiting points too: link index -1).
            return self.junction_blocked(vid, via)
        if via in self.network.internal_vias:
            if self.internal_junction_busy(vid, via):
                return True
        else:
            for link in self.conn.sumo.vehicle.getNextLinks(vid):
                # (lane, has priority, is open, has foe, via lane, state, direction, length)
                if link[4] == via:
                    if (not link[1]) and bool(link[3]):
                        return True
                    break
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

    def junction_blocked(self, vid: str, via: str) -> bool:
        """Is a vehicle inside the junction in the way of ``vid``, about to
        enter it through ``via``: its body (SUMO's front point, angle, length
        and width) within the half width of ``vid``'s path through the
        junction plus ``INSIDE_MARGIN_M``? A left turner waiting at its
        internal stop point can reach into a crossing lane, and a follower's
        lane can diverge from it barely apart; ``getLeader`` reports neither
        (they are on other junction lanes), SUMO's drivers see them through
        the junction's foe lanes, so blendtrack checks the geometry itself.
        Asked only near a junction whose lanes come near this one."""
        path, lanes = self.network.junction_lanes(via)
        if not lanes:
            return False
        veh = self.conn.sumo.vehicle
        reach = 0.5 * float(veh.getWidth(vid)) + INSIDE_MARGIN_M
        for lane in lanes:
            for other in self.conn.vehicles_on(lane):
                if other == vid:
                    continue
                body, half = body_segment(veh, other)
                if segments_distance(body, path) < reach + half:
                    self.counts["inside_junction_waits"] += 1
                    return True
        return False

    def internal_junction_busy(self, vid: str, via: str, horizon_s: float = INTERNAL_YIELD_S) -> bool:
        """At the waiting point of a turn across oncoming lanes: is a foe
        inside the junction, or about to enter it through an open link?

        SUMO's ``getNextLinks`` does not report this internal link, and SUMO
        registers a controlled vehicle as approaching a link only while its
        own movement carries it (not after a ``moveTo`` or ``moveToXY``), so
        the check is ours: a vehicle on a foe junction lane, or one on the
        lane leading to it, with its link open, within ``horizon_s`` seconds
        (``INTERNAL_YIELD_S`` at the point) or ``INTERNAL_YIELD_NEAR_M``
        metres of the stop line.
        """
        veh = self.conn.sumo.vehicle
        vehicles_on = self.conn.vehicles_on
        for foe, incoming, length, tls, link in self.network.internal_foes(via):
            if any(other != vid for other in vehicles_on(foe)):
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
                dist = length - veh.getLanePosition(other)
                speed = float(veh.getSpeed(other))
                if yellow:
                    # At yellow a foe stops only if it can: one too close
                    # comes through (traced: a left turner went when the
                    # oncoming light turned yellow, and a vehicle 23 m from
                    # its line at 13.8 m/s drove on into it).
                    if dist < speed * YELLOW_RUN_REACTION_S + speed * speed / (2.0 * YELLOW_RUN_DECEL_MPS2):
                        return True
                elif dist < INTERNAL_YIELD_NEAR_M or dist < horizon_s * speed:
                    return True
        return False
