"""A vehicle inserted with its front at the start of its lane (SUMO's
``departPos="0"``, every vehicle of Bologna's Acosta scenario) has its
control point behind the start of the lane, where its track starts. Its
lateral error there is its distance from the line the track's first
segment extends (``Path``'s projection beyond an open path's ends), not
from the track's first point: as that distance a 12 m bus had 6 m, more
than its lane's width, and was handed back at once as a placement fault,
and a car had 2.5 m, of either sign, which it steered to make up."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

from blendtrack import sumo
from blendtrack.sumo.runner import RunOptions

ROUTES = """<routes>
  <vType id="bus" vClass="bus" length="12" minGap="3" accel="2.6" decel="4.5" sigma="0"/>
  <vType id="car" length="5" minGap="2.5" accel="2.6" decel="4.5" sigma="0"/>
  <vehicle id="bus" type="bus" depart="0" departPos="0" departSpeed="max"><route edges="AB BC"/></vehicle>
  <vehicle id="car" type="car" depart="10" departPos="0" departSpeed="max"><route edges="AB BC"/></vehicle>
  <vehicle id="base" type="car" depart="20" departSpeed="max"><route edges="AB BC"/></vehicle>
</routes>"""


def test_a_vehicle_whose_rear_is_behind_its_lane_is_driven_from_its_departure(tmp_path: Path, build_net: Any) -> None:
    build_net(tmp_path, '<nodes><node id="A" x="0" y="0"/><node id="B" x="300" y="0"/><node id="C" x="600" y="0"/></nodes>',
              '<edges><edge id="AB" from="A" to="B" speed="13.89"/><edge id="BC" from="B" to="C" speed="13.89"/></edges>')
    (tmp_path / "r.rou.xml").write_text(ROUTES)
    cfg = tmp_path / "d.sumocfg"
    cfg.write_text('<configuration><input><net-file value="n.net.xml"/><route-files value="r.rou.xml"/></input>'
                   '<time><step-length value="1"/></time></configuration>')
    out = tmp_path / "out"
    result = sumo.run_scenario(sumo.resolve_scenario(str(cfg)), RunOptions(end_s=60, progress=False, controlled_fraction=1.0), out)
    assert result.summary["placement_faults"] == 0
    with open(out / "vehicles.csv") as f:
        rows = {r["id"]: r for r in csv.DictReader(f)}
    assert set(rows) == {"bus", "car", "base"}, "every vehicle is driven by blendtrack"
    # Each is taken over after the step SUMO inserted it in (the runner's
    # clock reads the end of that step), the bus with its control point 6 m
    # behind its track's start, the car with its rear axle (2.6 + 1.2 m
    # behind the front, plus half the 2.6 m wheelbase) 2.5 m behind it,
    # "base" (SUMO's default departPos: its back at the start) on its track.
    assert {k: float(r["depart_s"]) for k, r in rows.items()} == {"bus": 1.0, "car": 11.0, "base": 21.0}
    for vid in ("bus", "car", "base"):
        assert float(rows[vid]["lateral_error_max_abs_m"]) < 0.2, vid
