"""The outputs of a batch, derived from its records: results table, plots, summary.

- ``results.parquet`` and ``results.csv``: one row per run of the sweep
  (``batch.json``): id, name, kind, scenario, seed, status, error, wall
  time, attempt, host, then one column per parameter and one per metric.
  A run without a record (an interrupted batch) has status ``not run``.
- ``plots/<metric>.png``: the metric against each swept parameter, one line
  per scenario; at each value the runs of a seed are averaged over the other
  swept parameters, then the mean and 95 % Student-t interval are taken
  across seeds (:func:`blendtrack.reporting.mean_ci`).
- ``summary.md``: runs per status, the best parameter set per metric and
  scenario (mean over seeds; the direction of "better" is set per metric by
  :func:`direction`), the plots, and every failed run with its error.

Nothing here runs a simulation; ``blendtrack batch --report-only`` calls
:func:`write_report` on a folder as it is.
"""

from __future__ import annotations

import io
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pandas as pd

from blendtrack.batch.store import BatchError, ResultStore, atomic_write, atomic_write_all

#: Columns before the parameters, in order.
META_COLUMNS = ("run_id", "name", "kind", "scenario", "seed", "status", "error", "wall_time_s", "attempt", "host")
#: Statuses in the order summary.md lists them.
STATUSES = ("ok", "failed", "timeout", "not run")

# Metric names containing one of these are better when lower / higher.
_HIGHER = ("mean_speed", "throughput", "distance", "paired_vehicles")
_LOWER = ("error", "jerk", "collision", "teleport", "time_loss", "violation", "warning", "conflict", "overshoot",
          "settling", "accel", "steering_rate", "time_above", "travel_time", "co2", "fuel", "vanished", "reached_time")


def direction(metric: str) -> str | None:
    """``"lower"`` or ``"higher"`` (is better), or None when neither is (a count of vehicles, say).

    Errors, jerk, accelerations, steering rates, collisions, teleports,
    violations, warnings, conflicts, time loss, travel time, settling time,
    overshoot, CO2 and fuel: lower. Speed, throughput and distance: higher.
    Of ``compare``'s metrics, ``treatment_*`` and ``difference_*`` follow the
    metric; ``baseline_*`` has none (the baseline runs without blendtrack).
    """
    if metric.startswith("baseline_"):
        return None
    name = metric.removeprefix("treatment_").removeprefix("difference_")
    if any(k in name for k in _HIGHER):
        return "higher"
    if any(k in name for k in _LOWER):
        return "lower"
    return None


def results_frame(manifest: dict[str, Any], records: dict[str, dict[str, Any]]) -> pd.DataFrame:
    """One row per run of the manifest (see the module docs for the columns)."""
    runs = manifest.get("runs", [])
    param_names: list[str] = []
    metric_names: list[str] = []
    for m in runs:
        for k in m.get("params", {}):
            if k not in param_names:
                param_names.append(k)
        for k in records.get(m["run_id"], {}).get("metrics", {}) or {}:
            if k not in metric_names:
                metric_names.append(k)
    taken = set(META_COLUMNS) | set(param_names)
    metric_cols = {k: (f"metric_{k}" if k in taken else k) for k in metric_names}
    rows = []
    for m in runs:
        rec = records.get(m["run_id"])
        row: dict[str, Any] = {
            "run_id": m["run_id"],
            "name": m["name"],
            "kind": m["kind"],
            "scenario": m["scenario"],
            "seed": m["seed"],
            "status": rec.get("status", "failed") if rec else "not run",
            "error": (rec.get("error") or "") if rec else "",
            "wall_time_s": rec.get("wall_time_s") if rec else None,
            "attempt": rec.get("attempt") if rec else 0,
            "host": rec.get("host", "") if rec else "",
        }
        for k in param_names:
            row[k] = m.get("params", {}).get(k)
        metrics = (rec.get("metrics") or {}) if rec else {}
        for k, col in metric_cols.items():
            v = metrics.get(k)
            row[col] = float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else math.nan
        rows.append(row)
    frame = pd.DataFrame(rows, columns=[*META_COLUMNS, *param_names, *metric_cols.values()])
    frame["wall_time_s"] = frame["wall_time_s"].astype(float)
    return frame


def _parquet_safe(frame: pd.DataFrame) -> pd.DataFrame:
    """Parquet wants one type a column: a parameter swept over numbers and
    words (alpha = [0.5, "auto"]) is written as text there ("0.5", "auto");
    the frame itself (and results.csv) keeps the values as they are."""
    mixed = [c for c in frame.columns if frame[c].dtype == object
             and {type(v) for v in frame[c] if v is not None and v == v} - {str} and frame[c].map(lambda v: isinstance(v, str)).any()]
    if not mixed:
        return frame
    out = frame.copy()
    for c in mixed:
        out[c] = out[c].map(lambda v: None if v is None or v != v else _fmt(v) if not isinstance(v, str) else v)
    return out


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _fmt(x: Any) -> str:
    from blendtrack.reporting import fmt

    return fmt(x) if _is_number(x) else str(x)


def _param_text(values: dict[str, Any]) -> str:
    return ", ".join(f"{k}={_fmt(v)}" for k, v in values.items()) or "(the only parameter set)"


def _same(a: Any, b: Any) -> bool:
    if _is_number(a) and _is_number(b):
        return float(a) == float(b)
    return bool(a == b)


def _seed_means(frame: pd.DataFrame, metric: str) -> list[float]:
    """The metric per seed (mean over the other runs of that seed), NaN left out."""
    per_seed = frame.groupby("seed")[metric].mean()
    return [float(v) for v in per_seed if v == v]


def _dims(manifest: dict[str, Any], frame: pd.DataFrame) -> list[str]:
    """The parameters to plot against: swept ones with more than one value, else the scenario."""
    swept = [k for k, vals in manifest.get("swept", {}).items() if len(vals) > 1 and k in frame.columns]
    if not swept and frame["scenario"].nunique() > 1:
        return ["scenario"]
    return swept


def _x_values(manifest: dict[str, Any], dim: str, frame: pd.DataFrame) -> list[Any]:
    if dim == "scenario":
        return list(manifest.get("scenarios", sorted(frame["scenario"].unique())))
    vals = list(manifest.get("swept", {}).get(dim, []))
    if vals and all(_is_number(v) for v in vals):
        vals = sorted(vals)
    return vals


def plot_metric(manifest: dict[str, Any], ok: pd.DataFrame, metric: str, dims: Sequence[str], file: Path) -> None:
    """``metric`` against each of ``dims`` (one panel each), a line per scenario, mean and 95 % CI over seeds."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from blendtrack.reporting import mean_ci

    scenarios = list(dict.fromkeys(ok["scenario"]))
    n = len(dims)
    cols = min(n, 3)
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.6 * cols, 3.4 * rows), squeeze=False)
    for i, dim in enumerate(dims):
        ax = axes[i // cols][i % cols]
        xs = _x_values(manifest, dim, ok)
        numeric = all(_is_number(v) for v in xs)
        lines = [None] if dim == "scenario" else scenarios
        for j, scenario in enumerate(lines):
            sub = ok if scenario is None else ok[ok["scenario"] == scenario]
            px, py, lo, hi = [], [], [], []
            for k, x in enumerate(xs):
                at = sub[sub[dim].map(lambda v, x=x: _same(v, x))]
                m, l, h = mean_ci(_seed_means(at, metric))
                if m != m:
                    continue
                px.append(float(x) if numeric else k)
                py.append(m)
                lo.append(m - l if l == l else 0.0)
                hi.append(h - m if h == h else 0.0)
            if not px:
                continue
            # Categorical axes: lines side by side, so their intervals do not hide each other.
            shift = 0.0 if numeric or len(lines) == 1 else (j - (len(lines) - 1) / 2) * 0.08
            ax.errorbar([p + shift for p in px], py, yerr=[lo, hi], marker="o", ms=4, capsize=3, lw=1.3,
                        label=scenario if scenario is not None and len(lines) > 1 else None)
        if not numeric:
            ax.set_xticks(range(len(xs)), [str(x) for x in xs], rotation=20 if len(xs) > 4 else 0)
        ax.set_xlabel(dim)
        ax.set_ylabel(metric)
        ax.grid(alpha=0.3)
        if len(lines) > 1 and ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
    for k in range(n, rows * cols):
        axes[k // cols][k % cols].set_visible(False)
    seeds = ok["seed"].nunique()
    # Two lines: a long metric name on one line with the rest overflowed a
    # one-panel figure.
    fig.suptitle(f"{metric}\nmean and 95% CI over {seeds} seed{'s' if seeds != 1 else ''}", fontsize=10)
    # Fixed margins: tight_layout would draw every figure twice (a third of the report's time).
    width, height = 4.6 * cols, 3.4 * rows
    fig.subplots_adjust(left=0.8 / width, right=1 - 0.15 / width, bottom=0.5 / height, top=1 - 0.6 / height,
                        wspace=0.35, hspace=0.45)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    atomic_write(file, buf.getvalue())


def best_sets(manifest: dict[str, Any], ok: pd.DataFrame, metrics: Sequence[str]) -> list[dict[str, Any]]:
    """Per metric with a direction and per scenario: the parameter set with the best mean over seeds."""
    from blendtrack.reporting import mean_ci

    swept = [k for k, vals in manifest.get("swept", {}).items() if len(vals) > 1 and k in ok.columns]
    out = []
    for metric in metrics:
        better = direction(metric)
        if better is None:
            continue
        for scenario, sub in ok.groupby("scenario", sort=False):
            best: dict[str, Any] | None = None
            means = []
            groups = sub.groupby(swept, sort=False, dropna=False) if swept else [((), sub)]
            for key, g in groups:
                vals = _seed_means(g, metric)
                m, lo, hi = mean_ci(vals)
                if m != m:
                    continue
                means.append(m)
                if best is None or (m < best["mean"] if better == "lower" else m > best["mean"]):
                    key_t = key if isinstance(key, tuple) else (key,)
                    best = {"metric": metric, "better": better, "scenario": scenario, "params": dict(zip(swept, key_t)),
                            "mean": m, "ci_low": lo, "ci_high": hi, "seeds": len(vals)}
            if best is not None:
                # How many other parameter sets have the same mean (e.g. no collision anywhere).
                best["ties"] = sum(1 for m in means if m == best["mean"]) - 1
                best["sets"] = len(means)
                out.append(best)
    return out


def _best_text(b: dict[str, Any]) -> str:
    if b["sets"] > 1 and b["ties"] == b["sets"] - 1:
        return f"all {b['sets']} sets equal"
    text = _param_text(b["params"])
    return f"{text} (tied with {b['ties']} more)" if b["ties"] else text


def _metric_order(names: Sequence[str]) -> list[str]:
    """The metrics in the order each kind lists them (tracking metrics before counts), others after."""
    from blendtrack.batch.kinds import SUMO_SUMMARY_METRICS, SUMO_VEHICLE_METRICS
    from blendtrack.simulation import EXTRA_METRIC_KEYS, METRIC_KEYS

    known = [*METRIC_KEYS, *EXTRA_METRIC_KEYS, *SUMO_VEHICLE_METRICS, *SUMO_SUMMARY_METRICS]
    rank = {k: i for i, k in enumerate(known)}
    return sorted(names, key=lambda k: (rank.get(k, len(known)), list(names).index(k)))


def _cell(text: Any) -> str:
    return " ".join(str(text).split()).replace("|", "\\|")


def write_report(out: Path) -> pd.DataFrame:
    """Writes plots/, then summary.md, results.parquet and results.csv together, from the records in ``out``."""
    store = ResultStore(out)
    manifest = store.manifest()
    if manifest is None:
        raise BatchError(f"{store.out} holds no batch (no batch.json): run the sweep first")
    records = store.records()
    frame = results_frame(manifest, records)
    buf = io.BytesIO()
    _parquet_safe(frame).to_parquet(buf, index=False)

    params = list(dict.fromkeys(k for m in manifest.get("runs", []) for k in m.get("params", {})))
    metric_cols = _metric_order([c for c in frame.columns if c not in META_COLUMNS and c not in params])
    ok = frame[frame["status"] == "ok"]
    plotted = [m for m in metric_cols if ok[m].notna().any() and not m.startswith("baseline_")]
    dims = _dims(manifest, frame)
    plots_dir = store.out / "plots"
    plots: list[tuple[str, Path]] = []
    if dims and len(ok):
        plots_dir.mkdir(exist_ok=True)
        for old in plots_dir.glob("*.png"):
            old.unlink()
        for metric in plotted:
            file = plots_dir / f"{metric}.png"
            plot_metric(manifest, ok, metric, dims, file)
            plots.append((metric, file))

    counts = frame["status"].value_counts()
    swept = {k: v for k, v in manifest.get("swept", {}).items()}
    lines = [
        f"# blendtrack batch: {Path(manifest.get('sweep_file', 'sweep')).name}",
        "",
    ]
    if manifest.get("description"):
        lines += [" ".join(str(manifest["description"]).split()), ""]
    lines += [
        f"Kind: `{manifest.get('kind')}`. Scenarios: {', '.join(manifest.get('scenarios', []))}. "
        f"Seeds: {', '.join(str(s) for s in manifest.get('seeds', []))}. Runs: {len(frame)}.",
        "",
        "Swept: " + ("; ".join(f"`{k}` = {', '.join(_fmt(v) for v in vals)}" for k, vals in swept.items()) or "nothing") + ".",
        "",
        "Fixed: " + (", ".join(f"`{k}` = {_fmt(v)}" for k, v in manifest.get("fixed", {}).items()) or "nothing (defaults)") + ".",
        "",
        "## Runs",
        "",
        "| status | runs |",
        "|---|---|",
        *(f"| {s} | {int(counts.get(s, 0))} |" for s in STATUSES if counts.get(s, 0) or s in ("ok", "failed")),
        "",
        "Wall time per run (s): " + (
            f"median {frame['wall_time_s'].median():.3g}, max {frame['wall_time_s'].max():.3g}, sum {frame['wall_time_s'].sum():.4g}."
            if frame["wall_time_s"].notna().any() else "none recorded."),
        "",
    ]
    best = best_sets(manifest, ok, [m for m in metric_cols if ok[m].notna().any()]) if len(ok) else []
    lines += ["## Best parameter set per metric", ""]
    if not any(len(v) > 1 for v in swept.values()):
        lines += ["One parameter set per scenario: nothing to choose.", ""]
    elif not best:
        lines += ["No finished run.", ""]
    else:
        lines += [
            "Per scenario, the parameter set whose mean over seeds is best (ties are counted; \"all equal\" when no set "
            "differs); `better` says which way: lower for "
            "errors, jerk, accelerations, steering rates, collisions, teleports, violations, warnings, conflicts, "
            "time loss, travel and settling time, overshoot, CO2 and fuel; higher for speed, throughput and distance. "
            "Metrics with no better direction (vehicle counts, lane changes) and compare's `baseline_*` are left out. "
            "95% CI: Student's t over the seeds.",
            "",
            "| metric | better | scenario | best parameters | mean | 95% CI | seeds |",
            "|---|---|---|---|---|---|---|",
        ]
        for b in best:
            ci = f"[{_fmt(b['ci_low'])}, {_fmt(b['ci_high'])}]" if b["ci_low"] == b["ci_low"] else "n/a"
            lines.append(f"| {b['metric']} | {b['better']} | {b['scenario']} | {_best_text(b)} | {_fmt(b['mean'])} | {ci} | {b['seeds']} |")
        lines.append("")
    lines += ["## Plots", ""]
    if plots:
        lines += [
            f"Each metric against {', '.join(f'`{d}`' for d in dims)}"
            + (", one line per scenario" if dims != ["scenario"] and frame["scenario"].nunique() > 1 else "")
            + ". At each value, the runs of a seed are averaged over the other swept parameters; the point is the "
            "mean over seeds and the bar its 95% confidence interval (Student's t; none with one seed). "
            "Failed runs are left out.",
            "",
        ]
        lines += [f"### {metric}\n\n![{metric}](plots/{file.name})\n" for metric, file in plots]
    else:
        lines += ["No plot: nothing was swept, or no run finished.", ""]
    bad = frame[frame["status"] != "ok"]
    lines += ["## Failed runs", ""]
    if len(bad):
        lines += ["| run | id | status | error |", "|---|---|---|---|"]
        lines += [f"| {_cell(r['name'])} | {r['run_id']} | {r['status']} | {_cell(r['error']) or '-'} |" for _, r in bad.iterrows()]
        lines += ["", "`blendtrack batch SWEEP --resume --out DIR` runs these again (and only these). Each run's log: `work/<id>/run.log`.", ""]
    else:
        lines += ["None.", ""]
    lines += [
        "## Files",
        "",
        "- `results.parquet`, `results.csv`: one row per run (parameters, seed, status, error, wall time, metrics).",
        "- `runs/<id>.json`: the record of each run; `work/<id>/`: what the run wrote, and its log.",
        "- `batch.json`: the runs of the sweep; `sweep.toml`: the sweep file.",
        "",
    ]
    # All three renamed at the end, summary.md first: a batch killed while
    # its report is made leaves no results.* without a summary.md.
    atomic_write_all([
        (store.out / "summary.md", "\n".join(lines)),
        (store.out / "results.parquet", buf.getvalue()),
        (store.out / "results.csv", frame.to_csv(index=False)),
    ])
    return frame
