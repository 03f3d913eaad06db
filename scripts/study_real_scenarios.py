#!/usr/bin/env python3
"""Study: blendtrack on public SUMO scenarios nobody on this project wrote.

Runs `blendtrack compare` on each scenario exactly as published (at its own
step length), 30 % of the vehicles controlled, for --end seconds, and
reports for the controlled vehicles: how many arrived against how many of
the same vehicles arrived under plain SUMO, their mean |lateral error| and
their mean speed in both runs; plus collisions and teleports of both runs.
Writes OUT/study.md (and each compare's report under OUT/<scenario>/) and
prints the table. A study measures; it asserts nothing.

    .venv/bin/python scripts/study_real_scenarios.py [--end 600] [--fraction 0.3] [--seeds 1] [--out out/study_real]
"""

from __future__ import annotations

import argparse
import csv
import subprocess
import sys
from pathlib import Path

import sumolib

ROOT = Path(__file__).resolve().parent.parent
REAL = ROOT.parent / "shared" / "scenarios_real"
SCENARIOS = {
    "bologna_acosta": REAL / "bologna_acosta" / "run.sumocfg",
    "eccles_interchange": REAL / "eccles_interchange" / "interchangeSim.cfg",
}


def trips(file: Path) -> dict[str, dict[str, float]]:
    """Per vehicle: arrived (0/1), route length and duration, from a tripinfo file."""
    out = {}
    for t in sumolib.xml.parse(str(file), "tripinfo"):
        arrived = float(t.arrival) >= 0
        out[t.id] = {"arrived": float(arrived), "length": float(t.routeLength), "duration": float(t.duration)}
    return out


def study(name: str, cfg: Path, args: argparse.Namespace) -> dict[str, object]:
    out = args.out / name
    cmd = [sys.executable, "-m", "blendtrack.cli", "compare", str(cfg), "--controlled-fraction", str(args.fraction),
           "--seeds", str(args.seeds), "--end", str(args.end), "--quiet", "--out", str(out), *args.extra]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        sys.exit(f"study: {name}: {proc.stderr.strip()}")
    # Summed over the seeds: each seed's controlled vehicles, and how many of
    # them arrived in the run and in plain SUMO's run with the same seed.
    n_ctl = 0
    arrived_t = arrived_b = 0.0
    err: list[float] = []
    done: dict[str, list[dict[str, float]]] = {"t": [], "b": []}
    for seed in range(args.seeds):
        runs = out / "runs" / f"seed{seed}"
        with open(runs / "treatment" / "vehicles.csv") as f:
            rows = list(csv.DictReader(f))
        ids = {r["id"] for r in rows}
        n_ctl += len(ids)
        base, treat = trips(runs / "baseline" / "sumo" / "tripinfo.xml"), trips(runs / "treatment" / "sumo" / "tripinfo.xml")
        arrived_t += sum(treat.get(i, {}).get("arrived", 0.0) for i in ids)
        arrived_b += sum(base.get(i, {}).get("arrived", 0.0) for i in ids)
        err += [float(r["lateral_error_mean_abs_m"]) for r in rows if r.get("lateral_error_mean_abs_m")]
        for key, tr in (("t", treat), ("b", base)):
            done[key] += [tr[i] for i in ids if i in tr and tr[i]["arrived"] and tr[i]["duration"] > 0]

    def mean_speed(key: str) -> float:
        d = done[key]
        return sum(x["length"] for x in d) / sum(x["duration"] for x in d) if d else float("nan")

    totals: dict[str, float] = {}
    with open(out / "network.csv") as f:
        for r in csv.DictReader(f):
            for k in ("collisions", "teleports"):
                totals[f"{r['run']}_{k}"] = totals.get(f"{r['run']}_{k}", 0.0) + float(r[k])
    return {
        "scenario": name,
        "controlled": n_ctl,
        "arrived": f"{arrived_t:.0f} / {arrived_b:.0f}",
        "ratio": arrived_t / arrived_b if arrived_b else float("nan"),
        "lat_err": sum(err) / len(err) if err else float("nan"),
        "speed": f"{mean_speed('t'):.2f} / {mean_speed('b'):.2f}",
        "collisions": f"{totals['treatment_collisions']:.0f} / {totals['baseline_collisions']:.0f}",
        "teleports": f"{totals['treatment_teleports']:.0f} / {totals['baseline_teleports']:.0f}",
    }


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--end", type=float, default=600.0)
    p.add_argument("--fraction", type=float, default=0.3)
    p.add_argument("--seeds", type=int, default=1, help="seeds 0..N-1, counts summed over them")
    p.add_argument("--out", type=Path, default=ROOT / "out" / "study_real")
    p.add_argument("extra", nargs="*", help="further options for blendtrack compare (after --)")
    args = p.parse_args()
    missing = [str(c) for c in SCENARIOS.values() if not c.is_file()]
    if missing:
        sys.exit(f"study: {', '.join(missing)} not found (keep ../shared beside the repository)")
    rows = [study(n, c, args) for n, c in SCENARIOS.items()]
    lines = [
        f"{args.fraction:.0%} of the vehicles controlled, {args.end:g} s at each scenario's own step length, "
        f"seeds 0-{args.seeds - 1} (counts summed over them). "
        "Pairs are blendtrack / the same vehicles under plain SUMO.",
        "",
        "| scenario | controlled | arrived | ratio | mean abs lateral error (m) | mean speed of arrived (m/s) | collisions | teleports |",
        "|---|---|---|---|---|---|---|---|",
    ]
    lines += [f"| {r['scenario']} | {r['controlled']} | {r['arrived']} | {r['ratio']:.2f} | {r['lat_err']:.3f} | {r['speed']} | "
              f"{r['collisions']} | {r['teleports']} |" for r in rows]
    text = "\n".join(lines) + "\n"
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "study.md").write_text(text)
    print(text)
    print(f"wrote {args.out / 'study.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
