"""Why the blend loses to Stanley: the rear law's curvature look-ahead term.

Writes docs/lookahead_clothoid.png, docs/lookahead_grid.png and
docs/lookahead.json (the numbers docs/paper.md quotes). Run from the
repository root: ``.venv/bin/python scripts/paper_lookahead.py`` (about a
minute; needs ../shared/tracks/Nuerburgring.csv for the track grid).

Closed form (rust/blendtrack/src/lateral.rs, ``lookahead_forcing``): the
second term of the rear law feeds forward the MEAN curvature over the next L
metres, (theta(s+L) - theta(s)) / L, where the rear axle needs the curvature
at s. The difference is a forcing f(s); linearised about the path the rear
axle's error obeys  e'' + (2/d + 1/L) e' + (2/d^2) e = f(s)  (d/ds), so on a
clothoid kappa = c s (f = c L / 2) it settles at  e = c L d^2 / 4,  to the
inside of the curve.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path as FsPath

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import blendtrack  # noqa: E402
from blendtrack import paper_eval as pe  # noqa: E402
from blendtrack.paper import choose_scale, tightest_radius_m  # noqa: E402

ROOT = FsPath(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
TRACK = ROOT.parent / "shared" / "tracks" / "Nuerburgring.csv"
V = 8.0
E = 2.6
STRAIGHT_M, CLOTHOID_M, RADIUS_M, ARC_M = 100.0, 150.0, 40.0, 150.0


def clothoid_entry() -> tuple[blendtrack.Path, float]:
    """Straight, clothoid from 0 to 1/R over CLOTHOID_M, arc (blendtrack.paper_eval.clothoid_entry)."""
    return pe.clothoid_entry(STRAIGHT_M, CLOTHOID_M, RADIUS_M, ARC_M)


def rear_law(d: float, lookahead: float, **kw: object) -> blendtrack.ControllerConfig:
    """The rear law alone (alpha = 0) with d and L fixed at speed V."""
    return blendtrack.ControllerConfig(
        lat_blend_factor=0.0,
        target_distance_min_m=d,
        target_distance_gain_s=0.0,
        curvature_lookahead_gain_s=lookahead / V,
        preferred_speed=V,
        **kw,
    )


def clothoid_study() -> dict[str, object]:
    path, c = clothoid_entry()
    rows = []
    fig, ax = plt.subplots(figsize=(8, 3.8))
    for d in (2.0, 4.0, 8.0, 16.0):
        for lookahead in (2 * E, 8.0, 16.0, 24.0):
            frame, _ = blendtrack.simulate(path, rear_law(d, lookahead), fixed_speed_mps=V, duration_s=(path.length_m - 5) / V)
            s = frame["s_m"].to_numpy() - STRAIGHT_M
            e = frame["lateral_error_rear_m"].to_numpy()
            at = int(np.searchsorted(s, CLOTHOID_M - lookahead))
            rows.append({"d_m": d, "L_m": lookahead, "sim_m": float(e[at]), "closed_form_m": c * lookahead * d * d / 4})
            if lookahead == 16.0 or d == 8.0:
                # Stop short of the open path's end, where the look-ahead runs off it.
                keep = s < CLOTHOID_M + ARC_M - 40.0
                ax.plot(s[keep], e[keep], lw=1, label=f"d = {d:g} m, L = {lookahead:g} m")
    ax.axvspan(0, CLOTHOID_M, color="0.9")
    ax.set_xlabel("arc length from the clothoid's start (m)")
    ax.set_ylabel("rear axle error (m, > 0 inside)")
    ax.set_title(f"Rear law alone at {V:g} m/s: straight, clothoid to R = {RADIUS_M:g} m (shaded), arc")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(DOCS / "lookahead_clothoid.png", dpi=110)
    plt.close(fig)
    return {"c_per_m2": c, "rows": rows}


def track_grid() -> dict[str, object]:
    vehicle = blendtrack.VehicleParams()
    full = blendtrack.Path.from_tum_csv(str(TRACK), True)
    track = full.scaled(choose_scale(tightest_radius_m(full), vehicle))
    ds = (1.0, 2.0, 4.0, 8.0, 16.0)
    ls = (2 * E, 8.0, 16.0, 32.0)
    kw = dict(laps=1.0, duration_s=2000.0, offset_m=0.0, noise="uniform:0.05:0.5", delay_s=0.1, seed=0)
    grid = np.full((len(ds), len(ls)), np.nan)
    for i, d in enumerate(ds):
        for j, lookahead in enumerate(ls):
            _, m = blendtrack.simulate(track, rear_law(d, lookahead), vehicle, **kw)
            grid[i, j] = m["lateral_error_rear_axle_mean_abs_m"]
    _, st = blendtrack.simulate(track, blendtrack.ControllerConfig(preferred_speed=V, lateral_controller="stanley"), vehicle, **kw)
    fig, ax = plt.subplots(figsize=(6, 4))
    im = ax.imshow(grid, origin="lower", cmap="viridis", norm=matplotlib.colors.LogNorm())
    ax.set_xticks(range(len(ls)), [f"{x:g}" for x in ls])
    ax.set_yticks(range(len(ds)), [f"{x:g}" for x in ds])
    for i in range(len(ds)):
        for j in range(len(ls)):
            ax.text(j, i, f"{grid[i, j]:.3f}", ha="center", va="center", color="w", fontsize=8)
    ax.set_xlabel("curvature look-ahead L (m)")
    ax.set_ylabel("target distance d (m)")
    ax.set_title(f"Rear law alone, scaled Nuerburgring, {V:g} m/s:\nmean |rear axle error| (m); Stanley's front axle: "
                 f"{st['lateral_error_front_axle_mean_abs_m']:.3f}")
    fig.colorbar(im, ax=ax)
    fig.tight_layout()
    fig.savefig(DOCS / "lookahead_grid.png", dpi=110)
    plt.close(fig)
    return {
        "d_m": list(ds),
        "L_m": list(ls),
        "rear_error_mean_abs_m": grid.tolist(),
        "stanley_front_mean_abs_m": st["lateral_error_front_axle_mean_abs_m"],
        "stanley_rear_mean_abs_m": st["lateral_error_rear_axle_mean_abs_m"],
        "paper_default_d_L_m": [2 * V, 2 * V],
    }


def main() -> int:
    if not TRACK.is_file():
        print(f"{TRACK}: missing (../shared/tracks beside the repository)", file=sys.stderr)
        return 2
    DOCS.mkdir(exist_ok=True)
    result = {"clothoid": clothoid_study(), "track": track_grid()}
    (DOCS / "lookahead.json").write_text(json.dumps(result, indent=1) + "\n")
    for r in result["clothoid"]["rows"]:  # type: ignore[index]
        print(r)
    print(json.dumps(result["track"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
