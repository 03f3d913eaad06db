"""``blendtrack compare``: blendtrack against SUMO's own drivers, paired by vehicle.

For each seed the scenario runs twice with the same demand, seed, end time
and step length:

- *baseline*: plain SUMO (a ``sumo`` subprocess), every vehicle on SUMO's
  car-following model; the vehicles the treatment would control are found by
  the same rule (seeded hash of the id, a vType, or the vType parameter
  ``blendtrack.controlled``);
- *treatment*: :func:`blendtrack.sumo.run_scenario` with those vehicles
  driven by blendtrack.

Both write tripinfo (with emissions, unfinished trips included), FCD, SSM and
SUMO's statistics. Every per-vehicle metric that both runs have is computed
the same way for both, from SUMO's own outputs (FCD, tripinfo), so the pairs
compare like with like; only the lateral error comes from blendtrack
(``vehicles.csv``): SUMO's drivers sit on the lane centreline, so theirs is 0
by construction.

Everything is written into ``DIR/.partial-*`` and moved into place at the
end, ``report.md`` last: an interrupted compare leaves no complete-looking
report.
"""

from __future__ import annotations

import dataclasses
import os
import shutil
import sys
import tempfile
from pathlib import Path
from typing import Any

from blendtrack.sumo.compare.metrics import (
    NETWORK_METRICS,
    VEHICLE_METRICS,
    RunData,
    SeedResult,
    load_run,
    pair,
    summarise,
    vehicle_metrics,
)
from blendtrack.sumo.compare.report import write_outputs
from blendtrack.sumo.compare.runs import MODELS, CompareOptions, vtype_params, run_baseline, run_treatment, selector, with_model
from blendtrack.sumo.scenario import Scenario, ScenarioError

__all__ = [
    "MODELS",
    "NETWORK_METRICS",
    "VEHICLE_METRICS",
    "CompareOptions",
    "RunData",
    "SeedResult",
    "compare",
    "load_run",
    "pair",
    "run_baseline",
    "run_treatment",
    "selector",
    "summarise",
    "vehicle_metrics",
    "with_model",
    "write_outputs",
]


def compare(scenario: Scenario, opts: CompareOptions, out: Path) -> list[dict[str, Any]]:
    """Runs every seed's baseline and treatment and writes the report into ``out``."""
    from tqdm import tqdm

    from blendtrack.sumo.preflight import check_selection, reconcile_sumo_args
    from blendtrack.sumo.report import vehicle_ids

    # The same pre-run checks as sumo run (one intake for both).
    opts = dataclasses.replace(opts, run=reconcile_sumo_args(opts.run))
    if opts.end_s is None and opts.run.end_s is not None:  # --end given in --sumo-args
        opts = dataclasses.replace(opts, end_s=opts.run.end_s)
    check_selection(scenario, dataclasses.replace(opts.run, controlled_fraction=opts.controlled_fraction,
                                                  controlled_type=opts.controlled_type))
    # SUMO resolves relative output paths against the .sumocfg's folder.
    out = out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    # A report left from an earlier compare would look like this one's if we are interrupted.
    for name in ("report.md", "report.html", "comparison.csv", "network.csv"):
        (out / name).unlink(missing_ok=True)
    work = Path(tempfile.mkdtemp(prefix=".partial-", dir=out))
    try:
        end_s = opts.end_s if opts.end_s is not None else scenario.default_end_s
        sc = with_model(scenario, opts.baseline, work / "model")
        dt = sc.step_length_s
        results = []
        with tqdm(total=2 * opts.seeds, desc="blendtrack compare", unit="run", file=sys.stderr, disable=not opts.progress or None) as bar:
            for seed in range(opts.seeds):
                rd = work / "runs" / f"seed{seed}"
                bar.set_postfix_str(f"seed {seed} baseline")
                run_baseline(sc, seed, end_s, rd / "baseline", opts.run.sumo_args)
                bar.update()
                bar.set_postfix_str(f"seed {seed} treatment")
                ropt = dataclasses.replace(opts.run, controlled_fraction=opts.controlled_fraction,
                                           controlled_type=opts.controlled_type, seed=seed, end_s=end_s, progress=False)
                run_treatment(sc, ropt, rd / "treatment")
                bar.update()
                tctl = vehicle_ids(rd / "treatment" / "vehicles.csv")
                base_run = load_run(rd / "baseline", selector(opts, sc, seed))
                treat_run = load_run(rd / "treatment", lambda vid, vtype: vid in tctl)
                results.append(pair(seed, base_run, treat_run, dt, scenario.comfort_lateral_accel_mps2))
        table = write_outputs(results, work, sc, opts, dt, end_s)
        # Into place: runs and data first, report.md last.
        if (out / "runs").exists():
            shutil.rmtree(out / "runs")
        os.replace(work / "runs", out / "runs")
        names = [p.name for p in work.iterdir() if p.is_file() and p.name != "report.md"]
        for name in names:
            os.replace(work / name, out / name)
        os.replace(work / "report.md", out / "report.md")
        return table
    finally:
        shutil.rmtree(work, ignore_errors=True)
