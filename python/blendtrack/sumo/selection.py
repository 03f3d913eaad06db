"""Which vehicles blendtrack controls, and with what: the selection rules
(a seeded fraction, a vType, explicit ids, or the vType parameter
``blendtrack.controlled``) and each vType's controller and vehicle
(``blendtrack.*`` vType parameters over the run's configuration)."""

from __future__ import annotations

import hashlib
from collections.abc import Iterable
from typing import Any

import blendtrack
from blendtrack import ControllerConfig, VehicleParams
from blendtrack.sumo.connection import SumoConnection
from blendtrack.sumo.options import AUTO_LIFT_COMFORT_FRACTION, AUTO_LIFT_MIN_LIMIT_MPS, RunOptions
from blendtrack.sumo.scenario import ScenarioError

#: vType parameter that marks a type as controlled.
CONTROLLED_PARAM = "blendtrack.controlled"
#: Prefix of per-vType parameter overrides, e.g. ``blendtrack.lat_blend_factor``.
PARAM_PREFIX = "blendtrack."
#: SUMO's vehicle classes that run on rails (SUMO's own list of rail
#: classes, with the tram and the cable car): such a vehicle is guided by its
#: track and has no steering for a path-tracking controller to command, so
#: blendtrack never takes one over; it stays SUMO's, counted as
#: ``rail_bound_not_controlled`` when the selection named it. (Driven, the
#: three trains of SUMO's tools/game/rail_demo were each handed back with a
#: placement fault within 105 s, after 20-70 m.)
RAIL_BOUND = frozenset({"tram", "rail_urban", "rail", "rail_electric", "rail_fast", "subway", "cable_car"})


def unit_hash(seed: int, vid: str) -> float:
    """A vehicle id's seeded hash in [0, 1): below the controlled fraction, selected."""
    h = hashlib.blake2b(f"{seed}:{vid}".encode(), digest_size=8).digest()
    return int.from_bytes(h, "little") / 2.0**64


def parse_like(raw: str, current: Any) -> Any:
    """A vType parameter's text as the type of the value it replaces."""
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


def parse_ids(values: Iterable[str]) -> tuple[str, ...]:
    """Vehicle ids from command-line values, each one or several comma-separated."""
    out: list[str] = []
    for v in values:
        out.extend(x for x in v.split(",") if x)
    return tuple(out)


#: The road corridor's curve speeds read the track's curvature averaged
#: with a Gaussian of this standard deviation (m; arc reads it as drawn,
#: which keeps to the comfort bound at lane joints' kinks too): SUMO
#: draws a road's curve as a polyline, vertices up to about 20 m apart on a
#: motorway loop, and read as drawn each vertex is a sharp curve (Eccles'
#: R = 230 m loop: about R = 40 m at each vertex, 9 m/s instead of 21 m/s
#: at 2 m/s^2; the core's curve_speed tests).
CURVE_SMOOTHING_M = 10.0


class Selection:
    """The run's selection rule and the controller and vehicle of each vType
    (read from SUMO once per vType)."""

    def __init__(self, options: RunOptions, conn: SumoConnection) -> None:
        self.opt = options
        self.conn = conn
        self.base_config = (options.config or ControllerConfig()).replace(
            use_path_widths="path_width_m" not in options.fixed_keys
        )
        self.base_vehicle = options.vehicle or VehicleParams()
        self.base_config = self.base_config.with_alpha(options.alpha)
        curves = options.corridor in ("arc", "road", "auto")
        lifted = options.corridor in ("road", "auto")
        if "curve_lateral_accel" not in options.fixed_keys:
            # The arc and road corridors keep to the scenario's comfort bound,
            # auto to a fraction of it; the others are the paper's ray cast
            # (curve_lateral_accel 0).
            a_y = conn.scenario.comfort_lateral_accel_mps2 if curves else 0.0
            if options.corridor == "auto":
                a_y *= AUTO_LIFT_COMFORT_FRACTION
            self.base_config = self.base_config.replace(curve_lateral_accel=a_y)
        if "curve_with_ray" not in options.fixed_keys:
            # road and auto: the faster of the ray cast and the curve speeds.
            self.base_config = self.base_config.replace(curve_with_ray=lifted)
        if lifted and "curve_smoothing_m" not in options.fixed_keys:
            self.base_config = self.base_config.replace(curve_smoothing_m=CURVE_SMOOTHING_M)
        if options.corridor == "auto" and "curve_lift_min_limit_mps" not in options.fixed_keys:
            # Town streets keep the paper's corridor; faster roads get the lift.
            self.base_config = self.base_config.replace(curve_lift_min_limit_mps=AUTO_LIFT_MIN_LIMIT_MPS)
        self._types: dict[str, dict[str, Any]] = {}
        #: vType -> does it run on rails (RAIL_BOUND), asked of SUMO once.
        self._rail_bound: dict[str, bool] = {}
        #: Vehicles the rule selected that run on rails, left to SUMO.
        self.rail_bound_skipped = 0
        #: The vTypes --controlled-type stands for (a distribution: its members).
        self.controlled_types: set[str] = set()
        if options.controlled_type is not None:
            members = conn.scenario.vtypes().members(options.controlled_type)
            self.controlled_types = set(members or [options.controlled_type])

    def type_info(self, vtype: str) -> dict[str, Any]:
        """The controller, vehicle and SUMO sizes of ``vtype``."""
        info = self._types.get(vtype)
        if info is not None:
            return info
        vt = self.conn.sumo.vehicletype
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
                target[key] = parse_like(raw, current)
            except ValueError:
                raise ScenarioError(f"vType {vtype!r}: param {PARAM_PREFIX + key} = {raw!r} is not a valid {type(current).__name__}") from None
        self._check_param_names(vtype, cfg_keys | veh_keys)
        param_keys = {PARAM_PREFIX + k for k in (*overrides, *vehicle_overrides)}
        # The hardest braking without a plan: the vType's own emergency
        # deceleration, unless set explicitly.
        emergency = float(vt.getEmergencyDecel(vtype))
        if "emergency_deceleration" not in self.opt.fixed_keys and "emergency_deceleration" not in overrides and emergency > 0:
            overrides["emergency_deceleration"] = -emergency
        # max_obs_deceleration in SUMO runs, unless set explicitly
        # (RunOptions.fixed_keys or a blendtrack.* vType param): the paper assumes an
        # obstacle braking at 8 m/s^2 while the vehicle plans with 4, which at 33 m/s
        # keeps about 3 s to a leader and cuts a highway's capacity nearly in half
        # (measured: 378 instead of 650 vehicles entered, highway_onramp x2, 300 s,
        # every vehicle controlled). Here the leader is assumed to brake as hard as
        # the vehicle plans to (max_obs_deceleration = max_deceleration): about
        # reaction_time s of headway at equal speeds, the assumption of SUMO's Krauss
        # model.
        if "max_obs_deceleration" not in self.opt.fixed_keys and "max_obs_deceleration" not in overrides:
            overrides["max_obs_deceleration"] = overrides.get("max_deceleration", self.base_config.max_deceleration)
        # preferred_acceleration keeps the paper's 1 m/s^2 unless set (a
        # blendtrack.preferred_acceleration vType param, or --config). The
        # vType's accel (2.6 m/s^2 for SUMO's passenger car) gains arrivals but
        # brought collisions with controlled vehicles at Eccles (vehicles
        # changing two lanes in one go into a dense stream): docs/sumo.md.
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
            "width": float(vt.getWidth(vtype)),
            "min_gap": float(vt.getMinGap(vtype)),
            "max_speed": float(vt.getMaxSpeed(vtype)),
        }
        self._types[vtype] = info
        return info

    def _check_param_names(self, vtype: str, keys: set[str]) -> None:
        """A ``blendtrack.*`` parameter of ``vtype`` that names no key is an
        error naming it and the closest key (a typo would be ignored)."""
        import difflib

        if not self.conn.scenario.declares(PARAM_PREFIX):
            # No file names a parameter of ours: nothing to check, and the
            # route files (Bologna's: 1.7 MB) need no parse.
            return
        declared = self.conn.scenario.vtypes().types.get(vtype, {})
        for name in declared:
            if not name.startswith(PARAM_PREFIX) or name == CONTROLLED_PARAM:
                continue
            key = name[len(PARAM_PREFIX):]
            if key not in keys:
                close = difflib.get_close_matches(key, sorted(keys), n=1)
                hint = f" (did you mean {PARAM_PREFIX + close[0]}?)" if close else ""
                raise ScenarioError(f"vType {vtype!r}: unknown parameter {name!r}{hint}")

    def is_selected(self, vid: str, vtype: str, n_controlled: int) -> bool:
        """Is ``vid`` (of ``vtype``) to be controlled, ``n_controlled`` being
        taken over so far? Never one that runs on rails (``RAIL_BOUND``)."""
        if not self._rule(vid, vtype, n_controlled):
            return False
        if self.rail_bound(vtype):
            self.rail_bound_skipped += 1
            return False
        return True

    def _rule(self, vid: str, vtype: str, n_controlled: int) -> bool:
        o = self.opt
        if o.max_controlled is not None and n_controlled >= o.max_controlled:
            return False
        if o.controlled_ids:
            return vid in o.controlled_ids
        if o.controlled_fraction is not None:
            return unit_hash(o.seed, vid) < o.controlled_fraction
        if o.controlled_type is not None:
            return vtype in self.controlled_types
        return bool(self.type_info(vtype)["controlled_param"])

    def rail_bound(self, vtype: str) -> bool:
        """Does ``vtype`` run on rails (its vClass, as SUMO has it, in ``RAIL_BOUND``)?"""
        known = self._rail_bound.get(vtype)
        if known is None:
            known = self._rail_bound[vtype] = str(self.conn.sumo.vehicletype.getVehicleClass(vtype)) in RAIL_BOUND
        return known
