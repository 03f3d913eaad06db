"""Pre-run checks: a run's options against the scenario, before SUMO starts.

- :func:`declared_ids`: the vehicle, trip and flow ids the scenario's route
  files declare (read statically, without SUMO).
- :func:`check_controlled_ids`: ``--controlled-ids`` against those ids: an
  id the scenario never declares is named in a warning, and a selection of
  none of its vehicles is an error naming some that exist (it would run
  with 0 controlled vehicles and look like a success).
- :func:`check_selection`: a ``--controlled-type`` (a vType or a
  vTypeDistribution, which selects its members) that no vehicle of the
  scenario has, or no selector at all in a scenario with no vType marked
  ``blendtrack.controlled``, is an error naming what exists: the run would
  control nobody and look like a success.
- :func:`reconcile_sumo_args`: ``--sumo-args`` options that blendtrack also
  sets. ``--end`` given there wins (the run loop stops there too, not only
  SUMO); given both ways with different values, or ``--seed`` (which also
  seeds blendtrack's vehicle selection), it is refused.
"""

from __future__ import annotations

import dataclasses
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from blendtrack.sumo.scenario import Scenario, ScenarioError, VTypes
from blendtrack.sumo.selection import CONTROLLED_PARAM, RAIL_BOUND
from blendtrack.sumo.sumocfg import iter_xml, sumo_seconds

if TYPE_CHECKING:
    from blendtrack.sumo.runner import RunOptions

#: SUMO options that add demand: with one of them in --sumo-args the route
#: files no longer list every vehicle, so ids are not checked.
_DEMAND_OPTIONS = ("route-files", "r", "additional-files", "a")


_DEMAND_TAGS = {"vehicle", "trip", "flow"}


def _demand(route_files: Sequence[Path]) -> list[ET.Element] | None:
    """The vehicle, trip and flow elements of ``route_files`` (gzipped or
    not); None if one cannot be read (then nothing can be said)."""
    try:
        return [el for file in route_files for el in iter_xml(file, _DEMAND_TAGS)]
    except ScenarioError:
        return None


def declared_ids(route_files: Sequence[Path]) -> tuple[set[str], set[str]] | None:
    """(vehicle and trip ids, flow ids) declared in ``route_files``; None if
    one cannot be read (then nothing can be said about ids)."""
    demand = _demand(route_files)
    if demand is None:
        return None
    vehicles = {el.get("id", "") for el in demand if el.tag in ("vehicle", "trip") and el.get("id") is not None}
    flows = {el.get("id", "") for el in demand if el.tag == "flow" and el.get("id") is not None}
    return vehicles, flows


def check_selection(scenario: Scenario, options: RunOptions) -> None:
    """Raises :class:`ScenarioError` when the selection can match no vehicle
    of the scenario (see the module docs); says nothing where the route
    files cannot tell (demand added through ``--sumo-args``)."""
    o = options
    if o.controlled_ids or o.controlled_fraction is not None:
        return
    if _option_names(o.sumo_args) & set(_DEMAND_OPTIONS):
        return
    vtypes = scenario.vtypes()
    demand = _demand(scenario.route_files)
    if demand is None:
        return
    used: set[str] = set()
    for el in demand:
        used.update(vtypes.members(el.get("type", "DEFAULT_VEHTYPE")) or [el.get("type", "DEFAULT_VEHTYPE")])
    if o.controlled_type is not None:
        members = vtypes.members(o.controlled_type)
        if members is None:
            raise ScenarioError(
                f"--controlled-type {o.controlled_type!r}: no such vType or vTypeDistribution in "
                f"{scenario.sumocfg.name} (known: {', '.join(vtypes.known())})"
            )
        if not used & set(members):
            raise ScenarioError(
                f"--controlled-type {o.controlled_type!r}: no vehicle of {scenario.name} is of that type "
                f"(its vehicles' types: {', '.join(sorted(used)) or 'none'})"
            )
        _not_all_rail_bound(vtypes, used & set(members), f"--controlled-type {o.controlled_type!r}")
        return
    marked = {t for t, params in vtypes.types.items() if params.get(CONTROLLED_PARAM, "").strip().lower() in ("1", "true", "yes")}
    if not marked & used:
        raise ScenarioError(
            f"{scenario.name}: nothing selects a vehicle to control: no vType of its vehicles carries "
            f"<param key=\"{CONTROLLED_PARAM}\" value=\"true\"/>; choose with --controlled-fraction P, "
            f"--controlled-type T or --controlled-ids (its vehicles' types: {', '.join(sorted(used)) or 'none'})"
        )
    _not_all_rail_bound(vtypes, marked & used, f"{scenario.name}: {CONTROLLED_PARAM}")


def _not_all_rail_bound(vtypes: VTypes, types: set[str], what: str) -> None:
    """Raises :class:`ScenarioError` when every one of ``types`` (the
    selected vTypes that have vehicles) runs on rails: the run would control
    nothing (``selection.RAIL_BOUND``)."""
    if types and all(vtypes.vclass(t) in RAIL_BOUND for t in types):
        classes = ", ".join(f"{t} ({vtypes.vclass(t)})" for t in sorted(types))
        raise ScenarioError(
            f"{what}: every vehicle it selects runs on rails ({classes}): blendtrack steers road "
            f"vehicles along their lanes, and a rail vehicle has no steering to command; it stays SUMO's. "
            f"Select road vehicles instead"
        )


def _option_names(args: Sequence[str]) -> set[str]:
    return {a.split("=", 1)[0].lstrip("-") for a in args if a.startswith("-") and len(a) > 1 and not a[1].isdigit()}


def check_controlled_ids(scenario: Scenario, options: RunOptions) -> None:
    """Warns naming the ``controlled_ids`` the scenario does not declare;
    raises :class:`ScenarioError` when it declares none of them."""
    ids = options.controlled_ids
    if not ids or _option_names(options.sumo_args) & set(_DEMAND_OPTIONS):
        return
    declared = declared_ids(scenario.route_files)
    if declared is None:
        return
    vehicles, flows = declared

    def known(vid: str) -> bool:
        head, _, tail = vid.rpartition(".")
        return vid in vehicles or (head in flows and tail.isdigit())

    unknown = [v for v in ids if not known(v)]
    if len(unknown) == len(ids):
        some = sorted(vehicles)[:8] + [f"{f}.N" for f in sorted(flows)[:4]]
        raise ScenarioError(
            f"{scenario.name}: none of the controlled ids ({', '.join(ids[:8])}) is a vehicle of the scenario "
            f"(it declares e.g. {', '.join(some) or 'no vehicles'})"
        )
    if unknown:
        warnings.warn(
            f"{scenario.name}: controlled ids not in the scenario, ignored: {', '.join(unknown)}",
            UserWarning,
            stacklevel=3,
        )


def _take_option(args: list[str], names: tuple[str, ...]) -> tuple[list[str], str | None]:
    """``args`` without the option ``names`` (``--end 5`` or ``--end=5``), and its value."""
    kept: list[str] = []
    value: str | None = None
    i = 0
    while i < len(args):
        a = args[i]
        name, eq, inline = a.partition("=")
        if a.startswith("-") and name.lstrip("-") in names and (name.startswith("--") or len(name) == 2):
            if eq:
                value = inline
                i += 1
            else:
                value = args[i + 1] if i + 1 < len(args) else ""
                i += 2
            continue
        kept.append(a)
        i += 1
    return kept, value


def reconcile_sumo_args(options: RunOptions) -> RunOptions:
    """``options`` with an ``--end`` of ``sumo_args`` moved to ``end_s``;
    raises :class:`ScenarioError` for a conflicting end or a ``--seed`` there."""
    args = list(options.sumo_args)
    if not args:
        return options
    _, seed = _take_option(args, ("seed",))
    if seed is not None:
        raise ScenarioError(
            f"--sumo-args: give the seed as blendtrack's own seed (--seed N), not to SUMO ({seed!r}): "
            "it also seeds the choice of controlled vehicles"
        )
    kept, end = _take_option(args, ("end", "e"))
    if end is None:
        return options
    try:
        end_s = sumo_seconds(end)
    except ValueError:
        raise ScenarioError(f"--sumo-args: --end {end!r} is not a time (seconds, H:M:S or D:H:M:S)") from None
    if not end_s > 0 or end_s == float("inf"):
        raise ScenarioError(f"--sumo-args: --end must be finite and > 0, got {end!r}")
    if options.end_s is not None and options.end_s != end_s:
        raise ScenarioError(
            f"the end time is given twice, {options.end_s:g} s (--end) and {end_s:g} s (--sumo-args): give it once"
        )
    return dataclasses.replace(options, end_s=end_s, sumo_args=tuple(kept))
