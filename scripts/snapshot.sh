#!/usr/bin/env bash
# Behaviour snapshot: six fixed-seed SUMO runs of the shipped scenarios
# (rural loop, ring, urban grid 30 % with the trace and 100 %, highway 100 %
# and 50 % with tactical lane changes), each writing vehicles.csv,
# summary.json and (one) trace.csv; prints an md5 per file, with wall-time
# keys and checkout paths stripped from the summary, so two checkouts'
# lines can be diffed. A refactor that must not change behaviour gives the
# same lines before and after.
#
#   scripts/snapshot.sh OUTDIR [REPO]     (REPO: a checkout with its .venv; default this one)
set -uo pipefail
OUT=$1; REPO=$(cd "${2:-$(dirname "$0")/..}" && pwd); mkdir -p "$OUT"; OUT=$(cd "$OUT" && pwd)
BT="$REPO/.venv/bin/blendtrack"
run() { name=$1; shift; "$BT" sumo run "$@" --quiet --sumo-args '--no-warnings true' --out "$OUT/$name" >"$OUT/$name.log" 2>&1 || echo "FAIL $name rc=$?"; }
cd "$REPO"
run rural rural_loop --end 300
run ring ring_single_lane --end 300
run grid30 urban_grid --controlled-fraction 0.3 --end 300 --trace
run grid100 urban_grid --controlled-fraction 1 --end 200
run hw100 highway_onramp --controlled-fraction 1 --end 300
run hwtac highway_onramp --controlled-fraction 0.5 --tactical-lane-changes --end 300 --seed 1
"$REPO/.venv/bin/python" - "$OUT" "$REPO" <<'PY'
import json, sys, hashlib, pathlib
out = pathlib.Path(sys.argv[1])
REPO_DIR = sys.argv[2]
for d in sorted(p for p in out.iterdir() if p.is_dir()):
    s = d / "summary.json"
    if not s.exists():
        print(d.name, "NO SUMMARY"); continue
    j = json.loads(s.read_text())
    def strip(o):
        if isinstance(o, dict):
            return {k: strip(v) for k, v in o.items() if not any(w in k for w in ("wall", "elapsed", "seconds_real", "duration_s_real", "timestamp", "per_second"))}
        if isinstance(o, list): return [strip(x) for x in o]
        if isinstance(o, str) and o.startswith(REPO_DIR):
            return "<repo>" + o[len(REPO_DIR):]
        return o
    (d / "summary.stripped.json").write_text(json.dumps(strip(j), indent=1, sort_keys=True))
    h = lambda p: hashlib.md5(p.read_bytes()).hexdigest()[:10] if p.exists() else "-"
    print(f"{d.name:10s} vehicles.csv {h(d/'vehicles.csv')} summary {h(d/'summary.stripped.json')} trace {h(d/'trace.csv')}")
PY
