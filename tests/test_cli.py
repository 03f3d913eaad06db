"""`blendtrack sim` and `blendtrack paper` end to end (subprocesses)."""

from __future__ import annotations

import csv
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

from blendtrack.simulation import METRIC_KEYS

REPO_ROOT = Path(__file__).resolve().parents[1]
# BLENDTRACK_SHARED_DIR: where ../shared is (set it to a missing folder to see the skips).
TRACKS = Path(os.environ.get("BLENDTRACK_SHARED_DIR") or REPO_ROOT.parent / "shared") / "tracks"
NUERBURGRING = TRACKS / "Nuerburgring.csv"
needs_nuerburgring = pytest.mark.skipif(not NUERBURGRING.is_file(), reason=f"{NUERBURGRING} is absent (shared/ track data not beside the repo)")
PLOTS = ["trajectory.png", "lateral_error.png", "heading_error.png", "steering.png", "speed.png", "alpha.png"]


def _cli(*args: str, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "blendtrack.cli", *args], capture_output=True, text=True, timeout=timeout, check=False)


def _check_outputs(out: Path) -> dict[str, float]:
    with open(out / "metrics.json") as f:
        metrics = json.load(f)
    assert list(metrics) == list(METRIC_KEYS)
    assert set(metrics) == {
        "lateral_error_mean_abs_m", "lateral_error_rms_m", "lateral_error_max_abs_m", "heading_error_rms_deg",
        "steering_rate_rms_deg_s", "steering_rate_max_deg_s", "lateral_accel_max_mps2", "reached_time_s",
        "settling_time_s", "initial_overshoot_m", "mean_speed_mps", "distance_m", "lateral_error_mean_abs_m_reached",
        "lateral_error_mean_abs_m_settled", "lateral_error_rms_m_settled", "lateral_error_max_abs_m_settled",
        "heading_error_rms_deg_settled", "lateral_error_front_axle_mean_abs_m", "lateral_error_rear_axle_mean_abs_m",
        "body_error_mean_m", "body_error_max_m",
    }  # fmt: skip
    for key, value in metrics.items():
        assert isinstance(value, float) and math.isfinite(value), (key, value)
    header = (out / "timeseries.csv").read_text().splitlines()[0].split(",")
    assert {"t_s", "x_m", "y_m", "theta_rad", "v_mps", "delta_rad", "alpha", "s_m", "lateral_error_m", "lateral_error_front_m", "lateral_error_rear_m", "heading_error_rad", "accel_mps2", "virtual_obstacle_m"} <= set(header)
    for name in PLOTS:
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    return metrics


def test_sim_on_a_builtin_track(tmp_path: Path) -> None:
    out = tmp_path / "run"
    r = _cli("sim", "--track", "test_track", "--duration", "60", "--offset", "2", "--noise", "uniform:0.02:0.2", "--delay", "0.05", "--out", str(out))
    assert r.returncode == 0, r.stderr
    m = _check_outputs(out)
    assert m["lateral_error_max_abs_m"] >= 1.9  # the 2 m start is in the run
    # Settled for good within the run: |e| below SETTLING_THRESHOLD_M (0.1 m)
    # from the settling time on, so its mean after settling too (a run that
    # never settles has NaN there and fails).
    assert math.isfinite(m["settling_time_s"]) and m["lateral_error_mean_abs_m_settled"] < 0.1
    rows = (out / "timeseries.csv").read_text().count("\n") - 1
    assert rows == 6000


def test_sim_backward_stanley_on_a_circle_with_a_config_file(tmp_path: Path) -> None:
    cfg = tmp_path / "c.toml"
    cfg.write_text("[controller]\nstanley_gain = 2.0\n[vehicle]\nwheelbase_m = 3.0\n")
    r = _cli("sim", "--track", "circle:40", "--controller", "stanley", "--direction", "backward", "--speed", "1", "--offset", "1", "--duration", "40", "--config", str(cfg), "--out", str(tmp_path / "o"))
    assert r.returncode == 0, r.stderr
    with (tmp_path / "o" / "timeseries.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert all(float(r["v_mps"]) <= 0.0 for r in rows)  # never forwards
    # It really moves, body first: from rest at 1 m/s^2 to 1 m/s, then 39 s at
    # 1 m/s is 39.5 m; the displacement points against the heading.
    assert float(rows[-1]["distance_m"]) > 0.9 * 39.5
    a, b = rows[-101], rows[-1]
    dx, dy = float(b["x_m"]) - float(a["x_m"]), float(b["y_m"]) - float(a["y_m"])
    th = float(b["theta_rad"])
    assert dx * math.cos(th) + dy * math.sin(th) < -0.9 * math.hypot(dx, dy)
    # And it tracks the circle it was put 1 m off: at the end within the
    # metrics' settling threshold (SETTLING_THRESHOLD_M, 0.1 m) of it.
    assert abs(float(rows[-1]["lateral_error_m"])) < 0.1


def test_sim_with_automatic_alpha(tmp_path: Path) -> None:
    out = tmp_path / "auto"
    r = _cli("sim", "--track", "test_track", "--alpha", "auto", "--speed", "8", "--duration", "60", "--offset", "2", "--out", str(out))
    assert r.returncode == 0, r.stderr
    m = _check_outputs(out)
    assert "body error" in r.stdout
    # The body error is the mean of the larger axle error: between the two axles' means and their sum.
    front, rear = m["lateral_error_front_axle_mean_abs_m"], m["lateral_error_rear_axle_mean_abs_m"]
    assert max(front, rear) <= m["body_error_mean_m"] <= front + rear
    import pandas as pd

    alpha = pd.read_csv(out / "timeseries.csv")["alpha"]
    assert alpha.between(0.0, 1.0).all() and alpha.nunique() > 10  # it moves
    bad = _cli("sim", "--track", "test_track", "--alpha", "sometimes", "--out", str(tmp_path / "x"))
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1 and "alpha" in bad.stderr


@needs_nuerburgring
def test_sim_on_the_nuerburgring(tmp_path: Path) -> None:
    out = tmp_path / "n"
    r = _cli("sim", "--track", str(NUERBURGRING), "--scale", "0.45", "--speed", "8", "--alpha-schedule", "sine:0.2", "--duration", "120", "--out", str(out))
    assert r.returncode == 0, r.stderr
    m = _check_outputs(out)
    assert m["distance_m"] > 500


@needs_nuerburgring
def test_paper_report(tmp_path: Path) -> None:
    out = tmp_path / "paper"
    r = _cli("paper", "--track", str(NUERBURGRING), "--out", str(out), "--quick")
    assert r.returncode == 0, r.stderr
    report = (out / "report.md").read_text()
    for paper_value in ("0.043", "0.042", "0.026", "0.050", "0.049", "0.260"):
        assert paper_value in report
    for line in report.splitlines():
        if line.startswith("![]("):
            assert (out / line[4:-1]).is_file(), line
    assert "Where our numbers differ" in report
    for claim in ("Verdict on C1", "Verdict on C2", "Verdict on C3"):
        assert claim in report


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--track", "no-such-track"], "unknown track"),
        (["--track", "/nonexistent/track.csv"], "cannot read track file"),
        (["--track", "test_track", "--alpha", "1.5"], "alpha"),
        (["--track", "test_track", "--alpha", "-0.1"], "alpha"),
        (["--track", "test_track", "--dt", "-0.01"], "dt"),
        (["--track", "test_track", "--dt", "abc"], "dt"),
        (["--track", "test_track", "--scale", "0"], "scale"),
        (["--track", "circle:-5"], "radius"),
        (["--track", "test_track", "--noise", "gauss:1"], "noise"),
        (["--track", "test_track", "--config", "/nonexistent.toml"], "config"),
        (["--track", "test_track", "--alpha", "0.3", "--alpha-schedule", "sine:0.2"], "not allowed"),
        (["--track", "test_track", "--controller", "mpc"], "controller"),
    ],
)
def test_bad_sim_arguments_are_one_line_errors(tmp_path: Path, args: list[str], needle: str) -> None:
    r = _cli("sim", *args, "--out", str(tmp_path / "o"), timeout=60)
    assert r.returncode == 2, (r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert needle in lines[0] and "Traceback" not in r.stderr


def test_bad_config_contents_are_one_line_errors(tmp_path: Path) -> None:
    cfg = tmp_path / "c.toml"
    cfg.write_text("[controller]\nlat_blend_factr = 0.2\n")
    r = _cli("sim", "--track", "test_track", "--config", str(cfg), "--out", str(tmp_path / "o"), timeout=60)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "lat_blend_factr" in r.stderr


def test_paper_with_a_missing_track_is_a_one_line_error(tmp_path: Path) -> None:
    r = _cli("paper", "--track", str(tmp_path / "none.csv"), "--out", str(tmp_path / "o"), timeout=60)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("command", ["sim", "paper"])
def test_help_documents_every_option(command: str) -> None:
    r = _cli(command, "--help", timeout=60)
    assert r.returncode == 0
    flags = {
        "sim": ["--track", "--scale", "--controller", "--alpha", "--alpha-schedule", "--direction", "--speed", "--offset", "--noise", "--delay", "--duration", "--laps", "--dt", "--config", "--seed", "--out"],
        "paper": ["--track", "--out", "--scale", "--tests", "--quick"],
    }[command]
    for flag in flags:
        assert flag in r.stdout, flag


def test_a_config_or_track_that_is_not_a_readable_file_says_why(tmp_path: Path) -> None:
    """A folder, a device and a missing name are three different mistakes:
    one line each, naming the file and what is wrong, exit code 2."""
    cases = [
        (("sumo", "run", "ring_single_lane", "--config", str(tmp_path)), "a folder, not a file"),
        (("sumo", "run", "ring_single_lane", "--config", "/dev/null"), "not a regular file"),
        (("sumo", "run", "ring_single_lane", "--config", str(tmp_path / "none.toml")), "no such file"),
        (("sim", "--track", str(tmp_path)), "a folder, not a file"),
    ]
    for args, why in cases:
        r = _cli(*args, "--out", str(tmp_path / "out"))
        lines = r.stderr.strip().splitlines()
        assert r.returncode == 2 and len(lines) == 1, (args, r.stderr)
        assert why in lines[0] and args[-1] in lines[0], (args, lines[0])
    assert not (tmp_path / "out").exists(), "nothing written"


@pytest.mark.parametrize("argv", [["sumo", "run", "x.sumocfg", "--out", "o"], ["compare", "x.sumocfg", "--out", "o"]])
def test_no_open_gaps_reaches_the_run_options(argv: list[str]) -> None:
    """`--no-open-gaps` (sumo run and compare) and the sweep parameter
    `open_gaps` switch off the gaps SUMO's drivers open for controlled
    vehicles; by default they are on."""
    from blendtrack.batch.kinds import _run_options as task_options
    from blendtrack.cli import _build_parser
    from blendtrack.cli.sumo import _run_options

    parser = _build_parser()
    assert _run_options(parser.parse_args(argv)).open_gaps is True
    assert _run_options(parser.parse_args([*argv, "--no-open-gaps"])).open_gaps is False
    assert task_options({"params": {}, "seed": 0}).open_gaps is True
    assert task_options({"params": {"open_gaps": False}, "seed": 0}).open_gaps is False
