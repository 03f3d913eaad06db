"""The comparison's report: comparison.csv, network.csv, the plots,
report.md and report.html (from the ``compare_report.html`` template)."""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any

import numpy as np

from blendtrack.reporting import fmt, render_html, save_figure
from blendtrack.sumo.compare.metrics import NETWORK_METRICS, VEHICLE_METRICS, SeedResult, summarise
from blendtrack.sumo.compare.runs import MODELS, CompareOptions
from blendtrack.sumo.outputs import LAT_WINDOW_S, lateral_series
from blendtrack.sumo.scenario import Scenario
from blendtrack.sumo.selection import CONTROLLED_PARAM


def summary_lines(table: list[dict[str, Any]]) -> list[str]:
    lines = ["| metric | unit | baseline | treatment | difference | 95% CI |", "|---|---|---|---|---|---|"]
    for r in table:
        ci = f"[{fmt(r['ci_low'])}, {fmt(r['ci_high'])}]" if r["ci_low"] == r["ci_low"] else "n/a"
        lines.append(f"| {r['label']} | {r['unit']} | {fmt(r['baseline'])} | {fmt(r['treatment'])} | {fmt(r['difference'])} | {ci} |")
    return lines


def plain_text(table: list[dict[str, Any]], results: list[SeedResult], model: str) -> str:
    """A paragraph built from the numbers only."""
    by = {r["metric"]: r for r in table}
    n_pairs = sum(len(r.rows) for r in results)
    n_seeds = len(results)
    who = "SUMO's own drivers" + ("" if model == "krauss" else f" ({MODELS[model]})")
    parts = [f"Over {n_seeds} seed{'s' if n_seeds != 1 else ''} and {n_pairs} paired vehicles, "
             f"the same vehicles were driven by blendtrack (treatment) and by {who} (baseline)."]

    def sentence(metric: str, what: str) -> str | None:
        r = by[metric]
        if not (r["difference"] == r["difference"]):
            return None
        word = "lower" if r["difference"] < 0 else "higher" if r["difference"] > 0 else "unchanged"
        unit = "" if r["unit"] in ("count", "veh") else " " + r["unit"]
        s = f"{what} was {fmt(r['treatment'])}{unit} against {fmt(r['baseline'])}{unit} ({word}; difference {fmt(r['difference'])}"
        if r["ci_low"] == r["ci_high"] == r["difference"] == 0.0:
            s += ", the same in every seed"
        elif r["ci_low"] == r["ci_low"]:
            zero = r["ci_low"] <= 0.0 <= r["ci_high"]
            s += f", 95% CI [{fmt(r['ci_low'])}, {fmt(r['ci_high'])}]" + (", which includes zero: not distinguishable from no change with these seeds" if zero else ", which excludes zero")
        else:
            s += ", no confidence interval with one seed"
        return s + ")."

    lower = sum(1 for r in results for row in r.rows
                if row["lat_accel_max_mps2_treatment"] < row["lat_accel_max_mps2_baseline"])
    with_both = sum(1 for r in results for row in r.rows
                    if row["lat_accel_max_mps2_treatment"] == row["lat_accel_max_mps2_treatment"]
                    and row["lat_accel_max_mps2_baseline"] == row["lat_accel_max_mps2_baseline"])
    for metric, what in (("lat_accel_max_mps2", "The mean of the controlled vehicles' maximum lateral acceleration"),
                         ("time_above_comfort_s", "Their time above the comfort bound"),
                         ("time_loss_s", "Their time loss"),
                         ("co2_g", "Their CO2"),
                         ("background_time_loss_s", "The background vehicles' mean time loss"),
                         ("ssm_conflicts", "The number of SSM conflicts per run")):
        s = sentence(metric, what)
        if s:
            parts.append(s)
    if with_both:
        parts.append(f"The maximum lateral acceleration was lower with blendtrack for {lower} of {with_both} pairs.")
    col_b, col_t = by["collisions"]["baseline"], by["collisions"]["treatment"]
    parts.append(f"Collisions per run: {fmt(col_t)} with blendtrack, {fmt(col_b)} without.")
    return " ".join(parts)


# --------------------------------------------------------------------- plots
def _plots(results: list[SeedResult], out: Path, dt: float, comfort: float) -> list[tuple[str, Path]]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    files: list[tuple[str, Path]] = []
    samples: dict[str, list[np.ndarray]] = {"baseline": [], "treatment": []}
    lat: dict[str, list[np.ndarray]] = {"baseline": [], "treatment": []}
    for r in results:
        ids = [row["id"] for row in r.rows]
        for which, run in (("baseline", r.base), ("treatment", r.treat)):
            for vid in ids:
                tr = run.fcd[vid]
                t_all, a, kap, _ = lateral_series(tr, dt)
                idx = np.searchsorted(tr.t, t_all)
                v = tr.speed[np.clip(idx, 0, len(tr.speed) - 1)]
                ok = kap == kap
                # Every 0.5 s: enough points, a readable scatter.
                samples[which].append(np.column_stack([kap[ok], v[ok]])[:: max(1, round(0.5 / dt))])
                lat[which].append(np.abs(a))
    colors = {"baseline": "tab:orange", "treatment": "tab:blue"}

    fig, ax = plt.subplots(figsize=(7, 4.5))
    kmax = 1e-3
    for which in ("baseline", "treatment"):
        s = np.vstack(samples[which]) if samples[which] else np.zeros((0, 2))
        if len(s):
            ax.scatter(s[:, 0], s[:, 1], s=3, alpha=0.35, color=colors[which], label=which)
            kmax = max(kmax, float(np.nanpercentile(s[:, 0], 99.5)))
    k = np.linspace(kmax / 200, kmax, 200)
    ax.plot(k, np.sqrt(comfort / k), "k--", lw=1, label=f"v = sqrt({comfort:g} / curvature)")
    vmax = max([float(np.nanmax(np.vstack(samples[w])[:, 1])) for w in samples if samples[w] and len(np.vstack(samples[w]))] + [1.0])
    ax.set_xlim(0, kmax * 1.05)
    ax.set_ylim(0, vmax * 1.15)
    ax.set_xlabel("curvature of the driven path, |dpsi| / ds over 1 s (1/m, from FCD)")
    ax.set_ylabel("speed (m/s)")
    ax.set_title("Speed against curvature, controlled vehicles and their baseline twins")
    ax.legend(fontsize=8)
    files.append(("Speed against curvature", save_figure(fig, out / "speed_vs_curvature.png", 100)))

    fig, ax = plt.subplots(figsize=(7, 4))
    allv = [np.concatenate(lat[w]) if lat[w] else np.zeros(0) for w in ("baseline", "treatment")]
    top = max([float(v.max()) for v in allv if len(v)] + [comfort * 1.5])
    bins = np.linspace(0, top, 60)
    for which, v in zip(("baseline", "treatment"), allv):
        if len(v):
            ax.hist(v, bins=bins.tolist(), density=True, color=colors[which], label=which,
                    **({"alpha": 0.5} if which == "baseline" else {"histtype": "step", "lw": 1.5}))
    ax.axvline(comfort, color="k", ls="--", lw=1, label=f"comfort {comfort:g} m/s^2")
    ax.set_yscale("log")
    ax.set_xlabel("|lateral acceleration| (m/s^2, v dpsi/dt over 1 s, from FCD)")
    ax.set_ylabel("density")
    ax.set_title("Lateral acceleration of the paired vehicles")
    ax.legend(fontsize=8)
    files.append(("Lateral acceleration histograms", save_figure(fig, out / "lateral_accel_hist.png", 100)))

    r0 = results[0]
    counts: dict[str, int] = {}
    for tr in r0.treat.fcd.values():
        for ln in tr.lane:
            if not ln.startswith(":"):
                counts[ln] = counts.get(ln, 0) + 1
    if counts:
        lane = max(counts, key=lambda x: counts[x])
        fig, axes = plt.subplots(1, 2, figsize=(11, 4.5), sharey=True)
        for ax, (which, run) in zip(axes, (("baseline", r0.base), ("treatment", r0.treat))):
            for vid, tr in run.fcd.items():
                m = np.array([ln == lane for ln in tr.lane])
                if not m.any():
                    continue
                c = "tab:red" if vid in r0.treat.controlled and vid in r0.base.controlled else "0.5"
                tt = np.where(m, tr.t, np.nan)
                ax.plot(tt, np.where(m, tr.pos, np.nan), color=c, lw=0.8)
            ax.set_title(f"{which}, seed {r0.seed}")
            ax.set_xlabel("time (s)")
        axes[0].set_ylabel(f"position on lane {lane} (m)")
        fig.suptitle(f"Time-space diagram of the busiest lane ({lane}); red = controlled in the treatment")
        files.append(("Time-space diagram", save_figure(fig, out / "time_space.png", 100)))

    # The tightest curve any controlled vehicle drove (largest driven-path
    # curvature in the treatment), and the same vehicle there in the baseline.
    best = None
    for row in r0.rows:
        t_k, _, kap, _ = lateral_series(r0.treat.fcd[row["id"]], dt)
        if len(kap) and np.isfinite(kap).any():
            j = int(np.nanargmax(kap))
            if best is None or kap[j] > best[0]:
                best = (float(kap[j]), row["id"], float(t_k[j]))
    if best is not None:
        _, vid, t_peak = best
        peak = r0.treat.fcd[vid]
        i = min(int(np.searchsorted(peak.t, t_peak)), len(peak.t) - 1)
        # The middle of the 1 s window that had the largest curvature.
        i = max(i - max(1, round(LAT_WINDOW_S / dt)) // 2, 0)
        cx, cy = peak.x[i], peak.y[i]
        fig, (ax, ax2) = plt.subplots(1, 2, figsize=(11, 4.5))
        for which, run in (("baseline", r0.base), ("treatment", r0.treat)):
            tr = run.fcd[vid]
            near = np.hypot(tr.x - cx, tr.y - cy) < 60.0
            # Only the first pass through the curve.
            if near.any():
                start = int(np.argmax(near))
                stop = start + int(np.argmax(~near[start:])) if (~near[start:]).any() else len(near)
                sl = slice(start, stop)
                ax.plot(tr.x[sl], tr.y[sl], color=colors[which], lw=1.2, label=which)
                ax2.plot(tr.t[sl] - tr.t[start], tr.speed[sl], color=colors[which], label=which)
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_title(f"{vid} through its tightest curve (seed {r0.seed}, 60 m around it)")
        ax.legend(fontsize=8)
        ax2.set_xlabel("time since entering the window (s)")
        ax2.set_ylabel("speed (m/s)")
        ax2.set_title("speed in the same window (first pass)")
        ax2.legend(fontsize=8)
        files.append((f"Trajectory of {vid} in a tight curve", save_figure(fig, out / "curve_trajectory.png", 100)))
    return files


# -------------------------------------------------------------------- report
def write_outputs(results: list[SeedResult], out: Path, scenario: Scenario, opts: CompareOptions, dt: float, end_s: float | None) -> list[dict[str, Any]]:
    """comparison.csv, the plots, report.html and report.md into ``out``."""
    comfort = scenario.comfort_lateral_accel_mps2
    fields = ["seed", "id"] + [f"{m}_{w}" for m, _, _ in VEHICLE_METRICS for w in ("baseline", "treatment")]
    with open(out / "comparison.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields)
        w.writeheader()
        for r in results:
            for row in r.rows:
                w.writerow({k: ("" if isinstance(v, float) and not math.isfinite(v) else (repr(v) if isinstance(v, float) else v)) for k, v in row.items()})
    with open(out / "network.csv", "w", newline="") as f:
        nw = csv.writer(f)
        nw.writerow(["seed", "run", *[m for m, _, _ in NETWORK_METRICS]])
        for r in results:
            for which in ("baseline", "treatment"):
                nw.writerow([r.seed, which, *[repr(r.network[which][m]) for m, _, _ in NETWORK_METRICS]])
    table = summarise(results)
    plots = _plots(results, out, dt, comfort)
    text = plain_text(table, results, opts.baseline)
    if opts.controlled_fraction is not None:
        sel = f"a fraction {opts.controlled_fraction:g} of all vehicles (seeded hash of the id)"
    elif opts.controlled_type is not None:
        sel = f"every vehicle of vType {opts.controlled_type}"
    else:
        sel = f"the vTypes with {CONTROLLED_PARAM}=true"
    unpaired = sum(r.unpaired for r in results)
    head = [
        f"# blendtrack compare: {scenario.name}",
        "",
        f"Baseline: SUMO's car-following model ({'as in the scenario' if opts.baseline == 'krauss' else f'{MODELS[opts.baseline]} for every vType, in both runs'}), no blendtrack. "
        f"Treatment: blendtrack drives {sel}. Seeds 0..{opts.seeds - 1}, end {fmt(end_s) if end_s is not None else 'scenario default'} s, step {dt:g} s.",
        f"Vehicles paired by id: {sum(len(r.rows) for r in results)}; selected in only one of the two runs (not paired): {unpaired}.",
        "",
        "## Summary",
        "",
        "Baseline and treatment: mean over seeds of the per-seed means; difference: treatment - baseline, "
        "mean over seeds with its 95% confidence interval (Student's t over the seeds).",
        "",
        *summary_lines(table),
        "",
        "## In plain words",
        "",
        text,
        "",
        "## How the numbers are made",
        "",
        "- Every per-vehicle number except the lateral error comes from SUMO's outputs, computed the same way for both runs: "
        "travel time and time loss from tripinfo (trips still running at the end are counted up to the end: "
        "`--tripinfo-output.write-unfinished`), CO2 and fuel from the emissions device (g), speed and accelerations from FCD.",
        f"- Lateral acceleration: a_lat = v * dpsi/dt with the heading change over {LAT_WINDOW_S:g} s "
        "(`blendtrack.sumo.outputs.lateral_series`); samples touching a junction lane are left out. "
        f"Time above comfort counts samples with |a_lat| > {comfort:g} m/s^2. Jerk: second difference of the FCD speed per step.",
        "- Lateral error: blendtrack's own (vehicles.csv, RMS of the control point's distance to the lane centreline). "
        "SUMO's drivers are placed on the lane centreline, so the baseline's is 0 by construction, not measured.",
        "- Curvature in the speed plot is the curvature of the driven path (|dpsi| / ds over 1 s, from FCD), "
        "the same estimate for both runs, not the lane's geometry.",
        "- SSM conflicts: conflicts in ssm.xml with minimum TTC < 3 s or maximum DRAC > 3 m/s^2 "
        "(every conflict SUMO's SSM device listed in the run's ssm.xml). "
        "Collisions and teleports: SUMO's statistic output (all vehicles).",
        "- Per-vehicle pairs: comparison.csv; per-run network numbers: network.csv; the runs: runs/seed*/.",
        "",
        "## Plots",
        "",
    ]
    md = head + [f"![{title}]({p.name})\n" for title, p in plots]
    page = render_html(
        "compare_report.html",
        scenario=scenario.name,
        intro=head[2:4],
        table=table,
        text=text,
        notes=[line[2:] for line in head if line.startswith("- ")],
        plots=plots,
    )
    (out / "report.html").write_text(page)
    (out / "report.md").write_text("\n".join(md))
    return table
