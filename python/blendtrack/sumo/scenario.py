"""Finding and checking a SUMO scenario before SUMO is started.

A scenario is either a folder of ``sumo_scenarios/`` (by name or path), any
folder holding a ``scenario.toml`` or exactly one SUMO configuration, or a
configuration file a user brings, whatever its name (``.sumocfg``, ``.cfg``,
``.xml``: a configuration is known by its root element). Inputs may be
gzipped. ``scenario.toml`` is optional: a user's own network and demand work
without it. Every problem found here raises :class:`ScenarioError` with one
line that names the file and what is wrong.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from blendtrack.sumo.sumocfg import ScenarioError, SumoConfig, is_config, iter_xml, mentions, sumo_seconds

#: The repository's scenario folder (present in a source checkout).
SCENARIO_ROOT = Path(__file__).resolve().parents[3] / "sumo_scenarios"


__all__ = ["SCENARIO_ROOT", "Scenario", "ScenarioError", "VTypes", "available_scenarios", "resolve_scenario"]

#: File name patterns a folder's configuration may have.
CONFIG_PATTERNS = ("*.sumocfg", "*.cfg", "*.xml", "*.sumocfg.gz", "*.xml.gz")


#: The vehicle classes of SUMO's default vTypes.
_DEFAULT_CLASSES = {"DEFAULT_RAILTYPE": "rail", "DEFAULT_BIKETYPE": "bicycle", "DEFAULT_TAXITYPE": "taxi",
                    "DEFAULT_PEDTYPE": "pedestrian", "DEFAULT_CONTAINERTYPE": "ignoring"}


@dataclass
class VTypes:
    """The vTypes a scenario defines (route and additional files), with
    their ``<param>`` values, and its vTypeDistributions with their members."""

    types: dict[str, dict[str, str]] = field(default_factory=dict)
    distributions: dict[str, list[str]] = field(default_factory=dict)
    #: vType -> its ``vClass`` attribute, where it has one.
    classes: dict[str, str] = field(default_factory=dict)

    def vclass(self, name: str) -> str:
        """The vehicle class of vType ``name``: its ``vClass``, SUMO's for
        its default types, else SUMO's default (passenger)."""
        return self.classes.get(name) or _DEFAULT_CLASSES.get(name, "passenger")

    def members(self, name: str) -> list[str] | None:
        """The vTypes ``name`` stands for: itself, a distribution's members,
        or ``None`` when the scenario defines no such type."""
        if name in self.distributions:
            return list(self.distributions[name])
        if name in self.types or name == "DEFAULT_VEHTYPE":
            return [name]
        return None

    def known(self) -> list[str]:
        return sorted({*self.types, *self.distributions, "DEFAULT_VEHTYPE"})


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
    additional_files: list[Path] = field(default_factory=list)

    def config(self) -> SumoConfig:
        """The scenario's SUMO configuration, parsed."""
        return SumoConfig(self.sumocfg)

    def run_config(self, out_dir: Path) -> Path:
        """Writes the configuration a run starts SUMO with into ``out_dir``
        (see :meth:`SumoConfig.write_run_config`) and returns its path."""
        return self.config().write_run_config(out_dir)

    def vtypes(self) -> VTypes:
        """The vTypes and vTypeDistributions of the route and additional
        files (gzipped or not), read once."""
        cached: VTypes | None = self.__dict__.get("_vtypes")
        if cached is not None:
            return cached
        out = VTypes()
        for file in [*self.route_files, *self.additional_files]:
            for el in iter_xml(file, {"vType", "vTypeDistribution"}):
                if el.tag == "vTypeDistribution":
                    nested = [t.get("id", "") for t in el.findall("vType")]
                    listed = (el.get("vTypes") or "").split()
                    out.distributions[el.get("id", "")] = [m for m in nested + listed if m]
                elif el.get("id"):
                    params = {p.get("key", ""): p.get("value", "") for p in el.findall("param")}
                    out.types[el.get("id", "")] = params
                    if el.get("vClass"):
                        out.classes[el.get("id", "")] = el.get("vClass", "")
        self.__dict__["_vtypes"] = out
        return out

    def declares(self, text: str) -> bool:
        """Do the route or additional files hold ``text`` anywhere (a scan,
        no parse; kept per text)? Lets a check of vType parameters skip
        parsing files that name none of them."""
        seen: dict[str, bool] = self.__dict__.setdefault("_declares", {})
        if text not in seen:
            seen[text] = any(mentions(f, text.encode()) for f in [*self.route_files, *self.additional_files])
        return seen[text]

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


def resolve_scenario(spec: str | Path) -> Scenario:
    """Turns a scenario name, folder or configuration file into a checked :class:`Scenario`."""
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
            cfgs = sorted({c for pattern in CONFIG_PATTERNS for c in folder.glob(pattern) if is_config(c)})
            if len(cfgs) != 1:
                what = "no SUMO configuration" if not cfgs else f"{len(cfgs)} SUMO configurations ({', '.join(c.name for c in cfgs)})"
                raise ScenarioError(f"{folder}: {what} and no scenario.toml saying which to run")
            sumocfg = cfgs[0]
    else:
        sumocfg = path
        folder = path.absolute().parent
    cfg = SumoConfig(sumocfg)
    nets = cfg.files("net-file")
    if not nets:
        raise ScenarioError(f"{sumocfg}: no <net-file> in <input>")
    net_file = nets[0]
    route_files = cfg.files("route-files")
    additional_files = cfg.files("additional-files")
    step = cfg.option("step-length")
    end = cfg.option("end")
    try:
        end_s = sumo_seconds(end) if end else None
    except ValueError:
        raise ScenarioError(f"{sumocfg}: end {end!r} is not a time (seconds, H:M:S or D:H:M:S)") from None
    try:
        step_length = float(step) if step else 1.0
    except ValueError:
        raise ScenarioError(f"{sumocfg}: step-length {step!r} is not a number") from None
    if not step_length > 0:
        raise ScenarioError(f"{sumocfg}: step-length must be > 0, got {step_length}")
    return Scenario(
        name=str(meta.get("name", folder.name if path.is_dir() else sumocfg.stem)),
        folder=folder,
        sumocfg=sumocfg.absolute(),
        net_file=net_file,
        route_files=route_files,
        additional_files=additional_files,
        meta=meta,
        step_length_s=step_length,
        end_s=end_s,
    )
