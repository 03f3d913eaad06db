"""Shared pieces of the paper study: tracks, the two driving scenarios, the
two parameter sets and 95 % confidence intervals.

Used by :mod:`blendtrack.paper` (the report) and ``scripts/paper_tune.py``
(the tuning sweep on the training tracks and the held-out evaluation, whose
results ``configs/paper_tuned.json`` the report reads).

- Training tracks: the built-in ``test_track`` and the Nuerburgring;
  held-out tracks: every other ``*.csv`` of ``../shared/tracks/`` (read from
  there, never copied). Track files are scaled as the report scales the
  Nuerburgring (:func:`blendtrack.paper.choose_scale`); ``test_track`` is
  used as built.
- Forward scenario (the paper's section V-A): preferred speed 8 m/s, start
  4 m off the path, one lap, uniform sensor noise +-0.05 m / +-0.5 deg and a
  0.1 s actuation delay, seeded.
- Backward scenario (the paper's tests #4-#6): preferred speed 1 m/s, start
  2 m off, the same noise and delay, the first 800 m of the lap.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path as FsPath
from typing import Any

import numpy as np

from blendtrack._blendtrack import ConfigError, ControllerConfig, Path, VehicleParams
from blendtrack.simulation import simulate

REPO_ROOT = FsPath(__file__).resolve().parents[2]
SHARED_TRACKS = REPO_ROOT.parent / "shared" / "tracks"
TUNED_FILE = REPO_ROOT / "configs" / "paper_tuned.json"
TRAINING = ("test_track", "Nuerburgring")
NOISE = "uniform:0.05:0.5"
DELAY_S = 0.1


def clothoid_entry(straight_m: float = 100.0, clothoid_m: float = 150.0, radius_m: float = 40.0, arc_m: float = 150.0) -> tuple[Path, float]:
    """An open test path: a straight, a clothoid whose curvature grows
    linearly from 0 to 1/R over ``clothoid_m``, and an arc; points every
    0.25 m. Returns the path and the clothoid's curvature rate c (1/m^2)."""
    c = 1.0 / (radius_m * clothoid_m)
    ds = 0.25
    n = int((straight_m + clothoid_m + arc_m) / ds)
    x = y = th = 0.0
    pts = [(x, y)]
    for i in range(n):
        sm = (i + 0.5) * ds - straight_m
        kappa = 0.0 if sm < 0 else (c * sm if sm < clothoid_m else 1.0 / radius_m)
        th_mid = th + 0.5 * kappa * ds
        x += ds * math.cos(th_mid)
        y += ds * math.sin(th_mid)
        th += kappa * ds
        pts.append((x, y))
    return Path(np.array(pts)), c


def clothoid_plateau_m(d_m: float, lookahead_m: float, speed_mps: float, delay_s: float = 0.0) -> tuple[float, float]:
    """The rear law alone (alpha 0, d and L fixed) at a fixed speed through
    :func:`clothoid_entry`: the rear axle's simulated error at the end of the
    clothoid's plateau (arc length ``clothoid_m - L`` into it) and the closed
    form ``c (L - 2 v tau) d^2 / 4`` (docs/paper.md)."""
    straight_m, clothoid_m = 100.0, 150.0
    path, c = clothoid_entry(straight_m, clothoid_m)
    cfg = ControllerConfig(
        lat_blend_factor=0.0,
        target_distance_min_m=d_m,
        target_distance_gain_s=0.0,
        curvature_lookahead_gain_s=lookahead_m / speed_mps,
        preferred_speed=speed_mps,
    )
    frame, _ = simulate(path, cfg, fixed_speed_mps=speed_mps, duration_s=(path.length_m - 5.0) / speed_mps, delay_s=delay_s)
    s = frame["s_m"].to_numpy() - straight_m
    at = int(np.searchsorted(s, clothoid_m - lookahead_m))
    return float(frame["lateral_error_rear_m"].to_numpy()[at]), c * (lookahead_m - 2.0 * speed_mps * delay_s) * d_m * d_m / 4.0


def held_out_tracks() -> list[str]:
    """Names of the track files in ../shared/tracks other than the training ones."""
    return sorted(p.stem for p in SHARED_TRACKS.glob("*.csv") if p.stem not in TRAINING)


def track(name: str, vehicle: VehicleParams) -> Path:
    """``test_track`` as built, or ``../shared/tracks/NAME.csv`` scaled as the report scales the Nuerburgring."""
    from blendtrack.paper import choose_scale, tightest_radius_m

    if name == "test_track":
        return Path.test_track(1.0)
    file = SHARED_TRACKS / f"{name}.csv"
    if not file.is_file():
        raise ConfigError(f"track {name!r}: {file} is missing")
    full = Path.from_tum_csv(str(file), True)
    return full.scaled(choose_scale(tightest_radius_m(full), vehicle))


@dataclass(frozen=True)
class Scenario:
    direction: str
    speed_mps: float
    offset_m: float
    max_distance_m: float | None


FORWARD = Scenario("forward", 8.0, 4.0, None)
BACKWARD = Scenario("backward", 1.0, 2.0, 800.0)


def run(path: Path, config: ControllerConfig, vehicle: VehicleParams, sc: Scenario, seed: int, noisy: bool = True, alpha: str | None = None) -> tuple[Any, dict[str, float]]:
    """One run of scenario ``sc`` (the config's direction and speed are set from it)."""
    cfg = config.replace(direction=sc.direction, preferred_speed=sc.speed_mps)
    laps = 1.0 if sc.max_distance_m is None else min(1.0, sc.max_distance_m / path.length_m)
    return simulate(
        path,
        cfg,
        vehicle,
        alpha=alpha,
        offset_m=sc.offset_m,
        laps=laps,
        duration_s=10.0 * laps * path.length_m / sc.speed_mps + 60.0,
        noise=NOISE if noisy else None,
        delay_s=DELAY_S if noisy else 0.0,
        seed=seed,
    )


def ci95(values: Iterable[float]) -> tuple[float, float]:
    """Mean and the half-width of its 95 % confidence interval (Student t, from
    :func:`blendtrack.reporting.mean_ci`; infinities left out; NaN half-width
    for fewer than 2 finite values)."""
    from blendtrack.reporting import mean_ci

    m, lo, _ = mean_ci([x for x in values if math.isfinite(x)])
    return m, m - lo


def fmt_ci(values: Iterable[float], digits: int = 3) -> str:
    m, h = ci95(values)
    if not math.isfinite(m):
        return "n/a"
    return f"{m:.{digits}f}" if not math.isfinite(h) else f"{m:.{digits}f} ± {h:.{digits}f}"


#: Controllers of the study: label -> the config keys that select them.
CONTROLLERS: Mapping[str, Mapping[str, Any]] = {
    "pure pursuit": {"lateral_controller": "pure_pursuit"},
    "Stanley": {"lateral_controller": "stanley"},
    "rear law (alpha 0)": {"lateral_controller": "blend", "lat_blend_factor": 0.0},
    "blend": {"lateral_controller": "blend"},
    "auto alpha": {"lateral_controller": "blend", "alpha_mode": "auto"},
}

#: The keys each controller's tuning may change (scripts/paper_tune.py).
TUNED_KEYS = {
    "pure pursuit": ("pure_pursuit_gain_s", "pure_pursuit_min_lookahead_m"),
    "Stanley": ("stanley_gain",),
    "rear law (alpha 0)": ("target_distance_min_m", "target_distance_gain_s", "curvature_lookahead_gain_s"),
    "blend": ("lat_blend_factor",),
}


def paper_config(label: str) -> ControllerConfig:
    """The paper's parameter set (Table 1 and the documented defaults) for one controller."""
    return ControllerConfig(**CONTROLLERS[label])


def load_tuned(file: FsPath = TUNED_FILE) -> dict[str, Any] | None:
    """The tuning results (None when scripts/paper_tune.py has not written them)."""
    if not file.is_file():
        return None
    with open(file) as f:
        data: dict[str, Any] = json.load(f)
    return data


def fair_config(label: str, tuned: Mapping[str, Any]) -> ControllerConfig:
    """The fair parameter set: each controller with its own tuned keys (the
    blend also takes the tuned Stanley gain and rear-law distances)."""
    params = tuned["parameters"]
    keys: dict[str, Any] = dict(CONTROLLERS[label])
    if label in ("blend", "auto alpha"):
        keys.update(params["Stanley"])
        keys.update(params["rear law (alpha 0)"])
    if label in params:
        keys.update(params[label])
    return ControllerConfig(**keys)
