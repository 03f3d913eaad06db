"""Type stubs of the native module (rust/blendtrack-py).

Keep in step with the module: scripts/test runs
``python -m mypy.stubtest blendtrack._blendtrack`` against the build.
"""

import os
from collections.abc import Callable, Sequence
from typing import Any, Literal, final

import numpy as np
import numpy.typing as npt

__all__ = [
    "__version__",
    "MAX_SIM_STEPS",
    "HOLD_BRAKING_MIN_STEP_S",
    "ADVANCE_MAX_M",
    "BlendtrackError",
    "ConfigError",
    "PathError",
    "SimulationError",
    "InputError",
    "Path",
    "ControllerConfig",
    "VehicleParams",
    "load_config",
    "simulate",
    "compute_metrics",
    "stopping_accel",
    "Fleet",
    "RouteFleet",
    "polyline_arc_lengths",
    "polyline_resample",
    "polyline_smooth",
    "polyline_blend",
    "polyline_join",
    "polyline_distance",
    "smoothstep",
]

__version__: str
#: Most steps one ``simulate`` run may record (the core refuses more, before allocating).
MAX_SIM_STEPS: int
#: The shortest simulator step (s) over which the traffic engine holds leaders by what they can still do
#: within the step (a braking one at its mean speed, one it drives with its own control steps, one the
#: simulator drives at its stop point); the SUMO bridge uses the same bound.
HOLD_BRAKING_MIN_STEP_S: float
#: The most (m) ``RouteFleet.advance_state`` moves a vehicle on (more is a lost vehicle, not a lag).
ADVANCE_MAX_M: float

_F64 = npt.NDArray[np.float64]
_ArrayLike = npt.ArrayLike

class BlendtrackError(Exception):
    """Base class of every error raised by blendtrack."""

class ConfigError(BlendtrackError):
    """An invalid parameter or configuration (the message names the key)."""

class PathError(BlendtrackError):
    """A reference path that cannot be built or read (the message names the row)."""

class SimulationError(BlendtrackError):
    """A simulation that cannot proceed."""

class InputError(BlendtrackError, ValueError):
    """A bad argument to a call: wrong array length, unknown slot or track, bad time step (the message names it)."""

@final
class Path:
    def __new__(cls, points: _ArrayLike, widths: _ArrayLike | None = None, closed: bool = False) -> Path: ...
    @staticmethod
    def from_tum_csv(file: str | os.PathLike[str], closed: bool = True) -> Path: ...
    @staticmethod
    def straight(length_m: float, spacing_m: float = 1.0) -> Path: ...
    @staticmethod
    def circle(radius_m: float, max_sagitta_m: float = 0.001) -> Path: ...
    @staticmethod
    def test_track(spacing_m: float = 1.0) -> Path: ...
    def scaled(self, factor: float) -> Path: ...
    @property
    def length_m(self) -> float: ...
    @property
    def is_closed(self) -> bool: ...
    @property
    def has_widths(self) -> bool: ...
    def __len__(self) -> int: ...
    def points(self) -> _F64: ...
    def widths(self) -> _F64 | None: ...
    def vertex_s(self) -> _F64: ...
    def point_at(self, s_m: float) -> tuple[float, float]: ...
    def heading_at(self, s_m: float) -> float: ...
    def curvature_at(self, s_m: float) -> float: ...
    def project(self, x_m: float, y_m: float) -> dict[str, float]: ...

@final
class ControllerConfig:
    lat_blend_factor: float
    acceleration_exp: float
    deceleration_factor: float
    max_deceleration: float
    max_obs_deceleration: float
    path_width_m: float
    preferred_acceleration: float
    preferred_deceleration: float
    preferred_speed: float
    preferred_stop_dist: float
    reaction_time: float
    direction: str
    lateral_controller: str
    stanley_gain: float
    stanley_gain_reverse: float
    stanley_softening_mps: float
    target_distance_min_m: float
    target_distance_gain_s: float
    curvature_lookahead_gain_s: float
    pure_pursuit_gain_s: float
    pure_pursuit_min_lookahead_m: float
    use_path_widths: bool
    border_margin_m: float
    ray_horizon_m: float
    emergency_deceleration: float
    curve_lateral_accel: float
    curve_deceleration: float
    curve_with_ray: bool
    curve_smoothing_m: float
    curve_lift_min_limit_mps: float
    alpha_mode: str
    auto_alpha_forward: float
    auto_alpha_backward: float
    auto_alpha_curve_gain: float
    auto_alpha_curvature_change_gain: float
    auto_alpha_preview_s: float
    auto_alpha_large_error_m: float
    auto_alpha_error_gain: float
    def __new__(cls, **kwargs: Any) -> ControllerConfig: ...
    def replace(self, **kwargs: Any) -> ControllerConfig: ...
    def validate(self) -> None: ...
    @staticmethod
    def from_toml(text: str, source: str = "<string>") -> ControllerConfig: ...
    @staticmethod
    def load(file: str | os.PathLike[str]) -> ControllerConfig: ...
    @staticmethod
    def keys_in_file(file: str | os.PathLike[str]) -> set[str]: ...
    def with_alpha(self, alpha: float | Literal["auto"] | None) -> ControllerConfig: ...
    def to_toml(self, table: bool = False) -> str: ...
    def to_dict(self) -> dict[str, Any]: ...
    def __copy__(self) -> ControllerConfig: ...
    def __deepcopy__(self, _memo: Any) -> ControllerConfig: ...
    def __reduce__(self) -> tuple[Any, tuple[str, str]]: ...
    def __eq__(self, value: object, /) -> bool: ...

@final
class VehicleParams:
    wheelbase_m: float
    max_steering_deg: float
    max_steering_rate_deg_s: float
    max_acceleration_mps2: float
    max_braking_mps2: float
    max_speed_mps: float
    def __new__(cls, **kwargs: Any) -> VehicleParams: ...
    def replace(self, **kwargs: Any) -> VehicleParams: ...
    def validate(self) -> None: ...
    @staticmethod
    def from_toml(text: str, source: str = "<string>") -> VehicleParams: ...
    @staticmethod
    def load(file: str | os.PathLike[str]) -> VehicleParams: ...
    def to_toml(self) -> str: ...
    def to_dict(self) -> dict[str, Any]: ...
    def __reduce__(self) -> tuple[Any, tuple[str, str]]: ...
    def __eq__(self, value: object, /) -> bool: ...

def load_config(file: str | os.PathLike[str]) -> tuple[ControllerConfig, VehicleParams]: ...
def simulate(
    path: Path,
    config: ControllerConfig | None = None,
    vehicle: VehicleParams | None = None,
    *,
    alpha: float | None = None,
    alpha_sine_omega: float | None = None,
    alpha_knots: tuple[_F64, _F64] | None = None,
    dt_s: float = 0.01,
    duration_s: float = 60.0,
    laps: float | None = None,
    noise: dict[str, Any] | None = None,
    delay_s: float = 0.0,
    seed: int = 0,
    start_s_m: float = 0.0,
    offset_m: float = 0.0,
    heading_error_deg: float = 0.0,
    initial_speed_mps: float = 0.0,
    fixed_speed_mps: float | None = None,
) -> tuple[dict[str, _F64], dict[str, float]]: ...
def compute_metrics(
    t_s: _F64,
    lateral_error_m: _F64,
    heading_error_rad: _F64,
    delta_rad: _F64,
    v_mps: _F64,
    distance_m: _F64,
    wheelbase_m: float = 2.6,
    lateral_error_front_m: _F64 | None = None,
    lateral_error_rear_m: _F64 | None = None,
) -> dict[str, float]: ...

@final
class Fleet:
    def __new__(cls) -> Fleet: ...
    def add_track(self, path: Path, config: ControllerConfig | None = None) -> int: ...
    def add_vehicle(self, track_id: int, config: ControllerConfig | None = None, vehicle: VehicleParams | None = None) -> int: ...
    def remove_vehicle(self, slot: int) -> None: ...
    def reset_vehicle(self, slot: int) -> None: ...
    def set_vehicle_config(self, slot: int, config: ControllerConfig) -> None: ...
    def vehicle_config(self, slot: int) -> ControllerConfig: ...
    def vehicle_params(self, slot: int) -> VehicleParams: ...
    def vehicle_track(self, slot: int) -> int: ...
    def slots(self) -> npt.NDArray[np.int64]: ...
    @property
    def n_tracks(self) -> int: ...
    @property
    def threads(self) -> int: ...
    @threads.setter
    def threads(self, threads: int) -> None: ...
    def __len__(self) -> int: ...
    def step(
        self,
        slots: _ArrayLike,
        x: _ArrayLike,
        y: _ArrayLike,
        theta: _ArrayLike,
        v: _ArrayLike,
        delta: _ArrayLike,
        alpha: _ArrayLike | None = None,
        leader_gap: _ArrayLike | None = None,
        leader_speed: _ArrayLike | None = None,
        stop_gap: _ArrayLike | None = None,
        speed_limit: _ArrayLike | None = None,
        dt: float | None = None,
        soft_gap: _ArrayLike | None = None,
        soft_speed: _ArrayLike | None = None,
    ) -> dict[str, npt.NDArray[Any]]: ...

@final
class RouteFleet:
    def __new__(
        cls,
        *,
        standstill_margin_m: float = 1.0,
        yield_lookahead_m: float = 30.0,
        lane_change_room_m: float = 15.0,
        stop_at_route_end: bool = False,
        route_end_extra_m: float = 5.0,
        route_end_horizon_m: float = 200.0,
        lane_move_lateral_m: float = 0.15,
        lane_move_heading_deg: float = 2.0,
        comfort_lateral_accel_mps2: float = 2.0,
        sample_every: int = 10,
        verify_every: int = 10,
        control_dt_s: float = 0.05,
    ) -> RouteFleet: ...
    def add_route(
        self,
        path: Path,
        config: ControllerConfig | None,
        *,
        piece_start_m: _ArrayLike,
        piece_scale: _ArrayLike,
        piece_offset_m: _ArrayLike,
        piece_lane_length_m: _ArrayLike,
        piece_speed_mps: _ArrayLike,
        piece_lane: _ArrayLike,
        piece_edge: _ArrayLike,
        piece_lane_index: _ArrayLike,
        length_m: float,
        piece_lane_pos_m: _ArrayLike | None = None,
        stop_s_m: _ArrayLike | None = None,
        stop_light: _ArrayLike | None = None,
        stop_link: _ArrayLike | None = None,
        stop_major: _ArrayLike | None = None,
        stop_via: _ArrayLike | None = None,
        stop_exit_m: _ArrayLike | None = None,
        stop_check_inside: _ArrayLike | None = None,
        lane_change: tuple[int, int] | tuple[int, int, int] | None = None,
        piece_occurrence: _ArrayLike | None = None,
        station_m: _ArrayLike | None = None,
    ) -> int: ...
    def add_vehicle(
        self,
        track_id: int,
        config: ControllerConfig | None,
        vehicle: VehicleParams | None,
        *,
        reach_m: float,
        length_m: float,
        min_gap_m: float,
        x: float,
        y: float,
        theta: float,
        v: float,
        delta: float = 0.0,
        name: str | None = None,
        occurrence: int | None = None,
    ) -> int: ...
    def retrack(self, slot: int, track_id: int, occurrence: int | None = None) -> None: ...
    def advance_state(self, slot: int, by_m: float) -> None: ...
    def remove_route(self, track_id: int) -> None: ...
    def remove_vehicle(self, slot: int) -> dict[str, float]: ...
    def stats(self, slot: int) -> dict[str, float]: ...
    def state(self, slot: int) -> tuple[float, float, float, float, float]: ...
    def set_halt(self, slot: int, s_m: float) -> None: ...
    def halt(self, slot: int) -> float: ...
    def s_front(self, slot: int) -> float: ...
    def occurrence(self, slot: int) -> int: ...
    def front_lane_position(self, slot: int) -> tuple[int, float]: ...
    def occurrences_near_front(self, slot: int, slack_m: float) -> list[int]: ...
    def arc_at_lane_position(self, slot: int, lane: int, pos_m: float, s_from_m: float) -> float | None: ...
    def next_stop(self, slot: int) -> tuple[float, int, int, bool, int, float] | None: ...
    def stops_ahead(
        self, slots: _ArrayLike, max_m: float
    ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.float64]]: ...
    def vehicle_config(self, slot: int) -> ControllerConfig: ...
    def vehicle_params(self, slot: int) -> VehicleParams: ...
    def vehicle_track(self, slot: int) -> int: ...
    def set_signal(self, light: int, state: str) -> None: ...
    def plan(
        self,
        slots: _ArrayLike,
        leader_gap: _ArrayLike,
        leader_slot: _ArrayLike,
        leader_speed: _ArrayLike,
        lane: _ArrayLike,
        lane_pos: _ArrayLike,
    ) -> npt.NDArray[np.int64]: ...
    def plan_sumo(
        self,
        slots: _ArrayLike,
        leaders: Sequence[tuple[str, float] | tuple[str, float, float] | None],
        speed_of: Callable[[str], float],
        read_index: _ArrayLike | None = None,
        read_lane: _ArrayLike | None = None,
        read_pos: _ArrayLike | None = None,
        leader_index: _ArrayLike | None = None,
        soft_leaders: Sequence[tuple[int, str, float]] | None = None,
    ) -> npt.NDArray[np.int64]: ...
    def lanes_with_followers(self, slots: _ArrayLike) -> npt.NDArray[np.int64]: ...
    def leaders_on_lanes(self, slots: _ArrayLike, lanes: _ArrayLike, vehicles: Sequence[Sequence[str]]) -> npt.NDArray[np.int64]: ...
    def listed_leaders(self) -> list[tuple[str, float] | None]: ...
    def step(self, must_yield: _ArrayLike, dt: float) -> dict[str, npt.NDArray[Any]]: ...
    def take_samples(self) -> npt.NDArray[np.float64]: ...
    @property
    def n_tracks(self) -> int: ...
    @property
    def track_capacity(self) -> int: ...
    @property
    def threads(self) -> int: ...
    @threads.setter
    def threads(self, threads: int) -> None: ...
    @property
    def ballistic(self) -> bool: ...
    @ballistic.setter
    def ballistic(self, ballistic: bool) -> None: ...
    def __len__(self) -> int: ...

def stopping_accel(v_mps: float, gap_m: float, v_l_mps: float, s0_m: float, tau_s: float, b_f_mps2: float, b_l_mps2: float) -> float: ...

def polyline_arc_lengths(points: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]: ...
def polyline_resample(
    points: npt.NDArray[np.float64], spacing_m: float
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], float]: ...
def polyline_smooth(points: npt.NDArray[np.float64], sigma_pts: float) -> npt.NDArray[np.float64]: ...
def polyline_blend(
    source: npt.NDArray[np.float64],
    target: npt.NDArray[np.float64],
    spacing_m: float,
    start_m: float | None = None,
    length_m: float | None = None,
) -> tuple[
    npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64], float, float
]: ...
def polyline_join(
    pieces: list[tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], bool, float]],
    sigma_pts: float,
    near_m: float,
    min_run: int,
    kappa_max: float = 0.0,
) -> dict[str, Any]: ...
def polyline_distance(p: npt.NDArray[np.float64], q: npt.NDArray[np.float64]) -> float: ...
def smoothstep(u: float) -> float:
    """The lateral profile of a lane change's blend (``polyline_blend``): 3u^2 - 2u^3 of ``u`` clamped to [0, 1]."""
