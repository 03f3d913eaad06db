"""The SUMO plugin: blendtrack controllers drive selected vehicles of a SUMO simulation.

- :func:`resolve_scenario` finds and checks a scenario (a folder of
  ``sumo_scenarios/``, any folder with a ``scenario.toml`` or one
  ``.sumocfg``, or a ``.sumocfg`` file).
- :class:`SumoRun` runs it with the selected vehicles under blendtrack
  control (libsumo in-process, or TraCI for sumo-gui).
- :func:`run_scenario` does both and writes the outputs
  (``vehicles.csv``, a row per vehicle as it finishes, ``summary.json``,
  plots, SUMO's own outputs in ``sumo/``); the folder holds an
  ``INCOMPLETE`` marker from the start until they are all written, so a
  killed run's folder says so (and keeps the rows of the vehicles that
  finished).
"""

from __future__ import annotations

import os
from pathlib import Path

from blendtrack import ControllerConfig
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
    return ControllerConfig.keys_in_file(file)


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
    from blendtrack.sumo.preflight import check_controlled_ids, check_selection, reconcile_sumo_args

    if not isinstance(out, (str, os.PathLike)):
        raise TypeError(f"run_scenario: out must be a folder path (str or os.PathLike), not {type(out).__name__}")
    out = Path(out)
    options = reconcile_sumo_args(options)
    check_controlled_ids(scenario, options)
    check_selection(scenario, options)
    uses_libsumo = options.backend == "libsumo" and not options.gui
    if uses_libsumo and libsumo_started():
        return _run_in_child(scenario, options, out)
    return _run_here(scenario, options, out)


#: Written into the output folder when a run starts and removed when all its
#: outputs are written: a folder holding it describes a run that did not
#: finish (killed, or failed), whatever else it holds.
INCOMPLETE = "INCOMPLETE"
#: What a run writes (removed at the start, so no earlier run's file is left
#: beside a new run's partial outputs).
OUTPUTS = (
    "summary.json", "vehicles.csv", "collisions.csv", "red_lights.csv", "trace.csv", "alpha.png", "lateral_error_hist.png", "speed_vs_curvature.png", "trajectory.png",
    "sumo/tripinfo.xml", "sumo/collisions.xml", "sumo/sumo.log", "sumo/fcd.xml", "sumo/ssm.xml",
)


def _is_sumo_error(e: BaseException) -> bool:
    """An exception of libsumo or TraCI (SUMO refused or lost the simulation)."""
    return any(c.__module__.split(".")[0] in ("libsumo", "traci") for c in type(e).__mro__)


def _run_here(scenario: Scenario, options: RunOptions, out: Path) -> RunResult:
    from blendtrack.sumo import report

    out.mkdir(parents=True, exist_ok=True)
    marker = out / INCOMPLETE
    marker.write_text(
        f"blendtrack sumo run of {scenario.sumocfg} started here and has not finished (still running, killed or "
        "failed): the other files in this folder are partial.\n"
    )
    for name in OUTPUTS:
        (out / name).unlink(missing_ok=True)
    run = SumoRun(scenario, options, out)
    if options.trace:
        run.trace.stream(out / "trace.csv")
    try:
        with report.VehicleWriter(out / "vehicles.csv") as rows:
            run.vehicles.finished.append(rows.write)
            result = run.run()
    except Exception as e:
        if not _is_sumo_error(e):
            raise
        first = (str(e).strip() or type(e).__name__).splitlines()[0]
        raise ScenarioError(
            f"{scenario.sumocfg}: SUMO stopped the run: {first} (see {out / 'sumo' / 'sumo.log'})"
        ) from None
    finally:
        run.trace.close()
    _count_collisions(result, out, run.remote_found)
    run.incidents.write_csv(out / "red_lights.csv")
    if options.trace:
        report.plot_alpha(out / "trace.csv", out / "alpha.png")
    report.plot_run(result, out, scenario.comfort_lateral_accel_mps2)
    report.write_json(result.summary, out / "summary.json")
    marker.unlink()
    return result


def _count_collisions(result: RunResult, out: Path, remote: list[tuple[float, str, str, str, str, str]]) -> None:
    """Adds SUMO's own collision record, and the lane collisions SUMO skips
    for vehicles moved by (x, y) under ``collision.action teleport``
    (``remote``, found by blendtrack: :mod:`blendtrack.sumo.collisions`), to
    the summary (``collisions_all``, ``collisions_with_controlled``: every
    collision of the run, counted the same under any ``collision.action``;
    a pair SUMO reports again after blendtrack found it is listed but not
    counted again: ``outputs.mark_repeats``) and writes ``collisions.csv``,
    in order of time."""
    import csv

    from blendtrack.sumo.collisions import REMOTE_WINDOW_S
    from blendtrack.sumo.outputs import REPEAT, COLLISION_COLUMNS, mark_repeats, read_collisions, remote_collision_rows

    ids = _Ids(out / "vehicles.csv")
    rows = read_collisions(out / "sumo" / "collisions.xml", ids) + remote_collision_rows(remote, ids)
    # (Stable: at equal times SUMO's rows come first.)
    rows.sort(key=lambda r: float(r["time_s"]))  # type: ignore[arg-type]
    rows = mark_repeats(rows, REMOTE_WINDOW_S + 1.0)
    counted = [r for r in rows if r["detected_by"] != REPEAT]
    result.summary["collisions_all"] = len(counted)
    result.summary["collisions_with_controlled"] = sum(int(r["controlled_involved"]) for r in counted)
    with open(out / "collisions.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=COLLISION_COLUMNS)
        w.writeheader()
        w.writerows(rows)


class _Ids:
    """The controlled vehicles' ids, read from ``vehicles.csv`` when first asked
    (most runs have no collision to ask about)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._ids: set[str] | None = None

    def __contains__(self, vid: object) -> bool:
        if self._ids is None:
            from blendtrack.sumo.report import vehicle_ids

            self._ids = vehicle_ids(self.path)
        return vid in self._ids


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
