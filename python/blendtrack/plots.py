"""Figures of runs (matplotlib, Agg backend: files only, no display).

Every function takes one or more labelled runs (``{label: DataFrame}`` as
returned by :func:`blendtrack.simulate`) and writes one PNG. Angles are
plotted in degrees (SPEC: degrees only at the edges).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path as FsPath

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from blendtrack._blendtrack import Path  # noqa: E402

Runs = Mapping[str, pd.DataFrame]


def _save(fig: "matplotlib.figure.Figure", out: FsPath) -> FsPath:
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def trajectory(runs: Runs, path: Path, out: FsPath, title: str = "Trajectory") -> FsPath:
    """Rear-axle trajectory of each run over the reference path."""
    fig, ax = plt.subplots(figsize=(7, 6))
    pts = path.points()
    closed = np.vstack([pts, pts[:1]]) if path.is_closed else pts
    ax.plot(closed[:, 0], closed[:, 1], color="0.6", lw=2.5, label="reference path")
    for label, df in runs.items():
        ax.plot(df["x_m"], df["y_m"], lw=1.0, label=label)
        ax.plot(df["x_m"].iloc[0], df["y_m"].iloc[0], "o", ms=4, color=ax.lines[-1].get_color())
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title)
    ax.legend(fontsize=8)
    return _save(fig, out)


def _series(runs: Runs, column: str, ylabel: str, out: FsPath, title: str, scale: float = 1.0) -> FsPath:
    fig, ax = plt.subplots(figsize=(8, 3.6))
    for label, df in runs.items():
        ax.plot(df["t_s"], df[column] * scale, lw=0.9, label=label)
    ax.set_xlabel("t (s)")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    if len(runs) > 1:
        ax.legend(fontsize=8)
    return _save(fig, out)


def lateral_error(runs: Runs, out: FsPath, title: str = "Lateral error of the control point") -> FsPath:
    return _series(runs, "lateral_error_m", "lateral error (m)", out, title)


def heading_error(runs: Runs, out: FsPath, title: str = "Heading error") -> FsPath:
    return _series(runs, "heading_error_rad", "heading error (deg)", out, title, np.degrees(1.0))


def steering(runs: Runs, out: FsPath, title: str = "Steering angle") -> FsPath:
    return _series(runs, "delta_rad", "steering angle (deg)", out, title, np.degrees(1.0))


def speed(runs: Runs, out: FsPath, title: str = "Speed") -> FsPath:
    return _series(runs, "v_mps", "speed (m/s)", out, title)


def alpha(runs: Runs, out: FsPath, title: str = "Blend factor alpha") -> FsPath:
    return _series(runs, "alpha", "alpha", out, title)
