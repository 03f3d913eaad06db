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

from blendtrack.sumo.connection import sumo_command
from blendtrack.sumo.options import RunOptions
from blendtrack.sumo.scenario import Scenario, ScenarioError
from blendtrack.sumo.selection import CONTROLLED_PARAM, RAIL_BOUND, unit_hash
from blendtrack.sumo.sumocfg import read_xml

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



def vtype_params(scenario: Scenario) -> dict[str, dict[str, str]]:
    """vType id -> its params, wherever the scenario defines them (route and
    additional files, gzipped or not): the runner's own reading."""
    return scenario.vtypes().types


def with_model(scenario: Scenario, model: str, tmp: Path) -> Scenario:
    """The scenario with every vType's carFollowModel set to ``model``,
    wherever the vType is defined (route or additional file): rewritten
    copies of those files and a configuration naming them in ``tmp``."""
    cf = MODELS[model]
    if cf is None:
        return scenario
    tmp.mkdir(parents=True, exist_ok=True)

    def rewritten(files: Sequence[Path], kind: str) -> list[Path]:
        out = []
        for i, f in enumerate(files):
            root = read_xml(f)
            types = list(root.iter("vType"))
            if not types:
                out.append(f)
                continue
            for vt in types:
                vt.set("carFollowModel", cf)  # every other attribute kept
            dst = tmp / f"{kind}{i}_{f.name.removesuffix('.gz')}"
            ET.ElementTree(root).write(dst, encoding="UTF-8", xml_declaration=True)
            out.append(dst.absolute())
        return out

    routes = rewritten(scenario.route_files, "routes")
    additional = rewritten(scenario.additional_files, "additional")
    cfg = scenario.config().write_copy(
        tmp / "model.sumocfg", {"route-files": routes, "additional-files": additional}
    )
    return dataclasses.replace(scenario, sumocfg=cfg, route_files=routes, additional_files=additional)


def selector(opts: CompareOptions, scenario: Scenario, seed: int) -> Callable[[str, str], bool]:
    """The treatment's selection rule (RunOptions / Selection.is_selected) as a function of (id, vType)."""
    rule = _rule(opts, scenario, seed)
    vtypes = scenario.vtypes()
    rail = {t for t in [*vtypes.types, "DEFAULT_RAILTYPE"] if vtypes.vclass(t) in RAIL_BOUND}
    if not rail:
        return rule
    # Never a vehicle on rails (Selection.is_selected).
    return lambda vid, vtype: vtype not in rail and rule(vid, vtype)


def _rule(opts: CompareOptions, scenario: Scenario, seed: int) -> Callable[[str, str], bool]:
    if opts.controlled_fraction is not None:
        frac = opts.controlled_fraction
        return lambda vid, vtype: unit_hash(seed, vid) < frac
    if opts.controlled_type is not None:
        want = set(scenario.vtypes().members(opts.controlled_type) or [opts.controlled_type])
        return lambda vid, vtype: vtype in want
    marked = {t for t, params in vtype_params(scenario).items()
              if params.get(CONTROLLED_PARAM, "").strip().lower() in ("1", "true", "yes")}
    return lambda vid, vtype: vtype in marked


def output_args(sd: Path) -> list[str]:
    """SUMO outputs written by both runs (the runner's plus unfinished trips
    and statistics); also what a treatment run made outside ``compare``
    passes with ``blendtrack sumo run --sumo-args`` to have them."""
    return ["--tripinfo-output.write-unfinished", "true", "--statistic-output", str(sd / "statistics.xml")]


def run_baseline(scenario: Scenario, seed: int, end_s: float | None, out: Path, sumo_args: Sequence[str] = (),
                 devices: bool = True) -> None:
    """Plain SUMO with the options the runner uses (SumoConnection.command
    with fcd and ssm, unless ``devices`` is False), the scenario's run
    configuration (its outputs under ``out/sumo``) and the user's extra SUMO
    options, which replace ours."""
    sd = out / "sumo"
    sd.mkdir(parents=True, exist_ok=True)
    cmd = baseline_command(scenario, seed, end_s, sd, sumo_args, devices)
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        lines = [ln.strip() for ln in (proc.stderr + proc.stdout).splitlines() if ln.strip()]
        errors = [ln for ln in lines if "Error" in ln] or lines or [f"exit code {proc.returncode}"]
        raise ScenarioError(f"{scenario.sumocfg}: SUMO refused to start: {errors[0]}")


def baseline_command(scenario: Scenario, seed: int, end_s: float | None, sd: Path, sumo_args: Sequence[str] = (),
                     devices: bool = True) -> list[str]:
    """The baseline's ``sumo`` command line, its outputs under ``sd``: the
    runner's (``connection.sumo_command``) with the FCD and SSM device
    (``devices``; tripinfo, collisions and statistics either way)."""
    return sumo_command(scenario, sd, seed, end_s, sd, fcd=devices, ssm=devices, ours=output_args(sd), sumo_args=sumo_args)


def run_treatment(scenario: Scenario, options: RunOptions, out: Path) -> Any:
    from blendtrack.sumo import run_scenario

    sd = out / "sumo"
    sd.mkdir(parents=True, exist_ok=True)
    # The controlled vehicles' rows are in out/vehicles.csv (report.vehicle_ids): no records kept.
    options = dataclasses.replace(options, fcd=True, ssm=True, keep_records=False,
                                  sumo_args=(*options.sumo_args, *output_args(sd)))
    return run_scenario(scenario, options, out)
