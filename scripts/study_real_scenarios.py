#!/usr/bin/env python3
"""Study: issue 18's acceptance, measured on SUMO scenarios nobody on this
project wrote (and on any other scenario given).

For each scenario and seed it runs plain SUMO (every vehicle SUMO's own
driver: compare's baseline, without its FCD and SSM devices) and
`blendtrack sumo run` with a share of the vehicles controlled, each in a
fresh process, `--jobs` at a time, at the scenario's own step length. Then
it pools the seeds and sets each figure against its target:

- collisions with a controlled vehicle in them (target 0);
- red-light crossings by SUMO's signal states (target 0);
- the controlled vehicles' arrivals at their own destination (a missed exit
  does not count) against the same vehicles' arrivals under plain SUMO
  (target at least 0.9);
- the background vehicles' mean time loss against plain SUMO's, over the
  vehicles in both runs' trip info, unfinished trips counted to the end
  (target within 10 %);
- the controlled vehicles' mean |lateral error| (target at most 0.1 m);

and, for the record, teleports of controlled vehicles, placement faults,
emergency brakings and missed exits. Writes OUT/study.md (the table),
OUT/per_seed.csv and OUT/study.png (the figures seed by seed), and prints
the table. A study measures; it asserts nothing. Runs already finished under
OUT are reused (delete OUT to start again); a run that fails is reported and
its seed left out, and the study then exits 1. `--sumo-args` gives SUMO
options to both runs of each seed, plain and blendtrack (e.g. SUMO's sublane
model, `--sumo-args "--lateral-resolution 0.8"`).

    .venv/bin/python scripts/study_real_scenarios.py [--seeds 3] [--first 0] [--end 600] \\
        [--fraction 0.3] [--jobs 2] [--scenario NAME_OR_CFG ...] [--out out/study_real] \\
        [--sumo-args 'SUMO OPTIONS'] [-- further options of blendtrack sumo run, e.g. --corridor lane]
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import shlex
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
REAL = ROOT.parent / "shared" / "scenarios_real"
DEFAULT_SCENARIOS = {
    "bologna_acosta": REAL / "bologna_acosta" / "run.sumocfg",
    "eccles_interchange": REAL / "eccles_interchange" / "interchangeSim.cfg",
}
#: Marks a run that finished (its outputs complete).
DONE = "DONE"

#: (key, what, target, met): issue 18's acceptance, in the table's order.
CRITERIA = (
    ("collisions_with_controlled", "collisions with a controlled vehicle", "0", lambda x: x == 0),
    ("red_light_crossings", "red-light crossings (SUMO's signal states)", "0", lambda x: x == 0),
    ("arrivals_ratio", "arrivals at own destination, of the same vehicles' under plain SUMO", ">= 0.9", lambda x: x >= 0.9),
    ("background_time_loss_change", "background vehicles' mean time loss against plain SUMO", "within +10 %", lambda x: x <= 0.10),
    ("lateral_error_mean_abs_m", "mean abs lateral error of the controlled vehicles (m)", "<= 0.1", lambda x: x <= 0.1),
)
#: Counted for the record, no target.
RECORD = (
    ("teleports_controlled", "teleports of controlled vehicles"),
    ("placement_faults", "placement faults"),
    ("emergency_brakings", "emergency brakings by controlled vehicles"),
    ("missed_exits", "missed exits (controlled vehicles rerouted)"),
)


@dataclass
class Pooled:
    """One scenario's figures pooled over its seeds (``pool``)."""

    seeds: list[int] = field(default_factory=list)
    counts: dict[str, int] = field(default_factory=dict)
    controlled: int = 0
    arrived: int = 0
    arrived_plain: int = 0
    background: int = 0
    time_loss: float = 0.0
    time_loss_plain: float = 0.0
    lateral_sum: float = 0.0
    lateral_n: int = 0

    def figures(self) -> dict[str, float]:
        nan = math.nan
        return {
            **{k: float(v) for k, v in self.counts.items()},
            "arrivals_ratio": self.arrived / self.arrived_plain if self.arrived_plain else nan,
            "background_time_loss_change": self.time_loss / self.time_loss_plain - 1.0 if self.time_loss_plain else nan,
            "lateral_error_mean_abs_m": self.lateral_sum / self.lateral_n if self.lateral_n else nan,
        }


def seed_figures(seed_dir: Path) -> dict[str, float]:
    """One seed's raw figures from its two runs under ``seed_dir``
    (``baseline/``, ``treatment/``): the summary's counts, and the sums
    ``pool`` adds up."""
    from blendtrack.sumo.compare.metrics import read_vehicles
    from blendtrack.sumo.outputs import read_tripinfo

    treat = seed_dir / "treatment"
    summary = json.loads((treat / "summary.json").read_text())
    lat_err, missed = read_vehicles(treat / "vehicles.csv", "lateral_error_mean_abs_m")
    ctl = set(lat_err)
    tt = read_tripinfo(treat / "sumo" / "tripinfo.xml")
    tb = read_tripinfo(seed_dir / "baseline" / "sumo" / "tripinfo.xml")
    bg = [v for v in tt if v not in ctl and v in tb]
    lat = [x for x in lat_err.values() if not math.isnan(x)]
    return {
        "collisions_with_controlled": summary["collisions_with_controlled"],
        "red_light_crossings": summary["red_light_crossings_sumo"],
        "teleports_controlled": summary["teleports_controlled"],
        "placement_faults": summary["placement_faults"],
        "emergency_brakings": summary["emergency_brakings"],
        "missed_exits": len(missed),
        "controlled": len(ctl),
        "arrived": sum(1 for v in ctl if v not in missed and tt.get(v, {}).get("arrived", 0.0) > 0),
        "arrived_plain": sum(1 for v in ctl if tb.get(v, {}).get("arrived", 0.0) > 0),
        "background": len(bg),
        "time_loss": sum(tt[v]["time_loss"] for v in bg),
        "time_loss_plain": sum(tb[v]["time_loss"] for v in bg),
        "lateral_sum": sum(lat),
        "lateral_n": len(lat),
    }


def pool(per_seed: dict[int, dict[str, float]]) -> Pooled:
    """The seeds' figures pooled: counts and arrivals summed, the background
    time loss as the mean over every background vehicle of every seed, the
    lateral error as the mean of the controlled vehicles' own means."""
    p = Pooled(seeds=sorted(per_seed))
    for seed in p.seeds:
        f = per_seed[seed]
        for key, *_ in (*CRITERIA, *RECORD):
            if key in f:
                p.counts[key] = p.counts.get(key, 0) + int(f[key])
        p.controlled += int(f["controlled"])
        p.arrived += int(f["arrived"])
        p.arrived_plain += int(f["arrived_plain"])
        p.background += int(f["background"])
        p.time_loss += f["time_loss"]
        p.time_loss_plain += f["time_loss_plain"]
        p.lateral_sum += f["lateral_sum"]
        p.lateral_n += int(f["lateral_n"])
    return p


def table(pooled: dict[str, Pooled]) -> str:
    """The study's Markdown table: each criterion's figure per scenario and
    whether it meets its target."""
    names = list(pooled)
    lines = ["| | target | " + " | ".join(names) + " |", "|---|---|" + "---|" * len(names)]

    def show(key: str, x: float) -> str:
        if math.isnan(x):
            return "n/a"
        if key == "background_time_loss_change":
            return f"{100 * x:+.1f} %"
        if key == "arrivals_ratio" or key.endswith("_m"):
            return f"{x:.3f}"
        return f"{x:.0f}"

    figs = {n: p.figures() for n, p in pooled.items()}
    for key, what, target, met in CRITERIA:
        cells = []
        for n in names:
            x = figs[n].get(key, math.nan)
            cells.append(show(key, x) + ("" if math.isnan(x) else (" (met)" if met(x) else " (**not met**)")))
        lines.append(f"| {what} | {target} | " + " | ".join(cells) + " |")
    for key, what in RECORD:
        lines.append(f"| {what} | | " + " | ".join(show(key, figs[n].get(key, math.nan)) for n in names) + " |")
    lines.append("| seeds; controlled vehicles | | " + " | ".join(
        f"{_span(p.seeds)}; {p.controlled}" for p in pooled.values()) + " |")
    return "\n".join(lines) + "\n"


def _span(seeds: list[int]) -> str:
    if not seeds:
        return "none"
    if len(seeds) == 1:
        return str(seeds[0])
    return f"{seeds[0]}-{seeds[-1]}" if seeds == list(range(seeds[0], seeds[-1] + 1)) else ",".join(map(str, seeds))


def _resolve(name: str) -> tuple[str, Path | str]:
    """A --scenario: a public scenario's name, a path, or a shipped name."""
    if name in DEFAULT_SCENARIOS:
        return name, DEFAULT_SCENARIOS[name]
    path = Path(name)
    if path.exists():
        # A configuration file by its folder's name (run.sumocfg says little).
        return (path.resolve().parent.name if path.is_file() else path.name), path.resolve()
    return name, name  # a shipped scenario's name: blendtrack resolves it


def _run(kind: str, scen: Path | str, seed: int, out: Path, args: argparse.Namespace) -> tuple[bool, str]:
    """One run in a fresh process (libsumo: one simulation a process);
    (succeeded, why not). Its outputs go under ``out``, marked DONE at the end."""
    (out / "sumo").mkdir(parents=True, exist_ok=True)
    if kind == "baseline":
        code = ("import sys\nfrom pathlib import Path\nfrom blendtrack.sumo import resolve_scenario\n"
                "from blendtrack.sumo.compare.runs import run_baseline\n"
                "import shlex\n"
                "run_baseline(resolve_scenario(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3]), Path(sys.argv[4]),\n"
                "             sumo_args=shlex.split(sys.argv[5]), devices=False)\n")
        cmd = [sys.executable, "-c", code, str(scen), str(seed), str(args.end), str(out), args.sumo_args]
    else:
        from blendtrack.sumo.compare.runs import output_args

        cmd = [sys.executable, "-m", "blendtrack.cli", "sumo", "run", str(scen), "--controlled-fraction", str(args.fraction),
               "--end", str(args.end), "--seed", str(seed), "--quiet", "--out", str(out),
               "--sumo-args", shlex.join([*output_args(out / "sumo"), *shlex.split(args.sumo_args)]), *args.extra]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        lines = [ln for ln in (proc.stderr + proc.stdout).splitlines() if ln.strip()]
        return False, (lines[-1] if lines else f"exit code {proc.returncode}")
    (out / DONE).write_text("")
    return True, ""


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seeds", type=int, default=3, help="how many seeds (default 3)")
    p.add_argument("--first", type=int, default=0, help="first seed (default 0)")
    p.add_argument("--end", type=float, default=600.0, help="simulated seconds (default 600)")
    p.add_argument("--fraction", type=float, default=0.3, help="share of the vehicles controlled (default 0.3)")
    p.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="runs at a time (default: one per core)")
    p.add_argument("--scenario", action="append", default=None,
                   help="a public scenario's name, a shipped one's, or a SUMO configuration (repeatable; default: the two public ones)")
    p.add_argument("--out", type=Path, default=ROOT / "out" / "study_real")
    p.add_argument("--sumo-args", default="", metavar="'OPTS'",
                   help="SUMO options for both runs of each seed, plain and blendtrack (e.g. '--lateral-resolution 0.8'); "
                        "runs already under --out are reused whatever they were run with")
    p.add_argument("extra", nargs="*", help="further options for blendtrack sumo run (after --)")
    args = p.parse_args(argv)
    if args.seeds < 1 or args.first < 0 or args.jobs < 1 or not args.end > 0 or not 0.0 < args.fraction <= 1.0:
        p.error("--seeds and --jobs must be at least 1, --first at least 0, --end above 0, --fraction in (0, 1]")
    if any(a == "--sumo-args" or a.startswith("--sumo-args=") for a in args.extra):
        p.error("give SUMO options as the study's own --sumo-args (before --): both runs of a seed need them")
    try:
        shlex.split(args.sumo_args)
    except ValueError as e:
        p.error(f"--sumo-args {args.sumo_args!r}: {e}")
    scenarios = dict(_resolve(n) for n in (args.scenario or list(DEFAULT_SCENARIOS)))
    from blendtrack.sumo import resolve_scenario
    from blendtrack.sumo.sumocfg import ScenarioError

    for name, scen in scenarios.items():
        if name in DEFAULT_SCENARIOS and not Path(scen).exists():
            p.error(f"{scen} not found (keep ../shared beside the repository)")
        try:
            resolve_scenario(scen)
        except ScenarioError as e:
            p.error(str(e))
    seeds = range(args.first, args.first + args.seeds)
    todo = [(name, scen, seed, kind) for name, scen in scenarios.items() for seed in seeds for kind in ("baseline", "treatment")
            if not (args.out / name / f"seed{seed}" / kind / DONE).exists()]
    failed: dict[tuple[str, int], str] = {}
    started = time.monotonic()
    with ThreadPoolExecutor(args.jobs) as pool_:
        futures = {pool_.submit(_run, kind, scen, seed, args.out / name / f"seed{seed}" / kind, args): (name, seed, kind)
                   for name, scen, seed, kind in todo}
        for k, fut in enumerate(as_completed(futures), 1):
            name, seed, kind = futures[fut]
            ok, why = fut.result()
            if not ok:
                failed[(name, seed)] = f"{kind}: {why}"
            print(f"[{k}/{len(todo)}] {name} seed {seed} {kind} {'done' if ok else 'FAILED: ' + why} "
                  f"({time.monotonic() - started:.0f} s)", flush=True)
    pooled: dict[str, Pooled] = {}
    rows: list[dict[str, Any]] = []
    for name in scenarios:
        per_seed = {}
        for seed in seeds:
            if (name, seed) in failed:
                continue
            per_seed[seed] = figs = seed_figures(args.out / name / f"seed{seed}")
            rows.append({"scenario": name, "seed": seed, **figs})
        pooled[name] = pool(per_seed)
    text = (f"{args.fraction:.0%} of the vehicles controlled, {args.end:g} s at each scenario's own step length, "
            f"pooled over the seeds; `blendtrack sumo run` options: {shlex.join(args.extra) or 'the defaults'}"
            f"{f'; SUMO options for both runs: `{args.sumo_args}`' if args.sumo_args.strip() else ''}.\n\n"
            + table(pooled))
    for (name, seed), why in sorted(failed.items()):
        text += f"\n{name} seed {seed} left out: {why}\n"
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "study.md").write_text(text)
    if rows:
        with open(args.out / "per_seed.csv", "w", newline="") as out_csv:
            w = csv.DictWriter(out_csv, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
        plot(rows, args.out / "study.png")
    print(text)
    print(f"wrote {args.out / 'study.md'}, per_seed.csv and study.png")
    return 1 if failed else 0


def plot(rows: list[dict[str, Any]], file: Path) -> None:
    """Seed by seed, per scenario: collisions with a controlled vehicle,
    the arrivals ratio and the background time loss change, with their
    targets."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
    names = sorted({str(r["scenario"]) for r in rows})
    # (key of Pooled.figures, title, scale, target): each seed's own figures.
    panels = (
        ("collisions_with_controlled", "collisions with a controlled vehicle", 1.0, 0.0),
        ("arrivals_ratio", "arrivals / plain SUMO's", 1.0, 0.9),
        ("background_time_loss_change", "background time loss change (%)", 100.0, 10.0),
    )
    for ax, (key, title, scale, target) in zip(axes, panels):
        for name in names:
            mine = [r for r in rows if r["scenario"] == name]
            ax.plot([r["seed"] for r in mine], [scale * pool({0: r}).figures()[key] for r in mine], "o-", label=name, ms=4)
        ax.axhline(target, color="k", ls="--", lw=1, label="target")
        ax.set_title(title, fontsize=10)
        ax.set_xlabel("seed")
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    axes[0].yaxis.set_major_locator(MaxNLocator(integer=True))
    axes[0].set_ylim(bottom=-0.5)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(file, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
