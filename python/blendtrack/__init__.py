"""blendtrack: path tracking with dynamic control point blending.

The numerics live in the native module ``blendtrack._blendtrack`` (Rust,
built by maturin); this package is its public face and re-exports what
callers need, so ``_blendtrack`` itself stays private.

- ``Path``: reference tracks (numpy array, TUM csv, built-ins, scaled).
- ``ControllerConfig`` / ``VehicleParams``: parameters under the paper's
  names, from/to TOML; ``load_config`` reads a whole config file.
- ``simulate``: one closed-loop run in Rust -> (pandas DataFrame, metrics dict);
  ``compute_metrics`` applies the same metrics to recorded columns.
- ``Fleet``: many vehicles on many tracks stepped in one call (numpy in/out).
- ``RouteFleet``: a Fleet driving road routes among traffic (lane pieces,
  stop lines, signals, per-vehicle statistics): the SUMO plugin's engine.
- Errors: ``BlendtrackError`` and its subclasses ``ConfigError``,
  ``PathError``, ``SimulationError``, ``InputError`` (also a ``ValueError``).
"""

from blendtrack._blendtrack import (
    BlendtrackError,
    ConfigError,
    ControllerConfig,
    Fleet,
    InputError,
    Path,
    PathError,
    RouteFleet,
    SimulationError,
    VehicleParams,
    __version__,
    compute_metrics,
    load_config,
    stopping_accel,
)
from blendtrack.simulation import METRIC_KEYS, load_track, parse_noise, simulate

__all__ = [
    "BlendtrackError",
    "ConfigError",
    "ControllerConfig",
    "Fleet",
    "InputError",
    "METRIC_KEYS",
    "Path",
    "PathError",
    "RouteFleet",
    "SimulationError",
    "VehicleParams",
    "__version__",
    "compute_metrics",
    "load_config",
    "load_track",
    "parse_noise",
    "simulate",
    "stopping_accel",
]
