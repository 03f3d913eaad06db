"""The control rate does not depend on SUMO's step length (issue 17, item 1):
a shipped scenario at SUMO steps of 0.1 s and 1 s gives close results."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from blendtrack import sumo
from blendtrack.sumo.runner import RunOptions


def _controlled(out: Path) -> tuple[float, float, int]:
    """(mean |lateral error|, mean speed, control steps) of the controlled
    vehicles, weighted by their control steps (time-weighted: each control
    step of a run is equally long)."""
    with open(out / "vehicles.csv") as f:
        rows = [r for r in csv.DictReader(f) if int(r["steps"]) > 0]
    steps = sum(int(r["steps"]) for r in rows)
    assert steps > 0
    e = sum(float(r["lateral_error_mean_abs_m"]) * int(r["steps"]) for r in rows) / steps
    v = sum(float(r["mean_speed_mps"]) * int(r["steps"]) for r in rows) / steps
    return e, v, steps


def _run(tmp_path: Path, name: str, step_s: float, control_dt_s: float = 0.05) -> tuple[float, float, int]:
    sc = sumo.resolve_scenario("highway_onramp")
    opts = RunOptions(
        controlled_fraction=0.3,
        end_s=120,
        control_dt_s=control_dt_s,
        sumo_args=("--step-length", str(step_s), "--no-warnings", "true"),
        progress=False,
    )
    out = tmp_path / name
    sumo.run_scenario(sc, opts, out)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["step_length_s"] == pytest.approx(step_s)
    assert summary["control_dt_s"] == control_dt_s
    assert summary["controlled_vehicles"] >= 10
    return _controlled(out)


def test_a_one_second_step_drives_as_a_tenth_of_a_second_step(tmp_path: Path) -> None:
    e_fine, v_fine, n_fine = _run(tmp_path, "fine", 0.1)
    e_coarse, v_coarse, n_coarse = _run(tmp_path, "coarse", 1.0)
    # Both run 0.05 s control steps: about as many over the same 120 s.
    assert n_coarse == pytest.approx(n_fine, rel=0.1)
    # The two traffics differ (SUMO's drivers decide once a second in the
    # coarse run), so no closed form gives the 1 s run's numbers. What is
    # compared instead is the independent alternative: the same 1 s run with
    # the control tied to SUMO's step (one control step per 1 s step, as
    # before the control rate). Whichever of the two runs the 1 s run is
    # nearer to is the rate it drives at: nearest of two, the decision rule
    # with no margin to choose, so each difference must be under half the
    # distance between the 0.1 s run and the tied one. With the control tied
    # to the step the coarse run is the tied run and both checks fail; if
    # the tied run drove like the fine one (nothing to tell apart), the
    # strict "<" against 0 fails too.
    e_old, v_old, _ = _run(tmp_path, "old", 1.0, control_dt_s=1.0)
    assert abs(e_coarse - e_fine) < 0.5 * abs(e_old - e_fine), (e_fine, e_coarse, e_old)
    assert abs(v_coarse - v_fine) < 0.5 * abs(v_old - v_fine), (v_fine, v_coarse, v_old)


def test_the_control_rate_must_be_positive() -> None:
    with pytest.raises(sumo.ScenarioError, match="control dt"):
        RunOptions(control_dt_s=0.0)
