"""The control point in SUMO runs: the alpha each controlled vehicle used,
step by step, in trace.csv, and the alpha(t) plot of ``--alpha auto``."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from blendtrack import sumo
from blendtrack.sumo.options import RunOptions


def _run(out: Path, alpha: float | str) -> pd.DataFrame:
    sc = sumo.resolve_scenario("rural_loop")
    sumo.run_scenario(sc, RunOptions(end_s=120, trace=True, progress=False, alpha=alpha), out)
    return pd.read_csv(out / "trace.csv")


def test_a_fixed_alpha_is_the_alpha_of_every_traced_step_and_draws_no_plot(tmp_path: Path) -> None:
    trace = _run(tmp_path, 0.35)
    # One row per SUMO step (0.1 s, rural_loop.sumocfg) per controlled
    # vehicle: the first auto vehicle departs at 0 s for 4 laps of 2560 m,
    # over 400 s at 25 m/s, so it is traced every step of the 120 s (a
    # second's grace for its insertion).
    assert (trace["id"] == "auto_ccw.0").sum() >= round((120.0 - 1.0) / 0.1), trace["id"].value_counts().head()
    assert (trace["alpha"] == 0.35).all()
    assert not (tmp_path / "alpha.png").exists()


def test_auto_alpha_leads_with_the_front_axle_on_straights_and_moves_back_in_curves(tmp_path: Path) -> None:
    # auto_alpha forward: 1 (Stanley, the leading axle) wherever no curvature
    # is ahead, toward auto_alpha_forward = 0.3 in steady curves: the rural
    # loop has both, so both ends must show up, and nothing outside [0, 1].
    trace = _run(tmp_path, "auto")
    a = trace["alpha"]
    assert a.between(0.0, 1.0).all()
    assert a.max() == pytest.approx(1.0)
    assert a.min() < 0.6
    straight = trace[trace["curvature_per_m"].abs() < 1e-9]
    assert len(straight) > 0 and (straight["alpha"] > 0.6).mean() > 0.5
    assert (tmp_path / "alpha.png").stat().st_size > 1000
