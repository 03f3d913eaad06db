"""The SUMO plugin: blendtrack controllers drive selected vehicles of a SUMO simulation.

- :func:`resolve_scenario` finds and checks a scenario (a folder of
  ``sumo_scenarios/``, any folder with a ``scenario.toml`` or one
  ``.sumocfg``, or a ``.sumocfg`` file).
- :class:`SumoRun` runs it with the selected vehicles under blendtrack
  control (libsumo in-process, or TraCI for sumo-gui).
- :func:`run_scenario` does both and writes the outputs
  (``vehicles.csv``, ``summary.json``, plots, SUMO's own outputs in ``sumo/``).
"""

from __future__ import annotations

import os
import tomllib
from pathlib import Path
from typing import Any

from blendtrack.sumo.runner import RunOptions, RunResult, SumoRun
from blendtrack.sumo.scenario import Scenario, ScenarioError, available_scenarios, resolve_scenario

__all__ = [
    "RunOptions",
    "RunResult",
    "Scenario",
    "ScenarioError",
    "SumoRun",
    "available_scenarios",
    "config_keys",
    "resolve_scenario",
    "run_scenario",
]


def config_keys(file: str | Path) -> set[str]:
    """Keys set in the ``[controller]`` table of a config file (to tell a
    user's explicit ``path_width_m`` or ``preferred_speed`` from the defaults)."""
    data: dict[str, Any] = tomllib.loads(Path(file).read_text())
    table = data.get("controller", {})
    return set(table) if isinstance(table, dict) else set()


def run_scenario(scenario: Scenario, options: RunOptions, out: str | os.PathLike[str]) -> RunResult:
    """Runs ``scenario`` and writes ``out/vehicles.csv``, ``out/summary.json``,
    the plots, the optional trace, and SUMO's outputs under ``out/sumo/``
    (``out``: a folder, a ``str`` or a path; created if missing).

    libsumo allows one simulation per process reliably (see ``SumoConnection.start``):
    when this process has run one already, the run happens in a fresh child
    process (spawned: a script that calls this more than once needs an
    ``if __name__ == "__main__":`` guard) and its result comes back here; a
    crash there is a :class:`ScenarioError`, not a dead interpreter. Options
    and results are pickled across (ControllerConfig and VehicleParams
    pickle through their TOML).
    """
    from blendtrack.sumo.connection import libsumo_started

    if not isinstance(out, (str, os.PathLike)):
        raise TypeError(f"run_scenario: out must be a folder path (str or os.PathLike), not {type(out).__name__}")
    out = Path(out)
    uses_libsumo = options.backend == "libsumo" and not options.gui
    if uses_libsumo and libsumo_started():
        return _run_in_child(scenario, options, out)
    return _run_here(scenario, options, out)


def _run_here(scenario: Scenario, options: RunOptions, out: Path) -> RunResult:
    from blendtrack.sumo import report

    out.mkdir(parents=True, exist_ok=True)
    run = SumoRun(scenario, options, out)
    result = run.run()
    report.write_vehicles_csv(result.records, out / "vehicles.csv")
    if options.trace:
        run.write_trace(out / "trace.csv")
    report.plot_run(result, out, scenario.comfort_lateral_accel_mps2)
    report.write_json(result.summary, out / "summary.json")
    return result


def _run_in_child(scenario: Scenario, options: RunOptions, out: Path) -> RunResult:
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor
    from concurrent.futures.process import BrokenProcessPool

    with ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn")) as pool:
        try:
            return pool.submit(_run_here, scenario, options, out).result()
        except BrokenProcessPool:
            raise ScenarioError(
                f"{scenario.sumocfg}: the process running SUMO died: SUMO crashed, or a script calling"
                " run_scenario twice lacks an `if __name__ == \"__main__\":` guard (the second run"
                " starts a fresh Python process, which imports the script)"
            ) from None
