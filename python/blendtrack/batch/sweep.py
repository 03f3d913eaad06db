"""Sweep files: parsing, validation and expansion into runs.

A sweep file is TOML (see docs/batch.md)::

    kind = "sumo"                         # "sim", "sumo" or "compare"
    scenarios = ["rural_loop", "urban_grid"]
    seeds = 3                             # 0, 1, 2; or a list: [0, 7, 42]
    out = "../out/alpha_sweep"            # optional; --out overrides it
    timeout_s = 900                       # optional per-run limit

    [fixed]                               # the same in every run
    end = 600

    [grid]                                # cartesian product
    alpha = { start = 0.0, stop = 1.0, step = 0.1 }
    preferred_speed = [8.0, 12.0]

    [zip]                                 # lists of equal length, taken together
    reaction_time = [0.5, 1.0]
    preferred_stop_dist = [1.0, 2.0]

    [[cases]]                             # explicit parameter sets
    lateral_controller = "stanley"

The runs are scenarios x grid x zip x cases x seeds (a missing table counts
as one empty parameter set). A parameter may be set in one table only.
Relative paths (``out``, scenario folders, track files, ``config``) are
relative to the sweep file's folder.

Everything that can be checked without running is checked here: unknown
keys, unknown kinds, parameter names that the kind does not know, types,
ranges (by building the ControllerConfig and VehicleParams of every run),
empty lists, duplicate runs, and that scenarios and track files exist. What
only a run can find (a track file that is not a track, SUMO refusing a
network) fails that run and is recorded with its error.

Each run gets a stable id, a short hash of the canonical JSON of its kind,
scenario, parameters and seed: the same run has the same id in every
invocation, which is what ``--resume`` relies on.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from blendtrack import BlendtrackError, ControllerConfig, VehicleParams

#: What a run can be: a standalone closed-loop simulation, one ``sumo run``,
#: or one seed of ``compare`` (baseline and treatment).
KINDS = ("sim", "sumo", "compare")
#: Top-level keys of a sweep file.
TOP_KEYS = ("kind", "scenarios", "seeds", "out", "timeout_s", "description", "fixed", "grid", "zip", "cases")
#: Baseline car-following models of ``compare`` (blendtrack.sumo.compare.MODELS).
BASELINES = ("krauss", "idm", "eidm", "acc")
#: Most runs one sweep may expand to (scenarios x grid x zip x cases x
#: seeds), checked on the counts before any list of runs is built.
MAX_RUNS = 100_000


class SweepError(BlendtrackError, ValueError):
    """A sweep file that cannot be run (one line naming the file and the key)."""


# ------------------------------------------------------------- parameters
@dataclass(frozen=True)
class Param:
    """A parameter a sweep can set: its type, the kinds that know it, its bounds."""

    name: str
    type: type
    kinds: tuple[str, ...]
    help: str
    low: float | None = None
    high: float | None = None
    #: The lower bound is exclusive.
    strict: bool = False
    choices: tuple[str, ...] = ()
    #: Words a numeric parameter also takes (alpha: "auto").
    words: tuple[str, ...] = ()


def _config_params() -> dict[str, Param]:
    out: dict[str, Param] = {}
    for name, default in ControllerConfig().to_dict().items():
        # The SUMO runner sets use_path_widths itself (lane widths unless
        # path_width_m is given), so only a standalone sim can change it.
        kinds = ("sim",) if name == "use_path_widths" else KINDS
        out[name] = Param(name, type(default), kinds, "ControllerConfig field ([controller])")
    for name, default in VehicleParams().to_dict().items():
        out[name] = Param(name, type(default), KINDS, "VehicleParams field ([vehicle])")
    return out


_OWN: tuple[Param, ...] = (
    Param("alpha", float, KINDS, "blend factor (lat_blend_factor): 0 = rear axle, 1 = front axle; \"auto\": alpha_mode auto", 0.0, 1.0,
          words=("auto",)),
    Param("config", str, KINDS, "a TOML file with [controller] and [vehicle] tables; parameters override it"),
    # sim: the options of `blendtrack sim`
    Param("duration_s", float, ("sim",), "simulated time (s)", 0.0, None, True),
    Param("laps", float, ("sim",), "stop after this many laps instead of duration_s", 0.0, None, True),
    Param("dt_s", float, ("sim",), "time step (s)", 0.0, 1.0, True),
    Param("offset_m", float, ("sim",), "initial lateral offset (m, > 0 left)"),
    Param("heading_error_deg", float, ("sim",), "initial heading error (deg)"),
    Param("noise", str, ("sim",), "sensor noise: none, uniform:POS_M[:HEADING_DEG] or walk:..."),
    Param("delay_s", float, ("sim",), "actuation delay (s)", 0.0),
    Param("alpha_schedule", str, ("sim",), "moving control point sine:OMEGA"),
    Param("initial_speed_mps", float, ("sim",), "speed at the start (m/s)"),
    Param("fixed_speed_mps", float, ("sim",), "drive at this speed, no longitudinal law (m/s)"),
    Param("start_s_m", float, ("sim",), "arc length of the start (m)"),
    Param("scale", float, ("sim",), "scale of the track", 0.0, None, True),
    # sumo and compare: the options of `blendtrack sumo run` / `compare`
    Param("end", float, ("sumo", "compare"), "simulated end time (s)", 0.0, None, True),
    Param("controlled_fraction", float, ("sumo", "compare"), "fraction of all vehicles controlled (penetration rate)", 0.0, 1.0),
    Param("controlled_type", str, ("sumo", "compare"), "control every vehicle of this vType"),
    Param("max_controlled", int, ("sumo",), "control at most this many vehicles", 0.0),
    Param("border_margin_m", float, ("sumo", "compare"), "added to each side of a lane's half width for the virtual borders (m)", 0.0),
    Param("corridor", str, ("sumo", "compare"), "what limits curve speeds: lane (the paper's), arc, road, auto (default: road from 60 km/h, lane under it) or carriageway", choices=("lane", "arc", "road", "auto", "carriageway")),
    Param("stop_at_route_end", bool, ("sumo", "compare"), "controlled vehicles stop at their route's end (default: leave at speed)"),
    Param("tactical_lane_changes", bool, ("sumo", "compare"), "controlled vehicles also change lanes their route does not need (default: no)"),
    Param("open_gaps", bool, ("sumo", "compare"), "SUMO's drivers are asked to open a gap for a controlled vehicle waiting to change lanes (default: yes)"),
    Param("miss_exit_after_s", float, ("sumo", "compare"), "a controlled vehicle standing this long (s) at its lane's end waiting for a change its route needs drives on, rerouted (0: it waits)", 0.0),
    Param("control_dt_s", float, ("sumo", "compare"), "control rate: control steps per SUMO step = ceil(step / control_dt_s) (s; default 0.05)", 0.0, None, True),
    Param("baseline", str, ("compare",), "car-following model of the baseline", choices=BASELINES),
)

#: Every parameter a sweep can set, by name.
PARAMS: dict[str, Param] = {**_config_params(), **{p.name: p for p in _OWN}}
#: The sim options' defaults: those of `blendtrack sim`.
SIM_DEFAULTS: dict[str, Any] = {"duration_s": 60.0, "offset_m": 4.0, "dt_s": 0.01, "delay_s": 0.0, "heading_error_deg": 0.0}


def params_for(kind: str) -> list[str]:
    """The parameter names a run of ``kind`` knows, sorted."""
    return sorted(n for n, p in PARAMS.items() if kind in p.kinds)


def _fmt(value: Any) -> str:
    return repr(value) if isinstance(value, str) else json.dumps(value)


def _coerce(where: str, kind: str, name: str, value: Any) -> Any:
    """A parameter value checked against its type and bounds, in canonical form (ints of float fields become floats)."""
    p = PARAMS.get(name)
    if p is None or kind not in p.kinds:
        import difflib

        known = params_for(kind)
        close = difflib.get_close_matches(name, known, n=1)
        hint = f"did you mean {close[0]!r}? " if close else ""
        raise SweepError(f"{where}: unknown parameter {name!r} for kind {kind!r} ({hint}known: {', '.join(known)})")
    if p.words and isinstance(value, str):
        if value not in p.words:
            raise SweepError(f"{where}: {name} must be a number or one of {', '.join(map(repr, p.words))}, got {value!r}")
        return value
    if p.type is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SweepError(f"{where}: {name} must be a number, got {_fmt(value)}")
        value = float(value)
        if not math.isfinite(value):
            raise SweepError(f"{where}: {name} must be finite, got {value}")
    elif p.type is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise SweepError(f"{where}: {name} must be a whole number, got {_fmt(value)}")
    elif p.type is bool:
        if not isinstance(value, bool):
            raise SweepError(f"{where}: {name} must be true or false, got {_fmt(value)}")
    elif p.type is str:
        if not isinstance(value, str):
            raise SweepError(f"{where}: {name} must be a string, got {_fmt(value)}")
    if p.low is not None and (value <= p.low if p.strict else value < p.low):
        raise SweepError(f"{where}: {name} must be {'>' if p.strict else '>='} {p.low:g}, got {value}")
    if p.high is not None and value > p.high:
        raise SweepError(f"{where}: {name} must be <= {p.high:g}, got {value}")
    if p.choices and value not in p.choices:
        raise SweepError(f"{where}: {name} must be one of {', '.join(p.choices)}, got {value!r}")
    return value


def _values(where: str, kind: str, name: str, raw: Any) -> list[Any]:
    """The values of a swept parameter: a list, or {start, stop, step} (stop included)."""
    if isinstance(raw, Mapping):
        extra = set(raw) - {"start", "stop", "step"}
        if extra or set(raw) != {"start", "stop", "step"}:
            raise SweepError(f"{where}: a range is {{ start = A, stop = B, step = S }}, got keys {', '.join(sorted(raw))}")
        nums = []
        for k in ("start", "stop", "step"):
            v = raw[k]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise SweepError(f"{where}: range {k} must be a finite number, got {_fmt(v)}")
            nums.append(float(v))
        start, stop, step = nums
        if step <= 0 or stop < start:
            raise SweepError(f"{where}: a range needs step > 0 and stop >= start, got start {start:g}, stop {stop:g}, step {step:g}")
        n = math.floor((stop - start) / step + 1e-9) + 1
        if n > 100_000:
            raise SweepError(f"{where}: the range has {n} values (at most 100000)")
        # Rounded so 0.1-steps give 0.3, not 0.30000000000000004 (the run ids hash the values).
        raw = [round(start + i * step, 12) for i in range(n)]
        if PARAMS.get(name) is not None and PARAMS[name].type is int:
            raw = [int(v) if float(v).is_integer() else v for v in raw]
    if not isinstance(raw, list):
        raise SweepError(f"{where}: must be a list of values or {{ start, stop, step }}, got {_fmt(raw)}")
    if not raw:
        raise SweepError(f"{where}: empty list (give at least one value)")
    values = [_coerce(where, kind, name, v) for v in raw]
    if len({json.dumps(v) for v in values}) != len(values):
        raise SweepError(f"{where}: the same value is listed twice")
    return values


# ------------------------------------------------------------------- runs
@dataclass(frozen=True)
class Run:
    """One run of a sweep: what ``blendtrack batch`` executes in one worker process."""

    run_id: str
    #: Readable: scenario, the swept parameters, the seed.
    name: str
    kind: str
    #: The scenario (sumo, compare) or track (sim) as the sweep file gives it.
    scenario: str
    #: Every parameter of this run (fixed and swept), canonical types.
    params: dict[str, Any]
    seed: int
    #: The scenario or track as the run opens it (an absolute path, a shipped
    #: scenario name, or a built-in track spec).
    scenario_path: str
    #: Parameters holding file names, made absolute (``config``).
    files: dict[str, str] = field(default_factory=dict)

    def task(self, work_dir: Path, timeout_s: float | None) -> dict[str, Any]:
        """What a worker needs to execute the run (plain JSON data)."""
        return {
            "run_id": self.run_id,
            "name": self.name,
            "kind": self.kind,
            "scenario": self.scenario_path,
            "params": {**self.params, **self.files},
            "seed": self.seed,
            "work_dir": str(work_dir),
            "timeout_s": timeout_s,
        }

    def manifest(self) -> dict[str, Any]:
        return {"run_id": self.run_id, "name": self.name, "kind": self.kind, "scenario": self.scenario, "params": self.params, "seed": self.seed}


def run_id(kind: str, scenario: str, params: Mapping[str, Any], seed: int) -> str:
    """12 hex digits of the SHA-256 of the canonical JSON of the run."""
    canonical = json.dumps({"kind": kind, "scenario": scenario, "params": dict(params), "seed": seed}, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(canonical.encode()).hexdigest()[:12]


@dataclass
class Sweep:
    """A parsed, checked sweep file and its runs."""

    file: Path
    text: str
    kind: str
    scenarios: list[str]
    seeds: list[int]
    out: Path | None
    timeout_s: float | None
    description: str
    fixed: dict[str, Any]
    #: Swept parameter -> its values in the order given (grid, zip and cases).
    swept: dict[str, list[Any]]
    runs: list[Run]


def _short(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, str):
        return value.replace("/", "_").replace(" ", "_")[:24]
    return str(value)


def _scenario_label(spec: str) -> str:
    p = Path(spec)
    if p.suffix in (".sumocfg", ".csv"):
        return p.stem
    return p.name or spec


def _resolve_scenario(where: str, kind: str, spec: Any, base: Path) -> str:
    """Where the run finds the scenario or track; checks it exists."""
    if not isinstance(spec, str) or not spec.strip():
        raise SweepError(f"{where}: each scenario must be a non-empty string, got {_fmt(spec)}")
    if kind == "sim":
        from blendtrack.simulation import load_track

        head = spec.strip().partition(":")[0].replace("-", "_").lower()
        if head in ("straight", "circle", "test_track"):
            try:
                load_track(spec)
            except BlendtrackError as e:
                raise SweepError(f"{where}: {e}") from None
            return spec.strip()
        path = (base / spec).resolve()
        if not path.is_file():
            raise SweepError(f"{where}: track {spec!r}: no such file ({path}); expected a TUM csv, straight[:L], circle:R or test_track")
        return str(path)
    from blendtrack.sumo.scenario import SCENARIO_ROOT, ScenarioError, resolve_scenario

    local = base / spec
    target = str(local.resolve()) if local.exists() else spec
    if not local.exists() and not (SCENARIO_ROOT / spec).exists():
        raise SweepError(f"{where}: scenario {spec!r} not found (neither a path beside the sweep file nor a shipped scenario)")
    try:
        resolve_scenario(target)
    except ScenarioError as e:
        raise SweepError(f"{where}: {e}") from None
    return target


def _check_run(where: str, kind: str, params: dict[str, Any], files: dict[str, str]) -> None:
    """Builds the run's ControllerConfig and VehicleParams to check ranges and combinations."""
    pairs = [("alpha", "lat_blend_factor"), ("alpha", "alpha_schedule"), ("lat_blend_factor", "alpha_schedule"),
             ("duration_s", "laps"), ("controlled_fraction", "controlled_type")]
    for a, b in pairs:
        if a in params and b in params:
            raise SweepError(f"{where}: {a} and {b} cannot both be set in one run")
    cfg_fields = set(ControllerConfig().to_dict())
    veh_fields = set(VehicleParams().to_dict())
    try:
        if "config" in files:
            cfg, veh = _load_config(files["config"])
        else:
            cfg, veh = ControllerConfig(), VehicleParams()
        cfg = cfg.replace(**{k: v for k, v in params.items() if k in cfg_fields}).with_alpha(params.get("alpha"))
        veh.replace(**{k: v for k, v in params.items() if k in veh_fields})
        if "noise" in params:
            from blendtrack.simulation import parse_noise

            parse_noise(params["noise"])
        sched = params.get("alpha_schedule")
        if sched is not None:
            head, _, omega = sched.partition(":")
            if head != "sine" or not omega:
                raise SweepError(f"{where}: alpha_schedule must be sine:OMEGA, got {sched!r}")
            from blendtrack.simulation import _alpha_kwargs

            _alpha_kwargs(sched, 0.01, 1.0)
    except BlendtrackError as e:
        raise SweepError(f"{where}: {' '.join(str(e).split())}") from None
    except ValueError as e:
        raise SweepError(f"{where}: {e}") from None


def _load_config(file: str) -> tuple[ControllerConfig, VehicleParams]:
    import blendtrack

    return blendtrack.load_config(file)


def _table(where: str, data: dict[str, Any], key: str) -> dict[str, Any]:
    value = data.get(key, {})
    if not isinstance(value, dict):
        raise SweepError(f"{where}: [{key}] must be a table, got {_fmt(value)}")
    return value


def load_sweep(file: str | Path) -> Sweep:
    """Reads and checks a sweep file; raises :class:`SweepError` (one line) on any problem."""
    path = Path(file)
    if not path.is_file():
        raise SweepError(f"cannot read sweep file {path}: no such file")
    try:
        text = path.read_text()
        data = tomllib.loads(text)
    except UnicodeDecodeError as e:
        raise SweepError(f"{path}: not a text file: {e}") from None
    except tomllib.TOMLDecodeError as e:
        raise SweepError(f"{path}: malformed TOML: {e}") from None
    return parse_sweep(data, path, text)


def parse_sweep(data: dict[str, Any], path: Path, text: str = "") -> Sweep:
    """Checks parsed TOML ``data`` of the sweep file ``path`` and expands it into runs."""
    f = str(path)
    base = path.resolve().parent
    unknown = [k for k in data if k not in TOP_KEYS]
    if unknown:
        raise SweepError(f"{f}: unknown key {unknown[0]!r} (known: {', '.join(TOP_KEYS)})")
    if "kind" not in data:
        raise SweepError(f"{f}: missing key 'kind' (one of {', '.join(KINDS)})")
    kind = data["kind"]
    if kind not in KINDS:
        raise SweepError(f"{f}: kind: unknown run kind {kind!r} (expected one of {', '.join(KINDS)})")

    # scenarios
    if "scenarios" not in data:
        what = "tracks (test_track, circle:R, straight:L or a TUM csv)" if kind == "sim" else "SUMO scenarios"
        raise SweepError(f"{f}: missing key 'scenarios' (a list of {what})")
    scen = data["scenarios"]
    if isinstance(scen, str):
        scen = [scen]
    if not isinstance(scen, list) or not scen:
        raise SweepError(f"{f}: scenarios: must be a non-empty list of strings, got {_fmt(scen)}")
    if len(set(map(str, scen))) != len(scen):
        raise SweepError(f"{f}: scenarios: the same scenario is listed twice")
    resolved = {s: _resolve_scenario(f"{f}: scenarios", kind, s, base) for s in scen}

    # seeds
    seeds_raw = data.get("seeds", 1)
    if isinstance(seeds_raw, bool):
        raise SweepError(f"{f}: seeds: must be a count or a list of whole numbers, got {_fmt(seeds_raw)}")
    if isinstance(seeds_raw, int):
        if seeds_raw < 1:
            raise SweepError(f"{f}: seeds: must be >= 1, got {seeds_raw}")
        if seeds_raw > MAX_RUNS:
            raise SweepError(f"{f}: seeds: {seeds_raw} seeds, more than the limit of {MAX_RUNS} runs")
        seeds = list(range(seeds_raw))
    elif isinstance(seeds_raw, list) and seeds_raw and all(
        isinstance(s, int) and not isinstance(s, bool) and 0 <= s < 2**64 for s in seeds_raw
    ):
        seeds = list(seeds_raw)
        if len(set(seeds)) != len(seeds):
            raise SweepError(f"{f}: seeds: the same seed is listed twice")
    else:
        raise SweepError(f"{f}: seeds: must be a count (>= 1) or a non-empty list of whole numbers in [0, 2**64), got {_fmt(seeds_raw)}")

    out = data.get("out")
    if out is not None and (not isinstance(out, str) or not out.strip()):
        raise SweepError(f"{f}: out: must be a folder name, got {_fmt(out)}")
    timeout = data.get("timeout_s")
    if timeout is not None and (isinstance(timeout, bool) or not isinstance(timeout, (int, float)) or not timeout > 0 or not math.isfinite(timeout)):
        raise SweepError(f"{f}: timeout_s: must be a number > 0 (seconds per run), got {_fmt(timeout)}")
    description = data.get("description", "")
    if not isinstance(description, str):
        raise SweepError(f"{f}: description: must be a string")

    # parameter tables
    fixed_raw = _table(f, data, "fixed")
    grid_raw = _table(f, data, "grid")
    zip_raw = _table(f, data, "zip")
    cases_raw = data.get("cases", [])
    if not isinstance(cases_raw, list) or not all(isinstance(c, dict) for c in cases_raw):
        raise SweepError(f"{f}: cases: must be an array of tables ([[cases]]), got {_fmt(cases_raw)}")
    if "cases" in data and not cases_raw:
        raise SweepError(f"{f}: cases: empty list (give at least one [[cases]] table)")
    owner: dict[str, str] = {}
    for table, keys in (("fixed", fixed_raw), ("grid", grid_raw), ("zip", zip_raw), *((f"cases[{i}]", c) for i, c in enumerate(cases_raw))):
        for k in keys:
            prev = owner.get(k)
            if prev is not None and not (prev.startswith("cases[") and table.startswith("cases[")):
                raise SweepError(f"{f}: {table}.{k}: {k} is already set in [{prev.split('[')[0]}] (a parameter belongs to one table)")
            owner[k] = table

    fixed = {k: _coerce(f"{f}: fixed.{k}", kind, k, v) for k, v in fixed_raw.items()}
    grid = {k: _values(f"{f}: grid.{k}", kind, k, v) for k, v in grid_raw.items()}
    zipped = {k: _values(f"{f}: zip.{k}", kind, k, v) for k, v in zip_raw.items()}
    lengths = {k: len(v) for k, v in zipped.items()}
    if len(set(lengths.values())) > 1:
        desc = ", ".join(f"{k} has {n}" for k, n in lengths.items())
        raise SweepError(f"{f}: zip: the lists must have the same length ({desc})")
    cases = [{k: _coerce(f"{f}: cases[{i}].{k}", kind, k, v) for k, v in c.items()} for i, c in enumerate(cases_raw)]

    n_runs = len(scen) * math.prod(len(v) for v in grid.values()) * max(len(v) for v in [[0], *zipped.values()])
    n_runs *= max(len(cases), 1) * len(seeds)
    if n_runs > MAX_RUNS:
        raise SweepError(
            f"{f}: the sweep expands to {n_runs} runs (scenarios x grid x zip x cases x seeds), "
            f"more than the limit of {MAX_RUNS}"
        )
    grid_sets = [dict(zip(grid, combo)) for combo in itertools.product(*grid.values())] if grid else [{}]
    n_zip = next(iter(lengths.values())) if zipped else 0
    zip_sets = [{k: v[i] for k, v in zipped.items()} for i in range(n_zip)] if zipped else [{}]
    case_sets = cases or [{}]
    param_sets = [{**fixed, **g, **z, **c} for g in grid_sets for z in zip_sets for c in case_sets]

    swept: dict[str, list[Any]] = {}
    for ps in param_sets:
        for k, v in ps.items():
            if k in fixed:
                continue
            vals = swept.setdefault(k, [])
            if v not in vals:
                vals.append(v)

    files: dict[str, str] = {}
    runs: list[Run] = []
    seen: dict[str, str] = {}
    for scenario in scen:
        for ps in param_sets:
            run_files = {}
            if "config" in ps:
                cfg = (base / ps["config"]).resolve()
                if not cfg.is_file():
                    raise SweepError(f"{f}: config: cannot read config file {ps['config']} ({cfg}): no such file")
                run_files["config"] = files.setdefault(ps["config"], str(cfg))
            where = f"{f}: run {scenario} {', '.join(f'{k}={_short(v)}' for k, v in ps.items() if k not in fixed) or '(fixed parameters)'}"
            _check_run(where, kind, ps, run_files)
            for seed in seeds:
                rid = run_id(kind, scenario, ps, seed)
                label = "-".join([_scenario_label(scenario), *(f"{k}={_short(v)}" for k, v in ps.items() if k in swept), f"s{seed}"])
                if rid in seen:
                    raise SweepError(f"{f}: two runs are the same ({label}): a parameter set is listed twice")
                seen[rid] = label
                runs.append(Run(rid, label, kind, scenario, dict(ps), seed, resolved[scenario], run_files))
    return Sweep(path, text, kind, list(scen), seeds, (base / out).resolve() if out else None,
                 float(timeout) if timeout is not None else None, description, fixed, swept, runs)
