"""Hostile input (issue 20): every case ends in exactly one expected class of
outcome, and never in an abort, a panic, a traceback or a wrong answer.

- CLI: exit code 2 and exactly one line on stderr naming the problem (or a
  correct run, where the input is valid but odd);
- API: a specific exception class (a ``BlendtrackError`` subclass, or
  ``TypeError`` / ``OverflowError`` where Python's conventions say so), or a
  correct result checked against an independent computation.

Inputs that used to abort the process (memory sized by the input) run in a
subprocess, so a regression shows as exit code 134, not a dead test session.
The SUMO cases are few and short.
"""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import blendtrack
from blendtrack import cli
from blendtrack.batch import report as batch_report
from blendtrack.batch import store as batch_store

REPO = Path(__file__).resolve().parents[1]
RING = REPO / "sumo_scenarios" / "ring_single_lane"
LIMIT = str(blendtrack._blendtrack.MAX_SIM_STEPS)


# ------------------------------------------------------------------ helpers
def _main(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    try:
        rc = cli.main(argv)
    except SystemExit as e:  # argparse errors
        rc = int(e.code or 0)
    out, err = capsys.readouterr()
    return rc, out, err


def _assert_one_line_error(rc: int, err: str, *needles: str) -> None:
    assert rc == 2, err
    assert "Traceback" not in err
    assert err.endswith("\n") and err.count("\n") == 1, repr(err)
    for n in needles:
        assert n in err, err


def _subprocess_cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "blendtrack.cli", *args], capture_output=True, text=True, timeout=300, check=False
    )


def _csv(tmp_path: Path, text: str) -> str:
    f = tmp_path / "track.csv"
    f.write_text(text)
    return str(f)


def _toml(tmp_path: Path, text: str, name: str = "cfg.toml") -> str:
    f = tmp_path / name
    f.write_text(text)
    return str(f)


# ------------------------------------------- sim: memory sized by the input
@pytest.mark.parametrize(
    ("args", "name"),
    [
        (["--laps", "1e6"], "laps"),
        (["--duration", "1e8"], "duration_s"),
        (["--delay", "1e9"], "delay_s"),
        (["--dt", "1e-300"], "duration_s"),
        (["--track", "straight:1e300"], "length_m"),
        (["--track", "circle:20", "--laps", "1e5"], "laps"),
    ],
)
def test_sizes_beyond_the_limits_are_one_line_errors_not_aborts(tmp_path: Path, args: list[str], name: str) -> None:
    argv = ["sim", "--track", "straight:200", *args, "--out", str(tmp_path / "o")]
    p = _subprocess_cli(*argv)
    _assert_one_line_error(p.returncode, p.stderr, name, "limit")


# --------------------------------------------------- sim: argument errors
SIM_BAD_ARGS: list[tuple[list[str], str]] = [
    (["--seed", "-1"], "seed must be in [0, 2**64)"),
    (["--seed", str(2**64)], "seed must be in [0, 2**64)"),
    (["--seed", "1.5"], "seed must be a whole number"),
    (["--seed", "abc"], "seed must be a whole number"),
    (["--scale", "1e300"], "beyond +-1e9 m"),
    (["--scale", "1e10"], "beyond +-1e9 m"),
    (["--scale", "0"], "scale must be > 0"),
    (["--scale", "nan"], "scale must be finite"),
    (["--scale", "-1"], "scale must be > 0"),
    (["--dt", "0"], "dt must be > 0"),
    (["--dt", "2"], "dt must be <= 1"),
    (["--dt", "nan"], "dt must be finite"),
    (["--duration", "-1"], "duration must be > 0"),
    (["--duration", "inf"], "duration must be finite"),
    (["--laps", "0"], "laps must be > 0"),
    (["--delay", "-1"], "delay must be >= 0"),
    (["--alpha", "1.5"], "alpha must be <= 1"),
    (["--alpha-schedule", "sine:nan"], "must be finite"),
    (["--alpha-schedule", "sine:inf"], "must be finite"),
    (["--alpha-schedule", "cosine:1"], "bad alpha"),
    (["--noise", "uniform:-1"], "amplitudes must be >= 0"),
    (["--noise", "walk:1"], "bad noise"),
    (["--noise", "uniform:nan"], "must be finite"),
    (["--noise", "bogus"], "bad noise"),
    (["--track", "circle:"], "give the radius"),
    (["--track", "circle:-5"], "radius_m"),
    (["--track", "circle:nan"], "must be finite"),
    (["--track", "circle:1e300"], "beyond +-1e9 m"),
    (["--track", "straight:0"], "length_m"),
    (["--track", "nosuch.csv"], "no such file"),
    (["--track", "garbage"], "unknown track"),
    (["--speed", "0"], "speed must be > 0"),
    (["--offset", "nan"], "offset must be finite"),
    (["--offset", "1e300"], "beyond 1e9 m"),
    (["--heading-error-deg", "inf"], "heading error must be finite"),
    (["--config", "nosuch.toml"], "no such file"),
    (["--controller", "mpc"], "invalid choice"),
]


@pytest.mark.parametrize(("args", "needle"), SIM_BAD_ARGS)
def test_bad_sim_arguments_are_one_line_and_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], needle: str
) -> None:
    argv = ["sim", "--track", "straight:100", "--duration", "1", *args, "--out", str(tmp_path / "o")]
    rc, _, err = _main(argv, capsys)
    _assert_one_line_error(rc, err, needle)


TRACK_FILES: list[tuple[str, str]] = [
    ("x,y\n1,2\n", "not a number"),
    ("0,0\nnan,1\n", "not finite"),
    ("0,0\n", "at least 2 distinct points"),
    ("0,0\n1e10,0\n", "beyond +-1e9 m"),
    ("0,0,1,1\n1,0,1\n", "columns"),
    ("0,0,1,-1\n5,0,1,1\n", "must be >= 0"),
    ("0,0,1,1,1\n", "expected 2 or 4 columns"),
    ("", "at least 2 distinct points"),
    ("0,0\n0,0\n0,0\n", "at least 2 distinct points"),
    ("0,0\n1e309,0\n", "not finite"),
]


@pytest.mark.parametrize(("text", "needle"), TRACK_FILES)
def test_bad_track_files_are_one_line_and_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str, needle: str
) -> None:
    track = _csv(tmp_path, text)
    rc, _, err = _main(["sim", "--track", track, "--duration", "1", "--out", str(tmp_path / "o")], capsys)
    _assert_one_line_error(rc, err, needle)


CONFIG_FILES: list[tuple[str, str]] = [
    ("[controller]\nbogus = 1\n", "bogus"),
    ("[controller]\nlat_blend_factor = 2.0\n", "lat_blend_factor"),
    ("[controller]\nlat_blend_factor = 99999999999999999999999\n", "cfg.toml"),
    ("[controller]\nlat_blend_factor = nan\n", "lat_blend_factor"),
    ("[controller]\nlat_blend_factor = \"half\"\n", "lat_blend_factor"),
    ("[vehicle]\nwheelbase_m = -1.0\n", "wheelbase_m"),
    ("[vehicle]\nmax_steering_deg = 90.0\n", "max_steering_deg"),
    ("[controller\n", "cfg.toml"),
    ("\x00\x01", "cfg.toml"),
]


@pytest.mark.parametrize(("text", "needle"), CONFIG_FILES)
def test_bad_config_files_are_one_line_and_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str, needle: str
) -> None:
    cfg = _toml(tmp_path, text)
    rc, _, err = _main(["sim", "--track", "straight:100", "--config", cfg, "--duration", "1", "--out", str(tmp_path / "o")], capsys)
    _assert_one_line_error(rc, err, needle)


def test_an_output_path_that_is_a_file_is_one_line_and_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "o"
    out.write_text("mine")
    rc, _, err = _main(["sim", "--track", "straight:100", "--duration", "1", "--out", str(out)], capsys)
    _assert_one_line_error(rc, err, str(out))
    assert out.read_text() == "mine"


# ------------------------------------------------- sim: odd but valid input
def test_a_vehicle_starting_on_the_virtual_border_recovers(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # The default corridor is 12 m wide: an offset of 6 m puts the rear axle
    # on its border. It used to stand still there for the whole run.
    out = tmp_path / "o"
    rc, _, err = _main(["sim", "--track", "circle:50", "--offset", "6", "--duration", "30", "--out", str(out)], capsys)
    assert rc == 0, err
    m = json.loads((out / "metrics.json").read_text())
    assert m["distance_m"] > 50.0
    # Recovered: settled for good within the 30 s (|e| below the metrics'
    # 0.1 m settling threshold from then on; a vehicle that stays on the
    # border, 6 m off, never settles and has NaN here).
    assert math.isfinite(m["settling_time_s"]) and m["settling_time_s"] < 30.0, m["settling_time_s"]


@pytest.mark.parametrize("offset", [6.0, -6.0, 6.0 - 1e-12, -6.0 + 1e-12])
def test_api_runs_starting_on_either_border_drive_back(offset: float) -> None:
    path = blendtrack.Path.circle(50.0)
    frame, m = blendtrack.simulate(path, blendtrack.ControllerConfig(), offset_m=offset, duration_s=30.0)
    assert m["distance_m"] > 50.0
    # Back on the path: settled for good within the run, so the last sample
    # is within the metrics' 0.1 m settling threshold.
    assert math.isfinite(m["settling_time_s"]), m["settling_time_s"]
    assert abs(frame["lateral_error_m"].iloc[-1]) < 0.1


def test_laps_run_to_the_lap_under_the_step_limit(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "o"
    rc, _, err = _main(["sim", "--track", "circle:20", "--laps", "2", "--out", str(out)], capsys)
    assert rc == 0, err
    m = json.loads((out / "metrics.json").read_text())
    assert m["distance_m"] >= 2 * 2 * math.pi * 20 * 0.999


def test_the_largest_seed_is_accepted(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "o"
    argv = ["sim", "--track", "straight:100", "--duration", "2", "--noise", "uniform:0.1", "--seed", str(2**64 - 1), "--out", str(out)]
    rc, _, err = _main(argv, capsys)
    assert rc == 0, err
    assert (out / "metrics.json").is_file()


# ------------------------------------------------------------- API: Path
PTS = [[0, 0], [10, 0], [20, 5]]

PATH_CASES: list[tuple[str, Callable[[], Any], type[BaseException]]] = [
    ("1-D array", lambda: blendtrack.Path(np.zeros(4)), blendtrack.InputError),
    ("3 columns", lambda: blendtrack.Path(np.zeros((3, 3))), blendtrack.InputError),
    ("3-D array", lambda: blendtrack.Path(np.zeros((2, 2, 2))), blendtrack.InputError),
    ("None", lambda: blendtrack.Path(None), TypeError),
    ("a string", lambda: blendtrack.Path("0,0;1,1"), TypeError),
    ("text array", lambda: blendtrack.Path(np.array([["a", "b"], ["c", "d"]])), TypeError),
    ("ragged list", lambda: blendtrack.Path([[0, 0], [1]]), TypeError),
    ("no rows", lambda: blendtrack.Path(np.zeros((0, 2))), blendtrack.PathError),
    ("NaN", lambda: blendtrack.Path([[0, 0], [math.nan, 1]]), blendtrack.PathError),
    ("too far", lambda: blendtrack.Path([[0, 0], [1e10, 0]]), blendtrack.PathError),
    ("widths 1-D", lambda: blendtrack.Path(PTS, widths=np.zeros(3)), blendtrack.InputError),
    ("widths count", lambda: blendtrack.Path(PTS, widths=np.ones((2, 2))), blendtrack.PathError),
    ("negative width", lambda: blendtrack.Path(PTS, widths=[[1, -1], [1, 1], [1, 1]]), blendtrack.PathError),
    ("straight 1e300", lambda: blendtrack.Path.straight(1e300), blendtrack.PathError),
    ("straight nan", lambda: blendtrack.Path.straight(math.nan), blendtrack.PathError),
    ("straight spacing 0", lambda: blendtrack.Path.straight(10.0, 0.0), blendtrack.PathError),
    ("straight tiny spacing", lambda: blendtrack.Path.straight(1e7, 1e-3), blendtrack.PathError),
    ("circle 1e300", lambda: blendtrack.Path.circle(1e300), blendtrack.PathError),
    ("circle -1", lambda: blendtrack.Path.circle(-1.0), blendtrack.PathError),
    ("test track 1e-7", lambda: blendtrack.Path.test_track(1e-7), blendtrack.PathError),
    ("scaled 1e300", lambda: blendtrack.Path.straight(10.0).scaled(1e300), blendtrack.PathError),
    ("scaled 0", lambda: blendtrack.Path.straight(10.0).scaled(0.0), blendtrack.PathError),
    ("project nan", lambda: blendtrack.Path.straight(10.0).project(math.nan, math.nan), blendtrack.InputError),
    ("project inf", lambda: blendtrack.Path.straight(10.0).project(math.inf, 0.0), blendtrack.InputError),
    ("project 1e300", lambda: blendtrack.Path.straight(10.0).project(1e300, 1e300), blendtrack.InputError),
    ("point_at nan", lambda: blendtrack.Path.straight(10.0).point_at(math.nan), blendtrack.InputError),
    ("heading_at inf", lambda: blendtrack.Path.straight(10.0).heading_at(math.inf), blendtrack.InputError),
    ("curvature_at nan", lambda: blendtrack.Path.straight(10.0).curvature_at(math.nan), blendtrack.InputError),
    ("tum csv missing", lambda: blendtrack.Path.from_tum_csv("/nonexistent/track.csv"), blendtrack.PathError),
    ("tum csv a folder", lambda: blendtrack.Path.from_tum_csv("/"), blendtrack.PathError),
]


@pytest.mark.parametrize(("what", "call", "error"), PATH_CASES, ids=[c[0] for c in PATH_CASES])
def test_bad_paths_raise_the_class_of_their_kind(what: str, call: Callable[[], Any], error: type[BaseException]) -> None:
    with pytest.raises(error) as info:
        call()
    assert "\n" not in str(info.value)
    if error is TypeError:
        assert "(N, 2)" in str(info.value)


@pytest.mark.parametrize("dtype", [np.int64, np.int32, np.uint8, np.float32])
def test_int_and_narrow_coordinates_are_coordinates(dtype: type) -> None:
    p = blendtrack.Path(np.array(PTS, dtype=dtype))
    assert p.length_m == pytest.approx(10.0 + math.hypot(10.0, 5.0), rel=1e-12)
    np.testing.assert_array_equal(p.points(), np.array(PTS, dtype=np.float64))


def test_nested_lists_of_ints_are_coordinates() -> None:
    p = blendtrack.Path(PTS, widths=[[1, 2], [1, 2], [1, 2]])
    assert p.has_widths and len(p) == 3


def test_a_far_point_within_range_projects_onto_the_path() -> None:
    # 1 km to the left of a straight along +x, and 1e9 m (the limit), where
    # only the lateral distance is still resolved (the foot is not: every
    # vertex is as near to within rounding).
    d = blendtrack.Path.straight(10.0).project(5.0, 1e3)
    assert d["s_m"] == pytest.approx(5.0)
    assert d["lateral_m"] == pytest.approx(1e3, rel=1e-12)
    d = blendtrack.Path.straight(10.0).project(5.0, -1e9)
    assert 0.0 <= d["s_m"] <= 10.0
    assert d["lateral_m"] == pytest.approx(-1e9, rel=1e-12)


# ------------------------------------------------------ API: configuration
CONFIG_CASES: list[tuple[str, Callable[[], Any], type[BaseException]]] = [
    ("unknown key 10**400", lambda: blendtrack.ControllerConfig(x=10**400), blendtrack.ConfigError),
    ("known key 10**400", lambda: blendtrack.ControllerConfig(lat_blend_factor=10**400), blendtrack.ConfigError),
    ("vehicle 10**400", lambda: blendtrack.VehicleParams(wheelbase_m=-(10**400)), blendtrack.ConfigError),
    ("replace 10**400", lambda: blendtrack.ControllerConfig().replace(preferred_speed=10**400), blendtrack.ConfigError),
    ("nan", lambda: blendtrack.ControllerConfig(lat_blend_factor=math.nan), blendtrack.ConfigError),
    ("inf speed", lambda: blendtrack.ControllerConfig(preferred_speed=math.inf), blendtrack.ConfigError),
    ("string for a number", lambda: blendtrack.ControllerConfig(lat_blend_factor="half"), blendtrack.ConfigError),
    ("list for a number", lambda: blendtrack.ControllerConfig(lat_blend_factor=[1.0]), TypeError),
    ("unknown key", lambda: blendtrack.ControllerConfig(bogus=1), blendtrack.ConfigError),
    ("unknown direction", lambda: blendtrack.ControllerConfig(direction="sideways"), blendtrack.ConfigError),
    ("negative wheelbase", lambda: blendtrack.VehicleParams(wheelbase_m=-1.0), blendtrack.ConfigError),
    ("toml garbage", lambda: blendtrack.ControllerConfig.from_toml("= = ="), blendtrack.ConfigError),
    ("load missing", lambda: blendtrack.load_config("/nonexistent.toml"), blendtrack.ConfigError),
]


@pytest.mark.parametrize(("what", "call", "error"), CONFIG_CASES, ids=[c[0] for c in CONFIG_CASES])
def test_bad_configs_raise_config_error_or_type_error(what: str, call: Callable[[], Any], error: type[BaseException]) -> None:
    with pytest.raises(error):
        call()


def test_a_huge_int_that_fits_a_float_is_taken_as_that_float() -> None:
    c = blendtrack.ControllerConfig(ray_horizon_m=10**20)
    assert c.ray_horizon_m == 1e20


# ---------------------------------------------------------- API: Fleet
@pytest.fixture
def fleet() -> tuple[blendtrack.Fleet, int]:
    f = blendtrack.Fleet()
    tid = f.add_track(blendtrack.Path.straight(100.0))
    return f, f.add_vehicle(tid)


Z = np.zeros(1)
FLEET_CASES: list[tuple[str, dict[str, Any], type[BaseException], str]] = [
    ("2-D x", {"x": np.zeros((1, 1))}, TypeError, "`x`"),
    ("text x", {"x": np.array(["a"])}, TypeError, "`x`"),
    ("numeric text x", {"x": ["1.5"]}, TypeError, "`x`"),
    ("None x", {"x": None}, TypeError, "`x`"),
    ("2-D alpha", {"alpha": np.zeros((1, 1))}, TypeError, "`alpha`"),
    ("text leader gap", {"leader_gap": ["near"]}, TypeError, "`leader_gap`"),
    ("float slot", {"slots": [0.5]}, TypeError, "`slots`"),
    ("integral float slot", {"slots": np.array([0.0])}, TypeError, "`slots`"),
    ("text slot", {"slots": "0"}, TypeError, "`slots`"),
    ("2-D slots", {"slots": np.zeros((1, 1), dtype=np.int64)}, TypeError, "`slots`"),
    ("short y", {"y": np.zeros(0)}, blendtrack.InputError, "y"),
    ("unknown slot", {"slots": [7]}, blendtrack.InputError, "7"),
    ("dt 0", {"dt": 0.0}, blendtrack.InputError, "dt"),
    ("dt nan", {"dt": math.nan}, blendtrack.InputError, "dt"),
]


@pytest.mark.parametrize(("what", "override", "error", "needle"), FLEET_CASES, ids=[c[0] for c in FLEET_CASES])
def test_bad_fleet_steps_name_the_argument(
    fleet: tuple[blendtrack.Fleet, int], what: str, override: dict[str, Any], error: type[BaseException], needle: str
) -> None:
    f, slot = fleet
    kw: dict[str, Any] = {"slots": [slot], "x": Z, "y": Z, "theta": Z, "v": Z, "delta": Z}
    kw.update(override)
    with pytest.raises(error) as info:
        f.step(**kw)
    assert needle in str(info.value) and "\n" not in str(info.value)


@pytest.mark.parametrize(("field", "value"), [("x", 1e308), ("y", -1e308), ("x", 2e9), ("x", math.nan), ("theta", math.inf)])
def test_unusable_vehicle_data_is_flagged_not_stepped(fleet: tuple[blendtrack.Fleet, int], field: str, value: float) -> None:
    f, slot = fleet
    kw: dict[str, Any] = {"slots": [slot], "x": [1.0], "y": [0.5], "theta": [0.0], "v": [2.0], "delta": [0.0]}
    kw[field] = [value]
    out = f.step(**kw)
    assert out["ok"].tolist() == [False]
    assert math.isnan(out["steering_rad"][0])


def test_int_columns_and_an_empty_step_are_fine(fleet: tuple[blendtrack.Fleet, int]) -> None:
    f, slot = fleet
    out = f.step([slot], [1], [0], [0], [2], [0])
    ref = f.step([slot], [1.0], [0.0], [0.0], [2.0], [0.0])
    assert out["ok"].tolist() == [True]
    assert out["accel_mps2"][0] == ref["accel_mps2"][0]
    assert len(f.step([], [], [], [], [], [])["ok"]) == 0


@pytest.mark.parametrize("slot", [0.5, "0", None])
def test_slot_arguments_must_be_ints(fleet: tuple[blendtrack.Fleet, int], slot: Any) -> None:
    f, _ = fleet
    with pytest.raises(TypeError):
        f.remove_vehicle(slot)


# ------------------------------------------------------ API: simulate, metrics
SIM_API_CASES: list[tuple[str, dict[str, Any], type[BaseException]]] = [
    ("duration 1e8", {"duration_s": 1e8}, blendtrack.ConfigError),
    ("dt 1e-300", {"dt_s": 1e-300}, blendtrack.ConfigError),
    ("delay 1e9", {"delay_s": 1e9}, blendtrack.ConfigError),
    ("laps 1e6", {"laps": 1e6, "duration_s": 1e12}, blendtrack.ConfigError),
    ("callable alpha, 1e9 s", {"alpha": lambda t: 0.5, "duration_s": 1e9}, blendtrack.ConfigError),
    ("callable alpha, dt 0", {"alpha": lambda t: 0.5, "dt_s": 0.0}, blendtrack.ConfigError),
    ("alpha sine nan", {"alpha": "sine:nan"}, blendtrack.ConfigError),
    ("offset 1e300", {"offset_m": 1e300}, blendtrack.ConfigError),
    ("noise nan", {"noise": "uniform:nan"}, blendtrack.ConfigError),
    ("seed -1", {"seed": -1}, OverflowError),
    ("seed 2**64", {"seed": 2**64}, OverflowError),
]


@pytest.mark.parametrize(("what", "kw", "error"), SIM_API_CASES, ids=[c[0] for c in SIM_API_CASES])
def test_bad_simulate_calls_raise_their_class(what: str, kw: dict[str, Any], error: type[BaseException]) -> None:
    with pytest.raises(error):
        blendtrack.simulate(blendtrack.Path.straight(100.0), **kw)


def test_metrics_of_no_samples_are_an_error_not_zero() -> None:
    e = np.zeros(0)
    with pytest.raises(blendtrack.InputError, match="empty"):
        blendtrack.compute_metrics(e, e, e, e, e, e)


def test_metrics_of_one_sample_are_that_sample() -> None:
    one = np.array([0.3])
    m = blendtrack.compute_metrics(np.array([0.1]), one, np.zeros(1), np.zeros(1), np.ones(1), np.array([0.1]))
    assert m["lateral_error_mean_abs_m"] == pytest.approx(0.3)
    assert m["lateral_error_max_abs_m"] == pytest.approx(0.3)


# ------------------------------------------------------------------- batch
def _sweep(tmp_path: Path, body: str) -> str:
    return _toml(tmp_path, body, "sweep.toml")


SWEEP_CASES: list[tuple[str, str]] = [
    (
        'kind = "sim"\nscenarios = ["test_track"]\nseeds = 10\n[grid]\n'
        "alpha = { start = 0.0, stop = 1.0, step = 0.0001 }\n"
        "preferred_speed = { start = 1.0, stop = 10.0, step = 0.001 }\n",
        "limit of 100000",
    ),
    ('kind = "sim"\nscenarios = ["test_track"]\nseeds = 1000000000\n', "limit of 100000"),
    ('kind = "sim"\nscenarios = ["test_track"]\nseeds = [-1]\n', "seeds"),
    ('kind = "sim"\nscenarios = ["test_track"]\nseeds = [18446744073709551616]\n', "seeds"),
    ('kind = "sim"\nscenarios = ["test_track"]\n[fixed]\nalpha_schedule = "sine:nan"\n', "must be finite"),
    ('kind = "sim"\nscenarios = ["test_track"]\n[grid]\nalpha_schedule = ["sine:0.2", "sine:inf"]\n', "must be finite"),
    ('kind = "sim"\nscenarios = ["test_track"]\n[fixed]\nnoise = "uniform:nan"\n', "must be finite"),
]


@pytest.mark.parametrize(("body", "needle"), SWEEP_CASES)
def test_bad_sweeps_are_refused_before_running(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], body: str, needle: str
) -> None:
    rc, _, err = _main(["batch", _sweep(tmp_path, body), "--out", str(tmp_path / "out"), "--quiet"], capsys)
    _assert_one_line_error(rc, err, needle)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--dask-local", "100000"], "dask-local must be <= 256"),
        (["--workers", "0"], "workers must be >= 1"),
        (["--workers", "1e3"], "workers must be a whole number"),
        (["--timeout", "nan"], "timeout must be finite"),
    ],
)
def test_bad_batch_options_are_one_line_errors(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], needle: str
) -> None:
    sweep = _sweep(tmp_path, 'kind = "sim"\nscenarios = ["straight:100"]\n')
    rc, _, err = _main(["batch", sweep, *args, "--out", str(tmp_path / "out")], capsys)
    _assert_one_line_error(rc, err, needle)
    assert not (tmp_path / "out").exists()


@pytest.fixture(scope="module")
def done_batch(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A finished batch of two short sim runs (made once, copied per test)."""
    base = tmp_path_factory.mktemp("batch")
    sweep = base / "sweep.toml"
    sweep.write_text('kind = "sim"\nscenarios = ["straight:100"]\nseeds = 2\n[fixed]\nduration_s = 2.0\n')
    p = _subprocess_cli("batch", str(sweep), "--out", str(base / "out"), "--workers", "1", "--quiet")
    assert p.returncode == 0, p.stderr
    return base / "out"


def _copy(done: Path, tmp_path: Path) -> Path:
    out = tmp_path / "out"
    shutil.copytree(done, out)
    return out


def _first_record(out: Path) -> Path:
    return sorted((out / "runs").glob("*.json"))[0]


@pytest.mark.parametrize(
    ("field", "value"),
    [("metrics", "garbage"), ("attempt", "abc"), ("status", 3), ("metrics", {"m": "x"}), ("wall_time_s", [1])],
)
@pytest.mark.parametrize("mode", ["--report-only", "--resume"])
def test_corrupt_records_are_one_line_errors_naming_the_file(
    done_batch: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], field: str, value: Any, mode: str
) -> None:
    out = _copy(done_batch, tmp_path)
    rec_file = _first_record(out)
    rec = json.loads(rec_file.read_text())
    rec[field] = value
    rec_file.write_text(json.dumps(rec))
    sweep = str(out / "sweep.toml")
    rc, _, err = _main(["batch", sweep, "--out", str(out), mode, "--quiet"], capsys)
    _assert_one_line_error(rc, err, rec_file.name, f"`{field}`")


@pytest.mark.parametrize("manifest", ['{"runs": 5}', '{"runs": [5]}', "[1, 2]", '{"runs": [], "swept": 3}'])
def test_a_corrupt_manifest_is_a_one_line_error(
    done_batch: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], manifest: str
) -> None:
    out = _copy(done_batch, tmp_path)
    (out / "batch.json").write_text(manifest)
    rc, _, err = _main(["batch", str(out / "sweep.toml"), "--out", str(out), "--report-only", "--quiet"], capsys)
    _assert_one_line_error(rc, err, "batch.json")


@pytest.mark.parametrize("name", ["results.csv", "summary.md", "results.parquet"])
def test_a_users_own_files_are_not_overwritten_by_a_batch(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], name: str
) -> None:
    out = tmp_path / "mine"
    out.mkdir()
    (out / name).write_text("my own work\n")
    sweep = _sweep(tmp_path, 'kind = "sim"\nscenarios = ["straight:100"]\n[fixed]\nduration_s = 1.0\n')
    rc, _, err = _main(["batch", sweep, "--out", str(out), "--quiet"], capsys)
    _assert_one_line_error(rc, err, name, "not a batch folder")
    assert (out / name).read_text() == "my own work\n"
    assert sorted(p.name for p in out.iterdir()) == [name]


def test_report_only_on_a_folder_without_a_batch_is_a_one_line_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    sweep = _sweep(tmp_path, 'kind = "sim"\nscenarios = ["straight:100"]\n')
    rc, _, err = _main(["batch", sweep, "--out", str(tmp_path), "--report-only"], capsys)
    _assert_one_line_error(rc, err, "no batch.json")


def test_a_report_interrupted_while_written_leaves_no_results_without_summary(
    done_batch: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = _copy(done_batch, tmp_path)
    for name in batch_store.DERIVED:
        (out / name).unlink()
    import pandas as pd

    def killed(self: Any, *a: Any, **k: Any) -> Any:
        raise KeyboardInterrupt  # as a kill while the csv is rendered

    monkeypatch.setattr(pd.DataFrame, "to_csv", killed)
    with pytest.raises(KeyboardInterrupt):
        batch_report.write_report(out)
    left = {p.name for p in out.iterdir()}
    assert not left & {"results.parquet", "results.csv", "summary.md"}, left
    assert not [p for p in out.iterdir() if p.name.endswith(".tmp")]


def test_renames_put_the_summary_first(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import os

    done: list[str] = []
    real = os.replace

    def replace(src: Any, dst: Any) -> None:
        if done:
            raise KeyboardInterrupt  # killed after the first rename
        real(src, dst)
        done.append(Path(dst).name)

    monkeypatch.setattr(os, "replace", replace)
    with pytest.raises(KeyboardInterrupt):
        batch_store.atomic_write_all([(tmp_path / "summary.md", "s"), (tmp_path / "results.csv", "r")])
    assert done == ["summary.md"]
    assert not (tmp_path / "results.csv").exists()


# -------------------------------------------------------------------- SUMO
def _sumo(tmp_path: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return _subprocess_cli("sumo", "run", *args, "--quiet")


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--end", "10", "--sumo-args", "--end 5"], "given twice"),
        (["--sumo-args", "--seed 3"], "--seed"),
        (["--sumo-args", "--end soon"], "not a time"),
        (["--controlled-ids", "nosuch,other"], "none of the controlled ids"),
        (["--seed", "-1"], "seed must be in [0, 2**64)"),
        (["--end", "nan"], "end time must be finite"),
        (["--end", "soon"], "end time must be a time (seconds, H:M:S or D:H:M:S), got 'soon'"),
        (["--end", "0:0:0"], "end time must be > 0"),
    ],
)
def test_bad_sumo_runs_are_refused_before_sumo_starts(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], needle: str
) -> None:
    out = tmp_path / "o"
    rc, _, err = _main(["sumo", "run", str(RING), *args, "--out", str(out), "--quiet"], capsys)
    _assert_one_line_error(rc, err, needle)
    assert not (out / "sumo" / "sumo.log").exists()


def test_an_end_in_sumo_args_wins(tmp_path: Path) -> None:
    out = tmp_path / "o"
    p = _sumo(tmp_path, str(RING), "--sumo-args", "--end 4", "--out", str(out))
    assert p.returncode == 0, p.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["end_s"] == pytest.approx(4.0)
    assert not (out / "INCOMPLETE").exists()


def test_unknown_controlled_ids_are_named_in_a_warning(tmp_path: Path) -> None:
    out = tmp_path / "o"
    p = _sumo(tmp_path, str(RING), "--controlled-ids", "auto0,ghost7", "--end", "3", "--out", str(out))
    assert p.returncode == 0, p.stderr
    warnings = [line for line in p.stderr.splitlines() if "warning" in line]
    assert len(warnings) == 1 and "ghost7" in warnings[0] and "auto0" not in warnings[0], p.stderr
    rows = (out / "vehicles.csv").read_text().splitlines()
    assert len(rows) == 2 and rows[1].startswith("auto0")


def test_a_late_route_error_is_one_line_and_the_folder_says_incomplete(tmp_path: Path) -> None:
    # A vehicle departing at 350 s on a route through an edge that does not
    # exist, after one departing at 250 s: SUMO reads routes 200 s ahead and
    # stops at the first beyond that, so it parses the bad one only in the
    # middle of the run, not at the pre-check's load. The folder held an
    # earlier run.
    scen = tmp_path / "ring"
    shutil.copytree(RING, scen)
    rou = scen / "ring_single_lane.rou.xml"
    rou.write_text(
        rou.read_text().replace(
            "</routes>",
            '    <vehicle id="later" type="human" route="ring_from_s" depart="250"/>\n'
            '    <vehicle id="late" type="human" depart="350"><route edges="ring_n no_such_edge"/></vehicle>\n</routes>',
        )
    )
    out = tmp_path / "o"
    out.mkdir()
    (out / "summary.json").write_text('{"old": true}')
    (out / "vehicles.csv").write_text("old\n")
    p = _sumo(tmp_path, str(scen), "--end", "400", "--out", str(out))
    _assert_one_line_error(p.returncode, p.stderr, "SUMO stopped the run")
    assert (out / "INCOMPLETE").is_file()
    assert not (out / "summary.json").exists()
    # vehicles.csv is written as vehicles finish: this run's header, no row
    # of the earlier run's, none of a vehicle still driving when SUMO stopped.
    lines = (out / "vehicles.csv").read_text().splitlines()
    assert lines[0].startswith("id,") and all(",end," not in line for line in lines[1:])
