"""The two runs of a pair: the baseline (plain SUMO, a ``sumo`` subprocess,
optionally with another car-following model) and the treatment
(:func:`blendtrack.sumo.run_scenario`), and which vehicles the treatment
controls."""

from __future__ import annotations

import dataclasses
import subprocess
import xml.etree.ElementTree as ET
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from blendtrack.sumo.connection import sumo_binary
from blendtrack.sumo.options import RunOptions
from blendtrack.sumo.scenario import Scenario, ScenarioError
from blendtrack.sumo.selection import CONTROLLED_PARAM, unit_hash

#: Car-following models a baseline can use ("krauss" = as the scenario says).
MODELS = {"krauss": None, "idm": "IDM", "eidm": "EIDM", "acc": "ACC"}


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



def vtype_params(route_files: Sequence[Path]) -> dict[str, dict[str, str]]:
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
    marked = {t for t, params in vtype_params(scenario.route_files).items()
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
