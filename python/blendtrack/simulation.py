"""One closed-loop run from Python: track specs, noise and alpha specs, and
``simulate`` returning a pandas DataFrame plus the metrics dict.

The run itself is one call into Rust (``blendtrack._blendtrack.simulate``);
this module only turns friendly arguments (strings such as ``"circle:50"``,
``"uniform:0.05:0.5"``, ``"sine:0.2"``, or a Python callable for alpha) into
the native call's arguments.
"""

from __future__ import annotations

import os

import math
from collections.abc import Callable, Mapping
from pathlib import Path as FsPath
from typing import Any

import numpy as np
import pandas as pd

from blendtrack._blendtrack import (
    MAX_SIM_STEPS,
    ConfigError,
    ControllerConfig,
    Path,
    PathError,
    VehicleParams,
)
from blendtrack._blendtrack import simulate as _native_simulate

#: Built-in track names accepted by :func:`load_track` (besides files,
#: ``straight[:LENGTH]`` and ``circle:RADIUS``).
BUILTIN_TRACKS = ("test_track",)

#: The keys of ``metrics.json``, in order (see rust/blendtrack/src/metrics.rs
#: for the definitions): whole-run errors of the control point, the initial
#: transient (first time within 0.1 m, settled for good, initial overshoot),
#: the control point's mean |e| after first reaching 0.1 m and after settling,
#: and the true front and rear axles' errors with the body error
#: (mean over the run of max(|e_front|, |e_rear|)).
METRIC_KEYS = (
    "lateral_error_mean_abs_m",
    "lateral_error_rms_m",
    "lateral_error_max_abs_m",
    "heading_error_rms_deg",
    "steering_rate_rms_deg_s",
    "steering_rate_max_deg_s",
    "lateral_accel_max_mps2",
    "reached_time_s",
    "settling_time_s",
    "initial_overshoot_m",
    "mean_speed_mps",
    "distance_m",
    "lateral_error_mean_abs_m_reached",
    "lateral_error_mean_abs_m_settled",
    "lateral_error_rms_m_settled",
    "lateral_error_max_abs_m_settled",
    "heading_error_rms_deg_settled",
    "lateral_error_front_axle_mean_abs_m",
    "lateral_error_rear_axle_mean_abs_m",
    "body_error_mean_m",
    "body_error_max_m",
)

#: Further keys of :func:`simulate`'s metrics dict (not in ``metrics.json``):
#: the largest excursion to the side opposite the start anywhere in the run,
#: and the rest of the window from the first time |e| < 0.1 m on.
EXTRA_METRIC_KEYS = (
    "opposite_side_max_m",
    "lateral_error_rms_m_reached",
    "lateral_error_max_abs_m_reached",
    "heading_error_rms_deg_reached",
)


def file_problem(name: str | os.PathLike[str]) -> str | None:
    """Why ``name`` cannot be read as a data file, in a few words (None: it can)."""
    p = FsPath(name)
    if p.is_file():
        return None
    if not p.exists():
        return "no such file"
    if p.is_dir():
        return "a folder, not a file"
    return "not a regular file"

def _number(text: str, what: str, spec: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ConfigError(f"{what} in {spec!r} is not a number: {text!r}") from None
    if not math.isfinite(value):
        raise ConfigError(f"{what} in {spec!r} must be finite, got {text!r}")
    return value


def load_track(spec: str, scale: float | None = None) -> Path:
    """A path from a spec: a TUM csv file, ``straight[:LENGTH_M]`` (default
    1000 m), ``circle:RADIUS_M`` or a built-in name (:data:`BUILTIN_TRACKS`;
    ``-`` and ``_`` are interchangeable), optionally scaled by ``scale``.

    Raises PathError for an unknown name, an unreadable file or a bad number.
    """
    name = spec.strip()
    kind, _, arg = name.partition(":")
    key = kind.replace("-", "_").lower()
    if key == "straight":
        length = _number(arg, "length", spec) if arg else 1000.0
        path = Path.straight(length, 1.0)
    elif key == "circle":
        if not arg:
            raise PathError(f"track {spec!r}: give the radius, e.g. circle:50")
        path = Path.circle(_number(arg, "radius", spec), 0.001)
    elif key in BUILTIN_TRACKS and not arg:
        path = Path.test_track(1.0)
    elif FsPath(name).suffix.lower() == ".csv" or FsPath(name).exists():
        problem = file_problem(name)
        if problem:
            raise PathError(f"cannot read track file {name}: {problem}")
        path = Path.from_tum_csv(name, True)
    else:
        choices = ", ".join(["straight[:LENGTH]", "circle:RADIUS", *BUILTIN_TRACKS, "FILE.csv"])
        raise PathError(f"unknown track {spec!r} (expected one of: {choices})")
    if scale is not None:
        path = path.scaled(scale)
    return path


def parse_noise(spec: str | Mapping[str, Any] | None) -> dict[str, Any] | None:
    """Sensor noise from ``none``, ``uniform:POS_M[:HEADING_DEG]`` or
    ``walk:STEP_M:MAX_M[:HEADING_STEP_DEG:HEADING_MAX_DEG[:INTERVAL_S]]``
    (heading amplitudes default to 0, the walk interval to 0.1 s), or a dict
    in the core's form (``{"kind": "uniform", "position_m": ..., ...}``)."""
    if spec is None:
        return None
    if isinstance(spec, Mapping):
        return dict(spec)
    kind, *args = spec.strip().split(":")
    vals = [_number(a, "noise amplitude", spec) for a in args]
    if any(v < 0 for v in vals):
        raise ConfigError(f"noise {spec!r}: amplitudes must be >= 0")
    if kind == "none" and not vals:
        return None
    if kind == "uniform" and len(vals) in (1, 2):
        return {"kind": "uniform", "position_m": vals[0], "heading_deg": vals[1] if len(vals) == 2 else 0.0}
    if kind == "walk" and len(vals) in (2, 4, 5):
        heading = vals[2:4] if len(vals) >= 4 else [0.0, 0.0]
        interval = vals[4] if len(vals) == 5 else 0.1
        if interval <= 0:
            raise ConfigError(f"noise {spec!r}: the interval must be > 0")
        return {
            "kind": "random_walk",
            "position_step_m": vals[0],
            "position_max_m": vals[1],
            "heading_step_deg": heading[0],
            "heading_max_deg": heading[1],
            "interval_s": interval,
        }
    raise ConfigError(
        f"bad noise {spec!r} (expected none, uniform:POS_M[:HEADING_DEG] or "
        "walk:STEP_M:MAX_M[:HEADING_STEP_DEG:HEADING_MAX_DEG[:INTERVAL_S]])"
    )


AlphaSpec = float | str | Callable[[float], float] | None


def _alpha_kwargs(alpha: AlphaSpec, dt_s: float, duration_s: float) -> dict[str, Any]:
    if alpha is None or alpha == "auto":
        return {}
    if isinstance(alpha, str):
        kind, _, arg = alpha.partition(":")
        if kind == "sine" and arg:
            return {"alpha_sine_omega": _number(arg, "omega", alpha)}
        try:
            return {"alpha": float(alpha)}
        except ValueError:
            raise ConfigError(f"bad alpha {alpha!r} (expected a number in [0, 1] , sine:OMEGA or auto)") from None
    if callable(alpha):
        # Sampled on the time grid once, then run as a piecewise schedule in
        # Rust: exact at every step time, no Python call per step.
        for name, value in (("dt_s", dt_s), ("duration_s", duration_s)):
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ConfigError(f"simulation parameter `{name}` = {value}: must be finite and > 0")
        steps = duration_s / dt_s
        if not (math.isfinite(steps) and steps <= MAX_SIM_STEPS):
            raise ConfigError(
                f"alpha callable: duration_s / dt_s = {steps:g} steps to sample, more than the limit of {MAX_SIM_STEPS}"
            )
        n = max(1, round(steps))
        t = np.arange(n, dtype=np.float64) * dt_s
        values = np.array([float(alpha(float(ti))) for ti in t], dtype=np.float64)
        return {"alpha_knots": (t, values)}
    return {"alpha": float(alpha)}


def simulate(
    path: Path,
    config: ControllerConfig | None = None,
    vehicle: VehicleParams | None = None,
    *,
    alpha: AlphaSpec = None,
    dt_s: float = 0.01,
    duration_s: float = 60.0,
    laps: float | None = None,
    noise: str | Mapping[str, Any] | None = None,
    delay_s: float = 0.0,
    seed: int = 0,
    start_s_m: float = 0.0,
    offset_m: float = 0.0,
    heading_error_deg: float = 0.0,
    initial_speed_mps: float = 0.0,
    fixed_speed_mps: float | None = None,
) -> tuple[pd.DataFrame, dict[str, float]]:
    """Runs one closed-loop simulation in Rust.

    ``alpha``: None (the config's ``lat_blend_factor``, or its automatic alpha
    when ``alpha_mode = "auto"``), a number, ``"sine:OMEGA"`` (the paper's
    moving point ``0.5 (sin(OMEGA t) + 1)``), ``"auto"`` (the automatic alpha:
    the config with ``alpha_mode = "auto"``) or a callable of time. A fixed
    alpha given here with a config in auto mode is an error. Returns the time
    series (one row per step: t_s, x_m, y_m, theta_rad, v_mps, delta_rad,
    alpha (the one used), s_m, lateral_error_m, lateral_error_front_m,
    lateral_error_rear_m (the true axles), heading_error_rad, accel_mps2, virtual_obstacle_m, curvature_per_m,
    distance_m) and the metrics (:data:`METRIC_KEYS` then
    :data:`EXTRA_METRIC_KEYS`; NaN where undefined, i.e. the after-settling
    values of a run that never settles).
    """
    if alpha == "auto":
        config = (config or ControllerConfig()).replace(alpha_mode="auto")
    elif alpha is not None and config is not None and config.alpha_mode == "auto":
        raise ConfigError(f"alpha {alpha!r} given with a config whose alpha_mode is \"auto\" (pass alpha=None or \"auto\")")
    columns, metrics = _native_simulate(
        path,
        config,
        vehicle,
        dt_s=dt_s,
        duration_s=duration_s,
        laps=laps,
        noise=parse_noise(noise),
        delay_s=delay_s,
        seed=seed,
        start_s_m=start_s_m,
        offset_m=offset_m,
        heading_error_deg=heading_error_deg,
        initial_speed_mps=initial_speed_mps,
        fixed_speed_mps=fixed_speed_mps,
        **_alpha_kwargs(alpha, dt_s, duration_s),
    )
    return pd.DataFrame(columns), metrics
