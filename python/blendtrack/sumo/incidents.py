"""Incidents judged by SUMO's own state, not by blendtrack's counters
(issues 18 and 23): red-light crossings of controlled vehicles read off
SUMO's signal states, emergency brakings by SUMO's rule, and teleports of
every vehicle, controlled or not. (Collisions come from SUMO's collision
output, read after the run: :func:`blendtrack.sumo.outputs.read_collisions`.)

**Red-light crossings.** After each control step's moves, SUMO's lane of
every controlled vehicle is read (one ``getLaneID`` each, only on networks
with traffic lights). A vehicle whose front left a normal lane for a lane
of a connection out of it (the connection's first junction lane, or its
target lane when the step jumped the junction lanes) crossed that
connection's stop line during the step. For a signalised connection the
link's state is read from SUMO twice: as of the end of SUMO's step (the
light's subscription: SUMO switches its lights at the start of a step,
before it moves the vehicles, so this is the state the step's movement
and a ``moveToXY`` pushed before it happened under) and now, with
``trafficlight.getRedYellowGreenState`` (the state a ``moveTo``, which
takes effect at once, happened under; another client may have switched
the light in between). SUMO's drivers must stop at ``r`` and ``u``
(red-yellow) and may pass ``y`` only when they cannot stop: a crossing
with the link red (``r``/``u``) in both readings is a red-light crossing
(``red_light_crossings_sumo``); one on yellow, or while a light switched
to or from red, is counted on its own (``yellow_light_crossings_sumo``).
Both go to ``red_lights.csv``. Blendtrack's own count
(``red_light_violations``, from its signal table in Rust) stays beside it:
a signal table that missed a switch is caught here and not there.

**Emergency brakings.** SUMO warns that a vehicle "performs emergency
braking" when its deceleration over a step reaches ``decel +
threshold * (emergencyDecel - decel)`` of its vType, the threshold being
``--emergencydecel.warning-threshold`` (default 1: braking at the full
``emergencyDecel``; SUMO's car-following documentation, and its
maintainers in eclipse-sumo/sumo#14757). The same rule, on the speed change
blendtrack pushes to SUMO from one step to the next (what SUMO's check
sees), counts steps of emergency braking
of controlled vehicles (``emergency_brakings``, in the summary and per
vehicle), whose speed SUMO takes from TraCI.

**Teleports.** Every vehicle that starts a teleport (SUMO's simulation
subscription), controlled or in the background.
"""

from __future__ import annotations

import math
from itertools import compress
from operator import ne
from typing import Any

import numpy as np

from blendtrack.sumo.connection import SumoConnection
from blendtrack.sumo.network import Network

#: Signal states at which SUMO's drivers must stop (red, red-yellow).
RED_STATES = frozenset("ru")
#: Yellow: SUMO's drivers pass it when they cannot stop.
YELLOW_STATES = frozenset("yY")
#: SUMO's default ``--emergencydecel.warning-threshold``.
DEFAULT_WARNING_THRESHOLD = 1.0
#: Numerical slack on the braking threshold (m/s^2): braking at the full
#: ``emergencyDecel`` (blendtrack's own cap) counts, as SUMO's warning does.
BRAKE_EPS_MPS2 = 1e-6
#: red_lights.csv's columns: one row per crossing on red, red-yellow or yellow.
RED_LIGHT_COLUMNS = ("time_s", "vehicle", "tls", "link_index", "state", "state_at_moves")


class Incidents:
    """The run's incident counts from SUMO's state (see the module docs)."""

    def __init__(self, conn: SumoConnection, network: Network) -> None:
        self.conn = conn
        self.network = network
        #: The controlled vehicles at the last check (the runner's list)
        #: and their SUMO lanes then, in its order (None: not read).
        self._lane_ids: list[str] = []
        self._lanes: list[str | None] = []
        #: (from lane, to lane) -> (traffic light, link index) of the
        #: signalised connection between them, or None.
        self._links: dict[tuple[str, str], tuple[str, int] | None] = {}
        #: vType -> the braking (m/s^2, > 0) at which SUMO would warn.
        self._brake_limit: dict[str, float] = {}
        self._threshold: float | None = None
        #: SUMO's ``collision.action`` (read at the first step).
        self.collision_action: str | None = None
        #: The controlled vehicles at the last step and the speeds pushed to SUMO then.
        self._ids: list[str] = []
        self._speeds = np.zeros(0)
        #: (time, vehicle, traffic light, link index, state while SUMO moved
        #: the vehicles, state when blendtrack's moves were pushed) of each
        #: crossing on r, u or y.
        self.crossings: list[tuple[float, str, str, int, str, str]] = []
        #: Each light's state as read after this step's SUMO step, where the
        #: lights are not subscribed to (``Junctions.tls_state``, set by the runner).
        self.step_states: dict[str, str] = {}
        self.counts = {
            "signal_crossings_checked": 0,
            "red_light_crossings_sumo": 0,
            "yellow_light_crossings_sumo": 0,
            "emergency_brakings": 0,
            "teleports_controlled": 0,
            "teleports_background": 0,
        }

    # ------------------------------------------------------------ teleports
    def teleports(self, ids: Any, controlled: Any) -> None:
        """Vehicles starting a teleport this step (``controlled``: the ids blendtrack drives)."""
        if self.collision_action is None:
            self.collision_action = ""
            try:
                self.collision_action = str(self.conn.sumo.simulation.getOption("collision.action"))
            except Exception:
                pass  # an older SUMO without getOption
        for vid in ids:
            self.counts["teleports_controlled" if vid in controlled else "teleports_background"] += 1

    # ---------------------------------------------------------- after moves
    def after_moves(self, t: float, ids: list[str], acts: list[Any], out: dict[str, np.ndarray]) -> None:
        """This step's emergency brakings, and (with traffic lights) the
        stop lines crossed, once the step's moves are pushed to SUMO."""
        self._brakings(ids, acts, out["sumo_speed_mps"])
        if self.conn.has_tls:
            self._crossings(t, ids, acts)

    def _brakings(self, ids: list[str], acts: list[Any], speeds: np.ndarray) -> None:
        """Braking as SUMO sees it: the speed pushed now against the one
        pushed at the last step (SUMO's speed over it), over SUMO's step."""
        if ids is self._ids and len(self._speeds) == len(speeds):
            before = self._speeds  # the same vehicles in the same order (the usual case)
        else:
            last = dict(zip(self._ids, self._speeds.tolist()))
            before = np.array([last.get(vid, math.nan) for vid in ids], dtype=float)
        self._ids, self._speeds = ids, np.array(speeds, dtype=float)
        braking = (before - self._speeds) / self.conn.dt
        floor = min(self._brake_limit.values(), default=0.0)
        for i in np.flatnonzero(braking > floor).tolist():
            rec = acts[i].record
            limit = self._brake_limit.get(rec.vtype)
            if limit is None:
                limit = self._brake_limit[rec.vtype] = self._limit(rec.vtype)
            if braking[i] >= limit:
                rec.emergency_brakings += 1
                self.counts["emergency_brakings"] += 1

    def _limit(self, vtype: str) -> float:
        """The braking (m/s^2) at which SUMO warns of an emergency braking by a vehicle of ``vtype``."""
        if self._threshold is None:
            self._threshold = DEFAULT_WARNING_THRESHOLD
            try:
                self._threshold = float(self.conn.sumo.simulation.getOption("emergencydecel.warning-threshold"))
            except Exception:
                pass  # an older SUMO without getOption: its default
        vt = self.conn.sumo.vehicletype
        decel, emergency = float(vt.getDecel(vtype)), float(vt.getEmergencyDecel(vtype))
        return max(decel + self._threshold * max(emergency - decel, 0.0) - BRAKE_EPS_MPS2, decel + BRAKE_EPS_MPS2)

    def _crossings(self, t: float, ids: list[str], acts: list[Any]) -> None:
        get_lane = self.conn.get_lane_id or self.conn.sumo.vehicle.getLaneID
        prev_ids, prevs = self._lane_ids, self._lanes
        complete = True
        try:
            lanes: list[str | None] = list(map(get_lane, ids))
        except Exception:
            # One is gone (dropped by the runner): the others one by one.
            complete = False
            lanes = []
            for vid in ids:
                try:
                    lanes.append(get_lane(vid))
                except Exception:
                    lanes.append(None)
        self._lane_ids, self._lanes = ids, lanes
        if complete and ids is prev_ids and None not in prevs:
            # The same vehicles in the same order as at the last check, and
            # every lane read then and now (the usual case): compared in place.
            moved = list(compress(range(len(ids)), map(ne, prevs, lanes)))
            before = None
        else:
            before = {vid: lane for vid, lane in zip(prev_ids, prevs) if lane is not None}
            moved = [i for i, (vid, lane) in enumerate(zip(ids, lanes)) if lane and before.get(vid, lane) != lane]
        for i in moved:
            prev, now = (prevs[i] if before is None else before[ids[i]]), lanes[i]
            if not now or prev is None or prev.startswith(":"):
                continue
            link = self._link(prev, now)
            if link is not None:
                self._check(t, ids[i], acts[i].record, *link)

    def _check(self, t: float, vid: str, record: Any, tls: str, index: int) -> None:
        """A crossing of ``tls``'s link ``index``: red only if the link was red
        both while SUMO moved the vehicles (the light's subscription, as of the
        step's end) and when blendtrack's moves were pushed (read now; another
        client may have switched the light in between)."""
        tl, tc = self.conn.sumo.trafficlight, self.conn.tc
        if self.conn.light_subscriptions:
            moving = str(tl.getSubscriptionResults(tls).get(tc.TL_RED_YELLOW_GREEN_STATE, ""))
        else:
            # Not subscribed (libsumo, no step hook): the state read after
            # SUMO's step by the control step (``step_states``) is the one.
            moving = str(self.step_states.get(tls, ""))
        pushed = str(tl.getRedYellowGreenState(tls))
        a = moving[index] if 0 <= index < len(moving) else ""
        b = pushed[index] if 0 <= index < len(pushed) else ""
        self.counts["signal_crossings_checked"] += 1
        if a in RED_STATES and b in RED_STATES:
            self.counts["red_light_crossings_sumo"] += 1
            record.red_light_crossings_sumo += 1
        elif (a + b) and set(a + b) & (YELLOW_STATES | RED_STATES):
            # Yellow, or a light switched to or from red in between.
            self.counts["yellow_light_crossings_sumo"] += 1
        else:
            return
        self.crossings.append((t, vid, tls, index, a, b))

    def _link(self, prev: str, lane: str) -> tuple[str, int] | None:
        """The signalised connection out of the normal lane ``prev`` that
        ``lane`` belongs to (its first junction lane, or its target when
        the step passed the junction lanes), as (traffic light, link index)."""
        key = (prev, lane)
        if key in self._links:
            return self._links[key]
        hit: tuple[str, int] | None = None
        if lane.startswith(":"):
            c = self.network.connection_of(lane)
            if c is not None and c.getFromLane().getID() != prev:
                c = None
        else:
            c = None
            try:
                outgoing = self.network.net().getLane(prev).getOutgoing()
            except Exception:
                outgoing = []
            for o in outgoing:
                if o.getToLane().getID() == lane:
                    c = o
                    break
        if c is not None and c.getTLSID():
            hit = (str(c.getTLSID()), int(c.getTLLinkIndex()))
        self._links[key] = hit
        return hit

    def summary(self) -> dict[str, Any]:
        """The counts, and SUMO's ``collision.action`` (under ``none`` SUMO
        detects no collision: its collision output, and so
        ``collisions_all``, stay empty whatever happens)."""
        return {**self.counts, "collision_action": self.collision_action}

    def write_csv(self, file: Any) -> None:
        import csv

        with open(file, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(RED_LIGHT_COLUMNS)
            w.writerows((round(t, 6) if math.isfinite(t) else t, *rest) for t, *rest in self.crossings)
