"""Mutation testing of the SUMO bridge's decision code with cosmic-ray (run
by ``scripts/mutants``; docs/testing.md).

For each module of ``SCOPE``: a cosmic-ray session over the module, every
mutant outside the listed functions skipped (the rest of the module is
plumbing: SUMO calls, retracking), then, when ``--sample`` is under 1, a
seeded random share of the remaining ones kept; each kept mutant is applied
to the file in place and ``TESTS`` run against it. Writes
``OUT/python.json`` (counts and the surviving mutants with their diffs).

``--retest``: keep the sessions in OUT and run their survivors again (after
tests were added), the killed ones left as they are.

Usage: python scripts/mutants_py.py OUT [--sample 0.5] [--seed 23] [--timeout 120] [--retest]
(run with the cosmic-ray environment's python; the tests run with .venv's).
Nothing else may run pytest in this checkout meanwhile: the files are
mutated in place (and put back after each mutant).
"""

from __future__ import annotations

import argparse
import ast
import json
import random
import subprocess
import sys
from pathlib import Path

from cosmic_ray.work_db import WorkDB, use_db
from cosmic_ray.work_item import TestOutcome, WorkerOutcome, WorkResult

REPO = Path(__file__).resolve().parents[1]
# The decision code: junctions (yielding, lights), lane changes and leaders.
SCOPE = {
    "python/blendtrack/sumo/junctions.py": ["refresh_tls", "must_yield", "junction_blocked", "internal_junction_busy"],
    "python/blendtrack/sumo/lanechange.py": [
        "tighter_leader", "target_lane_clear", "tactical_room", "far_lane_room", "ask_courtesy", "wait_for_gap",
        "soft_leaders", "has_soft_leaders", "tactical_gap", "change_length", "could_change_lane", "alongside_on_lane",
        "left_behind",
    ],
}
# Tests per mutant: the stand-in-for-SUMO tests of these decisions (seconds).
TESTS = ["tests/test_decisions.py"]


def function_lines(path: Path, names: list[str]) -> list[tuple[int, int]]:
    """Line ranges (first, last) of the functions or methods named ``names``."""
    tree = ast.parse(path.read_text())
    found = {n.name: (n.lineno, n.end_lineno or n.lineno) for n in ast.walk(tree) if isinstance(n, ast.FunctionDef) and n.name in names}
    missing = sorted(set(names) - set(found))
    if missing:
        sys.exit(f"mutants_py: {path}: no function {', '.join(missing)}")
    return sorted(found.values())


def config(module: str, session_dir: Path, timeout: float) -> Path:
    test_cmd = " ".join([f"env PYTHONDONTWRITEBYTECODE=1 {REPO / '.venv/bin/python'} -m pytest -x -q -n 0 -p no:cacheprovider", *TESTS])
    cfg = session_dir / (Path(module).stem + ".toml")
    cfg.write_text(
        "[cosmic-ray]\n"
        f'module-path = "{module}"\n'
        f"timeout = {timeout}\n"
        "excluded-modules = []\n"
        f'test-command = "{test_cmd}"\n'
        "[cosmic-ray.distributor]\n"
        'name = "local"\n'
    )
    return cfg


def narrow(session: Path, ranges: list[tuple[int, int]], sample: float, rng: random.Random) -> tuple[int, int]:
    """Skips the mutants outside ``ranges`` and, of the rest, all but a
    ``sample`` share; returns (in scope, kept)."""
    skip = WorkResult(worker_outcome=WorkerOutcome.SKIPPED)
    in_scope = kept = 0
    with use_db(str(session), WorkDB.Mode.open) as db:
        items = sorted(db.work_items, key=lambda w: w.job_id)
        for item in items:
            line = item.mutations[0].start_pos[0]
            inside = any(a <= line <= b for a, b in ranges)
            in_scope += inside
            if inside and rng.random() < sample:
                kept += 1
            else:
                db.set_result(item.job_id, skip)
    return in_scope, kept


def forget_survivors(session: Path) -> int:
    """Drops the survivors' results, so ``cosmic-ray exec`` runs them again."""
    import sqlite3

    with sqlite3.connect(session) as db:
        return db.execute("DELETE FROM work_results WHERE test_outcome = 'SURVIVED'").rowcount


def summarise(session: Path) -> dict:
    out = subprocess.run([str(Path(sys.executable).parent / "cosmic-ray"), "dump", str(session)], capture_output=True, text=True, check=True)
    killed = survived = incompetent = 0
    survivors = []
    for line in out.stdout.splitlines():
        item, result = json.loads(line)
        if result is None or result["worker_outcome"] == WorkerOutcome.SKIPPED:
            continue
        outcome = result.get("test_outcome")
        if outcome == TestOutcome.KILLED:
            killed += 1
        elif outcome == TestOutcome.SURVIVED:
            survived += 1
            m = item["mutations"][0]
            survivors.append({"line": m["start_pos"][0], "operator": m["operator_name"], "occurrence": m["occurrence"], "diff": result.get("diff", "")})
        else:
            incompetent += 1
    return {"killed": killed, "survived": survived, "incompetent": incompetent, "survivors": survivors}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("out", type=Path)
    ap.add_argument("--sample", type=float, default=1.0)
    ap.add_argument("--seed", type=int, default=23)
    ap.add_argument("--timeout", type=float, default=120.0)
    ap.add_argument("--retest", action="store_true")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    rng = random.Random(args.seed)
    old = json.loads((args.out / "python.json").read_text()) if args.retest else None
    report = {"sample": args.sample, "seed": args.seed, "tests": TESTS, "modules": {}}
    for module, names in SCOPE.items():
        session = args.out / (Path(module).stem + ".sqlite")
        cfg = config(module, args.out, args.timeout)
        cr = [str(Path(sys.executable).parent / "cosmic-ray")]
        if old is not None:
            in_scope = old["modules"][module]["in_scope"]
            print(f"==> {module}: running the {forget_survivors(session)} survivors again", flush=True)
        else:
            subprocess.run([*cr, "init", "--force", str(cfg), str(session)], cwd=REPO, check=True)
            in_scope, kept = narrow(session, function_lines(REPO / module, names), args.sample, rng)
            print(f"==> {module}: {in_scope} mutants in {', '.join(names)}; running {kept}", flush=True)
        subprocess.run([*cr, "exec", str(cfg), str(session)], cwd=REPO, check=True)
        subprocess.run(["git", "diff", "--exit-code", "--quiet", "--", module], cwd=REPO, check=True)  # put back
        report["modules"][module] = {"functions": names, "in_scope": in_scope, **summarise(session)}
    (args.out / "python.json").write_text(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
