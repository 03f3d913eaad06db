"""The SUMO plugin: blendtrack controllers drive selected SUMO vehicles.

One :class:`SumoRun` owns one SUMO simulation (in-process through libsumo by
default, or over TraCI sockets, which sumo-gui needs) and a
:class:`blendtrack.Fleet`. Each simulation step:

1. SUMO advances (``simulationStep``); the per-step event lists (departed,
   arrived, teleporting, colliding) arrive through one simulation
   subscription.
2. Vehicles that left (arrived, teleported, collided, removed by another
   client) are dropped from the fleet; newly departed ones that are selected
   are taken over: their state is initialised from SUMO's pose and speed,
   and their reference track is the centreline of their lane along their
   route (:mod:`blendtrack.sumo.geometry`), shared by every vehicle on the
   same route and lane.
3. The leader of every controlled vehicle comes from a vehicle subscription
   (``VAR_LEADER``), traffic-light states from one subscription per light;
   stop lines of red or yellow lights ahead and the leader become obstacles.
4. One ``Fleet.step`` call computes every controlled vehicle's command and
   integrates its kinematic bicycle over the step, in Rust with the
   interpreter released.
5. Each new pose is pushed with ``moveToXY`` (front-bumper centre, SUMO
   angle, keepRoute = 3 with the edge and lane as hints): SUMO keeps the
   route, so other drivers see the vehicle at junctions and behind them.

blendtrack's state is authoritative for controlled vehicles; SUMO displays
them and makes everybody else react to them. What SUMO cannot represent is
counted, not hidden: a speed above the lane limit, or driving backwards
(SUMO takes displacement as forward speed), increments a warning count.
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
from blendtrack import ControllerConfig, Fleet, VehicleParams
from blendtrack.sumo.geometry import RouteGeometry, route_geometry
from blendtrack.sumo.scenario import Scenario, ScenarioError

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
# How far before a junction without priority a vehicle asks SUMO whether foes approach (m).
YIELD_LOOKAHEAD_M = 30.0


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
    #: True when the config file set ``path_width_m`` (then the lanes' widths are not used).
    fixed_path_width: bool = False
    #: True when the config file set ``preferred_speed``; otherwise each
    #: vehicle aims at its vType's desired speed (maxSpeed x speedFactor),
    #: capped by the lane's limit.
    fixed_preferred_speed: bool = False
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
    """A vehicle under control."""

    vid: str
    slot: int
    geo: RouteGeometry
    wheelbase_m: float
    front_overhang_m: float
    min_gap_m: float
    length_m: float
    route_id: str
    record: VehicleRecord
    config: ControllerConfig
    next_stop: int = 0
    #: (stop index, stop?) decided when the light ahead turned yellow.
    yellow_decision: tuple[int, bool] | None = None
    trajectory: list[tuple[float, float, float, float, float, float]] | None = None


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
        self.base_config = (options.config or ControllerConfig()).replace(use_path_widths=not options.fixed_path_width)
        self.base_vehicle = options.vehicle or VehicleParams()
        if options.alpha is not None:
            self.base_config = self.base_config.replace(lat_blend_factor=options.alpha)
        self.fleet = Fleet()
        self.active: dict[str, _Active] = {}
        self.records: list[VehicleRecord] = []
        self._geo_cache: dict[tuple[tuple[str, ...], int], tuple[RouteGeometry, int, blendtrack.Path]] = {}
        self._state: dict[str, tuple[float, float, float, float, float]] = {}
        self._s_front: dict[str, float] = {}
        self._trajectories: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self._type_cache: dict[str, dict[str, Any]] = {}
        self._seen: set[str] = set()
        self._background: set[str] = set()
        self._tls_state: dict[str, str] = {}
        self._net: Any = None
        self._samples: list[tuple[float, float, float, float]] = []
        self._trace_rows: list[tuple[Any, ...]] = []
        # Events with no per-vehicle record; collisions, teleports and red-light
        # crossings are summed from the records.
        self.counts = {"vanished": 0, "takeover_failures": 0}
        self.step_hooks: list[Callable[[SumoRun, float], None]] = []
        self.cheap_moves = 0
        #: (time, vehicle, traffic light, link index, front before, front after, stop line) of each red-light crossing.
        self.violations: list[tuple[Any, ...]] = []
        self.xy_moves = 0
        self.sumo: Any = None
        self._tc: Any = None
        self._use_subscriptions = False

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
        cmd += list(self.opt.sumo_args)
        return cmd

    def start(self) -> None:
        _sumo_home()
        if self.opt.backend == "traci" or self.opt.gui:
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

    def _check_loads(self) -> None:
        import subprocess

        cmd = [sumo_binary(False), "-c", str(self.scenario.sumocfg), "--end", "0", "--no-step-log", "true",
               "--duration-log.disable", "true", "--no-warnings", "true"]
        try:
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
        except (OSError, subprocess.TimeoutExpired) as e:
            raise ScenarioError(f"{self.scenario.sumocfg}: cannot run SUMO to check the scenario: {e}") from None
        if proc.returncode != 0:
            lines = [ln for ln in (proc.stderr + proc.stdout).splitlines() if ln.strip()]
            crash = f"SUMO crashed while loading it (signal {-proc.returncode})" if proc.returncode < 0 else f"exit code {proc.returncode}"
            errors = [ln for ln in lines if "Error" in ln] or lines or [crash]
            raise ScenarioError(f"{self.scenario.sumocfg}: SUMO refused to start: {errors[0].strip()}")

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
            "param_keys": {PARAM_PREFIX + k for k in (*overrides, *vehicle_overrides)},
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
        self, edges: tuple[str, ...], lane_index: int, change: tuple[float, float] | None = None
    ) -> tuple[RouteGeometry, int, blendtrack.Path]:
        """The track of a route from a lane; shared by every vehicle on the same
        route and lane (a track with a lane change in it belongs to one vehicle)."""
        key = (edges, lane_index)
        hit = self._geo_cache.get(key) if change is None else None
        if hit is None:
            geo = route_geometry(self._net_geometry(), edges, lane_index, defer_changes=True, change=change)
            path = blendtrack.Path(geo.points, geo.widths, closed=False)
            track = self.fleet.add_track(path, self.base_config)
            hit = (geo, track, path)
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
        geo, track, path = self._geometry(edges, max(lane_index, 0))
        veh: VehicleParams = info["vehicle"]
        cfg: ControllerConfig = info["config"]
        if not self.opt.fixed_preferred_speed and PARAM_PREFIX + "preferred_speed" not in info["param_keys"]:
            cfg = cfg.replace(preferred_speed=info["max_speed"] * float(v.getSpeedFactor(vid)))
        slot = self.fleet.add_vehicle(track, cfg, veh)
        x, y = v.getPosition(vid)
        angle = float(v.getAngle(vid))
        theta = math.pi / 2.0 - math.radians(angle)
        overhang = max(0.5 * (info["length"] - veh.wheelbase_m), 0.0)
        back = veh.wheelbase_m + overhang
        state = (x - back * math.cos(theta), y - back * math.sin(theta), theta, float(v.getSpeed(vid)), 0.0)
        rec = VehicleRecord(vid=vid, vtype=vtype, depart_s=t)
        self.records.append(rec)
        act = _Active(
            vid=vid,
            slot=slot,
            geo=geo,
            wheelbase_m=veh.wheelbase_m,
            front_overhang_m=overhang,
            min_gap_m=info["min_gap"],
            length_m=info["length"],
            route_id=v.getRouteID(vid),
            record=rec,
            config=cfg,
        )
        if len(self._trajectories) + sum(a.trajectory is not None for a in self.active.values()) < self.opt.keep_trajectories or self.opt.keep_trajectories < 0:
            act.trajectory = []
        self._s_front[vid] = float(path.project(x, y)["s_m"])
        self.active[vid] = act
        self._state[vid] = state
        v.setSpeedMode(vid, 0)
        v.setLaneChangeMode(vid, 0)
        if self._use_subscriptions:
            tc = self._tc
            v.subscribe(vid, [tc.VAR_ROUTE_ID, tc.VAR_LANE_ID, tc.VAR_LANEPOSITION])
            v.subscribeLeader(vid, LEADER_RANGE_M)

    def _drop(self, vid: str, t: float, reason: str) -> None:
        act = self.active.pop(vid, None)
        self._state.pop(vid, None)
        self._s_front.pop(vid, None)
        if act is None:
            return
        self.fleet.remove_vehicle(act.slot)
        rec = act.record
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
            try:
                self.sumo.vehicle.setSpeedMode(vid, 31)
                self.sumo.vehicle.setLaneChangeMode(vid, 1621)
                self.sumo.vehicle.unsubscribe(vid)
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
            "backend": "traci" if (self.opt.backend == "traci" or self.opt.gui) else "libsumo",
            "seed": self.opt.seed,
            "end_s": t_end,
            "steps": steps,
            "step_length_s": self.dt,
            "controlled_vehicles": controlled,
            "background_vehicles": len(self._background),
            "collisions": sum(r.collisions for r in self.records),
            "teleports": sum(r.teleports for r in self.records),
            "red_light_violations": sum(r.red_light_violations for r in self.records),
            "vanished": self.counts["vanished"],
            "speed_warnings": sum(r.speed_warnings for r in self.records),
            "reverse_warnings": sum(r.reverse_warnings for r in self.records),
            "wall_time_s": wall,
            "steps_per_second": steps / wall if wall > 0 else math.nan,
            "comfort_lateral_accel_mps2": self.scenario.comfort_lateral_accel_mps2,
            "moves_lane_position": self.cheap_moves,
            "moves_xy": self.xy_moves,
        }
        samples = np.array(self._samples) if self._samples else np.zeros((0, 4))
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
            for vid in ev.get(tc.VAR_COLLIDING_VEHICLES_IDS, ()):
                if vid in self.active:
                    self._drop(vid, t, "collision")
            for vid in ev.get(tc.VAR_DEPARTED_VEHICLES_IDS, ()):
                if vid in self._seen:
                    continue
                self._seen.add(vid)
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

    def _read_controlled(self) -> dict[str, dict[int, Any]]:
        """Lane, lane position, route id and leader of every controlled vehicle
        still in the simulation, keyed like subscription results.

        Over TraCI these come from vehicle subscriptions (one socket round trip
        for all). With libsumo 1.28 a vehicle subscription breaks every later
        ``simulationStep`` ("Vehicle 'x' is not known") once another client
        removes the subscribed vehicle, so there the same values come from
        in-process getters (about a microsecond each, no cheaper through a
        subscription) and the simulation survives such removals.
        """
        sumo = self.sumo
        tc = self._tc
        if self._use_subscriptions:
            return sumo.vehicle.getAllSubscriptionResults()  # type: ignore[no-any-return]
        v = sumo.vehicle
        present = set(v.getIDList())
        out: dict[str, dict[int, Any]] = {}
        for vid in self.active:
            if vid not in present:
                continue
            out[vid] = {
                tc.VAR_ROUTE_ID: v.getRouteID(vid),
                tc.VAR_LANE_ID: v.getLaneID(vid),
                tc.VAR_LANEPOSITION: v.getLanePosition(vid),
                tc.VAR_LEADER: v.getLeader(vid, LEADER_RANGE_M),
            }
        return out

    def _control_step(self, t: float, comfort: float) -> None:
        sumo = self.sumo
        tc = self._tc
        subs = self._read_controlled()
        ids = []
        for vid in list(self.active):
            r = subs.get(vid)
            if r is None:
                # Removed by another client (or otherwise gone) without an event.
                self.counts["vanished"] += 1
                self._drop(vid, t, "vanished")
                continue
            act = self.active[vid]
            rid = r.get(tc.VAR_ROUTE_ID)
            if rid is not None and rid != act.route_id:
                self._rebuild(act)
            ids.append(vid)
        n = len(ids)
        if n == 0:
            return
        if self._has_tls:
            self._refresh_tls()
        acts = [self.active[v] for v in ids]
        st = np.array([self._state[v] for v in ids])
        leader_gap = np.full(n, np.nan)
        leader_speed = np.full(n, np.nan)
        stop_gap = np.full(n, np.nan)
        limit = np.empty(n)
        s_front = np.empty(n)
        speeds = st[:, 3]
        margin = self.opt.standstill_margin_m
        for i, (vid, act) in enumerate(zip(ids, acts)):
            lead = subs[vid].get(tc.VAR_LEADER)
            if lead and lead[0] and lead[1] >= -100.0:
                lid, gap = lead
                # SUMO's gap already leaves out the vType's minGap, and SUMO
                # counts anything closer than minGap as a collision: plan to
                # stop standstill_margin_m further back still.
                leader_gap[i] = gap - margin
                other = self._state.get(lid)
                leader_speed[i] = other[3] if other is not None else sumo.vehicle.getSpeed(lid)
            if act.geo.pending_change is not None:
                self._try_lane_change(act, subs[vid], speeds[i])
            geo = act.geo
            sf = self._s_front.get(vid, math.nan)
            s_front[i] = sf
            limit[i] = geo.speeds[geo.piece_index_at(sf) if sf == sf else 0]
            # The next signalised stop line ahead of the front bumper.
            while act.next_stop < len(geo.stops) and sf == sf and geo.stops[act.next_stop][0] < sf - 0.5:
                act.next_stop += 1
            if act.next_stop < len(geo.stops) and sf == sf:
                s_stop, tls, link, major, via, s_exit = geo.stops[act.next_stop]
                gap = s_stop - sf - margin
                state = self._tls_char(tls, link) if tls else ("G" if major else "m")
                if state not in "yY":
                    act.yellow_decision = None
                if state in "rRu":
                    stop_gap[i] = gap
                elif state in "yY":
                    # Yellow: stop when the stopping law manages it at the
                    # planning deceleration, otherwise clear the junction. The
                    # decision holds until the light changes: re-deciding every
                    # step flips to "go" as the stop nears (the law brakes
                    # harder than b_f at the end) and then fails to stop at red.
                    if act.yellow_decision is None or act.yellow_decision[0] != act.next_stop:
                        act.yellow_decision = (act.next_stop, self._can_stop(act, abs(speeds[i]), gap))
                    if act.yellow_decision[1]:
                        stop_gap[i] = gap
                elif (
                    gap < YIELD_LOOKAHEAD_M
                    and leader_gap[i] == leader_gap[i]
                    # Where the leader's back would stop if it braked now at 4 m/s^2.
                    and sf + leader_gap[i] + margin + leader_speed[i] ** 2 / 8.0 - s_exit
                    < act.length_m + act.min_gap_m + margin
                    and self._can_stop(act, abs(speeds[i]), gap)
                ):
                    # Keep the junction clear: no room for this vehicle behind
                    # its leader on the far side, so wait at the line.
                    stop_gap[i] = gap
                elif (
                    state != "G"
                    and gap < YIELD_LOOKAHEAD_M
                    and self._can_stop(act, abs(speeds[i]), gap)
                    and self._must_yield(vid, via)
                ):
                    # A link without priority (green without priority, an
                    # unsignalised minor road): wait at the line while SUMO
                    # reports foes approaching it, unless it is too late to
                    # stop before the line (then stopping would block the
                    # junction: clear it instead).
                    stop_gap[i] = gap
            # End of the route: a standing obstacle a little past the last lane's end,
            # so the vehicle slows down and SUMO sees it arrive. A track that stops
            # where a lane change is due ends LANE_CHANGE_ROOM_M early instead:
            # the vehicle waits there for a gap, with room left to change.
            if geo.pending_change is not None:
                end_gap = geo.length_m - LANE_CHANGE_ROOM_M - sf - margin if sf == sf else math.nan
            else:
                end_gap = geo.length_m + 5.0 - sf if sf == sf else math.nan
            if end_gap == end_gap and end_gap < 200.0:
                stop_gap[i] = end_gap if not stop_gap[i] == stop_gap[i] else min(stop_gap[i], end_gap)
        # After the loop: a lane change above may have moved a vehicle to a new slot.
        slots = np.fromiter((a.slot for a in acts), dtype=np.int64, count=n)
        out = self.fleet.step(
            slots,
            st[:, 0],
            st[:, 1],
            st[:, 2],
            st[:, 3],
            st[:, 4],
            leader_gap=leader_gap,
            leader_speed=leader_speed,
            stop_gap=stop_gap,
            speed_limit=limit,
            dt=self.dt,
        )
        # Python lists: indexing them is several times cheaper than numpy scalars.
        ok = out["ok"].tolist()
        nx, ny, nth, nv, nd = (out[k].tolist() for k in ("x_m", "y_m", "theta_rad", "v_mps", "delta_rad"))
        e = out["lateral_error_m"].tolist()
        eth = out["heading_error_rad"].tolist()
        s_rear = out["s_rear_m"].tolist()
        kappa = out["curvature_per_m"].tolist()
        v_obs = out["virtual_obstacle_m"].tolist()
        limits = limit.tolist()
        s_fronts = s_front.tolist()
        trace = self.opt.trace
        move = sumo.vehicle.moveToXY
        move_to = sumo.vehicle.moveTo
        set_speed = sumo.vehicle.setSpeed
        dt = self.dt
        for i, (vid, act) in enumerate(zip(ids, acts)):
            rec = act.record
            if not ok[i]:
                # Unusable state (NaN): hand the vehicle back rather than move it anywhere.
                self._drop(vid, t, "invalid_state")
                continue
            x, y, th, v, d = nx[i], ny[i], nth[i], nv[i], nd[i]
            reach = act.wheelbase_m + act.front_overhang_m
            xf, yf = x + reach * math.cos(th), y + reach * math.sin(th)
            sf_new = s_rear[i] + reach
            geo = act.geo
            k = geo.piece_index_at(sf_new)
            edge, lane_index, lane_id = geo.piece_edge[k], geo.piece_index[k], geo.piece_lane[k]
            try:
                # The cheap call carries the same pose when the vehicle is on its
                # lane's centreline (SPEC §7): moveTo places it BEFORE SUMO's own
                # movement, so aim v dt short and let setSpeed(v) cover the rest.
                pos = (sf_new - geo.starts[k]) * geo.scales[k] - v * dt
                if k == len(geo.piece_lane) - 1 and geo.pending_change is None and sf_new > geo.length_m - 2.0 * v * dt - 2.0:
                    # About to arrive: a deferred (x, y) move would be applied
                    # after SUMO removed the vehicle. Let SUMO carry it to the end.
                    set_speed(vid, v)
                    self.cheap_moves += 1
                # Only when the whole vehicle is on that lane: SUMO keeps a
                # vehicle's back on the lanes behind it (its "further lanes")
                # through (x, y) moves, and a lane-position move would drop them.
                elif geo.plains[k] and pos >= act.length_m and abs(e[i]) < CHEAP_LATERAL_M and abs(eth[i]) < CHEAP_HEADING_RAD and v >= 0.0:
                    # Our arc length and SUMO's lane position can differ by a
                    # few cm (smoothed geometry, earlier (x, y) moves): never
                    # move a vehicle backwards into its follower's minGap.
                    sub = subs[vid]
                    if sub.get(tc.VAR_LANE_ID) == lane_id:
                        pos = max(pos, float(sub.get(tc.VAR_LANEPOSITION, pos)))
                    move_to(vid, lane_id, pos)
                    set_speed(vid, v)
                    self.cheap_moves += 1
                else:
                    angle = math.degrees(math.pi / 2.0 - th) % 360.0
                    move(vid, edge, lane_index, xf, yf, angle, 3)
                    # Without it SUMO keeps reporting the last setSpeed value,
                    # and followers plan with a wrong leader speed.
                    set_speed(vid, v)
                    self.xy_moves += 1
            except Exception:
                self.counts["vanished"] += 1
                self._drop(vid, t, "vanished")
                continue
            # Red-light crossing: the front passed a stop line whose light is red.
            old_sf = s_fronts[i]
            if act.next_stop < len(act.geo.stops) and old_sf == old_sf:
                s_stop, tls, link = act.geo.stops[act.next_stop][:3]
                if tls and old_sf < s_stop <= sf_new and self._tls_char(tls, link) in "rR":
                    rec.red_light_violations += 1
                    self.violations.append((t, vid, tls, link, old_sf, sf_new, s_stop))
            self._s_front[vid] = sf_new
            prev_v = self._state[vid][3]
            self._state[vid] = (x, y, th, v, d)
            acc = (v - prev_v) / dt
            lat_acc = v * v * math.tan(d) / act.wheelbase_m
            ae = abs(e[i])
            rec.steps += 1
            rec.sum_abs_e += ae
            rec.sum_e2 += ae * ae
            if ae > rec.max_abs_e:
                rec.max_abs_e = ae
            rec.sum_eth2 += eth[i] * eth[i]
            rec.sum_v += abs(v)
            rec.distance_m += abs(v) * dt
            if abs(lat_acc) > rec.max_lat_acc:
                rec.max_lat_acc = abs(lat_acc)
            if abs(lat_acc) > comfort:
                rec.time_above_comfort_s += dt
            if rec.last_acc == rec.last_acc:
                jerk = (acc - rec.last_acc) / dt
                rec.sum_jerk2 += jerk * jerk
                rec.jerk_n += 1
            rec.last_acc = acc
            if abs(v) > limits[i] * 1.0001:
                rec.speed_warnings += 1
            if v < 0.0:
                rec.reverse_warnings += 1
            if rec.steps % 10 == 0:
                self._samples.append((abs(kappa[i]), abs(v), ae, abs(lat_acc)))
            if act.trajectory is not None:
                act.trajectory.append((t, xf, yf, v, e[i], kappa[i]))
            if trace:
                self._trace_rows.append((t, vid, x, y, th, v, d, e[i], eth[i], s_rear[i], kappa[i], acc, v_obs[i], edge, lane_index))

    def _can_stop(self, act: _Active, v: float, gap: float) -> bool:
        c = act.config
        a = blendtrack.stopping_accel(v, gap, 0.0, c.preferred_stop_dist, c.reaction_time, c.max_deceleration, c.max_obs_deceleration)
        return a >= c.max_deceleration

    def _try_lane_change(self, act: _Active, sub: dict[int, Any], speed: float) -> None:
        """A lane change is due on this edge: make it once SUMO's lane-change
        model says the target lane has room (``couldChangeLane``)."""
        tc = self._tc
        geo = act.geo
        k_edge, target = geo.pending_change  # type: ignore[misc]
        edge = geo.edges[k_edge]
        lane_id = sub.get(tc.VAR_LANE_ID, "")
        if not lane_id or lane_id.rsplit("_", 1)[0] != edge:
            return
        current = int(lane_id.rsplit("_", 1)[1])
        if current == target:
            return
        direction = 1 if target > current else -1
        if not self.sumo.vehicle.couldChangeLane(act.vid, direction):
            return
        pos = float(sub.get(tc.VAR_LANEPOSITION, 0.0))
        lane_length = float(self._net_geometry().getLane(lane_id).getLength())
        length = min(max(2.0 * abs(speed), 10.0), 30.0, lane_length - pos - 1.0)
        if length < 8.0:
            return
        geo2, track, path = self._geometry(geo.edges[k_edge:], current, change=(pos, length))
        cfg = self.fleet.vehicle_config(act.slot)
        veh = self.fleet.vehicle_params(act.slot)
        self.fleet.remove_vehicle(act.slot)
        act.slot = self.fleet.add_vehicle(track, cfg, veh)
        act.geo = geo2
        act.next_stop = 0
        act.record.lane_changes += 1
        x, y, th = self._state[act.vid][:3]
        reach = act.wheelbase_m + act.front_overhang_m
        self._s_front[act.vid] = float(path.project(x + reach * math.cos(th), y + reach * math.sin(th))["s_m"])

    def _must_yield(self, vid: str, via: str) -> bool:
        """SUMO's view of the link ahead: does it lack priority with foes approaching?"""
        for link in self.sumo.vehicle.getNextLinks(vid):
            # (lane, has priority, is open, has foe, via lane, state, direction, length)
            if link[4] == via:
                return (not link[1]) and bool(link[3])
        return False

    def _tls_char(self, tls: str, link: int) -> str:
        st = self._tls_state.get(tls, "")
        return st[link] if 0 <= link < len(st) else "G"

    def _refresh_tls(self) -> None:
        tc = self._tc
        for tls, res in self.sumo.trafficlight.getAllSubscriptionResults().items():
            self._tls_state[tls] = res.get(tc.TL_RED_YELLOW_GREEN_STATE, "")

    def _rebuild(self, act: _Active) -> None:
        """The route changed (rerouting): rebuild the track from where the vehicle is."""
        v = self.sumo.vehicle
        route = tuple(v.getRoute(act.vid))
        idx = max(int(v.getRouteIndex(act.vid)), 0)
        geo, track, path = self._geometry(route[idx:], max(int(v.getLaneIndex(act.vid)), 0))
        cfg = self.fleet.vehicle_config(act.slot)
        veh = self.fleet.vehicle_params(act.slot)
        self.fleet.remove_vehicle(act.slot)
        act.slot = self.fleet.add_vehicle(track, cfg, veh)
        act.geo = geo
        act.next_stop = 0
        act.route_id = v.getRouteID(act.vid)
        x, y = v.getPosition(act.vid)
        self._s_front[act.vid] = float(path.project(x, y)["s_m"])

    def write_trace(self, file: Path) -> None:
        import csv

        with open(file, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["t_s", "id", "x_m", "y_m", "theta_rad", "v_mps", "delta_rad", "lateral_error_m", "heading_error_rad", "s_m", "curvature_per_m", "accel_mps2", "virtual_obstacle_m", "edge", "lane_index"])
            w.writerows(self._trace_rows)


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


def _first_line(e: BaseException) -> str:
    text = str(e).strip() or type(e).__name__
    return text.splitlines()[0]


def parse_ids(values: Iterable[str]) -> tuple[str, ...]:
    out: list[str] = []
    for v in values:
        out.extend(x for x in v.split(",") if x)
    return tuple(out)
