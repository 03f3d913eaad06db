"""SUMO's position update, Euler (its default) or ballistic
(``--step-method.ballistic``): at a 1 s step SUMO has each controlled
vehicle's front where blendtrack has it under ballistic, and under Euler
within the known lead pulling away."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from blendtrack import sumo
from blendtrack.sumo.runner import RunOptions, SumoRun

SCENARIOS = Path(__file__).resolve().parents[1] / "sumo_scenarios"


@pytest.mark.parametrize("ballistic", [False, True])
def test_sumo_has_the_front_where_blendtrack_has_it(tmp_path: Path, ballistic: bool) -> None:
    """The shipped grid at a 1 s step, 30 % controlled, 150 s. After each of
    SUMO's steps every controlled vehicle on the lane blendtrack has its
    front on is compared: SUMO's lane position against blendtrack's.

    Under ballistic the moves are worked out for it: 99 % of the offsets
    under 0.25 m (0.075 m measured; before, the median was 1.24 m and the
    99th percentile 3.3 m, SUMO moving the mean of two speeds where an
    Euler move was assumed, with 15 collisions with a controlled vehicle).
    Under Euler (SUMO's default) the moves are as before: SUMO runs ahead
    of blendtrack pulling away from the lights (the speed sent is the end
    speed less the glide tolerance, blendtrack moves the step's mean; a
    known limit, docs/sumo.md "SUMO a little ahead"): 99 % under 2 m (1.39 m
    measured), none past the placement check's 5 m."""
    args = ("--step-length", "1", "--no-warnings", "true")
    if ballistic:
        args += ("--step-method.ballistic", "true")
    sc = sumo.resolve_scenario(str(SCENARIOS / "urban_grid"))
    run = SumoRun(sc, RunOptions(controlled_fraction=0.3, end_s=150, seed=0, sumo_args=args, progress=False), tmp_path)
    offsets: list[float] = []

    def compare(r: SumoRun, t: float) -> None:
        v = r.conn.sumo.vehicle
        present = set(v.getIDList())  # (the ones that arrived in this step are still active)
        for vid, act in r.active.items():
            if vid not in present:
                continue
            lane, pos = r.fleet.front_lane_position(act.slot)
            if v.getLaneID(vid) == r.tracks.lanes.name(lane):
                offsets.append(float(v.getLanePosition(vid)) - pos)

    run.step_hooks.append(compare)
    result = run.run()
    assert result.summary["ballistic_update"] is ballistic
    assert result.summary["controlled_vehicles"] >= 50
    off = np.abs(np.array(offsets))
    assert len(off) > 2000
    if ballistic:
        assert np.percentile(off, 99) < 0.25, np.percentile(off, [50, 99, 100])
        assert off.max() < 1.0, off.max()
    else:
        assert np.percentile(off, 99) < 2.0, np.percentile(off, [50, 99, 100])
        assert off.max() < 5.0, off.max()
    assert result.summary["collisions"] == 0
