"""The controlled vehicles: taking one over from SUMO (its state from SUMO's
pose and speed, its track, its record), letting one go (its statistics into
its record, SUMO's own driving again), and the hot loop's lists of them in a
fixed order."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from blendtrack import ControllerConfig, RouteFleet, VehicleParams
from blendtrack._blendtrack import HOLD_BRAKING_MIN_STEP_S
from blendtrack.sumo.connection import SumoConnection
from blendtrack.sumo.options import RunOptions
from blendtrack.sumo.records import RecordTotals, VehicleRecord
from blendtrack.sumo.selection import PARAM_PREFIX, Selection
from blendtrack.sumo.tracks import Active, Tracks

# Distances of the leader look-up (m).
LEADER_RANGE_M = 250.0


def euler_brake_gap(v: float, decel: float, dt: float) -> float:
    """How far a vehicle of SUMO's (Euler updates, the default) at speed ``v``
    travels braking at ``decel`` (m/s^2, > 0) until it stands, with steps of
    ``dt``: its speed drops by ``decel dt`` at the start of each step, so it
    stops about ``v dt / 2`` shorter than braking continuously
    (``MSCFModel::brakeGapEuler``)."""
    red = decel * dt
    if red <= 0.0 or v <= 0.0:
        return 0.0
    steps = int(v / red)
    return dt * (steps * v - red * steps * (steps + 1) / 2.0)


class SumoLeaders:
    """Gaps to leaders SUMO drives, shortened by what the stopping law's
    picture of them misses.

    The stopping law takes a leader to brake continuously at the follower's
    ``max_obs_deceleration`` from its observed speed, stopping after
    ``v^2 / (2 b)``. A leader SUMO drives brakes at its vType's ``decel``, and
    with SUMO's Euler updates its speed drops at the start of a step, a whole
    step early: it stops within ``euler_brake_gap`` (traced on Bologna at its
    1 s step: a follower 1.6 s behind a car braking at 3 to 4.5 m/s^2 for a
    queue still hit it, 6 to 9 m short). The gap handed to the law is
    shortened by the difference, so the law keeps that much more room, as
    SUMO's own drivers do (they take a leader to brake at its decel, with
    Euler steps). Leaders blendtrack drives brake continuously and keep
    their gap. Taking the leader's decel as the follower's (4 m/s^2 instead
    of 4.5) left one collision on Bologna (a car cutting in 18.7 m ahead,
    then braking at 4.5 m/s^2). At long steps the leader's stop point is
    also bounded by its own leader's (``second_leader_stop``).
    """

    def __init__(self, conn: SumoConnection, active: dict[str, Active], obs_decel: float) -> None:
        self.conn = conn
        self.active = active
        #: The deceleration the stopping law assumes of a leader (m/s^2, > 0).
        self.obs_decel = obs_decel
        self._decel: dict[str, float] = {}
        self._min_gap: dict[str, float] = {}

    def _decel_of(self, vid: str) -> float:
        decel = self._decel.get(vid)
        if decel is None:
            decel = self._decel[vid] = max(float(self.conn.sumo.vehicle.getDecel(vid)), self.obs_decel)
        return decel

    def _speed_of(self, vid: str) -> float:
        return max(self.conn.leader_speed(vid), 0.0)

    def correct(self, leaders: list[Any]) -> list[Any]:
        """``leaders`` (``getLeader`` results: None or (id, gap)) with each gap
        to a vehicle SUMO drives shortened, as (id, shortened gap, SUMO's
        gap); the list itself is updated.

        At steps of ``HOLD_BRAKING_MIN_STEP_S`` or more the leader's stop
        point is also bounded by its own leader's (``second_leader_stop``)."""
        dt = self.conn.dt
        b = self.obs_decel
        second = dt >= HOLD_BRAKING_MIN_STEP_S
        for k, item in enumerate(leaders):
            if not item or not item[0] or item[0] in self.active:
                continue
            lid, gap = item
            decel = self._decel_of(lid)
            v = self._speed_of(lid)
            brake = euler_brake_gap(v, decel, dt)
            short = v * v / (2.0 * b) - brake
            if second and brake > 0.0:
                bound = self.second_leader_stop(lid, gap, brake)
                if bound < gap + brake:
                    # Its stop point, max(gap, bound), as the law sees it.
                    short = gap + v * v / (2.0 * b) - max(gap, bound)
            if short > 0.0:
                # SUMO's own gap goes along: it bounds a move by lane
                # position (SUMO puts the vehicle there before anyone
                # moves). Bounded by the shortened gap, a controlled car
                # just inserted behind a queue at Eccles (seed 13, 24 s)
                # braked 3.7 m in blendtrack but stood in SUMO, and the
                # controlled car inserted behind it, planning with the
                # leader's advance, ran into it.
                leaders[k] = (lid, gap - short, gap)
        return leaders

    def second_leader_stop(self, lid: str, gap: float, brake: float) -> float:
        """Where the back of ``lid`` (a leader SUMO drives, ``gap`` ahead)
        stops at the latest, measured as ``gap`` is: no further than where
        its own leader's back stops (that one braking at its decel with
        Euler steps from its speed now), less ``lid``'s length, i.e.
        ``gap + minGap(lid) + gap2 + euler_brake_gap(v2)`` with ``gap2`` what
        ``getLeader(lid)`` gives. Only a leader within ``lid``'s own brake
        gap (``brake``) can bound it; inf without one.

        A driver of SUMO's brakes at up to its emergencyDecel (9 m/s^2 for a
        passenger car) when a vehicle cuts in just ahead of it, and a 1 s
        step's follower sees that only a step later, having planned with the
        leader braking at its decel (traced at Eccles, seed 7 at 248 s: a
        driver changed onto the lane 4.4 m ahead of a controlled vehicle at
        11 m/s, a controlled vehicle changing in from the far side 3 m ahead
        of its front; it braked from 11 to 2 m/s in the step and was run
        into). Its own leader bounds where it can get whatever it does."""
        found = self.conn.get_leader(lid, brake)
        if not found or not found[0]:
            return math.inf
        lid2, gap2 = found
        v2 = self._speed_of(lid2)
        min_gap = self._min_gap.get(lid)
        if min_gap is None:
            min_gap = self._min_gap[lid] = float(self.conn.sumo.vehicle.getMinGap(lid))
        return gap + min_gap + float(gap2) + euler_brake_gap(v2, self._decel_of(lid2), self.conn.dt)

    def forget(self, vid: str) -> None:
        """``vid`` left the simulation."""
        self._decel.pop(vid, None)
        self._min_gap.pop(vid, None)


class Controlled:
    """The vehicles blendtrack drives, their records and kept trajectories."""

    def __init__(self, conn: SumoConnection, selection: Selection, tracks: Tracks, fleet: RouteFleet, options: RunOptions) -> None:
        self.conn = conn
        self.selection = selection
        self.tracks = tracks
        self.fleet = fleet
        self.opt = options
        self.active: dict[str, Active] = {}
        #: Every vehicle taken over, in the order they were (kept only with
        #: ``RunOptions.keep_records``; otherwise a record goes when its
        #: vehicle finishes, see ``finished``).
        self.records: list[VehicleRecord] = []
        #: Vehicles taken over so far.
        self.taken = 0
        #: Running sums over the finished vehicles' records.
        self.totals = RecordTotals()
        #: Called with each record when its vehicle finishes (e.g. a row of ``vehicles.csv``).
        self.finished: list[Callable[[VehicleRecord], None]] = []
        #: vid -> (trajectory rows (t, x, y, v, e, kappa), its reference points).
        self.trajectories: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        #: The vehicles keeping a trajectory.
        self.tracing: dict[str, Active] = {}
        #: Vehicles whose SUMO lane position is read next step (unknown to
        #: blendtrack, or due for a check of its prediction).
        self.read_position: set[str] = set()
        #: The controlled vehicles in a fixed order (rebuilt when one comes or
        #: goes), their ids, slots, and index by id: the hot loop's lists.
        self.order: list[Active] = []
        self.ids: list[str] = []
        self.slots = np.zeros(0, dtype=np.int64)
        self.index: dict[str, int] = {}
        self._dirty = True

    def refresh_order(self) -> None:
        """The hot loop's lists again, if a vehicle came or went."""
        if self._dirty:
            self.order = list(self.active.values())
            self.ids = [a.vid for a in self.order]
            self.slots = np.array([a.slot for a in self.order], dtype=np.int64)
            self.index = {vid: i for i, vid in enumerate(self.ids)}
            self._dirty = False

    def take_over(self, vid: str, t: float) -> None:
        """``vid`` (just departed, selected) is driven by blendtrack from now on."""
        v = self.conn.sumo.vehicle
        vtype = v.getTypeID(vid)
        info = self.selection.type_info(vtype)
        route = tuple(v.getRoute(vid))
        idx = max(int(v.getRouteIndex(vid)), 0)
        edges = route[idx:]
        if not edges:
            return
        lane_index = int(v.getLaneIndex(vid))
        geo, track = self.tracks.geometry(edges, max(lane_index, 0))
        veh: VehicleParams = info["vehicle"]
        cfg: ControllerConfig = info["config"]
        if "preferred_speed" not in self.opt.fixed_keys and PARAM_PREFIX + "preferred_speed" not in info["param_keys"]:
            cfg = cfg.replace(preferred_speed=info["max_speed"] * float(v.getSpeedFactor(vid)))
        x, y = v.getPosition(vid)
        theta = math.pi / 2.0 - math.radians(float(v.getAngle(vid)))
        overhang = max(0.5 * (info["length"] - veh.wheelbase_m), 0.0)
        reach = veh.wheelbase_m + overhang
        slot = self.fleet.add_vehicle(
            track, cfg, veh,
            reach_m=reach, length_m=info["length"], min_gap_m=info["min_gap"],
            x=x - reach * math.cos(theta), y=y - reach * math.sin(theta), theta=theta, v=float(v.getSpeed(vid)),
            name=vid, occurrence=0,
        )
        rec = VehicleRecord(vid=vid, vtype=vtype, depart_s=t)
        self.taken += 1
        if self.opt.keep_records:
            self.records.append(rec)
        self.tracks.enter(track)
        act = Active(vid=vid, slot=slot, geo=geo, route_id=v.getRouteID(vid), record=rec, track=track, route_base=idx)
        if len(self.trajectories) + len(self.tracing) < self.opt.keep_trajectories or self.opt.keep_trajectories < 0:
            act.trajectory = []
            self.tracing[vid] = act
        self.active[vid] = act
        self.tracks.note_track(act)
        self._dirty = True
        self.read_position.add(vid)
        v.setSpeedMode(vid, 0)
        v.setLaneChangeMode(vid, 0)

    def drop(self, vid: str, t: float, reason: str) -> None:
        """``vid`` is no longer driven by blendtrack (``reason``: arrived,
        teleport, collision, vanished, end, ...): its statistics go into its
        record, and unless it arrived or the run ended SUMO drives it again."""
        act = self.active.pop(vid, None)
        self.read_position.discard(vid)
        self.tracks.early.pop(vid, None)
        if act is None:
            return
        self._dirty = True
        self.tracing.pop(vid, None)
        rec = act.record
        for key, value in self.fleet.remove_vehicle(act.slot).items():
            setattr(rec, key, value)
        if act.own_track is not None:
            self.fleet.remove_route(act.own_track)
        else:
            self.tracks.leave(act.track)
        rec.end_s = t
        rec.reason = reason
        if act.trajectory is not None and act.trajectory:
            self.trajectories[vid] = (np.array(act.trajectory), act.geo.points)
        if reason == "collision":
            rec.collisions += 1
        elif reason == "teleport":
            rec.teleports += 1
        self.totals.add(rec)
        for sink in self.finished:
            sink(rec)
        if reason not in ("arrived", "end"):
            # Hand the vehicle back to SUMO's own models if it is still there.
            # setSpeed(-1) ends the last speed command: SUMO keeps applying
            # one until told otherwise, even after a teleport, so a vehicle
            # that waited at standstill would stand for good.
            self.conn.hand_back(vid)

    def note_trajectories(self, t: float, acts: list[Active], out: dict[str, np.ndarray]) -> None:
        """This step's point of each vehicle keeping a trajectory (``out``: ``RouteFleet.step``'s, in the order of ``acts``)."""
        if not self.tracing:
            return
        xf, yf, vv, ee, kk = (out[k] for k in ("x_front_m", "y_front_m", "v_mps", "lateral_error_m", "curvature_per_m"))
        index = self.index
        for act in self.tracing.values():
            j = index.get(act.vid)
            if j is not None and j < len(acts) and acts[j] is act and act.trajectory is not None:
                act.trajectory.append((t, float(xf[j]), float(yf[j]), float(vv[j]), float(ee[j]), float(kk[j])))
