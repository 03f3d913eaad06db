"""SUMO's output files read with sumolib's parsers: FCD (a vehicle's series),
the lateral acceleration from FCD, tripinfo, SSM conflicts and the statistic
output."""

from __future__ import annotations

import csv
import math
from array import array
from collections.abc import Container
from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: Window of the heading change in a_lat = v dpsi/dt (s).
LAT_WINDOW_S = 1.0
#: SSM thresholds of a conflict (the runner's ``--device.ssm.thresholds``).
TTC_CONFLICT_S = 3.0
DRAC_CONFLICT_MPS2 = 3.0

#: The FCD vehicle attributes read, in SUMO's order (sumolib's fast parser
#: matches them in this order; others may come between).
_FCD_ATTRS = ["id", "x", "y", "angle", "type", "speed", "pos", "lane"]


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
    """Every vehicle's series in an FCD file (``--fcd-output``).

    Samples go straight into a flat array of doubles per vehicle (8 bytes a
    value) and each lane name is kept once: held as a tuple of Python floats
    per sample and a string per sample, the FCD of Bologna run to its end
    (1.1 GB) took the compare process to about 8 GB."""
    import sumolib

    raw: dict[str, tuple[str, array[float], list[str]]] = {}
    lane_names: dict[str, str] = {}
    for step, veh in sumolib.xml.parse_fast_nested(str(file), "timestep", ["time"], "vehicle", _FCD_ATTRS):
        rec = raw.get(veh.id)
        if rec is None:
            rec = raw[veh.id] = (veh.type, array("d"), [])
        rec[1].extend((float(step.time), float(veh.x), float(veh.y), float(veh.angle), float(veh.speed), float(veh.pos)))
        rec[2].append(lane_names.setdefault(veh.lane, veh.lane))
    out = {}
    for vid, (vtype, flat, lanes) in raw.items():
        a = np.frombuffer(flat, dtype=float).reshape(-1, 6)
        out[vid] = Track(vtype, a[:, 0], a[:, 1], a[:, 2], a[:, 3], a[:, 4], lanes, a[:, 5])
    return out


def lateral_series(
    tr: Track, dt: float, window_s: float = LAT_WINDOW_S, skip_internal: bool = True
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The lateral acceleration of a vehicle from its FCD series: ``a_lat =
    v * dpsi/dt`` with the heading change taken over ``window_s`` (it smooths
    the heading steps where lane shapes meet), over windows of consecutive
    steps. Returns (time, a_lat, driven-path curvature |dpsi| / ds, the index
    of each sample in the series), samples touching a junction (internal)
    lane left out by default (SUMO limits turn speeds there)."""
    k = max(1, round(window_s / dt))
    n = len(tr.t)
    if n <= k:
        return np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0, dtype=np.int64)
    dpsi = np.radians((tr.angle[k:] - tr.angle[:-k] + 180.0) % 360.0 - 180.0)
    keep = np.isclose(tr.t[k:] - tr.t[:-k], k * dt)
    if skip_internal:
        internal = np.array([ln.startswith(":") for ln in tr.lane])
        keep &= ~internal[k:] & ~internal[:-k]
    a_lat = tr.speed[k:] * dpsi / (k * dt)
    ds = np.hypot(tr.x[k:] - tr.x[:-k], tr.y[k:] - tr.y[:-k])
    with np.errstate(divide="ignore", invalid="ignore"):
        kappa = np.where(ds > 1.0, np.abs(dpsi) / ds, np.nan)
    return tr.t[k:][keep], a_lat[keep], kappa[keep], np.flatnonzero(keep) + k


def fcd_lateral_accel(
    fcd_file: Path, dt_s: float, window_s: float = LAT_WINDOW_S, skip_internal: bool = True
) -> dict[str, tuple[float, str]]:
    """Largest lateral acceleration of every vehicle in an FCD file
    (:func:`lateral_series`): ``{vehicle id: (max |a_lat| in m/s^2, lane
    where it happened)}``, for the vehicles with a sample."""
    best: dict[str, tuple[float, str]] = {}
    for vid, tr in read_fcd(fcd_file).items():
        _, a_lat, _, at = lateral_series(tr, dt_s, window_s, skip_internal)
        if len(a_lat):
            j = int(np.argmax(np.abs(a_lat)))
            best[vid] = (float(abs(a_lat[j])), tr.lane[int(at[j])])
    return best


def read_tripinfo(file: Path) -> dict[str, dict[str, float]]:
    """Per trip: duration, time loss, whether it arrived (1/0), CO2 and fuel (g)."""
    import sumolib

    out: dict[str, dict[str, float]] = {}
    for trip in sumolib.xml.parse(str(file), "tripinfo"):
        em = trip.emissions[0] if trip.hasChild("emissions") else None
        out[trip.id] = {
            "duration": float(trip.getAttributeSecure("duration", "nan")),
            "time_loss": float(trip.getAttributeSecure("timeLoss", "nan")),
            "arrived": float(float(trip.getAttributeSecure("arrival", "-1")) >= 0.0),
            "co2_g": float(em.getAttributeSecure("CO2_abs", "nan")) / 1000.0 if em is not None else math.nan,
            "fuel_g": float(em.getAttributeSecure("fuel_abs", "nan")) / 1000.0 if em is not None else math.nan,
        }
    return out


#: collisions.csv's columns: one row per collision, SUMO's own (``detected_by``
#: "sumo") and the lane collisions SUMO skips for vehicles moved by (x, y)
#: under ``collision.action teleport`` ("blendtrack"; :mod:`blendtrack.sumo.collisions`).
COLLISION_COLUMNS = ("time_s", "type", "lane", "collider", "victim", "collider_type", "victim_type", "controlled_involved", "detected_by")


def read_collisions(file: Path, controlled: Container[str]) -> list[dict[str, object]]:
    """Every collision in SUMO's collision output, whatever ``collision.action``
    made of it (a warning, a teleport, a removal), with who was involved and
    whether a vehicle of ``controlled`` was one of them; [] without the file."""
    import sumolib

    if not Path(file).is_file():
        return []
    rows: list[dict[str, object]] = []
    for c in sumolib.xml.parse(str(file), "collision"):
        collider, victim = c.getAttributeSecure("collider", ""), c.getAttributeSecure("victim", "")
        rows.append({
            "time_s": float(c.getAttributeSecure("time", "nan")),
            "type": c.getAttributeSecure("type", ""),
            "lane": c.getAttributeSecure("lane", ""),
            "collider": collider,
            "victim": victim,
            "collider_type": c.getAttributeSecure("colliderType", ""),
            "victim_type": c.getAttributeSecure("victimType", ""),
            "controlled_involved": int(collider in controlled or victim in controlled),
            "detected_by": "sumo",
        })
    return rows


def remote_collision_rows(found: list[tuple[float, str, str, str, str, str]], controlled: Container[str]) -> list[dict[str, object]]:
    """collisions.csv rows of the collisions blendtrack found where SUMO does
    not look ((time, collider, victim, lane, collider's vType, victim's vType)
    each; type ``collision``, as SUMO names one along a lane)."""
    return [
        {
            "time_s": t, "type": "collision", "lane": lane, "collider": collider, "victim": victim,
            "collider_type": ctype, "victim_type": vtype,
            "controlled_involved": int(collider in controlled or victim in controlled),
            "detected_by": "blendtrack",
        }
        for t, collider, victim, lane, ctype, vtype in found
    ]


#: ``detected_by`` of a collision SUMO reported for a pair blendtrack had
#: already found (``mark_repeats``): listed, not counted again.
REPEAT = "sumo_repeat"


def mark_repeats(rows: list[dict[str, object]], window_s: float) -> list[dict[str, object]]:
    """``rows`` (collisions.csv rows, in order of time) with each one SUMO
    reported for a pair blendtrack had found less than ``window_s`` earlier
    marked ``detected_by`` = ``REPEAT``: the same contact. blendtrack hands
    its vehicle back to SUMO at once, the two stay where they are, and
    SUMO's own check reports them when its exemption for vehicles moved by
    (x, y) runs out (Bologna, 30 %, road corridor, seed 35: found at 509 s,
    reported again at 519 s)."""
    found: dict[frozenset[str], float] = {}
    for r in rows:
        pair = frozenset((str(r["collider"]), str(r["victim"])))
        t = float(r["time_s"])  # type: ignore[arg-type]
        if r["detected_by"] == "blendtrack":
            found[pair] = t
        elif pair in found and t - found[pair] < window_s:
            r["detected_by"] = REPEAT
    return rows


def count_remote_collisions(file: Path) -> int:
    """What a run's ``collisions.csv`` adds to SUMO's own count of collisions:
    the rows blendtrack found where SUMO does not look (``detected_by``
    "blendtrack"), less SUMO's reports of a pair blendtrack had found
    (``REPEAT``, which SUMO's count includes); 0 without the file (a plain run)."""
    if not Path(file).is_file():
        return 0
    with open(file, newline="") as f:
        by = [r.get("detected_by") for r in csv.DictReader(f)]
    return by.count("blendtrack") - by.count(REPEAT)


def read_ssm_conflicts(file: Path) -> float:
    """Conflicts with TTC < 3 s or DRAC > 3 m/s^2 (NaN without an ssm.xml)."""
    import sumolib

    if not file.exists():
        return math.nan
    n = 0
    for conflict in sumolib.xml.parse(str(file), "conflict"):
        if _value(conflict, "minTTC") < TTC_CONFLICT_S or _value(conflict, "maxDRAC") > DRAC_CONFLICT_MPS2:
            n += 1
    return n


def _value(el: object, child: str) -> float:
    """The ``value`` of an SSM conflict's child element, NaN when absent or not a number."""
    if not el.hasChild(child):  # type: ignore[attr-defined]
        return math.nan
    try:
        return float(el.getChild(child)[0].getAttributeSecure("value", "nan"))  # type: ignore[attr-defined]
    except ValueError:
        return math.nan


def read_statistics(file: Path) -> tuple[int, int]:
    """(collisions, teleports) from SUMO's statistic output."""
    import sumolib

    root = next(sumolib.xml.parse(str(file), "statistics"))
    saf = root.getChild("safety")[0] if root.hasChild("safety") else None
    tel = root.getChild("teleports")[0] if root.hasChild("teleports") else None
    return (int(saf.getAttributeSecure("collisions", "0")) if saf is not None else 0,
            int(tel.getAttributeSecure("total", "0")) if tel is not None else 0)
