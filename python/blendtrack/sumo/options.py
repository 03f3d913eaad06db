"""What a SUMO run controls and how: :class:`RunOptions` (importable from
:mod:`blendtrack.sumo.runner` as well). A module of its own so that every
part of the bridge can take the options without importing the runner."""

from __future__ import annotations

import math
from dataclasses import dataclass

from blendtrack import ControllerConfig, VehicleParams
from blendtrack.sumo.scenario import ScenarioError


#: The corridors a SUMO run can use (``RunOptions.corridor``).
CORRIDORS = ("lane", "arc", "road", "auto", "carriageway")
#: The ``auto`` corridor lifts the ray's cap with the curve speeds (as
#: ``road``) only where the lane's speed limit is at least this (m/s, 60 km/h):
#: town streets (50 km/h and under) keep the paper's ``lane`` corridor
#: (docs/sumo.md, "Curves").
AUTO_LIFT_MIN_LIMIT_MPS = 60.0 / 3.6
#: The ``auto`` corridor plans its curve speeds at this fraction of the
#: scenario's comfort bound: the tracking lags where SUMO's arcs begin
#: without a clothoid, and the rural loop's peaks were 2.5-2.65 m/s^2 with
#: the curve speeds at the bound of 2, 2.24 at 0.75 of it, 2.06 at 0.6
#: (docs/sumo.md, "Curves").
AUTO_LIFT_COMFORT_FRACTION = 0.5


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
    #: A fixed blend factor for every controlled vehicle, or "auto" (alpha_mode auto).
    alpha: float | str | None = None
    config: ControllerConfig | None = None
    vehicle: VehicleParams | None = None
    #: Controller keys the user set explicitly (config file, sweep): those
    #: keep their value. Otherwise ``path_width_m`` comes from the lanes'
    #: widths, ``preferred_speed`` from the vType's desired speed (maxSpeed x
    #: the vehicle's speedFactor, capped by the lane's limit), and
    #: ``max_obs_deceleration`` equals ``max_deceleration`` (why: see
    #: ``Selection.type_info``).
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
    #: Keep every controlled vehicle's record in memory (``RunResult.records``).
    #: Without, a record goes once its vehicle finishes (its row is in
    #: ``vehicles.csv`` and its sums in ``RunResult.totals``): a long run's
    #: memory stays flat. ``blendtrack sumo run`` keeps none.
    keep_records: bool = True
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
    #: What limits the speed in curves (docs/sumo.md, "Curves"): "arc" the curve speeds sqrt(a_y / |kappa|) previewed along the
    #: path, a_y = the config's ``curve_lateral_accel`` when set, else the
    #: scenario's comfort bound on lateral acceleration; "lane" the paper's
    #: virtual borders at the lane's half width (plus ``border_margin_m``) and
    #: its ray cast; "road" the faster of "lane" and "arc" (config
    #: ``curve_with_ray``); "auto" "road" (its curve speeds at
    #: ``AUTO_LIFT_COMFORT_FRACTION`` of the comfort bound) where the lane's speed
    #: limit is at least ``AUTO_LIFT_MIN_LIMIT_MPS`` and "lane" under it (config
    #: ``curve_lift_min_limit_mps``; the default); "carriageway" the same ray cast with the borders at the
    #: edges of the lane's whole edge (junction lanes keep their half width).
    corridor: str = "auto"
    #: Stop at the end of the route (a standing obstacle there). By default
    #: controlled vehicles, like SUMO's drivers (``arrivalSpeed="current"``),
    #: leave the network at their route's end without slowing down.
    stop_at_route_end: bool = False
    #: Let controlled vehicles change lanes where their route does not need
    #: it, when SUMO's lane-change model would (to overtake, keep right or
    #: make room): see ``lanechange.TACTICAL_CHECK_EVERY``. Off by default:
    #: only the changes the route needs (see the README for what it does to a
    #: merge). Experimental: tried on 2 networks and 3 seeds; on the urban
    #: grid it adds teleports (README, known limits).
    tactical_lane_changes: bool = False
    #: Ask the SUMO driver behind a controlled vehicle waiting to change
    #: lanes to open a gap for it (TraCI ``openGap``, braking at most
    #: 2 m/s^2), as SUMO's drivers do for each other: see
    #: ``lanechange.COURTESY_DECEL_MPS2``. Off: blendtrack never influences
    #: a vehicle it does not drive.
    open_gaps: bool = True
    #: The control rate (s, > 0): in every SUMO step of ``dt`` the
    #: controllers and the bicycle model run ``ceil(dt / control_dt_s)``
    #: times, with leaders and signals held for the step, and the vehicle is
    #: placed once (docs/sumo.md, "Control rate and SUMO's step length").
    #: ``control_dt_s >= dt`` gives one control step per SUMO step.
    control_dt_s: float = 0.05
    #: A controlled vehicle that has stood this long (s) at the end of its
    #: lane waiting for a lane change its route needs there drives on along
    #: its lane and is rerouted to its destination, or out of the network
    #: where no way leads back (``missed_exits`` in summary.json and
    #: vehicles.csv; ``lanechange.MISS_EXIT_SPEED_MPS``). 0: never, it waits
    #: as SUMO's drivers do until SUMO teleports it. 20 s: at Eccles (seeds
    #: 0-23, 30 %) background time loss +4.1 % against +18.2 % with 0 and
    #: +12.0 % with 60 s, 5.8 % of the controlled vehicles missing an exit
    #: (2.8 % at 60 s); docs/sumo.md, "Lane changes".
    miss_exit_after_s: float = 20.0

    def __post_init__(self) -> None:
        m = self.border_margin_m
        if not (isinstance(m, (int, float)) and math.isfinite(m) and m >= 0.0):
            raise ScenarioError(f"border margin {m!r} m: must be a finite number >= 0")
        if self.corridor not in CORRIDORS:
            raise ScenarioError(f"corridor {self.corridor!r}: must be one of {', '.join(CORRIDORS)}")
        c = self.control_dt_s
        if not (isinstance(c, (int, float)) and math.isfinite(c) and c > 0.0):
            raise ScenarioError(f"control dt {c!r} s: must be a finite number > 0")
        w = self.miss_exit_after_s
        if not (isinstance(w, (int, float)) and math.isfinite(w) and w >= 0.0):
            raise ScenarioError(f"miss exit after {w!r} s: must be a finite number >= 0 (0: never)")
