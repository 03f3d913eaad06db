"""Writes ``OUT/report.md`` from a ``scripts/mutants`` run: per area the
mutants tested, killed (caught or timed out), missed, unviable, the kill
rate (killed / viable) against its target, and every survivor.

Usage: python scripts/mutants_report.py OUT
"""

from __future__ import annotations

import json
import sys
from datetime import datetime, timezone
from pathlib import Path

# Area -> (what, target kill rate) (issue 23).
RUST_AREAS = {"laws": ("control laws (lateral, longitudinal, controller, path)", 0.90), "traffic": ("traffic engine (blendtrack-traffic)", 0.80)}
PY_TARGET = 0.80


def lines(path: Path) -> list[str]:
    return [ln for ln in path.read_text().splitlines() if ln.strip()] if path.is_file() else []


def rust_area(out: Path, area: str) -> dict | None:
    """The area's counts; its survivors run again (``RUST_RETEST``, in
    ``AREA/retest``) count as killed when the new tests caught them."""
    d = out / area / "mutants.out"
    if not d.is_dir():
        return None
    caught, missed, timeout, unviable = (lines(d / f"{k}.txt") for k in ("caught", "missed", "timeout", "unviable"))
    killed, later, extra = len(caught) + len(timeout), 0, []
    r = out / area / "retest" / "mutants.out"
    if (r / "outcomes.json").is_file():
        # Only the first run's survivors count (cargo-mutants' --re can
        # match a few more mutants: listed apart, outside the sample).
        first = set(missed)
        again = lines(r / "caught.txt") + lines(r / "timeout.txt")
        later = sum(m in first for m in again)
        timeout += [m for m in lines(r / "timeout.txt") if m in first]
        missed = [m for m in lines(r / "missed.txt") if m in first]
        extra = [f"{m} (caught)" for m in again if m not in first] + [f"{m} (missed)" for m in lines(r / "missed.txt") if m not in first]
    return {"killed": killed + later, "later": later, "missed": missed, "unviable": len(unviable), "timeout": len(timeout), "extra": extra}


def rate(killed: int, missed: int) -> str:
    viable = killed + missed
    return f"{killed / viable:.1%}" if viable else "n/a"


def main() -> None:
    out = Path(sys.argv[1])
    meta = json.loads((out / "meta.json").read_text()) if (out / "meta.json").is_file() else {}
    rows, survivors, extras = [], [], []
    for area, (what, target) in RUST_AREAS.items():
        r = rust_area(out, area)
        if r is None:
            continue
        k, m = r["killed"], len(r["missed"])
        rows.append(f"| {what} | cargo-mutants | {k + m} | {k} ({r['later']} by tests added after the first run, {r['timeout']} by time-out) | {m} | {r['unviable']} | {rate(k, m)} | {target:.0%} |")
        survivors += [f"- `{s}`" for s in r["missed"]]
        extras += [f"- `{s}`" for s in r["extra"]]
    py = out / "py" / "python.json"
    if py.is_file():
        rep = json.loads(py.read_text())
        for module, r in rep["modules"].items():
            k, m = r["killed"], r["survived"]
            rows.append(f"| {Path(module).name} ({r['in_scope']} in scope) | cosmic-ray | {k + m} | {k} | {m} | {r['incompetent']} | {rate(k, m)} | {PY_TARGET:.0%} |")
            for s in r["survivors"]:
                diff = [ln for ln in s["diff"].splitlines() if ln[:1] in "+-" and not ln.startswith(("+++", "---"))]
                survivors.append(f"- `{module}:{s['line']}` {s['operator']} #{s['occurrence']}: `{' / '.join(d.strip() for d in diff)}`")
    text = [
        "# Mutation testing report",
        "",
        f"Written {datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC by `scripts/mutants`; settings: {json.dumps(meta)}.",
        "",
        "| area | tool | viable tested | killed | survived | unviable / incompetent | kill rate | target |",
        "|---|---|---|---|---|---|---|---|",
        *rows,
        "",
        "## Survivors",
        "",
        *(survivors or ["none"]),
        "",
        *(["## Outside the sample (tested by the survivors' re-run filter)", "", *extras, ""] if extras else []),
    ]
    (out / "report.md").write_text("\n".join(text))
    print("\n".join(text[:6 + len(rows)]))


if __name__ == "__main__":
    main()
