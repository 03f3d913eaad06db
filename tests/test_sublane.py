"""Under SUMO's sublane model a driver on the lane beside can reach into a
controlled vehicle's lane; ``getLeader`` does not see it
(:mod:`blendtrack.sumo.sublane`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from blendtrack.sumo import RunOptions, SumoRun, resolve_scenario

ROUTES = """<routes>
<vType id="car" accel="2.6" decel="4.5" sigma="0" length="5" minGap="2.5" maxSpeed="15"/>
<route id="r" edges="ab"/>
<vehicle id="intruder" type="car" route="r" depart="0" departLane="1" departPos="150" departSpeed="0"/>
<vehicle id="car" type="car" route="r" depart="0" departLane="0" departPos="0" departSpeed="10"/>
</routes>"""


def _road(tmp_path: Path, build_net: Any) -> Path:
    net = build_net(tmp_path, '<nodes><node id="a" x="0" y="0"/><node id="b" x="600" y="0"/></nodes>',
                    '<edges><edge id="ab" from="a" to="b" numLanes="2" speed="15"/></edges>')
    (tmp_path / "n.rou.xml").write_text(ROUTES)
    cfg = tmp_path / "n.sumocfg"
    cfg.write_text(f'<configuration><input><net-file value="{net.name}"/><route-files value="n.rou.xml"/></input></configuration>')
    return cfg


def _run(cfg: Path, out: Path, sublane: bool) -> tuple[SumoRun, dict[str, Any], list[tuple[float, float, Any]]]:
    """The controlled car on lane 0 drives up to a driver standing on lane 1,
    1.5 m towards lane 0 (its body 0.8 m into lane 0, over the car's side by
    0.1 m). Returns the run, its summary and (time, the car's lane
    position, SUMO's leader for it) each step."""
    seen: list[tuple[float, float, Any]] = []
    shifted: list[float] = []

    def hook(run: SumoRun, t: float) -> None:
        veh = run.sumo.vehicle
        if "intruder" in veh.getIDList():
            veh.setSpeed("intruder", 0.0)
            if not shifted:
                veh.setLaneChangeMode("intruder", 0)
                veh.changeSublane("intruder", -1.5)
                shifted.append(t)
        if "car" in veh.getIDList():
            seen.append((t, float(veh.getLanePosition("car")), veh.getLeader("car", 200.0)))

    args = ("--collision.action", "warn", *(("--lateral-resolution", "0.8") if sublane else ()))
    run = SumoRun(resolve_scenario(cfg), RunOptions(controlled_ids=("car",), end_s=40.0, progress=False, sumo_args=args), out)
    run.step_hooks.append(hook)
    summary = run.run().summary
    return run, summary, seen


def test_a_driver_reaching_in_from_the_lane_beside_is_a_leader(tmp_path: Path, build_net: Any) -> None:
    run, summary, seen = _run(_road(tmp_path / "net", build_net), tmp_path / "o", sublane=True)
    assert run.sublane.active
    assert all(lead is None for _, _, lead in seen), "SUMO's getLeader saw it: nothing to test"
    # It stops behind the driver's back (145 m) instead of driving on
    # through its side.
    last = seen[-1][1]
    assert 130.0 < last < 145.0, seen[-5:]
    assert summary["collisions"] == 0
    assert "<collision " not in (tmp_path / "o" / "sumo" / "collisions.xml").read_text()


def test_without_the_sublane_model_nothing_changes(tmp_path: Path, build_net: Any) -> None:
    """Without ``--lateral-resolution`` the driver stays centred on lane 1
    (no sublane move) and the car drives by."""
    run, _, seen = _run(_road(tmp_path / "net", build_net), tmp_path / "o", sublane=False)
    assert not run.sublane.active
    assert seen[-1][1] > 160.0
