"""Finding and checking a SUMO scenario before SUMO is started.

A scenario is either a folder of ``sumo_scenarios/`` (by name or path), any
folder holding a ``scenario.toml`` or exactly one ``.sumocfg``, or a
``.sumocfg`` file a user brings. ``scenario.toml`` is optional: a user's own
network and demand work without it. Every problem found here raises
:class:`ScenarioError` with one line that names the file and what is wrong.
"""

from __future__ import annotations

import tomllib
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from blendtrack import BlendtrackError

#: The repository's scenario folder (present in a source checkout).
SCENARIO_ROOT = Path(__file__).resolve().parents[3] / "sumo_scenarios"


class ScenarioError(BlendtrackError, ValueError):
    """A scenario that cannot be run (missing, malformed, rejected by SUMO)."""


@dataclass
class Scenario:
    name: str
    folder: Path
    sumocfg: Path
    net_file: Path
    route_files: list[Path]
    #: Contents of scenario.toml, empty when there is none.
    meta: dict[str, Any] = field(default_factory=dict)
    step_length_s: float = 1.0
    end_s: float | None = None

    @property
    def controlled_type(self) -> str | None:
        value = self.meta.get("controlled_type")
        return str(value) if value is not None else None

    @property
    def comfort_lateral_accel_mps2(self) -> float:
        return float(self.meta.get("comfort_lateral_accel_mps2", 2.0))

    @property
    def default_end_s(self) -> float | None:
        value = self.meta.get("default_end_s")
        return float(value) if value is not None else self.end_s


def available_scenarios() -> list[str]:
    """Names of the scenario folders shipped in ``sumo_scenarios/``."""
    if not SCENARIO_ROOT.is_dir():
        return []
    return sorted(p.name for p in SCENARIO_ROOT.iterdir() if (p / "scenario.toml").is_file())


def _option(root: ET.Element, section: str, name: str) -> str | None:
    for sec in root:
        if sec.tag == section or section == "*":
            for opt in sec:
                if opt.tag == name:
                    return opt.get("value")
    # SUMO also accepts options directly under <configuration>.
    for opt in root:
        if opt.tag == name:
            return opt.get("value")
    return None


def resolve_scenario(spec: str | Path) -> Scenario:
    """Turns a scenario name, folder or ``.sumocfg`` path into a checked :class:`Scenario`."""
    path = Path(spec)
    if not path.exists() and SCENARIO_ROOT.joinpath(str(spec)).exists():
        path = SCENARIO_ROOT / str(spec)
    if not path.exists():
        known = ", ".join(available_scenarios()) or "none found"
        raise ScenarioError(f"scenario {str(spec)!r} not found (not a path; shipped scenarios: {known})")
    meta: dict[str, Any] = {}
    if path.is_dir():
        folder = path
        toml_file = folder / "scenario.toml"
        if toml_file.is_file():
            try:
                meta = tomllib.loads(toml_file.read_text())
            except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
                raise ScenarioError(f"{toml_file}: malformed TOML: {e}") from None
            if "sumocfg" not in meta:
                raise ScenarioError(f"{toml_file}: missing key 'sumocfg' (the SUMO configuration to run)")
            sumocfg = folder / str(meta["sumocfg"])
            if not sumocfg.is_file():
                raise ScenarioError(f"{toml_file}: sumocfg {meta['sumocfg']!r} does not exist in {folder}")
        else:
            cfgs = sorted(folder.glob("*.sumocfg"))
            if len(cfgs) != 1:
                what = "no .sumocfg" if not cfgs else f"{len(cfgs)} .sumocfg files ({', '.join(c.name for c in cfgs)})"
                raise ScenarioError(f"{folder}: {what} and no scenario.toml saying which to run")
            sumocfg = cfgs[0]
    else:
        if path.suffix != ".sumocfg":
            raise ScenarioError(f"{path}: expected a scenario folder or a .sumocfg file")
        sumocfg = path
        folder = path.parent
    try:
        root = ET.parse(sumocfg).getroot()
    except ET.ParseError as e:
        raise ScenarioError(f"{sumocfg}: malformed XML: {e}") from None
    net = _option(root, "input", "net-file")
    if not net:
        raise ScenarioError(f"{sumocfg}: no <net-file> in <input>")
    net_file = (sumocfg.parent / net).resolve()
    if not net_file.is_file():
        raise ScenarioError(f"{sumocfg}: net-file {net!r} does not exist")
    routes = _option(root, "input", "route-files") or ""
    route_files = []
    for r in (x.strip() for x in routes.split(",") if x.strip()):
        rf = (sumocfg.parent / r).resolve()
        if not rf.is_file():
            raise ScenarioError(f"{sumocfg}: route file {r!r} does not exist")
        route_files.append(rf)
    step = _option(root, "time", "step-length")
    end = _option(root, "time", "end")
    try:
        step_length = float(step) if step else 1.0
        end_s = float(end) if end else None
    except ValueError:
        raise ScenarioError(f"{sumocfg}: step-length or end is not a number") from None
    if not step_length > 0:
        raise ScenarioError(f"{sumocfg}: step-length must be > 0, got {step_length}")
    return Scenario(
        name=str(meta.get("name", folder.name if path.is_dir() else sumocfg.stem)),
        folder=folder,
        sumocfg=sumocfg.resolve(),
        net_file=net_file,
        route_files=route_files,
        meta=meta,
        step_length_s=step_length,
        end_s=end_s,
    )
