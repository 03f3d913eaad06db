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
   speed unless blendtrack drives it too), and traffic-light states from one
   subscription per light. ``RouteFleet.plan`` turns red and yellow lights,
   links without priority, blocked junction exits and the route's end into
   stop lines; for links without priority it asks which vehicles must
   check SUMO for approaching foes (``getNextLinks``).
4. ``RouteFleet.step`` computes every controlled vehicle's command and
   integrates its kinematic bicycle over the step, in Rust with the
   interpreter released, and says how to push each new pose to SUMO.
5. A vehicle on its lane's centreline moves with ``moveTo`` (lane, position)
   and ``setSpeed``: cheap, and SUMO keeps it on its lanes. Elsewhere (junction
   lanes, lane changes, off-centre) it moves with ``moveToXY`` (front-bumper
   centre, SUMO angle, keepRoute = 3 with the edge and lane as hints) and
   ``setSpeed``: SUMO keeps the route, so other drivers see the vehicle at
   junctions and behind them.

Python does only the SUMO calls, about three per controlled vehicle and step
(leader, move, speed); everything per vehicle that needs no SUMO call is in
Rust. blendtrack's state is authoritative for controlled vehicles; SUMO
displays them and makes everybody else react to them. What SUMO cannot
represent is counted, not hidden: a speed above the lane limit, or driving
backwards (SUMO takes displacement as forward speed), increments a warning
count.
"""

from __future__ import annotations

import hashlib
import math
import os
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

import blendtrack
from blendtrack import ControllerConfig, RouteFleet, VehicleParams
from blendtrack.sumo.geometry import RouteGeometry, _via_chain, route_geometry
from blendtrack.sumo.geometry import body_segment as _body_segment
from blendtrack.sumo.geometry import segments_distance as _segments_distance
from blendtrack.sumo.scenario import Scenario, ScenarioError

#: A vehicle's followers and leaders on the lane beside it: (gap m, speed m/s) each.
_Neighbours = tuple[list[tuple[float, float]], list[tuple[float, float]]]

#: vType parameter that marks a type as controlled.
CONTROLLED_PARAM = "blendtrack.controlled"
#: Prefix of per-vType parameter overrides, e.g. ``blendtrack.lat_blend_factor``.
PARAM_PREFIX = "blendtrack."

# Distances of the leader look-up (m).
LEADER_RANGE_M = 250.0
# Below these errors of the control point a vehicle is pushed to SUMO as
# (lane, position) at the lane centre instead of as (x, y, angle).
CHEAP_LATERAL_M = 0.15
CHEAP_HEADING_RAD = math.radians(2.0)
# Room kept before the end of a lane that does not continue, to change lanes (m).
LANE_CHANGE_ROOM_M = 15.0
# A lane change starts only with this gap (m), plus what the closing speed
# eats during the change, to the vehicles ahead and behind on the target lane.
LANE_CHANGE_GAP_M = 5.0
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
# A lane change whose vehicle is still within this distance (m) of its lane's
# centre is checked again every step and given up when the room has gone.
ABORT_CHANGE_LAT_M = 0.5
# During a change the leader on the lane left behind stops counting once the
# change will have the vehicle this far (m) beside it, sideways, when its front
# reaches it (``SumoRun._left_behind``), the front axle taken this far (m)
# behind the front bumper.
LANE_CHANGE_CLEAR_M = 0.5
CHANGE_AXLE_BEHIND_M = 2.0
# Courtesy to a vehicle waiting to change lanes onto a controlled vehicle's
# lane (a merge at the end of an acceleration lane): the nearest controlled
# follower on the target lane (up to COURTESY_RANGE_M behind it) that can do so
# braking at most COURTESY_DECEL_MPS2 takes it as its leader and opens the gap;
# nearer ones drive on. SUMO's drivers do the like for each other (LC2013's
# cooperative speed adaptation), but not for vehicles blendtrack drives.
COURTESY_DECEL_MPS2 = 2.0
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
# No such change within this many metres past where SUMO has inserted a
# vehicle on an edge: SUMO inserts on a lane without seeing a vehicle that is
# changing onto it (traced: a vehicle inserted at 28 m/s behind one that
# moved onto its lane at 10 m/s ran into it).
TACTICAL_INSERTION_CLEAR_M = 200.0
# How far before a junction without priority a vehicle asks SUMO whether foes approach (m).
YIELD_LOOKAHEAD_M = 30.0
# A controlled vehicle's route id is compared with SUMO's every this many steps
# (rerouting is rare; a move SUMO rejects triggers the check at once).
ROUTE_CHECK_EVERY = 10
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
#: Junction lanes further than this from a path (m) never carry a vehicle in
#: its way: a wide body's half width (1.25 m) plus a car's reach (0.9 m +
#: INSIDE_MARGIN_M) plus 0.5 m. Parallel lanes (3.2 m and more apart) are
#: not checked, so a junction that only joins lane after lane (a highway's
#: edges) asks nothing.
INSIDE_LANE_REACH_M = 3.0
# True once this process has started a libsumo simulation (see SumoRun.start).
_LIBSUMO_STARTED = False

# RouteFleet move codes.
_SPEED, _LANE, _XY, _INVALID, _HOLD = 0, 1, 2, 3, 4


def _sumo_home() -> str:
    home = os.environ.get("SUMO_HOME")
    if home:
        return home
    import sumo  # the eclipse-sumo wheel

    home = str(sumo.SUMO_HOME)
    os.environ["SUMO_HOME"] = home
    return home


def sumo_binary(gui: bool = False) -> str:
    """Path of the ``sumo`` (or ``sumo-gui``) binary of the installed SUMO:
    the eclipse-sumo wheel's, else ``$SUMO_HOME/bin``, else the one on PATH."""
    import shutil

    name = "sumo-gui" if gui else "sumo"
    homes = []
    try:
        import sumo  # the eclipse-sumo wheel

        homes.append(str(sumo.SUMO_HOME))
    except ImportError:
        pass
    homes.append(_sumo_home())
    for home in homes:
        path = Path(home) / "bin" / name
        if path.exists():
            return str(path)
    return shutil.which(name) or name


def _cache_dir() -> Path:
    env = os.environ.get("BLENDTRACK_CACHE_DIR")
    if env:
        return Path(env)
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "blendtrack"


def loads_ok_marker(scenario: Scenario, binary: str, sumo_args: tuple[str, ...] = ()) -> Path | None:
    """Where the runner notes that SUMO loaded ``scenario`` without error: a
    file named by a hash of the SUMO binary (path, size, modification time),
    the .sumocfg and every file its ``<input>`` names (the network, routes,
    additional files) and the extra SUMO options, under
    ``$BLENDTRACK_CACHE_DIR`` (default ``~/.cache/blendtrack``). Any change to
    them is another name, so the child check runs again. None when a file
    cannot be read (no caching)."""
    import xml.etree.ElementTree as ET

    try:
        h = hashlib.sha256()
        st = os.stat(binary)
        h.update(f"{os.path.realpath(binary)}:{st.st_size}:{st.st_mtime_ns}\n".encode())
        cfg = scenario.sumocfg
        h.update(cfg.read_bytes())
        h.update(("\n".join(sumo_args) + "\n").encode())
        files = {scenario.net_file, *scenario.route_files}
        inputs = ET.parse(cfg).getroot().find("input")
        for opt in inputs if inputs is not None else ():
            for part in opt.get("value", "").replace(",", " ").split():
                f = (cfg.parent / part).resolve()
                if f.is_file():
                    files.add(f)
        for f in sorted(files):
            h.update(f"\n{f}\n".encode())
            with open(f, "rb") as fh:
                for chunk in iter(lambda: fh.read(1 << 20), b""):
                    h.update(chunk)
    except (OSError, ET.ParseError):
        return None
    return _cache_dir() / "sumo-loads-ok" / h.hexdigest()


@dataclass
class RunOptions:
    """What a run controls and how (see ``blendtrack sumo run --help``)."""

    #: Fraction of all vehicles controlled, chosen by a seeded hash of the id.
    controlled_fraction: float | None = None
    #: vType whose vehicles are controlled.
    controlled_type: str | None = None
    #: Explicit vehicle ids to control.
    controlled_ids: tuple[str, ...] = ()
    #: Control at most this many vehicles (the first selected ones to depart).
    max_controlled: int | None = None
    #: Blend factor override for every controlled vehicle.
    alpha: float | None = None
    config: ControllerConfig | None = None
    vehicle: VehicleParams | None = None
    #: Controller keys the user set explicitly (config file, sweep): those
    #: keep their value. Otherwise ``path_width_m`` comes from the lanes'
    #: widths, ``preferred_speed`` from the vType's desired speed (maxSpeed x
    #: the vehicle's speedFactor, capped by the lane's limit), and
    #: ``max_obs_deceleration`` equals ``max_deceleration`` (why: see
    #: ``SumoRun._type_info``).
    fixed_keys: frozenset[str] = frozenset()
    end_s: float | None = None
    seed: int = 0
    backend: str = "libsumo"  # or "traci"
    gui: bool = False
    #: Write a per-step trace of the controlled vehicles.
    trace: bool = False
    fcd: bool = False
    ssm: bool = False
    #: Extra SUMO command-line options.
    sumo_args: tuple[str, ...] = ()
    progress: bool = True
    #: Keep the trajectories of this many controlled vehicles (for plots; -1 = all).
    keep_trajectories: int = 1
    #: Extra distance (m) kept to leaders and stop lines at standstill, on top
    #: of SUMO's minGap (SUMO counts a gap below minGap as a collision).
    standstill_margin_m: float = 1.0
    #: Added (m, >= 0) to each side of every lane's half width for the
    #: virtual borders (ignored when ``path_width_m`` is set): wider borders
    #: let the ray cast see further through a curve, so the curvature-aware
    #: law slows a vehicle less there.
    border_margin_m: float = 0.0
    #: Stop at the end of the route (a standing obstacle there). By default
    #: controlled vehicles, like SUMO's drivers (``arrivalSpeed="current"``),
    #: leave the network at their route's end without slowing down.
    stop_at_route_end: bool = False
    #: Let controlled vehicles change lanes where their route does not need
    #: it, when SUMO's lane-change model would (to overtake, keep right or
    #: make room): see ``TACTICAL_CHECK_EVERY``. Off by default: only the
    #: changes the route needs (see the README for what it does to a merge).
    #: Experimental: tried on 2 networks and 3 seeds; on the urban grid it
    #: adds teleports (README, known limits).
    tactical_lane_changes: bool = False

    def __post_init__(self) -> None:
        m = self.border_margin_m
        if not (isinstance(m, (int, float)) and math.isfinite(m) and m >= 0.0):
            raise ScenarioError(f"border margin {m!r} m: must be a finite number >= 0")


@dataclass
class VehicleRecord:
    """Per-vehicle accumulators for ``vehicles.csv``."""

    vid: str
    vtype: str
    depart_s: float
    end_s: float = math.nan
    reason: str = "running"
    steps: int = 0
    sum_abs_e: float = 0.0
    sum_e2: float = 0.0
    max_abs_e: float = 0.0
    #: |lateral error| sums at the rear and the front axle (the same points for every alpha).
    sum_abs_e_rear: float = 0.0
    sum_abs_e_front: float = 0.0
    sum_eth2: float = 0.0
    sum_v: float = 0.0
    max_lat_acc: float = 0.0
    sum_jerk2: float = 0.0
    jerk_n: int = 0
    last_acc: float = math.nan
    distance_m: float = 0.0
    collisions: int = 0
    teleports: int = 0
    red_light_violations: int = 0
    speed_warnings: int = 0
    reverse_warnings: int = 0
    time_above_comfort_s: float = 0.0
    lane_changes: int = 0


@dataclass
class _Active:
    """A vehicle under control (its state and statistics live in the RouteFleet)."""

    vid: str
    slot: int
    geo: RouteGeometry
    route_id: str
    record: VehicleRecord
    trajectory: list[tuple[float, float, float, float, float, float]] | None = None
    #: While a lane change is under way: (+1 left or -1 right, target lane index).
    changing: tuple[int, int] | None = None
    #: The change under way is one the route does not need (checked every step, see _changing_leader).
    tactical: bool = False
    #: The change under way: (SUMO lane position of the front where it
    #: starts, its length in m) on the lane it leaves.
    change_span: tuple[float, float] | None = None
    #: The track built for this vehicle alone (a lane change in it), removed
    #: from the RouteFleet once the vehicle leaves it; None on a shared track.
    own_track: int | None = None


@dataclass
class RunResult:
    records: list[VehicleRecord]
    summary: dict[str, Any]
    #: vid -> (trajectory rows (t, x, y, v, e, kappa), its reference points).
    trajectories: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    #: Samples of (|curvature|, speed, |lateral error|, lateral acceleration) of controlled vehicles.
    samples: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))


def _unit_hash(seed: int, vid: str) -> float:
    h = hashlib.blake2b(f"{seed}:{vid}".encode(), digest_size=8).digest()
    return int.from_bytes(h, "little") / 2.0**64


class SumoRun:
    """One SUMO simulation with blendtrack driving the selected vehicles."""

    def __init__(self, scenario: Scenario, options: RunOptions, out_dir: Path | None = None):
        self.scenario = scenario
        self.opt = options
        # Absolute: SUMO resolves relative output paths against the scenario's folder.
        self.out_dir = out_dir.resolve() if out_dir is not None else None
        self.base_config = (options.config or ControllerConfig()).replace(
            use_path_widths="path_width_m" not in options.fixed_keys
        )
        self.base_vehicle = options.vehicle or VehicleParams()
        if options.alpha is not None:
            self.base_config = self.base_config.replace(lat_blend_factor=options.alpha)
        #: The deceleration (m/s^2, > 0) a vehicle plans to stop with.
        self._plan_decel = max(abs(float(self.base_config.max_deceleration)), 0.5)
        self.fleet = RouteFleet(
            standstill_margin_m=options.standstill_margin_m,
            yield_lookahead_m=YIELD_LOOKAHEAD_M,
            lane_change_room_m=LANE_CHANGE_ROOM_M,
            stop_at_route_end=options.stop_at_route_end,
            lane_move_lateral_m=CHEAP_LATERAL_M,
            lane_move_heading_deg=math.degrees(CHEAP_HEADING_RAD),
            comfort_lateral_accel_mps2=scenario.comfort_lateral_accel_mps2,
        )
        self.active: dict[str, _Active] = {}
        self.records: list[VehicleRecord] = []
        self._geo_cache: dict[tuple[tuple[str, ...], int], tuple[RouteGeometry, int]] = {}
        #: Edge -> the furthest position SUMO has inserted a vehicle at.
        self._insertions: dict[str, float] = {}
        # SUMO's string ids interned as the small integers RouteFleet takes.
        self._lanes = _Interned()
        self._edges = _Interned()
        self._lights = _Interned()
        self._trajectories: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self._type_cache: dict[str, dict[str, Any]] = {}
        self._seen: set[str] = set()
        self._background: set[str] = set()
        self._net: Any = None
        self._tls_state: dict[str, str] = {}
        self._foes: dict[str, list[tuple[str, str | None, float, str, int]]] = {}
        #: Junction lanes that start at an internal junction (see geometry's stops).
        self._internal_vias: set[str] = set()
        self._conn_of_via: dict[str, Any] | None = None
        #: Per junction entry lane: (its path through the junction, the other
        #: junction lanes that come near it); see ``_junction_lanes``.
        self._inside: dict[str, tuple[np.ndarray, tuple[str, ...]]] = {}
        #: Per junction entry lane: its internal waiting point and the distance to it.
        self._waiting_points: dict[str, tuple[str | None, float]] = {}
        #: Lanes' vehicle lists read this step (several vehicles ask about one junction).
        self._lane_ids_step: tuple[int, dict[str, Any]] = (-1, {})
        self._trace_rows: list[tuple[Any, ...]] = []
        #: Vehicles whose SUMO lane position is read next step (unknown to
        #: blendtrack, or due for a check of its prediction).
        self._read_position: set[str] = set()
        #: The controlled vehicles in a fixed order (rebuilt when one comes or
        #: goes), their ids, slots, and index by id: the hot loop's lists.
        self._order: list[_Active] = []
        self._ids: list[str] = []
        self._slots = np.zeros(0, dtype=np.int64)
        self._index: dict[str, int] = {}
        self._order_dirty = True
        #: The vehicles keeping a trajectory, and those changing lanes.
        self._tracing: dict[str, _Active] = {}
        self._changing: dict[str, _Active] = {}
        #: Vehicles where a lane change is due: (vid, lane, lane position, speed).
        self._lane_change_due: list[tuple[str, int, float, float]] = []
        #: This step's courtesy leaders: follower id -> (lane changer id, gap m).
        self._courtesy: dict[str, tuple[str, float]] = {}
        #: This step's target-lane leaders of vehicles waiting to change lanes:
        #: vehicle id -> (leader id, gap m).
        self._merge_leads: dict[str, tuple[str, float]] = {}
        self._steps = 0
        # Events with no per-vehicle record; collisions, teleports and red-light
        # crossings are summed from the records.
        self.counts = {"vanished": 0, "takeover_failures": 0, "reroutes": 0, "collision_events": 0, "lane_changes_aborted": 0, "inside_junction_waits": 0, "courtesy_steps": 0, "merge_lead_steps": 0, "tactical_lane_changes": 0}
        self.step_hooks: list[Callable[[SumoRun, float], None]] = []
        #: Moves by kind (see RouteFleet): speed only, nothing to send,
        #: (lane, position), (x, y, angle).
        self.moves = {"speed": 0, "none": 0, "lane": 0, "xy": 0}
        #: (time, vehicle, traffic light, link index, stop line arc length) of each red-light crossing.
        self.violations: list[tuple[Any, ...]] = []
        self.sumo: Any = None
        self._tc: Any = None
        self._use_subscriptions = False
        self.backend = "libsumo"
        self.backend_note = ""

    # ------------------------------------------------------------------ SUMO
    def _command(self) -> list[str]:
        cmd = [sumo_binary(self.opt.gui), "-c", str(self.scenario.sumocfg), "--seed", str(self.opt.seed)]
        cmd += ["--no-step-log", "true", "--duration-log.disable", "true"]
        if self.out_dir is not None:
            sd = self.out_dir / "sumo"
            sd.mkdir(parents=True, exist_ok=True)
            cmd += ["--tripinfo-output", str(sd / "tripinfo.xml"), "--device.emissions.probability", "1"]
            cmd += ["--collision-output", str(sd / "collisions.xml"), "--log", str(sd / "sumo.log")]
            if self.opt.fcd:
                cmd += ["--fcd-output", str(sd / "fcd.xml")]
            if self.opt.ssm:
                cmd += [
                    "--device.ssm.probability", "1",
                    "--device.ssm.file", str(sd / "ssm.xml"),
                    "--device.ssm.measures", "TTC DRAC PET",
                    "--device.ssm.thresholds", "3.0 3.0 2.0",
                ]
        if self.opt.end_s is not None:
            cmd += ["--end", str(self.opt.end_s)]
        # SUMO refuses an option given twice: the user's replace ours.
        return cmd[:3] + _override_options(cmd[3:], list(self.opt.sumo_args))

    def start(self) -> None:
        global _LIBSUMO_STARTED
        _sumo_home()
        self.backend = "traci" if (self.opt.backend == "traci" or self.opt.gui) else "libsumo"
        if self.backend == "libsumo" and _LIBSUMO_STARTED:
            # libsumo 1.28 keeps state across simulations in one process: a
            # second simulation of the urban grid after one with every
            # vehicle moved by moveToXY crashed (segmentation fault). A
            # second run in a process therefore drives SUMO over TraCI (its
            # own process; same results, slower); run_scenario avoids this by
            # running it in a fresh process instead.
            self.backend = "traci"
            self.backend_note = "libsumo was already used in this process: TraCI instead"
        if self.backend == "traci":
            import traci
            import traci.constants as tc

            self.sumo = traci
            self._tc = tc
            self._use_subscriptions = True
            label = f"blendtrack-{os.getpid()}-{id(self)}"
            try:
                traci.start(self._command(), label=label)
            except Exception as e:  # SUMO refused the configuration
                raise ScenarioError(f"{self.scenario.sumocfg}: SUMO refused to start: {_first_line(e)}") from None
            self.sumo = traci.getConnection(label)
        else:
            import libsumo
            import traci.constants as tc  # the same constants libsumo uses

            # libsumo runs SUMO inside this process, and SUMO 1.28 crashes it
            # (segmentation fault) on some malformed networks: load the
            # configuration once in a child process first, so a bad scenario
            # is a clear error and not a dead interpreter.
            self._check_loads()

            self.sumo = libsumo
            self._tc = tc
            self._use_subscriptions = False
            _LIBSUMO_STARTED = True
            try:
                libsumo.start(self._command())
            except Exception as e:
                raise ScenarioError(f"{self.scenario.sumocfg}: SUMO refused to start: {_first_line(e)}") from None
        self.dt = float(self.sumo.simulation.getDeltaT())
        tc = self._tc
        self.sumo.simulation.subscribe(
            [
                tc.VAR_DEPARTED_VEHICLES_IDS,
                tc.VAR_ARRIVED_VEHICLES_IDS,
                tc.VAR_TELEPORT_STARTING_VEHICLES_IDS,
                tc.VAR_COLLIDING_VEHICLES_IDS,
            ]
        )
        types = set(self.sumo.vehicletype.getIDList())
        if self.opt.controlled_type is not None and self.opt.controlled_type not in types:
            self.close()
            raise ScenarioError(
                f"--controlled-type {self.opt.controlled_type!r}: no such vType in {self.scenario.sumocfg.name} "
                f"(known: {', '.join(sorted(types))})"
            )
        lights = self.sumo.trafficlight.getIDList()
        for tls in lights:
            self.sumo.trafficlight.subscribe(tls, [tc.TL_RED_YELLOW_GREEN_STATE])
        self._has_tls = bool(lights)
        self._bind_calls()

    def _bind_calls(self) -> None:
        """The per-vehicle SUMO calls of the hot loop. With libsumo, its SWIG
        functions themselves: the Python wrappers around them add about a
        third to each call (measured: setSpeed 405 vs 279 ns)."""
        v = self.sumo.vehicle
        raw: Any = None
        if self.backend == "libsumo":
            try:
                import libsumo._libsumo

                raw = libsumo._libsumo
            except ImportError:  # a libsumo built differently: its wrappers then
                raw = None

        def pick(name: str) -> Any:
            f = getattr(raw, "vehicle_" + name, None)
            return f if callable(f) else getattr(v, name)

        self._get_leader = pick("getLeader")
        self._get_speed = pick("getSpeed")
        self._get_lane_id = pick("getLaneID")
        self._get_lane_pos = pick("getLanePosition")
        self._get_route_id = pick("getRouteID")
        self._set_speed = pick("setSpeed")
        self._move_to = pick("moveTo")
        self._move_to_xy = pick("moveToXY")
        self._lane_change_state = pick("getLaneChangeState")
        lane_ids = getattr(raw, "lane_getLastStepVehicleIDs", None)
        self._lane_vehicles = lane_ids if callable(lane_ids) else self.sumo.lane.getLastStepVehicleIDs

    def _check_loads(self) -> None:
        """Loads the scenario once in a child ``sumo`` (see ``start``). A
        scenario that loaded before, byte for byte with the same SUMO binary,
        is not loaded again (``loads_ok_marker``): the check costs a second
        on the highway, once per run otherwise (batch sweeps, benchmarks)."""
        import subprocess

        binary = sumo_binary(False)
        marker = loads_ok_marker(self.scenario, binary, tuple(self.opt.sumo_args))
        if marker is not None and marker.exists():
            return
        # SUMO refuses an option given twice: the user's extra options replace
        # the check's quiet flags, and the check's --end 0 replaces theirs.
        quiet = ["--no-step-log", "true", "--duration-log.disable", "true", "--no-warnings", "true"]
        opts = _override_options(_override_options(quiet, list(self.opt.sumo_args)), ["--end", "0"])
        cmd = [binary, "-c", str(self.scenario.sumocfg), *opts]
        try:
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
        except (OSError, subprocess.TimeoutExpired) as e:
            raise ScenarioError(f"{self.scenario.sumocfg}: cannot run SUMO to check the scenario: {e}") from None
        if proc.returncode != 0:
            lines = [ln for ln in (proc.stderr + proc.stdout).splitlines() if ln.strip()]
            crash = f"SUMO crashed while loading it (signal {-proc.returncode})" if proc.returncode < 0 else f"exit code {proc.returncode}"
            errors = [ln for ln in lines if "Error" in ln] or lines or [crash]
            raise ScenarioError(f"{self.scenario.sumocfg}: SUMO refused to start: {errors[0].strip()}")
        if marker is not None:
            try:
                marker.parent.mkdir(parents=True, exist_ok=True)
                tmp = marker.with_name(marker.name + f".{os.getpid()}.tmp")
                tmp.write_text(str(self.scenario.sumocfg) + "\n")
                os.replace(tmp, marker)
            except OSError:
                pass  # no cache: the check runs again next time

    def close(self) -> None:
        if self.sumo is not None:
            try:
                self.sumo.close()
            except Exception:
                pass
            self.sumo = None

    # -------------------------------------------------------------- selection
    def _type_info(self, vtype: str) -> dict[str, Any]:
        info = self._type_cache.get(vtype)
        if info is not None:
            return info
        vt = self.sumo.vehicletype
        overrides: dict[str, Any] = {}
        vehicle_overrides: dict[str, Any] = {}
        cfg_keys = set(self.base_config.to_dict())
        veh_keys = set(self.base_vehicle.to_dict())
        controlled_param = vt.getParameter(vtype, CONTROLLED_PARAM).strip().lower()
        for key in sorted(cfg_keys | veh_keys):
            raw = vt.getParameter(vtype, PARAM_PREFIX + key)
            if raw == "":
                continue
            target = overrides if key in cfg_keys else vehicle_overrides
            current = (self.base_config.to_dict() if key in cfg_keys else self.base_vehicle.to_dict())[key]
            try:
                target[key] = _parse_like(raw, current)
            except ValueError:
                raise ScenarioError(f"vType {vtype!r}: param {PARAM_PREFIX + key} = {raw!r} is not a valid {type(current).__name__}") from None
        param_keys = {PARAM_PREFIX + k for k in (*overrides, *vehicle_overrides)}
        # max_obs_deceleration in SUMO runs, unless set explicitly
        # (RunOptions.fixed_keys or a blendtrack.* vType param): the paper assumes an
        # obstacle braking at 8 m/s^2 while the vehicle plans with 4, which at 33 m/s
        # keeps about 3 s to a leader and cuts a highway's capacity nearly in half
        # (measured: 378 instead of 650 vehicles entered, highway_onramp x2, 300 s,
        # every vehicle controlled). Here the leader is assumed to brake as hard as
        # the vehicle plans to (max_obs_deceleration = max_deceleration): about
        # reaction_time s of headway at equal speeds, the assumption of SUMO's Krauss
        # model. preferred_acceleration keeps the paper's 1 m/s^2: with the vType's
        # 2.6 m/s^2 the urban grid with every vehicle controlled had 3 junction
        # collisions in 300 s (README, known limits).
        if "max_obs_deceleration" not in self.opt.fixed_keys and "max_obs_deceleration" not in overrides:
            overrides["max_obs_deceleration"] = overrides.get("max_deceleration", self.base_config.max_deceleration)
        try:
            cfg = self.base_config.replace(**overrides) if overrides else self.base_config
            veh = self.base_vehicle.replace(**vehicle_overrides) if vehicle_overrides else self.base_vehicle
            cfg.validate()
            veh.validate()
        except blendtrack.BlendtrackError as e:
            raise ScenarioError(f"vType {vtype!r}: {e}") from None
        length = float(vt.getLength(vtype))
        wheelbase = min(float(veh.wheelbase_m), 0.8 * length)
        if wheelbase != veh.wheelbase_m:
            veh = veh.replace(wheelbase_m=wheelbase)
        info = {
            "param_keys": param_keys,
            "controlled_param": controlled_param in ("1", "true", "yes"),
            "config": cfg,
            "vehicle": veh,
            "length": length,
            "min_gap": float(vt.getMinGap(vtype)),
            "max_speed": float(vt.getMaxSpeed(vtype)),
        }
        self._type_cache[vtype] = info
        return info

    def is_selected(self, vid: str, vtype: str) -> bool:
        o = self.opt
        if o.max_controlled is not None and len(self.records) >= o.max_controlled:
            return False
        if o.controlled_ids:
            return vid in o.controlled_ids
        if o.controlled_fraction is not None:
            return _unit_hash(o.seed, vid) < o.controlled_fraction
        if o.controlled_type is not None:
            return vtype == o.controlled_type
        return bool(self._type_info(vtype)["controlled_param"])

    # ---------------------------------------------------------------- takeover
    def _net_geometry(self) -> Any:
        if self._net is None:
            import sumolib

            self._net = sumolib.net.readNet(str(self.scenario.net_file), withInternal=True)
        return self._net

    def _geometry(
        self, edges: tuple[str, ...], lane_index: int, change: tuple[float, float] | tuple[float, float, int] | None = None
    ) -> tuple[RouteGeometry, int]:
        """The track of a route from a lane, registered with its lane pieces and
        stop lines; shared by every vehicle on the same route and lane (a track
        with a lane change in it belongs to one vehicle)."""
        key = (edges, lane_index)
        hit = self._geo_cache.get(key) if change is None else None
        if hit is None:
            geo = route_geometry(
                self._net_geometry(), edges, lane_index, defer_changes=True, change=change,
                border_margin_m=self.opt.border_margin_m,
            )
            path = blendtrack.Path(geo.points, geo.widths, closed=False)
            lanes, edge_ids = self._lanes, self._edges
            stops = geo.stops
            self._internal_vias.update(st[4] for st in stops if st[2] < 0)
            track = self.fleet.add_route(
                path,
                self.base_config,
                piece_start_m=geo.piece_start_s,
                piece_scale=geo.piece_scale,
                piece_offset_m=geo.piece_offset,
                piece_lane_length_m=geo.piece_lane_length,
                piece_lane_pos_m=geo.piece_lane_pos,
                piece_speed_mps=geo.piece_speed,
                piece_lane=[lanes.id(x) for x in geo.piece_lane],
                piece_edge=[edge_ids.id(x) for x in geo.piece_edge],
                piece_lane_index=geo.piece_index,
                length_m=geo.length_m,
                stop_s_m=[st[0] for st in stops],
                stop_light=[self._lights.id(st[1]) if st[1] else -1 for st in stops],
                stop_link=[st[2] for st in stops],
                stop_major=[int(st[3]) for st in stops],
                stop_via=[lanes.id(st[4]) for st in stops],
                stop_exit_m=[st[5] for st in stops],
                stop_check_inside=[int(bool(self._junction_lanes(st[4])[1])) for st in stops],
                lane_change=(
                    (edge_ids.id(geo.edges[geo.pending_change[0]]), geo.pending_change[1])
                    if geo.pending_change is not None
                    else None
                ),
            )
            hit = (geo, track)
            if change is None:
                self._geo_cache[key] = hit
        return hit

    def _take_over(self, vid: str, t: float) -> None:
        v = self.sumo.vehicle
        vtype = v.getTypeID(vid)
        info = self._type_info(vtype)
        route = tuple(v.getRoute(vid))
        idx = max(int(v.getRouteIndex(vid)), 0)
        edges = route[idx:]
        if not edges:
            return
        lane_index = int(v.getLaneIndex(vid))
        geo, track = self._geometry(edges, max(lane_index, 0))
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
            name=vid,
        )
        rec = VehicleRecord(vid=vid, vtype=vtype, depart_s=t)
        self.records.append(rec)
        act = _Active(vid=vid, slot=slot, geo=geo, route_id=v.getRouteID(vid), record=rec)
        if len(self._trajectories) + len(self._tracing) < self.opt.keep_trajectories or self.opt.keep_trajectories < 0:
            act.trajectory = []
            self._tracing[vid] = act
        self.active[vid] = act
        self._order_dirty = True
        self._read_position.add(vid)
        v.setSpeedMode(vid, 0)
        v.setLaneChangeMode(vid, 0)
        if self._use_subscriptions:
            tc = self._tc
            v.subscribe(vid, [tc.VAR_ROUTE_ID, tc.VAR_LANE_ID, tc.VAR_LANEPOSITION])
            v.subscribeLeader(vid, LEADER_RANGE_M)

    def _drop(self, vid: str, t: float, reason: str) -> None:
        act = self.active.pop(vid, None)
        self._read_position.discard(vid)
        if act is None:
            return
        self._order_dirty = True
        self._tracing.pop(vid, None)
        self._changing.pop(vid, None)
        rec = act.record
        for key, value in self.fleet.remove_vehicle(act.slot).items():
            setattr(rec, key, value)
        if act.own_track is not None:
            self.fleet.remove_route(act.own_track)
        rec.end_s = t
        rec.reason = reason
        if act.trajectory is not None and act.trajectory:
            self._trajectories[vid] = (np.array(act.trajectory), act.geo.points)
        if reason == "collision":
            rec.collisions += 1
        elif reason == "teleport":
            rec.teleports += 1
        if reason not in ("arrived", "end"):
            # Hand the vehicle back to SUMO's own models if it is still there.
            # setSpeed(-1) ends the last speed command: SUMO keeps applying
            # one until told otherwise, even after a teleport, so a vehicle
            # that waited at standstill would stand for good.
            self._hand_back(vid)

    def _hand_back(self, vid: str) -> None:
        """SUMO's own driving for ``vid`` again (each call on its own: one
        failing, say on a vehicle gone meanwhile, does not skip the rest)."""
        v = self.sumo.vehicle
        for call, args in ((v.setSpeed, (-1.0,)), (v.setSpeedMode, (31,)), (v.setLaneChangeMode, (1621,)), (v.unsubscribe, ())):
            try:
                call(vid, *args)
            except Exception:
                pass

    # -------------------------------------------------------------------- run
    def run(self) -> RunResult:
        wall0 = time.perf_counter()
        self.start()
        try:
            end = self.opt.end_s if self.opt.end_s is not None else self.scenario.default_end_s
            steps = self._loop(end)
        finally:
            t_end = self._time()
            for vid in list(self.active):
                self._drop(vid, t_end, "end")
            self.close()
        wall = time.perf_counter() - wall0
        controlled = len(self.records)
        summary = {
            "scenario": self.scenario.name,
            "sumocfg": str(self.scenario.sumocfg),
            "backend": self.backend,
            "backend_note": self.backend_note,
            "seed": self.opt.seed,
            "end_s": t_end,
            "steps": steps,
            "step_length_s": self.dt,
            "controlled_vehicles": controlled,
            "background_vehicles": len(self._background),
            "collisions": self.counts["collision_events"],
            "controlled_vehicles_in_collisions": sum(r.collisions for r in self.records),
            "teleports": sum(r.teleports for r in self.records),
            "red_light_violations": sum(r.red_light_violations for r in self.records),
            "vanished": self.counts["vanished"],
            "speed_warnings": sum(r.speed_warnings for r in self.records),
            "reverse_warnings": sum(r.reverse_warnings for r in self.records),
            "wall_time_s": wall,
            "steps_per_second": steps / wall if wall > 0 else math.nan,
            "comfort_lateral_accel_mps2": self.scenario.comfort_lateral_accel_mps2,
            "border_margin_m": self.opt.border_margin_m,
            "stop_at_route_end": self.opt.stop_at_route_end,
            "tactical_lane_changes_enabled": self.opt.tactical_lane_changes,
            "moves_speed_only": self.moves["speed"],
            "moves_none": self.moves["none"],
            "moves_lane_position": self.moves["lane"],
            "moves_xy": self.moves["xy"],
            "reroutes": self.counts["reroutes"],
            "lane_changes_aborted": self.counts["lane_changes_aborted"],
            "inside_junction_waits": self.counts["inside_junction_waits"],
            "courtesy_steps": self.counts["courtesy_steps"],
            "merge_lead_steps": self.counts["merge_lead_steps"],
            "tactical_lane_changes": self.counts["tactical_lane_changes"],
        }
        samples = self.fleet.take_samples()
        return RunResult(self.records, summary, self._trajectories, samples)

    def _time(self) -> float:
        try:
            return float(self.sumo.simulation.getTime()) if self.sumo is not None else math.nan
        except Exception:
            return math.nan

    def _loop(self, end: float | None) -> int:
        sumo = self.sumo
        tc = self._tc
        bar = None
        if self.opt.progress and end is not None:
            from tqdm import tqdm

            bar = tqdm(total=round(end), unit="sim s", desc=self.scenario.name, leave=False, dynamic_ncols=True)
        steps = 0
        last_t = 0.0
        comfort = self.scenario.comfort_lateral_accel_mps2
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
            ev = sumo.simulation.getSubscriptionResults()
            for vid in ev.get(tc.VAR_ARRIVED_VEHICLES_IDS, ()):
                self._drop(vid, t, "arrived")
            for vid in ev.get(tc.VAR_TELEPORT_STARTING_VEHICLES_IDS, ()):
                if vid in self.active:
                    self._drop(vid, t, "teleport")
            colliding = ev.get(tc.VAR_COLLIDING_VEHICLES_IDS, ())
            if colliding:
                # Events, not vehicles: one collision of two controlled
                # vehicles is one event and two vehicle records.
                for c in sumo.simulation.getCollisions():
                    if c.collider in self.active or c.victim in self.active:
                        self.counts["collision_events"] += 1
            for vid in colliding:
                if vid in self.active:
                    self._drop(vid, t, "collision")
            for vid in ev.get(tc.VAR_DEPARTED_VEHICLES_IDS, ()):
                if vid in self._seen:
                    continue
                self._seen.add(vid)
                if self.opt.tactical_lane_changes:
                    self._note_insertion(vid)
                vtype = sumo.vehicle.getTypeID(vid)
                if self.is_selected(vid, vtype):
                    try:
                        self._take_over(vid, t)
                    except blendtrack.PathError:
                        # An undrivable route: leave it to SUMO, and say so.
                        self.counts["takeover_failures"] += 1
                        self._background.add(vid)
                else:
                    self._background.add(vid)
            if self.active:
                self._control_step(t, comfort)
            if bar is not None and t - last_t >= 1.0:
                bar.update(int(t) - int(last_t))
                last_t = float(int(t))
        if bar is not None:
            bar.close()
        return steps

    def _refresh_order(self) -> None:
        if self._order_dirty:
            self._order = list(self.active.values())
            self._ids = [a.vid for a in self._order]
            self._slots = np.array([a.slot for a in self._order], dtype=np.int64)
            self._index = {vid: i for i, vid in enumerate(self._ids)}
            self._order_dirty = False

    def _observe(self, t: float) -> tuple[tuple[list[int] | None, list[Any]], list[int], list[int], list[float]]:
        """Leaders, and where needed lane positions, of every controlled
        vehicle still in the simulation, in ``self._order``; drops the ones
        that vanished without an event.

        Over TraCI these come from vehicle subscriptions (one socket round trip
        for all). With libsumo 1.28 a vehicle subscription breaks every later
        ``simulationStep`` ("Vehicle 'x' is not known") once another client
        removes the subscribed vehicle, so there the same values come from
        in-process getters (under a microsecond each), and only the ones
        needed: the leader every step, the lane position where RouteFleet asks
        for it (unknown, or due for a check), the route id every
        ``ROUTE_CHECK_EVERY`` steps.
        """
        if self._use_subscriptions:
            return self._observe_subscribed(t)
        self._refresh_order()
        try:
            asked, leaders = self._leaders()
        except Exception:
            # Removed by another client (or otherwise gone) without an event.
            present = set(self.sumo.vehicle.getIDList())
            for vid in [x for x in self._ids if x not in present]:
                self.counts["vanished"] += 1
                self._drop(vid, t, "vanished")
            self._refresh_order()
            asked, leaders = self._leaders()
        ids = self._ids
        get_route = self._get_route_id
        for act in self._order[self._steps % ROUTE_CHECK_EVERY :: ROUTE_CHECK_EVERY]:
            if get_route(act.vid) != act.route_id:
                self._rebuild(act)
        index, lane_id = self._index, self._lanes.id
        get_lane, get_pos = self._get_lane_id, self._get_lane_pos
        read = [(i, vid) for vid in self._read_position if (i := index.get(vid)) is not None]
        lanes = [lane_id(get_lane(vid)) for _, vid in read]
        poss = [get_pos(vid) for _, vid in read]
        if self._changing:
            assert asked is not None
            pos = {i: k for k, i in enumerate(asked)}
            # The lane changers' leaders need SUMO's word (and a look at the target lane).
            for act in self._changing.values():
                self._ask_leader(index[act.vid], pos, asked, leaders)
            self._changing_leaders(leaders, pos)
        return (asked, leaders), [i for i, _ in read], lanes, poss

    def _ask_leader(self, i: int, pos: dict[int, int], asked: list[int], leaders: list[Any]) -> int:
        """Where the leader of the vehicle at index ``i`` is in ``leaders``;
        one not asked yet is asked of SUMO now and added (to ``asked`` too)."""
        k = pos.get(i)
        if k is None:
            k = pos[i] = len(asked)
            asked.append(i)
            leaders.append(self._get_leader(self._ids[i], LEADER_RANGE_M))
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
        fleet, ids = self.fleet, self._ids
        lanes = fleet.lanes_with_followers(self._slots).tolist()
        names, lane_vehicles = self._lanes.names, self._lane_vehicles
        ask = fleet.leaders_on_lanes(self._slots, lanes, [lane_vehicles(names[lane]) for lane in lanes]).tolist()
        get_leader = self._get_leader
        return ask, [get_leader(ids[i], LEADER_RANGE_M) for i in ask]

    def _observe_subscribed(self, t: float) -> tuple[tuple[list[int] | None, list[Any]], list[int], list[int], list[float]]:
        """``_observe`` over TraCI: everything from the vehicle subscriptions."""
        tc = self._tc
        res = self.sumo.vehicle.getAllSubscriptionResults()
        self._refresh_order()
        for act in list(self._order):
            r = res.get(act.vid)
            if r is None:
                self.counts["vanished"] += 1
                self._drop(act.vid, t, "vanished")
            elif r.get(tc.VAR_ROUTE_ID, act.route_id) != act.route_id:
                self._rebuild(act)
        self._refresh_order()
        lane_id = self._lanes.id
        rows = [res[vid] for vid in self._ids]
        leaders = [r.get(tc.VAR_LEADER) for r in rows]
        lanes = [lane_id(r.get(tc.VAR_LANE_ID, "")) for r in rows]
        poss = [float(r.get(tc.VAR_LANEPOSITION, math.nan)) for r in rows]
        self._changing_leaders(leaders, None)
        return (None, leaders), list(range(len(rows))), lanes, poss

    def _changing_leaders(self, leaders: list[Any], pos: dict[int, int] | None) -> None:
        """The lane changers' leaders (``leaders[pos[i]]`` for the vehicle at
        index i, or ``leaders[i]`` when all are listed)."""
        index = self._index
        for act in list(self._changing.values()):
            i = index[act.vid]
            k = i if pos is None else pos[i]
            leaders[k] = self._changing_leader(act, leaders[k])

    def _retrack(self, act: _Active, geo: RouteGeometry, track: int, owned: bool) -> None:
        """Puts ``act`` on ``track`` (``owned``: built for it alone); a track
        it owned before goes (nobody else drives it), so a long run's lane
        changes do not pile up tracks."""
        self.fleet.retrack(act.slot, track)
        old, act.own_track = act.own_track, (track if owned else None)
        act.geo = geo
        if old is not None and old != track:
            self.fleet.remove_route(old)

    def _set_changing(self, act: _Active, changing: tuple[int, int] | None) -> None:
        act.changing = changing
        if changing is None:
            act.tactical = False
            act.change_span = None
            self._changing.pop(act.vid, None)
        else:
            self._changing[act.vid] = act

    def _left_behind(self, act: _Active, lead: Any) -> bool:
        """During a lane change: is ``lead``, the leader on the lane the
        vehicle leaves (SUMO's ``(id, gap)``), one it leaves behind? It is
        when the change's smoothstep has the vehicle clear of it (lateral
        room ``LANE_CHANGE_CLEAR_M``) by the time the front reaches its back,
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
        v = self.sumo.vehicle
        vid, lid = act.vid, str(lead[0])
        speed = max(float(v.getSpeed(vid)), 0.0)
        gap = float(lead[1])
        committed = not act.tactical and abs(float(v.getLateralLanePosition(vid))) >= ABORT_CHANGE_LAT_M
        if not committed and gap < speed * speed / (2.0 * self._plan_decel) + LANE_CHANGE_GAP_M:
            return False
        start, length = act.change_span
        lane_id = v.getLaneID(vid)
        edge = lane_id.rpartition("_")[0]
        net = self._net_geometry()
        try:
            lane = net.getLane(lane_id)
            spacing = 0.5 * (float(lane.getWidth()) + float(net.getLane(f"{edge}_{act.changing[1]}").getWidth()))
        except (KeyError, AttributeError):
            return False  # not on the edge the change is on (a junction lane): the leader counts
        # Where the front axle is when the front bumper reaches the leader's
        # back (SUMO's gap leaves out minGap): the offset the change has there.
        back = float(v.getLanePosition(vid)) + gap + float(v.getMinGap(vid))
        if back > float(lane.getLength()):
            return False  # beyond this lane: where lanes merge it may be ahead on the target lane too
        u = min(max((back - CHANGE_AXLE_BEHIND_M - start) / max(length, 1e-6), 0.0), 1.0)
        offset = spacing * u * u * (3.0 - 2.0 * u)
        return offset >= 0.5 * (float(v.getWidth(vid)) + float(v.getWidth(lid))) + LANE_CHANGE_CLEAR_M

    def _changing_leader(self, act: _Active, lead: Any) -> Any:
        """During a lane change SUMO reports the leader on the lane the vehicle
        is still on; the one on the target lane matters as much. Returns the
        closer of the two (or the one there is)."""
        v = self.sumo.vehicle
        direction, target = act.changing  # type: ignore[misc]
        if v.getLaneIndex(act.vid) == target:
            self._set_changing(act, None)
            return lead
        if act.tactical:
            # Until SUMO puts it on the target lane nobody there sees it, and
            # a SUMO driver may move onto that lane from the far side: a
            # change that is only wanted is given up whenever its room goes.
            if not self._tactical_room(act.vid, direction, float(v.getSpeed(act.vid)), TACTICAL_KEEP_FACTOR):
                self._abort_change(act)
                return lead
        elif abs(v.getLateralLanePosition(act.vid)) < ABORT_CHANGE_LAT_M:
            # Barely started (or held at its start by a leader): the room
            # checked when it began may be gone, e.g. a follower has come up
            # on the target lane while the vehicle stood. Check again.
            speed = float(v.getSpeed(act.vid))
            length = _change_length(speed, math.inf)
            if not self._target_lane_clear(act.vid, direction, speed, length / max(abs(speed), 1.0)):
                self._abort_change(act)
                return lead
        if self._left_behind(act, lead):
            lead = None
        # getNeighbors mode: bit 0 right (1) / left (0), bit 1 leaders (2).
        for nid, gap in v.getNeighbors(act.vid, 2 | (1 if direction < 0 else 0)):
            # A neighbour alongside (gap < 0) is no obstacle ahead: braking
            # would leave the vehicle standing across both lanes.
            if gap >= 0.0:
                lead = self._tighter_leader(lead, (nid, gap))
        return lead

    def _control_step(self, t: float, comfort: float) -> None:
        del comfort  # the RouteFleet applies the scenario's (given at construction)
        self._steps += 1
        for vid, lane, pos, speed in self._lane_change_due:
            act = self.active.get(vid)
            if act is not None:
                self._try_lane_change(act, self._lanes.name(lane), pos, speed)
        self._lane_change_due = []
        if self.opt.tactical_lane_changes and self._order:
            self._tactical_changes()
        if self._has_tls:
            self._refresh_tls()
        (asked, leaders), read, lanes, poss = self._observe(t)
        # This step's courtesy and lining-up targets are taken (and cleared)
        # even when no controlled vehicle is left to step.
        soft = self._soft_leaders() if self._courtesy or self._merge_leads else None
        if not self._ids:
            return
        ids, order, fleet = self._ids, self._order, self.fleet
        queries = fleet.plan_sumo(self._slots, leaders, self._get_speed, read, lanes, poss, asked, soft).tolist()
        answers = [self._must_yield(ids[i], order[i].slot) for i in queries]
        out = fleet.step(np.array(answers, dtype=bool), self.dt)
        self._apply(t, ids, order, out)

    def _apply(self, t: float, ids: list[str], acts: list[_Active], out: dict[str, np.ndarray]) -> None:
        """Pushes the new poses to SUMO, by the move RouteFleet chose for each:
        most only get a speed (SUMO's own movement puts them in place), some
        nothing at all."""
        moves = out["move"]
        speeds = out["sumo_speed_mps"]
        failed: list[int] = []
        set_speed, move_to, move_xy = self._set_speed, self._move_to, self._move_to_xy
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
        lane_names = self._lanes.names
        idx = np.flatnonzero(moves == _LANE)
        for i, lane, pos, sp in zip(idx.tolist(), out["lane"][idx].tolist(), out["lane_pos_m"][idx].tolist(), speeds[idx].tolist()):
            try:
                move_to(ids[i], lane_names[lane], pos)
                set_speed(ids[i], sp)
            except Exception:
                failed.append(i)
        self.moves["lane"] += len(idx)
        idx = np.flatnonzero(moves == _XY)
        edge_names = self._edges.names
        xy_cols = (out[k][idx].tolist() for k in ("edge", "lane_index", "x_front_m", "y_front_m", "angle_deg"))
        for i, edge, lane_index, x_front, y_front, angle, sp in zip(idx.tolist(), *xy_cols, speeds[idx].tolist()):
            try:
                move_xy(ids[i], edge_names[edge], lane_index, x_front, y_front, angle, 3)
                # Without it SUMO keeps reporting the last setSpeed value,
                # and followers plan with a wrong leader speed.
                set_speed(ids[i], sp)
            except Exception:
                failed.append(i)
        self.moves["xy"] += len(idx)
        for i in np.flatnonzero(moves == _INVALID).tolist():
            # Unusable state (NaN): hand the vehicle back rather than move it anywhere.
            self._drop(ids[i], t, "invalid_state")
        for i in failed:
            self._move_failed(ids[i], acts[i], t)
        self._read_position = {ids[i] for i in np.flatnonzero(out["read_position"]).tolist()}
        for i in np.flatnonzero(out["red_light"]).tolist():
            stop = self.fleet.next_stop(acts[i].slot)
            light = self._lights.name(stop[1]) if stop is not None and stop[1] >= 0 else ""
            self.violations.append((t, ids[i], light, stop[2] if stop else -1, stop[0] if stop else math.nan))
        due = np.flatnonzero(out["lane_change_due"])
        if len(due):
            v = out["v_mps"][due]
            # Where SUMO will have the front after its movement over the step:
            # the new front position (lane_pos_m is it minus v dt).
            front = (out["lane_pos_m"][due] + v * self.dt).tolist()
            self._lane_change_due = [
                (ids[i], lane, pos, sp) for i, lane, pos, sp in zip(due.tolist(), out["lane"][due].tolist(), front, v.tolist())
            ]
        if self._tracing:
            xf, yf, vv, ee, kk = (out[k] for k in ("x_front_m", "y_front_m", "v_mps", "lateral_error_m", "curvature_per_m"))
            index = self._index
            for act in self._tracing.values():
                j = index.get(act.vid)
                if j is not None and j < len(acts) and acts[j] is act and act.trajectory is not None:
                    act.trajectory.append((t, float(xf[j]), float(yf[j]), float(vv[j]), float(ee[j]), float(kk[j])))
        if self.opt.trace:
            self._trace(t, ids, acts, out)

    def _trace(self, t: float, ids: list[str], acts: list[_Active], out: dict[str, np.ndarray]) -> None:
        keys = ("x_m", "y_m", "theta_rad", "v_mps", "delta_rad", "lateral_error_m", "heading_error_rad", "s_rear_m", "curvature_per_m", "accel_mps2", "virtual_obstacle_m")
        edge_names = self._edges.names
        cols = [out[k].tolist() for k in keys]
        edges = [edge_names[e] for e in out["edge"].tolist()]
        for row in zip(ids, *cols, edges, out["lane_index"].tolist()):
            self._trace_rows.append((t, *row))

    def _move_failed(self, vid: str, act: _Active, t: float) -> None:
        """SUMO rejected a move: a new route (rerouted since the last check)
        gets a new track; a vehicle that is gone is dropped."""
        try:
            rerouted = self.sumo.vehicle.getRouteID(vid) != act.route_id
        except Exception:
            rerouted = False
        if rerouted:
            self._rebuild(act)
            return
        self.counts["vanished"] += 1
        self._drop(vid, t, "vanished")

    def _try_lane_change(self, act: _Active, lane_id: str, pos: float, speed: float) -> None:
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
        if not _could_change_lane(self._lane_change_state, act.vid, direction):
            self._wait_for_gap(act.vid, direction, target_lane, pos, speed)
            return
        lane_length = float(self._net_geometry().getLane(lane_id).getLength())
        length = _change_length(speed, lane_length - pos - 1.0)
        if length < 8.0:
            return
        # SUMO (without the sublane model) shows the vehicle on the target
        # lane only once its centre is over the line, so vehicles there do
        # not react to it before: start only with room for the whole change
        # (its duration, at the present speed or 1 m/s, times the closing
        # speed) plus a margin.
        if not self._target_lane_clear(act.vid, direction, speed, length / max(abs(speed), 1.0)):
            self._wait_for_gap(act.vid, direction, target_lane, pos, speed)
            return
        geo2, track = self._geometry(geo.edges[k_edge:], current, change=(pos, length))
        self._begin_change(act, geo2, track, direction, target, (pos, length))

    def _note_insertion(self, vid: str) -> None:
        """Where SUMO inserted ``vid``: the furthest insertion point per edge."""
        v = self.sumo.vehicle
        try:
            edge, pos = v.getRoadID(vid), float(v.getLanePosition(vid))
        except Exception:
            return
        if pos > self._insertions.get(edge, -math.inf):
            self._insertions[edge] = pos

    def _tactical_changes(self) -> None:
        """This step's share of the controlled vehicles (every
        ``TACTICAL_CHECK_EVERY``-th) change lanes where SUMO's lane-change
        model wants a change the route does not need and has room for it."""
        import traci.constants as tc

        state = self._lane_change_state
        reasons = tc.LCA_SPEEDGAIN | tc.LCA_KEEPRIGHT | tc.LCA_COOPERATIVE
        for act in self._order[self._steps % TACTICAL_CHECK_EVERY :: TACTICAL_CHECK_EVERY]:
            if act.changing is not None or self.active.get(act.vid) is not act:
                continue
            for direction in (1, -1):
                try:
                    wants, _ = state(act.vid, direction)
                except Exception:
                    break  # gone without an event: _observe drops it
                side = tc.LCA_LEFT if direction > 0 else tc.LCA_RIGHT
                if wants & side and wants & reasons and not wants & (tc.LCA_BLOCKED | tc.LCA_STRATEGIC):
                    self._try_tactical_change(act, direction)
                    break

    def _try_tactical_change(self, act: _Active, direction: int) -> None:
        """Changes ``act`` one lane over (+1 left, -1 right) on its edge, if
        the target lane goes on along the route and has room now."""
        v = self.sumo.vehicle
        try:
            lane_id = v.getLaneID(act.vid)
            speed = float(v.getSpeed(act.vid))
            pos = float(v.getLanePosition(act.vid))
            rest = tuple(v.getRoute(act.vid))[max(int(v.getRouteIndex(act.vid)), 0) :]
        except Exception:
            return
        geo = act.geo
        edge, _, index = lane_id.rpartition("_")
        if speed < TACTICAL_MIN_SPEED_MPS or lane_id.startswith(":") or not index.isdigit():
            return
        k = len(geo.edges) - len(rest)
        if not rest or k < 0 or geo.edges[k:] != rest or rest[0] != edge:
            return  # the track is not of the route from here (a rebuild is due)
        if geo.pending_change is not None and geo.pending_change[0] == k:
            return  # the route needs a change on this edge: that one first
        if pos < self._insertions.get(edge, -math.inf) + TACTICAL_INSERTION_CLEAR_M:
            return  # SUMO inserts vehicles just behind here (see TACTICAL_INSERTION_CLEAR_M)
        current = int(index)
        target = current + direction
        lane = self._net_geometry().getLane(lane_id)
        if not 0 <= target < lane.getEdge().getLaneNumber():
            return
        length = _change_length(speed, float(lane.getLength()) - pos - 1.0)
        if length < 8.0:
            return
        # Both checks of the target lane on one reading of it.
        near = self._target_lane_neighbours(act.vid, direction)
        if not self._target_lane_clear(act.vid, direction, speed, length / speed, near):
            return
        far = target + direction
        if not self._tactical_room(act.vid, direction, speed, 1.0, near) or self._changing_into(edge, target, act.vid):
            return
        if 0 <= far < lane.getEdge().getLaneNumber() and not self._far_lane_room(act.vid, f"{edge}_{far}", pos, speed):
            return
        try:
            geo2, track = self._geometry(rest, current, change=(pos, length, target))
        except blendtrack.PathError:
            return  # the target lane does not go on along the route
        self._begin_change(act, geo2, track, direction, target, (pos, length))
        act.tactical = True
        self.counts["tactical_lane_changes"] += 1

    def _begin_change(self, act: _Active, geo: RouteGeometry, track: int, direction: int, target: int, span: tuple[float, float]) -> None:
        """``act`` starts a lane change on its own ``track`` (built for it),
        over ``span`` (front's lane position where it starts, length)."""
        self._retrack(act, geo, track, owned=True)
        self._set_changing(act, (direction, target))
        act.change_span = span
        act.record.lane_changes += 1

    def _changing_into(self, edge: str, target: int, vid: str) -> bool:
        """Is another controlled vehicle changing onto lane ``target`` of
        ``edge`` (from the other side, say)? Neither would see the other on
        the target lane before SUMO puts it there."""
        v = self.sumo.vehicle
        for other in self._changing.values():
            if other.vid != vid and other.changing is not None and other.changing[1] == target:
                try:
                    if v.getRoadID(other.vid) == edge:
                        return True
                except Exception:
                    continue
        return False

    def _tactical_room(self, vid: str, direction: int, speed: float, factor: float, near: _Neighbours | None = None) -> bool:
        """Gaps on the target lane for a change that is only wanted (see
        ``TACTICAL_HEADWAY_S``), the headway and braking terms scaled by
        ``factor``: 1 to start, ``TACTICAL_KEEP_FACTOR`` to go on. ``near``:
        ``_target_lane_neighbours`` of this step, if read already."""
        followers, leaders = near if near is not None else self._target_lane_neighbours(vid, direction)
        return not (
            any(gap < _tactical_gap(f_speed, speed, factor) for gap, f_speed in followers)
            or any(gap < _tactical_gap(speed, l_speed, factor) for gap, l_speed in leaders)
        )

    def _far_lane_room(self, vid: str, far_lane: str, front: float, speed: float) -> bool:
        """Gaps (``TACTICAL_KEEP_FACTOR`` of them) to the vehicles on the lane
        beyond the target lane, checked before a change that is only wanted
        starts: a SUMO driver there may move onto the target lane at the same
        time, and SUMO's drivers see the changer only once SUMO has put it
        there (a collision of one at 33 m/s, from 3.5 m behind, before this
        check). ``front``: the changer's front on its lane."""
        v = self.sumo.vehicle
        back = front - float(v.getLength(vid))
        for other in self._vehicles_on(far_lane):
            o_front = float(v.getLanePosition(other))
            o_speed = float(v.getSpeed(other))
            if o_front <= front:
                gap = back - o_front - float(v.getMinGap(other))
                if gap < _tactical_gap(o_speed, speed, TACTICAL_KEEP_FACTOR):
                    return False
            else:
                gap = o_front - float(v.getLength(other)) - front - float(v.getMinGap(vid))
                if gap < _tactical_gap(speed, o_speed, TACTICAL_KEEP_FACTOR):
                    return False
        return True

    def _wait_for_gap(self, vid: str, direction: int, target_lane: str, pos: float, speed: float) -> None:
        """``vid`` has a lane change due and no room yet: it keeps behind the
        target lane's nearest vehicle ahead as well as its own leader, so it
        matches the target lane's speed and lines up behind that vehicle, and
        it falls back behind a vehicle alongside (taken as a leader at gap 0:
        the stopping law then keeps it a little slower) rather than drive
        level with it down the lane; the follower there is asked for
        courtesy."""
        v = self.sumo.vehicle
        side = 1 if direction < 0 else 0
        near = [(nid, max(gap, 0.0)) for nid, gap in v.getNeighbors(vid, 2 | side)]
        near += [(nid, 0.0) for nid, gap in v.getNeighbors(vid, side) if gap < 0.0]
        lead = None
        for cand in near:
            lead = self._tighter_leader(lead, cand)
        if lead is not None:
            self._merge_leads[vid] = lead
        self._ask_courtesy(vid, target_lane, pos, speed)

    def _ask_courtesy(self, vid: str, target_lane: str, pos: float, speed: float) -> None:
        """``vid`` waits to change onto ``target_lane`` with its front at
        ``pos``: the nearest controlled vehicle behind it there, within
        ``COURTESY_RANGE_M``, that can stay behind it braking at most
        ``COURTESY_DECEL_MPS2`` is given it as its leader this step (nearer
        ones, too close to brake so gently, pass). Gaps as SUMO's leader gaps
        (the changer's back less the follower's front and minGap), less the
        room the change needs."""
        v = self.sumo.vehicle
        back = pos - float(v.getLength(vid))
        for fid in reversed(self._vehicles_on(target_lane)):
            f_pos = float(v.getLanePosition(fid))
            if f_pos >= back:
                continue  # ahead of the changer's back, or alongside
            if back - f_pos > COURTESY_RANGE_M:
                return
            if fid not in self.active:
                continue  # SUMO's own drivers cooperate in SUMO's way
            # It stays back far enough for the change to start: the changer
            # asks LANE_CHANGE_GAP_M of room (and a metre more, so a follower
            # that creeps up does not close it again).
            gap = back - f_pos - float(v.getMinGap(fid)) - LANE_CHANGE_GAP_M - 1.0
            closing = max(float(v.getSpeed(fid)) - max(speed, 0.0), 0.0)
            if gap > 0.5 and closing * closing <= 2.0 * COURTESY_DECEL_MPS2 * gap:
                old = self._courtesy.get(fid)
                if old is None or gap < old[1]:
                    self._courtesy[fid] = (vid, gap)
                return

    def _soft_leaders(self) -> list[tuple[int, str, float]]:
        """This step's vehicles to line up behind, as ``plan_sumo``'s
        ``soft_leaders``: a courtesy follower's is the lane changer it gives
        way to, a waiting changer's the vehicle it lines up behind. Each comes
        on top of the vehicle's own leader, as a soft obstacle: the vehicle
        falls back for it braking at ``max_deceleration`` at most, never as in
        an emergency (it is on another lane). As a leader in its place, one
        alongside (gap 0) had the merger braking at the actuator's 9 m/s^2
        (traced: 26 steps at the limit in the mix at demand x2, SUMO's
        emergency-braking warnings), and it dropped the own leader."""
        index = self._index
        soft = [(index.get(fid), cid, gap, "courtesy_steps") for fid, (cid, gap) in self._courtesy.items() if cid in index]
        soft += [(index.get(vid), nid, gap, "merge_lead_steps") for vid, (nid, gap) in self._merge_leads.items()]
        self._courtesy = {}
        self._merge_leads = {}
        chosen: dict[int, tuple[str, float]] = {}
        for i, cid, gap, count in soft:
            if i is not None:
                # One per vehicle: of a courtesy and a lining-up target, the tighter.
                chosen[i] = self._tighter_leader(chosen.get(i), (cid, gap))
                self.counts[count] += 1
        return [(i, cid, gap) for i, (cid, gap) in chosen.items()]

    def _tighter_leader(self, a: Any, b: tuple[str, float]) -> Any:
        """Of two leaders (SUMO's ``(id, gap)``; ``a`` may be None or empty),
        the one the stopping law brakes harder for: the smaller virtual
        obstacle distance, gap plus the leader's braking distance at the
        planning deceleration. Not simply the closer one: a near leader
        pulling away matters less than a slower one further on, and following
        only the near one runs into the other."""
        if not (a and a[0] and a[1] >= -100.0):
            return b
        speed = self._get_speed
        two_b = 2.0 * self._plan_decel
        da = a[1] + max(float(speed(a[0])), 0.0) ** 2 / two_b
        db = b[1] + max(float(speed(b[0])), 0.0) ** 2 / two_b
        return b if db < da else a

    def _target_lane_neighbours(self, vid: str, direction: int) -> _Neighbours:
        """SUMO's followers and leaders of ``vid`` on the lane beside it
        (+1 left, -1 right), each as (gap in m, its speed in m/s)."""
        v = self.sumo.vehicle
        side = 0 if direction > 0 else 1  # getNeighbors: bit 0 right, bit 1 leaders
        followers = [(gap, float(v.getSpeed(nid))) for nid, gap in v.getNeighbors(vid, side)]
        leaders = [(gap, float(v.getSpeed(nid))) for nid, gap in v.getNeighbors(vid, side | 2)]
        return followers, leaders

    def _target_lane_clear(self, vid: str, direction: int, speed: float, duration: float, near: _Neighbours | None = None) -> bool:
        """Room on the target lane for a change lasting ``duration`` seconds:
        the gap to the follower and to the leader there, each at least
        ``LANE_CHANGE_GAP_M`` plus what the closing speed eats in that time.
        ``near``: ``_target_lane_neighbours`` of this step, if read already."""
        followers, leaders = near if near is not None else self._target_lane_neighbours(vid, direction)
        return not (
            any(gap < LANE_CHANGE_GAP_M + duration * max(f_speed - speed, 0.0) for gap, f_speed in followers)
            or any(gap < LANE_CHANGE_GAP_M + duration * max(speed - l_speed, 0.0) for gap, l_speed in leaders)
        )

    def _abort_change(self, act: _Active) -> None:
        """Back to the lane the vehicle is on, the change pending again (it is
        retried when there is room)."""
        lane_index = int(self.sumo.vehicle.getLaneIndex(act.vid))
        geo, track = self._geometry(act.geo.edges, max(lane_index, 0))
        self._retrack(act, geo, track, owned=False)
        self._set_changing(act, None)
        self.counts["lane_changes_aborted"] += 1

    def _must_yield(self, vid: str, slot: int) -> bool:
        """SUMO's view of the link ahead: does it lack priority with foes approaching?"""
        stop = self.fleet.next_stop(slot)
        if stop is None:
            return False
        via = self._lanes.name(stop[4])
        if via in self._internal_vias:
            if self._internal_junction_busy(vid, via):
                return True
        else:
            for link in self.sumo.vehicle.getNextLinks(vid):
                # (lane, has priority, is open, has foe, via lane, state, direction, length)
                if link[4] == via:
                    if (not link[1]) and bool(link[3]):
                        return True
                    break
            inner, offset = self._waiting_point_after(via)
            if inner is not None:
                # A turn with an internal waiting point a few metres into the
                # junction: too fast to stop there, the vehicle would cross
                # the oncoming lanes without looking (the point is asked
                # about only once the entry is passed). While it could not
                # stop there gently (ENTRY_SLOW_DECEL of the planning
                # deceleration) and the point would make it wait, it is held
                # at the entry line, so it slows; once slow it goes on to
                # wait at the point, as SUMO's drivers do.
                v = max(float(self.sumo.vehicle.getSpeed(vid)), 0.0)
                room = stop[0] - self.fleet.s_front(slot) + offset - STOP_MARGIN_M
                gentle = ENTRY_SLOW_DECEL * self._plan_decel
                # Foes are looked for as far ahead as the vehicle needs to
                # reach the point, on top of the point's own horizon: it
                # decides here for a point it gets to later (traced: with 4 s
                # only, a left turner 30 m from its point at 12.6 m/s went on,
                # and the straight-on foe, 5.7 s away, met it in the turn).
                horizon = INTERNAL_YIELD_S + room / max(v, 1.0)
                if v * v > 2.0 * gentle * room and self._internal_junction_busy(vid, inner, horizon):
                    return True
        return self._junction_blocked(vid, via)

    def _waiting_point_after(self, via: str) -> tuple[str | None, float]:
        """The internal waiting point on the junction path that starts with
        ``via`` (its junction lane, and its distance from the entry line along
        the lanes), or (None, 0)."""
        hit = self._waiting_points.get(via)
        if hit is None:
            hit = (None, 0.0)
            c = self._connection_of(via)
            if c is not None:
                offset = 0.0
                for part in _via_chain(self._net_geometry(), c):
                    if part.getID() != via and part.getID() in self._internal_vias:
                        hit = (part.getID(), offset)
                        break
                    offset += float(part.getLength())
            self._waiting_points[via] = hit
        return hit

    def _junction_blocked(self, vid: str, via: str) -> bool:
        """Is a vehicle inside the junction in the way of ``vid``, about to
        enter it through ``via``: its body (SUMO's front point, angle, length
        and width) within the half width of ``vid``'s path through the
        junction plus ``INSIDE_MARGIN_M``? A left turner waiting at its
        internal stop point can reach into a crossing lane, and a follower's
        lane can diverge from it barely apart; ``getLeader`` reports neither
        (they are on other junction lanes), SUMO's drivers see them through
        the junction's foe lanes, so blendtrack checks the geometry itself.
        Asked only near a junction whose lanes come near this one."""
        path, lanes = self._junction_lanes(via)
        if not lanes:
            return False
        veh = self.sumo.vehicle
        reach = 0.5 * float(veh.getWidth(vid)) + INSIDE_MARGIN_M
        for lane in lanes:
            for other in self._vehicles_on(lane):
                if other == vid:
                    continue
                body, half = _body_segment(veh, other)
                if _segments_distance(body, path) < reach + half:
                    self.counts["inside_junction_waits"] += 1
                    return True
        return False

    def _vehicles_on(self, lane: str) -> Any:
        """SUMO's list of the vehicles on ``lane`` this step, read once a step
        (several vehicles ask about the lanes of one junction)."""
        step, listed = self._lane_ids_step
        if step != self._steps:
            listed = {}
            self._lane_ids_step = (self._steps, listed)
        ids = listed.get(lane)
        if ids is None:
            ids = listed[lane] = self._lane_vehicles(lane)
        return ids

    def _connection_of(self, via: str) -> Any:
        """The network connection whose junction lanes include ``via`` (None if none)."""
        if self._conn_of_via is None:
            net = self._net_geometry()
            self._conn_of_via = {}
            for edge in net.getEdges():
                for ln in edge.getLanes():
                    for c in ln.getOutgoing():
                        for part in _via_chain(net, c):
                            self._conn_of_via[part.getID()] = c
        return self._conn_of_via.get(via)

    def _junction_lanes(self, via: str) -> tuple[np.ndarray, tuple[str, ...]]:
        """The path (points) through the junction from the junction lane
        ``via`` on, and the junction's other lanes that come within
        ``INSIDE_LANE_REACH_M`` of it (none: nothing to check)."""
        hit = self._inside.get(via)
        if hit is None:
            net = self._net_geometry()
            c = self._connection_of(via)
            path = np.zeros((0, 2))
            near: list[str] = []
            if c is not None:
                chain = [part.getID() for part in _via_chain(net, c)]
                own = chain[chain.index(via):] if via in chain else chain
                if own:
                    path = np.concatenate([np.asarray(net.getLane(x).getShape(), dtype=float)[:, :2] for x in own])
                    node = c.getFrom().getToNode()
                    seen = set(chain)
                    for other in node.getConnections():
                        for part in _via_chain(net, other):
                            lid = part.getID()
                            if lid in seen:
                                continue
                            seen.add(lid)
                            pts = np.asarray(part.getShape(), dtype=float)[:, :2]
                            if _segments_distance(pts, path) < INSIDE_LANE_REACH_M:
                                near.append(lid)
            hit = (path, tuple(near))
            self._inside[via] = hit
        return hit

    def _internal_junction_busy(self, vid: str, via: str, horizon_s: float = INTERNAL_YIELD_S) -> bool:
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
        veh = self.sumo.vehicle
        for foe, incoming, length, tls, link in self._internal_foes(via):
            if any(other != vid for other in self._vehicles_on(foe)):
                return True
            if incoming is None:
                continue
            yellow = False
            if tls:
                state = self._tls_state.get(tls, "")
                if 0 <= link < len(state) and state[link] in "yY":
                    yellow = True
                elif 0 <= link < len(state) and state[link] not in "GgsOo":
                    continue  # the foe's light is red: it stops
            for other in self._vehicles_on(incoming):
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

    def _internal_foes(self, via: str) -> list[tuple[str, str | None, float, str, int]]:
        """Foe junction lanes of an internal junction lane: (foe lane, the normal
        lane leading into it or None, that lane's length, its traffic light, link
        index). From the network's right-of-way matrix (sumolib), not from
        libsumo's ``lane.getInternalFoes``: that call leaves state behind which
        crashes a later simulation in the same process (libsumo 1.28)."""
        hit = self._foes.get(via)
        if hit is None:
            net = self._net_geometry()
            hit = []
            c = self._connection_of(via)
            if c is not None:
                node = c.getFrom().getToNode()
                i = node.getLinkIndex(c)
                for other in node.getConnections():
                    j = node.getLinkIndex(other)
                    if other is c or i < 0 or j < 0 or not node.areFoes(i, j):
                        continue
                    chain = [part.getID() for part in _via_chain(net, other)]
                    if not chain:
                        continue
                    src = other.getFromLane()
                    hit.append((chain[0], src.getID(), float(src.getLength()), other.getTLSID() or "", int(other.getTLLinkIndex())))
                    hit.extend((part, None, 0.0, "", -1) for part in chain[1:])
            self._foes[via] = hit
        return hit

    def _refresh_tls(self) -> None:
        tc = self._tc
        light = self._lights.id
        set_signal = self.fleet.set_signal
        for tls, res in self.sumo.trafficlight.getAllSubscriptionResults().items():
            state = res.get(tc.TL_RED_YELLOW_GREEN_STATE, "")
            if self._tls_state.get(tls) != state:
                self._tls_state[tls] = state
                set_signal(light(tls), state)

    def _rebuild(self, act: _Active) -> None:
        """The route changed (rerouting): a new track from where the vehicle is."""
        v = self.sumo.vehicle
        route = tuple(v.getRoute(act.vid))
        idx = max(int(v.getRouteIndex(act.vid)), 0)
        geo, track = self._geometry(route[idx:], max(int(v.getLaneIndex(act.vid)), 0))
        self._retrack(act, geo, track, owned=False)
        self._set_changing(act, None)
        act.route_id = v.getRouteID(act.vid)
        self.counts["reroutes"] += 1

    def write_trace(self, file: Path) -> None:
        import csv

        with open(file, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["t_s", "id", "x_m", "y_m", "theta_rad", "v_mps", "delta_rad", "lateral_error_m", "heading_error_rad", "s_m", "curvature_per_m", "accel_mps2", "virtual_obstacle_m", "edge", "lane_index"])
            w.writerows(self._trace_rows)


class _Interned:
    """String ids as small integers (RouteFleet takes integers), both ways."""

    def __init__(self) -> None:
        self.ids: dict[str, int] = {}
        self.names: list[str] = []

    def id(self, name: str) -> int:
        i = self.ids.get(name)
        if i is None:
            i = self.ids[name] = len(self.names)
            self.names.append(name)
        return i

    def get(self, name: str, default: int) -> int:
        return self.ids.get(name, default)

    def name(self, i: int) -> str:
        return self.names[i]


def _parse_like(raw: str, current: Any) -> Any:
    if isinstance(current, bool):
        low = raw.strip().lower()
        if low in ("1", "true", "yes"):
            return True
        if low in ("0", "false", "no"):
            return False
        raise ValueError(raw)
    if isinstance(current, float):
        return float(raw)
    return raw.strip()


def _override_options(base: list[str], extra: list[str]) -> list[str]:
    """SUMO command-line options ``base`` with ``extra`` added, an option in
    both taken from ``extra`` only (SUMO refuses one given twice). An option
    is a token starting with ``-`` and the tokens after it up to the next
    such token (its values; none for a bare flag)."""

    given = {name for a in extra if (name := _option_name(a)) is not None}
    kept: list[str] = []
    skipping = False
    for a in base:
        name = _option_name(a)
        if name is not None:
            skipping = name in given
        if not skipping:
            kept.append(a)
    return kept + extra


def _option_name(token: str) -> str | None:
    """The option a command-line token names (``--end=5`` -> ``end``), or
    None for a value (a negative number is a value)."""
    if not token.startswith("-"):
        return None
    try:
        float(token)
        return None
    except ValueError:
        return token.split("=", 1)[0].lstrip("-")


def _tactical_gap(rear: float, front: float, factor: float) -> float:
    """The gap (m) a change that is only wanted asks between a rear vehicle
    at ``rear`` m/s and a front one at ``front`` (see ``TACTICAL_HEADWAY_S``)."""
    rear, front = max(rear, 0.0), max(front, 0.0)
    return LANE_CHANGE_GAP_M + factor * (TACTICAL_HEADWAY_S * rear + max(rear * rear - front * front, 0.0) / (2.0 * TACTICAL_DECEL_MPS2))


def _change_length(speed: float, room_m: float) -> float:
    """How long (m) a lane change at ``speed`` is, with ``room_m`` of lane left."""
    return min(max(LANE_CHANGE_S * abs(speed), LANE_CHANGE_MIN_M), LANE_CHANGE_MAX_M, room_m)


def _could_change_lane(lane_change_state: Callable[[str, int], Any], vid: str, direction: int) -> bool:
    """TraCI's ``couldChangeLane`` on a given ``getLaneChangeState``: the
    target lane had room at SUMO's last lane-change check (and the vehicle
    did not just change)."""
    import traci.constants as tc

    state, traci_state = lane_change_state(vid, direction)
    if traci_state & tc.LCA_BLOCKED == 0 and traci_state & (tc.LCA_LEFT if direction > 0 else tc.LCA_RIGHT):
        return False  # it changed in the last step: the state no longer applies
    return bool(state != tc.LCA_UNKNOWN and state & tc.LCA_BLOCKED == 0)


def _first_line(e: BaseException) -> str:
    text = str(e).strip() or type(e).__name__
    return text.splitlines()[0]


def parse_ids(values: Iterable[str]) -> tuple[str, ...]:
    out: list[str] = []
    for v in values:
        out.extend(x for x in v.split(",") if x)
    return tuple(out)
