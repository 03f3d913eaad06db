"""Lane changes of controlled vehicles: the ones the route needs, the ones
SUMO's lane-change model wants (tactical), courtesy to a vehicle waiting to
merge, and the soft leaders these give (a vehicle lined up behind on
another lane)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import blendtrack
from blendtrack._blendtrack import ADVANCE_MAX_M, smoothstep
from blendtrack.sumo.connection import SumoConnection
from blendtrack.sumo.geometry import RouteGeometry
from blendtrack.sumo.network import Network
from blendtrack.sumo.tracks import Active, Tracks

#: A vehicle's followers and leaders on the lane beside it: (gap m, speed m/s) each.
Neighbours = tuple[list[tuple[float, float]], list[tuple[float, float]]]

# Room kept before the end of a lane that does not continue, to change lanes (m).
LANE_CHANGE_ROOM_M = 15.0
# A lane change starts only with this gap (m), plus what the closing speed
# eats during the change, to the vehicles ahead and behind on the target lane.
LANE_CHANGE_GAP_M = 5.0
# How far (m) behind a changer's back and past the end of its change a
# vehicle on the lane beyond the target lane is looked at for a change onto
# the target lane (``LaneChanges.joining_from_beyond``).
JOIN_LOOK_M = 30.0
# How long (s) one of SUMO's drivers there is held on its lane while a change
# onto the target lane is under way, renewed each step
# (``LaneChanges.hold_far_side``).
FAR_SIDE_HOLD_S = 1.0
# A lane change takes LANE_CHANGE_S seconds of travel at the present speed
# (at least LANE_CHANGE_MIN_M, at most LANE_CHANGE_MAX_M metres, and no more
# than the lane has left): 1.6 m/s across on average, 4.8 m/s^2 of lateral
# acceleration at most for a 3.2 m lane. (At most 30 m before: a change at
# 30 m/s swept across in one second, at up to 19 m/s^2. Measured on the
# highway, 600 s, every vehicle controlled: 2 s and 60 m let in more than
# 30 m, and more than 3 s and 100 m, whose longer gaps held the mergers back.)
LANE_CHANGE_S = 2.0
LANE_CHANGE_MIN_M = 10.0
LANE_CHANGE_MAX_M = 60.0
# A change over several lanes crosses each lane between the one beside and
# the last while its body is over it: the smoothstep's lateral fraction
# times the lanes crossed within SWEEP_OVERLAP_LANES of that lane's index
# (half a lane plus half a car of 1.8 m on a 3.5 m lane), checked at
# SWEEP_SAMPLES + 1 points along the change (``LaneChanges.clear_of_sweep``).
SWEEP_OVERLAP_LANES = 0.75
SWEEP_SAMPLES = 20
# A lane change whose vehicle is still within this distance (m) of its lane's
# centre is checked again every step and given up when the room has gone.
ABORT_CHANGE_LAT_M = 0.5
# During a change the leader on the lane left behind stops counting once the
# change will have the vehicle this far (m) beside it, sideways, when its front
# comes within minGap of its back, where SUMO counts a collision
# (``LaneChanges.left_behind``), the front axle taken this far (m) behind
# the front bumper.
LANE_CHANGE_CLEAR_M = 0.5
CHANGE_AXLE_BEHIND_M = 2.0
# Courtesy to a vehicle waiting to change lanes onto a controlled vehicle's
# lane (a merge at the end of an acceleration lane): the nearest controlled
# follower on the target lane (up to COURTESY_RANGE_M behind it) that can do so
# braking at most COURTESY_DECEL_MPS2 takes it as its leader and opens the gap;
# nearer ones drive on. SUMO's drivers do the like for each other (LC2013's
# cooperative speed adaptation), but not for vehicles blendtrack drives: a
# SUMO-driven follower is asked the same through TraCI's ``openGap`` (the
# changer as reference vehicle, COURTESY_SPACE_M of extra space reached within
# 1/COURTESY_CHANGE_RATE s, braking at most COURTESY_DECEL_MPS2) where the
# changer's lane ends for its route on this edge, held while the changer waits
# and switched off (``deactivateGapControl``) the step it no longer asks.
COURTESY_DECEL_MPS2 = 2.0
COURTESY_SPACE_M = LANE_CHANGE_GAP_M + 1.0
COURTESY_CHANGE_RATE = 1.0
COURTESY_HOLD_S = 5.0
# A vehicle waiting to change lanes falls back behind one alongside on the
# target lane whose front is behind its own only while that one moves at
# this speed (m/s) or more (``LaneChanges.wait_for_gap``).
ALONGSIDE_MOVING_MPS = 1.0
COURTESY_RANGE_M = 150.0
# Lane changes the route does not need: every TACTICAL_CHECK_EVERY steps
# (staggered over the vehicles) SUMO's lane-change model (LC2013, whose state
# it keeps for every vehicle, controlled or not) is asked whether a controlled
# vehicle would change to gain speed, to keep right or to make room for a
# merger; where it would, has room by SUMO's and blendtrack's checks and drives
# at TACTICAL_MIN_SPEED_MPS or more, blendtrack makes the change (as it does
# the ones the route needs). Without them controlled vehicles keep their lane
# for good: at a merge the mainline never moves over, the ramp's traffic all
# lands on the right lane, and it jams.
TACTICAL_CHECK_EVERY = 10
TACTICAL_MIN_SPEED_MPS = 3.0
# Such a change also needs, to the target lane's follower and leader, a gap of
# LANE_CHANGE_GAP_M plus TACTICAL_HEADWAY_S of the rear one's speed plus what
# it takes the rear one to come down to the front one's speed braking at
# TACTICAL_DECEL_MPS2: nobody brakes hard for a change that is only wanted
# (SUMO's "not blocked" is by its own drivers' measure, and lets a changer cut
# in closer than blendtrack's stopping law keeps).
TACTICAL_HEADWAY_S = 1.0
TACTICAL_DECEL_MPS2 = 1.0
# Once started, such a change is given up (back to its lane) as soon as the
# room falls below the same gaps at half the headway and twice the braking
# (the margin keeps a change from being given up for a small speed change).
TACTICAL_KEEP_FACTOR = 0.5
# A vehicle whose route needs a lane change where its lane ends for the route
# and that has stood (under MISS_EXIT_SPEED_MPS) within MISS_EXIT_NEAR_END_M
# of that end for ``RunOptions.miss_exit_after_s`` seconds drives on along
# its lane and is rerouted from there to its destination
# (``LaneChanges.miss_exit``; "lost vehicles" in other traffic simulators):
# a change over several lanes of a busy motorway from a standstill needs a
# gap on every lane at once, and at Eccles one such car stood at the end of
# the weaving edge's lane 0 from 249 s to the end of the run with the
# through traffic queued behind it.
MISS_EXIT_SPEED_MPS = 0.5
MISS_EXIT_NEAR_END_M = 2.0 * LANE_CHANGE_ROOM_M
# No such change within this many metres past where SUMO has inserted a
# vehicle on an edge: SUMO inserts on a lane without seeing a vehicle that is
# changing onto it (traced: a vehicle inserted at 28 m/s behind one that
# moved onto its lane at 10 m/s ran into it).
TACTICAL_INSERTION_CLEAR_M = 200.0


class LaneChanges:
    """The lane changes under way and due, and this step's soft leaders."""

    def __init__(self, conn: SumoConnection, network: Network, tracks: Tracks, active: dict[str, Active], plan_decel: float,
                 plan_accel: float = 1.0, open_gaps: bool = True, miss_exit_after_s: float = 0.0) -> None:
        self.conn = conn
        self.network = network
        self.tracks = tracks
        #: The runner's controlled vehicles by id (read only here).
        self.active = active
        #: The deceleration (m/s^2, > 0) a vehicle plans to stop with, and
        #: the acceleration it pulls away with.
        self.plan_decel = plan_decel
        self.plan_accel = plan_accel
        #: SUMO's drivers are asked to open gaps (``RunOptions.open_gaps``).
        self.open_gaps_on = open_gaps
        #: The vehicles changing lanes.
        self.changing: dict[str, Active] = {}
        #: ``RunOptions.miss_exit_after_s`` (0: never), and how long (s)
        #: each vehicle has stood at the end of its lane waiting to change.
        self.miss_exit_after_s = miss_exit_after_s
        self._stood: dict[str, float] = {}
        #: Vehicles where a lane change is due: (vid, lane, lane position, speed).
        self.due: list[tuple[str, int, float, float]] = []
        #: This step's courtesy leaders: follower id -> (lane changer id, gap m).
        self._courtesy: dict[str, tuple[str, float]] = {}
        #: SUMO drivers asked to open a gap, follower id -> lane changer id:
        #: those with the gap controller on, and those asked this step.
        self._opening: dict[str, str] = {}
        self._asked: dict[str, str] = {}
        #: This step's target-lane leaders of vehicles waiting to change lanes:
        #: vehicle id -> (leader id, gap m).
        self._merge_leads: dict[str, tuple[str, float]] = {}
        #: This step's changers coming onto a controlled vehicle's lane ahead
        #: of it: follower id -> (lane changer id, gap m).
        self._cut_ins: dict[str, tuple[str, float]] = {}
        #: SUMO's drivers whose speed is capped this step for a changer they
        #: do not see yet (``cap_blind_follower``), and the cap.
        self._capping: dict[str, float] = {}
        #: Edge -> the furthest position SUMO has inserted a vehicle at.
        self._insertions: dict[str, float] = {}
        self.counts = {"lane_changes_aborted": 0, "courtesy_steps": 0, "merge_lead_steps": 0, "tactical_lane_changes": 0,
                       "gaps_opened": 0, "cut_in_steps": 0, "far_side_holds": 0, "blind_caps": 0,
                       "missed_exits": 0}

    def set_changing(self, act: Active, changing: tuple[int, int] | None) -> None:
        act.changing = changing
        if changing is None:
            act.tactical = False
            act.change_span = None
            self.changing.pop(act.vid, None)
        else:
            self.changing[act.vid] = act

    def drop(self, vid: str) -> None:
        """``vid`` is no longer controlled."""
        self.changing.pop(vid, None)
        self._stood.pop(vid, None)

    # ------------------------------------------------------------- under way
    def changing_leaders(self, leaders: list[Any], pos: dict[int, int] | None, index: dict[str, int]) -> None:
        """The lane changers' leaders (``leaders[pos[i]]`` for the vehicle at
        ``index[vid]`` = i, or ``leaders[i]`` when all are listed)."""
        for act in list(self.changing.values()):
            i = index[act.vid]
            k = i if pos is None else pos[i]
            leaders[k] = self.changing_leader(act, leaders[k])

    def left_behind(self, act: Active, lead: Any) -> bool:
        """During a lane change: is ``lead``, the leader on the lane the
        vehicle leaves (SUMO's ``(id, gap)``), one it leaves behind? It is
        when the change's smoothstep has the vehicle clear of it (lateral
        room ``LANE_CHANGE_CLEAR_M``) by the time the front comes within
        minGap of its back,
        with the leader standing (the worst case), and the vehicle either is
        past giving the change up (a change the route needs, over
        ``ABORT_CHANGE_LAT_M`` from its lane's centre) or could still stop
        short of it at the planning deceleration. Braking for it would keep
        the vehicle slow on its way onto the target lane (traced: a merger
        braked from 9.5 to 4.3 m/s during its change for a vehicle standing
        at the end of the acceleration lane, and the follower on the target
        lane then braked at 9 m/s^2)."""
        if act.change_span is None or act.changing is None or not lead or not lead[0] or not float(lead[1]) >= -100.0:
            return False
        v = self.conn.sumo.vehicle
        vid, lid = act.vid, str(lead[0])
        speed = max(float(v.getSpeed(vid)), 0.0)
        gap = float(lead[1])
        committed = not act.tactical and abs(float(v.getLateralLanePosition(vid))) >= ABORT_CHANGE_LAT_M
        if not committed and gap < speed * speed / (2.0 * self.plan_decel) + LANE_CHANGE_GAP_M:
            return False
        start, length = act.change_span
        lane_id = v.getLaneID(vid)
        edge = lane_id.rpartition("_")[0]
        net = self.network.net()
        try:
            lane = net.getLane(lane_id)
            spacing = 0.5 * (float(lane.getWidth()) + float(net.getLane(f"{edge}_{act.changing[1]}").getWidth()))
        except (KeyError, AttributeError, IndexError):
            # Not on the edge the change is on (a junction lane, or an edge
            # without the target lane's index: sumolib raises IndexError,
            # which ended a run at Eccles): the leader counts.
            return False
        # Where the front axle is when the front bumper comes within minGap
        # of the leader's back (SUMO's gap 0): SUMO counts a collision there
        # (``collision.mingap-factor``, 1 by default), not at the bumpers
        # (traced: highway_onramp, every vehicle controlled, seed 1, 207.5 s:
        # a car changing at 4 m/s, 1.6 m across, "collided" at gap -0.09 m
        # with a standing one this rule had left behind, judged at its back).
        back = float(v.getLanePosition(vid)) + gap
        if back + float(v.getMinGap(vid)) > float(lane.getLength()):
            return False  # beyond this lane: where lanes merge it may be ahead on the target lane too
        offset = spacing * smoothstep((back - CHANGE_AXLE_BEHIND_M - start) / max(length, 1e-6))
        return offset >= 0.5 * (float(v.getWidth(vid)) + float(v.getWidth(lid))) + LANE_CHANGE_CLEAR_M

    def changing_leader(self, act: Active, lead: Any) -> Any:
        """During a lane change SUMO reports the leader on the lane the vehicle
        is still on; the one on the target lane matters as much. Returns the
        closer of the two (or the one there is)."""
        v = self.conn.sumo.vehicle
        direction, target = act.changing  # type: ignore[misc]
        index = v.getLaneIndex(act.vid)
        if index == target or v.getRoadID(act.vid) != act.change_edge:
            # On the target lane, or past the edge of the change: over. (A
            # change that ended at its edge's end with SUMO never showing
            # the vehicle on the target lane stayed under way: two edges on,
            # on a lane of the index it had left, it was taken for barely
            # started, given up, and put back 11 m sideways onto the old
            # edge's lane, into a driver there; Eccles, 30 %, seed 7, 571 s.)
            self.set_changing(act, None)
            return lead
        if act.tactical:
            # Until SUMO puts it on the target lane nobody there sees it, and
            # a SUMO driver may move onto that lane from the far side: a
            # change that is only wanted is given up whenever its room goes.
            if not self.tactical_room(act.vid, direction, float(v.getSpeed(act.vid)), TACTICAL_KEEP_FACTOR):
                self.abort_change(act)
                return lead
        elif abs(v.getLateralLanePosition(act.vid)) < ABORT_CHANGE_LAT_M and index == act.change_from:
            # Barely started (or held at its start by a leader): the room
            # checked when it began may be gone, e.g. a follower has come up
            # on the target lane while the vehicle stood. Check again. Not
            # when it passes the centre of a lane between (a change over
            # several lanes): given up there, it was put on that lane's
            # track while SUMO had it a lane further, and stood (Eccles).
            speed = float(v.getSpeed(act.vid))
            length = change_length(speed, math.inf)
            if not self.room_for_change(act.vid, direction, speed, length):
                self.abort_change(act)
                return lead
        # getNeighbors mode: bit 0 right (1) / left (0), bit 1 leaders (2).
        side = 1 if direction < 0 else 0
        beside_leaders = v.getNeighbors(act.vid, 2 | side)
        if (target - index) * direction > 0 and self.alongside_on_target(act.vid, side, beside_leaders):
            # Past giving up by its offset, but SUMO still has it on the lane
            # it leaves (or on a lane between, in a change over several),
            # and a vehicle has come alongside on the next lane
            # (a SUMO driver moving in from the far side sees the changer
            # only once SUMO puts it there): carried over, it lands on that
            # vehicle (traced on highway_onramp: 3.3 m into a driver at
            # 27.6 m/s). It goes back, the change pending again.
            self.abort_change(act)
            return lead
        self.seen_coming(act, index, target)
        if self.left_behind(act, lead):
            lead = None
        for nid, gap in beside_leaders:
            # A neighbour alongside (gap < 0) is no obstacle ahead: braking
            # would leave the vehicle standing across both lanes.
            if gap >= 0.0:
                lead = self.tighter_leader(lead, (nid, gap))
        return lead

    def seen_coming(self, act: Active, index: int, target: int) -> None:
        """A change under way from lane ``index`` to ``target`` is seen by
        the nearest controlled vehicle behind the changer's back on each
        lane it moves onto (within ``COURTESY_RANGE_M``), which takes the
        changer as a soft leader this step (``cut_in_steps``); SUMO's
        drivers beyond the target lane are held (``hold_far_side``). SUMO
        (without the sublane model) puts the changer on a lane only once its
        centre is over the line, and nobody there saw it before: traced at
        Eccles (30 %, seed 0, 300 s), 6 of 15 collisions were a controlled
        vehicle pulling away behind one that changed over two lanes from a
        standstill in front of it. (Asking SUMO's drivers there to open a
        gap too, as for a waiting changer, did not help: Eccles, seeds
        0-11, 96 collisions with a controlled vehicle with it, 82 without.)"""
        v = self.conn.sumo.vehicle
        lane_id = str(v.getLaneID(act.vid))
        if lane_id.startswith(":") or index == target:
            return
        edge = lane_id.rpartition("_")[0]
        front = float(v.getLanePosition(act.vid))
        back = front - float(v.getLength(act.vid))
        step = 1 if target > index else -1
        self.hold_far_side(act, edge, target + step, back, front)
        for k in range(index + step, target + step, step):
            try:
                behind = self.nearest_behind(f"{edge}_{k}", back - 1e-6)
            except self.conn.errors:
                return
            if behind is None or back - behind[0] > COURTESY_RANGE_M:
                continue
            f_pos, fid = behind
            gap = back - f_pos - float(v.getMinGap(fid))
            if fid in self.active:
                old = self._cut_ins.get(fid)
                if old is None or gap < old[1]:
                    self._cut_ins[fid] = (act.vid, gap)
            else:
                self.cap_blind_follower(fid, gap, float(v.getSpeed(act.vid)))

    def cap_blind_follower(self, fid: str, gap: float, lead_speed: float) -> None:
        """One of SUMO's drivers, ``gap`` m (minGap left out) behind a
        changer coming onto its lane at ``lead_speed`` m/s that SUMO does not
        show there yet, drives this step no faster than Krauss's safe speed
        behind it, ``blind_speed`` (TraCI ``setSpeed``, released the next
        step, ``release_caps``; SUMO still applies the driver's own
        acceleration and deceleration limits and its safe speed behind its
        own leader; the cap is kept under the lane's speed limit times the
        driver's speed factor, which ``setSpeed`` would override): what the driver would
        do seeing the changer signal and move over. SUMO places a vehicle
        moved by (x, y) at the end of its step, after the others planned
        theirs, and on a lane only once its centre is over the line, so
        without the cap the driver sees the changer a step after it is on
        its lane. Traced at Eccles (30 %, seed 2, 600 s): drivers on the
        weaving lane pulled away behind a changer from 12 to 17 m/s in
        those two steps of 1 s and ran into it (21 of 64 collisions with a
        controlled vehicle over seeds 0-11 were on that lane)."""
        v = self.conn.sumo.vehicle
        try:
            speed = float(self.conn.get_speed(fid))
            cap = blind_speed(gap, lead_speed, float(v.getDecel(fid)), float(v.getTau(fid)))
            if cap >= min(speed + float(v.getAccel(fid)) * self.conn.dt, self._capping.get(fid, math.inf)):
                return
            # setSpeed overrides the driver's wish: never above its own top speed here.
            cap = min(cap, float(v.getAllowedSpeed(fid)) * float(v.getSpeedFactor(fid)))
            v.setSpeed(fid, cap)
        except self.conn.errors:
            return
        if fid not in self._capping:
            self.counts["blind_caps"] += 1
        self._capping[fid] = cap

    def release_caps(self) -> None:
        """Last step's capped drivers (``cap_blind_follower``) drive as SUMO
        would again, unless capped again this step (which comes after this
        call and before SUMO's step). A vehicle that has left is skipped."""
        v = self.conn.sumo.vehicle
        for fid in self._capping:
            try:
                v.setSpeed(fid, -1.0)
            except self.conn.errors:
                pass
        self._capping = {}

    def hold_far_side(self, act: Active, edge: str, far: int, back: float, front: float) -> None:
        """SUMO's drivers on lane ``far`` of ``edge``, beyond the target lane of ``act``'s
        change, level with it (from ``JOIN_LOOK_M`` behind its back to that
        far past the end of the change), are held on their lane for
        ``FAR_SIDE_HOLD_S`` (``changeLane`` to their own lane; renewed each
        step while the change goes on; ``far_side_holds``). They do not see
        the changer before SUMO puts it on the target lane; a driver would
        see it coming. Traced at Eccles (30 %, seed 0, 300 s): 5 of 15
        collisions with a controlled vehicle were a driver and a controlled
        vehicle moving onto the same lane from either side in the same
        step. Holding only drivers whose lane-change model showed the wish
        the step before held few (381 holds against 5,714, Eccles seeds
        0-11) and did not help: SUMO's drivers decide within the
        step (the one at Eccles, seed 0, 157 s, showed none)."""
        if act.change_span is None:
            return
        v = self.conn.sumo.vehicle
        start, length = act.change_span
        lo, hi = back - JOIN_LOOK_M, max(front, start + length) + JOIN_LOOK_M
        try:
            others = self.conn.vehicles_on(f"{edge}_{far}")
        except self.conn.errors:
            return
        for other in others:
            if other in self.active or not lo <= float(self.conn.get_lane_pos(other)) <= hi:
                continue
            try:
                v.changeLane(other, far, FAR_SIDE_HOLD_S)
            except self.conn.errors:
                continue
            self.counts["far_side_holds"] += 1

    def nearest_behind(self, lane: str, limit: float) -> tuple[float, str] | None:
        """(position, id) of the vehicle on ``lane`` whose front is furthest
        along at or before lane position ``limit``; with none there, of the
        one nearest the lane's start on the lanes leading onto it
        (``Network.feeders``), its position counted back from that start.
        A vehicle still inside the junction before the lane is as near as
        one on it: traced at Eccles (30 %, seed 0), one of SUMO's drivers
        came off a junction lane onto the weaving lane at 13 m/s where a
        controlled vehicle had just changed over two lanes, having looked
        only at the lane itself."""
        get_pos = self.conn.get_lane_pos
        best: tuple[float, str] | None = None
        for other in self.conn.vehicles_on(lane):
            at = float(get_pos(other))
            if at <= limit and (best is None or at > best[0]):
                best = (at, other)
        if best is not None:
            return best
        for feeder, dist in self.network.feeders(lane):
            for other in self.conn.vehicles_on(feeder):
                at = float(get_pos(other)) - dist
                if best is None or at > best[0]:
                    best = (at, other)
        return best

    def alongside_on_target(self, vid: str, side: int, leaders: list[tuple[str, float]]) -> bool:
        """Is a vehicle alongside ``vid`` on the lane beside it (``side``: 1
        right, 0 left), its body overlapping ``vid``'s along the road?
        ``getNeighbors`` gives such a leader (``leaders``: its answer for
        that lane's leaders) a gap below minus ``vid``'s minGap, and such a
        follower one below minus its own."""
        v = self.conn.sumo.vehicle
        if any(gap < -float(v.getMinGap(vid)) for _, gap in leaders):
            return True
        return any(gap < -float(v.getMinGap(other)) for other, gap in v.getNeighbors(vid, side))

    def abort_change(self, act: Active) -> None:
        """Back to the lane the vehicle is on, the change pending again (it is
        retried when there is room)."""
        lane_index = int(self.conn.sumo.vehicle.getLaneIndex(act.vid))
        geo, track = self.tracks.geometry(act.geo.edges, max(lane_index, 0))
        self.tracks.retrack(act, geo, track, owned=False, base=act.route_base)
        self.set_changing(act, None)
        self.counts["lane_changes_aborted"] += 1

    def begin_change(
        self, act: Active, geo: RouteGeometry, track: int, base: int, direction: int, target: int, span: tuple[float, float]
    ) -> None:
        """``act`` starts a lane change on its own ``track`` (built for it,
        from SUMO's route index ``base``), over ``span`` (front's lane
        position where it starts, length)."""
        self.tracks.retrack(act, geo, track, owned=True, base=base)
        self.set_changing(act, (direction, target))
        act.change_span = span
        act.change_from = int(self.conn.sumo.vehicle.getLaneIndex(act.vid))
        act.change_edge = str(self.conn.sumo.vehicle.getRoadID(act.vid))
        act.record.lane_changes += 1

    # ---------------------------------------------------- the route's changes
    def make_due(self) -> None:
        """The changes found due last step (``due``), made where there is room.
        A vehicle with no change due this step starts its wait for a missed
        exit (``stood_too_long``) again."""
        name = self.tracks.lanes.name
        for vid, lane, pos, speed in self.due:
            act = self.active.get(vid)
            if act is not None:
                self.try_lane_change(act, name(lane), pos, speed)
        if self._stood:
            due = {d[0] for d in self.due}
            self._stood = {vid: s for vid, s in self._stood.items() if vid in due}
        self.due = []
        self.open_gaps()
        self.release_caps()

    def open_gaps(self) -> None:
        """The SUMO drivers asked for courtesy this step open a gap for their
        changer (TraCI ``openGap``); those no longer asked, or asked by
        another changer, drive on as SUMO would (``deactivateGapControl``).
        Switched off first, then on: SUMO (1.28) keeps one gap controller
        per reference vehicle in a table that switching any controller off
        clears for its reference, and a controller left out of that table
        keeps a pointer to its reference after it has left the network
        (traced: a heap corruption crashed SUMO at Eccles). So each changer
        has at most one follower opening a gap, each follower one changer,
        and every switch-off comes before the switch-ons of the step. A
        vehicle that has left is skipped."""
        v = self.conn.sumo.vehicle
        for fid, cid in self._opening.items():
            if self._asked.get(fid) != cid:
                try:
                    v.deactivateGapControl(fid)
                except self.conn.errors:
                    pass
        for fid, cid in self._asked.items():
            if self._opening.get(fid) != cid:
                try:
                    v.openGap(fid, -1.0, COURTESY_SPACE_M, COURTESY_HOLD_S, COURTESY_CHANGE_RATE, COURTESY_DECEL_MPS2, cid)
                except self.conn.errors:
                    continue
                self.counts["gaps_opened"] += 1
        self._opening, self._asked = self._asked, {}

    def try_lane_change(self, act: Active, lane_id: str, pos: float, speed: float) -> None:
        """A lane change is due on this edge: make it once SUMO's lane-change
        model says the target lane has room (``couldChangeLane``)."""
        geo = act.geo
        if geo.pending_change is None:
            return
        k_edge, target = geo.pending_change
        edge, _, index = lane_id.rpartition("_")
        if edge != geo.edges[k_edge] or not index.isdigit() or int(index) == target:
            return
        current = int(index)
        direction = 1 if target > current else -1
        target_lane = f"{edge}_{target}"
        # SUMO's drivers are asked for a gap only where the lane ends for the
        # route on this edge, not for a change due early on a lane that goes
        # on (Eccles 30 %, seeds 0-11: asked for every waiting change,
        # arrivals fell from 0.628 to 0.594 of plain's; asked only here, 0.621).
        urgent = not geo.pending_early
        last_lane = target_lane if abs(target - current) > 1 else None
        lane_length = float(self.network.net().getLane(lane_id).getLength())
        if urgent and self.stood_too_long(act.vid, lane_length - pos, speed) and self.miss_exit(act, lane_id):
            return
        if not could_change_lane(self.conn.lane_change_state, act.vid, direction):
            self.wait_for_gap(act.vid, direction, target_lane, pos, speed, urgent, last_lane)
            return
        # SUMO a little ahead on the lane (a crawl's speed-only moves let it
        # run on): the change starts where SUMO has the front, and the
        # state is moved on to it first, never back onto the vehicle behind.
        ahead = self.sumo_ahead(act.vid, lane_id, pos)
        pos += ahead
        length = change_length(speed, lane_length - pos - 1.0)
        if length < 8.0:
            return
        # SUMO (without the sublane model) shows the vehicle on the target
        # lane only once its centre is over the line, so vehicles there do
        # not react to it before: start only with room for the whole change
        # (what the follower closes in while the vehicle covers the change's
        # length, pulling away from its present speed) plus a margin.
        if (
            not self.room_for_change(act.vid, direction, speed, length)
            or (abs(target - current) > 1 and not self.room_on_lane(act.vid, target_lane, pos, speed, length))
            or not self.room_between(act.vid, edge, current, target, pos, speed, length)
            or self.joining_from_beyond(act.vid, edge, target, direction, pos, length)
        ):
            self.wait_for_gap(act.vid, direction, target_lane, pos, speed, urgent, last_lane)
            return
        self._stood.pop(act.vid, None)
        geo2, track = self.tracks.geometry(geo.edges[k_edge:], current, change=(pos, length))
        if ahead > 0.0:
            self.tracks.fleet.advance_state(act.slot, ahead)
        self.begin_change(act, geo2, track, act.route_base + k_edge, direction, target, (pos, length))

    def stood_too_long(self, vid: str, to_end: float, speed: float) -> bool:
        """One more step of ``vid`` waiting for its change ``to_end`` m
        before its lane ends for its route: True once it has stood
        (``MISS_EXIT_SPEED_MPS``) within ``MISS_EXIT_NEAR_END_M`` of the
        end for ``miss_exit_after_s`` (never when that is 0). Moving, or
        further back, starts the count again."""
        if self.miss_exit_after_s <= 0.0 or speed >= MISS_EXIT_SPEED_MPS or to_end > MISS_EXIT_NEAR_END_M:
            self._stood.pop(vid, None)
            return False
        stood = self._stood.get(vid, 0.0) + self.conn.dt
        self._stood[vid] = stood
        return stood >= self.miss_exit_after_s

    def miss_exit(self, act: Active, lane_id: str) -> bool:
        """``act`` gives up the change it waits for and drives on along
        ``lane_id``: its route becomes this edge, then the fastest route
        SUMO's router finds from an edge the lane leads to, to its
        destination, or where none does, ``out_of_network``. True when
        rerouted; False (it waits on) when the lane leads nowhere, the
        vehicle has a stop ahead (a bus must serve its stops), or SUMO
        refuses the route."""
        v, sim = self.conn.sumo.vehicle, self.conn.sumo.simulation
        edge = lane_id.rpartition("_")[0]
        try:
            if v.getStops(act.vid, 1):
                return False
            route = tuple(v.getRoute(act.vid))
            vtype = v.getTypeID(act.vid)
            lane = self.network.net().getLane(lane_id)
        except (self.conn.errors, KeyError, IndexError):
            return False
        best = None
        vclass = v.getVehicleClass(act.vid)
        for out in lane.getOutgoing():
            nxt = out.getTo().getID()
            try:
                stage = sim.findRoute(nxt, route[-1], vtype)
            except self.conn.errors:
                continue
            if stage.edges and (best is None or stage.travelTime < best.travelTime):
                best = stage
        if best is not None:
            rest = list(best.edges)
        else:
            # No way back to the destination from here (a motorway's
            # exit): out of the network along the widest road.
            outgoing = [o.getTo() for o in lane.getOutgoing() if o.getTo().allows(vclass)]
            if not outgoing:
                return False
            rest = out_of_network(max(outgoing, key=lambda e: e.getLaneNumber()), vclass)
        try:
            v.setRoute(act.vid, [edge, *rest])
        except self.conn.errors:
            return False
        self.tracks.rebuild(act, v)
        self._stood.pop(act.vid, None)
        self.counts["missed_exits"] += 1
        act.record.missed_exits += 1
        return True

    def sumo_ahead(self, vid: str, lane_id: str, pos: float) -> float:
        """How far (m) SUMO has ``vid``'s front ahead of lane position
        ``pos`` on ``lane_id`` (where blendtrack has it after this step's
        movement), when it has it on that lane up to ``ADVANCE_MAX_M``
        ahead (``RouteFleet.advance_state``'s bound: further is a lost
        vehicle, which the placement check hands back); else 0. A stop-and-go crawl's speed-only moves let SUMO run
        on, and a lane change begun from blendtrack's state moved the car
        back onto the one behind it (Eccles, 30 %, seed 0, 459 s and
        seed 1, 576 s: 2.2-3 m back in the change's first step, a collision
        each)."""
        try:
            if self.conn.get_lane_id(vid) != lane_id:
                return 0.0
            ahead = float(self.conn.get_lane_pos(vid)) - pos
        except self.conn.errors:
            return 0.0
        return ahead if 0.0 < ahead <= ADVANCE_MAX_M else 0.0

    def wait_for_gap(
        self, vid: str, direction: int, target_lane: str, pos: float, speed: float, urgent: bool = True, last_lane: str | None = None
    ) -> None:
        """``vid`` has a lane change due and no room yet: it keeps behind the
        target lane's nearest vehicle ahead as well as its own leader, so it
        matches the target lane's speed and lines up behind that vehicle, and
        it falls back behind a vehicle alongside (taken as a leader at gap 0:
        the stopping law then keeps it a little slower) rather than drive
        level with it down the lane; the follower there is asked for
        courtesy. ``last_lane``: the last lane of a change over several
        lanes, where it falls back behind a moving vehicle alongside too
        (``alongside_on_lane``)."""
        v = self.conn.sumo.vehicle
        side = 1 if direction < 0 else 0
        near = [(nid, max(gap, 0.0)) for nid, gap in v.getNeighbors(vid, 2 | side)]
        # Not behind one alongside but behind it, standing or crawling: it
        # is no traffic to keep level with, and two vehicles each waiting
        # to change onto the other's lane stood level for good (Eccles:
        # 300 s, the queue behind both with them).
        near += [(nid, 0.0) for nid, gap in v.getNeighbors(vid, side) if gap < 0.0 and float(v.getSpeed(nid)) >= ALONGSIDE_MOVING_MPS]
        if last_lane is not None:
            near += [(nid, 0.0) for nid in self.alongside_on_lane(vid, last_lane, pos)]
        lead = None
        for cand in near:
            lead = self.tighter_leader(lead, cand)
        if lead is not None:
            self._merge_leads[vid] = lead
        self.ask_courtesy(vid, target_lane, pos, speed, urgent)

    def alongside_on_lane(self, vid: str, lane: str, front: float) -> list[str]:
        """The vehicles on ``lane`` (of ``vid``'s edge: lane positions are
        shared) whose bodies overlap ``vid``'s along the road, ``vid``'s
        front at ``front``, moving at ``ALONGSIDE_MOVING_MPS`` or more: on
        the last lane of a change over several, ``getNeighbors`` sees only
        the lane beside. Traced (``tests/test_merges.py``, early exit): a
        car on lane 2 needing lane 0 drove level with one there the whole
        edge, whose lane never had room for it, and stood 61 s at the end."""
        back = front - float(self.conn.sumo.vehicle.getLength(vid))
        out = []
        for other in self.conn.vehicles_on(lane):
            at = float(self.conn.get_lane_pos(other))
            if at > back and at - float(self.conn.sumo.vehicle.getLength(other)) < front and float(self.conn.get_speed(other)) >= ALONGSIDE_MOVING_MPS:
                out.append(other)
        return out

    def ask_courtesy(self, vid: str, target_lane: str, pos: float, speed: float, urgent: bool = True) -> None:
        """``vid`` waits to change onto ``target_lane`` with its front at
        ``pos``: the nearest controlled vehicle behind it there, within
        ``COURTESY_RANGE_M``, that can stay behind it braking at most
        ``COURTESY_DECEL_MPS2`` is given it as its leader this step (nearer
        ones, too close to brake so gently, pass). Gaps as SUMO's leader gaps
        (the changer's back less the follower's front and minGap), less the
        room the change needs."""
        v = self.conn.sumo.vehicle
        back = pos - float(v.getLength(vid))
        for fid in reversed(self.conn.vehicles_on(target_lane)):
            f_pos = float(v.getLanePosition(fid))
            if f_pos >= back:
                continue  # ahead of the changer's back, or alongside
            if back - f_pos > COURTESY_RANGE_M:
                return
            # It stays back far enough for the change to start: the changer
            # asks LANE_CHANGE_GAP_M of room (and a metre more, so a follower
            # that creeps up does not close it again).
            gap = back - f_pos - float(v.getMinGap(fid)) - LANE_CHANGE_GAP_M - 1.0
            closing = max(float(v.getSpeed(fid)) - max(speed, 0.0), 0.0)
            if gap > 0.5 and closing * closing <= 2.0 * COURTESY_DECEL_MPS2 * gap:
                if fid not in self.active:
                    if not (urgent and self.open_gaps_on):
                        continue  # not asked: as before openGap, a controlled one further back may be
                    # One follower per changer, one changer per follower (open_gaps).
                    if fid not in self._asked and vid not in self._asked.values():
                        self._asked[fid] = vid
                    return
                old = self._courtesy.get(fid)
                if old is None or gap < old[1]:
                    self._courtesy[fid] = (vid, gap)
                return

    # ------------------------------------------------------------- soft leaders
    def add_merge_leads(self, leads: list[tuple[str, tuple[str, float]]]) -> None:
        """More vehicles to line up behind this step (vehicle, (leader, gap)),
        e.g. the foe ahead at a zipper merge; with one already there, the tighter."""
        for vid, lead in leads:
            self._merge_leads[vid] = self.tighter_leader(self._merge_leads.get(vid), lead)

    def has_soft_leaders(self) -> bool:
        return bool(self._courtesy or self._merge_leads or self._cut_ins)

    def soft_leaders(self, index: dict[str, int]) -> list[tuple[int, str, float]]:
        """This step's vehicles to line up behind, as ``plan_sumo``'s
        ``soft_leaders`` (by the index of the vehicle in ``index``); taken,
        so the next step starts with none. A courtesy follower's is the lane
        changer it gives way to, a waiting changer's the vehicle it lines up
        behind. Each comes on top of the vehicle's own leader, as a soft
        obstacle: the vehicle falls back for it braking at
        ``max_deceleration`` at most, never as in an emergency (it is on
        another lane). As a leader in its place, one alongside (gap 0) had
        the merger braking at the actuator's 9 m/s^2 (traced: 26 steps at the
        limit in the mix at demand x2, SUMO's emergency-braking warnings),
        and it dropped the own leader."""
        soft = [(index.get(fid), cid, gap, "courtesy_steps") for fid, (cid, gap) in self._courtesy.items() if cid in index]
        soft += [(index.get(vid), nid, gap, "merge_lead_steps") for vid, (nid, gap) in self._merge_leads.items()]
        soft += [(index.get(fid), cid, gap, "cut_in_steps") for fid, (cid, gap) in self._cut_ins.items() if cid in index]
        self._courtesy = {}
        self._merge_leads = {}
        self._cut_ins = {}
        chosen: dict[int, tuple[str, float]] = {}
        for i, cid, gap, count in soft:
            if i is not None:
                # One per vehicle: of a courtesy and a lining-up target, the tighter.
                chosen[i] = self.tighter_leader(chosen.get(i), (cid, gap))
                self.counts[count] += 1
        return [(i, cid, gap) for i, (cid, gap) in chosen.items()]

    def tighter_leader(self, a: Any, b: tuple[str, float]) -> Any:
        """Of two leaders (SUMO's ``(id, gap)``; ``a`` may be None or empty),
        the one the stopping law brakes harder for: the smaller virtual
        obstacle distance, gap plus the leader's braking distance at the
        planning deceleration. Not simply the closer one: a near leader
        pulling away matters less than a slower one further on, and following
        only the near one runs into the other."""
        if not (a and a[0] and a[1] >= -100.0):
            return b
        speed = self.conn.get_speed
        two_b = 2.0 * self.plan_decel
        da = a[1] + max(float(speed(a[0])), 0.0) ** 2 / two_b
        db = b[1] + max(float(speed(b[0])), 0.0) ** 2 / two_b
        return b if db < da else a

    # ------------------------------------------------------------ the target lane
    def target_lane_neighbours(self, vid: str, direction: int) -> Neighbours:
        """SUMO's followers and leaders of ``vid`` on the lane beside it
        (+1 left, -1 right), each as (gap in m, its speed in m/s)."""
        v = self.conn.sumo.vehicle
        side = 0 if direction > 0 else 1  # getNeighbors: bit 0 right, bit 1 leaders
        followers = [(gap, float(v.getSpeed(nid))) for nid, gap in v.getNeighbors(vid, side)]
        leaders = [(gap, float(v.getSpeed(nid))) for nid, gap in v.getNeighbors(vid, side | 2)]
        return followers, leaders

    def target_lane_clear(self, vid: str, direction: int, speed: float, duration: float, near: Neighbours | None = None) -> bool:
        """Room on the target lane for a change lasting ``duration`` seconds:
        the gap to the follower and to the leader there, each at least
        ``LANE_CHANGE_GAP_M`` plus what the closing speed eats in that time.
        ``near``: ``target_lane_neighbours`` of this step, if read already."""
        followers, leaders = near if near is not None else self.target_lane_neighbours(vid, direction)
        return not (
            any(gap < LANE_CHANGE_GAP_M + duration * max(f_speed - speed, 0.0) for gap, f_speed in followers)
            or any(gap < LANE_CHANGE_GAP_M + duration * max(speed - l_speed, 0.0) for gap, l_speed in leaders)
        )

    def room_for_change(self, vid: str, direction: int, speed: float, length: float) -> bool:
        """``target_lane_clear`` for a change the route needs, of ``length``
        m from ``speed`` m/s: it lasts ``change_duration`` at the planning
        acceleration, at the mean speed that covers the length in that time."""
        duration = change_duration(speed, length, self.plan_accel)
        return self.target_lane_clear(vid, direction, length / duration, duration)

    def room_on_lane(self, vid: str, lane: str, front: float, speed: float, length: float, ahead: bool = True) -> bool:
        """``room_for_change`` on ``lane``, the last lane of a change over
        several (``getNeighbors`` sees only the lane beside): the nearest
        vehicle there (or coming onto it, ``nearest_behind``) level with or behind the changer's front, and the
        nearest ahead, by their lane positions (the lanes of an edge share
        them), each with the gap the closing speed needs over the change.
        Without it a change over two lanes landed on a vehicle there (a
        3-lane road with an exit two lanes over, due early: 9 collisions in
        600 s by SUMO's rule, which ``collision.action teleport`` hid).
        ``ahead`` False: the vehicle behind only (``room_between``)."""
        v = self.conn.sumo.vehicle
        get_pos, get_speed = self.conn.get_lane_pos, self.conn.get_speed
        back = front - float(v.getLength(vid))
        follower = self.nearest_behind(lane, front)
        leader: tuple[float, str] | None = None
        for other in self.conn.vehicles_on(lane) if ahead else ():
            at = float(get_pos(other))
            if at > front and (leader is None or at < leader[0]):
                leader = (at, other)
        followers, leaders = [], []
        if follower is not None:
            at, o = follower
            followers.append((back - at - float(v.getMinGap(o)), float(get_speed(o))))
        if leader is not None:
            at, o = leader
            leaders.append((at - float(v.getLength(o)) - front - float(v.getMinGap(vid)), float(get_speed(o))))
        duration = change_duration(speed, length, self.plan_accel)
        return self.target_lane_clear(vid, 0, length / duration, duration, (followers, leaders))

    def room_between(self, vid: str, edge: str, current: int, target: int, front: float, speed: float, length: float) -> bool:
        """Room behind the vehicle on every lane of ``edge`` a change from
        lane ``current`` to ``target`` crosses between the one beside
        (``room_for_change``'s) and the last (``room_on_lane``'s): the
        nearest vehicle there level with or behind the front, with the gap
        its closing speed needs over the whole change. Changes from lane 1
        to lane 4 from a standstill at Eccles crossed lane 3 of
        145852815-AddedOffRampEdge (88 m, before the off-ramp) at 1-4 m/s in
        front of drivers there at 17-19 m/s (seed 9, 220 s): 9 of the 12
        collisions with a controlled vehicle over seeds 0-23. The vehicles
        ahead on those lanes only let the change's diagonal pass behind
        them (``clear_of_sweep``): with the last lane's full check on every
        lane, the cars waited for three gaps at once, and arrivals fell
        from 0.497 to 0.405 of plain SUMO's."""
        step = 1 if target > current else -1
        return all(
            self.room_on_lane(vid, f"{edge}_{k}", front, speed, length, ahead=False)
            and self.clear_of_sweep(vid, f"{edge}_{k}", abs(k - current), abs(target - current), front, speed, length)
            for k in range(current + 2 * step, target, step)
        )

    def clear_of_sweep(self, vid: str, lane: str, j: int, n: int, front: float, speed: float, length: float) -> bool:
        """Does the changer's diagonal over lane ``j`` of the ``n`` it
        crosses (``lane``, neither the one beside nor the last) pass behind
        the vehicles ahead on it? While its body is over that lane (the
        smoothstep's lateral fraction within ``SWEEP_OVERLAP_LANES`` of the
        lane's centre) its front, pulling away at the planning acceleration,
        must stay ``minGap`` behind each one's back (at its present speed),
        SUMO's rule for a collision. Not judged before (``room_between``), a
        change over three lanes at 17 m/s swept across lane 2 of
        145852821.67 (Eccles, 30 %, seed 4, 215 s) through the place of a
        SUMO driver there at 11 m/s, 1.3 m ahead of its front, and the two
        met on the last lane."""
        v = self.conn.sumo.vehicle
        get_pos, get_speed = self.conn.get_lane_pos, self.conn.get_speed
        own_back = front - float(v.getLength(vid))
        backs = ((o, float(get_pos(o)) - float(v.getLength(o))) for o in self.conn.vehicles_on(lane) if o != vid)
        ahead = [(b, float(get_speed(o))) for o, b in backs if b + 1e-9 >= own_back]
        if not ahead:
            return True
        gap_needed = float(v.getMinGap(vid))
        for i in range(SWEEP_SAMPLES + 1):
            u = i / SWEEP_SAMPLES
            if abs(smoothstep(u) * n - j) >= SWEEP_OVERLAP_LANES:
                continue
            t = change_duration(speed, u * length, self.plan_accel)
            at = front + u * length
            if any(b + s * t - at < gap_needed for b, s in ahead):
                return False
        return True

    def joining_from_beyond(self, vid: str, edge: str, target: int, direction: int, front: float, length: float) -> bool:
        """Is a vehicle on the lane beyond ``target`` (seen from the changer)
        about to change onto it level with the change (from
        ``JOIN_LOOK_M`` behind the changer's back to that far past the end
        of the change, ``length`` m from ``front``)? One of SUMO's drivers
        whose lane-change model wants and could make that change, or a
        controlled vehicle changing there. Neither sees the changer before
        SUMO puts it on the target lane, nor the changer it: traced at
        Eccles (30 %, seed 11, 549 s), a controlled vehicle and one of SUMO's
        drivers changed onto the weaving lane in the same step from either
        side, 10 m apart, and the driver ran into it."""
        far = target + direction
        try:
            lanes = int(self.network.net().getLane(f"{edge}_{target}").getEdge().getLaneNumber())
        except Exception:
            return False
        if not 0 <= far < lanes:
            return False
        v = self.conn.sumo.vehicle
        back = front - float(v.getLength(vid))
        lo, hi = back - JOIN_LOOK_M, front + length + JOIN_LOOK_M
        toward = -direction
        import traci.constants as tc

        wish = tc.LCA_LEFT if toward > 0 else tc.LCA_RIGHT
        for other in self.conn.vehicles_on(f"{edge}_{far}"):
            if not lo <= float(v.getLanePosition(other)) <= hi:
                continue
            act = self.active.get(other)
            if act is not None:
                if act.changing is not None and act.changing[1] == target:
                    return True
                continue
            state, _ = self.conn.lane_change_state(other, toward)
            if state & wish and not state & tc.LCA_BLOCKED:
                return True
        return False

    def tactical_room(self, vid: str, direction: int, speed: float, factor: float, near: Neighbours | None = None) -> bool:
        """Gaps on the target lane for a change that is only wanted (see
        ``TACTICAL_HEADWAY_S``), the headway and braking terms scaled by
        ``factor``: 1 to start, ``TACTICAL_KEEP_FACTOR`` to go on. ``near``:
        ``target_lane_neighbours`` of this step, if read already."""
        followers, leaders = near if near is not None else self.target_lane_neighbours(vid, direction)
        return not (
            any(gap < tactical_gap(f_speed, speed, factor) for gap, f_speed in followers)
            or any(gap < tactical_gap(speed, l_speed, factor) for gap, l_speed in leaders)
        )

    # ------------------------------------------------------------ tactical
    def note_insertion(self, vid: str) -> None:
        """Where SUMO inserted ``vid``: the furthest insertion point per edge."""
        v = self.conn.sumo.vehicle
        try:
            edge, pos = v.getRoadID(vid), float(v.getLanePosition(vid))
        except Exception:
            return
        if pos > self._insertions.get(edge, -math.inf):
            self._insertions[edge] = pos

    def tactical_changes(self, order: list[Active], step: int) -> None:
        """This step's share of the controlled vehicles (every
        ``TACTICAL_CHECK_EVERY``-th of ``order``, from ``step``) change lanes
        where SUMO's lane-change model wants a change the route does not need
        and has room for it."""
        import traci.constants as tc

        state = self.conn.lane_change_state
        reasons = tc.LCA_SPEEDGAIN | tc.LCA_KEEPRIGHT | tc.LCA_COOPERATIVE
        for act in order[step % TACTICAL_CHECK_EVERY :: TACTICAL_CHECK_EVERY]:
            if act.changing is not None or self.active.get(act.vid) is not act:
                continue
            for direction in (1, -1):
                try:
                    wants, _ = state(act.vid, direction)
                except Exception:
                    break  # gone without an event: the runner's observe drops it
                side = tc.LCA_LEFT if direction > 0 else tc.LCA_RIGHT
                if wants & side and wants & reasons and not wants & (tc.LCA_BLOCKED | tc.LCA_STRATEGIC):
                    self.try_tactical_change(act, direction)
                    break

    def try_tactical_change(self, act: Active, direction: int, for_stop: bool = False) -> bool:
        """Changes ``act`` one lane over (+1 left, -1 right) on its edge, if
        the target lane goes on along the route and has room now; True when
        the change began. ``for_stop``: towards the lane of the vehicle's next
        stop (``Stops``), counted there, and made also where SUMO inserts
        vehicles just behind (a bus stop near the start of an edge where
        vehicles depart could otherwise never be reached)."""
        v = self.conn.sumo.vehicle
        try:
            lane_id = v.getLaneID(act.vid)
            speed = float(v.getSpeed(act.vid))
            pos = float(v.getLanePosition(act.vid))
            base = max(int(v.getRouteIndex(act.vid)), 0)
            rest = tuple(v.getRoute(act.vid))[base:]
        except Exception:
            return False
        geo = act.geo
        edge, _, index = lane_id.rpartition("_")
        if speed < TACTICAL_MIN_SPEED_MPS or lane_id.startswith(":") or not index.isdigit():
            return False
        k = len(geo.edges) - len(rest)
        if not rest or k < 0 or geo.edges[k:] != rest or rest[0] != edge:
            return False  # the track is not of the route from here (a rebuild is due)
        if geo.pending_change is not None and geo.pending_change[0] == k:
            return False  # the route needs a change on this edge: that one first
        if not for_stop and pos < self._insertions.get(edge, -math.inf) + TACTICAL_INSERTION_CLEAR_M:
            return False  # SUMO inserts vehicles just behind here (see TACTICAL_INSERTION_CLEAR_M)
        current = int(index)
        target = current + direction
        lane = self.network.net().getLane(lane_id)
        if not 0 <= target < lane.getEdge().getLaneNumber():
            return False
        length = change_length(speed, float(lane.getLength()) - pos - 1.0)
        if length < 8.0:
            return False
        # Both checks of the target lane on one reading of it.
        near = self.target_lane_neighbours(act.vid, direction)
        if not self.target_lane_clear(act.vid, direction, speed, length / speed, near):
            return False
        far = target + direction
        if not self.tactical_room(act.vid, direction, speed, 1.0, near) or self.changing_into(edge, target, act.vid):
            return False
        if 0 <= far < lane.getEdge().getLaneNumber() and not self.far_lane_room(act.vid, f"{edge}_{far}", pos, speed):
            return False
        try:
            geo2, track = self.tracks.geometry(rest, current, change=(pos, length, target))
        except blendtrack.PathError:
            return False  # the target lane does not go on along the route
        self.begin_change(act, geo2, track, base, direction, target, (pos, length))
        act.tactical = True
        if not for_stop:
            self.counts["tactical_lane_changes"] += 1
        return True

    def changing_into(self, edge: str, target: int, vid: str) -> bool:
        """Is another controlled vehicle changing onto lane ``target`` of
        ``edge`` (from the other side, say)? Neither would see the other on
        the target lane before SUMO puts it there."""
        v = self.conn.sumo.vehicle
        for other in self.changing.values():
            if other.vid != vid and other.changing is not None and other.changing[1] == target:
                try:
                    if v.getRoadID(other.vid) == edge:
                        return True
                except Exception:
                    continue
        return False

    def far_lane_room(self, vid: str, far_lane: str, front: float, speed: float) -> bool:
        """Gaps (``TACTICAL_KEEP_FACTOR`` of them) to the vehicles on the lane
        beyond the target lane, checked before a change that is only wanted
        starts: a SUMO driver there may move onto the target lane at the same
        time, and SUMO's drivers see the changer only once SUMO has put it
        there (a collision of one at 33 m/s, from 3.5 m behind, before this
        check). ``front``: the changer's front on its lane."""
        v = self.conn.sumo.vehicle
        back = front - float(v.getLength(vid))
        for other in self.conn.vehicles_on(far_lane):
            o_front = float(v.getLanePosition(other))
            o_speed = float(v.getSpeed(other))
            if o_front <= front:
                gap = back - o_front - float(v.getMinGap(other))
                if gap < tactical_gap(o_speed, speed, TACTICAL_KEEP_FACTOR):
                    return False
            else:
                gap = o_front - float(v.getLength(other)) - front - float(v.getMinGap(vid))
                if gap < tactical_gap(speed, o_speed, TACTICAL_KEEP_FACTOR):
                    return False
        return True


def out_of_network(first: Any, vclass: str, limit: int = 200) -> list[str]:
    """Edge ids from sumolib edge ``first`` on, each the widest next edge
    ``vclass`` may use, never one twice, until an edge leads nowhere (the
    network's edge) or ``limit`` edges."""
    edges, seen, e = [], set(), first
    while e is not None and e.getID() not in seen and len(edges) < limit:
        edges.append(e.getID())
        seen.add(e.getID())
        nxt = [x for x in e.getOutgoing() if x.allows(vclass) and x.getID() not in seen]
        e = max(nxt, key=lambda x: x.getLaneNumber()) if nxt else None
    return edges


def tactical_gap(rear: float, front: float, factor: float) -> float:
    """The gap (m) a change that is only wanted asks between a rear vehicle
    at ``rear`` m/s and a front one at ``front`` (see ``TACTICAL_HEADWAY_S``)."""
    rear, front = max(rear, 0.0), max(front, 0.0)
    return LANE_CHANGE_GAP_M + factor * (TACTICAL_HEADWAY_S * rear + max(rear * rear - front * front, 0.0) / (2.0 * TACTICAL_DECEL_MPS2))


def blind_speed(gap: float, lead_speed: float, decel: float, tau: float) -> float:
    """Krauss's safe speed (m/s) behind a leader ``gap`` m ahead (minGap
    left out) at ``lead_speed`` m/s, both braking at ``decel`` m/s^2, with
    reaction time ``tau`` s: the speed v with v tau + v^2 / (2 b) =
    gap + lead_speed^2 / (2 b), i.e. -b tau + sqrt((b tau)^2 + v_l^2 + 2 b gap);
    0 for a gap of 0 or less or not a number. A deceleration, reaction
    time or leader speed that is not a number counts as its floor (1e-3,
    0, 0): the result is always a number for ``setSpeed``."""
    if not gap > 0.0:
        return 0.0
    b = decel if decel > 1e-3 else 1e-3
    t = tau if tau > 0.0 else 0.0
    vl = lead_speed if lead_speed > 0.0 else 0.0
    room = vl * vl + 2.0 * b * gap
    return max(-b * t + math.sqrt(b * b * t * t + room), 0.0)


def change_duration(speed: float, length: float, accel: float) -> float:
    """How long (s) a lane change of ``length`` m takes a vehicle at
    ``speed`` m/s that pulls away at ``accel`` m/s^2:
    (sqrt(v^2 + 2 a L) - v) / a. From a standstill 10 m take sqrt(20) =
    4.5 s at 1 m/s^2; taken at a crawl of 1 m/s they were 10 s, during
    which traffic at 18 m/s on the target lane closes in 180 m, a gap that
    never came: a vehicle at the end of its lane waited for it until SUMO
    teleported it (Eccles, 300 s)."""
    v, a = max(speed, 0.0), max(accel, 1e-3)
    return (math.sqrt(v * v + 2.0 * a * length) - v) / a


def change_length(speed: float, room_m: float) -> float:
    """How long (m) a lane change at ``speed`` is, with ``room_m`` of lane left."""
    return min(max(LANE_CHANGE_S * abs(speed), LANE_CHANGE_MIN_M), LANE_CHANGE_MAX_M, room_m)


def could_change_lane(lane_change_state: Callable[[str, int], Any], vid: str, direction: int) -> bool:
    """TraCI's ``couldChangeLane`` on a given ``getLaneChangeState``: the
    target lane had room at SUMO's last lane-change check (and the vehicle
    did not just change)."""
    import traci.constants as tc

    state, traci_state = lane_change_state(vid, direction)
    if traci_state & tc.LCA_BLOCKED == 0 and traci_state & (tc.LCA_LEFT if direction > 0 else tc.LCA_RIGHT):
        return False  # it changed in the last step: the state no longer applies
    return bool(state != tc.LCA_UNKNOWN and state & tc.LCA_BLOCKED == 0)
