"""``blendtrack compare``: blendtrack against SUMO's own drivers, paired by vehicle.

For each seed the scenario runs twice with the same demand, seed, end time
and step length:

- *baseline*: plain SUMO (a ``sumo`` subprocess), every vehicle on SUMO's
  car-following model; the vehicles the treatment would control are found by
  the same rule (seeded hash of the id, a vType, or the vType parameter
  ``blendtrack.controlled``);
- *treatment*: :func:`blendtrack.sumo.run_scenario` with those vehicles
  driven by blendtrack.

Both write tripinfo (with emissions, unfinished trips included), FCD, SSM and
SUMO's statistics. Every per-vehicle metric that both runs have is computed
the same way for both, from SUMO's own outputs (FCD, tripinfo), so the pairs
compare like with like; only the lateral error comes from blendtrack
(``vehicles.csv``): SUMO's drivers sit on the lane centreline, so theirs is 0
by construction.

Everything is written into ``DIR/.partial-*`` and moved into place at the
end, ``report.md`` last: an interrupted compare leaves no complete-looking
report.
"""

from __future__ import annotations

import base64
import csv
import dataclasses
import math
import os
import shutil
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from blendtrack.sumo.connection import sumo_binary
from blendtrack.sumo.options import RunOptions
from blendtrack.sumo.selection import CONTROLLED_PARAM, unit_hash
from blendtrack.sumo.scenario import Scenario, ScenarioError

#: Car-following models a baseline can use ("krauss" = as the scenario says).
MODELS = {"krauss": None, "idm": "IDM", "eidm": "EIDM", "acc": "ACC"}
#: SSM thresholds of a conflict (the runner's ``--device.ssm.thresholds``).
TTC_CONFLICT_S = 3.0
DRAC_CONFLICT_MPS2 = 3.0
#: Window of the heading change in a_lat = v dpsi/dt (as report.fcd_lateral_accel).
LAT_WINDOW_S = 1.0

#: Per-vehicle metrics: (name, label, unit, lower is better?).
VEHICLE_METRICS: tuple[tuple[str, str, str], ...] = (
    ("travel_time_s", "travel time (to arrival or the end)", "s"),
    ("time_loss_s", "time loss", "s"),
    ("mean_speed_mps", "mean speed", "m/s"),
    ("lat_accel_max_mps2", "max lateral acceleration", "m/s^2"),
    ("lat_accel_rms_mps2", "RMS lateral acceleration", "m/s^2"),
    ("long_jerk_rms_mps3", "RMS longitudinal jerk", "m/s^3"),
    ("time_above_comfort_s", "time above the comfort lateral acceleration", "s"),
    ("lateral_error_rms_m", "RMS lateral error (baseline 0 by construction)", "m"),
    ("co2_g", "CO2", "g"),
    ("fuel_g", "fuel", "g"),
)
#: Per-run network metrics.
NETWORK_METRICS: tuple[tuple[str, str, str], ...] = (
    ("controlled_travel_time_s", "mean travel time, controlled vehicles", "s"),
    ("controlled_time_loss_s", "mean time loss, controlled vehicles", "s"),
    ("background_travel_time_s", "mean travel time, background vehicles", "s"),
    ("background_time_loss_s", "mean time loss, background vehicles", "s"),
    ("throughput", "throughput (arrived vehicles)", "veh"),
    ("ssm_conflicts", "SSM conflicts (TTC < 3 s or DRAC > 3 m/s^2)", "count"),
    ("collisions", "collisions", "count"),
    ("teleports", "teleports", "count"),
)

# Two-sided 95 % quantiles of Student's t for 1..30 degrees of freedom.
_T975 = (12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160, 2.145, 2.131,
         2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048, 2.045, 2.042)


def t975(df: int) -> float:
    """Two-sided 95 % quantile of Student's t with ``df`` degrees of freedom."""
    if df < 1:
        return math.nan
    return _T975[df - 1] if df <= len(_T975) else 1.96 + 2.4 / df


def mean_ci(values: Sequence[float]) -> tuple[float, float, float]:
    """Mean and 95 % t confidence interval (NaN bounds with fewer than 2 values)."""
    x = np.array([v for v in values if v == v], dtype=float)
    if len(x) == 0:
        return math.nan, math.nan, math.nan
    m = float(x.mean())
    if len(x) < 2:
        return m, math.nan, math.nan
    half = t975(len(x) - 1) * float(x.std(ddof=1)) / math.sqrt(len(x))
    return m, m - half, m + half


@dataclass
class CompareOptions:
    baseline: str = "krauss"
    controlled_fraction: float | None = None
    controlled_type: str | None = None
    seeds: int = 3
    end_s: float | None = None
    #: Options of the treatment run (controller config, alpha); selection,
    #: seed, end and outputs are set per run.
    run: RunOptions = dataclasses.field(default_factory=RunOptions)
    progress: bool = True


# ----------------------------------------------------------------- scenarios
def _vtypes(route_files: Sequence[Path]) -> dict[str, dict[str, str]]:
    """vType id -> its params, from the route files."""
    out: dict[str, dict[str, str]] = {}
    for rf in route_files:
        try:
            root = ET.parse(rf).getroot()
        except ET.ParseError as e:
            raise ScenarioError(f"{rf}: malformed XML: {e}") from None
        for vt in root.iter("vType"):
            out[vt.get("id", "")] = {p.get("key", ""): p.get("value", "") for p in vt.iter("param")}
    return out


def with_model(scenario: Scenario, model: str, tmp: Path) -> Scenario:
    """The scenario with every vType's carFollowModel set to ``model``: copies
    of the route files and of the sumocfg (input paths made absolute) in ``tmp``."""
    cf = MODELS[model]
    if cf is None:
        return scenario
    tmp.mkdir(parents=True, exist_ok=True)
    new_routes: list[Path] = []
    for i, rf in enumerate(scenario.route_files):
        tree = ET.parse(rf)
        for vt in tree.getroot().iter("vType"):
            vt.set("carFollowModel", cf)  # every other attribute kept
        dst = tmp / f"{i}_{rf.name}"
        tree.write(dst, encoding="UTF-8", xml_declaration=True)
        new_routes.append(dst.resolve())
    tree = ET.parse(scenario.sumocfg)
    root = tree.getroot()
    base = scenario.sumocfg.parent
    for el in root.iter():
        if el.tag == "route-files":
            el.set("value", ",".join(str(p) for p in new_routes))
        elif el.tag in ("net-file", "additional-files") and el.get("value"):
            el.set("value", ",".join(str((base / v.strip()).resolve()) for v in el.get("value", "").split(",") if v.strip()))
    cfg = tmp / scenario.sumocfg.name
    tree.write(cfg, encoding="UTF-8", xml_declaration=True)
    return dataclasses.replace(scenario, sumocfg=cfg.resolve(), route_files=new_routes)


def selector(opts: CompareOptions, scenario: Scenario, seed: int) -> Callable[[str, str], bool]:
    """The treatment's selection rule (RunOptions / Selection.is_selected) as a function of (id, vType)."""
    if opts.controlled_fraction is not None:
        frac = opts.controlled_fraction
        return lambda vid, vtype: unit_hash(seed, vid) < frac
    if opts.controlled_type is not None:
        want = opts.controlled_type
        return lambda vid, vtype: vtype == want
    marked = {t for t, params in _vtypes(scenario.route_files).items()
              if params.get(CONTROLLED_PARAM, "").strip().lower() in ("1", "true", "yes")}
    return lambda vid, vtype: vtype in marked


def _output_args(sd: Path) -> list[str]:
    """SUMO outputs written by both runs (the runner's plus unfinished trips and statistics)."""
    return ["--tripinfo-output.write-unfinished", "true", "--statistic-output", str(sd / "statistics.xml")]


def run_baseline(scenario: Scenario, seed: int, end_s: float | None, out: Path) -> None:
    """Plain SUMO with the options the runner uses (SumoConnection.command with fcd and ssm)."""
    sd = out / "sumo"
    sd.mkdir(parents=True, exist_ok=True)
    cmd = [sumo_binary(False), "-c", str(scenario.sumocfg), "--seed", str(seed),
           "--no-step-log", "true", "--duration-log.disable", "true",
           "--tripinfo-output", str(sd / "tripinfo.xml"), "--device.emissions.probability", "1",
           "--collision-output", str(sd / "collisions.xml"), "--log", str(sd / "sumo.log"),
           "--fcd-output", str(sd / "fcd.xml"),
           "--device.ssm.probability", "1", "--device.ssm.file", str(sd / "ssm.xml"),
           "--device.ssm.measures", "TTC DRAC PET", "--device.ssm.thresholds", "3.0 3.0 2.0",
           *_output_args(sd)]
    if end_s is not None:
        cmd += ["--end", str(end_s)]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        lines = [ln.strip() for ln in (proc.stderr + proc.stdout).splitlines() if ln.strip()]
        errors = [ln for ln in lines if "Error" in ln] or lines or [f"exit code {proc.returncode}"]
        raise ScenarioError(f"{scenario.sumocfg}: SUMO refused to start: {errors[0]}")


def run_treatment(scenario: Scenario, options: RunOptions, out: Path) -> Any:
    from blendtrack.sumo import run_scenario

    sd = out / "sumo"
    sd.mkdir(parents=True, exist_ok=True)
    options = dataclasses.replace(options, fcd=True, ssm=True, sumo_args=(*options.sumo_args, *_output_args(sd)))
    return run_scenario(scenario, options, out)


# ------------------------------------------------------------------- outputs
@dataclass
class Track:
    """One vehicle's FCD series."""

    vtype: str
    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    angle: np.ndarray
    speed: np.ndarray
    lane: list[str]
    pos: np.ndarray


def read_fcd(file: Path) -> dict[str, Track]:
    raw: dict[str, tuple[str, list[tuple[float, float, float, float, float, float]], list[str]]] = {}
    t = 0.0
    for _, el in ET.iterparse(file, events=("start", "end")):
        if el.tag == "timestep":
            t = float(el.get("time", "0"))
            continue
        if el.tag != "vehicle" or _ != "end":
            continue
        vid = el.get("id", "")
        rec = raw.get(vid)
        if rec is None:
            rec = raw[vid] = (el.get("type", ""), [], [])
        rec[1].append((t, float(el.get("x", "nan")), float(el.get("y", "nan")), float(el.get("angle", "nan")),
                       float(el.get("speed", "nan")), float(el.get("pos", "nan"))))
        rec[2].append(el.get("lane", ""))
        el.clear()
    out = {}
    for vid, (vtype, rows, lanes) in raw.items():
        a = np.array(rows, dtype=float)
        out[vid] = Track(vtype, a[:, 0], a[:, 1], a[:, 2], a[:, 3], a[:, 4], lanes, a[:, 5])
    return out


def lateral_series(tr: Track, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(time, a_lat, driven-path curvature) over a LAT_WINDOW_S window, samples
    touching a junction (internal) lane left out, as report.fcd_lateral_accel."""
    k = max(1, round(LAT_WINDOW_S / dt))
    n = len(tr.t)
    if n <= k:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    dpsi = np.radians((tr.angle[k:] - tr.angle[:-k] + 180.0) % 360.0 - 180.0)
    contiguous = np.isclose(tr.t[k:] - tr.t[:-k], k * dt)
    internal = np.array([ln.startswith(":") for ln in tr.lane])
    keep = contiguous & ~internal[k:] & ~internal[:-k]
    a_lat = tr.speed[k:] * dpsi / (k * dt)
    ds = np.hypot(tr.x[k:] - tr.x[:-k], tr.y[k:] - tr.y[:-k])
    with np.errstate(divide="ignore", invalid="ignore"):
        kappa = np.where(ds > 1.0, np.abs(dpsi) / ds, np.nan)
    return tr.t[k:][keep], a_lat[keep], kappa[keep]


def read_tripinfo(file: Path) -> dict[str, dict[str, float]]:
    out: dict[str, dict[str, float]] = {}
    for _, el in ET.iterparse(file, events=("end",)):
        if el.tag != "tripinfo":
            continue
        em = el.find("emissions")
        out[el.get("id", "")] = {
            "duration": float(el.get("duration", "nan")),
            "time_loss": float(el.get("timeLoss", "nan")),
            "arrived": float(float(el.get("arrival", "-1")) >= 0.0),
            "co2_g": float(em.get("CO2_abs", "nan")) / 1000.0 if em is not None else math.nan,
            "fuel_g": float(em.get("fuel_abs", "nan")) / 1000.0 if em is not None else math.nan,
        }
    return out


def read_ssm_conflicts(file: Path) -> float:
    """Conflicts with TTC < 3 s or DRAC > 3 m/s^2 (NaN without an ssm.xml)."""
    n = 0
    if not file.exists():
        return math.nan
    for _, el in ET.iterparse(file, events=("end",)):
        if el.tag != "conflict":
            continue
        ttc = _num(el.find("minTTC"))
        drac = _num(el.find("maxDRAC"))
        if ttc < TTC_CONFLICT_S or drac > DRAC_CONFLICT_MPS2:
            n += 1
        el.clear()
    return n


def _num(el: ET.Element | None) -> float:
    if el is None:
        return math.nan
    try:
        return float(el.get("value", "nan"))
    except ValueError:
        return math.nan


def read_statistics(file: Path) -> tuple[int, int]:
    """(collisions, teleports) from SUMO's statistic output."""
    root = ET.parse(file).getroot()
    tel = root.find("teleports")
    saf = root.find("safety")
    return (int(saf.get("collisions", "0")) if saf is not None else 0, int(tel.get("total", "0")) if tel is not None else 0)


@dataclass
class RunData:
    """What one run (baseline or treatment) gives the comparison."""

    fcd: dict[str, Track]
    trips: dict[str, dict[str, float]]
    controlled: set[str]
    network: dict[str, float]
    lateral_error: dict[str, float]


def vehicle_metrics(tr: Track, trip: dict[str, float] | None, dt: float, comfort: float) -> dict[str, float]:
    _, a_lat, _ = lateral_series(tr, dt)
    acc = np.diff(tr.speed) / dt
    jerk = np.diff(acc) / dt
    nan = math.nan
    return {
        "travel_time_s": trip["duration"] if trip else nan,
        "time_loss_s": trip["time_loss"] if trip else nan,
        "mean_speed_mps": float(tr.speed.mean()) if len(tr.speed) else nan,
        "lat_accel_max_mps2": float(np.abs(a_lat).max()) if len(a_lat) else nan,
        "lat_accel_rms_mps2": float(np.sqrt(np.mean(a_lat**2))) if len(a_lat) else nan,
        "long_jerk_rms_mps3": float(np.sqrt(np.mean(jerk**2))) if len(jerk) else nan,
        "time_above_comfort_s": float(np.count_nonzero(np.abs(a_lat) > comfort) * dt),
        "co2_g": trip["co2_g"] if trip else nan,
        "fuel_g": trip["fuel_g"] if trip else nan,
    }


def load_run(out: Path, is_controlled: Callable[[str, str], bool]) -> RunData:
    sd = out / "sumo"
    fcd = read_fcd(sd / "fcd.xml")
    controlled = {v for v, tr in fcd.items() if is_controlled(v, tr.vtype)}
    trips = read_tripinfo(sd / "tripinfo.xml")
    collisions, teleports = read_statistics(sd / "statistics.xml")

    def mean_of(ids: list[str], key: str) -> float:
        vals = [trips[i][key] for i in ids]
        return float(np.mean(vals)) if vals else math.nan

    ctrl = [v for v in trips if v in controlled]
    back = [v for v in trips if v not in controlled]
    network = {
        "controlled_travel_time_s": mean_of(ctrl, "duration"),
        "controlled_time_loss_s": mean_of(ctrl, "time_loss"),
        "background_travel_time_s": mean_of(back, "duration"),
        "background_time_loss_s": mean_of(back, "time_loss"),
        "throughput": float(sum(t["arrived"] for t in trips.values())),
        "ssm_conflicts": float(read_ssm_conflicts(sd / "ssm.xml")),
        "collisions": float(collisions),
        "teleports": float(teleports),
    }
    lat_err: dict[str, float] = {}
    vcsv = out / "vehicles.csv"
    if vcsv.exists():
        with open(vcsv) as f:
            for row in csv.DictReader(f):
                lat_err[row["id"]] = float(row["lateral_error_rms_m"]) if row["lateral_error_rms_m"] else math.nan
    return RunData(fcd, trips, controlled, network, lat_err)


# ------------------------------------------------------------------- compare
@dataclass
class SeedResult:
    seed: int
    rows: list[dict[str, Any]]
    network: dict[str, dict[str, float]]  # "baseline"/"treatment" -> metrics
    unpaired: int
    base: RunData
    treat: RunData


def pair(seed: int, base: RunData, treat: RunData, dt: float, comfort: float) -> SeedResult:
    ids = sorted(base.controlled & treat.controlled & base.fcd.keys() & treat.fcd.keys())
    rows = []
    for vid in ids:
        mb = vehicle_metrics(base.fcd[vid], base.trips.get(vid), dt, comfort)
        mt = vehicle_metrics(treat.fcd[vid], treat.trips.get(vid), dt, comfort)
        mb["lateral_error_rms_m"] = 0.0
        mt["lateral_error_rms_m"] = treat.lateral_error.get(vid, math.nan)
        row: dict[str, Any] = {"seed": seed, "id": vid}
        for name, _, _ in VEHICLE_METRICS:
            row[f"{name}_baseline"] = mb[name]
            row[f"{name}_treatment"] = mt[name]
        rows.append(row)
    unpaired = len(base.controlled ^ treat.controlled)
    return SeedResult(seed, rows, {"baseline": base.network, "treatment": treat.network}, unpaired, base, treat)


def summarise(results: list[SeedResult]) -> list[dict[str, Any]]:
    """One row per metric: baseline and treatment (mean over seeds of the
    per-seed means), difference (treatment - baseline) and its 95 % CI over seeds."""
    table = []
    for name, label, unit in VEHICLE_METRICS:
        b, t, d = [], [], []
        for r in results:
            pairs = [(row[f"{name}_baseline"], row[f"{name}_treatment"]) for row in r.rows]
            pairs = [(x, y) for x, y in pairs if x == x and y == y]
            if not pairs:
                continue
            mb = float(np.mean([x for x, _ in pairs]))
            mt = float(np.mean([y for _, y in pairs]))
            b.append(mb)
            t.append(mt)
            d.append(mt - mb)
        table.append(_row(name, f"{label} (per controlled vehicle)", unit, b, t, d))
    for name, label, unit in NETWORK_METRICS:
        b = [r.network["baseline"][name] for r in results]
        t = [r.network["treatment"][name] for r in results]
        d = [y - x for x, y in zip(b, t)]
        table.append(_row(name, label, unit, b, t, d))
    return table


def _row(name: str, label: str, unit: str, b: list[float], t: list[float], d: list[float]) -> dict[str, Any]:
    mb = float(np.nanmean(b)) if any(x == x for x in b) else math.nan
    mt = float(np.nanmean(t)) if any(x == x for x in t) else math.nan
    md, lo, hi = mean_ci(d)
    return {"metric": name, "label": label, "unit": unit, "baseline": mb, "treatment": mt, "difference": md,
            "ci_low": lo, "ci_high": hi, "seeds": len([x for x in d if x == x])}


def fmt(x: float) -> str:
    """How report.md prints a number (tests parse it back)."""
    if not isinstance(x, (int, float)) or not math.isfinite(x):
        return "n/a"
    return f"{x:.4g}"


def summary_lines(table: list[dict[str, Any]]) -> list[str]:
    lines = ["| metric | unit | baseline | treatment | difference | 95% CI |", "|---|---|---|---|---|---|"]
    for r in table:
        ci = f"[{fmt(r['ci_low'])}, {fmt(r['ci_high'])}]" if r["ci_low"] == r["ci_low"] else "n/a"
        lines.append(f"| {r['label']} | {r['unit']} | {fmt(r['baseline'])} | {fmt(r['treatment'])} | {fmt(r['difference'])} | {ci} |")
    return lines


def plain_text(table: list[dict[str, Any]], results: list[SeedResult], model: str) -> str:
    """A paragraph built from the numbers only."""
    by = {r["metric"]: r for r in table}
    n_pairs = sum(len(r.rows) for r in results)
    n_seeds = len(results)
    who = "SUMO's own drivers" + ("" if model == "krauss" else f" ({MODELS[model]})")
    parts = [f"Over {n_seeds} seed{'s' if n_seeds != 1 else ''} and {n_pairs} paired vehicles, "
             f"the same vehicles were driven by blendtrack (treatment) and by {who} (baseline)."]

    def sentence(metric: str, what: str) -> str | None:
        r = by[metric]
        if not (r["difference"] == r["difference"]):
            return None
        word = "lower" if r["difference"] < 0 else "higher" if r["difference"] > 0 else "unchanged"
        unit = "" if r["unit"] in ("count", "veh") else " " + r["unit"]
        s = f"{what} was {fmt(r['treatment'])}{unit} against {fmt(r['baseline'])}{unit} ({word}; difference {fmt(r['difference'])}"
        if r["ci_low"] == r["ci_high"] == r["difference"] == 0.0:
            s += ", the same in every seed"
        elif r["ci_low"] == r["ci_low"]:
            zero = r["ci_low"] <= 0.0 <= r["ci_high"]
            s += f", 95% CI [{fmt(r['ci_low'])}, {fmt(r['ci_high'])}]" + (", which includes zero: not distinguishable from no change with these seeds" if zero else ", which excludes zero")
        else:
            s += ", no confidence interval with one seed"
        return s + ")."

    lower = sum(1 for r in results for row in r.rows
                if row["lat_accel_max_mps2_treatment"] < row["lat_accel_max_mps2_baseline"])
    with_both = sum(1 for r in results for row in r.rows
                    if row["lat_accel_max_mps2_treatment"] == row["lat_accel_max_mps2_treatment"]
                    and row["lat_accel_max_mps2_baseline"] == row["lat_accel_max_mps2_baseline"])
    for metric, what in (("lat_accel_max_mps2", "The mean of the controlled vehicles' maximum lateral acceleration"),
                         ("time_above_comfort_s", "Their time above the comfort bound"),
                         ("time_loss_s", "Their time loss"),
                         ("co2_g", "Their CO2"),
                         ("background_time_loss_s", "The background vehicles' mean time loss"),
                         ("ssm_conflicts", "The number of SSM conflicts per run")):
        s = sentence(metric, what)
        if s:
            parts.append(s)
    if with_both:
        parts.append(f"The maximum lateral acceleration was lower with blendtrack for {lower} of {with_both} pairs.")
    col_b, col_t = by["collisions"]["baseline"], by["collisions"]["treatment"]
    parts.append(f"Collisions per run: {fmt(col_t)} with blendtrack, {fmt(col_b)} without.")
    return " ".join(parts)


# --------------------------------------------------------------------- plots
def _plots(results: list[SeedResult], out: Path, dt: float, comfort: float) -> list[tuple[str, Path]]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    files: list[tuple[str, Path]] = []
    samples: dict[str, list[np.ndarray]] = {"baseline": [], "treatment": []}
    lat: dict[str, list[np.ndarray]] = {"baseline": [], "treatment": []}
    for r in results:
        ids = [row["id"] for row in r.rows]
        for which, run in (("baseline", r.base), ("treatment", r.treat)):
            for vid in ids:
                tr = run.fcd[vid]
                t_all, a, kap = lateral_series(tr, dt)
                idx = np.searchsorted(tr.t, t_all)
                v = tr.speed[np.clip(idx, 0, len(tr.speed) - 1)]
                ok = kap == kap
                # Every 0.5 s: enough points, a readable scatter.
                samples[which].append(np.column_stack([kap[ok], v[ok]])[:: max(1, round(0.5 / dt))])
                lat[which].append(np.abs(a))
    colors = {"baseline": "tab:orange", "treatment": "tab:blue"}

    fig, ax = plt.subplots(figsize=(7, 4.5))
    kmax = 1e-3
    for which in ("baseline", "treatment"):
        s = np.vstack(samples[which]) if samples[which] else np.zeros((0, 2))
        if len(s):
            ax.scatter(s[:, 0], s[:, 1], s=3, alpha=0.35, color=colors[which], label=which)
            kmax = max(kmax, float(np.nanpercentile(s[:, 0], 99.5)))
    k = np.linspace(kmax / 200, kmax, 200)
    ax.plot(k, np.sqrt(comfort / k), "k--", lw=1, label=f"v = sqrt({comfort:g} / curvature)")
    vmax = max([float(np.nanmax(np.vstack(samples[w])[:, 1])) for w in samples if samples[w] and len(np.vstack(samples[w]))] + [1.0])
    ax.set_xlim(0, kmax * 1.05)
    ax.set_ylim(0, vmax * 1.15)
    ax.set_xlabel("curvature of the driven path, |dpsi| / ds over 1 s (1/m, from FCD)")
    ax.set_ylabel("speed (m/s)")
    ax.set_title("Speed against curvature, controlled vehicles and their baseline twins")
    ax.legend(fontsize=8)
    fig.tight_layout()
    files.append(("Speed against curvature", out / "speed_vs_curvature.png"))
    fig.savefig(files[-1][1], dpi=100)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(7, 4))
    allv = [np.concatenate(lat[w]) if lat[w] else np.zeros(0) for w in ("baseline", "treatment")]
    top = max([float(v.max()) for v in allv if len(v)] + [comfort * 1.5])
    bins = np.linspace(0, top, 60)
    for which, v in zip(("baseline", "treatment"), allv):
        if len(v):
            ax.hist(v, bins=bins.tolist(), density=True, color=colors[which], label=which,
                    **({"alpha": 0.5} if which == "baseline" else {"histtype": "step", "lw": 1.5}))
    ax.axvline(comfort, color="k", ls="--", lw=1, label=f"comfort {comfort:g} m/s^2")
    ax.set_yscale("log")
    ax.set_xlabel("|lateral acceleration| (m/s^2, v dpsi/dt over 1 s, from FCD)")
    ax.set_ylabel("density")
    ax.set_title("Lateral acceleration of the paired vehicles")
    ax.legend(fontsize=8)
    fig.tight_layout()
    files.append(("Lateral acceleration histograms", out / "lateral_accel_hist.png"))
    fig.savefig(files[-1][1], dpi=100)
    plt.close(fig)

    r0 = results[0]
    counts: dict[str, int] = {}
    for tr in r0.treat.fcd.values():
        for ln in tr.lane:
            if not ln.startswith(":"):
                counts[ln] = counts.get(ln, 0) + 1
    if counts:
        lane = max(counts, key=lambda x: counts[x])
        fig, axes = plt.subplots(1, 2, figsize=(11, 4.5), sharey=True)
        for ax, (which, run) in zip(axes, (("baseline", r0.base), ("treatment", r0.treat))):
            for vid, tr in run.fcd.items():
                m = np.array([ln == lane for ln in tr.lane])
                if not m.any():
                    continue
                c = "tab:red" if vid in r0.treat.controlled and vid in r0.base.controlled else "0.5"
                tt = np.where(m, tr.t, np.nan)
                ax.plot(tt, np.where(m, tr.pos, np.nan), color=c, lw=0.8)
            ax.set_title(f"{which}, seed {r0.seed}")
            ax.set_xlabel("time (s)")
        axes[0].set_ylabel(f"position on lane {lane} (m)")
        fig.suptitle(f"Time-space diagram of the busiest lane ({lane}); red = controlled in the treatment")
        fig.tight_layout()
        files.append(("Time-space diagram", out / "time_space.png"))
        fig.savefig(files[-1][1], dpi=100)
        plt.close(fig)

    # The tightest curve any controlled vehicle drove (largest driven-path
    # curvature in the treatment), and the same vehicle there in the baseline.
    best = None
    for row in r0.rows:
        t_k, _, kap = lateral_series(r0.treat.fcd[row["id"]], dt)
        if len(kap) and np.isfinite(kap).any():
            j = int(np.nanargmax(kap))
            if best is None or kap[j] > best[0]:
                best = (float(kap[j]), row["id"], float(t_k[j]))
    if best is not None:
        _, vid, t_peak = best
        peak = r0.treat.fcd[vid]
        i = min(int(np.searchsorted(peak.t, t_peak)), len(peak.t) - 1)
        # The middle of the 1 s window that had the largest curvature.
        i = max(i - max(1, round(LAT_WINDOW_S / dt)) // 2, 0)
        cx, cy = peak.x[i], peak.y[i]
        fig, (ax, ax2) = plt.subplots(1, 2, figsize=(11, 4.5))
        for which, run in (("baseline", r0.base), ("treatment", r0.treat)):
            tr = run.fcd[vid]
            near = np.hypot(tr.x - cx, tr.y - cy) < 60.0
            # Only the first pass through the curve.
            if near.any():
                start = int(np.argmax(near))
                stop = start + int(np.argmax(~near[start:])) if (~near[start:]).any() else len(near)
                sl = slice(start, stop)
                ax.plot(tr.x[sl], tr.y[sl], color=colors[which], lw=1.2, label=which)
                ax2.plot(tr.t[sl] - tr.t[start], tr.speed[sl], color=colors[which], label=which)
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_title(f"{vid} through its tightest curve (seed {r0.seed}, 60 m around it)")
        ax.legend(fontsize=8)
        ax2.set_xlabel("time since entering the window (s)")
        ax2.set_ylabel("speed (m/s)")
        ax2.set_title("speed in the same window (first pass)")
        ax2.legend(fontsize=8)
        fig.tight_layout()
        files.append((f"Trajectory of {vid} in a tight curve", out / "curve_trajectory.png"))
        fig.savefig(files[-1][1], dpi=100)
        plt.close(fig)
    return files


# -------------------------------------------------------------------- report
def write_outputs(results: list[SeedResult], out: Path, scenario: Scenario, opts: CompareOptions, dt: float, end_s: float | None) -> list[dict[str, Any]]:
    """comparison.csv, the plots, report.html and report.md into ``out``."""
    comfort = scenario.comfort_lateral_accel_mps2
    fields = ["seed", "id"] + [f"{m}_{w}" for m, _, _ in VEHICLE_METRICS for w in ("baseline", "treatment")]
    with open(out / "comparison.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields)
        w.writeheader()
        for r in results:
            for row in r.rows:
                w.writerow({k: ("" if isinstance(v, float) and not math.isfinite(v) else (repr(v) if isinstance(v, float) else v)) for k, v in row.items()})
    with open(out / "network.csv", "w", newline="") as f:
        nw = csv.writer(f)
        nw.writerow(["seed", "run", *[m for m, _, _ in NETWORK_METRICS]])
        for r in results:
            for which in ("baseline", "treatment"):
                nw.writerow([r.seed, which, *[repr(r.network[which][m]) for m, _, _ in NETWORK_METRICS]])
    table = summarise(results)
    plots = _plots(results, out, dt, comfort)
    text = plain_text(table, results, opts.baseline)
    if opts.controlled_fraction is not None:
        sel = f"a fraction {opts.controlled_fraction:g} of all vehicles (seeded hash of the id)"
    elif opts.controlled_type is not None:
        sel = f"every vehicle of vType {opts.controlled_type}"
    else:
        sel = f"the vTypes with {CONTROLLED_PARAM}=true"
    unpaired = sum(r.unpaired for r in results)
    head = [
        f"# blendtrack compare: {scenario.name}",
        "",
        f"Baseline: SUMO's car-following model ({'as in the scenario' if opts.baseline == 'krauss' else f'{MODELS[opts.baseline]} for every vType, in both runs'}), no blendtrack. "
        f"Treatment: blendtrack drives {sel}. Seeds 0..{opts.seeds - 1}, end {fmt(end_s) if end_s is not None else 'scenario default'} s, step {dt:g} s.",
        f"Vehicles paired by id: {sum(len(r.rows) for r in results)}; selected in only one of the two runs (not paired): {unpaired}.",
        "",
        "## Summary",
        "",
        "Baseline and treatment: mean over seeds of the per-seed means; difference: treatment - baseline, "
        "mean over seeds with its 95% confidence interval (Student's t over the seeds).",
        "",
        *summary_lines(table),
        "",
        "## In plain words",
        "",
        text,
        "",
        "## How the numbers are made",
        "",
        "- Every per-vehicle number except the lateral error comes from SUMO's outputs, computed the same way for both runs: "
        "travel time and time loss from tripinfo (trips still running at the end are counted up to the end: "
        "`--tripinfo-output.write-unfinished`), CO2 and fuel from the emissions device (g), speed and accelerations from FCD.",
        f"- Lateral acceleration: a_lat = v * dpsi/dt with the heading change over {LAT_WINDOW_S:g} s "
        "(as `blendtrack.sumo.report.fcd_lateral_accel`); samples touching a junction lane are left out. "
        f"Time above comfort counts samples with |a_lat| > {comfort:g} m/s^2. Jerk: second difference of the FCD speed per step.",
        "- Lateral error: blendtrack's own (vehicles.csv, RMS of the control point's distance to the lane centreline). "
        "SUMO's drivers are placed on the lane centreline, so the baseline's is 0 by construction, not measured.",
        "- Curvature in the speed plot is the curvature of the driven path (|dpsi| / ds over 1 s, from FCD), "
        "the same estimate for both runs, not the lane's geometry.",
        "- SSM conflicts: conflicts in ssm.xml with minimum TTC < 3 s or maximum DRAC > 3 m/s^2 "
        "(every conflict SUMO's SSM device listed in the run's ssm.xml). "
        "Collisions and teleports: SUMO's statistic output (all vehicles).",
        "- Per-vehicle pairs: comparison.csv; per-run network numbers: network.csv; the runs: runs/seed*/.",
        "",
        "## Plots",
        "",
    ]
    md = head + [f"![{title}]({p.name})\n" for title, p in plots]
    html_rows = "".join(
        f"<tr><td>{r['label']}</td><td>{r['unit']}</td><td>{fmt(r['baseline'])}</td><td>{fmt(r['treatment'])}</td>"
        f"<td>{fmt(r['difference'])}</td><td>{'[' + fmt(r['ci_low']) + ', ' + fmt(r['ci_high']) + ']' if r['ci_low'] == r['ci_low'] else 'n/a'}</td></tr>"
        for r in table
    )
    imgs = "".join(
        f"<h3>{title}</h3><img alt='{title}' src='data:image/png;base64,{base64.b64encode(p.read_bytes()).decode()}'/>"
        for title, p in plots
    )
    import html as _html

    notes = "".join(f"<li>{_html.escape(line[2:])}</li>" for line in head if line.startswith("- "))
    page = (
        "<!DOCTYPE html><html><head><meta charset='utf-8'><title>blendtrack compare: "
        f"{_html.escape(scenario.name)}</title><style>body{{font-family:sans-serif;max-width:1100px;margin:auto}}"
        "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:3px 8px}td:nth-child(n+3){text-align:right}"
        "img{max-width:100%}</style></head><body>"
        f"<h1>blendtrack compare: {_html.escape(scenario.name)}</h1><p>{_html.escape(head[2])}</p><p>{_html.escape(head[3])}</p>"
        "<h2>Summary</h2><table><tr><th>metric</th><th>unit</th><th>baseline</th><th>treatment</th><th>difference</th><th>95% CI</th></tr>"
        f"{html_rows}</table><h2>In plain words</h2><p>{_html.escape(text)}</p><h2>How the numbers are made</h2><ul>{notes}</ul>"
        f"<h2>Plots</h2>{imgs}</body></html>\n"
    )
    (out / "report.html").write_text(page)
    (out / "report.md").write_text("\n".join(md))
    return table


def compare(scenario: Scenario, opts: CompareOptions, out: Path) -> list[dict[str, Any]]:
    """Runs every seed's baseline and treatment and writes the report into ``out``."""
    from tqdm import tqdm

    if opts.controlled_type is not None:
        known = set(_vtypes(scenario.route_files)) | {"DEFAULT_VEHTYPE"}
        if opts.controlled_type not in known:
            raise ScenarioError(f"--controlled-type {opts.controlled_type!r}: no such vType in {scenario.sumocfg.name} "
                                f"(known: {', '.join(sorted(known))})")
    # SUMO resolves relative output paths against the .sumocfg's folder.
    out = out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    # A report left from an earlier compare would look like this one's if we are interrupted.
    for name in ("report.md", "report.html", "comparison.csv", "network.csv"):
        (out / name).unlink(missing_ok=True)
    work = Path(tempfile.mkdtemp(prefix=".partial-", dir=out))
    try:
        end_s = opts.end_s if opts.end_s is not None else scenario.default_end_s
        sc = with_model(scenario, opts.baseline, work / "model")
        dt = sc.step_length_s
        results = []
        with tqdm(total=2 * opts.seeds, desc="blendtrack compare", unit="run", file=sys.stderr, disable=not opts.progress or None) as bar:
            for seed in range(opts.seeds):
                rd = work / "runs" / f"seed{seed}"
                bar.set_postfix_str(f"seed {seed} baseline")
                run_baseline(sc, seed, end_s, rd / "baseline")
                bar.update()
                bar.set_postfix_str(f"seed {seed} treatment")
                ropt = dataclasses.replace(opts.run, controlled_fraction=opts.controlled_fraction,
                                           controlled_type=opts.controlled_type, seed=seed, end_s=end_s, progress=False)
                treat = run_treatment(sc, ropt, rd / "treatment")
                bar.update()
                tctl = {r.vid for r in treat.records}
                base_run = load_run(rd / "baseline", selector(opts, sc, seed))
                treat_run = load_run(rd / "treatment", lambda vid, vtype: vid in tctl)
                results.append(pair(seed, base_run, treat_run, dt, scenario.comfort_lateral_accel_mps2))
        table = write_outputs(results, work, sc, opts, dt, end_s)
        # Into place: runs and data first, report.md last.
        if (out / "runs").exists():
            shutil.rmtree(out / "runs")
        os.replace(work / "runs", out / "runs")
        names = [p.name for p in work.iterdir() if p.is_file() and p.name != "report.md"]
        for name in names:
            os.replace(work / name, out / name)
        os.replace(work / "report.md", out / "report.md")
        return table
    finally:
        shutil.rmtree(work, ignore_errors=True)
