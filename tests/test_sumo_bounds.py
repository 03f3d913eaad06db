"""Per-vehicle bounds on every shipped scenario, judged by SUMO's own state
(issue 23): each controlled vehicle's gap to its leader as ``getLeader``
gives it, every step; its lateral acceleration and its front's step-to-step
displacement from SUMO's FCD output; red-light crossings from SUMO's signal
states and collisions from SUMO's collision output; and its lateral error
outside lane changes. One short run per scenario (all checks on it: one
test each, so a worker runs each scenario once)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from blendtrack import sumo
from blendtrack.sumo.lanechange import LANE_CHANGE_S
from blendtrack.sumo.outputs import LAT_WINDOW_S, lateral_series, read_collisions, read_fcd
from blendtrack.sumo.runner import CHEAP_HEADING_RAD, CHEAP_LATERAL_M, RunOptions, SumoRun

#: (scenario, controlled fraction (None: the scenario's own automated
#: vehicles), simulated seconds). The grid and the highway with every
#: vehicle controlled: controlled leaders, queues at lights, the merge.
RUNS = [("rural_loop", None, 150.0), ("ring_single_lane", None, 120.0), ("urban_grid", 1.0, 120.0), ("highway_onramp", 1.0, 120.0)]

#: A lane change is LANE_CHANGE_S of travel (at least 10 m: up to 4 s at
#: 2.5 m/s); samples within this many seconds of a change of lane index
#: on one edge belong to it (and the 1 s window of the lateral acceleration).
LANE_CHANGE_WINDOW_S = 2.0 * LANE_CHANGE_S + 2.0
#: SUMO's FCD position is the front bumper and its lane the front's: after a
#: junction turn the body still turns for about a body length (4.5 m at
#: >= 4.5 m/s: 1 s). Samples whose lateral-acceleration window, or the
#: second before it, touched a junction lane belong to the turn.
AFTER_JUNCTION_S = LAT_WINDOW_S + 1.0
#: The lateral acceleration measured from FCD over 1 s windows may exceed
#: the curvature law's comfort bound by the heading steps where SUMO's lane
#: shapes meet and the tracking corrections: 0.3 m/s^2 (as on the rural
#: loop in test_sumo).
LAT_ACCEL_SLACK_MPS2 = 0.3
#: A controlled front moves at most its speed times the step, plus a lane
#: move's lateral snap onto the centreline: the control point within
#: CHEAP_LATERAL_M of it and the heading within CHEAP_HEADING_RAD, over a
#: reach of at most 4 m from the control point to the front: 0.15 + 4 sin 2 deg
#: = 0.29 m.
JUMP_TOLERANCE_M = CHEAP_LATERAL_M + 4.0 * math.sin(CHEAP_HEADING_RAD)
#: The most a move to or from the track's point (a front over the traffic
#: crate's XY_ON_TRACK_M, 1 m, off the track) may add to a jump: twice that.
ON_TRACK_SWITCH_M = 2.0
#: The standstill gap blendtrack keeps beyond SUMO's minGap (RunOptions
#: default 1 m): two standing vehicles stay at least half of it apart
#: (creeping to a stop eats some; a vehicle that ignored the margin stops
#: at 0).
STANDSTILL_FLOOR_FRACTION = 0.5


_Gap = tuple[float, float, float, float, str]


def _run(name: str, fraction: float | None, end: float, out: Path) -> tuple[SumoRun, Any, list[_Gap], dict[str, float]]:
    sc = sumo.resolve_scenario(name)
    run = SumoRun(sc, RunOptions(end_s=end, controlled_fraction=fraction, fcd=True, trace=True, progress=False), out)
    gaps: list[_Gap] = []
    widths: dict[str, float] = {}

    def leader_gaps(r: SumoRun, t: float) -> None:
        v = r.sumo.vehicle
        present = set(v.getIDList())
        for vid in r.active:
            if vid not in present:
                continue  # arrived this step; dropped after the hooks
            if vid not in widths:
                widths[vid] = float(v.getWidth(vid))
            lead = v.getLeader(vid, 250.0)
            if lead and lead[0]:
                gaps.append((float(lead[1]), float(v.getSpeed(vid)), float(v.getSpeed(lead[0])), t, vid))

    run.step_hooks.append(leader_gaps)
    # (time, vehicle) of each move that put a vehicle nearer its track than
    # its front (a front over 1 m off the track): SUMO's place then switches
    # between the two, by design.
    run.on_track_moves = []  # type: ignore[attr-defined]
    apply = run._apply

    def note_on_track(t: float, ids: list[str], acts: list[Any], out: dict[str, Any]) -> None:
        run.on_track_moves.extend((t, ids[i]) for i in out["xy_on_track"].nonzero()[0].tolist())  # type: ignore[attr-defined]
        apply(t, ids, acts, out)

    run._apply = note_on_track  # type: ignore[method-assign]
    result = run.run()
    run.write_trace(out / "trace.csv")
    return run, result, gaps, widths


def _lane_change_times(lanes: list[str], t: np.ndarray) -> np.ndarray:
    edges = [ln.rsplit("_", 1)[0] for ln in lanes]
    return np.array([t[i] for i in range(1, len(lanes)) if lanes[i] != lanes[i - 1] and edges[i] == edges[i - 1]])


@pytest.mark.parametrize(("name", "fraction", "end"), RUNS, ids=[r[0] for r in RUNS])
def test_every_controlled_vehicle_keeps_its_bounds_by_sumos_state(tmp_path: Path, name: str, fraction: float | None, end: float) -> None:
    import csv

    import sumolib

    run, result, gaps, vehicle_width = _run(name, fraction, end, tmp_path)
    s = result.summary
    controlled = {r.vid for r in result.records}
    assert controlled, "vehicles were taken over"
    dt = float(s["step_length_s"])
    comfort = float(s["comfort_lateral_accel_mps2"])

    # Collisions and red lights, by SUMO's records and signal states.
    assert read_collisions(tmp_path / "sumo" / "collisions.xml", controlled) == []
    assert s["red_light_crossings_sumo"] == 0, run.incidents.crossings
    assert s["teleports_controlled"] == 0

    # Gaps by getLeader: never below 0 (SUMO counts a gap below the
    # follower's minGap, which getLeader leaves out, as a collision), and
    # two standing vehicles keep half of blendtrack's standstill margin.
    g = np.array([x[:3] for x in gaps])
    assert len(g) > 100
    i = int(np.argmin(g[:, 0]))
    assert g[i, 0] >= 0.0, f"gap {g[i, 0]:.3f} m by getLeader: {gaps[i]}"
    still = (g[:, 1] < 0.1) & (g[:, 2] < 0.1)
    if still.any():
        floor = STANDSTILL_FLOOR_FRACTION * run.opt.standstill_margin_m
        j = int(np.flatnonzero(still)[np.argmin(g[still, 0])])
        assert g[j, 0] >= floor, f"standing gap {g[j, 0]:.3f} m < {floor} m: {gaps[j]}"

    # From SUMO's FCD: lateral acceleration outside lane changes and
    # junction turns within the comfort bound plus slack; no placement jumps.
    fcd = read_fcd(tmp_path / "sumo" / "fcd.xml")
    back = round(AFTER_JUNCTION_S / dt)
    on_track: dict[str, list[float]] = {}
    for t_move, vid in run.on_track_moves:  # type: ignore[attr-defined]
        on_track.setdefault(vid, []).append(t_move)
    worst_lat: tuple[float, Any] = (0.0, None)
    worst_jump: tuple[float, Any] = (-math.inf, None)
    for vid in controlled & fcd.keys():
        tr = fcd[vid]
        ts, a_lat, _, idx = lateral_series(tr, dt)
        internal = np.concatenate([[0], np.cumsum([ln.startswith(":") for ln in tr.lane])])
        changes = _lane_change_times(tr.lane, tr.t)
        for tj, aj, ej in zip(ts.tolist(), np.abs(a_lat).tolist(), idx.tolist()):
            if internal[ej + 1] - internal[max(ej - back, 0)] > 0:
                continue
            if len(changes) and np.min(np.abs(changes - tj)) < LANE_CHANGE_WINDOW_S:
                continue
            if aj > worst_lat[0]:
                worst_lat = (aj, (vid, tj, tr.lane[ej]))
        step = np.isclose(np.diff(tr.t), dt)
        moved = np.hypot(np.diff(tr.x), np.diff(tr.y))
        excess = np.where(step, moved - np.maximum(tr.speed[1:], tr.speed[:-1]) * dt, -math.inf)
        # A move to or from the track's point may jump by up to twice the
        # 1 m limit (XY_ON_TRACK_M in the traffic crate), and no more. One
        # made after SUMO's step ending at t lands in the FCD sample of the
        # next step, stamped t (SUMO stamps a sample with its step's start);
        # the first move after the last such one, a step later.
        for t_move in on_track.get(vid, ()):
            near = (tr.t[1:] > t_move - 0.5 * dt) & (tr.t[1:] < t_move + 1.5 * dt)
            excess[near] -= ON_TRACK_SWITCH_M
        if len(excess) and excess.max() > worst_jump[0]:
            k = int(np.argmax(excess))
            worst_jump = (float(excess[k]), (vid, float(tr.t[k + 1]), tr.lane[k], tr.lane[k + 1]))
    assert worst_lat[0] <= comfort + LAT_ACCEL_SLACK_MPS2, f"lateral acceleration {worst_lat}"
    assert worst_jump[0] <= JUMP_TOLERANCE_M, f"placement jump beyond v dt by {worst_jump}"

    # Lateral error outside lane changes (blendtrack's trace, against the
    # lane widths of SUMO's network): the control point inside the
    # corridor of the lane (half its width) everywhere; where no junction
    # turn is driven (rural loop, ring, highway) the whole body inside the
    # lane: |e| <= (lane width - vehicle width) / 2.
    net = sumolib.net.readNet(str(run.scenario.net_file), withInternal=True)
    with open(tmp_path / "trace.csv") as f:
        rows = list(csv.DictReader(f))
    by_vehicle: dict[str, list[dict[str, str]]] = {}
    for r in rows:
        by_vehicle.setdefault(r["id"], []).append(r)
    turns = name == "urban_grid"
    widths: dict[str, float] = {}
    worst_e: tuple[float, Any] = (-math.inf, None)
    for vid, vrows in by_vehicle.items():
        t = np.array([float(r["t_s"]) for r in vrows])
        lanes = [f"{r['edge']}_{r['lane_index']}" for r in vrows]
        changes = _lane_change_times(lanes, t)
        width = vehicle_width[vid]
        for tj, lane, r in zip(t.tolist(), lanes, vrows):
            if len(changes) and np.min(np.abs(changes - tj)) < LANE_CHANGE_WINDOW_S:
                continue
            w = widths.get(lane)
            if w is None:
                w = widths[lane] = float(net.getLane(lane).getWidth())
            bound = 0.5 * w if turns else 0.5 * (w - width)
            over = abs(float(r["lateral_error_m"])) - bound
            if over > worst_e[0]:
                worst_e = (over, (vid, tj, lane, r["lateral_error_m"], bound))
    assert worst_e[0] <= 0.0, f"lateral error beyond its bound: {worst_e}"
