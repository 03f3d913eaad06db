"""The SUMO plugin: blendtrack controllers drive selected SUMO vehicles.

One :class:`SumoRun` owns one SUMO simulation (in-process through libsumo by
default, or over TraCI sockets, which sumo-gui needs) and a
:class:`blendtrack.RouteFleet`, which keeps every controlled vehicle's state,
route, stop-line decisions and statistics in Rust. Each simulation step:

1. SUMO advances (``simulationStep``); the per-step event lists (departed,
   arrived, teleporting, colliding) arrive through one simulation
   subscription.
2. Vehicles that left (arrived, teleported, collided, removed by another
   client) are dropped; newly departed ones that are selected are taken
   over: their state is initialised from SUMO's pose and speed, and their
   reference track is the centreline of their lane along their route
   (:mod:`blendtrack.sumo.geometry`), shared by every vehicle on the same
   route and lane, registered once with its lane pieces and stop lines.
3. The leader of every controlled vehicle is read from SUMO (its gap; its
   speed unless blendtrack drives it too), and traffic-light states (each
   light's, read after SUMO's step). ``RouteFleet.plan`` turns red and yellow lights,
   links without priority, blocked junction exits and the route's end into
   stop lines; for links without priority it asks which vehicles must
   check SUMO for approaching foes (``getNextLinks``).
4. ``RouteFleet.step`` computes every controlled vehicle's command and
   integrates its kinematic bicycle over the step, in Rust with the
   interpreter released, and says how to push each new pose to SUMO.
5. A vehicle on its lane's centreline moves with ``moveTo`` (lane, position)
   and ``setSpeed``: cheap, and SUMO keeps it on its lanes. Elsewhere (junction
   lanes, lane changes, off-centre) it moves with ``moveToXY`` (front-bumper
   centre, SUMO angle, keepRoute = 3 with the edge and lane as hints; 1 for
   a long vehicle whose front swings off its lane, see ``_keep_route``) and
   ``setSpeed``: SUMO keeps the route, so other drivers see the vehicle at
   junctions and behind them.

Python does only the SUMO calls, about three per controlled vehicle and step
(leader, move, speed); everything per vehicle that needs no SUMO call is in
Rust. blendtrack's state is authoritative for controlled vehicles; SUMO
displays them and makes everybody else react to them. What SUMO cannot
represent is counted, not hidden: a speed above the lane limit, or driving
backwards (SUMO takes displacement as forward speed), increments a warning
count.

The parts, each in its module: :mod:`~blendtrack.sumo.connection` (SUMO
itself), :mod:`~blendtrack.sumo.selection` (which vehicles, with what),
:mod:`~blendtrack.sumo.network` (static analysis of the network),
:mod:`~blendtrack.sumo.tracks` (the reference tracks),
:mod:`~blendtrack.sumo.junctions` (yielding), :mod:`~blendtrack.sumo.lanechange`
(lane changes and soft leaders) and :mod:`~blendtrack.sumo.records` (what a run
keeps). This module is the loop: observe, then plan and step, then apply.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from itertools import repeat
from pathlib import Path
from typing import Any

import numpy as np

import blendtrack
from blendtrack import RouteFleet
from blendtrack.sumo.collisions import RemoteCollisions
from blendtrack.sumo.sublane import SublaneLeaders
from blendtrack.sumo.connection import SumoConnection, loads_ok_marker, sumo_binary
from blendtrack.sumo.faults import ROUTE_INDEX_SLACK_M, PlacementCheck, repair
from blendtrack.sumo.geometry import segments_distance
from blendtrack.sumo.incidents import Incidents
from blendtrack.sumo.junctions import NOT_LOOKED_UP, YIELD_LOOKAHEAD_M, Junctions
from blendtrack.sumo.lanechange import LANE_CHANGE_ROOM_M, LaneChanges
from blendtrack.sumo.network import Network
from blendtrack.sumo.options import RunOptions
from blendtrack.sumo.records import RunResult, SampleHistograms, Trace, VehicleRecord
from blendtrack.sumo.scenario import Scenario
from blendtrack.sumo.selection import Selection, parse_ids
from blendtrack.sumo.stops import Stops
from blendtrack.sumo.tracks import Active, Tracks
from blendtrack.sumo.vehicles import LEADER_RANGE_M, Controlled, SumoLeaders
from blendtrack.sumo.zipper import Zippers

__all__ = ["RunOptions", "RunResult", "SumoRun", "VehicleRecord", "loads_ok_marker", "parse_ids", "sumo_binary"]

# Below these errors of the control point a vehicle is pushed to SUMO as
# (lane, position) at the lane centre instead of as (x, y, angle).
CHEAP_LATERAL_M = 0.15
CHEAP_HEADING_RAD = math.radians(2.0)
# A controlled vehicle's route id is compared with SUMO's every this many steps
# (rerouting is rare; a move SUMO rejects triggers the check at once).
ROUTE_CHECK_EVERY = 10
#: Steps between foldings of the fleet's plot samples into fixed-bin
#: histograms (their memory stays fixed over any run length).
SAMPLE_FOLD_STEPS = 500

#: A vehicle at least this long (m: buses, lorries) moved by (x, y) onto a
#: lane (not a junction's), not changing lanes, with its front over half
#: that lane's width off its centreline is kept on that lane (``moveToXY``
#: keepRoute 1) rather than put on the nearest lane (see ``_keep_route``).
LONG_VEHICLE_M = 8.0
#: Slack (m) on SUMO's test of whether a vehicle moved by (x, y) with
#: keepRoute 3 is still on a lane: off by more than half the lane's and
#: half its own width, SUMO takes it off the network (see ``_keep_route``).
OFF_ROAD_MARGIN_M = 0.1

# RouteFleet move codes.
_SPEED, _LANE, _XY, _INVALID, _HOLD = 0, 1, 2, 3, 4

#: What ``_observe`` gives ``plan_sumo``: (the indices of the vehicles whose
#: leaders were asked, or None for all; the leaders), the indices with a lane
#: position read, their lanes, their positions.
_Observed = tuple[tuple[list[int] | None, list[Any]], list[int], list[int], list[float]]


class SumoRun:
    """One SUMO simulation with blendtrack driving the selected vehicles."""

    def __init__(self, scenario: Scenario, options: RunOptions, out_dir: Path | None = None):
        self.scenario = scenario
        self.opt = options
        # Absolute: SUMO resolves relative output paths against the scenario's folder.
        self.out_dir = out_dir.resolve() if out_dir is not None else None
        self.conn = SumoConnection(scenario, options, self.out_dir)
        self.selection = Selection(options, self.conn)
        base_config = self.selection.base_config
        # The deceleration (m/s^2, > 0) a vehicle plans to stop with.
        plan_decel = max(abs(float(base_config.max_deceleration)), 0.5)
        self.fleet = RouteFleet(
            standstill_margin_m=options.standstill_margin_m,
            yield_lookahead_m=YIELD_LOOKAHEAD_M,
            lane_change_room_m=LANE_CHANGE_ROOM_M,
            stop_at_route_end=options.stop_at_route_end,
            lane_move_lateral_m=CHEAP_LATERAL_M,
            lane_move_heading_deg=math.degrees(CHEAP_HEADING_RAD),
            comfort_lateral_accel_mps2=scenario.comfort_lateral_accel_mps2,
            control_dt_s=options.control_dt_s,
        )
        self.network = Network(scenario.net_file)
        self.tracks = Tracks(self.fleet, self.network, base_config, options.border_margin_m, options.corridor)
        self.vehicles = Controlled(self.conn, self.selection, self.tracks, self.fleet, options)
        #: The controlled vehicles by id, and the records of all taken over.
        self.active = self.vehicles.active
        self.records = self.vehicles.records
        self.histograms = SampleHistograms()
        self.junctions = Junctions(self.conn, self.network, self.tracks, self.fleet, plan_decel,
                                   float(base_config.preferred_acceleration), controlled=self.active)
        self.lanes = LaneChanges(self.conn, self.network, self.tracks, self.active, plan_decel,
                                 float(base_config.preferred_acceleration), open_gaps=options.open_gaps,
                                 miss_exit_after_s=options.miss_exit_after_s)
        self.stops = Stops(self.conn, self.fleet, self.network, self.tracks.lanes, self.lanes)
        obs_decel = base_config.max_obs_deceleration if "max_obs_deceleration" in options.fixed_keys else base_config.max_deceleration
        self.sumo_leaders = SumoLeaders(self.conn, self.active, max(abs(float(obs_decel)), 0.5))
        self.zippers = Zippers(self.conn, self.network, self.tracks, self.active)
        self.trace = Trace()
        #: The vehicles in the simulation whose departure was seen (an id
        #: goes when its vehicle arrives, so the set stays as small as the traffic).
        #: Red-light crossings, emergency brakings and teleports from SUMO's state.
        self.incidents = Incidents(self.conn, self.network)
        self.incidents.step_states = self.junctions.tls_state
        #: The lane collisions SUMO skips for vehicles moved by (x, y) (set
        #: up once SUMO runs), and those found: (time, collider, victim, lane,
        #: collider's vType, victim's vType).
        self.remote_collisions = RemoteCollisions(None, "", -1.0)
        self.sublane = SublaneLeaders(None, 0.0)
        self.remote_found: list[tuple[float, str, str, str, str, str]] = []
        self._seen: set[str] = set()
        #: Vehicles left to SUMO (not selected, or not drivable).
        self._background = 0
        #: Control steps so far.
        self._steps = 0
        # Events with no per-vehicle record; collisions, teleports and red-light
        # crossings are summed from the records.
        self.counts = {"vanished": 0, "takeover_failures": 0, "reroutes": 0, "collision_events": 0, "placement_faults": 0, "route_index_repairs": 0,
                       "fanout_retracks": 0}
        #: Per controlled vehicle: the lane that fans out it was last asked
        #: about, and on which occurrence of its edge (``_follow_fanouts``).
        self._fanout_asked: dict[str, tuple[str, int]] = {}
        self.placement = PlacementCheck(self.tracks.lanes.names, self.network)
        #: Vehicles whose route index was repaired, by the lane they were on
        #: then: moved by lane position, not (x, y), while on it.
        self._by_lane: dict[str, int] = {}
        self.step_hooks: list[Callable[[SumoRun, float], None]] = []
        #: SUMO's time when the run started (the scenario's begin).
        self.begin_s = 0.0
        #: Moves by kind (see RouteFleet): speed only, nothing to send,
        #: (lane, position), (x, y, angle).
        self.moves = {"speed": 0, "none": 0, "lane": 0, "xy": 0, "xy_on_track": 0}
        #: (time, vehicle, traffic light, link index, stop line arc length) of each red-light crossing.
        self.violations: list[tuple[Any, ...]] = []

    @property
    def sumo(self) -> Any:
        """SUMO's API (libsumo, or the TraCI connection) while the run is on; None otherwise."""
        return self.conn.sumo

    # ---------------------------------------------------------------- vehicles
    def _drop(self, vid: str, t: float, reason: str) -> None:
        """``vid`` is no longer controlled (see ``Controlled.drop``)."""
        self.vehicles.drop(vid, t, reason)
        self.lanes.drop(vid)
        self.stops.drop(vid)
        self.placement.forget(vid)
        self.junctions.forget(vid)
        self._fanout_asked.pop(vid, None)

    def _rebuild(self, act: Active) -> None:
        """The route changed (rerouting): a new track from where the vehicle is."""
        self.tracks.rebuild(act, self.conn.sumo.vehicle)
        self.lanes.set_changing(act, None)
        self.counts["reroutes"] += 1

    # -------------------------------------------------------------------- run
    def run(self) -> RunResult:
        wall0 = time.perf_counter()
        # A step hook may switch a light after SUMO's step: the lights'
        # subscriptions then keep the state the step ran under.
        self.conn.subscribe_lights = bool(self.step_hooks)
        self.conn.start()
        self.fleet.ballistic = self._ballistic()
        self.remote_collisions = RemoteCollisions(self.conn.sumo.vehicle, *self._collision_options(), self.conn.sumo.lane,
                                                  self.network.ways_from, self.network.through_length)
        self.sublane = SublaneLeaders(self.conn.sumo.vehicle, self._lateral_resolution())
        completed = False
        try:
            end = self.opt.end_s if self.opt.end_s is not None else self.scenario.default_end_s
            steps = self._loop(end)
            completed = True
        finally:
            t_end = self.conn.time()
            if not completed:
                # The run broke off: the vehicles still driving did not finish (no rows for them).
                self.vehicles.finished.clear()
            for vid in list(self.active):
                self._drop(vid, t_end, "end")
            self.conn.close()
        wall = time.perf_counter() - wall0
        self.histograms.add(self.fleet.take_samples())
        return RunResult(self.records, self._summary(t_end, steps, wall), self.vehicles.trajectories, self.histograms,
                         self.vehicles.totals)

    def _type_of(self, vid: str) -> str:
        try:
            return str(self.conn.sumo.vehicle.getTypeID(vid))
        except Exception:
            return ""

    def _ballistic(self) -> bool:
        """Does SUMO move vehicles by the ballistic update
        (``--step-method.ballistic``, in the scenario's configuration or
        ``--sumo-args``)? A speed sent then carries a vehicle the mean of
        its old and new speed over the step, not the new one (SUMO's
        default, Euler): the RouteFleet works its moves out for that. Before
        it did, a Bologna run under ballistic had 240 collisions with a
        controlled vehicle, where the same run under Euler had 1 (30 %,
        seed 0, 600 s)."""
        try:
            return str(self.conn.sumo.simulation.getOption("step-method.ballistic")).lower() == "true"
        except Exception:
            return False  # an older SUMO without getOption: its default

    def _lateral_resolution(self) -> float:
        """SUMO's ``lateral-resolution`` (> 0: the sublane model; -1 if not to be read)."""
        try:
            return float(self.conn.sumo.simulation.getOption("lateral-resolution"))
        except Exception:
            return -1.0  # an older SUMO without getOption

    def _collision_options(self) -> tuple[str, float]:
        """SUMO's ``collision.action`` and ``collision.mingap-factor`` ("" and -1 if not to be read)."""
        try:
            get = self.conn.sumo.simulation.getOption
            return str(get("collision.action")), float(get("collision.mingap-factor"))
        except Exception:
            return "", -1.0  # an older SUMO without getOption

    def _summary(self, t_end: float, steps: int, wall: float) -> dict[str, Any]:
        totals, counts, lanes = self.vehicles.totals, self.counts, self.lanes.counts
        return {
            "scenario": self.scenario.name,
            "sumocfg": str(self.scenario.sumocfg),
            "backend": self.conn.backend,
            "backend_note": self.conn.backend_note,
            "seed": self.opt.seed,
            "begin_s": self.begin_s,
            "end_s": t_end,
            "steps": steps,
            "step_length_s": self.conn.dt,
            "control_dt_s": self.opt.control_dt_s,
            "ballistic_update": self.fleet.ballistic,
            "controlled_vehicles": totals.vehicles,
            "background_vehicles": self._background,
            "rail_bound_not_controlled": self.selection.rail_bound_skipped,
            "takeover_failures": self.counts["takeover_failures"],
            "collisions": counts["collision_events"],
            "collisions_remote_checked": len(self.remote_found),
            "controlled_vehicles_in_collisions": totals.collisions,
            "teleports": totals.teleports,
            "red_light_violations": totals.red_light_violations,
            "vanished": counts["vanished"],
            "speed_warnings": totals.speed_warnings,
            "reverse_warnings": totals.reverse_warnings,
            "wall_time_s": wall,
            "steps_per_second": steps / wall if wall > 0 else math.nan,
            "comfort_lateral_accel_mps2": self.scenario.comfort_lateral_accel_mps2,
            "border_margin_m": self.opt.border_margin_m,
            "corridor": self.opt.corridor,
            "stop_at_route_end": self.opt.stop_at_route_end,
            "tactical_lane_changes_enabled": self.opt.tactical_lane_changes,
            "open_gaps_enabled": self.opt.open_gaps,
            "miss_exit_after_s": self.opt.miss_exit_after_s,
            "moves_speed_only": self.moves["speed"],
            "moves_none": self.moves["none"],
            "moves_lane_position": self.moves["lane"],
            "moves_xy": self.moves["xy"],
            "moves_xy_on_track": self.moves["xy_on_track"],
            "reroutes": counts["reroutes"],
            "fanout_retracks": counts["fanout_retracks"],
            "placement_faults": counts["placement_faults"],
            "route_index_repairs": counts["route_index_repairs"],
            "lane_changes_aborted": lanes["lane_changes_aborted"],
            "inside_junction_waits": self.junctions.counts["inside_junction_waits"],
            "waiting_point_waits": self.junctions.counts["waiting_point_waits"],
            "keep_clear_waits": self.junctions.counts["keep_clear_waits"],
            "entered_across_waits": self.junctions.counts["entered_across_waits"],
            "courtesy_steps": lanes["courtesy_steps"],
            "cut_in_steps": lanes["cut_in_steps"],
            "far_side_holds": lanes["far_side_holds"],
            "blind_caps": lanes["blind_caps"],
            "gaps_opened": lanes["gaps_opened"],
            "merge_lead_steps": lanes["merge_lead_steps"],
            "tactical_lane_changes": lanes["tactical_lane_changes"],
            "missed_exits": lanes["missed_exits"],
            **self.stops.counts,
            **self.incidents.summary(),
            "zipper_steps": self.zippers.counts["zipper_steps"],
        }

    def _loop(self, end: float | None) -> int:
        sumo = self.conn.sumo
        bar = None
        # (A scenario's begin can be hours in: Braunschweig's 15:0:0 in SUMO's tools/game.)
        self.begin_s = float(sumo.simulation.getTime())
        last_t = float(int(self.begin_s))
        if self.opt.progress and end is not None:
            from tqdm import tqdm

            bar = tqdm(total=max(round(end - last_t), 0), unit="sim s", desc=self.scenario.name, leave=False, dynamic_ncols=True)
        steps = 0
        while True:
            t = float(sumo.simulation.getTime())
            if end is not None and t >= end - 1e-9:
                break
            if sumo.simulation.getMinExpectedNumber() <= 0 and not self.active:
                break
            sumo.simulationStep()
            steps += 1
            t = float(sumo.simulation.getTime())
            for hook in self.step_hooks:
                hook(self, t)
            self._events(t)
            self.tracks.expire(t)
            if self.active:
                self._control_step(t)
            if steps % SAMPLE_FOLD_STEPS == 0:
                self.histograms.add(self.fleet.take_samples())
            if bar is not None and t - last_t >= 1.0:
                bar.update(int(t) - int(last_t))
                last_t = float(int(t))
        if bar is not None:
            bar.close()
        return steps

    def _events(self, t: float) -> None:
        """This step's arrivals, teleports, collisions and departures."""
        sumo, tc = self.conn.sumo, self.conn.tc
        ev = sumo.simulation.getSubscriptionResults()
        remote = self.remote_collisions
        for vid in ev.get(tc.VAR_ARRIVED_VEHICLES_IDS, ()):
            remote.forget(vid)
            self._drop(vid, t, "arrived")
            self._seen.discard(vid)
            self.sumo_leaders.forget(vid)
            self.sublane.forget(vid)
        teleporting = ev.get(tc.VAR_TELEPORT_STARTING_VEHICLES_IDS, ())
        colliding = list(ev.get(tc.VAR_COLLIDING_VEHICLES_IDS, ()))
        self.incidents.teleports(teleporting, self.active)
        # Under collision.action teleport SUMO teleports the collider in the
        # step of the collision: it is dropped for the collision below, not
        # for a teleport (dropped first, it was no longer controlled when the
        # collision was counted: a collision with a controlled vehicle in
        # SUMO's own output, 0 in the summary and the CLI's line).
        in_collision = set(colliding)
        for vid in teleporting:
            remote.forget(vid)
            if vid in self.active and vid not in in_collision:
                self._drop(vid, t, "teleport")
        reported: set[tuple[str, str]] = set()
        if colliding:
            # Events, not vehicles: one collision of two controlled
            # vehicles is one event and two vehicle records.
            for c in sumo.simulation.getCollisions():
                reported.add((c.collider, c.victim))
                if c.collider in self.active or c.victim in self.active:
                    self.counts["collision_events"] += 1
        if remote.active:
            # The ones SUMO skipped (a vehicle moved by (x, y) under
            # collision.action teleport): counted and handled alike.
            for collider, victim, lane in remote.check(t, reported):
                self.remote_found.append((t, collider, victim, lane, self._type_of(collider), self._type_of(victim)))
                if collider in self.active or victim in self.active:
                    self.counts["collision_events"] += 1
                colliding += [collider, victim]
        for vid in colliding:
            if vid in self.active:
                self._drop(vid, t, "collision")
        for vid in ev.get(tc.VAR_DEPARTED_VEHICLES_IDS, ()):
            if vid in self._seen:
                continue
            self._seen.add(vid)
            if self.opt.tactical_lane_changes:
                self.lanes.note_insertion(vid)
            vtype = sumo.vehicle.getTypeID(vid)
            if self.selection.is_selected(vid, vtype, self.vehicles.taken):
                try:
                    self.vehicles.take_over(vid, t)
                    if vid in self.active:
                        self.stops.take_over(self.active[vid])
                except blendtrack.PathError:
                    # An undrivable route: leave it to SUMO, and say so.
                    self.counts["takeover_failures"] += 1
                    self._background += 1
            else:
                self._background += 1

    def _control_step(self, t: float) -> None:
        """Observe, then plan and step, then apply."""
        self._steps += 1
        self.conn.new_step()
        checked = list(self.active)
        if self.stops.pending:
            dwelling = self.stops.dwelling()
            checked = [vid for vid in checked if vid not in dwelling]
        for vid, what in self.placement.faults(checked, self.conn.sumo.vehicle, self._route_indices, self.conn.get_position):
            # Not where blendtrack put it: SUMO's again, and counted (issue 18).
            if vid in self.active and not (what == "route index" and self._repair_route_index(vid)):
                self.counts["placement_faults"] += 1
                self._drop(vid, t, "placement_fault")
        self.lanes.make_due()
        if self.opt.tactical_lane_changes and self.vehicles.order:
            self.lanes.tactical_changes(self.vehicles.order, self._steps)
        if self.conn.has_tls:
            self.junctions.lights_anew = bool(self.step_hooks) or self.conn.backend != "libsumo"
            self.junctions.refresh_tls(t)
        # The lanes' vehicle lists from here on are read after this step's
        # lane changes and repairs, once, and shared by the leader look-ups
        # and the junction checks.
        self.conn.new_step()
        (asked, leaders), read, lanes, poss = self._observe(t)
        self.lanes.add_merge_leads(self.zippers.leaders(self.vehicles.order))
        # This step's courtesy and lining-up targets are taken (and cleared)
        # even when no controlled vehicle is left to step.
        soft = self.lanes.soft_leaders(self.vehicles.index) if self.lanes.has_soft_leaders() else None
        if not self.vehicles.ids:
            return
        if self.stops.pending:
            self.stops.update()
        ids, order, fleet = self.vehicles.ids, self.vehicles.order, self.fleet
        queries = fleet.plan_sumo(self.vehicles.slots, leaders, self.conn.step_speed, read, lanes, poss, asked, soft).tolist()
        self.junctions.new_step()
        must_yield = self.junctions.must_yield
        answers = [must_yield(ids[i], order[i].slot) for i in queries]
        out = fleet.step(np.array(answers, dtype=bool), self.conn.dt)
        self._apply(t, ids, order, out)

    # ---------------------------------------------------------------- observe
    def _observe(self, t: float) -> _Observed:
        """Leaders, and where needed lane positions, of every controlled
        vehicle still in the simulation, in ``self.vehicles.order``; drops the ones
        that vanished without an event.

        The values come from getters, and only the ones needed: the leader
        every step, the lane position where RouteFleet asks for it (unknown,
        or due for a check), the route id every ``ROUTE_CHECK_EVERY`` steps.
        With libsumo they are in-process calls (under a microsecond each);
        vehicle subscriptions are not used, as with libsumo 1.28 one breaks
        every later ``simulationStep`` ("Vehicle 'x' is not known") once
        another client removes the subscribed vehicle. Over TraCI the same
        getters go over the socket: the two backends observe the same values
        at the same moments, so they drive alike (subscriptions over TraCI
        gave every position every step, and a vehicle SUMO had 1 cm into a
        junction was let go over TraCI and stood there under libsumo).
        """
        conn = self.conn
        self.vehicles.refresh_order()
        try:
            asked, leaders = self._leaders()
        except Exception:
            # Removed by another client (or otherwise gone) without an event.
            present = set(conn.sumo.vehicle.getIDList())
            for vid in [x for x in self.vehicles.ids if x not in present]:
                self.counts["vanished"] += 1
                self._drop(vid, t, "vanished")
            self.vehicles.refresh_order()
            asked, leaders = self._leaders()
        get_route = conn.get_route_id
        leave_own = self.tracks.leave_own_track
        for act in self.vehicles.order[self._steps % ROUTE_CHECK_EVERY :: ROUTE_CHECK_EVERY]:
            if get_route(act.vid) != act.route_id:
                self._rebuild(act)
            else:
                leave_own(act)
        if self.tracks.early:
            retry = self.tracks.retry_early_change
            for act in list(self.tracks.early.values()):
                retry(act)
        self._follow_fanouts()
        index, lane_id = self.vehicles.index, self.tracks.lanes.id
        get_lane, get_pos = conn.get_lane_id, conn.get_lane_pos
        read = [(i, vid) for vid in self.vehicles.read_position if (i := index.get(vid)) is not None]
        lanes = [lane_id(get_lane(vid)) for _, vid in read]
        poss = [get_pos(vid) for _, vid in read]
        if self.lanes.changing:
            assert asked is not None
            pos = {i: k for k, i in enumerate(asked)}
            # The lane changers' leaders need SUMO's word (and a look at the target lane).
            for act in self.lanes.changing.values():
                self._ask_leader(index[act.vid], pos, asked, leaders)
            self.lanes.changing_leaders(leaders, pos, index)
        return (asked, leaders), [i for i, _ in read], lanes, poss

    def _follow_fanouts(self) -> None:
        """Each controlled vehicle on a lane of its track that fans out is
        asked once there (``getBestLanes``) which junction lane SUMO's
        driver takes at its end, and put on the track that takes it
        (``Tracks.follow_fanout``). Nothing to do on a network with no such
        lane (the loop over the vehicles cost 0.7 % of a grid run)."""
        if not self.network.fanouts():
            return
        fanout_lane = self.tracks.fanout_lane
        for act in self.vehicles.order:
            lane = fanout_lane(act)
            if lane is None:
                continue
            asked = (lane, self.fleet.occurrence(act.slot))
            if self._fanout_asked.get(act.vid) == asked:
                continue
            self._fanout_asked[act.vid] = asked
            try:
                best = self.conn.sumo.vehicle.getBestLanes(act.vid)
            except self.conn.errors:
                continue
            if self.tracks.follow_fanout(act, best):
                self.counts["fanout_retracks"] += 1

    def _ask_leader(self, i: int, pos: dict[int, int], asked: list[int], leaders: list[Any]) -> int:
        """Where the leader of the vehicle at index ``i`` is in ``leaders``;
        one not asked yet is asked of SUMO now and added (to ``asked`` too)."""
        k = pos.get(i)
        if k is None:
            k = pos[i] = len(asked)
            asked.append(i)
            leaders.extend(self.sumo_leaders.correct([self.conn.get_leader(self.vehicles.ids[i], LEADER_RANGE_M)]))
        return k

    def _leaders(self) -> tuple[list[int] | None, list[Any]]:
        """Every controlled vehicle's leader as ``vehicle.getLeader`` gives it:
        (the indices of the ones asked, their leaders); RouteFleet keeps the others.
        Where controlled vehicles follow each other on a lane, SUMO's list of
        the lane's vehicles (back to front) says so at once: the one in front
        is the leader, and the gap is SUMO's own (RouteFleet knows both
        places), so only the others are asked (first on their lane, behind a
        vehicle SUMO drives, place not known): one call per such lane instead
        of one per vehicle."""
        fleet, ids = self.fleet, self.vehicles.ids
        # Under the sublane model every vehicle is asked (a driver beside
        # can reach in between two controlled vehicles following each other).
        lanes = [] if self.sublane.active else fleet.lanes_with_followers(self.vehicles.slots).tolist()
        names = self.tracks.lanes.names
        ask = fleet.leaders_on_lanes(self.vehicles.slots, lanes, self.conn.vehicles_on_lanes([names[lane] for lane in lanes])).tolist()
        asked = list(map(ids.__getitem__, ask))
        # Reads only, so all the leaders first, then all the lanes.
        leaders = list(map(self.conn.get_leader, asked, repeat(LEADER_RANGE_M)))
        order, junctions = self.vehicles.order, self.junctions
        fanouts = self.network.fanouts() if ask else {}
        displaced: list[tuple[str, Any]] = []
        for k, (i, vid, lane) in enumerate(zip(ask, asked, map(self.conn.get_lane_id, asked))):
            # Only a vehicle on a junction lane, or on a lane that fans out,
            # needs a second look.
            lead = leaders[k]
            geo = order[i].geo
            if not lane.startswith(":"):
                if not lead or not lead[0]:
                    lead = None
                if lane in fanouts:
                    lead = junctions.leader_at_fanout(vid, lane, geo.piece_lane, lead)
            else:
                if not lead or not lead[0]:
                    lead = junctions.leader_beyond(vid, geo.piece_lane, lane)
                else:
                    lead = junctions.leader_on_track(vid, geo.piece_lane, lead, lane)
                lead = junctions.leader_in_fanout(vid, lane, geo.piece_lane, lead)
            # (A lane known to have no merge ahead on this track: nothing to look for.)
            if geo.memo.get(lane, NOT_LOOKED_UP) is not None:
                merging = junctions.leader_at_merge(vid, lane, geo.piece_lane, lead, geo.memo)
                if lead is not None and merging is not lead:
                    # The leader it displaces stays an obstacle, as a soft
                    # one: the merging vehicle's stop point is the nearer
                    # now, but over a long step it drives on while a
                    # standing leader does not. Dropped, a controlled car
                    # standing 0.8 m behind a car at a red light followed a
                    # bus merging beyond the light (gap -3 m at 5.4 m/s)
                    # and drove into the car (Bologna, 203[0]).
                    displaced.append((vid, lead))
                lead = merging
            leaders[k] = lead
        if displaced:
            self.lanes.add_merge_leads(displaced)
        if self.sublane.active:
            self.sublane.new_step()
            nearest = self.sublane.nearest
            leaders = [nearest(vid, lead) for vid, lead in zip(asked, leaders)]
        return ask, self.sumo_leaders.correct(leaders)

    # ------------------------------------------------------------------ apply
    def _apply(self, t: float, ids: list[str], acts: list[Active], out: dict[str, np.ndarray]) -> None:
        """Pushes the new poses to SUMO, by the move RouteFleet chose for each:
        most only get a speed (SUMO's own movement puts them in place), some
        nothing at all; then notes what the step found."""
        moves = out["move"]
        speeds = out["sumo_speed_mps"]
        failed: list[int] = []
        conn = self.conn
        set_speed, move_to, move_xy = conn.set_speed, conn.move_to, conn.move_to_xy
        speed_idx = np.flatnonzero(moves == _SPEED).tolist()
        try:
            # The bulk: one call each, no per-vehicle Python beyond it.
            list(map(set_speed, map(ids.__getitem__, speed_idx), speeds[speed_idx].tolist()))
        except Exception:
            # A vehicle gone (removed by another client): find which, one by one.
            for i, sp in zip(speed_idx, speeds[speed_idx].tolist()):
                try:
                    set_speed(ids[i], sp)
                except Exception:
                    failed.append(i)
        self.moves["speed"] += len(speed_idx)
        self.moves["none"] += int(np.count_nonzero(moves == _HOLD))
        if self.stops.pending:
            self.stops.keep_speeds(ids, np.flatnonzero(moves == _HOLD).tolist(), speeds)
        lane_names = self.tracks.lanes.names
        if self._by_lane:
            moves = self._lane_not_xy(ids, moves, out["lane"])
        idx = np.flatnonzero(moves == _LANE)
        for i, lane, pos, sp in zip(idx.tolist(), out["lane"][idx].tolist(), out["lane_pos_m"][idx].tolist(), speeds[idx].tolist()):
            try:
                move_to(ids[i], lane_names[lane], pos)
                set_speed(ids[i], sp)
            except Exception:
                failed.append(i)
        self.moves["lane"] += len(idx)
        idx = np.flatnonzero(moves == _XY)
        edge_names, lanes = self.tracks.edges.names, out["lane"]
        moved_xy = self.remote_collisions.moved_xy
        xy_cols = (out[k][idx].tolist() for k in ("edge", "lane_index", "x_front_m", "y_front_m", "angle_deg"))
        for i, edge, lane_index, x_front, y_front, angle, sp in zip(idx.tolist(), *xy_cols, speeds[idx].tolist()):
            try:
                keep = self._keep_route(acts[i], edge_names[edge], lane_names[lanes[i]], x_front, y_front)
                move_xy(ids[i], edge_names[edge], lane_index, x_front, y_front, angle, keep)
                moved_xy(ids[i], t)
                # Without it SUMO keeps reporting the last setSpeed value,
                # and followers plan with a wrong leader speed.
                set_speed(ids[i], sp)
            except Exception:
                failed.append(i)
        self.moves["xy"] += len(idx)
        self.moves["xy_on_track"] += int(np.count_nonzero(out["xy_on_track"]))
        for i in np.flatnonzero(moves == _INVALID).tolist():
            # Unusable state (NaN): hand the vehicle back rather than move it anywhere.
            self._drop(ids[i], t, "invalid_state")
        self.placement.note(ids, out, moves != _INVALID, (moves == _LANE) | (moves == _XY))
        for i in failed:
            self._move_failed(ids[i], acts[i], t)
        self._note(t, ids, acts, out)

    def _keep_route(self, act: Active, edge: str, lane: str, x_front: float, y_front: float) -> int:
        """``moveToXY``'s keepRoute for ``act`` moved by (x, y) with its front
        at (``x_front``, ``y_front``) onto ``lane`` of ``edge`` (its track's):
        3 (the route's nearest lane, the exact lateral place), or 1 (SUMO
        keeps the vehicle on a lane of its route, drawn on the centreline).

        1 wherever 3 would take the vehicle off the network: keepRoute 3
        lets it leave the road, and SUMO does so when the front is further
        off the lane it maps to than half the lane's and half the vehicle's
        width. Off the network a vehicle is on no lane, so nobody sees it:
        at Bologna's junction 47 (58[0] -> 58[1], a 2.4 m junction lane
        turning about 170 deg) a controlled car turning at its smallest
        radius swung 3 m beyond the lane, stood off the road for three
        steps, and SUMO's driver behind drove into it (that junction had
        49 of the 75 collisions with a controlled vehicle over seeds 0-11
        at 30 % under ``collision.action warn``).

        1 also for a vehicle of ``LONG_VEHICLE_M`` or more, not changing
        lanes, on a lane that is not a junction's, with its front over half
        the lane's width off the centreline. SUMO takes the lane given only
        within half its width; a 12 m bus just out of a tight turn at
        Bologna's junction 40, its front swung 2.4 m towards lane 1 (the
        rear axle tracks the lane), stood on lane 1 to SUMO, and SUMO's
        drivers merging onto lane 0 from the junction lane beside drove into
        it (3 of 13 collisions with a controlled vehicle over seeds 0-11,
        30 %; none with this). For every vehicle length the same rule cost
        arrivals (0.781 -> 0.769 of plain SUMO's): cars' fronts that far off
        are over the other lane."""
        info = self.selection.type_info(act.record.vtype)
        front = np.array([[x_front, y_front]])
        shape_of = self.network.lane_shape
        reach = 0.5 * info["width"] - OFF_ROAD_MARGIN_M
        # The track's lane first: the front is over it in all but a few moves.
        own, own_width = shape_of(lane)
        off = segments_distance(front, own)
        if off >= 0.5 * own_width + reach and all(
            segments_distance(front, shape) >= 0.5 * width + reach
            for shape, width in map(shape_of, [x for x in self.network.edge_lanes(edge) if x != lane])
        ):
            return 1
        if act.changing is not None or lane.startswith(":") or info["length"] < LONG_VEHICLE_M:
            return 3
        return 1 if off >= 0.5 * own_width else 3

    def _note(self, t: float, ids: list[str], acts: list[Active], out: dict[str, np.ndarray]) -> None:
        """What the step found: positions to read, red-light crossings, lane
        changes due; and the trajectories and trace."""
        self.vehicles.read_position = {ids[i] for i in np.flatnonzero(out["read_position"]).tolist()}
        for i in np.flatnonzero(out["red_light"]).tolist():
            stop = self.fleet.next_stop(acts[i].slot)
            light = self.tracks.lights.name(stop[1]) if stop is not None and stop[1] >= 0 else ""
            self.violations.append((t, ids[i], light, stop[2] if stop else -1, stop[0] if stop else math.nan))
        due = np.flatnonzero(out["lane_change_due"])
        if len(due):
            v = out["v_mps"][due]
            # Where SUMO will have the front after its movement over the step:
            # the new front position (lane_pos_m is it minus v dt; under the
            # ballistic update a lane-position move's is it minus the mean
            # of two speeds times dt, so the front is read from the fleet).
            if self.fleet.ballistic:
                where = self.fleet.front_lane_position
                front = [where(acts[i].slot)[1] for i in due.tolist()]
            else:
                front = (out["lane_pos_m"][due] + v * self.conn.dt).tolist()
            self.lanes.due = [
                (ids[i], lane, pos, sp) for i, lane, pos, sp in zip(due.tolist(), out["lane"][due].tolist(), front, v.tolist())
            ]
        self.incidents.after_moves(t, ids, acts, out)
        self.vehicles.note_trajectories(t, acts, out)
        if self.opt.trace:
            self.trace.add(t, ids, out, self.tracks.edges.names)

    def _route_indices(self, vid: str) -> set[int]:
        """SUMO's route indices that agree with where blendtrack has ``vid``."""
        act = self.active[vid]
        return {act.route_base + k for k in self.fleet.occurrences_near_front(act.slot, ROUTE_INDEX_SLACK_M)}

    def _repair_route_index(self, vid: str) -> bool:
        """SUMO has ``vid`` on another occurrence of its edge: put it on
        blendtrack's lane and position with ``moveTo`` (see
        :mod:`~blendtrack.sumo.faults`); True when SUMO's index is right then."""
        act = self.active[vid]
        lane_id, pos = self.fleet.front_lane_position(act.slot)
        lane = self.tracks.lanes.names[lane_id]
        index = act.route_base + self.fleet.occurrence(act.slot)
        try:
            repaired = repair(self.conn.sumo.vehicle, vid, lane, pos, index, self._route_indices(vid))
        except Exception:
            return False
        if repaired:
            self.counts["route_index_repairs"] += 1
            self.vehicles.read_position.add(vid)
            # SUMO's moveToXY would match the same other lane again: on
            # this lane the vehicle moves by lane position instead.
            self._by_lane[vid] = self.tracks.lanes.id(lane)
        return repaired

    def _lane_not_xy(self, ids: list[str], moves: np.ndarray, lanes: np.ndarray) -> np.ndarray:
        """``moves`` with the (x, y) moves of the vehicles repaired on their
        present lane (``_by_lane``) made lane-position moves (``lane_pos_m``
        is the same for both); a vehicle on another lane is let go."""
        moves = moves.copy()
        for i in np.flatnonzero(moves == _XY).tolist():
            lane = self._by_lane.get(ids[i])
            if lane is not None and lane == lanes[i]:
                moves[i] = _LANE
        self._by_lane = {vid: ln for vid, ln in self._by_lane.items() if (i := self.vehicles.index.get(vid)) is not None and lanes[i] == ln}
        return moves

    def _move_failed(self, vid: str, act: Active, t: float) -> None:
        """SUMO rejected a move: a new route (rerouted since the last check)
        gets a new track; a vehicle that is gone is dropped."""
        try:
            rerouted = self.conn.sumo.vehicle.getRouteID(vid) != act.route_id
        except Exception:
            rerouted = False
        if rerouted:
            self._rebuild(act)
            return
        self.counts["vanished"] += 1
        self._drop(vid, t, "vanished")

    def write_trace(self, file: Path) -> None:
        self.trace.write(file)
